//! Methods and their flags. The FLR flags:
//! `--guides normal,depth,ao` (default: those of normal, depth, ao present),
//! `--block B`, `--sigma S`, `--radius R` (full-resolution pixels; default 3σ),
//! or `--sigma S0,S1,S2` (the adaptive window: three sizes blended per cell),
//! `--regularization normalized:EPS_MUL,EPS_ADD | tikhonov:EPS`, `--upsample 2|4`.
//! The default window is the adaptive one (σ 6/12/20): it meets the quality
//! the issue asks of the defaults more nearly, for ~40 % more time; one
//! `--sigma` value (or `--radius` alone, σ = 12) is the single, faster window.
//!
//! BMFR (`--method bmfr`, single frame; `bmfr-temporal`, the pipeline over a
//! sequence) reads `--guides` (default: normal and position, or normal and
//! depth without positions) and `--block` (default 32); the other flags are
//! FLR's and are refused with it.
//!
//! WALR (`--method walr`, single frame; `walr-temporal`, its pipeline) reads
//! `--guides` (normal and position required; depth makes distances relative;
//! ao becomes an extra feature), `--iterations`, `--near`, `--far`,
//! `--no-tracing` and `--storage f16|f32`; those flags are refused elsewhere.

use crate::runner::{BmfrRunner, FlnrRunner, FlrRunner, Inputs, TemporalRunner, WalrRunner};
use clap::Args;
use lrdenoise::walr::Storage;
use lrdenoise::{Blur, BmfrConfig, FlrConfig, GuideSet, Regularization, WalrConfig};

#[derive(Args, Clone, Debug, Default)]
pub struct FlrArgs {
    /// Guides to use, comma separated from normal,depth,position,ao (default: normal,depth,ao present in the frame); "none" for none
    #[arg(long)]
    pub guides: Option<String>,
    /// Block size B: one affine model per BxB pixels (1, 2, 4, 8, 16)
    #[arg(long)]
    pub block: Option<usize>,
    /// Gaussian window sigma in full-resolution pixels: one value fits one window (fastest; e.g. 12); three increasing values fit all three and blend them per cell (the adaptive window; default 6,12,20, flr-temporal 3,6,12)
    #[arg(long)]
    pub sigma: Option<String>,
    /// Window truncation radius in full-resolution pixels (default 3*sigma); with no --sigma, a single sigma = 12 window
    #[arg(long)]
    pub radius: Option<f32>,
    /// Use a box window of this radius instead of the Gaussian (the guided filter's window)
    #[arg(long = "box")]
    pub box_radius: Option<f32>,
    /// normalized:EPS_MUL,EPS_ADD (default) or tikhonov:EPS
    #[arg(long)]
    pub regularization: Option<String>,
    /// Joint denoise + upsample: trace at 1/2 or 1/4 resolution (emulated by taking every 2nd/4th pixel of the noisy layer)
    #[arg(long)]
    pub upsample: Option<usize>,
    /// Adaptive window with AO: also fit the smallest window without AO and let each cell's blend weigh that fit too (off by default)
    #[arg(long)]
    pub without_ao: bool,
    /// With AO among the guides: divide the noisy light by sqrt(ao + C) before the fit and multiply the output back (AO demodulation; default C = 0.1), or "off" for plain FLR
    #[arg(long, value_name = "C|off")]
    pub ao_demodulation: Option<String>,
    /// WALR: à-trous iterations (1..=5; 4 = an 81x81 window)
    #[arg(long)]
    pub iterations: Option<u8>,
    /// WALR: plane distance (relative to camera distance) below which a tap has full weight
    #[arg(long)]
    pub near: Option<f32>,
    /// WALR: plane distance at which a tap's weight reaches 0
    #[arg(long)]
    pub far: Option<f32>,
    /// WALR: evaluate the edge-stopping function at the tap only (no edge tracing)
    #[arg(long)]
    pub no_tracing: bool,
    /// WALR: storage of the averages, f16 or f32
    #[arg(long)]
    pub storage: Option<String>,
    /// WALR: fraction of the previous iteration's edge distance that tracing may skip (0..=1; 0 visits every pixel)
    #[arg(long)]
    pub sdf_step: Option<f32>,
    /// WALR: pivot floor of the per-pixel Cholesky
    #[arg(long)]
    pub epsilon: Option<f32>,
    /// WALR: weight w of the previous iteration's fit (a window a third as wide) in the output, (1 - w) fit_T + w fit_T-1 (0..=1; 0 = one window), or "adaptive": w per pixel from the two fits' estimated errors, averaged over the small window
    #[arg(long)]
    pub previous_weight: Option<String>,
    /// BMFR: kappa of the Wiener shrinkage of each block's fit in its QR basis (0..=100; default 4; 0 = the paper's plain least squares)
    #[arg(long)]
    pub shrinkage: Option<f32>,
    /// FLNR: a weight blob from train/flnr.py (default: the bundled train/flnr.bin)
    #[arg(long)]
    pub weights: Option<std::path::PathBuf>,
    /// Every method: firefly clamp factor K: a noisy sample brighter than K times the larger of the third brightest 8x8 cell of its 104x8 neighbourhood and that neighbourhood's mean (without its brightest cell) is scaled down to that level (default 1.5), or "off"
    #[arg(long, value_name = "K|off")]
    pub fireflies: Option<String>,
    /// flr, flr-temporal: run on the CPU (default) or on the GPU (wgpu's default adapter; compute shaders, f32)
    #[arg(long)]
    pub device: Option<String>,
    /// Temporal pipelines (flr-temporal, bmfr-temporal, walr-temporal): longest per-pixel history in frames (default 16; shorter follows light that changes, e.g. around moving objects)
    #[arg(long, value_name = "FRAMES")]
    pub history: Option<f32>,
    /// flr-temporal: lowest blend weight of the new output frame in the output accumulation (default 0.5; 1 = off: ~20 % faster, the output less smooth in time)
    #[arg(long, value_name = "A")]
    pub output_alpha: Option<f32>,
    /// flr-temporal: half-width of the output history's clip box in standard deviations of the 3x3 neighbourhood (default 1.5)
    #[arg(long, value_name = "G")]
    pub clip_gamma: Option<f32>,
    /// Temporal pipelines (flr-temporal, bmfr-temporal, walr-temporal): the firefly clamp's reference is at most F times the brightest sample the previous frame kept around each cell (default 2; 0 = off)
    #[arg(long, value_name = "F")]
    pub firefly_history: Option<f32>,
    /// flr-temporal: the fit weighs each pixel by its history length, the samples its accumulated light averages (default off)
    #[arg(long)]
    pub history_weights: bool,
    /// flr-temporal: what the history accumulates: "light" (default: the noisy light per pixel, then FLR on it) or "moments" (FLR's cell moments: 1.1-1.5x FLR's time at 1080p against light's 2.5-3x, about three quarters of light's gain over per-frame FLR; of the temporal flags it reads --history and --lag-sigmas only; CPU only)
    #[arg(long, value_name = "light|moments")]
    pub accumulate: Option<String>,
    /// flr-temporal --accumulate moments: the lag test's threshold in standard errors; a cell whose newest 2 frames' mean luminance differs from its history's by more restarts, so that light that changes (a moving object's shadow) does not lag (default 3; 0 = off)
    #[arg(long, value_name = "K")]
    pub lag_sigmas: Option<f32>,
}

