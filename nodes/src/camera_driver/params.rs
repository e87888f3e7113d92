//! The parameters of `camera_driver`, declared once (see `xsurf_runtime::parameters!`).

use crate::edge_detector::Transport;
use std::path::PathBuf;

xsurf_runtime::choice! {
    /// Which source the images come from (the `source` parameter).
    pub enum SourceKind {
        /// The synthetic scanner.
        Synthetic = "synthetic",
        /// An image sequence.
        Files = "files",
        /// A Video4Linux2 camera.
        V4l2 = "v4l2",
    }
}

xsurf_runtime::parameters! {
    /// The parameters of `camera_driver`.
    pub struct CameraDriverParams {
        /// image source: synthetic, files, or v4l2 (a USB/UVC camera; needs the cargo feature v4l2)
        source: SourceKind = SourceKind::Synthetic, via Choice;
        /// v4l2 source: the video device
        device: String = "/dev/video0".into();
        /// v4l2 source: the camera's delay from exposure to delivery, subtracted from the time a
        /// frame is dequeued
        /// (in [0, 1]; checked only for the v4l2 source)
        stamp_offset_s: f64 = 0.0, unit "s";
        /// files source: a directory (its .bmp/.png/.pgm/.ppm/.jpg in name order) or a pattern
        /// such as /data/frame_%03d.bmp
        files: String = String::new();
        /// files source: one stamp per frame (seconds, or integer ns), else stamps from fps
        timestamps_file: Option<PathBuf> = None;
        /// files source: start again after the last frame
        loop_files: bool = false;
        /// camera_calibration YAML (file:///path or a path), as `xsurf calibrate intrinsics`
        /// writes it; empty: the rig's intrinsics
        camera_info_url: String = String::new();
        /// turn every image by 180 degrees before publishing
        rotate_180: bool = false;
        /// synthetic source: pyramid, phantom, sphere, cylinder, box or body
        scene: String = "pyramid".into();
        /// camera name in the rig (default: the node's namespace)
        camera: String = String::new();
        /// rig YAML (see launch-config/rig_study.yaml); empty: the study's rig
        rig_file: Option<PathBuf> = None;
        /// image width (the study rig's intrinsics are scaled to it)
        width: i64 = 640, unit "px";
        /// image height
        height: i64 = 480, unit "px";
        /// frame rate
        fps: f64 = 30.0, unit "Hz";
        /// mono8, rgb8 or bgr8
        encoding: String = "mono8".into();
        /// synthetic source: the scanner's lasers by name (empty: the rig's), rendered each in
        /// its colour (laser.<name>.plane, .source, .channel); several need a colour encoding
        lasers: Vec<String> = Vec::new();
        /// raw: publish image_raw (sensor_msgs/Image); compressed: publish image_raw/compressed
        /// (sensor_msgs/CompressedImage) instead, as image_transport's compressed plugin writes it
        image_transport: Transport = Transport::Raw, via Choice;
        /// compressed transport: jpeg or png
        compressed_format: String = "jpeg".into();
        /// compressed transport: JPEG quality, 1..=100 (image_transport's default 95)
        jpeg_quality: i64 = 95, range 1..=100;
        /// synthetic sensor noise seed
        seed: i64 = 1;
        /// fixed frame of /tf
        table_frame: String = "table".into();
        /// C-arm frame of /tf
        carm_frame: String = "carm".into();
    }
}

