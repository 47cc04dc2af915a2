//! The temporal stage (`lrdenoise::temporal`) and temporal FLR over sequences
//! of synthetic frames: a static camera converges to the multi-sample result,
//! a disoccluded pixel restarts from its own sample, a cut resets, bad motion
//! is rejected and counted, a burst of fireflies is gone within 2 frames,
//! outliers too common for one frame's clamp are clamped with the previous
//! frame's evidence, a history of another size is refused, the parallel
//! run gives the same bits, a moving object restarts where world positions
//! judge the taps, an object entering the view leaves no ghost in any
//! temporal pipeline, and temporal FLR on moments follows light that changes.

mod common;
use common::*;
use lrdenoise::flr::moment_history::MomentFlr;
use lrdenoise::flr::temporal::TemporalFlr;
use lrdenoise::temporal::{History, Inputs, Reprojection, TemporalConfig};
use lrdenoise::*;

const SET: GuideSet = GuideSet::NORMAL_DEPTH_AO;

/// Frame `t` of a static sequence: the same guides and clean light, fresh
/// zero-mean noise (uniform, ±80 %).
fn frame_at(w: usize, h: usize, t: u64) -> Owned {
    let mut f = Owned::synthetic(w, h, 3, 0.5);
    let mut rng = Rng(0x9e37_79b9 ^ (t + 1).wrapping_mul(0x2545_f491_4f6c_dd1d));
    for (n, c) in f.noisy.iter_mut().zip(&f.clean) {
        *n = c * (1.0 + 0.8 * (2.0 * rng.f32() - 1.0));
    }
    f
}

struct Seq {
    plan: TemporalFlr,
    history: Vec<f32>,
    frames: u32,
    scratch: Vec<f32>,
    flr_scratch: Vec<f64>,
}

impl Seq {
    fn new(cfg: FlrConfig, t: TemporalConfig, w: usize, h: usize) -> Seq {
        let plan = TemporalFlr::new(cfg, t, w, h).unwrap();
        Seq {
            history: vec![0.0; plan.history_len()],
            scratch: vec![f32::NAN; plan.parallel_scratch_len(3)],
            flr_scratch: vec![f64::NAN; plan.parallel_flr_scratch_len(3)],
            plan,
            frames: 0,
        }
    }
    fn next(&mut self, f: &Owned, motion: Option<&[f32]>, threads: usize) -> (Vec<f32>, Report) {
        let (w, h) = (f.w, f.h);
        let mut out = vec![f32::NAN; 3 * w * h];
        let mv = motion.map(|m| ImageView::interleaved(m, w, h, 2).unwrap());
        let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
        let mut history = History::resume(&mut self.history, self.frames);
        let frame = f.frame(SET);
        let rep = if threads > 1 {
            let exec = |n: usize, body: &(dyn Fn(usize, usize) + Sync)| {
                std::thread::scope(|s| {
                    for wk in 0..threads {
                        s.spawn(move || (wk..n).step_by(threads).for_each(|i| body(i, wk)));
                    }
                })
            };
            self.plan.denoise_parallel(&frame, mv.as_ref(), &mut history, &mut self.scratch, &mut self.flr_scratch, &mut ov, threads, &exec)
        } else {
            self.plan.denoise(&frame, mv.as_ref(), &mut history, &mut self.scratch, &mut self.flr_scratch, &mut ov)
        }
        .unwrap();
        self.frames = history.frames();
        assert!(out.iter().all(|v| v.is_finite()));
        (out, rep)
    }
}

fn cfg() -> FlrConfig {
    FlrConfig::with_guides(SET)
}

fn flr_of(noisy: &[f32], like: &Owned) -> Vec<f32> {
    let mut f = like.clone();
    f.noisy = noisy.to_vec();
    run(FlrConfig { fireflies: None, ..cfg() }, &f).0
}

fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let mse = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / a.len() as f64;
    -10.0 * mse.log10()
}

/// With a static camera and no output accumulation, frame n's output is FLR
/// on the mean of the n noisy frames (up to the rounding of a running mean),
/// and it beats per-frame FLR.
#[test]
fn static_camera_converges_to_the_multi_sample_result() {
    let (w, h) = (64, 40);
    let t = TemporalConfig { output_alpha: 1.0, ..Default::default() };
    let mut seq = Seq::new(FlrConfig { fireflies: None, ..cfg() }, t, w, h);
    let zero = vec![0f32; 2 * w * h];
    let mut sum = vec![0f64; 3 * w * h];
    let n = 8;
    let (mut out, mut last) = (vec![], frame_at(w, h, 0));
    for k in 0..n {
        let f = frame_at(w, h, k);
        (out, _) = seq.next(&f, Some(&zero), 1);
        for (s, v) in sum.iter_mut().zip(&f.noisy) {
            *s += *v as f64;
        }
        last = f;
    }
    let mean: Vec<f32> = sum.iter().map(|s| (s / n as f64) as f32).collect();
    let want = flr_of(&mean, &last);
    let worst = out.iter().zip(&want).map(|(a, b)| (a - b).abs() / b.abs().max(0.05)).fold(0f32, f32::max);
    assert!(worst < 1e-3, "temporal FLR vs FLR on the mean of {n} frames: relative error {worst}");
    let per_frame = flr_of(&last.noisy, &last);
    let (gain, p) = (psnr(&out, &last.clean), psnr(&per_frame, &last.clean));
    let pm = psnr(&mean, &last.clean);
    let pn = psnr(&last.noisy, &last.clean);
    assert!(gain > p + 3.0, "{n} frames: {gain:.2} dB against per-frame {p:.2} dB (mean {pm:.2}, noisy {pn:.2})");
}

