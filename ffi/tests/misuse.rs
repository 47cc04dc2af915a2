//! The C API refuses misuse with a status, never with wrong output: tiled
//! stages out of order, skipped, repeated or with other arguments; outputs
//! that overlap an input, the scratch, the history or themselves.

use lrdenoise::*;
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
fn out_view(data: *mut f32, w: u32, h: u32) -> LrdImageMut {
    LrdImageMut { data: data as *mut _, format: 0, width: w, height: h, pixel_stride: 0, row_stride: 0, channel_stride: 0 }
}

const OK: LrdStatus = LrdStatus::LRD_STATUS_OK;
const ORDER: LrdStatus = LrdStatus::LRD_STATUS_STAGE_ORDER;
const INVALID: LrdStatus = LrdStatus::LRD_STATUS_INVALID_ARGUMENT;

/// A 61×43 frame (noise, depth and AO guides) and the default adaptive
/// config with depth + AO.
struct Case {
    w: u32,
    h: u32,
    noisy: Vec<f32>,
    depth: Vec<f32>,
    ao: Vec<f32>,
    cfg: LrdFlrConfig,
}

impl Case {
    fn new() -> Case {
        let (w, h) = (61u32, 43u32);
        let n = (w * h) as usize;
        let noisy = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 400.0).collect();
        let depth = (0..n).map(|i| 1.0 + (i / w as usize) as f32 * 0.1 + (i % 5) as f32 * 0.01).collect();
        let ao = (0..n).map(|i| 0.3 + 0.7 * ((i % 13) as f32 / 13.0)).collect();
        let mut cfg = lrd_flr_config_default();
        cfg.guides = LRD_GUIDE_DEPTH | LRD_GUIDE_AO;
        Case { w, h, noisy, depth, ao, cfg }
    }
    fn frame(&self) -> LrdFrame {
        let mut f = LrdFrame {
            noisy: img(self.noisy.as_ptr(), self.w, self.h, 3),
            guides: guides_none(),
            guides_low: guides_none(),
            sample_weights: none(),
        };
        f.guides.depth = img(self.depth.as_ptr(), self.w, self.h, 1);
        f.guides.ao = img(self.ao.as_ptr(), self.w, self.h, 1);
        f
    }
    fn tiles(&self) -> u32 {
        let mut nt = 0;
        assert_eq!(unsafe { lrd_flr_tile_count(&self.cfg, self.w, self.h, &mut nt) }, OK);
        nt
    }
    fn tiled_scratch(&self, workers: u32) -> (Vec<f64>, usize) {
        let mut b = 0;
        assert_eq!(unsafe { lrd_flr_tiled_scratch_size(&self.cfg, self.w, self.h, workers, &mut b) }, OK);
        (vec![0f64; b / 8], b)
    }
    fn whole(&self) -> Vec<f32> {
        let mut b = 0;
        assert_eq!(unsafe { lrd_flr_scratch_size(&self.cfg, self.w, self.h, &mut b) }, OK);
        let mut s = vec![0f64; b / 8];
        let mut out = vec![0f32; 3 * (self.w * self.h) as usize];
        let o = out_view(out.as_mut_ptr(), self.w, self.h);
        assert_eq!(unsafe { lrd_flr_denoise(&self.cfg, &self.frame(), &o, s.as_mut_ptr() as *mut _, b, null_mut()) }, OK);
        out
    }
}

#[test]
fn stage_tile_counts_follow_the_stage_numbers() {
    let c = Case::new();
    let nt = c.tiles();
    assert!(nt >= 2);
    for stage in 0..7u32 {
        let mut n = 0;
        assert_eq!(unsafe { lrd_flr_stage_tile_count(&c.cfg, c.w, c.h, stage, &mut n) }, OK);
        assert_eq!(n, if stage == 0 || stage == 2 { 1 } else { nt }, "stage {stage}");
    }
    let mut n = 0;
    assert_eq!(unsafe { lrd_flr_stage_tile_count(&c.cfg, c.w, c.h, 7, &mut n) }, LrdStatus::LRD_STATUS_INVALID_TILE);
    assert_eq!(LrdStage::LRD_STAGE_BLEND as u32 + 1, LrdStage::LRD_STAGE_APPLY as u32);
}

