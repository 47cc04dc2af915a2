//! `lrd`: denoise frames, evaluate and compare methods, report error against
//! run time, advise what a scene can drop, benchmark. See the README.

mod evaluate;
mod methods;
mod report;
mod runner;

use lrdenoise_cli::{exrio, metrics};

use clap::{Parser, Subcommand};
use evaluate::{evaluate, list_frames, means, time_method, EvalOptions, Record, Variant};
use exrio::{ExrFrame, Layer};
use methods::{check_method, Built, FlrArgs, Method, MethodName};
use runner::Inputs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(name = "lrd", version, about = "Real-time regression denoisers for path-traced diffuse GI (lrdenoise)")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Denoise one frame: writes OUT.exr with a `denoised` layer (plus the input layers)
    Denoise {
        /// The input frame: an OpenEXR file with a `noisy` RGB layer and the guide layers (normal, depth, position, ao, albedo)
        frame: PathBuf,
        /// The EXR file to write (the `denoised` layer, plus the input's layers unless --only-output)
        #[arg(short, long, value_name = "OUT.exr")]
        output: PathBuf,
        #[command(flatten)]
        run: RunArgs,
        /// Also write a tone-mapped PNG preview of albedo * denoised
        #[arg(long)]
        png: Option<PathBuf>,
        /// Write only the `denoised` layer
        #[arg(long)]
        only_output: bool,
    },
    /// Denoise a sequence directory (frame_NNNN.exr) into OUTDIR, same file names
    DenoiseSeq {
        /// Directory of the sequence's frames, frame_0000.exr, frame_0001.exr, ... (denoised in name order)
        dir: PathBuf,
        /// Directory to write the denoised frames to (created if missing)
        #[arg(short, long, value_name = "OUTDIR")]
        output: PathBuf,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Score methods on frames with a reference: PSNR, SSIM, FLIP, rMSE and median time
    Eval {
        /// Frames with a `reference` layer, or directories of them (a directory of frame_NNNN.exr is a sequence)
        #[arg(required = true)]
        frames: Vec<PathBuf>,
        /// Methods to score, comma separated (each with the flags below)
        #[arg(long, value_enum, value_delimiter = ',', default_value = "flr")]
        methods: Vec<MethodName>,
        #[command(flatten)]
        flr: FlrArgs,
        /// Write one JSON record per (method, frame)
        #[arg(long)]
        json: Option<PathBuf>,
        /// Timed runs per measurement (after one warm-up; at least 5)
        #[arg(long, default_value_t = 7)]
        runs: usize,
        /// Threads (default: all cores)
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Evaluate every method and configuration; write DIR/report.md, plot.svg/png and image strips
    Report {
        /// Frames with a `reference` layer, or directories of them (a directory of frame_NNNN.exr is a sequence)
        #[arg(required = true)]
        frames: Vec<PathBuf>,
        /// Directory to write report.md, plot.png, plot.svg, records.json and strip_FRAME.png to (created if missing)
        #[arg(short, long, value_name = "DIR")]
        output: PathBuf,
        /// JSON files of records produced elsewhere (same schema as `eval --json`), merged into tables and plot
        #[arg(long)]
        peers: Vec<PathBuf>,
        /// Timed runs per measurement (after one warm-up; at least 5)
        #[arg(long, default_value_t = 7)]
        runs: usize,
        /// Threads (default: all cores)
        #[arg(long)]
        threads: Option<usize>,
        /// Strips with every configuration (default: the noisy input, the best configuration of each method, the reference)
        #[arg(long)]
        full_strips: bool,
    },
    /// Measure which guides and settings earn their cost on this scene; print the flags to use
    Advise {
        /// A frame with a `reference` layer and the guide layers
        frame: PathBuf,
        /// Cheapest configuration within D dB of the best (default 0.25)
        #[arg(long, conflicts_with = "budget_ms")]
        max_loss_db: Option<f64>,
        /// Best configuration within T ms
        #[arg(long)]
        budget_ms: Option<f64>,
        /// Timed runs per measurement (after one warm-up; at least 5)
        #[arg(long, default_value_t = 7)]
        runs: usize,
        /// Threads (default: all cores)
        #[arg(long)]
        threads: Option<usize>,
        /// Methods to weigh, comma separated from flr,bmfr,walr: besides FLR's guides × block × window
        /// grid, BMFR at 32×32 and 64×64 blocks and WALR's stages (tracing, blend) with the frame's
        /// guides; the choice is then made over all of them
        #[arg(long, default_value = "flr")]
        methods: String,
    },
    /// Time the denoiser alone on a synthetic frame (or FRAME resampled to WxH)
    Bench {
        /// The method to time
        #[arg(long, value_enum, default_value_t = MethodName::Flr)]
        method: MethodName,
        /// Frame size, WIDTHxHEIGHT
        #[arg(long, default_value = "1920x1080")]
        size: String,
        /// Threads
        #[arg(long, default_value_t = 1)]
        threads: usize,
        /// Timed runs (after one warm-up; at least 5); the median is reported
        #[arg(long, default_value_t = 30)]
        runs: usize,
        #[command(flatten)]
        flr: FlrArgs,
        /// An EXR frame to resample to --size and time on (default: a synthetic frame with every guide)
        frame: Option<PathBuf>,
    },
    /// Write FLR's GPU compute shaders (WGSL, SPIR-V, MSL, HLSL) and their dispatch description to DIR
    Shaders {
        /// Directory to write flr.wgsl, flr.spv, flr.metal, flr.hlsl, dispatch.md and params.bin to (created if missing)
        #[arg(short, long, value_name = "DIR")]
        out: PathBuf,
        /// Frame size the dispatch description is written for
        #[arg(long, default_value = "1920x1080")]
        size: String,
        /// Describe f16 noisy and guide buffers (default f32)
        #[arg(long)]
        f16_inputs: bool,
        #[command(flatten)]
        flr: FlrArgs,
    },
    /// Denoise the bundled sample frames with every method and write the report to ./lrd-demo/
    Demo {
        /// Directory to write the report to (report.md, plot.png, plot.svg, records.json, strip_FRAME.png)
        #[arg(short, long, value_name = "DIR", default_value = "lrd-demo")]
        output: PathBuf,
        /// Threads (default: all cores)
        #[arg(long)]
        threads: Option<usize>,
        /// Strips with every configuration (default: the noisy input, the best configuration of each method, the reference)
        #[arg(long)]
        full_strips: bool,
    },
}

/// Flags shared by `denoise` and `denoise-seq`.
#[derive(clap::Args)]
struct RunArgs {
    /// The denoiser (on a sequence, bmfr and walr run their temporal pipelines)
    #[arg(long, value_enum, default_value_t = MethodName::Flr)]
    method: MethodName,
    #[command(flatten)]
    flr: FlrArgs,
    /// The noisy layer to denoise (e.g. noisy4)
    #[arg(long, default_value = "noisy")]
    input_layer: String,
    /// Threads (default: all cores)
    #[arg(long)]
    threads: Option<usize>,
}

fn threads_or_all(t: Option<usize>) -> usize {
    t.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).max(1)
}

