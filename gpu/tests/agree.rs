//! The GPU path against the CPU path on the same frames: several synthetic
//! scenes, sizes not divisible by the block, every guide-set size, both
//! regularizations, the box blur, and the degenerate cases of the FLR tests
//! (constant, all-zero, duplicated, linearly dependent guides; NaN/Inf).
//!
//! The tests that run shaders need a wgpu adapter (in CI, Mesa's lavapipe,
//! `mesa-vulkan-drivers`): they are `#[ignore]`d, so a plain `cargo test`
//! reports them as ignored, and fail when run without one
//! (`cargo test -p lrdenoise-gpu -- --ignored`; `.ci/run` does).

#[path = "../../tests/common/mod.rs"]
mod common;
use common::*;
use lrdenoise::flr::gpu;
use lrdenoise::*;
use lrdenoise_gpu::{GpuError, GpuFlr};

/// Tolerance: the mean |GPU − CPU| over the mean |CPU| (f32 against f64 moments;
/// measured on lavapipe: at most 1.1e-6, the worst pixel 1.2e-5).
const MEAN_TOL: f64 = 1e-4;
/// Worst single value, relative to the mean |CPU| (a pixel near a hard edge).
const MAX_TOL: f64 = 1e-3;

/// Why the shader tests are ignored by default.
const NEEDS_ADAPTER: &str = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does";

/// The GPU executor (a failure that says so where there is no adapter).
fn gpu(cfg: FlrConfig, w: usize, h: usize) -> GpuFlr {
    match GpuFlr::new(cfg, w, h) {
        Ok(g) => g,
        Err(GpuError::NoAdapter(why)) => panic!("no GPU adapter ({why}): {NEEDS_ADAPTER}"),
        Err(e) => panic!("{e}"),
    }
}

/// Runs both paths; returns (mean, max) relative differences and both reports.
fn compare(cfg: FlrConfig, f: &Owned, set: GuideSet) -> (f64, f64, Report, Report) {
    let mut g = gpu(cfg, f.w, f.h);
    let frame = f.frame(set);
    let (cpu, rep_cpu) = run_frame(cfg, f.w, f.h, &frame);
    let mut out = vec![0f32; 3 * f.w * f.h];
    let rep_gpu = g.denoise(&frame, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap()).unwrap();
    if let Some(t) = g.pass_times_ms() {
        assert!(t.iter().all(|v| v.is_finite() && *v >= 0.0) && t.iter().sum::<f64>() > 0.0, "pass times {t:?}");
    }
    assert!(out.iter().all(|v| v.is_finite()), "GPU output not finite");
    let (mean, max) = rel_diff(&out, &cpu);
    (mean, max, rep_cpu, rep_gpu)
}

/// Mean relative difference between two configurations' GPU outputs on one
/// frame (what an option moves).
fn gpu_difference(a: FlrConfig, b: FlrConfig, f: &Owned, set: GuideSet) -> f64 {
    let frame = f.frame(set);
    let run = |c: FlrConfig| {
        let mut out = vec![0f32; 3 * f.w * f.h];
        gpu(c, f.w, f.h).denoise(&frame, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap()).unwrap();
        out
    };
    rel_diff(&run(b), &run(a)).0
}

fn check(name: &str, cfg: FlrConfig, f: &Owned, set: GuideSet) -> (Report, Report) {
    let (mean, max, rc, rg) = compare(cfg, f, set);
    eprintln!("{name}: {}x{} mean {mean:.2e} max {max:.2e} clamped {}", f.w, f.h, rc.clamped_fireflies);
    assert!(mean < MEAN_TOL && max < MAX_TOL, "{name} {}x{}: mean {mean:.2e} max {max:.2e}", f.w, f.h);
    assert_eq!(
        (rc.nonfinite_noisy, rc.nonfinite_guides, rc.fallback_pixels),
        (rg.nonfinite_noisy, rg.nonfinite_guides, rg.fallback_pixels),
        "{name}"
    );
    assert_eq!((rc.empty_blocks, rc.empty_cells), (rg.empty_blocks, rg.empty_cells), "{name}");
    assert_eq!(rc.clamped_fireflies, rg.clamped_fireflies, "{name}: clamped fireflies");
    (rc, rg)
}

