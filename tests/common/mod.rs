//! Test support: synthetic frames and the slow, obvious f64 reference.
#![allow(dead_code)]

use lrdenoise::{Blur, Flr, FlrConfig, Frame, GuideSet, Guides, ImageView, ImageViewMut, Regularization, Report};

/// xorshift64*: deterministic, dependency-free.
pub struct Rng(pub u64);
impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545F4914F6CDD1D)
    }
    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// An owned frame with every guide (interleaved f32 buffers).
#[derive(Clone)]
pub struct Owned {
    pub w: usize,
    pub h: usize,
    pub noisy: Vec<f32>,
    pub clean: Vec<f32>,
    pub normal: Vec<f32>,
    pub depth: Vec<f32>,
    pub position: Vec<f32>,
    pub ao: Vec<f32>,
    pub user: Vec<Vec<f32>>,
}

impl Owned {
    /// A scene-like frame: a few planar regions with different normals, a
    /// depth ramp, AO darkening near region edges, light an affine function of
    /// the guides per region plus noise of relative amplitude `noise`.
    pub fn synthetic(w: usize, h: usize, seed: u64, noise: f32) -> Owned {
        let mut rng = Rng(seed.wrapping_mul(2654435761).wrapping_add(12345) | 1);
        let n = w * h;
        let mut o = Owned {
            w,
            h,
            noisy: vec![0.0; 3 * n],
            clean: vec![0.0; 3 * n],
            normal: vec![0.0; 3 * n],
            depth: vec![0.0; n],
            position: vec![0.0; 3 * n],
            ao: vec![0.0; n],
            user: vec![],
        };
        let split_x = (w as f32 * (0.3 + 0.4 * rng.f32())) as usize;
        let split_y = (h as f32 * (0.3 + 0.4 * rng.f32())) as usize;
        let coef: Vec<f32> = (0..24).map(|_| rng.f32()).collect();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let region = (x >= split_x) as usize + 2 * (y >= split_y) as usize;
                let nrm = match region {
                    0 => [0.0, 1.0, 0.0],
                    1 => [std::f32::consts::FRAC_1_SQRT_2, 0.0, std::f32::consts::FRAC_1_SQRT_2],
                    2 => [-0.6, 0.0, 0.8],
                    _ => [0.0, 0.0, 1.0],
                };
                let fx = x as f32 / w.max(1) as f32;
                let fy = y as f32 / h.max(1) as f32;
                let depth = 2.0 + 3.0 * fy + region as f32 * 0.5 + 0.3 * fx;
                let ao = (1.0 - 0.6 * (-(((x as f32 - split_x as f32).abs()) / 3.0)).exp()).clamp(0.0, 1.0);
                o.normal[3 * i..3 * i + 3].copy_from_slice(&nrm);
                o.depth[i] = depth;
                o.ao[i] = ao;
                o.position[3 * i..3 * i + 3].copy_from_slice(&[fx * 4.0, depth, fy * 4.0]);
                for c in 0..3 {
                    let k = &coef[region * 6..region * 6 + 6];
                    let v = (0.2 + k[c] * 0.5) * ao + 0.1 * k[3 + c] * depth * 0.3 + 0.05 * nrm[c].abs();
                    o.clean[3 * i + c] = v;
                    let u = rng.f32();
                    // heavy-tailed multiplicative noise (like 1 spp)
                    let m = if u < 0.5 { 2.0 * u } else { 1.0 + noise * 4.0 * (u - 0.5) * (u - 0.5) * 8.0 };
                    o.noisy[3 * i + c] = v * (1.0 - noise + noise * m);
                }
            }
        }
        o
    }

    pub fn guides(&self, set: GuideSet) -> Guides<'_> {
        let (w, h) = (self.w, self.h);
        let mut g = Guides::default();
        if set.normal {
            g.normal = Some(ImageView::interleaved(&self.normal, w, h, 3).unwrap());
        }
        if set.depth {
            g.depth = Some(ImageView::interleaved(&self.depth, w, h, 1).unwrap());
        }
        if set.position {
            g.position = Some(ImageView::interleaved(&self.position, w, h, 3).unwrap());
        }
        if set.ao {
            g.ao = Some(ImageView::interleaved(&self.ao, w, h, 1).unwrap());
        }
        for u in 0..set.user as usize {
            g.user[u] = Some(ImageView::interleaved(&self.user[u], w, h, 1).unwrap());
        }
        g
    }

    pub fn frame(&self, set: GuideSet) -> Frame<'_> {
        Frame::new(ImageView::interleaved(&self.noisy, self.w, self.h, 3).unwrap(), self.guides(set))
    }

    /// Guide channels in kernel order (normal, depth, position, ao, user), per pixel.
    pub fn channels(&self, set: GuideSet) -> Vec<Vec<f64>> {
        let n = self.w * self.h;
        let mut out = vec![];
        if set.normal {
            for c in 0..3 {
                out.push((0..n).map(|i| self.normal[3 * i + c] as f64).collect());
            }
        }
        if set.depth {
            out.push(self.depth.iter().map(|&v| v as f64).collect());
        }
        if set.position {
            for c in 0..3 {
                out.push((0..n).map(|i| self.position[3 * i + c] as f64).collect());
            }
        }
        if set.ao {
            out.push(self.ao.iter().map(|&v| v as f64).collect());
        }
        for u in 0..set.user as usize {
            out.push(self.user[u].iter().map(|&v| v as f64).collect());
        }
        out
    }
}

