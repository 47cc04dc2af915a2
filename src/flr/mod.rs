//! The FLR frame driver: plan, scratch layout, and the stage kernels, each
//! split into independent tiles (bands of cell rows). The stage order and the
//! entry that runs one tile are written once, in [`schedule`];
//! [`Flr::denoise`] and [`Flr::denoise_parallel`] are both drivers of it.
//!
//! A caller needs [`Flr::new`], [`Flr::scratch_len`] and [`Flr::denoise`],
//! or for threads [`Flr::denoise_parallel`] / [`Flr::tiled`] and
//! [`Tiled::run`]. The stage kernels they run (`prepare`, `moments_tile`,
//! `finish_stats`, `blur_rows_tile_at`, `blur_cols_tiles_at`, `solve_tile_at`,
//! `blend_tile`, `apply_tile`, and their tile ranges) are crate-private; the
//! `internals` feature makes them public (hidden from the documentation) for
//! this crate's benches, fuzz targets and tests. They check their slices but
//! not the stage order.
//!
//! With an adaptive window ([`Blur::Adaptive`], three window sizes) the blur
//! and solve stages run once per window `s` (`*_at(s, ..)`, the blurred grid of
//! window 0 into `first`, the others into `blurred`; each window's models and
//! variances into `scale_models` / `variances`), and `blend_tile` then
//! writes `models` from them. The larger windows are fitted on the moment grid
//! pooled 2×2 (`pool_tile`: `cells` band → `pooled` band, in the moments
//! stage). With [`FlrConfig::adaptive_without_ao`] window 0's solve also fits
//! each cell without AO (from the same Cholesky factor) and the blend weighs
//! that fit as a fourth candidate. See [`adaptive`].

pub mod adaptive;
pub mod config;
pub mod gpu;
pub mod moment_history;
pub mod schedule;
pub mod temporal;

pub use schedule::{Stage, Tiled};

use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::{Frame, MAX_GUIDES};
use crate::image::{ImageView, ImageViewMut};
use crate::isa::Kernel;
use crate::kernels::apply::{apply_row, lerp_rows, RowGuides, RowOut};
use crate::kernels::blur::{blur_cols_band, blur_row, radius_to_cells, Taps, GAUSSIAN_TRUNCATION};
use crate::kernels::demodulation;
use crate::kernels::moments::{moments_band, moments_rows, rows_supported, BandPlanes, BandRows, BlockScratch, MAX_ROWS};
use crate::kernels::solve::{solve_cell, solve_cell_without, solve_cells4, solve_cells4_without, CellOutcome, SolveParams};
use crate::kernels::{dispatch_q, model_len, CellLayout};
use adaptive::MAX_CANDIDATES;
use config::{Blur, FlrConfig};

/// Most window sizes one run fits ([`Blur::Adaptive`]).
pub const MAX_SCALES: usize = 3;

/// Cell rows per tile. Small enough for parallelism at 720p, large enough to
/// amortise the vertical box-window initialisation. Even, so that a tile is
/// also whole rows of the pooled grid.
pub const TILE_CELL_ROWS: usize = 4;

/// The cell grid one window is fitted on: the block grid, or (the larger
/// windows of [`Blur::Adaptive`], see [`adaptive::POOL_MIN_SIGMA`]) its 2×2
/// pooling, cells of 2B × 2B pixels.
#[cfg_attr(feature = "internals", visibility::make(pub))]
#[doc(hidden)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Grid {
    /// Cells per row and per column.
    pub cells_x: usize,
    pub cells_y: usize,
    /// Block cells per cell side: 1 (the block grid) or 2 (pooled).
    pub factor: usize,
}

impl Grid {
    /// Cell rows `[start, end)` of tile `t` (the caller checked `t`).
    fn tile_rows(&self, t: usize) -> (usize, usize) {
        let r = TILE_CELL_ROWS / self.factor;
        ((t * r).min(self.cells_y), ((t + 1) * r).min(self.cells_y))
    }
    fn cell_count(&self) -> usize {
        self.cells_x * self.cells_y
    }
}

pub use crate::report::Report;

/// `mask[i] = 0` where `v[i]` is NaN or ±Inf. Written as a multiply by 0/1 so
/// it vectorises to compare + and + multiply with plain stores (a conditional
/// store compiles to slow masked stores).
#[inline]
fn mask_finite(v: &[f32], mask: &mut [f32]) {
    for (m, x) in mask.iter_mut().zip(v) {
        let keep = (x.abs() <= f32::MAX) as u32 as f32;
        *m *= keep;
    }
}

/// `dst = src − m` and `mask = 0` where `src` is not finite (one pass).
#[inline]
fn centre_and_mask(src: &[f32], m: f32, dst: &mut [f32], mask: &mut [f32]) {
    for ((d, k), &v) in dst.iter_mut().zip(mask.iter_mut()).zip(src) {
        *k *= (v.abs() <= f32::MAX) as u32 as f32;
        *d = v - m;
    }
}

/// [`centre_and_mask`] for values already in `dst`.
#[inline]
fn centre_and_mask_in_place(m: f32, dst: &mut [f32], mask: &mut [f32]) {
    for (d, k) in dst.iter_mut().zip(mask.iter_mut()) {
        *k *= (d.abs() <= f32::MAX) as u32 as f32;
        *d -= m;
    }
}

/// 1 / the mean of the weights in `weights` (channel 0) that are finite and
/// positive; 1 if there is none. Each run of up to 256 values is summed in 8
/// independent f32 lanes (so it vectorises), the runs in f64.
fn weight_scale(weights: &ImageView<'_>) -> f64 {
    let (mut sum, mut n) = (0f64, 0usize);
    let mut row = [0f32; 256];
    for y in 0..weights.height() {
        for x0 in (0..weights.width()).step_by(row.len()) {
            let len = row.len().min(weights.width() - x0);
            let run = &mut row[..len];
            if weights.read_row(y, 0, x0, run).is_none() {
                return 1.0;
            }
            let (mut lanes, mut count) = ([0f32; 8], [0u32; 8]);
            let mut add = |l: usize, w: f32| {
                let ok = w > 0.0 && w <= f32::MAX;
                lanes[l] += if ok { w } else { 0.0 };
                count[l] += ok as u32;
            };
            let mut eights = run.chunks_exact(8);
            for e in &mut eights {
                for (l, &w) in e.iter().enumerate() {
                    add(l, w);
                }
            }
            for (l, &w) in eights.remainder().iter().enumerate() {
                add(l, w);
            }
            sum += lanes.iter().map(|&v| v as f64).sum::<f64>();
            n += count.iter().sum::<u32>() as usize;
        }
    }
    let scale = n as f64 / sum;
    if n > 0 && scale.is_finite() && scale > 0.0 {
        scale
    } else {
        1.0
    }
}

/// Number of zero entries (integer count: vectorises, unlike an f32 sum).
#[inline]
fn count_zero(mask: &[f32]) -> usize {
    mask.iter().map(|&m| (m == 0.0) as usize).sum()
}

/// Per-frame constants: the reference each guide is measured from (a sample
/// of the frame, so that large offsets cancel exactly) and the frame mean and
/// standard deviation used to standardise guides in the normalized solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stats {
    /// Per guide channel: the frame sample its moments are measured from.
    pub reference: [f32; MAX_GUIDES],
    /// Per guide channel: the frame mean, relative to `reference`.
    pub mean: [f64; MAX_GUIDES],
    /// Per guide channel: the frame standard deviation (1 for constants).
    pub scale: [f64; MAX_GUIDES],
    /// With [`Frame::sample_weights`]: 1 / the mean of the frame's weights that are
    /// finite and positive (1 without weights, or without such a weight). The
    /// moments weigh pixels by `w · weight_scale`, whose frame mean is 1, so
    /// that only the weights' ratios matter and the adaptive window's sample
    /// counts are pixel counts over the frame (not in each window).
    pub weight_scale: f64,
}

/// Sums over the cells of their weights, guide sums and guide squares,
/// turned into [`Stats`] by `Flr::finish_stats_sums`.
#[derive(Clone, Copy, Debug, Default)]
struct StatsSums {
    n: f64,
    s: [f64; MAX_GUIDES],
    ss: [f64; MAX_GUIDES],
}

impl Default for Stats {
    fn default() -> Self {
        Stats { reference: [0.0; MAX_GUIDES], mean: [0.0; MAX_GUIDES], scale: [1.0; MAX_GUIDES], weight_scale: 1.0 }
    }
}

