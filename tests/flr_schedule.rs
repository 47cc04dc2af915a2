//! FLR's schedule (`flr::schedule`): the stages run tile by tile, in order,
//! on one thread or on an executor's threads, are bit-identical to
//! `Flr::denoise`; every misuse returns `Error::StageOrder` (or an index
//! error) and writes nothing.

mod common;
use common::*;
use lrdenoise::*;

/// A `for_each(count, f)` executor on `workers` scoped std threads: worker
/// `w` runs the indices `w, w + workers, ...` (interleaved, unlike lrd's
/// contiguous groups: the order must not matter).
fn threads(workers: usize) -> impl Fn(usize, &(dyn Fn(usize, usize) + Sync)) {
    move |count, f| {
        std::thread::scope(|s| {
            for w in 0..workers {
                s.spawn(move || (w..count).step_by(workers).for_each(|i| f(i, w)));
            }
        });
    }
}

fn configs() -> Vec<FlrConfig> {
    let all = GuideSet { normal: true, depth: true, ao: true, ..GuideSet::NONE };
    let d = FlrConfig::with_guides(all);
    vec![
        d,
        FlrConfig { blur: Blur::Gaussian { sigma: 12.0, radius: None }, ..d },
        FlrConfig { adaptive_without_ao: true, ..d },
        FlrConfig { block: 2, ..d },
        FlrConfig { blur: Blur::Box { radius: 9.0 }, block: 4, ..d },
        FlrConfig::with_guides(GuideSet::NONE),
    ]
}

#[test]
fn parallel_equals_whole_frame() {
    for (w, h) in [(1, 1), (7, 3), (255, 37), (256, 40), (257, 71)] {
        let f = Owned::synthetic(w, h, 3 + w as u64, 0.3);
        for cfg in configs() {
            let (want, want_rep) = run(cfg, &f);
            let flr = Flr::new(cfg, w, h).unwrap();
            for workers in [1, 3] {
                let mut scratch = vec![f64::NAN; flr.tiled_scratch_len(workers).unwrap()];
                let mut out = vec![0f32; 3 * w * h];
                let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                let rep = flr.denoise_parallel(&f.frame(cfg.guides), &mut scratch, &mut ov, workers, &threads(workers)).unwrap();
                assert_eq!(rep, want_rep, "{w}x{h} {cfg:?}");
                assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "{w}x{h} workers {workers} {cfg:?}");
            }
        }
    }
}

#[test]
fn parallel_refuses_what_it_cannot_do() {
    let (w, h) = (40, 100);
    let f = Owned::synthetic(w, h, 1, 0.3);
    let cfg = configs()[0];
    let flr = Flr::new(cfg, w, h).unwrap();
    assert!(flr.tile_count() > 1);
    let mut scratch = vec![0f64; flr.tiled_scratch_len(2).unwrap()];
    let mut out = vec![0f32; 3 * w * h];
    let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
    let short = scratch.len() - 1;
    let e = flr.denoise_parallel(&f.frame(cfg.guides), &mut scratch[..short], &mut ov, 2, &threads(2));
    assert!(matches!(e, Err(Error::ScratchTooSmall { .. })), "{e:?}");
    assert!(matches!(flr.denoise_parallel(&f.frame(cfg.guides), &mut scratch, &mut ov, 0, &threads(1)), Err(Error::InvalidConfig(_))));
    // an executor that forgets tiles is caught, not answered with a partial output
    let lazy = |count: usize, f: &(dyn Fn(usize, usize) + Sync)| (0..count.saturating_sub(1)).for_each(|i| f(i, 0));
    let e = flr.denoise_parallel(&f.frame(cfg.guides), &mut scratch, &mut ov, 2, &lazy);
    assert!(matches!(e, Err(Error::StageOrder { .. })), "{e:?}");
    // planar output: rows interleave with the other planes' rows
    let mut planar = vec![0f32; 3 * w * h];
    let mut pv = ImageViewMut::new(SamplesMut::F32(&mut planar), w, h, 3, Layout::planar(w, h)).unwrap();
    let e = flr.denoise_parallel(&f.frame(cfg.guides), &mut scratch, &mut pv, 2, &threads(2));
    assert!(matches!(e, Err(Error::Unsupported(_))), "{e:?}");
}