impl FlrArgs {
    /// `--device`: false for cpu (default), true for gpu.
    pub fn gpu(&self) -> Result<bool, String> {
        match self.device.as_deref() {
            None | Some("cpu") => Ok(false),
            Some("gpu") => Ok(true),
            Some(d) => Err(format!("--device: '{d}' is not cpu or gpu")),
        }
    }
    /// Each method flag, whether it was given, and the methods that read it:
    /// the one list the checks and their messages come from. (The flags are
    /// one clap group shared by every method rather than a subcommand per
    /// method because `eval`, `report` and `bench` take one flag set for
    /// several methods at once, `--methods flr,bmfr`; this table gives clap's
    /// refusal instead, naming whose flag it is and what the method takes.)
    fn flags(&self) -> [(&'static str, bool, &'static [Family]); 28] {
        use Family::*;
        [
            ("--guides", self.guides.is_some(), &[Flr, Bmfr, Walr]),
            ("--block", self.block.is_some(), &[Flr, Bmfr]),
            ("--sigma", self.sigma.is_some(), &[Flr]),
            ("--radius", self.radius.is_some(), &[Flr]),
            ("--box", self.box_radius.is_some(), &[Flr]),
            ("--regularization", self.regularization.is_some(), &[Flr]),
            ("--upsample", self.upsample.is_some(), &[Flr]),
            ("--without-ao", self.without_ao, &[Flr]),
            ("--ao-demodulation", self.ao_demodulation.is_some(), &[Flr]),
            // (only flr and flr-temporal run on the GPU: Method::build says so for the others)
            ("--device", self.device.is_some(), &[Flr, Bmfr, Walr, Flnr]),
            ("--shrinkage", self.shrinkage.is_some(), &[Bmfr]),
            ("--iterations", self.iterations.is_some(), &[Walr]),
            ("--near", self.near.is_some(), &[Walr]),
            ("--far", self.far.is_some(), &[Walr]),
            ("--no-tracing", self.no_tracing, &[Walr]),
            ("--storage", self.storage.is_some(), &[Walr]),
            ("--sdf-step", self.sdf_step.is_some(), &[Walr]),
            ("--epsilon", self.epsilon.is_some(), &[Walr]),
            ("--previous-weight", self.previous_weight.is_some(), &[Walr]),
            ("--weights", self.weights.is_some(), &[Flnr]),
            ("--fireflies", self.fireflies.is_some(), &[Flr, Bmfr, Walr, Flnr]),
            ("--history", self.history.is_some(), &[Flr, Bmfr, Walr]),
            ("--output-alpha", self.output_alpha.is_some(), &[Flr]),
            ("--clip-gamma", self.clip_gamma.is_some(), &[Flr]),
            ("--firefly-history", self.firefly_history.is_some(), &[Flr, Bmfr, Walr]),
            ("--history-weights", self.history_weights, &[Flr]),
            ("--accumulate", self.accumulate.is_some(), &[Flr]),
            ("--lag-sigmas", self.lag_sigmas.is_some(), &[Flr]),
        ]
    }

    /// The temporal stage's settings (`--history`, `--output-alpha`; the rest default).
    pub fn temporal_config(&self) -> Result<lrdenoise::temporal::TemporalConfig, String> {
        let mut t = lrdenoise::temporal::TemporalConfig::default();
        if let Some(n) = self.history {
            t.max_history = n;
        }
        if let Some(a) = self.output_alpha {
            t.output_alpha = a;
        }
        if let Some(g) = self.clip_gamma {
            t.clip_gamma = g;
        }
        if let Some(f) = self.firefly_history {
            t.firefly_history = f;
        }
        if let Some(k) = self.lag_sigmas {
            t.lag_sigmas = k;
        }
        t.validate().map_err(|e| format!("--history / --output-alpha / --clip-gamma / --firefly-history / --lag-sigmas: {e}"))?;
        Ok(t)
    }

    /// Refuses the flags `family` does not read, naming whose they are and what `family` takes.
    fn only_for(&self, family: Family) -> Result<(), String> {
        let flags = self.flags();
        let foreign: Vec<_> = flags.iter().filter(|(_, given, owners)| *given && !owners.contains(&family)).collect();
        let Some((flag, _, owners)) = foreign.first() else { return Ok(()) };
        let whose: Vec<&str> = owners.iter().map(|o| o.upper()).collect();
        let article = if whose[0].starts_with('F') { "an" } else { "a" };
        let also: Vec<&str> = foreign[1..].iter().map(|(f, _, _)| *f).collect();
        let also = match also.len() {
            0 => String::new(),
            1 => format!(" (so is {})", also[0]),
            _ => format!(" (so are {})", also.join(", ")),
        };
        // (--device cpu is accepted everywhere; only flr and flr-temporal take --device gpu)
        let takes: Vec<&str> = flags
            .iter()
            .filter(|(f, _, o)| o.contains(&family) && (*f != "--device" || family == Family::Flr))
            .map(|(f, _, _)| *f)
            .collect();
        let takes = takes.join(", ");
        Err(format!(
            "{flag} is {article} {} flag, not one of {}'s{also}; {} takes {takes}",
            whose.join(" and "),
            family.upper(),
            family.lower()
        ))
    }
}

/// The methods as their flags see them (a temporal pipeline reads its single-frame method's flags).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Family {
    Flr,
    Bmfr,
    Walr,
    Flnr,
}

impl Family {
    fn upper(self) -> &'static str {
        match self {
            Family::Flr => "FLR",
            Family::Bmfr => "BMFR",
            Family::Walr => "WALR",
            Family::Flnr => "FLNR",
        }
    }
    fn lower(self) -> &'static str {
        match self {
            Family::Flr => "flr",
            Family::Bmfr => "bmfr",
            Family::Walr => "walr",
            Family::Flnr => "flnr",
        }
    }
}

