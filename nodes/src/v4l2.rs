//! camera_driver's `v4l2` source: a USB/UVC camera through Video4Linux2.
//!
//! The frame conversion (the camera's pixel format to the `encoding` the node publishes) is
//! plain code, built and tested always. Opening the device and streaming from it needs the cargo
//! feature `v4l2` (the `linuxvideo` crate: pure Rust, memory-mapped streaming I/O). Without it,
//! [`Capture::open`] says how to get it.

use xsurf_core::image::{luma, Encoding, Image};

/// The camera pixel formats the source reads, as V4L2 fourcc codes.
pub const FORMATS: [[u8; 4]; 4] = [*b"GREY", *b"YUYV", *b"RGB3", *b"BGR3"];

/// The formats to ask the camera for, best first, for the `encoding` published: the one that
/// needs no conversion, then the one that loses nothing.
pub fn preference(encoding: Encoding) -> [[u8; 4]; 4] {
    match encoding {
        Encoding::Mono8 | Encoding::Mono16 => [*b"GREY", *b"YUYV", *b"RGB3", *b"BGR3"],
        Encoding::Rgb8 => [*b"RGB3", *b"BGR3", *b"YUYV", *b"GREY"],
        Encoding::Bgr8 => [*b"BGR3", *b"RGB3", *b"YUYV", *b"GREY"],
    }
}

/// A frame in the camera's layout.
#[derive(Debug, Clone, Copy)]
pub struct RawFrame<'a> {
    /// V4L2 fourcc.
    pub fourcc: [u8; 4],
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bytes from one row to the next (at least the row's pixels).
    pub bytes_per_line: u32,
    /// The used part of the buffer.
    pub data: &'a [u8],
}

/// BT.601 (studio range, as UVC cameras send YUYV) to RGB.
fn yuv_to_rgb(y: u8, u: u8, v: u8) -> [u8; 3] {
    let c = 1.164 * (f32::from(y) - 16.0);
    let d = f32::from(u) - 128.0;
    let e = f32::from(v) - 128.0;
    let q = |x: f32| x.round().clamp(0.0, 255.0) as u8;
    [q(c + 1.596 * e), q(c - 0.392 * d - 0.813 * e), q(c + 2.017 * d)]
}

/// Converts a camera frame to an image of `encoding` (mono8, rgb8 or bgr8). Grey from colour is
/// the luma (0.299 R + 0.587 G + 0.114 B; the Y of YUYV); colour from grey repeats it.
pub fn convert(f: &RawFrame<'_>, encoding: Encoding) -> Result<Image, String> {
    let name = String::from_utf8_lossy(&f.fourcc).into_owned();
    let bpp = match &f.fourcc {
        b"GREY" => 1,
        b"YUYV" => 2,
        b"RGB3" | b"BGR3" => 3,
        _ => return Err(format!("pixel format {name} is not read (GREY, YUYV, RGB3, BGR3)")),
    };
    let (w, h, stride) = (f.width as usize, f.height as usize, f.bytes_per_line as usize);
    if w == 0 || h == 0 || (f.fourcc == *b"YUYV" && w % 2 == 1) {
        return Err(format!("{name} frame of {w}x{h} pixels"));
    }
    if stride < w * bpp {
        return Err(format!("{name} frame: {stride} bytes per line for {w} pixels of {bpp} bytes"));
    }
    let need = stride * (h - 1) + w * bpp;
    if f.data.len() < need {
        return Err(format!("{name} frame of {w}x{h}: {} bytes, needs {need}", f.data.len()));
    }
    let channels = match encoding {
        Encoding::Mono8 => 1,
        Encoding::Rgb8 | Encoding::Bgr8 => 3,
        Encoding::Mono16 => return Err("the v4l2 source publishes mono8, rgb8 or bgr8".into()),
    };
    let mut data = Vec::with_capacity(w * h * channels);
    for r in 0..h {
        let row = &f.data[r * stride..r * stride + w * bpp];
        match (&f.fourcc, channels) {
            (b"GREY", 1) => data.extend_from_slice(row),
            (b"GREY", _) => data.extend(row.iter().flat_map(|&g| [g, g, g])),
            (b"YUYV", 1) => data.extend(row.iter().step_by(2)),
            (b"YUYV", _) => {
                for q in row.chunks_exact(4) {
                    let (y0, u, y1, v) = (q[0], q[1], q[2], q[3]);
                    data.extend(yuv_to_rgb(y0, u, v));
                    data.extend(yuv_to_rgb(y1, u, v));
                }
            }
            (_, 1) => {
                let (ri, bi) = if f.fourcc == *b"RGB3" { (0, 2) } else { (2, 0) };
                data.extend(row.chunks_exact(3).map(|p| {
                    luma(f32::from(p[ri]), f32::from(p[1]), f32::from(p[bi])).round().clamp(0.0, 255.0) as u8
                }));
            }
            _ => data.extend(row.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2]])),
        }
    }
    // Colour samples so far are in RGB order, except a BGR3 frame copied as it came.
    let in_bgr = f.fourcc == *b"BGR3";
    if channels == 3 && in_bgr != (encoding == Encoding::Bgr8) {
        for p in data.chunks_exact_mut(3) {
            p.swap(0, 2);
        }
    }
    Ok(Image { width: f.width, height: f.height, encoding, data })
}

