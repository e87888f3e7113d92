//! `mesher`: `profile` -> the organized grid of the scan (`cloud`, published while the scan
//! runs) and its mesh (`mesh`, at END), plus `<output_dir>/scan_<id>/<cam>.ply`. While the scan
//! runs, `mesh` also carries the growing surface at `mesh_rate_hz`: each part holds only the
//! triangles of the frames since the last part (`core::mesh::mesh_grid_frames`), as a marker
//! of its own in namespace `<cam>_growing` that a viewer keeps; at END a DELETEALL clears them
//! and the scan's cleaned, smoothed mesh follows. At END the report and the final cloud go
//! first; the mesh, its markers and the PLY file are made on a thread of their own and
//! published at the next tick after they are done (offline, at [`Component::settle`], so that
//! the merge runs beside them).
//!
//! Scans are bounded by `/scan/events` from whoever publishes them: frames outside START..END
//! belong to no scan (counted; a frame stamped before START that arrives after it as well). A
//! source without events (a bag of one scan) gives scan 0, from the first frame with points.
//! Gaps in the frame stamps are counted as dropped frames, logged, and kept as
//! empty grid columns so the mesh does not bridge them (a single missing frame is filled).

mod params;
pub use params::*;

/// The node type, as the registry lists it.
pub const NODE: crate::registry::NodeType =
    crate::registry::NodeType::of::<MesherParams>("mesher", crate::registry::Role::PerCamera, 50, |p| Ok(boxed(MesherNode::new(p)?)));

