//! Frame inputs for the denoisers, and running FLR with its tiles spread over
//! threads (each stage's tiles split into one contiguous group per thread).

use lrdenoise::bmfr::Report as BmfrReport;
use lrdenoise::flr::moment_history::MomentFlr;
use lrdenoise::flr::temporal::TemporalFlr;
use lrdenoise::temporal::TemporalConfig;
use lrdenoise::walr::Report as WalrReport;
use lrdenoise::{
    Bmfr, BmfrConfig, Error, Flr, FlrConfig, Frame, GuideSet, Guides, History, ImageView, ImageViewMut, Report, TemporalDenoiser, Walr,
    WalrConfig,
};
use lrdenoise_cli::exrio::ExrFrame;
use std::path::Path;

/// The layers of one frame, interleaved f32, at full resolution.
#[derive(Clone, Debug)]
pub struct Inputs {
    pub w: usize,
    pub h: usize,
    pub noisy: Vec<f32>,
    pub normal: Option<Vec<f32>>,
    pub depth: Option<Vec<f32>>,
    pub position: Option<Vec<f32>>,
    pub ao: Option<Vec<f32>>,
    pub albedo: Option<Vec<f32>>,
    pub reference: Option<Vec<f32>>,
    /// Sequences: previous − current pixel position (2 channels).
    pub motion: Option<Vec<f32>>,
    /// The light and the normal, depth and AO as an engine hands them over
    /// (`lrd bench --layout`): the denoisers read these instead of the
    /// separate layers above.
    pub packed: Option<Packed>,
}

/// How `lrd bench` hands a frame to the library.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum InputLayout {
    /// One tightly packed buffer per layer: RGB light, RGB normal, depth, AO (f32).
    Planar,
    /// Two RGBA f32 buffers, as engine G-buffers: light with AO in alpha,
    /// normal with depth in the fourth channel.
    Rgba32,
    /// The same two buffers as RGBA16F.
    Rgba16,
}

/// Engine-style RGBA buffers: light (AO in alpha) and normal (depth in the
/// fourth channel), f32 or f16. Other layers stay separate.
#[derive(Clone, Debug)]
pub enum Packed {
    F32 { light: Vec<f32>, normal: Vec<f32> },
    F16 { light: Vec<half::f16>, normal: Vec<half::f16> },
}

impl Packed {
    /// Bytes of both buffers.
    pub fn bytes(&self) -> usize {
        match self {
            Packed::F32 { light, normal } => 4 * (light.len() + normal.len()),
            Packed::F16 { light, normal } => 2 * (light.len() + normal.len()),
        }
    }
    /// Channels `first..first + count` of the light (`normal = false`) or
    /// normal buffer, as a view.
    fn view(&self, normal: bool, first: usize, count: usize, w: usize, h: usize) -> Result<ImageView<'_>, Error> {
        let layout = lrdenoise::Layout { offset: first, pixel_stride: 4, row_stride: 4 * w, channel_stride: 1 };
        match self {
            Packed::F32 { light, normal: n } => ImageView::f32(if normal { n } else { light }, w, h, count, layout),
            Packed::F16 { light, normal: n } => ImageView::f16(if normal { n } else { light }, w, h, count, layout),
        }
    }
}

impl Inputs {
    /// Reads the noisy layer `noisy_layer` and whatever guides the frame has.
    pub fn from_exr(f: &ExrFrame, path: &Path, noisy_layer: &str) -> Result<Self, String> {
        let get = |name: &str, n: usize| -> Result<Option<Vec<f32>>, String> {
            if f.has(name) {
                Ok(Some(f.layer(name, n, path)?.interleaved(n)))
            } else {
                Ok(None)
            }
        };
        Ok(Inputs {
            w: f.width,
            h: f.height,
            noisy: f.layer(noisy_layer, 3, path)?.interleaved(3),
            normal: get("normal", 3)?,
            depth: get("depth", 1)?,
            position: get("position", 3)?,
            ao: get("ao", 1)?,
            albedo: get("albedo", 3)?,
            reference: get("reference", 3)?,
            motion: get("motion", 2)?,
            packed: None,
        })
    }

