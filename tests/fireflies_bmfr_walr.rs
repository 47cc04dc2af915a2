//! The firefly clamp in BMFR and WALR (`BmfrConfig::fireflies`,
//! `WalrConfig::fireflies`, `lrdenoise::fireflies`) and in their temporal
//! pipelines.
//!
//! The rule has its own f64 oracle (the fireflies module's unit tests); here:
//! the temporal stage's clamp is the band-by-band reference built on the
//! rule's kernel; each method with the clamp is the method without it on a frame clamped
//! first, band by band, bit for bit (single frame, the temporal pipelines'
//! first frame, awkward sizes, block sizes, grid offsets, kernels,
//! storages, read paths), with the count clamped reported; a few outliers
//! at 1e4 times the mean barely move the output with the clamp and ruin it
//! without; and a burst of outliers in one frame of a static sequence is
//! gone from the temporal pipelines' output two frames later.

mod common;

use common::{pre_clamp, Owned, Rng};
use lrdenoise::fireflies;
use lrdenoise::image::Layout;
use lrdenoise::isa::Kernel;
use lrdenoise::walr::{Storage, Walr, WalrConfig};
use lrdenoise::{Bmfr, BmfrConfig, Frame, GuideSet, History, ImageView, ImageViewMut, Report};

const NP: GuideSet = GuideSet { normal: true, depth: false, position: true, ao: false, user: 0 };
const NDP: GuideSet = GuideSet { normal: true, depth: true, position: true, ao: false, user: 0 };
const K: f32 = fireflies::DEFAULT_STRENGTH;

/// Mean luminance-free brightness of a frame: the mean of its values.
fn mean(v: &[f32]) -> f32 {
    (v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64) as f32
}

/// Sets `count` pixels (chosen by `seed`) to `factor` times the frame's mean
/// in every channel; returns their indices.
fn inject(f: &mut Owned, count: usize, factor: f32, seed: u64) -> Vec<usize> {
    let value = factor * mean(&f.noisy);
    let mut rng = Rng(seed | 1);
    (0..count)
        .map(|_| {
            let i = (rng.next_u64() % (f.w * f.h) as u64) as usize;
            f.noisy[3 * i..3 * i + 3].fill(value);
            i
        })
        .collect()
}

/// A frame with outliers where the clamp's reads are awkward: the corners and
/// borders (BMFR mirrors them), light-scale samples (WALR's `prepare` reads
/// pixels at multiples of 4), and random places; one NaN sample.
fn with_outliers(w: usize, h: usize, seed: u64) -> Owned {
    let mut f = Owned::synthetic(w, h, seed, 0.5);
    let v = 1e4 * mean(&f.noisy);
    for (x, y) in [(0, 0), (w - 1, h - 1), (w - 1, 0), (0, h / 2), (w / 2, 0), ((w / 2) & !3, (h / 2) & !3)] {
        f.noisy[3 * (y * w + x)..3 * (y * w + x) + 3].fill(v);
    }
    inject(&mut f, (w * h / 500).max(1), 1e4, seed * 3 + 1);
    if w * h > 4 {
        f.noisy[3 * (w * h / 3) + 1] = f32::NAN;
    }
    f
}

