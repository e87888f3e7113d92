//! The radiograph: our synthetic DICOM read by pydicom, files written by pydicom read by us,
//! bad DICOM refused (naming the file and the element) with the surface still written, and the
//! placement measured: the sphere's shadow lands under the sphere fitted to the surface.
#![allow(clippy::unwrap_used)]

mod common;
use common::*;
use std::path::Path;
use xsurf_core::eval::fit_sphere;
use xsurf_core::geom::Vec3;
use xsurf_formats::dicom::{read_file, XrayFile};

#[test]
fn our_dicom_reads_in_pydicom_and_pydicom_files_read_in_ours() {
    let bag = pyramid_bag();
    let dcm = bag.join("xray.dcm");
    let ours = read_file(&dcm).unwrap();
    let dir = scratch("dicom-variants");
    let Some(facts) = checker("check_dicom.py", &[&dcm, &dir]) else { return };
    let img = &ours.image;
    assert_eq!(facts["rows"], img.height);
    assert_eq!(facts["columns"], img.width);
    assert_eq!(facts["bits_allocated"], 16);
    assert_eq!(facts["bits_stored"], 14);
    assert_eq!(facts["high_bit"], 13);
    assert_eq!(facts["photometric"], "MONOCHROME1");
    assert_eq!(facts["modality"], "DX");
    let w = img.window.unwrap();
    assert_eq!(facts["window_center"].as_f64().unwrap(), w.center);
    assert_eq!(facts["window_width"].as_f64().unwrap(), w.width);
    let sum: u64 = img.pixels.iter().map(|&p| u64::from(p)).sum();
    assert_eq!(facts["sum"].as_u64().unwrap(), sum, "pixel values");
    assert_eq!(facts["max"].as_u64().unwrap(), u64::from(*img.pixels.iter().max().unwrap()));
    assert_eq!(facts["source_detector_mm"].as_f64().unwrap(), 1300.0);
    assert_eq!(facts["imager_pixel_spacing_mm"][1].as_f64().unwrap(), 0.5);
    // The exposure is the scan's START..END (the bag's events).
    let (t0, t1) = (ours.info.acquisition_start_ns.unwrap(), ours.info.exposure_ms.unwrap());
    assert!(t0 > 0 && t1 > 1000.0, "{t0} {t1}");

    // RLE Lossless compressed by pydicom: the same pixels.
    let rle: XrayFile = read_file(&dir.join("rle.dcm")).unwrap();
    assert_eq!(rle.transfer_syntax, "1.2.840.10008.1.2.5");
    assert_eq!(rle.image.pixels, img.pixels);
    // Implicit VR, 12-bit signed MONOCHROME2 with a rescale and a VOI LUT.
    let f = read_file(&dir.join("implicit12.dcm")).unwrap();
    let values: Vec<i64> = facts["implicit12_values"].as_array().unwrap().iter().map(|v| v.as_i64().unwrap()).collect();
    let rescaled: Vec<f64> =
        f.image.pixels.iter().map(|&p| f.image.rescale_slope * f64::from(p) + f.image.rescale_intercept).collect();
    let want: Vec<f64> = values.iter().map(|&v| 2.0 * v as f64 + 100.0).collect();
    assert_eq!(rescaled, want);
    assert!(!f.image.monochrome1);
    // The VOI LUT (first value 98, 4 entries of 8 bits) maps 98 -> 0, 100 -> 200, beyond -> 255.
    let shown = f.image.display(None);
    assert_eq!(&shown[..4], &[0, 0, 200, 255], "{shown:?}");
    // Refused with the file and the element named.
    let e = read_file(&dir.join("jpegls.dcm")).unwrap_err().to_string();
    assert!(
        e.contains("jpegls.dcm") && e.contains("PixelData (7FE0,0010)") && e.contains("1.2.840.10008.1.2.4.80"),
        "{e}"
    );
    let e = read_file(&dir.join("nopixels.dcm")).unwrap_err().to_string();
    assert!(e.contains("nopixels.dcm") && e.contains("PixelData (7FE0,0010) is missing"), "{e}");
}

