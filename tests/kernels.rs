//! Fast paths against their plain versions: the four-cell (f64x4) solve against
//! the one-cell solve (bit-identical, degenerate cells included), and the
//! interleaved / planar row accessors of the image views against element reads.

use lrdenoise::kernels::solve::{solve_cell, solve_cells4, SolveParams};
use lrdenoise::kernels::{model_len, moment_count, CellLayout};
use lrdenoise::*;
use proptest::prelude::*;

/// Moments of `n` random samples (guides with an offset and scale, one guide a
/// duplicate of another when `dup`, one constant when `constant`), in the cell layout.
fn cell<const Q: usize>(seed: u64, n: usize, offset: f64, scale: f64, dup: bool, constant: bool) -> Vec<f64> {
    let lay = CellLayout::new(Q);
    let mut c = vec![0f64; lay.k];
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..n {
        let mut g = [0f64; Q];
        for v in g.iter_mut() {
            *v = offset + scale * rnd();
        }
        if dup && Q > 1 {
            g[1] = g[0];
        }
        if constant && Q > 2 {
            g[2] = offset;
        }
        let y = [rnd() * 2.0, rnd(), 0.5 + g.first().copied().unwrap_or(0.0) * 1e-3];
        c[0] += 1.0;
        let mut p = lay.ss;
        for a in 0..Q {
            c[lay.s + a] += g[a];
            for b in a..Q {
                c[p] += g[a] * g[b];
                p += 1;
            }
            for ch in 0..3 {
                c[lay.p + 3 * a + ch] += g[a] * y[ch];
            }
        }
        for ch in 0..3 {
            c[lay.t + ch] += y[ch];
        }
    }
    c
}

fn params(regularization: Regularization) -> SolveParams {
    SolveParams {
        reference: [0.0; MAX_GUIDES],
        mean: [0.3; MAX_GUIDES],
        scale: [0.7; MAX_GUIDES],
        regularization,
        weight_norm: 1.0 / 64.0,
        min_weight: 1e-9,
    }
}

fn check_lanes<const Q: usize>(cells: &[f64], p: &SolveParams) {
    let (k, ml) = (moment_count(Q), model_len(Q));
    let mut one = vec![0f32; 4 * ml];
    let mut four = vec![7f32; 4 * ml];
    let o4 = solve_cells4::<Q>(cells, p, &mut four);
    for l in 0..4 {
        let o1 = solve_cell::<Q>(&cells[l * k..(l + 1) * k], p, &mut one[l * ml..(l + 1) * ml]);
        assert_eq!(o1, o4[l], "lane {l}");
    }
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&one), bits(&four));
    assert!(four.iter().all(|v| v.is_finite()));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn four_cell_solve_is_bit_identical(seed in 0u64..1 << 40, offset in -1e4f64..1e4, scale_exp in -3f64..3.0, kinds in 0u32..256) {
        let scale = 10f64.powf(scale_exp);
        let mut cells = Vec::new();
        for l in 0..4 {
            let kind = kinds >> (2 * l) & 3;
            let mut c = cell::<5>(seed + l as u64, 40, offset, scale, kind == 1, kind == 2);
            if kind == 3 {
                // empty, or a NaN moment
                if seed % 2 == 0 { c.fill(0.0) } else { c[7] = f64::NAN }
            }
            cells.extend(c);
        }
        for reg in [Regularization::Normalized { eps_mul: 1e-3, eps_add: 1e-2 }, Regularization::Normalized { eps_mul: 0.0, eps_add: 0.0 }, Regularization::Tikhonov { eps: 1e-4 }] {
            check_lanes::<5>(&cells, &params(reg));
        }
    }
}

#[test]
fn four_cell_solve_every_guide_count() {
    fn run<const Q: usize>() {
        let mut cells = Vec::new();
        for l in 0..4 {
            cells.extend(cell::<Q>(l, 30 + l as usize, 1.0, 0.1, l == 1, l == 2));
        }
        check_lanes::<Q>(&cells, &params(Regularization::Normalized { eps_mul: 1e-3, eps_add: 1e-2 }));
    }
    run::<0>();
    run::<1>();
    run::<3>();
    run::<5>();
    run::<8>();
    run::<12>();
}

