//! The adaptive window (`Blur::Adaptive`) against a plain f64 per-pixel
//! reference of the same estimator (B = 1), tiled against whole frame, the
//! energy moment against its definition, robustness and errors.

mod common;
use common::*;
use lrdenoise::flr::adaptive::BIAS_DISCOUNT;
use lrdenoise::*;
use proptest::prelude::*;

const L: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The adaptive estimator written out per pixel in f64: each window's model
/// from [`reference_models`]; its residual variance measured directly over the
/// window; the bias term from the predictions' squared difference over the
/// smallest window; weights 1 / (bias² + variance).
fn adaptive_reference(cfg: &FlrConfig, w: usize, h: usize, guides: &[Vec<f64>], y: &[f32]) -> Vec<f64> {
    let Blur::Adaptive { sigmas } = cfg.blur else { panic!("adaptive only") };
    let q = guides.len();
    let one = |s: f32| FlrConfig { blur: Blur::Gaussian { sigma: s, radius: None }, ..*cfg };
    let models: Vec<_> = sigmas.iter().map(|&s| reference_models(&one(s), w, h, guides, y)).collect();
    let kernels: Vec<_> = sigmas.iter().map(|&s| window_kernel(one(s).blur)).collect();
    let valid = valid_pixels(w, h, guides, y);
    let g = |i: usize| (0..q).map(|a| guides[a][i]).collect::<Vec<_>>();
    let luma = |m: &PixelModel, i: usize| (0..3).map(|c| L[c] * m.predict(&g(i), c)).sum::<f64>();
    let light = |i: usize| (0..3).map(|c| L[c] * y[3 * i + c] as f64).sum::<f64>();
    let mut out = vec![0.0; 3 * w * h];
    for k in 0..w * h {
        let (px, py) = ((k % w) as isize, (k / w) as isize);
        let taps: Vec<_> = kernels.iter().map(|(kern, r)| window_taps(kern, *r, (w, h), &valid, (px, py))).collect();
        let mut v = [f64::INFINITY; 3];
        let mut gap = [0.0; 3];
        for s in 0..3 {
            let Some(m) = &models[s][k] else { continue };
            let n: f64 = taps[s].iter().map(|t| t.1).sum();
            let resid = taps[s].iter().map(|&(i, wt)| wt * (light(i) - luma(m, i)).powi(2)).sum::<f64>() / n;
            let area = 4.0 * std::f64::consts::PI * (sigmas[s] as f64).powi(2);
            v[s] = resid * (q + 1) as f64 / (area * n.min(1.0)).max(1.0);
            if let (Some(m0), true) = (&models[0][k], s > 0) {
                let n0: f64 = taps[0].iter().map(|t| t.1).sum();
                gap[s] = taps[0].iter().map(|&(i, wt)| wt * (luma(m, i) - luma(m0, i)).powi(2)).sum::<f64>() / n0;
            }
        }
        let mut wts = [0.0; 3];
        for s in 0..3 {
            let mse = if s == 0 { v[0] } else { (gap[s] - BIAS_DISCOUNT * (v[0] - v[s]).max(0.0)).max(0.0) + v[s] };
            wts[s] = if mse.is_finite() { 1.0 / mse.max(1e-300) } else { 0.0 };
        }
        let total: f64 = wts.iter().sum();
        for c in 0..3 {
            out[3 * k + c] = (0..3).filter_map(|s| models[s][k].as_ref().map(|m| wts[s] * m.predict(&g(k), c))).sum::<f64>() / total;
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
    for (seed, set) in [(1, GuideSet::NORMAL_DEPTH_AO), (2, GuideSet::NORMAL_DEPTH), (3, GuideSet::NONE)] {
        let f = Owned::synthetic(29, 23, seed, 0.6);
        let c = adaptive_plain(set, [1.0, 2.0, 3.5]);
        let (out, _) = run(c, &f);
        let ch = f.channels(set);
        let want = adaptive_reference(&c, f.w, f.h, &ch, &f.noisy);
        let (max, mean) = diff(&out, &want);
        assert!(max < 1e-3 && mean < 1e-5, "{set:?}: max {max} mean {mean}");
        // sensitivity: each single window is far from the blend
        for s in [1.0, 3.5] {
            let single = reference(&FlrConfig { blur: Blur::Gaussian { sigma: s, radius: None }, ..c }, f.w, f.h, &ch, &f.noisy);
            let (m, _) = diff(&out, &single);
            assert!(m > 20.0 * max, "{set:?} sigma {s}: blend only {m} from the single window");
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
    for (w, h, block) in [(61, 45, 8), (33, 70, 4), (7, 3, 1)] {
        let f = Owned::synthetic(w, h, 5, 0.5);
        let set = GuideSet::NORMAL_DEPTH_AO;
        let c = adaptive(set, block, [3.0, 6.0, 11.0]);
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
        for s in 0..3 {
            for t in (0..nt).rev() {
                flr.blur_rows_tile_at(s, t, p.cells, &mut p.tmp[flr.cells_tile_range(t).unwrap()]).unwrap();
            }
            let dst: &mut [f64] = if s == 0 { p.first } else { p.blurred };
            for t in (0..nt).rev() {
                let r = flr.cells_tile_range(t).unwrap();
                flr.blur_cols_tiles_at(s, t..t + 1, p.tmp, &mut dst[r.clone()]).unwrap();
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
        assert_eq!(bits(&out), bits(&whole), "{w}x{h} B={block}");
        let (scalar, _) = run(FlrConfig { kernel: Kernel::Scalar, ..c }, &f);
        let worst = scalar.iter().zip(&whole).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        assert!(worst < 1e-4, "{w}x{h} B={block}: scalar vs SIMD {worst}");
    }
}

/// The energy moment `e = Σ ℓ²` of every cell, both moment paths, against f64.
#[test]
fn energy_moment_is_sum_of_squared_luminance() {
    use lrdenoise::kernels::CellLayout;
    for (block, w, h) in [(8, 40, 16), (4, 13, 9), (16, 35, 17)] {
        let f = Owned::synthetic(w, h, 6, 0.7);
        let set = GuideSet::NORMAL_DEPTH_AO;
        for kernel in [Kernel::Simd, Kernel::Scalar] {
            let c = FlrConfig { kernel, ..cfg(set, block) };
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
                        let l: f64 = (0..3).map(|ch| L[ch] * f.noisy[3 * (y * w + x) + ch] as f64).sum();
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
    let single = Flr::new(FlrConfig::default(), 64, 64).unwrap();
    let mut m = vec![0f32; single.models_tile_len(0).unwrap()];
    assert!(matches!(single.blend_tile(0, &cells, &[], &[], &mut m), Err(Error::InvalidTile { .. })));
    assert!(matches!(single.blur_rows_tile_at(1, 0, &cells, &mut tmp), Err(Error::InvalidTile { .. })));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Garbage in (NaN, ±Inf, HDR 1e-8..1e6, offsets, duplicated or constant
    /// guides): the adaptive window's output is finite and non-negative.
    #[test]
    fn output_is_finite(seed in 0u64..1000, scale in -8i32..7, offset in 0f32..1e4, nan_every in 0usize..40, dup in any::<bool>()) {
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
        let (out, _) = run(FlrConfig { clamp_negative: true, ..c }, &f);
        prop_assert!(out.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
}
