//! `merger`: the cameras' organized clouds (`/<cam>/cloud` for each name in `cameras`) ->
//! one surface in `table` (`/surface/cloud`, `/surface/mesh`) after each END, and the files
//! `<output_dir>/scan_<id>/{merged.ply, scene.wrl, scene.glb, preview.png}`.
//!
//! The cameras are placed by calibration (their clouds are already in `table`). With `refine`,
//! each further camera's placement (`carm -> <cam>_optical_frame` from `/tf_static`) is then
//! refined against the first camera's surface (`core/src/register.rs`: each point's frame
//! pose follows from its travel, `table -> carm` from `/tf` gives the angle and tabletop
//! height; point-to-plane Gauss-Newton on smoothed surfaces, trimmed and robust), its points are
//! re-triangulated through the refined placement, the placements are published on
//! `/surface/placements` and, with `save_rig_file`, written into that rig file for the next
//! scans. A refinement that is refused (too little overlap, a poor fit, a correction beyond
//! the bounds) is logged with its reason and counted; the calibrated placement then stands.
//! Where the cameras overlap, each region is kept from the camera that sees it better (brighter line) and the
//! other camera's samples there are averaged into it (`fuse_distance_m`, `core/src/fuse.rs`), so
//! the merged surface is one layer; then each grid is meshed, the surfaces are combined, the
//! seams between them stitched (`zipper`, `core/src/zipper.rs`) and the small holes left closed
//! (`max_hole_edges`, `core/src/holes.rs`). The merge waits `merge_delay_s` after END so the
//! meshers' final clouds arrive first. The radiograph placed by `xray_aligner`
//! (`/xray/overlay`, marker id = scan id) goes under the surface in `scene.wrl`, `scene.glb`
//! and `preview.png`, with `xray.png` beside them; one that arrives after the merge (a
//! radiograph loaded later) rewrites that scan's scene files.

mod dicom;
mod params;
pub use params::*;

/// The node type, as the registry lists it.
pub const NODE: crate::registry::NodeType =
    crate::registry::NodeType::of::<MergerParams>("merger", crate::registry::Role::Scanner, 50, |p| Ok(boxed(MergerNode::new(p)?)));

