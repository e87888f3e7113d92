//! The synthetic radiograph: the scene projected through the fan beam onto a line detector
//! below the table, one detector line per row while the C-arm travels (line integrals of
//! attenuation through the analytic objects, Beer-Lambert, Poisson-like noise, 14-bit).

use super::{Scene, SplitMix};
use crate::geom::Iso3;
use crate::xray::{Placement, Radiograph, Window};

/// How the synthetic radiograph is acquired.
#[derive(Debug, Clone, PartialEq)]
pub struct XraySettings {
    /// Detector elements in the line.
    pub detector_columns: u32,
    /// Half width of the collimated fan at the tabletop, metres (columns outside get no dose).
    pub collimation_half_width_m: f64,
    /// Detector lines per second.
    pub line_rate_hz: f64,
    /// Stored value of the open beam.
    pub open_beam: f64,
    /// Stored value with no dose (dark current).
    pub dark: f64,
    /// Noise of the open beam, stored units (scaled with the square root of the dose).
    pub noise_sigma: f64,
    /// Bits stored.
    pub bits_stored: u8,
    /// Random seed.
    pub seed: u64,
}

impl Default for XraySettings {
    fn default() -> Self {
        Self {
            detector_columns: 1400,
            collimation_half_width_m: 0.26,
            line_rate_hz: 140.0,
            open_beam: 15000.0,
            dark: 40.0,
            noise_sigma: 40.0,
            bits_stored: 14,
            seed: 1,
        }
    }
}

/// Renders the radiograph of `scene` for `placement` (its `rows` and exposure times; the
/// detector geometry with the reference plane ignored), with `table -> carm` of each row's
/// stamp from `pose_at`. Stored values rise with the dose (`MONOCHROME1`); the window covers
/// the exposed range.
pub fn render_radiograph(
    scene: &Scene,
    placement: &Placement,
    settings: &XraySettings,
    pose_at: &dyn Fn(i64) -> Iso3,
) -> Radiograph {
    let (w, h) = (placement.detector_columns, placement.rows);
    let g = &placement.geometry;
    let f = &placement.fan;
    let center = g.center_column.unwrap_or(f64::from(w) / 2.0);
    let sign = if g.flip_columns { -1.0 } else { 1.0 };
    let full = f64::from((1u32 << settings.bits_stored.clamp(8, 16)) - 1);
    // Collimation: the fan's half angle from the tabletop half width at the source's height.
    let half_angle = (settings.collimation_half_width_m / f.source.z.max(1e-6)).atan();
    let mut rng = SplitMix::new(settings.seed ^ 0xB5AD_4ECE_DA1C_E2A9);
    let mut pixels = Vec::with_capacity(w as usize * h as usize);
    for r in 0..h {
        let pose = pose_at(placement.row_stamp(f64::from(r) + 0.5));
        let s = pose.transform_point(f.source);
        for c in 0..w {
            let off = sign * (f64::from(c) + 0.5 - center) * g.pitch_m;
            let det_carm = f.source + f.down * g.source_detector_m + f.across * off;
            let exposed = (off / g.source_detector_m).atan().abs() <= half_angle;
            let dose = if exposed { (-scene.attenuation(s, pose.transform_point(det_carm))).exp() } else { 0.0 };
            let v =
                settings.dark + settings.open_beam * dose + settings.noise_sigma * dose.sqrt().max(0.05) * rng.normal();
            pixels.push(v.round().clamp(0.0, full) as u16);
        }
    }
    let lo = settings.dark;
    let hi = settings.dark + settings.open_beam;
    Radiograph {
        width: w,
        height: h,
        pixels,
        bits_stored: settings.bits_stored,
        monochrome1: true,
        rescale_slope: 1.0,
        rescale_intercept: 0.0,
        window: Some(Window { center: 0.5 * (lo + hi), width: hi - lo }),
        voi_lut: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::{Plane, Vec3};
    use crate::pose::table_from_carm;
    use crate::xray::{DetectorGeometry, FanBeam};

    #[test]
    fn sphere_shadow_lies_where_the_ray_through_its_centre_meets_the_detector() {
        let scene = Scene::by_name("sphere").unwrap();
        let plane = Plane::from_params([0.0, 1.0, 0.0, 0.0]).unwrap();
        let p = Placement {
            fan: FanBeam::new(&plane, Vec3::new(0.0, 0.0, 1.2)).unwrap(),
            geometry: DetectorGeometry::default(),
            detector_columns: 1400,
            rows: 240,
            start_ns: 0,
            end_ns: 2_400_000_000,
        };
        // 0.1 m/s from travel -0.12.
        let pose = |t: i64| table_from_carm(-0.12 + t as f64 * 1e-10, 0.0, 0.0);
        let s = XraySettings { noise_sigma: 0.0, ..XraySettings::default() };
        let r = render_radiograph(&scene, &p, &s, &pose);
        assert_eq!((r.width, r.height, r.pixels.len()), (1400, 240, 1400 * 240));
        // Columns outside the collimation get dark current only.
        assert_eq!(r.pixels[0], 40);
        let exposed = r.exposed_columns(0.1).unwrap();
        let expect = 0.26 * 1.3 / 1.2 / 0.0005;
        assert!((f64::from(exposed.start) - (700.0 - expect)).abs() <= 1.0, "{exposed:?}");
        // The attenuation-weighted centroid of the shadow (chords are symmetric about the
        // ray through the centre) lies at column 700 + 0.06 * 1.3 / 1.12 / pitch; its row at
        // travel 0.
        let open = 40.0 + 15000.0 * (-4.0f64 * 0.02).exp();
        let weight = |v: u16| ((open - 40.0) / (f64::from(v) - 40.0).max(1.0)).ln().max(0.0);
        let (mut sw, mut sc, mut sr) = (0.0, 0.0, 0.0);
        for (i, &v) in r.pixels.iter().enumerate() {
            let (c, row) = ((i % 1400) as f64 + 0.5, (i / 1400) as f64 + 0.5);
            if exposed.contains(&((i % 1400) as u32)) && weight(v) > 0.05 {
                sw += weight(v);
                sc += weight(v) * c;
                sr += weight(v) * row;
            }
        }
        let (col, row) = (sc / sw, sr / sw);
        let want_col = 700.0 + 0.06 * 1.3 / 1.12 / 0.0005;
        // (Within 0.6 px: columns are linear in tan(angle), the chords symmetric in angle.)
        assert!((col - want_col).abs() <= 0.6, "{col} vs {want_col}");
        assert!((row - 120.0).abs() <= 0.3, "{row}");
        // Open beam through the table only.
        let got = f64::from(r.pixels[230 * 1400 + 700]);
        assert!((got - open).abs() < 2.0, "{got} vs {open}");
    }
}
