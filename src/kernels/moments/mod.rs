//! Kernel 1: per-pixel moments summed over B×B blocks (paper §3.2, eq. 12).
//!
//! Two ways in: [`moments_rows`] reads one band of `B` rows in place (row
//! slices of the caller's images, no copy; the fast path for whole blocks) and
//! [`moments_band`] reads a band already gathered into planes with a weight
//! per pixel ([`BandPlanes`]; edges, odd block sizes, sample weights, the
//! scalar oracle). With 0/1 weights both give bit-identical cells. Each block is accumulated *relative to its first
//! valid pixel* in f32 (so large guide offsets do not cancel), then shifted
//! to the frame reference in f64 and stored. With B a multiple of 8 one block
//! row maps onto `f32x8` lanes.

#[cfg(target_arch = "x86_64")]
mod avx2;

use super::{demodulation, CellLayout};
use crate::guides::MAX_GUIDES;
use crate::image::{prefetch, prefetch_l2};
use crate::isa::Isa;
use wide::f32x8;

/// Largest moment count (Q = 12).
const MAX_K: usize = super::moment_count(MAX_GUIDES);

/// A band of `rows` input rows, `width` (padded to whole blocks) pixels each,
/// as planes: `s`, the square root of the pixel's weight (1 = valid, 0 =
/// excluded; a weight `w` between counts the pixel `w` times), y0, y1, y2,
/// then one plane per guide holding `g − m` (every plane zero where `s` is).
/// The moments are the `w`-weighted sums (`Σ w`, `Σ w g`, `Σ w g y`, …): the
/// kernels scale the guides and the colours by `s`, so products carry `s²`.
#[derive(Clone, Copy, Debug)]
pub struct BandPlanes<'a> {
    /// The planes, `rows × width` values each, one after another.
    pub data: &'a [f32],
    /// Rows per plane.
    pub rows: usize,
    /// Pixels per row.
    pub width: usize,
}

impl BandPlanes<'_> {
    /// Floats needed for `q` guides.
    pub const fn len(q: usize, rows: usize, width: usize) -> usize {
        (4 + q) * rows * width
    }
    #[inline]
    fn plane(&self, p: usize) -> &[f32] {
        let n = self.rows * self.width;
        &self.data[p * n..(p + 1) * n]
    }
}

/// Register-sized working space of the SIMD block accumulation (21 KB); make one
/// per thread and reuse it for many bands.
#[derive(Clone, Debug)]
pub struct BlockScratch {
    groups: [[f32x8; VW]; MAX_GROUPS],
    /// A block's moments as 8 partial sums each, before the reduction. Kept
    /// here rather than on the stack: at `MAX_K` vectors (4 KiB) a fresh
    /// zeroed array per block was a `memset` costing ~1 ms per 1080p frame.
    sums: [f32x8; MAX_K],
    /// Per group of a gathered block: `s`, the square roots of the weights.
    weights: [f32x8; MAX_GROUPS],
}

impl Default for BlockScratch {
    fn default() -> Self {
        BlockScratch { groups: [[f32x8::ZERO; VW]; MAX_GROUPS], sums: [f32x8::ZERO; MAX_K], weights: [f32x8::ZERO; MAX_GROUPS] }
    }
}

/// Accumulates the moments of blocks `first..first + cells.len() / k` of the
/// band into `cells`. Returns the number of empty cells.
pub fn moments_band<const Q: usize>(
    band: BandPlanes<'_>,
    block: usize,
    simd: bool,
    first: usize,
    cells: &mut [f64],
    scratch: &mut BlockScratch,
) -> usize {
    let lay = CellLayout::new(Q);
    let k = lay.k;
    // The SIMD path reads planes unchecked: establish its preconditions here.
    if band.data.len() < BandPlanes::len(Q, band.rows, band.width) || (first + cells.len() / k.max(1)) * block > band.width || block == 0 {
        cells.fill(0.0);
        return cells.len() / k.max(1);
    }
    let w = band.plane(0);
    let y = [band.plane(1), band.plane(2), band.plane(3)];
    let mut g: [&[f32]; MAX_GUIDES] = [&[]; MAX_GUIDES];
    for (i, gi) in g.iter_mut().enumerate().take(Q) {
        *gi = band.plane(4 + i);
    }
    let isa = Isa::detect();
    let mut acc = [0f32; MAX_K];
    let mut empty = 0;
    for (cx, cell) in cells.chunks_exact_mut(k).enumerate() {
        let x0 = (first + cx) * block;
        // Block reference: the first valid pixel (exact sample; a constant guide stays exactly constant).
        let mut r = [0f32; MAX_GUIDES];
        let mut found = false;
        'find: for row in 0..band.rows {
            for x in x0..x0 + block {
                let i = row * band.width + x;
                if w[i] != 0.0 {
                    for q in 0..Q {
                        r[q] = g[q][i];
                    }
                    found = true;
                    break 'find;
                }
            }
        }
        if !found {
            cell.fill(0.0);
            empty += 1;
            continue;
        }
        if simd && block.is_multiple_of(8) && band.rows * block / 8 <= MAX_GROUPS {
            block_simd::<Q>(isa, &band, x0, block, w, &y, &g, &r, &lay, &mut acc, scratch);
        } else {
            acc[..k].fill(0.0);
            block_scalar::<Q>(&band, x0, block, w, &y, &g, &r, &lay, &mut acc);
        }
        store_shifted::<Q>(&acc, &r, &lay, cell);
    }
    empty
}

