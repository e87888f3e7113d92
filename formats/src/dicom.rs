//! DICOM radiographs in and out, through the dicom-rs crates.
//!
//! Reading accepts 8- to 16-bit greyscale (the scanner's 14-bit images), MONOCHROME1 and
//! MONOCHROME2, signed or unsigned, with Rescale Slope/Intercept, Window Center/Width and the
//! VOI LUT Sequence kept for display, in the uncompressed transfer syntaxes and the compressed
//! ones the pure-Rust codecs decode (JPEG baseline, extended and lossless, RLE, deflate). Every
//! other case is an error naming the file and the element. Multi-frame files give their first
//! frame.
//!
//! Writing produces a Digital X-Ray Image (for presentation) in Explicit VR Little Endian,
//! with the acquisition geometry and timing that [`XrayInfo`] holds.

use dicom_core::value::{DataSetSequence, PrimitiveValue, C};
use dicom_core::{DataElement, Tag, VR};
use dicom_dictionary_std::tags;
use dicom_encoding::TransferSyntaxIndex;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject, OpenFileOptions};
use dicom_pixeldata::PixelDecoder;
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use std::path::{Path, PathBuf};
use xsurf_core::xray::{Radiograph, VoiLut, Window};

/// A DICOM file that cannot be read or written, with the file and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{}: {what}", file.display())]
pub struct DicomError {
    /// The file.
    pub file: PathBuf,
    /// What is wrong (naming the element where one is at fault).
    pub what: String,
}

/// Acquisition facts from the file (all optional in DICOM).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct XrayInfo {
    /// Acquisition DateTime (0008,002A) as ns since the Unix epoch (UTC unless the value
    /// carries an offset).
    pub acquisition_start_ns: Option<i64>,
    /// Exposure Time (0018,1150), ms.
    pub exposure_ms: Option<f64>,
    /// Distance Source to Detector (0018,1110), metres.
    pub source_detector_m: Option<f64>,
    /// Imager Pixel Spacing (0018,1164), metres: `[row spacing, column spacing]`.
    pub pixel_spacing_m: Option<[f64; 2]>,
}

/// A radiograph read from a file.
#[derive(Debug, Clone)]
pub struct XrayFile {
    /// The pixels and display attributes.
    pub image: Radiograph,
    /// Acquisition facts.
    pub info: XrayInfo,
    /// Transfer syntax UID.
    pub transfer_syntax: String,
}

pub(crate) fn name_of(tag: Tag) -> String {
    use dicom_core::dictionary::DataDictionary;
    let name = dicom_dictionary_std::StandardDataDictionary
        .by_tag(tag)
        .map(|e| e.alias.to_string())
        .unwrap_or_else(|| "element".to_string());
    format!("{name} ({:04X},{:04X})", tag.0, tag.1)
}

/// A data set's encoding, from its transfer syntax.
#[derive(Clone, Copy, PartialEq)]
enum Syntax {
    ExplicitLe,
    ImplicitLe,
    ExplicitBe,
}

impl Syntax {
    /// The encoding of transfer syntax `uid`; `None` for a deflated data set (whose lengths are
    /// those of the inflated stream).
    fn of(uid: &str) -> Option<Syntax> {
        match uid.trim_end_matches(['\0', ' ']) {
            "1.2.840.10008.1.2" => Some(Syntax::ImplicitLe),
            "1.2.840.10008.1.2.2" => Some(Syntax::ExplicitBe),
            "1.2.840.10008.1.2.1.99" => None,
            _ => Some(Syntax::ExplicitLe),
        }
    }
}

fn u16_at(b: &[u8], i: usize, be: bool) -> u16 {
    let v = [b[i], b[i + 1]];
    if be {
        u16::from_be_bytes(v)
    } else {
        u16::from_le_bytes(v)
    }
}

fn u32_at(b: &[u8], i: usize, be: bool) -> u32 {
    let v = [b[i], b[i + 1], b[i + 2], b[i + 3]];
    if be {
        u32::from_be_bytes(v)
    } else {
        u32::from_le_bytes(v)
    }
}

