//! `sensor_msgs/msg/CompressedImage` as image_transport's `compressed` plugin writes it: the
//! `format` string and the JPEG or PNG bytes, decoded into a frame (and encoded from one).
//!
//! Formats read: `jpeg` and `png` (ROS 1 and early ROS 2), and `<encoding>; <codec> compressed
//! [<target>]` (`bgr8; jpeg compressed bgr8`, `rgb8; jpeg compressed bgr8`, `mono8; png
//! compressed`, `mono16; png compressed`). The bytes are a standard JPEG or PNG file, so colour
//! decodes to true-colour rgb8 whatever the `bgr8` in the string says (OpenCV's encoder takes a
//! BGR buffer and writes ordinary colour). The codec the string names must be the one the bytes
//! start with; depth images (`compressedDepth`) and other codecs are refused by name.

use crate::frames::{encode_jpeg, jpeg_frame, png_frame};
use xsurf_core::image::{Encoding, Image};

/// A compression codec of image_transport's `compressed` plugin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Codec {
    /// JPEG (8-bit grey or colour).
    Jpeg,
    /// PNG (lossless; 8-bit grey or colour, 16-bit grey).
    Png,
}

impl Codec {
    /// `jpeg` or `png`.
    pub fn parse(s: &str) -> Option<Codec> {
        match s {
            "jpeg" | "jpg" => Some(Codec::Jpeg),
            "png" => Some(Codec::Png),
            _ => None,
        }
    }
    /// The codec's name in `format` strings.
    pub fn name(self) -> &'static str {
        match self {
            Codec::Jpeg => "jpeg",
            Codec::Png => "png",
        }
    }
    /// The codec whose signature the bytes start with.
    fn sniff(data: &[u8]) -> Option<Codec> {
        if data.starts_with(&[0xFF, 0xD8, 0xFF]) {
            Some(Codec::Jpeg)
        } else if data.starts_with(&[0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A]) {
            Some(Codec::Png)
        } else {
            None
        }
    }
}

/// The codec a `format` string names, or why it names none we read.
pub fn codec_of(format: &str) -> Result<Codec, String> {
    let f = format.trim();
    if let Some(c) = Codec::parse(&f.to_ascii_lowercase()) {
        return Ok(c);
    }
    // "<encoding>; <codec> compressed [<target>]"
    let Some((_, rest)) = f.split_once(';') else {
        return Err(format!("format {format:?}: expected \"jpeg\", \"png\" or \"<encoding>; <codec> compressed ...\""));
    };
    let mut words = rest.split_whitespace();
    let codec = words.next().unwrap_or_default();
    if codec == "compressedDepth" || rest.contains("compressedDepth") {
        return Err(format!("format {format:?}: compressedDepth (depth images) is not read"));
    }
    match (Codec::parse(&codec.to_ascii_lowercase()), words.next()) {
        (Some(c), Some("compressed")) => Ok(c),
        (Some(_), _) => Err(format!("format {format:?}: expected \"<encoding>; {codec} compressed ...\"")),
        (None, _) => Err(format!("format {format:?}: codec {codec:?} is not read (jpeg or png)")),
    }
}

/// Decodes a CompressedImage's bytes by its `format` string.
pub fn decode(format: &str, data: &[u8]) -> Result<Image, String> {
    let codec = codec_of(format)?;
    match Codec::sniff(data) {
        Some(c) if c == codec => {}
        Some(c) => {
            return Err(format!(
                "format {format:?} says {} but the {} bytes are {}",
                codec.name(),
                data.len(),
                c.name()
            ))
        }
        None => {
            let head: Vec<String> = data.iter().take(4).map(|b| format!("{b:02x}")).collect();
            return Err(format!(
                "format {format:?}: the {} bytes are not {} (they start {})",
                data.len(),
                codec.name(),
                if head.is_empty() { "empty".to_string() } else { head.join(" ") }
            ));
        }
    }
    match codec {
        Codec::Jpeg => jpeg_frame(data),
        Codec::Png => png_frame(data).map_err(|e| format!("PNG: {e}")),
    }
}

