//! FLR configuration: guides, block size, window, regulariser, upsampling.
//!
//! All distances are in full-resolution pixels. Defaults are the tuned ones
//! (see docs/METHODS.md, FLR).

use crate::error::Error;
use crate::fireflies;
use crate::guides::GuideSet;
use crate::isa::Kernel;
use crate::kernels::blur::{radius_to_cells, GAUSSIAN_TRUNCATION, MAX_RADIUS_CELLS};
use crate::kernels::solve::Regularization;

/// The window over which each local regression is fitted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Blur {
    /// Gaussian of standard deviation `sigma`, truncated at `radius`
    /// (`None`: 3σ). Applied to the block grid with σ/B and ⌈radius/B⌉ cells.
    Gaussian {
        /// Standard deviation in output pixels.
        sigma: f32,
        /// Truncation radius in output pixels (`None`: 3σ).
        radius: Option<f32>,
    },
    /// Box of half-width `radius` (the guided filter's window), O(1) per cell.
    Box {
        /// Half-width in output pixels.
        radius: f32,
    },
    /// Three Gaussian windows `sigmas[0] < sigmas[1] < sigmas[2]` (each
    /// truncated at 3σ), fitted side by side and blended per cell with weights
    /// 1 / (estimated squared error): small windows where the light changes
    /// faster than the guides explain, large ones where it does not
    /// (`flr::adaptive`). The default, with [`DEFAULT_SIGMAS`].
    Adaptive {
        /// The three standard deviations in output pixels, increasing.
        sigmas: [f32; 3],
    },
}

impl Blur {
    /// The window sizes this blur fits: one, or three for [`Blur::Adaptive`].
    pub fn scale_count(&self) -> usize {
        match self {
            Blur::Adaptive { .. } => 3,
            _ => 1,
        }
    }
}

/// Everything that defines an FLR run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlrConfig {
    /// Guides the frames will carry.
    pub guides: GuideSet,
    /// Block size B ∈ {1, 2, 4, 8, 16}: one affine model per B×B pixels.
    pub block: usize,
    /// The regression window (default: the adaptive window, σ 6/12/20 px;
    /// `Blur::Gaussian { sigma: 12.0, radius: None }` is the faster single window).
    pub blur: Blur,
    /// The regulariser.
    pub regularization: Regularization,
    /// Joint denoise + upsample: the noisy input is at 1/`upsample`
    /// resolution (1, 2 or 4; `block` must be ≥ `upsample`).
    pub upsample: usize,
    /// Clamp negative output to 0 (light is never negative).
    pub clamp_negative: bool,
    /// Kernel implementation.
    pub kernel: Kernel,
    /// Adaptive window only, with AO among the guides: also fit the smallest
    /// window without the AO channel (from its own Cholesky factor: one more
    /// substitution per cell, no blur) and blend that fit as a fourth candidate, with
    /// the variance of its one coefficient fewer and its bias measured like a
    /// larger window's (`flr::adaptive`). AO helps some scenes and costs
    /// others up to half a dB; this lets each cell choose. Off by default:
    /// on the training scenes +0.1–0.2 dB, on the held-out scenes +0.05 dB
    /// (scene-dependent: −0.12 to +0.23; +0.07 dB on top of the AO
    /// demodulation) for ~7 % more time (docs/RESULTS.md). CPU and
    /// GPU paths.
    pub adaptive_without_ao: bool,
    /// AO demodulation, with AO among the guides: the noisy light is divided
    /// per pixel by `s = √(clamp(ao, 0, 1) + c)` (`c` this offset) before the
    /// fit and the output multiplied by the same `s` where the model is
    /// applied, so the model is `y ≈ s · (c₀ + β·g)` and its least squares
    /// weigh each pixel by `1 / s²` (occluded pixels, which the tone-mapped
    /// error weighs most, count more). A non-finite AO value counts as 1 (open).
    /// Ignored when AO is not a guide, so the default suits every guide set,
    /// and in the Tikhonov mode (the paper's textbook fit, everything as
    /// given); [`FlrConfig::demodulation`] says when it applies.
    /// Default `Some(DEFAULT_AO_OFFSET)`; `None` is plain FLR (the paper's).
    /// Chosen on the training scenes (+0.16 dB on 6 frames and on 20 more;
    /// on the held-out scenes, measured once afterwards, +0.14 dB, level with
    /// OIDN; ~6 % more time; docs/RESULTS.md). The output is then
    /// not invariant to an affine change of the AO channel (DATA.md fixes AO
    /// to [0, 1]); every other guide stays invariant. CPU and GPU paths.
    pub ao_demodulation: Option<f32>,
    /// The firefly clamp's threshold factor `k` ([`crate::fireflies`]): a
    /// noisy sample whose luminance is above `k` times the larger of the third brightest
    /// 8 × 8 cell of its 104 × 8 pixel neighbourhood and that neighbourhood's
    /// mean without its brightest cell is scaled down to that
    /// level before the moments are taken. `None` turns it off. Default
    /// `Some(fireflies::DEFAULT_STRENGTH)`; `k ≥ 1`. CPU and GPU paths.
    pub fireflies: Option<f32>,
}

