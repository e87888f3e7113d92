//! Small raster plots for reports (bars, scatter, lines) with a 3x5 pixel font, written as PNG.
//! Enough to show a technician the residuals; no layout engine.

use crate::image::{write_png, PngKind};
use crate::FileError;
use std::path::Path;

/// An RGB colour.
pub type Rgb = [u8; 3];
/// Black.
pub const BLACK: Rgb = [0, 0, 0];
/// Light grey (grid lines, unused items).
pub const GREY: Rgb = [190, 190, 190];
/// Red (rejected items).
pub const RED: Rgb = [200, 30, 30];
/// Blue (used items).
pub const BLUE: Rgb = [40, 90, 200];

/// A distinct colour for series `i`.
pub fn palette(i: usize) -> Rgb {
    const P: [Rgb; 8] = [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [23, 190, 207],
    ];
    P[i % P.len()]
}

/// 3x5 glyphs, rows top to bottom, 3 bits each (MSB left).
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [7, 4, 4, 4, 7],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [7, 4, 5, 5, 7],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 7],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [7, 5, 5, 5, 7],
        'P' => [7, 5, 7, 4, 4],
        'Q' => [7, 5, 5, 7, 1],
        'R' => [6, 5, 6, 5, 5],
        'S' => [7, 4, 7, 1, 7],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        '/' => [1, 1, 2, 4, 4],
        '(' => [2, 4, 4, 4, 2],
        ')' => [2, 1, 1, 1, 2],
        '%' => [5, 1, 2, 4, 5],
        '=' => [0, 7, 0, 7, 0],
        _ => [0; 5],
    }
}

/// An RGB raster.
#[derive(Debug, Clone)]
pub struct Canvas {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// RGB bytes, row-major.
    pub rgb: Vec<u8>,
}

impl Canvas {
    /// A white canvas.
    pub fn new(width: usize, height: usize) -> Canvas {
        Canvas { width, height, rgb: vec![255; width * height * 3] }
    }
    /// Sets one pixel (ignored outside).
    pub fn pixel(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let i = (y as usize * self.width + x as usize) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }
    /// A filled rectangle (corners inclusive, any order).
    pub fn rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb) {
        for y in y0.min(y1)..=y0.max(y1) {
            for x in x0.min(x1)..=x0.max(x1) {
                self.pixel(x, y, c);
            }
        }
    }
    /// A one-pixel line.
    pub fn line(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb) {
        let n = (x1 - x0).abs().max((y1 - y0).abs()).max(1);
        for k in 0..=n {
            let t = k as f64 / n as f64;
            self.pixel(x0 + ((x1 - x0) as f64 * t).round() as i64, y0 + ((y1 - y0) as f64 * t).round() as i64, c);
        }
    }
    /// Text in the 3x5 font at `scale` pixels per font pixel; `(x, y)` is the top-left corner.
    pub fn text(&mut self, x: i64, y: i64, s: &str, scale: i64, c: Rgb) {
        for (i, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        let (px, py) = (x + (i as i64 * 4 + col) * scale, y + row as i64 * scale);
                        self.rect(px, py, px + scale - 1, py + scale - 1, c);
                    }
                }
            }
        }
    }
    /// Writes the canvas as PNG (atomically).
    pub fn write_png(&self, path: &Path) -> Result<(), FileError> {
        write_png(path, self.width as u32, self.height as u32, PngKind::Rgb8, &self.rgb)
    }
}

/// A plot: a canvas with a framed data area mapping `x_range` x `y_range`.
#[derive(Debug, Clone)]
pub struct Plot {
    /// The raster.
    pub canvas: Canvas,
    x_range: (f64, f64),
    y_range: (f64, f64),
    area: (i64, i64, i64, i64),
}

fn label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

