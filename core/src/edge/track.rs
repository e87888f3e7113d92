//! Continuity along the line: runs of samples that follow each other from row to row, their
//! extension into neighbouring rows by a search near their own course, and the removal of runs
//! too short to be a laser line.

use super::{EdgeConfig, LaserLine};
use std::ops::Range;

/// Missing samples a run may step over.
const MAX_GAP: u32 = 2;
/// Samples at a run's end from which its course is extrapolated.
const SLOPE_SPAN: u32 = 3;

/// A run of samples: first and last index, and how many samples it holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Run {
    pub first: u32,
    pub last: u32,
    pub count: u32,
}

/// The runs of `line` within `range`: consecutive found samples, at most `MAX_GAP` missing
/// between two, whose positions across differ by at most `max_jump_px` per step.
pub(super) fn runs(line: &LaserLine, range: Range<u32>, max_jump_px: f32) -> Vec<Run> {
    let mut out: Vec<Run> = Vec::new();
    let mut last: Option<(u32, f32)> = None;
    for s in range {
        let x = line.across(s as usize);
        if !x.is_finite() {
            continue;
        }
        match (last, out.last_mut()) {
            (Some(l), Some(run)) if continues(l, (s, x), max_jump_px) => {
                run.last = s;
                run.count += 1;
            }
            _ => out.push(Run { first: s, last: s, count: 1 }),
        }
        last = Some((s, x));
    }
    out
}

/// Whether sample `b` (index, position across) continues the run whose last sample is `a`: at
/// most `MAX_GAP` missing between them, and at most `max_jump_px` a step apart.
fn continues((a, xa): (u32, f32), (b, xb): (u32, f32), max_jump_px: f32) -> bool {
    b - a <= MAX_GAP + 1 && (xb - xa).abs() <= max_jump_px * (b - a) as f32
}

/// Clears every lone sample off the line's course on both sides where the found samples just
/// before and after it (at most `MAX_GAP` missing between those two) lie within `max_jump_px`
/// of each other: a peak of another surface or of texture in a row where the line itself was
/// not found, with the line running on smoothly across it. Such a sample, a run of one, is
/// dropped with the short runs anyway; cleared first, it no longer cuts the line's run in two
/// (on the robot's real frames a piece of six samples so cut off was dropped as a blob). The
/// two neighbours must agree within one step's tolerance, not the runs' own `max_jump_px` a
/// step: with that, the tail of the sheet on another surface (6 px aside over two rows) joined
/// a run of the hard phantom at 640x480 and its points 11 mm off were kept. Nor may either
/// neighbour be a faint tail (under half the strongest sample near it): the hard body's table
/// line at 640x480 so took on samples of a twentieth of its strength, 5-6 mm off. Returns how
/// many were cleared.
fn drop_strays(line: &mut LaserLine, range: Range<u32>, max_jump_px: f32) -> u32 {
    let strays = strays(line, range, max_jump_px);
    for &s in &strays {
        line.clear(s as usize);
    }
    strays.len() as u32
}

/// The samples [`drop_strays`] clears (read in one pass: a cleared sample is never read again).
fn strays(line: &LaserLine, range: Range<u32>, max_jump_px: f32) -> Vec<u32> {
    let across = match line.orientation {
        super::Orientation::Vertical => &line.u,
        super::Orientation::Horizontal => &line.v,
    };
    let follows = |a, b| continues(a, b, max_jump_px);
    let strength = |s: u32| line.strength[s as usize];
    let last = (across.len() as u32).saturating_sub(1);
    // The last two found samples (index, position across) before the one at hand.
    let (mut before, mut lone) = (None::<(u32, f32)>, None::<(u32, f32)>);
    let mut out = Vec::new();
    for s in range {
        let x = across[s as usize];
        if !x.is_finite() {
            continue;
        }
        let after = (s, x);
        if let (Some(b), Some(c)) = (before, lone) {
            let smooth = || after.0 - b.0 <= MAX_GAP + 1 && (after.1 - b.1).abs() <= max_jump_px;
            // Neither neighbour a faint tail: each at least half as strong as the strongest
            // sample near them (the stray aside).
            let firm = || {
                let near = b.0.saturating_sub(COURSE_SPAN)..=(after.0 + COURSE_SPAN).min(last);
                let strongest = near.filter(|&s| s != c.0).map(strength).fold(0.0, f32::max);
                strength(b.0).min(strength(after.0)) >= SLIVER_STRENGTH * strongest
            };
            if !follows(b, c) && !follows(c, after) && smooth() && firm() {
                out.push(c.0);
                lone = Some(after);
                continue;
            }
        }
        (before, lone) = (lone, Some(after));
    }
    out
}