use crate::convert;
use crate::scan_report::{FinalCloud, Gap, MesherReport};
use std::path::PathBuf;
use std::sync::Arc;
use xsurf_core::edge::Orientation;
use xsurf_core::mesh::{mesh_grid, Grid, Mesh, MeshConfig};
use xsurf_core::triangulate::Profile;
use xsurf_msgs::sensor_msgs::{CameraInfo, PointCloud2};
use xsurf_msgs::std_msgs::StringMsg;
use xsurf_msgs::visualization_msgs::Marker;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{boxed, Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{NodeParams, ParamError, Params};

struct Config {
    mesh: MeshConfig,
    cloud_period_ns: Option<i64>,
    republish_ns: Option<i64>,
    /// The growing surface's period (`mesh_rate_hz`).
    mesh_period_ns: Option<i64>,
    /// Its samples' stride (`mesh_preview_stride`).
    preview_stride: usize,
    output_dir: Option<PathBuf>,
    camera: String,
    frame_id: String,
    gap_factor: f64,
    end_grace_ns: i64,
    orientation: Orientation,
    /// The lasers (`lasers`), each a block of every profile's samples (empty: one laser, and
    /// no `laser` field in the cloud); their names are their meshes' namespaces.
    laser_names: Vec<String>,
}

fn config(raw: &Params) -> Result<Config, ParamError> {
    let p = MesherParams::from_params(raw)?;
    // Checked as every node checks them, though only their number shapes the grid.
    crate::lasers::from_params(raw, &p.lasers, [0.0; 3])?;
    let mesh = MeshConfig {
        max_edge_m: p.max_edge_m,
        max_edge_per_m: p.max_edge_per_m,
        min_angle_deg: p.min_angle_deg,
        fill_single_holes: p.fill_single_holes,
        outlier_tolerance_m: p.outlier_tolerance_m,
        partial_sheet_ratio: p.partial_sheet_ratio,
        smooth_iterations: p.smooth_iterations,
        smooth_lambda: p.smooth_lambda,
    };
    mesh.validate().map_err(|e| Params::invalid("mesher", e))?;
    if !(p.gap_factor > 1.0) {
        return Err(Params::invalid("gap_factor", format!("{:?} must be > 1", p.gap_factor)));
    }
    let seconds = |s: f64| (s > 0.0).then_some((s * 1e9) as i64);
    Ok(Config {
        mesh,
        cloud_period_ns: (p.cloud_rate_hz > 0.0).then(|| (1e9 / p.cloud_rate_hz) as i64),
        mesh_period_ns: (p.mesh_rate_hz > 0.0).then(|| (1e9 / p.mesh_rate_hz) as i64),
        preview_stride: p.mesh_preview_stride as usize,
        republish_ns: seconds(p.mesh_republish_s),
        output_dir: p.output_dir,
        camera: p.camera,
        frame_id: p.frame_id,
        gap_factor: p.gap_factor,
        end_grace_ns: (p.end_grace_s * 1e9) as i64,
        orientation: p.line_orientation,
        laser_names: p.lasers,
    })
}

impl Config {
    /// The number of lasers (0: `lasers` unset).
    fn lasers(&self) -> usize {
        self.laser_names.len()
    }
}

/// Frame-gap detection from image stamps.
#[derive(Debug, Default, Clone)]
struct GapDetector {
    last_ns: Option<i64>,
    recent: Vec<i64>,
}

impl GapDetector {
    /// The frame period: the median of the recent intervals, once there are three.
    fn nominal_ns(&self) -> Option<i64> {
        (self.recent.len() >= 3).then(|| {
            let mut v = self.recent.clone();
            v.sort_unstable();
            v[v.len() / 2]
        })
    }

    /// Frames missing before a frame at `stamp_ns`.
    fn missing(&mut self, stamp_ns: i64, factor: f64) -> u32 {
        let Some(last) = self.last_ns.replace(stamp_ns) else { return 0 };
        let dt = stamp_ns - last;
        if dt <= 0 {
            return 0;
        }
        match self.nominal_ns() {
            Some(n) if dt as f64 > factor * n as f64 => {
                ((dt as f64 / n as f64).round() as u32).saturating_sub(1).max(1)
            }
            _ => {
                self.recent.push(dt);
                if self.recent.len() > 31 {
                    self.recent.remove(0);
                }
                0
            }
        }
    }
}

/// One scan's frames as the mesher saw them, for its report on `/scan/report`.
#[derive(Debug, Default, Clone)]
struct ScanAccount {
    /// The START event's stamp (none for a scan without events).
    start_ns: Option<i64>,
    first_ns: Option<i64>,
    last_ns: Option<i64>,
    /// The stamps of the frames received.
    received: Vec<i64>,
    without_line: u64,
    refused: u64,
    /// Points of the finished grid rejected before meshing: those their neighbours contradict
    /// and those the laser sheet only partly reached.
    points_rejected: u64,
    /// Of `points_rejected`, those the laser sheet only partly reached.
    points_partial_sheet: u64,
    /// `(stamp before, stamp after, frames missing between)`.
    gaps: Vec<(i64, i64, u32)>,
    /// The final cloud's stamp and points, once the scan is closed.
    final_cloud: Option<(i64, usize)>,
}

impl ScanAccount {
    /// The report of a scan that ended at `end_ns` (its END or ABORT), with `period_ns` the
    /// frame period. Frames are counted as lost between two frames whose stamps are further
    /// apart than the period allows (the gaps). Before the first frame and after the last, the
    /// stamps cannot tell a lost frame from a camera not yet (or no longer) exposing, so the
    /// margins to START and END are given in seconds and not counted.
    fn report(&self, scan_id: u32, camera: &str, aborted: bool, end_ns: Option<i64>, period_ns: Option<i64>) -> String {
        let lost: u64 = self.gaps.iter().map(|g| u64::from(g.2)).sum();
        // A frame stamped after END that arrived before the END event did is in the grid (it
        // is of the object) but not of the scan's count, as the other nodes count.
        let received = self.received.iter().filter(|&&t| end_ns.is_none_or(|e| t < e)).count() as u64;
        let margin = |a: Option<i64>, b: Option<i64>| a.zip(b).map(|(a, b)| (b - a) as f64 * 1e-9);
        let t = |ns: Option<i64>| ns.map(convert::fmt_stamp);
        let report = MesherReport {
            aborted,
            camera: camera.to_string(),
            end: t(end_ns),
            final_cloud: self
                .final_cloud
                .map(|(stamp, points)| FinalCloud { points: points as u64, stamp: convert::fmt_stamp(stamp) }),
            first_frame: t(self.first_ns),
            first_frame_after_start_s: margin(self.start_ns, self.first_ns),
            frame_period_s: period_ns.map(|p| p as f64 * 1e-9),
            frames_expected: received + lost,
            frames_lost: lost,
            frames_received: received,
            frames_without_line: self.without_line,
            gaps: self
                .gaps
                .iter()
                .map(|g| Gap { after: convert::fmt_stamp(g.0), before: convert::fmt_stamp(g.1), frames: g.2 })
                .collect(),
            last_frame: t(self.last_ns),
            last_frame_before_end_s: margin(self.last_ns, end_ns),
            node: "mesher".into(),
            points_partial_sheet: self.points_partial_sheet,
            points_rejected: self.points_rejected,
            profiles_refused: self.refused,
            scan_id,
            start: t(self.start_ns),
        };
        serde_json::to_string(&report).unwrap_or_default()
    }
}

/// The mesher component.
pub struct MesherNode {
    cfg: Config,
    camera: String,
    scan_id: u32,
    active: bool,
    /// END or ABORT seen, the scan not yet closed: `(aborted, end stamp)`; closed at the end
    /// stamp plus `end_grace_s`, or by the first profile stamped after it.
    closing: Option<(bool, i64)>,
    /// The last profiles that arrived between scans, `(stamp, profile, lines per laser)`.
    early: std::collections::VecDeque<(i64, Profile, usize)>,
    /// Once a scan event has been seen, scans are bounded by events only.
    events_seen: bool,
    grid: Grid,
    /// Lines per laser in the grid's frames (2: second surfaces' lines, the profiles' field
    /// `layer`), fixed by the scan's first profile.
    layers: usize,
    gaps: GapDetector,
    last_cloud_ns: i64,
    /// The last scan's mesh marker, published again between scans.
    last_mesh: crate::republish::Republisher<Output>,
    scans: u64,
    frames: u64,
    dropped_frames: u64,
    triangles: u64,
    /// Vertices of the meshes written (the points the surface uses).
    mesh_points: u64,
    files_written: u64,
    outside_scan: u64,
    /// Samples per frame by the camera (camera_info and the line orientation), once known.
    samples: Option<usize>,
    /// Profiles refused for a size the camera does not give.
    bad_profiles: u64,
    /// Points rejected before meshing (contradicted, or the sheet only partly reached them),
    /// over all scans.
    points_rejected: u64,
    /// Of `points_rejected`, those the sheet only partly reached, over all scans.
    points_partial_sheet: u64,
    /// The scan's frames, for its report.
    account: ScanAccount,
    /// The growing surface: the first frame whose cells are not yet published, the parts
    /// published in this scan, and the stamp of the last one.
    growing: Growing,
    /// The last closed scan, while its mesh is made on a thread of its own.
    meshing: Option<(ScanMeta, xsurf_core::par::Background<MeshMade>)>,
}

/// The growing surface of a scan (`mesh_rate_hz`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Growing {
    from_frame: usize,
    parts: u32,
    last_ns: i64,
}

impl Default for Growing {
    fn default() -> Self {
        Growing { from_frame: 0, parts: 0, last_ns: i64::MIN }
    }
}

/// Profiles kept between scans for a START event that arrives after them.
const EARLY_FRAMES: usize = 8;

/// The mesher's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `profile`: the camera's profiles, one per frame.
    Profile,
    /// `/scan/events`: the scans.
    Events,
    /// `camera_info`: the samples per frame of the grid.
    CameraInfo,
}

/// The mesher's outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `cloud`: the scan's organized grid, growing while it runs.
    Cloud,
    /// `mesh`: the growing surface's parts while the scan runs; a DELETEALL and the scan's mesh
    /// at its end.
    Mesh,
    /// `/scan/report`: this camera's account of each scan.
    Report,
}

