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

/// `denoise_parallel` through the trait equals `denoise` bit for bit for
/// every method, on real threads, at awkward sizes; an executor that breaks
/// its contract (skips a tile, runs one twice) gets an error, not a wrong or
/// racy output.
#[test]
fn parallel_through_the_trait_equals_one_thread() {
    let blob = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/train/flnr.bin")).unwrap();
    for (w, h) in [(1, 1), (7, 3), (130, 97), (257, 71)] {
        let f = Owned::synthetic(w, h, 3 + w as u64, 0.3);
        let flr = Flr::new(FlrConfig::default(), w, h).unwrap();
        let bmfr = Bmfr::new(BmfrConfig::default(), w, h).unwrap();
        let walr = Walr::new(WalrConfig::default(), w, h).unwrap();
        let fl = (w >= flnr::MIN_TILE).then(|| Flnr::new(FlnrConfig { tile: 64, ..FlnrConfig::new(&blob) }, w, h).unwrap());
        let mut methods: Vec<(&dyn Denoiser, GuideSet, &str)> =
            vec![(&flr, flr.config().guides, "flr"), (&bmfr, bmfr.config().guides, "bmfr"), (&walr, walr.config().guides, "walr")];
        if let Some(fl) = &fl {
            methods.push((fl, flnr::INPUT_GUIDES, "flnr"));
        }
        for (m, set, name) in methods {
            let frame = f.frame(set);
            let (want, want_rep) = through_trait(m, &frame);
            for workers in [1, 3] {
                let mut out = vec![f32::NAN; 3 * w * h];
                let mut scratch = vec![f64::NAN; m.parallel_scratch_len(workers).unwrap()];
                let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                let rep = m.denoise_parallel(&frame, &mut scratch, &mut ov, workers, &threads(workers)).unwrap();
                assert!(same(&out, &want), "{name} {w}x{h} workers {workers}");
                assert_eq!(rep, want_rep, "{name} {w}x{h}");
            }
            if h < 64 {
                continue; // a stage of one tile runs without the executor
            }
            let mut scratch = vec![0f64; m.parallel_scratch_len(2).unwrap()];
            let mut out = vec![0f32; 3 * w * h];
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            let skips = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| (1..n).for_each(|i| f(i, 0));
            let twice = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| (0..n).chain(0..1).for_each(|i| f(i, 0));
            for (e, what) in [(&skips as Executor<'_>, "skips"), (&twice, "twice")] {
                let r = m.denoise_parallel(&frame, &mut scratch, &mut ov, 2, e);
                assert!(r.is_err(), "{name} {w}x{h}: an executor that {what} was not refused");
            }
        }
    }
}

/// Per-pixel sample weights are single-frame FLR's: FLNR, BMFR and WALR
/// refuse a frame that has them, through the trait, as `Unsupported`.
#[test]
fn sample_weights_are_refused_where_unsupported() {
    let blob = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/train/flnr.bin")).unwrap();
    let (w, h) = (40, 24);
    let f = Owned::synthetic(w, h, 13, 0.3);
    let ones = vec![1f32; w * h];
    let b = Bmfr::new(BmfrConfig::default(), w, h).unwrap();
    let wl = Walr::new(WalrConfig::default(), w, h).unwrap();
    let fl = Flnr::new(FlnrConfig::new(&blob), w, h).unwrap();
    let methods: [(&dyn Denoiser, GuideSet); 3] = [(&b, b.config().guides), (&wl, wl.config().guides), (&fl, flnr::INPUT_GUIDES)];
    for (i, (m, set)) in methods.into_iter().enumerate() {
        let mut frame = f.frame(set);
        frame.sample_weights = Some(ImageView::interleaved(&ones, w, h, 1).unwrap());
        let mut out = vec![0f32; 3 * w * h];
        let mut scratch = vec![0f64; m.scratch_len()];
        let e = m.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap());
        assert!(matches!(e, Err(Error::Unsupported(_))), "method {i}: {e:?}");
    }
}