/// The VR, value length and header size of the element at `pos` (at least 8 bytes there);
/// implicit VRs come from the dictionary, an unknown VR code is read as UN with a 4-byte length
/// (as dicom-rs reads it).
fn element_header(
    b: &[u8],
    pos: usize,
    (group, elem): (u16, u16),
    implicit: bool,
    be: bool,
) -> Result<(VR, u32, usize), String> {
    use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry};
    const LONG_VRS: [VR; 13] =
        [VR::OB, VR::OD, VR::OF, VR::OL, VR::OV, VR::OW, VR::SQ, VR::SV, VR::UC, VR::UN, VR::UR, VR::UT, VR::UV];
    if implicit {
        let vr = dicom_dictionary_std::StandardDataDictionary
            .by_tag(Tag(group, elem))
            .map(|e| e.vr().relaxed())
            .unwrap_or(VR::UN);
        return Ok((vr, u32_at(b, pos + 4, false), 8));
    }
    let vr = VR::from_binary([b[pos + 4], b[pos + 5]]).unwrap_or(VR::UN);
    if !LONG_VRS.contains(&vr) {
        return Ok((vr, u32::from(u16_at(b, pos + 6, be)), 8));
    }
    if b.len() - pos < 12 {
        return Err(format!("the element header at byte offset {pos} is cut short by the end of the file"));
    }
    Ok((vr, u32_at(b, pos + 8, be), 12))
}

/// Checks that every element and item of a DICOM file (PS3.10: preamble, "DICM", meta group,
/// data set) that has a defined length fits in the file, before a parser allocates that length
/// (found by the fuzz suite: a 1 KB file whose element said 4 GB made dicom-rs fill 4 GB).
/// Sequences, items and undefined lengths are walked into; encapsulated pixel data's fragments
/// are stepped over by their lengths. A deflated data set is checked only as far as its meta
/// group.
fn check_lengths(b: &[u8]) -> Result<(), String> {
    let mut pos = 132;
    let mut syntax = Syntax::ExplicitLe;
    let mut in_meta = true;
    // Inside encapsulated pixel data, items are fragments of bytes, not data sets.
    let mut fragments = false;
    let mut transfer_syntax = String::new();
    while pos < b.len() {
        if in_meta && (b.len() - pos < 2 || u16_at(b, pos, false) != 0x0002) {
            in_meta = false;
            let Some(s) = Syntax::of(&transfer_syntax) else { return Ok(()) };
            syntax = s;
        }
        let be = syntax == Syntax::ExplicitBe && !in_meta;
        if b.len() - pos < 8 {
            return Err(format!("the element header at byte offset {pos} is cut short by the end of the file"));
        }
        let (group, elem) = (u16_at(b, pos, be), u16_at(b, pos + 2, be));
        let remaining = |header: usize| (b.len() - pos).saturating_sub(header);
        if group == 0xFFFE {
            // Item (E000), item delimiter (E00D), sequence delimiter (E0DD): tag and a 4-byte length.
            let len = u32_at(b, pos + 4, be);
            match elem {
                0xE0DD => fragments = false,
                0xE000 if len != u32::MAX => {
                    if len as usize > remaining(8) {
                        return Err(format!(
                            "the item at byte offset {pos} says {len} bytes, the file has {} after it",
                            remaining(8)
                        ));
                    }
                    if fragments {
                        pos += len as usize;
                    }
                }
                _ => {}
            }
            pos += 8;
            continue;
        }
        let implicit = syntax == Syntax::ImplicitLe && !in_meta;
        let (vr, len, header) = element_header(b, pos, (group, elem), implicit, be)?;
        if len == u32::MAX {
            // Undefined length: a sequence, or encapsulated pixel data; walk into it.
            fragments = vr != VR::SQ;
            pos += header;
            continue;
        }
        let tag = Tag(group, elem);
        if len as usize > remaining(header) {
            return Err(format!(
                "{} at byte offset {pos} says {len} bytes, the file has {} after its header",
                name_of(tag),
                remaining(header)
            ));
        }
        if in_meta && tag == tags::TRANSFER_SYNTAX_UID {
            transfer_syntax = String::from_utf8_lossy(&b[pos + header..pos + header + len as usize]).into_owned();
        }
        // A sequence of defined length is walked into; any other value is stepped over.
        pos += header + if vr == VR::SQ { 0 } else { len as usize };
    }
    Ok(())
}

/// The 128-byte preamble and "DICM" of a DICOM file (PS3.10 7.1); what the file is instead,
/// if it is a common image format.
fn check_preamble(path: &Path) -> Result<(), String> {
    // A DICOM file (PS3.10) is a 128-byte preamble and "DICM" before its meta group.
    let mut head = Vec::with_capacity(132);
    std::fs::File::open(path)
        .and_then(|f| std::io::Read::read_to_end(&mut std::io::Read::take(f, 132), &mut head))
        .map_err(|e| e.to_string())?;
    let n = head.len();
    if n < 132 || &head[128..132] != b"DICM" {
        let kind = match &head[..n.min(8)] {
            [0x89, b'P', b'N', b'G', ..] => " (it is a PNG image)",
            [0xFF, 0xD8, 0xFF, ..] => " (it is a JPEG image)",
            [b'I', b'I', 42, 0, ..] | [b'M', b'M', 0, 42, ..] => " (it is a TIFF image)",
            _ => "",
        };
        let end = if n < 132 { format!(" (the file ends at byte {n})") } else { String::new() };
        return Err(format!(
            "not a DICOM file{kind}: the \"DICM\" prefix at byte offset 128 (PS3.10 7.1) is missing{end}"
        ));
    }
    Ok(())
}