/// `--ao-demodulation`: "off" (plain FLR) or the offset C of sqrt(ao + C).
pub fn parse_ao_demodulation(s: &str) -> Result<Option<f32>, String> {
    match s {
        "off" | "none" => Ok(None),
        v => match v.parse::<f32>() {
            Ok(c) if c.is_finite() && c > 0.0 => Ok(Some(c)),
            _ => Err(format!("--ao-demodulation: '{v}' is not 'off' or a number > 0")),
        },
    }
}

/// `--fireflies`: "off" or the clamp strength K (≥ 1).
pub fn parse_fireflies(s: &str) -> Result<Option<f32>, String> {
    match s {
        "off" | "none" => Ok(None),
        v => match v.parse::<f32>() {
            Ok(k) if lrdenoise::fireflies::valid_strength(k) => Ok(Some(k)),
            _ => Err(format!("--fireflies: '{v}' is not 'off' or a number >= 1")),
        },
    }
}

/// User guide channels that `--guides albedo` adds (the albedo's R, G, B).
pub const ALBEDO_CHANNELS: u8 = 3;

pub fn parse_guides(s: &str) -> Result<GuideSet, String> {
    let mut g = GuideSet::NONE;
    if s.trim() == "none" {
        return Ok(g);
    }
    for p in s.split(',').map(str::trim) {
        match p {
            "normal" => g.normal = true,
            "depth" => g.depth = true,
            "position" => g.position = true,
            "ao" => g.ao = true,
            // The albedo's three channels go in as user guides (opt-in: see the README).
            "albedo" => g.user = ALBEDO_CHANNELS,
            _ => return Err(format!("--guides: unknown guide '{p}' (use normal, depth, position, ao, albedo or none)")),
        }
    }
    Ok(g)
}

pub fn guides_string(g: &GuideSet) -> String {
    let mut v = vec![];
    if g.normal {
        v.push("normal");
    }
    if g.depth {
        v.push("depth");
    }
    if g.position {
        v.push("position");
    }
    if g.ao {
        v.push("ao");
    }
    if g.user == ALBEDO_CHANNELS {
        v.push("albedo");
    }
    if v.is_empty() {
        "none".into()
    } else {
        v.join(",")
    }
}

pub fn parse_regularization(s: &str) -> Result<Regularization, String> {
    let bad = || format!("--regularization: '{s}' is not normalized:EPS_MUL,EPS_ADD or tikhonov:EPS");
    let (kind, vals) = s.split_once(':').ok_or_else(bad)?;
    let nums: Vec<f64> = vals.split(',').map(|v| v.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad())?;
    match (kind, nums.as_slice()) {
        ("normalized", [a, b]) => Ok(Regularization::Normalized { eps_mul: *a, eps_add: *b }),
        ("tikhonov", [e]) => Ok(Regularization::Tikhonov { eps: *e }),
        _ => Err(bad()),
    }
}

impl FlrArgs {
    /// `--accumulate`: false for light (default), true for moments; refuses
    /// the temporal flags the moments do not read.
    pub fn accumulate_moments(&self) -> Result<bool, String> {
        match self.accumulate.as_deref() {
            None | Some("light") if self.lag_sigmas.is_some() => {
                Err("--lag-sigmas is the moments' lag test: it needs flr-temporal --accumulate moments".into())
            }
            None | Some("light") => Ok(false),
            Some("moments") => {
                let unread = [
                    ("--output-alpha", self.output_alpha.is_some()),
                    ("--clip-gamma", self.clip_gamma.is_some()),
                    ("--firefly-history", self.firefly_history.is_some()),
                    ("--history-weights", self.history_weights),
                    ("--device", self.device.as_deref() == Some("gpu")),
                ];
                match unread.iter().find(|(_, given)| *given) {
                    Some((flag, _)) => {
                        Err(format!("flr-temporal --accumulate moments does not take {flag} (it accumulates no light; CPU only)"))
                    }
                    None => Ok(true),
                }
            }
            Some(a) => Err(format!("--accumulate: '{a}' is not light or moments")),
        }
    }

    /// `cfg` with temporal FLR's window ([`FlrConfig::temporal`]) unless a
    /// window flag (`--sigma`, `--radius`, `--box`) chose one.
    pub fn temporal_window(&self, mut cfg: FlrConfig) -> FlrConfig {
        if self.sigma.is_none() && self.radius.is_none() && self.box_radius.is_none() {
            cfg.blur = FlrConfig::temporal().blur;
        }
        cfg
    }

    pub fn config(&self, inputs: &Inputs) -> Result<FlrConfig, String> {
        let guides = match &self.guides {
            Some(s) => parse_guides(s)?,
            None => inputs.default_guides(),
        };
        if let Some(m) = inputs.missing(&guides) {
            return Err(format!("--guides asks for '{m}' but the frame has no '{m}' layer"));
        }
        self.only_for(Family::Flr)?;
        let mut c = FlrConfig::with_guides(guides);
        if let Some(b) = self.block {
            c.block = b;
        }
        c.blur = match (self.box_radius, &self.sigma) {
            (Some(r), None) => Blur::Box { radius: r },
            (Some(_), Some(_)) => return Err("--box and --sigma are two different windows: give one".into()),
            (None, None) if self.radius.is_none() => c.blur,
            (None, None) => Blur::Gaussian { sigma: lrdenoise::flr::config::DEFAULT_SIGMA, radius: self.radius },
            (None, Some(s)) => match parse_sigmas(s)? {
                Blur::Gaussian { sigma, .. } => Blur::Gaussian { sigma, radius: self.radius },
                _ if self.radius.is_some() => {
                    return Err("--radius applies to a single --sigma (each adaptive window is truncated at 3 sigma)".into())
                }
                adaptive => adaptive,
            },
        };
        if let Some(r) = &self.regularization {
            c.regularization = parse_regularization(r)?;
        }
        if let Some(u) = self.upsample {
            c.upsample = u;
        }
        c.adaptive_without_ao = self.without_ao; // validate() says when it cannot apply
        if let Some(d) = &self.ao_demodulation {
            c.ao_demodulation = parse_ao_demodulation(d)?;
        }
        if let Some(f) = &self.fireflies {
            c.fireflies = parse_fireflies(f)?;
        }
        c.validate().map_err(|e| format!("flr flags: {e}"))?;
        Ok(c)
    }
}