#[test]
fn stages_out_of_order_are_refused() {
    let (w, h) = (61, 43);
    let f = Owned::synthetic(w, h, 9, 0.3);
    let cfg = configs()[0];
    let (want, _) = run(cfg, &f);
    let flr = Flr::new(cfg, w, h).unwrap();
    let frame = f.frame(cfg.guides);
    let cf = flr.check_frame(&frame).unwrap();
    let mut scratch = vec![0f64; flr.tiled_scratch_len(2).unwrap()];
    let tiled = flr.tiled(&mut scratch, 2).unwrap();
    let mut out = vec![0f32; 3 * w * h];
    let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
    let nt = flr.tile_count();
    let order = |r: Result<Report, Error>| matches!(r, Err(Error::StageOrder { .. }));
    let mut run = |stage: Stage, t: usize, worker: usize| {
        if stage == Stage::Apply {
            let (y0, y1) = flr.tile_pixel_rows(t).unwrap();
            tiled.run(&cf, stage, t, worker, Some(&mut ov.rows(y0, y1 - y0).unwrap()))
        } else {
            tiled.run(&cf, stage, t, worker, None)
        }
    };
    assert!(order(run(Stage::Moments, 0, 0)), "before Prepare");
    assert!(order(run(Stage::Apply, 0, 0)), "before Prepare");
    run(Stage::Prepare, 0, 0).unwrap();
    assert!(order(run(Stage::Apply, 0, 0)), "Apply before its models");
    assert!(matches!(run(Stage::Moments, nt, 0), Err(Error::InvalidTile { .. })));
    assert!(matches!(run(Stage::Moments, 0, 2), Err(Error::InvalidTile { .. })));
    assert!(matches!(run(Stage::Stats, 1, 0), Err(Error::InvalidTile { .. })));
    for t in 0..nt {
        run(Stage::Moments, t, t % 2).unwrap();
    }
    assert!(order(run(Stage::Moments, 0, 0)), "a tile twice");
    for stage in [Stage::Stats, Stage::BlurRows, Stage::BlurColsSolve] {
        for t in 0..flr.stage_tiles(stage) {
            run(stage, t, 0).unwrap();
        }
    }
    assert!(order(run(Stage::Apply, 0, 0)), "Apply without Blend");
    for t in 0..nt {
        run(Stage::Blend, t, 1).unwrap();
    }
    assert!(tiled.completed(Stage::Blend) && !tiled.completed(Stage::Apply));
    for t in (0..nt).rev() {
        run(Stage::Apply, t, 0).unwrap();
    }
    assert!(tiled.completed(Stage::Apply));
    assert!(order(run(Stage::Apply, 0, 0)), "the frame is done");
    assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "stages one by one != denoise");
    // a Tiled of another worker count over the same memory is another plan
    let tiled1 = flr.tiled(&mut scratch, 1).unwrap();
    assert!(order(tiled1.run(&cf, Stage::Moments, 0, 0, None)));
}

#[test]
fn stage_numbers_are_the_run_order() {
    for (i, s) in Stage::ALL.iter().enumerate() {
        assert_eq!(s.index(), i);
        assert_eq!(Stage::from_index(i), Some(*s));
    }
    assert!(Stage::ALL.windows(2).all(|p| p[0] < p[1]));
    assert_eq!(Stage::from_index(7), None);
    let flr = Flr::new(FlrConfig::default(), 100, 70).unwrap();
    assert_eq!(flr.stage_tiles(Stage::Prepare), 1);
    assert_eq!(flr.stage_tiles(Stage::Stats), 1);
    assert_eq!(flr.stage_tiles(Stage::Apply), flr.tile_count());
}

