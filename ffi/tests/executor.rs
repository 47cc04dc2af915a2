//! The `..._parallel` entry points on a caller's thread pool (`LrdExecutor`):
//! the same bits as the single-threaded calls, and a status, never a race,
//! for an executor that breaks its contract.

use lrdenoise::*;
use std::ffi::c_void;
use std::ptr::{null, null_mut};
use std::sync::atomic::{AtomicU32, Ordering};

/// How the test pool runs a `for_each`.
#[derive(Clone, Copy, PartialEq)]
enum Mode {
    /// `workers` threads take the indices from a shared counter.
    Threads,
    /// Index 0 is never run.
    SkipFirst,
    /// Index 0 runs twice, one after the other.
    RunFirstTwice,
    /// Every task gets worker `workers` (out of range).
    WorkerOutOfRange,
}

struct Pool {
    workers: u32,
    mode: Mode,
}

unsafe extern "C" fn for_each(pool: *mut c_void, count: u32, task: LrdTask, task_data: *mut c_void) {
    // SAFETY: `pool` is the test's `Pool`, alive for the call.
    let pool = unsafe { &*(pool as *const Pool) };
    // the task data is shared by the threads, as a C pool would share it
    let data = task_data as usize;
    match pool.mode {
        Mode::Threads => {
            let next = AtomicU32::new(0);
            std::thread::scope(|s| {
                for worker in 0..pool.workers {
                    let next = &next;
                    s.spawn(move || loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= count {
                            break;
                        }
                        // SAFETY: the library's task, called as its contract says.
                        unsafe { task(data as *mut c_void, i, worker) };
                    });
                }
            });
        }
        Mode::SkipFirst => (1..count).for_each(|i| unsafe { task(task_data, i, 0) }),
        Mode::RunFirstTwice => {
            (0..count).for_each(|i| unsafe { task(task_data, i, 0) });
            if count > 0 {
                unsafe { task(task_data, 0, 0) };
            }
        }
        Mode::WorkerOutOfRange => (0..count).for_each(|i| unsafe { task(task_data, i, pool.workers) }),
    }
}

fn executor(pool: &Pool) -> LrdExecutor {
    LrdExecutor { for_each: Some(for_each), pool: pool as *const Pool as *mut c_void, workers: pool.workers }
}

fn img(data: *const f32, w: u32, h: u32, ch: usize) -> LrdImage {
    LrdImage { data: data as *const _, format: 0, width: w, height: h, pixel_stride: ch * 4, row_stride: 0, channel_stride: 0 }
}
fn none() -> LrdImage {
    LrdImage { data: null(), format: 0, width: 0, height: 0, pixel_stride: 0, row_stride: 0, channel_stride: 0 }
}

/// A frame's planes: noisy RGB of frame `k`, normal, depth, AO, and a pan.
struct Planes {
    w: u32,
    h: u32,
    normal: Vec<f32>,
    depth: Vec<f32>,
    ao: Vec<f32>,
    position: Vec<f32>,
    motion: Vec<f32>,
}

