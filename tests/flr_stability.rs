//! Numerical stability: degenerate guides, affine invariance, extreme values,
//! NaN/Inf. Property tests over conditioning, scale and offset.

mod common;
use common::*;
use lrdenoise::*;
use proptest::prelude::*;

fn all_finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Mean |out − clean| relative to the mean of clean.
fn rel_err(out: &[f32], f: &Owned) -> f64 {
    let e: f64 = out.iter().zip(&f.clean).map(|(a, b)| (a - b).abs() as f64).sum();
    let m: f64 = f.clean.iter().map(|b| b.abs() as f64).sum();
    e / m
}

fn with_user(mut f: Owned, users: Vec<Vec<f32>>) -> Owned {
    f.user = users;
    f
}

#[test]
fn degenerate_guides_stay_finite_and_accurate() {
    let base = Owned::synthetic(64, 48, 2, 0.6);
    let n = base.w * base.h;
    let set = GuideSet { user: 1, ..GuideSet::NORMAL_DEPTH_AO };
    let cases: Vec<(&str, Vec<f32>)> = vec![
        ("constant", vec![3.25; n]),
        ("all-zero", vec![0.0; n]),
        ("duplicate of depth", base.depth.clone()),
        ("linear combination", (0..n).map(|i| 2.0 * base.depth[i] - 0.5 * base.ao[i] + 1.0).collect()),
        ("huge constant", vec![1e6; n]),
    ];
    let (plain, _) = run(cfg(GuideSet::NORMAL_DEPTH_AO, 8), &base);
    let e_plain = rel_err(&plain, &base);
    for (name, u) in cases {
        let f = with_user(base.clone(), vec![u]);
        for reg in [Regularization::Normalized { eps_mul: 1e-4, eps_add: 1e-4 }, Regularization::Tikhonov { eps: 1e-4 }] {
            for b in [1, 8] {
                let c = FlrConfig { regularization: reg, ..cfg(set, b) };
                let (out, _) = run(c, &f);
                assert!(all_finite(&out), "{name} {reg:?} B{b}");
                if matches!(reg, Regularization::Normalized { .. }) && b == 8 {
                    let e = rel_err(&out, &f);
                    assert!(e < e_plain * 1.05 + 1e-3, "{name}: {e} vs {e_plain} without the extra guide");
                }
            }
        }
    }
}

