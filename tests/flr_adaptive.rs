//! The adaptive window (`Blur::Adaptive`) against a plain f64 per-pixel
//! reference of the same estimator (B = 1), tiled against whole frame, the
//! energy moment against its definition, robustness and errors.

mod common;
use common::*;
use lrdenoise::flr::adaptive::BIAS_DISCOUNT;
use lrdenoise::*;
use proptest::prelude::*;

const L: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// One window of the reference: a model and a variance per cell (pixels, or
/// 2×2-pixel cells when pooled), and for each pixel the cells it reads with
/// their weights (one cell, or the bilinear corners on the pooled grid).
struct WindowFit {
    models: Vec<Option<PixelModel>>,
    variances: Vec<f64>,
    corners: Vec<Vec<(usize, f64)>>,
}

/// Pixel `p` sits at `p/2 − 1/4` on a grid of `n` 2-pixel cells (cell centres),
/// clamped to the grid: its two neighbours and bilinear weights.
fn lerp_corners(p: usize, n: usize) -> [(usize, f64); 2] {
    let at = (p as f64 / 2.0 - 0.25).clamp(0.0, (n - 1) as f64);
    let lo = at.floor() as usize;
    let t = at - lo as f64;
    [(lo, 1.0 - t), ((lo + 1).min(n - 1), t)]
}

/// Window `sigma` of the adaptive reference at B = 1, pooled (cells of 2×2
/// pixels, the Gaussian over cell offsets with σ/2 and ⌈3σ/2⌉ cells) or not.
/// `valid`: the pixels the library fits (every guide finite, also those a
/// guide subset leaves out).
fn window_fit(
    cfg: &FlrConfig,
    sigma: f32,
    pooled: bool,
    (w, h): (usize, usize),
    guides: &[Vec<f64>],
    valid: &[bool],
    y: &[f32],
) -> WindowFit {
    let q = guides.len();
    let scales = frame_scales(w, h, guides, valid);
    let g = |i: usize| (0..q).map(|a| guides[a][i]).collect::<Vec<_>>();
    let luma = |m: &PixelModel, i: usize| (0..3).map(|c| L[c] * m.predict(&g(i), c)).sum::<f64>();
    let light = |i: usize| (0..3).map(|c| L[c] * y[3 * i + c] as f64).sum::<f64>();
    let one = FlrConfig { blur: Blur::Gaussian { sigma, radius: None }, ..*cfg };
    let area = 4.0 * std::f64::consts::PI * (sigma as f64).powi(2);
    let (factor, blur) = if pooled {
        let r = (3.0 * sigma / 2.0 - 1e-4).ceil();
        (2, Blur::Gaussian { sigma: sigma / 2.0, radius: Some(r) })
    } else {
        (1, one.blur)
    };
    let (kern, r) = window_kernel(blur);
    let (cw, ch) = (w.div_ceil(factor), h.div_ceil(factor));
    let cell_valid: Vec<bool> = (0..cw * ch).map(|_| true).collect();
    let mut models = vec![];
    let mut variances = vec![];
    for cy in 0..ch as isize {
        for cx in 0..cw as isize {
            // the window's cells, then their valid pixels
            let mut taps = vec![];
            for (c, wt) in window_taps(&kern, r, (cw, ch), &cell_valid, (cx, cy)) {
                let (x0, y0) = ((c % cw) * factor, (c / cw) * factor);
                for yy in y0..(y0 + factor).min(h) {
                    for xx in x0..(x0 + factor).min(w) {
                        if valid[yy * w + xx] {
                            taps.push((yy * w + xx, wt));
                        }
                    }
                }
            }
            let m = fit_taps(&one, guides, y, &taps, &scales);
            let n: f64 = taps.iter().map(|t| t.1).sum();
            let v = match &m {
                Some(m) => {
                    let resid = taps.iter().map(|&(i, wt)| wt * (light(i) - luma(m, i)).powi(2)).sum::<f64>() / n;
                    resid * (q + 1) as f64 / (area * (n / (factor * factor) as f64).min(1.0)).max(1.0)
                }
                None => f64::INFINITY,
            };
            models.push(m);
            variances.push(v);
        }
    }
    let corners = (0..w * h)
        .map(|k| {
            let (px, py) = (k % w, k / w);
            if !pooled {
                return vec![(k, 1.0)];
            }
            let mut c = vec![];
            for (yy, wy) in lerp_corners(py, ch) {
                for (xx, wx) in lerp_corners(px, cw) {
                    if wy * wx > 0.0 {
                        c.push((yy * cw + xx, wy * wx));
                    }
                }
            }
            c
        })
        .collect();
    WindowFit { models, variances, corners }
}

