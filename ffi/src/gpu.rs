//! FLR's GPU path: the dispatch description of a configuration
//! (`lrd_gpu_dispatch`) and the WGSL shader module (`lrd_gpu_wgsl`).

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
    use lrdenoise_core::flr::gpu::{GpuLayouts, GpuPlan, InputFormat};
    guard(|| {
        let input = match input_format {
            0 => InputFormat::F32,
            1 => InputFormat::F16,
            _ => return Err(LRD_STATUS_INVALID_ARGUMENT),
        };
        // SAFETY: checked for NULL; the caller passes a valid config pointer.
        let c = unsafe { config.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
        let (w, h) = (width as usize, height as usize);
        let plan = GpuPlan::new(crate::flr::config(c)?, w, h).map_err(status_of)?;
        let layouts = if c.upsample > 1 {
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
        // SAFETY: checked for NULL; caller passes a valid pointer.
        *unsafe { out.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = d;
        Ok(())
    })
}

/// FLR's WGSL shader module (static, NUL-terminated).
#[no_mangle]
pub extern "C" fn lrd_gpu_wgsl() -> *const c_char {
    concat!(include_str!("../../src/flr/flr.wgsl"), "\0").as_ptr() as *const c_char
}