/// Without output accumulation `run_frame` skips step 3 and the fit writes the
/// output: bit for bit what the steps called one by one give (step 3 then
/// copies the fit's output), over a pan with a disocclusion, on one thread
/// and on two; the frame counter and every history field but the previous
/// output's (which only step 3 writes) too, with 6 values per pixel less
/// scratch than with the accumulation.
#[test]
fn without_output_accumulation_the_fit_is_the_output() {
    let (w, h) = (37, 19);
    let st = Reprojection::new(TemporalConfig { output_alpha: 1.0, ..Default::default() }, SET, w, h).unwrap();
    assert!(!st.accumulates_output());
    // no previous output gathered and no fitted image kept: 6 values per pixel less scratch
    let with = Reprojection::new(TemporalConfig::default(), SET, w, h).unwrap();
    assert_eq!(with.scratch_len(), st.scratch_len() + 3 * w * h);
    assert_eq!(with.frame_scratch_len(None), st.frame_scratch_len(None).map(|n| n + 6 * w * h));
    assert_eq!(with.frame_scratch_len(Some(2)), st.frame_scratch_len(Some(2)).map(|n| n + 6 * w * h));
    let (mut ha, mut hb, mut hc) = (vec![0f32; st.history_len()], vec![0f32; st.history_len()], vec![0f32; st.history_len()]);
    let mut sa = vec![f32::NAN; st.frame_scratch_len(None).unwrap()];
    let mut sb = vec![f32::NAN; st.scratch_len()];
    let mut sc = vec![f32::NAN; st.frame_scratch_len(Some(2)).unwrap()];
    let exec = |n: usize, body: &(dyn Fn(usize, usize) + Sync)| {
        std::thread::scope(|s| {
            for wk in 0..2 {
                s.spawn(move || (wk..n).step_by(2).for_each(|i| body(i, wk)));
            }
        })
    };
    // the record's fields of each history value (row y, field f, pixel x at (y · rec + f) · w + x, two slots)
    let rec = st.slot_len() / (w * h);
    let field = |i: usize| (i % st.slot_len()) / w % rec;
    // the fit: half the accumulated light plus a ramp, clamped at 0 (as the methods clamp)
    let fit = |acc: &ImageView<'_>, o: &mut ImageViewMut<'_>| {
        for y in 0..h {
            for c in 0..3 {
                let row: Vec<f32> = (0..w).map(|x| (0.5 * acc.get(x, y, c).unwrap() + 0.01 * x as f32 - 0.1).max(0.0)).collect();
                o.write_row(y, c, 0, &row).unwrap();
            }
        }
    };
    let mv: Vec<f32> = (0..w * h).flat_map(|i| [if i % w < 3 { -5.0 } else { 1.25 }, 0.5]).collect();
    for k in 0..3u32 {
        let f = frame_at(w, h, k as u64);
        let (noisy, motion) = (ImageView::interleaved(&f.noisy, w, h, 3).unwrap(), ImageView::interleaved(&mv, w, h, 2).unwrap());
        let guides = f.guides(SET);
        let mut a = vec![f32::NAN; 3 * w * h];
        {
            let mut history = History::resume(&mut ha, k);
            let mut ov = ImageViewMut::interleaved(&mut a, w, h, 3).unwrap();
            st.run_frame(noisy, guides, Some(motion), Some(4.0), true, &mut history, &mut sa, None, &mut ov, |acc, _, _, o| {
                fit(&acc, o);
                Ok(Report::default())
            })
            .unwrap();
            assert_eq!(history.frames(), k + 1);
        }
        let mut c = vec![f32::NAN; 3 * w * h];
        {
            let mut history = History::resume(&mut hc, k);
            let mut ov = ImageViewMut::interleaved(&mut c, w, h, 3).unwrap();
            st.run_frame(noisy, guides, Some(motion), Some(4.0), true, &mut history, &mut sc, Some((2, &exec)), &mut ov, |acc, _, _, o| {
                fit(&acc, o);
                Ok(Report::default())
            })
            .unwrap();
        }
        let mut b = vec![f32::NAN; 3 * w * h];
        {
            let mut history = History::resume(&mut hb, k);
            let inputs = Inputs { noisy, fireflies: Some(4.0), guides, motion: Some(motion) };
            let c = st.accumulate(&inputs, &mut history, &mut sb).unwrap();
            let mut fitted = vec![0f32; 3 * w * h];
            fit(&st.accumulated(&mut history).unwrap(), &mut ImageViewMut::interleaved(&mut fitted, w, h, 3).unwrap());
            let mut ov = ImageViewMut::interleaved(&mut b, w, h, 3).unwrap();
            st.resolve(&fitted, &mut history, &mut sb, c.cut != 0, true, &mut ov).unwrap();
            assert_eq!(history.frames(), k + 1);
        }
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()), "frame {k}");
        assert!(a.iter().zip(&c).all(|(x, y)| x.to_bits() == y.to_bits()), "frame {k}, two threads");
        // fields 4..7 are the previous output's
        let same =
            |x: &[f32], y: &[f32]| x.iter().zip(y).enumerate().all(|(i, (x, y))| (4..7).contains(&field(i)) || x.to_bits() == y.to_bits());
        assert!(same(&ha, &hb) && same(&ha, &hc), "frame {k}: the history");
    }
}

/// The stage on its own: a pixel whose motion leaves the frame has no history
/// and restarts from its own sample (count 1); the others average.
#[test]
fn disoccluded_pixels_restart_from_their_own_sample() {
    let (w, h) = (23, 9);
    let st = Reprojection::new(TemporalConfig::default(), SET, w, h).unwrap();
    let mut hist = vec![0f32; st.history_len()];
    let mut scratch = vec![0f32; st.scratch_len()];
    let mut history = History::new(&mut hist);
    let f0 = frame_at(w, h, 0);
    let f1 = frame_at(w, h, 1);
    // frame 1: the left 5 columns point outside the frame, the rest stay put
    let mv: Vec<f32> = (0..w * h).flat_map(|i| if i % w < 5 { [-10.0, 0.0] } else { [0.0, 0.0] }).collect();
    for (f, m) in [(&f0, None), (&f1, Some(&mv[..]))] {
        let inp = Inputs {
            noisy: ImageView::interleaved(&f.noisy, w, h, 3).unwrap(),
            fireflies: None,
            guides: f.guides(SET),
            motion: m.map(|m| ImageView::interleaved(m, w, h, 2).unwrap()),
        };
        let c = st.accumulate(&inp, &mut history, &mut scratch).unwrap();
        if m.is_some() {
            assert_eq!(c.rejected, 5 * h as u64);
            assert_eq!(c.cut, 0);
            let acc = st.accumulated(&mut history).unwrap();
            for y in 0..h {
                for x in 0..w {
                    for c in 0..3 {
                        let i = 3 * (y * w + x) + c;
                        let want = if x < 5 { f1.noisy[i] } else { 0.5 * (f0.noisy[i] + f1.noisy[i]) };
                        let got = acc.get(x, y, c).unwrap();
                        assert!((got - want).abs() <= 1e-6 * want.abs().max(1.0), "({x},{y}) c{c}: {got} vs {want}");
                    }
                }
            }
        }
        let current = vec![0.25f32; 3 * w * h];
        let mut out = vec![0f32; 3 * w * h];
        st.resolve(&current, &mut history, &mut scratch, c.cut != 0, true, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap())
            .unwrap();
    }
}