type Out = Outbox<Input, Output>;
/// How often a node whose closed scan's mesh is being made looks whether it is done.
const MESH_POLL_NS: i64 = 2_000_000;

/// Longest run of empty columns inserted for a stamp gap.
const MAX_GAP_COLUMNS: u32 = 300;

impl MesherNode {
    /// Triangles of the scans' meshes, so far.
    pub fn triangles(&self) -> u64 {
        self.triangles
    }
    /// Points of the scans' meshes, so far.
    pub fn mesh_points(&self) -> u64 {
        self.mesh_points
    }
    /// Frames missing from the stamps, so far.
    pub fn dropped_frames(&self) -> u64 {
        self.dropped_frames
    }
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let cfg = config(p)?;
        Ok(Self {
            camera: cfg.camera.clone(),
            cfg,
            scan_id: 0,
            active: false,
            closing: None,
            early: Default::default(),
            events_seen: false,
            grid: Grid::default(),
            layers: 1,
            gaps: GapDetector::default(),
            last_cloud_ns: i64::MIN,
            last_mesh: crate::republish::Republisher::default(),
            scans: 0,
            frames: 0,
            dropped_frames: 0,
            triangles: 0,
            mesh_points: 0,
            files_written: 0,
            outside_scan: 0,
            samples: None,
            bad_profiles: 0,
            points_rejected: 0,
            points_partial_sheet: 0,
            account: ScanAccount::default(),
            growing: Growing::default(),
            meshing: None,
        })
    }

    fn start(&mut self, scan_id: u32, start_ns: Option<i64>) {
        self.account = ScanAccount { start_ns, ..ScanAccount::default() };
        self.scan_id = scan_id;
        self.active = true;
        self.grid = Grid::default();
        self.gaps = GapDetector::default();
        self.last_cloud_ns = i64::MIN;
        self.growing = Growing::default();
    }

    /// The growing surface's next part: the cells of the frames since the last part, a marker
    /// of its own in namespace `<camera>_growing`.
    fn publish_part(&mut self, stamp: i64, out: &mut Out) {
        let frames = self.grid.frames();
        if frames < self.growing.from_frame + 2 {
            return;
        }
        // Only the new frames (and the last one before them), every stride-th sample, each
        // laser's grid apart.
        let new = self.grid.part(self.growing.from_frame..frames, 1);
        let mut part = Mesh::default();
        for block in new.blocks(self.blocks().count()) {
            let sub = block.part(0..block.frames(), self.cfg.preview_stride);
            part.append(&xsurf_core::mesh::mesh_grid_frames(&sub, &self.cfg.mesh, 0..sub.frames()));
        }
        self.growing.from_frame = frames - 1;
        self.growing.last_ns = stamp;
        if part.triangles.is_empty() {
            return;
        }
        let header = convert::header(stamp, &self.cfg.frame_id);
        let ns = format!("{}_growing", self.camera);
        let id = self.growing.parts as i32;
        self.growing.parts += 1;
        out.publish(Output::Mesh, Msg::Marker(Arc::new(convert::mesh_marker(&part, header, &ns, id, 1.0))));
    }

    /// The blocks of the grid's frames: a block per laser and line.
    fn blocks(&self) -> convert::Blocks {
        convert::Blocks { lasers: self.cfg.lasers(), layers: self.layers }
    }

    /// A profile of `layers` lines per laser into the scan's grid.
    fn push(&mut self, stamp: i64, p: &Profile, layers: usize) -> Result<(), NodeError> {
        // The grid's size comes from the camera, not from whichever profile arrives first.
        if let Some(n) = self.samples.map(|n| n * layers).filter(|&n| n != p.points.len()) {
            self.bad_profiles += 1;
            self.account.refused += 1;
            return Err(NodeError::contradicts(format!(
                "profile has {} samples; the camera (camera_info, {} line, {} laser(s), {layers} line(s) each) gives {n}",
                p.points.len(),
                self.cfg.orientation.name(),
                self.cfg.lasers().max(1)
            )));
        }
        if self.grid.frames() == 0 {
            self.grid = Grid::new(p.points.len());
            self.layers = layers;
        } else if layers != self.layers {
            self.bad_profiles += 1;
            self.account.refused += 1;
            return Err(NodeError::contradicts(format!(
                "profile has {layers} line(s) per laser (its field layer); this scan's grid has {}",
                self.layers
            )));
        }
        let before = self.gaps.last_ns;
        let missing = self.gaps.missing(stamp, self.cfg.gap_factor);
        if let Some(b) = before.filter(|_| missing > 0) {
            self.account.gaps.push((b, stamp, missing));
            self.dropped_frames += u64::from(missing);
            log::warn!("{}: {missing} frame(s) missing before {} (stamp gap)", self.camera, convert::fmt_stamp(stamp));
            let empty = Profile {
                points: vec![[f32::NAN; 3]; p.points.len()],
                intensity: vec![0.0; p.points.len()],
                rgb: None,
                range: vec![f32::NAN; p.points.len()],
                outside_volume: 0,
            };
            for _ in 0..missing.min(MAX_GAP_COLUMNS) {
                let _ = self.grid.push(stamp, &empty);
            }
        }
        self.grid.push(stamp, p).map_err(|n| {
            NodeError::contradicts(format!("profile has {n} samples, this scan's grid has {}", self.grid.samples()))
        })?;
        self.frames += 1;
        let a = &mut self.account;
        a.received.push(stamp);
        a.without_line += u64::from(p.valid() == 0);
        a.first_ns = Some(a.first_ns.map_or(stamp, |f| f.min(stamp)));
        a.last_ns = Some(a.last_ns.map_or(stamp, |l| l.max(stamp)));
        Ok(())
    }

    /// Closes the scan whose END or ABORT has been seen, if any.
    fn close_pending(&mut self, out: &mut Out) {
        if let Some((aborted, end)) = self.closing.take() {
            self.close(aborted, Some(end), out);
        }
    }

    fn close(&mut self, aborted: bool, end_ns: Option<i64>, out: &mut Out) {
        self.closing = None;
        if !self.active {
            return;
        }
        self.mesh_done(true, out);
        // One grid per laser and line, cleaned and meshed apart; the cloud stacks them again.
        let layout = self.blocks();
        let mut blocks = self.grid.blocks(layout.count());
        let (rejected, partial) = blocks.iter_mut().map(|b| b.clean(&self.cfg.mesh)).fold((0, 0), |(r, p), c| {
            (r + c.rejected as u64, p + c.partial_sheet as u64)
        });
        (self.account.points_rejected, self.account.points_partial_sheet) = (rejected, partial);
        self.points_rejected += rejected;
        self.points_partial_sheet += partial;
        let stamp = self.grid.stamps_ns().last().copied().unwrap_or(0);
        self.account.final_cloud = Some((stamp, blocks.iter().map(Grid::valid).sum()));
        let report = self.account.report(self.scan_id, &self.camera, aborted, end_ns, self.gaps.nominal_ns());
        out.publish(Output::Report, Msg::Text(Arc::new(StringMsg { data: report })));
        self.active = false;
        self.scans += 1;
        // The final cloud first (the merger waits for it); the mesh, its markers and the PLY
        // file follow from a thread of their own, published by the first tick after they are
        // made (see `mesh_done`).
        let grid = Grid::stacked(blocks.clone());
        let header = convert::header(stamp, &self.cfg.frame_id);
        out.publish(Output::Cloud, Msg::Cloud(Arc::new(convert::grid_cloud_blocks(&grid, header.clone(), layout))));
        let scan = ScanMeta {
            scan_id: self.scan_id,
            aborted,
            frames: grid.frames(),
            points: grid.valid(),
            clear_growing: std::mem::take(&mut self.growing).parts > 0,
        };
        let job = MeshJob {
            blocks,
            mesh: self.cfg.mesh,
            camera: self.camera.clone(),
            laser_names: self.cfg.laser_names.clone(),
            header,
            file: (scan.points > 0).then(|| self.cfg.output_dir.clone()).flatten().map(|dir| {
                let dir = dir.join(format!("scan_{}{}", scan.scan_id, if aborted { "_aborted" } else { "" }));
                dir.join(format!("{}.ply", if self.camera.is_empty() { "camera" } else { &self.camera }))
            }),
            id: scan.scan_id as i32,
            markers: out.heard(Output::Mesh),
        };
        let meshing = xsurf_core::par::background(format!("{}-mesh", self.camera), move || {
            // Below the merger, which waits for the cloud that has gone, not for this.
            xsurf_runtime::threads::lower_this_thread_to(xsurf_runtime::threads::BACKGROUND_NICE);
            job.run()
        });
        self.meshing = Some((scan, meshing));
        self.mesh_done(false, out);
    }

    /// Publishes the closed scan's mesh once it is made (with `wait`, waits for it): the
    /// DELETEALL of its growing parts, its markers; counts it and logs the scan.
    fn mesh_done(&mut self, wait: bool, out: &mut Out) {
        let Some((scan, meshing)) = self.meshing.take() else { return };
        if !wait && !meshing.is_finished() {
            self.meshing = Some((scan, meshing));
            return;
        }
        let made = meshing.join();
        let Some(made) = made else {
            log::error!("{}: scan {}: the mesh's thread failed; no mesh", self.camera, scan.scan_id);
            return;
        };
        if scan.clear_growing {
            // The growing parts go; the scan's mesh takes their place.
            let clear = Marker { header: made.header.clone(), action: Marker::DELETEALL, ..Default::default() };
            out.publish(Output::Mesh, Msg::Marker(Arc::new(clear)));
        }
        for (port, m) in &made.markers {
            out.publish(*port, m.clone());
        }
        self.last_mesh.set(made.markers);
        self.triangles += made.triangles as u64;
        self.mesh_points += made.vertices as u64;
        if scan.points == 0 {
            log::warn!("{}: scan {} has no points; nothing written", self.camera, scan.scan_id);
            return;
        }
        match made.file {
            Some(Ok(())) => self.files_written += 1,
            Some(Err(e)) => log::error!("{}: {e}", self.camera),
            None => {}
        }
        log::info!(
            "{}: scan {} {}: {} frames, {} points in the grid, {} in the surface ({} triangles)",
            self.camera,
            scan.scan_id,
            if scan.aborted { "aborted" } else { "ended" },
            scan.frames,
            scan.points,
            made.vertices,
            made.triangles
        );
    }
}

