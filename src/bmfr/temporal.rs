//! BMFR's temporal pipeline (Koskela et al. 2019, §3.2; the authors' OpenCL
//! kernels `accumulate_noisy_data`, `accumulate_filtered_data`, `taa`):
//!
//! 1. **noisy accumulation**: reproject the previous accumulated noisy colour
//!    with `motion` (bilinear, 4 taps), drop taps whose world position, normal
//!    (or, without positions, depth) differs too much, and blend with weight
//!    `max(1/n, noisy_alpha)` (a cumulative average that becomes exponential);
//! 2. the block **fit** on the accumulated colour;
//! 3. **filtered accumulation**: the same reprojection (same accepted taps) of
//!    the previous filtered output, blend `max(1/n, filtered_alpha)`;
//! 4. **TAA**: the previous TAA output, reprojected without rejection and
//!    clamped to the current 3×3 neighbourhood in YCoCg, blend `taa_alpha`.
//!
//! With the firefly clamp ([`super::BmfrConfig::fireflies`], on by default)
//! step 1 accumulates the frame's light clamped
//! ([`crate::fireflies::clamp_frame`]), and a clamped sample enters the
//! history with its weight scaled by the fraction of it the clamp kept
//! ([`crate::fireflies::kept`]): an outlier clamped to a hundredth counts as
//! a hundredth of a sample. The fit of step 2 reads the accumulated colour as
//! it is.
//!
//! All state lives in a caller-owned [`History`]; planes are f32, full size.

use super::{Bmfr, Report};
use crate::error::{Arg, Error};
use crate::fireflies;
use crate::guides::Frame;
use crate::image::{ImageView, ImageViewMut, Layout, SamplesMut};
use crate::reproject::{bilinear_taps, clamp_box_row, floor, reproject3, rgb, ycocg};

/// Settings of the temporal pipeline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TemporalConfig {
    /// Lowest blend weight of the new noisy sample (0.2 in the paper).
    pub noisy_alpha: f32,
    /// Lowest blend weight of the new filtered frame (0.1).
    pub filtered_alpha: f32,
    /// Blend weight of the new frame in TAA (0.2; 1 turns TAA off).
    pub taa_alpha: f32,
    /// Largest squared distance between previous and current unit normals
    /// (1.0, the original's: an angle of 60°).
    pub normal_limit: f32,
    /// Largest distance between previous and current world positions, as a
    /// fraction of the camera distance when the frame has depth (0.05), in
    /// world units when it has none.
    pub position_limit: f32,
    /// Without positions: largest relative depth difference (0.05).
    pub depth_limit: f32,
}

impl Default for TemporalConfig {
    fn default() -> Self {
        TemporalConfig { noisy_alpha: 0.2, filtered_alpha: 0.1, taa_alpha: 0.2, normal_limit: 1.0, position_limit: 0.05, depth_limit: 0.05 }
    }
}

impl TemporalConfig {
    /// Checks every field: blend weights in `(0, 1]`, limits finite and ≥ 0.
    pub fn validate(&self) -> Result<(), Error> {
        let unit = |v: f32| v > 0.0 && v <= 1.0;
        if !unit(self.noisy_alpha) || !unit(self.filtered_alpha) || !unit(self.taa_alpha) {
            return Err(Error::InvalidConfig("temporal blend weights (0, 1]"));
        }
        let pos = |v: f32| v >= 0.0 && v.is_finite();
        if !pos(self.normal_limit) || !pos(self.position_limit) || !pos(self.depth_limit) {
            return Err(Error::InvalidConfig("temporal rejection limits (≥ 0, finite)"));
        }
        Ok(())
    }
}

pub use crate::history::History;

// History planes.
const H_ACC: usize = 0; // 3
const H_COUNT: usize = 3;
const H_FILT: usize = 4; // 3
const H_TAA: usize = 7; // 3
const H_GUIDES: usize = 10; // normal 3, position 3, depth 1 (those present)

