//! Outputs published again between scans, for viewers that join late.

use xsurf_runtime::component::{Msg, Outbox};

/// Outputs published again at a fixed period until cleared, as a latched topic would be for
/// viewers that join late or lose a large best-effort message (the mesher's and merger's
/// results between scans).
pub(crate) struct Republisher<O> {
    /// Output and message.
    msgs: Vec<(O, Msg)>,
    /// When they were last published (set at the first tick after `set`).
    last_ns: Option<i64>,
}

impl<O> Default for Republisher<O> {
    fn default() -> Self {
        Republisher { msgs: Vec::new(), last_ns: None }
    }
}

impl<O: Copy> Republisher<O> {
    /// Remembers the messages just published.
    pub(crate) fn set(&mut self, msgs: Vec<(O, Msg)>) {
        self.msgs = msgs;
        self.last_ns = None;
    }
    /// Forgets them (a new scan).
    pub(crate) fn clear(&mut self) {
        self.msgs.clear();
    }
    /// Publishes them again when `period_ns` has passed (`None`: never).
    pub(crate) fn tick<I>(&mut self, period_ns: Option<i64>, now_ns: i64, out: &mut Outbox<I, O>) {
        let Some(period) = period_ns else { return };
        if self.msgs.is_empty() {
            return;
        }
        match self.last_ns {
            Some(t) if now_ns - t < period => {}
            Some(_) => {
                self.last_ns = Some(now_ns);
                for (i, m) in &self.msgs {
                    out.publish(*i, m.clone());
                }
            }
            None => self.last_ns = Some(now_ns),
        }
    }
}