/// BMFR's configuration from the shared flags.
pub fn bmfr_config(a: &FlrArgs, inputs: &Inputs) -> Result<BmfrConfig, String> {
    a.only_for(Family::Bmfr)?;
    let guides = match &a.guides {
        Some(s) => parse_guides(s)?,
        None => GuideSet {
            normal: inputs.normal.is_some(),
            position: inputs.position.is_some(),
            depth: inputs.position.is_none() && inputs.depth.is_some(),
            ..GuideSet::NONE
        },
    };
    if let Some(m) = inputs.missing(&guides) {
        return Err(format!("--guides asks for '{m}' but the frame has no '{m}' layer"));
    }
    let mut c = BmfrConfig { block: a.block.unwrap_or(32), ..BmfrConfig::with_guides(guides) };
    if let Some(k) = a.shrinkage {
        c.shrinkage = k;
    }
    if let Some(f) = &a.fireflies {
        c.fireflies = parse_fireflies(f)?;
    }
    if let Some(f) = a.firefly_history {
        c.temporal.firefly_history = f;
    }
    if let Some(n) = a.history {
        c.temporal.max_history = n;
    }
    c.validate().map_err(|e| format!("bmfr flags: {e}"))?;
    Ok(c)
}

/// WALR's configuration from the shared flags.
pub fn walr_config(a: &FlrArgs, inputs: &Inputs) -> Result<WalrConfig, String> {
    a.only_for(Family::Walr)?;
    let guides = match &a.guides {
        Some(s) => parse_guides(s)?,
        None => GuideSet { normal: true, position: true, depth: inputs.depth.is_some(), ..GuideSet::NONE },
    };
    if !guides.normal || !guides.position {
        return Err("walr needs the normal and position guides (--guides normal,position[,depth][,ao])".into());
    }
    if let Some(m) = inputs.missing(&guides) {
        return Err(format!("walr needs '{m}' but the frame has no '{m}' layer"));
    }
    let mut c = WalrConfig::with_guides(guides);
    if let Some(t) = a.iterations {
        c.iterations = t;
    }
    if let Some(v) = a.near {
        c.near = v;
    }
    if let Some(v) = a.far {
        c.far = v;
    }
    c.tracing = !a.no_tracing;
    if let Some(v) = a.sdf_step {
        c.sdf_step = v;
    }
    if let Some(v) = a.epsilon {
        c.epsilon = v;
    }
    match a.previous_weight.as_deref() {
        None => {}
        Some("adaptive") => c.adaptive_blend = true,
        Some(v) => {
            c.previous_weight = v.parse().map_err(|_| format!("--previous-weight: '{v}' is not a number in 0..=1 or 'adaptive'"))?;
            c.adaptive_blend = false;
        }
    }
    if let Some(s) = &a.storage {
        c.storage = match s.as_str() {
            "f16" => Storage::F16,
            "f32" => Storage::F32,
            _ => return Err(format!("--storage: '{s}' is not f16 or f32")),
        };
    }
    if let Some(f) = &a.fireflies {
        c.fireflies = parse_fireflies(f)?;
    }
    if let Some(f) = a.firefly_history {
        c.temporal.firefly_history = f;
    }
    if let Some(n) = a.history {
        c.temporal.max_history = n;
    }
    c.validate().map_err(|e| format!("walr flags: {e}"))?;
    Ok(c)
}

fn walr_flags(name: &str, c: &WalrConfig) -> (String, String) {
    let st = match c.storage {
        Storage::F16 => "f16",
        Storage::F32 => "f32",
    };
    let tr = if c.tracing { "" } else { " --no-tracing" };
    let pw = match (c.iterations > 1, c.adaptive_blend) {
        (true, true) => " pw-adaptive".to_string(),
        (true, false) if c.previous_weight > 0.0 => format!(" pw{}", c.previous_weight),
        _ => String::new(),
    };
    let pw_flag = if c.adaptive_blend { "adaptive".to_string() } else { c.previous_weight.to_string() };
    let default = WalrConfig::default().fireflies;
    let ff = fireflies_label(c.fireflies, default);
    let label = format!("{name} {} t{}{pw} {st}{}{ff}", short_guides(&c.guides), c.iterations, if c.tracing { "" } else { " notrace" });
    let mut flags = format!(
        "--method {name} --guides {} --iterations {} --near {} --far {} --sdf-step {} --epsilon {:e} --previous-weight {} --storage {st}{tr}",
        guides_string(&c.guides),
        c.iterations,
        c.near,
        c.far,
        c.sdf_step,
        c.epsilon,
        pw_flag
    );
    if c.fireflies != default {
        flags += &fireflies_flag(c.fireflies);
    }
    if name == "walr-temporal" {
        return pipeline_label(label, flags, &c.temporal);
    }
    (label, flags)
}

/// BMFR's or WALR's temporal pipeline's label and flag line with a
/// non-default `--history` and `--firefly-history`.
fn pipeline_label(mut label: String, mut flags: String, t: &lrdenoise::temporal::TemporalConfig) -> (String, String) {
    if t.max_history != lrdenoise::temporal::TemporalConfig::default().max_history {
        label += &format!(" h{}", t.max_history);
        flags += &format!(" --history {}", t.max_history);
    }
    firefly_history_label(label, flags, t.firefly_history)
}

/// A temporal pipeline's label and flag line with a non-default `--firefly-history`.
fn firefly_history_label(mut label: String, mut flags: String, f: f32) -> (String, String) {
    if f != lrdenoise::temporal::TemporalConfig::default().firefly_history {
        label += &format!(" fh{f}");
        flags += &format!(" --firefly-history {f}");
    }
    (label, flags)
}

fn short_guides(g: &GuideSet) -> String {
    guides_string(g)
        .split(',')
        .map(|p| match p {
            "none" => "-".to_string(),
            "albedo" => "Alb".to_string(), // "A" is AO
            _ => p[..1].to_uppercase(),
        })
        .collect()
}

/// `--sigma`: one number (a Gaussian window) or three increasing ones (the adaptive window).
pub fn parse_sigmas(s: &str) -> Result<Blur, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>().map_err(|_| format!("--sigma {s}: '{x}' is not a number")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [sigma] => Ok(Blur::Gaussian { sigma, radius: None }),
        [a, b, c] => Ok(Blur::Adaptive { sigmas: [a, b, c] }),
        _ => Err(format!("--sigma {s}: give one sigma, or three increasing ones for the adaptive window (e.g. 6,12,20)")),
    }
}