#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn frames_sizes_and_guide_sets() {
    let sets = [
        GuideSet::NORMAL_DEPTH_AO,
        GuideSet::NONE,
        GuideSet { normal: true, ..GuideSet::NONE },
        GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 },
    ];
    for (w, h, seed) in [(64, 48, 1), (75, 61, 2), (257, 40, 3), (7, 3, 4), (1, 1, 5), (33, 70, 6)] {
        let f = Owned::synthetic(w, h, seed, 0.5);
        for set in sets {
            for block in [8, 4, 16] {
                let c = cfg(set, block);
                check(&format!("set {set:?} B{block}"), c, &f, set);
            }
        }
    }
}

#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn regularizations_and_box_blur() {
    let f = Owned::synthetic(96, 64, 7, 0.6);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let configs = [
        ("tikhonov", FlrConfig { regularization: Regularization::Tikhonov { eps: 1e-3 }, ..cfg(set, 8) }),
        ("box", FlrConfig { blur: Blur::Box { radius: 24.0 }, ..cfg(set, 8) }),
        ("no clamp", FlrConfig { clamp_negative: false, ..cfg(set, 8) }),
        ("B1", cfg(set, 1)),
    ];
    for (name, c) in configs {
        check(name, c, &f, set);
    }
}

/// The adaptive window (three windows blended per cell): windows 1 and 2
/// pooled (σ 6/12/20 at B = 8), not pooled (B = 16), one of each (σ 6/8/20);
/// sizes odd and tiny; the degenerate and NaN/Inf frames.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn adaptive_window() {
    let set = GuideSet::NORMAL_DEPTH_AO;
    let adaptive = |sigmas: [f32; 3], block: usize| FlrConfig { blur: Blur::Adaptive { sigmas }, ..cfg(set, block) };
    for (w, h, seed) in [(96, 64, 7), (75, 61, 2), (7, 3, 4), (1, 1, 5), (33, 70, 6)] {
        let f = Owned::synthetic(w, h, seed, 0.6);
        for (sigmas, block) in [([6.0, 12.0, 20.0], 8), ([6.0, 12.0, 20.0], 16), ([6.0, 8.0, 20.0], 8), ([3.0, 6.0, 10.0], 4)] {
            check(&format!("adaptive {sigmas:?} B{block}"), adaptive(sigmas, block), &f, set);
        }
    }
    // no guides (a blend of three blurs), every guide, and B = 1 (pooled cells of 2×2 pixels)
    let f = Owned::synthetic(40, 29, 9, 0.6);
    let all = GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 };
    for (set, block) in [(GuideSet::NONE, 8), (all, 8), (set, 1)] {
        let c = FlrConfig { guides: set, ..adaptive([6.0, 12.0, 20.0], block) };
        check(&format!("adaptive {set:?} B{block}"), c, &f, set);
    }
    let mut f = Owned::synthetic(64, 48, 2, 0.6);
    f.noisy[3 * 7] = f32::NAN;
    f.depth[900] = f32::INFINITY;
    for v in &mut f.ao[..64 * 20] {
        *v = 0.25; // a constant guide over the top rows
    }
    check("adaptive nan/inf", adaptive([6.0, 12.0, 20.0], 8), &f, set);
}

/// The AO-free candidate (`adaptive_without_ao`): window 0 also fitted
/// without AO and blended as a fourth candidate; AO last and AO followed by a
/// user guide (the system reordered), both regularizations, sizes odd and
/// tiny, NaN/Inf; and its output differs from the three-window blend.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn adaptive_without_ao() {
    let base = GuideSet::NORMAL_DEPTH_AO;
    for (set, user) in [(base, false), (GuideSet { user: 1, ..base }, true)] {
        for (w, h, seed) in [(96, 64, 7), (75, 61, 2), (7, 3, 4), (1, 1, 5)] {
            let mut f = Owned::synthetic(w, h, seed, 0.6);
            if user {
                f.user = vec![(0..w * h).map(|i| ((i * 7919) % 101) as f32 / 101.0).collect()];
            }
            for reg in [Regularization::Normalized { eps_mul: 1e-3, eps_add: 1e-2 }, Regularization::Tikhonov { eps: 1e-3 }] {
                let three = FlrConfig { regularization: reg, ..adaptive(cfg(set, 8)) };
                let four = FlrConfig { adaptive_without_ao: true, ..three };
                let (mean, max, _, _) = compare(three, &f, set);
                check(&format!("without AO {set:?} {reg:?}"), four, &f, set);
                assert!(mean < MEAN_TOL && max < MAX_TOL);
                if w * h > 1000 {
                    // the candidate changes the result by far more than the GPU's tolerance
                    let m = gpu_difference(three, four, &f, set);
                    assert!(m > 10.0 * MEAN_TOL, "{set:?} {reg:?}: the candidate moves the output by only {m:.2e}");
                }
            }
        }
    }
    let mut f = Owned::synthetic(64, 48, 2, 0.6);
    f.noisy[3 * 7] = f32::NAN;
    f.depth[900] = f32::INFINITY;
    f.ao[1500] = f32::NAN;
    check("without AO nan/inf", FlrConfig { adaptive_without_ao: true, ..adaptive(cfg(base, 8)) }, &f, base);
}

