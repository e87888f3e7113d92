//! The surface in the hospital's archive: DICOM Surface Scan Mesh Storage (PS3.3 A.68) and
//! Surface Scan Point Cloud Storage (A.69) instances, the patient and study they join, and the
//! radiograph's copy that shares their Frame of Reference.
//!
//! Every mandatory module is written (Patient, General Study, General Series, Optical Surface
//! Scanner Series, Frame of Reference, General and Enhanced General Equipment, Scan Procedure,
//! Surface Mesh or Point Cloud, SOP Common), with each type 1 attribute given a value and each
//! type 2 attribute present (empty where nothing is known). [`MODULES`] lists them, and the
//! tests check every instance against that list.
//!
//! Choices the standard leaves open:
//! - **Points** are in millimetres in the scan's Frame of Reference, which is the `table`
//!   frame (x across the table, y along the C-arm's travel, z up). The triangles are the
//!   Long Triangle Point Index List, 1-based.
//! - **Colour.** The Surface Mesh module has one colour per surface, not per point: Recommended
//!   Display CIELab Value is the mean of the vertex colours (sRGB, turned to CIELab D50 as the
//!   ICC profile connection space has it), and Recommended Display Grayscale Value their mean
//!   luminance. The Point Cloud instance carries each point's colour (Surface Point Color
//!   CIELab Value Data). A colour per vertex of the mesh stays in `merged.ply`, `scene.glb`.
//! - **Acquisition.** One scan (one travel of the C-arm, all cameras at once) is one shot:
//!   Surface Scan Acquisition Type (114203, DCM, "Laser scanning"), Instance Number 1,
//!   Acquisition Number the scan id, Shot Duration Time the scan's length. The cameras are
//!   placed by calibration, so no Registration Method is named.
//! - **UIDs** are made under the `2.25` root (ISO/IEC 9834-8: a 128-bit number in decimal) from
//!   a key: the same scan gives the same UIDs, so a PACS receiving it twice keeps one copy.
//! - **Character set.** Names are copied with the radiograph's Specific Character Set; the ones
//!   we make are ASCII (the default repertoire).
//! - The data set is Explicit VR Little Endian, but for a point cloud with colours
//!   (Implicit VR Little Endian: the colours are US values, whose explicit length field of 16
//!   bits holds no more than 10 922 points).

use crate::dicom::{check_uid, name_of, open_checked, uid, DicomError};
use dicom_core::value::{DataSetSequence, PrimitiveValue, C};
use dicom_core::{DataElement, Length, Tag, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::InMemDicomObject;
use std::path::Path;
use xsurf_core::mesh::Mesh;

/// Explicit VR Little Endian.
const EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1";
/// Implicit VR Little Endian.
const IMPLICIT_VR_LE: &str = "1.2.840.10008.1.2";

/// The patient and the study a scan joins.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Study {
    /// Patient's Name (0010,0010).
    pub patient_name: String,
    /// Patient ID (0010,0020).
    pub patient_id: String,
    /// Patient's Birth Date (0010,0030).
    pub patient_birth_date: String,
    /// Patient's Sex (0010,0040).
    pub patient_sex: String,
    /// Study Instance UID (0020,000D).
    pub study_instance_uid: String,
    /// Study Date (0008,0020).
    pub study_date: String,
    /// Study Time (0008,0030).
    pub study_time: String,
    /// Referring Physician's Name (0008,0090).
    pub referring_physician_name: String,
    /// Study ID (0020,0010).
    pub study_id: String,
    /// Accession Number (0008,0050).
    pub accession_number: String,
    /// Study Description (0008,1030).
    pub study_description: String,
    /// Specific Character Set (0008,0005) of the names; empty for the default repertoire.
    pub specific_character_set: String,
}

/// The patient, study and frame of a radiograph's DICOM file, and the file as read.
#[derive(Debug, Clone)]
pub struct XrayStudy {
    /// Its patient and study.
    pub study: Study,
    /// Its Frame of Reference UID (0020,0052), if it has one.
    pub frame_of_reference_uid: Option<String>,
    /// Its SOP Instance UID.
    pub sop_instance_uid: String,
    /// Its Series Instance UID.
    pub series_instance_uid: String,
    /// The file as read (for [`write_xray_in_frame`], so that it is not read again).
    pub file: XrayFileData,
}

/// A radiograph's DICOM file as read, every element kept.
#[derive(Debug, Clone)]
pub struct XrayFileData(dicom_object::DefaultDicomObject);

fn text(obj: &InMemDicomObject, tag: Tag) -> String {
    obj.element_opt(tag)
        .ok()
        .flatten()
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim_end_matches(['\0', ' ']).trim_start().to_string())
        .unwrap_or_default()
}