/// A frame checked against the plan: one single-channel view per guide channel.
#[derive(Clone, Copy, Debug)]
pub struct CheckedFrame<'a> {
    noisy: ImageView<'a>,
    /// Guides the moments are built from (input resolution).
    fit: [Option<ImageView<'a>>; MAX_GUIDES],
    /// Guides the model is applied to (output resolution).
    map: [Option<ImageView<'a>>; MAX_GUIDES],
    /// Per-pixel weights of the fit ([`Frame::sample_weights`]).
    weights: Option<ImageView<'a>>,
}

/// The scratch buffer split into its regions.
#[cfg(feature = "internals")]
#[doc(hidden)]
#[derive(Debug)]
pub struct Parts<'s> {
    /// Moment grid, `cells_x * cells_y * k` f64.
    pub cells: &'s mut [f64],
    /// Second moment grid for the separable blur.
    pub tmp: &'s mut [f64],
    /// Model grid, `cells_x * cells_y * model_len` f32.
    pub models: &'s mut [f32],
    /// One private buffer of `worker_len()` f32 per worker.
    pub workers: &'s mut [f32],
    /// Adaptive window only (else empty): window 0's blurred grid.
    pub first: &'s mut [f64],
    /// Adaptive window only: the blurred grid of windows 1 and 2 (in turn).
    pub blurred: &'s mut [f64],
    /// Adaptive window with pooled windows only: the moment grid pooled 2×2.
    pub pooled: &'s mut [f64],
    /// Adaptive window only: each window's model grid on its own grid
    /// (window-major, [`Flr::scale_models_tile_range`]).
    pub scale_models: &'s mut [f32],
    /// Adaptive window only: each window's per-cell variance estimate on its
    /// own grid (window-major, [`Flr::scale_variances_tile_range`]).
    pub variances: &'s mut [f64],
}

/// [`Flr::scratch_layout`]: each region's f64 range in the scratch.
#[cfg_attr(feature = "internals", visibility::make(pub))]
#[doc(hidden)]
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct ScratchLayout {
    pub cells: core::ops::Range<usize>,
    pub tmp: core::ops::Range<usize>,
    pub models: core::ops::Range<usize>,
    pub workers: core::ops::Range<usize>,
    pub first: core::ops::Range<usize>,
    pub blurred: core::ops::Range<usize>,
    pub pooled: core::ops::Range<usize>,
    pub scale_models: core::ops::Range<usize>,
    pub variances: core::ops::Range<usize>,
}

/// Fast Local Regression for one frame size and configuration.
#[derive(Clone, Copy, Debug)]
pub struct Flr {
    cfg: FlrConfig,
    width: usize,
    height: usize,
    in_w: usize,
    in_h: usize,
    /// Block size at input resolution (B / upsample).
    bin: usize,
    cells_x: usize,
    cells_y: usize,
    q: usize,
    lay: CellLayout,
    ml: usize,
    /// One set of taps per window (only `scale_count()` are used).
    taps: [Taps; MAX_SCALES],
    /// The grid each window is fitted on.
    grids: [Grid; MAX_SCALES],
    /// Most samples per pixel the adaptive window's variances count: 1 for a
    /// frame; the history cap for cells that hold sums over several frames
    /// (`moment_history`).
    sample_cap: f64,
    /// Whether the `Moments` stage also sums the pooled cells (not when a
    /// later pass changes the cells and pools them itself: `moment_history`).
    pool_in_moments: bool,
}

impl Flr {
    /// Plans a denoiser for `width`×`height` output frames.
    pub fn new(cfg: FlrConfig, width: usize, height: usize) -> Result<Self, Error> {
        cfg.validate()?;
        if width == 0 || height == 0 || width > crate::image::MAX_DIM || height > crate::image::MAX_DIM {
            return Err(Error::InvalidSize { arg: Arg::Output, width, height });
        }
        let q = cfg.guides.channels();
        if q > MAX_GUIDES {
            return Err(Error::TooManyGuides { got: q });
        }
        let b = cfg.block;
        let r = cfg.radius_cells();
        let one = |t: Taps| [t; MAX_SCALES];
        let fine = Grid { cells_x: width.div_ceil(b), cells_y: height.div_ceil(b), factor: 1 };
        let mut grids = [fine; MAX_SCALES];
        let taps = match cfg.blur {
            Blur::Gaussian { sigma, .. } => one(Taps::gaussian(sigma as f64 / b as f64, r)),
            Blur::Box { .. } => one(Taps::boxed(r)),
            Blur::Adaptive { sigmas } => {
                let mut taps = [Taps::boxed(0); MAX_SCALES];
                for (s, &sigma) in sigmas.iter().enumerate() {
                    if s > 0 && adaptive::pooled(sigma, b) {
                        grids[s] = Grid { cells_x: fine.cells_x.div_ceil(2), cells_y: fine.cells_y.div_ceil(2), factor: 2 };
                    }
                    let cell = b * grids[s].factor;
                    taps[s] = Taps::gaussian(sigma as f64 / cell as f64, radius_to_cells(GAUSSIAN_TRUNCATION * sigma, cell));
                }
                taps
            }
        };
        Ok(Flr {
            cfg,
            width,
            height,
            in_w: width.div_ceil(cfg.upsample),
            in_h: height.div_ceil(cfg.upsample),
            bin: b / cfg.upsample,
            cells_x: width.div_ceil(b),
            cells_y: height.div_ceil(b),
            q,
            lay: CellLayout::new(q),
            ml: model_len(q),
            taps,
            grids,
            sample_cap: 1.0,
            pool_in_moments: true,
        })
    }

    /// The same plan for cells that hold sums over up to `cap` frames
    /// (`moment_history`): the adaptive window's variances count up to `cap`
    /// samples per pixel. 1 is a single frame's plan.
    pub(crate) fn with_sample_cap(mut self, cap: f64) -> Self {
        self.sample_cap = if cap.is_finite() { cap.max(1.0) } else { 1.0 };
        self
    }

    /// The same plan whose `Moments` stage leaves the pooled cells to the caller.
    pub(crate) fn without_pooling_in_moments(mut self) -> Self {
        self.pool_in_moments = false;
        self
    }

