//! Bags we write are read in full by independent readers (rosbags Reader and AnyReader,
//! mcap-ros2-support), with the same counts and contents; a bag written by rosbags is read by us.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;
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
