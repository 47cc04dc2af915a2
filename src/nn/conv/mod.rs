//! The network's layers on planar f32 tensors (`[c][y][x]`, row stride = width):
//! 3×3 (stride 1 or 2, zero padding 1) and 1×1 convolutions with f16 weights,
//! LeakyReLU (0.01) or sigmoid, and "upsample ×2 (nearest) + concat skip".
//! Rows are accumulated with slice arithmetic the compiler vectorises; the
//! 3×3 layers' rows in 8-pixel lanes, with `wide` (any ISA, chosen at
//! compile time) or, where the CPU has them, AVX2 + FMA intrinsics
//! (`avx2`) or AVX-512F intrinsics in 16-pixel lanes (`avx512`: the
//! stride-1 layers in Winograd's F(2, 3) along the row), chosen at run time
//! (see [`Isa`]).

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;

use crate::error::Error;
use half::f16;

/// A convolution: shapes and its f16 parameters (weights `[out][in][k][k]`, then biases).
#[derive(Clone, Copy, Debug)]
pub struct ConvDesc<'b> {
    /// Input channels.
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
    /// Kernel side: 3 or 1.
    pub k: usize,
    /// 1, or 2 (the output is half the input, rounded up).
    pub stride: usize,
    /// The f16 parameters, little-endian bytes.
    pub params: &'b [u8],
}

impl ConvDesc<'_> {
    pub(crate) const EMPTY: ConvDesc<'static> = ConvDesc { cin: 0, cout: 0, k: 0, stride: 1, params: &[] };
    #[inline]
    /// Parameters `first..first + dst.len()` (weights `[out][in][k][k]`,
    /// then biases) into `dst` as f32, converted in runs of 64.
    fn params_f32(&self, first: usize, dst: &mut [f32]) {
        let mut halves = [f16::ZERO; 64];
        for (j, run) in dst.chunks_mut(64).enumerate() {
            let at = 2 * (first + 64 * j);
            let Some(bytes) = self.params.get(at..at + 2 * run.len()) else { return };
            for (h, b) in halves.iter_mut().zip(bytes.chunks_exact(2)) {
                *h = f16::from_le_bytes([b[0], b[1]]);
            }
            crate::convert::f16_to_f32(&halves[..run.len()], run);
        }
    }
    /// f32 of `weights` scratch [`conv`] needs: `cout · cin · k · k` weights,
    /// `cout` biases and, for a stride-1 3×3 layer, room for the weights
    /// transformed for the AVX-512 lanes' Winograd products (`cout · cin · 12`).
    pub fn weights_len(&self) -> usize {
        let wino = if self.k == 3 && self.stride == 1 { self.cout * self.cin * 12 } else { 0 };
        self.cout * self.cin * self.k * self.k + self.cout + wino
    }
    /// Output size for a `w × h` input.
    pub fn out_size(&self, w: usize, h: usize) -> (usize, usize) {
        if self.stride == 2 {
            (w.div_ceil(2), h.div_ceil(2))
        } else {
            (w, h)
        }
    }
}

/// The activation after a convolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Act {
    /// Leaky ReLU, slope 0.01 below 0.
    Leaky,
    /// Logistic sigmoid `1 / (1 + e^−x)`.
    Sigmoid,
}

const LEAKY_SLOPE: f32 = 0.01;

/// Output channels computed together (their accumulators share every load).
/// 6 divides the bundled network's widths (12, 24, 48); with the AVX2 lanes'
/// two 8-pixel groups that is 12 independent accumulators, enough to keep
/// both FMA pipes busy through the multiply-add latency, and 15 of the 16
/// vector registers live.
const OB: usize = 6;

/// Output pixels of a row computed for every block of `OB` channels before
/// the next ones: the input a strip reads (`cin · 3` rows of
/// `stride · STRIP + 2` values) stays in L1 across the blocks, instead of
/// being fetched again from L2 for each block.
const STRIP: usize = 32;

pub use crate::isa::Isa;

