//! The ray-cast room WALR is benchmarked on (`benches/walr.rs`, `tools/depbench`'s
//! `walr16`): planes and a thin pole, so tracing meets real edges.

/// A pinhole view of a room (back wall, floor, left wall) with a thin pole.
pub fn room(w: usize, h: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
    let n = w * h;
    let (mut noisy, mut normal, mut position, mut depth) = (vec![0f32; 3 * n], vec![0f32; 3 * n], vec![0f32; 3 * n], vec![0f32; n]);
    let mut seed = 1u32;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let d = [(x as f32 + 0.5) / w as f32 * 2.0 - 1.0, (1.0 - (y as f32 + 0.5) / h as f32 * 2.0) * h as f32 / w as f32, 0.8];
            let mut best = (10.0 / d[2], [0.0, 0.0, -1.0f32]);
            if d[1] < 0.0 && -2.0 / d[1] < best.0 {
                best = (-2.0 / d[1], [0.0, 1.0, 0.0]);
            }
            if d[0] < 0.0 && -4.0 / d[0] < best.0 {
                best = (-4.0 / d[0], [1.0, 0.0, 0.0]);
            }
            if x % (w / 5) < 3 && 5.0 / d[2] < best.0 {
                best = (5.0 / d[2], [0.0, 0.0, -1.0]);
            }
            let p = d.map(|c| c * best.0);
            normal[3 * i..3 * i + 3].copy_from_slice(&best.1);
            position[3 * i..3 * i + 3].copy_from_slice(&p);
            depth[i] = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            for c in 0..3 {
                seed ^= seed << 13;
                seed ^= seed >> 17;
                seed ^= seed << 5;
                noisy[3 * i + c] = (0.5 + 0.05 * p[1]) * if seed.is_multiple_of(5) { 3.0 } else { 0.5 };
            }
        }
    }
    (noisy, normal, position, depth)
}
