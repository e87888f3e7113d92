//! The synthetic scanner: renders the camera images of a scan of an analytic scene and knows
//! the truth (the surface's signed distance and the points each camera can observe on the
//! laser sheet). Deterministic for a seed.

pub mod calib;
pub mod scene;
pub mod xray;

use crate::camera::CameraModel;
use crate::edge::{LaserColor, Orientation};
use crate::geom::{Iso3, Plane, Vec3};
use crate::image::{Encoding, Image};
use crate::pose::table_from_carm;
use crate::rig::Rig;
use crate::rig::MAX_LASERS;
pub use scene::{Scene, SCENE_NAMES};

/// The laser fan beam's appearance.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserModel {
    /// Standard deviation of the sheet's Gaussian thickness profile, metres.
    pub sheet_sigma_m: f64,
    /// Half opening angle of the fan, degrees.
    pub fan_half_angle_deg: f64,
    /// Grey level added by the laser on a white surface at normal incidence.
    pub peak_level: f64,
    /// The laser's colour as seen by a colour camera (linear RGB weights).
    pub rgb: [f64; 3],
}

impl Default for LaserModel {
    fn default() -> Self {
        Self { sheet_sigma_m: 0.0015, fan_half_angle_deg: 28.0, peak_level: 240.0, rgb: [1.0, 0.12, 0.08] }
    }
}

impl LaserModel {
    /// The colour a colour camera sees of a laser of colour `c` (linear RGB weights): the
    /// red of [`LaserModel::rgb`], and for green and blue lasers the crosstalk of a Bayer
    /// sensor's filters into the other channels.
    pub fn rgb_of(&self, c: LaserColor) -> [f64; 3] {
        match c {
            LaserColor::Red => self.rgb,
            LaserColor::Green => [0.10, 1.0, 0.18],
            LaserColor::Blue => [0.06, 0.22, 1.0],
        }
    }
    /// The laser of the `hard` preset: a sheet thinner than a pixel at 320x240 (its image is
    /// about a third of a pixel wide before the optics blur it), bright enough to saturate on
    /// white surfaces.
    pub fn hard() -> Self {
        Self { sheet_sigma_m: 0.0008, peak_level: 700.0, ..Self::default() }
    }
}

/// What real cameras and rooms do that an ideal render does not; every effect can be switched
/// off (zero). [`Realism::none`] is the ideal render, [`Realism::hard`] turns everything on.
#[derive(Debug, Clone, PartialEq)]
pub struct Realism {
    /// Optics blur: standard deviation of a Gaussian point-spread function, pixels.
    pub psf_sigma_px: f64,
    /// Laser speckle: standard deviation of a per-pixel factor on the laser light (mean 1).
    pub speckle_contrast: f64,
    /// Room light from above and behind the cameras, grey levels on a white surface facing it.
    pub room_light_level: f64,
    /// Specular reflectance of the objects (not the tabletop) under the room light: glossy
    /// highlights.
    pub specular: f64,
    /// Phong exponent of the highlights.
    pub shininess: f64,
    /// Exposure time: the sheet moves `speed * exposure` during it (motion smear), seconds.
    pub exposure_s: f64,
    /// Very dark surfaces (hair, print): the reflectance of every printed band, and bands added
    /// where a scene has none (`None`: the scene's own).
    pub dark_albedo: Option<f64>,
}

impl Realism {
    /// The ideal render: none of the effects.
    pub fn none() -> Self {
        Self {
            psf_sigma_px: 0.0,
            speckle_contrast: 0.0,
            room_light_level: 0.0,
            specular: 0.0,
            shininess: 1.0,
            exposure_s: 0.0,
            dark_albedo: None,
        }
    }
    /// Every effect on, at levels seen in real scanner cameras.
    pub fn hard() -> Self {
        Self {
            psf_sigma_px: 0.6,
            speckle_contrast: 0.25,
            room_light_level: 45.0,
            specular: 2.5,
            shininess: 20.0,
            exposure_s: 0.008,
            dark_albedo: Some(0.15),
        }
    }
}

impl Default for Realism {
    fn default() -> Self {
        Self::none()
    }
}

/// A named set of scanner settings: `ideal` (today's render) or `hard` (every effect of
/// [`Realism::hard`], a thin saturating sheet, more laser-off frames).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Preset {
    /// The ideal render.
    #[default]
    Ideal,
    /// As unkind as real cameras.
    Hard,
}

