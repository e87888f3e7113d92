//! `c_arm_pose`: the C-arm's pose: `table -> carm` on `/tf` and `/joint_states` (`carm_travel`,
//! `carm_angle`), the cameras' `carm -> <cam>_optical_frame` on `/tf_static` from the rig, and
//! `/scan/events` START / END / ABORT.
//!
//! `mode: speed` models the travel (`speed` from `travel_start_m` to `travel_end_m`, at
//! `rate_hz`); a scan starts by itself (`auto_start`) or on a START request and ends at
//! `travel_end_m` or on an END request. `mode: encoder` follows the scanner controller's position
//! feed (`sensor_msgs/JointState` on `/carm/encoder`, joint `encoder_joint`): every sample becomes
//! a `/tf` at its own stamp; a scan starts on a START request or (with `auto_start`) when the
//! C-arm moves; it ends with END when the C-arm stops within `end_tolerance_m` of
//! `travel_end_m` (or on an END request), and with ABORT when it stops elsewhere (a stall) or the
//! feed falls silent for `max_gap_s` (a pose gap). Requests are `xsurf_msgs/ScanEvent` messages
//! on `/scan/request` (event START, END or ABORT), from the hospital stack or
//! `ros2 topic pub`.
//!
//! With `follow_placements` (the default) the cameras' placements refined by the merger
//! (`/surface/placements`, `carm -> <cam>_optical_frame`) replace the rig's between scans, and
//! `/tf_static` is published again: `c_arm_pose` stays the one source of the static transforms,
//! and the next scans are triangulated through the refined placements. (The merger's
//! `save_rig_file` keeps them across restarts.)

mod params;
pub use params::*;

/// The node type, as the registry lists it.
pub const NODE: crate::registry::NodeType =
    crate::registry::NodeType::of::<CArmPoseParams>("c_arm_pose", crate::registry::Role::Source, 2, |p| Ok(boxed(CArmPoseNode::new(p)?)));

use crate::convert;
use std::path::PathBuf;
use std::sync::Arc;
use xsurf_core::geom::Iso3;
use xsurf_core::pose::table_from_carm;
use xsurf_core::rig::Rig;
use xsurf_msgs::sensor_msgs::JointState as JointStateMsg;
use xsurf_msgs::sensor_msgs::JointState;
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{boxed, Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{NodeParams, ParamError, Params};

struct Config {
    encoder: bool,
    joint: String,
    motion_m: f64,
    stop_ns: i64,
    end_tol_m: f64,
    max_gap_ns: i64,
    speed: f64,
    start: f64,
    end: f64,
    auto_start: bool,
    delay_ns: i64,
    scan_id: u32,
    period_ns: i64,
    rig: Rig,
    table_frame: String,
    carm_frame: String,
    follow_placements: bool,
    rig_file: Option<PathBuf>,
}

fn config(p: &Params) -> Result<Config, ParamError> {
    let p = CArmPoseParams::from_params(p)?;
    let speed = p.speed;
    if !xsurf_core::limits::speed_ok(speed) {
        let (lo, hi) = xsurf_core::limits::SPEED_MPS;
        return Err(Params::invalid("speed", format!("{speed:?} m/s is not in ({lo:?}, {hi:?})")));
    }
    let rig = match &p.rig_file {
        None => Rig::study(640, 480),
        Some(f) => xsurf_formats::rig::read(f).map_err(|e| Params::invalid("rig_file", e.to_string()))?,
    };
    let positive = |n: &str, v: f64| -> Result<f64, ParamError> {
        if !(v > 0.0 && v.is_finite()) {
            return Err(Params::invalid(n, format!("{v} must be positive")));
        }
        Ok(v)
    };
    Ok(Config {
        encoder: p.mode == Mode::Encoder,
        joint: p.encoder_joint,
        motion_m: positive("motion_threshold_m", p.motion_threshold_m)?,
        stop_ns: (positive("stop_time_s", p.stop_time_s)? * 1e9) as i64,
        end_tol_m: positive("end_tolerance_m", p.end_tolerance_m)?,
        max_gap_ns: (positive("max_gap_s", p.max_gap_s)? * 1e9) as i64,
        speed,
        start: p.travel_start_m,
        end: p.travel_end_m,
        auto_start: p.auto_start,
        delay_ns: (p.start_delay_s.max(0.0) * 1e9) as i64,
        scan_id: p.scan_id,
        period_ns: (1e9 / p.rate_hz) as i64,
        rig,
        table_frame: p.table_frame,
        carm_frame: p.carm_frame,
        follow_placements: p.follow_placements,
        rig_file: p.rig_file,
    })
}

/// Where the node is in its scans.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Scan {
    /// No scan yet.
    Idle,
    /// Speed mode: a scan starts at this stamp (an automatic start, or a START request).
    Scheduled(i64),
    /// A scan runs since this stamp (speed mode measures the travel from it).
    Running(i64),
    /// The last scan ended; speed mode: the C-arm stands where an END or ABORT request stopped
    /// it, or (None) at `travel_end_m`.
    Ended(Option<f64>),
}