fn layer_of(comps: &[&str], inter: &[f32]) -> Layer {
    let n = comps.len();
    Layer {
        comps: comps.iter().map(|s| s.to_string()).collect(),
        planes: (0..n).map(|c| inter.iter().skip(c).step_by(n).copied().collect()).collect(),
    }
}

fn write_png(path: &Path, rgb: &[f32], w: usize, h: usize) -> Result<(), String> {
    let bytes: Vec<u8> = rgb.iter().map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8).collect();
    image::RgbImage::from_raw(w as u32, h as u32, bytes).ok_or("png: bad size")?.save(path).map_err(|e| format!("{}: {e}", path.display()))
}

struct DenoiseJob<'a> {
    method: &'a str,
    flr: &'a FlrArgs,
    input_layer: &'a str,
    threads: usize,
}

/// Reads, denoises and writes one frame; returns (config label, ms, width,
/// height). `method` is built from the first frame and kept (sequences: the
/// temporal history lives in it).
fn denoise_file(
    job: &DenoiseJob,
    method: &mut Option<Built>,
    input: &Path,
    output: &Path,
    png: Option<&Path>,
    only_output: bool,
) -> Result<(String, f64, usize, usize), String> {
    check_method(job.method)?;
    let exr = ExrFrame::read(input)?;
    let inputs = Inputs::from_exr(&exr, input, job.input_layer)?;
    if method.is_none() {
        *method = Some(Method::build(job.method, job.flr, &inputs, job.threads).map_err(|e| format!("{}: {e}", input.display()))?);
    }
    let m = method.as_mut().ok_or("no method")?;
    let mut out = vec![0f32; inputs.w * inputs.h * 3];
    let t = Instant::now();
    m.method.run(&inputs, &mut out).map_err(|e| format!("{}: {e}", input.display()))?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let den = layer_of(&["R", "G", "B"], &out);
    let mut layers: Vec<(&str, &Layer)> = vec![("denoised", &den)];
    if !only_output {
        for (k, l) in &exr.layers {
            if k != "denoised" {
                layers.push((k.as_str(), l));
            }
        }
    }
    ExrFrame::write(output, inputs.w, inputs.h, &layers)?;
    if let Some(p) = png {
        let albedo = inputs.albedo.clone().unwrap_or_else(|| vec![1.0; out.len()]);
        let i: Vec<f32> = out.iter().zip(&albedo).map(|(a, b)| a * b).collect();
        let l = match &inputs.reference {
            Some(r) => metrics::mean_luminance(&r.iter().zip(&albedo).map(|(a, b)| a * b).collect::<Vec<_>>()),
            None => metrics::mean_luminance(&i),
        };
        write_png(p, &metrics::tonemap(&i, l), inputs.w, inputs.h)?;
    }
    Ok((m.label.clone(), ms, inputs.w, inputs.h))
}