/// The pixels of `data` as u16, keeping only the stored bits (sign-extended for signed data,
/// then offset by 32768 into u16; the caller moves the offset into the rescale intercept).
fn stored_pixels(
    data: &[u8],
    (rows, cols): (u32, u32),
    bits_allocated: u32,
    bits_stored: u32,
    signed: bool,
) -> Result<Vec<u16>, String> {
    let n = rows as usize * cols as usize;
    let mut pixels: Vec<u16> = if bits_allocated == 16 {
        if data.len() < 2 * n {
            return Err(format!(
                "{} holds {} bytes, {rows}x{cols} 16-bit pixels need {}",
                name_of(tags::PIXEL_DATA),
                data.len(),
                2 * n
            ));
        }
        data[..2 * n].chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect()
    } else {
        if data.len() < n {
            return Err(format!(
                "{} holds {} bytes, {rows}x{cols} 8-bit pixels need {n}",
                name_of(tags::PIXEL_DATA),
                data.len()
            ));
        }
        data[..n].iter().map(|&b| u16::from(b)).collect()
    };
    // Keep only the stored bits (sign-extended for signed data), then offset signed values into
    // u16 and move the offset into the rescale intercept.
    let shift = 16 - bits_stored.min(16);
    for p in &mut pixels {
        *p = if signed {
            let v = ((*p << shift) as i16) >> shift;
            (i32::from(v) + 32768) as u16
        } else {
            (*p << shift) >> shift
        };
    }
    Ok(pixels)
}

/// Element `tag` of `obj`, or what is wrong with it.
fn element(obj: &InMemDicomObject, tag: Tag) -> Result<&dicom_object::mem::InMemElement, String> {
    obj.element_opt(tag)
        .map_err(|e| format!("{}: {e}", name_of(tag)))?
        .ok_or_else(|| format!("{} is missing", name_of(tag)))
}

/// Element `tag` of `obj` as an unsigned integer.
fn uint(obj: &InMemDicomObject, tag: Tag) -> Result<u32, String> {
    element(obj, tag)?.to_int::<u32>().map_err(|e| format!("{}: {e}", name_of(tag)))
}

/// The pixel layout a radiograph is read in.
struct PixelFormat {
    rows: u32,
    cols: u32,
    bits_allocated: u32,
    bits_stored: u32,
    monochrome1: bool,
}

/// The pixel layout of `obj`, checked: one sample per pixel, 8- or 16-bit, MONOCHROME1 or 2,
/// and a decoded size bounded before decoding allocates it (a damaged Rows, Columns or Number
/// of Frames must not cost gigabytes): at most 1 GiB, and for compressed pixel data (`encapsulated`) at most
/// 256 times the file's size of `file_len` bytes (or 64 MiB).
fn pixel_format(obj: &InMemDicomObject, encapsulated: bool, file_len: usize) -> Result<PixelFormat, String> {
    element(obj, tags::PIXEL_DATA)?;
    let (rows, cols) = (uint(obj, tags::ROWS)?, uint(obj, tags::COLUMNS)?);
    let spp = uint(obj, tags::SAMPLES_PER_PIXEL)?;
    if spp != 1 {
        return Err(format!(
            "{} is {spp}: a radiograph must be greyscale (1 sample per pixel)",
            name_of(tags::SAMPLES_PER_PIXEL)
        ));
    }
    let bits_allocated = uint(obj, tags::BITS_ALLOCATED)?;
    let bits_stored = uint(obj, tags::BITS_STORED)?;
    let frames = obj
        .element_opt(tags::NUMBER_OF_FRAMES)
        .ok()
        .flatten()
        .map(|e| e.to_int::<u32>().map_err(|e| format!("{}: {e}", name_of(tags::NUMBER_OF_FRAMES))))
        .transpose()?
        .unwrap_or(1);
    let decoded = u64::from(rows) * u64::from(cols) * u64::from(frames.max(1)) * u64::from(bits_allocated.div_ceil(8));
    let limit = if encapsulated { (file_len as u64).saturating_mul(256).clamp(64 << 20, 1 << 30) } else { 1 << 30 };
    if decoded > limit {
        return Err(format!(
            "{rows}x{cols} pixels ({}, {}) in {frames} frame(s) would decode to {decoded} bytes, more than the {limit} a file of {file_len} bytes may hold",
            name_of(tags::ROWS),
            name_of(tags::COLUMNS),
        ));
    }
    if !matches!(bits_allocated, 8 | 16) || !(1..=bits_allocated).contains(&bits_stored) {
        return Err(format!(
            "{} {bits_allocated} with {} {bits_stored}: only 8- to 16-bit greyscale is supported",
            name_of(tags::BITS_ALLOCATED),
            name_of(tags::BITS_STORED)
        ));
    }
    let photometric = element(obj, tags::PHOTOMETRIC_INTERPRETATION)?
        .to_str()
        .map_err(|e| format!("{}: {e}", name_of(tags::PHOTOMETRIC_INTERPRETATION)))?
        .trim()
        .to_string();
    let monochrome1 = match photometric.as_str() {
        "MONOCHROME1" => true,
        "MONOCHROME2" => false,
        other => {
            return Err(format!(
                "{} is {other}: a radiograph must be MONOCHROME1 or MONOCHROME2",
                name_of(tags::PHOTOMETRIC_INTERPRETATION)
            ))
        }
    };
    Ok(PixelFormat { rows, cols, bits_allocated, bits_stored, monochrome1 })
}