/// A flag line that reproduces `c` on the command line.
pub fn flag_line(c: &FlrConfig) -> String {
    let mut s = format!("--method flr --guides {} --block {}", guides_string(&c.guides), c.block);
    match c.blur {
        Blur::Gaussian { sigma, radius } => {
            s += &format!(" --sigma {sigma}");
            if let Some(r) = radius {
                s += &format!(" --radius {r}");
            }
        }
        Blur::Box { radius } => s += &format!(" --box {radius}"),
        Blur::Adaptive { sigmas: [a, b, c] } => s += &format!(" --sigma {a},{b},{c}"),
    }
    match c.regularization {
        Regularization::Normalized { eps_mul, eps_add } => s += &format!(" --regularization normalized:{eps_mul:e},{eps_add:e}"),
        Regularization::Tikhonov { eps } => s += &format!(" --regularization tikhonov:{eps:e}"),
    }
    if c.upsample > 1 {
        s += &format!(" --upsample {}", c.upsample);
    }
    if c.adaptive_without_ao {
        s += " --without-ao";
    }
    if c.guides.ao && c.ao_demodulation != FlrConfig::default().ao_demodulation {
        match c.ao_demodulation {
            Some(v) => s += &format!(" --ao-demodulation {v}"),
            None => s += " --ao-demodulation off",
        }
    }
    if c.fireflies != FlrConfig::default().fireflies {
        s += &fireflies_flag(c.fireflies);
    }
    s
}

/// ` --fireflies K|off`.
pub fn fireflies_flag(k: Option<f32>) -> String {
    match k {
        Some(k) => format!(" --fireflies {k}"),
        None => " --fireflies off".into(),
    }
}

/// A label's suffix for a firefly clamp other than the default: ` ff K` or ` -ff`.
pub fn fireflies_label(k: Option<f32>, default: Option<f32>) -> String {
    match k {
        _ if k == default => String::new(),
        Some(k) => format!(" ff{k}"),
        None => " -ff".into(),
    }
}

/// A short label for tables and plots.
pub fn label(c: &FlrConfig) -> String {
    let g = short_guides(&c.guides);
    let blur = match c.blur {
        Blur::Gaussian { sigma, .. } => format!("s{sigma}"),
        Blur::Box { radius } => format!("box{radius}"),
        Blur::Adaptive { sigmas: [a, b, c] } => format!("s{a}/{b}/{c}"),
    };
    let reg = match c.regularization {
        Regularization::Tikhonov { .. } => " tik",
        _ => "",
    };
    let up = if c.upsample > 1 { format!(" up{}", c.upsample) } else { String::new() };
    let ao = if c.adaptive_without_ao { " -ao" } else { "" };
    let demod = match c.ao_demodulation {
        _ if !c.guides.ao => String::new(),
        None => " -aod".into(),
        v if v == FlrConfig::default().ao_demodulation => String::new(),
        Some(v) => format!(" aod{v}"),
    };
    let ff = fireflies_label(c.fireflies, FlrConfig::default().fireflies);
    format!("flr {g} b{} {blur}{ao}{demod}{reg}{up}{ff}", c.block)
}

/// A runnable method on one frame size.
pub enum Method {
    /// The noisy input itself (the baseline row).
    Noisy,
    Flr {
        runner: Box<FlrRunner>,
        low: Option<Box<Inputs>>,
    },
    /// Single-frame BMFR (frame index 0: no grid shift between runs).
    Bmfr(Box<BmfrRunner>),
    /// FLNR with its weights.
    Flnr(Box<FlnrRunner>),
    /// Single-frame WALR (frame index 0).
    Walr(Box<WalrRunner>),
    /// A temporal pipeline (BMFR's or WALR's): every `run` is the next frame of a sequence.
    Temporal(Box<TemporalRunner>),
    /// FLR's compute shaders on the GPU (`--device gpu`).
    FlrGpu {
        gpu: Box<lrdenoise_gpu::GpuFlr>,
        low: Option<Box<Inputs>>,
    },
    /// Temporal FLR on the GPU (`flr-temporal --device gpu`): every `run` is
    /// the next frame of a sequence; `saved`, the history [`Method::save`] kept.
    FlrTemporalGpu {
        gpu: Box<lrdenoise_gpu::GpuTemporalFlr>,
        saved: Option<(Vec<f32>, u32)>,
    },
}

/// A method built for one frame: the runner, its table label and the flags
/// that reproduce it.
pub struct Built {
    pub method: Method,
    pub label: String,
    pub flags: String,
    /// Bytes one call must at least move: every f32 input layer it reads,
    /// once, and the f32 RGB output, once; the temporal pipelines also read
    /// the motion and one history slot and write the other (`lrd bench`'s
    /// memory-copy baseline). `None` for the GPU path (upload and readback).
    pub min_bytes: Option<usize>,
}

/// The guides temporal FLR judges history taps by: FLR's, and world
/// positions where the frames have them (they judge a tap by where it is,
/// whatever the camera did); " rp" is added to `label` when positions are
/// not among FLR's own.
fn rejection_guides(cfg: &FlrConfig, inputs: &Inputs, label: &mut String) -> GuideSet {
    let mut reject = cfg.guides;
    reject.position |= inputs.missing(&GuideSet { position: true, ..GuideSet::NONE }).is_none();
    if reject.position && !cfg.guides.position {
        *label += " rp";
    }
    reject
}

/// Table label and flags of temporal FLR with `cfg` and `temporal`.
fn temporal_label(cfg: &FlrConfig, temporal: &lrdenoise::temporal::TemporalConfig) -> (String, String) {
    let mut label = format!("{} temporal", label(cfg));
    let mut flags = flag_line(cfg).replacen("--method flr", "--method flr-temporal", 1);
    if *temporal != lrdenoise::temporal::TemporalConfig::default() {
        let t = temporal;
        label += &format!(" h{} o{} g{}", t.max_history, t.output_alpha, t.clip_gamma);
        flags += &format!(" --history {} --output-alpha {} --clip-gamma {}", t.max_history, t.output_alpha, t.clip_gamma);
    }
    firefly_history_label(label, flags, temporal.firefly_history)
}

/// [`Built::min_bytes`] of a single-frame method reading the noisy RGB at
/// `noisy_px` pixels and `guide_channels` f32 guide values per output pixel.
fn one_pass_bytes(w: usize, h: usize, noisy_px: usize, guide_channels: usize) -> usize {
    4 * (3 * noisy_px + (guide_channels + 3) * w * h)
}

