//! FLR's roofline: times each stage on a synthetic 1920×1080 frame (Q = 5:
//! normal, depth, AO; one σ = 12 px window; one thread; the fastest of 16 runs
//! (default) per stage, as this is a shared virtual machine) and sets it
//! against the two floors measured in the same run: the bytes the stage must
//! move over the copy bandwidth (a 256 MiB `memcpy`, read + write), and its
//! floating-point operations over the core's fused multiply-add peak (12
//! independent AVX2 FMA chains, f32 for the per-pixel stages, f64 for the
//! cell stages). Bytes are those of the stage's inputs and outputs; flops are
//! counted from the kernels' arithmetic per pixel or per cell (below).
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
    let (cells, models) = {
        let p = flr.split_scratch(&mut scratch, 1).unwrap();
        (p.cells.len() as f64, p.models.len() as f64)
    };
    let (px, q) = (n as f64, 5.0);
    // blur taps per pass: the Gaussian truncated at 3σ, in cells of 8 px
    let taps = 2.0 * (3.0 * flr::config::DEFAULT_SIGMA as f64 / 8.0 - 1e-4).ceil() + 1.0;
    // moments per pixel: the guides and light minus the reference (Q + 3), S = Σ g gᵀ
    // (Q(Q+1)/2 FMAs), P = Σ g yᵀ (3Q FMAs), s and t (Q + 3 adds), ℓ and ℓ² (2 FMAs, a
    // multiply, an FMA)
    let moments_flops = px * ((q + 3.0) + 2.0 * (q * (q + 1.0) / 2.0 + 3.0 * q) + (q + 3.0) + 7.0);
    // solve per cell: a (Q+1)² Cholesky and 3 right-hand sides, with the normalization
    let solve_flops = cells / 40.0 * (2.0 * (q + 1.0).powi(3) / 3.0 + 6.0 * (q + 1.0).powi(2));
    // apply per pixel: the model's 3 + 3Q values interpolated along the row (an FMA each),
    // then 3Q FMAs and 3 adds
    let apply_flops = px * (2.0 * (3.0 + 3.0 * q) + 2.0 * 3.0 * q + 3.0);
    let (bw, f32_peak, f64_peak) = (copy_bandwidth(), fma_peak(false), fma_peak(true));
    let rows: [(&str, f64, f64, f64, bool); 6] = [
        ("moments", t[0], px * 4.0 * (3.0 + q) + cells * 8.0, moments_flops, false),
        ("frame statistics", t[1], cells * 8.0, cells / 40.0 * 2.0 * q, true),
        ("blur rows", t[2], 2.0 * cells * 8.0, cells * taps * 2.0, true),
        ("blur columns", t[3], 2.0 * cells * 8.0, cells * taps * 2.0, true),
        ("solve", t[4], cells * 8.0 + models * 4.0, solve_flops, true),
        ("apply", t[5], px * 4.0 * (q + 3.0) + models * 4.0, apply_flops, false),
    ];
    println!(
        "FLR stages {w}x{h}, Q = 5, one σ = 12 window, one thread, simd {}; same run: copy {:.1} GB/s, FMA peak f32 {:.1} / f64 {:.1} GFLOP/s\n",
        SIMD_LEVEL,
        bw / 1e9,
        f32_peak / 1e9,
        f64_peak / 1e9
    );
    println!("| stage | time (ms) | bytes (MB) | flops (M) | memory floor (ms) | compute floor (ms) | time / larger floor |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let (mut tt, mut tm, mut tc) = (0.0, 0.0, 0.0);
    for (name, ms, bytes, flops, f64) in rows {
        let mem = bytes / bw * 1e3;
        let comp = flops / if f64 { f64_peak } else { f32_peak } * 1e3;
        println!("| {name} | {ms:.2} | {:.1} | {:.0} | {mem:.2} | {comp:.2} | {:.1}× |", bytes / 1e6, flops / 1e6, ms / mem.max(comp));
        (tt, tm, tc) = (tt + ms, tm + mem, tc + comp);
    }
    println!("| whole frame, stage by stage | {tt:.2} | | | {tm:.2} | {tc:.2} | {:.1}× |", tt / tm.max(tc));
    // what a streaming data flow would move: each input read once, the output written once
    let one_pass = px * 4.0 * (3.0 + q + 3.0);
    let floor = one_pass / bw * 1e3;
    println!("| whole frame, one pass | {tt:.2} | {:.1} | | {floor:.2} | {tc:.2} | {:.1}× |", one_pass / 1e6, tt / floor.max(tc));
}