#[test]
fn tiled_stages_out_of_order_are_refused() {
    let c = Case::new();
    let frame = c.frame();
    let nt = c.tiles();
    let want = c.whole();
    let mut out = vec![0f32; want.len()];
    let o = out_view(out.as_mut_ptr(), c.w, c.h);
    let (mut scratch, tb) = c.tiled_scratch(2);
    let sp = scratch.as_mut_ptr() as *mut _;
    let run = |o: &LrdImageMut, stage: u32, t: u32, worker: u32| unsafe {
        lrd_flr_run_tile(&c.cfg, &frame, o, sp, tb, 2, stage, t, worker, null_mut())
    };
    let stage_all = |o: &LrdImageMut, stage: u32| {
        let tiles = if stage == 0 || stage == 2 { 1 } else { nt };
        (0..tiles).map(|t| run(o, stage, t, t % 2)).find(|&s| s != OK).unwrap_or(OK)
    };
    // apply on a scratch that never saw PREPARE, and right after PREPARE
    assert_eq!(run(&o, 6, 0, 0), ORDER);
    assert_eq!(run(&o, 1, 0, 0), ORDER);
    assert_eq!(run(&o, 0, 0, 0), OK);
    assert_eq!(run(&o, 6, 0, 0), ORDER);
    assert_eq!(run(&o, 2, 0, 0), ORDER, "STATS before every MOMENTS tile");
    // one MOMENTS tile twice, and STATS with one tile missing
    assert_eq!(run(&o, 1, 0, 0), OK);
    assert_eq!(run(&o, 1, 0, 1), ORDER, "a tile twice");
    for t in 1..nt - 1 {
        assert_eq!(run(&o, 1, t, 0), OK);
    }
    assert_eq!(run(&o, 2, 0, 0), ORDER, "STATS with a MOMENTS tile missing");
    assert_eq!(run(&o, 1, nt - 1, 1), OK);
    // the rest in numeric order, skipping BLEND: APPLY refuses
    for stage in 2..5 {
        assert_eq!(stage_all(&o, stage), OK, "stage {stage}");
    }
    assert_eq!(run(&o, 6, 0, 0), ORDER, "APPLY without BLEND");
    assert!(out.iter().all(|&v| v == 0.0), "a refused call wrote nothing");
    // another output than PREPARE's is refused
    let mut other = vec![0f32; want.len()];
    let o2 = out_view(other.as_mut_ptr(), c.w, c.h);
    assert_eq!(run(&o2, 5, 0, 0), ORDER, "arguments differ from PREPARE's");
    assert_eq!(stage_all(&o, 5), OK);
    assert_eq!(stage_all(&o, 6), OK);
    assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "tiled != whole frame");
    // the frame is done: APPLY again is refused until the next PREPARE
    assert_eq!(run(&o, 6, 0, 0), ORDER);
    out.fill(0.0);
    for stage in 0..7 {
        assert_eq!(stage_all(&o, stage), OK, "second frame, stage {stage}");
    }
    assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "second frame");
}

#[test]
fn scratch_of_a_different_worker_count_is_refused() {
    let c = Case::new();
    let frame = c.frame();
    let mut out = vec![0f32; 3 * (c.w * c.h) as usize];
    let o = out_view(out.as_mut_ptr(), c.w, c.h);
    let (mut scratch, tb) = c.tiled_scratch(3);
    let sp = scratch.as_mut_ptr() as *mut _;
    unsafe {
        assert_eq!(lrd_flr_run_tile(&c.cfg, &frame, &o, sp, tb, 3, 0, 0, 0, null_mut()), OK);
        assert_eq!(lrd_flr_run_tile(&c.cfg, &frame, &o, sp, tb, 2, 1, 0, 0, null_mut()), ORDER);
        let mut sigma = c.cfg;
        sigma.sigmas = [5.0, 12.0, 20.0];
        assert_eq!(lrd_flr_run_tile(&sigma, &frame, &o, sp, tb, 3, 1, 0, 0, null_mut()), ORDER, "another config");
        assert_eq!(lrd_flr_run_tile(&c.cfg, &frame, &o, sp, tb, 3, 1, 0, 0, null_mut()), OK);
    }
}

