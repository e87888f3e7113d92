//! The C-arm's pose over time: `table -> carm` samples and interpolation at image stamps.

use crate::geom::{Iso3, Mat3, Quat, Vec3};
use std::collections::VecDeque;

/// `table -> carm` for a C-arm at `travel` metres along Y, the tabletop lowered by `height_m`
/// since calibration, turned by `angle_rad` about Y (the spec's frame definition).
pub fn table_from_carm(travel_m: f64, height_m: f64, angle_rad: f64) -> Iso3 {
    Iso3 { rotation: Mat3::rot_y(angle_rad), translation: Vec3::new(0.0, travel_m, -height_m) }
}

/// Why no pose could be given for a stamp.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PoseError {
    /// No sample has arrived yet.
    #[error("no table -> carm transform received yet")]
    Empty,
    /// The stamp is before the first sample (beyond the allowed extrapolation).
    #[error("stamp {stamp_ns} ns is {gap_ns} ns before the first table -> carm sample")]
    TooEarly {
        /// Requested stamp.
        stamp_ns: i64,
        /// How far before the first sample.
        gap_ns: i64,
    },
    /// The stamp is after the last sample (beyond the allowed extrapolation).
    #[error("stamp {stamp_ns} ns is {gap_ns} ns after the last table -> carm sample")]
    TooLate {
        /// Requested stamp.
        stamp_ns: i64,
        /// How far after the last sample.
        gap_ns: i64,
    },
    /// The samples around the stamp are further apart than allowed.
    #[error("gap of {gap_ns} ns in table -> carm around stamp {stamp_ns} ns")]
    Gap {
        /// Requested stamp.
        stamp_ns: i64,
        /// Distance between the samples that bracket it.
        gap_ns: i64,
    },
}

/// A time-ordered buffer of `table -> carm` samples with linear interpolation (slerp for the
/// rotation), like a tf buffer restricted to one transform.
#[derive(Debug, Clone)]
pub struct PoseTrack {
    samples: VecDeque<(i64, Vec3, Quat)>,
    capacity: usize,
    /// Largest gap between two samples that is interpolated across, ns.
    pub max_gap_ns: i64,
    /// How far beyond the first or last sample a stamp may lie, ns (held constant there).
    pub max_extrapolation_ns: i64,
}

impl Default for PoseTrack {
    fn default() -> Self {
        Self::new(100_000)
    }
}

impl PoseTrack {
    /// An empty track keeping at most `capacity` samples.
    pub fn new(capacity: usize) -> Self {
        Self {
            samples: VecDeque::new(),
            capacity: capacity.max(2),
            max_gap_ns: 500_000_000,
            max_extrapolation_ns: 5_000_000,
        }
    }
    /// Most samples kept.
    pub fn capacity(&self) -> usize {
        self.capacity
    }
    /// Adds a sample; out-of-order samples are inserted in place, an equal stamp replaces.
    pub fn push(&mut self, stamp_ns: i64, t: &Iso3) {
        let entry = (stamp_ns, t.translation, t.quaternion());
        match self.samples.back() {
            Some(&(last, _, _)) if stamp_ns < last => {
                let i = self.samples.partition_point(|s| s.0 < stamp_ns);
                if self.samples.get(i).is_some_and(|s| s.0 == stamp_ns) {
                    self.samples[i] = entry;
                } else {
                    self.samples.insert(i, entry);
                }
            }
            Some(&(last, _, _)) if stamp_ns == last => {
                if let Some(b) = self.samples.back_mut() {
                    *b = entry;
                }
            }
            _ => self.samples.push_back(entry),
        }
        while self.samples.len() > self.capacity {
            self.samples.pop_front();
        }
    }
    /// Drops the samples stamped before `stamp_ns` (keeping the last one before it, so that a
    /// stamp at `stamp_ns` still interpolates).
    pub fn forget_before(&mut self, stamp_ns: i64) {
        while self.samples.len() > 2 && self.samples.get(1).is_some_and(|s| s.0 <= stamp_ns) {
            self.samples.pop_front();
        }
    }
    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }
    /// True when no sample is held.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
    /// Removes every sample.
    pub fn clear(&mut self) {
        self.samples.clear();
    }
    /// The stamp of the newest sample.
    pub fn latest_stamp(&self) -> Option<i64> {
        self.samples.back().map(|s| s.0)
    }
    /// `table -> carm` at `stamp_ns`, extrapolated linearly from the two newest samples when the
    /// stamp is after the newest by at most `max_ahead_ns` (a C-arm travelling at constant speed
    /// is predicted exactly); otherwise as [`PoseTrack::at`].
    pub fn predict(&self, stamp_ns: i64, max_ahead_ns: i64) -> Result<Iso3, PoseError> {
        let n = self.samples.len();
        match (n >= 2, self.samples.back()) {
            (true, Some(b)) if stamp_ns > b.0 && stamp_ns - b.0 <= max_ahead_ns => {
                let a = &self.samples[n - 2];
                let gap_ns = b.0 - a.0;
                if gap_ns <= 0 || gap_ns > self.max_gap_ns {
                    return Err(PoseError::Gap { stamp_ns, gap_ns });
                }
                let t = (stamp_ns - a.0) as f64 / gap_ns as f64;
                Ok(Iso3::from_parts(a.1 + (b.1 - a.1) * t, b.2))
            }
            _ => self.at(stamp_ns),
        }
    }
    /// `table -> carm` at `stamp_ns`.
    pub fn at(&self, stamp_ns: i64) -> Result<Iso3, PoseError> {
        let first = self.samples.front().ok_or(PoseError::Empty)?;
        let last = self.samples.back().ok_or(PoseError::Empty)?;
        if stamp_ns <= first.0 {
            let gap_ns = first.0 - stamp_ns;
            return if gap_ns <= self.max_extrapolation_ns {
                Ok(Iso3::from_parts(first.1, first.2))
            } else {
                Err(PoseError::TooEarly { stamp_ns, gap_ns })
            };
        }
        if stamp_ns >= last.0 {
            let gap_ns = stamp_ns - last.0;
            return if gap_ns <= self.max_extrapolation_ns {
                Ok(Iso3::from_parts(last.1, last.2))
            } else {
                Err(PoseError::TooLate { stamp_ns, gap_ns })
            };
        }
        let i = self.samples.partition_point(|s| s.0 <= stamp_ns);
        let (a, b) = (&self.samples[i - 1], &self.samples[i]);
        let gap_ns = b.0 - a.0;
        if gap_ns > self.max_gap_ns {
            return Err(PoseError::Gap { stamp_ns, gap_ns });
        }
        let t = (stamp_ns - a.0) as f64 / gap_ns as f64;
        Ok(Iso3::from_parts(a.1.lerp(b.1, t), slerp(a.2, b.2, t)))
    }
}

