//! The parameters of `triangulator`, declared once (see `xsurf_runtime::parameters!`).

xsurf_runtime::parameters! {
    /// The parameters of `triangulator`.
    pub struct TriangulatorParams {
        /// the laser plane in carm, [nx, ny, nz, d]: {p : n.p = d}
        laser_plane: Vec<f64> = vec![0.0, 1.0, 0.0, 0.0], unit "m";
        /// the scanner's lasers by name (empty: the single laser_plane); each needs
        /// laser.<name>.plane (double[4] nx ny nz d in carm, unit normal) and
        /// laser.<name>.channel (red, green or blue); each line sample is intersected with its own
        /// laser's plane, and the profile has a block of rows per laser and a field `laser`
        lasers: Vec<String> = Vec::new();
        /// camera rays meeting the plane at a smaller angle are rejected
        min_ray_plane_angle_deg: f64 = 10.0, unit "deg";
        /// line samples weaker than this are dropped
        min_strength: f32 = 0.0, unit "grey levels";
        /// points lower than this above the tabletop are rejected (nothing below it can be seen)
        min_z_m: f64 = -0.01, unit "m";
        /// points higher than this above the tabletop are rejected (top of the measurement volume)
        max_z_m: f64 = 0.6, unit "m";
        /// the fixed frame points are placed in
        table_frame: String = "table".into();
        /// the C-arm frame the laser plane is given in
        carm_frame: String = "carm".into();
        /// largest gap between table -> carm samples that is interpolated across
        max_pose_gap_s: f64 = 0.5, unit "s";
        /// lines held while waiting for their pose; beyond this the oldest is placed or dropped
        max_pending: usize = 120, unit "lines", range 1..=100_000;
        /// place a line up to this long after the newest table -> carm sample, extrapolating the
        /// travel linearly (0: wait for a sample after the image, exact interpolation)
        max_extrapolation_s: f64 = 0.0, unit "s", range 0.0..=0.1;
    }
}