/// A UID element of `obj` checked: `Ok(None)` when absent or empty.
fn uid_of(obj: &InMemDicomObject, tag: Tag) -> Result<Option<String>, String> {
    let v = text(obj, tag);
    if v.is_empty() {
        return Ok(None);
    }
    check_uid(&v).map_err(|why| format!("{} {v:?} is not a valid UID: {why}", name_of(tag)))?;
    Ok(Some(v))
}

/// Reads the patient, study and frame of the radiograph in `path` (its pixels are not
/// decoded). A missing or malformed Study Instance UID, SOP Instance UID or Frame of
/// Reference UID is an error naming the file, the element and the value; a missing Patient ID
/// is not (it is type 2: the caller decides).
pub fn read_study(path: &Path) -> Result<XrayStudy, DicomError> {
    let err = |what: String| DicomError { file: path.to_path_buf(), what };
    let obj = open_checked(path)?;
    let required = |tag| uid_of(&obj, tag)?.ok_or_else(|| format!("{} is missing", name_of(tag)));
    let study_instance_uid = required(tags::STUDY_INSTANCE_UID).map_err(err)?;
    let sop_instance_uid = required(tags::SOP_INSTANCE_UID).map_err(err)?;
    let series_instance_uid = required(tags::SERIES_INSTANCE_UID).map_err(err)?;
    let frame_of_reference_uid = uid_of(&obj, tags::FRAME_OF_REFERENCE_UID).map_err(err)?;
    let study = Study {
        patient_name: text(&obj, tags::PATIENT_NAME),
        patient_id: text(&obj, tags::PATIENT_ID),
        patient_birth_date: text(&obj, tags::PATIENT_BIRTH_DATE),
        patient_sex: text(&obj, tags::PATIENT_SEX),
        study_instance_uid,
        study_date: text(&obj, tags::STUDY_DATE),
        study_time: text(&obj, tags::STUDY_TIME),
        referring_physician_name: text(&obj, tags::REFERRING_PHYSICIAN_NAME),
        study_id: text(&obj, tags::STUDY_ID),
        accession_number: text(&obj, tags::ACCESSION_NUMBER),
        study_description: text(&obj, tags::STUDY_DESCRIPTION),
        specific_character_set: text(&obj, tags::SPECIFIC_CHARACTER_SET),
    };
    Ok(XrayStudy { study, frame_of_reference_uid, sop_instance_uid, series_instance_uid, file: XrayFileData(obj) })
}

/// A UID under the `2.25` root made from `key` (the same key gives the same UID).
pub fn uid_for(key: &str) -> String {
    uid(key)
}

/// The device that made the surface (General and Enhanced General Equipment).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Equipment {
    /// Manufacturer (0008,0070).
    pub manufacturer: String,
    /// Manufacturer's Model Name (0008,1090).
    pub model_name: String,
    /// Device Serial Number (0018,1000).
    pub device_serial_number: String,
    /// Software Versions (0018,1020).
    pub software_versions: String,
    /// Station Name (0008,1010); empty: not written.
    pub station_name: String,
    /// Institution Name (0008,0080); empty: not written.
    pub institution_name: String,
}

/// What makes one surface instance: its study, series, frame and acquisition.
#[derive(Debug, Clone)]
pub struct Instance<'a> {
    /// The patient and study.
    pub study: &'a Study,
    /// The device.
    pub equipment: &'a Equipment,
    /// Series Instance UID (the OSS series of the scan).
    pub series_instance_uid: String,
    /// Series Number.
    pub series_number: u32,
    /// Series Description.
    pub series_description: String,
    /// SOP Instance UID.
    pub sop_instance_uid: String,
    /// Frame of Reference UID: the `table` frame of this scan.
    pub frame_of_reference_uid: String,
    /// The scan's START, ns since the Unix epoch.
    pub acquisition_start_ns: i64,
    /// The scan's length (START to END), s.
    pub acquisition_duration_s: f64,
    /// Acquisition Number: the scan id.
    pub acquisition_number: u32,
    /// Recommended Presentation Opacity, 0..1.
    pub opacity: f32,
}

