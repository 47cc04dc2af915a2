//! End-to-end tests of the `lrd` binary on the bundled sample frames.

use std::path::{Path, PathBuf};
use std::process::Command;

fn lrd(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_lrd")).args(args).output().expect("run lrd");
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

fn data(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data").join(name).to_string_lossy().into()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("lrd-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

/// Fails with exactly one line on stderr that contains every `needle`, and no panic.
fn fails_with(args: &[&str], needles: &[&str]) {
    let (ok, _, err) = lrd(args);
    assert!(!ok, "{args:?} should fail");
    assert!(!err.contains("panicked") && !err.contains("internal error"), "{args:?}: {err}");
    let first = err.lines().next().unwrap_or("");
    for n in needles {
        assert!(first.contains(n), "{args:?}: '{first}' lacks '{n}'");
    }
}

#[test]
fn bad_inputs_give_clear_errors() {
    let room = data("room_7.exr");
    let out = tmp("o.exr");
    let out = out.to_str().unwrap();
    fails_with(&["denoise", "nope.exr", "-o", out], &["nope.exr", "no such file"]);
    let txt = tmp("not.exr");
    std::fs::write(&txt, "hello, not an exr").unwrap();
    fails_with(&["denoise", txt.to_str().unwrap(), "-o", out], &["not.exr", "OpenEXR"]);
    let bytes = std::fs::read(&room).unwrap();
    let trunc = tmp("trunc.exr");
    std::fs::write(&trunc, &bytes[..bytes.len() / 3]).unwrap();
    fails_with(&["denoise", trunc.to_str().unwrap(), "-o", out], &["trunc.exr"]);
    fails_with(&["denoise", &room, "-o", out, "--input-layer", "noisy64"], &["noisy64", "missing layer"]);
    fails_with(&["denoise", &room, "-o", out, "--regularization", "magic:1"], &["--regularization"]);
    fails_with(&["denoise", &room, "-o", out, "--guides", "normal,colour"], &["--guides", "colour"]);
    fails_with(&["denoise", &room, "-o", out, "--block", "3"], &["block"]);
    fails_with(&["denoise", &room, "-o", out, "--method", "magic"], &["--method", "magic"]);
    // clap lists the methods
    let (_, _, e) = lrd(&["denoise", &room, "-o", out, "--method", "magic"]);
    assert!(e.contains("possible values: flr, flr-temporal, flnr, bmfr, bmfr-temporal, walr, walr-temporal"), "{e}");
    fails_with(&["eval", &room, "--methods", "flr,oidn"], &["--methods", "oidn"]);
    fails_with(&["bench", "--size", "12by7"], &["--size"]);
    // a frame without the depth layer, asked to use depth
    let nodepth = tmp("nodepth.exr");
    let (ok, _, e) = lrd(&["denoise", &room, "-o", nodepth.to_str().unwrap(), "--guides", "normal", "--only-output"]);
    assert!(ok, "{e}");
    // (a frame holding only `denoised`: the noisy layer it needs is named)
    fails_with(&["denoise", nodepth.to_str().unwrap(), "-o", out, "--guides", "depth"], &["missing layer 'noisy'"]);
}

#[test]
fn denoise_writes_layers_and_preview() {
    let room = data("room_7.exr");
    let out = tmp("room_d.exr");
    let png = tmp("room.png");
    let (ok, so, e) = lrd(&["denoise", &room, "-o", out.to_str().unwrap(), "--png", png.to_str().unwrap(), "--threads", "2"]);
    assert!(ok, "{e}");
    assert!(so.contains("256x256") && so.contains("ms") && so.contains("threads 2"), "{so}");
    // the summary names every file written
    assert!(so.contains(out.to_str().unwrap()) && so.contains(png.to_str().unwrap()), "{so}");
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    // output keeps the inputs and can be denoised again; eval reads it
    let (ok, so, e) = lrd(&["eval", out.to_str().unwrap(), "--runs", "5"]);
    assert!(ok, "{e}");
    assert!(so.contains("flr"), "{so}");
    // --input-layer noisy4 and --only-output
    let out4 = tmp("room_d4.exr");
    let (ok, _, e) = lrd(&[
        "denoise",
        &room,
        "-o",
        out4.to_str().unwrap(),
        "--input-layer",
        "noisy4",
        "--only-output",
        "--block",
        "16",
        "--sigma",
        "20",
    ]);
    assert!(ok, "{e}");
    assert!(std::fs::metadata(&out4).unwrap().len() < std::fs::metadata(&out).unwrap().len());
}

#[test]
fn eval_json_and_quality() {
    let json = tmp("eval.json");
    let (ok, _, e) = lrd(&["eval", &data("room_7.exr"), &data("poles_7.exr"), "--json", json.to_str().unwrap(), "--runs", "5"]);
    assert!(ok, "{e}");
    // the progress bar draws only on a terminal
    assert!(e.is_empty(), "{e}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let recs = v.as_array().unwrap();
    assert_eq!(recs.len(), 4); // (noisy, flr) x 2 frames
    for r in recs {
        for k in ["psnr", "ssim", "flip", "rmse", "ms"] {
            assert!(r[k].as_f64().unwrap().is_finite(), "{k} in {r}");
        }
    }
    // --guides ...,albedo feeds the albedo to the fit: on this untextured scene it
    // changes the result (+0.4 dB measured), and the row is labelled
    let (ok, _, e) =
        lrd(&["eval", &data("farclutter_7.exr"), "--guides", "normal,depth,ao,albedo", "--json", json.to_str().unwrap(), "--runs", "5"]);
    assert!(ok, "{e}");
    let with: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let (ok, _, e) = lrd(&["eval", &data("farclutter_7.exr"), "--json", json.to_str().unwrap(), "--runs", "5"]);
    assert!(ok, "{e}");
    let without: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let (w, wo) = (&with.as_array().unwrap()[1], &without.as_array().unwrap()[1]);
    assert!(w["config"].as_str().unwrap().contains("NDAAlb"), "{w}");
    assert!(w["psnr"].as_f64().unwrap() > wo["psnr"].as_f64().unwrap() + 0.1, "{w} vs {wo}");
    // FLR must beat the noisy input by a wide margin on every frame
    for f in ["room_7", "poles_7"] {
        let get = |m: &str| recs.iter().find(|r| r["frame"] == f && r["method"] == m).unwrap()["psnr"].as_f64().unwrap();
        assert!(get("flr") > get("noisy") + 10.0, "{f}");
    }
}

/// `lrd`'s metrics against scikit-image's PSNR/SSIM and NVIDIA's FLIP
/// (`tools/metrics_reference.py`). Ignored by default; `.ci/run` installs the
/// packages and runs it with `--ignored`, where a missing package fails it.
#[test]
#[ignore = "needs python3 with scikit-image, flip-evaluator, OpenEXR (run with --ignored; CI does)"]
fn metrics_agree_with_python_references() {
    let py = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/metrics_reference.py");
    // output(), not status(): the import error goes into the failure message, not the test log
    let probe = Command::new("python3").args(["-c", "import skimage, flip_evaluator, OpenEXR"]).output();
    match probe {
        Ok(o) if o.status.success() => {}
        Ok(o) => panic!(
            "python3 lacks scikit-image, flip-evaluator or OpenEXR \
             (python3 -m pip install scikit-image flip-evaluator OpenEXR numpy): {}",
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")
        ),
        Err(e) => panic!("cannot run python3: {e}"),
    }
    for f in ["room_7.exr", "farclutter_7.exr", "colonnade_7.exr"] {
        let frame = data(f);
        let den = tmp(&format!("py_{f}"));
        assert!(lrd(&["denoise", &frame, "-o", den.to_str().unwrap()]).0);
        let json = tmp(&format!("py_{f}.json"));
        assert!(lrd(&["eval", den.to_str().unwrap(), "--json", json.to_str().unwrap(), "--runs", "5"]).0);
        let ours: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let o = Command::new("python3").arg(&py).arg(&frame).arg(&den).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let theirs: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        for (row, key) in [("noisy", "noisy"), ("flr", "denoised")] {
            let a = ours.as_array().unwrap().iter().find(|r| r["method"] == row).unwrap();
            let b = &theirs[key];
            let d = |k: &str| (a[k].as_f64().unwrap() - b[k].as_f64().unwrap()).abs();
            assert!(d("psnr") < 0.01, "{f} {row} psnr {a} vs {b}");
            assert!(d("ssim") < 1e-3, "{f} {row} ssim {a} vs {b}");
            assert!(d("flip") < 1e-3, "{f} {row} flip {a} vs {b}");
            assert!(d("rmse") < 1e-3 * b["rmse"].as_f64().unwrap().max(1e-3), "{f} {row} rmse {a} vs {b}");
        }
    }
}

#[test]
fn advise_bench_and_sequences() {
    let (ok, so, e) = lrd(&["advise", &data("poles_7.exr"), "--runs", "5"]);
    assert!(ok, "{e}");
    let last = so.lines().last().unwrap();
    assert!(last.starts_with("--method flr --guides"), "{so}");
    assert!(so.contains("guide normal"), "{so}");
    // Each guide's worth is best-with minus best-without: both finite (every
    // flag line contains "normalized", which must not count as the normal guide).
    for line in so.lines().filter(|l| l.trim_start().starts_with("guide ")) {
        let db: Vec<f64> = line.split_whitespace().filter_map(|w| w.trim_start_matches('(').parse::<f64>().ok()).collect();
        assert!(db.len() == 3 && db.iter().all(|v| v.is_finite() && v.abs() < 100.0), "{line}");
    }
    assert!(so.contains("guide albedo"), "{so}");
    // with the other methods: WALR's stages and BMFR's blocks weighed too, the choice over all
    let (ok, so, e) = lrd(&["advise", &data("poles_7.exr"), "--runs", "5", "--budget-ms", "1000", "--methods", "flr,flnr,bmfr,walr"]);
    assert!(ok && so.contains("chosen"), "{e}");
    for l in ["walr tracing", "walr blend", "bmfr blocks", "bmfr shrinkage", ": best FLR "] {
        assert!(so.contains(l), "{l}: {so}");
    }
    fails_with(&["advise", &data("poles_7.exr"), "--methods", "walr"], &["flr is always weighed"]);
    fails_with(&["advise", &data("poles_7.exr"), "--methods", "flr,oidn"], &["'oidn' is not flr, flnr, bmfr or walr"]);
    let (ok, so, e) = lrd(&["bench", "--size", "320x200", "--runs", "5"]);
    assert!(ok, "{e}");
    assert!(so.contains("median") && so.contains("ms") && so.contains("simd"), "{so}");
    // the same-run baseline: noisy RGB + normal, depth, AO in, RGB out = 11 f32 × 320 × 200
    assert!(so.contains("memcpy of the 2.8 MB") && so.contains("x that"), "{so}");
    let (ok, so, e) = lrd(&["bench", "--size", "100x70", "--runs", "5", &data("room_7.exr"), "--guides", "normal,depth"]);
    assert!(ok && so.contains("median"), "{e}");
    let outdir = tmp("seq");
    let (ok, so, e) = lrd(&["denoise-seq", &data("seq_box_7"), "-o", outdir.to_str().unwrap()]);
    assert!(ok, "{e}");
    assert!(so.contains("6 frames"), "{so}");
    assert!(outdir.join("frame_0005.exr").exists());
}

#[test]
fn mismatched_layer_sizes_are_named() {
    use exr::prelude::*;
    let part = |name: &str, w: usize, h: usize| {
        let chans = AnyChannels::sort(smallvec::smallvec![
            AnyChannel::new("R", FlatSamples::F32(vec![0.5; w * h])),
            AnyChannel::new("G", FlatSamples::F32(vec![0.5; w * h])),
            AnyChannel::new("B", FlatSamples::F32(vec![0.5; w * h])),
        ]);
        Layer::new((w, h), LayerAttributes::named(name), Encoding::UNCOMPRESSED, chans)
    };
    let img = Image::from_layers(
        ImageAttributes::new(IntegerBounds::from_dimensions((16, 16))),
        smallvec::smallvec![part("noisy", 16, 16), part("albedo", 8, 16)],
    );
    let path = tmp("mismatch.exr");
    img.write().to_file(&path).unwrap();
    fails_with(
        &["denoise", path.to_str().unwrap(), "-o", tmp("m_out.exr").to_str().unwrap(), "--guides", "none"],
        &["mismatch.exr", "different sizes"],
    );
    // a frame without albedo, asked to use it as a guide
    let img =
        Image::from_layers(ImageAttributes::new(IntegerBounds::from_dimensions((16, 16))), smallvec::smallvec![part("noisy", 16, 16)]);
    let path = tmp("noalbedo.exr");
    img.write().to_file(&path).unwrap();
    fails_with(&["denoise", path.to_str().unwrap(), "-o", tmp("a_out.exr").to_str().unwrap(), "--guides", "albedo"], &["'albedo'"]);
}

#[test]
fn bmfr_single_frame_temporal_and_flicker() {
    let json = tmp("bmfr.json");
    let seq = data("seq_box_7");
    let (ok, so, e) = lrd(&["eval", &seq, "--methods", "flr,bmfr,bmfr-temporal", "--runs", "5", "--json", json.to_str().unwrap()]);
    assert!(ok, "{e}");
    assert!(so.contains("flicker") && so.contains("bmfr-temporal NP b32"), "{so}");
    let recs: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let recs = recs.as_array().unwrap();
    let get = |method: &str, frame: &str| recs.iter().find(|r| r["method"] == method && r["frame"] == frame).unwrap().clone();
    for m in ["noisy", "flr", "bmfr", "bmfr-temporal"] {
        assert!(get(m, "frame_0000")["flicker"].is_null(), "no previous frame, no flicker");
        for f in 1..6 {
            let r = get(m, &format!("frame_{f:04}"));
            assert!(r["psnr"].as_f64().unwrap().is_finite());
            assert!(r["flicker"].as_f64().is_some(), "{m} frame {f}: {r}");
        }
    }
    let fl = |m: &str| get(m, "frame_0005")["flicker"].as_f64().unwrap();
    assert!(fl("bmfr") < 0.5 * fl("noisy") && fl("bmfr-temporal") < 0.5 * fl("noisy"));
    // the temporal pipeline improves along the sequence
    let ps = |m: &str, f: &str| get(m, f)["psnr"].as_f64().unwrap();
    assert!(ps("bmfr-temporal", "frame_0005") > ps("bmfr-temporal", "frame_0000"));

    let outdir = tmp("seq-bmfr");
    let (ok, so, e) = lrd(&["denoise-seq", &seq, "-o", outdir.to_str().unwrap(), "--method", "bmfr"]);
    assert!(ok, "{e}");
    assert!(so.contains("bmfr-temporal") && so.contains("6 frames"), "{so}");
    let (ok, so, e) = lrd(&["bench", "--method", "bmfr-temporal", "--size", "128x96", "--runs", "5"]);
    assert!(ok && so.contains("median"), "{e}");
    // a temporal pipeline's baseline counts its history, read and written
    assert!(so.contains("memcpy") && so.contains("the history read and written"), "{so}");
    let (ok, so, e) = lrd(&["bench", "--method", "bmfr", "--size", "128x96", "--runs", "5", "--threads", "2"]);
    assert!(ok && so.contains("median"), "{e}");
    // normal + position: 12 f32 × 128 × 96
    assert!(so.contains("memcpy of the 0.6 MB"), "{so}");
    fails_with(
        &["denoise", &data("room_7.exr"), "-o", tmp("x.exr").to_str().unwrap(), "--method", "bmfr", "--sigma", "3"],
        &["--sigma is an FLR flag", "bmfr takes --guides, --block, --shrinkage"],
    );
    fails_with(&["denoise", &data("room_7.exr"), "-o", tmp("x.exr").to_str().unwrap(), "--method", "bmfr", "--block", "4"], &["block"]);
    // the shared stage's history length, in the label and the flag line
    let (ok, so, e) = lrd(&["eval", &seq, "--methods", "bmfr-temporal", "--history", "4", "--runs", "1"]);
    assert!(ok && so.contains("bmfr-temporal NP b32 h4") && so.contains("--history 4"), "{e}{so}");
    fails_with(&["denoise-seq", &seq, "-o", outdir.to_str().unwrap(), "--method", "bmfr", "--history", "0.5"], &["max_history"]);
}

/// Temporal FLR on cell moments: `--lag-sigmas` in its label and flag line,
/// refused without `--accumulate moments` and out of range; the light
/// pipeline's flags refused with it.
#[test]
fn temporal_moments_flags() {
    let seq = data("seq_box_7");
    let (ok, so, e) = lrd(&["eval", &seq, "--methods", "flr-temporal", "--accumulate", "moments", "--lag-sigmas", "0", "--runs", "1"]);
    assert!(ok && so.contains("temporal moments l0") && so.contains("--lag-sigmas 0 --accumulate moments"), "{e}{so}");
    let x = tmp("seq-moments");
    let x = x.to_str().unwrap();
    fails_with(&["denoise-seq", &seq, "-o", x, "--method", "flr", "--lag-sigmas", "2"], &["--lag-sigmas is the moments' lag test"]);
    fails_with(&["denoise-seq", &seq, "-o", x, "--method", "flr", "--accumulate", "moments", "--lag-sigmas=-1"], &["lag_sigmas"]);
    fails_with(
        &["denoise-seq", &seq, "-o", x, "--method", "flr", "--accumulate", "moments", "--output-alpha", "1"],
        &["does not take --output-alpha"],
    );
    fails_with(&["denoise-seq", &seq, "-o", x, "--method", "bmfr", "--lag-sigmas", "2"], &["--lag-sigmas is an FLR flag"]);
}

#[test]
fn walr_single_frame_temporal_flags_and_errors() {
    let json = tmp("walr.json");
    let seq = data("seq_box_7");
    let (ok, so, e) = lrd(&["eval", &seq, "--methods", "walr,walr-temporal", "--runs", "5", "--json", json.to_str().unwrap()]);
    assert!(ok, "{e}");
    // the default blends the last two windows adaptively
    assert!(so.contains("walr-temporal NDP t4 pw-adaptive f32"), "{so}");
    let recs: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let recs = recs.as_array().unwrap();
    let get = |method: &str, frame: &str| recs.iter().find(|r| r["method"] == method && r["frame"] == frame).unwrap().clone();
    let fl = |m: &str| get(m, "frame_0005")["flicker"].as_f64().unwrap();
    assert!(fl("walr-temporal") < fl("walr") && fl("walr") < 0.5 * fl("noisy"));
    for f in 0..6 {
        assert!(get("walr", &format!("frame_{f:04}"))["psnr"].as_f64().unwrap() > 25.0);
    }
    let outdir = tmp("seq-walr");
    let (ok, so, e) = lrd(&["denoise-seq", &seq, "-o", outdir.to_str().unwrap(), "--method", "walr", "--iterations", "3"]);
    assert!(ok, "{e}");
    assert!(so.contains("walr-temporal") && so.contains("6 frames"), "{so}");
    let (ok, so, e) = lrd(&["bench", "--method", "walr", "--size", "128x96", "--runs", "5", "--threads", "2"]);
    assert!(ok && so.contains("median"), "{e}");
    let room = data("room_7.exr");
    let x = tmp("w.exr");
    let x = x.to_str().unwrap();
    fails_with(&["denoise", &room, "-o", x, "--method", "walr", "--block", "8"], &["--block is an FLR and BMFR flag, not one of WALR's"]);
    fails_with(&["denoise", &room, "-o", x, "--method", "flr", "--iterations", "3"], &["--iterations is a WALR flag"]);
    fails_with(&["denoise", &room, "-o", x, "--method", "flr", "--iterations", "3", "--storage", "f16"], &["(so is --storage)"]);
    fails_with(&["denoise", &room, "-o", x, "--method", "walr", "--guides", "normal,depth"], &["normal and position"]);
    fails_with(&["denoise", &room, "-o", x, "--method", "walr", "--storage", "f8"], &["f16 or f32"]);
    fails_with(&["denoise", &room, "-o", x, "--method", "walr", "--near", "0.5", "--far", "0.1"], &["near/far"]);
    fails_with(&["denoise", &room, "-o", x, "--method", "walr", "--previous-weight", "1.5"], &["previous_weight"]);
    fails_with(
        &["denoise", &room, "-o", x, "--method", "walr", "--previous-weight", "auto"],
        &["'auto' is not a number in 0..=1 or 'adaptive'"],
    );
    // a fixed blend
    let (ok, so, e) = lrd(&["eval", &room, "--methods", "walr", "--previous-weight", "0.6", "--runs", "5"]);
    assert!(ok && so.contains("walr NDP t4 pw0.6 f32"), "{e}{so}");
    fails_with(&["denoise", &room, "-o", x, "--method", "bmfr", "--previous-weight", "0.5"], &["--previous-weight is a WALR flag"]);
    // one window (the paper's): no pw in the label
    let (ok, so, e) = lrd(&["eval", &room, "--methods", "walr", "--previous-weight", "0", "--runs", "5"]);
    assert!(ok && so.contains("walr NDP t4 f32") && !so.contains("pw"), "{e}{so}");
}

#[test]
fn flnr_runs_with_bundled_and_given_weights() {
    let room = data("room_7.exr");
    let (ok, so, e) = lrd(&["eval", &room, "--methods", "flr,flnr", "--runs", "5", "--threads", "1"]);
    assert!(ok, "{e}");
    assert!(so.contains("flnr["), "{so}");
    let x = tmp("f.exr");
    let x = x.to_str().unwrap();
    fails_with(&["denoise", &room, "-o", x, "--method", "flnr", "--sigma", "3"], &["--sigma is an FLR flag", "flnr takes --weights"]);
    fails_with(&["denoise", &room, "-o", x, "--weights", "w.bin"], &["--weights is an FLNR flag", "flr takes --guides"]);
    let bad = tmp("bad.bin");
    std::fs::write(&bad, b"not a network").unwrap();
    fails_with(&["denoise", &room, "-o", x, "--method", "flnr", "--weights", bad.to_str().unwrap()], &["bad magic"]);
    fails_with(&["denoise", &room, "-o", x, "--method", "flnr", "--weights", "/nonexistent.bin"], &["--weights"]);
}

#[test]
fn device_flag_and_shaders() {
    fails_with(&["denoise", &data("room_7.exr"), "-o", "x.exr", "--device", "tpu"], &["--device", "tpu"]);
    fails_with(
        &["denoise", &data("room_7.exr"), "-o", "x.exr", "--device", "gpu", "--method", "bmfr"],
        &["only flr and flr-temporal run on the GPU"],
    );
    // shaders and dispatch description (no adapter needed)
    let dir = tmp("shaders");
    let (ok, _, e) = lrd(&["shaders", "--out", dir.to_str().unwrap(), "--size", "640x360", "--guides", "normal,depth"]);
    assert!(ok, "{e}");
    let spv = std::fs::read(dir.join("flr.spv")).unwrap();
    assert_eq!(&spv[..4], &0x0723_0203u32.to_le_bytes());
    assert_eq!(std::fs::metadata(dir.join("params.bin")).unwrap().len(), lrdenoise::flr::gpu::PARAMS_BYTES as u64);
    let md = std::fs::read_to_string(dir.join("dispatch.md")).unwrap();
    assert!(md.contains("640x360") && md.contains("| `moments` | 80 x 45 x 1 |") && md.contains("(4 guide channels)"), "{md}");
    let dir16 = tmp("shaders16");
    let (ok, _, e) = lrd(&["shaders", "--out", dir16.to_str().unwrap(), "--f16-inputs"]);
    assert!(ok, "{e}");
    let md = std::fs::read_to_string(dir16.join("dispatch.md")).unwrap();
    assert!(md.contains("F16 inputs"));
    // temporal FLR's own FLR dispatch: its clamp off and f32 inputs, whatever the single-frame one has
    use lrdenoise::flr::gpu::{GpuLayouts, GpuPlan, InputFormat};
    use lrdenoise::FlrConfig;
    let plan = GpuPlan::new(FlrConfig { fireflies: None, ..FlrConfig::temporal() }, 1920, 1080).unwrap();
    let params = plan.params(&GpuLayouts::planar(1920, 1080, InputFormat::F32)).unwrap();
    let temporal_flr = std::fs::read(dir16.join("temporal_flr_params.bin")).unwrap();
    assert_eq!(temporal_flr, params.as_bytes());
    assert_ne!(temporal_flr, std::fs::read(dir16.join("params.bin")).unwrap());
    let temporal_part = md.split("## Temporal FLR").nth(1).unwrap();
    // FLR's noisy buffer (binding 1) holds f32 light there
    assert!(temporal_part.contains(&format!("| 1 | Noisy | ReadOnlyStorage | {} |", 3 * 1920 * 1080 * 4)), "{temporal_part}");
    assert!(temporal_part.contains("| temporal | `t_resolve` |") && temporal_part.contains("| flr | `moments` |"), "{temporal_part}");
    for f in ["temporal_params_first.bin", "temporal_params.bin"] {
        assert_eq!(std::fs::metadata(dir16.join(f)).unwrap().len(), 112, "{f}");
    }
    let dira = tmp("shaders_adaptive");
    let (ok, _, e) = lrd(&["shaders", "--out", dira.to_str().unwrap(), "--size", "640x360", "--sigma", "6,12,20"]);
    assert!(ok, "{e}");
    let md = std::fs::read_to_string(dira.join("dispatch.md")).unwrap();
    assert!(md.contains("| `pool` |") && md.contains("| `solve_2` |") && md.contains("| `blend` | 2 x 45 x 1 |"), "{md}");
    for f in ["flr.wgsl", "flr.metal", "flr.hlsl"] {
        assert!(std::fs::read_to_string(dir.join(f)).unwrap().contains("apply"), "{f}");
    }
}

/// `--device gpu` against the CPU on every bundled frame. Ignored by default;
/// `.ci/run` installs Mesa's lavapipe and runs it with `--ignored`, where a
/// missing adapter fails it.
#[test]
#[ignore = "needs a wgpu adapter (a GPU, or Mesa's lavapipe: mesa-vulkan-drivers) (run with --ignored; CI does)"]
fn gpu_device_matches_cpu() {
    use lrdenoise_cli::exrio::ExrFrame;
    // every bundled frame: the GPU's output equals the CPU's within f32 rounding
    let rel_diff = |a: &[f32], b: &[f32]| -> f64 {
        let scale = a.iter().map(|v| v.abs() as f64).sum::<f64>() / a.len() as f64;
        a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64).sum::<f64>() / a.len() as f64 / scale
    };
    let denoised = |p: &Path| -> Vec<f32> {
        let f = ExrFrame::read(p).unwrap();
        f.layers["denoised"].planes.concat()
    };
    for name in ["room_7.exr", "poles_7.exr", "colonnade_7.exr", "farclutter_7.exr"] {
        let (cpu, gpu) = (tmp(&format!("cpu_{name}")), tmp(&format!("gpu_{name}")));
        let (ok, _, e) = lrd(&["denoise", &data(name), "-o", cpu.to_str().unwrap(), "--only-output"]);
        assert!(ok, "{e}");
        let (ok, so, e) = lrd(&["denoise", &data(name), "-o", gpu.to_str().unwrap(), "--only-output", "--device", "gpu"]);
        assert!(ok && so.contains("gpu"), "{e}");
        let mean = rel_diff(&denoised(&cpu), &denoised(&gpu));
        assert!(mean < 1e-4, "{name}: mean relative difference {mean:.2e}");
    }
    // joint upsampling on the GPU: the same as on the CPU
    let (cpu, gpu) = (tmp("cpu_up.exr"), tmp("gpu_up.exr"));
    let room = data("room_7.exr");
    assert!(lrd(&["denoise", &room, "-o", cpu.to_str().unwrap(), "--only-output", "--upsample", "2"]).0);
    assert!(lrd(&["denoise", &room, "-o", gpu.to_str().unwrap(), "--only-output", "--upsample", "2", "--device", "gpu"]).0);
    let mean = rel_diff(&denoised(&cpu), &denoised(&gpu));
    assert!(mean < 1e-4, "upsample 2: mean relative difference {mean:.2e}");
    // the adaptive window on the GPU: the same as on the CPU
    let (cpu, gpu) = (tmp("cpu_adaptive.exr"), tmp("gpu_adaptive.exr"));
    assert!(lrd(&["denoise", &room, "-o", cpu.to_str().unwrap(), "--only-output", "--sigma", "6,12,20"]).0);
    assert!(lrd(&["denoise", &room, "-o", gpu.to_str().unwrap(), "--only-output", "--sigma", "6,12,20", "--device", "gpu"]).0);
    let mean = rel_diff(&denoised(&cpu), &denoised(&gpu));
    assert!(mean < 1e-4, "adaptive: mean relative difference {mean:.2e}");
    let (ok, so, e) = lrd(&["bench", "--device", "gpu", "--size", "64x48", "--runs", "5"]);
    assert!(ok && so.contains("GPU adapter") && so.contains("median") && so.contains("GPU time"), "{so}{e}");
    // temporal FLR on the GPU: each frame of a sequence as on the CPU, both
    // rejecting by position (FLR fitted with it, or without it: then the
    // positions are the stage's alone)
    let seq = data("seq_box_7");
    let g = ["--guides", "normal,depth,position,ao"];
    for (tag, guides) in [("fit", &g[..]), ("reject", &[][..])] {
        let (cpu, gpu) = (tmp(&format!("seq_cpu_{tag}")), tmp(&format!("seq_gpu_{tag}")));
        assert!(lrd(&[&["denoise-seq", &seq, "-o", cpu.to_str().unwrap()][..], guides].concat()).0);
        let (ok, so, e) = lrd(&[&["denoise-seq", &seq, "-o", gpu.to_str().unwrap(), "--device", "gpu"][..], guides].concat());
        assert!(ok && so.contains("6 frames"), "{so}{e}");
        for i in 0..6 {
            let name = format!("frame_{i:04}.exr");
            let mean = rel_diff(&denoised(&cpu.join(&name)), &denoised(&gpu.join(&name)));
            assert!(mean < 2e-4, "temporal ({tag}) {name}: mean relative difference {mean:.2e}");
        }
    }
    // `eval` repeats each frame (--runs) from the saved history: the GPU's table is the CPU's
    let table = |dev: &str| {
        let (ok, so, e) = lrd(&[&["eval", &seq, "--methods", "flr-temporal", "--runs", "3", "--device", dev][..], &g].concat());
        assert!(ok, "{e}");
        so.lines().filter(|l| l.starts_with("| seq_box_7")).map(|l| l.replace(" gpu |", " |")).collect::<Vec<_>>()
    };
    let cpu_rows = table("cpu");
    assert!(!cpu_rows.is_empty());
    assert_eq!(cpu_rows, table("gpu"));
    let (ok, so, e) = lrd(&["bench", "--method", "flr-temporal", "--device", "gpu", "--size", "64x48", "--runs", "5"]);
    // the synthetic frame has positions: the GPU judges history by them, as the CPU does
    assert!(ok && so.contains("GPU adapter") && so.contains("temporal rp gpu") && so.contains("median"), "{so}{e}");
}

/// `--sigma 6,12,20` is the adaptive window, and the default: labelled,
/// better than the single window (`--sigma 12`) on room_7 (+0.56 dB
/// measured), the same on 1 and 2 threads; `--radius` alone means the single
/// window; wrong counts and `--radius` with three sigmas are refused with a
/// one-line reason.
#[test]
fn adaptive_window_flag() {
    let room = data("room_7.exr");
    let json = tmp("adaptive.json");
    let psnr = |args: &[&str]| {
        let mut a = vec!["eval", &room, "--json", json.to_str().unwrap(), "--runs", "3"];
        a.extend_from_slice(args);
        let (ok, _, e) = lrd(&a);
        assert!(ok, "{e}");
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let r = v.as_array().unwrap().iter().find(|r| r["method"] == "flr").unwrap().clone();
        (r["config"].as_str().unwrap().to_string(), r["psnr"].as_f64().unwrap())
    };
    let (label, one) = psnr(&["--threads", "1", "--sigma", "6,12,20"]);
    assert!(label.contains("s6/12/20"), "{label}");
    let (_, two) = psnr(&["--threads", "2", "--sigma", "6,12,20"]);
    assert_eq!(one, two, "threads change the result");
    let (label_single, single) = psnr(&["--threads", "1", "--sigma", "12"]);
    assert!(label_single.contains("s12") && !label_single.contains('/'), "{label_single}");
    assert!(one > single + 0.2, "adaptive {one} vs single {single}");
    let (label_default, default) = psnr(&["--threads", "1"]);
    assert_eq!((label_default.as_str(), default), (label.as_str(), one), "the default is the adaptive window");
    let (label_radius, _) = psnr(&["--threads", "1", "--radius", "30"]);
    assert!(label_radius.contains("s12") && !label_radius.contains("s6/12/20"), "{label_radius}");
    let out = tmp("adaptive.exr");
    let o = out.to_str().unwrap();
    fails_with(&["denoise", &room, "-o", o, "--sigma", "6,12"], &["three increasing"]);
    fails_with(&["denoise", &room, "-o", o, "--sigma", "6,x,20"], &["'x' is not a number"]);
    fails_with(&["denoise", &room, "-o", o, "--sigma", "12,6,20"], &["increasing"]);
    fails_with(&["denoise", &room, "-o", o, "--sigma", "6,12,20", "--radius", "30"], &["--radius applies to a single"]);
}

/// WALR without depth measures plane distances against the positions' spread:
/// on farclutter_7 it scores within 0.3 dB of WALR with depth (it scored
/// 15.8 dB against 28.5 when the thresholds fell back to world units).
#[test]
fn walr_without_depth_is_unit_free() {
    let json = tmp("walr_nodepth.json");
    let psnr = |guides: &str| {
        let args =
            ["eval", &data("farclutter_7.exr"), "--methods", "walr", "--guides", guides, "--json", json.to_str().unwrap(), "--runs", "1"];
        let (ok, _, e) = lrd(&args);
        assert!(ok, "{e}");
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        v.as_array().unwrap().iter().find(|r| r["method"] == "walr").unwrap()["psnr"].as_f64().unwrap()
    };
    let (with, without) = (psnr("normal,depth,position"), psnr("normal,position"));
    assert!((with - without).abs() < 0.3, "with depth {with}, without {without}");
}

/// Output into a closed pipe (`lrd bench | head -1`) ends lrd quietly: by
/// SIGPIPE (status 141 in a shell) or with status 0, never with a panic.
#[cfg(unix)]
#[test]
fn closed_stdout_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    for args in [&["bench", "--size", "320x200", "--runs", "5"][..], &["--help"][..]] {
        let mut child =
            Command::new(env!("CARGO_BIN_EXE_lrd")).args(args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("run lrd");
        drop(child.stdout.take()); // the reader goes away before lrd writes
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success() || o.status.signal() == Some(13) || o.status.code() == Some(141), "{args:?}: {:?} {err}", o.status);
        assert!(!err.contains("internal error") && !err.contains("panicked") && !err.contains("Broken pipe"), "{args:?}: {err}");
    }
}

/// `lrd report` on one frame: the tables with the legend of configuration
/// names, the plot, and a strip of the main configurations (noisy, the best of
/// each method, reference: at most 8 panels); `--full-strips` shows them all.
/// The robustness section, with the injected stills and their records.
#[test]
fn report_writes_legend_plot_and_capped_strips() {
    let dir = tmp("report");
    let (ok, so, e) = lrd(&["report", &data("room_7.exr"), "-o", dir.to_str().unwrap(), "--runs", "5"]);
    assert!(ok, "{e}");
    assert!(so.contains("report.md"), "{so}");
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("Configuration names") && md.contains("`-aod`") && md.contains("`kK`"), "{md}");
    for f in ["plot.png", "plot.svg", "records.json", "strip_room_7.png"] {
        assert!(std::fs::metadata(dir.join(f)).unwrap().len() > 1000, "{f}");
    }
    // the robustness table: a row per method at its defaults and FLR without
    // its firefly clamp, a column per case and a drop per injected case; the
    // injected stills and every record beside it
    let rob = &md[md.find("## Robustness (outliers injected into the noisy input)").expect("robustness section")..];
    let rows: Vec<&str> = rob.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| config")).collect();
    assert_eq!(rows.len(), 5, "{rob}");
    assert!(rows[1].contains(" -ff ") && rows.iter().any(|r| r.starts_with("| flnr")), "{rob}");
    assert!(rows.iter().all(|r| r.matches('|').count() == 9 && !r.contains('–')), "{rob}");
    assert!(rob.contains("tools/peers.py") && rob.contains("--inject-name"), "{rob}");
    for case in ["ff1e-4x1000", "ff1e-3x100", "nan-inf1e-3"] {
        assert!(dir.join("robustness").join(case).join("room_7.exr").exists(), "{case}");
    }
    let recs: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("robustness.json")).unwrap()).unwrap();
    assert_eq!(recs.as_array().unwrap().len(), 5 * 4);
    // an injected frame on disk (noisy layer in f32) scores as the injection in memory
    let ff = dir.join("robustness/ff1e-3x100/room_7.exr");
    let evj = tmp("report_ff.json");
    let (ok, _, e) = lrd(&["eval", ff.to_str().unwrap(), "--runs", "5", "--json", evj.to_str().unwrap()]);
    assert!(ok, "{e}");
    let ev: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&evj).unwrap()).unwrap();
    let in_memory = recs.as_array().unwrap().iter().find(|r| r["inject"] == "ff1e-3x100" && r["method"] == "flr").unwrap();
    let diff = (ev[1]["psnr"].as_f64().unwrap() - in_memory["psnr"].as_f64().unwrap()).abs();
    assert!(diff < 1e-9, "{} vs {in_memory}", ev[1]);
    let strip = image::image_dimensions(dir.join("strip_room_7.png")).unwrap();
    // noisy, the best of each of the 7 methods, the reference
    assert!(strip.0 <= 9 * 256 && strip.0 >= 4 * 256, "{strip:?}");
    let full = tmp("report_full");
    let (ok, _, e) = lrd(&["report", &data("room_7.exr"), "-o", full.to_str().unwrap(), "--runs", "5", "--full-strips"]);
    assert!(ok, "{e}");
    assert!(image::image_dimensions(full.join("strip_room_7.png")).unwrap().0 > 16 * 256);
}

