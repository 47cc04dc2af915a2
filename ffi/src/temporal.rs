//! What the temporal entry points (FLR's, BMFR's, WALR's) share: the
//! caller-owned [`LrdHistory`], the temporal stage's [`LrdTemporalConfig`],
//! the scratch and history buffers, and the single-frame and temporal runs
//! over the core's [`TemporalDenoiser`].

use crate::executor::{self, LrdExecutor};
use crate::images::{
    byte_range, check_output_disjoint, check_scratch, frame_and_out, frame_views, guide_set, view, view_mut, LrdFrame, LrdImage,
    LrdImageMut, LRD_GUIDE_DEPTH, LRD_GUIDE_NORMAL, LRD_GUIDE_POSITION,
};
use crate::status::{status_of, write_report, LrdReport, LrdStatus, LrdStatus::*};
use core::ffi::c_void;
use lrdenoise_core::{Denoiser, Error, Frame, GuideSet, ImageViewMut, Report, TemporalDenoiser};

/// The caller-owned state of a temporal pipeline (FLR, BMFR or WALR): `data`
/// (4-byte aligned, at least the history size from the method's
/// `..._temporal_sizes` or `..._temporal_parallel_sizes` call: the two give
/// the same size) and the number of frames accumulated. Set
/// `frames = 0` to start (or after a camera cut); each successful
/// `..._denoise_temporal` or `..._denoise_temporal_parallel` call advances it. The contents of `data` are ignored while `frames == 0`.
/// One history serves one method, size and configuration.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdHistory {
    /// The history buffer: not NULL, 4-byte aligned, read and written by each
    /// temporal call. It must not overlap the scratch, the images or `out`.
    pub data: *mut c_void,
    /// Size of `data` in bytes, at least the history size of the
    /// `..._temporal_sizes` call (else LRD_STATUS_BUFFER_TOO_SMALL).
    pub bytes: usize,
    /// Frames accumulated: 0 starts a new sequence; each successful temporal
    /// call increments it (past UINT32_MAX it wraps to a small number, never to 0).
    pub frames: u32,
}

/// Settings of the temporal stage temporal FLR runs (`lrd_temporal_config_default`
/// gives the defaults; see the core's `temporal::TemporalConfig`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdTemporalConfig {
    /// Longest per-pixel history in frames (1..=1e6; default 16).
    pub max_history: f32,
    /// Smallest cosine between a history tap's normal and the current one (default 0.5).
    pub normal_limit: f32,
    /// Largest world-position distance of a history tap, as a fraction of the
    /// camera distance: the depth, or without depth an estimate from the
    /// pixel's footprint for a 60° field of view (default 0.05).
    pub position_limit: f32,
    /// Without positions: largest relative depth difference (default 0.05).
    pub depth_limit: f32,
    /// Half-width of the output's clip box in standard deviations (default 1.5).
    pub clip_gamma: f32,
    /// Lowest blend weight of the new output frame, (0, 1]; 1 turns the output
    /// accumulation off, and its work and 6 f32 per pixel of scratch with it (default 0.5).
    pub output_alpha: f32,
    /// Fraction of pixels without history above which a frame is a camera cut
    /// and the history restarts, (0, 1] (default 0.5).
    pub cut_fraction: f32,
    /// With the firefly clamp on: the clamp's reference (the third brightest
    /// cell of a cell's neighbourhood) counts at most this many times the
    /// brightest luminance the previous frame kept around the cell; 0 or
    /// finite ≥ 1 (default 2; 0 turns it off).
    pub firefly_history: f32,
    /// Temporal FLR on moments only (the other pipelines ignore it): the lag
    /// test's threshold in standard errors. A cell whose newest frames' mean
    /// luminance differs from its history's by more than this restarts from
    /// its own moments, so that light that changed (a moving object's
    /// shadow) does not lag; finite ≥ 0 (default 3; 0 turns the test off).
    pub lag_sigmas: f32,
    /// Temporal FLR: the bit set of LRD_GUIDE_NORMAL, LRD_GUIDE_DEPTH and
    /// LRD_GUIDE_POSITION that judges history taps, which the frames must then
    /// carry too; 0 (the default): FLR's own guides. Positions keep the
    /// history of surfaces the camera moves towards, which depth rejects. Any
    /// other bit: LRD_STATUS_INVALID_CONFIG. BMFR and WALR judge by their own
    /// guides and need 0 (else LRD_STATUS_UNSUPPORTED).
    pub rejection_guides: u32,
}