/// `out = act(conv(input))`; `input` holds `cin` planes of `w × h`, `in_plane`
/// values apart, `out` `cout` planes of the output size, `out_plane` apart
/// (see [`crate::nn::plane_stride`]). `weights`: room for the layer's
/// weights in f32 ([`ConvDesc::weights_len`]), converted from f16 once per
/// call. `split`: for a stride-2 layer, room for `cin · in_plane` values where
/// the input's rows are rearranged as [even columns | odd columns], so the
/// taps become contiguous 8-pixel loads (without it, or for narrow rows,
/// stride 2 runs per pixel). `isa`: the lanes' instruction set;
/// [`Isa::detect`]'s where `isa` is not [`Isa::available`].
///
/// Output rows are the outer loop, strips of `STRIP` pixels the next and
/// blocks of `OB` output channels the inner one: the 3·cin input rows an
/// output row reads are fetched into the cache once for all the blocks, and
/// a strip's part of them stays in L1 across the blocks (blocks outermost
/// re-streamed the whole input tensor from memory `cout / OB` times). The
/// AVX-512 lanes of a stride-1 layer take a whole row at a time instead
/// (Winograd's F(2, 3), see `avx512`).
#[allow(clippy::too_many_arguments)]
pub fn conv(
    isa: Isa,
    d: ConvDesc<'_>,
    input: &[f32],
    in_plane: usize,
    w: usize,
    h: usize,
    out: &mut [f32],
    out_plane: usize,
    act: Act,
    weights: &mut [f32],
    split: &mut [f32],
) -> Result<(), Error> {
    super::run_layer(None, isa, d, input, in_plane, w, h, out, out_plane, act, weights, split)
}

/// Whether a layer with `split_len` f32 of split room runs its stride-2
/// taps on even/odd split rows ([`split_rows`]; otherwise per pixel).
pub fn splits(d: ConvDesc<'_>, w: usize, h: usize, in_plane: usize, split_len: usize) -> bool {
    d.k == 3 && d.stride == 2 && w / 2 >= 9 && in_plane >= w * h && split_len >= d.cin * in_plane
}

/// Rows `y0..y1` (clamped to `split`'s height) of every plane of `input`
/// (planes `in_plane` apart, `split`'s width) rearranged into `split` as
/// [even columns | odd columns], where a stride-2 layer's taps are
/// contiguous 8-pixel loads.
///
/// # Safety
/// No other live slice covers these rows of `split`'s planes.
pub unsafe fn split_rows(input: &[f32], in_plane: usize, split: &Planes<'_>, y0: usize, y1: usize) {
    let w = split.width;
    let ew = w.div_ceil(2);
    for c in 0..split.count {
        for y in y0..y1.min(split.height) {
            let Some(src) = input.get(c * in_plane + y * w..c * in_plane + (y + 1) * w) else { return };
            // SAFETY: the caller keeps these rows to this call.
            let dst = unsafe { split.row(c, y) };
            if dst.len() != w {
                return;
            }
            let (even, odd) = dst.split_at_mut(ew);
            for (pair, (e, o)) in src.chunks_exact(2).zip(even.iter_mut().zip(odd.iter_mut())) {
                *e = pair[0];
                *o = pair[1];
            }
            if w % 2 == 1 {
                even[ew - 1] = src[w - 1];
            }
        }
    }
}

/// A convolution ready to run row by row ([`Layer::rows`]): its weights in
/// f32 and the input it reads (for stride 2, rearranged into even/odd
/// columns). Its output rows are independent, so bands of them may run on
/// different threads ([`crate::nn::UNet::forward_parallel`]).
#[derive(Debug)]
pub struct Layer<'a> {
    isa: Isa,
    d: ConvDesc<'a>,
    input: &'a [f32],
    /// What the lanes read: `input`, or its even/odd split rows.
    lanes_input: &'a [f32],
    stride: usize,
    w: usize,
    h: usize,
    in_plane: usize,
    act: Act,
    wts: &'a [f32],
    /// The biases in f32.
    bias: &'a [f32],
    /// The blocks' weights for the Winograd lanes (empty: not used; read by
    /// the AVX-512 lanes only).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    wino: &'a [f32],
    /// Output channels computed in blocks of `OB` lanes.
    blocks: usize,
}