/// The mandatory modules of the two IODs and their attributes of types 1 and 2 (top level;
/// sequences' items are checked by [`check_instance`]), `(module, tag, type)`.
pub const MODULES: &[(&str, Tag, &str)] = &[
    ("Patient", tags::PATIENT_NAME, "2"),
    ("Patient", tags::PATIENT_ID, "2"),
    ("Patient", tags::PATIENT_BIRTH_DATE, "2"),
    ("Patient", tags::PATIENT_SEX, "2"),
    ("General Study", tags::STUDY_INSTANCE_UID, "1"),
    ("General Study", tags::STUDY_DATE, "2"),
    ("General Study", tags::STUDY_TIME, "2"),
    ("General Study", tags::REFERRING_PHYSICIAN_NAME, "2"),
    ("General Study", tags::STUDY_ID, "2"),
    ("General Study", tags::ACCESSION_NUMBER, "2"),
    ("General Series", tags::MODALITY, "1"),
    ("General Series", tags::SERIES_INSTANCE_UID, "1"),
    ("General Series", tags::SERIES_NUMBER, "2"),
    ("Optical Surface Scanner Series", tags::REFERENCED_SURFACE_DATA_SEQUENCE, "2"),
    ("Frame of Reference", tags::FRAME_OF_REFERENCE_UID, "1"),
    ("Frame of Reference", tags::POSITION_REFERENCE_INDICATOR, "2"),
    ("General Equipment", tags::MANUFACTURER, "2"),
    ("Enhanced General Equipment", tags::MANUFACTURER, "1"),
    ("Enhanced General Equipment", tags::MANUFACTURER_MODEL_NAME, "1"),
    ("Enhanced General Equipment", tags::DEVICE_SERIAL_NUMBER, "1"),
    ("Enhanced General Equipment", tags::SOFTWARE_VERSIONS, "1"),
    ("Scan Procedure", tags::SURFACE_SCAN_ACQUISITION_TYPE_CODE_SEQUENCE, "1"),
    ("Scan Procedure", tags::SURFACE_SCAN_MODE_CODE_SEQUENCE, "2"),
    ("Scan Procedure", tags::INSTANCE_NUMBER, "1"),
    ("Scan Procedure", tags::ACQUISITION_NUMBER, "1"),
    ("Scan Procedure", tags::ACQUISITION_DATE_TIME, "1"),
    ("Scan Procedure", tags::SHOT_DURATION_TIME, "1"),
    ("SOP Common", tags::SOP_CLASS_UID, "1"),
    ("SOP Common", tags::SOP_INSTANCE_UID, "1"),
];

/// The Surface Mesh module's attributes (top level, then in the Surface Sequence item).
pub const SURFACE_MESH_MODULE: &[(&str, Tag, &str)] = &[
    ("Surface Mesh", tags::NUMBER_OF_SURFACES, "1"),
    ("Surface Mesh", tags::SURFACE_SEQUENCE, "1"),
    ("Surface Sequence item", tags::SURFACE_NUMBER, "1"),
    ("Surface Sequence item", tags::SURFACE_PROCESSING, "2"),
    ("Surface Sequence item", tags::RECOMMENDED_DISPLAY_GRAYSCALE_VALUE, "1"),
    ("Surface Sequence item", tags::RECOMMENDED_DISPLAY_CIE_LAB_VALUE, "1"),
    ("Surface Sequence item", tags::RECOMMENDED_PRESENTATION_OPACITY, "1"),
    ("Surface Sequence item", tags::RECOMMENDED_PRESENTATION_TYPE, "1"),
    ("Surface Sequence item", tags::FINITE_VOLUME, "1"),
    ("Surface Sequence item", tags::MANIFOLD, "1"),
    ("Surface Sequence item", tags::SURFACE_POINTS_SEQUENCE, "1"),
    ("Surface Sequence item", tags::SURFACE_POINTS_NORMALS_SEQUENCE, "2"),
    ("Surface Sequence item", tags::SURFACE_MESH_PRIMITIVES_SEQUENCE, "1"),
];

fn el_str(tag: Tag, vr: VR, v: &str) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, vr, PrimitiveValue::from(v))
}

fn empty(tag: Tag, vr: VR) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, vr, PrimitiveValue::Empty)
}

fn seq(tag: Tag, items: Vec<InMemDicomObject>) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, VR::SQ, DataSetSequence::new(items, Length::UNDEFINED))
}

/// A Code Sequence Macro item.
fn code(value: &str, scheme: &str, meaning: &str) -> InMemDicomObject {
    InMemDicomObject::from_element_iter([
        el_str(tags::CODE_VALUE, VR::SH, value),
        el_str(tags::CODING_SCHEME_DESIGNATOR, VR::SH, scheme),
        el_str(tags::CODE_MEANING, VR::LO, meaning),
    ])
}

/// A string element, or an empty one for a type 2 attribute with nothing known.
fn maybe(tag: Tag, vr: VR, v: &str) -> DataElement<InMemDicomObject> {
    if v.is_empty() {
        empty(tag, vr)
    } else {
        el_str(tag, vr, v)
    }
}

