//! What a scene file holds: surfaces and the radiograph as a textured plane.

use xsurf_core::mesh::Mesh;

/// One surface of a scene.
#[derive(Debug, Clone, Copy)]
pub struct Surface<'a> {
    /// Name (`cam1`, `merged`).
    pub name: &'a str,
    /// The mesh, in `table` (Z up, metres).
    pub mesh: &'a Mesh,
    /// 0 opaque .. 1 invisible.
    pub transparency: f32,
}

/// The radiograph on its plane: a textured grid (rows of a linear scan follow the C-arm's
/// travel, so the grid has a vertex pair per sampled row).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TexturedPlane {
    /// Vertices in `table`.
    pub positions: Vec<[f32; 3]>,
    /// Texture coordinates per vertex, (0, 0) at the image's bottom-left (VRML's convention).
    pub uv: Vec<[f32; 2]>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// The texture as PNG bytes.
    pub png: Vec<u8>,
    /// File name of the PNG beside a VRML file.
    pub file_name: String,
}

impl TexturedPlane {
    /// A quad: corners counter-clockwise from the texture's bottom-left.
    pub fn quad(corners: [[f32; 3]; 4], png: Vec<u8>, file_name: &str) -> Self {
        Self {
            positions: corners.to_vec(),
            uv: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            png,
            file_name: file_name.to_string(),
        }
    }
}

/// A whole scene.
#[derive(Debug, Clone, Default)]
pub struct Scene<'a> {
    /// Surfaces.
    pub surfaces: Vec<Surface<'a>>,
    /// The radiograph, if any.
    pub plane: Option<TexturedPlane>,
}
