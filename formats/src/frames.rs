//! Camera frames as image files (the study's `frame_000.bmp`... sequences): BMP (8-bit
//! palette, 24- and 32-bit, bottom-up or top-down, uncompressed), PGM/PPM (binary, 8 or 16
//! bits), PNG (grey 8/16, RGB, palette) and JPEG (baseline and progressive, grey or colour).
//! Grey images become mono8 or mono16, colour ones rgb8 (BMP's own byte order becomes bgr8). Errors name the file and, where the data is short, the
//! byte offset.

use std::path::{Path, PathBuf};
use xsurf_core::image::{Encoding, Image};

/// A frame file that cannot be read.
#[derive(Debug, thiserror::Error)]
#[error("{}: {what}", file.display())]
pub struct FrameError {
    /// The file.
    pub file: PathBuf,
    /// What is wrong.
    pub what: String,
}

/// Reads a frame by its extension (`.bmp`, `.pgm`, `.ppm`, `.png`, `.jpg`/`.jpeg`, any case).
pub fn read_frame(path: &Path) -> Result<Image, FrameError> {
    let err = |what: String| FrameError { file: path.to_path_buf(), what };
    let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    match ext.as_str() {
        "bmp" => bmp(&bytes),
        "pgm" | "ppm" | "pnm" => pnm(&bytes),
        "png" => png_frame(&bytes),
        "jpg" | "jpeg" => jpeg_frame(&bytes),
        other => Err(format!("extension {other:?}: frames must be .bmp, .pgm, .ppm, .png or .jpg")),
    }
    .map_err(err)
}

fn u16le(b: &[u8], at: usize) -> Result<u16, String> {
    b.get(at..at + 2).map(|s| u16::from_le_bytes([s[0], s[1]])).ok_or_else(|| format!("ends at byte {}", b.len()))
}
fn u32le(b: &[u8], at: usize) -> Result<u32, String> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or_else(|| format!("ends at byte {}, header field at {at} missing", b.len()))
}

fn bmp(b: &[u8]) -> Result<Image, String> {
    if b.get(0..2) != Some(b"BM") {
        return Err("not a BMP (no 'BM' at byte 0)".into());
    }
    let offset = u32le(b, 10)? as usize;
    let dib = u32le(b, 14)? as usize;
    let w = u32le(b, 18)? as i32;
    let h = u32le(b, 22)? as i32;
    let bpp = u16le(b, 28)?;
    let compression = u32le(b, 30)?;
    if compression != 0 {
        return Err(format!("compression {compression} at byte 30: only uncompressed BMP is read"));
    }
    if w <= 0 || h == 0 {
        return Err(format!("size {w}x{h} at byte 18"));
    }
    let (w, top_down, h) = (w as usize, h < 0, h.unsigned_abs() as usize);
    let stride = (bpp as usize * w).div_ceil(32) * 4;
    let need = offset + stride * h;
    if b.len() < need {
        return Err(format!("pixel data ends at byte {}, {w}x{h} at {bpp} bits needs {need}", b.len()));
    }
    let row = |y: usize| {
        let r = if top_down { y } else { h - 1 - y };
        &b[offset + r * stride..offset + r * stride + stride]
    };
    match bpp {
        8 => {
            let colours = match u32le(b, 46)? {
                0 => 256,
                n => n as usize,
            };
            let pal_at = 14 + dib;
            let pal = b.get(pal_at..pal_at + 4 * colours).ok_or_else(|| format!("palette at byte {pal_at} is cut"))?;
            let grey = pal.chunks_exact(4).all(|c| c[0] == c[1] && c[1] == c[2]);
            let look = |i: u8| -> [u8; 3] {
                let c = pal.get(4 * i as usize..4 * i as usize + 4).unwrap_or(&[0, 0, 0, 0]);
                [c[2], c[1], c[0]]
            };
            let mut img = Image::new(w as u32, h as u32, if grey { Encoding::Mono8 } else { Encoding::Rgb8 });
            for y in 0..h {
                for (x, &i) in row(y)[..w].iter().enumerate() {
                    if grey {
                        img.data[y * w + x] = look(i)[0];
                    } else {
                        img.data[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&look(i));
                    }
                }
            }
            Ok(img)
        }
        24 | 32 => {
            let n = bpp as usize / 8;
            let mut img = Image::new(w as u32, h as u32, Encoding::Bgr8);
            for y in 0..h {
                for (x, px) in row(y).chunks_exact(n).take(w).enumerate() {
                    img.data[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&px[..3]);
                }
            }
            Ok(img)
        }
        other => Err(format!("{other} bits per pixel at byte 28: 8, 24 or 32 are read")),
    }
}

