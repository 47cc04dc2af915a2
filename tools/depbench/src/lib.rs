//! Shared by the binaries: views over f32 or f16 copies of the same values,
//! and the timing loop.
use half::f16;
use lrdenoise::{ImageView, Layout};
use std::time::Instant;

/// Whether the command line asks for f16 inputs (argument `f16`).
pub fn f16_asked() -> bool {
    std::env::args().any(|a| a == "f16")
}

/// The values `v` as f16 (empty when not `half`, so f32 runs pay nothing).
pub fn halves(half: bool, v: &[f32]) -> Vec<f16> {
    if half {
        v.iter().map(|&x| f16::from_f32(x)).collect()
    } else {
        Vec::new()
    }
}

/// A view of `v` (f32) or of its halves `v16`, `channels` channels in `layout`.
pub fn view<'a>(half: bool, v: &'a [f32], v16: &'a [f16], (w, h): (usize, usize), channels: usize, layout: Layout) -> ImageView<'a> {
    if half { ImageView::f16(v16, w, h, channels, layout) } else { ImageView::f32(v, w, h, channels, layout) }.unwrap()
}

/// Median and minimum wall time (ms) of `runs` calls of `f`.
pub fn time_runs(runs: usize, mut f: impl FnMut()) -> (f64, f64) {
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(|a, b| a.total_cmp(b));
    (t[runs / 2], t[0])
}

/// Sum of the output, to compare two builds' results.
pub fn checksum(out: &[f32]) -> f64 {
    out.iter().map(|&v| v as f64).sum()
}
