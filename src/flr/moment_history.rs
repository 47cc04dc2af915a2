//! Temporal FLR on accumulated cell moments: the history is FLR's block
//! moments, not the light, so that a frame costs one FLR plus one pass over
//! the cells (`docs/METHODS.md`, Temporal FLR).
//!
//! A frame runs FLR's [`Stage::Prepare`], [`Stage::Moments`] and
//! [`Stage::Stats`]; then four passes over the tiles:
//! - **find**: each cell's mean motion (over its middle pixel row), and
//!   whether any history tap is kept for it: the previous frame's cells
//!   sampled bilinearly there, a tap kept where its mean normal and depth
//!   match the cell's ([`TapTest`]). When more than `cut_fraction` of the
//!   cells keep none, the frame is a camera cut and every cell restarts;
//! - **blend**: the kept taps moved into this frame's guide references,
//!   their depth rescaled to the cell's, and blended with the cell as a
//!   running mean over up to `max_history` frames; the cell's pixel count
//!   and luminance sum also as a running mean over up to
//!   [`LAG_FAST_HISTORY`] frames (the fast history);
//! - **lag**: where the light changed, the history lags it: a cell whose
//!   fast history's mean luminance differs from the history's by more than
//!   `lag_sigmas` standard errors ([`TemporalConfig::lag_sigmas`]), over
//!   its 3×3 cells ([`lags`]), is marked (skipped on a frame that does not
//!   blend);
//! - **commit**: a marked cell restarts from its own moments; the history
//!   written, the fit's cells made the sums over its frames, the pooled
//!   window summed again;
//!
//! then FLR's remaining stages. The adaptive window counts up to
//! `max_history` samples per pixel in its variances.
//!
//! The caller-owned [`History`] holds two slots (the previous frame's, and
//! the one this frame writes), each the frame's guide references and, per
//! cell, its moments (a running mean, relative to the references), its
//! history length, its mean guides and its fast history (pixel count and
//! luminance sum). The values are f64, stored as two
//! 32-bit words each in the history's f32 buffer (bit patterns, never used
//! as f32).

use core::sync::atomic::{AtomicU32, Ordering};

use super::schedule::Stage;
use super::{Flr, FlrConfig, Stats};
use crate::error::{Arg, Error};
use crate::guides::{Frame, MAX_GUIDES};
use crate::history::History;
use crate::image::{ImageView, ImageViewMut};
use crate::kernels::{CellLayout, LUMA};
use crate::parallel::{run_tiles, Executor};
use crate::report::Report;
use crate::temporal::TemporalConfig;

/// Smallest cosine between the mean normals of a cell and a history tap.
pub const NORMAL_LIMIT: f64 = 0.8;
/// Largest relative difference between the mean depths of a cell and a history tap.
pub const DEPTH_LIMIT: f64 = 0.1;
/// The fast history's longest length, in frames (the lag test's reference).
pub const LAG_FAST_HISTORY: f64 = 2.0;

/// f64 value `i` of a history slot stored as two words.
#[inline]
fn get(words: &[u32], i: usize) -> f64 {
    f64::from_bits(u64::from(words[2 * i]) | (u64::from(words[2 * i + 1]) << 32))
}
/// Stores f64 value `i` of a history slot as two words.
#[inline]
fn put(words: &mut [u32], i: usize, v: f64) {
    let b = v.to_bits();
    words[2 * i] = b as u32;
    words[2 * i + 1] = (b >> 32) as u32;
}

/// The f64 values stored as word pairs in `words`, in order (as [`get`]
/// reads them; one bounds check for the slice instead of one per value).
#[inline]
fn values(words: &[u32]) -> impl Iterator<Item = f64> + '_ {
    words.chunks_exact(2).map(|p| f64::from_bits(u64::from(p[0]) | (u64::from(p[1]) << 32)))
}

/// Stores `vals` as word pairs from the start of `words` (as [`put`] does),
/// as many as both hold.
#[inline]
fn store(words: &mut [u32], vals: &[f64]) {
    for (p, v) in words.chunks_exact_mut(2).zip(vals) {
        let b = v.to_bits();
        (p[0], p[1]) = (b as u32, (b >> 32) as u32);
    }
}

/// The words of record `i` (`rec` values from value `i · rec`).
#[inline]
fn record(words: &[u32], i: usize, rec: usize) -> &[u32] {
    &words[2 * i * rec..2 * (i + 1) * rec]
}

/// The moments of `g' = a g + b` (per guide) from the moments of `g`, in
/// place: exact, since every moment is a polynomial of degree ≤ 2 in `g`.
/// `n`, the light sums and the energy do not change.
pub(crate) fn affine(cell: &mut [f64], lay: &CellLayout, a: &[f64], b: &[f64]) {
    let q = lay.q;
    let n = cell[0];
    let mut s = [0f64; MAX_GUIDES];
    s[..q].copy_from_slice(&cell[lay.s..lay.s + q]);
    let t = [cell[lay.t], cell[lay.t + 1], cell[lay.t + 2]];
    let mut p = lay.ss;
    for i in 0..q {
        for j in i..q {
            cell[p] = a[i] * a[j] * cell[p] + a[i] * b[j] * s[i] + b[i] * a[j] * s[j] + b[i] * b[j] * n;
            p += 1;
        }
    }
    for i in 0..q {
        cell[lay.s + i] = a[i] * s[i] + b[i] * n;
        for (c, tc) in t.iter().enumerate() {
            let at = lay.p + 3 * i + c;
            cell[at] = a[i] * cell[at] + b[i] * tc;
        }
    }
}

/// A cell's mean guides in raw units (`s / n + reference`); `None` for an empty cell.
pub(crate) fn mean_guides(cell: &[f64], lay: &CellLayout, reference: &[f32]) -> Option<[f64; MAX_GUIDES]> {
    let n = cell[0];
    if n.is_nan() || n <= 0.0 {
        return None;
    }
    let mut m = [0f64; MAX_GUIDES];
    for (i, v) in m.iter_mut().enumerate().take(lay.q) {
        *v = cell[lay.s + i] / n + reference[i] as f64;
    }
    Some(m)
}

/// How a history tap is judged against the current cell: the cosine between
/// their mean normals (guides 0..3) and the relative difference of their mean
/// depths (guide `depth`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TapTest {
    pub normal_limit: f64,
    pub depth_limit: f64,
    /// The depth's guide index, if the guides have one.
    pub depth: Option<usize>,
}

impl TapTest {
    /// Whether a tap whose mean guides are `tap` may feed a cell whose mean
    /// guides are `cur` (guides 0..3 are the normal).
    pub(crate) fn accepts(&self, cur: &[f64; MAX_GUIDES], tap: &[f64; MAX_GUIDES]) -> bool {
        let norm = |v: &[f64; MAX_GUIDES]| crate::kernels::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        let (nc, nt) = (norm(cur), norm(tap));
        if nc < 1e-6 && nt < 1e-6 {
            // no geometry on both sides: sky continues sky
            return true;
        }
        let dot = cur[0] * tap[0] + cur[1] * tap[1] + cur[2] * tap[2];
        if !(nc > 0.0 && nt > 0.0 && dot >= self.normal_limit * nc * nt) {
            return false;
        }
        match self.depth {
            Some(d) => (tap[d] - cur[d]).abs() <= self.depth_limit * cur[d].abs(),
            None => true,
        }
    }
}