/// Bytes per second of a 256 MiB copy (each byte read and written), the
/// fastest of 5.
fn copy_bandwidth() -> f64 {
    let len = 256 << 20;
    let (src, mut dst) = (vec![1u8; len], vec![0u8; len]);
    let mut best = f64::MAX;
    for _ in 0..5 {
        let t = Instant::now();
        dst.copy_from_slice(std::hint::black_box(&src));
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(&dst);
    2.0 * len as f64 / best
}

/// Floating-point operations per second of one core's fused multiply-adds
/// (AVX2 + FMA when the CPU has them, else `wide`'s lanes), the fastest of 5.
fn fma_peak(f64: bool) -> f64 {
    let iters = 20_000_000;
    let mut best = f64::MAX;
    let mut flops = 0.0;
    for _ in 0..5 {
        let t = Instant::now();
        let (sum, per_iter) = fma_chains(iters, f64);
        best = best.min(t.elapsed().as_secs_f64());
        std::hint::black_box(sum);
        flops = (iters * per_iter) as f64;
    }
    flops / best
}

/// 12 independent FMA chains `iters` times; returns a sum of the results and
/// the flops per iteration.
fn fma_chains(iters: usize, f64: bool) -> (f64, usize) {
    #[cfg(target_arch = "x86_64")]
    if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has AVX2 and FMA (checked above).
        return unsafe {
            if f64 {
                (fma_chains_f64(iters), 12 * 4 * 2)
            } else {
                (fma_chains_f32(iters), 12 * 8 * 2)
            }
        };
    }
    if f64 {
        let (a, b) = (wide::f64x4::splat(0.9999), wide::f64x4::splat(1e-4));
        let mut acc = [wide::f64x4::splat(0.5); 12];
        for _ in 0..iters {
            for v in acc.iter_mut() {
                *v = v.mul_add(a, b);
            }
        }
        return (acc.iter().map(|v| v.reduce_add()).sum(), 12 * 4 * 2);
    }
    let (a, b) = (wide::f32x8::splat(0.9999), wide::f32x8::splat(1e-4));
    let mut acc = [wide::f32x8::splat(0.5); 12];
    for _ in 0..iters {
        for v in acc.iter_mut() {
            *v = v.mul_add(a, b);
        }
    }
    (acc.iter().map(|v| v.reduce_add() as f64).sum(), 12 * 8 * 2)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma_chains_f32(iters: usize) -> f64 {
    use std::arch::x86_64::*;
    let (a, b) = (_mm256_set1_ps(0.9999), _mm256_set1_ps(1e-4));
    let mut acc = [_mm256_set1_ps(0.5); 12];
    for _ in 0..iters {
        for v in acc.iter_mut() {
            *v = _mm256_fmadd_ps(*v, a, b);
        }
    }
    let mut out = [0f32; 8];
    acc.iter()
        .map(|v| {
            _mm256_storeu_ps(out.as_mut_ptr(), *v);
            out.iter().map(|&x| x as f64).sum::<f64>()
        })
        .sum()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma_chains_f64(iters: usize) -> f64 {
    use std::arch::x86_64::*;
    let (a, b) = (_mm256_set1_pd(0.9999), _mm256_set1_pd(1e-4));
    let mut acc = [_mm256_set1_pd(0.5); 12];
    for _ in 0..iters {
        for v in acc.iter_mut() {
            *v = _mm256_fmadd_pd(*v, a, b);
        }
    }
    let mut out = [0f64; 4];
    acc.iter()
        .map(|v| {
            _mm256_storeu_pd(out.as_mut_ptr(), *v);
            out.iter().sum::<f64>()
        })
        .sum()
}