/// Most rows in a [`BandRows`] (B = 16).
pub const MAX_ROWS: usize = 16;

/// One band of `rows` input rows read in place: `planes[r][0..3]` are the
/// noisy colour rows of band row `r`, `planes[r][3 + q]` the raw guide rows
/// (not centred), each at least `width` long; `reference` is the frame
/// reference `m` subtracted from each guide; `demod`, the AO demodulation's
/// guide index and offset ([`crate::FlrConfig::ao_demodulation`]): the colour
/// is divided by `s(ao)` as its vectors are built (`None`: taken as it is).
#[derive(Clone, Copy, Debug)]
pub struct BandRows<'a> {
    /// Per band row: noisy r, g, b, then each guide channel's row.
    pub planes: [[&'a [f32]; 3 + MAX_GUIDES]; MAX_ROWS],
    /// Rows in the band (at most [`MAX_ROWS`]).
    pub rows: usize,
    /// Pixels per row.
    pub width: usize,
    /// Per guide channel: the frame reference `m`.
    pub reference: [f32; MAX_GUIDES],
    /// The AO demodulation: guide index and offset (`None`: off).
    pub demod: Option<(usize, f32)>,
}

/// What [`moments_rows`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowsCounts {
    /// Blocks without a valid pixel.
    pub empty_blocks: usize,
    /// Pixels with a NaN/Inf noisy value.
    pub nonfinite_noisy: usize,
    /// Pixels with a NaN/Inf guide value.
    pub nonfinite_guides: usize,
}

/// Whether [`moments_rows`] handles this block size and band height.
pub const fn rows_supported(block: usize, rows: usize) -> bool {
    block.is_multiple_of(8) && block > 0 && rows <= MAX_ROWS && rows * block / 8 <= MAX_GROUPS
}

/// Accumulates the moments of blocks `0..cells.len() / k` (all whole: they
/// must lie inside `width`) of a band read in place, bit-identical to
/// gathering it into [`BandPlanes`] and calling [`moments_band`].
///
/// Each block is first accumulated as if every pixel were valid, with the
/// block's first pixel as reference: one subtraction pair per value and no
/// masks. If a plain sum comes out non-finite the block holds a NaN/Inf and is
/// redone with per-pixel validity (and counted). Unsupported shapes
/// ([`rows_supported`], short rows) give zero cells, all counted empty.
///
/// `before_block(i, n)` is called before block `i` of the `n` whole blocks (a
/// hook for the caller to spread its own work over the band, such as asking
/// for its next band's rows: [`crate::flr`] does); `|_, _| {}` for nothing.
pub fn moments_rows<const Q: usize>(
    band: &BandRows<'_>,
    block: usize,
    cells: &mut [f64],
    scratch: &mut BlockScratch,
    mut before_block: impl FnMut(usize, usize),
) -> RowsCounts {
    let lay = CellLayout::new(Q);
    let k = lay.k.max(1);
    let nb = cells.len() / k;
    let mut counts = RowsCounts::default();
    let shape_ok = rows_supported(block, band.rows)
        && band.rows > 0
        && nb * block <= band.width
        && band.planes[..band.rows].iter().all(|row| row[..3 + Q].iter().all(|p| p.len() >= band.width));
    if !shape_ok {
        cells.fill(0.0);
        counts.empty_blocks = nb;
        return counts;
    }
    let isa = Isa::detect();
    let mut acc = [0f32; MAX_K];
    for (cx, cell) in cells.chunks_exact_mut(k).enumerate() {
        let x0 = cx * block;
        // Fast attempt: the first pixel as reference, every pixel valid.
        let mut r = [0f32; MAX_GUIDES];
        for q in 0..Q {
            r[q] = band.planes[0][3 + q][x0] - band.reference[q];
        }
        before_block(cx, nb);
        let ng = groups_plain_on::<Q>(isa, band, x0, block, &r, &mut scratch.groups);
        // every lane of every group has weight 1
        let wsum = f32x8::splat(ng as f32);
        if !accumulate_on::<Q>(isa, &scratch.groups[..ng], None, &mut scratch.sums, wsum, &lay, &mut acc, true) {
            // Some value is NaN/Inf: count, pick the first valid pixel, mask.
            let Some(r2) = first_valid::<Q>(band, x0, block, &mut counts) else {
                cell.fill(0.0);
                counts.empty_blocks += 1;
                continue;
            };
            r = r2;
            let (ng, wsum) = groups_masked::<Q>(band, x0, block, &r, &mut scratch.groups);
            accumulate_on::<Q>(isa, &scratch.groups[..ng], None, &mut scratch.sums, wsum, &lay, &mut acc, false);
        }
        store_shifted::<Q>(&acc, &r, &lay, cell);
    }
    counts
}

