//! The temporal stage: reprojection, per-tap rejection, a per-pixel history
//! length, camera-cut detection and the clipped accumulation of an output.
//!
//! A pipeline runs it around a single-frame denoiser:
//!
//! 1. [`Reprojection::accumulate`]: each pixel's previous position is its
//!    position plus `motion` (previous − current, in pixels). Its 4 bilinear
//!    taps into the previous frame are tested against the current pixel's
//!    guides (normal, world position or, without positions, depth); the
//!    accepted taps give the previous accumulated light and sample count.
//!    The new sample is blended in with weight `kept / n`, where `n`, the
//!    history length, grows by `kept` per frame up to
//!    [`TemporalConfig::max_history`] (a cumulative average that becomes an
//!    exponential one) and `kept` is the fraction of the sample the firefly
//!    clamp left ([`crate::fireflies::kept`]): an outlier clamped to a
//!    hundredth counts as a hundredth of a sample. A pixel with no accepted
//!    tap (disocclusion, motion out of the frame) starts again at `n = kept`.
//!    When more than [`TemporalConfig::cut_fraction`] of the pixels have no
//!    accepted tap, the frame is a camera cut and the whole history restarts.
//! 2. The denoiser runs on the accumulated light.
//! 3. [`Reprojection::resolve`]: the previous *output*, reprojected through
//!    the same accepted taps (gathered in step 1, whose taps read the same
//!    records), is clipped to the current output's 3×3
//!    neighbourhood (mean ± [`TemporalConfig::clip_gamma`] standard
//!    deviations, per YCoCg channel) and blended with weight
//!    `max(1/n, output_alpha)` for the new frame.
//!
//! Everything is per pixel, per band of [`fireflies::CELL`] rows (the firefly
//! clamp), or reads a 3×3 neighbourhood of an image the step before wrote in
//! full, so any split into bands of whole clamp bands gives the same bits: the
//! `_parallel` entries run such bands over the caller's [`Executor`].
//! State lives in a caller-owned [`History`] of two slots: a frame reads the
//! slot the previous frame wrote and writes the other, so nothing is copied.

use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::{GuideSet, Guides};
use crate::image::{ImageView, ImageViewMut, RowBands};
use crate::isa::Isa;
use crate::parallel::{run_tiles, Bands, Executor};
use crate::report::Report;
use crate::reproject::{bilinear_taps, rgb, ycocg};

pub use crate::history::History;

#[cfg(feature = "flr")]
pub mod gpu;
mod lanes;

/// Settings of the temporal stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TemporalConfig {
    /// Longest per-pixel history, in frames: the blend weight of a new sample
    /// never drops below `1 / max_history` (default 16).
    pub max_history: f32,
    /// Smallest cosine between a history tap's normal and the current one (default 0.5, 60°).
    pub normal_limit: f32,
    /// Largest world-position distance of a history tap, as a fraction of the
    /// camera distance (default 0.05): the depth where the frame has it, else
    /// estimated from the pixel's footprint (the distance to its left or
    /// right neighbour's position, for a 60° horizontal field of view), so
    /// that a scene's unit does not matter.
    pub position_limit: f32,
    /// Without positions: largest relative depth difference (default 0.05).
    pub depth_limit: f32,
    /// Half-width of the output's clip box in standard deviations (default 1.5).
    pub clip_gamma: f32,
    /// Lowest blend weight of the new output frame in [`Reprojection::resolve`]
    /// (default 0.5; 1 turns the output accumulation off: step 1 then gathers
    /// no previous output and [`Reprojection::run_frame`] skips step 3, so the
    /// history holds none; [`History::reset`] before turning it on for a
    /// history written without it).
    pub output_alpha: f32,
    /// A frame where more than this fraction of pixels has no usable history
    /// is a camera cut: the history restarts (default 0.5; 1 turns it off).
    pub cut_fraction: f32,
    /// With the firefly clamp on: the third brightest cell of a cell's
    /// neighbourhood, the clamp's reference, counts at most this many times
    /// the brightest luminance the previous frame kept in the same
    /// neighbourhood (at the same screen position), so that outliers common
    /// enough to fill three cells of one frame are still clamped (0 or ≥ 1;
    /// default 2; 0 turns it off). The cap rises with the neighbourhood's
    /// mean, so light that brightens as a whole passes; a bright detail that
    /// appears in an unchanged neighbourhood is held to `firefly_history · k`
    /// times the previous frame's brightest there, a factor that compounds
    /// each frame.
    pub firefly_history: f32,
    /// Temporal FLR on cell moments only (the other pipelines ignore it):
    /// the lag test's threshold, in standard errors. A cell whose newest
    /// frames' mean luminance differs from its history's by more than this
    /// restarts from its own moments, so that light that changed (a moving
    /// object's shadow) does not lag (`flr::moment_history`; default 3,
    /// 0 turns the test off; finite ≥ 0).
    pub lag_sigmas: f32,
}

impl Default for TemporalConfig {
    fn default() -> Self {
        TemporalConfig {
            max_history: 16.0,
            normal_limit: 0.5,
            position_limit: 0.05,
            depth_limit: 0.05,
            clip_gamma: 1.5,
            output_alpha: 0.5,
            cut_fraction: 0.5,
            firefly_history: 2.0,
            lag_sigmas: 3.0,
        }
    }
}

impl TemporalConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), Error> {
        if !(self.max_history >= 1.0 && self.max_history <= 1e6) {
            return Err(Error::InvalidConfig("temporal.max_history (1..=1e6)"));
        }
        if !(self.normal_limit >= -1.0 && self.normal_limit <= 1.0) {
            return Err(Error::InvalidConfig("temporal.normal_limit (a cosine, -1..=1)"));
        }
        let pos = |v: f32| v >= 0.0 && v.is_finite();
        if !pos(self.position_limit) || !pos(self.depth_limit) || !pos(self.clip_gamma) {
            return Err(Error::InvalidConfig("temporal limits (≥ 0, finite)"));
        }
        if !(self.output_alpha > 0.0 && self.output_alpha <= 1.0) {
            return Err(Error::InvalidConfig("temporal.output_alpha (0, 1]"));
        }
        if !(self.cut_fraction > 0.0 && self.cut_fraction <= 1.0) {
            return Err(Error::InvalidConfig("temporal.cut_fraction (0, 1]"));
        }
        if !(self.firefly_history == 0.0 || self.firefly_history >= 1.0 && self.firefly_history.is_finite()) {
            return Err(Error::InvalidConfig("temporal.firefly_history (0 or finite >= 1)"));
        }
        if !(self.lag_sigmas >= 0.0 && self.lag_sigmas.is_finite()) {
            return Err(Error::InvalidConfig("temporal.lag_sigmas (finite >= 0)"));
        }
        Ok(())
    }
}

