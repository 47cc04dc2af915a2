//! The WALR pipeline (§4): temporal **pre-accumulation** → WALR → a TAA-like
//! **post pass**.
//!
//! 1. Pre-accumulation: the previous accumulated light is reprojected with
//!    `motion` (bilinear, 4 taps); a tap is rejected when its camera distance
//!    differs from the current one by more than `depth_limit` (relative) —
//!    or, without depth, its world position by more than `position_limit`
//!    world units. Blend weight `max(1/n, 1/max_samples)`: a cumulative
//!    moving average over the first `max_samples` frames that then becomes
//!    exponential (§4.2).
//! 2. WALR on the accumulated light.
//! 3. Post pass: the previous output, reprojected without rejection, is
//!    clipped to the current 3×3 neighbourhood's mean ± `clip_gamma` standard
//!    deviations in YCoCg (variance clipping, §4.4) and blended with
//!    `max(1/n, post_alpha)` (the same cumulative-then-exponential scheme,
//!    with the sample count of step 1).
//!
//! With the firefly clamp ([`super::WalrConfig::fireflies`], on by default)
//! step 1 accumulates the frame's light clamped
//! ([`crate::fireflies::clamp_frame`]), and a clamped sample enters the
//! history with its weight scaled by the fraction of it the clamp kept
//! ([`crate::fireflies::kept`]); WALR in step 2 reads the accumulated light
//! as it is.
//!
//! The paper resamples bicubically with dilated motion vectors; this uses
//! bilinear taps (what BMFR's pipeline here uses too, so the two compare).
//! All state lives in a caller-owned [`History`]; planes are f32, full size.

use super::{Report, Walr};
use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::Frame;
use crate::image::{ImageView, ImageViewMut, Layout, SamplesMut};
use crate::reproject::{bilinear_taps, reproject3, rgb, ycocg};

/// Settings of the WALR pipeline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TemporalConfig {
    /// Frames after which the accumulation becomes exponential (default 16).
    pub max_samples: f32,
    /// Lowest blend weight of the new frame in the post pass (default 0.1).
    pub post_alpha: f32,
    /// Half-width of the variance-clipping box in standard deviations (default 1.25).
    pub clip_gamma: f32,
    /// Largest relative camera-distance change of a history tap (default 0.05).
    pub depth_limit: f32,
    /// Without depth: largest world-position change of a history tap (world units, default 0.05).
    pub position_limit: f32,
}

impl Default for TemporalConfig {
    fn default() -> Self {
        TemporalConfig { max_samples: 16.0, post_alpha: 0.1, clip_gamma: 1.25, depth_limit: 0.05, position_limit: 0.05 }
    }
}

impl TemporalConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), Error> {
        if !(self.max_samples >= 1.0 && self.max_samples <= 1e6) {
            return Err(Error::InvalidConfig("temporal.max_samples (1..=1e6)"));
        }
        if !(self.post_alpha > 0.0 && self.post_alpha <= 1.0) {
            return Err(Error::InvalidConfig("temporal.post_alpha (0, 1]"));
        }
        let pos = |v: f32| v >= 0.0 && v.is_finite();
        if !pos(self.clip_gamma) || !pos(self.depth_limit) || !pos(self.position_limit) {
            return Err(Error::InvalidConfig("temporal limits (≥ 0, finite)"));
        }
        Ok(())
    }
}

pub use crate::history::History;

// History planes: accumulated light (3), sample count, post output (3), rejection guide.
const H_ACC: usize = 0;
const H_COUNT: usize = 3;
const H_POST: usize = 4;
const H_GUIDE: usize = 7;
// Scratch planes (after WALR's own scratch).
const S_ACC: usize = 0;
const S_COUNT: usize = 3;
const S_PREV: usize = 4;
const S_WALR: usize = 6;
const S_POST: usize = 9;
const S_GUIDE: usize = 12;

