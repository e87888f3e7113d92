//! `xsurf reconstruct BAG --out DIR`: the live graph's components driven from a bag.
//!
//! The cameras are the namespaces of the bag's `/<cam>/image_raw` topics. Each camera gets
//! `edge_detector`, `triangulator` and `mesher` in its namespace and one `merger` takes them
//! all, with parameters resolved exactly as for the live nodes `/<cam>/<node>` (`--params-file`
//! in the ROS 2 format). The meshers and the merger write the files; a bag with one scan has
//! them in `DIR`, several scans in `DIR/scan_<id>/`.

use crate::registry as components;
use anyhow::{bail, Context};
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;
use xsurf_formats::bag::Bag;
use xsurf_runtime::component::Msg;
use xsurf_runtime::params::ParamValue;
use xsurf_runtime::rosargs::{fq_name, RosArgs};
use xsurf_runtime::router::Router;

/// Options of a reconstruction.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The bag directory.
    pub bag: PathBuf,
    /// A ROS 2 params file.
    pub params_file: Option<PathBuf>,
    /// Output directory.
    pub out: PathBuf,
    /// Progress on stderr.
    pub progress: bool,
    /// A DICOM radiograph of the scan, placed under the surface.
    pub xray: Option<PathBuf>,
    /// Parameters for every node, as ROS 2 `-p` rules (`name:=value`), after the params file.
    pub params: Vec<String>,
}

/// Per-node figures in the report.
#[derive(Debug, Clone, Serialize)]
pub struct NodeReport {
    /// Fully qualified node name.
    pub node: String,
    /// Messages handled.
    pub messages: u64,
    /// Messages refused (bad input).
    pub errors: u64,
    /// The same by kind (`malformed`, `contradicts`, `not_ready`, `wrong_type`, `failed`).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub errors_by_kind: BTreeMap<&'static str, u64>,
    /// Time in the node, seconds.
    pub seconds: f64,
    /// The node's own counters.
    pub counters: BTreeMap<String, u64>,
    /// The last message it refused, and why.
    pub last_error: Option<String>,
    /// Failures not about one message (files it could not write), the most recent last.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub problems: Vec<String>,
}

/// What `report.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The bag read.
    pub bag: String,
    /// Cameras found.
    pub cameras: Vec<String>,
    /// Messages read from the bag.
    pub messages_read: u64,
    /// Images read per camera.
    pub frames_read: BTreeMap<String, u64>,
    /// Images in which a line was found, per camera.
    pub frames_with_line: BTreeMap<String, u64>,
    /// Points per camera triangulated from the lines (all scans).
    pub points: BTreeMap<String, u64>,
    /// Points per camera in its surface, `<cam>.ply`'s vertices (all scans): fewer than
    /// `points` by the samples the grid or the mesher set aside (a frame's duplicate row, a
    /// point no triangle uses).
    pub surface_points: BTreeMap<String, u64>,
    /// Triangles per camera (all scans).
    pub triangles: BTreeMap<String, u64>,
    /// Merged surface: points and triangles (all scans).
    pub merged_points: u64,
    /// Merged surface triangles.
    pub merged_triangles: u64,
    /// Scans reconstructed.
    pub scans: Vec<u32>,
    /// Frames missing from the stamp sequence, per camera.
    pub dropped_frames: BTreeMap<String, u64>,
    /// Seconds per stage (all cameras), and in total.
    pub timings_s: BTreeMap<String, f64>,
    /// Frames per second over the whole run (all cameras).
    pub frames_per_second: f64,
    /// Peak resident memory, bytes (VmHWM).
    pub peak_rss_bytes: Option<u64>,
    /// Set when the bag ended early (a truncated or corrupt file): what and where.
    pub truncated: Option<String>,
    /// Messages that could not be decoded, per topic.
    pub undecodable: BTreeMap<String, u64>,
    /// Topics in the bag that the reconstruction does not use.
    pub unused_topics: Vec<String>,
    /// Per-node details.
    pub nodes: Vec<NodeReport>,
    /// Files written, relative to the output directory.
    pub files: Vec<String>,
    /// The radiograph: placed, or why not (`None` without `--xray`).
    pub xray: Option<String>,
    /// Per scan, each camera's frames: expected from the stamps, received, lost (with the gaps'
    /// times), without a line, refused; and the cameras missing from the merge.
    pub scan_reports: Vec<serde_json::Value>,
    /// Why `report.json` itself could not be written (a full disk): a problem like any other
    /// file's, printed and counted in the exit code, not an abort that hides the others.
    #[serde(skip)]
    pub report_error: Option<String>,
}

