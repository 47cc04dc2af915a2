//! WALR — Weighted À-trous Linear Regression (Meunier & Harada, "Weighted
//! À-Trous Linear Regression (WALR) for Real-Time Diffuse Indirect Lighting
//! Denoising"; section numbers below are the paper's).
//!
//! A per-pixel weighted linear regression of the noisy light on the features
//! `X = (1, octahedral normal (2 values in [0, 1]), extra guides)`, solved from
//! weighted **averages** (§3.1):
//! `XX̄_pq = Σ w X_p X_q / Σ w`, `YX̄_p = Σ w X_p Y / Σ w` by Cholesky with a
//! per-pivot floor (Algorithm 1) and substitution (Algorithm 2,
//! [`crate::kernels::cholesky::factor_floor`]). The averages come from an
//! **edge-aware à-trous** transform (§3.2): iteration `t` averages a 3×3 box of
//! taps spaced `3^t` apart, carrying the sample count `W` so that every sample
//! is counted once (`Z_{t+1} = Σ f W_t Z_t / Σ f W_t`; stored as the sums
//! `W_t Z_t`, divided once by the solve); 4 iterations cover
//! 81×81 pixels. The weight `f` of a tap is the plane-distance edge-stopping
//! function (§4.3) **traced** along the segment from the centre (§3.3): its
//! minimum over the pixels crossed, so a thin object is never jumped over.
//! Tracing steps with the signed distance field of the previous iteration
//! (§5.2), and a tap cut off by an edge is replaced by the average at a random
//! point of its segment before the edge (§3.3), so neighbouring pixels do not
//! disagree abruptly (no à-trous seams).
//!
//! Stages (each callable on any band of rows; bands are independent and
//! bit-identical to the whole frame): [`Walr::prepare`] (frame-wide constants),
//! [`Walr::features_rows`], [`Walr::iterate_rows`] × T, [`Walr::solve_rows`]
//! (or, with the adaptive blend, [`Walr::fit_rows`] then [`Walr::blend_rows`]).
//! [`Walr::denoise`] runs them all. [`Walr::reference`] is REFWLR, the slow
//! exact per-pixel version used as the test oracle, and [`temporal`] the
//! paper's pipeline around it.
//!
//! Deliberate choices where the paper is silent or GPU-specific:
//! * edge-stopping distances are relative to the centre's camera distance when
//!   the frame has depth, and to the RMS spread of the frame's positions
//!   without (a stand-in of the same order), so they never depend on units;
//! * pixels without geometry (zero normal) or with NaN/Inf guides are a
//!   surface of their own: nothing is averaged across their border;
//! * the octahedral map's pole is the frame's mean normal unless
//!   [`WalrConfig::view`] gives the direction towards the camera (the paper
//!   maps view-space normals; this keeps visible normals on the seam-free half);
//! * outliers of the noisy light are clamped as WALR reads it
//!   ([`crate::fireflies`], [`WalrConfig::fireflies`], on by default): the
//!   à-trous averages would spread a firefly over its whole window.
//!   [`Walr::features_rows`] measures the whole 8-row bands of its rows and
//!   [`Walr::prepare`] the bands of its samples, so bands of rows stay
//!   independent and bit-identical to the whole frame;
//! * light is divided by the frame's log-average before it is stored (and multiplied
//!   back), so f16 averages neither overflow nor lose HDR frames; the stored
//!   value is clamped to ±60000 × that scale (both storages), which bounds
//!   what a 1e30 firefly can do to its window;
//! * SIMD tracing steps 8 neighbouring pixels together, by the smallest SDF
//!   step of the 8, so it evaluates a superset of the scalar path's points
//!   (identical away from edges; never less careful).

// Index loops mirror the equations (planes, lanes, features); `!(x > 0)` is
// used on purpose: it is also true for NaN.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod atrous;
pub mod blend;
pub mod features;
pub mod reference;
mod regress;
mod store;
pub mod temporal;

use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::{Frame, GuideSet, MAX_GUIDES};
use crate::image::{ImageView, ImageViewMut, RowBands};
use crate::isa::Kernel;
use crate::parallel::{run_tiles, Bands, Executor, TileRun};

pub use temporal::{History, TemporalConfig};

