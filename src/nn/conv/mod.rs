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
    let isa = if isa.available() { isa } else { Isa::Portable };
    let (ow, oh) = d.out_size(w, h);
    let taps = d.cin * d.k * d.k;
    let (ip, op) = (in_plane, out_plane);
    if ip < w * h || op < ow * oh || input.len() < d.cin * ip || out.len() < d.cout * op || d.params.len() != 2 * (d.cout * taps + d.cout) {
        return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed: d.cout * op, len: out.len() });
    }
    if weights.len() < d.weights_len() {
        return Err(Error::ScratchTooSmall { needed: d.weights_len(), got: weights.len() });
    }
    let wts = &mut weights[..d.weights_len()];
    for (i, v) in wts.iter_mut().enumerate() {
        *v = d.param(i);
    }
    let wts = &*wts;
    // Stride 2: the blocked lanes below run on the even/odd split rows.
    let s2 = d.k == 3 && d.stride == 2 && w / 2 >= 9 && split.len() >= d.cin * ip;
    let (lanes_input, stride): (&[f32], usize) = if s2 {
        let ew = w.div_ceil(2);
        for (sp, dp) in input[..d.cin * ip].chunks_exact(ip).zip(split.chunks_exact_mut(ip)) {
            for (src, dst) in sp[..w * h].chunks_exact(w).zip(dp[..w * h].chunks_exact_mut(w)) {
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
        (&split[..d.cin * ip], 2)
    } else {
        (input, 1)
    };
    // blocks of OB output channels in lanes (3×3 on rows wide enough), the
    // rest one channel at a time
    let blocks = if d.k == 3 && ((d.stride == 1 && w >= 18) || s2) { d.cout / OB } else { 0 };
    let (blocked, rest) = out[..d.cout * op].split_at_mut(blocks * OB * op);
    for y in 0..oh {
        for (k, block) in blocked.chunks_exact_mut(OB * op).enumerate() {
            let mut rows: [&mut [f32]; OB] = Default::default();
            let mut bias = [0f32; OB];
            let mut wb: [&[f32]; OB] = [&[]; OB];
            for (b, (r, p)) in rows.iter_mut().zip(block.chunks_exact_mut(op)).enumerate() {
                let o = k * OB + b;
                bias[b] = d.bias(o);
                wb[b] = &wts[o * taps..(o + 1) * taps];
                *r = &mut p[y * ow..(y + 1) * ow];
                r.fill(bias[b]);
            }
            conv3_rows_block(isa, &wb, d.cin, lanes_input, input, (w, h, ip), y, stride, bias, &mut rows);
            for r in rows.iter_mut() {
                activate(r, act);
            }
        }
        for (j, plane_o) in rest.chunks_exact_mut(op).enumerate() {
            let o = blocks * OB + j;
            let wts = &wts[o * taps..(o + 1) * taps];
            let prow = &mut plane_o[y * ow..(y + 1) * ow];
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
            activate(prow, act);
        }
    }
    Ok(())
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
    let n = sw * sh;
    if lp < lw * lh
        || sp < n
        || low.len() < cl * lp
        || skip.len() < cs * sp
        || out.len() < (cl + cs) * sp
        || lw < sw.div_ceil(2)
        || lh < sh.div_ceil(2)
    {
        return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed: (cl + cs) * sp, len: out.len() });
    }
    for c in 0..cl {
        let src = &low[c * lp..c * lp + lw * lh];
        let dst = &mut out[c * sp..c * sp + n];
        for y in 0..sh {
            let srow = &src[(y / 2) * lw..(y / 2) * lw + lw];
            for (x, d) in dst[y * sw..(y + 1) * sw].iter_mut().enumerate() {
                *d = srow[x / 2];
            }
        }
    }
    out[cl * sp..(cl + cs) * sp].copy_from_slice(&skip[..cs * sp]);
    Ok(())
}