/// The AO demodulation (`ao_demodulation`, on by default, so every other
/// test here runs it with AO): off and on, one window and the adaptive one,
/// a tiny offset (s down to 1e-3), AO outside [0, 1] and NaN; and it moves
/// the output by far more than the GPU's tolerance.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn ao_demodulation() {
    let set = GuideSet::NORMAL_DEPTH_AO;
    for (w, h, seed) in [(96, 64, 3), (37, 29, 8), (1, 1, 2)] {
        let mut f = Owned::synthetic(w, h, seed, 0.6);
        for (i, a) in f.ao.iter_mut().enumerate() {
            match i % 97 {
                5 => *a = -0.5,
                9 => *a = 3.0,
                _ => {}
            }
        }
        for blur in [cfg(set, 8).blur, Blur::Adaptive { sigmas: [6.0, 12.0, 20.0] }] {
            let on = FlrConfig { blur, ..cfg(set, 8) };
            assert!(on.ao_demodulation.is_some());
            for demod in [None, on.ao_demodulation, Some(1e-6)] {
                let c = FlrConfig { ao_demodulation: demod, ..on };
                check(&format!("ao demodulation {demod:?} {blur:?}"), c, &f, set);
            }
            if w * h > 1000 {
                let m = gpu_difference(FlrConfig { ao_demodulation: None, ..on }, on, &f, set);
                assert!(m > 10.0 * MEAN_TOL, "{blur:?}: the demodulation moves the output by only {m:.2e}");
            }
        }
    }
    let mut f = Owned::synthetic(64, 48, 2, 0.6);
    f.noisy[3 * 7] = f32::NAN;
    f.ao[1500] = f32::NAN;
    f.ao[1700] = f32::INFINITY;
    check("ao demodulation nan/inf", cfg(set, 8), &f, set);
}

#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn degenerate_guides_and_nonfinite_inputs() {
    let base = Owned::synthetic(64, 48, 2, 0.6);
    let n = base.w * base.h;
    let set = GuideSet { user: 1, ..GuideSet::NORMAL_DEPTH_AO };
    let cases: Vec<(&str, Vec<f32>)> = vec![
        ("constant", vec![3.25; n]),
        ("all-zero", vec![0.0; n]),
        ("duplicate of depth", base.depth.clone()),
        ("linear combination", (0..n).map(|i| 2.0 * base.depth[i] - 0.5 * base.ao[i] + 1.0).collect()),
    ];
    for (name, u) in cases {
        let mut f = base.clone();
        f.user = vec![u];
        check(name, cfg(set, 8), &f, set);
    }
    // NaN and Inf in the noisy image and in guides: excluded and counted alike
    let mut f = base.clone();
    f.noisy[3 * 7] = f32::NAN;
    f.noisy[3 * 500 + 1] = f32::INFINITY;
    f.depth[900] = f32::NAN;
    f.normal[3 * 1200 + 2] = f32::NEG_INFINITY;
    let set = GuideSet::NORMAL_DEPTH_AO;
    let (rc, _) = check("nan/inf", cfg(set, 8), &f, set);
    assert_eq!((rc.nonfinite_noisy, rc.nonfinite_guides, rc.fallback_pixels), (2, 2, 2));
}

#[test]
fn shaders_translate() {
    let s = lrdenoise_gpu::shaders().unwrap();
    assert_eq!(s.spirv[0], 0x0723_0203, "SPIR-V magic");
    for entry in ["reference", "moments", "finish_stats", "blur_rows", "blur_cols", "solve", "apply"] {
        assert!(s.msl.contains(entry) && s.hlsl.contains(entry) && s.wgsl.contains(entry), "{entry}");
    }
}

#[test]
fn plan_errors() {
    let set = GuideSet { normal: true, depth: true, position: true, ao: true, user: 2 };
    assert!(matches!(gpu::GpuPlan::new(cfg(set, 8), 64, 64), Err(Error::TooManyGuides { got: 10 })));
    assert!(matches!(gpu::GpuPlan::new(cfg(GuideSet::NORMAL_DEPTH, 8), 0, 64), Err(Error::InvalidSize { .. })));
    assert!(gpu::GpuPlan::new(cfg(GuideSet::NORMAL_DEPTH, 1), 65536, 8).is_err());
}

