//! WALR benchmarks (one thread) at 1920×1080 on a ray-cast room (planes, a
//! pole, so tracing meets real edges): the single-frame filter (f32 and f16
//! averages, tracing on and off) and the temporal pipeline, next to a memory
//! copy of the bytes the single frame moves, measured in the same run.
//!
//! `RUSTFLAGS="-C target-cpu=x86-64-v3" cargo bench --bench walr`.
//!
//! Bytes moved per pixel (f32 averages, m = 3, 15 planes incl. the count):
//! features: inputs 40 read, geometry 40 + averages 60 written; each of the
//! 4 iterations: averages 60 read (the taps hit cache) + 60 written,
//! geometry 32 + SDF 4 read, SDF 4 written; solve: 60 + 12 read, 12 written
//! ≈ 860 B/pixel (f16 averages: ≈ 560).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lrdenoise::walr::{History, Storage, Walr, WalrConfig};
use lrdenoise::*;
use std::hint::black_box;
use std::time::Duration;

#[path = "common/room.rs"]
mod room;
use room::room;

fn bench(c: &mut Criterion) {
    let (w, h) = (1920, 1080);
    let n = w * h;
    let (noisy, normal, position, depth) = room(w, h);
    let motion = vec![0.25f32; 2 * n];
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
        position: Some(ImageView::interleaved(&position, w, h, 3).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
    let mut out = vec![0f32; 3 * n];

    let mut g = c.benchmark_group("walr_1920x1080");
    g.sample_size(10).measurement_time(Duration::from_secs(6)).warm_up_time(Duration::from_millis(500));
    let bytes = 860 * n;
    g.throughput(Throughput::Bytes(bytes as u64));
    for (name, cfg) in [
        ("f32", WalrConfig::default()),
        ("f16", WalrConfig { storage: Storage::F16, ..Default::default() }),
        ("f32_no_tracing", WalrConfig { tracing: false, ..Default::default() }),
    ] {
        let wl = Walr::new(cfg, w, h).unwrap();
        let d: &dyn Denoiser = &wl;
        let mut scratch = vec![0f64; d.scratch_len()];
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                black_box(d.denoise(&frame, &mut scratch, &mut ov).unwrap())
            })
        });
    }
    let src = vec![1f32; bytes / 4];
    let mut dst = vec![0f32; bytes / 4];
    g.bench_function("memcpy_f32_bytes", |b| b.iter(|| dst.copy_from_slice(black_box(&src))));
    let wl = Walr::new(WalrConfig::default(), w, h).unwrap();
    let d: &dyn TemporalDenoiser = &wl;
    let mut scratch = vec![0f64; d.temporal_scratch_len()];
    let mut hist = vec![0f32; d.history_len()];
    g.bench_function("temporal", |b| {
        let mut history = History::new(&mut hist);
        b.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            black_box(d.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ov).unwrap())
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
