//! The fast path against the slow f64 reference, SIMD against scalar, tiled
//! against whole frame, and awkward sizes.

mod common;
use common::*;
use lrdenoise::*;

const SETS: [GuideSet; 4] = [
    GuideSet::NONE,
    GuideSet::NORMAL_DEPTH,
    GuideSet::NORMAL_DEPTH_AO,
    GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 },
];

#[test]
fn block1_matches_reference_normalized() {
    for (s, set) in SETS.iter().enumerate() {
        let f = Owned::synthetic(29, 23, s as u64, 0.5);
        let mut c = cfg(*set, 1);
        c.blur = Blur::Gaussian { sigma: 3.0, radius: None };
        let (out, rep) = run(c, &f);
        let want = reference(&c, f.w, f.h, &f.channels(*set), &f.noisy);
        let (max, mean) = diff(&out, &want);
        assert!(max < 2e-4 && mean < 2e-5, "set {set:?}: max {max} mean {mean}");
        assert_eq!(rep.nonfinite_noisy, 0);
    }
}

#[test]
fn block1_matches_reference_tikhonov_and_box() {
    let f = Owned::synthetic(31, 19, 3, 0.5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    for blur in [Blur::Gaussian { sigma: 2.5, radius: Some(5.0) }, Blur::Box { radius: 3.0 }] {
        for reg in [Regularization::Tikhonov { eps: 1e-3 }, Regularization::Normalized { eps_mul: 1e-4, eps_add: 1e-4 }] {
            let c = FlrConfig { blur, regularization: reg, ..cfg(set, 1) };
            let (out, _) = run(c, &f);
            let want = reference(&c, f.w, f.h, &f.channels(set), &f.noisy);
            let (max, mean) = diff(&out, &want);
            assert!(max < 5e-4 && mean < 5e-5, "{blur:?} {reg:?}: max {max} mean {mean}");
        }
    }
}

/// The paper's Fig. 3 configuration (B = 1, σ 10, radius 20, Tikhonov 1e-6,
/// features [1, normal, depth, ao]) is the reference exactly, away from borders
/// (and at them too: both drop out-of-image taps).
#[test]
fn fig3_configuration() {
    let f = Owned::synthetic(48, 44, 5, 0.5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let c = FlrConfig {
        blur: Blur::Gaussian { sigma: 10.0, radius: Some(20.0) },
        regularization: Regularization::Tikhonov { eps: 1e-6 },
        ..cfg(set, 1)
    };
    let (out, _) = run(c, &f);
    let want = reference(&c, f.w, f.h, &f.channels(set), &f.noisy);
    let (max, _) = diff(&out, &want);
    assert!(max < 2e-3, "max {max}");
}

/// With larger blocks the model is interpolated between block centres, so the
/// result only approximates the per-pixel reference: the error must stay small
/// next to the noise it removes.
#[test]
fn blocks_approximate_reference() {
    let f = Owned::synthetic(96, 80, 9, 0.5);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let mut c1 = cfg(set, 1);
    c1.blur = Blur::Gaussian { sigma: 12.0, radius: None };
    let want = reference(&c1, f.w, f.h, &f.channels(set), &f.noisy);
    let noise: f64 = f.noisy.iter().zip(&f.clean).map(|(a, b)| (a - b).abs() as f64).sum::<f64>() / f.noisy.len() as f64;
    for b in [2, 4, 8, 16] {
        let c = FlrConfig { block: b, ..c1 };
        let (out, _) = run(c, &f);
        let (_, mean) = diff(&out, &want);
        assert!(mean < 0.25 * noise, "block {b}: mean diff {mean} vs noise {noise}");
    }
}

/// Light that is exactly affine in the guides is reproduced exactly (up to the
/// regularisation bias) by every block size, kernel and upsampling factor.
#[test]
fn affine_signal_is_reproduced() {
    let mut f = Owned::synthetic(53, 37, 11, 0.0);
    for i in 0..f.w * f.h {
        for c in 0..3 {
            f.noisy[3 * i + c] = 0.3 + 0.1 * c as f32 + 0.05 * f.normal[3 * i] - 0.02 * f.depth[i] + 0.2 * f.ao[i];
        }
    }
    let set = GuideSet::NORMAL_DEPTH_AO;
    // With the AO demodulation (the default) the model is s·(affine): that
    // signal, s = √(ao + c) times the same affine one, is what it reproduces.
    let c0 = cfg(set, 8).ao_demodulation.expect("on by default");
    let mut g = f.clone();
    for (i, px) in g.noisy.chunks_exact_mut(3).enumerate() {
        px.iter_mut().for_each(|v| *v *= (f.ao[i].clamp(0.0, 1.0) + c0).sqrt());
    }
    for (demod, f) in [(None, &f), (Some(c0), &g)] {
        for b in [1, 2, 4, 8, 16] {
            for kernel in [Kernel::Simd, Kernel::Scalar] {
                let reg = Regularization::Normalized { eps_mul: 1e-7, eps_add: 1e-7 };
                let c = FlrConfig { kernel, regularization: reg, ao_demodulation: demod, ..cfg(set, b) };
                let (out, _) = run(c, f);
                let err = out.iter().zip(&f.noisy).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
                assert!(err < 2e-3, "block {b} {kernel:?} demodulation {demod:?}: {err}");
            }
        }
    }
}

#[test]
fn simd_matches_scalar() {
    for (s, set) in SETS.iter().enumerate() {
        for (w, h) in [(64, 40), (257, 19), (100, 33)] {
            let f = Owned::synthetic(w, h, 20 + s as u64, 0.7);
            for b in [8, 16] {
                let (a, _) = run(FlrConfig { kernel: Kernel::Simd, ..cfg(*set, b) }, &f);
                let (c, _) = run(FlrConfig { kernel: Kernel::Scalar, ..cfg(*set, b) }, &f);
                let max = a.iter().zip(&c).map(|(x, y)| (x - y).abs() / (1e-3 + y.abs())).fold(0f32, f32::max);
                // Block moments are summed in f32, lane-wise (SIMD) or pixel by pixel
                // (scalar): different rounding over up to 256 pixels, amplified by the
                // solve's conditioning, plus FMA vs mul+add. Measured ≤ 2.5e-4.
                assert!(max < 1e-3, "{set:?} {w}x{h} B{b}: rel {max}");
            }
        }
    }
}

/// Runs the stages by hand, tiles in reverse order, two worker buffers used
/// alternately, output split into row bands: must equal `denoise` bit for bit.
#[test]
fn tiled_equals_whole_frame() {
    // (`denoise` runs each tile's vertical blur as soon as the rows below it
    // exist and takes the stats tile by tile: both blurs, and radii from 1 to
    // 36 cells, reach it.)
    let boxed = |set, b| FlrConfig { blur: Blur::Box { radius: 10.0 }, ..cfg(set, b) };
    // (64, 300, 8): tall enough that `denoise` keeps the horizontally blurred
    // rows in a ring (more cell rows than the ring holds), with a partial last tile.
    for (w, h, b) in [(75, 61, 8), (257, 40, 4), (33, 70, 16), (20, 9, 1), (64, 300, 8)] {
        for (set, c) in SETS.into_iter().flat_map(|set| [(set, cfg(set, b)), (set, boxed(set, b))]) {
            let f = Owned::synthetic(w, h, 7, 0.6);
            let (whole, rep_whole) = run(c, &f);
            let flr = Flr::new(c, w, h).unwrap();
            let mut scratch = vec![0f64; flr.scratch_len_for(2)];
            let p = flr.split_scratch(&mut scratch, 2).unwrap();
            let frame = flr.check_frame(&f.frame(set)).unwrap();
            let (w0, w1) = p.workers.split_at_mut(flr.worker_len());
            let workers = [w0, w1];
            let mut stats = flr.prepare(&frame);
            let nt = flr.tile_count();
            let c = |t: usize| flr.cells_tile_range(t).unwrap();
            let m = |t: usize| flr.models_tile_range(t).unwrap();
            let mut rep = Report::default();
            for t in (0..nt).rev() {
                rep += flr.moments_tile(&frame, &stats, t, &mut p.cells[c(t)], workers[t % 2]).unwrap();
            }
            flr.finish_stats(p.cells, &mut stats).unwrap();
            for t in (0..nt).rev() {
                flr.blur_rows_tile(t, p.cells, &mut p.tmp[c(t)]).unwrap();
            }
            for t in (0..nt).rev() {
                flr.blur_cols_tile(t, p.tmp, &mut p.cells[c(t)]).unwrap();
            }
            for t in (0..nt).rev() {
                rep += flr.solve_tile(&stats, t, &p.cells[c(t)], &mut p.models[m(t)]).unwrap();
            }
            let mut out = vec![0f32; w * h * 3];
            let mut rest = Some(ImageViewMut::interleaved(&mut out, w, h, 3).unwrap());
            let mut bands = vec![];
            for t in 0..nt {
                let (y0, y1) = flr.tile_pixel_rows(t).unwrap();
                let (band, r) = rest.take().unwrap().split_rows(y1 - y0).unwrap();
                bands.push((t, y0, band));
                rest = r;
            }
            for (t, _, band) in bands.iter_mut().rev() {
                rep += flr.apply_tile(&frame, &stats, *t, p.models, workers[*t % 2], band).unwrap();
            }
            drop(bands);
            assert_eq!(rep, rep_whole);
            assert!(out.iter().zip(&whole).all(|(a, b)| a.to_bits() == b.to_bits()), "{w}x{h} B{b} {set:?}");
        }
    }
}

/// `blur_cols_tiles` over a band of tiles equals one tile at a time bit for
/// bit, for both blurs, on HDR moment grids where running sums round (a
/// sliding box window started at the band, not the tile, once broke this).
#[test]
fn vertical_blur_band_equals_tiles() {
    for blur in [Blur::Gaussian { sigma: 12.0, radius: None }, Blur::Box { radius: 10.0 }] {
        for (w, h, b) in [(30, 90, 2), (64, 200, 4), (9, 300, 8)] {
            let flr = Flr::new(FlrConfig { blur, ..cfg(GuideSet::NORMAL_DEPTH_AO, b) }, w, h).unwrap();
            let nt = flr.tile_count();
            let len = flr.cells_tile_range(nt - 1).unwrap().end;
            let mut rng = 0x9e3779b97f4a7c15u64;
            let tmp: Vec<f64> = (0..len)
                .map(|i| {
                    rng ^= rng << 13;
                    rng ^= rng >> 7;
                    rng ^= rng << 17;
                    (rng >> 11) as f64 / (1u64 << 53) as f64 * [1e-6, 1.0, 1e9, 3e3][i % 4]
                })
                .collect();
            let mut one = vec![0f64; len];
            for t in 0..nt {
                flr.blur_cols_tile(t, &tmp, &mut one[flr.cells_tile_range(t).unwrap()]).unwrap();
            }
            for step in [2, 3, 4, nt] {
                let mut band = vec![0f64; len];
                for t0 in (0..nt).step_by(step) {
                    let t1 = (t0 + step).min(nt);
                    let r = flr.cells_tile_range(t0).unwrap().start..flr.cells_tile_range(t1 - 1).unwrap().end;
                    flr.blur_cols_tiles(t0..t1, &tmp, &mut band[r]).unwrap();
                }
                assert!(one.iter().zip(&band).all(|(a, b)| a.to_bits() == b.to_bits()), "{blur:?} {w}x{h} B{b} step {step}");
            }
        }
    }
}

#[test]
fn awkward_sizes() {
    let sizes = [(1, 1), (7, 3), (3, 7), (255, 5), (256, 5), (257, 5), (17, 1), (1, 17), (9, 9)];
    for (w, h) in sizes {
        for b in [1, 2, 4, 8, 16] {
            for set in SETS {
                let f = Owned::synthetic(w, h, 1, 0.5);
                for kernel in [Kernel::Simd, Kernel::Scalar] {
                    let (out, _) = run(FlrConfig { kernel, ..cfg(set, b) }, &f);
                    assert!(out.iter().all(|v| v.is_finite()), "{w}x{h} B{b} {set:?}");
                }
                if w * h <= 64 {
                    // small frames: compare the B = 1 path with the reference too
                    let c = FlrConfig { blur: Blur::Gaussian { sigma: 2.0, radius: None }, ..cfg(set, 1) };
                    let (out, _) = run(c, &f);
                    let want = reference(&c, w, h, &f.channels(set), &f.noisy);
                    assert!(diff(&out, &want).0 < 5e-4, "{w}x{h} {set:?}");
                }
            }
        }
    }
}

/// Normals in an RGBA buffer and positions interleaved RGB (each read in one
/// de-interleaving pass, `ImageView::merged3`), depth and AO between and after
/// them: bit-identical to the same guides planar, at sizes with a partial
/// right-edge block and an odd block row count.
#[test]
fn interleaved_triples_equal_planar() {
    let set = GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 };
    for (w, h, b) in [(75, 41, 8), (64, 40, 16), (33, 17, 4)] {
        let f = Owned::synthetic(w, h, 9, 0.5);
        let c = cfg(set, b);
        let n = w * h;
        let mut normal4 = vec![0f32; 4 * n];
        let (mut normal_p, mut position_p) = (vec![0f32; 3 * n], vec![0f32; 3 * n]);
        for i in 0..n {
            for ch in 0..3 {
                normal4[4 * i + ch] = f.normal[3 * i + ch];
                normal_p[ch * n + i] = f.normal[3 * i + ch];
                position_p[ch * n + i] = f.position[3 * i + ch];
            }
        }
        let noisy = ImageView::interleaved(&f.noisy, w, h, 3).unwrap();
        let interleaved = Guides {
            normal: Some(ImageView::f32(&normal4, w, h, 3, Layout::interleaved(w, 4)).unwrap()),
            depth: Some(ImageView::interleaved(&f.depth, w, h, 1).unwrap()),
            position: Some(ImageView::interleaved(&f.position, w, h, 3).unwrap()),
            ao: Some(ImageView::interleaved(&f.ao, w, h, 1).unwrap()),
            ..Default::default()
        };
        let pl = Layout::planar(w, h);
        let planar = Guides {
            normal: Some(ImageView::f32(&normal_p, w, h, 3, pl).unwrap()),
            position: Some(ImageView::f32(&position_p, w, h, 3, pl).unwrap()),
            ..interleaved
        };
        let (a, ra) = run_frame(c, w, h, &Frame::new(noisy, interleaved));
        let (p, rp) = run_frame(c, w, h, &Frame::new(noisy, planar));
        assert_eq!(ra, rp);
        assert!(a.iter().zip(&p).all(|(x, y)| x.to_bits() == y.to_bits()), "{w}x{h} B{b}");
    }
}

/// The layouts engines hold frames in: RGBA light and RGBA normals with depth
/// in their fourth value, f32 or f16 (the f16 triples also read in one pass,
/// `ImageView::merged3`; depth picked from the converted pixels), output
/// into an RGBA buffer whose fourth channel must stay untouched. Bit-identical
/// to the same values planar (an f16 value reads exactly), at sizes with a
/// partial right-edge block and widths around the 64-pixel read chunks.
#[test]
fn rgba_and_f16_layouts_equal_planar() {
    let set = GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 };
    for (w, h, b) in [(75, 41, 8), (129, 17, 8), (33, 17, 4)] {
        let f = Owned::synthetic(w, h, 9, 0.5);
        let c = cfg(set, b);
        let n = w * h;
        let h16 = |v: &[f32]| v.iter().map(|x| half::f16::from_f32(*x)).collect::<Vec<_>>();
        let back = |v: &[half::f16]| v.iter().map(|x| x.to_f32()).collect::<Vec<_>>();
        let rgba = |v: &[f32]| {
            let mut o = vec![-5f32; 4 * n];
            for i in 0..n {
                o[4 * i..4 * i + 3].copy_from_slice(&v[3 * i..3 * i + 3]);
            }
            o
        };
        let planar3 = |v: &[f32]| {
            let mut o = vec![0f32; 3 * n];
            for i in 0..n {
                for ch in 0..3 {
                    o[ch * n + i] = v[3 * i + ch];
                }
            }
            o
        };
        let pl = Layout::planar(w, h);
        for half in [false, true] {
            // the values both runs see: the inputs, or their f16 roundings
            let vals = |v: &[f32]| if half { back(&h16(v)) } else { v.to_vec() };
            let (noisy, normal, position, depth, ao) = (vals(&f.noisy), vals(&f.normal), vals(&f.position), vals(&f.depth), vals(&f.ao));
            // the normal buffer carries depth in its fourth value (a common G-buffer)
            let mut normal4 = rgba(&normal);
            for i in 0..n {
                normal4[4 * i + 3] = depth[i];
            }
            let noisy4 = rgba(&noisy);
            let (noisy4_16, normal4_16, position_16, ao_16) = (h16(&noisy4), h16(&normal4), h16(&position), h16(&ao));
            fn view4<'a>(half: bool, v: &'a [f32], v16: &'a [half::f16], w: usize, h: usize) -> ImageView<'a> {
                if half {
                    ImageView::f16(v16, w, h, 3, Layout::interleaved(w, 4)).unwrap()
                } else {
                    ImageView::f32(v, w, h, 3, Layout::interleaved(w, 4)).unwrap()
                }
            }
            let engine = Guides {
                normal: Some(view4(half, &normal4, &normal4_16, w, h)),
                position: Some(if half {
                    ImageView::f16(&position_16, w, h, 3, Layout::interleaved(w, 3)).unwrap()
                } else {
                    ImageView::interleaved(&position, w, h, 3).unwrap()
                }),
                depth: Some({
                    let w_of_normal = Layout { offset: 3, ..Layout::interleaved(w, 4) };
                    if half {
                        ImageView::f16(&normal4_16, w, h, 1, w_of_normal).unwrap()
                    } else {
                        ImageView::f32(&normal4, w, h, 1, w_of_normal).unwrap()
                    }
                }),
                ao: Some(if half { ImageView::f16(&ao_16, w, h, 1, pl).unwrap() } else { ImageView::f32(&ao, w, h, 1, pl).unwrap() }),
                ..Default::default()
            };
            let flr = Flr::new(c, w, h).unwrap();
            let mut scratch = vec![0f64; flr.scratch_len()];
            let mut out4 = vec![7f32; 4 * n];
            let mut ov = ImageViewMut::new(SamplesMut::F32(&mut out4), w, h, 3, Layout::interleaved(w, 4)).unwrap();
            let ra = flr.denoise(&Frame::new(view4(half, &noisy4, &noisy4_16, w, h), engine), &mut scratch, &mut ov).unwrap();
            let (normal_p, position_p, noisy_p) = (planar3(&normal), planar3(&position), planar3(&noisy));
            let planar = Guides {
                normal: Some(ImageView::f32(&normal_p, w, h, 3, pl).unwrap()),
                position: Some(ImageView::f32(&position_p, w, h, 3, pl).unwrap()),
                depth: Some(ImageView::f32(&depth, w, h, 1, pl).unwrap()),
                ao: Some(ImageView::f32(&ao, w, h, 1, pl).unwrap()),
                ..Default::default()
            };
            let (p, rp) = run_frame(c, w, h, &Frame::new(ImageView::f32(&noisy_p, w, h, 3, pl).unwrap(), planar));
            assert_eq!(ra, rp);
            for i in 0..n {
                for ch in 0..3 {
                    assert_eq!(out4[4 * i + ch].to_bits(), p[3 * i + ch].to_bits(), "{w}x{h} B{b} f16 {half}: pixel {i} channel {ch}");
                }
                assert_eq!(out4[4 * i + 3], 7.0, "{w}x{h} B{b} f16 {half}: the fourth channel was written");
            }
        }
    }
}

