//! The checks every target runs, aarch64 under qemu-user included: a plain
//! `main` on one thread (`harness = false`: qemu-user hangs in any binary
//! that spawns a thread, libtest's harness among them).
//!
//! For each method (FLR in three shapes, BMFR, WALR, FLNR, and the three
//! temporal pipelines over three frames) on small frames of awkward sizes:
//! - the output is finite, or the call returns a typed error;
//! - the SIMD kernels against the scalar ones (`Kernel::Scalar`), within
//!   [`SIMD_BOUND`] ([`QR_BOUND`] for BMFR, [`TRACED_BOUND`] for WALR);
//! - the slow f64 oracles (`tests/common`): FLR per pixel ([`ORACLE_BOUND`]),
//!   BMFR's blockwise fit, FLNR's network on random weights and WALR's
//!   per-pixel Cholesky (each with its own test file's bound);
//! - a denoise call allocates nothing (a counting allocator);
//! - half-float rows read and written through images (each target's bulk
//!   conversion: F16C, NEON's `FCVTL`/`FCVTN`, or software) give `half`'s
//!   software bits, for every f16 and a sweep of f32 values;
//! - across targets: `LRD_ARCH_WRITE=FILE` writes every output, and
//!   `LRD_ARCH_AGAINST=FILE` compares this target's outputs with those
//!   another target wrote (the same statuses; values within [`ARCH_BOUND`],
//!   [`QR_BOUND`] for BMFR, [`TRACED_BOUND`] for WALR).
//!
//! `.ci/run` writes the file on x86-64 and compares under qemu-aarch64. The
//! targets may round differently: the x86 kernels run AVX2 + FMA intrinsics
//! where the CPU has them (SSE2 lanes without FMA otherwise), aarch64 runs
//! `wide`'s NEON lanes (fused multiply-adds), and f32 block sums taken in
//! another lane order round differently. Those differences are of the size of
//! SIMD against scalar on one target, so the bound across targets is the same.

mod common;
#[path = "common/oracles.rs"]
mod oracles;
use common::*;
use half::f16;
use lrdenoise::flr::temporal::TemporalFlr;
use lrdenoise::temporal::{History, TemporalConfig};
use lrdenoise::*;
use oracles::{blob, bmfr_oracle, cholesky_case, random_guides, reference as network_reference};
use std::alloc::{GlobalAlloc, Layout as AllocLayout, System};
use std::fmt::Write as _;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Largest difference between SIMD and scalar kernels, relative:
/// |a − b| / (1e-3 + |b|) (FLR's own SIMD test measures ≤ 2.5e-4).
const SIMD_BOUND: f32 = 2e-3;
/// The same measure between two targets' outputs.
const ARCH_BOUND: f32 = SIMD_BOUND;
/// BMFR's bound on the same measure, SIMD against scalar and across targets:
/// its f32 Householder QR amplifies the last bits of a block's sums where a
/// column is nearly dependent (tests/bmfr.rs's bound).
const QR_BOUND: f32 = 1e-2;
/// WALR's bound, on the RMS difference over the mean: its SIMD edge tracing
/// steps 8 pixels by the most careful SDF step of the 8, a superset of the
/// scalar points, and a step decision can flip with the last bit of a sum
/// (tests/walr.rs's bound).
const TRACED_BOUND: f32 = 0.01;
/// Largest absolute difference from the f64 reference (light of order 1;
/// tests/flr_oracle.rs's bound for small frames).
const ORACLE_BOUND: f64 = 5e-4;

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: AllocLayout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as our caller's.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: AllocLayout) {
        // SAFETY: `p` came from `System.alloc` with layout `l`.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: AllocLayout, n: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as our caller's.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

const SIZES: [(usize, usize); 6] = [(1, 1), (7, 3), (33, 17), (64, 48), (255, 9), (257, 19)];

/// One output: the case, and the pixels or the error.
struct Case {
    name: String,
    result: Result<Vec<f32>, String>,
}

/// Runs `d` on `frame` (one call to warm up, then one counted for allocations).
fn run_single(d: &dyn Denoiser, frame: &Frame<'_>, failures: &mut Vec<String>, name: &str) -> Result<Vec<f32>, String> {
    let (w, h) = d.size();
    let mut scratch = vec![0f64; d.scratch_len()];
    let mut out = vec![f32::NAN; 3 * w * h];
    let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).map_err(|e| e.to_string())?;
    d.denoise(frame, &mut scratch, &mut ov).map_err(|e| e.to_string())?;
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    d.denoise(frame, &mut scratch, &mut ov).map_err(|e| e.to_string())?;
    if ALLOCATIONS.load(Ordering::Relaxed) != before {
        failures.push(format!("{name}: a denoise call allocated"));
    }
    Ok(out)
}