use crate::convert;
use crate::scan_report::{CameraAccount, MesherReport, Report, ScanReport, StageReport};
use crate::tf::TfBuffer;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use xsurf_core::fuse::FuseConfig;
use xsurf_core::geom::{Iso3, Plane};
use xsurf_core::merge::refine::{refine_cameras, CarmMotion, Record, RefinementFile};
use xsurf_core::merge::{merge_grids, MergeConfig, Merged};
use xsurf_core::mesh::{Grid, Mesh, MeshConfig};
use xsurf_core::register::{RefineConfig, RefineReport};
use xsurf_formats::scene::{Scene, Surface, TexturedPlane};
use xsurf_msgs::pointcloud;
use xsurf_msgs::sensor_msgs::{CameraInfo, PointCloud2};
use xsurf_msgs::std_msgs::StringMsg;
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::visualization_msgs::Marker;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{boxed, Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{NodeParams, ParamError, Params};

struct Config {
    cameras: Vec<String>,
    /// The lasers (empty: one laser, no `laser` field); the first is the one the refinement
    /// fits, the others' grids follow their camera.
    lasers: Vec<xsurf_core::rig::RigLaser>,
    refine: Option<(RefineConfig, Plane)>,
    save_rig_file: Option<PathBuf>,
    delay_ns: i64,
    merge: MergeConfig,
    transparency: f32,
    output_dir: Option<PathBuf>,
    frame_id: String,
    table_frame: String,
    carm_frame: String,
    republish_ns: Option<i64>,
    dicom: dicom::DicomConfig,
    /// The PACS, our side of it and the queue's folder.
    pacs: Option<dicom::PacsConfig>,
}

fn config(raw: &Params) -> Result<Config, ParamError> {
    let p = MergerParams::from_params(raw)?;
    let lasers = crate::lasers::from_params(raw, &p.lasers, [0.0; 3])?.unwrap_or_default();
    let cameras = p.cameras.clone();
    if cameras.is_empty() || cameras.iter().any(|c| c.is_empty() || c.contains(char::is_whitespace)) {
        return Err(Params::invalid("cameras", format!("{cameras:?}: needs one or more camera names")));
    }
    let mesh = MeshConfig { max_edge_m: p.max_edge_m, min_angle_deg: p.min_angle_deg, ..MeshConfig::default() };
    mesh.validate().map_err(|e| Params::invalid("merger", e))?;
    let plane = match lasers.first() {
        Some(l) => l.plane,
        None => crate::triangulator::laser_plane("laser_plane", &p.laser_plane)?,
    };
    let plane = Plane::from_params(plane)
        .ok_or_else(|| Params::invalid("laser_plane", format!("{plane:?}: needs [nx, ny, nz, d] with |n| = 1")))?;
    let positive = |name: &str, v: f64| -> Result<f64, ParamError> {
        if v > 0.0 && v.is_finite() {
            Ok(v)
        } else {
            Err(Params::invalid(name, format!("{v} must be positive")))
        }
    };
    let refine_cfg = RefineConfig {
        max_translation_m: positive("refine_max_translation_m", p.refine_max_translation_m)?,
        max_rotation_deg: positive("refine_max_rotation_deg", p.refine_max_rotation_deg)?,
        max_rms_m: positive("refine_max_rms_m", p.refine_max_rms_m)?,
        max_edge_m: p.max_edge_m,
        ..RefineConfig::default()
    };
    let (dicom, pacs) = dicom::config(&p)?;
    Ok(Config {
        lasers,
        dicom,
        pacs,
        refine: p.refine.then_some((refine_cfg, plane)),
        save_rig_file: p.save_rig_file,
        cameras,
        delay_ns: (p.merge_delay_s * 1e9) as i64,
        merge: MergeConfig {
            mesh,
            fuse: FuseConfig { min_distance_m: p.fuse_distance_m, mesh, ..FuseConfig::default() },
            zipper: p.zipper,
            max_hole_edges: p.max_hole_edges,
        },
        transparency: p.transparency,
        output_dir: p.output_dir,
        frame_id: p.frame_id,
        table_frame: p.table_frame,
        carm_frame: p.carm_frame,
        republish_ns: (p.republish_s > 0.0).then_some((p.republish_s * 1e9) as i64),
    })
}

/// The last scan merged: its id, the merged mesh and each camera's (kept so that a radiograph
/// arriving later can be added to its scene files).
type LastMerge = (u32, Mesh, Vec<(String, Mesh)>);

/// One camera's reports of one scan: its mesher's, and the nodes' before it by node name.
#[derive(Debug, Default)]
struct CameraReports {
    mesher: Option<MesherReport>,
    upstream: BTreeMap<String, StageReport>,
}

/// Reports kept at most (scans and cameras): those of scans furthest from the current one go
/// first, so that a peer sending reports of any scan id cannot grow the merger.
const MAX_REPORTS: usize = 32;

/// The merger component.
pub struct MergerNode {
    cfg: Config,
    /// Each camera's latest grid of the scan, decoded and checked when it arrived, with its stamp
    /// and its lines per laser (2 with second surfaces' lines).
    clouds: BTreeMap<usize, (i64, Grid, usize)>,
    /// Each camera's image size by its camera_info, once known.
    camera_sizes: BTreeMap<usize, (u32, u32)>,
    /// The current scan's START stamp: an older cloud is a late one of an earlier scan.
    scan_start_ns: Option<i64>,
    /// The reports on `/scan/report`, by scan and camera: the current scan's, and any that
    /// arrived before the merger saw their scan's START or END (they take other paths).
    reports: BTreeMap<(u32, String), CameraReports>,
    scan_id: u32,
    pending_deadline: Option<i64>,
    merges: u64,
    points: u64,
    triangles: u64,
    bad_clouds: u64,
    overlays: BTreeMap<u32, TexturedPlane>,
    last_merge: Option<LastMerge>,
    merged_current: bool,
    bad_overlays: u64,
    /// Files (surfaces, refinement.json, the rig) that could not be written.
    write_errors: u64,
    /// The last few of those failures, with the file and the reason.
    problems: Vec<String>,
    fused_dropped: u64,
    refinements: u64,
    refinements_refused: u64,
    seam_triangles: u64,
    /// `carm -> <cam>_optical_frame` from `/tf_static`.
    statics: TfBuffer,
    /// The scan's C-arm motion so far.
    motion: Option<CarmMotion>,
    /// The last merge's cloud and mesh, published again between scans.
    last_outputs: crate::republish::Republisher<Output>,
    /// The last merged scan's files, not yet written: they are written at the next tick, after
    /// its surface has been published (a merge on the last final cloud puts the surface on the
    /// wire first), with its account as it stands then.
    unwritten: Option<Unwritten>,
    /// The current scan's END stamp.
    scan_end_ns: Option<i64>,
    /// The PACS queue and its sender, with `pacs`.
    pacs: Option<(crate::pacs::Queue, crate::pacs::Sender)>,
    /// Scans whose DICOM files were written.
    dicom_scans: u64,
    /// Scans put in the PACS queue.
    pacs_queued: u64,
}

/// A merged scan's files still to write (its meshes are the last merge's).
struct Unwritten {
    /// The scan: id, START and END.
    span: dicom::ScanSpan,
    /// The cameras in the surface.
    names: Vec<String>,
    refinement: Vec<Record>,
}

/// Every camera's grids (`blocks[camera]`: a grid per laser and line, layer-major) as one list
/// to fuse into one layer, each named: `cam1`, or `cam1.left` with lasers; a second surfaces'
/// line's `cam1.second` (`cam1.left.second`).
fn named_grids(cams: &[String], blocks: Vec<Vec<Grid>>, lasers: &[xsurf_core::rig::RigLaser]) -> (Vec<String>, Vec<Grid>) {
    let mut names = Vec::new();
    let mut gs = Vec::new();
    for (cam, grids) in cams.iter().zip(blocks) {
        for (j, g) in grids.into_iter().enumerate() {
            let (k, layer) = (j % lasers.len().max(1), j / lasers.len().max(1));
            let name = lasers.get(k).map_or_else(|| cam.clone(), |l| format!("{cam}.{}", l.name));
            names.push(if layer > 0 { format!("{name}.second") } else { name });
            gs.push(g);
        }
    }
    (names, gs)
}

impl MergerNode {
    /// Points of the merged clouds, so far.
    pub fn points(&self) -> u64 {
        self.points
    }
    /// Triangles of the merged surfaces, so far.
    pub fn triangles(&self) -> u64 {
        self.triangles
    }
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let cfg = config(p)?;
        let mut node = Self {
            statics: TfBuffer::new(&cfg.table_frame, &cfg.carm_frame, 0),
            cfg,
            clouds: BTreeMap::new(),
            camera_sizes: BTreeMap::new(),
            scan_start_ns: None,
            reports: BTreeMap::new(),
            scan_id: 0,
            pending_deadline: None,
            merges: 0,
            points: 0,
            triangles: 0,
            bad_clouds: 0,
            overlays: BTreeMap::new(),
            last_merge: None,
            merged_current: false,
            bad_overlays: 0,
            write_errors: 0,
            problems: Vec::new(),
            fused_dropped: 0,
            refinements: 0,
            refinements_refused: 0,
            seam_triangles: 0,
            motion: None,
            last_outputs: crate::republish::Republisher::default(),
            unwritten: None,
            scan_end_ns: None,
            pacs: None,
            dicom_scans: 0,
            pacs_queued: 0,
        };
        node.start_pacs();
        Ok(node)
    }

    /// Starts the PACS sender the configuration asks for (what is queued goes first); a queue
    /// that cannot be made is logged, and the scans' files stay in their folders.
    fn start_pacs(&mut self) {
        // The old sender first ends (after its current attempt), so that two never send one queue.
        self.pacs = None;
        self.pacs = self.cfg.pacs.as_ref().and_then(|(peer, client, dir)| match crate::pacs::Queue::open(dir) {
            Ok(q) => {
                let waiting = q.entries().len();
                if waiting > 0 {
                    log::info!("merger: {waiting} scan(s) waiting in {} for the PACS {peer}", dir.display());
                }
                Some((q.clone(), crate::pacs::Sender::spawn(q, client.clone(), peer.clone())))
            }
            Err(e) => {
                log::error!("merger: no PACS queue: {e:#}");
                None
            }
        });
    }

    /// Decodes camera `i`'s cloud and checks it against the camera and the scan: a cloud whose
    /// samples per frame no image of the camera has, or one stamped before this scan's START
    /// (a late cloud of an earlier scan), is refused and the camera's grid so far stays.
    fn check_cloud(&self, i: usize, c: &PointCloud2) -> Result<(Grid, usize), NodeError> {
        let at = convert::fmt_stamp(c.header.stamp.nanos());
        let grid = convert::cloud_grid(c).map_err(|e| NodeError::malformed(format!("cloud at {at}: {e}")))?;
        // A cloud with the field `layer` holds each laser's second surfaces' line too.
        let layers = convert::cloud_layers(c);
        if let Some(&(w, h)) = self.camera_sizes.get(&i) {
            let l = self.cfg.lasers.len().max(1) as u32;
            let k = l * layers as u32;
            if c.height != w * k && c.height != h * k {
                return Err(NodeError::contradicts(format!(
                    "cloud at {at} has {} samples per frame; the camera's {w}x{h} images (camera_info) give {h} (vertical lines) or {w} (horizontal), times {l} laser(s) and {layers} line(s) per laser",
                    c.height
                )));
            }
        }
        if let Some(start) = self.scan_start_ns.filter(|&s| c.header.stamp.nanos() < s) {
            return Err(NodeError::contradicts(format!(
                "cloud at {at} is older than scan {}'s START at {}: a late cloud of an earlier scan",
                self.scan_id,
                convert::fmt_stamp(start)
            )));
        }
        Ok((grid, layers))
    }

    /// Merges now if the scan has ended and every camera's final cloud is in: its mesher's
    /// report of the scan names the final cloud (`final_cloud`: stamp and points), and the
    /// camera's latest cloud is that one. A camera whose report has not come waits for the
    /// bound (`merge_delay_s` after END).
    fn merge_if_complete(&mut self, out: &mut Out) {
        if self.pending_deadline.is_none() {
            return;
        }
        let done = |k: usize, cam: &String| {
            let Some(m) = self.reports.get(&(self.scan_id, cam.clone())).and_then(|r| r.mesher.as_ref()) else {
                return false;
            };
            match (&m.final_cloud, self.clouds.get(&k)) {
                // A mesher that does not mark its final cloud: the bound.
                (None, _) => false,
                // A scan without points: no cloud of it to wait for.
                (Some(f), _) if f.points == 0 => true,
                (Some(f), Some((stamp, grid, _))) => {
                    convert::fmt_stamp(*stamp) == f.stamp && grid.valid() as u64 == f.points
                }
                (Some(_), None) => false,
            }
        };
        if self.cfg.cameras.iter().enumerate().all(|(k, cam)| done(k, cam)) {
            self.merge(out);
        }
    }

    /// Writes the last merged scan's files if they are not yet written, and logs its account
    /// (the cameras missing, without a report, or short of frames) as it stands then.
    fn write_unwritten(&mut self) {
        let Some(u) = self.unwritten.take() else { return };
        let Some((id, merged, meshes)) = self.last_merge.take() else { return };
        let report = self.scan_report(u.span.scan_id, &u.names);
        Self::log_account(&report);
        self.write(u.span.scan_id, &merged, &meshes, &u.refinement, Some((&report, u.span)));
        self.last_merge = Some((id, merged, meshes));
    }

    fn merge(&mut self, out: &mut Out) {
        self.write_unwritten();
        self.pending_deadline = None;
        if self.clouds.is_empty() {
            return;
        }
        let stamp = self.clouds.values().map(|(t, _, _)| *t).max().unwrap_or(0);
        let lasers = self.cfg.lasers.clone();
        // Per camera, one grid per laser and line (its blocks of samples, layer-major).
        let (cams, mut blocks): (Vec<String>, Vec<Vec<Grid>>) = self
            .clouds
            .iter()
            .map(|(&i, (_, g, layers))| {
                let count = convert::Blocks { lasers: lasers.len(), layers: *layers }.count();
                (self.cfg.cameras[i].clone(), g.blocks(count))
            })
            .unzip();
        let (refined, refinement) = self.refine(&cams, &mut blocks);
        if !refined.is_empty() {
            let placements = TFMessage {
                transforms: refined
                    .iter()
                    .map(|(name, e)| convert::transform_stamped(stamp, &self.cfg.carm_frame, &format!("{name}_optical_frame"), e))
                    .collect(),
            };
            out.publish(Output::Placements, Msg::Tf(Arc::new(placements)));
            self.save_rig(&refined);
        }
        let (names, mut gs) = named_grids(&cams, blocks, &lasers);
        let Merged { surface: merged, meshes, fused_dropped, seam_triangles, vertex_grid } =
            merge_grids(&names, &mut gs, &self.cfg.merge);
        self.fused_dropped += fused_dropped as u64;
        self.seam_triangles += seam_triangles as u64;
        let header = convert::header(stamp, &self.cfg.frame_id);
        let pts = &merged.positions;
        let point = |c: usize| {
            let col = merged.colors.get(c).copied().unwrap_or([200; 3]);
            (pts[c], 0.0, (u32::from(col[0]) << 16) | (u32::from(col[1]) << 8) | u32::from(col[2]))
        };
        self.merges += 1;
        self.points += pts.len() as u64;
        self.triangles += merged.triangles.len() as u64;
        // What no one takes (offline) is not built: the marker is some 40 bytes a vertex.
        let mut outputs = Vec::new();
        if out.heard(Output::Cloud) {
            let cloud = if lasers.is_empty() {
                pointcloud::build(header.clone(), 1, pts.len() as u32, |_, c| point(c))
            } else {
                // Each vertex's laser: its grid's, grids being camera-major, laser-minor.
                pointcloud::build_with_laser(header.clone(), 1, pts.len() as u32, |_, c| {
                    let (p, i, rgb) = point(c);
                    (p, i, rgb, vertex_grid.get(c).map_or(0.0, |&g| (usize::from(g) % lasers.len()) as f32))
                })
            };
            outputs.push((Output::Cloud, Msg::Cloud(Arc::new(cloud))));
        }
        if out.heard(Output::Mesh) {
            let alpha = 1.0 - self.cfg.transparency;
            let marker = convert::mesh_marker(&merged, header, "surface", self.scan_id as i32, alpha);
            outputs.push((Output::Mesh, Msg::Marker(Arc::new(marker))));
        }
        for (port, msg) in &outputs {
            out.publish(*port, msg.clone());
        }
        self.last_outputs.set(outputs);
        let start_ns = self.scan_start_ns.unwrap_or(stamp);
        let end_ns = self.scan_end_ns.filter(|&e| e >= start_ns).unwrap_or(stamp);
        let span = dicom::ScanSpan { scan_id: self.scan_id, start_ns, end_ns };
        self.unwritten = Some(Unwritten { span, names: cams, refinement });
        log::info!(
            "merger: scan {}: {} points, {} triangles from {} camera(s)",
            self.scan_id,
            pts.len(),
            merged.triangles.len(),
            gs.len()
        );
        self.last_merge = Some((self.scan_id, merged, meshes));
        self.merged_current = true;
    }

    /// Refines each further camera's placement against the first camera's grid
    /// (`core::merge::refine`); returns the placements refined and, per camera, what happened
    /// (for `refinement.json`). Each decision is logged and counted.
    /// With several lasers or lines (`blocks[camera][block]`, layer-major) the first laser's
    /// first grids are fitted, and a refined camera's further grids are re-triangulated through
    /// the refined placement, each with its own laser's plane.
    fn refine(&mut self, names: &[String], blocks: &mut [Vec<Grid>]) -> (Vec<(String, Iso3)>, Vec<Record>) {
        let Some((cfg, plane)) = self.cfg.refine else { return (Vec::new(), Vec::new()) };
        if blocks.len() < 2 {
            return (Vec::new(), Vec::new());
        }
        let statics = &self.statics;
        let placement = |name: &str| {
            let frame = format!("{name}_optical_frame");
            statics.carm_from(&frame).ok_or_else(|| format!("no carm -> {frame} on /tf_static"))
        };
        let mut firsts: Vec<Grid> = blocks.iter_mut().map(|b| std::mem::take(&mut b[0])).collect();
        let outcomes = refine_cameras(names, &mut firsts, placement, self.motion.as_ref(), &plane, &cfg);
        for (b, g) in blocks.iter_mut().zip(firsts) {
            b[0] = g;
        }
        for o in &outcomes {
            let (Some(report), Some(k), Some(motion)) =
                (&o.report, names.iter().position(|n| *n == o.record.camera), self.motion.as_ref())
            else {
                continue;
            };
            let Ok(from) = placement(&o.record.camera) else { continue };
            let motion = xsurf_core::register::ScanMotion { table_from_carm: motion.first };
            // Every further grid (laser `j % lasers`'s, layer-major) with its laser's plane.
            let lasers = &self.cfg.lasers;
            for (j, grid) in blocks[k].iter_mut().enumerate().skip(1) {
                let (name, laser_plane) = match lasers.get(j % lasers.len().max(1)) {
                    Some(l) => (l.name.as_str(), Plane::from_params(l.plane)),
                    None => ("", Some(plane)),
                };
                let moved = laser_plane.map(|p| {
                    xsurf_core::register::retriangulate_grid(grid, &from, &report.carm_from_optical, &p, &motion, cfg.max_travel_spread_m)
                });
                if let Some(Err(e)) = moved {
                    log::warn!("merger: {} laser {name:?} grid {j}: it stays where calibration put it: {e}", o.record.camera);
                }
            }
        }
        let scan = self.scan_id;
        let mut refined = Vec::new();
        let mut records = Vec::new();
        for o in outcomes {
            let r = &o.record;
            match &o.report {
                Some(report) => {
                    log_refinement(scan, &r.camera, &r.reference, report);
                    self.refinements += 1;
                    refined.push((r.camera.clone(), report.carm_from_optical));
                }
                None => {
                    self.refinements_refused += 1;
                    log::warn!("merger: scan {scan}: {} keeps its calibrated placement: {}", r.camera, r.reason);
                }
            }
            records.push(o.record);
        }
        (refined, records)
    }

    /// Writes refined placements into `save_rig_file`.
    fn save_rig(&mut self, refined: &[(String, Iso3)]) {
        let Some(path) = &self.cfg.save_rig_file else { return };
        let result = (|| -> anyhow::Result<()> {
            let mut rig = xsurf_formats::rig::read(path)?;
            for (name, e) in refined {
                let cam = rig
                    .cameras
                    .iter_mut()
                    .find(|c| &c.name == name)
                    .ok_or_else(|| anyhow::anyhow!("the rig file has no camera {name:?}"))?;
                cam.set_carm_from_optical(e);
            }
            let header = format!(
                "xsurf rig file (see launch-config/rig_study.yaml); the placement of {} refined by the merger against {} on scan {}.",
                refined.iter().map(|r| r.0.as_str()).collect::<Vec<_>>().join(", "),
                self.cfg.cameras[0],
                self.scan_id
            );
            xsurf_formats::rig::write(path, &rig, &header)?;
            Ok(())
        })();
        match result {
            Ok(()) => log::info!("merger: refined placement saved to {}", path.display()),
            Err(e) => self.write_failed(format!("save_rig_file {}: {e:#}", path.display())),
        }
    }

    /// Counts, logs and keeps (the last 8) a file that could not be written.
    fn write_failed(&mut self, why: String) {
        self.write_errors += 1;
        log::error!("merger: {why}");
        if self.problems.len() == 8 {
            self.problems.remove(0);
        }
        self.problems.push(why);
    }

    /// The last scan merged and its cameras (of its meshes, those of ours: not the seams').
    fn last_merged(&self) -> Option<(u32, Vec<String>)> {
        let (id, _, meshes) = self.last_merge.as_ref()?;
        Some((*id, meshes.iter().map(|(n, _)| n).filter(|n| self.cfg.cameras.contains(n)).cloned().collect()))
    }

    /// Keeps a report of a camera of ours (the others are no merge's).
    fn keep_report(&mut self, r: Report) {
        if !self.cfg.cameras.iter().any(|c| c == r.camera()) {
            return;
        }
        let reports = self.reports.entry((r.scan_id(), r.camera().to_string())).or_default();
        match r {
            Report::Mesher(m) => reports.mesher = Some(m),
            Report::Stage(s) => {
                reports.upstream.insert(s.node.clone(), s);
            }
        }
        while self.reports.len() > MAX_REPORTS {
            let current = self.scan_id;
            let furthest = self.reports.keys().max_by_key(|(scan, _)| scan.abs_diff(current)).cloned();
            if let Some(k) = furthest {
                self.reports.remove(&k);
            }
        }
    }

    /// The scan's account: each camera's report from its mesher, the cameras whose surface is
    /// missing from the merge (no cloud) and those that lost frames; the last two are logged.
    fn scan_report(&self, scan_id: u32, merged: &[String]) -> ScanReport {
        let missing: Vec<String> = self.cfg.cameras.iter().filter(|c| !merged.contains(c)).cloned().collect();
        let cameras: BTreeMap<&String, CameraAccount> = self
            .cfg
            .cameras
            .iter()
            .filter_map(|c| {
                let r = self.reports.get(&(scan_id, c.clone()))?;
                Some((c, CameraAccount::new(r.mesher.clone()?, r.upstream.clone())))
            })
            .collect();
        let incomplete =
            merged.iter().filter(|c| cameras.get(c).is_some_and(|a| a.mesher.frames_lost > 0)).cloned().collect();
        ScanReport {
            scan_id,
            merged: merged.to_vec(),
            missing,
            incomplete,
            cameras: cameras.into_values().collect(),
        }
    }

    fn write(
        &mut self,
        scan_id: u32,
        merged: &Mesh,
        meshes: &[(String, Mesh)],
        refinement: &[Record],
        first: Option<(&ScanReport, dicom::ScanSpan)>,
    ) {
        let Some(out) = self.cfg.output_dir.clone() else { return };
        let dir = out.join(format!("scan_{scan_id}"));
        if let Some((report, _)) = first {
            self.write_report(scan_id, report);
        }
        let plane = self.overlays.get(&scan_id);
        let span = first.filter(|_| !merged.triangles.is_empty()).map(|(_, span)| span);
        let (errors, dicom) = write_files(&dir, merged, meshes, plane, self.cfg.transparency, |dir| {
            span.map(|span| (span, dicom::write_scan(&self.cfg.dicom, dir, span, merged)))
        });
        for e in errors {
            self.write_failed(format!("cannot write files in {}: {e:#}", dir.display()));
        }
        if let Some((span, files)) = dicom {
            self.queue_dicom(span, files);
        }
        if !refinement.is_empty() {
            let file = RefinementFile { scan_id, cameras: refinement.to_vec() };
            self.write_json(&dir, "refinement.json", &serde_json::to_value(file).unwrap_or_default());
        }
    }

    /// Counts the scan's DICOM files as written (see `dicom.rs`) and queues them for the PACS,
    /// or counts their failure.
    fn queue_dicom(&mut self, span: dicom::ScanSpan, files: Result<Vec<std::path::PathBuf>, String>) {
        let files = match files {
            Ok(f) => f,
            Err(e) => return self.write_failed(e),
        };
        self.dicom_scans += 1;
        let Some((queue, sender)) = &self.pacs else { return };
        let name = format!("{:020}-scan_{}", span.start_ns.max(0), span.scan_id);
        match queue.enqueue(&name, &files) {
            Ok(_) => {
                self.pacs_queued += 1;
                sender.wake();
            }
            Err(e) => self.write_failed(format!("scan {}: not queued for the PACS: {e:#}", span.scan_id)),
        }
    }

    /// Logs the cameras a scan's account finds missing from the merge, without a report, or
    /// short of frames (with their gaps).
    fn log_account(report: &ScanReport) {
        let id = report.scan_id;
        for c in &report.missing {
            log::warn!("merger: scan {id}: no surface from {c}: merged without it");
        }
        for c in &report.merged {
            match report.cameras.iter().find(|a| &a.mesher.camera == c) {
                Some(a) if a.mesher.frames_lost > 0 => {
                    let gaps: Vec<String> = a.mesher.gaps.iter().map(|g| format!("{} after {}", g.frames, g.after)).collect();
                    log::warn!(
                        "merger: scan {id}: {c} lost {} of {} frames ({} in transport, {} refused on the way, {} never sent; gaps: {})",
                        a.mesher.frames_lost,
                        a.mesher.frames_expected,
                        a.frames_lost_in_transport,
                        a.frames_refused_upstream,
                        a.frames_not_sent,
                        if gaps.is_empty() { "at the ends".to_string() } else { gaps.join(", ") }
                    );
                }
                Some(_) => {}
                None => log::warn!("merger: scan {id}: no report from {c}'s mesher"),
            }
        }
    }

    /// Writes `scan_<id>/scan_report.json`.
    fn write_report(&mut self, scan_id: u32, report: &ScanReport) {
        let Some(out) = self.cfg.output_dir.clone() else { return };
        // Through a JSON value, whose keys are sorted (the flattened mesher report's too).
        let value = serde_json::to_value(report).unwrap_or_default();
        self.write_json(&out.join(format!("scan_{scan_id}")), "scan_report.json", &value);
    }

    /// Writes `value` as `dir/name` (atomically, `dir` made if need be); a failure is counted.
    fn write_json(&mut self, dir: &std::path::Path, name: &str, value: &serde_json::Value) {
        let path = dir.join(name);
        let text = serde_json::to_string_pretty(value).unwrap_or_default();
        let r = std::fs::create_dir_all(dir)
            .map_err(|e| e.to_string())
            .and_then(|_| xsurf_formats::write_bytes_atomic(&path, text.as_bytes()).map_err(|e| e.to_string()));
        if let Err(e) = r {
            self.write_failed(format!("cannot write {}: {e}", path.display()));
        }
    }

    fn overlay(&mut self, m: &Marker) -> Result<(), NodeError> {
        let plane = overlay_plane(m).map_err(|e| {
            self.bad_overlays += 1;
            NodeError::malformed(format!("/xray/overlay: {e}"))
        })?;
        let scan_id = m.id.max(0) as u32;
        self.overlays.insert(scan_id, plane);
        while self.overlays.len() > 4 {
            self.overlays.pop_first();
        }
        // A merged scan whose files are still to write takes it then.
        let unwritten = self.unwritten.as_ref().is_some_and(|u| u.span.scan_id == scan_id);
        if unwritten {
            return Ok(());
        }
        if let Some((id, merged, meshes)) = self.last_merge.take() {
            if id == scan_id {
                log::info!("merger: scan {scan_id}: radiograph arrived after the merge; scene files rewritten");
                self.write(scan_id, &merged, &meshes, &[], None);
            }
            self.last_merge = Some((id, merged, meshes));
        }
        Ok(())
    }
}