impl Preset {
    /// Parses `ideal` / `hard`.
    pub fn parse(s: &str) -> Option<Preset> {
        match s {
            "ideal" => Some(Preset::Ideal),
            "hard" => Some(Preset::Hard),
            _ => None,
        }
    }
    /// The laser of this preset.
    pub fn laser(self) -> LaserModel {
        match self {
            Preset::Ideal => LaserModel::default(),
            Preset::Hard => LaserModel::hard(),
        }
    }
    /// Applies the preset's camera and room effects to `settings` (speed, size, encoding and
    /// seed are left as they are).
    pub fn apply(self, settings: &mut ScanSettings) {
        if self == Preset::Hard {
            settings.realism = Realism::hard();
            settings.laser_off_frames = 4;
        }
    }
}

/// How the scan is run and imaged.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanSettings {
    /// C-arm speed, m/s (the study's: 0.035, 0.070, 0.140).
    pub speed_mps: f64,
    /// Camera frame rate, frames per second.
    pub fps: f64,
    /// Travel at the first frame, metres (`None`: the scene's own).
    pub travel_start_m: Option<f64>,
    /// Travel at the last frame, metres (`None`: the scene's own).
    pub travel_end_m: Option<f64>,
    /// Stamp of the first frame, ns since the epoch.
    pub start_stamp_ns: i64,
    /// Largest deviation of an exposure from the nominal frame time, seconds.
    pub jitter_s: f64,
    /// Frames with the laser off at the start and at the end.
    pub laser_off_frames: u32,
    /// Sensor noise, grey levels (standard deviation).
    pub noise_sigma: f64,
    /// Ambient light on a white surface, grey levels.
    pub ambient_level: f64,
    /// Image encoding.
    pub encoding: Encoding,
    /// Sub-samples per pixel side near the laser sheet.
    pub supersample: u32,
    /// Random seed (noise and jitter).
    pub seed: u64,
    /// The real-camera effects (none by default).
    pub realism: Realism,
}

impl Default for ScanSettings {
    fn default() -> Self {
        Self {
            speed_mps: 0.070,
            fps: 30.0,
            travel_start_m: None,
            travel_end_m: None,
            start_stamp_ns: 1_700_000_000_000_000_000,
            jitter_s: 0.0015,
            laser_off_frames: 2,
            noise_sigma: 1.5,
            ambient_level: 55.0,
            encoding: Encoding::Mono8,
            supersample: 5,
            seed: 1,
            realism: Realism::none(),
        }
    }
}

/// One frame's timing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTime {
    /// Frame number in the scan.
    pub index: u32,
    /// Exposure stamp, ns since the epoch.
    pub stamp_ns: i64,
    /// C-arm travel at the exposure, metres.
    pub travel_m: f64,
    /// Whether the laser is on.
    pub laser_on: bool,
}

/// Why a scanner cannot be set up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SynthError {
    /// Unknown scene name.
    #[error("unknown scene {0:?} (known: pyramid, phantom, sphere, cylinder, box, body)")]
    UnknownScene(String),
    /// A setting is out of range.
    #[error("invalid scan setting {name}: {reason}")]
    Invalid {
        /// Setting.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A rig camera is unusable.
    #[error("rig camera {name}: {source}")]
    Camera {
        /// Camera name.
        name: String,
        /// Cause.
        source: crate::camera::CameraError,
    },
}

struct CamState {
    model: CameraModel,
    carm_from_optical: Iso3,
    /// Undistorted rays (z = 1) at pixel corners, (w + 1) x (h + 1).
    corners: Vec<Vec3>,
}

/// A synthetic scanner for one scene, rig, laser and scan.
pub struct Scanner {
    /// The scene.
    pub scene: Scene,
    /// The rig.
    pub rig: Rig,
    /// The laser.
    pub laser: LaserModel,
    /// The scan.
    pub settings: ScanSettings,
    cams: Vec<CamState>,
    /// The lasers' sheets: the rig's `lasers`, or its single `laser_plane`.
    sheets: Vec<Sheet>,
}

/// One laser's sheet of light, fixed in `carm`.
#[derive(Debug, Clone, Copy)]
struct Sheet {
    plane_carm: Plane,
    source: Vec3,
    rgb: [f64; 3],
}

