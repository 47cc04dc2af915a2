//! Temporal FLR on the GPU against temporal FLR on the CPU over sequences of
//! synthetic frames: a sub-pixel pan with fireflies, NaN/Inf light and bad
//! motion vectors in the frame, a disocclusion, a camera cut; with and
//! without the clamp, the output accumulation and positions; awkward sizes.
//!
//! The tests that run shaders need a wgpu adapter (lavapipe in CI) and are
//! `#[ignore]`d, as in `agree.rs`; the shader module's validation and the
//! plan's bookkeeping run everywhere.

#[path = "../../tests/common/mod.rs"]
mod common;
use common::*;
use lrdenoise::flr::temporal::TemporalFlr;
use lrdenoise::temporal::gpu::{GpuTemporalParams, GpuTemporalPlan, TemporalBuffer, GUIDE_IN_WORK, TEMPORAL_WGSL};
use lrdenoise::temporal::{History, TemporalConfig};
use lrdenoise::*;
use lrdenoise_gpu::{GpuError, GpuTemporalFlr};

/// Mean |GPU − CPU| over the mean |CPU|, per frame (f32 moments on the GPU
/// against f64 on the CPU, fed back through the history).
const MEAN_TOL: f64 = 2e-4;
/// Worst single value, relative to the mean |CPU|.
const MAX_TOL: f64 = 2e-2;

const NEEDS_ADAPTER: &str = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does";

const WITH_POSITION: GuideSet = GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 };

/// Frame `t` of a sequence: the scene panned by `t` pixels (a pixel's
/// previous position is one pixel to its right), fresh noise, a few
/// fireflies, one NaN sample, every third row's positions moved.
fn frame_at(w: usize, h: usize, t: usize) -> Owned {
    let big = Owned::synthetic(w + 16, h + 16, 5, 0.5);
    let mut f = Owned::synthetic(w, h, 5, 0.5);
    let (dx, dy) = (t, 0);
    let mut rng = Rng(0x51ed ^ (t as u64 + 1).wrapping_mul(0x2545_f491_4f6c_dd1d));
    for y in 0..h {
        for x in 0..w {
            let (i, j) = (y * w + x, (y + dy) * (w + 16) + x + dx);
            for c in 0..3 {
                f.clean[3 * i + c] = big.clean[3 * j + c];
                f.normal[3 * i + c] = big.normal[3 * j + c];
                f.position[3 * i + c] = big.position[3 * j + c];
                f.noisy[3 * i + c] = big.clean[3 * j + c] * (1.0 + 0.8 * (2.0 * rng.f32() - 1.0));
            }
            f.depth[i] = big.depth[j];
            f.ao[i] = big.ao[j];
        }
    }
    for k in 0..4 {
        let i = (rng.next_u64() as usize) % (w * h);
        f.noisy[3 * i + k % 3] *= 1e3;
    }
    f.noisy[3 * ((t * 7919) % (w * h))] = f32::NAN;
    // every third row an object that moves: positions a unit further each frame, depths
    // unchanged (rejected where positions are guides, kept by depth alone)
    for i in (0..w * h).filter(|i| (i / w).is_multiple_of(3)) {
        f.position[3 * i] += t as f32;
    }
    f
}

/// Motion of frame `t`: the pan, a quarter pixel off in x and half a pixel
/// in y (every pixel reads 4 taps), with a NaN, an Inf and a huge vector,
/// and (frame 3) a block of pixels pointing out of the frame.
fn motion_at(w: usize, h: usize, t: usize) -> Vec<f32> {
    let mut m = vec![0f32; 2 * w * h];
    for p in m.chunks_exact_mut(2) {
        p[0] = 1.25;
        p[1] = -0.5;
    }
    let n = w * h;
    m[2 * (n / 3)] = f32::NAN;
    m[2 * (n / 2) + 1] = f32::INFINITY;
    m[2 * (n / 5)] = 1e9;
    if t == 3 {
        for y in 0..h / 4 {
            for x in 0..w / 4 {
                m[2 * (y * w + x)] = -(w as f32) - 3.0;
            }
        }
    }
    m
}

