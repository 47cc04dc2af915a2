//! FLR's schedule, written once: the stages in run order ([`Stage::ALL`]),
//! how many tiles each has ([`Flr::stage_tiles`]), and one entry that runs one
//! tile of one stage ([`Tiled::run`]) on a scratch that records the frame's
//! progress. The C tiled API, [`Flr::denoise_parallel`] (generic over the
//! caller's executor) and the CLI's threads all run these tiles; the GPU pass
//! list names the stage each pass belongs to ([`super::gpu`]).
//!
//! | stage | tiles | reads | writes |
//! |---|---|---|---|
//! | `Prepare` | 1 | a few guide samples | progress (reset), `Stats` references |
//! | `Moments` | per band | frame rows of the band | `cells` band (and `pooled` band, unless the moment history pools after its blend) |
//! | `Stats` | 1 | all `cells` | `Stats` mean / scale |
//! | `BlurRows` | per band | `cells` / `pooled` band | each window's `tmp` band |
//! | `BlurColsSolve` | per band | all `tmp` | blurred band, models (and variances) band |
//! | `Blend` | per band | every window's models and variances | `models` band (adaptive window; else nothing) |
//! | `Apply` | per band | all `models`, frame rows | output rows of the band |
//!
//! Misuse is refused with [`Error::StageOrder`], never answered with wrong
//! output: the scratch's header holds a key of the plan and its arguments,
//! which tiles of which stage have completed, and which workers are busy. A
//! tile runs only when every tile of the stage before it has completed, it
//! has not run yet for this frame, and its worker is idle. `Prepare` starts a
//! frame: it resets the header, so it must not run while any other call on the
//! same scratch is in flight.
//!
//! [`Flr::denoise`] runs the stages one after another on the calling thread,
//! through the same [`Tiled::run`]. (Interleaving the stages band by band,
//! each tile as soon as the bands it reads exist, measured no faster at 1080p:
//! an apply band is larger than L2 and evicts what the next blur would reuse.)

use core::marker::PhantomData;
use core::sync::atomic::{AtomicU32, Ordering};

use super::{CheckedFrame, Flr, Report, ScratchLayout, Stats, MAX_SCALES};
use crate::error::{Arg, Error};
use crate::guides::Frame;
use crate::image::ImageViewMut;
use crate::parallel::{Executor, ResultCell};

/// One stage of a tiled FLR run. Numbered in run order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Stage {
    /// One tile: starts a frame and picks the per-guide references.
    Prepare = 0,
    /// Per band: block moments (uses the worker's buffer).
    Moments = 1,
    /// One tile: the frame's guide statistics.
    Stats = 2,
    /// Per band: horizontal blur of every window.
    BlurRows = 3,
    /// Per band: vertical blur and per-cell solve of every window.
    BlurColsSolve = 4,
    /// Per band: blends the adaptive window's models (nothing with one window).
    Blend = 5,
    /// Per band: applies the models to the output rows (uses the worker's buffer).
    Apply = 6,
}

impl Stage {
    /// Every stage, in run order.
    pub const ALL: [Stage; 7] =
        [Stage::Prepare, Stage::Moments, Stage::Stats, Stage::BlurRows, Stage::BlurColsSolve, Stage::Blend, Stage::Apply];

    /// The stage numbered `i` (its position in [`Stage::ALL`]).
    pub fn from_index(i: usize) -> Option<Stage> {
        Stage::ALL.get(i).copied()
    }
    /// Position in [`Stage::ALL`].
    pub const fn index(self) -> usize {
        self as usize
    }
    /// Lower-case name (`"blur_cols_solve"`).
    pub const fn name(self) -> &'static str {
        match self {
            Stage::Prepare => "prepare",
            Stage::Moments => "moments",
            Stage::Stats => "stats",
            Stage::BlurRows => "blur_rows",
            Stage::BlurColsSolve => "blur_cols_solve",
            Stage::Blend => "blend",
            Stage::Apply => "apply",
        }
    }
    /// Whether the stage has one tile (tile 0) instead of one per band.
    pub const fn single(self) -> bool {
        matches!(self, Stage::Prepare | Stage::Stats)
    }
}

/// Header words (u32) before the per-worker and per-tile bit sets.
const MAGIC_AT: usize = 0;
const KEY_AT: usize = 1; // two words
const DONE_AT: usize = 3; // one word per stage
const BITS_AT: usize = DONE_AT + Stage::ALL.len();
const MAGIC: u32 = 0x4c52_4431; // "LRD1"