impl Plot {
    /// A 640x400 plot with a title, axis names and the range's end values written on the axes.
    pub fn new(title: &str, x_name: &str, y_name: &str, x_range: (f64, f64), y_range: (f64, f64)) -> Plot {
        let mut canvas = Canvas::new(640, 400);
        let area = (70, 40, 620, 350);
        canvas.text(70, 12, title, 3, BLACK);
        canvas.text(area.0, area.3 + 26, x_name, 2, BLACK);
        canvas.text(4, 22, y_name, 2, BLACK);
        let fix = |r: (f64, f64)| if r.1 > r.0 { r } else { (r.0 - 1.0, r.0 + 1.0) };
        let (x_range, y_range) = (fix(x_range), fix(y_range));
        canvas.rect(area.0, area.1, area.2, area.1, BLACK);
        canvas.rect(area.0, area.3, area.2, area.3, BLACK);
        canvas.rect(area.0, area.1, area.0, area.3, BLACK);
        canvas.rect(area.2, area.1, area.2, area.3, BLACK);
        canvas.text(area.0, area.3 + 6, &label(x_range.0), 2, BLACK);
        let xr = label(x_range.1);
        canvas.text(area.2 - 8 * xr.len() as i64, area.3 + 6, &xr, 2, BLACK);
        let (y0, y1) = (label(y_range.0), label(y_range.1));
        canvas.text(area.0 - 4 - 8 * y0.len() as i64, area.3 - 10, &y0, 2, BLACK);
        canvas.text(area.0 - 4 - 8 * y1.len() as i64, area.1, &y1, 2, BLACK);
        Plot { canvas, x_range, y_range, area }
    }
    /// Data to canvas coordinates.
    pub fn to_px(&self, x: f64, y: f64) -> (i64, i64) {
        let (a, b, c, d) = self.area;
        let fx = (x - self.x_range.0) / (self.x_range.1 - self.x_range.0);
        let fy = (y - self.y_range.0) / (self.y_range.1 - self.y_range.0);
        ((a as f64 + fx * (c - a) as f64).round() as i64, (d as f64 - fy * (d - b) as f64).round() as i64)
    }
    /// A dot of radius `r` pixels at a data point.
    pub fn dot(&mut self, x: f64, y: f64, r: i64, c: Rgb) {
        let (px, py) = self.to_px(x, y);
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        for dy in -r..=r {
            for dx in -r..=r {
                if dx * dx + dy * dy <= r * r {
                    self.canvas.pixel(px + dx, py + dy, c);
                }
            }
        }
    }
    /// A vertical bar from `y = 0` (or the range's bottom) to `y`, centred at `x`, `width` data units.
    pub fn bar(&mut self, x: f64, width: f64, y: f64, c: Rgb) {
        let base = self.y_range.0.max(0.0).min(self.y_range.1);
        let (x0, y0) = self.to_px(x - width * 0.5, base);
        let (x1, y1) = self.to_px(x + width * 0.5, y.clamp(self.y_range.0, self.y_range.1));
        self.canvas.rect(x0 + 1, y0 - 1, x1 - 1, y1, c);
    }
    /// A horizontal reference line at `y`.
    pub fn hline(&mut self, y: f64, c: Rgb) {
        let (x0, py) = self.to_px(self.x_range.0, y);
        let (x1, _) = self.to_px(self.x_range.1, y);
        self.canvas.line(x0 + 1, py, x1 - 1, py, c);
    }
    /// A circle of radius `r` data units (x units) around `(x, y)`.
    pub fn circle(&mut self, x: f64, y: f64, r: f64, c: Rgb) {
        for k in 0..720 {
            let a = std::f64::consts::TAU * f64::from(k) / 720.0;
            let (px, py) = self.to_px(x + r * a.cos(), y + r * a.sin());
            self.canvas.pixel(px, py, c);
        }
    }
    /// A legend line at the top right.
    pub fn legend(&mut self, row: usize, text: &str, c: Rgb) {
        let y = self.area.1 + 6 + 14 * row as i64;
        let x = self.area.2 - 8 - 8 * text.len() as i64 - 14;
        self.canvas.rect(x, y, x + 8, y + 8, c);
        self.canvas.text(x + 14, y, text, 2, BLACK);
    }
    /// Writes the plot as PNG.
    pub fn write_png(&self, path: &Path) -> Result<(), FileError> {
        self.canvas.write_png(path)
    }
}
