//! FLNR end to end: FLR fitted on one guide set and applied to another (the
//! mechanism FLNR uses), the pipeline on random weights (finite, typed errors),
//! and the bundled weights on a synthetic frame.

mod common;
#[path = "common/oracles.rs"]
mod oracles;
use common::*;
use lrdenoise::flnr::{self, Flnr, INPUT_GUIDES};
use lrdenoise::*;

#[test]
fn flr_with_the_same_fit_and_map_guides_is_plain_flr() {
    let f = Owned::synthetic(45, 31, 3, 0.6);
    let set = GuideSet::NORMAL_DEPTH_AO;
    let (a, _) = run(cfg(set, 8), &f);
    let mut fr = f.frame(set);
    fr.guides_low = Some(f.guides(set));
    let (b, _) = run_frame(cfg(set, 8), f.w, f.h, &fr);
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    // fitted on the guides, applied to other values: the model follows the map guides
    let mut shifted = f.clone();
    for v in shifted.ao.iter_mut() {
        *v = (*v * 0.5).min(1.0);
    }
    let mut fr = shifted.frame(set);
    fr.guides_low = Some(f.guides(set));
    let (c, _) = run_frame(cfg(set, 8), f.w, f.h, &fr);
    assert!(a.iter().zip(&c).any(|(x, y)| (x - y).abs() > 1e-3));
}

/// A blob with random weights: 8 inputs, 2·q outputs, the given widths.
fn random_blob(q: usize, widths: &[usize]) -> Vec<u8> {
    oracles::blob(8, 2 * q, widths, 10.0, 7)
}

/// A blob with random weights whose network also reads the prior (11 inputs).
fn random_prior_blob(q: usize, widths: &[usize]) -> Vec<u8> {
    oracles::blob(11, 2 * q, widths, 10.0, 7)
}

fn run_flnr(blob: &[u8], f: &Owned) -> Result<(Vec<f32>, Report), Error> {
    let fl = Flnr::new(FlnrConfig::new(blob), f.w, f.h)?;
    let mut scratch = vec![0f32; fl.scratch_len()];
    let mut fs = vec![0f64; fl.flr_scratch_len()];
    let mut out = vec![f32::NAN; 3 * f.w * f.h];
    let rep = fl.denoise(&f.frame(INPUT_GUIDES), &mut scratch, &mut fs, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap())?;
    Ok((out, rep))
}

#[test]
fn random_weights_run_finite_and_errors_are_typed() {
    for &(w, h) in &[(1, 1), (7, 3), (40, 33), (257, 9)] {
        for q in [1, 4] {
            let blob = random_blob(q, &[4, 6]);
            let mut f = Owned::synthetic(w, h, 2, 0.5);
            f.noisy[0] = f32::NAN;
            f.depth[(w * h) / 2] = f32::INFINITY;
            let (out, rep) = run_flnr(&blob, &f).unwrap();
            assert!(out.iter().all(|v| v.is_finite()), "{w}x{h} q={q}");
            assert_eq!(rep.nonfinite_noisy, 1);
        }
    }
    let f = Owned::synthetic(16, 16, 2, 0.5);
    // 5 outputs (odd), 10 outputs (Q' = 5 > 4)
    assert!(matches!(run_flnr(&random_blob(1, &[4])[..], &f).map(|_| ()), Ok(())));
    let mut odd = random_blob(2, &[4]);
    odd[12] = 3;
    assert!(matches!(run_flnr(&odd, &f), Err(Error::InvalidConfig(_))));
    assert!(matches!(Flnr::new(FlnrConfig::new(&random_blob(5, &[4])), 16, 16), Err(Error::InvalidConfig(_))));
    // missing AO
    let blob = random_blob(2, &[4]);
    let fl = Flnr::new(FlnrConfig::new(&blob), 16, 16).unwrap();
    let mut scratch = vec![0f32; fl.scratch_len()];
    let mut fs = vec![0f64; fl.flr_scratch_len()];
    let mut out = vec![0f32; 3 * 256];
    let r =
        fl.denoise(&f.frame(GuideSet::NORMAL_DEPTH), &mut scratch, &mut fs, &mut ImageViewMut::interleaved(&mut out, 16, 16, 3).unwrap());
    assert!(matches!(r, Err(Error::GuideMismatch)));
    let r = fl.denoise(&f.frame(INPUT_GUIDES), &mut scratch[..10], &mut fs, &mut ImageViewMut::interleaved(&mut out, 16, 16, 3).unwrap());
    assert!(matches!(r, Err(Error::ScratchTooSmall { .. })));
}

