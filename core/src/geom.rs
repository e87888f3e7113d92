//! Small, dependency-free 3D geometry: vectors, rotations, rigid transforms and planes.
//!
//! Only what the scanner needs, in `f64`. Degenerate inputs are handled with
//! [`Vec3::try_normalize`] rather than producing NaNs.

use serde::{Deserialize, Serialize};
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

/// A 3D vector or point, metres unless said otherwise.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vec3 {
    /// X component.
    pub x: f64,
    /// Y component.
    pub y: f64,
    /// Z component.
    pub z: f64,
}

impl Vec3 {
    /// The zero vector.
    pub const ZERO: Vec3 = Vec3::new(0.0, 0.0, 0.0);
    /// Unit X.
    pub const X: Vec3 = Vec3::new(1.0, 0.0, 0.0);
    /// Unit Y.
    pub const Y: Vec3 = Vec3::new(0.0, 1.0, 0.0);
    /// Unit Z.
    pub const Z: Vec3 = Vec3::new(0.0, 0.0, 1.0);

    /// A vector from its components.
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }
    /// From an array `[x, y, z]`.
    pub const fn from_array(a: [f64; 3]) -> Self {
        Self::new(a[0], a[1], a[2])
    }
    /// As an array `[x, y, z]`.
    pub const fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
    /// Dot product.
    pub fn dot(self, o: Vec3) -> f64 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Cross product.
    pub fn cross(self, o: Vec3) -> Vec3 {
        Vec3::new(self.y * o.z - self.z * o.y, self.z * o.x - self.x * o.z, self.x * o.y - self.y * o.x)
    }
    /// Euclidean length.
    pub fn norm(self) -> f64 {
        self.dot(self).sqrt()
    }
    /// Squared length.
    pub fn norm_squared(self) -> f64 {
        self.dot(self)
    }
    /// Unit vector in the same direction, or `None` for a (near) zero or non-finite vector.
    pub fn try_normalize(self) -> Option<Vec3> {
        let n = self.norm();
        (n > 1e-300 && n.is_finite()).then(|| self / n)
    }
    /// Component-wise minimum.
    pub fn min(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x.min(o.x), self.y.min(o.y), self.z.min(o.z))
    }
    /// Component-wise maximum.
    pub fn max(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x.max(o.x), self.y.max(o.y), self.z.max(o.z))
    }
    /// Component-wise absolute value.
    pub fn abs(self) -> Vec3 {
        Vec3::new(self.x.abs(), self.y.abs(), self.z.abs())
    }
    /// True when every component is finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
    /// Linear interpolation `self + (o - self) * t`.
    pub fn lerp(self, o: Vec3, t: f64) -> Vec3 {
        self + (o - self) * t
    }
}

