//! # lrdenoise
//!
//! Real-time regression denoisers for path-traced diffuse global illumination:
//! `no_std`, allocation-free, tile-based SIMD kernels.
//!
//! The core method is **FLR** (Fast Local Regression, Salmi, Csefalvay & Imber):
//! per-pixel weighted least squares of the noisy demodulated indirect light
//! against noise-free guides (normals, depth, positions, AO), computed from
//! moments summed over B×B blocks, blurred, solved per block with the
//! normalized-correlation regularized inverse, and bilinearly applied.
//!
//! ```
//! use lrdenoise::{Flr, FlrConfig, Frame, Guides, GuideSet, ImageView, ImageViewMut};
//! let (w, h) = (64, 48);
//! let noisy = vec![0.5f32; w * h * 3];
//! let normal = vec![0.0f32; w * h * 3];
//! let depth = vec![1.0f32; w * h];
//! let cfg = FlrConfig::with_guides(GuideSet::NORMAL_DEPTH);
//! let flr = Flr::new(cfg, w, h)?;
//! let mut scratch = vec![0f64; flr.scratch_len()];   // once; reuse every frame
//! let mut out = vec![0f32; w * h * 3];
//! let guides = Guides {
//!     normal: Some(ImageView::interleaved(&normal, w, h, 3)?),
//!     depth: Some(ImageView::interleaved(&depth, w, h, 1)?),
//!     ..Default::default()
//! };
//! let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3)?, guides);
//! let report = flr.denoise(&frame, &mut scratch, &mut ImageViewMut::interleaved(&mut out, w, h, 3)?)?;
//! assert_eq!(report.nonfinite_noisy, 0);
//! assert!((out[0] - 0.5).abs() < 1e-4);
//! # Ok::<(), lrdenoise::Error>(())
//! ```
#![no_std]
#![forbid(unsafe_op_in_unsafe_fn)]
#![warn(missing_debug_implementations)]
#![warn(missing_docs)]

#[cfg(feature = "bmfr")]
pub mod bmfr;
mod convert;
mod denoiser;
pub mod error;
pub mod fireflies;
#[cfg(feature = "flnr")]
pub mod flnr;
#[cfg(feature = "flr")]
pub mod flr;
pub mod guides;
#[cfg(any(feature = "bmfr", feature = "walr"))]
mod hash;
#[cfg(any(feature = "bmfr", feature = "walr", feature = "flr"))]
mod history;
pub mod image;
pub mod isa;
pub mod kernels;
#[cfg(feature = "flnr")]
pub mod nn;
pub mod parallel;
pub mod report;
#[cfg(any(feature = "bmfr", feature = "walr", feature = "flr"))]
mod reproject;
#[cfg(any(feature = "bmfr", feature = "walr", feature = "flr"))]
pub mod temporal;
#[cfg(feature = "walr")]
pub mod walr;

#[cfg(feature = "bmfr")]
pub use bmfr::{Bmfr, BmfrConfig};
pub use denoiser::Denoiser;
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
pub use denoiser::TemporalDenoiser;
pub use error::{Arg, Error};
#[cfg(feature = "flnr")]
pub use flnr::{Flnr, FlnrConfig};
#[cfg(feature = "flr")]
pub use flr::config::{Blur, FlrConfig};
#[cfg(feature = "flr")]
pub use flr::{CheckedFrame, Flr, Stage, Tiled};
#[cfg(all(feature = "flr", feature = "internals"))]
#[doc(hidden)]
pub use flr::{Parts, ScratchLayout, Stats};
pub use guides::{Frame, GuideSet, Guides, MAX_GUIDES, MAX_USER_GUIDES};
#[cfg(any(feature = "bmfr", feature = "walr", feature = "flr"))]
pub use history::History;
pub use image::{ImageView, ImageViewMut, Layout, Samples, SamplesMut};
pub use isa::Kernel;
pub use kernels::solve::Regularization;
pub use parallel::Executor;
pub use report::Report;
#[cfg(feature = "walr")]
pub use walr::{Walr, WalrConfig};

/// The SIMD instruction set `wide` was compiled for (chosen at compile time by
/// `-C target-feature`/`target-cpu`).
pub const SIMD_LEVEL: &str = if cfg!(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma")) {
    "avx2+fma"
} else if cfg!(all(target_arch = "x86_64", target_feature = "avx")) {
    "avx"
} else if cfg!(all(target_arch = "x86_64", target_feature = "sse4.1")) {
    "sse4.1"
} else if cfg!(target_arch = "x86_64") {
    "sse2"
} else if cfg!(all(target_arch = "aarch64", target_feature = "neon")) {
    "neon"
} else {
    "scalar"
};

/// The instruction set FLR's, BMFR's and FLNR's 8-lane kernels run on this
/// CPU: `"avx2+fma"` when [`isa::Isa::detect`] picks the AVX2 + FMA kernels
/// (also in a plain x86-64 build, whose `wide` lanes are SSE2), else
/// [`SIMD_LEVEL`].
pub fn simd_level() -> &'static str {
    if isa::Isa::detect() == isa::Isa::Avx2Fma {
        "avx2+fma"
    } else {
        SIMD_LEVEL
    }
}

/// Crate version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
