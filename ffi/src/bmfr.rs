//! BMFR: its configuration and entry points (single frame and the temporal
//! pipeline, both through [`crate::temporal`]).

use crate::executor::LrdExecutor;
use crate::images::{guide_set, LrdFrame, LrdImage, LrdImageMut, LRD_GUIDE_NORMAL, LRD_GUIDE_POSITION};
use crate::status::{guard, status_of, LrdReport, LrdStatus, LrdStatus::*};
use crate::temporal::{
    denoise_single, denoise_temporal, scratch_size, temporal_config, temporal_parallel_sizes, temporal_sizes, LrdHistory, LrdTemporalConfig,
};
use core::ffi::c_void;
use lrdenoise_core::Kernel;

/// BMFR configuration (Koskela et al. 2019: blockwise multi-order feature
/// regression, Householder QR per block, and its temporal pipeline). Start
/// from `lrd_bmfr_config_default()`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdBmfrConfig {
    /// Bit set of LRD_GUIDE_* the frames carry (default normal + position).
    /// Features: 1, every guide channel, the squares of the position channels
    /// (of depth without positions).
    pub guides: u32,
    /// User guide channels (0..=4).
    pub user_guides: u32,
    /// Block edge B, 8..=64 (default 32).
    pub block: u32,
    /// Add the squared features (default true).
    pub quadratic: bool,
    /// Stochastic regularisation: uniform noise in [-noise, noise] on every
    /// non-constant feature, for the fit only (default 0.01; 0 = off).
    pub noise: f32,
    /// Drop a feature whose QR pivot is below pivot_tol x the largest (1e-4).
    pub pivot_tol: f32,
    /// Wiener shrinkage of each block's fit in its QR basis: component q of
    /// Q^T z is scaled by q^2 / (q^2 + shrinkage x residual variance)
    /// (0..=100; default 4; 0 = the paper's plain least squares).
    pub shrinkage: f32,
    /// Shift the block grid every frame (default true).
    pub shift: bool,
    /// Clamp negative output to 0 (default true).
    pub clamp_negative: bool,
    /// Use the scalar reference kernels (slow; for testing).
    pub scalar_kernels: bool,
    /// The temporal pipeline's stage, shared with temporal FLR and WALR
    /// (BMFR's defaults: `output_alpha` 0.1 and `clip_gamma` 4, the rest as
    /// `lrd_temporal_config_default`).
    pub temporal: LrdTemporalConfig,
    /// The firefly clamp's threshold factor k (>= 1): a noisy sample whose
    /// luminance exceeds k times the larger of the third brightest 8x8
    /// cell of its 104x8-pixel neighbourhood and that neighbourhood's mean
    /// without its brightest cell is scaled down to that level for the fit,
    /// and for the temporal pipeline's accumulation (see the core's
    /// `fireflies` module); 0 turns it off. Default 1.5.
    pub fireflies: f32,
}

fn bmfr_config(c: &LrdBmfrConfig) -> Result<lrdenoise_core::BmfrConfig, LrdStatus> {
    let cfg = lrdenoise_core::BmfrConfig {
        guides: guide_set(c.guides, c.user_guides)?,
        block: c.block as usize,
        quadratic: c.quadratic,
        noise: c.noise,
        pivot_tol: c.pivot_tol,
        shrinkage: c.shrinkage,
        shift: c.shift,
        clamp_negative: c.clamp_negative,
        kernel: if c.scalar_kernels { Kernel::Scalar } else { Kernel::Simd },
        temporal: temporal_config(&c.temporal)?,
        fireflies: (c.fireflies != 0.0).then_some(c.fireflies),
    };
    cfg.validate().map_err(status_of)?;
    Ok(cfg)
}

