//! Our nodes over DDS, as separate processes inside a private network namespace
//! (`../shared/tools/netns-run`): `edge_detector` and `triangulator` in /cam1 with a params file
//! and a remap, fed by `xsurf bag play`; an independent DDS implementation (Python `cyclonedds`)
//! subscribes their PointCloud2 and the TFMessages, and publishes an Image that our
//! `edge_detector` answers. The points that crossed DDS are checked against the ground truth.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;
use std::path::Path;
use std::process::Command;
use xsurf_core::eval;

#[test]
fn nodes_exchange_images_and_clouds_with_an_independent_dds_peer() {
    graph("separate", "edge_detector_cam1.log", "[0, 0, 0, 0]");
}

#[test]
fn composed_nodes_pass_messages_in_memory_and_still_publish_on_dds() {
    graph("composed", "compose.log", "[0, 0, 0]");
}

fn graph(mode: &str, cam1_log: &str, exits: &str) {
    let _turn = one_graph_at_a_time();
    let Some(py) = python() else { return };
    let netns = root().join("../shared/tools/netns-run");
    assert!(netns.is_file(), "{} is needed to keep DDS on this machine", netns.display());
    let bin_dir = std::path::Path::new(env!("CARGO_BIN_EXE_xsurf")).parent().unwrap();
    let out = scratch(&format!("dds-{mode}"));
    // A params file in the ROS 2 format: the laser plane for every node, a method for cam1.
    let params = out.join("params.yaml");
    std::fs::write(&params, "/**:\n  ros__parameters:\n    laser_plane: [0.0, 1.0, 0.0, 0.0]\n/cam1/edge_detector:\n  ros__parameters:\n    method: gaussian\n").unwrap();
    let run = Command::new(&netns)
        .arg(&py)
        .arg(root().join("tests/py/dds_graph.py"))
        .arg(bin_dir)
        .arg(pyramid_bag())
        .arg(&params)
        .arg(out.join("run"))
        .arg(mode)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "dds_graph.py failed:\n{stdout}\n{}", String::from_utf8_lossy(&run.stderr));
    let s: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    // Every frame's profile arrived, well formed, in table.
    assert_eq!(s["clouds"], 78, "{s}");
    assert_eq!(s["cloud_errors"], serde_json::json!([]), "{s}");
    assert!(s["tf"].as_u64().unwrap() >= 270, "{s}");
    assert_eq!(s["tf_frames"], serde_json::json!(["table->carm"]));
    // The image Cyclone DDS published was seen by our edge_detector (line at column 30.25).
    let lines = s["lines"].as_array().unwrap();
    assert!(!lines.is_empty(), "no LaserLine from /cam9/edge_detector: {s}");
    for l in lines {
        assert_eq!(l["found"], 8);
        assert!((l["mean_u"].as_f64().unwrap() - 30.25).abs() < 0.05, "{l}");
        assert_eq!(l["frame_id"], "cam9_optical_frame");
    }
    // CompressedImage from Cyclone DDS (Pillow's PNG and JPEG) decoded by an edge_detector with
    // image_transport compressed; the truncated JPEG between them is refused by name, and costs
    // only itself.
    let c = s["compressed_lines"].as_array().unwrap();
    let stamps: Vec<u64> = c.iter().map(|l| l["stamp"][1].as_u64().unwrap()).collect();
    assert_eq!(stamps, [0, 2], "PNG and JPEG answered, the truncated one not: {s}");
    for l in c {
        assert_eq!(l["found"], 8, "{l}");
        assert!((l["mean_u"].as_f64().unwrap() - 30.25).abs() < 0.1, "{l}");
    }
    let log8 = std::fs::read_to_string(out.join("run/edge_detector_cam8.log")).unwrap();
    assert!(log8.contains("compressed image at 150.000000001") && log8.contains("JPEG"), "{log8}");
    // Parameter services: list, get, a refused set with the reason, a valid set that changes behaviour.
    let p = &s["param"];
    assert_eq!(p["list"]["code"], 0, "{p}");
    for name in ["method", "min_strength", "roi.x_offset", "line_orientation", "use_sim_time"] {
        assert!(p["list"]["out"].as_str().unwrap().contains(name), "{name} not listed: {p}");
    }
    assert_eq!(p["get"]["out"], "double value is: 30.0", "{p}");
    assert_ne!(p["set_bad_method"]["code"], 0);
    assert!(p["set_bad_method"]["out"].as_str().unwrap().contains("unknown method \"bogus\""), "{p}");
    // The reason once: on stdout as `ros2 param set` prints it, not again in the error line.
    assert!(!p["set_bad_method"]["err"].as_str().unwrap().contains("unknown method"), "{p}");
    assert_ne!(p["set_bad_type"]["code"], 0);
    assert!(
        p["set_bad_type"]["out"]
            .as_str()
            .unwrap()
            .contains("Cannot change type of parameter 'min_strength' from Double to String"),
        "{p}"
    );
    assert_eq!(p["set_high_threshold"]["code"], 0, "{p}");
    assert_eq!(p["get_after"]["out"], "double value is: 250.0", "{p}");
    let after = s["lines_after_set"].as_array().unwrap();
    assert!(
        !after.is_empty() && after.iter().all(|l| l["found"] == 0),
        "a 200-level line must fall below min_strength 250: {s}"
    );
    assert_eq!(s["player_exit"], 0);
    assert_eq!(s["node_exits"].to_string().replace(',', ", "), exits, "nodes leave cleanly on SIGTERM");
    assert!(s["cam1_lines"].as_u64().unwrap() >= 70, "/cam1/laser_line is visible on DDS: {s}");
    // Clean shutdowns log no error, and no warning about ROS_DISTRO (there is no ROS install).
    for e in std::fs::read_dir(out.join("run")).unwrap() {
        let path = e.unwrap().path();
        if path.extension().is_some_and(|x| x == "log") {
            let log = std::fs::read_to_string(&path).unwrap();
            for bad in ["Cannot notify spin task", "ROS_DISTRO is not set"] {
                assert!(!log.contains(bad), "{}: {bad}\n{log}", path.display());
            }
        }
    }
    // The params file reached the right node only.
    let log1 = std::fs::read_to_string(out.join("run").join(cam1_log)).unwrap();
    assert!(log1.contains("/cam1/edge_detector: parameter method = gaussian"), "{log1}");
    let log9 = std::fs::read_to_string(out.join("run/edge_detector_cam9.log")).unwrap();
    assert!(!log9.contains("method = gaussian") && log9.contains("parameter min_strength = 30"), "{log9}");
    // The points that crossed DDS against the truth.
    let raw = std::fs::read(out.join("run/points.f32")).unwrap();
    let pts: Vec<[f32; 3]> = raw
        .chunks_exact(12)
        .map(|c| {
            let f = |k: usize| f32::from_le_bytes([c[k], c[k + 1], c[k + 2], c[k + 3]]);
            [f(0), f(4), f(8)]
        })
        .collect();
    let scene = xsurf_core::synth::Scene::by_name("pyramid").unwrap();
    let acc = eval::accuracy(eval::surface_errors(&scene, &pts));
    assert!(acc.points > 15_000, "{acc:?}");
    assert!(acc.rms_m < 0.001 && acc.outlier_fraction_2mm < 0.005, "{acc:?}");
    std::fs::remove_dir_all(&out).unwrap();
}