/// The radiograph from the decoded pixel data: the stored bits, the rescale (with signed
/// pixels' offset moved into its intercept), the first window and the first VOI LUT.
fn radiograph(px: &dicom_pixeldata::DecodedPixelData<'_>, f: &PixelFormat) -> Result<Radiograph, String> {
    let signed = matches!(px.pixel_representation(), dicom_pixeldata::PixelRepresentation::Signed);
    let intercept_offset = if signed { -32768.0 } else { 0.0 };
    let pixels = stored_pixels(px.data(), (f.rows, f.cols), f.bits_allocated, f.bits_stored, signed)?;
    let rescale = px.rescale().ok().and_then(|r| r.first().copied());
    let (slope, intercept) = rescale.map_or((1.0, 0.0), |r| (r.slope, r.intercept));
    let window = px
        .window()
        .ok()
        .flatten()
        .and_then(|w| w.first().copied())
        .filter(|w| w.width >= 1.0 && w.center.is_finite())
        .map(|w| Window { center: w.center, width: w.width });
    let voi_lut = px.voi_lut_sequence().ok().flatten().and_then(|l| l.first().cloned()).map(|l| VoiLut {
        // The LUT's first value is in rescaled units, which the display maps with the same
        // rescale; the signed offset lives in the intercept so needs no change here.
        first: l.min_pixel_value,
        bits: l.bits_stored,
        data: l.data,
    });
    let image = Radiograph {
        width: f.cols,
        height: f.rows,
        pixels,
        bits_stored: if signed { 16 } else { f.bits_stored as u8 },
        monochrome1: f.monochrome1,
        rescale_slope: slope,
        rescale_intercept: intercept + slope * intercept_offset,
        window,
        voi_lut,
    };
    image.validate().map_err(|e| e.to_string())?;
    Ok(image)
}

/// The acquisition facts of `obj`, those it has.
fn xray_info(obj: &InMemDicomObject) -> XrayInfo {
    let opt_f64s = |tag: Tag| -> Option<Vec<f64>> {
        obj.element_opt(tag).ok().flatten().and_then(|e| e.to_multi_float64().ok()).filter(|v| !v.is_empty())
    };
    XrayInfo {
        acquisition_start_ns: obj
            .element_opt(tags::ACQUISITION_DATE_TIME)
            .ok()
            .flatten()
            .and_then(|e| e.to_str().ok())
            .and_then(|s| parse_datetime_ns(&s)),
        exposure_ms: opt_f64s(tags::EXPOSURE_TIME).map(|v| v[0]),
        source_detector_m: opt_f64s(tags::DISTANCE_SOURCE_TO_DETECTOR).map(|v| v[0] * 1e-3),
        pixel_spacing_m: opt_f64s(tags::IMAGER_PIXEL_SPACING)
            .filter(|v| v.len() == 2)
            .map(|v| [v[0] * 1e-3, v[1] * 1e-3]),
    }
}

