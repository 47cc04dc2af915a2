//! Householder QR least squares (BMFR's kernel) against f64 oracles.

mod common;
use common::Rng;
use lrdenoise::kernels::qr::{lstsq, lstsq_ld, lstsq_shrunk_ld, padded_ld, Shrinkage};
use proptest::prelude::*;

/// Column-major rows × (m + k) matrix.
struct Problem {
    rows: usize,
    m: usize,
    k: usize,
    a: Vec<f32>,
}

impl Problem {
    fn random(rows: usize, m: usize, k: usize, seed: u64) -> Problem {
        let mut r = Rng(seed * 7919 + 1);
        let mut a = vec![0f32; rows * (m + k)];
        a[..rows].fill(1.0); // intercept feature
        for v in a.iter_mut().skip(rows) {
            *v = r.f32() * 2.0 - 1.0;
        }
        Problem { rows, m, k, a }
    }
    fn col(&self, j: usize) -> &[f32] {
        &self.a[j * self.rows..(j + 1) * self.rows]
    }
    fn solve(&self, simd: bool) -> (Vec<f32>, u32) {
        let mut a = self.a.clone();
        let mut x = vec![0f32; self.m * self.k];
        let fit = lstsq(&mut a, self.rows, self.m, self.k, 1e-4, simd, &mut x).unwrap();
        (x, fit.dropped)
    }
    /// ‖A x − z_c‖² summed over right-hand sides, in f64.
    fn residual(&self, x: &[f32]) -> f64 {
        let mut s = 0.0;
        for c in 0..self.k {
            for i in 0..self.rows {
                let mut v = -(self.col(self.m + c)[i] as f64);
                for j in 0..self.m {
                    v += self.col(j)[i] as f64 * x[j * self.k + c] as f64;
                }
                s += v * v;
            }
        }
        s
    }
    /// f64 normal equations solved by Gaussian elimination with pivoting (tests/common).
    fn oracle(&self) -> Vec<f64> {
        let (m, k) = (self.m, self.k);
        let mut ata = vec![0f64; m * m];
        let mut atz = vec![0f64; m * k];
        for i in 0..m {
            for j in 0..m {
                ata[i * m + j] = self.col(i).iter().zip(self.col(j)).map(|(a, b)| *a as f64 * *b as f64).sum();
            }
            for c in 0..k {
                atz[i * k + c] = self.col(i).iter().zip(self.col(m + c)).map(|(a, b)| *a as f64 * *b as f64).sum();
            }
        }
        common::gauss(ata, m, atz, k)
    }
}

#[test]
fn matches_f64_on_well_conditioned_problems() {
    for (rows, m, k) in [(10, 1, 1), (33, 3, 2), (64, 10, 3), (1024, 10, 3), (257, 16, 3), (16, 16, 1)] {
        for seed in 0..5 {
            let p = Problem::random(rows, m, k, seed);
            let want = p.oracle();
            for simd in [true, false] {
                let (x, dropped) = p.solve(simd);
                assert_eq!(dropped, 0);
                let err = x.iter().zip(&want).map(|(a, b)| (*a as f64 - b).abs()).fold(0f64, f64::max);
                let scale = want.iter().fold(1f64, |a, b| a.max(b.abs()));
                // f32 Householder: backward stable; condition numbers here are < 1e2.
                assert!(err < 2e-3 * scale, "{rows}x{m}x{k} seed {seed} simd {simd}: {err}");
            }
        }
    }
}

/// R from the factorisation satisfies RᵀR = AᵀA (Q orthogonal), checked in f64,
/// and the fit's residual equals the f64 optimum.
#[test]
fn r_reconstructs_gram_matrix() {
    for (rows, m) in [(40, 5), (1024, 10), (19, 16)] {
        let p = Problem::random(rows, m, 1, 3);
        let mut a = p.a.clone();
        let mut x = vec![0f32; m];
        lstsq(&mut a, rows, m, 1, 1e-6, true, &mut x).unwrap();
        let r = |i: usize, j: usize| if i <= j { a[j * rows + i] as f64 } else { 0.0 };
        let mut worst = 0f64;
        let mut scale = 0f64;
        for i in 0..m {
            for j in 0..m {
                let rtr: f64 = (0..m).map(|l| r(l, i) * r(l, j)).sum();
                let ata: f64 = p.col(i).iter().zip(p.col(j)).map(|(a, b)| *a as f64 * *b as f64).sum();
                worst = worst.max((rtr - ata).abs());
                scale = scale.max(ata.abs());
            }
        }
        assert!(worst < 1e-5 * scale * (rows as f64).sqrt(), "{rows}x{m}: |RᵀR − AᵀA| = {worst} (scale {scale})");
        let want: Vec<f32> = p.oracle().iter().map(|v| *v as f32).collect();
        let (r_ours, r_opt) = (p.residual(&x), p.residual(&want));
        assert!(r_ours <= r_opt * (1.0 + 1e-3) + 1e-6, "{r_ours} vs {r_opt}");
    }
}