/// The adaptive estimator written out per pixel in f64: each window's models
/// fitted directly (on 2×2-pixel cells for the windows the library pools, and
/// interpolated to the pixel); with `adaptive_without_ao`, window 0 fitted
/// again on the guides without AO; residual variances measured directly over
/// the window (with each fit's own coefficient count); the bias term from the
/// predictions' squared difference over the smallest window; weights 1 /
/// (bias² + variance).
fn adaptive_reference(cfg: &FlrConfig, w: usize, h: usize, guides: &[Vec<f64>], y: &[f32]) -> Vec<f64> {
    if let Some(s) = demodulation(cfg, guides) {
        // the estimator on y / s, its output times s (`FlrConfig::ao_demodulation`)
        let plain = FlrConfig { ao_demodulation: None, ..*cfg };
        let mut out = adaptive_reference(&plain, w, h, guides, &demodulate(y, &s));
        out.iter_mut().enumerate().for_each(|(i, v)| *v *= s[i / 3]);
        return out;
    }
    let Blur::Adaptive { sigmas } = cfg.blur else { panic!("adaptive only") };
    assert_eq!(cfg.block, 1);
    let q = guides.len();
    let pooled = |s: usize| s > 0 && lrdenoise::flr::adaptive::pooled(sigmas[s], 1);
    let valid = valid_pixels(w, h, guides, y);
    // each candidate's fit and the guides it uses
    let all: Vec<usize> = (0..q).collect();
    let mut fits: Vec<_> = (0..3).map(|s| (window_fit(cfg, sigmas[s], pooled(s), (w, h), guides, &valid, y), all.clone())).collect();
    if cfg.adaptive_without_ao {
        let ao = cfg.guides.ao_channel().expect("AO");
        let keep: Vec<usize> = all.iter().copied().filter(|&a| a != ao).collect();
        let sub: Vec<Vec<f64>> = keep.iter().map(|&a| guides[a].clone()).collect();
        fits.push((window_fit(cfg, sigmas[0], false, (w, h), &sub, &valid, y), keep));
    }
    let n = fits.len();
    let first = window_kernel(Blur::Gaussian { sigma: sigmas[0], radius: None });
    // candidate `s`'s prediction of channel `c` at pixel `i` with pixel `k`'s model
    let predict = |s: usize, k: usize, i: usize, c: usize| -> Option<f64> {
        let (f, keep) = &fits[s];
        let g: Vec<f64> = keep.iter().map(|&a| guides[a][i]).collect();
        f.corners[k].iter().map(|&(cell, wt)| f.models[cell].as_ref().map(|m| wt * m.predict(&g, c))).sum()
    };
    let luma = |s: usize, k: usize, i: usize| (0..3).map(|c| predict(s, k, i, c).map(|p| L[c] * p)).sum::<Option<f64>>();
    let mut out = vec![0.0; 3 * w * h];
    for k in 0..w * h {
        let (px, py) = ((k % w) as isize, (k / w) as isize);
        let taps0 = window_taps(&first.0, first.1, (w, h), &valid, (px, py));
        let n0: f64 = taps0.iter().map(|t| t.1).sum();
        let mut v = vec![f64::INFINITY; n];
        let mut gap = vec![0.0; n];
        for s in 0..n {
            if luma(s, k, k).is_none() {
                continue;
            }
            let f = &fits[s].0;
            v[s] = f.corners[k].iter().map(|&(cell, wt)| wt * f.variances[cell]).sum();
            if s > 0 && luma(0, k, k).is_some() {
                gap[s] = taps0.iter().map(|&(i, wt)| wt * (luma(s, k, i).unwrap() - luma(0, k, i).unwrap()).powi(2)).sum::<f64>() / n0;
            }
        }
        let mut wts = vec![0.0; n];
        for s in 0..n {
            let mse = if s == 0 { v[0] } else { (gap[s] - BIAS_DISCOUNT * (v[0] - v[s]).max(0.0)).max(0.0) + v[s] };
            wts[s] = if mse.is_finite() { 1.0 / mse.max(1e-300) } else { 0.0 };
        }
        let total: f64 = wts.iter().sum();
        for c in 0..3 {
            out[3 * k + c] = (0..n).filter(|&s| wts[s] > 0.0).map(|s| wts[s] * predict(s, k, k, c).unwrap()).sum::<f64>() / total;
        }
    }
    out
}