fn gpu(cfg: FlrConfig, t: TemporalConfig, w: usize, h: usize) -> GpuTemporalFlr {
    match GpuTemporalFlr::new(cfg, t, w, h) {
        Ok(g) => g,
        Err(GpuError::NoAdapter(why)) => panic!("no GPU adapter ({why}): {NEEDS_ADAPTER}"),
        Err(e) => panic!("{e}"),
    }
}

/// Runs `frames` frames on both paths (frame 5 on: a camera cut, every
/// vector out of the frame) and compares each frame's output and counts.
fn sequence(name: &str, cfg: FlrConfig, t: TemporalConfig, w: usize, h: usize, frames: usize) {
    sequence_rejecting(name, cfg, cfg.guides, t, w, h, frames);
}

/// [`sequence`] with history taps judged by the guides of `reject`.
fn sequence_rejecting(name: &str, cfg: FlrConfig, reject: GuideSet, t: TemporalConfig, w: usize, h: usize, frames: usize) {
    let cpu = TemporalFlr::new(cfg, t, w, h).unwrap().with_rejection_guides(reject).unwrap();
    let mut g = gpu(cfg, t, w, h).with_rejection_guides(reject).unwrap();
    assert_eq!(g.history_len(), cpu.history_len());
    let set = cpu.frame_guides();
    assert_eq!(g.frame_guides(), set);
    let (mut hist, mut scratch, mut flr_scratch) =
        (vec![0f32; cpu.history_len()], vec![0f32; cpu.scratch_len()], vec![0f64; cpu.flr_scratch_len()]);
    let mut history = History::new(&mut hist);
    let mut rejected = 0;
    for i in 0..frames {
        let f = frame_at(w, h, i);
        let mut m = motion_at(w, h, i);
        if i >= 5 {
            m.iter_mut().for_each(|v| *v = 4.0 * w.max(h) as f32 / 3.0);
        }
        let mv = ImageView::interleaved(&m, w, h, 2).unwrap();
        let frame = f.frame(set);
        let (mut a, mut b) = (vec![0f32; 3 * w * h], vec![0f32; 3 * w * h]);
        let rc = cpu
            .denoise(
                &frame,
                Some(&mv),
                &mut history,
                &mut scratch,
                &mut flr_scratch,
                &mut ImageViewMut::interleaved(&mut a, w, h, 3).unwrap(),
            )
            .unwrap();
        let rg = g.denoise(&frame, Some(&mv), &mut ImageViewMut::interleaved(&mut b, w, h, 3).unwrap()).unwrap();
        assert!(b.iter().all(|v| v.is_finite()), "{name} frame {i}: GPU output not finite");
        let (mean, max) = rel_diff(&b, &a);
        eprintln!(
            "{name} {w}x{h} frame {i}: mean {mean:.2e} max {max:.2e} rejected {} clamped {}",
            rc.history_rejected, rc.clamped_fireflies
        );
        assert!(mean < MEAN_TOL && max < MAX_TOL, "{name} {w}x{h} frame {i}: mean {mean:.2e} max {max:.2e}");
        assert_eq!(
            (rc.history_rejected, rc.invalid_motion, rc.history_resets, rc.nonfinite_noisy),
            (rg.history_rejected, rg.invalid_motion, rg.history_resets, rg.nonfinite_noisy),
            "{name} frame {i}: rejected, invalid motion, cut, NaN/Inf"
        );
        // a sample within rounding of its threshold may go either way
        assert!(rc.clamped_fireflies.abs_diff(rg.clamped_fireflies) <= 1, "{name} frame {i}: clamped {rc:?} {rg:?}");
        assert_eq!((rc.empty_blocks, rc.fallback_pixels), (rg.empty_blocks, rg.fallback_pixels), "{name} frame {i}");
        rejected += rc.history_rejected;
        if i == 5 {
            assert_eq!(rc.history_resets, 1, "{name}: frame 5 is a cut");
        }
    }
    assert_eq!(g.frames(), frames as u32);
    assert!(rejected > 0, "{name}: the sequence has disocclusions");
    // the device's history has the CPU's layout: the GPU's and the CPU's agree
    // (without output accumulation the CPU leaves the previous output's fields,
    // 4..7 of each record, unwritten: nothing reads them)
    let mut on_gpu = vec![f32::NAN; g.history_len()];
    assert_eq!(g.history(&mut on_gpu).unwrap(), history.frames());
    let (slot, rec) = (cpu.stage().slot_len(), cpu.stage().slot_len() / (w * h));
    let unread = |i: usize| !cpu.stage().accumulates_output() && (4..7).contains(&((i % slot) / w % rec));
    let finite = |v: &[f32]| v.iter().enumerate().map(|(i, x)| if x.is_finite() && !unread(i) { *x } else { 0.0 }).collect::<Vec<_>>();
    let (mean, _) = rel_diff(&finite(&on_gpu), &finite(&hist));
    assert!(mean < MEAN_TOL, "{name}: histories differ by {mean:.2e}");
}