/// Runs `denoise` with a fresh scratch buffer; returns (output, report).
pub fn run(cfg: FlrConfig, f: &Owned) -> (Vec<f32>, Report) {
    run_frame(cfg, f.w, f.h, &f.frame(cfg.guides))
}

pub fn run_frame(cfg: FlrConfig, w: usize, h: usize, frame: &Frame<'_>) -> (Vec<f32>, Report) {
    let flr = Flr::new(cfg, w, h).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![f32::NAN; w * h * 3];
    let rep = flr.denoise(frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
    (out, rep)
}

/// Least squares `min ‖A x − z_c‖` with the fit shrunk in its orthogonal
/// basis (`lrdenoise::kernels::qr::Shrinkage`), the obvious way in f64:
/// modified Gram–Schmidt on the columns `cols[j]` of A (Q₁ explicit, R upper
/// triangular), `q = Q₁ᵀz`, the residual variance `‖z − Q₁q‖² / (samples −
/// m)`, each `q_l` (l ≥ 1) scaled by `q_l² / (q_l² + κσ̂²)`, then `x = R⁻¹q`
/// (row-major m × k). κ = 0 is plain least squares. Full column rank assumed.
pub fn shrunk_lstsq(cols: &[Vec<f64>], zs: &[Vec<f64>], kappa: f64, samples: usize) -> Vec<f64> {
    let (m, k, rows) = (cols.len(), zs.len(), cols[0].len());
    let mut q = cols.to_vec();
    let mut r = vec![0f64; m * m];
    for j in 0..m {
        for i in 0..j {
            let (done, rest) = q.split_at_mut(j);
            let d: f64 = done[i].iter().zip(&rest[0]).map(|(a, b)| a * b).sum();
            r[i * m + j] = d;
            for (v, u) in rest[0].iter_mut().zip(&done[i]) {
                *v -= d * u;
            }
        }
        let n = q[j].iter().map(|v| v * v).sum::<f64>().sqrt();
        r[j * m + j] = n;
        q[j].iter_mut().for_each(|v| *v /= n);
    }
    let mut x = vec![0f64; m * k];
    for (c, z) in zs.iter().enumerate() {
        let mut qz: Vec<f64> = (0..m).map(|j| (0..rows).map(|t| q[j][t] * z[t]).sum()).collect();
        let rss: f64 = (0..rows).map(|t| (z[t] - (0..m).map(|j| q[j][t] * qz[j]).sum::<f64>()).powi(2)).sum();
        let noise = kappa * rss / (samples - m) as f64;
        if kappa > 0.0 {
            for v in qz.iter_mut().skip(1) {
                let f = *v * *v / (*v * *v + noise);
                *v *= f;
            }
        }
        for i in (0..m).rev() {
            let s: f64 = qz[i] - (i + 1..m).map(|j| r[i * m + j] * x[j * k + c]).sum::<f64>();
            x[i * k + c] = s / r[i * m + i];
        }
    }
    x
}

/// Solves the dense system `a x = b` (n×n, nrhs columns) by Gaussian
/// elimination with partial pivoting (a different algorithm from the library's
/// Cholesky on purpose). Singular pivots give 0.
pub fn gauss(mut a: Vec<f64>, n: usize, mut b: Vec<f64>, nrhs: usize) -> Vec<f64> {
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs())).unwrap();
        for k in 0..n {
            a.swap(col * n + k, piv * n + k);
        }
        for k in 0..nrhs {
            b.swap(col * nrhs + k, piv * nrhs + k);
        }
        let p = a[col * n + col];
        if p.abs() < 1e-300 {
            continue;
        }
        for r in col + 1..n {
            let f = a[r * n + col] / p;
            for k in col..n {
                a[r * n + k] -= f * a[col * n + k];
            }
            for k in 0..nrhs {
                b[r * nrhs + k] -= f * b[col * nrhs + k];
            }
        }
    }
    let mut x = vec![0.0; n * nrhs];
    for k in 0..nrhs {
        for r in (0..n).rev() {
            let p = a[r * n + r];
            if p.abs() < 1e-300 {
                continue;
            }
            let mut s = b[r * nrhs + k];
            for c in r + 1..n {
                s -= a[r * n + c] * x[c * nrhs + k];
            }
            x[r * nrhs + k] = s / p;
        }
    }
    x
}

