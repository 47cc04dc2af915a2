//! FLNR — Fast Local Neural Regression (Salmi, Cséfalvay & Imber, "Fast Local
//! Neural Regression for Low-Cost, Path Traced Lambertian Global
//! Illumination", §3.3): a small U-Net ([`crate::nn::UNet`]) writes `Q'`
//! model guides `X'_model` (the moments are built from them) and `Q'` map
//! guides `X'_map` (the per-block models are applied to them); then FLR runs
//! as usual, with the σ, ε, ϵ trained with the network.
//!
//! One deliberate difference: FLR is fitted on `[normal, depth, AO, X'_model]`
//! and applied to `[normal, depth, AO, X'_map]` — the network *adds* guides
//! instead of replacing them. FLNR then starts out as FLR (near-constant
//! learned guides are regularised away) and even a short CPU training can only
//! improve on it; the paper's replacement needs far longer training to catch up
//! with the plain guides.
//!
//! Network input (as `train/flnr.py` builds it): the normal (3), depth
//! divided by the frame's mean depth (1), AO (1), and `ln(1 + max(noisy, 0) /
//! s)` (3) with `s` the frame's mean of `max(noisy, 0)`; NaN/Inf become 0
//! (and FLR itself excludes NaN/Inf noisy samples). A network of 11 input
//! planes also reads **FLR's defaults output** on the same frame, as
//! `ln(1 + max(FLR, 0) / s)` (3): the *prior*, a first FLR
//! ([`FlrConfig::default`] with the configured firefly clamp) that runs
//! before the network, so that the network refines a denoised estimate
//! instead of learning the light from one noisy sample. The frame needs
//! normal, depth and AO.
//!
//! **Tiles with halos.** The network runs tile by tile (default
//! [`DEFAULT_TILE`] = 512 px edge, at least [`MIN_TILE`]), each on its input
//! grown by a halo of the network's receptive radius (17 px for two levels,
//! rounded up to 20 so the stride-2 grids of tile and frame coincide) and
//! clipped to the frame, so its working memory is bounded by the tile, not the
//! frame. At 1920×1080 with the bundled 12/24/48 network,
//! [`Flnr::scratch_len`] is about 46 M f32 (184 MB) instead of about 0.2 G
//! (0.9 GB) for the whole frame at once: 23.3 M for one tile's tensors,
//! 16.6 M for the 2·Q' = 8 learned guide planes FLR reads and 6.2 M for the
//! prior, which stay frame-sized like any other guides of the frame. The tiles' results are bit-identical to the
//! whole frame's (the zero padding at the frame's border is the same; a
//! tile's own border effects stay inside its halo; tested). The halo is
//! recomputed: ~1.16× the network's arithmetic at 512 px tiles, ~1.34× at 256
//! (`cargo bench --bench flnr_tiles` times the tile sizes). The
//! tiles are independent: [`Flnr::network_tile`] runs one, on any thread.

use crate::error::{Arg, Error};
use crate::flr::config::{Blur, FlrConfig};
use crate::flr::{Flr, Report};
use crate::guides::{Frame, GuideSet, MAX_USER_GUIDES};
use crate::image::{ImageView, ImageViewMut, Layout};
use crate::kernels::solve::Regularization;
use crate::nn::conv::Planes;
use crate::nn::{for_rows, Isa, UNet};
use crate::parallel::{run_tiles, Executor, TileRun};
use core::sync::atomic::{AtomicBool, Ordering};

/// Guides the network reads.
pub const INPUT_GUIDES: GuideSet = GuideSet::NORMAL_DEPTH_AO;
/// Input planes of a network that reads the guides and the noisy light.
const BASE_INPUTS: usize = 8;
/// Input planes of a network that also reads the prior (FLR's defaults output).
const PRIOR_INPUTS: usize = BASE_INPUTS + 3;
/// Default edge (pixels) of the network's output tiles. 512: the halo's
/// recomputation is ~1.16× at this size (~1.34× at 256; the 3×3 layers do not
/// depend on a tile's tensors staying in cache), a tile's tensors (23.3 M
/// f32, 93 MB, for the bundled network) are a tenth of the whole frame's, and
/// a 1080p frame still has 12 tiles to spread over threads.
pub const DEFAULT_TILE: usize = 512;
/// Fewest network tiles per worker at which [`Flnr::denoise_parallel`]
/// spreads whole tiles over the workers; with fewer (a 512×384 frame is one
/// tile), the tiles run one after another with each layer's rows split over
/// the workers ([`UNet::forward_parallel`]), which adds no halo arithmetic
/// and leaves no worker idle for want of a tile.
pub const TILES_PER_WORKER: usize = 2;

/// Smallest tile edge ([`FlnrConfig::tile`]) a plan accepts: for networks of up to 3
/// levels (tested; the bundled one has 2) every level of a tile's input stays
/// wide enough for the vectorised convolution paths, which is what keeps
/// tiles bit-identical to the whole frame (deeper networks may differ in the
/// last bit where a narrow level falls back to the per-pixel path).
pub const MIN_TILE: usize = 64;

