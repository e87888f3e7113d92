//! Synthetic calibration sets with known truth: a checkerboard seen at varied poses (for the
//! intrinsics), lying on the tabletop (for the placement), and the laser line on the bare
//! tabletop at several heights (for the laser plane; rendered by the [`Scanner`](super::Scanner)).

use super::SplitMix;
use crate::calib::board::BoardSpec;
use crate::camera::CameraModel;
use crate::geom::{Iso3, Mat3, Vec3};
use crate::image::{Encoding, Image};

/// How the printed board looks.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardLook {
    /// White border around the squares, in squares.
    pub margin_squares: f64,
    /// Albedo of the black squares.
    pub black: f64,
    /// Albedo of the white squares and border.
    pub white: f64,
    /// Albedo of the surface around the board (in the board's plane).
    pub background: f64,
    /// Off the board, instead of that surface, a cluttered room behind it (see [`wall_albedo`]):
    /// a second checkerboard on a screen, a striped shirt and patches of every grey.
    pub clutter: bool,
}

impl Default for BoardLook {
    fn default() -> Self {
        Self { margin_squares: 0.75, black: 0.05, white: 0.85, background: 0.4, clutter: false }
    }
}

impl BoardLook {
    /// The hard set's look: a narrow border, and clutter behind the board.
    pub fn hard() -> Self {
        Self { margin_squares: 0.35, clutter: true, ..Self::default() }
    }
}

/// Distance of the cluttered wall from the camera, metres (along the optical axis).
pub const WALL_Z: f64 = 1.3;

/// The cluttered wall's albedo at `(x, y)` (optical frame, metres, at z = [`WALL_Z`]): a
/// screen showing a second checkerboard (7x5 inner corners, 45 mm squares, a dark bezel) to
/// the right of the axis, horizontal stripes (12 mm) on the left, and 60 mm patches of random
/// grey elsewhere.
pub fn wall_albedo(x: f64, y: f64) -> f64 {
    const SQ: f64 = 0.045;
    let (x0, y0) = (0.12, -0.30);
    let (a, b) = ((x - x0) / SQ, (y - y0) / SQ);
    if (-0.5..8.5).contains(&a) && (-0.5..6.5).contains(&b) {
        if (0.0..8.0).contains(&a) && (0.0..6.0).contains(&b) {
            return if (a.floor() as i64 + b.floor() as i64) % 2 == 0 { 0.08 } else { 0.75 };
        }
        return 0.1; // bezel
    }
    if x < -0.15 {
        return if (y / 0.012).floor().rem_euclid(2.0) == 0.0 { 0.25 } else { 0.7 };
    }
    let cell =
        ((x / 0.06).floor() as i64).wrapping_mul(73_856_093) ^ ((y / 0.06).floor() as i64).wrapping_mul(19_349_663);
    let h = SplitMix::new(cell as u64).uniform();
    0.15 + 0.65 * h
}

/// Light, optics and sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct Exposure {
    /// Grey level of a white surface at the image centre.
    pub level: f64,
    /// Fall-off of the light towards the image corners (0: none, 0.3: corners at 70 %).
    pub vignetting: f64,
    /// Sensor noise, grey levels (standard deviation).
    pub noise_sigma: f64,
    /// Optical blur (Gaussian sigma), pixels; 0 for a focused lens.
    pub blur_px: f64,
    /// Sub-samples per pixel side.
    pub supersample: u32,
    /// Uneven light, 0 to 1: the light falls to `1 - uneven / 2` towards the image's left edge,
    /// and a soft shadow across the lower right dims it by the same factor again.
    pub uneven: f64,
}

impl Default for Exposure {
    fn default() -> Self {
        Self { level: 215.0, vignetting: 0.25, noise_sigma: 2.0, blur_px: 0.0, supersample: 4, uneven: 0.0 }
    }
}

impl Exposure {
    /// The hard set's light: uneven (a gradient and a shadow, down to a quarter of the light),
    /// a slightly soft lens, and more sensor noise.
    pub fn hard() -> Self {
        Self { uneven: 1.0, blur_px: 0.7, noise_sigma: 3.0, ..Self::default() }
    }
    /// The light's factor at pixel `(x, y)` of a `w x h` image from the gradient and the shadow.
    fn uneven_at(&self, x: f64, y: f64, w: f64, h: f64) -> f64 {
        if self.uneven <= 0.0 {
            return 1.0;
        }
        let k = 0.5 * self.uneven;
        let gradient = 1.0 - k * (1.0 - x / w);
        // The shadow's edge runs from (0.35 w, h) to (w, 0.45 h); soft over about 8 pixels.
        let (ax, ay, bx, by) = (0.35 * w, h, w, 0.45 * h);
        let side = ((bx - ax) * (y - ay) - (by - ay) * (x - ax)) / (bx - ax).hypot(by - ay);
        let s = (0.5 + side / 16.0).clamp(0.0, 1.0);
        let shade = 1.0 - k * s * s * (3.0 - 2.0 * s);
        gradient * shade
    }
}

