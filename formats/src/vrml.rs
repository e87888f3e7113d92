//! VRML 2.0 scenes: one `Shape` per surface (IndexedFaceSet, per-vertex colour, transparent
//! material) and the radiograph as a textured plane (an `ImageTexture` naming a PNG beside the
//! file), wrapped in a Transform that turns `table` (Z up) into VRML's Y up.

use crate::scene::{Scene, Surface};
use crate::FileError;
use std::io::Write;
use std::path::Path;

/// Writes the scene. The plane's PNG is not written here (see [`write_file`]).
pub fn write(w: &mut impl Write, scene: &Scene<'_>) -> std::io::Result<()> {
    writeln!(w, "#VRML V2.0 utf8")?;
    writeln!(w, "# xsurf scene: surfaces in the table frame (metres), turned Z-up to Y-up")?;
    writeln!(w, "Transform {{\n  rotation 1 0 0 -1.5707963\n  children [")?;
    let mut text = Text::new();
    for s in &scene.surfaces {
        surface(w, s, &mut text)?;
    }
    if let Some(p) = &scene.plane {
        writeln!(w, "    DEF xray Shape {{")?;
        writeln!(
            w,
            "      appearance Appearance {{ texture ImageTexture {{ url \"{}\" repeatS FALSE repeatT FALSE }} }}",
            p.file_name
        )?;
        writeln!(w, "      geometry IndexedFaceSet {{\n        solid FALSE")?;
        write!(w, "        coord Coordinate {{ point [")?;
        for c in &p.positions {
            write!(w, " {} {} {},", c[0], c[1], c[2])?;
        }
        writeln!(w, " ] }}")?;
        write!(w, "        texCoord TextureCoordinate {{ point [")?;
        for t in &p.uv {
            write!(w, " {} {},", t[0], t[1])?;
        }
        writeln!(w, " ] }}")?;
        write!(w, "        coordIndex [")?;
        for t in &p.triangles {
            write!(w, " {} {} {} -1,", t[0], t[1], t[2])?;
        }
        writeln!(w, " ]\n      }}\n    }}")?;
    }
    writeln!(w, "  ]\n}}")
}

/// One surface's `Shape`: its vertices, their colours and its triangles.
fn surface(w: &mut impl Write, s: &Surface<'_>, text: &mut Text) -> std::io::Result<()> {
    let m = s.mesh;
    writeln!(w, "    DEF {} Shape {{", sanitize(s.name))?;
    writeln!(
        w,
        "      appearance Appearance {{ material Material {{ diffuseColor 0.8 0.8 0.8 transparency {:.3} }} }}",
        s.transparency.clamp(0.0, 1.0)
    )?;
    writeln!(w, "      geometry IndexedFaceSet {{\n        solid FALSE\n        colorPerVertex TRUE")?;
    write!(w, "        coord Coordinate {{ point [")?;
    text.list(w, &m.positions, 4, |t, p| {
        t.float(p[0]);
        t.line.push(b' ');
        t.float(p[1]);
        t.line.push(b' ');
        t.float(p[2]);
        t.line.extend_from_slice(b", ");
    })?;
    writeln!(w, "\n        ] }}")?;
    if m.colors.len() == m.positions.len() {
        write!(w, "        color Color {{ color [")?;
        text.list(w, &m.colors, 6, |t, c| {
            for (k, &v) in c.iter().enumerate() {
                t.line.extend_from_slice(&t.levels[usize::from(v)]);
                t.line.extend_from_slice(if k < 2 { b" " } else { b", " });
            }
        })?;
        writeln!(w, "\n        ] }}")?;
    }
    write!(w, "        coordIndex [")?;
    text.list(w, &m.triangles, 6, |t, tri| {
        for &v in tri {
            t.line.extend_from_slice(t.integers.format(v).as_bytes());
            t.line.push(b' ');
        }
        t.line.extend_from_slice(b"-1, ");
    })?;
    writeln!(w, "\n        ]\n      }}\n    }}")
}