// Defaults tuned on the training scenes (tools/render.py --split train, 256×256,
// 1 spp): the optimum is flat (±0.1 dB over σ 10–14, ε 1e-4–1e-2). ε and ϵ are
// larger than the paper's learned 1e-5–1e-4 because guides are standardised per
// frame here (unit variance), not used in their raw units.

/// Gaussian σ in full-resolution pixels of the single window (`Blur::Gaussian`
/// when only a radius is given; the fastest configuration).
pub const DEFAULT_SIGMA: f32 = 12.0;
/// The default window: the adaptive window's three σ in full-resolution
/// pixels. Chosen on the training scenes (+0.29 dB over σ = 12 alone there,
/// +0.42 dB on the held-out test scenes) for ~40 % more time than one
/// window; `Blur::Gaussian { sigma: DEFAULT_SIGMA, .. }` is the fast choice.
pub const DEFAULT_SIGMAS: [f32; 3] = [6.0, 12.0, 20.0];
/// The adaptive window's σ for temporal FLR ([`FlrConfig::temporal`]): light
/// accumulated over frames is less noisy than one frame's, so smaller windows
/// fit it better (chosen on the training sequences: +0.28 dB over
/// [`DEFAULT_SIGMAS`] there, last 4 frames, and higher on each of the 5).
pub const TEMPORAL_SIGMAS: [f32; 3] = [3.0, 6.0, 12.0];
/// Window of temporal FLR on accumulated moments ([`FlrConfig::temporal_moments`]):
/// σ 6 pixels, chosen on the training sequences.
pub const TEMPORAL_MOMENTS_SIGMA: f32 = 6.0;
/// Additive ϵ of temporal FLR on accumulated moments
/// ([`FlrConfig::temporal_moments`]; chosen on the training sequences).
pub const TEMPORAL_MOMENTS_EPS_ADD: f64 = 1e-3;
/// Default ε (multiplicative regulariser).
pub const DEFAULT_EPS_MUL: f64 = 1e-3;
/// Default ϵ (additive regulariser).
pub const DEFAULT_EPS_ADD: f64 = 1e-2;
/// Default offset `c` of the AO demodulation `s = √(ao + c)`
/// ([`FlrConfig::ao_demodulation`]), chosen on the training scenes.
pub const DEFAULT_AO_OFFSET: f32 = 0.1;

impl Default for FlrConfig {
    fn default() -> Self {
        FlrConfig {
            guides: GuideSet::NORMAL_DEPTH_AO,
            block: 8,
            blur: Blur::Adaptive { sigmas: DEFAULT_SIGMAS },
            regularization: Regularization::Normalized { eps_mul: DEFAULT_EPS_MUL, eps_add: DEFAULT_EPS_ADD },
            upsample: 1,
            clamp_negative: true,
            kernel: Kernel::Simd,
            adaptive_without_ao: false,
            ao_demodulation: Some(DEFAULT_AO_OFFSET),
            fireflies: Some(fireflies::DEFAULT_STRENGTH),
        }
    }
}

impl FlrConfig {
    /// The default configuration with another guide set.
    pub fn with_guides(guides: GuideSet) -> Self {
        FlrConfig { guides, ..Self::default() }
    }

    /// The defaults for temporal FLR ([`crate::flr::temporal::TemporalFlr`]):
    /// the adaptive window at [`TEMPORAL_SIGMAS`], the rest as
    /// [`FlrConfig::default`].
    pub fn temporal() -> Self {
        FlrConfig { blur: Blur::Adaptive { sigmas: TEMPORAL_SIGMAS }, ..Self::default() }
    }

