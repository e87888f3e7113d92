//! A per-camera node's account of one scan, published on `/scan/report` 0.3 s after its END or
//! ABORT (or at the next START), next to the mesher's: what the node did with the frames
//! stamped in the scan (sent by the camera_driver; refused by the edge_detector or
//! triangulator, and why). The merger puts them
//! under the camera's report, so that a frame the mesher did not get is told apart: refused on
//! the way (and why), never sent (a camera behind its frame rate), or lost in transport.

use std::collections::BTreeMap;
use std::sync::Arc;
use xsurf_msgs::std_msgs::StringMsg;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_runtime::component::Msg;

use crate::scan_report::{Refusal, StageReport};

/// The per-camera nodes before the mesher, each counting its frames: the camera_driver those
/// sent (`frames_sent`), the edge_detector those taken (`frames_taken`), the triangulator those
/// placed (`frames_placed`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) enum Stage {
    /// The camera_driver.
    #[default]
    CameraDriver,
    /// The edge_detector.
    EdgeDetector,
    /// The triangulator.
    Triangulator,
}

impl Stage {
    /// The node's name.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Stage::CameraDriver => "camera_driver",
            Stage::EdgeDetector => "edge_detector",
            Stage::Triangulator => "triangulator",
        }
    }
}

/// Refusal reasons kept per scan, each with its count and first message.
const MAX_REASONS: usize = 8;

/// Frames remembered between scans: a frame stamped after START may arrive before the START
/// event does (the image and the event take different paths), and is still the scan's.
const BETWEEN_SCANS: usize = 64;

/// Stamps of frames, and a few of their messages.
#[derive(Debug, Default)]
struct Stamps {
    stamps: std::collections::VecDeque<i64>,
    /// The first messages (`(stamp, message)`), for a refusal's reason.
    first: Vec<(i64, String)>,
}

impl Stamps {
    /// A frame at `stamp`; `start`: the running scan's START stamp (a frame stamped before it
    /// is none of the scan's); `between`: no scan runs or awaits its report (only the last
    /// [`BETWEEN_SCANS`] are kept).
    fn push(&mut self, stamp: i64, message: Option<&str>, start: Option<i64>, between: bool) {
        if start.is_some_and(|s| stamp < s) {
            return;
        }
        self.stamps.push_back(stamp);
        if between && self.stamps.len() > BETWEEN_SCANS {
            self.stamps.pop_front();
        }
        if let Some(m) = message.filter(|_| self.first.len() < 4) {
            self.first.push((stamp, m.to_string()));
        }
    }
    /// Keeps what is stamped from `start` on.
    fn start(&mut self, start: i64) {
        self.stamps.retain(|&t| t >= start);
        self.first.retain(|(t, _)| *t >= start);
    }
    /// Frames stamped before `end` (and from the scan's START on: see `start`).
    fn before(&self, end: i64) -> usize {
        self.stamps.iter().filter(|&&t| t < end).count()
    }
}

/// After END or ABORT, frames stamped before it are still counted for this long (they were
/// exposed in the scan and are on their way), as the mesher's `end_grace_s` default.
pub(crate) const GRACE_NS: i64 = 300_000_000;

/// One node's frames of the current scan.
#[derive(Debug, Default)]
pub(crate) struct ScanTally {
    /// `(scan id, START stamp)` while a scan runs.
    scan: Option<(u32, i64)>,
    /// END or ABORT seen, the report not yet made: `(scan id, END stamp)`.
    ending: Option<(u32, i64)>,
    /// The report's labels: the node, the camera.
    labels: (Stage, String),
    /// The frames counted (sent, taken, placed).
    counted: Stamps,
    /// Frame slots skipped (a camera behind its rate).
    skipped: Stamps,
    /// The frames refused, by reason.
    refused: BTreeMap<&'static str, Stamps>,
}

