//! WALR: its configuration and entry points (single frame and the temporal
//! pipeline, both through [`crate::temporal`]).

use crate::executor::LrdExecutor;
use crate::images::{guide_set, LrdFrame, LrdImage, LrdImageMut, LRD_GUIDE_DEPTH, LRD_GUIDE_NORMAL, LRD_GUIDE_POSITION};
use crate::status::{guard, status_of, LrdReport, LrdStatus, LrdStatus::*};
use crate::temporal::{
    denoise_single, denoise_temporal, scratch_size, temporal_config, temporal_parallel_sizes, temporal_sizes, LrdHistory, LrdTemporalConfig,
};
use core::ffi::c_void;
use lrdenoise_core::Kernel;

/// WALR configuration (Meunier & Harada: edge-traced à-trous weighted
/// averages, per-pixel Cholesky regression, and its pipeline). Start from
/// `lrd_walr_config_default()`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdWalrConfig {
    /// Bit set of LRD_GUIDE_*: normal and position are required; depth makes the
    /// edge-stopping distances relative; AO and user guides become features
    /// (default normal + depth + position).
    pub guides: u32,
    /// User guide channels (0..=4).
    pub user_guides: u32,
    /// À-trous iterations T, 1..=5 (default 4: an 81x81 window).
    pub iterations: u32,
    /// Plane distance below which a tap has full weight (0.005, relative to the
    /// camera distance with depth).
    pub near: f32,
    /// Plane distance at which a tap's weight reaches 0 (0.01).
    pub far: f32,
    /// Trace the edge-stopping function along each tap's segment (true).
    pub tracing: bool,
    /// Replace a tap cut off by an edge with an average before the edge (true).
    pub replace: bool,
    /// Fraction of the previous iteration's edge distance tracing may skip (0.5).
    pub sdf_step: f32,
    /// Cholesky pivot floor for the features (1e-3).
    pub epsilon: f32,
    /// Store the averages as f16 (the paper's) instead of f32 (default false).
    pub storage_f16: bool,
    /// Use `view` (direction towards the camera, in the normals' space) as the
    /// pole of the octahedral normal map; false: the frame's mean normal.
    pub has_view: bool,
    /// With `has_view`: the direction towards the camera, finite and not
    /// zero (need not be unit length); ignored otherwise (default 0, 0, 1).
    pub view: [f32; 3],
    /// Clamp negative output to 0 (true).
    pub clamp_negative: bool,
    /// Use the scalar reference kernels (slow; for testing).
    pub scalar_kernels: bool,
    /// Weight w of the previous iteration's fit in the output, (1 − w)·fit_T +
    /// w·fit_{T−1}: 0..=1, 0 = one window (default: see lrd_walr_config_default).
    pub previous_weight: f32,
    /// Blend the two windows per pixel by their estimated errors (true by
    /// default); previous_weight is then ignored.
    pub adaptive_blend: bool,
    /// The temporal pipeline's stage, shared with temporal FLR (defaults:
    /// `lrd_temporal_config_default`).
    pub temporal: LrdTemporalConfig,
    /// The firefly clamp's threshold factor k (>= 1): a noisy sample whose
    /// luminance exceeds k times the larger of the third brightest 8x8
    /// cell of its 104x8-pixel neighbourhood and that neighbourhood's mean
    /// without its brightest cell is scaled down to that level for the filter,
    /// and for the temporal pipeline's accumulation (see the core's
    /// `fireflies` module); 0 turns it off. Default 1.5.
    pub fireflies: f32,
}

fn walr_config(c: &LrdWalrConfig) -> Result<lrdenoise_core::WalrConfig, LrdStatus> {
    use lrdenoise_core::walr::Storage;
    let cfg = lrdenoise_core::WalrConfig {
        guides: guide_set(c.guides, c.user_guides)?,
        iterations: u8::try_from(c.iterations).map_err(|_| LRD_STATUS_INVALID_CONFIG)?,
        near: c.near,
        far: c.far,
        tracing: c.tracing,
        replace: c.replace,
        sdf_step: c.sdf_step,
        epsilon: c.epsilon,
        storage: if c.storage_f16 { Storage::F16 } else { Storage::F32 },
        view: c.has_view.then_some(c.view),
        clamp_negative: c.clamp_negative,
        kernel: if c.scalar_kernels { Kernel::Scalar } else { Kernel::Simd },
        previous_weight: c.previous_weight,
        adaptive_blend: c.adaptive_blend,
        temporal: temporal_config(&c.temporal)?,
        fireflies: (c.fireflies != 0.0).then_some(c.fireflies),
    };
    cfg.validate().map_err(status_of)?;
    Ok(cfg)
}

