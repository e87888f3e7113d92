//! `triangulator`: `laser_line` + `camera_info` + `/tf` + `/tf_static` -> `profile`.
//!
//! A line waits (bounded) until `table -> carm` is known at its stamp, so tf arriving a little
//! after the image is fine; a line that cannot be placed is counted and reported.

mod params;
pub use params::*;

/// The node type, as the registry lists it.
pub const NODE: crate::registry::NodeType =
    crate::registry::NodeType::of::<TriangulatorParams>("triangulator", crate::registry::Role::PerCamera, 50, |p| Ok(boxed(TriangulatorNode::new(p)?)));

use crate::convert;
use crate::tf::TfBuffer;
use std::collections::VecDeque;
use std::sync::Arc;
use xsurf_core::camera::CameraModel;
use xsurf_core::edge::LaserLine as CoreLine;
use xsurf_core::triangulate::{CameraGeometry, Profile, Triangulator, TriangulatorConfig};
use xsurf_msgs::sensor_msgs::{CameraInfo, PointCloud2};
use xsurf_msgs::std_msgs::StringMsg;
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::xsurf_msgs::{LaserLine, ScanEvent};
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{boxed, Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{NodeParams, ParamError, Params};

/// The plane `[nx, ny, nz, d]` of the parameter `name`: four values, a normal that is not zero.
pub(crate) fn laser_plane(name: &str, v: &[f64]) -> Result<[f64; 4], ParamError> {
    let plane: [f64; 4] =
        v.try_into().map_err(|_| Params::invalid(name, format!("needs 4 values [nx, ny, nz, d], got {}", v.len())))?;
    match xsurf_core::geom::Plane::from_params(plane) {
        Some(_) => Ok(plane),
        None => Err(Params::invalid(name, format!("{plane:?} has a zero or non-finite normal"))),
    }
}

struct Config {
    /// One configuration per laser (its plane), in the order of `lasers`.
    tri: Vec<TriangulatorConfig>,
    /// The lasers' names (empty without `lasers`).
    lasers: Vec<String>,
    table_frame: String,
    carm_frame: String,
    max_gap_ns: i64,
    max_pending: usize,
    max_extrapolation_ns: i64,
}

fn config(raw: &Params) -> Result<Config, ParamError> {
    let p = TriangulatorParams::from_params(raw)?;
    let plane = laser_plane("laser_plane", &p.laser_plane)?;
    let lasers = crate::lasers::from_params(raw, &p.lasers, [0.0; 3])?;
    let angle = p.min_ray_plane_angle_deg;
    if !(0.0..90.0).contains(&angle) {
        return Err(Params::invalid("min_ray_plane_angle_deg", format!("{angle:?} is not in [0, 90)")));
    }
    if !(p.min_z_m < p.max_z_m) {
        return Err(Params::invalid("max_z_m", format!("{:?} must be above min_z_m {:?}", p.max_z_m, p.min_z_m)));
    }
    let gap = p.max_pose_gap_s;
    if !(gap > 0.0 && gap < 3600.0) {
        return Err(Params::invalid("max_pose_gap_s", format!("{gap:?} is not in (0, 3600)")));
    }
    let tri = |laser_plane| TriangulatorConfig {
        laser_plane,
        min_ray_plane_angle_deg: angle,
        min_strength: p.min_strength,
        min_z_m: p.min_z_m,
        max_z_m: p.max_z_m,
    };
    Ok(Config {
        tri: match &lasers {
            None => vec![tri(plane)],
            Some(l) => l.iter().map(|l| tri(l.plane)).collect(),
        },
        lasers: lasers.map(|l| l.into_iter().map(|l| l.name).collect()).unwrap_or_default(),
        table_frame: p.table_frame,
        carm_frame: p.carm_frame,
        max_gap_ns: (gap * 1e9) as i64,
        max_pending: p.max_pending,
        max_extrapolation_ns: (p.max_extrapolation_s * 1e9) as i64,
    })
}

/// The triangulator component.
pub struct TriangulatorNode {
    cfg: Config,
    tf: TfBuffer,
    model: Option<(CameraModel, String)>,
    /// One triangulator per laser, for the camera frame and model they were built for.
    tri: Option<(Vec<Triangulator>, String, CameraModel)>,
    /// Lines waiting for their pose, each already checked and converted (a line per laser).
    pending: VecDeque<(Arc<LaserLine>, Arc<Vec<CoreLine>>)>,
    profile: Profile,
    /// One laser's profile, before it joins `profile`.
    part: Profile,
    lines: u64,
    profiles: u64,
    points: u64,
    unplaced: u64,
    outside_volume: u64,
    /// The camera (the node's namespace), for the scan reports.
    camera: String,
    /// The lines of the current scan placed and refused, for its report.
    tally: crate::tally::ScanTally,
}

/// How long C-arm poses are kept, as tf2's buffer keeps 10 s: a line older than the newest pose
/// by more than this is placed by no pose (and counted), and the memory stays flat however long
/// the node runs.
const TF_CACHE_NS: i64 = 10_000_000_000;

/// The triangulator's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `laser_line`: the camera's lines.
    Line,
    /// `camera_info`: the camera's model.
    CameraInfo,
    /// `/tf`: the C-arm's pose.
    Tf,
    /// `/tf_static`: where the camera sits on the C-arm.
    TfStatic,
    /// `/scan/events`: the scans.
    Events,
}