/// A sequence moves from the CPU to the GPU: the GPU resumes the CPU's
/// history and gives the CPU's next frame.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn a_cpu_history_resumes_on_the_gpu() {
    let (w, h) = (40, 24);
    let cfg = FlrConfig::with_guides(GuideSet::NORMAL_DEPTH_AO);
    let t = TemporalConfig::default();
    let cpu = TemporalFlr::new(cfg, t, w, h).unwrap();
    let mut g = gpu(cfg, t, w, h);
    let (mut hist, mut scratch, mut flr_scratch) =
        (vec![0f32; cpu.history_len()], vec![0f32; cpu.scratch_len()], vec![0f64; cpu.flr_scratch_len()]);
    let mut frames = 0;
    let mut last = (vec![0f32; 3 * w * h], vec![0f32; 3 * w * h]);
    for i in 0..4 {
        let f = frame_at(w, h, i);
        let m = motion_at(w, h, 1);
        let mv = ImageView::interleaved(&m, w, h, 2).unwrap();
        let frame = f.frame(cfg.guides);
        if i == 3 {
            g.set_history(&hist, frames).unwrap();
            g.denoise(&frame, Some(&mv), &mut ImageViewMut::interleaved(&mut last.1, w, h, 3).unwrap()).unwrap();
        }
        let mut history = History::resume(&mut hist, frames);
        cpu.denoise(
            &frame,
            Some(&mv),
            &mut history,
            &mut scratch,
            &mut flr_scratch,
            &mut ImageViewMut::interleaved(&mut last.0, w, h, 3).unwrap(),
        )
        .unwrap();
        frames = history.frames();
    }
    let (mean, max) = rel_diff(&last.1, &last.0);
    assert!(mean < MEAN_TOL && max < MAX_TOL, "mean {mean:.2e} max {max:.2e}");
    assert!(g.set_history(&hist[1..], 3).is_err(), "a history of another length is refused");
}

#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn a_pan_with_fireflies_bad_motion_and_a_cut_matches_the_cpu() {
    let cfg = FlrConfig::with_guides(GuideSet::NORMAL_DEPTH_AO);
    for (w, h) in [(61, 37), (130, 67)] {
        sequence("defaults", cfg, TemporalConfig::default(), w, h, 7);
    }
}

#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn positions_no_clamp_and_no_output_blend_match_the_cpu() {
    let (w, h) = (57, 41);
    let pos = FlrConfig::with_guides(WITH_POSITION);
    sequence("positions", pos, TemporalConfig::default(), w, h, 6);
    // without depth: positions judged against each pixel's footprint
    let no_depth = FlrConfig::with_guides(GuideSet { normal: true, position: true, ..GuideSet::NONE });
    sequence("positions without depth", no_depth, TemporalConfig::default(), w, h, 6);
    let off = FlrConfig { fireflies: None, ..FlrConfig::with_guides(GuideSet::NORMAL_DEPTH) };
    sequence("no clamp", off, TemporalConfig { output_alpha: 1.0, firefly_history: 0.0, ..TemporalConfig::default() }, w, h, 6);
    let one = FlrConfig::with_guides(GuideSet { normal: false, depth: false, position: false, ao: true, user: 0 });
    sequence("no rejection guides", one, TemporalConfig::default(), 9, 7, 6);
}

