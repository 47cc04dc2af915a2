//! The network's layers on planar f32 tensors (`[c][y][x]`, row stride = width):
//! 3×3 (stride 1 or 2, zero padding 1) and 1×1 convolutions with f16 weights,
//! LeakyReLU (0.01) or sigmoid, and "upsample ×2 (nearest) + concat skip".
//! Rows are accumulated with slice arithmetic the compiler vectorises; the
//! 3×3 layers' rows in 8-pixel lanes, with `wide` (any ISA, chosen at
//! compile time) or, where the CPU has them, AVX2 + FMA intrinsics
//! (`avx2`, chosen at run time: see [`Isa`]).

#[cfg(target_arch = "x86_64")]
mod avx2;

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
    fn param(&self, i: usize) -> f32 {
        let b = &self.params[2 * i..2 * i + 2];
        f16::from_le_bytes([b[0], b[1]]).to_f32()
    }
    /// f32 of `weights` scratch [`conv`] needs: `cout · cin · k · k`.
    pub fn weights_len(&self) -> usize {
        self.cout * self.cin * self.k * self.k
    }
    fn bias(&self, o: usize) -> f32 {
        self.param(self.cout * self.cin * self.k * self.k + o)
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
const OB: usize = 4;

pub use crate::isa::Isa;

/// `out = act(conv(input))`; `input` holds `cin` planes of `w × h`, `in_plane`
/// values apart, `out` `cout` planes of the output size, `out_plane` apart
/// (see [`crate::nn::plane_stride`]). `weights`: room for the layer's
/// weights in f32 ([`ConvDesc::weights_len`]), converted from f16 once per
/// call. `split`: for a stride-2 layer, room for `cin · in_plane` values where
/// the input's rows are rearranged as [even columns | odd columns], so the
/// taps become contiguous 8-pixel loads (without it, or for narrow rows,
/// stride 2 runs per pixel). `isa`: the lanes' instruction set;
/// [`Isa::Portable`] where `isa` is not [`Isa::available`].
///
/// Output rows are the outer loop and blocks of `OB` output channels the
/// inner one: the 3·cin input rows an output row reads are fetched into the
/// cache once for all the blocks (blocks outermost re-streamed the whole
/// input tensor from memory `cout / OB` times). Each output row stays in L1
/// while it accumulates every input channel and tap.
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
        let isa = if isa.available() { isa } else { Isa::Portable };
        let taps = d.cin * d.k * d.k;
        let ip = in_plane;
        if ip < w * h || input.len() < d.cin * ip || d.params.len() != 2 * (d.cout * taps + d.cout) {
            return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed: d.cin * ip, len: input.len() });
        }
        if weights.len() < d.weights_len() {
            return Err(Error::ScratchTooSmall { needed: d.weights_len(), got: weights.len() });
        }
        let wts = &mut weights[..d.weights_len()];
        for (i, v) in wts.iter_mut().enumerate() {
            *v = d.param(i);
        }
        let split = split.filter(|s| splits(d, w, h, ip, s.len()));
        let (lanes_input, stride) = match split {
            Some(s) => (&s[..d.cin * ip], 2),
            None => (input, 1),
        };
        // blocks of OB output channels in lanes (3×3 on rows wide enough), the
        // rest one channel at a time
        let blocks = if d.k == 3 && ((d.stride == 1 && w >= 18) || split.is_some()) { d.cout / OB } else { 0 };
        Ok(Layer { isa, d, input, lanes_input, stride, w, h, in_plane: ip, act, wts, blocks })
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
            for k in 0..self.blocks {
                let mut rows: [&mut [f32]; OB] = Default::default();
                let mut bias = [0f32; OB];
                let mut wb: [&[f32]; OB] = [&[]; OB];
                for (b, r) in rows.iter_mut().enumerate() {
                    let o = k * OB + b;
                    bias[b] = d.bias(o);
                    wb[b] = &wts[o * taps..(o + 1) * taps];
                    // SAFETY: row y of plane o is this call's alone (the caller's contract).
                    *r = unsafe { out.row(o, y) };
                    r.fill(bias[b]);
                }
                conv3_rows_block(self.isa, &wb, d.cin, self.lanes_input, input, (w, h, ip), y, self.stride, bias, &mut rows);
                for r in rows.iter_mut() {
                    activate(r, self.act);
                }
            }
            for o in self.blocks * OB..d.cout {
                let wts = &wts[o * taps..(o + 1) * taps];
                // SAFETY: as above.
                let prow = unsafe { out.row(o, y) };
                prow.fill(d.bias(o));
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
/// [`split_rows`], a concatenation in [`concat_rows`]).
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

fn activate(row: &mut [f32], act: Act) {
    match act {
        Act::Leaky => {
            // a select, not a conditional store: it vectorises
            for p in row.iter_mut() {
                *p = if *p < 0.0 { *p * LEAKY_SLOPE } else { *p };
            }
        }
        Act::Sigmoid => {
            for p in row.iter_mut() {
                *p = 1.0 / (1.0 + libm::expf(-*p));
            }
        }
    }
}

/// [`conv3_row_lanes`] for `OB` output channels at once: each 8-pixel load
/// feeds `OB` accumulators. Stride 1 reads `input`; stride 2 reads `lanes`,
/// the input with each row split into [even | odd] columns, where the taps of
/// output pixel x are odd[x − 1], even[x], odd[x]. The lanes cover whole
/// rows (the groups at either end load the zero padding lane by lane); rows
/// of fewer than 8 output pixels are computed per pixel from `input`.
#[allow(clippy::too_many_arguments)]
fn conv3_rows_block(
    isa: Isa,
    wts: &[&[f32]; OB],
    cin: usize,
    lanes: &[f32],
    input: &[f32],
    (w, h, plane): (usize, usize, usize),
    y: usize,
    stride: usize,
    bias: [f32; OB],
    rows: &mut [&mut [f32]; OB],
) {
    let sy = |ky: usize| (stride * y + ky).checked_sub(1).filter(|&r| r < h);
    let src_rows: [Option<usize>; 3] = [sy(0), sy(1), sy(2)];
    let ow = rows[0].len();
    // The lanes cover the whole row (loads past either end read the zero
    // padding); a row narrower than one group goes per pixel.
    let g = Lanes { wts, cin, lanes, w, plane, src_rows, stride, bias };
    let done = if ow < 8 {
        0
    } else {
        match isa {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `conv` runs `Isa::Avx2Fma` only where it is available (checked at its top).
            Isa::Avx2Fma => unsafe { avx2::conv3_lanes(&g, rows) },
            _ => conv3_lanes(&g, rows),
        }
    };
    for (row, wb) in rows.iter_mut().zip(wts) {
        for (px, out) in row.iter_mut().enumerate().skip(done) {
            let mut a = *out;
            for i in 0..cin {
                let src = &input[i * plane..i * plane + w * h];
                for (ky, r) in src_rows.iter().enumerate() {
                    let Some(sy) = *r else { continue };
                    for kx in 0..3 {
                        let sx = (stride * px + kx) as isize - 1;
                        if sx >= 0 && (sx as usize) < w {
                            a += wb[(i * 3 + ky) * 3 + kx] * src[sy * w + sx as usize];
                        }
                    }
                }
            }
            *out = a;
        }
    }
}

/// One output row's 8-pixel groups for [`conv3_rows_block`]: what the lanes
/// read (see there).
struct Lanes<'a> {
    wts: &'a [&'a [f32]; OB],
    cin: usize,
    lanes: &'a [f32],
    w: usize,
    /// Distance between two input planes (≥ w · h).
    plane: usize,
    /// The 3 input rows (`None`: the zero padding).
    src_rows: [Option<usize>; 3],
    stride: usize,
    bias: [f32; OB],
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

