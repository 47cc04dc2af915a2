//! FLR's firefly clamp (`FlrConfig::fireflies`, `lrdenoise::fireflies`).
//!
//! The clamp's rule has its own f64 oracle (the module's unit tests); here:
//! FLR with the clamp is FLR without it on a frame clamped beforehand, bit
//! for bit, on every read path, block size and awkward size; and under
//! outliers of any density, magnitude and placement the output stays finite
//! and close to the clean frame's output.

mod common;

use common::{pre_clamp, Owned, Rng};
use lrdenoise::fireflies::CELL;
use lrdenoise::image::Layout;
use lrdenoise::isa::Kernel;
use lrdenoise::{Blur, Flr, FlrConfig, GuideSet, ImageView, ImageViewMut, Report};
use proptest::prelude::*;

fn denoise(cfg: FlrConfig, f: &Owned) -> (Vec<f32>, Report) {
    let flr = Flr::new(cfg, f.w, f.h).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![f32::NAN; f.w * f.h * 3];
    let frame = f.frame(cfg.guides);
    let rep = flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap()).unwrap();
    (out, rep)
}

/// Sets `count` pixels (chosen by `seed`) to `value` in every channel.
fn inject(f: &mut Owned, count: usize, value: f32, seed: u64) {
    let mut rng = Rng(seed | 1);
    for _ in 0..count {
        let i = (rng.next_u64() % (f.w * f.h) as u64) as usize;
        f.noisy[3 * i..3 * i + 3].fill(value);
    }
}

#[test]
fn clamp_inside_flr_equals_clamping_the_input_first() {
    let set = GuideSet::NORMAL_DEPTH_AO;
    for (w, h) in [(1, 1), (7, 3), (255, 40), (256, 33), (257, 17), (64, 48)] {
        let mut f = Owned::synthetic(w, h, (w * 7 + h) as u64, 1.0);
        inject(&mut f, (w * h / 1500).max(1), 1e4, w as u64);
        f.noisy[0] = f32::NAN;
        for block in [1, 2, 4, 8, 16] {
            for kernel in [Kernel::Simd, Kernel::Scalar] {
                for blur in [Blur::Gaussian { sigma: 12.0, radius: None }, Blur::Adaptive { sigmas: [6.0, 12.0, 20.0] }] {
                    let on = FlrConfig { block, kernel, blur, fireflies: Some(1.5), ..FlrConfig::with_guides(set) };
                    let (got, rep) = denoise(on, &f);
                    let mut pre = f.clone();
                    let clamped = pre_clamp(&mut pre.noisy, w, h, 1.5);
                    let (want, _) = denoise(FlrConfig { fireflies: None, ..on }, &pre);
                    let same = got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(same, "{w}x{h} B={block} {kernel:?} {blur:?}");
                    assert_eq!(rep.clamped_fireflies, clamped, "{w}x{h} B={block} {kernel:?}");
                    assert!(w * h < 64 || clamped > 0, "{w}x{h}: the injected outliers were clamped");
                }
            }
        }
    }
}

#[test]
fn planar_and_rgba16f_inputs_clamp_alike() {
    // the clamp reads the light through the image views: an RGBA f16 layout
    // with values exactly representable in f16 gives the interleaved result
    let (w, h) = (61, 29);
    let mut f = Owned::synthetic(w, h, 3, 1.0);
    for v in f.noisy.iter_mut() {
        *v = half::f16::from_f32(*v).to_f32();
    }
    inject(&mut f, 2, 6e4, 5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let cfg = FlrConfig::with_guides(set);
    let (want, rep) = denoise(cfg, &f);
    assert!(rep.clamped_fireflies >= 2);
    let rgba: Vec<half::f16> =
        (0..w * h).flat_map(|i| [f.noisy[3 * i], f.noisy[3 * i + 1], f.noisy[3 * i + 2], 1.0]).map(half::f16::from_f32).collect();
    // RGBA: three channels of a four-channel interleaved layout
    let noisy = ImageView::f16(&rgba, w, h, 3, Layout { pixel_stride: 4, row_stride: 4 * w, ..Layout::interleaved(w, 3) }).unwrap();
    let frame = lrdenoise::Frame::new(noisy, f.guides(set));
    let flr = Flr::new(cfg, w, h).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; w * h * 3];
    flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
    assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// Mean |a − b| over the frame, relative to the mean of `b`.
fn relative_error(a: &[f32], b: &[f32]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| (*x as f64 - *y as f64).abs()).sum();
    let m: f64 = b.iter().map(|y| y.abs() as f64).sum();
    d / m.max(1e-12)
}