/// What the capture thread reports.
#[derive(Debug)]
pub enum Captured {
    /// A frame, stamped with the wall-clock time (ns) it was dequeued.
    Frame(i64, Image),
    /// A frame that could not be used (flagged corrupt by the driver, or not convertible).
    Bad(String),
    /// The stream failed (the camera was unplugged): the capture is over.
    Ended(String),
}

/// A camera streaming into a channel from a thread of its own.
pub struct Capture {
    frames: std::sync::mpsc::Receiver<Captured>,
    /// The format the camera agreed to.
    pub fourcc: [u8; 4],
}

impl Capture {
    /// The next thing the camera sent, if any.
    pub fn try_next(&self) -> Option<Captured> {
        match self.frames.try_recv() {
            Ok(f) => Some(f),
            Err(std::sync::mpsc::TryRecvError::Empty) => None,
            Err(std::sync::mpsc::TryRecvError::Disconnected) => Some(Captured::Ended("capture thread ended".into())),
        }
    }

    /// Opens `device`, negotiates `width` x `height` at `fps` in the best format for `encoding`,
    /// and starts streaming. Frames the node has not taken yet are dropped beyond two.
    #[cfg(feature = "v4l2")]
    pub fn open(
        device: &std::path::Path,
        width: u32,
        height: u32,
        fps: f64,
        encoding: Encoding,
    ) -> Result<Capture, String> {
        use linuxvideo::format::{PixFormat, PixelFormat};
        use linuxvideo::{BufType, Device, Fract};
        let dev_name = device.display().to_string();
        let io = |what: &str, e: std::io::Error| format!("{dev_name}: {what}: {e}");
        let dev = Device::open(device).map_err(|e| io("open", e))?;
        let offered: Vec<PixelFormat> = dev
            .formats(BufType::VIDEO_CAPTURE)
            .map(|f| f.map(|f| f.pixel_format()))
            .collect::<std::io::Result<_>>()
            .map_err(|e| io("list formats", e))?;
        let Some(fourcc) = preference(encoding).into_iter().find(|c| offered.contains(&PixelFormat::from_fourcc(*c)))
        else {
            let names: Vec<String> =
                offered.iter().map(|p| String::from_utf8_lossy(&p.as_fourcc()).into_owned()).collect();
            return Err(format!("{dev_name}: offers {names:?}, none of GREY, YUYV, RGB3, BGR3"));
        };
        let cap = dev
            .video_capture(PixFormat::new(width, height, PixelFormat::from_fourcc(fourcc)))
            .map_err(|e| io("set format", e))?;
        let (got_w, got_h, got, bytes_per_line) = {
            let f = cap.format();
            (f.width(), f.height(), f.pixel_format().as_fourcc(), f.bytes_per_line())
        };
        if (got_w, got_h) != (width, height) || got != fourcc {
            return Err(format!(
                "{dev_name}: asked for {width}x{height} {}, the camera gives {got_w}x{got_h} {} (set width and height to a size it offers)",
                String::from_utf8_lossy(&fourcc),
                String::from_utf8_lossy(&got),
            ));
        }
        let per_frame = ((1000.0 / fps).round() as u32).max(1);
        if let Err(e) = cap.set_frame_interval(Fract::new(per_frame, 1000)) {
            log::warn!("camera_driver: {dev_name}: frame rate {fps} Hz not set ({e}); the camera keeps its own");
        }
        let mut stream = cap.into_stream().map_err(|e| io("start streaming", e))?;
        let (tx, rx) = std::sync::mpsc::sync_channel(2);
        let name = dev_name.clone();
        std::thread::Builder::new()
            .name(format!("v4l2 {dev_name}"))
            .spawn(move || loop {
                let r = stream.dequeue(|buf| {
                    let now = xsurf_runtime::wall_clock_ns();
                    if buf.is_error() {
                        return Ok(Captured::Bad(format!("{name}: the driver flagged a corrupt frame")));
                    }
                    let raw = RawFrame { fourcc, width, height, bytes_per_line, data: &buf };
                    Ok(match convert(&raw, encoding) {
                        Ok(img) => Captured::Frame(now, img),
                        Err(e) => Captured::Bad(format!("{name}: {e}")),
                    })
                });
                let item = match r {
                    Ok(item) => item,
                    Err(e) => {
                        let _ = tx.send(Captured::Ended(format!("{name}: stream: {e}")));
                        return;
                    }
                };
                match tx.try_send(item) {
                    Ok(()) | Err(std::sync::mpsc::TrySendError::Full(_)) => {}
                    Err(std::sync::mpsc::TrySendError::Disconnected(_)) => return,
                }
            })
            .map_err(|e| format!("{dev_name}: thread: {e}"))?;
        Ok(Capture { frames: rx, fourcc })
    }

