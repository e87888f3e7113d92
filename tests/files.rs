//! The files we write are read by independent tools: the Khronos glTF validator reports no
//! error or warning, Coin3D (an Open Inventor / VRML97 implementation) parses the VRML and
//! generates our triangles, trimesh reads PLY and GLB (tests/reconstruct.rs).
#![allow(clippy::unwrap_used)]

mod common;
use common::*;
use std::path::Path;
use std::process::Command;
use xsurf_core::mesh::Mesh;
use xsurf_formats::scene::{Scene, Surface, TexturedPlane};

fn gltf_validate(files: &[&Path]) -> Option<serde_json::Value> {
    let dir = root().join("tests/gltf");
    if !dir.join("node_modules/gltf-validator").is_dir() {
        python()?; // fails under CI, skips otherwise
        assert!(
            std::env::var("XSURF_REQUIRE_CHECKERS").is_err(),
            "gltf-validator not installed: run scripts/setup-venv.sh"
        );
        return None;
    }
    let out = Command::new("node").arg(dir.join("validate.mjs")).args(files).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

fn vrml_check(file: &Path) -> Option<(bool, serde_json::Value, String)> {
    let bin = root().join(".venv/bin/vrml_check");
    if !bin.is_file() {
        assert!(std::env::var("XSURF_REQUIRE_CHECKERS").is_err(), "vrml_check not built: run scripts/setup-venv.sh");
        eprintln!("skipped: no vrml_check");
        return None;
    }
    let out = Command::new(bin).arg(file).output().unwrap();
    let json = serde_json::from_slice(&out.stdout).unwrap_or(serde_json::Value::Null);
    Some((out.status.success(), json, String::from_utf8_lossy(&out.stderr).into_owned()))
}

fn wavy(n: usize, dz: f32) -> Mesh {
    let mut m = Mesh::default();
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f32 * 0.01, j as f32 * 0.01);
            m.positions.push([x, y, dz + 0.02 * (x * 20.0).sin() * (y * 15.0).cos()]);
            m.colors.push([(i * 20) as u8, 128, (j * 20) as u8]);
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            m.triangles.push([a, a + 1, a + n as u32 + 1]);
            m.triangles.push([a, a + n as u32 + 1, a + n as u32]);
        }
    }
    m.compute_normals();
    m
}

#[test]
fn scene_with_surfaces_and_radiograph_passes_both_readers() {
    let dir = scratch("scene-files");
    let (a, b) = (wavy(12, 0.0), wavy(9, 0.05));
    let png = xsurf_formats::image::encode_png(
        4,
        2,
        xsurf_formats::image::PngKind::Grey8,
        &[0, 50, 100, 150, 200, 250, 30, 60],
    )
    .unwrap();
    let scene = Scene {
        surfaces: vec![
            Surface { name: "cam1", mesh: &a, transparency: 0.3 },
            Surface { name: "cam2", mesh: &b, transparency: 0.0 },
        ],
        plane: Some(TexturedPlane::quad(
            [[-0.1, -0.1, -0.01], [0.2, -0.1, -0.01], [0.2, 0.2, -0.01], [-0.1, 0.2, -0.01]],
            png,
            "xray.png",
        )),
    };
    let glb = dir.join("scene.glb");
    let wrl = dir.join("scene.wrl");
    xsurf_formats::gltf::write_file(&glb, &scene).unwrap();
    xsurf_formats::vrml::write_file(&wrl, &scene).unwrap();
    assert!(dir.join("xray.png").is_file(), "the texture is written beside the VRML");
    if let Some(j) = gltf_validate(&[&glb]) {
        let r = &j[glb.to_str().unwrap()];
        assert_eq!(r["errors"], 0, "{r}");
        assert_eq!(r["warnings"], 0, "{r}");
    }
    if let Some((ok, j, err)) = vrml_check(&wrl) {
        assert!(ok, "Coin could not read our VRML: {err}");
        assert_eq!(j["triangles"].as_u64().unwrap() as usize, a.triangles.len() + b.triangles.len() + 2, "{j}");
        assert_eq!(j["face_sets"], 3);
        assert_eq!(j["textures"], 1);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn reconstructed_scene_passes_both_readers() {
    let dir = scratch("recon-files");
    let params = pyramid_bag().join("params.yaml");
    let out = xsurf(&[
        "reconstruct",
        pyramid_bag().to_str().unwrap(),
        "--params-file",
        params.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
    if let Some(j) = gltf_validate(&[&dir.join("scene.glb")]) {
        let r = &j[dir.join("scene.glb").to_str().unwrap()];
        assert_eq!(r["errors"], 0, "{r}");
    }
    if let Some((ok, j, err)) = vrml_check(&dir.join("scene.wrl")) {
        assert!(ok, "{err}");
        assert_eq!(j["triangles"], report["merged_triangles"]);
    }
    // A broken VRML file is refused by the same reader: the check can fail.
    let bad = dir.join("bad.wrl");
    std::fs::write(
        &bad,
        "#VRML V2.0 utf8\nShape { geometry IndexedFaceSet { coord Coordinate { point [0 0 0, 1 0 0 } } }\n",
    )
    .unwrap();
    if let Some((ok, _, _)) = vrml_check(&bad) {
        assert!(!ok);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