#[derive(Clone, Copy, Debug)]
enum Placement {
    /// Uniformly at random (several may share a neighbourhood).
    Random,
    /// At most one per band and 14 cells (a jittered lattice).
    Isolated,
    /// 3×3 clusters.
    Clustered,
    /// On the synthetic frame's region edges (its normal changes there).
    Edges,
    /// In the outermost rows and columns.
    Border,
}

fn place(f: &mut Owned, placement: Placement, count: usize, value: f32, seed: u64) {
    let (w, h) = (f.w, f.h);
    // the synthetic frame's normals change at one column (its region edge)
    let normal = |x: usize, y: usize| &f.normal[3 * (y * w + x)..3 * (y * w + x) + 3];
    let edge = (0..w - 1).find(|&x| normal(x, 0) != normal(x + 1, 0)).unwrap_or(w / 2);
    let mut rng = Rng(seed | 1);
    for _ in 0..count {
        let (x, y) = ((rng.next_u64() % w as u64) as usize, (rng.next_u64() % h as u64) as usize);
        let pixels: Vec<(usize, usize)> = match placement {
            Placement::Random => vec![(x, y)],
            Placement::Isolated => {
                // lattice sites of 14 cells × 1 band, `count` of them at random
                let (sx, sy) = (w.div_ceil(14 * CELL), h.div_ceil(CELL));
                let site = (rng.next_u64() % (sx * sy) as u64) as usize;
                let (cx, cy) = (site % sx * 14 * CELL, site / sx * CELL);
                vec![((cx + x % CELL).min(w - 1), (cy + y % CELL).min(h - 1))]
            }
            Placement::Clustered => (0..9).map(|i| ((x + i % 3).min(w - 1), (y + i / 3).min(h - 1))).collect(),
            Placement::Edges => vec![(edge, y)],
            Placement::Border => vec![match rng.next_u64() % 4 {
                0 => (x, 0),
                1 => (x, h - 1),
                2 => (0, y),
                _ => (w - 1, y),
            }],
        };
        for (x, y) in pixels {
            f.noisy[3 * (y * w + x)..3 * (y * w + x) + 3].fill(value);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Outliers from 0.001 % to 0.5 % of the pixels, 10× to 1e6× the mean
    /// luminance or f16's largest value, at random, isolated, in 3×3 clusters,
    /// on a region edge or at the border: the output is finite and never
    /// further from the clean frame's output than FLR without the clamp (by
    /// more than 1 % of the mean). Where the rule's premise holds (at most two
    /// cells of outliers per 104 × 8 neighbourhood: isolated or on one edge
    /// column) it stays within 5 % of the clean frame's output (mean absolute
    /// difference relative to the mean), whatever the magnitude.
    #[test]
    fn outliers_leave_the_output_finite_and_close(
        density in 1e-5f64..5e-3,
        magnitude in prop_oneof![10f32..1e6, Just(-1.0f32)],
        placement in prop_oneof![
            Just(Placement::Random), Just(Placement::Isolated), Just(Placement::Clustered), Just(Placement::Edges), Just(Placement::Border)
        ],
        seed in 1u64..1000,
    ) {
        let (w, h) = (160, 96);
        let clean = Owned::synthetic(w, h, seed, 1.0);
        let mean = clean.noisy.chunks_exact(3).map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).sum::<f32>() / (w * h) as f32;
        let value = if magnitude < 0.0 { 65504.0 } else { magnitude * mean };
        let per = if matches!(placement, Placement::Clustered) { 9.0 } else { 1.0 };
        let count = ((density * (w * h) as f64 / per).round() as usize).max(1);
        let mut dirty = clean.clone();
        place(&mut dirty, placement, count, value, seed);
        let cfg = FlrConfig::with_guides(GuideSet::NORMAL_DEPTH_AO);
        let (base, _) = denoise(cfg, &clean);
        let (out, _) = denoise(cfg, &dirty);
        let (unclamped, _) = denoise(FlrConfig { fireflies: None, ..cfg }, &dirty);
        prop_assert!(out.iter().all(|v| v.is_finite()));
        let err = relative_error(&out, &base);
        let err_off = relative_error(&unclamped, &base);
        prop_assert!(err <= err_off + 0.01, "clamped {err} vs unclamped {err_off}");
        if matches!(placement, Placement::Isolated | Placement::Edges) {
            prop_assert!(err <= 0.05, "{count} outliers of {value}: error {err} (unclamped {err_off})");
        }
    }
}
