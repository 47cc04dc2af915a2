//! FLR benchmarks (one thread): whole frame and each stage at 1280×720 and
//! 1920×1080, f32 and f16 inputs, 3/5/8 guide channels, next to a memory copy
//! of the same full-resolution bytes measured in the same run.
//!
//! `cargo bench --bench flr` (default build: SSE2 on x86-64), and
//! `RUSTFLAGS="-C target-cpu=x86-64-v3" cargo bench --bench flr` for AVX2+FMA.
//! Bytes per frame = inputs read by the moments stage (noisy + Q guides) +
//! guides read by the apply stage + the f32 RGB output written.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use half::f16;
use lrdenoise::*;
use std::hint::black_box;
use std::time::Duration;

struct Data {
    w: usize,
    h: usize,
    noisy: Vec<f32>,
    g: Vec<f32>, // Q planes of w*h (planar guide channels)
    noisy16: Vec<f16>,
    g16: Vec<f16>,
}

fn data(w: usize, h: usize) -> Data {
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let g: Vec<f32> = (0..8 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    Data { w, h, noisy16: noisy.iter().map(|v| f16::from_f32(*v)).collect(), g16: g.iter().map(|v| f16::from_f32(*v)).collect(), noisy, g }
}

/// Guide set with `q` channels: 3 = normal, 5 = normal+depth+ao, 8 = all four layers.
fn set(q: usize) -> GuideSet {
    match q {
        3 => GuideSet { normal: true, ..GuideSet::NONE },
        5 => GuideSet::NORMAL_DEPTH_AO,
        _ => GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 },
    }
}

fn frame<'a>(d: &'a Data, q: usize, f16in: bool) -> Frame<'a> {
    let (w, h) = (d.w, d.h);
    let pl = Layout::planar(w, h);
    let view = |ch: usize, first: usize| -> ImageView<'a> {
        let off = Layout { offset: first * w * h, ..pl };
        if f16in {
            ImageView::f16(&d.g16, w, h, ch, off).unwrap()
        } else {
            ImageView::f32(&d.g, w, h, ch, off).unwrap()
        }
    };
    let s = set(q);
    let mut guides = Guides { normal: Some(view(3, 0)), ..Default::default() };
    if s.depth {
        guides.depth = Some(view(1, 3));
    }
    if s.position {
        guides.position = Some(view(3, 4));
    }
    if s.ao {
        guides.ao = Some(view(1, 7));
    }
    let noisy = if f16in {
        ImageView::f16(&d.noisy16, w, h, 3, Layout::interleaved(w, 3)).unwrap()
    } else {
        ImageView::interleaved(&d.noisy, w, h, 3).unwrap()
    };
    Frame::new(noisy, guides)
}

fn bytes(w: usize, h: usize, q: usize, elem: usize) -> u64 {
    ((w * h) * (elem * (3 + 2 * q) + 4 * 3)) as u64
}

/// One Gaussian window of σ = 12 px (not the default adaptive window).
fn single(q: usize) -> FlrConfig {
    FlrConfig { blur: Blur::Gaussian { sigma: lrdenoise::flr::config::DEFAULT_SIGMA, radius: None }, ..FlrConfig::with_guides(set(q)) }
}

fn bench_frames(c: &mut Criterion) {
    for (w, h) in [(1280, 720), (1920, 1080)] {
        let d = data(w, h);
        for (f16in, fmt) in [(false, "f32"), (true, "f16")] {
            let mut g = c.benchmark_group(format!("frame_{w}x{h}_{fmt}"));
            g.sample_size(10).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_millis(500));
            for q in [3, 5, 8] {
                let nbytes = bytes(w, h, q, if f16in { 2 } else { 4 });
                g.throughput(Throughput::Bytes(nbytes));
                let fr = frame(&d, q, f16in);
                // the defaults (the adaptive window, the AO demodulation), one σ = 12 px
                // window (the fast path), and the defaults without the AO demodulation
                let plain = FlrConfig { ao_demodulation: None, ..FlrConfig::with_guides(set(q)) };
                let configs = [("flr", FlrConfig::with_guides(set(q))), ("flr_sigma12", single(q)), ("flr_no_ao_demod", plain)];
                for (name, cfg) in configs.into_iter().filter(|(n, c)| *n != "flr_no_ao_demod" || c.guides.ao) {
                    let flr = Flr::new(cfg, w, h).unwrap();
                    let mut scratch = vec![0f64; flr.scratch_len()];
                    let mut out = vec![0f32; 3 * w * h];
                    g.bench_function(BenchmarkId::new(name, format!("q{q}")), |b| {
                        b.iter(|| {
                            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                            black_box(flr.denoise(&fr, &mut scratch, &mut ov).unwrap())
                        })
                    });
                }
                // baseline: copy the same number of bytes (read + write half each)
                let src = vec![1u8; nbytes as usize / 2];
                let mut dst = vec![0u8; nbytes as usize / 2];
                g.bench_function(BenchmarkId::new("memcpy", format!("q{q}")), |b| {
                    b.iter(|| {
                        dst.copy_from_slice(black_box(&src));
                        black_box(&dst);
                    })
                });
            }
            g.finish();
        }
    }
}

