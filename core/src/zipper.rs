//! Zippering: the seams between the surfaces of different cameras stitched with triangles.
//!
//! After fusing ([`crate::fuse`]) each region of the scene belongs to one camera, and each
//! camera's grid is meshed on its own, so a strip of no triangles runs along every border where
//! ownership changes. The zipper closes those strips: each boundary edge of one camera's surface
//! gets a triangle to the nearest boundary vertex of the other's across the gap, and each
//! boundary edge of the other that then lies between two such triangles closes the fan. The new
//! triangles obey the mesher's own limits (longest edge, smallest angle), so a real hole or a
//! jump in depth is never bridged, and they keep the surface's orientation.

use crate::cells::Cells;
use crate::mesh::{cross, dot, norm, sub, triangle_ok, Mesh};
use std::collections::HashSet;

/// What the zipper did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ZipperReport {
    /// Boundary edges of all surfaces before.
    pub boundary_edges: usize,
    /// Triangles added from a boundary edge to the other surface's nearest vertex.
    pub bridges: usize,
    /// Triangles added to close the fans between two bridges.
    pub closings: usize,
}

/// The mesher's test on triangle `(a, b, c)` of `p`.
fn acceptable(p: &[[f32; 3]], [a, b, c]: [u32; 3], max_edge: f32, sin_min: f32) -> bool {
    triangle_ok([p[a as usize], p[b as usize], p[c as usize]], max_edge, sin_min)
}

/// Stitches the seams between the surfaces of different cameras in `mesh`, in place:
/// `camera[v]` is the camera of vertex `v`. Triangles are added only between vertices of
/// different cameras, with every edge within `max_edge_m` and every angle at least
/// `min_angle_deg` (the mesher's limits). The mesh's triangles must be consistently oriented
/// (as [`crate::mesh::mesh_grid`] makes them); the added ones follow that orientation.
pub fn zipper(mesh: &mut Mesh, camera: &[u8], max_edge_m: f32, min_angle_deg: f32) -> ZipperReport {
    let n = mesh.positions.len();
    let mut report = ZipperReport::default();
    if camera.len() != n || mesh.triangles.is_empty() {
        return report;
    }
    // Directed edges a -> b per vertex, with the triangle's third vertex.
    let (start, out) = mesh.corners();
    let mut seams = Seams {
        p: &mesh.positions,
        camera,
        start: &start,
        out: &out,
        max_edge_m,
        sin_min: min_angle_deg.to_radians().sin(),
        used: HashSet::new(),
        added: Vec::new(),
    };
    let (boundary, on_boundary) = seams.boundary();
    report.boundary_edges = boundary.len();
    let links = seams.bridges(&boundary, &on_boundary);
    report.bridges = seams.added.len();
    report.closings = seams.closings(&boundary, links);
    let added = seams.added;
    mesh.add_triangles(added);
    report
}

/// The zipper's work: the mesh's positions, cameras and directed edges, and the triangles
/// added so far with their directed edges (a new triangle may not repeat any: it would overlap
/// a neighbour or flip against it).
struct Seams<'a> {
    p: &'a [[f32; 3]],
    camera: &'a [u8],
    /// `out[start[a]..start[a + 1]]`: the directed edges a -> b, with the third vertex.
    start: &'a [usize],
    out: &'a [(u32, u32)],
    max_edge_m: f32,
    sin_min: f32,
    used: HashSet<(u32, u32)>,
    added: Vec<[u32; 3]>,
}