/// The temporal stage clamps the light as step 1 reads it: without history
/// the accumulated light is the band-by-band reference's clamped light, bit
/// for bit, with its count, on every read path, whole frame and in bands.
#[test]
fn temporal_stage_clamps_as_the_band_by_band_reference() {
    use lrdenoise::temporal::{Inputs, Reprojection, TemporalConfig};
    for (w, h) in [(1, 1), (7, 3), (9, 8), (61, 29), (257, 17), (900, 20), (33, 70)] {
        let f = with_outliers(w, h, (w + 3 * h) as u64);
        let mut pre = f.noisy.clone();
        let clamped = pre_clamp(&mut pre, w, h, K);
        let rgba: Vec<f32> = (0..w * h).flat_map(|i| [f.noisy[3 * i], f.noisy[3 * i + 1], f.noisy[3 * i + 2], -1.0]).collect();
        let views = [
            ImageView::interleaved(&f.noisy, w, h, 3).unwrap(),
            ImageView::f32(&rgba, w, h, 3, Layout { pixel_stride: 4, row_stride: 4 * w, ..Layout::interleaved(w, 3) }).unwrap(),
        ];
        let st = Reprojection::new(TemporalConfig::default(), GuideSet::NONE, w, h).unwrap();
        for v in views {
            for workers in [None, Some(3)] {
                let mut data = vec![f32::NAN; st.history_len()];
                let mut history = History::new(&mut data);
                let inp = Inputs { noisy: v, fireflies: Some(K), guides: Default::default(), motion: None };
                let c = match workers {
                    None => {
                        let mut s = vec![f32::NAN; st.scratch_len()];
                        st.accumulate(&inp, &mut history, &mut s).unwrap()
                    }
                    Some(n) => {
                        let mut s = vec![f32::NAN; st.parallel_scratch_len(n).unwrap()];
                        st.accumulate_parallel(&inp, &mut history, &mut s, n, &|t, f| (0..t).for_each(|i| f(i, i % n))).unwrap()
                    }
                };
                assert_eq!(c.clamped, clamped, "{w}x{h} {workers:?}");
                let acc = st.accumulated(&mut history).unwrap();
                let mut got = vec![0f32; 3 * w * h];
                let mut row = vec![0f32; w];
                for y in 0..h {
                    for ch in 0..3 {
                        acc.read_row(y, ch, 0, &mut row).unwrap();
                        for (x, v) in row.iter().enumerate() {
                            got[3 * (y * w + x) + ch] = *v;
                        }
                    }
                }
                assert!(same(&got, &pre), "{w}x{h} {workers:?}");
            }
        }
    }
}

fn bmfr(cfg: BmfrConfig, f: &Owned, frame: &Frame<'_>, index: u32) -> (Vec<f32>, Report) {
    let b = Bmfr::new(cfg, f.w, f.h).unwrap();
    let mut scratch = vec![f32::NAN; b.scratch_len()];
    let mut out = vec![f32::NAN; f.w * f.h * 3];
    let rep = b.denoise(frame, index, &mut scratch, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap()).unwrap();
    (out, rep)
}

fn walr(cfg: WalrConfig, f: &Owned, frame: &Frame<'_>, index: u32) -> (Vec<f32>, Report) {
    let wl = Walr::new(cfg, f.w, f.h).unwrap();
    let mut scratch = vec![f32::NAN; wl.scratch_len()];
    let mut out = vec![f32::NAN; f.w * f.h * 3];
    let rep = wl.denoise(frame, index, &mut scratch, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap()).unwrap();
    (out, rep)
}

