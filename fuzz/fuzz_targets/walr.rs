//! (f) WALR, single frame, bands and a few temporal frames, on arbitrary
//! small frames, guide sets, iterations, storages and thresholds (NaN/Inf/huge
//! values included): no panic, output finite, bands in reverse order == whole.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lrdenoise::walr::{History, Parts, Storage, Walr, WalrConfig};
use lrdenoise::*;

fuzz_target!(|d: &[u8]| {
    if d.len() < 8 {
        return;
    }
    let w = 1 + d[0] as usize % 60;
    let h = 1 + d[1] as usize % 40;
    let guides = GuideSet { normal: true, position: true, depth: d[2] & 1 != 0, ao: d[2] & 2 != 0, user: 0 };
    let cfg = WalrConfig {
        iterations: 1 + d[3] % 4,
        tracing: d[4] & 1 == 0,
        replace: d[4] & 2 == 0,
        storage: if d[4] & 4 == 0 { Storage::F32 } else { Storage::F16 },
        kernel: if d[4] & 8 == 0 { Kernel::Simd } else { Kernel::Scalar },
        previous_weight: if d[4] & 16 == 0 { 0.0 } else { 0.5 },
        adaptive_blend: d[4] & 32 == 0,
        sdf_step: (d[5] % 5) as f32 * 0.25,
        near: (d[6] % 8) as f32 * 0.005,
        far: (d[6] % 8) as f32 * 0.005 + 0.001 + (d[7] % 8) as f32 * 0.01,
        ..WalrConfig::with_guides(guides)
    };
    let body = &d[8..];
    let val = |i: usize| -> f32 {
        if body.is_empty() {
            return 0.5;
        }
        match body[i % body.len()] {
            0 => f32::NAN,
            1 => f32::NEG_INFINITY,
            2 => 1e30,
            3 => -1e9,
            b => (b as f32 - 4.0) / 25.0 * if i % 5 == 0 { 1e4 } else { 1.0 },
        }
    };
    let n = w * h;
    let plane = |c: usize, k: usize| -> Vec<f32> { (0..n * k).map(|i| val(i * 17 + c)).collect() };
    let (noisy, normal, depth, position, ao, motion) = (plane(0, 3), plane(1, 3), plane(2, 1), plane(3, 3), plane(4, 1), plane(5, 2));
    let g = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: guides.depth.then(|| ImageView::interleaved(&depth, w, h, 1).unwrap()),
        position: Some(ImageView::interleaved(&position, w, h, 3).unwrap()),
        ao: guides.ao.then(|| ImageView::interleaved(&ao, w, h, 1).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), g);
    let Ok(wl) = Walr::new(cfg, w, h) else { return };
    let mut scratch = vec![0f32; wl.temporal_scratch_len()];
    let mut whole = vec![0f32; 3 * n];
    wl.denoise(&frame, 1, &mut scratch, &mut ImageViewMut::interleaved(&mut whole, w, h, 3).unwrap()).unwrap();
    assert!(whole.iter().all(|v| v.is_finite()));

    // the same frame in bands of 7 rows, each stage in reverse band order
    let f = wl.check_frame(&frame).unwrap();
    let prep = wl.prepare(&f, 1);
    let mut banded = vec![0f32; 3 * n];
    {
        let Parts { geo, sdf: [s0, s1], z: [z0, z1] } = wl.parts(&mut scratch).unwrap();
        let (gl, zl) = (wl.geo_row_len(), wl.z_row_len());
        let bands: Vec<(usize, usize)> = (0..h).step_by(7).map(|a| (a, (a + 7).min(h))).rev().collect();
        for &(a, b) in &bands {
            wl.features_rows(&f, &prep, a, &mut geo[a * gl..b * gl], &mut z0[a * zl..b * zl]).unwrap();
        }
        for t in 0..cfg.iterations {
            let (sin, sout, zin, zout) =
                if Walr::buffer_of(t) == 0 { (&*s0, &mut *s1, &*z0, &mut *z1) } else { (&*s1, &mut *s0, &*z1, &mut *z0) };
            for &(a, b) in &bands {
                wl.iterate_rows(t, &prep, a, geo, sin, zin, &mut sout[a * w..b * w], &mut zout[a * zl..b * zl]).unwrap();
            }
        }
        if wl.blends_adaptively() {
            let t = cfg.iterations;
            let (last, prev) = if Walr::buffer_of(t) == 0 { (&mut *z0, &mut *z1) } else { (&mut *z1, &mut *z0) };
            for &(a, b) in &bands {
                wl.fit_rows(a, geo, &last[a * zl..b * zl], &mut prev[a * zl..b * zl]).unwrap();
            }
            for &(a, b) in &bands {
                let mut band = ImageViewMut::interleaved(&mut banded[3 * w * a..3 * w * b], w, b - a, 3).unwrap();
                wl.blend_rows(&prep, a, prev, &mut last[a * zl..b * zl], &mut band).unwrap();
            }
        } else {
            let zr = [&*z0, &*z1];
            for &(a, b) in &bands {
                let mut band = ImageViewMut::interleaved(&mut banded[3 * w * a..3 * w * b], w, b - a, 3).unwrap();
                wl.solve_rows(&prep, a, geo, zr, &mut band).unwrap();
            }
        }
    }
    assert!(whole.iter().zip(&banded).all(|(a, b)| a.to_bits() == b.to_bits()));

    let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
    let mut hist = vec![0f32; wl.history_len()];
    let mut history = History::new(&mut hist);
    for _ in 0..3 {
        wl.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut whole, w, h, 3).unwrap())
            .unwrap();
        assert!(whole.iter().all(|v| v.is_finite()));
    }
});