/// Extends every run of at least `min_run` samples, longest first, beyond its ends: the next
/// sample's position is extrapolated from the run's last samples, and `probe(line, s, (centre,
/// radius), held)` searches sample `s` near it, writing what it finds (and leaving the sample
/// as it was when it finds nothing) and saying whether it found a peak; `held` is the length of
/// the run that holds the sample (zero for none). A sample that a longer run already holds
/// stops the extension; one that a shorter run holds is searched again near this run's course.
pub(super) fn extend(
    line: &mut LaserLine,
    cfg: &EdgeConfig,
    range: Range<u32>,
    mut probe: impl FnMut(&mut LaserLine, u32, (f32, f32), u32) -> bool,
) {
    let mut list = runs(line, range.clone(), cfg.max_jump_px);
    if list.len() <= 1 && list.first().is_none_or(|r| r.first == range.start && r.last + 1 == range.end) {
        // One run over the whole range, or none: nothing to extend beyond the ends.
        fill_gaps(line, cfg, &list, &mut probe);
        return;
    }
    // Which run holds each sample (by rank, longest first), so that a longer run keeps its own.
    list.sort_by(|a, b| b.count.cmp(&a.count).then(a.first.cmp(&b.first)));
    let n = line.len();
    let mut owner = vec![u32::MAX; n];
    for (rank, r) in list.iter().enumerate() {
        for s in r.first..=r.last {
            if line.across(s as usize).is_finite() {
                owner[s as usize] = rank as u32;
            }
        }
    }
    let mut found = false;
    for (rank, r) in list.iter().enumerate() {
        if r.count < cfg.min_run {
            break;
        }
        let rank = rank as u32;
        for forward in [false, true] {
            let (mut end, mut misses) = (if forward { r.last } else { r.first }, 0u32);
            loop {
                let step = misses + 1;
                let s = if forward { end.checked_add(step) } else { end.checked_sub(step) };
                let Some(s) = s.filter(|s| range.contains(s)) else { break };
                if owner[s as usize] < rank {
                    break;
                }
                let centre = extrapolate(line, end, forward, step, cfg.max_jump_px);
                let radius = cfg.max_jump_px * step as f32;
                let held = list.get(owner[s as usize] as usize).map_or(0, |r| r.count);
                if probe(line, s, (centre, radius), held) {
                    owner[s as usize] = rank;
                    (end, misses, found) = (s, 0, true);
                } else {
                    misses += 1;
                    if misses > MAX_GAP {
                        break;
                    }
                }
            }
        }
    }
    // The runs again where the extension found samples (it joins and lengthens runs) and a gap
    // could lie inside one; else the runs are those it started from.
    if !found {
        fill_gaps(line, cfg, &list, &mut probe);
    } else if has_short_gap(line, range.clone()) {
        let list = runs(line, range, cfg.max_jump_px);
        fill_gaps(line, cfg, &list, &mut probe);
    }
}

/// Whether `line` misses at most `MAX_GAP` samples in a row somewhere in `range` between two
/// found samples (a gap that a run may hold).
fn has_short_gap(line: &LaserLine, range: Range<u32>) -> bool {
    let across = match line.orientation {
        super::Orientation::Vertical => &line.u,
        super::Orientation::Horizontal => &line.v,
    };
    let mut last = None::<usize>;
    for (i, x) in across.iter().enumerate().take(range.end as usize).skip(range.start as usize) {
        if x.is_finite() {
            if last.is_some_and(|l| i - l > 1 && i - l <= MAX_GAP as usize + 1) {
                return true;
            }
            last = Some(i);
        }
    }
    false
}

/// Searches the missing samples inside every run of `list` of at least `min_run` samples (at
/// most `MAX_GAP` in a row, the run going on past them) that are still missing, near the course
/// between the found samples on either side: `probe` as in [`extend`], the sample held by no
/// run. A sample found on its own inside a stretch that only the course's search finds cuts
/// that stretch into pieces whose ends the extension reaches, but not the samples between them
/// (the hard pyramid's line beside its dark print at 320x240).
fn fill_gaps(
    line: &mut LaserLine,
    cfg: &EdgeConfig,
    list: &[Run],
    probe: &mut impl FnMut(&mut LaserLine, u32, (f32, f32), u32) -> bool,
) {
    for r in list.iter().filter(|r| r.count >= cfg.min_run && r.count <= r.last - r.first) {
        let mut before = r.first;
        for s in r.first + 1..r.last {
            if line.across(s as usize).is_finite() {
                before = s;
                continue;
            }
            let Some(after) = (s + 1..=r.last).find(|&t| line.across(t as usize).is_finite()) else { break };
            let (a, b) = (line.across(before as usize), line.across(after as usize));
            let f = (s - before) as f32 / (after - before) as f32;
            if probe(line, s, (a + f * (b - a), cfg.max_jump_px), 0) {
                before = s;
            }
        }
    }
}

/// What a search for a second sample found.
pub(super) enum Probe {
    /// A line at this position across, written into the second line.
    Found(f32),
    /// Nothing apart from the first line.
    Missed,
    /// The sample's second line is already taken (by another run's walk).
    Taken,
}