/// A closed scan, while its mesh is being made.
struct ScanMeta {
    scan_id: u32,
    aborted: bool,
    frames: usize,
    /// Points in its final grid.
    points: usize,
    /// It published growing parts, which its mesh replaces.
    clear_growing: bool,
}

/// What a closed scan's mesh needs: its cleaned grids (one per laser and line, layer-major),
/// and where it goes.
struct MeshJob {
    blocks: Vec<Grid>,
    mesh: MeshConfig,
    camera: String,
    laser_names: Vec<String>,
    header: xsurf_msgs::std_msgs::Header,
    /// The PLY file to write (`None`: no output folder, or no points).
    file: Option<PathBuf>,
    id: i32,
    /// Markers are made (something takes them).
    markers: bool,
}

/// A closed scan's mesh, made: its markers, its size, and the PLY file written (or why not).
struct MeshMade {
    header: xsurf_msgs::std_msgs::Header,
    markers: Vec<(Output, Msg)>,
    triangles: usize,
    vertices: usize,
    file: Option<Result<(), String>>,
}

impl MeshJob {
    /// Meshes each laser's grid; one marker for the camera, or with lasers one per laser in
    /// namespace `<camera>.<laser>`; writes the camera's PLY file (all lasers).
    fn run(self) -> MeshMade {
        let meshes: Vec<Mesh> = self.blocks.iter().map(|b| mesh_grid(b, &self.mesh)).collect();
        // A laser's mesh holds its lines' (the blocks are layer-major: block `j` is laser
        // `j % lasers`'s).
        let lasers = self.laser_names.len().max(1);
        let mut per_laser = vec![Mesh::default(); lasers];
        for (j, m) in meshes.iter().enumerate() {
            per_laser[j % lasers].append(m);
        }
        let (mesh, per_laser) = if self.laser_names.is_empty() {
            (per_laser.pop().unwrap_or_default(), Vec::new())
        } else {
            let all = per_laser.iter().fold(Mesh::default(), |mut m, b| {
                m.append(b);
                m
            });
            (all, per_laser)
        };
        let header = self.header;
        let markers: Vec<(Output, Msg)> = if !self.markers {
            Vec::new()
        } else if per_laser.is_empty() {
            vec![(Output::Mesh, Msg::Marker(Arc::new(convert::mesh_marker(&mesh, header.clone(), &self.camera, self.id, 1.0))))]
        } else {
            per_laser
                .iter()
                .zip(&self.laser_names)
                .map(|(m, l)| {
                    let ns = format!("{}.{l}", self.camera);
                    (Output::Mesh, Msg::Marker(Arc::new(convert::mesh_marker(m, header.clone(), &ns, self.id, 1.0))))
                })
                .collect()
        };
        let file = self.file.map(|path| {
            let dir = path.parent().map(std::path::Path::to_path_buf).unwrap_or_default();
            std::fs::create_dir_all(&dir)
                .map_err(|e| e.to_string())
                .and_then(|_| xsurf_formats::ply::write_file(&path, &mesh).map_err(|e| e.to_string()))
                .map_err(|e| format!("cannot write {}: {e}", path.display()))
        });
        MeshMade { header, markers, triangles: mesh.triangles.len(), vertices: mesh.positions.len(), file }
    }
}

