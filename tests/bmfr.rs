//! BMFR: the blockwise fit against an f64 oracle, rank-deficient blocks,
//! stability over scale/offset/HDR/NaN, tiles, SIMD vs scalar, awkward sizes,
//! and the temporal pipeline on a static-camera sequence.

mod common;
#[path = "common/oracles.rs"]
mod oracles;
use common::*;
use lrdenoise::bmfr::{temporal::TemporalConfig, Report as BmfrReport};
use lrdenoise::*;
use oracles::{bmfr_oracle, random_guides};
use proptest::prelude::*;

const NP: GuideSet = GuideSet { normal: true, depth: false, position: true, ao: false, user: 0 };

fn run(cfg: BmfrConfig, f: &Owned, index: u32) -> (Vec<f32>, BmfrReport) {
    let b = Bmfr::new(cfg, f.w, f.h).unwrap();
    let mut scratch = vec![0f32; b.scratch_len()];
    let mut out = vec![f32::NAN; f.w * f.h * 3];
    let rep = b.denoise(&f.frame(cfg.guides), index, &mut scratch, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap()).unwrap();
    (out, rep)
}

fn rel_err(out: &[f32], clean: &[f32]) -> f64 {
    let e: f64 = out.iter().zip(clean).map(|(a, b)| (a - b).abs() as f64).sum();
    e / clean.iter().map(|b| b.abs() as f64).sum::<f64>()
}

/// Without the stochastic regularisation, with and without the shrinkage.
#[test]
fn matches_f64_oracle_without_noise() {
    let set = GuideSet { depth: true, user: 2, ..GuideSet::NONE };
    let sizes = [(70, 50, 32, 0u32), (64, 64, 16, 5), (40, 33, 8, 11), (45, 31, 12, 2), (30, 29, 9, 7)];
    for ((w, h, block, index), shrinkage) in sizes.into_iter().flat_map(|s| [(s, 0.0), (s, 4.0)]) {
        let f = random_guides(w, h, w as u64);
        // (the oracle fits the noisy light as given: no firefly clamp)
        let cfg = BmfrConfig { noise: 0.0, block, shrinkage, fireflies: None, ..BmfrConfig::with_guides(set) };
        let b = Bmfr::new(cfg, w, h).unwrap();
        assert_eq!(b.feature_count(), 5);
        let (out, rep) = run(cfg, &f, index);
        assert_eq!(rep.dropped_pivots, 0);
        let want = bmfr_oracle(&b, &f, index);
        let (max, mean) = diff(&out, &want);
        // measured ≤ 3.4e-7 / 7.3e-8 (f32 rounding)
        assert!(max < 1e-5 && mean < 1e-6, "{w}x{h} B={block} κ={shrinkage}: mean {mean:.2e} max {max:.2e}");
    }
}

#[test]
fn stochastic_regularisation_changes_little_and_is_deterministic() {
    let set = GuideSet { depth: true, user: 2, ..GuideSet::NONE };
    let f = random_guides(64, 48, 3);
    let (a, _) = run(BmfrConfig::with_guides(set), &f, 2);
    let (b, _) = run(BmfrConfig::with_guides(set), &f, 2);
    let (c, _) = run(BmfrConfig { noise: 0.0, ..BmfrConfig::with_guides(set) }, &f, 2);
    assert_eq!(a, b, "same frame index → same noise → same output");
    let d = rel_err(&a, &c);
    assert!(d > 0.0 && d < 0.02, "regularisation changed the fit by {d}");
    let (e, _) = run(BmfrConfig::with_guides(set), &f, 3);
    assert_ne!(a, e, "the frame index moves the grid and the noise");
}

/// A flat wall: constant normal, positions on a plane (p_z constant, p_x and
/// p_y linear: p² is a function of p): every feature but a few is redundant.
fn wall(w: usize, h: usize, sky_from: usize) -> Owned {
    let mut f = Owned::synthetic(w, h, 9, 0.5);
    let mut rng = Rng(77);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let sky = x >= sky_from;
            let n = if sky { [0.0; 3] } else { [0.0, 0.0, 1.0] };
            let p = if sky { [0.0; 3] } else { [x as f32 * 0.01, y as f32 * 0.01, 5.0] };
            f.normal[3 * i..3 * i + 3].copy_from_slice(&n);
            f.position[3 * i..3 * i + 3].copy_from_slice(&p);
            for c in 0..3 {
                let v = if sky { 0.0 } else { 0.3 + 0.001 * x as f32 + 0.1 * c as f32 };
                f.clean[3 * i + c] = v;
                f.noisy[3 * i + c] = if sky { 0.0 } else { v * 2.0 * rng.f32() };
            }
        }
    }
    f
}