/// Peak resident set size of this process (Linux), bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    proc_status_bytes("VmHWM:")
}

/// A memory field of `/proc/self/status` (`VmRSS:`, `VmHWM:`, ...), bytes (Linux).
pub fn proc_status_bytes(field: &str) -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(field))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Per-camera topics a reconstruction needs besides the images.
const USED_TYPES: &[(&str, &str)] = &[("camera_info", "sensor_msgs/msg/CameraInfo")];

/// The transport a camera's image readers (the per-camera nodes that declare `image_transport`)
/// take from a bag: the one the bag holds, or, where it holds both, the one their
/// `image_transport` parameter chooses (an error without it: the frames would be read twice).
fn image_transport(cam: &str, in_bag: &[&str], ros: &RosArgs) -> anyhow::Result<&'static str> {
    let ns = format!("/{cam}");
    let readers: Vec<String> = components::NODES
        .iter()
        .filter(|t| {
            t.role == components::Role::PerCamera && (t.declarations)().iter().any(|d| d.name == "image_transport")
        })
        .map(|t| fq_name(&ns, t.name))
        .collect();
    let mut chosen = None;
    for fq in &readers {
        chosen = match ros.param_overrides(fq)?.get("image_transport") {
            None => chosen,
            Some(ParamValue::String(s)) if s == "raw" => Some("raw"),
            Some(ParamValue::String(s)) if s == "compressed" => Some("compressed"),
            Some(v) => bail!("parameter {fq} image_transport: {v:?} is not raw or compressed"),
        };
    }
    let topic = |t: &str| if t == "raw" { format!("/{cam}/image_raw") } else { format!("/{cam}/image_raw/compressed") };
    match (chosen, in_bag) {
        (Some(c), _) if in_bag.contains(&c) => Ok(c),
        (Some(c), _) => bail!("camera {cam}: image_transport {c} chosen, but the bag has no {}", topic(c)),
        (None, [only]) => Ok(if *only == "raw" { "raw" } else { "compressed" }),
        (None, _) => bail!(
            "camera {cam}: the bag holds both {} and {}; choose one with the parameter image_transport (raw or compressed) of {} in --params-file",
            topic("raw"),
            topic("compressed"),
            readers.join(", ")
        ),
    }
}

/// Where the offline reader tells the xray_aligner (alone) the implicit scan of a bag without
/// `/scan/events`.
const IMPLICIT_SCAN_TOPIC: &str = "/xsurf/implicit_scan_events";

/// A START or END of scan 0 at `stamp_ns`.
fn scan_event(stamp_ns: i64, event: u8) -> Msg {
    Msg::ScanEvent(std::sync::Arc::new(xsurf_msgs::xsurf_msgs::ScanEvent {
        header: crate::convert::header(stamp_ns, "table"),
        scan_id: 0,
        event,
    }))
}

/// Files a reconstruction writes into its folder (besides `<cam>.ply`) and in `scan_<id>/`.
const OUTPUT_FILES: &[&str] = &[
    "merged.ply",
    "scene.wrl",
    "scene.glb",
    "preview.png",
    "xray.png",
    "xray.json",
    "surface.dcm",
    "points.dcm",
    "xray.dcm",
    "refinement.json",
    "scan_report.json",
    "report.json",
];