fn pnm(b: &[u8]) -> Result<Image, String> {
    let magic = b.get(0..2).ok_or("empty file")?;
    let channels = match magic {
        b"P5" => 1,
        b"P6" => 3,
        _ => return Err("not a binary PGM/PPM (no 'P5' or 'P6' at byte 0)".into()),
    };
    // Three numbers after the magic, with comments, then one whitespace byte.
    let mut at = 2;
    let mut nums = Vec::new();
    while nums.len() < 3 {
        while at < b.len() && (b[at].is_ascii_whitespace() || b[at] == b'#') {
            if b[at] == b'#' {
                while at < b.len() && b[at] != b'\n' {
                    at += 1;
                }
            } else {
                at += 1;
            }
        }
        let start = at;
        while at < b.len() && b[at].is_ascii_digit() {
            at += 1;
        }
        let n: usize = std::str::from_utf8(&b[start..at])
            .ok()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| format!("bad header number at byte {start}"))?;
        nums.push(n);
    }
    at += 1;
    let (w, h, max) = (nums[0], nums[1], nums[2]);
    if w == 0 || h == 0 || !(1..=65535).contains(&max) {
        return Err(format!("header {w}x{h} max {max}"));
    }
    let wide = max > 255;
    let bytes = w * h * channels * if wide { 2 } else { 1 };
    let data =
        b.get(at..at + bytes).ok_or_else(|| format!("pixel data ends at byte {}, needs {}", b.len(), at + bytes))?;
    let enc = match (channels, wide) {
        (1, false) => Encoding::Mono8,
        (1, true) => Encoding::Mono16,
        (_, false) => Encoding::Rgb8,
        (_, true) => return Err("16-bit PPM is not read".into()),
    };
    let mut img = Image::new(w as u32, h as u32, enc);
    if wide {
        // PNM is big-endian; our mono16 rows are little-endian.
        for (o, i) in img.data.chunks_exact_mut(2).zip(data.chunks_exact(2)) {
            o.copy_from_slice(&[i[1], i[0]]);
        }
    } else {
        img.data.copy_from_slice(data);
    }
    Ok(img)
}

/// Decodes a PNG (grey or colour, 8 or 16 bits grey; alpha dropped) into a frame.
pub fn png_frame(b: &[u8]) -> Result<Image, String> {
    let mut dec = png::Decoder::new(std::io::Cursor::new(b));
    dec.set_transformations(png::Transformations::EXPAND);
    let mut reader = dec.read_info().map_err(|e| e.to_string())?;
    // The size is checked before the output buffer is allocated (as for JPEG).
    let max = *xsurf_core::limits::IMAGE_SIDE_PX.end();
    let (w, h) = (reader.info().width, reader.info().height);
    if w > max || h > max {
        return Err(format!("{w}x{h} is larger than {max} pixels a side"));
    }
    let mut buf = vec![0; reader.output_buffer_size().unwrap_or(0)];
    let info = reader.next_frame(&mut buf).map_err(|e| e.to_string())?;
    buf.truncate(info.buffer_size());
    let (w, h) = (info.width, info.height);
    let sixteen = info.bit_depth == png::BitDepth::Sixteen;
    let mut img = match (info.color_type, sixteen) {
        (png::ColorType::Grayscale, false) => Image { width: w, height: h, encoding: Encoding::Mono8, data: buf },
        (png::ColorType::Grayscale, true) => Image {
            width: w,
            height: h,
            encoding: Encoding::Mono16,
            data: buf.chunks_exact(2).flat_map(|c| [c[1], c[0]]).collect(),
        },
        (png::ColorType::Rgb, false) => Image { width: w, height: h, encoding: Encoding::Rgb8, data: buf },
        (png::ColorType::Rgba, false) => Image {
            width: w,
            height: h,
            encoding: Encoding::Rgb8,
            data: buf.chunks_exact(4).flat_map(|c| [c[0], c[1], c[2]]).collect(),
        },
        (png::ColorType::GrayscaleAlpha, false) => {
            Image { width: w, height: h, encoding: Encoding::Mono8, data: buf.chunks_exact(2).map(|c| c[0]).collect() }
        }
        (ct, _) => return Err(format!("PNG colour type {ct:?} at {} bits is not read", info.bit_depth as u8)),
    };
    img.data.truncate(img.width as usize * img.height as usize * img.encoding.bytes_per_pixel());
    Ok(img)
}

