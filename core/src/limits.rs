//! The limits every tool and node applies to the same quantities, in one place.

use std::ops::RangeInclusive;

/// A camera image's width or height, pixels (rig files, the camera_driver, `synth --size`,
/// `calibrate synth --size`).
pub const IMAGE_SIDE_PX: RangeInclusive<u32> = 32..=8192;

/// Travel speed of the C-arm, m/s: exclusive bounds (the LODOX scans at 0.035-0.14 m/s).
pub const SPEED_MPS: (f64, f64) = (0.0, 2.0);

/// Frame rate, Hz: `(0, 1000]`.
pub const MAX_FPS: f64 = 1000.0;

/// Whether `v` is a valid image side.
pub fn image_side_ok(v: u32) -> bool {
    IMAGE_SIDE_PX.contains(&v)
}

/// Whether `v` is a valid travel speed.
pub fn speed_ok(v: f64) -> bool {
    v > SPEED_MPS.0 && v < SPEED_MPS.1
}

/// The image side limits as text (`32..=8192`).
pub fn image_side_text() -> String {
    format!("{}..={}", IMAGE_SIDE_PX.start(), IMAGE_SIDE_PX.end())
}