/// Removes an earlier reconstruction's files from `dir` (ours only, by name: `<cam>.ply` of
/// this bag's cameras, [`OUTPUT_FILES`], and `scan_<id>/` folders holding nothing else), so that
/// no stale surface sits beside the new one.
fn clear_outputs(dir: &Path, cameras: &[String]) -> anyhow::Result<()> {
    let ours = |name: &str| OUTPUT_FILES.contains(&name) || cameras.iter().any(|c| name == format!("{c}.ply"));
    let clear = |d: &Path| -> anyhow::Result<bool> {
        let mut only_ours = true;
        for e in std::fs::read_dir(d).with_context(|| format!("cannot read {}", d.display()))? {
            let e = e?;
            let name = e.file_name().to_string_lossy().into_owned();
            if e.file_type()?.is_file() && ours(&name) {
                std::fs::remove_file(e.path()).with_context(|| format!("cannot remove {}", e.path().display()))?;
            } else {
                only_ours = false;
            }
        }
        Ok(only_ours)
    };
    clear(dir)?;
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        let name = e.file_name().to_string_lossy().into_owned();
        let is_scan =
            name.strip_prefix("scan_").is_some_and(|id| !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()));
        if is_scan && e.file_type()?.is_dir() && clear(&e.path())? {
            std::fs::remove_dir(e.path()).with_context(|| format!("cannot remove {}", e.path().display()))?;
        }
    }
    Ok(())
}

/// What a reconstruction needs to know of a bag: its cameras and their image transports, and
/// whether it has scan events. Each topic the graph reads is checked for its type first, so a
/// wrong bag is named before any work.
struct BagTopics<'a> {
    /// Topic name to type.
    types: BTreeMap<&'a str, &'a str>,
    /// The cameras: namespaces of `/<cam>/image_raw` and `/<cam>/image_raw/compressed`.
    cameras: Vec<String>,
    /// Each camera's transports in the bag (`raw`, `compressed`).
    transports: BTreeMap<String, Vec<&'static str>>,
}