impl Seams<'_> {
    fn has_edge(&self, a: u32, b: u32) -> bool {
        self.out[self.start[a as usize]..self.start[a as usize + 1]].iter().any(|e| e.0 == b)
    }

    /// Boundary edges `(a, b, third vertex)`, a -> b with no b -> a; and which vertices are on
    /// the boundary.
    fn boundary(&self) -> (Vec<(u32, u32, u32)>, Vec<bool>) {
        let n = self.p.len();
        let mut boundary: Vec<(u32, u32, u32)> = Vec::new();
        let mut on_boundary = vec![false; n];
        for a in 0..n as u32 {
            for &(b, opp) in &self.out[self.start[a as usize]..self.start[a as usize + 1]] {
                if !self.has_edge(b, a) {
                    boundary.push((a, b, opp));
                    on_boundary[a as usize] = true;
                    on_boundary[b as usize] = true;
                }
            }
        }
        (boundary, on_boundary)
    }

    /// True if triangle `t` passes the mesher's test and repeats no directed edge.
    fn fits(&self, t: [u32; 3]) -> bool {
        let [x, y, z] = t;
        acceptable(self.p, t, self.max_edge_m, self.sin_min)
            && [(x, y), (y, z), (z, x)].iter().all(|&(u, v)| !self.has_edge(u, v) && !self.used.contains(&(u, v)))
    }

    fn add(&mut self, [x, y, z]: [u32; 3]) {
        self.used.extend([(x, y), (y, z), (z, x)]);
        self.added.push([x, y, z]);
    }

    /// Bridges: from each boundary edge of a lower-numbered camera to the best boundary vertex
    /// of a higher-numbered one on the far side of the edge. Returns the new edges.
    fn bridges(&mut self, boundary: &[(u32, u32, u32)], on_boundary: &[bool]) -> Vec<(u32, u32)> {
        let (p, camera, max_edge_m) = (self.p, self.camera, self.max_edge_m);
        let indexed: Vec<[f32; 3]> =
            p.iter().zip(on_boundary).map(|(q, &b)| if b { *q } else { [f32::NAN; 3] }).collect();
        let cells = Cells::new(&indexed, max_edge_m);
        let mut links: Vec<(u32, u32)> = Vec::new();
        for &(a, b, opp) in boundary {
            if camera[b as usize] != camera[a as usize] {
                continue;
            }
            let (pa, pb) = (p[a as usize], p[b as usize]);
            let normal = cross(sub(pb, pa), sub(p[opp as usize], pa));
            let mid = [0, 1, 2].map(|k| (pa[k] + pb[k]) / 2.0);
            let mut best: Option<(f32, u32)> = None;
            cells.within(&mid, max_edge_m, |c, _| {
                if camera[c as usize] <= camera[a as usize] {
                    return;
                }
                let pc = p[c as usize];
                if dot(cross(sub(pa, pb), sub(pc, pb)), normal) <= 0.0 || !self.fits([b, a, c]) {
                    return;
                }
                let cost = norm(sub(pc, pa)) + norm(sub(pc, pb));
                if best.is_none_or(|(bc, _)| cost < bc) {
                    best = Some((cost, c));
                }
            });
            if let Some((_, c)) = best {
                self.add([b, a, c]);
                links.push((a, c));
                links.push((b, c));
            }
        }
        links
    }

    /// Closings: a boundary edge d -> e of the higher-numbered camera whose ends both got a
    /// bridge to one vertex v closes the fan with (e, d, v); at the end of a seam, one bridged
    /// to either end (on the far side of the edge) closes the last gap. Returns how many.
    fn closings(&mut self, boundary: &[(u32, u32, u32)], links: Vec<(u32, u32)>) -> usize {
        let (p, camera) = (self.p, self.camera);
        // Both directions, sorted: the vertices bridged to x are the run of (x, _).
        let mut links: Vec<(u32, u32)> = links.iter().flat_map(|&(x, y)| [(x, y), (y, x)]).collect();
        links.sort_unstable();
        links.dedup();
        let linked = |x: u32, y: u32| links.binary_search(&(x, y)).is_ok();
        let bridged_to = |x: u32| {
            let from = links.partition_point(|&(a, _)| a < x);
            links[from..].iter().take_while(move |&&(a, _)| a == x).map(|&(_, b)| b)
        };
        let mut closings = 0;
        for &(d, e, opp) in boundary {
            let cam = camera[d as usize];
            if camera[e as usize] != cam {
                continue;
            }
            let (pd, pe) = (p[d as usize], p[e as usize]);
            let normal = cross(sub(pe, pd), sub(p[opp as usize], pd));
            let mut best: Option<(bool, f32, u32)> = None;
            for v in bridged_to(d).chain(bridged_to(e)) {
                let pv = p[v as usize];
                if camera[v as usize] >= cam
                    || dot(cross(sub(pd, pe), sub(pv, pe)), normal) <= 0.0
                    || !self.fits([e, d, v])
                {
                    continue;
                }
                let both = linked(d, v) && linked(e, v);
                let cost = norm(sub(pv, pd)) + norm(sub(pv, pe));
                if best.is_none_or(|(b2, c2, _)| (both, -cost) > (b2, -c2)) {
                    best = Some((both, cost, v));
                }
            }
            if let Some((_, _, v)) = best {
                self.add([e, d, v]);
                closings += 1;
            }
        }
        closings
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::checks::{area, doubled_edges};
    use crate::mesh::{mesh_grid, Grid, MeshConfig};
    use crate::triangulate::Profile;

    /// A flat strip `x in [x0, x1]` sampled every 1 mm across and 2 mm along, z = 0.
    fn strip(x0: f32, x1: f32) -> Grid {
        let ns = ((x1 - x0) / 0.001).round() as usize + 1;
        let mut g = Grid::new(ns);
        for f in 0..20 {
            let points: Vec<[f32; 3]> = (0..ns).map(|s| [x0 + s as f32 * 0.001, f as f32 * 0.002, 0.0]).collect();
            let profile = Profile { intensity: vec![100.0; ns], range: vec![0.5; ns], points, ..Profile::default() };
            g.push(f as i64, &profile).unwrap();
        }
        g
    }

    fn two_strips(gap: f32) -> (Mesh, Vec<u8>) {
        let cfg = MeshConfig { fill_single_holes: false, ..MeshConfig::default() };
        let a = mesh_grid(&strip(0.0, 0.01), &cfg);
        let b = mesh_grid(&strip(0.01 + gap, 0.02 + gap), &cfg);
        let mut camera = vec![0u8; a.positions.len()];
        camera.extend(vec![1u8; b.positions.len()]);
        let mut m = a;
        m.append(&b);
        (m, camera)
    }

    #[test]
    fn a_seam_is_closed_with_the_area_of_the_gap_and_nothing_more() {
        for gap in [0.0015f32, 0.003, 0.006] {
            let (mut m, camera) = two_strips(gap);
            let before = area(&m);
            let r = zipper(&mut m, &camera, 0.012, 12.0);
            // The two strips are 10 mm x 38 mm each; the gap between them is `gap` x 38 mm.
            let gained = area(&m) - before;
            assert!((gained - gap * 0.038).abs() < 0.02 * gap * 0.038, "gap {gap}: area {gained} {r:?}");
            assert!(r.bridges > 0 && r.closings > 0, "{r:?}");
            assert_eq!(doubled_edges(&m), 0, "gap {gap}: a directed edge used twice");
            // Every added triangle faces up like the strips.
            for t in &m.triangles {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                assert!(cross(sub(b, a), sub(c, a))[2] > 0.0);
            }
        }
    }

    #[test]
    fn a_gap_wider_than_an_edge_and_one_camera_alone_are_left_alone() {
        let (mut m, camera) = two_strips(0.02);
        let n = m.triangles.len();
        let r = zipper(&mut m, &camera, 0.012, 12.0);
        assert_eq!((r.bridges, r.closings, m.triangles.len()), (0, 0, n));
        // One camera: its own boundary is never bridged to itself.
        let (mut m, _) = two_strips(0.003);
        let n = m.triangles.len();
        let one = vec![0u8; m.positions.len()];
        assert_eq!(zipper(&mut m, &one, 0.012, 12.0).bridges, 0);
        assert_eq!(m.triangles.len(), n);
        // A label per vertex is required.
        assert_eq!(zipper(&mut m, &[0], 0.012, 12.0), ZipperReport::default());
    }
}