#[inline(always)]
fn load_at(s: &[f32], i: usize) -> f32x8 {
    debug_assert!(i + 8 <= s.len());
    // SAFETY: callers pass `i + 8 <= s.len()`: `moments_rows` checked that every row
    // slice holds `width` values and that its blocks (block % 8 == 0) lie inside `width`.
    unsafe { core::ptr::read_unaligned(s.as_ptr().add(i) as *const f32x8) }
}

/// How far ahead (values) the in-place path asks for its guide rows. The
/// band has `rows × Q` guide streams advancing by one block each: more than
/// the hardware prefetchers follow, so every block's loads would wait on DRAM
/// (14.3 ms instead of 7.7 for 1080p's moments without). Two distances: into
/// L1 three lines ahead, and into L2 eight lines ahead, which lets more
/// misses be in flight than L1 alone can track (x86-64-v3, 1080p, Q = 5,
/// `benches/stages.rs`: 6.8–6.9 ms with the L2 prefetch, 7.3–7.8 ms without;
/// L1 alone at 24–192 values ahead made no difference).
const PREFETCH_AHEAD: usize = 48;
const PREFETCH_L2_AHEAD: usize = 128;

/// [`groups_plain`] in AVX2 intrinsics where `isa` says so (a build whose
/// `wide` lacks them on a CPU that has them), else the portable lanes;
/// bit-identical either way. Same preconditions as `groups_plain` (checked
/// by `moments_rows`).
#[inline(always)]
fn groups_plain_on<const Q: usize>(
    isa: Isa,
    band: &BandRows<'_>,
    x0: usize,
    block: usize,
    r: &[f32; MAX_GUIDES],
    v: &mut [[f32x8; VW]; MAX_GROUPS],
) -> usize {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 (`Isa::intrinsics`); `moments_rows` checked the
        // band's shape (`rows_supported`, rows of `width` values, blocks inside it).
        return unsafe { avx2::groups_plain::<Q>(band, x0, block, r, v) };
    }
    let _ = isa;
    groups_plain::<Q>(band, x0, block, r, v)
}

/// Group vectors of a block assuming every pixel valid: `e = (g − m) − r`
/// (the value the gathered plane holds, minus the reference, times weight 1).
#[inline(always)]
fn groups_plain<const Q: usize>(
    band: &BandRows<'_>,
    x0: usize,
    block: usize,
    r: &[f32; MAX_GUIDES],
    v: &mut [[f32x8; VW]; MAX_GROUPS],
) -> usize {
    let mut mv = [f32x8::ZERO; MAX_GUIDES];
    let mut rv = [f32x8::ZERO; MAX_GUIDES];
    for q in 0..Q {
        mv[q] = f32x8::splat(band.reference[q]);
        rv[q] = f32x8::splat(r[q]);
    }
    let demod = band.demod.filter(|&(a, _)| a < Q).map(|(a, c)| (a, f32x8::splat(c)));
    let mut ng = 0;
    for row in &band.planes[..band.rows] {
        for q in 0..Q {
            prefetch(row[3 + q], x0 + PREFETCH_AHEAD);
            prefetch_l2(row[3 + q], x0 + PREFETCH_L2_AHEAD);
        }
        for x in (x0..x0 + block).step_by(8) {
            let vg = &mut v[ng];
            for q in 0..Q {
                vg[q] = (load_at(row[3 + q], x) - mv[q]) - rv[q];
            }
            if let Some((a, c)) = demod {
                let f = demodulation::inverse8(load_at(row[3 + a], x), c);
                for c in 0..3 {
                    vg[Q + c] = demodulation::demodulate8(load_at(row[c], x), f);
                }
            } else {
                for c in 0..3 {
                    vg[Q + c] = load_at(row[c], x);
                }
            }
            ng += 1;
        }
    }
    ng
}