    /// The configuration.
    pub fn config(&self) -> &FlrConfig {
        &self.cfg
    }
    /// Output size.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }
    /// Size of the noisy input (output size / upsample, rounded up).
    pub fn input_size(&self) -> (usize, usize) {
        (self.in_w, self.in_h)
    }
    /// Model grid size.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn cells(&self) -> (usize, usize) {
        (self.cells_x, self.cells_y)
    }
    /// Guide channel count Q.
    pub fn guide_channels(&self) -> usize {
        self.q
    }
    /// Window sizes fitted: 1, or 3 with [`Blur::Adaptive`] (then the blur and
    /// solve stages run per window, `*_at`, and the blend stage follows).
    pub fn scale_count(&self) -> usize {
        self.cfg.blur.scale_count()
    }
    /// `4πσ²` of window `s` in input pixels: its sample count when full
    /// (the adaptive variance estimate).
    pub(crate) fn window_area(&self, s: usize) -> f64 {
        let Blur::Adaptive { sigmas } = self.cfg.blur else { return 0.0 };
        let sigma = sigmas[s] as f64 / self.cfg.upsample as f64;
        4.0 * core::f64::consts::PI * sigma * sigma
    }
    /// Number of tiles of every tiled stage.
    pub fn tile_count(&self) -> usize {
        self.cells_y.div_ceil(TILE_CELL_ROWS)
    }
    /// Cell rows `[start, end)` of tile `t`.
    fn tile_rows(&self, t: usize) -> Result<(usize, usize), Error> {
        if t >= self.tile_count() {
            return Err(Error::InvalidTile { index: t, count: self.tile_count() });
        }
        Ok((t * TILE_CELL_ROWS, ((t + 1) * TILE_CELL_ROWS).min(self.cells_y)))
    }
    /// Output pixel rows `[start, end)` of tile `t`.
    pub fn tile_pixel_rows(&self, t: usize) -> Result<(usize, usize), Error> {
        let (a, b) = self.tile_rows(t)?;
        Ok((a * self.cfg.block, (b * self.cfg.block).min(self.height)))
    }
    /// Where tile `t`'s band lies in `cells` (and `tmp`): tiles are consecutive
    /// row bands, so `&mut cells[range]` is that tile's slice.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn cells_tile_range(&self, t: usize) -> Result<core::ops::Range<usize>, Error> {
        let (a, b) = self.tile_rows(t)?;
        let row = self.cells_x * self.lay.k;
        Ok(a * row..b * row)
    }
    /// Where tile `t`'s band lies in `models`.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn models_tile_range(&self, t: usize) -> Result<core::ops::Range<usize>, Error> {
        let (a, b) = self.tile_rows(t)?;
        let row = self.cells_x * self.ml;
        Ok(a * row..b * row)
    }
    /// f64 values in `cells` (and `tmp`) for tile `t`.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn cells_tile_len(&self, t: usize) -> Result<usize, Error> {
        let (a, b) = self.tile_rows(t)?;
        Ok((b - a) * self.cells_x * self.lay.k)
    }
    /// f32 values in `models` for tile `t`.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn models_tile_len(&self, t: usize) -> Result<usize, Error> {
        let (a, b) = self.tile_rows(t)?;
        Ok((b - a) * self.cells_x * self.ml)
    }
    fn grid_len(&self) -> usize {
        self.cells_x * self.cells_y * self.lay.k
    }
    /// The grid window `s` is fitted on (the block grid, or its 2×2 pooling).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn window_grid(&self, s: usize) -> Result<Grid, Error> {
        Ok(self.grids[self.scale(s)?])
    }
    /// Grid and blur taps (in cells of that grid) of window `s < MAX_SCALES`
    /// (for `s ≥ scale_count()`: window 0's).
    pub(crate) fn window_grid_taps(&self, s: usize) -> (Grid, &Taps) {
        let s = if s < self.scale_count() { s } else { 0 };
        (self.grids[s], &self.taps[s])
    }
    /// Whether window `s` is fitted on the pooled grid: its blur then reads
    /// `pooled` (written by [`Flr::pool_tile`]) instead of `cells`.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn window_pooled(&self, s: usize) -> bool {
        s < self.scale_count() && self.grids[s].factor > 1
    }
    /// The first window fitted on the pooled grid (its tile ranges are those
    /// of `pooled`), if any.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn pooled_window(&self) -> Option<usize> {
        (1..self.scale_count()).find(|&s| self.window_pooled(s))
    }
    /// Cell rows of tile `t` on window `s`'s grid.
    fn window_tile_rows(&self, s: usize, t: usize) -> Result<(usize, usize), Error> {
        let g = self.window_grid(s)?;
        self.tile_rows(t)?;
        Ok(g.tile_rows(t))
    }
    /// Where tile `t` lies in window `s`'s moment grids (`cells` or `pooled`,
    /// `tmp`, `first` / `blurred`): [`Flr::cells_tile_range`] on the block grid.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn window_cells_tile_range(&self, s: usize, t: usize) -> Result<core::ops::Range<usize>, Error> {
        let (a, b) = self.window_tile_rows(s, t)?;
        let row = self.grids[s].cells_x * self.lay.k;
        Ok(a * row..b * row)
    }
    /// f64 values of window `s`'s moment grid (0 past the last window).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn window_grid_len(&self, s: usize) -> usize {
        if s >= self.scale_count() {
            return 0;
        }
        self.grids[s].cell_count() * self.lay.k
    }
    /// Where tile `t` of window `s` lies in `scale_models` (windows one after another).
    /// With [`FlrConfig::adaptive_without_ao`], window 0 holds two models per
    /// cell ([`Flr::fits_per_cell`]).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn scale_models_tile_range(&self, s: usize, t: usize) -> Result<core::ops::Range<usize>, Error> {
        let (a, b) = self.window_tile_rows(s, t)?;
        let row = self.grids[s].cells_x * self.ml * self.fits_per_cell(s);
        let o: usize = (0..s).map(|u| self.grids[u].cell_count() * self.ml * self.fits_per_cell(u)).sum();
        Ok(o + a * row..o + b * row)
    }
    /// Where tile `t` of window `s` lies in `variances` (one f64 per cell of
    /// the window's grid, windows one after another).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn scale_variances_tile_range(&self, s: usize, t: usize) -> Result<core::ops::Range<usize>, Error> {
        let (a, b) = self.window_tile_rows(s, t)?;
        let row = self.grids[s].cells_x * self.fits_per_cell(s);
        let o: usize = (0..s).map(|u| self.grids[u].cell_count() * self.fits_per_cell(u)).sum();
        Ok(o + a * row..o + b * row)
    }
    /// Fits per cell in window `s`'s model and variance grids: 2 for window 0
    /// with [`FlrConfig::adaptive_without_ao`] (per cell its model, then its
    /// AO-free fit's; its variance, then the AO-free fit's), else 1.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn fits_per_cell(&self, s: usize) -> usize {
        1 + usize::from(s == 0 && self.without_guide().is_some())
    }
    /// The guide window 0 is also fitted without ([`FlrConfig::adaptive_without_ao`]: AO).
    /// The AO channel and offset of [`FlrConfig::ao_demodulation`], when it
    /// applies ([`FlrConfig::demodulation`]).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn demodulation(&self) -> Option<(usize, f32)> {
        self.cfg.demodulation()
    }

    fn without_guide(&self) -> Option<usize> {
        self.cfg.guides.ao_channel().filter(|_| self.cfg.adaptive_without_ao && self.scale_count() > 1)
    }
    /// Lengths of the adaptive window's regions: `first`, `blurred`, `pooled`
    /// (f64), `scale_models` (f32), `variances` (f64); all 0 for one window.
    fn adaptive_lens(&self) -> [usize; 5] {
        let n = self.scale_count();
        if n == 1 {
            return [0; 5];
        }
        let blurred = (1..n).map(|s| self.window_grid_len(s)).max().unwrap_or(0);
        let pooled = (1..n).filter(|&s| self.window_pooled(s)).map(|s| self.window_grid_len(s)).max().unwrap_or(0);
        let cells: usize = (0..n).map(|s| self.grids[s].cell_count() * self.fits_per_cell(s)).sum();
        [self.grid_len(), blurred, pooled, cells * self.ml, cells]
    }
    /// f64 values of the adaptive window's extra regions (0 for one window).
    fn adaptive_len(&self) -> usize {
        let [first, blurred, pooled, models, variances] = self.adaptive_lens();
        first + blurred + pooled + models.div_ceil(2) + variances
    }
    fn models_len(&self) -> usize {
        self.cells_x * self.cells_y * self.ml
    }
    /// f32 values of one worker's private buffer.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn worker_len(&self) -> usize {
        // moments in place: colour rows, guide rows that are not planar f32,
        // the edge block gathered; or the gathered band
        let apply = self.q * self.width + 2 * self.cells_x * self.ml + 3 * self.width;
        (self.moments_worker_len() + self.firefly_len()).max(apply)
    }

    /// Worker values the moments take besides the firefly clamp's.
    fn moments_worker_len(&self) -> usize {
        let pw = self.cells_x * self.bin;
        let gathered = BandPlanes::len(self.q, self.bin, pw);
        let in_place = (3 + self.q) * self.bin * self.in_w + BandPlanes::len(self.q, self.bin, self.bin);
        gathered.max(in_place)
    }

    /// Worker values of the firefly clamp: a row of colour and a band's thresholds.
    fn firefly_len(&self) -> usize {
        if self.cfg.fireflies.is_some() {
            3 * self.in_w + fireflies::work_len(self.in_w)
        } else {
            0
        }
    }
    /// Scratch length in f64 elements for `workers` concurrent workers.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn scratch_len_for(&self, workers: usize) -> usize {
        2 * self.grid_len() + self.models_len().div_ceil(2) + (workers.max(1) * self.worker_len()).div_ceil(2) + self.adaptive_len()
    }

    /// Where each region of a `scratch_len_for(workers)` scratch lies, in f64
    /// elements ([`Flr::split_scratch`]'s layout; the f32 regions `models`,
    /// `workers` and `scale_models` are packed two per f64). For callers that
    /// hand regions to concurrent workers through raw pointers (the C API).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn scratch_layout(&self, workers: usize) -> ScratchLayout {
        let mut at = 0;
        let mut next = |len: usize| {
            let r = at..at + len;
            at += len;
            r
        };
        let cells = next(self.grid_len());
        let tmp = next(self.grid_len());
        let models = next(self.models_len().div_ceil(2));
        let workers = next((workers.max(1) * self.worker_len()).div_ceil(2));
        let [nf, nb, np, nm, nv] = self.adaptive_lens();
        let first = next(nf);
        let blurred = next(nb);
        let pooled = next(np);
        let scale_models = next(nm.div_ceil(2));
        let variances = next(nv);
        ScratchLayout { cells, tmp, models, workers, first, blurred, pooled, scale_models, variances }
    }

    /// Splits `scratch` (at least `scratch_len_for(workers)` long) into its regions.
    #[cfg(feature = "internals")]
    #[doc(hidden)]
    pub fn split_scratch<'s>(&self, scratch: &'s mut [f64], workers: usize) -> Result<Parts<'s>, Error> {
        let needed = self.scratch_len_for(workers);
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let l = self.scratch_layout(workers);
        let (cells, rest) = scratch.split_at_mut(l.cells.len());
        let (tmp, rest) = rest.split_at_mut(l.tmp.len());
        let (models, rest) = rest.split_at_mut(l.models.len());
        let models = &mut bytemuck::cast_slice_mut::<f64, f32>(models)[..self.models_len()];
        let (workers_buf, rest) = rest.split_at_mut(l.workers.len());
        let workers = &mut bytemuck::cast_slice_mut::<f64, f32>(workers_buf)[..workers.max(1) * self.worker_len()];
        let (first, rest) = rest.split_at_mut(l.first.len());
        let (blurred, rest) = rest.split_at_mut(l.blurred.len());
        let (pooled, rest) = rest.split_at_mut(l.pooled.len());
        let (scale_models, rest) = rest.split_at_mut(l.scale_models.len());
        let scale_models = &mut bytemuck::cast_slice_mut::<f64, f32>(scale_models)[..self.adaptive_lens()[3]];
        let variances = &mut rest[..l.variances.len()];
        Ok(Parts { cells, tmp, models, workers, first, blurred, pooled, scale_models, variances })
    }

    /// Checks a frame against the plan (sizes, channels, guide set).
    pub fn check_frame<'a>(&self, frame: &Frame<'a>) -> Result<CheckedFrame<'a>, Error> {
        let n = &frame.noisy;
        if (n.width(), n.height()) != (self.in_w, self.in_h) {
            return Err(Error::SizeMismatch { arg: Arg::Noisy, expected: (self.in_w, self.in_h), got: (n.width(), n.height()) });
        }
        if n.channel_count() < 3 {
            return Err(Error::ChannelCount { arg: Arg::Noisy, expected: 3, got: n.channel_count() });
        }
        let set = &self.cfg.guides;
        let map = frame.guides.channel_views(set, self.width, self.height, Arg::Guide)?;
        let fit = match (self.cfg.upsample, &frame.guides_low) {
            (1, None) => map,
            // same resolution: moments from `guides_low`, the model applied to
            // `guides` (FLNR's X'_model and X'_map)
            (1, Some(low)) => low.channel_views(set, self.width, self.height, Arg::GuideLow)?,
            (_, Some(low)) => low.channel_views(set, self.in_w, self.in_h, Arg::GuideLow)?,
            (_, None) if self.q == 0 => map,
            (_, None) => return Err(Error::Unsupported("upsampling needs guides_low at the noisy resolution")),
        };
        if let Some(wv) = frame.sample_weights {
            if (wv.width(), wv.height()) != (self.in_w, self.in_h) {
                return Err(Error::SizeMismatch { arg: Arg::Weights, expected: (self.in_w, self.in_h), got: (wv.width(), wv.height()) });
            }
        }
        Ok(CheckedFrame { noisy: frame.noisy, fit, map, weights: frame.sample_weights })
    }

    /// Stage 0: picks the per-guide reference (the first finite value among
    /// 16 fixed sample positions), so moments are accumulated near zero; with
    /// sample weights, their scale ([`Stats::weight_scale`], one pass over them).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn prepare(&self, frame: &CheckedFrame<'_>) -> Stats {
        let mut st = Stats::default();
        for (q, r) in st.reference.iter_mut().enumerate().take(self.q) {
            let Some(v) = frame.fit[q] else { continue };
            'search: for sy in 0..4 {
                for sx in 0..4 {
                    let x = (2 * sx + 1) * self.in_w / 8;
                    let y = (2 * sy + 1) * self.in_h / 8;
                    if let Some(g) = v.get(x, y, 0) {
                        if g.is_finite() {
                            *r = g;
                            break 'search;
                        }
                    }
                }
            }
        }
        if let Some(wv) = frame.weights {
            st.weight_scale = weight_scale(&wv);
        }
        st
    }

    fn kernel_simd(&self) -> bool {
        self.cfg.kernel == Kernel::Simd
    }

    /// Stage 1: moments of tile `t` into `cells_tile` (`cells_tile_len(t)`).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn moments_tile(
        &self,
        frame: &CheckedFrame<'_>,
        stats: &Stats,
        t: usize,
        cells_tile: &mut [f64],
        worker: &mut [f32],
    ) -> Result<Report, Error> {
        let (r0, r1) = self.tile_rows(t)?;
        if cells_tile.len() != self.cells_tile_len(t)? || worker.len() < self.worker_len() {
            return Err(Error::InvalidTile { index: t, count: self.tile_count() });
        }
        let row_len = self.cells_x * self.lay.k;
        let mut rep = Report::default();
        let mut block_scratch = BlockScratch::default();
        let (worker, clamp_work) = worker.split_at_mut(self.moments_worker_len());
        let mut clamp =
            self.cfg.fireflies.map(|k| FireflyClamp { k, band: None, width: self.in_w, work: &mut clamp_work[..self.firefly_len()] });
        for (j, cells_row) in (r0..r1).zip(cells_tile.chunks_exact_mut(row_len)) {
            rep += if frame.weights.is_none() && self.reads_in_place(j) {
                self.moments_in_place(frame, stats, (t, j), cells_row, worker, &mut block_scratch, clamp.as_mut())?
            } else {
                // (Splitting rows into column chunks to keep the planes in L2 was
                // measured slower: whole rows it is.)
                self.moments_chunk(frame, stats, (t, j, 0, self.cells_x), cells_row, worker, &mut block_scratch, clamp.as_mut())?
            };
        }
        Ok(rep)
    }

    /// Whether cell row `j` is read in place ([`moments_rows`]): SIMD kernel,
    /// a supported block size and every row of the band inside the image.
    fn reads_in_place(&self, j: usize) -> bool {
        self.kernel_simd() && rows_supported(self.bin, self.bin) && (j + 1) * self.bin <= self.in_h
    }

    /// Cell row `j` read in place: colour rows (and guides that are not planar
    /// f32) are copied into `worker`, planar f32 guides are borrowed; whole
    /// blocks go to [`moments_rows`], a partial block at the right edge to the
    /// gathering path.
    #[allow(clippy::too_many_arguments)]
    fn moments_in_place(
        &self,
        frame: &CheckedFrame<'_>,
        stats: &Stats,
        (t, j): (usize, usize),
        cells: &mut [f64],
        worker: &mut [f32],
        block_scratch: &mut BlockScratch,
        mut clamp: Option<&mut FireflyClamp<'_>>,
    ) -> Result<Report, Error> {
        let (bin, w, q) = (self.bin, self.in_w, self.q);
        let bad = Error::InvalidTile { index: t, count: 0 };
        let y0 = j * bin;
        let (colour, rest) = worker.split_at_mut(3 * bin * w);
        let (gathered, edge) = rest.split_at_mut(q * bin * w);
        // the band is the clamp's band (B = 8): its thresholds from each row as it arrives
        let k = clamp.as_deref().map_or(1.0, |c| c.k);
        let mut thresholds = match clamp.as_deref_mut() {
            Some(c) if bin == fireflies::CELL => Some(c.begin(j)?),
            _ => None,
        };
        for (r, rgb) in colour.chunks_exact_mut(3 * w).enumerate() {
            let (p0, p12) = rgb.split_at_mut(w);
            let (p1, p2) = p12.split_at_mut(w);
            frame.noisy.read_row_n(y0 + r, 0, [&mut *p0, &mut *p1, &mut *p2]).ok_or(bad)?;
            if let Some(t) = thresholds.as_mut() {
                t.add_row([p0, p1, p2]);
            }
        }
        if let Some(t) = thresholds {
            t.finish(k);
            if let Some(c) = clamp.as_deref_mut() {
                c.band = Some(j);
            }
        }
        let mut clamped = 0;
        if let Some(c) = clamp.as_deref_mut() {
            // the whole blocks; a partial block at the right edge is clamped as it is gathered
            let wp = (w / bin).min(self.cells_x) * bin;
            for (r, rgb) in colour.chunks_exact_mut(3 * w).enumerate() {
                let (p0, p12) = rgb.split_at_mut(w);
                let (p1, p2) = p12.split_at_mut(w);
                clamped += c.clamp(frame, y0 + r, 0, [&mut p0[..wp], &mut p1[..wp], &mut p2[..wp]])?;
            }
        }
        let mut borrowed = [false; MAX_GUIDES];
        for (g, b) in borrowed.iter_mut().enumerate().take(q) {
            *b = frame.fit[g].ok_or(Error::GuideMismatch)?.row_f32(y0, 0, 0, w).is_some();
        }
        let mut g = 0;
        while g < q {
            if borrowed[g] {
                g += 1;
                continue;
            }
            let band = &mut gathered[g * bin * w..];
            if let Some(m) = merged3(&frame.fit, g, q) {
                // interleaved RGB/RGBA channels g..g + 3: one de-interleaving pass
                let (a, rest) = band.split_at_mut(bin * w);
                let (b, c) = rest.split_at_mut(bin * w);
                for ((a, b), (r, c)) in a.chunks_exact_mut(w).zip(b.chunks_exact_mut(w)).zip(c.chunks_exact_mut(w).enumerate()) {
                    m.read_row_n(y0 + r, 0, [a, b, c]).ok_or(bad)?;
                }
                g += 3;
            } else {
                let v = frame.fit[g].ok_or(Error::GuideMismatch)?;
                for (r, row) in band[..bin * w].chunks_exact_mut(w).enumerate() {
                    v.read_row(y0 + r, 0, 0, row).ok_or(bad)?;
                }
                g += 1;
            }
        }
        // (the AO demodulation is applied as the moments build their colour vectors)
        let planes = [[&[][..]; 3 + MAX_GUIDES]; MAX_ROWS];
        let mut band = BandRows { planes, rows: bin, width: w, reference: stats.reference, demod: self.demodulation() };
        for (r, planes) in band.planes.iter_mut().enumerate().take(bin) {
            for c in 0..3 {
                planes[c] = &colour[(3 * r + c) * w..(3 * r + c + 1) * w];
            }
            for g in 0..q {
                planes[3 + g] = if borrowed[g] {
                    frame.fit[g].and_then(|v| v.row_f32(y0 + r, 0, 0, w)).ok_or(bad)?
                } else {
                    &gathered[(g * bin + r) * w..(g * bin + r + 1) * w]
                };
            }
        }
        let whole = (w / bin).min(self.cells_x);
        let k = self.lay.k;
        let (cells_whole, cells_edge) = cells.split_at_mut(whole * k);
        // While this band's blocks are summed, the next band's noisy rows are
        // asked into L2, a slice before each block, so that their
        // de-interleaving at the start of the next band waits less on memory
        // (1080p Q5 v3, `benches/stages.rs`: moments ~3 % faster with it;
        // asking for the next band's guide rows as well is slower).
        let (next_y0, next_rows) = (y0 + bin, bin.min(self.in_h.saturating_sub(y0 + bin)));
        let noisy = frame.noisy;
        let next_band = |i: usize, n: usize| {
            let total = next_rows * w;
            let (mut a, b) = (total * i / n, total * (i + 1) / n);
            while a < b {
                let (r, x) = (a / w, a % w);
                let len = (w - x).min(b - a);
                noisy.prefetch_span_l2(next_y0 + r, x, len);
                a += len;
            }
        };
        let counts = dispatch_q!(q, moments_rows(&band, bin, cells_whole, block_scratch, next_band));
        let mut rep = Report {
            nonfinite_noisy: counts.nonfinite_noisy as u64,
            nonfinite_guides: counts.nonfinite_guides as u64,
            empty_blocks: counts.empty_blocks as u64,
            clamped_fireflies: clamped as u64,
            ..Report::default()
        };
        if whole < self.cells_x {
            rep += self.moments_chunk(frame, stats, (t, j, whole, self.cells_x - whole), cells_edge, edge, block_scratch, clamp)?;
        }
        Ok(rep)
    }

    /// Gathers input rows of cell row `j` (blocks `c0..c0 + ncx`) into planes and
    /// accumulates their block moments.
    #[allow(clippy::too_many_arguments)]
    fn moments_chunk(
        &self,
        frame: &CheckedFrame<'_>,
        stats: &Stats,
        (t, j, c0, ncx): (usize, usize, usize, usize),
        cells: &mut [f64],
        worker: &mut [f32],
        block_scratch: &mut BlockScratch,
        mut clamp: Option<&mut FireflyClamp<'_>>,
    ) -> Result<Report, Error> {
        let pw = ncx * self.bin; // chunk width (whole blocks)
        let x0 = c0 * self.bin;
        let vw = self.in_w.saturating_sub(x0).min(pw); // pixels inside the image
        let plane = self.bin * pw;
        let buf = &mut worker[..BandPlanes::len(self.q, self.bin, pw)];
        let mut rep = Report::default();
        let np = 4 + self.q;
        let bad = Error::InvalidTile { index: t, count: 0 };
        for r in 0..self.bin {
            let y = j * self.bin + r;
            let o = r * pw;
            if y >= self.in_h {
                // below the image: an empty row (weight 0, values 0)
                for p in 0..np {
                    buf[p * plane + o..p * plane + o + pw].fill(0.0);
                }
                continue;
            }
            for p in 0..np {
                // padding to whole blocks
                buf[p * plane + o + vw..p * plane + o + pw].fill(0.0);
            }
            let (wplane, rest) = buf.split_at_mut(plane);
            let wrow = &mut wplane[o..o + vw];
            match frame.weights {
                // the plane holds √w (`BandPlanes`); 0 for weights that are not finite and positive
                Some(wv) => {
                    wv.read_row(y, 0, x0, wrow).ok_or(bad)?;
                    for v in wrow.iter_mut() {
                        let w = *v as f64 * stats.weight_scale;
                        *v = if *v > 0.0 && w <= f32::MAX as f64 { libm::sqrt(w) as f32 } else { 0.0 };
                    }
                }
                None => wrow.fill(1.0),
            }
            {
                let (colour, guides) = rest.split_at_mut(3 * plane);
                let (p0, p12) = colour.split_at_mut(plane);
                let (p1, p2) = p12.split_at_mut(plane);
                let rgb = [&mut p0[o..o + vw], &mut p1[o..o + vw], &mut p2[o..o + vw]];
                frame.noisy.read_row_n(y, x0, rgb).ok_or(bad)?;
                if let Some(c) = clamp.as_deref_mut() {
                    let rgb = [&mut p0[o..o + vw], &mut p1[o..o + vw], &mut p2[o..o + vw]];
                    rep.clamped_fireflies += c.clamp(frame, y, x0, rgb)? as u64;
                }
                if let Some((ao, c)) = self.demodulation() {
                    // AO's plane gets its raw row first (centred in the loop below)
                    let a = &mut guides[ao * plane + o..ao * plane + o + vw];
                    frame.fit[ao].ok_or(Error::GuideMismatch)?.read_row(y, 0, x0, a).ok_or(bad)?;
                    demodulation::divide_rows([&mut p0[o..o + vw], &mut p1[o..o + vw], &mut p2[o..o + vw]], a, c);
                }
                for p in [&p0[o..o + vw], &p1[o..o + vw], &p2[o..o + vw]] {
                    mask_finite(p, wrow);
                }
            }
            for q in 0..self.q {
                let v = frame.fit[q].ok_or(Error::GuideMismatch)?;
                let dst = &mut rest[(3 + q) * plane + o..(3 + q) * plane + o + vw];
                let m = stats.reference[q];
                // One pass: d = g − m, weight 0 where g is not finite.
                if let Some(src) = v.row_f32(y, 0, x0, vw) {
                    centre_and_mask(src, m, dst, wrow);
                } else {
                    v.read_row(y, 0, x0, dst).ok_or(bad)?;
                    centre_and_mask_in_place(m, dst, wrow);
                }
            }
            if count_zero(wrow) > 0 {
                // rare: count what was not finite and zero those pixels everywhere
                for x in 0..vw {
                    if wrow[x] != 0.0 {
                        continue;
                    }
                    let bad = |p: usize| !rest[p * plane + o + x].is_finite();
                    rep.nonfinite_noisy += (0..3).any(bad) as u64;
                    rep.nonfinite_guides += (3..3 + self.q).any(bad) as u64;
                    for p in 0..3 + self.q {
                        rest[p * plane + o + x] = 0.0;
                    }
                }
            }
        }
        let band = BandPlanes { data: buf, rows: self.bin, width: pw };
        let simd = self.kernel_simd();
        let empty = dispatch_q!(self.q, moments_band(band, self.bin, simd, 0, cells, block_scratch));
        rep.empty_blocks += empty as u64;
        Ok(rep)
    }

    /// Stage 2: frame mean and standard deviation of each guide, from all cells.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn finish_stats(&self, cells: &[f64], stats: &mut Stats) -> Result<(), Error> {
        if cells.len() != self.grid_len() {
            return Err(Error::InvalidTile { index: 0, count: 1 });
        }
        let mut sums = StatsSums::default();
        self.add_stats(cells, &mut sums);
        self.finish_stats_sums(&sums, stats);
        Ok(())
    }

    fn add_stats(&self, cells: &[f64], sums: &mut StatsSums) {
        let l = &self.lay;
        for cell in cells.chunks_exact(l.k) {
            sums.n += cell[0];
            let mut p = l.ss;
            for a in 0..self.q {
                sums.s[a] += cell[l.s + a];
                sums.ss[a] += cell[p];
                p += self.q - a;
            }
        }
    }

    /// Stage 2's end: the mean and standard deviation of each guide from the
    /// sums of every cell.
    fn finish_stats_sums(&self, sums: &StatsSums, stats: &mut Stats) {
        let (n, s, ss) = (sums.n, &sums.s, &sums.ss);
        for a in 0..self.q {
            let (mean, var) = if n > 0.0 { (s[a] / n, ss[a] / n - (s[a] / n) * (s[a] / n)) } else { (0.0, 0.0) };
            // A guide cannot vary by less than f32 resolution of its magnitude.
            let floor = 1e-6 * (stats.reference[a] as f64 + mean).abs();
            let sd = crate::kernels::sqrt(var.max(0.0)).max(floor);
            stats.mean[a] = if mean.is_finite() { mean } else { 0.0 };
            stats.scale[a] = if sd.is_finite() && sd > 0.0 { sd } else { 1.0 };
        }
    }

    /// Stage 3: horizontal blur of tile `t`: `cells` band → `tmp_tile`.
    #[cfg(feature = "internals")]
    #[doc(hidden)]
    pub fn blur_rows_tile(&self, t: usize, cells: &[f64], tmp_tile: &mut [f64]) -> Result<(), Error> {
        self.blur_rows_tile_at(0, t, cells, tmp_tile)
    }

    /// The window index checked against the plan.
    fn scale(&self, s: usize) -> Result<usize, Error> {
        if s < self.scale_count() {
            Ok(s)
        } else {
            Err(Error::InvalidTile { index: s, count: self.scale_count() })
        }
    }

    /// Adaptive window, after stage 1: sums tile `t`'s band of `cells`
    /// (`cells_tile_range(t)`) 2×2 into its band of `pooled`
    /// (`window_cells_tile_range(s, t)` of a pooled window `s`). Moments are
    /// sums, so a pooled cell is exactly the moments of its 2B × 2B pixels.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn pool_tile(&self, t: usize, cells_tile: &[f64], pooled_tile: &mut [f64]) -> Result<(), Error> {
        let bad = Error::InvalidTile { index: t, count: self.tile_count() };
        let s = self.pooled_window().ok_or(bad)?;
        let (k, cx) = (self.lay.k, self.cells_x);
        let (fine, coarse) = (self.tile_rows(t)?, self.window_tile_rows(s, t)?);
        let pcx = self.grids[s].cells_x;
        if cells_tile.len() != self.cells_tile_len(t)? || pooled_tile.len() != (coarse.1 - coarse.0) * pcx * k {
            return Err(bad);
        }
        let rows = fine.1 - fine.0;
        for (r, dst_row) in pooled_tile.chunks_exact_mut(pcx * k).enumerate() {
            dst_row.fill(0.0);
            for fr in (2 * r..(2 * r + 2).min(rows)).map(|fr| &cells_tile[fr * cx * k..(fr + 1) * cx * k]) {
                for (c, src) in fr.chunks_exact(k).enumerate() {
                    let d = &mut dst_row[(c / 2) * k..(c / 2 + 1) * k];
                    for (a, b) in d.iter_mut().zip(src) {
                        *a += b;
                    }
                }
            }
        }
        Ok(())
    }

    /// Stage 3 for window `s` (`s < scale_count()`): `src` is `cells`, or
    /// `pooled` for a pooled window ([`Flr::window_pooled`]); `tmp_tile` is
    /// `window_cells_tile_range(s, t)` of `tmp`.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn blur_rows_tile_at(&self, s: usize, t: usize, src: &[f64], tmp_tile: &mut [f64]) -> Result<(), Error> {
        let (r0, r1) = self.window_tile_rows(self.scale(s)?, t)?;
        let row_len = self.grids[s].cells_x * self.lay.k;
        if src.len() != self.window_grid_len(s) {
            return Err(Error::InvalidTile { index: t, count: self.tile_count() });
        }
        self.blur_rows_band_at(s, t, &src[r0 * row_len..r1 * row_len], tmp_tile)
    }

    /// [`Flr::blur_rows_tile_at`] given tile `t`'s band of `src` alone.
    fn blur_rows_band_at(&self, s: usize, t: usize, band: &[f64], tmp_tile: &mut [f64]) -> Result<(), Error> {
        let taps = &self.taps[self.scale(s)?];
        let (r0, r1) = self.window_tile_rows(s, t)?;
        let row_len = self.grids[s].cells_x * self.lay.k;
        if band.len() != (r1 - r0) * row_len || tmp_tile.len() != (r1 - r0) * row_len {
            return Err(Error::InvalidTile { index: t, count: self.tile_count() });
        }
        for (src, dst) in band.chunks_exact(row_len).zip(tmp_tile.chunks_exact_mut(row_len)) {
            blur_row(taps, self.lay.k, src, dst);
        }
        Ok(())
    }

    /// Stage 4: vertical blur of tile `t`: all of `tmp` → `cells_tile`.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn blur_cols_tile(&self, t: usize, tmp: &[f64], cells_tile: &mut [f64]) -> Result<(), Error> {
        self.blur_cols_tiles(t..t + 1, tmp, cells_tile)
    }

    /// Stage 4 for consecutive tiles `tiles` at once (`cells_band` spans them):
    /// bit-identical to one tile at a time, and each source row of a Gaussian
    /// is fetched from memory fewer times (a tile's 4 rows read 4 + 2r source
    /// rows). The box blur's sliding window still restarts at every tile.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn blur_cols_tiles(&self, tiles: core::ops::Range<usize>, tmp: &[f64], cells_band: &mut [f64]) -> Result<(), Error> {
        self.blur_cols_tiles_at(0, tiles, tmp, cells_band)
    }

    /// [`Flr::blur_cols_tiles`] for window `s` on its grid; `tmp` is that
    /// window's whole row-blurred grid, `out_band` the band of the grid its
    /// solve reads (`cells`, or `first` / `blurred`).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn blur_cols_tiles_at(
        &self,
        s: usize,
        tiles: core::ops::Range<usize>,
        tmp: &[f64],
        out_band: &mut [f64],
    ) -> Result<(), Error> {
        let taps = &self.taps[self.scale(s)?];
        let cells_band = out_band;
        let bad = Error::InvalidTile { index: tiles.end, count: self.tile_count() };
        if tiles.is_empty() {
            return Err(bad);
        }
        let (r0, _) = self.window_tile_rows(s, tiles.start)?;
        let (_, r1) = self.window_tile_rows(s, tiles.end - 1)?;
        let g = self.grids[s];
        let row_len = g.cells_x * self.lay.k;
        if tmp.len() != self.window_grid_len(s) || cells_band.len() != (r1 - r0) * row_len {
            return Err(bad);
        }
        if taps.is_box {
            // The sliding window restarts at each tile (its running sums round
            // differently from a fresh sum), so the box blur goes tile by tile.
            let mut rest = cells_band;
            for t in tiles {
                let (a, b) = g.tile_rows(t);
                let (band, tail) = rest.split_at_mut((b - a) * row_len);
                blur_cols_band(taps, row_len, g.cells_y, a, tmp, band);
                rest = tail;
            }
        } else {
            blur_cols_band(taps, row_len, g.cells_y, r0, tmp, cells_band);
        }
        Ok(())
    }

    /// Total window weight of window `s` (the sum of its 2-D kernel over the
    /// pixels of its cells).
    pub(crate) fn window_weight(&self, s: usize) -> f64 {
        let taps = &self.taps[s];
        let side = (self.bin * self.grids[s].factor) as f64;
        side * side * taps.sum() * taps.sum()
    }

    /// A cell of window `s` whose window weight is at most this is empty.
    pub(crate) fn min_weight(&self, s: usize) -> f64 {
        1e-12 * self.window_weight(s)
    }

    fn solve_params(&self, stats: &Stats, s: usize) -> SolveParams {
        let mut reference = [0f64; MAX_GUIDES];
        for (r, v) in reference.iter_mut().zip(&stats.reference) {
            *r = *v as f64;
        }
        let total = self.window_weight(s);
        SolveParams {
            reference,
            mean: stats.mean,
            scale: stats.scale,
            regularization: self.cfg.regularization,
            weight_norm: 1.0 / total,
            min_weight: self.min_weight(s),
        }
    }

    /// Stage 5: solve every cell of tile `t`: `cells` band → `models_tile`.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn solve_tile(&self, stats: &Stats, t: usize, cells_tile: &[f64], models_tile: &mut [f32]) -> Result<Report, Error> {
        self.solve_tile_at(0, stats, t, cells_tile, models_tile, &mut [])
    }

    /// Stage 5 for window `s`: also writes each cell's variance estimate to
    /// `variances_tile` (one f64 per cell of the tile; empty to skip it).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn solve_tile_at(
        &self,
        s: usize,
        stats: &Stats,
        t: usize,
        cells_tile: &[f64],
        models_tile: &mut [f32],
        variances_tile: &mut [f64],
    ) -> Result<Report, Error> {
        let s = self.scale(s)?;
        let fits = self.fits_per_cell(s);
        let cells_n = self.scale_variances_tile_range(s, t)?.len() / fits;
        if cells_tile.len() != cells_n * self.lay.k
            || models_tile.len() != cells_n * self.ml * fits
            || !(variances_tile.is_empty() || variances_tile.len() == cells_n * fits)
        {
            return Err(Error::InvalidTile { index: t, count: self.tile_count() });
        }
        let p = self.solve_params(stats, s);
        let mut rep = Report::default();
        let (k, ml) = (self.lay.k, self.ml);
        let mut count = |o: CellOutcome| {
            rep.empty_cells += o.empty as u64;
            rep.dropped_pivots += o.dropped as u64;
        };
        // Four cells per f64x4 (bit-identical to one at a time), then the rest.
        let stride = ml * fits;
        let quads = if self.kernel_simd() { cells_tile.len() / (4 * k) } else { 0 };
        let (cq, cr) = cells_tile.split_at(4 * k * quads);
        let (mq, mr) = models_tile.split_at_mut(4 * stride * quads);
        let quad_cells = cq.chunks_exact(4 * k).zip(mq.chunks_exact_mut(4 * stride));
        let rest = cr.chunks_exact(k).zip(mr.chunks_exact_mut(stride));
        match self.without_guide().filter(|_| fits == 2) {
            None => {
                for (cells, models) in quad_cells {
                    dispatch_q!(self.q, solve_cells4(cells, &p, models)).into_iter().for_each(&mut count);
                }
                for (cell, model) in rest {
                    count(dispatch_q!(self.q, solve_cell(cell, &p, model)));
                }
            }
            Some(drop) => {
                for (cells, models) in quad_cells {
                    dispatch_q!(self.q, solve_cells4_without(cells, &p, drop, models)).into_iter().for_each(&mut count);
                }
                for (cell, model) in rest {
                    count(dispatch_q!(self.q, solve_cell_without(cell, &p, drop, model)));
                }
            }
        }
        if !variances_tile.is_empty() {
            let (area, simd) = (self.window_area(s), self.kernel_simd());
            // samples = area · min(n · norm, 1) counts at most `sample_cap` per
            // pixel as (area · cap) · min(n · norm / cap, 1): the same values at 1
            let (area, vp) = (area * self.sample_cap, SolveParams { weight_norm: p.weight_norm / self.sample_cap, ..p });
            dispatch_q!(self.q, variances_of(cells_tile, models_tile, fits, &vp, area, simd, variances_tile));
        }
        Ok(rep)
    }

    /// Adaptive window: blends the three windows' models of tile `t` into
    /// `models_tile`. `first_tile` is window 0's blurred band, `scale_models`
    /// and `variances` the whole window-major grids (a pooled window's model
    /// and variance are interpolated bilinearly to each block-grid cell).
    /// With [`FlrConfig::adaptive_without_ao`], window 0's AO-free fit (made
    /// by its solve, [`Flr::fits_per_cell`]) is blended as a fourth candidate.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn blend_tile(
        &self,
        t: usize,
        first_tile: &[f64],
        scale_models: &[f32],
        variances: &[f64],
        models_tile: &mut [f32],
    ) -> Result<(), Error> {
        let bad = Error::InvalidTile { index: t, count: self.tile_count() };
        let fits: usize = (0..MAX_SCALES).map(|s| self.grids[s].cell_count() * self.fits_per_cell(s)).sum();
        if self.scale_count() != MAX_SCALES
            || first_tile.len() != self.cells_tile_len(t)?
            || scale_models.len() != fits * self.ml
            || variances.len() != fits
            || models_tile.len() != self.models_tile_len(t)?
        {
            return Err(bad);
        }
        let mut windows = [WindowModels { models: &[], variances: &[], grid: self.grids[0], fits: 1 }; MAX_SCALES];
        let (mut mo, mut vo) = (0, 0);
        for (s, (w, g)) in windows.iter_mut().zip(&self.grids).enumerate() {
            let fits = self.fits_per_cell(s);
            let n = g.cell_count() * fits;
            *w = WindowModels { models: &scale_models[mo..mo + n * self.ml], variances: &variances[vo..vo + n], grid: *g, fits };
            mo += n * self.ml;
            vo += n;
        }
        let (r0, _) = self.tile_rows(t)?;
        let candidate = self.fits_per_cell(0) == 2;
        dispatch_q!(self.q, blend_band(first_tile, windows, candidate, r0, self.min_weight(0), self.kernel_simd(), models_tile));
        Ok(())
    }

    /// Stage 6: apply the models to the output rows of tile `t`. `out_band`
    /// holds exactly those rows (`tile_pixel_rows(t)`), numbered from 0.
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[doc(hidden)]
    pub(crate) fn apply_tile(
        &self,
        frame: &CheckedFrame<'_>,
        stats: &Stats,
        t: usize,
        models: &[f32],
        worker: &mut [f32],
        out_band: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        let (y0, y1) = self.tile_pixel_rows(t)?;
        if models.len() != self.models_len() || worker.len() < self.worker_len() {
            return Err(Error::InvalidTile { index: t, count: self.tile_count() });
        }
        if out_band.width() != self.width || out_band.height() != y1 - y0 || out_band.channel_count() < 3 {
            return Err(Error::SizeMismatch {
                arg: Arg::Output,
                expected: (self.width, y1 - y0),
                got: (out_band.width(), out_band.height()),
            });
        }
        let w = self.width;
        let (gbuf, rest) = worker.split_at_mut(self.q * w);
        let (row_models, rest) = rest.split_at_mut(self.cells_x * self.ml);
        let (row_slopes, rest) = rest.split_at_mut(self.cells_x * self.ml);
        let outbuf = &mut rest[..3 * w];
        let mut rep = Report::default();
        let simd = self.kernel_simd();
        let bad = Error::InvalidTile { index: t, count: 0 };
        for y in y0..y1 {
            // Guide rows: borrowed from planar f32 images, else gathered
            // (three interleaved channels in one pass).
            let mut rows: [&[f32]; MAX_GUIDES] = [&[]; MAX_GUIDES];
            let mut gathered = gbuf.chunks_exact_mut(w);
            let mut g = 0;
            while g < self.q {
                let v = frame.map[g].ok_or(Error::GuideMismatch)?;
                let dst = gathered.next().ok_or(bad)?;
                if let Some(r) = v.row_f32(y, 0, 0, w) {
                    rows[g] = r;
                    g += 1;
                } else if let Some(m) = merged3(&frame.map, g, self.q) {
                    let (b, c) = (gathered.next().ok_or(bad)?, gathered.next().ok_or(bad)?);
                    m.read_row_n(y, 0, [&mut *dst, &mut *b, &mut *c]).ok_or(bad)?;
                    (rows[g], rows[g + 1], rows[g + 2]) = (dst, b, c);
                    g += 3;
                } else {
                    v.read_row(y, 0, 0, dst).ok_or(bad)?;
                    rows[g] = dst;
                    g += 1;
                }
            }
            lerp_rows(models, self.cells_x, self.cells_y, self.ml, self.cfg.block, y, row_models, row_slopes);
            let guides = RowGuides { rows, reference: stats.reference, width: w };
            let (clamp, demod) = (self.cfg.clamp_negative, self.demodulation());
            // Interleaved RGB f32 output (the usual case) is written as it is
            // computed; any other layout through three planes and `write_row_n`.
            // Streaming stores need a 16-byte aligned row (then every group of
            // eight pixels is: they start at multiples of four pixels, 48 bytes).
            let band_row = y - y0;
            let direct = match out_band.rgb_row_f32(band_row) {
                Some((dst, false)) => Some(RowOut::Rgb(dst)),
                Some((dst, true)) if (dst.as_ptr() as usize).is_multiple_of(16) => Some(RowOut::RgbStreaming(dst)),
                _ => None,
            };
            let fallback = if let Some(o) = direct {
                dispatch_q!(self.q, apply_row(row_models, row_slopes, self.cells_x, self.cfg.block, guides, clamp, demod, simd, o))
            } else {
                let o = RowOut::Planes(&mut outbuf[..]);
                let f = dispatch_q!(self.q, apply_row(row_models, row_slopes, self.cells_x, self.cfg.block, guides, clamp, demod, simd, o));
                let (r, gb) = outbuf.split_at(w);
                let (g, b) = gb.split_at(w);
                out_band.write_row_n(band_row, 0, [r, g, &b[..w]]).ok_or(bad)?;
                f
            };
            rep.fallback_pixels += fallback as u64;
        }
        Ok(rep)
    }
}