fn print_table(records: &[Record]) {
    println!("{}", report::table(records, true));
    let m = means(records);
    println!("{}", report::table(&m, false));
}

/// The configurations `lrd report` compares: the default, then one setting changed at a time.
fn report_variants() -> Vec<Variant> {
    let g = |s: &str| FlrArgs { guides: Some(s.into()), ..Default::default() };
    vec![
        Variant::noisy("noisy"),
        Variant::noisy("noisy4"),
        Variant::flr(FlrArgs::default()),
        Variant::flr(g("none")),
        Variant::flr(g("normal")),
        Variant::flr(g("normal,depth")),
        Variant::flr(g("normal,depth,position,ao")),
        Variant::flr(FlrArgs { block: Some(4), ..Default::default() }),
        Variant::flr(FlrArgs { block: Some(16), ..Default::default() }),
        Variant::flr(FlrArgs { sigma: Some("6".into()), ..Default::default() }),
        Variant::flr(FlrArgs { sigma: Some("24".into()), ..Default::default() }),
        Variant::flr(FlrArgs { sigma: Some("12".into()), ..Default::default() }),
        Variant::flr(FlrArgs { box_radius: Some(16.0), ..Default::default() }),
        Variant::flr(FlrArgs { regularization: Some("tikhonov:1e-4".into()), ..Default::default() }),
        Variant::flr(FlrArgs { upsample: Some(2), ..Default::default() }),
        Variant::flr(FlrArgs { without_ao: true, ..Default::default() }),
        Variant::flr(FlrArgs { ao_demodulation: Some("off".into()), ..Default::default() }),
        Variant::flr(FlrArgs::default()).on("noisy4"),
        Variant::method("bmfr", FlrArgs::default()),
        Variant::method("bmfr", FlrArgs { shrinkage: Some(0.0), ..Default::default() }),
        Variant::method("bmfr-temporal", FlrArgs::default()),
        Variant::method("bmfr-temporal", FlrArgs { shrinkage: Some(0.0), ..Default::default() }),
        Variant::method("walr", FlrArgs::default()),
        Variant::method("walr", FlrArgs { no_tracing: true, ..Default::default() }),
        Variant::method("walr", FlrArgs { storage: Some("f16".into()), ..Default::default() }),
        Variant::method("walr", FlrArgs { previous_weight: Some("0.6".into()), ..Default::default() }),
        Variant::method("walr", FlrArgs { previous_weight: Some("0".into()), ..Default::default() }),
        Variant::method("walr", FlrArgs { iterations: Some(3), previous_weight: Some("0".into()), ..Default::default() }),
        Variant::method("walr-temporal", FlrArgs::default()),
        Variant::method("flnr", FlrArgs::default()),
    ]
}

/// Writes the report into `out`; returns the mean records (over frames, one per configuration).
fn write_report(
    frames: &[PathBuf],
    out: &Path,
    peers: &[PathBuf],
    runs: usize,
    threads: usize,
    full_strips: bool,
) -> Result<Vec<Record>, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let opt = EvalOptions { runs: runs.max(5), threads, keep_images: true };
    let (mut records, images) = evaluate(frames, &report_variants(), &opt)?;
    if records.is_empty() {
        return Err("no frame with a 'reference' layer: nothing to report".into());
    }
    for p in peers {
        let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
        let peer: Vec<Record> = serde_json::from_str(&text).map_err(|e| format!("{}: not a JSON list of records ({e})", p.display()))?;
        records.extend(peer);
    }
    let mean = means(&records);
    let refs: Vec<&Record> = mean.iter().collect();
    report::plot(out, &refs)?;
    // the strips: by default the noisy input and each method's best configuration
    let keep: Vec<String> = report::best_per_method(&mean).iter().map(|r| r.config.clone()).collect();
    let strips = report::strips(out, &images, (!full_strips).then_some(keep.as_slice()))?;
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string()))
        .unwrap_or_else(|| "unknown CPU".into());
    let (w, h) = (records[0].width, records[0].height);
    let mut md = String::new();
    md += "# lrdenoise report\n\n";
    md += &format!(
        "{} frame(s), {w}x{h} (first frame); {threads} thread(s); {cpu}; SIMD level `{}` (compiled; run-time choice for FLR's moments, solve and apply, BMFR's QR and FLNR's 3×3 layers: `{:?}`); time = median of {} runs after a warm-up, denoiser only (no I/O). \
         Metrics follow shared/DATA.md (albedo-modulated, tone-mapped PSNR/SSIM/LDR-FLIP, linear rMSE). Peer rows (if any) were measured by their own tools.\n\n",
        images.len(),
        lrdenoise::SIMD_LEVEL,
        lrdenoise::isa::Isa::detect(),
        opt.runs
    );
    md += "## Mean over frames\n\n";
    md += &report::table(&mean, false);
    md += "\n### Configuration names\n\n";
    md += report::LEGEND;
    md += "\n![error versus run time](plot.png)\n\n";
    md += "## Per frame\n\n";
    md += &report::table(&records, true);
    md += if full_strips {
        "\n## Image strips\n\nTop: noisy | each configuration | reference; bottom: FLIP error maps.\n\n"
    } else {
        "\n## Image strips\n\nTop: noisy | the best configuration of each method (mean PSNR) | reference; bottom: FLIP error maps. \
         Every configuration: `--full-strips`.\n\n"
    };
    for s in &strips {
        md += &format!("![{s}]({s})\n\n");
    }
    std::fs::write(out.join("report.md"), md).map_err(|e| format!("{}: {e}", out.display()))?;
    let json = serde_json::to_string_pretty(&records).map_err(|e| e.to_string())?;
    std::fs::write(out.join("records.json"), json).map_err(|e| e.to_string())?;
    Ok(mean)
}

