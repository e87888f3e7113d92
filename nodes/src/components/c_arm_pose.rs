//! `c_arm_pose`: the C-arm's pose from the speed model: `table -> carm` on `/tf` and
//! `/joint_states` (`carm_travel`, `carm_angle`) at `rate_hz`, the cameras' `carm -> <cam>_optical_frame`
//! on `/tf_static` from the rig, and `/scan/events` START when travel begins and END when it
//! reaches `travel_end_m`.

use super::decl;
use crate::convert;
use std::sync::Arc;
use xsurf_core::pose::table_from_carm;
use xsurf_core::rig::Rig;
use xsurf_msgs::sensor_msgs::JointState;
use xsurf_msgs::tf2_msgs::TFMessage;
use xsurf_msgs::xsurf_msgs::ScanEvent;
use xsurf_msgs::RosMessage;
use xsurf_runtime::component::{Component, Msg, NodeError, Outbox, Port, QosClass};
use xsurf_runtime::params::{ParamDecl, ParamError, ParamValue as V, Params};

/// The parameters of `c_arm_pose`.
pub fn declarations() -> Vec<ParamDecl> {
    vec![
        decl("speed", V::Double(0.070), "m/s", "travel speed (the study's: 0.035, 0.070, 0.140)"),
        decl("travel_start_m", V::Double(-0.18), "m", "travel at the start of a scan"),
        decl("travel_end_m", V::Double(0.18), "m", "travel at which the scan ends"),
        decl("auto_start", V::Bool(true), "", "start a scan by itself start_delay_s after start-up"),
        decl("start_delay_s", V::Double(2.0), "s", "wait before an automatic scan"),
        decl("scan_id", V::Integer(1), "", "id of the first scan"),
        decl("rate_hz", V::Double(100.0), "Hz", "rate of /tf and /joint_states"),
        decl("rig_file", V::String(String::new()), "", "rig YAML with the cameras' placement; empty: the study's rig"),
        decl("table_frame", V::String("table".into()), "", "fixed frame"),
        decl("carm_frame", V::String("carm".into()), "", "C-arm frame"),
    ]
}

struct Config {
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
}

fn config(p: &Params) -> Result<Config, ParamError> {
    let speed = p.f64("speed")?;
    if !(speed > 0.0 && speed < 2.0) {
        return Err(Params::invalid("speed", format!("{speed} m/s is not in (0, 2)")));
    }
    let rate = p.f64("rate_hz")?;
    if !(1.0..=1000.0).contains(&rate) {
        return Err(Params::invalid("rate_hz", format!("{rate} is not in [1, 1000]")));
    }
    let rig_file = p.string("rig_file")?;
    let rig = if rig_file.is_empty() {
        Rig::study(640, 480)
    } else {
        let text =
            std::fs::read_to_string(&rig_file).map_err(|e| Params::invalid("rig_file", format!("{rig_file}: {e}")))?;
        serde_yaml::from_str(&text).map_err(|e| Params::invalid("rig_file", format!("{rig_file}: {e}")))?
    };
    let id = p.i64("scan_id")?;
    Ok(Config {
        speed,
        start: p.f64("travel_start_m")?,
        end: p.f64("travel_end_m")?,
        auto_start: p.bool("auto_start")?,
        delay_ns: (p.f64("start_delay_s")?.max(0.0) * 1e9) as i64,
        scan_id: u32::try_from(id).map_err(|_| Params::invalid("scan_id", format!("{id} is not a u32")))?,
        period_ns: (1e9 / rate) as i64,
        rig,
        table_frame: p.string("table_frame")?,
        carm_frame: p.string("carm_frame")?,
    })
}

/// The C-arm pose component.
pub struct CArmPoseNode {
    cfg: Config,
    start_ns: Option<i64>,
    scanning: bool,
    done: bool,
    last_pub: i64,
    statics_sent: bool,
    scans: u64,
}

