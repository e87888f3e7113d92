//! Analytic scenes on a bounded tabletop: exact ray intersection and signed distance.

use crate::geom::Vec3;

/// A solid.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// The tabletop: the half-space z <= 0 inside `|x| <= half_x`, `y_min <= y <= y_max`.
    Table {
        /// Half width across the table (X), metres.
        half_x: f64,
        /// Start along Y, metres.
        y_min: f64,
        /// End along Y, metres.
        y_max: f64,
    },
    /// A rectangular pyramid standing on the table, apex above the base centre.
    Pyramid {
        /// Base centre (z = 0).
        center: Vec3,
        /// Base size across X, metres.
        base_x: f64,
        /// Base size along Y, metres.
        base_y: f64,
        /// Height, metres.
        height: f64,
    },
    /// An axis-aligned box.
    Cuboid {
        /// Centre.
        center: Vec3,
        /// Half sizes.
        half: Vec3,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f64,
    },
    /// A capped cylinder with its axis along Y.
    CylinderY {
        /// Axis position across X.
        x: f64,
        /// Axis height.
        z: f64,
        /// Radius.
        radius: f64,
        /// Start along Y.
        y_min: f64,
        /// End along Y.
        y_max: f64,
    },
    /// An axis-aligned ellipsoid.
    Ellipsoid {
        /// Centre.
        center: Vec3,
        /// Semi-axes.
        radii: Vec3,
    },
}

/// A printed band of different reflectance on an object: `y_min <= y <= y_max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// Start along Y.
    pub y_min: f64,
    /// End along Y.
    pub y_max: f64,
    /// Reflectance inside the band.
    pub albedo: f64,
}

/// A shape with its surface properties.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// Geometry.
    pub shape: Shape,
    /// Diffuse reflectance (0..1).
    pub albedo: f64,
    /// Surface colour (linear RGB, 0..1), used by colour cameras.
    pub color: [f64; 3],
    /// Optional printed band.
    pub band: Option<Band>,
    /// Linear X-ray attenuation, 1/m, added to whatever else the ray crosses at the same place
    /// (an object inside another adds its excess over the outer one: bone in soft tissue).
    pub mu_per_m: f64,
    /// Hidden inside another object: seen by X-rays only, never by a camera or the laser.
    pub internal: bool,
}

/// A ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter (distance for a unit direction).
    pub t: f64,
    /// Outward unit normal.
    pub normal: Vec3,
    /// Index of the object hit.
    pub object: usize,
}

/// A named set of objects and the travel range that scans it.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Scene name (`pyramid`, `phantom`, ...).
    pub name: String,
    /// Objects, the tabletop first.
    pub objects: Vec<Object>,
    /// C-arm travel at the start of a scan, metres.
    pub travel_start_m: f64,
    /// C-arm travel at the end of a scan, metres.
    pub travel_end_m: f64,
}

/// Names accepted by [`Scene::by_name`].
pub const SCENE_NAMES: [&str; 6] = ["pyramid", "phantom", "sphere", "cylinder", "box", "body"];

const WHITE: [f64; 3] = [0.92, 0.92, 0.9];
const EPS: f64 = 1e-9;

/// Attenuation of soft tissue (water at about 70 keV), 1/m.
pub const MU_TISSUE: f64 = 20.0;
/// Excess attenuation of bone over soft tissue, 1/m.
pub const MU_BONE_EXCESS: f64 = 30.0;
/// Attenuation of the tabletop (carbon fibre sandwich), 1/m.
const MU_TABLE: f64 = 4.0;
/// Thickness of the tabletop for X-rays, metres.
pub const TABLE_THICKNESS_M: f64 = 0.02;

fn table(y_min: f64, y_max: f64) -> Object {
    Object {
        shape: Shape::Table { half_x: 0.35, y_min, y_max },
        albedo: 0.85,
        color: WHITE,
        band: None,
        mu_per_m: MU_TABLE,
        internal: false,
    }
}

