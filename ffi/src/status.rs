//! The outcome of a call: its [`LrdStatus`] (library errors and caught
//! panics mapped to a status) and the counts it adds to an [`LrdReport`].

use core::ffi::c_char;
use lrdenoise_core::{Error, Report};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Result of every call. Values are stable across versions.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LrdStatus {
    /// Success.
    LRD_STATUS_OK = 0,
    /// A required pointer was NULL.
    LRD_STATUS_NULL_POINTER = 1,
    /// A size, stride, format, alignment or enum value is invalid.
    LRD_STATUS_INVALID_ARGUMENT = 2,
    /// The scratch buffer (or another buffer) is smaller than required.
    LRD_STATUS_BUFFER_TOO_SMALL = 3,
    /// Valid, but not supported here (e.g. a method not compiled in).
    LRD_STATUS_UNSUPPORTED = 4,
    /// An image does not have the size implied by the output and configuration.
    LRD_STATUS_SIZE_MISMATCH = 5,
    /// A configuration value is out of range.
    LRD_STATUS_INVALID_CONFIG = 6,
    /// The frame's guides do not match the configuration's guide set.
    LRD_STATUS_GUIDE_MISMATCH = 7,
    /// Stage, tile or worker index out of range.
    LRD_STATUS_INVALID_TILE = 8,
    /// A panic was caught: a bug in lrdenoise. Please report it.
    LRD_STATUS_PANIC = 9,
    /// Any other internal error.
    LRD_STATUS_INTERNAL = 10,
    /// A tiled stage was run out of order: before every tile of the stage
    /// ahead of it finished (or before this frame's PREPARE), a second time
    /// for one tile, on a worker that is busy, or with other arguments than
    /// the frame's PREPARE. Nothing was written.
    LRD_STATUS_STAGE_ORDER = 11,
}

use LrdStatus::*;

/// What happened during a run (added to by every call that takes one).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct LrdReport {
    /// Input pixels with a NaN or infinite noisy value (left out of the fit).
    pub nonfinite_noisy: u64,
    /// Input pixels with a NaN or infinite guide value (left out of the fit;
    /// WALR treats them as "no geometry").
    pub nonfinite_guides: u64,
    /// Output pixels whose own guides were not finite, or that had no usable
    /// sample: given a local mean (or 0 where there was none).
    pub fallback_pixels: u64,
    /// FLR, BMFR: blocks without any valid pixel.
    pub empty_blocks: u64,
    /// FLR: cells whose window held no valid pixel (output 0 there).
    pub empty_cells: u64,
    /// FLR: pivots floored in the solve; BMFR: features dropped by the QR.
    pub dropped_pivots: u64,
    /// Temporal pipelines: pixels whose history was rejected (disocclusion,
    /// motion out of the frame; the first frame is not counted).
    pub history_rejected: u64,
    /// Noisy samples scaled down by the firefly clamp.
    pub clamped_fireflies: u64,
    /// Temporal pipelines: pixels whose motion vector was NaN, infinite or
    /// longer than twice the frame (they get no history).
    pub invalid_motion: u64,
    /// Temporal pipelines: frames taken as a camera cut (history restarted).
    pub history_resets: u64,
    /// Temporal FLR on cell moments: pixels whose history restarted
    /// because their light changed (the lag test).
    pub light_changed: u64,
}

pub(crate) fn status_of(e: Error) -> LrdStatus {
    match e {
        Error::InvalidSize { .. } | Error::InvalidStride { .. } | Error::ChannelCount { .. } => LRD_STATUS_INVALID_ARGUMENT,
        Error::SizeMismatch { .. } => LRD_STATUS_SIZE_MISMATCH,
        Error::BufferTooSmall { .. } | Error::ScratchTooSmall { .. } => LRD_STATUS_BUFFER_TOO_SMALL,
        Error::GuideMismatch => LRD_STATUS_GUIDE_MISMATCH,
        Error::TooManyGuides { .. } | Error::InvalidConfig(_) => LRD_STATUS_INVALID_CONFIG,
        Error::InvalidTile { .. } => LRD_STATUS_INVALID_TILE,
        Error::Unsupported(_) => LRD_STATUS_UNSUPPORTED,
        Error::StageOrder { .. } => LRD_STATUS_STAGE_ORDER,
    }
}

/// Runs `f`, turning errors and panics into a status.
pub(crate) fn guard(f: impl FnOnce() -> Result<(), LrdStatus>) -> LrdStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => LRD_STATUS_OK,
        Ok(Err(s)) => s,
        Err(_) => LRD_STATUS_PANIC,
    }
}

pub(crate) fn write_report(report: *mut LrdReport, r: Report) {
    // SAFETY: NULL is allowed; otherwise the caller passes a valid, exclusive pointer.
    if let Some(out) = unsafe { report.as_mut() } {
        out.nonfinite_noisy += r.nonfinite_noisy;
        out.nonfinite_guides += r.nonfinite_guides;
        out.fallback_pixels += r.fallback_pixels;
        out.empty_blocks += r.empty_blocks;
        out.empty_cells += r.empty_cells;
        out.dropped_pivots += r.dropped_pivots;
        out.history_rejected += r.history_rejected;
        out.clamped_fireflies += r.clamped_fireflies;
        out.invalid_motion += r.invalid_motion;
        out.history_resets += r.history_resets;
        out.light_changed += r.light_changed;
    }
}

/// A static, NUL-terminated description of a status (any value).
#[no_mangle]
pub extern "C" fn lrd_status_string(status: u32) -> *const c_char {
    let s: &core::ffi::CStr = match status {
        0 => c"ok",
        1 => c"a required pointer was NULL",
        2 => c"invalid size, stride, format, alignment or enum value",
        3 => c"buffer too small",
        4 => c"unsupported",
        5 => c"image size does not match the output size and configuration",
        6 => c"invalid configuration",
        7 => c"the frame's guides do not match the configured guide set",
        8 => c"stage, tile or worker index out of range",
        9 => c"internal panic (a bug in lrdenoise)",
        10 => c"internal error",
        11 => c"tiled stage run out of order, twice, on a busy worker, or with other arguments than its frame's PREPARE",
        _ => c"unknown status",
    };
    s.as_ptr()
}
