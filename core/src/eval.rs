//! Accuracy against ground truth: distance of reconstructed points from the true surface,
//! coverage of the observable truth, and the pyramid's measured extents.

use crate::geom::{solve3, Vec3};
use crate::synth::scene::{pyramid_faces, Scene, Shape};
use std::collections::HashMap;

/// Error statistics of a reconstruction against the true surface.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Accuracy {
    /// Points evaluated.
    pub points: usize,
    /// Root-mean-square distance from the true surface, metres.
    pub rms_m: f64,
    /// 99th percentile of the distance, metres.
    pub p99_m: f64,
    /// Largest distance, metres.
    pub max_m: f64,
    /// Fraction of points farther than 2 mm.
    pub outlier_fraction_2mm: f64,
}

/// Distances of `points` from the scene's true surface.
pub fn surface_errors(scene: &Scene, points: &[[f32; 3]]) -> Vec<f64> {
    points
        .iter()
        .filter(|p| p[0].is_finite())
        .map(|p| scene.signed_distance(Vec3::new(p[0].into(), p[1].into(), p[2].into())).abs())
        .collect()
}

/// Statistics of a set of distances.
pub fn accuracy(mut errors: Vec<f64>) -> Accuracy {
    if errors.is_empty() {
        return Accuracy::default();
    }
    errors.sort_by(f64::total_cmp);
    let n = errors.len();
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
    Accuracy {
        points: n,
        rms_m: rms,
        p99_m: errors[((n as f64 * 0.99) as usize).min(n - 1)],
        max_m: errors[n - 1],
        outlier_fraction_2mm: errors.iter().filter(|&&e| e > 0.002).count() as f64 / n as f64,
    }
}

/// A uniform hash grid over points, for radius queries.
pub struct PointHash {
    cell: f64,
    map: HashMap<(i32, i32, i32), Vec<Vec3>>,
}

impl PointHash {
    /// Buckets `points` (NaNs skipped) into cells of `cell` metres.
    pub fn new(points: impl IntoIterator<Item = Vec3>, cell: f64) -> Self {
        let mut map: HashMap<(i32, i32, i32), Vec<Vec3>> = HashMap::new();
        for p in points.into_iter().filter(|p| p.is_finite()) {
            map.entry(Self::key(p, cell)).or_default().push(p);
        }
        Self { cell, map }
    }
    fn key(p: Vec3, cell: f64) -> (i32, i32, i32) {
        ((p.x / cell).floor() as i32, (p.y / cell).floor() as i32, (p.z / cell).floor() as i32)
    }
    /// True if a point lies within `radius` (<= cell) of `p`.
    pub fn any_within(&self, p: Vec3, radius: f64) -> bool {
        let (kx, ky, kz) = Self::key(p, self.cell);
        let r2 = radius * radius;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(v) = self.map.get(&(kx + dx, ky + dy, kz + dz)) {
                        if v.iter().any(|q| (*q - p).norm_squared() <= r2) {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }
}

/// Fraction of `truth` points with a reconstructed point within `radius`.
pub fn coverage(truth: &[Vec3], reconstructed: &[[f32; 3]], radius: f64) -> f64 {
    if truth.is_empty() {
        return 0.0;
    }
    let hash = PointHash::new(reconstructed.iter().map(|p| Vec3::new(p[0].into(), p[1].into(), p[2].into())), radius);
    truth.iter().filter(|t| hash.any_within(**t, radius)).count() as f64 / truth.len() as f64
}

/// Fraction of `truth` points within about `radius` of the surface of `mesh` (its triangles,
/// not only its vertices): each triangle is sampled at most `radius / 2` apart. A gap between
/// triangles wider than `2 * radius` leaves the truth points in it uncovered; the distance is
/// approximate to `radius / 4`.
pub fn mesh_coverage(truth: &[Vec3], mesh: &crate::mesh::Mesh, radius: f64) -> f64 {
    if truth.is_empty() {
        return 0.0;
    }
    let v = |a: [f32; 3]| Vec3::new(a[0].into(), a[1].into(), a[2].into());
    let step = radius / 2.0;
    let mut samples = Vec::new();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| v(mesh.positions[i as usize]));
        let longest = (b - a).norm().max((c - b).norm()).max((a - c).norm());
        let n = (longest / step).ceil().max(1.0) as usize;
        for i in 0..=n {
            for j in 0..=n - i {
                let (u, w) = (i as f64 / n as f64, j as f64 / n as f64);
                samples.push(a + (b - a) * u + (c - a) * w);
            }
        }
    }
    let hash = PointHash::new(samples, radius);
    truth.iter().filter(|t| hash.any_within(**t, radius)).count() as f64 / truth.len() as f64
}