/// One cell of the reprojected history. `prev` holds the previous frame's
/// cell records (`rec` f64 each, stored as word pairs: `lay.k` moments, the
/// history length, `lay.q` mean guides, NaN for an empty cell) on a
/// `grid` (cells across × down); they are sampled bilinearly at the cell
/// `at` moved by `motion` (previous − current, in cells), the taps of
/// `kept` ([`kept_mask`]) only. Writes the kept taps'
/// weighted mean into `out` (and of their fast histories, at record offset
/// [`fast_at`], into `fast` where given) and returns their mean history
/// length (0 and zeros when no tap is kept).
#[allow(clippy::too_many_arguments)]
pub(crate) fn reproject_cell(
    prev: &[u32],
    rec: usize,
    grid: (usize, usize),
    lay: &CellLayout,
    at: (usize, usize),
    motion: (f64, f64),
    kept: u8,
    out: &mut [f64],
    mut fast: Option<&mut [f64; FAST_LEN]>,
) -> f64 {
    let k = lay.k;
    out[..k].fill(0.0);
    if let Some(f) = fast.as_deref_mut() {
        f.fill(0.0);
    }
    let (mut wsum, mut nsum) = (0f64, 0f64);
    for (i, w) in masked_taps(grid, at, motion, kept) {
        let r = record(prev, i, rec);
        for (o, v) in out[..k].iter_mut().zip(values(r)) {
            *o += w * v;
        }
        if let Some(f) = fast.as_deref_mut() {
            for (o, v) in f.iter_mut().zip(values(&r[2 * fast_at(lay)..])) {
                *o += w * v;
            }
        }
        nsum += w * get(r, k);
        wsum += w;
    }
    let kept = wsum > MIN_TAP_WEIGHT;
    let inv = 1.0 / wsum;
    for o in out[..k].iter_mut().chain(fast.into_iter().flat_map(|f| f.iter_mut())) {
        *o = if kept { *o * inv } else { 0.0 };
    }
    if kept {
        nsum * inv
    } else {
        0.0
    }
}

/// Offset of the fast history in a cell record (after the moments, the
/// length and the mean guides): its pixel count and luminance sum
/// ([`FAST_LEN`] values).
pub(crate) const fn fast_at(lay: &CellLayout) -> usize {
    lay.k + 1 + lay.q
}

/// Values of the fast history per cell: its pixel count and luminance sum.
pub(crate) const FAST_LEN: usize = 2;

/// A cell's pixel count and luminance sum, from its moments.
fn count_and_luma(cell: &[f64], lay: &CellLayout) -> [f64; FAST_LEN] {
    [cell[0], luma(|c| cell[lay.t + c])]
}

/// The luminance of the colour whose channel `c` is `rgb(c)`.
fn luma(rgb: impl Fn(usize) -> f64) -> f64 {
    (0..3).map(|c| LUMA[c] as f64 * rgb(c)).sum()
}

/// Least bilinear weight of the kept taps for a cell to keep its history.
const MIN_TAP_WEIGHT: f64 = 1e-3;

/// Whether [`reproject_cell`] with `kept` keeps the history at cell `at`
/// moved by `motion`: the kept taps' bilinear weight is above [`MIN_TAP_WEIGHT`].
pub(crate) fn keeps_history(grid: (usize, usize), at: (usize, usize), motion: (f64, f64), kept: u8) -> bool {
    masked_taps(grid, at, motion, kept).map(|(_, w)| w).sum::<f64>() > MIN_TAP_WEIGHT
}

/// The bilinear taps at cell `at` moved by `motion` (bit `j` for tap `j` of
/// [`taps`]) whose records are not empty and whose mean guides `test`
/// accepts against `cur`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn kept_mask(
    prev: &[u32],
    rec: usize,
    (cx, cy): (usize, usize),
    lay: &CellLayout,
    (x, y): (usize, usize),
    motion: (f64, f64),
    cur: &[f64; MAX_GUIDES],
    test: &TapTest,
) -> u8 {
    let accepted = |i: usize| {
        let mut tm = [0f64; MAX_GUIDES];
        for (t, v) in tm[..lay.q].iter_mut().zip(values(&record(prev, i, rec)[2 * (lay.k + 1)..])) {
            *t = v;
        }
        !tm[0].is_nan() && test.accepts(cur, &tm)
    };
    let mut mask = 0;
    for (j, tap) in taps(x, y, motion, cx, cy).into_iter().enumerate() {
        if tap.is_some_and(|(i, _)| accepted(i)) {
            mask |= 1 << j;
        }
    }
    mask
}

/// The taps (previous cell index, weight) of `kept` ([`kept_mask`]) at
/// cell `(x, y)` moved by `motion`, in [`taps`]' order.
fn masked_taps((cx, cy): (usize, usize), (x, y): (usize, usize), motion: (f64, f64), kept: u8) -> impl Iterator<Item = (usize, f64)> {
    taps(x, y, motion, cx, cy).into_iter().enumerate().filter_map(move |(j, t)| if kept >> j & 1 == 1 { t } else { None })
}

/// The 4 bilinear taps (cell index, weight) at cell `(x, y)` moved by
/// `motion`, `None` off the `cx × cy` grid (all `None` for a motion that is
/// not finite).
fn taps(x: usize, y: usize, motion: (f64, f64), cx: usize, cy: usize) -> [Option<(usize, f64)>; 4] {
    let (px, py) = (x as f64 + motion.0, y as f64 + motion.1);
    if !(px.is_finite() && py.is_finite()) {
        return [None; 4];
    }
    let (fx, fy) = (libm::floor(px), libm::floor(py));
    let (ax, ay) = (px - fx, py - fy);
    let at = |dx: f64, dy: f64, w: f64| {
        let (tx, ty) = (fx + dx, fy + dy);
        (w > 0.0 && tx >= 0.0 && ty >= 0.0 && tx < cx as f64 && ty < cy as f64).then(|| (ty as usize * cx + tx as usize, w))
    };
    [at(0.0, 0.0, (1.0 - ax) * (1.0 - ay)), at(1.0, 0.0, ax * (1.0 - ay)), at(0.0, 1.0, (1.0 - ax) * ay), at(1.0, 1.0, ax * ay)]
}

/// The reprojected history `hist` (moments relative to `prev_reference`)
/// moved into this frame's `reference`, in place: `g − ref' = (g − ref) +
/// (ref − ref')`, a map linear in the moments, so the taps' mean maps as each
/// tap would. With a `depth` guide, its moments are also scaled so that the
/// history's mean depth is the current cell's (`cur`, raw units): `d ↦ r d`,
/// `r` the ratio of the two means clamped to 0.5–2 (a dolly moves every
/// surface's depth). One affine map ([`affine`]) does both.
pub(crate) fn into_current_frame(
    hist: &mut [f64],
    lay: &CellLayout,
    prev_reference: &[f32],
    reference: &[f32],
    cur: &[f64; MAX_GUIDES],
    depth: Option<usize>,
) {
    let (mut a, mut b) = ([1f64; MAX_GUIDES], [0f64; MAX_GUIDES]);
    for (i, v) in b.iter_mut().enumerate().take(lay.q) {
        *v = prev_reference[i] as f64 - reference[i] as f64;
    }
    if let Some(d) = depth {
        let mean = hist[lay.s + d] / hist[0] + prev_reference[d] as f64;
        let r = (cur[d] / mean).clamp(0.5, 2.0);
        if mean.abs() > 1e-6 && r.is_finite() {
            // g − ref' ↦ r (g − ref) + (r − 1) ref, so that g ↦ r g
            a[d] = r;
            b[d] = r * b[d] + (r - 1.0) * reference[d] as f64;
        }
    }
    affine(hist, lay, &a, &b);
}

/// Settings of the moment history.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Blend {
    pub test: TapTest,
    /// Longest history, in frames.
    pub max_history: f64,
    /// The fast history's longest length, in frames.
    pub fast_history: f64,
    /// Standard errors past which the lag test marks a cell (0: off;
    /// [`TemporalConfig::lag_sigmas`]).
    pub lag_sigmas: f64,
}

impl Blend {
    /// The fast history's length where the slow one's is `n`.
    pub(crate) fn fast_len(&self, n: f64) -> f64 {
        n.min(self.fast_history)
    }
}

