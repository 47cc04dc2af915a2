//! BMFR's temporal pipeline (Koskela et al. 2019, §3.2) on the temporal stage
//! every pipeline shares ([`crate::temporal`]):
//!
//! 1. **noisy accumulation**: the frame's light, firefly-clamped
//!    ([`super::BmfrConfig::fireflies`]), is accumulated over the history the
//!    stage accepts (bilinear taps rejected by normal and position or depth;
//!    a cumulative average that becomes exponential; a clamped sample counts
//!    as the fraction of it the clamp kept);
//! 2. the block **fit** on the accumulated colour (it does not clamp it again);
//! 3. the **resolve**: the previous output, through the same accepted taps,
//!    clipped to the current 3×3 neighbourhood in YCoCg and blended.
//!
//! The paper's pipeline accumulates the fit's output and then runs a TAA pass
//! with a min/max clamp; the stage's one resolve stands in for both (on the
//! training sequences it scored higher: docs/RESULTS.md). All state lives in
//! a caller-owned [`History`].

use super::{Bmfr, Report, BLOCK_OFFSETS};
use crate::error::Error;
use crate::guides::Frame;
use crate::image::{ImageView, ImageViewMut};
use crate::parallel::Executor;
use crate::temporal::Reprojection;

pub use crate::temporal::{History, TemporalConfig};

impl Bmfr {
    /// The temporal stage of this plan (its guides: BMFR's normal, position and depth).
    fn stage(&self) -> Result<Reprojection, Error> {
        Reprojection::new(self.cfg.temporal, self.cfg.guides, self.width, self.height)
    }
    /// f32 values of the [`History`] buffer.
    pub fn history_len(&self) -> usize {
        self.stage().map_or(0, |s| s.history_len())
    }
    /// f32 values of the scratch for [`Bmfr::denoise_temporal`]: the
    /// pipeline frame's ([`Reprojection::frame_scratch_len`]) and a fit worker.
    pub fn temporal_scratch_len(&self) -> usize {
        let frame = self.stage().ok().and_then(|s| s.frame_scratch_len(None));
        frame.and_then(|n| n.checked_add(self.worker_len())).unwrap_or(usize::MAX)
    }

    /// f32 values of the scratch for [`Bmfr::denoise_temporal_parallel`] with
    /// `workers` (`None` if it overflows): the pipeline frame's and the fit's
    /// tiles for the frame index with the most tiles.
    pub fn temporal_parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let frame = self.stage().ok()?.frame_scratch_len(Some(workers))?;
        frame.checked_add(self.parallel_fit_len(workers)?)
    }

    /// f32 values of the parallel fit's tiles for the frame index with the most tiles.
    fn parallel_fit_len(&self, workers: usize) -> Option<usize> {
        (0..BLOCK_OFFSETS.len() as u32).try_fold(0, |m: usize, i| Some(m.max(self.parallel_scratch_len(i, workers)?)))
    }

    /// One frame of the temporal pipeline. `motion` (2 channels: previous −
    /// current pixel position) may be `None` for a static camera; it is ignored
    /// on the first frame. Allocates nothing.
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

    /// [`Bmfr::denoise_temporal`] with the stage's bands and the fit's tiles
    /// spread by the caller's executor ([`Executor`]); bit-identical to it.
    /// `scratch`: at least [`Bmfr::temporal_parallel_scratch_len`] f32; `out`
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
    /// caller's executor; the fit's worker buffers first in `scratch`, then
    /// the stage's.
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
        self.check_out(out, (0, self.height))?;
        let overflow = Error::InvalidConfig("workers: scratch size overflows");
        let (cfg, stage) = (&self.cfg, self.stage()?);
        let fit_len = match parallel {
            None => self.worker_len(),
            Some((workers, _)) => self.parallel_fit_len(workers).ok_or(overflow)?,
        };
        let stage_len = stage.frame_scratch_len(parallel.map(|p| p.0)).ok_or(overflow)?;
        let needed = fit_len.checked_add(stage_len).ok_or(overflow)?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let (fit, rest) = scratch.split_at_mut(fit_len);
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
                // the fit on the accumulated colour (clamped already: the fit does not clamp it again)
                let mut fit_frame = f;
                fit_frame.noisy = acc;
                match parallel {
                    Some((workers, for_each)) => self.fit_frame_parallel(&fit_frame, index, fit, o, workers, for_each, None),
                    None => self.fit_frame(&fit_frame, index, fit, o, None),
                }
            },
        )
    }
}