/// A pyramid's size measured from points: each face plane fitted by least squares, the base
/// from the planes' intersections with the tabletop, the height from opposite faces meeting.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PyramidExtents {
    /// Base across X, metres.
    pub base_x_m: f64,
    /// Base along Y, metres.
    pub base_y_m: f64,
    /// Height, metres.
    pub height_m: f64,
}

/// Measures the scene's pyramid from reconstructed points. Points are assigned to the nearest
/// true face (segmentation only); the planes are fitted to the points alone. `None` when the
/// scene has no pyramid or a face has too few points.
pub fn pyramid_extents(scene: &Scene, points: &[[f32; 3]]) -> Option<PyramidExtents> {
    let (center, bx, by, h) = scene.objects.iter().find_map(|o| match o.shape {
        Shape::Pyramid { center, base_x, base_y, height } => Some((center, base_x, base_y, height)),
        _ => None,
    })?;
    let faces = pyramid_faces(center, bx, by, h);
    // Normal equations for z = a x + b y + c per face, in coordinates relative to the centre.
    let mut ata = [[[0.0f64; 3]; 3]; 4];
    let mut atb = [[0.0f64; 3]; 4];
    let mut count = [0usize; 4];
    for p in points.iter().filter(|p| p[0].is_finite()) {
        let q = Vec3::new(p[0].into(), p[1].into(), p[2].into());
        if q.z < 0.008 || q.z > h - 0.008 {
            continue;
        }
        let (k, _) = faces
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let n = (f[1] - f[0]).cross(f[2] - f[0]).try_normalize().unwrap_or(Vec3::Z);
                (k, n.dot(q - f[0]).abs())
            })
            .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        let r = [q.x - center.x, q.y - center.y, 1.0];
        for i in 0..3 {
            for j in 0..3 {
                ata[k][i][j] += r[i] * r[j];
            }
            atb[k][i] += r[i] * q.z;
        }
        count[k] += 1;
    }
    if count.iter().any(|&c| c < 20) {
        return None;
    }
    let mut planes = [[0.0; 3]; 4];
    for k in 0..4 {
        planes[k] = solve3(ata[k], atb[k])?;
    }
    // Faces: 0 = -Y, 1 = +X, 2 = +Y, 3 = -X (see pyramid_faces).
    let [ny, px, py, nx] = planes;
    let x_at_zero = |p: [f64; 3]| -p[2] / p[0]; // along y = 0
    let y_at_zero = |p: [f64; 3]| -p[2] / p[1]; // along x = 0
    let base_x = x_at_zero(px) - x_at_zero(nx);
    let base_y = y_at_zero(py) - y_at_zero(ny);
    // Apex: where opposite faces meet above the centre line.
    let hx = {
        let x = (nx[2] - px[2]) / (px[0] - nx[0]);
        px[0] * x + px[2]
    };
    let hy = {
        let y = (ny[2] - py[2]) / (py[1] - ny[1]);
        py[1] * y + py[2]
    };
    Some(PyramidExtents { base_x_m: base_x, base_y_m: base_y, height_m: 0.5 * (hx + hy) })
}