/// `xsurf compose NODE_TYPE --help` prints what the node type's own executable prints: a node
/// type without an executable of its own has its help there.
#[test]
fn a_node_types_help_comes_from_the_one_binary_too() {
    for spec in ["merger", "/cam1/mesher", "/cam1/m=mesher"] {
        let out = xsurf(&["compose", spec, "--help"]);
        let node = spec.rsplit(['/', '=']).next().unwrap();
        let exe = std::path::Path::new(env!("CARGO_BIN_EXE_xsurf")).with_file_name(node);
        let own = Command::new(exe).arg("--help").output().unwrap();
        assert!(out.status.success() && out.stdout == own.stdout, "{spec}: {}", String::from_utf8_lossy(&out.stdout));
        assert!(String::from_utf8_lossy(&out.stdout).contains("parameters (name, type, default, unit: meaning):"));
    }
}

/// Malformed command lines, parameters and environment stop a node before it opens DDS:
/// exit code 2 and one line naming the problem.
#[test]
fn node_executables_refuse_bad_input_with_exit_2() {
    let run = |bin: &str, args: &[&str], env: &[(&str, &str)]| {
        let mut c = Command::new(bin);
        c.args(args);
        for (k, v) in env {
            c.env(k, v);
        }
        c.output().unwrap()
    };
    let ed = env!("CARGO_BIN_EXE_edge_detector");
    assert_clean_failure(&run(ed, &["--ros-args", "--bogus"], &[]), 2, "unknown ROS argument \"--bogus\"");
    assert_clean_failure(
        &run(ed, &["--ros-args", "-p", "method:=nope"], &[]),
        2,
        "/edge_detector: parameter method: unknown method \"nope\"",
    );
    assert_clean_failure(
        &run(ed, &["--ros-args", "-p", "min_strength:=high"], &[]),
        2,
        "parameter min_strength: expected double, got string",
    );
    assert_clean_failure(
        &run(ed, &["--ros-args", "-p", "qos.sensor.reliability:=sometimes"], &[]),
        2,
        "qos.sensor.reliability",
    );
    assert_clean_failure(&run(ed, &["stray"], &[]), 2, "unexpected arguments");
    // Help and version, without DDS: the topics and every declared parameter.
    for node in ["edge_detector", "triangulator", "c_arm_pose", "camera_driver"] {
        let bin = std::path::Path::new(env!("CARGO_BIN_EXE_xsurf")).with_file_name(node);
        let out = run(bin.to_str().unwrap(), &["--help"], &[]);
        assert!(out.status.success(), "{node} --help");
        let text = String::from_utf8_lossy(&out.stdout);
        for d in xsurf_nodes::registry::declarations(node).unwrap() {
            let line = text.lines().find(|l| l.starts_with(&format!("  {} (", d.name)));
            let line = line.unwrap_or_else(|| panic!("{node} --help lacks {}:\n{text}", d.name));
            // Type, default and unit, as `ros2 param describe` gives them.
            assert!(line.contains(d.default.type_name()) && line.contains(&format!("default {}", d.default)), "{line}");
            assert!(d.unit.is_empty() || line.contains(&format!(" {}):", d.unit)), "{node}: no unit in {line}");
        }
        assert!(text.contains("publishes:") && text.contains("services:"), "{text}");
        let v = run(bin.to_str().unwrap(), &["--version"], &[]);
        assert!(v.status.success() && String::from_utf8_lossy(&v.stdout).starts_with(node));
    }
    let out = run(ed, &["--help"], &[]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("image_raw                    sensor_msgs/msg/Image"));
    let out = xsurf(&["compose", "--help"]);
    assert!(out.status.success() && String::from_utf8_lossy(&out.stdout).contains("node types: camera_driver"));
    let out = xsurf(&["--version"]);
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), format!("xsurf {}", env!("CARGO_PKG_VERSION")));
    // A parameter the node does not have is named in a warning (before the bad value stops it).
    let out = run(ed, &["--ros-args", "-p", "nope:=3", "-p", "min_strength:=banana"], &[]);
    assert_clean_failure(&out, 2, "min_strength");
    assert!(String::from_utf8_lossy(&out.stderr).contains("parameter nope is not a parameter of edge_detector"));
    // Numbers are echoed as written, not at full binary length (1e308 was 309 digits).
    let pose = env!("CARGO_BIN_EXE_c_arm_pose");
    let out = run(pose, &["--ros-args", "-p", "speed:=1e308"], &[]);
    assert_clean_failure(&out, 2, "parameter speed: 1e308 m/s is not in (0.0, 2.0)");
    assert!(out.stderr.len() < 200, "{}", String::from_utf8_lossy(&out.stderr));
    let tr = env!("CARGO_BIN_EXE_triangulator");
    assert_clean_failure(
        &run(tr, &["--ros-args", "--params-file", "/nonexistent/p.yaml"], &[]),
        2,
        "params file /nonexistent/p.yaml",
    );
    assert_clean_failure(&run(tr, &["--ros-args", "-p", "laser_plane:=[0, 0, 0, 1]"], &[]), 2, "laser_plane");
    assert_clean_failure(&run(tr, &[], &[("ROS_DOMAIN_ID", "999")]), 2, "ROS_DOMAIN_ID=\"999\"");
    assert_clean_failure(&xsurf(&["compose", "/cam1/teapot"]), 2, "unknown node type \"teapot\"");
    // A node that is not there: said within two seconds, given up after the timeout.
    let netns = root().join("../shared/tools/netns-run");
    let t0 = std::time::Instant::now();
    let out = Command::new(&netns)
        .arg(env!("CARGO_BIN_EXE_xsurf"))
        .args(["param", "list", "/nosuch", "--timeout", "3"])
        .env("ROS_LOCALHOST_ONLY", "1")
        .output()
        .unwrap();
    assert_clean_failure(&out, 1, "no answer from the parameter services of /nosuch within 3 s");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("waiting for the parameter services of /nosuch (ROS_DOMAIN_ID"), "{err}");
    assert!(t0.elapsed().as_secs_f64() < 10.0, "{:?}", t0.elapsed());
}

