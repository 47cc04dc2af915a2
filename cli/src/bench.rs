//! `lrd bench`: the denoiser alone on a synthetic frame (or a frame resampled),
//! against a memory-copy baseline; GPU pass times where the adapter has them.

use crate::evaluate::{self, time_method};
use crate::methods::{check_method, FlrArgs, Method};
use crate::runner::{InputLayout, Inputs};
use lrdenoise_cli::exrio::ExrFrame;
use std::path::Path;

pub fn parse_size(size: &str) -> Result<(usize, usize), String> {
    size.split_once('x')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .filter(|(a, b)| *a > 0 && *b > 0)
        .ok_or_else(|| format!("--size: '{size}' is not WIDTHxHEIGHT"))
}

pub fn bench(
    method: &str,
    size: &str,
    threads: usize,
    runs: usize,
    layout: InputLayout,
    flr: &FlrArgs,
    frame: Option<&Path>,
) -> Result<(), String> {
    check_method(method)?;
    let (w, h) = parse_size(size)?;
    let inputs = match frame {
        Some(p) => {
            let exr = ExrFrame::read(p)?;
            Inputs::from_exr(&exr, p, "noisy")?.resample(w, h)
        }
        None => synthetic(w, h),
    }
    .with_layout(layout)?;
    let mut b = Method::build(method, flr, &inputs, threads)?;
    if let Method::FlrGpu { gpu, .. } = &b.method {
        // lavapipe (a CPU rasteriser) is for correctness; its times mean nothing
        println!("GPU adapter: {}; times include upload and readback", gpu.adapter_name());
    }
    let mut out = vec![0f32; w * h * 3];
    if let Method::FlrTemporalGpu { gpu, .. } = &b.method {
        println!("GPU adapter: {}; times include upload and readback", gpu.flr().adapter_name());
    }
    if b.method.is_temporal() {
        // time a frame with a history (the first frame of a sequence has none
        // and skips the reprojection): every timed run restarts from here
        for _ in 0..2 {
            b.method.run(&inputs, &mut out)?;
        }
    }
    let (med, all) = time_method(&mut b.method, &inputs, &mut out, runs.max(5))?;
    if let Method::FlrGpu { .. } = &b.method {
        gpu_pass_times(&mut b.method, &inputs, &mut out, runs.max(5))?;
    }
    let min = all.iter().copied().fold(f64::MAX, f64::min);
    let max = all.iter().copied().fold(0.0, f64::max);
    println!(
        "{method} {w}x{h} [{}] layout {layout:?} threads {threads} simd {} (run-time kernels {:?}{}): median {med:.3} ms (min {min:.3}, max {max:.3}, {} runs), {:.1} MPix/s",
        b.label,
        lrdenoise::SIMD_LEVEL,
        lrdenoise::isa::Isa::detect(),
        match method {
            "flnr" => format!(", network {:?}", lrdenoise::isa::Isa::detect_widest()),
            _ if matches!(b.method, Method::Temporal(_)) => format!(", temporal stage {:?}", lrdenoise::isa::Isa::detect_widest()),
            _ => String::new(),
        },
        all.len(),
        (w * h) as f64 / med / 1e3
    );
    if let Some(planar) = b.min_bytes {
        let set = if method == "flnr" { lrdenoise::flnr::INPUT_GUIDES } else { flr.config(&inputs)?.guides };
        let bytes = packed_bytes(&inputs, &set, planar);
        let copy = memcpy_median(bytes, all.len());
        println!(
            "baseline, same run: memcpy of the {:.1} MB one call must at least move (each input layer read once, the RGB output written once{}; one thread): median {copy:.3} ms; {method} takes {:.1}x that",
            bytes as f64 / 1e6,
            if b.method.is_temporal() { ", the history read and written" } else { "" },
            med / copy
        );
    }
    Ok(())
}

