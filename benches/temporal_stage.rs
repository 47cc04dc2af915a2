//! Times the temporal stage's steps on their own: step 1
//! (`Reprojection::accumulate`, with the firefly clamp) and step 3
//! (`Reprojection::resolve`) on a frame with a history, a quarter-pixel pan
//! (every pixel reprojects through 4 taps), normal + depth, one thread; the
//! pixel groups in `wide`'s lanes, AVX2's and AVX-512's (where the CPU has them)
//! against the per-pixel reference, alternated; minimum and median of RUNS
//! (default 15) each. Then both steps as temporal FLR runs them on one and
//! on THREADS (default 2) workers (scoped std threads, each taking a
//! contiguous group of bands, as in `stage_threads`), alternated.
//! `cargo bench --bench temporal_stage [-- WIDTH HEIGHT [RUNS [THREADS]]]`
use lrdenoise::temporal::{History, Inputs, Reprojection, TemporalConfig};
use lrdenoise::*;
use std::time::Instant;

#[path = "common/threads.rs"]
mod threads;
use threads::run_groups;

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    let (w, h) = (a.first().copied().unwrap_or(1920), a.get(1).copied().unwrap_or(1080));
    let runs = a.get(2).copied().unwrap_or(15).max(1);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..n).flat_map(|i| if (i / 97) % 2 == 0 { [0.0, 1.0, 0.0] } else { [0.6, 0.0, 0.8] }).collect();
    let depth: Vec<f32> = (0..n).map(|i| 2.0 + (i % w) as f32 * 1e-3).collect();
    let motion = vec![0.25f32; 2 * n];
    let current: Vec<f32> = noisy.iter().map(|v| 0.5 * v + 0.25).collect();
    let inputs = Inputs {
        noisy: ImageView::interleaved(&noisy, w, h, 3).unwrap(),
        fireflies: Some(fireflies::DEFAULT_STRENGTH),
        guides: Guides {
            normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
            depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
            ..Default::default()
        },
        motion: Some(ImageView::interleaved(&motion, w, h, 2).unwrap()),
    };
    let fast = Reprojection::new(TemporalConfig::default(), GuideSet::NORMAL_DEPTH, w, h).unwrap();
    let mut stages = vec![("per pixel", fast.per_pixel())];
    for (name, isa) in [("portable lanes", isa::Isa::Portable), ("AVX2 lanes", isa::Isa::Avx2Fma), ("AVX-512 lanes", isa::Isa::Avx512)] {
        if let Some(st) = fast.with_isa(isa) {
            stages.push((name, st));
        }
    }
    let mut hist = vec![0f32; fast.history_len()];
    let mut scratch = vec![0f32; fast.scratch_len()];
    let mut out = vec![0f32; 3 * n];
    let mut times = vec![(Vec::new(), Vec::new()); stages.len()];
    // two frames, so that the timed one (the third) has a history
    let mut frames = 0;
    for _ in 0..2 {
        let mut history = History::resume(&mut hist, frames);
        fast.accumulate(&inputs, &mut history, &mut scratch).unwrap();
        let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
        fast.resolve(&current, &mut history, &mut scratch, false, true, &mut ov).unwrap();
        frames = history.frames();
    }
    for _ in 0..runs {
        for (i, (_, st)) in stages.iter().enumerate() {
            // the same frame each run: it reads one slot and writes the other
            let mut history = History::resume(&mut hist, frames);
            let t = Instant::now();
            st.accumulate(&inputs, &mut history, &mut scratch).unwrap();
            times[i].0.push(t.elapsed().as_secs_f64() * 1e3);
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            let t = Instant::now();
            st.resolve(&current, &mut history, &mut scratch, false, true, &mut ov).unwrap();
            times[i].1.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    let stat = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[0], v[v.len() / 2])
    };
    println!("temporal stage {w}x{h}, one thread, {runs} runs: min / median ms");
    for ((name, _), (a, r)) in stages.iter().zip(times.iter_mut()) {
        let ((amin, amed), (rmin, rmed)) = (stat(a), stat(r));
        println!("{name:>14}: step 1 {amin:.2} / {amed:.2}, step 3 {rmin:.2} / {rmed:.2}");
    }
    let threads = a.get(3).copied().unwrap_or(2).max(2);
    let mut scratch = vec![0f32; fast.parallel_scratch_len(threads).unwrap()];
    let mut times = [(Vec::new(), Vec::new()), (Vec::new(), Vec::new())];
    for _ in 0..runs {
        for (i, workers) in [1, threads].into_iter().enumerate() {
            let exec = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| run_groups(workers, n, f);
            let mut history = History::resume(&mut hist, frames);
            let t = Instant::now();
            fast.accumulate_parallel(&inputs, &mut history, &mut scratch, workers, &exec).unwrap();
            times[i].0.push(t.elapsed().as_secs_f64() * 1e3);
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            let t = Instant::now();
            fast.resolve_parallel(&current, &mut history, &mut scratch, false, true, &mut ov, workers, &exec).unwrap();
            times[i].1.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    println!("threads (the run-time lanes), {runs} runs: min / median ms");
    for (workers, (a, r)) in [1, threads].into_iter().zip(times.iter_mut()) {
        let ((amin, amed), (rmin, rmed)) = (stat(a), stat(r));
        println!("{workers:>2} worker(s): step 1 {amin:.2} / {amed:.2}, step 3 {rmin:.2} / {rmed:.2}");
    }
}