#[test]
fn bad_dicom_is_named_and_the_surface_still_written() {
    let bag = pyramid_bag();
    let dir = scratch("bad-dicom");
    let bytes = std::fs::read(bag.join("xray.dcm")).unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("truncated.dcm", bytes[..bytes.len() / 2].to_vec(), "truncated.dcm"),
        ("text.dcm", b"not dicom at all".to_vec(), "not a DICOM file: the \"DICM\" prefix at byte offset 128 (PS3.10 7.1) is missing (the file ends at byte 16)"),
    ];
    for (name, data, what) in cases {
        let f = dir.join(name);
        std::fs::write(&f, data).unwrap();
        let out_dir = dir.join(format!("out-{name}"));
        let params = bag.join("params.yaml");
        let out = xsurf(&[
            "reconstruct",
            bag.to_str().unwrap(),
            "--params-file",
            params.to_str().unwrap(),
            "--xray",
            f.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
            "--quiet",
        ]);
        assert_clean_failure(&out, 3, what);
        assert_clean_failure(&out, 3, name);
        for file in ["merged.ply", "scene.wrl", "scene.glb", "preview.png", "report.json"] {
            assert!(out_dir.join(file).is_file(), "{name}: {file} missing");
        }
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out_dir.join("report.json")).unwrap()).unwrap();
        assert!(report["xray"].as_str().unwrap().starts_with("not placed"), "{report}");
    }
}

/// Where the sphere's shadow lies in the radiograph: the attenuation-weighted centroid (chord
/// lengths are symmetric about the ray through the centre), in full-detector pixel coordinates.
fn shadow_centroid(x: &XrayFile) -> (f64, f64) {
    let img = &x.image;
    let w = img.width as usize;
    let cols = img.exposed_columns(0.1).unwrap();
    // Open beam (through the tabletop only): the 90th percentile of the exposed pixels.
    let mut exposed: Vec<u16> =
        img.pixels.iter().enumerate().filter(|(i, _)| cols.contains(&((i % w) as u32))).map(|(_, &p)| p).collect();
    exposed.sort_unstable();
    let open = f64::from(exposed[exposed.len() * 9 / 10]);
    let dark = 40.0;
    let (mut sw, mut sc, mut sr) = (0.0, 0.0, 0.0);
    for (i, &p) in img.pixels.iter().enumerate() {
        if !cols.contains(&((i % w) as u32)) {
            continue;
        }
        let a = ((open - dark) / (f64::from(p) - dark).max(1.0)).ln();
        if a > 0.1 {
            sw += a;
            sc += a * ((i % w) as f64 + 0.5);
            sr += a * ((i / w) as f64 + 0.5);
        }
    }
    (sc / sw, sr / sw)
}

/// The table point of detector position (col, row) through the placement in `xray.json`
/// (bilinear in the grid, which is regular in texture coordinates).
fn placed(json: &serde_json::Value, col: f64, row: f64) -> Vec3 {
    let [c0, c1] = [json["columns"][0].as_f64().unwrap(), json["columns"][1].as_f64().unwrap()];
    let rows = json["rows"].as_f64().unwrap();
    let g = &json["grid"];
    let (nc, nr) = (g["columns"].as_u64().unwrap() as usize, g["rows"].as_u64().unwrap() as usize);
    let p = |j: usize, k: usize| {
        let v = &g["positions"][k * nc + j];
        Vec3::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap(), v[2].as_f64().unwrap())
    };
    let (fu, fv) = ((col - c0) / (c1 - c0) * (nc - 1) as f64, row / rows * (nr - 1) as f64);
    let (j, k) = ((fu.floor() as usize).min(nc - 2), (fv.floor() as usize).min(nr - 2));
    let (a, b) = (fu - j as f64, fv - k as f64);
    let top = p(j, k).lerp(p(j + 1, k), a);
    let bottom = p(j, k + 1).lerp(p(j + 1, k + 1), a);
    top.lerp(bottom, b)
}