fn same(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn bmfr_clamp_equals_clamping_the_input_first() {
    for (w, h) in [(1, 1), (7, 3), (70, 45), (150, 97), (257, 17), (33, 65)] {
        let f = with_outliers(w, h, (w * 7 + h) as u64);
        let mut pre = f.clone();
        let clamped = pre_clamp(&mut pre.noisy, w, h, K);
        assert!(w * h < 64 || clamped >= 3, "{w}x{h}: the outliers were clamped ({clamped})");
        for block in [8, 12, 32, 64] {
            for kernel in [Kernel::Simd, Kernel::Scalar] {
                for index in [0u32, 5] {
                    let on = BmfrConfig { block, kernel, fireflies: Some(K), ..BmfrConfig::with_guides(NP) };
                    let (got, rep) = bmfr(on, &f, &f.frame(NP), index);
                    let (want, want_rep) = bmfr(BmfrConfig { fireflies: None, ..on }, &pre, &pre.frame(NP), index);
                    assert!(same(&got, &want), "{w}x{h} B={block} {kernel:?} frame {index}");
                    assert_eq!(rep.clamped_fireflies, clamped, "{w}x{h} B={block} {kernel:?} frame {index}");
                    assert_eq!(Report { clamped_fireflies: 0, ..rep }, want_rep);
                }
            }
        }
    }
}

#[test]
fn walr_clamp_equals_clamping_the_input_first() {
    // 900 wide: the light scale's clamp measures the band in windows of cells
    for (w, h) in [(1, 1), (7, 3), (61, 47), (130, 9), (900, 20)] {
        let f = with_outliers(w, h, (w * 5 + h) as u64);
        let mut pre = f.clone();
        let clamped = pre_clamp(&mut pre.noisy, w, h, K);
        assert!(w * h < 64 || clamped >= 3, "{w}x{h}: the outliers were clamped ({clamped})");
        for (storage, kernel, adaptive_blend) in
            [(Storage::F32, Kernel::Simd, true), (Storage::F16, Kernel::Simd, true), (Storage::F32, Kernel::Scalar, false)]
        {
            let on = WalrConfig { storage, kernel, adaptive_blend, iterations: 3, fireflies: Some(K), ..WalrConfig::with_guides(NDP) };
            let (got, rep) = walr(on, &f, &f.frame(NDP), 1);
            let (want, want_rep) = walr(WalrConfig { fireflies: None, ..on }, &pre, &pre.frame(NDP), 1);
            assert!(same(&got, &want), "{w}x{h} {storage:?} {kernel:?}");
            assert_eq!(rep.clamped_fireflies, clamped, "{w}x{h} {storage:?} {kernel:?}");
            assert_eq!(Report { clamped_fireflies: 0, ..rep }, want_rep);
        }
    }
}

/// The clamp reads the light through the image views: planar and RGBA f16
/// inputs (values exact in f16) give the interleaved f32 input's output.
#[test]
fn read_paths_clamp_alike() {
    let (w, h) = (61, 29);
    let mut f = with_outliers(w, h, 4);
    for v in f.noisy.iter_mut() {
        *v = half::f16::from_f32(*v).to_f32();
    }
    let planar: Vec<f32> = (0..3).flat_map(|c| (0..w * h).map(move |i| (c, i))).map(|(c, i)| f.noisy[3 * i + c]).collect();
    let rgba: Vec<half::f16> =
        (0..w * h).flat_map(|i| [f.noisy[3 * i], f.noisy[3 * i + 1], f.noisy[3 * i + 2], 1.0]).map(half::f16::from_f32).collect();
    let views = [
        ImageView::f32(&planar, w, h, 3, Layout::planar(w, h)).unwrap(),
        ImageView::f16(&rgba, w, h, 3, Layout { pixel_stride: 4, row_stride: 4 * w, ..Layout::interleaved(w, 3) }).unwrap(),
    ];
    let b_cfg = BmfrConfig::with_guides(NP);
    let w_cfg = WalrConfig { iterations: 2, ..WalrConfig::with_guides(NDP) };
    let (b_want, b_rep) = bmfr(b_cfg, &f, &f.frame(NP), 3);
    let (w_want, w_rep) = walr(w_cfg, &f, &f.frame(NDP), 3);
    assert!(b_rep.clamped_fireflies >= 3 && w_rep.clamped_fireflies == b_rep.clamped_fireflies, "{b_rep:?} {w_rep:?}");
    for v in views {
        assert!(same(&bmfr(b_cfg, &f, &Frame::new(v, f.guides(NP)), 3).0, &b_want));
        assert!(same(&walr(w_cfg, &f, &Frame::new(v, f.guides(NDP)), 3).0, &w_want));
    }
}

/// Mean |a − b| relative to the mean of `b`.
fn relative_error(a: &[f32], b: &[f32]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| (*x as f64 - *y as f64).abs()).sum();
    d / b.iter().map(|v| v.abs() as f64).sum::<f64>()
}

