//! `lrd report` and `lrd demo`: the configurations compared, report.md
//! (tables, a legend of the configuration names), the error-versus-runtime
//! plot ([`plot`]), the per-frame image strips ([`strips`]) and the
//! robustness table ([`robustness`]).

mod plot;
pub mod robustness;
pub mod sequences;
mod strips;

use crate::evaluate::{evaluate, means, EvalOptions, Record, Variant};
use crate::methods::FlrArgs;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

pub fn register_font() {
    let _ = plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, FONT);
}

/// Indices of the Pareto-optimal rows: no other row is both faster and better.
pub fn pareto(rows: &[&Record], better: impl Fn(&Record, &Record) -> bool) -> Vec<usize> {
    (0..rows.len())
        .filter(|&i| {
            !(0..rows.len()).any(|j| {
                j != i && rows[j].ms <= rows[i].ms && better(rows[j], rows[i]) && (rows[j].ms < rows[i].ms || better(rows[j], rows[i]))
            })
        })
        .collect()
}

pub fn table(rows: &[Record], with_frame: bool) -> String {
    let mut s = String::new();
    if with_frame {
        s += "| frame | config | PSNR dB | SSIM | FLIP | rMSE | flicker | ms |\n|---|---|---:|---:|---:|---:|---:|---:|\n";
    } else {
        s += "| config | PSNR dB | SSIM | FLIP | rMSE | flicker | ms | flags |\n|---|---:|---:|---:|---:|---:|---:|---|\n";
    }
    for r in rows {
        let ms = if r.method == "noisy" { "–".to_string() } else { format!("{:.3}", r.ms) };
        let fl = r.flicker.map(|f| format!("{f:.4}")).unwrap_or_else(|| "–".into());
        if with_frame {
            let _ = writeln!(
                s,
                "| {} | {} | {:.2} | {:.4} | {:.4} | {:.4} | {fl} | {} |",
                r.frame, r.config, r.psnr, r.ssim, r.flip, r.rmse, ms
            );
        } else {
            let _ = writeln!(
                s,
                "| {} | {:.2} | {:.4} | {:.4} | {:.4} | {fl} | {} | `{}` |",
                r.config, r.psnr, r.ssim, r.flip, r.rmse, ms, r.flags
            );
        }
    }
    s
}

/// What the short configuration names of the tables, plot and strips mean.
pub const LEGEND: &str = "\
Each configuration is named `METHOD GUIDES SETTINGS`; the `flags` column gives the full `lrd denoise` flags.