    /// The defaults for temporal FLR on accumulated moments
    /// ([`crate::flr::moment_history::MomentFlr`]): one Gaussian window of
    /// σ = [`TEMPORAL_MOMENTS_SIGMA`] pixels and the additive ϵ at [`TEMPORAL_MOMENTS_EPS_ADD`], the rest as
    /// [`FlrConfig::default`]. The accumulated cells are less noisy than a
    /// frame's: one window scores as the adaptive one there, and a smaller ϵ
    /// fits them better (`docs/METHODS.md`).
    pub fn temporal_moments() -> Self {
        FlrConfig {
            blur: Blur::Gaussian { sigma: TEMPORAL_MOMENTS_SIGMA, radius: None },
            regularization: Regularization::Normalized { eps_mul: DEFAULT_EPS_MUL, eps_add: TEMPORAL_MOMENTS_EPS_ADD },
            ..Self::default()
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), Error> {
        self.guides.validate()?;
        if !matches!(self.block, 1 | 2 | 4 | 8 | 16) {
            return Err(Error::InvalidConfig("block (must be 1, 2, 4, 8 or 16)"));
        }
        if !matches!(self.upsample, 1 | 2 | 4) {
            return Err(Error::InvalidConfig("upsample (must be 1, 2 or 4)"));
        }
        if self.block < self.upsample {
            return Err(Error::InvalidConfig("block must be at least upsample"));
        }
        let ok = |v: f32| v.is_finite() && v > 0.0;
        match self.blur {
            Blur::Gaussian { sigma, radius } => {
                if !ok(sigma) || sigma > 4096.0 {
                    return Err(Error::InvalidConfig("sigma (must be finite and > 0)"));
                }
                if let Some(r) = radius {
                    if !(r.is_finite() && r >= 0.0) {
                        return Err(Error::InvalidConfig("radius (must be finite and >= 0)"));
                    }
                }
            }
            Blur::Box { radius } => {
                if !(radius.is_finite() && radius >= 0.0) {
                    return Err(Error::InvalidConfig("radius (must be finite and >= 0)"));
                }
            }
            Blur::Adaptive { sigmas } => {
                if !(sigmas.iter().all(|&s| ok(s) && s <= 4096.0) && sigmas[0] < sigmas[1] && sigmas[1] < sigmas[2]) {
                    return Err(Error::InvalidConfig("adaptive sigmas (must be finite, > 0 and increasing)"));
                }
            }
        }
        if self.adaptive_without_ao && !(matches!(self.blur, Blur::Adaptive { .. }) && self.guides.ao) {
            return Err(Error::InvalidConfig("adaptive_without_ao needs the adaptive window and AO among the guides"));
        }
        if let Some(c) = self.ao_demodulation {
            if !(c.is_finite() && c > 0.0) {
                return Err(Error::InvalidConfig("ao_demodulation offset (must be finite and > 0)"));
            }
        }
        if let Some(k) = self.fireflies {
            if !fireflies::valid_strength(k) {
                return Err(Error::InvalidConfig("fireflies strength (must be finite and >= 1)"));
            }
        }
        let reg_ok = |v: f64| (0.0..1.0).contains(&v);
        match self.regularization {
            Regularization::Normalized { eps_mul, eps_add } => {
                if !reg_ok(eps_mul) || !reg_ok(eps_add) || eps_add == 0.0 && eps_mul == 0.0 {
                    return Err(Error::InvalidConfig("regularization (eps in [0, 1), not both 0)"));
                }
            }
            Regularization::Tikhonov { eps } => {
                if !(eps.is_finite() && eps > 0.0) {
                    return Err(Error::InvalidConfig("regularization (tikhonov eps must be > 0)"));
                }
            }
        }
        if self.radius_cells() > MAX_RADIUS_CELLS {
            return Err(Error::InvalidConfig("radius too large for the block size (at most 64 blocks)"));
        }
        Ok(())
    }

    /// The AO channel and offset of [`FlrConfig::ao_demodulation`] where it
    /// applies: AO among the guides and the normalized regularization (the
    /// Tikhonov mode is the paper's textbook fit, guides and light as given).
    pub fn demodulation(&self) -> Option<(usize, f32)> {
        match self.regularization {
            Regularization::Normalized { .. } => Some((self.guides.ao_channel()?, self.ao_demodulation?)),
            Regularization::Tikhonov { .. } => None,
        }
    }

    /// Window half-width on the cell grid: ⌈radius / B⌉ (the largest window's).
    pub fn radius_cells(&self) -> usize {
        let r = match self.blur {
            Blur::Gaussian { sigma, radius } => radius.unwrap_or(GAUSSIAN_TRUNCATION * sigma),
            Blur::Box { radius } => radius,
            Blur::Adaptive { sigmas } => GAUSSIAN_TRUNCATION * sigmas[2],
        };
        radius_to_cells(r, self.block)
    }
}
