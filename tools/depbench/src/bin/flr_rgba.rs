//! FLR defaults on a 1920×1080 frame held the way engines often hold it: RGBA
//! noisy light and an RGBA normal buffer (xyz + unused w), f32 or (argument
//! `f16`) f16, depth and AO planar; RGBA f32 output; one thread, median of 21
//! runs, with an output checksum.
use depbench::*;
use lrdenoise::*;

fn main() {
    let half = f16_asked();
    // `packed`: depth in the normal buffer's fourth channel (a common G-buffer)
    let packed = std::env::args().any(|a| a == "packed");
    let (w, h) = (1920usize, 1080usize);
    let n = w * h;
    let noisy: Vec<f32> = (0..4 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..4 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    let da: Vec<f32> = (0..2 * n).map(|i| ((i / 89) % 5) as f32 * 0.2 + (i % w) as f32 * 1e-3).collect();
    let (noisy16, normal16, da16) = (halves(half, &noisy), halves(half, &normal), halves(half, &da));
    let planar = |ch: usize| Layout { offset: ch * n, ..Layout::planar(w, h) };
    let guides = Guides {
        normal: Some(view(half, &normal, &normal16, (w, h), 3, Layout::interleaved(w, 4))),
        depth: Some(if packed {
            view(half, &normal, &normal16, (w, h), 1, Layout { offset: 3, ..Layout::interleaved(w, 4) })
        } else {
            view(half, &da, &da16, (w, h), 1, planar(0))
        }),
        ao: Some(view(half, &da, &da16, (w, h), 1, planar(1))),
        ..Default::default()
    };
    let frame = Frame::new(view(half, &noisy, &noisy16, (w, h), 3, Layout::interleaved(w, 4)), guides);
    let (median, min, sum) = time_flr_defaults(&frame, (w, h), 4);
    let kind = if half { "f16" } else { "f32" };
    let kind = if packed { format!("{kind}, depth in normal.w") } else { kind.to_string() };
    println!("RGBA {kind} 1080p q5 defaults: median {median:.2} ms (min {min:.2})  checksum {sum}");
}