#[test]
fn rank_deficient_blocks_are_finite_and_sensible() {
    for noise in [0.0, 0.01] {
        for sky_from in [200, 50, 0] {
            let f = wall(96, 64, sky_from);
            let cfg = BmfrConfig { noise, ..BmfrConfig::with_guides(NP) };
            let (out, rep) = run(cfg, &f, 0);
            assert!(out.iter().all(|v| v.is_finite() && *v >= 0.0));
            if noise == 0.0 {
                assert!(rep.dropped_pivots > 0, "the constant normal must be dropped");
            }
            for y in 0..f.h {
                for x in 0..f.w {
                    let i = y * f.w + x;
                    if x >= sky_from {
                        // (a least-squares fit: ~0, not exactly 0; albedo is 0 there anyway)
                        assert!(out[3 * i..3 * i + 3].iter().all(|&v| v.abs() < 5e-3), "sky stays black: {:?}", &out[3 * i..3 * i + 3]);
                    }
                }
            }
            if sky_from > 0 {
                // the wall: a smooth ramp, estimated from 1-spp-like noise
                let (o, c): (Vec<f32>, Vec<f32>) = (0..f.w * f.h)
                    .filter(|i| i % f.w < sky_from)
                    .flat_map(|i| (0..3).map(move |c| 3 * i + c))
                    .map(|k| (out[k], f.clean[k]))
                    .unzip();
                let e = rel_err(&o, &c);
                assert!(e < 0.08, "noise {noise} sky_from {sky_from}: wall error {e}");
            }
        }
    }
}

#[test]
fn nonfinite_inputs_are_excluded_and_counted() {
    let mut f = Owned::synthetic(80, 40, 4, 0.5);
    f.noisy[3 * 100] = f32::NAN;
    f.noisy[3 * 200 + 1] = f32::INFINITY;
    f.position[3 * 300] = f32::NAN;
    f.normal[3 * 400 + 2] = f32::NEG_INFINITY;
    let (out, rep) = run(BmfrConfig::with_guides(NP), &f, 0);
    assert!(out.iter().all(|v| v.is_finite()));
    assert_eq!(rep.nonfinite_noisy, 2);
    assert_eq!(rep.nonfinite_guides, 2);
    assert_eq!(rep.fallback_pixels, 2);
    let (clean_out, _) = run(BmfrConfig::with_guides(NP), &Owned::synthetic(80, 40, 4, 0.5), 0);
    assert!(rel_err(&out, &clean_out) < 0.02, "a few bad samples must not spread");
}

/// With the firefly clamp (on by default) too: outliers on the borders, in
/// the corners and on rows where tiles meet are clamped alike by every tile
/// that reads them.
#[test]
fn tiles_in_any_order_equal_the_whole_frame() {
    let mut f = Owned::synthetic(150, 97, 5, 0.5);
    let (w, h) = (f.w, f.h);
    for (x, y) in [(0, 0), (w - 1, h - 1), (0, 40), (75, 0), (149, 50), (60, 96), (33, 17), (34, 18), (90, 49), (91, 64), (12, 81)] {
        f.noisy[3 * (y * w + x)..3 * (y * w + x) + 3].fill(1e4);
    }
    for fireflies in [Some(lrdenoise::fireflies::DEFAULT_STRENGTH), None] {
        let cfg = BmfrConfig { fireflies, ..BmfrConfig::with_guides(NP) };
        let b = Bmfr::new(cfg, w, h).unwrap();
        for index in [0u32, 7] {
            let (whole, rep) = run(cfg, &f, index);
            assert_eq!(rep.clamped_fireflies > 0, fireflies.is_some());
            let frame = b.check_frame(&f.frame(NP)).unwrap();
            let mut out = vec![0f32; w * h * 3];
            let mut worker = vec![0f32; b.worker_len()];
            let mut tiled = BmfrReport::default();
            for t in (0..b.tile_count(index)).rev() {
                let (y0, y1) = b.tile_pixel_rows(index, t).unwrap();
                let mut view = ImageViewMut::interleaved(&mut out[3 * w * y0..3 * w * y1], w, y1 - y0, 3).unwrap();
                tiled += b.fit_tile(&frame, index, t, &mut worker, &mut view).unwrap();
            }
            assert_eq!(out, whole, "{fireflies:?} frame {index}");
            assert_eq!(tiled, rep, "{fireflies:?} frame {index}");
        }
    }
}

