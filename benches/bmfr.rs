//! BMFR benchmarks (one thread) at 1920×1080: the single-frame fit and the
//! full temporal pipeline, normal + position guides (M = 10 features), f32
//! inputs, next to a memory copy of the bytes each one moves, measured in the
//! same run.
//!
//! `RUSTFLAGS="-C target-cpu=x86-64-v3" cargo bench --bench bmfr`.
//!
//! Bytes moved (f32): fit = noisy (3) + guides (6) read + output (3) written
//! = 48 B/pixel; temporal = fit + history read (reprojection, 10 + 6 planes)
//! and written (16) + scratch planes (13 written, ~13 read) ≈ 280 B/pixel.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lrdenoise::*;
use std::hint::black_box;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let (w, h) = (1920, 1080);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| (((i / 3) / 97) % 7) as f32 * 0.1 - 0.3).collect();
    let position: Vec<f32> = (0..3 * n).map(|i| ((i / 3) % w) as f32 * 1e-2 + (i % 3) as f32 + ((i / 3 / w) as f32 * 1e-2)).collect();
    let motion = vec![0.25f32; 2 * n];
    let set = GuideSet { normal: true, position: true, ..GuideSet::NONE };
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        position: Some(ImageView::interleaved(&position, w, h, 3).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
    let b = Bmfr::new(BmfrConfig::with_guides(set), w, h).unwrap();
    let mut out = vec![0f32; 3 * n];
    // through the traits every method shares (an f64 scratch for both runs)
    let d: &dyn TemporalDenoiser = &b;
    let mut scratch = vec![0f64; d.temporal_scratch_len().max(d.scratch_len())];
    let mut hist = vec![0f32; d.history_len()];

    let fit_bytes = 48 * n;
    let mut g = c.benchmark_group("bmfr_1920x1080");
    g.sample_size(10).measurement_time(Duration::from_secs(4)).warm_up_time(Duration::from_millis(500));
    g.throughput(Throughput::Bytes(fit_bytes as u64));
    g.bench_function("fit", |bch| {
        bch.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            black_box(d.denoise(&frame, &mut scratch, &mut ov).unwrap())
        })
    });
    let src = vec![1f32; fit_bytes / 4];
    let mut dst = vec![0f32; fit_bytes / 4];
    g.bench_function("memcpy_fit_bytes", |bch| bch.iter(|| dst.copy_from_slice(black_box(&src))));
    let temporal_bytes = 280 * n;
    g.throughput(Throughput::Bytes(temporal_bytes as u64));
    g.bench_function("temporal", |bch| {
        let mut history = History::new(&mut hist);
        bch.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            black_box(d.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ov).unwrap())
        })
    });
    let src = vec![1f32; temporal_bytes / 4];
    let mut dst = vec![0f32; temporal_bytes / 4];
    g.bench_function("memcpy_temporal_bytes", |bch| bch.iter(|| dst.copy_from_slice(black_box(&src))));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