/// Two surfaces in one row: where an object hides part of the table, the object's line and
/// the table's overlap by some rows, and the first line holds one of them there (the longer
/// run's, see [`extend`]). Each run of at least `min_run` samples is followed on beyond its
/// ends into rows that another run holds, by a search near its own course:
/// `probe(s, (centre, radius), held)` searches sample `s` near `centre`, away from `held` (the
/// first line's position there), writes what it finds into the second line, and says so.
/// The walk stops at a row without a first sample (the first line's own extension has
/// searched it), where the course meets the first line's sample (one line, not two), after
/// `MAX_GAP + 1` misses, at the range's end, or at a row whose second sample is taken.
pub(super) fn second_surfaces(
    line: &LaserLine,
    cfg: &EdgeConfig,
    range: Range<u32>,
    mut probe: impl FnMut(u32, (f32, f32), f32) -> Probe,
) {
    // The walk's own course: (sample, position across), the run's end first.
    let mut course: Vec<(u32, f32)> = Vec::new();
    for r in runs(line, range.clone(), cfg.max_jump_px).iter().filter(|r| r.count >= cfg.min_run) {
        for forward in [false, true] {
            let mut end = if forward { r.last } else { r.first };
            course.clear();
            if let Some(b) = behind(end, forward).filter(|&b| b >= r.first && b <= r.last) {
                course.push((b, line.across(b as usize)));
            }
            course.push((end, line.across(end as usize)));
            let mut misses = 0u32;
            loop {
                let step = misses + 1;
                let s = if forward { end.checked_add(step) } else { end.checked_sub(step) };
                let Some(s) = s.filter(|s| range.contains(s)) else { break };
                let held = line.across(s as usize);
                if !held.is_finite() {
                    break;
                }
                let at = |k: u32| course.iter().rev().find(|c| c.0 == k).map(|c| c.1);
                let x = at(end).unwrap_or(f32::NAN);
                let centre = project(x, behind(end, forward).and_then(at), step, cfg.max_jump_px);
                let radius = cfg.max_jump_px * step as f32;
                if (held - centre).abs() <= radius {
                    break; // the course runs into the first line: one line
                }
                match probe(s, (centre, radius), held) {
                    Probe::Found(pos) => {
                        course.push((s, pos));
                        (end, misses) = (s, 0);
                    }
                    Probe::Missed => {
                        misses += 1;
                        if misses > MAX_GAP {
                            break;
                        }
                    }
                    Probe::Taken => break,
                }
            }
        }
    }
}

/// Where the run ending at `end` is expected `step` samples further on.
fn extrapolate(line: &LaserLine, end: u32, forward: bool, step: u32, max_jump_px: f32) -> f32 {
    let back = behind(end, forward).filter(|&b| (b as usize) < line.len()).map(|b| line.across(b as usize));
    project(line.across(end as usize), back, step, max_jump_px)
}

/// The sample `SLOPE_SPAN` behind `end` (before it when walking forward).
fn behind(end: u32, forward: bool) -> Option<u32> {
    if forward {
        end.checked_sub(SLOPE_SPAN)
    } else {
        end.checked_add(SLOPE_SPAN)
    }
}

/// A course at `x` whose position `SLOPE_SPAN` samples behind was `back` (none or NaN: a flat
/// course), `step` samples further on; its slope at most `max_jump_px` a sample.
fn project(x: f32, back: Option<f32>, step: u32, max_jump_px: f32) -> f32 {
    let slope = back
        .filter(|xb| xb.is_finite())
        .map_or(0.0, |xb| ((x - xb) / SLOPE_SPAN as f32).clamp(-max_jump_px, max_jump_px));
    x + slope * step as f32
}

/// A line is long and thin: a run must be at least this many times as long as its mean width
/// (a highlight or a blob of texture is about as long as it is wide).
const MIN_LENGTH_PER_WIDTH: f32 = 2.0;

/// Runs shorter than this many times `min_run` are compared with the line's typical width.
const WIDE_RUNS: u32 = 10;
/// A sample of a kept run this many times wider than the run's median width, and
/// `WIDTH_EXCESS_PX` wider, is not the line: two surfaces' peaks merged in one row (at the hard
/// pyramid's base corners at 320x240, 2.7-4.5 px against 2 and 8-18 mm off; the widest of them
/// are caught), or the line straddling a dark/bright edge.
const WIDTH_TOLERANCE: f32 = 1.6;
/// The least excess width (pixels) that rejects a sample: a line under a pixel wide measures
/// one to two pixels wide as its sub-pixel phase changes along the run, which is no mixture.
const WIDTH_EXCESS_PX: f32 = 1.5;
/// A sample of a kept run narrower than this fraction of the run's median width (and
/// `NARROW_DEFICIT_PX` narrower, and narrower than `narrow_width_px`) is the sheet cut by an
/// edge parallel to the line (the first or last frame on an object, a dark/bright edge under
/// the sheet): what is seen is a sliver of the sheet, its centre on the sliver, not on the
/// sheet. On the hard phantom at 640x480 such samples, 0.9-1.6 px wide in runs of 2.8, lay 1-5
/// mm off in whole stretches of one frame, and carried half of the squared error.
const NARROW_TOLERANCE: f32 = 0.6;
/// The least deficit (pixels) that rejects a narrow sample: a line under a pixel wide measures
/// one to two pixels wide as its phase changes along the run, which is no sliver.
const NARROW_DEFICIT_PX: f32 = 1.1;
/// A narrow sample at least this fraction of its run's median strength is a sliver. A dim line
/// on dark print (reflectance 0.15) measures as narrow as a sliver beside a saturated run, but
/// at 0.12-0.57 of its strength (the hard pyramid at 640x480, grey), while the phantom's
/// slivers lie at 0.2-1.1 of theirs.
const SLIVER_STRENGTH: f32 = 0.5;
/// A weaker narrow sample is a sliver where it lies this far (pixels) off the straight line
/// between the run's nearest samples of the line's own width on each side (or has none on a
/// side within `SLIVER_SPAN`): a sliver's centre is the sliver's, off the sheet's, while a
/// dim line on dark print stays on course (0.15 px median, 0.4 px at the 90th percentile, on
/// the hard pyramid; the phantom's weak slivers 0.43 / 0.35 px median, or at a run's end).
const SLIVER_OFF_COURSE_PX: f32 = 0.5;
/// A sample under `SLIVER_STRENGTH` of its run's median strength, whatever its width, is dropped
/// where it lies this far (pixels) off the straight line between the run's nearest samples of
/// at least that strength on each side (within `SLIVER_SPAN`): light of the sheet's tail on a
/// surface just off the sheet (the hard phantom at 640x480 in colour: stretches 1-2 px wide at
/// 0.1-0.4 of the run's strength, 1 px off course, 3-4 mm off the surface).
const WEAK_OFF_COURSE_PX: f32 = 0.7;
/// ... but not more than this many times the run's median width off it: the sheet's tail lies
/// within about the line's width of the sheet, and farther off a straight course is the course
/// itself bending between the strong samples (the hard pyramid at 320x240 in colour: its dim
/// line on the print, right but 8-12 px off the straight line across a corner).
const WEAK_REACH_WIDTHS: f32 = 2.0;
/// Samples on each side of a narrow sample within which its course's neighbours are sought.
const SLIVER_SPAN: u32 = 40;
/// A sample too wide for its run is dropped only if its centre is also this fraction of its
/// width off the course of its neighbours: two surfaces merged into one peak pull its centre
/// aside, while a real line that merely widens (blooming on a bright floor) stays on course.
/// On the hard phantom and pyramid at 320x240 this keeps all but 1 of the 122 wide samples
/// beyond 5 mm that the width alone drops, and on the robot's real frames it keeps 54 % of the
/// width alone's drops.
const OFF_COURSE_PER_WIDTH: f32 = 0.1;
/// Samples on each side of a wide sample within which `off_course` looks for a neighbour.
const COURSE_SPAN: u32 = 3;