/// `lrd eval --inject`: the records name their case; `--inject all` runs the
/// four cases of the robustness protocol and prints their table.
#[test]
fn eval_injects_outliers() {
    let room = data("room_7.exr");
    let json = tmp("inject.json");
    let j = json.to_str().unwrap();
    let (ok, _, e) = lrd(&["eval", "--inject", "fireflies:1e-3:100", &room, "--runs", "5", "--threads", "1", "--json", j]);
    assert!(ok, "{e}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let recs = v.as_array().unwrap();
    assert_eq!(recs.len(), 2);
    assert!(recs.iter().all(|r| r["inject"] == "ff1e-3x100"), "{v}");
    let injected_flr = recs[1]["psnr"].as_f64().unwrap();
    let (ok, so, e) = lrd(&["eval", "--inject", "all", &room, "--methods", "flr,bmfr", "--runs", "5", "--threads", "1", "--json", j]);
    assert!(ok, "{e}");
    assert!(so.contains("| config | clean | 0.01 % × 1000 | 0.1 % × 100 |") && so.contains("drop, 0.1 % × 100"), "{so}");
    assert!(so.lines().any(|l| l.starts_with("| flr ")) && so.lines().any(|l| l.starts_with("| bmfr ")), "{so}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let cases: Vec<&str> = v.as_array().unwrap().iter().map(|r| r["inject"].as_str().unwrap()).collect();
    assert_eq!(cases.len(), 3 * 4); // (noisy, flr, bmfr) x 4 cases
    for c in ["clean", "ff1e-4x1000", "ff1e-3x100", "nan-inf1e-3"] {
        assert_eq!(cases.iter().filter(|x| **x == c).count(), 3, "{c}");
    }
    let flr_ff = v.as_array().unwrap().iter().find(|r| r["method"] == "flr" && r["inject"] == "ff1e-3x100").unwrap();
    assert_eq!(flr_ff["psnr"].as_f64().unwrap(), injected_flr);
    fails_with(&["eval", &room, "--inject", "most"], &["--inject", "all"]);
}

/// The firefly clamp, on by default, leaves clean frames alone: on the four
/// bundled stills no method's mean PSNR is more than 0.05 dB below
/// `--fireflies off` (BMFR gains about as much: its blocks spread a clean
/// frame's brightest samples too), while 0.01 % of the pixels at 1000× the mean cost the
/// clamped defaults at most 0.3 dB.
#[test]
fn firefly_clamp_leaves_clean_frames_alone() {
    let stills: Vec<String> = ["colonnade_7.exr", "farclutter_7.exr", "poles_7.exr", "room_7.exr"].iter().map(|f| data(f)).collect();
    let mean_psnr = |method: &str, extra: &[&str], tag: &str| -> f64 {
        let json = tmp(&format!("ff_{method}_{tag}.json"));
        let mut args: Vec<&str> = vec!["eval"];
        args.extend(stills.iter().map(String::as_str));
        args.extend(["--methods", method, "--runs", "5", "--threads", "1", "--json", json.to_str().unwrap()]);
        args.extend(extra);
        let (ok, _, e) = lrd(&args);
        assert!(ok, "{e}");
        let recs: Vec<serde_json::Value> = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let ps: Vec<f64> = recs.iter().filter(|r| r["method"] == method).map(|r| r["psnr"].as_f64().unwrap()).collect();
        assert_eq!(ps.len(), 4);
        ps.iter().sum::<f64>() / 4.0
    };
    for method in ["flr", "bmfr", "walr"] {
        let on = mean_psnr(method, &[], "on");
        let off = mean_psnr(method, &["--fireflies", "off"], "off");
        assert!(on >= off - 0.05, "{method}: {on:.3} dB with the clamp, {off:.3} without");
        let hot = mean_psnr(method, &["--inject", "fireflies:1e-4:1000"], "hot");
        assert!(on - hot <= 0.3, "{method}: 0.01 % x 1000 costs {:.3} dB", on - hot);
    }
}
