//! The radiograph: its grey levels (modality rescale, VOI windowing, MONOCHROME1), the
//! unexposed detector columns to crop, and its placement in `table`.
//!
//! A linear-scan machine builds the radiograph line by line: image row `r` is the detector line
//! read while the C-arm passed through the travel of row `r`'s time, and image column `c` is one
//! detector element of the line detector that lies in the fan beam's plane, below the table. So
//! the scan axis comes from the C-arm's travel over the exposure (rows evenly spaced in time
//! between its start and end), and the cross axis from the fan-beam geometry: the ray from the
//! focal spot (`laser_source`) to detector element `c` meets the reference plane (the tabletop,
//! or another height) at the point where that column belongs.

use crate::geom::{Iso3, Plane, Vec3};
use std::ops::Range;

/// Why a radiograph cannot be used or placed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum XrayError {
    /// The pixel buffer does not match the size.
    #[error("radiograph {width}x{height} needs {needed} pixels, got {got}")]
    Size {
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
        /// Pixels needed.
        needed: usize,
        /// Pixels given.
        got: usize,
    },
    /// No column received radiation.
    #[error("no exposed detector columns (every column is below {0} % of the brightest)")]
    Unexposed(u32),
    /// A geometry value is out of range.
    #[error("{0}")]
    Geometry(String),
    /// The pose of a row is not known.
    #[error("no C-arm pose at row {row} (stamp {stamp_ns} ns): {reason}")]
    Pose {
        /// Row.
        row: f64,
        /// Stamp of that row.
        stamp_ns: i64,
        /// Why.
        reason: String,
    },
}

/// A DICOM window (C.11.2.1.2, the `LINEAR` function).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// Window Center, in rescaled units.
    pub center: f64,
    /// Window Width (>= 1).
    pub width: f64,
}

impl Window {
    /// Maps `x` to 0..=1.
    pub fn apply(&self, x: f64) -> f64 {
        let w = (self.width - 1.0).max(1e-9);
        (((x - (self.center - 0.5)) / w) + 0.5).clamp(0.0, 1.0)
    }
}

/// A VOI lookup table (C.11.2.1.1).
#[derive(Debug, Clone, PartialEq)]
pub struct VoiLut {
    /// First input value mapped (to `data[0]`).
    pub first: i32,
    /// Bits per output entry.
    pub bits: u8,
    /// Entries.
    pub data: Vec<u16>,
}

/// A radiograph as acquired: stored values and what the file says about showing them.
#[derive(Debug, Clone, PartialEq)]
pub struct Radiograph {
    /// Columns (detector elements).
    pub width: u32,
    /// Rows (detector lines, along the scan).
    pub height: u32,
    /// Stored values, row-major (signed data are offset into `u16` and the offset moved into
    /// `rescale_intercept`).
    pub pixels: Vec<u16>,
    /// Bits stored (8..=16).
    pub bits_stored: u8,
    /// `MONOCHROME1`: the lowest value is shown white.
    pub monochrome1: bool,
    /// Modality rescale slope.
    pub rescale_slope: f64,
    /// Modality rescale intercept.
    pub rescale_intercept: f64,
    /// The file's first window, if any.
    pub window: Option<Window>,
    /// The file's first VOI LUT, if any.
    pub voi_lut: Option<VoiLut>,
}

impl Radiograph {
    /// A radiograph with identity rescale and no window.
    pub fn new(width: u32, height: u32, pixels: Vec<u16>, bits_stored: u8) -> Result<Self, XrayError> {
        let r = Self {
            width,
            height,
            pixels,
            bits_stored,
            monochrome1: false,
            rescale_slope: 1.0,
            rescale_intercept: 0.0,
            window: None,
            voi_lut: None,
        };
        r.validate()?;
        Ok(r)
    }

    /// Checks the buffer against the size.
    pub fn validate(&self) -> Result<(), XrayError> {
        let needed = self.width as usize * self.height as usize;
        if self.pixels.len() != needed || needed == 0 {
            return Err(XrayError::Size { width: self.width, height: self.height, needed, got: self.pixels.len() });
        }
        Ok(())
    }

