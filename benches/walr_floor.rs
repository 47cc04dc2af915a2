//! A floor under WALR's single-frame time at 1920×1080 on one core: the
//! à-trous sums alone, as a perfect implementation would do them (a timing
//! aid, not a benchmark; see `docs/PERFORMANCE.md`, WALR).
//!
//! Every WALR iteration sums, per pixel and stored plane, the centre and 8
//! taps weighted by their edge-stopping values: 9 loads and 8 multiply-adds
//! per plane. The method stores at least 14 planes for m = 3 features plus
//! the sample count W (this library stores those 15, and 16 with the adaptive
//! blend), and runs T = 4 iterations. This program does exactly that work and
//! nothing else: weights already in registers (no edge-stopping, no tracing),
//! every value it reads in L2 (no memory traffic), no solve, no features, no
//! borders, f32x8 lanes with fused multiply-adds. Whatever it measures, the
//! real method needs more.
//!
//! A second run adds the one thing no implementation can skip either: each
//! tap's edge-stopping weight from the geometry (untraced: the tap itself).
//!
//! `RUSTFLAGS="-C target-cpu=x86-64-v3" cargo bench --bench walr_floor [-- PLANES]`

use std::hint::black_box;
use std::time::Instant;
use wide::f32x8;

const W: usize = 1920;
const H: usize = 1080;
const ITERATIONS: usize = 4;
/// Room for the widest tap offset (3^(T−1) = 27 pixels at T = 4), rounded
/// up to a whole group so that every centre load is aligned.
const HALO: usize = 32;

/// Floats per stored row of one plane (the row and both halos).
const N: usize = W + 2 * HALO;

/// Geometry planes per row for the edge-stopping weights: position (3) and
/// normal (3) of the plane test, validity, 1 / scale.
const G: usize = 8;

/// The 8 tap weights of the group at `x` from the geometry rows (`geo`:
/// `[row][plane][N]`, planes p (3), n (3), valid, 1/scale): the plane
/// distance of each tap from the centre's plane, mapped to [0, 1], 0 where
/// the validity differs (the untraced edge-stopping weight, as `weight8`).
#[inline(always)]
fn weights_at(geo: *const f32, x: usize, s: usize) -> [f32x8; 8] {
    // SAFETY: as in `row` (same bounds, G planes).
    let g = |r: usize, k: usize, i: usize| unsafe { core::ptr::read_unaligned(geo.add((r * G + k) * N + i) as *const f32x8) };
    let (p, n) = ([g(1, 0, x), g(1, 1, x), g(1, 2, x)], [g(1, 3, x), g(1, 4, x), g(1, 5, x)]);
    let (valid, scale) = (g(1, 6, x), g(1, 7, x) * f32x8::splat(100.0));
    let far = f32x8::splat(2.0);
    let w = |r: usize, i: usize| {
        // (fused where the library is not, to keep the floor low)
        let d = n[0].mul_add(g(r, 0, i) - p[0], n[1].mul_add(g(r, 1, i) - p[1], n[2] * (g(r, 2, i) - p[2])));
        let v = (-d.abs()).mul_add(scale, far).fast_max(f32x8::ZERO).fast_min(f32x8::ONE);
        g(r, 6, i).simd_eq(valid).select(v, f32x8::ZERO)
    };
    [w(0, x - s), w(0, x), w(0, x + s), w(1, x - s), w(1, x + s), w(2, x - s), w(2, x), w(2, x + s)]
}