/// Encodes a frame as image_transport's `compressed` plugin would: `(format, bytes)`. JPEG takes
/// mono8 and rgb8 (bgr8 is turned to rgb8 first); PNG also mono16.
pub fn encode(img: &Image, codec: Codec, jpeg_quality: u8) -> Result<(String, Vec<u8>), String> {
    let enc = img.encoding.ros_name();
    let rgb;
    let img = if img.encoding == Encoding::Bgr8 {
        let mut c = img.clone();
        for p in c.data.chunks_exact_mut(3) {
            p.swap(0, 2);
        }
        c.encoding = Encoding::Rgb8;
        rgb = c;
        &rgb
    } else {
        img
    };
    let colour = img.encoding == Encoding::Rgb8;
    let target = if colour { "bgr8" } else { "" };
    let format = format!("{enc}; {} compressed {target}", codec.name());
    let bytes = match codec {
        Codec::Jpeg => encode_jpeg(img, jpeg_quality)?,
        Codec::Png => {
            use crate::image::{encode_png, PngKind};
            let (kind, data) = match img.encoding {
                Encoding::Mono8 => (PngKind::Grey8, img.data.clone()),
                Encoding::Rgb8 => (PngKind::Rgb8, img.data.clone()),
                Encoding::Mono16 => (PngKind::Grey16, img.data.chunks_exact(2).flat_map(|c| [c[1], c[0]]).collect()),
                other => return Err(format!("PNG: {} frames are not encoded", other.ros_name())),
            };
            encode_png(img.width, img.height, kind, &data).map_err(|e| format!("PNG: {e}"))?
        }
    };
    Ok((format, bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(enc: Encoding) -> Image {
        let mut img = Image::new(40, 30, enc);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (60 + (i % 97)) as u8;
        }
        img
    }

    #[test]
    fn format_strings_as_image_transport_writes_them() {
        for (f, c) in [
            ("jpeg", Codec::Jpeg),
            ("png", Codec::Png),
            ("bgr8; jpeg compressed bgr8", Codec::Jpeg),
            ("rgb8; jpeg compressed bgr8", Codec::Jpeg),
            ("mono8; jpeg compressed ", Codec::Jpeg),
            ("mono8; png compressed", Codec::Png),
            ("mono16; png compressed ", Codec::Png),
        ] {
            assert_eq!(codec_of(f), Ok(c), "{f}");
        }
        for (f, says) in [
            ("tiff", "expected"),
            ("bgr8; tiff compressed bgr8", "codec \"tiff\""),
            ("16UC1; compressedDepth png", "compressedDepth"),
            ("rgb8; jpeg", "compressed"),
        ] {
            let e = codec_of(f).unwrap_err();
            assert!(e.contains(says) && e.contains(f), "{f}: {e}");
        }
    }

    #[test]
    fn png_round_trips_exactly_and_jpeg_within_its_loss() {
        for enc in [Encoding::Mono8, Encoding::Rgb8, Encoding::Mono16] {
            let img = frame(enc);
            let (format, bytes) = encode(&img, Codec::Png, 90).unwrap();
            assert_eq!(decode(&format, &bytes).unwrap(), img, "{format}");
        }
        let img = frame(Encoding::Rgb8);
        let (format, bytes) = encode(&img, Codec::Jpeg, 95).unwrap();
        assert_eq!(format, "rgb8; jpeg compressed bgr8");
        let back = decode(&format, &bytes).unwrap();
        assert_eq!((back.width, back.height, back.encoding), (40, 30, Encoding::Rgb8));
        // bgr8 in, true colour out.
        let mut bgr = img.clone();
        bgr.encoding = Encoding::Bgr8;
        for p in bgr.data.chunks_exact_mut(3) {
            p.swap(0, 2);
        }
        let (format, bytes) = encode(&bgr, Codec::Png, 0).unwrap();
        assert_eq!(format, "bgr8; png compressed bgr8");
        assert_eq!(decode(&format, &bytes).unwrap(), img);
    }

    #[test]
    fn wrong_codec_truncation_and_garbage_are_named() {
        let img = frame(Encoding::Mono8);
        let (_, png) = encode(&img, Codec::Png, 0).unwrap();
        let (_, jpeg) = encode(&img, Codec::Jpeg, 90).unwrap();
        let e = decode("mono8; jpeg compressed ", &png).unwrap_err();
        assert!(e.contains("says jpeg") && e.contains("are png"), "{e}");
        let e = decode("jpeg", &jpeg[..jpeg.len() / 3]).unwrap_err();
        assert!(e.starts_with("JPEG"), "{e}");
        let e = decode("png", &png[..png.len() / 2]).unwrap_err();
        assert!(e.starts_with("PNG"), "{e}");
        let e = decode("jpeg", b"GIF89a").unwrap_err();
        assert!(e.contains("start 47 49 46 38"), "{e}");
        let e = decode("jpeg", &[]).unwrap_err();
        assert!(e.contains("empty"), "{e}");
    }
}
