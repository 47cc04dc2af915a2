//! Times each FLR stage on a synthetic 1920×1080 frame (one thread; the
//! fastest of 15 runs (default) per stage, as this is a shared virtual machine).
//! `cargo bench --bench stages [-- WIDTH HEIGHT [RUNS]]` (more runs for `perf`)
use lrdenoise::*;
use std::time::Instant;

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    let (w, h) = (a.first().copied().unwrap_or(1920), a.get(1).copied().unwrap_or(1080));
    let runs = a.get(2).copied().unwrap_or(16).max(2);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    // Planar guides (as in `benches/flr.rs`): normal x, y, z, depth, AO.
    let g: Vec<f32> = (0..5 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    // one σ = 12 px window: the stage sequence below is the single-window one
    let cfg = FlrConfig { blur: Blur::Gaussian { sigma: flr::config::DEFAULT_SIGMA, radius: None }, ..FlrConfig::default() };
    let flr = Flr::new(cfg, w, h).unwrap();
    let view = |ch: usize, first: usize| {
        let l = Layout { offset: first * n, ..Layout::planar(w, h) };
        ImageView::f32(&g, w, h, ch, l).unwrap()
    };
    let guides = Guides { normal: Some(view(3, 0)), depth: Some(view(1, 3)), ao: Some(view(1, 4)), ..Default::default() };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; 3 * n];
    let mut t = [f64::MAX; 6];
    for it in 0..runs {
        let f = flr.check_frame(&frame).unwrap();
        let p = flr.split_scratch(&mut scratch, 1).unwrap();
        let nt = flr.tile_count();
        let s = Instant::now();
        let mut stats = flr.prepare(&f);
        for k in 0..nt {
            flr.moments_tile(&f, &stats, k, &mut p.cells[flr.cells_tile_range(k).unwrap()], p.workers).unwrap();
        }
        let t0 = s.elapsed().as_secs_f64();
        flr.finish_stats(p.cells, &mut stats).unwrap();
        let t1 = s.elapsed().as_secs_f64();
        for k in 0..nt {
            flr.blur_rows_tile(k, p.cells, &mut p.tmp[flr.cells_tile_range(k).unwrap()]).unwrap();
        }
        let t2 = s.elapsed().as_secs_f64();
        for k0 in (0..nt).step_by(4) {
            let k1 = (k0 + 4).min(nt);
            let band = flr.cells_tile_range(k0).unwrap().start..flr.cells_tile_range(k1 - 1).unwrap().end;
            flr.blur_cols_tiles(k0..k1, p.tmp, &mut p.cells[band]).unwrap();
        }
        let t3 = s.elapsed().as_secs_f64();
        for k in 0..nt {
            flr.solve_tile(&stats, k, &p.cells[flr.cells_tile_range(k).unwrap()], &mut p.models[flr.models_tile_range(k).unwrap()])
                .unwrap();
        }
        let t4 = s.elapsed().as_secs_f64();
        let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
        for k in 0..nt {
            let (y0, y1) = flr.tile_pixel_rows(k).unwrap();
            let mut band = ov.rows(y0, y1 - y0).unwrap();
            flr.apply_tile(&f, &stats, k, p.models, p.workers, &mut band).unwrap();
        }
        let t5 = s.elapsed().as_secs_f64();
        if it > 0 {
            for (acc, v) in t.iter_mut().zip([t0, t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4]) {
                *acc = acc.min(v * 1e3);
            }
        }
    }
    println!(
        "{w}x{h} simd {}: moments {:.2} stats {:.2} blur_rows {:.2} blur_cols {:.2} solve {:.2} apply {:.2} ms; total {:.2}",
        SIMD_LEVEL,
        t[0],
        t[1],
        t[2],
        t[3],
        t[4],
        t[5],
        t.iter().sum::<f64>()
    );
}
