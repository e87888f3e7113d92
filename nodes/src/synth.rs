//! Writes a synthetic scan as a rosbag2 bag, as the live graph would record it: both cameras'
//! `image_raw` and `camera_info`, `/tf` (`table -> carm` at 100 Hz), `/tf_static`
//! (`carm -> <cam>_optical_frame`), `/joint_states` and `/scan/events`; plus the radiograph
//! taken during the scan (`xray.dcm`) and the ground truth beside it (`truth.json`,
//! `truth_<cam>.ply`, the rig and a params file).

use crate::convert;
use anyhow::Context;
use serde::Serialize;
use std::path::Path;
use xsurf_core::mesh::Mesh;
use xsurf_core::synth::Scanner;
use xsurf_formats::bag::{BagOptions, BagWriter, Qos};
use xsurf_formats::compressed::{encode, Codec};
use xsurf_msgs::sensor_msgs::{CameraInfo, CompressedImage, Image, JointState};
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::{cdr, RosMessage};

/// Rate of `/tf` and `/joint_states`, Hz.
pub const POSE_RATE_HZ: f64 = 100.0;
/// Simulated transport delay between exposure and recording, ns.
const IMAGE_LATENCY_NS: i64 = 4_000_000;

/// What was written.
#[derive(Debug, Clone, Serialize)]
pub struct SynthSummary {
    /// Scene name.
    pub scene: String,
    /// Frames per camera.
    pub frames: u32,
    /// Cameras.
    pub cameras: Vec<String>,
    /// Messages in the bag.
    pub messages: u64,
    /// Ground-truth points per camera.
    pub truth_points: Vec<usize>,
}

enum Item {
    Pose(i64),
    Frame(u32),
    Event(i64, u8),
}

fn put<M: RosMessage>(w: &mut BagWriter, topic: &str, t: i64, m: &M) -> anyhow::Result<()> {
    let bytes = cdr::encode(m)?;
    w.write(topic, t as u64, t as u64, &bytes)?;
    Ok(())
}

/// Bytes the synthetic scanner needs per image pixel and camera (ray table, sub-sample and
/// light buffers, the frame), measured: peak RSS 59 MB at 640x480 and 220 MB at 1280x960 with two
/// cameras.
const SYNTH_BYTES_PER_PIXEL: u64 = 90;

/// Memory this process can still use, bytes, and what limits it: the smallest of the system's
/// available memory, the cgroup's limit and the address-space limit.
fn memory_available() -> Option<(u64, &'static str)> {
    let mut best: Option<(u64, &'static str)> = None;
    let mut consider = |v: u64, what: &'static str| {
        if best.is_none_or(|(b, _)| v < b) {
            best = Some((v, what));
        }
    };
    let kb_field = |text: &str, key: &str| -> Option<u64> {
        let line = text.lines().find(|l| l.starts_with(key))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|k| k * 1024)
    };
    if let Some(v) = std::fs::read_to_string("/proc/meminfo").ok().and_then(|t| kb_field(&t, "MemAvailable:")) {
        consider(v, "available memory");
    }
    let read_u64 = |p: &str| std::fs::read_to_string(p).ok().and_then(|s| s.trim().parse::<u64>().ok());
    if let (Some(max), current) = (read_u64("/sys/fs/cgroup/memory.max"), read_u64("/sys/fs/cgroup/memory.current")) {
        consider(max.saturating_sub(current.unwrap_or(0)), "the cgroup's memory.max");
    }
    if let Some(limit) = rustix::process::getrlimit(rustix::process::Resource::As).current {
        let used = std::fs::read_to_string("/proc/self/status").ok().and_then(|t| kb_field(&t, "VmSize:")).unwrap_or(0);
        consider(limit.saturating_sub(used), "the address-space limit (ulimit -v)");
    }
    best
}

/// Refuses a scan that cannot fit in memory, with the figures, before any work.
pub fn check_memory(rig: &xsurf_core::rig::Rig) -> anyhow::Result<()> {
    let pixels: u64 = rig.cameras.iter().map(|c| u64::from(c.width) * u64::from(c.height)).sum();
    let need = (8 << 20) + pixels * SYNTH_BYTES_PER_PIXEL * 5 / 4;
    if let Some((available, what)) = memory_available() {
        if need > available {
            let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
            anyhow::bail!(
                "this scan ({} cameras, {:.1} Mpx in all) needs about {:.1} GiB of memory; {:.1} GiB is free under {what}: a smaller --size",
                rig.cameras.len(),
                pixels as f64 * 1e-6,
                gib(need),
                gib(available)
            );
        }
    }
    Ok(())
}

