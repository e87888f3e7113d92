//! The synthetic scanner: renders the camera images of a scan of an analytic scene and knows
//! the truth (the surface's signed distance and the points each camera can observe on the
//! laser sheet). Deterministic for a seed.

pub mod calib;
pub mod scene;
pub mod xray;

use crate::camera::CameraModel;
use crate::geom::{Iso3, Plane, Vec3};
use crate::image::{Encoding, Image};
use crate::pose::table_from_carm;
use crate::rig::Rig;
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
    plane_carm: Plane,
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
        if !(settings.speed_mps > 0.0 && settings.speed_mps < 10.0) {
            return bad("speed", format!("{} m/s is not in (0, 10)", settings.speed_mps));
        }
        if !(settings.fps > 0.0 && settings.fps <= 1000.0) {
            return bad("fps", format!("{} is not in (0, 1000]", settings.fps));
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
        let Some(plane_carm) = Plane::from_params(rig.laser_plane) else {
            return bad("laser_plane", format!("{:?} is degenerate", rig.laser_plane));
        };
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
        Ok(Self { scene, rig, laser, settings, cams, plane_carm })
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
    /// varies the sensor noise from frame to frame.
    pub fn render_at(&self, cam: usize, pose: &Iso3, laser_on: bool, frame_seed: u64) -> Image {
        let pose = *pose;
        let c = &self.cams[cam];
        let (w, h) = (c.model.width as usize, c.model.height as usize);
        let table_from_optical = pose.compose(&c.carm_from_optical);
        let ctx = RenderCtx {
            scanner: self,
            origin: table_from_optical.translation,
            rot: table_from_optical,
            plane: self.plane_carm.transformed(&pose),
            source: pose.transform_point(Vec3::from_array(self.rig.laser_source)),
            carm_from_table: pose.inverse(),
            laser_on,
        };
        // Pass 1: centre rays, signed distance of each hit from the laser sheet.
        let mut center = vec![Shade::default(); w * h];
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(8);
        let rows_per = h.div_ceil(threads);
        std::thread::scope(|s| {
            for (k, chunk) in center.chunks_mut(rows_per * w).enumerate() {
                let ctx = &ctx;
                s.spawn(move || {
                    for (i, px) in chunk.iter_mut().enumerate() {
                        let (x, y) = (i % w, k * rows_per + i / w);
                        *px = ctx.shade(c.ray_at(w, x as f64 + 0.5, y as f64 + 0.5));
                    }
                });
            }
        });
        // Pass 2: supersample pixels near the sheet, add noise, quantise.
        let enc = self.settings.encoding;
        let bpp = enc.bytes_per_pixel();
        let mut img = Image::new(w as u32, h as u32, enc);
        let band = 4.0 * self.laser.sheet_sigma_m;
        let n = self.settings.supersample as usize;
        let seed = self.settings.seed ^ ((cam as u64 + 1) << 48) ^ (frame_seed << 16);
        std::thread::scope(|s| {
            for (k, chunk) in img.data.chunks_mut(rows_per * w * bpp).enumerate() {
                let (ctx, center) = (&ctx, &center);
                s.spawn(move || {
                    let mut rng = SplitMix::new(seed ^ (k as u64).wrapping_mul(0x9E37_79B9));
                    for (i, out) in chunk.chunks_mut(bpp).enumerate() {
                        let (x, y) = (i % w, k * rows_per + i / w);
                        let near = ctx.laser_on && {
                            let mut near = false;
                            let d0 = center[y * w + x].plane_dist;
                            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                                    let d = center[yy * w + xx].plane_dist;
                                    near |= d.abs() < band
                                        || (d.is_finite() && d0.is_finite() && d.signum() != d0.signum());
                                }
                            }
                            near
                        };
                        let rgb = if near {
                            let mut acc = [0.0; 3];
                            for sy in 0..n {
                                for sx in 0..n {
                                    let (u, v) = (
                                        x as f64 + (sx as f64 + 0.5) / n as f64,
                                        y as f64 + (sy as f64 + 0.5) / n as f64,
                                    );
                                    let s = ctx.shade(c.ray_at(w, u, v));
                                    for (a, v) in acc.iter_mut().zip(s.rgb) {
                                        *a += v;
                                    }
                                }
                            }
                            acc.map(|a| a / (n * n) as f64)
                        } else {
                            center[y * w + x].rgb
                        };
                        write_pixel(out, enc, rgb, &mut rng, self.settings.noise_sigma);
                    }
                });
            }
        });
        img
    }

    /// The points on the laser sheet that camera `cam` can observe in frame `index`, in `table`:
    /// lit by the source within the fan, in the image, not occluded, facing the camera and not
    /// grazing the plane by less than `min_ray_plane_angle_deg`. Sampled every ~0.5 mm.
    pub fn observable_points(&self, cam: usize, index: u32, min_ray_plane_angle_deg: f64) -> Vec<Vec3> {
        let ft = self.frame_time(index);
        if !ft.laser_on {
            return Vec::new();
        }
        let pose = table_from_carm(ft.travel_m, 0.0, 0.0);
        let c = &self.cams[cam];
        let table_from_optical = pose.compose(&c.carm_from_optical);
        let optical_from_table = table_from_optical.inverse();
        let eye = table_from_optical.translation;
        let src_c = Vec3::from_array(self.rig.laser_source);
        let src = pose.transform_point(src_c);
        let n = self.plane_carm.normal;
        let Some(down) = (-Vec3::Z - n * (-Vec3::Z).dot(n)).try_normalize() else { return Vec::new() };
        let across = n.cross(down);
        let fan = self.laser.fan_half_angle_deg.to_radians();
        let step = 0.0005 / src_c.z.abs().max(0.1);
        let min_sin = min_ray_plane_angle_deg.to_radians().sin();
        let plane_t = self.plane_carm.transformed(&pose);
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

#[derive(Debug, Clone, Copy)]
struct Shade {
    rgb: [f64; 3],
    plane_dist: f64,
}
impl Default for Shade {
    fn default() -> Self {
        Self { rgb: [0.0; 3], plane_dist: f64::NAN }
    }
}

struct RenderCtx<'a> {
    scanner: &'a Scanner,
    origin: Vec3,
    rot: Iso3,
    plane: Plane,
    source: Vec3,
    carm_from_table: Iso3,
    laser_on: bool,
}