/// Flat wall (constant normal and position: features constant, p² ∝ p), a
/// duplicated column, an all-zero column, empty sky (all-zero block): finite
/// output, dropped features flagged, residual as good as without the redundant columns.
#[test]
fn rank_deficient_blocks() {
    let rows = 1024;
    let base = Problem::random(rows, 4, 3, 11);
    type Column = Box<dyn Fn(&[f32], usize) -> f32>;
    let cases: Vec<(&str, Column)> = vec![
        ("constant feature", Box::new(|_, _| 0.37)),
        ("duplicate of column 2", Box::new(|c2, i| c2[i])),
        ("scaled duplicate", Box::new(|c2, i| 3.0 * c2[i])),
        ("all zero", Box::new(|_, _| 0.0)),
    ];
    let full_res = base.residual(&base.solve(true).0);
    for (name, f) in cases {
        // insert the redundant column as feature 4 (before the rhs columns)
        let c2: Vec<f32> = base.col(2).to_vec();
        let mut a = base.a[..4 * rows].to_vec();
        a.extend((0..rows).map(|i| f(&c2, i)));
        a.extend_from_slice(&base.a[4 * rows..]);
        let p = Problem { rows, m: 5, k: 3, a };
        let (x, dropped) = p.solve(true);
        assert!(x.iter().all(|v| v.is_finite()), "{name}");
        assert!(dropped != 0, "{name}: nothing dropped");
        let r = p.residual(&x);
        assert!(r <= full_res * (1.0 + 1e-3) + 1e-6, "{name}: residual {r} vs {full_res}");
    }
    let sky = Problem { rows, m: 10, k: 3, a: vec![0.0; rows * 13] };
    let (x, dropped) = sky.solve(true);
    assert!(x.iter().all(|v| *v == 0.0));
    assert_eq!(dropped, (1 << 10) - 1);
    // more features than rows
    let p = Problem::random(5, 10, 2, 4);
    let (x, _) = p.solve(true);
    assert!(x.iter().all(|v| v.is_finite()));
    assert!(lstsq(&mut [0.0; 4], 2, 17, 1, 1e-4, true, &mut [0.0; 17]).is_none());
}

/// Column 0's dot products handed in (`dots0`, as BMFR sums its columns while
/// filling them) give the fit the QR computes them for, to rounding: the
/// products are summed in another order. Dots of a different problem change
/// the fit (so they are used), and too few are refused.
#[test]
fn given_column_dots_match_computed_ones() {
    for (rows, m, k) in [(1024, 10, 3), (81, 5, 3), (7, 3, 1)] {
        let p = Problem::random(rows, m, k, 21);
        let dots: Vec<f32> =
            (0..m + k).map(|c| p.col(0).iter().zip(p.col(c)).map(|(a, b)| *a as f64 * *b as f64).sum::<f64>() as f32).collect();
        let shrink = Shrinkage { kappa: 4.0, samples: rows };
        let run = |d: Option<&[f32]>| {
            let (mut a, mut x) = (p.a.clone(), vec![0f32; m * k]);
            lstsq_shrunk_ld(&mut a, rows, rows, m, k, 1e-4, true, shrink, d, &mut x).unwrap();
            x
        };
        let (want, got) = (run(None), run(Some(&dots)));
        let scale = want.iter().fold(1e-3f32, |s, v| s.max(v.abs()));
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= 1e-4 * scale, "{rows}x{m}x{k}: {g} vs {w}");
        }
        let wrong: Vec<f32> = dots.iter().map(|d| d * 1.5 + 1.0).collect();
        assert_ne!(run(Some(&wrong)), want, "{rows}x{m}x{k}: the given dots are used");
        let (mut a, mut x) = (p.a.clone(), vec![0f32; m * k]);
        assert!(lstsq_shrunk_ld(&mut a, rows, rows, m, k, 1e-4, true, shrink, Some(&dots[..m + k - 1]), &mut x).is_none());
    }
}

