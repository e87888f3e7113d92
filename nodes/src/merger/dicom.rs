//! The merger's DICOM files and their way to the PACS.
//!
//! After each scan, beside its PLY and scenes, the merger writes `scan_<id>/surface.dcm` (a
//! Surface Scan Mesh instance, `xsurf_formats::dicom_surface`), with `dicom_file` also
//! `xray.dcm` (the radiograph in the scan's Frame of Reference) and with `point_cloud_dcm`
//! also `points.dcm` (a Surface Scan Point Cloud with each point's colour). With `pacs` set,
//! the scan's DICOM files are queued on disk and sent by a thread of their own
//! (`crate::pacs`).
//!
//! Which patient and study:
//! - With `dicom_file`, the radiograph's: the same Patient ID, names and Study Instance UID, a
//!   new series. A radiograph with a Frame of Reference UID gives the scan that frame (its
//!   pixels are already placed in the scanner's frame, which is `table`). Without a Patient
//!   ID, the `patient_id` parameter stands in where set (logged), else it stays empty as in
//!   the radiograph (type 2), so that both land in one study. A missing or malformed Study
//!   Instance UID, SOP Instance UID or Frame of Reference UID is an error naming the file,
//!   the element and the value: no DICOM is written for that scan (its other files are), for
//!   a surface in another study than its radiograph would mislead.
//! - Without, the parameters `patient_id`, `patient_name`, `accession_number` and
//!   `study_instance_uid`; without that UID, a new study per scan.
//! - UIDs are made under `2.25` from the study and the scan's START, so the same scan written
//!   twice gives the same instances (a PACS keeps one).
//!
//! The radiograph and the surface: the radiograph's pixel (column c, row r) is the detector
//! element c at the C-arm's travel of row r; `xray.json` beside them gives its placement in
//! `table` (the same Frame of Reference), which DX itself cannot carry.

use std::path::{Path, PathBuf};
use xsurf_core::mesh::Mesh;
use xsurf_formats::dicom_surface::{self as ds, Equipment, Instance, Study};
use xsurf_runtime::params::{ParamError, Params};

/// What the merger's parameters say about DICOM.
#[derive(Debug, Clone, PartialEq)]
pub struct DicomConfig {
    /// The radiograph whose patient and study the scans join.
    pub dicom_file: Option<PathBuf>,
    /// Patient and study without a radiograph (its UID empty: a new study per scan).
    pub study: Study,
    /// Also write `points.dcm`.
    pub point_cloud: bool,
    /// The device.
    pub equipment: Equipment,
    /// The surface's opacity.
    pub opacity: f32,
}

/// The PACS, our side of it and the queue's folder.
pub type PacsConfig = (crate::pacs::Peer, crate::pacs::Client, PathBuf);

