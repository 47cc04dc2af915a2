//! The common shape (`Denoiser`, `TemporalDenoiser`): every method behind the
//! trait gives its own entry point's output bit for bit, sizes its f64
//! scratch, refuses a short one, and reports in the shared `Report`.

mod common;
use common::*;
use lrdenoise::*;

fn same(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Runs `d` through the trait on `frame`; checks a scratch one value short is refused.
fn through_trait(d: &dyn Denoiser, frame: &Frame<'_>) -> (Vec<f32>, Report) {
    let (w, h) = d.size();
    let mut out = vec![f32::NAN; 3 * w * h];
    let mut scratch = vec![f64::NAN; d.scratch_len()];
    let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
    let short = d.scratch_len() - 1;
    assert!(matches!(d.denoise(frame, &mut scratch[..short], &mut ov), Err(Error::ScratchTooSmall { .. })));
    let rep = d.denoise(frame, &mut scratch, &mut ov).unwrap();
    (out, rep)
}

#[test]
fn flr_through_the_trait() {
    for (w, h) in [(1, 1), (7, 3), (257, 40)] {
        let f = Owned::synthetic(w, h, 5, 0.3);
        let cfg = FlrConfig::default();
        let (want, want_rep) = run(cfg, &f);
        let flr = Flr::new(cfg, w, h).unwrap();
        let (got, rep) = through_trait(&flr, &f.frame(cfg.guides));
        assert!(same(&got, &want), "{w}x{h}");
        assert_eq!(rep, want_rep);
    }
}

#[test]
fn bmfr_and_walr_through_the_traits() {
    let (w, h) = (71, 45);
    let f = Owned::synthetic(w, h, 7, 0.3);
    let b = Bmfr::new(BmfrConfig::default(), w, h).unwrap();
    let wl = Walr::new(WalrConfig::default(), w, h).unwrap();
    let methods: [(&dyn TemporalDenoiser, GuideSet); 2] = [(&b, b.config().guides), (&wl, wl.config().guides)];
    for (i, (m, set)) in methods.into_iter().enumerate() {
        let frame = f.frame(set);
        // single frame: frame index 0 of the method's own entry point
        let mut want = vec![0f32; 3 * w * h];
        let mut s32 = vec![0f32; 2 * m.scratch_len()];
        let mut ov = ImageViewMut::interleaved(&mut want, w, h, 3).unwrap();
        let want_rep = if i == 0 { b.denoise(&frame, 0, &mut s32, &mut ov) } else { wl.denoise(&frame, 0, &mut s32, &mut ov) }.unwrap();
        let (got, rep) = through_trait(m, &frame);
        assert!(same(&got, &want), "method {i}");
        assert_eq!(rep, want_rep);
        // three frames of the pipeline, trait against the method's own
        let mut h_want = vec![0f32; m.history_len()];
        let mut h_got = vec![0f32; m.history_len()];
        let (mut hw, mut hg) = (History::new(&mut h_want), History::new(&mut h_got));
        let mut t32 = vec![0f32; 2 * m.temporal_scratch_len()];
        let mut t64 = vec![0f64; m.temporal_scratch_len()];
        for k in 0..3 {
            let mut a = vec![0f32; 3 * w * h];
            let mut c = vec![0f32; 3 * w * h];
            let mut av = ImageViewMut::interleaved(&mut a, w, h, 3).unwrap();
            let ra = if i == 0 {
                b.denoise_temporal(&frame, None, &mut hw, &mut t32, &mut av)
            } else {
                wl.denoise_temporal(&frame, None, &mut hw, &mut t32, &mut av)
            }
            .unwrap();
            let rc = m.denoise_temporal(&frame, None, &mut hg, &mut t64, &mut ImageViewMut::interleaved(&mut c, w, h, 3).unwrap()).unwrap();
            assert!(same(&a, &c), "method {i} frame {k}");
            assert_eq!(ra, rc);
        }
        assert_eq!(hw.frames(), 3);
        assert_eq!(hg.frames(), 3);
        let short = m.temporal_scratch_len() - 1;
        let mut c = vec![0f32; 3 * w * h];
        let e = m.denoise_temporal(&frame, None, &mut hg, &mut t64[..short], &mut ImageViewMut::interleaved(&mut c, w, h, 3).unwrap());
        assert!(matches!(e, Err(Error::ScratchTooSmall { .. })), "{e:?}");
    }
}

#[test]
fn flnr_through_the_trait() {
    let blob = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/train/flnr.bin")).unwrap();
    let (w, h) = (80, 64);
    let f = Owned::synthetic(w, h, 11, 0.3);
    let frame = f.frame(flnr::INPUT_GUIDES);
    for tile in [64, flnr::DEFAULT_TILE] {
        let fl = Flnr::new(FlnrConfig { tile, ..FlnrConfig::new(&blob) }, w, h).unwrap();
        let mut want = vec![0f32; 3 * w * h];
        let mut s32 = vec![0f32; fl.scratch_len()];
        let mut s64 = vec![0f64; fl.flr_scratch_len()];
        let want_rep = fl.denoise(&frame, &mut s32, &mut s64, &mut ImageViewMut::interleaved(&mut want, w, h, 3).unwrap()).unwrap();
        let (got, rep) = through_trait(&fl, &frame);
        assert!(same(&got, &want), "tile {tile}");
        assert_eq!(rep, want_rep);
    }
    assert!(matches!(Flnr::new(FlnrConfig { tile: flnr::MIN_TILE - 1, ..FlnrConfig::new(&blob) }, w, h), Err(Error::InvalidConfig(_))));
}
