//! Small holes in a surface closed with triangles: the minimum-area triangulation of each
//! boundary loop (Liepa, "Filling holes in meshes", SGP 2003, without the refinement step).
//!
//! Fusing and zippering the cameras' surfaces ([`crate::fuse`], [`crate::zipper`]) leave gaps
//! of a few triangles where ownership changes from sample to sample: a missing triangle, a
//! quad, a short slit. Each such gap is a closed loop of boundary edges. A loop is filled when
//! it is short (at most `max_loop_edges` edges) and a triangulation of it exists whose every new
//! edge is within `max_edge_m` (the mesher's own limit, so a gap the mesher would have bridged
//! in one grid is bridged here, and a real hole wider than a triangle is left open), whose new
//! edges are not edges of the mesh already (the surface stays a manifold), and whose triangles
//! do not fold back against each other or the surface around. Of the triangulations, the one
//! that folds least is taken, then the one of least area (Liepa's weight). The outer rim of a
//! surface is one long loop and is never filled.

use crate::mesh::{cross, dot, norm, sub, Mesh};
use std::collections::{HashMap, HashSet};

/// What hole filling did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HoleReport {
    /// Boundary loops found (the outer rim included).
    pub loops: usize,
    /// Loops filled.
    pub filled: usize,
    /// Triangles added.
    pub triangles: usize,
}

/// The directed edges of a mesh: its triangles' (each vertex's outgoing edges with the third
/// vertex, as [`Mesh::corners`] lists them), and the ones a fill added.
struct Edges {
    start: Vec<usize>,
    out: Vec<(u32, u32)>,
    added: HashSet<(u32, u32)>,
}

impl Edges {
    fn new(mesh: &Mesh) -> Self {
        let (start, out) = mesh.corners();
        Self { start, out, added: HashSet::new() }
    }
    /// The triangles' edges from `a`: `(b, third vertex)`.
    fn from(&self, a: u32) -> &[(u32, u32)] {
        &self.out[self.start[a as usize]..self.start[a as usize + 1]]
    }
    fn has(&self, a: u32, b: u32) -> bool {
        self.from(a).iter().any(|e| e.0 == b) || self.added.contains(&(a, b))
    }
}

/// The boundary loops of `mesh`: each a cycle of vertices `v[0] -> v[1] -> ... -> v[0]` along
/// directed edges used by one triangle only (none of them is used backwards), each vertex once
/// per loop (a vertex where loops touch starts a loop of its own). Returned with, per edge
/// `v[i] -> v[i+1]`, the normal of the triangle on it.
fn boundary_loops(mesh: &Mesh, edges: &Edges) -> Vec<(Vec<u32>, Vec<[f32; 3]>)> {
    let p = &mesh.positions;
    // Boundary edges from each vertex, with the normal of their triangle.
    let mut out: HashMap<u32, Vec<(u32, [f32; 3])>> = HashMap::new();
    for a in 0..p.len() as u32 {
        for &(b, opp) in edges.from(a) {
            if !edges.has(b, a) {
                let pa = p[a as usize];
                out.entry(a).or_default().push((b, cross(sub(p[b as usize], pa), sub(p[opp as usize], pa))));
            }
        }
    }
    let mut starts: Vec<u32> = out.keys().copied().collect();
    starts.sort_unstable();
    let mut loops = Vec::new();
    for s in starts {
        while let Some((b, n)) = out.get_mut(&s).and_then(Vec::pop) {
            // Walk from s; where the walk meets a vertex already on its path, the cycle since
            // then is a loop.
            let mut path: Vec<(u32, [f32; 3])> = vec![(s, n)];
            // Where each vertex of the path is on it (the rim is a loop of thousands).
            let mut on_path: HashMap<u32, usize> = HashMap::from([(s, 0)]);
            let mut at = b;
            loop {
                if let Some(&j) = on_path.get(&at) {
                    let cycle = path.split_off(j);
                    for (v, _) in &cycle {
                        on_path.remove(v);
                    }
                    loops.push(cycle.into_iter().unzip());
                    if path.is_empty() {
                        break;
                    }
                }
                match out.get_mut(&at).and_then(Vec::pop) {
                    Some((next, n)) => {
                        on_path.insert(at, path.len());
                        path.push((at, n));
                        at = next;
                    }
                    None => break, // an open chain (inconsistent orientation): not a loop
                }
            }
        }
    }
    loops
}

/// The angle between two normals, radians (0: the triangles continue each other flat; pi: one
/// folds back onto the other).
fn angle(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = norm(a) * norm(b);
    if d > 0.0 {
        (dot(a, b) / d).clamp(-1.0, 1.0).acos()
    } else {
        0.0
    }
}

/// A fill whose triangles fold against each other or the surface around by more than this is
/// refused, radians (a crease of the object itself, a right angle where a wall meets the table,
/// stays well within it).
const MAX_FOLD: f32 = 150.0 * std::f32::consts::PI / 180.0;

/// Dihedral angles closer than this are equal when triangulations are compared, radians.
const ANGLE_TIE: f32 = 1e-3;

