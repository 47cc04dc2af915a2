//! Householder QR least squares (BMFR's per-block fit): one 32×32 block
//! (1024 rows, 10 features, 3 right-hand sides), and the 2040 blocks that tile
//! a 1920×1080 frame, one thread. Baseline: copying the same matrices.
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lrdenoise::kernels::qr::{lstsq, lstsq_ld, padded_ld};
use std::hint::black_box;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let (rows, m, k) = (1024, 10, 3);
    let mut s = 0x9E3779B97F4A7C15u64;
    let src: Vec<f32> = (0..rows * (m + k))
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect();
    let mut g = c.benchmark_group("qr_1024x10x3");
    g.sample_size(20).measurement_time(Duration::from_secs(3));
    g.throughput(Throughput::Bytes((src.len() * 4) as u64));
    let mut a = src.clone();
    let mut x = vec![0f32; m * k];
    for (name, simd) in [("simd", true), ("scalar", false)] {
        g.bench_function(format!("block_{name}"), |b| {
            b.iter(|| {
                a.copy_from_slice(&src);
                black_box(lstsq(&mut a, rows, m, k, 1e-4, simd, &mut x))
            })
        });
    }
    g.bench_function("copy_only", |b| b.iter(|| a.copy_from_slice(black_box(&src))));
    // Columns padded off multiples of 4 KiB (what BMFR uses): the copy is
    // column by column in the same loop, so copy_only_padded is its baseline.
    let ld = padded_ld(rows);
    let mut ap = vec![0f32; ld * (m + k)];
    let copy_padded = |ap: &mut [f32]| {
        for (d, s) in ap.chunks_mut(ld).zip(src.chunks(rows)) {
            for (d, s) in d.iter_mut().zip(s) {
                *d = *s;
            }
        }
    };
    g.bench_function("block_simd_padded_ld", |b| {
        b.iter(|| {
            copy_padded(&mut ap);
            black_box(lstsq_ld(&mut ap, ld, rows, m, k, 1e-4, true, &mut x))
        })
    });
    g.bench_function("copy_only_padded", |b| b.iter(|| copy_padded(black_box(&mut ap))));
    g.bench_function("frame_1080p_2040_blocks_simd", |b| {
        b.iter(|| {
            for _ in 0..2040 {
                a.copy_from_slice(&src);
                black_box(lstsq(&mut a, rows, m, k, 1e-4, true, &mut x));
            }
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