/// A scratch for tiled runs of one [`Flr`] plan with a fixed worker count:
/// the plan's regions, each window's own blur grids, the frame's [`Stats`]
/// and the progress header. Made by [`Flr::tiled`] (from a slice) or
/// [`Flr::tiled_raw`] (from a pointer, for callers that share it across
/// threads themselves).
#[derive(Debug)]
pub struct Tiled<'s> {
    flr: &'s Flr,
    base: *mut f64,
    workers: usize,
    key: u64,
    /// u32 words of one stage's tile bit set, and of the worker bit set.
    tile_words: usize,
    worker_words: usize,
    /// f64 offsets from `base`: the stats, then the plan's regions.
    stats_at: usize,
    layout: ScratchLayout,
    /// Window `s`'s horizontal-blur grid and blurred grid.
    tmp: [usize; MAX_SCALES],
    blurred: [usize; MAX_SCALES],
    _scratch: PhantomData<&'s mut [f64]>,
}

/// f64 values of the header: the words, the worker bits and the tile bits.
fn header_len(workers: usize, tiles: usize) -> usize {
    let words = BITS_AT + workers.div_ceil(32) + Stage::ALL.len() * tiles.div_ceil(32);
    words.div_ceil(2)
}

const STATS_LEN: usize = core::mem::size_of::<Stats>().div_ceil(8);
const _: () = assert!(core::mem::align_of::<Stats>() <= 8);

impl Flr {
    /// Tiles of `stage`: 1 for [`Stage::Prepare`] and [`Stage::Stats`],
    /// [`Flr::tile_count`] for the others.
    pub fn stage_tiles(&self, stage: Stage) -> usize {
        if stage.single() {
            1
        } else {
            self.tile_count()
        }
    }

    /// Denoises one frame on the calling thread: every tile of every stage,
    /// in order ([`Tiled::run`] on a one-worker scratch). `scratch` holds at
    /// least [`Flr::scratch_len`] values; `out` is the output-size, ≥ 3-channel
    /// image. Allocates nothing.
    pub fn denoise(&self, frame: &Frame<'_>, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        self.denoise_checked(&self.check_frame(frame)?, scratch, out)
    }

    /// [`Flr::denoise`] of a checked frame.
    pub(crate) fn denoise_checked(&self, f: &CheckedFrame<'_>, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        self.check_output(out)?;
        let tiled = self.tiled(scratch, 1)?;
        self.run_stages(&tiled, f, out, &Stage::ALL, None)
    }

    /// Every tile of `stages` (consecutive, in run order) of the frame on
    /// `tiled`: on the calling thread as worker 0, or over `for_each` (then
    /// `out` must have rows that do not overlap in memory).
    pub(crate) fn run_stages(
        &self,
        tiled: &Tiled<'_>,
        f: &CheckedFrame<'_>,
        out: &mut ImageViewMut<'_>,
        stages: &[Stage],
        for_each: Option<Executor<'_>>,
    ) -> Result<Report, Error> {
        let Some(for_each) = for_each else {
            let mut rep = Report::default();
            for &stage in stages {
                for tile in 0..self.stage_tiles(stage) {
                    rep += if stage == Stage::Apply {
                        let (y0, y1) = self.tile_pixel_rows(tile)?;
                        tiled.run(f, stage, tile, 0, Some(&mut out.rows(y0, y1 - y0)?))?
                    } else {
                        tiled.run(f, stage, tile, 0, None)?
                    };
                }
            }
            return Ok(rep);
        };
        let bands = crate::image::RowBands::new(out)
            .ok_or(Error::Unsupported("a parallel run needs an output whose rows do not overlap (use Flr::denoise)"))?;
        let shared = Shared { tiled, out: bands, result: ResultCell::new() };
        for &stage in stages {
            let n = self.stage_tiles(stage);
            let run = |tile: usize, worker: usize| shared.run(f, stage, tile, worker);
            if n == 1 {
                run(0, 0);
            } else {
                for_each(n, &run);
            }
            shared.result.error()?;
            if !tiled.completed(stage) {
                return Err(Error::StageOrder { stage: stage.index() as u8, tile: 0 });
            }
        }
        Ok(shared.result.report())
    }