impl CArmPoseNode {
    /// Builds the node from its parameters.
    pub fn new(p: &Params) -> Result<Self, ParamError> {
        Ok(Self {
            cfg: config(p)?,
            start_ns: None,
            scanning: false,
            done: false,
            last_pub: i64::MIN,
            statics_sent: false,
            scans: 0,
        })
    }
    fn travel(&self, now: i64) -> f64 {
        let dir = (self.cfg.end - self.cfg.start).signum();
        match self.start_ns {
            Some(t0) if now > t0 && !self.done => {
                let t = self.cfg.start + dir * self.cfg.speed * (now - t0) as f64 * 1e-9;
                if dir >= 0.0 {
                    t.min(self.cfg.end)
                } else {
                    t.max(self.cfg.end)
                }
            }
            _ if self.done => self.cfg.end,
            _ => self.cfg.start,
        }
    }
    fn event(&self, now: i64, event: u8) -> Msg {
        Msg::ScanEvent(Arc::new(ScanEvent {
            header: convert::header(now, &self.cfg.table_frame),
            scan_id: self.cfg.scan_id,
            event,
        }))
    }
}

impl Component for CArmPoseNode {
    fn node_name(&self) -> &'static str {
        "c_arm_pose"
    }
    fn inputs(&self) -> Vec<Port> {
        Vec::new()
    }
    fn outputs(&self) -> Vec<Port> {
        vec![
            Port::new("/tf", TFMessage::TYPE_NAME, QosClass::Reliable),
            Port::new("/tf_static", TFMessage::TYPE_NAME, QosClass::Static),
            Port::new("/joint_states", JointState::TYPE_NAME, QosClass::Reliable),
            Port::new("/scan/events", ScanEvent::TYPE_NAME, QosClass::Reliable),
        ]
    }
    fn declarations(&self) -> Vec<ParamDecl> {
        declarations()
    }
    fn reconfigure(&mut self, p: &Params) -> Result<(), ParamError> {
        let c = config(p)?;
        if self.scanning {
            return Err(Params::invalid("c_arm_pose", "parameters cannot change during a scan"));
        }
        self.cfg = c;
        Ok(())
    }
    fn handle(&mut self, i: usize, m: &Msg, _out: &mut Outbox) -> Result<(), NodeError> {
        Err(NodeError::new(format!("unexpected {} on input {i}", m.type_name())))
    }
    fn tick(&mut self, now: i64, out: &mut Outbox) {
        if !self.statics_sent {
            self.statics_sent = true;
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
            out.publish(1, Msg::Tf(Arc::new(tf)));
            if self.cfg.auto_start {
                self.start_ns = Some(now + self.cfg.delay_ns);
            }
        }
        if let Some(t0) = self.start_ns {
            if !self.scanning && !self.done && now >= t0 {
                self.scanning = true;
                out.publish(3, self.event(t0, ScanEvent::START));
            }
        }
        if now.saturating_sub(self.last_pub) >= self.cfg.period_ns {
            self.last_pub = now;
            let travel = self.travel(now);
            let pose = table_from_carm(travel, 0.0, 0.0);
            out.publish(
                0,
                Msg::Tf(Arc::new(TFMessage {
                    transforms: vec![convert::transform_stamped(
                        now,
                        &self.cfg.table_frame,
                        &self.cfg.carm_frame,
                        &pose,
                    )],
                })),
            );
            let js = JointState {
                header: convert::header(now, ""),
                name: vec!["carm_travel".into(), "carm_angle".into()],
                position: vec![travel, 0.0],
                velocity: vec![if self.scanning { self.cfg.speed } else { 0.0 }, 0.0],
                effort: vec![],
            };
            out.publish(2, Msg::JointState(Arc::new(js)));
            if self.scanning && (travel - self.cfg.end).abs() < 1e-12 {
                self.scanning = false;
                self.done = true;
                self.scans += 1;
                out.publish(3, self.event(now, ScanEvent::END));
            }
        }
    }
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![("scans", self.scans)]
    }
}
