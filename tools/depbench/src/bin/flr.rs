//! FLR defaults on a 1920×1080 frame: interleaved RGB noisy light, planar
//! normal + depth + AO, f32 or (argument `f16`) f16; f32 RGB output; one
//! thread, median of 21 runs, with an output checksum so that two builds can
//! be compared for identical output.
use depbench::*;
use lrdenoise::*;

fn main() {
    let half = f16_asked();
    let (w, h) = (1920usize, 1080usize);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let g: Vec<f32> = (0..5 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    let (noisy16, g16) = (halves(half, &noisy), halves(half, &g));
    let planar = |first: usize| Layout { offset: first * n, ..Layout::planar(w, h) };
    let guides = Guides {
        normal: Some(view(half, &g, &g16, (w, h), 3, planar(0))),
        depth: Some(view(half, &g, &g16, (w, h), 1, planar(3))),
        ao: Some(view(half, &g, &g16, (w, h), 1, planar(4))),
        ..Default::default()
    };
    let frame = Frame::new(view(half, &noisy, &noisy16, (w, h), 3, Layout::interleaved(w, 3)), guides);
    let (median, min, sum) = time_flr_defaults(&frame, (w, h), 3);
    let kind = if half { "f16" } else { "f32" };
    println!("{kind} 1080p q5 defaults: median {median:.2} ms (min {min:.2})  checksum {sum}");
}