/// Undistorted rays at pixel corners, interpolated for sub-samples (one undistortion per
/// pixel corner instead of one per sample).
pub struct RayTable {
    model: CameraModel,
    rays: Vec<Vec3>,
}

impl RayTable {
    /// The table of a camera.
    pub fn new(model: &CameraModel) -> RayTable {
        let (w, h) = (model.width as usize, model.height as usize);
        let mut rays = Vec::with_capacity((w + 1) * (h + 1));
        for y in 0..=h {
            for x in 0..=w {
                let (u, v) = (x as f64 - 0.5, y as f64 - 0.5);
                rays.push(model.ray(u, v).unwrap_or(Vec3::new(
                    (u - model.cx) / model.fx,
                    (v - model.cy) / model.fy,
                    1.0,
                )));
            }
        }
        RayTable { model: *model, rays }
    }
    /// The ray at pixel position `(u, v)` (ROS convention), z = 1.
    pub fn ray(&self, u: f64, v: f64) -> Vec3 {
        let w = self.model.width as usize;
        let (gx, gy) = (u + 0.5, v + 0.5);
        let (x0, y0) = (gx.floor().max(0.0) as usize, gy.floor().max(0.0) as usize);
        let (x0, y0) = (x0.min(w - 1), y0.min(self.model.height as usize - 1));
        let (fx, fy) = (gx - x0 as f64, gy - y0 as f64);
        let s = w + 1;
        let i = y0 * s + x0;
        let top = self.rays[i].lerp(self.rays[i + 1], fx);
        let bottom = self.rays[i + s].lerp(self.rays[i + s + 1], fx);
        top.lerp(bottom, fy)
    }
}

/// The board's albedo at `(x, y)` in its frame; None off the printed board.
fn board_albedo(spec: &BoardSpec, look: &BoardLook, x: f64, y: f64) -> Option<f64> {
    let s = spec.square_m;
    let (a, b) = ((x / s).floor(), (y / s).floor());
    let inside_squares = a >= -1.0 && b >= -1.0 && a <= spec.cols as f64 - 1.0 && b <= spec.rows as f64 - 1.0;
    if inside_squares {
        return Some(if BoardSpec::square_is_black(a as i64, b as i64) { look.black } else { look.white });
    }
    let m = (1.0 + look.margin_squares) * s;
    let on_board = x >= -m && y >= -m && x <= (spec.cols as f64 - 1.0) * s + m && y <= (spec.rows as f64 - 1.0) * s + m;
    on_board.then_some(look.white)
}

/// Renders the board at `optical_from_board` (mono8).
pub fn render_board(
    rays: &RayTable,
    optical_from_board: &Iso3,
    spec: &BoardSpec,
    look: &BoardLook,
    exposure: &Exposure,
    seed: u64,
) -> Image {
    let m = &rays.model;
    let (w, h) = (m.width as usize, m.height as usize);
    let n = exposure.supersample.max(1) as usize;
    let normal = optical_from_board.rotation.column(2);
    let origin = optical_from_board.translation;
    let board_from_optical = optical_from_board.inverse();
    let mut lin = vec![0.0f64; w * h];
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(8);
    let rows_per = h.div_ceil(threads);
    std::thread::scope(|scope| {
        for (k, chunk) in lin.chunks_mut(rows_per * w).enumerate() {
            let (board_from_optical, normal) = (&board_from_optical, normal);
            scope.spawn(move || {
                for (i, out) in chunk.iter_mut().enumerate() {
                    let (x, y) = (i % w, k * rows_per + i / w);
                    let mut acc = 0.0;
                    for sy in 0..n {
                        for sx in 0..n {
                            let u = x as f64 + (sx as f64 + 0.5) / n as f64 - 0.5;
                            let v = y as f64 + (sy as f64 + 0.5) / n as f64 - 0.5;
                            let d = rays.ray(u, v);
                            let den = normal.dot(d);
                            let t = if den.abs() > 1e-12 { normal.dot(origin) / den } else { -1.0 };
                            let albedo = if t > 0.0 {
                                let p = board_from_optical.transform_point(d * t);
                                board_albedo(spec, look, p.x, p.y)
                            } else {
                                None
                            };
                            acc += albedo.unwrap_or_else(|| {
                                if look.clutter {
                                    wall_albedo(d.x / d.z * WALL_Z, d.y / d.z * WALL_Z)
                                } else {
                                    look.background
                                }
                            });
                        }
                    }
                    let (dx, dy) = ((x as f64 - m.cx) / w as f64, (y as f64 - m.cy) / h as f64);
                    let light = exposure.level
                        * (1.0 - exposure.vignetting * 2.0 * (dx * dx + dy * dy))
                        * exposure.uneven_at(x as f64, y as f64, w as f64, h as f64);
                    *out = light * acc / (n * n) as f64;
                }
            });
        }
    });
    if exposure.blur_px > 0.0 {
        lin = crate::image::gaussian_blur(&lin, w, h, exposure.blur_px);
    }
    let mut rng = SplitMix::new(seed ^ 0xB0A4_D000);
    let mut img = Image::new(w as u32, h as u32, Encoding::Mono8);
    for (o, v) in img.data.iter_mut().zip(&lin) {
        *o = (v + exposure.noise_sigma * rng.normal()).round().clamp(0.0, 255.0) as u8;
    }
    img
}

