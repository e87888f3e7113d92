//! Borrowed views of `sensor_msgs/Image` buffers with checked strides.

use serde::{Deserialize, Serialize};

/// Luma of a colour (ITU-R BT.601 weights: 0.299 R + 0.587 G + 0.114 B).
#[inline]
pub fn luma(r: f32, g: f32, b: f32) -> f32 {
    0.299 * r + 0.587 * g + 0.114 * b
}

/// Pixel encodings we handle (`sensor_msgs/image_encodings` names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Encoding {
    /// 8-bit grey.
    Mono8,
    /// 16-bit grey.
    Mono16,
    /// 8-bit red, green, blue.
    Rgb8,
    /// 8-bit blue, green, red.
    Bgr8,
}

impl Encoding {
    /// Parses a ROS encoding name.
    pub fn from_ros(name: &str) -> Result<Encoding, ImageError> {
        match name {
            "mono8" | "8UC1" => Ok(Encoding::Mono8),
            "mono16" | "16UC1" => Ok(Encoding::Mono16),
            "rgb8" => Ok(Encoding::Rgb8),
            "bgr8" | "8UC3" => Ok(Encoding::Bgr8),
            other => Err(ImageError::UnsupportedEncoding(other.to_string())),
        }
    }
    /// The ROS encoding name.
    pub fn ros_name(self) -> &'static str {
        match self {
            Encoding::Mono8 => "mono8",
            Encoding::Mono16 => "mono16",
            Encoding::Rgb8 => "rgb8",
            Encoding::Bgr8 => "bgr8",
        }
    }
    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Encoding::Mono8 => 1,
            Encoding::Mono16 => 2,
            Encoding::Rgb8 | Encoding::Bgr8 => 3,
        }
    }
    /// True for the colour encodings.
    pub fn is_color(self) -> bool {
        matches!(self, Encoding::Rgb8 | Encoding::Bgr8)
    }
    /// The largest value a channel can hold.
    pub fn max_value(self) -> f32 {
        match self {
            Encoding::Mono16 => 65535.0,
            _ => 255.0,
        }
    }
}

/// Why an image buffer cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImageError {
    /// Encoding name not handled.
    #[error("unsupported image encoding {0:?} (handled: mono8, mono16, rgb8, bgr8)")]
    UnsupportedEncoding(String),
    /// Width or height is zero.
    #[error("empty image ({width}x{height})")]
    Empty {
        /// Width, pixels.
        width: u32,
        /// Height, pixels.
        height: u32,
    },
    /// `step` is smaller than a row of pixels.
    #[error("row step {step} bytes is less than width {width} x {bytes_per_pixel} bytes per pixel")]
    StepTooSmall {
        /// Given step.
        step: u32,
        /// Width, pixels.
        width: u32,
        /// Bytes per pixel of the encoding.
        bytes_per_pixel: usize,
    },
    /// The data buffer is shorter than `step * height`.
    #[error("image data is {len} bytes, expected at least {expected} (step {step} x height {height})")]
    DataTooShort {
        /// Actual length.
        len: usize,
        /// Needed length.
        expected: usize,
        /// Row step.
        step: u32,
        /// Height.
        height: u32,
    },
}

/// A validated, borrowed image.
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    width: u32,
    height: u32,
    step: usize,
    encoding: Encoding,
    big_endian: bool,
    data: &'a [u8],
}

impl<'a> ImageView<'a> {
    /// Checks sizes and wraps the buffer.
    pub fn new(
        width: u32,
        height: u32,
        step: u32,
        encoding: Encoding,
        big_endian: bool,
        data: &'a [u8],
    ) -> Result<Self, ImageError> {
        if width == 0 || height == 0 {
            return Err(ImageError::Empty { width, height });
        }
        let bpp = encoding.bytes_per_pixel();
        if (step as usize) < width as usize * bpp {
            return Err(ImageError::StepTooSmall { step, width, bytes_per_pixel: bpp });
        }
        let expected = step as usize * height as usize;
        if data.len() < expected {
            return Err(ImageError::DataTooShort { len: data.len(), expected, step, height });
        }
        Ok(Self { width, height, step: step as usize, encoding, big_endian, data })
    }
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// Bytes per row.
    pub fn step(&self) -> usize {
        self.step
    }
    /// Pixel encoding.
    pub fn encoding(&self) -> Encoding {
        self.encoding
    }
    /// True if 16-bit samples are big-endian.
    pub fn is_big_endian(&self) -> bool {
        self.big_endian
    }
    /// The whole buffer: row `r` starts at `r * step()`.
    pub(crate) fn data(&self) -> &'a [u8] {
        self.data
    }
    /// The bytes of row `r` (exactly `width * bytes_per_pixel` long). Panics never: `r` is clamped
    /// by the caller's loop bounds; an out-of-range row gives an empty slice.
    pub fn row(&self, r: u32) -> &'a [u8] {
        let start = r as usize * self.step;
        let len = self.width as usize * self.encoding.bytes_per_pixel();
        self.data.get(start..start + len).unwrap_or(&[])
    }
    /// The 8-bit (r, g, b) colour at pixel (x, y); grey images give r = g = b.
    pub fn rgb_at(&self, x: u32, y: u32) -> [u8; 3] {
        let row = self.row(y);
        let x = x as usize;
        match self.encoding {
            Encoding::Mono8 => row.get(x).map_or([0; 3], |&g| [g; 3]),
            Encoding::Mono16 => {
                let g = self.mono16_at(row, x) >> 8;
                [g as u8; 3]
            }
            Encoding::Rgb8 => row.get(3 * x..3 * x + 3).map_or([0; 3], |p| [p[0], p[1], p[2]]),
            Encoding::Bgr8 => row.get(3 * x..3 * x + 3).map_or([0; 3], |p| [p[2], p[1], p[0]]),
        }
    }
    fn mono16_at(&self, row: &[u8], x: usize) -> u16 {
        row.get(2 * x..2 * x + 2).map_or(0, |b| {
            if self.big_endian {
                u16::from_be_bytes([b[0], b[1]])
            } else {
                u16::from_le_bytes([b[0], b[1]])
            }
        })
    }
}