impl<'a> BagTopics<'a> {
    fn inspect(bag: &'a Bag, path: &Path) -> anyhow::Result<BagTopics<'a>> {
        let meta = &bag.metadata;
        let types: BTreeMap<&str, &str> = meta.topics.iter().map(|t| (t.name.as_str(), t.type_name.as_str())).collect();
        let mut cameras: Vec<String> = Vec::new();
        let mut transports: BTreeMap<String, Vec<&'static str>> = BTreeMap::new();
        for t in &meta.topics {
            let (ns, transport, ty) = if let Some(ns) = t.name.strip_suffix("/image_raw/compressed") {
                (ns, "compressed", "sensor_msgs/msg/CompressedImage")
            } else if let Some(ns) = t.name.strip_suffix("/image_raw") {
                (ns, "raw", "sensor_msgs/msg/Image")
            } else {
                continue;
            };
            let cam = ns.trim_start_matches('/');
            if cam.is_empty() || cam.contains('/') {
                bail!("topic {}: expected /<camera>/image_raw or /<camera>/image_raw/compressed", t.name);
            }
            if t.type_name != ty {
                bail!("topic {} has type {}, expected {ty}", t.name, t.type_name);
            }
            if !cameras.iter().any(|c| c == cam) {
                cameras.push(cam.to_string());
            }
            transports.entry(cam.to_string()).or_default().push(transport);
        }
        if cameras.is_empty() {
            bail!(
                "{}: no /<camera>/image_raw (or image_raw/compressed) topic in the bag (topics: {})",
                path.display(),
                meta.topics.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
            );
        }
        let bag_topics = BagTopics { types, cameras, transports };
        bag_topics.check_types()?;
        Ok(bag_topics)
    }

    /// The camera_info of every camera, `/tf` and `/tf_static` are there with their types, and
    /// `/scan/events` has its type if it is there.
    fn check_types(&self) -> anyhow::Result<()> {
        for cam in &self.cameras {
            for (suffix, ty) in USED_TYPES {
                let topic = format!("/{cam}/{suffix}");
                match self.types.get(topic.as_str()) {
                    None => bail!("no {topic} in the bag: camera {cam} cannot be triangulated without its intrinsics"),
                    Some(t) if t != ty => bail!("topic {topic} has type {t}, expected {ty}"),
                    _ => {}
                }
            }
        }
        for (topic, ty) in [("/tf", "tf2_msgs/msg/TFMessage"), ("/tf_static", "tf2_msgs/msg/TFMessage")] {
            match self.types.get(topic) {
                None => bail!(
                    "no {topic} in the bag: the frames cannot be placed (table -> carm and carm -> camera are needed)"
                ),
                Some(t) if *t != ty => bail!("topic {topic} has type {t}, expected {ty}"),
                _ => {}
            }
        }
        match self.types.get("/scan/events") {
            Some(t) if *t != "xsurf_msgs/msg/ScanEvent" => {
                bail!("topic /scan/events has type {t}, expected xsurf_msgs/msg/ScanEvent")
            }
            _ => Ok(()),
        }
    }

    /// A bag without `/scan/events` is one scan (scan 0, as the mesher and merger take it).
    fn implicit_scan(&self) -> bool {
        !self.types.contains_key("/scan/events")
    }
}

/// The ROS 2 arguments of a reconstruction: the params file, then the `-p` rules.
fn ros_args(opts: &Options) -> anyhow::Result<RosArgs> {
    let mut args: Vec<String> = vec!["--ros-args".into()];
    if let Some(f) = &opts.params_file {
        if let Some(why) = xsurf_formats::file_problem(f) {
            bail!("--params-file {}: {why}", f.display());
        }
        args.extend(["--params-file".into(), f.to_string_lossy().into_owned()]);
    }
    for p in &opts.params {
        args.extend(["-p".into(), p.clone()]);
    }
    Ok(RosArgs::parse(&args)?)
}

/// The processing graph of a bag in a [`Router`]: the registry's per-camera nodes in each
/// camera's namespace, the merger, and the X-ray aligner when a radiograph is given, with
/// parameters resolved as for the live nodes. Returns the router and, for a radiograph that
/// cannot be read, why (the surface is still reconstructed).
fn build_graph(topics: &BagTopics, ros: &RosArgs, opts: &Options) -> anyhow::Result<(Router, Option<String>)> {
    let out_dir = ParamValue::String(opts.out.to_string_lossy().into_owned());
    let mut router = Router::new();
    let build = |node: &str,
                 ns: &str,
                 extra: &[(&str, ParamValue)]|
     -> anyhow::Result<Box<dyn xsurf_runtime::component::AnyComponent>> {
        let fq = fq_name(ns, node);
        let (_, params) = components::resolve(node, &fq, ros, extra).map_err(anyhow::Error::msg)?;
        components::build(node, &params).with_context(|| format!("node {fq}"))
    };
    for cam in &topics.cameras {
        let ns = format!("/{cam}");
        let transport = image_transport(cam, &topics.transports[cam], ros)?;
        for node in components::NODES.iter().filter(|t| t.role == components::Role::PerCamera) {
            // What the bag and the command decide, given to each node that declares it: the
            // images' transport to the image readers, the output folder to the file writers; and
            // neither a growing surface nor a growing cloud from the meshers (offline nobody
            // watches them grow, and the merger merges the scan's final cloud).
            let declared = (node.declarations)();
            let extra: Vec<(&str, ParamValue)> = [
                ("image_transport", ParamValue::String(transport.into())),
                ("output_dir", out_dir.clone()),
                ("mesh_rate_hz", ParamValue::Double(0.0)),
                ("cloud_rate_hz", ParamValue::Double(0.0)),
            ]
            .into_iter()
            .filter(|(name, _)| declared.iter().any(|d| d.name == *name))
            .collect();
            router.add(build(node.name, &ns, &extra)?, node.name, &ns, &ros.remaps);
        }
    }
    let mut xray_error = None;
    if let Some(x) = &opts.xray {
        if let Some(why) = xsurf_formats::file_problem(x) {
            bail!("--xray {}: {why}", x.display());
        }
        // Read once up front so a bad file is named before the work starts; the surface is
        // still reconstructed when it cannot be placed.
        if let Err(e) = xsurf_formats::dicom::read_file(x) {
            log::error!("{e}; the surface is reconstructed without the radiograph");
            xray_error = Some(e.to_string());
        } else {
            let file = ParamValue::String(x.to_string_lossy().into_owned());
            // Without /scan/events the radiograph's exposure is the travel from the bag's first
            // frame to its last, given to the aligner alone as START and END on a topic of its own.
            let mut remaps = ros.remaps.clone();
            if topics.implicit_scan() {
                remaps.insert(
                    0,
                    xsurf_runtime::rosargs::Remap {
                        node: Some("xray_aligner".into()),
                        from: "/scan/events".into(),
                        to: IMPLICIT_SCAN_TOPIC.into(),
                    },
                );
            }
            router.add(
                build("xray_aligner", "/", &[("dicom_file", file), ("output_dir", out_dir.clone())])?,
                "xray_aligner",
                "/",
                &remaps,
            );
        }
    }
    // The merger's cameras: the bag's, or the ones its `cameras` parameter names (first = the
    // reference), each of which the bag must hold.
    let cameras = &topics.cameras;
    let merged_cameras = match ros.param_overrides(&fq_name("/", "merger"))?.get("cameras") {
        None => cameras.clone(),
        Some(ParamValue::StringArray(list)) => {
            if let Some(missing) = list.iter().find(|c| !cameras.contains(c)) {
                bail!(
                    "parameter /merger cameras names {missing:?}, which the bag does not hold (its cameras: {})",
                    cameras.join(", ")
                );
            }
            list.clone()
        }
        Some(v) => bail!("parameter /merger cameras: {v:?} is not a list of camera names"),
    };
    let cams_param = ParamValue::StringArray(merged_cameras);
    // The merger writes the DICOM files (the radiograph's patient and study with --xray); the
    // PACS is sent to by the command itself, after the files are complete.
    let mut merger =
        vec![("output_dir", out_dir), ("cameras", cams_param), ("pacs", ParamValue::String(String::new()))];
    if let (Some(x), None) = (&opts.xray, &xray_error) {
        merger.push(("dicom_file", ParamValue::String(x.to_string_lossy().into_owned())));
    }
    router.add(build("merger", "/", &merger)?, "merger", "/", &ros.remaps);
    Ok((router, xray_error))
}

/// The bag's messages fed to the graph in file order, with the progress on stderr: what the
/// graph computes itself, or no node reads, is passed over. Returns the images fed and the
/// seconds spent decoding.
struct Replay<'a> {
    router: &'a mut Router,
    /// Topics the graph computes itself (a bag recorded from a live graph holds its clouds,
    /// meshes and scan reports too); shared topics, `/tf` and the scan events, come from
    /// outside even where a node publishes.
    computed: std::collections::BTreeSet<String>,
    /// For a bag without scan events: the first and last image stamps so far.
    implicit_span: Option<Option<(i64, i64)>>,
    images: u64,
    read_s: f64,
}