#[test]
fn outliers_barely_move_the_output_with_the_clamp() {
    let (w, h) = (128, 96);
    let clean = Owned::synthetic(w, h, 21, 0.5);
    let mut hit = clean.clone();
    inject(&mut hit, 6, 1e4, 99);
    let mut errors = vec![];
    for on in [true, false] {
        let fireflies = on.then_some(K);
        let b = BmfrConfig { fireflies, ..BmfrConfig::with_guides(NP) };
        let wl = WalrConfig { fireflies, ..WalrConfig::with_guides(NDP) };
        let eb = relative_error(&bmfr(b, &hit, &hit.frame(NP), 0).0, &bmfr(b, &clean, &clean.frame(NP), 0).0);
        let ew = relative_error(&walr(wl, &hit, &hit.frame(NDP), 0).0, &walr(wl, &clean, &clean.frame(NDP), 0).0);
        eprintln!("clamp {on}: 6 outliers at 1e4 x the mean move BMFR by {eb:.2e}, WALR by {ew:.2e} (relative mean abs)");
        errors.push([eb, ew]);
    }
    let [[b_on, w_on], [b_off, w_off]] = errors[..] else { unreachable!() };
    // measured: 7.0e-3 / 4.3e-3 with the clamp, 5.5 / 4.7 without
    assert!(b_on < 0.015 && w_on < 0.015, "with the clamp: BMFR {b_on}, WALR {w_on}");
    assert!(b_off > 100.0 * b_on && w_off > 100.0 * w_on, "without the clamp: BMFR {b_off}, WALR {w_off}");
}

/// One frame of a temporal pipeline: frame, motion, history, output.
type Step<'a> = dyn FnMut(&Frame<'_>, &ImageView<'_>, &mut History<'_>, &mut Vec<f32>) -> Report + 'a;

/// A static camera (zero motion), fresh noise every frame, three times:
/// as is, with outliers at 1e4 times the mean added to frame `burst`, and
/// with frame `burst`'s noise drawn again instead (the trace an ordinary
/// frame leaves in the history). Returns each run's per-frame output.
fn temporal_runs(run: &mut Step<'_>, history_len: usize, frames: usize, burst: usize) -> [Vec<(Vec<f32>, Report)>; 3] {
    let (w, h) = (96, 80);
    let base = Owned::synthetic(w, h, 12, 0.0);
    let zero = vec![0f32; 2 * w * h];
    let motion = ImageView::interleaved(&zero, w, h, 2).unwrap();
    [0, 1, 2].map(|variant| {
        let mut hist = vec![0f32; history_len];
        let mut history = History::new(&mut hist);
        (0..frames)
            .map(|k| {
                let mut f = base.clone();
                let seed = if variant == 2 && k == burst { 5000 } else { 1000 + k as u64 };
                let mut rng = Rng(seed);
                // 1-spp-like: mostly dim, sometimes bright (mean preserved)
                for (n, c) in f.noisy.iter_mut().zip(&base.clean) {
                    *n = c * if rng.f32() < 0.7 { 0.5 } else { 13.0 / 6.0 };
                }
                if variant == 1 && k == burst {
                    inject(&mut f, 8, 1e4, 7);
                }
                let mut out = vec![0f32; 3 * w * h];
                let rep = run(&f.frame(GuideSet { depth: true, ..NP }), &motion, &mut history, &mut out);
                (out, rep)
            })
            .collect()
    })
}

/// A list of numbers printed `[1.2e-3, …]`.
struct Sci<'a>(&'a [f64]);
impl std::fmt::LowerExp for Sci<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v: Vec<String> = self.0.iter().map(|x| format!("{x:.1e}")).collect();
        write!(f, "[{}]", v.join(", "))
    }
}

/// Per frame: the mean |a − b| relative to the mean of `a`, and the largest |a − b| relative to it.
fn differences(a: &[(Vec<f32>, Report)], b: &[(Vec<f32>, Report)]) -> (Vec<f64>, Vec<f64>) {
    a.iter()
        .zip(b)
        .map(|(a, b)| {
            (relative_error(&b.0, &a.0), (a.0.iter().zip(&b.0).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max) / mean(&a.0)) as f64)
        })
        .unzip()
}