/// The modules shared by both IODs: Patient, General Study, General Series, Optical Surface
/// Scanner Series, Frame of Reference, General and Enhanced General Equipment, Scan Procedure
/// and SOP Common.
fn common(inst: &Instance, sop_class: &str) -> Vec<DataElement<InMemDicomObject>> {
    let s = inst.study;
    let e = inst.equipment;
    let when = crate::dicom::format_datetime(inst.acquisition_start_ns);
    let (date, time) = (&when[..8], &when[8..14]);
    let mut v = vec![
        el_str(tags::SOP_CLASS_UID, VR::UI, sop_class),
        el_str(tags::SOP_INSTANCE_UID, VR::UI, &inst.sop_instance_uid),
        maybe(tags::PATIENT_NAME, VR::PN, &s.patient_name),
        maybe(tags::PATIENT_ID, VR::LO, &s.patient_id),
        maybe(tags::PATIENT_BIRTH_DATE, VR::DA, &s.patient_birth_date),
        maybe(tags::PATIENT_SEX, VR::CS, &s.patient_sex),
        el_str(tags::STUDY_INSTANCE_UID, VR::UI, &s.study_instance_uid),
        el_str(tags::STUDY_DATE, VR::DA, if s.study_date.is_empty() { date } else { &s.study_date }),
        el_str(tags::STUDY_TIME, VR::TM, if s.study_time.is_empty() { time } else { &s.study_time }),
        maybe(tags::REFERRING_PHYSICIAN_NAME, VR::PN, &s.referring_physician_name),
        maybe(tags::STUDY_ID, VR::SH, &s.study_id),
        maybe(tags::ACCESSION_NUMBER, VR::SH, &s.accession_number),
        el_str(tags::MODALITY, VR::CS, "OSS"),
        el_str(tags::SERIES_INSTANCE_UID, VR::UI, &inst.series_instance_uid),
        el_str(tags::SERIES_NUMBER, VR::IS, &inst.series_number.to_string()),
        el_str(tags::SERIES_DATE, VR::DA, date),
        el_str(tags::SERIES_TIME, VR::TM, time),
        seq(tags::REFERENCED_SURFACE_DATA_SEQUENCE, Vec::new()),
        el_str(tags::FRAME_OF_REFERENCE_UID, VR::UI, &inst.frame_of_reference_uid),
        empty(tags::POSITION_REFERENCE_INDICATOR, VR::LO),
        el_str(tags::MANUFACTURER, VR::LO, &e.manufacturer),
        el_str(tags::MANUFACTURER_MODEL_NAME, VR::LO, &e.model_name),
        el_str(tags::DEVICE_SERIAL_NUMBER, VR::LO, &e.device_serial_number),
        el_str(tags::SOFTWARE_VERSIONS, VR::LO, &e.software_versions),
        seq(tags::SURFACE_SCAN_ACQUISITION_TYPE_CODE_SEQUENCE, vec![code("114203", "DCM", "Laser scanning")]),
        seq(tags::SURFACE_SCAN_MODE_CODE_SEQUENCE, Vec::new()),
        el_str(tags::INSTANCE_NUMBER, VR::IS, "1"),
        el_str(tags::ACQUISITION_NUMBER, VR::IS, &inst.acquisition_number.to_string()),
        el_str(tags::ACQUISITION_DATE_TIME, VR::DT, &when),
        DataElement::new(tags::SHOT_DURATION_TIME, VR::FD, PrimitiveValue::from(inst.acquisition_duration_s.max(0.0))),
        el_str(tags::CONTENT_DATE, VR::DA, date),
        el_str(tags::CONTENT_TIME, VR::TM, time),
    ];
    if !s.study_description.is_empty() {
        v.push(el_str(tags::STUDY_DESCRIPTION, VR::LO, &s.study_description));
    }
    if !inst.series_description.is_empty() {
        v.push(el_str(tags::SERIES_DESCRIPTION, VR::LO, &inst.series_description));
    }
    if !s.specific_character_set.is_empty() {
        v.push(el_str(tags::SPECIFIC_CHARACTER_SET, VR::CS, &s.specific_character_set));
    }
    if !e.station_name.is_empty() {
        v.push(el_str(tags::STATION_NAME, VR::SH, &e.station_name));
    }
    if !e.institution_name.is_empty() {
        v.push(el_str(tags::INSTITUTION_NAME, VR::LO, &e.institution_name));
    }
    v
}

/// The Points Macro item of `positions` (metres) in millimetres, with their bounding box.
fn points_item(positions: &[[f32; 3]]) -> InMemDicomObject {
    let mm: Vec<f32> = positions.iter().flat_map(|p| p.map(|c| (f64::from(c) * 1e3) as f32)).collect();
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in mm.chunks_exact(3) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let mut els = vec![
        DataElement::new(tags::NUMBER_OF_SURFACE_POINTS, VR::UL, PrimitiveValue::from(positions.len() as u32)),
        DataElement::new(tags::POINT_COORDINATES_DATA, VR::OF, PrimitiveValue::F32(C::from_vec(mm))),
    ];
    if !positions.is_empty() {
        els.push(DataElement::new(
            tags::POINTS_BOUNDING_BOX_COORDINATES,
            VR::FL,
            PrimitiveValue::F32(C::from_vec(vec![lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]])),
        ));
    }
    InMemDicomObject::from_element_iter(els)
}

