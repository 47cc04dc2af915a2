//! FLR defaults on a 1920×1080 frame of f32 inputs (interleaved RGB noisy,
//! planar normal + depth + AO), one thread, median of 21 runs, with an output
//! checksum so that two builds can be compared for identical output.
use lrdenoise::*;
use std::time::Instant;
fn main() {
    let (w, h) = (1920usize, 1080usize);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let g: Vec<f32> = (0..5 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    let flr = Flr::new(FlrConfig::default(), w, h).unwrap();
    let view = |ch: usize, first: usize| {
        let l = Layout { offset: first * n, ..Layout::planar(w, h) };
        ImageView::f32(&g, w, h, ch, l).unwrap()
    };
    let guides = Guides { normal: Some(view(3, 0)), depth: Some(view(1, 3)), ao: Some(view(1, 4)), ..Default::default() };
    let frame = Frame::new(ImageView::f32(&noisy, w, h, 3, Layout::interleaved(w, 3)).unwrap(), guides);
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; 3 * n];
    let mut t = vec![];
    for _ in 0..21 {
        let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
        let s = Instant::now();
        flr.denoise(&frame, &mut scratch, &mut ov).unwrap();
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(|a, b| a.partial_cmp(b).unwrap());
    println!("f32 1080p q5 defaults: median {:.2} ms (min {:.2})  checksum {}", t[10], t[0], out.iter().map(|&v| v as f64).sum::<f64>());
}
