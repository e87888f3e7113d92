//! Our CDR against bytes written by an independent implementation (the Python `rosbags`
//! package, see fixtures/README.md): decode to the expected values, encode byte for byte.
#![allow(clippy::unwrap_used)]

use serde_json::Value;
use std::path::Path;
use xsurf_msgs::{
    builtin_interfaces, cdr, definition_of, geometry_msgs, rcl_interfaces, rosgraph_msgs, sensor_msgs, shape_msgs,
    std_msgs, tf2_msgs, visualization_msgs, xsurf_msgs as ours, RosMessage,
};

fn check<T: RosMessage + PartialEq + std::fmt::Debug>(samples: &Value) {
    let name = T::TYPE_NAME;
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(format!("{}.cdr", name.replacen("/msg/", "__", 1)));
    let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let expected: T = serde_json::from_value(samples[name].clone()).unwrap_or_else(|e| panic!("{name}: {e}"));
    let decoded: T = cdr::decode(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(decoded, expected, "{name}: decoded value");
    let encoded = cdr::encode(&expected).unwrap();
    assert_eq!(encoded, bytes, "{name}: our bytes differ from rosbags'");
    assert!(definition_of(name).is_some(), "{name}: no definition");
}

#[test]
fn every_type_matches_rosbags_byte_for_byte() {
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/samples.json")).unwrap();
    let s: Value = serde_json::from_str(&text).unwrap();
    check::<builtin_interfaces::Time>(&s);
    check::<builtin_interfaces::Duration>(&s);
    check::<std_msgs::Header>(&s);
    check::<std_msgs::ColorRGBA>(&s);
    check::<std_msgs::StringMsg>(&s);
    check::<std_msgs::Float64>(&s);
    check::<rosgraph_msgs::Clock>(&s);
    check::<sensor_msgs::Image>(&s);
    check::<sensor_msgs::CompressedImage>(&s);
    check::<sensor_msgs::RegionOfInterest>(&s);
    check::<sensor_msgs::CameraInfo>(&s);
    check::<sensor_msgs::PointField>(&s);
    check::<sensor_msgs::PointCloud2>(&s);
    check::<sensor_msgs::JointState>(&s);
    check::<geometry_msgs::Vector3>(&s);
    check::<geometry_msgs::Quaternion>(&s);
    check::<geometry_msgs::Point>(&s);
    check::<geometry_msgs::Pose>(&s);
    check::<geometry_msgs::Transform>(&s);
    check::<geometry_msgs::TransformStamped>(&s);
    check::<tf2_msgs::TFMessage>(&s);
    check::<shape_msgs::MeshTriangle>(&s);
    check::<shape_msgs::Mesh>(&s);
    check::<visualization_msgs::UVCoordinate>(&s);
    check::<visualization_msgs::MeshFile>(&s);
    check::<visualization_msgs::Marker>(&s);
    check::<visualization_msgs::MarkerArray>(&s);
    check::<rcl_interfaces::Log>(&s);
    check::<ours::LaserLine>(&s);
    check::<ours::ScanEvent>(&s);
    assert_eq!(s.as_object().unwrap().len(), 30, "every fixture checked");
}

#[test]
fn definitions_carry_the_dependency_closure() {
    let d = definition_of("visualization_msgs/msg/Marker").unwrap();
    for dep in [
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
        "MSG: sensor_msgs/CompressedImage",
        "MSG: visualization_msgs/MeshFile",
    ] {
        assert!(d.contains(dep), "missing {dep}");
    }
    assert_eq!(d.matches("MSG: std_msgs/Header").count(), 1, "each dependency once");
    assert!(d.lines().all(|l| !l.contains("/msg/")), "ros2msg field types use pkg/Type");
    assert!(definition_of("xsurf_msgs/msg/LaserLine").unwrap().contains("float32[] strength"));
    assert!(definition_of("nope/msg/Nope").is_none());
}

/// A LaserLine written before `lasers` existed (its payload ends after `rgb`) reads as one
/// laser, and one written before `layers` (ending after `lasers`) as one line per laser; one
/// with lasers and layers keeps them.
#[test]
fn laser_lines_without_the_lasers_field_read_as_one_laser() {
    let line = ours::LaserLine {
        header: std_msgs::Header { frame_id: "cam1_optical_frame".into(), ..Default::default() },
        image_width: 640,
        image_height: 3,
        u: vec![1.5, f32::NAN, 3.0],
        v: vec![0.0, 1.0, 2.0],
        strength: vec![9.0, 0.0, 8.0],
        width: vec![2.0, 0.0, 2.5],
        rgb: vec![1, 2, 3, 4, 5, 6, 7],
        ..Default::default()
    };
    let bytes = cdr::encode(&line).unwrap();
    // The layout before `layers`: the same bytes without the last one.
    assert_eq!(bytes[bytes.len() - 1], 0);
    let before_layers = &bytes[..bytes.len() - 1];
    let back: ours::LaserLine = cdr::decode(before_layers).unwrap();
    assert_eq!(format!("{back:?}"), format!("{line:?}"));
    assert_eq!(back.layer_count(), 1);
    // The older layout: the same bytes up to the end of rgb (the empty list and its padding cut).
    let old = &before_layers[..before_layers.len() - 4 - 1];
    assert_eq!(u32::from_le_bytes(before_layers[before_layers.len() - 4..].try_into().unwrap()), 0);
    let back: ours::LaserLine = cdr::decode(old).unwrap();
    assert_eq!(format!("{back:?}"), format!("{line:?}"));
    let three =
        ours::LaserLine { lasers: vec!["collimator".into(), "left".into(), "right".into()], layers: 2, ..line.clone() };
    let back: ours::LaserLine = cdr::decode(&cdr::encode(&three).unwrap()).unwrap();
    assert_eq!((back.lasers.clone(), back.layers, back.layer_count()), (three.lasers.clone(), 2, 2));
    // A payload cut inside the older fields is still an error.
    assert!(cdr::decode::<ours::LaserLine>(&old[..old.len() - 6]).is_err());
}

#[test]
fn truncated_and_foreign_payloads_are_errors() {
    let b = cdr::encode(&std_msgs::Header { frame_id: "table".into(), ..Default::default() }).unwrap();
    assert!(matches!(cdr::decode::<std_msgs::Header>(&b[..2]), Err(cdr::CdrError::TooShort(2))));
    assert!(matches!(cdr::decode::<std_msgs::Header>(&b[..b.len() - 3]), Err(cdr::CdrError::Decode(_))));
    let mut x = b.clone();
    x[1] = 7;
    assert!(matches!(cdr::decode::<std_msgs::Header>(&x), Err(cdr::CdrError::Encapsulation(0, 7))));
}