/// Three frames of a sequence through `d` (a quarter-pixel pan); the last output.
fn run_temporal(d: &dyn TemporalDenoiser, f: &Owned, set: GuideSet, failures: &mut Vec<String>, name: &str) -> Result<Vec<f32>, String> {
    let (w, h) = d.size();
    let mut history = vec![0f32; d.history_len()];
    let mut scratch = vec![0f64; d.temporal_scratch_len()];
    let mut out = vec![f32::NAN; 3 * w * h];
    let motion: Vec<f32> = (0..w * h).flat_map(|_| [0.25f32, -0.25]).collect();
    let mv = ImageView::interleaved(&motion, w, h, 2).map_err(|e| e.to_string())?;
    let frame = f.frame(set);
    for k in 0..3u32 {
        let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).map_err(|e| e.to_string())?;
        let mut hist = History::resume(&mut history, k);
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        d.denoise_temporal(&frame, (k > 0).then_some(&mv), &mut hist, &mut scratch, &mut ov).map_err(|e| e.to_string())?;
        if ALLOCATIONS.load(Ordering::Relaxed) != before {
            failures.push(format!("{name}: frame {k} allocated"));
        }
    }
    Ok(out)
}

/// Largest relative difference |a − b| / (1e-3 + |b|).
fn rel(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs() / (1e-3 + y.abs())).fold(0f32, f32::max)
}

/// RMS difference over the mean magnitude.
fn rms_rel(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().max(1) as f64;
    let rms = (a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / n).sqrt();
    let mean = b.iter().map(|y| y.abs() as f64).sum::<f64>() / n;
    (rms / mean.max(1e-6)) as f32
}

/// A case's distance from another run of it, over its bound (≤ 1 passes):
/// WALR's (traced) by [`rms_rel`] against [`TRACED_BOUND`], BMFR's by [`rel`]
/// against [`QR_BOUND`], the others by [`rel`] against `bound`.
fn distance(name: &str, a: &[f32], b: &[f32], bound: f32) -> f32 {
    if name.starts_with("walr") {
        rms_rel(a, b) / TRACED_BOUND
    } else if name.starts_with("bmfr") {
        rel(a, b) / QR_BOUND
    } else {
        rel(a, b) / bound
    }
}

/// Checks of one case, and its record: SIMD against scalar (when run), finite output.
fn check(name: String, simd: Result<Vec<f32>, String>, scalar: Option<Result<Vec<f32>, String>>, failures: &mut Vec<String>) -> Case {
    match (&simd, &scalar) {
        (Ok(a), Some(Ok(b))) if distance(&name, a, b, SIMD_BOUND) > 1.0 => {
            failures.push(format!("{name}: SIMD against scalar at {} of the bound", distance(&name, a, b, SIMD_BOUND)))
        }
        (Ok(_), Some(Err(e))) | (Err(e), Some(Ok(_))) => failures.push(format!("{name}: only one kernel failed: {e}")),
        _ => {}
    }
    if let Ok(a) = &simd {
        if !a.iter().all(|v| v.is_finite()) {
            failures.push(format!("{name}: output not finite"));
        }
    }
    Case { name, result: simd }
}

/// A single-frame case built by `make` for each kernel: SIMD and scalar run and compared.
fn single_case<D: Denoiser>(
    name: String,
    make: impl Fn(Kernel) -> Result<D, Error>,
    frame: &Frame<'_>,
    failures: &mut Vec<String>,
) -> Case {
    let mut run = |kernel| make(kernel).map_err(|e| e.to_string()).and_then(|d| run_single(&d, frame, failures, &name));
    let (simd, scalar) = (run(Kernel::Simd), run(Kernel::Scalar));
    check(name, simd, Some(scalar), failures)
}

/// A temporal case: three frames through `made` (SIMD kernels).
fn temporal_case<D: TemporalDenoiser>(name: String, made: Result<D, Error>, f: &Owned, set: GuideSet, failures: &mut Vec<String>) -> Case {
    let out = made.map_err(|e| e.to_string()).and_then(|d| run_temporal(&d, f, set, failures, &name));
    check(name, out, None, failures)
}

