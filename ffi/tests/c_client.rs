//! Builds the C client (`ffi/examples/client.c`) against the static library with
//! `gcc -std=c99 -Wall -Wextra -Werror`, runs it, checks the header also
//! compiles as C++17, and compares the client's output with the Rust API's.
//! The same run under valgrind memcheck is `#[ignore]`d (it needs valgrind and
//! takes minutes): `cargo test -p lrdenoise-ffi -- --ignored` runs it, as CI does.

use lrdenoise_core::{Flr, FlrConfig, Frame, Guides, ImageView, ImageViewMut};
use std::path::PathBuf;
use std::process::Command;

const W: usize = 333;
const H: usize = 217;

fn hash01(mut x: u32) -> f32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846ca68b);
    x ^= x >> 16;
    (x >> 8) as f32 / 16777216.0
}

/// Mirrors synthetic() in client.c.
fn synthetic() -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
    let (mut noisy, mut normal, mut depth, mut ao) = (vec![0f32; 3 * W * H], vec![0f32; 3 * W * H], vec![0f32; W * H], vec![0f32; W * H]);
    for y in 0..H as u32 {
        for x in 0..W as u32 {
            let i = (y * W as u32 + x) as usize;
            let region = (x > W as u32 / 3) as u32 + 2 * (y > H as u32 / 2) as u32;
            normal[3 * i] = if region == 1 { 1.0 } else { 0.0 };
            normal[3 * i + 1] = if region == 0 { 1.0 } else { 0.0 };
            normal[3 * i + 2] = if region >= 2 { 1.0 } else { 0.0 };
            depth[i] = 2.0 + 0.01 * y as f32 + region as f32;
            ao[i] = 0.5 + 0.5 * hash01(i as u32 / 7);
            for c in 0..3u32 {
                let clean = (0.2 + 0.1 * c as f32 + 0.05 * region as f32) * ao[i];
                noisy[3 * i + c as usize] = clean * 2.0 * hash01(i as u32 * 3 + c + 12345);
            }
        }
    }
    (noisy, normal, depth, ao)
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn c_client_matches_rust() {
    run_client(false);
}

#[test]
#[ignore = "needs valgrind (memcheck); run with --ignored, CI does"]
fn c_client_under_valgrind() {
    run_client(true);
}

fn run_client(memcheck: bool) {
    let profile = if cfg!(debug_assertions) { "debug" } else { "release" };
    let mut build = Command::new(env!("CARGO"));
    build.current_dir(root()).args(["build", "-p", "lrdenoise-ffi"]);
    if profile == "release" {
        build.arg("--release");
    }
    assert!(build.status().unwrap().success(), "building liblrdenoise.a failed");
    let target = std::env::var("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|_| root().join("target"));
    let lib = target.join(profile).join("liblrdenoise.a");
    assert!(lib.exists(), "{} missing", lib.display());
    let dir = std::env::temp_dir().join(format!("lrd-c-{}-{memcheck}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exe = dir.join("client");
    let inc = root().join("ffi/include");
    let st = Command::new("gcc")
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", "-I"])
        .arg(&inc)
        .arg(root().join("ffi/examples/client.c"))
        .arg(&lib)
        .args(["-lpthread", "-lm", "-ldl", "-o"])
        .arg(&exe)
        .status()
        .unwrap();
    assert!(st.success(), "gcc failed");
    // The header as C++17.
    let cpp = dir.join("h.cpp");
    std::fs::write(&cpp, "#include \"lrdenoise.h\"\nint main() { LrdFlrConfig c = lrd_flr_config_default(); return (int)c.block - 8; }\n")
        .unwrap();
    let st = Command::new("g++")
        .args(["-std=c++17", "-Wall", "-Wextra", "-Werror", "-fsyntax-only", "-I"])
        .arg(&inc)
        .arg(&cpp)
        .status()
        .unwrap();
    assert!(st.success(), "header does not compile as C++17");

    let raw = dir.join("out.raw");
    let blob = root().join("train/flnr.bin");
    let out = if memcheck {
        assert!(Command::new("valgrind").arg("--version").output().is_ok(), "valgrind is not installed");
        Command::new("valgrind")
            .args(["--error-exitcode=3", "--leak-check=full", "--errors-for-leak-kinds=definite", "-q"])
            .arg(&exe)
            .arg(&raw)
            .arg(&blob)
            .output()
            .unwrap()
    } else {
        Command::new(&exe).arg(&raw).arg(&blob).output().unwrap()
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "client failed ({:?}): {stdout}{}", out.status, String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("identical"), "{stdout}");
    assert!(stdout.contains("FLNR") && stdout.contains("tiles in stages: identical"), "{stdout}");
    // the GPU pass list, in order (the reference pass's size depends on the firefly clamp)
    let passes = stdout.find("passes: reference ").and_then(|i| stdout[i..].find(" moments ").map(|j| i + j));
    assert!(passes.is_some() && stdout.contains("apply"), "{stdout}");
    println!("{stdout}");

    let bytes = std::fs::read(&raw).unwrap();
    let c_out: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    let (noisy, normal, depth, ao) = synthetic();
    let flr = Flr::new(FlrConfig::default(), W, H).unwrap();
    let mut scratch = vec![0f64; flr.scratch_len()];
    let mut rust = vec![0f32; 3 * W * H];
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, W, H, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, W, H, 1).unwrap()),
        ao: Some(ImageView::interleaved(&ao, W, H, 1).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, W, H, 3).unwrap(), guides);
    flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut rust, W, H, 3).unwrap()).unwrap();
    assert_eq!(c_out.len(), rust.len());
    // Same code, but compiled in two crates: allow last-bit differences.
    let max = c_out.iter().zip(&rust).map(|(a, b)| (a - b).abs() / (b.abs() + 1e-3)).fold(0f32, f32::max);
    assert!(max < 1e-5, "C and Rust outputs differ: {max}");
}
