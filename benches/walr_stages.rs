//! Times WALR's stages separately at 1920×1080 on one thread (a profiling
//! aid, not a benchmark: `cargo bench --bench walr` is the benchmark).
//! `RUSTFLAGS="-C target-cpu=x86-64-v3" cargo bench --bench walr_stages [-- [W H] [trace|notrace] [f16] [fixed]]`
//! (fixed: the fixed blend of the last two windows, not the adaptive one;
//! with `WALR_BLEND_TIMES=1` set, the adaptive blend's two passes are timed
//! apart on every run).

use lrdenoise::walr::{Parts, Storage, Walr, WalrConfig};
use lrdenoise::*;
use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let (w, h) = if args.len() == 2 { (args[0], args[1]) } else { (1920, 1080) };
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| if i % 3 == 2 { -1.0 } else { 0.0 }).collect();
    let position: Vec<f32> = (0..3 * n).map(|i| if i % 3 == 2 { 10.0 } else { ((i / 3) % w) as f32 * 1e-2 }).collect();
    let depth = vec![10f32; n];
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
        position: Some(ImageView::interleaved(&position, w, h, 3).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mut out = vec![0f32; 3 * n];
    // `walr_stages W H notrace` / `trace`: only that setting (for profiling)
    let only = std::env::args().find_map(|a| match a.as_str() {
        "trace" => Some(true),
        "notrace" => Some(false),
        _ => None,
    });
    for tracing in [false, true].into_iter().filter(|t| only.is_none_or(|o| o == *t)) {
        let storage = if std::env::args().any(|a| a == "f16") { Storage::F16 } else { Storage::F32 };
        let adaptive_blend = !std::env::args().any(|a| a == "fixed");
        let wl = Walr::new(WalrConfig { tracing, storage, adaptive_blend, ..Default::default() }, w, h).unwrap();
        let mut scratch = vec![0f32; wl.scratch_len()];
        // fastest of the repetitions per stage: prepare, features, 4 iterations, solve, total
        let mut best = [f64::INFINITY; 8];
        for _rep in 0..(40_000_000 / (w * h)).clamp(5, 2000) {
            let cf = wl.check_frame(&frame).unwrap();
            let t0 = Instant::now();
            let prep = wl.prepare(&cf, 0);
            let t1 = Instant::now();
            let Parts { geo, sdf: [s0, s1], z: [z0, z1] } = wl.parts(&mut scratch).unwrap();
            wl.features_rows(&cf, &prep, 0, geo, z0).unwrap();
            let t2 = Instant::now();
            let mut its = vec![];
            for t in 0..4u8 {
                let a = Instant::now();
                if t % 2 == 0 {
                    wl.iterate_rows(t, &prep, 0, geo, s0, z0, s1, z1).unwrap();
                } else {
                    wl.iterate_rows(t, &prep, 0, geo, s1, z1, s0, z0).unwrap();
                }
                its.push(a.elapsed().as_secs_f64() * 1e3);
            }
            let t3 = Instant::now();
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            if wl.blends_adaptively() {
                // T = 4: the last sums are in z0, the previous window's in z1
                let a = Instant::now();
                wl.fit_rows(0, geo, z0, z1).unwrap();
                let b = Instant::now();
                wl.blend_rows(&prep, 0, z1, z0, &mut ov).unwrap();
                if std::env::var_os("WALR_BLEND_TIMES").is_some() {
                    eprintln!("fit_rows {:.2} blend_rows {:.2} ms", (b - a).as_secs_f64() * 1e3, b.elapsed().as_secs_f64() * 1e3);
                }
            } else {
                wl.solve_rows(&prep, 0, geo, [z0, z1], &mut ov).unwrap();
            }
            let t4 = Instant::now();
            let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
            let this = [ms(t0, t1), ms(t1, t2), its[0], its[1], its[2], its[3], ms(t3, t4), ms(t0, t4)];
            for (b, v) in best.iter_mut().zip(this) {
                *b = b.min(v);
            }
        }
        println!(
            "tracing {tracing}: prepare {:.2} features {:.2} iterations [{:.2}, {:.2}, {:.2}, {:.2}] solve {:.2}, total {:.2} ms (fastest of the runs)",
            best[0], best[1], best[2], best[3], best[4], best[5], best[6], best[7]
        );
    }
}