/// The line naming what `lrd report` / `lrd demo` wrote.
fn report_written(out: &Path) -> String {
    format!("report: {} (with plot.png, plot.svg, records.json and strip_FRAME.png in {})", out.join("report.md").display(), out.display())
}

/// One `lrd advise` line weighing an option: the best configuration without
/// it (`a`) against the best with it (`b`), each with its description;
/// `verdicts[0]` when `b` gains more than 0.1 dB, else `verdicts[1]`.
fn print_option(name: &str, (what_a, a): (&str, &Record), (what_b, b): (&str, &Record), verdicts: [&str; 2]) {
    let gain = b.psnr - a.psnr;
    let verdict = if gain > 0.1 { verdicts[0] } else { verdicts[1] };
    println!(
        "  {name:<17}: {what_a} {:.2} dB in {:.3} ms, {what_b} {:.2} dB in {:.3} ms ({gain:+.2} dB) -> {verdict}",
        a.psnr, a.ms, b.psnr, b.ms
    );
}

fn advise(frame: &Path, max_loss: Option<f64>, budget: Option<f64>, runs: usize, threads: usize, methods: &str) -> Result<(), String> {
    let exr = ExrFrame::read(frame)?;
    let inputs = Inputs::from_exr(&exr, frame, "noisy")?;
    if inputs.reference.is_none() {
        return Err(format!("{}: advise measures quality and needs a 'reference' layer", frame.display()));
    }
    let methods: Vec<&str> = methods.split(',').map(str::trim).filter(|m| !m.is_empty()).collect();
    if let Some(m) = methods.iter().find(|m| !["flr", "bmfr", "walr"].contains(m)) {
        return Err(format!("--methods: '{m}' is not flr, bmfr or walr"));
    }
    if !methods.contains(&"flr") {
        return Err("--methods: flr is always weighed (the guide verdicts are FLR's); add bmfr and/or walr to it".into());
    }
    // Every subset of the available guides x block sizes x window sizes.
    let avail: Vec<&str> = [
        ("normal", inputs.normal.is_some()),
        ("depth", inputs.depth.is_some()),
        ("position", inputs.position.is_some()),
        ("ao", inputs.ao.is_some()),
        ("albedo", inputs.albedo.is_some()),
    ]
    .iter()
    .filter(|(_, a)| *a)
    .map(|(n, _)| *n)
    .collect();
    let mut variants = vec![Variant::noisy("noisy")];
    for mask in 0..(1usize << avail.len()) {
        let g: Vec<&str> = avail.iter().enumerate().filter(|(i, _)| mask >> i & 1 == 1).map(|(_, n)| *n).collect();
        let gs = if g.is_empty() { "none".to_string() } else { g.join(",") };
        for block in [4, 8, 16] {
            for sigma in ["6", "12", "24", "6,12,20"] {
                // the adaptive window with AO also without AO as a candidate (`--without-ao`)
                let with_ao = sigma.contains(',') && g.contains(&"ao");
                for without_ao in [false, true].into_iter().take(1 + with_ao as usize) {
                    // with AO at B = 8, also without the AO demodulation
                    let plain = g.contains(&"ao") && block == 8 && !without_ao;
                    for demod in [None, Some("off")].into_iter().take(1 + plain as usize) {
                        variants.push(Variant::flr(FlrArgs {
                            guides: Some(gs.clone()),
                            block: Some(block),
                            sigma: Some(sigma.into()),
                            without_ao,
                            ao_demodulation: demod.map(String::from),
                            ..Default::default()
                        }));
                    }
                }
            }
        }
    }
    // Other methods with what the frame has (BMFR wants normals; WALR normals and positions),
    // and WALR's optional stages one at a time.
    let has = |g: &str| avail.contains(&g);
    if methods.contains(&"bmfr") && has("normal") {
        for block in [32, 64] {
            variants.push(Variant::method("bmfr", FlrArgs { block: Some(block), ..Default::default() }));
        }
        variants.push(Variant::method("bmfr", FlrArgs { shrinkage: Some(0.0), ..Default::default() }));
    }
    if methods.contains(&"walr") && has("normal") && has("position") {
        let pw = |w: &str| Some(w.to_string());
        variants.push(Variant::method("walr", FlrArgs::default()));
        variants.push(Variant::method("walr", FlrArgs { no_tracing: true, ..Default::default() }));
        variants.push(Variant::method("walr", FlrArgs { previous_weight: pw("0.6"), ..Default::default() }));
        variants.push(Variant::method("walr", FlrArgs { previous_weight: pw("0"), ..Default::default() }));
    }
    let opt = EvalOptions { runs: runs.max(5), threads, keep_images: false };
    let (records, _) = evaluate(&[frame.to_path_buf()], &variants, &opt)?;
    let noisy = records.iter().find(|r| r.method == "noisy").map(|r| r.psnr).unwrap_or(f64::NAN);
    let flr: Vec<&Record> = records.iter().filter(|r| r.method == "flr").collect();
    // the choice is made over every method weighed
    let all: Vec<&Record> = records.iter().filter(|r| r.method != "noisy").collect();
    let best = all.iter().max_by(|a, b| a.psnr.total_cmp(&b.psnr)).ok_or("no configuration could run")?;
    let pick = match budget {
        Some(t) => all.iter().filter(|r| r.ms <= t).max_by(|a, b| a.psnr.total_cmp(&b.psnr)).ok_or_else(|| {
            format!("no configuration runs within {t} ms (fastest: {:.3} ms)", all.iter().map(|r| r.ms).fold(f64::MAX, f64::min))
        })?,
        None => {
            let d = max_loss.unwrap_or(0.25);
            all.iter().filter(|r| r.psnr >= best.psnr - d).min_by(|a, b| a.ms.total_cmp(&b.ms)).unwrap_or(best)
        }
    };
    // What each guide is worth: best PSNR with it minus best without it.
    println!("{}: {} configurations measured, {threads} thread(s), noisy input {noisy:.2} dB", frame.display(), flr.len());
    // (By the --guides value: "normal" also occurs in "--regularization normalized:...".)
    let uses = |r: &Record, g: &str| {
        r.flags.split("--guides ").nth(1).and_then(|v| v.split_whitespace().next()).is_some_and(|v| v.split(',').any(|x| x == g))
    };
    for gname in &avail {
        let with = flr.iter().filter(|r| uses(r, gname)).map(|r| r.psnr).fold(f64::MIN, f64::max);
        let without = flr.iter().filter(|r| !uses(r, gname)).map(|r| r.psnr).fold(f64::MIN, f64::max);
        let verdict = if with - without > 0.1 { "keep" } else { "can drop" };
        println!("  guide {gname:<8}: best with {with:.2} dB, without {without:.2} dB ({:+.2} dB) -> {verdict}", with - without);
    }
    // The AO-free candidate: the best adaptive configuration with AO, with and without it
    let adaptive_ao = |free: bool| {
        flr.iter()
            .filter(|r| uses(r, "ao") && r.flags.contains("--sigma 6,12,20") && r.flags.contains("--without-ao") == free)
            .max_by(|a, b| a.psnr.total_cmp(&b.psnr))
    };
    if let (Some(d), Some(f)) = (adaptive_ao(false), adaptive_ao(true)) {
        let (a, b) = (("best adaptive with AO", *d), ("with the AO-free candidate", *f));
        print_option("flr without-ao", a, b, ["use it (--without-ao)", "skip it"]);
    }
    // The AO demodulation: the best B = 8 configuration with AO, with it (the default) and without
    let demodulated = |on: bool| {
        flr.iter()
            .filter(|r| uses(r, "ao") && r.flags.contains("--block 8 ") && !r.flags.contains("--without-ao"))
            .filter(|r| r.flags.contains("--ao-demodulation off") != on)
            .max_by(|a, b| a.psnr.total_cmp(&b.psnr))
    };
    if let (Some(d), Some(p)) = (demodulated(true), demodulated(false)) {
        let (a, b) = (("best B = 8 with AO", *d), ("without the AO demodulation", *p));
        print_option("flr ao-demod", a, b, ["turn it off (--ao-demodulation off)", "keep it"]);
    }
    // BMFR and WALR, each against its own default
    let find = |method: &str, flag: &str| records.iter().find(|r| r.method == method && r.flags.contains(flag));
    let walr = |flag: &str| find("walr", flag);
    let walr_default = records.iter().find(|r| r.method == "walr" && r.flags.contains("adaptive") && !r.flags.contains("--no-tracing"));
    if let (Some(d), Some(nt)) = (walr_default, walr("--no-tracing")) {
        let verdict = if d.psnr - nt.psnr > 0.1 { "keep" } else { "can drop (it also stops light leaking past thin objects: check those)" };
        println!(
            "  walr tracing     : with {:.2} dB in {:.3} ms, without {:.2} dB in {:.3} ms ({:+.2} dB) -> {verdict}",
            d.psnr,
            d.ms,
            nt.psnr,
            nt.ms,
            d.psnr - nt.psnr
        );
    }
    if let (Some(d), Some(f), Some(one)) = (walr_default, walr("--previous-weight 0.6 "), walr("--previous-weight 0 ")) {
        let verdict = if d.psnr - f.psnr > 0.1 { "keep" } else { "can drop (--previous-weight 0.6)" };
        println!(
            "  walr blend       : adaptive {:.2} dB in {:.3} ms, fixed 0.6 {:.2} dB in {:.3} ms, one window {:.2} dB ({:+.2} dB adaptive - fixed) -> {verdict}",
            d.psnr,
            d.ms,
            f.psnr,
            f.ms,
            one.psnr,
            d.psnr - f.psnr
        );
    }
    let bmfr_default = records.iter().find(|r| r.method == "bmfr" && r.flags.contains("--block 32") && !r.flags.contains("--shrinkage"));
    if let (Some(b32), Some(b64)) = (bmfr_default, find("bmfr", "--block 64")) {
        println!("  bmfr blocks      : 32x32 {:.2} dB in {:.3} ms, 64x64 {:.2} dB in {:.3} ms", b32.psnr, b32.ms, b64.psnr, b64.ms);
    }
    if let (Some(d), Some(plain)) = (bmfr_default, find("bmfr", "--shrinkage 0")) {
        let verdict = if d.psnr - plain.psnr > 0.1 { "keep" } else { "can drop (--shrinkage 0)" };
        println!(
            "  bmfr shrinkage   : with {:.2} dB in {:.3} ms, without {:.2} dB in {:.3} ms ({:+.2} dB) -> {verdict}",
            d.psnr,
            d.ms,
            plain.psnr,
            plain.ms,
            d.psnr - plain.psnr
        );
    }
    println!("  best     : {:.2} dB in {:.3} ms  ({})", best.psnr, best.ms, best.config);
    println!("  chosen   : {:.2} dB in {:.3} ms  ({})", pick.psnr, pick.ms, pick.config);
    println!("{}", pick.flags);
    Ok(())
}