#[test]
fn simd_matches_scalar() {
    let f = Owned::synthetic(128, 96, 6, 0.6);
    let (a, _) = run(BmfrConfig::with_guides(NP), &f, 1);
    let (b, _) = run(BmfrConfig { kernel: Kernel::Scalar, ..BmfrConfig::with_guides(NP) }, &f, 1);
    let m = a.iter().zip(&b).map(|(x, y)| (x - y).abs() / (1e-3 + y.abs())).fold(0f32, f32::max);
    assert!(m < 1e-2, "max relative difference {m}");
    assert!(rel_err(&a, &b) < 1e-4);
}

#[test]
fn awkward_sizes() {
    for (w, h) in [(1, 1), (7, 3), (255, 9), (256, 9), (257, 9), (33, 65), (5, 70)] {
        let f = Owned::synthetic(w, h, 8, 0.5);
        for set in [NP, GuideSet::NORMAL_DEPTH, GuideSet::NONE, GuideSet { ao: true, user: 0, ..GuideSet::NORMAL_DEPTH }] {
            for index in [0, 3] {
                let (out, _) = run(BmfrConfig::with_guides(set), &f, index);
                assert!(out.iter().all(|v| v.is_finite()), "{w}x{h} {set:?}");
            }
        }
    }
}

#[test]
fn grid_shift_covers_every_pixel_once() {
    let b = Bmfr::new(BmfrConfig::default(), 100, 70).unwrap();
    for index in 0..16 {
        let (x0, y0) = b.grid_origin(index);
        assert!(x0 <= 0 && x0 > -32 && y0 <= 0 && y0 > -32);
        let rows: Vec<_> = (0..b.tile_count(index)).map(|t| b.tile_pixel_rows(index, t).unwrap()).collect();
        assert_eq!(rows[0].0, 0);
        assert_eq!(rows.last().unwrap().1, 70);
        assert!(rows.windows(2).all(|p| p[0].1 == p[1].0 && p[0].0 < p[0].1));
    }
}

#[test]
fn typed_errors() {
    let f = Owned::synthetic(40, 30, 1, 0.5);
    assert!(matches!(Bmfr::new(BmfrConfig { block: 4, ..Default::default() }, 40, 30), Err(Error::InvalidConfig(_))));
    assert!(matches!(Bmfr::new(BmfrConfig { noise: f32::NAN, ..Default::default() }, 40, 30), Err(Error::InvalidConfig(_))));
    let bad_t = TemporalConfig { output_alpha: 0.0, ..Default::default() };
    assert!(matches!(Bmfr::new(BmfrConfig { temporal: bad_t, ..Default::default() }, 40, 30), Err(Error::InvalidConfig(_))));
    let all = GuideSet { normal: true, depth: true, position: true, ao: true, user: 4 };
    assert_eq!(Bmfr::new(BmfrConfig::with_guides(all), 40, 30).unwrap().feature_count(), 16, "every guide + 3 squares fits");
    assert!(matches!(Bmfr::new(BmfrConfig::default(), 0, 30), Err(Error::InvalidSize { .. })));
    let b = Bmfr::new(BmfrConfig::with_guides(NP), 40, 30).unwrap();
    let mut out = vec![0f32; 40 * 30 * 3];
    let mut small = vec![0f32; b.scratch_len() - 1];
    let mut ov = ImageViewMut::interleaved(&mut out, 40, 30, 3).unwrap();
    assert!(matches!(b.denoise(&f.frame(NP), 0, &mut small, &mut ov), Err(Error::ScratchTooSmall { .. })));
    let mut scratch = vec![0f32; b.scratch_len()];
    assert_eq!(b.denoise(&f.frame(GuideSet::NORMAL_DEPTH), 0, &mut scratch, &mut ov).unwrap_err(), Error::GuideMismatch);
    let mut hist = vec![0f32; b.history_len() - 1];
    let mut ts = vec![0f32; b.temporal_scratch_len()];
    let mut h = History::new(&mut hist);
    assert!(matches!(b.denoise_temporal(&f.frame(NP), None, &mut h, &mut ts, &mut ov), Err(Error::BufferTooSmall { .. })));
    let mut hist = vec![0f32; b.history_len()];
    let mut h = History::new(&mut hist);
    let one = vec![0f32; 40 * 30];
    let m1 = ImageView::interleaved(&one, 40, 30, 1).unwrap();
    assert!(matches!(b.denoise_temporal(&f.frame(NP), Some(&m1), &mut h, &mut ts, &mut ov), Err(Error::ChannelCount { .. })));
}

