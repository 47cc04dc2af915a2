//! How FLR's stages scale with threads: each stage of the schedule
//! (`Flr::tiled` + `Tiled::run`, as `Flr::denoise_parallel` runs them) timed
//! on one worker and on `THREADS` workers (scoped std threads, each taking a
//! contiguous group of the stage's tiles, as `lrd --threads` does), the two
//! alternated run by run; a memory copy of the bytes one frame moves is timed
//! on one and on `THREADS` threads in the same runs. Defaults: 1920×1080,
//! normal + depth + AO, FLR's default configuration, 2 threads, 15 runs;
//! medians.
//! `cargo bench --bench stage_threads [-- WIDTH HEIGHT [RUNS [THREADS]]]`
use lrdenoise::*;
use std::sync::Mutex;
use std::time::Instant;

#[path = "common/threads.rs"]
mod threads;
use threads::run_groups;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    let (w, h) = (a.first().copied().unwrap_or(1920), a.get(1).copied().unwrap_or(1080));
    let runs = a.get(2).copied().unwrap_or(15).max(1);
    let threads = a.get(3).copied().unwrap_or(2).max(2);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let g: Vec<f32> = (0..5 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    let flr = Flr::new(FlrConfig::default(), w, h).unwrap();
    let view = |ch: usize, first: usize| {
        let l = Layout { offset: first * n, ..Layout::planar(w, h) };
        ImageView::f32(&g, w, h, ch, l).unwrap()
    };
    let guides = Guides { normal: Some(view(3, 0)), depth: Some(view(1, 3)), ao: Some(view(1, 4)), ..Default::default() };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let f = flr.check_frame(&frame).unwrap();
    let mut scratch = vec![0f64; flr.tiled_scratch_len(threads).unwrap()];
    let mut out = vec![0f32; 3 * n];
    // the copy: the light, the guides and the output once
    let bytes = 4 * n * (3 + 5 + 3);
    let (src, mut dst) = (vec![1u8; bytes / 2], vec![0u8; bytes / 2]);
    let mut times: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); Stage::ALL.len() + 2]; 2];
    for _ in 0..runs {
        for (k, workers) in [1, threads].into_iter().enumerate() {
            // each call gets its own `Tiled` over the same scratch (`Flr::tiled_raw`, as the C API's threads)
            let (ptr, len) = (scratch.as_mut_ptr() as usize, scratch.len());
            // SAFETY: the scratch is aligned, holds `len` f64, is reached only through
            // these `Tiled`s while the frame runs, and the calls keep `Tiled::run`'s rules
            // (one stage at a time, each tile once, each worker on one thread).
            let tiled = || unsafe { flr.tiled_raw(ptr as *mut f64, len, workers, 0) }.unwrap();
            // the Apply tiles' output bands, one per tile
            let mut bands = Vec::new();
            let mut rest = &mut out[..];
            for t in 0..flr.tile_count() {
                let (y0, y1) = flr.tile_pixel_rows(t).unwrap();
                let (band, r) = rest.split_at_mut(3 * w * (y1 - y0));
                rest = r;
                bands.push(Mutex::new(ImageViewMut::interleaved(band, w, y1 - y0, 3).unwrap()));
            }
            let frame_start = Instant::now();
            for (i, stage) in Stage::ALL.into_iter().enumerate() {
                let s = Instant::now();
                let run = |t: usize, worker: usize| {
                    let r = if stage == Stage::Apply {
                        tiled().run(&f, stage, t, worker, Some(&mut bands[t].lock().unwrap()))
                    } else {
                        tiled().run(&f, stage, t, worker, None)
                    };
                    r.unwrap();
                };
                match flr.stage_tiles(stage) {
                    1 => run(0, 0),
                    count => run_groups(workers, count, &run),
                }
                times[k][i].push(s.elapsed().as_secs_f64() * 1e3);
            }
            times[k][Stage::ALL.len()].push(frame_start.elapsed().as_secs_f64() * 1e3);
            let chunk = (bytes / 2).div_ceil(workers);
            let parts: Vec<Mutex<&mut [u8]>> = dst.chunks_mut(chunk).map(Mutex::new).collect();
            let s = Instant::now();
            run_groups(workers, parts.len(), &|i, _| {
                let mut d = parts[i].lock().unwrap();
                let len = d.len();
                d.copy_from_slice(std::hint::black_box(&src[i * chunk..i * chunk + len]));
            });
            drop(parts);
            std::hint::black_box(&mut dst);
            times[k][Stage::ALL.len() + 1].push(s.elapsed().as_secs_f64() * 1e3);
        }
    }
    println!("FLR defaults {w}x{h}, normal + depth + AO: stage medians of {runs} runs (ms), 1 and {threads} threads alternated");
    println!("{:>16} {:>9} {:>9} {:>8}", "stage", "1 thread", format!("{threads} thr."), "ratio");
    let names: Vec<String> =
        Stage::ALL.iter().map(|s| format!("{s:?}")).chain(["whole frame".into(), format!("copy {} MB", bytes / 1_000_000)]).collect();
    for (i, name) in names.iter().enumerate() {
        let (one, many) = (median(&mut times[0][i]), median(&mut times[1][i]));
        println!("{name:>16} {one:>9.3} {many:>9.3} {:>7.2}x", one / many);
    }
}