    /// Scratch length in f64 elements for [`Flr::denoise`] (one worker).
    pub fn scratch_len(&self) -> usize {
        self.tiled_scratch_len(1).unwrap_or(usize::MAX)
    }

    /// Refuses an output of another size or with fewer than 3 channels.
    pub(crate) fn check_output(&self, out: &ImageViewMut<'_>) -> Result<(), Error> {
        let (w, h) = self.size();
        if out.width() != w || out.height() != h || out.channel_count() < 3 {
            return Err(Error::SizeMismatch { arg: Arg::Output, expected: (w, h), got: (out.width(), out.height()) });
        }
        Ok(())
    }

    /// f64 values of a [`Tiled`] scratch for `workers` concurrent workers
    /// (`workers` ≥ 1); `None` if it overflows.
    pub fn tiled_scratch_len(&self, workers: usize) -> Option<usize> {
        // `scratch_len_for`'s terms, checked (a huge worker count must not wrap)
        let workers_len = workers.max(1).checked_mul(self.worker_len())?;
        2usize.checked_mul(self.grid_len())?.checked_add(self.models_len())?.checked_add(workers_len)?.checked_add(self.adaptive_len())?;
        let n = self.scale_count();
        let extra: usize = (1..n).chain(2..n).map(|s| self.window_grid_len(s)).sum();
        header_len(workers.max(1), self.tile_count()).checked_add(STATS_LEN)?.checked_add(self.scratch_len_for(workers))?.checked_add(extra)
    }

    /// A tiled scratch over `scratch` (at least [`Flr::tiled_scratch_len`]
    /// values) for `workers` workers. Its first [`Stage::Prepare`] starts a
    /// frame; the values it holds before do not matter.
    pub fn tiled<'s>(&'s self, scratch: &'s mut [f64], workers: usize) -> Result<Tiled<'s>, Error> {
        // SAFETY: `scratch` is a live, exclusive, aligned slice for 's; its
        // length is passed along and checked.
        unsafe { self.tiled_raw(scratch.as_mut_ptr(), scratch.len(), workers, 0) }
    }

    /// [`Flr::tiled`] over a raw buffer, for a caller that runs tiles of the
    /// same frame from several threads, each with its own `Tiled` over the
    /// same memory (the C API). `key` is mixed into the progress key: calls
    /// that pass another key than the frame's `Prepare` are refused.
    ///
    /// # Safety
    /// `ptr` is 8-byte aligned and valid for reads and writes of `len` f64
    /// for `'s`; while a `Tiled` over it is used, the memory is accessed only
    /// through `Tiled`s of this plan; the caller keeps [`Tiled::run`]'s rules
    /// for concurrent calls.
    pub unsafe fn tiled_raw<'s>(&'s self, ptr: *mut f64, len: usize, workers: usize, key: u64) -> Result<Tiled<'s>, Error> {
        if workers == 0 {
            return Err(Error::InvalidConfig("workers must be at least 1"));
        }
        let needed = self.tiled_scratch_len(workers).ok_or(Error::InvalidConfig("workers: scratch size overflows"))?;
        if len < needed {
            return Err(Error::ScratchTooSmall { needed, got: len });
        }
        let stats_at = header_len(workers, self.tile_count());
        let data = stats_at + STATS_LEN;
        let l = self.scratch_layout(workers);
        let shift = |r: core::ops::Range<usize>| r.start + data..r.end + data;
        let layout = ScratchLayout {
            cells: shift(l.cells),
            tmp: shift(l.tmp),
            models: shift(l.models),
            workers: shift(l.workers),
            first: shift(l.first),
            blurred: shift(l.blurred),
            pooled: shift(l.pooled),
            scale_models: shift(l.scale_models),
            variances: shift(l.variances),
        };
        // Window 0 uses the layout's `tmp` and `first`, window 1 its
        // `blurred`; the others get grids of their own after the plan's regions.
        let mut at = data + self.scratch_len_for(workers);
        let n = self.scale_count();
        let (mut tmp, mut blurred) = ([layout.tmp.start; MAX_SCALES], [layout.first.start, layout.blurred.start, 0]);
        for (s, t) in tmp.iter_mut().enumerate().take(n).skip(1) {
            *t = at;
            at += self.window_grid_len(s);
        }
        for (s, b) in blurred.iter_mut().enumerate().take(n).skip(2) {
            *b = at;
            at += self.window_grid_len(s);
        }
        let key = plan_key(self, workers, len) ^ key.rotate_left(17);
        Ok(Tiled {
            flr: self,
            base: ptr,
            workers,
            key,
            tile_words: self.tile_count().div_ceil(32),
            worker_words: workers.div_ceil(32),
            stats_at,
            layout,
            tmp,
            blurred,
            _scratch: PhantomData,
        })
    }
}

