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

/// A pinhole view of a room (back wall, floor, left wall) with a thin pole.
fn room(w: usize, h: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
    let n = w * h;
    let (mut noisy, mut normal, mut position, mut depth) = (vec![0f32; 3 * n], vec![0f32; 3 * n], vec![0f32; 3 * n], vec![0f32; n]);
    let mut seed = 1u32;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let d = [(x as f32 + 0.5) / w as f32 * 2.0 - 1.0, (1.0 - (y as f32 + 0.5) / h as f32 * 2.0) * h as f32 / w as f32, 0.8];
            let mut best = (10.0 / d[2], [0.0, 0.0, -1.0f32]);
            if d[1] < 0.0 && -2.0 / d[1] < best.0 {
                best = (-2.0 / d[1], [0.0, 1.0, 0.0]);
            }
            if d[0] < 0.0 && -4.0 / d[0] < best.0 {
                best = (-4.0 / d[0], [1.0, 0.0, 0.0]);
            }
            if x % (w / 5) < 3 && 5.0 / d[2] < best.0 {
                best = (5.0 / d[2], [0.0, 0.0, -1.0]);
            }
            let p = d.map(|c| c * best.0);
            normal[3 * i..3 * i + 3].copy_from_slice(&best.1);
            position[3 * i..3 * i + 3].copy_from_slice(&p);
            depth[i] = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            for c in 0..3 {
                seed ^= seed << 13;
                seed ^= seed >> 17;
                seed ^= seed << 5;
                noisy[3 * i + c] = (0.5 + 0.05 * p[1]) * if seed.is_multiple_of(5) { 3.0 } else { 0.5 };
            }
        }
    }
    (noisy, normal, position, depth)
}

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
        let mut scratch = vec![0f32; wl.scratch_len()];
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                black_box(wl.denoise(&frame, 1, &mut scratch, &mut ov).unwrap())
            })
        });
    }
    let src = vec![1f32; bytes / 4];
    let mut dst = vec![0f32; bytes / 4];
    g.bench_function("memcpy_f32_bytes", |b| b.iter(|| dst.copy_from_slice(black_box(&src))));
    let wl = Walr::new(WalrConfig::default(), w, h).unwrap();
    let mut scratch = vec![0f32; wl.temporal_scratch_len()];
    let mut hist = vec![0f32; wl.history_len()];
    g.bench_function("temporal", |b| {
        let mut history = History::new(&mut hist);
        b.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            black_box(wl.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ov).unwrap())
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