/// Renders `scanner`'s scan into the bag directory `dir` (which must not exist or be empty).
/// The cameras' images are `sensor_msgs/Image` on `/<cam>/image_raw`, or with `compressed`
/// (codec, JPEG quality) `sensor_msgs/CompressedImage` on `/<cam>/image_raw/compressed`, as
/// image_transport's compressed plugin records them.
///
/// The bag is written under a temporary name beside `dir` (`.<name>.partial`) and renamed when
/// it is complete, with its radiograph and truth: a failed run leaves no half-written bag.
pub fn write_bag(
    dir: &Path,
    scanner: &Scanner,
    zstd: bool,
    scan_id: u32,
    compressed: Option<(Codec, u8)>,
    progress: impl FnMut(u32, u32),
) -> anyhow::Result<SynthSummary> {
    check_memory(&scanner.rig)?;
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| anyhow::anyhow!("{}: not a folder name for a bag", dir.display()))?;
    if dir.exists() && std::fs::read_dir(dir).with_context(|| format!("{}", dir.display()))?.next().is_some() {
        anyhow::bail!("{} exists and is not empty: choose a new folder for the bag", dir.display());
    }
    let partial = dir.with_file_name(format!(".{name}.partial"));
    if partial.exists() {
        std::fs::remove_dir_all(&partial).with_context(|| format!("cannot clear {}", partial.display()))?;
    }
    match write_bag_into(&partial, &name, scanner, zstd, scan_id, compressed, progress) {
        Ok(summary) => {
            if dir.exists() {
                std::fs::remove_dir(dir).with_context(|| format!("cannot replace {}", dir.display()))?;
            }
            std::fs::rename(&partial, dir)
                .with_context(|| format!("cannot rename {} to {}", partial.display(), dir.display()))?;
            Ok(summary)
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(&partial);
            Err(e)
        }
    }
}

/// The bag's topics: each camera's images (raw or compressed) and camera_info, `/tf`,
/// `/tf_static`, `/joint_states` and the scan events.
fn add_topics(w: &mut BagWriter, rig: &xsurf_core::rig::Rig, compressed: bool) -> anyhow::Result<()> {
    for c in &rig.cameras {
        if compressed {
            w.add_topic(
                &format!("/{}/image_raw/compressed", c.name),
                CompressedImage::TYPE_NAME,
                &CompressedImage::definition(),
                &Qos::SENSOR,
            )?;
        } else {
            w.add_topic(&format!("/{}/image_raw", c.name), Image::TYPE_NAME, &Image::definition(), &Qos::SENSOR)?;
        }
        w.add_topic(
            &format!("/{}/camera_info", c.name),
            CameraInfo::TYPE_NAME,
            &CameraInfo::definition(),
            &Qos::SENSOR,
        )?;
    }
    w.add_topic("/tf", TFMessage::TYPE_NAME, &TFMessage::definition(), &Qos::RELIABLE)?;
    w.add_topic("/tf_static", TFMessage::TYPE_NAME, &TFMessage::definition(), &Qos::STATIC)?;
    w.add_topic("/joint_states", JointState::TYPE_NAME, &JointState::definition(), &Qos::RELIABLE)?;
    w.add_topic("/scan/events", ScanEvent::TYPE_NAME, &ScanEvent::definition(), &Qos::RELIABLE)?;
    Ok(())
}

/// What the bag holds, in the order of its log times: the C-arm's poses at `POSE_RATE_HZ` over
/// the scan and a margin, each frame (logged `IMAGE_LATENCY_NS` after its exposure), and START
/// and END; with the START and END stamps.
fn schedule(scanner: &Scanner) -> (Vec<(i64, Item)>, i64, i64) {
    let n = scanner.frame_count();
    let t0 = scanner.settings.start_stamp_ns;
    let margin = 0.1;
    let mut items: Vec<(i64, Item)> = Vec::new();
    let steps = ((scanner.duration_s() + 2.0 * margin) * POSE_RATE_HZ).ceil() as i64;
    for k in 0..=steps {
        let t = t0 + ((-margin + k as f64 / POSE_RATE_HZ) * 1e9).round() as i64;
        items.push((t, Item::Pose(t)));
    }
    for f in 0..n {
        let ft = scanner.frame_time(f);
        items.push((ft.stamp_ns + IMAGE_LATENCY_NS, Item::Frame(f)));
    }
    let start = t0 - 50_000_000;
    let end = t0 + (scanner.duration_s() * 1e9) as i64 + 50_000_000;
    items.push((start, Item::Event(start, ScanEvent::START)));
    items.push((end + IMAGE_LATENCY_NS + 1, Item::Event(end, ScanEvent::END)));
    items.sort_by_key(|(t, _)| *t);

    (items, start, end)
}

