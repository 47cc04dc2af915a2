//! FLNR — Fast Local Neural Regression (Salmi, Csefalvay & Imber, §3.3;
//! `../shared/ALGORITHMS.md` §2): a small U-Net ([`crate::nn::UNet`]) writes
//! `Q'` model guides `X'_model` (the moments are built from them) and `Q'` map
//! guides `X'_map` (the per-block models are applied to them); then FLR runs
//! as usual, with the σ, ε, ϵ trained with the network.
//!
//! One deliberate difference: FLR is fitted on `[normal, depth, AO, X'_model]`
//! and applied to `[normal, depth, AO, X'_map]` — the network *adds* guides
//! instead of replacing them. FLNR then starts out as FLR (near-constant
//! learned guides are regularised away) and even a short CPU training can only
//! improve on it; the paper's replacement needs far longer training to catch up
//! with the plain guides (measured: −1.1 dB after the same training).
//!
//! Network input (8 planes, as `train/flnr.py` builds it): the normal (3),
//! depth divided by the frame's mean depth (1), AO (1), and
//! `ln(1 + max(noisy, 0) / s)` (3) with `s` the frame's mean of
//! `max(noisy, 0)`; NaN/Inf become 0 (and FLR itself excludes NaN/Inf noisy
//! samples). The frame needs normal, depth and AO.

use crate::config::{Blur, FlrConfig, Regularization};
use crate::error::{Arg, Error};
use crate::flr::{Flr, Report};
use crate::guides::{Frame, GuideSet, MAX_USER_GUIDES};
use crate::image::{ImageView, ImageViewMut, Layout};
use crate::nn::UNet;

/// Guides the network reads.
pub const INPUT_GUIDES: GuideSet = GuideSet::NORMAL_DEPTH_AO;
const IN_CHANNELS: usize = 8;

/// FLNR for one frame size and one set of weights.
#[derive(Clone, Copy, Debug)]
pub struct Flnr<'w> {
    net: UNet<'w>,
    flr: Flr,
    width: usize,
    height: usize,
    q: usize,
}