/// Largest motion, in frame sizes, that is taken as a motion vector; longer
/// ones (and NaN/Inf) are counted as invalid and the pixel gets no history.
const MAX_MOTION_FRAMES: f32 = 2.0;

/// `2 tan 30°`: the width of a 60° field of view at distance 1
/// ([`Reprojection::footprint_limit2`]).
const TWO_TAN_30: f32 = 1.154_700_5;

/// The squared pixel footprint of pixel `x` of a row whose record is `row`
/// (fields `w` apart; the position's x, y, z at `p_at`): the smaller squared
/// distance from its position to its left and right neighbours' (the one on
/// the same surface, at an edge), of those that are finite; 0 without one,
/// which keeps only taps at the very same position. The pixel groups compute
/// the same in lanes, bit for bit.
fn footprint2(row: &[f32], p_at: usize, w: usize, x: usize) -> f32 {
    let p = |x: usize, c: usize| row[(p_at + c) * w + x];
    let d2 = |n: usize| {
        let e = [p(n, 0) - p(x, 0), p(n, 1) - p(x, 1), p(n, 2) - p(x, 2)];
        let d = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
        if d.is_finite() {
            d
        } else {
            f32::INFINITY
        }
    };
    let left = if x > 0 { d2(x - 1) } else { f32::INFINITY };
    let right = if x + 1 < w { d2(x + 1) } else { f32::INFINITY };
    let m = left.min(right);
    if m.is_finite() {
        m
    } else {
        0.0
    }
}

// The fields of a history slot: accumulated light (3), history length (1),
// output (3), then the rejection guides (normal 3, position 3, depth 1:
// those present). A slot row holds each field's row of `w` values in turn
// (row `y`, field `f`, pixel `x` at `(y · fields + f) · w + x`): a band of
// rows is one contiguous range, the light reads as a planar image, and a
// pass that writes some fields (step 3 writes only the output) touches
// only their cache lines.
const LIGHT: usize = 0;
const COUNT: usize = 3;
const OUTPUT: usize = 4;
const GUIDES: usize = 7;

/// What the stage did in one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Pixels without usable history (the first frame and cut frames are not counted).
    pub rejected: u64,
    /// Pixels whose motion vector was NaN/Inf or longer than twice the frame
    /// (counted in a cut frame too).
    pub invalid_motion: u64,
    /// Pixels whose noisy light was NaN/Inf (bridged with the history where there is one).
    pub nonfinite: u64,
    /// Samples the firefly clamp lowered.
    pub clamped: u64,
    /// 1 when this frame was taken as a camera cut (the history restarted).
    pub cut: u64,
}

/// `e` about `arg` instead.
fn with_arg(e: Error, arg: Arg) -> Error {
    match e {
        Error::SizeMismatch { expected, got, .. } => Error::SizeMismatch { arg, expected, got },
        Error::ChannelCount { expected, got, .. } => Error::ChannelCount { arg, expected, got },
        e => e,
    }
}

/// The inputs of [`Reprojection::accumulate`] for one frame.
#[derive(Clone, Copy, Debug)]
pub struct Inputs<'a> {
    /// The noisy light (3 channels).
    pub noisy: ImageView<'a>,
    /// The firefly clamp's factor `k` ([`crate::fireflies`]): the light is
    /// clamped band by band as step 1 reads it, and a clamped sample enters
    /// the history weighted by the fraction of it the clamp kept; `None`:
    /// the light as it is.
    pub fireflies: Option<f32>,
    /// The frame's guides (those of the plan's [`GuideSet`] are read).
    pub guides: Guides<'a>,
    /// Previous − current pixel position (2 channels); `None`: a static camera.
    pub motion: Option<ImageView<'a>>,
}

/// What step 1 reads of the previous frame: its slot's records and the
/// largest clamped luminance of each of its clamp cells.
#[derive(Clone, Copy)]
struct Previous<'a> {
    records: &'a [f32],
    cells: &'a [f32],
}

/// What step 1 reads for one row of pixels: the previous frame's records and
/// the row's light (as read and clamped) and motion, each channel a plane of
/// the row.
struct Row<'a> {
    y: usize,
    read: &'a [f32],
    raw: &'a [f32],
    cur: &'a [f32],
    mv: &'a [f32],
    /// The firefly clamp is on (`cur` is the clamped `raw`).
    clamped: bool,
    has_history: bool,
}

/// What step 3 reads for one row `y`: the ring of rows `y - 1 ..= y + 1`
/// (offsets of their slots, `rows` of them within the frame) and the
/// reprojected previous output of the row (3 planes, NaN without history).
struct ResolveRow<'a> {
    ring: &'a [f32],
    slots: [usize; 3],
    rows: usize,
    cur: usize,
    prev: &'a [f32],
    blend: bool,
    clamp_negative: bool,
}

/// The temporal stage of one frame size and guide set.
#[derive(Clone, Copy, Debug)]
pub struct Reprojection {
    cfg: TemporalConfig,
    width: usize,
    height: usize,
    normal: bool,
    position: bool,
    depth: bool,
    /// Steps 1 and 3 on groups of pixels in these lanes where they qualify
    /// ([`lanes`]); `None`: every pixel on its own (the reference the groups
    /// are tested against).
    lanes: Option<Isa>,
}

/// Values per pixel [`Reprojection::accumulate`] leaves for
/// [`Reprojection::resolve`] in the caller's scratch: the previous output
/// reprojected through the accepted taps (NaN where none was), row `y`,
/// channel `c`, pixel `x` at `(3y + c) · w + x`.
const PIXEL_VALUES: usize = 3;
/// Rows of working space in the scratch (step 1: the raw and the clamped
/// light of one band of [`fireflies::CELL`] rows and a row of motion; step
/// 3 needs fewer), besides the clamp's [`fireflies::work_len`].
const ROWS: usize = 6 * fireflies::CELL + 2;
/// Planes of a row in step 3's ring: the row's RGB, the horizontal 3-sums
/// of its YCoCg and those of their squares.
const RING_PLANES: usize = 9;
/// Rows of step 3's working space: a ring of 3 rows, and an output row (3 planes).
const RESOLVE_ROWS: usize = 3 * RING_PLANES + 3;

