//! Evaluation: run variants (method + flags + input layer) on frames with a
//! reference, score them with the quality protocol, time them.

use crate::methods::{Built, FlrArgs, Method};
use crate::runner::Inputs;
use indicatif::{ProgressBar, ProgressStyle};
use lrdenoise_cli::exrio::ExrFrame;
use lrdenoise_cli::inject::Injection;
use lrdenoise_cli::metrics::{score, Scores};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One row of a table: a method with its flags on one input layer.
#[derive(Clone, Debug)]
pub struct Variant {
    /// "noisy" (the input itself) or one of `methods::METHODS`.
    pub method: String,
    pub args: FlrArgs,
    pub input_layer: String,
}

impl Variant {
    pub fn noisy(layer: &str) -> Self {
        Variant { method: "noisy".into(), args: FlrArgs::default(), input_layer: layer.into() }
    }
    pub fn flr(args: FlrArgs) -> Self {
        Self::method("flr", args)
    }
    pub fn method(name: &str, args: FlrArgs) -> Self {
        Variant { method: name.into(), args, input_layer: "noisy".into() }
    }
    pub fn on(mut self, layer: &str) -> Self {
        self.input_layer = layer.into();
        self
    }
    /// For the progress bar: the method and the flags it was given.
    pub fn describe(&self) -> String {
        let mut s = self.method.clone();
        let a = &self.args;
        let mut add = |flag: &str, v: Option<String>| {
            if let Some(v) = v {
                s += &format!(" --{flag} {v}");
            }
        };
        add("guides", a.guides.clone());
        add("block", a.block.map(|v| v.to_string()));
        add("sigma", a.sigma.clone());
        add("box", a.box_radius.map(|v| v.to_string()));
        add("regularization", a.regularization.clone());
        add("upsample", a.upsample.map(|v| v.to_string()));
        add("shrinkage", a.shrinkage.map(|v| v.to_string()));
        add("iterations", a.iterations.map(|v| v.to_string()));
        add("previous-weight", a.previous_weight.clone());
        add("storage", a.storage.clone());
        add("ao-demodulation", a.ao_demodulation.clone());
        add("fireflies", a.fireflies.clone());
        add("accumulate", a.accumulate.clone());
        add("lag-sigmas", a.lag_sigmas.map(|v| v.to_string()));
        if a.without_ao {
            s += " --without-ao";
        }
        if a.no_tracing {
            s += " --no-tracing";
        }
        if self.input_layer != "noisy" || self.method == "noisy" {
            s += &format!(" [{}]", self.input_layer);
        }
        s
    }
}

/// One (variant, frame) result; the JSON schema `lrd eval --json` writes and
/// `lrd report --peers` reads.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Record {
    pub method: String,
    pub config: String,
    pub frame: String,
    pub psnr: f64,
    pub ssim: f64,
    pub flip: f64,
    pub rmse: f64,
    /// Median denoise time in milliseconds (no I/O).
    pub ms: f64,
    #[serde(default)]
    pub threads: usize,
    #[serde(default)]
    pub width: usize,
    #[serde(default)]
    pub height: usize,
    /// Flags that reproduce this row with `lrd denoise`.
    #[serde(default)]
    pub flags: String,
    /// Sequences, frames after the first: temporal instability
    /// (`metrics::flicker`); `None` elsewhere.
    #[serde(default)]
    pub flicker: Option<f64>,
    /// Sequences whose frames carry a second, independent reference
    /// (`reference_b`, `tools/render.py --second-reference`): the flicker the
    /// reference's own noise puts into every method's figure, `flicker(B vs
    /// A) / √2` (`metrics::flicker`); `None` elsewhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_flicker: Option<f64>,
    /// The robustness case of the input (`inject::Injection::name`; "clean"
    /// or empty for the frame as rendered).
    #[serde(default)]
    pub inject: String,
    /// The sequence (its directory's name) the frame belongs to; `None` for a still.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<String>,
    /// The index in `evaluate`'s `variants` of the variant that made this
    /// row (`lrd advise` reads the configuration from it); not in the JSON.
    #[serde(skip)]
    pub variant: Option<usize>,
}

