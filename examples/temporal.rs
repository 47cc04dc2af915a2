//! A temporal pipeline over a sequence of EXR frames, with the history in a
//! buffer the caller owns, on one thread or on the caller's threads.
//!
//! ```sh
//! cargo run --release --example temporal                        # temporal FLR over data/seq_box_7
//! cargo run --release --example temporal -- moments|bmfr|walr [DIR] [--threads N]
//! ```
//!
//! `DIR` holds `frame_0000.exr`, `frame_0001.exr`, ... in the repository's
//! layout (`docs/DATA.md`): `noisy.R/G/B`, the guides `normal.X/Y/Z`,
//! `depth.Z`, `position.X/Y/Z` and `ao.Y`, and `motion.X/Y` (previous −
//! current pixel position, README "Input conventions") in every frame but
//! the first.
//!
//! Every pipeline (temporal FLR on the light or on FLR's cell moments, BMFR's,
//! WALR's) is a [`TemporalDenoiser`]: plan it once for the frame size, then
//! per frame `denoise_temporal` (or `denoise_temporal_parallel` with an
//! executor, the same bits). It keeps everything it carries from frame to
//! frame in a `History` over a caller-owned f32 buffer of `history_len()`
//! values, plus a frame counter: no allocation, no hidden state. Keep one per
//! sequence; `History::reset` after a camera cut.

use lrdenoise::flr::moment_history::MomentFlr;
use lrdenoise::flr::temporal::TemporalFlr;
use lrdenoise::temporal::TemporalConfig;
use lrdenoise::{
    Bmfr, BmfrConfig, FlrConfig, Frame, GuideSet, Guides, History, ImageView, ImageViewMut, TemporalDenoiser, Walr, WalrConfig,
};
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
            eprintln!("temporal: {e}");
            ExitCode::FAILURE
        }
    }
}