/// Each stage alone (normal+depth+ao, f32, 1920×1080, one σ = 12 px window).
fn bench_stages(c: &mut Criterion) {
    let (w, h, q) = (1920, 1080, 5);
    let d = data(w, h);
    let flr = Flr::new(single(q), w, h).unwrap();
    let fr = frame(&d, q, false);
    let f = flr.check_frame(&fr).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; 3 * w * h];
    // fill every intermediate once
    flr.denoise(&fr, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
    let p = flr.split_scratch(&mut scratch, 1).unwrap();
    let nt = flr.tile_count();
    let mut stats = flr.prepare(&f);
    flr.finish_stats(p.cells, &mut stats).unwrap();
    let mut g = c.benchmark_group("stages_1920x1080_q5");
    g.sample_size(10).measurement_time(Duration::from_secs(2)).warm_up_time(Duration::from_millis(300));
    g.bench_function("1_moments", |b| {
        b.iter(|| {
            for t in 0..nt {
                flr.moments_tile(&f, &stats, t, &mut p.cells[flr.cells_tile_range(t).unwrap()], p.workers).unwrap();
            }
        })
    });
    g.bench_function("2_blur_rows", |b| {
        b.iter(|| {
            for t in 0..nt {
                flr.blur_rows_tile(t, p.cells, &mut p.tmp[flr.cells_tile_range(t).unwrap()]).unwrap();
            }
        })
    });
    g.bench_function("3_blur_cols", |b| {
        b.iter(|| {
            for t in 0..nt {
                flr.blur_cols_tile(t, p.tmp, &mut p.cells[flr.cells_tile_range(t).unwrap()]).unwrap();
            }
        })
    });
    g.bench_function("4_solve", |b| {
        b.iter(|| {
            for t in 0..nt {
                flr.solve_tile(&stats, t, &p.cells[flr.cells_tile_range(t).unwrap()], &mut p.models[flr.models_tile_range(t).unwrap()])
                    .unwrap();
            }
        })
    });
    g.bench_function("5_apply", |b| {
        b.iter(|| {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            for t in 0..nt {
                let (y0, y1) = flr.tile_pixel_rows(t).unwrap();
                let mut band = ov.rows(y0, y1 - y0).unwrap();
                flr.apply_tile(&f, &stats, t, p.models, p.workers, &mut band).unwrap();
            }
        })
    });
    g.finish();
}

/// The adaptive window (σ = 6/12/20 px, two of them on the pooled grid; the
/// default) next to one σ = 12 px window in the same run (normal+depth+ao,
/// f32, 1920×1080).
fn bench_adaptive(c: &mut Criterion) {
    let (w, h, q) = (1920, 1080, 5);
    let d = data(w, h);
    let fr = frame(&d, q, false);
    let mut g = c.benchmark_group(format!("window_{w}x{h}_f32_q{q}"));
    g.sample_size(10).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_millis(500));
    let adaptive = FlrConfig { blur: Blur::Adaptive { sigmas: [6.0, 12.0, 20.0] }, ..single(q) };
    for (name, cfg) in [("sigma12", single(q)), ("sigma6_12_20", adaptive)] {
        let flr = Flr::new(cfg, w, h).unwrap();
        let mut scratch = vec![0f64; flr.scratch_len()];
        let mut out = vec![0f32; 3 * w * h];
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                black_box(flr.denoise(&fr, &mut scratch, &mut ov).unwrap())
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_frames, bench_stages, bench_adaptive);
criterion_main!(benches);