/// f16 rows read one channel at a time (`read_row`: contiguous halves in bulk,
/// strided one at a time) and three at a time (`read_row_n`: planar per
/// channel; interleaved RGB and RGBA in 16-pixel bulk chunks and a per-pixel
/// tail; other strides per value) give exactly `f16::to_f32` of every sample,
/// specials and subnormals included.
#[test]
fn f16_rows_convert_exactly() {
    let (w, h) = (45, 3);
    let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, 6e-8, -3e-6, 65504.0, 1e-5];
    let same = |g: f32, want: f32| g.to_bits() == want.to_bits() || (g.is_nan() && want.is_nan());
    for (ps, cs, chans) in [(1, w * h, 3), (3, 1, 3), (4, 1, 4), (5, 1, 5)] {
        let n = if ps == 1 { chans * w * h } else { ps * w * h };
        let data: Vec<half::f16> = (0..n)
            .map(|i| half::f16::from_f32(if i % 7 == 3 { specials[(i / 7) % specials.len()] } else { i as f32 * 0.37 - 20.0 }))
            .collect();
        let layout = Layout { offset: 0, pixel_stride: ps, row_stride: w * ps, channel_stride: cs };
        let v = ImageView::f16(&data, w, h, chans, layout).unwrap();
        let want = |ch: usize, y: usize, x: usize| data[y * w * ps + x * ps + ch * cs].to_f32();
        for y in 0..h {
            for (x0, len) in [(0, w), (5, 33), (44, 1), (3, 16), (2, 17)] {
                let mut rows = [vec![0f32; len], vec![0f32; len], vec![0f32; len]];
                for (ch, row) in rows.iter_mut().enumerate() {
                    v.read_row(y, ch, x0, row).unwrap();
                    for (i, g) in row.iter().enumerate() {
                        assert!(same(*g, want(ch, y, x0 + i)), "read_row ps {ps} ch {ch} y {y} x {}: {g}", x0 + i);
                    }
                }
                // overwrite what read_row wrote (12345 is no sample's value)
                rows.iter_mut().for_each(|r| r.fill(12345.0));
                let [a, b, c] = &mut rows;
                v.read_row_n(y, x0, [a, b, c]).unwrap();
                for (ch, row) in rows.iter().enumerate() {
                    for (i, g) in row.iter().enumerate() {
                        assert!(same(*g, want(ch, y, x0 + i)), "read_row_n ps {ps} ch {ch} y {y} x {}: {g}", x0 + i);
                    }
                }
            }
        }
    }
}

#[test]
fn row_access_matches_element_reads() {
    let (w, h) = (37, 5);
    for (ps, cs, extra) in [(3, 1, 0), (4, 1, 0), (5, 1, 2), (1, w * h, 0)] {
        let layout = Layout { offset: extra, pixel_stride: ps, row_stride: if ps == 1 { w } else { w * ps + 3 }, channel_stride: cs };
        let len = extra + (h - 1) * layout.row_stride + (w - 1) * ps + 2 * cs + 1;
        let data: Vec<f32> = (0..len).map(|i| i as f32 * 0.5 - 3.0).collect();
        let v = ImageView::f32(&data, w, h, 3, layout).unwrap();
        for (y, x0, n) in [(0, 0, w), (4, 3, 30), (2, 36, 1), (1, 1, 9)] {
            let (mut a, mut b, mut c) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
            v.read_row_n(y, x0, [&mut a, &mut b, &mut c]).unwrap();
            for i in 0..n {
                let e = |ch| v.get(x0 + i, y, ch).unwrap();
                assert_eq!((a[i], b[i], c[i]), (e(0), e(1), e(2)), "layout {layout:?} y {y} x {}", x0 + i);
            }
            // one channel at a time (interleaved RGB / RGBA: constant-stride
            // extraction; other strides per value)
            for ch in 0..3 {
                let mut r = vec![12345f32; n];
                v.read_row(y, ch, x0, &mut r).unwrap();
                assert!((0..n).all(|i| r[i] == v.get(x0 + i, y, ch).unwrap()), "read_row {layout:?} y {y} ch {ch}");
            }
            match v.row_f32(y, 1, x0, n) {
                Some(r) => {
                    assert_eq!(ps, 1);
                    assert_eq!(r, &b[..]);
                }
                None => assert_ne!(ps, 1),
            }
            // write the planes back (shuffled) and read them again
            let mut out = vec![0f32; len];
            let mut o = ImageViewMut::new(SamplesMut::F32(&mut out), w, h, 3, layout).unwrap();
            o.write_row_n(y, x0, [&c, &a, &b]).unwrap();
            let o = ImageView::f32(&out, w, h, 3, layout).unwrap();
            for i in 0..n {
                assert_eq!(o.get(x0 + i, y, 0).unwrap(), c[i]);
                assert_eq!(o.get(x0 + i, y, 1).unwrap(), a[i]);
                assert_eq!(o.get(x0 + i, y, 2).unwrap(), b[i]);
            }
            // nothing else written
            let written = out.iter().filter(|v| **v != 0.0).count();
            assert!(written <= 3 * n);
        }
    }
}