fn bmfr_plan(c: *const LrdBmfrConfig, width: u32, height: u32) -> Result<lrdenoise_core::Bmfr, LrdStatus> {
    // SAFETY: checked for NULL; the caller passes a valid config pointer.
    let c = unsafe { c.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
    lrdenoise_core::Bmfr::new(bmfr_config(c)?, width as usize, height as usize).map_err(status_of)
}

/// The default BMFR configuration: the paper's normal + position guides
/// (M = 10 features), 32x32 blocks, noise 0.01 and pipeline blend weights,
/// plus this library's shrinkage 4 (set `shrinkage = 0` for the paper's
/// plain least squares).
#[no_mangle]
pub extern "C" fn lrd_bmfr_config_default() -> LrdBmfrConfig {
    let d = lrdenoise_core::BmfrConfig::default();
    let t = d.temporal;
    LrdBmfrConfig {
        guides: LRD_GUIDE_NORMAL | LRD_GUIDE_POSITION,
        user_guides: 0,
        block: d.block as u32,
        quadratic: d.quadratic,
        noise: d.noise,
        pivot_tol: d.pivot_tol,
        shrinkage: d.shrinkage,
        shift: d.shift,
        clamp_negative: d.clamp_negative,
        scalar_kernels: false,
        temporal: crate::temporal::lrd_temporal_config(&t),
        fireflies: d.fireflies.unwrap_or(0.0),
    }
}

/// Scratch bytes `lrd_bmfr_denoise` (single frame) needs for `width`x`height` frames.
#[no_mangle]
pub unsafe extern "C" fn lrd_bmfr_scratch_size(config: *const LrdBmfrConfig, width: u32, height: u32, bytes: *mut usize) -> LrdStatus {
    guard(|| scratch_size(bmfr_plan(config, width, height)?, bytes))
}

/// Scratch and history bytes of the temporal pipeline (`lrd_bmfr_denoise_temporal`).
#[no_mangle]
pub unsafe extern "C" fn lrd_bmfr_temporal_sizes(
    config: *const LrdBmfrConfig,
    width: u32,
    height: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_sizes(bmfr_plan(config, width, height)?, scratch_bytes, history_bytes))
}

/// Single-frame BMFR on the calling thread. `index` picks the block-grid
/// offset and the regularisation noise (use the frame number). `out` (3
/// channels) has the frame's size; `frame.guides_low` must be absent.
/// `scratch`: 8-byte aligned, at least `lrd_bmfr_scratch_size` bytes.
/// `report` may be NULL; otherwise the run's counts are added to it.
#[no_mangle]
pub unsafe extern "C" fn lrd_bmfr_denoise(
    config: *const LrdBmfrConfig,
    frame: *const LrdFrame,
    index: u32,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    report: *mut LrdReport,
) -> LrdStatus {
    // SAFETY: forwarded contract (see `denoise_single`).
    guard(|| unsafe { denoise_single(|w, h| bmfr_plan(config, w, h), frame, index, out, scratch, scratch_bytes, report) })
}

/// One frame of BMFR's temporal pipeline (reprojection and rejection, noisy
/// accumulation, the fit, filtered accumulation, TAA) on the calling thread.
/// `motion` (2 channels: previous minus current pixel position) may be NULL,
/// or have `data == NULL`, for a static camera. `history` is read and
/// advanced; `scratch` (8-byte aligned) and `history->data` must be at least
/// the sizes from `lrd_bmfr_temporal_sizes`. `report` may be NULL.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_bmfr_denoise_temporal(
    config: *const LrdBmfrConfig,
    frame: *const LrdFrame,
    motion: *const LrdImage,
    history: *mut LrdHistory,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    report: *mut LrdReport,
) -> LrdStatus {
    // SAFETY: forwarded contract (see `denoise_temporal`).
    guard(|| unsafe {
        denoise_temporal(|w, h| bmfr_plan(config, w, h), frame, motion, history, out, scratch, scratch_bytes, core::ptr::null(), report)
    })
}

/// Scratch bytes of `lrd_bmfr_denoise_temporal_parallel` with `workers`
/// workers, and history bytes (those of `lrd_bmfr_temporal_sizes`: one
/// history serves both calls).
#[no_mangle]
pub unsafe extern "C" fn lrd_bmfr_temporal_parallel_sizes(
    config: *const LrdBmfrConfig,
    width: u32,
    height: u32,
    workers: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_parallel_sizes(bmfr_plan(config, width, height)?, workers, scratch_bytes, history_bytes))
}

/// lrd_bmfr_denoise_temporal with the work run on the caller's threads
/// (`executor`, see LrdExecutor); bit-identical to it. The scratch size is
/// from `lrd_bmfr_temporal_parallel_sizes` with `executor->workers`; `out`
/// needs rows that do not overlap in memory.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_bmfr_denoise_temporal_parallel(
    config: *const LrdBmfrConfig,
    frame: *const LrdFrame,
    motion: *const LrdImage,
    history: *mut LrdHistory,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    executor: *const LrdExecutor,
    report: *mut LrdReport,
) -> LrdStatus {
    if executor.is_null() {
        return LRD_STATUS_NULL_POINTER;
    }
    // SAFETY: forwarded contract (see `denoise_temporal`).
    guard(|| unsafe {
        denoise_temporal(|w, h| bmfr_plan(config, w, h), frame, motion, history, out, scratch, scratch_bytes, executor, report)
    })
}