#[test]
fn interleaved_planar_and_f16_agree() {
    let f = Owned::synthetic(40, 24, 4, 0.5);
    let set = GuideSet::NORMAL_DEPTH;
    let c = cfg(set, 8);
    let (a, _) = run(c, &f);
    let (w, h) = (f.w, f.h);
    // planar noisy and normal, depth as the 2nd channel of an RGBA-like buffer
    let mut noisy_p = vec![0f32; 3 * w * h];
    let mut normal_p = vec![0f32; 3 * w * h];
    let mut depth4 = vec![0f32; 4 * w * h];
    for i in 0..w * h {
        for ch in 0..3 {
            noisy_p[ch * w * h + i] = f.noisy[3 * i + ch];
            normal_p[ch * w * h + i] = f.normal[3 * i + ch];
        }
        depth4[4 * i + 1] = f.depth[i];
    }
    let pl = Layout::planar(w, h);
    let guides = Guides {
        normal: Some(ImageView::f32(&normal_p, w, h, 3, pl).unwrap()),
        depth: Some(ImageView::f32(&depth4, w, h, 1, Layout { offset: 1, ..Layout::interleaved(w, 4) }).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::f32(&noisy_p, w, h, 3, pl).unwrap(), guides);
    let (b, _) = run_frame(c, w, h, &frame);
    assert_eq!(a, b);
    // f16 inputs: same up to f16 rounding of the inputs
    let h16 = |v: &[f32]| v.iter().map(|x| half::f16::from_f32(*x)).collect::<Vec<_>>();
    let (n16, nr16, d16) = (h16(&f.noisy), h16(&f.normal), h16(&f.depth));
    let guides = Guides {
        normal: Some(ImageView::f16(&nr16, w, h, 3, Layout::interleaved(w, 3)).unwrap()),
        depth: Some(ImageView::f16(&d16, w, h, 1, Layout::interleaved(w, 1)).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::f16(&n16, w, h, 3, Layout::interleaved(w, 3)).unwrap(), guides);
    let (c16, _) = run_frame(c, w, h, &frame);
    let max = a.iter().zip(&c16).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    assert!(max < 2e-2, "f16 {max}");
}

/// Every output layout holds the same bits: interleaved RGB f32, which the
/// apply writes as it computes (with non-temporal stores at and above
/// `image::STREAM_MIN_BYTES`, where the row starts 16-byte aligned), the same
/// one float off that alignment (then through three planes and
/// `write_row_n`), planar, and RGBA; with the defaults (adaptive window, AO
/// demodulation), without the demodulation, and with one window at B = 16.
#[test]
fn output_layouts_agree_streamed_or_not() {
    let set = GuideSet { normal: true, depth: true, position: false, ao: true, user: 0 };
    let big_w = lrdenoise::image::STREAM_MIN_BYTES / (12 * 96) + 1; // 96 rows of interleaved RGB ≥ the threshold
    let configs = [
        FlrConfig { guides: set, ..FlrConfig::default() },
        FlrConfig { guides: set, ao_demodulation: None, ..FlrConfig::default() },
        FlrConfig { guides: set, block: 16, blur: Blur::Gaussian { sigma: 12.0, radius: None }, ..FlrConfig::default() },
    ];
    for (w, h) in [(75, 41), (big_w, 96)] {
        let f = Owned::synthetic(w, h, 5, 0.5);
        let n = w * h;
        let streamed = 12 * n >= lrdenoise::image::STREAM_MIN_BYTES;
        assert_eq!(streamed, w == big_w);
        for c in configs {
            let flr = Flr::new(c, w, h).unwrap();
            let mut scratch = vec![0f64; flr.scratch_len()];
            let mut run = |out: &mut ImageViewMut<'_>| flr.denoise(&f.frame(set), &mut scratch, out).unwrap();
            // interleaved RGB at a 16-byte aligned start, and one float after it
            let mut buf = vec![f32::NAN; 3 * n + 8];
            let at = (0..4).find(|k| (buf.as_ptr() as usize + 4 * k).is_multiple_of(16)).unwrap();
            let mut rgb = |off: usize, buf: &mut Vec<f32>| {
                let l = Layout { offset: off, ..Layout::interleaved(w, 3) };
                let rep = run(&mut ImageViewMut::new(SamplesMut::F32(buf), w, h, 3, l).unwrap());
                (buf[off..off + 3 * n].to_vec(), rep)
            };
            let (aligned, ra) = rgb(at, &mut buf);
            let (shifted, rs) = rgb(at + 1, &mut buf);
            let mut planar = vec![f32::NAN; 3 * n];
            let rp = run(&mut ImageViewMut::new(SamplesMut::F32(&mut planar), w, h, 3, Layout::planar(w, h)).unwrap());
            let mut rgba = vec![-3f32; 4 * n];
            let rr = run(&mut ImageViewMut::new(SamplesMut::F32(&mut rgba), w, h, 3, Layout::interleaved(w, 4)).unwrap());
            assert!(ra == rs && ra == rp && ra == rr);
            for i in 0..n {
                for ch in 0..3 {
                    let want = aligned[3 * i + ch];
                    assert!(want.is_finite());
                    let got = [shifted[3 * i + ch], planar[ch * n + i], rgba[4 * i + ch]];
                    assert!(got.iter().all(|g| g.to_bits() == want.to_bits()), "{w}x{h} pixel {i} channel {ch}: {want} vs {got:?}");
                }
                assert_eq!(rgba[4 * i + 3], -3.0, "the fourth channel is left as it was");
            }
        }
    }
}

/// Per-pixel sample weights (`Frame::sample_weights`): random weights, zeros and
/// weights that are not finite and positive (which exclude their pixel)
/// against the f64 reference with each pixel's taps and frame statistics
/// multiplied by its weight, for every guide set, with and without the AO
/// demodulation; every output is finite, a weight-0 pixel included.
#[test]
fn sample_weights_match_reference() {
    for (s, set) in SETS.iter().enumerate() {
        let f = Owned::synthetic(29, 23, 40 + s as u64, 0.5);
        let mut seed = 91 + s as u32;
        let mut weights: Vec<f32> = (0..f.w * f.h).map(|_| 3.0 * lrdenoise_test_uniform(&mut seed)).collect();
        for (i, w) in weights.iter_mut().enumerate() {
            match i % 11 {
                0 => *w = 0.0,
                3 if i % 7 == 0 => *w = f32::NAN,
                5 if i % 7 == 0 => *w = -1.0,
                7 if i % 7 == 0 => *w = f32::INFINITY,
                _ => {}
            }
        }
        let wide: Vec<f64> = weights.iter().map(|&v| v as f64).collect();
        for demod in [None, Some(0.1)] {
            let mut c = FlrConfig { ao_demodulation: demod, ..cfg(*set, 1) };
            c.blur = Blur::Gaussian { sigma: 3.0, radius: None };
            let mut frame = f.frame(*set);
            frame.sample_weights = Some(ImageView::interleaved(&weights, f.w, f.h, 1).unwrap());
            let (out, _) = run_frame(c, f.w, f.h, &frame);
            let want = reference_weighted(&c, f.w, f.h, &f.channels(*set), &f.noisy, Some(&wide));
            let (max, mean) = diff(&out, &want);
            assert!(max < 5e-4 && mean < 5e-5, "set {set:?} demodulation {demod:?}: max {max} mean {mean}");
            assert!(out.iter().all(|v| v.is_finite()));
            // and the weights make a difference the reference sees
            let plain = reference(&c, f.w, f.h, &f.channels(*set), &f.noisy);
            let (moved, _) = diff(&out, &plain);
            assert!(moved > 10.0 * max, "set {set:?}: weights moved the output by {moved} only");
        }
    }
}

/// Uniform weights fit as no weights (bit for bit: they scale to exactly 1),
/// in blocks of 8 and 16; weighted SIMD and scalar agree, with zero, NaN and
/// +∞ weights among random ones; tiles over threads equal the whole frame bit
/// for bit with weights; every output is finite.
#[test]
fn sample_weights_uniform_simd_and_tiles() {
    let set = GuideSet::NORMAL_DEPTH_AO;
    for (w, h) in [(64, 40), (257, 19), (7, 3)] {
        let f = Owned::synthetic(w, h, 77, 0.7);
        let uniform = vec![4.0f32; w * h];
        let mut seed = 5u32;
        let random: Vec<f32> = (0..w * h)
            .map(|i| match i % 13 {
                0 => 0.0,
                4 => f32::NAN,
                9 => f32::INFINITY,
                _ => 0.1 + 2.0 * lrdenoise_test_uniform(&mut seed),
            })
            .collect();
        for b in [8, 16] {
            let (plain, _) = run(cfg(set, b), &f);
            let weighted = |weights: &[f32], kernel: Kernel| {
                let mut frame = f.frame(set);
                frame.sample_weights = Some(ImageView::interleaved(weights, w, h, 1).unwrap());
                run_frame(FlrConfig { kernel, ..cfg(set, b) }, w, h, &frame).0
            };
            let rel = |a: &[f32], c: &[f32]| {
                assert!(a.iter().chain(c).all(|v| v.is_finite()), "{w}x{h} B{b}: an output is not finite");
                a.iter().zip(c).map(|(x, y)| (x - y).abs() / (1e-3 + y.abs())).fold(0f32, f32::max)
            };
            let u = weighted(&uniform, Kernel::Simd);
            assert!(u.iter().zip(&plain).all(|(a, b)| a.to_bits() == b.to_bits()), "{w}x{h} B{b}: uniform weights moved the output");
            let (simd, scalar) = (weighted(&random, Kernel::Simd), weighted(&random, Kernel::Scalar));
            assert!(rel(&simd, &scalar) < 1e-3, "{w}x{h} B{b}: SIMD vs scalar {}", rel(&simd, &scalar));
            // tiles over two threads, bit for bit
            let c = cfg(set, b);
            let flr = Flr::new(c, w, h).unwrap();
            let mut scratch = vec![0f64; flr.tiled_scratch_len(2).unwrap()];
            let mut out = vec![f32::NAN; w * h * 3];
            let mut frame = f.frame(set);
            frame.sample_weights = Some(ImageView::interleaved(&random, w, h, 1).unwrap());
            let exec = |n: usize, job: &(dyn Fn(usize, usize) + Sync)| {
                std::thread::scope(|s| {
                    for worker in 0..2 {
                        s.spawn(move || (worker..n).step_by(2).for_each(|i| job(i, worker)));
                    }
                })
            };
            flr.denoise_parallel(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap(), 2, &exec).unwrap();
            assert_eq!(out, simd, "{w}x{h} B{b}: tiles over threads differ from the whole frame");
        }
    }
    // a weight image of another size is refused
    let f = Owned::synthetic(16, 8, 1, 0.5);
    let small = vec![1.0f32; 8 * 8];
    let mut frame = f.frame(set);
    frame.sample_weights = Some(ImageView::interleaved(&small, 8, 8, 1).unwrap());
    let flr = Flr::new(cfg(set, 8), 16, 8).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut out = vec![0f32; 16 * 8 * 3];
    let err = flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, 16, 8, 3).unwrap()).unwrap_err();
    assert!(matches!(err, Error::SizeMismatch { arg: error::Arg::Weights, .. }), "{err:?}");
}