fn burst_case(name: &str, runs: &[Vec<(Vec<f32>, Report)>; 3], burst: usize, on: bool) {
    let [plain, hit, reseeded] = runs;
    let (mean_hit, max_hit) = differences(plain, hit);
    let (mean_noise, max_noise) = differences(plain, reseeded);
    eprintln!(
        "{name}, clamp {on}: per frame, mean and largest difference made by the burst {:.1e} {:.1e}, by drawing that frame's noise again {:.1e} {:.1e}",
        Sci(&mean_hit),
        Sci(&max_hit),
        Sci(&mean_noise),
        Sci(&max_noise)
    );
    assert!(mean_hit[..burst].iter().all(|&e| e == 0.0), "{name}: the frames up to the burst are untouched");
    let after = burst + 2;
    if on {
        assert!(hit[burst].1.clamped_fireflies >= 8, "{name}: {:?}", hit[burst].1);
        // Two frames on, the burst is gone: each clamped outlier entered the
        // history at the fraction of it the clamp kept, so what is left is a
        // twentieth of what drawing that frame's noise again changes over
        // the frame, and below its largest change at every pixel (without
        // the clamp, hundreds of times both).
        assert!(mean_hit[after] < 0.05 * mean_noise[after], "{name}: two frames after the burst, over the frame");
        assert!(max_hit[after] < max_noise[after], "{name}: two frames after the burst, the largest difference");
    } else {
        assert!(mean_hit[after] > 30.0 * mean_noise[after], "{name}: without the clamp the burst stays in the history");
        assert!(max_hit[after] > 10.0, "{name}: without the clamp the burst stays in the history");
    }
}

#[test]
fn a_burst_of_outliers_is_gone_two_frames_later() {
    let (w, h, frames, burst) = (96, 80, 6, 2);
    let set = GuideSet { depth: true, ..NP };
    for on in [true, false] {
        let fireflies = on.then_some(K);
        let b = Bmfr::new(BmfrConfig { fireflies, ..BmfrConfig::with_guides(set) }, w, h).unwrap();
        let mut scratch = vec![0f32; b.temporal_scratch_len()];
        let mut run = |f: &Frame<'_>, m: &ImageView<'_>, hist: &mut History<'_>, out: &mut Vec<f32>| {
            b.denoise_temporal(f, Some(m), hist, &mut scratch, &mut ImageViewMut::interleaved(out, w, h, 3).unwrap()).unwrap()
        };
        burst_case("BMFR", &temporal_runs(&mut run, b.history_len(), frames, burst), burst, on);

        let wl = Walr::new(WalrConfig { fireflies, ..WalrConfig::with_guides(set) }, w, h).unwrap();
        let mut scratch = vec![0f32; wl.temporal_scratch_len()];
        let mut run = |f: &Frame<'_>, m: &ImageView<'_>, hist: &mut History<'_>, out: &mut Vec<f32>| {
            wl.denoise_temporal(f, Some(m), hist, &mut scratch, &mut ImageViewMut::interleaved(out, w, h, 3).unwrap()).unwrap()
        };
        burst_case("WALR", &temporal_runs(&mut run, wl.history_len(), frames, burst), burst, on);
    }
}

fn view(o: &mut [f32], w: usize, h: usize) -> ImageViewMut<'_> {
    ImageViewMut::interleaved(o, w, h, 3).unwrap()
}