/// The C-arm pose component.
pub struct CArmPoseNode {
    cfg: Config,
    scan: Scan,
    last_pub: i64,
    statics_sent: bool,
    scans: u64,
    aborts: u64,
    scan_id: u32,
    /// Encoder mode: the newest sample (stamp, travel, angle) and the last movement.
    encoder: Option<(i64, f64, f64)>,
    rest: Option<(i64, f64)>,
    start_requested: bool,
    bad_samples: u64,
    /// Refined placements received (rig camera index, `carm -> optical`), applied between scans.
    placements: Vec<(usize, Iso3)>,
    placements_applied: u64,
}

/// The C-arm pose node's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `/scan/request`: START, END or ABORT asked for by the hospital stack.
    Request,
    /// `/carm/encoder`: the scanner controller's position feed (`mode: encoder`).
    Encoder,
    /// `/surface/placements`: the cameras' placements refined by the merger.
    Placements,
}

/// The C-arm pose node's outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `/tf`: `table -> carm`.
    Tf,
    /// `/tf_static`: `carm -> <cam>_optical_frame` of every rig camera.
    TfStatic,
    /// `/joint_states`: `carm_travel`, `carm_angle`.
    Joints,
    /// `/scan/events`: START, END, ABORT.
    Events,
}

type Out = Outbox<Input, Output>;