impl ScanTally {
    /// Follows a scan event of `node` for `camera`. The report of a scan is made [`GRACE_NS`] after its END or ABORT
    /// (see [`ScanTally::due`]), or at the next START; a START returns the last scan's report
    /// if it was still waiting.
    pub(crate) fn event(&mut self, e: &ScanEvent, node: Stage, camera: &str) -> Option<Msg> {
        self.labels = (node, camera.to_string());
        let stamp = e.header.stamp.nanos();
        match e.event {
            ScanEvent::START => {
                let last = self.report();
                self.scan = Some((e.scan_id, stamp));
                self.counted.start(stamp);
                self.skipped.start(stamp);
                self.refused.values_mut().for_each(|r| r.start(stamp));
                self.refused.retain(|_, r| !r.stamps.is_empty());
                last
            }
            ScanEvent::END | ScanEvent::ABORT => {
                if let Some((id, _)) = self.scan.take() {
                    self.ending = Some((id, stamp));
                }
                None
            }
            _ => None,
        }
    }
    /// The report of the scan that ended, once `now_ns` is [`GRACE_NS`] past its END.
    pub(crate) fn due(&mut self, now_ns: i64) -> Option<Msg> {
        if self.ending.is_some_and(|(_, end)| now_ns >= end.saturating_add(GRACE_NS)) {
            self.report()
        } else {
            None
        }
    }
    /// The report of the scan that ended, now (at shutdown, or at the next START).
    pub(crate) fn report(&mut self) -> Option<Msg> {
        let (id, stamp) = self.ending.take()?;
        let mut refused = BTreeMap::new();
        for (why, r) in &self.refused {
            let frames = r.before(stamp) as u64;
            if frames > 0 {
                let first = r.first.iter().find(|(t, _)| *t < stamp).map(|(_, m)| m.clone());
                refused.insert(why.to_string(), Refusal { first, frames });
            }
        }
        let (node, camera) = self.labels.clone();
        let counted = Some(self.counted.before(stamp) as u64);
        let mut report = StageReport {
            camera,
            frames_refused: refused.values().map(|r| r.frames).sum(),
            frames_skipped: self.skipped.before(stamp) as u64,
            node: node.name().to_string(),
            refused,
            scan_id: id,
            ..StageReport::default()
        };
        match node {
            Stage::CameraDriver => report.frames_sent = counted,
            Stage::EdgeDetector => report.frames_taken = counted,
            Stage::Triangulator => report.frames_placed = counted,
        }
        // What came after the END stamp may be the next scan's (its START not yet seen).
        self.counted.start(stamp);
        self.skipped.start(stamp);
        self.refused.values_mut().for_each(|r| r.start(stamp));
        let data = serde_json::to_string(&report).unwrap_or_default();
        Some(Msg::Text(Arc::new(StringMsg { data })))
    }
    fn start(&self) -> Option<i64> {
        self.scan.map(|(_, s)| s)
    }
    fn between(&self) -> bool {
        self.scan.is_none() && self.ending.is_none()
    }
    /// A frame at `stamp` done (sent, taken, placed).
    pub(crate) fn count(&mut self, stamp: i64) {
        self.counted.push(stamp, None, self.start(), self.between());
    }
    /// `n` frame slots at `stamp` that were never made (a camera behind its rate).
    pub(crate) fn skip(&mut self, stamp: i64, n: u64) {
        for _ in 0..n.min(1 << 16) {
            self.skipped.push(stamp, None, self.start(), self.between());
        }
    }
    /// A frame at `stamp` refused for `why` (a short class: `image`, `line`); `message` is the
    /// node's error, kept for the first few of each class.
    pub(crate) fn refuse(&mut self, stamp: i64, why: &'static str, message: &str) {
        if !self.refused.contains_key(why) && self.refused.len() >= MAX_REASONS {
            return;
        }
        let (start, between) = (self.start(), self.between());
        self.refused.entry(why).or_default().push(stamp, Some(message), start, between);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn event(kind: u8, id: u32, sec: i32) -> ScanEvent {
        let mut e = ScanEvent { scan_id: id, event: kind, ..Default::default() };
        e.header.stamp.sec = sec;
        e
    }

    #[test]
    fn counts_only_the_frames_stamped_in_the_scan() {
        let s = 1_000_000_000;
        let mut t = ScanTally::default();
        t.count(5 * s); // before any scan
        t.count(10 * s); // the scan's first frame, before its START event arrives
        assert!(t.event(&event(ScanEvent::START, 4, 10), Stage::CameraDriver, "cam1").is_none());
        t.count(9 * s); // exposed before START
        t.count(11 * s);
        t.count(12 * s);
        t.skip(13 * s, 2);
        t.refuse(12 * s, "image", "image at 12: bad");
        t.refuse(12 * s, "image", "image at 12: worse");
        t.count(21 * s); // after the END stamp, counted before END arrived
        assert!(t.event(&event(ScanEvent::END, 4, 20), Stage::CameraDriver, "cam1").is_none());
        t.count(19 * s); // exposed in the scan, arriving after its END
        for _ in 0..2 * BETWEEN_SCANS {
            t.count(21 * s); // the next scan's, before its START: none of this one's frames go
        }
        assert!(t.due(20 * s + GRACE_NS - 1).is_none(), "the report waits for the late frames");
        let Some(Msg::Text(r)) = t.due(20 * s + GRACE_NS) else { panic!("a report after END") };
        let r: serde_json::Value = serde_json::from_str(&r.data).unwrap();
        assert_eq!(r["scan_id"], 4);
        assert_eq!(r["node"], "camera_driver");
        assert_eq!(r["frames_sent"], 4);
        assert_eq!(r["frames_skipped"], 2);
        assert_eq!(r["frames_refused"], 2);
        assert_eq!(r["refused"]["image"]["first"], "image at 12: bad");
        // No scan: nothing to report.
        assert!(t.event(&event(ScanEvent::END, 4, 30), Stage::CameraDriver, "cam1").is_none());
        assert!(t.due(40 * s).is_none() && t.report().is_none());
    }
}