/// Guides far from zero: the frame reference removes a common offset exactly,
/// so world positions at 1e4 and depth at 1e3 cost no accuracy.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn large_offsets() {
    let mut f = Owned::synthetic(80, 64, 9, 0.5);
    for v in f.position.iter_mut() {
        *v += 1e4;
    }
    for v in f.depth.iter_mut() {
        *v = *v * 10.0 + 1e3;
    }
    let set = GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 };
    check("offsets", cfg(set, 8), &f, set);
}

/// f16 input buffers: the GPU reads the halves the CPU reads from f16 views.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn f16_inputs() {
    let f = Owned::synthetic(75, 61, 11, 0.5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    for c in [cfg(set, 8), adaptive(cfg(set, 8))] {
        f16_case(&f, c);
    }
}

/// The adaptive window (the library's default) on top of `c`.
fn adaptive(c: FlrConfig) -> FlrConfig {
    FlrConfig { blur: Blur::Adaptive { sigmas: lrdenoise::flr::config::DEFAULT_SIGMAS }, ..c }
}

fn f16_case(f: &Owned, c: FlrConfig) {
    use half::f16;
    let mut g = match GpuFlr::with_input(c, f.w, f.h, gpu::InputFormat::F16) {
        Err(GpuError::NoAdapter(why)) => panic!("no GPU adapter ({why}): {NEEDS_ADAPTER}"),
        r => r.unwrap(),
    };
    let h16 = |v: &[f32]| v.iter().map(|x| f16::from_f32(*x)).collect::<Vec<_>>();
    let (noisy, normal, depth, ao) = (h16(&f.noisy), h16(&f.normal), h16(&f.depth), h16(&f.ao));
    let (w, h) = (f.w, f.h);
    fn view(d: &[f16], w: usize, h: usize, ch: usize) -> ImageView<'_> {
        ImageView::f16(d, w, h, ch, Layout::interleaved(w, ch)).unwrap()
    }
    let guides = Guides {
        normal: Some(view(&normal, w, h, 3)),
        depth: Some(view(&depth, w, h, 1)),
        ao: Some(view(&ao, w, h, 1)),
        ..Default::default()
    };
    let frame = Frame::new(view(&noisy, w, h, 3), guides);
    let (cpu, _) = run_frame(c, w, h, &frame);
    let mut out = vec![0f32; 3 * w * h];
    g.denoise(&frame, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
    let (mean, _) = rel_diff(&out, &cpu);
    eprintln!("f16 inputs, {:?}: mean {mean:.2e}", c.blur);
    assert!(mean < MEAN_TOL, "f16 inputs, {:?}: {mean:.2e}", c.blur);
}

