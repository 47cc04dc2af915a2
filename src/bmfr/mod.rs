//! BMFR — Blockwise Multi-Order Feature Regression (Koskela et al. 2019).
//!
//! Per block of B×B pixels (32×32 by default) the noisy colour is regressed
//! on the features `1, g, g²` (every guide channel, plus the squares of the
//! position channels — or of depth when a frame has no positions) by
//! Householder QR least squares ([`crate::kernels::qr`]), and the fitted model
//! is evaluated on the same block. Differences from the authors' OpenCL code,
//! all deliberate:
//!
//! * positions, depth and user guides are rescaled to `[0, 1]` per block
//!   *before* squaring (`(p − min)/(max − min)` and its square span the same
//!   model space as `p, p²`, without squaring 1e4-sized coordinates in f32),
//!   and always by their range (the original skips the division for ranges
//!   below 1 world unit, which makes the fit depend on the scene's units);
//! * NaN/Inf samples are excluded from the fit (their row is zeroed) and
//!   counted; a pixel whose own guides are not finite gets the block mean;
//! * outliers of the noisy light are clamped as the fit reads them
//!   ([`crate::fireflies`], [`BmfrConfig::fireflies`], on by default): a
//!   firefly would otherwise pull its whole block's model. Each tile measures
//!   the 8-row bands its rows belong to (at full width) and clamps the pixels
//!   its chunks read, so tiles stay independent and bit-identical to the
//!   whole frame;
//! * the fit is shrunk in the QR's orthogonal basis
//!   ([`crate::kernels::qr::Shrinkage`], κ = [`BmfrConfig::shrinkage`], 4 by
//!   default, 0 for the paper's plain least squares): each component of `Qᵀz`
//!   is damped by `q² / (q² + κσ̂²)`, σ̂² the block's residual variance. Ten
//!   features fitted to 1024 one-sample pixels overfit the noise, which the
//!   shrinkage damps; the temporal pipeline, whose accumulated input is less
//!   noisy and so is shrunk less, gains too (`docs/METHODS.md`, BMFR).
//!
//! The block grid shifts every frame by one of 16 offsets ([`BLOCK_OFFSETS`],
//! the original's table, in 1/32 of a block), so temporal accumulation hides
//! the seams; blocks that cross the image border read mirrored pixels.
//! [`Bmfr::denoise`] is the single-frame fit; [`temporal`] adds the
//! paper's pipeline (noisy accumulation → fit → filtered accumulation → TAA).

pub mod features;
pub mod temporal;

use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::{Frame, GuideSet, MAX_GUIDES};
use crate::image::{ImageView, ImageViewMut, RowBands};
use crate::isa::Kernel;
use crate::kernels::qr::{lstsq_shrunk_ld, Shrinkage, MAX_FEATURES};
use crate::parallel::{run_tiles, Executor, TileRun};
use features::{apply_block, gather_block, Band, FeatureSet, Sources};

pub use temporal::History;

/// The grid offsets of the original implementation (in pixels for 32×32
/// blocks; scaled by B/32 for other block sizes), one per frame, cycling.
pub const BLOCK_OFFSETS: [(i32, i32); 16] = [
    (-14, -14),
    (4, -6),
    (-8, 14),
    (8, 0),
    (-10, -8),
    (2, 12),
    (12, -12),
    (-10, 0),
    (12, 14),
    (-8, -16),
    (6, 6),
    (-2, -2),
    (6, -14),
    (-16, 12),
    (14, -4),
    (-6, 4),
];