fn reconstruct_sphere(bag: &Path, out: &Path, plane_height: f64) -> serde_json::Value {
    let params = out.with_extension("yaml");
    std::fs::write(
        &params,
        format!(
            "{}\n/xray_aligner:\n  ros__parameters:\n    plane_height_m: {plane_height}\n",
            std::fs::read_to_string(bag.join("params.yaml")).unwrap()
        ),
    )
    .unwrap();
    let dcm = bag.join("xray.dcm");
    let run = xsurf(&[
        "reconstruct",
        bag.to_str().unwrap(),
        "--params-file",
        params.to_str().unwrap(),
        "--xray",
        dcm.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    for f in ["xray.png", "xray.json", "scene.wrl", "scene.glb", "preview.png"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let wrl = std::fs::read_to_string(out.join("scene.wrl")).unwrap();
    assert!(wrl.contains("ImageTexture { url \"xray.png\""));
    let glb = std::fs::read(out.join("scene.glb")).unwrap();
    let j = xsurf_formats::gltf::read_json(&glb).unwrap();
    assert_eq!(j["images"][0]["mimeType"], "image/png");
    serde_json::from_slice(&std::fs::read(out.join("xray.json")).unwrap()).unwrap()
}

#[test]
fn the_sphere_shadow_lies_under_the_sphere_fitted_to_the_surface() {
    let dir = scratch("xray-sphere");
    let bag = dir.join("bag");
    let out = xsurf(&["synth", "sphere", "-o", bag.to_str().unwrap(), "--size", "320x240", "--speed", "0.14"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // The sphere fitted to the reconstructed surface (points above the table).
    let flat = dir.join("flat");
    let placement = reconstruct_sphere(&bag, &flat, 0.0);
    let merged =
        xsurf_formats::ply::read(&mut std::io::BufReader::new(std::fs::File::open(flat.join("merged.ply")).unwrap()))
            .unwrap();
    let pts: Vec<Vec3> = merged
        .positions
        .iter()
        .map(|p| Vec3::new(p[0].into(), p[1].into(), p[2].into()))
        .filter(|p| p.z > 0.01)
        .collect();
    // Refit without the few silhouette outliers (mixed pixels at the sphere's rim).
    let first = fit_sphere(&pts).unwrap();
    let inliers: Vec<Vec3> =
        pts.into_iter().filter(|p| ((*p - first.center).norm() - first.radius).abs() < 2e-3).collect();
    let fit = fit_sphere(&inliers).unwrap();
    assert!(fit.rms_m < 0.5e-3 && (fit.radius - 0.08).abs() < 1e-3, "{fit:?}");
    let x = read_file(&bag.join("xray.dcm")).unwrap();
    let (col, row) = shadow_centroid(&x);

    // On the tabletop the fan beam projects the centre outwards by z / (source height - z).
    let on_table = placed(&placement, col, row);
    let c = fit.center;
    let projected = c.x * 1.2 / (1.2 - c.z);
    assert!((on_table.y - c.y).abs() < 1e-3, "Y: radiograph {:.4} vs surface {:.4}", on_table.y, c.y);
    assert!((on_table.x - projected).abs() < 1e-3, "X: {:.4} vs projected {:.4}", on_table.x, projected);
    assert!((on_table.x - c.x).abs() > 2e-3, "the tabletop placement must show the fan magnification");

    // On the plane through the centre: within 1 mm in X and Y.
    let mid = dir.join("mid");
    let placement = reconstruct_sphere(&bag, &mid, c.z);
    let at_center = placed(&placement, col, row);
    let (dx, dy) = (at_center.x - c.x, at_center.y - c.y);
    eprintln!("sphere fit {c:?} r {:.4}; radiograph centre {at_center:?}; dx {dx:.5} dy {dy:.5} m", fit.radius);
    assert!(dx.abs() < 1e-3 && dy.abs() < 1e-3, "dx {dx} dy {dy}");
    assert!((at_center.z - c.z).abs() < 1e-9);
}