/// FNV-1a over the plan's size and configuration, the worker count and the
/// scratch length. The configuration is hashed through its `Debug` text, so
/// every field (and any field added later) takes part without a list here.
fn plan_key(flr: &Flr, workers: usize, len: usize) -> u64 {
    struct Fnv(u64);
    impl core::fmt::Write for Fnv {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            for b in s.bytes() {
                self.0 ^= u64::from(b);
                self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
            }
            Ok(())
        }
    }
    let mut h = Fnv(0xcbf2_9ce4_8422_2325);
    // Writing into `Fnv` cannot fail.
    let _ = core::fmt::Write::write_fmt(&mut h, format_args!("{:?} {:?} {workers} {len}", flr.config(), flr.size()));
    h.0
}

impl<'s> Tiled<'s> {
    /// Header word `i` as an atomic.
    fn word(&self, i: usize) -> &AtomicU32 {
        // SAFETY: `i` is inside the header (callers index below
        // `2 * stats_at`), the buffer is 8-byte aligned and valid for 's, and
        // header words are only ever accessed atomically.
        unsafe { AtomicU32::from_ptr((self.base as *mut u32).add(i)) }
    }
    fn tile_bit(&self, stage: Stage, tile: usize) -> (&AtomicU32, u32) {
        let at = BITS_AT + self.worker_words + stage.index() * self.tile_words + tile / 32;
        (self.word(at), 1 << (tile % 32))
    }
    fn worker_bit(&self, worker: usize) -> (&AtomicU32, u32) {
        (self.word(BITS_AT + worker / 32), 1 << (worker % 32))
    }
    fn prepared(&self) -> bool {
        self.word(MAGIC_AT).load(Ordering::Acquire) == MAGIC
            && self.word(KEY_AT).load(Ordering::Acquire) == self.key as u32
            && self.word(KEY_AT + 1).load(Ordering::Acquire) == (self.key >> 32) as u32
    }

    /// Whether every tile of `stage` has completed for the current frame.
    pub fn completed(&self, stage: Stage) -> bool {
        self.prepared() && self.word(DONE_AT + stage.index()).load(Ordering::Acquire) as usize == self.flr.stage_tiles(stage)
    }

