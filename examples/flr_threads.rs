//! FLR's tiles on threads, with the caller's executor.
//!
//! ```sh
//! cargo run --release --example flr_threads                  # 1920x1080, one worker per core
//! cargo run --release --example flr_threads -- W H [WORKERS]
//! ```
//!
//! The library spawns no threads. `Flr::denoise_parallel` runs each stage's
//! tiles through an executor the caller passes in: here `std::thread::scope`,
//! with worker `w` taking tiles `w, w + workers, ...`. A thread pool (rayon, a
//! game engine's job system) fits the same closure. The second half runs the
//! same schedule one tile at a time (`Flr::tiled` + `Tiled::run`): what an
//! executor does with each tile, and what the C API's tiled entry points expose.
//! Both give the same output as `Flr::denoise`, bit for bit.

use lrdenoise::{Error, Flr, FlrConfig, Frame, Guides, ImageView, ImageViewMut, Report, Stage};
use std::time::Instant;

/// An executor for `Flr::denoise_parallel`: runs `f(tile, worker)` for every
/// tile in `0..count` on `workers` scoped threads, worker `w` taking tiles
/// `w, w + workers, ...`, and returns when all have run.
fn strided(workers: usize) -> impl Fn(usize, &(dyn Fn(usize, usize) + Sync)) {
    move |count, f| {
        std::thread::scope(|s| {
            for w in 0..workers {
                s.spawn(move || (w..count).step_by(workers).for_each(|tile| f(tile, w)));
            }
        })
    }
}

/// The fastest of `runs` calls of `f`, in ms.
fn fastest(runs: usize, mut f: impl FnMut() -> Result<Report, Error>) -> Result<f64, Error> {
    let mut best = f64::INFINITY;
    for _ in 0..runs {
        let t = Instant::now();
        f()?;
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(best)
}

fn main() -> Result<(), Error> {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let (w, h) = (args.first().copied().unwrap_or(1920), args.get(1).copied().unwrap_or(1080));
    let workers = args.get(2).copied().unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get())).max(1);

    // A synthetic frame: two walls and a floor (normal, depth, AO) under noisy light.
    let n = w * h;
    let hash = |i: usize| ((i.wrapping_mul(2654435761) >> 7) % 1000) as f32 / 1000.0;
    let wall = |i: usize| if i / w > 2 * h / 3 { 2 } else { usize::from(i % w > w / 2) };
    let normal: Vec<f32> = (0..3 * n).map(|i| [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 1.0, 0.0]][wall(i / 3)][i % 3]).collect();
    let depth: Vec<f32> = (0..n).map(|i| 4.0 + (i % w) as f32 / w as f32 - wall(i) as f32).collect();
    let ao: Vec<f32> = (0..n).map(|i| 0.5 + 0.5 * ((i / w) as f32 / h as f32)).collect();
    let noisy: Vec<f32> = (0..3 * n).map(|i| 2.0 * ao[i / 3] * hash(i) * hash(i + 7)).collect();
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3)?),
        depth: Some(ImageView::interleaved(&depth, w, h, 1)?),
        ao: Some(ImageView::interleaved(&ao, w, h, 1)?),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3)?, guides);

    let flr = Flr::new(FlrConfig::default(), w, h)?;
    let runs = 5;

    // One thread.
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut one = vec![0f32; 3 * n];
    let t_one = fastest(runs, || flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut one, w, h, 3)?))?;

    // `workers` threads: a scratch for that many workers, the executor above.
    let mut tiled_scratch = vec![0f64; flr.tiled_scratch_len(workers).expect("scratch size")];
    let mut many = vec![0f32; 3 * n];
    let t_many = fastest(runs, || {
        let mut out = ImageViewMut::interleaved(&mut many, w, h, 3)?;
        flr.denoise_parallel(&frame, &mut tiled_scratch, &mut out, workers, &strided(workers))
    })?;

    // The same schedule, one tile at a time on this thread (worker 0 of 1).
    // Each stage's tiles may run in any order, on any worker, once every
    // tile of the stage before has completed; `Tiled::run` refuses anything else.
    let mut step_scratch = vec![0f64; flr.tiled_scratch_len(1).expect("scratch size")];
    let mut stepped = vec![0f32; 3 * n];
    let checked = flr.check_frame(&frame)?;
    let tiled = flr.tiled(&mut step_scratch, 1)?;
    let mut out = ImageViewMut::interleaved(&mut stepped, w, h, 3)?;
    let mut report = Report::default();
    for stage in Stage::ALL {
        for tile in 0..flr.stage_tiles(stage) {
            report += if stage == Stage::Apply {
                // an apply tile writes the output rows of its band
                let (y0, y1) = flr.tile_pixel_rows(tile)?;
                tiled.run(&checked, stage, tile, 0, Some(&mut out.rows(y0, y1 - y0)?))?
            } else {
                tiled.run(&checked, stage, tile, 0, None)?
            };
        }
    }

    let same = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
    println!("{w}x{h}, normal + depth + AO, FLR defaults, {} band tiles per stage, fastest of {runs}:", flr.tile_count());
    println!("  Flr::denoise                      {t_one:7.2} ms");
    println!(
        "  Flr::denoise_parallel, {workers} workers  {t_many:7.2} ms ({:.2}x), same output bit for bit: {}",
        t_one / t_many,
        same(&one, &many)
    );
    println!("  Tiled::run, tile by tile          same output bit for bit: {}; {report:?}", same(&one, &stepped));
    Ok(())
}