/// SplitMix64: a tiny deterministic generator for noise and jitter.
#[derive(Debug, Clone)]
pub struct SplitMix(u64);
impl SplitMix {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

impl Scanner {
    /// Sets up a scanner.
    pub fn new(scene: Scene, rig: Rig, laser: LaserModel, settings: ScanSettings) -> Result<Self, SynthError> {
        let bad = |name, reason: String| Err(SynthError::Invalid { name, reason });
        if !crate::limits::speed_ok(settings.speed_mps) {
            let (lo, hi) = crate::limits::SPEED_MPS;
            return bad("speed", format!("{} m/s is not in ({lo}, {hi})", settings.speed_mps));
        }
        if !(settings.fps > 0.0 && settings.fps <= crate::limits::MAX_FPS) {
            return bad("fps", format!("{} is not in (0, {}]", settings.fps, crate::limits::MAX_FPS));
        }
        if settings.supersample == 0 || settings.supersample > 16 {
            return bad("supersample", format!("{} is not in 1..=16", settings.supersample));
        }
        if !(laser.sheet_sigma_m > 0.0) {
            return bad("sheet_sigma_m", format!("{} must be > 0", laser.sheet_sigma_m));
        }
        if !(settings.jitter_s >= 0.0 && settings.jitter_s < 0.5 / settings.fps) {
            return bad("jitter", format!("{} s must be in [0, half a frame period)", settings.jitter_s));
        }
        let r = &settings.realism;
        for (name, v) in [
            ("psf_sigma_px", r.psf_sigma_px),
            ("speckle_contrast", r.speckle_contrast),
            ("room_light_level", r.room_light_level),
            ("specular", r.specular),
            ("exposure_s", r.exposure_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, format!("{v} must be a finite value >= 0"));
            }
        }
        if r.psf_sigma_px > 8.0 || r.exposure_s >= 1.0 / settings.fps || !(r.shininess >= 1.0) {
            return bad("realism", "psf_sigma_px <= 8, exposure_s under a frame period, shininess >= 1".into());
        }
        let scene = match r.dark_albedo {
            Some(a) if (0.0..=1.0).contains(&a) => scene.with_dark_print(a),
            Some(a) => return bad("dark_albedo", format!("{a} is not in [0, 1]")),
            None => scene,
        };
        if let Err(e) = crate::rig::validate_lasers(&rig.lasers) {
            return bad("lasers", e);
        }
        let mut sheets = Vec::new();
        for l in rig.effective_lasers() {
            let Some(plane_carm) = Plane::from_params(l.plane) else {
                return bad("laser_plane", format!("{:?} is degenerate", l.plane));
            };
            let rgb = if rig.lasers.is_empty() { laser.rgb } else { laser.rgb_of(l.channel) };
            sheets.push(Sheet { plane_carm, source: Vec3::from_array(l.source), rgb });
        }
        let mut cams = Vec::new();
        for c in &rig.cameras {
            let model = c.model().map_err(|source| SynthError::Camera { name: c.name.clone(), source })?;
            let (w, h) = (model.width as usize, model.height as usize);
            let mut corners = Vec::with_capacity((w + 1) * (h + 1));
            for y in 0..=h {
                for x in 0..=w {
                    let (u, v) = (x as f64 - 0.5, y as f64 - 0.5);
                    // Undistortion fails only far outside any real lens' field: fall back to pinhole.
                    let r =
                        model.ray(u, v).unwrap_or(Vec3::new((u - model.cx) / model.fx, (v - model.cy) / model.fy, 1.0));
                    corners.push(r);
                }
            }
            cams.push(CamState { model, carm_from_optical: c.carm_from_optical(), corners });
        }
        Ok(Self { scene, rig, laser, settings, cams, sheets })
    }

    /// The number of lasers (sheets) rendered.
    pub fn lasers(&self) -> usize {
        self.sheets.len()
    }

    /// Index of the rig camera called `name`.
    pub fn camera_index(&self, name: &str) -> Option<usize> {
        self.rig.cameras.iter().position(|c| c.name == name)
    }

    /// Travel range of the scan, metres.
    pub fn travel_range(&self) -> (f64, f64) {
        (
            self.settings.travel_start_m.unwrap_or(self.scene.travel_start_m),
            self.settings.travel_end_m.unwrap_or(self.scene.travel_end_m),
        )
    }

    /// Number of frames per camera.
    pub fn frame_count(&self) -> u32 {
        let (a, b) = self.travel_range();
        (((b - a).abs() / self.settings.speed_mps * self.settings.fps).floor() as u32) + 1
    }

    /// Duration of the scan, seconds.
    pub fn duration_s(&self) -> f64 {
        f64::from(self.frame_count() - 1) / self.settings.fps
    }

    /// Travel at `t` seconds after the first nominal frame time (linear speed model).
    pub fn travel_at(&self, t_s: f64) -> f64 {
        let (a, b) = self.travel_range();
        a + (b - a).signum() * self.settings.speed_mps * t_s
    }

    /// `table -> carm` at `t` seconds after the start.
    pub fn pose_at(&self, t_s: f64) -> Iso3 {
        table_from_carm(self.travel_at(t_s), 0.0, 0.0)
    }