/// `xsurf bag record` while `xsurf bag play` publishes a synthetic scan: every message of every
/// topic comes back, in order, byte for byte, with the QoS of its class; the same for a scan
/// whose cameras are `sensor_msgs/CompressedImage` (JPEG) on `/<cam>/image_raw/compressed`.
#[test]
fn record_then_play_round_trips_every_message() {
    let out = scratch("record-play");
    let compressed = out.join("compressed-src");
    let made = xsurf(&[
        "synth",
        "pyramid",
        "-o",
        compressed.to_str().unwrap(),
        "--size",
        "320x240",
        "--speed",
        "0.14",
        "--compressed",
        "jpeg",
    ]);
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    for (k, src_bag) in [pyramid_bag(), compressed.as_path()].into_iter().enumerate() {
        record_and_play(src_bag, &out.join(format!("run{k}")));
    }
    std::fs::remove_dir_all(&out).unwrap();
}

/// Runs `tests/<script> BIN_DIR SRC_BAG REC_DIR OUT/logs` inside the network namespace, after
/// `wrap` (a command the script runs under, such as `tests/full_disk.sh`), with `env` set;
/// returns its stdout and the recorder's log.
fn recording(
    script: &str,
    wrap: &[std::ffi::OsString],
    env: &[(&str, &str)],
    src: &Path,
    rec: &Path,
    out: &Path,
) -> (String, String) {
    let _turn = one_graph_at_a_time();
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_xsurf")).parent().unwrap();
    let run = Command::new(root().join("../shared/tools/netns-run"))
        .envs(env.iter().copied())
        .args(wrap)
        .arg(root().join("tests").join(script))
        .arg(bin_dir)
        .arg(src)
        .arg(rec)
        .arg(out.join("logs"))
        .output()
        .unwrap();
    let log = std::fs::read_to_string(out.join("logs/record.log")).unwrap_or_default();
    (String::from_utf8_lossy(&run.stdout).into_owned(), log)
}