    /// The window used for display: `over` if given, else the file's, else the 0.5..99.5 %
    /// range of the rescaled values.
    pub fn display_window(&self, over: Option<Window>) -> Window {
        if let Some(w) = over.or(self.window) {
            return w;
        }
        let mut hist = vec![0u32; 65536];
        for &p in &self.pixels {
            hist[p as usize] += 1;
        }
        let n = self.pixels.len() as u64;
        let quantile = |q: f64| {
            let target = (q * n as f64) as u64;
            let mut acc = 0u64;
            for (v, &c) in hist.iter().enumerate() {
                acc += u64::from(c);
                if acc > target {
                    return v as f64;
                }
            }
            65535.0
        };
        let (lo, hi) = (self.rescale(quantile(0.005)), self.rescale(quantile(0.995)));
        let (lo, hi) = (lo.min(hi), lo.max(hi));
        Window { center: 0.5 * (lo + hi) + 0.5, width: (hi - lo).max(1.0) + 1.0 }
    }

    fn rescale(&self, stored: f64) -> f64 {
        self.rescale_slope * stored + self.rescale_intercept
    }

    /// 8-bit grey for display, bone bright: modality rescale, then the VOI (`window` if given,
    /// else the file's window, else the file's VOI LUT, else an automatic window), then
    /// MONOCHROME1 inverted.
    pub fn display(&self, window: Option<Window>) -> Vec<u8> {
        let use_lut = window.is_none() && self.window.is_none() && self.voi_lut.is_some();
        let w = self.display_window(window);
        // One table entry per stored value.
        let lut: Vec<u8> = (0..=u16::MAX)
            .map(|v| {
                let x = self.rescale(f64::from(v));
                let y = match (&self.voi_lut, use_lut) {
                    (Some(l), true) if !l.data.is_empty() => {
                        let i = (x.round() as i64 - i64::from(l.first)).clamp(0, l.data.len() as i64 - 1) as usize;
                        f64::from(l.data[i]) / ((1u32 << l.bits.clamp(1, 16)) - 1) as f64
                    }
                    _ => w.apply(x),
                };
                let y = if self.monochrome1 { 1.0 - y } else { y };
                (y * 255.0).round() as u8
            })
            .collect();
        self.pixels.iter().map(|&p| lut[p as usize]).collect()
    }

    /// The columns that received radiation: scanning in from each edge, columns whose mean
    /// dose is below `threshold` (fraction) of the 95th percentile of the column means are
    /// unexposed (outside the collimated fan). Dose rises with the stored value for
    /// MONOCHROME1 data and falls with it for MONOCHROME2 (where bone is bright).
    pub fn exposed_columns(&self, threshold: f64) -> Result<Range<u32>, XrayError> {
        self.validate()?;
        let (w, h) = (self.width as usize, self.height as usize);
        let mut mean = vec![0f64; w];
        for row in self.pixels.chunks_exact(w) {
            for (m, &p) in mean.iter_mut().zip(row) {
                *m += f64::from(p);
            }
        }
        let full = f64::from((1u32 << self.bits_stored.clamp(1, 16)) - 1);
        let dose: Vec<f64> = mean
            .iter()
            .map(|&m| {
                let m = m / h as f64;
                if self.monochrome1 {
                    m
                } else {
                    full - m
                }
            })
            .collect();
        let mut sorted = dose.clone();
        sorted.sort_by(f64::total_cmp);
        let ref_dose = sorted[((sorted.len() - 1) as f64 * 0.95) as usize].max(1e-9);
        let exposed = |d: f64| d >= threshold * ref_dose;
        let first = dose.iter().position(|&d| exposed(d));
        let last = dose.iter().rposition(|&d| exposed(d));
        match (first, last) {
            (Some(a), Some(b)) => Ok(a as u32..b as u32 + 1),
            _ => Err(XrayError::Unexposed((threshold * 100.0).round() as u32)),
        }
    }

    /// The sub-image of columns `cols` (all rows).
    pub fn crop_columns(&self, cols: Range<u32>) -> Radiograph {
        let (a, b) = (cols.start.min(self.width) as usize, cols.end.min(self.width) as usize);
        let mut out = self.clone();
        out.width = (b - a) as u32;
        out.pixels = self.pixels.chunks_exact(self.width as usize).flat_map(|r| r[a..b].iter().copied()).collect();
        out
    }
}

/// The line detector and the reference plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorGeometry {
    /// Focal spot to detector line along the central ray, metres.
    pub source_detector_m: f64,
    /// Detector element pitch, metres.
    pub pitch_m: f64,
    /// Detector column (pixel edges at integers) hit by the central ray; `None`: the middle
    /// of the full, uncropped detector.
    pub center_column: Option<f64>,
    /// Columns count towards -X instead of +X.
    pub flip_columns: bool,
    /// Height above the tabletop of the plane the radiograph is placed on, metres.
    pub plane_height_m: f64,
}

