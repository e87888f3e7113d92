//! A preview picture of a surface, rendered in software: an orthographic view from above and
//! to the side of the scan, z-buffered, Lambert-shaded with the vertex colours.

use crate::scene::TexturedPlane;
use xsurf_core::mesh::Mesh;

/// Direction the preview looks from (table frame): above, in front, a little to the side.
const VIEW_FROM: [f32; 3] = [0.35, -0.75, 1.0];
/// Background colour.
const BACKGROUND: [u8; 3] = [38, 40, 46];

fn normalize(v: [f32; 3]) -> [f32; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-12);
    [v[0] / n, v[1] / n, v[2] / n]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Opacity of the surface over the radiograph.
const SURFACE_ALPHA: f32 = 0.6;

/// Renders `mesh` into a `width` x `height` RGB8 image (row-major, top row first).
pub fn render(mesh: &Mesh, width: u32, height: u32) -> Vec<u8> {
    render_scene(mesh, None, width, height)
}

/// Renders `mesh` over the radiograph `plane` (semi-transparent where they overlap). A plane
/// whose PNG does not decode is left out.
pub fn render_scene(mesh: &Mesh, plane: Option<&TexturedPlane>, width: u32, height: u32) -> Vec<u8> {
    let (w, h) = (width as usize, height as usize);
    let mut rgb: Vec<u8> = std::iter::repeat_n(BACKGROUND, w * h).flatten().collect();
    let texture = plane.and_then(|p| {
        let (tw, th, px) = crate::image::decode_png_rgb(&p.png).ok()?;
        (p.uv.len() == p.positions.len() && tw > 0 && th > 0).then_some((p, tw as usize, th as usize, px))
    });
    if (mesh.triangles.is_empty() && texture.is_none()) || w == 0 || h == 0 {
        return rgb;
    }
    // View basis: d towards the viewer, right = Z x d (horizontal), up = d x right.
    let d = normalize(VIEW_FROM);
    let right = normalize(cross([0.0, 0.0, 1.0], d));
    let up = cross(d, right);
    let proj = |p: [f32; 3]| [dot(p, right), dot(p, up), dot(p, d)];
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    let mut grow = |p: [f32; 3]| {
        let q = proj(p);
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    };
    for t in &mesh.triangles {
        for &i in t {
            grow(mesh.positions[i as usize]);
        }
    }
    if let Some((p, ..)) = &texture {
        p.positions.iter().for_each(|&q| grow(q));
    }
    let margin = 0.05;
    let span = ((hi[0] - lo[0]) / w as f32).max((hi[1] - lo[1]) / h as f32).max(1e-9) * (1.0 + 2.0 * margin);
    let (cx, cy) = ((lo[0] + hi[0]) * 0.5, (lo[1] + hi[1]) * 0.5);
    let to_px = |p: [f32; 3]| {
        let q = proj(p);
        [(q[0] - cx) / span + w as f32 * 0.5, h as f32 * 0.5 - (q[1] - cy) / span, q[2]]
    };
    // The radiograph first, into its own layer.
    let mut under: Vec<Option<[f32; 3]>> = vec![None; w * h];
    if let Some((p, tw, th, px)) = &texture {
        let scr: Vec<[f32; 3]> = p.positions.iter().map(|&q| to_px(q)).collect();
        let mut depth = vec![f32::NEG_INFINITY; w * h];
        raster(&scr, &p.triangles, w, h, &mut depth, |i, t, wts| {
            let [a, b, c] = t.map(|v| p.uv[v as usize]);
            let u = wts[0] * a[0] + wts[1] * b[0] + wts[2] * c[0];
            let v = wts[0] * a[1] + wts[1] * b[1] + wts[2] * c[1];
            let x = ((u * *tw as f32) as usize).min(tw - 1);
            let y = (((1.0 - v) * *th as f32) as usize).min(th - 1);
            let k = 3 * (y * tw + x);
            let col = [f32::from(px[k]), f32::from(px[k + 1]), f32::from(px[k + 2])];
            under[i] = Some(col);
            rgb[3 * i..3 * i + 3].copy_from_slice(&col.map(|v| v as u8));
        });
    }
    if mesh.triangles.is_empty() {
        return rgb;
    }
    let scr: Vec<[f32; 3]> = mesh.positions.iter().map(|&p| to_px(p)).collect();
    let light = normalize([0.5 * d[0] + 0.3, 0.5 * d[1] + 0.2, d[2] + 0.2]);
    let normals = if mesh.normals.len() == mesh.positions.len() {
        mesh.normals.clone()
    } else {
        let mut m = mesh.clone();
        m.compute_normals();
        m.normals
    };
    let mut depth = vec![f32::NEG_INFINITY; w * h];
    raster(&scr, &mesh.triangles, w, h, &mut depth, |i, t, [wa, wb, wc]| {
        let [ia, ib, ic] = t.map(|v| v as usize);
        let n = normalize([0, 1, 2].map(|k| wa * normals[ia][k] + wb * normals[ib][k] + wc * normals[ic][k]));
        let shade = 0.28 + 0.72 * dot(n, light).abs();
        let col = [0, 1, 2].map(|k| {
            let c = |v: usize| f32::from(mesh.colors.get(v).map_or(200, |c| c[k]));
            let s = (wa * c(ia) + wb * c(ib) + wc * c(ic)) * shade;
            match under[i] {
                Some(u) => SURFACE_ALPHA * s + (1.0 - SURFACE_ALPHA) * u[k],
                None => s,
            }
        });
        rgb[3 * i..3 * i + 3].copy_from_slice(&col.map(|v| v.clamp(0.0, 255.0) as u8));
    });
    rgb
}

