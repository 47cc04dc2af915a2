//! One shape for every method: a config plus a frame size give a plan
//! (`Flr::new`, `Bmfr::new`, `Walr::new`, `Flnr::new`); the plan says how
//! much scratch it needs, in f64; `denoise(frame, scratch, out)` returns the
//! shared [`Report`]. Temporal methods add a caller-owned [`History`].
//!
//! `denoise_parallel(frame, scratch, out, workers, for_each)` spreads the
//! work over the caller's threads ([`Executor`]), bit-identical to `denoise`.
//!
//! The methods' own entry points stay (BMFR and WALR take a frame index for
//! their per-frame grid offsets; FLNR's takes its two scratch types apart);
//! the traits are what generic callers (the C API, `lrd`, a renderer that
//! switches methods) program against.

use crate::error::Error;
use crate::guides::Frame;
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
use crate::image::ImageView;
use crate::image::ImageViewMut;
use crate::parallel::Executor;
use crate::report::Report;

/// A single-frame denoiser planned for one output size.
pub trait Denoiser {
    /// Output size (width, height).
    fn size(&self) -> (usize, usize);
    /// f64 values of scratch [`Denoiser::denoise`] needs.
    fn scratch_len(&self) -> usize;
    /// Denoises `frame` into `out` (the output size, at least 3 channels).
    /// Allocates nothing.
    fn denoise(&self, frame: &Frame<'_>, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error>;
    /// f64 values of scratch [`Denoiser::denoise_parallel`] needs for
    /// `workers` workers (`None` if it overflows).
    fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let _ = workers;
        Some(self.scratch_len())
    }
    /// [`Denoiser::denoise`] with the work spread by the caller's executor
    /// over `workers` workers (see [`Executor`]); bit-identical to it. `out`
    /// must have rows that do not overlap in memory. Every method here runs
    /// its tiles (FLR, BMFR, FLNR) or bands (WALR) on the executor; the
    /// default, for a method without a parallel run, runs
    /// [`Denoiser::denoise`] on the calling thread.
    fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let _ = (workers, for_each);
        self.denoise(frame, scratch, out)
    }
}

/// A denoiser with a temporal pipeline over a caller-owned history.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
pub trait TemporalDenoiser: Denoiser {
    /// f32 values of the [`History`] buffer.
    fn history_len(&self) -> usize;
    /// f64 values of scratch [`TemporalDenoiser::denoise_temporal`] needs.
    fn temporal_scratch_len(&self) -> usize;
    /// One frame of the pipeline; advances `history`. `motion` (2 channels:
    /// previous − current pixel position) may be `None` for a static camera.
    fn denoise_temporal(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error>;
    /// f64 values of scratch [`TemporalDenoiser::denoise_temporal_parallel`]
    /// needs for `workers` workers (`None` if it overflows).
    fn temporal_parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        let _ = workers;
        Some(self.temporal_scratch_len())
    }
    /// [`TemporalDenoiser::denoise_temporal`] with the work spread by the
    /// caller's executor over `workers` workers (see [`Executor`]);
    /// bit-identical to it. Every pipeline here (FLR's on light and on
    /// moments, BMFR's, WALR's) runs its tiles or bands on the executor; the
    /// default, for a pipeline without a parallel run, runs
    /// [`TemporalDenoiser::denoise_temporal`] on the calling thread.
    #[allow(clippy::too_many_arguments)]
    fn denoise_temporal_parallel(
        &self,
        frame: &Frame<'_>,
        motion: Option<&ImageView<'_>>,
        history: &mut History<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let _ = (workers, for_each);
        self.denoise_temporal(frame, motion, history, scratch, out)
    }
}

#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
use crate::history::History;

