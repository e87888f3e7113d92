//! One surface from several cameras: where two cameras' grids overlap, the better observation
//! of each region is kept and the other camera's samples there are dropped (or averaged into the
//! kept one), so that the merged mesh has no double layer.
//!
//! "Better" is the laser line's strength averaged over a neighbourhood of the grid (a brighter
//! line is a less grazing view of a better lit surface), so ownership changes in coherent
//! regions rather than from sample to sample. After fusing, no two samples of different cameras
//! are closer than `min_distance_m`.

use crate::cells::Cells;
use crate::mesh::{meshed_samples, Grid, MeshConfig};
use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// Settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FuseConfig {
    /// Samples of different cameras closer than this are one observation, metres.
    pub min_distance_m: f32,
    /// Average the dropped sample into the kept one (weighted by quality) instead of only
    /// dropping it.
    pub average: bool,
    /// Half size of the grid window whose mean strength is a sample's quality, samples. 15 (a
    /// 31 x 31 window, about 70 mm at 2.3 mm spacing) by default: where two cameras see a region
    /// about equally (a flat table), the line's strength ripples from sample to sample, and a
    /// narrower window lets ownership flip with it, leaving islands and seams full of holes (the
    /// demo's merged surface: 371 interior boundary edges at radius 3, 10 at 8, 3 at 15).
    pub quality_radius: usize,
    /// The mesher's limits: a sample that fusing leaves in no triangle is given back (see
    /// [`one_surface`]).
    pub mesh: MeshConfig,
    /// A region that a camera keeps inside another camera's region, of fewer samples than
    /// this, is given back to the other camera (see [`one_surface`]).
    pub min_region: usize,
}

impl FuseConfig {
    /// The defaults (the merger's parameter defaults), usable in constant expressions.
    pub const DEFAULT: FuseConfig = FuseConfig {
        min_distance_m: 0.002,
        average: true,
        quality_radius: 15,
        mesh: MeshConfig::DEFAULT,
        min_region: 50,
    };
}

impl Default for FuseConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What fusing did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FuseReport {
    /// Samples dropped per grid.
    pub dropped: Vec<usize>,
    /// Samples that absorbed others.
    pub fused: usize,
    /// Close pairs examined.
    pub pairs: usize,
    /// Kept samples that fusing left in no triangle, given back to the other cameras.
    pub orphans: usize,
    /// Small kept regions inside another camera's region, given back to it.
    pub islands: usize,
}

/// Mean strength over a `(2r+1)^2` window of valid samples (a summed-area table).
fn quality(g: &Grid, r: usize) -> Vec<f32> {
    let (ns, nf) = (g.samples(), g.frames());
    let pts = g.points();
    let inten = g.intensity();
    let w = ns + 1;
    let mut sum = vec![0.0f64; (ns + 1) * (nf + 1)];
    let mut cnt = vec![0u32; (ns + 1) * (nf + 1)];
    for f in 0..nf {
        for s in 0..ns {
            let i = f * ns + s;
            let (v, c) = if pts[i][0].is_finite() { (f64::from(inten[i].max(0.0)), 1) } else { (0.0, 0) };
            let k = (f + 1) * w + s + 1;
            sum[k] = v + sum[k - 1] + sum[k - w] - sum[k - w - 1];
            cnt[k] = c + cnt[k - 1] + cnt[k - w] - cnt[k - w - 1];
        }
    }
    let mut q = vec![0.0f32; ns * nf];
    for f in 0..nf {
        for s in 0..ns {
            let (s0, s1, f0, f1) = (s.saturating_sub(r), (s + r + 1).min(ns), f.saturating_sub(r), (f + r + 1).min(nf));
            let box_sum = sum[f1 * w + s1] - sum[f0 * w + s1] - sum[f1 * w + s0] + sum[f0 * w + s0];
            let n = cnt[f1 * w + s1] + cnt[f0 * w + s0] - cnt[f0 * w + s1] - cnt[f1 * w + s0];
            q[f * ns + s] = if n > 0 { (box_sum / f64::from(n)) as f32 } else { 0.0 };
        }
    }
    q
}

