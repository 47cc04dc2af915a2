//! Shared by the binaries: views over f32 or f16 copies of the same values,
//! and the timing loop.
use half::f16;
use lrdenoise::{Flr, FlrConfig, Frame, ImageView, ImageViewMut, Layout, SamplesMut};
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

/// FLR's defaults on the `w`×`h` `frame`, written into an f32 output of
/// `stride` values per pixel (the first three: RGB, or RGBA with the fourth
/// left alone), 21 timed runs: median and minimum (ms), and the output's
/// checksum.
pub fn time_flr_defaults(frame: &Frame<'_>, (w, h): (usize, usize), stride: usize) -> (f64, f64, f64) {
    let flr = Flr::new(FlrConfig::default(), w, h).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; stride * w * h];
    let (median, min) = time_runs(21, || {
        let mut ov = ImageViewMut::new(SamplesMut::F32(&mut out), w, h, 3, Layout::interleaved(w, stride)).unwrap();
        flr.denoise(frame, &mut scratch, &mut ov).unwrap();
    });
    (median, min, checksum(&out))
}