fn log_refinement(scan: u32, name: &str, reference: &str, r: &RefineReport) {
    log::info!(
        "merger: scan {scan}: {name} refined against {reference}: moved {:.2} mm / {:.3} deg ({:.0} standard \
         deviations; {} of 6 directions held by the data), {} iterations, RMS {:.3} -> {:.3} mm over {} points, \
         overlap {:.0} %",
        r.translation_m.norm() * 1e3,
        r.rotation_deg,
        r.significance,
        r.held_directions,
        r.iterations,
        r.rms_before_m * 1e3,
        r.rms_after_m * 1e3,
        r.points,
        r.overlap_fraction * 100.0
    );
}

/// The radiograph plane from an `/xray/overlay` marker: its triangles, its uv (rviz2's v = 0 at
/// the top, turned to VRML's) and its embedded PNG texture.
fn overlay_plane(m: &Marker) -> Result<TexturedPlane, String> {
    if m.type_ != Marker::TRIANGLE_LIST || m.points.is_empty() || !m.points.len().is_multiple_of(3) {
        return Err(format!("type {} with {} points: expected a TRIANGLE_LIST", m.type_, m.points.len()));
    }
    if m.uv_coordinates.len() != m.points.len() {
        return Err(format!("{} uv coordinates for {} points", m.uv_coordinates.len(), m.points.len()));
    }
    if m.texture.format != "png" || m.texture.data.is_empty() {
        return Err(format!("texture format {:?}: expected an embedded png", m.texture.format));
    }
    Ok(TexturedPlane {
        positions: m.points.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect(),
        uv: m.uv_coordinates.iter().map(|c| [c.u, 1.0 - c.v]).collect(),
        triangles: (0..m.points.len() as u32 / 3).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect(),
        png: m.texture.data.clone(),
        file_name: "xray.png".into(),
    })
}