/// The first `len` f32 of an f64 scratch (`len.div_ceil(2)` f64).
#[cfg(any(feature = "bmfr", feature = "walr"))]
fn as_f32(scratch: &mut [f64], len: usize) -> Result<&mut [f32], Error> {
    let (needed, got) = (len.div_ceil(2), scratch.len());
    let s = scratch.get_mut(..needed).ok_or(Error::ScratchTooSmall { needed, got })?;
    Ok(&mut bytemuck::cast_slice_mut::<f64, f32>(s)[..len])
}

#[cfg(feature = "flr")]
impl Denoiser for crate::flr::Flr {
    fn size(&self) -> (usize, usize) {
        crate::flr::Flr::size(self)
    }
    fn scratch_len(&self) -> usize {
        crate::flr::Flr::scratch_len(self)
    }
    fn denoise(&self, frame: &Frame<'_>, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        crate::flr::Flr::denoise(self, frame, scratch, out)
    }
    fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        self.tiled_scratch_len(workers)
    }
    fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        crate::flr::Flr::denoise_parallel(self, frame, scratch, out, workers, for_each)
    }
}

/// The [`Denoiser`] of a temporal FLR (`$ty` with a `single: Flr` field):
/// a single frame is FLR's as configured.
#[cfg(feature = "flr")]
macro_rules! single_frame_is_flr {
    ($ty:ty) => {
        impl crate::Denoiser for $ty {
            fn size(&self) -> (usize, usize) {
                self.single.size()
            }
            fn scratch_len(&self) -> usize {
                self.single.scratch_len()
            }
            fn denoise(
                &self,
                frame: &crate::guides::Frame<'_>,
                scratch: &mut [f64],
                out: &mut crate::image::ImageViewMut<'_>,
            ) -> Result<crate::report::Report, crate::error::Error> {
                self.single.denoise(frame, scratch, out)
            }
            fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
                self.single.tiled_scratch_len(workers)
            }
            fn denoise_parallel(
                &self,
                frame: &crate::guides::Frame<'_>,
                scratch: &mut [f64],
                out: &mut crate::image::ImageViewMut<'_>,
                workers: usize,
                for_each: crate::parallel::Executor<'_>,
            ) -> Result<crate::report::Report, crate::error::Error> {
                self.single.denoise_parallel(frame, scratch, out, workers, for_each)
            }
        }
    };
}
#[cfg(feature = "flr")]
pub(crate) use single_frame_is_flr;

/// BMFR and WALR: the single frame is frame index 0 of their grid offsets;
/// after `;`, more items of the `Denoiser` impl (their parallel runs).
#[cfg(any(feature = "bmfr", feature = "walr"))]
macro_rules! temporal_method {
    ($ty:ty $(; $($parallel:tt)*)?) => {
        impl Denoiser for $ty {
            fn size(&self) -> (usize, usize) {
                <$ty>::size(self)
            }
            fn scratch_len(&self) -> usize {
                <$ty>::scratch_len(self).div_ceil(2)
            }
            fn denoise(&self, frame: &Frame<'_>, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
                <$ty>::denoise(self, frame, 0, as_f32(scratch, <$ty>::scratch_len(self))?, out)
            }
            $($($parallel)*)?
        }
        impl TemporalDenoiser for $ty {
            fn history_len(&self) -> usize {
                <$ty>::history_len(self)
            }
            fn temporal_scratch_len(&self) -> usize {
                <$ty>::temporal_scratch_len(self).div_ceil(2)
            }
            fn denoise_temporal(
                &self,
                frame: &Frame<'_>,
                motion: Option<&ImageView<'_>>,
                history: &mut History<'_>,
                scratch: &mut [f64],
                out: &mut ImageViewMut<'_>,
            ) -> Result<Report, Error> {
                let s = as_f32(scratch, <$ty>::temporal_scratch_len(self))?;
                <$ty>::denoise_temporal(self, frame, motion, history, s, out)
            }
            fn temporal_parallel_scratch_len(&self, workers: usize) -> Option<usize> {
                Some(<$ty>::temporal_parallel_scratch_len(self, workers)?.div_ceil(2))
            }
            fn denoise_temporal_parallel(
                &self,
                frame: &Frame<'_>,
                motion: Option<&ImageView<'_>>,
                history: &mut History<'_>,
                scratch: &mut [f64],
                out: &mut ImageViewMut<'_>,
                workers: usize,
                for_each: Executor<'_>,
            ) -> Result<Report, Error> {
                let overflow = Error::InvalidConfig("workers: scratch size overflows");
                let len = <$ty>::temporal_parallel_scratch_len(self, workers).ok_or(overflow)?;
                <$ty>::denoise_temporal_parallel(self, frame, motion, history, as_f32(scratch, len)?, out, workers, for_each)
            }
        }
    };
}

