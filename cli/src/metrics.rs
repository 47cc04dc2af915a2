//! The quality protocol of `docs/DATA.md`, exactly: compare `I = albedo·Ŷ`
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

/// Bilinear sample of the 3-channel image `img` at continuous pixel position
/// `(px, py)`; `None` unless all 4 taps are inside.
fn bilinear(img: &[f32], w: usize, h: usize, px: f32, py: f32) -> Option<[f32; 3]> {
    let (fx, fy) = (px.floor(), py.floor());
    if !(fx >= 0.0 && fy >= 0.0 && fx + 1.0 < w as f32 && fy + 1.0 < h as f32) {
        return None;
    }
    let (x, y, ax, ay) = (fx as usize, fy as usize, px - fx, py - fy);
    let at = |x: usize, y: usize, c: usize| img[3 * (y * w + x) + c];
    Some([0, 1, 2].map(|c| {
        (1.0 - ay) * ((1.0 - ax) * at(x, y, c) + ax * at(x + 1, y, c)) + ay * ((1.0 - ax) * at(x, y + 1, c) + ax * at(x + 1, y + 1, c))
    }))
}

/// **Temporal instability (flicker)** of frame t of a sequence: the RMS over
/// pixels and channels of `(O_t − W O_{t−1}) − (R_t − W R_{t−1})`, where `O`, `R`
/// are the tone-mapped albedo-modulated output and reference (as scored), and
/// `W` warps the previous frame to this one with `motion` (previous − current
/// pixel offset, bilinear). Motion-compensated differences of the reference
/// hold what really changes (new surfaces, moving light); what the output adds
/// on top is flicker. Pixels whose 4 taps are not all inside are skipped.
/// 0 = as steady as the reference. `None` without any usable pixel.
pub fn flicker(
    out_tm: &[f32],
    prev_out_tm: &[f32],
    ref_tm: &[f32],
    prev_ref_tm: &[f32],
    motion: &[f32],
    w: usize,
    h: usize,
) -> Option<f64> {
    let (mut s, mut n) = (0f64, 0usize);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (px, py) = (x as f32 + motion[2 * i], y as f32 + motion[2 * i + 1]);
            let (Some(po), Some(pr)) = (bilinear(prev_out_tm, w, h, px, py), bilinear(prev_ref_tm, w, h, px, py)) else { continue };
            for c in 0..3 {
                let d = (out_tm[3 * i + c] - po[c]) as f64 - (ref_tm[3 * i + c] - pr[c]) as f64;
                s += d * d;
                n += 1;
            }
        }
    }
    (n > 0).then(|| (s / n as f64).sqrt())
}

#[cfg(test)]
mod flicker_tests {
    use super::flicker;

    #[test]
    fn steady_output_has_no_flicker_and_noise_has_some() {
        let (w, h) = (16, 8);
        // a ramp that moves one pixel right per frame: motion = (−1, 0)
        let img = |shift: f32| -> Vec<f32> { (0..w * h).flat_map(|i| [((i % w) as f32 - shift) * 0.05; 3]).collect() };
        let motion = [-1.0f32, 0.0].repeat(w * h);
        let (r0, r1) = (img(0.0), img(1.0));
        assert_eq!(flicker(&r1, &r0, &r1, &r0, &motion, w, h), Some(0.0));
        let noisy: Vec<f32> = r1.iter().enumerate().map(|(i, v)| v + if i % 2 == 0 { 0.1 } else { -0.1 }).collect();
        let f = flicker(&noisy, &r0, &r1, &r0, &motion, w, h).unwrap();
        assert!((f - 0.1).abs() < 1e-6, "{f}");
        // motion pointing outside: nothing to compare
        assert_eq!(flicker(&r1, &r0, &r1, &r0, &vec![100.0; 2 * w * h], w, h), None);
    }
}
