//! PNG encoding of grey and colour buffers.

use crate::FileError;
use std::path::Path;

/// Pixel layout of a buffer to encode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PngKind {
    /// 8-bit grey.
    Grey8,
    /// 16-bit grey (big-endian samples, as PNG stores them).
    Grey16,
    /// 8-bit RGB.
    Rgb8,
    /// 8-bit RGBA.
    Rgba8,
}

/// Encodes a buffer as PNG.
pub fn encode_png(width: u32, height: u32, kind: PngKind, data: &[u8]) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        let (ct, bd) = match kind {
            PngKind::Grey8 => (png::ColorType::Grayscale, png::BitDepth::Eight),
            PngKind::Grey16 => (png::ColorType::Grayscale, png::BitDepth::Sixteen),
            PngKind::Rgb8 => (png::ColorType::Rgb, png::BitDepth::Eight),
            PngKind::Rgba8 => (png::ColorType::Rgba, png::BitDepth::Eight),
        };
        enc.set_color(ct);
        enc.set_depth(bd);
        enc.set_compression(png::Compression::Fast);
        let mut w = enc.write_header()?;
        w.write_image_data(data)?;
    }
    Ok(out)
}

/// Encodes and writes a PNG atomically.
pub fn write_png(path: &Path, width: u32, height: u32, kind: PngKind, data: &[u8]) -> Result<(), FileError> {
    let bytes = encode_png(width, height, kind, data).map_err(|e| FileError::new(path, std::io::Error::other(e)))?;
    crate::write_bytes_atomic(path, &bytes)
}

/// Decodes a PNG into (width, height, RGB8 bytes) (grey is expanded).
pub fn decode_png_rgb(bytes: &[u8]) -> Result<(u32, u32, Vec<u8>), png::DecodingError> {
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec.read_info()?;
    let mut buf = vec![0; reader.output_buffer_size().unwrap_or(0)];
    let info = reader.next_frame(&mut buf)?;
    buf.truncate(info.buffer_size());
    let rgb = match info.color_type {
        png::ColorType::Grayscale => buf.iter().flat_map(|&g| [g, g, g]).collect(),
        png::ColorType::GrayscaleAlpha => buf.chunks(2).flat_map(|c| [c[0], c[0], c[0]]).collect(),
        png::ColorType::Rgba => buf.chunks(4).flat_map(|c| [c[0], c[1], c[2]]).collect(),
        _ => buf,
    };
    Ok((info.width, info.height, rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip() {
        let data: Vec<u8> = (0..12).collect();
        let png = encode_png(2, 2, PngKind::Rgb8, &data).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let (w, h, rgb) = decode_png_rgb(&png).unwrap();
        assert_eq!((w, h), (2, 2));
        assert_eq!(rgb, data);
        assert!(encode_png(2, 2, PngKind::Rgb8, &data[..5]).is_err());
    }
}