/// The triangulator's outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `profile`: one per line placed.
    Profile,
    /// `/scan/report`: this camera's account of each scan.
    Report,
}

type Out = Outbox<Input, Output>;

impl TriangulatorNode {
    /// Points triangulated, so far.
    pub fn points(&self) -> u64 {
        self.points
    }
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let cfg = config(p)?;
        let tf = TfBuffer::new(&cfg.table_frame, &cfg.carm_frame, cfg.max_gap_ns);
        Ok(Self {
            cfg,
            tf,
            model: None,
            tri: None,
            pending: VecDeque::new(),
            profile: Profile::default(),
            part: Profile::default(),
            lines: 0,
            profiles: 0,
            points: 0,
            unplaced: 0,
            outside_volume: 0,
            camera: String::new(),
            tally: Default::default(),
        })
    }

    /// Makes sure the triangulator for `frame` is built.
    fn ensure_triangulator(&mut self, frame: &str) -> Result<(), NodeError> {
        let (model, info_frame) = self.model.clone().ok_or_else(|| NodeError::not_ready("no camera_info received yet"))?;
        let rebuild = match &self.tri {
            Some((_, f, m)) => f != frame || *m != model,
            None => true,
        };
        if rebuild {
            let carm_from_optical = self.tf.carm_from(frame).ok_or_else(|| {
                NodeError::not_ready(format!(
                    "no tf from {} to {frame} on /tf_static (camera_info frame {info_frame})",
                    self.cfg.carm_frame
                ))
            })?;
            let t = self
                .cfg
                .tri
                .iter()
                .map(|c| Triangulator::new(CameraGeometry { model, carm_from_optical }, c))
                .collect::<Result<Vec<_>, _>>()
                .map_err(NodeError::failed)?;
            self.tri = Some((t, frame.to_string(), model));
        }
        Ok(())
    }

    /// The pose of the line at `stamp`, once it is known to be of this camera's image and the
    /// triangulator for its frame is built.
    fn place(&mut self, line: &LaserLine, stamp: i64, ahead: i64) -> Result<xsurf_core::geom::Iso3, NodeError> {
        if let Some((m, _)) = &self.model {
            if (m.width, m.height) != (line.image_width, line.image_height) {
                return Err(NodeError::contradicts(format!(
                    "the line is of a {}x{} image, camera_info says {}x{}",
                    line.image_width, line.image_height, m.width, m.height
                )));
            }
        }
        let pose = self.tf.predict_table_from_carm(stamp, ahead).map_err(NodeError::not_ready)?;
        self.ensure_triangulator(line.header.frame_id.trim_start_matches('/'))?;
        Ok(pose)
    }

    /// Places the pending lines, oldest first, while their poses are bracketed; `force` places
    /// them even if not. A line that cannot be placed is refused as itself (on `laser_line`,
    /// whatever message triggered the placing), and the others go on: one bad line costs only
    /// itself.
    fn drain(&mut self, out: &mut Out, force: bool) {
        while let Some((line, core)) = self.pending.front().cloned() {
            let stamp = line.header.stamp.nanos();
            let ahead = self.cfg.max_extrapolation_ns;
            let ready = self.model.is_some() && self.tf.latest_pose_stamp().is_some_and(|l| l >= stamp - ahead);
            if !ready && !force && self.pending.len() <= self.cfg.max_pending {
                return;
            }
            self.pending.pop_front();
            let placed = self.place(&line, stamp, ahead);
            let pose = match placed {
                Ok(p) => p,
                Err(e) => {
                    self.unplaced += 1;
                    let e = e.context(format!("line at {}", convert::fmt_stamp(stamp)));
                    self.tally.refuse(stamp, "line", &e.to_string());
                    out.refuse(Input::Line, e);
                    continue;
                }
            };
            let Some((tri, _, _)) = self.tri.as_ref() else { continue };
            join_profiles(tri, &core, &pose, &mut self.part, &mut self.profile);
            self.profiles += 1;
            self.points += self.profile.valid() as u64;
            self.outside_volume += u64::from(self.profile.outside_volume);
            let header = convert::header(stamp, &self.cfg.table_frame);
            let blocks = convert::Blocks { lasers: self.cfg.lasers.len(), layers: line.layer_count() };
            let cloud: PointCloud2 = convert::profile_cloud_blocks(&self.profile, header, blocks);
            out.publish(Output::Profile, Msg::Cloud(Arc::new(cloud)));
            self.tally.count(stamp);
        }
    }
}