/// A rectangle of pixels `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    /// First column.
    pub x0: usize,
    /// First row.
    pub y0: usize,
    /// One past the last column.
    pub x1: usize,
    /// One past the last row.
    pub y1: usize,
}

impl Rect {
    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.x1 - self.x0
    }
    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.y1 - self.y0
    }
}

/// Start of tile `i` of `n` along an axis of `len` pixels: near-equal tiles
/// whose starts are multiples of `align` (the network's stride-2 grids).
fn tile_start(i: usize, n: usize, len: usize, align: usize) -> usize {
    if i >= n {
        len
    } else {
        i * len / n / align * align
    }
}

/// FLNR's configuration: the network's weights and the tile size it runs in.
#[derive(Clone, Copy, Debug)]
pub struct FlnrConfig<'w> {
    /// A weight blob from `train/flnr.py` (e.g. the bundled `train/flnr.bin`),
    /// borrowed for the plan's lifetime.
    pub weights: &'w [u8],
    /// Network tile edge in pixels (at least [`MIN_TILE`]; default [`DEFAULT_TILE`]).
    pub tile: usize,
    /// The firefly clamp of the FLR fit ([`crate::FlrConfig::fireflies`];
    /// default `Some(fireflies::DEFAULT_STRENGTH)`). The network reads the
    /// light unclamped: its input is `ln(1 + light / mean)`, which already
    /// compresses outliers.
    pub fireflies: Option<f32>,
}

impl<'w> FlnrConfig<'w> {
    /// The weights with the default tile and firefly clamp.
    pub fn new(weights: &'w [u8]) -> Self {
        FlnrConfig { weights, tile: DEFAULT_TILE, fireflies: Some(crate::fireflies::DEFAULT_STRENGTH) }
    }
}

/// FLNR for one frame size and one set of weights.
#[derive(Clone, Copy, Debug)]
pub struct Flnr<'w> {
    net: UNet<'w>,
    flr: Flr,
    /// FLR's defaults, whose output the network reads (11-input networks).
    prior: Option<Flr>,
    width: usize,
    height: usize,
    q: usize,
    tile: usize,
    /// Input pixels added on every side of a tile (the receptive radius,
    /// rounded up to a multiple of the coarsest level's stride).
    halo: usize,
    /// Largest tile input (tile + halos, clipped to the frame), per axis.
    region_max: (usize, usize),
}

impl<'w> Flnr<'w> {
    /// Parses the weights (a blob from `train/flnr.py`) and plans FLR with the
    /// window(s) and ε, ϵ it was trained with (block 8; three windows: the
    /// adaptive window), and the network in tiles of `cfg.tile` px.
    pub fn new(config: FlnrConfig<'w>, width: usize, height: usize) -> Result<Self, Error> {
        let net = UNet::parse(config.weights)?;
        let q = net.out_channels() / 2;
        let inputs = net.in_channels();
        if !(inputs == BASE_INPUTS || inputs == PRIOR_INPUTS) || net.out_channels() % 2 != 0 || !(1..=MAX_USER_GUIDES).contains(&q) {
            return Err(Error::InvalidConfig("weights: FLNR needs 8 or 11 input channels and 2·Q' outputs, Q' ≤ 4"));
        }
        let [eps_mul, eps_add] = net.flr_eps();
        let blur = match *net.flr_sigmas() {
            [a, b, c] => Blur::Adaptive { sigmas: [a, b, c] },
            [sigma, ..] => Blur::Gaussian { sigma, radius: None },
            [] => return Err(Error::InvalidConfig("weights: no FLR window")),
        };
        let cfg = FlrConfig {
            guides: GuideSet { user: q as u8, ..INPUT_GUIDES },
            block: 8,
            blur,
            regularization: Regularization::Normalized { eps_mul: eps_mul as f64, eps_add: eps_add as f64 },
            // as the network was trained (train/flnr.py)
            ao_demodulation: net.flr_ao_demodulation(),
            fireflies: config.fireflies,
            ..FlrConfig::default()
        };
        let flr = Flr::new(cfg, width, height)?;
        let prior = if inputs == PRIOR_INPUTS {
            let cfg = FlrConfig { guides: INPUT_GUIDES, fireflies: config.fireflies, ..FlrConfig::default() };
            Some(Flr::new(cfg, width, height)?)
        } else {
            None
        };
        let align = tile_align(&net);
        let halo = net.receptive_radius().div_ceil(align) * align;
        let fl = Flnr { net, flr, prior, width, height, q, tile: DEFAULT_TILE, halo, region_max: (0, 0) };
        fl.with_tile(config.tile)
    }