#[test]
fn outputs_that_overlap_are_refused() {
    let c = Case::new();
    let n = (c.w * c.h) as usize;
    let mut b = 0;
    assert_eq!(unsafe { lrd_flr_scratch_size(&c.cfg, c.w, c.h, &mut b) }, OK);
    let mut scratch = vec![0f64; b / 8 + 2 * n];
    let sp = scratch.as_mut_ptr() as *mut _;
    let mut noisy = c.noisy.clone();
    let mut depth = c.depth.clone();
    let mut frame = c.frame();
    frame.noisy.data = noisy.as_ptr() as *const _;
    frame.guides.depth.data = depth.as_ptr() as *const _;
    unsafe {
        // output over the noisy input, over a guide, over the scratch
        let on_noisy = out_view(noisy.as_mut_ptr(), c.w, c.h);
        assert_eq!(lrd_flr_denoise(&c.cfg, &frame, &on_noisy, sp, b, null_mut()), INVALID);
        let on_depth = out_view(depth.as_mut_ptr(), 1, 1);
        let mut one = c.cfg;
        one.block = 1;
        let mut small = frame;
        small.noisy.width = 1;
        small.noisy.height = 1;
        small.guides.depth.width = 1;
        small.guides.depth.height = 1;
        small.guides.ao.width = 1;
        small.guides.ao.height = 1;
        assert_eq!(lrd_flr_denoise(&one, &small, &on_depth, sp, b, null_mut()), INVALID);
        let on_scratch = out_view((scratch.as_mut_ptr() as *mut f32).add(8), c.w, c.h);
        assert_eq!(lrd_flr_denoise(&c.cfg, &frame, &on_scratch, sp, b, null_mut()), INVALID);
        // the scratch right after the output is fine
        let mut out = vec![0f32; 3 * n];
        let o = out_view(out.as_mut_ptr(), c.w, c.h);
        assert_eq!(lrd_flr_denoise(&c.cfg, &frame, &o, sp, b, null_mut()), OK);
        // pixels that share memory (pixel stride one float), rows that overlap
        let mut px = o;
        px.pixel_stride = 4;
        px.channel_stride = 4;
        assert_eq!(lrd_flr_denoise(&c.cfg, &frame, &px, sp, b, null_mut()), INVALID);
        let mut rows = o;
        rows.row_stride = 12 * (c.w as usize - 1);
        assert_eq!(lrd_flr_denoise(&c.cfg, &frame, &rows, sp, b, null_mut()), INVALID);
        // the tiled call checks the same
        let mut tb = 0;
        assert_eq!(lrd_flr_tiled_scratch_size(&c.cfg, c.w, c.h, 1, &mut tb), OK);
        let mut ts = vec![0f64; tb / 8];
        let tp = ts.as_mut_ptr() as *mut _;
        assert_eq!(lrd_flr_run_tile(&c.cfg, &frame, &on_noisy, tp, tb, 1, 0, 0, 0, null_mut()), INVALID);
        assert_eq!(lrd_flr_run_tile(&c.cfg, &frame, &rows, tp, tb, 1, 0, 0, 0, null_mut()), INVALID);
        let on_tiled = out_view((ts.as_mut_ptr() as *mut f32).add(2), c.w, c.h);
        assert_eq!(lrd_flr_run_tile(&c.cfg, &frame, &on_tiled, tp, tb, 1, 0, 0, 0, null_mut()), INVALID);
    }
}