// Scratch planes.
const S_ACC: usize = 0; // 3
const S_COUNT: usize = 3;
const S_PREV: usize = 4; // 2: previous-frame pixel coordinates
const S_ACCEPT: usize = 6; // accepted taps, bit mask as f32
const S_FIT: usize = 7; // 3: fit, then filtered accumulation in place
const S_TAA: usize = 10; // 3
const S_PLANES: usize = 13;

/// Channels of the current frame used for rejection: (first guide channel, count).
#[derive(Clone, Copy, Debug)]
struct Rejection {
    normal: Option<usize>,
    position: Option<usize>,
    depth: Option<usize>,
    planes: usize,
}

impl Bmfr {
    fn rejection(&self) -> Rejection {
        let s = &self.cfg.guides;
        let normal = s.normal.then_some(0);
        let depth = s.depth.then_some(3 * s.normal as usize);
        let position = s.position.then_some(3 * s.normal as usize + s.depth as usize);
        Rejection { normal, position, depth, planes: 3 * s.normal as usize + 3 * s.position as usize + s.depth as usize }
    }
    fn plane(&self) -> usize {
        self.width * self.height
    }
    /// f32 values of the [`History`] buffer.
    pub fn history_len(&self) -> usize {
        (H_GUIDES + self.rejection().planes) * self.plane()
    }
    /// f32 values of the scratch for [`Bmfr::denoise_temporal`]: the
    /// pipeline's planes, 15 rows, a fit worker and, with the firefly clamp,
    /// the work of one band's thresholds.
    pub fn temporal_scratch_len(&self) -> usize {
        S_PLANES * self.plane() + 15 * self.width + self.worker_len() + self.frame_clamp_len()
    }
    /// f32 values the temporal pipeline's frame clamp needs besides its planes.
    fn frame_clamp_len(&self) -> usize {
        if self.cfg.fireflies.is_some() {
            fireflies::work_len(self.width)
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
        if let Some(m) = motion {
            if (m.width(), m.height()) != (self.width, self.height) {
                return Err(Error::SizeMismatch { arg: Arg::Guide, expected: (self.width, self.height), got: (m.width(), m.height()) });
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
        let (w, h, np) = (self.width, self.height, self.plane());
        let (planes, rest) = scratch.split_at_mut(S_PLANES * np);
        let (rows, rest) = rest.split_at_mut(15 * w);
        let (worker, clamp_work) = rest.split_at_mut(self.worker_len());
        let index = history.frames;
        let mut rep = match self.cfg.fireflies {
            // 0. the firefly clamp: the frame's light, clamped, into the fit planes
            // (free until stage 2), and accumulated from there
            Some(k) => {
                let (head, fit) = planes.split_at_mut(S_FIT * np);
                let light = &mut fit[..3 * np];
                let clamped = fireflies::clamp_frame(&f.noisy, k, light, clamp_work).ok_or(Error::InvalidTile { index: 0, count: h })?;
                let cf = super::CheckedFrame { noisy: ImageView::f32(light, w, h, 3, Layout::planar(w, h))?, guides: f.guides };
                let r = self.accumulate_noisy(&cf, Some(&f.noisy), motion, history, head, rows)?;
                Report { clamped_fireflies: clamped, ..r }
            }
            None => self.accumulate_noisy(&f, None, motion, history, planes, rows)?,
        };

        // 2. fit on the accumulated colour (clamped already: the fit does not clamp it again)
        let (acc, fit_and_rest) = planes.split_at_mut(S_FIT * np);
        let acc_view = ImageView::f32(&acc[..3 * np], w, h, 3, Layout::planar(w, h))?;
        let mut fit_frame = f;
        fit_frame.noisy = acc_view;
        {
            let mut fit_out = ImageViewMut::new(SamplesMut::F32(&mut fit_and_rest[..3 * np]), w, h, 3, Layout::planar(w, h))?;
            let r = self.fit_frame(&fit_frame, index, worker, &mut fit_out, None)?;
            // (non-finite noisy samples were counted, and bridged, by the accumulation)
            rep += Report { nonfinite_noisy: 0, ..r };
        }
        self.accumulate_filtered(history, planes);
        self.taa(history, planes, rows);

        // 5. commit the new state and write the output
        let hd = &mut *history.data;
        hd[H_ACC * np..(H_COUNT + 1) * np].copy_from_slice(&planes[S_ACC * np..(S_COUNT + 1) * np]);
        hd[H_FILT * np..(H_FILT + 3) * np].copy_from_slice(&planes[S_FIT * np..(S_FIT + 3) * np]);
        hd[H_TAA * np..(H_TAA + 3) * np].copy_from_slice(&planes[S_TAA * np..(S_TAA + 3) * np]);
        self.store_guides(&f, hd, rows)?;
        for y in 0..h {
            let o = S_TAA * np + y * w;
            let (r, gb) = planes[o..o + 2 * np + w].split_at(np);
            let src = [&r[..w], &gb[..w], &gb[np..np + w]];
            out.write_row_n(y, 0, src).ok_or(Error::InvalidTile { index: y, count: h })?;
        }
        history.frames = history.frames.wrapping_add(1).max(1);
        Ok(rep)
    }

    /// Reads the rejection guides of row `y` into `dst` (planes of `w`).
    fn read_rejection_row(&self, f: &super::CheckedFrame<'_>, y: usize, dst: &mut [f32]) -> Result<(), Error> {
        let rj = self.rejection();
        let w = self.width;
        let mut p = 0;
        for (first, n) in [(rj.normal, 3), (rj.position, 3), (rj.depth, 1)] {
            let Some(first) = first else { continue };
            for c in 0..n {
                let v = f.guides[first + c].as_ref().ok_or(Error::GuideMismatch)?;
                v.read_row(y, 0, 0, &mut dst[p * w..(p + 1) * w]).ok_or(Error::InvalidTile { index: y, count: 0 })?;
                p += 1;
            }
        }
        Ok(())
    }

    fn store_guides(&self, f: &super::CheckedFrame<'_>, hd: &mut [f32], rows: &mut [f32]) -> Result<(), Error> {
        let (w, np) = (self.width, self.plane());
        let planes = self.rejection().planes;
        for y in 0..self.height {
            self.read_rejection_row(f, y, rows)?;
            for p in 0..planes {
                hd[(H_GUIDES + p) * np + y * w..(H_GUIDES + p) * np + (y + 1) * w].copy_from_slice(&rows[p * w..(p + 1) * w]);
            }
        }
        Ok(())
    }

    /// Stage 1: reprojection, rejection and noisy accumulation → scratch
    /// planes (the planes below `S_FIT`: `planes` may end there).
    fn accumulate_noisy(
        &self,
        f: &super::CheckedFrame<'_>,
        raw: Option<&ImageView<'_>>,
        motion: Option<&ImageView<'_>>,
        history: &History<'_>,
        planes: &mut [f32],
        rows: &mut [f32],
    ) -> Result<Report, Error> {
        let (w, h, np) = (self.width, self.height, self.plane());
        let t = &self.cfg.temporal;
        let rj = self.rejection();
        let hd = &*history.data;
        let has_history = history.frames > 0;
        let mut rep = Report::default();
        let bad = Error::InvalidTile { index: 0, count: 0 };
        let (cur, rest) = rows.split_at_mut(7 * w);
        let (rgb, rest) = rest.split_at_mut(3 * w);
        let (mv, raw_rgb) = rest.split_at_mut(2 * w);
        for y in 0..h {
            self.read_rejection_row(f, y, cur)?;
            {
                let (r, gb) = rgb.split_at_mut(w);
                let (g, b) = gb.split_at_mut(w);
                f.noisy.read_row_n(y, 0, [r, g, &mut b[..w]]).ok_or(bad)?;
            }
            if let Some(raw) = raw {
                let (r, gb) = raw_rgb[..3 * w].split_at_mut(w);
                let (g, b) = gb.split_at_mut(w);
                raw.read_row_n(y, 0, [r, g, b]).ok_or(bad)?;
            }
            match motion {
                Some(m) if has_history => {
                    let (mx, my) = mv.split_at_mut(w);
                    m.read_row_n(y, 0, [mx, &mut my[..w]]).ok_or(bad)?;
                }
                _ => mv[..2 * w].fill(0.0),
            }
            for x in 0..w {
                let i = y * w + x;
                let c = [rgb[x], rgb[w + x], rgb[2 * w + x]];
                let cur_ok = c.iter().all(|v| v.is_finite());
                rep.nonfinite_noisy += !cur_ok as u64;
                let (mx, my) = (mv[x], mv[w + x]);
                let (mx, my) = if mx.is_finite() && my.is_finite() { (mx, my) } else { (0.0, 0.0) };
                let (px, py) = (x as f32 + mx, y as f32 + my);
                let mut accept = 0u32;
                let (mut tw, mut spp, mut prev) = (0f32, 0f32, [0f32; 3]);
                if has_history {
                    let g = |p: usize| cur[p * w + x];
                    for (k, (tx, ty, wt)) in bilinear_taps(px, py).into_iter().enumerate() {
                        if tx < 0 || ty < 0 || tx >= w as i64 || ty >= h as i64 || wt <= 0.0 || wt.is_nan() {
                            continue;
                        }
                        let j = ty as usize * w + tx as usize;
                        let hg = |p: usize| hd[(H_GUIDES + p) * np + j];
                        let mut p = 0;
                        let mut ok = true;
                        if rj.normal.is_some() {
                            let d2: f32 = (0..3).map(|c| (hg(c) - g(c)) * (hg(c) - g(c))).sum();
                            ok &= d2 < t.normal_limit;
                            p = 3;
                        }
                        let depth_plane = rj.depth.map(|_| p + 3 * rj.position.is_some() as usize);
                        let depth = depth_plane.map(|d| g(d).abs());
                        if rj.position.is_some() {
                            let d2: f32 = (p..p + 3).map(|c| (hg(c) - g(c)) * (hg(c) - g(c))).sum();
                            let lim = t.position_limit * depth.unwrap_or(1.0);
                            ok &= d2 < lim * lim;
                        } else if let Some(d) = depth_plane {
                            ok &= (hg(d) - g(d)).abs() < t.depth_limit * g(d).abs();
                        }
                        let pc = [hd[H_ACC * np + j], hd[(H_ACC + 1) * np + j], hd[(H_ACC + 2) * np + j]];
                        let n = hd[H_COUNT * np + j];
                        ok &= pc.iter().all(|v| v.is_finite()) && n.is_finite();
                        if ok {
                            accept |= 1 << k;
                            tw += wt;
                            spp += wt * n;
                            for ch in 0..3 {
                                prev[ch] += wt * pc[ch];
                            }
                        }
                    }
                }
                let (acc, count) = if tw > 0.0 {
                    let spp = spp / tw;
                    let prev = prev.map(|v| v / tw);
                    if cur_ok {
                        // a clamped sample counts as the fraction of it the clamp kept
                        let kept = raw.map_or(1.0, |_| fireflies::kept([raw_rgb[x], raw_rgb[w + x], raw_rgb[2 * w + x]], c));
                        let a = (1.0 / (spp + 1.0)).max(t.noisy_alpha) * kept;
                        ([0, 1, 2].map(|ch| a * c[ch] + (1.0 - a) * prev[ch]), spp.min(254.0) + kept)
                    } else {
                        (prev, spp) // bridge a NaN/Inf sample with the history
                    }
                } else {
                    rep.history_rejected += has_history as u64;
                    (c, 1.0)
                };
                for ch in 0..3 {
                    planes[(S_ACC + ch) * np + i] = acc[ch];
                }
                planes[S_COUNT * np + i] = count;
                planes[S_PREV * np + i] = px;
                planes[(S_PREV + 1) * np + i] = py;
                planes[S_ACCEPT * np + i] = accept as f32;
            }
        }
        Ok(rep)
    }

    /// Stage 3: filtered accumulation, in place on the fit planes.
    fn accumulate_filtered(&self, history: &History<'_>, planes: &mut [f32]) {
        if history.frames == 0 {
            return;
        }
        let (w, np) = (self.width, self.plane());
        let hd = &*history.data;
        let alpha = self.cfg.temporal.filtered_alpha;
        for i in 0..np {
            let accept = planes[S_ACCEPT * np + i] as u32;
            if accept == 0 {
                continue;
            }
            let (px, py) = (planes[S_PREV * np + i], planes[(S_PREV + 1) * np + i]);
            if let Some(prev) = reproject3(&hd[H_FILT * np..], np, (w, self.height), (px, py), accept) {
                let a = (1.0 / planes[S_COUNT * np + i]).max(alpha);
                for ch in 0..3 {
                    let f = &mut planes[(S_FIT + ch) * np + i];
                    *f = a * *f + (1.0 - a) * prev[ch];
                }
            }
        }
    }

    /// Stage 4: TAA with neighbourhood clamping in YCoCg → the TAA planes.
    /// `rows`: 15 rows of scratch (three rows of YCoCg, rolling, and the
    /// clamp box of the current row).
    fn taa(&self, history: &History<'_>, planes: &mut [f32], rows: &mut [f32]) {
        let (w, h, np) = (self.width, self.height, self.plane());
        let hd = &*history.data;
        let alpha = self.cfg.temporal.taa_alpha;
        let (head, taa) = planes.split_at_mut(S_TAA * np);
        let filt = &head[S_FIT * np..(S_FIT + 3) * np];
        let at = |p: &[f32], i: usize| [p[i], p[np + i], p[2 * np + i]];
        let (yc, boxes) = rows.split_at_mut(9 * w);
        let (lo, hi) = boxes.split_at_mut(3 * w);
        let to_ycocg = |y: usize, dst: &mut [f32]| {
            for x in 0..w {
                let v = ycocg(at(filt, y * w + x));
                for c in 0..3 {
                    dst[c * w + x] = v[c];
                }
            }
        };
        let clamping = history.frames > 0;
        if clamping {
            to_ycocg(0, &mut yc[3 * w..6 * w]);
        }
        for y in 0..h {
            if clamping {
                // slot (y + k) % 3 holds row y − 1 + k … here: rows y − 1, y, y + 1
                if y + 1 < h {
                    to_ycocg(y + 1, &mut yc[((y + 2) % 3) * 3 * w..((y + 2) % 3 + 1) * 3 * w]);
                }
                let slot = |r: usize| &yc[(r % 3) * 3 * w..(r % 3 + 1) * 3 * w];
                let above = (y > 0).then(|| slot(y));
                let below = (y + 1 < h).then(|| slot(y + 2));
                clamp_box_row(above, slot(y + 1), below, w, &mut lo[..3 * w], &mut hi[..3 * w]);
            }
            for x in 0..w {
                let i = y * w + x;
                let cur = at(filt, i);
                let (px, py) = (head[S_PREV * np + i], head[(S_PREV + 1) * np + i]);
                let (fx, fy) = (floor(px), floor(py));
                let outside = !(fx >= -1.0 && fy >= -1.0 && fx < w as f32 && fy < h as f32);
                let mut res = cur;
                if clamping && !outside {
                    if let Some(prev) = reproject3(&hd[H_TAA * np..], np, (w, h), (px, py), 0xF) {
                        let p = ycocg(prev);
                        let clamped = [0, 1, 2].map(|c| p[c].max(lo[c * w + x]).min(hi[c * w + x]));
                        let prev = rgb(clamped);
                        res = [0, 1, 2].map(|c| alpha * cur[c] + (1.0 - alpha) * prev[c]);
                    }
                }
                for c in 0..3 {
                    let v = res[c];
                    let v = if self.cfg.clamp_negative { v.max(0.0) } else { v };
                    taa[c * np + i] = if v.is_finite() { v } else { 0.0 };
                }
            }
        }
    }
}