    /// The same plan with the network run in tiles of about `tile` × `tile`
    /// output pixels (at least [`MIN_TILE`]; `usize::MAX`: the whole frame at
    /// once). Larger tiles recompute less halo and need more scratch; every
    /// tile size gives the same output, bit for bit.
    fn with_tile(mut self, tile: usize) -> Result<Self, Error> {
        if tile < MIN_TILE {
            return Err(Error::InvalidConfig("tile (at least 64 pixels)"));
        }
        self.tile = tile;
        let (nx, ny) = self.tile_grid();
        let mut rw = 0;
        for i in 0..nx {
            rw = rw.max(self.region(self.tile_rect_at(i, 0, nx, ny)).width());
        }
        let mut rh = 0;
        for j in 0..ny {
            rh = rh.max(self.region(self.tile_rect_at(0, j, nx, ny)).height());
        }
        self.region_max = (rw, rh);
        Ok(self)
    }
    /// The parsed network.
    pub fn network(&self) -> &UNet<'w> {
        &self.net
    }
    /// The FLR plan (σ, ε, ϵ from the weights).
    pub fn flr(&self) -> &Flr {
        &self.flr
    }
    /// The plan of the FLR whose output the network reads, for networks of
    /// 11 input planes; `None` for networks of 8.
    pub fn prior(&self) -> Option<&Flr> {
        self.prior.as_ref()
    }
    fn inputs(&self) -> usize {
        self.net.in_channels()
    }
    /// The tile edge asked for ([`FlnrConfig::tile`]).
    pub fn tile(&self) -> usize {
        self.tile
    }
    /// Input pixels a tile reads beyond its edges (where the frame has them).
    pub fn halo(&self) -> usize {
        self.halo
    }
    /// Tiles per row and per column.
    pub fn tile_grid(&self) -> (usize, usize) {
        (self.width.div_ceil(self.tile).max(1), self.height.div_ceil(self.tile).max(1))
    }
    fn tile_rect_at(&self, i: usize, j: usize, nx: usize, ny: usize) -> Rect {
        let align = tile_align(&self.net);
        Rect {
            x0: tile_start(i, nx, self.width, align),
            x1: tile_start(i + 1, nx, self.width, align),
            y0: tile_start(j, ny, self.height, align),
            y1: tile_start(j + 1, ny, self.height, align),
        }
    }
    /// The output pixels of tile `t` (row-major over [`Flnr::tile_grid`]).
    pub fn tile_rect(&self, t: usize) -> Result<Rect, Error> {
        let (nx, ny) = self.tile_grid();
        if t >= nx * ny {
            return Err(Error::InvalidTile { index: t, count: nx * ny });
        }
        Ok(self.tile_rect_at(t % nx, t / nx, nx, ny))
    }
    /// The input pixels the network reads for the tile `r`: grown by the
    /// halo, clipped to the frame (starts stay multiples of the stride).
    fn region(&self, r: Rect) -> Rect {
        Rect {
            x0: r.x0.saturating_sub(self.halo),
            y0: r.y0.saturating_sub(self.halo),
            x1: (r.x1 + self.halo).min(self.width),
            y1: (r.y1 + self.halo).min(self.height),
        }
    }
    fn plane(&self) -> usize {
        self.width * self.height
    }
    fn region_len(&self) -> usize {
        self.region_max.0 * self.region_max.1
    }
    fn single_tile(&self) -> bool {
        self.tile_grid() == (1, 1)
    }
    /// f32 of the 2·Q' learned guide planes (frame-sized; FLR reads them): the
    /// first part of [`Flnr::scratch_len`], and what [`TileGuides::scatter`]
    /// writes into when the tiles run on several threads.
    pub fn guide_planes_len(&self) -> usize {
        2 * self.q * self.plane()
    }
    /// f32 of the prior (FLR's defaults output, a frame-sized interleaved
    /// RGB image; 0 without a prior): what [`Flnr::run_prior`] writes and
    /// [`Flnr::network_tile`] reads.
    pub fn prior_len(&self) -> usize {
        if self.prior.is_some() {
            3 * self.plane()
        } else {
            0
        }
    }
    /// f32 of working space one thread needs for [`Flnr::network_tile`]: one
    /// tile's network input and output and working tensors
    /// ([`UNet::scratch_len`] of the largest tile input).
    pub fn tile_scratch_len(&self) -> usize {
        let r = self.region_len();
        (self.inputs() + 2 * self.q) * r + self.net.scratch_len(self.region_max.0, self.region_max.1)
    }
    /// f32 of scratch for [`Flnr::denoise`]: the guide planes, the prior
    /// and one tile's working space (without the tile's output copy
    /// when the whole frame is one tile: it is written straight into the
    /// planes).
    pub fn scratch_len(&self) -> usize {
        let copy = if self.single_tile() { 2 * self.q * self.region_len() } else { 0 };
        self.guide_planes_len() + self.prior_len() + self.tile_scratch_len() - copy
    }
    /// f64 of scratch for the FLR stages on one thread: the larger of
    /// [`Flr::scratch_len`] of the fit and of the prior.
    pub fn flr_scratch_len(&self) -> usize {
        self.flr.scratch_len().max(self.prior.map_or(0, |p| p.scratch_len()))
    }
    /// f64 of scratch for the FLR stages of [`Flnr::denoise_parallel`] on
    /// `workers` workers (`None` if it overflows): the larger of
    /// [`Flr::tiled_scratch_len`] of the fit and of the prior.
    pub fn flr_tiled_scratch_len(&self, workers: usize) -> Option<usize> {
        let prior = match &self.prior {
            Some(p) => p.tiled_scratch_len(workers)?,
            None => 0,
        };
        Some(self.flr.tiled_scratch_len(workers)?.max(prior))
    }

    /// The frame's input scales, one pass over its depth and noisy rows.
    fn scale_of(&self, depth: &ImageView<'_>, noisy: &ImageView<'_>) -> Result<InputScale, Error> {
        const CHUNK: usize = 64;
        let bad = Error::InvalidTile { index: 0, count: self.height };
        let (mut dsum, mut dn, mut lsum) = (0f64, 0u64, 0f64);
        let mut d = [0f32; CHUNK];
        let mut c = [[0f32; CHUNK]; 3];
        for y in 0..self.height {
            for x0 in (0..self.width).step_by(CHUNK) {
                let n = CHUNK.min(self.width - x0);
                depth.read_row(y, 0, x0, &mut d[..n]).ok_or(bad)?;
                let [c0, c1, c2] = &mut c;
                noisy.read_row_n(y, x0, [&mut c0[..n], &mut c1[..n], &mut c2[..n]]).ok_or(bad)?;
                for &v in &d[..n] {
                    if v.is_finite() && v > 0.0 {
                        dsum += v as f64;
                        dn += 1;
                    }
                }
                for v in c.iter().flat_map(|ch| &ch[..n]) {
                    lsum += clean(*v).max(0.0) as f64;
                }
            }
        }
        let depth = if dn > 0 { (dsum / dn as f64) as f32 } else { 1.0 };
        let light = ((lsum / (3 * self.plane()) as f64) as f32).max(1e-6);
        Ok(InputScale { depth, light })
    }

    /// Builds the network's input planes for the pixels `r` (row stride
    /// `r.width()`) into `x`, its rows on this thread or in bands over `threads`.
    #[allow(clippy::too_many_arguments)]
    fn input(
        &self,
        views: &[ImageView<'_>; 5],
        noisy: &ImageView<'_>,
        sc: InputScale,
        prior: &[f32],
        r: Rect,
        x: &mut [f32],
        threads: Threads<'_>,
    ) -> Result<(), Error> {
        let (w, h) = (r.width(), r.height());
        let planes = Planes::new(x, self.inputs(), w * h, w, h)?;
        let prior = Prior { rgb: prior, width: self.width };
        let failed = AtomicBool::new(false);
        for_rows(threads, h, &|y0, y1| {
            for y in y0..y1 {
                // SAFETY: each band writes only its own rows of `planes`, which borrows `x` exclusively.
                if unsafe { !input_row(views, noisy, sc, &prior, r, &planes, y) } {
                    failed.store(true, Ordering::Relaxed);
                }
            }
        })?;
        if failed.load(Ordering::Relaxed) {
            return Err(Error::InvalidTile { index: 0, count: self.height });
        }
        Ok(())
    }

    /// The frame's five input views (normal x, y, z, depth, AO), checked against the plan.
    fn views<'a>(&self, frame: &Frame<'a>) -> Result<[ImageView<'a>; 5], Error> {
        let (w, h) = (self.width, self.height);
        let n = &frame.noisy;
        if (n.width(), n.height()) != (w, h) {
            return Err(Error::SizeMismatch { arg: Arg::Noisy, expected: (w, h), got: (n.width(), n.height()) });
        }
        if n.channel_count() < 3 {
            return Err(Error::ChannelCount { arg: Arg::Noisy, expected: 3, got: n.channel_count() });
        }
        if frame.guides_low.is_some() {
            return Err(Error::Unsupported("FLNR has no joint upsampling (guides_low given)"));
        }
        if frame.sample_weights.is_some() {
            // (its network reads every pixel's light, sampled or not)
            return Err(Error::Unsupported("FLNR has no per-pixel sample weights (Frame::sample_weights given)"));
        }
        let cv = frame.guides.channel_views(&INPUT_GUIDES, w, h, Arg::Guide)?;
        let mut views = [*n; 5];
        for (v, c) in views.iter_mut().zip(&cv) {
            *v = c.ok_or(Error::GuideMismatch)?;
        }
        Ok(views)
    }

    /// Step 1 of a run split over threads: checks `frame` against the plan and
    /// measures the per-frame scales of the network's input (one pass over its
    /// depth and noisy rows). [`Flnr::denoise`] runs all the steps on one thread.
    pub fn input_scale(&self, frame: &Frame<'_>) -> Result<InputScale, Error> {
        let views = self.views(frame)?;
        self.scale_of(&views[3], &frame.noisy)
    }

    /// Step 1b, for networks that read the prior ([`Flnr::prior`]; nothing
    /// to do otherwise): FLR's defaults on `frame` into `prior` (at least
    /// [`Flnr::prior_len`] f32, an interleaved RGB image of the frame's
    /// size), in `flr_scratch` (at least [`Flnr::flr_scratch_len`] f64).
    pub fn run_prior(&self, frame: &Frame<'_>, prior: &mut [f32], flr_scratch: &mut [f64]) -> Result<(), Error> {
        self.views(frame)?;
        self.prior_planes(frame, prior, flr_scratch, None)
    }

    /// [`Flnr::run_prior`] on a checked frame, on this thread or spread over `threads`.
    fn prior_planes(&self, frame: &Frame<'_>, prior: &mut [f32], flr_scratch: &mut [f64], threads: Threads<'_>) -> Result<(), Error> {
        let Some(plan) = &self.prior else { return Ok(()) };
        self.check_prior(prior)?;
        let f = Frame { noisy: frame.noisy, guides: frame.guides, guides_low: None, sample_weights: None };
        let mut out = ImageViewMut::interleaved(&mut prior[..self.prior_len()], self.width, self.height, 3)?;
        match threads {
            Some((workers, for_each)) => plan.denoise_parallel(&f, flr_scratch, &mut out, workers, for_each),
            None => plan.denoise(&f, flr_scratch, &mut out),
        }
        .map(|_| ())
    }

    /// Runs the network on the input region `reg` into `o` (2·Q' planes of
    /// `reg`'s size); `x` holds the input, `net_scratch` the network's tensors.
    #[allow(clippy::too_many_arguments)]
    fn forward_region(
        &self,
        views: &[ImageView<'_>; 5],
        noisy: &ImageView<'_>,
        sc: InputScale,
        prior: &[f32],
        reg: Rect,
        x: &mut [f32],
        net_scratch: &mut [f32],
        o: &mut [f32],
        threads: Threads<'_>,
    ) -> Result<(), Error> {
        let rn = reg.width() * reg.height();
        let x = &mut x[..self.inputs() * rn];
        self.input(views, noisy, sc, prior, reg, x, threads)?;
        let (w, h, o) = (reg.width(), reg.height(), &mut o[..2 * self.q * rn]);
        match threads {
            Some((workers, for_each)) => self.net.forward_parallel(Isa::detect_widest(), x, w, h, net_scratch, o, workers, for_each),
            None => self.net.forward(x, w, h, net_scratch, o),
        }
    }

    /// Step 2: the network on tile `t` (row-major over [`Flnr::tile_grid`];
    /// every tile once, in any order, on any thread), computed in
    /// `tile_scratch` (at least [`Flnr::tile_scratch_len`] f32, one per
    /// thread); `prior`: the planes [`Flnr::run_prior`] wrote (any slice,
    /// e.g. empty, for networks without a prior). The result borrows the
    /// scratch until it is scattered ([`TileGuides::scatter`]) into the
    /// guide planes. Tiles are independent, so the planes come out
    /// bit-identical to [`Flnr::denoise`]'s.
    pub fn network_tile<'s>(
        &self,
        frame: &Frame<'_>,
        scale: InputScale,
        prior: &[f32],
        t: usize,
        tile_scratch: &'s mut [f32],
    ) -> Result<TileGuides<'s>, Error> {
        let views = self.views(frame)?;
        self.check_prior(prior)?;
        self.run_tile(&views, &frame.noisy, scale, prior, t, tile_scratch, None)
    }

    fn check_prior(&self, prior: &[f32]) -> Result<(), Error> {
        if prior.len() < self.prior_len() {
            return Err(Error::ScratchTooSmall { needed: self.prior_len(), got: prior.len() });
        }
        Ok(())
    }

    /// [`Flnr::network_tile`] on views and prior already checked.
    #[allow(clippy::too_many_arguments)]
    fn run_tile<'s>(
        &self,
        views: &[ImageView<'_>; 5],
        noisy: &ImageView<'_>,
        scale: InputScale,
        prior: &[f32],
        t: usize,
        tile_scratch: &'s mut [f32],
        threads: Threads<'_>,
    ) -> Result<TileGuides<'s>, Error> {
        if tile_scratch.len() < self.tile_scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.tile_scratch_len(), got: tile_scratch.len() });
        }
        let rect = self.tile_rect(t)?;
        let reg = self.region(rect);
        let rl = self.region_len();
        let (x, rest) = tile_scratch.split_at_mut(self.inputs() * rl);
        let (o, net_scratch) = rest.split_at_mut(2 * self.q * rl);
        self.forward_region(views, noisy, scale, prior, reg, x, net_scratch, o, threads)?;
        let len = 2 * self.q * reg.width() * reg.height();
        Ok(TileGuides { rect, region: reg, planes: 2 * self.q, frame: (self.width, self.height), data: &o[..len] })
    }

    /// Step 3: the frame FLR runs on, given the learned guide planes `planes`
    /// (at least [`Flnr::guide_planes_len`] f32, every tile scattered into
    /// them): fitted on `[normal, depth, AO, X'_model]`, applied to `[normal,
    /// depth, AO, X'_map]`. Denoise it with [`Flnr::flr`] (whole frame, or its
    /// tiles over threads).
    pub fn flr_frame<'a>(&self, frame: &Frame<'a>, planes: &'a [f32]) -> Result<Frame<'a>, Error> {
        if planes.len() < self.guide_planes_len() {
            return Err(Error::ScratchTooSmall { needed: self.guide_planes_len(), got: planes.len() });
        }
        self.views(frame)?;
        self.learned_frame(frame, planes)
    }

    /// [`Flnr::flr_frame`] on a frame and planes already checked.
    fn learned_frame<'a>(&self, frame: &Frame<'a>, planes: &'a [f32]) -> Result<Frame<'a>, Error> {
        let (w, h, np) = (self.width, self.height, self.plane());
        let plane = |k: usize| ImageView::f32(&planes[k * np..(k + 1) * np], w, h, 1, Layout::planar(w, h));
        let mut model = frame.guides;
        let mut map = frame.guides;
        for k in 0..self.q {
            model.user[k] = Some(plane(k)?);
            map.user[k] = Some(plane(self.q + k)?);
        }
        Ok(Frame { noisy: frame.noisy, guides: map, guides_low: Some(model), sample_weights: None })
    }

    /// Denoises one frame (normal, depth and AO guides) on the calling thread.
    /// `scratch`: at least [`Flnr::scratch_len`] f32, `flr_scratch`:
    /// [`Flnr::flr_scratch_len`] f64. Allocates nothing. To spread the network
    /// (nearly all of the time) over threads, run the steps yourself:
    /// [`Flnr::input_scale`], then [`Flnr::network_tile`] and
    /// [`TileGuides::scatter`] for every tile, then [`Flnr::flr_frame`] (as
    /// `lrd --threads N` does).
    pub fn denoise(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f32],
        flr_scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        if scratch.len() < self.scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.scratch_len(), got: scratch.len() });
        }
        let views = self.views(frame)?;
        let sc = self.scale_of(&views[3], &frame.noisy)?;
        let (g, rest) = scratch.split_at_mut(self.guide_planes_len());
        let (prior, work) = rest.split_at_mut(self.prior_len());
        self.prior_planes(frame, prior, flr_scratch, None)?;
        self.network_planes(&views, &frame.noisy, sc, prior, g, work, None)?;
        let f = self.learned_frame(frame, g)?;
        self.flr.denoise(&f, flr_scratch, out)
    }

    /// The network on every tile, one after another, into the learned guide
    /// planes `g`; `work`: [`Flnr::scratch_len`]'s share after the planes.
    #[allow(clippy::too_many_arguments)]
    fn network_planes(
        &self,
        views: &[ImageView<'_>; 5],
        noisy: &ImageView<'_>,
        sc: InputScale,
        prior: &[f32],
        g: &mut [f32],
        work: &mut [f32],
        threads: Threads<'_>,
    ) -> Result<(), Error> {
        if self.single_tile() {
            // the whole frame in one piece, straight into the planes
            let reg = Rect { x0: 0, y0: 0, x1: self.width, y1: self.height };
            let (x, net_scratch) = work.split_at_mut(self.inputs() * self.region_len());
            self.forward_region(views, noisy, sc, prior, reg, x, net_scratch, g, threads)
        } else {
            let (nx, ny) = self.tile_grid();
            for t in 0..nx * ny {
                self.run_tile(views, noisy, sc, prior, t, work, threads)?.scatter(g)?;
            }
            Ok(())
        }
    }

    /// Whether a parallel run on `workers` splits each layer's rows over
    /// them (too few tiles, see [`TILES_PER_WORKER`]) rather than whole tiles.
    fn layer_threads(&self, workers: usize) -> bool {
        let (nx, ny) = self.tile_grid();
        workers > 1 && nx * ny < TILES_PER_WORKER.saturating_mul(workers)
    }

    /// The guide and prior planes' share of a parallel scratch (rounded up
    /// to whole f64, so that the tile scratches after them stay 8-byte aligned).
    fn padded_planes_len(&self) -> usize {
        (self.guide_planes_len() + self.prior_len()).div_ceil(2) * 2
    }

    /// f32 values of the network scratch [`Flnr::denoise_parallel`] needs for
    /// `workers` workers (`None` if it overflows): [`Flnr::scratch_len`] where
    /// the layers' rows are split over the workers, otherwise the guide planes
    /// and one tile scratch per worker. Its FLR part needs
    /// `flr().tiled_scratch_len(workers)` f64.
    pub fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        if self.layer_threads(workers) {
            return Some(self.scratch_len());
        }
        let (nx, ny) = self.tile_grid();
        TileRun::scratch_len(nx * ny, workers.max(1), self.tile_scratch_len())?.checked_add(self.padded_planes_len())
    }

    /// [`Flnr::denoise`] with the prior, the network, then FLR's tiles,
    /// spread by the caller's executor ([`Executor`]); bit-identical to it.
    /// The network runs whole tiles on the workers where there are at least
    /// [`TILES_PER_WORKER`] per worker, and otherwise each layer's rows in
    /// bands over them. `scratch`: at least [`Flnr::parallel_scratch_len`]
    /// f32; `flr_scratch`: at least [`Flnr::flr_tiled_scratch_len`] f64;
    /// `out` must have rows that do not overlap in memory. Allocates nothing.
    pub fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f32],
        flr_scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let views = self.views(frame)?;
        let sc = self.scale_of(&views[3], &frame.noisy)?;
        let threads = Some((workers, for_each));
        if self.layer_threads(workers) {
            if scratch.len() < self.scratch_len() {
                return Err(Error::ScratchTooSmall { needed: self.scratch_len(), got: scratch.len() });
            }
            let (g, rest) = scratch.split_at_mut(self.guide_planes_len());
            let (prior, work) = rest.split_at_mut(self.prior_len());
            self.prior_planes(frame, prior, flr_scratch, threads)?;
            self.network_planes(&views, &frame.noisy, sc, prior, g, work, threads)?;
            let f = self.learned_frame(frame, g)?;
            return self.flr.denoise_parallel(&f, flr_scratch, out, workers, for_each);
        }
        let np = self.padded_planes_len();
        if scratch.len() < np {
            return Err(Error::ScratchTooSmall { needed: np, got: scratch.len() });
        }
        let (both, rest) = scratch.split_at_mut(np);
        let (planes, prior) = both.split_at_mut(self.guide_planes_len());
        self.prior_planes(frame, prior, flr_scratch, threads)?;
        let prior: &[f32] = prior;
        let (nx, ny) = self.tile_grid();
        let shared = PlanesPtr(planes.as_mut_ptr());
        run_tiles(rest, nx * ny, workers, self.tile_scratch_len(), for_each, &|t, buf| {
            let tile = self.run_tile(&views, &frame.noisy, sc, prior, t, buf, None)?;
            // SAFETY: the planes hold `guide_planes_len` f32 (checked above)
            // and are not otherwise used until every tile has returned; each
            // tile runs once (`run_tiles`) and writes only the pixels of its
            // own rect, disjoint from every other's.
            unsafe { tile.scatter_to(shared.get()) }?;
            Ok(Report::default())
        })?;
        let f = self.learned_frame(frame, &planes[..self.guide_planes_len()])?;
        self.flr.denoise_parallel(&f, flr_scratch, out, workers, for_each)
    }
}