#[cfg(feature = "bmfr")]
#[test]
fn temporal_outputs_that_overlap_are_refused() {
    let (w, h) = (40u32, 33u32);
    let n = (w * h) as usize;
    let mut noisy: Vec<f32> = (0..3 * n).map(|i| (i % 11) as f32 * 0.1).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| if i % 3 == 2 { 1.0 } else { 0.0 }).collect();
    let position: Vec<f32> = (0..3 * n).map(|i| (i % 97) as f32 * 0.01).collect();
    let cfg = lrd_bmfr_config_default();
    let mut frame =
        LrdFrame { noisy: img(noisy.as_ptr(), w, h, 3), guides: guides_none(), guides_low: guides_none(), sample_weights: none() };
    frame.guides.normal = img(normal.as_ptr(), w, h, 3);
    frame.guides.position = img(position.as_ptr(), w, h, 3);
    let (mut sb, mut hb) = (0, 0);
    unsafe {
        assert_eq!(lrd_bmfr_temporal_sizes(&cfg, w, h, &mut sb, &mut hb), OK);
        let mut scratch = vec![0f64; sb / 8];
        let mut history = vec![0f32; hb / 4];
        let sp = scratch.as_mut_ptr() as *mut _;
        let mut out = vec![0f32; 3 * n];
        let o = out_view(out.as_mut_ptr(), w, h);
        let mut hist = LrdHistory { data: history.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        assert_eq!(lrd_bmfr_denoise_temporal(&cfg, &frame, null(), &mut hist, &o, sp, sb, null_mut()), OK);
        let on_history = out_view(history.as_mut_ptr(), w, h);
        assert_eq!(lrd_bmfr_denoise_temporal(&cfg, &frame, null(), &mut hist, &on_history, sp, sb, null_mut()), INVALID);
        let on_noisy = out_view(noisy.as_mut_ptr(), w, h);
        assert_eq!(lrd_bmfr_denoise(&cfg, &frame, 0, &on_noisy, sp, sb, null_mut()), INVALID);
        let mut hist_on_scratch = LrdHistory { data: scratch.as_mut_ptr() as *mut _, bytes: hb.min(sb), frames: 0 };
        assert_eq!(lrd_bmfr_denoise_temporal(&cfg, &frame, null(), &mut hist_on_scratch, &o, sp, sb, null_mut()), INVALID);
        let _ = &mut noisy;
    }
}

#[test]
fn simd_level_is_the_one_that_runs() {
    let s = unsafe { std::ffi::CStr::from_ptr(lrd_simd_level()) }.to_str().unwrap();
    assert_eq!(s, lrdenoise_core::simd_level());
    if lrdenoise_core::isa::Isa::detect() == lrdenoise_core::isa::Isa::Avx2Fma {
        assert_eq!(s, "avx2+fma");
    }
}

/// Two threads run every stage's tiles (worker = thread), with a barrier
/// between stages, as the C client does: bit-identical to the whole frame.
#[test]
fn tiled_stages_on_threads() {
    let c = Case::new();
    let frame = c.frame();
    let nt = c.tiles();
    let want = c.whole();
    let mut out = vec![0f32; want.len()];
    let o = out_view(out.as_mut_ptr(), c.w, c.h);
    let (mut scratch, tb) = c.tiled_scratch(2);
    #[derive(Clone, Copy)]
    struct Shared(*const LrdFlrConfig, *const LrdFrame, *const LrdImageMut, *mut core::ffi::c_void, usize);
    // SAFETY: the pointees outlive the scope; lrd_flr_run_tile's rules are kept (barrier, own worker).
    unsafe impl Send for Shared {}
    let sh = Shared(&c.cfg, &frame, &o, scratch.as_mut_ptr() as *mut _, tb);
    let barrier = std::sync::Barrier::new(2);
    std::thread::scope(|s| {
        for worker in 0..2u32 {
            let barrier = &barrier;
            s.spawn(move || {
                let sh = sh;
                for stage in 0..7u32 {
                    let n = if stage == 0 || stage == 2 { 1 } else { nt };
                    for t in (worker..n).step_by(2) {
                        let st = unsafe { lrd_flr_run_tile(sh.0, sh.1, sh.2, sh.3, sh.4, 2, stage, t, worker, null_mut()) };
                        assert_eq!(st, OK, "stage {stage} tile {t} worker {worker}");
                    }
                    barrier.wait();
                }
            });
        }
    });
    assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "threads != whole frame");
}
