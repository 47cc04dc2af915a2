//! Times the adaptive window's per-cell arithmetic (gaps, variance, blend) on
//! synthetic cells, one cell at a time and four per f64x4 lane (what `Flr`
//! runs), in the same run: `cargo run --release --example adaptive_cells`.
use lrdenoise::flr::adaptive::{blend, blend4, prediction_gaps, variance, variances4, ModelLanes};
use std::time::Instant;

fn main() {
    const Q: usize = 5;
    let k = 1 + Q + Q * (Q + 1) / 2 + 3 + 3 * Q + 1;
    let ml = 3 + 3 * Q + 3;
    let n = 32400;
    let mut seed = 1u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((seed >> 33) as f64) / (1u64 << 31) as f64
    };
    let cells: Vec<f64> = (0..n * k).map(|i| if i % k == 0 { 100.0 + rnd() } else { rnd() * 10.0 + 50.0 }).collect();
    let models: Vec<Vec<f32>> = (0..3).map(|_| (0..n * ml).map(|_| rnd() as f32).collect()).collect();
    let mut out = vec![0f32; n * ml];
    let mut best = [f64::MAX; 3];
    let mut check = 0.0;
    for _ in 0..30 {
        let t = Instant::now();
        let mut gs = Vec::with_capacity(n);
        for c in 0..n {
            let m = [&models[0][c * ml..(c + 1) * ml], &models[1][c * ml..(c + 1) * ml], &models[2][c * ml..(c + 1) * ml]];
            gs.push(prediction_gaps::<Q, 3>(&cells[c * k..(c + 1) * k], m, 1e-9));
        }
        best[0] = best[0].min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let mut vs = Vec::with_capacity(n);
        for c in 0..n {
            vs.push(variance::<Q>(&cells[c * k..(c + 1) * k], &models[0][c * ml..(c + 1) * ml], Q + 1, 0.01, 1800.0, 1e-9));
        }
        best[1] = best[1].min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for c in 0..n {
            let m = [&models[0][c * ml..(c + 1) * ml], &models[1][c * ml..(c + 1) * ml], &models[2][c * ml..(c + 1) * ml]];
            blend(m, [vs[c], vs[c] * 0.5, vs[c] * 0.25], gs[c], &mut out[c * ml..(c + 1) * ml]);
        }
        best[2] = best[2].min(t.elapsed().as_secs_f64());
        check = gs.iter().map(|g| g[1] + g[2]).sum::<f64>() + vs.iter().sum::<f64>() + out.iter().map(|v| *v as f64).sum::<f64>();
    }
    println!(
        "one cell at a time: gaps {:.3} ms, variance {:.3} ms, blend {:.3} ms (check {check:.12e})",
        best[0] * 1e3,
        best[1] * 1e3,
        best[2] * 1e3
    );
    // four cells per lane: variances, then gaps + blend together (as `Flr` does)
    let mut best4 = [f64::MAX; 2];
    let mut vs = vec![0f64; n];
    let mut out4 = vec![0f32; n * ml];
    let mut lanes = ModelLanes::default();
    for _ in 0..30 {
        let t = Instant::now();
        for (q, v) in vs.chunks_exact_mut(4).enumerate() {
            v.copy_from_slice(
                &variances4::<Q, 1>(
                    &cells[4 * q * k..4 * (q + 1) * k],
                    std::array::from_fn(|l| [&models[0][(4 * q + l) * ml..(4 * q + l + 1) * ml]]),
                    [Q + 1],
                    0.01,
                    1800.0,
                    1e-9,
                )[0],
            );
        }
        best4[0] = best4[0].min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for q in 0..n / 4 {
            let m: [[&[f32]; 3]; 4] = std::array::from_fn(|l| {
                let c = 4 * q + l;
                std::array::from_fn(|w| &models[w][c * ml..(c + 1) * ml])
            });
            let v: [[f64; 4]; 3] = std::array::from_fn(|w| std::array::from_fn(|l| vs[4 * q + l] * [1.0, 0.5, 0.25][w]));
            blend4::<Q, 3>(&cells[4 * q * k..4 * (q + 1) * k], m, v, 1e-9, &mut lanes, &mut out4[4 * q * ml..4 * (q + 1) * ml]);
        }
        best4[1] = best4[1].min(t.elapsed().as_secs_f64());
    }
    let same = out4.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits());
    println!(
        "four per lane: variance {:.3} ms, gaps + blend {:.3} ms (same blend output bit for bit: {same})",
        best4[0] * 1e3,
        best4[1] * 1e3
    );
}