/// [`Built::min_bytes`] of a temporal pipeline: a single frame's, the motion
/// (2 values per pixel), and its history's two slots (one read, one written).
fn temporal_bytes(w: usize, h: usize, guide_channels: usize, r: &TemporalRunner) -> usize {
    one_pass_bytes(w, h, w * h, guide_channels) + 4 * (2 * w * h + r.history_len())
}

impl Method {
    pub fn flr(cfg: FlrConfig, inputs: &Inputs, threads: usize) -> Result<Self, String> {
        let low = (cfg.upsample > 1).then(|| Box::new(inputs.subsample(cfg.upsample)));
        Ok(Method::Flr { runner: Box::new(FlrRunner::new(cfg, inputs.w, inputs.h, threads)?), low })
    }

    /// Builds method `name` (one of [`METHODS`]) with flags `a` for this frame.
    pub fn build(name: &str, a: &FlrArgs, inputs: &Inputs, threads: usize) -> Result<Built, String> {
        if a.accumulate.is_some() && name != "flr-temporal" {
            return Err(format!("--accumulate is flr-temporal's (what its history accumulates), not {name}'s"));
        }
        check_method(name)?;
        let (w, h) = (inputs.w, inputs.h);
        match name {
            "flr" if a.gpu()? => {
                let cfg = a.config(inputs)?;
                let gpu = lrdenoise_gpu::GpuFlr::new(cfg, w, h).map_err(|e| format!("flr --device gpu: {e}"))?;
                let low = (cfg.upsample > 1).then(|| Box::new(inputs.subsample(cfg.upsample)));
                let label = format!("{} gpu", label(&cfg));
                let method = Method::FlrGpu { gpu: Box::new(gpu), low };
                Ok(Built { method, label, flags: format!("{} --device gpu", flag_line(&cfg)), min_bytes: None })
            }
            "flr" => {
                let cfg = a.config(inputs)?;
                let u = cfg.upsample.max(1);
                let min_bytes = Some(one_pass_bytes(w, h, w.div_ceil(u) * h.div_ceil(u), cfg.guides.channels()));
                Ok(Built { method: Method::flr(cfg, inputs, threads)?, label: label(&cfg), flags: flag_line(&cfg), min_bytes })
            }
            "flr-temporal" if a.accumulate_moments()? => {
                let mut cfg = a.config(inputs)?;
                if a.sigma.is_none() && a.box_radius.is_none() {
                    // (a lone --radius truncates the moments' own window)
                    cfg.blur = Blur::Gaussian { sigma: lrdenoise::flr::config::TEMPORAL_MOMENTS_SIGMA, radius: a.radius };
                }
                if a.regularization.is_none() {
                    cfg.regularization = FlrConfig::temporal_moments().regularization;
                }
                let temporal = a.temporal_config()?;
                let runner = TemporalRunner::moments(cfg, temporal, w, h, threads)?;
                let (mut label, mut flags) =
                    (format!("{} temporal moments", label(&cfg)), flag_line(&cfg).replacen("--method flr", "--method flr-temporal", 1));
                if temporal.max_history != lrdenoise::temporal::TemporalConfig::default().max_history {
                    label += &format!(" h{}", temporal.max_history);
                    flags += &format!(" --history {}", temporal.max_history);
                }
                if temporal.lag_sigmas != lrdenoise::temporal::TemporalConfig::default().lag_sigmas {
                    label += &format!(" l{}", temporal.lag_sigmas);
                    flags += &format!(" --lag-sigmas {}", temporal.lag_sigmas);
                }
                flags += " --accumulate moments";
                let min_bytes = Some(temporal_bytes(w, h, cfg.guides.channels(), &runner));
                Ok(Built { method: Method::Temporal(Box::new(runner)), label, flags, min_bytes })
            }
            "flr-temporal" if a.gpu()? => {
                let cfg = a.temporal_window(a.config(inputs)?);
                let temporal = a.temporal_config()?;
                if a.history_weights {
                    return Err("flr-temporal --device gpu: --history-weights runs on the CPU only".into());
                }
                let (mut label, flags) = temporal_label(&cfg, &temporal);
                let reject = rejection_guides(&cfg, inputs, &mut label);
                let err = |e: lrdenoise_gpu::GpuError| format!("flr-temporal --device gpu: {e}");
                let gpu =
                    lrdenoise_gpu::GpuTemporalFlr::new(cfg, temporal, w, h).map_err(err)?.with_rejection_guides(reject).map_err(err)?;
                let method = Method::FlrTemporalGpu { gpu: Box::new(gpu), saved: None };
                Ok(Built { method, label: label + " gpu", flags: flags + " --device gpu", min_bytes: None })
            }
            _ if a.gpu()? => Err(format!("--device gpu: only flr and flr-temporal run on the GPU, not {name}")),
            "flr-temporal" => {
                let cfg = a.temporal_window(a.config(inputs)?);
                let temporal = a.temporal_config()?;
                let (mut label, mut flags) = temporal_label(&cfg, &temporal);
                if a.history_weights {
                    label += " hw";
                    flags += " --history-weights";
                }
                let reject = rejection_guides(&cfg, inputs, &mut label);
                let runner = TemporalRunner::flr(cfg, temporal, a.history_weights, reject, w, h, threads)?;
                let min_bytes = Some(temporal_bytes(w, h, cfg.guides.channels(), &runner));
                Ok(Built { method: Method::Temporal(Box::new(runner)), label, flags, min_bytes })
            }
            "flnr" => {
                a.only_for(Family::Flnr)?;
                if let Some(m) = inputs.missing(&lrdenoise::flnr::INPUT_GUIDES) {
                    return Err(format!("flnr needs '{m}' but the frame has no '{m}' layer"));
                }
                let (blob, name) = match &a.weights {
                    Some(p) => (std::fs::read(p).map_err(|e| format!("--weights {}: {e}", p.display()))?, p.display().to_string()),
                    None => (BUNDLED_WEIGHTS.to_vec(), "train/flnr.bin".to_string()),
                };
                let default = lrdenoise::FlnrConfig::new(&[]).fireflies;
                let fireflies = a.fireflies.as_deref().map(parse_fireflies).transpose()?.unwrap_or(default);
                let runner = FlnrRunner::new(blob, fireflies, w, h, threads).map_err(|e| format!("flnr ({name}): {e}"))?;
                let net = runner.flnr.network();
                let prior = if runner.flnr.prior().is_some() { "+prior" } else { "" };
                let label = format!("flnr {:?}", net.widths()).replace(' ', "") + prior + &fireflies_label(fireflies, default);
                let mut flags = match &a.weights {
                    Some(p) => format!("--method flnr --weights {}", p.display()),
                    None => "--method flnr".to_string(),
                };
                if fireflies != default {
                    flags += &fireflies_flag(fireflies);
                }
                let min_bytes = Some(one_pass_bytes(w, h, w * h, lrdenoise::flnr::INPUT_GUIDES.channels()));
                Ok(Built { method: Method::Flnr(Box::new(runner)), label, flags, min_bytes })
            }
            "walr" | "walr-temporal" => {
                let cfg = walr_config(a, inputs)?;
                let (label, flags) = walr_flags(name, &cfg);
                let (method, min_bytes) = if name == "walr" {
                    (Method::Walr(Box::new(WalrRunner::new(cfg, w, h, threads)?)), one_pass_bytes(w, h, w * h, cfg.guides.channels()))
                } else {
                    let runner = TemporalRunner::walr(cfg, w, h, threads)?;
                    let bytes = temporal_bytes(w, h, cfg.guides.channels(), &runner);
                    (Method::Temporal(Box::new(runner)), bytes)
                };
                Ok(Built { method, label, flags, min_bytes: Some(min_bytes) })
            }
            _ => {
                let cfg = bmfr_config(a, inputs)?;
                let temporal = name == "bmfr-temporal";
                let mut label = format!("{name} {} b{}", short_guides(&cfg.guides), cfg.block);
                let mut flags = format!("--method {name} --guides {} --block {}", guides_string(&cfg.guides), cfg.block);
                if cfg.shrinkage != BmfrConfig::default().shrinkage {
                    label += &format!(" k{}", cfg.shrinkage);
                    flags += &format!(" --shrinkage {}", cfg.shrinkage);
                }
                if cfg.fireflies != BmfrConfig::default().fireflies {
                    label += &fireflies_label(cfg.fireflies, BmfrConfig::default().fireflies);
                    flags += &fireflies_flag(cfg.fireflies);
                }
                if temporal {
                    (label, flags) = pipeline_label(label, flags, &cfg.temporal);
                }
                let (method, min_bytes) = if temporal {
                    let runner = TemporalRunner::new(cfg, w, h, threads)?;
                    let bytes = temporal_bytes(w, h, cfg.guides.channels(), &runner);
                    (Method::Temporal(Box::new(runner)), bytes)
                } else {
                    (Method::Bmfr(Box::new(BmfrRunner::new(cfg, w, h, threads)?)), one_pass_bytes(w, h, w * h, cfg.guides.channels()))
                };
                Ok(Built { method, label, flags, min_bytes: Some(min_bytes) })
            }
        }
    }