fn record_and_play(src_bag: &std::path::Path, out: &std::path::Path) {
    let rec = out.join("rec");
    let (stdout, _) = recording("record_play.sh", &[], &[], src_bag, &rec, out);
    let log = |f: &str| std::fs::read_to_string(out.join("logs").join(f)).unwrap_or_default();
    assert!(stdout.contains("exits 0 0"), "{stdout}\nrecord:\n{}\nplay:\n{}", log("record.log"), log("play.log"));
    let by_topic = |dir: &std::path::Path| {
        let mut m: std::collections::BTreeMap<String, Vec<Vec<u8>>> = Default::default();
        for msg in xsurf_formats::bag::Bag::open(dir).unwrap().messages() {
            let msg = msg.unwrap();
            m.entry(msg.topic).or_default().push(msg.data);
        }
        m
    };
    let (src, got) = (by_topic(src_bag), by_topic(&rec));
    for (topic, msgs) in &src {
        let g = got.get(topic).unwrap_or_else(|| panic!("{topic} not recorded\n{}", log("record.log")));
        assert_eq!(g.len(), msgs.len(), "{topic}: {} of {} messages", g.len(), msgs.len());
        assert!(g == msgs, "{topic}: payloads differ");
    }
    let meta = xsurf_formats::bag::Bag::open(&rec).unwrap().metadata;
    let q = |t: &str| meta.topics.iter().find(|x| x.name == t).and_then(|x| x.qos).unwrap();
    let images = meta.topics.iter().find(|t| t.name.starts_with("/cam1/image_raw")).unwrap();
    assert!(!q(&images.name).reliable && q("/tf_static").transient_local && q("/tf").reliable);
    // The recorded bag is read by the independent readers too.
    if let Some(j) = checker("check_bag.py", &[&rec]) {
        assert_eq!(j["agree"], true, "{j}");
        assert_eq!(j["rosbags_counts"][&images.name].as_u64(), Some(images.message_count), "{j}");
    }
}