/// Half-float reads and writes through images against `half`'s software
/// conversion, bit for bit (NaN: any NaN), in runs of every length 0..=19 and
/// at every offset mod 8 (the bulk conversions' tails), and through a
/// 4-channel (RGBA16F) row.
fn f16_rows(failures: &mut Vec<String>) {
    let all: Vec<f16> = (0..=u16::MAX).map(f16::from_bits).collect();
    let same32 = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    let same16 = |a: f16, b: f16| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    let mut bad = 0usize;
    let planar = ImageView::f16(&all, all.len(), 1, 1, Layout::interleaved(all.len(), 1)).unwrap();
    let mut got = vec![0f32; all.len()];
    planar.read_row(0, 0, 0, &mut got).unwrap();
    bad += all.iter().zip(&got).filter(|(h, v)| !same32(**v, h.to_f32_const())).count();
    for (x0, len) in (0..8).flat_map(|x0| (0..20).map(move |len| (1000 + x0, len))) {
        let mut o = vec![0f32; len];
        planar.read_row(0, 0, x0, &mut o).unwrap();
        bad += all[x0..x0 + len].iter().zip(&o).filter(|(h, v)| !same32(**v, h.to_f32_const())).count();
    }
    let rgba = ImageView::f16(&all, all.len() / 4, 1, 4, Layout::interleaved(all.len() / 4, 4)).unwrap();
    for c in 0..4 {
        let mut o = vec![0f32; all.len() / 4];
        rgba.read_row(0, c, 0, &mut o).unwrap();
        bad += o.iter().enumerate().filter(|(i, v)| !same32(**v, all[4 * i + c].to_f32_const())).count();
    }
    // f32 → f16: every 2^-13 step across f16's range and beyond (ties to
    // even, subnormals, overflow), both signs, and the specials
    let mut vals: Vec<f32> = (0..1 << 20).map(|k: u32| f32::from_bits(0x3300_0000 + (k << 10) + (k % 7) * 0x100)).collect();
    vals.extend(vals.clone().iter().map(|v| -v));
    vals.extend([0.0, -0.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 65504.0, 65520.0, 65519.99, 6.1e-5, 5.96e-8, 2.98e-8]);
    const W: usize = 4096;
    vals.resize(vals.len().div_ceil(W) * W, 1.0);
    let mut halves = vec![f16::ONE; vals.len()];
    let mut out = ImageViewMut::new(SamplesMut::F16(&mut halves), W, vals.len() / W, 1, Layout::interleaved(W, 1)).unwrap();
    for (y, row) in vals.chunks_exact(W).enumerate() {
        out.write_row(y, 0, 0, row).unwrap();
    }
    for x0 in 0..8 {
        for len in 0..20 {
            out.write_row(1, 0, 1000 + x0, &vals[W + 1000 + x0..W + 1000 + x0 + len]).unwrap();
        }
    }
    bad += vals.iter().zip(&halves).filter(|(v, h)| !same16(**h, f16::from_f32_const(**v))).count();
    if bad > 0 {
        failures.push(format!("half-float rows: {bad} values differ from half's software conversion"));
    }
}

/// The kernels' oracles that do not depend on the frame size: WALR's
/// Cholesky (its lanes bit for bit against its scalar path, both against
/// f64 Gauss), and FLNR's network on random weights against the f64
/// network (tests/nn.rs's bound, 1e-4), on every ISA this CPU runs.
fn kernel_oracles(failures: &mut Vec<String>) {
    let mut rng = Rng(99);
    for r in [cholesky_case::<3>(&mut rng), cholesky_case::<4>(&mut rng), cholesky_case::<6>(&mut rng), cholesky_case::<8>(&mut rng)] {
        if let Err(e) = r {
            failures.push(format!("walr cholesky: {e}"));
        }
    }
    for (k, (w, h)) in SIZES.into_iter().enumerate() {
        for widths in [&[3][..], &[2, 4, 6]] {
            let b = blob(5, 3, widths, 12.0, k as u64 + 1);
            let net = match lrdenoise::nn::UNet::parse(&b) {
                Ok(n) => n,
                Err(e) => {
                    failures.push(format!("network {widths:?}: {e}"));
                    continue;
                }
            };
            let mut rng = Rng(9 + k as u64);
            let input: Vec<f32> = (0..5 * w * h).map(|_| rng.f32() * 4.0 - 2.0).collect();
            let want = network_reference(&b, &input, w, h);
            let mut scratch = vec![0f32; net.scratch_len(w, h)];
            for isa in [isa::Isa::Portable, isa::Isa::detect(), isa::Isa::detect_widest()] {
                let mut out = vec![0f32; 3 * w * h];
                match net.forward_with(isa, &input, w, h, &mut scratch, &mut out) {
                    Ok(()) => {
                        let worst = out.iter().zip(&want).map(|(a, b)| (*a as f64 - b).abs()).fold(0f64, f64::max);
                        if worst.is_nan() || worst > 1e-4 || !out.iter().all(|v| v.is_finite()) {
                            failures.push(format!("network {widths:?} {isa:?} {w}x{h}: {worst} from the f64 network"));
                        }
                    }
                    Err(e) => failures.push(format!("network {widths:?} {isa:?} {w}x{h}: {e}")),
                }
            }
        }
    }
}