/// The 4-neighbours of sample `i` in a grid of `ns` samples per frame and `n` samples.
fn neighbours(i: usize, ns: usize, n: usize) -> impl Iterator<Item = usize> {
    let s = i % ns;
    [(s > 0).then(|| i - 1), (s + 1 < ns).then_some(i + 1), i.checked_sub(ns), Some(i + ns).filter(|&j| j < n)]
        .into_iter()
        .flatten()
}

/// Fusing decides sample by sample, so where one camera's line is brighter over a strip only
/// one sample wide (a face the other camera sees almost edge-on), a single column of its samples
/// survives between the other camera's kept samples, and no triangle reaches it: a gap. Such an
/// orphan (kept, in no triangle of its grid, and either fused or next to a sample the fuse
/// dropped) is dropped, and the other grids' samples that were dropped within the distance of
/// it are restored, so the other camera's mesh covers the strip. Returns the orphans.
fn give_back_orphans(
    grids: &mut [Grid],
    originals: &[Vec<[f32; 3]>],
    cfg: &FuseConfig,
    dropped: &mut [usize],
) -> usize {
    // Each grid's orphans from its own samples alone: the grids meshed on a core each.
    let per_grid = crate::par::filter_map(grids, 1, |k, g| {
        let meshed = meshed_samples(g, &cfg.mesh);
        let (pts, orig, ns) = (g.points(), &originals[k], g.samples().max(1));
        let fused_away = |j: usize| orig[j][0].is_finite() && !pts[j][0].is_finite();
        let orphan = |i: usize| {
            pts[i][0].is_finite() && !meshed[i] && (pts[i] != orig[i] || neighbours(i, ns, pts.len()).any(fused_away))
        };
        Some((0..pts.len()).filter(|&i| orphan(i)).map(|i| (k, i)).collect::<Vec<_>>())
    });
    let orphans: Vec<(usize, usize)> = per_grid.into_iter().flatten().collect();
    give_back(grids, originals, cfg, dropped, &orphans);
    orphans.len()
}

/// Drops the samples `(grid, index)` and restores the other grids' samples that fusing dropped
/// within the distance of them.
fn give_back(
    grids: &mut [Grid],
    originals: &[Vec<[f32; 3]>],
    cfg: &FuseConfig,
    dropped: &mut [usize],
    samples: &[(usize, usize)],
) {
    if samples.is_empty() {
        return;
    }
    let cells: Vec<Cells> = originals.iter().map(|o| Cells::new(o, cfg.min_distance_m)).collect();
    for &(k, i) in samples {
        grids[k].points_mut()[i] = [f32::NAN; 3];
        dropped[k] += 1;
        let q = originals[k][i];
        for (m, g) in grids.iter_mut().enumerate().filter(|(m, _)| *m != k) {
            let pts = g.points_mut();
            cells[m].within(&q, cfg.min_distance_m, |j, _| {
                let j = j as usize;
                if !pts[j][0].is_finite() {
                    pts[j] = originals[m][j];
                    dropped[m] -= 1;
                }
            });
        }
    }
}