/// A sphere fitted to points: centre, radius and RMS radial residual (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereFit {
    /// Centre.
    pub center: Vec3,
    /// Radius.
    pub radius: f64,
    /// RMS of |p - center| - radius.
    pub rms_m: f64,
}

/// Least-squares sphere through `points` (algebraic fit: |p|^2 = 2 c.p + k, centred to drop
/// k); `None` for fewer than 4 points or a degenerate (planar) set.
pub fn fit_sphere(points: &[Vec3]) -> Option<SphereFit> {
    if points.len() < 4 {
        return None;
    }
    let n = points.len() as f64;
    let mean = points.iter().fold(Vec3::ZERO, |a, &p| a + p) / n;
    let q: Vec<(Vec3, f64)> = points.iter().map(|&p| (p - mean, (p - mean).norm_squared())).collect();
    let mean_sq = q.iter().map(|x| x.1).sum::<f64>() / n;
    let (mut a, mut b) = ([[0.0; 3]; 3], [0.0; 3]);
    for (d, s) in &q {
        let v = [d.x, d.y, d.z];
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] += 2.0 * v[i] * v[j];
            }
            b[i] += v[i] * (s - mean_sq);
        }
    }
    let c = solve3(a, b)?;
    let center = mean + Vec3::new(c[0], c[1], c[2]);
    let radius = (points.iter().map(|&p| (p - center).norm_squared()).sum::<f64>() / n).sqrt();
    let rms_m = (points.iter().map(|&p| ((p - center).norm() - radius).powi(2)).sum::<f64>() / n).sqrt();
    Some(SphereFit { center, radius, rms_m })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_fit_recovers_a_cap() {
        // A cap (upper third) of a sphere, as the cameras see one resting on the table.
        let c = Vec3::new(0.06, -0.01, 0.08);
        let mut pts = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (th, ph) = (0.05 * f64::from(i), std::f64::consts::TAU * f64::from(j) / 40.0);
                pts.push(c + Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * 0.08);
            }
        }
        let f = fit_sphere(&pts).unwrap();
        assert!((f.center - c).norm() < 1e-9 && (f.radius - 0.08).abs() < 1e-9 && f.rms_m < 1e-9, "{f:?}");
        assert!(fit_sphere(&pts[..3]).is_none());
    }

    #[test]
    fn exact_pyramid_points_measure_exact_extents() {
        let scene = Scene::by_name("pyramid").unwrap();
        let faces = pyramid_faces(Vec3::ZERO, 0.21, 0.297, 0.086);
        let mut pts = Vec::new();
        for f in &faces {
            for i in 0..30 {
                for j in 0..30 - i {
                    let (u, v) = (i as f64 / 30.0, j as f64 / 30.0);
                    let p = f[0] + (f[1] - f[0]) * u + (f[2] - f[0]) * v;
                    pts.push([p.x as f32, p.y as f32, p.z as f32]);
                }
            }
        }
        let e = pyramid_extents(&scene, &pts).unwrap();
        assert!(
            (e.base_x_m - 0.21).abs() < 1e-5 && (e.base_y_m - 0.297).abs() < 1e-5 && (e.height_m - 0.086).abs() < 1e-5,
            "{e:?}"
        );
        let acc = accuracy(surface_errors(&scene, &pts));
        assert!(acc.rms_m < 1e-6);
        // Lifted by 3 mm: the errors say so.
        let lifted: Vec<_> = pts.iter().map(|p| [p[0], p[1], p[2] + 0.003]).collect();
        assert!(accuracy(surface_errors(&scene, &lifted)).rms_m > 0.002);
    }

    #[test]
    fn coverage_counts_truth_near_points() {
        let truth = vec![Vec3::ZERO, Vec3::new(0.01, 0.0, 0.0)];
        assert_eq!(coverage(&truth, &[[0.0, 0.0, 0.002]], 0.003), 0.5);
        assert_eq!(coverage(&truth, &[], 0.003), 0.0);
    }
}