/// Size of `preview.png`, pixels.
const PREVIEW_SIZE: (u32, u32) = (960, 720);

/// Writes the scan's surface files into `dir`, and `then` the files it writes there (the
/// DICOM); returns what could not be written, each failure naming its file (the others are
/// written whole), in the order merged.ply, scene.wrl, scene.glb, preview.png, and `then`'s
/// result.
///
/// Two at a time: the ones built whole in memory before their atomic write (scene.glb, then
/// `then`'s) one after the other here, for their buffers not to add up (at 1920x1200, some
/// 250 MiB more in a live merger when all were side by side), and merged.ply (written as it is
/// made) after them; beside them on another core scene.wrl (written as it is made) and the
/// preview, a few MiB. The two lanes take about as long (at 640x480, each 60-110 ms).
fn write_files<T: Send>(
    dir: &std::path::Path,
    merged: &Mesh,
    meshes: &[(String, Mesh)],
    plane: Option<&TexturedPlane>,
    transparency: f32,
    then: impl FnOnce(&std::path::Path) -> T,
) -> (Vec<anyhow::Error>, T) {
    if let Err(e) = std::fs::create_dir_all(dir) {
        return (vec![anyhow::Error::from(e)], then(dir));
    }
    let scene = Scene {
        surfaces: meshes.iter().map(|(name, mesh)| Surface { name, mesh, transparency }).collect(),
        plane: plane.cloned(),
    };
    let (w, h) = PREVIEW_SIZE;
    let ((glb, after, ply), [wrl, png]) = xsurf_core::par::join(
        || {
            let glb = xsurf_formats::gltf::write_file(&dir.join("scene.glb"), &scene).map_err(anyhow::Error::from);
            let after = then(dir);
            (glb, after, xsurf_formats::ply::write_file(&dir.join("merged.ply"), merged).map_err(anyhow::Error::from))
        },
        || {
            [
                xsurf_formats::vrml::write_file(&dir.join("scene.wrl"), &scene).map_err(anyhow::Error::from),
                {
                    let rgb = xsurf_formats::preview::render_scene(merged, plane, w, h);
                    let kind = xsurf_formats::image::PngKind::Rgb8;
                    xsurf_formats::image::write_png(&dir.join("preview.png"), w, h, kind, &rgb)
                        .map_err(anyhow::Error::from)
                },
            ]
        },
    );
    ([ply, wrl, glb, png].into_iter().filter_map(Result::err).collect(), after)
}