#[cfg(feature = "bmfr")]
temporal_method!(crate::bmfr::Bmfr;
    fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        Some(crate::bmfr::Bmfr::parallel_scratch_len(self, 0, workers)?.div_ceil(2))
    }
    fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let overflow = Error::InvalidConfig("workers: scratch size overflows");
        let len = crate::bmfr::Bmfr::parallel_scratch_len(self, 0, workers).ok_or(overflow)?;
        crate::bmfr::Bmfr::denoise_parallel(self, frame, 0, as_f32(scratch, len)?, out, workers, for_each)
    }
);
#[cfg(feature = "walr")]
temporal_method!(crate::walr::Walr;
    fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        Some(crate::walr::Walr::parallel_scratch_len(self, workers)?.div_ceil(2))
    }
    fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let overflow = Error::InvalidConfig("workers: scratch size overflows");
        let len = crate::walr::Walr::parallel_scratch_len(self, workers).ok_or(overflow)?;
        crate::walr::Walr::denoise_parallel(self, frame, 0, as_f32(scratch, len)?, out, workers, for_each)
    }
);

#[cfg(feature = "flnr")]
impl Denoiser for crate::flnr::Flnr<'_> {
    fn size(&self) -> (usize, usize) {
        self.flr().size()
    }
    /// FLR's f64 scratch, then the network's f32 scratch packed two per f64.
    fn scratch_len(&self) -> usize {
        self.flr_scratch_len() + crate::flnr::Flnr::scratch_len(self).div_ceil(2)
    }
    fn denoise(&self, frame: &Frame<'_>, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        let needed = Denoiser::scratch_len(self);
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let (flr, net) = scratch.split_at_mut(self.flr_scratch_len());
        let net_len = crate::flnr::Flnr::scratch_len(self);
        let net = &mut bytemuck::cast_slice_mut::<f64, f32>(net)[..net_len];
        crate::flnr::Flnr::denoise(self, frame, net, flr, out)
    }
    /// FLR's tiled f64 scratch (the fit's or the prior's, the larger), then the network's parallel f32 scratch packed two per f64.
    fn parallel_scratch_len(&self, workers: usize) -> Option<usize> {
        self.flr_tiled_scratch_len(workers)?.checked_add(crate::flnr::Flnr::parallel_scratch_len(self, workers)?.div_ceil(2))
    }
    fn denoise_parallel(
        &self,
        frame: &Frame<'_>,
        scratch: &mut [f64],
        out: &mut ImageViewMut<'_>,
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<Report, Error> {
        let overflow = Error::InvalidConfig("workers: scratch size overflows");
        let needed = Denoiser::parallel_scratch_len(self, workers).ok_or(overflow)?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let flr_len = self.flr_tiled_scratch_len(workers).ok_or(overflow)?;
        let net_len = crate::flnr::Flnr::parallel_scratch_len(self, workers).ok_or(overflow)?;
        let (flr, net) = scratch.split_at_mut(flr_len);
        let net = &mut bytemuck::cast_slice_mut::<f64, f32>(net)[..net_len];
        crate::flnr::Flnr::denoise_parallel(self, frame, net, flr, out, workers, for_each)
    }
}
