//! FLR: its configuration, the whole-frame entry point and the tiled API
//! (`lrd_flr_run_tile` and its sizes).

use crate::executor::{self, LrdExecutor};
use crate::images::{
    check_output_disjoint, check_scratch, frame_and_out, frame_views, guide_set, images, view_mut, LrdFrame, LrdImage, LrdImageMut,
    LRD_GUIDE_AO, LRD_GUIDE_DEPTH, LRD_GUIDE_NORMAL,
};
use crate::status::{guard, status_of, write_report, LrdReport, LrdStatus, LrdStatus::*};
use crate::temporal::{
    denoise_temporal, temporal_config_and_rejection, temporal_parallel_sizes, temporal_sizes, LrdHistory, LrdTemporalConfig,
};
use core::ffi::c_void;
use lrdenoise_core::flr::moment_history::MomentFlr;
use lrdenoise_core::flr::temporal::TemporalFlr;
use lrdenoise_core::{Blur, Flr, FlrConfig, Kernel, Regularization};

/// Window shape.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LrdBlur {
    /// One Gaussian window of standard deviation `sigma`, truncated at
    /// `radius` (< 0: 3·sigma).
    LRD_BLUR_GAUSSIAN = 0,
    /// A box of half-width `radius` (≥ 0; the guided filter's window).
    LRD_BLUR_BOX = 1,
    /// Three Gaussian windows (`sigmas`) blended per cell; whole frame or
    /// tiled (the tiled run then needs LRD_STAGE_BLEND).
    LRD_BLUR_ADAPTIVE = 2,
}

/// Regulariser.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LrdRegularization {
    /// Normalized-correlation regularized inverse (eqs. 12–23): eps_mul = ε, eps_add = ϵ.
    LRD_REGULARIZATION_NORMALIZED = 0,
    /// Tikhonov (eq. 11): eps_add = ε; guides used as given.
    LRD_REGULARIZATION_TIKHONOV = 1,
}

/// FLR configuration. Start from `lrd_flr_config_default()`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdFlrConfig {
    /// Bit set of LRD_GUIDE_*.
    pub guides: u32,
    /// Number of single-channel user guides (0..4).
    pub user_guides: u32,
    /// Block size: 1, 2, 4, 8 or 16.
    pub block: u32,
    /// LrdBlur.
    pub blur: u32,
    /// Gaussian sigma in full-resolution pixels.
    pub sigma: f32,
    /// Window radius in full-resolution pixels (Gaussian: < 0 means 3·sigma).
    pub radius: f32,
    /// LRD_BLUR_ADAPTIVE: the three window sigmas, increasing (full-resolution pixels).
    pub sigmas: [f32; 3],
    /// LrdRegularization.
    pub regularization: u32,
    /// LRD_REGULARIZATION_NORMALIZED: ε, the multiplicative regulariser, in
    /// [0, 1) (default 1e-3). Ignored by LRD_REGULARIZATION_TIKHONOV.
    pub eps_mul: f64,
    /// LRD_REGULARIZATION_NORMALIZED: ϵ, the additive regulariser, in [0, 1)
    /// and not 0 together with `eps_mul` (default 1e-2).
    /// LRD_REGULARIZATION_TIKHONOV: ε added to the diagonal, > 0.
    pub eps_add: f64,
    /// 1, 2 or 4 (joint denoise + upsample).
    pub upsample: u32,
    /// Clamp negative output to 0.
    pub clamp_negative: bool,
    /// Use the portable scalar kernels (testing).
    pub scalar_kernels: bool,
    /// LRD_BLUR_ADAPTIVE with LRD_GUIDE_AO: also fit the smallest window
    /// without AO and blend it as a fourth candidate (off by default; see
    /// `FlrConfig::adaptive_without_ao`), on the CPU and the GPU path.
    pub adaptive_without_ao: bool,
    /// With LRD_GUIDE_AO and the normalized regularization: the offset c of
    /// the AO demodulation (the noisy light divided by sqrt(ao + c) before the
    /// fit, the output multiplied back; see `FlrConfig::ao_demodulation`);
    /// 0 turns it off. Default 0.1 (`lrd_flr_config_default`).
    pub ao_demodulation: f32,
    /// The firefly clamp's threshold factor k (>= 1): a noisy sample whose
    /// luminance exceeds k times the larger of the third brightest 8x8
    /// cell of its 104x8-pixel neighbourhood and that neighbourhood's mean
    /// without its brightest cell is scaled down to that level before the fit
    /// (see the core's `fireflies` module); 0 turns it off. Default 1.5.
    pub fireflies: f32,
}