/// The triangulation of the loop `v` within the limits that folds least (the smallest largest
/// angle between neighbouring triangles, the loop's own triangles included), and of those the
/// least area: Liepa's weight. Triangles are oriented against the loop's edges, so they continue
/// the surface. `normals[i]` is the normal of the triangle on edge `v[i] -> v[i+1]`. `None` if no
/// triangulation keeps within the limits.
fn triangulate_loop(
    p: &[[f32; 3]],
    v: &[u32],
    normals: &[[f32; 3]],
    max_edge: f32,
    edges: &Edges,
) -> Option<Vec<[u32; 3]>> {
    let n = v.len();
    let at = |i: usize| p[v[i] as usize];
    let max2 = max_edge * max_edge;
    let d2 = |i: usize, k: usize| {
        let d = sub(at(i), at(k));
        dot(d, d)
    };
    // A chord i-k (not a loop edge) may be new only if the mesh lacks it in either direction.
    let chord_ok = |i: usize, k: usize| {
        k == i + 1 || (i == 0 && k == n - 1) || (d2(i, k) <= max2 && !edges.has(v[i], v[k]) && !edges.has(v[k], v[i]))
    };
    // Per sub-polygon i..=k: (largest fold, area), the apex chosen, the normal of the triangle
    // on chord i-k (the neighbour of the triangle above it).
    let idx = |i: usize, k: usize| i * n + k;
    let mut fold = vec![f32::INFINITY; n * n];
    let mut area = vec![f32::INFINITY; n * n];
    let mut apex = vec![usize::MAX; n * n];
    let mut normal = vec![[0.0f32; 3]; n * n];
    for i in 0..n - 1 {
        fold[idx(i, i + 1)] = 0.0;
        area[idx(i, i + 1)] = 0.0;
        normal[idx(i, i + 1)] = normals[i];
    }
    for span in 2..n {
        for i in 0..n - span {
            let k = i + span;
            if !chord_ok(i, k) {
                continue;
            }
            for m in i + 1..k {
                let (a, b) = (idx(i, m), idx(m, k));
                if !(fold[a].is_finite() && fold[b].is_finite()) {
                    continue;
                }
                // The triangle (i, m, k), emitted as (k, m, i).
                let c = cross(sub(at(m), at(k)), sub(at(i), at(k)));
                if dot(c, c) == 0.0 {
                    continue;
                }
                let f = fold[a].max(fold[b]).max(angle(c, normal[a])).max(angle(c, normal[b]));
                let s = area[a] + area[b] + norm(c) / 2.0;
                let (f0, s0) = (fold[idx(i, k)], area[idx(i, k)]);
                if f < f0 - ANGLE_TIE || (f < f0 + ANGLE_TIE && s < s0) {
                    fold[idx(i, k)] = f;
                    area[idx(i, k)] = s;
                    apex[idx(i, k)] = m;
                    normal[idx(i, k)] = c;
                }
            }
        }
    }
    // The last triangle also meets the surface across the closing edge v[n-1] -> v[0].
    let top = idx(0, n - 1);
    if !fold[top].is_finite() || fold[top].max(angle(normal[top], normals[n - 1])) > MAX_FOLD {
        return None;
    }
    let mut triangles = Vec::with_capacity(n - 2);
    let mut stack = vec![(0usize, n - 1)];
    while let Some((i, k)) = stack.pop() {
        if k - i < 2 {
            continue;
        }
        let m = apex[idx(i, k)];
        triangles.push([v[k], v[m], v[i]]);
        stack.push((i, m));
        stack.push((m, k));
    }
    Some(triangles)
}