impl Planes {
    fn new(w: u32, h: u32) -> Self {
        let (wu, n) = (w as usize, (w * h) as usize);
        Planes {
            w,
            h,
            normal: (0..3 * n).map(|i| if i % 3 == (i / 3 / 500) % 3 { 1.0 } else { 0.0 }).collect(),
            depth: (0..n).map(|i| 2.0 + (i / wu) as f32 * 0.02).collect(),
            ao: (0..n).map(|i| 0.5 + ((i * 31) % 50) as f32 / 100.0).collect(),
            position: (0..3 * n).map(|i| ((i / 3) % wu) as f32 * 0.1 + (i % 3) as f32 + ((i / 3) / wu) as f32 * 0.05).collect(),
            motion: (0..2 * n).map(|i| if i % 2 == 0 { 5.5 } else { -0.3 }).collect(),
        }
    }
    fn noisy(&self, k: usize) -> Vec<f32> {
        (0..3 * (self.w * self.h) as usize).map(|i| (((i + 977 * k) * 7919) % 1000) as f32 / 500.0).collect()
    }
    fn frame(&self, noisy: &[f32]) -> LrdFrame {
        let g = LrdGuides { normal: none(), depth: none(), position: none(), ao: none(), user: [none(); 4] };
        let mut f = LrdFrame { noisy: img(noisy.as_ptr(), self.w, self.h, 3), guides: g, guides_low: g, sample_weights: none() };
        f.guides.normal = img(self.normal.as_ptr(), self.w, self.h, 3);
        f.guides.depth = img(self.depth.as_ptr(), self.w, self.h, 1);
        f.guides.ao = img(self.ao.as_ptr(), self.w, self.h, 1);
        f
    }
    /// The frame with the guides `method` reads: FLR normal, depth and AO;
    /// BMFR normal and position; WALR normal, depth and position.
    fn frame_for(&self, noisy: &[f32], method: Temporal) -> LrdFrame {
        let mut f = self.frame(noisy);
        match method {
            Temporal::Moments | Temporal::Light => {}
            Temporal::Bmfr => {
                f.guides.depth = none();
                f.guides.ao = none();
                f.guides.position = img(self.position.as_ptr(), self.w, self.h, 3);
            }
            Temporal::Walr => {
                f.guides.ao = none();
                f.guides.position = img(self.position.as_ptr(), self.w, self.h, 3);
            }
        }
        f
    }
    fn motion(&self) -> LrdImage {
        img(self.motion.as_ptr(), self.w, self.h, 2)
    }
}

fn packed_out(out: &mut [f32], w: u32, h: u32) -> LrdImageMut {
    LrdImageMut { data: out.as_mut_ptr() as *mut _, format: 0, width: w, height: h, pixel_stride: 0, row_stride: 0, channel_stride: 0 }
}

