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
use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::Frame;
use crate::image::{ImageView, ImageViewMut};
use crate::temporal::{Inputs, Reprojection};

pub use crate::temporal::{History, TemporalConfig};

impl Walr {
    fn plane(&self) -> usize {
        self.width * self.height
    }
    /// The temporal stage of this plan (its guides: WALR's normal, position and depth).
    fn stage(&self) -> Result<Reprojection, Error> {
        Reprojection::new(self.cfg.temporal, self.cfg.guides, self.width, self.height)
    }
    /// f32 of the [`History`] buffer.
    pub fn history_len(&self) -> usize {
        self.stage().map_or(0, |s| s.history_len())
    }
    /// f32 of scratch for [`Walr::denoise_temporal`]: WALR's own, the
    /// stage's, WALR's output (RGB) and, with the firefly clamp, the clamped
    /// light (3 planes) and the work of one band's thresholds.
    pub fn temporal_scratch_len(&self) -> usize {
        let stage = self.stage().map_or(0, |s| s.scratch_len());
        self.scratch_len() + stage + 3 * self.plane() + self.frame_clamp_len()
    }
    /// f32 the frame's firefly clamp needs: the clamped light and its work.
    fn frame_clamp_len(&self) -> usize {
        if self.cfg.fireflies.is_some() {
            3 * self.plane() + fireflies::work_len(self.width)
        } else {
            0
        }
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
        let f = self.check_frame(frame)?;
        self.check_out(out, self.height)?;
        let (w, h, np) = (self.width, self.height, self.plane());
        let stage = self.stage()?;
        stage.check_history(history)?;
        if scratch.len() < self.temporal_scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.temporal_scratch_len(), got: scratch.len() });
        }
        let (walr_scratch, rest) = scratch.split_at_mut(self.scratch_len());
        let (stage_scratch, rest) = rest.split_at_mut(stage.scratch_len());
        let (fitted, rest) = rest.split_at_mut(3 * np);
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
            // 2. WALR on the accumulated light (clamped already: WALR does not clamp it again)
            let mut frame2 = *frame;
            frame2.noisy = stage.accumulated(history)?;
            let f2 = self.check_frame(&frame2)?;
            let prep = self.prepare_with(&f2, index, None);
            let mut wout = ImageViewMut::interleaved(fitted, w, h, 3)?;
            let r = self.run(&f2, &prep, self.parts(walr_scratch)?, &mut wout, None)?;
            rep.fallback_pixels += r.fallback_pixels;
        }
        stage.resolve(fitted, history, stage_scratch, c.cut != 0, self.cfg.clamp_negative, out)?;
        Ok(rep)
    }
}
