//! Bad sizes, strides, lengths and configurations give typed errors.

mod common;
use common::*;
use lrdenoise::*;

#[test]
fn view_validation() {
    let d = vec![0f32; 30];
    assert!(matches!(ImageView::interleaved(&d, 0, 1, 3), Err(Error::InvalidSize { .. })));
    assert!(matches!(ImageView::interleaved(&d, 4, 3, 3), Err(Error::BufferTooSmall { needed: 36, len: 30, .. })));
    assert!(ImageView::interleaved(&d, 5, 2, 3).is_ok());
    let huge = Layout { offset: 0, pixel_stride: usize::MAX / 2 + 1, row_stride: 1, channel_stride: 1 };
    assert!(matches!(ImageView::f32(&d, 3, 1, 1, huge), Err(Error::InvalidStride { .. })));
    assert!(matches!(ImageView::f32(&d, 1, 1, 0, Layout::interleaved(1, 1)), Err(Error::ChannelCount { .. })));
    let mut o = vec![0f32; 30];
    let zero = Layout { offset: 0, pixel_stride: 0, row_stride: 3, channel_stride: 1 };
    assert!(matches!(ImageViewMut::new(SamplesMut::F32(&mut o), 2, 2, 3, zero), Err(Error::InvalidStride { .. })));
}

#[test]
fn config_validation() {
    let bad = [
        FlrConfig { block: 3, ..FlrConfig::default() },
        FlrConfig { upsample: 3, ..FlrConfig::default() },
        FlrConfig { block: 2, upsample: 4, ..FlrConfig::default() },
        FlrConfig { blur: Blur::Gaussian { sigma: f32::NAN, radius: None }, ..FlrConfig::default() },
        FlrConfig { blur: Blur::Gaussian { sigma: -1.0, radius: None }, ..FlrConfig::default() },
        FlrConfig { blur: Blur::Box { radius: 1e9 }, ..FlrConfig::default() },
        FlrConfig { regularization: Regularization::Tikhonov { eps: 0.0 }, ..FlrConfig::default() },
        FlrConfig { regularization: Regularization::Normalized { eps_mul: 0.0, eps_add: 0.0 }, ..FlrConfig::default() },
        FlrConfig { guides: GuideSet { user: 5, ..GuideSet::NONE }, ..FlrConfig::default() },
    ];
    for c in bad {
        assert!(matches!(Flr::new(c, 16, 16), Err(Error::InvalidConfig(_))), "{c:?}");
    }
    assert!(matches!(Flr::new(FlrConfig::default(), 0, 5), Err(Error::InvalidSize { .. })));
    assert!(matches!(Flr::new(FlrConfig::default(), 1 << 20, 5), Err(Error::InvalidSize { .. })));
}

#[test]
fn frame_and_scratch_validation() {
    let f = Owned::synthetic(32, 16, 1, 0.5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let flr = Flr::new(cfg(set, 8), 32, 16).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; 32 * 16 * 3];
    let mut ov = ImageViewMut::interleaved(&mut out, 32, 16, 3).unwrap();
    // scratch too small
    let mut small = vec![0f64; flr.scratch_len() - 1];
    assert!(matches!(flr.denoise(&f.frame(set), &mut small, &mut ov), Err(Error::ScratchTooSmall { .. })));
    // guide set mismatch
    assert_eq!(flr.denoise(&f.frame(GuideSet::NORMAL_DEPTH), &mut scratch, &mut ov).unwrap_err(), Error::GuideMismatch);
    // wrong size
    let g = Owned::synthetic(31, 16, 1, 0.5);
    assert!(matches!(flr.denoise(&g.frame(set), &mut scratch, &mut ov), Err(Error::SizeMismatch { .. })));
    // 2-channel normal
    let mut guides = f.guides(set);
    guides.normal = Some(ImageView::f32(&f.normal, 32, 16, 2, Layout::interleaved(32, 3)).unwrap());
    let frame = Frame::new(ImageView::interleaved(&f.noisy, 32, 16, 3).unwrap(), guides);
    assert!(matches!(flr.denoise(&frame, &mut scratch, &mut ov), Err(Error::ChannelCount { expected: 3, got: 2, .. })));
    // guides_low of the wrong size (at upsample 1 it is the fit guide set), and
    // upsampling without guides_low
    let mut fr = f.frame(set);
    let small = Owned::synthetic(16, 8, 1, 0.5);
    fr.guides_low = Some(small.guides(set));
    assert!(matches!(flr.denoise(&fr, &mut scratch, &mut ov), Err(Error::SizeMismatch { arg: Arg::GuideLow, .. })));
    let big = Owned::synthetic(64, 32, 1, 0.5);
    let up = Flr::new(FlrConfig { upsample: 2, ..cfg(set, 8) }, 64, 32).unwrap();
    let mut out2 = vec![0f32; 64 * 32 * 3];
    let mut s2 = vec![0f64; up.scratch_len()];
    let fr = Frame::new(ImageView::interleaved(&f.noisy, 32, 16, 3).unwrap(), big.guides(set));
    let r = up.denoise(&fr, &mut s2, &mut ImageViewMut::interleaved(&mut out2, 64, 32, 3).unwrap());
    assert!(matches!(r, Err(Error::Unsupported(_))));
    // bad tile index / slice length
    let frame = flr.check_frame(&f.frame(set)).unwrap();
    let stats = flr.prepare(&frame);
    let mut w = vec![0f32; flr.worker_len()];
    let mut cells = vec![0f64; 3];
    assert!(matches!(flr.moments_tile(&frame, &stats, 99, &mut cells, &mut w), Err(Error::InvalidTile { .. })));
    assert!(matches!(flr.moments_tile(&frame, &stats, 0, &mut cells, &mut w), Err(Error::InvalidTile { .. })));
    assert!(matches!(flr.finish_stats(&cells, &mut flr.prepare(&frame)), Err(Error::InvalidTile { .. })));
}

/// The branch-free f16 → f32 conversion equals `half`'s on all 65536 inputs.
#[test]
fn f16_conversion_is_exact() {
    for b in 0..=u16::MAX {
        let h = half::f16::from_bits(b);
        let (a, e) = (lrdenoise::image::f16_to_f32(h), h.to_f32());
        assert!(a.to_bits() == e.to_bits() || (a.is_nan() && e.is_nan()), "{b:#06x}: {a} vs {e}");
    }
}