impl Add for Vec3 {
    type Output = Vec3;
    fn add(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl AddAssign for Vec3 {
    fn add_assign(&mut self, o: Vec3) {
        *self = *self + o;
    }
}
impl Sub for Vec3 {
    type Output = Vec3;
    fn sub(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl Mul<f64> for Vec3 {
    type Output = Vec3;
    fn mul(self, s: f64) -> Vec3 {
        Vec3::new(self.x * s, self.y * s, self.z * s)
    }
}
impl Div<f64> for Vec3 {
    type Output = Vec3;
    fn div(self, s: f64) -> Vec3 {
        Vec3::new(self.x / s, self.y / s, self.z / s)
    }
}
impl Neg for Vec3 {
    type Output = Vec3;
    fn neg(self) -> Vec3 {
        Vec3::new(-self.x, -self.y, -self.z)
    }
}

/// A unit quaternion (x, y, z, w), the ROS `geometry_msgs/Quaternion` convention.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quat {
    /// X (vector part).
    pub x: f64,
    /// Y (vector part).
    pub y: f64,
    /// Z (vector part).
    pub z: f64,
    /// W (scalar part).
    pub w: f64,
}

impl Default for Quat {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Quat {
    /// No rotation.
    pub const IDENTITY: Quat = Quat { x: 0.0, y: 0.0, z: 0.0, w: 1.0 };

    /// Rotation of `angle_rad` about a unit `axis`.
    pub fn from_axis_angle(axis: Vec3, angle_rad: f64) -> Quat {
        let (s, c) = (angle_rad * 0.5).sin_cos();
        Quat { x: axis.x * s, y: axis.y * s, z: axis.z * s, w: c }
    }
    /// This quaternion scaled to unit length; identity when degenerate.
    pub fn normalized(self) -> Quat {
        let n = (self.x * self.x + self.y * self.y + self.z * self.z + self.w * self.w).sqrt();
        if n > 1e-300 && n.is_finite() {
            Quat { x: self.x / n, y: self.y / n, z: self.z / n, w: self.w / n }
        } else {
            Quat::IDENTITY
        }
    }
    /// The rotation matrix of this (unit) quaternion.
    pub fn to_mat3(self) -> Mat3 {
        let Quat { x, y, z, w } = self.normalized();
        Mat3 {
            m: [
                [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
                [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
                [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
            ],
        }
    }
}

/// A 3x3 matrix, row-major.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mat3 {
    /// Rows.
    pub m: [[f64; 3]; 3],
}

impl Mat3 {
    /// The identity matrix.
    pub const IDENTITY: Mat3 = Mat3 { m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] };

    /// A matrix whose columns are `a`, `b`, `c`.
    pub fn from_columns(a: Vec3, b: Vec3, c: Vec3) -> Mat3 {
        Mat3 { m: [[a.x, b.x, c.x], [a.y, b.y, c.y], [a.z, b.z, c.z]] }
    }
    /// Rotation about Y by `angle_rad`.
    pub fn rot_y(angle_rad: f64) -> Mat3 {
        let (s, c) = angle_rad.sin_cos();
        Mat3 { m: [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]] }
    }
    /// Rotation about X by `angle_rad`.
    pub fn rot_x(angle_rad: f64) -> Mat3 {
        let (s, c) = angle_rad.sin_cos();
        Mat3 { m: [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]] }
    }
    /// Rotation about Z by `angle_rad`.
    pub fn rot_z(angle_rad: f64) -> Mat3 {
        let (s, c) = angle_rad.sin_cos();
        Mat3 { m: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]] }
    }
    /// The rotation by `|v|` radians about `v` (Rodrigues' formula).
    pub fn from_rotation_vector(v: Vec3) -> Mat3 {
        let angle = v.norm();
        match v.try_normalize() {
            Some(axis) if angle > 1e-300 => Quat::from_axis_angle(axis, angle).to_mat3(),
            _ => Mat3::IDENTITY,
        }
    }
    /// The angle of the rotation that takes `self` to `o` (both rotations), radians.
    pub fn angle_to(&self, o: &Mat3) -> f64 {
        let r = self.transpose().mul_mat(o);
        let tr = r.m[0][0] + r.m[1][1] + r.m[2][2];
        ((tr - 1.0) * 0.5).clamp(-1.0, 1.0).acos()
    }
    /// Column `i`.
    pub fn column(&self, i: usize) -> Vec3 {
        Vec3::new(self.m[0][i], self.m[1][i], self.m[2][i])
    }
    /// Transpose (the inverse of a rotation).
    pub fn transpose(&self) -> Mat3 {
        let m = &self.m;
        Mat3 { m: [[m[0][0], m[1][0], m[2][0]], [m[0][1], m[1][1], m[2][1]], [m[0][2], m[1][2], m[2][2]]] }
    }
    /// Matrix times vector.
    pub fn mul_vec(&self, v: Vec3) -> Vec3 {
        let m = &self.m;
        Vec3::new(
            m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
            m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
        )
    }
    /// Matrix product `self * o`.
    pub fn mul_mat(&self, o: &Mat3) -> Mat3 {
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, cell) in row.iter_mut().enumerate() {
                *cell = (0..3).map(|k| self.m[i][k] * o.m[k][j]).sum();
            }
        }
        Mat3 { m: r }
    }
    /// The unit quaternion of this rotation matrix.
    pub fn to_quat(&self) -> Quat {
        let m = &self.m;
        let tr = m[0][0] + m[1][1] + m[2][2];
        let q = if tr > 0.0 {
            let s = (tr + 1.0).sqrt() * 2.0;
            Quat { w: 0.25 * s, x: (m[2][1] - m[1][2]) / s, y: (m[0][2] - m[2][0]) / s, z: (m[1][0] - m[0][1]) / s }
        } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
            let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
            Quat { w: (m[2][1] - m[1][2]) / s, x: 0.25 * s, y: (m[0][1] + m[1][0]) / s, z: (m[0][2] + m[2][0]) / s }
        } else if m[1][1] > m[2][2] {
            let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
            Quat { w: (m[0][2] - m[2][0]) / s, x: (m[0][1] + m[1][0]) / s, y: 0.25 * s, z: (m[1][2] + m[2][1]) / s }
        } else {
            let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
            Quat { w: (m[1][0] - m[0][1]) / s, x: (m[0][2] + m[2][0]) / s, y: (m[1][2] + m[2][1]) / s, z: 0.25 * s }
        };
        q.normalized()
    }
}

