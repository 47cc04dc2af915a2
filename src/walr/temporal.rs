//! The WALR pipeline (§4): temporal **pre-accumulation** → WALR → a TAA-like
//! **post pass**, on the temporal stage every pipeline shares
//! ([`crate::temporal`]):
//!
//! 1. Pre-accumulation: the noisy light, firefly-clamped
//!    ([`super::WalrConfig::fireflies`]), is accumulated over the history the
//!    stage accepts (bilinear taps rejected by normal and position or depth;
//!    a cumulative moving average over the first `max_history` frames that
//!    then becomes exponential, §4.2; a clamped sample counts as the fraction
//!    of it the clamp kept).
//! 2. WALR on the accumulated light (it does not clamp it again).
//! 3. Post pass: the previous output, reprojected through the same taps, is
//!    clipped to the current 3×3 neighbourhood's mean ± `clip_gamma`
//!    standard deviations in YCoCg (variance clipping, §4.4) and blended with
//!    `max(1/n, output_alpha)`.
//!
//! The stage's settings are its defaults, as for every pipeline. (The
//! paper's post pass, a blend weight of at least 0.1 and a clip at 1.25 σ,
//! scored the same on the training sequences: within 0.06 dB.) The paper
//! resamples bicubically with dilated motion vectors; the stage uses
//! bilinear taps.
//! All state lives in a caller-owned [`History`].

use super::{Report, Walr};
use crate::error::Error;
use crate::guides::Frame;
use crate::image::{ImageView, ImageViewMut};
use crate::parallel::Executor;
use crate::temporal::Reprojection;

pub use crate::temporal::{History, TemporalConfig};

impl Walr {
    /// The temporal stage of this plan (its guides: WALR's normal, position and depth).
    fn stage(&self) -> Result<Reprojection, Error> {
        Reprojection::new(self.cfg.temporal, self.cfg.guides, self.width, self.height)
    }
    /// f32 of the [`History`] buffer.
    pub fn history_len(&self) -> usize {
        self.stage().map_or(0, |s| s.history_len())
    }
    /// f32 of scratch for [`Walr::denoise_temporal`]: WALR's own and the
    /// pipeline frame's ([`Reprojection::frame_scratch_len`]).
    pub fn temporal_scratch_len(&self) -> usize {
        let frame = self.stage().ok().and_then(|s| s.frame_scratch_len(None));
        frame.and_then(|n| n.checked_add(self.scratch_len())).unwrap_or(usize::MAX)
    }

    /// f32 of scratch for [`Walr::denoise_temporal_parallel`] with `workers`
    /// (`None` if it overflows): WALR's parallel run's and the pipeline frame's.
    pub fn temporal_parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let frame = self.stage().ok()?.frame_scratch_len(Some(workers))?;
        frame.checked_add(self.parallel_scratch_len(workers)?)
    }

    /// One frame of the WALR pipeline. `motion` (2 channels, previous −
    /// current pixel position) may be `None` for a static camera; it is
    /// ignored on the first frame. Allocates nothing.
    pub fn denoise_temporal(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f32],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        self.run_temporal(frame, motion, history, scratch, out, None)
    }

    /// [`Walr::denoise_temporal`] with the stage's and WALR's bands spread
    /// by the caller's executor ([`Executor`]); bit-identical to it.
    /// `scratch`: at least [`Walr::temporal_parallel_scratch_len`] f32; `out`
    /// must have rows that do not overlap in memory. Allocates nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn denoise_temporal_parallel(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f32],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        self.run_temporal(frame, motion, history, scratch, out, Some((workers, for_each)))
    }

    /// The pipeline on the calling thread (`parallel` `None`) or on the
    /// caller's executor; WALR's scratch first in `scratch`, then the stage's.
    fn run_temporal(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f32],
        out: &mut ImageViewMut<'_>,
        parallel: Option<(usize, Executor<'_>)>,
    ) -> Result<Report, Error> {
        let f = self.check_frame(frame)?;
        self.check_out(out, self.height)?;
        let overflow = Error::InvalidConfig("workers: scratch size overflows");
        let (cfg, stage) = (&self.cfg, self.stage()?);
        let walr_len = match parallel {
            None => self.scratch_len(),
            Some((workers, _)) => self.parallel_scratch_len(workers).ok_or(overflow)?,
        };
        let needed = walr_len.checked_add(stage.frame_scratch_len(parallel.map(|p| p.0)).ok_or(overflow)?).ok_or(overflow)?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let (walr_scratch, rest) = scratch.split_at_mut(walr_len);
        stage.run_frame(
            f.noisy,
            frame.guides,
            motion.copied(),
            cfg.fireflies,
            cfg.clamp_negative,
            history,
            rest,
            parallel,
            out,
            |acc, _, index, o| {
                // WALR on the accumulated light (clamped already: WALR does not clamp it again)
                let f2 = self.check_frame(&Frame { noisy: acc, ..*frame })?;
                let prep = self.prepare_with(&f2, index, None);
                match parallel {
                    Some((workers, for_each)) => self.run_parallel(&f2, &prep, walr_scratch, o, workers, for_each, None),
                    None => self.run(&f2, &prep, self.parts(walr_scratch)?, o, None),
                }
            },
        )
    }
}