    /// Timing of frame `index` (jittered exposure; the same for every camera).
    pub fn frame_time(&self, index: u32) -> FrameTime {
        let mut rng = SplitMix::new(self.settings.seed ^ 0x6A09_E667 ^ (u64::from(index) << 32));
        let jitter = (rng.uniform() * 2.0 - 1.0) * self.settings.jitter_s;
        let t = f64::from(index) / self.settings.fps + jitter;
        let off = self.settings.laser_off_frames;
        FrameTime {
            index,
            stamp_ns: self.settings.start_stamp_ns + (t * 1e9).round() as i64,
            travel_m: self.travel_at(t),
            laser_on: index >= off && index + off < self.frame_count(),
        }
    }

    /// Seconds since the first nominal frame for a stamp.
    pub fn seconds_of(&self, stamp_ns: i64) -> f64 {
        (stamp_ns - self.settings.start_stamp_ns) as f64 * 1e-9
    }

    /// Renders camera `cam`'s image of frame `index`.
    pub fn render(&self, cam: usize, index: u32) -> Image {
        let ft = self.frame_time(index);
        self.render_at(cam, &table_from_carm(ft.travel_m, 0.0, 0.0), ft.laser_on, u64::from(index))
    }

    /// Renders camera `cam`'s image with the C-arm at `pose` (`table -> carm`); `frame_seed`
    /// varies the sensor noise (and the speckle) from frame to frame.
    pub fn render_at(&self, cam: usize, pose: &Iso3, laser_on: bool, frame_seed: u64) -> Image {
        let pose = *pose;
        let c = &self.cams[cam];
        let (w, h) = (c.model.width as usize, c.model.height as usize);
        let table_from_optical = pose.compose(&c.carm_from_optical);
        let realism = &self.settings.realism;
        let sheets = self
            .sheets
            .iter()
            .map(|sh| {
                let plane = sh.plane_carm.transformed(&pose);
                CtxSheet {
                    plane,
                    source: pose.transform_point(sh.source),
                    // The sheet moves along the travel (table Y) during the exposure: across
                    // the plane, its profile is the Gaussian convolved with a box of this
                    // half-width.
                    smear_m: 0.5 * self.settings.speed_mps * realism.exposure_s * plane.normal.y.abs(),
                }
            })
            .collect();
        let ctx = RenderCtx {
            scanner: self,
            origin: table_from_optical.translation,
            rot: table_from_optical,
            sheets,
            carm_from_table: pose.inverse(),
            laser_on,
            room_light: Vec3::new(0.2, -0.5, 1.0).try_normalize().unwrap_or(Vec3::Z),
        };
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(8);
        let rows_per = h.div_ceil(threads);
        // Pass 1: centre rays, signed distance of each hit from the laser sheet.
        let mut center = vec![Shade::default(); w * h];
        std::thread::scope(|s| {
            for (k, chunk) in center.chunks_mut(rows_per * w).enumerate() {
                let ctx = &ctx;
                s.spawn(move || {
                    for (i, px) in chunk.iter_mut().enumerate() {
                        let (x, y) = (i % w, k * rows_per + i / w);
                        *px = ctx.shade(c.ray_at(w, x as f64 + 0.5, y as f64 + 0.5)).compact();
                    }
                });
            }
        });
        // Pass 2: the light on each pixel, supersampled near the sheet, the laser's share
        // under speckle. The optics blur the room's light on the pixel grid, and the sheet's
        // image before the pixels integrate it (a discrete blur of a line thinner than a pixel
        // would keep it locked to its pixel): see `pixel_light`.
        let seed = self.settings.seed ^ ((cam as u64 + 1) << 48) ^ (frame_seed << 16);
        let mut ambient = vec![[0.0f64; 3]; w * h];
        let mut laser = vec![[0.0f64; 3]; w * h];
        std::thread::scope(|s| {
            for (k, (amb, las)) in ambient.chunks_mut(rows_per * w).zip(laser.chunks_mut(rows_per * w)).enumerate() {
                let (ctx, center) = (&ctx, &center);
                s.spawn(move || {
                    let mut rng = SplitMix::new(seed ^ 0x5DEE_CE66 ^ (k as u64).wrapping_mul(0x9E37_79B9));
                    for (i, (a, l)) in amb.iter_mut().zip(las.iter_mut()).enumerate() {
                        let (x, y) = (i % w, k * rows_per + i / w);
                        (*a, *l) = self.pixel_light(ctx, c, center, (x, y), &mut rng);
                    }
                });
            }
        });
        if realism.psf_sigma_px > 0.0 {
            blur(&mut ambient, w, h, realism.psf_sigma_px);
        }
        let light: Vec<[f64; 3]> =
            ambient.iter().zip(&laser).map(|(a, l)| [a[0] + l[0], a[1] + l[1], a[2] + l[2]]).collect();
        // Pass 3: sensor noise and quantisation.
        let enc = self.settings.encoding;
        let bpp = enc.bytes_per_pixel();
        let mut img = Image::new(w as u32, h as u32, enc);
        std::thread::scope(|s| {
            for (k, (chunk, light)) in
                img.data.chunks_mut(rows_per * w * bpp).zip(light.chunks(rows_per * w)).enumerate()
            {
                s.spawn(move || {
                    let mut rng = SplitMix::new(seed ^ (k as u64).wrapping_mul(0x9E37_79B9));
                    for (out, rgb) in chunk.chunks_mut(bpp).zip(light) {
                        write_pixel(out, enc, *rgb, &mut rng, self.settings.noise_sigma);
                    }
                });
            }
        });
        img
    }

