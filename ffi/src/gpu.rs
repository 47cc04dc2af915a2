//! FLR's GPU path: the dispatch description of a configuration
//! (`lrd_gpu_dispatch`) and the WGSL shader module (`lrd_gpu_wgsl`); temporal
//! FLR's, the temporal stage's passes around FLR's (`lrd_gpu_temporal_dispatch`,
//! `lrd_gpu_temporal_wgsl`).

#[cfg(feature = "flr")]
use crate::flr::LrdFlrConfig;
#[cfg(feature = "flr")]
use crate::status::{guard, status_of, LrdStatus, LrdStatus::*};
use core::ffi::c_char;

/// One compute dispatch of the GPU path: the WGSL entry point and its workgroup counts.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdGpuPass {
    /// Static, NUL-terminated entry point name.
    pub entry: *const c_char,
    /// Workgroup counts along x, y and z (the arguments of `dispatchWorkgroups`).
    pub workgroups: [u32; 3],
}

/// How to run FLR's compute shaders (`lrd_gpu_wgsl`, or the SPIR-V/MSL/HLSL of
/// `lrd shaders`) for one frame size with planar buffers: noisy R, G, B
/// planes; guide channels one plane each (normal x, y, z, depth, position x,
/// y, z, AO, user, those configured), f32 or f16; output R, G, B f32 planes.
/// With `upsample` > 1 the noisy planes are at the low resolution and the
/// guide buffer holds, after the full-resolution guide planes, the same
/// channels at the low resolution (what the moments are taken from). Every pass uses
/// one bind group, binding `i` = buffer `i`: 0 the uniform `params` block, 1
/// noisy, 2 guides (read-only storage), 3 stats, 4 cells, 5 tmp, 6 models, 7
/// output (read-write storage). Run the first `pass_count` passes in order
/// with a storage barrier between them: 7 with one window, up to 15 with the
/// adaptive window (`LRD_BLUR_ADAPTIVE`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdGpuDispatch {
    /// The dispatches, in order; entries from `pass_count` on are unused
    /// (`entry` NULL, `workgroups` 0).
    pub passes: [LrdGpuPass; 15],
    /// Number of valid entries of `passes` (7 with one window, at most 15).
    pub pass_count: u32,
    /// Minimum size of each buffer in bytes, in binding order.
    pub buffer_bytes: [u64; 8],
    /// Contents of the uniform parameter block (binding 0): upload these
    /// bytes unchanged.
    pub params: [u8; 1424],
}

#[cfg(feature = "flr")]
const _: () = assert!(lrdenoise_core::flr::gpu::MAX_PASSES == 15 && lrdenoise_core::flr::gpu::PARAMS_BYTES == 1424);