/// A rigid transform `parent <- child`: `p_parent = rotation * p_child + translation`.
///
/// This is the meaning of a ROS `TransformStamped` from `header.frame_id` (parent) to
/// `child_frame_id` (child).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Iso3 {
    /// Rotation part.
    pub rotation: Mat3,
    /// Translation part, metres.
    pub translation: Vec3,
}

impl Default for Iso3 {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Iso3 {
    /// The identity transform.
    pub const IDENTITY: Iso3 = Iso3 { rotation: Mat3::IDENTITY, translation: Vec3::ZERO };

    /// From a translation and a quaternion.
    pub fn from_parts(translation: Vec3, rotation: Quat) -> Iso3 {
        Iso3 { rotation: rotation.to_mat3(), translation }
    }
    /// Maps a point from the child frame into the parent frame.
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation.mul_vec(p) + self.translation
    }
    /// Rotates a direction from the child frame into the parent frame.
    pub fn transform_vector(&self, v: Vec3) -> Vec3 {
        self.rotation.mul_vec(v)
    }
    /// The inverse transform (`child <- parent`).
    pub fn inverse(&self) -> Iso3 {
        let rt = self.rotation.transpose();
        Iso3 { rotation: rt, translation: -rt.mul_vec(self.translation) }
    }
    /// Composition `self * o`: first `o`, then `self`.
    pub fn compose(&self, o: &Iso3) -> Iso3 {
        Iso3 { rotation: self.rotation.mul_mat(&o.rotation), translation: self.transform_point(o.translation) }
    }
    /// The rotation as a quaternion.
    pub fn quaternion(&self) -> Quat {
        self.rotation.to_quat()
    }
    /// A camera pose (`parent <- optical`) at `eye` looking at `target`, with the image's
    /// down axis (optical +y) as close as possible to `down_hint`.
    ///
    /// Returns `None` when `eye == target` or `down_hint` is parallel to the view direction.
    pub fn look_at(eye: Vec3, target: Vec3, down_hint: Vec3) -> Option<Iso3> {
        let z = (target - eye).try_normalize()?;
        let y = (down_hint - z * down_hint.dot(z)).try_normalize()?;
        let x = y.cross(z);
        Some(Iso3 { rotation: Mat3::from_columns(x, y, z), translation: eye })
    }
}

/// A plane `{p : normal · p = d}` with a unit normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal.
    pub normal: Vec3,
    /// Offset: the signed distance of the plane from the origin along `normal`.
    pub d: f64,
}