impl RenderCtx<'_> {
    fn shade(&self, ray_optical: Vec3) -> Shade {
        let s = self.scanner;
        let dir = self.rot.transform_vector(ray_optical);
        let Some(hit) = s.scene.intersect(self.origin, dir, 1e-6, 20.0) else { return Shade::default() };
        let p = self.origin + dir * hit.t;
        let obj = &s.scene.objects[hit.object];
        let albedo = s.scene.albedo(hit.object, p);
        let plane_dist = self.plane.signed_distance(p);
        let shade_amb = s.settings.ambient_level * albedo * (0.45 + 0.55 * hit.normal.z.max(0.0));
        let mut laser = 0.0;
        let sigma = s.laser.sheet_sigma_m;
        if self.laser_on && plane_dist.abs() < 6.0 * sigma {
            let to_src = self.source - p;
            let cos_inc = hit.normal.dot(to_src) / to_src.norm();
            let v = self.carm_from_table.transform_vector(-to_src);
            let pc = s.plane_carm.normal;
            let in_plane = v - pc * v.dot(pc);
            let down = (-Vec3::Z - pc * (-Vec3::Z).dot(pc)).try_normalize().unwrap_or(-Vec3::Z);
            let within_fan = in_plane.dot(down) >= in_plane.norm() * s.laser.fan_half_angle_deg.to_radians().cos();
            if cos_inc > 0.0 && within_fan && !s.scene.occluded(p, self.source, 1e-6) {
                laser = s.laser.peak_level * albedo * cos_inc * (-0.5 * (plane_dist / sigma).powi(2)).exp();
            }
        }
        let rgb = if s.settings.encoding.is_color() {
            [0, 1, 2].map(|k| (shade_amb + laser * s.laser.rgb[k]) * obj.color[k])
        } else {
            let lum = 0.299 * obj.color[0] + 0.587 * obj.color[1] + 0.114 * obj.color[2];
            [(shade_amb + laser) * lum; 3]
        };
        Shade { rgb, plane_dist }
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