impl MesherNode {
    /// A profile: into the scan's grid if it was exposed in the scan; the growing cloud at its rate.
    fn profile(&mut self, c: &PointCloud2, out: &mut Out) -> Result<(), NodeError> {
        let p = convert::cloud_profile(c).map_err(|e| NodeError::malformed(format!("profile: {e}")))?;
        let layers = convert::cloud_layers(c);
        if !self.active {
            // Outside a scan bounded by events, frames belong to no scan; the last few
            // are kept, since a frame stamped after START may arrive before the START
            // event. Without any event (a bag of one scan), the first frame with
            // points starts scan 0.
            if self.events_seen {
                self.early.push_back((c.header.stamp.nanos(), p, layers));
                if self.early.len() > EARLY_FRAMES {
                    self.early.pop_front();
                    self.outside_scan += 1;
                }
                return Ok(());
            }
            if p.valid() == 0 {
                self.outside_scan += 1;
                return Ok(());
            }
            self.start(0, None);
        }
        let stamp = c.header.stamp.nanos();
        // A frame exposed after END: the scan it would close is complete.
        if self.closing.is_some_and(|(_, end)| stamp >= end) {
            self.close_pending(out);
            self.outside_scan += 1;
            return Ok(());
        }
        // A frame exposed before START that arrives after it (the pipeline's latency)
        // is not part of the scan either: scans are bounded by stamps, not arrivals.
        if self.account.start_ns.is_some_and(|s| stamp < s) {
            self.outside_scan += 1;
            return Ok(());
        }
        self.push(stamp, &p, layers)?;
        if let Some(period) = self.cfg.cloud_period_ns {
            if stamp.saturating_sub(self.last_cloud_ns) >= period {
                self.last_cloud_ns = stamp;
                let h = convert::header(stamp, &self.cfg.frame_id);
                out.publish(Output::Cloud, Msg::Cloud(Arc::new(convert::grid_cloud_blocks(&self.grid, h, self.blocks()))));
            }
        }
        if self.cfg.mesh_period_ns.is_some_and(|period| stamp.saturating_sub(self.growing.last_ns) >= period) {
            self.publish_part(stamp, out);
        }
        Ok(())
    }

    /// START, END or ABORT of a scan.
    fn event(&mut self, e: &ScanEvent, out: &mut Out) -> Result<(), NodeError> {
        self.events_seen = true;
        match e.event {
            ScanEvent::START => {
                self.close_pending(out);
                self.close(false, None, out);
                // The last scan's mesh goes out before this scan's first part.
                self.mesh_done(true, out);
                self.last_mesh.clear();
                let start = e.header.stamp.nanos();
                self.start(e.scan_id, Some(start));
                for (stamp, p, layers) in std::mem::take(&mut self.early) {
                    if stamp < start {
                        self.outside_scan += 1;
                    } else if let Err(e) = self.push(stamp, &p, layers) {
                        log::warn!("{}: profile at {}: {e}", self.camera, convert::fmt_stamp(stamp));
                    }
                }
            }
            ScanEvent::END | ScanEvent::ABORT if self.active && self.closing.is_none() => {
                let aborted = e.event == ScanEvent::ABORT;
                self.closing = Some((aborted, e.header.stamp.nanos()));
                if self.cfg.end_grace_ns == 0 {
                    self.close_pending(out);
                }
            }
            ScanEvent::END | ScanEvent::ABORT => {}
            other => return Err(NodeError::malformed(format!("unknown scan event {other}"))),
        }
        Ok(())
    }