/// The first pixel of the block (row-major) whose values are all finite, as
/// `g − m`, counting the pixels that are not; `None` if there is none.
#[inline(never)]
fn first_valid<const Q: usize>(band: &BandRows<'_>, x0: usize, block: usize, counts: &mut RowsCounts) -> Option<[f32; MAX_GUIDES]> {
    let mut first = None;
    for row in &band.planes[..band.rows] {
        for x in x0..x0 + block {
            let noisy_ok = row[..3].iter().all(|p| p[x].is_finite());
            let guides_ok = row[3..3 + Q].iter().all(|p| p[x].is_finite());
            counts.nonfinite_noisy += !noisy_ok as usize;
            counts.nonfinite_guides += !guides_ok as usize;
            if noisy_ok && guides_ok && first.is_none() {
                let mut r = [0f32; MAX_GUIDES];
                for q in 0..Q {
                    r[q] = row[3 + q][x] - band.reference[q];
                }
                first = Some(r);
            }
        }
    }
    first
}

/// Group vectors with per-pixel validity, exactly as [`moments_band`] sees a
/// gathered band: an invalid pixel has weight 0 and all its planes 0.
#[inline(never)]
fn groups_masked<const Q: usize>(
    band: &BandRows<'_>,
    x0: usize,
    block: usize,
    r: &[f32; MAX_GUIDES],
    v: &mut [[f32x8; VW]; MAX_GROUPS],
) -> (usize, f32x8) {
    let max = f32x8::splat(f32::MAX);
    let one = f32x8::splat(1.0);
    let demod = band.demod.filter(|&(a, _)| a < Q).map(|(a, c)| (a, f32x8::splat(c)));
    let mut ng = 0;
    let mut wsum = f32x8::ZERO;
    for row in &band.planes[..band.rows] {
        for x in (x0..x0 + block).step_by(8) {
            let mut ok = f32x8::splat(f32::from_bits(u32::MAX));
            for p in &row[..3 + Q] {
                ok &= load_at(p, x).abs().simd_le(max);
            }
            let w = ok & one;
            wsum += w;
            let vg = &mut v[ng];
            for q in 0..Q {
                let d = ok.select(load_at(row[3 + q], x) - f32x8::splat(band.reference[q]), f32x8::ZERO);
                vg[q] = (d - f32x8::splat(r[q])) * w;
            }
            let f = demod.map_or(one, |(a, c)| demodulation::inverse8(load_at(row[3 + a], x), c));
            for c in 0..3 {
                vg[Q + c] = ok.select(demodulation::demodulate8(load_at(row[c], x), f), f32x8::ZERO);
            }
            ng += 1;
        }
    }
    (ng, wsum)
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn block_scalar<const Q: usize>(
    band: &BandPlanes<'_>,
    x0: usize,
    block: usize,
    w: &[f32],
    y: &[&[f32]; 3],
    g: &[&[f32]; MAX_GUIDES],
    r: &[f32; MAX_GUIDES],
    lay: &CellLayout,
    acc: &mut [f32; MAX_K],
) {
    for row in 0..band.rows {
        let base = row * band.width;
        for i in base + x0..base + x0 + block {
            // s = √w: e and y scaled by s, plain sums by s again
            let si = w[i];
            let mut e = [0f32; MAX_GUIDES];
            for q in 0..Q {
                e[q] = (g[q][i] - r[q]) * si;
            }
            let yy = [y[0][i] * si, y[1][i] * si, y[2][i] * si];
            acc[0] += si * si;
            let mut p = lay.ss;
            for a in 0..Q {
                acc[lay.s + a] += si * e[a];
                for b in a..Q {
                    acc[p] += e[a] * e[b];
                    p += 1;
                }
            }
            for c in 0..3 {
                acc[lay.t + c] += si * yy[c];
            }
            let [l0, l1, l2] = super::LUMA;
            let l = yy[0] * l0 + yy[1] * l1 + yy[2] * l2;
            acc[lay.e] += l * l;
            for a in 0..Q {
                for c in 0..3 {
                    acc[lay.p + 3 * a + c] += e[a] * yy[c];
                }
            }
        }
    }
}

/// Most 8-pixel groups in one block (B = 16: 16 rows × 2).
const MAX_GROUPS: usize = 32;
/// Vectors per group: Q centred guides, then 3 colours.
const VW: usize = MAX_GUIDES + 3;

/// SIMD block accumulation from gathered planes: every 8-pixel group of the
/// block is turned into vectors `v = [e_0..e_Q, y_0, y_1, y_2]`
/// (e = (g − r)·s and y scaled by s, with s = √w), then [`accumulate`]d with
/// the plain sums weighted by s.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn block_simd<const Q: usize>(
    isa: Isa,
    band: &BandPlanes<'_>,
    x0: usize,
    block: usize,
    w: &[f32],
    y: &[&[f32]; 3],
    g: &[&[f32]; MAX_GUIDES],
    r: &[f32; MAX_GUIDES],
    lay: &CellLayout,
    acc: &mut [f32; MAX_K],
    scratch: &mut BlockScratch,
) {
    #[inline(always)]
    fn load(s: &[f32], i: usize) -> f32x8 {
        debug_assert!(i + 8 <= s.len());
        // SAFETY: callers pass `i + 8 <= s.len()`: `moments_band` checked that every
        // plane holds `rows * width` values and `x0 + block <= width` with block % 8 == 0.
        unsafe { core::ptr::read_unaligned(s.as_ptr().add(i) as *const f32x8) }
    }
    let mut rv = [f32x8::ZERO; MAX_GUIDES];
    for q in 0..Q {
        rv[q] = f32x8::splat(r[q]);
    }
    let mut wsum = f32x8::ZERO;
    let mut ng = 0;
    let v = &mut scratch.groups;
    for row in 0..band.rows {
        let base = row * band.width;
        let mut i = base + x0;
        while i < base + x0 + block && ng < MAX_GROUPS {
            // s = √w: e and y scaled by s, plain sums by s again (`accumulate`)
            let si = load(w, i);
            wsum = si.mul_add(si, wsum);
            scratch.weights[ng] = si;
            let vg = &mut v[ng];
            for q in 0..Q {
                vg[q] = (load(g[q], i) - rv[q]) * si;
            }
            for c in 0..3 {
                vg[Q + c] = load(y[c], i) * si;
            }
            ng += 1;
            i += 8;
        }
    }
    let weights = Some(&scratch.weights[..ng]);
    accumulate_on::<Q>(isa, &scratch.groups[..ng], weights, &mut scratch.sums, wsum, lay, acc, false);
}