/// The surfaces' numbers as text, exactly as `{}` (coordinates, indices) and `{:.3}` (colour
/// levels over 255) write them, some ten times faster: a full-body scene holds millions.
struct Text {
    /// Text not yet written.
    line: Vec<u8>,
    floats: ryu::Buffer,
    integers: itoa::Buffer,
    /// Each 8-bit colour level over 255, as `{:.3}` writes it.
    levels: Vec<[u8; 5]>,
}

impl Text {
    fn new() -> Text {
        let levels = (0..=255u8)
            .map(|v| {
                let mut l = [b'0'; 5];
                l.copy_from_slice(&format!("{:.3}", f32::from(v) / 255.0).as_bytes()[..5]);
                l
            })
            .collect();
        Text { line: Vec::with_capacity(1 << 16), floats: ryu::Buffer::new(), integers: itoa::Buffer::new(), levels }
    }

    /// `v` as `{}` writes it: the shortest digits that read back as `v` (ryu's, which are
    /// std's), laid out without an exponent, and no `.0` on a whole number.
    fn float(&mut self, v: f32) {
        if !v.is_finite() {
            self.line.extend_from_slice(v.to_string().as_bytes());
            return;
        }
        let s = self.floats.format_finite(v).as_bytes();
        let (negative, s) = match s.split_first() {
            Some((b'-', rest)) => (true, rest),
            _ => (false, s),
        };
        let (mantissa, exponent) = match s.iter().position(|&c| c == b'e') {
            Some(e) => {
                (&s[..e], std::str::from_utf8(&s[e + 1..]).ok().and_then(|x| x.parse::<i32>().ok()).unwrap_or(0))
            }
            None => (s, 0),
        };
        let whole = mantissa.iter().position(|&c| c == b'.').unwrap_or(mantissa.len());
        let mut digits = [0u8; 24];
        let mut n = 0;
        for &c in mantissa.iter().filter(|c| c.is_ascii_digit()) {
            digits[n] = c;
            n += 1;
        }
        // The decimal point sits after `point` digits; leading and trailing zeros go.
        let mut point = whole as i32 + exponent;
        let first = digits[..n].iter().position(|&c| c != b'0').unwrap_or(n);
        point -= first as i32;
        let last = digits[..n].iter().rposition(|&c| c != b'0').map_or(first, |i| i + 1);
        let digits = &digits[first..last];
        // Where `v` lies exactly halfway between two shortest candidates, ryu takes the even
        // one and std the one of greater magnitude: such a value (its digits and a 5 one place
        // further make a whole number) is left to std, as is any too large or small to check.
        let k = 1 - (point - digits.len() as i32);
        let scaled = match k {
            0..=22 => f64::from(v.abs()) * 10f64.powi(k),
            -22..=-1 => f64::from(v.abs()) / 10f64.powi(-k),
            _ => 5.0,
        };
        if !digits.is_empty() && scaled.fract() == 0.0 && (scaled >= 9e15 || scaled as u64 % 10 == 5) {
            self.line.extend_from_slice(v.to_string().as_bytes());
            return;
        }
        if negative {
            self.line.push(b'-');
        }
        if digits.is_empty() {
            self.line.push(b'0');
        } else if point <= 0 {
            self.line.extend_from_slice(b"0.");
            self.line.extend(std::iter::repeat_n(b'0', (-point) as usize));
            self.line.extend_from_slice(digits);
        } else if point as usize >= digits.len() {
            self.line.extend_from_slice(digits);
            self.line.extend(std::iter::repeat_n(b'0', point as usize - digits.len()));
        } else {
            let (a, b) = digits.split_at(point as usize);
            self.line.extend_from_slice(a);
            self.line.push(b'.');
            self.line.extend_from_slice(b);
        }
    }

    /// Writes `items`, `per_line` to a line, each by `item`.
    fn list<T>(
        &mut self,
        w: &mut impl Write,
        items: &[T],
        per_line: usize,
        mut item: impl FnMut(&mut Text, &T),
    ) -> std::io::Result<()> {
        for (i, x) in items.iter().enumerate() {
            if i % per_line == 0 {
                self.line.extend_from_slice(b"\n          ");
            }
            item(self, x);
            if self.line.len() > 60_000 {
                w.write_all(&self.line)?;
                self.line.clear();
            }
        }
        w.write_all(&self.line)?;
        self.line.clear();
        Ok(())
    }
}

