//! How fast one core reads FLR's guide bytes in the orders the kernels use:
//! 1920×1080 × 5 planar f32 guide planes (41 MB), summed
//! * row by row (apply's order: 5 row streams at a time),
//! * block by block over bands of 8 rows (the moments' order: 8 rows × 5 planes
//!   = 40 row streams advancing 8 values at a time), without software prefetch,
//!   with the moments' L1 prefetch 48 values ahead, and with it plus the L2
//!   prefetch 128 values ahead (`kernels::moments`),
//!
//! next to a `memcpy` of the same 41 MB. Minimum of 7 runs each.
//! `cargo run --release --example read_patterns` (x86-64-v3, one thread, two
//! runs on the machine of `docs/PERFORMANCE.md`: row by row 1.4 / 2.1 ms;
//! blocks 3.7 / 5.1 ms without prefetch, 3.3 / 3.3 with the L1 prefetch,
//! 1.3 / 1.8 ms with both).
use std::hint::black_box;
use std::time::Instant;

const W: usize = 1920;
const H: usize = 1080;
const PLANES: usize = 5;

#[inline(always)]
fn prefetch(s: &[f32], i: usize, l2: bool) {
    #[cfg(target_arch = "x86_64")]
    if i < s.len() {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0, _MM_HINT_T1};
        // SAFETY: `i < s.len()`; a prefetch reads nothing architecturally.
        unsafe {
            if l2 {
                _mm_prefetch(s.as_ptr().add(i) as *const i8, _MM_HINT_T1)
            } else {
                _mm_prefetch(s.as_ptr().add(i) as *const i8, _MM_HINT_T0)
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (s, i, l2);
}

/// Sums 8 values (one block row) into 8 lanes: the compiler keeps it vectorised.
#[inline(always)]
fn add8(acc: &mut [f32; 8], s: &[f32]) {
    for (a, v) in acc.iter_mut().zip(&s[..8]) {
        *a += v;
    }
}

fn rows(g: &[f32]) -> f32 {
    let mut acc = [0f32; 8];
    for y in 0..H {
        for x in (0..W).step_by(8) {
            for p in 0..PLANES {
                add8(&mut acc, &g[p * W * H + y * W + x..]);
            }
        }
    }
    acc.iter().sum()
}

fn blocks(g: &[f32], l1: Option<usize>, l2: Option<usize>) -> f32 {
    let mut acc = [0f32; 8];
    for band in 0..H / 8 {
        for x in (0..W).step_by(8) {
            for r in 0..8 {
                for p in 0..PLANES {
                    let row = &g[p * W * H + (band * 8 + r) * W..][..W];
                    if let Some(d) = l1 {
                        prefetch(row, x + d, false);
                    }
                    if let Some(d) = l2 {
                        prefetch(row, x + d, true);
                    }
                    add8(&mut acc, &row[x..]);
                }
            }
        }
    }
    acc.iter().sum()
}

fn main() {
    let n = PLANES * W * H;
    let g: Vec<f32> = (0..n).map(|i| (i % 977) as f32 * 1e-3).collect();
    let mut dst = vec![0f32; n];
    let mb = (4 * n) as f64 / 1e6;
    let time = |f: &mut dyn FnMut()| {
        (0..7)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .fold(f64::MAX, f64::min)
    };
    let report = |name: &str, ms: f64| println!("{name:<44} {ms:6.2} ms  {:5.1} GB/s", mb / ms);
    report("memcpy (read + write)", time(&mut || dst.copy_from_slice(black_box(&g))));
    report(
        "row by row (5 streams)",
        time(&mut || {
            black_box(rows(&g));
        }),
    );
    report(
        "8-row blocks (40 streams), no prefetch",
        time(&mut || {
            black_box(blocks(&g, None, None));
        }),
    );
    report(
        "8-row blocks, L1 prefetch +48",
        time(&mut || {
            black_box(blocks(&g, Some(48), None));
        }),
    );
    report(
        "8-row blocks, L1 +48 and L2 +128",
        time(&mut || {
            black_box(blocks(&g, Some(48), Some(128)));
        }),
    );
    black_box(&dst);
}