/// A static-camera sequence: the same scene, fresh 1-spp-like noise per frame.
fn static_sequence(frames: usize) -> Vec<Owned> {
    let base = Owned::synthetic(96, 80, 12, 0.8);
    (0..frames)
        .map(|k| {
            let mut f = base.clone();
            let mut rng = Rng(1000 + k as u64);
            for (n, c) in f.noisy.iter_mut().zip(&base.clean) {
                let u = rng.f32();
                *n = c * if u < 0.7 { 0.3 } else { 0.3 + 0.7 / 0.3 * 1.0 * (u - 0.7) / 0.3 * 2.0 };
            }
            f
        })
        .collect()
}

#[test]
fn temporal_accumulation_lowers_the_error_frame_over_frame() {
    let seq = static_sequence(8);
    let (w, h) = (seq[0].w, seq[0].h);
    for set in [NP, GuideSet::NORMAL_DEPTH] {
        let b = Bmfr::new(BmfrConfig::with_guides(set), w, h).unwrap();
        let mut hist = vec![0f32; b.history_len()];
        let mut history = History::new(&mut hist);
        let mut scratch = vec![0f32; b.temporal_scratch_len()];
        let zero = vec![0f32; 2 * w * h];
        let motion = ImageView::interleaved(&zero, w, h, 2).unwrap();
        let mut errs = vec![];
        let mut single = vec![];
        for (k, f) in seq.iter().enumerate() {
            let mut out = vec![0f32; 3 * w * h];
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            let rep = b.denoise_temporal(&f.frame(set), Some(&motion), &mut history, &mut scratch, &mut ov).unwrap();
            assert_eq!(rep.history_rejected, 0, "static camera: nothing to reject");
            assert!(out.iter().all(|v| v.is_finite()));
            errs.push(rel_err(&out, &f.clean));
            single.push(rel_err(&run(BmfrConfig::with_guides(set), f, k as u32).0, &f.clean));
        }
        assert_eq!(history.frames(), 8);
        for k in 1..errs.len() {
            // (the block grid moves every frame: a frame's error may rise a little)
            assert!(errs[k] < errs[k - 1] * 1.05, "{set:?}: error rose at frame {k}: {errs:?}");
        }
        // (with normal and depth only, the fit's bias is a floor the accumulation does not lower)
        assert!(errs[7] < 0.65 * errs[0], "{set:?}: {errs:?}");
        assert!(errs[7] < 0.6 * single[7], "{set:?}: temporal {} vs single {}", errs[7], single[7]);
    }
}