    /// One denoise call (what is timed).
    pub fn run(&mut self, inputs: &Inputs, out: &mut [f32]) -> Result<(), String> {
        match self {
            Method::Noisy => {
                out.copy_from_slice(&inputs.noisy);
                Ok(())
            }
            Method::Flr { runner, low } => runner.run(inputs, low.as_deref(), out).map(|_| ()),
            Method::Bmfr(r) => r.run(inputs, 0, out).map(|_| ()),
            Method::Walr(r) => r.run(inputs, 0, out).map(|_| ()),
            Method::Flnr(r) => r.run(inputs, out),
            Method::Temporal(r) => r.run(inputs, out),
            Method::FlrGpu { gpu, low } => {
                let set = gpu.plan().config().guides;
                let err = |e: lrdenoise::Error| e.to_string();
                // as FlrRunner: with upsampling, noisy and fit guides come from the subsampled frame
                let (src, guides_low) = match low.as_deref() {
                    Some(l) => (l, Some(l.guides(&set).map_err(err)?)),
                    None => (inputs, None),
                };
                let noisy = src.noisy_view().map_err(err)?;
                let frame = lrdenoise::Frame { noisy, guides: inputs.guides(&set).map_err(err)?, guides_low, sample_weights: None };
                let mut ov = lrdenoise::ImageViewMut::interleaved(out, inputs.w, inputs.h, 3).map_err(err)?;
                gpu.denoise(&frame, &mut ov).map(|_| ()).map_err(|e| e.to_string())
            }
            Method::FlrTemporalGpu { gpu, .. } => {
                let set = gpu.frame_guides();
                let err = |e: lrdenoise::Error| e.to_string();
                let frame = lrdenoise::Frame::new(inputs.noisy_view().map_err(err)?, inputs.guides(&set).map_err(err)?);
                let (w, h) = (inputs.w, inputs.h);
                let motion = inputs.motion.as_deref().map(|m| lrdenoise::ImageView::interleaved(m, w, h, 2)).transpose().map_err(err)?;
                let mut ov = lrdenoise::ImageViewMut::interleaved(out, w, h, 3).map_err(err)?;
                gpu.denoise(&frame, motion.as_ref(), &mut ov).map(|_| ()).map_err(|e| format!("flr-temporal --device gpu: {e}"))
            }
        }
    }

    /// Temporal methods: remember the state, so repeated timing runs of one
    /// frame can each start from it ([`Method::restore`]).
    pub fn save(&mut self) -> Result<(), String> {
        match self {
            Method::Temporal(r) => r.save(),
            Method::FlrTemporalGpu { gpu, saved } => {
                let mut h = vec![0f32; gpu.history_len()];
                let frames = gpu.history(&mut h).map_err(|e| format!("flr-temporal --device gpu: reading the history: {e}"))?;
                *saved = Some((h, frames));
            }
            _ => {}
        }
        Ok(())
    }

    /// Temporal methods: go back to the state [`Method::save`] kept (on the
    /// GPU, the history is on the device when this returns).
    pub fn restore(&mut self) -> Result<(), String> {
        match self {
            Method::Temporal(r) => r.restore(),
            Method::FlrTemporalGpu { gpu, saved: Some((h, frames)) } => {
                gpu.set_history(h, *frames).map_err(|e| format!("flr-temporal --device gpu: restoring the history: {e}"))?;
            }
            _ => {}
        }
        Ok(())
    }

    /// Whether every `run` is the next frame of a sequence.
    pub fn is_temporal(&self) -> bool {
        matches!(self, Method::Temporal(_) | Method::FlrTemporalGpu { .. })
    }
}

/// Known method names for `--methods` / `--method`.
pub const METHODS: &[&str] = &["flr", "flr-temporal", "flnr", "bmfr", "bmfr-temporal", "walr", "walr-temporal"];

