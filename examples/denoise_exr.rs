//! Denoises one frame stored as a multi-layer EXR with FLR and writes the
//! result as an RGB EXR.
//!
//! ```sh
//! cargo run --release --example denoise_exr                       # data/room_7.exr -> target/denoised.exr
//! cargo run --release --example denoise_exr -- IN.exr OUT.exr
//! ```
//!
//! The input has the repository's layout (`docs/DATA.md`): channels named
//! `layer.component`, the light to denoise in `noisy.R/G/B` and the guides in
//! `normal.X/Y/Z`, `depth.Z` and `ao.Y`. FLR uses whichever of those guides
//! the file has. The output is the denoised `noisy` quantity (albedo-demodulated
//! light): multiply it by `albedo` to get radiance.

use lrdenoise::{Flr, FlrConfig, Frame, GuideSet, Guides, ImageView, ImageViewMut};
use std::collections::BTreeMap;
use std::process::ExitCode;
use std::time::Instant;

/// A frame read from an EXR file: its size and every channel (`"noisy.R"`, ...)
/// as a plane of f32.
struct Exr {
    width: usize,
    height: usize,
    channels: BTreeMap<String, Vec<f32>>,
}

impl Exr {
    fn read(path: &str) -> Result<Exr, String> {
        let image = exr::prelude::read_all_flat_layers_from_file(path).map_err(|e| format!("{path}: {e}"))?;
        let mut frame = Exr { width: 0, height: 0, channels: BTreeMap::new() };
        for part in &image.layer_data {
            (frame.width, frame.height) = (part.size.0, part.size.1);
            for ch in &part.channel_data.list {
                // a multi-part file names the layer in the part, a single-part one in the channel
                let name = match &part.attributes.layer_name {
                    Some(layer) => format!("{layer}.{}", ch.name),
                    None => ch.name.to_string(),
                };
                frame.channels.insert(name, ch.sample_data.values_as_f32().collect());
            }
        }
        Ok(frame)
    }

    /// The layer's components interleaved (`xyzxyz...`), or `None` if the file lacks one of them.
    fn layer(&self, layer: &str, components: &[&str]) -> Option<Vec<f32>> {
        let planes: Vec<&Vec<f32>> = components.iter().map(|c| self.channels.get(&format!("{layer}.{c}"))).collect::<Option<_>>()?;
        Some((0..self.width * self.height).flat_map(|i| planes.iter().map(move |p| p[i])).collect())
    }
}

/// An interleaved `channels`-channel view of a layer the file may lack.
fn view(w: usize, h: usize, data: &Option<Vec<f32>>, channels: usize) -> Result<Option<ImageView<'_>>, lrdenoise::Error> {
    data.as_deref().map(|d| ImageView::interleaved(d, w, h, channels)).transpose()
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("denoise_exr: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let input = args.next().unwrap_or_else(|| concat!(env!("CARGO_MANIFEST_DIR"), "/data/room_7.exr").into());
    let output = args.next().unwrap_or_else(|| concat!(env!("CARGO_MANIFEST_DIR"), "/target/denoised.exr").into());
    // `lrdenoise::Error` implements `Display` and `core::error::Error`
    let lrd = |e: lrdenoise::Error| format!("lrdenoise: {e}");

    let exr = Exr::read(&input)?;
    let (w, h) = (exr.width, exr.height);
    let noisy = exr.layer("noisy", &["R", "G", "B"]).ok_or(format!("{input}: no noisy.R/G/B channels"))?;
    let normal = exr.layer("normal", &["X", "Y", "Z"]);
    let depth = exr.layer("depth", &["Z"]);
    let ao = exr.layer("ao", &["Y"]);

    // The plan: the default configuration with the guides this file has. Made
    // once per frame size; it allocates nothing and holds no frame data.
    let guides = GuideSet { normal: normal.is_some(), depth: depth.is_some(), ao: ao.is_some(), ..GuideSet::NONE };
    let flr = Flr::new(FlrConfig::with_guides(guides), w, h).map_err(lrd)?;
    // All of FLR's working memory, owned by the caller and reused frame after frame.
    let mut scratch = vec![0f64; flr.scratch_len()];

    // Views of the caller's buffers: interleaved f32 here; planar, strided
    // and f16 layouts work too (`ImageView::new`).
    let frame = Frame::new(
        ImageView::interleaved(&noisy, w, h, 3).map_err(lrd)?,
        Guides {
            normal: view(w, h, &normal, 3).map_err(lrd)?,
            depth: view(w, h, &depth, 1).map_err(lrd)?,
            ao: view(w, h, &ao, 1).map_err(lrd)?,
            ..Default::default()
        },
    );
    let mut out = vec![0f32; 3 * w * h];

    let mut times = Vec::new();
    let mut report = Default::default();
    for _ in 0..5 {
        let t = Instant::now();
        report = flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3).map_err(lrd)?).map_err(lrd)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }

    exr::prelude::write_rgb_file(&output, w, h, |x, y| {
        let i = 3 * (y * w + x);
        (out[i], out[i + 1], out[i + 2])
    })
    .map_err(|e| format!("{output}: {e}"))?;

    let names = [("normal", guides.normal), ("depth", guides.depth), ("ao", guides.ao)];
    let used: Vec<&str> = names.iter().filter(|(_, on)| *on).map(|(n, _)| *n).collect();
    println!("{input}: {w}x{h}, guides {}", used.join(" + "));
    println!(
        "report: {} non-finite noisy and {} non-finite guide pixels, {} fallback pixels, {} empty blocks, {} dropped pivots",
        report.nonfinite_noisy, report.nonfinite_guides, report.fallback_pixels, report.empty_blocks, report.dropped_pivots
    );
    println!(
        "denoise: {:.2} ms the first call, {:.2} ms the fastest of the next {} (one thread, {} kernels)",
        times[0],
        times[1..].iter().copied().fold(f64::INFINITY, f64::min),
        times.len() - 1,
        lrdenoise::simd_level()
    );
    println!("wrote {output}");
    Ok(())
}
