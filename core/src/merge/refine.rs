//! The refinement of a scan's further cameras against the first camera's surface, with the
//! decision and its reason for each: the merger runs it, writes the records to
//! `refinement.json`, and `xsurf calibrate scan` reads them back (the same [`Record`]).

use crate::geom::{Iso3, Plane, Quat, Vec3};
use crate::mesh::Grid;
use crate::register::{refine_grid, RefineConfig, RefineReport, ScanMotion};
use serde::{Deserialize, Serialize};

/// Largest rotation of the C-arm, summed over a scan, for the refinement to run, radians.
pub const MAX_ANGLE_CHANGE_RAD: f64 = 1e-4;
/// Largest change of the C-arm's across / height offset during a scan, metres.
pub const MAX_OFFSET_CHANGE_M: f64 = 1e-4;

/// The C-arm's motion over a scan, from its poses (`table -> carm`) in order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarmMotion {
    /// The first pose of the scan.
    pub first: Iso3,
    /// The latest.
    pub last: Iso3,
    /// The rotation summed from pose to pose, radians.
    pub turned_rad: f64,
    /// The largest change of the tabletop's lateral offset or height from the first pose, m.
    pub offset_m: f64,
}

impl CarmMotion {
    /// The motion of a scan whose first pose is `pose`.
    pub fn start(pose: Iso3) -> CarmMotion {
        CarmMotion { first: pose, last: pose, turned_rad: 0.0, offset_m: 0.0 }
    }
    /// With the next pose.
    pub fn then(self, pose: Iso3) -> CarmMotion {
        let d = pose.translation - self.first.translation;
        CarmMotion {
            last: pose,
            // Summed from pose to pose, so a full turn reads 360 degrees, not the 0 (or at most
            // 180) between the first and the last.
            turned_rad: self.turned_rad + self.last.rotation.angle_to(&pose.rotation),
            offset_m: self.offset_m.max(d.x.abs()).max(d.z.abs()),
            ..self
        }
    }
}

/// A placement `carm -> optical` as the records write it: translation (m) and quaternion
/// `[x, y, z, w]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Quaternion `[x, y, z, w]`.
    pub rotation: [f64; 4],
    /// Translation, metres.
    pub translation: [f64; 3],
}

impl From<&Iso3> for Placement {
    fn from(e: &Iso3) -> Placement {
        let q = e.quaternion();
        Placement { rotation: [q.x, q.y, q.z, q.w], translation: e.translation.to_array() }
    }
}

impl Placement {
    /// As a rigid transform.
    pub fn iso(&self) -> Iso3 {
        let [x, y, z, w] = self.rotation;
        Iso3::from_parts(Vec3::from_array(self.translation), Quat { x, y, z, w })
    }
}

/// What happened to one camera's placement: a record of `refinement.json`. The fields are in
/// alphabetical order, as the file has always had them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// The calibrated placement, where it was known.
    pub calibrated: Option<Placement>,
    /// The camera.
    pub camera: String,
    /// Angle of the orientation correction, degrees (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_deg: Option<f64>,
    /// Correction of the camera's position in `carm`, metres (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_m: Option<[f64; 3]>,
    /// Of the placement's six directions (rotations taken at 1 m), those the data held; along
    /// the others the camera stayed as calibrated (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_directions: Option<u32>,
    /// Iterations run (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<u32>,
    /// Fraction of the observations near the reference surface, after (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overlap_fraction: Option<f64>,
    /// Observations used (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<usize>,
    /// Why the placement was refined or kept.
    pub reason: String,
    /// The camera whose surface is the reference.
    pub reference: String,
    /// The refined placement (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refined: Option<Placement>,
    /// RMS point-to-plane residual after, metres (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rms_after_m: Option<f64>,
    /// The same before (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rms_before_m: Option<f64>,
    /// One standard deviation of the orientation correction, degrees (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_rotation_deg: Option<f64>,
    /// One standard deviation of the position correction, metres (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_translation_m: Option<f64>,
    /// Standard deviations of the whole correction (refined only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub significance_sigma: Option<f64>,
    /// `refined` or `refused`.
    pub status: Status,
}

/// Whether a placement was refined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// The refined placement replaces the calibrated one.
    Refined,
    /// The calibrated placement stands.
    Refused,
}

impl Record {
    /// A refused camera.
    pub fn refused(camera: &str, reference: &str, calibrated: Option<&Iso3>, reason: String) -> Record {
        Record {
            calibrated: calibrated.map(Placement::from),
            camera: camera.into(),
            correction_deg: None,
            correction_m: None,
            held_directions: None,
            iterations: None,
            overlap_fraction: None,
            points: None,
            reason,
            reference: reference.into(),
            refined: None,
            rms_after_m: None,
            rms_before_m: None,
            sigma_rotation_deg: None,
            sigma_translation_m: None,
            significance_sigma: None,
            status: Status::Refused,
        }
    }
    /// A refined camera.
    pub fn refined(camera: &str, reference: &str, calibrated: &Iso3, r: &RefineReport) -> Record {
        let t = r.translation_m;
        Record {
            calibrated: Some(calibrated.into()),
            correction_deg: Some(r.rotation_deg),
            correction_m: Some([t.x, t.y, t.z]),
            held_directions: Some(r.held_directions),
            iterations: Some(r.iterations),
            overlap_fraction: Some(r.overlap_fraction),
            points: Some(r.points),
            reason: format!(
                "the correction is {:.0} standard deviations and lowers the RMS residual from {:.5} to {:.5} m; \
                 {} of 6 directions held by the data (the others left as calibrated)",
                r.significance, r.rms_before_m, r.rms_after_m, r.held_directions
            ),
            refined: Some((&r.carm_from_optical).into()),
            rms_after_m: Some(r.rms_after_m),
            rms_before_m: Some(r.rms_before_m),
            sigma_rotation_deg: Some(r.sigma_rotation_deg),
            sigma_translation_m: Some(r.sigma_translation_m),
            significance_sigma: Some(r.significance),
            status: Status::Refined,
            ..Record::refused(camera, reference, None, String::new())
        }
    }
}