    /// The guides present among normal, depth and AO (the default set).
    pub fn default_guides(&self) -> GuideSet {
        GuideSet { normal: self.normal.is_some(), depth: self.depth.is_some(), position: false, ao: self.ao.is_some(), user: 0 }
    }

    /// Names the first guide in `set` that this frame lacks.
    pub fn missing(&self, set: &GuideSet) -> Option<&'static str> {
        [
            (set.normal, self.normal.is_none(), "normal"),
            (set.depth, self.depth.is_none(), "depth"),
            (set.position, self.position.is_none(), "position"),
            (set.ao, self.ao.is_none(), "ao"),
            (set.user > 0, self.albedo.is_none(), "albedo"),
        ]
        .into_iter()
        .find(|(want, lack, _)| *want && *lack)
        .map(|(_, _, n)| n)
    }

    /// A `w`×`h` frame whose pixel (x, y) is this frame's pixel `src(x, y)`
    /// (every layer the denoisers read; the reference is dropped).
    pub fn pick(&self, w: usize, h: usize, src: impl Fn(usize, usize) -> (usize, usize)) -> Inputs {
        let layer = |v: &Vec<f32>, c: usize| -> Vec<f32> {
            let mut o = Vec::with_capacity(w * h * c);
            for y in 0..h {
                for x in 0..w {
                    let (sx, sy) = src(x, y);
                    let i = sy.min(self.h - 1) * self.w + sx.min(self.w - 1);
                    o.extend_from_slice(&v[i * c..(i + 1) * c]);
                }
            }
            o
        };
        Inputs {
            w,
            h,
            noisy: layer(&self.noisy, 3),
            normal: self.normal.as_ref().map(|v| layer(v, 3)),
            depth: self.depth.as_ref().map(|v| layer(v, 1)),
            position: self.position.as_ref().map(|v| layer(v, 3)),
            ao: self.ao.as_ref().map(|v| layer(v, 1)),
            albedo: self.albedo.as_ref().map(|v| layer(v, 3)),
            reference: None,
            motion: self.motion.as_ref().map(|v| layer(v, 2)),
            packed: None,
        }
    }

    /// This frame with its light, AO, normal and depth also packed in
    /// `layout` (every layer must be present for the RGBA layouts).
    pub fn with_layout(mut self, layout: InputLayout) -> Result<Inputs, String> {
        let n = self.w * self.h;
        let (Some(normal), Some(depth), Some(ao)) = (&self.normal, &self.depth, &self.ao) else {
            return match layout {
                InputLayout::Planar => Ok(self),
                _ => Err("--layout rgba32|rgba16 needs a frame with normal, depth and AO".into()),
            };
        };
        let mut light4 = vec![0f32; 4 * n];
        let mut normal4 = vec![0f32; 4 * n];
        for i in 0..n {
            light4[4 * i..4 * i + 3].copy_from_slice(&self.noisy[3 * i..3 * i + 3]);
            light4[4 * i + 3] = ao[i];
            normal4[4 * i..4 * i + 3].copy_from_slice(&normal[3 * i..3 * i + 3]);
            normal4[4 * i + 3] = depth[i];
        }
        let half = |v: &[f32]| v.iter().map(|&x| half::f16::from_f32(x)).collect::<Vec<_>>();
        self.packed = match layout {
            InputLayout::Planar => None,
            InputLayout::Rgba32 => Some(Packed::F32 { light: light4, normal: normal4 }),
            InputLayout::Rgba16 => Some(Packed::F16 { light: half(&light4), normal: half(&normal4) }),
        };
        Ok(self)
    }

    /// The noisy light as the denoisers read it (RGB).
    pub fn noisy_view(&self) -> Result<ImageView<'_>, Error> {
        match &self.packed {
            Some(p) => p.view(false, 0, 3, self.w, self.h),
            None => ImageView::interleaved(&self.noisy, self.w, self.h, 3),
        }
    }

    /// Every `u`-th pixel (the centre-most of each u×u block): what a renderer
    /// tracing at 1/u resolution with the same sample count would produce.
    pub fn subsample(&self, u: usize) -> Inputs {
        self.pick(self.w.div_ceil(u), self.h.div_ceil(u), |x, y| (x * u + u / 2, y * u + u / 2))
    }

    /// Nearest-neighbour resample to `w`×`h` (for `lrd bench` on a given frame).
    pub fn resample(&self, w: usize, h: usize) -> Inputs {
        self.pick(w, h, |x, y| (x * self.w / w, y * self.h / h))
    }

    pub fn guides(&self, set: &GuideSet) -> Result<Guides<'_>, Error> {
        let (w, h) = (self.w, self.h);
        fn view(v: &Option<Vec<f32>>, want: bool, w: usize, h: usize, c: usize) -> Result<Option<ImageView<'_>>, Error> {
            match (want, v) {
                (true, Some(v)) => Ok(Some(ImageView::interleaved(v, w, h, c)?)),
                (true, None) => Err(Error::GuideMismatch),
                _ => Ok(None),
            }
        }
        let view = |v, want, c| view(v, want, w, h, c);
        // User guides are the albedo's channels, in order (`--guides albedo`).
        let mut user = [None; lrdenoise::MAX_USER_GUIDES];
        if let Some(alb) = view(&self.albedo, set.user > 0, 3)? {
            for (c, u) in user.iter_mut().enumerate().take((set.user as usize).min(3)) {
                *u = Some(alb.channels(c, 1)?);
            }
        }
        let mut g = Guides {
            user,
            normal: view(&self.normal, set.normal, 3)?,
            depth: view(&self.depth, set.depth, 1)?,
            position: view(&self.position, set.position, 3)?,
            ao: view(&self.ao, set.ao, 1)?,
        };
        if let Some(p) = &self.packed {
            let packed = |want: bool, normal: bool, first: usize, count: usize| -> Result<_, Error> {
                if want {
                    Ok(Some(p.view(normal, first, count, w, h)?))
                } else {
                    Ok(None)
                }
            };
            g.normal = packed(set.normal, true, 0, 3)?;
            g.depth = packed(set.depth, true, 3, 1)?;
            g.ao = packed(set.ao, false, 3, 1)?;
        }
        Ok(g)
    }
}