/// Largest number of regression features (1 + 2 normal + AO + 4 user).
pub const MAX_FEATURES: usize = 8;
/// Default [`WalrConfig::previous_weight`]: 0.6 of the 27×27 window's fit and
/// 0.4 of the 81×81 one's, used when [`WalrConfig::adaptive_blend`] is off;
/// chosen on training scenes (`docs/METHODS.md`, WALR). Neither window suits
/// every region, and the mixture of a narrow and a wide box is a
/// heavier-tailed kernel than either.
pub const DEFAULT_PREVIOUS_WEIGHT: f32 = 0.6;

/// Largest number of à-trous iterations (5: 243×243 pixels).
pub const MAX_ITERATIONS: u8 = 5;

/// How the averages are stored between iterations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Storage {
    /// Half floats, as in the paper (half the memory traffic; the conversions
    /// cost more than they save on CPUs without F16C-vectorised code).
    F16,
    /// Single floats (the default on CPUs: as accurate as f64 sums here, and
    /// no conversions).
    #[default]
    F32,
}

/// Everything that defines a WALR run. The default is the paper's
/// configuration (m = 3 features, 4 iterations, tracing and replacement on),
/// with f32 averages (the paper's f16 is [`Storage::F16`]) and, beyond the
/// paper, the last two windows' fits blended per pixel
/// ([`WalrConfig::adaptive_blend`]; `previous_weight = 0` with it off is the
/// paper's single window).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WalrConfig {
    /// Guides the frames carry. Normal and position are required; depth, if
    /// present, makes the edge-stopping distances relative; AO and user
    /// guides become extra features (rescaled to [0, 1] over the frame).
    pub guides: GuideSet,
    /// À-trous iterations T (1..=5, default 4: an 81×81 window).
    pub iterations: u8,
    /// Plane distance (relative to camera distance with depth, else to the
    /// positions' RMS spread) below which a
    /// tap has full weight (default 0.005, tuned on the training scenes).
    pub near: f32,
    /// Plane distance at and beyond which a tap has weight 0 (default 0.01).
    pub far: f32,
    /// Trace the edge-stopping function along each tap's segment (§3.3).
    /// Off: evaluate it at the tap only (the plain à-trous of Dammertz et al.).
    pub tracing: bool,
    /// Replace a tap cut off by an edge with a random average before the edge.
    pub replace: bool,
    /// Fraction of the previous iteration's edge distance that tracing may skip
    /// (0..=1, default 0.5; 0 visits every pixel of every segment).
    pub sdf_step: f32,
    /// Pivot floor ε_i of Algorithm 1 for the feature pivots (features live in
    /// [0, 1]; default 1e-3, above f16 rounding of the averages).
    pub epsilon: f32,
    /// Storage of the averages.
    pub storage: Storage,
    /// Direction towards the camera in the normals' space, if known: the pole
    /// of the octahedral map. `None`: the frame's mean normal.
    pub view: Option<[f32; 3]>,
    /// Clamp negative output to 0.
    pub clamp_negative: bool,
    /// Kernel implementation (SIMD or the scalar oracle).
    pub kernel: Kernel,
    /// Weight `w` of the previous iteration's fit in the output: each pixel
    /// is `(1 − w)·fit_T + w·fit_{T−1}`, the fits of the 3^T and 3^(T−1)
    /// windows (the sums of iteration T − 1 are still in the other buffer, so
    /// this costs one more solve). 0..=1; 0 is the paper's single window;
    /// ignored when T = 1.
    pub previous_weight: f32,
    /// Blend the last two windows per pixel by their estimated errors
    /// instead of with the fixed `previous_weight` (which is then ignored):
    /// weights 1 / (bias² + variance), from statistics averaged over the
    /// small window ([`blend`]). Costs one more stored plane per pixel (the
    /// light's energy) and a second pass after the solve. Ignored when T = 1.
    pub adaptive_blend: bool,
    /// Temporal pipeline settings: the shared stage's ([`crate::temporal`];
    /// ignored by the single-frame filter).
    pub temporal: TemporalConfig,
    /// The firefly clamp's strength `k` ([`crate::fireflies`]): a noisy
    /// sample whose luminance is above `k` times the larger of the third brightest
    /// 8 × 8 cell of its 104 × 8 pixel neighbourhood and that neighbourhood's
    /// mean without its brightest cell is scaled down to that level
    /// for WALR (the temporal pipeline accumulates each frame's light
    /// clamped). `None` turns it off. Default
    /// `Some(fireflies::DEFAULT_STRENGTH)`; `k ≥ 1`.
    pub fireflies: Option<f32>,
}