impl<'w> Flnr<'w> {
    /// Parses `weights` (a blob from `train/flnr.py`) and plans FLR with the
    /// trained σ, ε, ϵ (block 8).
    pub fn new(weights: &'w [u8], width: usize, height: usize) -> Result<Self, Error> {
        let net = UNet::parse(weights)?;
        let q = net.out_channels() / 2;
        if net.in_channels() != IN_CHANNELS || net.out_channels() % 2 != 0 || !(1..=MAX_USER_GUIDES).contains(&q) {
            return Err(Error::InvalidConfig("weights: FLNR needs 8 input channels and 2·Q' outputs, Q' ≤ 4"));
        }
        let [sigma, eps_mul, eps_add] = net.flr_params();
        let cfg = FlrConfig {
            guides: GuideSet { user: q as u8, ..INPUT_GUIDES },
            block: 8,
            blur: Blur::Gaussian { sigma, radius: None },
            regularization: Regularization::Normalized { eps_mul: eps_mul as f64, eps_add: eps_add as f64 },
            ..FlrConfig::default()
        };
        let flr = Flr::new(cfg, width, height)?;
        Ok(Flnr { net, flr, width, height, q })
    }
    /// The parsed network.
    pub fn network(&self) -> &UNet<'w> {
        &self.net
    }
    /// The FLR plan (σ, ε, ϵ from the weights).
    pub fn flr(&self) -> &Flr {
        &self.flr
    }
    fn plane(&self) -> usize {
        self.width * self.height
    }
    /// f32 of scratch for [`Flnr::denoise`]: network input and output planes
    /// and the network's own scratch (see [`UNet::scratch_len`]).
    pub fn scratch_len(&self) -> usize {
        (IN_CHANNELS + 2 * self.q) * self.plane() + self.net.scratch_len(self.width, self.height)
    }
    /// f64 of scratch for the FLR stage ([`Flr::scratch_len`]).
    pub fn flr_scratch_len(&self) -> usize {
        self.flr.scratch_len()
    }

    /// Builds the network's input planes from a frame.
    fn input(&self, frame: &Frame<'_>, x: &mut [f32]) -> Result<(), Error> {
        let (w, h, np) = (self.width, self.height, self.plane());
        let views = frame.guides.channel_views(&INPUT_GUIDES, w, h, Arg::Guide)?;
        let n = &frame.noisy;
        if (n.width(), n.height()) != (w, h) {
            return Err(Error::SizeMismatch { arg: Arg::Noisy, expected: (w, h), got: (n.width(), n.height()) });
        }
        if n.channel_count() < 3 {
            return Err(Error::ChannelCount { arg: Arg::Noisy, expected: 3, got: n.channel_count() });
        }
        let bad = Error::InvalidTile { index: 0, count: h };
        for (c, v) in views.iter().take(5).enumerate() {
            let v = v.as_ref().ok_or(Error::GuideMismatch)?;
            for y in 0..h {
                v.read_row(y, 0, 0, &mut x[c * np + y * w..c * np + (y + 1) * w]).ok_or(bad)?;
            }
        }
        for y in 0..h {
            let (a, rest) = x[5 * np..8 * np].split_at_mut(np);
            let (b, c) = rest.split_at_mut(np);
            n.read_row_n(y, 0, [&mut a[y * w..(y + 1) * w], &mut b[y * w..(y + 1) * w], &mut c[y * w..(y + 1) * w]]).ok_or(bad)?;
        }
        let clean = |v: f32| if v.is_finite() { v } else { 0.0 };
        // depth / mean depth (finite, positive samples)
        let (mut dsum, mut dn) = (0f64, 0u64);
        for &d in &x[3 * np..4 * np] {
            if d.is_finite() && d > 0.0 {
                dsum += d as f64;
                dn += 1;
            }
        }
        let dm = if dn > 0 { (dsum / dn as f64) as f32 } else { 1.0 };
        for d in &mut x[3 * np..4 * np] {
            *d = clean(*d / dm);
        }
        for v in &mut x[..3 * np] {
            *v = clean(*v);
        }
        for v in &mut x[4 * np..5 * np] {
            *v = clean(*v);
        }
        let mut s = 0f64;
        for v in &x[5 * np..8 * np] {
            s += clean(*v).max(0.0) as f64;
        }
        let s = ((s / (3 * np) as f64) as f32).max(1e-6);
        for v in &mut x[5 * np..8 * np] {
            *v = libm::log1pf(clean(*v).max(0.0) / s);
        }
        Ok(())
    }

    /// Denoises one frame (normal, depth and AO guides). `scratch`: at least
    /// [`Flnr::scratch_len`] f32, `flr_scratch`: [`Flnr::flr_scratch_len`] f64.
    /// Allocates nothing.
    pub fn denoise(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f32],
        flr_scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        if scratch.len() < self.scratch_len() {
            return Err(Error::ScratchTooSmall { needed: self.scratch_len(), got: scratch.len() });
        }
        if frame.guides_low.is_some() {
            return Err(Error::Unsupported("FLNR has no joint upsampling (guides_low given)"));
        }
        let (w, h, np, q) = (self.width, self.height, self.plane(), self.q);
        let (x, rest) = scratch.split_at_mut(IN_CHANNELS * np);
        let (g, net_scratch) = rest.split_at_mut(2 * q * np);
        self.input(frame, x)?;
        self.net.forward(x, w, h, net_scratch, g)?;
        let g = &*g;
        let plane = |k: usize| ImageView::f32(&g[k * np..(k + 1) * np], w, h, 1, Layout::planar(w, h));
        let mut model = frame.guides;
        let mut map = frame.guides;
        for k in 0..q {
            model.user[k] = Some(plane(k)?);
            map.user[k] = Some(plane(q + k)?);
        }
        let f = Frame { noisy: frame.noisy, guides: map, guides_low: Some(model) };
        self.flr.denoise(&f, flr_scratch, out)
    }
}