#[test]
fn nan_inf_are_excluded_counted_and_output_is_finite() {
    let mut f = Owned::synthetic(50, 40, 3, 0.5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let (clean_out, _) = run(cfg(set, 8), &f);
    f.noisy[3 * 7] = f32::NAN;
    f.noisy[3 * 100 + 1] = f32::INFINITY;
    f.noisy[3 * 300 + 2] = f32::NEG_INFINITY;
    f.depth[500] = f32::NAN;
    f.normal[3 * 600] = f32::INFINITY;
    f.ao[700] = f32::NAN;
    let (out, rep) = run(cfg(set, 8), &f);
    assert!(all_finite(&out));
    assert_eq!(rep.nonfinite_noisy, 3);
    assert_eq!(rep.nonfinite_guides, 3);
    assert_eq!(rep.fallback_pixels, 3);
    // a handful of excluded pixels barely change the result elsewhere
    let d = out.iter().zip(&clean_out).map(|(a, b)| (a - b).abs()).sum::<f32>() / out.len() as f32;
    assert!(d < 2e-3, "{d}");
    // an all-NaN frame: output finite (zero), every cell empty
    let mut g = f.clone();
    g.noisy.fill(f32::NAN);
    let (out, rep) = run(cfg(set, 8), &g);
    assert!(out.iter().all(|v| *v == 0.0));
    assert_eq!(rep.nonfinite_noisy as usize, g.w * g.h);
}

#[test]
fn hdr_range_works() {
    let mut f = Owned::synthetic(64, 64, 8, 0.5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    for (scale, what) in [(1e-8f32, "dim"), (1e6, "bright")] {
        let mut g = f.clone();
        g.noisy.iter_mut().for_each(|v| *v *= scale);
        g.clean.iter_mut().for_each(|v| *v *= scale);
        let (out, _) = run(cfg(set, 8), &g);
        assert!(all_finite(&out), "{what}");
        let (base, _) = run(cfg(set, 8), &f);
        // linear in y: scaled input gives scaled output
        let rel = out.iter().zip(&base).map(|(a, b)| ((a / scale) - b).abs() / (b.abs() + 1e-3)).fold(0f32, f32::max);
        assert!(rel < 1e-3, "{what}: {rel}");
    }
    // fireflies of 1e9 next to 1e-8 values
    for i in (0..f.noisy.len()).step_by(97) {
        f.noisy[i] = 1e9;
    }
    let (out, _) = run(cfg(set, 8), &f);
    assert!(all_finite(&out));
}

fn transformed(f: &Owned, a: f32, b: f32, which: usize) -> Owned {
    let mut g = f.clone();
    match which {
        0 => g.depth.iter_mut().for_each(|v| *v = a * *v + b),
        1 => g.position.iter_mut().for_each(|v| *v = a * *v + b),
        2 => g.ao.iter_mut().for_each(|v| *v = a * *v + b),
        _ => g.normal.iter_mut().for_each(|v| *v = a * *v + b),
    }
    g
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    /// g → a·g + b on any guide leaves the normalized-mode output unchanged (up to rounding).
    /// The AO demodulation (on by default) reads AO's values as occlusion in
    /// [0, 1], so a transformed AO is checked without it; every other guide with it.
    #[test]
    fn affine_invariance(seed in 0u64..1000, which in 0usize..4, log_a in -3.0f32..3.0, neg in any::<bool>(), b in -1e4f32..1e4, block in prop::sample::select(vec![1usize, 4, 8, 16])) {
        let f = Owned::synthetic(40, 33, seed, 0.6);
        let set = GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 };
        let cfg = |set, block| FlrConfig { ao_demodulation: if which == 2 { None } else { cfg(set, block).ao_demodulation }, ..cfg(set, block) };
        prop_assert!(which == 2 || cfg(set, block).ao_demodulation.is_some());
        let a = 10f32.powf(log_a) * if neg { -1.0 } else { 1.0 };
        let g = transformed(&f, a, b, which);
        // one window, and the default adaptive window (its bias and variance
        // estimates are differences of predictions: invariant as well)
        let adaptive = FlrConfig { blur: Blur::Adaptive { sigmas: lrdenoise::flr::config::DEFAULT_SIGMAS }, ..cfg(set, block) };
        for c in [cfg(set, block), adaptive] {
            let (o1, _) = run(c, &f);
            let (o2, _) = run(c, &g);
            prop_assert!(all_finite(&o2));
            // Rounding of a·g + b in f32 itself perturbs the guide by ~|b|·6e-8, i.e.
            // relative to the guide's spread by |b|/(|a|·spread)·6e-8.
            let tol = 2e-3 + 1e-6 * (b.abs() / a.abs()) as f64;
            let d = o1.iter().zip(&o2).map(|(x, y)| (x - y).abs() as f64).sum::<f64>() / o1.len() as f64;
            prop_assert!(d < tol, "{:?}: mean diff {} (tol {})", c.blur, d, tol);
        }
    }

    /// Ill-conditioned windows: guides that are nearly collinear, tiny or huge,
    /// offset far from zero. Output finite and close to the f64 reference.
    #[test]
    fn conditioning_scale_offset(seed in 0u64..1000, log_s in -3.0f32..3.0, off in -1e4f32..1e4, mix in 0.0f32..1e-3) {
        let f = Owned::synthetic(24, 20, seed, 0.5);
        let n = f.w * f.h;
        let s = 10f32.powf(log_s);
        let mut rng = Rng(seed + 17);
        let u0: Vec<f32> = (0..n).map(|i| f.depth[i] * s + off).collect();
        let u1: Vec<f32> = (0..n).map(|i| (f.depth[i] + mix * rng.f32()) * s + off).collect();
        let g = with_user(f.clone(), vec![u0, u1]);
        let set = GuideSet { user: 2, ..GuideSet::NORMAL_DEPTH_AO };
        let mut c = cfg(set, 1);
        c.blur = Blur::Gaussian { sigma: 3.0, radius: None };
        let (out, _) = run(c, &g);
        prop_assert!(all_finite(&out));
        let want = reference(&c, g.w, g.h, &g.channels(set), &g.noisy);
        let (_, mean) = diff(&out, &want);
        prop_assert!(mean < 5e-3, "mean diff {}", mean);
    }

    /// Arbitrary garbage (including NaN/Inf, huge values) never panics and never
    /// yields a non-finite output.
    #[test]
    fn arbitrary_values_finite(vals in prop::collection::vec(prop_oneof![
        Just(f32::NAN), Just(f32::INFINITY), Just(-1e30f32), Just(0.0f32), -1e6f32..1e6, 0f32..1.0], 16..400),
        w in 1usize..20, block in prop::sample::select(vec![1usize, 2, 4, 8, 16])) {
        let h = (vals.len() / (w * 8)).max(1);
        let n = w * h;
        let pick = |k: usize| -> Vec<f32> { (0..n * k).map(|i| vals[(i * 7 + k) % vals.len()]).collect() };
        let (noisy, normal, depth, ao) = (pick(3), pick(3), pick(1), pick(1));
        let guides = Guides {
            normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
            depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
            ao: Some(ImageView::interleaved(&ao, w, h, 1).unwrap()),
            ..Default::default()
        };
        let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
        for reg in [Regularization::Normalized { eps_mul: 1e-4, eps_add: 1e-4 }, Regularization::Tikhonov { eps: 1e-4 }] {
            let c = FlrConfig { regularization: reg, ..cfg(GuideSet::NORMAL_DEPTH_AO, block) };
            let (out, _) = run_frame(c, w, h, &frame);
            prop_assert!(all_finite(&out));
        }
    }
}

/// The AO demodulation (`FlrConfig::ao_demodulation`, on by default): it
/// applies only with AO among the guides and the normalized regularization
/// (elsewhere the output is bit-identical to it off); AO that is NaN, ±Inf or
/// outside [0, 1], a tiny offset and near-overflow light stay finite, and a
/// non-finite AO is counted as a guide, not as noisy light; offsets that are
/// not finite and > 0 are typed errors.
#[test]
fn ao_demodulation_applies_where_it_should_and_stays_finite() {
    let f = Owned::synthetic(45, 37, 12, 0.5);
    let on = cfg(GuideSet::NORMAL_DEPTH_AO, 8).ao_demodulation;
    assert_eq!(on, Some(lrdenoise::flr::config::DEFAULT_AO_OFFSET));
    let same = |c: FlrConfig| {
        let (a, _) = run(c, &f);
        let (b, _) = run(FlrConfig { ao_demodulation: None, ..c }, &f);
        a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits())
    };
    assert!(same(cfg(GuideSet::NORMAL_DEPTH, 8)), "no AO guide: nothing to demodulate");
    assert!(same(FlrConfig { regularization: Regularization::Tikhonov { eps: 1e-4 }, ..cfg(GuideSet::NORMAL_DEPTH_AO, 8) }));
    assert!(!same(cfg(GuideSet::NORMAL_DEPTH_AO, 8)), "with AO (normalized) it changes the fit");

    let mut g = f.clone();
    g.ao[10] = f32::NAN;
    g.ao[20] = f32::INFINITY;
    g.ao[30] = -3.0;
    g.ao[40] = 1e30;
    g.noisy[3 * 50] = 3e38; // y / s would overflow for a small offset
    for kernel in [Kernel::Simd, Kernel::Scalar] {
        for offset in [on, Some(1e-6), Some(1e6)] {
            for blur in [cfg(GuideSet::NORMAL_DEPTH_AO, 8).blur, Blur::Adaptive { sigmas: lrdenoise::flr::config::DEFAULT_SIGMAS }] {
                let c = FlrConfig { kernel, blur, ao_demodulation: offset, ..cfg(GuideSet::NORMAL_DEPTH_AO, 8) };
                let (out, rep) = run(c, &g);
                assert!(all_finite(&out), "{kernel:?} {offset:?} {blur:?}");
                assert_eq!((rep.nonfinite_noisy, rep.nonfinite_guides), (0, 2), "{kernel:?} {offset:?}");
            }
        }
    }
    for bad in [0.0, -0.1, f32::NAN, f32::INFINITY] {
        let c = FlrConfig { ao_demodulation: Some(bad), ..cfg(GuideSet::NORMAL_DEPTH_AO, 8) };
        assert!(matches!(Flr::new(c, 16, 16), Err(Error::InvalidConfig(_))), "{bad}");
    }
}