/// Opens the DICOM file `path` after checking that it is one and that every length in it fits
/// in the file; the error names the file and what is wrong.
pub(crate) fn open_checked(path: &Path) -> Result<dicom_object::DefaultDicomObject, DicomError> {
    Ok(open_bytes(path)?.0)
}

fn open_bytes(path: &Path) -> Result<(dicom_object::DefaultDicomObject, usize), DicomError> {
    let err = |what: String| DicomError { file: path.to_path_buf(), what };
    if let Some(why) = crate::file_problem(path) {
        return Err(err(why));
    }
    check_preamble(path).map_err(err)?;
    let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
    check_lengths(&bytes).map_err(|e| err(format!("not a readable DICOM file: {e}")))?;
    let obj = OpenFileOptions::new().open_file(path).map_err(|e| err(format!("not a readable DICOM file: {e}")))?;
    Ok((obj, bytes.len()))
}

/// Checks a UID (PS3.5 9.1): at most 64 characters, components of digits separated by single
/// dots, none with a leading zero (but "0" itself); the error says what is wrong.
pub fn check_uid(s: &str) -> Result<(), String> {
    if s.is_empty() {
        return Err("empty".into());
    }
    if s.len() > 64 {
        return Err(format!("{} characters, at most 64", s.len()));
    }
    for c in s.split('.') {
        if c.is_empty() {
            return Err("an empty component".into());
        }
        if !c.bytes().all(|b| b.is_ascii_digit()) {
            return Err(format!("component {c:?} is not digits"));
        }
        if c.len() > 1 && c.starts_with('0') {
            return Err(format!("component {c:?} has a leading zero"));
        }
    }
    Ok(())
}

/// Reads the radiograph in `path`.
pub fn read_file(path: &Path) -> Result<XrayFile, DicomError> {
    let err = |what: String| DicomError { file: path.to_path_buf(), what };
    let (obj, len) = open_bytes(path)?;
    let ts_uid = obj.meta().transfer_syntax().trim_end_matches(['\0', ' ']).to_string();
    let ts = TransferSyntaxRegistry
        .get(&ts_uid)
        .ok_or_else(|| err(format!("TransferSyntaxUID (0002,0010) {ts_uid} is unknown")))?;
    let format = pixel_format(&obj, ts.is_encapsulated_pixel_data(), len).map_err(err)?;
    if ts.is_encapsulated_pixel_data() && !ts.can_decode_all() {
        return Err(err(format!(
            "{}: transfer syntax {ts_uid} ({}) is not supported (supported: uncompressed, deflate, RLE, JPEG baseline/extended/lossless)",
            name_of(tags::PIXEL_DATA),
            ts.name()
        )));
    }
    let px = obj.decode_pixel_data().map_err(|e| err(format!("{}: {e}", name_of(tags::PIXEL_DATA))))?;
    let image = radiograph(&px, &format).map_err(err)?;
    Ok(XrayFile { image, info: xray_info(&obj), transfer_syntax: ts_uid })
}

/// Parses a DICOM DT value (`YYYYMMDDHHMMSS.FFFFFF&ZZXX`, trailing parts optional) to ns since
/// the Unix epoch.
pub fn parse_datetime_ns(s: &str) -> Option<i64> {
    let s = s.trim();
    let (body, offset_s) = match s.find(['+', '-']) {
        Some(i) if i >= 4 => {
            let (b, o) = s.split_at(i);
            let sign = if o.starts_with('-') { -1 } else { 1 };
            let hh: i64 = o.get(1..3)?.parse().ok()?;
            let mm: i64 = o.get(3..5)?.parse().ok()?;
            (b, sign * (hh * 3600 + mm * 60))
        }
        _ => (s, 0),
    };
    let (whole, frac) = body.split_once('.').unwrap_or((body, ""));
    if whole.len() < 8 || !whole.bytes().all(|b| b.is_ascii_digit()) || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let num = |a: usize, b: usize, default: i64| -> Option<i64> {
        match whole.get(a..b) {
            Some(x) if !x.is_empty() => x.parse().ok(),
            _ => Some(default),
        }
    };
    let (y, mo, d) = (num(0, 4, 1970)?, num(4, 6, 1)?, num(6, 8, 1)?);
    let (h, mi, sec) = (num(8, 10, 0)?, num(10, 12, 0)?, num(12, 14, 0)?);
    let ns_frac: i64 = if frac.is_empty() {
        0
    } else {
        let digits = &frac[..frac.len().min(9)];
        digits.parse::<i64>().ok()? * 10i64.pow(9 - digits.len() as u32)
    };
    let days = days_from_civil(y, mo, d);
    Some(((days * 86400 + h * 3600 + mi * 60 + sec) - offset_s) * 1_000_000_000 + ns_frac)
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = if y >= 0 { y } else { y - 399 } / 400;
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146097 + doe - 719468
}