/// The board's printed area (squares plus half the border) as four corners in the board frame.
fn outline(spec: &BoardSpec, look: &BoardLook) -> [Vec3; 4] {
    let s = spec.square_m;
    let m = (1.0 + 0.5 * look.margin_squares) * s;
    let (x1, y1) = ((spec.cols as f64 - 1.0) * s + m, (spec.rows as f64 - 1.0) * s + m);
    [Vec3::new(-m, -m, 0.0), Vec3::new(x1, -m, 0.0), Vec3::new(x1, y1, 0.0), Vec3::new(-m, y1, 0.0)]
}

/// Whether the board's squares lie inside the image with `margin_px` to spare.
pub fn board_in_view(model: &CameraModel, optical_from_board: &Iso3, spec: &BoardSpec, margin_px: f64) -> bool {
    outline(spec, &BoardLook { margin_squares: 0.0, ..BoardLook::default() }).iter().all(|&p| {
        model.project(optical_from_board.transform_point(p)).is_some_and(|(u, v)| {
            u >= margin_px
                && v >= margin_px
                && u <= f64::from(model.width) - 1.0 - margin_px
                && v <= f64::from(model.height) - 1.0 - margin_px
        })
    })
}

/// `count` varied board poses (`optical <- board`) for an intrinsics set: 0.45-0.85 m away,
/// tilted 10-40 degrees, turned up to 20 degrees, spread over the image, every square in view.
pub fn board_views(model: &CameraModel, spec: &BoardSpec, count: usize, seed: u64) -> Vec<Iso3> {
    let mut rng = SplitMix::new(seed ^ 0x5EED_CA1B);
    let centre =
        Vec3::new((spec.cols as f64 - 1.0) * 0.5 * spec.square_m, (spec.rows as f64 - 1.0) * 0.5 * spec.square_m, 0.0);
    let mut out = Vec::new();
    let mut tries = 0;
    while out.len() < count && tries < 100_000 {
        tries += 1;
        let i = out.len();
        let sign = |r: &mut SplitMix| if r.uniform() < 0.5 { -1.0 } else { 1.0 };
        let tilt = (20.0 + 25.0 * rng.uniform()).to_radians() * sign(&mut rng);
        let other = (20.0 * rng.uniform()).to_radians() * sign(&mut rng);
        let (ax, ay) = if i % 2 == 0 { (tilt, other) } else { (other, tilt) };
        let az = (40.0 * rng.uniform() - 20.0).to_radians();
        let rotation = Mat3::rot_x(ax).mul_mat(&Mat3::rot_y(ay)).mul_mat(&Mat3::rot_z(az));
        let dist = 0.35 + 0.3 * rng.uniform();
        let (u, v) = (
            f64::from(model.width) * (0.2 + 0.6 * rng.uniform()),
            f64::from(model.height) * (0.2 + 0.6 * rng.uniform()),
        );
        let Some(ray) = model.ray(u, v) else { continue };
        let translation = ray * dist - rotation.mul_vec(centre);
        let pose = Iso3 { rotation, translation };
        if board_in_view(model, &pose, spec, 6.0) {
            out.push(pose);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::board::detect;
    use crate::rig::Rig;

    #[test]
    fn rendered_board_is_found_where_it_projects() {
        let model = Rig::study(640, 480).cameras[0].model().unwrap();
        let spec = BoardSpec::parse("9x6", 0.03).unwrap();
        let rays = RayTable::new(&model);
        let mut worst = 0.0f64;
        let mut sum2 = 0.0;
        let mut n = 0;
        for (i, pose) in board_views(&model, &spec, 6, 3).iter().enumerate() {
            let img = render_board(&rays, pose, &spec, &BoardLook::default(), &Exposure::default(), i as u64);
            let c = detect(&img.view().unwrap(), &spec).unwrap_or_else(|e| panic!("view {i}: {e}"));
            for (k, p) in c.points.iter().enumerate() {
                let (u, v) = model.project(pose.transform_point(spec.point(k))).unwrap();
                let e = ((p[0] - u).powi(2) + (p[1] - v).powi(2)).sqrt();
                worst = worst.max(e);
                sum2 += e * e;
                n += 1;
            }
        }
        let rms = (sum2 / f64::from(n)).sqrt();
        eprintln!("corner error rms {rms:.3} px, max {worst:.3} px over {n} corners");
        assert!(rms < 0.08 && worst < 0.3, "rms {rms} max {worst}");
    }
}