/// Moments read in place (`moments_rows`) are bit-identical to moments of the
/// same band gathered into weighted planes (`moments_band`), NaN/Inf included.
fn rows_match_planes<const Q: usize>(seed: u64, block: usize, offset: f32, bad: usize) {
    use lrdenoise::kernels::moments::*;
    let (nb, rows) = (5, block);
    let width = nb * block + 3; // a few pixels past the last whole block
    let mut rng = seed | 1;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    let planes_n = 3 + Q;
    // raw rows: planes_n × rows × width
    let mut raw: Vec<f32> = (0..planes_n * rows * width)
        .map(|i| {
            let p = i / (rows * width);
            if p < 3 {
                next() * 4.0
            } else {
                offset * (p as f32 - 2.0) + next() * 3.0
            }
        })
        .collect();
    for _ in 0..bad {
        let i = (next() * raw.len() as f32) as usize % raw.len();
        raw[i] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][i % 3];
    }
    let mut reference = [0f32; 12];
    for (q, r) in reference.iter_mut().enumerate().take(Q) {
        *r = raw[(3 + q) * rows * width + 1];
    }
    let row = |p: usize, r: usize| &raw[(p * rows + r) * width..(p * rows + r + 1) * width];
    let mut band = BandRows { planes: [[&[][..]; 15]; MAX_ROWS], rows, width, reference, demod: None };
    for r in 0..rows {
        for p in 0..planes_n {
            band.planes[r][p] = row(p, r);
        }
    }
    let k = CellLayout::new(Q).k;
    let mut scratch = BlockScratch::default();
    let mut a = vec![0f64; nb * k];
    let counts = moments_rows::<Q>(&band, block, &mut a, &mut scratch, |_, _| {});
    // the same band as the driver gathers it: weight, colours, guides − m, zeros where invalid
    let pw = nb * block;
    let mut planes = vec![0f32; BandPlanes::len(Q, rows, pw)];
    let n = rows * pw;
    let (mut bad_noisy, mut bad_guides) = (0, 0);
    for r in 0..rows {
        for x in 0..pw {
            let nok = (0..3).all(|p| row(p, r)[x].is_finite());
            let gok = (3..planes_n).all(|p| row(p, r)[x].is_finite());
            bad_noisy += !nok as usize;
            bad_guides += !gok as usize;
            let ok = nok && gok;
            planes[r * pw + x] = ok as u32 as f32;
            for p in 0..planes_n {
                let v = row(p, r)[x];
                let v = if p >= 3 { v - reference[p - 3] } else { v };
                planes[(1 + p) * n + r * pw + x] = if ok { v } else { 0.0 };
            }
        }
    }
    let mut b = vec![0f64; nb * k];
    let empty = moments_band::<Q>(BandPlanes { data: &planes, rows, width: pw }, block, true, 0, &mut b, &mut scratch);
    assert_eq!(counts.empty_blocks, empty);
    assert_eq!((counts.nonfinite_noisy, counts.nonfinite_guides), (bad_noisy, bad_guides));
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(x.to_bits() == y.to_bits() || (*x == 0.0 && *y == 0.0), "Q {Q} block {block} moment {i}: {x} vs {y}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn moments_in_place_match_gathered(seed in 0u64..1 << 40, big in proptest::bool::ANY, bad in 0usize..6, b16 in proptest::bool::ANY) {
        let offset = if big { 1e4 } else { 0.5 };
        let block = if b16 { 16 } else { 8 };
        rows_match_planes::<0>(seed, block, offset, bad);
        rows_match_planes::<1>(seed, block, offset, bad);
        rows_match_planes::<5>(seed, block, offset, bad);
        rows_match_planes::<8>(seed, block, offset, bad);
        rows_match_planes::<12>(seed, block, offset, bad);
    }
}

