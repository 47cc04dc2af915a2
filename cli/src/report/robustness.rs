//! The robustness table: every case of `inject::CASES` (docs/DATA.md's
//! robustness protocol: outliers in the `noisy` layer only, fixed seed), the
//! mean PSNR of each configuration under it and the drop from the same
//! configuration's clean PSNR. `lrd report` runs it on the still frames and
//! writes the injected frames for `tools/peers.py`; `lrd eval --inject all`
//! prints it for the configurations asked for.

use crate::evaluate::{evaluate, EvalOptions, Record, Variant};
use crate::methods::FlrArgs;
use lrdenoise_cli::exrio::{ExrFrame, Layer};
use lrdenoise_cli::inject::{Injection, CASES};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The configurations of the report's robustness table: each method at its
/// defaults, and FLR without its firefly clamp (what the clamp buys).
pub fn variants() -> Vec<Variant> {
    vec![
        Variant::flr(FlrArgs::default()),
        Variant::flr(FlrArgs { fireflies: Some("off".into()), ..Default::default() }),
        Variant::method("bmfr", FlrArgs::default()),
        Variant::method("walr", FlrArgs::default()),
        Variant::method("flnr", FlrArgs::default()),
    ]
}

/// Whether a record is of the frame as rendered (`inject` empty or "clean").
pub fn is_clean(r: &Record) -> bool {
    r.inject.is_empty() || r.inject == Injection::Clean.name()
}

/// The case a record belongs to: its index in `CASES`, `None` for an unknown name.
fn case_of(r: &Record) -> Option<usize> {
    if is_clean(r) {
        return Some(0);
    }
    CASES.iter().position(|c| c.name() == r.inject)
}

/// Whether `p` is a frame of a sequence: its directory holds `frame_NNNN.exr` files.
pub fn in_sequence(p: &Path) -> bool {
    let dir = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let numbered = |name: &str| {
        name.strip_prefix("frame_")
            .and_then(|s| s.strip_suffix(".exr").or_else(|| s.strip_suffix(".EXR")))
            .is_some_and(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()))
    };
    std::fs::read_dir(dir).map(|rd| rd.filter_map(|e| e.ok()).any(|e| numbered(&e.file_name().to_string_lossy()))).unwrap_or(false)
}

/// The salt `evaluate` injects a frame with: its number for `frame_NNNN`, else 0.
fn salt(p: &Path) -> u64 {
    let stem = p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
    stem.strip_prefix("frame_").and_then(|n| n.parse::<u64>().ok()).unwrap_or(0)
}

/// Variants that get the same table label (FLR with and without the firefly
/// clamp, where the label does not say): the later ones get their flags
/// appended to `config` (and to `flags` where those lack them), so every
/// variant keeps its own row.
fn disambiguate(records: &mut [Record], variants: &[Variant]) {
    let mut owner: Vec<(String, Option<usize>)> = vec![];
    for r in records.iter() {
        if !owner.iter().any(|(c, v)| *c == r.config && *v == r.variant) {
            owner.push((r.config.clone(), r.variant));
        }
    }
    for r in records.iter_mut() {
        let first = owner.iter().find(|(c, _)| *c == r.config).and_then(|(_, v)| *v);
        let Some(vi) = r.variant.filter(|&vi| Some(vi) != first) else { continue };
        let Some(v) = variants.get(vi) else { continue };
        let extra = v.describe().strip_prefix(v.method.as_str()).unwrap_or_default().trim().to_string();
        if extra.is_empty() {
            continue;
        }
        r.config = format!("{} ({extra})", r.config);
        if !extra.split_whitespace().filter(|w| w.starts_with("--")).all(|f| r.flags.contains(f)) {
            r.flags = format!("{} {extra}", r.flags).trim().to_string();
        }
    }
}

/// Runs `variants` on `frames` once per case of `CASES`; returns every record
/// (each carries its case in `inject`).
pub fn run_cases(frames: &[PathBuf], variants: &[Variant], runs: usize, threads: usize) -> Result<Vec<Record>, String> {
    let mut all = vec![];
    for case in CASES {
        let opt = EvalOptions { runs, threads, keep_images: false, inject: case };
        let (mut records, _) = evaluate(frames, variants, &opt)?;
        disambiguate(&mut records, variants);
        all.extend(records);
    }
    Ok(all)
}

fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn cell(v: Option<f64>) -> String {
    // (a drop within ±0.005 dB prints as 0.00, not -0.00)
    v.map(|x| format!("{:.2}", if x.abs() < 0.005 { 0.0 } else { x })).unwrap_or_else(|| "–".into())
}

/// The markdown table: one row per configuration that has a record of an
/// injected case (first-seen order), the mean PSNR of each case over its
/// frames, then for each injected case the drop in dB from the row's clean
/// PSNR, over the frames that have both.
pub fn table(records: &[Record]) -> String {
    let mut configs: Vec<&str> = vec![];
    for r in records {
        if case_of(r).is_some_and(|c| c > 0) && !configs.contains(&r.config.as_str()) {
            configs.push(&r.config);
        }
    }
    let mut s = String::from("| config |");
    for c in CASES {
        let _ = write!(s, " {} |", c.caption());
    }
    for c in &CASES[1..] {
        let _ = write!(s, " drop, {} |", c.caption());
    }
    s += "\n|---|";
    s += &"---:|".repeat(2 * CASES.len() - 1);
    s += "\n";
    for config in configs {
        let of = |case: usize| -> Vec<&Record> { records.iter().filter(|r| r.config == config && case_of(r) == Some(case)).collect() };
        let clean = of(0);
        let _ = write!(s, "| {config} |");
        for ci in 0..CASES.len() {
            let _ = write!(s, " {} |", cell(mean(&of(ci).iter().map(|r| r.psnr).collect::<Vec<_>>())));
        }
        for ci in 1..CASES.len() {
            let drops: Vec<f64> =
                of(ci).iter().filter_map(|r| clean.iter().find(|c| c.frame == r.frame).map(|c| c.psnr - r.psnr)).collect();
            let _ = write!(s, " {} |", cell(mean(&drops)));
        }
        s += "\n";
    }
    s
}

/// The names of the injected cases, for shell loops.
fn injected_names() -> Vec<String> {
    CASES[1..].iter().map(|c| c.name()).collect()
}