/// The DT value (UTC, microseconds) of ns since the Unix epoch.
pub fn format_datetime(ns: i64) -> String {
    let secs = ns.div_euclid(1_000_000_000);
    let micros = ns.rem_euclid(1_000_000_000) / 1000;
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // civil_from_days (Hinnant).
    let z = days + 719468;
    let era = if z >= 0 { z } else { z - 146096 } / 146097;
    let doe = z - era * 146097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}{m:02}{d:02}{:02}{:02}{:02}.{micros:06}+0000", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// A UID under the `2.25` root (ISO/IEC 9834-8: a 128-bit number in decimal) derived from `key`.
pub(crate) fn uid(key: &str) -> String {
    // Two FNV-1a 64-bit hashes with different bases make the 128 bits.
    let fnv = |basis: u64| key.bytes().fold(basis, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3));
    let v = (u128::from(fnv(0xcbf2_9ce4_8422_2325)) << 64) | u128::from(fnv(0x6c62_272e_07bb_0142));
    format!("2.25.{v}")
}

/// Digital X-Ray Image Storage - For Presentation.
const DX_FOR_PRESENTATION: &str = "1.2.840.10008.5.1.4.1.1.1.1";
/// Explicit VR Little Endian.
const EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1";

/// The attributes a Digital X-Ray image needs beyond the pixels and the rescale (types 1 and 2
/// of its Patient, General Study, General Series, General Image, DX Anatomy Imaged, DX Image,
/// DX Detector and Acquisition Context modules; dciodvfy checks them).
fn dx_attributes(monochrome1: bool) -> Vec<DataElement<InMemDicomObject>> {
    let s = |tag, vr, v: &str| DataElement::new(tag, vr, PrimitiveValue::from(v));
    vec![
        DataElement::new(tags::PATIENT_BIRTH_DATE, VR::DA, PrimitiveValue::Empty),
        DataElement::new(tags::PATIENT_SEX, VR::CS, PrimitiveValue::Empty),
        DataElement::new(tags::REFERRING_PHYSICIAN_NAME, VR::PN, PrimitiveValue::Empty),
        s(tags::STUDY_ID, VR::SH, "1"),
        DataElement::new(tags::ACCESSION_NUMBER, VR::SH, PrimitiveValue::Empty),
        s(tags::SERIES_NUMBER, VR::IS, "1"),
        s(tags::INSTANCE_NUMBER, VR::IS, "1"),
        // The whole body, front to back: rows run from the patient's right to left, columns
        // from head to feet; the body is not a paired structure (Image Laterality U).
        s(tags::PATIENT_ORIENTATION, VR::CS, "L\\F"),
        s(tags::IMAGE_LATERALITY, VR::CS, "U"),
        DataElement::new(
            tags::ANATOMIC_REGION_SEQUENCE,
            VR::SQ,
            DataSetSequence::from(vec![InMemDicomObject::from_element_iter([
                s(tags::CODE_VALUE, VR::SH, "38266002"),
                s(tags::CODING_SCHEME_DESIGNATOR, VR::SH, "SCT"),
                s(tags::CODE_MEANING, VR::LO, "Entire body"),
            ])]),
        ),
        s(tags::PRESENTATION_LUT_SHAPE, VR::CS, if monochrome1 { "INVERSE" } else { "IDENTITY" }),
        s(tags::BURNED_IN_ANNOTATION, VR::CS, "NO"),
        s(tags::DETECTOR_TYPE, VR::CS, "SCINTILLATOR"),
        DataElement::new(
            tags::ACQUISITION_CONTEXT_SEQUENCE,
            VR::SQ,
            DataSetSequence::<InMemDicomObject>::from(Vec::new()),
        ),
    ]
}

