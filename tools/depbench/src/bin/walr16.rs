//! WALR (defaults, f32 and f16 storage) on `benches/walr.rs`'s 1920×1080 room,
//! one thread, median of 5 runs, with an output checksum.
use lrdenoise::walr::{Storage, Walr, WalrConfig};
use lrdenoise::*;
use std::time::Instant;
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

fn main() {
    let (w, h) = (1920, 1080);
    let (noisy, normal, position, depth) = room(w, h);
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
        position: Some(ImageView::interleaved(&position, w, h, 3).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mut out = vec![0f32; 3 * w * h];
    for (name, cfg) in [("f32", WalrConfig::default()), ("f16", WalrConfig { storage: Storage::F16, ..Default::default() })] {
        let wl = Walr::new(cfg, w, h).unwrap();
        let mut scratch = vec![0f32; wl.scratch_len()];
        let mut t = vec![];
        for _ in 0..5 {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            let s = Instant::now();
            wl.denoise(&frame, 1, &mut scratch, &mut ov).unwrap();
            t.push(s.elapsed().as_secs_f64() * 1e3);
        }
        t.sort_by(|a, b| a.partial_cmp(b).unwrap());
        println!("walr {name}: median {:.1} ms  checksum {}", t[2], out.iter().map(|&v| v as f64).sum::<f64>());
    }
}