/// `refinement.json`: a scan's records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefinementFile {
    /// One record per further camera.
    pub cameras: Vec<Record>,
    /// The scan.
    pub scan_id: u32,
}

/// One camera's outcome.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The record (for the file and the log).
    pub record: Record,
    /// The full report of a refined camera.
    pub report: Option<RefineReport>,
}

/// Refines each further camera's placement (`names[k]` is grid `k`'s camera; its calibrated
/// placement from `placement`, which says why when it has none) against the first camera's
/// grid, given the C-arm's motion over the scan (`None`: no pose arrived). A refined grid is
/// re-triangulated in place. Each further camera gets one outcome, in order.
pub fn refine_cameras(
    names: &[String],
    grids: &mut [Grid],
    placement: impl Fn(&str) -> Result<Iso3, String>,
    motion: Option<&CarmMotion>,
    plane: &Plane,
    cfg: &RefineConfig,
) -> Vec<Outcome> {
    let Some((reference, further)) = names.split_first() else { return Vec::new() };
    let refuse_all = |why: String| -> Vec<Outcome> {
        further
            .iter()
            .map(|cam| Outcome { record: Record::refused(cam, reference, None, why.clone()), report: None })
            .collect()
    };
    let motion = match motion {
        None => return refuse_all("no table -> carm on /tf during the scan".into()),
        Some(m) if m.turned_rad > MAX_ANGLE_CHANGE_RAD || m.offset_m > MAX_OFFSET_CHANGE_M => {
            return refuse_all(format!(
                "table -> carm turned {:.3} deg in all and the tabletop moved up to {:.1} mm during the scan; the \
                 refinement needs one angle and height per scan",
                m.turned_rad.to_degrees(),
                m.offset_m * 1e3
            ))
        }
        Some(m) => ScanMotion { table_from_carm: m.first },
    };
    let Some((first, rest)) = grids.split_first_mut() else { return Vec::new() };
    let mut out = Vec::new();
    for (name, grid) in further.iter().zip(rest) {
        let e = match placement(name) {
            Ok(e) => e,
            Err(why) => {
                out.push(Outcome { record: Record::refused(name, reference, None, why), report: None });
                continue;
            }
        };
        out.push(match refine_grid(first, grid, &e, plane, &motion, cfg) {
            Ok(r) => Outcome { record: Record::refined(name, reference, &e, &r), report: Some(r) },
            Err(err) => Outcome { record: Record::refused(name, reference, Some(&e), err.to_string()), report: None },
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_read_back_and_keep_their_fields_in_order() {
        let e = Iso3::from_parts(Vec3::new(0.1, -0.2, 0.3), Quat { x: 0.0, y: 0.0, z: 0.0, w: 1.0 });
        let r = Record::refused("cam2", "cam1", Some(&e), "too little overlap".into());
        let text = serde_json::to_string(&r).unwrap();
        assert_eq!(
            text,
            r#"{"calibrated":{"rotation":[0.0,0.0,0.0,1.0],"translation":[0.1,-0.2,0.3]},"camera":"cam2","reason":"too little overlap","reference":"cam1","status":"refused"}"#
        );
        assert_eq!(serde_json::from_str::<Record>(&text).unwrap(), r);
        assert_eq!(Placement::from(&e).iso().translation, e.translation);
    }

    #[test]
    fn a_turning_carm_refuses_every_further_camera() {
        let pose = |a: f64| Iso3::from_parts(Vec3::ZERO, Quat::from_axis_angle(Vec3::new(0.0, 1.0, 0.0), a));
        let m = CarmMotion::start(pose(0.0)).then(pose(0.01)).then(pose(0.0));
        assert!((m.turned_rad - 0.02).abs() < 1e-9, "summed from pose to pose: {}", m.turned_rad);
        let names = ["cam1".to_string(), "cam2".to_string(), "cam3".to_string()];
        let mut grids = vec![Grid::new(4); 3];
        let plane = Plane::from_params([0.0, 1.0, 0.0, 0.0]).unwrap();
        let out = refine_cameras(&names, &mut grids, |_| Ok(Iso3::IDENTITY), Some(&m), &plane, &Default::default());
        assert_eq!(out.len(), 2);
        assert!(out.iter().all(|o| o.record.status == Status::Refused && o.record.reason.contains("turned")));
        let out = refine_cameras(&names, &mut grids, |c| Err(format!("no {c}")), None, &plane, &Default::default());
        assert!(out.iter().all(|o| o.record.reason == "no table -> carm on /tf during the scan"));
    }
}