/// FLNR with the network in tiles of `tile` pixels (`usize::MAX`: whole frame).
fn run_tiled(blob: &[u8], f: &Owned, tile: usize) -> (Vec<f32>, usize) {
    let fl = Flnr::new(FlnrConfig { tile, ..FlnrConfig::new(blob) }, f.w, f.h).unwrap();
    let mut scratch = vec![f32::NAN; fl.scratch_len()];
    let mut fs = vec![0f64; fl.flr_scratch_len()];
    let mut out = vec![f32::NAN; 3 * f.w * f.h];
    fl.denoise(&f.frame(INPUT_GUIDES), &mut scratch, &mut fs, &mut ImageViewMut::interleaved(&mut out, f.w, f.h, 3).unwrap()).unwrap();
    let (nx, ny) = fl.tile_grid();
    (out, nx * ny)
}

#[test]
fn tiles_with_halos_equal_the_whole_frame_bit_for_bit() {
    // 0, 1, 2 and 3 levels; frames from one tile to 5×4 tiles, odd sizes,
    // tiles cut at rows and columns that are not multiples of the block;
    // widths of 6 and 12 run the blocked lanes (with AVX-512, Winograd's
    // pairs of columns)
    for (widths, sizes) in [
        (&[6usize][..], &[(150usize, 70usize)][..]),
        (&[6, 12][..], &[(201, 133)][..]),
        (&[4, 6, 8][..], &[(300, 200), (257, 131), (70, 330), (129, 64)][..]),
        (&[3, 4, 5, 6][..], &[(260, 150)][..]),
    ] {
        for blob in [random_blob(2, widths), random_prior_blob(2, widths)] {
            for &(w, h) in sizes {
                let mut f = Owned::synthetic(w, h, (w * h) as u64, 0.5);
                f.noisy[7] = f32::INFINITY;
                f.normal[3 * (w * h / 3)] = f32::NAN;
                let (whole, one) = run_tiled(&blob, &f, usize::MAX);
                assert_eq!(one, 1);
                assert!(whole.iter().all(|v| v.is_finite()));
                for tile in [64, 100, 128] {
                    let (tiled, count) = run_tiled(&blob, &f, tile);
                    assert!(count > 1, "{w}x{h} tile {tile}");
                    let bad = whole.iter().zip(&tiled).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
                    assert_eq!(bad, 0, "{widths:?} {w}x{h} tile {tile}: {bad} values differ");
                }
            }
        }
    }
    // the halo matters: a tile cut without it would differ (checked by the
    // receptive-radius test below), and tiles below the minimum are refused
    let blob = random_blob(2, &[4, 6, 8]);
    assert!(matches!(Flnr::new(FlnrConfig { tile: 63, ..FlnrConfig::new(&blob) }, 300, 200), Err(Error::InvalidConfig(_))));
}