    /// Runs tile `tile` of `stage` for `frame` as worker `worker`. An
    /// [`Stage::Apply`] tile writes `out`: the output rows
    /// [`Flr::tile_pixel_rows`]`(tile)`, as a view of just those rows; the
    /// other stages take `None`.
    ///
    /// Rules: a frame starts with [`Stage::Prepare`] (which must not run
    /// while another call on this scratch is in flight); then the stages run in
    /// order, every tile of a stage once, after every tile of the stage before.
    /// Every call of a frame passes the same frame and output. Tiles of one
    /// stage may run concurrently (through [`Flr::tiled_raw`]) when each call
    /// has its own `worker` below the scratch's worker count. A call that
    /// breaks the order returns [`Error::StageOrder`] and changes nothing.
    pub fn run(
        &self,
        frame: &CheckedFrame<'_>,
        stage: Stage,
        tile: usize,
        worker: usize,
        out: Option<&mut ImageViewMut<'_>>,
    ) -> Result<Report, Error> {
        let tiles = self.flr.stage_tiles(stage);
        if tile >= tiles {
            return Err(Error::InvalidTile { index: tile, count: tiles });
        }
        if worker >= self.workers {
            return Err(Error::InvalidTile { index: worker, count: self.workers });
        }
        let out = match (stage, out) {
            (Stage::Apply, Some(o)) => {
                let (y0, y1) = self.flr.tile_pixel_rows(tile)?;
                let w = self.flr.size().0;
                if o.width() != w || o.height() != y1 - y0 || o.channel_count() < 3 {
                    return Err(Error::SizeMismatch { arg: Arg::Output, expected: (w, y1 - y0), got: (o.width(), o.height()) });
                }
                Some(o)
            }
            (Stage::Apply, None) => return Err(Error::Unsupported("an apply tile needs its output rows")),
            _ => None,
        };
        if stage == Stage::Prepare {
            // SAFETY: Prepare runs alone (the rules above).
            unsafe { self.run_unchecked(frame, stage, tile, worker, None)? };
            for i in DONE_AT..2 * self.stats_at {
                self.word(i).store(0, Ordering::Relaxed);
            }
            self.word(KEY_AT).store(self.key as u32, Ordering::Relaxed);
            self.word(KEY_AT + 1).store((self.key >> 32) as u32, Ordering::Relaxed);
            self.word(MAGIC_AT).store(MAGIC, Ordering::Release);
            self.word(DONE_AT).store(1, Ordering::Release);
            return Ok(Report::default());
        }
        let order = Error::StageOrder { stage: stage.index() as u8, tile };
        let before = Stage::ALL[stage.index() - 1];
        if !self.completed(before) {
            return Err(order);
        }
        let (wb, wm) = self.worker_bit(worker);
        if wb.fetch_or(wm, Ordering::Acquire) & wm != 0 {
            return Err(order);
        }
        let (tb, tm) = self.tile_bit(stage, tile);
        if tb.fetch_or(tm, Ordering::AcqRel) & tm != 0 {
            wb.fetch_and(!wm, Ordering::Release);
            return Err(order);
        }
        // SAFETY: the stage before has completed and no later stage can start
        // before this one completes, so the regions this tile reads are not
        // written meanwhile; the tile and worker bits make this call the only
        // one writing this tile's bands and this worker's buffer.
        let r = unsafe { self.run_unchecked(frame, stage, tile, worker, out) };
        match r {
            Ok(_) => {
                self.word(DONE_AT + stage.index()).fetch_add(1, Ordering::AcqRel);
            }
            Err(_) => {
                tb.fetch_and(!tm, Ordering::AcqRel);
            }
        }
        wb.fetch_and(!wm, Ordering::Release);
        r
    }

    /// Between [`Stage::Stats`] and [`Stage::BlurRows`]: the block cells, the
    /// pooled cells (empty without a pooled window) and the frame's
    /// statistics, for a caller that changes the moments before they are
    /// blurred (`moment_history`). Refused unless every `Stats` tile has
    /// completed and no `BlurRows` tile has started. Only for a `Tiled` made
    /// by [`Flr::tiled`] (over an exclusive slice), never by `tiled_raw`.
    pub(crate) fn cells_before_blur(&mut self) -> Result<(&mut [f64], &mut [f64], Stats), Error> {
        let blur = Stage::BlurRows;
        let started = self.word(DONE_AT + blur.index()).load(Ordering::Acquire) != 0
            || (0..self.tile_words)
                .any(|i| self.word(BITS_AT + self.worker_words + blur.index() * self.tile_words + i).load(Ordering::Acquire) != 0);
        if !self.completed(Stage::Stats) || started {
            return Err(Error::StageOrder { stage: blur.index() as u8, tile: 0 });
        }
        let (cells, pooled) = (self.layout.cells.clone(), self.layout.pooled.clone());
        // SAFETY: `&mut self`: no call through this `Tiled` is in flight; its
        // only caller made it with `Flr::tiled` over an exclusive slice, so no
        // other `Tiled` shares the memory; between Stats and BlurRows no tile
        // reads or writes the two regions,
        // which are disjoint and inside the buffer (`tiled_raw`); Stats is
        // written only by Prepare and Stats.
        unsafe { Ok((self.f64s_mut(cells.start, cells.len()), self.f64s_mut(pooled.start, pooled.len()), self.stats_ptr().read())) }
    }

    fn stats_ptr(&self) -> *mut Stats {
        // SAFETY: `stats_at + STATS_LEN` is inside the buffer (checked in `tiled_raw`).
        unsafe { self.base.add(self.stats_at) as *mut Stats }
    }