/// One iteration of one row: for each 8-pixel group, the 8 tap weights in
/// registers (given, or with `WEIGHTS` computed from `geo`), then every
/// plane's centre + 8 multiply-adds. `rows` holds the rows above, at and
/// below the pixel (`[row][plane][N]`), `out` the row's result
/// (`[plane][W]`): constant offsets from base pointers.
#[inline(never)]
fn row<const P: usize, const WEIGHTS: bool>(rows: &[f32], geo: &[f32], weights: &[[f32x8; 8]], s: usize, out: &mut [f32]) {
    assert!(s <= HALO && weights.len() * 8 <= W && rows.len() >= 3 * P * N && geo.len() >= 3 * G * N && out.len() >= P * W);
    let (src, dst) = (rows.as_ptr(), out.as_mut_ptr());
    // SAFETY: x − s ≥ 0 and x + s + 8 ≤ N, r < 3, k < P (asserted above).
    let ld = |r: usize, k: usize, i: usize| unsafe { core::ptr::read_unaligned(src.add((r * P + k) * N + i) as *const f32x8) };
    for (g, f) in weights.iter().enumerate() {
        let x = HALO + 8 * g;
        let f = if WEIGHTS { weights_at(geo.as_ptr(), x, s) } else { *f };
        for k in 0..P {
            let mut a = ld(1, k, x);
            a = f[0].mul_add(ld(0, k, x - s), a);
            a = f[1].mul_add(ld(0, k, x), a);
            a = f[2].mul_add(ld(0, k, x + s), a);
            a = f[3].mul_add(ld(1, k, x - s), a);
            let mut b = f[4] * ld(1, k, x + s);
            b = f[5].mul_add(ld(2, k, x - s), b);
            b = f[6].mul_add(ld(2, k, x), b);
            b = f[7].mul_add(ld(2, k, x + s), b);
            // SAFETY: k·W + 8g + 8 ≤ P·W (asserted above).
            unsafe { core::ptr::write_unaligned(dst.add(k * W + 8 * g) as *mut f32x8, a + b) };
        }
    }
}

/// 32-byte aligned f32 storage (as f32x8) of `n` values.
fn aligned(n: usize, f: impl Fn(usize) -> f32) -> Vec<f32x8> {
    let mut v = vec![f32x8::ZERO; n.div_ceil(8)];
    bytemuck::cast_slice_mut::<f32x8, f32>(&mut v).iter_mut().enumerate().for_each(|(i, x)| *x = f(i));
    v
}

fn run<const P: usize, const WEIGHTS: bool>() {
    let rows = aligned(3 * P * N, |i| ((i * 7) % 97) as f32 * 0.01);
    // geometry: a gently varying surface, valid everywhere
    let geo = aligned(3 * G * N, |i| match (i / N) % G {
        6 => 1.0,
        3..=5 => 0.57,
        _ => (i % N) as f32 * 1e-3 + ((i * 13) % 7) as f32 * 1e-4,
    });
    let (rows, geo): (&[f32], &[f32]) = (bytemuck::cast_slice(&rows), bytemuck::cast_slice(&geo));
    let weights: Vec<[f32x8; 8]> = (0..W / 8).map(|g| core::array::from_fn(|d| f32x8::splat(((g + d) % 5) as f32 * 0.2))).collect();
    let mut out = aligned(P * W, |_| 0.0);
    let out: &mut [f32] = bytemuck::cast_slice_mut(&mut out);
    let mut best = f64::INFINITY;
    for _ in 0..7 {
        let t0 = Instant::now();
        for t in 0..ITERATIONS {
            let s = 3usize.pow(t as u32);
            for _y in 0..H {
                row::<P, WEIGHTS>(black_box(rows), black_box(geo), black_box(&weights), s, out);
                black_box(&mut *out);
            }
        }
        best = best.min(t0.elapsed().as_secs_f64() * 1e3);
    }
    let fmas = (ITERATIONS * 8 * P) as f64 * (W * H) as f64;
    let what = if WEIGHTS { "with untraced edge-stopping weights" } else { "weights given" };
    println!(
        "à-trous sums, {P} planes, {what}, T = {ITERATIONS}, {W}x{H}, one thread, in L2, fastest of 7: {best:.1} ms ({:.1} multiply-add lanes per ns)",
        fmas / (best * 1e6)
    );
}

fn main() {
    // (`cargo bench` adds `--bench` to the arguments)
    let planes = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(15usize);
    match planes {
        14 => (run::<14, false>(), run::<14, true>()),
        16 => (run::<16, false>(), run::<16, true>()),
        _ => (run::<15, false>(), run::<15, true>()),
    };
}