/// With world positions among the rejection guides a tap is judged by where
/// it is: an object that moves (its positions shifted by 10 % of the depth,
/// its depths unchanged) restarts, while judged by depth alone it keeps its
/// history. Two frames of a still camera whose left third moves (below the
/// cut's half, so the frame is no cut).
#[test]
fn with_positions_a_moving_object_restarts() {
    let (w, h) = (24, 10);
    let f0 = frame_at(w, h, 0);
    let mut f1 = frame_at(w, h, 1);
    for i in (0..w * h).filter(|i| i % w < w / 3) {
        f1.position[3 * i] += 0.1 * f1.depth[i];
    }
    let zero = vec![0f32; 2 * w * h];
    for (set, rejected) in [(GuideSet { position: true, ..GuideSet::NORMAL_DEPTH }, (w / 3 * h) as u64), (GuideSet::NORMAL_DEPTH, 0)] {
        let st = Reprojection::new(TemporalConfig::default(), set, w, h).unwrap();
        let mut hist = vec![0f32; st.history_len()];
        let mut scratch = vec![0f32; st.scratch_len()];
        let mut history = History::new(&mut hist);
        for (f, m) in [(&f0, None), (&f1, Some(&zero[..]))] {
            let inp = Inputs {
                noisy: ImageView::interleaved(&f.noisy, w, h, 3).unwrap(),
                fireflies: None,
                guides: f.guides(set),
                motion: m.map(|m| ImageView::interleaved(m, w, h, 2).unwrap()),
            };
            let c = st.accumulate(&inp, &mut history, &mut scratch).unwrap();
            if m.is_some() {
                assert_eq!((c.rejected, c.cut), (rejected, 0), "{set:?}");
            }
            let mut out = vec![0f32; 3 * w * h];
            let current = vec![0.25f32; 3 * w * h];
            st.resolve(&current, &mut history, &mut scratch, c.cut != 0, true, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap())
                .unwrap();
        }
    }
}

/// The fit weighed by history length (`TemporalFlr::with_history_weights`):
/// where every pixel has the same history (a static camera) it equals the
/// unweighted fit to rounding (without the firefly clamp); after a disocclusion (left columns restart at
/// 1, the rest hold 2, as `Reprojection::history_lengths` says) it differs;
/// and a frame that brings its own `Frame::sample_weights` is refused.
#[test]
fn history_weights_weigh_the_fit_by_history_length() {
    let (w, h) = (40, 24);
    let f: Vec<Owned> = (0..3).map(|t| frame_at(w, h, t)).collect();
    let mv: Vec<f32> = (0..w * h).flat_map(|i| if i % w < 8 { [-100.0, 0.0] } else { [0.0, 0.0] }).collect();
    let run = |weights: bool, motion: Option<&[f32]>| {
        // (without the firefly clamp, whose clamped samples count as less than one)
        let mut seq = Seq::new(FlrConfig { fireflies: None, ..cfg() }, TemporalConfig::default(), w, h);
        seq.plan = seq.plan.clone().with_history_weights(weights);
        assert_eq!(seq.plan.history_weights(), weights);
        (0..3).map(|t| seq.next(&f[t], if t == 0 { None } else { motion }, 1).0).last().unwrap()
    };
    // (Seq::next asserts every output finite)
    let rel = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs() / (1e-3 + y.abs())).fold(0f32, f32::max);
    let (plain, weighed) = (run(false, None), run(true, None));
    assert!(rel(&weighed, &plain) < 1e-3, "static: {}", rel(&weighed, &plain));
    let (plain, weighed) = (run(false, Some(&mv)), run(true, Some(&mv)));
    assert!(rel(&weighed, &plain) > 1e-3, "a disocclusion: the weights changed nothing");

    // the history lengths the weights are
    let st = Reprojection::new(TemporalConfig::default(), SET, w, h).unwrap();
    let (mut hist, mut scratch) = (vec![0f32; st.history_len()], vec![0f32; st.scratch_len()]);
    let mut history = History::new(&mut hist);
    for (t, m) in [(0, None), (1, Some(&mv[..]))] {
        let inp = Inputs {
            noisy: ImageView::interleaved(&f[t].noisy, w, h, 3).unwrap(),
            fireflies: None,
            guides: f[t].guides(SET),
            motion: m.map(|m| ImageView::interleaved(m, w, h, 2).unwrap()),
        };
        st.accumulate(&inp, &mut history, &mut scratch).unwrap();
        if t == 1 {
            let n = st.history_lengths(&mut history).unwrap();
            for (x, y) in [(0, 0), (7, 23), (8, 0), (39, 23)] {
                assert_eq!(n.get(x, y, 0).unwrap(), if x < 8 { 1.0 } else { 2.0 }, "({x}, {y})");
            }
        }
        let mut out = vec![0f32; 3 * w * h];
        st.resolve(
            &vec![0.25f32; 3 * w * h],
            &mut history,
            &mut scratch,
            false,
            true,
            &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap(),
        )
        .unwrap();
    }

    let plan = TemporalFlr::new(cfg(), TemporalConfig::default(), w, h).unwrap();
    let (mut hist, mut scratch, mut flr_scratch) =
        (vec![0f32; plan.history_len()], vec![0f32; plan.scratch_len()], vec![0f64; plan.flr_scratch_len()]);
    let ones = vec![1f32; w * h];
    let mut frame = f[0].frame(SET);
    frame.sample_weights = Some(ImageView::interleaved(&ones, w, h, 1).unwrap());
    let mut out = vec![0f32; 3 * w * h];
    let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
    let err = plan.denoise(&frame, None, &mut History::new(&mut hist), &mut scratch, &mut flr_scratch, &mut ov).unwrap_err();
    assert!(matches!(err, Error::Unsupported(_)), "{err:?}");
}

/// History taps judged by world position (`TemporalFlr::with_rejection_guides`):
/// a camera that moves towards the scene changes every depth by 10 % while
/// the positions stay: with depth every tap is rejected (a cut), with positions
/// none is, and the fit is FLR's on the same guides either way; a frame
/// without the positions is refused.
#[test]
fn positions_keep_the_history_of_a_camera_moving_closer() {
    let (w, h) = (40, 24);
    let f0 = frame_at(w, h, 0);
    let mut f1 = frame_at(w, h, 1);
    f1.depth.iter_mut().for_each(|d| *d *= 0.9);
    let with_positions = GuideSet { position: true, ..SET };
    let run = |reject: GuideSet, set: GuideSet| {
        let plan = TemporalFlr::new(cfg(), TemporalConfig::default(), w, h).unwrap().with_rejection_guides(reject).unwrap();
        assert_eq!(plan.stage().rejection_guides(), GuideSet { ao: false, ..reject });
        let (mut hist, mut scratch, mut flr_scratch) =
            (vec![0f32; plan.history_len()], vec![0f32; plan.scratch_len()], vec![0f64; plan.flr_scratch_len()]);
        let mut history = History::new(&mut hist);
        let mut out = vec![0f32; 3 * w * h];
        let mut last = Report::default();
        for f in [&f0, &f1] {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            last = plan.denoise(&f.frame(set), None, &mut history, &mut scratch, &mut flr_scratch, &mut ov)?;
        }
        Ok::<_, Error>(last)
    };
    let by_depth = run(SET, SET).unwrap();
    assert_eq!(by_depth.history_resets, 1, "{by_depth:?}");
    let by_position = run(with_positions, with_positions).unwrap();
    assert_eq!((by_position.history_rejected, by_position.history_resets), (0, 0), "{by_position:?}");
    assert!(matches!(run(with_positions, SET), Err(Error::GuideMismatch)));
}