impl Default for WalrConfig {
    fn default() -> Self {
        WalrConfig {
            guides: GuideSet { normal: true, depth: true, position: true, ao: false, user: 0 },
            iterations: 4,
            near: 0.005,
            far: 0.01,
            tracing: true,
            replace: true,
            sdf_step: 0.5,
            epsilon: 1e-3,
            storage: Storage::F32,
            view: None,
            clamp_negative: true,
            kernel: Kernel::Simd,
            previous_weight: DEFAULT_PREVIOUS_WEIGHT,
            adaptive_blend: true,
            temporal: TemporalConfig::default(),
            fireflies: Some(fireflies::DEFAULT_STRENGTH),
        }
    }
}

impl WalrConfig {
    /// The default configuration with these guides.
    pub fn with_guides(guides: GuideSet) -> Self {
        WalrConfig { guides, ..Default::default() }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), Error> {
        self.guides.validate()?;
        if !self.guides.normal || !self.guides.position {
            return Err(Error::InvalidConfig("guides: WALR needs normal and position"));
        }
        if !(1..=MAX_ITERATIONS).contains(&self.iterations) {
            return Err(Error::InvalidConfig("iterations (1..=5)"));
        }
        if !(self.near >= 0.0 && self.far > self.near && self.far.is_finite()) {
            return Err(Error::InvalidConfig("near/far (0 ≤ near < far, finite)"));
        }
        if !(0.0..=1.0).contains(&self.sdf_step) {
            return Err(Error::InvalidConfig("sdf_step (0..=1)"));
        }
        if !(self.epsilon > 0.0 && self.epsilon < 1.0) {
            return Err(Error::InvalidConfig("epsilon (0..1)"));
        }
        if !(0.0..=1.0).contains(&self.previous_weight) {
            return Err(Error::InvalidConfig("previous_weight (0..=1)"));
        }
        if let Some(v) = self.view {
            let l = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if !(l > 1e-12 && l.is_finite()) {
                return Err(Error::InvalidConfig("view (non-zero, finite)"));
            }
        }
        if let Some(k) = self.fireflies {
            if !fireflies::valid_strength(k) {
                return Err(Error::InvalidConfig("fireflies strength (must be finite and >= 1)"));
            }
        }
        self.temporal.validate()
    }

    /// Regression features m: 1 + 2 (normal) + AO + user guides.
    pub const fn feature_count(&self) -> usize {
        3 + self.guides.ao as usize + self.guides.user as usize
    }
}

pub use crate::report::Report;

/// A frame checked against the plan: the noisy view and one view per guide channel.
#[derive(Clone, Copy, Debug)]
pub struct CheckedFrame<'a> {
    pub(crate) noisy: ImageView<'a>,
    pub(crate) guides: [Option<ImageView<'a>>; MAX_GUIDES],
}

/// Frame-wide constants computed once per frame by [`Walr::prepare`] (from
/// every 4th pixel of every 4th row, so it costs ~1/16 of a pass).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prepared {
    /// Orthonormal basis whose third vector is the octahedral map's pole.
    pub basis: [[f32; 3]; 3],
    /// Light is stored divided by this: the log-average of the finite,
    /// non-zero noisy values (robust to fireflies, exact under scaling).
    pub light_scale: f32,
    /// (min, 1 / range) of each extra guide (AO, user), for rescaling to [0, 1].
    pub extra: [(f32, f32); MAX_FEATURES - 3],
    /// Seed of the replacement choices (from the frame index).
    pub seed: u32,
    /// The RMS spread of the frame's positions: without depth, plane
    /// distances are relative to it (with depth, to each pixel's depth).
    pub distance: f32,
}