/// How the network's layers run: on the calling thread (`None`), or with
/// their rows in bands over `(workers, executor)`.
type Threads<'e> = Option<(usize, Executor<'e>)>;

/// The guide planes, written by concurrent tiles at disjoint pixels.
struct PlanesPtr(*mut f32);
// SAFETY: only `TileGuides::scatter_to` writes through it, each tile at its own pixels.
unsafe impl Sync for PlanesPtr {}

impl PlanesPtr {
    fn get(&self) -> *mut f32 {
        self.0
    }
}

/// The per-frame scales of the network's input ([`Flnr::input_scale`]): every
/// tile of a frame must use the same.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputScale {
    /// Mean of the finite, positive depths (1 without any).
    depth: f32,
    /// Mean of `max(noisy, 0)` over the finite samples of all three channels
    /// (at least 1e-6).
    light: f32,
}

/// One tile's share of the learned guide planes ([`Flnr::network_tile`]),
/// held in that thread's scratch.
#[derive(Debug)]
pub struct TileGuides<'s> {
    rect: Rect,
    region: Rect,
    planes: usize,
    frame: (usize, usize),
    data: &'s [f32],
}

impl TileGuides<'_> {
    /// The output pixels this tile owns.
    pub fn rect(&self) -> Rect {
        self.rect
    }
    /// Number of learned guide planes (2·Q').
    pub fn plane_count(&self) -> usize {
        self.planes
    }
    /// Plane `k`'s values of frame row `y` over this tile's own columns
    /// (`rect().x0..rect().x1`); `None` outside the tile. For callers that
    /// copy into the frame-sized planes through their own pointers (the C
    /// API's threads); [`TileGuides::scatter`] does the copy from safe code.
    pub fn row(&self, k: usize, y: usize) -> Option<&[f32]> {
        let (r, reg) = (self.rect, self.region);
        if k >= self.planes || !(r.y0..r.y1).contains(&y) {
            return None;
        }
        let s = k * reg.width() * reg.height() + (y - reg.y0) * reg.width() + (r.x0 - reg.x0);
        self.data.get(s..s + r.width())
    }
    /// [`TileGuides::scatter`] through a pointer to the planes (at least
    /// [`Flnr::guide_planes_len`] f32), for tiles that write them concurrently.
    ///
    /// # Safety
    /// `planes` is valid for writes of the planes, and nothing else reads or
    /// writes this tile's pixels of them meanwhile.
    unsafe fn scatter_to(&self, planes: *mut f32) -> Result<(), Error> {
        let (w, h) = self.frame;
        let r = self.rect;
        for k in 0..self.planes {
            for y in r.y0..r.y1 {
                let src = self.row(k, y).ok_or(Error::InvalidTile { index: y, count: h })?;
                // SAFETY: the pixel range lies inside plane k (the rect is inside the
                // frame); the caller keeps it to this call.
                unsafe { core::ptr::copy_nonoverlapping(src.as_ptr(), planes.add(k * w * h + y * w + r.x0), src.len()) };
            }
        }
        Ok(())
    }
    /// Copies the tile's pixels into the frame-sized guide planes `planes`
    /// (at least [`Flnr::guide_planes_len`] f32; other tiles' pixels are left
    /// as they are).
    pub fn scatter(&self, planes: &mut [f32]) -> Result<(), Error> {
        let (w, h) = self.frame;
        let np = w * h;
        if planes.len() < self.planes * np {
            return Err(Error::ScratchTooSmall { needed: self.planes * np, got: planes.len() });
        }
        let r = self.rect;
        for (k, dst) in planes.chunks_exact_mut(np).take(self.planes).enumerate() {
            for y in r.y0..r.y1 {
                let src = self.row(k, y).ok_or(Error::InvalidTile { index: y, count: h })?;
                dst[y * w + r.x0..y * w + r.x1].copy_from_slice(src);
            }
        }
        Ok(())
    }
}