impl Default for DetectorGeometry {
    fn default() -> Self {
        Self { source_detector_m: 1.3, pitch_m: 0.0005, center_column: None, flip_columns: false, plane_height_m: 0.0 }
    }
}

impl DetectorGeometry {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), XrayError> {
        if !(self.source_detector_m.is_finite() && self.source_detector_m > 0.0) {
            return Err(XrayError::Geometry(format!("source_detector_m {} must be positive", self.source_detector_m)));
        }
        if !(self.pitch_m.is_finite() && self.pitch_m > 0.0) {
            return Err(XrayError::Geometry(format!("pitch_m {} must be positive", self.pitch_m)));
        }
        if !self.plane_height_m.is_finite() {
            return Err(XrayError::Geometry("plane_height_m must be finite".into()));
        }
        Ok(())
    }
}

/// The fan beam in `carm`: focal spot and the unit directions of the central ray (`down`) and
/// of the detector line (`across`), both in the beam's plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FanBeam {
    /// Focal spot in `carm`.
    pub source: Vec3,
    /// Central ray direction.
    pub down: Vec3,
    /// Direction of increasing detector column (before `flip_columns`).
    pub across: Vec3,
}

impl FanBeam {
    /// The fan in the laser plane through the focal spot: `down` is -Z of `carm` projected on
    /// the plane, `across` is `down x n` (+X for the plane `y = d`).
    pub fn new(plane: &Plane, source: Vec3) -> Result<Self, XrayError> {
        let n = plane.normal;
        let down = (-Vec3::Z - n * n.dot(-Vec3::Z))
            .try_normalize()
            .ok_or_else(|| XrayError::Geometry("the laser plane is horizontal: no fan beam downwards".into()))?;
        Ok(Self { source, down, across: down.cross(n) })
    }
}

/// Where a radiograph lies in `table`: the fan, the detector, and the exposure in time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The fan beam in `carm`.
    pub fan: FanBeam,
    /// The detector and reference plane.
    pub geometry: DetectorGeometry,
    /// Columns of the full detector (for the default centre column).
    pub detector_columns: u32,
    /// Rows of the radiograph.
    pub rows: u32,
    /// Exposure start (the first row's leading edge), ns.
    pub start_ns: i64,
    /// Exposure end (the last row's trailing edge), ns.
    pub end_ns: i64,
}

impl Placement {
    /// Stamp of row position `row` (0 = the first row's leading edge, `rows` = the last row's
    /// trailing edge).
    pub fn row_stamp(&self, row: f64) -> i64 {
        let f = row / f64::from(self.rows.max(1));
        self.start_ns + ((self.end_ns - self.start_ns) as f64 * f).round() as i64
    }

    /// The point in `table` of detector position `col` (pixel edges at integers, full detector
    /// columns) at row position `row`, given `table -> carm` at that row's stamp.
    pub fn point_with_pose(&self, col: f64, table_from_carm: &Iso3) -> Result<Vec3, XrayError> {
        let g = &self.geometry;
        let center = g.center_column.unwrap_or(f64::from(self.detector_columns) / 2.0);
        let sign = if g.flip_columns { -1.0 } else { 1.0 };
        let f = &self.fan;
        let det = f.source + f.down * g.source_detector_m + f.across * (sign * (col - center) * g.pitch_m);
        let s = table_from_carm.transform_point(f.source);
        let d = table_from_carm.transform_point(det);
        let dz = s.z - d.z;
        if dz.abs() < 1e-9 || (s.z - g.plane_height_m) * dz <= 0.0 {
            return Err(XrayError::Geometry(format!(
                "the ray to detector column {col:.1} does not meet the plane z = {} m",
                g.plane_height_m
            )));
        }
        Ok(s + (d - s) * ((s.z - g.plane_height_m) / dz))
    }

    /// The point in `table` of (`col`, `row`) with the pose looked up by `pose_at(stamp_ns)`.
    pub fn point(&self, col: f64, row: f64, pose_at: &dyn Fn(i64) -> Result<Iso3, String>) -> Result<Vec3, XrayError> {
        self.point_with_pose(col, &self.row_pose(row, pose_at)?)
    }

