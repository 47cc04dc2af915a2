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

use super::{Bmfr, Report};
use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::Frame;
use crate::image::{ImageView, ImageViewMut};
use crate::temporal::{Inputs, Reprojection};

pub use crate::temporal::{History, TemporalConfig};

impl Bmfr {
    fn plane(&self) -> usize {
        self.width * self.height
    }
    /// The temporal stage of this plan (its guides: BMFR's normal, position and depth).
    fn stage(&self) -> Result<Reprojection, Error> {
        Reprojection::new(self.cfg.temporal, self.cfg.guides, self.width, self.height)
    }
    /// f32 values of the [`History`] buffer.
    pub fn history_len(&self) -> usize {
        self.stage().map_or(0, |s| s.history_len())
    }
    /// f32 values of the scratch for [`Bmfr::denoise_temporal`]: the stage's,
    /// the fit's output (RGB), a fit worker and, with the firefly clamp, the
    /// clamped light (3 planes) and the work of one band's thresholds.
    pub fn temporal_scratch_len(&self) -> usize {
        let stage = self.stage().map_or(0, |s| s.scratch_len());
        stage + 3 * self.plane() + self.worker_len() + self.frame_clamp_len()
    }
    /// f32 values the frame's firefly clamp needs: the clamped light and its work.
    fn frame_clamp_len(&self) -> usize {
        if self.cfg.fireflies.is_some() {
            3 * self.plane() + fireflies::work_len(self.width)
        } else {
            0
        }
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
        let f = self.check_frame(frame)?;
        self.check_out(out, (0, self.height))?;
        let (w, h, np) = (self.width, self.height, self.plane());
        let stage = self.stage()?;
        stage.check_history(history)?;
        if scratch.len() < self.temporal_scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.temporal_scratch_len(), got: scratch.len() });
        }
        let (stage_scratch, rest) = scratch.split_at_mut(stage.scratch_len());
        let (fitted, rest) = rest.split_at_mut(3 * np);
        let (worker, rest) = rest.split_at_mut(self.worker_len());
        let mut rep = Report::default();
        let clamped = match self.cfg.fireflies {
            Some(k) => {
                let (light, work) = rest.split_at_mut(3 * np);
                let bad = Error::BufferTooSmall { arg: Arg::Scratch, needed: self.temporal_scratch_len(), len: 0 };
                rep.clamped_fireflies = fireflies::clamp_frame(&f.noisy, k, light, work).ok_or(bad)?;
                Some(&*light)
            }
            None => None,
        };
        let inputs = Inputs { noisy: f.noisy, clamped, guides: frame.guides, motion: motion.copied() };
        let c = stage.accumulate(&inputs, history, stage_scratch)?;
        rep.history_rejected = c.rejected;
        rep.invalid_motion = c.invalid_motion;
        rep.history_resets = c.cut;
        rep.nonfinite_noisy = c.nonfinite;
        let index = history.frames;
        {
            // 2. the fit on the accumulated colour (clamped already: the fit does not clamp it again)
            let mut fit_frame = f;
            fit_frame.noisy = stage.accumulated(history)?;
            let mut fit_out = ImageViewMut::interleaved(fitted, w, h, 3)?;
            let r = self.fit_frame(&fit_frame, index, worker, &mut fit_out, None)?;
            // (non-finite noisy samples were counted, and bridged, by the stage)
            rep += Report { nonfinite_noisy: 0, ..r };
        }
        stage.resolve(fitted, history, stage_scratch, c.cut != 0, self.cfg.clamp_negative, out)?;
        Ok(rep)
    }
}