    /// The light on pixel `(x, y)`, as (everything else, the laser): the centre ray's, or near
    /// the sheet the mean of sub-samples (at least `supersample` a side, more where the sheet's
    /// image is thin), the laser's share under speckle. The optics' blur of the sheet is in its
    /// profile: the sheet is widened by the point-spread function's width in metres across the
    /// plane (from the plane distance's change from pixel to pixel), its energy kept.
    fn pixel_light(
        &self,
        ctx: &RenderCtx<'_>,
        c: &CamState,
        center: &[Shade],
        (x, y): (usize, usize),
        rng: &mut SplitMix,
    ) -> ([f64; 3], [f64; 3]) {
        let (w, h) = (c.model.width as usize, c.model.height as usize);
        let s0 = center[y * w + x];
        if !ctx.laser_on {
            return (s0.rgb, [0.0; 3]);
        }
        let sigma = self.laser.sheet_sigma_m;
        // Per laser: its sheet widened by the optics, and whether it passes near this pixel.
        let mut sheet = [sigma; MAX_LASERS];
        let mut n = 0;
        for (k, sh) in ctx.sheets.iter().enumerate() {
            let d = |xx: usize, yy: usize| center[yy * w + xx].plane_dist[k];
            let d0 = s0.plane_dist[k];
            // The plane distance's change per pixel, from the smaller one-sided difference in
            // each direction (so that a depth edge beside the pixel does not count).
            let one_sided = |a: Option<f64>, b: Option<f64>| {
                [a, b]
                    .into_iter()
                    .flatten()
                    .map(|v| (v - d0).abs())
                    .filter(|v| v.is_finite())
                    .fold(f64::INFINITY, f64::min)
            };
            let gx = one_sided(x.checked_sub(1).map(|xx| d(xx, y)), (x + 1 < w).then(|| d(x + 1, y)));
            let gy = one_sided(y.checked_sub(1).map(|yy| d(x, yy)), (y + 1 < h).then(|| d(x, y + 1)));
            let g = [gx, gy].into_iter().filter(|v| v.is_finite()).map(|v| v * v).sum::<f64>().sqrt();
            sheet[k] = (sigma * sigma + (self.settings.realism.psf_sigma_px * g).powi(2)).sqrt();
            let sigma_eff = (sheet[k] * sheet[k] + sh.smear_m.powi(2) / 3.0).sqrt();
            let band = 4.0 * sigma_eff + sh.smear_m;
            let mut near = false;
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    let dv = d(xx, yy);
                    near |= dv.abs() < band || (dv.is_finite() && d0.is_finite() && dv.signum() != d0.signum());
                }
            }
            if near {
                // Sub-samples a side: four across the sheet's standard deviation in the image.
                n = n.max(((4.0 * g / sigma_eff).ceil() as usize).clamp(self.settings.supersample as usize, 16));
            }
        }
        if n == 0 {
            return (s0.rgb, s0.laser);
        }
        let mut ambient = [0.0; 3];
        let mut laser = [[0.0; 3]; MAX_LASERS];
        for sy in 0..n {
            for sx in 0..n {
                let (u, v) = (x as f64 + (sx as f64 + 0.5) / n as f64, y as f64 + (sy as f64 + 0.5) / n as f64);
                let s = ctx.shade_with(c.ray_at(w, u, v), &sheet);
                for k in 0..3 {
                    ambient[k] += s.rgb[k];
                    for (l, acc) in laser.iter_mut().enumerate().take(ctx.sheets.len()) {
                        acc[k] += s.laser[l][k];
                    }
                }
            }
        }
        let k = self.settings.realism.speckle_contrast;
        let speckle = if k > 0.0 { (1.0 + k * rng.normal()).max(0.0) } else { 1.0 };
        // Each widened sheet keeps its laser's energy.
        let mut total = [0.0; 3];
        for (l, light) in laser.iter().enumerate().take(ctx.sheets.len()) {
            let f = speckle * sigma / sheet[l] / (n * n) as f64;
            for c in 0..3 {
                total[c] += light[c] * f;
            }
        }
        (ambient.map(|a| a / (n * n) as f64), total)
    }

    /// Which way the laser line runs in camera `cam`'s images: `Vertical` (one sample per row)
    /// when the points the camera observes at a quarter, half and three quarters of the scan
    /// spread further down the image than across it, else `Horizontal` (one sample per column).
    /// What the camera's `edge_detector` needs as `line_orientation`.
    pub fn line_orientation(&self, cam: usize) -> Orientation {
        let Some(c) = self.cams.get(cam) else { return Orientation::Vertical };
        let n = self.frame_count();
        let (mut u, mut v) = ((f64::INFINITY, f64::NEG_INFINITY), (f64::INFINITY, f64::NEG_INFINITY));
        for index in [n / 4, n / 2, 3 * n / 4] {
            let pose = table_from_carm(self.frame_time(index).travel_m, 0.0, 0.0);
            let optical_from_table = pose.compose(&c.carm_from_optical).inverse();
            for p in self.observable_points(cam, index, 0.0) {
                if let Some((x, y)) = c.model.project(optical_from_table.transform_point(p)) {
                    (u, v) = ((u.0.min(x), u.1.max(x)), (v.0.min(y), v.1.max(y)));
                }
            }
        }
        // No point seen: the default, as the node's.
        if !(v.1 - v.0 < u.1 - u.0) {
            Orientation::Vertical
        } else {
            Orientation::Horizontal
        }
    }

    /// The points on the laser sheet that camera `cam` can observe in frame `index`, in `table`:
    /// lit by the source within the fan, in the image, not occluded, facing the camera and not
    /// grazing the plane by less than `min_ray_plane_angle_deg`. Sampled every ~0.5 mm.
    pub fn observable_points(&self, cam: usize, index: u32, min_ray_plane_angle_deg: f64) -> Vec<Vec3> {
        (0..self.sheets.len()).flat_map(|l| self.observable_points_of(cam, l, index, min_ray_plane_angle_deg)).collect()
    }

    /// The same for laser `laser` alone (an index into the rig's effective lasers).
    pub fn observable_points_of(
        &self,
        cam: usize,
        laser: usize,
        index: u32,
        min_ray_plane_angle_deg: f64,
    ) -> Vec<Vec3> {
        let Some(sheet) = self.sheets.get(laser) else { return Vec::new() };
        let ft = self.frame_time(index);
        if !ft.laser_on {
            return Vec::new();
        }
        let pose = table_from_carm(ft.travel_m, 0.0, 0.0);
        let c = &self.cams[cam];
        let table_from_optical = pose.compose(&c.carm_from_optical);
        let optical_from_table = table_from_optical.inverse();
        let eye = table_from_optical.translation;
        let src_c = sheet.source;
        let src = pose.transform_point(src_c);
        let n = sheet.plane_carm.normal;
        let Some(down) = (-Vec3::Z - n * (-Vec3::Z).dot(n)).try_normalize() else { return Vec::new() };
        let across = n.cross(down);
        let fan = self.laser.fan_half_angle_deg.to_radians();
        let step = 0.0005 / src_c.z.abs().max(0.1);
        let min_sin = min_ray_plane_angle_deg.to_radians().sin();
        let plane_t = sheet.plane_carm.transformed(&pose);
        let mut out = Vec::new();
        let mut a = -fan;
        while a <= fan {
            let dir = pose.transform_vector(down * a.cos() + across * a.sin());
            a += step;
            let Some(hit) = self.scene.intersect(src, dir, 1e-6, 10.0) else { continue };
            let p = src + dir * hit.t;
            if hit.normal.dot(-dir) < 0.05 {
                continue; // laser grazing the surface: no light reflected
            }
            let to_eye = eye - p;
            if hit.normal.dot(to_eye) <= 0.0 || self.scene.occluded(p, eye, 1e-6) {
                continue;
            }
            if (plane_t.normal.dot(to_eye) / to_eye.norm()).abs() < min_sin {
                continue;
            }
            let Some((u, v)) = c.model.project(optical_from_table.transform_point(p)) else { continue };
            if u < 1.0 || v < 1.0 || u > f64::from(c.model.width) - 2.0 || v > f64::from(c.model.height) - 2.0 {
                continue;
            }
            out.push(p);
        }
        out
    }
}