impl CArmPoseNode {
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        let cfg = config(p)?;
        Ok(Self {
            scan_id: cfg.scan_id,
            cfg,
            scan: Scan::Idle,
            last_pub: i64::MIN,
            statics_sent: false,
            scans: 0,
            aborts: 0,
            encoder: None,
            rest: None,
            start_requested: false,
            bad_samples: 0,
            placements: Vec::new(),
            placements_applied: 0,
        })
    }

    /// `carm -> <cam>_optical_frame` of every rig camera on `/tf_static`.
    fn publish_statics(&self, now: i64, out: &mut Out) {
        let tf = TFMessage {
            transforms: self
                .cfg
                .rig
                .cameras
                .iter()
                .map(|c| {
                    convert::transform_stamped(
                        now,
                        &self.cfg.carm_frame,
                        &format!("{}_optical_frame", c.name),
                        &c.carm_from_optical(),
                    )
                })
                .collect(),
        };
        out.publish(Output::TfStatic, Msg::Tf(Arc::new(tf)));
    }

    /// Takes the refined placements of a `/surface/placements` message (applied between scans).
    /// A transform from another parent, to a frame that is no rig camera's, or with a rotation
    /// that is no unit quaternion refuses the whole message.
    fn take_placements(&mut self, m: &TFMessage) -> Result<(), NodeError> {
        let mut taken = Vec::new();
        for t in &m.transforms {
            let (parent, child) = (t.header.frame_id.trim_start_matches('/'), t.child_frame_id.trim_start_matches('/'));
            if parent != self.cfg.carm_frame {
                return Err(NodeError::contradicts(format!(
                    "/surface/placements: transform to {child} is from {parent:?}, not from {:?}",
                    self.cfg.carm_frame
                )));
            }
            let cam = child
                .strip_suffix("_optical_frame")
                .and_then(|n| self.cfg.rig.cameras.iter().position(|c| c.name == n));
            let Some(cam) = cam else {
                return Err(NodeError::contradicts(format!(
                    "/surface/placements: {child} is not a rig camera's optical frame"
                )));
            };
            let iso = convert::rigid(t).map_err(|e| NodeError::malformed(format!("/surface/placements: {e}")))?;
            taken.push((cam, iso));
        }
        self.placements.extend(taken);
        Ok(())
    }
    fn scanning(&self) -> bool {
        matches!(self.scan, Scan::Running(_))
    }
    /// Speed mode: the travel at `now`.
    fn travel(&self, now: i64) -> f64 {
        let dir = (self.cfg.end - self.cfg.start).signum();
        match self.scan {
            Scan::Running(t0) if now > t0 => {
                let t = self.cfg.start + dir * self.cfg.speed * (now - t0) as f64 * 1e-9;
                if dir >= 0.0 {
                    t.min(self.cfg.end)
                } else {
                    t.max(self.cfg.end)
                }
            }
            Scan::Ended(at) => at.unwrap_or(self.cfg.end),
            _ => self.cfg.start,
        }
    }
    fn event(&self, now: i64, event: u8) -> Msg {
        Msg::ScanEvent(Arc::new(ScanEvent {
            header: convert::header(now, &self.cfg.table_frame),
            scan_id: self.scan_id,
            event,
        }))
    }

    /// Ends the current scan with `event` (END or ABORT) at `stamp`; speed mode: the C-arm
    /// stands at `at` (None: at the end of travel).
    fn finish_scan(&mut self, stamp: i64, event: u8, why: &str, at: Option<f64>, out: &mut Out) {
        if !self.scanning() {
            return;
        }
        self.scan = Scan::Ended(at);
        if event == ScanEvent::END {
            self.scans += 1;
            log::info!("c_arm_pose: scan {} ended ({why})", self.scan_id);
        } else {
            self.aborts += 1;
            log::warn!("c_arm_pose: scan {} aborted: {why}", self.scan_id);
        }
        out.publish(Output::Events, self.event(stamp, event));
        self.scan_id += 1;
    }

    fn begin_scan(&mut self, stamp: i64, out: &mut Out) {
        if self.scanning() {
            return;
        }
        self.scan = Scan::Running(stamp);
        out.publish(Output::Events, self.event(stamp, ScanEvent::START));
    }

    fn publish_pose(&self, stamp: i64, travel: f64, angle: f64, velocity: f64, out: &mut Out) {
        let pose = table_from_carm(travel, 0.0, angle);
        out.publish(
            Output::Tf,
            Msg::Tf(Arc::new(TFMessage {
                transforms: vec![convert::transform_stamped(stamp, &self.cfg.table_frame, &self.cfg.carm_frame, &pose)],
            })),
        );
        let js = JointStateMsg {
            header: convert::header(stamp, ""),
            name: vec!["carm_travel".into(), "carm_angle".into()],
            position: vec![travel, angle],
            velocity: vec![velocity, 0.0],
            effort: vec![],
        };
        out.publish(Output::Joints, Msg::JointState(Arc::new(js)));
    }

    /// One encoder sample.
    fn encoder_sample(&mut self, m: &JointStateMsg, out: &mut Out) -> Result<(), NodeError> {
        let i = m.name.iter().position(|n| *n == self.cfg.joint).ok_or_else(|| {
            self.bad_samples += 1;
            NodeError::malformed(format!("/carm/encoder: no joint {:?} in {:?}", self.cfg.joint, m.name))
        })?;
        let travel = m.position.get(i).copied().filter(|v| v.is_finite()).ok_or_else(|| {
            self.bad_samples += 1;
            NodeError::malformed(format!("/carm/encoder: joint {:?} has no finite position", self.cfg.joint))
        })?;
        let angle =
            m.name.iter().position(|n| n == "carm_angle").and_then(|j| m.position.get(j).copied()).unwrap_or(0.0);
        let stamp = m.header.stamp.nanos();
        let velocity = match self.encoder {
            Some((t0, x0, _)) if stamp > t0 => (travel - x0) / ((stamp - t0) as f64 * 1e-9),
            _ => 0.0,
        };
        self.encoder = Some((stamp, travel, angle));
        self.publish_pose(stamp, travel, angle, velocity, out);
        // Movement: the rest point moves with the C-arm; standing still keeps its stamp.
        let moved = match self.rest {
            Some((_, x)) => (travel - x).abs() >= self.cfg.motion_m,
            None => false,
        };
        if self.rest.is_none() || moved {
            let was_at_rest = self.rest.is_some();
            self.rest = Some((stamp, travel));
            if moved && was_at_rest && !self.scanning() && (self.cfg.auto_start || self.start_requested) {
                self.start_requested = false;
                self.begin_scan(stamp, out);
            }
        } else if let Some((t_rest, _)) = self.rest {
            if self.scanning() && stamp - t_rest >= self.cfg.stop_ns {
                if (travel - self.cfg.end).abs() <= self.cfg.end_tol_m {
                    self.finish_scan(stamp, ScanEvent::END, "the C-arm stopped at the end of travel", None, out);
                } else {
                    let why =
                        format!("stall: the C-arm stopped at {travel:.4} m, not at the end {:.4} m", self.cfg.end);
                    self.finish_scan(stamp, ScanEvent::ABORT, &why, None, out);
                }
            }
        }
        Ok(())
    }
}

