//! `lrd advise`: measures which guides and settings earn their cost on one
//! frame, prints a verdict for each and the flags of the chosen configuration.

use crate::evaluate::{evaluate, EvalOptions, Record, Variant};
use crate::methods::{bmfr_config, walr_config, FlrArgs, ALBEDO_CHANNELS};
use crate::runner::Inputs;
use lrdenoise::{Blur, BmfrConfig, FlrConfig, WalrConfig};
use lrdenoise_cli::exrio::ExrFrame;
use std::path::Path;

/// The configuration a measured row ran.
enum Config {
    Flr(FlrConfig),
    Bmfr(BmfrConfig),
    Walr(WalrConfig),
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

pub fn advise(frame: &Path, max_loss: Option<f64>, budget: Option<f64>, runs: usize, threads: usize, methods: &str) -> Result<(), String> {
    let exr = ExrFrame::read(frame)?;
    let inputs = Inputs::from_exr(&exr, frame, "noisy")?;
    if inputs.reference.is_none() {
        return Err(format!("{}: advise measures quality and needs a 'reference' layer", frame.display()));
    }
    let methods: Vec<&str> = methods.split(',').map(str::trim).filter(|m| !m.is_empty()).collect();
    if let Some(m) = methods.iter().find(|m| !["flr", "flnr", "bmfr", "walr"].contains(m)) {
        return Err(format!("--methods: '{m}' is not flr, flnr, bmfr or walr"));
    }
    if !methods.contains(&"flr") {
        return Err("--methods: flr is always weighed (the guide verdicts are FLR's); add flnr, bmfr and/or walr to it".into());
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
    // FLNR (the bundled network) is measured on the frame like the rest, so it is recommended
    // only where it beats FLR on frames like this one, never by the family it was trained on
    if methods.contains(&"flnr") && has("normal") && has("depth") && has("ao") {
        variants.push(Variant::method("flnr", FlrArgs::default()));
    }
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
    let opt = EvalOptions { runs: runs.max(5), threads, keep_images: false, inject: lrdenoise_cli::inject::Injection::Clean };
    let (records, _) = evaluate(&[frame.to_path_buf()], &variants, &opt)?;
    let noisy = records.iter().find(|r| r.method == "noisy").map(|r| r.psnr).unwrap_or(f64::NAN);
    // each row with the configuration it ran (the verdicts compare configurations, not flag strings)
    let config = |r: &Record| -> Option<Config> {
        let v = variants.get(r.variant?)?;
        match v.method.as_str() {
            "flr" => v.args.config(&inputs).ok().map(Config::Flr),
            "bmfr" => bmfr_config(&v.args, &inputs).ok().map(Config::Bmfr),
            "walr" => walr_config(&v.args, &inputs).ok().map(Config::Walr),
            _ => None,
        }
    };
    let measured: Vec<(&Record, Config)> = records.iter().filter_map(|r| Some((r, config(r)?))).collect();
    let flr: Vec<(&Record, &FlrConfig)> = measured
        .iter()
        .filter_map(|(r, c)| match c {
            Config::Flr(c) => Some((*r, c)),
            _ => None,
        })
        .collect();
    let bmfr = |f: &dyn Fn(&BmfrConfig) -> bool| {
        measured.iter().find_map(|(r, c)| match c {
            Config::Bmfr(c) if f(c) => Some(*r),
            _ => None,
        })
    };
    let walr = |f: &dyn Fn(&WalrConfig) -> bool| {
        measured.iter().find_map(|(r, c)| match c {
            Config::Walr(c) if f(c) => Some(*r),
            _ => None,
        })
    };
    let best_flr =
        |f: &dyn Fn(&FlrConfig) -> bool| flr.iter().filter(|(_, c)| f(c)).map(|(r, _)| *r).max_by(|a, b| a.psnr.total_cmp(&b.psnr));
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
    let uses = |c: &FlrConfig, g: &str| match g {
        "normal" => c.guides.normal,
        "depth" => c.guides.depth,
        "position" => c.guides.position,
        "ao" => c.guides.ao,
        "albedo" => c.guides.user == ALBEDO_CHANNELS,
        _ => false,
    };
    for gname in &avail {
        let with = flr.iter().filter(|(_, c)| uses(c, gname)).map(|(r, _)| r.psnr).fold(f64::MIN, f64::max);
        let without = flr.iter().filter(|(_, c)| !uses(c, gname)).map(|(r, _)| r.psnr).fold(f64::MIN, f64::max);
        let verdict = if with - without > 0.1 { "keep" } else { "can drop" };
        println!("  guide {gname:<8}: best with {with:.2} dB, without {without:.2} dB ({:+.2} dB) -> {verdict}", with - without);
    }
    // The AO-free candidate: the best adaptive configuration with AO, with and without it
    let adaptive_ao = |free: bool| best_flr(&|c| c.guides.ao && matches!(c.blur, Blur::Adaptive { .. }) && c.adaptive_without_ao == free);
    if let (Some(d), Some(f)) = (adaptive_ao(false), adaptive_ao(true)) {
        let (a, b) = (("best adaptive with AO", d), ("with the AO-free candidate", f));
        print_option("flr without-ao", a, b, ["use it (--without-ao)", "skip it"]);
    }
    // The AO demodulation: the best B = 8 configuration with AO, with it (the default) and without
    let demodulated = |on: bool| best_flr(&|c| c.guides.ao && c.block == 8 && !c.adaptive_without_ao && c.ao_demodulation.is_some() == on);
    if let (Some(d), Some(p)) = (demodulated(true), demodulated(false)) {
        let (a, b) = (("best B = 8 with AO", d), ("without the AO demodulation", p));
        print_option("flr ao-demod", a, b, ["turn it off (--ao-demodulation off)", "keep it"]);
    }
    // BMFR and WALR, each against its own default
    let walr_default = walr(&|c| c.adaptive_blend && c.tracing);
    if let (Some(d), Some(nt)) = (walr_default, walr(&|c| !c.tracing)) {
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
    let fixed = |w: f32| walr(&|c| c.tracing && !c.adaptive_blend && c.previous_weight == w);
    if let (Some(d), Some(f), Some(one)) = (walr_default, fixed(0.6), fixed(0.0)) {
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
    if let (Some(f), Some(n)) = (best_flr(&|_| true), records.iter().find(|r| r.method == "flnr")) {
        print_option("flnr", ("best FLR", f), ("FLNR", n), ["FLNR wins on this frame", "FLR: FLNR does not pay here"]);
    }
    let bmfr_default = bmfr(&|c| c.block == 32 && c.shrinkage == BmfrConfig::default().shrinkage);
    if let (Some(b32), Some(b64)) = (bmfr_default, bmfr(&|c| c.block == 64)) {
        println!("  bmfr blocks      : 32x32 {:.2} dB in {:.3} ms, 64x64 {:.2} dB in {:.3} ms", b32.psnr, b32.ms, b64.psnr, b64.ms);
    }
    if let (Some(d), Some(plain)) = (bmfr_default, bmfr(&|c| c.shrinkage == 0.0)) {
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