/// Runs `tests/py/rviz_standin.py MODE` in the network namespace; returns its summary and the
/// surface points it received.
fn peer(
    mode: &str,
    params: &std::path::Path,
    bag: Option<&std::path::Path>,
) -> Option<(serde_json::Value, Vec<[f32; 3]>)> {
    let py = python()?;
    let _turn = one_graph_at_a_time();
    let netns = root().join("../shared/tools/netns-run");
    let bin_dir = std::path::Path::new(env!("CARGO_BIN_EXE_xsurf")).parent().unwrap();
    let work = params.parent().unwrap().join("work");
    let mut cmd = Command::new(&netns);
    cmd.arg(&py).arg(root().join("tests/py/rviz_standin.py")).arg(mode).arg(bin_dir).arg(root()).arg(&work).arg(params);
    if let Some(b) = bag {
        cmd.arg(b);
    }
    let run = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let log = std::fs::read_to_string(work.join("launch.log")).unwrap_or_default();
    assert!(
        run.status.success(),
        "rviz_standin.py {mode} failed:\n{stdout}\n{}\n{log}",
        String::from_utf8_lossy(&run.stderr)
    );
    let s: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let bytes = std::fs::read(work.join("surface.f32")).unwrap_or_default();
    let pts = bytes
        .chunks_exact(12)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
            [f(0), f(4), f(8)]
        })
        .collect();
    Some((s, pts))
}

fn assert_pyramid(pts: &[[f32; 3]], what: &str) {
    let scene = xsurf_core::synth::Scene::by_name("pyramid").unwrap();
    let acc = eval::accuracy(eval::surface_errors(&scene, pts));
    eprintln!("{what}: {acc:?}");
    // One layer (the cameras fused where they overlap): about 7 700 points for the stand-in's scan.
    assert!(acc.points > 5_000 && acc.rms_m <= 0.001 && acc.outlier_fraction_2mm < 0.005, "{what}: {acc:?}");
}