/// Writes `image` as a DICOM Digital X-Ray file (Explicit VR Little Endian, 16 bits allocated),
/// atomically. `key` makes the UIDs (the same key gives the same UIDs).
pub fn write_file(path: &Path, image: &Radiograph, info: &XrayInfo, key: &str) -> Result<(), DicomError> {
    let err = |what: String| DicomError { file: path.to_path_buf(), what };
    image.validate().map_err(|e| err(e.to_string()))?;
    let s = |tag, vr, v: &str| DataElement::new(tag, vr, PrimitiveValue::from(v));
    let us = |tag, v: u16| DataElement::new(tag, VR::US, PrimitiveValue::from(v));
    let ds = |tag, v: f64| DataElement::new(tag, VR::DS, PrimitiveValue::from(format_ds(v)));
    let sop_instance = uid(&format!("{key}/instance"));
    let date = info.acquisition_start_ns.map(format_datetime).unwrap_or_else(|| "19700101000000.000000+0000".into());
    let mut els = vec![
        s(tags::SOP_CLASS_UID, VR::UI, DX_FOR_PRESENTATION),
        s(tags::SOP_INSTANCE_UID, VR::UI, &sop_instance),
        s(tags::STUDY_DATE, VR::DA, &date[..8]),
        s(tags::CONTENT_DATE, VR::DA, &date[..8]),
        s(tags::STUDY_TIME, VR::TM, &date[8..14]),
        s(tags::CONTENT_TIME, VR::TM, &date[8..14]),
        s(tags::ACQUISITION_DATE_TIME, VR::DT, &date),
        s(tags::MODALITY, VR::CS, "DX"),
        s(tags::MANUFACTURER, VR::LO, "xsurf synthetic scanner"),
        s(tags::PATIENT_NAME, VR::PN, "SYNTHETIC^PHANTOM"),
        s(tags::PATIENT_ID, VR::LO, "XSURF-SYNTH"),
        s(tags::STUDY_INSTANCE_UID, VR::UI, &uid(&format!("{key}/study"))),
        s(tags::SERIES_INSTANCE_UID, VR::UI, &uid(&format!("{key}/series"))),
        s(tags::PRESENTATION_INTENT_TYPE, VR::CS, "FOR PRESENTATION"),
        s(tags::IMAGE_TYPE, VR::CS, "DERIVED\\PRIMARY"),
        s(tags::IMAGE_COMMENTS, VR::LT, "linear scan: rows along the C-arm travel, columns along the detector line"),
        us(tags::SAMPLES_PER_PIXEL, 1),
        s(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, if image.monochrome1 { "MONOCHROME1" } else { "MONOCHROME2" }),
        us(tags::ROWS, u16::try_from(image.height).map_err(|_| err(format!("{} rows exceed 65535", image.height)))?),
        us(
            tags::COLUMNS,
            u16::try_from(image.width).map_err(|_| err(format!("{} columns exceed 65535", image.width)))?,
        ),
        us(tags::BITS_ALLOCATED, 16),
        us(tags::BITS_STORED, u16::from(image.bits_stored)),
        us(tags::HIGH_BIT, u16::from(image.bits_stored.max(1) - 1)),
        us(tags::PIXEL_REPRESENTATION, 0),
        ds(tags::RESCALE_SLOPE, image.rescale_slope),
        ds(tags::RESCALE_INTERCEPT, image.rescale_intercept),
        s(tags::RESCALE_TYPE, VR::LO, "US"),
        s(tags::PIXEL_INTENSITY_RELATIONSHIP, VR::CS, "LIN"),
        DataElement::new(tags::PIXEL_INTENSITY_RELATIONSHIP_SIGN, VR::SS, PrimitiveValue::from(1i16)),
        s(tags::LOSSY_IMAGE_COMPRESSION, VR::CS, "00"),
        DataElement::new(tags::PIXEL_DATA, VR::OW, PrimitiveValue::U16(C::from_vec(image.pixels.clone()))),
    ];
    els.extend(dx_attributes(image.monochrome1));
    if let Some(w) = image.window {
        els.push(ds(tags::WINDOW_CENTER, w.center));
        els.push(ds(tags::WINDOW_WIDTH, w.width));
    }
    if let Some(ms) = info.exposure_ms {
        els.push(s(tags::EXPOSURE_TIME, VR::IS, &format!("{}", ms.round() as i64)));
    }
    if let Some(d) = info.source_detector_m {
        els.push(ds(tags::DISTANCE_SOURCE_TO_DETECTOR, d * 1e3));
    }
    if let Some([r, c]) = info.pixel_spacing_m {
        els.push(s(tags::IMAGER_PIXEL_SPACING, VR::DS, &format!("{}\\{}", format_ds(r * 1e3), format_ds(c * 1e3))));
    }
    let obj = InMemDicomObject::from_element_iter(els);
    let bytes = file_bytes(obj, EXPLICIT_VR_LE, DX_FOR_PRESENTATION, &sop_instance).map_err(err)?;
    crate::write_bytes_atomic(path, &bytes).map_err(|e| err(e.cause.to_string()))
}