impl Scene {
    /// A scene by name, or `None` (see [`SCENE_NAMES`]).
    // Over 80 lines: the catalogue of the scenes, one definition of objects each, read best as one
    // table (splitting it would scatter the scenes, not simplify them).
    #[allow(clippy::too_many_lines)]
    pub fn by_name(name: &str) -> Option<Scene> {
        let obj =
            |shape, albedo, color| Object { shape, albedo, color, band: None, mu_per_m: MU_TISSUE, internal: false };
        let bone = |shape| Object {
            shape,
            albedo: 0.0,
            color: [0.0; 3],
            band: None,
            mu_per_m: MU_BONE_EXCESS,
            internal: true,
        };
        let (objects, start, end) = match name {
            // The study's calibration pyramid: base 210 x 297 mm, 86 mm high.
            "pyramid" => (
                vec![obj(
                    Shape::Pyramid { center: Vec3::ZERO, base_x: 0.210, base_y: 0.297, height: 0.086 },
                    0.75,
                    [0.85, 0.8, 0.7],
                )],
                -0.18,
                0.18,
            ),
            // Off the beam's centre, so that the fan beam's magnification across the table matters.
            "sphere" => (
                vec![obj(Shape::Sphere { center: Vec3::new(0.06, 0.0, 0.08), radius: 0.08 }, 0.7, [0.7, 0.75, 0.85])],
                -0.12,
                0.12,
            ),
            "cylinder" => (
                vec![obj(
                    Shape::CylinderY { x: 0.0, z: 0.06, radius: 0.06, y_min: -0.15, y_max: 0.15 },
                    0.7,
                    [0.8, 0.8, 0.6],
                )],
                -0.2,
                0.2,
            ),
            "box" | "phantom" => {
                let mut v = vec![Object {
                    shape: Shape::Cuboid { center: Vec3::new(-0.06, 0.0, 0.04), half: Vec3::new(0.05, 0.09, 0.04) },
                    albedo: 0.7,
                    color: [0.85, 0.85, 0.8],
                    band: Some(Band { y_min: -0.02, y_max: 0.02, albedo: 0.12 }),
                    mu_per_m: MU_TISSUE,
                    internal: false,
                }];
                if name == "phantom" {
                    v.push(obj(
                        Shape::Sphere { center: Vec3::new(0.09, -0.05, 0.05), radius: 0.05 },
                        0.7,
                        [0.75, 0.8, 0.9],
                    ));
                    v.push(obj(
                        Shape::CylinderY { x: 0.1, z: 0.035, radius: 0.035, y_min: 0.02, y_max: 0.14 },
                        0.7,
                        [0.9, 0.75, 0.6],
                    ));
                }
                (v, -0.15, 0.19)
            }
            // A crude supine body: head, neck, torso, arms, legs (ellipsoids resting on the table).
            "body" => {
                let skin = [0.88, 0.68, 0.56];
                let e = |c: [f64; 3], r: [f64; 3]| {
                    obj(Shape::Ellipsoid { center: Vec3::from_array(c), radii: Vec3::from_array(r) }, 0.6, skin)
                };
                (
                    vec![
                        e([0.0, 0.10, 0.09], [0.075, 0.10, 0.09]),
                        e([0.0, 0.22, 0.05], [0.05, 0.05, 0.05]),
                        e([0.0, 0.52, 0.10], [0.17, 0.28, 0.10]),
                        e([-0.21, 0.55, 0.045], [0.045, 0.30, 0.045]),
                        e([0.21, 0.55, 0.045], [0.045, 0.30, 0.045]),
                        e([-0.08, 1.15, 0.065], [0.07, 0.40, 0.065]),
                        e([0.08, 1.15, 0.065], [0.07, 0.40, 0.065]),
                        // Bones, for the radiograph: skull, spine, humeri, femurs.
                        bone(Shape::Ellipsoid {
                            center: Vec3::new(0.0, 0.10, 0.09),
                            radii: Vec3::new(0.065, 0.09, 0.08),
                        }),
                        bone(Shape::CylinderY { x: 0.0, z: 0.06, radius: 0.015, y_min: 0.20, y_max: 0.78 }),
                        bone(Shape::CylinderY { x: -0.21, z: 0.045, radius: 0.012, y_min: 0.30, y_max: 0.80 }),
                        bone(Shape::CylinderY { x: 0.21, z: 0.045, radius: 0.012, y_min: 0.30, y_max: 0.80 }),
                        bone(Shape::CylinderY { x: -0.08, z: 0.065, radius: 0.016, y_min: 0.80, y_max: 1.50 }),
                        bone(Shape::CylinderY { x: 0.08, z: 0.065, radius: 0.016, y_min: 0.80, y_max: 1.50 }),
                    ],
                    -0.03,
                    1.58,
                )
            }
            _ => return None,
        };
        let mut all = vec![table(-1.0, 2.5)];
        all.extend(objects);
        Some(Scene { name: name.to_string(), objects: all, travel_start_m: start, travel_end_m: end })
    }