fn walr_plan(c: *const LrdWalrConfig, width: u32, height: u32) -> Result<lrdenoise_core::Walr, LrdStatus> {
    // SAFETY: checked for NULL; the caller passes a valid config pointer.
    let c = unsafe { c.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
    lrdenoise_core::Walr::new(walr_config(c)?, width as usize, height as usize).map_err(status_of)
}

/// WALR's defaults: normal + depth + position, T = 4, tracing and replacement
/// on, thresholds 0.5 % / 1 %, f32 averages, the adaptive blend of the last
/// two windows, and the pipeline's settings.
#[no_mangle]
pub extern "C" fn lrd_walr_config_default() -> LrdWalrConfig {
    let d = lrdenoise_core::WalrConfig::default();
    let t = d.temporal;
    LrdWalrConfig {
        guides: LRD_GUIDE_NORMAL | LRD_GUIDE_DEPTH | LRD_GUIDE_POSITION,
        user_guides: 0,
        iterations: d.iterations as u32,
        near: d.near,
        far: d.far,
        tracing: d.tracing,
        replace: d.replace,
        sdf_step: d.sdf_step,
        epsilon: d.epsilon,
        storage_f16: d.storage == lrdenoise_core::walr::Storage::F16,
        has_view: d.view.is_some(),
        view: d.view.unwrap_or([0.0, 0.0, 1.0]),
        clamp_negative: d.clamp_negative,
        scalar_kernels: false,
        previous_weight: d.previous_weight,
        adaptive_blend: d.adaptive_blend,
        temporal: crate::temporal::lrd_temporal_config(&t),
        fireflies: d.fireflies.unwrap_or(0.0),
    }
}

/// Scratch bytes `lrd_walr_denoise` (single frame) needs for `width`x`height` frames.
#[no_mangle]
pub unsafe extern "C" fn lrd_walr_scratch_size(config: *const LrdWalrConfig, width: u32, height: u32, bytes: *mut usize) -> LrdStatus {
    guard(|| scratch_size(walr_plan(config, width, height)?, bytes))
}

/// Scratch and history bytes of the WALR pipeline (`lrd_walr_denoise_temporal`).
#[no_mangle]
pub unsafe extern "C" fn lrd_walr_temporal_sizes(
    config: *const LrdWalrConfig,
    width: u32,
    height: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_sizes(walr_plan(config, width, height)?, scratch_bytes, history_bytes))
}

/// Single-frame WALR on the calling thread. `index` seeds the replacement
/// averages (use the frame number). `out` (3 channels) has the frame's size;
/// `frame.guides_low` must be absent. `scratch`: 8-byte aligned, at least
/// `lrd_walr_scratch_size` bytes. `report` may be NULL.
#[no_mangle]
pub unsafe extern "C" fn lrd_walr_denoise(
    config: *const LrdWalrConfig,
    frame: *const LrdFrame,
    index: u32,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    report: *mut LrdReport,
) -> LrdStatus {
    // SAFETY: forwarded contract (see `denoise_single`).
    guard(|| unsafe { denoise_single(|w, h| walr_plan(config, w, h), frame, index, out, scratch, scratch_bytes, report) })
}

/// One frame of the WALR pipeline (reprojection with depth rejection,
/// accumulation, WALR, the variance-clipped post pass) on the calling thread.
/// Arguments as for `lrd_bmfr_denoise_temporal`, with the sizes from
/// `lrd_walr_temporal_sizes`.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_walr_denoise_temporal(
    config: *const LrdWalrConfig,
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
        denoise_temporal(|w, h| walr_plan(config, w, h), frame, motion, history, out, scratch, scratch_bytes, core::ptr::null(), report)
    })
}

/// Scratch bytes of `lrd_walr_denoise_temporal_parallel` with `workers`
/// workers, and history bytes (those of `lrd_walr_temporal_sizes`: one
/// history serves both calls).
#[no_mangle]
pub unsafe extern "C" fn lrd_walr_temporal_parallel_sizes(
    config: *const LrdWalrConfig,
    width: u32,
    height: u32,
    workers: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_parallel_sizes(walr_plan(config, width, height)?, workers, scratch_bytes, history_bytes))
}

/// lrd_walr_denoise_temporal with the work run on the caller's threads
/// (`executor`, see LrdExecutor); bit-identical to it. The scratch size is
/// from `lrd_walr_temporal_parallel_sizes` with `executor->workers`; `out`
/// needs rows that do not overlap in memory.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_walr_denoise_temporal_parallel(
    config: *const LrdWalrConfig,
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
        denoise_temporal(|w, h| walr_plan(config, w, h), frame, motion, history, out, scratch, scratch_bytes, executor, report)
    })
}