impl Walr {
    fn plane(&self) -> usize {
        self.width * self.height
    }
    /// Planes of the rejection guide: depth (1) or, without it, position (3).
    fn guide_planes(&self) -> usize {
        if self.cfg.guides.depth {
            1
        } else {
            3
        }
    }
    /// f32 of the [`History`] buffer.
    pub fn history_len(&self) -> usize {
        (H_GUIDE + self.guide_planes()) * self.plane()
    }
    /// f32 of scratch for [`Walr::denoise_temporal`]: WALR's own, the
    /// pipeline's planes and, with the firefly clamp, the work of one band's
    /// thresholds.
    pub fn temporal_scratch_len(&self) -> usize {
        self.scratch_len() + self.pipeline_planes_len() + self.frame_clamp_len()
    }
    /// f32 of the pipeline's planes.
    fn pipeline_planes_len(&self) -> usize {
        (S_GUIDE + self.guide_planes()) * self.plane()
    }
    /// f32 the frame's firefly clamp needs besides the planes.
    fn frame_clamp_len(&self) -> usize {
        if self.cfg.fireflies.is_some() {
            fireflies::work_len(self.width)
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
        if let Some(m) = motion {
            if (m.width(), m.height()) != (w, h) {
                return Err(Error::SizeMismatch { arg: Arg::Guide, expected: (w, h), got: (m.width(), m.height()) });
            }
            if m.channel_count() < 2 {
                return Err(Error::ChannelCount { arg: Arg::Guide, expected: 2, got: m.channel_count() });
            }
        }
        if scratch.len() < self.temporal_scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.temporal_scratch_len(), got: scratch.len() });
        }
        if history.data.len() < self.history_len() {
            return Err(Error::BufferTooSmall { arg: Arg::Scratch, needed: self.history_len(), len: history.data.len() });
        }
        let (walr_scratch, rest) = scratch.split_at_mut(self.scratch_len());
        let (planes, clamp_work) = rest.split_at_mut(self.pipeline_planes_len());
        let mut rep = self.pre_accumulate(&f, motion, history, planes, clamp_work)?;

        // 2. WALR on the accumulated light (clamped already: WALR does not clamp it again)
        {
            let (acc, rest) = planes.split_at_mut(S_WALR * np);
            let mut frame2 = *frame;
            frame2.noisy = ImageView::f32(&acc[S_ACC * np..(S_ACC + 3) * np], w, h, 3, Layout::planar(w, h))?;
            let f2 = self.check_frame(&frame2)?;
            let prep = self.prepare_with(&f2, history.frames, None);
            let mut wout = ImageViewMut::new(SamplesMut::F32(&mut rest[..3 * np]), w, h, 3, Layout::planar(w, h))?;
            let r = self.run(&f2, &prep, self.parts(walr_scratch)?, &mut wout, None)?;
            rep.fallback_pixels += r.fallback_pixels;
        }
        self.post(history, planes);

        // 4. commit the state, write the output
        let hd = &mut *history.data;
        hd[H_ACC * np..(H_COUNT + 1) * np].copy_from_slice(&planes[S_ACC * np..(S_COUNT + 1) * np]);
        hd[H_POST * np..(H_POST + 3) * np].copy_from_slice(&planes[S_POST * np..(S_POST + 3) * np]);
        let gp = self.guide_planes();
        hd[H_GUIDE * np..(H_GUIDE + gp) * np].copy_from_slice(&planes[S_GUIDE * np..(S_GUIDE + gp) * np]);
        for y in 0..h {
            let o = y * w;
            let p = &planes[S_POST * np..(S_POST + 3) * np];
            out.write_row_n(y, 0, [&p[o..o + w], &p[np + o..np + o + w], &p[2 * np + o..2 * np + o + w]])
                .ok_or(Error::InvalidTile { index: y, count: h })?;
        }
        history.frames = history.frames.wrapping_add(1).max(1);
        Ok(rep)
    }

    /// Step 1: reprojection, depth rejection and the moving average, of the
    /// light clamped first with the firefly clamp (`clamp_work`: its work).
    fn pre_accumulate(
        &self,
        f: &super::CheckedFrame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &History<'_>,
        planes: &mut [f32],
        clamp_work: &mut [f32],
    ) -> Result<Report, Error> {
        let (w, h, np) = (self.width, self.height, self.plane());
        let tc = &self.cfg.temporal;
        let gp = self.guide_planes();
        let has_depth = self.cfg.guides.depth;
        let bad = Error::InvalidTile { index: 0, count: h };
        let mut rep = Report::default();
        if let Some(k) = self.cfg.fireflies {
            // the frame's light, clamped, is what is accumulated
            let acc = &mut planes[S_ACC * np..(S_ACC + 3) * np];
            rep.clamped_fireflies = fireflies::clamp_frame(&f.noisy, k, acc, clamp_work).ok_or(bad)?;
        }
        // current rejection guide → S_GUIDE planes; noisy (unless clamped above) → S_ACC; motion → S_PREV
        let guide_first = if has_depth { 3 } else { 3 + has_depth as usize };
        for y in 0..h {
            for c in 0..gp {
                let v = f.guides[guide_first + c].as_ref().ok_or(Error::GuideMismatch)?;
                let o = (S_GUIDE + c) * np + y * w;
                v.read_row(y, 0, 0, &mut planes[o..o + w]).ok_or(bad)?;
            }
            if self.cfg.fireflies.is_none() {
                let o = y * w;
                let (r, rest) = planes[S_ACC * np..(S_ACC + 3) * np].split_at_mut(np);
                let (g, b) = rest.split_at_mut(np);
                f.noisy.read_row_n(y, 0, [&mut r[o..o + w], &mut g[o..o + w], &mut b[o..o + w]]).ok_or(bad)?;
            }
            let o = y * w;
            let (mx, my) = planes[S_PREV * np..(S_PREV + 2) * np].split_at_mut(np);
            match motion {
                Some(m) if history.frames > 0 => m.read_row_n(y, 0, [&mut mx[o..o + w], &mut my[o..o + w]]).ok_or(bad)?,
                _ => {
                    mx[o..o + w].fill(0.0);
                    my[o..o + w].fill(0.0);
                }
            }
        }
        let hd = &*history.data;
        let alpha_min = 1.0 / tc.max_samples;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let cur = [planes[i], planes[np + i], planes[2 * np + i]];
                let ok = cur.iter().all(|v| v.is_finite());
                rep.nonfinite_noisy += !ok as u64;
                let (mx, my) = (planes[S_PREV * np + i], planes[(S_PREV + 1) * np + i]);
                let (mx, my) = if mx.is_finite() && my.is_finite() { (mx, my) } else { (0.0, 0.0) };
                let (px, py) = (x as f32 + mx, y as f32 + my);
                planes[S_PREV * np + i] = px;
                planes[(S_PREV + 1) * np + i] = py;
                let g = |c: usize| planes[(S_GUIDE + c) * np + i];
                let (mut tw, mut n, mut prev) = (0f32, 0f32, [0f32; 3]);
                if history.frames > 0 {
                    for (tx, ty, wt) in bilinear_taps(px, py) {
                        if tx < 0 || ty < 0 || tx >= w as i64 || ty >= h as i64 || !(wt > 0.0) {
                            continue;
                        }
                        let j = ty as usize * w + tx as usize;
                        let hg = |c: usize| hd[(H_GUIDE + c) * np + j];
                        let keep = if has_depth {
                            (hg(0) - g(0)).abs() <= tc.depth_limit * g(0).abs()
                        } else {
                            let d2: f32 = (0..3).map(|c| (hg(c) - g(c)) * (hg(c) - g(c))).sum();
                            d2 <= tc.position_limit * tc.position_limit
                        };
                        let pc = [hd[H_ACC * np + j], hd[(H_ACC + 1) * np + j], hd[(H_ACC + 2) * np + j]];
                        let cnt = hd[H_COUNT * np + j];
                        if keep && pc.iter().all(|v| v.is_finite()) && cnt.is_finite() {
                            tw += wt;
                            n += wt * cnt;
                            for c in 0..3 {
                                prev[c] += wt * pc[c];
                            }
                        }
                    }
                }
                let (acc, count) = if tw > 0.0 {
                    let n = n / tw;
                    let prev = prev.map(|v| v / tw);
                    if ok {
                        // a clamped sample counts as the fraction of it the clamp kept
                        let kept = match self.cfg.fireflies {
                            Some(_) => fireflies::kept([0, 1, 2].map(|c| f.noisy.get(x, y, c).unwrap_or(cur[c])), cur),
                            None => 1.0,
                        };
                        let a = (1.0 / (n + 1.0)).max(alpha_min) * kept;
                        ([0, 1, 2].map(|c| a * cur[c] + (1.0 - a) * prev[c]), (n + kept).min(tc.max_samples))
                    } else {
                        (prev, n) // bridge a NaN/Inf sample with the history
                    }
                } else {
                    rep.history_rejected += (history.frames > 0) as u64;
                    (cur, 1.0) // a NaN/Inf stays and is excluded by WALR
                };
                for c in 0..3 {
                    planes[(S_ACC + c) * np + i] = acc[c];
                }
                planes[S_COUNT * np + i] = count;
            }
        }
        Ok(rep)
    }

    /// Step 3: reprojected previous output, variance-clipped, blended.
    fn post(&self, history: &History<'_>, planes: &mut [f32]) {
        let (w, h, np) = (self.width, self.height, self.plane());
        let tc = &self.cfg.temporal;
        let hd = &*history.data;
        let (head, post) = planes.split_at_mut(S_POST * np);
        let cur_of = |i: usize| [head[S_WALR * np + i], head[(S_WALR + 1) * np + i], head[(S_WALR + 2) * np + i]];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let cur = cur_of(i);
                let mut res = cur;
                let (px, py) = (head[S_PREV * np + i], head[(S_PREV + 1) * np + i]);
                if history.frames > 0 {
                    if let Some(prev) = reproject3(&hd[H_POST * np..], np, (w, h), (px, py), 0xF) {
                        let (mut s1, mut s2, mut n) = ([0f32; 3], [0f32; 3], 0f32);
                        for sy in y.saturating_sub(1)..(y + 2).min(h) {
                            for sx in x.saturating_sub(1)..(x + 2).min(w) {
                                let v = ycocg(cur_of(sy * w + sx));
                                for c in 0..3 {
                                    s1[c] += v[c];
                                    s2[c] += v[c] * v[c];
                                }
                                n += 1.0;
                            }
                        }
                        let p = ycocg(prev);
                        let clipped = [0, 1, 2].map(|c| {
                            let mu = s1[c] / n;
                            let sd = libm::sqrtf((s2[c] / n - mu * mu).max(0.0));
                            let (lo, hi) = (mu - tc.clip_gamma * sd, mu + tc.clip_gamma * sd);
                            if p[c] < lo {
                                lo
                            } else if p[c] > hi {
                                hi
                            } else {
                                p[c]
                            }
                        });
                        let prev = rgb(clipped);
                        let a = (1.0 / head[S_COUNT * np + i]).max(tc.post_alpha);
                        res = [0, 1, 2].map(|c| a * cur[c] + (1.0 - a) * prev[c]);
                    }
                }
                for c in 0..3 {
                    let v = if self.cfg.clamp_negative { res[c].max(0.0) } else { res[c] };
                    post[c * np + i] = if v.is_finite() { v } else { 0.0 };
                }
            }
        }
    }
}
