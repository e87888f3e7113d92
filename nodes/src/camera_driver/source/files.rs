//! An image sequence as a camera (the study's `frame_000.bmp`..., BMP/PNG/PGM/PPM/JPEG), a
//! frame a slot, stamped from the rate or a sidecar file; a looped sequence keeps its decoded
//! frames in memory (up to [`CACHE_BYTES`]).

use super::{model_for, rotate_180, Context, Frame, FrameSource};
use crate::camera_driver::SourceSpec;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use xsurf_core::camera::CameraModel;
use xsurf_core::image::Image;

/// Decoded frames kept in memory when looping a sequence.
const CACHE_BYTES: usize = 1 << 30;

/// The files source.
pub(in crate::camera_driver) struct Files {
    list: Vec<PathBuf>,
    stamps: Option<Vec<i64>>,
    repeat: bool,
    /// The next file.
    next: usize,
    /// Decoded frames kept for the next round of a loop.
    cache: Vec<Option<Arc<Image>>>,
    cache_bytes: usize,
    /// Without `camera_info_url`: the rig's intrinsics at the frames' size.
    rig_model: Option<CameraModel>,
    read_errors: u64,
}

impl Files {
    /// The sequence `list`, stamped by `stamps` if given, looped with `repeat`.
    pub(in crate::camera_driver) fn new(list: Vec<PathBuf>, stamps: Option<Vec<i64>>, repeat: bool) -> Files {
        Files { list, stamps, repeat, next: 0, cache: Vec::new(), cache_bytes: 0, rig_model: None, read_errors: 0 }
    }

    /// File `i`, decoded (or from the cache).
    fn read(&mut self, i: usize) -> Option<Image> {
        if self.cache.len() != self.list.len() {
            self.cache = vec![None; self.list.len()];
            self.cache_bytes = 0;
        }
        if let Some(img) = self.cache[i].as_deref() {
            return Some(img.clone());
        }
        match xsurf_formats::frames::read_frame(&self.list[i]) {
            Ok(img) => {
                if self.repeat && self.cache_bytes + img.data.len() <= CACHE_BYTES {
                    self.cache_bytes += img.data.len();
                    self.cache[i] = Some(Arc::new(img.clone()));
                }
                Some(img)
            }
            Err(e) => {
                self.read_errors += 1;
                log::error!("camera_driver: {e}");
                None
            }
        }
    }
}

impl FrameSource for Files {
    /// The next file of the sequence, for the frame slot `slot_ns` (its stamp, unless the
    /// timestamps file gives one).
    fn frames(&mut self, _now_ns: i64, slot_ns: i64, ctx: &Context) -> Vec<Frame> {
        let mut i = self.next;
        if i >= self.list.len() {
            if !self.repeat {
                return Vec::new();
            }
            i = 0;
        }
        self.next = i + 1;
        let stamp_ns = match &self.stamps {
            Some(s) => s[i],
            None => slot_ns,
        };
        let Some(mut image) = self.read(i) else { return Vec::new() };
        if ctx.cfg.rotate_180 {
            rotate_180(&mut image);
        }
        let Some(model) = model_for(ctx.cfg, ctx.camera, &mut self.rig_model, image.width, image.height) else {
            return Vec::new();
        };
        if (model.width, model.height) != (image.width, image.height) {
            self.read_errors += 1;
            log::error!(
                "camera_driver: {} is {}x{}, the calibration is for {}x{}",
                self.list[i].display(),
                image.width,
                image.height,
                model.width,
                model.height
            );
            return Vec::new();
        }
        if self.next == self.list.len() && !self.repeat {
            log::info!("camera_driver: all {} frames published", self.list.len());
        }
        vec![Frame { stamp_ns, image, model }]
    }
    fn read_errors(&self) -> u64 {
        self.read_errors
    }
    /// The same sequence keeps its place and its cache; the camera model is derived again.
    fn reconfigured(&mut self, spec: &SourceSpec) -> bool {
        self.rig_model = None;
        matches!(spec, SourceSpec::Files { list, stamps, repeat }
            if *list == self.list && *stamps == self.stamps && *repeat == self.repeat)
    }
}

/// The frames of a `files` spec: a directory's image files in name order, or a printf-style
/// pattern (`frame_%03d.bmp`) counted from 0 (or 1) until the first missing number.
pub(in crate::camera_driver) fn frame_list(spec: &str) -> Result<Vec<PathBuf>, String> {
    if spec.is_empty() {
        return Err("the files source needs a directory or a pattern".into());
    }
    let is_frame = |p: &Path| {
        p.extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .is_some_and(|e| ["bmp", "png", "pgm", "ppm", "pnm", "jpg", "jpeg"].contains(&e.as_str()))
    };
    let path = Path::new(spec);
    let list: Vec<PathBuf> = if path.is_dir() {
        let mut v: Vec<PathBuf> = std::fs::read_dir(path)
            .map_err(|e| format!("{spec}: {e}"))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| is_frame(p))
            .collect();
        v.sort();
        v
    } else if let Some(i) = spec.find('%') {
        let end = spec[i..].find('d').map(|j| i + j).ok_or_else(|| format!("{spec}: pattern needs %d or %0Nd"))?;
        let width: usize = spec[i + 1..end].trim_start_matches('0').parse().unwrap_or(0);
        let name = |n: usize| PathBuf::from(format!("{}{n:0width$}{}", &spec[..i], &spec[end + 1..]));
        let first = if name(0).is_file() { 0 } else { 1 };
        (first..).map(name).take_while(|p| p.is_file()).collect()
    } else {
        return Err(format!("{spec}: neither a directory nor a %d pattern"));
    };
    if list.is_empty() {
        return Err(format!("{spec}: no frames (.bmp, .png, .pgm, .ppm)"));
    }
    Ok(list)
}

/// Stamps of a sidecar file: one per line, seconds (with a decimal point) or integer ns.
pub(in crate::camera_driver) fn read_stamps(path: &Path) -> Result<Vec<i64>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let v = if l.contains('.') || l.contains('e') {
            l.parse::<f64>().ok().filter(|v| v.is_finite()).map(|s| (s * 1e9).round() as i64)
        } else {
            l.parse::<i64>().ok()
        };
        out.push(v.ok_or_else(|| format!("{} line {}: {l:?} is not a stamp", path.display(), i + 1))?);
    }
    Ok(out)
}