/// Stages of a tiled FLR run, numbered in the order they run (the core's
/// `flr::Stage`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LrdStage {
    /// One tile (tile 0): starts a frame, picks per-frame references.
    LRD_STAGE_PREPARE = 0,
    /// `tile_count` tiles: block moments (uses a worker buffer).
    LRD_STAGE_MOMENTS = 1,
    /// One tile (tile 0): frame statistics.
    LRD_STAGE_STATS = 2,
    /// `tile_count` tiles: horizontal blur.
    LRD_STAGE_BLUR_ROWS = 3,
    /// `tile_count` tiles: vertical blur and per-cell solve.
    LRD_STAGE_BLUR_COLS_SOLVE = 4,
    /// `tile_count` tiles: blends the adaptive window's models
    /// (LRD_BLUR_ADAPTIVE); with one window each tile returns at once, but
    /// the stage still runs: APPLY needs it completed.
    LRD_STAGE_BLEND = 5,
    /// `tile_count` tiles: apply the models to the output rows (uses a worker buffer).
    LRD_STAGE_APPLY = 6,
}

const _: () = {
    use lrdenoise_core::Stage;
    assert!(LrdStage::LRD_STAGE_PREPARE as usize == Stage::Prepare.index());
    assert!(LrdStage::LRD_STAGE_MOMENTS as usize == Stage::Moments.index());
    assert!(LrdStage::LRD_STAGE_STATS as usize == Stage::Stats.index());
    assert!(LrdStage::LRD_STAGE_BLUR_ROWS as usize == Stage::BlurRows.index());
    assert!(LrdStage::LRD_STAGE_BLUR_COLS_SOLVE as usize == Stage::BlurColsSolve.index());
    assert!(LrdStage::LRD_STAGE_BLEND as usize == Stage::Blend.index());
    assert!(LrdStage::LRD_STAGE_APPLY as usize == Stage::Apply.index());
    assert!(Stage::ALL.len() == 7);
};

pub(crate) fn config(c: &LrdFlrConfig) -> Result<FlrConfig, LrdStatus> {
    let guides = guide_set(c.guides, c.user_guides)?;
    let blur = match c.blur {
        0 => Blur::Gaussian { sigma: c.sigma, radius: (c.radius >= 0.0).then_some(c.radius) },
        1 => Blur::Box { radius: c.radius },
        2 => Blur::Adaptive { sigmas: c.sigmas },
        _ => return Err(LRD_STATUS_INVALID_CONFIG),
    };
    let regularization = match c.regularization {
        0 => Regularization::Normalized { eps_mul: c.eps_mul, eps_add: c.eps_add },
        1 => Regularization::Tikhonov { eps: c.eps_add },
        _ => return Err(LRD_STATUS_INVALID_CONFIG),
    };
    let cfg = FlrConfig {
        guides,
        block: c.block as usize,
        blur,
        regularization,
        upsample: c.upsample as usize,
        clamp_negative: c.clamp_negative,
        kernel: if c.scalar_kernels { Kernel::Scalar } else { Kernel::Simd },
        adaptive_without_ao: c.adaptive_without_ao,
        ao_demodulation: (c.ao_demodulation != 0.0).then_some(c.ao_demodulation),
        fireflies: (c.fireflies != 0.0).then_some(c.fireflies),
    };
    cfg.validate().map_err(status_of)?;
    Ok(cfg)
}