fn parse_size(size: &str) -> Result<(usize, usize), String> {
    size.split_once('x')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .filter(|(a, b)| *a > 0 && *b > 0)
        .ok_or_else(|| format!("--size: '{size}' is not WIDTHxHEIGHT"))
}

/// `lrd shaders`: the shader module in four languages plus `dispatch.md`, the
/// buffers, bindings, passes and parameter block for one frame size.
fn shaders(out: &Path, size: &str, f16_inputs: bool, flr: &FlrArgs) -> Result<(), String> {
    use lrdenoise::gpu::{GpuLayouts, GpuPlan, InputFormat};
    let (w, h) = parse_size(size)?;
    // a frame with every guide, so the guide set is --guides (default normal,depth,ao)
    let probe = Inputs {
        w: 1,
        h: 1,
        noisy: vec![0.0; 3],
        normal: Some(vec![0.0; 3]),
        depth: Some(vec![0.0]),
        position: Some(vec![0.0; 3]),
        ao: Some(vec![0.0]),
        albedo: None,
        reference: None,
        motion: None,
    };
    let cfg = flr.config(&probe)?;
    let plan = GpuPlan::new(cfg, w, h).map_err(|e| format!("shaders: {e}"))?;
    let s = lrdenoise_gpu::shaders().map_err(|e| e.to_string())?;
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let write = |name: &str, bytes: &[u8]| std::fs::write(out.join(name), bytes).map_err(|e| format!("{}: {e}", out.join(name).display()));
    write("flr.wgsl", s.wgsl.as_bytes())?;
    write("flr.spv", &le_bytes(&s.spirv))?;
    write("flr.metal", s.msl.as_bytes())?;
    write("flr.hlsl", s.hlsl.as_bytes())?;
    let input = if f16_inputs { InputFormat::F16 } else { InputFormat::F32 };
    let layouts = GpuLayouts::planar(w, h, input);
    let params = plan.params(&layouts).map_err(|e| e.to_string())?;
    let mut md = format!(
        "# FLR dispatch for {w}x{h}, {} ({} guide channels)\n\n\
         One bind group for every pass; binding i = the i-th buffer below. Inputs planar f32 \
         ({input:?} inputs, GpuLayouts::planar); other layouts: set the offsets and strides of the parameter block \
         (lrdenoise::gpu::GpuPlan::params).\n\n| binding | buffer | access | bytes |\n|---:|---|---|---:|\n",
        methods::flag_line(&cfg),
        plan.guide_channels()
    );
    for b in plan.buffers(&layouts).map_err(|e| e.to_string())? {
        md += &format!("| {} | {:?} | {:?} | {} |\n", b.binding, b.buffer, b.access, b.bytes);
    }
    md += "\nPasses, in order (a storage barrier between consecutive passes):\n\n| entry point | workgroups |\n|---|---|\n";
    for p in plan.passes().iter() {
        md += &format!("| `{}` | {} x {} x {} |\n", p.name(), p.workgroups[0], p.workgroups[1], p.workgroups[2]);
    }
    md += &format!("\nThe parameter block (binding 0, {} bytes) for these layouts is `params.bin`.\n", lrdenoise::gpu::PARAMS_BYTES);
    write("dispatch.md", md.as_bytes())?;
    write("params.bin", params.as_bytes())?;
    println!("wrote flr.wgsl, flr.spv, flr.metal, flr.hlsl, dispatch.md and params.bin to {}", out.display());
    Ok(())
}

