//! Temporal FLR: FLR fitted on light accumulated over the frames where the
//! history is valid, with its output accumulated again under a clip
//! ([`crate::temporal`] is the stage, shared with the other pipelines).
//!
//! Per frame: the noisy light is firefly-clamped ([`crate::fireflies`], with
//! [`FlrConfig::fireflies`]), accumulated ([`Reprojection::accumulate`]),
//! denoised by FLR (the schedule of [`Flr::denoise`], on one thread or over
//! the caller's executor) and resolved ([`Reprojection::resolve`]). FLR
//! itself runs without its clamp: the light it reads was clamped already.
//!
//! ```
//! use lrdenoise::flr::temporal::TemporalFlr;
//! use lrdenoise::temporal::{History, TemporalConfig};
//! use lrdenoise::{FlrConfig, Frame, Guides, GuideSet, ImageView, ImageViewMut};
//! let (w, h) = (32, 24);
//! let (noisy, normal, depth) = (vec![0.5f32; w * h * 3], vec![0.0f32; w * h * 3], vec![1.0f32; w * h]);
//! let motion = vec![0.0f32; w * h * 2];
//! let cfg = FlrConfig { guides: GuideSet::NORMAL_DEPTH, ..FlrConfig::temporal() };
//! let tflr = TemporalFlr::new(cfg, TemporalConfig::default(), w, h)?;
//! let (mut history, mut scratch) = (vec![0f32; tflr.history_len()], vec![0f32; tflr.scratch_len()]);
//! let mut flr_scratch = vec![0f64; tflr.flr_scratch_len()];
//! let mut history = History::new(&mut history); // one per sequence
//! let mut out = vec![0f32; w * h * 3];
//! for _ in 0..3 {
//!     let guides = Guides {
//!         normal: Some(ImageView::interleaved(&normal, w, h, 3)?),
//!         depth: Some(ImageView::interleaved(&depth, w, h, 1)?),
//!         ..Default::default()
//!     };
//!     let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3)?, guides);
//!     let mv = ImageView::interleaved(&motion, w, h, 2)?;
//!     let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3)?;
//!     tflr.denoise(&frame, Some(&mv), &mut history, &mut scratch, &mut flr_scratch, &mut ov)?;
//! }
//! assert_eq!(history.frames(), 3);
//! assert!((out[0] - 0.5).abs() < 1e-3);
//! # Ok::<(), lrdenoise::Error>(())
//! ```

use super::config::FlrConfig;
use super::{CheckedFrame, Flr};
use crate::error::Error;
use crate::guides::{Frame, GuideSet};
use crate::image::{ImageView, ImageViewMut};
use crate::parallel::Executor;
use crate::report::Report;
use crate::temporal::{History, Reprojection, TemporalConfig};

/// A temporal FLR plan: FLR and the temporal stage for one frame size.
#[derive(Clone, Debug)]
pub struct TemporalFlr {
    /// FLR on the accumulated light (its clamp off: the stage's input is clamped).
    flr: Flr,
    /// FLR as configured: what a single frame (`Denoiser::denoise`) runs.
    single: Flr,
    stage: Reprojection,
    fireflies: Option<f32>,
    /// Whether the fit weighs each pixel by its history length.
    history_weights: bool,
}

