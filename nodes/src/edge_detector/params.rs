//! The parameters of `edge_detector`, declared once (see `xsurf_runtime::parameters!`).

use xsurf_core::edge::{Channel, EdgeConfig, Method, Orientation, Roi};
use xsurf_runtime::params::{ParamError, Params};

/// The detector's defaults (core's), which the declarations show.
const D: EdgeConfig = EdgeConfig::DEFAULT;

xsurf_runtime::parameters! {
    /// The parameters of `edge_detector`.
    pub struct EdgeParams {
        /// how images arrive: raw (image_raw, sensor_msgs/Image) or compressed
        /// (image_raw/compressed, sensor_msgs/CompressedImage, jpeg or png, decoded here); fixed at start
        image_transport: Transport = Transport::Raw, via Choice;
        /// center_of_gravity, gaussian, parabolic, or gradient (the study's method)
        method: Method = D.method, via Choice;
        /// vertical: one sample per image row; horizontal: one per column
        line_orientation: Orientation = D.line_orientation, via Choice;
        /// signal of colour images: red_minus_others (the laser's colour against the others;
        /// a line that saturates the laser's own channel is placed on that channel),
        /// green_minus_others, blue_minus_others, red, green, blue, luma; with `lasers`, each
        /// laser's line is found in its own colour against the others instead
        channel: Channel = D.channel, via Choice;
        /// the scanner's lasers by name (empty: the single laser_plane); each needs
        /// laser.<name>.plane (double[4] nx ny nz d in carm, unit normal) and
        /// laser.<name>.channel (red, green or blue, each laser its own), and may give
        /// laser.<name>.source (double[3] in carm). Several lasers need a colour camera.
        lasers: Vec<String> = Vec::new();
        /// keep a second surface's line where a row (column) crosses two, as where an object
        /// hides part of the table: each laser's second line follows the first lines in
        /// laser_line (field layers 2), and the triangulator, mesher and merger keep it as a
        /// grid of its own
        second_surfaces: bool = false;
        /// first column searched
        roi_x_offset ["roi.x_offset"]: u32 = D.roi.x_offset, unit "px";
        /// first row searched
        roi_y_offset ["roi.y_offset"]: u32 = D.roi.y_offset, unit "px";
        /// columns searched (0: to the edge)
        roi_width ["roi.width"]: u32 = D.roi.width, unit "px";
        /// rows searched (0: to the edge)
        roi_height ["roi.height"]: u32 = D.roi.height, unit "px";
        /// smallest peak height above the local background (8-bit scale)
        min_strength: f32 = D.min_strength, unit "grey levels";
        /// the peak must also exceed this many local noise standard deviations
        noise_factor: f32 = D.noise_factor;
        /// samples above background + this fraction of the peak take part in the centre
        peak_fraction: f32 = D.peak_fraction;
        /// largest half-width searched around a peak
        max_half_width_px: u32 = D.max_half_width_px, unit "px";
        /// length of each background flank
        flank_px: u32 = D.flank_px, unit "px";
        /// wider peaks (FWHM) are rejected as smeared
        max_width_px: f32 = D.max_width_px, unit "px";
        /// narrower peaks (FWHM) are rejected: set it for a camera whose line is wide (edge
        /// overshoot, fine texture)
        min_width_px: f32 = D.min_width_px, unit "px";
        /// for method gradient: the five-pixel rise that marks the line
        gradient_threshold: f32 = D.gradient_threshold, unit "grey levels";
        /// colour is sampled this far either side of the line
        color_offset_px: f32 = D.color_offset_px, unit "px";
        /// a line rises above the background on both sides: the lower rise is at least this
        /// fraction of the higher (a step is not a line)
        min_side_ratio: f32 = D.min_side_ratio;
        /// lines narrower than this (FWHM) are located by a pixel-integrated Gaussian fit,
        /// whatever the method (no pixel locking)
        narrow_width_px: f32 = D.narrow_width_px, unit "px";
        /// peaks tried per row until one passes every test: the brightest, the one of highest
        /// contrast, then the next brightest
        max_candidates: u32 = D.max_candidates;
        /// a line runs along at least this many consecutive rows (columns); shorter runs are
        /// dropped, and so are runs under 4 times this that are shorter than twice their width
        /// or much wider than the line was in the last frames (highlights, marks)
        min_run: u32 = D.min_run, unit "rows";
        /// largest step of the line centre between neighbouring rows (columns) of one run
        max_jump_px: f32 = D.max_jump_px, unit "px";
    }
}

xsurf_runtime::choice! {
    /// How a camera's images arrive (image_transport's transports).
    pub enum Transport {
        /// `image_raw`, `sensor_msgs/msg/Image`.
        Raw = "raw",
        /// `image_raw/compressed`, `sensor_msgs/msg/CompressedImage` (JPEG or PNG).
        Compressed = "compressed",
    }
}

impl EdgeParams {
    /// The detector's configuration, checked as core checks it.
    pub fn config(&self) -> Result<EdgeConfig, ParamError> {
        let c = EdgeConfig {
            method: self.method,
            line_orientation: self.line_orientation,
            channel: self.channel,
            roi: Roi {
                x_offset: self.roi_x_offset,
                y_offset: self.roi_y_offset,
                width: self.roi_width,
                height: self.roi_height,
            },
            min_strength: self.min_strength,
            noise_factor: self.noise_factor,
            peak_fraction: self.peak_fraction,
            max_half_width_px: self.max_half_width_px,
            flank_px: self.flank_px,
            max_width_px: self.max_width_px,
            min_width_px: self.min_width_px,
            gradient_threshold: self.gradient_threshold,
            color_offset_px: self.color_offset_px,
            min_side_ratio: self.min_side_ratio,
            narrow_width_px: self.narrow_width_px,
            max_candidates: self.max_candidates,
            min_run: self.min_run,
            max_jump_px: self.max_jump_px,
        };
        c.validate().map_err(|e| match e {
            xsurf_core::edge::EdgeError::InvalidConfig { name, reason } => Params::invalid(name, reason),
            other => Params::invalid("edge_detector", other.to_string()),
        })?;
        Ok(c)
    }
}

