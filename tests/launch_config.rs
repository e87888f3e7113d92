//! The files in launch-config/ parse, agree with each other, and configure every node.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;
use xsurf_nodes::registry as components;
use xsurf_runtime::params::{ParamValue, Params};
use xsurf_runtime::rosargs::RosArgs;

#[test]
fn rig_file_is_the_study_rig() {
    let text = std::fs::read_to_string(root().join("launch-config/rig_study.yaml")).unwrap();
    let rig: xsurf_core::rig::Rig = serde_yaml::from_str(&text).unwrap();
    assert_eq!(rig, xsurf_core::rig::Rig::study(640, 480));
}

#[test]
fn params_file_configures_every_node_and_matches_the_rig() {
    let path = root().join("launch-config/params.yaml");
    let ros = RosArgs::parse(&["--ros-args", "--params-file", path.to_str().unwrap()]).unwrap();
    let nodes = [
        ("c_arm_pose", "/c_arm_pose"),
        ("camera_driver", "/cam1/camera_driver"),
        ("edge_detector", "/cam2/edge_detector"),
        ("triangulator", "/cam1/triangulator"),
        ("mesher", "/cam2/mesher"),
        ("merger", "/merger"),
    ];
    for (node, fq) in nodes {
        let o = ros.param_overrides(fq).unwrap();
        let p = Params::resolve(&components::declarations(node).unwrap(), &o).unwrap();
        components::build(node, &p).unwrap_or_else(|e| panic!("{fq}: {e}"));
        if node == "triangulator" {
            let rig = xsurf_core::rig::Rig::study(640, 480);
            assert_eq!(p.get("laser_plane"), Some(&ParamValue::DoubleArray(rig.laser_plane.to_vec())));
        }
    }
}

#[test]
fn launch_file_starts_every_node_with_the_params_file() {
    let file = root().join("launch-config/xsurf.launch.yaml");
    let nodes = xsurf_nodes::launch::load(&file, &Default::default()).unwrap();
    let names: Vec<String> = nodes.iter().map(|n| n.fq_name()).collect();
    assert_eq!(
        names,
        [
            "/c_arm_pose",
            "/cam1/camera_driver",
            "/cam1/edge_detector",
            "/cam1/triangulator",
            "/cam1/mesher",
            "/cam2/camera_driver",
            "/cam2/edge_detector",
            "/cam2/triangulator",
            "/cam2/mesher",
            "/merger",
            "/xray_aligner",
        ]
    );
    let params = root().join("launch-config/params.yaml");
    for n in &nodes {
        assert!(components::NODE_NAMES.contains(&n.exec.as_str()), "{}", n.exec);
        assert_eq!(n.param_files.len(), 1);
        assert_eq!(std::fs::canonicalize(&n.param_files[0]).unwrap(), std::fs::canonicalize(&params).unwrap());
        // Each node builds from the params file as the launcher passes it.
        let ros = RosArgs::parse(&["--ros-args", "--params-file", n.param_files[0].to_str().unwrap()]).unwrap();
        let o = ros.param_overrides(&n.fq_name()).unwrap();
        let p = Params::resolve(&components::declarations(&n.exec).unwrap(), &o).unwrap();
        components::build(&n.exec, &p).unwrap_or_else(|e| panic!("{}: {e}", n.fq_name()));
    }
    // A launch argument on the command line replaces the default.
    let other = scratch("launch-arg").join("p.yaml");
    std::fs::write(&other, "/**:\n  ros__parameters: {}\n").unwrap();
    let cli = [("params".to_string(), other.to_string_lossy().into_owned())].into_iter().collect();
    let nodes = xsurf_nodes::launch::load(&file, &cli).unwrap();
    assert!(nodes.iter().all(|n| n.param_files == [other.clone()]));
}