/// One cell of a frame: the current cell's moments `cell` (in this frame's
/// `reference`) blended with the previous records `prev` (in
/// `prev_reference`; see [`reproject_cell`]) reprojected at it. Writes the
/// history's new moments (the running mean of the frames' moments) into
/// `hist`, the fast history's new count and luminance sum into `fast`, and
/// returns the new length `n` and whether a history was kept (`(1, false)`,
/// and the cell's own values, when no tap was). The fast history's length
/// is [`Blend::fast_len`] of `n`. The fit takes `hist · n`, the sums over
/// `n` frames, so that its sample counts are frames × pixels. `kept`: the
/// taps to keep where already known ([`kept_mask`]), else `None`.
/// `work`: `lay.k` values of working space.
#[allow(clippy::too_many_arguments)]
pub(crate) fn blend_cell(
    cell: &[f64],
    hist: &mut [f64],
    fast: &mut [f64; FAST_LEN],
    prev: &[u32],
    rec: usize,
    grid: (usize, usize),
    lay: &CellLayout,
    at: (usize, usize),
    motion: (f64, f64),
    reference: &[f32],
    prev_reference: &[f32],
    blend: &Blend,
    kept: Option<u8>,
    work: &mut [f64],
) -> (f64, bool) {
    let k = lay.k;
    let own = count_and_luma(cell, lay);
    *fast = own;
    let Some(cur) = mean_guides(cell, lay, reference) else {
        hist[..k].copy_from_slice(&cell[..k]);
        return (1.0, false);
    };
    let mut fast_prev = [0f64; FAST_LEN];
    let kept = kept.unwrap_or_else(|| kept_mask(prev, rec, grid, lay, at, motion, &cur, &blend.test));
    let n_prev = reproject_cell(prev, rec, grid, lay, at, motion, kept, work, Some(&mut fast_prev));
    if n_prev <= 0.0 {
        hist[..k].copy_from_slice(&cell[..k]);
        return (1.0, false);
    }
    into_current_frame(&mut work[..k], lay, prev_reference, reference, &cur, blend.test.depth);
    let n = (n_prev + 1.0).min(blend.max_history);
    let w = 1.0 / n;
    for ((h, c), r) in hist[..k].iter_mut().zip(&cell[..k]).zip(&work[..k]) {
        *h = (1.0 - w) * r + w * c;
    }
    // the count and the light sums do not change with the guides' references
    let wf = 1.0 / blend.fast_len(n);
    for ((f, c), r) in fast.iter_mut().zip(own).zip(fast_prev) {
        *f = (1.0 - wf) * r + wf * c;
    }
    (n, true)
}

/// Values per cell of the lag test's inputs ([`lag_inputs`]).
pub(crate) const LAG_LEN: usize = 6;

/// The lag test's inputs from a cell record `r` (word pairs): its history
/// length, pixel count, luminance sum and energy, and its fast history's
/// count and luminance sum.
fn lag_inputs(r: &[u32], lay: &CellLayout) -> [f64; LAG_LEN] {
    let fast = fast_at(lay);
    [get(r, lay.k), get(r, 0), luma(|c| get(r, lay.t + c)), get(r, lay.e), get(r, fast), get(r, fast + 1)]
}

/// The lag test of the cell at `(x, y)`: whether its fast history's mean
/// luminance differs from its slow one's by more than `sigmas` standard
/// errors. `inputs` are this frame's cells' [`lag_inputs`] ([`LAG_LEN`]
/// each) on a `grid`; both histories are summed over the cell and its 8
/// neighbours. Both were
/// reprojected through the same taps, so reprojection error moves them
/// alike; light that changed moves the fast one first. The fast history
/// holds the slow one's newest `n_f` of `n` frames, so their difference is
/// `(1 − n_f / n)` times that of the fast frames' mean and the older ones',
/// whose standard error follows from the slow sums' luminance variance. A
/// cell whose slow history is no longer than the fast one does not lag.
pub(crate) fn lags(inputs: &[f64], (cx, cy): (usize, usize), (x, y): (usize, usize), fast_cap: f64, sigmas: f64) -> bool {
    let cell = |c: usize| &inputs[LAG_LEN * c..LAG_LEN * (c + 1)];
    let n = cell(y * cx + x)[0];
    let n_fast = n.min(fast_cap);
    if !(n > n_fast && sigmas > 0.0) {
        return false;
    }
    // over the 3×3 cells: the slow count, luminance and energy; the fast count and luminance
    let (mut ns, mut ls, mut es, mut nf, mut lf) = (0f64, 0f64, 0f64, 0f64, 0f64);
    for ty in y.saturating_sub(1)..(y + 2).min(cy) {
        for tx in x.saturating_sub(1)..(x + 2).min(cx) {
            let v = cell(ty * cx + tx);
            ns += v[1];
            ls += v[2];
            es += v[3];
            nf += v[4];
            lf += v[5];
        }
    }
    if !(ns > 0.0 && nf > 0.0) {
        return false;
    }
    let (ls, lf) = (ls / ns, lf / nf);
    let var = (es / ns - ls * ls).max(0.0);
    let older = n - n_fast;
    let se = crate::kernels::sqrt(var / ns * (older / n) * (older / n) * (1.0 / n_fast + 1.0 / older));
    let d = lf - ls;
    d.is_finite() && se.is_finite() && d.abs() > sigmas * se + 1e-9 * (ls.abs() + lf.abs())
}

/// A raw pointer the tiles of one pass share; each tile takes its own band.
#[derive(Clone, Copy)]
struct Shared<T>(*mut T);
// SAFETY: the tiles that use it take disjoint bands ([`run_tiles`] runs each
// tile once) and the pointee outlives the pass.
unsafe impl<T: Send> Sync for Shared<T> {}
// SAFETY: as for `Sync`.
unsafe impl<T: Send> Send for Shared<T> {}

impl<T> Shared<T> {
    /// `len` values at `at`.
    ///
    /// # Safety
    /// Inside the pointee, and no other live reference overlaps them.
    #[allow(clippy::mut_from_ref)]
    unsafe fn band(&self, at: usize, len: usize) -> &mut [T] {
        // SAFETY: the caller's contract.
        unsafe { core::slice::from_raw_parts_mut(self.0.add(at), len) }
    }
}

/// Temporal FLR on accumulated cell moments (the module's doc): one plan per
/// frame size and configuration. It needs the normal guide (the history's
/// taps are judged by their mean normal, and by their mean depth where the
/// guides have depth) and no joint upsampling.
#[derive(Clone, Debug)]
pub struct MomentFlr {
    /// FLR on the blended cells (variances counting up to `max_history`
    /// samples per pixel; the pooled window summed after the blend).
    flr: Flr,
    /// FLR as configured: what a single frame (`Denoiser::denoise`) runs.
    single: Flr,
    blend: Blend,
    /// A frame with more than this fraction of fresh cells is a camera cut.
    cut_fraction: f64,
}

