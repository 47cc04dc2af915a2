//! Joint denoise + upsample (paper §3.2.1): noisy at 1/2 or 1/4 resolution.

mod common;
use common::*;
use lrdenoise::*;

/// Box-downsamples interleaved `c`-channel data by `u` (partial blocks averaged).
fn down(v: &[f32], w: usize, h: usize, c: usize, u: usize) -> Vec<f32> {
    let (lw, lh) = (w.div_ceil(u), h.div_ceil(u));
    let mut o = vec![0f32; lw * lh * c];
    for y in 0..lh {
        for x in 0..lw {
            for ch in 0..c {
                let (mut s, mut n) = (0.0, 0.0);
                for yy in y * u..((y + 1) * u).min(h) {
                    for xx in x * u..((x + 1) * u).min(w) {
                        s += v[(yy * w + xx) * c + ch];
                        n += 1.0;
                    }
                }
                o[(y * lw + x) * c + ch] = s / n;
            }
        }
    }
    o
}

#[test]
fn upsampled_denoise_is_close_to_full_resolution() {
    for (w, h) in [(96, 64), (101, 67)] {
        let f = Owned::synthetic(w, h, 12, 0.5);
        let set = GuideSet::NORMAL_DEPTH_AO;
        let (full, _) = run(cfg(set, 8), &f);
        let e_full = full.iter().zip(&f.clean).map(|(a, b)| (a - b).abs()).sum::<f32>() / full.len() as f32;
        for u in [2, 4] {
            let (lw, lh) = (w.div_ceil(u), h.div_ceil(u));
            let noisy = down(&f.noisy, w, h, 3, u);
            let normal = down(&f.normal, w, h, 3, u);
            let depth = down(&f.depth, w, h, 1, u);
            let ao = down(&f.ao, w, h, 1, u);
            let low = Guides {
                normal: Some(ImageView::interleaved(&normal, lw, lh, 3).unwrap()),
                depth: Some(ImageView::interleaved(&depth, lw, lh, 1).unwrap()),
                ao: Some(ImageView::interleaved(&ao, lw, lh, 1).unwrap()),
                ..Default::default()
            };
            let frame = Frame {
                noisy: ImageView::interleaved(&noisy, lw, lh, 3).unwrap(),
                guides: f.guides(set),
                guides_low: Some(low),
                sample_weights: None,
            };
            let c = FlrConfig { upsample: u, ..cfg(set, 8) };
            let flr = Flr::new(c, w, h).unwrap();
            assert_eq!(flr.input_size(), (lw, lh));
            let (out, _) = run_frame(c, w, h, &frame);
            assert!(out.iter().all(|v| v.is_finite()));
            let e = out.iter().zip(&f.clean).map(|(a, b)| (a - b).abs()).sum::<f32>() / out.len() as f32;
            // fewer samples: somewhat worse than full resolution, but a real reconstruction
            let noisy_err = f.noisy.iter().zip(&f.clean).map(|(a, b)| (a - b).abs()).sum::<f32>() / out.len() as f32;
            assert!(e < 2.5 * e_full && e < 0.5 * noisy_err, "{w}x{h} u{u}: {e} vs full {e_full}, noisy {noisy_err}");
        }
    }
}