impl TemporalFlr {
    /// Plans temporal FLR for `width × height` frames. The stage rejects
    /// history with the guides of `cfg.guides` it knows (normal, position,
    /// depth); joint upsampling (`cfg.upsample > 1`) is not supported.
    /// [`FlrConfig::temporal`] is the default configuration for it (smaller
    /// windows than a single frame's).
    pub fn new(cfg: FlrConfig, temporal: TemporalConfig, width: usize, height: usize) -> Result<Self, Error> {
        if cfg.upsample != 1 {
            return Err(Error::Unsupported("temporal FLR with upsample > 1"));
        }
        let single = Flr::new(cfg, width, height)?;
        let flr = Flr::new(FlrConfig { fireflies: None, ..cfg }, width, height)?;
        let stage = Reprojection::new(temporal, cfg.guides, width, height)?;
        Ok(TemporalFlr { flr, single, stage, fireflies: cfg.fireflies, history_weights: false })
    }
    /// With `on`, FLR's fit weighs each pixel by its history length (the
    /// samples its accumulated light averages, [`Frame::sample_weights`]), so that
    /// young pixels (disocclusions, the edge a pan uncovers) move the fit less
    /// than converged ones; they are still predicted through their guides.
    /// Off by default: on the training sequences it lowered the mean PSNR of
    /// the last 4 frames by 0.07 dB (`docs/METHODS.md`), and it moves the
    /// moments off FLR's in-place fast path.
    pub fn with_history_weights(mut self, on: bool) -> Self {
        self.history_weights = on;
        self
    }
    /// The same plan with history taps rejected by the guides of `guides`
    /// (normal, position, depth; [`Reprojection::new`]) rather than those of
    /// FLR's fit: world positions, where a frame has them, judge a tap by
    /// where it is, whatever the camera did, while depth changes as the
    /// camera moves towards or away from a surface (`lrd` rejects with
    /// positions when the frames have them). The frames then carry FLR's
    /// guides and these; the history's size follows.
    pub fn with_rejection_guides(mut self, guides: GuideSet) -> Result<Self, Error> {
        let (w, h) = self.single.size();
        self.stage = Reprojection::new(*self.stage.config(), guides, w, h)?;
        Ok(self)
    }
    /// The guides each frame carries: FLR's and the stage's rejection guides.
    pub fn frame_guides(&self) -> GuideSet {
        self.flr.config().guides.with_geometry_of(self.stage.rejection_guides())
    }
    /// Whether the fit weighs pixels by their history length ([`TemporalFlr::with_history_weights`]).
    pub fn history_weights(&self) -> bool {
        self.history_weights
    }
    /// The FLR plan that runs on the accumulated light (its clamp is off).
    pub fn flr(&self) -> &Flr {
        &self.flr
    }
    /// FLR as configured (clamp included): the single-frame method.
    pub fn single_frame(&self) -> &Flr {
        &self.single
    }
    /// The temporal stage.
    pub fn stage(&self) -> &Reprojection {
        &self.stage
    }
    /// f32 values of the [`History`] buffer.
    pub fn history_len(&self) -> usize {
        self.stage.history_len()
    }
    /// f32 values of the scratch of [`TemporalFlr::denoise`]
    /// ([`Reprojection::frame_scratch_len`]).
    pub fn scratch_len(&self) -> usize {
        self.stage.frame_scratch_len(None).unwrap_or(usize::MAX)
    }
    /// f32 values of the scratch of [`TemporalFlr::denoise_parallel`] with `workers`.
    pub fn parallel_scratch_len(&self, workers: usize) -> usize {
        self.stage.frame_scratch_len(Some(workers)).unwrap_or(usize::MAX)
    }
    /// f64 values of FLR's scratch for [`TemporalFlr::denoise`].
    pub fn flr_scratch_len(&self) -> usize {
        self.flr.scratch_len()
    }
    /// f64 values of FLR's scratch for [`TemporalFlr::denoise_parallel`] with `workers`.
    pub fn parallel_flr_scratch_len(&self, workers: usize) -> usize {
        self.flr.tiled_scratch_len(workers).unwrap_or(usize::MAX)
    }