/// BMFR without its stochastic term or firefly clamp against the f64
/// blockwise fit (tests/bmfr.rs's bound, 1e-5 absolute), at two grid
/// offsets. Frames of at least 9 rows and columns: smaller ones mirror a
/// block onto a few pixels, whose features the oracle cannot rescale.
fn bmfr_against_oracle(w: usize, h: usize, failures: &mut Vec<String>) {
    if w.min(h) < 9 {
        return;
    }
    let f = random_guides(w, h, w as u64);
    let set = GuideSet { depth: true, user: 2, ..GuideSet::NONE };
    let cfg = BmfrConfig { noise: 0.0, block: 8, fireflies: None, ..BmfrConfig::with_guides(set) };
    let b = match Bmfr::new(cfg, w, h) {
        Ok(b) => b,
        Err(e) => return failures.push(format!("bmfr oracle {w}x{h}: {e}")),
    };
    let mut scratch = vec![0f32; b.scratch_len()];
    for index in [0, 5] {
        let mut out = vec![f32::NAN; 3 * w * h];
        let run = ImageViewMut::interleaved(&mut out, w, h, 3).and_then(|mut ov| b.denoise(&f.frame(set), index, &mut scratch, &mut ov));
        match run {
            Ok(_) => {
                let (max, _) = diff(&out, &bmfr_oracle(&b, &f, index));
                if max.is_nan() || max > 1e-5 || !out.iter().all(|v| v.is_finite()) {
                    failures.push(format!("bmfr {w}x{h} frame {index}: {max} from the f64 fit"));
                }
            }
            Err(e) => failures.push(format!("bmfr oracle {w}x{h}: {e}")),
        }
    }
}

/// Every case at one size.
fn cases_at(w: usize, h: usize, blob: &[u8], failures: &mut Vec<String>) -> Vec<Case> {
    let f = Owned::synthetic(w, h, (w * 31 + h) as u64, 0.5);
    let mut cases = Vec::new();

    let flr_cfgs = [
        ("flr defaults", FlrConfig::default()),
        (
            "flr gaussian b4 tikhonov",
            FlrConfig {
                block: 4,
                blur: Blur::Gaussian { sigma: 6.0, radius: None },
                regularization: Regularization::Tikhonov { eps: 1e-4 },
                guides: GuideSet { normal: true, depth: true, position: true, ao: true, user: 0 },
                ..FlrConfig::default()
            },
        ),
        ("flr box b16", FlrConfig { block: 16, blur: Blur::Box { radius: 8.0 }, guides: GuideSet::NORMAL_DEPTH, ..FlrConfig::default() }),
    ];
    for (label, c) in flr_cfgs {
        let make = |kernel| Flr::new(FlrConfig { kernel, ..c }, w, h);
        cases.push(single_case(format!("{label} {w}x{h}"), make, &f.frame(c.guides), failures));
    }

    // FLR against the f64 reference (per pixel: B = 1, one Gaussian window)
    let set = GuideSet::NORMAL_DEPTH_AO;
    let c = FlrConfig { blur: Blur::Gaussian { sigma: 2.0, radius: None }, ..cfg(set, 1) };
    match Flr::new(c, w, h).map_err(|e| e.to_string()).and_then(|flr| run_single(&flr, &f.frame(set), failures, "flr oracle")) {
        Ok(out) => {
            let want = reference(&c, w, h, &f.channels(set), &f.noisy);
            let (max, _) = diff(&out, &want);
            if max > ORACLE_BOUND {
                failures.push(format!("flr B1 {w}x{h}: {max} from the f64 reference"));
            }
        }
        Err(e) => failures.push(format!("flr oracle {w}x{h}: {e}")),
    }

    bmfr_against_oracle(w, h, failures);
    let bmfr = BmfrConfig::default();
    let make = |kernel| Bmfr::new(BmfrConfig { kernel, ..bmfr }, w, h);
    cases.push(single_case(format!("bmfr {w}x{h}"), make, &f.frame(bmfr.guides), failures));
    let walr = WalrConfig::default();
    let make = |kernel| Walr::new(WalrConfig { kernel, ..walr }, w, h);
    cases.push(single_case(format!("walr {w}x{h}"), make, &f.frame(walr.guides), failures));

    let name = format!("flnr {w}x{h}");
    let flnr = Flnr::new(FlnrConfig::new(blob), w, h)
        .map_err(|e| e.to_string())
        .and_then(|d| run_single(&d, &f.frame(lrdenoise::flnr::INPUT_GUIDES), failures, &name));
    cases.push(check(name, flnr, None, failures));

    let flr = FlrConfig::default();
    let t = TemporalFlr::new(flr, TemporalConfig::default(), w, h);
    cases.push(temporal_case(format!("flr temporal {w}x{h}"), t, &f, flr.guides, failures));
    cases.push(temporal_case(format!("bmfr temporal {w}x{h}"), Bmfr::new(bmfr, w, h), &f, bmfr.guides, failures));
    cases.push(temporal_case(format!("walr temporal {w}x{h}"), Walr::new(walr, w, h), &f, walr.guides, failures));
    cases
}

