//! A counting global allocator proves that denoising a frame allocates nothing.

mod common;
use common::*;
use lrdenoise::*;
use std::alloc::{GlobalAlloc, Layout as AllocLayout, System};

struct Counting;

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: AllocLayout) -> *mut u8 {
        let _ = MINE.try_with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as our caller's.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: AllocLayout) {
        // SAFETY: `p` came from `System.alloc` with layout `l`.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: AllocLayout, n: usize) -> *mut u8 {
        let _ = MINE.try_with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as our caller's.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

thread_local! {
    /// Allocations made by this thread (the harness allocates on other threads).
    static MINE: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

fn mine() -> usize {
    MINE.with(|c| c.get())
}

#[test]
fn denoise_allocates_nothing() {
    let f = Owned::synthetic(131, 77, 1, 0.5);
    for (set, block, reg) in [
        (GuideSet::NORMAL_DEPTH_AO, 8, Regularization::Normalized { eps_mul: 1e-4, eps_add: 1e-4 }),
        (GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 }, 4, Regularization::Tikhonov { eps: 1e-4 }),
        (GuideSet::NONE, 16, Regularization::Normalized { eps_mul: 1e-4, eps_add: 1e-4 }),
    ] {
        let adaptive = Blur::Adaptive { sigmas: [6.0, 12.0, 20.0] };
        for (blur, without_ao) in [(Blur::Gaussian { sigma: 12.0, radius: None }, false), (adaptive, false), (adaptive, set.ao)] {
            let c = FlrConfig { regularization: reg, block, blur, adaptive_without_ao: without_ao, ..FlrConfig::with_guides(set) };
            let flr = Flr::new(c, f.w, f.h).unwrap();
            let mut scratch = vec![0f64; flr.scratch_len()];
            let mut out = vec![0f32; f.w * f.h * 3];
            let frame = f.frame(set);
            let before = mine();
            for _ in 0..3 {
                let mut ov = ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap();
                flr.denoise(&frame, &mut scratch, &mut ov).unwrap();
            }
            assert_eq!(mine() - before, 0, "{set:?} {blur:?} without_ao {without_ao}");
        }
    }
}

#[test]
fn bmfr_single_frame_and_temporal_allocate_nothing() {
    let f = Owned::synthetic(131, 77, 2, 0.5);
    let set = GuideSet { normal: true, position: true, ..GuideSet::NONE };
    let b = Bmfr::new(BmfrConfig::with_guides(set), f.w, f.h).unwrap();
    let mut scratch = vec![0f32; b.temporal_scratch_len()];
    let mut hist = vec![0f32; b.history_len()];
    let mut out = vec![0f32; f.w * f.h * 3];
    let motion = vec![0.3f32; 2 * f.w * f.h];
    let frame = f.frame(set);
    let mv = ImageView::interleaved(&motion, f.w, f.h, 2).unwrap();
    let mut history = History::new(&mut hist);
    let before = mine();
    for i in 0..3 {
        let mut ov = ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap();
        b.denoise(&frame, i, &mut scratch, &mut ov).unwrap();
        b.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ov).unwrap();
    }
    assert_eq!(mine() - before, 0);
}

#[test]
fn walr_single_frame_and_temporal_allocate_nothing() {
    use lrdenoise::walr::{History as WalrHistory, Storage, Walr, WalrConfig};
    let f = Owned::synthetic(131, 77, 2, 0.5);
    let set = GuideSet { normal: true, depth: true, position: true, ..GuideSet::NONE };
    let frame = f.frame(set);
    let motion = vec![0.3f32; 2 * f.w * f.h];
    let mv = ImageView::interleaved(&motion, f.w, f.h, 2).unwrap();
    let mut out = vec![0f32; f.w * f.h * 3];
    for storage in [Storage::F32, Storage::F16] {
        let wl = Walr::new(WalrConfig { storage, ..WalrConfig::with_guides(set) }, f.w, f.h).unwrap();
        let mut scratch = vec![0f32; wl.temporal_scratch_len()];
        let mut hist = vec![0f32; wl.history_len()];
        let mut history = WalrHistory::new(&mut hist);
        let before = mine();
        for i in 0..3 {
            let mut ov = ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap();
            wl.denoise(&frame, i, &mut scratch, &mut ov).unwrap();
            wl.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ov).unwrap();
        }
        assert_eq!(mine() - before, 0, "{storage:?}");
    }
}

#[test]
fn flnr_allocates_nothing() {
    use lrdenoise::flnr::{Flnr, INPUT_GUIDES};
    let blob = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/train/flnr.bin")).unwrap();
    let f = Owned::synthetic(150, 91, 2, 0.5);
    // one tile (the default for this size) and 3×2 tiles with halos
    for tile in [lrdenoise::flnr::DEFAULT_TILE, 64] {
        let fl = Flnr::new(FlnrConfig { tile, ..FlnrConfig::new(&blob) }, f.w, f.h).unwrap();
        let mut scratch = vec![0f32; fl.scratch_len()];
        let mut fs = vec![0f64; fl.flr_scratch_len()];
        let mut out = vec![0f32; f.w * f.h * 3];
        let frame = f.frame(INPUT_GUIDES);
        let before = mine();
        for _ in 0..2 {
            let mut ov = ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap();
            fl.denoise(&frame, &mut scratch, &mut fs, &mut ov).unwrap();
        }
        assert_eq!(mine() - before, 0, "tile {tile}");
        // two workers: each layer's rows in bands (one tile), or whole tiles
        let mut scratch = vec![0f32; fl.parallel_scratch_len(2).unwrap()];
        let mut fs = vec![0f64; fl.flr().tiled_scratch_len(2).unwrap()];
        let two = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| (0..n).for_each(|i| f(i, i % 2));
        let before = mine();
        let mut ov = ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap();
        fl.denoise_parallel(&frame, &mut scratch, &mut fs, &mut ov, 2, &two).unwrap();
        assert_eq!(mine() - before, 0, "tile {tile}, two workers");
    }
}