impl MomentFlr {
    /// Plans `width × height` frames; of `temporal` it reads `max_history`,
    /// `cut_fraction` and `lag_sigmas`. [`FlrConfig::temporal_moments`] is the default
    /// configuration for it.
    pub fn new(cfg: FlrConfig, temporal: &TemporalConfig, width: usize, height: usize) -> Result<Self, Error> {
        temporal.validate()?;
        if cfg.upsample != 1 {
            return Err(Error::Unsupported("temporal FLR on moments with joint upsampling (upsample > 1)"));
        }
        if !cfg.guides.normal {
            return Err(Error::Unsupported("temporal FLR on moments needs the normal guide (taps are judged by their mean normal)"));
        }
        let max_history = temporal.max_history as f64;
        let single = Flr::new(cfg, width, height)?;
        let flr = single.with_sample_cap(max_history).without_pooling_in_moments();
        // the normal is guides 0..3, so the depth is guide 3
        let test = TapTest { normal_limit: NORMAL_LIMIT, depth_limit: DEPTH_LIMIT, depth: cfg.guides.depth.then_some(3) };
        let blend = Blend { test, max_history, fast_history: LAG_FAST_HISTORY, lag_sigmas: temporal.lag_sigmas as f64 };
        Ok(MomentFlr { flr, single, blend, cut_fraction: temporal.cut_fraction as f64 })
    }
    /// The FLR configuration it fits with.
    pub fn config(&self) -> &FlrConfig {
        self.flr.config()
    }
    /// Output size.
    pub fn size(&self) -> (usize, usize) {
        self.flr.size()
    }
    fn cells(&self) -> usize {
        let (cx, cy) = self.flr.cells();
        cx * cy
    }
    /// f64 values per cell record: moments, length, mean guides, fast history.
    fn record(&self) -> usize {
        fast_at(&self.flr.lay) + FAST_LEN
    }
    /// f64 values of one slot: the references, then the cell records.
    fn slot_len(&self) -> usize {
        MAX_GUIDES + self.cells() * self.record()
    }
    /// f32 values of the [`History`] buffer (two slots of f64 values).
    pub fn history_len(&self) -> usize {
        4 * self.slot_len()
    }
    /// f64 values of a worker's buffer: a motion row (two f32 planes), or
    /// two cells of working space.
    fn worker_len(&self) -> usize {
        self.flr.size().0.max(2 * self.flr.lay.k)
    }
    /// f64 values of the scratch of [`MomentFlr::denoise_parallel`] with
    /// `workers`: FLR's, each cell's mean motion and kept taps, its lag
    /// test's inputs, the workers' buffers.
    pub fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let own = crate::parallel::TileRun::scratch_len(self.flr.tile_count(), workers, 2 * self.worker_len())?;
        self.flr.tiled_scratch_len(workers)?.checked_add((3 + LAG_LEN) * self.cells())?.checked_add(own.div_ceil(2))
    }
    /// f64 values of the scratch of [`MomentFlr::denoise`].
    pub fn scratch_len(&self) -> usize {
        self.parallel_scratch_len(1).unwrap_or(usize::MAX)
    }

    /// One frame of the sequence on the calling thread; advances `history`
    /// (a [`History`] of [`MomentFlr::history_len`] f32: its frame count 0
    /// starts afresh). `motion` (2 channels, previous − current pixel
    /// position) may be `None` for a static camera. Allocates nothing.
    pub fn denoise(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        self.run(frame, motion, history, scratch, out, None)
    }

    /// [`MomentFlr::denoise`] with the tiles spread by the caller's executor
    /// (as [`Flr::denoise_parallel`]); the same bits.
    #[allow(clippy::too_many_arguments)]
    pub fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        if !out.rows_are_separable() {
            return Err(Error::Unsupported("a parallel run needs an output whose rows do not overlap (use the sequential call)"));
        }
        self.run(frame, motion, history, scratch, out, Some((workers, for_each)))
    }

    fn run(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        parallel: Option<(usize, Executor<'_>)>,
    ) -> Result<Report, Error> {
        if frame.sample_weights.is_some() || frame.guides_low.is_some() {
            return Err(Error::Unsupported("temporal FLR on moments with sample weights or a low-resolution guide set"));
        }
        let f = self.flr.check_frame(frame)?;
        self.flr.check_output(out)?;
        if history.data.len() != self.history_len() {
            return Err(Error::BufferTooSmall { arg: Arg::History, needed: self.history_len(), len: history.data.len() });
        }
        let (w, h) = self.flr.size();
        if let Some(m) = motion {
            if m.width() != w || m.height() != h {
                return Err(Error::SizeMismatch { arg: Arg::Motion, expected: (w, h), got: (m.width(), m.height()) });
            }
            if m.channel_count() < 2 {
                return Err(Error::ChannelCount { arg: Arg::Motion, expected: 2, got: m.channel_count() });
            }
        }
        let workers = parallel.map_or(1, |p| p.0);
        let needed = self.parallel_scratch_len(workers).ok_or(Error::InvalidConfig("workers: scratch size overflows"))?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let flr_len = self.flr.tiled_scratch_len(workers).ok_or(Error::InvalidConfig("workers: scratch size overflows"))?;
        let (flr_scratch, own) = scratch.split_at_mut(flr_len);
        let (means, own) = own.split_at_mut(3 * self.cells());
        let (lag_in, own) = own.split_at_mut(LAG_LEN * self.cells());
        let own: &mut [f32] = bytemuck::cast_slice_mut(own);
        let sequential = |n: usize, body: &(dyn Fn(usize, usize) + Sync)| (0..n).for_each(|i| body(i, 0));
        let for_each: Executor<'_> = parallel.map_or(&sequential, |p| p.1);
        let mut tiled = self.flr.tiled(flr_scratch, workers)?;
        let stages = parallel.map(|p| p.1);
        let mut rep = self.flr.run_stages(&tiled, &f, out, &Stage::ALL[..3], stages)?;
        let index = history.frames;
        {
            let (cells, pooled, stats) = tiled.cells_before_blur()?;
            let words: &mut [u32] = bytemuck::cast_slice_mut(&mut *history.data);
            rep += self.history_passes(cells, pooled, &stats, motion, words, index, means, lag_in, own, workers, for_each)?;
        }
        rep += self.flr.run_stages(&tiled, &f, out, &Stage::ALL[3..], stages)?;
        // the slots alternate with the count's parity (past u32::MAX it goes on at 2)
        history.frames = crate::temporal::next_frame(index);
        Ok(rep)
    }

    /// The history passes (the module's doc) over `cells` (this frame's
    /// block moments, relative to `stats.reference`) and the two history
    /// slots in `words`; frame `index` reads slot `(index + 1) % 2` and
    /// writes slot `index % 2`. The first pass finds each cell's mean motion
    /// and the history taps it keeps (into `means`: x, y, [`kept_mask`]) and
    /// whether it keeps any, for the cut test; the second blends and writes
    /// the history; the third runs the lag test; the fourth leaves the fit's
    /// sums in `cells` (and `pooled`).
    #[allow(clippy::too_many_arguments)]
    fn history_passes(
        &self,
        cells: &mut [f64],
        pooled: &mut [f64],
        stats: &Stats,
        motion: Option<&ImageView<'_>>,
        words: &mut [u32],
        index: u32,
        means: &mut [f64],
        lag_in: &mut [f64],
        own: &mut [f32],
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let (flr, lay, rec) = (&self.flr, self.flr.lay, self.record());
        let (cx, cy) = flr.cells();
        let k = lay.k;
        let sw = 2 * self.slot_len();
        let (s0, s1) = words.split_at_mut(sw);
        let (read, write) = if index % 2 == 1 { (&*s0, &mut s1[..sw]) } else { (&*s1, s0) };
        let prev_reference: [f32; MAX_GUIDES] = core::array::from_fn(|i| get(read, i) as f32);
        for (i, r) in stats.reference.iter().enumerate() {
            put(write, i, *r as f64);
        }
        let (prev, write) = (&read[2 * MAX_GUIDES..], &mut write[2 * MAX_GUIDES..]);
        let (tiles, wl) = (flr.tile_count(), 2 * self.worker_len());
        let (cells_at, write_at, means_at) = (Shared(cells.as_mut_ptr()), Shared(write.as_mut_ptr()), Shared(means.as_mut_ptr()));
        // a tile's cells: `cells_tile_range` of `cells`; records and means at the same cell indices
        let band = |t: usize| -> Result<(usize, usize), Error> {
            let r = flr.cells_tile_range(t)?;
            Ok((r.start / k, r.len() / k))
        };
        let (fresh, filled) = (AtomicU32::new(0), AtomicU32::new(0));
        let find = |t: usize, buf: &mut [f32]| -> Result<Report, Error> {
            let (c0, n) = band(t)?;
            // SAFETY: tile t's means, disjoint from every other tile's
            // (`cells_tile_range`); each tile runs once (`run_tiles`).
            let means_t = unsafe { means_at.band(3 * c0, 3 * n) };
            let row: &mut [f64] = bytemuck::try_cast_slice_mut(buf).map_err(|_| Error::Unsupported("a misaligned worker buffer"))?;
            let mut rep = Report::default();
            let (mut fr, mut fi) = (0u64, 0u64);
            for y in c0 / cx..(c0 + n) / cx {
                let row_means = &mut means_t[3 * (y * cx - c0)..3 * ((y + 1) * cx - c0)];
                let invalid = self.motion_means(motion, y, row, row_means)?;
                if index == 0 {
                    continue;
                }
                rep.invalid_motion += invalid;
                for x in 0..cx {
                    let c = y * cx + x;
                    let Some(cur) = mean_guides(&cells[c * k..(c + 1) * k], &lay, &stats.reference) else { continue };
                    fi += 1;
                    let m = (row_means[3 * x], row_means[3 * x + 1]);
                    let kept = kept_mask(prev, rec, (cx, cy), &lay, (x, y), m, &cur, &self.blend.test);
                    row_means[3 * x + 2] = kept as f64;
                    fr += !keeps_history((cx, cy), (x, y), m, kept) as u64;
                }
            }
            fresh.fetch_add(fr as u32, Ordering::Relaxed);
            filled.fetch_add(fi as u32, Ordering::Relaxed);
            Ok(rep)
        };
        // `find` reads `cells` shared: no band of it is borrowed mutably until it returns
        let mut rep = run_tiles(own, tiles, workers, wl, for_each, &find)?;
        let cut = index > 0 && fresh.load(Ordering::Relaxed) as f64 > self.cut_fraction * filled.load(Ordering::Relaxed) as f64;
        rep.history_resets += cut as u64;
        let blend = index > 0 && !cut;
        let rejected = AtomicU32::new(0);
        // blend: the history, its length and the fast history into this frame's records
        // (`cells` and `means` are only read until the lag pass)
        let means_read: &[f64] = means;
        let lag_at = Shared(lag_in.as_mut_ptr());
        let blend_pass = |t: usize, buf: &mut [f32]| -> Result<Report, Error> {
            let (c0, n) = band(t)?;
            // SAFETY: tile t's records and lag inputs, disjoint from every
            // other tile's; each tile runs once (`run_tiles`).
            let (write_t, lag_t) = unsafe { (write_at.band(2 * c0 * rec, 2 * n * rec), lag_at.band(LAG_LEN * c0, LAG_LEN * n)) };
            let buf: &mut [f64] = bytemuck::try_cast_slice_mut(buf).map_err(|_| Error::Unsupported("a misaligned worker buffer"))?;
            let (work, hist) = buf.split_at_mut(k);
            let hist = &mut hist[..k];
            let mut fast = [0f64; FAST_LEN];
            let mut rej = 0u64;
            for c in 0..n {
                let cell = &cells[(c0 + c) * k..(c0 + c + 1) * k];
                let (len, kept) = if blend {
                    let (x, y) = ((c0 + c) % cx, (c0 + c) / cx);
                    let m = (means_read[3 * (c0 + c)], means_read[3 * (c0 + c) + 1]);
                    blend_cell(
                        cell,
                        hist,
                        &mut fast,
                        prev,
                        rec,
                        (cx, cy),
                        &lay,
                        (x, y),
                        m,
                        &stats.reference,
                        &prev_reference,
                        &self.blend,
                        Some(means_read[3 * (c0 + c) + 2] as u8),
                        work,
                    )
                } else {
                    hist.copy_from_slice(cell);
                    fast = count_and_luma(cell, &lay);
                    (1.0, false)
                };
                if blend && !kept && cell[0] > 0.0 {
                    rej += cell[0] as u64;
                }
                let r = &mut write_t[2 * c * rec..2 * (c + 1) * rec];
                store(r, hist);
                put(r, k, len);
                store(&mut r[2 * fast_at(&lay)..], &fast);
                lag_t[LAG_LEN * c..LAG_LEN * (c + 1)].copy_from_slice(&lag_inputs(r, &lay));
            }
            rejected.fetch_add(rej as u32, Ordering::Relaxed);
            Ok(Report::default())
        };
        run_tiles(own, tiles, workers, wl, for_each, &blend_pass)?;
        // lag: each cell's verdict (over its neighbours' lag inputs) into `means`;
        // without a blend (the first frame, a cut) every record is the cell's own
        let lag_read: &[f64] = lag_in;
        let lag_pass = |t: usize, _: &mut [f32]| -> Result<Report, Error> {
            let (c0, n) = band(t)?;
            // SAFETY: tile t's means, disjoint from every other tile's; the
            // lag inputs are only read during this pass.
            let means_t = unsafe { means_at.band(3 * c0, 3 * n) };
            for c in 0..n {
                let at = ((c0 + c) % cx, (c0 + c) / cx);
                let lagging = lags(lag_read, (cx, cy), at, self.blend.fast_history, self.blend.lag_sigmas);
                means_t[3 * c] = if lagging { 1.0 } else { 0.0 };
            }
            Ok(Report::default())
        };
        let lag_tested = blend && self.blend.lag_sigmas > 0.0;
        if lag_tested {
            run_tiles(own, tiles, workers, wl, for_each, &lag_pass)?;
        }
        let (pooled_at, pooled_window) = (Shared(pooled.as_mut_ptr()), flr.pooled_window());
        let relit = AtomicU32::new(0);
        // commit: a lagging cell restarts from its own moments; the fit's sums
        let commit = |t: usize, _: &mut [f32]| -> Result<Report, Error> {
            let (c0, n) = band(t)?;
            // SAFETY: tile t's cells, records and means, disjoint from every
            // other tile's; each tile runs once (`run_tiles`).
            let (cells_t, write_t, means_t) =
                unsafe { (cells_at.band(c0 * k, n * k), write_at.band(2 * c0 * rec, 2 * n * rec), means_at.band(3 * c0, 3 * n)) };
            let mut restarts = 0u64;
            for (c, cell) in cells_t.chunks_exact_mut(k).enumerate() {
                let r = &mut write_t[2 * c * rec..2 * (c + 1) * rec];
                if lag_tested && means_t[3 * c] != 0.0 {
                    // `cell` still holds this frame's own moments
                    put(r, k, 1.0);
                    store(r, cell);
                    restarts += cell[0].max(0.0) as u64;
                } else {
                    let len = get(r, k);
                    for (v, h) in cell.iter_mut().zip(values(r)) {
                        *v = h * len;
                    }
                }
                let means = mean_guides(cell, &lay, &stats.reference).unwrap_or([f64::NAN; MAX_GUIDES]);
                store(&mut r[2 * (k + 1)..], &means[..lay.q]);
            }
            relit.fetch_add(restarts as u32, Ordering::Relaxed);
            if let Some(s) = pooled_window {
                let r = flr.window_cells_tile_range(s, t)?;
                // SAFETY: tile t's band of the pooled grid, disjoint from every other tile's.
                flr.pool_tile(t, cells_t, unsafe { pooled_at.band(r.start, r.len()) })?;
            }
            Ok(Report::default())
        };
        run_tiles(own, tiles, workers, wl, for_each, &commit)?;
        rep.history_rejected += u64::from(rejected.load(Ordering::Relaxed));
        rep.light_changed += u64::from(relit.load(Ordering::Relaxed));
        Ok(rep)
    }

    /// Cell row `y`'s mean motion in cells, `[x, y, 0]` per cell (the third
    /// value is for the find pass's kept taps), over
    /// the cell's middle pixel row (as good as all its rows on the training
    /// sequences, at an eighth of the reads; values within twice the frame's
    /// size only; NaN without any, so that the cell finds no history; 0
    /// without `motion`) into `means`; `row`:
    /// a row of working space. Returns the pixels read whose motion was left out.
    fn motion_means(&self, motion: Option<&ImageView<'_>>, y: usize, row: &mut [f64], means: &mut [f64]) -> Result<u64, Error> {
        means.fill(0.0);
        let Some(m) = motion else { return Ok(0) };
        let (w, h) = self.flr.size();
        let b = self.flr.bin;
        let buf: &mut [f32] = bytemuck::cast_slice_mut(&mut row[..w]);
        let (mx, my) = buf.split_at_mut(w);
        // motion beyond twice the frame's size is as unusable as NaN
        let limit = 2.0 * w.max(h) as f32;
        let py = y * b + (((y + 1) * b).min(h) - y * b) / 2;
        let missing = Error::SizeMismatch { arg: Arg::Motion, expected: (w, h), got: (m.width(), m.height()) };
        m.read_row_n(py, 0, [&mut mx[..w], &mut my[..w]]).ok_or(missing)?;
        let mut invalid = 0u64;
        for (cell, (xs, ys)) in means.chunks_exact_mut(3).zip(mx.chunks(b).zip(my.chunks(b))) {
            let (mut sx, mut sy, mut n) = (0f32, 0f32, 0usize);
            for (&a, &c) in xs.iter().zip(ys) {
                let ok = a.abs() <= limit && c.abs() <= limit;
                sx += if ok { a } else { 0.0 };
                sy += if ok { c } else { 0.0 };
                n += ok as usize;
            }
            invalid += (xs.len() - n) as u64;
            if n > 0 {
                // pixels → cells
                let scale = 1.0 / (n * b) as f64;
                (cell[0], cell[1]) = (sx as f64 * scale, sy as f64 * scale);
            } else {
                // no usable vector: the cell finds no history
                (cell[0], cell[1]) = (f64::NAN, f64::NAN);
            }
        }
        Ok(invalid)
    }
}