/// One configuration's images of one frame, kept for the image strips.
pub struct Panel {
    pub method: String,
    pub config: String,
    pub psnr: f64,
    pub flip: f64,
    /// Tone-mapped RGB.
    pub tm: Vec<f32>,
    /// FLIP error map.
    pub fmap: Vec<f32>,
}

/// Outputs kept for image strips.
pub struct FrameImages {
    pub frame: String,
    pub w: usize,
    pub h: usize,
    pub reference_tm: Vec<f32>,
    pub rows: Vec<Panel>,
}

/// Expands directories to the `.exr` files directly inside them, sorted.
pub fn list_frames(args: &[PathBuf]) -> Result<Vec<PathBuf>, String> {
    let mut out = vec![];
    for a in args {
        if a.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(a)
                .map_err(|e| format!("{}: {e}", a.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("exr")))
                .collect();
            v.sort();
            out.extend(v);
        } else if a.exists() {
            out.push(a.clone());
        } else {
            return Err(format!("{}: no such file or directory", a.display()));
        }
    }
    if out.is_empty() {
        return Err("no .exr frames found in the given paths".into());
    }
    Ok(out)
}

pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// A progress bar on stderr: `what`, the bar, steps done, elapsed time and
/// ETA, then the message (the frame and configuration at work). indicatif
/// draws nothing when stderr is not a terminal (a pipe, a file, CI logs).
pub fn progress(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} {elapsed_precise} ETA {eta}  {wide_msg}")
            .unwrap_or(ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_prefix(what.to_string());
    pb
}