/// A temporal pipeline with the clamp equals the pipeline without it on
/// frames clamped first while it has no history (the clamped light is what
/// enters it, and the accumulated light is not clamped again), and counts
/// the same clamped samples in every frame. With a history the clamped
/// samples enter at a weight scaled by what the clamp kept
/// (`a_burst_of_outliers_is_gone_two_frames_later`).
#[test]
fn temporal_clamp_equals_clamping_each_frame_first() {
    let (w, h) = (83, 41);
    let set = GuideSet { depth: true, ..NP };
    let frames: Vec<Owned> = (0..4).map(|k| with_outliers(w, h, 50 + k)).collect();
    let zero = vec![0.25f32; 2 * w * h];
    let motion = ImageView::interleaved(&zero, w, h, 2).unwrap();
    // the history's cap off: with it, later frames clamp more than one frame's rule (tests/temporal.rs)
    let no_cap = |t: lrdenoise::temporal::TemporalConfig| lrdenoise::temporal::TemporalConfig { firefly_history: 0.0, ..t };
    let b_on = BmfrConfig::with_guides(set);
    let b_on = Bmfr::new(BmfrConfig { fireflies: Some(K), temporal: no_cap(b_on.temporal), ..b_on }, w, h).unwrap();
    let b_off = Bmfr::new(BmfrConfig { fireflies: None, ..*b_on.config() }, w, h).unwrap();
    let w_on = WalrConfig::with_guides(set);
    let w_on = Walr::new(WalrConfig { fireflies: Some(K), iterations: 3, temporal: no_cap(w_on.temporal), ..w_on }, w, h).unwrap();
    let w_off = Walr::new(WalrConfig { fireflies: None, ..*w_on.config() }, w, h).unwrap();
    assert!(b_on.temporal_scratch_len() > b_off.temporal_scratch_len());
    assert_eq!((b_on.history_len(), w_on.history_len()), (b_off.history_len(), w_off.history_len()));
    let mut hists =
        [vec![0f32; b_on.history_len()], vec![0f32; b_on.history_len()], vec![0f32; w_on.history_len()], vec![0f32; w_on.history_len()]];
    let [h0, h1, h2, h3] = &mut hists;
    let (mut hb_on, mut hb_off, mut hw_on, mut hw_off) = (History::new(h0), History::new(h1), History::new(h2), History::new(h3));
    let mut scratch = vec![f32::NAN; b_on.temporal_scratch_len().max(w_on.temporal_scratch_len())];
    let mut outs = [vec![0f32; 3 * w * h], vec![0f32; 3 * w * h]];
    for (k, f) in frames.iter().enumerate() {
        let mut pre = f.clone();
        let clamped = pre_clamp(&mut pre.noisy, w, h, K);
        assert!(clamped >= 6);
        let m = (k > 0).then_some(&motion);
        let [a, b] = &mut outs;
        let r_on = b_on.denoise_temporal(&f.frame(set), m, &mut hb_on, &mut scratch, &mut view(a, w, h)).unwrap();
        let r_off = b_off.denoise_temporal(&pre.frame(set), m, &mut hb_off, &mut scratch, &mut view(b, w, h)).unwrap();
        assert!(k > 0 || same(a, b), "BMFR frame {k}");
        assert_eq!((r_on.clamped_fireflies, Report { clamped_fireflies: 0, ..r_on }), (clamped, r_off), "BMFR frame {k}");
        let r_on = w_on.denoise_temporal(&f.frame(set), m, &mut hw_on, &mut scratch, &mut view(a, w, h)).unwrap();
        let r_off = w_off.denoise_temporal(&pre.frame(set), m, &mut hw_off, &mut scratch, &mut view(b, w, h)).unwrap();
        assert!(k > 0 || same(a, b), "WALR frame {k}");
        assert_eq!((r_on.clamped_fireflies, Report { clamped_fireflies: 0, ..r_on }), (clamped, r_off), "WALR frame {k}");
    }
}

#[test]
fn strengths_are_validated() {
    for k in [0.5, f32::NAN, f32::INFINITY, -2.0] {
        assert!(Bmfr::new(BmfrConfig { fireflies: Some(k), ..Default::default() }, 16, 16).is_err(), "{k}");
        assert!(Walr::new(WalrConfig { fireflies: Some(k), ..Default::default() }, 16, 16).is_err(), "{k}");
    }
    for k in [None, Some(1.0), Some(K), Some(1e6)] {
        assert!(Bmfr::new(BmfrConfig { fireflies: k, ..Default::default() }, 16, 16).is_ok());
        assert!(Walr::new(WalrConfig { fireflies: k, ..Default::default() }, 16, 16).is_ok());
    }
    assert_eq!((BmfrConfig::default().fireflies, WalrConfig::default().fireflies), (Some(K), Some(K)));
}