/// The DICOM and PACS parameters, checked: each error names its parameter.
pub fn config(p: &super::MergerParams) -> Result<(DicomConfig, Option<PacsConfig>), ParamError> {
    let text = |name: &str, v: &str| -> Result<(), ParamError> {
        match v.chars().find(|c| c.is_control() || *c == '\\') {
            Some(c) => Err(Params::invalid(name, format!("{v:?} holds {c:?}"))),
            None => Ok(()),
        }
    };
    for (name, v) in [
        ("patient_id", &p.patient_id),
        ("patient_name", &p.patient_name),
        ("accession_number", &p.accession_number),
        ("device_serial_number", &p.device_serial_number),
        ("institution_name", &p.institution_name),
    ] {
        text(name, v)?;
    }
    if p.device_serial_number.trim().is_empty() {
        return Err(Params::invalid("device_serial_number", "must not be empty (a type 1 DICOM attribute)"));
    }
    if !p.study_instance_uid.is_empty() {
        xsurf_formats::dicom::check_uid(&p.study_instance_uid)
            .map_err(|why| Params::invalid("study_instance_uid", format!("{:?} is not a valid UID: {why}", p.study_instance_uid)))?;
    }
    let dicom = DicomConfig {
        dicom_file: (!p.dicom_file.is_empty()).then(|| PathBuf::from(&p.dicom_file)),
        study: xsurf_formats::dicom_surface::Study {
            patient_id: p.patient_id.clone(),
            patient_name: p.patient_name.clone(),
            accession_number: p.accession_number.clone(),
            study_instance_uid: p.study_instance_uid.clone(),
            ..Default::default()
        },
        point_cloud: p.point_cloud_dcm,
        equipment: xsurf_formats::dicom_surface::Equipment {
            manufacturer: "xsurf".into(),
            model_name: "xsurf C-arm laser surface scanner".into(),
            device_serial_number: p.device_serial_number.clone(),
            software_versions: env!("CARGO_PKG_VERSION").into(),
            station_name: String::new(),
            institution_name: p.institution_name.clone(),
        },
        opacity: 1.0 - p.transparency,
    };
    let pacs = if p.pacs.is_empty() {
        None
    } else {
        let peer: crate::pacs::Peer = p.pacs.parse().map_err(|e| Params::invalid("pacs", e))?;
        let client = crate::pacs::Client::new(&p.ae_title).map_err(|e| Params::invalid("ae_title", e))?;
        let queue = match (&p.pacs_queue_dir, &p.output_dir) {
            (Some(q), _) => q.clone(),
            (None, Some(o)) => o.join("pacs_queue"),
            (None, None) => {
                return Err(Params::invalid("pacs", "needs output_dir (the scans' DICOM files are written there) or pacs_queue_dir"))
            }
        };
        Some((peer, client, queue))
    };
    if pacs.is_some() && p.output_dir.is_none() {
        return Err(Params::invalid("pacs", "needs output_dir: the scans' DICOM files are written there first"));
    }
    Ok((dicom, pacs))
}

/// One scan's identity for its DICOM files.
#[derive(Debug, Clone, Copy)]
pub struct ScanSpan {
    /// Its id.
    pub scan_id: u32,
    /// START, ns since the Unix epoch.
    pub start_ns: i64,
    /// END.
    pub end_ns: i64,
}