fn plan(c: *const LrdFlrConfig, width: u32, height: u32) -> Result<Flr, LrdStatus> {
    // SAFETY: checked for NULL; the caller passes a valid config pointer.
    let c = unsafe { c.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
    Flr::new(config(c)?, width as usize, height as usize).map_err(status_of)
}

/// Bytes of a whole-frame run's scratch: the core's [`Flr::scratch_len`].
fn scratch_bytes(flr: &Flr) -> Result<usize, LrdStatus> {
    flr.scratch_len().checked_mul(8).ok_or(LRD_STATUS_INVALID_ARGUMENT)
}

/// Bytes of a tiled run's scratch: the core's [`Flr::tiled_scratch_len`].
fn tiled_scratch_bytes(flr: &Flr, workers: usize) -> Result<usize, LrdStatus> {
    flr.tiled_scratch_len(workers).and_then(|n| n.checked_mul(8)).ok_or(LRD_STATUS_INVALID_ARGUMENT)
}

/// The default FLR configuration (normal + depth + AO, B = 8, the adaptive window
/// LRD_BLUR_ADAPTIVE with sigmas 6/12/20 (`sigma` = 12 for LRD_BLUR_GAUSSIAN), normalized 1e-3/1e-2).
#[no_mangle]
pub extern "C" fn lrd_flr_config_default() -> LrdFlrConfig {
    lrd_flr_config_of(&FlrConfig::default())
}

/// The defaults for temporal FLR (`lrd_flr_denoise_temporal`): those of
/// `lrd_flr_config_default` with the adaptive window's sigmas at 3/6/12 (light
/// accumulated over frames is less noisy, so smaller windows fit it better).
#[no_mangle]
pub extern "C" fn lrd_flr_config_temporal_default() -> LrdFlrConfig {
    lrd_flr_config_of(&FlrConfig::temporal())
}

/// The defaults for temporal FLR on accumulated moments
/// (`lrd_flr_denoise_temporal_moments`): those of `lrd_flr_config_default`
/// with one Gaussian window of sigma 6 and the additive epsilon at 1e-3.
#[no_mangle]
pub extern "C" fn lrd_flr_config_temporal_moments_default() -> LrdFlrConfig {
    lrd_flr_config_of(&FlrConfig::temporal_moments())
}

/// The C form of the default-guide configuration `d`.
fn lrd_flr_config_of(d: &FlrConfig) -> LrdFlrConfig {
    let (blur, sigma, radius, sigmas) = match d.blur {
        Blur::Gaussian { sigma, radius } => (LrdBlur::LRD_BLUR_GAUSSIAN, sigma, radius.unwrap_or(-1.0), [0.0; 3]),
        Blur::Box { radius } => (LrdBlur::LRD_BLUR_BOX, 0.0, radius, [0.0; 3]),
        Blur::Adaptive { sigmas } => (LrdBlur::LRD_BLUR_ADAPTIVE, sigmas[1], -1.0, sigmas),
    };
    let (eps_mul, eps_add) = match d.regularization {
        Regularization::Normalized { eps_mul, eps_add } => (eps_mul, eps_add),
        Regularization::Tikhonov { eps } => (0.0, eps),
    };
    LrdFlrConfig {
        guides: LRD_GUIDE_NORMAL | LRD_GUIDE_DEPTH | LRD_GUIDE_AO,
        user_guides: 0,
        block: d.block as u32,
        blur: blur as u32,
        sigma,
        radius,
        sigmas,
        regularization: LrdRegularization::LRD_REGULARIZATION_NORMALIZED as u32,
        eps_mul,
        eps_add,
        upsample: 1,
        clamp_negative: d.clamp_negative,
        scalar_kernels: false,
        adaptive_without_ao: d.adaptive_without_ao,
        ao_demodulation: d.ao_demodulation.unwrap_or(0.0),
        fireflies: d.fireflies.unwrap_or(0.0),
    }
}

/// Scratch bytes `lrd_flr_denoise` needs for `width`×`height` output frames.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_scratch_size(config: *const LrdFlrConfig, width: u32, height: u32, bytes: *mut usize) -> LrdStatus {
    guard(|| {
        let flr = plan(config, width, height)?;
        let b = scratch_bytes(&flr)?;
        // SAFETY: checked for NULL; caller passes a valid pointer.
        *unsafe { bytes.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = b;
        Ok(())
    })
}

/// Scratch bytes for a tiled run with `workers` concurrent workers.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_tiled_scratch_size(
    config: *const LrdFlrConfig,
    width: u32,
    height: u32,
    workers: u32,
    bytes: *mut usize,
) -> LrdStatus {
    guard(|| {
        let flr = plan(config, width, height)?;
        if workers == 0 {
            return Err(LRD_STATUS_INVALID_ARGUMENT);
        }
        let b = tiled_scratch_bytes(&flr, workers as usize)?;
        // SAFETY: checked for NULL; caller passes a valid pointer.
        *unsafe { bytes.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = b;
        Ok(())
    })
}

/// Number of tiles of each tiled stage (MOMENTS, BLUR_ROWS, BLUR_COLS_SOLVE, BLEND, APPLY).
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_tile_count(config: *const LrdFlrConfig, width: u32, height: u32, count: *mut u32) -> LrdStatus {
    guard(|| {
        let flr = plan(config, width, height)?;
        // SAFETY: checked for NULL; caller passes a valid pointer.
        *unsafe { count.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = flr.tile_count() as u32;
        Ok(())
    })
}

/// Denoises one frame on the calling thread. `out` (3 channels) sets the
/// output size; the noisy image is `out` size / upsample (rounded up).
/// `scratch` must be 8-byte aligned and at least `lrd_flr_scratch_size` bytes.
/// `report` may be NULL; otherwise the run's counts are added to it.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_denoise(
    config: *const LrdFlrConfig,
    frame: *const LrdFrame,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    report: *mut LrdReport,
) -> LrdStatus {
    guard(|| {
        // SAFETY: the caller passes valid (or NULL) pointers.
        let (frame, out) = unsafe { frame_and_out(frame, out)? };
        let flr = plan(config, out.width, out.height)?;
        check_scratch(scratch)?;
        let needed = self::scratch_bytes(&flr)?;
        if scratch_bytes < needed {
            return Err(LRD_STATUS_BUFFER_TOO_SMALL);
        }
        check_output_disjoint(out, frame, &[(scratch as usize, scratch_bytes)])?;
        // SAFETY: the caller's frame images satisfy the LrdImage contract; the
        // scratch is aligned and at least `needed` bytes; `out` is exclusively ours.
        let r = unsafe {
            let f = frame_views(frame, true)?;
            let s = core::slice::from_raw_parts_mut(scratch as *mut f64, needed / 8);
            let mut o = view_mut(out, 0, out.height as usize)?;
            flr.denoise(&f, s, &mut o).map_err(status_of)?
        };
        write_report(report, r);
        Ok(())
    })
}

/// lrd_flr_denoise with the tiles run on the caller's threads (`executor`,
/// see LrdExecutor); bit-identical to it. `scratch` (8-byte aligned) must
/// hold at least `lrd_flr_tiled_scratch_size(.., executor->workers, ..)`
/// bytes, and `out` rows that do not overlap in memory (planar outputs return
/// LRD_STATUS_UNSUPPORTED). For a job system that cannot take a `for_each`
/// call, lrd_flr_run_tile gives the same run stage by stage.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_denoise_parallel(
    config: *const LrdFlrConfig,
    frame: *const LrdFrame,
    out: *const LrdImageMut,
    scratch: *mut c_void,
    scratch_bytes: usize,
    executor: *const LrdExecutor,
    report: *mut LrdReport,
) -> LrdStatus {
    guard(|| {
        // SAFETY: the caller passes valid (or NULL) pointers.
        let (frame, out) = unsafe { frame_and_out(frame, out)? };
        let flr = plan(config, out.width, out.height)?;
        // SAFETY: the caller passes a valid (or NULL) executor.
        let ex = unsafe { executor::checked(executor)? };
        let workers = ex.workers as usize;
        check_scratch(scratch)?;
        let needed = tiled_scratch_bytes(&flr, workers)?;
        if scratch_bytes < needed {
            return Err(LRD_STATUS_BUFFER_TOO_SMALL);
        }
        check_output_disjoint(out, frame, &[(scratch as usize, scratch_bytes)])?;
        // SAFETY: the caller's frame images satisfy the LrdImage contract; the
        // scratch is aligned and at least `needed` bytes; `out` is exclusively
        // ours; the executor keeps LrdExecutor's contract.
        let r = unsafe {
            let f = frame_views(frame, true)?;
            let s = core::slice::from_raw_parts_mut(scratch as *mut f64, needed / 8);
            let mut o = view_mut(out, 0, out.height as usize)?;
            if !o.rows_are_separable() {
                return Err(LRD_STATUS_UNSUPPORTED);
            }
            executor::run(&ex, |for_each| flr.denoise_parallel(&f, s, &mut o, workers, for_each))?.map_err(status_of)?
        };
        write_report(report, r);
        Ok(())
    })
}

