//! The slow, obvious f64 oracles of BMFR's blockwise fit, FLNR's network and
//! WALR's per-pixel Cholesky (FLR's is `common::reference`), shared by each
//! method's tests and `tests/arch_check.rs`. A test declares it beside
//! `mod common;` as `#[path = "common/oracles.rs"] mod oracles;` (not inside
//! `common`, which the GPU crate's tests include without `wide`).
#![allow(clippy::needless_range_loop)] // loops mirror the definitions
#![allow(dead_code)] // each test uses some of them

use crate::common::{gauss, shrunk_lstsq, Owned, Rng};
use lrdenoise::bmfr::features::mirror as mirror_index;
use lrdenoise::kernels::cholesky::{factor_floor, substitute};
use lrdenoise::Bmfr;
use wide::f32x8;

/// A frame whose guides are random (well-conditioned blocks): depth and two
/// user channels; light affine in them plus noise.
pub fn random_guides(w: usize, h: usize, seed: u64) -> Owned {
    let mut f = Owned::synthetic(w, h, seed, 0.5);
    let mut rng = Rng(seed * 7 + 1);
    f.user = (0..2).map(|_| (0..w * h).map(|_| rng.f32() * 3.0 - 1.0).collect()).collect();
    for i in 0..w * h {
        f.depth[i] = 1.0 + 4.0 * rng.f32();
        for c in 0..3 {
            let v = 0.5 + 0.1 * f.depth[i] + 0.2 * f.user[0][i] * (c as f32 - 1.0) + 0.05 * f.user[1][i];
            f.clean[3 * i + c] = v;
            f.noisy[3 * i + c] = v + 0.3 * (rng.f32() - 0.5);
        }
    }
    f
}

/// The obvious f64 version of one noise-free BMFR frame: per block, features
/// `1, d̂, û₁, û₂, d̂²` (hats: rescaled to [0,1] over the block, mirrored
/// borders), least squares shrunk by the configuration's κ
/// ([`shrunk_lstsq`]: Gram–Schmidt in f64; κ = 0 is plain least squares).
pub fn bmfr_oracle(b: &Bmfr, f: &Owned, index: u32) -> Vec<f64> {
    let (w, h) = (f.w, f.h);
    let bs = b.config().block;
    let (x0, y0) = b.grid_origin(index);
    let (nbx, nby) = b.block_grid(index);
    let mut out = vec![0.0; 3 * w * h];
    for by in 0..nby {
        for bx in 0..nbx {
            let (ox, oy) = (x0 + (bx * bs) as i64, y0 + (by * bs) as i64);
            let mut px = vec![];
            for j in 0..bs as i64 {
                for i in 0..bs as i64 {
                    px.push((mirror_index(ox + i, w), mirror_index(oy + j, h), ox + i, oy + j));
                }
            }
            let raw: Vec<[f64; 3]> = px
                .iter()
                .map(|&(x, y, _, _)| [f.depth[y * w + x] as f64, f.user[0][y * w + x] as f64, f.user[1][y * w + x] as f64])
                .collect();
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for r in &raw {
                for k in 0..3 {
                    lo[k] = lo[k].min(r[k]);
                    hi[k] = hi[k].max(r[k]);
                }
            }
            let feats: Vec<Vec<f64>> = raw
                .iter()
                .map(|r| {
                    let s: Vec<f64> = (0..3).map(|k| (r[k] - lo[k]) / (hi[k] - lo[k])).collect();
                    vec![1.0, s[0], s[1], s[2], s[0] * s[0]]
                })
                .collect();
            let m = 5;
            let cols: Vec<Vec<f64>> = (0..m).map(|a| feats.iter().map(|r| r[a]).collect()).collect();
            let zs: Vec<Vec<f64>> = (0..3).map(|c| px.iter().map(|&(x, y, _, _)| f.noisy[3 * (y * w + x) + c] as f64).collect()).collect();
            let coef = shrunk_lstsq(&cols, &zs, b.config().shrinkage as f64, px.len());
            for (r, &(x, y, ux, uy)) in feats.iter().zip(&px) {
                if ux < 0 || uy < 0 || ux as usize >= w || uy as usize >= h {
                    continue;
                }
                for c in 0..3 {
                    out[3 * (y * w + x) + c] = (0..m).map(|a| r[a] * coef[a * 3 + c]).sum::<f64>().max(0.0);
                }
            }
        }
    }
    out
}

