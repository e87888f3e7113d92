//! Bags we write are read in full by independent readers (rosbags Reader and AnyReader,
//! mcap-ros2-support), with the same counts and contents; a bag written by rosbags is read by us.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;
use std::path::Path;
use xsurf_formats::bag::Bag;
use xsurf_msgs::{cdr, sensor_msgs::CameraInfo, sensor_msgs::Image, tf2_msgs::TFMessage};

#[test]
fn synthetic_bag_is_read_in_full_by_independent_readers() {
    let bag = pyramid_bag();
    let Some(j) = checker("check_bag.py", &[bag]) else { return };
    assert_eq!(j["agree"], true, "{j}");
    let ours = Bag::open(bag).unwrap();
    assert_eq!(j["metadata_total"].as_u64().unwrap(), ours.metadata.message_count);
    for t in &ours.metadata.topics {
        assert_eq!(j["mcap_counts"][&t.name].as_u64(), Some(t.message_count), "{}", t.name);
        assert_eq!(j["anyreader_counts"][&t.name].as_u64(), Some(t.message_count), "{}", t.name);
    }
    // Contents: the first message of each kind, as we read it, equals what rosbags decoded.
    let mut seen = std::collections::BTreeSet::new();
    for m in ours.messages() {
        let m = m.unwrap();
        if !seen.insert(m.topic.clone()) {
            continue;
        }
        let s = &j["samples"][&m.topic];
        match m.type_name.as_str() {
            "sensor_msgs/msg/Image" => {
                let img: Image = cdr::decode(&m.data).unwrap();
                assert_eq!(s["width"], img.width);
                assert_eq!(s["height"], img.height);
                assert_eq!(s["encoding"], img.encoding.as_str());
                assert_eq!(s["frame_id"], img.header.frame_id.as_str());
                assert_eq!(s["sum"].as_u64().unwrap(), img.data.iter().map(|&v| u64::from(v)).sum::<u64>());
            }
            "sensor_msgs/msg/CameraInfo" => {
                let ci: CameraInfo = cdr::decode(&m.data).unwrap();
                let k: Vec<f64> = s["k"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                assert_eq!(k, ci.k.to_vec());
                assert_eq!(s["model"], ci.distortion_model.as_str());
            }
            "tf2_msgs/msg/TFMessage" => {
                let tf: TFMessage = cdr::decode(&m.data).unwrap();
                let t = &tf.transforms[0];
                assert_eq!(s["parent"], t.header.frame_id.as_str());
                assert_eq!(s["child"], t.child_frame_id.as_str());
                assert_eq!(s["stamp"].as_i64().unwrap(), t.header.stamp.nanos());
                assert_eq!(s["t"][1].as_f64().unwrap(), t.transform.translation.y);
                assert_eq!(s["q"][3].as_f64().unwrap(), t.transform.rotation.w);
            }
            _ => {}
        }
    }
    assert!(seen.len() >= 8, "{seen:?}");
}

#[test]
fn bag_info_lists_topics_like_ros2_bag_info() {
    let out = xsurf(&["bag", "info", pyramid_bag().to_str().unwrap()]);
    assert!(out.status.success());
    let s = String::from_utf8_lossy(&out.stdout);
    assert!(s.contains("Storage id:        mcap"), "{s}");
    assert!(s.contains("Topic: /cam1/image_raw") && s.contains("Type: sensor_msgs/msg/Image"), "{s}");
    assert!(s.contains("best_effort volatile depth 5"), "{s}");
    assert!(s.contains("reliable transient_local depth 1"), "{s}");
}

#[test]
fn bag_written_by_rosbags_is_reconstructed() {
    let dir = scratch("rosbags-written");
    let rb = dir.join("rb");
    if checker_write(&rb).is_none() {
        return;
    }
    let meta = Bag::open(&rb).unwrap().metadata;
    assert_eq!(meta.version, 9, "rosbags writes version 9");
    let out_dir = dir.join("out");
    let params = pyramid_bag().join("params.yaml");
    let out = xsurf(&[
        "reconstruct",
        rb.to_str().unwrap(),
        "--params-file",
        params.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let merged = xsurf_formats::ply::read(&mut std::io::BufReader::new(
        std::fs::File::open(out_dir.join("merged.ply")).unwrap(),
    ))
    .unwrap();
    let scene = xsurf_core::synth::Scene::by_name("pyramid").unwrap();
    let acc = xsurf_core::eval::accuracy(xsurf_core::eval::surface_errors(&scene, &merged.positions));
    // Two cameras fused into one layer: about 18 000 points.
    assert!(acc.points > 14_000 && acc.rms_m < 0.001, "{acc:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn checker_write(dst: &std::path::Path) -> Option<()> {
    let py = python()?;
    let out = std::process::Command::new(py)
        .arg(root().join("tests/py/rosbags_write.py"))
        .arg(pyramid_bag())
        .arg(dst)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    Some(())
}

/// CompressedImage written by Python (rosbags' Writer, the bytes by Pillow: JPEG for cam1, PNG
/// for cam2, image_transport's format strings): decoded by us to the pixels Pillow decodes
/// (PNG exactly; JPEG within the rounding of two IDCTs), and the bag reconstructs.
#[test]
fn compressed_images_written_by_python_decode_to_pillows_pixels() {
    use xsurf_msgs::sensor_msgs::CompressedImage;
    let dir = scratch("py-compressed");
    let bag = dir.join("bag");
    let Some(py) = python() else { return };
    let out = std::process::Command::new(py)
        .arg(root().join("tests/py/rosbags_compressed.py"))
        .arg(pyramid_bag())
        .arg(&bag)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(bag.join("pillow/index.json")).unwrap()).unwrap();
    let frames = index.as_array().unwrap();
    assert_eq!(frames.len(), 6);
    let ours = Bag::open(&bag).unwrap();
    let mut compared = 0;
    for m in ours.messages() {
        let m = m.unwrap();
        let Some(cam) = m.topic.strip_suffix("/image_raw/compressed") else { continue };
        let c: CompressedImage = cdr::decode(&m.data).unwrap();
        let stamp = c.header.stamp.nanos();
        let Some(f) =
            frames.iter().find(|f| f["stamp_ns"].as_i64() == Some(stamp) && f["camera"] == cam.trim_start_matches('/'))
        else {
            continue;
        };
        assert_eq!(c.format, f["format"].as_str().unwrap());
        let img = xsurf_formats::compressed::decode(&c.format, &c.data).unwrap();
        let pillow = std::fs::read(bag.join("pillow").join(f["file"].as_str().unwrap())).unwrap();
        assert_eq!((img.width, img.height), (320, 240));
        assert_eq!(img.data.len(), pillow.len());
        let diffs: Vec<i32> =
            img.data.iter().zip(&pillow).map(|(&a, &b)| (i32::from(a) - i32::from(b)).abs()).collect();
        let max = diffs.iter().copied().max().unwrap_or(0);
        let same = diffs.iter().filter(|&&d| d == 0).count() as f64 / diffs.len() as f64;
        eprintln!("{cam} {}: max difference {max}, {:.2} % identical", c.format, 100.0 * same);
        if c.format.contains("png") {
            assert_eq!(max, 0, "PNG decodes exactly");
        } else {
            assert!(max <= 1 && same > 0.95, "JPEG: max difference {max}, {:.2} % identical", 100.0 * same);
        }
        compared += 1;
    }
    assert_eq!(compared, 6);
    let out_dir = dir.join("out");
    let params = pyramid_bag().join("params.yaml");
    let out = xsurf(&[
        "reconstruct",
        bag.to_str().unwrap(),
        "--params-file",
        params.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("report.json")).unwrap()).unwrap();
    assert!(
        report["points"]["cam1"].as_u64().unwrap() > 10_000 && report["points"]["cam2"].as_u64().unwrap() > 10_000,
        "{report}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `bag info` checks the storage itself, not only metadata.yaml: a recording cut short and bytes
/// that are not MCAP are refused with the file and the offset. `synth` writes its bag under a
/// temporary name, renamed when complete, and refuses a non-empty folder up front.
#[test]
fn bag_info_checks_the_mcap_and_synth_leaves_no_half_bag() {
    let dir = scratch("bag-info");
    let bag = dir.join("b");
    copy_bag(pyramid_bag(), &bag);
    let mcap = std::fs::read_dir(&bag)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .unwrap();
    let bytes = std::fs::read(&mcap).unwrap();
    std::fs::write(&mcap, &bytes[..bytes.len() / 2]).unwrap();
    let out = xsurf(&["bag", "info", bag.to_str().unwrap()]);
    assert_clean_failure(&out, 1, &format!("MCAP error at byte offset {}", bytes.len() / 2 - 8));
    assert_clean_failure(&out, 1, "cut short");
    std::fs::write(&mcap, b"these bytes are not an MCAP file at all").unwrap();
    assert_clean_failure(&xsurf(&["bag", "info", bag.to_str().unwrap()]), 1, "not an MCAP file");
    // A non-empty folder is refused before any work; a good run leaves no partial folder.
    let out = xsurf(&["synth", "pyramid", "-o", bag.to_str().unwrap(), "--size", "160x120"]);
    assert_clean_failure(&out, 1, "exists and is not empty");
    let fresh = dir.join("fresh");
    let out = xsurf(&["synth", "pyramid", "-o", fresh.to_str().unwrap(), "--size", "160x120", "--speed", "0.14"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(fresh.join("fresh_0.mcap").is_file() && fresh.join("metadata.yaml").is_file());
    assert!(!dir.join(".fresh.partial").exists());
    let out = xsurf(&["bag", "info", fresh.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// rosbag2's own split files without metadata.yaml (`reindex_test_bags`, from the rosbag2
/// repository: ../shared/realdata/README.md): `bag info` reads them as they are and says so,
/// `bag reindex` writes the metadata.yaml `ros2 bag reindex` would, checked against the MCAP
/// files counted by the `mcap` package and read back through it by `rosbags`. A file cut short
/// (a recorder killed) is indexed up to its last whole chunk; sqlite3 storage is refused by name.
#[test]
fn rosbag2_split_files_without_metadata_are_reindexed() {
    let src = root().join("../shared/realdata/rosbag2/rosbag2_py/test/resources/mcap/reindex_test_bags/multiple_files");
    let dir = scratch("reindex");
    std::fs::create_dir_all(&dir).unwrap();
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(&src).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    for f in &files {
        let to = dir.join(f.file_name().unwrap());
        std::fs::copy(f, &to).unwrap();
        // The fixtures are read-only; the copies are cut below.
        std::fs::set_permissions(&to, std::os::unix::fs::PermissionsExt::from_mode(0o644)).unwrap();
    }
    let d = dir.to_str().unwrap();
    // Without metadata.yaml, `bag info` reads the files themselves and says so.
    let info = xsurf(&["bag", "info", d]);
    assert!(info.status.success(), "{info:?}");
    assert!(String::from_utf8_lossy(&info.stdout).contains("Count: 3177"), "{info:?}");
    assert!(String::from_utf8_lossy(&info.stderr).contains("has no metadata.yaml; indexed from its storage files"));
    let out = xsurf(&["bag", "reindex", d]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_clean_failure(&xsurf(&["bag", "reindex", d]), 1, "exists already");
    let bag = xsurf_formats::bag::Bag::open(&dir).unwrap();
    let m = &bag.metadata;
    assert_eq!(m.files, ["multiple_files_0.mcap", "multiple_files_1.mcap", "multiple_files_2.mcap"]);
    let info = xsurf(&["bag", "info", d]);
    assert!(String::from_utf8_lossy(&info.stdout).contains("Count: 3177"), "{info:?}");
    let Some(j) = checker("mcap_counts.py", &files.iter().map(|p| p.as_path()).collect::<Vec<_>>()) else { return };
    let chatter = &j["topics"]["/chatter"];
    assert_eq!(m.topics.len(), 1);
    let t = &m.topics[0];
    assert_eq!((t.name.as_str(), t.type_name.as_str()), ("/chatter", chatter["type"].as_str().unwrap()));
    assert_eq!(t.serialization_format, chatter["encoding"].as_str().unwrap());
    assert_eq!(t.message_count, chatter["count"].as_u64().unwrap());
    assert_eq!(t.qos.map(|q| (q.reliable, q.depth)), Some((true, 1)), "the offered QoS from the channel metadata");
    let per_file = j["files"].as_array().unwrap();
    for (span, f) in m.file_spans.iter().zip(per_file) {
        assert_eq!(span.message_count, f["count"].as_u64().unwrap());
        assert_eq!(span.start_ns, f["first"].as_u64().unwrap());
        assert_eq!(span.start_ns + span.duration_ns, f["last"].as_u64().unwrap());
    }
    assert_eq!(m.start_ns, per_file[0]["first"].as_u64().unwrap());
    // rosbags reads the folder through the metadata.yaml written: every message.
    let r = checker("mcap_counts.py", &[Path::new("--rosbags"), &dir]).unwrap();
    assert_eq!(r["messages"].as_u64().unwrap(), m.message_count, "{r}");
    // The last file cut short, as a killed recorder leaves it: indexed up to its last whole
    // chunk. This file is one chunk of 529 messages followed by its index and summary: cut at
    // half, the chunk is whole (the messages are kept, the index is lost); cut at a quarter,
    // inside the chunk, none of its messages is.
    let last = dir.join("multiple_files_2.mcap");
    let bytes = std::fs::read(&last).unwrap();
    for (cut_at, kept) in [(bytes.len() / 2, 529), (bytes.len() / 4, 0)] {
        std::fs::write(&last, &bytes[..cut_at]).unwrap();
        let out = xsurf(&["bag", "reindex", d, "--force"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && err.contains("multiple_files_2.mcap: MCAP error at byte offset"), "{err}");
        let cut = xsurf_formats::bag::Bag::open(&dir).unwrap().metadata;
        assert_eq!(cut.file_spans[2].message_count, kept, "cut at byte {cut_at}");
        assert_eq!(cut.message_count, 1324 + 1324 + kept);
    }
    // sqlite3 storage: refused by name.
    let sq =
        root().join("../shared/realdata/rosbag2/rosbag2_py/test/resources/sqlite3/reindex_test_bags/multiple_files");
    let sqd = scratch("reindex-sqlite");
    std::fs::create_dir_all(&sqd).unwrap();
    std::fs::copy(sq.join("multiple_files_0.db3"), sqd.join("multiple_files_0.db3")).unwrap();
    assert_clean_failure(&xsurf(&["bag", "reindex", sqd.to_str().unwrap()]), 1, "sqlite3 storage");
    std::fs::remove_dir_all(&dir).unwrap();
    std::fs::remove_dir_all(&sqd).unwrap();
}

/// What a recorder killed mid-scan leaves: MCAP storage cut short and no metadata.yaml. `bag
/// info` reads the files themselves and names the cut; `reconstruct` rebuilds the surface from
/// the frames before it and exits 3 saying the bag ended early.
#[test]
fn a_bag_cut_short_without_metadata_is_read_up_to_the_cut() {
    let dir = scratch("killed-recorder");
    std::fs::create_dir_all(&dir).unwrap();
    let src = pyramid_bag();
    let meta = Bag::open(src).unwrap().metadata;
    let file = &meta.files[0];
    let bytes = std::fs::read(src.join(file)).unwrap();
    std::fs::write(dir.join(file), &bytes[..bytes.len() * 3 / 5]).unwrap();
    let d = dir.to_str().unwrap();
    let info = xsurf(&["bag", "info", d]);
    let err = String::from_utf8_lossy(&info.stderr);
    assert!(info.status.success(), "{err}");
    assert!(err.contains("has no metadata.yaml") && err.contains("MCAP error at byte offset"), "{err}");
    let indexed = Bag::open(&dir).unwrap();
    let n = indexed.metadata.message_count;
    assert!(n > meta.message_count / 3 && n < meta.message_count, "{n} of {} messages", meta.message_count);
    let out_dir = scratch("killed-recorder-out");
    let r = xsurf(&["reconstruct", d, "--out", out_dir.to_str().unwrap(), "--quiet"]);
    assert_clean_failure(&r, 3, "the bag ended early");
    let merged = xsurf_formats::ply::read(&mut std::io::BufReader::new(
        std::fs::File::open(out_dir.join("merged.ply")).unwrap(),
    ))
    .unwrap();
    assert!(merged.positions.len() > 5000, "{} points from the frames before the cut", merged.positions.len());
    // Random bytes named like a storage file are no bag.
    std::fs::write(dir.join(file), [7u8; 4096]).unwrap();
    assert_clean_failure(&xsurf(&["bag", "info", d]), 1, "the storage files hold no message");
    std::fs::remove_dir_all(&dir).unwrap();
    std::fs::remove_dir_all(&out_dir).unwrap();
}