    /// The scene with very dark print or hair: every printed band at reflectance `albedo`, and a
    /// band added where the scene has none (across the pyramid's middle, the body's hair on the
    /// top of its head, the sphere's and the cylinder's middle).
    pub fn with_dark_print(mut self, albedo: f64) -> Scene {
        let added = match self.name.as_str() {
            "pyramid" => Some((1, 0.03, 0.07)),
            "body" => Some((1, -0.01, 0.06)),
            "sphere" => Some((1, -0.02, 0.02)),
            "cylinder" => Some((1, -0.03, 0.03)),
            _ => None,
        };
        if let Some((i, y_min, y_max)) = added {
            if let Some(o) = self.objects.get_mut(i) {
                o.band.get_or_insert(Band { y_min, y_max, albedo });
            }
        }
        for b in self.objects.iter_mut().filter_map(|o| o.band.as_mut()) {
            b.albedo = albedo;
        }
        self
    }

    /// True if `p` (on the surface, within 1 mm) lies on a printed band, at least `margin`
    /// metres inside its edges.
    pub fn in_band(&self, p: Vec3, margin: f64) -> bool {
        self.objects.iter().filter(|o| !o.internal).any(|o| {
            o.band.is_some_and(|b| p.y >= b.y_min + margin && p.y <= b.y_max - margin) && sdf(&o.shape, p).abs() < 1e-3
        })
    }

    /// True if the surface nearest `p` is the tabletop, at least `margin` metres from every
    /// object on it.
    pub fn on_bare_table(&self, p: Vec3, margin: f64) -> bool {
        self.objects.iter().skip(1).filter(|o| !o.internal).all(|o| sdf(&o.shape, p) > margin)
            && self.objects.first().is_some_and(|t| sdf(&t.shape, p).abs() < 0.01)
    }

    /// The bare tabletop (for laser-plane calibration sets).
    pub fn tabletop() -> Scene {
        Scene { name: "tabletop".to_string(), objects: vec![table(-1.0, 2.5)], travel_start_m: -0.1, travel_end_m: 0.1 }
    }

    /// The nearest hit along `origin + t * dir` with `t_min < t < t_max` (`dir` need not be unit).
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f64, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, o) in self.objects.iter().enumerate().filter(|(_, o)| !o.internal) {
            let limit = best.map_or(t_max, |b| b.t);
            if let Some((t, normal)) = intersect_shape(&o.shape, origin, dir, t_min, limit) {
                best = Some(Hit { t, normal, object: i });
            }
        }
        best
    }

    /// True if anything blocks the segment from `a` to `b` (ends excluded by `eps` metres).
    pub fn occluded(&self, a: Vec3, b: Vec3, eps: f64) -> bool {
        let d = b - a;
        let len = d.norm();
        if len <= 2.0 * eps {
            return false;
        }
        let dir = d / len;
        self.objects.iter().any(|o| !o.internal && intersect_shape(&o.shape, a, dir, eps, len - eps).is_some())
    }

    /// Signed distance from `p` to the scene's surface (negative inside a solid).
    pub fn signed_distance(&self, p: Vec3) -> f64 {
        self.objects.iter().filter(|o| !o.internal).map(|o| sdf(&o.shape, p)).fold(f64::INFINITY, f64::min)
    }

    /// The X-ray attenuation integral along the segment from `a` to `b`: the sum over objects
    /// of `mu_per_m` times the length of the segment inside each (dimensionless; the detected
    /// fraction of the beam is `exp(-value)`).
    pub fn attenuation(&self, a: Vec3, b: Vec3) -> f64 {
        let d = b - a;
        let len = d.norm();
        self.objects.iter().map(|o| o.mu_per_m * len * chord(&o.shape, a, d).map_or(0.0, |(t0, t1)| t1 - t0)).sum()
    }

    /// Reflectance of object `i` at `p` (bands and a faint surface texture included).
    pub fn albedo(&self, i: usize, p: Vec3) -> f64 {
        let o = &self.objects[i];
        let base = match o.band {
            Some(b) if p.y >= b.y_min && p.y <= b.y_max => b.albedo,
            _ => o.albedo,
        };
        // A faint, smooth paper/skin texture so that the background is not flat.
        let tex = 1.0 + 0.06 * (p.x * 271.0).sin() * (p.y * 197.0).sin() + 0.03 * ((p.x + p.y) * 613.0).sin();
        base * tex
    }
}