/// The firefly clamp of one moments call ([`crate::fireflies`]): `work` holds
/// a row of colour, then the thresholds of `band`, the clamp band last computed.
struct FireflyClamp<'w> {
    k: f32,
    band: Option<usize>,
    width: usize,
    work: &'w mut [f32],
}

impl FireflyClamp<'_> {
    /// Empty thresholds for `band`, to be filled row by row and finished
    /// (then `band` is set by the caller).
    fn begin(&mut self, band: usize) -> Result<fireflies::Thresholds<'_>, Error> {
        self.band = None;
        let work = &mut self.work[3 * self.width..];
        fireflies::Thresholds::new(work, self.width).ok_or(Error::InvalidTile { index: band, count: 0 })
    }

    /// Clamps row `y`'s pixels `x0..` (`rgb`), computing the thresholds of
    /// its band from the frame unless they are in hand. Returns the count clamped.
    fn clamp(&mut self, frame: &CheckedFrame<'_>, y: usize, x0: usize, rgb: [&mut [f32]; 3]) -> Result<usize, Error> {
        let (w, band) = (self.width, y / fireflies::CELL);
        if self.band != Some(band) {
            let bad = Error::InvalidTile { index: band, count: 0 };
            let (row, work) = self.work.split_at_mut(3 * w);
            let mut t = fireflies::Thresholds::new(work, w).ok_or(bad)?;
            let (a, bc) = row.split_at_mut(w);
            let (b, c) = bc.split_at_mut(w);
            let rows = band * fireflies::CELL..((band + 1) * fireflies::CELL).min(frame.noisy.height());
            for yy in rows {
                frame.noisy.read_row_n(yy, 0, [&mut *a, &mut *b, &mut *c]).ok_or(bad)?;
                t.add_row([a, b, c]);
            }
            t.finish(self.k);
            self.band = Some(band);
        }
        Ok(fireflies::clamp_row(rgb, x0, fireflies::finished(&self.work[3 * w..], w)))
    }
}

