//! `lrd`: denoise frames, evaluate and compare methods, report error against
//! run time, advise what a scene can drop, benchmark. See the README.

mod advise;
mod bench;
mod evaluate;
mod methods;
mod report;
mod runner;
mod shaders;

use lrdenoise_cli::inject::Injection;
use lrdenoise_cli::{exrio, metrics};

use clap::{Parser, Subcommand};
use evaluate::{evaluate, list_frames, means, EvalOptions, Record, Variant};
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
        /// Run the method's temporal pipeline (flr, bmfr and walr have one: on by default) or denoise each frame on its own
        #[arg(long, value_enum, default_value = "on")]
        temporal: OnOff,
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
        /// Outliers to inject into each frame's noisy layer first (docs/DATA.md's robustness protocol, fixed seed): clean, fireflies:P:K (probability P, K x the mean luminance) or nonfinite:P (P NaN and P +Inf); or "all": every case of the protocol in turn (clean, fireflies:1e-4:1000, fireflies:1e-3:100, nonfinite:1e-3), printed as the robustness table of `lrd report` (mean PSNR per case, drop from clean), with --json holding every case's records
        #[arg(long, value_parser = parse_inject, default_value = "clean", value_name = "CASE|all")]
        inject: InjectArg,
    },
    /// Evaluate every method and configuration; write DIR/report.md, plot.svg/png, image strips and the robustness table (outliers injected into the stills)
    Report {
        /// Frames with a `reference` layer, or directories of them (a directory of frame_NNNN.exr is a sequence)
        #[arg(required = true)]
        frames: Vec<PathBuf>,
        /// Directory to write report.md, plot.png, plot.svg, records.json, strip_FRAME.png, robustness.json and robustness/CASE/FRAME.exr (the stills with each case's outliers) to (created if missing)
        #[arg(short, long, value_name = "DIR")]
        output: PathBuf,
        /// JSON files of records produced elsewhere (same schema as `eval --json`), merged into tables and plot; records whose `inject` names an outlier case (tools/peers.py --inject-name) go to the robustness table only
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
        /// Methods to weigh, comma separated from flr,flnr,bmfr,walr: besides FLR's guides × block ×
        /// window grid, FLNR with the bundled network (frames with normal, depth and AO), BMFR at
        /// 32×32 and 64×64 blocks and WALR's stages (tracing, blend) with the frame's guides; the
        /// choice is then made over all of them, so FLNR is chosen only where it wins on the frame
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
        /// How the frame is handed over: separate buffers per layer, or the
        /// engine G-buffer layouts (RGBA light with AO in alpha, RGBA normal
        /// with depth in the fourth channel), f32 or RGBA16F
        #[arg(long, value_enum, default_value_t = runner::InputLayout::Planar)]
        layout: runner::InputLayout,
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

/// `lrd eval --inject`: one case, or every case of the robustness protocol.
#[derive(Clone, Copy, Debug)]
enum InjectArg {
    One(Injection),
    All,
}

fn parse_inject(s: &str) -> Result<InjectArg, String> {
    if s == "all" {
        Ok(InjectArg::All)
    } else {
        Injection::parse(s).map(InjectArg::One).map_err(|e| {
            let known = ["clean", "fireflies:", "nonfinite:"].iter().any(|k| s.starts_with(k));
            if known {
                e
            } else {
                format!("{e}, or all (every case in turn)")
            }
        })
    }
}

/// `--temporal on|off`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum OnOff {
    On,
    Off,
}

/// Flags shared by `denoise` and `denoise-seq`.
#[derive(clap::Args)]
struct RunArgs {
    /// The denoiser (on a sequence, flr, bmfr and walr run their temporal pipelines unless --temporal off)
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
        Cmd::DenoiseSeq { dir, output, temporal, run: RunArgs { method, flr, input_layer, threads } } => {
            let t = threads_or_all(threads);
            let frames = list_frames(std::slice::from_ref(&dir))?;
            std::fs::create_dir_all(&output).map_err(|e| format!("{}: {e}", output.display()))?;
            // On a sequence, flr, bmfr and walr mean their temporal pipelines unless --temporal off.
            let method = match (method, temporal) {
                (MethodName::Flr, OnOff::On) => MethodName::FlrTemporal,
                (MethodName::Bmfr, OnOff::On) => MethodName::BmfrTemporal,
                (MethodName::Walr, OnOff::On) => MethodName::WalrTemporal,
                (MethodName::FlrTemporal, OnOff::Off) => MethodName::Flr,
                (MethodName::BmfrTemporal, OnOff::Off) => MethodName::Bmfr,
                (MethodName::WalrTemporal, OnOff::Off) => MethodName::Walr,
                (m, _) => m,
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
        Cmd::Eval { frames, methods, flr, json, runs, threads, inject } => {
            let mut variants = vec![Variant::noisy("noisy")];
            for m in methods {
                variants.push(Variant::method(m.as_str(), flr.clone()));
            }
            let t = threads_or_all(threads);
            let frames = list_frames(&frames)?;
            let records = match inject {
                InjectArg::One(inject) => {
                    evaluate(&frames, &variants, &EvalOptions { runs: runs.max(5), threads: t, keep_images: false, inject })?.0
                }
                InjectArg::All => report::robustness::run_cases(&frames, &variants, runs.max(5), t)?,
            };
            if records.is_empty() {
                return Err("no frame with a 'reference' layer: nothing to evaluate".into());
            }
            match inject {
                InjectArg::One(_) => {
                    print_table(&records);
                    let seq = report::sequences::table(&records);
                    if !seq.is_empty() {
                        println!(
                            "\nSequences: mean PSNR of all frames and of the last 4, flicker of the last 4, frames to converge\n\n{seq}"
                        );
                    }
                }
                InjectArg::All => {
                    println!("Robustness (docs/DATA.md): mean PSNR dB per case; drop = clean minus the case\n");
                    print!("{}", report::robustness::table(&records));
                }
            }
            if let Some(j) = json {
                std::fs::write(&j, serde_json::to_string_pretty(&records).map_err(|e| e.to_string())?)
                    .map_err(|e| format!("{}: {e}", j.display()))?;
            }
        }
        Cmd::Report { frames, output, peers, runs, threads, full_strips } => {
            let mean = report::write_report(&list_frames(&frames)?, &output, &peers, runs, threads_or_all(threads), full_strips)?;
            println!("{}", report::table(&mean, false));
            println!("{}", report::report_written(&output));
        }
        Cmd::Advise { frame, max_loss_db, budget_ms, runs, threads, methods } => {
            advise::advise(&frame, max_loss_db, budget_ms, runs, threads_or_all(threads), &methods)?
        }
        Cmd::Bench { method, size, threads, runs, layout, flr, frame } => {
            bench::bench(method.as_str(), &size, threads, runs, layout, &flr, frame.as_deref())?
        }
        Cmd::Shaders { out, size, f16_inputs, flr } => shaders::shaders(&out, &size, f16_inputs, &flr)?,
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
            let mean = report::write_report(&frames, &output, &[], 7, t, full_strips)?;
            let configs = mean.iter().filter(|r| r.method != "noisy").count();
            println!("lrd demo: {configs} configurations on {} frames (the bundled stills and sequence), {t} thread(s)", frames.len());
            print!("{}", report::summary(&mean));
            println!("{}", report::report_written(&output));
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