/// Without depth, a tap's position is judged against the pixel's footprint
/// (the distance to its neighbours' positions), so the scene's unit does not
/// matter: a pan over a plane with a step and a block that moves away, its
/// positions in units 1024 times larger or smaller, keeps the same taps and
/// accumulates the same light, bit for bit (a power of two scales both sides
/// exactly). The block's pixels lose their history, the others keep it.
#[test]
fn positions_without_depth_judge_taps_whatever_the_scenes_unit() {
    let (w, h) = (64, 24);
    let set = GuideSet { position: true, ..GuideSet::NONE };
    let st = Reprojection::new(TemporalConfig::default(), set, w, h).unwrap();
    // frame k: the plane (0.01 x, z, 0.01 y) seen 0.4k px right and 0.3k px down, z stepping at
    // x = 32, and in front of it a block of 10 × 4 pixels that moves away by 1 each frame
    let plane = |k: usize, scale: f32| -> Vec<f32> {
        (0..w * h)
            .flat_map(|i| {
                let (x, y) = ((i % w) as f32 + 0.4 * k as f32, (i / w) as f32 + 0.3 * k as f32);
                let block = (10..20).contains(&(i % w)) && (10..14).contains(&(i / w));
                let z = if block {
                    0.5 + k as f32
                } else if x < 32.0 {
                    1.0
                } else {
                    3.0
                };
                [0.01 * x * scale, z * scale, 0.01 * y * scale]
            })
            .collect()
    };
    let motion: Vec<f32> = (0..w * h).flat_map(|_| [0.4f32, 0.3]).collect();
    let run = |scale: f32| {
        let (mut hist, mut scratch) = (vec![0f32; st.history_len()], vec![0f32; st.scratch_len()]);
        let mut history = History::new(&mut hist);
        let mut rejected = Vec::new();
        for k in 0..3 {
            let (f, p) = (frame_at(w, h, k as u64), plane(k, scale));
            let inp = Inputs {
                noisy: ImageView::interleaved(&f.noisy, w, h, 3).unwrap(),
                fireflies: None,
                guides: Guides { position: Some(ImageView::interleaved(&p, w, h, 3).unwrap()), ..Default::default() },
                motion: Some(ImageView::interleaved(&motion, w, h, 2).unwrap()),
            };
            let c = st.accumulate(&inp, &mut history, &mut scratch).unwrap();
            rejected.push(c.rejected);
            let (current, mut out) = (vec![0.25f32; 3 * w * h], vec![0f32; 3 * w * h]);
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            st.resolve(&current, &mut history, &mut scratch, false, true, &mut ov).unwrap();
        }
        let mut acc = vec![0f32; 3 * w * h];
        let view = st.accumulated(&mut history).unwrap();
        for y in 0..h {
            view.read_row_n(y, 0, {
                let (r, rest) = acc.split_at_mut(w * h);
                let (g, b) = rest.split_at_mut(w * h);
                [&mut r[y * w..(y + 1) * w], &mut g[y * w..(y + 1) * w], &mut b[y * w..(y + 1) * w]]
            })
            .unwrap();
        }
        (rejected, acc)
    };
    let (rejected, acc) = run(1.0);
    // frame 0 has no history; then the block's pixels lose theirs, the rest keep it
    assert!((30..=40).contains(&rejected[1]) && (30..=40).contains(&rejected[2]), "{rejected:?}");
    for scale in [1024.0, 1.0 / 1024.0] {
        let (r, a) = run(scale);
        assert_eq!(r, rejected, "scale {scale}");
        assert!(a.iter().zip(&acc).all(|(x, y)| x.to_bits() == y.to_bits()), "scale {scale}: the accumulated light differs");
    }
}

/// Frame 0 then frame 1 of a static sequence through the stage alone, with
/// the firefly clamp; returns frame 1's counts and accumulated light.
fn two_frames(cfg: TemporalConfig, f0: &Owned, f1: &Owned) -> (temporal::Counts, Vec<f32>) {
    let (w, h) = (f0.w, f0.h);
    let st = Reprojection::new(cfg, SET, w, h).unwrap();
    let mut hist = vec![0f32; st.history_len()];
    let mut scratch = vec![0f32; st.scratch_len()];
    let mut history = History::new(&mut hist);
    let mut counts = temporal::Counts::default();
    for f in [f0, f1] {
        let inp = Inputs {
            noisy: ImageView::interleaved(&f.noisy, w, h, 3).unwrap(),
            fireflies: Some(fireflies::DEFAULT_STRENGTH),
            guides: f.guides(SET),
            motion: None,
        };
        counts = st.accumulate(&inp, &mut history, &mut scratch).unwrap();
        if history.frames() == 0 {
            let (current, mut out) = (vec![0.25f32; 3 * w * h], vec![0f32; 3 * w * h]);
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            st.resolve(&current, &mut history, &mut scratch, false, true, &mut ov).unwrap();
        }
    }
    let acc = st.accumulated(&mut history).unwrap();
    let light = (0..w * h).flat_map(|i| (0..3).map(move |c| (i, c))).map(|(i, c)| acc.get(i % w, i / w, c).unwrap()).collect();
    (counts, light)
}

/// Outliers in four cells of one neighbourhood are the third brightest cell
/// themselves, so the clamp of one frame lets them through; capped by what
/// the previous frame held there (`firefly_history`), they are clamped.
#[test]
fn outliers_in_three_cells_are_clamped_with_the_previous_frame() {
    let (w, h) = (64, 16);
    let (f0, mut f1) = (frame_at(w, h, 0), frame_at(w, h, 1));
    let at = [(3, 2), (12, 3), (21, 5), (30, 4)]; // four cells of one band
    for &(x, y) in &at {
        for c in 0..3 {
            f1.noisy[3 * (y * w + x) + c] = 1e3;
        }
    }
    let off = TemporalConfig { firefly_history: 0.0, ..TemporalConfig::default() };
    let (c_off, l_off) = two_frames(off, &f0, &f1);
    let (c_on, l_on) = two_frames(TemporalConfig::default(), &f0, &f1);
    assert_eq!(c_off.clamped, 0, "one frame's evidence: the outliers are its brightest cells");
    assert!(c_on.clamped >= at.len() as u64, "{} clamped", c_on.clamped);
    for &(x, y) in &at {
        let i = 3 * (y * w + x);
        assert!(l_off[i] > 400.0, "unclamped, averaged with one clean frame: {}", l_off[i]);
        assert!(l_on[i] < 4.0, "({x},{y}): {} (the clean frame's light is below 1)", l_on[i]);
    }
}