/// An FLR denoiser for one size: plan, scratch, thread pool, and (for
/// upsampling) the low-resolution inputs, prepared outside the timed call.
pub struct FlrRunner {
    pub flr: Flr,
    scratch: Vec<f64>,
    threads: usize,
    pool: Option<rayon::ThreadPool>,
}

impl FlrRunner {
    pub fn new(cfg: FlrConfig, w: usize, h: usize, threads: usize) -> Result<Self, String> {
        let flr = Flr::new(cfg, w, h).map_err(|e| format!("flr: {e}"))?;
        let threads = threads.max(1);
        let len = if threads > 1 { flr.tiled_scratch_len(threads).ok_or("flr: scratch size overflows")? } else { flr.scratch_len() };
        let scratch = vec![0f64; len];
        let pool =
            if threads > 1 { Some(rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| e.to_string())?) } else { None };
        Ok(FlrRunner { flr, scratch, threads, pool })
    }

    /// Denoises `full` (and `low` = its subsampled version when upsampling) into `out`.
    pub fn run(&mut self, full: &Inputs, low: Option<&Inputs>, out: &mut [f32]) -> Result<Report, String> {
        let cfg = *self.flr.config();
        let set = cfg.guides;
        let (noisy_src, guides_low) = match low {
            Some(l) => (l, Some(l.guides(&set).map_err(|e| e.to_string())?)),
            None => (full, None),
        };
        let noisy = noisy_src.noisy_view().map_err(|e| e.to_string())?;
        let frame = Frame { noisy, guides: full.guides(&set).map_err(|e| e.to_string())?, guides_low, sample_weights: None };
        let mut ov = ImageViewMut::interleaved(out, full.w, full.h, 3).map_err(|e| e.to_string())?;
        let r = match &self.pool {
            None => self.flr.denoise(&frame, &mut self.scratch, &mut ov),
            Some(pool) => {
                self.flr.denoise_parallel(&frame, &mut self.scratch, &mut ov, self.threads, &for_each_in_groups(pool, self.threads))
            }
        };
        r.map_err(|e| format!("flr: {e}"))
    }
}