/// Guide channels `g..g + 3` of `views` as one view when they are three
/// channels of one interleaved f32 image that is not planar ([`ImageView::merged3`]).
fn merged3<'a>(views: &[Option<ImageView<'a>>; MAX_GUIDES], g: usize, q: usize) -> Option<ImageView<'a>> {
    if g + 3 > q {
        return None;
    }
    let (a, b, c) = (views[g].as_ref()?, views[g + 1].as_ref()?, views[g + 2].as_ref()?);
    ImageView::merged3([a, b, c])
}

/// Each cell's variance estimate ([`adaptive::variance`]; with `simd`, four
/// cells per `f64x4`, bit-identical).
fn variances_of<const Q: usize>(cells: &[f64], models: &[f32], fits: usize, p: &SolveParams, area: f64, simd: bool, out: &mut [f64]) {
    // fit 1 (window 0's AO-free fit) has one coefficient fewer
    if fits == 2 {
        variances_of_n::<Q, 2>(cells, models, [Q + 1, Q], p, area, simd, out);
    } else {
        variances_of_n::<Q, 1>(cells, models, [Q + 1], p, area, simd, out);
    }
}

/// [`variances_of`] with `F` fits per cell (models and variances cell-major).
fn variances_of_n<const Q: usize, const F: usize>(
    cells: &[f64],
    models: &[f32],
    coefficients: [usize; F],
    p: &SolveParams,
    area: f64,
    simd: bool,
    out: &mut [f64],
) {
    let (k, ml) = (CellLayout::new(Q).k, model_len(Q));
    let quads = if simd { out.len() / (4 * F) } else { 0 };
    let (oq, or) = out.split_at_mut(4 * F * quads);
    let (mq, mr) = models.split_at(4 * F * ml * quads);
    for ((cells, models), v) in cells.chunks_exact(4 * k).zip(mq.chunks_exact(4 * F * ml)).zip(oq.chunks_exact_mut(4 * F)) {
        let m = core::array::from_fn(|l| core::array::from_fn(|f| &models[(l * F + f) * ml..(l * F + f + 1) * ml]));
        let lanes = adaptive::variances4::<Q, F>(cells, m, coefficients, p.weight_norm, area, p.min_weight);
        for (f, lanes) in lanes.into_iter().enumerate() {
            for (l, x) in lanes.into_iter().enumerate() {
                v[l * F + f] = x;
            }
        }
    }
    let cells = &cells[4 * quads * k..];
    for ((cell, models), v) in cells.chunks_exact(k).zip(mr.chunks_exact(F * ml)).zip(or.chunks_exact_mut(F)) {
        for f in 0..F {
            v[f] = adaptive::variance::<Q>(cell, &models[f * ml..(f + 1) * ml], coefficients[f], p.weight_norm, area, p.min_weight);
        }
    }
}

