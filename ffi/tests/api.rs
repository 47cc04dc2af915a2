//! The C entry points called from Rust: null pointers, bad strides and sizes,
//! f16 images, planar outputs, status strings.

use lrdenoise::*;
use std::ffi::CStr;
use std::ptr::{null, null_mut};

fn img(data: *const f32, w: u32, h: u32, ch: usize) -> LrdImage {
    LrdImage { data: data as *const _, format: 0, width: w, height: h, pixel_stride: ch * 4, row_stride: 0, channel_stride: 0 }
}
fn none() -> LrdImage {
    LrdImage { data: null(), format: 0, width: 0, height: 0, pixel_stride: 0, row_stride: 0, channel_stride: 0 }
}
fn guides_none() -> LrdGuides {
    LrdGuides { normal: none(), depth: none(), position: none(), ao: none(), user: [none(); 4] }
}

/// A frame of packed RGB noise and a depth guide (the views borrow the vectors).
fn depth_frame(noisy: &[f32], depth: &[f32], w: u32, h: u32) -> LrdFrame {
    let mut frame =
        LrdFrame { noisy: img(noisy.as_ptr(), w, h, 3), guides: guides_none(), guides_low: guides_none(), sample_weights: none() };
    frame.guides.depth = img(depth.as_ptr(), w, h, 1);
    frame
}

/// A depth guide that rises row by row.
fn depth_ramp(w: u32, h: u32) -> Vec<f32> {
    (0..(w * h) as usize).map(|i| 1.0 + (i / w as usize) as f32 * 0.1).collect()
}

/// Scratch for `cfg` at `w`×`h` (sized by `lrd_flr_scratch_size`, which must
/// succeed) and its size in bytes.
fn flr_scratch(cfg: &LrdFlrConfig, w: u32, h: u32) -> (Vec<f64>, usize) {
    let mut bytes = 0usize;
    // SAFETY: `cfg` and `bytes` are valid references for the duration of the call.
    assert_eq!(unsafe { lrd_flr_scratch_size(cfg, w, h, &mut bytes) }, LrdStatus::LRD_STATUS_OK);
    (vec![0f64; bytes / 8 + 1], bytes)
}

/// A packed f32 RGB output over `out`.
fn packed_out(out: &mut [f32], w: u32, h: u32) -> LrdImageMut {
    LrdImageMut { data: out.as_mut_ptr() as *mut _, format: 0, width: w, height: h, pixel_stride: 0, row_stride: 0, channel_stride: 0 }
}

/// Packed f32 guide planes of one frame size, handed to the C API
/// ([`GuidePlanes::c_frame`]) and to the Rust API
/// ([`GuidePlanes::rust_frame`]) from the same memory.
struct GuidePlanes {
    w: u32,
    h: u32,
    normal: Vec<f32>,
    depth: Vec<f32>,
    ao: Vec<f32>,
    position: Option<Vec<f32>>,
}

impl GuidePlanes {
    /// A C frame of `noisy` (packed RGB) and these guides (positions only with `position`).
    fn c_frame(&self, noisy: &[f32], position: bool) -> LrdFrame {
        let (w, h) = (self.w, self.h);
        let mut frame =
            LrdFrame { noisy: img(noisy.as_ptr(), w, h, 3), guides: guides_none(), guides_low: guides_none(), sample_weights: none() };
        frame.guides.normal = img(self.normal.as_ptr(), w, h, 3);
        frame.guides.depth = img(self.depth.as_ptr(), w, h, 1);
        frame.guides.ao = img(self.ao.as_ptr(), w, h, 1);
        if let Some(p) = self.position.as_ref().filter(|_| position) {
            frame.guides.position = img(p.as_ptr(), w, h, 3);
        }
        frame
    }

    /// The Rust frame of [`GuidePlanes::c_frame`] (with the positions where there are some).
    fn rust_frame<'a>(&'a self, noisy: &'a [f32]) -> lrdenoise_core::Frame<'a> {
        use lrdenoise_core::{Frame, Guides, ImageView};
        let (w, h) = (self.w as usize, self.h as usize);
        let g = Guides {
            normal: Some(ImageView::interleaved(&self.normal, w, h, 3).unwrap()),
            depth: Some(ImageView::interleaved(&self.depth, w, h, 1).unwrap()),
            ao: Some(ImageView::interleaved(&self.ao, w, h, 1).unwrap()),
            position: self.position.as_ref().map(|p| ImageView::interleaved(p, w, h, 3).unwrap()),
            ..Default::default()
        };
        Frame::new(ImageView::interleaved(noisy, w, h, 3).unwrap(), g)
    }
}