/// rviz2's view of the live graph (the committed launch file, composed): a Cyclone DDS peer with
/// best-effort readers gets well-formed clouds, meshes and images whose frames resolve through tf.
#[test]
fn an_rviz2_stand_in_sees_well_formed_clouds_meshes_images_and_tf() {
    let dir = scratch("rviz-standin");
    let params = dir.join("params.yaml");
    std::fs::write(
        &params,
        format!(
            "/**:\n  ros__parameters:\n    laser_plane: [0.0, 1.0, 0.0, 0.0]\n    output_dir: {}\n/**/camera_driver:\n  ros__parameters:\n    width: 320\n    height: 240\n    fps: 15.0\n/c_arm_pose:\n  ros__parameters:\n    start_delay_s: 3.0\n/merger:\n  ros__parameters:\n    merge_delay_s: 1.0\n",
            dir.join("files").display()
        ),
    )
    .unwrap();
    let Some((s, pts)) = peer("standin", &params, None) else { return };
    assert_eq!(s["errors"], serde_json::json!([]), "{s}");
    for k in ["clouds", "meshes", "images", "tf", "static"] {
        assert!(s[k].as_u64().unwrap() >= 1, "no {k}: {s}");
    }
    assert_eq!(s["unresolved"], serde_json::json!([]), "frames not resolvable through tf: {s}");
    assert_eq!(s["frames"], serde_json::json!(["cam1_optical_frame", "table"]), "{s}");
    assert_eq!(s["launch_exit"], 0, "{s}");
    assert_pyramid(&pts, "surface seen by the rviz2 stand-in");
}

/// A hospital stack's CI: Python publishes a synthetic scan (frames, camera_info, tf, events)
/// into our running processing nodes and gets the surface back.
#[test]
fn frames_published_from_python_come_back_as_a_surface() {
    let dir = scratch("python-frames");
    let params = dir.join("params.yaml");
    std::fs::write(
        &params,
        "/**:\n  ros__parameters:\n    laser_plane: [0.0, 1.0, 0.0, 0.0]\n/merger:\n  ros__parameters:\n    merge_delay_s: 1.0\n",
    )
    .unwrap();
    let Some((s, pts)) = peer("publish", &params, Some(pyramid_bag())) else { return };
    assert_eq!(s["errors"], serde_json::json!([]), "{s}");
    assert!(s["published"].as_u64().unwrap() > 300, "{s}");
    assert_eq!(s["launch_exit"], 0, "{s}");
    assert_pyramid(&pts, "surface from frames published by Python");
}

/// use_sim_time: /clock from an independent peer drives the node's stamps; its log records
/// reach /rosout as rcl_interfaces/msg/Log.
#[test]
fn sim_time_from_clock_and_logs_on_rosout() {
    let _turn = one_graph_at_a_time();
    let Some(py) = python() else { return };
    let netns = root().join("../shared/tools/netns-run");
    let bin_dir = std::path::Path::new(env!("CARGO_BIN_EXE_xsurf")).parent().unwrap();
    let run = Command::new(&netns).arg(&py).arg(root().join("tests/py/sim_time.py")).arg(bin_dir).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&run.stderr));
    let s: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert!(s["tf_count"].as_u64().unwrap() > 10, "{s}");
    // Every /tf stamp is simulated time (from 1000 s), none wall-clock time.
    let (first, last) = (s["tf_first"].as_f64().unwrap(), s["tf_last"].as_f64().unwrap());
    assert!(first >= 1000.0 && last <= s["sim_last"].as_f64().unwrap() + 0.5, "{s}");
    let logs = s["logs"].as_array().unwrap();
    let end = logs.iter().find(|l| l["msg"].as_str().unwrap_or("").contains("scan 1 ended"));
    let end = end.unwrap_or_else(|| panic!("no end-of-scan record on /rosout: {s}"));
    assert_eq!(end["name"], "c_arm_pose");
    assert_eq!(end["level"], 20, "INFO");
    assert_eq!(s["exit"], 0, "{s}");
}