/// The rayon executor of the `denoise_parallel` and
/// `denoise_temporal_parallel` runs: a stage's tiles in
/// `threads` contiguous groups (neighbouring bands share rows of the frame),
/// one task per group, the group's index as its worker.
fn for_each_in_groups(pool: &rayon::ThreadPool, threads: usize) -> impl Fn(usize, &(dyn Fn(usize, usize) + Sync)) + '_ {
    move |count, f| {
        let per = count.div_ceil(threads).max(1);
        pool.scope(|s| {
            for w in 0..threads {
                s.spawn(move |_| (w * per..((w + 1) * per).min(count)).for_each(|i| f(i, w)));
            }
        });
    }
}

/// Single-frame BMFR for one size: plan, one worker buffer per thread; the
/// tiles (block rows) are spread over threads (bit-identical to one thread).
pub struct BmfrRunner {
    pub bmfr: Bmfr,
    workers: Vec<f32>,
    threads: usize,
    pool: Option<rayon::ThreadPool>,
}

fn pool(threads: usize) -> Result<Option<rayon::ThreadPool>, String> {
    if threads > 1 {
        Ok(Some(rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| e.to_string())?))
    } else {
        Ok(None)
    }
}

impl BmfrRunner {
    pub fn new(cfg: BmfrConfig, w: usize, h: usize, threads: usize) -> Result<Self, String> {
        let bmfr = Bmfr::new(cfg, w, h).map_err(|e| format!("bmfr: {e}"))?;
        let threads = threads.max(1);
        Ok(BmfrRunner { workers: vec![0f32; bmfr.scratch_len()], bmfr, threads, pool: pool(threads)? })
    }

    /// Fits frame `index` (grid offset and regularisation noise) into `out`.
    pub fn run(&mut self, inputs: &Inputs, index: u32, out: &mut [f32]) -> Result<BmfrReport, String> {
        let set = self.bmfr.config().guides;
        let noisy = inputs.noisy_view().map_err(|e| e.to_string())?;
        let frame = Frame::new(noisy, inputs.guides(&set).map_err(|e| e.to_string())?);
        let ov = ImageViewMut::interleaved(out, inputs.w, inputs.h, 3).map_err(|e| e.to_string())?;
        let b = &self.bmfr;
        let r = match &self.pool {
            None => {
                let mut ov = ov;
                b.denoise(&frame, index, &mut self.workers, &mut ov)
            }
            Some(pool) => {
                let mut ov = ov;
                // the frame index moves the block grid, and with it the tile count
                let len = b.parallel_scratch_len(index, self.threads).ok_or("bmfr: scratch size overflows")?;
                if self.workers.len() < len {
                    self.workers.resize(len, 0.0);
                }
                b.denoise_parallel(&frame, index, &mut self.workers, &mut ov, self.threads, &for_each_in_groups(pool, self.threads))
            }
        };
        r.map_err(|e| format!("bmfr: {e}"))
    }
}

/// FLNR for one size: the weights (kept for the process's life), the plan and
/// its scratch. With threads, the network's tiles (nearly all of the time) are
/// handed out to the threads one at a time, each thread on its own tile
/// scratch, and FLR runs its tiles in parallel: bit-identical to one thread.
pub struct FlnrRunner {
    pub flnr: lrdenoise::flnr::Flnr<'static>,
    /// One thread: `Flnr::scratch_len`. More: the guide planes, then one tile
    /// scratch per thread.
    scratch: Vec<f32>,
    flr_scratch: Vec<f64>,
    threads: usize,
    pool: Option<rayon::ThreadPool>,
}