/// Rasterises the screen-space triangles with a z-buffer (larger z nearer); `shade(pixel,
/// triangle, barycentric weights)` is called for each visible pixel.
fn raster(
    scr: &[[f32; 3]],
    triangles: &[[u32; 3]],
    w: usize,
    h: usize,
    depth: &mut [f32],
    mut shade: impl FnMut(usize, [u32; 3], [f32; 3]),
) {
    for &t in triangles {
        let [a, b, c] = t.map(|i| scr[i as usize]);
        let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as usize;
        let x1 = (a[0].max(b[0]).max(c[0]).ceil().max(0.0) as usize).min(w - 1);
        let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as usize;
        let y1 = (a[1].max(b[1]).max(c[1]).ceil().max(0.0) as usize).min(h - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let wa = ((b[0] - px) * (c[1] - py) - (b[1] - py) * (c[0] - px)) / area;
                let wb = ((c[0] - px) * (a[1] - py) - (c[1] - py) * (a[0] - px)) / area;
                let wc = 1.0 - wa - wb;
                if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                    continue;
                }
                let z = wa * a[2] + wb * b[2] + wc * c[2];
                let i = y * w + x;
                if z <= depth[i] {
                    continue;
                }
                depth[i] = z;
                shade(i, t, [wa, wb, wc]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_covers_the_middle_and_leaves_the_corners() {
        let m = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            colors: vec![[255, 255, 255]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let img = render(&m, 64, 48);
        let px = |x: usize, y: usize| &img[3 * (y * 64 + x)..3 * (y * 64 + x) + 3];
        assert_ne!(px(32, 24), &BACKGROUND, "the surface is drawn");
        assert!(px(32, 24)[0] > 100, "and lit");
        assert_eq!(px(0, 0), &BACKGROUND);
        assert_eq!(render(&Mesh::default(), 8, 8).len(), 8 * 8 * 3);
    }

    #[test]
    fn the_radiograph_shows_under_and_through_the_surface() {
        // A 2x1 texture: left half black, right half white, on a plane larger than the surface.
        let png = crate::image::encode_png(2, 1, crate::image::PngKind::Grey8, &[0, 255]).unwrap();
        let plane = TexturedPlane::quad(
            [[-1.0, -1.0, 0.0], [2.0, -1.0, 0.0], [2.0, 2.0, 0.0], [-1.0, 2.0, 0.0]],
            png,
            "xray.png",
        );
        let m = Mesh {
            positions: vec![[0.0, 0.0, 0.1], [1.0, 0.0, 0.1], [1.0, 1.0, 0.1], [0.0, 1.0, 0.1]],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            colors: vec![[200, 200, 200]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let alone = render(&m, 64, 64);
        let img = render_scene(&m, Some(&plane), 64, 64);
        let px = |img: &[u8], x: usize, y: usize| img[3 * (y * 64 + x)];
        // Both halves of the texture show (black and white pixels).
        let pixels: Vec<&[u8]> = img.chunks(3).collect();
        assert!(pixels.iter().any(|p| p == &[0, 0, 0]) && pixels.iter().any(|p| p == &[255, 255, 255]));
        // The surface is blended with what lies under it.
        assert_ne!(px(&img, 32, 32), px(&alone, 32, 32));
        // An undecodable texture is left out.
        let bad = TexturedPlane { png: vec![1, 2, 3], ..plane };
        assert_eq!(render_scene(&m, Some(&bad), 64, 64), alone);
    }
}
