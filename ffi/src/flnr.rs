//! FLNR (FLR with guides written by a network): the whole-frame entry point
//! and the threaded run (`lrd_flnr_run_tile`, its stages and sizes).

use crate::images::{check_output_disjoint, check_scratch, frame_and_out, frame_views, view_mut, LrdFrame, LrdImageMut};
use crate::status::{guard, status_of, write_report, LrdReport, LrdStatus, LrdStatus::*};
use core::ffi::c_void;
use lrdenoise_core::flnr::{Flnr, FlnrConfig};
use std::sync::atomic::{AtomicU64, Ordering};

/// Stages of a threaded FLNR run (`lrd_flnr_run_tile`), in order.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LrdFlnrStage {
    /// One tile (tile 0): checks the frame, measures the network's input scales
    /// and, for networks that read it, runs the prior (FLR's defaults).
    LRD_FLNR_STAGE_PREPARE = 0,
    /// `lrd_flnr_tile_count` tiles: the network on one tile (nearly all of the
    /// time; tiles may run concurrently, each call with its own `worker`).
    LRD_FLNR_STAGE_NETWORK = 1,
    /// One tile (tile 0): FLR with the learned guides, into `out`.
    LRD_FLNR_STAGE_FLR = 2,
}

/// FLNR configuration: the network and how it runs. Start from
/// `lrd_flnr_config_default(weights, weights_bytes)`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdFlnrConfig {
    /// The weight blob (e.g. the contents of `train/flnr.bin`): read during
    /// each call, not kept after it.
    pub weights: *const u8,
    /// Bytes at `weights`.
    pub weights_bytes: usize,
    /// Network tile edge in pixels (at least 64; 0: the default, 512).
    pub tile: u32,
    /// Firefly clamp factor k of the FLR fit with the learned guides (as
    /// `LrdFlrConfig::fireflies`: finite, ≥ 1); 0 turns it off. Default 1.5. The network
    /// reads the light unclamped (its input, ln(1 + light / mean), already
    /// compresses outliers).
    pub fireflies: f32,
}

/// The default FLNR configuration for the network `weights` (`weights_bytes`
/// bytes): the default tile and firefly clamp.
#[no_mangle]
pub extern "C" fn lrd_flnr_config_default(weights: *const u8, weights_bytes: usize) -> LrdFlnrConfig {
    let d = FlnrConfig::new(&[]);
    LrdFlnrConfig { weights, weights_bytes, tile: d.tile as u32, fireflies: d.fireflies.unwrap_or(0.0) }
}

