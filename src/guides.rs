//! Guide sets: which noise-free feature images a frame carries.
//!
//! A guide set is any subset of normal (3 channels), depth (1), world position (3),
//! ambient occlusion (1), plus up to [`MAX_USER_GUIDES`] single-channel user guides.
//! Kernels are monomorphised on the total channel count `Q`, so a frame without
//! AO pays nothing for AO.

use crate::error::{Arg, Error};
use crate::image::ImageView;

/// Most single-channel user guides a frame may carry.
pub const MAX_USER_GUIDES: usize = 4;
/// Most guide channels in total (3 + 1 + 3 + 1 + 4).
pub const MAX_GUIDES: usize = 12;

/// Which guides are used. The channel order inside the kernels is always
/// normal, depth, position, ao, user.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct GuideSet {
    /// Shading normal, 3 channels.
    pub normal: bool,
    /// Depth, 1 channel.
    pub depth: bool,
    /// World-space position, 3 channels.
    pub position: bool,
    /// Ambient occlusion, 1 channel.
    pub ao: bool,
    /// Number of single-channel user guides (0..=4).
    pub user: u8,
}

impl GuideSet {
    /// No guides: FLR degenerates to a (normalised) Gaussian blur.
    pub const NONE: GuideSet = GuideSet { normal: false, depth: false, position: false, ao: false, user: 0 };
    /// Normal + depth + AO, the paper's FLR configuration.
    pub const NORMAL_DEPTH_AO: GuideSet = GuideSet { normal: true, depth: true, position: false, ao: true, user: 0 };
    /// Normal + depth.
    pub const NORMAL_DEPTH: GuideSet = GuideSet { normal: true, depth: true, position: false, ao: false, user: 0 };

    /// Total number of guide channels `Q`.
    pub const fn channels(&self) -> usize {
        3 * self.normal as usize + self.depth as usize + 3 * self.position as usize + self.ao as usize + self.user as usize
    }

    /// This set with the normal, position and depth of `other` added (the
    /// guides a temporal frame carries: FLR's and those the stage judges
    /// history by).
    pub const fn with_geometry_of(self, other: GuideSet) -> GuideSet {
        GuideSet { normal: self.normal | other.normal, position: self.position | other.position, depth: self.depth | other.depth, ..self }
    }

    /// The AO channel's index among the `Q` guide channels (they come in the
    /// order normal, depth, position, AO, user), if AO is in the set.
    pub const fn ao_channel(&self) -> Option<usize> {
        if self.ao {
            Some(3 * self.normal as usize + self.depth as usize + 3 * self.position as usize)
        } else {
            None
        }
    }

    pub(crate) fn validate(&self) -> Result<(), Error> {
        if self.user as usize > MAX_USER_GUIDES {
            return Err(Error::InvalidConfig("guides.user (at most 4 user guides)"));
        }
        Ok(())
    }
}

/// The guide images of one frame, all of the same size.
#[derive(Clone, Copy, Debug, Default)]
pub struct Guides<'a> {
    /// World-space shading normal, 3 channels.
    pub normal: Option<ImageView<'a>>,
    /// Camera distance, 1 channel.
    pub depth: Option<ImageView<'a>>,
    /// World-space position, 3 channels.
    pub position: Option<ImageView<'a>>,
    /// Ambient occlusion, 1 channel.
    pub ao: Option<ImageView<'a>>,
    /// Single-channel user guides, used in order; stop at the first `None`.
    pub user: [Option<ImageView<'a>>; MAX_USER_GUIDES],
}

impl<'a> Guides<'a> {
    /// The guide set these images make up.
    pub fn set(&self) -> GuideSet {
        GuideSet {
            normal: self.normal.is_some(),
            depth: self.depth.is_some(),
            position: self.position.is_some(),
            ao: self.ao.is_some(),
            user: self.user.iter().take_while(|u| u.is_some()).count() as u8,
        }
    }

    /// Checks the images against `set` and the size, and returns one
    /// single-channel view per guide channel, in kernel order.
    pub fn channel_views(
        &self,
        set: &GuideSet,
        width: usize,
        height: usize,
        arg: Arg,
    ) -> Result<[Option<ImageView<'a>>; MAX_GUIDES], Error> {
        if self.set() != *set || self.user.iter().skip(set.user as usize).any(|u| u.is_some()) {
            return Err(Error::GuideMismatch);
        }
        let mut out = [None; MAX_GUIDES];
        let mut q = 0;
        let layers: [(Option<ImageView<'a>>, usize); 4] = [(self.normal, 3), (self.depth, 1), (self.position, 3), (self.ao, 1)];
        let users = self.user.iter().take(set.user as usize).map(|u| (*u, 1));
        for (view, ch) in layers.into_iter().chain(users) {
            let Some(v) = view else { continue };
            if v.width() != width || v.height() != height {
                return Err(Error::SizeMismatch { arg, expected: (width, height), got: (v.width(), v.height()) });
            }
            if v.channel_count() < ch {
                return Err(Error::ChannelCount { arg, expected: ch, got: v.channel_count() });
            }
            for c in 0..ch {
                out[q] = Some(v.channels(c, 1)?);
                q += 1;
            }
        }
        Ok(out)
    }
}

/// One frame to denoise: the noisy demodulated indirect light and its guides.
#[derive(Clone, Copy, Debug)]
pub struct Frame<'a> {
    /// Noisy RGB (3 channels; extra channels such as alpha are ignored).
    pub noisy: ImageView<'a>,
    /// Guides at the output resolution.
    pub guides: Guides<'a>,
    /// The guides the regression is *fitted* on, at the noisy input's
    /// resolution (FLR only): for joint denoise + upsample, the low-resolution
    /// guides; at the same resolution, a second guide set (FLNR's `X'_model`,
    /// with `guides` = `X'_map`). `None`: fit and apply on `guides`.
    pub guides_low: Option<Guides<'a>>,
    /// Per-pixel sample weights of the fit, at the noisy input's resolution
    /// (single-frame FLR on the CPU only; channel 0 is read): each pixel
    /// counts `w` times in its windows, so the regression leans on pixels of
    /// large `w`: a pixel's sample count under adaptive sampling, or 0 for a
    /// pixel that has no sample this frame (checkerboard or sparse
    /// rendering), which is then predicted from its neighbours through its
    /// guides. A weight that is not finite and positive excludes the pixel
    /// from the fit. Only ratios matter: the weights are scaled to a frame
    /// mean of 1, and uniform weights fit as `None` does, up to rounding. The
    /// adaptive window counts a window's weight as its share of pixels, so
    /// windows of weights below the frame's mean lean towards the larger
    /// windows. The firefly clamp ([`crate::FlrConfig::fireflies`]) still
    /// measures every finite pixel whatever its weight: turn it off, or fill
    /// pixels without a sample with a value of their neighbourhood's scale.
    /// FLNR, BMFR, WALR, the temporal pipelines and the GPU path refuse it.
    /// `None`: every finite pixel has weight 1.
    pub sample_weights: Option<ImageView<'a>>,
}

impl<'a> Frame<'a> {
    /// A frame at one resolution (no upsampling).
    pub fn new(noisy: ImageView<'a>, guides: Guides<'a>) -> Self {
        Frame { noisy, guides, guides_low: None, sample_weights: None }
    }
}
