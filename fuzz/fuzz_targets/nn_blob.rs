//! (g) FLNR weight blobs: any bytes parse to a typed error or a network; a
//! network that parses runs on a small input without panicking, output in [0, 1],
//! and its layers' rows in bands over workers give the same bits.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lrdenoise::nn::UNet;

fuzz_target!(|d: &[u8]| {
    let Ok(net) = UNet::parse(d) else { return };
    let (w, h) = (1 + d.len() % 9, 1 + d.len() % 5);
    let input: Vec<f32> = (0..net.in_channels() * w * h).map(|i| d[i % d.len()] as f32 / 64.0 - 2.0).collect();
    let mut scratch = vec![0f32; net.scratch_len(w, h)];
    let mut out = vec![0f32; net.out_channels() * w * h];
    net.forward(&input, w, h, &mut scratch, &mut out).unwrap();
    assert!(out.iter().all(|v| (0.0..=1.0).contains(v)));
    let mut banded = vec![0f32; out.len()];
    let workers = 2 + d.len() % 3;
    let each = |n: usize, f: &(dyn Fn(usize, usize) + Sync)| (0..n).for_each(|i| f(i, i % workers));
    net.forward_parallel(lrdenoise::nn::Isa::detect_widest(), &input, w, h, &mut scratch, &mut banded, workers, &each).unwrap();
    assert!(out.iter().zip(&banded).all(|(a, b)| a.to_bits() == b.to_bits()));
});