/// History judged by guides FLR does not fit with (uploaded into the work
/// buffer): positions next to FLR's normal, depth and AO, as `lrd` runs
/// frames that have them, and normal and depth under a fit on AO alone.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn rejection_guides_beyond_flrs_match_the_cpu() {
    let t = TemporalConfig::default();
    let cfg = FlrConfig::with_guides(GuideSet::NORMAL_DEPTH_AO);
    sequence_rejecting("positions beside FLR's", cfg, GuideSet { position: true, ..GuideSet::NORMAL_DEPTH_AO }, t, 61, 37, 7);
    let ao = FlrConfig::with_guides(GuideSet { normal: false, depth: false, position: false, ao: true, user: 0 });
    sequence_rejecting("normal and depth beside AO", ao, GuideSet::NORMAL_DEPTH, t, 33, 20, 6);
}

#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn bad_calls_are_refused() {
    let cfg = FlrConfig::with_guides(GuideSet::NORMAL_DEPTH);
    assert!(matches!(
        GpuTemporalFlr::new(FlrConfig { upsample: 2, ..cfg }, TemporalConfig::default(), 64, 48),
        Err(GpuError::Config(Error::Unsupported(_)))
    ));
    let r = GpuTemporalFlr::new(FlrConfig { fireflies: Some(0.5), ..cfg }, TemporalConfig::default(), 32, 24);
    assert!(matches!(r, Err(GpuError::Config(Error::InvalidConfig(_)))), "a clamp factor below 1 is refused at creation: {r:?}");
    let mut g = gpu(cfg, TemporalConfig::default(), 32, 24);
    let f = Owned::synthetic(32, 24, 1, 0.5);
    let m = vec![0f32; 2 * 16 * 24];
    let mut out = vec![0f32; 3 * 32 * 24];
    let mv = ImageView::interleaved(&m, 16, 24, 2).unwrap();
    let r = g.denoise(&f.frame(GuideSet::NORMAL_DEPTH), Some(&mv), &mut ImageViewMut::interleaved(&mut out, 32, 24, 3).unwrap());
    assert!(matches!(r, Err(GpuError::Config(Error::SizeMismatch { arg: Arg::Motion, .. }))), "{r:?}");
    assert_eq!(g.frames(), 0, "a refused frame leaves the history alone");
    let r = g.denoise(
        &f.frame(GuideSet { depth: false, ..GuideSet::NORMAL_DEPTH }),
        None,
        &mut ImageViewMut::interleaved(&mut out, 32, 24, 3).unwrap(),
    );
    assert!(matches!(r, Err(GpuError::Config(Error::GuideMismatch))), "{r:?}");
}

/// The module validates and translates to SPIR-V, MSL and HLSL (no adapter needed).
#[test]
fn the_temporal_module_validates_and_translates() {
    let s = lrdenoise_gpu::translate(TEMPORAL_WGSL).unwrap();
    for entry in ["t_cells", "t_taps", "t_thresholds", "t_accumulate", "t_resolve"] {
        assert!(s.msl.contains(entry) && s.hlsl.contains(entry), "{entry}");
    }
    assert!(!s.spirv.is_empty());
}