fn write_bag_into(
    dir: &Path,
    stem: &str,
    scanner: &Scanner,
    zstd: bool,
    scan_id: u32,
    compressed: Option<(Codec, u8)>,
    mut progress: impl FnMut(u32, u32),
) -> anyhow::Result<SynthSummary> {
    let rig = &scanner.rig;
    let mut w = BagWriter::create_with_stem(dir, stem, BagOptions { zstd })?;
    add_topics(&mut w, rig, compressed.is_some())?;
    let n = scanner.frame_count();
    let (items, start, end) = schedule(scanner);

    // Static transforms first, at the start.
    let statics = TFMessage {
        transforms: rig
            .cameras
            .iter()
            .map(|c| {
                convert::transform_stamped(start, "carm", &format!("{}_optical_frame", c.name), &c.carm_from_optical())
            })
            .collect(),
    };
    put(&mut w, "/tf_static", items[0].0, &statics)?;
    let models: Vec<_> = rig.cameras.iter().map(|c| c.model()).collect::<Result<_, _>>()?;
    for (t, item) in items {
        match item {
            Item::Pose(stamp) => {
                let s = scanner.seconds_of(stamp);
                let pose = scanner.pose_at(s);
                put(
                    &mut w,
                    "/tf",
                    t,
                    &TFMessage { transforms: vec![convert::transform_stamped(stamp, "table", "carm", &pose)] },
                )?;
                let js = JointState {
                    header: convert::header(stamp, ""),
                    name: vec!["carm_travel".into(), "carm_angle".into()],
                    position: vec![scanner.travel_at(s), 0.0],
                    velocity: vec![scanner.settings.speed_mps, 0.0],
                    effort: vec![],
                };
                put(&mut w, "/joint_states", t, &js)?;
            }
            Item::Frame(f) => {
                let ft = scanner.frame_time(f);
                for (ci, c) in rig.cameras.iter().enumerate() {
                    let frame = format!("{}_optical_frame", c.name);
                    let header = convert::header(ft.stamp_ns, &frame);
                    put(
                        &mut w,
                        &format!("/{}/camera_info", c.name),
                        t,
                        &convert::camera_info(&models[ci], header.clone()),
                    )?;
                    let frame = scanner.render(ci, f);
                    match compressed {
                        None => put(
                            &mut w,
                            &format!("/{}/image_raw", c.name),
                            t,
                            &crate::convert::image_msg(header, frame),
                        )?,
                        Some((codec, quality)) => {
                            let (format, data) = encode(&frame, codec, quality).map_err(anyhow::Error::msg)?;
                            let m = CompressedImage { header, format, data };
                            put(&mut w, &format!("/{}/image_raw/compressed", c.name), t, &m)?;
                        }
                    }
                }
                progress(f + 1, n);
            }
            Item::Event(stamp, event) => {
                let e = ScanEvent { header: convert::header(stamp, "table"), scan_id, event };
                put(&mut w, "/scan/events", t, &e)?;
            }
        }
    }
    let meta = w.finish()?;
    write_xray(&dir.join(XRAY_FILE), scanner, start, end)?;
    let truth = write_truth(dir, scanner)?;
    Ok(SynthSummary {
        scene: scanner.scene.name.clone(),
        frames: n,
        cameras: rig.cameras.iter().map(|c| c.name.clone()).collect(),
        messages: meta.message_count,
        truth_points: truth,
    })
}

/// Name of the synthetic radiograph beside the bag.
pub const XRAY_FILE: &str = "xray.dcm";

/// The synthetic radiograph of the scan (exposure from `start_ns` to `end_ns`, the scan's
/// START and END), written as a DICOM Digital X-Ray file.
pub fn write_xray(path: &Path, scanner: &Scanner, start_ns: i64, end_ns: i64) -> anyhow::Result<()> {
    use xsurf_core::xray::{DetectorGeometry, FanBeam, Placement};
    let settings = xsurf_core::synth::xray::XraySettings { seed: scanner.settings.seed, ..Default::default() };
    let plane = xsurf_core::geom::Plane::from_params(scanner.rig.laser_plane).context("rig laser_plane")?;
    let source = xsurf_core::geom::Vec3::from_array(scanner.rig.laser_source);
    let geometry = DetectorGeometry::default();
    let rows = (((end_ns - start_ns) as f64 * 1e-9) * settings.line_rate_hz).round().max(1.0) as u32;
    let placement = Placement {
        fan: FanBeam::new(&plane, source)?,
        geometry,
        detector_columns: settings.detector_columns,
        rows,
        start_ns,
        end_ns,
    };
    let image = xsurf_core::synth::xray::render_radiograph(&scanner.scene, &placement, &settings, &|t| {
        scanner.pose_at(scanner.seconds_of(t))
    });
    let info = xsurf_formats::dicom::XrayInfo {
        acquisition_start_ns: Some(start_ns),
        exposure_ms: Some((end_ns - start_ns) as f64 * 1e-6),
        source_detector_m: Some(geometry.source_detector_m),
        pixel_spacing_m: Some([geometry.pitch_m, geometry.pitch_m]),
    };
    let key = format!("xsurf-synth/{}/{}/{start_ns}", scanner.scene.name, scanner.settings.seed);
    xsurf_formats::dicom::write_file(path, &image, &info, &key)?;
    Ok(())
}