/// How far (pixels) sample `s` of run `r` lies from the straight line between its nearest
/// neighbours of the run on each side (within `span` samples, found and accepted by
/// `eligible`, given the sample's index); `None` where a side has none.
fn off_course(line: &LaserLine, r: &Run, s: u32, span: u32, eligible: impl Fn(usize) -> bool) -> Option<f32> {
    let neighbour = |forward: bool| {
        (1..=span).find_map(|k| {
            let t = if forward { s.checked_add(k)? } else { s.checked_sub(k)? };
            if !(r.first..=r.last).contains(&t) {
                return None;
            }
            let x = line.across(t as usize);
            (x.is_finite() && eligible(t as usize)).then_some((t as f32, x))
        })
    };
    let ((a, xa), (b, xb)) = (neighbour(false)?, neighbour(true)?);
    Some((line.across(s as usize) - (xa + (xb - xa) * (s as f32 - a) / (b - a))).abs())
}

/// The median width of run `r`'s samples that have one (0 where none has).
fn median_width(line: &LaserLine, r: &Run, scratch: &mut Vec<u32>) -> f32 {
    median(scratch, (r.first..=r.last).map(|s| line.width[s as usize]).filter(|w| *w > 0.0)).unwrap_or(0.0)
}

/// The median strength of run `r`'s samples (0 where none is found).
fn median_strength(line: &LaserLine, r: &Run, scratch: &mut Vec<u32>) -> f32 {
    let found = (r.first..=r.last).filter(|&s| line.across(s as usize).is_finite());
    median(scratch, found.map(|s| line.strength[s as usize])).unwrap_or(0.0)
}

/// The median (the upper one of an even count) of `values`, `None` where there are none;
/// `scratch` holds their keys.
fn median(scratch: &mut Vec<u32>, values: impl Iterator<Item = f32>) -> Option<f32> {
    scratch.clear();
    scratch.extend(values.map(order_key));
    let mid = scratch.len() / 2;
    (!scratch.is_empty()).then(|| select(scratch, mid))
}