fn adaptive(set: GuideSet, block: usize, sigmas: [f32; 3]) -> FlrConfig {
    FlrConfig { blur: Blur::Adaptive { sigmas }, ..cfg(set, block) }
}

/// Nearly unregularised, so the library's residual formula equals the measured one.
fn adaptive_plain(set: GuideSet, sigmas: [f32; 3]) -> FlrConfig {
    FlrConfig { regularization: Regularization::Normalized { eps_mul: 0.0, eps_add: 1e-7 }, ..adaptive(set, 1, sigmas) }
}

/// At B = 1 every pixel is a cell: the library is the reference up to the
/// residual formula (`E[ℓ²] − E[ℓ]² − βᵀcov` vs measured, equal without
/// regularisation) and f32 moments. The windows disagree by far more than the
/// tolerance, so a wrong weight would show.
#[test]
fn block1_matches_reference() {
    // [1, 2, 3.5]: windows 1 and 2 on the pooled grid; [0.6, 1, 1.4]: none pooled.
    for (sigmas, pooled) in [([1.0, 2.0, 3.5], true), ([1.0, 1.2, 1.4], false)] {
        // seed 4: AO is not the last guide (a user channel follows it), so the
        // AO-free fit reorders the system before factoring
        let ao_then_user = GuideSet { depth: false, user: 1, ..GuideSet::NORMAL_DEPTH_AO };
        for (seed, set) in [(1, GuideSet::NORMAL_DEPTH_AO), (2, GuideSet::NORMAL_DEPTH), (3, GuideSet::NONE), (4, ao_then_user)] {
            let mut f = Owned::synthetic(29, 23, seed, 0.6);
            if set.user > 0 {
                f.user = vec![(0..f.w * f.h).map(|i| ((i * 7919) % 101) as f32 / 101.0).collect()];
            }
            let c = adaptive_plain(set, sigmas);
            let flr = Flr::new(c, f.w, f.h).unwrap();
            assert_eq!((flr.window_pooled(0), flr.window_pooled(1), flr.window_pooled(2)), (false, pooled, pooled));
            let (out, _) = run(c, &f);
            let ch = f.channels(set);
            let want = adaptive_reference(&c, f.w, f.h, &ch, &f.noisy);
            let (max, mean) = diff(&out, &want);
            assert!(max < 1e-3 && mean < 1e-5, "{sigmas:?} {set:?}: max {max} mean {mean}");
            if set.ao {
                // window 0 without AO as a fourth candidate: the reference with it,
                // and far from the three-window blend
                let c4 = FlrConfig { adaptive_without_ao: true, ..c };
                let (out4, _) = run(c4, &f);
                let (max4, mean4) = diff(&out4, &adaptive_reference(&c4, f.w, f.h, &ch, &f.noisy));
                assert!(max4 < 1e-3 && mean4 < 1e-5, "{sigmas:?} without AO: max {max4} mean {mean4}");
                let three: Vec<f64> = out.iter().map(|&v| v as f64).collect();
                let (m, _) = diff(&out4, &three);
                assert!(m > 20.0 * max4, "{sigmas:?}: the AO-free candidate moves the blend only {m}");
            }
            // sensitivity: each single window is far from the blend
            for s in [sigmas[0], sigmas[2]] {
                let single = reference(&FlrConfig { blur: Blur::Gaussian { sigma: s, radius: None }, ..c }, f.w, f.h, &ch, &f.noisy);
                let (m, _) = diff(&out, &single);
                assert!(m > 20.0 * max, "{sigmas:?} {set:?} sigma {s}: blend only {m} from the single window");
            }
        }
    }
}