impl<'a> Replay<'a> {
    fn new(router: &'a mut Router, implicit_scan: bool) -> Replay<'a> {
        let computed = router
            .output_topics()
            .into_iter()
            .filter(|(t, p)| !xsurf_runtime::router::is_shared(t, p.type_name))
            .map(|(t, _)| t)
            .collect();
        Replay { router, computed, implicit_span: implicit_scan.then_some(None), images: 0, read_s: 0.0 }
    }

    /// True for a topic of the bag the graph takes.
    fn takes(&self, topic: &str) -> bool {
        self.router.has_subscriber(topic) && !self.computed.contains(topic)
    }

    /// Feeds every message; a bag cut short ends the feed with its error in the report.
    fn run(&mut self, bag: &Bag, opts: &Options, report: &mut Report) {
        let total_images: u64 = report
            .cameras
            .iter()
            .map(|c| {
                let topic = match self.router.has_subscriber(&format!("/{c}/image_raw/compressed")) {
                    true => format!("/{c}/image_raw/compressed"),
                    false => format!("/{c}/image_raw"),
                };
                bag.metadata.topics.iter().find(|t| t.name == topic).map_or(0, |t| t.message_count)
            })
            .sum();
        let mut progress = Progress::new(opts.progress, total_images);
        // The bag's chunks are read and decompressed ahead on threads of their own (see
        // `Bag::messages`); the graph takes the messages in file order, so the results are
        // those of one thread.
        for m in bag.messages() {
            let m = match m {
                Ok(m) => m,
                Err(e) => {
                    log::error!("{e}; reconstructing what was read before it");
                    report.truncated = Some(e.to_string());
                    break;
                }
            };
            report.messages_read += 1;
            if self.takes(&m.topic) {
                self.feed(&m, report);
                progress.show(self.images);
            }
        }
        if let Some(Some((_, last))) = self.implicit_span {
            self.router.publish(IMPLICIT_SCAN_TOPIC, &scan_event(last, xsurf_msgs::xsurf_msgs::ScanEvent::END));
            self.router.tick(last);
        }
        self.router.finish();
        progress.end();
    }

    fn feed(&mut self, m: &xsurf_formats::bag::RawMessage, report: &mut Report) {
        let t_dec = Instant::now();
        let msg = match Msg::decode(&m.type_name, &m.data) {
            Ok(msg) => msg,
            Err(e) => {
                *report.undecodable.entry(m.topic.clone()).or_default() += 1;
                log::warn!("{} at {}: {e}", m.topic, crate::convert::fmt_stamp(m.log_time_ns as i64));
                return;
            }
        };
        self.read_s += t_dec.elapsed().as_secs_f64();
        if let Some(cam) = m.topic.strip_suffix("/image_raw").or_else(|| m.topic.strip_suffix("/image_raw/compressed"))
        {
            if let (Some(span), Some(stamp)) = (self.implicit_span.as_mut(), msg.stamp_ns()) {
                if span.is_none() {
                    self.router
                        .publish(IMPLICIT_SCAN_TOPIC, &scan_event(stamp, xsurf_msgs::xsurf_msgs::ScanEvent::START));
                }
                let (a, z) = span.unwrap_or((stamp, stamp));
                *span = Some((a.min(stamp), z.max(stamp)));
            }
            self.images += 1;
            *report.frames_read.entry(cam.trim_start_matches('/').to_string()).or_default() += 1;
        }
        // The time reaches the message before it arrives: what was due earlier happens first,
        // as it does live (a mesher closes a scan at END and its grace; the merger merges at its
        // bound) and not after a message that came later (the next scan's START, which would
        // have the merger merge the earlier scan without its final clouds).
        let now = m.log_time_ns as i64;
        self.router.tick(now);
        self.router.publish(&m.topic, &msg);
        self.router.tick(now);
    }
}

/// The progress of a reconstruction on stderr: a bar on a terminal, a line every 2 s otherwise.
struct Progress {
    on: bool,
    tty: bool,
    total: u64,
    started: Instant,
    last: Instant,
}

impl Progress {
    fn new(on: bool, total: u64) -> Progress {
        let now = Instant::now();
        Progress { on, tty: on && std::io::stderr().is_terminal(), total, started: now, last: now }
    }
    fn show(&mut self, images: u64) {
        if !self.on || self.last.elapsed().as_secs_f64() <= if self.tty { 0.2 } else { 2.0 } {
            return;
        }
        self.last = Instant::now();
        let fps = images as f64 / self.started.elapsed().as_secs_f64().max(1e-9);
        let total = self.total;
        if self.tty {
            let w = 30usize;
            let done = ((images as f64 / total.max(1) as f64) * w as f64) as usize;
            eprint!(
                "\r[{}{}] {images}/{total} frames, {fps:.0} frames/s ",
                "#".repeat(done.min(w)),
                " ".repeat(w - done.min(w))
            );
        } else {
            eprintln!("reconstruct: {images}/{total} frames, {fps:.0} frames/s");
        }
    }
    fn end(&self) {
        if self.tty {
            eprintln!();
        }
    }
}

impl Report {
    /// An empty report of `bag`, listing the topics the graph does not take.
    fn start(opts: &Options, topics: &BagTopics, bag: &Bag, replay: &Replay) -> Report {
        Report {
            bag: opts.bag.display().to_string(),
            cameras: topics.cameras.clone(),
            messages_read: 0,
            frames_read: BTreeMap::new(),
            frames_with_line: BTreeMap::new(),
            points: BTreeMap::new(),
            triangles: BTreeMap::new(),
            surface_points: BTreeMap::new(),
            merged_points: 0,
            merged_triangles: 0,
            scans: Vec::new(),
            dropped_frames: BTreeMap::new(),
            timings_s: BTreeMap::new(),
            frames_per_second: 0.0,
            peak_rss_bytes: None,
            truncated: None,
            undecodable: BTreeMap::new(),
            unused_topics: bag
                .metadata
                .topics
                .iter()
                .filter(|t| !replay.takes(&t.name))
                .map(|t| t.name.clone())
                .collect(),
            nodes: Vec::new(),
            files: Vec::new(),
            xray: None,
            scan_reports: Vec::new(),
            report_error: None,
        }
    }