/// One line per case: name, then `ok` and the values (shortest round-trip
/// decimal), or `err` and the message.
fn write(cases: &[Case]) -> String {
    let mut s = String::new();
    for c in cases {
        match &c.result {
            Ok(v) => {
                let _ = write!(s, "{}\tok", c.name);
                for x in v {
                    let _ = write!(s, " {x}");
                }
            }
            Err(e) => {
                let _ = write!(s, "{}\terr {e}", c.name);
            }
        }
        s.push('\n');
    }
    s
}

fn compare(cases: &[Case], other: &str, failures: &mut Vec<String>) {
    let lines: Vec<&str> = other.lines().collect();
    if lines.len() != cases.len() {
        failures.push(format!("{} cases here, {} in the other target's file", cases.len(), lines.len()));
        return;
    }
    let mut worst = (0f32, String::new());
    for (c, line) in cases.iter().zip(lines) {
        let (name, rest) = line.split_once('\t').unwrap_or((line, ""));
        if name != c.name {
            failures.push(format!("case {} here, {name} there", c.name));
            continue;
        }
        match (&c.result, rest.strip_prefix("ok")) {
            (Ok(v), Some(vals)) => {
                let theirs: Vec<f32> = vals.split_whitespace().filter_map(|t| t.parse().ok()).collect();
                if theirs.len() != v.len() {
                    failures.push(format!("{name}: {} values here, {} there", v.len(), theirs.len()));
                    continue;
                }
                let d = distance(name, v, &theirs, ARCH_BOUND);
                if d > worst.0 {
                    worst = (d, name.to_string());
                }
                if d > 1.0 {
                    failures.push(format!("{name}: {d} of the bound from the other target"));
                }
            }
            (Err(e), None) if rest == format!("err {e}") => {}
            (r, _) => failures.push(format!("{name}: {} here, {rest} there", if r.is_ok() { "ok" } else { "an error" })),
        }
    }
    println!("largest difference from the other target: {} of its bound ({})", worst.0, worst.1);
}

fn main() {
    let blob = match std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/train/flnr.bin")) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("arch_check: train/flnr.bin: {e}");
            std::process::exit(1);
        }
    };
    println!("arch_check: {} ({}, kernels {:?})", std::env::consts::ARCH, simd_level(), isa::Isa::detect());
    let mut failures = Vec::new();
    f16_rows(&mut failures);
    kernel_oracles(&mut failures);
    let mut cases = Vec::new();
    for (w, h) in SIZES {
        cases.extend(cases_at(w, h, &blob, &mut failures));
    }
    println!(
        "{} outputs, {} typed errors",
        cases.iter().filter(|c| c.result.is_ok()).count(),
        cases.iter().filter(|c| c.result.is_err()).count()
    );
    if let Ok(path) = std::env::var("LRD_ARCH_WRITE") {
        if let Err(e) = std::fs::write(&path, write(&cases)) {
            failures.push(format!("writing {path}: {e}"));
        }
    }
    if let Ok(path) = std::env::var("LRD_ARCH_AGAINST") {
        match std::fs::read_to_string(&path) {
            Ok(other) => compare(&cases, &other, &mut failures),
            Err(e) => failures.push(format!("reading {path}: {e}")),
        }
    }
    for f in &failures {
        println!("FAILED: {f}");
    }
    if !failures.is_empty() {
        std::process::exit(1);
    }
    println!("arch_check: all passed");
}