/// Each laser's line intersected with its own plane, the profiles one after the other in
/// `profile` (a block of samples per laser; with second lines, every laser's first line, then
/// every laser's second, each with its laser's plane).
fn join_profiles(tri: &[Triangulator], lines: &[CoreLine], pose: &xsurf_core::geom::Iso3, part: &mut Profile, profile: &mut Profile) {
    if let ([t], [line]) = (tri, lines) {
        t.triangulate(line, pose, profile);
        return;
    }
    // Emptied, not replaced: its buffers serve every frame.
    profile.points.clear();
    profile.intensity.clear();
    profile.range.clear();
    profile.outside_volume = 0;
    let mut rgb = profile.rgb.take().unwrap_or_default();
    rgb.clear();
    let mut colour = false;
    for (t, line) in tri.iter().cycle().zip(lines) {
        t.triangulate(line, pose, part);
        profile.points.extend_from_slice(&part.points);
        profile.intensity.extend_from_slice(&part.intensity);
        profile.range.extend_from_slice(&part.range);
        profile.outside_volume += part.outside_volume;
        if let Some(c) = &part.rgb {
            rgb.extend_from_slice(c);
            colour = true;
        }
    }
    profile.rgb = colour.then_some(rgb);
}

impl Component for TriangulatorNode {
    type Input = Input;
    type Output = Output;
    fn node_name(&self) -> &'static str {
        "triangulator"
    }
    fn set_identity(&mut self, _name: &str, namespace: &str) {
        self.camera = namespace.trim_matches('/').rsplit('/').next().unwrap_or("").to_string();
    }
    fn inputs(&self) -> Vec<(Input, Port)> {
        vec![
            (Input::Line, Port::new("laser_line", LaserLine::TYPE_NAME, QosClass::Reliable)),
            (Input::CameraInfo, Port::new("camera_info", CameraInfo::TYPE_NAME, QosClass::Sensor)),
            (Input::Tf, Port::new("/tf", TFMessage::TYPE_NAME, QosClass::Reliable)),
            (Input::TfStatic, Port::new("/tf_static", TFMessage::TYPE_NAME, QosClass::Static)),
            (Input::Events, Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn outputs(&self) -> Vec<(Output, Port)> {
        vec![
            (Output::Profile, Port::new("profile", PointCloud2::TYPE_NAME, QosClass::Reliable)),
            (Output::Report, Port::new("/scan/report", StringMsg::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        self.cfg = config(p)?;
        self.tri = None;
        Ok(())
    }
    fn handle(&mut self, input: Input, msg: &Msg, out: &mut Out) -> Result<(), NodeError> {
        match (input, msg) {
            (Input::Line, Msg::LaserLine(l)) => {
                self.lines += 1;
                // Checked on arrival, so that a malformed line is refused as itself.
                let core = convert::core_lines(l).map_err(NodeError::malformed).and_then(|c| {
                    if l.lasers == self.cfg.lasers {
                        Ok(c)
                    } else {
                        Err(NodeError::contradicts(convert::LineShapeError::Lasers {
                            got: l.lasers.clone(),
                            expected: self.cfg.lasers.clone(),
                        }))
                    }
                });
                let core = core.inspect_err(|e| self.tally.refuse(l.header.stamp.nanos(), "line", &e.to_string()))?;
                self.pending.push_back((l.clone(), Arc::new(core)));
                self.drain(out, false);
                Ok(())
            }
            (Input::CameraInfo, Msg::CameraInfo(i)) => {
                let m = convert::camera_model(i).map_err(|e| NodeError::malformed(format!("camera_info: {e}")))?;
                self.model = Some((m, i.header.frame_id.clone()));
                self.drain(out, false);
                Ok(())
            }
            (Input::Tf, Msg::Tf(t)) => {
                let added = self.tf.add_dynamic(t);
                if let Some(latest) = self.tf.latest_pose_stamp() {
                    self.tf.forget_before(latest.saturating_sub(TF_CACHE_NS));
                }
                self.drain(out, false);
                added.map_err(NodeError::malformed)
            }
            (Input::TfStatic, Msg::Tf(t)) => {
                let added = self.tf.add_static(t);
                self.tri = None;
                added.map_err(NodeError::malformed)
            }
            (Input::Events, Msg::ScanEvent(e)) => {
                // At the end of a scan the lines still waiting for a pose are placed now, so the
                // mesher has them before it closes the scan.
                if e.event != ScanEvent::START {
                    self.drain(out, true);
                }
                if let Some(report) = self.tally.event(e, crate::tally::Stage::Triangulator, &self.camera) {
                    out.publish(Output::Report, report);
                }
                Ok(())
            }
            (i, m) => Err(NodeError::unexpected(i, m)),
        }
    }
    fn tick(&mut self, now_ns: i64, out: &mut Out) {
        if let Some(report) = self.tally.due(now_ns) {
            out.publish(Output::Report, report);
        }
    }
    fn finish(&mut self, out: &mut Out) {
        self.drain(out, true);
        if let Some(report) = self.tally.report() {
            out.publish(Output::Report, report);
        }
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("lines", self.lines),
            ("profiles", self.profiles),
            ("points", self.points),
            ("unplaced_lines", self.unplaced),
        ]
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use std::collections::BTreeMap;
    use xsurf_runtime::router::Router;

    fn line(stamp_s: i32, n: usize, v: usize) -> Msg {
        let mut l = LaserLine {
            image_width: 64,
            image_height: n as u32,
            orientation: LaserLine::ORIENTATION_VERTICAL,
            u: vec![10.0; n],
            v: vec![1.0; v],
            strength: vec![50.0; n],
            width: vec![3.0; n],
            ..LaserLine::default()
        };
        l.header.stamp.sec = stamp_s;
        l.header.frame_id = "cam1_optical_frame".into();
        Msg::LaserLine(Arc::new(l))
    }

    /// A malformed line is refused as itself, on arrival, under its own topic; a line that can
    /// never be placed (no tf) is refused under laser_line too, when the scan ends, and the
    /// others are not held up.
    #[test]
    fn a_bad_line_is_refused_under_its_own_topic_and_costs_only_itself() {
        let params = Params::resolve(&TriangulatorParams::declarations(), &BTreeMap::new()).unwrap();
        let mut r = Router::new();
        r.add(boxed(TriangulatorNode::new(&params).unwrap()), "triangulator", "/cam1", &[]);
        r.publish("/cam1/laser_line", &line(1, 40, 39));
        let n = &r.nodes()[0];
        assert_eq!(n.errors, 1);
        assert!(
            n.last_error.as_deref().unwrap().starts_with("/cam1/laser_line: LaserLine arrays disagree"),
            "{:?}",
            n.last_error
        );
        // Two good lines wait for their camera_info and pose; at the END of the scan they cannot
        // be placed (no /tf at all): each is refused, as a laser_line, not as the event.
        // The line of issue 24: a 0x0 image, orientation 9, 10 samples. And 10 samples for a
        // 64x40 image.
        let Msg::LaserLine(good) = line(0, 10, 10) else { unreachable!() };
        let odd = LaserLine { image_width: 0, image_height: 0, orientation: 9, ..(*good).clone() };
        r.publish("/cam1/laser_line", &Msg::LaserLine(Arc::new(odd)));
        let last = |r: &Router| r.nodes()[0].last_error.clone().unwrap();
        assert!(last(&r).contains("orientation 9"), "{}", last(&r));
        let few = LaserLine { image_height: 40, ..(*good).clone() };
        r.publish("/cam1/laser_line", &Msg::LaserLine(Arc::new(few)));
        assert!(last(&r).contains("has 10 samples; a vertical line of a 64x40 image has 40"), "{}", last(&r));
        assert_eq!(r.nodes()[0].errors, 3);
        r.publish("/cam1/laser_line", &line(2, 40, 40));
        r.publish("/cam1/laser_line", &line(3, 40, 40));
        let end = xsurf_msgs::xsurf_msgs::ScanEvent { event: ScanEvent::END, ..Default::default() };
        r.publish("/scan/events", &Msg::ScanEvent(Arc::new(end)));
        let n = &r.nodes()[0];
        assert_eq!(n.errors, 5, "{:?}", n.last_error);
        assert!(
            n.last_error.as_deref().unwrap().starts_with("/cam1/laser_line: line at 3.000000000"),
            "{:?}",
            n.last_error
        );
    }

    /// A line the camera saw of points on the laser plane is placed at those points in
    /// `table`: camera_info, the camera's placement on /tf_static and the C-arm's travel on /tf
    /// (interpolated at the image's stamp) all enter. The samples are the points projected
    /// through the rig's camera model (distortion included); placing them back undoes it.
    #[test]
    fn a_line_is_placed_where_the_camera_saw_it() {
        use xsurf_core::geom::Vec3;
        use xsurf_runtime::harness::Harness;
        let rig = xsurf_core::rig::Rig::study(64, 48);
        let cam = rig.camera("cam1").unwrap();
        let model = cam.model().unwrap();
        let carm_from_optical = cam.carm_from_optical();
        let (t0, t1, t_image) = (1_000_000_000i64, 1_100_000_000i64, 1_040_000_000i64);
        let (travel0, travel1) = (0.05, 0.057);
        let travel = travel0 + (travel1 - travel0) * 0.4;
        let table_from_carm = xsurf_core::pose::table_from_carm(travel, 0.0, 0.0);
        // A bumpy profile across the table in the laser plane (y = 0 of carm).
        let mut line = LaserLine {
            image_width: 64,
            image_height: 48,
            orientation: LaserLine::ORIENTATION_VERTICAL,
            u: vec![f32::NAN; 48],
            v: vec![f32::NAN; 48],
            strength: vec![0.0; 48],
            width: vec![0.0; 48],
            ..LaserLine::default()
        };
        let mut truth = vec![None; 48];
        for k in 0..4000 {
            let x = -0.3 + 0.6 * f64::from(k) / 4000.0;
            let p = Vec3::new(x, 0.0, 0.05 + 0.04 * (x * 12.0).sin());
            let Some((u, v)) = model.project(carm_from_optical.inverse().transform_point(p)) else { continue };
            let row = v.round();
            if !(0.0..64.0).contains(&u) || !(0.0..48.0).contains(&row) || truth[row as usize].is_some() {
                continue;
            }
            let r = row as usize;
            (line.u[r], line.v[r], line.strength[r], line.width[r]) = (u as f32, v as f32, 60.0, 3.0);
            truth[r] = Some(table_from_carm.transform_point(p));
        }
        let seen = truth.iter().flatten().count();
        assert!(seen > 30, "the profile crosses the image: {seen} rows");
        line.header = convert::header(t_image, "cam1_optical_frame");

        let params = Params::resolve(&TriangulatorParams::declarations(), &BTreeMap::new()).unwrap();
        let mut h = Harness::new(boxed(TriangulatorNode::new(&params).unwrap()), "triangulator", "/cam1");
        let info = convert::camera_info(&model, convert::header(t_image, "cam1_optical_frame"));
        let pose = |t, travel| {
            let e = xsurf_core::pose::table_from_carm(travel, 0.0, 0.0);
            Msg::Tf(Arc::new(TFMessage { transforms: vec![convert::transform_stamped(t, "table", "carm", &e)] }))
        };
        let statics = TFMessage {
            transforms: vec![convert::transform_stamped(0, "carm", "cam1_optical_frame", &carm_from_optical)],
        };
        h.feed("/cam1/camera_info", &Msg::CameraInfo(Arc::new(info)))
            .feed("/tf_static", &Msg::Tf(Arc::new(statics)))
            .feed("/tf", &pose(t0, travel0))
            .feed("/cam1/laser_line", &Msg::LaserLine(Arc::new(line)));
        assert!(h.take("/cam1/profile").is_empty(), "the line waits for a pose after its stamp");
        h.feed("/tf", &pose(t1, travel1));
        let out = h.take("/cam1/profile");
        assert_eq!((out.len(), h.errors()), (1, 0), "{:?}", h.last_error());
        let Msg::Cloud(cloud) = &out[0] else { panic!("a profile is a PointCloud2") };
        assert_eq!(cloud.header.frame_id, "table");
        let profile = convert::cloud_profile(cloud).unwrap();
        assert_eq!(profile.valid(), seen);
        for (p, t) in profile.points.iter().zip(&truth) {
            match t {
                Some(t) => {
                    let d = Vec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])) - *t;
                    assert!(d.norm() < 2e-5, "{p:?} against {t:?}: {:.3} mm", d.norm() * 1e3);
                }
                None => assert!(p[0].is_nan()),
            }
        }
        assert_eq!(h.counter("points"), Some(seen as u64));
    }

    /// Two lasers, each with a second surface's line: one line message with a block per laser
    /// and layer (layer-major); each block is intersected with its laser's plane (the
    /// collimator's y = 0 and a plane tilted 25 degrees), the profile stacks them with the
    /// fields `laser` and `layer`, and a line of other lasers than the node's is refused.
    #[test]
    fn each_laser_block_is_placed_on_its_own_plane() {
        use xsurf_core::geom::Vec3;
        use xsurf_runtime::harness::Harness;
        use xsurf_runtime::params::ParamValue as V;
        let rig = xsurf_core::rig::Rig::three_lasers(64, 48);
        let cam = rig.camera("cam2").unwrap();
        let (model, carm_from_optical) = (cam.model().unwrap(), cam.carm_from_optical());
        let lasers = [&rig.lasers[0], &rig.lasers[2]];
        let n = 48;
        let mut line = LaserLine {
            image_width: 64,
            image_height: 48,
            orientation: LaserLine::ORIENTATION_VERTICAL,
            lasers: lasers.iter().map(|l| l.name.clone()).collect(),
            layers: 2,
            ..LaserLine::default()
        };
        let mut truth = Vec::new();
        // The first lines on a wavy surface, the second ones on a flat table below it.
        for (layer, l) in [(0, lasers[0]), (0, lasers[1]), (1, lasers[0]), (1, lasers[1])] {
            let [_, ny, nz, d] = l.plane;
            let mut block = vec![None; n];
            let (mut u, mut v) = (vec![f32::NAN; n], vec![f32::NAN; n]);
            for k in 0..4000 {
                let x = -0.3 + 0.6 * f64::from(k) / 4000.0;
                let z = if layer == 0 { 0.04 + 0.02 * (x * 9.0).cos() } else { 0.01 };
                let p = Vec3::new(x, (d - nz * z) / ny, z);
                let Some((pu, pv)) = model.project(carm_from_optical.inverse().transform_point(p)) else { continue };
                let row = pv.round();
                if !(0.0..64.0).contains(&pu) || !(0.0..48.0).contains(&row) || block[row as usize].is_some() {
                    continue;
                }
                (u[row as usize], v[row as usize]) = (pu as f32, pv as f32);
                block[row as usize] = Some(p);
            }
            assert!(block.iter().flatten().count() > 20, "{} crosses the image", l.name);
            line.strength.extend(u.iter().map(|u| if u.is_finite() { 60.0 } else { 0.0 }));
            line.width.extend(u.iter().map(|u| if u.is_finite() { 3.0 } else { 0.0 }));
            line.u.extend(u);
            line.v.extend(v);
            truth.extend(block);
        }
        line.header = convert::header(1_040_000_000, "cam2_optical_frame");
        let mut o: BTreeMap<String, V> = BTreeMap::new();
        o.insert("lasers".into(), V::StringArray(line.lasers.clone()));
        for l in lasers {
            o.insert(format!("laser.{}.plane", l.name), V::DoubleArray(l.plane.to_vec()));
            o.insert(format!("laser.{}.channel", l.name), V::String(l.channel.name().into()));
        }
        let params = Params::resolve(&TriangulatorParams::declarations(), &o).unwrap();
        let mut h = Harness::new(boxed(TriangulatorNode::new(&params).unwrap()), "triangulator", "/cam2");
        let pose = |t| {
            let e = xsurf_core::pose::table_from_carm(0.0, 0.0, 0.0);
            Msg::Tf(Arc::new(TFMessage { transforms: vec![convert::transform_stamped(t, "table", "carm", &e)] }))
        };
        let statics = TFMessage {
            transforms: vec![convert::transform_stamped(0, "carm", "cam2_optical_frame", &carm_from_optical)],
        };
        let info = convert::camera_info(&model, line.header.clone());
        let other = LaserLine { lasers: vec!["collimator".into(), "left".into()], ..line.clone() };
        h.feed("/cam2/camera_info", &Msg::CameraInfo(Arc::new(info)))
            .feed("/tf_static", &Msg::Tf(Arc::new(statics)))
            .feed("/tf", &pose(1_000_000_000))
            .feed("/tf", &pose(1_100_000_000))
            .feed("/cam2/laser_line", &Msg::LaserLine(Arc::new(line)))
            .feed("/cam2/laser_line", &Msg::LaserLine(Arc::new(other)));
        assert_eq!(h.errors(), 1);
        assert!(h.last_error().unwrap().contains("this node's lasers"), "{:?}", h.last_error());
        let out = h.take("/cam2/profile");
        let Msg::Cloud(cloud) = &out[0] else { panic!("a profile is a PointCloud2") };
        assert_eq!((cloud.height, cloud.width), (4 * 48, 1));
        let points = xsurf_msgs::pointcloud::read(cloud).unwrap();
        for (r, (p, t)) in points.iter().zip(&truth).enumerate() {
            assert_eq!((p.laser, p.layer), (Some((r / n % 2) as f32), Some((r / n / 2) as f32)));
            match t {
                Some(t) => {
                    let d = Vec3::new(f64::from(p.xyz[0]), f64::from(p.xyz[1]), f64::from(p.xyz[2])) - *t;
                    assert!(d.norm() < 2e-5, "row {r}: {:?} against {t:?}", p.xyz);
                }
                None => assert!(p.xyz[0].is_nan(), "row {r}"),
            }
        }
    }
}