impl FlnrRunner {
    /// FLNR with `weights`; `fireflies`: the clamp of its FLR fit.
    pub fn new(weights: Vec<u8>, fireflies: Option<f32>, w: usize, h: usize, threads: usize) -> Result<Self, String> {
        // leaked on purpose: a runner lives as long as the command
        let blob: &'static [u8] = Box::leak(weights.into_boxed_slice());
        let config = lrdenoise::FlnrConfig { fireflies, ..lrdenoise::FlnrConfig::new(blob) };
        let flnr = lrdenoise::flnr::Flnr::new(config, w, h).map_err(|e| e.to_string())?;
        // the library splits the network into more tiles where the frame has fewer than the threads
        let threads = threads.max(1);
        let (scratch, flr_scratch) = if threads > 1 {
            (
                vec![0f32; flnr.parallel_scratch_len(threads).ok_or("flnr: scratch size overflows")?],
                vec![0f64; flnr.flr_tiled_scratch_len(threads).ok_or("flnr: scratch size overflows")?],
            )
        } else {
            (vec![0f32; flnr.scratch_len()], vec![0f64; flnr.flr_scratch_len()])
        };
        Ok(FlnrRunner { scratch, flr_scratch, flnr, threads, pool: pool(threads)? })
    }
    pub fn run(&mut self, inputs: &Inputs, out: &mut [f32]) -> Result<(), String> {
        let set = lrdenoise::flnr::INPUT_GUIDES;
        let noisy = inputs.noisy_view().map_err(|e| e.to_string())?;
        let frame = Frame::new(noisy, inputs.guides(&set).map_err(|e| e.to_string())?);
        let mut ov = ImageViewMut::interleaved(out, inputs.w, inputs.h, 3).map_err(|e| e.to_string())?;
        let fl = &self.flnr;
        let r = match &self.pool {
            None => fl.denoise(&frame, &mut self.scratch, &mut self.flr_scratch, &mut ov),
            Some(pool) => fl.denoise_parallel(
                &frame,
                &mut self.scratch,
                &mut self.flr_scratch,
                &mut ov,
                self.threads,
                &for_each_in_groups(pool, self.threads),
            ),
        };
        r.map(|_| ()).map_err(|e| format!("flnr: {e}"))
    }
}

/// Single-frame WALR for one size: plan, scratch, and each stage's rows
/// spread over threads in bands (bit-identical to one thread).
pub struct WalrRunner {
    pub walr: Walr,
    scratch: Vec<f32>,
    threads: usize,
    pool: Option<rayon::ThreadPool>,
}

impl WalrRunner {
    pub fn new(cfg: WalrConfig, w: usize, h: usize, threads: usize) -> Result<Self, String> {
        let walr = Walr::new(cfg, w, h).map_err(|e| format!("walr: {e}"))?;
        let threads = threads.max(1);
        let len = walr.parallel_scratch_len(threads).ok_or("walr: scratch size overflows")?;
        Ok(WalrRunner { scratch: vec![0f32; len], walr, threads, pool: pool(threads)? })
    }

    /// Denoises frame `index` (which seeds the replacement choices) into `out`.
    pub fn run(&mut self, inputs: &Inputs, index: u32, out: &mut [f32]) -> Result<WalrReport, String> {
        let set = self.walr.config().guides;
        let noisy = inputs.noisy_view().map_err(|e| e.to_string())?;
        let frame = Frame::new(noisy, inputs.guides(&set).map_err(|e| e.to_string())?);
        let mut ov = ImageViewMut::interleaved(out, inputs.w, inputs.h, 3).map_err(|e| e.to_string())?;
        let wl = &self.walr;
        let r = match &self.pool {
            None => wl.denoise(&frame, index, &mut self.scratch, &mut ov),
            Some(pool) => {
                wl.denoise_parallel(&frame, index, &mut self.scratch, &mut ov, self.threads, &for_each_in_groups(pool, self.threads))
            }
        };
        r.map_err(|e| format!("walr: {e}"))
    }
}

/// A temporal pipeline (FLR's on light or on cell moments, BMFR's or WALR's)
/// over a sequence: the plan behind [`TemporalDenoiser`], its scratch, its
/// threads and the history. [`TemporalRunner::save`] /
/// [`TemporalRunner::restore`] let a benchmark repeat one frame without
/// advancing the sequence.
pub struct TemporalRunner {
    plan: Box<dyn TemporalDenoiser + Sync>,
    /// What errors are prefixed with (the method's name).
    name: &'static str,
    /// The guides the frames must carry.
    guides: GuideSet,
    scratch: Vec<f64>,
    history: Vec<f32>,
    threads: usize,
    pool: Option<rayon::ThreadPool>,
    frames: u32,
    saved: Option<(Vec<f32>, u32)>,
}