/// Columns `ld > rows` apart (padded off multiples of 4 KiB, as BMFR stores
/// its blocks) give bit-identical results; the padding is never read.
#[test]
fn leading_dimension_does_not_change_the_result() {
    for (rows, m, k) in [(1024, 10, 3), (81, 5, 3), (7, 3, 1), (1, 1, 1)] {
        let p = Problem::random(rows, m, k, 9);
        let ld = padded_ld(rows) + 3;
        assert!(ld > rows && !(ld * 4).is_multiple_of(4096));
        for simd in [true, false] {
            let mut padded = vec![f32::NAN; ld * (m + k)];
            for c in 0..m + k {
                padded[c * ld..c * ld + rows].copy_from_slice(p.col(c));
            }
            let mut x = vec![0f32; m * k];
            let fit = lstsq_ld(&mut padded, ld, rows, m, k, 1e-4, simd, &mut x).unwrap();
            let (want, dropped) = p.solve(simd);
            assert_eq!((x, fit.dropped), (want, dropped), "{rows}x{m}x{k} simd {simd}");
        }
    }
    assert!(lstsq_ld(&mut [0.0; 8], 3, 4, 1, 1, 1e-4, true, &mut [0.0]).is_none(), "ld < rows");
}

impl Problem {
    /// The shrunk fit in f64 ([`common::shrunk_lstsq`]).
    fn shrunk_oracle(&self, kappa: f64, samples: usize) -> Vec<f64> {
        let col = |j: usize| self.col(j).iter().map(|&v| v as f64).collect::<Vec<f64>>();
        let cols: Vec<Vec<f64>> = (0..self.m).map(col).collect();
        let zs: Vec<Vec<f64>> = (self.m..self.m + self.k).map(col).collect();
        common::shrunk_lstsq(&cols, &zs, kappa, samples)
    }
    fn solve_shrunk(&self, kappa: f32, samples: usize, simd: bool) -> Vec<f32> {
        let mut a = self.a.clone();
        let mut x = vec![0f32; self.m * self.k];
        lstsq_shrunk_ld(&mut a, self.rows, self.rows, self.m, self.k, 1e-4, simd, Shrinkage { kappa, samples }, None, &mut x).unwrap();
        x
    }
    /// A block of `rows` samples whose right-hand sides are `A β` for a
    /// `β` with only its constant and first slope non-zero, plus uniform noise
    /// of amplitude `noise`; `zero_rows` all-zero rows appended (invalid pixels).
    fn noisy(rows: usize, zero_rows: usize, m: usize, noise: f32, seed: u64) -> (Problem, Vec<f64>) {
        let clean = Problem::random(rows, m, 3, seed);
        let n = rows + zero_rows;
        let mut a = vec![0f32; n * (m + 3)];
        let mut r = Rng(seed * 31 + 7);
        let beta = [0.5, 0.8];
        let mut truth = vec![0f64; n * 3];
        for j in 0..m {
            a[j * n..j * n + rows].copy_from_slice(clean.col(j));
        }
        for c in 0..3 {
            for i in 0..rows {
                let t = beta[0] + beta[1] * clean.col(1)[i] as f64;
                truth[c * n + i] = t;
                a[(m + c) * n + i] = t as f32 + noise * (2.0 * r.f32() - 1.0);
            }
        }
        (Problem { rows: n, m, k: 3, a }, truth)
    }
    /// ‖A x − truth‖² over the right-hand sides, in f64.
    fn error_to(&self, x: &[f32], truth: &[f64]) -> f64 {
        let mut s = 0.0;
        for c in 0..self.k {
            for i in 0..self.rows {
                let fit: f64 = (0..self.m).map(|j| self.col(j)[i] as f64 * x[j * self.k + c] as f64).sum();
                s += (fit - truth[c * self.rows + i]).powi(2);
            }
        }
        s
    }
}

