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

/// A textured quad: the radiograph on its plane.
#[derive(Debug, Clone)]
pub struct TexturedPlane {
    /// Corners in `table`, counter-clockwise seen from above, starting at the texture's
    /// bottom-left (u, v) = (0, 0).
    pub corners: [[f32; 3]; 4],
    /// The texture as PNG bytes.
    pub png: Vec<u8>,
    /// File name of the PNG beside a VRML file.
    pub file_name: String,
}

/// A whole scene.
#[derive(Debug, Clone, Default)]
pub struct Scene<'a> {
    /// Surfaces.
    pub surfaces: Vec<Surface<'a>>,
    /// The radiograph, if any.
    pub plane: Option<TexturedPlane>,
}