/// The merger's outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `/surface/cloud`: the merged cloud.
    Cloud,
    /// `/surface/mesh`: the merged surface.
    Mesh,
    /// `/surface/placements`: the cameras' placements as refined.
    Placements,
}

type Out = Outbox<Input, Output>;

/// The merger's inputs, in the order `inputs()` lists them: a cloud per camera, the scan
/// events, the radiograph overlay, `/tf`, `/tf_static`, a camera_info per camera, the reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `/<camera>/cloud` of camera `k` of `cameras`.
    Cloud(usize),
    /// `/scan/events`.
    Events,
    /// `/xray/overlay`.
    Overlay,
    /// `/tf`.
    Tf,
    /// `/tf_static`.
    TfStatic,
    /// `/<camera>/camera_info` of camera `k`.
    CameraInfo(usize),
    /// `/scan/report`.
    Report,
}

impl MergerNode {
    fn input_list(&self) -> Vec<Input> {
        let n = self.cfg.cameras.len();
        let mut v: Vec<Input> = (0..n).map(Input::Cloud).collect();
        v.extend([Input::Events, Input::Overlay, Input::Tf, Input::TfStatic]);
        v.extend((0..n).map(Input::CameraInfo));
        v.push(Input::Report);
        v
    }
    fn input_port(&self, input: Input) -> Port {
        let cam = |k: usize| self.cfg.cameras[k].as_str();
        match input {
            Input::Cloud(k) => Port::new(&format!("/{}/cloud", cam(k)), PointCloud2::TYPE_NAME, QosClass::State),
            Input::Events => Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable),
            Input::Overlay => Port::new("/xray/overlay", Marker::TYPE_NAME, QosClass::State),
            Input::Tf => Port::new("/tf", TFMessage::TYPE_NAME, QosClass::Reliable),
            Input::TfStatic => Port::new("/tf_static", TFMessage::TYPE_NAME, QosClass::Static),
            Input::CameraInfo(k) => {
                Port::new(&format!("/{}/camera_info", cam(k)), CameraInfo::TYPE_NAME, QosClass::Sensor)
            }
            Input::Report => Port::new("/scan/report", StringMsg::TYPE_NAME, QosClass::Reliable),
        }
    }
}