/// The network of `config` planned for `width`×`height` frames.
fn flnr_plan<'w>(config: *const LrdFlnrConfig, width: u32, height: u32) -> Result<Flnr<'w>, LrdStatus> {
    // SAFETY: checked for NULL; the caller passes a valid config pointer.
    let c = unsafe { config.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
    if c.weights.is_null() {
        return Err(LRD_STATUS_NULL_POINTER);
    }
    // SAFETY: the caller passes `weights_bytes` readable bytes at `weights`,
    // unchanged for the duration of the call (the header's contract).
    let blob = unsafe { core::slice::from_raw_parts(c.weights, c.weights_bytes) };
    let tile = if c.tile == 0 { lrdenoise_core::flnr::DEFAULT_TILE } else { c.tile as usize };
    let fireflies = (c.fireflies != 0.0).then_some(c.fireflies);
    Flnr::new(FlnrConfig { weights: blob, tile, fireflies }, width as usize, height as usize).map_err(status_of)
}

/// Byte offsets of a threaded FLNR scratch: the header (input scales), FLR's
/// f64 scratch, the learned guide planes, the prior's planes (networks of 11
/// inputs), then one network scratch per worker.
struct FlnrLayout {
    flr: usize,
    planes: usize,
    prior: usize,
    workers: usize,
    worker: usize,
    total: usize,
}

fn flnr_layout(fl: &Flnr<'_>, workers: usize) -> Result<FlnrLayout, LrdStatus> {
    let big = LRD_STATUS_INVALID_ARGUMENT;
    let flr = HEADER;
    let planes = fl.flr_scratch_len().checked_mul(8).and_then(|b| b.checked_add(flr)).ok_or(big)?;
    let worker_bytes = fl.tile_scratch_len().checked_mul(4).ok_or(big)?;
    let prior = fl.guide_planes_len().checked_mul(4).and_then(|b| b.checked_add(planes)).ok_or(big)?;
    let first_worker = fl.prior_len().checked_mul(4).and_then(|b| b.checked_add(prior)).ok_or(big)?;
    let total = worker_bytes.checked_mul(workers).and_then(|b| b.checked_add(first_worker)).ok_or(big)?;
    Ok(FlnrLayout { flr, planes, prior, workers: first_worker, worker: worker_bytes, total })
}

/// Bytes at the start of a threaded FLNR scratch: the marker, the input
/// scales and the count of NETWORK tiles done.
const HEADER: usize = 256;

/// Marks a header whose input scales the PREPARE stage wrote.
const FLNR_PREPARED: u64 = 0x6c72_645f_666c_6e72;

/// Bytes of scratch `lrd_flnr_denoise` needs for `width`×`height` frames with
/// `config`.
#[no_mangle]
pub unsafe extern "C" fn lrd_flnr_scratch_size(config: *const LrdFlnrConfig, width: u32, height: u32, bytes: *mut usize) -> LrdStatus {
    guard(|| {
        let fl = flnr_plan(config, width, height)?;
        let need = fl
            .flr_scratch_len()
            .checked_mul(8)
            .and_then(|a| fl.scratch_len().checked_mul(4).and_then(|b| a.checked_add(b)))
            .ok_or(LRD_STATUS_INVALID_ARGUMENT)?;
        // SAFETY: NULL-checked; the caller passes a valid pointer.
        *unsafe { bytes.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = need;
        Ok(())
    })
}

/// FLNR (FLR with guides written by the network of `config`) on the calling
/// thread. The frame needs normal, depth and AO guides and no `guides_low`;
/// `out` (3 channels) has the frame's size. `scratch`: 8-byte aligned, at
/// least `lrd_flnr_scratch_size` bytes (same config and size). A blob that
/// does not parse, a tile below 64 or a `fireflies` that is neither 0 nor
/// finite and ≥ 1 give LRD_STATUS_INVALID_CONFIG. `report` may be NULL.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_flnr_denoise(
    config: *const LrdFlnrConfig,
    frame: *const LrdFrame,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    report: *mut LrdReport,
) -> LrdStatus {
    guard(|| {
        // SAFETY: the caller passes valid (or NULL) pointers.
        let (frame, out) = unsafe { frame_and_out(frame, out)? };
        let fl = flnr_plan(config, out.width, out.height)?;
        check_scratch(scratch)?;
        let (flr_len, net_len) = (fl.flr_scratch_len(), fl.scratch_len());
        let need = flr_len.checked_mul(8).and_then(|a| net_len.checked_mul(4).and_then(|b| a.checked_add(b)));
        if need.is_none_or(|n| scratch_bytes < n) {
            return Err(LRD_STATUS_BUFFER_TOO_SMALL);
        }
        check_output_disjoint(out, frame, &[(scratch as usize, scratch_bytes)])?;
        // SAFETY: the caller's images satisfy the LrdImage contract; the scratch
        // is 8-byte aligned and holds `flr_len` f64 followed by `net_len` f32
        // (checked above); `out` is exclusively ours for the call.
        let r = unsafe {
            let f = frame_views(frame, false)?;
            let fs = core::slice::from_raw_parts_mut(scratch as *mut f64, flr_len);
            let ns = core::slice::from_raw_parts_mut((scratch as *mut u8).add(flr_len * 8) as *mut f32, net_len);
            let mut o = view_mut(out, 0, out.height as usize)?;
            fl.denoise(&f, ns, fs, &mut o).map_err(status_of)?
        };
        write_report(report, r);
        Ok(())
    })
}

/// Number of network tiles of a threaded FLNR run (LRD_FLNR_STAGE_NETWORK).
#[no_mangle]
pub unsafe extern "C" fn lrd_flnr_tile_count(config: *const LrdFlnrConfig, width: u32, height: u32, count: *mut u32) -> LrdStatus {
    guard(|| {
        let (nx, ny) = flnr_plan(config, width, height)?.tile_grid();
        let n = u32::try_from(nx * ny).map_err(|_| LRD_STATUS_INVALID_ARGUMENT)?;
        // SAFETY: NULL-checked; the caller passes a valid pointer.
        *unsafe { count.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = n;
        Ok(())
    })
}

/// Bytes of scratch a threaded FLNR run with `workers` concurrent network
/// tiles needs (`lrd_flnr_run_tile`).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_flnr_tiled_scratch_size(
    config: *const LrdFlnrConfig,
    width: u32,
    height: u32,
    workers: u32,
    bytes: *mut usize,
) -> LrdStatus {
    guard(|| {
        if workers == 0 {
            return Err(LRD_STATUS_INVALID_ARGUMENT);
        }
        let fl = flnr_plan(config, width, height)?;
        let total = flnr_layout(&fl, workers as usize)?.total;
        // SAFETY: NULL-checked; the caller passes a valid pointer.
        *unsafe { bytes.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = total;
        Ok(())
    })
}

/// Runs one tile of one stage of a threaded FLNR run.
///
/// Rules (they make concurrent calls safe):
/// - every call of a frame passes the same config, frame, out,
///   scratch (8-byte aligned, at least `lrd_flnr_tiled_scratch_size(.., workers, ..)`
///   bytes) and `workers`;
/// - stages run in order PREPARE (tile 0), NETWORK (tiles 0 .. `lrd_flnr_tile_count`),
///   FLR (tile 0); every tile of a stage finishes before the next stage starts;
/// - NETWORK tiles may run concurrently if each concurrent call passes a
///   different `worker` in [0, workers).
///
/// The result is bit-identical to `lrd_flnr_denoise`. An unknown stage, a tile
/// or worker index out of range (checked in every stage) and `workers` = 0
/// return LRD_STATUS_INVALID_TILE; NETWORK before PREPARE on this scratch, and
/// FLR before as many NETWORK tiles as `lrd_flnr_tile_count` have returned OK
/// since PREPARE, return LRD_STATUS_STAGE_ORDER. `report` may be NULL (FLR
/// stage only adds to it).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_flnr_run_tile(
    config: *const LrdFlnrConfig,
    frame: *const LrdFrame,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    workers: u32,
    stage: u32,
    tile: u32,
    worker: u32,
    report: *mut LrdReport,
) -> LrdStatus {
    guard(|| {
        // SAFETY: the caller passes valid (or NULL) pointers.
        let (frame, out) = unsafe { frame_and_out(frame, out)? };
        let fl = flnr_plan(config, out.width, out.height)?;
        check_scratch(scratch)?;
        // As in lrd_flr_run_tile: no worker index is in [0, 0); every stage checks it.
        if workers == 0 || worker >= workers {
            return Err(LRD_STATUS_INVALID_TILE);
        }
        let lay = flnr_layout(&fl, workers as usize)?;
        if scratch_bytes < lay.total {
            return Err(LRD_STATUS_BUFFER_TOO_SMALL);
        }
        check_output_disjoint(out, frame, &[(scratch as usize, scratch_bytes)])?;
        let (nx, ny) = fl.tile_grid();
        let one = |t: u32| if t == 0 { Ok(()) } else { Err(LRD_STATUS_INVALID_TILE) };
        let base = scratch as *mut u8;
        // SAFETY (the whole block): the caller's images satisfy the LrdImage
        // contract; every region below lies inside the checked `lay.total` bytes;
        // the header and planes are written only by the one-tile stages or, for
        // the planes, at the disjoint pixels of each NETWORK tile (through raw
        // pointers, never a `&mut` over the shared planes); a worker's network
        // scratch is used by one call at a time (the rules above).
        unsafe {
            let f = frame_views(frame, false)?;
            let header = base as *mut u64;
            let scale_at = base.add(8) as *mut lrdenoise_core::flnr::InputScale;
            const { assert!(8 + core::mem::size_of::<lrdenoise_core::flnr::InputScale>() <= HEADER - 8) };
            // NETWORK tiles completed since PREPARE (the header's last 8 bytes)
            let networks_done = AtomicU64::from_ptr(base.add(HEADER - 8) as *mut u64);
            let planes = base.add(lay.planes) as *mut f32;
            match stage {
                s if s == LrdFlnrStage::LRD_FLNR_STAGE_PREPARE as u32 => {
                    one(tile)?;
                    let sc = fl.input_scale(&f).map_err(status_of)?;
                    let prior = core::slice::from_raw_parts_mut(base.add(lay.prior) as *mut f32, fl.prior_len());
                    let fs = core::slice::from_raw_parts_mut(base.add(lay.flr) as *mut f64, fl.flr_scratch_len());
                    fl.run_prior(&f, prior, fs).map_err(status_of)?;
                    scale_at.write_unaligned(sc);
                    (*networks_done).store(0, Ordering::Relaxed);
                    header.write(FLNR_PREPARED);
                }
                s if s == LrdFlnrStage::LRD_FLNR_STAGE_NETWORK as u32 => {
                    if tile as usize >= nx * ny {
                        return Err(LRD_STATUS_INVALID_TILE);
                    }
                    if header.read() != FLNR_PREPARED {
                        return Err(LRD_STATUS_STAGE_ORDER);
                    }
                    let sc = scale_at.read_unaligned();
                    let ws =
                        core::slice::from_raw_parts_mut(base.add(lay.workers + worker as usize * lay.worker) as *mut f32, lay.worker / 4);
                    let prior = core::slice::from_raw_parts(base.add(lay.prior) as *const f32, fl.prior_len());
                    let tg = fl.network_tile(&f, sc, prior, tile as usize, ws).map_err(status_of)?;
                    let (r, w, np) = (tg.rect(), out.width as usize, out.width as usize * out.height as usize);
                    for k in 0..tg.plane_count() {
                        for y in r.y0..r.y1 {
                            let src = tg.row(k, y).ok_or(LRD_STATUS_INTERNAL)?;
                            core::ptr::copy_nonoverlapping(src.as_ptr(), planes.add(k * np + y * w + r.x0), src.len());
                        }
                    }
                    (*networks_done).fetch_add(1, Ordering::AcqRel);
                }
                s if s == LrdFlnrStage::LRD_FLNR_STAGE_FLR as u32 => {
                    one(tile)?;
                    if header.read() != FLNR_PREPARED || (*networks_done).load(Ordering::Acquire) != (nx * ny) as u64 {
                        return Err(LRD_STATUS_STAGE_ORDER);
                    }
                    let g = core::slice::from_raw_parts(planes, fl.guide_planes_len());
                    let fs = core::slice::from_raw_parts_mut(base.add(lay.flr) as *mut f64, fl.flr_scratch_len());
                    let lf = fl.flr_frame(&f, g).map_err(status_of)?;
                    let mut o = view_mut(out, 0, out.height as usize)?;
                    let r = fl.flr().denoise(&lf, fs, &mut o).map_err(status_of)?;
                    write_report(report, r);
                }
                // an unknown stage is a stage index out of range (as in lrd_flr_run_tile)
                _ => return Err(LRD_STATUS_INVALID_TILE),
            }
        }
        Ok(())
    })
}