/// Fills `out` with the GPU dispatch description of `config` for
/// `width`×`height` output frames (at most 8 guide channels), with
/// noisy and guide buffers in `input_format` (LRD_FORMAT_F32 or LRD_FORMAT_F16).
#[cfg(feature = "flr")]
#[no_mangle]
pub unsafe extern "C" fn lrd_gpu_dispatch(
    config: *const LrdFlrConfig,
    width: u32,
    height: u32,
    input_format: u32,
    out: *mut LrdGpuDispatch,
) -> LrdStatus {
    use lrdenoise_core::flr::gpu::InputFormat;
    guard(|| {
        let input = match input_format {
            0 => InputFormat::F32,
            1 => InputFormat::F16,
            _ => return Err(LRD_STATUS_INVALID_ARGUMENT),
        };
        // SAFETY: checked for NULL; the caller passes a valid config pointer.
        let c = unsafe { config.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
        let d = flr_dispatch(crate::flr::config(c)?, width, height, input)?;
        // SAFETY: checked for NULL; caller passes a valid pointer.
        *unsafe { out.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = d;
        Ok(())
    })
}

/// The dispatch description of FLR planned with `cfg`, planar buffers in `input`.
#[cfg(feature = "flr")]
fn flr_dispatch(
    cfg: lrdenoise_core::FlrConfig,
    width: u32,
    height: u32,
    input: lrdenoise_core::flr::gpu::InputFormat,
) -> Result<LrdGpuDispatch, LrdStatus> {
    use lrdenoise_core::flr::gpu::{GpuLayouts, GpuPlan};
    let (w, h) = (width as usize, height as usize);
    let plan = GpuPlan::new(cfg, w, h).map_err(status_of)?;
    let layouts = if cfg.upsample > 1 {
        let (iw, ih) = plan.input_size();
        GpuLayouts::planar_with_fit(w, h, iw, ih, plan.guide_channels(), input)
    } else {
        GpuLayouts::planar(w, h, input)
    };
    let params = plan.params(&layouts).map_err(status_of)?;
    let buffers = plan.buffers(&layouts).map_err(status_of)?;
    let passes = plan.passes();
    let mut d = LrdGpuDispatch {
        passes: [LrdGpuPass { entry: core::ptr::null(), workgroups: [0; 3] }; 15],
        pass_count: passes.len() as u32,
        buffer_bytes: [0; 8],
        params: [0; 1424],
    };
    for (dst, p) in d.passes.iter_mut().zip(passes.iter()) {
        *dst = LrdGpuPass { entry: p.entry.as_ptr(), workgroups: p.workgroups };
    }
    for (dst, b) in d.buffer_bytes.iter_mut().zip(&buffers) {
        *dst = b.bytes;
    }
    d.params.copy_from_slice(params.as_bytes());
    Ok(d)
}

/// FLR's WGSL shader module (static, NUL-terminated).
#[no_mangle]
pub extern "C" fn lrd_gpu_wgsl() -> *const c_char {
    concat!(include_str!("../../src/flr/flr.wgsl"), "\0").as_ptr() as *const c_char
}

/// How to run temporal FLR's compute shaders (FLR's, and the temporal stage's
/// module `lrd_gpu_temporal_wgsl`) for one frame size, with the history on
/// the device. Each frame:
/// 1. upload the noisy light, the guides (as for `flr`) and the motion (x
///    then y plane, f32, previous minus current pixel position; zeros for a
///    static camera) into buffer 4 at `motion_offset`, and there too the
///    rejection guides FLR does not read (`work_guides`);
/// 2. upload `params_first` for the first frame of a sequence (or after a
///    cut the caller knows of), `params` otherwise;
/// 3. bind the history's two slot buffers (`buffer_bytes[3]` bytes each): a
///    frame after an even number of frames (0, 2, …) reads slot 1 as binding 3
///    and writes slot 0 as binding 8, the next the other way round;
/// 4. dispatch `before`, then `flr.passes`, then `after`, with a storage
///    barrier between dispatches;
/// 5. read buffer 7, the output (R, G, B f32 planes), and for the counts
///    buffer 5: four u32, pixels without history, invalid motion vectors,
///    NaN/Inf samples, clamped fireflies; a frame with history is a camera
///    cut (its history restarted) when the first exceeds `cut_limit`.
///
/// The stage's bind group, binding `i` = `buffer_bytes[i]`: 0 the uniform
/// parameter block, 1 the light (FLR's noisy buffer, binding 1 of `flr`,
/// overwritten with the accumulated light), 2 the guides (FLR's guide buffer),
/// 3 the history slot read (read-only storage), 4 work, 5 counters, 6 FLR's
/// output (binding 7 of `flr`), 7 the stage's output, 8 the history slot
/// written. The slots, slot 0 then slot 1, are the CPU history
/// (`lrd_flr_denoise_temporal`'s `LrdHistory.data`) of the same configs and
/// size, so a sequence can move between the two paths.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdGpuTemporalDispatch {
    /// FLR's dispatch for the accumulated light: `config` with the firefly
    /// clamp off (the stage clamps the light), f32 planar inputs.
    pub flr: LrdGpuDispatch,
    /// The stage's passes before FLR's: `t_cells`, `t_taps`, `t_thresholds`, `t_accumulate`.
    pub before: [LrdGpuPass; 4],
    /// The stage's pass after FLR's: `t_resolve`.
    pub after: LrdGpuPass,
    /// Minimum size of each buffer of the stage's bind group in bytes, in binding order.
    pub buffer_bytes: [u64; 9],
    /// Byte offset of the motion planes in buffer 4.
    pub motion_offset: u64,
    /// Byte offsets in buffer 4 of the normal (x, y, z planes), the position
    /// (x, y, z planes) and the depth (one plane) when
    /// `temporal->rejection_guides` names them and `config->guides` does not
    /// (f32, `width · height` values a plane); UINT64_MAX: not uploaded.
    pub work_guides: [u64; 3],
    /// A frame with history and more pixels without history than this is a camera cut.
    pub cut_limit: u32,
    /// The parameter block (binding 0) of a sequence's first frame: upload unchanged.
    pub params_first: [u8; 112],
    /// The parameter block of every later frame.
    pub params: [u8; 112],
}

#[cfg(feature = "flr")]
const _: () = assert!(core::mem::size_of::<lrdenoise_core::temporal::gpu::GpuTemporalParams>() == 112);

/// Fills `out` with the GPU dispatch description of temporal FLR with
/// `config` and `temporal` for `width`×`height` frames (`config->upsample`
/// must be 1: LRD_STATUS_UNSUPPORTED otherwise). History taps are judged by
/// `temporal->rejection_guides`, as in `lrd_flr_denoise_temporal`.
#[cfg(feature = "flr")]
#[no_mangle]
pub unsafe extern "C" fn lrd_gpu_temporal_dispatch(
    config: *const LrdFlrConfig,
    temporal: *const crate::temporal::LrdTemporalConfig,
    width: u32,
    height: u32,
    out: *mut LrdGpuTemporalDispatch,
) -> LrdStatus {
    use lrdenoise_core::flr::gpu::InputFormat;
    use lrdenoise_core::temporal::gpu::GpuTemporalPlan;
    guard(|| {
        // SAFETY: checked for NULL; the caller passes a valid config pointer.
        let c = unsafe { config.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
        let (t, reject) = crate::temporal::temporal_config_and_rejection(temporal)?;
        let cfg = crate::flr::config(c)?;
        if cfg.upsample != 1 {
            return Err(LRD_STATUS_UNSUPPORTED);
        }
        let reject = reject.unwrap_or(cfg.guides);
        let plan = GpuTemporalPlan::with_rejection_guides(t, cfg.guides, reject, width as usize, height as usize).map_err(status_of)?;
        let flr = flr_dispatch(lrdenoise_core::FlrConfig { fireflies: None, ..cfg }, width, height, InputFormat::F32)?;
        let pass = |p: lrdenoise_core::temporal::gpu::TemporalPass| LrdGpuPass { entry: p.entry.as_ptr(), workgroups: p.workgroups };
        let first = plan.params(0, cfg.fireflies, cfg.clamp_negative).map_err(status_of)?;
        let later = plan.params(1, cfg.fireflies, cfg.clamp_negative).map_err(status_of)?;
        let mut d = LrdGpuTemporalDispatch {
            flr,
            before: plan.passes_before().map(pass),
            after: pass(plan.pass_after()),
            buffer_bytes: plan.buffers().map(|b| b.bytes),
            motion_offset: plan.motion_offset(),
            work_guides: plan.work_guides().map(|o| o.unwrap_or(u64::MAX)),
            cut_limit: later.cut_limit,
            params_first: [0; 112],
            params: [0; 112],
        };
        d.params_first.copy_from_slice(first.as_bytes());
        d.params.copy_from_slice(later.as_bytes());
        // SAFETY: checked for NULL; the caller passes a valid pointer.
        *unsafe { out.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = d;
        Ok(())
    })
}

/// The temporal stage's WGSL shader module (static, NUL-terminated).
#[no_mangle]
pub extern "C" fn lrd_gpu_temporal_wgsl() -> *const c_char {
    concat!(include_str!("../../src/temporal/temporal.wgsl"), "\0").as_ptr() as *const c_char
}