/// One window's whole model and variance grids, as the blend reads them.
#[derive(Clone, Copy)]
struct WindowModels<'a> {
    models: &'a [f32],
    variances: &'a [f64],
    grid: Grid,
    /// Fits per cell ([`Flr::fits_per_cell`]; 2 only on the block grid).
    fits: usize,
}

/// Reads one window's model and variance at block-grid cells, visited in
/// row-major order as the blend does. On the block grid they are read; on a
/// pooled grid they are interpolated bilinearly ([`adaptive::pooled_taps`]),
/// separably: each pooled column is interpolated vertically to the block row
/// once and kept for the next block column, which shares it, then two such
/// columns horizontally. Neighbours of weight 0 are skipped, so an empty
/// neighbour's infinite variance makes the interpolated one infinite only
/// where it counts. (Four corners per cell would take about four times as
/// long: ~0.75 ms of a 1080p frame.)
struct WindowReader<'a> {
    win: WindowModels<'a>,
    /// The block row whose vertical taps `ys` hold (`usize::MAX`: none yet).
    row: usize,
    ys: [(usize, f64); 2],
    /// Pooled columns interpolated to `row` (`usize::MAX`: empty slot), with
    /// their models and variances.
    cols: [usize; 2],
    models: [[f32; model_len(MAX_GUIDES)]; 2],
    variances: [f64; 2],
}