/// The plan mirrors the CPU stage: the same history length, slots that
/// alternate with the frame count, no history on the first frame, the cut
/// limit of `cut_fraction`.
#[test]
fn the_plan_mirrors_the_cpu_stage() {
    let (w, h) = (33, 17);
    let t = TemporalConfig { cut_fraction: 0.5, ..TemporalConfig::default() };
    let plan = GpuTemporalPlan::new(t, GuideSet::NORMAL_DEPTH_AO, w, h).unwrap();
    let cpu = TemporalFlr::new(FlrConfig::with_guides(GuideSet::NORMAL_DEPTH_AO), t, w, h).unwrap();
    assert_eq!(plan.stage().history_len(), cpu.history_len());
    let p0 = plan.params(0, Some(1.5), false).unwrap();
    let p1 = plan.params(1, Some(1.5), false).unwrap();
    assert_eq!((p0.has_history, p1.has_history), (0, 1));
    // the slots alternate with the frame count, as the CPU's History's do
    assert_eq!((GpuTemporalPlan::slots(0), GpuTemporalPlan::slots(1), GpuTemporalPlan::slots(2)), ((1, 0), (0, 1), (1, 0)));
    assert_eq!(p0.cut_limit as usize, w * h / 2);
    // normal planes 0..3, depth 3 (AO 4 is not a rejection guide)
    assert_eq!((p0.g_normal, p0.g_depth, p0.g_position), (0, 3 * (w * h) as u32, u32::MAX));
    assert!(plan.params(0, Some(0.5), false).is_err(), "a clamp factor below 1 is refused");
    let b = plan.buffers();
    // one slot per history buffer: the history is slot 0 then slot 1
    assert_eq!((b[3].buffer, b[8].buffer), (TemporalBuffer::HistoryIn, TemporalBuffer::HistoryOut));
    assert_eq!(2 * b[3].bytes, 4 * cpu.history_len() as u64);
    assert_eq!(b[3].bytes, b[8].bytes);
    assert!(
        b.iter().filter(|d| d.access != lrdenoise::flr::gpu::Access::Uniform).count() <= 8,
        "WebGPU's default: 8 storage buffers per stage"
    );
    assert!(b.iter().enumerate().all(|(i, d)| d.binding == i as u32));
    let bytes: Vec<u8> = [(w * h) as u32, 2, 0, 9].iter().flat_map(|v| v.to_le_bytes()).collect();
    let counts = plan.counts(&bytes, &p1);
    assert_eq!((counts.cut, counts.rejected, counts.invalid_motion, counts.clamped), (1, 0, 2, 9));
    assert_eq!(plan.work_guides(), [None; 3], "every rejection guide is FLR's");
}

/// Rejection guides FLR does not read go into the work buffer after the
/// motion, flagged in the parameter block; the history has the CPU's layout.
#[test]
fn rejection_guides_beyond_flrs_are_planned_in_the_work_buffer() {
    let (w, h) = (33, 17);
    let plane = (w * h) as u64;
    let t = TemporalConfig::default();
    let with_position = GuideSet { position: true, ..GuideSet::NORMAL_DEPTH_AO };
    let plan = GpuTemporalPlan::with_rejection_guides(t, GuideSet::NORMAL_DEPTH_AO, with_position, w, h).unwrap();
    let cpu = TemporalFlr::new(FlrConfig::with_guides(GuideSet::NORMAL_DEPTH_AO), t, w, h).unwrap();
    let cpu = cpu.with_rejection_guides(with_position).unwrap();
    assert_eq!(plan.stage().history_len(), cpu.history_len());
    let mo = plan.motion_offset();
    assert_eq!(plan.work_guides(), [None, Some(mo + 8 * plane), None]);
    let p = plan.params(0, None, false).unwrap();
    assert_eq!((p.g_normal, p.g_depth), (0, 3 * plane as u32), "FLR's own planes");
    assert_eq!(p.g_position, GUIDE_IN_WORK | (mo / 4 + 2 * plane) as u32);
    let fitted_alone = GpuTemporalPlan::new(t, GuideSet::NORMAL_DEPTH_AO, w, h).unwrap();
    let work = |p: &GpuTemporalPlan| p.buffers()[TemporalBuffer::Work as usize].bytes;
    assert_eq!(work(&plan), work(&fitted_alone) + 3 * 4 * plane, "three more planes");
    assert!(mo + 4 * 5 * plane <= work(&plan), "motion and guides fit in the work buffer");
    // a fit on AO alone: normal and depth both in the work buffer, in that order
    let ao = GuideSet { normal: false, depth: false, position: false, ao: true, user: 0 };
    let plan = GpuTemporalPlan::with_rejection_guides(t, ao, GuideSet::NORMAL_DEPTH, w, h).unwrap();
    assert_eq!(plan.work_guides(), [Some(mo + 8 * plane), None, Some(mo + 20 * plane)]);
    let p = plan.params(1, None, false).unwrap();
    assert_eq!((p.g_normal & GUIDE_IN_WORK, p.g_position, p.g_depth & GUIDE_IN_WORK), (GUIDE_IN_WORK, u32::MAX, GUIDE_IN_WORK));
    assert_eq!(plan.buffers()[TemporalBuffer::Guides as usize].bytes, 4 * plane, "FLR's AO plane");
}