impl Component for MergerNode {
    type Input = Input;
    type Output = Output;
    fn node_name(&self) -> &'static str {
        "merger"
    }
    fn inputs(&self) -> Vec<(Input, Port)> {
        self.input_list().into_iter().map(|i| (i, self.input_port(i))).collect()
    }
    fn outputs(&self) -> Vec<(Output, Port)> {
        vec![
            (Output::Cloud, Port::new("/surface/cloud", PointCloud2::TYPE_NAME, QosClass::State)),
            (Output::Mesh, Port::new("/surface/mesh", Marker::TYPE_NAME, QosClass::State)),
            (Output::Placements, Port::new("/surface/placements", TFMessage::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        let c = config(p)?;
        if c.cameras != self.cfg.cameras {
            return Err(Params::invalid("cameras", "cannot change while running (restart the node)"));
        }
        if (&c.table_frame, &c.carm_frame) != (&self.cfg.table_frame, &self.cfg.carm_frame) {
            return Err(Params::invalid("carm_frame", "the frames cannot change while running (restart the node)"));
        }
        let pacs_changed = c.pacs.as_ref().map(|(p, cl, d)| (p, &cl.calling, d))
            != self.cfg.pacs.as_ref().map(|(p, cl, d)| (p, &cl.calling, d));
        self.cfg = c;
        if pacs_changed {
            // The old sender ends after its current attempt; what it had not sent stays queued.
            self.start_pacs();
        }
        Ok(())
    }
    fn handle(&mut self, input: Input, msg: &Msg, out: &mut Out) -> Result<(), NodeError> {
        match (input, msg) {
            (Input::Cloud(i), Msg::Cloud(c)) => {
                let (grid, layers) = self.check_cloud(i, c).inspect_err(|_| self.bad_clouds += 1)?;
                self.clouds.insert(i, (c.header.stamp.nanos(), grid, layers));
                self.merged_current = false;
                self.merge_if_complete(out);
                Ok(())
            }
            (Input::Report, Msg::Text(t)) => {
                let r = Report::parse(&t.data).map_err(|e| NodeError::malformed(format!("/scan/report: {e}")))?;
                let scan = r.scan_id();
                let merged = self.last_merged().filter(|(id, _)| *id == scan);
                self.keep_report(r);
                let unwritten = self.unwritten.as_ref().is_some_and(|u| u.span.scan_id == scan);
                match merged {
                    // Its files are still to write, with the account as it stands then.
                    Some(_) if unwritten => {}
                    // A report of a scan already merged: its account is written again, whole.
                    Some((id, names)) => {
                        log::info!("merger: scan {id}: a report arrived after the merge; scan_report.json written again");
                        let report = self.scan_report(id, &names);
                        self.write_report(id, &report);
                    }
                    None => self.merge_if_complete(out),
                }
                Ok(())
            }
            (Input::CameraInfo(i), Msg::CameraInfo(info)) => {
                let (w, h) = (info.width, info.height);
                if !xsurf_core::limits::image_side_ok(w) || !xsurf_core::limits::image_side_ok(h) {
                    return Err(NodeError::malformed(format!(
                        "camera_info size {w}x{h} is outside {} pixels a side",
                        xsurf_core::limits::image_side_text()
                    )));
                }
                self.camera_sizes.insert(i, (w, h));
                Ok(())
            }
            (Input::Events, Msg::ScanEvent(e)) => {
                match e.event {
                    ScanEvent::START => {
                        if self.pending_deadline.is_some() {
                            self.merge(out);
                        }
                        self.last_outputs.clear();
                        self.clouds.clear();
                        self.motion = None;
                        self.scan_id = e.scan_id;
                        self.scan_start_ns = Some(e.header.stamp.nanos());
                        self.scan_end_ns = None;
                        self.reports.retain(|(scan, _), _| *scan == e.scan_id);
                    }
                    ScanEvent::END => {
                        self.scan_id = e.scan_id;
                        self.scan_end_ns = Some(e.header.stamp.nanos());
                        self.pending_deadline = Some(e.header.stamp.nanos() + self.cfg.delay_ns);
                        self.merge_if_complete(out);
                    }
                    _ => {
                        self.pending_deadline = None;
                        self.clouds.clear();
                    }
                }
                Ok(())
            }
            (Input::Overlay, Msg::Marker(m)) => self.overlay(m),
            (Input::Tf, Msg::Tf(t)) => {
                for t in t.transforms.iter().filter(|t| {
                    t.header.frame_id.trim_start_matches('/') == self.cfg.table_frame
                        && t.child_frame_id.trim_start_matches('/') == self.cfg.carm_frame
                }) {
                    let pose = convert::rigid(t).map_err(NodeError::malformed)?;
                    self.motion = Some(self.motion.map_or(CarmMotion::start(pose), |m| m.then(pose)));
                }
                Ok(())
            }
            (Input::TfStatic, Msg::Tf(t)) => self.statics.add_static(t).map_err(NodeError::malformed),
            (port, m) => Err(NodeError::unexpected(port, m)),
        }
    }
    fn tick(&mut self, now_ns: i64, out: &mut Out) {
        // The files of a merge made while handling a message (its surface is out by now).
        self.write_unwritten();
        if self.pending_deadline.is_some_and(|d| now_ns >= d) {
            self.merge(out);
            // The bound: the surface waits for its files (the slower path anyway).
            self.write_unwritten();
        }
        self.last_outputs.tick(self.cfg.republish_ns, now_ns, out);
    }
    fn finish(&mut self, out: &mut Out) {
        if !self.merged_current {
            self.merge(out);
        }
        self.write_unwritten();
    }
    /// At once while a merged scan's files are still to write.
    fn next_tick_ns(&self) -> Option<i64> {
        self.unwritten.as_ref().map(|_| i64::MIN)
    }
    /// Bulk work: the live host runs it behind the frame path.
    fn bulk(&self) -> bool {
        true
    }
    fn problems(&self) -> Vec<String> {
        self.problems.clone()
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("merges", self.merges),
            ("points", self.points),
            ("triangles", self.triangles),
            ("bad_clouds", self.bad_clouds),
            ("bad_overlays", self.bad_overlays),
            ("fused_dropped", self.fused_dropped),
            ("refinements", self.refinements),
            ("refinements_refused", self.refinements_refused),
            ("seam_triangles", self.seam_triangles),
            ("write_errors", self.write_errors),
            ("dicom_scans", self.dicom_scans),
            ("pacs_queued", self.pacs_queued),
            ("pacs_sent", self.pacs.as_ref().map_or(0, |(_, s)| s.counts().sent.load(std::sync::atomic::Ordering::Relaxed))),
            (
                "pacs_failures",
                self.pacs.as_ref().map_or(0, |(_, s)| s.counts().failures.load(std::sync::atomic::Ordering::Relaxed)),
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use xsurf_core::geom::{Quat, Vec3};

    /// A turntable scan: `table -> carm` turns 358.45 degrees in steps. The refusal gives the
    /// whole turn, not the 1.55 degrees (or at most 180) between the first and the last pose.
    #[test]
    fn a_turn_is_reported_in_full() {
        let params = Params::resolve(&MergerParams::declarations(), &BTreeMap::new()).unwrap();
        let mut m = MergerNode::new(&params).unwrap();
        let steps = 200;
        let total = 358.45f64.to_radians();
        let mut out = Out::default();
        for k in 0..=steps {
            let pose =
                Iso3::from_parts(Vec3::ZERO, Quat::from_axis_angle(Vec3::Z, total * f64::from(k) / f64::from(steps)));
            let tf = TFMessage { transforms: vec![convert::transform_stamped(i64::from(k), "table", "carm", &pose)] };
            m.handle(Input::Tf, &Msg::Tf(Arc::new(tf)), &mut out).unwrap();
        }
        let names = vec!["cam1".to_string(), "cam2".to_string()];
        let (refined, records) = m.refine(&names, &mut [vec![Grid::new(1)], vec![Grid::new(1)]]);
        assert!(refined.is_empty());
        let why = records[0].reason.as_str();
        assert!(why.contains("turned 358.450 deg"), "{why}");
    }

    /// A cloud that contradicts its camera, or a late one of an earlier scan, is refused where
    /// it enters and counted; the camera's grid so far stays (issue 24).
    #[test]
    fn clouds_that_contradict_the_camera_or_the_scan_are_refused() {
        use xsurf_core::triangulate::Profile;
        let params = Params::resolve(&MergerParams::declarations(), &Default::default()).unwrap();
        let mut m = MergerNode::new(&params).unwrap();
        let mut out = Out::default();
        let cloud_of = |samples: usize, frames: usize, sec: i32, blocks: convert::Blocks| {
            let mut g = Grid::new(samples);
            for f in 0..frames {
                let p = Profile {
                    points: vec![[0.1 * f as f32, 0.2, 0.3]; samples],
                    intensity: vec![50.0; samples],
                    rgb: None,
                    range: vec![0.5; samples],
                    outside_volume: 0,
                };
                g.push(f as i64, &p).unwrap();
            }
            let mut h = xsurf_msgs::std_msgs::Header::default();
            h.stamp.sec = sec;
            Msg::Cloud(Arc::new(convert::grid_cloud_blocks(&g, h, blocks)))
        };
        let cloud = |samples, frames, sec| cloud_of(samples, frames, sec, convert::Blocks::ONE);
        let mut start = ScanEvent { scan_id: 4, event: ScanEvent::START, ..Default::default() };
        start.header.stamp.sec = 10;
        m.handle(Input::Events, &Msg::ScanEvent(Arc::new(start)), &mut out).unwrap();
        let info = CameraInfo { width: 64, height: 40, ..Default::default() };
        m.handle(Input::CameraInfo(0), &Msg::CameraInfo(Arc::new(info)), &mut out).unwrap();
        m.handle(Input::Cloud(0), &cloud(40, 5, 11), &mut out).unwrap();
        m.handle(Input::Cloud(0), &cloud(64, 6, 12), &mut out).unwrap(); // horizontal lines: one per column
        let e = m.handle(Input::Cloud(0), &cloud(10, 7, 13), &mut out).unwrap_err().to_string();
        assert!(e.contains("has 10 samples per frame; the camera's 64x40 images"), "{e}");
        let e = m.handle(Input::Cloud(0), &cloud(64, 8, 9), &mut out).unwrap_err().to_string();
        assert!(e.contains("older than scan 4's START at 10.000000000"), "{e}");
        assert_eq!(m.bad_clouds, 2);
        let (stamp, grid, _) = &m.clouds[&0];
        assert_eq!((*stamp, grid.samples(), grid.frames()), (12_000_000_000, 64, 6), "the last good cloud stays");
        // With second surfaces' lines (the field `layer`) a frame has twice the samples.
        let two = convert::Blocks { lasers: 0, layers: 2 };
        let e = m.handle(Input::Cloud(0), &cloud_of(40, 5, 13, two), &mut out).unwrap_err().to_string();
        assert!(e.contains("has 40 samples per frame; the camera's 64x40 images (camera_info) give 40 (vertical lines) or 64 (horizontal), times 1 laser(s) and 2 line(s) per laser"), "{e}");
        m.handle(Input::Cloud(0), &cloud_of(80, 5, 14, two), &mut out).unwrap();
        assert_eq!((m.clouds[&0].1.samples(), m.clouds[&0].2, m.bad_clouds), (80, 2, 3));
        // Camera 2 has no camera_info yet: its cloud is taken as it is.
        m.handle(Input::Cloud(1), &cloud(10, 3, 11), &mut out).unwrap();
        let bad = CameraInfo { width: 64, height: 0, ..Default::default() };
        assert!(m.handle(Input::CameraInfo(1), &Msg::CameraInfo(Arc::new(bad)), &mut out).is_err());
    }

    /// A scan event of scan `scan_id` stamped at `sec`.
    fn scan_event(scan_id: u32, event: u8, sec: i32) -> Msg {
        let mut e = ScanEvent { scan_id, event, ..Default::default() };
        e.header.stamp.sec = sec;
        Msg::ScanEvent(Arc::new(e))
    }

    /// A merger without refinement in a harness, with `output_dir` if given.
    fn merger_without_refinement(output_dir: Option<&std::path::Path>) -> xsurf_runtime::harness::Harness {
        use xsurf_runtime::params::ParamValue;
        let mut o = BTreeMap::new();
        o.insert("refine".to_string(), ParamValue::Bool(false));
        if let Some(dir) = output_dir {
            o.insert("output_dir".to_string(), ParamValue::String(dir.to_string_lossy().into()));
        }
        let params = Params::resolve(&MergerParams::declarations(), &o).unwrap();
        xsurf_runtime::harness::Harness::new(boxed(MergerNode::new(&params).unwrap()), "merger", "/")
    }

    /// A fresh output folder for a test named `tag`, and a merger without refinement writing there.
    fn merger_writing(tag: &str) -> (xsurf_runtime::harness::Harness, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("xsurf-merger-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        (merger_without_refinement(Some(&dir)), dir)
    }

    /// A mesher's report on `/scan/report`: 20 frames received and `lost` lost, and its final
    /// cloud (stamp, points) if given.
    fn mesher_report(cam: &str, scan: u32, lost: u64, final_cloud: Option<(&str, u64)>) -> Msg {
        let mut json = serde_json::json!({"node": "mesher", "camera": cam, "scan_id": scan, "aborted": false,
            "frames_expected": 20 + lost, "frames_received": 20, "frames_lost": lost, "frames_without_line": 0,
            "gaps": [], "points_rejected": 0, "profiles_refused": 0});
        if let Some((stamp, points)) = final_cloud {
            json["final_cloud"] = serde_json::json!({"stamp": stamp, "points": points});
        }
        Msg::Text(Arc::new(StringMsg { data: json.to_string() }))
    }

    /// A camera's grid of `frames` frames of `samples` points on a flat patch at height
    /// 0.02 + `dz`, stamped at `sec`.
    fn flat_cloud(samples: usize, frames: usize, dz: f32, sec: i32) -> Msg {
        use xsurf_core::triangulate::Profile;
        let mut g = Grid::new(samples);
        for f in 0..frames {
            let p = Profile {
                points: (0..samples).map(|s| [0.002 * s as f32, 0.002 * f as f32, 0.02 + dz]).collect(),
                intensity: vec![50.0; samples],
                rgb: None,
                range: vec![0.5; samples],
                outside_volume: 0,
            };
            g.push(i64::from(sec) * 1_000_000_000 + f as i64, &p).unwrap();
        }
        let mut h = xsurf_msgs::std_msgs::Header::default();
        h.stamp.sec = sec;
        Msg::Cloud(Arc::new(convert::grid_cloud(&g, h)))
    }

    /// The reports take other paths than the scan events: one that arrives before its scan's
    /// START is kept for it, and one that arrives after the merge has its scan's
    /// scan_report.json written again, whole; reports of other scans and cameras, and bad
    /// ones, are none of it.
    #[test]
    fn reports_before_the_scan_and_after_the_merge_reach_its_account() {
        let (mut h, dir) = merger_writing("reports");
        let event = |event, sec| scan_event(5, event, sec);
        let report = |json: serde_json::Value| Msg::Text(Arc::new(StringMsg { data: json.to_string() }));
        let mesher = |cam: &str, scan: u32, lost: u64| mesher_report(cam, scan, lost, None);
        h.feed("/scan/report", &mesher("cam1", 5, 2))
            .feed("/scan/report", &mesher("cam1", 4, 9))
            .feed("/scan/report", &mesher("cam9", 5, 9))
            .feed("/scan/report", &report(serde_json::json!({"node": "mesher", "scan_id": "five"})))
            .feed("/scan/events", &event(ScanEvent::START, 10))
            .feed("/cam1/cloud", &flat_cloud(30, 20, 0.0, 11))
            .feed("/cam2/cloud", &flat_cloud(30, 20, 0.0, 11))
            .feed("/scan/events", &event(ScanEvent::END, 12));
        assert_eq!(h.errors(), 1, "the bad report is refused");
        assert!(h.last_error().unwrap_or_default().contains("/scan/report: not a mesher report"), "{:?}", h.last_error());
        h.tick(13_100_000_000);
        let read = || -> serde_json::Value {
            serde_json::from_slice(&std::fs::read(dir.join("scan_5/scan_report.json")).unwrap()).unwrap()
        };
        let r = read();
        assert_eq!((r["merged"].clone(), r["incomplete"].clone()), (serde_json::json!(["cam1", "cam2"]), serde_json::json!(["cam1"])));
        assert_eq!(r["cameras"].as_array().unwrap().len(), 1, "{r}");
        assert_eq!(r["cameras"][0]["frames_lost"], 2, "{r}");
        h.feed("/scan/report", &mesher("cam2", 5, 0));
        let r = read();
        assert_eq!(r["cameras"].as_array().unwrap().len(), 2, "{r}");
        assert_eq!(r["cameras"][1]["camera"], "cam2", "{r}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The merge follows the last camera's final cloud (named by its mesher's report) at once,
    /// whichever of END, the reports and the clouds comes last; a cloud that is not the final
    /// one (another stamp, or as many points) does not start it, and the bound
    /// (`merge_delay_s`) then merges nothing twice.
    #[test]
    fn the_merge_follows_the_last_final_cloud_without_waiting() {
        let event = scan_event;
        let mesher = |cam: &str, scan: u32, stamp: &str, points: u64| mesher_report(cam, scan, 0, Some((stamp, points)));
        let (mut h, dir) = merger_writing("final");
        // END before the reports: the last of cam2's three messages merges.
        h.feed("/scan/events", &event(1, ScanEvent::START, 10))
            .feed("/cam1/cloud", &flat_cloud(30, 20, 0.0, 11))
            .feed("/cam2/cloud", &flat_cloud(30, 20, 0.0, 11))
            .feed("/scan/events", &event(1, ScanEvent::END, 14))
            .feed("/scan/report", &mesher("cam1", 1, "11.000000000", 600))
            .feed("/scan/report", &mesher("cam2", 1, "13.000000000", 600));
        assert!(h.take("/surface/mesh").is_empty(), "cam2's final cloud (at 13 s) is not in");
        h.feed("/cam2/cloud", &flat_cloud(30, 20, 0.0, 12));
        assert!(h.take("/surface/mesh").is_empty(), "a cloud at 12 s is not the final one");
        h.feed("/cam2/cloud", &flat_cloud(30, 20, 0.0, 13));
        assert_eq!(h.take("/surface/mesh").len(), 1, "merged with no tick, at the final cloud");
        assert!(!dir.join("scan_1/merged.ply").exists(), "the surface goes out before its files are written");
        h.tick(15_100_000_000);
        assert!(dir.join("scan_1/merged.ply").exists() && dir.join("scan_1/scan_report.json").exists());
        assert_eq!((h.counter("merges"), h.take("/surface/mesh").len()), (Some(1), 0), "the bound merges nothing twice");
        // The reports and clouds before END: END merges; a final cloud of as many points is
        // required.
        h.feed("/scan/events", &event(2, ScanEvent::START, 20))
            .feed("/cam1/cloud", &flat_cloud(30, 20, 0.0, 21))
            .feed("/cam2/cloud", &flat_cloud(30, 20, 0.0, 21))
            .feed("/scan/report", &mesher("cam1", 2, "21.000000000", 600))
            .feed("/scan/report", &mesher("cam2", 2, "21.000000000", 599))
            .feed("/scan/events", &event(2, ScanEvent::END, 22));
        assert!(h.take("/surface/mesh").is_empty(), "cam2's cloud in hand has 600 points, its final one 599");
        h.feed("/scan/report", &mesher("cam2", 2, "21.000000000", 600));
        assert_eq!(h.take("/surface/mesh").len(), 1);
        assert_eq!((h.counter("merges"), h.errors()), (Some(2), 0), "{:?}", h.last_error());
        h.finish();
        assert!(dir.join("scan_2/merged.ply").exists(), "finish writes what is unwritten");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Two cameras that see the same flat patch 0.3 mm apart (inside fuse_distance_m): after
    /// END and merge_delay_s, one layer is published on /surface/cloud and /surface/mesh,
    /// about one camera's points, not both; a camera 5 mm off (beyond it) stays a layer of its
    /// own.
    #[test]
    fn overlapping_cameras_merge_into_one_layer_after_the_delay() {
        let (samples, frames) = (30, 20);
        let cloud = |dz: f32, sec: i32| flat_cloud(samples, frames, dz, sec);
        let event = |event, sec| scan_event(3, event, sec);
        let merged_points = |dz: f32| {
            let mut h = merger_without_refinement(None);
            h.feed("/scan/events", &event(ScanEvent::START, 10))
                .feed("/cam1/cloud", &cloud(0.0, 11))
                .feed("/cam2/cloud", &cloud(dz, 11))
                .feed("/scan/events", &event(ScanEvent::END, 12));
            h.tick(12_500_000_000);
            assert!(h.take("/surface/cloud").is_empty(), "the merge waits merge_delay_s (1 s) after END");
            h.tick(13_100_000_000);
            let clouds = h.take("/surface/cloud");
            assert_eq!((clouds.len(), h.take("/surface/mesh").len(), h.errors()), (1, 1, 0), "{:?}", h.last_error());
            assert_eq!(h.counter("merges"), Some(1));
            let Msg::Cloud(c) = &clouds[0] else { panic!("a PointCloud2") };
            (c.width * c.height) as usize
        };
        let one = samples * frames;
        let fused = merged_points(0.0003);
        assert!(fused >= one * 9 / 10 && fused <= one * 11 / 10, "one layer: {fused} points of {one} a camera");
        let apart = merged_points(0.005);
        assert!(apart >= 2 * one * 9 / 10, "two layers 5 mm apart stay two: {apart}");
    }
}