/// The blend is what the estimator is for: on a frame whose light has a hard
/// shadow the guides do not see, next to flat regions, it has less error than
/// the middle window alone (and than either extreme).
#[test]
fn shadow_and_flat_regions_choose_their_window() {
    let (w, h) = (160, 160);
    let mut f = Owned::synthetic(w, h, 4, 0.0);
    let mut rng = Rng(99);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let shadow = if (20..32).contains(&x) && (20..70).contains(&y) { 0.15 } else { 1.0 };
            for c in 0..3 {
                let v = f.clean[3 * i + c] * shadow;
                f.clean[3 * i + c] = v;
                // exponential noise (mean 1, standard deviation 1): few-sample light
                f.noisy[3 * i + c] = v * -(1.0 - rng.f32()).ln();
            }
        }
    }
    let set = GuideSet::NORMAL_DEPTH_AO;
    let err = |c: FlrConfig| {
        let (out, _) = run(c, &f);
        out.iter().zip(&f.clean).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>()
    };
    let blend = err(FlrConfig { blur: Blur::Adaptive { sigmas: [6.0, 12.0, 20.0] }, ..FlrConfig::with_guides(set) });
    for s in [6.0, 12.0, 20.0] {
        let single = err(FlrConfig { blur: Blur::Gaussian { sigma: s, radius: None }, ..FlrConfig::with_guides(set) });
        assert!(blend < single, "blend {blend} vs sigma {s}: {single}");
    }
}

/// Tile by tile through the public stages (reverse tile order) is bit-identical
/// to `denoise`, and so is the scalar kernel within rounding.
#[test]
fn tiled_equals_whole_frame() {
    // (61, 45, 8) with σ 3/6/11 fits every window on the block grid; the others pool.
    // The awkward sizes run the default sigmas (the default window).
    let d = lrdenoise::flr::config::DEFAULT_SIGMAS;
    for (w, h, block, sigmas) in [
        (61, 45, 8, [3.0, 6.0, 11.0]),
        (75, 53, 8, [6.0, 12.0, 20.0]),
        // more cell rows than `denoise`'s rings hold (blurred rows, raw moments)
        (40, 300, 8, d),
        (33, 70, 4, [3.0, 6.0, 11.0]),
        (7, 3, 1, [3.0, 6.0, 11.0]),
        (1, 1, 8, d),
        (255, 9, 8, d),
        (256, 9, 8, d),
        (257, 9, 8, d),
    ] {
        for without_ao in [false, true] {
            tiled_case(w, h, block, sigmas, without_ao);
        }
    }
}

/// One case of [`tiled_equals_whole_frame`]: every stage tile by tile,
/// bottom to top, against `denoise`; the scalar kernels against SIMD.
fn tiled_case(w: usize, h: usize, block: usize, sigmas: [f32; 3], without_ao: bool) {
    {
        let f = Owned::synthetic(w, h, 5, 0.5);
        let set = GuideSet::NORMAL_DEPTH_AO;
        let c = FlrConfig { adaptive_without_ao: without_ao, ..adaptive(set, block, sigmas) };
        let (whole, _) = run(c, &f);
        let flr = Flr::new(c, w, h).unwrap();
        let frame = f.frame(set);
        let cf = flr.check_frame(&frame).unwrap();
        let mut scratch = vec![0f64; flr.scratch_len()];
        let p = flr.split_scratch(&mut scratch, 1).unwrap();
        let mut stats = flr.prepare(&cf);
        let nt = flr.tile_count();
        for t in (0..nt).rev() {
            flr.moments_tile(&cf, &stats, t, &mut p.cells[flr.cells_tile_range(t).unwrap()], p.workers).unwrap();
        }
        flr.finish_stats(p.cells, &mut stats).unwrap();
        assert_eq!(flr.scale_count(), 3);
        assert_eq!(flr.window_pooled(1), block < 8 || sigmas[1] >= 12.0, "{w}x{h} B={block}");
        if let Some(s) = flr.pooled_window() {
            for t in (0..nt).rev() {
                let r = flr.window_cells_tile_range(s, t).unwrap();
                flr.pool_tile(t, &p.cells[flr.cells_tile_range(t).unwrap()], &mut p.pooled[r]).unwrap();
            }
        }
        for s in 0..3 {
            let n = flr.window_cells_tile_range(s, nt - 1).unwrap().end;
            let src: &[f64] = if flr.window_pooled(s) { p.pooled } else { p.cells };
            for t in (0..nt).rev() {
                flr.blur_rows_tile_at(s, t, src, &mut p.tmp[flr.window_cells_tile_range(s, t).unwrap()]).unwrap();
            }
            let dst: &mut [f64] = if s == 0 { p.first } else { &mut p.blurred[..n] };
            for t in (0..nt).rev() {
                let r = flr.window_cells_tile_range(s, t).unwrap();
                flr.blur_cols_tiles_at(s, t..t + 1, &p.tmp[..n], &mut dst[r.clone()]).unwrap();
                let (m, v) = (flr.scale_models_tile_range(s, t).unwrap(), flr.scale_variances_tile_range(s, t).unwrap());
                flr.solve_tile_at(s, &stats, t, &dst[r], &mut p.scale_models[m], &mut p.variances[v]).unwrap();
            }
        }
        for t in (0..nt).rev() {
            let r = flr.cells_tile_range(t).unwrap();
            flr.blend_tile(t, &p.first[r], p.scale_models, p.variances, &mut p.models[flr.models_tile_range(t).unwrap()]).unwrap();
        }
        let mut out = vec![0f32; 3 * w * h];
        for t in (0..nt).rev() {
            let (y0, y1) = flr.tile_pixel_rows(t).unwrap();
            let mut band = ImageViewMut::interleaved(&mut out[3 * w * y0..3 * w * y1], w, y1 - y0, 3).unwrap();
            flr.apply_tile(&cf, &stats, t, p.models, p.workers, &mut band).unwrap();
        }
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&out), bits(&whole), "{w}x{h} B={block} without_ao {without_ao}");
        let (scalar, _) = run(FlrConfig { kernel: Kernel::Scalar, ..c }, &f);
        let worst = scalar.iter().zip(&whole).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        assert!(worst < 1e-4, "{w}x{h} B={block} without_ao {without_ao}: scalar vs SIMD {worst}");
    }
}