crate::denoiser::single_frame_is_flr!(MomentFlr);

impl crate::TemporalDenoiser for MomentFlr {
    fn history_len(&self) -> usize {
        MomentFlr::history_len(self)
    }
    fn temporal_scratch_len(&self) -> usize {
        self.scratch_len()
    }
    fn denoise_temporal(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        self.denoise(frame, motion, history, scratch, out)
    }
    fn temporal_parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        self.parallel_scratch_len(workers)
    }
    fn denoise_temporal_parallel(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        self.denoise_parallel(frame, motion, history, scratch, out, workers, for_each)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;
    use std::{vec, vec::Vec};

    /// The moments of pixels `(g, y)` in the library's layout, in f64.
    fn moments(px: &[([f64; 5], [f64; 3])], lay: &CellLayout) -> Vec<f64> {
        let mut m = vec![0f64; lay.k];
        for (g, y) in px {
            m[0] += 1.0;
            let mut p = lay.ss;
            for i in 0..lay.q {
                m[lay.s + i] += g[i];
                for j in i..lay.q {
                    m[p] += g[i] * g[j];
                    p += 1;
                }
                for c in 0..3 {
                    m[lay.p + 3 * i + c] += g[i] * y[c];
                }
            }
            for c in 0..3 {
                m[lay.t + c] += y[c];
            }
            let l = 0.2126 * y[0] + 0.7152 * y[1] + 0.0722 * y[2];
            m[lay.e] += l * l;
        }
        m
    }

    fn pixels(seed: u64, n: usize) -> Vec<([f64; 5], [f64; 3])> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut r = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n).map(|_| (core::array::from_fn(|_| 4.0 * r() - 2.0), core::array::from_fn(|_| r()))).collect()
    }

    /// Cell records as the history stores them (`reproject_cell`'s `prev`).
    /// The fast history is the cell's own count and luminance sum.
    fn records(cells: &[Vec<f64>], lengths: &[f64], lay: &CellLayout, reference: &[f32]) -> Vec<u32> {
        let rec = fast_at(lay) + FAST_LEN;
        let mut w = vec![0u32; 2 * rec * cells.len()];
        for (c, (m, n)) in cells.iter().zip(lengths).enumerate() {
            let means = mean_guides(m, lay, reference).unwrap_or([f64::NAN; MAX_GUIDES]);
            for (j, v) in m.iter().chain([*n].iter()).chain(means[..lay.q].iter()).chain(count_and_luma(m, lay).iter()).enumerate() {
                put(&mut w, c * rec + j, *v);
            }
        }
        w
    }

    /// Records of a 3×3 grid after `n` frames of light `gain(f)` (per frame
    /// `f`; each cell and frame its own noise): per cell, the history (the
    /// mean of the `n` frames' moments) and the fast one (of the last 2).
    fn lag_records(n: usize, gain: impl Fn(usize) -> f64, lay: &CellLayout) -> Vec<u32> {
        let rec = fast_at(lay) + FAST_LEN;
        let mut w = vec![0u32; 2 * rec * 9];
        for c in 0..9 {
            let frame = |f: usize| {
                let px: Vec<_> = pixels((100 * c + f) as u64, 64)
                    .into_iter()
                    .map(|(g, y)| {
                        // light that varies with guide 0, and 1-spp-like noise
                        let l = gain(f) * (1.0 + 0.2 * g[0]) * (0.2 + 1.6 * y[0]);
                        (g, [l, l, l])
                    })
                    .collect();
                moments(&px, lay)
            };
            let (mut slow, mut fast) = (vec![0f64; lay.k], vec![0f64; lay.k]);
            for f in 0..n {
                let m = frame(f);
                slow.iter_mut().zip(&m).for_each(|(s, v)| *s += v / n as f64);
                if f + 2 >= n {
                    fast.iter_mut().zip(&m).for_each(|(s, v)| *s += v / 2.0);
                }
            }
            let fast = count_and_luma(&fast, lay);
            for (j, v) in slow.iter().chain([n as f64].iter()).chain([0f64; MAX_GUIDES][..lay.q].iter()).chain(fast.iter()).enumerate() {
                put(&mut w, c * rec + j, *v);
            }
        }
        w
    }

    /// The lag test: no lag where the light holds (the fast history differs
    /// from the slow one by noise); a lag where it brightened by 30 % two
    /// frames ago; none while the slow history is no longer than the fast
    /// one, or with the test off.
    #[test]
    fn the_lag_test_marks_light_that_changed_only() {
        let lay = CellLayout::new(5);
        let rec = fast_at(&lay) + FAST_LEN;
        let inputs = |w: &[u32]| -> Vec<f64> { (0..9).flat_map(|c| lag_inputs(record(w, c, rec), &lay)).collect() };
        let lag = |w: &[u32], sigmas: f64| lags(&inputs(w), (3, 3), (1, 1), 2.0, sigmas);
        let steady = lag_records(16, |_| 1.0, &lay);
        assert!(!lag(&steady, 3.0));
        let brighter = lag_records(16, |f| if f >= 14 { 1.3 } else { 1.0 }, &lay);
        assert!(lag(&brighter, 3.0));
        assert!(!lag(&brighter, 0.0));
        assert!(!lag(&lag_records(2, |f| if f >= 1 { 1.3 } else { 1.0 }, &lay), 3.0));
        // at the grid's corner: its 2×2 cells
        assert!(lags(&inputs(&brighter), (3, 3), (0, 0), 2.0, 3.0));
        assert!(!lags(&inputs(&steady), (3, 3), (2, 2), 2.0, 3.0));
    }

    /// The affine map equals the moments of the mapped guides, on awkward
    /// scales and offsets (large offsets, a negative and a zero scale).
    #[test]
    fn affine_equals_moments_of_mapped_guides() {
        let lay = CellLayout::new(5);
        for seed in 0..8 {
            let px = pixels(seed, 37);
            let a = [1.0, -0.5, 3.0, 0.0, 1e-3];
            let b = [0.0, 1e3, -2.0, 7.0, -1e4];
            let mapped: Vec<_> = px.iter().map(|(g, y)| (core::array::from_fn(|i| a[i] * g[i] + b[i]), *y)).collect();
            let mut m = moments(&px, &lay);
            affine(&mut m, &lay, &a, &b);
            let want = moments(&mapped, &lay);
            for (i, (x, y)) in m.iter().zip(&want).enumerate() {
                assert!((x - y).abs() <= 1e-9 * y.abs().max(1.0), "seed {seed} moment {i}: {x} against {y}");
            }
        }
    }

    /// A static camera keeps every cell's history; a tap whose mean normal
    /// turned away, or whose depth moved by more than the limit, is dropped;
    /// a motion off the grid or NaN finds none.
    #[test]
    fn reprojection_keeps_matching_taps_only() {
        let lay = CellLayout::new(5);
        let (cx, cy) = (3, 2);
        let cell = |normal: [f64; 3], depth: f64| {
            let px: Vec<_> = (0..64).map(|i| ([normal[0], normal[1], normal[2], depth, 0.5], [0.1 * (i % 8) as f64, 0.2, 0.3])).collect();
            moments(&px, &lay)
        };
        let up = cell([0.0, 1.0, 0.0], 2.0);
        let cells: Vec<_> = (0..cx * cy)
            .map(|i| match i {
                4 => cell([1.0, 0.0, 0.0], 2.0),
                5 => cell([0.0, 1.0, 0.0], 3.0),
                _ => up.clone(),
            })
            .collect();
        let lengths = [4f64, 5.0, 6.0, 7.0, 8.0, 9.0];
        let reference = [0f32; MAX_GUIDES];
        let prev = records(&cells, &lengths, &lay, &reference);
        let rec = fast_at(&lay) + FAST_LEN;
        let test = TapTest { normal_limit: 0.8, depth_limit: 0.1, depth: Some(3) };
        let cur = mean_guides(&up, &lay, &reference).unwrap();
        let mut out = vec![0f64; lay.k];
        let at = |c, motion, out: &mut [f64]| {
            let kept = kept_mask(&prev, rec, (cx, cy), &lay, c, motion, &cur, &test);
            reproject_cell(&prev, rec, (cx, cy), &lay, c, motion, kept, out, None)
        };
        let n = at((1, 0), (0.0, 0.0), &mut out);
        assert_eq!(n, 5.0);
        assert!(out.iter().zip(&up).all(|(a, b)| (a - b).abs() < 1e-12));
        // halfway to cell 4 (normal turned): only the kept taps, renormalised
        let n = at((1, 0), (0.0, 0.5), &mut out);
        assert_eq!(n, 5.0);
        // towards cell 5 (depth 3 against 2): dropped too
        let n = at((2, 0), (0.0, 1.0), &mut out);
        assert_eq!(n, 0.0);
        assert!(out.iter().all(|&v| v == 0.0));
        for motion in [(-5.0, 0.0), (f64::NAN, 0.0), (0.0, f64::INFINITY)] {
            assert_eq!(at((0, 0), motion, &mut out), 0.0);
        }
    }

    /// A static cell's history is the running mean of its frames' moments
    /// (the mean of all while fewer than `max_history`), its length counts the
    /// frames up to the cap; a frame whose references moved reads the same
    /// history; a cell whose
    /// normal turned restarts.
    #[test]
    fn a_static_cell_averages_its_frames() {
        let lay = CellLayout::new(5);
        let blend = Blend {
            test: TapTest { normal_limit: 0.8, depth_limit: 0.1, depth: Some(3) },
            max_history: 4.0,
            fast_history: 2.0,
            lag_sigmas: 3.0,
        };
        let rec = fast_at(&lay) + FAST_LEN;
        let frame = |f: u64, reference: &[f32; MAX_GUIDES]| {
            let px: Vec<([f64; 5], [f64; 3])> = (0..64)
                .map(|i| {
                    let g = [0.0, 1.0, 0.0, 2.0 + 0.001 * i as f64, 0.5];
                    (core::array::from_fn(|q| g[q] - reference[q] as f64), [0.1 + 0.01 * ((i + f as usize) % 7) as f64, 0.2, 0.3])
                })
                .collect();
            moments(&px, &lay)
        };
        let refs = [[0f32; MAX_GUIDES], [0.5, 0.25, -0.25, 1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]];
        let mut prev = records(&[frame(0, &refs[0])], &[1.0], &lay, &refs[0]);
        let mut sum = frame(0, &refs[0]);
        let mut work = vec![0f64; lay.k];
        for f in 1..6u64 {
            let (r, pr) = (&refs[f as usize % 2], &refs[(f as usize - 1) % 2]);
            let cell = frame(f, r);
            let (mut hist, mut fast) = (vec![0f64; lay.k], [0f64; FAST_LEN]);
            let (n, _) =
                blend_cell(&cell, &mut hist, &mut fast, &prev, rec, (1, 1), &lay, (0, 0), (0.0, 0.0), r, pr, &blend, None, &mut work);
            assert_eq!(n, (f as f64 + 1.0).min(4.0), "frame {f}");
            // the light sums do not depend on the references: the mean of the frames' while n counts every frame
            let m = frame(f, r);
            for c in 0..3 {
                sum[lay.t + c] += m[lay.t + c];
            }
            if f < 4 {
                let want = sum[lay.t] / (f as f64 + 1.0);
                assert!((hist[lay.t] - want).abs() < 1e-12, "frame {f}: {} against {want}", hist[lay.t]);
            }
            // the mean guides are this frame's
            let (mh, mc) = (mean_guides(&hist, &lay, r).unwrap(), mean_guides(&m, &lay, r).unwrap());
            assert!((mh[3] - mc[3]).abs() < 1e-9 && (mh[1] - 1.0).abs() < 1e-12, "frame {f}");
            prev = records(&[hist], &[n], &lay, r);
        }
        // a cell whose normal turned restarts from its own moments
        let px: Vec<([f64; 5], [f64; 3])> = (0..64).map(|_| ([1.0, 0.0, 0.0, 2.0, 0.5], [0.4, 0.4, 0.4])).collect();
        let cell = moments(&px, &lay);
        let own = cell.clone();
        let (mut hist, mut fast) = (vec![0f64; lay.k], [0f64; FAST_LEN]);
        let n = blend_cell(
            &cell,
            &mut hist,
            &mut fast,
            &prev,
            rec,
            (1, 1),
            &lay,
            (0, 0),
            (0.0, 0.0),
            &refs[0],
            &refs[1],
            &blend,
            None,
            &mut work,
        );
        assert_eq!(n, (1.0, false));
        assert_eq!(hist, own);
    }

    struct Scene {
        w: usize,
        h: usize,
        normal: Vec<f32>,
        depth: Vec<f32>,
        ao: Vec<f32>,
        clean: Vec<f32>,
    }

    fn scene(w: usize, h: usize, flip: bool) -> Scene {
        let n = w * h;
        let left = |i: usize| (i % w) < w / 2;
        let normal = (0..n)
            .flat_map(|i| match (left(i), flip) {
                (true, false) => [0.0, 1.0, 0.0],
                (false, false) => [0.6, 0.0, 0.8],
                (true, true) => [0.0, -1.0, 0.0],
                (false, true) => [-0.6, 0.0, -0.8],
            })
            .collect();
        let depth = (0..n).map(|i| 2.0 + 0.01 * (i / w) as f32).collect();
        let ao = (0..n).map(|i| 0.6 + 0.3 * ((i % w) as f32 / w as f32)).collect();
        let clean = (0..3 * n).map(|i| if left(i / 3) { 0.5 } else { 0.2 } * (1.0 + 0.1 * (i % 3) as f32)).collect();
        Scene { w, h, normal, depth, ao, clean }
    }

    fn noisy(s: &Scene, seed: u64) -> Vec<f32> {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        s.clean
            .iter()
            .map(|v| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                v * 2.0 * ((x >> 40) as f32 / (1u64 << 24) as f32)
            })
            .collect()
    }

    fn frame<'a>(s: &'a Scene, noisy: &'a [f32]) -> Frame<'a> {
        use crate::guides::Guides;
        let (w, h) = (s.w, s.h);
        let g = Guides {
            normal: Some(ImageView::interleaved(&s.normal, w, h, 3).unwrap()),
            depth: Some(ImageView::interleaved(&s.depth, w, h, 1).unwrap()),
            ao: Some(ImageView::interleaved(&s.ao, w, h, 1).unwrap()),
            ..Default::default()
        };
        Frame::new(ImageView::interleaved(noisy, w, h, 3).unwrap(), g)
    }

    fn mse(a: &[f32], b: &[f32]) -> f64 {
        a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / a.len() as f64
    }

    /// The first frame, and a frame after a camera cut, are FLR's bit for bit
    /// (the sample cap is a power of two); a static camera's frames average,
    /// so that the eighth frame's error is well under FLR's on that frame.
    #[test]
    fn static_frames_average_and_a_cut_restarts() {
        let (w, h) = (64, 48);
        let (st, flipped) = (scene(w, h, false), scene(w, h, true));
        let cfg = FlrConfig::default();
        let (mf, flr) = (MomentFlr::new(cfg, &TemporalConfig::default(), w, h).unwrap(), Flr::new(cfg, w, h).unwrap());
        let (mut data, mut scratch) = (vec![0f32; mf.history_len()], vec![0f64; mf.scratch_len()]);
        let mut history = History::new(&mut data);
        let mut fs = vec![0f64; flr.scratch_len()];
        let (mut out, mut single) = (vec![0f32; 3 * w * h], vec![0f32; 3 * w * h]);
        let motion = vec![0f32; 2 * w * h];
        let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
        for k in 0..8u64 {
            let n = noisy(&st, k);
            let f = frame(&st, &n);
            let rep =
                mf.denoise(&f, Some(&mv), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
            assert_eq!((rep.history_resets, rep.history_rejected, rep.invalid_motion), (0, 0, 0));
            flr.denoise(&f, &mut fs, &mut ImageViewMut::interleaved(&mut single, w, h, 3).unwrap()).unwrap();
            if k == 0 {
                assert!(out.iter().zip(&single).all(|(a, b)| a.to_bits() == b.to_bits()), "the first frame is FLR's");
            }
        }
        assert_eq!(history.frames(), 8);
        let (m, s) = (mse(&out, &st.clean), mse(&single, &st.clean));
        assert!(m < 0.5 * s, "eight frames: {m:.3e} against FLR's {s:.3e}");
        // every normal turned: a cut
        let n = noisy(&flipped, 99);
        let f = frame(&flipped, &n);
        let rep =
            mf.denoise(&f, Some(&mv), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
        assert_eq!(rep.history_resets, 1);
        flr.denoise(&f, &mut fs, &mut ImageViewMut::interleaved(&mut single, w, h, 3).unwrap()).unwrap();
        assert!(out.iter().zip(&single).all(|(a, b)| a.to_bits() == b.to_bits()), "after a cut: FLR's");
    }

    /// A panning sequence (awkward sizes, one to three workers on real
    /// threads, with a pooled window and without): the parallel runs give
    /// the sequential run's bits, frame after frame.
    #[test]
    fn threads_give_the_sequential_bits() {
        use crate::flr::config::Blur;
        for (w, h) in [(37, 29), (129, 70)] {
            let st = scene(w, h, false);
            let motion: Vec<f32> = (0..w * h).flat_map(|i| [1.5 + 0.01 * (i % 7) as f32, -0.25]).collect();
            let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
            for blur in [Blur::Gaussian { sigma: 6.0, radius: None }, FlrConfig::temporal().blur] {
                let cfg = FlrConfig { blur, block: 4, ..FlrConfig::default() };
                let mf = MomentFlr::new(cfg, &TemporalConfig::default(), w, h).unwrap();
                let mut want: Vec<Vec<f32>> = Vec::new();
                for workers in 1..=3usize {
                    let mut data = vec![0f32; mf.history_len()];
                    let mut history = History::new(&mut data);
                    let mut scratch = vec![0f64; mf.parallel_scratch_len(workers).unwrap()];
                    let mut out = vec![0f32; 3 * w * h];
                    for k in 0..4u64 {
                        let n = noisy(&st, k);
                        let f = frame(&st, &n);
                        let mut o = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                        if workers == 1 {
                            mf.denoise(&f, Some(&mv), &mut history, &mut scratch, &mut o).unwrap();
                            want.push(out.clone());
                        } else {
                            let exec = |count: usize, body: &(dyn Fn(usize, usize) + Sync)| {
                                std::thread::scope(|sc| {
                                    for wk in 0..workers {
                                        sc.spawn(move || (wk..count).step_by(workers).for_each(|i| body(i, wk)));
                                    }
                                })
                            };
                            mf.denoise_parallel(&f, Some(&mv), &mut history, &mut scratch, &mut o, workers, &exec).unwrap();
                            let same = out.iter().zip(&want[k as usize]).all(|(a, b)| a.to_bits() == b.to_bits());
                            assert!(same, "{w}x{h} {blur:?}: {workers} workers, frame {k}");
                        }
                    }
                }
            }
        }
    }

    /// A history of another size, a motion image of another size and a
    /// short scratch are refused with typed errors; NaN, infinite and absurd
    /// motion vectors are left out and counted, and the output stays finite.
    #[test]
    fn bad_history_and_motion() {
        let (w, h) = (40, 24);
        let st = scene(w, h, false);
        let n = noisy(&st, 1);
        let f = frame(&st, &n);
        let mf = MomentFlr::new(FlrConfig::temporal_moments(), &TemporalConfig::default(), w, h).unwrap();
        let other = MomentFlr::new(FlrConfig::temporal_moments(), &TemporalConfig::default(), w, h + 8).unwrap();
        let mut out = vec![0f32; 3 * w * h];
        let mut scratch = vec![0f64; mf.scratch_len()];
        let mut wrong = vec![0f32; other.history_len()];
        let e =
            mf.denoise(&f, None, &mut History::new(&mut wrong), &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap());
        assert!(matches!(e, Err(Error::BufferTooSmall { arg: Arg::History, .. })), "{e:?}");
        let mut data = vec![0f32; mf.history_len()];
        let mut history = History::new(&mut data);
        let small = vec![0f32; 2 * w * (h - 1)];
        let sv = ImageView::interleaved(&small, w, h - 1, 2).unwrap();
        let e = mf.denoise(&f, Some(&sv), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap());
        assert!(matches!(e, Err(Error::SizeMismatch { arg: Arg::Motion, .. })), "{e:?}");
        let mut short = vec![0f64; mf.scratch_len() - 1];
        let e = mf.denoise(&f, None, &mut history, &mut short, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap());
        assert!(matches!(e, Err(Error::ScratchTooSmall { .. })), "{e:?}");
        assert_eq!(history.frames(), 0, "a refused frame leaves the history alone");
        let bad = [f32::NAN, f32::INFINITY, 1e30, -1e9];
        let motion: Vec<f32> = (0..w * h).flat_map(|i| if i % 5 == 0 { [bad[i % 4], 0.0] } else { [0.5, 0.0] }).collect();
        let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
        for k in 0..3 {
            let rep =
                mf.denoise(&f, Some(&mv), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
            // with a history, the vectors read (each cell row's middle pixel row: 4, 12, 20) are counted
            let want = if k == 0 { 0 } else { (0..w * h).filter(|i| i % 5 == 0 && (i / w) % 8 == 4).count() as u64 };
            assert_eq!((rep.invalid_motion, rep.history_resets), (want, 0));
        }
        assert!(out.iter().all(|v| v.is_finite()));
        // no usable vector anywhere: no cell keeps its history, a cut
        let nan = vec![f32::NAN; 2 * w * h];
        let nv = ImageView::interleaved(&nan, w, h, 2).unwrap();
        let rep =
            mf.denoise(&f, Some(&nv), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
        assert_eq!(rep.history_resets, 1);
        assert!(out.iter().all(|v| v.is_finite()));
        // a one-channel motion image is refused by its channel count
        let one = vec![0f32; w * h];
        let ov = ImageView::interleaved(&one, w, h, 1).unwrap();
        let e = mf.denoise(&f, Some(&ov), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap());
        assert!(matches!(e, Err(Error::ChannelCount { arg: Arg::Motion, expected: 2, got: 1 })), "{e:?}");
    }

    /// Moving a history into the current frame gives the moments of its
    /// pixels measured from the current references, with its mean depth
    /// scaled onto the current cell's and the other guides unchanged.
    #[test]
    fn a_history_moves_into_the_current_frame() {
        let lay = CellLayout::new(5);
        let (prev_reference, reference) = ([0.25f32, 0.5, -0.5, 1.5, 0.5], [-0.1f32, 0.2, 0.3, 2.5, 0.4]);
        let px: Vec<_> = (0..64).map(|i| ([0.0, 1.0, 0.0, 2.0 + 0.01 * i as f64, 0.5], [0.2, 0.2, 0.2])).collect();
        let from = |r: &[f32; 5], scale: f64| -> Vec<([f64; 5], [f64; 3])> {
            px.iter().map(|(g, y)| (core::array::from_fn(|i| if i == 3 { scale * g[i] } else { g[i] } - r[i] as f64), *y)).collect()
        };
        let mut hist = moments(&from(&prev_reference, 1.0), &lay);
        let mut cur = mean_guides(&hist, &lay, &prev_reference).unwrap();
        // without depth: only the references move
        let mut shifted = hist.clone();
        into_current_frame(&mut shifted, &lay, &prev_reference, &reference, &cur, None);
        let want = moments(&from(&reference, 1.0), &lay);
        assert!(shifted.iter().zip(&want).all(|(a, b)| (a - b).abs() <= 1e-9 * b.abs().max(1.0)), "{shifted:?}\n{want:?}");
        // with depth: the depth scaled by 1.1, exactly the moments of the scaled pixels
        cur[3] *= 1.1;
        into_current_frame(&mut hist, &lay, &prev_reference, &reference, &cur, Some(3));
        let want = moments(&from(&reference, 1.1), &lay);
        assert!(hist.iter().zip(&want).all(|(a, b)| (a - b).abs() <= 1e-9 * b.abs().max(1.0)), "{hist:?}\n{want:?}");
    }
}