/// Runs one tile of one stage of a tiled FLR run.
///
/// Rules (they make concurrent calls safe; breaking one returns a status):
/// - every call of a frame passes the same config, frame, out, scratch (8-byte
///   aligned, at least `lrd_flr_tiled_scratch_size(.., workers, ..)` bytes) and `workers`;
/// - a frame starts with PREPARE, which must not run while another call on
///   the same scratch is in flight; then the stages run in their numeric
///   order, every tile of each once: PREPARE, MOMENTS, STATS, BLUR_ROWS,
///   BLUR_COLS_SOLVE, BLEND, APPLY (`lrd_flr_stage_tile_count` tiles each);
///   a stage's tiles may start only when every tile of the stage before has
///   returned OK (a barrier);
/// - tiles of one stage may run concurrently if each concurrent call passes a
///   different `worker` in [0, workers);
/// - APPLY needs an output whose rows do not overlap in memory (e.g. interleaved
///   RGB/RGBA); planar outputs return LRD_STATUS_UNSUPPORTED (use lrd_flr_denoise);
/// - `out` must not overlap the noisy image, a guide or the scratch, and its
///   pixels must not share memory (LRD_STATUS_INVALID_ARGUMENT otherwise).
///
/// The scratch records the frame's progress: a tile run before PREPARE, before
/// the stage ahead of it completed, a second time, on a busy worker, or with
/// other arguments than the frame's PREPARE returns LRD_STATUS_STAGE_ORDER and
/// writes nothing. The result is bit-identical to lrd_flr_denoise. An unknown
/// stage, a tile or worker index out of range and `workers` = 0 return
/// LRD_STATUS_INVALID_TILE. `report` may be NULL; give concurrent calls
/// distinct reports and sum them.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_run_tile(
    config: *const LrdFlrConfig,
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
        let flr = plan(config, out.width, out.height)?;
        let (workers, tile, worker) = (workers as usize, tile as usize, worker as usize);
        let stage = lrdenoise_core::Stage::from_index(stage as usize).ok_or(LRD_STATUS_INVALID_TILE)?;
        if workers == 0 || worker >= workers || tile >= flr.stage_tiles(stage) {
            return Err(LRD_STATUS_INVALID_TILE);
        }
        check_scratch(scratch)?;
        if scratch_bytes < tiled_scratch_bytes(&flr, workers)? {
            return Err(LRD_STATUS_BUFFER_TOO_SMALL);
        }
        check_output_disjoint(out, frame, &[(scratch as usize, scratch_bytes)])?;
        let key = call_key(frame, out, scratch);
        // SAFETY: the scratch is 8-byte aligned and `scratch_bytes` long
        // (checked); under the documented rules every call on it goes through
        // a `Tiled` of this plan, and `Tiled::run` refuses the calls that would
        // race. The images satisfy the LrdImage contract (caller); the output
        // band is this tile's rows, which no other APPLY tile writes.
        let rep = unsafe {
            let tiled = flr.tiled_raw(scratch as *mut f64, scratch_bytes / 8, workers, key).map_err(status_of)?;
            let f = frame_views(frame, true)?;
            let cf = flr.check_frame(&f).map_err(status_of)?;
            if stage == lrdenoise_core::Stage::Apply {
                let (y0, y1) = flr.tile_pixel_rows(tile).map_err(status_of)?;
                if !view_mut(out, 0, out.height as usize)?.rows_are_separable() {
                    return Err(LRD_STATUS_UNSUPPORTED);
                }
                let mut band = view_mut(out, y0, y1 - y0)?;
                tiled.run(&cf, stage, tile, worker, Some(&mut band)).map_err(status_of)?
            } else {
                tiled.run(&cf, stage, tile, worker, None).map_err(status_of)?
            }
        };
        write_report(report, rep);
        Ok(())
    })
}

