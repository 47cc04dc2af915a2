//! (a) The per-cell solvers on arbitrary moment matrices: the model is always
//! finite; so is the fit without one guide (`solve_cell_without`), whose full
//! model is bit-identical to `solve_cell`'s when that guide is the last (else
//! the system is factored in another order) and whose dropped guide has no
//! coefficient.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lrdenoise::kernels::solve::{solve_cell, solve_cell_without, SolveParams};
use lrdenoise::kernels::{model_len, moment_count};
use lrdenoise::{Regularization, MAX_GUIDES};

fn f64_at(d: &[u8], i: usize) -> f64 {
    let mut b = [0u8; 8];
    for (k, x) in b.iter_mut().enumerate() {
        *x = d.get(i * 8 + k).copied().unwrap_or(0);
    }
    f64::from_le_bytes(b)
}

fn run<const Q: usize>(d: &[u8]) {
    let k = moment_count(Q);
    let cell: Vec<f64> = (0..k).map(|i| f64_at(d, 2 + i)).collect();
    let mut p = SolveParams {
        reference: [0.0; MAX_GUIDES],
        mean: [0.0; MAX_GUIDES],
        scale: [1.0; MAX_GUIDES],
        regularization: if d[1] & 1 == 0 {
            Regularization::Normalized { eps_mul: (d[1] as f64) * 1e-5, eps_add: 1e-4 }
        } else {
            Regularization::Tikhonov { eps: 1e-6 + (d[1] as f64) * 1e-5 }
        },
        weight_norm: 1.0,
        min_weight: 1e-12,
    };
    for q in 0..Q {
        p.reference[q] = f64_at(d, 2 + k + q).clamp(-1e6, 1e6);
        p.mean[q] = f64_at(d, 2 + k + Q + q).clamp(-1e6, 1e6);
        let s = f64_at(d, 2 + k + 2 * Q + q).abs();
        p.scale[q] = if s.is_finite() && s > 1e-30 && s < 1e30 { s } else { 1.0 };
        if !p.reference[q].is_finite() {
            p.reference[q] = 0.0;
        }
        if !p.mean[q].is_finite() {
            p.mean[q] = 0.0;
        }
    }
    let ml = model_len(Q);
    let mut model = vec![0f32; ml];
    let full = solve_cell::<Q>(&cell, &p, &mut model);
    assert!(model.iter().all(|v| v.is_finite()), "non-finite model {model:?} from {cell:?}");
    let drop = d[1] as usize % Q;
    let mut both = vec![0f32; 2 * ml];
    let outcome = solve_cell_without::<Q>(&cell, &p, drop, &mut both);
    assert_eq!(outcome.empty, full.empty);
    if drop == Q - 1 {
        assert_eq!(outcome, full);
    }
    assert!(both.iter().all(|v| v.is_finite()), "non-finite fit without guide {drop}: {both:?} from {cell:?}");
    if drop == Q - 1 {
        assert!(both[..ml].iter().zip(&model).all(|(a, b)| a.to_bits() == b.to_bits()), "the full fit changed");
    }
    assert!(both[ml + 3 + 3 * drop..ml + 6 + 3 * drop].iter().all(|&v| v == 0.0), "guide {drop} kept a coefficient");
}

fuzz_target!(|d: &[u8]| {
    if d.len() < 2 {
        return;
    }
    match d[0] % 6 {
        0 => run::<1>(d),
        1 => run::<2>(d),
        2 => run::<3>(d),
        3 => run::<5>(d),
        4 => run::<8>(d),
        _ => run::<12>(d),
    }
});