impl<'a> Layer<'a> {
    /// Checks the shapes and converts the weights into `weights`. `split`:
    /// for a stride-2 layer where [`splits`] holds, the input's rows split by
    /// [`split_rows`] (`None`: stride 2 runs per pixel).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        isa: Isa,
        d: ConvDesc<'a>,
        input: &'a [f32],
        in_plane: usize,
        w: usize,
        h: usize,
        act: Act,
        weights: &'a mut [f32],
        split: Option<&'a [f32]>,
    ) -> Result<Self, Error> {
        let isa = if isa.available() { isa } else { Isa::detect() };
        let taps = d.cin * d.k * d.k;
        let ip = in_plane;
        if ip < w * h || input.len() < d.cin * ip || d.params.len() != 2 * (d.cout * taps + d.cout) {
            return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed: d.cin * ip, len: input.len() });
        }
        if weights.len() < d.weights_len() {
            return Err(Error::ScratchTooSmall { needed: d.weights_len(), got: weights.len() });
        }
        let split = split.filter(|s| splits(d, w, h, ip, s.len()));
        let (lanes_input, stride) = match split {
            Some(s) => (&s[..d.cin * ip], 2),
            None => (input, 1),
        };
        // blocks of OB output channels in lanes (3×3 on rows wide enough), the
        // rest one channel at a time
        let blocks = if d.k == 3 && ((d.stride == 1 && w >= 18) || split.is_some()) { d.cout / OB } else { 0 };
        // the blocks' weights as [block][tap][OB] (one tap's OB weights
        // adjacent, read in sequence by the lanes), the rest as [out][tap]
        let (wts, rest) = weights[..d.weights_len()].split_at_mut(d.cout * taps);
        let (bias, wino) = rest.split_at_mut(d.cout);
        let (packed, rest) = wts.split_at_mut(blocks * OB * taps);
        let mut run = [0f32; 64];
        for (k, block) in packed.chunks_exact_mut(OB * taps).enumerate() {
            for b in 0..OB {
                let first = (k * OB + b) * taps;
                for t0 in (0..taps).step_by(64) {
                    let n = (taps - t0).min(64);
                    d.params_f32(first + t0, &mut run[..n]);
                    for (t, &v) in run[..n].iter().enumerate() {
                        block[(t0 + t) * OB + b] = v;
                    }
                }
            }
        }
        d.params_f32(blocks * OB * taps, rest);
        d.params_f32(d.cout * taps, bias);
        // the AVX-512 lanes of a stride-1 layer multiply in Winograd's
        // F(2, 3) along the row: per kernel row (g0, g1, g2) the four
        // weights g0, (g0 + g1 + g2) / 2, (g0 − g1 + g2) / 2, g2, as
        // [block][input channel · 3 + ky][4][OB]
        let wino = if isa == Isa::Avx512 && d.k == 3 && d.stride == 1 && blocks > 0 {
            let wino = &mut wino[..blocks * OB * d.cin * 12];
            for (block, wb) in packed.chunks_exact(OB * taps).zip(wino.chunks_exact_mut(OB * d.cin * 12)) {
                for (r, wr) in block.chunks_exact(3 * OB).zip(wb.chunks_exact_mut(4 * OB)) {
                    for b in 0..OB {
                        let (g0, g1, g2) = (r[b], r[OB + b], r[2 * OB + b]);
                        wr[b] = g0;
                        wr[OB + b] = (g0 + g1 + g2) * 0.5;
                        wr[2 * OB + b] = (g0 - g1 + g2) * 0.5;
                        wr[3 * OB + b] = g2;
                    }
                }
            }
            &*wino
        } else {
            &[]
        };
        Ok(Layer { isa, d, input, lanes_input, stride, w, h, in_plane: ip, act, wts, bias, wino, blocks })
    }

    /// Output rows.
    pub fn out_height(&self) -> usize {
        self.d.out_size(self.w, self.h).1
    }

    /// Computes output rows `y0..y1` (clamped to the output) into `out`.
    ///
    /// # Safety
    /// No other live slice, on this thread or another, covers rows `y0..y1`
    /// of `out`'s planes while this runs.
    pub unsafe fn rows(&self, out: &Planes<'_>, y0: usize, y1: usize) {
        let d = &self.d;
        let (w, h, ip, wts) = (self.w, self.h, self.in_plane, self.wts);
        let oh = d.out_size(w, h).1;
        let taps = d.cin * d.k * d.k;
        let input = self.input;
        for y in y0..y1.min(oh) {
            #[cfg(target_arch = "x86_64")]
            let winograd = self.isa == Isa::Avx512 && self.stride == 1 && !self.wino.is_empty() && {
                let g = avx512::WinogradRow {
                    wino: self.wino,
                    bias: self.bias,
                    blocks: self.blocks,
                    cin: d.cin,
                    lanes: self.lanes_input,
                    w,
                    plane: ip,
                    src_rows: src_rows(y, h),
                    leaky: self.act == Act::Leaky,
                };
                let fits = g.fits();
                if fits {
                    // SAFETY: `Layer::new` runs `Isa::Avx512` only where it is
                    // available; `g.fits()` holds; row y is this call's (the caller's contract).
                    unsafe { avx512::winograd_row(&g, out, y) };
                }
                fits
            };
            #[cfg(not(target_arch = "x86_64"))]
            let winograd = false;
            if self.blocks > 0 && !winograd {
                let ow = d.out_size(w, h).0;
                let mut x0 = 0;
                while x0 < ow {
                    let x1 = (x0 + STRIP).min(ow);
                    for k in 0..self.blocks {
                        let mut rows: [&mut [f32]; OB] = Default::default();
                        for (b, r) in rows.iter_mut().enumerate() {
                            // SAFETY: row y of plane k·OB + b is this call's alone (the caller's contract).
                            *r = unsafe { out.row(k * OB + b, y) };
                        }
                        let bias = core::array::from_fn(|b| self.bias[k * OB + b]);
                        let g = Lanes {
                            wts: &wts[k * OB * taps..(k + 1) * OB * taps],
                            cin: d.cin,
                            lanes: self.lanes_input,
                            w,
                            plane: ip,
                            src_rows: src_rows(self.stride * y, h),
                            stride: self.stride,
                            bias,
                            leaky: self.act == Act::Leaky,
                        };
                        conv3_block_strip(self.isa, &g, input, h, &mut rows, x0, x1);
                    }
                    x0 = x1;
                }
            }
            if self.blocks > 0 && self.act != Act::Leaky {
                for o in 0..self.blocks * OB {
                    // SAFETY: row y is this call's (the caller's contract).
                    activate(unsafe { out.row(o, y) }, self.act);
                }
            }
            for o in self.blocks * OB..d.cout {
                let wts = &wts[o * taps..(o + 1) * taps];
                // SAFETY: as above.
                let prow = unsafe { out.row(o, y) };
                prow.fill(self.bias[o]);
                for i in 0..d.cin {
                    let src = &input[i * ip..i * ip + w * h];
                    match (d.k, d.stride) {
                        (1, _) => {
                            let wt = wts[i];
                            for (p, v) in prow.iter_mut().zip(&src[y * w..(y + 1) * w]) {
                                *p += wt * v;
                            }
                        }
                        (_, 1) if w >= 18 => {} // the interior is done in lanes below
                        (_, 1) => {
                            for ky in 0..3 {
                                let sy = y as isize + ky as isize - 1;
                                if sy < 0 || sy >= h as isize {
                                    continue;
                                }
                                let srow = &src[sy as usize * w..(sy as usize + 1) * w];
                                for kx in 0..3 {
                                    let wt = wts[(i * 3 + ky) * 3 + kx];
                                    // x + kx − 1 inside the row
                                    let (x0, x1) = (if kx == 0 { 1 } else { 0 }, if kx == 2 { w - 1 } else { w });
                                    if x0 >= x1 {
                                        continue;
                                    }
                                    for (p, v) in prow[x0..x1].iter_mut().zip(&srow[x0 + kx - 1..x1 + kx - 1]) {
                                        *p += wt * v;
                                    }
                                }
                            }
                        }
                        _ => {
                            for ky in 0..3 {
                                let sy = 2 * y as isize + ky as isize - 1;
                                if sy < 0 || sy >= h as isize {
                                    continue;
                                }
                                let srow = &src[sy as usize * w..(sy as usize + 1) * w];
                                for kx in 0..3 {
                                    let wt = wts[(i * 3 + ky) * 3 + kx];
                                    for (x, p) in prow.iter_mut().enumerate() {
                                        let sx = 2 * x as isize + kx as isize - 1;
                                        if sx >= 0 && (sx as usize) < w {
                                            *p += wt * srow[sx as usize];
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
                if d.k == 3 && d.stride == 1 && w >= 18 {
                    conv3_row_lanes(wts, d.cin, input, (w, h, ip), y, prow);
                }
                activate(prow, self.act);
            }
        }
    }
}

/// A planar tensor (`count` planes of `width × height`, `plane` values
/// apart) written row by row, possibly by several threads at once at
/// disjoint rows (a layer's output in [`Layer::rows`], the split rows of
/// [`split_rows`], a concatenation in [`Concat::rows`]).
#[derive(Debug)]
pub struct Planes<'o> {
    ptr: *mut f32,
    len: usize,
    count: usize,
    plane: usize,
    width: usize,
    height: usize,
    _out: core::marker::PhantomData<&'o mut [f32]>,
}

// SAFETY: rows are handed out only through the unsafe `row`, whose callers
// keep concurrent calls at disjoint rows; the tensor is borrowed mutably for 'o.
unsafe impl Sync for Planes<'_> {}

impl<'o> Planes<'o> {
    /// `buf` as `count` planes of `width × height`, `plane` values apart.
    pub fn new(buf: &'o mut [f32], count: usize, plane: usize, width: usize, height: usize) -> Result<Self, Error> {
        let needed = count.saturating_mul(plane);
        if plane < width.saturating_mul(height) || buf.len() < needed {
            return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed, len: buf.len() });
        }
        Ok(Planes { ptr: buf.as_mut_ptr(), len: buf.len(), count, plane, width, height, _out: core::marker::PhantomData })
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Planes.
    pub fn channels(&self) -> usize {
        self.count
    }

    /// Row `y` of plane `c` (empty outside the tensor).
    ///
    /// # Safety
    /// No other live slice covers this row.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn row(&self, c: usize, y: usize) -> &mut [f32] {
        if c >= self.count || y >= self.height {
            return &mut [];
        }
        let at = c * self.plane + y * self.width;
        // SAFETY: `at..at + width` lies inside plane c (new checked plane ≥
        // width · height and count · plane ≤ len), borrowed for 'o; the
        // caller keeps this row to one user.
        unsafe { core::slice::from_raw_parts_mut(self.ptr.add(at), self.width) }
    }
}

/// Leaky ReLU of one value (what every version of the lanes computes).
#[inline(always)]
fn leaky(v: f32) -> f32 {
    if v < 0.0 {
        v * LEAKY_SLOPE
    } else {
        v
    }
}

fn activate(row: &mut [f32], act: Act) {
    match act {
        Act::Leaky => {
            // a select, not a conditional store: it vectorises
            for p in row.iter_mut() {
                *p = leaky(*p);
            }
        }
        Act::Sigmoid => {
            use wide::f32x8;
            super::map8(row, |x| f32x8::ONE / (f32x8::ONE + (-x).exp()));
        }
    }
}

/// The 3 input rows of output row `y` of a 3×3 layer (`sy` = stride · y;
/// `None`: the zero padding).
fn src_rows(sy: usize, h: usize) -> [Option<usize>; 3] {
    let r = |ky: usize| (sy + ky).checked_sub(1).filter(|&r| r < h);
    [r(0), r(1), r(2)]
}

/// The first `n` entries of the result: the rows of `src_rows` inside the
/// input, as (ky, offset of row sy in a plane of width `w`), for the
/// intrinsics lanes' unchecked loads.
#[cfg(target_arch = "x86_64")]
fn rows_inside(src_rows: &[Option<usize>; 3], w: usize) -> ([(usize, usize); 3], usize) {
    let mut valid = [(0, 0); 3];
    let mut n = 0;
    for (ky, r) in src_rows.iter().enumerate() {
        if let Some(sy) = *r {
            valid[n] = (ky, sy * w);
            n += 1;
        }
    }
    (valid, n)
}

/// Output pixels `x0..x1` of `OB` channels' rows (`rows`, whole output rows)
/// of a 3×3 layer, from the bias: each 8-pixel load feeds `OB` accumulators.
/// Stride 1 reads `g.lanes`, the input; stride 2 reads `g.lanes` as the input
/// with each row split into [even | odd] columns, where the taps of output
/// pixel x are odd[x − 1], even[x], odd[x]. The lanes cover whole rows (the
/// groups at either end load the zero padding lane by lane); rows of fewer
/// than 8 output pixels are computed per pixel from `input` (`h` rows).
fn conv3_block_strip(isa: Isa, g: &Lanes<'_>, input: &[f32], h: usize, rows: &mut [&mut [f32]; OB], x0: usize, x1: usize) {
    let ow = rows[0].len();
    let done = if ow < 8 || !g.fits() {
        x0
    } else {
        match isa {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `conv` runs an instruction set only where it is
            // available (checked in `Layer::new`); `g.fits()` holds.
            Isa::Avx2Fma => unsafe { avx2::conv3_lanes(g, rows, x0, x1) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as above.
            Isa::Avx512 => unsafe { avx512::conv3_lanes(g, rows, x0, x1) },
            _ => conv3_lanes(g, rows, x0, x1),
        }
    };
    let (w, plane, stride) = (g.w, g.plane, g.stride);
    for (b, row) in rows.iter_mut().enumerate() {
        for px in done..x1.min(row.len()) {
            let mut a = g.bias[b];
            for i in 0..g.cin {
                let Some(src) = input.get(i * plane..i * plane + w * h) else { return };
                for (ky, r) in g.src_rows.iter().enumerate() {
                    let Some(sy) = *r else { continue };
                    for kx in 0..3 {
                        let sx = (stride * px + kx) as isize - 1;
                        if sx >= 0 && (sx as usize) < w {
                            a += g.wts[((i * 3 + ky) * 3 + kx) * OB + b] * src[sy * w + sx as usize];
                        }
                    }
                }
            }
            row[px] = if g.leaky { leaky(a) } else { a };
        }
    }
}

/// What the lanes of one block of `OB` output channels read, for one output
/// row (see [`conv3_block_strip`]).
struct Lanes<'a> {
    /// The block's weights, `[tap][OB]` (tap = (i · 3 + ky) · 3 + kx).
    wts: &'a [f32],
    cin: usize,
    lanes: &'a [f32],
    w: usize,
    /// Distance between two input planes (≥ w · h).
    plane: usize,
    /// The 3 input rows (`None`: the zero padding).
    src_rows: [Option<usize>; 3],
    stride: usize,
    bias: [f32; OB],
    /// Whether the lanes apply the leaky ReLU before they store (else the
    /// caller applies the layer's activation).
    leaky: bool,
}

impl Lanes<'_> {
    /// Whether every value the lanes read lies inside `lanes` and `wts`: the
    /// unchecked loads of the AVX2 lanes rely on it.
    fn fits(&self) -> bool {
        let rows_fit = self.src_rows.iter().flatten().all(|&sy| (sy + 1) * self.w <= self.plane);
        rows_fit && self.stride <= 2 && self.lanes.len() >= self.cin * self.plane && self.wts.len() >= self.cin * 9 * OB
    }
}

/// The 8 values `s[x..x + 8]`, zeros for those outside `s` (the zero padding:
/// x = −1 at a row's start, x + 8 > len at its end).
#[inline(always)]
fn load8(s: &[f32], x: isize) -> wide::f32x8 {
    let c = usize::try_from(x).ok().and_then(|x| s.get(x..x + 8)).and_then(|c| <&[f32; 8]>::try_from(c).ok());
    wide::f32x8::from(match c {
        Some(c) => *c,
        None => padded8(s, x),
    })
}

/// `s[x..x + 8]` with zeros outside `s` (the padded loads' slow path): the
/// part inside `s` copied, the rest left zero.
#[cold]
fn padded8(s: &[f32], x: isize) -> [f32; 8] {
    let mut a = [0f32; 8];
    // lanes before s[0], and the first element of `s` read
    let skip = x.clamp(-8, 0).unsigned_abs();
    let start = usize::try_from(x).unwrap_or(0);
    if let Some(tail) = s.get(start..) {
        let n = (8 - skip).min(tail.len());
        a[skip..skip + n].copy_from_slice(&tail[..n]);
    }
    a
}

/// The 8-pixel groups of [`conv3_block_strip`] with `wide` (`OB`
/// accumulators per group, 3 loads and 3·`OB` multiply-adds per input row
/// and channel) over output pixels `x0..x1` (rows of at least 8); returns
/// `x1`.
fn conv3_lanes(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB], x0: usize, x1: usize) -> usize {
    use wide::f32x8;
    let (w, plane, ew) = (g.w, g.plane, g.w.div_ceil(2));
    let mut x = x0;
    while x < x1 {
        // the last group is shifted left to end at `x1` (it recomputes a few
        // pixels, bit-identically: every group starts from the bias)
        let xs = x.min(x1.max(8) - 8);
        let xi = xs as isize;
        let mut acc = g.bias.map(f32x8::splat);
        for i in 0..g.cin {
            let src = &g.lanes[i * plane..];
            for (ky, r) in g.src_rows.iter().enumerate() {
                let Some(sy) = *r else { continue };
                let srow = &src[sy * w..(sy + 1) * w];
                let t = (i * 3 + ky) * 3;
                let v = if g.stride == 1 {
                    [load8(srow, xi - 1), load8(srow, xi), load8(srow, xi + 1)]
                } else {
                    let (even, odd) = srow.split_at(ew);
                    [load8(odd, xi - 1), load8(even, xi), load8(odd, xi)]
                };
                for (kx, vk) in v.iter().enumerate() {
                    let wk = &g.wts[(t + kx) * OB..(t + kx + 1) * OB];
                    for (a, &wt) in acc.iter_mut().zip(wk) {
                        *a = f32x8::splat(wt).mul_add(*vk, *a);
                    }
                }
            }
        }
        for (a, r) in acc.iter().zip(rows.iter_mut()) {
            let a = if g.leaky { a.simd_lt(f32x8::ZERO).select(*a * f32x8::splat(LEAKY_SLOPE), *a) } else { *a };
            r[xs..xs + 8].copy_from_slice(&a.to_array());
        }
        x = xs + 8;
    }
    x1
}

/// One output row of a 3×3 stride-1 convolution (`prow` holds the bias):
/// 8-pixel groups accumulate every input channel and tap in registers (one
/// load and one multiply-add per 8 products); the first and last pixels of
/// the row, which touch the zero padding, per pixel.
fn conv3_row_lanes(wts: &[f32], cin: usize, input: &[f32], (w, h, plane): (usize, usize, usize), y: usize, prow: &mut [f32]) {
    use wide::f32x8;
    let rows: [Option<usize>; 3] = [y.checked_sub(1), Some(y), (y + 1 < h).then_some(y + 1)];
    let load = |s: &[f32], x: usize| -> f32x8 {
        let c: &[f32; 8] = s[x..x + 8].try_into().unwrap_or(&[0.0; 8]);
        f32x8::from(*c)
    };
    // groups [x, x + 8) with 1 ≤ x and x + 9 ≤ w: every tap inside the row
    let mut x = 1;
    while x + 9 <= w {
        let mut acc = f32x8::from(<[f32; 8]>::try_from(&prow[x..x + 8]).unwrap_or([0.0; 8]));
        for i in 0..cin {
            let src = &input[i * plane..i * plane + w * h];
            for (ky, r) in rows.iter().enumerate() {
                let Some(sy) = *r else { continue };
                let srow = &src[sy * w..(sy + 1) * w];
                let t = (i * 3 + ky) * 3;
                acc += f32x8::splat(wts[t]) * load(srow, x - 1);
                acc += f32x8::splat(wts[t + 1]) * load(srow, x);
                acc += f32x8::splat(wts[t + 2]) * load(srow, x + 1);
            }
        }
        prow[x..x + 8].copy_from_slice(&acc.to_array());
        x += 8;
    }
    // the rest, per pixel (x = 0, and the tail)
    for px in core::iter::once(0).chain(x..w) {
        let mut a = prow[px];
        for i in 0..cin {
            let src = &input[i * plane..i * plane + w * h];
            for (ky, r) in rows.iter().enumerate() {
                let Some(sy) = *r else { continue };
                for kx in 0..3 {
                    let sx = px as isize + kx as isize - 1;
                    if sx >= 0 && (sx as usize) < w {
                        a += wts[(i * 3 + ky) * 3 + kx] * src[sy * w + sx as usize];
                    }
                }
            }
        }
        prow[px] = a;
    }
}

/// `out = concat(upsample×2(low) cropped to sw × sh, skip)` along channels;
/// `low` (`cl` planes of `lw × lh`) has planes `lp` apart, `skip` (`cs`
/// planes of `sw × sh`) and `out` `sp` apart.
#[allow(clippy::too_many_arguments)]
pub fn concat_upsampled(
    low: &[f32],
    cl: usize,
    (lw, lh, lp): (usize, usize, usize),
    skip: &[f32],
    cs: usize,
    (sw, sh, sp): (usize, usize, usize),
    out: &mut [f32],
) -> Result<(), Error> {
    let out = Planes::new(out, cl + cs, sp, sw, sh)?;
    let cat = Concat::new(low, cl, (lw, lh, lp), skip, cs, sp, &out)?;
    // SAFETY: `out` borrows the caller's tensor exclusively; this is its only user.
    unsafe { cat.rows(&out, 0, sh) };
    Ok(())
}

/// The inputs of a [`concat_upsampled`], checked, to write row by row.
#[derive(Clone, Copy, Debug)]
pub struct Concat<'a> {
    low: &'a [f32],
    cl: usize,
    lw: usize,
    lp: usize,
    skip: &'a [f32],
    cs: usize,
    sp: usize,
}