/// A checkerboard of weights 0 and 1 (a frame rendered on half its pixels):
/// what the unrendered pixels hold (huge values, NaN) changes no output bit,
/// and every pixel, the unrendered ones included, gets a finite prediction.
/// (Without the firefly clamp, whose statistics take every finite pixel
/// whatever its weight: `Frame::sample_weights`.)
#[test]
fn weight_zero_pixels_do_not_reach_the_fit() {
    let set = GuideSet::NORMAL_DEPTH_AO;
    for (w, h, b) in [(64, 40, 8), (37, 21, 8), (33, 17, 1)] {
        let f = Owned::synthetic(w, h, 12, 0.5);
        let board: Vec<f32> = (0..w * h).map(|i| ((i % w + i / w) % 2) as f32).collect();
        let run_with = |noisy: &[f32]| {
            let mut g = f.clone();
            g.noisy = noisy.to_vec();
            let mut frame = g.frame(set);
            frame.sample_weights = Some(ImageView::interleaved(&board, w, h, 1).unwrap());
            run_frame(FlrConfig { block: b, fireflies: None, ..FlrConfig::with_guides(set) }, w, h, &frame)
        };
        let (want, _) = run_with(&f.noisy);
        assert!(want.iter().all(|v| v.is_finite()));
        for garbage in [1e6f32, f32::NAN] {
            let noisy: Vec<f32> = f.noisy.iter().enumerate().map(|(i, &v)| if board[i / 3] == 0.0 { garbage } else { v }).collect();
            let (got, _) = run_with(&noisy);
            assert!(
                got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{w}x{h} B{b}: {garbage} in unrendered pixels moved the output"
            );
        }
    }
}

/// Uniform in [0, 1) from a small xorshift (the tests' own, no dependency).
fn lrdenoise_test_uniform(s: &mut u32) -> f32 {
    *s ^= *s << 13;
    *s ^= *s >> 17;
    *s ^= *s << 5;
    (*s >> 8) as f32 / (1u32 << 24) as f32
}
