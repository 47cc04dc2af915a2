//! The quality protocol of `shared/DATA.md`, exactly: compare `I = albedo·Ŷ`
//! with `R = albedo·reference`; tone map with the mean luminance of `R`; PSNR,
//! SSIM (scikit-image defaults: 7×7 uniform window, K1 0.01, K2 0.03, sample
//! covariance, reflect padding, border of 3 cropped) and LDR-FLIP on the tone
//! mapped images; rMSE on linear values.

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Scores {
    pub psnr: f64,
    pub ssim: f64,
    pub flip: f64,
    pub rmse: f64,
}

/// Mean luminance of interleaved linear RGB.
pub fn mean_luminance(rgb: &[f32]) -> f64 {
    let n = rgb.len() / 3;
    let s: f64 = rgb.chunks_exact(3).map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64).sum();
    s / n.max(1) as f64
}

/// `tm = (v / (1 + v))^(1/2.2)`, `v = max(I, 0) · 0.5 / L`.
pub fn tonemap(rgb: &[f32], l: f64) -> Vec<f32> {
    let k = if l > 0.0 && l.is_finite() { 0.5 / l } else { 1.0 };
    rgb.iter()
        .map(|&x| {
            let v = (x.max(0.0) as f64 * k).min(f64::MAX);
            let t = if v.is_finite() { v / (1.0 + v) } else { 1.0 };
            t.powf(1.0 / 2.2) as f32
        })
        .collect()
}

pub fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let mse: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / a.len() as f64;
    if mse == 0.0 {
        return f64::INFINITY;
    }
    10.0 * (1.0 / mse).log10()
}

/// scipy.ndimage 'reflect' index (d c b a | a b c d | d c b a).
fn reflect(i: isize, n: isize) -> usize {
    if n == 1 {
        return 0;
    }
    let p = 2 * n;
    let mut m = i.rem_euclid(p);
    if m >= n {
        m = p - 1 - m;
    }
    m as usize
}

/// 7×7 uniform filter with reflect padding (separable), one channel.
fn uniform7(src: &[f64], w: usize, h: usize) -> Vec<f64> {
    let mut tmp = vec![0.0; w * h];
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for d in -3..=3isize {
                s += src[y * w + reflect(x as isize + d, w as isize)];
            }
            tmp[y * w + x] = s / 7.0;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for d in -3..=3isize {
                s += tmp[reflect(y as isize + d, h as isize) * w + x];
            }
            out[y * w + x] = s / 7.0;
        }
    }
    out
}

/// SSIM of interleaved RGB images, averaged over channels (scikit-image
/// `structural_similarity(..., channel_axis=-1, data_range=1)`).
pub fn ssim(a: &[f32], b: &[f32], w: usize, h: usize) -> f64 {
    let (c1, c2) = ((0.01f64).powi(2), (0.03f64).powi(2));
    let np = 49.0;
    let cov_norm = np / (np - 1.0);
    let mut total = 0.0;
    for ch in 0..3 {
        let x: Vec<f64> = (0..w * h).map(|i| a[3 * i + ch] as f64).collect();
        let y: Vec<f64> = (0..w * h).map(|i| b[3 * i + ch] as f64).collect();
        let ux = uniform7(&x, w, h);
        let uy = uniform7(&y, w, h);
        let uxx = uniform7(&x.iter().map(|v| v * v).collect::<Vec<_>>(), w, h);
        let uyy = uniform7(&y.iter().map(|v| v * v).collect::<Vec<_>>(), w, h);
        let uxy = uniform7(&x.iter().zip(&y).map(|(p, q)| p * q).collect::<Vec<_>>(), w, h);
        let (mut s, mut n) = (0.0, 0usize);
        for yy in 3..h.saturating_sub(3) {
            for xx in 3..w.saturating_sub(3) {
                let i = yy * w + xx;
                let vx = cov_norm * (uxx[i] - ux[i] * ux[i]);
                let vy = cov_norm * (uyy[i] - uy[i] * uy[i]);
                let vxy = cov_norm * (uxy[i] - ux[i] * uy[i]);
                let num = (2.0 * ux[i] * uy[i] + c1) * (2.0 * vxy + c2);
                let den = (ux[i] * ux[i] + uy[i] * uy[i] + c1) * (vx + vy + c2);
                s += num / den;
                n += 1;
            }
        }
        total += if n > 0 { s / n as f64 } else { 1.0 };
    }
    total / 3.0
}

fn to_rgb8(v: &[f32]) -> Vec<u8> {
    v.iter().map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8).collect()
}

/// LDR-FLIP error map (NVIDIA FLIP, default 67 pixels per degree) of
/// tone-mapped images, quantised to 8 bits as LDR images are.
pub fn flip_map(test_tm: &[f32], ref_tm: &[f32], w: usize, h: usize) -> Vec<f32> {
    if w < 2 || h < 2 {
        return vec![0.0; w * h];
    }
    let r = nv_flip::FlipImageRgb8::with_data(w as u32, h as u32, &to_rgb8(ref_tm));
    let t = nv_flip::FlipImageRgb8::with_data(w as u32, h as u32, &to_rgb8(test_tm));
    nv_flip::flip(r, t, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec()
}

pub fn rmse(i: &[f32], r: &[f32]) -> f64 {
    i.iter()
        .zip(r)
        .map(|(a, b)| {
            let (a, b) = (*a as f64, *b as f64);
            (a - b).powi(2) / (b * b + 0.01)
        })
        .sum::<f64>()
        / i.len() as f64
}

/// All four scores of a demodulated estimate against the demodulated reference.
pub fn score(estimate: &[f32], reference: &[f32], albedo: &[f32], w: usize, h: usize) -> (Scores, Vec<f32>) {
    let i: Vec<f32> = estimate.iter().zip(albedo).map(|(e, a)| e * a).collect();
    let r: Vec<f32> = reference.iter().zip(albedo).map(|(e, a)| e * a).collect();
    let l = mean_luminance(&r);
    let (ti, tr) = (tonemap(&i, l), tonemap(&r, l));
    let fmap = flip_map(&ti, &tr, w, h);
    let flip = fmap.iter().map(|v| *v as f64).sum::<f64>() / fmap.len().max(1) as f64;
    (Scores { psnr: psnr(&ti, &tr), ssim: ssim(&ti, &tr, w, h), flip, rmse: rmse(&i, &r) }, fmap)
}