/// Writes a mono8 image as an 8-bit grey-palette BMP (bottom-up), as the study's frames were.
pub fn write_bmp_mono8(path: &Path, img: &Image) -> Result<(), crate::FileError> {
    let (w, h) = (img.width as usize, img.height as usize);
    let stride = w.div_ceil(4) * 4;
    let offset = 14 + 40 + 1024;
    let size = offset + stride * h;
    let mut b = Vec::with_capacity(size);
    b.extend_from_slice(b"BM");
    b.extend_from_slice(&(size as u32).to_le_bytes());
    b.extend_from_slice(&[0; 4]);
    b.extend_from_slice(&(offset as u32).to_le_bytes());
    b.extend_from_slice(&40u32.to_le_bytes());
    b.extend_from_slice(&(w as i32).to_le_bytes());
    b.extend_from_slice(&(h as i32).to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&8u16.to_le_bytes());
    b.extend_from_slice(&[0; 4]); // BI_RGB
    b.extend_from_slice(&((stride * h) as u32).to_le_bytes());
    b.extend_from_slice(&[0x13, 0x0b, 0, 0, 0x13, 0x0b, 0, 0]); // 72 dpi
    b.extend_from_slice(&256u32.to_le_bytes());
    b.extend_from_slice(&[0; 4]);
    for i in 0..=255u8 {
        b.extend_from_slice(&[i, i, i, 0]);
    }
    for y in (0..h).rev() {
        b.extend_from_slice(&img.data[y * w..y * w + w]);
        b.extend(std::iter::repeat_n(0u8, stride - w));
    }
    crate::write_bytes_atomic(path, &b)
}

/// Writes a mono8 or mono16 image as a binary PGM.
pub fn write_pgm(path: &Path, img: &Image) -> Result<(), crate::FileError> {
    let (max, data): (u32, Vec<u8>) = match img.encoding {
        Encoding::Mono16 => (65535, img.data.chunks_exact(2).flat_map(|c| [c[1], c[0]]).collect()),
        _ => (255, img.data.clone()),
    };
    let mut b = format!("P5\n# xsurf\n{} {}\n{max}\n", img.width, img.height).into_bytes();
    b.extend_from_slice(&data);
    crate::write_bytes_atomic(path, &b)
}

/// Decodes a JPEG (baseline or progressive; grey, YCbCr or RGB; not CMYK) into mono8 or rgb8.
pub fn jpeg_frame(b: &[u8]) -> Result<Image, String> {
    let mut d = jpeg_decoder::Decoder::new(b);
    // The size is checked before the decoder allocates it (a damaged frame header said
    // 65535x65535: 4 GiB for a 600-byte image, found by the fuzz suite).
    d.read_info().map_err(|e| format!("JPEG: {e}"))?;
    let max = *xsurf_core::limits::IMAGE_SIDE_PX.end();
    if let Some(i) = d.info().filter(|i| u32::from(i.width) > max || u32::from(i.height) > max) {
        return Err(format!("JPEG: {}x{} is larger than {max} pixels a side", i.width, i.height));
    }
    d.set_max_decoding_buffer_size(max as usize * max as usize * 3);
    let pixels = d.decode().map_err(|e| format!("JPEG: {e}"))?;
    let info = d.info().ok_or("JPEG: no frame header")?;
    let (w, h) = (u32::from(info.width), u32::from(info.height));
    let enc = match info.pixel_format {
        jpeg_decoder::PixelFormat::L8 => Encoding::Mono8,
        jpeg_decoder::PixelFormat::RGB24 => Encoding::Rgb8,
        other => return Err(format!("JPEG: pixel format {other:?} is not read (grey or colour only)")),
    };
    let need = w as usize * h as usize * enc.bytes_per_pixel();
    if w == 0 || h == 0 || pixels.len() != need {
        return Err(format!("JPEG: {w}x{h} decoded to {} bytes, {need} expected", pixels.len()));
    }
    let mut img = Image::new(w, h, enc);
    img.data = pixels;
    Ok(img)
}