    /// The figures of every node (its counters), and the time each stage took.
    fn collect(&mut self, router: &Router, implicit_scan: bool, xray_error: Option<String>) {
        for n in router.nodes() {
            let counters: BTreeMap<String, u64> =
                n.component.counters().into_iter().map(|(k, v)| (k.to_string(), v)).collect();
            let cam = n.namespace.trim_start_matches('/').to_string();
            self.take_figures(n.component.as_any(), cam, implicit_scan, n.last_error.as_deref());
            *self.timings_s.entry(n.name.clone()).or_default() += n.busy_ns as f64 * 1e-9;
            self.nodes.push(NodeReport {
                node: n.fq_name(),
                messages: n.handled,
                errors: n.errors,
                errors_by_kind: n.errors_by_kind.clone(),
                seconds: n.busy_ns as f64 * 1e-9,
                counters,
                last_error: n.last_error.clone(),
                problems: n.component.problems(),
            });
        }
        if let Some(e) = xray_error {
            self.xray = Some(format!("not placed: {e}"));
        }
    }

    /// The figures of one node, read from its own type.
    fn take_figures(&mut self, node: &dyn std::any::Any, cam: String, implicit_scan: bool, last_error: Option<&str>) {
        if let Some(e) = node.downcast_ref::<crate::edge_detector::EdgeDetectorNode>() {
            self.frames_with_line.insert(cam, e.frames_with_line());
        } else if let Some(t) = node.downcast_ref::<crate::triangulator::TriangulatorNode>() {
            self.points.insert(cam, t.points());
        } else if let Some(m) = node.downcast_ref::<crate::mesher::MesherNode>() {
            self.triangles.insert(cam.clone(), m.triangles());
            self.surface_points.insert(cam.clone(), m.mesh_points());
            self.dropped_frames.insert(cam, m.dropped_frames());
        } else if let Some(m) = node.downcast_ref::<crate::merger::MergerNode>() {
            self.merged_points = m.points();
            self.merged_triangles = m.triangles();
        } else if let Some(x) = node.downcast_ref::<crate::xray_aligner::XrayAlignerNode>() {
            self.xray = Some(if x.placed() > 0 && implicit_scan {
                "placed (exposure: the bag's first to last frame, as it has no /scan/events)".to_string()
            } else if x.placed() > 0 {
                "placed".to_string()
            } else {
                format!("not placed: {}", last_error.unwrap_or("see the log"))
            });
        }
    }