/// Where the better camera changes from place to place over a region both see about equally
/// (a flat table between two cameras), fusing leaves small islands of one camera's samples
/// inside the other's region, each with a seam all round it. A connected region (4-neighbours
/// in the grid) of kept samples smaller than `min_region` whose neighbours outside it are
/// mostly samples the fuse dropped (so the other cameras cover what surrounds it) is given
/// back: dropped, and the other grids' samples dropped near it restored. Returns the islands.
fn give_back_islands(
    grids: &mut [Grid],
    originals: &[Vec<[f32; 3]>],
    cfg: &FuseConfig,
    dropped: &mut [usize],
) -> usize {
    let mut islands = 0;
    // Grid by grid, each on the state the previous ones left.
    for k in 0..grids.len() {
        let mut give: Vec<(usize, usize)> = Vec::new();
        let g = &grids[k];
        let (pts, orig, ns) = (g.points(), &originals[k], g.samples().max(1));
        let n = pts.len();
        let kept = |i: usize| pts[i][0].is_finite();
        let mut seen = vec![false; n];
        let mut stack = Vec::new();
        let mut region = Vec::new();
        for seed in 0..n {
            if !kept(seed) || seen[seed] {
                continue;
            }
            seen[seed] = true;
            stack.push(seed);
            region.clear();
            let (mut fused_away, mut unseen) = (0usize, 0usize);
            while let Some(i) = stack.pop() {
                region.push(i);
                for j in neighbours(i, ns, n) {
                    if kept(j) {
                        if !seen[j] {
                            seen[j] = true;
                            stack.push(j);
                        }
                    } else if orig[j][0].is_finite() {
                        fused_away += 1;
                    } else {
                        unseen += 1;
                    }
                }
                if region.len() >= cfg.min_region {
                    break;
                }
            }
            if region.len() < cfg.min_region && fused_away > unseen {
                islands += 1;
                give.extend(region.iter().map(|&i| (k, i)));
            } else {
                // Too large: mark the rest of it so that it is not walked again.
                while let Some(i) = stack.pop() {
                    for j in neighbours(i, ns, n) {
                        if kept(j) && !seen[j] {
                            seen[j] = true;
                            stack.push(j);
                        }
                    }
                }
            }
        }
        give_back(grids, originals, cfg, dropped, &give);
    }
    islands
}

/// Fuses the grids (all in `table`) in place: dropped samples become NaN. Orphans (kept samples
/// that fusing left in no triangle) are then given back to the other cameras, and last no two
/// samples of different grids closer than `min_distance_m` stay.
pub fn one_surface(grids: &mut [Grid], cfg: &FuseConfig) -> FuseReport {
    let mut report = FuseReport { dropped: vec![0; grids.len()], ..FuseReport::default() };
    if !(cfg.min_distance_m > 0.0) {
        return report;
    }
    let mut near: Vec<(f32, usize)> = Vec::new();
    let originals: Vec<Vec<[f32; 3]>> = grids.iter().map(|g| g.points().to_vec()).collect();
    let qual: Vec<Vec<f32>> = grids.iter().map(|g| quality(g, cfg.quality_radius)).collect();
    for j in 1..grids.len() {
        for i in 0..j {
            // Index grid i; walk grid j's samples.
            let (lo, hi) = grids.split_at_mut(j);
            let (gi, gj) = (&mut lo[i], &mut hi[0]);
            let cells = Cells::new(gi.points(), cfg.min_distance_m);
            for b in 0..gj.points().len() {
                let pb = gj.points()[b];
                if !pb.iter().all(|v| v.is_finite()) {
                    continue;
                }
                // Grid i's samples within the distance, nearest first.
                near.clear();
                cells.within(&pb, cfg.min_distance_m, |a, d2| near.push((d2, a as usize)));
                near.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
                let (mut acc, mut wsum) = ([0.0f32; 3], 0.0f32);
                let mut b_dropped = false;
                for &(_, a) in &near {
                    let pa = gi.points()[a];
                    if !pa[0].is_finite() {
                        continue; // dropped earlier
                    }
                    report.pairs += 1;
                    let (qa, qb) = (qual[i][a], qual[j][b]);
                    if qa >= qb {
                        // Grid i keeps this region: b goes (into a).
                        if cfg.average {
                            let (wa, wb) = (qa.max(1e-3), qb.max(1e-3));
                            let m = [0, 1, 2].map(|k| (pa[k] * wa + pb[k] * wb) / (wa + wb));
                            gi.points_mut()[a] = m;
                            report.fused += 1;
                        }
                        b_dropped = true;
                        break;
                    }
                    // Grid j keeps it: a goes (into b).
                    if cfg.average {
                        let wa = qa.max(1e-3);
                        acc = [0, 1, 2].map(|k| acc[k] + pa[k] * wa);
                        wsum += wa;
                    }
                    gi.points_mut()[a] = [f32::NAN; 3];
                    report.dropped[i] += 1;
                }
                if b_dropped {
                    gj.points_mut()[b] = [f32::NAN; 3];
                    report.dropped[j] += 1;
                } else if wsum > 0.0 {
                    let wb = qual[j][b].max(1e-3);
                    gj.points_mut()[b] = [0, 1, 2].map(|k| (acc[k] + pb[k] * wb) / (wsum + wb));
                    report.fused += 1;
                }
            }
        }
    }
    report.islands = give_back_islands(grids, &originals, cfg, &mut report.dropped);
    report.orphans = give_back_orphans(grids, &originals, cfg, &mut report.dropped);
    // Averaging moved kept samples a little: drop the rare pair that came closer than the bound.
    for j in 1..grids.len() {
        for i in 0..j {
            let (lo, hi) = grids.split_at_mut(j);
            let (gi, gj) = (&mut lo[i], &mut hi[0]);
            let cells = Cells::new(gi.points(), cfg.min_distance_m);
            for b in 0..gj.points().len() {
                let pb = gj.points()[b];
                if !pb[0].is_finite() {
                    continue;
                }
                let mut close = false;
                cells.within(&pb, cfg.min_distance_m, |_, _| close = true);
                if close {
                    gj.points_mut()[b] = [f32::NAN; 3];
                    report.dropped[j] += 1;
                }
            }
        }
    }
    report
}