    /// `table -> carm` at row position `row`.
    fn row_pose(&self, row: f64, pose_at: &dyn Fn(i64) -> Result<Iso3, String>) -> Result<Iso3, XrayError> {
        let stamp_ns = self.row_stamp(row);
        pose_at(stamp_ns).map_err(|reason| XrayError::Pose { row, stamp_ns, reason })
    }

    /// A grid over the columns `cols` and all rows, with up to `max_col_strips` x
    /// `max_row_strips` cells (vertices at cell corners), texture coordinates with (0, 0) at the
    /// image's bottom-left (the last row, first column) as VRML has them. Rows are sampled so
    /// that the grid follows the travel (uneven speed included); columns so that vertex colours
    /// can stand in for the texture.
    pub fn grid(
        &self,
        cols: Range<u32>,
        max_col_strips: u32,
        max_row_strips: u32,
        pose_at: &dyn Fn(i64) -> Result<Iso3, String>,
    ) -> Result<PlacedGrid, XrayError> {
        self.geometry.validate()?;
        if cols.is_empty() || self.rows == 0 {
            return Err(XrayError::Geometry("an empty radiograph cannot be placed".into()));
        }
        let nc = cols.len().min(max_col_strips.max(1) as usize) as u32;
        let nr = self.rows.min(max_row_strips.max(1));
        let mut g = PlacedGrid { columns: nc + 1, rows: nr + 1, ..PlacedGrid::default() };
        for k in 0..=nr {
            let row = f64::from(self.rows) * f64::from(k) / f64::from(nr);
            let pose = self.row_pose(row, pose_at)?;
            let v = 1.0 - (f64::from(k) / f64::from(nr)) as f32;
            for j in 0..=nc {
                let f = f64::from(j) / f64::from(nc);
                let col = f64::from(cols.start) + f * cols.len() as f64;
                g.positions.push(self.point_with_pose(col, &pose)?);
                g.uv.push([f as f32, v]);
            }
        }
        let w = nc + 1;
        for k in 0..nr {
            for j in 0..nc {
                let (a, b) = (k * w + j, k * w + j + 1);
                let (c, d) = (a + w, b + w);
                g.triangles.push([a, b, d]);
                g.triangles.push([a, d, c]);
            }
        }
        Ok(g)
    }
}

