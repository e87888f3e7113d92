//! The scan reports, typed once for the nodes that write them and the merger that reads them.
//!
//! Each per-camera node publishes its account of a scan on `/scan/report` (std_msgs/String, a
//! JSON object whose `node` field says which): the camera_driver, edge_detector and
//! triangulator a [`StageReport`] (from `tally.rs`), the mesher a [`MesherReport`]. The merger
//! puts them together, per camera, into the [`CameraAccount`]s of the scan's
//! `scan_<id>/scan_report.json` ([`ScanReport`]). The fields are listed alphabetically, the order
//! in which they are written.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One class of refused frames in a node's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Refusal {
    /// The first refusal's message.
    pub first: Option<String>,
    /// Frames refused for this reason.
    pub frames: u64,
}

/// A camera_driver's, edge_detector's or triangulator's account of one scan's frames.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageReport {
    /// The camera whose frames these are.
    pub camera: String,
    /// Frames placed (the triangulator).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_placed: Option<u64>,
    /// Frames refused, over all reasons.
    pub frames_refused: u64,
    /// Frames sent (the camera_driver).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_sent: Option<u64>,
    /// Frame slots never made (a camera behind its rate).
    pub frames_skipped: u64,
    /// Frames taken (the edge_detector).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_taken: Option<u64>,
    /// The node: `camera_driver`, `edge_detector` or `triangulator`.
    pub node: String,
    /// The frames refused, by reason.
    pub refused: BTreeMap<String, Refusal>,
    /// The scan.
    pub scan_id: u32,
}

/// A gap in a camera's frames, as the mesher saw it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Gap {
    /// The stamp of the frame before the gap.
    pub after: String,
    /// The stamp of the frame after the gap.
    pub before: String,
    /// Frames missing between the two.
    pub frames: u32,
}

/// The mesher's account of one scan of its camera.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MesherReport {
    /// The scan ended with ABORT.
    pub aborted: bool,
    /// The camera.
    pub camera: String,
    /// The END (or ABORT) stamp.
    pub end: Option<String>,
    /// The scan's final grid as the mesher published it on `cloud`: a cloud of this camera
    /// with this stamp and this many points is the scan's last, and the merger need wait no
    /// longer for it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub final_cloud: Option<FinalCloud>,
    /// The first frame's stamp.
    pub first_frame: Option<String>,
    /// Seconds from START to the first frame (not counted as lost: a camera not yet exposing).
    pub first_frame_after_start_s: Option<f64>,
    /// The frame period from the stamps.
    pub frame_period_s: Option<f64>,
    /// Frames expected from the stamps: received and lost.
    pub frames_expected: u64,
    /// Frames lost in the gaps.
    pub frames_lost: u64,
    /// Frames received, stamped before the END.
    pub frames_received: u64,
    /// Frames whose profile had no line.
    pub frames_without_line: u64,
    /// The gaps, in order.
    pub gaps: Vec<Gap>,
    /// The last frame's stamp.
    pub last_frame: Option<String>,
    /// Seconds from the last frame to END.
    pub last_frame_before_end_s: Option<f64>,
    /// Always `mesher`.
    pub node: String,
    /// Of `points_rejected`, the points the laser sheet only partly reached (a surface's first
    /// or last frame, see the mesher's `partial_sheet_ratio`); 0 in reports of older meshers.
    #[serde(default)]
    pub points_partial_sheet: u64,
    /// Points of the finished grid rejected before meshing: those their neighbours contradict
    /// and those the laser sheet only partly reached.
    pub points_rejected: u64,
    /// Profiles refused (a size the camera does not give, a late one).
    pub profiles_refused: u64,
    /// The scan.
    pub scan_id: u32,
    /// The START stamp.
    pub start: Option<String>,
}

/// The mark of a scan's final cloud in its mesher's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FinalCloud {
    /// Its points (valid cells of the grid).
    pub points: u64,
    /// Its stamp (the grid's last frame).
    pub stamp: String,
}

/// A message on `/scan/report`.
#[derive(Debug, Clone, PartialEq)]
pub enum Report {
    /// A mesher's.
    Mesher(MesherReport),
    /// Another per-camera node's.
    Stage(StageReport),
}

impl Report {
    /// Parses a `/scan/report` message.
    pub fn parse(text: &str) -> Result<Self, String> {
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
        let node = v.get("node").and_then(|n| n.as_str()).ok_or("no \"node\" field")?.to_string();
        let r = if node == "mesher" {
            serde_json::from_value(v).map(Report::Mesher)
        } else {
            serde_json::from_value(v).map(Report::Stage)
        };
        r.map_err(|e| format!("not a {node} report: {e}"))
    }
    /// The scan it is of.
    pub fn scan_id(&self) -> u32 {
        match self {
            Report::Mesher(r) => r.scan_id,
            Report::Stage(r) => r.scan_id,
        }
    }
    /// The camera it is of.
    pub fn camera(&self) -> &str {
        match self {
            Report::Mesher(r) => &r.camera,
            Report::Stage(r) => &r.camera,
        }
    }
}