    /// The camera's image size: the samples per frame of its grid.
    fn camera_info(&mut self, i: &CameraInfo) -> Result<(), NodeError> {
        let n = match self.cfg.orientation {
            Orientation::Vertical => i.height,
            Orientation::Horizontal => i.width,
        };
        if !xsurf_core::limits::image_side_ok(i.width) || !xsurf_core::limits::image_side_ok(i.height) {
            return Err(NodeError::malformed(format!(
                "camera_info size {}x{} is outside {} pixels a side",
                i.width,
                i.height,
                xsurf_core::limits::image_side_text()
            )));
        }
        self.samples = Some(n as usize * self.cfg.lasers().max(1));
        Ok(())
    }
}

impl Component for MesherNode {
    type Input = Input;
    type Output = Output;
    fn node_name(&self) -> &'static str {
        "mesher"
    }
    fn set_identity(&mut self, _name: &str, namespace: &str) {
        if self.cfg.camera.is_empty() {
            self.camera = namespace.trim_matches('/').rsplit('/').next().unwrap_or("").to_string();
        }
    }
    fn inputs(&self) -> Vec<(Input, Port)> {
        vec![
            (Input::Profile, Port::new("profile", PointCloud2::TYPE_NAME, QosClass::Reliable)),
            (Input::Events, Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable)),
            (Input::CameraInfo, Port::new("camera_info", CameraInfo::TYPE_NAME, QosClass::Sensor)),
        ]
    }
    fn outputs(&self) -> Vec<(Output, Port)> {
        vec![
            (Output::Cloud, Port::new("cloud", PointCloud2::TYPE_NAME, QosClass::State)),
            (Output::Mesh, Port::new("mesh", Marker::TYPE_NAME, QosClass::State)),
            (Output::Report, Port::new("/scan/report", StringMsg::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        self.cfg = config(p)?;
        if !self.cfg.camera.is_empty() {
            self.camera = self.cfg.camera.clone();
        }
        Ok(())
    }
    fn handle(&mut self, input: Input, msg: &Msg, out: &mut Out) -> Result<(), NodeError> {
        match (input, msg) {
            (Input::Profile, Msg::Cloud(c)) => self.profile(c, out),
            (Input::Events, Msg::ScanEvent(e)) => self.event(e, out),
            (Input::CameraInfo, Msg::CameraInfo(i)) => self.camera_info(i),
            (i, m) => Err(NodeError::unexpected(i, m)),
        }
    }
    fn tick(&mut self, now_ns: i64, out: &mut Out) {
        if self.closing.is_some_and(|(_, end)| now_ns >= end.saturating_add(self.cfg.end_grace_ns)) {
            self.close_pending(out);
        }
        self.mesh_done(false, out);
        self.last_mesh.tick(self.cfg.republish_ns, now_ns, out);
    }
    /// While a closed scan's mesh is being made: soon, to publish it once made.
    fn next_tick_ns(&self) -> Option<i64> {
        self.meshing.as_ref().map(|_| xsurf_runtime::wall_clock_ns() + MESH_POLL_NS)
    }
    fn finish(&mut self, out: &mut Out) {
        self.outside_scan += self.early.len() as u64;
        self.early.clear();
        self.close_pending(out);
        self.close(false, None, out);
    }
    fn settle(&mut self, out: &mut Out) {
        self.mesh_done(true, out);
    }
    /// Bulk work: the live host runs it behind the frame path.
    fn bulk(&self) -> bool {
        true
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("scans", self.scans),
            ("frames", self.frames),
            ("dropped_frames", self.dropped_frames),
            ("triangles", self.triangles),
            ("mesh_points", self.mesh_points),
            ("files_written", self.files_written),
            ("frames_outside_scans", self.outside_scan),
            ("bad_profiles", self.bad_profiles),
            ("points_rejected", self.points_rejected),
            ("points_partial_sheet", self.points_partial_sheet),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_counted_from_stamps() {
        let mut g = GapDetector::default();
        let mut missing = 0;
        for (i, t) in [0, 33, 66, 100, 133, 233, 266].iter().enumerate() {
            let m = g.missing(*t * 1_000_000, 1.5);
            if i == 5 {
                assert_eq!(m, 2);
            }
            missing += m;
        }
        assert_eq!(missing, 2);
    }
    /// Scan `scan_id`'s event `kind` stamped at `sec`.
    fn scan_event(scan_id: u32, kind: u8, sec: i32) -> Msg {
        let mut e = ScanEvent { scan_id, event: kind, ..Default::default() };
        e.header.stamp.sec = sec;
        Msg::ScanEvent(Arc::new(e))
    }

    /// A mesher with its defaults that has the camera_info of a 64x40 camera.
    fn mesher_of_a_64x40_camera() -> (MesherNode, Out) {
        #![allow(clippy::unwrap_used)]
        let params = Params::resolve(&MesherParams::declarations(), &Default::default()).unwrap();
        let mut m = MesherNode::new(&params).unwrap();
        let mut out = Out::default();
        let info = CameraInfo { width: 64, height: 40, ..Default::default() };
        m.handle(Input::CameraInfo, &Msg::CameraInfo(Arc::new(info)), &mut out).unwrap();
        (m, out)
    }

    /// The grid's samples per frame come from camera_info: a stray 10-sample profile arriving
    /// first no longer fixes the grid and costs the camera's real profiles (issue 24).
    #[test]
    fn the_grid_size_comes_from_the_camera() {
        #![allow(clippy::unwrap_used)]
        let (mut m, mut out) = mesher_of_a_64x40_camera();
        let profile = |n: usize, sec: i32| {
            let p = Profile {
                points: vec![[0.1, 0.2, 0.3]; n],
                intensity: vec![50.0; n],
                rgb: None,
                range: vec![0.5; n],
                outside_volume: 0,
            };
            let mut h = xsurf_msgs::std_msgs::Header::default();
            h.stamp.sec = sec;
            Msg::Cloud(Arc::new(convert::profile_cloud(&p, h)))
        };
        let e = m.handle(Input::Profile, &profile(10, 1), &mut out).unwrap_err();
        assert!(
            e.to_string().contains("profile has 10 samples; the camera (camera_info, vertical line, 1 laser(s), 1 line(s) each) gives 40"),
            "{e}"
        );
        for sec in 2..6 {
            m.handle(Input::Profile, &profile(40, sec), &mut out).unwrap();
        }
        assert_eq!((m.frames, m.bad_profiles, m.grid.samples()), (4, 1, 40));
        // A camera_info that no camera has is refused by name.
        let bad = CameraInfo { width: 0, height: 0, ..Default::default() };
        assert!(m.handle(Input::CameraInfo, &Msg::CameraInfo(Arc::new(bad)), &mut out).unwrap_err().to_string().contains("0x0"));
        // A scan from START at 10 s: a frame exposed at 9 s that arrives after START is not
        // part of it (nor the reason for a cloud stamped before START); the 11 s one is.
        let mut start = ScanEvent { scan_id: 3, event: ScanEvent::START, ..Default::default() };
        start.header.stamp.sec = 10;
        m.handle(Input::Events, &Msg::ScanEvent(Arc::new(start)), &mut out).unwrap();
        let outside = m.outside_scan;
        m.handle(Input::Profile, &profile(40, 9), &mut out).unwrap();
        m.handle(Input::Profile, &profile(40, 11), &mut out).unwrap();
        assert_eq!((m.outside_scan - outside, m.grid.frames(), m.account.first_ns), (1, 1, Some(11_000_000_000)));
    }

    /// A point that its neighbours contradict is rejected before meshing, counted, and named in
    /// the scan's report; the cloud published at END does not have it. So are the points of a
    /// first frame much weaker than the next (the sheet only partly on the surface), counted
    /// apart as well.
    #[test]
    fn contradicted_points_are_rejected_and_reported() {
        #![allow(clippy::unwrap_used)]
        let (mut m, mut out) = mesher_of_a_64x40_camera();
        let event = |kind: u8, sec: i32| scan_event(7, kind, sec);
        m.handle(Input::Events, &event(ScanEvent::START, 1), &mut out).unwrap();
        for f in 0..20 {
            // A plane, 1 mm between samples and 2 mm between frames; frame 10 has a wrong
            // peak 8 mm above it at sample 5.
            let points = (0..40)
                .map(|s| [s as f32 * 0.001, f as f32 * 0.002, if (f, s) == (10, 5) { 0.058 } else { 0.05 }])
                .collect();
            // The first frame at a fifth of the others' strength.
            let strength = if f == 0 { 10.0 } else { 50.0 };
            let p = Profile { points, intensity: vec![strength; 40], rgb: None, range: vec![0.5; 40], outside_volume: 0 };
            let mut h = xsurf_msgs::std_msgs::Header::default();
            (h.stamp.sec, h.stamp.nanosec) = (2, f * 10_000_000);
            m.handle(Input::Profile, &Msg::Cloud(Arc::new(convert::profile_cloud(&p, h))), &mut out).unwrap();
        }
        m.handle(Input::Events, &event(ScanEvent::END, 3), &mut out).unwrap();
        m.finish(&mut out);
        let report = out
            .items
            .iter()
            .find_map(|(port, msg)| match msg {
                Msg::Text(t) if *port == Output::Report => {
                    Some(serde_json::from_str::<serde_json::Value>(&t.data).unwrap())
                }
                _ => None,
            })
            .unwrap();
        assert_eq!((&report["points_rejected"], &report["points_partial_sheet"]), (&41.into(), &40.into()), "{report}");
        assert!(m.counters().contains(&("points_rejected", 41)) && m.counters().contains(&("points_partial_sheet", 40)));
        let cloud = out
            .items
            .iter()
            .rev()
            .find_map(|(port, msg)| match msg {
                Msg::Cloud(c) if *port == Output::Cloud => Some(convert::cloud_grid(c).unwrap()),
                _ => None,
            })
            .unwrap();
        // The single hole it leaves is filled from its neighbours (`fill_single_holes`); the
        // first frame is gone.
        assert_eq!(cloud.valid(), 40 * 19);
        assert!((0..40).all(|s| cloud.point(s, 0)[0].is_nan()));
        assert!((cloud.point(5, 10)[2] - 0.05).abs() < 1e-6, "{:?}", cloud.point(5, 10));
    }

    /// Profiles with second surfaces' lines (the field `layer`): twice the camera's samples, a
    /// grid per line cleaned and meshed apart (no triangle joins the lines, though here the
    /// second continues the first's plane), both in the marker; the cloud keeps the field. A
    /// profile of the other shape is refused and counted.
    #[test]
    fn second_surfaces_lines_are_grids_of_their_own() {
        #![allow(clippy::unwrap_used)]
        let (mut m, mut out) = mesher_of_a_64x40_camera();
        m.set_identity("mesher", "/cam1");
        let two = convert::Blocks { lasers: 0, layers: 2 };
        let profile = |f: u32, blocks: convert::Blocks, n: usize| {
            // The first line on a plane (samples 0-39), the second on its continuation in 10
            // rows only (samples 40-49 of the second block), NaN elsewhere.
            let points = (0..n)
                .map(|s| if s < 50 { [s as f32 * 0.001, f as f32 * 0.002, 0.05] } else { [f32::NAN; 3] })
                .collect();
            let p = Profile { points, intensity: vec![50.0; n], rgb: None, range: vec![0.5; n], outside_volume: 0 };
            let mut h = xsurf_msgs::std_msgs::Header::default();
            (h.stamp.sec, h.stamp.nanosec) = (2, f * 10_000_000);
            Msg::Cloud(Arc::new(convert::profile_cloud_blocks(&p, h, blocks)))
        };
        let event = |kind: u8, sec: i32| scan_event(5, kind, sec);
        m.handle(Input::Events, &event(ScanEvent::START, 1), &mut out).unwrap();
        for f in 0..20 {
            m.handle(Input::Profile, &profile(f, two, 80), &mut out).unwrap();
        }
        // One line where the camera gives two, and a second line on a one-line camera's count.
        let e = m.handle(Input::Profile, &profile(20, convert::Blocks::ONE, 80), &mut out).unwrap_err();
        assert!(e.to_string().contains("profile has 80 samples; the camera (camera_info, vertical line, 1 laser(s), 1 line(s) each) gives 40"), "{e}");
        let e = m.handle(Input::Profile, &profile(21, two, 40), &mut out).unwrap_err();
        assert!(e.to_string().contains("profile has 40 samples; the camera (camera_info, vertical line, 1 laser(s), 2 line(s) each) gives 80"), "{e}");
        assert_eq!((m.frames, m.bad_profiles), (20, 2));
        m.handle(Input::Events, &event(ScanEvent::END, 3), &mut out).unwrap();
        m.finish(&mut out);
        m.settle(&mut out);
        let cloud = out
            .items
            .iter()
            .rev()
            .find_map(|(port, msg)| match msg {
                Msg::Cloud(c) if *port == Output::Cloud => Some(c.clone()),
                _ => None,
            })
            .unwrap();
        assert_eq!((cloud.height, cloud.width), (80, 20));
        let points = xsurf_msgs::pointcloud::read(&cloud).unwrap();
        assert_eq!((points[39 * 20].layer, points[45 * 20].layer), (Some(0.0), Some(1.0)));
        assert_eq!(points.iter().filter(|p| p.xyz[0].is_finite()).count(), 50 * 20);
        let marker = out
            .items
            .iter()
            .find_map(|(port, msg)| match msg {
                Msg::Marker(k) if *port == Output::Mesh && k.ns == "cam1" => Some(k.clone()),
                _ => None,
            })
            .unwrap();
        // 39 x 19 cells of the first line and 9 x 19 of the second, two triangles each; one
        // grid would have joined them by 19 cells more.
        assert_eq!((marker.ns.as_str(), marker.points.len() / 3), ("cam1", 2 * (39 + 9) * 19));
    }

    /// While a scan runs the surface grows at `mesh_rate_hz`: parts of the new frames only, in
    /// order, in a namespace of their own; at END a DELETEALL, then the scan's mesh (issue 22).
    #[test]
    fn the_surface_grows_in_parts_of_the_new_frames() {
        #![allow(clippy::unwrap_used)]
        let (mut m, mut out) = mesher_of_a_64x40_camera();
        m.set_identity("mesher", "/cam1");
        let event = |kind: u8, sec: i32| scan_event(2, kind, sec);
        m.handle(Input::Events, &event(ScanEvent::START, 1), &mut out).unwrap();
        // 2 s at 30 fps over a gentle slope, 2 mm between frames.
        let frames = 60u32;
        for f in 0..frames {
            let points = (0..40).map(|s| [s as f32 * 0.001, f as f32 * 0.002, 0.05 + s as f32 * 0.0002]).collect();
            let p = Profile { points, intensity: vec![50.0; 40], rgb: None, range: vec![0.5; 40], outside_volume: 0 };
            let mut h = xsurf_msgs::std_msgs::Header::default();
            let ns = 1_100_000_000u64 + u64::from(f) * 33_333_333;
            (h.stamp.sec, h.stamp.nanosec) = ((ns / 1_000_000_000) as i32, (ns % 1_000_000_000) as u32);
            m.handle(Input::Profile, &Msg::Cloud(Arc::new(convert::profile_cloud(&p, h))), &mut out).unwrap();
        }
        let markers = |out: &Out| -> Vec<Marker> {
            out.items
                .iter()
                .filter_map(|(port, msg)| match msg {
                    Msg::Marker(k) if *port == Output::Mesh => Some((**k).clone()),
                    _ => None,
                })
                .collect()
        };
        let during = markers(&out);
        // At 2 Hz: a part each 15 frames, the first as soon as two frames are in.
        assert!((4..=5).contains(&during.len()), "{} parts", during.len());
        let mut next_y = 0.0f64;
        let mut triangles = 0;
        for (k, part) in during.iter().enumerate() {
            assert_eq!((part.ns.as_str(), part.id, part.action), ("cam1_growing", k as i32, Marker::ADD));
            let ys: Vec<f64> = part.points.iter().map(|p| p.y).collect();
            let (lo, hi) = ys.iter().fold((f64::MAX, f64::MIN), |(a, b), &y| (a.min(y), b.max(y)));
            // Each part starts at the frame where the last one ended: only new cells.
            assert!((lo - next_y).abs() < 1e-6, "part {k} starts at {lo}, expected {next_y}");
            next_y = hi;
            triangles += part.points.len() / 3;
        }
        // Every cell of the frames covered so far, two triangles each, over every fourth
        // sample (mesh_preview_stride 4: 10 of the 40).
        let covered = (next_y / 0.002).round() as usize;
        assert_eq!(triangles, 2 * 9 * covered);
        out.items.clear();
        m.handle(Input::Events, &event(ScanEvent::END, 3), &mut out).unwrap();
        m.finish(&mut out);
        m.settle(&mut out);
        let after = markers(&out);
        // The final cloud goes first: the mesh is made after it, on a thread of its own.
        let first = |f: &dyn Fn(&(Output, Msg)) -> bool| out.items.iter().position(f).unwrap();
        assert!(
            first(&|(p, m)| *p == Output::Cloud && matches!(m, Msg::Cloud(_)))
                < first(&|(p, m)| *p == Output::Mesh && matches!(m, Msg::Marker(_)))
        );
        assert_eq!(after.len(), 2);
        assert_eq!(after[0].action, Marker::DELETEALL);
        assert_eq!((after[1].ns.as_str(), after[1].id, after[1].points.len() / 3), ("cam1", 2, 2 * 39 * (frames as usize - 1)));
    }
}