#[test]
fn entry_points_validate_everything() {
    let (w, h) = (37u32, 21u32);
    let n = (w * h) as usize;
    let noisy: Vec<f32> = (0..3 * n).map(|i| (i % 7) as f32 * 0.1).collect();
    let depth = depth_ramp(w, h);
    let mut cfg = lrd_flr_config_default();
    cfg.guides = LRD_GUIDE_DEPTH;
    let frame = depth_frame(&noisy, &depth, w, h);
    let mut out = vec![0f32; 3 * n];
    let o = packed_out(&mut out, w, h);
    let (mut scratch, mut bytes) = flr_scratch(&cfg, w, h);
    unsafe {
        let sp = scratch.as_mut_ptr() as *mut _;
        let mut rep = LrdReport::default();
        assert_eq!(lrd_flr_denoise(&cfg, &frame, &o, sp, bytes, &mut rep), LrdStatus::LRD_STATUS_OK);
        assert!(out.iter().all(|v| v.is_finite()));
        // nulls
        assert_eq!(lrd_flr_denoise(null(), &frame, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        assert_eq!(lrd_flr_denoise(&cfg, &frame, null(), sp, bytes, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        assert_eq!(lrd_flr_denoise(&cfg, &frame, &o, null_mut(), bytes, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        let mut nf = frame;
        nf.noisy.data = null();
        assert_eq!(lrd_flr_denoise(&cfg, &nf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        // misaligned scratch, short scratch
        assert_eq!(
            lrd_flr_denoise(&cfg, &frame, &o, (sp as *mut u8).add(4) as *mut _, bytes, null_mut()),
            LrdStatus::LRD_STATUS_INVALID_ARGUMENT
        );
        assert_eq!(lrd_flr_denoise(&cfg, &frame, &o, sp, bytes - 1, null_mut()), LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL);
        // bad format, odd stride, size mismatch, guide mismatch, bad config
        let mut bf = frame;
        bf.noisy.format = 7;
        assert_eq!(lrd_flr_denoise(&cfg, &bf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
        bf = frame;
        bf.guides.depth.row_stride = 3;
        assert_eq!(lrd_flr_denoise(&cfg, &bf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
        bf = frame;
        bf.guides.depth.width = w - 1;
        assert_eq!(lrd_flr_denoise(&cfg, &bf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_SIZE_MISMATCH);
        bf = frame;
        bf.guides.ao = img(depth.as_ptr(), w, h, 1);
        assert_eq!(lrd_flr_denoise(&cfg, &bf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_GUIDE_MISMATCH);
        let mut bc = cfg;
        bc.sigmas[1] = f32::NAN; // the default blur is the adaptive window
        assert_eq!(lrd_flr_scratch_size(&bc, w, h, &mut bytes), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        bc = cfg;
        bc.blur = LrdBlur::LRD_BLUR_GAUSSIAN as u32;
        bc.sigma = f32::NAN;
        assert_eq!(lrd_flr_scratch_size(&bc, w, h, &mut bytes), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        bc = cfg;
        bc.blur = 9;
        assert_eq!(lrd_flr_scratch_size(&bc, w, h, &mut bytes), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        assert_eq!(lrd_flr_scratch_size(&cfg, 0, h, &mut bytes), LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
        // tiles: bad stage / tile / worker
        let mut tb = 0;
        assert_eq!(lrd_flr_tiled_scratch_size(&cfg, w, h, 1, &mut tb), LrdStatus::LRD_STATUS_OK);
        // the tiled scratch is larger than the whole-frame one with the adaptive window
        let mut tiled_scratch = vec![0f64; tb / 8 + 1];
        let sp = tiled_scratch.as_mut_ptr() as *mut _;
        for (stage, tile, worker) in [(7, 0, 0), (0, 1, 0), (1, 99, 0), (1, 0, 1), (6, 99, 0)] {
            assert_eq!(lrd_flr_run_tile(&cfg, &frame, &o, sp, tb, 1, stage, tile, worker, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        }
        assert_eq!(lrd_flr_run_tile(&cfg, &frame, &o, sp, tb, 0, 1, 0, 0, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        // f16 noisy + planar f32 output give the same result as f32 interleaved
        let n16: Vec<half::f16> = noisy.iter().map(|v| half::f16::from_f32(*v)).collect();
        let noisy_r: Vec<f32> = n16.iter().map(|v| v.to_f32()).collect();
        let mut fr = frame;
        fr.noisy.data = noisy_r.as_ptr() as *const _;
        let mut want = vec![0f32; 3 * n];
        let ow = LrdImageMut { data: want.as_mut_ptr() as *mut _, ..o };
        assert_eq!(lrd_flr_denoise(&cfg, &fr, &ow, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_OK);
        fr.noisy =
            LrdImage { data: n16.as_ptr() as *const _, format: 1, width: w, height: h, pixel_stride: 6, row_stride: 0, channel_stride: 0 };
        let mut planar = vec![0f32; 3 * n];
        let op = LrdImageMut {
            data: planar.as_mut_ptr() as *mut _,
            format: 0,
            width: w,
            height: h,
            pixel_stride: 4,
            row_stride: 4 * w as usize,
            channel_stride: 4 * n,
        };
        assert_eq!(lrd_flr_denoise(&cfg, &fr, &op, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_OK);
        for i in 0..n {
            for c in 0..3 {
                assert_eq!(planar[c * n + i], want[3 * i + c]);
            }
        }
        // planar output cannot be split into row bands for APPLY
        let mut nt = 0u32;
        assert_eq!(lrd_flr_tile_count(&cfg, w, h, &mut nt), LrdStatus::LRD_STATUS_OK);
        assert!(nt >= 1);
        for stage in 0..6 {
            let tiles = if stage == 0 || stage == 2 { 1 } else { nt };
            for t in 0..tiles {
                assert_eq!(lrd_flr_run_tile(&cfg, &fr, &op, sp, tb, 1, stage, t, 0, null_mut()), LrdStatus::LRD_STATUS_OK);
            }
        }
        assert_eq!(lrd_flr_run_tile(&cfg, &fr, &op, sp, tb, 1, 6, 0, 0, null_mut()), LrdStatus::LRD_STATUS_UNSUPPORTED);
    }
    for s in 0..13 {
        let m = unsafe { CStr::from_ptr(lrd_status_string(s)) };
        assert!(!m.to_bytes().is_empty());
    }
    assert_eq!(unsafe { CStr::from_ptr(lrd_version()) }.to_str().unwrap(), env!("CARGO_PKG_VERSION"));
    assert_eq!(lrd_features() & LRD_FEATURE_FLR, LRD_FEATURE_FLR);
}

#[test]
fn gpu_temporal_dispatch_description() {
    use lrdenoise_core::temporal::gpu::{GpuTemporalPlan, TEMPORAL_WGSL};
    let (cfg, t) = (lrd_flr_config_default(), lrd_temporal_config_default());
    let mut d = std::mem::MaybeUninit::<LrdGpuTemporalDispatch>::zeroed();
    assert_eq!(unsafe { lrd_gpu_temporal_dispatch(&cfg, &t, 100, 70, d.as_mut_ptr()) }, LrdStatus::LRD_STATUS_OK);
    let d = unsafe { d.assume_init() };
    let core = lrdenoise_core::FlrConfig::default();
    let plan = GpuTemporalPlan::new(lrdenoise_core::temporal::TemporalConfig::default(), core.guides, 100, 70).unwrap();
    let names = |p: &[LrdGpuPass]| p.iter().map(|p| unsafe { CStr::from_ptr(p.entry) }.to_str().unwrap().to_string()).collect::<Vec<_>>();
    assert_eq!(names(&d.before), ["t_cells", "t_taps", "t_thresholds", "t_accumulate"]);
    assert_eq!(names(&[d.after]), ["t_resolve"]);
    assert_eq!(d.before.map(|p| p.workgroups), plan.passes_before().map(|p| p.workgroups));
    assert_eq!(d.buffer_bytes, plan.buffers().map(|b| b.bytes));
    assert_eq!(d.motion_offset, plan.motion_offset());
    assert_eq!(&d.params_first[..], plan.params(0, core.fireflies, core.clamp_negative).unwrap().as_bytes());
    assert_eq!(&d.params[..], plan.params(1, core.fireflies, core.clamp_negative).unwrap().as_bytes());
    assert_eq!(d.cut_limit as usize, 100 * 70 / 2);
    assert_eq!(d.work_guides, [u64::MAX; 3], "FLR's guides judge the history");
    // FLR's part: the configuration without its clamp (the stage clamps), f32
    let mut no_clamp = cfg;
    no_clamp.fireflies = 0.0;
    let mut f = std::mem::MaybeUninit::<LrdGpuDispatch>::zeroed();
    assert_eq!(unsafe { lrd_gpu_dispatch(&no_clamp, 100, 70, 0, f.as_mut_ptr()) }, LrdStatus::LRD_STATUS_OK);
    let f = unsafe { f.assume_init() };
    assert_eq!((d.flr.pass_count, d.flr.buffer_bytes, d.flr.params), (f.pass_count, f.buffer_bytes, f.params));
    // the slots, slot 0 then slot 1, are the CPU history
    let (mut scratch, mut history) = (0usize, 0usize);
    assert_eq!(unsafe { lrd_flr_temporal_sizes(&cfg, &t, 100, 70, &mut scratch, &mut history) }, LrdStatus::LRD_STATUS_OK);
    assert_eq!(2 * d.buffer_bytes[3] as usize, history);
    assert_eq!(unsafe { CStr::from_ptr(lrd_gpu_temporal_wgsl()) }.to_str().unwrap(), TEMPORAL_WGSL);
    // refused
    let mut out = std::mem::MaybeUninit::<LrdGpuTemporalDispatch>::zeroed();
    let call = |c: *const LrdFlrConfig, t: *const LrdTemporalConfig, w: u32, o: *mut LrdGpuTemporalDispatch| unsafe {
        lrd_gpu_temporal_dispatch(c, t, w, 70, o)
    };
    assert_eq!(call(null(), &t, 100, out.as_mut_ptr()), LrdStatus::LRD_STATUS_NULL_POINTER);
    assert_eq!(call(&cfg, null(), 100, out.as_mut_ptr()), LrdStatus::LRD_STATUS_NULL_POINTER);
    assert_eq!(call(&cfg, &t, 100, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
    assert_eq!(call(&cfg, &t, 0, out.as_mut_ptr()), LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
    let mut up = cfg;
    up.upsample = 2;
    assert_eq!(call(&up, &t, 100, out.as_mut_ptr()), LrdStatus::LRD_STATUS_UNSUPPORTED);
    let mut bad = t;
    bad.rejection_guides = LRD_GUIDE_AO;
    assert_eq!(call(&cfg, &bad, 100, out.as_mut_ptr()), LrdStatus::LRD_STATUS_INVALID_CONFIG);
    let mut bad = t;
    bad.max_history = 0.0;
    assert_eq!(call(&cfg, &bad, 100, out.as_mut_ptr()), LrdStatus::LRD_STATUS_INVALID_CONFIG);
}

/// Rejection guides beyond FLR's: the planes FLR does not read go into the
/// work buffer, and the slots are still the CPU history of the same configs.
#[test]
fn gpu_temporal_dispatch_with_rejection_guides() {
    use lrdenoise_core::temporal::gpu::GpuTemporalPlan;
    use lrdenoise_core::GuideSet;
    let (cfg, mut t) = (lrd_flr_config_default(), lrd_temporal_config_default());
    t.rejection_guides = LRD_GUIDE_NORMAL | LRD_GUIDE_DEPTH | LRD_GUIDE_POSITION;
    let mut d = std::mem::MaybeUninit::<LrdGpuTemporalDispatch>::zeroed();
    assert_eq!(unsafe { lrd_gpu_temporal_dispatch(&cfg, &t, 100, 70, d.as_mut_ptr()) }, LrdStatus::LRD_STATUS_OK);
    let d = unsafe { d.assume_init() };
    let core = lrdenoise_core::FlrConfig::default();
    let reject = GuideSet { position: true, ..core.guides };
    let plan =
        GpuTemporalPlan::with_rejection_guides(lrdenoise_core::temporal::TemporalConfig::default(), core.guides, reject, 100, 70).unwrap();
    let positions = plan.work_guides()[1].unwrap();
    assert_eq!(d.work_guides, [u64::MAX, positions, u64::MAX]);
    assert_eq!(positions, d.motion_offset + 2 * 4 * 100 * 70, "after the motion");
    assert_eq!(d.buffer_bytes, plan.buffers().map(|b| b.bytes));
    assert_eq!(&d.params[..], plan.params(1, core.fireflies, core.clamp_negative).unwrap().as_bytes());
    let (mut scratch, mut history) = (0usize, 0usize);
    assert_eq!(unsafe { lrd_flr_temporal_sizes(&cfg, &t, 100, 70, &mut scratch, &mut history) }, LrdStatus::LRD_STATUS_OK);
    assert_eq!(2 * d.buffer_bytes[3] as usize, history, "the CPU history with positions");
}

#[test]
fn gpu_dispatch_description() {
    use lrdenoise_core::flr::gpu::{GpuLayouts, GpuPlan};
    let cfg = lrd_flr_config_default();
    let mut d = std::mem::MaybeUninit::<LrdGpuDispatch>::zeroed();
    assert_eq!(unsafe { lrd_gpu_dispatch(&cfg, 100, 70, 0, d.as_mut_ptr()) }, LrdStatus::LRD_STATUS_OK);
    let d = unsafe { d.assume_init() };
    let plan = GpuPlan::new(lrdenoise_core::FlrConfig::default(), 100, 70).unwrap();
    let layouts = GpuLayouts::planar(100, 70, lrdenoise_core::flr::gpu::InputFormat::F32);
    assert_eq!(d.pass_count as usize, plan.passes().len());
    for (c, r) in d.passes.iter().zip(plan.passes().iter()) {
        assert_eq!(unsafe { CStr::from_ptr(c.entry) }, r.entry);
        assert_eq!(c.workgroups, r.workgroups);
    }
    for (c, r) in d.buffer_bytes.iter().zip(plan.buffers(&layouts).unwrap()) {
        assert_eq!(*c, r.bytes);
    }
    assert_eq!(&d.params[..], plan.params(&layouts).unwrap().as_bytes());
    let wgsl = unsafe { CStr::from_ptr(lrd_gpu_wgsl()) }.to_str().unwrap();
    assert_eq!(wgsl, lrdenoise_core::flr::gpu::FLR_WGSL);
    // errors
    let mut out = std::mem::MaybeUninit::<LrdGpuDispatch>::zeroed();
    assert_eq!(unsafe { lrd_gpu_dispatch(null(), 100, 70, 0, out.as_mut_ptr()) }, LrdStatus::LRD_STATUS_NULL_POINTER);
    assert_eq!(unsafe { lrd_gpu_dispatch(&cfg, 100, 70, 0, null_mut()) }, LrdStatus::LRD_STATUS_NULL_POINTER);
    assert_eq!(unsafe { lrd_gpu_dispatch(&cfg, 0, 70, 0, out.as_mut_ptr()) }, LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
    assert_eq!(unsafe { lrd_gpu_dispatch(&cfg, 100, 70, 7, out.as_mut_ptr()) }, LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
    let mut f16 = std::mem::MaybeUninit::<LrdGpuDispatch>::zeroed();
    assert_eq!(unsafe { lrd_gpu_dispatch(&cfg, 100, 70, 1, f16.as_mut_ptr()) }, LrdStatus::LRD_STATUS_OK);
    let f16 = unsafe { f16.assume_init() };
    assert_eq!(f16.buffer_bytes[1] * 2, d.buffer_bytes[1], "f16 noisy buffer is half the f32 one");
    // upsampling: noisy at half resolution, the low-resolution guides after the full ones
    let mut up = cfg;
    up.upsample = 2;
    assert_eq!(unsafe { lrd_gpu_dispatch(&up, 100, 70, 0, out.as_mut_ptr()) }, LrdStatus::LRD_STATUS_OK);
    let up = unsafe { out.assume_init() };
    assert_eq!(up.buffer_bytes[1], 50 * 35 * 3 * 4);
    assert_eq!(up.buffer_bytes[2], 5 * (100 * 70 + 50 * 35) * 4);
    // the default is the adaptive window: 15 passes (σ 6/12/20 at B = 8 pools
    // windows 1 and 2); one Gaussian window: 7, and smaller tmp and models
    assert_eq!((cfg.blur, cfg.sigmas), (LrdBlur::LRD_BLUR_ADAPTIVE as u32, [6.0, 12.0, 20.0]));
    assert_eq!(d.pass_count, 15);
    let names: Vec<&str> = d.passes.iter().map(|p| unsafe { CStr::from_ptr(p.entry) }.to_str().unwrap()).collect();
    assert_eq!(names[2], "pool");
    assert_eq!(names[13..], ["blend", "apply"]);
    let mut single = cfg;
    single.blur = LrdBlur::LRD_BLUR_GAUSSIAN as u32;
    let mut out = std::mem::MaybeUninit::<LrdGpuDispatch>::zeroed();
    assert_eq!(unsafe { lrd_gpu_dispatch(&single, 100, 70, 0, out.as_mut_ptr()) }, LrdStatus::LRD_STATUS_OK);
    let single = unsafe { out.assume_init() };
    assert_eq!(single.pass_count, 7);
    assert!(d.buffer_bytes[5] > single.buffer_bytes[5] && d.buffer_bytes[6] > single.buffer_bytes[6], "adaptive needs more tmp and models");
    let mut out = std::mem::MaybeUninit::<LrdGpuDispatch>::zeroed();
    let mut many = cfg;
    many.guides = LRD_GUIDE_NORMAL | LRD_GUIDE_DEPTH | LRD_GUIDE_POSITION | LRD_GUIDE_AO;
    many.user_guides = 2;
    assert_eq!(unsafe { lrd_gpu_dispatch(&many, 100, 70, 0, out.as_mut_ptr()) }, LrdStatus::LRD_STATUS_INVALID_CONFIG);
}

/// Temporal FLR through the C ABI gives exactly the Rust API's output over
/// three frames (history advanced by the call), with the same counts, and
/// refuses a short history, a NULL or invalid temporal config and upsampling.
#[test]
fn flr_temporal_matches_the_rust_api() {
    use lrdenoise_core::flr::temporal::TemporalFlr;
    use lrdenoise_core::temporal::{History, TemporalConfig};
    use lrdenoise_core::{FlrConfig, ImageView, ImageViewMut};
    let (w, h) = (67u32, 38u32);
    let (wu, hu, n) = (w as usize, h as usize, (w * h) as usize);
    let planes = GuidePlanes {
        w,
        h,
        normal: (0..3 * n).map(|i| if i % 3 == (i / 3 / 500) % 3 { 1.0 } else { 0.0 }).collect(),
        depth: (0..n).map(|i| 2.0 + (i / wu) as f32 * 0.02).collect(),
        ao: (0..n).map(|i| 0.5 + ((i * 31) % 50) as f32 / 100.0).collect(),
        position: None,
    };
    let motion: Vec<f32> = (0..2 * n).map(|i| if i % 2 == 0 { 0.4 } else { -0.3 }).collect();
    let cfg = lrd_flr_config_default();
    let tc = lrd_temporal_config_default();
    let plan = TemporalFlr::new(FlrConfig::default(), TemporalConfig::default(), wu, hu).unwrap();
    let (mut sb, mut hb) = (0usize, 0usize);
    let mut rhd = vec![0f32; plan.history_len()];
    let mut rh = History::new(&mut rhd);
    let (mut rs, mut rfs) = (vec![0f32; plan.scratch_len()], vec![0f64; plan.flr_scratch_len()]);
    unsafe {
        assert_eq!(lrd_flr_temporal_sizes(&cfg, &tc, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_OK);
        assert_eq!(hb, 4 * plan.history_len());
        let mut ts = vec![0f64; sb / 8];
        let mut hd = vec![0f32; hb / 4];
        let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        let (mut out, mut want) = (vec![0f32; 3 * n], vec![0f32; 3 * n]);
        let o = packed_out(&mut out, w, h);
        let (mut rep, mut rrep) = (LrdReport::default(), lrdenoise_core::Report::default());
        for k in 0..3usize {
            let noisy: Vec<f32> = (0..3 * n).map(|i| (((i + 977 * k) * 7919) % 1000) as f32 / 500.0).collect();
            let frame = planes.c_frame(&noisy, false);
            let mv = img(motion.as_ptr(), w, h, 2);
            let m = if k == 0 { null() } else { &mv as *const LrdImage };
            let sp = ts.as_mut_ptr() as *mut _;
            assert_eq!(lrd_flr_denoise_temporal(&cfg, &tc, &frame, m, &mut hist, &o, sp, sb, &mut rep), LrdStatus::LRD_STATUS_OK);
            let rframe = planes.rust_frame(&noisy);
            let rmv = ImageView::interleaved(&motion, wu, hu, 2).unwrap();
            let mut ov = ImageViewMut::interleaved(&mut want, wu, hu, 3).unwrap();
            rrep += plan.denoise(&rframe, (k > 0).then_some(&rmv), &mut rh, &mut rs, &mut rfs, &mut ov).unwrap();
            assert_eq!(out, want, "frame {k}");
            assert_eq!(hist.frames as usize, k + 1);
            // errors
            let mut short = hist;
            short.bytes -= 4;
            assert_eq!(
                lrd_flr_denoise_temporal(&cfg, &tc, &frame, m, &mut short, &o, sp, sb, null_mut()),
                LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL
            );
            assert_eq!(
                lrd_flr_denoise_temporal(&cfg, null(), &frame, m, &mut hist, &o, sp, sb, null_mut()),
                LrdStatus::LRD_STATUS_NULL_POINTER
            );
            let mut bad = tc;
            bad.output_alpha = 0.0;
            assert_eq!(
                lrd_flr_denoise_temporal(&cfg, &bad, &frame, m, &mut hist, &o, sp, sb, null_mut()),
                LrdStatus::LRD_STATUS_INVALID_CONFIG
            );
            assert_eq!(
                lrd_flr_denoise_temporal(&cfg, &tc, &frame, m, &mut hist, &o, sp, sb - 8, null_mut()),
                LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL
            );
            assert_eq!(hist.frames as usize, k + 1, "a refused call leaves the history as it was");
        }
        assert_eq!(
            (rep.history_rejected, rep.clamped_fireflies, rep.history_resets),
            (rrep.history_rejected, rrep.clamped_fireflies, rrep.history_resets)
        );
        let mut up = cfg;
        up.upsample = 2;
        up.block = 8;
        assert_eq!(lrd_flr_temporal_sizes(&up, &tc, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_UNSUPPORTED);
    }
}

/// Temporal FLR on accumulated moments through the C ABI gives exactly the
/// Rust API's output over three frames, and refuses rejection guides, a
/// configuration without normals and a short history.
#[test]
fn flr_temporal_moments_match_the_rust_api() {
    use lrdenoise_core::flr::moment_history::MomentFlr;
    use lrdenoise_core::temporal::{History, TemporalConfig};
    use lrdenoise_core::{FlrConfig, ImageView, ImageViewMut};
    let (w, h) = (67u32, 38u32);
    let (wu, hu, n) = (w as usize, h as usize, (w * h) as usize);
    let planes = GuidePlanes {
        w,
        h,
        normal: (0..3 * n).map(|i| if i % 3 == (i / 3 / 500) % 3 { 1.0 } else { 0.0 }).collect(),
        depth: (0..n).map(|i| 2.0 + (i / wu) as f32 * 0.02).collect(),
        ao: (0..n).map(|i| 0.5 + ((i * 31) % 50) as f32 / 100.0).collect(),
        position: None,
    };
    let motion: Vec<f32> = (0..2 * n).map(|i| if i % 2 == 0 { 12.0 } else { -0.3 }).collect();
    let cfg = lrd_flr_config_temporal_moments_default();
    let tc = lrd_temporal_config_default();
    let plan = MomentFlr::new(FlrConfig::temporal_moments(), &TemporalConfig::default(), wu, hu).unwrap();
    let (mut sb, mut hb) = (0usize, 0usize);
    let mut rhd = vec![0f32; plan.history_len()];
    let mut rh = History::new(&mut rhd);
    let mut rs = vec![0f64; plan.scratch_len()];
    unsafe {
        assert_eq!(lrd_flr_temporal_moments_sizes(&cfg, &tc, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_OK);
        assert_eq!((hb, sb), (4 * plan.history_len(), 8 * plan.scratch_len()));
        let mut ts = vec![0f64; sb / 8];
        let mut hd = vec![0f32; hb / 4];
        let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        let (mut out, mut want) = (vec![0f32; 3 * n], vec![0f32; 3 * n]);
        let o = packed_out(&mut out, w, h);
        let (mut rep, mut rrep) = (LrdReport::default(), lrdenoise_core::Report::default());
        for k in 0..3usize {
            let noisy: Vec<f32> = (0..3 * n).map(|i| (((i + 977 * k) * 7919) % 1000) as f32 / 500.0).collect();
            let frame = planes.c_frame(&noisy, false);
            let mv = img(motion.as_ptr(), w, h, 2);
            let m = if k == 0 { null() } else { &mv as *const LrdImage };
            let sp = ts.as_mut_ptr() as *mut _;
            let status = lrd_flr_denoise_temporal_moments(&cfg, &tc, &frame, m, &mut hist, &o, sp, sb, &mut rep);
            assert_eq!(status, LrdStatus::LRD_STATUS_OK);
            let rframe = planes.rust_frame(&noisy);
            let rmv = ImageView::interleaved(&motion, wu, hu, 2).unwrap();
            let mut ov = ImageViewMut::interleaved(&mut want, wu, hu, 3).unwrap();
            rrep += plan.denoise(&rframe, (k > 0).then_some(&rmv), &mut rh, &mut rs, &mut ov).unwrap();
            assert_eq!(out, want, "frame {k}");
            assert_eq!(hist.frames as usize, k + 1);
            let mut short = hist;
            short.bytes -= 4;
            assert_eq!(
                lrd_flr_denoise_temporal_moments(&cfg, &tc, &frame, m, &mut short, &o, sp, sb, null_mut()),
                LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL
            );
            assert_eq!(hist.frames as usize, k + 1, "a refused call leaves the history as it was");
        }
        assert_eq!((rep.history_rejected, rep.history_resets), (rrep.history_rejected, rrep.history_resets));
        assert!(rep.history_rejected > 0 && rep.history_resets == 0, "the pan uncovers a border");
        let mut reject = tc;
        reject.rejection_guides = LRD_GUIDE_NORMAL;
        assert_eq!(lrd_flr_temporal_moments_sizes(&cfg, &reject, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        let mut no_normal = cfg;
        no_normal.guides = LRD_GUIDE_DEPTH | LRD_GUIDE_AO;
        assert_eq!(lrd_flr_temporal_moments_sizes(&no_normal, &tc, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_UNSUPPORTED);
    }
}

/// Temporal FLR with `rejection_guides` (normal + position) gives exactly the
/// Rust API's `with_rejection_guides` output, the history size follows, and
/// the field refuses AO or user bits, a frame without the positions, and
/// BMFR's pipeline.
#[test]
fn flr_temporal_rejection_guides_match_the_rust_api() {
    use lrdenoise_core::flr::temporal::TemporalFlr;
    use lrdenoise_core::temporal::{History, TemporalConfig};
    use lrdenoise_core::{FlrConfig, GuideSet, ImageView, ImageViewMut};
    let (w, h) = (41u32, 23u32);
    let (wu, hu, n) = (w as usize, h as usize, (w * h) as usize);
    let planes = GuidePlanes {
        w,
        h,
        normal: (0..3 * n).map(|i| if i % 3 == 2 { 1.0 } else { 0.0 }).collect(),
        depth: (0..n).map(|i| 2.0 + (i % wu) as f32 * 0.05).collect(),
        ao: (0..n).map(|i| 0.4 + ((i * 13) % 60) as f32 / 100.0).collect(),
        position: Some((0..3 * n).map(|i| [(i / 3 % wu) as f32 * 0.1, (i / 3 / wu) as f32 * 0.1, 2.0][i % 3]).collect()),
    };
    let motion: Vec<f32> = (0..2 * n).map(|i| if i % 2 == 0 { -0.6 } else { 0.2 }).collect();
    let cfg = lrd_flr_config_default();
    let mut tc = lrd_temporal_config_default();
    assert_eq!(tc.rejection_guides, 0);
    tc.rejection_guides = LRD_GUIDE_NORMAL | LRD_GUIDE_POSITION;
    let reject = GuideSet { normal: true, position: true, ..GuideSet::default() };
    let plan = TemporalFlr::new(FlrConfig::default(), TemporalConfig::default(), wu, hu).unwrap().with_rejection_guides(reject).unwrap();
    let mut rhd = vec![0f32; plan.history_len()];
    let mut rh = History::new(&mut rhd);
    let (mut rs, mut rfs) = (vec![0f32; plan.scratch_len()], vec![0f64; plan.flr_scratch_len()]);
    let (mut sb, mut hb) = (0usize, 0usize);
    unsafe {
        assert_eq!(lrd_flr_temporal_sizes(&cfg, &tc, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_OK);
        assert_eq!(hb, 4 * plan.history_len());
        let mut ts = vec![0f64; sb / 8];
        let mut hd = vec![0f32; hb / 4];
        let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        let (mut out, mut want) = (vec![0f32; 3 * n], vec![0f32; 3 * n]);
        let o = packed_out(&mut out, w, h);
        for k in 0..3usize {
            let noisy: Vec<f32> = (0..3 * n).map(|i| (((i + 613 * k) * 7919) % 1000) as f32 / 400.0).collect();
            let frame = planes.c_frame(&noisy, false);
            let mv = img(motion.as_ptr(), w, h, 2);
            let m = if k == 0 { null() } else { &mv as *const LrdImage };
            let sp = ts.as_mut_ptr() as *mut _;
            // without the positions the frame does not carry the rejection guides
            assert_eq!(
                lrd_flr_denoise_temporal(&cfg, &tc, &frame, m, &mut hist, &o, sp, sb, null_mut()),
                LrdStatus::LRD_STATUS_GUIDE_MISMATCH
            );
            let frame = planes.c_frame(&noisy, true);
            assert_eq!(lrd_flr_denoise_temporal(&cfg, &tc, &frame, m, &mut hist, &o, sp, sb, null_mut()), LrdStatus::LRD_STATUS_OK);
            let rframe = planes.rust_frame(&noisy);
            let rmv = ImageView::interleaved(&motion, wu, hu, 2).unwrap();
            let mut ov = ImageViewMut::interleaved(&mut want, wu, hu, 3).unwrap();
            plan.denoise(&rframe, (k > 0).then_some(&rmv), &mut rh, &mut rs, &mut rfs, &mut ov).unwrap();
            assert_eq!(out, want, "frame {k}");
        }
        for bits in [LRD_GUIDE_AO, LRD_GUIDE_POSITION | 16, 1 << 31] {
            let mut bad = tc;
            bad.rejection_guides = bits;
            assert_eq!(lrd_flr_temporal_sizes(&cfg, &bad, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_INVALID_CONFIG, "{bits}");
        }
        let mut bmfr = lrd_bmfr_config_default();
        bmfr.temporal.rejection_guides = LRD_GUIDE_POSITION;
        assert_eq!(lrd_bmfr_temporal_sizes(&bmfr, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_UNSUPPORTED);
    }
}

/// BMFR through the C ABI gives exactly the Rust API's output, single frame and
/// temporal (history advanced by the call), and validates its arguments.
#[test]
fn bmfr_matches_the_rust_api() {
    use lrdenoise_core::{Bmfr, BmfrConfig, Frame, GuideSet, Guides, History, ImageView, ImageViewMut};
    let (w, h) = (70u32, 45u32);
    let n = (w * h) as usize;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 500.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| if i % 3 == (i / 3 / 300) % 3 { 1.0 } else { 0.0 }).collect();
    let position: Vec<f32> =
        (0..3 * n).map(|i| ((i / 3) % w as usize) as f32 * 0.1 + (i % 3) as f32 + ((i / 3) / w as usize) as f32 * 0.05).collect();
    let motion: Vec<f32> = (0..2 * n).map(|i| if i % 2 == 0 { 0.5 } else { -0.25 }).collect();
    let cfg = lrd_bmfr_config_default();
    assert_eq!(cfg.guides, LRD_GUIDE_NORMAL | LRD_GUIDE_POSITION);
    let mut frame =
        LrdFrame { noisy: img(noisy.as_ptr(), w, h, 3), guides: guides_none(), guides_low: guides_none(), sample_weights: none() };
    frame.guides.normal = img(normal.as_ptr(), w, h, 3);
    frame.guides.position = img(position.as_ptr(), w, h, 3);
    let mv = img(motion.as_ptr(), w, h, 2);

    // the Rust API
    let b = Bmfr::new(BmfrConfig::default(), w as usize, h as usize).unwrap();
    let rguides = Guides {
        normal: Some(ImageView::interleaved(&normal, w as usize, h as usize, 3).unwrap()),
        position: Some(ImageView::interleaved(&position, w as usize, h as usize, 3).unwrap()),
        ..Default::default()
    };
    let rframe = Frame::new(ImageView::interleaved(&noisy, w as usize, h as usize, 3).unwrap(), rguides);
    let rmv = ImageView::interleaved(&motion, w as usize, h as usize, 2).unwrap();
    assert_eq!(b.config().guides, GuideSet { normal: true, position: true, ..GuideSet::NONE });
    let mut want = vec![0f32; 3 * n];
    let mut scratch = vec![0f32; b.temporal_scratch_len()];
    b.denoise(&rframe, 3, &mut scratch, &mut ImageViewMut::interleaved(&mut want, w as usize, h as usize, 3).unwrap()).unwrap();

    let mut out = vec![0f32; 3 * n];
    let o =
        LrdImageMut { data: out.as_mut_ptr() as *mut _, format: 0, width: w, height: h, pixel_stride: 0, row_stride: 0, channel_stride: 0 };
    unsafe {
        let mut bytes = 0usize;
        assert_eq!(lrd_bmfr_scratch_size(&cfg, w, h, &mut bytes), LrdStatus::LRD_STATUS_OK);
        let mut cs = vec![0f64; bytes / 8];
        let sp = cs.as_mut_ptr() as *mut _;
        let mut rep = LrdReport::default();
        assert_eq!(lrd_bmfr_denoise(&cfg, &frame, 3, &o, sp, bytes, &mut rep), LrdStatus::LRD_STATUS_OK);
        assert_eq!(out, want);
        // errors
        assert_eq!(lrd_bmfr_denoise(&cfg, &frame, 3, &o, sp, bytes - 4, null_mut()), LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL);
        assert_eq!(
            lrd_bmfr_denoise(&cfg, &frame, 3, &o, (sp as *mut u8).add(2) as *mut _, bytes, null_mut()),
            LrdStatus::LRD_STATUS_INVALID_ARGUMENT
        );
        assert_eq!(lrd_bmfr_denoise(null(), &frame, 3, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        let mut bad = cfg;
        bad.block = 4;
        assert_eq!(lrd_bmfr_denoise(&bad, &frame, 3, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        bad = cfg;
        bad.temporal.output_alpha = 0.0;
        assert_eq!(lrd_bmfr_scratch_size(&bad, w, h, &mut bytes), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        let mut missing = frame;
        missing.guides.position = none();
        assert_eq!(lrd_bmfr_denoise(&cfg, &missing, 3, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_GUIDE_MISMATCH);
        let mut low = frame;
        low.guides_low = frame.guides;
        assert_eq!(lrd_bmfr_denoise(&cfg, &low, 3, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_UNSUPPORTED);

        // temporal: three frames through both APIs
        let (mut sb, mut hb) = (0usize, 0usize);
        assert_eq!(lrd_bmfr_temporal_sizes(&cfg, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_OK);
        assert_eq!((sb, hb), (8 * b.temporal_scratch_len().div_ceil(2), 4 * b.history_len()));
        let mut ts = vec![0f64; sb / 8];
        let mut hd = vec![0f32; hb / 4];
        let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        let mut rhd = vec![0f32; b.history_len()];
        let mut rh = History::new(&mut rhd);
        let mut rep = LrdReport::default();
        let mut rrep = lrdenoise_core::bmfr::Report::default();
        for k in 0..3 {
            let m = if k == 0 { null() } else { &mv as *const LrdImage };
            assert_eq!(
                lrd_bmfr_denoise_temporal(&cfg, &frame, m, &mut hist, &o, ts.as_mut_ptr() as *mut _, sb, &mut rep),
                LrdStatus::LRD_STATUS_OK
            );
            let rm = if k == 0 { None } else { Some(&rmv) };
            rrep += b
                .denoise_temporal(
                    &rframe,
                    rm,
                    &mut rh,
                    &mut scratch,
                    &mut ImageViewMut::interleaved(&mut want, w as usize, h as usize, 3).unwrap(),
                )
                .unwrap();
            assert_eq!(out, want, "frame {k}");
            assert_eq!(hist.frames, k + 1);
        }
        assert_eq!(
            (rep.history_rejected, rep.dropped_pivots, rep.fallback_pixels),
            (rrep.history_rejected, rrep.dropped_pivots, rrep.fallback_pixels)
        );
        let mut short = hist;
        short.bytes -= 4;
        assert_eq!(
            lrd_bmfr_denoise_temporal(&cfg, &frame, null(), &mut short, &o, ts.as_mut_ptr() as *mut _, sb, null_mut()),
            LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL
        );
        assert_eq!(
            lrd_bmfr_denoise_temporal(&cfg, &frame, null(), null_mut(), &o, ts.as_mut_ptr() as *mut _, sb, null_mut()),
            LrdStatus::LRD_STATUS_NULL_POINTER
        );
        assert_eq!(lrd_features() & LRD_FEATURE_BMFR, LRD_FEATURE_BMFR);
    }
}

/// WALR through the C ABI gives exactly the Rust API's output, single frame and
/// temporal, and validates its arguments.
#[test]
fn walr_matches_the_rust_api() {
    use lrdenoise_core::{Frame, Guides, History, ImageView, ImageViewMut, Walr, WalrConfig};
    let (w, h) = (41u32, 29u32);
    let (wu, hu) = (w as usize, h as usize);
    let n = wu * hu;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 500.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| if i % 3 == (i / 3 / 300) % 3 { 1.0 } else { 0.0 }).collect();
    let depth: Vec<f32> = (0..n).map(|i| 2.0 + (i / wu) as f32 * 0.01).collect();
    let position: Vec<f32> = (0..3 * n).map(|i| ((i / 3) % wu) as f32 * 0.1 + (i % 3) as f32 + ((i / 3) / wu) as f32 * 0.05).collect();
    let motion: Vec<f32> = (0..2 * n).map(|i| if i % 2 == 0 { 0.5 } else { -0.25 }).collect();
    let cfg = lrd_walr_config_default();
    let mut frame =
        LrdFrame { noisy: img(noisy.as_ptr(), w, h, 3), guides: guides_none(), guides_low: guides_none(), sample_weights: none() };
    frame.guides.normal = img(normal.as_ptr(), w, h, 3);
    frame.guides.depth = img(depth.as_ptr(), w, h, 1);
    frame.guides.position = img(position.as_ptr(), w, h, 3);
    let mv = img(motion.as_ptr(), w, h, 2);

    let wl = Walr::new(WalrConfig::default(), wu, hu).unwrap();
    let rguides = Guides {
        normal: Some(ImageView::interleaved(&normal, wu, hu, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, wu, hu, 1).unwrap()),
        position: Some(ImageView::interleaved(&position, wu, hu, 3).unwrap()),
        ..Default::default()
    };
    let rframe = Frame::new(ImageView::interleaved(&noisy, wu, hu, 3).unwrap(), rguides);
    let rmv = ImageView::interleaved(&motion, wu, hu, 2).unwrap();
    let mut want = vec![0f32; 3 * n];
    let mut scratch = vec![0f32; wl.temporal_scratch_len()];
    wl.denoise(&rframe, 2, &mut scratch, &mut ImageViewMut::interleaved(&mut want, wu, hu, 3).unwrap()).unwrap();

    let mut out = vec![0f32; 3 * n];
    let o =
        LrdImageMut { data: out.as_mut_ptr() as *mut _, format: 0, width: w, height: h, pixel_stride: 0, row_stride: 0, channel_stride: 0 };
    unsafe {
        let mut bytes = 0usize;
        assert_eq!(lrd_walr_scratch_size(&cfg, w, h, &mut bytes), LrdStatus::LRD_STATUS_OK);
        let mut cs = vec![0f64; bytes / 8];
        let sp = cs.as_mut_ptr() as *mut _;
        assert_eq!(lrd_walr_denoise(&cfg, &frame, 2, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_OK);
        assert_eq!(out, want);
        assert_eq!(lrd_walr_denoise(&cfg, &frame, 2, &o, sp, bytes - 4, null_mut()), LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL);
        let mut bad = cfg;
        bad.iterations = 300;
        assert_eq!(lrd_walr_scratch_size(&bad, w, h, &mut bytes), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        bad = cfg;
        bad.iterations = 0;
        assert_eq!(lrd_walr_scratch_size(&bad, w, h, &mut bytes), LrdStatus::LRD_STATUS_INVALID_CONFIG);
        let mut missing = frame;
        missing.guides.position = none();
        assert_eq!(lrd_walr_denoise(&cfg, &missing, 2, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_GUIDE_MISMATCH);

        let (mut sb, mut hb) = (0usize, 0usize);
        assert_eq!(lrd_walr_temporal_sizes(&cfg, w, h, &mut sb, &mut hb), LrdStatus::LRD_STATUS_OK);
        assert_eq!((sb, hb), (8 * wl.temporal_scratch_len().div_ceil(2), 4 * wl.history_len()));
        let mut ts = vec![0f64; sb / 8];
        let mut hd = vec![0f32; hb / 4];
        let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        let mut rhd = vec![0f32; wl.history_len()];
        let mut rh = History::new(&mut rhd);
        let (mut rep, mut rrep) = (LrdReport::default(), lrdenoise_core::walr::Report::default());
        for k in 0..3 {
            let m = if k == 0 { null() } else { &mv as *const LrdImage };
            assert_eq!(
                lrd_walr_denoise_temporal(&cfg, &frame, m, &mut hist, &o, ts.as_mut_ptr() as *mut _, sb, &mut rep),
                LrdStatus::LRD_STATUS_OK
            );
            let rm = if k == 0 { None } else { Some(&rmv) };
            let r = wl
                .denoise_temporal(&rframe, rm, &mut rh, &mut scratch, &mut ImageViewMut::interleaved(&mut want, wu, hu, 3).unwrap())
                .unwrap();
            rrep.history_rejected += r.history_rejected;
            rrep.fallback_pixels += r.fallback_pixels;
            assert_eq!(out, want, "frame {k}");
            assert_eq!(hist.frames, k + 1);
        }
        assert_eq!((rep.history_rejected, rep.fallback_pixels), (rrep.history_rejected, rrep.fallback_pixels));
        assert_eq!(lrd_features() & LRD_FEATURE_WALR, LRD_FEATURE_WALR);
    }
}

/// LRD_BLUR_ADAPTIVE runs through lrd_flr_denoise (same output as the Rust
/// API) and through the tiled stages (BLEND included; tiles in reverse order
/// on two alternating workers), bit-identical, with and without pooled
/// windows, and with an AO guide with and without `adaptive_without_ao`.
#[test]
fn adaptive_window_whole_frame_and_tiled() {
    // σ 6/12/20 px at B = 8: windows 1 and 2 on the pooled grid; 3/6/10: none pooled
    for (w, h, sigmas) in [(101u32, 75u32, [6.0, 12.0, 20.0]), (45, 33, [3.0, 6.0, 10.0])] {
        for (ao, without_ao) in [(false, false), (true, false), (true, true)] {
            adaptive_case(w, h, sigmas, ao, without_ao);
        }
    }
}

fn adaptive_case(w: u32, h: u32, sigmas: [f32; 3], ao: bool, without_ao: bool) {
    use lrdenoise_core::{Blur, Flr, FlrConfig, Frame, GuideSet, Guides, ImageView, ImageViewMut};
    let n = (w * h) as usize;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 13) as f32 * 0.1).collect();
    let depth = depth_ramp(w, h);
    // an AO guide that varies across the rows, where the depth varies down them
    let occlusion: Vec<f32> = (0..n).map(|i| 0.5 + 0.4 * ((i % w as usize) as f32 * 0.3).sin()).collect();
    let mut cfg = lrd_flr_config_default();
    cfg.guides = if ao { LRD_GUIDE_DEPTH | LRD_GUIDE_AO } else { LRD_GUIDE_DEPTH };
    cfg.blur = LrdBlur::LRD_BLUR_ADAPTIVE as u32;
    cfg.sigmas = sigmas;
    cfg.adaptive_without_ao = without_ao;
    let mut frame = depth_frame(&noisy, &depth, w, h);
    if ao {
        frame.guides.ao = img(occlusion.as_ptr(), w, h, 1);
    }
    let mut out = vec![0f32; 3 * n];
    let o = packed_out(&mut out, w, h);
    let (mut scratch, bytes) = flr_scratch(&cfg, w, h);
    let mut tiled = vec![0f32; 3 * n];
    let ot = packed_out(&mut tiled, w, h);
    let mut tb = 0;
    assert_eq!(unsafe { lrd_flr_tiled_scratch_size(&cfg, w, h, 2, &mut tb) }, LrdStatus::LRD_STATUS_OK);
    assert!(tb > bytes, "the tiled run keeps every window's grids");
    let mut tscratch = vec![0f64; tb / 8];
    let mut nt = 0u32;
    assert_eq!(unsafe { lrd_flr_tile_count(&cfg, w, h, &mut nt) }, LrdStatus::LRD_STATUS_OK);
    assert!(nt >= 2, "several tiles");
    unsafe {
        let sp = scratch.as_mut_ptr() as *mut _;
        assert_eq!(lrd_flr_denoise(&cfg, &frame, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_OK);
        let tp = tscratch.as_mut_ptr() as *mut _;
        assert_eq!(lrd_flr_run_tile(&cfg, &frame, &ot, tp, tb - 8, 2, 0, 0, 0, null_mut()), LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL);
        let (mut r_whole, mut r_tiled) = (LrdReport::default(), LrdReport::default());
        assert_eq!(lrd_flr_denoise(&cfg, &frame, &o, sp, bytes, &mut r_whole), LrdStatus::LRD_STATUS_OK);
        for stage in 0u32..7 {
            let tiles = if stage == 0 || stage == 2 { 1 } else { nt };
            for t in (0..tiles).rev() {
                let st = lrd_flr_run_tile(&cfg, &frame, &ot, tp, tb, 2, stage, t, t % 2, &mut r_tiled);
                assert_eq!(st, LrdStatus::LRD_STATUS_OK, "stage {stage} tile {t}");
            }
        }
        assert_eq!(format!("{r_whole:?}"), format!("{r_tiled:?}"));
        cfg.sigmas = [sigmas[1], sigmas[0], sigmas[2]];
        assert_eq!(lrd_flr_denoise(&cfg, &frame, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_INVALID_CONFIG);
    }
    assert!(out.iter().zip(&tiled).all(|(a, b)| a.to_bits() == b.to_bits()), "{w}x{h} tiled != whole");
    let set = GuideSet { depth: true, ao, ..GuideSet::NONE };
    let c = FlrConfig { blur: Blur::Adaptive { sigmas }, adaptive_without_ao: without_ao, ..FlrConfig::with_guides(set) };
    let flr = Flr::new(c, w as usize, h as usize).unwrap();
    let view = |v| Some(ImageView::interleaved(v, w as usize, h as usize, 1).unwrap());
    let guides = Guides { depth: view(&depth[..]), ao: if ao { view(&occlusion[..]) } else { None }, ..Guides::default() };
    let f = Frame::new(ImageView::interleaved(&noisy, w as usize, h as usize, 3).unwrap(), guides);
    let mut want = vec![0f32; 3 * n];
    let mut scratch = vec![0f64; flr.scratch_len()];
    flr.denoise(&f, &mut scratch, &mut ImageViewMut::interleaved(&mut want, w as usize, h as usize, 3).unwrap()).unwrap();
    assert_eq!(out, want);
}

/// `lrd_flnr_denoise` and the threaded stages (`lrd_flnr_run_tile`, tiles
/// run in reverse order on two alternating workers, and concurrently on
/// threads) equal `Flnr::denoise` bit for bit; bad blobs, sizes, stages
/// and orders give their statuses.
#[test]
fn flnr_matches_the_rust_api() {
    use lrdenoise_core::flnr::Flnr;
    let blob = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../train/flnr.bin")).expect("train/flnr.bin");
    // 150×97 in 64 px tiles: 3×2 tiles, the last ones partial
    let (w, h, tile) = (150u32, 97u32, 64u32);
    let n = (w * h) as usize;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 400.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| if i % 3 == (i / 3 / 40) % 3 { 1.0 } else { 0.0 }).collect();
    let depth: Vec<f32> = (0..n).map(|i| 2.0 + (i % w as usize) as f32 * 0.01 + (i / 997) as f32).collect();
    let ao: Vec<f32> = (0..n).map(|i| ((i / w as usize) % 13) as f32 / 13.0).collect();
    let mut frame = depth_frame(&noisy, &depth, w, h);
    frame.guides.normal = img(normal.as_ptr(), w, h, 3);
    frame.guides.ao = img(ao.as_ptr(), w, h, 1);

    // the Rust API
    let fl =
        Flnr::new(lrdenoise_core::FlnrConfig { tile: tile as usize, ..lrdenoise_core::FlnrConfig::new(&blob) }, w as usize, h as usize)
            .unwrap();
    let guides = lrdenoise_core::Guides {
        normal: Some(lrdenoise_core::ImageView::interleaved(&normal, w as usize, h as usize, 3).unwrap()),
        depth: Some(lrdenoise_core::ImageView::interleaved(&depth, w as usize, h as usize, 1).unwrap()),
        ao: Some(lrdenoise_core::ImageView::interleaved(&ao, w as usize, h as usize, 1).unwrap()),
        ..Default::default()
    };
    let rf = lrdenoise_core::Frame::new(lrdenoise_core::ImageView::interleaved(&noisy, w as usize, h as usize, 3).unwrap(), guides);
    let mut want = vec![0f32; 3 * n];
    let (mut s32, mut s64) = (vec![0f32; fl.scratch_len()], vec![0f64; fl.flr_scratch_len()]);
    let mut wv = lrdenoise_core::ImageViewMut::interleaved(&mut want, w as usize, h as usize, 3).unwrap();
    fl.denoise(&rf, &mut s32, &mut s64, &mut wv).unwrap();
    assert!(want.iter().all(|v| v.is_finite()));

    let cfg = LrdFlnrConfig { tile, ..lrd_flnr_config_default(blob.as_ptr(), blob.len()) };
    unsafe {
        // whole frame
        let mut bytes = 0usize;
        assert_eq!(lrd_flnr_scratch_size(&cfg, w, h, &mut bytes), LrdStatus::LRD_STATUS_OK);
        let mut scratch = vec![0f64; bytes / 8 + 1];
        let sp = scratch.as_mut_ptr() as *mut _;
        let mut out = vec![0f32; 3 * n];
        let o = packed_out(&mut out, w, h);
        let mut rep = LrdReport::default();
        assert_eq!(lrd_flnr_denoise(&cfg, &frame, &o, sp, bytes, &mut rep), LrdStatus::LRD_STATUS_OK);
        assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "C whole frame != Rust");
        assert_eq!(lrd_features() & LRD_FEATURE_FLNR, LRD_FEATURE_FLNR);
        // the firefly clamp of the FLR fit: off, or another k, as in Rust
        let bright: Vec<f32> = noisy.iter().enumerate().map(|(i, v)| if i % 997 == 0 { v * 1e4 } else { *v }).collect();
        let mut bf = frame;
        bf.noisy = img(bright.as_ptr(), w, h, 3);
        let rb = lrdenoise_core::Frame::new(lrdenoise_core::ImageView::interleaved(&bright, w as usize, h as usize, 3).unwrap(), rf.guides);
        for k in [0.0f32, 3.0] {
            let rc = lrdenoise_core::FlnrConfig {
                tile: tile as usize,
                fireflies: (k != 0.0).then_some(k),
                ..lrdenoise_core::FlnrConfig::new(&blob)
            };
            let rfl = Flnr::new(rc, w as usize, h as usize).unwrap();
            let mut rwant = vec![0f32; 3 * n];
            let mut rv = lrdenoise_core::ImageViewMut::interleaved(&mut rwant, w as usize, h as usize, 3).unwrap();
            let rrep = rfl.denoise(&rb, &mut s32, &mut s64, &mut rv).unwrap();
            let mut crep = LrdReport::default();
            let kc = LrdFlnrConfig { fireflies: k, ..cfg };
            assert_eq!(lrd_flnr_denoise(&kc, &bf, &o, sp, bytes, &mut crep), LrdStatus::LRD_STATUS_OK);
            assert!(out.iter().zip(&rwant).all(|(a, b)| a.to_bits() == b.to_bits()), "C fireflies {k} != Rust");
            assert_eq!(crep.clamped_fireflies, rrep.clamped_fireflies, "k {k}");
            assert_eq!(crep.clamped_fireflies == 0, k == 0.0, "k {k}: {}", crep.clamped_fireflies);
        }
        for k in [0.5f32, -1.0, f32::NAN, f32::INFINITY] {
            let kc = LrdFlnrConfig { fireflies: k, ..cfg };
            assert_eq!(lrd_flnr_denoise(&kc, &frame, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_INVALID_CONFIG, "k {k}");
        }
        assert_eq!(lrd_flnr_denoise(null(), &frame, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        let d = lrd_flnr_config_default(blob.as_ptr(), blob.len());
        assert_eq!((d.tile, d.fireflies), (512, 1.5));

        // errors
        assert_eq!(lrd_flnr_denoise(&cfg, &frame, &o, sp, bytes - 1, null_mut()), LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL);
        assert_eq!(
            lrd_flnr_denoise(&LrdFlnrConfig { weights: null(), ..cfg }, &frame, &o, sp, bytes, null_mut()),
            LrdStatus::LRD_STATUS_NULL_POINTER
        );
        assert_eq!(
            lrd_flnr_denoise(&LrdFlnrConfig { weights_bytes: cfg.weights_bytes - 1, ..cfg }, &frame, &o, sp, bytes, null_mut()),
            LrdStatus::LRD_STATUS_INVALID_CONFIG
        );
        assert_eq!(
            lrd_flnr_denoise(&LrdFlnrConfig { tile: 8, ..cfg }, &frame, &o, sp, bytes, null_mut()),
            LrdStatus::LRD_STATUS_INVALID_CONFIG
        );
        let mut bad = blob.clone();
        bad[0] ^= 1;
        assert_eq!(
            lrd_flnr_scratch_size(&LrdFlnrConfig { weights: bad.as_ptr(), ..cfg }, w, h, &mut bytes),
            LrdStatus::LRD_STATUS_INVALID_CONFIG
        );
        assert_eq!(lrd_flnr_scratch_size(&cfg, w, h, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        let mut nf = frame;
        nf.guides.ao = none();
        assert_eq!(lrd_flnr_denoise(&cfg, &nf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_GUIDE_MISMATCH);
        nf = frame;
        nf.guides_low.depth = img(depth.as_ptr(), w, h, 1);
        assert_eq!(lrd_flnr_denoise(&cfg, &nf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_UNSUPPORTED);
        nf = frame;
        nf.guides.depth.width = w - 1;
        assert_eq!(lrd_flnr_denoise(&cfg, &nf, &o, sp, bytes, null_mut()), LrdStatus::LRD_STATUS_SIZE_MISMATCH);

        // threaded stages, two workers, tiles in reverse order
        let mut count = 0u32;
        assert_eq!(lrd_flnr_tile_count(&cfg, w, h, &mut count), LrdStatus::LRD_STATUS_OK);
        assert_eq!(count, 6);
        let mut tb = 0usize;
        assert_eq!(lrd_flnr_tiled_scratch_size(&cfg, w, h, 0, &mut tb), LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
        assert_eq!(lrd_flnr_tiled_scratch_size(&cfg, w, h, 2, &mut tb), LrdStatus::LRD_STATUS_OK);
        let mut tiled = vec![0f64; tb / 8 + 1];
        let tp = tiled.as_mut_ptr() as *mut _;
        const PREPARE: u32 = LrdFlnrStage::LRD_FLNR_STAGE_PREPARE as u32;
        const NETWORK: u32 = LrdFlnrStage::LRD_FLNR_STAGE_NETWORK as u32;
        const FLR: u32 = LrdFlnrStage::LRD_FLNR_STAGE_FLR as u32;
        // a network tile before PREPARE (fresh scratch), and bad stage / tile / worker
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, NETWORK, 0, 0, null_mut()), LrdStatus::LRD_STATUS_STAGE_ORDER);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb - 1, 2, PREPARE, 0, 0, null_mut()), LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, 9, 0, 0, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 0, PREPARE, 0, 0, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, PREPARE, 1, 0, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        out.fill(0.0);
        let o = packed_out(&mut out, w, h);
        // the worker index is checked in every stage
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, PREPARE, 0, 2, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, FLR, 0, 7, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, PREPARE, 0, 0, null_mut()), LrdStatus::LRD_STATUS_OK);
        // FLR before every network tile has run
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, FLR, 0, 0, null_mut()), LrdStatus::LRD_STATUS_STAGE_ORDER);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, NETWORK, 0, 0, null_mut()), LrdStatus::LRD_STATUS_OK);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, FLR, 0, 0, null_mut()), LrdStatus::LRD_STATUS_STAGE_ORDER);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, PREPARE, 0, 0, null_mut()), LrdStatus::LRD_STATUS_OK);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, NETWORK, count, 0, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, NETWORK, 0, 2, null_mut()), LrdStatus::LRD_STATUS_INVALID_TILE);
        for t in (0..count).rev() {
            assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, NETWORK, t, t % 2, null_mut()), LrdStatus::LRD_STATUS_OK);
        }
        let mut trep = LrdReport::default();
        assert_eq!(lrd_flnr_run_tile(&cfg, &frame, &o, tp, tb, 2, FLR, 0, 0, &mut trep), LrdStatus::LRD_STATUS_OK);
        assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "C tiled != Rust");
        assert_eq!((trep.nonfinite_noisy, trep.fallback_pixels), (rep.nonfinite_noisy, rep.fallback_pixels));

        // the network stage on three threads at once, each with its own worker
        assert_eq!(lrd_flnr_tiled_scratch_size(&cfg, w, h, 3, &mut tb), LrdStatus::LRD_STATUS_OK);
        let mut tiled = vec![0f64; tb / 8 + 1];
        out.fill(0.0);
        let o = packed_out(&mut out, w, h);
        /// The call's pointers, shared with the threads (the C API's rules make it safe).
        #[derive(Clone, Copy)]
        struct Shared(*const LrdFlnrConfig, *const LrdFrame, *const LrdImageMut, *mut core::ffi::c_void, usize);
        // SAFETY: the pointees outlive the scope and the threads write only disjoint tiles (lrd_flnr_run_tile's rules).
        unsafe impl Send for Shared {}
        unsafe impl Sync for Shared {}
        let sh = Shared(&cfg, &frame, &o, tiled.as_mut_ptr() as *mut _, tb);
        let run = |stage: u32, t: u32, worker: u32| lrd_flnr_run_tile(sh.0, sh.1, sh.2, sh.3, sh.4, 3, stage, t, worker, null_mut());
        assert_eq!(run(PREPARE, 0, 0), LrdStatus::LRD_STATUS_OK);
        std::thread::scope(|s| {
            for worker in 0..3u32 {
                s.spawn(move || {
                    let sh = sh;
                    for t in (worker..count).step_by(3) {
                        let st = lrd_flnr_run_tile(sh.0, sh.1, sh.2, sh.3, sh.4, 3, NETWORK, t, worker, null_mut());
                        assert_eq!(st, LrdStatus::LRD_STATUS_OK);
                    }
                });
            }
        });
        assert_eq!(run(FLR, 0, 0), LrdStatus::LRD_STATUS_OK);
        assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "C on threads != Rust");
    }
}