/// Tiles of `stage` (an LrdStage) in a tiled run: 1 for PREPARE and STATS,
/// `lrd_flr_tile_count` for the others.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_stage_tile_count(
    config: *const LrdFlrConfig,
    width: u32,
    height: u32,
    stage: u32,
    count: *mut u32,
) -> LrdStatus {
    guard(|| {
        let flr = plan(config, width, height)?;
        let stage = lrdenoise_core::Stage::from_index(stage as usize).ok_or(LRD_STATUS_INVALID_TILE)?;
        let n = u32::try_from(flr.stage_tiles(stage)).map_err(|_| LRD_STATUS_INVALID_ARGUMENT)?;
        // SAFETY: checked for NULL; caller passes a valid pointer.
        *unsafe { count.as_mut() }.ok_or(LRD_STATUS_NULL_POINTER)? = n;
        Ok(())
    })
}

/// FNV-1a over the frame's and the output's descriptions and the scratch
/// address: a tiled call whose arguments differ from its frame's PREPARE gets
/// another key and is refused. (Fields one by one: the structs' padding
/// bytes are not the caller's to define.)
fn call_key(frame: &LrdFrame, out: &LrdImageMut, scratch: *mut c_void) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut add = |v: u64| {
        for b in v.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    let mut image = |d: usize, f: u32, w: u32, hh: u32, s: [usize; 3]| {
        for v in [d as u64, u64::from(f) | u64::from(w) << 32, u64::from(hh), s[0] as u64, s[1] as u64, s[2] as u64] {
            add(v);
        }
    };
    for (i, _) in images(frame) {
        image(i.data as usize, i.format, i.width, i.height, [i.pixel_stride, i.row_stride, i.channel_stride]);
    }
    image(out.data as usize, out.format, out.width, out.height, [out.pixel_stride, out.row_stride, out.channel_stride]);
    image(scratch as usize, 0, 0, 0, [0; 3]);
    h
}