/// A `bag record` killed with SIGKILL mid-scan leaves a bag without metadata.yaml whose storage
/// file ends inside a chunk. `bag info` and `reconstruct` read it up to the cut: every message
/// the independent `mcap` reader finds in the complete chunks, in the same order and bytes
/// (ours also keeps the whole messages of the cut chunk). `bag reindex` then writes its
/// metadata.yaml (issue 24, item 4).
#[test]
fn a_killed_recorder_leaves_a_bag_read_up_to_the_cut() {
    let out = scratch("record-kill");
    let rec = out.join("rec");
    let (stdout, _) = recording("record_kill.sh", &[], &[], pyramid_bag(), &rec, &out);
    let log = |f: &str| std::fs::read_to_string(out.join("logs").join(f)).unwrap_or_default();
    // Play exits 0; the recorder dies by SIGKILL (128 + 9).
    assert!(stdout.contains("exits 0 137"), "{stdout}\nrecord:\n{}\nplay:\n{}", log("record.log"), log("play.log"));
    assert!(!rec.join("metadata.yaml").exists(), "a killed recorder wrote no metadata.yaml");

    // Ours, message by message, up to the cut.
    let bag = xsurf_formats::bag::Bag::open(&rec).unwrap();
    let mut ours: Vec<(String, Vec<u8>)> = Vec::new();
    let mut cut = None;
    for m in bag.messages() {
        match m {
            Ok(m) => ours.push((m.topic, m.data)),
            Err(e) => cut = Some(e.to_string()),
        }
    }
    let cut = cut.expect("the storage file ends inside a record");
    assert!(cut.contains("rec_0.mcap") && cut.contains("byte offset"), "{cut}");
    let count = |topic: &str| ours.iter().filter(|(t, _)| t == topic).count();
    let src = xsurf_formats::bag::Bag::open(pyramid_bag()).unwrap().metadata;
    let src_images = src.topics.iter().find(|t| t.name == "/cam1/image_raw").unwrap().message_count as usize;
    let images = count("/cam1/image_raw");
    assert!(images > src_images / 10 && images < src_images * 9 / 10, "{images} of {src_images} images: not mid-scan");

    // The independent reader: the same messages, as far as the last complete chunk.
    if let Some(j) = checker("mcap_counts.py", &[std::path::Path::new("--damaged"), &rec.join("rec_0.mcap")]) {
        let file = &j["files"][0];
        assert!(file["damage"].is_string(), "{j}");
        let theirs = file["count"].as_u64().unwrap() as usize;
        assert!(theirs > 0 && theirs <= ours.len(), "mcap read {theirs}, we read {}", ours.len());
        for (topic, t) in j["topics"].as_object().unwrap() {
            assert!(t["count"].as_u64().unwrap() as usize <= count(topic), "{topic}: {t}");
        }
    }

    // bag info reads it, says how, and counts what it holds.
    let info = xsurf(&["bag", "info", rec.to_str().unwrap()]);
    let text = format!("{}{}", String::from_utf8_lossy(&info.stdout), String::from_utf8_lossy(&info.stderr));
    assert!(info.status.success(), "{text}");
    assert!(text.contains("no metadata.yaml") && text.contains("counted up to there"), "{text}");
    assert!(text.contains(&format!("Messages:          {}", ours.len())), "{text}");

    // The scan up to the kill is reconstructed from it.
    let o = out.join("o");
    let r = xsurf(&["reconstruct", rec.to_str().unwrap(), "--out", o.to_str().unwrap()]);
    // Exit 3: the files are written and the cut is named.
    assert_clean_failure(&r, 3, "reconstructed up to the cut: ");
    assert_clean_failure(&r, 3, "rec_0.mcap: MCAP error at byte offset");
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(o.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["frames_read"]["cam1"].as_u64().unwrap() as usize, images, "{report}");
    for f in ["cam1.ply", "cam2.ply", "merged.ply"] {
        assert!(std::fs::metadata(o.join(f)).unwrap().len() > 1000, "{f}");
    }

    // reindex writes the metadata.yaml, with the counts read.
    let ri = xsurf(&["bag", "reindex", rec.to_str().unwrap()]);
    assert!(ri.status.success(), "{}", String::from_utf8_lossy(&ri.stderr));
    let meta = xsurf_formats::bag::Bag::open(&rec).unwrap().metadata;
    assert_eq!(meta.message_count as usize, ours.len());
    assert_eq!(meta.topics.iter().find(|t| t.name == "/cam1/image_raw").unwrap().message_count as usize, images);
    std::fs::remove_dir_all(&out).unwrap();
}