#[test]
fn moments_in_place_whole_block_invalid() {
    // every value NaN: all blocks empty, every pixel counted
    use lrdenoise::kernels::moments::*;
    let nan = vec![f32::NAN; 16];
    let mut band = BandRows { planes: [[&[][..]; 15]; MAX_ROWS], rows: 8, width: 16, reference: [0.0; 12], demod: None };
    for r in 0..8 {
        for p in 0..4 {
            band.planes[r][p] = &nan;
        }
    }
    let mut cells = vec![1f64; 2 * CellLayout::new(1).k];
    let c = moments_rows::<1>(&band, 8, &mut cells, &mut BlockScratch::default(), |_, _| {});
    assert_eq!((c.empty_blocks, c.nonfinite_noisy, c.nonfinite_guides), (2, 128, 128));
    assert!(cells.iter().all(|v| *v == 0.0));
}

/// `ImageView::merged3` joins exactly three consecutive channels of one
/// interleaved f32 RGB/RGBA image (and reading the merged view equals reading
/// each channel), and refuses everything else.
#[test]
fn merged3_joins_only_interleaved_siblings() {
    let (w, h) = (9, 4);
    let data: Vec<f32> = (0..4 * w * h + 1).map(|i| i as f32 * 0.25).collect();
    for (ps, offset) in [(3, 0), (4, 0), (4, 1)] {
        let v = ImageView::f32(&data, w, h, 3, Layout { offset, ..Layout::interleaved(w, ps) }).unwrap();
        let ch = |c| v.channels(c, 1).unwrap();
        let (c0, c1, c2) = (ch(0), ch(1), ch(2));
        let m = ImageView::merged3([&c0, &c1, &c2]).expect("siblings");
        assert_eq!(m.channel_count(), 3);
        for y in 0..h {
            let (mut a, mut b, mut c) = (vec![0f32; w - 2], vec![0f32; w - 2], vec![0f32; w - 2]);
            m.read_row_n(y, 2, [&mut a, &mut b, &mut c]).unwrap();
            for (k, row) in [a, b, c].iter().enumerate() {
                assert!((0..w - 2).all(|i| row[i] == v.get(2 + i, y, k).unwrap()), "ps {ps} y {y} ch {k}");
            }
        }
        assert!(ImageView::merged3([&c1, &c0, &c2]).is_none(), "order");
        assert!(ImageView::merged3([&c0, &c1, &c1]).is_none(), "repeat");
        let copy = data.clone();
        let other = ImageView::f32(&copy, w, h, 3, Layout { offset, ..Layout::interleaved(w, ps) }).unwrap().channels(2, 1).unwrap();
        assert!(ImageView::merged3([&c0, &c1, &other]).is_none(), "another buffer");
        assert!(ImageView::merged3([&v, &c1, &c2]).is_none(), "a 3-channel view");
    }
    // planar channels are read in place, not merged
    let p = ImageView::f32(&data[..3 * w * h], w, h, 3, Layout::planar(w, h)).unwrap();
    let pc = |c| p.channels(c, 1).unwrap();
    assert!(ImageView::merged3([&pc(0), &pc(1), &pc(2)]).is_none());
    // f16 siblings merge too (one bulk-converting pass rather than a strided
    // read converting per value), but never with f32 ones
    for ps in [3usize, 4] {
        let d16: Vec<half::f16> = data.iter().map(|x| half::f16::from_f32(*x)).collect();
        let v16 = ImageView::f16(&d16[..ps * w * h], w, h, 3, Layout::interleaved(w, ps)).unwrap();
        let hc = |c| v16.channels(c, 1).unwrap();
        let m = ImageView::merged3([&hc(0), &hc(1), &hc(2)]).expect("f16 siblings");
        for y in 0..h {
            let (mut a, mut b, mut c) = (vec![0f32; w - 1], vec![0f32; w - 1], vec![0f32; w - 1]);
            m.read_row_n(y, 1, [&mut a, &mut b, &mut c]).unwrap();
            for (k, row) in [a, b, c].iter().enumerate() {
                assert!((0..w - 1).all(|i| row[i] == v16.get(1 + i, y, k).unwrap()), "f16 ps {ps} y {y} ch {k}");
            }
        }
        let v32 = ImageView::f32(&data[..ps * w * h], w, h, 3, Layout::interleaved(w, ps)).unwrap();
        assert!(ImageView::merged3([&hc(0), &hc(1), &v32.channels(2, 1).unwrap()]).is_none(), "f16 with f32");
    }
}