/// The pyramid's four faces as triangles (apex last), outward counter-clockwise.
pub fn pyramid_faces(center: Vec3, base_x: f64, base_y: f64, height: f64) -> [[Vec3; 3]; 4] {
    let (hx, hy) = (base_x / 2.0, base_y / 2.0);
    let c = |x: f64, y: f64| center + Vec3::new(x, y, 0.0);
    let apex = center + Vec3::new(0.0, 0.0, height);
    let (a, b, cc, d) = (c(-hx, -hy), c(hx, -hy), c(hx, hy), c(-hx, hy));
    [[a, b, apex], [b, cc, apex], [cc, d, apex], [d, a, apex]]
}

fn intersect_triangle(o: Vec3, d: Vec3, tri: &[Vec3; 3]) -> Option<f64> {
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-15 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - tri[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) * inv)
}

// Over 80 lines: one closed-form ray intersection per kind of shape, each arm a few lines of
// its own formula; the match is the table of them.
#[allow(clippy::too_many_lines)]
fn intersect_shape(shape: &Shape, o: Vec3, d: Vec3, t_min: f64, t_max: f64) -> Option<(f64, Vec3)> {
    let accept = |t: f64| t > t_min && t < t_max;
    match *shape {
        Shape::Table { half_x, y_min, y_max } => {
            if d.z.abs() < EPS {
                return None;
            }
            let t = -o.z / d.z;
            let p = o + d * t;
            (accept(t) && p.x.abs() <= half_x && p.y >= y_min && p.y <= y_max && o.z > 0.0).then_some((t, Vec3::Z))
        }
        Shape::Pyramid { center, base_x, base_y, height } => {
            let mut best: Option<(f64, Vec3)> = None;
            for tri in pyramid_faces(center, base_x, base_y, height) {
                if let Some(t) = intersect_triangle(o, d, &tri) {
                    if accept(t) && best.is_none_or(|b| t < b.0) {
                        let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).try_normalize().unwrap_or(Vec3::Z);
                        best = Some((t, n));
                    }
                }
            }
            best
        }
        Shape::Cuboid { center, half } => {
            let (mut t0, mut t1) = (t_min, t_max);
            let mut n0 = Vec3::ZERO;
            let oc = o - center;
            for k in 0..3 {
                let (oo, dd, hh) = match k {
                    0 => (oc.x, d.x, half.x),
                    1 => (oc.y, d.y, half.y),
                    _ => (oc.z, d.z, half.z),
                };
                if dd.abs() < EPS {
                    if oo.abs() > hh {
                        return None;
                    }
                    continue;
                }
                let (mut a, mut b) = ((-hh - oo) / dd, (hh - oo) / dd);
                let mut sign = -1.0;
                if a > b {
                    std::mem::swap(&mut a, &mut b);
                    sign = 1.0;
                }
                if a > t0 {
                    t0 = a;
                    n0 = match k {
                        0 => Vec3::X * sign,
                        1 => Vec3::Y * sign,
                        _ => Vec3::Z * sign,
                    };
                }
                t1 = t1.min(b);
                if t0 > t1 {
                    return None;
                }
            }
            (t0 > t_min && n0 != Vec3::ZERO).then_some((t0, n0))
        }
        Shape::Sphere { center, radius } => {
            let oc = o - center;
            let a = d.dot(d);
            let b = oc.dot(d);
            let c = oc.dot(oc) - radius * radius;
            let disc = b * b - a * c;
            if disc < 0.0 {
                return None;
            }
            let sq = disc.sqrt();
            [(-b - sq) / a, (-b + sq) / a]
                .into_iter()
                .find(|&t| accept(t))
                .and_then(|t| ((o + d * t - center) / radius).try_normalize().map(|n| (t, n)))
        }
        Shape::CylinderY { x, z, radius, y_min, y_max } => {
            let mut best: Option<(f64, Vec3)> = None;
            let (ox, oz) = (o.x - x, o.z - z);
            let a = d.x * d.x + d.z * d.z;
            if a > EPS * EPS {
                let b = ox * d.x + oz * d.z;
                let c = ox * ox + oz * oz - radius * radius;
                let disc = b * b - a * c;
                if disc >= 0.0 {
                    for t in [(-b - disc.sqrt()) / a, (-b + disc.sqrt()) / a] {
                        let y = o.y + d.y * t;
                        if accept(t) && y >= y_min && y <= y_max {
                            let n = Vec3::new(ox + d.x * t, 0.0, oz + d.z * t) / radius;
                            best = Some((t, n));
                            break;
                        }
                    }
                }
            }
            if d.y.abs() > EPS {
                for (yc, n) in [(y_min, -Vec3::Y), (y_max, Vec3::Y)] {
                    let t = (yc - o.y) / d.y;
                    let (px, pz) = (ox + d.x * t, oz + d.z * t);
                    if accept(t) && px * px + pz * pz <= radius * radius && best.is_none_or(|b| t < b.0) {
                        best = Some((t, n));
                    }
                }
            }
            best
        }
        Shape::Ellipsoid { center, radii } => {
            let s = |v: Vec3| Vec3::new(v.x / radii.x, v.y / radii.y, v.z / radii.z);
            let (oc, ds) = (s(o - center), s(d));
            let a = ds.dot(ds);
            let b = oc.dot(ds);
            let c = oc.dot(oc) - 1.0;
            let disc = b * b - a * c;
            if disc < 0.0 {
                return None;
            }
            let sq = disc.sqrt();
            [(-b - sq) / a, (-b + sq) / a].into_iter().find(|&t| accept(t)).and_then(|t| {
                let p = o + d * t - center;
                Vec3::new(p.x / (radii.x * radii.x), p.y / (radii.y * radii.y), p.z / (radii.z * radii.z))
                    .try_normalize()
                    .map(|n| (t, n))
            })
        }
    }
}