/// sRGB (8 bits a channel) to CIELab under D50 (the ICC profile connection space), as DICOM
/// encodes it (PS3.3 C.10.7.1.1): L* 0..100 to 0..0xFFFF, a* and b* -128..127 to 0..0xFFFF.
pub fn srgb_to_dicom_lab(rgb: [f64; 3]) -> [u16; 3] {
    let lin = rgb.map(|c| {
        let c = (c / 255.0).clamp(0.0, 1.0);
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    });
    // sRGB to XYZ, Bradford-adapted from D65 to D50 (Lindbloom).
    let m = [[0.4360747, 0.3850649, 0.1430804], [0.2225045, 0.7168786, 0.0606169], [0.0139322, 0.0971045, 0.7141733]];
    let xyz = m.map(|r| r[0] * lin[0] + r[1] * lin[1] + r[2] * lin[2]);
    let white = [0.96422, 1.0, 0.82521];
    let f = |t: f64| {
        let e = 216.0 / 24389.0;
        if t > e {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let [fx, fy, fz] = [f(xyz[0] / white[0]), f(xyz[1] / white[1]), f(xyz[2] / white[2])];
    let (l, a, b) = (116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz));
    let q = |v: f64| v.round().clamp(0.0, 65535.0) as u16;
    [q(l * 65535.0 / 100.0), q((a + 128.0) * 65535.0 / 255.0), q((b + 128.0) * 65535.0 / 255.0)]
}

/// The Surface Scan Mesh instance of `mesh` (positions in metres in `table`).
pub fn surface_mesh(mesh: &Mesh, inst: &Instance) -> Result<InMemDicomObject, String> {
    let n = mesh.positions.len();
    if n == 0 || mesh.triangles.is_empty() {
        return Err(format!("{n} points and {} triangles: nothing to store", mesh.triangles.len()));
    }
    if let Some(t) = mesh.triangles.iter().find(|t| t.iter().any(|&i| i as usize >= n)) {
        return Err(format!("triangle {t:?} names a point beyond the {n} points"));
    }
    let mean = if mesh.colors.len() == n {
        let mut s = [0.0f64; 3];
        for c in &mesh.colors {
            for k in 0..3 {
                s[k] += f64::from(c[k]);
            }
        }
        s.map(|v| v / n as f64)
    } else {
        [200.0; 3]
    };
    let grey = (0.2126 * mean[0] + 0.7152 * mean[1] + 0.0722 * mean[2]) / 255.0 * 65535.0;
    let normals = if mesh.normals.len() == n {
        vec![InMemDicomObject::from_element_iter([
            DataElement::new(tags::NUMBER_OF_VECTORS, VR::UL, PrimitiveValue::from(n as u32)),
            DataElement::new(tags::VECTOR_DIMENSIONALITY, VR::US, PrimitiveValue::from(3u16)),
            DataElement::new(
                tags::VECTOR_COORDINATE_DATA,
                VR::OF,
                PrimitiveValue::F32(C::from_vec(mesh.normals.iter().flatten().copied().collect())),
            ),
        ])]
    } else {
        Vec::new()
    };
    let triangles: Vec<u32> = mesh.triangles.iter().flatten().map(|&i| i + 1).collect();
    let primitives = InMemDicomObject::from_element_iter([
        empty(tags::LONG_VERTEX_POINT_INDEX_LIST, VR::OL),
        empty(tags::LONG_EDGE_POINT_INDEX_LIST, VR::OL),
        DataElement::new(tags::LONG_TRIANGLE_POINT_INDEX_LIST, VR::OL, PrimitiveValue::U32(C::from_vec(triangles))),
        seq(tags::TRIANGLE_STRIP_SEQUENCE, Vec::new()),
        seq(tags::TRIANGLE_FAN_SEQUENCE, Vec::new()),
        seq(tags::LINE_SEQUENCE, Vec::new()),
        seq(tags::FACET_SEQUENCE, Vec::new()),
    ]);
    let surface = InMemDicomObject::from_element_iter([
        DataElement::new(tags::SURFACE_NUMBER, VR::UL, PrimitiveValue::from(1u32)),
        el_str(tags::SURFACE_COMMENTS, VR::LT, "the merged skin surface of one scan, all cameras"),
        empty(tags::SURFACE_PROCESSING, VR::CS),
        DataElement::new(
            tags::RECOMMENDED_DISPLAY_GRAYSCALE_VALUE,
            VR::US,
            PrimitiveValue::from(grey.round().clamp(0.0, 65535.0) as u16),
        ),
        DataElement::new(
            tags::RECOMMENDED_DISPLAY_CIE_LAB_VALUE,
            VR::US,
            PrimitiveValue::U16(C::from_vec(srgb_to_dicom_lab(mean).to_vec())),
        ),
        DataElement::new(
            tags::RECOMMENDED_PRESENTATION_OPACITY,
            VR::FL,
            PrimitiveValue::from(inst.opacity.clamp(0.0, 1.0)),
        ),
        el_str(tags::RECOMMENDED_PRESENTATION_TYPE, VR::CS, "SURFACE"),
        el_str(tags::FINITE_VOLUME, VR::CS, "NO"),
        el_str(tags::MANIFOLD, VR::CS, "UNKNOWN"),
        seq(tags::SURFACE_POINTS_SEQUENCE, vec![points_item(&mesh.positions)]),
        seq(tags::SURFACE_POINTS_NORMALS_SEQUENCE, normals),
        seq(tags::SURFACE_MESH_PRIMITIVES_SEQUENCE, vec![primitives]),
    ]);
    let mut els = common(inst, uids::SURFACE_SCAN_MESH_STORAGE);
    els.push(DataElement::new(tags::NUMBER_OF_SURFACES, VR::UL, PrimitiveValue::from(1u32)));
    els.push(seq(tags::SURFACE_SEQUENCE, vec![surface]));
    Ok(InMemDicomObject::from_element_iter(els))
}

/// The Surface Scan Point Cloud instance of `mesh`'s points (metres in `table`) with their
/// colours where it has them.
pub fn point_cloud(mesh: &Mesh, inst: &Instance) -> Result<InMemDicomObject, String> {
    let n = mesh.positions.len();
    if n == 0 {
        return Err("no points to store".into());
    }
    let mut els = common(inst, uids::SURFACE_SCAN_POINT_CLOUD_STORAGE);
    els.push(seq(tags::SURFACE_POINTS_SEQUENCE, vec![points_item(&mesh.positions)]));
    if mesh.colors.len() == n {
        let lab: Vec<u16> = mesh.colors.iter().flat_map(|c| srgb_to_dicom_lab(c.map(f64::from))).collect();
        els.push(DataElement::new(
            tags::SURFACE_POINT_COLOR_CIE_LAB_VALUE_DATA,
            VR::US,
            PrimitiveValue::U16(C::from_vec(lab)),
        ));
    }
    Ok(InMemDicomObject::from_element_iter(els))
}

/// The bytes of `obj` as a DICOM file (PS3.10) in `transfer_syntax`.
fn file_bytes(obj: InMemDicomObject, transfer_syntax: &str) -> Result<Vec<u8>, String> {
    let class = text(&obj, tags::SOP_CLASS_UID);
    let instance = text(&obj, tags::SOP_INSTANCE_UID);
    crate::dicom::file_bytes(obj, transfer_syntax, &class, &instance)
}

/// The file (PS3.10) of the Surface Scan Mesh instance of `mesh`, as [`write_surface_mesh`]
/// writes it.
pub fn surface_mesh_bytes(mesh: &Mesh, inst: &Instance) -> Result<Vec<u8>, String> {
    file_bytes(surface_mesh(mesh, inst)?, EXPLICIT_VR_LE)
}

/// Writes the Surface Scan Mesh instance of `mesh` to `path` (atomically).
pub fn write_surface_mesh(path: &Path, mesh: &Mesh, inst: &Instance) -> Result<(), DicomError> {
    let err = |what: String| DicomError { file: path.to_path_buf(), what };
    let bytes = surface_mesh_bytes(mesh, inst).map_err(err)?;
    crate::write_bytes_atomic(path, &bytes).map_err(|e| err(e.cause.to_string()))
}

/// Writes the Surface Scan Point Cloud instance of `mesh`'s points to `path` (atomically).
pub fn write_point_cloud(path: &Path, mesh: &Mesh, inst: &Instance) -> Result<(), DicomError> {
    let err = |what: String| DicomError { file: path.to_path_buf(), what };
    let bytes = file_bytes(point_cloud(mesh, inst).map_err(err)?, IMPLICIT_VR_LE).map_err(err)?;
    crate::write_bytes_atomic(path, &bytes).map_err(|e| err(e.cause.to_string()))
}

/// Writes the radiograph `src` (as [`read_study`] read it) to `dst` (atomically) in the scan's
/// Frame of Reference: the same patient, study and series, a new SOP Instance UID made from the
/// original's and the frame's (the original is another instance: the same pixels without a
/// frame), Frame of Reference UID `frame_of_reference_uid` and Position Reference Indicator,
/// the rest as it was.
pub fn write_xray_in_frame(src: XrayFileData, dst: &Path, frame_of_reference_uid: &str) -> Result<String, DicomError> {
    let err = |what: String| DicomError { file: dst.to_path_buf(), what };
    check_uid(frame_of_reference_uid)
        .map_err(|why| err(format!("Frame of Reference UID {frame_of_reference_uid:?}: {why}")))?;
    let mut obj = src.0;
    let original = text(&obj, tags::SOP_INSTANCE_UID);
    let instance = uid(&format!("{original}/in frame {frame_of_reference_uid}"));
    obj.put(el_str(tags::SOP_INSTANCE_UID, VR::UI, &instance));
    obj.put(el_str(tags::FRAME_OF_REFERENCE_UID, VR::UI, frame_of_reference_uid));
    if obj.element_opt(tags::POSITION_REFERENCE_INDICATOR).ok().flatten().is_none() {
        obj.put(empty(tags::POSITION_REFERENCE_INDICATOR, VR::LO));
    }
    let ts = obj.meta().transfer_syntax().trim_end_matches(['\0', ' ']).to_string();
    let bytes = file_bytes(obj.into_inner(), &ts).map_err(err)?;
    crate::write_bytes_atomic(dst, &bytes).map_err(|e| err(e.cause.to_string()))?;
    Ok(instance)
}

/// What is wrong with `obj` as an instance of the modules in `modules`: a missing attribute,
/// an empty type 1 attribute, a malformed UID. Empty when nothing is.
pub fn check_modules(obj: &InMemDicomObject, modules: &[(&str, Tag, &str)]) -> Vec<String> {
    let mut wrong = Vec::new();
    for &(module, tag, kind) in modules {
        match obj.element_opt(tag).ok().flatten() {
            None => wrong.push(format!("{module}: {} (type {kind}) is missing", name_of(tag))),
            Some(e) if kind == "1" && e.value().multiplicity() == 0 && e.items().is_none_or(|i| i.is_empty()) => {
                wrong.push(format!("{module}: {} (type 1) is empty", name_of(tag)))
            }
            Some(e) if e.vr() == VR::UI => {
                let v = e.to_str().map(|s| s.trim_end_matches(['\0', ' ']).to_string()).unwrap_or_default();
                if let Err(why) = check_uid(&v) {
                    wrong.push(format!("{module}: {} {v:?}: {why}", name_of(tag)));
                }
            }
            Some(_) => {}
        }
    }
    wrong
}

/// What is wrong with a Surface Scan Mesh instance: [`MODULES`], the Surface Mesh module
/// ([`SURFACE_MESH_MODULE`]) in its item, and the points and triangles consistent (the counts
/// agree, every index names a point, 1-based).
pub fn check_instance(obj: &InMemDicomObject) -> Vec<String> {
    let mut wrong = check_modules(obj, MODULES);
    let top: Vec<_> = SURFACE_MESH_MODULE.iter().copied().filter(|m| m.0 == "Surface Mesh").collect();
    wrong.extend(check_modules(obj, &top));
    let item = obj.element_opt(tags::SURFACE_SEQUENCE).ok().flatten().and_then(|e| e.items()).and_then(|i| i.first());
    let Some(item) = item else {
        wrong.push("Surface Mesh: the Surface Sequence has no item".into());
        return wrong;
    };
    let inner: Vec<_> = SURFACE_MESH_MODULE.iter().copied().filter(|m| m.0 != "Surface Mesh").collect();
    wrong.extend(check_modules(item, &inner));
    let first = |o: &InMemDicomObject, tag| {
        o.element_opt(tag).ok().flatten().and_then(|e| e.items()).and_then(|i| i.first()).cloned()
    };
    let (Some(points), Some(prims)) =
        (first(item, tags::SURFACE_POINTS_SEQUENCE), first(item, tags::SURFACE_MESH_PRIMITIVES_SEQUENCE))
    else {
        wrong.push("Surface Mesh: no points or no primitives item".into());
        return wrong;
    };
    let n = points.element(tags::NUMBER_OF_SURFACE_POINTS).ok().and_then(|e| e.to_int::<u32>().ok()).unwrap_or(0);
    let coords =
        points.element(tags::POINT_COORDINATES_DATA).ok().and_then(|e| e.to_multi_float32().ok()).unwrap_or_default();
    if coords.len() != 3 * n as usize {
        wrong.push(format!("Points: {} coordinates for {n} points", coords.len()));
    }
    let tri: Vec<u32> = prims
        .element(tags::LONG_TRIANGLE_POINT_INDEX_LIST)
        .ok()
        .and_then(|e| {
            e.value().primitive().map(|p| match p {
                PrimitiveValue::U32(v) => v.to_vec(),
                _ => Vec::new(),
            })
        })
        .unwrap_or_default();
    if tri.is_empty() || !tri.len().is_multiple_of(3) {
        wrong.push(format!("Surface Mesh Primitives: {} triangle indices", tri.len()));
    }
    if let Some(i) = tri.iter().find(|&&i| i == 0 || i > n) {
        wrong.push(format!("Surface Mesh Primitives: index {i} outside 1..={n}"));
    }
    wrong
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("xsurf-dcmsurf-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn mesh() -> Mesh {
        let positions = vec![[0.0, 0.0, 0.1], [0.01, 0.0, 0.1], [0.0, 0.01, 0.11], [0.01, 0.01, 0.12]];
        Mesh {
            normals: Vec::new(),
            colors: vec![[255, 0, 0], [255, 0, 0], [255, 0, 0], [255, 0, 0]],
            triangles: vec![[0, 1, 2], [1, 3, 2]],
            positions,
        }
    }

    fn equipment() -> Equipment {
        Equipment {
            manufacturer: "xsurf".into(),
            model_name: "test".into(),
            device_serial_number: "0".into(),
            software_versions: "0.1".into(),
            station_name: String::new(),
            institution_name: String::new(),
        }
    }

    fn instance<'a>(study: &'a Study, e: &'a Equipment) -> Instance<'a> {
        Instance {
            study,
            equipment: e,
            series_instance_uid: uid_for("s"),
            series_number: 3,
            series_description: "surface".into(),
            sop_instance_uid: uid_for("i"),
            frame_of_reference_uid: uid_for("f"),
            acquisition_start_ns: 1_700_000_000_000_000_000,
            acquisition_duration_s: 9.5,
            acquisition_number: 3,
            opacity: 0.7,
        }
    }

    #[test]
    fn lab_of_known_colours() {
        // White is L* 100, a* = b* = 0; sRGB red under D50 is L* 54.29, a* 80.80, b* 69.89
        // (Lindbloom's calculator, Bradford adaptation).
        let dec = |v: [u16; 3]| {
            [
                f64::from(v[0]) * 100.0 / 65535.0,
                f64::from(v[1]) * 255.0 / 65535.0 - 128.0,
                f64::from(v[2]) * 255.0 / 65535.0 - 128.0,
            ]
        };
        let w = dec(srgb_to_dicom_lab([255.0; 3]));
        assert!((w[0] - 100.0).abs() < 0.01 && w[1].abs() < 0.02 && w[2].abs() < 0.02, "{w:?}");
        let r = dec(srgb_to_dicom_lab([255.0, 0.0, 0.0]));
        assert!((r[0] - 54.29).abs() < 0.05 && (r[1] - 80.80).abs() < 0.1 && (r[2] - 69.89).abs() < 0.1, "{r:?}");
        assert_eq!(srgb_to_dicom_lab([0.0; 3])[0], 0);
    }

    #[test]
    fn a_mesh_instance_has_every_module_and_reads_back() {
        let d = dir("mesh");
        let study = Study { study_instance_uid: uid_for("study"), patient_id: "P1".into(), ..Study::default() };
        let e = equipment();
        let inst = instance(&study, &e);
        let m = mesh();
        let obj = surface_mesh(&m, &inst).unwrap();
        assert_eq!(check_instance(&obj), Vec::<String>::new());
        let p = d.join("surface.dcm");
        write_surface_mesh(&p, &m, &inst).unwrap();
        let back = dicom_object::open_file(&p).unwrap();
        assert_eq!(check_instance(&back), Vec::<String>::new());
        let item = back.element(tags::SURFACE_SEQUENCE).unwrap().items().unwrap()[0].clone();
        let pts = item.element(tags::SURFACE_POINTS_SEQUENCE).unwrap().items().unwrap()[0].clone();
        let c = pts.element(tags::POINT_COORDINATES_DATA).unwrap().to_multi_float32().unwrap();
        assert_eq!(c.len(), 12);
        assert_eq!(&c[6..9], &[0.0, 10.0, 110.0]);
        // A broken instance is caught: a missing module attribute, an index beyond the points.
        let mut bad = obj.clone();
        bad.remove_element(tags::FRAME_OF_REFERENCE_UID);
        assert!(check_instance(&bad).iter().any(|w| w.contains("FrameOfReferenceUID")), "{:?}", check_instance(&bad));
        let mut m2 = m.clone();
        m2.triangles.push([0, 1, 9]);
        assert!(surface_mesh(&m2, &inst).unwrap_err().contains("beyond the 4 points"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn uids_are_checked() {
        assert!(check_uid("1.2.840.10008.1.2").is_ok());
        assert!(check_uid(&uid_for("anything")).is_ok());
        assert!(check_uid("1.02.3").unwrap_err().contains("leading zero"));
        assert!(check_uid("1..3").unwrap_err().contains("empty"));
        assert!(check_uid("1.2.a").unwrap_err().contains("not digits"));
        assert!(check_uid(&"1.".repeat(40)).is_err());
        assert!(check_uid("").is_err());
    }
}