/// The temporal stage's defaults (temporal FLR's and WALR's; BMFR's differ:
/// see `lrd_bmfr_config_default`).
#[no_mangle]
pub extern "C" fn lrd_temporal_config_default() -> LrdTemporalConfig {
    lrd_temporal_config(&lrdenoise_core::temporal::TemporalConfig::default())
}

/// The C form of the core's settings.
pub(crate) fn lrd_temporal_config(d: &lrdenoise_core::temporal::TemporalConfig) -> LrdTemporalConfig {
    LrdTemporalConfig {
        max_history: d.max_history,
        normal_limit: d.normal_limit,
        position_limit: d.position_limit,
        depth_limit: d.depth_limit,
        clip_gamma: d.clip_gamma,
        output_alpha: d.output_alpha,
        cut_fraction: d.cut_fraction,
        firefly_history: d.firefly_history,
        lag_sigmas: d.lag_sigmas,
        rejection_guides: 0,
    }
}

/// The core's settings from `c` (NULL: LRD_STATUS_NULL_POINTER; out of
/// range: LRD_STATUS_INVALID_CONFIG), for a method that judges history by its
/// own guides (`rejection_guides` other than 0: LRD_STATUS_UNSUPPORTED).
pub(crate) fn temporal_config(c: *const LrdTemporalConfig) -> Result<lrdenoise_core::temporal::TemporalConfig, LrdStatus> {
    let (t, reject) = temporal_config_and_rejection(c)?;
    if reject.is_some() {
        return Err(LRD_STATUS_UNSUPPORTED);
    }
    Ok(t)
}