/// Everything that defines a BMFR run. `BmfrConfig::default()` is the paper's
/// configuration for normal + position guides, plus the shrinkage (κ = 4;
/// `shrinkage: 0.0` is the paper's fit exactly).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BmfrConfig {
    /// Guides the frames carry. Features: 1, every guide channel, and the
    /// squares of the position channels (of depth without positions).
    pub guides: GuideSet,
    /// Block edge B (8..=64, default 32): one model per B×B pixels.
    pub block: usize,
    /// Add the squared features (`false`: first-order BMFR).
    pub quadratic: bool,
    /// Amplitude of the stochastic regularisation: uniform noise in
    /// `[−noise, noise]` added to every non-constant feature for the fit only
    /// (default 0.01, as in the paper). 0 turns it off.
    pub noise: f32,
    /// Back-substitution drops a feature whose pivot is below `pivot_tol` ×
    /// the largest pivot (default 1e-4).
    pub pivot_tol: f32,
    /// κ of the Wiener shrinkage of every block's fit in its QR basis
    /// ([`Shrinkage`]; 0..=100, default 4); 0 is the paper's plain least
    /// squares.
    pub shrinkage: f32,
    /// Shift the block grid every frame by [`BLOCK_OFFSETS`] (default on;
    /// off: blocks start at pixel (0, 0)).
    pub shift: bool,
    /// Clamp negative output to 0.
    pub clamp_negative: bool,
    /// Kernel implementation (SIMD or the scalar oracle).
    pub kernel: Kernel,
    /// Temporal pipeline settings: the shared stage's ([`crate::temporal`];
    /// ignored by the single-frame fit). BMFR's default blends the new
    /// output with weight 0.1 (the paper's filtered accumulation) and clips
    /// at 4 σ: its block fits flicker with the per-frame grid offset, and a
    /// longer, looser output average scored best on the training sequences.
    pub temporal: temporal::TemporalConfig,
    /// The firefly clamp's strength `k` ([`crate::fireflies`]): a noisy
    /// sample whose luminance is above `k` times the larger of the third brightest
    /// 8 × 8 cell of its 104 × 8 pixel neighbourhood and that neighbourhood's
    /// mean without its brightest cell is scaled down to that level
    /// for the fit (the temporal pipeline accumulates each frame's light
    /// clamped). `None` turns it off. Default
    /// `Some(fireflies::DEFAULT_STRENGTH)`; `k ≥ 1`.
    pub fireflies: Option<f32>,
}

impl Default for BmfrConfig {
    fn default() -> Self {
        BmfrConfig {
            guides: GuideSet { normal: true, depth: false, position: true, ao: false, user: 0 },
            block: 32,
            quadratic: true,
            noise: 0.01,
            pivot_tol: 1e-4,
            shrinkage: 4.0,
            shift: true,
            clamp_negative: true,
            kernel: Kernel::Simd,
            temporal: temporal::TemporalConfig { output_alpha: 0.1, clip_gamma: 4.0, ..temporal::TemporalConfig::default() },
            fireflies: Some(fireflies::DEFAULT_STRENGTH),
        }
    }
}

impl BmfrConfig {
    /// The default configuration with these guides.
    pub fn with_guides(guides: GuideSet) -> Self {
        BmfrConfig { guides, ..Default::default() }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), Error> {
        self.guides.validate()?;
        if !(8..=64).contains(&self.block) {
            return Err(Error::InvalidConfig("block (8..=64)"));
        }
        if !(self.noise >= 0.0 && self.noise <= 1.0) {
            return Err(Error::InvalidConfig("noise (0..=1)"));
        }
        if !(self.shrinkage >= 0.0 && self.shrinkage <= 100.0) {
            return Err(Error::InvalidConfig("shrinkage (0..=100)"));
        }
        if !(self.pivot_tol >= 0.0 && self.pivot_tol < 1.0) {
            return Err(Error::InvalidConfig("pivot_tol (0..1)"));
        }
        self.temporal.validate()?;
        if let Some(k) = self.fireflies {
            if !fireflies::valid_strength(k) {
                return Err(Error::InvalidConfig("fireflies strength (must be finite and >= 1)"));
            }
        }
        if FeatureSet::new(&self.guides, self.quadratic).count() > MAX_FEATURES {
            return Err(Error::TooManyGuides { got: self.guides.channels() });
        }
        Ok(())
    }
}

pub use crate::report::Report;

/// A frame checked against the plan: the noisy view and one view per guide channel.
#[derive(Clone, Copy, Debug)]
pub struct CheckedFrame<'a> {
    pub(crate) noisy: ImageView<'a>,
    pub(crate) guides: [Option<ImageView<'a>>; MAX_GUIDES],
}

/// BMFR for one frame size and configuration.
#[derive(Clone, Copy, Debug)]
pub struct Bmfr {
    cfg: BmfrConfig,
    width: usize,
    height: usize,
    fs: FeatureSet,
}

