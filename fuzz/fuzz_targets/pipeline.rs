//! (b) FLR on arbitrary small frames, configs and strides: output finite, and
//! tiles run in reverse order equal the whole frame bit for bit.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lrdenoise::*;

fuzz_target!(|d: &[u8]| {
    if d.len() < 12 {
        return;
    }
    let w = 1 + d[0] as usize % 40;
    let h = 1 + d[1] as usize % 40;
    let block = [1, 2, 4, 8, 16][d[2] as usize % 5];
    let sigma = 0.5 + d[3] as f32 / 8.0;
    let reg = if d[4] & 1 == 0 {
        Regularization::Normalized { eps_mul: d[5] as f64 * 1e-5, eps_add: 1e-6 + d[6] as f64 * 1e-5 }
    } else {
        Regularization::Tikhonov { eps: 1e-6 + d[6] as f64 * 1e-4 }
    };
    let guides = GuideSet { normal: d[7] & 1 != 0, depth: d[7] & 2 != 0, position: d[7] & 4 != 0, ao: d[7] & 8 != 0, user: 0 };
    let pad = d[8] as usize % 3; // extra elements per pixel (RGBA-like strides)
                                 // the adaptive window (with the AO-free candidate when AO is a guide and
                                 // bit 3 is set) is checked whole-frame only: its staged order is longer
    let adaptive = d[9] & 4 != 0;
    let blur = match (adaptive, d[9] & 1) {
        (true, _) => Blur::Adaptive { sigmas: [sigma, 2.0 * sigma, 3.5 * sigma] },
        (false, 0) => Blur::Gaussian { sigma, radius: None },
        _ => Blur::Box { radius: sigma },
    };
    let cfg = FlrConfig {
        guides,
        block,
        blur,
        regularization: reg,
        kernel: if d[9] & 2 == 0 { Kernel::Simd } else { Kernel::Scalar },
        adaptive_without_ao: adaptive && guides.ao && d[9] & 8 != 0,
        // the AO demodulation (on by default): off, or a tiny offset (s down to 1e-3)
        ao_demodulation: match d[9] >> 4 & 3 {
            1 => None,
            2 => Some(1e-6),
            _ => FlrConfig::default().ao_demodulation,
        },
        // the firefly clamp: default, off, the tightest factor, or a huge one
        fireflies: match d[9] >> 6 {
            1 => None,
            2 => Some(1.0),
            3 => Some(1e6),
            _ => FlrConfig::default().fireflies,
        },
        ..FlrConfig::default()
    };
    let body = &d[12..];
    let val = |i: usize| -> f32 {
        if body.is_empty() {
            return 0.5;
        }
        let b = body[i % body.len()];
        match b {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => -1e30,
            3 => 1e9,
            _ => (b as f32 - 4.0) / 25.0 * if i % 7 == 0 { 1e4 } else { 1.0 },
        }
    };
    let n = w * h;
    let ps3 = 3 + pad;
    let plane = |c: usize, k: usize| -> Vec<f32> { (0..n * k).map(|i| val(i * 31 + c)).collect() };
    let noisy = plane(0, ps3);
    let normal = plane(1, ps3);
    let depth = plane(2, 1);
    let position = plane(3, 3);
    let ao = plane(4, 1);
    let l3 = Layout { offset: 0, pixel_stride: ps3, row_stride: w * ps3, channel_stride: 1 };
    let g = Guides {
        normal: guides.normal.then(|| ImageView::f32(&normal, w, h, 3, l3).unwrap()),
        depth: guides.depth.then(|| ImageView::interleaved(&depth, w, h, 1).unwrap()),
        position: guides.position.then(|| ImageView::interleaved(&position, w, h, 3).unwrap()),
        ao: guides.ao.then(|| ImageView::interleaved(&ao, w, h, 1).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::f32(&noisy, w, h, 3, l3).unwrap(), g);
    let Ok(flr) = Flr::new(cfg, w, h) else { return };
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut whole = vec![0f32; 3 * n];
    flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut whole, w, h, 3).unwrap()).unwrap();
    assert!(whole.iter().all(|v| v.is_finite()));
    if adaptive {
        return;
    }
    // tiled, reverse order
    let p = flr.split_scratch(&mut scratch, 1).unwrap();
    let f = flr.check_frame(&frame).unwrap();
    let mut st = flr.prepare(&f);
    let nt = flr.tile_count();
    let c = |t: usize| flr.cells_tile_range(t).unwrap();
    let m = |t: usize| flr.models_tile_range(t).unwrap();
    for t in (0..nt).rev() {
        flr.moments_tile(&f, &st, t, &mut p.cells[c(t)], p.workers).unwrap();
    }
    flr.finish_stats(p.cells, &mut st).unwrap();
    for t in (0..nt).rev() {
        flr.blur_rows_tile(t, p.cells, &mut p.tmp[c(t)]).unwrap();
    }
    for t in (0..nt).rev() {
        flr.blur_cols_tile(t, p.tmp, &mut p.cells[c(t)]).unwrap();
        flr.solve_tile(&st, t, &p.cells[c(t)], &mut p.models[m(t)]).unwrap();
    }
    let mut tiled = vec![0f32; 3 * n];
    let mut ov = ImageViewMut::interleaved(&mut tiled, w, h, 3).unwrap();
    for t in (0..nt).rev() {
        let (y0, y1) = flr.tile_pixel_rows(t).unwrap();
        let mut band = ov.rows(y0, y1 - y0).unwrap();
        flr.apply_tile(&f, &st, t, p.models, p.workers, &mut band).unwrap();
    }
    assert!(whole.iter().zip(&tiled).all(|(a, b)| a.to_bits() == b.to_bits()), "tiled != whole");
});