    /// `len` f64 at `offset`, shared.
    ///
    /// # Safety
    /// Nothing writes them meanwhile; `offset + len` is inside the buffer.
    unsafe fn f64s(&self, offset: usize, len: usize) -> &[f64] {
        // SAFETY: the caller's contract.
        unsafe { core::slice::from_raw_parts(self.base.add(offset), len) }
    }
    /// # Safety
    /// Nothing else accesses them meanwhile; inside the buffer.
    #[allow(clippy::mut_from_ref)]
    unsafe fn f64s_mut(&self, offset: usize, len: usize) -> &mut [f64] {
        // SAFETY: the caller's contract.
        unsafe { core::slice::from_raw_parts_mut(self.base.add(offset), len) }
    }
    /// `len` f32 starting `index` f32 into the region that starts at f64 `region`.
    ///
    /// # Safety
    /// As for [`Tiled::f64s`].
    unsafe fn f32s(&self, region: usize, index: usize, len: usize) -> &[f32] {
        // SAFETY: the caller's contract.
        unsafe { core::slice::from_raw_parts((self.base.add(region) as *const f32).add(index), len) }
    }
    /// # Safety
    /// As for [`Tiled::f64s_mut`].
    #[allow(clippy::mut_from_ref)]
    unsafe fn f32s_mut(&self, region: usize, index: usize, len: usize) -> &mut [f32] {
        // SAFETY: the caller's contract.
        unsafe { core::slice::from_raw_parts_mut((self.base.add(region) as *mut f32).add(index), len) }
    }

    /// The stage's work, without the progress checks.
    ///
    /// # Safety
    /// The stage before has completed, no other call writes what this tile
    /// reads, and no other call touches this tile's bands or this worker's buffer.
    unsafe fn run_unchecked(
        &self,
        frame: &CheckedFrame<'_>,
        stage: Stage,
        tile: usize,
        worker: usize,
        out: Option<&mut ImageViewMut<'_>>,
    ) -> Result<Report, Error> {
        let flr = self.flr;
        let l = &self.layout;
        let nt = flr.tile_count();
        let windows = flr.scale_count();
        let wl = flr.worker_len();
        // SAFETY (every block below): the regions are inside the buffer
        // (`tiled_raw` checked its length against this layout); the bands
        // taken mutably are this tile's (disjoint from every other tile's) or
        // this worker's, and the shared ones were written by earlier stages.
        let worker_buf = || unsafe { self.f32s_mut(l.workers.start, worker * wl, wl) };
        let band = |region: usize, r: core::ops::Range<usize>| unsafe { self.f64s_mut(region + r.start, r.len()) };
        // window s's moment grid: cells or pooled
        let src = |s: usize| if flr.window_pooled(s) { l.pooled.start } else { l.cells.start };
        if stage == Stage::Prepare {
            // SAFETY: Prepare runs alone.
            unsafe { self.stats_ptr().write(flr.prepare(frame)) };
            return Ok(Report::default());
        }
        // SAFETY: Stats is written only by Prepare and Stats, which run while
        // no tile that reads it does.
        let stats = unsafe { self.stats_ptr().read() };
        Ok(match stage {
            Stage::Prepare => Report::default(),
            Stage::Moments => {
                let cells = band(l.cells.start, flr.cells_tile_range(tile)?);
                let rep = flr.moments_tile(frame, &stats, tile, cells, worker_buf())?;
                if let Some(s) = flr.pooled_window().filter(|_| flr.pool_in_moments) {
                    flr.pool_tile(tile, cells, band(l.pooled.start, flr.window_cells_tile_range(s, tile)?))?;
                }
                rep
            }
            Stage::Stats => {
                let mut st = stats;
                // SAFETY: every Moments tile has completed; nothing writes `cells` now.
                flr.finish_stats(unsafe { self.f64s(l.cells.start, l.cells.len()) }, &mut st)?;
                // SAFETY: Stats has one tile and no other stage runs meanwhile.
                unsafe { self.stats_ptr().write(st) };
                Report::default()
            }
            Stage::BlurRows => {
                for s in 0..windows {
                    // SAFETY: written by Moments, only read now.
                    let grid = unsafe { self.f64s(src(s), flr.window_grid_len(s)) };
                    flr.blur_rows_tile_at(s, tile, grid, band(self.tmp[s], flr.window_cells_tile_range(s, tile)?))?;
                }
                Report::default()
            }
            Stage::BlurColsSolve if windows == 1 => {
                let cells = band(l.cells.start, flr.cells_tile_range(tile)?);
                let m = flr.models_tile_range(tile)?;
                // SAFETY: this tile's models band.
                let models = unsafe { self.f32s_mut(l.models.start, m.start, m.len()) };
                // SAFETY: `tmp` was written by BlurRows, only read now.
                flr.blur_cols_tile(tile, unsafe { self.f64s(l.tmp.start, l.tmp.len()) }, cells)?;
                flr.solve_tile(&stats, tile, cells, models)?
            }
            Stage::BlurColsSolve => {
                let mut rep = Report::default();
                for s in 0..windows {
                    let dst = band(self.blurred[s], flr.window_cells_tile_range(s, tile)?);
                    // SAFETY: window s's `tmp` was written by BlurRows, only read now.
                    let tmp = unsafe { self.f64s(self.tmp[s], flr.window_grid_len(s)) };
                    flr.blur_cols_tiles_at(s, tile..tile + 1, tmp, dst)?;
                    let m = flr.scale_models_tile_range(s, tile)?;
                    // SAFETY: this tile's band of window s's models.
                    let models = unsafe { self.f32s_mut(l.scale_models.start, m.start, m.len()) };
                    let variances = band(l.variances.start, flr.scale_variances_tile_range(s, tile)?);
                    rep += flr.solve_tile_at(s, &stats, tile, dst, models, variances)?;
                }
                rep
            }
            Stage::Blend if windows == 1 => Report::default(),
            Stage::Blend => {
                // SAFETY: written by BlurColsSolve, only read now.
                let (first, models_all, variances) = unsafe {
                    let c = flr.cells_tile_range(tile)?;
                    let nm = flr.scale_models_tile_range(windows - 1, nt - 1)?.end;
                    let nv = flr.scale_variances_tile_range(windows - 1, nt - 1)?.end;
                    (self.f64s(l.first.start + c.start, c.len()), self.f32s(l.scale_models.start, 0, nm), self.f64s(l.variances.start, nv))
                };
                let m = flr.models_tile_range(tile)?;
                // SAFETY: this tile's models band.
                let models = unsafe { self.f32s_mut(l.models.start, m.start, m.len()) };
                flr.blend_tile(tile, first, models_all, variances, models)?;
                Report::default()
            }
            Stage::Apply => {
                let (cx, cy) = flr.cells();
                // SAFETY: every model band was written by BlurColsSolve or Blend.
                let models = unsafe { self.f32s(l.models.start, 0, cx * cy * crate::kernels::model_len(flr.guide_channels())) };
                let out = out.ok_or(Error::Unsupported("an apply tile needs its output rows"))?;
                flr.apply_tile(frame, &stats, tile, models, worker_buf(), out)?
            }
        })
    }
}

