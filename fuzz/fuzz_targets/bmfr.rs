//! (e) BMFR, single frame and a few temporal frames, on arbitrary small frames,
//! block sizes, guide sets, grid offsets and motion (NaN/Inf/huge values
//! included): no panic, output finite, tiles in reverse order == whole frame.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lrdenoise::*;

fuzz_target!(|d: &[u8]| {
    if d.len() < 8 {
        return;
    }
    let w = 1 + d[0] as usize % 70;
    let h = 1 + d[1] as usize % 50;
    let block = 8 + d[2] as usize % 57;
    let guides = GuideSet { normal: d[3] & 1 != 0, depth: d[3] & 2 != 0, position: d[3] & 4 != 0, ao: d[3] & 8 != 0, user: 0 };
    let index = d[4] as u32;
    // bits 3..4 of d[5]: the shrinkage (off, the default, or strong)
    let shrinkage = [0.0, 4.0, 100.0, 4.0][(d[5] >> 3 & 3) as usize];
    let cfg = BmfrConfig { block, noise: (d[5] % 4) as f32 * 0.01, shift: d[5] & 4 == 0, shrinkage, ..BmfrConfig::with_guides(guides) };
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
        normal: guides.normal.then(|| ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: guides.depth.then(|| ImageView::interleaved(&depth, w, h, 1).unwrap()),
        position: guides.position.then(|| ImageView::interleaved(&position, w, h, 3).unwrap()),
        ao: guides.ao.then(|| ImageView::interleaved(&ao, w, h, 1).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), g);
    let Ok(b) = Bmfr::new(cfg, w, h) else { return };
    let mut scratch = vec![0f32; b.temporal_scratch_len()];
    let mut whole = vec![0f32; 3 * n];
    b.denoise(&frame, index, &mut scratch, &mut ImageViewMut::interleaved(&mut whole, w, h, 3).unwrap()).unwrap();
    assert!(whole.iter().all(|v| v.is_finite()));
    let f = b.check_frame(&frame).unwrap();
    let mut tiled = vec![0f32; 3 * n];
    for t in (0..b.tile_count(index)).rev() {
        let (y0, y1) = b.tile_pixel_rows(index, t).unwrap();
        let mut band = ImageViewMut::interleaved(&mut tiled[3 * w * y0..3 * w * y1], w, y1 - y0, 3).unwrap();
        b.fit_tile(&f, index, t, &mut scratch, &mut band).unwrap();
    }
    assert!(whole.iter().zip(&tiled).all(|(a, b)| a.to_bits() == b.to_bits()));
    let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
    let mut hist = vec![0f32; b.history_len()];
    let mut history = History::new(&mut hist);
    for _ in 0..3 {
        b.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ImageViewMut::interleaved(&mut whole, w, h, 3).unwrap())
            .unwrap();
        assert!(whole.iter().all(|v| v.is_finite()));
    }
});