/// One pixel's fitted model: `y_c = muy[c] + Σ_a beta[a][c] (g_a − mu[a])`.
#[derive(Clone, Debug, Default)]
#[allow(dead_code)]
pub struct PixelModel {
    pub mu: Vec<f64>,
    pub muy: [f64; 3],
    pub beta: Vec<[f64; 3]>,
}

#[allow(dead_code)]
impl PixelModel {
    /// The model's prediction of channel `c` at guide values `g`.
    pub fn predict(&self, g: &[f64], c: usize) -> f64 {
        self.muy[c] + g.iter().zip(&self.mu).zip(&self.beta).map(|((g, m), b)| b[c] * (g - m)).sum::<f64>()
    }
}

/// The reference's window: normalised 1-D kernel and radius.
pub fn window_kernel(blur: Blur) -> (Vec<f64>, isize) {
    match blur {
        Blur::Gaussian { sigma, radius } => {
            let r = radius.unwrap_or(3.0 * sigma).ceil() as isize;
            let s = sigma as f64;
            let k: Vec<f64> = (-r..=r).map(|d| (-(d * d) as f64 / (2.0 * s * s)).exp()).collect();
            let sum: f64 = k.iter().sum();
            (k.iter().map(|v| v / sum).collect::<Vec<_>>(), r)
        }
        Blur::Box { radius } => {
            let r = radius.ceil() as isize;
            (vec![1.0 / (2 * r + 1) as f64; (2 * r + 1) as usize], r)
        }
        Blur::Adaptive { .. } => panic!("one window at a time"),
    }
}

/// The valid pixels of the window around `(px, py)` with their weights.
pub fn window_taps(kern: &[f64], r: isize, (w, h): (usize, usize), valid: &[bool], (px, py): (isize, isize)) -> Vec<(usize, f64)> {
    let mut idx = vec![];
    for dy in -r..=r {
        for dx in -r..=r {
            let (x, yy) = (px + dx, py + dy);
            if x < 0 || yy < 0 || x >= w as isize || yy >= h as isize {
                continue;
            }
            let i = (yy as usize) * w + x as usize;
            if valid[i] {
                idx.push((i, kern[(dx + r) as usize] * kern[(dy + r) as usize]));
            }
        }
    }
    idx
}

/// The AO demodulation's per-pixel scale `s = √(clamp(ao, 0, 1) + c)`, in
/// f64 from its definition (a non-finite AO counts as 1), when
/// `cfg.ao_demodulation` applies (AO among the guides, normalized mode).
#[allow(dead_code)]
pub fn demodulation(cfg: &FlrConfig, guides: &[Vec<f64>]) -> Option<Vec<f64>> {
    let ao = cfg.guides.ao_channel()?;
    let c = cfg.ao_demodulation.filter(|_| matches!(cfg.regularization, Regularization::Normalized { .. }))? as f64;
    Some(guides[ao].iter().map(|&a| (if a.is_finite() { a.clamp(0.0, 1.0) } else { 1.0 } + c).sqrt()).collect())
}

