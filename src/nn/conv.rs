//! The network's layers on planar f32 tensors (`[c][y][x]`, row stride = width):
//! 3×3 (stride 1 or 2, zero padding 1) and 1×1 convolutions with f16 weights,
//! LeakyReLU (0.01) or sigmoid, and "upsample ×2 (nearest) + concat skip".
//! Rows are accumulated with slice arithmetic the compiler vectorises.

use crate::error::Error;
use half::f16;

/// A convolution: shapes and its f16 parameters (weights `[out][in][k][k]`, then biases).
#[derive(Clone, Copy, Debug)]
pub struct ConvDesc<'b> {
    pub cin: usize,
    pub cout: usize,
    pub k: usize,
    pub stride: usize,
    pub params: &'b [u8],
}

impl ConvDesc<'_> {
    pub(crate) const EMPTY: ConvDesc<'static> = ConvDesc { cin: 0, cout: 0, k: 0, stride: 1, params: &[] };
    #[inline]
    fn param(&self, i: usize) -> f32 {
        let b = &self.params[2 * i..2 * i + 2];
        f16::from_le_bytes([b[0], b[1]]).to_f32()
    }
    fn weight(&self, o: usize, i: usize, ky: usize, kx: usize) -> f32 {
        self.param(((o * self.cin + i) * self.k + ky) * self.k + kx)
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
    Leaky,
    Sigmoid,
}

const LEAKY_SLOPE: f32 = 0.01;

/// `out = act(conv(input))`; `input` holds `cin` planes of `w × h`, `out` at
/// least `cout` planes of the output size.
pub fn conv(d: ConvDesc<'_>, input: &[f32], w: usize, h: usize, out: &mut [f32], act: Act) -> Result<(), Error> {
    let (ow, oh) = d.out_size(w, h);
    if input.len() < d.cin * w * h || out.len() < d.cout * ow * oh || d.params.len() != 2 * (d.cout * d.cin * d.k * d.k + d.cout) {
        return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed: d.cout * ow * oh, len: out.len() });
    }
    for o in 0..d.cout {
        let plane = &mut out[o * ow * oh..(o + 1) * ow * oh];
        plane.fill(d.bias(o));
        for i in 0..d.cin {
            let src = &input[i * w * h..(i + 1) * w * h];
            match (d.k, d.stride) {
                (1, _) => {
                    let wt = d.weight(o, i, 0, 0);
                    for (p, s) in plane.iter_mut().zip(src) {
                        *p += wt * s;
                    }
                }
                (_, 1) => {
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let wt = d.weight(o, i, ky, kx);
                            for y in 0..oh {
                                let sy = y as isize + ky as isize - 1;
                                if sy < 0 || sy >= h as isize {
                                    continue;
                                }
                                let srow = &src[sy as usize * w..(sy as usize + 1) * w];
                                let prow = &mut plane[y * ow..(y + 1) * ow];
                                // x + kx − 1 inside the row
                                let (x0, x1) = (if kx == 0 { 1 } else { 0 }, if kx == 2 { w - 1 } else { w });
                                if x0 >= x1 {
                                    continue;
                                }
                                let s = &srow[x0 + kx - 1..x1 + kx - 1];
                                for (p, v) in prow[x0..x1].iter_mut().zip(s) {
                                    *p += wt * v;
                                }
                            }
                        }
                    }
                }
                _ => {
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let wt = d.weight(o, i, ky, kx);
                            for y in 0..oh {
                                let sy = 2 * y as isize + ky as isize - 1;
                                if sy < 0 || sy >= h as isize {
                                    continue;
                                }
                                let srow = &src[sy as usize * w..(sy as usize + 1) * w];
                                let prow = &mut plane[y * ow..(y + 1) * ow];
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
        }
        match act {
            Act::Leaky => {
                for p in plane.iter_mut() {
                    if *p < 0.0 {
                        *p *= LEAKY_SLOPE;
                    }
                }
            }
            Act::Sigmoid => {
                for p in plane.iter_mut() {
                    *p = 1.0 / (1.0 + libm::expf(-*p));
                }
            }
        }
    }
    Ok(())
}

/// `out = concat(upsample×2(low) cropped to sw × sh, skip)` along channels.
#[allow(clippy::too_many_arguments)]
pub fn concat_upsampled(
    low: &[f32],
    cl: usize,
    lw: usize,
    lh: usize,
    skip: &[f32],
    cs: usize,
    sw: usize,
    sh: usize,
    out: &mut [f32],
) -> Result<(), Error> {
    let n = sw * sh;
    if low.len() < cl * lw * lh || skip.len() < cs * n || out.len() < (cl + cs) * n || lw < sw.div_ceil(2) || lh < sh.div_ceil(2) {
        return Err(Error::BufferTooSmall { arg: crate::error::Arg::Scratch, needed: (cl + cs) * n, len: out.len() });
    }
    for c in 0..cl {
        let src = &low[c * lw * lh..(c + 1) * lw * lh];
        let dst = &mut out[c * n..(c + 1) * n];
        for y in 0..sh {
            let srow = &src[(y / 2) * lw..(y / 2) * lw + lw];
            for (x, d) in dst[y * sw..(y + 1) * sw].iter_mut().enumerate() {
                *d = srow[x / 2];
            }
        }
    }
    out[cl * n..(cl + cs) * n].copy_from_slice(&skip[..cs * n]);
    Ok(())
}