/// Single-frame FLR on 3 threads gives lrd_flr_denoise's bits.
#[test]
fn flr_parallel_gives_the_sequential_bits() {
    for (w, h) in [(67u32, 38u32), (257, 70), (7, 3)] {
        let p = Planes::new(w, h);
        let cfg = lrd_flr_config_default();
        let noisy = p.noisy(0);
        let frame = p.frame(&noisy);
        let pool = Pool { workers: 3, mode: Mode::Threads };
        let ex = executor(&pool);
        let n = (3 * w * h) as usize;
        let (mut want, mut got) = (vec![0f32; n], vec![0f32; n]);
        unsafe {
            let mut sb = 0usize;
            assert_eq!(lrd_flr_scratch_size(&cfg, w, h, &mut sb), LrdStatus::LRD_STATUS_OK);
            let mut s = vec![0f64; sb / 8];
            let o = packed_out(&mut want, w, h);
            assert_eq!(lrd_flr_denoise(&cfg, &frame, &o, s.as_mut_ptr() as *mut _, sb, null_mut()), LrdStatus::LRD_STATUS_OK);
            assert_eq!(lrd_flr_tiled_scratch_size(&cfg, w, h, 3, &mut sb), LrdStatus::LRD_STATUS_OK);
            let mut s = vec![0f64; sb / 8];
            let o = packed_out(&mut got, w, h);
            let sp = s.as_mut_ptr() as *mut c_void;
            assert_eq!(lrd_flr_denoise_parallel(&cfg, &frame, &o, sp, sb, &ex, null_mut()), LrdStatus::LRD_STATUS_OK);
            assert_eq!(got, want, "{w}x{h}");
            assert_eq!(lrd_flr_denoise_parallel(&cfg, &frame, &o, sp, sb - 8, &ex, null_mut()), LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL);
            assert_eq!(lrd_flr_denoise_parallel(&cfg, &frame, &o, sp, sb, null(), null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
            let zero = LrdExecutor { workers: 0, ..ex };
            assert_eq!(lrd_flr_denoise_parallel(&cfg, &frame, &o, sp, sb, &zero, null_mut()), LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
            let no_fn = LrdExecutor { for_each: None, ..ex };
            assert_eq!(lrd_flr_denoise_parallel(&cfg, &frame, &o, sp, sb, &no_fn, null_mut()), LrdStatus::LRD_STATUS_NULL_POINTER);
        }
    }
}

/// Which temporal pipeline the test runs.
#[derive(Clone, Copy, Debug)]
enum Temporal {
    Moments,
    Light,
    Bmfr,
    Walr,
}

/// A pipeline's configuration.
enum Config {
    Flr(LrdFlrConfig),
    Bmfr(LrdBmfrConfig),
    Walr(LrdWalrConfig),
}

impl Temporal {
    fn config(self) -> Config {
        match self {
            Temporal::Moments => Config::Flr(lrd_flr_config_temporal_moments_default()),
            Temporal::Light => Config::Flr(lrd_flr_config_temporal_default()),
            Temporal::Bmfr => Config::Bmfr(lrd_bmfr_config_default()),
            Temporal::Walr => Config::Walr(lrd_walr_config_default()),
        }
    }
    /// Scratch and history bytes, for `workers` workers (None: the sequential call).
    unsafe fn sizes(self, cfg: &Config, tc: &LrdTemporalConfig, w: u32, h: u32, workers: Option<u32>) -> (usize, usize) {
        let (mut sb, mut hb) = (0usize, 0usize);
        let status = unsafe {
            match (self, cfg, workers) {
                (Temporal::Moments, Config::Flr(c), None) => lrd_flr_temporal_moments_sizes(c, tc, w, h, &mut sb, &mut hb),
                (Temporal::Moments, Config::Flr(c), Some(n)) => lrd_flr_temporal_moments_parallel_sizes(c, tc, w, h, n, &mut sb, &mut hb),
                (Temporal::Light, Config::Flr(c), None) => lrd_flr_temporal_sizes(c, tc, w, h, &mut sb, &mut hb),
                (Temporal::Light, Config::Flr(c), Some(n)) => lrd_flr_temporal_parallel_sizes(c, tc, w, h, n, &mut sb, &mut hb),
                (_, Config::Bmfr(c), None) => lrd_bmfr_temporal_sizes(c, w, h, &mut sb, &mut hb),
                (_, Config::Bmfr(c), Some(n)) => lrd_bmfr_temporal_parallel_sizes(c, w, h, n, &mut sb, &mut hb),
                (_, Config::Walr(c), None) => lrd_walr_temporal_sizes(c, w, h, &mut sb, &mut hb),
                (_, Config::Walr(c), Some(n)) => lrd_walr_temporal_parallel_sizes(c, w, h, n, &mut sb, &mut hb),
                _ => unreachable!("a pipeline with another's config"),
            }
        };
        assert_eq!(status, LrdStatus::LRD_STATUS_OK);
        (sb, hb)
    }
    /// One frame: the sequential call without an executor, the `_parallel` call with one (`Some(NULL)`: a NULL executor).
    #[allow(clippy::too_many_arguments)]
    unsafe fn run(
        self,
        cfg: &Config,
        tc: &LrdTemporalConfig,
        frame: &LrdFrame,
        motion: *const LrdImage,
        hist: &mut LrdHistory,
        out: &LrdImageMut,
        scratch: &mut [f64],
        bytes: usize,
        ex: Option<*const LrdExecutor>,
    ) -> LrdStatus {
        let sp = scratch.as_mut_ptr() as *mut c_void;
        let r = null_mut();
        unsafe {
            match (self, cfg, ex) {
                (Temporal::Moments, Config::Flr(c), None) => {
                    lrd_flr_denoise_temporal_moments(c, tc, frame, motion, hist, out, sp, bytes, r)
                }
                (Temporal::Moments, Config::Flr(c), Some(e)) => {
                    lrd_flr_denoise_temporal_moments_parallel(c, tc, frame, motion, hist, out, sp, bytes, e, r)
                }
                (Temporal::Light, Config::Flr(c), None) => lrd_flr_denoise_temporal(c, tc, frame, motion, hist, out, sp, bytes, r),
                (Temporal::Light, Config::Flr(c), Some(e)) => {
                    lrd_flr_denoise_temporal_parallel(c, tc, frame, motion, hist, out, sp, bytes, e, r)
                }
                (_, Config::Bmfr(c), None) => lrd_bmfr_denoise_temporal(c, frame, motion, hist, out, sp, bytes, r),
                (_, Config::Bmfr(c), Some(e)) => lrd_bmfr_denoise_temporal_parallel(c, frame, motion, hist, out, sp, bytes, e, r),
                (_, Config::Walr(c), None) => lrd_walr_denoise_temporal(c, frame, motion, hist, out, sp, bytes, r),
                (_, Config::Walr(c), Some(e)) => lrd_walr_denoise_temporal_parallel(c, frame, motion, hist, out, sp, bytes, e, r),
                _ => unreachable!("a pipeline with another's config"),
            }
        }
    }
}

/// Every temporal pipeline (FLR on moments and on light, BMFR, WALR) on 3
/// threads gives the sequential call's bits over 4 frames of a pan; a NULL
/// executor, 0 workers and a short scratch are refused.
#[test]
fn temporal_parallel_gives_the_sequential_bits() {
    for t in [Temporal::Moments, Temporal::Light, Temporal::Bmfr, Temporal::Walr] {
        for (w, h) in [(67u32, 38u32), (129, 70)] {
            let p = Planes::new(w, h);
            let (cfg, tc) = (t.config(), lrd_temporal_config_default());
            let pool = Pool { workers: 3, mode: Mode::Threads };
            let ex = executor(&pool);
            let n = (3 * w * h) as usize;
            unsafe {
                let (sb1, hb) = t.sizes(&cfg, &tc, w, h, None);
                let (sb3, hb3) = t.sizes(&cfg, &tc, w, h, Some(3));
                assert_eq!(hb, hb3, "one history serves both calls");
                let (mut s1, mut s3) = (vec![0f64; sb1 / 8], vec![0f64; sb3 / 8]);
                let (mut hd1, mut hd3) = (vec![0f32; hb / 4], vec![0f32; hb / 4]);
                let mut h1 = LrdHistory { data: hd1.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
                let mut h3 = LrdHistory { data: hd3.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
                let (mut want, mut got) = (vec![0f32; n], vec![0f32; n]);
                let (ow, og) = (packed_out(&mut want, w, h), packed_out(&mut got, w, h));
                let mv = p.motion();
                let zero = LrdExecutor { workers: 0, ..ex };
                for k in 0..4 {
                    let noisy = p.noisy(k);
                    let frame = p.frame_for(&noisy, t);
                    let m = if k == 0 { null() } else { &mv as *const LrdImage };
                    assert_eq!(t.run(&cfg, &tc, &frame, m, &mut h1, &ow, &mut s1, sb1, None), LrdStatus::LRD_STATUS_OK);
                    assert_eq!(
                        t.run(&cfg, &tc, &frame, m, &mut h3, &og, &mut s3, sb3, Some(&ex as *const LrdExecutor)),
                        LrdStatus::LRD_STATUS_OK
                    );
                    assert_eq!(got, want, "{t:?} {w}x{h} frame {k}");
                    assert_eq!(h3.frames, h1.frames);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
                    let written = bits(&hd3);
                    let refused = [
                        t.run(&cfg, &tc, &frame, m, &mut h3, &og, &mut s3, sb3 - 8, Some(&ex as *const LrdExecutor)),
                        t.run(&cfg, &tc, &frame, m, &mut h3, &og, &mut s3, sb3, Some(&zero as *const LrdExecutor)),
                        t.run(&cfg, &tc, &frame, m, &mut h3, &og, &mut s3, sb3, Some(null())),
                    ];
                    let want_refused = [
                        LrdStatus::LRD_STATUS_BUFFER_TOO_SMALL,
                        LrdStatus::LRD_STATUS_INVALID_ARGUMENT,
                        LrdStatus::LRD_STATUS_NULL_POINTER,
                    ];
                    assert_eq!(refused, want_refused, "{t:?}");
                    assert_eq!(h3.frames, h1.frames, "a refused call leaves the history as it was");
                    assert!(bits(&hd3) == written, "{t:?}: a refused call wrote the history");
                }
            }
        }
    }
    let (cfg, tc) = (lrd_flr_config_temporal_moments_default(), lrd_temporal_config_default());
    let (mut a, mut b) = (0usize, 0usize);
    let status = unsafe { lrd_flr_temporal_moments_parallel_sizes(&cfg, &tc, 67, 38, 0, &mut a, &mut b) };
    assert_eq!(status, LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
}

/// An executor that skips a task, runs one twice or passes a worker out of
/// range gets one of the statuses LrdExecutor's contract names, and the
/// history's frame count stays; the same call on a working pool succeeds.
#[test]
fn a_broken_executor_is_refused() {
    let (w, h) = (67u32, 38u32);
    let p = Planes::new(w, h);
    let noisy = p.noisy(0);
    let mut out = vec![0f32; (3 * w * h) as usize];
    let o = packed_out(&mut out, w, h);
    let named = [LrdStatus::LRD_STATUS_UNSUPPORTED, LrdStatus::LRD_STATUS_STAGE_ORDER, LrdStatus::LRD_STATUS_INVALID_TILE];
    let good = Pool { workers: 2, mode: Mode::Threads };
    let good = executor(&good);
    for mode in [Mode::SkipFirst, Mode::RunFirstTwice, Mode::WorkerOutOfRange] {
        let pool = Pool { workers: 2, mode };
        let ex = executor(&pool);
        unsafe {
            let cfg = lrd_flr_config_default();
            let frame = p.frame(&noisy);
            let mut sb = 0usize;
            assert_eq!(lrd_flr_tiled_scratch_size(&cfg, w, h, 2, &mut sb), LrdStatus::LRD_STATUS_OK);
            let mut s = vec![0f64; sb / 8];
            let sp = s.as_mut_ptr() as *mut c_void;
            let status = lrd_flr_denoise_parallel(&cfg, &frame, &o, sp, sb, &ex, null_mut());
            assert!(named.contains(&status), "{status:?}");
            assert_eq!(lrd_flr_denoise_parallel(&cfg, &frame, &o, sp, sb, &good, null_mut()), LrdStatus::LRD_STATUS_OK);
            for t in [Temporal::Moments, Temporal::Light, Temporal::Bmfr, Temporal::Walr] {
                let (cfg, tc) = (t.config(), lrd_temporal_config_default());
                let frame = p.frame_for(&noisy, t);
                let (sb, hb) = t.sizes(&cfg, &tc, w, h, Some(2));
                let mut s = vec![0f64; sb / 8];
                let mut hd = vec![0f32; hb / 4];
                let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
                let status = t.run(&cfg, &tc, &frame, null(), &mut hist, &o, &mut s, sb, Some(&ex as *const LrdExecutor));
                assert!(named.contains(&status), "{t:?}: {status:?}");
                assert_eq!(hist.frames, 0, "{t:?}");
                let status = t.run(&cfg, &tc, &frame, null(), &mut hist, &o, &mut s, sb, Some(&good as *const LrdExecutor));
                assert_eq!(status, LrdStatus::LRD_STATUS_OK, "{t:?}");
                assert_eq!(hist.frames, 1, "{t:?}");
            }
        }
    }
}

/// A history that overlaps an input image or the motion, and a scratch that
/// overlaps an input image, are refused: the call writes them.
#[test]
fn a_history_over_an_input_is_refused() {
    let (w, h) = (67u32, 38u32);
    let p = Planes::new(w, h);
    let noisy = p.noisy(0);
    let (cfg, tc) = (Temporal::Moments.config(), lrd_temporal_config_default());
    let mut out = vec![0f32; (3 * w * h) as usize];
    let o = packed_out(&mut out, w, h);
    unsafe {
        let (sb, hb) = Temporal::Moments.sizes(&cfg, &tc, w, h, None);
        let mut s = vec![0f64; sb / 8];
        let mut big = vec![0f32; hb / 4 + noisy.len()];
        // the history over a copy of the noisy image: the frame reads it there
        big[..noisy.len()].copy_from_slice(&noisy);
        let frame = p.frame(&big[..noisy.len()]);
        let mut hist = LrdHistory { data: big.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        let status = Temporal::Moments.run(&cfg, &tc, &frame, null(), &mut hist, &o, &mut s, sb, None);
        assert_eq!(status, LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
        // the history over the motion vectors
        let mut mbig = vec![0f32; hb / 4 + p.motion.len()];
        mbig[..p.motion.len()].copy_from_slice(&p.motion);
        let mv = img(mbig.as_ptr(), w, h, 2);
        let frame = p.frame(&noisy);
        let mut hist = LrdHistory { data: mbig.as_mut_ptr() as *mut _, bytes: hb, frames: 1 };
        let status = Temporal::Moments.run(&cfg, &tc, &frame, &mv, &mut hist, &o, &mut s, sb, None);
        assert_eq!(status, LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
        // the scratch over the noisy image, with a separate history
        let mut hd = vec![0f32; hb / 4];
        let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
        let mut sbig = vec![0f64; sb / 8 + noisy.len()];
        let over: &[f32] = std::slice::from_raw_parts(sbig.as_ptr() as *const f32, noisy.len());
        let frame = p.frame(over);
        let status = Temporal::Moments.run(&cfg, &tc, &frame, null(), &mut hist, &o, &mut sbig, sb, None);
        assert_eq!(status, LrdStatus::LRD_STATUS_INVALID_ARGUMENT);
        // and the same call with the scratch apart runs
        let frame = p.frame(&noisy);
        assert_eq!(Temporal::Moments.run(&cfg, &tc, &frame, null(), &mut hist, &o, &mut s, sb, None), LrdStatus::LRD_STATUS_OK);
    }
}

/// A planar output (rows of one channel interleaved with the others'
/// planes) cannot be split into row bands: every parallel call refuses it
/// before it runs (the history's frame count stays).
#[test]
fn a_planar_output_is_refused() {
    let (w, h) = (67u32, 38u32);
    let p = Planes::new(w, h);
    let noisy = p.noisy(0);
    let mut out = vec![0f32; (3 * w * h) as usize];
    let planar = LrdImageMut {
        data: out.as_mut_ptr() as *mut _,
        format: 0,
        width: w,
        height: h,
        pixel_stride: 4,
        row_stride: 4 * w as usize,
        channel_stride: 4 * (w * h) as usize,
    };
    let pool = Pool { workers: 2, mode: Mode::Threads };
    let ex = executor(&pool);
    unsafe {
        for t in [Temporal::Moments, Temporal::Light, Temporal::Bmfr, Temporal::Walr] {
            let (cfg, tc) = (t.config(), lrd_temporal_config_default());
            let frame = p.frame_for(&noisy, t);
            let (sb, hb) = t.sizes(&cfg, &tc, w, h, Some(2));
            let mut s = vec![0f64; sb / 8];
            let mut hd = vec![0f32; hb / 4];
            let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
            let status = t.run(&cfg, &tc, &frame, null(), &mut hist, &planar, &mut s, sb, Some(&ex as *const LrdExecutor));
            assert_eq!(status, LrdStatus::LRD_STATUS_UNSUPPORTED, "{t:?}");
            assert_eq!(hist.frames, 0);
        }
        let frame = p.frame(&noisy);
        let cfg = lrd_flr_config_default();
        let mut sb = 0usize;
        assert_eq!(lrd_flr_tiled_scratch_size(&cfg, w, h, 2, &mut sb), LrdStatus::LRD_STATUS_OK);
        let mut s = vec![0f64; sb / 8];
        let status = lrd_flr_denoise_parallel(&cfg, &frame, &planar, s.as_mut_ptr() as *mut c_void, sb, &ex, null_mut());
        assert_eq!(status, LrdStatus::LRD_STATUS_UNSUPPORTED);
    }
}
