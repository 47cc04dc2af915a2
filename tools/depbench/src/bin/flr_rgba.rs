//! FLR defaults on a 1920×1080 frame held the way engines often hold it: RGBA
//! noisy light and an RGBA normal buffer (xyz + unused w), f32 or f16
//! (argument `f16`), depth and AO planar; one thread, median of 21 runs.
use half::f16;
use lrdenoise::*;
use std::time::Instant;

fn main() {
    let half = std::env::args().any(|a| a == "f16");
    let (w, h) = (1920usize, 1080usize);
    let n = w * h;
    let noisy: Vec<f32> = (0..4 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..4 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    let da: Vec<f32> = (0..2 * n).map(|i| ((i / 89) % 5) as f32 * 0.2 + (i % w) as f32 * 1e-3).collect();
    let to16 = |v: &[f32]| v.iter().map(|&x| f16::from_f32(x)).collect::<Vec<f16>>();
    let (noisy16, normal16, da16) = (to16(&noisy), to16(&normal), to16(&da));
    let planar = |ch: usize| Layout { offset: ch * n, ..Layout::planar(w, h) };
    let frame = if half {
        Frame::new(
            ImageView::f16(&noisy16, w, h, 3, Layout::interleaved(w, 4)).unwrap(),
            Guides {
                normal: Some(ImageView::f16(&normal16, w, h, 3, Layout::interleaved(w, 4)).unwrap()),
                depth: Some(ImageView::f16(&da16, w, h, 1, planar(0)).unwrap()),
                ao: Some(ImageView::f16(&da16, w, h, 1, planar(1)).unwrap()),
                ..Default::default()
            },
        )
    } else {
        Frame::new(
            ImageView::f32(&noisy, w, h, 3, Layout::interleaved(w, 4)).unwrap(),
            Guides {
                normal: Some(ImageView::f32(&normal, w, h, 3, Layout::interleaved(w, 4)).unwrap()),
                depth: Some(ImageView::f32(&da, w, h, 1, planar(0)).unwrap()),
                ao: Some(ImageView::f32(&da, w, h, 1, planar(1)).unwrap()),
                ..Default::default()
            },
        )
    };
    let flr = Flr::new(FlrConfig::default(), w, h).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; 4 * n];
    let mut t = vec![];
    for _ in 0..21 {
        let mut ov = ImageViewMut::new(SamplesMut::F32(&mut out), w, h, 3, Layout::interleaved(w, 4)).unwrap();
        let s = Instant::now();
        flr.denoise(&frame, &mut scratch, &mut ov).unwrap();
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let sum: f64 = out.iter().map(|&v| v as f64).sum();
    println!("RGBA {} 1080p q5 defaults: median {:.2} ms (min {:.2})  checksum {sum}", if half { "f16" } else { "f32" }, t[10], t[0]);
}