impl Plane {
    /// From the spec's parameter layout `[nx, ny, nz, d]`; the normal is normalised (and `d`
    /// scaled with it). `None` when the normal is zero or any value is not finite.
    pub fn from_params(p: [f64; 4]) -> Option<Plane> {
        let n = Vec3::new(p[0], p[1], p[2]);
        let len = n.norm();
        if !(len > 1e-12) || !p[3].is_finite() || !len.is_finite() {
            return None;
        }
        Some(Plane { normal: n / len, d: p[3] / len })
    }
    /// As the parameter layout `[nx, ny, nz, d]`.
    pub fn to_params(self) -> [f64; 4] {
        [self.normal.x, self.normal.y, self.normal.z, self.d]
    }
    /// Signed distance of `p` from the plane.
    pub fn signed_distance(&self, p: Vec3) -> f64 {
        self.normal.dot(p) - self.d
    }
    /// This plane expressed in the parent frame of `t` (the plane is given in `t`'s child frame).
    pub fn transformed(&self, t: &Iso3) -> Plane {
        let n = t.transform_vector(self.normal);
        Plane { normal: n, d: self.d + n.dot(t.translation) }
    }
}

/// Solves the 3x3 linear system `a x = b` by Cramer's rule; `None` when (nearly) singular.
pub fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&a);
    if !d.is_finite() || d.abs() < 1e-18 {
        return None;
    }
    let mut out = [0.0; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        *o = det(&m) / d;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solve3_solves_and_refuses_singular() {
        let x = solve3([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]], [3.0, 5.0, 5.0]).unwrap();
        assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12 && (x[2] - 1.0).abs() < 1e-12);
        assert!(solve3([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]], [1.0, 2.0, 3.0]).is_none());
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).norm() < 1e-12
    }

    #[test]
    fn quaternion_round_trip() {
        let q = Quat::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).try_normalize().unwrap(), 0.7);
        let q2 = q.to_mat3().to_quat();
        let same = (q.x - q2.x).abs() + (q.y - q2.y).abs() + (q.z - q2.z).abs() + (q.w - q2.w).abs();
        let opposite = (q.x + q2.x).abs() + (q.y + q2.y).abs() + (q.z + q2.z).abs() + (q.w + q2.w).abs();
        assert!(same.min(opposite) < 1e-12);
    }

    #[test]
    fn inverse_composes_to_identity() {
        let t = Iso3::from_parts(Vec3::new(0.1, -0.2, 0.3), Quat::from_axis_angle(Vec3::Z, 0.4));
        let p = Vec3::new(1.0, 2.0, 3.0);
        assert!(close(t.inverse().transform_point(t.transform_point(p)), p));
        assert!(close(t.compose(&t.inverse()).transform_point(p), p));
    }

    #[test]
    fn look_at_points_z_at_target_and_y_down_hint() {
        let t = Iso3::look_at(Vec3::new(0.0, -1.0, 1.0), Vec3::ZERO, Vec3::X).unwrap();
        let z = t.rotation.column(2);
        assert!(close(z, Vec3::new(0.0, 1.0, -1.0) / 2f64.sqrt()));
        assert!(close(t.rotation.column(1), Vec3::X));
        assert!(Iso3::look_at(Vec3::ZERO, Vec3::ZERO, Vec3::X).is_none());
    }

    #[test]
    fn plane_transform_keeps_points_on_it() {
        let plane = Plane::from_params([0.0, 2.0, 0.0, 0.2]).unwrap();
        assert!((plane.d - 0.1).abs() < 1e-15);
        let t = Iso3::from_parts(Vec3::new(0.3, 0.5, -0.1), Quat::from_axis_angle(Vec3::X, 0.3));
        let p_child = Vec3::new(0.4, 0.1, 7.0);
        assert!(plane.signed_distance(p_child).abs() < 1e-15);
        let moved = plane.transformed(&t);
        assert!(moved.signed_distance(t.transform_point(p_child)).abs() < 1e-12);
        assert!(Plane::from_params([0.0, 0.0, 0.0, 1.0]).is_none());
    }
}