impl Bmfr {
    /// Plans BMFR for `width`×`height` frames.
    pub fn new(cfg: BmfrConfig, width: usize, height: usize) -> Result<Self, Error> {
        cfg.validate()?;
        if width == 0 || height == 0 || width > crate::image::MAX_DIM || height > crate::image::MAX_DIM {
            return Err(Error::InvalidSize { arg: Arg::Output, width, height });
        }
        Ok(Bmfr { cfg, width, height, fs: FeatureSet::new(&cfg.guides, cfg.quadratic) })
    }

    /// The configuration.
    pub fn config(&self) -> &BmfrConfig {
        &self.cfg
    }
    /// Frame size.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }
    /// Number of features M (constant included).
    pub fn feature_count(&self) -> usize {
        self.fs.count()
    }

    /// Top-left pixel of block (0, 0) for frame `index`: in `(−B, 0]`.
    pub fn grid_origin(&self, index: u32) -> (i64, i64) {
        if !self.cfg.shift {
            return (0, 0);
        }
        let b = self.cfg.block as i64;
        let (ox, oy) = BLOCK_OFFSETS[index as usize % BLOCK_OFFSETS.len()];
        let wrap = |o: i32| {
            let o = (o as i64 * b / 32 - b / 2).rem_euclid(b);
            if o == 0 {
                0
            } else {
                o - b
            }
        };
        (wrap(ox), wrap(oy))
    }
    /// Blocks per row and per column for frame `index`.
    pub fn block_grid(&self, index: u32) -> (usize, usize) {
        let (x0, y0) = self.grid_origin(index);
        let b = self.cfg.block;
        ((self.width + (-x0) as usize).div_ceil(b), (self.height + (-y0) as usize).div_ceil(b))
    }
    /// Tiles (block rows) of frame `index`: each can run on its own thread.
    pub fn tile_count(&self, index: u32) -> usize {
        self.block_grid(index).1
    }
    /// Output pixel rows `[start, end)` that tile `t` of frame `index` writes.
    pub fn tile_pixel_rows(&self, index: u32, t: usize) -> Result<(usize, usize), Error> {
        let n = self.tile_count(index);
        if t >= n {
            return Err(Error::InvalidTile { index: t, count: n });
        }
        let y0 = self.grid_origin(index).1 + (t * self.cfg.block) as i64;
        let a = y0.max(0) as usize;
        let b = ((y0 + self.cfg.block as i64).max(0) as usize).min(self.height);
        Ok((a, b))
    }

    /// Blocks whose input pixels are read together (a chunk of about 256
    /// pixels of a tile's rows: long enough row segments for the hardware
    /// prefetchers, small enough, ≈ 300 KB for B = 32, to stay in L2 until
    /// its blocks are fitted and applied).
    fn chunk_blocks(&self) -> usize {
        (256 / self.cfg.block).max(1)
    }
    /// f32 values of one worker's private buffer: one block's QR and model,
    /// a chunk's input pixels (3 + Q planes) and, with the firefly clamp, its
    /// thresholds for the tile ([`Bmfr::clamp_len`]).
    pub fn worker_len(&self) -> usize {
        self.band_offset() + self.band_len() + self.clamp_len()
    }
    /// Where a worker's chunk of input pixels starts.
    fn band_offset(&self) -> usize {
        features::worker_len(self.cfg.block, self.fs.count())
    }
    /// f32 values of a worker's chunk of input pixels.
    fn band_len(&self) -> usize {
        let b = self.cfg.block;
        Band::len(3 + self.fs.q, b, b * self.chunk_blocks())
    }
    /// 8-row bands of the clamp ([`fireflies::CELL`]) that a tile's rows can
    /// touch: B rows, or fewer mirrored ones, span at most this many.
    fn clamp_bands(&self) -> usize {
        self.cfg.block.div_ceil(fireflies::CELL) + 1
    }
    /// f32 values of a worker's firefly clamp (0 when it is off): a row of
    /// colour and the work of one band's thresholds while the tile's bands
    /// are measured, then the thresholds of every band the tile reads.
    pub fn clamp_len(&self) -> usize {
        match self.cfg.fireflies {
            Some(_) => {
                let w = self.width;
                3 * w + fireflies::work_len(w) + self.clamp_bands() * fireflies::cells(w)
            }
            None => 0,
        }
    }
    /// Scratch length (f32) for [`Bmfr::denoise`].
    pub fn scratch_len(&self) -> usize {
        self.worker_len()
    }