/// The energy moment `e = Σ ℓ²` of every cell, both moment paths, against
/// f64; with the AO demodulation (the default) of the demodulated light `y / s`.
#[test]
fn energy_moment_is_sum_of_squared_luminance() {
    use lrdenoise::kernels::CellLayout;
    for ((block, w, h), demod) in [(8, 40, 16), (4, 13, 9), (16, 35, 17)].into_iter().flat_map(|s| [(s, true), (s, false)]) {
        let f = Owned::synthetic(w, h, 6, 0.7);
        let set = GuideSet::NORMAL_DEPTH_AO;
        let base = FlrConfig { ao_demodulation: if demod { cfg(set, block).ao_demodulation } else { None }, ..cfg(set, block) };
        assert_eq!(base.ao_demodulation.is_some(), demod);
        let s = demodulation(&base, &f.channels(set)).unwrap_or(vec![1.0; w * h]);
        for kernel in [Kernel::Simd, Kernel::Scalar] {
            let c = FlrConfig { kernel, ..base };
            let flr = Flr::new(c, w, h).unwrap();
            let frame = f.frame(set);
            let cf = flr.check_frame(&frame).unwrap();
            let mut scratch = vec![0f64; flr.scratch_len()];
            let p = flr.split_scratch(&mut scratch, 1).unwrap();
            let stats = flr.prepare(&cf);
            for t in 0..flr.tile_count() {
                flr.moments_tile(&cf, &stats, t, &mut p.cells[flr.cells_tile_range(t).unwrap()], p.workers).unwrap();
            }
            let lay = CellLayout::new(set.channels());
            let (cx, _) = flr.cells();
            for (i, cell) in p.cells.chunks_exact(lay.k).enumerate() {
                let (bx, by) = (i % cx, i / cx);
                let mut want = 0f64;
                for y in by * block..((by + 1) * block).min(h) {
                    for x in bx * block..((bx + 1) * block).min(w) {
                        let l: f64 = (0..3).map(|ch| L[ch] * f.noisy[3 * (y * w + x) + ch] as f64).sum::<f64>() / s[y * w + x];
                        want += l * l;
                    }
                }
                assert!((cell[lay.e] - want).abs() <= 1e-5 * want.max(1e-3), "{kernel:?} B={block} cell {i}: {} vs {want}", cell[lay.e]);
            }
        }
    }
}