fn temporal_plan(c: *const LrdFlrConfig, t: *const LrdTemporalConfig, width: u32, height: u32) -> Result<TemporalFlr, LrdStatus> {
    // SAFETY: checked for NULL; the caller passes a valid config pointer.
    let c = unsafe { c.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
    let (t, reject) = temporal_config_and_rejection(t)?;
    let plan = TemporalFlr::new(config(c)?, t, width as usize, height as usize).map_err(status_of)?;
    match reject {
        Some(guides) => plan.with_rejection_guides(guides).map_err(status_of),
        None => Ok(plan),
    }
}

fn moments_plan(c: *const LrdFlrConfig, t: *const LrdTemporalConfig, width: u32, height: u32) -> Result<MomentFlr, LrdStatus> {
    // SAFETY: checked for NULL; the caller passes a valid config pointer.
    let c = unsafe { c.as_ref() }.ok_or(LRD_STATUS_NULL_POINTER)?;
    let (t, reject) = temporal_config_and_rejection(t)?;
    if reject.is_some() {
        // the moments judge history by the fit's own normal and depth
        return Err(LRD_STATUS_INVALID_CONFIG);
    }
    MomentFlr::new(config(c)?, &t, width as usize, height as usize).map_err(status_of)
}

/// Scratch and history bytes of temporal FLR on accumulated moments
/// (`lrd_flr_denoise_temporal_moments`) for `width`x`height` frames.
/// `config->guides` must hold the normal and `config->upsample` must be 1.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_temporal_moments_sizes(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
    width: u32,
    height: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_sizes(moments_plan(config, temporal, width, height)?, scratch_bytes, history_bytes))
}