impl CamState {
    /// The optical-frame ray at pixel position (u, v) measured from the image's top-left corner
    /// (pixel centres at +0.5), interpolated from the corner table.
    fn ray_at(&self, w: usize, u: f64, v: f64) -> Vec3 {
        let (x0, y0) = (u.floor() as usize, v.floor() as usize);
        let (fx, fy) = (u - x0 as f64, v - y0 as f64);
        let stride = w + 1;
        let i = y0 * stride + x0;
        let r = |k: usize| self.corners[k.min(self.corners.len() - 1)];
        let top = r(i).lerp(r(i + 1), fx);
        let bottom = r(i + stride).lerp(r(i + stride + 1), fx);
        top.lerp(bottom, fy)
    }
}

/// A centre ray's light: what every sub-sample decision reads.
#[derive(Debug, Clone, Copy)]
struct Shade {
    /// Everything but the laser: ambient and room light, highlights.
    rgb: [f64; 3],
    /// The lasers' light.
    laser: [f64; 3],
    /// Signed distance from each laser's plane (NaN: no hit, or no such laser).
    plane_dist: [f64; MAX_LASERS],
}
impl Default for Shade {
    fn default() -> Self {
        Self { rgb: [0.0; 3], laser: [0.0; 3], plane_dist: [f64::NAN; MAX_LASERS] }
    }
}

