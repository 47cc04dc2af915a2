//! FLNR's network inference: parity with PyTorch on an exported test vector
//! (`train/unet.py --parity tests/data/nn_parity`), each layer against a slow
//! f64 reference, and blob validation.

mod common;
#[path = "common/oracles.rs"]
mod oracles;
use common::{threads, Rng};
use lrdenoise::nn::{level_size, Isa, UNet};
use lrdenoise::{Blur, Error};
use oracles::{blob, reference as network_reference, u32_at};

const BLOB: &[u8] = include_bytes!("data/nn_parity.bin");
const VECTOR: &[u8] = include_bytes!("data/nn_parity.vec");

fn f32s(b: &[u8]) -> Vec<f32> {
    b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

#[test]
fn matches_pytorch_on_the_exported_vector() {
    let net = UNet::parse(BLOB).unwrap();
    assert_eq!(&VECTOR[..4], b"LRDT");
    let (w, h, cin, cout) = (u32_at(VECTOR, 4), u32_at(VECTOR, 8), u32_at(VECTOR, 12), u32_at(VECTOR, 16));
    assert_eq!((cin, cout), (net.in_channels(), net.out_channels()));
    let data = f32s(&VECTOR[20..]);
    let (input, want) = data.split_at(cin * w * h);
    let mut scratch = vec![0f32; net.scratch_len(w, h)];
    let mut out = vec![f32::NAN; cout * w * h];
    net.forward(input, w, h, &mut scratch, &mut out).unwrap();
    let worst = out.iter().zip(want).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    // Same f16-rounded weights, f32 activations: only the summation order
    // differs (and with AVX-512, Winograd's products).
    assert!(worst < 1e-5, "worst |lrdenoise − PyTorch| = {worst}");
}

#[test]
fn every_layer_matches_an_f64_reference_on_awkward_sizes() {
    for (k, &(w, h)) in [(1, 1), (7, 3), (3, 7), (16, 16), (33, 17), (257, 2), (48, 20), (19, 9)].iter().enumerate() {
        // [6, 27], [12, 24]: decoder layers of 33 and 36 input channels, more
        // than the AVX-512 Winograd lanes transform at once
        for widths in [vec![3], vec![3, 5], vec![2, 4, 6], vec![4, 4, 4, 4, 4], vec![6, 13], vec![6, 27], vec![12, 24]] {
            let b = blob(5, 3, &widths, 12.0, k as u64 + 1);
            let net = UNet::parse(&b).unwrap();
            let mut rng = Rng(9 + k as u64);
            let input: Vec<f32> = (0..5 * w * h).map(|_| rng.f32() * 4.0 - 2.0).collect();
            let mut scratch = vec![0f32; net.scratch_len(w, h)];
            let want = network_reference(&b, &input, w, h);
            for isa in isas() {
                let mut out = vec![0f32; 3 * w * h];
                net.forward_with(isa, &input, w, h, &mut scratch, &mut out).unwrap();
                let worst = out.iter().zip(&want).map(|(a, b)| (*a as f64 - b).abs()).fold(0f64, f64::max);
                assert!(worst < 1e-4, "{isa:?} {w}x{h} {widths:?}: {worst}");
            }
        }
    }
    assert_eq!(level_size(7, 3, 2), (2, 1));
}

/// Each layer's rows in bands over real threads give the one-thread output
/// bit for bit, for every instruction set, at sizes from one row to levels
/// narrower than the lanes; executors that skip or repeat a band are refused.
#[test]
fn layer_rows_over_threads_equal_one_thread_bit_for_bit() {
    for (k, &(w, h)) in [(1, 1), (7, 3), (19, 9), (33, 17), (48, 20), (130, 97), (257, 41)].iter().enumerate() {
        for widths in [vec![3], vec![3, 5], vec![4, 6, 8], vec![12, 7]] {
            let b = blob(8, 4, &widths, 12.0, k as u64 + 3);
            let net = UNet::parse(&b).unwrap();
            let mut rng = Rng(5 + k as u64);
            let input: Vec<f32> = (0..8 * w * h).map(|_| rng.f32() * 4.0 - 2.0).collect();
            let mut scratch = vec![0f32; net.scratch_len(w, h)];
            for isa in isas() {
                let mut want = vec![0f32; 4 * w * h];
                net.forward_with(isa, &input, w, h, &mut scratch, &mut want).unwrap();
                for workers in [2, 3, 5] {
                    let mut out = vec![f32::NAN; 4 * w * h];
                    scratch.fill(f32::NAN);
                    net.forward_parallel(isa, &input, w, h, &mut scratch, &mut out, workers, &threads(workers)).unwrap();
                    let bad = want.iter().zip(&out).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
                    assert_eq!(bad, 0, "{isa:?} {w}x{h} {widths:?} workers {workers}: {bad} values differ");
                }
            }
        }
    }
    let b = blob(8, 4, &[4, 6], 12.0, 1);
    let net = UNet::parse(&b).unwrap();
    let (w, h) = (64, 48);
    let input = vec![0.5f32; 8 * w * h];
    let mut scratch = vec![0f32; net.scratch_len(w, h)];
    let mut out = vec![0f32; 4 * w * h];
    let skips = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| (1..n).for_each(|i| f(i, 0));
    let twice = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| (0..n).chain(0..1).for_each(|i| f(i, 0));
    let past = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| (0..=n).for_each(|i| f(i, 0));
    for (e, what) in [(&skips as lrdenoise::Executor<'_>, "skips"), (&twice, "twice"), (&past, "past the end")] {
        let r = net.forward_parallel(Isa::detect(), &input, w, h, &mut scratch, &mut out, 2, e);
        assert!(matches!(r, Err(Error::Unsupported(_))), "an executor that runs bands {what}: {r:?}");
    }
    let r = net.forward_parallel(Isa::detect(), &input, w, h, &mut scratch, &mut out, 0, &threads(1));
    assert!(matches!(r, Err(Error::InvalidConfig(_))), "{r:?}");
}

/// The instruction sets this build can run here (the AVX2 one needs a CPU with
/// AVX2 and FMA, the AVX-512 one AVX-512F; both are detected at run time in
/// every build).
fn isas() -> Vec<Isa> {
    let all: Vec<Isa> = [Isa::Portable, Isa::Avx2Fma, Isa::Avx512].into_iter().filter(|i| i.available()).collect();
    if all.len() < 3 {
        eprintln!("note: only {all:?} run here: the other lanes are not exercised");
    }
    all
}

#[test]
fn avx2_and_avx512_lanes_match_the_portable_lanes() {
    // Every 8-pixel group, the shifted last group, stride 1 and 2, OB-blocked
    // and remaining channels (13 = two blocks of 6 and one more), strips of
    // 32 pixels; the AVX2 lanes go 16 pixels at a time, and 30 and 46 leave
    // more than one group after the last pair; the AVX-512 lanes go 32 at a
    // time with masked ends (33, 65: one pixel past a pass), in Winograd's
    // F(2, 3) for stride 1 (other rounding: compared within the bound).
    for (&(w, h), widths) in
        [(18, 3), (19, 9), (30, 4), (33, 6), (40, 7), (46, 5), (65, 4), (257, 5)].iter().zip([[6, 13, 12], [6, 27, 6]].iter().cycle())
    {
        let b = blob(5, 3, widths, 12.0, w as u64);
        let net = UNet::parse(&b).unwrap();
        let mut rng = Rng(w as u64);
        let input: Vec<f32> = (0..5 * w * h).map(|_| rng.f32() * 4.0 - 2.0).collect();
        let mut scratch = vec![0f32; net.scratch_len(w, h)];
        let mut outs = Vec::new();
        for isa in isas() {
            let mut out = vec![f32::NAN; 3 * w * h];
            net.forward_with(isa, &input, w, h, &mut scratch, &mut out).unwrap();
            outs.push((isa, out));
        }
        for (isa, o) in &outs[1..] {
            // fused against (in an SSE2 build) unfused multiply-adds: rounding
            // only, within the f64 reference test's bound
            let worst = o.iter().zip(&outs[0].1).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
            assert!(worst < 1e-4, "{isa:?} {w}x{h} {widths:?}: {worst}");
        }
    }
}

#[test]
fn bad_blobs_and_buffers_are_typed_errors() {
    let good = blob(5, 3, &[3, 5], 12.0, 1);
    assert!(UNet::parse(&good).is_ok());
    let bad = |f: &dyn Fn(&mut Vec<u8>)| {
        let mut b = good.clone();
        f(&mut b);
        UNet::parse(&b).map(|_| ())
    };
    assert!(matches!(bad(&|b| b[0] = b'X'), Err(Error::InvalidConfig(_))));
    assert!(matches!(bad(&|b| b[4] = 3), Err(Error::InvalidConfig(_))));
    assert!(matches!(bad(&|b| b[4] = 0), Err(Error::InvalidConfig(_))));
    assert!(matches!(bad(&|b| b.truncate(b.len() - 1)), Err(Error::InvalidConfig(_))));
    assert!(matches!(bad(&|b| b.push(0)), Err(Error::InvalidConfig(_))));
    assert!(matches!(bad(&|b| b[16] = 9), Err(Error::InvalidConfig(_))));
    assert!(matches!(bad(&|b| b[20] = 0), Err(Error::InvalidConfig(_))));
    assert!(matches!(bad(&|b| b[28..32].copy_from_slice(&f32::NAN.to_le_bytes())), Err(Error::InvalidConfig(_))));
    assert!(matches!(
        bad(&|b| {
            let n = b.len();
            b[n - 2..].copy_from_slice(&half::f16::INFINITY.to_le_bytes())
        }),
        Err(Error::InvalidConfig(_))
    ));
    for n in 0..good.len() {
        let _ = UNet::parse(&good[..n]); // no panic on any truncation
    }
    let net = UNet::parse(&good).unwrap();
    let mut out = vec![0f32; 3 * 16];
    let input = vec![0f32; 5 * 16];
    assert!(matches!(net.forward(&input, 4, 4, &mut [0f32; 3], &mut out), Err(Error::ScratchTooSmall { .. })));
    let mut scratch = vec![0f32; net.scratch_len(4, 4)];
    assert!(matches!(net.forward(&input[..10], 4, 4, &mut scratch, &mut out), Err(Error::BufferTooSmall { .. })));
    assert!(matches!(net.forward(&input, 0, 4, &mut scratch, &mut out), Err(Error::InvalidSize { .. })));
}

/// `b` (a version-1 blob with `levels`) rewritten as version 2 with these
/// FLR windows and ε, ϵ.
fn as_v2(b: &[u8], levels: usize, sigmas: &[f32], eps: [f32; 2]) -> Vec<u8> {
    let at = 20 + 4 * (levels + 1);
    let mut v = b[..at].to_vec();
    v[4] = 2;
    v.extend_from_slice(&(sigmas.len() as u32).to_le_bytes());
    for x in sigmas.iter().chain(&eps) {
        v.extend_from_slice(&x.to_le_bytes());
    }
    v.extend_from_slice(&b[at + 12..]);
    v
}

/// `b` (a version-1 blob with `levels`) rewritten as version 3: version 2's
/// fields and the AO demodulation's offset.
fn as_v3(b: &[u8], levels: usize, sigmas: &[f32], eps: [f32; 2], ao_offset: f32) -> Vec<u8> {
    let v2 = as_v2(b, levels, sigmas, eps);
    let at = 20 + 4 * (levels + 1) + 4 + 4 * (sigmas.len() + 2);
    let mut v = v2[..at].to_vec();
    v[4] = 3;
    v.extend_from_slice(&ao_offset.to_le_bytes());
    v.extend_from_slice(&v2[at..]);
    v
}

#[test]
fn version_3_blobs_carry_the_ao_demodulation() {
    let v1 = blob(8, 8, &[3, 5], 12.0, 1);
    assert_eq!(UNet::parse(&v1).unwrap().flr_ao_demodulation(), None);
    let v2 = as_v2(&v1, 1, &[6.0, 12.0, 20.0], [2e-3, 3e-2]);
    assert_eq!(UNet::parse(&v2).unwrap().flr_ao_demodulation(), None);
    let v3 = as_v3(&v1, 1, &[6.0, 12.0, 20.0], [2e-3, 3e-2], 0.1);
    let net = UNet::parse(&v3).unwrap();
    assert_eq!((net.flr_sigmas(), net.flr_eps(), net.flr_ao_demodulation()), (&[6f32, 12.0, 20.0][..], [2e-3, 3e-2], Some(0.1)));
    // FLNR plans the FLR it was trained with, AO demodulation included
    let fl = lrdenoise::flnr::Flnr::new(lrdenoise::FlnrConfig::new(&v3), 40, 30).unwrap();
    assert_eq!(fl.flr().config().ao_demodulation, Some(0.1));
    let off = as_v3(&v1, 1, &[12.0], [1e-3, 1e-2], 0.0);
    let fl = lrdenoise::flnr::Flnr::new(lrdenoise::FlnrConfig::new(&off), 40, 30).unwrap();
    assert_eq!(fl.flr().config().ao_demodulation, None);
    for c in [-0.1, f32::NAN, f32::INFINITY] {
        let b = as_v3(&v1, 1, &[12.0], [1e-3, 1e-2], c);
        assert!(matches!(UNet::parse(&b), Err(Error::InvalidConfig(_))), "{c}");
    }
    // the v2 layout labelled version 3 lacks four bytes: a typed error, never a panic
    let mut short = v2.clone();
    short[4] = 3;
    assert!(matches!(UNet::parse(&short), Err(Error::InvalidConfig(_))));
    for n in 0..v3.len() {
        let _ = UNet::parse(&v3[..n]);
    }
}

#[test]
fn version_2_blobs_carry_the_adaptive_window() {
    let v1 = blob(8, 8, &[3, 5], 12.0, 1);
    let net = UNet::parse(&v1).unwrap();
    assert_eq!((net.flr_sigmas(), net.flr_eps()), (&[12f32][..], [1e-3, 1e-2]));
    let v2 = as_v2(&v1, 1, &[6.0, 12.0, 20.0], [2e-3, 3e-2]);
    let net = UNet::parse(&v2).unwrap();
    assert_eq!((net.flr_sigmas(), net.flr_eps()), (&[6f32, 12.0, 20.0][..], [2e-3, 3e-2]));
    // FLNR plans the FLR it was trained with
    let fl = lrdenoise::flnr::Flnr::new(lrdenoise::FlnrConfig::new(&v2), 40, 30).unwrap();
    assert_eq!(fl.flr().config().blur, Blur::Adaptive { sigmas: [6.0, 12.0, 20.0] });
    let one = as_v2(&v1, 1, &[10.0], [1e-3, 1e-2]);
    let fl = lrdenoise::flnr::Flnr::new(lrdenoise::FlnrConfig::new(&one), 40, 30).unwrap();
    assert_eq!(fl.flr().config().blur, Blur::Gaussian { sigma: 10.0, radius: None });
    for (sigmas, eps) in
        [(&[6.0, 12.0][..], [1e-3, 1e-2]), (&[6.0, 6.0, 20.0][..], [1e-3, 1e-2]), (&[12.0][..], [0.0, 1e-2]), (&[][..], [1e-3, 1e-2])]
    {
        let b = as_v2(&v1, 1, sigmas, eps);
        assert!(matches!(UNet::parse(&b), Err(Error::InvalidConfig(_))), "{sigmas:?} {eps:?}");
    }
    for n in 0..v2.len() {
        let _ = UNet::parse(&v2[..n]); // no panic on any truncation
    }
}