    /// The scans' folders: their ids and scan reports; one scan's files are moved up into
    /// `out` itself. Then the list of files and `report.json`.
    fn finish_files(&mut self, out: &Path) -> anyhow::Result<()> {
        let mut scan_dirs: Vec<(u32, PathBuf)> = std::fs::read_dir(out)?
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                let id = name.strip_prefix("scan_")?.split('_').next()?.parse().ok()?;
                e.path().is_dir().then_some((id, e.path()))
            })
            .collect();
        scan_dirs.sort();
        self.scans = scan_dirs.iter().map(|s| s.0).collect();
        // Each scan's account of its frames (the merger's scan_report.json), in report.json too.
        for (_, dir) in &scan_dirs {
            if let Some(v) =
                std::fs::read(dir.join("scan_report.json")).ok().and_then(|b| serde_json::from_slice(&b).ok())
            {
                self.scan_reports.push(v);
            }
        }
        if let [(_, dir)] = scan_dirs.as_slice() {
            for e in std::fs::read_dir(dir)?.filter_map(|e| e.ok()) {
                std::fs::rename(e.path(), out.join(e.file_name()))?;
            }
            std::fs::remove_dir(dir)?;
        }
        self.files = list_files(out, out);
        self.files.push("report.json".into());
        self.peak_rss_bytes = peak_rss_bytes();
        let json = serde_json::to_string_pretty(&self)?;
        if let Err(e) = xsurf_formats::write_bytes_atomic(&out.join("report.json"), json.as_bytes()) {
            self.files.retain(|f| f != "report.json");
            self.report_error = Some(e.to_string());
        }
        Ok(())
    }
}