#[test]
fn outputs_whose_elements_overlap_are_refused() {
    let (w, h) = (5, 4);
    assert!(Layout::interleaved(w, 3).elements_distinct(w, h, 3));
    assert!(Layout::planar(w, h).elements_distinct(w, h, 3));
    let rgba_rows_padded = Layout { offset: 0, pixel_stride: 4, row_stride: 4 * w + 3, channel_stride: 1 };
    assert!(rgba_rows_padded.elements_distinct(w, h, 3));
    let shared_pixels = Layout { offset: 0, pixel_stride: 1, row_stride: 3 * w, channel_stride: 1 };
    let shared_rows = Layout { offset: 0, pixel_stride: 3, row_stride: 3 * w - 3, channel_stride: 1 };
    let planes_overlap = Layout { offset: 0, pixel_stride: 1, row_stride: w, channel_stride: w * h - 1 };
    let mut buf = vec![0f32; 3 * w * h];
    for l in [shared_pixels, shared_rows, planes_overlap] {
        assert!(!l.elements_distinct(w, h, 3), "{l:?}");
        let e = ImageViewMut::new(SamplesMut::F32(&mut buf), w, h, 3, l);
        assert!(matches!(e, Err(Error::InvalidStride { arg: Arg::Output })), "{l:?}");
    }
    // one row, one pixel or one channel: that dimension's stride does not matter
    assert!(Layout { offset: 0, pixel_stride: 3, row_stride: 0, channel_stride: 1 }.elements_distinct(w, 1, 3));
    assert!(Layout { offset: 0, pixel_stride: 0, row_stride: 3, channel_stride: 1 }.elements_distinct(1, h, 3));
}

/// The GPU's dispatches follow the CPU's stage order: frame-wide passes in
/// `Stage` order, each window's blur and solve in order between Stats and
/// Blend, every stage that does work present (Blend with the adaptive window only).
#[test]
fn gpu_passes_follow_the_stage_order() {
    use lrdenoise::flr::gpu::GpuPlan;
    let all = GuideSet { normal: true, depth: true, ao: true, ..GuideSet::NONE };
    let d = FlrConfig::with_guides(all);
    let configs = [
        d,
        FlrConfig { adaptive_without_ao: true, ..d },
        FlrConfig { blur: Blur::Gaussian { sigma: 12.0, radius: None }, ..d },
        FlrConfig { blur: Blur::Adaptive { sigmas: [2.0, 3.0, 4.0] }, block: 4, ..d },
    ];
    for cfg in configs {
        let plan = GpuPlan::new(cfg, 301, 173).unwrap();
        let passes = plan.passes();
        let windows = cfg.blur.scale_count();
        for s in 0..windows {
            let seq: Vec<Stage> = passes.iter().filter(|p| p.window as usize == s || !is_window_stage(p.stage)).map(|p| p.stage).collect();
            assert!(seq.windows(2).all(|w| w[0] <= w[1]), "window {s}: {seq:?} ({cfg:?})");
        }
        for stage in Stage::ALL {
            let present = passes.iter().any(|p| p.stage == stage);
            assert_eq!(present, stage != Stage::Blend || windows > 1, "{stage:?} ({cfg:?})");
        }
        for s in 0..windows {
            assert!(passes.iter().any(|p| p.window as usize == s && p.stage == Stage::BlurRows));
            assert!(passes.iter().any(|p| p.window as usize == s && p.stage == Stage::BlurColsSolve));
        }
        assert_eq!(passes.first().unwrap().stage, Stage::Prepare);
        assert_eq!(passes.last().unwrap().stage, Stage::Apply);
    }
}

fn is_window_stage(s: Stage) -> bool {
    matches!(s, Stage::BlurRows | Stage::BlurColsSolve)
}
