//! The scanner rig: cameras on the C-arm and the laser fan beam, as stored in a rig file.
//!
//! The rig file (YAML) is this struct serialised; see `launch-config/rig_study.yaml` for a
//! documented example. Rotations are quaternions `[x, y, z, w]` of `carm -> <cam>_optical_frame`.

use crate::camera::{CameraError, CameraModel, Distortion};
use crate::edge::LaserColor;
use crate::geom::{Iso3, Quat, Vec3};
use crate::triangulate::CameraGeometry;
use serde::{Deserialize, Serialize};

/// One camera of the rig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RigCamera {
    /// Camera name: its namespace (`cam1`) and frame prefix (`cam1_optical_frame`).
    pub name: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// `plumb_bob` or `rational_polynomial`.
    pub distortion_model: String,
    /// Distortion coefficients in ROS order.
    pub d: Vec<f64>,
    /// Optical centre in `carm`, metres.
    pub translation: [f64; 3],
    /// Rotation `carm -> optical` as a quaternion `[x, y, z, w]`.
    pub rotation: [f64; 4],
}

impl RigCamera {
    /// The intrinsics.
    pub fn model(&self) -> Result<CameraModel, CameraError> {
        let m = CameraModel {
            width: self.width,
            height: self.height,
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            distortion: Distortion::from_ros(&self.distortion_model, &self.d)?,
        };
        m.validate()?;
        Ok(m)
    }
    /// `carm -> optical` as a transform.
    pub fn carm_from_optical(&self) -> Iso3 {
        let [x, y, z, w] = self.rotation;
        Iso3::from_parts(Vec3::from_array(self.translation), Quat { x, y, z, w })
    }
    /// Sets `carm -> optical` (a refined placement).
    pub fn set_carm_from_optical(&mut self, e: &Iso3) {
        let q = e.quaternion();
        self.translation = e.translation.to_array();
        self.rotation = [q.x, q.y, q.z, q.w];
    }
    /// The camera turned a quarter turn about its optical axis, where it hangs (its image's
    /// rows become columns): the optical x axis turns to where y was. A camera mounted on its
    /// side sees the laser line run along its rows (`line_orientation: horizontal`).
    pub fn roll_quarter_turn(&mut self) {
        let roll = Iso3::from_parts(Vec3::ZERO, Quat::from_axis_angle(Vec3::Z, std::f64::consts::FRAC_PI_2));
        self.set_carm_from_optical(&self.carm_from_optical().compose(&roll));
    }
    /// Intrinsics and extrinsics together.
    pub fn geometry(&self) -> Result<CameraGeometry, CameraError> {
        Ok(CameraGeometry { model: self.model()?, carm_from_optical: self.carm_from_optical() })
    }
    /// A camera from a model and a pose.
    pub fn from_parts(name: &str, model: &CameraModel, carm_from_optical: &Iso3) -> RigCamera {
        let (dm, d) = model.distortion.to_ros();
        let q = carm_from_optical.quaternion();
        RigCamera {
            name: name.to_string(),
            width: model.width,
            height: model.height,
            fx: model.fx,
            fy: model.fy,
            cx: model.cx,
            cy: model.cy,
            distortion_model: dm.to_string(),
            d,
            translation: carm_from_optical.translation.to_array(),
            rotation: [q.x, q.y, q.z, q.w],
        }
    }
}

/// One laser of a scanner with several (the spec's `lasers` list; `laser.<name>.plane`,
/// `.source`, `.channel`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RigLaser {
    /// Its name in `lasers`: a letter, then letters, digits and underscores.
    pub name: String,
    /// Its plane in `carm`, `[nx, ny, nz, d]` with a unit normal.
    pub plane: [f64; 4],
    /// Its source point in `carm`, metres.
    pub source: [f64; 3],
    /// Its colour: on colour cameras its line is found in this colour against the others.
    pub channel: LaserColor,
}

/// Cameras and laser of one scanner.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rig {
    /// The laser plane in `carm`, `[nx, ny, nz, d]` (the collimator's: the X-ray fan beam's).
    pub laser_plane: [f64; 4],
    /// The laser (and X-ray) source in `carm`, metres.
    pub laser_source: [f64; 3],
    /// A scanner with several lasers: each one's plane, source and colour. Empty: the single
    /// laser `laser_plane` is the whole scanner.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lasers: Vec<RigLaser>,
    /// The cameras.
    pub cameras: Vec<RigCamera>,
}