- Guides: `N` normal, `D` depth, `P` position, `A` ambient occlusion (AO), `Alb` albedo, `-` none (so `NDA` = normal, depth, AO).
- `flr`: `bB` one affine model per B×B pixels (`--block`); `sS` a Gaussian window of σ = S pixels (`--sigma S`); \
`s6/12/20` the adaptive window, fits with σ 6, 12 and 20 blended per cell (the default); `boxR` a box window of radius R (`--box`); \
`-ao` the adaptive window's extra AO-free fit (`--without-ao`); `-aod` AO demodulation off (`--ao-demodulation off`), `aodC` with \
offset C; `tik` Tikhonov regularization (`--regularization tikhonov:…`); `up2`, `up4` traced at ½ or ¼ resolution and upsampled \
jointly (`--upsample`). `… temporal` is temporal FLR over a sequence (`--method flr-temporal`: accumulated light, output accumulated under a clip); `hH oA gG` its history length, output blend weight and clip width when not the defaults (`--history`, `--output-alpha`, `--clip-gamma`; `o1` = no output accumulation); `… temporal moments` accumulates FLR's cell moments instead (`--accumulate moments`; `hH lK` its history length and lag test threshold when not the defaults, `--history`, `--lag-sigmas`).
- `bmfr`: `bB` block size (`--block`); `kK` Wiener shrinkage κ = K (`--shrinkage`; `k0` = the paper's plain least squares; \
default 4, not shown). `bmfr-temporal` is the pipeline over a sequence (accumulation, reprojection).
- `walr`: `tT` à-trous iterations (`--iterations`); `pw-adaptive` the last two windows blended per pixel (default), `pwW` a fixed \
weight W of the previous window (`--previous-weight`), none = one window; `f16`/`f32` storage of the averages; `notrace` no edge \
tracing (`--no-tracing`). `walr-temporal` is its pipeline over a sequence.
- `flnr[…]`: the U-Net's channel widths (the bundled weights unless `--weights`); `+prior`: the network also reads FLR's defaults output.
- `[noisy4]`: run on the 4-spp input layer instead of the 1-spp `noisy` (`--input-layer noisy4`); `noisy`, `noisy4`: the inputs \
themselves, undenoised.
";

/// Whether a row ran on another input than the 1-spp frame: the 4-spp layer
/// or a subsampled frame (joint upsampling). Hollow markers in the plot.
pub fn other_input(r: &Record) -> bool {
    r.flags.contains("--input-layer") || r.flags.contains("--upsample")
}

/// The best row of each method by PSNR (1-spp input only), in first-seen order.
pub fn best_per_method(rows: &[Record]) -> Vec<&Record> {
    let mut out: Vec<&Record> = vec![];
    // the 1-spp rows; of the inputs themselves, only `noisy`
    let one_spp = |r: &&Record| !other_input(r) && (r.method != "noisy" || r.config == "noisy");
    for r in rows.iter().filter(one_spp) {
        match out.iter_mut().find(|b| b.method == r.method) {
            Some(b) if r.psnr > b.psnr => *b = r,
            Some(_) => {}
            None => out.push(r),
        }
    }
    out
}

/// Short text for the terminal: the best configuration of each method with its time.
pub fn summary(mean: &[Record]) -> String {
    let best = best_per_method(mean);
    let width = best.iter().map(|r| r.config.chars().count()).max().unwrap_or(0);
    let mut s = String::from("best configuration per method (mean PSNR over frames; median time per frame):\n");
    for r in best {
        let time = if r.method == "noisy" { "(the input)".to_string() } else { format!("{:>8.3} ms", r.ms) };
        let _ = writeln!(s, "  {:<width$}  {:>6.2} dB  {time}", r.config, r.psnr);
    }
    s
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
        Variant::method("flr-temporal", FlrArgs::default()),
        Variant::method("flr-temporal", FlrArgs { output_alpha: Some(1.0), ..Default::default() }),
        Variant::method("flr-temporal", FlrArgs { accumulate: Some("moments".into()), ..Default::default() }),
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
pub fn write_report(
    frames: &[PathBuf],
    out: &Path,
    peers: &[PathBuf],
    runs: usize,
    threads: usize,
    full_strips: bool,
) -> Result<Vec<Record>, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let opt = EvalOptions { runs: runs.max(5), threads, keep_images: true, inject: lrdenoise_cli::inject::Injection::Clean };
    let (mut records, images) = evaluate(frames, &report_variants(), &opt)?;
    if records.is_empty() {
        return Err("no frame with a 'reference' layer: nothing to report".into());
    }
    let mut peer_records = vec![];
    for p in peers {
        let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
        let peer: Vec<Record> = serde_json::from_str(&text).map_err(|e| format!("{}: not a JSON list of records ({e})", p.display()))?;
        peer_records.extend(peer);
    }
    // peers on injected frames go to the robustness table only
    records.extend(peer_records.iter().filter(|r| robustness::is_clean(r)).cloned());
    let mean = means(&records);
    // Rows that cover fewer frames (peers measured on the stills only) are
    // compared on the frames every row covers: the plot and the first table.
    let common = common_frames(&records);
    let partial = common.len() < images.len();
    let mean_common =
        if partial { means(&records.iter().filter(|r| common.contains(&r.frame)).cloned().collect::<Vec<_>>()) } else { mean.clone() };
    let refs: Vec<&Record> = mean_common.iter().collect();
    plot(out, &refs)?;
    // the strips: by default the noisy input and each method's best configuration
    let keep: Vec<String> = best_per_method(&mean).iter().map(|r| r.config.clone()).collect();
    let strips = strips(out, &images, (!full_strips).then_some(keep.as_slice()))?;
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string()))
        .unwrap_or_else(|| "unknown CPU".into());
    let (w, h) = (records[0].width, records[0].height);
    let mut md = String::new();
    md += "# lrdenoise report\n\n";
    md += &format!(
        "{} frame(s), {w}x{h} (first frame); {threads} thread(s); {cpu}; SIMD level `{}` (compiled; run-time choice for FLR's moments, solve and apply, BMFR's QR and FLNR's 3×3 layers: `{:?}`); time = median of {} runs after a warm-up, denoiser only (no I/O). \
         Metrics follow docs/DATA.md (albedo-modulated, tone-mapped PSNR/SSIM/LDR-FLIP, linear rMSE). Peer rows (if any) were measured by their own tools.\n\n",
        images.len(),
        lrdenoise::SIMD_LEVEL,
        lrdenoise::isa::Isa::detect(),
        opt.runs
    );
    if partial {
        md += &format!("## Mean over the {} frames every row covers ({})\n\nThe plot shows these.\n\n", common.len(), common.join(", "));
        md += &table(&mean_common, false);
        md += "\n## Mean over all frames (a row's own frames: peers cover fewer)\n\n";
    } else {
        md += "## Mean over frames\n\n";
    }
    md += &table(&mean, false);
    md += "\n### Configuration names\n\n";
    md += LEGEND;
    md += "\n![error versus run time](plot.png)\n\n";
    let seq = sequences::table(&records);
    if !seq.is_empty() {
        md += "## Sequences\n\nPer sequence: mean PSNR of all frames and of the last 4, flicker of the last 4 (docs/DATA.md's frames, `metrics::flicker`), and the frames until every later frame stays within 0.5 dB of the last 4's mean.\n\n";
        md += &seq;
        md += "\n";
    }
    md += "## Per frame\n\n";
    md += &table(&records, true);
    md += if full_strips {
        "\n## Image strips\n\nTop: noisy | each configuration | reference; bottom: FLIP error maps.\n\n"
    } else {
        "\n## Image strips\n\nTop: noisy | the best configuration of each method (mean PSNR) | reference; bottom: FLIP error maps. \
         Every configuration: `--full-strips`.\n\n"
    };
    for s in &strips {
        md += &format!("![{s}]({s})\n\n");
    }
    md += &robustness::section(frames, out, &peer_records, threads)?;
    std::fs::write(out.join("report.md"), md).map_err(|e| format!("{}: {e}", out.display()))?;
    let json = serde_json::to_string_pretty(&records).map_err(|e| e.to_string())?;
    std::fs::write(out.join("records.json"), json).map_err(|e| e.to_string())?;
    Ok(mean)
}

/// The frames every configuration (other than the noisy inputs) has a row
/// for, in the order they first appear.
fn common_frames(records: &[Record]) -> Vec<String> {
    let mut frames: Vec<String> = vec![];
    for r in records {
        if !frames.contains(&r.frame) {
            frames.push(r.frame.clone());
        }
    }
    let configs: Vec<&str> = records.iter().filter(|r| r.method != "noisy").map(|r| r.config.as_str()).collect();
    frames.retain(|f| configs.iter().all(|c| records.iter().any(|r| r.config == *c && &r.frame == f)));
    frames
}

/// The line naming what `lrd report` / `lrd demo` wrote.
pub fn report_written(out: &Path) -> String {
    format!(
        "report: {} (with plot.png, plot.svg, records.json, strip_FRAME.png, robustness.json and the injected stills robustness/CASE/FRAME.exr in {})",
        out.join("report.md").display(),
        out.display()
    )
}

pub use plot::plot;
pub use strips::strips;