pub fn u32_at(b: &[u8], i: usize) -> usize {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]) as usize
}

/// A version-1 blob with random weights for the given shape, trained (its header
/// says) with one Gaussian window of `sigma` pixels: the exporter's layout.
pub fn blob(cin: usize, cout: usize, widths: &[usize], sigma: f32, seed: u64) -> Vec<u8> {
    let mut b = b"LRDN".to_vec();
    for v in [1, cin, cout, widths.len() - 1] {
        b.extend_from_slice(&(v as u32).to_le_bytes());
    }
    for &c in widths {
        b.extend_from_slice(&(c as u32).to_le_bytes());
    }
    for v in [sigma, 1e-3, 1e-2] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    let c = widths;
    let l = c.len() - 1;
    let mut shapes = vec![(cin, c[0], 3), (c[0], c[0], 1)];
    for i in 1..=l {
        shapes.push((c[i - 1], c[i], 3));
        shapes.push((c[i], c[i], 3));
    }
    for i in (1..=l).rev() {
        shapes.push((c[i] + c[i - 1], c[i - 1], 3));
        shapes.push((c[i - 1], c[i - 1], 3));
    }
    shapes.push((c[0], c[0], 3));
    shapes.push((c[0], cout, 1));
    let n: usize = shapes.iter().map(|&(i, o, k)| o * i * k * k + o).sum();
    b.extend_from_slice(&(n as u32).to_le_bytes());
    let mut rng = Rng(seed);
    for _ in 0..n {
        b.extend_from_slice(&half::f16::from_f32(rng.f32() - 0.5).to_le_bytes());
    }
    b
}

/// The whole network in f64, obviously: every layer by its definition.
pub fn reference(b: &[u8], input: &[f32], w: usize, h: usize) -> Vec<f64> {
    let cin = u32_at(b, 8);
    let cout = u32_at(b, 12);
    let l = u32_at(b, 16);
    let c: Vec<usize> = (0..=l).map(|i| u32_at(b, 20 + 4 * i)).collect();
    let mut pos = 20 + 4 * (l + 1) + 12 + 4;
    let mut params = || {
        let v = half::f16::from_le_bytes([b[pos], b[pos + 1]]).to_f64();
        pos += 2;
        v
    };
    struct T {
        c: usize,
        w: usize,
        h: usize,
        d: Vec<f64>,
    }
    let mut conv = |x: &T, cout: usize, k: usize, stride: usize, act: u8| -> T {
        let wts: Vec<f64> = (0..cout * x.c * k * k).map(|_| params()).collect();
        let bias: Vec<f64> = (0..cout).map(|_| params()).collect();
        let (ow, oh) = if stride == 2 { (x.w.div_ceil(2), x.h.div_ceil(2)) } else { (x.w, x.h) };
        let mut d = vec![0f64; cout * ow * oh];
        let pad = (k / 2) as i64;
        for o in 0..cout {
            for y in 0..oh {
                for xx in 0..ow {
                    let mut s = bias[o];
                    for i in 0..x.c {
                        for ky in 0..k {
                            for kx in 0..k {
                                let sy = (stride * y) as i64 + ky as i64 - pad;
                                let sx = (stride * xx) as i64 + kx as i64 - pad;
                                if sy >= 0 && sx >= 0 && (sy as usize) < x.h && (sx as usize) < x.w {
                                    s += wts[((o * x.c + i) * k + ky) * k + kx] * x.d[(i * x.h + sy as usize) * x.w + sx as usize];
                                }
                            }
                        }
                    }
                    d[(o * oh + y) * ow + xx] = if act == 0 {
                        if s < 0.0 {
                            0.01 * s
                        } else {
                            s
                        }
                    } else {
                        1.0 / (1.0 + (-s).exp())
                    };
                }
            }
        }
        T { c: cout, w: ow, h: oh, d }
    };
    let x = T { c: cin, w, h, d: input.iter().map(|&v| v as f64).collect() };
    let a = conv(&x, c[0], 3, 1, 0);
    let mut cur = conv(&a, c[0], 1, 1, 0);
    let mut skips = vec![];
    for i in 1..=l {
        skips.push(cur);
        let s = skips.last().unwrap();
        let a = conv(s, c[i], 3, 1, 0);
        cur = conv(&a, c[i], 3, 2, 0);
    }
    for i in (1..=l).rev() {
        let s = &skips[i - 1];
        let mut d = vec![];
        for ch in 0..cur.c {
            for y in 0..s.h {
                for xx in 0..s.w {
                    d.push(cur.d[(ch * cur.h + y / 2) * cur.w + xx / 2]);
                }
            }
        }
        d.extend_from_slice(&s.d);
        let cat = T { c: cur.c + s.c, w: s.w, h: s.h, d };
        let a = conv(&cat, c[i - 1], 3, 1, 0);
        cur = conv(&a, c[i - 1], 3, 1, 0);
    }
    let a = conv(&cur, c[0], 3, 1, 0);
    let _ = cout;
    conv(&a, cout, 1, 1, 1).d
}

