//! VRML 2.0 scenes: one `Shape` per surface (IndexedFaceSet, per-vertex colour, transparent
//! material) and the radiograph as a textured plane (an `ImageTexture` naming a PNG beside the
//! file), wrapped in a Transform that turns `table` (Z up) into VRML's Y up.

use crate::scene::Scene;
use crate::FileError;
use std::io::Write;
use std::path::Path;

/// Writes the scene. The plane's PNG is not written here (see [`write_file`]).
pub fn write(w: &mut impl Write, scene: &Scene<'_>) -> std::io::Result<()> {
    writeln!(w, "#VRML V2.0 utf8")?;
    writeln!(w, "# xsurf scene: surfaces in the table frame (metres), turned Z-up to Y-up")?;
    writeln!(w, "Transform {{\n  rotation 1 0 0 -1.5707963\n  children [")?;
    for s in &scene.surfaces {
        let m = s.mesh;
        writeln!(w, "    DEF {} Shape {{", sanitize(s.name))?;
        writeln!(
            w,
            "      appearance Appearance {{ material Material {{ diffuseColor 0.8 0.8 0.8 transparency {:.3} }} }}",
            s.transparency.clamp(0.0, 1.0)
        )?;
        writeln!(w, "      geometry IndexedFaceSet {{\n        solid FALSE\n        colorPerVertex TRUE")?;
        write!(w, "        coord Coordinate {{ point [")?;
        for (i, p) in m.positions.iter().enumerate() {
            if i % 4 == 0 {
                write!(w, "\n          ")?;
            }
            write!(w, "{} {} {}, ", p[0], p[1], p[2])?;
        }
        writeln!(w, "\n        ] }}")?;
        if m.colors.len() == m.positions.len() {
            write!(w, "        color Color {{ color [")?;
            for (i, c) in m.colors.iter().enumerate() {
                if i % 6 == 0 {
                    write!(w, "\n          ")?;
                }
                write!(
                    w,
                    "{:.3} {:.3} {:.3}, ",
                    f32::from(c[0]) / 255.0,
                    f32::from(c[1]) / 255.0,
                    f32::from(c[2]) / 255.0
                )?;
            }
            writeln!(w, "\n        ] }}")?;
        }
        write!(w, "        coordIndex [")?;
        for (i, t) in m.triangles.iter().enumerate() {
            if i % 6 == 0 {
                write!(w, "\n          ")?;
            }
            write!(w, "{} {} {} -1, ", t[0], t[1], t[2])?;
        }
        writeln!(w, "\n        ]\n      }}\n    }}")?;
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
    use crate::scene::{Surface, TexturedPlane};
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
}
