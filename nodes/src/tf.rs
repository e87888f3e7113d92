//! The part of tf the scanner needs: static transforms (with chains through them) and the
//! moving `table -> carm`, interpolated at image stamps.

use crate::convert;
use std::collections::HashMap;
use xsurf_core::geom::Iso3;
use xsurf_core::pose::{PoseError, PoseTrack};
use xsurf_msgs::tf2_msgs::TFMessage;

/// Static transforms plus the `table -> carm` track.
#[derive(Debug, Clone)]
pub struct TfBuffer {
    /// Name of the table frame.
    pub table_frame: String,
    /// Name of the C-arm frame.
    pub carm_frame: String,
    statics: HashMap<String, (String, Iso3)>,
    track: PoseTrack,
}

impl TfBuffer {
    /// An empty buffer.
    pub fn new(table_frame: &str, carm_frame: &str, max_gap_ns: i64) -> Self {
        Self::with_capacity(table_frame, carm_frame, max_gap_ns, PoseTrack::default().capacity())
    }
    /// An empty buffer keeping at most `capacity` poses.
    pub fn with_capacity(table_frame: &str, carm_frame: &str, max_gap_ns: i64, capacity: usize) -> Self {
        let mut track = PoseTrack::new(capacity);
        track.max_gap_ns = max_gap_ns;
        Self { table_frame: table_frame.into(), carm_frame: carm_frame.into(), statics: HashMap::new(), track }
    }
    /// Adds the transforms of a `/tf_static` message. A transform that is not rigid (see
    /// [`convert::rigid`]) is refused and the others are kept; the error names the refused ones.
    pub fn add_static(&mut self, m: &TFMessage) -> Result<(), String> {
        let mut refused = Vec::new();
        for t in &m.transforms {
            match convert::rigid(t) {
                Ok(iso) => {
                    self.statics.insert(
                        t.child_frame_id.trim_start_matches('/').to_string(),
                        (t.header.frame_id.trim_start_matches('/').to_string(), iso),
                    );
                }
                Err(e) => refused.push(e),
            }
        }
        refusal(refused, m.transforms.len())
    }
    /// Adds the `table -> carm` samples of a `/tf` message (other transforms are ignored). A
    /// sample that is not rigid is refused, the others are kept; the error names the refused.
    pub fn add_dynamic(&mut self, m: &TFMessage) -> Result<(), String> {
        let mut refused = Vec::new();
        for t in &m.transforms {
            if t.header.frame_id.trim_start_matches('/') == self.table_frame
                && t.child_frame_id.trim_start_matches('/') == self.carm_frame
            {
                match convert::rigid(t) {
                    Ok(iso) => self.track.push(t.header.stamp.nanos(), &iso),
                    Err(e) => refused.push(e),
                }
            }
        }
        refusal(refused, m.transforms.len())
    }
    /// Forgets the `table -> carm` poses stamped before `stamp_ns` (see
    /// [`PoseTrack::forget_before`]).
    pub fn forget_before(&mut self, stamp_ns: i64) {
        self.track.forget_before(stamp_ns);
    }
    /// The newest `table -> carm` stamp.
    pub fn latest_pose_stamp(&self) -> Option<i64> {
        self.track.latest_stamp()
    }
    /// `table -> carm` at a stamp, extrapolated up to `max_ahead_ns` past the newest sample.
    pub fn predict_table_from_carm(&self, stamp_ns: i64, max_ahead_ns: i64) -> Result<Iso3, PoseError> {
        self.track.predict(stamp_ns, max_ahead_ns)
    }
    /// `table -> carm` at a stamp.
    pub fn table_from_carm(&self, stamp_ns: i64) -> Result<Iso3, PoseError> {
        self.track.at(stamp_ns)
    }
    /// `carm -> frame` through the static transforms (`None` when no chain leads there).
    pub fn carm_from(&self, frame: &str) -> Option<Iso3> {
        let mut t = Iso3::IDENTITY;
        let mut f = frame.trim_start_matches('/').to_string();
        for _ in 0..16 {
            if f == self.carm_frame {
                return Some(t);
            }
            let (parent, p_from_f) = self.statics.get(&f)?;
            t = p_from_f.compose(&t);
            f = parent.clone();
        }
        None
    }
    /// Forgets the moving pose (a new scan).
    pub fn clear_dynamic(&mut self) {
        self.track.clear();
    }
}

/// The error of a TF message some of whose `total` transforms were refused.
fn refusal(refused: Vec<String>, total: usize) -> Result<(), String> {
    match refused.len() {
        0 => Ok(()),
        n => Err(format!("{n} of {total} transform(s) refused (the rest kept): {}", refused.join("; "))),
    }
}