/// The smallest distance between samples of different grids (for checks), metres; infinite
/// when no two grids have samples.
pub fn min_cross_distance(grids: &[Grid]) -> f32 {
    let mut best = f32::INFINITY;
    for j in 1..grids.len() {
        for i in 0..j {
            let entries: Vec<[f32; 3]> = grids[i].points().iter().copied().filter(|p| p[0].is_finite()).collect();
            let Ok(tree) = ImmutableKdTree::<f32, 3>::new_from_slice(&entries) else { continue };
            for p in grids[j].points().iter().filter(|p| p[0].is_finite()) {
                let nn = tree.query(p).nearest_one::<SquaredEuclidean<f32>>().execute();
                best = best.min(nn.distance.sqrt());
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::triangulate::Profile;

    /// A flat 40 x 40 sample grid every 2 mm, `dz` above the table, the line's strength from
    /// `strength(s, f)`.
    fn flat(dz: f32, strength: impl Fn(usize, usize) -> f32) -> Grid {
        let ns = 40;
        let mut g = Grid::new(ns);
        for f in 0..40 {
            let points = (0..ns).map(|s| [s as f32 * 0.002, f as f32 * 0.002, dz]).collect();
            let intensity = (0..ns).map(|s| strength(s, f)).collect();
            g.push(f as i64, &Profile { intensity, range: vec![0.5; ns], points, ..Profile::default() }).unwrap();
        }
        g
    }

    /// Camera B sees a 3 x 3 patch brighter than camera A, inside A's region: fused sample by
    /// sample (a window of one) B keeps that island, with a seam all round it; given back, A
    /// keeps the whole plate and B nothing.
    #[test]
    fn a_small_island_goes_back_to_the_camera_around_it() {
        let run = |min_region: usize| {
            let bright = |s: usize, f: usize| if (19..22).contains(&s) && (19..22).contains(&f) { 200.0 } else { 50.0 };
            let mut grids = [flat(0.0, |_, _| 100.0), flat(0.0005, bright)];
            let cfg = FuseConfig { quality_radius: 0, min_region, ..FuseConfig::default() };
            let r = one_surface(&mut grids, &cfg);
            let kept = |g: &Grid| g.points().iter().filter(|p| p[0].is_finite()).count();
            (kept(&grids[0]), kept(&grids[1]), r.islands)
        };
        assert_eq!(run(0), (1600 - 9, 9, 0), "without giving back, B keeps its island");
        assert_eq!(run(50), (1600, 0, 1));
    }
}