/// Spherical linear interpolation between unit quaternions.
pub fn slerp(a: Quat, b: Quat, t: f64) -> Quat {
    let mut dot = a.x * b.x + a.y * b.y + a.z * b.z + a.w * b.w;
    let mut b = b;
    if dot < 0.0 {
        dot = -dot;
        b = Quat { x: -b.x, y: -b.y, z: -b.z, w: -b.w };
    }
    let (wa, wb) = if dot > 0.9995 {
        (1.0 - t, t)
    } else {
        let theta = dot.acos();
        let s = theta.sin();
        (((1.0 - t) * theta).sin() / s, (t * theta).sin() / s)
    };
    Quat { x: wa * a.x + wb * b.x, y: wa * a.y + wb * b.y, z: wa * a.z + wb * b.z, w: wa * a.w + wb * b.w }.normalized()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forgetting_keeps_what_interpolates_the_stamp() {
        let mut t = PoseTrack::default();
        for k in 0..10 {
            t.push(k * 10_000_000, &table_from_carm(0.001 * k as f64, 0.0, 0.0));
        }
        t.forget_before(45_000_000);
        assert_eq!(t.len(), 6, "40 ms (the last before 45 ms) and the five after it");
        assert!((t.at(45_000_000).unwrap().translation.y - 0.0045).abs() < 1e-12);
        assert!(t.at(30_000_000).is_err(), "forgotten");
        t.forget_before(i64::MAX);
        assert_eq!(t.len(), 2, "the last two are always kept");
    }

    #[test]
    fn prediction_is_exact_at_constant_speed_and_bounded() {
        let mut t = PoseTrack::default();
        for k in 0..5 {
            t.push(k * 10_000_000, &table_from_carm(0.07 * k as f64 * 0.01, 0.0, 0.0));
        }
        let p = t.predict(47_000_000, 10_000_000).unwrap();
        assert!((p.translation.y - 0.07 * 0.047).abs() < 1e-12);
        assert!(t.predict(60_000_000, 10_000_000).is_err(), "beyond the bound");
        let inside = t.predict(25_000_000, 10_000_000).unwrap();
        assert!((inside.translation.y - 0.07 * 0.025).abs() < 1e-12, "interpolated inside");
    }

    #[test]
    fn interpolates_travel_and_angle() {
        let mut tr = PoseTrack::default();
        tr.push(0, &table_from_carm(0.0, 0.0, 0.0));
        tr.push(100_000_000, &table_from_carm(0.007, 0.0, 0.2));
        let p = tr.at(25_000_000).unwrap();
        assert!((p.translation.y - 0.00175).abs() < 1e-12);
        let expect = table_from_carm(0.00175, 0.0, 0.05);
        let q = Vec3::new(0.3, 0.1, 0.2);
        assert!((p.transform_point(q) - expect.transform_point(q)).norm() < 1e-12);
    }

    #[test]
    fn out_of_range_and_gaps_are_errors() {
        let mut tr = PoseTrack::default();
        assert_eq!(tr.at(0), Err(PoseError::Empty));
        tr.push(1_000_000_000, &Iso3::IDENTITY);
        tr.push(3_000_000_000, &Iso3::IDENTITY);
        assert!(matches!(tr.at(0), Err(PoseError::TooEarly { .. })));
        assert!(matches!(tr.at(4_000_000_000), Err(PoseError::TooLate { .. })));
        assert!(matches!(tr.at(2_000_000_000), Err(PoseError::Gap { gap_ns: 2_000_000_000, .. })));
        assert!(tr.at(1_000_000_001).is_err());
        assert!(tr.at(999_000_000 + 1_000_000).is_ok());
    }

    #[test]
    fn out_of_order_samples_are_sorted() {
        let mut tr = PoseTrack::default();
        for s in [3, 1, 2] {
            tr.push(s * 10, &table_from_carm(s as f64, 0.0, 0.0));
        }
        assert!((tr.at(15).unwrap().translation.y - 1.5).abs() < 1e-12);
    }
}
