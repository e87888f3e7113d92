//! Shared by the core integration tests: a scan of the synthetic scanner reconstructed as the
//! live graph would (100 Hz poses, the edge detector's defaults, one grid per camera).
#![allow(dead_code, clippy::unwrap_used)]

use xsurf_core::edge::{EdgeConfig, EdgeDetector, LaserLine};
use xsurf_core::mesh::Grid;
use xsurf_core::pose::PoseTrack;
use xsurf_core::rig::Rig;
use xsurf_core::synth::Scanner;
use xsurf_core::triangulate::{Profile, Triangulator, TriangulatorConfig};

/// `table -> carm` as c_arm_pose would publish it: 100 Hz samples of the speed model.
pub fn pose_track(scanner: &Scanner) -> PoseTrack {
    let mut poses = PoseTrack::default();
    let mut t = -0.1;
    while t <= scanner.duration_s() + 0.1 {
        poses.push(scanner.settings.start_stamp_ns + (t * 1e9).round() as i64, &scanner.pose_at(t));
        t += 0.01;
    }
    poses
}

/// Each camera's grid of the scanner's scan, triangulated with the rig `used` (its cameras
/// and laser plane; the images come from the scanner's own rig).
pub fn camera_grids(scanner: &Scanner, used: &Rig) -> Vec<Grid> {
    let poses = pose_track(scanner);
    let cfg = TriangulatorConfig { laser_plane: used.laser_plane, ..Default::default() };
    used.cameras
        .iter()
        .enumerate()
        .map(|(ci, cam)| {
            let tri = Triangulator::new(cam.geometry().unwrap(), &cfg).unwrap();
            let mut det = EdgeDetector::new(EdgeConfig::default()).unwrap();
            let mut grid = Grid::new(cam.height as usize);
            let (mut line, mut prof) = (LaserLine::default(), Profile::default());
            for f in 0..scanner.frame_count() {
                let ft = scanner.frame_time(f);
                det.detect(&scanner.render(ci, f).view().unwrap(), &mut line).unwrap();
                tri.triangulate(&line, &poses.at(ft.stamp_ns).unwrap(), &mut prof);
                grid.push(ft.stamp_ns, &prof).unwrap();
            }
            grid
        })
        .collect()
}

/// Each camera's grids of the scanner's scan, one per laser of `used` (its effective lasers:
/// each found in its own colour against the others, intersected with its own plane), as the
/// live graph makes them: `grids[camera][laser]`.
pub fn laser_grids(scanner: &Scanner, used: &Rig) -> Vec<Vec<Grid>> {
    use xsurf_core::edge::{Channel, LaserDetectors};
    let poses = pose_track(scanner);
    let lasers = used.effective_lasers();
    let several = used.lasers.len() > 1;
    used.cameras
        .iter()
        .enumerate()
        .map(|(ci, cam)| {
            let tri: Vec<Triangulator> = lasers
                .iter()
                .map(|l| {
                    let cfg = TriangulatorConfig { laser_plane: l.plane, ..Default::default() };
                    Triangulator::new(cam.geometry().unwrap(), &cfg).unwrap()
                })
                .collect();
            let configs = lasers
                .iter()
                .map(|l| {
                    let channel =
                        if several { Channel::against_others(l.channel) } else { EdgeConfig::default().channel };
                    EdgeConfig { channel, ..EdgeConfig::default() }
                })
                .collect();
            let mut det = LaserDetectors::new(configs).unwrap();
            let mut grids = vec![Grid::new(cam.height as usize); lasers.len()];
            let (mut lines, mut prof) = (Vec::new(), Profile::default());
            for f in 0..scanner.frame_count() {
                let ft = scanner.frame_time(f);
                det.detect(&scanner.render(ci, f).view().unwrap(), &mut lines).unwrap();
                for (k, line) in lines.iter().enumerate() {
                    tri[k].triangulate(line, &poses.at(ft.stamp_ns).unwrap(), &mut prof);
                    grids[k].push(ft.stamp_ns, &prof).unwrap();
                }
            }
            grids
        })
        .collect()
}