impl Flr {
    /// Denoises one frame with the tiles spread by the caller's executor
    /// ([`Executor`]: `for_each(count, f)`). `scratch` holds at
    /// least [`Flr::tiled_scratch_len`]`(workers)` values; `out` must have
    /// rows that do not overlap in memory. Bit-identical to [`Flr::denoise`].
    /// Allocates nothing.
    pub fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        self.denoise_parallel_checked(&self.check_frame(frame)?, scratch, out, workers, for_each)
    }

    /// [`Flr::denoise_parallel`] of a checked frame.
    pub(crate) fn denoise_parallel_checked(
        &self,
        f: &CheckedFrame<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let tiled = self.tiled(scratch, workers)?;
        self.check_output(out)?;
        self.run_stages(&tiled, f, out, &Stage::ALL, Some(for_each))
    }
}

/// What the concurrent tiles of [`Flr::denoise_parallel`] share.
struct Shared<'a, 's, 'o> {
    tiled: &'a Tiled<'s>,
    out: crate::image::RowBands<'a, 'o>,
    result: ResultCell,
}

// SAFETY: `Tiled::run` refuses every pair of concurrent calls that would touch
// the same memory (stage order, tile and worker bits; Prepare runs alone), and
// each Apply tile writes only its own output rows (`RowBands`, rows that do
// not overlap, checked before).
unsafe impl Sync for Shared<'_, '_, '_> {}

impl Shared<'_, '_, '_> {
    fn run(&self, f: &CheckedFrame<'_>, stage: Stage, tile: usize, worker: usize) {
        let r = (|| {
            if stage != Stage::Apply {
                return self.tiled.run(f, stage, tile, worker, None);
            }
            let (y0, y1) = self.tiled.flr.tile_pixel_rows(tile)?;
            // SAFETY: each Apply tile runs once (the tile bits) and its rows
            // are its own (`tile_pixel_rows` are disjoint, rows do not overlap).
            let mut band = unsafe { self.out.band(y0, y1 - y0)? };
            self.tiled.run(f, stage, tile, worker, Some(&mut band))
        })();
        self.result.add(r);
    }
}