impl Component for CArmPoseNode {
    type Input = Input;
    type Output = Output;
    fn node_name(&self) -> &'static str {
        "c_arm_pose"
    }
    fn inputs(&self) -> Vec<(Input, Port)> {
        vec![
            (Input::Request, Port::new("/scan/request", ScanEvent::TYPE_NAME, QosClass::Reliable)),
            (Input::Encoder, Port::new("/carm/encoder", JointState::TYPE_NAME, QosClass::Reliable)),
            (Input::Placements, Port::new("/surface/placements", TFMessage::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn outputs(&self) -> Vec<(Output, Port)> {
        vec![
            (Output::Tf, Port::new("/tf", TFMessage::TYPE_NAME, QosClass::Reliable)),
            (Output::TfStatic, Port::new("/tf_static", TFMessage::TYPE_NAME, QosClass::Static)),
            (Output::Joints, Port::new("/joint_states", JointState::TYPE_NAME, QosClass::Reliable)),
            (Output::Events, Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable)),
        ]
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        let mut c = config(p)?;
        if self.scanning() {
            return Err(Params::invalid("c_arm_pose", "parameters cannot change during a scan"));
        }
        // The same rig file: the placements followed so far stay.
        if c.rig_file == self.cfg.rig_file {
            c.rig = self.cfg.rig.clone();
        }
        self.cfg = c;
        Ok(())
    }
    fn handle(&mut self, i: Input, m: &Msg, out: &mut Out) -> Result<(), NodeError> {
        match (i, m) {
            (Input::Request, Msg::ScanEvent(e)) => {
                let stamp = e.header.stamp.nanos();
                match e.event {
                    ScanEvent::START if self.cfg.encoder => {
                        // Starts now if the C-arm is moving, else at its first movement.
                        self.start_requested = true;
                    }
                    ScanEvent::START => {
                        if !self.scanning() {
                            self.scan = Scan::Scheduled(stamp);
                        }
                    }
                    ScanEvent::END | ScanEvent::ABORT => {
                        let (event, why) = if e.event == ScanEvent::END {
                            (ScanEvent::END, "END requested")
                        } else {
                            (ScanEvent::ABORT, "ABORT requested")
                        };
                        let at = (!self.cfg.encoder).then(|| self.travel(stamp));
                        self.finish_scan(stamp, event, why, at, out);
                    }
                    other => return Err(NodeError::malformed(format!("/scan/request: unknown event {other}"))),
                }
                Ok(())
            }
            (Input::Encoder, Msg::JointState(js)) if self.cfg.encoder => self.encoder_sample(js, out),
            (Input::Encoder, Msg::JointState(_)) => Ok(()),
            (Input::Placements, Msg::Tf(t)) if self.cfg.follow_placements => self.take_placements(t),
            (Input::Placements, Msg::Tf(_)) => Ok(()),
            (i, m) => Err(NodeError::unexpected(i, m)),
        }
    }
    fn tick(&mut self, now: i64, out: &mut Out) {
        if !self.scanning() && !self.placements.is_empty() {
            for (cam, e) in std::mem::take(&mut self.placements) {
                let c = &mut self.cfg.rig.cameras[cam];
                c.set_carm_from_optical(&e);
                log::info!("c_arm_pose: {} placed as refined by the merger", c.name);
                self.placements_applied += 1;
            }
            if self.statics_sent {
                self.publish_statics(now, out);
            }
        }
        if !self.statics_sent {
            self.statics_sent = true;
            self.publish_statics(now, out);
            if self.cfg.auto_start && !self.cfg.encoder && !self.scanning() {
                self.scan = Scan::Scheduled(now + self.cfg.delay_ns);
            }
        }
        if self.cfg.encoder {
            if let Some((t, _, _)) = self.encoder {
                if self.scanning() && now - t > self.cfg.max_gap_ns {
                    let why = format!("pose gap: no /carm/encoder sample for {:.3} s", (now - t) as f64 * 1e-9);
                    self.finish_scan(now, ScanEvent::ABORT, &why, None, out);
                }
            }
            return;
        }
        if let Scan::Scheduled(t0) = self.scan {
            if now >= t0 {
                self.scan = Scan::Running(t0);
                out.publish(Output::Events, self.event(t0, ScanEvent::START));
            }
        }
        if now.saturating_sub(self.last_pub) >= self.cfg.period_ns {
            self.last_pub = now;
            let travel = self.travel(now);
            let v = if self.scanning() { self.cfg.speed } else { 0.0 };
            self.publish_pose(now, travel, 0.0, v, out);
            if self.scanning() && (travel - self.cfg.end).abs() < 1e-12 {
                self.finish_scan(now, ScanEvent::END, "travel_end_m reached", None, out);
            }
        }
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("scans", self.scans),
            ("aborts", self.aborts),
            ("bad_samples", self.bad_samples),
            ("placements_applied", self.placements_applied),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::{build, declarations};
    use std::cell::RefCell;
    use std::rc::Rc;
    use xsurf_runtime::params::ParamValue as V;
    use xsurf_runtime::router::Router;

    type Seen = Rc<RefCell<Vec<(String, Msg)>>>;

    fn node(set: &[(&str, V)]) -> (Router, Seen) {
        let o = set.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
        let p = Params::resolve(&declarations("c_arm_pose").unwrap(), &o).unwrap();
        let mut r = Router::new();
        r.add(build("c_arm_pose", &p).unwrap(), "c_arm_pose", "/", &[]);
        let seen: Seen = Rc::default();
        let s = seen.clone();
        r.set_tap(Box::new(move |t, m| s.borrow_mut().push((t.to_string(), m.clone()))));
        (r, seen)
    }

    fn events(seen: &Seen) -> Vec<(u32, u8, i64)> {
        seen.borrow()
            .iter()
            .filter_map(|(_, m)| match m {
                Msg::ScanEvent(e) => Some((e.scan_id, e.event, e.header.stamp.nanos())),
                _ => None,
            })
            .collect()
    }

    fn request(r: &mut Router, t: i64, event: u8) {
        let e = ScanEvent { header: convert::header(t, "table"), scan_id: 0, event };
        r.publish("/scan/request", &Msg::ScanEvent(Arc::new(e)));
    }

    fn encoder(r: &mut Router, t: i64, travel: f64) {
        let js = JointStateMsg {
            header: convert::header(t, ""),
            name: vec!["carm_travel".into()],
            position: vec![travel],
            ..Default::default()
        };
        r.publish("/carm/encoder", &Msg::JointState(Arc::new(js)));
    }

    const MS: i64 = 1_000_000;

    fn statics(seen: &Seen) -> Vec<Vec<(String, Iso3)>> {
        seen.borrow()
            .iter()
            .filter_map(|(t, m)| match m {
                Msg::Tf(tf) if t == "/tf_static" => {
                    Some(tf.transforms.iter().map(|x| (x.child_frame_id.clone(), convert::iso(&x.transform))).collect())
                }
                _ => None,
            })
            .collect()
    }

    fn placements(child: &str, e: &Iso3) -> Msg {
        Msg::Tf(Arc::new(TFMessage { transforms: vec![convert::transform_stamped(0, "carm", child, e)] }))
    }

    /// In a composed graph with c_arm_pose, the transforms and scan events it publishes are
    /// still taken from outside too (a hospital controller's events, another tf publisher);
    /// its other outputs are not.
    #[test]
    fn a_composed_graph_takes_tf_and_scan_events_from_outside_as_well() {
        let mut r = Router::new();
        for (node, ns) in [("c_arm_pose", "/"), ("triangulator", "/cam1"), ("merger", "/")] {
            let p = Params::resolve(&declarations(node).unwrap(), &Default::default()).unwrap();
            r.add(build(node, &p).unwrap(), node, ns, &[]);
        }
        let shared: Vec<String> = r.shared_inputs().into_iter().map(|(t, _)| t).collect();
        assert_eq!(shared, ["/tf", "/tf_static", "/scan/events"]);
        let external: Vec<String> = r.external_inputs().into_iter().map(|(t, _)| t).collect();
        assert!(!external.iter().any(|t| shared.contains(t)), "{external:?}");
        assert!(external.contains(&"/scan/request".to_string()) && external.contains(&"/cam1/laser_line".to_string()));
        // /surface/placements goes from the merger to c_arm_pose in memory only.
        assert!(
            !external.contains(&"/surface/placements".to_string())
                && !shared.contains(&"/surface/placements".to_string())
        );
    }

    #[test]
    fn refined_placements_replace_the_rig_between_scans_and_bad_ones_are_refused() {
        let (mut r, seen) = node(&[("auto_start", V::Bool(false))]);
        r.tick(0);
        let first = statics(&seen);
        assert_eq!(first.len(), 1);
        let cam2 = first[0].iter().find(|(c, _)| c == "cam2_optical_frame").unwrap().1;
        let mut refined = cam2;
        refined.translation.x += 0.002;
        // During a scan the placement waits for its end.
        request(&mut r, 10 * MS, ScanEvent::START);
        r.tick(20 * MS);
        r.publish("/surface/placements", &placements("cam2_optical_frame", &refined));
        r.tick(30 * MS);
        assert_eq!(statics(&seen).len(), 1, "not during a scan");
        request(&mut r, 40 * MS, ScanEvent::END);
        r.tick(50 * MS);
        let now = statics(&seen);
        assert_eq!(now.len(), 2, "published again after the scan");
        let got: std::collections::BTreeMap<_, _> = now[1].iter().cloned().collect();
        assert!((got["cam2_optical_frame"].translation - refined.translation).norm() < 1e-12);
        let cam1 = first[0].iter().find(|(c, _)| c == "cam1_optical_frame").unwrap().1;
        assert_eq!(got["cam1_optical_frame"].translation, cam1.translation);
        assert_eq!(r.nodes()[0].component.counters().iter().find(|c| c.0 == "placements_applied").unwrap().1, 1);
        // A frame that is no rig camera's, another parent, a non-rotation: refused and counted.
        r.publish("/surface/placements", &placements("cam9_optical_frame", &refined));
        let mut bad = convert::transform_stamped(0, "carm", "cam1_optical_frame", &refined);
        bad.transform.rotation.w = 3.0;
        r.publish("/surface/placements", &Msg::Tf(Arc::new(TFMessage { transforms: vec![bad] })));
        let other = convert::transform_stamped(0, "table", "cam1_optical_frame", &refined);
        r.publish("/surface/placements", &Msg::Tf(Arc::new(TFMessage { transforms: vec![other] })));
        r.tick(60 * MS);
        assert_eq!(r.nodes()[0].errors, 3);
        assert!(r.nodes()[0].last_error.as_deref().unwrap().contains("table"));
        assert_eq!(statics(&seen).len(), 2);
        // Not followed when asked not to.
        let (mut r, seen) = node(&[("auto_start", V::Bool(false)), ("follow_placements", V::Bool(false))]);
        r.tick(0);
        r.publish("/surface/placements", &placements("cam2_optical_frame", &refined));
        r.tick(10 * MS);
        assert_eq!(statics(&seen).len(), 1);
    }

    #[test]
    fn speed_model_starts_and_stops_on_request_and_numbers_the_scans() {
        let (mut r, seen) = node(&[("auto_start", V::Bool(false))]);
        for k in 0..50 {
            r.tick(k * 10 * MS);
        }
        assert!(events(&seen).is_empty(), "no scan without a request");
        request(&mut r, 500 * MS, ScanEvent::START);
        for k in 50..150 {
            r.tick(k * 10 * MS);
        }
        request(&mut r, 1_500 * MS, ScanEvent::END);
        for k in 150..200 {
            r.tick(k * 10 * MS);
        }
        let e = events(&seen);
        assert_eq!(e, [(1, ScanEvent::START, 500 * MS), (1, ScanEvent::END, 1_500 * MS)]);
        // The C-arm stopped where the END came: 1 s at 0.07 m/s from -0.18.
        let last_tf = seen.borrow().iter().rev().find_map(|(t, m)| match m {
            Msg::Tf(tf) if t == "/tf" => Some(tf.transforms[0].transform.translation.y),
            _ => None,
        });
        assert!((last_tf.unwrap() - (-0.18 + 0.07)).abs() < 1e-9);
        // A second scan runs to the end of travel with the next id.
        request(&mut r, 2_000 * MS, ScanEvent::START);
        for k in 200..800 {
            r.tick(k * 10 * MS);
        }
        let e = events(&seen);
        assert_eq!(&e[2..], [(2, ScanEvent::START, 2_000 * MS), (2, ScanEvent::END, e[3].2)]);
        assert!((e[3].2 - (2_000 * MS + (0.36 / 0.07 * 1e9) as i64)).abs() <= 10 * MS);
    }

    #[test]
    fn encoder_feed_gives_tf_at_its_stamps_and_scan_events_from_the_motion() {
        let (mut r, seen) = node(&[("mode", V::String("encoder".into()))]);
        r.tick(0);
        // At rest, then 0.07 m/s from -0.18 to 0.18, then at rest at the end.
        let mut t = 0;
        for _ in 0..20 {
            encoder(&mut r, t, -0.18);
            t += 10 * MS;
        }
        let t_move = t;
        let mut x: f64 = -0.18;
        while x < 0.18 {
            x = (x + 0.0007).min(0.18);
            encoder(&mut r, t, x);
            t += 10 * MS;
        }
        for _ in 0..50 {
            encoder(&mut r, t, 0.18);
            r.tick(t);
            t += 10 * MS;
        }
        let e = events(&seen);
        assert_eq!(e.len(), 2, "{e:?}");
        assert_eq!((e[0].0, e[0].1), (1, ScanEvent::START));
        assert!(e[0].2 > t_move && e[0].2 <= t_move + 20 * MS, "START at the first millimetre of motion");
        assert_eq!((e[1].0, e[1].1), (1, ScanEvent::END));
        let tf_stamps: Vec<i64> = seen
            .borrow()
            .iter()
            .filter_map(|(topic, m)| match m {
                Msg::Tf(tf) if topic == "/tf" => Some(tf.transforms[0].header.stamp.nanos()),
                _ => None,
            })
            .collect();
        assert_eq!(tf_stamps.len(), 20 + 515 + 50);
        assert_eq!(tf_stamps[..3], [0, 10 * MS, 20 * MS], "each sample at its own stamp");
    }

    #[test]
    fn a_stall_or_a_silent_feed_aborts_the_scan() {
        // Stall: stops half way.
        let (mut r, seen) = node(&[("mode", V::String("encoder".into()))]);
        r.tick(0);
        let mut t = 0;
        encoder(&mut r, t, -0.18);
        for k in 1..=100 {
            t += 10 * MS;
            encoder(&mut r, t, -0.18 + 0.0007 * f64::from(k));
        }
        for _ in 0..40 {
            t += 10 * MS;
            encoder(&mut r, t, -0.11);
            r.tick(t);
        }
        let e = events(&seen);
        assert_eq!(e.iter().map(|e| e.1).collect::<Vec<_>>(), [ScanEvent::START, ScanEvent::ABORT]);
        // Silence: the feed stops during the scan.
        let (mut r, seen) = node(&[("mode", V::String("encoder".into()))]);
        r.tick(0);
        let mut t = 0;
        for k in 0..=20 {
            encoder(&mut r, t, -0.18 + 0.0007 * f64::from(k));
            t += 10 * MS;
        }
        r.tick(t + 100 * MS);
        assert_eq!(events(&seen).len(), 1, "a 0.1 s gap is tolerated");
        r.tick(t + 300 * MS);
        let e = events(&seen);
        assert_eq!(e.iter().map(|e| e.1).collect::<Vec<_>>(), [ScanEvent::START, ScanEvent::ABORT]);
        // A sample without the joint is refused, counted, and changes nothing.
        let js = JointStateMsg { name: vec!["other".into()], position: vec![1.0], ..Default::default() };
        r.publish("/carm/encoder", &Msg::JointState(Arc::new(js)));
        let n = &r.nodes()[0];
        assert_eq!(n.errors, 1);
        assert!(n.last_error.as_deref().unwrap_or("").contains("no joint \"carm_travel\""));
    }
}