/// The shrunk fit matches the f64 Gram–Schmidt oracle (Householder's Q
/// differs from Gram–Schmidt's only in column signs, which cancel), SIMD and
/// scalar; zero rows (invalid pixels) change nothing; κ = 0 is plain least
/// squares bit for bit.
#[test]
fn shrinkage_matches_f64_oracle() {
    for (rows, zero_rows, m) in [(1024, 0, 10), (700, 324, 10), (64, 0, 4), (30, 3, 7), (17, 0, 16)] {
        for seed in 0..4 {
            for noise in [0.05, 1.0, 20.0] {
                let (p, _) = Problem::noisy(rows, zero_rows, m, noise, seed);
                for kappa in [0.5f32, 4.0, 100.0] {
                    let want = p.shrunk_oracle(kappa as f64, rows);
                    let scale = want.iter().fold(1f64, |a, b| a.max(b.abs()));
                    for simd in [true, false] {
                        let x = p.solve_shrunk(kappa, rows, simd);
                        let err = x.iter().zip(&want).map(|(a, b)| (*a as f64 - b).abs()).fold(0f64, f64::max);
                        assert!(err < 2e-3 * scale, "{rows}+{zero_rows}x{m} seed {seed} noise {noise} κ {kappa} simd {simd}: {err}");
                    }
                }
            }
            let (p, _) = Problem::noisy(rows, zero_rows, m, 1.0, seed);
            for simd in [true, false] {
                assert_eq!(p.solve_shrunk(0.0, rows, simd), p.solve(simd).0, "κ = 0");
                // no residual degrees of freedom: plain least squares
                assert_eq!(p.solve_shrunk(4.0, m, simd), p.solve(simd).0, "samples = m");
            }
        }
    }
}

/// What the shrinkage is for: a block whose light depends on one feature,
/// fitted with ten at 1-spp noise levels. Summed over seeds, the shrunk fit
/// is closer to the noise-free light than least squares, by more the noisier
/// the data; with almost no noise it is the least-squares fit.
#[test]
fn shrinkage_lowers_the_error_of_noisy_fits() {
    for (noise, min_gain) in [(2.0f32, 2.0), (0.5, 1.5)] {
        let (mut plain, mut shrunk) = (0.0, 0.0);
        for seed in 0..20 {
            let (p, truth) = Problem::noisy(1024, 0, 10, noise, seed);
            plain += p.error_to(&p.solve(true).0, &truth);
            shrunk += p.error_to(&p.solve_shrunk(4.0, 1024, true), &truth);
        }
        assert!(plain > min_gain * shrunk, "noise {noise}: least squares {plain} vs shrunk {shrunk}");
    }
    let (p, _) = Problem::noisy(1024, 0, 10, 1e-5, 1);
    let (x, plain) = (p.solve_shrunk(4.0, 1024, true), p.solve(true).0);
    let diff = x.iter().zip(&plain).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(diff < 1e-3, "{diff}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]
    /// Conditioning (near-collinear columns), scale and offset: finite output and a
    /// residual no worse than the f64 optimum beyond f32 rounding of the data.
    #[test]
    fn stable_over_conditioning_scale_offset(seed in 0u64..10_000, log_scale in -3.0f32..3.0, offset in -100.0f32..100.0, mix in 0.0f32..1.0, rows in 16usize..300) {
        let mut p = Problem::random(rows, 6, 3, seed);
        let s = 10f32.powf(log_scale);
        let mut rng = Rng(seed + 5);
        for i in 0..rows {
            let c1 = p.a[rows + i];
            p.a[2 * rows + i] = c1 + (1.0 - mix) * 1e-3 * rng.f32(); // nearly collinear with column 1
            for j in 3..6 {
                p.a[j * rows + i] = p.a[j * rows + i] * s + offset;
            }
        }
        let (x, dropped) = p.solve(true);
        prop_assert!(x.iter().all(|v| v.is_finite()));
        let (xs, dropped_s) = p.solve(false);
        let (rs, r) = (p.residual(&xs), p.residual(&x));
        let z2: f64 = (6..9).flat_map(|c| p.col(c).to_vec()).map(|v| (v as f64).powi(2)).sum();
        // neither worse than predicting 0
        prop_assert!(r <= z2 * (1.0 + 1e-3) + 1e-3 && rs <= z2 * (1.0 + 1e-3) + 1e-3);
        // with the same pivots dropped, both paths fit about equally well (near the
        // drop threshold they may legitimately drop different pivots)
        if dropped == dropped_s {
            prop_assert!((r - rs).abs() <= 1e-2 * z2.max(1.0), "simd {} vs scalar {}", r, rs);
        }
    }
}