/// Interleaved RGB `y` divided by the per-pixel `s`.
#[allow(dead_code)]
pub fn demodulate(y: &[f32], s: &[f64]) -> Vec<f32> {
    y.iter().enumerate().map(|(i, &v)| (v as f64 / s[i / 3]) as f32).collect()
}

/// Pixels whose noisy value and guides are all finite.
pub fn valid_pixels(w: usize, h: usize, guides: &[Vec<f64>], y: &[f32]) -> Vec<bool> {
    (0..w * h).map(|i| (0..3).all(|c| y[3 * i + c].is_finite()) && guides.iter().all(|g| g[i].is_finite())).collect()
}

/// The f64 reference: per-pixel windowed weighted least squares at full
/// resolution (no blocks), Gaussian or box window, the same regulariser
/// equations written out plainly. `guides[q][pixel]`, `y` interleaved RGB.
/// Pixels with a non-finite value are excluded. Output interleaved RGB, no clamping.
pub fn reference(cfg: &FlrConfig, w: usize, h: usize, guides: &[Vec<f64>], y: &[f32]) -> Vec<f64> {
    reference_weighted(cfg, w, h, guides, y, None)
}

/// [`reference`] with per-pixel sample weights (`Frame::sample_weights`): each
/// pixel's window taps and its share of the frame statistics are multiplied
/// by its weight; a weight that is not finite and positive excludes it.
pub fn reference_weighted(cfg: &FlrConfig, w: usize, h: usize, guides: &[Vec<f64>], y: &[f32], weights: Option<&[f64]>) -> Vec<f64> {
    if let Some(s) = demodulation(cfg, guides) {
        // y / s fitted without it, the prediction times s (`FlrConfig::ao_demodulation`)
        let plain = FlrConfig { ao_demodulation: None, ..*cfg };
        let mut out = reference_weighted(&plain, w, h, guides, &demodulate(y, &s), weights);
        out.iter_mut().enumerate().for_each(|(i, v)| *v *= s[i / 3]);
        return out;
    }
    let q = guides.len();
    let models = reference_models_weighted(cfg, w, h, guides, y, weights);
    let mut out = vec![0.0; 3 * w * h];
    for (k, m) in models.iter().enumerate() {
        if let Some(m) = m {
            let g: Vec<f64> = (0..q).map(|a| guides[a][k]).collect();
            for c in 0..3 {
                out[3 * k + c] = m.predict(&g, c);
            }
        }
    }
    out
}

/// Each pixel's model of [`reference`] (`None` where its window is empty).
pub fn reference_models(cfg: &FlrConfig, w: usize, h: usize, guides: &[Vec<f64>], y: &[f32]) -> Vec<Option<PixelModel>> {
    reference_models_weighted(cfg, w, h, guides, y, None)
}

/// [`reference_models`] with per-pixel weights ([`reference_weighted`]).
fn reference_models_weighted(
    cfg: &FlrConfig,
    w: usize,
    h: usize,
    guides: &[Vec<f64>],
    y: &[f32],
    weights: Option<&[f64]>,
) -> Vec<Option<PixelModel>> {
    let (kern, r) = window_kernel(cfg.blur);
    let pw: Vec<f64> = match weights {
        Some(wt) => wt.iter().map(|&v| if v > 0.0 && v.is_finite() { v } else { 0.0 }).collect(),
        None => vec![1.0; w * h],
    };
    let valid: Vec<bool> = valid_pixels(w, h, guides, y).iter().zip(&pw).map(|(v, p)| *v && *p > 0.0).collect();
    let scales = frame_scales_weighted(w, h, guides, &valid, &pw);
    let mut out = vec![None; w * h];
    for py in 0..h as isize {
        for px in 0..w as isize {
            let mut idx = window_taps(&kern, r, (w, h), &valid, (px, py));
            idx.iter_mut().for_each(|t| t.1 *= pw[t.0]);
            out[(py as usize) * w + px as usize] = fit_taps(cfg, guides, y, &idx, &scales);
        }
    }
    out
}

/// Frame mean and scale of each guide over the valid pixels (two-pass): the
/// normalized solve's standardisation.
pub fn frame_scales(w: usize, h: usize, guides: &[Vec<f64>], valid: &[bool]) -> (Vec<f64>, Vec<f64>) {
    frame_scales_weighted(w, h, guides, valid, &vec![1.0; w * h])
}