/// The Rust parameter block has the WGSL `Params` layout: the same fields in
/// the same order at the same offsets, and the same size (no adapter needed).
#[test]
fn the_parameter_block_matches_the_shader() {
    macro_rules! offsets {
        ($($f:ident),*) => { [$((stringify!($f), core::mem::offset_of!(GpuTemporalParams, $f) as u32)),*] };
    }
    let rust = offsets!(
        width,
        height,
        nc,
        bands,
        record,
        n_at,
        p_at,
        d_at,
        cells_at,
        has_history,
        g_normal,
        g_position,
        g_depth,
        clamp_negative,
        fireflies,
        firefly_history,
        max_history,
        normal_limit,
        position_limit,
        depth_limit,
        clip_gamma,
        output_alpha,
        cut_limit,
        max_motion,
        footprint_limit2,
        pad
    );
    let module = naga::front::wgsl::parse_str(TEMPORAL_WGSL).unwrap();
    let (members, span) = module
        .types
        .iter()
        .find_map(|(_, t)| match &t.inner {
            naga::TypeInner::Struct { members, span } if t.name.as_deref() == Some("Params") => Some((members.clone(), *span)),
            _ => None,
        })
        .expect("the WGSL declares Params");
    let wgsl: Vec<(String, u32)> =
        members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset)).filter(|(n, _)| !n.starts_with("pad")).collect();
    let rust: Vec<(String, u32)> = rust.iter().filter(|(n, _)| *n != "pad").map(|(n, o)| (n.to_string(), *o)).collect();
    assert_eq!(wgsl, rust);
    assert_eq!(span as usize, core::mem::size_of::<GpuTemporalParams>());
}

/// A device whose storage bindings are smaller than a history slot gives a
/// typed error at creation, naming the buffer; a 1080p history (two 91 MB
/// slots) fits wgpu's default limits and runs.
#[test]
#[ignore = "needs a wgpu adapter (lavapipe: mesa-vulkan-drivers); run with --ignored, CI does"]
fn buffer_limits_are_checked_and_1080p_fits_the_default_limits() {
    let device = |limits: wgpu::Limits| {
        let instance = wgpu::Instance::default();
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default())).expect(NEEDS_ADAPTER);
        let desc = wgpu::DeviceDescriptor { required_limits: limits, ..Default::default() };
        let (d, q) = pollster::block_on(adapter.request_device(&desc)).unwrap();
        (d, q)
    };
    let cfg = FlrConfig::with_guides(GuideSet::NORMAL_DEPTH);
    let small = wgpu::Limits { max_storage_buffer_binding_size: 1 << 20, ..wgpu::Limits::default() };
    let (d, q) = device(small);
    let r = GpuTemporalFlr::with_device(d, q, "small".into(), cfg, TemporalConfig::default(), 256, 256);
    assert!(matches!(r, Err(GpuError::TooLarge { limit: 1048576, .. })), "{r:?}");

    let (w, h) = (1920, 1080);
    let (d, q) = device(wgpu::Limits::default());
    let mut g = GpuTemporalFlr::with_device(d, q, "default limits".into(), cfg, TemporalConfig::default(), w, h).unwrap();
    let f = Owned::synthetic(w, h, 1, 0.5);
    let mut out = vec![f32::NAN; 3 * w * h];
    for _ in 0..2 {
        g.denoise(&f.frame(cfg.guides), None, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
    }
    assert!(out.iter().all(|v| v.is_finite()));
    let mut history = vec![0f32; g.history_len()];
    assert_eq!(g.history(&mut history).unwrap(), 2);
    assert!(g.history_len() * 4 > 128 << 20, "the history is larger than one default binding");
}