impl Reprojection {
    /// The stage for `width × height` frames whose guides include those of
    /// `guides` that it uses for rejection (normal, position, depth).
    pub fn new(cfg: TemporalConfig, guides: GuideSet, width: usize, height: usize) -> Result<Self, Error> {
        cfg.validate()?;
        if width == 0 || height == 0 || width > crate::image::MAX_DIM || height > crate::image::MAX_DIM {
            return Err(Error::InvalidSize { arg: Arg::Output, width, height });
        }
        Ok(Reprojection {
            cfg,
            width,
            height,
            normal: guides.normal,
            position: guides.position,
            depth: guides.depth,
            lanes: Some(Isa::detect_widest()),
        })
    }
    /// The same stage with steps 1 and 3 run pixel by pixel: the reference
    /// its pixel groups are tested against (the same bits).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[allow(dead_code)]
    fn per_pixel(self) -> Self {
        Reprojection { lanes: None, ..self }
    }
    /// The same stage with its pixel groups in the lanes of `isa` (`None` if
    /// this build cannot run them on this CPU).
    #[cfg_attr(feature = "internals", visibility::make(pub))]
    #[allow(dead_code)]
    fn with_isa(self, isa: Isa) -> Option<Self> {
        isa.available().then_some(Reprojection { lanes: Some(isa), ..self })
    }
    /// The guides history taps are tested against (normal, position, depth).
    pub fn rejection_guides(&self) -> GuideSet {
        GuideSet { normal: self.normal, position: self.position, depth: self.depth, ..GuideSet::NONE }
    }
    /// The settings.
    pub fn config(&self) -> &TemporalConfig {
        &self.cfg
    }
    fn plane(&self) -> usize {
        self.width * self.height
    }
    fn guide_planes(&self) -> usize {
        3 * self.normal as usize + 3 * self.position as usize + self.depth as usize
    }
    fn record(&self) -> usize {
        GUIDES + self.guide_planes()
    }
    /// Values per cell of the firefly clamp's bands: each slot ends with the
    /// largest luminance of each cell of that frame's clamped light, then
    /// each cell's neighbourhood mean (the clamp's mean term).
    fn cells_len(&self) -> usize {
        2 * fireflies::cells(self.width) * self.height.div_ceil(fireflies::CELL)
    }
    /// f32 values of one of the history's two slots (a frame's records and
    /// its clamp cells): the history is slot 0, then slot 1.
    pub fn slot_len(&self) -> usize {
        self.record() * self.plane() + self.cells_len()
    }
    /// f32 values of the [`History`] buffer: two slots.
    pub fn history_len(&self) -> usize {
        2 * self.slot_len()
    }
    /// f32 values of the scratch [`Reprojection::accumulate`] and
    /// [`Reprojection::resolve`] share: 3 values per pixel (none without
    /// output accumulation) and a worker's rows.
    pub fn scratch_len(&self) -> usize {
        self.pixel_values() * self.plane() + self.rows_len()
    }
    /// Values per pixel step 1 leaves for step 3 in the scratch
    /// ([`PIXEL_VALUES`]); none without output accumulation, which gathers
    /// no previous output.
    fn pixel_values(&self) -> usize {
        if self.accumulates_output() {
            PIXEL_VALUES
        } else {
            0
        }
    }
    /// f32 of working space per worker.
    fn rows_len(&self) -> usize {
        ROWS * self.width + fireflies::work_len(self.width) + fireflies::cells(self.width)
    }
    /// f32 values of the scratch of the `_parallel` entries with `workers`:
    /// 3 values per pixel (none without output accumulation), rows per
    /// worker and the run's bookkeeping.
    pub fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let runs = crate::parallel::TileRun::scratch_len(self.bands(workers), workers, self.rows_len())?;
        (self.pixel_values() * self.plane()).checked_add(runs)
    }
    /// Rows per band of a parallel run: whole bands of the firefly clamp.
    fn band_rows(&self, workers: usize) -> usize {
        (self.height / (8 * workers.max(1))).max(16).next_multiple_of(fireflies::CELL)
    }
    fn bands(&self, workers: usize) -> usize {
        self.height.div_ceil(self.band_rows(workers))
    }

    /// Checks the history buffer's size; a buffer from another frame size or
    /// guide set is refused here.
    pub fn check_history(&self, history: &History<'_>) -> Result<(), Error> {
        if history.data.len() != self.history_len() {
            return Err(Error::BufferTooSmall { arg: Arg::History, needed: self.history_len(), len: history.data.len() });
        }
        Ok(())
    }

    /// The records of the two slots of the history: (read, write) for the frame `history.frames`.
    fn slots<'h>(&self, history: &'h mut History<'_>) -> (&'h [f32], &'h mut [f32]) {
        let (read, _, write, _) = self.slots_and_cells(history);
        (read, write)
    }

    /// The two slots as (read records, read cells, write records, write cells).
    #[allow(clippy::type_complexity)]
    fn slots_and_cells<'h>(&self, history: &'h mut History<'_>) -> (&'h [f32], &'h [f32], &'h mut [f32], &'h mut [f32]) {
        let n = self.slot_len();
        let (a, b) = history.data.split_at_mut(n);
        let (read, write) = if history.frames.is_multiple_of(2) { (&b[..n], &mut a[..n]) } else { (&a[..n], &mut b[..n]) };
        let records = self.record() * self.plane();
        let (rr, rc) = read.split_at(records);
        let (wr, wc) = write.split_at_mut(records);
        (rr, rc, wr, wc)
    }

    /// The accumulated light of the frame as [`Reprojection::accumulate`]
    /// wrote it into the history's write slot, as a view the denoiser reads
    /// (3 channels, each channel's row `w` values after the previous one's).
    pub fn accumulated<'h>(&self, history: &'h mut History<'_>) -> Result<ImageView<'h>, Error> {
        Ok(self.accumulated_and_lengths(history)?.0)
    }

    /// The history length of each pixel as step 1 wrote it into the
    /// history's write slot (1 channel), for a fit that weighs pixels by it.
    pub fn history_lengths<'h>(&self, history: &'h mut History<'_>) -> Result<ImageView<'h>, Error> {
        Ok(self.accumulated_and_lengths(history)?.1)
    }

    /// [`Reprojection::accumulated`] and [`Reprojection::history_lengths`].
    fn accumulated_and_lengths<'h>(&self, history: &'h mut History<'_>) -> Result<(ImageView<'h>, ImageView<'h>), Error> {
        let (w, h) = (self.width, self.height);
        let rec = self.record();
        self.check_history(history)?;
        let (_, write) = self.slots(history);
        let write: &'h [f32] = write;
        let view = |f: usize, ch: usize| {
            let layout = crate::image::Layout { offset: f * w, pixel_stride: 1, row_stride: rec * w, channel_stride: w };
            ImageView::f32(write, w, h, ch, layout)
        };
        Ok((view(LIGHT, 3)?, view(COUNT, 1)?))
    }

    /// Step 1 for the whole frame: reads the inputs, writes the accumulated
    /// light, the history length and the guides into the history's write slot
    /// and, with the output accumulation on, the reprojected previous output
    /// into `scratch` ([`Reprojection::scratch_len`]). A camera cut is detected here (and
    /// the pass rerun without history).
    pub fn accumulate(&self, inp: &Inputs<'_>, history: &mut History<'_>, scratch: &mut [f32]) -> Result<Counts, Error> {
        self.check_inputs(inp)?;
        self.check_history(history)?;
        if scratch.len() < self.scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.scratch_len(), got: scratch.len() });
        }
        let has_history = history.frames > 0;
        let (pixels, rows) = scratch.split_at_mut(self.pixel_values() * self.plane());
        let (read, read_cells, write, write_cells) = self.slots_and_cells(history);
        let prev = Previous { records: read, cells: read_cells };
        let c = self.accumulate_rows(inp, prev, 0, write, write_cells, pixels, rows, has_history)?;
        if self.is_cut(has_history, &c) {
            let again = self.accumulate_rows(inp, prev, 0, write, write_cells, pixels, rows, false)?;
            return Ok(Counts { invalid_motion: c.invalid_motion, cut: 1, ..again });
        }
        Ok(c)
    }

    /// [`Reprojection::accumulate`] in row bands over the caller's executor
    /// (`scratch`: [`Reprojection::parallel_scratch_len`]); the same bits.
    pub fn accumulate_parallel(
        &self,
        inp: &Inputs<'_>,
        history: &mut History<'_>,
        scratch: &mut [f32],
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Counts, Error> {
        self.check_inputs(inp)?;
        self.check_history(history)?;
        let needed = self.parallel_scratch_len(workers).ok_or(Error::InvalidConfig("workers: scratch size overflows"))?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let has_history = history.frames > 0;
        let (w, rec) = (self.width, self.record());
        let (rows, nb) = (self.band_rows(workers), self.bands(workers));
        let (pixels, runs) = scratch.split_at_mut(self.pixel_values() * self.plane());
        let (read, read_cells, write, write_cells) = self.slots_and_cells(history);
        let prev = Previous { records: read, cells: read_cells };
        let nc = fireflies::cells(w);
        let mut pass = |has_history: bool| -> Result<Counts, Error> {
            let (wb, pb) = (Bands::new(&mut *write, rows * w * rec), Bands::new(&mut *pixels, rows * w * self.pixel_values()));
            let cb = Bands::new(&mut *write_cells, 2 * rows / fireflies::CELL * nc);
            // SAFETY: `run_tiles` runs each band once, and a band writes only its own rows of each buffer.
            let r = run_tiles(runs, nb, workers, self.rows_len(), for_each, &|b, buf| {
                let c = unsafe { self.accumulate_rows(inp, prev, b * rows, wb.get(b), cb.get(b), pb.get(b), buf, has_history)? };
                Ok(Report {
                    history_rejected: c.rejected,
                    invalid_motion: c.invalid_motion,
                    nonfinite_noisy: c.nonfinite,
                    clamped_fireflies: c.clamped,
                    ..Report::default()
                })
            })?;
            Ok(Counts {
                rejected: r.history_rejected,
                invalid_motion: r.invalid_motion,
                nonfinite: r.nonfinite_noisy,
                clamped: r.clamped_fireflies,
                cut: 0,
            })
        };
        let c = pass(has_history)?;
        if self.is_cut(has_history, &c) {
            let again = pass(false)?;
            return Ok(Counts { invalid_motion: c.invalid_motion, cut: 1, ..again });
        }
        Ok(c)
    }

    /// f32 values a pipeline frame ([`Reprojection::run_frame`]) needs: the
    /// stage's scratch (for `workers`, or one thread with `None`) and, with
    /// output accumulation, the fit's RGB output (without, the fit writes the
    /// output itself). `None` if it overflows.
    pub fn frame_scratch_len(&self, workers: Option<usize>) -> Option<usize> {
        let stage = match workers {
            Some(n) => self.parallel_scratch_len(n)?,
            None => self.scratch_len(),
        };
        stage.checked_add(self.fitted_len())
    }
    /// f32 values of the fit's RGB output in a pipeline frame's scratch.
    fn fitted_len(&self) -> usize {
        if self.accumulates_output() {
            3 * self.plane()
        } else {
            0
        }
    }

    /// One frame of a temporal pipeline around a single-frame denoiser:
    /// accumulates `noisy`, clamped with `fireflies` (step 1), calls
    /// `fit(accumulated, history_lengths, frame_index, fitted)` (step 2: the
    /// denoiser on the accumulated light, into an RGB image of the frame's size) and resolves
    /// into `out` (step 3). `parallel`: the workers and executor of both
    /// passes (the fit brings its own). The report holds the stage's counts
    /// and the fit's, but for its NaN/Inf noisy samples (the stage counted,
    /// and bridged, those). Without output accumulation
    /// ([`Reprojection::accumulates_output`] false) step 3 would only copy
    /// the fit's output, zeroing non-finite values and, with
    /// `clamp_negative`, negative ones; it is skipped, and the fit writes
    /// `out`, whose values are then the fit's as they are: `clamp_negative`
    /// does not apply and non-finite values pass (FLR's, BMFR's and WALR's
    /// fits clamp with the same setting and write finite values, so their
    /// output is step 3's but for the sign of a zero).
    #[allow(clippy::too_many_arguments)]
    pub fn run_frame(
        &self,
        noisy: ImageView<'_>,
        guides: Guides<'_>,
        motion: Option<ImageView<'_>>,
        fireflies: Option<f32>,
        clamp_negative: bool,
        history: &mut History<'_>,
        scratch: &mut [f32],
        parallel: Option<(usize, Executor<'_>)>,
        out: &mut ImageViewMut<'_>,
        fit: impl FnOnce(ImageView<'_>, ImageView<'_>, u32, &mut ImageViewMut<'_>) -> Result<Report, Error>,
    ) -> Result<Report, Error> {
        let (w, h) = (self.width, self.height);
        self.check_history(history)?;
        if parallel.is_some() && !out.rows_are_separable() {
            // checked before any work: the parallel passes write the output in row bands
            return Err(Error::Unsupported("a parallel run needs an output whose rows do not overlap (use the sequential call)"));
        }
        let overflow = Error::InvalidConfig("workers: scratch size overflows");
        let needed = self.frame_scratch_len(parallel.map(|p| p.0)).ok_or(overflow)?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let (stage, rest) = scratch.split_at_mut(needed - self.fitted_len());
        let fitted = &mut rest[..self.fitted_len()];
        let mut rep = Report::default();
        let inputs = Inputs { noisy, fireflies, guides, motion };
        let c = match parallel {
            Some((workers, for_each)) => self.accumulate_parallel(&inputs, history, stage, workers, for_each)?,
            None => self.accumulate(&inputs, history, stage)?,
        };
        rep.history_rejected = c.rejected;
        rep.invalid_motion = c.invalid_motion;
        rep.history_resets = c.cut;
        rep.nonfinite_noisy = c.nonfinite;
        rep.clamped_fireflies = c.clamped;
        let index = history.frames;
        // without output accumulation step 3 would only copy the fit's
        // output: the fit writes `out` itself
        let accumulates = self.accumulates_output();
        if !accumulates {
            self.check_output(out)?;
        }
        {
            let (acc, lengths) = self.accumulated_and_lengths(history)?;
            let r = if accumulates {
                fit(acc, lengths, index, &mut ImageViewMut::interleaved(fitted, w, h, 3)?)?
            } else {
                fit(acc, lengths, index, out)?
            };
            rep += Report { nonfinite_noisy: 0, ..r };
        }
        if !accumulates {
            history.frames = next_frame(history.frames);
            return Ok(rep);
        }
        match parallel {
            Some((workers, for_each)) => {
                self.resolve_parallel(fitted, history, stage, c.cut != 0, clamp_negative, out, workers, for_each)?
            }
            None => self.resolve(fitted, history, stage, c.cut != 0, clamp_negative, out)?,
        }
        Ok(rep)
    }

    fn is_cut(&self, has_history: bool, c: &Counts) -> bool {
        has_history && c.rejected as f64 > self.cfg.cut_fraction as f64 * self.plane() as f64
    }

    fn check_inputs(&self, inp: &Inputs<'_>) -> Result<(), Error> {
        let (w, h) = (self.width, self.height);
        let size = |v: &ImageView<'_>, ch: usize| {
            if (v.width(), v.height()) != (w, h) {
                return Err(Error::SizeMismatch { arg: Arg::Guide, expected: (w, h), got: (v.width(), v.height()) });
            }
            if v.channel_count() < ch {
                return Err(Error::ChannelCount { arg: Arg::Guide, expected: ch, got: v.channel_count() });
            }
            Ok(())
        };
        size(&inp.noisy, 3).map_err(|e| with_arg(e, Arg::Noisy))?;
        if let Some(m) = &inp.motion {
            size(m, 2).map_err(|e| with_arg(e, Arg::Motion))?;
        }
        for (want, view, ch) in
            [(self.normal, &inp.guides.normal, 3), (self.position, &inp.guides.position, 3), (self.depth, &inp.guides.depth, 1)]
        {
            match view {
                Some(v) if want => size(v, ch)?,
                None if want => return Err(Error::GuideMismatch),
                _ => {}
            }
        }
        if inp.fireflies.is_some_and(|k| !fireflies::valid_strength(k)) {
            return Err(Error::InvalidConfig("fireflies strength (must be finite and >= 1)"));
        }
        Ok(())
    }

    /// Step 1 for rows `y0..` of the frame: `write` and `pixels` hold those
    /// rows' records and per-pixel values (as many rows as `write` holds);
    /// `rows`: the working space of one worker.
    #[allow(clippy::too_many_arguments)]
    fn accumulate_rows(
        &self,
        inp: &Inputs<'_>,
        prev: Previous<'_>,
        y0: usize,
        write: &mut [f32],
        write_cells: &mut [f32],
        pixels: &mut [f32],
        rows: &mut [f32],
        has_history: bool,
    ) -> Result<Counts, Error> {
        let read = prev.records;
        let pv = self.pixel_values();
        const CELL: usize = fireflies::CELL;
        let (w, h) = (self.width, self.height);
        let cfg = &self.cfg;
        let rec = self.record();
        let n_rows = write.len() / (w * rec);
        let short = pixels.len() < n_rows * w * pv || rows.len() < self.rows_len();
        // the clamp measures whole bands of CELL rows: a band of rows starts on one
        if y0 + n_rows > h || !y0.is_multiple_of(CELL) || short {
            return Err(Error::InvalidTile { index: y0, count: h });
        }
        // one band's light as read (`raw`) and clamped (`light`), row i channel ch at (3i + ch) w
        let (raw, rest) = rows.split_at_mut(3 * CELL * w);
        let (light, rest) = rest.split_at_mut(3 * CELL * w);
        let (mv, rest) = rest.split_at_mut(2 * w);
        let nc = fireflies::cells(w);
        // the clamp's caps from the previous frame
        let (caps, work) = rest.split_at_mut(nc);
        let capped = has_history && cfg.firefly_history > 0.0;
        let bad = Error::InvalidTile { index: 0, count: h };
        let mut c = Counts::default();
        for band in (y0..y0 + n_rows).step_by(CELL) {
            let band_rows = CELL.min(h - band);
            for (i, rgb) in raw.chunks_exact_mut(3 * w).take(band_rows).enumerate() {
                let (r, gb) = rgb.split_at_mut(w);
                let (g, b) = gb.split_at_mut(w);
                inp.noisy.read_row_n(band + i, 0, [r, g, b]).ok_or(bad)?;
            }
            // this cell row's maxima and means, and the previous frame's
            let cr = (band - y0) / CELL;
            let (maxima_out, means_out) = write_cells.get_mut(2 * cr * nc..2 * (cr + 1) * nc).ok_or(bad)?.split_at_mut(nc);
            let prev_cells = prev.cells.get(2 * (band / CELL) * nc..2 * (band / CELL + 1) * nc).ok_or(bad)?;
            let (prev_maxima, prev_means) = prev_cells.split_at(nc);
            if let Some(k) = inp.fireflies {
                light.copy_from_slice(raw);
                if capped {
                    for (i, cap) in caps.iter_mut().enumerate() {
                        let near = &prev_maxima[i.saturating_sub(fireflies::REACH)..(i + fireflies::REACH + 1).min(nc)];
                        *cap = cfg.firefly_history * near.iter().fold(0f32, |a, &b| a.max(b));
                    }
                }
                let mut t = fireflies::Thresholds::new(work, w).ok_or(bad)?;
                for rgb in light.chunks_exact(3 * w).take(band_rows) {
                    t.add_row([&rgb[..w], &rgb[w..2 * w], &rgb[2 * w..]]);
                }
                let (caps, prev_means): (&[f32], &[f32]) = if capped { (caps, prev_means) } else { (&[], &[]) };
                let th = t.finish_capped(k, caps, prev_means, means_out, maxima_out);
                for rgb in light.chunks_exact_mut(3 * w).take(band_rows) {
                    let (r, gb) = rgb.split_at_mut(w);
                    let (g, b) = gb.split_at_mut(w);
                    c.clamped += fireflies::clamp_row([r, g, b], 0, th) as u64;
                }
            } else {
                // no clamp, no cap for the next frame
                maxima_out.fill(f32::INFINITY);
                means_out.fill(f32::INFINITY);
            }
            // rows of the band this call writes (a band of rows may end inside the clamp's band)
            for y in band..(band + band_rows).min(y0 + n_rows) {
                let (out_row, px_row) =
                    (&mut write[(y - y0) * w * rec..(y - y0 + 1) * w * rec], &mut pixels[(y - y0) * w * pv..(y - y0 + 1) * w * pv]);
                let raw = &raw[3 * (y - band) * w..3 * (y - band + 1) * w];
                let cur_row = if inp.fireflies.is_some() { &light[3 * (y - band) * w..3 * (y - band + 1) * w] } else { raw };
                match inp.motion {
                    Some(m) if has_history => {
                        let (mx, my) = mv.split_at_mut(w);
                        m.read_row_n(y, 0, [mx, my]).ok_or(bad)?;
                    }
                    _ => mv.fill(0.0),
                }
                // the current guides, straight into their fields of the record row
                let mut p = GUIDES;
                for (on, view, ch) in
                    [(self.normal, inp.guides.normal, 3), (self.position, inp.guides.position, 3), (self.depth, inp.guides.depth, 1)]
                {
                    if !on {
                        continue;
                    }
                    let v = view.ok_or(Error::GuideMismatch)?;
                    let fields = &mut out_row[p * w..(p + ch) * w];
                    if ch == 3 {
                        // the 3 fields in one pass over the row (a de-interleave where the view is RGB)
                        let (a, bc) = fields.split_at_mut(w);
                        let (b, c) = bc.split_at_mut(w);
                        v.read_row_n(y, 0, [a, b, c]).ok_or(bad)?;
                    } else {
                        v.read_row(y, 0, 0, fields).ok_or(bad)?;
                    }
                    p += ch;
                }
                let row = Row { y, read, raw, cur: cur_row, mv, clamped: inp.fireflies.is_some(), has_history };
                let mut x = 0;
                while x < w {
                    // a group of pixels at once where their taps allow; the next pixels one by one where not
                    if let Some(isa) = self.lanes {
                        let (next, rejected) = lanes::accumulate(self, isa, &row, x, out_row, px_row);
                        c.rejected += rejected;
                        if next > x {
                            x = next;
                            continue;
                        }
                    }
                    let end = (x + lanes::PER_PIXEL_RUN).min(w);
                    for x in x..end {
                        self.accumulate_pixel(&row, x, out_row, px_row, &mut c);
                    }
                    x = end;
                }
            }
        }
        Ok(c)
    }

    /// The record fields of the normal, the position and the depth (those the plan has).
    fn guide_fields(&self) -> (usize, usize, usize) {
        let p_at = GUIDES + 3 * self.normal as usize;
        (GUIDES, p_at, p_at + 3 * self.position as usize)
    }
    /// Without depth, the square of the position limit per squared pixel
    /// footprint ([`footprint2`]): the camera distance is estimated as the
    /// footprint times the frame's width over `2 tan 30°` (a 60° horizontal
    /// field of view), and the limit is [`TemporalConfig::position_limit`]
    /// of it, as with depth.
    fn footprint_limit2(&self) -> f32 {
        let k = self.cfg.position_limit * (self.width as f32 / TWO_TAN_30);
        k * k
    }
    /// Largest motion component taken as a motion vector, in pixels.
    fn max_motion(&self) -> f32 {
        MAX_MOTION_FRAMES * self.width.max(self.height) as f32
    }

    /// Step 1 for pixel `x` of a row: the reference the pixel groups of
    /// [`lanes::accumulate`] equal bit for bit. `out_row`: the row's record
    /// (the current guides filled in), `px_row`: its per-pixel values.
    fn accumulate_pixel(&self, r: &Row<'_>, x: usize, out_row: &mut [f32], px_row: &mut [f32], c: &mut Counts) {
        let (w, h, rec, cfg) = (self.width, self.height, self.record(), &self.cfg);
        let (n_at, p_at, d_at) = self.guide_fields();
        let gather = self.accumulates_output();
        // field `f` of this pixel's record
        let at = |f: usize| f * w + x;
        let rawc = [r.raw[x], r.raw[w + x], r.raw[2 * w + x]];
        let cur = [r.cur[x], r.cur[w + x], r.cur[2 * w + x]];
        let cur_ok = cur.iter().all(|v| v.is_finite());
        c.nonfinite += !cur_ok as u64;
        let kept = if r.clamped { fireflies::kept(rawc, cur) } else { 1.0 };
        let (mx, my) = (r.mv[x], r.mv[w + x]);
        let max_motion = self.max_motion();
        let motion_ok = mx.abs() <= max_motion && my.abs() <= max_motion; // false for NaN
        c.invalid_motion += (r.has_history && !motion_ok) as u64;
        let (px, py) = (x as f32 + mx, r.y as f32 + my);
        let (mut tw, mut n, mut prev) = (0f32, 0f32, [0f32; 3]);
        // the previous output through the accepted taps, for step 3
        let (mut ow, mut out) = (0f32, [0f32; 3]);
        if r.has_history && motion_ok {
            let g = |f: usize| out_row[at(f)];
            // the square of the largest position distance of a tap
            let plim2 = if self.depth {
                let plim = cfg.position_limit * g(d_at).abs();
                plim * plim
            } else if self.position {
                self.footprint_limit2() * footprint2(out_row, p_at, w, x)
            } else {
                0.0
            };
            for (tx, ty, wt) in bilinear_taps(px, py) {
                if tx < 0 || ty < 0 || tx >= w as i64 || ty >= h as i64 || wt.is_nan() || wt <= 0.0 {
                    continue;
                }
                // the tap's record row, and its field `f`
                let j = ty as usize * w * rec + tx as usize;
                let Some(trow) = r.read.get(j..j + (rec - 1) * w + 1) else { continue };
                let t = |f: usize| trow[f * w];
                let mut ok = true;
                if self.normal {
                    let (a, b) = ([g(n_at), g(n_at + 1), g(n_at + 2)], [t(n_at), t(n_at + 1), t(n_at + 2)]);
                    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
                    let empty = |v: [f32; 3]| v[0] == 0.0 && v[1] == 0.0 && v[2] == 0.0;
                    // (no geometry on both sides: sky continues sky)
                    ok &= dot >= cfg.normal_limit || (empty(a) && empty(b));
                }
                if self.position {
                    let d2: f32 = (0..3).map(|c| (t(p_at + c) - g(p_at + c)) * (t(p_at + c) - g(p_at + c))).sum();
                    ok &= d2 <= plim2;
                } else if self.depth {
                    let d = g(d_at);
                    ok &= (t(d_at) - d).abs() <= cfg.depth_limit * d.abs();
                }
                let (pl, pn) = ([t(LIGHT), t(LIGHT + 1), t(LIGHT + 2)], t(COUNT));
                ok &= pl.iter().all(|v| v.is_finite()) && pn.is_finite() && pn >= 0.0;
                if ok {
                    tw += wt;
                    n += wt * pn;
                    for ch in 0..3 {
                        prev[ch] += wt * pl[ch];
                    }
                    if gather {
                        let po = [t(OUTPUT), t(OUTPUT + 1), t(OUTPUT + 2)];
                        if po.iter().all(|v| v.is_finite()) {
                            ow += wt;
                            for ch in 0..3 {
                                out[ch] += wt * po[ch];
                            }
                        }
                    }
                }
            }
        }
        let (acc, count) = if tw > 0.0 {
            let n = n / tw;
            let inv = 1.0 / tw;
            let prev = [prev[0] * inv, prev[1] * inv, prev[2] * inv];
            if cur_ok {
                let count = (n + kept).min(cfg.max_history);
                let a = if count > 0.0 { (kept / count).max(kept / cfg.max_history) } else { 1.0 };
                (lerp3(prev, cur, a), count)
            } else {
                (prev, n) // a NaN/Inf sample is bridged with the history
            }
        } else {
            c.rejected += r.has_history as u64;
            // a NaN/Inf sample without history stays: the denoiser excludes it
            (cur, kept.max(1e-3))
        };
        for (ch, v) in acc.into_iter().enumerate() {
            out_row[at(LIGHT + ch)] = v;
        }
        out_row[at(COUNT)] = count;
        if !gather {
            return;
        }
        let pv = if ow > 0.0 {
            let inv = 1.0 / ow;
            [out[0] * inv, out[1] * inv, out[2] * inv]
        } else {
            [f32::NAN; 3]
        };
        for (ch, v) in pv.into_iter().enumerate() {
            px_row[ch * w + x] = v;
        }
    }

    /// Step 3 for the whole frame: `current`, the denoiser's output of this
    /// frame (RGB interleaved), blended with the clipped reprojection of the
    /// previous output into the write slot and `out`; then advances the
    /// history to the next frame. `cut`: as [`Counts::cut`] said;
    /// `clamp_negative`: negative results become 0. `scratch`: as
    /// [`Reprojection::accumulate`] left it.
    pub fn resolve(
        &self,
        current: &[f32],
        history: &mut History<'_>,
        scratch: &mut [f32],
        cut: bool,
        clamp_negative: bool,
        out: &mut ImageViewMut<'_>,
    ) -> Result<(), Error> {
        self.check_resolve(current, history, out)?;
        if scratch.len() < self.scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.scratch_len(), got: scratch.len() });
        }
        let blend = self.blends(history, cut);
        let (pixels, rows) = scratch.split_at_mut(self.pixel_values() * self.plane());
        let (_, write) = self.slots(history);
        self.resolve_rows(current, 0, pixels, write, rows, blend, clamp_negative, out)?;
        history.frames = next_frame(history.frames);
        Ok(())
    }

    /// [`Reprojection::resolve`] in row bands over the caller's executor
    /// (`scratch`: as [`Reprojection::accumulate_parallel`] left it); the same bits.
    #[allow(clippy::too_many_arguments)]
    pub fn resolve_parallel(
        &self,
        current: &[f32],
        history: &mut History<'_>,
        scratch: &mut [f32],
        cut: bool,
        clamp_negative: bool,
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<(), Error> {
        self.check_resolve(current, history, out)?;
        let needed = self.parallel_scratch_len(workers).ok_or(Error::InvalidConfig("workers: scratch size overflows"))?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let blend = self.blends(history, cut);
        let (w, h, rec) = (self.width, self.height, self.record());
        let (rows, nb) = (self.band_rows(workers), self.bands(workers));
        let (pixels, runs) = scratch.split_at_mut(self.pixel_values() * self.plane());
        let (_, write) = self.slots(history);
        let bands = RowBands::new(out).ok_or(Error::Unsupported("a parallel run needs an output whose rows do not overlap"))?;
        let wb = Bands::new(write, rows * w * rec);
        let pixels = &*pixels;
        // SAFETY: `run_tiles` runs each band once; a band writes only its own
        // records and its own output rows (disjoint `RowBands`).
        run_tiles(runs, nb, workers, self.rows_len(), for_each, &|b, buf| {
            let y0 = b * rows;
            let mut ob = unsafe { bands.band(y0, rows.min(h - y0))? };
            let pb = &pixels[(y0 * w * self.pixel_values()).min(pixels.len())..];
            unsafe { self.resolve_rows(current, y0, pb, wb.get(b), buf, blend, clamp_negative, &mut ob)? };
            Ok(Report::default())
        })?;
        history.frames = next_frame(history.frames);
        Ok(())
    }

    fn check_resolve(&self, current: &[f32], history: &History<'_>, out: &ImageViewMut<'_>) -> Result<(), Error> {
        self.check_history(history)?;
        if current.len() < 3 * self.plane() {
            return Err(Error::BufferTooSmall { arg: Arg::Scratch, needed: 3 * self.plane(), len: current.len() });
        }
        self.check_output(out)
    }

    /// Refuses an output of another size or with fewer than 3 channels.
    fn check_output(&self, out: &ImageViewMut<'_>) -> Result<(), Error> {
        let (w, h) = (self.width, self.height);
        if (out.width(), out.height()) != (w, h) {
            return Err(Error::SizeMismatch { arg: Arg::Output, expected: (w, h), got: (out.width(), out.height()) });
        }
        if out.channel_count() < 3 {
            return Err(Error::ChannelCount { arg: Arg::Output, expected: 3, got: out.channel_count() });
        }
        Ok(())
    }

    fn blends(&self, history: &History<'_>, cut: bool) -> bool {
        history.frames > 0 && !cut && self.accumulates_output()
    }

    /// Whether the output is accumulated ([`TemporalConfig::output_alpha`] < 1).
    /// Without, step 1 gathers no previous output (the scratch holds none) and
    /// [`Reprojection::run_frame`] skips step 3.
    pub fn accumulates_output(&self) -> bool {
        self.cfg.output_alpha < 1.0
    }

    /// Step 3 for rows `y0..` (as many as `write` holds records of): `pixels`
    /// from those rows on, `out` a view whose row 0 is frame row `y0`.
    #[allow(clippy::too_many_arguments)]
    fn resolve_rows(
        &self,
        current: &[f32],
        y0: usize,
        pixels: &[f32],
        write: &mut [f32],
        rows: &mut [f32],
        blend: bool,
        clamp_negative: bool,
        out: &mut ImageViewMut<'_>,
    ) -> Result<(), Error> {
        let (w, h) = (self.width, self.height);
        let (rec, pv) = (self.record(), self.pixel_values());
        let n_rows = write.len() / (w * rec);
        if y0 + n_rows > h || pixels.len() < n_rows * w * pv || rows.len() < RESOLVE_ROWS * w || out.height() < n_rows {
            return Err(Error::InvalidTile { index: y0, count: h });
        }
        let (ring, rest) = rows.split_at_mut(3 * RING_PLANES * w);
        let out_row = &mut rest[..3 * w];
        if blend {
            for y in y0.saturating_sub(1)..y0 + 1 {
                self.resolve_ring_row(current, y, ring, out_row, true);
            }
        }
        for y in y0..y0 + n_rows {
            if !blend {
                self.resolve_ring_row(current, y, ring, out_row, false);
            } else if y + 1 < h {
                self.resolve_ring_row(current, y + 1, ring, out_row, true);
            }
            let (ya, yb) = (y.saturating_sub(1), (y + 2).min(h));
            let r = ResolveRow {
                ring,
                slots: [ya, ya + 1, yb - 1].map(|sy| (sy % 3) * RING_PLANES * w),
                rows: yb - ya,
                cur: (y % 3) * RING_PLANES * w,
                prev: &pixels[(y - y0) * w * pv..(y - y0 + 1) * w * pv],
                blend,
                clamp_negative,
            };
            let wrow = &mut write[(y - y0) * w * rec..(y - y0 + 1) * w * rec];
            let mut x = 0;
            while x < w {
                if let Some(isa) = self.lanes {
                    let next = lanes::resolve(self, isa, &r, x, wrow, out_row);
                    if next > x {
                        x = next;
                        continue;
                    }
                }
                let end = if x == 0 { 1 } else { (x + lanes::PER_PIXEL_RUN).min(w) };
                for x in x..end {
                    self.resolve_pixel(&r, x, wrow, out_row);
                }
                x = end;
            }
            out.write_row_n(y - y0, 0, [&out_row[..w], &out_row[w..2 * w], &out_row[2 * w..]])
                .ok_or(Error::InvalidTile { index: y, count: h })?;
        }
        Ok(())
    }

    /// Fills the ring slot of frame row `y`: the row of `current` (RGB
    /// interleaved) as 3 planes and, with `sums`, the horizontal 3-sums of its
    /// YCoCg and of their squares (`tmp`: 3 rows of working space).
    fn resolve_ring_row(&self, current: &[f32], y: usize, ring: &mut [f32], tmp: &mut [f32], sums: bool) {
        let w = self.width;
        let slot = &mut ring[(y % 3) * RING_PLANES * w..(y % 3 + 1) * RING_PLANES * w];
        let (rgb_planes, sum_planes) = slot.split_at_mut(3 * w);
        let (r, gb) = rgb_planes.split_at_mut(w);
        let (g, b) = gb.split_at_mut(w);
        crate::image::deinterleave_rgb(&current[3 * y * w..3 * (y + 1) * w], r, g, b);
        if !sums {
            return;
        }
        let (t0, t12) = tmp[..3 * w].split_at_mut(w);
        let (t1, t2) = t12.split_at_mut(w);
        // zipped planes (no index checks), so that it vectorises
        for (((luma, co), cg), ((red, green), blue)) in
            t0.iter_mut().zip(t1.iter_mut()).zip(t2.iter_mut()).zip(r.iter().zip(g.iter()).zip(b.iter()))
        {
            [*luma, *co, *cg] = ycocg([*red, *green, *blue]);
        }
        let (s1, s2) = sum_planes.split_at_mut(3 * w);
        for ch in 0..3 {
            let v = &tmp[ch * w..(ch + 1) * w];
            let (s1, s2) = (&mut s1[ch * w..(ch + 1) * w], &mut s2[ch * w..(ch + 1) * w]);
            lanes::three_sums(v, s1, s2);
        }
    }

    /// Step 3 for pixel `x` of a row: the reference the pixel groups of
    /// [`lanes::resolve`] equal bit for bit. Writes the pixel's output into
    /// the record row `wrow` and into `out_row` (3 planes).
    fn resolve_pixel(&self, r: &ResolveRow<'_>, x: usize, wrow: &mut [f32], out_row: &mut [f32]) {
        let (w, cfg) = (self.width, &self.cfg);
        let plane = |base: usize, p: usize| r.ring[base + p * w + x];
        let cur = [plane(r.cur, 0), plane(r.cur, 1), plane(r.cur, 2)];
        let mut res = cur;
        if r.blend && !r.prev[x].is_nan() {
            let (mut s1, mut s2) = ([0f32; 3], [0f32; 3]);
            for &slot in &r.slots[..r.rows] {
                for ch in 0..3 {
                    s1[ch] += plane(slot, 3 + ch);
                    s2[ch] += plane(slot, 6 + ch);
                }
            }
            let cols = (x + 2).min(w) - x.saturating_sub(1);
            let inv = 1.0 / (r.rows * cols) as f32;
            let p = ycocg([r.prev[x], r.prev[w + x], r.prev[2 * w + x]]);
            let mut clipped = [0f32; 3];
            for ch in 0..3 {
                let mu = s1[ch] * inv;
                // (compares, not f32::max/min, whose choice between ±0 is unspecified)
                let var = s2[ch] * inv - mu * mu;
                let sd = libm::sqrtf(if var > 0.0 { var } else { 0.0 });
                let (lo, hi) = (mu - cfg.clip_gamma * sd, mu + cfg.clip_gamma * sd);
                let c = if p[ch] >= lo { p[ch] } else { lo };
                clipped[ch] = if c <= hi { c } else { hi };
            }
            let n = wrow[COUNT * w + x];
            let a = if n > 0.0 { (1.0 / n).max(cfg.output_alpha).min(1.0) } else { 1.0 };
            res = lerp3(rgb(clipped), cur, a);
        }
        for ch in 0..3 {
            let v = match r.clamp_negative {
                true if res[ch] > 0.0 => res[ch],
                true => 0.0,
                false => res[ch],
            };
            let v = if v.is_finite() { v } else { 0.0 };
            wrow[(OUTPUT + ch) * w + x] = v;
            out_row[ch * w + x] = v;
        }
    }
}

/// The frame counter after a frame (its parity picks the slots: kept when it wraps).
pub(crate) fn next_frame(frames: u32) -> u32 {
    if frames == u32::MAX {
        2
    } else {
        frames + 1
    }
}

/// `a · new + (1 − a) · old`, per channel.
#[inline(always)]
fn lerp3(old: [f32; 3], new: [f32; 3], a: f32) -> [f32; 3] {
    [old[0] + a * (new[0] - old[0]), old[1] + a * (new[1] - old[1]), old[2] + a * (new[2] - old[2])]
}