/// [`frame_scales`] with each valid pixel counted `pw` times.
fn frame_scales_weighted(w: usize, h: usize, guides: &[Vec<f64>], valid: &[bool], pw: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let q = guides.len();
    let nv = (0..w * h).filter(|&i| valid[i]).map(|i| pw[i]).sum::<f64>();
    let nv = if nv > 0.0 { nv } else { 1.0 };
    let mut fmean = vec![0.0; q];
    let mut fscale = vec![1.0; q];
    for a in 0..q {
        let m: f64 = (0..w * h).filter(|&i| valid[i]).map(|i| pw[i] * guides[a][i]).sum::<f64>() / nv;
        let v: f64 = (0..w * h).filter(|&i| valid[i]).map(|i| pw[i] * (guides[a][i] - m).powi(2)).sum::<f64>() / nv;
        fmean[a] = m;
        let sd = v.sqrt().max(1e-6 * m.abs());
        fscale[a] = if sd > 0.0 { sd } else { 1.0 };
    }
    (fmean, fscale)
}

/// The weighted least-squares model of the pixels `idx` (index, weight):
/// the regulariser equations written out plainly. `None` for an empty window.
pub fn fit_taps(
    cfg: &FlrConfig,
    guides: &[Vec<f64>],
    y: &[f32],
    idx: &[(usize, f64)],
    (fmean, fscale): &(Vec<f64>, Vec<f64>),
) -> Option<PixelModel> {
    let q = guides.len();
    let n: f64 = idx.iter().map(|t| t.1).sum();
    let mut sx = vec![0.0; q];
    let mut sy = [0.0; 3];
    for &(i, wt) in idx {
        for a in 0..q {
            sx[a] += wt * guides[a][i];
        }
        for c in 0..3 {
            sy[c] += wt * y[3 * i + c] as f64;
        }
    }
    if n <= 0.0 {
        return None;
    }
    match cfg.regularization {
        Regularization::Normalized { eps_mul, eps_add } => {
            let mu: Vec<f64> = sx.iter().map(|s| s / n).collect();
            let muy: Vec<f64> = sy.iter().map(|s| s / n).collect();
            // centred covariance (two-pass), standardised by the frame scale
            let mut wm = vec![0.0; q * q];
            let mut cxy = vec![0.0; q * 3];
            for &(i, wt) in idx {
                for a in 0..q {
                    let ea = (guides[a][i] - mu[a]) / fscale[a];
                    for b in 0..q {
                        wm[a * q + b] += wt * ea * (guides[b][i] - mu[b]) / fscale[b];
                    }
                    for c in 0..3 {
                        cxy[a * 3 + c] += wt * ea * (y[3 * i + c] as f64 - muy[c]);
                    }
                }
            }
            let muz: Vec<f64> = (0..q).map(|a| (mu[a] - fmean[a]) / fscale[a]).collect();
            // eq. 18
            for a in 0..q {
                for b in 0..q {
                    wm[a * q + b] = wm[a * q + b] / n + eps_mul * muz[a] * muz[b];
                }
                wm[a * q + a] += eps_mul * muz[a] * muz[a] + eps_add;
            }
            let sig: Vec<f64> = (0..q).map(|a| wm[a * q + a].max(1e-300).sqrt()).collect();
            let mut c = vec![0.0; q * q];
            let mut bh = vec![0.0; q * 3];
            for a in 0..q {
                for b in 0..q {
                    c[a * q + b] = wm[a * q + b] / (sig[a] * sig[b]) + if a == b { eps_add } else { 0.0 };
                }
                for ch in 0..3 {
                    bh[a * 3 + ch] = cxy[a * 3 + ch] / n / sig[a];
                }
            }
            let ah = gauss(c, q, bh, 3);
            let beta = (0..q).map(|a| [0, 1, 2].map(|ch| ah[a * 3 + ch] / sig[a] / fscale[a])).collect();
            Some(PixelModel { mu, muy: [muy[0], muy[1], muy[2]], beta })
        }
        Regularization::Tikhonov { eps } => {
            let d = q + 1;
            let mut xx = vec![0.0; d * d];
            let mut xy = vec![0.0; d * 3];
            for &(i, wt) in idx {
                let mut x = vec![1.0];
                x.extend((0..q).map(|a| guides[a][i]));
                for a in 0..d {
                    for b in 0..d {
                        xx[a * d + b] += wt * x[a] * x[b];
                    }
                    for c in 0..3 {
                        xy[a * 3 + c] += wt * x[a] * y[3 * i + c] as f64;
                    }
                }
            }
            for a in 0..d {
                xx[a * d + a] += eps;
            }
            let coef = gauss(xx, d, xy, 3);
            let beta = (0..q).map(|a| [0, 1, 2].map(|c| coef[(a + 1) * 3 + c])).collect();
            Some(PixelModel { mu: vec![0.0; q], muy: [coef[0], coef[1], coef[2]], beta })
        }
    }
}