/// [`accumulate`] on the given instruction set: in AVX2 + FMA intrinsics
/// when `isa` says so, the build's `wide` lacks them and the CPU has them
/// (the moments' main cost: a default x86-64 build's SSE2 lanes took ~1.7×
/// as long), else the portable lanes.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn accumulate_on<const Q: usize>(
    isa: Isa,
    groups: &[[f32x8; VW]],
    weights: Option<&[f32x8]>,
    sums: &mut [f32x8; MAX_K],
    wsum: f32x8,
    lay: &CellLayout,
    acc: &mut [f32; MAX_K],
    check: bool,
) -> bool {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe { avx2::accumulate::<Q>(groups, weights, sums, wsum, lay, acc, check) };
    }
    let _ = isa;
    accumulate::<Q>(groups, weights, sums, wsum, lay, acc, check)
}

/// Block sums of the group vectors `v = [e_0..e_Q, y_0, y_1, y_2]` into
/// `acc` (cell layout, about the block reference): plain sums, then for each
/// guide `a` the whole row `Σ v_a v_b, b ≥ a` (that is `S_a·` and `P_a·`)
/// accumulated in registers over the groups, one fused multiply-add per
/// product, reduced eight at a time. With `weights` (`s` per group, the
/// vectors scaled by it), the plain sums are `Σ s v`, so that every moment
/// carries `s²`. With `check`, returns `false` (and leaves `acc`
/// unspecified) as soon as a plain sum is not finite.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn accumulate<const Q: usize>(
    groups: &[[f32x8; VW]],
    weights: Option<&[f32x8]>,
    sums: &mut [f32x8; MAX_K],
    wsum: f32x8,
    lay: &CellLayout,
    acc: &mut [f32; MAX_K],
    check: bool,
) -> bool {
    // Block sums as vectors (8 column partial sums each), in the cell layout
    // (every one of `sums[..k]` is written below), then reduced eight at a time.
    sums[0] = wsum;
    // s and t: plain sums of the vectors.
    let mut plain = [f32x8::ZERO; VW];
    let mut energy = f32x8::ZERO;
    let luma = super::LUMA.map(f32x8::splat);
    for (i, vg) in groups.iter().enumerate() {
        match weights {
            Some(s) => {
                for j in 0..Q + 3 {
                    plain[j] = s[i].mul_add(vg[j], plain[j]);
                }
            }
            None => {
                for j in 0..Q + 3 {
                    plain[j] += vg[j];
                }
            }
        }
        let l = vg[Q].mul_add(luma[0], vg[Q + 1].mul_add(luma[1], vg[Q + 2] * luma[2]));
        energy = l.mul_add(l, energy);
    }
    if check {
        // A non-finite input makes its plain sum non-finite (Inf, or NaN).
        let max = f32x8::splat(f32::MAX);
        let mut ok = f32x8::splat(f32::from_bits(u32::MAX));
        for j in 0..Q + 3 {
            ok &= plain[j].abs().simd_le(max);
        }
        if !ok.all() {
            return false;
        }
    }
    for a in 0..Q {
        sums[lay.s + a] = plain[a];
    }
    for c in 0..3 {
        sums[lay.t + c] = plain[Q + c];
    }
    sums[lay.e] = energy;
    // S (upper triangle) and P: for each guide `a`, the products with every
    // `b ≥ a` (guides then colours) accumulate in registers, up to `ROW` at a
    // time, loading `v_a` once per group.
    const ROW: usize = 8;
    let mut p = lay.ss;
    for a in 0..Q {
        let mut b0 = a;
        while b0 < Q + 3 {
            let nb = (Q + 3 - b0).min(ROW);
            let mut r = [f32x8::ZERO; ROW];
            for vg in groups {
                let va = vg[a];
                for j in 0..nb {
                    r[j] = va.mul_add(vg[b0 + j], r[j]);
                }
            }
            for j in 0..nb {
                let b = b0 + j;
                if b < Q {
                    sums[p] = r[j];
                    p += 1;
                } else {
                    sums[lay.p + 3 * a + (b - Q)] = r[j];
                }
            }
            b0 += nb;
        }
    }
    for i in (0..lay.k).step_by(8) {
        let t = f32x8::transpose(eight_at(&sums[..], i, f32x8::ZERO));
        let total: [f32; 8] = ((t[0] + t[1]) + (t[2] + t[3]) + ((t[4] + t[5]) + (t[6] + t[7]))).into();
        store_eight(acc, i, lay.k, &total);
    }
    true
}