/// The two-host launch files together start the whole graph, each node once, with the same
/// executables, respawn settings and params file as the one-host file.
#[test]
fn the_two_host_launch_files_split_the_graph() {
    let load = |f: &str| xsurf_nodes::launch::load(&root().join("launch-config").join(f), &Default::default()).unwrap();
    let key = |n: &xsurf_nodes::launch::NodeSpec| (n.fq_name(), n.exec.clone(), n.param_files.clone(), n.respawn);
    let mut split: Vec<_> =
        load("camera-host.launch.yaml").iter().chain(&load("processing-host.launch.yaml")).map(key).collect();
    let mut whole: Vec<_> = load("xsurf.launch.yaml").iter().map(key).collect();
    split.sort();
    whole.sort();
    assert_eq!(split, whole);
    let cam: Vec<String> = load("camera-host.launch.yaml").iter().map(|n| n.fq_name()).collect();
    assert_eq!(cam, ["/c_arm_pose", "/cam1/camera_driver", "/cam2/camera_driver"]);
}

#[test]
fn a_bad_launch_file_is_named_and_refused() {
    let dir = scratch("bad-launch");
    let f = dir.join("x.launch.yaml");
    std::fs::write(&f, "launch:\n- node: {exec: merger, param: [{from: /nope/p.yaml}]}\n").unwrap();
    let out = xsurf(&["launch", f.to_str().unwrap()]);
    assert_clean_failure(&out, 2, "/nope/p.yaml does not exist");
    assert_clean_failure(&out, 2, "x.launch.yaml");
}

#[test]
fn launch_file_names_our_executables() {
    let text = std::fs::read_to_string(root().join("launch-config/xsurf.launch.yaml")).unwrap();
    let doc: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
    let mut execs = Vec::new();
    fn walk(v: &serde_yaml::Value, out: &mut Vec<String>) {
        match v {
            serde_yaml::Value::Mapping(m) => {
                for (k, v) in m {
                    if k.as_str() == Some("exec") {
                        out.push(v.as_str().unwrap().to_string());
                    }
                    walk(v, out);
                }
            }
            serde_yaml::Value::Sequence(s) => s.iter().for_each(|v| walk(v, out)),
            _ => {}
        }
    }
    walk(&doc, &mut execs);
    assert_eq!(execs.len(), 11, "{execs:?}");
    for e in &execs {
        assert!(components::NODE_NAMES.contains(&e.as_str()), "{e}");
    }
}

#[test]
fn rviz_config_shows_our_topics_in_the_table_frame() {
    let text = std::fs::read_to_string(root().join("launch-config/xsurf.rviz")).unwrap();
    let doc: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
    let vm = &doc["Visualization Manager"];
    assert_eq!(vm["Global Options"]["Fixed Frame"], "table");
    let displays = vm["Displays"].as_sequence().unwrap();
    let topics: Vec<(&str, &str)> =
        displays.iter().filter_map(|d| Some((d["Class"].as_str()?, d["Topic"]["Value"].as_str()?))).collect();
    // Every topic shown is one our nodes publish, with the type the display expects.
    let published: std::collections::BTreeMap<String, String> = ["/cam1", "/cam2", "/"]
        .iter()
        .flat_map(|ns| {
            components::NODE_NAMES.iter().filter_map(move |node| {
                let decls = components::declarations(node)?;
                let p = Params::resolve(&decls, &Default::default()).ok()?;
                let c = components::build(node, &p).ok()?;
                Some(
                    c.outputs()
                        .into_iter()
                        .map(|port| {
                            let t = xsurf_runtime::rosargs::resolve_topic(
                                &port.topic,
                                &xsurf_runtime::rosargs::normalize_ns(ns),
                                node,
                                &[],
                            );
                            (t, port.type_name.to_string())
                        })
                        .collect::<Vec<_>>(),
                )
            })
        })
        .flatten()
        .collect();
    let expect = |class: &str| match class {
        "rviz_default_plugins/PointCloud2" => "sensor_msgs/msg/PointCloud2",
        "rviz_default_plugins/Marker" => "visualization_msgs/msg/Marker",
        "rviz_default_plugins/Image" => "sensor_msgs/msg/Image",
        other => panic!("unexpected display {other}"),
    };
    for (class, topic) in &topics {
        assert_eq!(published.get(*topic).map(String::as_str), Some(expect(class)), "{topic} ({class})");
    }
    for t in ["/surface/cloud", "/surface/mesh", "/cam1/mesh", "/xray/overlay", "/cam1/image_raw", "/cam2/image_raw"] {
        assert!(topics.iter().any(|(_, x)| x == &t), "{t} not shown");
    }
    assert!(displays.iter().any(|d| d["Class"] == "rviz_default_plugins/TF"));
}