/// 32-bit words as little-endian bytes (SPIR-V files are little-endian words).
fn le_bytes(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

fn bench(method: &str, size: &str, threads: usize, runs: usize, flr: &FlrArgs, frame: Option<&Path>) -> Result<(), String> {
    check_method(method)?;
    let (w, h) = parse_size(size)?;
    let inputs = match frame {
        Some(p) => {
            let exr = ExrFrame::read(p)?;
            Inputs::from_exr(&exr, p, "noisy")?.resample(w, h)
        }
        None => synthetic(w, h),
    };
    let mut b = Method::build(method, flr, &inputs, threads)?;
    if let Method::FlrGpu { gpu, .. } = &b.method {
        // lavapipe (a CPU rasteriser) is for correctness; its times mean nothing
        println!("GPU adapter: {}; times include upload and readback", gpu.adapter_name());
    }
    let mut out = vec![0f32; w * h * 3];
    let (med, all) = time_method(&mut b.method, &inputs, &mut out, runs.max(5))?;
    if let Method::FlrGpu { .. } = &b.method {
        gpu_pass_times(&mut b.method, &inputs, &mut out, runs.max(5))?;
    }
    let min = all.iter().copied().fold(f64::MAX, f64::min);
    let max = all.iter().copied().fold(0.0, f64::max);
    println!(
        "{method} {w}x{h} [{}] threads {threads} simd {} (run-time kernels {:?}): median {med:.3} ms (min {min:.3}, max {max:.3}, {} runs), {:.1} MPix/s",
        b.label,
        lrdenoise::SIMD_LEVEL,
        lrdenoise::isa::Isa::detect(),
        all.len(),
        (w * h) as f64 / med / 1e3
    );
    if let Some(bytes) = b.min_bytes {
        let copy = memcpy_median(bytes, all.len());
        println!(
            "baseline, same run: memcpy of the {:.1} MB one call must at least move (each input layer read once, the RGB output written once; one thread): median {copy:.3} ms; {method} takes {:.1}x that",
            bytes as f64 / 1e6,
            med / copy
        );
    }
    Ok(())
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
fn synthetic(w: usize, h: usize) -> Inputs {
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
    }
}

/// The bundled sample frames: `data/` next to the workspace, or ./data.
fn data_dir() -> Result<PathBuf, String> {
    let built = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("data");
    for d in [built, PathBuf::from("data")] {
        if d.is_dir() {
            return Ok(d);
        }
    }
    Err("cannot find the bundled data/ directory (run from the repository root)".into())
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.cmd {
        Cmd::Denoise { frame, output, run: RunArgs { method, flr, input_layer, threads }, png, only_output } => {
            let t = threads_or_all(threads);
            let method = method.as_str();
            let job = DenoiseJob { method, flr: &flr, input_layer: &input_layer, threads: t };
            let (cfg, ms, w, h) = denoise_file(&job, &mut None, &frame, &output, png.as_deref(), only_output)?;
            let written = match &png {
                Some(p) => format!("{} and {}", output.display(), p.display()),
                None => output.display().to_string(),
            };
            println!("{method} [{cfg}] {w}x{h} threads {t}: {ms:.2} ms; wrote {written}");
        }
        Cmd::DenoiseSeq { dir, output, run: RunArgs { method, flr, input_layer, threads } } => {
            let t = threads_or_all(threads);
            let frames = list_frames(std::slice::from_ref(&dir))?;
            std::fs::create_dir_all(&output).map_err(|e| format!("{}: {e}", output.display()))?;
            // On a sequence, bmfr and walr mean their temporal pipelines.
            let method = match method {
                MethodName::Bmfr => MethodName::BmfrTemporal,
                MethodName::Walr => MethodName::WalrTemporal,
                m => m,
            }
            .as_str();
            let job = DenoiseJob { method, flr: &flr, input_layer: &input_layer, threads: t };
            let pb = evaluate::progress(frames.len() as u64, method);
            let mut total = 0.0;
            let mut built = None;
            for f in &frames {
                let name = f.file_name().ok_or("bad frame name")?;
                pb.set_message(name.to_string_lossy().to_string());
                let (_, ms, _, _) = denoise_file(&job, &mut built, f, &output.join(name), None, false)?;
                total += ms;
                pb.inc(1);
            }
            pb.finish_and_clear();
            println!(
                "{method}: {} frames, mean {:.2} ms per frame, threads {t} -> {}",
                frames.len(),
                total / frames.len() as f64,
                output.display()
            );
        }
        Cmd::Eval { frames, methods, flr, json, runs, threads } => {
            let mut variants = vec![Variant::noisy("noisy")];
            for m in methods {
                variants.push(Variant::method(m.as_str(), flr.clone()));
            }
            let t = threads_or_all(threads);
            let (records, _) =
                evaluate(&list_frames(&frames)?, &variants, &EvalOptions { runs: runs.max(5), threads: t, keep_images: false })?;
            if records.is_empty() {
                return Err("no frame with a 'reference' layer: nothing to evaluate".into());
            }
            print_table(&records);
            if let Some(j) = json {
                std::fs::write(&j, serde_json::to_string_pretty(&records).map_err(|e| e.to_string())?)
                    .map_err(|e| format!("{}: {e}", j.display()))?;
            }
        }
        Cmd::Report { frames, output, peers, runs, threads, full_strips } => {
            let mean = write_report(&list_frames(&frames)?, &output, &peers, runs, threads_or_all(threads), full_strips)?;
            println!("{}", report::table(&mean, false));
            println!("{}", report_written(&output));
        }
        Cmd::Advise { frame, max_loss_db, budget_ms, runs, threads, methods } => {
            advise(&frame, max_loss_db, budget_ms, runs, threads_or_all(threads), &methods)?
        }
        Cmd::Bench { method, size, threads, runs, flr, frame } => bench(method.as_str(), &size, threads, runs, &flr, frame.as_deref())?,
        Cmd::Shaders { out, size, f16_inputs, flr } => shaders(&out, &size, f16_inputs, &flr)?,
        Cmd::Demo { output, threads, full_strips } => {
            let d = data_dir()?;
            let mut frames = list_frames(std::slice::from_ref(&d))?;
            // plus every frame of each bundled sequence, in order (temporal
            // methods accumulate over it; flicker is measured on it)
            if let Ok(rd) = std::fs::read_dir(&d) {
                let mut seqs: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_dir()).collect();
                seqs.sort();
                for s in seqs {
                    if let Ok(f) = list_frames(&[s]) {
                        frames.extend(f);
                    }
                }
            }
            let t = threads_or_all(threads);
            let mean = write_report(&frames, &output, &[], 7, t, full_strips)?;
            let configs = mean.iter().filter(|r| r.method != "noisy").count();
            println!("lrd demo: {configs} configurations on {} frames (the bundled stills and sequence), {t} thread(s)", frames.len());
            print!("{}", report::summary(&mean));
            println!("{}", report_written(&output));
        }
    }
    Ok(())
}