impl<'a> Concat<'a> {
    /// Checks the shapes against `out` (`cl + cs` planes of `sw × sh`).
    pub fn new(
        low: &'a [f32],
        cl: usize,
        (lw, lh, lp): (usize, usize, usize),
        skip: &'a [f32],
        cs: usize,
        sp: usize,
        out: &Planes<'_>,
    ) -> Result<Self, Error> {
        let (sw, sh) = (out.width, out.height);
        if lp < lw * lh
            || sp < sw * sh
            || low.len() < cl * lp
            || skip.len() < cs * sp
            || out.count < cl + cs
            || lw < sw.div_ceil(2)
            || lh < sh.div_ceil(2)
        {
            return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed: (cl + cs) * sp, len: out.len });
        }
        Ok(Concat { low, cl, lw, lp, skip, cs, sp })
    }

    /// Rows `y0..y1` (clamped to `out`'s height) of every output plane.
    ///
    /// # Safety
    /// No other live slice covers these rows of `out`'s planes.
    pub unsafe fn rows(&self, out: &Planes<'_>, y0: usize, y1: usize) {
        let sw = out.width;
        for y in y0..y1.min(out.height) {
            for c in 0..self.cl {
                let srow = &self.low[c * self.lp + (y / 2) * self.lw..c * self.lp + (y / 2 + 1) * self.lw];
                // SAFETY: the caller keeps this row to this call.
                for (x, d) in unsafe { out.row(c, y) }.iter_mut().enumerate() {
                    *d = srow[x / 2];
                }
            }
            for c in 0..self.cs {
                let at = c * self.sp + y * sw;
                // SAFETY: as above.
                unsafe { out.row(self.cl + c, y) }.copy_from_slice(&self.skip[at..at + sw]);
            }
        }
    }
}