/// Fills the loops of at most `max_loop_edges` boundary edges of `mesh` in place, each with new
/// edges within `max_edge_m` (see the module). The mesh's triangles must be consistently
/// oriented; the new ones follow that orientation. Normals are recomputed if the mesh has them.
pub fn fill_holes(mesh: &mut Mesh, max_edge_m: f32, max_loop_edges: usize) -> HoleReport {
    let mut report = HoleReport::default();
    if mesh.triangles.is_empty() || !(max_edge_m > 0.0) {
        return report;
    }
    let mut edges = Edges::new(mesh);
    let loops = boundary_loops(mesh, &edges);
    report.loops = loops.len();
    let mut added = Vec::new();
    for (v, normals) in loops {
        if v.len() < 3 || v.len() > max_loop_edges {
            continue;
        }
        let Some(tris) = triangulate_loop(&mesh.positions, &v, &normals, max_edge_m, &edges) else { continue };
        for t in &tris {
            edges.added.extend([(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]);
        }
        report.filled += 1;
        report.triangles += tris.len();
        added.extend(tris);
    }
    mesh.add_triangles(added);
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::checks::{area, doubled_edges};
    use crate::mesh::{mesh_grid, Grid, MeshConfig};
    use crate::triangulate::Profile;

    /// A flat 40 x 40 mm plate sampled every 2 mm, z = 0, without the samples for which
    /// `hole(x, y)` holds.
    fn plate(hole: impl Fn(f32, f32) -> bool) -> Mesh {
        let ns = 21;
        let mut g = Grid::new(ns);
        for f in 0..21 {
            let y = f as f32 * 0.002;
            let points: Vec<[f32; 3]> = (0..ns)
                .map(|s| {
                    let x = s as f32 * 0.002;
                    if hole(x, y) {
                        [f32::NAN; 3]
                    } else {
                        [x, y, 0.0]
                    }
                })
                .collect();
            let profile = Profile { intensity: vec![100.0; ns], range: vec![0.5; ns], points, ..Profile::default() };
            g.push(f as i64, &profile).unwrap();
        }
        mesh_grid(&g, &MeshConfig { fill_single_holes: false, ..MeshConfig::default() })
    }

    fn boundary_edge_count(m: &Mesh) -> usize {
        let e: HashSet<(u32, u32)> =
            m.triangles.iter().flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]).collect();
        e.iter().filter(|&&(a, b)| !e.contains(&(b, a))).count()
    }

    #[test]
    fn a_small_hole_is_closed_with_its_own_area_facing_up() {
        // Three missing samples in a row: an 8 x 4 mm hole (the triangles around them gone).
        let full = area(&plate(|_, _| false));
        let mut m = plate(|x, y| (0.0189..0.0251).contains(&x) && (0.0199..0.0201).contains(&y));
        let before = boundary_edge_count(&m);
        let r = fill_holes(&mut m, 0.012, 64);
        assert_eq!(r.filled, 1, "{r:?}");
        assert_eq!(r.loops, 2, "the rim and the hole: {r:?}");
        // Only the rim is left: 4 sides of 20 edges.
        assert_eq!(boundary_edge_count(&m), 80, "before {before}");
        assert!((area(&m) - full).abs() < 1e-4 * full, "area {} of {full}", area(&m));
        assert_eq!(doubled_edges(&m), 0);
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            assert!(cross(sub(b, a), sub(c, a))[2] > 0.0, "a triangle faces down");
        }
    }

    #[test]
    fn a_hole_wider_than_an_edge_and_the_outer_rim_stay_open() {
        // A 14 mm wide hole: every triangulation needs an edge longer than 12 mm.
        let mut m = plate(|x, y| (x - 0.02).abs() < 0.007 && (y - 0.02).abs() < 0.007);
        let (n, be) = (m.triangles.len(), boundary_edge_count(&m));
        let r = fill_holes(&mut m, 0.012, 1000);
        assert_eq!((r.filled, r.triangles, m.triangles.len(), boundary_edge_count(&m)), (0, 0, n, be), "{r:?}");
        // The same hole with a larger edge limit is closed, the rim still not.
        let r = fill_holes(&mut m, 0.03, 1000);
        assert_eq!(r.filled, 1, "{r:?}");
        assert_eq!(boundary_edge_count(&m), 80);
        // A loop longer than the limit is left.
        let mut m = plate(|x, y| (x - 0.02).abs() < 0.003 && (y - 0.02).abs() < 0.003);
        assert_eq!(fill_holes(&mut m, 0.012, 4).filled, 0);
        assert_eq!(fill_holes(&mut m, 0.012, 64).filled, 1);
    }

    #[test]
    fn holes_that_touch_at_a_vertex_are_filled_each() {
        // Two missing triangles sharing one vertex: the boundary passes that vertex twice.
        let mut m = plate(|_, _| false);
        let centre = m.positions.iter().position(|p| (p[0] - 0.02).abs() < 1e-6 && (p[1] - 0.02).abs() < 1e-6);
        let c = centre.unwrap() as u32;
        let mut around: Vec<usize> =
            m.triangles.iter().enumerate().filter(|(_, t)| t.contains(&c)).map(|(i, _)| i).collect();
        around.sort_unstable();
        // Remove two triangles around the centre that share only the centre.
        let (t0, t1) = (around[0], around[around.len() / 2]);
        let shared: Vec<u32> = m.triangles[t0].iter().filter(|v| m.triangles[t1].contains(v)).copied().collect();
        assert_eq!(shared, vec![c], "the test needs two triangles meeting at the centre only");
        m.triangles.remove(t1);
        m.triangles.remove(t0);
        let r = fill_holes(&mut m, 0.012, 64);
        assert_eq!((r.filled, r.triangles), (2, 2), "{r:?}");
        assert_eq!(boundary_edge_count(&m), 80);
        assert_eq!(doubled_edges(&m), 0);
    }

    #[test]
    fn nothing_to_fill_is_no_change() {
        let mut m = Mesh::default();
        assert_eq!(fill_holes(&mut m, 0.012, 64), HoleReport::default());
        let mut m = plate(|_, _| false);
        let n = m.triangles.len();
        assert_eq!(fill_holes(&mut m, 0.012, 64), HoleReport { loops: 1, filled: 0, triangles: 0 });
        assert_eq!(m.triangles.len(), n);
        assert_eq!(fill_holes(&mut m, f32::NAN, 64), HoleReport::default());
    }
}