/// The prior as the network input reads it: an interleaved RGB image of
/// `width`-pixel rows (empty without a prior).
struct Prior<'a> {
    rgb: &'a [f32],
    width: usize,
}

/// Row `y` of the network input planes of the pixels `r` (see
/// [`Flnr::input`]); `false` if a view or the prior has no such row.
///
/// # Safety
/// No other live slice covers row `y` of `planes`.
unsafe fn input_row(
    views: &[ImageView<'_>; 5],
    noisy: &ImageView<'_>,
    sc: InputScale,
    prior: &Prior<'_>,
    r: Rect,
    planes: &Planes<'_>,
    y: usize,
) -> bool {
    let fy = r.y0 + y;
    for (c, v) in views.iter().enumerate() {
        // SAFETY: the caller keeps row y to this call (and below).
        let row = unsafe { planes.row(c, y) };
        if v.read_row(fy, 0, r.x0, row).is_none() {
            return false;
        }
        let scale = if c == 3 { sc.depth } else { 1.0 };
        for v in row.iter_mut() {
            *v = clean(if c == 3 { *v / scale } else { *v });
        }
    }
    // SAFETY: as above.
    let light = unsafe { [planes.row(5, y), planes.row(6, y), planes.row(7, y)] };
    if noisy.read_row_n(fy, r.x0, light).is_none() {
        return false;
    }
    for c in 5..8 {
        // SAFETY: as above.
        log_light(unsafe { planes.row(c, y) }, sc.light);
    }
    if planes.channels() == PRIOR_INPUTS {
        let at = 3 * (fy * prior.width + r.x0);
        let Some(src) = prior.rgb.get(at..at + 3 * r.width()) else { return false };
        for c in 0..3 {
            // SAFETY: as above.
            let row = unsafe { planes.row(BASE_INPUTS + c, y) };
            for (v, p) in row.iter_mut().zip(src.chunks_exact(3)) {
                *v = p[c];
            }
            log_light(row, sc.light);
        }
    }
    true
}

/// What tile and region edges are multiples of: `2^levels`, so that the
/// stride-2 grids of a tile and the frame coincide, and at least 2, so that
/// the pairs of output columns of the AVX-512 Winograd lanes do too (a tile
/// gives the whole frame's bits).
fn tile_align(net: &UNet<'_>) -> usize {
    (1usize << net.levels()).max(2)
}

/// `ln(1 + v / scale)` of light (NaN/Inf → 0, negatives → 0), in place,
/// with `wide`'s `ln_1p` ([`crate::nn::map8`]: a value's result does not
/// depend on its position in the row, and tiles read rows from different
/// columns).
fn log_light(row: &mut [f32], scale: f32) {
    use wide::f32x8;
    let scale = f32x8::splat(scale);
    crate::nn::map8(row, |x| (x.is_finite().select(x, f32x8::ZERO).max(f32x8::ZERO) / scale).ln_1p());
}

/// NaN/Inf → 0.
#[inline]
fn clean(v: f32) -> f32 {
    if v.is_finite() {
        v
    } else {
        0.0
    }
}