/// A closed stdout (`lrd bench | head -1`) ends lrd as it ends other Unix
/// tools: by SIGPIPE, silently (status 141 in a shell). Rust starts programs
/// with SIGPIPE ignored, which turns such a write into an error that
/// `println!` panics on ("failed printing to stdout: Broken pipe"). Restoring
/// the default once covers every write to stdout and stderr, including the
/// progress bar's, where handling `BrokenPipe` would need every print changed
/// to a fallible write. Files lrd writes are complete before it prints about them.
#[cfg(unix)]
fn default_sigpipe() {
    // SAFETY: called first thing in main, before any other thread exists; SIG_DFL is a valid handler.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    #[cfg(unix)]
    default_sigpipe();
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        eprintln!("lrd: internal error: {msg} (at {})", info.location().map(|l| l.to_string()).unwrap_or_default());
    }));
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("lrd: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// `lrd --help` and every `lrd SUBCOMMAND --help` describe each argument.
    #[test]
    fn every_argument_has_help() {
        let cli = Cli::command();
        let mut missing = vec![];
        for sub in cli.get_subcommands() {
            if sub.get_about().is_none() {
                missing.push(sub.get_name().to_string());
            }
            for a in sub.get_arguments() {
                let builtin = matches!(a.get_id().as_str(), "help" | "version");
                if !builtin && a.get_help().is_none() && a.get_long_help().is_none() {
                    missing.push(format!("{} {}", sub.get_name(), a.get_id()));
                }
            }
        }
        assert!(missing.is_empty(), "without help text: {missing:?}");
    }
}