#[test]
fn split_steps_in_any_tile_order_equal_denoise_bit_for_bit() {
    // what `lrd --threads N` does: the scales, every tile on its own scratch
    // (here in reverse order, on two alternating scratches, as two threads
    // would), scattered into the planes, then FLR on `flr_frame`
    for (blob, &(w, h, tile)) in [random_blob(2, &[4, 6, 8]), random_prior_blob(2, &[4, 6, 8])]
        .iter()
        .flat_map(|b| [(300usize, 200usize, 64usize), (257, 131, 100), (64, 64, 64)].iter().map(move |s| (b, s)))
    {
        let mut f = Owned::synthetic(w, h, 11, 0.5);
        f.noisy[5] = f32::NAN;
        let fl = Flnr::new(FlnrConfig { tile, ..FlnrConfig::new(blob) }, w, h).unwrap();
        let (whole, _) = run_tiled(blob, &f, tile);
        let frame = f.frame(INPUT_GUIDES);
        let scale = fl.input_scale(&frame).unwrap();
        let mut fs = vec![0f64; fl.flr_scratch_len()];
        let mut prior = vec![f32::NAN; fl.prior_len()];
        fl.run_prior(&frame, &mut prior, &mut fs).unwrap();
        let mut planes = vec![f32::NAN; fl.guide_planes_len()];
        let mut scratches = [vec![f32::NAN; fl.tile_scratch_len()], vec![f32::NAN; fl.tile_scratch_len()]];
        let (nx, ny) = fl.tile_grid();
        for t in (0..nx * ny).rev() {
            let tg = fl.network_tile(&frame, scale, &prior, t, &mut scratches[t % 2]).unwrap();
            assert_eq!(tg.rect(), fl.tile_rect(t).unwrap());
            tg.scatter(&mut planes).unwrap();
        }
        assert!(planes.iter().all(|v| v.is_finite()), "{w}x{h}: a tile left a hole");
        let mut out = vec![f32::NAN; 3 * w * h];
        let ff = fl.flr_frame(&frame, &planes).unwrap();
        fl.flr().denoise(&ff, &mut fs, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
        let bad = whole.iter().zip(&out).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(bad, 0, "{w}x{h} tile {tile}: {bad} values differ");
        // typed errors: a tile past the grid, short scratch, short planes
        let count = nx * ny;
        assert!(matches!(fl.network_tile(&frame, scale, &prior, count, &mut scratches[0]), Err(Error::InvalidTile { .. })));
        assert!(matches!(fl.network_tile(&frame, scale, &prior, 0, &mut scratches[0][..3]), Err(Error::ScratchTooSmall { .. })));
        if fl.prior().is_some() {
            assert!(matches!(fl.network_tile(&frame, scale, &prior[..7], 0, &mut scratches[0]), Err(Error::ScratchTooSmall { .. })));
            assert!(matches!(fl.run_prior(&frame, &mut prior[..7], &mut fs), Err(Error::ScratchTooSmall { .. })));
        }
        let tg = fl.network_tile(&frame, scale, &prior, 0, &mut scratches[0]).unwrap();
        assert!(matches!(tg.scatter(&mut planes[..1]), Err(Error::ScratchTooSmall { .. })));
        assert!(matches!(fl.flr_frame(&frame, &planes[..1]), Err(Error::ScratchTooSmall { .. })));
        assert!(matches!(fl.input_scale(&f.frame(GuideSet::NORMAL_DEPTH)), Err(Error::GuideMismatch)));
    }
}

/// A parallel run with fewer tiles than `TILES_PER_WORKER` per worker splits
/// each layer's rows over the workers (one tile, or tiles one after another);
/// with enough tiles it spreads whole tiles. Both equal `denoise` bit for bit
/// on real threads.
#[test]
fn layer_threads_and_tile_threads_equal_denoise_bit_for_bit() {
    for blob in [random_blob(2, &[4, 6, 8]), random_prior_blob(2, &[4, 6, 8])] {
        // (w, h, tile): one tile and three (layer threads), fifteen (tile threads)
        for &(w, h, tile) in &[(150usize, 97usize, 512usize), (150, 60, 64), (257, 131, 64)] {
            let mut f = Owned::synthetic(w, h, 17, 0.5);
            f.noisy[9] = f32::NAN;
            let (whole, count) = run_tiled(&blob, &f, tile);
            let fl = Flnr::new(FlnrConfig { tile, ..FlnrConfig::new(&blob) }, w, h).unwrap();
            for workers in [2, 3] {
                let layers = count < flnr::TILES_PER_WORKER * workers;
                assert_eq!(layers, count <= 3, "{w}x{h} tile {tile}: {count} tiles");
                let mut scratch = vec![f32::NAN; fl.parallel_scratch_len(workers).unwrap()];
                let mut fs = vec![0f64; fl.flr_tiled_scratch_len(workers).unwrap()];
                let mut out = vec![f32::NAN; 3 * w * h];
                let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
                fl.denoise_parallel(&f.frame(INPUT_GUIDES), &mut scratch, &mut fs, &mut ov, workers, &threads(workers)).unwrap();
                let bad = whole.iter().zip(&out).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
                assert_eq!(bad, 0, "{w}x{h} tile {tile} ({count} tiles, layer threads {layers}) workers {workers}: {bad} values differ");
            }
        }
    }
}

/// An 11-input network reads, after the 8 planes of an 8-input one, `ln(1 +
/// max(FLR, 0) / s)` of FLR's defaults output: built here by hand from
/// `Flr` with `FlrConfig::default()` and the network run alone, it gives the
/// same learned guides, and so the same output, as `denoise`.
#[test]
fn the_prior_is_flr_defaults_output_as_the_networks_last_three_inputs() {
    let (w, h) = (67, 45);
    let blob = random_prior_blob(2, &[4, 6]);
    let mut f = Owned::synthetic(w, h, 5, 0.5);
    f.noisy[11] = f32::INFINITY;
    let fl = Flnr::new(FlnrConfig::new(&blob), w, h).unwrap();
    assert!(fl.prior().is_some() && fl.prior_len() == 3 * w * h);
    assert!(Flnr::new(FlnrConfig::new(&random_blob(2, &[4, 6])), w, h).unwrap().prior().is_none());
    let (want, _) = run_flnr(&blob, &f).unwrap();
    // FLR's defaults
    let frame = f.frame(INPUT_GUIDES);
    let flr = Flr::new(FlrConfig::default(), w, h).unwrap();
    let mut fs = vec![0f64; flr.scratch_len().max(fl.flr_scratch_len())];
    let mut prior = vec![0f32; 3 * w * h];
    flr.denoise(&frame, &mut fs, &mut ImageViewMut::interleaved(&mut prior, w, h, 3).unwrap()).unwrap();
    // the network's input by hand: the base planes, then the prior on the light's scale
    let n = w * h;
    let clean = |v: f32| if v.is_finite() { v } else { 0.0 };
    let depths: Vec<f64> = f.depth.iter().filter(|d| d.is_finite() && **d > 0.0).map(|&d| d as f64).collect();
    let dm = (depths.iter().sum::<f64>() / depths.len() as f64) as f32;
    let light = ((f.noisy.iter().map(|&v| clean(v).max(0.0) as f64).sum::<f64>() / (3 * n) as f64) as f32).max(1e-6);
    // ln(1 + v) as the library computes it: `wide`'s, lane by lane
    let log1p = |v: f32| wide::f32x8::splat(v).ln_1p().to_array()[0];
    let mut x = vec![0f32; 11 * n];
    for i in 0..n {
        for c in 0..3 {
            x[c * n + i] = clean(f.normal[3 * i + c]);
            x[(5 + c) * n + i] = log1p(clean(f.noisy[3 * i + c]).max(0.0) / light);
            x[(8 + c) * n + i] = log1p(clean(prior[3 * i + c]).max(0.0) / light);
        }
        x[3 * n + i] = clean(f.depth[i] / dm);
        x[4 * n + i] = clean(f.ao[i]);
    }
    let net = fl.network();
    let mut scratch = vec![0f32; net.scratch_len(w, h)];
    let mut planes = vec![0f32; fl.guide_planes_len()];
    net.forward(&x, w, h, &mut scratch, &mut planes).unwrap();
    let mut out = vec![f32::NAN; 3 * n];
    let lf = fl.flr_frame(&frame, &planes).unwrap();
    fl.flr().denoise(&lf, &mut fs, &mut ImageViewMut::interleaved(&mut out, w, h, 3).unwrap()).unwrap();
    let bad = want.iter().zip(&out).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
    assert_eq!(bad, 0, "{bad} values differ");
    // and the prior matters: the same network without its prior input differs
    let mut x8 = x.clone();
    x8[8 * n..].fill(0.0);
    let mut other = vec![0f32; fl.guide_planes_len()];
    net.forward(&x8, w, h, &mut scratch, &mut other).unwrap();
    assert!(planes.iter().zip(&other).any(|(a, b)| (a - b).abs() > 1e-4));
}

#[test]
fn receptive_radius_is_what_one_input_pixel_reaches() {
    // perturb one input value and find the farthest output that changes: the
    // halo is built from this radius, so it must not be an underestimate
    for (widths, expect) in [(&[4usize][..], 2usize), (&[4, 6][..], 7), (&[4, 6, 8][..], 17)] {
        let blob = random_blob(2, widths);
        let fl = Flnr::new(FlnrConfig::new(&blob), 96, 96).unwrap();
        let net = fl.network();
        assert_eq!(net.receptive_radius(), expect);
        let (w, h) = (96, 96);
        let mut rng = Rng(3);
        let input: Vec<f32> = (0..8 * w * h).map(|_| rng.f32()).collect();
        let mut scratch = vec![0f32; net.scratch_len(w, h)];
        let mut base = vec![0f32; net.out_channels() * w * h];
        net.forward(&input, w, h, &mut scratch, &mut base).unwrap();
        let mut reach = 0;
        for (px, py) in [(44, 44), (45, 45), (46, 47), (47, 46)] {
            let mut inp = input.clone();
            for c in 0..8 {
                inp[c * w * h + py * w + px] += 1.0;
            }
            let mut out = vec![0f32; base.len()];
            net.forward(&inp, w, h, &mut scratch, &mut out).unwrap();
            for (i, (a, b)) in base.iter().zip(&out).enumerate() {
                if a != b {
                    let (x, y) = ((i % (w * h)) % w, (i % (w * h)) / w);
                    reach = reach.max(x.abs_diff(px)).max(y.abs_diff(py));
                }
            }
        }
        assert_eq!(reach, expect, "{widths:?}");
    }
}