/// `sums[i..i + 8]`, padded with `zero` past the end (`MAX_K`). Lanes past the cell's
/// `k` moments may hold anything (an earlier block's sums): the reduction
/// keeps every moment in a lane of its own, and [`store_eight`] leaves them
/// where no one reads them. (A copy of the exact `k − i` vectors had a
/// run-time length and compiled to a `memcpy` call per eight moments: ~2 %
/// of a default build's frame.)
#[inline(always)]
fn eight_at<T: Copy>(sums: &[T], i: usize, zero: T) -> [T; 8] {
    if let Some(s) = sums.get(i..i + 8) {
        let mut e = [zero; 8];
        e.copy_from_slice(s);
        e
    } else {
        core::array::from_fn(|j| sums.get(i + j).copied().unwrap_or(zero))
    }
}

/// The eight lane sums of moments `i..i + 8` into `acc` (whole, where they fit
/// in `MAX_K`: entries `k..` of `acc` are scratch that [`store_shifted`] never
/// reads; else only those below `k`).
#[inline(always)]
fn store_eight(acc: &mut [f32; MAX_K], i: usize, k: usize, total: &[f32; 8]) {
    if let Some(d) = acc.get_mut(i..i + 8) {
        d.copy_from_slice(total);
    } else {
        for (j, t) in total.iter().enumerate().take(k.saturating_sub(i)) {
            acc[i + j] = *t;
        }
    }
}

