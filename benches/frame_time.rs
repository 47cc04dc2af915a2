//! Times `Flr::denoise` with the defaults (adaptive window, AO
//! demodulation), the defaults without the AO demodulation (`ao_demodulation:
//! None`), one σ = 12 px window and the defaults plus the AO-free candidate
//! (`adaptive_without_ao`) on the synthetic 1920×1080 frame of `benches/stages.rs`
//! (planar normal + depth + AO, interleaved RGB in and out), one thread; the
//! fastest of RUNS (default 15) each, alternating the configurations.
//! `cargo bench --bench frame_time [-- WIDTH HEIGHT [RUNS]]`
use lrdenoise::*;
use std::time::Instant;

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    let (w, h) = (a.first().copied().unwrap_or(1920), a.get(1).copied().unwrap_or(1080));
    let runs = a.get(2).copied().unwrap_or(15).max(1);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let g: Vec<f32> = (0..5 * n).map(|i| ((i / 97) % 7) as f32 * 0.3 + (i % w) as f32 * 1e-3).collect();
    let view = |ch: usize, first: usize| {
        let l = Layout { offset: first * n, ..Layout::planar(w, h) };
        ImageView::f32(&g, w, h, ch, l).unwrap()
    };
    let guides = Guides { normal: Some(view(3, 0)), depth: Some(view(1, 3)), ao: Some(view(1, 4)), ..Default::default() };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let configs = [
        ("defaults", FlrConfig::default()),
        ("no ao demodulation", FlrConfig { ao_demodulation: None, ..FlrConfig::default() }),
        ("sigma 12", FlrConfig { blur: Blur::Gaussian { sigma: flr::config::DEFAULT_SIGMA, radius: None }, ..FlrConfig::default() }),
        ("without ao", FlrConfig { adaptive_without_ao: true, ..FlrConfig::default() }),
    ];
    let flrs: Vec<Flr> = configs.iter().map(|(_, c)| Flr::new(*c, w, h).unwrap()).collect();
    let mut scratch: Vec<Vec<f64>> = flrs.iter().map(|f| vec![0f64; f.scratch_len()]).collect();
    let mut out = vec![0f32; 3 * n];
    let mut best = vec![f64::MAX; flrs.len()];
    let mut check = vec![0f64; flrs.len()];
    for _ in 0..runs {
        for (i, flr) in flrs.iter().enumerate() {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            let t = Instant::now();
            flr.denoise(&frame, &mut scratch[i], &mut ov).unwrap();
            best[i] = best[i].min(t.elapsed().as_secs_f64());
            check[i] = out.iter().step_by(97).map(|v| *v as f64).sum();
        }
    }
    for (i, (name, _)) in configs.iter().enumerate() {
        print!("{name} {:.2} ms (check {:.6e}); ", best[i] * 1e3, check[i]);
    }
    println!("{w}x{h}, best of {runs}");
}