/// The core's settings from `c` and its rejection guides (`None`: 0, the
/// method's own); errors as [`temporal_config`]'s, except that any set of
/// normal, depth and position is taken.
pub(crate) fn temporal_config_and_rejection(
    c: *const LrdTemporalConfig,
) -> Result<(lrdenoise_core::temporal::TemporalConfig, Option<GuideSet>), LrdStatus> {
    // SAFETY: checked for NULL; the caller passes a valid pointer.
    let c = unsafe { c.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
    let reject = match c.rejection_guides {
        0 => None,
        bits if bits & !(LRD_GUIDE_NORMAL | LRD_GUIDE_DEPTH | LRD_GUIDE_POSITION) != 0 => return Err(LRD_STATUS_INVALID_CONFIG),
        bits => Some(guide_set(bits, 0)?),
    };
    let t = lrdenoise_core::temporal::TemporalConfig {
        max_history: c.max_history,
        normal_limit: c.normal_limit,
        position_limit: c.position_limit,
        depth_limit: c.depth_limit,
        clip_gamma: c.clip_gamma,
        output_alpha: c.output_alpha,
        cut_fraction: c.cut_fraction,
        firefly_history: c.firefly_history,
        lag_sigmas: c.lag_sigmas,
    };
    t.validate().map_err(status_of)?;
    Ok((t, reject))
}

fn f32_bytes(len: usize) -> Result<usize, LrdStatus> {
    len.checked_mul(4).ok_or(LRD_STATUS_INVALID_ARGUMENT)
}

fn f64_bytes(len: usize) -> Result<usize, LrdStatus> {
    len.checked_mul(8).ok_or(LRD_STATUS_INVALID_ARGUMENT)
}

/// `bytes` bytes at `ptr` as f64 scratch (8-byte aligned, at least `needed` bytes).
///
/// # Safety
/// `ptr` must point to `bytes` writable bytes, exclusively ours for `'a`.
unsafe fn f64_buffer<'a>(ptr: *mut c_void, bytes: usize, needed: usize) -> Result<&'a mut [f64], LrdStatus> {
    check_scratch(ptr)?;
    if bytes < needed {
        return Err(LRD_STATUS_BUFFER_TOO_SMALL);
    }
    // SAFETY: non-null, 8-byte aligned, at least `needed` bytes (caller's contract).
    Ok(unsafe { core::slice::from_raw_parts_mut(ptr as *mut f64, needed / 8) })
}

/// `bytes` bytes at `ptr` as f32 (4-byte aligned, at least `needed` bytes).
///
/// # Safety
/// `ptr` must point to `bytes` writable bytes, exclusively ours for `'a`.
unsafe fn f32_buffer<'a>(ptr: *mut c_void, bytes: usize, needed: usize) -> Result<&'a mut [f32], LrdStatus> {
    if ptr.is_null() {
        return Err(LRD_STATUS_NULL_POINTER);
    }
    if !(ptr as usize).is_multiple_of(4) {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    if bytes < needed {
        return Err(LRD_STATUS_BUFFER_TOO_SMALL);
    }
    // SAFETY: non-null, aligned, at least `needed` bytes (caller's contract).
    Ok(unsafe { core::slice::from_raw_parts_mut(ptr as *mut f32, needed / 4) })
}

/// BMFR's and WALR's single frame at a frame index (their per-frame grid
/// offsets), over the f64 scratch of [`Denoiser`]; everything else the C
/// entry points of both call goes through the core's [`TemporalDenoiser`].
pub(crate) trait AtIndex: TemporalDenoiser {
    fn denoise_at(&self, f: &Frame<'_>, index: u32, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error>;
}

macro_rules! at_index {
    ($ty:ty) => {
        impl AtIndex for $ty {
            fn denoise_at(&self, f: &Frame<'_>, index: u32, scratch: &mut [f64], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
                let len = <$ty>::scratch_len(self);
                let got = 2 * scratch.len();
                let s = bytemuck::cast_slice_mut::<f64, f32>(scratch).get_mut(..len).ok_or(Error::ScratchTooSmall { needed: len, got })?;
                <$ty>::denoise(self, f, index, s, out)
            }
        }
    };
}

#[cfg(feature = "bmfr")]
at_index!(lrdenoise_core::Bmfr);
#[cfg(feature = "walr")]
at_index!(lrdenoise_core::Walr);

pub(crate) fn scratch_size<M: Denoiser>(plan: M, bytes: *mut usize) -> Result<(), LrdStatus> {
    let b = f64_bytes(plan.scratch_len())?;
    // SAFETY: checked for NULL; caller passes a valid pointer.
    *unsafe { bytes.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = b;
    Ok(())
}

pub(crate) fn temporal_sizes<M: TemporalDenoiser>(plan: M, scratch_bytes: *mut usize, history_bytes: *mut usize) -> Result<(), LrdStatus> {
    let (s, h) = (f64_bytes(plan.temporal_scratch_len())?, f32_bytes(plan.history_len())?);
    // SAFETY: checked for NULL; caller passes valid pointers.
    unsafe {
        *scratch_bytes.as_mut().ok_or(LRD_STATUS_NULL_POINTER)? = s;
        *history_bytes.as_mut().ok_or(LRD_STATUS_NULL_POINTER)? = h;
    }
    Ok(())
}

/// A single frame of a temporal method (`plan(width, height)` from the output size).
///
/// # Safety
/// The pointers satisfy the contracts of the `lrd_*_denoise` entry points.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn denoise_single<M: AtIndex>(
    plan: impl FnOnce(u32, u32) -> Result<M, LrdStatus>,
    frame: *const LrdFrame,
    index: u32,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    report: *mut LrdReport,
) -> Result<(), LrdStatus> {
    // SAFETY: NULL-checked; the caller passes valid pointers. The images satisfy
    // the LrdImage contract; the scratch is checked (NULL, alignment, size) and
    // `out` is exclusively ours.
    unsafe {
        let (frame, out) = frame_and_out(frame, out)?;
        let m = plan(out.width, out.height)?;
        check_output_disjoint(out, frame, &[(scratch as usize, scratch_bytes)])?;
        let f = frame_views(frame, false)?;
        let s = f64_buffer(scratch, scratch_bytes, f64_bytes(m.scratch_len())?)?;
        let mut o = view_mut(out, 0, out.height as usize)?;
        let r = m.denoise_at(&f, index, s, &mut o).map_err(status_of)?;
        write_report(report, r);
    }
    Ok(())
}

/// Scratch bytes (for `workers` workers of a `..._parallel` call) and
/// history bytes of a temporal method.
pub(crate) fn temporal_parallel_sizes<M: TemporalDenoiser>(
    plan: M,
    workers: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> Result<(), LrdStatus> {
    if workers == 0 {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    let s = plan.temporal_parallel_scratch_len(workers as usize).ok_or(LRD_STATUS_INVALID_ARGUMENT)?;
    let (s, h) = (f64_bytes(s)?, f32_bytes(plan.history_len())?);
    // SAFETY: checked for NULL; caller passes valid pointers.
    unsafe {
        *scratch_bytes.as_mut().ok_or(LRD_STATUS_NULL_POINTER)? = s;
        *history_bytes.as_mut().ok_or(LRD_STATUS_NULL_POINTER)? = h;
    }
    Ok(())
}

/// One frame of a temporal pipeline; advances `history.frames`. With an
/// `executor` (not NULL) the frame's tiles run on it
/// ([`TemporalDenoiser::denoise_temporal_parallel`]) and the scratch is that
/// of its worker count.
///
/// # Safety
/// The pointers satisfy the contracts of the `lrd_*_denoise_temporal` entry
/// points (and `executor` that of [`LrdExecutor`]).
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn denoise_temporal<M: TemporalDenoiser>(
    plan: impl FnOnce(u32, u32) -> Result<M, LrdStatus>,
    frame: *const LrdFrame,
    motion: *const LrdImage,
    history: *mut LrdHistory,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    executor: *const LrdExecutor,
    report: *mut LrdReport,
) -> Result<(), LrdStatus> {
    // SAFETY: as in `denoise_single`; the history buffer is checked the same way.
    unsafe {
        let frame = frame.as_ref().ok_or(LRD_STATUS_NULL_POINTER)?;
        let out = out.as_ref().ok_or(LRD_STATUS_NULL_POINTER)?;
        let hist = history.as_mut().ok_or(LRD_STATUS_NULL_POINTER)?;
        let m = plan(out.width, out.height)?;
        let ex = if executor.is_null() { None } else { Some(executor::checked(executor)?) };
        let workers = ex.map(|e| e.workers as usize);
        let ranges = [(scratch as usize, scratch_bytes), (hist.data as usize, hist.bytes)];
        check_output_disjoint(out, frame, &ranges)?;
        let motion_range = motion
            .as_ref()
            .and_then(|mi| byte_range(mi.data, mi.format, mi.width, mi.height, 2, (mi.pixel_stride, mi.row_stride, mi.channel_stride)));
        let o = byte_range(out.data, out.format, out.width, out.height, 3, (out.pixel_stride, out.row_stride, out.channel_stride));
        let overlap = |(a, b): (usize, usize), (c, d): (usize, usize)| a < d && c < b;
        if let (Some(mr), Some(o)) = (motion_range, o) {
            if overlap(mr, o) {
                return Err(LRD_STATUS_INVALID_ARGUMENT);
            }
        }
        // the history and the scratch are written: neither may overlap the
        // motion or the other (nor an image: `check_output_disjoint`)
        let h = (hist.data as usize, (hist.data as usize).saturating_add(hist.bytes));
        let sc = (scratch as usize, (scratch as usize).saturating_add(scratch_bytes));
        let written = [h, sc].into_iter().filter(|(a, b)| a < b);
        if written.clone().any(|w| motion_range.is_some_and(|m| overlap(m, w))) || (h.0 < h.1 && sc.0 < sc.1 && overlap(h, sc)) {
            return Err(LRD_STATUS_INVALID_ARGUMENT);
        }
        let f = frame_views(frame, false)?;
        let mv = match motion.as_ref() {
            Some(mi) => view(mi, 2)?,
            None => None,
        };
        let needed = match workers {
            None => m.temporal_scratch_len(),
            Some(w) => m.temporal_parallel_scratch_len(w).ok_or(LRD_STATUS_INVALID_ARGUMENT)?,
        };
        let s = f64_buffer(scratch, scratch_bytes, f64_bytes(needed)?)?;
        let hd = f32_buffer(hist.data, hist.bytes, f32_bytes(m.history_len())?)?;
        let mut h = lrdenoise_core::History::resume(hd, hist.frames);
        let mut o = view_mut(out, 0, out.height as usize)?;
        if workers.is_some() && !o.rows_are_separable() {
            // the parallel runs write the output in row bands
            return Err(LRD_STATUS_UNSUPPORTED);
        }
        let r = match ex {
            None => m.denoise_temporal(&f, mv.as_ref(), &mut h, s, &mut o),
            Some(e) => {
                let w = e.workers as usize;
                executor::run(&e, |for_each| m.denoise_temporal_parallel(&f, mv.as_ref(), &mut h, s, &mut o, w, for_each))?
            }
        }
        .map_err(status_of)?;
        hist.frames = h.frames();
        write_report(report, r);
    }
    Ok(())
}