/// A disk that fills up while `bag record` writes (a 4 MB tmpfs, the scan is about 12 MB raw):
/// the recorder stops with an error naming the file, the cause and how many messages it wrote,
/// and the bag is read up to its last complete chunk (issue 24, item 4).
#[test]
fn a_full_disk_stops_the_recorder_clearly_and_the_bag_is_kept() {
    let out = scratch("record-full");
    // The recording runs with its folder on a 4 MB tmpfs.
    let wrap = [
        "bash".into(),
        root().join("tests/full_disk.sh").into_os_string(),
        "4000000".into(),
        out.join("mnt").into_os_string(),
        out.join("kept").into_os_string(),
        "bash".into(),
    ];
    let (stdout, log) = recording("record_play.sh", &wrap, &[], pyramid_bag(), &out.join("mnt/rec"), &out);
    // Play exits 0, the recorder 1.
    assert!(stdout.contains("exits 0 1"), "{stdout}\n{log}");
    assert!(!log.contains("panicked"), "{log}");
    assert!(log.contains("rec_0.mcap: cannot write") && log.contains("No space left on device"), "{log}");
    let said: usize = log
        .split("recording stopped after ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count in {log}"));
    let rec = out.join("kept/rec");
    let read = xsurf_formats::bag::Bag::open(&rec).unwrap().messages().take_while(Result::is_ok).count();
    assert!(read > 0 && read <= said, "read {read}, the recorder wrote {said}");
    let info = xsurf(&["bag", "info", rec.to_str().unwrap()]);
    assert!(info.status.success(), "{}", String::from_utf8_lossy(&info.stderr));
    std::fs::remove_dir_all(&out).unwrap();
}

/// `bag record --split-by-scan`, the always-on recorder of the launch file's example: the same
/// scan played twice becomes two bags, `scan_1` and `scan_1_2`, each holding the whole scan
/// (every image, its placement) and nothing between; each reconstructs on its own (issue 24,
/// item 3).
#[test]
fn a_recorder_split_by_scan_writes_one_bag_per_scan() {
    let out = scratch("record-split");
    let rec = out.join("rec");
    let env = [("PLAYS", "2"), ("RECORD_ARGS", "--all --split-by-scan")];
    let (stdout, log) = recording("record_play.sh", &[], &env, pyramid_bag(), &rec, &out);
    assert!(stdout.contains("exits 0 0"), "{stdout}\n{log}");
    let mut bags: Vec<String> =
        std::fs::read_dir(&rec).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    bags.sort();
    assert_eq!(bags, ["scan_1", "scan_1_2"], "{log}");
    let src = xsurf_formats::bag::Bag::open(pyramid_bag()).unwrap().metadata;
    let count =
        |m: &xsurf_formats::bag::BagMetadata, t: &str| m.topics.iter().find(|x| x.name == t).map(|x| x.message_count);
    for b in &bags {
        let dir = rec.join(b);
        let meta = xsurf_formats::bag::Bag::open(&dir).unwrap().metadata;
        for t in ["/cam1/image_raw", "/cam2/image_raw", "/scan/events"] {
            assert_eq!(count(&meta, t), count(&src, t), "{b} {t}\n{log}");
        }
        assert!(count(&meta, "/tf_static").is_some_and(|n| n >= 1), "{b}: the placement\n{log}");
        // Nothing of the other play: no more tf than the scan's own and the last one before it.
        assert!(count(&meta, "/tf") <= count(&src, "/tf").map(|n| n + 1), "{b}\n{log}");
        let o = out.join(format!("o-{b}"));
        let r = xsurf(&["reconstruct", dir.to_str().unwrap(), "--out", o.to_str().unwrap()]);
        assert!(r.status.success(), "{b}: {}", String::from_utf8_lossy(&r.stderr));
        let report: serde_json::Value = serde_json::from_slice(&std::fs::read(o.join("report.json")).unwrap()).unwrap();
        assert_eq!(report["scans"], serde_json::json!([1]), "{report}");
        assert_eq!(report["scan_reports"][0]["incomplete"], serde_json::json!([]), "{report}");
    }
    std::fs::remove_dir_all(&out).unwrap();
}
