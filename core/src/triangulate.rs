//! Laser-plane triangulation: a detected line sample -> a point in `table`.

use crate::camera::CameraModel;
use crate::edge::LaserLine;
use crate::geom::{Iso3, Plane, Vec3};

/// One camera's fixed geometry on the C-arm.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraGeometry {
    /// Intrinsics and distortion.
    pub model: CameraModel,
    /// `carm -> <cam>_optical_frame` (maps optical-frame points into `carm`).
    pub carm_from_optical: Iso3,
}

/// Configuration of the triangulator (parameters of the `triangulator` node).
#[derive(Debug, Clone, PartialEq)]
pub struct TriangulatorConfig {
    /// The laser plane in `carm`, `[nx, ny, nz, d]`.
    pub laser_plane: [f64; 4],
    /// Rays meeting the laser plane at less than this angle are rejected, degrees.
    pub min_ray_plane_angle_deg: f64,
    /// Samples weaker than this (grey levels) are dropped.
    pub min_strength: f32,
    /// Points below this height above the tabletop (`table` z, metres) are rejected: nothing
    /// under the tabletop can be seen, so such a point is a false detection.
    pub min_z_m: f64,
    /// Points above this height are rejected: the top of the measurement volume.
    pub max_z_m: f64,
}

impl Default for TriangulatorConfig {
    fn default() -> Self {
        Self {
            laser_plane: [0.0, 1.0, 0.0, 0.0],
            min_ray_plane_angle_deg: 10.0,
            min_strength: 0.0,
            min_z_m: -0.01,
            max_z_m: 0.6,
        }
    }
}

/// Why the triangulator cannot be set up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TriangulateError {
    /// The laser plane parameter is degenerate.
    #[error("laser_plane {0:?} is not a plane (zero or non-finite normal)")]
    BadPlane([f64; 4]),
    /// The camera lies on the laser plane: every ray grazes it.
    #[error("camera centre lies {distance_m} m from the laser plane: no triangulation baseline")]
    CameraOnPlane {
        /// Distance of the optical centre from the plane.
        distance_m: f64,
    },
    /// The intrinsics are unusable.
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    /// The angle limit is out of range.
    #[error("min_ray_plane_angle_deg {0} must be in [0, 90)")]
    BadAngle(f64),
}

/// One frame's triangulated points: the algorithm side of a `/<cam>/profile` cloud.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Profile {
    /// Points in `table`, NaN where no point (one per line sample).
    pub points: Vec<[f32; 3]>,
    /// Laser strength per point (grey levels), 0 where none.
    pub intensity: Vec<f32>,
    /// Samples rejected because their point fell outside the measurement volume.
    pub outside_volume: u32,
    /// Surface colour per point, 0x00RRGGBB; `None` for grey images.
    pub rgb: Option<Vec<u32>>,
    /// Distance from the camera centre per point (m), NaN where none.
    pub range: Vec<f32>,
}

impl Profile {
    /// Number of finite points.
    pub fn valid(&self) -> usize {
        self.points.iter().filter(|p| p[0].is_finite()).count()
    }
}

/// Intersects camera rays with the laser plane.
#[derive(Debug, Clone)]
pub struct Triangulator {
    camera: CameraGeometry,
    plane_optical: Plane,
    min_sin: f64,
    min_strength: f32,
    z_range: (f64, f64),
}

impl Triangulator {
    /// Sets up a triangulator for one camera.
    pub fn new(camera: CameraGeometry, config: &TriangulatorConfig) -> Result<Self, TriangulateError> {
        camera.model.validate()?;
        let plane_carm =
            Plane::from_params(config.laser_plane).ok_or(TriangulateError::BadPlane(config.laser_plane))?;
        if !(0.0..90.0).contains(&config.min_ray_plane_angle_deg) {
            return Err(TriangulateError::BadAngle(config.min_ray_plane_angle_deg));
        }
        let plane_optical = plane_carm.transformed(&camera.carm_from_optical.inverse());
        if plane_optical.d.abs() < 1e-6 {
            return Err(TriangulateError::CameraOnPlane { distance_m: plane_optical.d.abs() });
        }
        Ok(Self {
            camera,
            plane_optical,
            min_sin: config.min_ray_plane_angle_deg.to_radians().sin(),
            min_strength: config.min_strength,
            z_range: (config.min_z_m, config.max_z_m),
        })
    }

    /// The laser plane in the camera's optical frame.
    pub fn plane_optical(&self) -> Plane {
        self.plane_optical
    }

    /// The camera's geometry.
    pub fn camera(&self) -> &CameraGeometry {
        &self.camera
    }

    /// The point in the optical frame seen at pixel `(u, v)` on the laser plane, or `None`
    /// (no ray, plane behind the camera, or a grazing ray).
    pub fn point_optical(&self, u: f64, v: f64) -> Option<Vec3> {
        let r = self.camera.model.ray(u, v)?;
        let n = self.plane_optical.normal;
        let nr = n.dot(r);
        let len = r.norm();
        if (nr / len).abs() < self.min_sin {
            return None;
        }
        let t = self.plane_optical.d / nr;
        (t > 0.0).then(|| r * t)
    }