/// `--method` / `--methods`: the values clap accepts and lists in `--help`
/// and in the error for an unknown one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MethodName {
    /// Fast Local Regression: per-block affine fits to the guides (CPU, or --device gpu)
    Flr,
    /// Temporal FLR: FLR on light accumulated over the valid history, output accumulated under a clip
    FlrTemporal,
    /// FLR on guides rewritten by a small U-Net (--weights)
    Flnr,
    /// Blockwise Multi-Order Feature Regression, one frame
    Bmfr,
    /// BMFR's temporal pipeline (accumulation and reprojection over a sequence)
    BmfrTemporal,
    /// Weighted à-trous Linear Regression, one frame
    Walr,
    /// WALR's temporal pipeline over a sequence
    WalrTemporal,
}

impl MethodName {
    pub fn as_str(self) -> &'static str {
        match self {
            MethodName::Flr => "flr",
            MethodName::FlrTemporal => "flr-temporal",
            MethodName::Flnr => "flnr",
            MethodName::Bmfr => "bmfr",
            MethodName::BmfrTemporal => "bmfr-temporal",
            MethodName::Walr => "walr",
            MethodName::WalrTemporal => "walr-temporal",
        }
    }
}

/// The network trained by `train/flnr.py` (see train/README.md).
pub const BUNDLED_WEIGHTS: &[u8] = include_bytes!("../../train/flnr.bin");

pub fn check_method(m: &str) -> Result<(), String> {
    if METHODS.contains(&m) {
        Ok(())
    } else {
        Err(format!("--method: unknown method '{m}' (available: {})", METHODS.join(", ")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inputs() -> Inputs {
        Inputs {
            w: 2,
            h: 1,
            noisy: vec![0.0; 6],
            normal: Some(vec![0.0; 6]),
            depth: None,
            position: None,
            ao: Some(vec![1.0; 2]),
            albedo: None,
            reference: None,
            motion: None,
            packed: None,
        }
    }

    /// Every method reads the engine layouts as it reads separate layers: the
    /// same bits (RGBA16F: on a frame whose values are halves already).
    #[test]
    fn packed_layouts_give_the_planar_output() {
        use crate::runner::InputLayout;
        let mut planar = crate::bench::synthetic(67, 41);
        let halves = |v: &mut Vec<f32>| v.iter_mut().for_each(|x| *x = half::f16::from_f32(*x).to_f32());
        halves(&mut planar.noisy);
        for v in [&mut planar.normal, &mut planar.depth, &mut planar.ao].into_iter().flatten() {
            halves(v);
        }
        for method in ["flr", "flr-temporal", "bmfr", "walr", "flnr"] {
            let run = |inputs: &Inputs| {
                let mut b = Method::build(method, &FlrArgs::default(), inputs, 1).unwrap();
                let mut out = vec![0f32; 3 * inputs.w * inputs.h];
                b.method.run(inputs, &mut out).unwrap();
                out
            };
            let want = run(&planar);
            for layout in [InputLayout::Rgba32, InputLayout::Rgba16] {
                let got = run(&planar.clone().with_layout(layout).unwrap());
                let same = want.iter().zip(&got).all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{method} {layout:?}");
            }
        }
    }

    #[test]
    fn missing_guide_is_named() {
        let a = FlrArgs { guides: Some("normal,depth".into()), ..Default::default() };
        let e = a.config(&inputs()).unwrap_err();
        assert!(e.contains("'depth'") && e.contains("--guides"), "{e}");
        // default guides: those of normal, depth, ao present
        let c = FlrArgs::default().config(&inputs()).unwrap();
        assert_eq!(c.guides, GuideSet { normal: true, ao: true, ..GuideSet::NONE });
    }

    #[test]
    fn albedo_guide_is_three_user_channels() {
        let g = parse_guides("normal,albedo").unwrap();
        assert_eq!(g, GuideSet { normal: true, user: ALBEDO_CHANNELS, ..GuideSet::NONE });
        assert_eq!(guides_string(&g), "normal,albedo");
        assert_eq!(short_guides(&g), "NAlb");
        // asked for but absent: named
        let a = FlrArgs { guides: Some("normal,albedo".into()), ..Default::default() };
        let e = a.config(&inputs()).unwrap_err();
        assert!(e.contains("'albedo'"), "{e}");
        // present: the user guides are the albedo's channels R, G, B in order
        let mut i = inputs();
        i.albedo = Some(vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        let c = a.config(&i).unwrap();
        let gd = i.guides(&c.guides).unwrap();
        for (ch, u) in gd.user.iter().take(3).enumerate() {
            let v = u.expect("user guide");
            assert_eq!((v.get(0, 0, 0), v.get(1, 0, 0)), (Some(0.1 * (ch + 1) as f32), Some(0.1 * (ch + 4) as f32)));
        }
        assert!(gd.user[3].is_none());
    }

    #[test]
    fn shrinkage_is_a_bmfr_flag() {
        let mut i = inputs();
        i.position = Some(vec![0.0; 6]);
        let a = FlrArgs { shrinkage: Some(0.0), ..Default::default() };
        assert_eq!(bmfr_config(&a, &i).unwrap().shrinkage, 0.0);
        assert_eq!(bmfr_config(&FlrArgs::default(), &i).unwrap().shrinkage, BmfrConfig::default().shrinkage);
        let bad = FlrArgs { shrinkage: Some(-1.0), ..Default::default() };
        assert!(bmfr_config(&bad, &i).unwrap_err().contains("shrinkage"));
        assert!(a.config(&i).unwrap_err().contains("BMFR flag"));
        assert!(walr_config(&a, &i).unwrap_err().contains("--shrinkage"));
        let built = Method::build("bmfr", &a, &i, 1).unwrap();
        assert!(built.label.ends_with(" k0") && built.flags.ends_with(" --shrinkage 0"), "{} / {}", built.label, built.flags);
        let built = Method::build("bmfr", &FlrArgs::default(), &i, 1).unwrap();
        assert!(!built.flags.contains("shrinkage"), "{}", built.flags);
    }

    #[test]
    fn flags_round_trip() {
        let a = FlrArgs {
            guides: Some("normal,ao".into()),
            block: Some(16),
            sigma: Some("7.5".into()),
            regularization: Some("tikhonov:1e-5".into()),
            upsample: Some(2),
            ..Default::default()
        };
        let c = a.config(&inputs()).unwrap();
        let line = flag_line(&c);
        assert_eq!(line, "--method flr --guides normal,ao --block 16 --sigma 7.5 --regularization tikhonov:1e-5 --upsample 2");
        assert!(parse_regularization("normalized:1e-3").is_err());
        assert!(parse_guides("normal,colour").is_err());
    }
}