/// Moments about the block reference `r` → moments about the frame reference (f64).
#[inline(always)]
fn store_shifted<const Q: usize>(acc: &[f32; MAX_K], r: &[f32; MAX_GUIDES], lay: &CellLayout, cell: &mut [f64]) {
    let n = acc[0] as f64;
    let mut rr = [0f64; MAX_GUIDES];
    let mut s = [0f64; MAX_GUIDES];
    for q in 0..Q {
        rr[q] = r[q] as f64;
        s[q] = acc[lay.s + q] as f64;
    }
    let t = [acc[lay.t] as f64, acc[lay.t + 1] as f64, acc[lay.t + 2] as f64];
    cell[0] = n;
    let mut p = lay.ss;
    for a in 0..Q {
        cell[lay.s + a] = s[a] + n * rr[a];
        for b in a..Q {
            cell[p] = acc[p] as f64 + rr[a] * s[b] + s[a] * rr[b] + n * rr[a] * rr[b];
            p += 1;
        }
    }
    for c in 0..3 {
        cell[lay.t + c] = t[c];
    }
    for a in 0..Q {
        for c in 0..3 {
            let j = lay.p + 3 * a + c;
            cell[j] = acc[j] as f64 + rr[a] * t[c];
        }
    }
    cell[lay.e] = acc[lay.e] as f64;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 + FMA block accumulation (where this CPU has it) agrees with
    /// the portable lanes: bit for bit where `wide` is AVX2 + FMA (the same
    /// operations in the same order), else to the rounding of fused against
    /// separate products; with `check`, both refuse the same non-finite block.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx2_accumulate_matches_portable() {
        if !Isa::Avx2Fma.available() {
            return;
        }
        let mut seed = 777u32;
        let mut rnd = || crate::hash::uniform(&mut seed) as f32;
        type Weights<'a> = Option<&'a [f32x8]>;
        fn run<const Q: usize>(isa: Isa, groups: &[[f32x8; VW]], weights: Weights<'_>, check: bool) -> (bool, [f32; MAX_K]) {
            let (mut sums, mut acc) = ([f32x8::ZERO; MAX_K], [0f32; MAX_K]);
            let (wsum, lay) = (f32x8::splat(groups.len() as f32), CellLayout::new(Q));
            let ok = match isa {
                Isa::Portable => accumulate::<Q>(groups, weights, &mut sums, wsum, &lay, &mut acc, check),
                // SAFETY: the test returned early unless the CPU has AVX2 and FMA.
                // (Called directly: `accumulate_on` skips it where `wide` is AVX2.)
                Isa::Avx2Fma | Isa::Avx512 => unsafe { avx2::accumulate::<Q>(groups, weights, &mut sums, wsum, &lay, &mut acc, check) },
            };
            (ok, acc)
        }
        // weights between 0 and 2 per lane, for the weighted plain sums (a seed of their own)
        let mut wseed = 4242u32;
        let mut weights = [f32x8::ZERO; MAX_GROUPS];
        for w in weights.iter_mut() {
            *w = f32x8::from(core::array::from_fn::<f32, 8, _>(|_| 2.0 * crate::hash::uniform(&mut wseed) as f32));
        }
        let compare_q = |groups: &[[f32x8; VW]], q: usize| {
            let w = Some(&weights[..groups.len()]);
            match q {
                0 => compare::<0>(groups, w),
                1 => compare::<1>(groups, w),
                5 => compare::<5>(groups, w),
                8 => compare::<8>(groups, w),
                _ => compare::<MAX_GUIDES>(groups, w),
            }
        };
        fn compare<const Q: usize>(groups: &[[f32x8; VW]], weights: Weights<'_>) {
            let k = CellLayout::new(Q).k;
            for (check, weights) in [(false, None), (true, None), (false, weights), (true, weights)] {
                let (pok, p) = run::<Q>(Isa::Portable, groups, weights, check);
                let (aok, a) = run::<Q>(Isa::Avx2Fma, groups, weights, check);
                assert_eq!(pok, aok, "Q {Q} check {check}");
                if !pok {
                    continue;
                }
                let fused = cfg!(all(target_feature = "avx2", target_feature = "fma"));
                // (weighted plain sums are products too: fused against separate
                // rounding over 32 groups of terms up to 20, which may cancel)
                let bound = if weights.is_some() { 2e-4 } else { 1e-5 };
                for j in 0..k {
                    if p[j].is_nan() {
                        assert!(a[j].is_nan(), "Q {Q} moment {j}: NaN vs {}", a[j]);
                    } else if fused {
                        assert_eq!(p[j].to_bits(), a[j].to_bits(), "Q {Q} moment {j}: {} vs {}", p[j], a[j]);
                    } else {
                        assert!((p[j] - a[j]).abs() <= bound * (1.0 + p[j].abs()), "Q {Q} moment {j}: {} vs {}", p[j], a[j]);
                    }
                }
            }
        }
        for ng in [1usize, 2, 8, 32] {
            let mut groups = [[f32x8::ZERO; VW]; MAX_GROUPS];
            for g in groups.iter_mut() {
                for v in g.iter_mut() {
                    *v = f32x8::from(core::array::from_fn::<f32, 8, _>(|_| 10.0 * rnd()));
                }
            }
            for q in [0, 1, 5, 8, MAX_GUIDES] {
                compare_q(&groups[..ng], q);
            }
            // a NaN in a colour plane: both refuse the block with `check`
            let mut bad = groups;
            let mut lanes = bad[ng - 1][5 + 1].to_array();
            lanes[3] = f32::NAN;
            bad[ng - 1][5 + 1] = f32x8::from(lanes);
            compare_q(&bad[..ng], 5);
        }
    }

    /// The AVX2 group builder (where this CPU has it) gives the portable
    /// lanes' vectors bit for bit, in any build: with and without the AO
    /// demodulation, NaN, ±Inf, huge and out-of-range values included, B = 8
    /// and 16, from 1 to 16 rows.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx2_groups_match_portable() {
        if !Isa::Avx2Fma.available() {
            return;
        }
        const W: usize = 48;
        let mut seed = 99u32;
        let mut rnd = || crate::hash::uniform(&mut seed) as f32;
        let special = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, -3.0, 1.5, 0.0];
        let data: [[[f32; W]; 3 + MAX_GUIDES]; MAX_ROWS] = core::array::from_fn(|row| {
            core::array::from_fn(|p| {
                core::array::from_fn(|x| if (x + 3 * p + 5 * row) % 23 == 0 { special[(x + p) % special.len()] } else { 4.0 * rnd() - 1.0 })
            })
        });
        fn compare<const Q: usize>(data: &[[[f32; W]; 3 + MAX_GUIDES]; MAX_ROWS], rows: usize, block: usize, demod: Option<(usize, f32)>) {
            let mut band = BandRows { planes: [[&[][..]; 3 + MAX_GUIDES]; MAX_ROWS], rows, width: W, reference: [0.5; MAX_GUIDES], demod };
            for (r, planes) in band.planes.iter_mut().enumerate() {
                for (p, plane) in planes.iter_mut().enumerate() {
                    *plane = &data[r][p][..];
                }
            }
            let r: [f32; MAX_GUIDES] = core::array::from_fn(|q| 0.25 * q as f32);
            for x0 in (0..=W - block).step_by(8) {
                let (mut p, mut a) = ([[f32x8::ZERO; VW]; MAX_GROUPS], [[f32x8::ZERO; VW]; MAX_GROUPS]);
                let np = groups_plain::<Q>(&band, x0, block, &r, &mut p);
                // SAFETY: the test returned early unless the CPU has AVX2; the band's
                // rows hold W values, x0 + block ≤ W and rows · block / 8 ≤ MAX_GROUPS.
                let na = unsafe { avx2::groups_plain::<Q>(&band, x0, block, &r, &mut a) };
                assert_eq!(np, na);
                for g in 0..np {
                    for j in 0..Q + 3 {
                        let (pv, av) = (p[g][j].to_array(), a[g][j].to_array());
                        for l in 0..8 {
                            assert_eq!(
                                pv[l].to_bits(),
                                av[l].to_bits(),
                                "Q {Q} rows {rows} B {block} x0 {x0} group {g} vector {j}: {pv:?} vs {av:?}"
                            );
                        }
                    }
                }
            }
        }
        for rows in [1usize, 2, 8, 16] {
            for demod in [None, Some((0, 0.1)), Some((4, 1e-6)), Some((7, 0.3))] {
                compare::<1>(&data, rows, 8, demod);
                compare::<5>(&data, rows, 8, demod);
                compare::<8>(&data, rows, 8, demod);
                compare::<5>(&data, rows, 16, demod);
                compare::<MAX_GUIDES>(&data, rows.min(MAX_GROUPS * 8 / 16), 16, demod);
            }
        }
    }
}