/// The scratch split into its buffers (see [`Walr::parts`]). Rows are
/// contiguous in every buffer, so a band of rows is one sub-slice.
#[derive(Debug)]
pub struct Parts<'s> {
    /// Geometry: per row, planes p (3), n (3), 1/scale, valid, features X_1.. (m − 1).
    pub geo: &'s mut [f32],
    /// The edge-distance fields (as tracing steps, a byte per pixel) of two
    /// consecutive iterations.
    pub sdf: [&'s mut [u8]; 2],
    /// Averages of two consecutive iterations (f32, or f16 bits packed in f32).
    pub z: [&'s mut [f32]; 2],
}

/// WALR for one frame size and configuration.
#[derive(Clone, Copy, Debug)]
pub struct Walr {
    pub(crate) cfg: WalrConfig,
    pub(crate) width: usize,
    pub(crate) height: usize,
    /// Features m.
    pub(crate) m: usize,
}

/// Planes of [`Parts::geo`] before the features.
pub(crate) const GEO_FIXED: usize = 8;
pub(crate) const G_P: usize = 0;
pub(crate) const G_N: usize = 3;
pub(crate) const G_INV_SCALE: usize = 6;
pub(crate) const G_VALID: usize = 7;

impl Walr {
    /// Plans WALR for `width × height` frames.
    pub fn new(cfg: WalrConfig, width: usize, height: usize) -> Result<Self, Error> {
        cfg.validate()?;
        if width == 0 || height == 0 || width > crate::image::MAX_DIM || height > crate::image::MAX_DIM {
            return Err(Error::InvalidSize { arg: Arg::Config, width, height });
        }
        Ok(Walr { cfg, width, height, m: cfg.feature_count() })
    }
    /// The configuration.
    pub fn config(&self) -> &WalrConfig {
        &self.cfg
    }
    /// Frame size.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }
    /// Regression features m.
    pub fn feature_count(&self) -> usize {
        self.m
    }
    /// Stored values per pixel: the sums behind `m(m+1)/2 − 1` values of XX̄
    /// (XX̄₀₀ = 1 is implicit) and `3m` of YX̄ — 14 for m = 3 — then, with the
    /// adaptive blend ([`Walr::blends_adaptively`]), the luminance energy
    /// `Σ ℓ²` (its noise estimate, see [`features::energy`]), and last the
    /// sample count (weight sum) W they are divided by.
    pub fn planes(&self) -> usize {
        self.m * (self.m + 1) / 2 - 1 + 3 * self.m + self.blends_adaptively() as usize + 1
    }
    /// Distance in values between two planes of a row: the width rounded up
    /// to a multiple of 16 (whole 64-byte lines; f16 rows are whole f32s).
    /// (Padding to an odd number of lines, against cache-set aliasing, was
    /// measured 25 % slower at 1920 wide and not kept.)
    pub fn plane_stride(&self) -> usize {
        self.width.div_ceil(16) * 16
    }
    /// Geometry planes per row.
    pub fn geo_planes(&self) -> usize {
        GEO_FIXED + self.m - 1
    }
    /// f32 per row of [`Parts::geo`].
    pub fn geo_row_len(&self) -> usize {
        self.geo_planes() * self.plane_stride()
    }
    /// Stored values per row of an averages buffer (f16 rows padded to an even count).
    pub(crate) fn z_row_values(&self) -> usize {
        // (the plane stride is a multiple of 16: f16 rows are whole f32s)
        self.planes() * self.plane_stride()
    }
    /// f32 per row of each [`Parts::z`] buffer.
    pub fn z_row_len(&self) -> usize {
        match self.cfg.storage {
            Storage::F32 => self.z_row_values(),
            Storage::F16 => self.z_row_values() / 2,
        }
    }
    /// f32 of scratch [`Walr::denoise`] needs.
    pub fn scratch_len(&self) -> usize {
        self.height * (self.geo_row_len() + 2 * self.z_row_len()) + 2 * self.field_len()
    }
    /// f32 of scratch per edge-distance field (a byte per pixel).
    fn field_len(&self) -> usize {
        (self.width * self.height).div_ceil(4)
    }
    /// Which sums buffer iteration `t` reads (iteration `t − 1` wrote it; `t`
    /// writes the other one). [`Walr::solve_rows`] reads `buffer_of(iterations)`
    /// and, with [`WalrConfig::previous_weight`], also `buffer_of(iterations − 1)`.
    pub fn buffer_of(t: u8) -> usize {
        (t % 2) as usize
    }

    /// Iteration `t`'s buffers: the edge field and sums it reads, and those it
    /// writes (by [`Walr::buffer_of`]).
    #[allow(clippy::type_complexity)]
    fn iteration_buffers<'b>(
        t: u8,
        sdf: &'b mut [&mut [u8]; 2],
        z: &'b mut [&mut [f32]; 2],
    ) -> (&'b [u8], &'b mut [u8], &'b [f32], &'b mut [f32]) {
        let ([sa, sb], [za, zb]) = (sdf, z);
        if Self::buffer_of(t) == 0 {
            (&**sa, &mut **sb, &**za, &mut **zb)
        } else {
            (&**sb, &mut **sa, &**zb, &mut **za)
        }
    }

    /// The sums after `t` iterations and those after `t − 1` (the adaptive
    /// blend's last and previous), by [`Walr::buffer_of`].
    fn last_and_previous<'b>(t: u8, z: &'b mut [&mut [f32]; 2]) -> (&'b mut [f32], &'b mut [f32]) {
        let [za, zb] = z;
        if Self::buffer_of(t) == 0 {
            (&mut **za, &mut **zb)
        } else {
            (&mut **zb, &mut **za)
        }
    }

    /// Splits a scratch of at least [`Walr::scratch_len`] f32 into its buffers.
    pub fn parts<'s>(&self, scratch: &'s mut [f32]) -> Result<Parts<'s>, Error> {
        if scratch.len() < self.scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.scratch_len(), got: scratch.len() });
        }
        let h = self.height;
        let (geo, rest) = scratch.split_at_mut(h * self.geo_row_len());
        let (s0, rest) = rest.split_at_mut(self.field_len());
        let (s1, rest) = rest.split_at_mut(self.field_len());
        let n = self.width * h;
        let (s0, s1) = (&mut bytemuck::cast_slice_mut::<f32, u8>(s0)[..n], &mut bytemuck::cast_slice_mut::<f32, u8>(s1)[..n]);
        let (z0, rest) = rest.split_at_mut(h * self.z_row_len());
        let z1 = &mut rest[..h * self.z_row_len()];
        Ok(Parts { geo, sdf: [s0, s1], z: [z0, z1] })
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
            return Err(Error::Unsupported("WALR has no joint upsampling (guides_low given)"));
        }
        if frame.sample_weights.is_some() {
            return Err(Error::Unsupported("WALR has no per-pixel sample weights (Frame::sample_weights given)"));
        }
        let guides = frame.guides.channel_views(&self.cfg.guides, self.width, self.height, Arg::Guide)?;
        Ok(CheckedFrame { noisy: frame.noisy, guides })
    }

    pub(crate) fn check_out(&self, out: &ImageViewMut<'_>, rows: usize) -> Result<(), Error> {
        if out.width() != self.width || out.height() != rows || out.channel_count() < 3 {
            return Err(Error::SizeMismatch { arg: Arg::Output, expected: (self.width, rows), got: (out.width(), out.height()) });
        }
        Ok(())
    }

    /// Checks that a band `y0..y0 + rows` of a row-major buffer with `row_len`
    /// values per row fits the frame and the slice.
    pub(crate) fn check_band(&self, y0: usize, slice_len: usize, row_len: usize) -> Result<usize, Error> {
        let rows = slice_len.checked_div(row_len).unwrap_or(0);
        if rows == 0 || slice_len != rows * row_len || y0 + rows > self.height {
            return Err(Error::InvalidTile { index: y0, count: self.height });
        }
        Ok(rows)
    }

    /// Single-frame WALR on the calling thread. `index` (the frame number)
    /// seeds the replacement choices. `scratch`: at least
    /// [`Walr::scratch_len`] f32. Allocates nothing.
    pub fn denoise(&self, frame: &Frame<'_>, index: u32, scratch: &mut [f32], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        let f = self.check_frame(frame)?;
        self.check_out(out, self.height)?;
        let prep = self.prepare(&f, index);
        let parts = self.parts(scratch)?;
        self.run(&f, &prep, parts, out, self.cfg.fireflies)
    }

    /// Rows per band of a parallel run over `workers` workers: at least 16,
    /// and about eight bands per worker.
    fn parallel_band_rows(&self, workers: usize) -> usize {
        16usize.max(self.height.div_ceil(workers.max(1) * 8))
    }

    /// f32 values of scratch [`Walr::denoise_parallel`] needs for `workers`
    /// workers (`None` if it overflows).
    pub fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let bands = self.height.div_ceil(self.parallel_band_rows(workers));
        self.scratch_len().checked_add(TileRun::scratch_len(bands, workers.max(1), 0)?)
    }

    /// [`Walr::denoise`] with each stage's rows spread in bands by the
    /// caller's executor ([`Executor`]); bit-identical to it. `scratch`: at
    /// least [`Walr::parallel_scratch_len`] f32; `out` must have rows that do
    /// not overlap in memory. Allocates nothing.
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
        self.check_out(out, self.height)?;
        let prep = self.prepare(&f, index);
        self.run_parallel(&f, &prep, scratch, out, workers, for_each, self.cfg.fireflies)
    }

    /// [`Walr::denoise_parallel`] on a checked frame with the firefly clamp
    /// `clamp` (`prep` from [`Walr::prepare_with`] with the same).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run_parallel(
        &self,
        f: &CheckedFrame<'_>,
        prep: &Prepared,
        scratch: &mut [f32],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
        clamp: Option<f32>,
    ) -> Result<Report, Error> {
        let needed = self.parallel_scratch_len(workers).ok_or(Error::InvalidConfig("workers: scratch size overflows"))?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let (own, runs) = scratch.split_at_mut(self.scratch_len());
        let rows = self.parallel_band_rows(workers);
        let nb = self.height.div_ceil(rows);
        let Parts { geo, sdf: [s0, s1], z: [z0, z1] } = self.parts(own)?;
        let (gl, zl, w) = (self.geo_row_len(), self.z_row_len(), self.width);
        let y0 = |b: usize| b * rows;
        // SAFETY (every `get` below): `run_tiles` runs each band once per
        // stage, and a stage writes only its own band of each buffer it writes.
        let mut rep = {
            let (g, z) = (Bands::new(geo, rows * gl), Bands::new(&mut *z0, rows * zl));
            run_tiles(runs, nb, workers, 0, for_each, &|b, _| unsafe {
                self.features_rows_with(f, prep, y0(b), g.get(b), z.get(b), clamp)
            })?
        };
        let geo = &*geo;
        let (mut sdf, mut z) = ([s0, s1], [z0, z1]);
        for t in 0..self.cfg.iterations {
            let (sin, sout, zin, zout) = Self::iteration_buffers(t, &mut sdf, &mut z);
            let (so, zo) = (Bands::new(sout, rows * w), Bands::new(zout, rows * zl));
            run_tiles(runs, nb, workers, 0, for_each, &|b, _| {
                unsafe { self.iterate_rows(t, prep, y0(b), geo, sin, zin, so.get(b), zo.get(b)) }.map(|_| Report::default())
            })?;
        }
        let bands =
            RowBands::new(out).ok_or(Error::Unsupported("a parallel run needs an output whose rows do not overlap (use denoise)"))?;
        // SAFETY: bands of output rows are disjoint, each made once per stage.
        let out_band = |b: usize| unsafe { bands.band(y0(b), rows.min(self.height - y0(b))) };
        if self.blends_adaptively() {
            // pass 1 over every band before pass 2 reads the rows around each
            let t = self.cfg.iterations;
            let (last, prev) = Self::last_and_previous(t, &mut z);
            {
                let (l, p) = (&*last, Bands::new(&mut *prev, rows * zl));
                let lb = |b: usize| &l[(y0(b) * zl).min(l.len())..((y0(b) + rows) * zl).min(l.len())];
                rep += run_tiles(runs, nb, workers, 0, for_each, &|b, _| unsafe { self.fit_rows(y0(b), geo, lb(b), p.get(b)) })?;
            }
            let (p, l) = (&*prev, Bands::new(last, rows * zl));
            run_tiles(runs, nb, workers, 0, for_each, &|b, _| {
                unsafe { self.blend_rows(prep, y0(b), p, l.get(b), &mut out_band(b)?) }.map(|_| Report::default())
            })?;
        } else {
            let zr = [&*z[0], &*z[1]];
            rep += run_tiles(runs, nb, workers, 0, for_each, &|b, _| self.solve_rows(prep, y0(b), geo, zr, &mut out_band(b)?))?;
        }
        Ok(rep)
    }

    /// The stages on one thread, on an already checked frame, with the
    /// firefly clamp `clamp` (`prep` from [`Walr::prepare_with`] with the same).
    pub(crate) fn run(
        &self,
        f: &CheckedFrame<'_>,
        prep: &Prepared,
        parts: Parts<'_>,
        out: &mut ImageViewMut<'_>,
        clamp: Option<f32>,
    ) -> Result<Report, Error> {
        let Parts { geo, sdf: [s0, s1], z: [z0, z1] } = parts;
        let mut rep = self.features_rows_with(f, prep, 0, geo, z0, clamp)?;
        let (mut sdf, mut z) = ([s0, s1], [z0, z1]);
        for t in 0..self.cfg.iterations {
            let (sin, sout, zin, zout) = Self::iteration_buffers(t, &mut sdf, &mut z);
            self.iterate_rows(t, prep, 0, geo, sin, zin, sout, zout)?;
        }
        if self.blends_adaptively() {
            let t = self.cfg.iterations;
            let (last, prev) = Self::last_and_previous(t, &mut z);
            rep += self.fit_rows(0, geo, last, prev)?;
            self.blend_rows(prep, 0, prev, last, out)?;
        } else {
            rep += self.solve_rows(prep, 0, geo, [&*z[0], &*z[1]], out)?;
        }
        Ok(rep)
    }
}