/// The tilt of [`Rig::three_lasers`]' side planes from the vertical, degrees.
pub const TILT_DEG: f64 = 25.0;

/// Where [`Rig::three_lasers`]' side planes meet the tabletop: this far either side of the
/// collimator's line, so that the three lines never meet below 0.3 m (where they would add up
/// to white, and no colour would tell them apart).
pub const TILTED_TABLE_Y_M: f64 = 0.08;

/// At most this many lasers: each needs a colour of its own (red, green, blue).
pub const MAX_LASERS: usize = 3;

/// Checks a scanner's lasers as every reader of a rig file and every node's `lasers`
/// parameters are checked: at most [`MAX_LASERS`], names that are ROS name tokens and unique,
/// planes with a unit normal (within 1e-3), finite sources, one colour each. The message names
/// the laser and its field (`laser.<name>.plane`).
pub fn validate_lasers(lasers: &[RigLaser]) -> Result<(), String> {
    if lasers.len() > MAX_LASERS {
        return Err(format!(
            "lasers: {} lasers; at most {MAX_LASERS} (one per colour: red, green, blue)",
            lasers.len()
        ));
    }
    for (i, l) in lasers.iter().enumerate() {
        let at = format!("laser.{}", l.name);
        if !valid_ros_token(&l.name) {
            return Err(format!("lasers: {:?} is not a valid name (a letter, then letters, digits or _)", l.name));
        }
        if lasers[..i].iter().any(|o| o.name == l.name) {
            return Err(format!("lasers: {:?} is listed twice", l.name));
        }
        let n = l.plane[..3].iter().map(|x| x * x).sum::<f64>().sqrt();
        if !l.plane.iter().all(|x| x.is_finite()) || (n - 1.0).abs() > 1e-3 {
            return Err(format!("{at}.plane: {:?} is not [nx, ny, nz, d] with a unit normal (|n| = {n})", l.plane));
        }
        if !l.source.iter().all(|x| x.is_finite()) {
            return Err(format!("{at}.source: {:?} is not finite", l.source));
        }
        if let Some(o) = lasers[..i].iter().find(|o| o.channel == l.channel) {
            return Err(format!(
                "{at}.channel: {} is laser.{}'s too; a camera tells lasers apart only by colour",
                l.channel.name(),
                o.name
            ));
        }
    }
    Ok(())
}

/// Whether `name` is a valid ROS name token (a namespace or frame prefix): a letter, then
/// letters, digits and underscores.
pub fn valid_ros_token(name: &str) -> bool {
    let mut c = name.chars();
    c.next().is_some_and(|f| f.is_ascii_alphabetic()) && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
}