    /// Triangulates a whole line with `table -> carm` at the image's stamp.
    pub fn triangulate(&self, line: &LaserLine, table_from_carm: &Iso3, out: &mut Profile) {
        let n = line.len();
        out.points.clear();
        out.points.resize(n, [f32::NAN; 3]);
        out.intensity.clear();
        out.intensity.resize(n, 0.0);
        out.range.clear();
        out.range.resize(n, f32::NAN);
        let color = line.rgb.len() == 3 * n && n > 0;
        out.rgb = color.then(|| vec![0u32; n]);
        let table_from_optical = table_from_carm.compose(&self.camera.carm_from_optical);
        out.outside_volume = 0;
        for i in 0..n {
            let (u, v) = (line.u[i], line.v[i]);
            if !(u.is_finite() && v.is_finite()) || line.strength[i] < self.min_strength {
                continue;
            }
            let Some(p) = self.point_optical(f64::from(u), f64::from(v)) else { continue };
            let q = table_from_optical.transform_point(p);
            if q.z < self.z_range.0 || q.z > self.z_range.1 {
                out.outside_volume += 1;
                continue;
            }
            out.points[i] = [q.x as f32, q.y as f32, q.z as f32];
            out.intensity[i] = line.strength[i];
            out.range[i] = p.norm() as f32;
            if let Some(rgb) = out.rgb.as_mut() {
                let c = &line.rgb[3 * i..3 * i + 3];
                rgb[i] = (u32::from(c[0]) << 16) | (u32::from(c[1]) << 8) | u32::from(c[2]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Distortion;
    use crate::pose::table_from_carm;
    use proptest::prelude::*;

    fn geometry() -> CameraGeometry {
        CameraGeometry {
            model: CameraModel {
                width: 640,
                height: 480,
                fx: 700.0,
                fy: 700.0,
                cx: 320.0,
                cy: 240.0,
                distortion: Distortion::PlumbBob { k1: -0.12, k2: 0.05, p1: 0.0005, p2: -0.0003, k3: 0.0 },
            },
            carm_from_optical: Iso3::look_at(Vec3::new(-0.25, -0.4, 0.8), Vec3::new(0.0, 0.0, 0.05), Vec3::X).unwrap(),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..ProptestConfig::default() })]
        #[test]
        fn project_then_triangulate_returns_the_point(x in -0.2f64..0.2, z in 0.0f64..0.3, travel in -1.0f64..2.0) {
            let g = geometry();
            let tri = Triangulator::new(g.clone(), &TriangulatorConfig::default()).unwrap();
            let pose = table_from_carm(travel, 0.0, 0.0);
            // A point on the laser plane (y = 0 in carm), in table.
            let p_carm = Vec3::new(x, 0.0, z);
            let p_table = pose.transform_point(p_carm);
            let p_opt = g.carm_from_optical.inverse().transform_point(p_carm);
            let (u, v) = g.model.project(p_opt).unwrap();
            let line = LaserLine { u: vec![u as f32], v: vec![v as f32], strength: vec![100.0], width: vec![3.0], ..Default::default() };
            // f32 pixels limit precision; go through the f64 path for the 1e-6 m property.
            let q = pose.compose(&g.carm_from_optical).transform_point(tri.point_optical(u, v).unwrap());
            prop_assert!((q - p_table).norm() < 1e-6, "{:?} vs {:?}", q, p_table);
            let mut prof = Profile::default();
            tri.triangulate(&line, &pose, &mut prof);
            let r = prof.points[0];
            let err = (Vec3::new(r[0].into(), r[1].into(), r[2].into()) - p_table).norm();
            prop_assert!(err < 1e-4, "f32 path error {}", err);
        }
    }

    #[test]
    fn points_outside_the_measurement_volume_are_rejected() {
        let g = geometry();
        let tri = Triangulator::new(g.clone(), &TriangulatorConfig { max_z_m: 0.1, ..Default::default() }).unwrap();
        let pose = table_from_carm(0.0, 0.0, 0.0);
        let mut line = LaserLine::default();
        for z in [0.05, 0.2, -0.05] {
            let p_opt = g.carm_from_optical.inverse().transform_point(Vec3::new(0.0, 0.0, z));
            let (u, v) = g.model.project(p_opt).unwrap();
            line.u.push(u as f32);
            line.v.push(v as f32);
            line.strength.push(50.0);
            line.width.push(3.0);
        }
        let mut prof = Profile::default();
        tri.triangulate(&line, &pose, &mut prof);
        assert!(prof.points[0][0].is_finite());
        assert!(prof.points[1][0].is_nan() && prof.points[2][0].is_nan());
        assert_eq!(prof.outside_volume, 2);
    }

    #[test]
    fn grazing_rays_and_bad_planes_are_rejected() {
        let g = geometry();
        assert!(matches!(
            Triangulator::new(g.clone(), &TriangulatorConfig { laser_plane: [0.0; 4], ..Default::default() }),
            Err(TriangulateError::BadPlane(_))
        ));
        // A plane through the camera centre.
        let c = g.carm_from_optical.translation;
        let plane = [0.0, 1.0, 0.0, c.y];
        assert!(matches!(
            Triangulator::new(g.clone(), &TriangulatorConfig { laser_plane: plane, ..Default::default() }),
            Err(TriangulateError::CameraOnPlane { .. })
        ));
        let strict =
            Triangulator::new(g, &TriangulatorConfig { min_ray_plane_angle_deg: 80.0, ..Default::default() }).unwrap();
        assert!(strict.point_optical(320.0, 240.0).is_none());
    }
}