/// Largest absolute difference, and the mean absolute difference.
pub fn diff(a: &[f32], b: &[f64]) -> (f64, f64) {
    let mut max: f64 = 0.0;
    let mut sum = 0.0;
    for (x, y) in a.iter().zip(b) {
        let d = (*x as f64 - y).abs();
        max = max.max(d);
        sum += d;
    }
    (max, sum / a.len() as f64)
}

/// The defaults with one Gaussian window of the default σ (what the f64
/// reference computes), `block`, and clamping off (the reference clamps
/// neither negative output nor fireflies; tests/flr_fireflies.rs tests the latter).
pub fn cfg(set: GuideSet, block: usize) -> FlrConfig {
    let blur = Blur::Gaussian { sigma: lrdenoise::flr::config::DEFAULT_SIGMA, radius: None };
    FlrConfig { guides: set, block, blur, clamp_negative: false, fireflies: None, ..FlrConfig::default() }
}

/// `noisy` (interleaved RGB) clamped band by band with the firefly clamp's
/// kernels (`Thresholds`, `clamp_row`), as a caller would before a method
/// that does not clamp: the reference of the methods' clamp tests (and of
/// the temporal stage's). Returns the count clamped.
pub fn pre_clamp(noisy: &mut [f32], w: usize, h: usize, k: f32) -> u64 {
    let mut planes = [vec![0f32; w * h], vec![0f32; w * h], vec![0f32; w * h]];
    for i in 0..w * h {
        for c in 0..3 {
            planes[c][i] = noisy[3 * i + c];
        }
    }
    let mut work = vec![0f32; lrdenoise::fireflies::work_len(w)];
    let mut clamped = 0;
    for band in 0..h.div_ceil(lrdenoise::fireflies::CELL) {
        let rows = band * lrdenoise::fireflies::CELL..((band + 1) * lrdenoise::fireflies::CELL).min(h);
        let mut t = lrdenoise::fireflies::Thresholds::new(&mut work, w).unwrap();
        for y in rows.clone() {
            t.add_row([&planes[0][y * w..][..w], &planes[1][y * w..][..w], &planes[2][y * w..][..w]]);
        }
        let th = t.finish(k);
        for y in rows {
            let [a, b, c] = &mut planes;
            clamped += lrdenoise::fireflies::clamp_row([&mut a[y * w..][..w], &mut b[y * w..][..w], &mut c[y * w..][..w]], 0, th);
        }
    }
    for i in 0..w * h {
        for c in 0..3 {
            noisy[3 * i + c] = planes[c][i];
        }
    }
    clamped as u64
}

/// A `for_each` executor on `workers` scoped std threads, worker `w` taking
/// the indices `w, w + workers, ...`.
pub fn threads(workers: usize) -> impl Fn(usize, &(dyn Fn(usize, usize) + Sync)) {
    move |count, f| {
        std::thread::scope(|s| {
            for w in 0..workers {
                s.spawn(move || (w..count).step_by(workers).for_each(|i| f(i, w)));
            }
        });
    }
}

/// Mean and largest |a − b|, relative to the mean |b| (the reference), as (mean, max).
pub fn rel_diff(a: &[f32], b: &[f32]) -> (f64, f64) {
    let scale = b.iter().map(|v| v.abs() as f64).sum::<f64>() / b.len() as f64 + 1e-6;
    let d = || a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64);
    (d().sum::<f64>() / b.len() as f64 / scale, d().fold(0.0, f64::max) / scale)
}