/// Writes the scan's DICOM files into `dir`; returns the files written, or what is wrong
/// (naming the file) when none could be.
pub fn write_scan(cfg: &DicomConfig, dir: &Path, scan: ScanSpan, merged: &Mesh) -> Result<Vec<PathBuf>, String> {
    let (study, frame, xray) = match &cfg.dicom_file {
        Some(f) => {
            let x = ds::read_study(f).map_err(|e| format!("{e}: no DICOM written for scan {}", scan.scan_id))?;
            let mut study = x.study;
            if study.patient_id.is_empty() {
                if cfg.study.patient_id.is_empty() {
                    log::warn!("merger: {}: no Patient ID; surface.dcm has none either (the same study)", f.display());
                } else {
                    log::warn!(
                        "merger: {}: no Patient ID; surface.dcm takes patient_id {:?}",
                        f.display(),
                        cfg.study.patient_id
                    );
                    study.patient_id = cfg.study.patient_id.clone();
                }
            }
            (study, x.frame_of_reference_uid, Some(x.file))
        }
        None => {
            let mut study = cfg.study.clone();
            if study.study_instance_uid.is_empty() {
                study.study_instance_uid = ds::uid_for(&format!("xsurf/study/{}/{}", scan.start_ns, scan.scan_id));
            }
            (study, None, None)
        }
    };
    let key = format!("xsurf/{}/{}/{}", study.study_instance_uid, scan.start_ns, scan.scan_id);
    let frame = frame.unwrap_or_else(|| ds::uid_for(&format!("{key}/frame")));
    let inst = Instance {
        study: &study,
        equipment: &cfg.equipment,
        series_instance_uid: ds::uid_for(&format!("{key}/series")),
        series_number: 1000 + scan.scan_id,
        series_description: format!("surface scan {}", scan.scan_id),
        sop_instance_uid: ds::uid_for(&format!("{key}/surface")),
        frame_of_reference_uid: frame.clone(),
        acquisition_start_ns: scan.start_ns,
        acquisition_duration_s: (scan.end_ns - scan.start_ns).max(0) as f64 * 1e-9,
        acquisition_number: scan.scan_id,
        opacity: cfg.opacity,
    };
    let mut files = Vec::new();
    let surface = dir.join("surface.dcm");
    ds::write_surface_mesh(&surface, merged, &inst).map_err(|e| e.to_string())?;
    files.push(surface);
    if cfg.point_cloud {
        let points = dir.join("points.dcm");
        let pc = Instance { sop_instance_uid: ds::uid_for(&format!("{key}/points")), ..inst.clone() };
        ds::write_point_cloud(&points, merged, &pc).map_err(|e| e.to_string())?;
        files.push(points);
    }
    if let Some(x) = xray {
        let path = dir.join("xray.dcm");
        ds::write_xray_in_frame(x, &path, &frame).map_err(|e| e.to_string())?;
        files.push(path);
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use dicom_core::value::PrimitiveValue;
    use dicom_core::{DataElement, VR};
    use dicom_dictionary_std::tags;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("xsurf-merger-dicom-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn mesh() -> Mesh {
        Mesh {
            positions: vec![[0.0, 0.0, 0.1], [0.01, 0.0, 0.1], [0.0, 0.01, 0.11]],
            normals: Vec::new(),
            colors: vec![[200, 150, 120]; 3],
            triangles: vec![[0, 1, 2]],
        }
    }

    fn config(dicom_file: Option<PathBuf>, patient_id: &str) -> DicomConfig {
        DicomConfig {
            dicom_file,
            study: Study { patient_id: patient_id.into(), ..Study::default() },
            point_cloud: true,
            equipment: Equipment {
                manufacturer: "xsurf".into(),
                model_name: "test".into(),
                device_serial_number: "0".into(),
                software_versions: "0".into(),
                station_name: String::new(),
                institution_name: String::new(),
            },
            opacity: 0.7,
        }
    }

    /// A radiograph as our synthetic scanner writes it, changed by `edit`.
    fn radiograph(d: &Path, name: &str, edit: impl FnOnce(&mut dicom_object::DefaultDicomObject)) -> PathBuf {
        let p = d.join(name);
        let image = xsurf_core::xray::Radiograph::new(4, 3, vec![100; 12], 14).unwrap();
        xsurf_formats::dicom::write_file(&p, &image, &Default::default(), name).unwrap();
        let mut obj = dicom_object::open_file(&p).unwrap();
        edit(&mut obj);
        obj.write_to_file(&p).unwrap();
        p
    }

    fn read(p: &Path) -> dicom_object::DefaultDicomObject {
        dicom_object::open_file(p).unwrap()
    }

    fn text(o: &dicom_object::DefaultDicomObject, tag: dicom_core::Tag) -> String {
        o.element_opt(tag)
            .unwrap()
            .map(|e| e.to_str().unwrap().trim_end_matches(['\0', ' ']).to_string())
            .unwrap_or_default()
    }

    const SCAN: ScanSpan = ScanSpan { scan_id: 2, start_ns: 1_700_000_000_000_000_000, end_ns: 1_700_000_009_000_000_000 };

    #[test]
    fn the_surface_joins_the_radiographs_patient_study_and_frame() {
        let d = dir("join");
        let x = radiograph(&d, "x.dcm", |_| {});
        let files = write_scan(&config(Some(x.clone()), ""), &d, SCAN, &mesh()).unwrap();
        let names: Vec<_> = files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
        assert_eq!(names, ["surface.dcm", "points.dcm", "xray.dcm"]);
        let (s, p, xr, orig) = (read(&files[0]), read(&files[1]), read(&files[2]), read(&x));
        for tag in [tags::PATIENT_ID, tags::PATIENT_NAME, tags::STUDY_INSTANCE_UID] {
            assert_eq!(text(&s, tag), text(&orig, tag));
            assert_eq!(text(&xr, tag), text(&orig, tag));
        }
        assert_ne!(text(&s, tags::SERIES_INSTANCE_UID), text(&orig, tags::SERIES_INSTANCE_UID), "a new series");
        assert_eq!(text(&s, tags::SERIES_INSTANCE_UID), text(&p, tags::SERIES_INSTANCE_UID));
        let frame = text(&s, tags::FRAME_OF_REFERENCE_UID);
        assert!(!frame.is_empty());
        assert_eq!(text(&xr, tags::FRAME_OF_REFERENCE_UID), frame);
        assert_eq!(text(&p, tags::FRAME_OF_REFERENCE_UID), frame);
        assert_ne!(text(&xr, tags::SOP_INSTANCE_UID), text(&orig, tags::SOP_INSTANCE_UID), "another instance");
        assert_eq!(ds::check_instance(&s), Vec::<String>::new());
        // The same scan again: the same UIDs (a PACS keeps one copy).
        let again = write_scan(&config(Some(x), ""), &dir("join-again"), SCAN, &mesh()).unwrap();
        assert_eq!(text(&read(&again[0]), tags::SOP_INSTANCE_UID), text(&s, tags::SOP_INSTANCE_UID));
        // Each point's colour in the point cloud (Implicit VR: its US values exceed an explicit
        // length beyond 10 922 points).
        assert_eq!(p.meta().transfer_syntax().trim_end_matches('\0'), "1.2.840.10008.1.2");
        assert_eq!(p.element(tags::SURFACE_POINT_COLOR_CIE_LAB_VALUE_DATA).unwrap().to_multi_int::<u16>().unwrap().len(), 9);
    }

    #[test]
    fn a_radiograph_without_patient_id_with_a_bad_study_uid_or_with_a_frame() {
        let d = dir("bad");
        // No Patient ID: the parameter's where set, else none (the radiograph's study, still).
        let no_id = radiograph(&d, "noid.dcm", |o| {
            o.remove_element(tags::PATIENT_ID);
        });
        let out = d.join("a");
        std::fs::create_dir_all(&out).unwrap();
        let f = write_scan(&config(Some(no_id.clone()), "P-77"), &out, SCAN, &mesh()).unwrap();
        assert_eq!(text(&read(&f[0]), tags::PATIENT_ID), "P-77");
        assert_eq!(text(&read(&f[0]), tags::STUDY_INSTANCE_UID), text(&read(&no_id), tags::STUDY_INSTANCE_UID));
        let f = write_scan(&config(Some(no_id), ""), &out, SCAN, &mesh()).unwrap();
        assert_eq!(text(&read(&f[0]), tags::PATIENT_ID), "");
        // A malformed Study Instance UID: an error naming the file, the element and the value;
        // nothing written.
        let bad = radiograph(&d, "baduid.dcm", |o| {
            o.put(DataElement::new(tags::STUDY_INSTANCE_UID, VR::UI, PrimitiveValue::from("1.2.03.x")));
        });
        let out = d.join("b");
        std::fs::create_dir_all(&out).unwrap();
        let e = write_scan(&config(Some(bad), ""), &out, SCAN, &mesh()).unwrap_err();
        assert!(e.contains("baduid.dcm") && e.contains("StudyInstanceUID (0020,000D)") && e.contains("1.2.03.x"), "{e}");
        assert!(!out.join("surface.dcm").exists());
        // A Frame of Reference already set: the scan takes it.
        let framed = radiograph(&d, "framed.dcm", |o| {
            o.put(DataElement::new(tags::FRAME_OF_REFERENCE_UID, VR::UI, PrimitiveValue::from("1.2.3.4.5")));
        });
        let out = d.join("c");
        std::fs::create_dir_all(&out).unwrap();
        let f = write_scan(&config(Some(framed), ""), &out, SCAN, &mesh()).unwrap();
        assert_eq!(text(&read(&f[0]), tags::FRAME_OF_REFERENCE_UID), "1.2.3.4.5");
        assert_eq!(text(&read(&f[2]), tags::FRAME_OF_REFERENCE_UID), "1.2.3.4.5");
        // No radiograph: the parameters, and a new study per scan.
        let out = d.join("d");
        std::fs::create_dir_all(&out).unwrap();
        let f = write_scan(&config(None, "P-1"), &out, SCAN, &mesh()).unwrap();
        let s = read(&f[0]);
        assert_eq!(text(&s, tags::PATIENT_ID), "P-1");
        assert!(xsurf_formats::dicom::check_uid(&text(&s, tags::STUDY_INSTANCE_UID)).is_ok());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