    /// Checks a frame against the plan (sizes, channels, guide set).
    pub fn check_frame<'a>(&self, frame: &Frame<'a>) -> Result<CheckedFrame<'a>, Error> {
        let n = &frame.noisy;
        if (n.width(), n.height()) != (self.width, self.height) {
            return Err(Error::SizeMismatch { arg: Arg::Noisy, expected: (self.width, self.height), got: (n.width(), n.height()) });
        }
        if n.channel_count() < 3 {
            return Err(Error::ChannelCount { arg: Arg::Noisy, expected: 3, got: n.channel_count() });
        }
        if frame.guides_low.is_some() {
            return Err(Error::Unsupported("BMFR has no joint upsampling (guides_low given)"));
        }
        if frame.sample_weights.is_some() {
            return Err(Error::Unsupported("BMFR has no per-pixel sample weights (Frame::sample_weights given)"));
        }
        let guides = frame.guides.channel_views(&self.cfg.guides, self.width, self.height, Arg::Guide)?;
        Ok(CheckedFrame { noisy: frame.noisy, guides })
    }

    fn check_out(&self, out: &ImageViewMut<'_>, rows: (usize, usize)) -> Result<(), Error> {
        if out.width() != self.width || out.height() != rows.1 - rows.0 || out.channel_count() < 3 {
            return Err(Error::SizeMismatch {
                arg: Arg::Output,
                expected: (self.width, rows.1 - rows.0),
                got: (out.width(), out.height()),
            });
        }
        Ok(())
    }

    /// Fits and applies every block of tile `t` (a row of blocks) of frame
    /// `index`. `out_band` holds exactly the rows `tile_pixel_rows(index, t)`,
    /// numbered from 0. Tiles are independent: any order, any thread. With
    /// the firefly clamp, the tile measures the whole 8-row bands its rows
    /// belong to and clamps the pixels it reads, so the tiles give the
    /// whole frame's output bit for bit.
    pub fn fit_tile(
        &self,
        frame: &CheckedFrame<'_>,
        index: u32,
        t: usize,
        worker: &mut [f32],
        out_band: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        self.fit_tile_with(frame, index, t, worker, out_band, self.cfg.fireflies)
    }

    /// [`Bmfr::fit_tile`] with the firefly clamp `clamp` (the temporal
    /// pipeline fits its accumulated colour, already clamped, without).
    fn fit_tile_with(
        &self,
        frame: &CheckedFrame<'_>,
        index: u32,
        t: usize,
        worker: &mut [f32],
        out_band: &mut ImageViewMut<'_>,
        clamp: Option<f32>,
    ) -> Result<Report, Error> {
        let rows = self.tile_pixel_rows(index, t)?;
        self.check_out(out_band, rows)?;
        if worker.len() < self.worker_len() {
            return Err(Error::ScratchTooSmall { needed: self.worker_len(), got: worker.len() });
        }
        let (x0, y0) = self.grid_origin(index);
        let b = self.cfg.block;
        let m = self.fs.count();
        let (bx_n, _) = self.block_grid(index);
        let chunk = self.chunk_blocks();
        let (blk, rest) = worker.split_at_mut(self.band_offset());
        let (band_buf, clamp_buf) = rest.split_at_mut(self.band_len());
        let mut wb = features::Worker::split(blk, b, m).ok_or(Error::ScratchTooSmall { needed: self.worker_len(), got: 0 })?;
        let ty0 = y0 + (t * b) as i64;
        features::noise_table(wb.noise, features::seed(index, u32::MAX - t as u32), self.cfg.noise);
        let mut rep = Report::default();
        let tiles = self.tile_count(index);
        let src = Sources::new(frame, self.fs.q)?;
        let clamp = match clamp {
            Some(k) => Some(self.tile_thresholds(frame, ty0, k, clamp_buf)?),
            None => None,
        };
        for c0 in (0..bx_n).step_by(chunk) {
            let blocks = chunk.min(bx_n - c0);
            let mut band = Band { data: &mut band_buf[..Band::len(3 + self.fs.q, b, b * blocks)], rows: b, stride: b * blocks };
            let origin = (x0 + (c0 * b) as i64, ty0);
            band.fill(&src, origin, self.height)?;
            if let Some(c) = &clamp {
                rep.clamped_fireflies += self.clamp_band(&mut band, c, origin)?;
            }
            // the chunk read next (this tile's, else the next tile's first), asked for
            // a few rows per block while this chunk's blocks are fitted (asked for
            // over the first half of them only, it measured slower)
            let next = if c0 + chunk < bx_n { Some((c0 + chunk, ty0)) } else { (t + 1 < tiles).then_some((0, ty0 + b as i64)) };
            for k in 0..blocks {
                // this block's share of the rows, a quarter before each of its stages
                // (in one burst the prefetches waited on the full miss buffers)
                let mut prefetch = |stage: usize| {
                    if let Some((nc, ny)) = next {
                        let (r0, r1) = (k * b / blocks, (k + 1) * b / blocks);
                        let rows = r0 + stage * (r1 - r0) / 4..r0 + (stage + 1) * (r1 - r0) / 4;
                        let stride = b * chunk.min(bx_n - nc);
                        Band::prefetch(&src, (x0 + (nc * b) as i64, ny), stride, rows, self.height);
                    }
                };
                let bx = c0 + k;
                let origin = (x0 + (bx * b) as i64, ty0);
                let block_id = (t * bx_n + bx) as u32;
                rep += self.fit_block(&band, k, index, block_id, origin, &mut wb, rows.0, out_band, &mut prefetch)?;
            }
        }
        Ok(rep)
    }

    /// The firefly clamp's thresholds ([`crate::fireflies`]) of every 8-row
    /// band that the rows `ty0..ty0 + B` of a tile (mirrored into the image)
    /// touch, each measured over all of its rows at full width, as the rule
    /// reads them: stored in `buf` ([`Bmfr::clamp_len`] values).
    fn tile_thresholds<'w>(&self, frame: &CheckedFrame<'_>, ty0: i64, k: f32, buf: &'w mut [f32]) -> Result<TileClamp<'w>, Error> {
        let (w, h) = (self.width, self.height);
        let n = fireflies::cells(w);
        let bad = Error::InvalidTile { index: 0, count: 0 };
        // the mirrored rows of a tile form one run: the pieces meet at the borders
        let (mut lo, mut hi) = (h, 0);
        for j in 0..self.cfg.block {
            let y = features::mirror(ty0 + j as i64, h);
            (lo, hi) = (lo.min(y), hi.max(y + 1));
        }
        let band0 = lo / fireflies::CELL;
        let bands = (hi - 1) / fireflies::CELL + 1 - band0;
        let (row, rest) = buf.split_at_mut(3 * w);
        let (work, store) = rest.split_at_mut(fireflies::work_len(w));
        let store = store.get_mut(..bands * n).ok_or(bad)?;
        let (r, gb) = row.split_at_mut(w);
        let (g, b) = gb.split_at_mut(w);
        for (i, dst) in store.chunks_exact_mut(n).enumerate() {
            let band = band0 + i;
            let mut t = fireflies::Thresholds::new(work, w).ok_or(bad)?;
            for y in band * fireflies::CELL..((band + 1) * fireflies::CELL).min(h) {
                frame.noisy.read_row_n(y, 0, [&mut *r, &mut *g, &mut *b]).ok_or(bad)?;
                t.add_row([r, g, b]);
            }
            for (d, s) in dst.iter_mut().zip(t.finish(k)) {
                *d = *s;
            }
        }
        Ok(TileClamp { band0, cells: n, thresholds: store })
    }

    /// Clamps the noisy colour of a chunk read at `(x0, y0)` ([`Band::fill`])
    /// with the tile's thresholds; pixels mirrored from the image are clamped
    /// as their originals are. Returns the count clamped among the pixels
    /// inside the image (each is read by exactly one tile and chunk).
    fn clamp_band(&self, band: &mut Band<'_>, c: &TileClamp<'_>, (x0, y0): (i64, i64)) -> Result<u64, Error> {
        let (w, h) = (self.width, self.height);
        let (plane, stride) = (band.plane(), band.stride);
        let bad = Error::InvalidTile { index: 0, count: 0 };
        // the columns inside the image, as band offsets
        let ia = ((x0.clamp(0, w as i64) - x0) as usize).min(stride);
        let ib = ((x0 + stride as i64).clamp(0, w as i64) - x0).max(ia as i64) as usize;
        let (p0, rest) = band.data.split_at_mut(plane);
        let (p1, p2) = rest.split_at_mut(plane);
        let mut clamped = 0u64;
        for j in 0..band.rows {
            let yu = y0 + j as i64;
            let y = features::mirror(yu, h);
            let i = (y / fireflies::CELL).checked_sub(c.band0).ok_or(bad)?;
            let th = c.thresholds.get(i * c.cells..(i + 1) * c.cells).ok_or(bad)?;
            let row = j * stride..(j + 1) * stride;
            let (r, g, b) = (&mut p0[row.clone()], &mut p1[row.clone()], &mut p2[row]);
            if ib > ia {
                let n = fireflies::clamp_row([&mut r[ia..ib], &mut g[ia..ib], &mut b[ia..ib]], (x0 + ia as i64) as usize, th);
                if yu >= 0 && (yu as usize) < h {
                    clamped += n as u64;
                }
            }
            for i in (0..ia).chain(ib..stride) {
                let x = features::mirror(x0 + i as i64, w);
                fireflies::clamp_row([&mut r[i..i + 1], &mut g[i..i + 1], &mut b[i..i + 1]], x, th);
            }
        }
        Ok(clamped)
    }

    /// Fits block `k` of the chunk in `band` (top-left pixel `origin`) and
    /// writes its pixels inside the image into `out` (whose row 0 is image
    /// row `row0`). Calls `prefetch(0..4)` before each of its four stages.
    #[allow(clippy::too_many_arguments)]
    fn fit_block(
        &self,
        band: &Band<'_>,
        k: usize,
        index: u32,
        block_id: u32,
        origin: (i64, i64),
        wb: &mut features::Worker<'_>,
        row0: usize,
        out: &mut ImageViewMut<'_>,
        prefetch: &mut dyn FnMut(usize),
    ) -> Result<Report, Error> {
        let b = self.cfg.block;
        let (m, w) = (self.fs.count(), self.width);
        let simd = self.cfg.kernel == Kernel::Simd;
        let mut rep = Report::default();
        prefetch(0);
        let g = gather_block(&self.fs, band, k, (w, self.height), origin, wb)?;
        rep.nonfinite_noisy += g.nonfinite_noisy;
        rep.nonfinite_guides += g.nonfinite_guides;
        let mut coef = [0f32; MAX_FEATURES * 3];
        prefetch(1);
        if g.valid > 0 {
            let dots = features::fit_matrix(&self.fs, band, k, &g, features::seed(index, block_id), wb);
            prefetch(2);
            let shrink = Shrinkage { kappa: self.cfg.shrinkage, samples: g.valid };
            let fit = lstsq_shrunk_ld(wb.a, wb.ld, b * b, m, 3, self.cfg.pivot_tol, simd, shrink, Some(&dots[..m + 3]), &mut coef[..m * 3])
                .ok_or(Error::Unsupported("QR sizes"))?;
            rep.dropped_pivots += fit.dropped.count_ones() as u64;
        } else {
            prefetch(2);
            rep.empty_blocks += 1;
        }
        prefetch(3);
        let ld = wb.ld;
        apply_block(&self.fs, band, k, &coef[..m * 3], &g, wb.guide_ok, self.cfg.clamp_negative, wb.model, ld);
        let xa = origin.0.max(0) as usize;
        let xb = ((origin.0 + b as i64).max(0) as usize).min(w);
        let ya = origin.1.max(0) as usize;
        let yb = ((origin.1 + b as i64).max(0) as usize).min(self.height);
        if xa >= xb {
            return Ok(rep);
        }
        let dx = (xa as i64 - origin.0) as usize;
        let bad = Error::InvalidTile { index: block_id as usize, count: 0 };
        let (p0, rest) = wb.model.split_at(ld);
        let (p1, p2) = rest.split_at(ld);
        for y in ya..yb {
            let r0 = (y as i64 - origin.1) as usize * b + dx;
            let r1 = r0 + (xb - xa);
            out.write_row_n(y - row0, xa, [&p0[r0..r1], &p1[r0..r1], &p2[r0..r1]]).ok_or(bad)?;
            rep.fallback_pixels += wb.guide_ok[r0..r1].iter().filter(|&&ok| ok == 0.0).count() as u64;
        }
        Ok(rep)
    }

    /// Single-frame BMFR: fits every block of frame `index` (which picks the
    /// grid offset and the regularisation noise) on the calling thread.
    /// `scratch`: at least [`Bmfr::scratch_len`] f32. Allocates nothing.
    pub fn denoise(&self, frame: &Frame<'_>, index: u32, scratch: &mut [f32], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        let f = self.check_frame(frame)?;
        self.check_out(out, (0, self.height))?;
        if scratch.len() < self.scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.scratch_len(), got: scratch.len() });
        }
        self.fit_frame(&f, index, scratch, out, self.cfg.fireflies)
    }

    /// f32 values of scratch [`Bmfr::denoise_parallel`] needs for frame
    /// `index` and `workers` workers (`None` if it overflows).
    pub fn parallel_scratch_len(&self, index: u32, workers: usize) -> Option<usize> {
        TileRun::scratch_len(self.tile_count(index), workers.max(1), self.worker_len())
    }

    /// [`Bmfr::denoise`] with the tiles (rows of blocks) spread by the
    /// caller's executor ([`Executor`]), each call with its worker's buffer;
    /// bit-identical to it. `scratch`: at least
    /// [`Bmfr::parallel_scratch_len`] f32; `out` must have rows that do not
    /// overlap in memory. Allocates nothing.
    pub fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        index: u32,
        scratch: &mut [f32],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let f = self.check_frame(frame)?;
        self.check_out(out, (0, self.height))?;
        self.fit_frame_parallel(&f, index, scratch, out, workers, for_each, self.cfg.fireflies)
    }

    /// [`Bmfr::denoise_parallel`] on a checked frame with the firefly clamp `clamp`.
    #[allow(clippy::too_many_arguments)]
    fn fit_frame_parallel(
        &self,
        f: &CheckedFrame<'_>,
        index: u32,
        scratch: &mut [f32],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
        clamp: Option<f32>,
    ) -> Result<Report, Error> {
        let bands =
            RowBands::new(out).ok_or(Error::Unsupported("a parallel run needs an output whose rows do not overlap (use denoise)"))?;
        run_tiles(scratch, self.tile_count(index), workers, self.worker_len(), for_each, &|t, buf| {
            let (a, b) = self.tile_pixel_rows(index, t)?;
            if a == b {
                return Ok(Report::default());
            }
            // SAFETY: each tile runs once (`run_tiles`), tiles write disjoint
            // rows (`tile_pixel_rows`) and rows do not overlap (`RowBands`).
            let mut band = unsafe { bands.band(a, b - a)? };
            self.fit_tile_with(f, index, t, buf, &mut band, clamp)
        })
    }

    fn fit_frame(
        &self,
        f: &CheckedFrame<'_>,
        index: u32,
        worker: &mut [f32],
        out: &mut ImageViewMut<'_>,
        clamp: Option<f32>,
    ) -> Result<Report, Error> {
        let mut rep = Report::default();
        for t in 0..self.tile_count(index) {
            let (a, b) = self.tile_pixel_rows(index, t)?;
            if a == b {
                continue;
            }
            let mut band = out.rows(a, b - a)?;
            rep += self.fit_tile_with(f, index, t, worker, &mut band, clamp)?;
        }
        Ok(rep)
    }
}

/// A tile's firefly thresholds ([`Bmfr::tile_thresholds`]): `cells` per
/// band, from band `band0` on.
#[derive(Debug)]
struct TileClamp<'w> {
    band0: usize,
    cells: usize,
    thresholds: &'w [f32],
}