/// An owned image buffer, laid out like `sensor_msgs/Image` (little-endian, `step` = packed row).
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Encoding.
    pub encoding: Encoding,
    /// Packed rows.
    pub data: Vec<u8>,
}

impl Image {
    /// A zeroed image.
    pub fn new(width: u32, height: u32, encoding: Encoding) -> Image {
        Image { width, height, encoding, data: vec![0; width as usize * height as usize * encoding.bytes_per_pixel()] }
    }
    /// Bytes per row.
    pub fn step(&self) -> u32 {
        self.width * self.encoding.bytes_per_pixel() as u32
    }
    /// A checked view of this image.
    pub fn view(&self) -> Result<ImageView<'_>, ImageError> {
        ImageView::new(self.width, self.height, self.step(), self.encoding, false, &self.data)
    }
}

/// A sample type [`gaussian_blur`] works in.
pub(crate) trait BlurSample:
    Copy + Default + std::ops::Add<Output = Self> + std::ops::Mul<Output = Self>
{
    /// The value nearest to `v`.
    fn from_f64(v: f64) -> Self;
}

impl BlurSample for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl BlurSample for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// Separable Gaussian blur of a row-major `w x h` buffer (kernel radius `3 sigma`, edges
/// clamped).
pub(crate) fn gaussian_blur<T: BlurSample>(src: &[T], w: usize, h: usize, sigma: f64) -> Vec<T> {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f64> = (-r..=r).map(|i| (-((i * i) as f64) / (2.0 * sigma * sigma)).exp()).collect();
    let sum: f64 = k.iter().sum();
    let k: Vec<T> = k.iter().map(|v| T::from_f64(v / sum)).collect();
    let (wi, hi) = (w as isize, h as isize);
    let pass = |src: &[T], horizontal: bool| {
        let mut out = vec![T::default(); src.len()];
        for y in 0..hi {
            for x in 0..wi {
                let mut acc = T::default();
                for (i, &kv) in k.iter().enumerate() {
                    let o = i as isize - r;
                    let (xx, yy) =
                        if horizontal { ((x + o).clamp(0, wi - 1), y) } else { (x, (y + o).clamp(0, hi - 1)) };
                    acc = acc + kv * src[(yy * wi + xx) as usize];
                }
                out[(y * wi + x) as usize] = acc;
            }
        }
        out
    };
    pass(&pass(src, true), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_strides_and_sizes_are_typed_errors() {
        let data = vec![0u8; 100];
        assert!(matches!(ImageView::new(0, 10, 10, Encoding::Mono8, false, &data), Err(ImageError::Empty { .. })));
        assert!(matches!(
            ImageView::new(10, 10, 9, Encoding::Mono8, false, &data),
            Err(ImageError::StepTooSmall { .. })
        ));
        assert!(matches!(
            ImageView::new(10, 10, 20, Encoding::Mono16, false, &data),
            Err(ImageError::DataTooShort { .. })
        ));
        assert!(matches!(Encoding::from_ros("yuv422"), Err(ImageError::UnsupportedEncoding(_))));
        assert!(ImageView::new(10, 10, 10, Encoding::Mono8, false, &data).is_ok());
    }

    #[test]
    fn colour_lookup_per_encoding() {
        let rgb = [10u8, 20, 30, 40, 50, 60];
        let v = ImageView::new(2, 1, 6, Encoding::Rgb8, false, &rgb).unwrap();
        assert_eq!(v.rgb_at(1, 0), [40, 50, 60]);
        let v = ImageView::new(2, 1, 6, Encoding::Bgr8, false, &rgb).unwrap();
        assert_eq!(v.rgb_at(1, 0), [60, 50, 40]);
        let m16 = [0x00u8, 0x80];
        let v = ImageView::new(1, 1, 2, Encoding::Mono16, false, &m16).unwrap();
        assert_eq!(v.rgb_at(0, 0), [0x80; 3]);
    }
}