/// The launch file's commented example of an always-on recorder, uncommented, is a node that
/// runs `xsurf bag record --split-by-scan` with respawn (its `--ros-args` are ignored by the
/// recorder; `tests/dds.rs` tests the split itself).
#[test]
fn the_launch_file_example_recorder_parses_when_uncommented() {
    let text = std::fs::read_to_string(root().join("launch-config/xsurf.launch.yaml")).unwrap();
    let i = text.find("  # - node:").expect("the recorder example");
    let block: Vec<String> = text[i..].lines().map(|l| l.replacen("  # ", "  ", 1)).collect();
    let dir = scratch("launch-recorder");
    let file = dir.join("rec.launch.yaml");
    std::fs::write(&file, format!("launch:\n{}\n", block.join("\n"))).unwrap();
    let nodes = xsurf_nodes::launch::load(&file, &Default::default()).unwrap();
    assert_eq!(nodes.len(), 1);
    let n = &nodes[0];
    assert_eq!((n.exec.as_str(), n.fq_name().as_str()), ("xsurf", "/recorder"));
    assert_eq!(&n.args[..3], ["bag", "record", "-o"]);
    assert!(n.args.contains(&"--split-by-scan".to_string()) && n.respawn.is_some(), "{n:?}");
    for t in ["/cam1/image_raw", "/cam2/camera_info", "/tf", "/tf_static", "/scan/events"] {
        assert!(n.args.contains(&t.to_string()), "{t} not recorded: {n:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The three-laser scanner's files (issue 20): its rig is `Rig::three_lasers`, its launch file
/// starts the whole graph with its params file and rig, every node builds from them, and each
/// node that uses the lasers has the rig's; its rviz config colours the clouds by laser.
#[test]
fn the_three_laser_files_configure_the_three_laser_scanner() {
    let text = std::fs::read_to_string(root().join("launch-config/rig_three_lasers.yaml")).unwrap();
    let rig: xsurf_core::rig::Rig = serde_yaml::from_str(&text).unwrap();
    assert_eq!(rig, xsurf_core::rig::Rig::three_lasers(640, 480));
    let one = xsurf_nodes::launch::load(&root().join("launch-config/xsurf.launch.yaml"), &Default::default()).unwrap();
    let file = root().join("launch-config/xsurf_three_lasers.launch.yaml");
    let nodes = xsurf_nodes::launch::load(&file, &Default::default()).unwrap();
    assert_eq!(
        nodes.iter().map(|n| n.fq_name()).collect::<Vec<_>>(),
        one.iter().map(|n| n.fq_name()).collect::<Vec<_>>()
    );
    for n in &nodes {
        let mut args =
            vec!["--ros-args".to_string(), "--params-file".into(), n.param_files[0].to_string_lossy().into_owned()];
        for (name, v) in &n.params {
            args.extend(["-p".into(), format!("{name}:={}", v.as_str().unwrap())]);
        }
        let ros = RosArgs::parse(&args).unwrap();
        let o = ros.param_overrides(&n.fq_name()).unwrap();
        let p = Params::resolve(&components::declarations(&n.exec).unwrap(), &o).unwrap();
        components::build(&n.exec, &p).unwrap_or_else(|e| panic!("{}: {e}", n.fq_name()));
        if ["camera_driver", "c_arm_pose"].contains(&n.exec.as_str()) {
            assert!(n
                .params
                .iter()
                .any(|(k, v)| k == "rig_file" && v.as_str().unwrap().ends_with("rig_three_lasers.yaml")));
        }
        if ["camera_driver", "edge_detector", "triangulator", "mesher", "merger"].contains(&n.exec.as_str()) {
            let names: Vec<String> = rig.lasers.iter().map(|l| l.name.clone()).collect();
            assert_eq!(p.get("lasers"), Some(&ParamValue::StringArray(names.clone())), "{}", n.fq_name());
            let lasers = xsurf_nodes::lasers::from_params(&p, &names, [0.0; 3]).unwrap().unwrap();
            for (a, b) in lasers.iter().zip(&rig.lasers) {
                assert_eq!((&a.name, a.channel, a.source), (&b.name, b.channel, b.source));
                assert!(a.plane.iter().zip(&b.plane).all(|(x, y)| (x - y).abs() < 1e-12), "{}: {a:?}", n.fq_name());
            }
        }
    }
    let rviz = std::fs::read_to_string(root().join("launch-config/xsurf_three_lasers.rviz")).unwrap();
    let doc: serde_yaml::Value = serde_yaml::from_str(&rviz).unwrap();
    let by_laser: Vec<&str> = doc["Visualization Manager"]["Displays"]
        .as_sequence()
        .unwrap()
        .iter()
        .filter(|d| d["Channel Name"] == "laser" && d["Enabled"] == true)
        .filter_map(|d| d["Topic"]["Value"].as_str())
        .collect();
    assert_eq!(by_laser, ["/surface/cloud", "/cam1/cloud", "/cam2/cloud"]);
}

/// A bad `lasers` configuration stops the node at start-up with an error naming the parameter
/// (what every host does with a node's parameters before it opens DDS), and `xsurf reconstruct`
/// exits 2 with it, writing nothing.
#[test]
fn bad_laser_configurations_name_the_parameter() {
    let good = std::fs::read_to_string(root().join("launch-config/params_three_lasers.yaml")).unwrap();
    let cases: [(&str, &str, &str, &[&str]); 5] = [
        (
            "laser.left.channel: green",
            "laser.left.channel: red",
            "laser.left.channel",
            &["edge_detector", "triangulator", "mesher", "merger"],
        ),
        (
            "laser.right.plane: [0, 0.9063077870366499, -0.42261826174069944, 0.072504622962932]",
            "laser.right.plane: [0, 0.9, -0.5, 0.07]",
            "laser.right.plane",
            &["triangulator", "merger", "edge_detector"],
        ),
        (
            "    laser.left.plane: [0, 0.9063077870366499, 0.42261826174069944, -0.072504622962932]\n",
            "",
            "laser.left.plane",
            &["triangulator", "edge_detector"],
        ),
        ("laser.right.channel: blue", "laser.right.channel: violet", "laser.right.channel", &["edge_detector"]),
        ("    encoding: rgb8", "    encoding: mono8", "laser.left.channel", &["camera_driver"]),
    ];
    let dir = scratch("bad-lasers");
    for (from, to, names, nodes) in cases {
        assert!(good.contains(from), "{from}");
        let path = dir.join("p.yaml");
        std::fs::write(&path, good.replacen(from, to, 1)).unwrap();
        let ros = RosArgs::parse(&["--ros-args", "--params-file", path.to_str().unwrap()]).unwrap();
        for node in nodes {
            let fq = if *node == "merger" { "/merger".to_string() } else { format!("/cam1/{node}") };
            let o = ros.param_overrides(&fq).unwrap();
            let p = Params::resolve(&components::declarations(node).unwrap(), &o).unwrap();
            let e = components::build(node, &p).err().unwrap_or_else(|| panic!("{fq} started with {to:?}")).to_string();
            eprintln!("{fq}: {e}");
            assert!(e.contains(names), "{fq}: {e}");
        }
        if *nodes != ["camera_driver"] {
            let out = dir.join("out");
            let r = reconstruct(pyramid_bag(), &path, &out);
            assert_clean_failure(&r, 2, names);
            assert!(std::fs::read_dir(&out).map_or(true, |mut d| d.next().is_none()), "nothing written");
        }
    }
}