pub fn random_spd(rng: &mut Rng, m: usize, cond: f32) -> Vec<f64> {
    // A = Q diag Q^T-ish: B B^T + cond I
    let b: Vec<f64> = (0..m * m).map(|_| rng.f32() as f64 - 0.5).collect();
    let mut a = vec![0f64; m * m];
    for i in 0..m {
        for j in 0..m {
            a[i * m + j] = (0..m).map(|k| b[i * m + k] * b[j * m + k]).sum::<f64>() + if i == j { cond as f64 } else { 0.0 };
        }
    }
    a
}

/// WALR's per-pixel Cholesky (`factor_floor` + `substitute`) on 50 random SPD
/// systems of size `M` (condition ~1 and ~100), 8 per lane group: the lanes
/// must equal the scalar f32 path bit for bit, and both the f64 Gauss solve
/// within 2e-3 of the solution's scale.
pub fn cholesky_case<const M: usize>(rng: &mut Rng) -> Result<(), String> {
    for case in 0..50 {
        let cond = if case % 2 == 0 { 0.5 } else { 1e-2 };
        let mats: Vec<Vec<f64>> = (0..8).map(|_| random_spd(rng, M, cond)).collect();
        let rhs: Vec<Vec<f64>> = (0..8).map(|_| (0..3 * M).map(|_| rng.f32() as f64 - 0.5).collect()).collect();
        let mut av = [[f32x8::ZERO; M]; M];
        let mut bv = [[f32x8::ZERO; 3]; M];
        for l in 0..8 {
            for i in 0..M {
                for j in 0..M {
                    av[i][j].as_mut_array()[l] = mats[l][i * M + j] as f32;
                }
                for r in 0..3 {
                    bv[i][r].as_mut_array()[l] = rhs[l][i * 3 + r] as f32;
                }
            }
        }
        let eps = [f32x8::splat(1e-9); M];
        let inv = factor_floor(&mut av, &eps);
        substitute(&av, &inv, &mut bv);
        for l in 0..8 {
            let want = gauss(mats[l].clone(), M, rhs[l].clone(), 3);
            let scale = want.iter().fold(0f64, |a, v| a.max(v.abs()));
            // scalar f32 path: bit-identical to the lanes
            let mut a1 = [[0f32; M]; M];
            let mut b1 = [[0f32; 3]; M];
            for i in 0..M {
                for j in 0..M {
                    a1[i][j] = mats[l][i * M + j] as f32;
                }
                for r in 0..3 {
                    b1[i][r] = rhs[l][i * 3 + r] as f32;
                }
            }
            let inv1 = factor_floor(&mut a1, &[1e-9; M]);
            substitute(&a1, &inv1, &mut b1);
            for i in 0..M {
                for r in 0..3 {
                    let got = bv[i][r].as_array()[l];
                    if got.to_bits() != b1[i][r].to_bits() {
                        return Err(format!("M={M}: lanes {got} vs scalar {}", b1[i][r]));
                    }
                    let err = (got as f64 - want[i * 3 + r]).abs();
                    if err > 2e-3 * scale.max(1.0) {
                        return Err(format!("M={M} cond={cond}: {got} vs {}", want[i * 3 + r]));
                    }
                }
            }
        }
    }
    Ok(())
}