/// The ground truth beside a synthetic bag: `truth.json` (scene, scan settings, counts),
/// `truth_<cam>.ply` (the points each camera can observe on the sheet), `rig.yaml` and
/// `params.yaml` (the laser plane for `reconstruct`).
pub fn write_truth(dir: &Path, scanner: &Scanner) -> anyhow::Result<Vec<usize>> {
    let mut counts = Vec::new();
    let per_laser: Vec<Vec<usize>> = (0..scanner.rig.cameras.len())
        .map(|ci| {
            (0..scanner.lasers())
                .map(|l| (0..scanner.frame_count()).map(|f| scanner.observable_points_of(ci, l, f, 10.0).len()).sum())
                .collect()
        })
        .collect();
    for (ci, c) in scanner.rig.cameras.iter().enumerate() {
        let pts: Vec<[f32; 3]> = (0..scanner.frame_count())
            .flat_map(|f| scanner.observable_points(ci, f, 10.0))
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
        counts.push(pts.len());
        let mesh = Mesh { positions: pts, ..Default::default() };
        xsurf_formats::ply::write_file(&dir.join(format!("truth_{}.ply", c.name)), &mesh)?;
    }
    let s = &scanner.settings;
    let truth = serde_json::json!({
        "scene": scanner.scene.name,
        "frames": scanner.frame_count(),
        "speed_mps": s.speed_mps,
        "fps": s.fps,
        "seed": s.seed,
        "encoding": s.encoding.ros_name(),
        "travel_m": scanner.travel_range(),
        "laser_sheet_sigma_m": scanner.laser.sheet_sigma_m,
        "truth_points": counts,
        "lasers": scanner.rig.effective_lasers().iter().map(|l| l.name.clone()).collect::<Vec<_>>(),
        "truth_points_per_laser": per_laser,
        "truth_ply": "truth_<cam>.ply: points on the laser sheet each camera can observe (table frame, metres)",
    });
    xsurf_formats::write_bytes_atomic(&dir.join("truth.json"), serde_json::to_string_pretty(&truth)?.as_bytes())?;
    xsurf_formats::rig::write(&dir.join("rig.yaml"), &scanner.rig, "the rig this synthetic scan was rendered with")?;
    let p = scanner.rig.laser_plane;
    let mut params = format!(
        "# Parameters for reconstructing this synthetic scan (ROS 2 params-file format).\n/**:\n  ros__parameters:\n    laser_plane: [{}, {}, {}, {}]\n",
        p[0], p[1], p[2], p[3]
    );
    if !scanner.rig.lasers.is_empty() {
        params.push_str(&crate::lasers::params_yaml(&scanner.rig.lasers));
    }
    // Frames further apart than the meshes' default longest edge allows (a fast scan, or few
    // frames): the edge that still joins neighbouring frames, for the meshers and the merger.
    let spacing = s.speed_mps / s.fps;
    if 2.0 * spacing > f64::from(xsurf_core::mesh::MeshConfig::DEFAULT.max_edge_m) {
        params.push_str(&format!("    max_edge_m: {}\n", (2000.0 * spacing).ceil() / 1000.0));
    }
    // A camera on its side sees the line along its rows: its detector reads columns, and its
    // mesher takes a sample per column.
    for (ci, c) in scanner.rig.cameras.iter().enumerate() {
        if scanner.line_orientation(ci) == xsurf_core::edge::Orientation::Horizontal {
            for node in ["edge_detector", "mesher"] {
                params
                    .push_str(&format!("/{}/{node}:\n  ros__parameters:\n    line_orientation: horizontal\n", c.name));
            }
        }
    }
    xsurf_formats::write_bytes_atomic(&dir.join("params.yaml"), params.as_bytes())?;
    Ok(counts)
}