/// `lrd report`'s robustness part: runs [`variants`] under every case on the
/// still frames among `frames`, writes the injected stills to
/// `out/robustness/CASE/FRAME.exr` and every record to `out/robustness.json`;
/// returns the report.md section. `peers`: every record of the `--peers`
/// files (those whose `inject` names a case get a row; their clean column is
/// their records without an `inject`).
pub fn section(frames: &[PathBuf], out: &Path, peers: &[Record], threads: usize) -> Result<String, String> {
    let stills: Vec<PathBuf> = frames.iter().filter(|p| !in_sequence(p)).cloned().collect();
    let mut md = String::from("## Robustness (outliers injected into the noisy input)\n\n");
    if stills.is_empty() {
        md += "No still frame among the frames given (the table runs on stills, not on sequences).\n";
        return Ok(md);
    }
    let dir = out.join("robustness");
    let mut written: Vec<String> = vec![];
    for case in &CASES[1..] {
        let case_dir = dir.join(case.name());
        std::fs::create_dir_all(&case_dir).map_err(|e| format!("{}: {e}", case_dir.display()))?;
        for p in &stills {
            let mut frame = ExrFrame::read(p)?;
            if !frame.has("reference") {
                continue;
            }
            case.apply(&mut frame, salt(p)).map_err(|e| format!("{}: {e}", p.display()))?;
            let stem = p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
            let layers: Vec<(&str, &Layer)> = frame.layers.iter().map(|(k, l)| (k.as_str(), l)).collect();
            ExrFrame::write(&case_dir.join(format!("{stem}.exr")), frame.width, frame.height, &layers)?;
            if !written.contains(&stem) {
                written.push(stem);
            }
        }
    }
    let mut records = run_cases(&stills, &variants(), 1, threads)?;
    let json = serde_json::to_string_pretty(&records).map_err(|e| e.to_string())?;
    std::fs::write(out.join("robustness.json"), json).map_err(|e| format!("{}: {e}", out.display()))?;
    let names: Vec<String> = records.iter().map(|r| r.frame.clone()).fold(vec![], |mut v, f| {
        if !v.contains(&f) {
            v.push(f);
        }
        v
    });
    // peer rows on the same stills only
    records.extend(peers.iter().filter(|r| names.contains(&r.frame) && case_of(r).is_some()).cloned());
    let _ = write!(
        md,
        "The protocol of docs/DATA.md: outliers in the `noisy` layer only, from a fixed seed (`lrd eval --inject`), \
         on the {} still frame(s) ({}); each method at its defaults, and FLR without its firefly clamp \
         (`--fireflies off`). Mean PSNR dB over the frames; \"drop\" is the row's clean PSNR minus the case's, \
         over the frames both cover. Scores follow the metrics protocol, where a NaN output pixel counts as black \
         and +Inf as white. Times are from one run per frame (robustness.json; not the medians of the tables above). \
         Peer rows: `--peers` records whose `inject` names a case (their clean column: their records without one).\n\n",
        names.len(),
        names.join(", ")
    );
    md += &table(&records);
    let d = dir.display();
    let cases = injected_names().join(" ");
    let _ = write!(
        md,
        "\nThe injected frames (the `noisy` layer in f32) are in `{d}/CASE/` ({}), the same on every run; \
         for the peer rows, score the peers on them and pass their records to the next `lrd report` \
         (with the peers' clean records, from the original stills):\n\n\
         ```sh\nfor c in {cases}; do python3 tools/peers.py {d}/$c --inject-name $c -o {d}/peers_$c.json --threads 1; done\n\
         lrd report FRAMES... -o {} --peers peers.json{}\n```\n",
        injected_names().join(", "),
        out.display(),
        injected_names().iter().map(|c| format!(" --peers {d}/peers_{c}.json")).collect::<String>()
    );
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(config: &str, frame: &str, inject: &str, psnr: f64) -> Record {
        Record {
            method: config.split(' ').next().unwrap_or_default().into(),
            config: config.into(),
            frame: frame.into(),
            psnr,
            ssim: 0.5,
            flip: 0.1,
            rmse: 0.01,
            ms: 1.0,
            threads: 1,
            width: 8,
            height: 8,
            flags: String::new(),
            flicker: None,
            reference_flicker: None,
            inject: inject.into(),
            sequence: None,
            variant: None,
        }
    }

    #[test]
    fn table_has_a_row_per_config_with_means_and_drops() {
        let [_, a, b, n] = CASES.map(|c| c.name());
        let mut rs = vec![];
        for (f, base) in [("room_7", 30.0), ("poles_7", 28.0)] {
            rs.push(rec("flr NDA", f, "clean", base));
            rs.push(rec("flr NDA", f, &a, base - 1.0));
            rs.push(rec("flr NDA", f, &b, base - 2.0));
            rs.push(rec("flr NDA", f, &n, base - 4.0));
        }
        // a peer: clean records without `inject`, one injected case, one frame only
        rs.push(rec("oidn", "room_7", "", 31.0));
        rs.push(rec("oidn", "poles_7", "", 29.0));
        rs.push(rec("oidn", "room_7", &a, 25.0));
        // a peer with clean records only gets no row
        rs.push(rec("guided", "room_7", "", 27.0));
        let t = table(&rs);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 4, "{t}");
        assert!(lines[0].starts_with("| config | clean | 0.01 % × 1000 |") && lines[0].contains("drop, NaN + Inf"), "{t}");
        assert_eq!(lines[2], "| flr NDA | 29.00 | 28.00 | 27.00 | 25.00 | 1.00 | 2.00 | 4.00 |");
        // the drop is over the frames both cover: room_7 only
        assert_eq!(lines[3], "| oidn | 30.00 | 25.00 | – | – | 6.00 | – | – |");
    }

    #[test]
    fn same_labels_get_their_flags() {
        let v = variants();
        let mut rs =
            vec![rec("flr NDA", "room_7", "clean", 30.0), rec("flr NDA", "room_7", "clean", 29.0), rec("bmfr NP b32", "room_7", "", 28.0)];
        rs[0].variant = Some(0);
        rs[1].variant = Some(1);
        rs[2].variant = Some(2);
        disambiguate(&mut rs, &v);
        assert_eq!(rs[0].config, "flr NDA");
        assert_eq!(rs[1].config, "flr NDA (--fireflies off)");
        assert_eq!(rs[1].flags, "--fireflies off");
        assert_eq!(rs[2].config, "bmfr NP b32");
    }
}
