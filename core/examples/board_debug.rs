//! Draws the board detector's candidates (grey crosses) and its largest lattice (white, with
//! cell labels printed) over an image, for diagnosis:
//! `cargo run --release -p xsurf-core --example board_debug -- IN.pgm COLSxROWS OUT.ppm`
//! (IN as binary PGM; convert other formats first).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use xsurf_core::calib::board::{lattice_debug, BoardSpec};
use xsurf_core::image::{Encoding, Image};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let bytes = std::fs::read(&args[1]).expect("read the PGM");
    // P5\nW H\n255\n
    let text = String::from_utf8_lossy(&bytes[..64.min(bytes.len())]).to_string();
    let mut it = text.split_ascii_whitespace();
    assert_eq!(it.next(), Some("P5"));
    let w: u32 = it.next().unwrap().parse().unwrap();
    let h: u32 = it.next().unwrap().parse().unwrap();
    let start = bytes.len() - (w * h) as usize;
    let mut img = Image::new(w, h, Encoding::Mono8);
    img.data.copy_from_slice(&bytes[start..]);
    let spec = BoardSpec::parse(&args[2], 0.02).unwrap();
    let (cands, lattice) = lattice_debug(&img.view().unwrap(), &spec);
    if let Ok(q) = std::env::var("NEAR") {
        let (x, y) = q.split_once(',').unwrap();
        let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
        for p in &cands {
            if (p[0] - x).hypot(p[1] - y) < 20.0 {
                println!("candidate near: {p:?}");
            }
        }
    }
    let mut out = Vec::with_capacity((w * h * 3) as usize);
    for &v in &img.data {
        out.extend([v / 2, v / 2, v / 2]);
    }
    let mut put = |x: f64, y: f64, c: [u8; 3], r: i64| {
        for d in -r..=r {
            for (xx, yy) in [(x as i64 + d, y as i64), (x as i64, y as i64 + d)] {
                if xx >= 0 && yy >= 0 && xx < i64::from(w) && yy < i64::from(h) {
                    let i = ((yy as u32 * w + xx as u32) * 3) as usize;
                    out[i..i + 3].copy_from_slice(&c);
                }
            }
        }
    };
    for p in &cands {
        put(p[0], p[1], [0, 0, 255], 2);
    }
    for (cell, p) in &lattice {
        let c = if (cell.0 + cell.1) % 2 == 0 { [255, 255, 0] } else { [0, 255, 0] };
        put(p[0], p[1], c, 4);
    }
    let mut f = format!("P6\n{w} {h}\n255\n").into_bytes();
    f.extend(out);
    std::fs::write(&args[3], f).unwrap();
    println!("{} candidates, lattice of {}", cands.len(), lattice.len());
    let mut cells: Vec<_> = lattice.iter().map(|(c, p)| (c.1, c.0, p[0].round(), p[1].round())).collect();
    cells.sort_by(|a, b| a.partial_cmp(b).unwrap());
    for c in cells {
        print!("({},{})@{},{} ", c.1, c.0, c.2, c.3);
    }
    println!();
}
