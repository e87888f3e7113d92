//! One surface from the cameras' grids of a scan, as the merger makes it: each further camera's
//! placement refined against the first camera's surface ([`refine`]), the grids fused where
//! they overlap ([`crate::fuse`]), each meshed, the surfaces combined, the seams between them
//! stitched ([`crate::zipper`]) and the small holes left closed ([`crate::holes`]).

pub mod refine;

use crate::fuse::{one_surface, FuseConfig};
use crate::holes::fill_holes;
use crate::mesh::{mesh_grid, Grid, Mesh, MeshConfig};
use crate::zipper::zipper;

/// How the surfaces are merged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MergeConfig {
    /// How each camera's grid is meshed (its edge and angle rule also judge the seams).
    pub mesh: MeshConfig,
    /// How overlapping cameras are fused into one layer.
    pub fuse: FuseConfig,
    /// Stitch the seams between the cameras' surfaces.
    pub zipper: bool,
    /// After zippering, holes bounded by at most this many edges are closed (0: none).
    pub max_hole_edges: usize,
}

/// The merged surface of a scan.
#[derive(Debug, Clone, Default)]
pub struct Merged {
    /// The one surface: every camera's mesh, then the seams.
    pub surface: Mesh,
    /// Each camera's mesh by name, then the seams' (named `seams`) if any: the scene files show
    /// them as surfaces of their own.
    pub meshes: Vec<(String, Mesh)>,
    /// Samples that fusing dropped (another camera's observation of the same place).
    pub fused_dropped: usize,
    /// Triangles added by the zipper and the hole filling.
    pub seam_triangles: usize,
    /// For each vertex of `surface`, the grid it came from (an index into the grids merged).
    pub vertex_grid: Vec<u8>,
}

/// Merges the cameras' grids (`names[k]` is grid `k`'s camera), which are fused in place.
pub fn merge_grids(names: &[String], grids: &mut [Grid], cfg: &MergeConfig) -> Merged {
    let fused = one_surface(grids, &cfg.fuse);
    // Each grid meshed on a core of its own.
    let mut meshes: Vec<(String, Mesh)> =
        crate::par::filter_map(grids, 1, |i, g| names.get(i).map(|n| (n.clone(), mesh_grid(g, &cfg.mesh))));
    let mut surface = Mesh::default();
    let mut camera = Vec::new();
    for (k, (_, m)) in meshes.iter().enumerate() {
        surface.append(m);
        camera.extend(std::iter::repeat_n(k as u8, m.positions.len()));
    }
    let mut seam_triangles = 0;
    if cfg.zipper && meshes.len() > 1 {
        let before = surface.triangles.len();
        let z = zipper(&mut surface, &camera, cfg.mesh.max_edge_m, cfg.mesh.min_angle_deg);
        let h = fill_holes(&mut surface, cfg.mesh.max_edge_m, cfg.max_hole_edges);
        seam_triangles = z.bridges + z.closings + h.triangles;
        let mut seams = Mesh {
            positions: surface.positions.clone(),
            colors: surface.colors.clone(),
            triangles: surface.triangles[before..].to_vec(),
            ..Mesh::default()
        };
        seams.remove_unreferenced();
        seams.compute_normals();
        if !seams.triangles.is_empty() {
            meshes.push(("seams".into(), seams));
        }
    }
    // The seams join existing vertices; any they add are counted as the last grid's.
    let last = camera.last().copied().unwrap_or(0);
    camera.resize(surface.positions.len(), last);
    Merged { surface, meshes, fused_dropped: fused.dropped.iter().sum(), seam_triangles, vertex_grid: camera }
}