/// The bytes of `obj` as a DICOM file (PS3.10: preamble, file meta group, data set) in
/// `transfer_syntax`, its meta naming SOP class `class` and instance `instance`.
pub(crate) fn file_bytes(
    obj: InMemDicomObject,
    transfer_syntax: &str,
    class: &str,
    instance: &str,
) -> Result<Vec<u8>, String> {
    let file = obj
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(transfer_syntax)
                .media_storage_sop_class_uid(class)
                .media_storage_sop_instance_uid(instance),
        )
        .map_err(|e| format!("file meta: {e}"))?;
    let mut bytes = Vec::new();
    file.write_all(&mut bytes).map_err(|e| format!("encoding: {e}"))?;
    Ok(bytes)
}

/// A decimal string of at most 16 characters (the DS limit).
fn format_ds(v: f64) -> String {
    let s = format!("{v}");
    if s.len() <= 16 {
        return s;
    }
    let mut p = 10;
    loop {
        let s = format!("{v:.p$}");
        if s.len() <= 16 || p == 0 {
            return s;
        }
        p -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("xsurf-dicom-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn sample() -> Radiograph {
        let px: Vec<u16> = (0..12 * 7).map(|i| (i * 190 % 16384) as u16).collect();
        let mut r = Radiograph::new(12, 7, px, 14).unwrap();
        r.monochrome1 = true;
        r.window = Some(Window { center: 8000.0, width: 14000.0 });
        r.rescale_intercept = -5.0;
        r
    }

    #[test]
    fn written_file_reads_back() {
        let d = dir("rt");
        let p = d.join("x.dcm");
        let info = XrayInfo {
            acquisition_start_ns: Some(1_700_000_000_123_456_000),
            exposure_ms: Some(2571.0),
            source_detector_m: Some(1.3),
            pixel_spacing_m: Some([0.0005, 0.0005]),
        };
        write_file(&p, &sample(), &info, "test").unwrap();
        let f = read_file(&p).unwrap();
        assert_eq!(f.image, sample());
        assert_eq!(f.info, info);
        assert_eq!(f.transfer_syntax, EXPLICIT_VR_LE);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn bad_files_name_the_file_and_the_element() {
        let d = dir("bad");
        let p = d.join("x.dcm");
        write_file(&p, &sample(), &XrayInfo::default(), "t").unwrap();
        let bytes = std::fs::read(&p).unwrap();
        // Truncated in the pixel data.
        let t = d.join("truncated.dcm");
        std::fs::write(&t, &bytes[..bytes.len() - 50]).unwrap();
        let e = read_file(&t).unwrap_err().to_string();
        assert!(e.contains("truncated.dcm"), "{e}");
        // Not DICOM at all.
        let n = d.join("not.dcm");
        std::fs::write(&n, b"hello").unwrap();
        let e = read_file(&n).unwrap_err().to_string();
        assert!(e.contains("not.dcm") && e.contains("not a DICOM file") && e.contains("ends at byte 5"), "{e}");
        // A PNG given for a radiograph: named as one, with the offset of the missing prefix.
        let png = d.join("x.png");
        std::fs::write(&png, [&[0x89u8, b'P', b'N', b'G', 13, 10, 26, 10][..], &[0u8; 200]].concat()).unwrap();
        let e = read_file(&png).unwrap_err().to_string();
        assert!(e.contains("x.png") && e.contains("PNG image") && e.contains("byte offset 128"), "{e}");
        // The prefix is there but the meta group is not: the reader's own message, named.
        let mut fake = vec![0u8; 128];
        fake.extend_from_slice(b"DICMgarbage");
        std::fs::write(&n, &fake).unwrap();
        let e = read_file(&n).unwrap_err().to_string();
        assert!(e.contains("not.dcm") && e.contains("not a readable DICOM file"), "{e}");
        // Missing file, and a folder.
        let e = read_file(&d.join("missing.dcm")).unwrap_err().to_string();
        assert!(e.contains("missing.dcm") && e.contains("does not exist"), "{e}");
        assert!(read_file(&d).unwrap_err().to_string().contains("is a folder, not a file"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn datetimes_round_trip() {
        for ns in [0, 1_700_000_000_123_456_000, 951_782_400_000_001_000] {
            assert_eq!(parse_datetime_ns(&format_datetime(ns)), Some(ns));
        }
        assert_eq!(parse_datetime_ns("19700101000000"), Some(0));
        assert_eq!(parse_datetime_ns("19700101010000+0100"), Some(0));
        assert_eq!(parse_datetime_ns("1970010100"), Some(0));
        assert_eq!(parse_datetime_ns("20000229"), Some(951_782_400_000_000_000));
        assert_eq!(parse_datetime_ns("garbage"), None);
    }
}