impl<'a> WindowReader<'a> {
    fn new(win: WindowModels<'a>) -> Self {
        WindowReader {
            win,
            row: usize::MAX,
            ys: [(0, 0.0); 2],
            cols: [usize::MAX; 2],
            models: [[0.0; model_len(MAX_GUIDES)]; 2],
            variances: [0.0; 2],
        }
    }

    /// The model (into `out`) and variance of this window at block-grid cell `(i, j)`.
    #[inline]
    fn at<const Q: usize>(&mut self, (i, j): (usize, usize), out: &mut [f32]) -> f64 {
        let (g, ml) = (self.win.grid, model_len(Q));
        let out = &mut out[..ml];
        if g.factor == 1 {
            return self.fit::<Q>((i, j), 0, out);
        }
        debug_assert_eq!(self.win.fits, 1, "a pooled window has one fit per cell");
        if i != self.row {
            self.row = i;
            self.ys = adaptive::pooled_taps(i, g.cells_y);
            self.cols = [usize::MAX; 2];
        }
        let [(x0, w0), (x1, w1)] = adaptive::pooled_taps(j, g.cells_x);
        let s0 = self.column::<Q>(x0, x1);
        let s1 = if w1 == 0.0 { s0 } else { self.column::<Q>(x1, x0) };
        let (a, wa) = (&self.models[s0][..ml], w0 as f32);
        if w1 == 0.0 {
            for (o, a) in out.iter_mut().zip(a) {
                *o = wa * a;
            }
            return w0 * self.variances[s0];
        }
        let (b, wb) = (&self.models[s1][..ml], w1 as f32);
        for ((o, a), b) in out.iter_mut().zip(a).zip(b) {
            *o = wa * a + wb * b;
        }
        w0 * self.variances[s0] + w1 * self.variances[s1]
    }