/// Joint denoise + upsample (noisy and fit guides at 1/2 and 1/4 resolution)
/// and a separate full-resolution fit set (FLNR's X'_model): the GPU takes the
/// moments from the same guides as the CPU.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn upsampling_and_separate_fit_guides() {
    let f = Owned::synthetic(101, 67, 12, 0.5);
    let (w, h) = (f.w, f.h);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let every = |v: &[f32], c: usize, u: usize| -> Vec<f32> {
        let (lw, lh) = (w.div_ceil(u), h.div_ceil(u));
        (0..lw * lh * c).map(|i| v[((i / c / lw * u) * w + (i / c % lw) * u) * c + i % c]).collect()
    };
    fn iv(d: &[f32], w: usize, h: usize, c: usize) -> ImageView<'_> {
        ImageView::interleaved(d, w, h, c).unwrap()
    }
    for u in [1, 2, 4] {
        let (lw, lh) = (w.div_ceil(u), h.div_ceil(u));
        // at u = 1: a second, different guide set to fit on
        let shift = if u == 1 { 0.05 } else { 0.0 };
        let noisy = every(&f.noisy, 3, u);
        let normal = every(&f.normal, 3, u);
        let depth: Vec<f32> = every(&f.depth, 1, u).iter().map(|d| d + shift).collect();
        let ao = every(&f.ao, 1, u);
        let low = Guides {
            normal: Some(iv(&normal, lw, lh, 3)),
            depth: Some(iv(&depth, lw, lh, 1)),
            ao: Some(iv(&ao, lw, lh, 1)),
            ..Default::default()
        };
        let frame = Frame { noisy: iv(&noisy, lw, lh, 3), guides: f.guides(set), guides_low: Some(low), sample_weights: None };
        let c = FlrConfig { upsample: u, ..cfg(set, 8) };
        for c in [adaptive(c), c] {
            let (cpu, _) = run_frame(c, w, h, &frame);
            let mut g = gpu(c, w, h);
            let mut out = vec![0f32; 3 * w * h];
            g.denoise(&frame, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
            let (mean, _) = rel_diff(&out, &cpu);
            eprintln!("upsample {u}, {:?}: mean {mean:.2e}", c.blur);
            assert!(mean < MEAN_TOL, "upsample {u}, {:?}: {mean:.2e}", c.blur);
        }
        let mut g = gpu(c, w, h);
        let mut out = vec![0f32; 3 * w * h];
        // and the same executor still runs frames without a separate set at upsample 1
        if u == 1 {
            let plain = f.frame(set);
            let (cpu, _) = run_frame(c, w, h, &plain);
            g.denoise(&plain, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
            let (mean, _) = rel_diff(&out, &cpu);
            assert!(mean < MEAN_TOL, "back to one guide set: {mean:.2e}");
        }
    }
    // upsampling without low-resolution guides is refused, as on the CPU
    let c = FlrConfig { upsample: 2, ..cfg(set, 8) };
    let mut g = gpu(c, w, h);
    let noisy = every(&f.noisy, 3, 2);
    let frame = Frame::new(iv(&noisy, w.div_ceil(2), h.div_ceil(2), 3), f.guides(set));
    let mut out = vec![0f32; 3 * w * h];
    assert!(matches!(
        g.denoise(&frame, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()),
        Err(GpuError::Config(Error::Unsupported(_)))
    ));
}

/// `f` with a handful of fireflies: samples at 1e4 × the frame's mean (two in
/// one clamp cell, one near the top, one in the bottom-right corner's
/// partial cell), at coordinates divisible by 4 so that 2× and 4×
/// subsampling keep them; a NaN and a negative sample beside them. Returns
/// the fireflies' count.
fn with_fireflies(f: &mut Owned) -> usize {
    let (w, h) = (f.w, f.h);
    let mean = f.noisy.iter().map(|v| *v as f64).sum::<f64>() / f.noisy.len() as f64;
    let (x0, y0) = ((w / 3) & !7, (h / 2) & !3);
    let mut at = vec![(x0, y0), (x0 + 4, y0), (20, 4), ((w - 1) & !3, (h - 1) & !3)];
    at.retain(|&(x, y)| x < w && y < h);
    at.sort_unstable();
    at.dedup();
    for &(x, y) in &at {
        for (c, tint) in [1.0, 0.8, 0.6].into_iter().enumerate() {
            f.noisy[3 * (y * w + x) + c] = (1e4 * mean * tint) as f32;
        }
    }
    let i = y0 * w + x0 + 1; // between the first two
    if i < w * h && w * h > 1 {
        f.noisy[3 * i] = f32::NAN;
        f.noisy[3 * (i / 2) + 1] = -0.5;
    }
    at.len()
}

/// The firefly clamp (`fireflies`, on by default) on frames with injected
/// fireflies: sizes odd, tiny and wider than one `reference` workgroup's 64
/// clamp cells; every block size (1 to 16: one or 2 × 2 clamp cells per
/// block), no guides, the adaptive window, another strength, the library's
/// default configuration, f16 inputs and upsampling. The GPU clamps the
/// samples the CPU clamps (same count, at least the injected ones) and agrees
/// with it; without the clamp the fireflies move the output far beyond the
/// tolerance.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn firefly_clamp() {
    let set = GuideSet::NORMAL_DEPTH_AO;
    let on = |c: FlrConfig| FlrConfig { fireflies: Some(lrdenoise::fireflies::DEFAULT_STRENGTH), ..c };
    for (w, h, seed) in [(96, 64, 3), (75, 61, 2), (530, 20, 5), (7, 3, 4), (1, 1, 5)] {
        let mut f = Owned::synthetic(w, h, seed, 0.5);
        let injected = with_fireflies(&mut f);
        let configs = [
            ("B8", on(cfg(set, 8))),
            ("B1", on(cfg(set, 1))),
            ("B4", on(cfg(set, 4))),
            ("B16", on(cfg(set, 16))),
            ("no guides", on(cfg(GuideSet::NONE, 8))),
            ("adaptive", on(adaptive(cfg(set, 8)))),
            ("k = 4", FlrConfig { fireflies: Some(4.0), ..cfg(set, 8) }),
            ("default", FlrConfig::default()),
        ];
        for (name, c) in configs {
            let (rc, _) = check(&format!("fireflies {name}"), c, &f, c.guides);
            if w * h > 1000 {
                assert!(rc.clamped_fireflies >= injected as u64, "{name} {w}x{h}: {} clamped of {injected}", rc.clamped_fireflies);
                let m = gpu_difference(FlrConfig { fireflies: None, ..c }, c, &f, c.guides);
                assert!(m > 10.0 * MEAN_TOL, "{name} {w}x{h}: the clamp moves the output by only {m:.2e}");
            }
        }
        // the count survives a clamp that finds nothing else to do: a frame without fireflies
        let clean = Owned::synthetic(w, h, seed, 0.5);
        let (rc, _) = check("fireflies, none injected", on(cfg(set, 8)), &clean, set);
        assert!(rc.clamped_fireflies < (w * h / 100 + 1) as u64, "{} clamped on a clean frame", rc.clamped_fireflies);
    }
    // dense: one sample in 150 at 1e4 × its value (many neighbourhoods hold
    // three or more, which the rule leaves alone), an Inf and a 65504; a band
    // of zeros but for one sample (threshold 0: clamped to 0), and a band
    // that is all zeros
    let mut f = Owned::synthetic(120, 48, 13, 0.5);
    for i in (0..120 * 48).step_by(150) {
        for c in 0..3 {
            f.noisy[3 * i + c] *= 1e4;
        }
    }
    f.noisy[3 * 2000] = f32::INFINITY;
    f.noisy[3 * 2100..3 * 2101].fill(65504.0);
    f.noisy[3 * 120 * 16..3 * 120 * 32].fill(0.0);
    f.noisy[3 * (120 * 20 + 50) + 1] = 0.25;
    for (name, c) in [("B8", on(cfg(set, 8))), ("B16", on(cfg(set, 16))), ("default", FlrConfig::default())] {
        let (rc, _) = check(&format!("fireflies dense {name}"), c, &f, c.guides);
        assert!(rc.clamped_fireflies > 10, "{name}: {} clamped", rc.clamped_fireflies);
    }
    let mut f = Owned::synthetic(75, 61, 11, 0.5);
    with_fireflies(&mut f);
    f16_case(&f, on(cfg(set, 8)));
    // upsampling: the clamp cells are 8×8 noisy pixels (blocks of 4 or 2 there)
    let (w, h) = (f.w, f.h);
    for u in [2, 4] {
        let (lw, lh) = (w.div_ceil(u), h.div_ceil(u));
        let every = |v: &[f32], c: usize| -> Vec<f32> {
            (0..lw * lh * c).map(|i| v[((i / c / lw * u) * w + (i / c % lw) * u) * c + i % c]).collect()
        };
        let (noisy, normal, depth, ao) = (every(&f.noisy, 3), every(&f.normal, 3), every(&f.depth, 1), every(&f.ao, 1));
        fn iv(d: &[f32], w: usize, h: usize, c: usize) -> ImageView<'_> {
            ImageView::interleaved(d, w, h, c).unwrap()
        }
        let low = Guides {
            normal: Some(iv(&normal, lw, lh, 3)),
            depth: Some(iv(&depth, lw, lh, 1)),
            ao: Some(iv(&ao, lw, lh, 1)),
            ..Default::default()
        };
        let frame = Frame { noisy: iv(&noisy, lw, lh, 3), guides: f.guides(set), guides_low: Some(low), sample_weights: None };
        for c in [on(cfg(set, 8)), on(adaptive(cfg(set, 8)))] {
            let c = FlrConfig { upsample: u, ..c };
            let (cpu, rc) = run_frame(c, w, h, &frame);
            let mut out = vec![0f32; 3 * w * h];
            let rg = gpu(c, w, h).denoise(&frame, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
            let (mean, max) = rel_diff(&out, &cpu);
            eprintln!("fireflies, upsample {u}, {:?}: mean {mean:.2e} max {max:.2e}", c.blur);
            assert!(mean < MEAN_TOL && max < MAX_TOL, "fireflies, upsample {u}, {:?}: mean {mean:.2e} max {max:.2e}", c.blur);
            assert!(rc.clamped_fireflies > 0, "upsample {u}: nothing clamped");
            assert_eq!(rc.clamped_fireflies, rg.clamped_fireflies, "upsample {u}");
        }
    }
}