/// One ray's light with each laser's apart.
#[derive(Debug, Clone, Copy)]
struct RayShade {
    rgb: [f64; 3],
    laser: [[f64; 3]; MAX_LASERS],
    plane_dist: [f64; MAX_LASERS],
}
impl Default for RayShade {
    fn default() -> Self {
        Self { rgb: [0.0; 3], laser: [[0.0; 3]; MAX_LASERS], plane_dist: [f64::NAN; MAX_LASERS] }
    }
}
impl RayShade {
    fn compact(&self) -> Shade {
        let mut laser = self.laser[0];
        for l in &self.laser[1..] {
            for k in 0..3 {
                laser[k] += l[k];
            }
        }
        Shade { rgb: self.rgb, laser, plane_dist: self.plane_dist }
    }
}

/// One laser's sheet in `table` for one frame.
struct CtxSheet {
    plane: Plane,
    source: Vec3,
    /// Half-width of the sheet's motion during the exposure, metres across the plane.
    smear_m: f64,
}

struct RenderCtx<'a> {
    scanner: &'a Scanner,
    origin: Vec3,
    rot: Iso3,
    sheets: Vec<CtxSheet>,
    carm_from_table: Iso3,
    laser_on: bool,
    /// Direction towards the room light, in `table`.
    room_light: Vec3,
}

impl RenderCtx<'_> {
    fn shade(&self, ray_optical: Vec3) -> RayShade {
        self.shade_with(ray_optical, &[self.scanner.laser.sheet_sigma_m; MAX_LASERS])
    }

    /// The shade with each sheet's standard deviation `sigma[k]` (metres, peak 1 on its plane).
    fn shade_with(&self, ray_optical: Vec3, sigma: &[f64; MAX_LASERS]) -> RayShade {
        let s = self.scanner;
        let dir = self.rot.transform_vector(ray_optical);
        let Some(hit) = s.scene.intersect(self.origin, dir, 1e-6, 20.0) else { return RayShade::default() };
        let p = self.origin + dir * hit.t;
        let obj = &s.scene.objects[hit.object];
        let albedo = s.scene.albedo(hit.object, p);
        let r = &s.settings.realism;
        let mut diffuse = s.settings.ambient_level * albedo * (0.45 + 0.55 * hit.normal.z.max(0.0));
        let mut gloss = 0.0;
        if r.room_light_level > 0.0 {
            let cos_l = hit.normal.dot(self.room_light).max(0.0);
            diffuse += r.room_light_level * albedo * cos_l;
            // Phong highlights on the objects (the tabletop is matte).
            if hit.object > 0 && r.specular > 0.0 && cos_l > 0.0 {
                let reflected = hit.normal * (2.0 * cos_l) - self.room_light;
                let to_eye = (-dir).try_normalize().unwrap_or(Vec3::Z);
                gloss = r.room_light_level * r.specular * reflected.dot(to_eye).max(0.0).powf(r.shininess);
            }
        }
        let mut out = RayShade::default();
        let lum = 0.299 * obj.color[0] + 0.587 * obj.color[1] + 0.114 * obj.color[2];
        for (k, sh) in self.sheets.iter().enumerate() {
            let plane_dist = sh.plane.signed_distance(p);
            out.plane_dist[k] = plane_dist;
            let mut laser = 0.0;
            if self.laser_on && plane_dist.abs() < 6.0 * sigma[k] + sh.smear_m {
                let to_src = sh.source - p;
                let cos_inc = hit.normal.dot(to_src) / to_src.norm();
                let v = self.carm_from_table.transform_vector(-to_src);
                let pc = s.sheets[k].plane_carm.normal;
                let in_plane = v - pc * v.dot(pc);
                let down = (-Vec3::Z - pc * (-Vec3::Z).dot(pc)).try_normalize().unwrap_or(-Vec3::Z);
                let within_fan = in_plane.dot(down) >= in_plane.norm() * s.laser.fan_half_angle_deg.to_radians().cos();
                if cos_inc > 0.0 && within_fan && !s.scene.occluded(p, sh.source, 1e-6) {
                    laser = s.laser.peak_level * albedo * cos_inc * sheet_profile(plane_dist, sigma[k], sh.smear_m);
                }
            }
            let rgb = s.sheets[k].rgb;
            out.laser[k] = if s.settings.encoding.is_color() {
                [0, 1, 2].map(|c| laser * rgb[c] * obj.color[c])
            } else {
                [laser * lum; 3]
            };
        }
        out.rgb = if s.settings.encoding.is_color() {
            [0, 1, 2].map(|k| diffuse * obj.color[k] + gloss)
        } else {
            [diffuse * lum + gloss; 3]
        };
        out
    }
}