/// A key whose unsigned order is `f32::total_cmp`'s order of `x`: selecting on integers is
/// several times cheaper than on floats through a comparison function.
fn order_key(x: f32) -> u32 {
    let b = x.to_bits();
    if b >> 31 == 1 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// The float whose [`order_key`] is `k`.
fn from_order_key(k: u32) -> f32 {
    f32::from_bits(if k >> 31 == 1 { k & 0x7FFF_FFFF } else { !k })
}

/// The `k`-th smallest of the keys (`k < keys.len()`), as a float; reorders `keys`.
fn select(keys: &mut [u32], k: usize) -> f32 {
    from_order_key(*keys.select_nth_unstable(k).1)
}

/// A short run this many times wider than the line's typical width is not the line: a
/// highlight, or the line spread over a grazing surface or mixed pixels (on the hard phantom
/// such a run lay 5-9 mm off, widening from 3 to 10 px while the line beside it was 2-3 px).
/// Not less: the robot's real frame 31 (the camera moving 16 px in the frame) has the line on
/// the near blocks 1.8-1.9 times the last frames' typical width, in runs of about 40 columns.
const WIDE_RUN_TOLERANCE: f32 = 2.0;

/// The typical width of the line in `line` (the median of its samples' widths), if it has at
/// least `min` samples.
pub(super) fn typical_width(line: &LaserLine, min: usize, scratch: &mut Vec<u32>) -> Option<f32> {
    let widths = line.width.iter().copied().filter(|w| *w > 0.0);
    median(scratch, widths).filter(|_| scratch.len() >= min)
}

/// Runs shorter than this many times `min_run` are judged by their length as well.
const BLOB_RUNS: u32 = 4;

/// Runs shorter than this many times `min_run`, and weak, are judged by their wider end's
/// width (the sheet's tail on the hard phantom's walls at 320x240: 6-9 rows). The hard body's
/// runs with a highlight at one end are 14-19 rows.
const SPREAD_RUNS: u32 = 2;

/// A run that fades out at both ends (a glossy highlight's strength falls away from its middle
/// as a blob's does) must have a body (its samples at least half as strong as its strong ones)
/// at least this many times as long as its mean width. A line's strength is about even along
/// it, and where a piece of it ends (an occlusion, a jump) it ends strong.
const BODY_LENGTH_PER_WIDTH: f32 = 2.0;

/// For a run `r` whose first and last samples are both less than half as strong as its
/// 90th-percentile sample (not its strongest, which a speckle may raise): its samples at least
/// that half. `None` for a run that ends strong at either end.
fn faded_body(line: &LaserLine, r: &Run, scratch: &mut Vec<u32>) -> Option<usize> {
    let found =
        || (r.first..=r.last).filter(|&s| line.across(s as usize).is_finite()).map(|s| line.strength[s as usize]);
    let (first, last) = (found().next()?, found().next_back()?);
    // Half the 90th percentile is at most half the strongest: a run that ends at least that
    // strong at either end ends strong (the common case, without a selection).
    let strongest = found().fold(0.0, f32::max);
    if first >= 0.5 * strongest || last >= 0.5 * strongest {
        return None;
    }
    scratch.clear();
    scratch.extend(found().map(order_key));
    let k = (scratch.len() * 9 / 10).min(scratch.len() - 1);
    let half = 0.5 * select(scratch, k);
    (first < half && last < half).then(|| found().filter(|&v| v >= half).count())
}

/// Clears every run shorter than `min_run`, the samples of a kept run more than
/// `WIDTH_TOLERANCE` times its median width (and `WIDTH_EXCESS_PX` more) and off its course, or
/// less than `NARROW_TOLERANCE` times it (a sliver of the sheet, see `SLIVER_STRENGTH`), or
/// under `SLIVER_STRENGTH` of its median strength and off the course of its strong samples
/// (`WEAK_OFF_COURSE_PX`), every short run
/// (under `BLOB_RUNS` times `min_run`) shorter than `MIN_LENGTH_PER_WIDTH` times its mean
/// width (or, under `SPREAD_RUNS` times `min_run` and under `SLIVER_STRENGTH` of the frame's
/// median strength, times the width of its wider end: the sheet's tail), and every run that
/// fades out at both ends with a body shorter than
/// `BODY_LENGTH_PER_WIDTH` times its median width (a highlight, before any frame has shown the
/// line's width); returns the samples cleared. A run that spans the whole region is not judged
/// by its length.
///
/// With the line's typical width from earlier frames (`typical_width_px`), a run under
/// `WIDE_RUNS` times `min_run` whose median width is more than `WIDE_RUN_TOLERANCE` times that
/// is dropped too: a highlight, or a bright mark, in a frame after the laser went off.
pub(super) fn drop_short_runs(
    line: &mut LaserLine,
    cfg: &EdgeConfig,
    range: Range<u32>,
    typical_width_px: Option<f32>,
    scratch: &mut Vec<u32>,
) -> u32 {
    // A stray parts the runs in three at least (the line's before it, itself, the line's after).
    let mut list = runs(line, range.clone(), cfg.max_jump_px);
    let mut dropped = if list.len() >= 3 { drop_strays(line, range.clone(), cfg.max_jump_px) } else { 0 };
    if dropped > 0 {
        list = runs(line, range.clone(), cfg.max_jump_px);
    }
    // The frame's median strength, where a short run needs it.
    let mut frame_strength: Option<f32> = None;
    for r in list {
        let mean_width: f32 = (r.first..=r.last).map(|s| line.width[s as usize]).sum::<f32>() / r.count as f32;
        // The faded body and the typical width are judged by the median width: a highlight
        // that crosses a dim line widens a few of its rows, and by their mean the whole run
        // read as a highlight (the hard body's hair at 320x240 lost 30 rows so). The length
        // rule keeps the mean: short runs that widen as they go (the sheet's tail at the
        // phantom's edges at 320x240, 2 to 5.6 px over 7 rows) pass it by their median.
        let median = median_width(line, &r, scratch);
        // A run that spans the whole region may be cut by it: its length says nothing.
        let whole = r.first == range.start && r.last + 1 == range.end;
        // The sheet's tail on a surface it grazes is weak and spreads as it goes: a short run
        // under half the frame's median strength is judged by its wider end (the mean width of
        // its first or last three samples) where that is above its mean. The line's own short
        // runs are as strong as the frame's; a highlight that widens their end does not make
        // them a tail.
        let mut spread = mean_width;
        if r.count < SPREAD_RUNS * cfg.min_run {
            let found = |s: &u32| line.across(*s as usize).is_finite();
            let end = |it: &mut dyn Iterator<Item = u32>| {
                let (sum, n) = it.filter(found).take(3).fold((0.0, 0), |(a, n), s| (a + line.width[s as usize], n + 1));
                sum / n.max(1) as f32
            };
            let ends = end(&mut (r.first..=r.last)).max(end(&mut (r.first..=r.last).rev()));
            if ends > mean_width {
                let frame = *frame_strength.get_or_insert_with(|| {
                    self::median(scratch, range.clone().filter(found).map(|s| line.strength[s as usize])).unwrap_or(0.0)
                });
                if median_strength(line, &r, scratch) < SLIVER_STRENGTH * frame {
                    spread = ends;
                }
            }
        }
        let blob = !whole
            && ((r.count < BLOB_RUNS * cfg.min_run && (r.count as f32) < MIN_LENGTH_PER_WIDTH * spread)
                || faded_body(line, &r, scratch).is_some_and(|n| (n as f32) < BODY_LENGTH_PER_WIDTH * median));
        let too_wide =
            r.count < WIDE_RUNS * cfg.min_run && typical_width_px.is_some_and(|t| median > WIDE_RUN_TOLERANCE * t);
        if r.count >= cfg.min_run && !blob && !too_wide {
            // A kept run: its samples far wider than its own median are mixed pixels (two
            // surfaces in one peak, the line straddling a dark/bright edge, or running into a
            // highlight).
            // A sliver of the sheet, cut by an edge parallel to the line: as narrow as the
            // optics allow (under `narrow_width_px`; a wide saturated line's narrower rows are
            // its top above a shoulder, not a sliver), in a run whose line is wider.
            let narrower =
                |w: f32| w < cfg.narrow_width_px && w < NARROW_TOLERANCE * median && w < median - NARROW_DEFICIT_PX;
            let narrow_width = |w: f32| w > 0.0 && narrower(w);
            // The run's median strength, taken (before any sample is cleared) only where a found
            // sample is narrow or under half the run's maximum strength (the median is at most
            // the maximum): NaN otherwise, and then never read. The samples a run steps over
            // (strength 0) ask for nothing.
            let found = || (r.first..=r.last).filter(|&s| line.across(s as usize).is_finite());
            let strongest = found().map(|s| line.strength[s as usize]).fold(0.0, f32::max);
            let strength = if found().any(|s| {
                line.strength[s as usize] < SLIVER_STRENGTH * strongest || narrow_width(line.width[s as usize])
            }) {
                median_strength(line, &r, scratch)
            } else {
                f32::NAN
            };
            for s in r.first..=r.last {
                if !line.across(s as usize).is_finite() {
                    continue;
                }
                let w = line.width[s as usize];
                let wide = w > WIDTH_TOLERANCE * median
                    && w > median + WIDTH_EXCESS_PX
                    && off_course(line, &r, s, COURSE_SPAN, |t| line.width[t] <= WIDTH_TOLERANCE * median)
                        .is_none_or(|d| d > OFF_COURSE_PER_WIDTH * w);
                // A sliver is either about as strong as the run or off the course of the run's
                // line on both sides (a dim line on dark print is narrower than a saturated run
                // too, but it is weak and stays on course).
                let narrow = narrow_width(w)
                    && (line.strength[s as usize] >= SLIVER_STRENGTH * strength
                        || off_course(line, &r, s, SLIVER_SPAN, |t| !narrower(line.width[t]))
                            .is_none_or(|d| d > SLIVER_OFF_COURSE_PX));
                // A weak sample (any width) well off the course of the run's strong samples on
                // both sides: the sheet's tail on a surface the sheet itself misses.
                let weak = line.strength[s as usize] < SLIVER_STRENGTH * strength
                    && off_course(line, &r, s, SLIVER_SPAN, |t| line.strength[t] >= SLIVER_STRENGTH * strength)
                        .is_some_and(|d| d > WEAK_OFF_COURSE_PX && d < WEAK_REACH_WIDTHS * median);
                if wide || narrow || weak {
                    line.clear(s as usize);
                    dropped += 1;
                }
            }
            continue;
        }
        for s in r.first..=r.last {
            if line.across(s as usize).is_finite() {
                line.clear(s as usize);
                dropped += 1;
            }
        }
    }
    dropped
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vertical line of `widths.len()` rows along a gentle slope, every row found.
    fn line(widths: &[f32]) -> LaserLine {
        let n = widths.len();
        LaserLine {
            orientation: crate::edge::Orientation::Vertical,
            image_width: 320,
            image_height: n as u32,
            u: (0..n).map(|i| 100.0 + 0.1 * i as f32).collect(),
            v: (0..n).map(|i| i as f32).collect(),
            strength: vec![150.0; n],
            width: widths.to_vec(),
            rgb: Vec::new(),
        }
    }

    /// A line 2.8 px wide and 60 rows long (`line`) whose rows `rows` are `width` wide, of
    /// strength 30 (a fifth of the rest) and `shift` px off its course.
    fn weak_stretch(rows: std::ops::Range<usize>, width: f32, shift: f32) -> LaserLine {
        let mut l = line(&[2.8; 60]);
        l.width[rows.clone()].fill(width);
        l.strength[rows.clone()].fill(30.0);
        for u in &mut l.u[rows] {
            *u += shift;
        }
        l
    }

    #[test]
    fn the_gaps_inside_a_run_are_searched_near_its_course() {
        // A run of 60 rows with rows 20, 23, 24 and 40 missing (a sample found on its own
        // between rows that only the course's search finds): the ends' extension never reaches
        // them; the gap search probes each near the course between its neighbours, as held by
        // no run, and nowhere else.
        let mut l = line(&[2.0; 60]);
        let missing = [20usize, 23, 24, 40];
        for &i in &missing {
            l.u[i] = f32::NAN;
        }
        let cfg = EdgeConfig::default();
        let mut probed = Vec::new();
        extend(&mut l, &cfg, 0..60, |line, s, (centre, radius), held| {
            probed.push(s);
            let truth = 100.0 + 0.1 * s as f32;
            assert!((centre - truth).abs() < 0.01, "row {s}: course {centre} against {truth}");
            assert_eq!((radius, held), (cfg.max_jump_px, 0), "row {s}");
            line.u[s as usize] = truth;
            true
        });
        assert_eq!(probed, missing.iter().map(|&i| i as u32).collect::<Vec<_>>());
        assert_eq!(runs(&l, 0..60, cfg.max_jump_px), vec![Run { first: 0, last: 59, count: 60 }]);
        // A gap wider than `MAX_GAP` parts two runs: it is the ends' extension's to search.
        let mut l = line(&[2.0; 60]);
        for i in 20..23 {
            l.u[i] = f32::NAN;
        }
        let mut probed = Vec::new();
        extend(&mut l, &cfg, 0..60, |_, s, _, _| {
            probed.push(s);
            false
        });
        assert!(probed.iter().all(|s| (20..23).contains(s)), "{probed:?}");
    }

    #[test]
    fn the_sheets_weak_spreading_tail_is_dropped_the_lines_short_runs_are_not() {
        // The hard phantom at 320x240 (cam2, frame 64, rows 85-91): where the line leaves one
        // surface for another, the sheet's tail on the wall between them, 6 px aside, a fifth of
        // the line's strength, spreading from 2.3 to 5.0 px over seven rows. By its mean width
        // (3.35 px) it was long enough to keep; its points lay 3-6.5 mm off the wall.
        let cfg = EdgeConfig::default();
        let mut scratch = Vec::new();
        let tail = [2.3, 2.5, 3.0, 2.9, 3.6, 4.1, 5.0];
        let with_run = |widths: &[f32], strength: f32| {
            let mut l = line(&[2.0; 60]);
            for s in 25..28 {
                l.clear(s);
            }
            for (k, &w) in widths.iter().enumerate() {
                let s = 28 + k;
                (l.u[s], l.width[s], l.strength[s]) = (l.u[s] + 6.0, w, strength);
            }
            for s in 28 + widths.len()..28 + widths.len() + 3 {
                l.clear(s);
            }
            l
        };
        let mut l = with_run(&tail, 30.0);
        let before = l.found();
        drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch);
        assert_eq!(l.found(), before - 7, "the tail is dropped");
        assert!((28..35).all(|s| !l.u[s].is_finite()));
        // As strong as the frame's line (the line's own short run, its end widened by a
        // highlight: the widest sample alone goes, as a mixed pixel), or as weak but not
        // spreading (a dim line on dark print), the run stays.
        for (widths, strength) in [(tail, 150.0), ([2.4; 7], 30.0)] {
            let mut l = with_run(&widths, strength);
            drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch);
            assert!((28..34).all(|s| l.u[s].is_finite()), "{widths:?} at strength {strength}");
        }
    }

    #[test]
    fn a_lone_stray_does_not_cut_the_line_into_runs_too_short_to_keep() {
        // The robot's real frame 62 (columns 572-579): a line 6 px wide whose rows 25 and 32
        // hold a peak of the floor 50 px off. Read as runs, the six rows between them are a
        // piece shorter than twice its width, a blob, and were dropped with the strays.
        let cfg = EdgeConfig::default();
        let mut scratch = Vec::new();
        let mut l = line(&[6.0; 60]);
        l.u[25] += 50.0;
        l.u[32] += 50.0;
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 2);
        assert!(!l.u[25].is_finite() && !l.u[32].is_finite());
        assert_eq!(l.found(), 58);
        // Where the line steps to another surface, the sample between the two is no stray: its
        // neighbours do not continue each other. It is dropped as a run of one, the two
        // surfaces' runs are kept whole.
        let mut l = line(&[6.0; 60]);
        for u in &mut l.u[30..] {
            *u += 50.0;
        }
        l.u[29] += 25.0;
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 1);
        assert!(!l.u[29].is_finite());
        assert_eq!(l.found(), 59);
        // The hard body's table line at 640x480: where it ends, two faint samples (a twentieth
        // of its strength, 2 px aside) around a stray. They are no line to join across it: the
        // stray and the faint sample beyond it go as runs of one.
        let mut l = line(&[3.0; 30]);
        for s in 27..30 {
            l.clear(s);
        }
        for s in [24, 26] {
            l.u[s] -= 2.0;
            l.strength[s] = 8.0;
        }
        l.u[25] += 150.0;
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..30, None, &mut scratch), 2);
        assert!(!l.u[25].is_finite() && !l.u[26].is_finite());
    }

    #[test]
    fn a_sample_much_wider_than_its_run_and_off_its_course_is_dropped_but_a_thin_lines_phase_is_not() {
        let cfg = EdgeConfig::default();
        let mut scratch = Vec::new();
        // Two surfaces' peaks merged into one row (3.7 px against the run's 2, its centre pulled
        // 0.6 px aside): dropped. A row 3.4 px wide is 1.7 times the median but only 1.4 px
        // more: kept. A row 3.8 px wide on the line's course (the line widening, as a real
        // line blooms on a bright floor) is kept, and so is one pulled aside by less than a
        // tenth of its width.
        let mut widths = vec![2.0; 60];
        widths[20] = 3.7;
        widths[40] = 3.4;
        widths[10] = 3.8;
        widths[50] = 3.8;
        let mut l = line(&widths);
        l.u[20] += 0.6;
        l.u[50] -= 0.3;
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 1);
        assert!(!l.u[20].is_finite() && l.found() == 59);
        assert!(l.u[40].is_finite() && l.u[10].is_finite() && l.u[50].is_finite());
        // At a run's end (no neighbour on one side) the width alone decides.
        let mut widths = vec![2.0; 60];
        widths[59] = 3.8;
        let mut l = line(&widths);
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 1);
        assert!(!l.u[59].is_finite());
        // A line under a pixel wide measures 1 to 2 px as its phase moves along the run (twice
        // its median in places): every sample kept.
        let mut l = line(&(0..60).map(|i| if i % 3 == 0 { 2.1 } else { 1.0 }).collect::<Vec<_>>());
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 0);
        assert_eq!(l.found(), 60);
    }

    #[test]
    fn a_highlight_that_crosses_a_dim_line_costs_its_own_samples_not_the_lines_run() {
        let cfg = EdgeConfig::default();
        let mut scratch = Vec::new();
        // The hard body's hair at 320x240 (frame 15, cam1): a dim line 2 px wide for 18 rows,
        // a glossy highlight across it for 8 (10 px wide, 2 px aside, four times as strong),
        // then the line again. By its mean width (4.1 px) the run read as a blob that fades out
        // at both ends (its strong body 8 samples against 2 x 4.1) and as twice the typical
        // width: all 29 rows were lost. By its median width the line is kept and only the
        // highlight's rows go.
        let mut l = line(&[2.0; 40]);
        for (i, s) in l.strength.iter_mut().enumerate() {
            *s = 20.0 + i as f32;
        }
        // No line in the last 11 rows: the run does not span the region (a run that does is
        // not judged by its length or its body).
        for i in 29..40 {
            l.clear(i);
        }
        for i in 18..26 {
            l.width[i] = 10.0;
            l.strength[i] = 100.0;
            l.u[i] += 2.0;
        }
        for typical in [None, Some(2.0)] {
            let mut k = l.clone();
            assert_eq!(drop_short_runs(&mut k, &cfg, 0..40, typical, &mut scratch), 8, "typical {typical:?}");
            assert!((0..29).all(|i| k.u[i].is_finite() != (18..26).contains(&i)), "typical {typical:?}");
        }
    }

    #[test]
    fn a_short_run_twice_as_wide_as_the_last_frames_line_is_dropped() {
        let cfg = EdgeConfig::default();
        let mut scratch = Vec::new();
        // Runs of 40 rows (under `WIDE_RUNS` times `min_run`) against a typical width of 4.8 px
        // from the last frames: 9.0 px (1.9 times, the robot's smeared line) is kept, 10.0 px
        // (2.1 times) is dropped; without a typical width both are kept, and a run of 60 rows
        // is never judged so.
        for (width, n, typical, kept) in [
            (9.0, 40, Some(4.8), true),
            (10.0, 40, Some(4.8), false),
            (10.0, 40, None, true),
            (10.0, 60, Some(4.8), true),
        ] {
            let mut l = line(&vec![width; n]);
            drop_short_runs(&mut l, &cfg, 0..n as u32, typical, &mut scratch);
            assert_eq!(l.found(), if kept { n } else { 0 }, "{width} px over {n} rows, typical {typical:?}");
        }
    }

    #[test]
    fn a_sliver_of_the_sheet_is_dropped_but_a_thin_or_a_wide_lines_or_a_dim_lines_narrower_rows_are_not() {
        let cfg = EdgeConfig::default();
        let mut scratch = Vec::new();
        // A line 2.8 px wide whose rows 20-24 see a sliver of the sheet cut by an edge (1.1 px):
        // dropped. Rows 1.8 px wide (0.64 of the median) are kept.
        let mut widths = vec![2.8; 60];
        widths[20..25].fill(1.1);
        widths[40] = 1.8;
        let mut l = line(&widths);
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 5);
        assert!((20..25).all(|i| !l.u[i].is_finite()) && l.u[40].is_finite() && l.found() == 55);
        // A thin line's phase (1 to 2 px along the run, median 2): kept.
        let mut l = line(&(0..60).map(|i| if i % 3 == 0 { 1.0 } else { 2.0 }).collect::<Vec<_>>());
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 0);
        // A wide saturated line (12 px) measured 5 px where only its top stands above a
        // shoulder: kept (wider than `narrow_width_px`, no sliver).
        let mut widths = vec![12.0; 60];
        widths[30..33].fill(5.0);
        let mut l = line(&widths);
        assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), 0);
        // A dim line on dark print (rows 20-31 at a fifth of the run's strength, 1.4 px in a
        // saturated run of 2.8) stays on the line's course: kept. The same rows 0.8 px off that
        // course (a faint sliver's centre) are dropped, and so are such rows at the run's end,
        // with no course beyond them.
        for (rows, shift, dropped) in [(20..32, 0.0, 0), (20..32, 0.8, 12), (52..60, 0.0, 8)] {
            let mut l = weak_stretch(rows, 1.4, shift);
            assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), dropped, "shift {shift}");
        }
    }

    #[test]
    fn a_weak_stretch_off_the_course_of_the_strong_line_is_dropped() {
        let cfg = EdgeConfig::default();
        let mut scratch = Vec::new();
        // Rows 20-31 of a run 2.8 px wide at a fifth of its strength, as wide as the run (no
        // sliver): 0.5 px off the strong line's course is kept (a dim line on a darker
        // surface), 1 px off is dropped (the sheet's tail on a surface off the sheet). The same
        // stretch at the run's end (no strong course beyond it): kept.
        for (rows, shift, dropped) in [(20..32, 0.5, 0), (20..32, 1.0, 12), (48..60, 1.0, 0)] {
            let mut l = weak_stretch(rows, 2.8, shift);
            assert_eq!(drop_short_runs(&mut l, &cfg, 0..60, None, &mut scratch), dropped, "shift {shift}");
        }
    }
}
