//! FLNR benchmark (one thread): the bundled network + FLR at 512×512 (with the
//! default tile, which at this size is the whole frame, and in 2×2 tiles of
//! 256 px with halos) and the network alone, next to plain FLR on the same
//! frame, measured in the same run.
//!
//! `RUSTFLAGS="-C target-cpu=x86-64-v3" cargo bench --bench flnr`.

use criterion::{criterion_group, criterion_main, Criterion};
use lrdenoise::flnr::{Flnr, INPUT_GUIDES};
use lrdenoise::*;
use std::hint::black_box;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let (w, h) = (512, 512);
    let n = w * h;
    let blob = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/train/flnr.bin")).unwrap();
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| (((i / 3) / 97) % 7) as f32 * 0.1 - 0.3).collect();
    let depth: Vec<f32> = (0..n).map(|i| 1.0 + (i % w) as f32 * 1e-2).collect();
    let ao: Vec<f32> = (0..n).map(|i| ((i / w) % 13) as f32 / 13.0).collect();
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
        ao: Some(ImageView::interleaved(&ao, w, h, 1).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let fl = Flnr::new(FlnrConfig::new(&blob), w, h).unwrap();
    let d: &dyn Denoiser = &fl;
    let mut scratch = vec![0f64; d.scratch_len()];
    let mut out = vec![0f32; 3 * n];
    let mut g = c.benchmark_group("flnr_512x512");
    g.sample_size(10).measurement_time(Duration::from_secs(8)).warm_up_time(Duration::from_millis(500));
    g.bench_function("flnr", |b| {
        b.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            black_box(d.denoise(&frame, &mut scratch, &mut ov).unwrap())
        })
    });
    // the network in 2×2 tiles of 256 px with halos (more halo recomputed than the default 512 px tile)
    let tiled = Flnr::new(FlnrConfig { tile: 256, ..FlnrConfig::new(&blob) }, w, h).unwrap();
    let dt: &dyn Denoiser = &tiled;
    let mut ws = vec![0f64; dt.scratch_len()];
    g.bench_function("flnr_tiles_256", |b| {
        b.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            black_box(dt.denoise(&frame, &mut ws, &mut ov).unwrap())
        })
    });
    let net = fl.network();
    let input = vec![0.5f32; net.in_channels() * n];
    let mut gout = vec![0f32; net.out_channels() * n];
    let mut ns = vec![0f32; net.scratch_len(w, h)];
    g.bench_function("network_only", |b| b.iter(|| net.forward(black_box(&input), w, h, &mut ns, &mut gout).unwrap()));
    let flr = Flr::new(FlrConfig::with_guides(INPUT_GUIDES), w, h).unwrap();
    let mut s2 = vec![0f64; flr.scratch_len()];
    g.bench_function("flr_baseline", |b| {
        b.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            black_box(flr.denoise(&frame, &mut s2, &mut ov).unwrap())
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