/// The sheet's intensity at distance `d` from its plane (peak 1 without motion): a Gaussian of
/// standard deviation `sigma`, averaged over a box of half-width `smear` (its motion during the
/// exposure), which keeps its energy.
fn sheet_profile(d: f64, sigma: f64, smear: f64) -> f64 {
    if smear < 1e-3 * sigma {
        return (-0.5 * (d / sigma).powi(2)).exp();
    }
    let phi = |x: f64| 0.5 * (1.0 + erf(x / std::f64::consts::SQRT_2));
    sigma * (2.0 * std::f64::consts::PI).sqrt() / (2.0 * smear) * (phi((d + smear) / sigma) - phi((d - smear) / sigma))
}

/// The error function (Abramowitz and Stegun 7.1.26, absolute error under 1.5e-7).
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - ((((1.061_405_429 * t - 1.453_152_027) * t + 1.421_413_741) * t - 0.284_496_736) * t + 0.254_829_592)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

/// Gaussian blur of an RGB float image in place (separable, kernel to 3 sigma, edges clamped):
/// the optics' point-spread function.
fn blur(img: &mut [[f64; 3]], w: usize, h: usize, sigma: f64) {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f64> = (-r..=r).map(|i| (-0.5 * (i as f64 / sigma).powi(2)).exp()).collect();
    let sum: f64 = k.iter().sum();
    let k: Vec<f64> = k.iter().map(|v| v / sum).collect();
    let mut tmp = vec![[0.0f64; 3]; img.len()];
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0; 3];
            for (j, kv) in k.iter().enumerate() {
                let px = img[y * w + clamp(x as isize + j as isize - r, w)];
                for c in 0..3 {
                    acc[c] += kv * px[c];
                }
            }
            tmp[y * w + x] = acc;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0; 3];
            for (j, kv) in k.iter().enumerate() {
                let px = tmp[clamp(y as isize + j as isize - r, h) * w + x];
                for c in 0..3 {
                    acc[c] += kv * px[c];
                }
            }
            img[y * w + x] = acc;
        }
    }
}

fn write_pixel(out: &mut [u8], enc: Encoding, rgb: [f64; 3], rng: &mut SplitMix, noise: f64) {
    let q8 = |v: f64, rng: &mut SplitMix| (v + noise * rng.normal()).round().clamp(0.0, 255.0) as u8;
    match enc {
        Encoding::Mono8 => out[0] = q8(rgb[0], rng),
        Encoding::Mono16 => {
            let v = ((rgb[0] + noise * rng.normal()) * 257.0).round().clamp(0.0, 65535.0) as u16;
            out.copy_from_slice(&v.to_le_bytes());
        }
        Encoding::Rgb8 => {
            for k in 0..3 {
                out[k] = q8(rgb[k], rng);
            }
        }
        Encoding::Bgr8 => {
            for k in 0..3 {
                out[2 - k] = q8(rgb[k], rng);
            }
        }
    }
}