/// The 8-pixel groups of [`conv3_rows_block`] with `wide` (`OB` accumulators
/// per group, 3 loads and 3·`OB` multiply-adds per input row and channel);
/// returns the end of the pixels filled (from 0).
fn conv3_lanes(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB]) -> usize {
    use wide::f32x8;
    let (w, plane, ew) = (g.w, g.plane, g.w.div_ceil(2));
    let mut x = 0;
    let mut done = 0;
    let end = rows[0].len(); // the output row (≥ 8)
    while done < end {
        // the last group is shifted left to end at `end` (it recomputes a few
        // pixels, bit-identically: every group starts from the bias)
        x = x.min(end - 8);
        let xi = x as isize;
        let mut acc = g.bias.map(f32x8::splat);
        for i in 0..g.cin {
            let src = &g.lanes[i * plane..];
            for (ky, r) in g.src_rows.iter().enumerate() {
                let Some(sy) = *r else { continue };
                let srow = &src[sy * w..(sy + 1) * w];
                let t = (i * 3 + ky) * 3;
                let (v0, v1, v2) = if g.stride == 1 {
                    (load8(srow, xi - 1), load8(srow, xi), load8(srow, xi + 1))
                } else {
                    let (even, odd) = srow.split_at(ew);
                    (load8(odd, xi - 1), load8(even, xi), load8(odd, xi))
                };
                for (a, wb) in acc.iter_mut().zip(g.wts) {
                    let wb = &wb[t..t + 3];
                    *a = f32x8::splat(wb[0]).mul_add(v0, *a);
                    *a = f32x8::splat(wb[1]).mul_add(v1, *a);
                    *a = f32x8::splat(wb[2]).mul_add(v2, *a);
                }
            }
        }
        for (a, r) in acc.iter().zip(rows.iter_mut()) {
            r[x..x + 8].copy_from_slice(&a.to_array());
        }
        done = x + 8;
        x += 8;
    }
    done
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