fn point_triangle_distance(p: Vec3, tri: &[Vec3; 3]) -> f64 {
    // Ericson, Real-Time Collision Detection 5.1.5: closest point on a triangle.
    let (a, b, c) = (tri[0], tri[1], tri[2]);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (p - a).norm();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (p - b).norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (p - (a + ab * (d1 / (d1 - d3)))).norm();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (p - c).norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (p - (a + ac * (d2 / (d2 - d6)))).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return (p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))))).norm();
    }
    let denom = 1.0 / (va + vb + vc);
    (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm()
}

/// The parameter interval `[t0, t1]` within `[0, 1]` of the segment `o + t d` inside `shape`.
fn chord(shape: &Shape, o: Vec3, d: Vec3) -> Option<(f64, f64)> {
    // Roots of a t^2 + 2 b t + c = 0 as an interval.
    let quad = |a: f64, b: f64, c: f64| -> Option<(f64, f64)> {
        if a < EPS * EPS {
            return (c <= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY));
        }
        let disc = b * b - a * c;
        (disc > 0.0).then(|| ((-b - disc.sqrt()) / a, (-b + disc.sqrt()) / a))
    };
    // The slab lo <= o + t d <= hi along one axis.
    let slab = |o: f64, d: f64, lo: f64, hi: f64| -> Option<(f64, f64)> {
        if d.abs() < EPS {
            return (o >= lo && o <= hi).then_some((f64::NEG_INFINITY, f64::INFINITY));
        }
        let (a, b) = ((lo - o) / d, (hi - o) / d);
        Some((a.min(b), a.max(b)))
    };
    let meet = |a: Option<(f64, f64)>, b: Option<(f64, f64)>| -> Option<(f64, f64)> {
        let (a, b) = (a?, b?);
        let r = (a.0.max(b.0), a.1.min(b.1));
        (r.0 < r.1).then_some(r)
    };
    let interval = match *shape {
        Shape::Table { half_x, y_min, y_max } => meet(
            meet(slab(o.z, d.z, -TABLE_THICKNESS_M, 0.0), slab(o.x, d.x, -half_x, half_x)),
            slab(o.y, d.y, y_min, y_max),
        ),
        Shape::Pyramid { center, base_x, base_y, height } => {
            let mut r = slab(o.z, d.z, 0.0, f64::INFINITY);
            for f in pyramid_faces(center, base_x, base_y, height) {
                // Inside: n . (p - f0) <= 0 with the outward normal n.
                let n = (f[1] - f[0]).cross(f[2] - f[0]);
                let (num, den) = (n.dot(o - f[0]), n.dot(d));
                let half = if den.abs() < EPS {
                    (num <= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY))
                } else if den > 0.0 {
                    Some((f64::NEG_INFINITY, -num / den))
                } else {
                    Some((-num / den, f64::INFINITY))
                };
                r = meet(r, half);
            }
            r
        }
        Shape::Cuboid { center, half } => {
            let lo = center - half;
            let hi = center + half;
            meet(meet(slab(o.x, d.x, lo.x, hi.x), slab(o.y, d.y, lo.y, hi.y)), slab(o.z, d.z, lo.z, hi.z))
        }
        Shape::Sphere { center, radius } => {
            let oc = o - center;
            quad(d.dot(d), oc.dot(d), oc.dot(oc) - radius * radius)
        }
        Shape::CylinderY { x, z, radius, y_min, y_max } => {
            let (ox, oz) = (o.x - x, o.z - z);
            meet(
                quad(d.x * d.x + d.z * d.z, ox * d.x + oz * d.z, ox * ox + oz * oz - radius * radius),
                slab(o.y, d.y, y_min, y_max),
            )
        }
        Shape::Ellipsoid { center, radii } => {
            let s = |v: Vec3| Vec3::new(v.x / radii.x, v.y / radii.y, v.z / radii.z);
            let (oc, ds) = (s(o - center), s(d));
            quad(ds.dot(ds), oc.dot(ds), oc.dot(oc) - 1.0)
        }
    };
    meet(interval, Some((0.0, 1.0)))
}