/// Times `runs` calls after one warm-up; returns the median in ms. A temporal
/// method restarts every run from the same state (restoring is not timed), so
/// it ends one frame further, as if run once.
pub fn time_method(m: &mut Method, inputs: &Inputs, out: &mut [f32], runs: usize) -> Result<(f64, Vec<f64>), String> {
    m.save()?;
    m.run(inputs, out)?;
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs.max(1) {
        m.restore()?;
        let s = Instant::now();
        m.run(inputs, out)?;
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    let all = t.clone();
    Ok((median(&mut t), all))
}

pub struct EvalOptions {
    pub runs: usize,
    pub threads: usize,
    pub keep_images: bool,
    /// Outliers injected into every frame's noisy layer before it is denoised.
    pub inject: Injection,
}

fn frame_name(p: &Path) -> String {
    p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default()
}

/// Sequence key of a frame: its directory when named `frame_NNNN.exr` (the
/// layout of docs/DATA.md), else `None` (a lone frame).
fn sequence_of(p: &Path) -> Option<PathBuf> {
    let stem = p.file_stem()?.to_string_lossy().to_string();
    stem.strip_prefix("frame_").filter(|n| n.chars().all(|c| c.is_ascii_digit())).and_then(|_| p.parent().map(Path::to_path_buf))
}

/// What a variant carries from one frame of a sequence to the next.
struct Carry {
    seq: PathBuf,
    /// Temporal methods keep their runner (and history).
    built: Option<Built>,
    /// Tone-mapped output and reference of the previous frame (for flicker).
    prev: (Vec<f32>, Vec<f32>),
}

/// Runs every variant on every frame that has a reference. Frames of a
/// sequence directory (`frame_NNNN.exr`) are taken in order: temporal methods
/// carry their history from frame to frame, and every variant gets a flicker
/// figure from the second frame on.
pub fn evaluate(frames: &[PathBuf], variants: &[Variant], opt: &EvalOptions) -> Result<(Vec<Record>, Vec<FrameImages>), String> {
    let pb = progress((frames.len() * variants.len()) as u64, "evaluating");
    let mut records = vec![];
    let mut images = vec![];
    let mut carry: Vec<Option<Carry>> = variants.iter().map(|_| None).collect();
    // the previous frame's sequence and tone-mapped references A and B
    let mut prev_refs: Option<(PathBuf, Vec<f32>, Vec<f32>)> = None;
    for path in frames {
        let mut exr = ExrFrame::read(path)?;
        // a sequence's frames get different pixels: salted by their number
        let salt = frame_name(path).strip_prefix("frame_").and_then(|n| n.parse::<u64>().ok()).unwrap_or(0);
        opt.inject.apply(&mut exr, salt).map_err(|e| format!("{}: {e}", path.display()))?;
        if !exr.has("reference") {
            pb.suspend(|| eprintln!("{}: no 'reference' layer, skipped", path.display()));
            pb.inc(variants.len() as u64);
            continue;
        }
        let seq = sequence_of(path);
        let base = Inputs::from_exr(&exr, path, "noisy")?;
        let reference = base.reference.clone().unwrap_or_default();
        let albedo = base.albedo.clone().ok_or_else(|| format!("{}: missing layer 'albedo' (needed to score)", path.display()))?;
        let (w, h) = (base.w, base.h);
        let name = frame_name(path);
        let r_mod: Vec<f32> = reference.iter().zip(&albedo).map(|(a, b)| a * b).collect();
        let l = lrdenoise_cli::metrics::mean_luminance(&r_mod);
        let ref_tm = lrdenoise_cli::metrics::tonemap(&r_mod, l);
        // the reference's own flicker, from a second reference rendered with other samples
        let ref_b_tm = if exr.has("reference_b") {
            let b = exr.layer("reference_b", 3, path)?.interleaved(3);
            let b_mod: Vec<f32> = b.iter().zip(&albedo).map(|(a, b)| a * b).collect();
            Some(lrdenoise_cli::metrics::tonemap(&b_mod, l))
        } else {
            None
        };
        let reference_flicker = match (&seq, prev_refs.take(), &ref_b_tm, &base.motion) {
            (Some(s), Some((ps, pa, pb)), Some(b), Some(mv)) if &ps == s => {
                lrdenoise_cli::metrics::flicker(b, &pb, &ref_tm, &pa, mv, w, h).map(|f| f / std::f64::consts::SQRT_2)
            }
            _ => None,
        };
        if let (Some(s), Some(b)) = (&seq, &ref_b_tm) {
            prev_refs = Some((s.clone(), ref_tm.clone(), b.clone()));
        }
        let mut fi = FrameImages { frame: name.clone(), w, h, reference_tm: vec![], rows: vec![] };
        if opt.keep_images {
            fi.reference_tm = ref_tm.clone();
        }
        for (vi, v) in variants.iter().enumerate() {
            pb.set_message(format!("{name}: {}", v.describe()));
            if vi > 0 {
                pb.inc(1);
            }
            if !exr.has(&v.input_layer) {
                pb.suspend(|| eprintln!("{}: no '{}' layer, variant skipped", path.display(), v.input_layer));
                continue;
            }
            let inputs = if v.input_layer == "noisy" {
                base.clone()
            } else {
                Inputs { noisy: exr.layer(&v.input_layer, 3, path)?.interleaved(3), ..base.clone() }
            };
            // The previous frame of the same sequence, if this variant saw it.
            let prev = match (&seq, carry[vi].take()) {
                (Some(s), Some(c)) if &c.seq == s => Some(c),
                _ => None,
            };
            let mut prev = prev;
            let mut built = match prev.as_mut().and_then(|c| c.built.take()) {
                Some(b) => b, // a temporal method, one frame further into its sequence
                None => {
                    let mut b = match v.method.as_str() {
                        "noisy" => Built { method: Method::Noisy, label: v.input_layer.clone(), flags: String::new(), min_bytes: None },
                        name => match Method::build(name, &v.args, &inputs, opt.threads) {
                            Ok(b) => b,
                            Err(e) => {
                                pb.suspend(|| eprintln!("{}: {e}; variant skipped", path.display()));
                                continue;
                            }
                        },
                    };
                    if v.input_layer != "noisy" && v.method != "noisy" {
                        b.label += &format!(" [{}]", v.input_layer);
                        b.flags += &format!(" --input-layer {}", v.input_layer);
                    }
                    b
                }
            };
            let mut out = vec![0f32; w * h * 3];
            let (ms, _) = if v.method == "noisy" {
                built.method.run(&inputs, &mut out).map(|_| (0.0, vec![]))?
            } else {
                time_method(&mut built.method, &inputs, &mut out, opt.runs)?
            };
            let (s, fmap): (Scores, Vec<f32>) = score(&out, &reference, &albedo, w, h);
            let i_mod: Vec<f32> = out.iter().zip(&albedo).map(|(a, b)| a * b).collect();
            let out_tm = lrdenoise_cli::metrics::tonemap(&i_mod, l);
            let flicker = match (&prev, &inputs.motion) {
                (Some(c), Some(mv)) => lrdenoise_cli::metrics::flicker(&out_tm, &c.prev.0, &ref_tm, &c.prev.1, mv, w, h),
                _ => None,
            };
            if opt.keep_images {
                let (method, config) = (v.method.clone(), built.label.clone());
                fi.rows.push(Panel { method, config, psnr: s.psnr, flip: s.flip, tm: out_tm.clone(), fmap });
            }
            records.push(Record {
                method: v.method.clone(),
                config: built.label.clone(),
                frame: name.clone(),
                psnr: s.psnr,
                ssim: s.ssim,
                flip: s.flip,
                rmse: s.rmse,
                ms,
                threads: if v.method == "noisy" { 0 } else { opt.threads },
                width: w,
                height: h,
                flags: built.flags.clone(),
                flicker,
                reference_flicker,
                inject: opt.inject.name(),
                sequence: seq.as_ref().and_then(|s| s.file_name()).map(|s| s.to_string_lossy().to_string()),
                variant: Some(vi),
            });
            if let Some(sq) = &seq {
                let temporal = built.method.is_temporal();
                carry[vi] = Some(Carry { seq: sq.clone(), built: temporal.then_some(built), prev: (out_tm, ref_tm.clone()) });
            }
        }
        pb.inc(1);
        if opt.keep_images {
            images.push(fi);
        }
    }
    pb.finish_and_clear();
    Ok((records, images))
}

/// Mean over frames per config, in first-seen order.
pub fn means(records: &[Record]) -> Vec<Record> {
    let mut order: Vec<String> = vec![];
    for r in records {
        if !order.contains(&r.config) {
            order.push(r.config.clone());
        }
    }
    order
        .iter()
        .map(|c| {
            let rs: Vec<&Record> = records.iter().filter(|r| &r.config == c).collect();
            let n = rs.len() as f64;
            let avg = |f: &dyn Fn(&Record) -> f64| rs.iter().map(|r| f(r)).sum::<f64>() / n;
            Record {
                method: rs[0].method.clone(),
                config: c.clone(),
                frame: format!("mean of {}", rs.len()),
                psnr: avg(&|r| r.psnr),
                ssim: avg(&|r| r.ssim),
                flip: avg(&|r| r.flip),
                rmse: avg(&|r| r.rmse),
                ms: avg(&|r| r.ms),
                threads: rs[0].threads,
                width: rs[0].width,
                height: rs[0].height,
                flags: rs[0].flags.clone(),
                flicker: {
                    let f: Vec<f64> = rs.iter().filter_map(|r| r.flicker).collect();
                    (!f.is_empty()).then(|| f.iter().sum::<f64>() / f.len() as f64)
                },
                reference_flicker: None,
                inject: rs[0].inject.clone(),
                sequence: None,
                variant: rs[0].variant,
            }
        })
        .collect()
}