/// The baseline's bytes with the frame in its packed layout: `planar` (every
/// layer read once, the output written once) with the light, and the normal,
/// depth and AO that `set` reads, replaced by the RGBA buffers they sit in.
fn packed_bytes(inputs: &Inputs, set: &lrdenoise::GuideSet, planar: usize) -> usize {
    let n = inputs.w * inputs.h;
    let Some(p) = &inputs.packed else { return planar };
    let separate = 4 * n * (3 + 3 * set.normal as usize + set.depth as usize + set.ao as usize);
    let buffer = p.bytes() / 2; // the two buffers are the same size
    planar - separate + buffer * (1 + (set.normal || set.depth) as usize)
}

/// Median time (ms) of copying `bytes / 2` bytes (reading half and writing
/// half of `bytes`), `runs` times after a warm-up: `lrd bench`'s baseline.
fn memcpy_median(bytes: usize, runs: usize) -> f64 {
    let src = vec![1u8; bytes / 2];
    let mut dst = vec![0u8; bytes / 2];
    dst.copy_from_slice(&src);
    let mut t: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let s = std::time::Instant::now();
            dst.copy_from_slice(std::hint::black_box(&src));
            std::hint::black_box(&mut dst);
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    evaluate::median(&mut t)
}

/// Prints the shader time alone (timestamp queries: median per pass over `runs` frames).
fn gpu_pass_times(m: &mut Method, inputs: &Inputs, out: &mut [f32], runs: usize) -> Result<(), String> {
    let names: Vec<&str> = match &*m {
        Method::FlrGpu { gpu, .. } => gpu.plan().passes().iter().map(|p| p.name()).collect(),
        _ => return Ok(()),
    };
    let mut per_pass: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    for _ in 0..runs {
        m.run(inputs, out)?;
        let Method::FlrGpu { gpu, .. } = &*m else { return Ok(()) };
        let Some(t) = gpu.pass_times_ms() else {
            println!("GPU time: the adapter has no timestamp queries");
            return Ok(());
        };
        for (v, t) in per_pass.iter_mut().zip(t) {
            v.push(*t);
        }
    }
    let med: Vec<f64> = per_pass.iter_mut().map(|v| evaluate::median(v)).collect();
    let parts: Vec<String> = names.iter().zip(&med).map(|(n, t)| format!("{n} {t:.3}")).collect();
    println!("GPU time (timestamps, median of {runs}): {:.3} ms = {} ms", med.iter().sum::<f64>(), parts.join(" + "));
    Ok(())
}

/// A synthetic frame with every guide (for benchmarks: content does not change the work).
pub(crate) fn synthetic(w: usize, h: usize) -> Inputs {
    let mut s = 0x9E3779B97F4A7C15u64;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let n = w * h;
    let mut normal = vec![0f32; 3 * n];
    let mut depth = vec![0f32; n];
    let mut position = vec![0f32; 3 * n];
    let mut ao = vec![0f32; n];
    let mut noisy = vec![0f32; 3 * n];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let r = ((x / 97) + (y / 61)) % 3;
            let nr = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]][r];
            normal[3 * i..3 * i + 3].copy_from_slice(&nr);
            depth[i] = 2.0 + y as f32 * 0.01 + r as f32;
            position[3 * i..3 * i + 3].copy_from_slice(&[x as f32 * 0.01, depth[i], y as f32 * 0.01]);
            ao[i] = 0.5 + 0.5 * ((x as f32) * 0.05).sin().abs();
            for c in 0..3 {
                noisy[3 * i + c] = (0.2 + 0.1 * c as f32) * ao[i] * 2.0 * rnd();
            }
        }
    }
    // a quarter-pixel pan, so temporal methods reproject every pixel
    let motion = Some(vec![0.25f32; 2 * n]);
    Inputs {
        w,
        h,
        noisy,
        normal: Some(normal),
        depth: Some(depth),
        position: Some(position),
        ao: Some(ao),
        albedo: None,
        reference: None,
        motion,
        packed: None,
    }
}