/// A placed radiograph as a textured grid.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlacedGrid {
    /// Vertices per grid row.
    pub columns: u32,
    /// Grid rows.
    pub rows: u32,
    /// Vertices in `table`, row-major.
    pub positions: Vec<Vec3>,
    /// Texture coordinates, (0, 0) at the image's bottom-left.
    pub uv: Vec<[f32; 2]>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::table_from_carm;

    fn placement() -> Placement {
        let plane = Plane::from_params([0.0, 1.0, 0.0, 0.0]).unwrap();
        Placement {
            fan: FanBeam::new(&plane, Vec3::new(0.0, 0.0, 1.2)).unwrap(),
            geometry: DetectorGeometry::default(),
            detector_columns: 1400,
            rows: 100,
            start_ns: 1_000_000_000,
            end_ns: 2_000_000_000,
        }
    }

    #[test]
    fn columns_map_across_the_table_by_the_fan_magnification() {
        let p = placement();
        let pose = table_from_carm(0.25, 0.0, 0.0);
        // The central column lies under the focal spot; 100 columns off lie 100 pitches
        // demagnified by 1.2 / 1.3 at the tabletop.
        let c = p.point_with_pose(700.0, &pose).unwrap();
        assert!((c - Vec3::new(0.0, 0.25, 0.0)).norm() < 1e-12, "{c:?}");
        let e = p.point_with_pose(800.0, &pose).unwrap();
        assert!((e.x - 100.0 * 0.0005 * 1.2 / 1.3).abs() < 1e-12, "{e:?}");
        // On a plane 0.1 m up the demagnification is 1.1 / 1.3.
        let mut q = p;
        q.geometry.plane_height_m = 0.1;
        let e = q.point_with_pose(800.0, &pose).unwrap();
        assert!((e.x - 100.0 * 0.0005 * 1.1 / 1.3).abs() < 1e-12 && (e.z - 0.1).abs() < 1e-12);
        // Flipped columns run towards -X.
        q.geometry.flip_columns = true;
        assert!(q.point_with_pose(800.0, &pose).unwrap().x < 0.0);
        // A plane above the focal spot is refused.
        q.geometry.plane_height_m = 1.5;
        assert!(q.point_with_pose(800.0, &pose).is_err());
    }

    #[test]
    fn rows_follow_the_travel_over_the_exposure() {
        let p = placement();
        // Travel 0.1 m/s from 0 at the exposure start.
        let pose_at = |t: i64| -> Result<Iso3, String> {
            if !(0..=3_000_000_000).contains(&t) {
                return Err("outside".into());
            }
            Ok(table_from_carm((t - 1_000_000_000) as f64 * 1e-10, 0.0, 0.0))
        };
        let mid = p.point(700.0, 50.0, &pose_at).unwrap();
        assert!((mid.y - 0.05).abs() < 1e-9, "{mid:?}");
        let g = p.grid(200..1200, 4, 10, &pose_at).unwrap();
        assert_eq!((g.columns, g.rows), (5, 11));
        assert_eq!(g.positions.len(), 55);
        assert_eq!(g.triangles.len(), 80);
        assert!((g.positions[0].y - 0.0).abs() < 1e-9 && (g.positions[54].y - 0.1).abs() < 1e-9);
        assert!((g.positions[2].x - p.point_with_pose(700.0, &pose_at(0).unwrap()).unwrap().x).abs() < 1e-12);
        assert_eq!(g.uv[0], [0.0, 1.0]);
        assert_eq!(g.uv[54], [1.0, 0.0]);
        // A pose gap is named with the row.
        let mut late = p;
        late.end_ns = 5_000_000_000;
        let e = late.grid(0..10, 2, 4, &pose_at).unwrap_err();
        assert!(e.to_string().contains("no C-arm pose at row"), "{e}");
    }

    fn image(monochrome1: bool) -> Radiograph {
        // 10 columns: 2 unexposed at each edge, an attenuating object in column 5.
        let mut px = Vec::new();
        for _ in 0..4 {
            for c in 0..10 {
                let dose: u16 = if !(2..8).contains(&c) {
                    30
                } else if c == 5 {
                    4000
                } else {
                    12000
                };
                px.push(if monochrome1 { dose } else { 16383 - dose });
            }
        }
        let mut r = Radiograph::new(10, 4, px, 14).unwrap();
        r.monochrome1 = monochrome1;
        r
    }

    #[test]
    fn unexposed_columns_are_cropped_from_the_edges_only() {
        for m1 in [true, false] {
            let r = image(m1);
            assert_eq!(r.exposed_columns(0.1).unwrap(), 2..8, "monochrome1 {m1}");
            let c = r.crop_columns(2..8);
            assert_eq!((c.width, c.pixels.len()), (6, 24));
        }
        let dark = Radiograph::new(3, 1, vec![0, 0, 0], 14).unwrap();
        assert!(matches!(dark.exposed_columns(0.1), Ok(_) | Err(XrayError::Unexposed(_))));
        assert!(Radiograph::new(3, 2, vec![0; 5], 14).is_err());
    }

    #[test]
    fn display_shows_attenuation_bright_for_both_photometric_interpretations() {
        for m1 in [true, false] {
            let r = image(m1);
            let w = Some(Window { center: 8192.0, width: 16384.0 });
            let d = r.display(w);
            // Column 5 (attenuating) brighter than column 3 (open beam).
            assert!(d[5] > d[3], "monochrome1 {m1}: {:?}", &d[..10]);
            let auto = r.display(None);
            assert!(auto[5] > auto[3]);
        }
        // The DICOM linear window: centre 2048, width 4096 maps 0 -> 0 and 4095 -> 1.
        let w = Window { center: 2048.0, width: 4096.0 };
        assert_eq!(w.apply(0.0), 0.0);
        assert!((w.apply(4095.0) - 1.0).abs() < 1e-12);
        assert!((w.apply(2047.5) - 0.5).abs() < 1e-12);
        // A VOI LUT is used when there is no window.
        let mut r = Radiograph::new(2, 1, vec![10, 11], 12).unwrap();
        r.voi_lut = Some(VoiLut { first: 10, bits: 8, data: vec![0, 255] });
        assert_eq!(r.display(None), vec![0, 255]);
        // Rescale applies before the window.
        r.voi_lut = None;
        r.rescale_slope = 100.0;
        r.window = Some(Window { center: 1050.5, width: 101.0 });
        assert_eq!(r.display(None), vec![0, 255]);
    }
}