impl Rig {
    /// Checks what every reader of a rig file relies on: at least one camera, unique camera
    /// names that are valid ROS names, image sizes within [`crate::limits::IMAGE_SIDE_PX`],
    /// valid intrinsics, finite placements with unit quaternions, and a laser plane with a unit
    /// normal. The message names the camera and the field.
    pub fn validate(&self) -> Result<(), String> {
        if self.cameras.is_empty() {
            return Err("cameras: none (a rig needs at least one camera)".into());
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        for (i, c) in self.cameras.iter().enumerate() {
            let at = format!("cameras[{i}] ({:?})", c.name);
            if !valid_ros_token(&c.name) {
                return Err(format!("{at}: name is not a valid ROS name (a letter, then letters, digits or _)"));
            }
            if let Some(j) = self.cameras[..i].iter().position(|o| o.name == c.name) {
                return Err(format!("{at}: the name is used by cameras[{j}] too (each camera needs its own topics)"));
            }
            for (what, v) in [("width", c.width), ("height", c.height)] {
                if !crate::limits::image_side_ok(v) {
                    return Err(format!("{at}: {what} {v} is not in {}", crate::limits::image_side_text()));
                }
            }
            c.model().map_err(|e| format!("{at}: {e}"))?;
            if !finite(&c.translation) {
                return Err(format!("{at}: translation {:?} is not finite", c.translation));
            }
            let norm = c.rotation.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !finite(&c.rotation) || (norm - 1.0).abs() > 1e-3 {
                return Err(format!(
                    "{at}: rotation {:?} is not a unit quaternion [x, y, z, w] (norm {norm})",
                    c.rotation
                ));
            }
        }
        let n = (self.laser_plane[..3].iter().map(|x| x * x).sum::<f64>()).sqrt();
        if !finite(&self.laser_plane) || (n - 1.0).abs() > 1e-3 {
            return Err(format!("laser_plane {:?}: [nx, ny, nz, d] with a unit normal", self.laser_plane));
        }
        if !finite(&self.laser_source) {
            return Err(format!("laser_source {:?} is not finite", self.laser_source));
        }
        validate_lasers(&self.lasers)
    }

    /// The scanner's lasers: the `lasers` list, or without one the single laser `laser_plane`
    /// (named `laser`, red).
    pub fn effective_lasers(&self) -> Vec<RigLaser> {
        if !self.lasers.is_empty() {
            return self.lasers.clone();
        }
        vec![RigLaser {
            name: "laser".into(),
            plane: self.laser_plane,
            source: self.laser_source,
            channel: LaserColor::Red,
        }]
    }

    /// A three-laser scanner (the study's recommendation of more fan beams): the collimator's
    /// plane (red, vertical, as [`Rig::study`]'s) and two planes tilted 25 degrees about the
    /// table's X axis, one from each side of the travel (green from -Y, blue from +Y), meeting
    /// the tabletop [`TILTED_TABLE_Y_M`] either side of the collimator's line. Each lights the upright faces across the travel
    /// on its side, which the collimator's plane only grazes. The cameras look from 45 degrees
    /// (the study's preferred angle, section 6.1), so that each views the tilted plane on its
    /// side at 20 degrees and the collimator's at 45.
    pub fn three_lasers(width: u32, height: u32) -> Rig {
        let mut rig = Rig::study(width, height);
        // The study's cameras are valid at every size it is asked for.
        let Ok(model) = rig.cameras[0].model() else { return rig };
        let target = Vec3::new(0.0, 0.0, 0.05);
        let cam = |name: &str, eye: Vec3, down: Vec3| {
            // look_at only fails for coincident points or a parallel hint; these are fixed.
            let pose = Iso3::look_at(eye, target, down).unwrap_or(Iso3::IDENTITY);
            RigCamera::from_parts(name, &model, &pose)
        };
        rig.cameras = vec![
            cam("cam1", Vec3::new(-0.20, -0.62, 0.67), Vec3::X),
            cam("cam2", Vec3::new(0.20, 0.62, 0.67), -Vec3::X),
        ];
        let (s, c) = TILT_DEG.to_radians().sin_cos();
        // A plane tilted about X through (0, y0, 0) on the tabletop, its source 1 m up.
        let tilted = |name: &str, sign: f64, channel| {
            let y0 = sign * TILTED_TABLE_Y_M;
            RigLaser {
                name: name.into(),
                plane: [0.0, c, -sign * s, c * y0],
                source: [0.0, y0 + sign * s / c, 1.0],
                channel,
            }
        };
        rig.lasers = vec![
            RigLaser {
                name: "collimator".into(),
                plane: rig.laser_plane,
                source: rig.laser_source,
                channel: LaserColor::Red,
            },
            tilted("left", -1.0, LaserColor::Green),
            tilted("right", 1.0, LaserColor::Blue),
        ];
        rig
    }

    /// The study's two-camera arrangement (thesis section 6.1: cameras 30 degrees from the
    /// vertical, on opposite sides of the fan beam), at the given image size. `cam1` sits behind
    /// the beam on the -X side, `cam2` ahead of it on the +X side, both 0.8 m above the tabletop;
    /// image rows run across the table, so the line is vertical in the image.
    pub fn study(width: u32, height: u32) -> Rig {
        let base = CameraModel {
            width: 640,
            height: 480,
            fx: 700.0,
            fy: 700.0,
            cx: 322.4,
            cy: 237.6,
            distortion: Distortion::PlumbBob { k1: -0.12, k2: 0.05, p1: 0.0005, p2: -0.0003, k3: 0.0 },
        };
        let model = base.scaled(width, height);
        let target = Vec3::new(0.0, 0.0, 0.05);
        let cam = |name: &str, eye: Vec3, down: Vec3| {
            // look_at only fails for coincident points or a parallel hint; these are fixed.
            let pose = Iso3::look_at(eye, target, down).unwrap_or(Iso3::IDENTITY);
            RigCamera::from_parts(name, &model, &pose)
        };
        Rig {
            laser_plane: [0.0, 1.0, 0.0, 0.0],
            laser_source: [0.0, 0.0, 1.2],
            lasers: Vec::new(),
            cameras: vec![
                cam("cam1", Vec3::new(-0.25, -0.40, 0.80), Vec3::X),
                cam("cam2", Vec3::new(0.25, 0.40, 0.80), -Vec3::X),
            ],
        }
    }

    /// The camera of that name.
    pub fn camera(&self, name: &str) -> Option<&RigCamera> {
        self.cameras.iter().find(|c| c.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarter_turn_puts_the_image_x_axis_where_y_was() {
        let mut c = Rig::study(640, 480).cameras[1].clone();
        let before = c.carm_from_optical();
        c.roll_quarter_turn();
        let after = c.carm_from_optical();
        let near = |a: Vec3, b: Vec3| (a - b).norm() < 1e-12;
        assert!(near(after.translation, before.translation));
        assert!(near(after.transform_vector(Vec3::X), before.transform_vector(Vec3::Y)));
        assert!(near(after.transform_vector(Vec3::Y), -before.transform_vector(Vec3::X)));
        assert!(near(after.transform_vector(Vec3::Z), before.transform_vector(Vec3::Z)));
        assert_eq!(Rig { cameras: vec![c], ..Rig::study(640, 480) }.validate(), Ok(()));
    }

    #[test]
    fn validation_names_the_camera_and_field() {
        assert_eq!(Rig::study(640, 480).validate(), Ok(()));
        let bad = |f: &dyn Fn(&mut Rig), says: &str| {
            let mut r = Rig::study(640, 480);
            f(&mut r);
            let e = r.validate().unwrap_err();
            assert!(e.contains(says), "{says}: {e}");
        };
        bad(&|r| r.cameras.clear(), "cameras: none");
        bad(&|r| r.cameras[1].name = "cam1".into(), "used by cameras[0]");
        bad(&|r| r.cameras[0].name = "cam 1/x".into(), "not a valid ROS name");
        bad(&|r| r.cameras[0].rotation = [0.0; 4], "not a unit quaternion");
        bad(&|r| r.cameras[0].rotation = [0.5, 0.5, 0.5, 0.6], "not a unit quaternion");
        bad(&|r| r.cameras[1].translation[2] = f64::NAN, "cameras[1] (\"cam2\"): translation");
        bad(&|r| r.cameras[0].width = 100_000, "width 100000 is not in 32..=8192");
        bad(&|r| r.cameras[0].fx = -1.0, "fx -1");
        bad(&|r| r.laser_plane = [0.0, 0.0, 0.0, 0.0], "laser_plane");
        let three = Rig::three_lasers(640, 480);
        assert_eq!(three.validate(), Ok(()));
        for l in &three.lasers {
            let p = crate::geom::Plane::from_params(l.plane).unwrap();
            assert!(p.signed_distance(Vec3::from_array(l.source)).abs() < 1e-12, "{} passes its source", l.name);
        }
        let bad3 = |f: &dyn Fn(&mut Vec<RigLaser>), says: &str| {
            let mut l = three.lasers.clone();
            f(&mut l);
            let e = validate_lasers(&l).unwrap_err();
            assert!(e.contains(says), "{says}: {e}");
        };
        bad3(&|l| l[1].channel = LaserColor::Red, "laser.left.channel: red is laser.collimator's too");
        bad3(&|l| l[2].plane = [0.0, 2.0, 0.0, 0.0], "laser.right.plane");
        bad3(&|l| l[1].source[0] = f64::NAN, "laser.left.source");
        bad3(&|l| l[1].name = "collimator".into(), "listed twice");
        bad3(&|l| l.push(l[0].clone()), "at most 3");
        assert!(valid_ros_token("cam_2") && !valid_ros_token("2cam") && !valid_ros_token(""));
    }
}