/// Runs the reconstruction and writes the files and `report.json`: the bag's topics checked,
/// the output folder cleared of an earlier reconstruction, the graph built, the bag replayed
/// through it, the figures collected and the files put in place.
pub fn reconstruct(opts: &Options) -> anyhow::Result<Report> {
    let t_start = Instant::now();
    let bag = Bag::open(&opts.bag)?;
    if bag.indexed.is_some() {
        log::warn!(
            "{}: no metadata.yaml; read from its storage files (`xsurf bag reindex {}` writes one)",
            opts.bag.display(),
            opts.bag.display()
        );
    }
    let topics = BagTopics::inspect(&bag, &opts.bag)?;
    if opts.out.as_os_str().is_empty() {
        bail!("--out: an empty path; name the folder the reconstruction is written to");
    }
    std::fs::create_dir_all(&opts.out).with_context(|| format!("cannot create {}", opts.out.display()))?;
    clear_outputs(&opts.out, &topics.cameras)?;
    let ros = ros_args(opts)?;
    let (mut router, xray_error) = build_graph(&topics, &ros, opts)?;
    // Nothing outside the graph reads it: what no node takes (the meshes' markers) is not built.
    router.quiet_unheard();
    let mut replay = Replay::new(&mut router, topics.implicit_scan());
    let mut report = Report::start(opts, &topics, &bag, &replay);
    replay.run(&bag, opts, &mut report);
    let (images, read_s) = (replay.images, replay.read_s);
    report.collect(&router, topics.implicit_scan(), xray_error);
    report.timings_s.insert("decode".into(), read_s);
    let total = t_start.elapsed().as_secs_f64();
    report.timings_s.insert("total".into(), total);
    report.frames_per_second = images as f64 / total.max(1e-9);
    report.finish_files(&opts.out)?;
    Ok(report)
}

impl Report {
    /// Problems that make the result incomplete, one line each: a truncated bag, a camera
    /// that produced no points (with the last reason its nodes gave), refused messages.
    pub fn problems(&self) -> Vec<String> {
        let mut v = Vec::new();
        if let Some(t) = &self.truncated {
            v.push(format!("the bag ended early; reconstructed up to the cut: {t}"));
        }
        for c in &self.cameras {
            if self.frames_read.get(c).copied().unwrap_or(0) > 0 && self.points.get(c).copied().unwrap_or(0) == 0 {
                let why = self
                    .nodes
                    .iter()
                    .filter(|n| n.node.starts_with(&format!("/{c}/")))
                    .find_map(|n| {
                        n.last_error.clone().map(|e| format!("{} refused {} message(s), last: {e}", n.node, n.errors))
                    })
                    .unwrap_or_else(|| "no laser line was found in any frame".into());
                v.push(format!("camera {c}: no points: {why}"));
            }
        }
        if let Some(x) = self.xray.as_ref().filter(|x| x.starts_with("not placed")) {
            v.push(format!("radiograph {x}"));
        }
        for (topic, n) in &self.undecodable {
            v.push(format!("{n} message(s) on {topic} could not be decoded"));
        }
        for n in &self.nodes {
            if let Some(&k) = n.counters.get("write_errors").filter(|&&k| k > 0) {
                let last = n.problems.last().map_or_else(|| "see the log".to_string(), |p| format!("last: {p}"));
                v.push(format!("{}: {k} file(s) could not be written ({last})", n.node));
            }
        }
        if let Some(e) = &self.report_error {
            v.push(format!("report.json could not be written: {e}"));
        }
        v
    }
}

fn list_files(root: &Path, dir: &Path) -> Vec<String> {
    let mut v = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.filter_map(|e| e.ok()) {
            let p = e.path();
            if p.is_dir() {
                v.extend(list_files(root, &p));
            } else if let Ok(rel) = p.strip_prefix(root) {
                let s = rel.to_string_lossy().into_owned();
                if !s.ends_with(".tmp") && s != "report.json" {
                    v.push(s);
                }
            }
        }
    }
    v.sort();
    v
}