#[test]
fn temporal_rejects_disocclusions_and_survives_nan() {
    let seq = static_sequence(3);
    let (w, h) = (seq[0].w, seq[0].h);
    let b = Bmfr::new(BmfrConfig::with_guides(NP), w, h).unwrap();
    let mut hist = vec![0f32; b.history_len()];
    let mut history = History::new(&mut hist);
    let mut scratch = vec![0f32; b.temporal_scratch_len()];
    let mut out = vec![0f32; 3 * w * h];
    let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
    b.denoise_temporal(&seq[0].frame(NP), None, &mut history, &mut scratch, &mut ov).unwrap();
    // frame 1: the left half moves 10 units away (a new surface)
    let mut f1 = seq[1].clone();
    for i in 0..w * h {
        if i % w < w / 2 {
            f1.position[3 * i + 1] += 10.0;
        }
    }
    f1.noisy[7] = f32::NAN;
    let rep = b.denoise_temporal(&f1.frame(NP), None, &mut history, &mut scratch, &mut ov).unwrap();
    assert_eq!(rep.history_rejected as usize, h * (w / 2));
    assert_eq!(rep.nonfinite_noisy, 1);
    // motion that points far outside the image is invalid everywhere: a cut
    let far = vec![1e4f32; 2 * w * h];
    let mv = ImageView::interleaved(&far, w, h, 2).unwrap();
    let rep = b.denoise_temporal(&seq[2].frame(NP), Some(&mv), &mut history, &mut scratch, &mut ov).unwrap();
    assert_eq!((rep.invalid_motion as usize, rep.history_resets), (w * h, 1));
    assert!(out.iter().all(|v| v.is_finite()));
    history.reset();
    assert_eq!(history.frames(), 0);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]
    /// Positions at any offset and scale, light at any scale: finite output,
    /// invariant to the positions' affine change (per-block rescaling), and
    /// linear in the light's scale.
    #[test]
    fn stable_over_offset_scale_and_hdr(seed in 0u64..1000, log_scale in -3.0f32..3.0, offset in -1e4f32..1e4, log_light in -8.0f32..6.0) {
        let f = Owned::synthetic(48, 40, seed, 0.6);
        let (base, _) = run(BmfrConfig::with_guides(NP), &f, seed as u32);
        let mut g = f.clone();
        let s = 10f32.powf(log_scale);
        for p in g.position.iter_mut() {
            *p = *p * s + offset;
        }
        let l = 10f32.powf(log_light);
        for v in g.noisy.iter_mut() {
            *v *= l;
        }
        let (out, _) = run(BmfrConfig::with_guides(NP), &g, seed as u32);
        prop_assert!(out.iter().all(|v| v.is_finite()));
        let scaled: Vec<f32> = out.iter().map(|v| v / l).collect();
        // f32 positions carry only ulp(offset) of absolute resolution: where
        // that is a visible fraction of the positions' scale, the input itself
        // has lost the geometry, so the bound grows with that fraction.
        let ulp = offset.abs().max(1.0) * f32::EPSILON;
        prop_assume!(ulp < 1e-3 * s);
        let tol = 2e-3 + 30.0 * (ulp / s) as f64;
        let e = rel_err(&scaled, &base);
        prop_assert!(e < tol, "scale {} offset {} light {}: {}", s, offset, l, e);
    }
}

/// Interleaved guides (read three channels at a time), planar guides and RGBA
/// noisy input with a row padding give bit-identical output, mirrored borders
/// included.
#[test]
fn input_layouts_give_identical_output() {
    let f = Owned::synthetic(70, 45, 12, 0.5);
    let (w, h, n) = (f.w, f.h, f.w * f.h);
    let (want, _) = run(BmfrConfig::with_guides(NP), &f, 5);
    let planar = |src: &[f32]| -> Vec<f32> { (0..3).flat_map(|c| (0..n).map(move |i| src[3 * i + c])).collect() };
    let (pn, pp) = (planar(&f.normal), planar(&f.position));
    // RGBA noisy with 3 padding floats at the end of each row
    let rs = 4 * w + 3;
    let mut rgba = vec![f32::NAN; rs * h];
    for y in 0..h {
        for x in 0..w {
            rgba[y * rs + 4 * x..y * rs + 4 * x + 3].copy_from_slice(&f.noisy[3 * (y * w + x)..3 * (y * w + x) + 3]);
        }
    }
    let noisy = ImageView::f32(&rgba, w, h, 3, Layout { offset: 0, pixel_stride: 4, row_stride: rs, channel_stride: 1 }).unwrap();
    let guides = Guides {
        normal: Some(ImageView::f32(&pn, w, h, 3, Layout::planar(w, h)).unwrap()),
        position: Some(ImageView::f32(&pp, w, h, 3, Layout::planar(w, h)).unwrap()),
        ..Default::default()
    };
    let b = Bmfr::new(BmfrConfig::with_guides(NP), w, h).unwrap();
    let mut out = vec![0f32; 3 * n];
    let mut scratch = vec![0f32; b.scratch_len()];
    b.denoise(&Frame::new(noisy, guides), 5, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
    assert_eq!(out, want);
}