impl TemporalRunner {
    /// BMFR's pipeline.
    pub fn new(cfg: BmfrConfig, w: usize, h: usize, threads: usize) -> Result<Self, String> {
        let bmfr = Bmfr::new(cfg, w, h).map_err(|e| format!("bmfr-temporal: {e}"))?;
        Self::with(Box::new(bmfr), "bmfr-temporal", cfg.guides, threads)
    }
    /// WALR's pipeline.
    pub fn walr(cfg: WalrConfig, w: usize, h: usize, threads: usize) -> Result<Self, String> {
        let walr = Walr::new(cfg, w, h).map_err(|e| format!("walr-temporal: {e}"))?;
        Self::with(Box::new(walr), "walr-temporal", cfg.guides, threads)
    }
    /// Temporal FLR on the accumulated light.
    pub fn flr(
        cfg: FlrConfig,
        temporal: TemporalConfig,
        history_weights: bool,
        reject: GuideSet,
        w: usize,
        h: usize,
        threads: usize,
    ) -> Result<Self, String> {
        let err = |e: Error| format!("flr-temporal: {e}");
        let plan = TemporalFlr::new(cfg, temporal, w, h)
            .map_err(err)?
            .with_history_weights(history_weights)
            .with_rejection_guides(reject)
            .map_err(err)?;
        let guides = plan.frame_guides();
        Self::with(Box::new(plan), "flr-temporal", guides, threads)
    }
    /// Temporal FLR on accumulated cell moments.
    pub fn moments(cfg: FlrConfig, temporal: TemporalConfig, w: usize, h: usize, threads: usize) -> Result<Self, String> {
        let plan = MomentFlr::new(cfg, &temporal, w, h).map_err(|e| format!("flr-temporal --accumulate moments: {e}"))?;
        Self::with(Box::new(plan), "flr-temporal --accumulate moments", cfg.guides, threads)
    }
    fn with(plan: Box<dyn TemporalDenoiser + Sync>, name: &'static str, guides: GuideSet, threads: usize) -> Result<Self, String> {
        let threads = threads.max(1);
        let scratch = if threads > 1 {
            plan.temporal_parallel_scratch_len(threads).ok_or_else(|| format!("{name}: too many threads"))?
        } else {
            plan.temporal_scratch_len()
        };
        let history = plan.history_len();
        Ok(TemporalRunner {
            plan,
            name,
            guides,
            scratch: vec![0f64; scratch],
            history: vec![0f32; history],
            threads,
            pool: pool(threads)?,
            frames: 0,
            saved: None,
        })
    }
    /// f32 values of the history (both slots).
    pub fn history_len(&self) -> usize {
        self.history.len()
    }
    pub fn save(&mut self) {
        self.saved = Some((self.history.clone(), self.frames));
    }
    pub fn restore(&mut self) {
        if let Some((h, f)) = &self.saved {
            self.history.copy_from_slice(h);
            self.frames = *f;
        }
    }
    /// The next frame of the sequence (its `motion` layer is used when present).
    pub fn run(&mut self, inputs: &Inputs, out: &mut [f32]) -> Result<(), String> {
        let (w, h) = (inputs.w, inputs.h);
        let noisy = inputs.noisy_view().map_err(|e| e.to_string())?;
        let frame = Frame::new(noisy, inputs.guides(&self.guides).map_err(|e| e.to_string())?);
        let motion = match &inputs.motion {
            Some(m) => Some(ImageView::interleaved(m, w, h, 2).map_err(|e| e.to_string())?),
            None => None,
        };
        let mut ov = ImageViewMut::interleaved(out, w, h, 3).map_err(|e| e.to_string())?;
        let mut history = History::resume(&mut self.history, self.frames);
        let r = match &self.pool {
            Some(pool) => self.plan.denoise_temporal_parallel(
                &frame,
                motion.as_ref(),
                &mut history,
                &mut self.scratch,
                &mut ov,
                self.threads,
                &for_each_in_groups(pool, self.threads),
            ),
            None => self.plan.denoise_temporal(&frame, motion.as_ref(), &mut history, &mut self.scratch, &mut ov),
        };
        // the library advances the count (its parity picks the history slots)
        self.frames = history.frames();
        r.map(|_| ()).map_err(|e| format!("{}: {e}", self.name))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic frame of several FLNR tiles: smooth guides with edges, noisy light.
    fn inputs(w: usize, h: usize) -> Inputs {
        let n = w * h;
        let hash = |i: usize| ((i.wrapping_mul(2654435761) >> 7) % 1000) as f32 / 1000.0;
        Inputs {
            w,
            h,
            noisy: (0..3 * n).map(|i| 4.0 * hash(i) * hash(i + 17)).collect(),
            normal: Some((0..3 * n).map(|i| if (i / 3) % w < w / 3 { [0.0, 1.0, 0.0][i % 3] } else { [0.6, 0.0, 0.8][i % 3] }).collect()),
            depth: Some((0..n).map(|i| 2.0 + (i / w) as f32 * 0.01 + ((i % w) > w / 2) as u8 as f32).collect()),
            position: None,
            ao: Some((0..n).map(|i| 0.5 + 0.5 * ((i % w) as f32 / w as f32)).collect()),
            albedo: None,
            reference: None,
            motion: None,
            packed: None,
        }
    }

    #[test]
    fn flnr_on_threads_equals_one_thread_bit_for_bit() {
        let (w, h) = (1100, 290); // several tiles of the default size, cut off-block
        let inp = inputs(w, h);
        let run = |threads: usize| {
            let mut r = FlnrRunner::new(crate::methods::BUNDLED_WEIGHTS.to_vec(), lrdenoise::FlnrConfig::new(&[]).fireflies, w, h, threads)
                .unwrap();
            let mut out = vec![f32::NAN; 3 * w * h];
            r.run(&inp, &mut out).unwrap();
            (out, r.threads)
        };
        let (one, t1) = run(1);
        assert_eq!(t1, 1);
        let fl = lrdenoise::flnr::Flnr::new(lrdenoise::FlnrConfig::new(crate::methods::BUNDLED_WEIGHTS), w, h).unwrap();
        let tiles = fl.tile_grid().0 * fl.tile_grid().1;
        assert!(tiles >= 2, "{tiles} tile(s): nothing to spread");
        assert!(one.iter().all(|v| v.is_finite()));
        for threads in [2, 3, 16] {
            let (many, used) = run(threads);
            assert_eq!(used, threads, "the library splits the network for more threads than tiles");
            let bad = one.iter().zip(&many).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
            assert_eq!(bad, 0, "{threads} threads: {bad} values differ");
        }
    }

    #[test]
    fn walr_on_threads_equals_one_thread_bit_for_bit() {
        // several bands (of 16+ rows), both blends (the adaptive one reads the rows around each band)
        let (w, h) = (70, 101);
        let mut inp = inputs(w, h);
        inp.position = Some((0..3 * w * h).map(|i| [(i / 3 % w) as f32 * 0.01, (i / 3 / w) as f32 * 0.01, 2.0][i % 3]).collect());
        for adaptive_blend in [true, false] {
            let cfg = WalrConfig { adaptive_blend, ..WalrConfig::default() };
            let run = |threads: usize| {
                let mut r = WalrRunner::new(cfg, w, h, threads).unwrap();
                let mut out = vec![f32::NAN; 3 * w * h];
                r.run(&inp, 3, &mut out).unwrap();
                out
            };
            let one = run(1);
            assert!(one.iter().all(|v| v.is_finite()));
            for threads in [2, 5] {
                let many = run(threads);
                let bad = one.iter().zip(&many).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
                assert_eq!(bad, 0, "adaptive {adaptive_blend}, {threads} threads: {bad} values differ");
            }
        }
    }
}