/// A camera's account of a scan in the merger's `scan_report.json`: its mesher's report, the
/// reports of the nodes before it, and the frames the mesher did not get, told apart.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraAccount {
    /// The mesher's report.
    #[serde(flatten)]
    pub mesher: MesherReport,
    /// Frames lost between the camera_driver and the mesher, neither refused nor skipped.
    pub frames_lost_in_transport: u64,
    /// Frame slots the camera never made (behind its rate).
    pub frames_not_sent: u64,
    /// Frames refused by the edge_detector or triangulator.
    pub frames_refused_upstream: u64,
    /// Frames the camera_driver sent in the scan (none without its report).
    pub frames_sent: Option<u64>,
    /// The refusals' reasons, by node.
    pub refused: BTreeMap<String, BTreeMap<String, Refusal>>,
    /// The other nodes' reports, by node.
    pub upstream: BTreeMap<String, StageReport>,
}

impl CameraAccount {
    /// The account from the camera's mesher report and the other nodes' (by node name):
    /// refused on the way (the edge_detector's and triangulator's refusals), never sent (the
    /// camera_driver's skipped slots), and lost in transport (what the camera_driver sent in
    /// the scan, less what the mesher took or refused and what was refused on the way; without
    /// the camera_driver's report, the mesher's gaps less the other two).
    pub fn new(mesher: MesherReport, upstream: BTreeMap<String, StageReport>) -> Self {
        let refused: u64 = upstream.iter().filter(|(n, _)| *n != "camera_driver").map(|(_, r)| r.frames_refused).sum();
        let driver = upstream.get("camera_driver");
        let not_sent = driver.map_or(0, |d| d.frames_skipped);
        let frames_sent = driver.map(|d| d.frames_sent.unwrap_or(0));
        let in_transport = match frames_sent {
            Some(sent) => sent.saturating_sub(mesher.frames_received + mesher.profiles_refused).saturating_sub(refused),
            None => mesher.frames_lost.saturating_sub(refused + not_sent),
        };
        Self {
            mesher,
            frames_lost_in_transport: in_transport,
            frames_not_sent: not_sent,
            frames_refused_upstream: refused,
            frames_sent,
            refused: upstream.iter().map(|(n, r)| (n.clone(), r.refused.clone())).collect(),
            upstream,
        }
    }
}

/// The merger's account of a scan, `scan_<id>/scan_report.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ScanReport {
    /// Each camera's account, of the cameras that reported.
    pub cameras: Vec<CameraAccount>,
    /// Merged cameras that lost frames.
    pub incomplete: Vec<String>,
    /// The cameras in the merge.
    pub merged: Vec<String>,
    /// The cameras with no surface in the merge.
    pub missing: Vec<String>,
    /// The scan.
    pub scan_id: u32,
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_report_is_read_by_its_node_and_a_bad_one_is_named() {
        let stage = r#"{"camera":"cam1","frames_refused":1,"frames_sent":9,"frames_skipped":2,"node":"camera_driver","refused":{"image":{"first":"bad","frames":1}},"scan_id":3}"#;
        let Report::Stage(s) = Report::parse(stage).unwrap() else { panic!("a stage report") };
        assert_eq!((s.frames_sent, s.frames_taken, s.refused["image"].frames), (Some(9), None, 1));
        assert_eq!(serde_json::to_string(&s).unwrap(), stage, "written back as read");
        assert_eq!(Report::parse("{}").unwrap_err(), "no \"node\" field");
        let e = Report::parse(r#"{"node":"mesher","scan_id":"x"}"#).unwrap_err();
        assert!(e.starts_with("not a mesher report: "), "{e}");
        assert!(Report::parse("[").unwrap_err().starts_with("not JSON"));
    }

    #[test]
    fn an_account_tells_apart_refused_never_sent_and_lost_in_transport() {
        let mesher = MesherReport { frames_received: 80, frames_lost: 20, profiles_refused: 1, ..Default::default() };
        let stage = |node: &str, f: fn(&mut StageReport)| {
            let mut r = StageReport { node: node.into(), ..Default::default() };
            f(&mut r);
            (node.to_string(), r)
        };
        let up: BTreeMap<_, _> = [
            stage("camera_driver", |r| (r.frames_sent, r.frames_skipped) = (Some(95), 5)),
            stage("edge_detector", |r| r.frames_refused = 3),
            stage("triangulator", |r| r.frames_refused = 2),
        ]
        .into();
        let a = CameraAccount::new(mesher.clone(), up.clone());
        // 95 sent = 80 received + 1 refused by the mesher + 5 refused on the way + 9 lost.
        assert_eq!((a.frames_refused_upstream, a.frames_not_sent, a.frames_lost_in_transport), (5, 5, 9));
        let mut no_driver = up;
        no_driver.remove("camera_driver");
        // Without the driver: 20 missing in the gaps, less the 5 refused.
        assert_eq!(CameraAccount::new(mesher, no_driver).frames_lost_in_transport, 15);
    }
}