#[test]
fn configuration_errors() {
    let bad = [[6.0, 6.0, 20.0], [12.0, 6.0, 20.0], [f32::NAN, 12.0, 20.0], [-1.0, 12.0, 20.0], [6.0, 12.0, f32::INFINITY]];
    for sigmas in bad {
        let c = FlrConfig { blur: Blur::Adaptive { sigmas }, ..FlrConfig::default() };
        assert!(matches!(Flr::new(c, 64, 64), Err(Error::InvalidConfig(_))), "{sigmas:?}");
    }
    let c = adaptive(GuideSet::NORMAL_DEPTH_AO, 8, [6.0, 12.0, 20.0]);
    let flr = Flr::new(c, 64, 64).unwrap();
    let cells = vec![0f64; flr.cells_tile_len(0).unwrap()];
    let mut tmp = cells.clone();
    assert!(matches!(flr.blur_rows_tile_at(3, 0, &vec![0f64; 64 * 1000], &mut tmp), Err(Error::InvalidTile { .. })));
    // window 1 is pooled: it reads the pooled grid, not the block grid
    assert!(flr.window_pooled(1));
    assert!(matches!(flr.blur_rows_tile_at(1, 0, &vec![0f64; cells.len() * 8 * 8 / 4], &mut tmp), Err(Error::InvalidTile { .. })));
    let mut pooled = vec![0f64; flr.window_cells_tile_range(1, 0).unwrap().len()];
    assert!(matches!(flr.pool_tile(0, &cells[1..], &mut pooled), Err(Error::InvalidTile { .. })));
    assert!(matches!(flr.pool_tile(9, &cells, &mut pooled), Err(Error::InvalidTile { .. })));
    let unpooled = Flr::new(adaptive(GuideSet::NORMAL_DEPTH_AO, 8, [3.0, 6.0, 11.0]), 64, 64).unwrap();
    assert!(matches!(unpooled.pool_tile(0, &cells, &mut pooled), Err(Error::InvalidTile { .. })));
    let single = Flr::new(FlrConfig::default(), 64, 64).unwrap();
    let mut m = vec![0f32; single.models_tile_len(0).unwrap()];
    assert!(matches!(single.blend_tile(0, &cells, &[], &[], &mut m), Err(Error::InvalidTile { .. })));
    // the AO-free candidate needs the adaptive window and AO
    for bad in [
        FlrConfig { adaptive_without_ao: true, ..cfg(GuideSet::NORMAL_DEPTH_AO, 8) },
        FlrConfig { adaptive_without_ao: true, ..adaptive(GuideSet::NORMAL_DEPTH, 8, [6.0, 12.0, 20.0]) },
    ] {
        assert!(matches!(Flr::new(bad, 64, 64), Err(Error::InvalidConfig(_))), "{bad:?}");
    }
    assert!(matches!(single.blur_rows_tile_at(1, 0, &cells, &mut tmp), Err(Error::InvalidTile { .. })));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Garbage in (NaN, ±Inf, HDR 1e-8..1e6, offsets, duplicated or constant
    /// guides): the adaptive window's output is finite and non-negative,
    /// with and without the AO-free candidate.
    #[test]
    fn output_is_finite(
        seed in 0u64..1000, scale in -8i32..7, offset in 0f32..1e4, nan_every in 0usize..40, dup in any::<bool>(), without_ao in any::<bool>(),
    ) {
        let (w, h) = (37, 29);
        let mut f = Owned::synthetic(w, h, seed, 0.8);
        let s = 10f32.powi(scale);
        for v in f.noisy.iter_mut() { *v *= s; }
        for v in f.depth.iter_mut() { *v += offset; }
        if dup { f.ao.clone_from(&f.depth); }
        if nan_every > 0 {
            for (i, v) in f.noisy.iter_mut().enumerate().step_by(nan_every * 7 + 1) { *v = if i % 2 == 0 { f32::NAN } else { f32::INFINITY }; }
            for v in f.normal.iter_mut().step_by(nan_every * 11 + 3) { *v = f32::NAN; }
        }
        let c = adaptive(GuideSet::NORMAL_DEPTH_AO, 8, [6.0, 12.0, 20.0]);
        let (out, _) = run(FlrConfig { clamp_negative: true, adaptive_without_ao: without_ao, ..c }, &f);
        prop_assert!(out.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
}