    /// Without the `v4l2` feature: refuses, saying how to build it in.
    #[cfg(not(feature = "v4l2"))]
    pub fn open(device: &std::path::Path, _: u32, _: u32, _: f64, _: Encoding) -> Result<Capture, String> {
        Err(format!("{}: this build has no V4L2 support (build xsurf-nodes with `--features v4l2`)", device.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(fourcc: &[u8; 4], w: u32, h: u32, stride: u32, data: &[u8]) -> Vec<u8> {
        convert(&RawFrame { fourcc: *fourcc, width: w, height: h, bytes_per_line: stride, data }, Encoding::Mono8)
            .map(|i| i.data)
            .unwrap_or_default()
    }

    #[test]
    fn grey_rows_skip_the_padding() {
        // 3 pixels, 4 bytes a line (one padding byte), 2 rows.
        assert_eq!(frame(b"GREY", 3, 2, 4, &[1, 2, 3, 99, 4, 5, 6]), [1, 2, 3, 4, 5, 6]);
    }

    #[test]
    fn yuyv_gives_the_luma_and_bt601_colour() {
        let data = [16, 128, 235, 128, 81, 90, 81, 240];
        assert_eq!(frame(b"YUYV", 2, 2, 4, &data), [16, 235, 81, 81]);
        let raw = RawFrame { fourcc: *b"YUYV", width: 2, height: 2, bytes_per_line: 4, data: &data };
        let rgb = convert(&raw, Encoding::Rgb8).unwrap().data;
        // Black and white, then BT.601 red (Y 81, U 90, V 240).
        assert_eq!(&rgb[..6], [0, 0, 0, 255, 255, 255]);
        let red = &rgb[6..9];
        assert!(red[0] >= 250 && red[1] <= 5 && red[2] <= 5, "{red:?}");
        let bgr = convert(&raw, Encoding::Bgr8).unwrap().data;
        assert_eq!(&bgr[6..9], [red[2], red[1], red[0]]);
    }

    #[test]
    fn colour_orders_and_luma() {
        let px = [200u8, 100, 50];
        let rgb = RawFrame { fourcc: *b"RGB3", width: 1, height: 1, bytes_per_line: 3, data: &px };
        assert_eq!(convert(&rgb, Encoding::Rgb8).unwrap().data, [200, 100, 50]);
        assert_eq!(convert(&rgb, Encoding::Bgr8).unwrap().data, [50, 100, 200]);
        let luma = (0.299f32 * 200.0 + 0.587 * 100.0 + 0.114 * 50.0).round() as u8;
        assert_eq!(convert(&rgb, Encoding::Mono8).unwrap().data, [luma]);
        let bgr = RawFrame { fourcc: *b"BGR3", ..rgb };
        assert_eq!(convert(&bgr, Encoding::Rgb8).unwrap().data, [50, 100, 200]);
        assert_eq!(convert(&bgr, Encoding::Bgr8).unwrap().data, [200, 100, 50]);
        let grey = RawFrame { fourcc: *b"GREY", data: &px[..1], bytes_per_line: 1, ..rgb };
        assert_eq!(convert(&grey, Encoding::Rgb8).unwrap().data, [200, 200, 200]);
    }

    #[test]
    fn bad_frames_are_errors_that_name_the_problem() {
        let raw = |fourcc: &[u8; 4], w, h, stride, data: &'static [u8]| {
            convert(&RawFrame { fourcc: *fourcc, width: w, height: h, bytes_per_line: stride, data }, Encoding::Mono8)
                .unwrap_err()
        };
        assert!(raw(b"MJPG", 2, 2, 4, &[0; 8]).contains("MJPG"));
        assert!(raw(b"GREY", 4, 2, 4, &[0; 7]).contains("7 bytes, needs 8"));
        assert!(raw(b"GREY", 4, 2, 3, &[0; 8]).contains("3 bytes per line"));
        assert!(raw(b"YUYV", 3, 1, 6, &[0; 6]).contains("3x1"));
        assert!(raw(b"GREY", 0, 2, 4, &[0; 8]).contains("0x2"));
    }

    #[test]
    fn preference_puts_the_native_format_first() {
        assert_eq!(preference(Encoding::Mono8)[0], *b"GREY");
        assert_eq!(preference(Encoding::Rgb8)[0], *b"RGB3");
        assert_eq!(preference(Encoding::Bgr8)[0], *b"BGR3");
        for e in [Encoding::Mono8, Encoding::Rgb8, Encoding::Bgr8] {
            let mut p = preference(e).to_vec();
            p.sort();
            let mut all = FORMATS.to_vec();
            all.sort();
            assert_eq!(p, all);
        }
    }

    #[cfg(not(feature = "v4l2"))]
    #[test]
    fn without_the_feature_open_says_how_to_build_it() {
        let e = Capture::open("/dev/video0".as_ref(), 640, 480, 30.0, Encoding::Mono8).err().unwrap();
        assert!(e.contains("/dev/video0") && e.contains("--features v4l2"), "{e}");
    }

    #[cfg(feature = "v4l2")]
    #[test]
    fn a_missing_device_is_an_error_naming_it() {
        let e = Capture::open("/dev/video-xsurf-none".as_ref(), 640, 480, 30.0, Encoding::Mono8).err().unwrap();
        assert!(e.contains("/dev/video-xsurf-none") && e.contains("open"), "{e}");
    }
}
