//! The parameters of `c_arm_pose`, declared once (see `xsurf_runtime::parameters!`).

use std::path::PathBuf;

xsurf_runtime::choice! {
    /// Where the travel comes from.
    pub enum Mode {
        /// The speed model.
        Speed = "speed",
        /// The scanner controller's position feed on `/carm/encoder`.
        Encoder = "encoder",
    }
}

xsurf_runtime::parameters! {
    /// The parameters of `c_arm_pose`.
    pub struct CArmPoseParams {
        /// travel speed (the study's: 0.035, 0.070, 0.140)
        speed: f64 = 0.070, unit "m/s";
        /// travel at the start of a scan
        travel_start_m: f64 = -0.18, unit "m";
        /// travel at which the scan ends
        travel_end_m: f64 = 0.18, unit "m";
        /// start a scan by itself start_delay_s after start-up
        auto_start: bool = true;
        /// wait before an automatic scan
        start_delay_s: f64 = 2.0, unit "s";
        /// id of the first scan
        scan_id: u32 = 1;
        /// rate of /tf and /joint_states
        rate_hz: f64 = 100.0, unit "Hz", range 1.0..=1000.0;
        /// rig YAML with the cameras' placement; empty: the study's rig
        rig_file: Option<PathBuf> = None;
        /// fixed frame
        table_frame: String = "table".into();
        /// C-arm frame
        carm_frame: String = "carm".into();
        /// speed: the speed model; encoder: follow /carm/encoder
        mode: Mode = Mode::Speed, via Choice;
        /// encoder mode: the joint of the travel (m)
        encoder_joint: String = "carm_travel".into();
        /// encoder mode: movement that starts a scan (auto_start)
        motion_threshold_m: f64 = 0.001, unit "m";
        /// encoder mode: no movement for this long is a stop
        stop_time_s: f64 = 0.3, unit "s";
        /// encoder mode: a stop this close to travel_end_m is END, elsewhere ABORT (stall)
        end_tolerance_m: f64 = 0.005, unit "m";
        /// encoder mode: silence of the feed during a scan is ABORT
        max_gap_s: f64 = 0.2, unit "s";
        /// take the merger's refined camera placements (/surface/placements) into /tf_static
        /// between scans
        follow_placements: bool = true;
    }
}