    /// Fit `f` of block-grid cell `(i, j)` of a window on the block grid: its
    /// model (into `out`) and variance.
    #[inline]
    fn fit<const Q: usize>(&self, (i, j): (usize, usize), f: usize, out: &mut [f32]) -> f64 {
        let (ml, fits) = (model_len(Q), self.win.fits);
        let c = (i * self.win.grid.cells_x + j) * fits + f;
        out[..ml].copy_from_slice(&self.win.models[c * ml..(c + 1) * ml]);
        self.win.variances[c]
    }

    /// The slot holding pooled column `x` interpolated to the current row,
    /// filled now if absent, without evicting column `keep`.
    #[inline]
    fn column<const Q: usize>(&mut self, x: usize, keep: usize) -> usize {
        if let Some(s) = self.cols.iter().position(|&c| c == x) {
            return s;
        }
        let s = usize::from(self.cols[0] == keep);
        self.cols[s] = x;
        let (g, ml) = (self.win.grid, model_len(Q));
        let [(y0, w0), (y1, w1)] = self.ys;
        let (c0, c1) = (y0 * g.cells_x + x, y1 * g.cells_x + x);
        let (a, b) = (&self.win.models[c0 * ml..(c0 + 1) * ml], &self.win.models[c1 * ml..(c1 + 1) * ml]);
        let (wa, wb) = (w0 as f32, w1 as f32);
        for ((o, a), b) in self.models[s][..ml].iter_mut().zip(a).zip(b) {
            *o = wa * a + wb * b;
        }
        let (va, vb) = (self.win.variances[c0], self.win.variances[c1]);
        self.variances[s] = if w1 == 0.0 { w0 * va } else { w0 * va + w1 * vb };
        s
    }
}

/// Per cell of a group of four, each candidate's model (window-major as in
/// [`adaptive::blend4`]; room for the most guides).
type CandidateModels = [[[f32; model_len(MAX_GUIDES)]; MAX_CANDIDATES]; 4];

/// The first `N` candidates' models of each of the four cells, `ml` values each.
fn views<const N: usize>(buf: &CandidateModels, ml: usize) -> [[&[f32]; N]; 4] {
    core::array::from_fn(|l| core::array::from_fn(|w| &buf[l][w][..ml]))
}

/// Every candidate's model (into `models`) and variance at block-grid cell
/// `ij`: the three windows', then with `candidate` window 0's AO-free fit.
#[inline(always)]
fn read_candidates<const Q: usize>(
    readers: &mut [WindowReader<'_>; MAX_SCALES],
    candidate: bool,
    ij: (usize, usize),
    models: &mut [[f32; model_len(MAX_GUIDES)]; MAX_CANDIDATES],
) -> [f64; MAX_CANDIDATES] {
    let mut v = [0f64; MAX_CANDIDATES];
    for (w, win) in readers.iter_mut().enumerate() {
        v[w] = win.at::<Q>(ij, &mut models[w]);
    }
    if candidate {
        v[3] = readers[0].fit::<Q>(ij, 1, &mut models[3]);
    }
    v
}

/// Blends one band of cells, whose first row is block-grid row `r0`
/// ([`adaptive::blend`]; with `simd`, four cells per `f64x4`, bit-identical),
/// with window 0's AO-free fit (its second fit per cell) as a fourth
/// candidate when `candidate`.
fn blend_band<const Q: usize>(
    first: &[f64],
    windows: [WindowModels<'_>; 3],
    candidate: bool,
    r0: usize,
    min_weight: f64,
    simd: bool,
    out: &mut [f32],
) {
    let (k, ml) = (CellLayout::new(Q).k, model_len(Q));
    let cx = windows[0].grid.cells_x;
    let n = out.len() / ml;
    let quads = if simd { n / 4 } else { 0 };
    let mut buf: CandidateModels = [[[0f32; model_len(MAX_GUIDES)]; MAX_CANDIDATES]; 4];
    let mut readers = windows.map(WindowReader::new);
    let mut lanes = adaptive::ModelLanes::default();
    for q in 0..quads {
        let mut v = [[0f64; 4]; MAX_CANDIDATES];
        for (l, b) in buf.iter_mut().enumerate() {
            let idx = 4 * q + l;
            let vl = read_candidates::<Q>(&mut readers, candidate, (r0 + idx / cx, idx % cx), b);
            for (w, x) in vl.into_iter().enumerate() {
                v[w][l] = x;
            }
        }
        let cells = &first[4 * q * k..4 * (q + 1) * k];
        let o = &mut out[4 * q * ml..4 * (q + 1) * ml];
        if candidate {
            adaptive::blend4::<Q, 4>(cells, views(&buf, ml), v, min_weight, &mut lanes, o);
        } else {
            adaptive::blend4::<Q, 3>(cells, views(&buf, ml), [v[0], v[1], v[2]], min_weight, &mut lanes, o);
        }
    }
    for idx in 4 * quads..n {
        let (cell, o) = (&first[idx * k..(idx + 1) * k], &mut out[idx * ml..(idx + 1) * ml]);
        let v = read_candidates::<Q>(&mut readers, candidate, (r0 + idx / cx, idx % cx), &mut buf[0]);
        if candidate {
            let m = views::<4>(&buf, ml)[0];
            let gaps = adaptive::prediction_gaps::<Q, 4>(cell, m, min_weight);
            adaptive::blend(m, v, gaps, o);
        } else {
            let m = views::<3>(&buf, ml)[0];
            let gaps = adaptive::prediction_gaps::<Q, 3>(cell, m, min_weight);
            adaptive::blend(m, [v[0], v[1], v[2]], gaps, o);
        }
    }
}