/// An executor over `threads` scoped threads: thread `t` runs items `t`,
/// `t + threads`, ... as worker `t`.
fn scoped_threads(threads: usize) -> impl Fn(usize, &(dyn Fn(usize, usize) + Sync)) {
    move |count, body| {
        std::thread::scope(|s| {
            for worker in 0..threads {
                s.spawn(move || (worker..count).step_by(threads).for_each(|i| body(i, worker)));
            }
        })
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut method = "flr".to_string();
    let mut dir = concat!(env!("CARGO_MANIFEST_DIR"), "/data/seq_box_7").to_string();
    let mut threads = 1usize;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "flr" | "moments" | "bmfr" | "walr" => method = a.clone(),
            "--threads" => threads = it.next().and_then(|n| n.parse().ok()).filter(|&n| n > 0).ok_or("--threads takes a count ≥ 1")?,
            _ => dir = a.clone(),
        }
    }
    // `lrdenoise::Error` implements `Display` and `core::error::Error`
    let lrd = |e: lrdenoise::Error| format!("lrdenoise: {e}");

    let mut paths: Vec<String> = std::fs::read_dir(&dir)
        .map_err(|e| format!("{dir}: {e}"))?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|name| name.starts_with("frame_") && name.ends_with(".exr"))
        .map(|name| format!("{dir}/{name}"))
        .collect();
    paths.sort();
    let first = Exr::read(paths.first().ok_or(format!("{dir}: no frame_*.exr"))?)?;
    let (w, h) = (first.width, first.height);
    let has = |layer: &str| first.channels.keys().any(|c| c.starts_with(&format!("{layer}.")));

    // Plan, scratch and history, once for the sequence; `guides`: what every frame must carry.
    let (plan, guides): (Box<dyn TemporalDenoiser + Sync>, GuideSet) = match method.as_str() {
        "flr" => {
            // FLR fits normal, depth and AO; world positions, where the frames have
            // them, also judge the history (they follow a dolly that depth alone rejects)
            let fit = GuideSet { normal: true, depth: true, ao: has("ao"), ..GuideSet::NONE };
            let reject = GuideSet { position: has("position"), ..fit };
            let cfg = FlrConfig { guides: fit, ..FlrConfig::temporal() };
            let plan = TemporalFlr::new(cfg, TemporalConfig::default(), w, h).map_err(lrd)?.with_rejection_guides(reject).map_err(lrd)?;
            let guides = plan.frame_guides();
            (Box::new(plan), guides)
        }
        "moments" => {
            let guides = GuideSet { normal: true, depth: true, ao: has("ao"), ..GuideSet::NONE };
            let cfg = FlrConfig { guides, ..FlrConfig::temporal_moments() };
            (Box::new(MomentFlr::new(cfg, &TemporalConfig::default(), w, h).map_err(lrd)?), guides)
        }
        "walr" => {
            // WALR needs normals and positions; depth scales its edge-stopping
            let guides = GuideSet { normal: true, position: true, depth: has("depth"), ..GuideSet::NONE };
            (Box::new(Walr::new(WalrConfig::with_guides(guides), w, h).map_err(lrd)?), guides)
        }
        _ => {
            // BMFR rejects history by world position, or by depth without positions
            let guides = GuideSet { normal: has("normal"), position: has("position"), depth: !has("position"), ..GuideSet::NONE };
            (Box::new(Bmfr::new(BmfrConfig::with_guides(guides), w, h).map_err(lrd)?), guides)
        }
    };
    let scratch_len = match threads {
        1 => plan.temporal_scratch_len(),
        n => plan.temporal_parallel_scratch_len(n).ok_or("too many threads")?,
    };
    let mut history_buffer = vec![0f32; plan.history_len()];
    let mut history = History::new(&mut history_buffer);
    let mut scratch = vec![0f64; scratch_len];
    let mut out = vec![0f32; 3 * w * h];
    let mut read_already = Some(first);
    let executor = scoped_threads(threads);

    println!(
        "{method} over {dir}: {} frames of {w}x{h} on {threads} thread(s), history {:.1} MB, scratch {:.1} MB",
        paths.len(),
        (4 * plan.history_len()) as f64 / 1e6,
        (8 * scratch_len) as f64 / 1e6
    );
    for path in &paths {
        let exr = match read_already.take() {
            Some(exr) => exr,
            None => Exr::read(path)?,
        };
        if (exr.width, exr.height) != (w, h) {
            return Err(format!("{path}: {}x{}, the sequence is {w}x{h}", exr.width, exr.height));
        }
        let noisy = exr.layer("noisy", &["R", "G", "B"]).ok_or(format!("{path}: no noisy.R/G/B channels"))?;
        let layer = |want: bool, name: &str, comps: &[&str]| match want {
            true => exr.layer(name, comps).ok_or(format!("{path}: no {name} layer")).map(Some),
            false => Ok(None),
        };
        let normal = layer(guides.normal, "normal", &["X", "Y", "Z"])?;
        let position = layer(guides.position, "position", &["X", "Y", "Z"])?;
        let depth = layer(guides.depth, "depth", &["Z"])?;
        let ao = layer(guides.ao, "ao", &["Y"])?;
        // absent in the first frame; the first frame of a history ignores it anyway
        let motion = exr.layer("motion", &["X", "Y"]);

        let frame = Frame::new(
            ImageView::interleaved(&noisy, w, h, 3).map_err(lrd)?,
            Guides {
                normal: view(w, h, &normal, 3).map_err(lrd)?,
                position: view(w, h, &position, 3).map_err(lrd)?,
                depth: view(w, h, &depth, 1).map_err(lrd)?,
                ao: view(w, h, &ao, 1).map_err(lrd)?,
                ..Default::default()
            },
        );
        let motion = view(w, h, &motion, 2).map_err(lrd)?;
        let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).map_err(lrd)?;

        let t = Instant::now();
        let report = match threads {
            1 => plan.denoise_temporal(&frame, motion.as_ref(), &mut history, &mut scratch, &mut ov),
            n => plan.denoise_temporal_parallel(&frame, motion.as_ref(), &mut history, &mut scratch, &mut ov, n, &executor),
        }
        .map_err(lrd)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let name = path.rsplit('/').next().unwrap_or(path);
        println!(
            "{name}: {ms:6.2} ms, motion {}, history rejected at {:5} {}, history.frames() = {}",
            if motion.is_some() { "yes" } else { "no " },
            report.history_rejected,
            if method == "moments" { "cells" } else { "pixels" },
            history.frames()
        );
    }
    Ok(())
}