/// One frame of temporal FLR on accumulated moments, on the calling thread:
/// FLR's block moments are blended with the previous frames' (reprojected
/// per cell of `config->block` pixels with `motion`, a cell's history kept
/// where its mean normal and depth match) and FLR is fitted on the sums;
/// about 1.1-1.5x FLR's time (`docs/PERFORMANCE.md`), below
/// `lrd_flr_denoise_temporal`'s quality. Of `temporal` it reads
/// `max_history`, `cut_fraction` and `lag_sigmas` (every field is validated);
/// `temporal->rejection_guides` must be 0 and `frame.sample_weights` absent. `motion`, `history`, `scratch`,
/// `report` and the frame are as for `lrd_flr_denoise_temporal`, with the
/// sizes from `lrd_flr_temporal_moments_sizes`.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_flr_denoise_temporal_moments(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
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
        denoise_temporal(
            |w, h| moments_plan(config, temporal, w, h),
            frame,
            motion,
            history,
            out,
            scratch,
            scratch_bytes,
            core::ptr::null(),
            report,
        )
    })
}

/// Scratch bytes of `lrd_flr_denoise_temporal_moments_parallel` with
/// `workers` workers, and history bytes (those of
/// `lrd_flr_temporal_moments_sizes`: one history serves both calls).
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_temporal_moments_parallel_sizes(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
    width: u32,
    height: u32,
    workers: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_parallel_sizes(moments_plan(config, temporal, width, height)?, workers, scratch_bytes, history_bytes))
}

/// lrd_flr_denoise_temporal_moments with the tiles run on the caller's
/// threads (`executor`, see LrdExecutor); bit-identical to it. The scratch
/// size is from `lrd_flr_temporal_moments_parallel_sizes` with
/// `executor->workers`; `out` needs rows that do not overlap in memory.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_flr_denoise_temporal_moments_parallel(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
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
        denoise_temporal(|w, h| moments_plan(config, temporal, w, h), frame, motion, history, out, scratch, scratch_bytes, executor, report)
    })
}

/// Scratch and history bytes of temporal FLR (`lrd_flr_denoise_temporal`)
/// for `width`x`height` frames. `config->upsample` must be 1.
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_temporal_sizes(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
    width: u32,
    height: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_sizes(temporal_plan(config, temporal, width, height)?, scratch_bytes, history_bytes))
}

/// One frame of temporal FLR on the calling thread: the noisy light is
/// firefly-clamped, accumulated over the valid history (reprojected with
/// `motion`, rejected by normal and position or depth), fitted by FLR, and
/// blended with the clipped previous output. `motion` (2 channels: previous
/// minus current pixel position) may be NULL, or have `data == NULL`, for a
/// static camera. `history` is read and advanced; `history->data` and
/// `scratch` (8-byte aligned) must hold at least the sizes from
/// `lrd_flr_temporal_sizes` with the same configs and size. The frame's guides
/// are those of `config->guides`; `frame.guides_low` must be absent.
/// `report` may be NULL; otherwise the run's counts are added to it
/// (`history_resets` counts frames taken as a camera cut).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_flr_denoise_temporal(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
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
        denoise_temporal(
            |w, h| temporal_plan(config, temporal, w, h),
            frame,
            motion,
            history,
            out,
            scratch,
            scratch_bytes,
            core::ptr::null(),
            report,
        )
    })
}

/// Scratch bytes of `lrd_flr_denoise_temporal_parallel` with `workers`
/// workers, and history bytes (those of `lrd_flr_temporal_sizes`).
#[no_mangle]
pub unsafe extern "C" fn lrd_flr_temporal_parallel_sizes(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
    width: u32,
    height: u32,
    workers: u32,
    scratch_bytes: *mut usize,
    history_bytes: *mut usize,
) -> LrdStatus {
    guard(|| temporal_parallel_sizes(temporal_plan(config, temporal, width, height)?, workers, scratch_bytes, history_bytes))
}

/// lrd_flr_denoise_temporal with the tiles run on the caller's threads
/// (`executor`, see LrdExecutor); bit-identical to it. The scratch size is
/// from `lrd_flr_temporal_parallel_sizes` with `executor->workers`; `out`
/// needs rows that do not overlap in memory.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn lrd_flr_denoise_temporal_parallel(
    config: *const LrdFlrConfig,
    temporal: *const LrdTemporalConfig,
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
        denoise_temporal(
            |w, h| temporal_plan(config, temporal, w, h),
            frame,
            motion,
            history,
            out,
            scratch,
            scratch_bytes,
            executor,
            report,
        )
    })
}