    /// One frame of the sequence, on the calling thread. `motion` (2
    /// channels, previous − current pixel position) may be `None` for a
    /// static camera. Allocates nothing.
    pub fn denoise(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f32],
        flr_scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        self.run(frame, motion, history, scratch, out, None, |flr, f, o| flr.denoise_checked(f, flr_scratch, o))
    }

    /// [`TemporalFlr::denoise`] with FLR's tiles over the caller's executor
    /// (as [`Flr::denoise_parallel`]); the same bits.
    #[allow(clippy::too_many_arguments)]
    pub fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f32],
        flr_scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        self.run(frame, motion, history, scratch, out, Some((workers, for_each)), |flr, f, o| {
            flr.denoise_parallel_checked(f, flr_scratch, o, workers, for_each)
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f32],
        out: &mut ImageViewMut<'_>,
        parallel: Option<(usize, Executor<'_>)>,
        fit: impl FnOnce(&Flr, &CheckedFrame<'_>, &mut ImageViewMut<'_>) -> Result<Report, Error>,
    ) -> Result<Report, Error> {
        self.flr.check_output(out)?;
        // the guides only the stage reads (rejection guides beyond FLR's set) are not FLR's
        let (fit_set, reject) = (self.flr.config().guides, self.stage.rejection_guides());
        let mut fit_guides = frame.guides;
        if reject.normal && !fit_set.normal {
            fit_guides.normal = None;
        }
        if reject.position && !fit_set.position {
            fit_guides.position = None;
        }
        if reject.depth && !fit_set.depth {
            fit_guides.depth = None;
        }
        self.flr.check_frame(&Frame { guides: fit_guides, ..*frame })?;
        if frame.guides_low.is_some() {
            return Err(Error::Unsupported("temporal FLR with a second (low-resolution) guide set"));
        }
        if frame.sample_weights.is_some() {
            return Err(Error::Unsupported("temporal FLR with Frame::sample_weights (see TemporalFlr::with_history_weights)"));
        }
        let clamp_negative = self.flr.config().clamp_negative;
        let (guides, st) = (frame.guides, &self.stage);
        st.run_frame(
            frame.noisy,
            guides,
            motion.copied(),
            self.fireflies,
            clamp_negative,
            history,
            scratch,
            parallel,
            out,
            |acc, lengths, _, o| {
                let sample_weights = self.history_weights.then_some(lengths);
                fit(&self.flr, &self.flr.check_frame(&Frame { noisy: acc, guides: fit_guides, guides_low: None, sample_weights })?, o)
            },
        )
    }
}

crate::denoiser::single_frame_is_flr!(TemporalFlr);

impl crate::TemporalDenoiser for TemporalFlr {
    fn history_len(&self) -> usize {
        TemporalFlr::history_len(self)
    }
    /// FLR's f64 scratch, then the pipeline's f32 scratch packed two per f64.
    fn temporal_scratch_len(&self) -> usize {
        self.flr_scratch_len() + self.scratch_len().div_ceil(2)
    }
    fn denoise_temporal(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        let needed = crate::TemporalDenoiser::temporal_scratch_len(self);
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let (flr, own) = scratch.split_at_mut(self.flr_scratch_len());
        let own = &mut bytemuck::cast_slice_mut::<f64, f32>(own)[..self.scratch_len()];
        self.denoise(frame, motion, history, own, flr, out)
    }
    /// FLR's tiled f64 scratch, then the pipeline's f32 scratch packed two per f64.
    fn temporal_parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let flr = self.flr.tiled_scratch_len(workers)?;
        let own = self.stage.frame_scratch_len(Some(workers))?;
        flr.checked_add(own.div_ceil(2))
    }
    fn denoise_temporal_parallel(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let too_many = Error::InvalidConfig("workers: scratch size overflows");
        let needed = crate::TemporalDenoiser::temporal_parallel_scratch_len(self, workers).ok_or(too_many)?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let (flr, own) = scratch.split_at_mut(self.parallel_flr_scratch_len(workers));
        let own = &mut bytemuck::cast_slice_mut::<f64, f32>(own)[..self.parallel_scratch_len(workers)];
        self.denoise_parallel(frame, motion, history, own, flr, out, workers, for_each)
    }
}