/// Encodes a mono8 or rgb8 frame as a baseline JPEG of `quality` (1..=100; 4:2:0 chroma for
/// colour). Other encodings are refused.
pub fn encode_jpeg(img: &Image, quality: u8) -> Result<Vec<u8>, String> {
    let colour = match img.encoding {
        Encoding::Mono8 => jpeg_encoder::ColorType::Luma,
        Encoding::Rgb8 => jpeg_encoder::ColorType::Rgb,
        other => return Err(format!("JPEG: {} frames are not encoded (mono8 or rgb8 only)", other.ros_name())),
    };
    let (w, h) = (u16::try_from(img.width), u16::try_from(img.height));
    let (Ok(w), Ok(h)) = (w, h) else {
        return Err(format!("JPEG: {}x{} is larger than 65535 pixels a side", img.width, img.height));
    };
    let mut out = Vec::with_capacity(img.data.len() / 4);
    let encoder = jpeg_encoder::Encoder::new(&mut out, quality.clamp(1, 100));
    encoder.encode(&img.data, w, h, colour).map_err(|e| format!("JPEG: {e}"))?;
    Ok(out)
}

/// Writes a frame as a JPEG file of `quality`, atomically.
pub fn write_jpeg(path: &Path, img: &Image, quality: u8) -> Result<(), crate::FileError> {
    let bytes = encode_jpeg(img, quality).map_err(|e| crate::FileError::new(path, std::io::Error::other(e)))?;
    crate::write_bytes_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h, Encoding::Mono8);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i * 7 % 251) as u8;
        }
        img
    }

    #[test]
    fn jpeg_round_trips_within_its_loss_and_refuses_what_it_cannot_encode() {
        // A smooth scene (JPEG's best case) and a noisy one, grey and colour.
        for enc in [Encoding::Mono8, Encoding::Rgb8] {
            let (w, h) = (96u32, 64u32);
            let mut img = Image::new(w, h, enc);
            let n = enc.bytes_per_pixel();
            for (i, v) in img.data.iter_mut().enumerate() {
                let (x, y) = ((i / n) as u32 % w, (i / n) as u32 / w);
                *v = (40.0 + 1.5 * f64::from(x) + 0.8 * f64::from(y) + 10.0 * ((i % n) as f64)) as u8;
            }
            let bytes = encode_jpeg(&img, 90).unwrap();
            let back = jpeg_frame(&bytes).unwrap();
            assert_eq!((back.width, back.height, back.encoding), (w, h, enc));
            let mse =
                img.data.iter().zip(&back.data).map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2)).sum::<f64>()
                    / img.data.len() as f64;
            let psnr = 10.0 * (255.0f64 * 255.0 / mse.max(1e-9)).log10();
            assert!(psnr > 38.0, "{enc:?}: PSNR {psnr:.1} dB at quality 90");
            // Cut short: a named refusal, not a panic.
            let e = jpeg_frame(&bytes[..bytes.len() / 2]).unwrap_err();
            assert!(e.starts_with("JPEG"), "{e}");
        }
        let e = encode_jpeg(&Image::new(4, 4, Encoding::Mono16), 90).unwrap_err();
        assert!(e.contains("mono16"), "{e}");
    }

    #[test]
    fn bmp_pgm_png_round_trips_and_errors() {
        let dir = std::env::temp_dir().join(format!("xsurf-frames-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let img = gradient(13, 5); // odd width: BMP rows are padded
        write_bmp_mono8(&dir.join("a.bmp"), &img).unwrap();
        assert_eq!(read_frame(&dir.join("a.bmp")).unwrap(), img);
        write_pgm(&dir.join("a.pgm"), &img).unwrap();
        assert_eq!(read_frame(&dir.join("a.pgm")).unwrap(), img);
        let mut wide = Image::new(3, 2, Encoding::Mono16);
        wide.data = vec![1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12];
        write_pgm(&dir.join("w.pgm"), &wide).unwrap();
        assert_eq!(read_frame(&dir.join("w.pgm")).unwrap(), wide);
        let png = crate::image::encode_png(13, 5, crate::image::PngKind::Grey8, &img.data).unwrap();
        std::fs::write(dir.join("a.png"), png).unwrap();
        assert_eq!(read_frame(&dir.join("a.png")).unwrap(), img);
        // Errors name the file and the offset.
        let b = std::fs::read(dir.join("a.bmp")).unwrap();
        std::fs::write(dir.join("cut.bmp"), &b[..b.len() - 10]).unwrap();
        let e = read_frame(&dir.join("cut.bmp")).unwrap_err().to_string();
        assert!(e.contains("cut.bmp") && e.contains("pixel data ends at byte"), "{e}");
        std::fs::write(dir.join("x.tif"), b"II*").unwrap();
        assert!(read_frame(&dir.join("x.tif")).unwrap_err().to_string().contains("extension"));
        std::fs::write(dir.join("bad.pgm"), b"P5\n3 x\n255\n").unwrap();
        assert!(read_frame(&dir.join("bad.pgm")).unwrap_err().to_string().contains("bad header number at byte"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