/// The cap leaves the mean term alone: a frame ten times brighter than the
/// previous one everywhere is clamped exactly as without history.
#[test]
fn light_that_brightens_as_a_whole_passes_the_cap() {
    let (w, h) = (64, 16);
    let (f0, mut f1) = (frame_at(w, h, 0), frame_at(w, h, 1));
    f1.noisy.iter_mut().for_each(|v| *v *= 10.0);
    let off = TemporalConfig { firefly_history: 0.0, ..TemporalConfig::default() };
    let (c_off, l_off) = two_frames(off, &f0, &f1);
    let (c_on, l_on) = two_frames(TemporalConfig::default(), &f0, &f1);
    assert_eq!(c_on.clamped, c_off.clamped);
    assert!(l_on.iter().zip(&l_off).all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// After a black frame, a lit one and a lone firefly on black clamp exactly
/// as without history (the cap is lifted where the light around was black,
/// on every ISA: no NaN decides it).
#[test]
fn after_a_black_frame_the_cap_changes_nothing() {
    let (w, h) = (64, 16);
    let mut black = frame_at(w, h, 0);
    black.noisy.iter_mut().for_each(|v| *v = 0.0);
    let mut firefly = black.clone();
    firefly.noisy[3 * (5 * w + 20)..3 * (5 * w + 21)].fill(1e4);
    let off = TemporalConfig { firefly_history: 0.0, ..TemporalConfig::default() };
    for f1 in [frame_at(w, h, 1), firefly] {
        let (c_off, l_off) = two_frames(off, &black, &f1);
        let (c_on, l_on) = two_frames(TemporalConfig::default(), &black, &f1);
        assert_eq!(c_on.clamped, c_off.clamped);
        assert!(l_on.iter().zip(&l_off).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}

/// A frame whose geometry matches nothing of the previous one is a cut: the
/// history restarts, and the output equals the first frame's of a fresh history.
#[test]
fn a_cut_resets() {
    let (w, h) = (48, 32);
    let mut seq = Seq::new(cfg(), TemporalConfig::default(), w, h);
    let zero = vec![0f32; 2 * w * h];
    for k in 0..3 {
        seq.next(&frame_at(w, h, k), Some(&zero), 1);
    }
    let mut other = frame_at(w, h, 7);
    for d in other.depth.iter_mut() {
        *d *= 3.0;
    }
    let (out, rep) = seq.next(&other, Some(&zero), 1);
    assert_eq!(rep.history_resets, 1);
    assert_eq!(rep.history_rejected, 0, "a cut frame counts no rejections");
    let mut fresh = Seq::new(cfg(), TemporalConfig::default(), w, h);
    let (want, _) = fresh.next(&other, Some(&zero), 1);
    assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// NaN, Inf and absurd motion vectors get no history and are counted; the
/// output stays finite. NaN/Inf noisy samples are bridged with the history.
#[test]
fn bad_motion_and_nonfinite_light_are_rejected_and_counted() {
    let (w, h) = (31, 17);
    let mut seq = Seq::new(cfg(), TemporalConfig::default(), w, h);
    let mut mv = vec![0f32; 2 * w * h];
    let bad = [f32::NAN, f32::INFINITY, -f32::INFINITY, 1e30, 3.0 * w as f32];
    for (k, v) in bad.iter().enumerate() {
        mv[2 * (k * 7)] = *v;
    }
    seq.next(&frame_at(w, h, 0), None, 1);
    let mut f = frame_at(w, h, 1);
    f.noisy[3 * 100] = f32::NAN;
    f.noisy[3 * 200 + 1] = f32::INFINITY;
    let (_, rep) = seq.next(&f, Some(&mv), 1);
    assert_eq!(rep.invalid_motion, bad.len() as u64);
    assert_eq!(rep.history_rejected, bad.len() as u64);
    assert_eq!(rep.nonfinite_noisy, 2);
}

/// One frame with 0.1 % of its pixels at 1000× the mean: with the firefly
/// clamp (the default) the output two frames later is within a small bound of
/// the sequence without the burst; without the clamp the burst is a large
/// disturbance (so the bound means something).
#[test]
fn a_burst_of_fireflies_is_gone_within_two_frames() {
    let (w, h) = (96, 64);
    let zero = vec![0f32; 2 * w * h];
    let mean = frame_at(w, h, 0).noisy.iter().sum::<f32>() / (3 * w * h) as f32;
    let rel = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.iter().sum::<f32>();
    let run = |cfg: FlrConfig| {
        let (mut clean, mut burst) = (Seq::new(cfg, TemporalConfig::default(), w, h), Seq::new(cfg, TemporalConfig::default(), w, h));
        let mut d = vec![];
        for k in 0..6u64 {
            let f = frame_at(w, h, k);
            let mut g = f.clone();
            if k == 3 {
                let mut rng = Rng(99);
                for i in 0..w * h {
                    if rng.f32() < 1e-3 {
                        g.noisy[3 * i..3 * i + 3].fill(1000.0 * mean);
                    }
                }
            }
            let ((a, _), (b, _)) = (clean.next(&f, Some(&zero), 1), burst.next(&g, Some(&zero), 1));
            d.push(rel(&a, &b));
        }
        d
    };
    let on = run(cfg());
    assert!(on[5] < 0.01 && on[3] < 0.05, "with the clamp: {on:?}");
    let off = run(FlrConfig { fireflies: None, ..cfg() });
    assert!(off[3] > 0.2, "without the clamp the burst must show: {off:?}");
}

/// A history sized for another frame size or guide set is refused with a typed error.
#[test]
fn a_history_of_another_size_is_refused() {
    let (w, h) = (20, 10);
    let plan = TemporalFlr::new(cfg(), TemporalConfig::default(), w, h).unwrap();
    let other = TemporalFlr::new(cfg(), TemporalConfig::default(), w + 1, h).unwrap();
    let f = frame_at(w, h, 0);
    let mut hist = vec![0f32; other.history_len()];
    let mut history = History::new(&mut hist);
    let (mut s, mut fs, mut out) = (vec![0f32; plan.scratch_len()], vec![0f64; plan.flr_scratch_len()], vec![0f32; 3 * w * h]);
    let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
    let r = plan.denoise(&f.frame(SET), None, &mut history, &mut s, &mut fs, &mut ov);
    assert!(matches!(r, Err(Error::BufferTooSmall { arg: Arg::History, .. })), "{r:?}");
    assert!(TemporalFlr::new(FlrConfig { upsample: 2, ..cfg() }, TemporalConfig::default(), w, h).is_err());
    assert!(TemporalFlr::new(cfg(), TemporalConfig { output_alpha: 0.0, ..Default::default() }, w, h).is_err());
    for lag_sigmas in [-1.0, f32::NAN, f32::INFINITY] {
        let bad = TemporalConfig { lag_sigmas, ..Default::default() };
        let r = MomentFlr::new(FlrConfig { guides: SET, ..FlrConfig::temporal_moments() }, &bad, w, h);
        assert!(matches!(r, Err(Error::InvalidConfig(_))), "lag_sigmas {lag_sigmas}: {r:?}");
    }
}

/// Over a moving sequence, the parallel run (3 threads) gives the bits of the
/// one-thread run, at awkward sizes.
#[test]
fn parallel_equals_one_thread() {
    for (w, h) in [(1, 1), (7, 3), (257, 71)] {
        let mv: Vec<f32> = (0..w * h).flat_map(|i| [0.6 + (i % 3) as f32 * 0.2, -0.3]).collect();
        let (mut a, mut b) = (Seq::new(cfg(), TemporalConfig::default(), w, h), Seq::new(cfg(), TemporalConfig::default(), w, h));
        for k in 0..3 {
            let f = frame_at(w, h, k);
            let m = (k > 0).then_some(&mv[..]);
            let (x, rx) = a.next(&f, m, 1);
            let (y, ry) = b.next(&f, m, 3);
            assert!(x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits()), "{w}x{h} frame {k}");
            assert_eq!(rx, ry);
        }
    }
}

/// Steps 1 and 3 on groups of pixels (SIMD lanes: `wide`'s, and AVX2's and
/// AVX-512's where the CPU has them) give the bits of the per-pixel reference
/// (`Reprojection::per_pixel`): awkward widths, motion that moves a
/// group as one, pixel by pixel, and out of the frame, NaN/Inf light and
/// motion, sky (no normal), negative light, with and without the firefly
/// clamp, the clamp of negative results and a narrower clip, for each set of
/// rejection guides.
#[test]
fn pixel_groups_equal_the_per_pixel_reference() {
    let sets = [
        GuideSet::NORMAL_DEPTH,
        GuideSet { position: true, ..GuideSet::NORMAL_DEPTH },
        GuideSet { depth: true, ..GuideSet::NONE },
        GuideSet { position: true, ..GuideSet::NONE },
    ];
    for (w, h) in [(1, 1), (7, 3), (9, 9), (17, 5), (255, 12), (256, 9), (257, 17)] {
        for set in sets {
            // the default settings; a narrow clip with a slow blend and negative results kept;
            // no output accumulation (step 1 gathers no previous output, step 3 is skipped)
            let narrow = TemporalConfig { clip_gamma: 1.0, output_alpha: 0.25, ..Default::default() };
            let no_output = TemporalConfig { output_alpha: 1.0, ..Default::default() };
            let cases =
                [(None, TemporalConfig::default(), true), (Some(fireflies::DEFAULT_STRENGTH), narrow, false), (None, no_output, false)];
            for (clamp, cfg, clamp_negative) in cases {
                let slow = Reprojection::new(cfg, set, w, h).unwrap().per_pixel();
                for fast in [isa::Isa::Portable, isa::Isa::Avx2Fma, isa::Isa::Avx512].into_iter().filter_map(|i| slow.with_isa(i)) {
                    let (mut ha, mut hb) = (vec![0f32; fast.history_len()], vec![0f32; fast.history_len()]);
                    let (mut sa, mut sb) =
                        (vec![0f32; fast.frame_scratch_len(None).unwrap()], vec![0f32; fast.frame_scratch_len(None).unwrap()]);
                    for k in 0..4u64 {
                        let mut f = frame_at(w, h, k);
                        let mut rng = Rng(k + 7);
                        // a pan (groups move as one), per-pixel jitter in a band of rows, motion out of the frame
                        let mv: Vec<f32> = (0..w * h)
                            .flat_map(|i| {
                                let (x, y) = (i % w, i / w);
                                let j = if y % 4 == 1 { rng.f32() - 0.5 } else { 0.0 };
                                match (x * 7 + y * 3 + k as usize) % 97 {
                                    0 => [f32::NAN, 0.0],
                                    1 => [f32::INFINITY, 0.0],
                                    2 => [w as f32 + 2.5, 0.0],
                                    _ => [0.6 + j - 0.2 * k as f32, -0.35 + 0.1 * k as f32],
                                }
                            })
                            .collect();
                        for (i, n) in f.noisy.iter_mut().enumerate() {
                            match (i * 13 + k as usize) % 101 {
                                0 => *n = f32::NAN,
                                1 => *n = f32::INFINITY,
                                2 => *n *= 300.0,
                                _ => {}
                            }
                        }
                        // a strip of sky: no normal; a few positions NaN or huge (footprints without a finite neighbour)
                        for i in (0..w * h).filter(|i| i % w < w / 5) {
                            f.normal[3 * i..3 * i + 3].fill(0.0);
                        }
                        for i in (0..w * h).filter(|i| i % 29 == 3) {
                            f.position[3 * i + i % 3] = if i % 2 == 0 { f32::NAN } else { 3e38 };
                        }
                        // every third row an object that moves: positions a unit further each
                        // frame, depths unchanged (rejected where positions are guides)
                        for i in (0..w * h).filter(|i| (i / w).is_multiple_of(3)) {
                            f.position[3 * i] += k as f32;
                        }
                        // a history with NaN/Inf in it (a caller may resume any buffer), the same in both
                        if k == 2 {
                            for hist in [&mut ha, &mut hb] {
                                for (j, v) in hist.iter_mut().enumerate() {
                                    match j % 37 {
                                        5 => *v = f32::NAN,
                                        11 => *v = f32::INFINITY,
                                        17 => *v = f32::NEG_INFINITY,
                                        _ => {}
                                    }
                                }
                            }
                        }
                        let guides = f.guides(set);
                        let mut outs = Vec::new();
                        for (st, hist, scratch) in [(&fast, &mut ha, &mut sa), (&slow, &mut hb, &mut sb)] {
                            let mut history = History::resume(hist, k as u32);
                            let mut out = vec![f32::NAN; 3 * w * h];
                            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                            let noisy = ImageView::interleaved(&f.noisy, w, h, 3).unwrap();
                            let motion = ImageView::interleaved(&mv, w, h, 2).unwrap();
                            // the fit: the accumulated light, brightened where x is odd (so the clip
                            // has contrast), lowered below 0 in every third column
                            let rep = st
                                .run_frame(
                                    noisy,
                                    guides,
                                    Some(motion),
                                    clamp,
                                    clamp_negative,
                                    &mut history,
                                    scratch,
                                    None,
                                    &mut ov,
                                    |acc, _, _, o| {
                                        for y in 0..h {
                                            for c in 0..3 {
                                                let row: Vec<f32> = (0..w)
                                                    .map(|x| {
                                                        acc.get(x, y, c).unwrap() * if x % 2 == 1 { 1.5 } else { 1.0 }
                                                            - if x % 3 == 0 { 0.4 } else { 0.0 }
                                                    })
                                                    .collect();
                                                o.write_row(y, c, 0, &row).unwrap();
                                            }
                                        }
                                        Ok(Report::default())
                                    },
                                )
                                .unwrap();
                            outs.push((out, rep));
                        }
                        let same = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits());
                        let at = format!("{w}x{h} {set:?} clamp {clamp:?} frame {k} {fast:?}");
                        assert!(same(&outs[0].0, &outs[1].0), "output, {at}");
                        assert_eq!(outs[0].1, outs[1].1, "counts, {at}");
                        assert!(same(&ha, &hb), "history, {at}");
                    }
                }
            }
        }
    }
}

/// BMFR's and WALR's pipelines on 3 real threads (`TemporalDenoiser::
/// denoise_temporal_parallel`) give the one-thread bits over a pan; BMFR's
/// over 17 frames, so that every one of its 16 block-grid offsets (the
/// parallel scratch is sized for the largest) runs.
#[test]
fn bmfr_and_walr_pipelines_on_threads_equal_one_thread() {
    let (w, h) = (45, 29);
    let mv: Vec<f32> = (0..w * h).flat_map(|i| [0.6 + (i % 3) as f32 * 0.2, -0.3]).collect();
    let plans: [(Box<dyn TemporalDenoiser + Sync>, GuideSet, u64); 2] = [
        (Box::new(Bmfr::new(BmfrConfig { block: 16, ..Default::default() }, w, h).unwrap()), BmfrConfig::default().guides, 17),
        (Box::new(Walr::new(WalrConfig::default(), w, h).unwrap()), WalrConfig::default().guides, 3),
    ];
    let exec = |n: usize, body: &(dyn Fn(usize, usize) + Sync)| {
        std::thread::scope(|s| {
            for wk in 0..3 {
                s.spawn(move || (wk..n).step_by(3).for_each(|i| body(i, wk)));
            }
        })
    };
    for (plan, set, frames) in plans {
        let (mut h1, mut h3) = (vec![0f32; plan.history_len()], vec![0f32; plan.history_len()]);
        let mut s1 = vec![f64::NAN; plan.temporal_scratch_len()];
        let mut s3 = vec![f64::NAN; plan.temporal_parallel_scratch_len(3).unwrap()];
        let (mut n1, mut n3) = (0, 0);
        for k in 0..frames {
            let f = frame_at(w, h, k);
            let frame = f.frame(set);
            let m = (k > 0).then(|| ImageView::interleaved(&mv, w, h, 2).unwrap());
            let (mut a, mut b) = (vec![0f32; 3 * w * h], vec![0f32; 3 * w * h]);
            let mut hist = History::resume(&mut h1, n1);
            let ra =
                plan.denoise_temporal(&frame, m.as_ref(), &mut hist, &mut s1, &mut ImageViewMut::interleaved(&mut a, w, h, 3).unwrap());
            n1 = hist.frames();
            let mut hist = History::resume(&mut h3, n3);
            let mut ob = ImageViewMut::interleaved(&mut b, w, h, 3).unwrap();
            let rb = plan.denoise_temporal_parallel(&frame, m.as_ref(), &mut hist, &mut s3, &mut ob, 3, &exec);
            n3 = hist.frames();
            assert_eq!(ra.unwrap(), rb.unwrap(), "frame {k}");
            assert!(a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()), "frame {k}");
            assert_eq!(n1, n3);
        }
    }
}

/// Frame `k` of a still camera watching an object enter from the left edge:
/// `frame_at`'s static background, and a 10×10 square (its own normal,
/// depth, positions and light 10× the background's) at column `3k − 6`,
/// rows 15..25; its pixels move 3 columns a frame (motion −3, 0), the
/// background stays. Returns the frame, its motion and the object's mask.
fn object_entering(w: usize, h: usize, k: u64) -> (Owned, Vec<f32>, Vec<bool>) {
    let mut f = frame_at(w, h, k);
    let mut mv = vec![0f32; 2 * w * h];
    let mut on = vec![false; w * h];
    let mut rng = Rng(0x51ed_270b ^ (k + 7).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let left = 3 * k as i64 - 6;
    for y in 15..25.min(h) {
        for x in left.max(0)..(left + 10).min(w as i64) {
            let i = y * w + x as usize;
            on[i] = true;
            f.normal[3 * i..3 * i + 3].copy_from_slice(&[0.0, -1.0, 0.0]);
            f.depth[i] = 1.0;
            f.ao[i] = 1.0;
            // world positions move with the object, as a renderer writes them
            f.position[3 * i..3 * i + 3].copy_from_slice(&[4.0 * x as f32 / w as f32, 1.0, 4.0 * y as f32 / h as f32]);
            for (c, v) in [3.0f32, 2.0, 1.0].into_iter().enumerate() {
                f.clean[3 * i + c] = v;
                f.noisy[3 * i + c] = v * (1.0 + 0.8 * (2.0 * rng.f32() - 1.0));
            }
            mv[2 * i] = -3.0;
        }
    }
    (f, mv, on)
}

/// Mean of `|out − clean| / clean` and of `(out − clean) / clean` (the bias a
/// ghost shows) over the pixels of `mask`.
fn errors(out: &[f32], clean: &[f32], mask: &[bool]) -> (f64, f64) {
    let (mut abs, mut bias, mut n) = (0f64, 0f64, 0usize);
    for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        for c in 0..3 {
            let e = (out[3 * i + c] - clean[3 * i + c]) as f64 / clean[3 * i + c] as f64;
            abs += e.abs();
            bias += e;
            n += 1;
        }
    }
    (abs / n as f64, bias / n as f64)
}

/// An object entering a still camera's view leaves no ghost in any temporal
/// pipeline (light FLR, FLR on moments, BMFR, WALR): after 10 frames, where it
/// was a frame ago and is no longer, and where it ever was, the output is no
/// further from the background's light than the pipeline's per-frame method
/// gives; on the object itself, no darker than that (the clamp's cap from the
/// previous frame does not take a bright object that moves for outliers; the
/// clamp itself darkens this object by ~20 % in every method, per frame too:
/// it is 2 cells wide and brighter than every other cell around it). A
/// control with the history's tap tests off (every tap kept) ghosts, so the
/// measure sees one.
#[test]
fn an_object_entering_the_view_leaves_no_ghost() {
    let (w, h, frames) = (64, 40, 10u64);
    let set = SET;
    let keep_all = TemporalConfig { normal_limit: -1.0, depth_limit: 1e6, position_limit: 1e6, ..Default::default() };
    let pipelines: [(&str, Box<dyn TemporalDenoiser + Sync>, GuideSet, bool); 5] = [
        (
            "light",
            Box::new(TemporalFlr::new(FlrConfig { guides: set, ..FlrConfig::temporal() }, TemporalConfig::default(), w, h).unwrap()),
            set,
            true,
        ),
        (
            "moments",
            Box::new(MomentFlr::new(FlrConfig { guides: set, ..FlrConfig::temporal_moments() }, &TemporalConfig::default(), w, h).unwrap()),
            set,
            true,
        ),
        ("bmfr", Box::new(Bmfr::new(BmfrConfig::default(), w, h).unwrap()), BmfrConfig::default().guides, true),
        ("walr", Box::new(Walr::new(WalrConfig::default(), w, h).unwrap()), WalrConfig::default().guides, true),
        (
            "light, every tap kept",
            Box::new(TemporalFlr::new(FlrConfig { guides: set, ..FlrConfig::temporal() }, keep_all, w, h).unwrap()),
            set,
            false,
        ),
    ];
    for (name, plan, set, clean) in pipelines {
        let mut hist = vec![0f32; plan.history_len()];
        let mut scratch = vec![f64::NAN; plan.temporal_scratch_len().max(plan.scratch_len())];
        let mut frames_done = 0;
        let (mut out, mut single) = (vec![0f32; 3 * w * h], vec![0f32; 3 * w * h]);
        let (mut last, mut was, mut ever) = (None, vec![false; w * h], vec![false; w * h]);
        for k in 0..frames {
            let (f, mv, on) = object_entering(w, h, k);
            if k + 1 == frames {
                // per frame, on the last frame
                plan.denoise(&f.frame(set), &mut scratch, &mut ImageViewMut::interleaved(&mut single, w, h, 3).unwrap()).unwrap();
            }
            let m = (k > 0).then(|| ImageView::interleaved(&mv, w, h, 2).unwrap());
            let mut history = History::resume(&mut hist, frames_done);
            let mut o = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            plan.denoise_temporal(&f.frame(set), m.as_ref(), &mut history, &mut scratch, &mut o).unwrap();
            frames_done = history.frames();
            if k + 1 < frames {
                was = on.clone();
                ever.iter_mut().zip(&on).for_each(|(e, o)| *e |= o);
            }
            last = Some((f, on));
        }
        let (f, on) = last.unwrap();
        let fresh: Vec<bool> = was.iter().zip(&on).map(|(a, b)| *a && !b).collect();
        let trail: Vec<bool> = ever.iter().zip(&on).map(|(a, b)| *a && !b).collect();
        let (ft, fs) = (errors(&out, &f.clean, &fresh), errors(&single, &f.clean, &fresh));
        let (tt, ts) = (errors(&out, &f.clean, &trail), errors(&single, &f.clean, &trail));
        let (ot, os) = (errors(&out, &f.clean, &on), errors(&single, &f.clean, &on));
        let msg = format!(
            "{name}: just uncovered |e| {:.3} bias {:+.3} (per frame {:.3} {:+.3}); trail {:.3} {:+.3} ({:.3} {:+.3}); object {:.3} {:+.3} ({:.3} {:+.3})",
            ft.0, ft.1, fs.0, fs.1, tt.0, tt.1, ts.0, ts.1, ot.0, ot.1, os.0, os.1
        );
        println!("{msg}");
        let ghost_free =
            ft.0 <= 1.25 * fs.0 + 0.02 && tt.0 <= 1.25 * ts.0 + 0.02 && ft.1 <= fs.1.max(0.0) + 0.1 && tt.1 <= ts.1.max(0.0) + 0.1;
        assert_eq!(ghost_free, clean, "{msg}");
        if clean {
            assert!(ot.1 >= os.1.min(0.0) - 0.1, "{msg}");
            // the firefly clamp takes this bright 2-cell object for outliers, per frame too
            assert!(os.1 < -0.1, "{msg}");
        } else {
            assert!(ft.1 > 0.5, "{msg}");
        }
    }
    // without the clamp, per-frame FLR keeps the object's light
    let (f, _, on) = object_entering(w, h, frames - 1);
    let bias = errors(&run(FlrConfig { fireflies: None, ..cfg() }, &f).0, &f.clean, &on).1;
    assert!(bias.abs() < 0.05, "FLR without the clamp: bias {bias:+.3} on the object");
}

/// Light that changes under a still camera: `frame_at`'s scene, whose right
/// half doubles its light from frame `step` on (a light switched on; the
/// geometry does not move, so every history tap is kept).
fn light_switched_on(w: usize, h: usize, k: u64, step: u64) -> (Owned, Vec<bool>) {
    let mut f = frame_at(w, h, k);
    let right: Vec<bool> = (0..w * h).map(|i| i % w >= w / 2).collect();
    if k >= step {
        for (i, _) in right.iter().enumerate().filter(|(_, &r)| r) {
            for c in 0..3 {
                f.clean[3 * i + c] *= 2.0;
                f.noisy[3 * i + c] *= 2.0;
            }
        }
    }
    (f, right)
}

/// Temporal FLR on moments follows light that changes: on the fourth frame
/// after the right half's light doubled, a 16-frame history is still more
/// than 30 % too dark there (the control without the lag test is), while
/// the lag test restarts it and the output's bias there is within 3 % of
/// per-frame FLR's. While the light holds, the test restarts nothing.
#[test]
fn moments_follow_light_that_changes() {
    let (w, h, step) = (64, 48, 16u64);
    let cfg = FlrConfig { guides: SET, ..FlrConfig::temporal_moments() };
    let plan = |lag_sigmas| MomentFlr::new(cfg, &TemporalConfig { lag_sigmas, ..Default::default() }, w, h).unwrap();
    for (name, plan, follows) in [("lag test", plan(3.0), true), ("without the lag test", plan(0.0), false)] {
        let mut hist = vec![0f32; plan.history_len()];
        let mut scratch = vec![f64::NAN; plan.scratch_len()];
        let mut out = vec![0f32; 3 * w * h];
        let (mut frames, mut before) = (0, Report::default());
        for k in 0..step + 4 {
            let (f, right) = light_switched_on(w, h, k, step);
            let mut history = History::resume(&mut hist, frames);
            let mut o = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            let rep = plan.denoise(&f.frame(SET), None, &mut history, &mut scratch, &mut o).unwrap();
            frames = history.frames();
            if k < step {
                before += rep;
                continue;
            }
            if k == step + 3 {
                let mut single = vec![0f32; 3 * w * h];
                Denoiser::denoise(&plan, &f.frame(SET), &mut scratch, &mut ImageViewMut::interleaved(&mut single, w, h, 3).unwrap())
                    .unwrap();
                let (bias, per_frame) = (errors(&out, &f.clean, &right).1, errors(&single, &f.clean, &right).1);
                let msg = format!(
                    "{name}: bias {bias:+.3} on the brightened half (per frame {per_frame:+.3}), {} pixels restarted",
                    rep.light_changed
                );
                println!("{msg}");
                assert_eq!(bias.abs() < per_frame.abs() + 0.03, follows, "{msg}");
                assert_eq!(bias < -0.3, !follows, "{msg}");
            }
        }
        assert_eq!(before.light_changed, 0, "{name}: the light held, yet histories restarted");
    }
}