fn sanitize(name: &str) -> String {
    let s: String = name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
    if s.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) {
        s
    } else {
        format!("s_{s}")
    }
}

/// Writes `path` and, when the scene has a radiograph, its PNG beside it (both atomically).
pub fn write_file(path: &Path, scene: &Scene<'_>) -> Result<(), FileError> {
    if let Some(p) = &scene.plane {
        let dir = path.parent().unwrap_or(Path::new("."));
        crate::write_bytes_atomic(&dir.join(&p.file_name), &p.png)?;
    }
    crate::write_atomic(path, |w| write(w, scene))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::TexturedPlane;
    use xsurf_core::mesh::Mesh;

    #[test]
    fn writes_shapes_plane_and_y_up_transform() {
        let m = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![],
            colors: vec![[255, 0, 0]; 3],
            triangles: vec![[0, 1, 2]],
        };
        let scene = Scene {
            surfaces: vec![Surface { name: "cam1", mesh: &m, transparency: 0.3 }],
            plane: Some(TexturedPlane::quad([[0.0; 3]; 4], vec![], "xray.png")),
        };
        let mut out = Vec::new();
        write(&mut out, &scene).unwrap();
        let s = String::from_utf8(out).unwrap();
        assert!(s.starts_with("#VRML V2.0 utf8\n"));
        assert!(s.contains("rotation 1 0 0 -1.5707963"));
        assert!(s.contains("DEF cam1 Shape"));
        assert!(s.contains("transparency 0.300"));
        assert!(s.contains("0 1 2 -1,"));
        assert!(s.contains("url \"xray.png\""));
        assert!(s.contains("texCoord TextureCoordinate { point [ 0 0, 1 0, 1 1, 0 1, ] }"));
        assert!(s.contains("coordIndex [ 0 1 2 -1, 0 2 3 -1, ]"));
        assert_eq!(s.matches('{').count(), s.matches('}').count());
        assert_eq!(s.matches('[').count(), s.matches(']').count());
    }

    /// The fast text is std's, character for character: every colour level, indices, and
    /// floats of every magnitude, sign and form (whole, tiny, huge, subnormal, zeros).
    #[test]
    fn numbers_are_written_as_std_writes_them() {
        let mut text = Text::new();
        for v in 0..=255u8 {
            assert_eq!(&text.levels[usize::from(v)][..], format!("{:.3}", f32::from(v) / 255.0).as_bytes());
        }
        let mut check = |v: f32| {
            text.line.clear();
            text.float(v);
            assert_eq!(std::str::from_utf8(&text.line).unwrap(), v.to_string(), "{:08x}", v.to_bits());
        };
        let ties = [2_110_626.2, -2_110_626.2, 0.5, 2.5, 8_388_609.5, 16_777_215.0];
        for v in
            [0.0, -0.0, 1.0, -1.0, 10.0, 1e16, 1.5e-7, 0.1, 0.123_456_79, 123_456_790.0, f32::MAX, f32::MIN_POSITIVE]
                .into_iter()
                .chain(ties)
        {
            check(v);
        }
        check(f32::from_bits(1)); // the least subnormal
        check(f32::NAN);
        check(f32::NEG_INFINITY);
        // Every exponent, a spread of mantissas (a xorshift over the bit patterns).
        let mut x = 0x9e37_79b9u32;
        for _ in 0..2_000_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            check(f32::from_bits(x));
        }
        // Coordinates in metres, as scans hold them.
        for i in -20_000..20_000 {
            check(i as f32 * 1.234_567e-4);
        }
        let mut out = Vec::new();
        text.line.clear();
        text.list(&mut out, &[[0u32, 7, 10], [4_294_967_295, 1, 2]], 1, |t, tri| {
            for &v in tri {
                t.line.extend_from_slice(t.integers.format(v).as_bytes());
                t.line.push(b' ');
            }
        })
        .unwrap();
        assert_eq!(out, b"\n          0 7 10 \n          4294967295 1 2 ");
    }
}