fn sdf(shape: &Shape, p: Vec3) -> f64 {
    match *shape {
        Shape::Table { .. } => p.z,
        Shape::Pyramid { center, base_x, base_y, height } => {
            let faces = pyramid_faces(center, base_x, base_y, height);
            let d = faces.iter().map(|f| point_triangle_distance(p, f)).fold(f64::INFINITY, f64::min);
            let inside = p.z >= 0.0
                && faces.iter().all(|f| {
                    let n = (f[1] - f[0]).cross(f[2] - f[0]);
                    n.dot(p - f[0]) <= 0.0
                });
            if inside {
                -d.min(p.z)
            } else {
                d
            }
        }
        Shape::Cuboid { center, half } => {
            let q = (p - center).abs() - half;
            q.max(Vec3::ZERO).norm() + q.x.max(q.y).max(q.z).min(0.0)
        }
        Shape::Sphere { center, radius } => (p - center).norm() - radius,
        Shape::CylinderY { x, z, radius, y_min, y_max } => {
            let r = ((p.x - x).powi(2) + (p.z - z).powi(2)).sqrt() - radius;
            let h = (p.y - 0.5 * (y_min + y_max)).abs() - 0.5 * (y_max - y_min);
            let (a, b) = (r.max(0.0), h.max(0.0));
            (a * a + b * b).sqrt() + r.max(h).min(0.0)
        }
        Shape::Ellipsoid { center, radii } => {
            // First-order distance (accurate near the surface, where it is used).
            let q = p - center;
            let k0 = Vec3::new(q.x / radii.x, q.y / radii.y, q.z / radii.z).norm();
            let k1 = Vec3::new(q.x / (radii.x * radii.x), q.y / (radii.y * radii.y), q.z / (radii.z * radii.z)).norm();
            if k1 > 0.0 {
                k0 * (k0 - 1.0) / k1
            } else {
                -radii.x.min(radii.y).min(radii.z)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_scene_builds_and_ray_hits_agree_with_distance() {
        for name in SCENE_NAMES {
            let s = Scene::by_name(name).unwrap();
            // Rays from above onto a grid: the hit point must lie on the surface.
            for i in 0..21 {
                for j in 0..21 {
                    let x = -0.3 + 0.025 * i as f64;
                    let y = s.travel_start_m + (s.travel_end_m - s.travel_start_m) * j as f64 / 20.0;
                    let o = Vec3::new(x, y, 1.0);
                    let d = Vec3::new(0.1, 0.2, -1.0).try_normalize().unwrap();
                    let h = s.intersect(o, d, 1e-9, 10.0).unwrap();
                    let p = o + d * h.t;
                    let tol = if name == "body" { 2e-4 } else { 1e-9 };
                    assert!(s.signed_distance(p).abs() < tol, "{name}: {p:?} sdf {}", s.signed_distance(p));
                    assert!(h.normal.dot(d) < 0.0, "{name}: normal faces the ray");
                }
            }
        }
        assert!(Scene::by_name("teapot").is_none());
    }

    #[test]
    fn attenuation_is_mu_times_chord_length() {
        let s = Scene::by_name("sphere").unwrap();
        let (c, r) = (Vec3::new(0.06, 0.0, 0.08), 0.08);
        // Straight down through the centre: the sphere's diameter plus the tabletop.
        let a = s.attenuation(c + Vec3::Z, c - Vec3::Z);
        assert!((a - (MU_TISSUE * 2.0 * r + MU_TABLE * TABLE_THICKNESS_M)).abs() < 1e-9, "{a}");
        // Off-centre by r/2 horizontally through the sphere only: chord 2 sqrt(r^2 - (r/2)^2).
        let off = c + Vec3::new(0.0, r / 2.0, 0.0);
        let a = s.attenuation(off - Vec3::X * 0.5, off + Vec3::X * 0.5);
        assert!((a - MU_TISSUE * 2.0 * (r * r * 0.75).sqrt()).abs() < 1e-9, "{a}");
        // Segment ends inside count only the part between them; a miss counts nothing.
        assert!((s.attenuation(c, c + Vec3::X) - MU_TISSUE * r).abs() < 1e-9);
        assert_eq!(s.attenuation(Vec3::new(0.5, 0.5, 0.5), Vec3::new(0.6, 0.5, 0.5)), 0.0);
        // The pyramid's vertical chord at the apex axis is its height; cuboid and cylinder likewise.
        let p = Scene::by_name("pyramid").unwrap();
        let a = p.attenuation(Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, 0.001));
        assert!((a - MU_TISSUE * (0.086 - 0.001)).abs() < 1e-9, "{a}");
        let b = Scene::by_name("phantom").unwrap();
        let a = b.attenuation(Vec3::new(-0.06, -0.05, 1.0), Vec3::new(-0.06, -0.05, 0.0));
        assert!((a - MU_TISSUE * 0.08).abs() < 1e-9, "{a}");
        let a = b.attenuation(Vec3::new(0.1, 0.08, 1.0), Vec3::new(0.1, 0.08, 0.0));
        assert!((a - MU_TISSUE * 0.07).abs() < 1e-9, "{a}");
    }

    #[test]
    fn bones_are_seen_by_x_rays_only() {
        let s = Scene::by_name("body").unwrap();
        let femur = Vec3::new(0.08, 1.0, 0.065);
        // The surface above the femur is the leg's, not the bone's.
        let h = s.intersect(femur + Vec3::Z, -Vec3::Z, 1e-9, 10.0).unwrap();
        assert!(!s.objects[h.object].internal);
        assert!(s.signed_distance(femur) < -0.03);
        let through = s.attenuation(femur + Vec3::Z * 0.5, femur - Vec3::Z * 0.04);
        let beside = s.attenuation(femur + Vec3::new(0.04, 0.0, 0.5), femur + Vec3::new(0.04, 0.0, -0.04));
        assert!(through > beside + MU_BONE_EXCESS * 0.02, "{through} {beside}");
    }

    #[test]
    fn pyramid_distance_inside_and_outside() {
        let s = Scene::by_name("pyramid").unwrap();
        assert!((s.signed_distance(Vec3::new(0.0, 0.0, 0.1)) - 0.014).abs() < 1e-12);
        assert!(s.signed_distance(Vec3::new(0.0, 0.0, 0.001)) < -0.0009);
        assert!((s.signed_distance(Vec3::new(0.2, 0.0, 0.003)) - 0.003).abs() < 1e-12);
    }
}
