//! The temporal stage on GPUs: the WGSL compute shaders ([`TEMPORAL_WGSL`])
//! and how to run them around FLR's passes ([`crate::flr::gpu`]), for engines
//! that drive their own graphics API; `lrdenoise-gpu`'s `GpuTemporalFlr`
//! executes the same description with `wgpu`. `no_std`, no allocation.
//!
//! One frame of temporal FLR on the GPU:
//! 1. Once: compile [`TEMPORAL_WGSL`] and FLR's shaders (FLR planned with
//!    [`FlrConfig::fireflies`](crate::FlrConfig) off and f32 planar inputs,
//!    [`crate::flr::gpu::GpuLayouts::planar`]: the stage clamps the light
//!    itself); create the buffers of [`GpuTemporalPlan::buffers`], where
//!    [`TemporalBuffer::Light`], [`TemporalBuffer::Guides`] and
//!    [`TemporalBuffer::Fitted`] are FLR's noisy, guide and output buffers,
//!    and the history is two buffers of one slot each (below).
//! 2. Each frame: upload the noisy light, the guides and the motion (into
//!    the work buffer at [`GpuTemporalPlan::motion_offset`], followed by the
//!    rejection guides FLR does not read, [`GpuTemporalPlan::work_guides`]); upload
//!    [`GpuTemporalPlan::params`] for the frame index; bind the history slots
//!    as [`GpuTemporalPlan::slots`] says (they swap each frame); dispatch
//!    [`GpuTemporalPlan::passes_before`], FLR's passes, then
//!    [`GpuTemporalPlan::pass_after`], with a storage barrier between them;
//!    read the output buffer and, for the counts, the counters
//!    ([`GpuTemporalPlan::counts`]).
//!
//! The history has the CPU stage's layout ([`Reprojection::history_len`]
//! values: slot 0, then slot 1, [`Reprojection::slot_len`] each), held as
//! one buffer per slot so that no binding is larger than a slot (wgpu's
//! default limit on a storage binding is 128 MiB; a 1080p slot with normal
//! and depth is 91 MB). The shaders compute what
//! [`Reprojection::accumulate`] and [`Reprojection::resolve`] compute, pixel
//! by pixel in f32; a compiler that fuses multiplies and adds may round a
//! value differently, and a tap or a sample within rounding of a limit may
//! then be taken on one path and not on the other.

use super::{Counts, Reprojection, TemporalConfig};
use crate::error::Error;
use crate::fireflies;
use crate::guides::GuideSet;

/// The temporal stage's shader module: entry points `t_cells`, `t_taps`,
/// `t_thresholds`, `t_accumulate`, `t_resolve`.
pub const TEMPORAL_WGSL: &str = include_str!("temporal.wgsl");

/// "Absent" in the parameter block's offsets.
const NONE: u32 = u32::MAX;

/// Set in a parameter block's guide offset (`g_normal`, `g_position`,
/// `g_depth`): the planes are in the work buffer, not in FLR's guide buffer.
pub const GUIDE_IN_WORK: u32 = 1 << 31;

/// The uniform parameter block (binding 0), laid out as the WGSL `Params`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuTemporalParams {
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// Firefly-clamp cells per band of 8 rows.
    pub nc: u32,
    /// Bands of 8 rows.
    pub bands: u32,
    /// f32 fields of a pixel's history record.
    pub record: u32,
    /// Record fields of the normal, the position and the depth (`u32::MAX`: absent).
    pub n_at: u32,
    /// See `n_at`.
    pub p_at: u32,
    /// See `n_at`.
    pub d_at: u32,
    /// Element offset of the clamp cells within a slot.
    pub cells_at: u32,
    /// 1 when the read slot holds a previous frame.
    pub has_history: u32,
    /// Element offset of the normal's x plane: in the guide buffer, or with
    /// [`GUIDE_IN_WORK`] set, in the work buffer (`u32::MAX`: absent).
    pub g_normal: u32,
    /// Element offset of the position's x plane, as `g_normal`.
    pub g_position: u32,
    /// Element offset of the depth plane, as `g_normal`.
    pub g_depth: u32,
    /// 1: negative output becomes 0.
    pub clamp_negative: u32,
    /// The firefly clamp's factor `k` (0: off).
    pub fireflies: f32,
    /// [`TemporalConfig::firefly_history`].
    pub firefly_history: f32,
    /// [`TemporalConfig::max_history`].
    pub max_history: f32,
    /// [`TemporalConfig::normal_limit`].
    pub normal_limit: f32,
    /// [`TemporalConfig::position_limit`].
    pub position_limit: f32,
    /// [`TemporalConfig::depth_limit`].
    pub depth_limit: f32,
    /// [`TemporalConfig::clip_gamma`].
    pub clip_gamma: f32,
    /// [`TemporalConfig::output_alpha`].
    pub output_alpha: f32,
    /// A frame with more pixels without history than this is a camera cut.
    pub cut_limit: u32,
    /// Largest motion component taken as a motion vector, in pixels.
    pub max_motion: f32,
    /// Without depth: the squared position limit per squared pixel footprint
    /// (the CPU stage's, from [`TemporalConfig::position_limit`] and the width).
    pub footprint_limit2: f32,
    /// Padding to the WGSL layout; zero.
    pub pad: [u32; 3],
}

// SAFETY: `repr(C)`, 25 four-byte fields and an array of three, no padding
// (112 bytes: checked below); any bit pattern is valid.
unsafe impl bytemuck::Zeroable for GpuTemporalParams {}
// SAFETY: as above.
unsafe impl bytemuck::Pod for GpuTemporalParams {}
const _: () = assert!(core::mem::size_of::<GpuTemporalParams>() == 112);

impl GpuTemporalParams {
    /// The block's bytes, as the uniform buffer holds them.
    pub fn as_bytes(&self) -> &[u8] {
        bytemuck::bytes_of(self)
    }
}

/// The buffers of the temporal bind group, in binding order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TemporalBuffer {
    /// [`GpuTemporalParams`], uniform.
    Params,
    /// The noisy light (3 f32 planes), overwritten with the accumulated
    /// light: FLR's noisy buffer. Read-write storage.
    Light,
    /// FLR's guide buffer (f32 planes in FLR's channel order). Read-only storage.
    Guides,
    /// The history slot the previous frame wrote ([`Reprojection::slot_len`] f32). Read-only storage.
    HistoryIn,
    /// Working space of one frame; the motion, previous − current pixel
    /// position (2 f32 planes, zeros for a static camera), is uploaded into
    /// it at [`GpuTemporalPlan::motion_offset`], and the rejection guides FLR
    /// does not read at [`GpuTemporalPlan::work_guides`]. Read-write.
    Work,
    /// Four u32 counters ([`GpuTemporalPlan::counts`]). Read-write.
    Counters,
    /// FLR's output (3 f32 planes). Read-only storage.
    Fitted,
    /// The stage's output (3 f32 planes). Read-write.
    Output,
    /// The history slot this frame writes ([`Reprojection::slot_len`] f32). Read-write.
    HistoryOut,
}

/// One buffer of the temporal bind group.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TemporalBufferDesc {
    /// Which buffer.
    pub buffer: TemporalBuffer,
    /// Its binding index in group 0.
    pub binding: u32,
    /// How it is bound.
    pub access: crate::flr::gpu::Access,
    /// Minimum size in bytes.
    pub bytes: u64,
}

/// One dispatch of the temporal module.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TemporalPass {
    /// The entry point's name, NUL-terminated.
    pub entry: &'static core::ffi::CStr,
    /// Workgroups along x, y and z.
    pub workgroups: [u32; 3],
}

impl TemporalPass {
    /// The entry point's name.
    pub fn name(&self) -> &'static str {
        self.entry.to_str().unwrap_or("")
    }
}

/// Bytes of the counters buffer.
pub const COUNTERS_BYTES: u64 = 16;

/// Where the stage reads one rejection guide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Source {
    /// FLR's guide buffer, from this channel on.
    Flr(usize),
    /// The work buffer, from this plane after the motion's two.
    Work(usize),
}

/// How to run the temporal stage on a GPU for one frame size, configuration
/// and guide set.
#[derive(Clone, Copy, Debug)]
pub struct GpuTemporalPlan {
    stage: Reprojection,
    /// Where the normal, the position and the depth are read.
    sources: [Option<Source>; 3],
}

impl GpuTemporalPlan {
    /// The plan for `width × height` frames whose guides are `guides`, FLR's:
    /// the stage rejects history with its normal, position and depth. Frames
    /// whose history would not be addressable with 31-bit indices are refused.
    pub fn new(cfg: TemporalConfig, guides: GuideSet, width: usize, height: usize) -> Result<Self, Error> {
        Self::with_rejection_guides(cfg, guides, guides, width, height)
    }

    /// The plan for FLR fitted on `fit` and history taps judged by the normal,
    /// position and depth of `reject` (as
    /// [`TemporalFlr::with_rejection_guides`](crate::flr::temporal::TemporalFlr::with_rejection_guides)):
    /// those FLR does not read are uploaded into the work buffer
    /// ([`GpuTemporalPlan::work_guides`]).
    pub fn with_rejection_guides(cfg: TemporalConfig, fit: GuideSet, reject: GuideSet, width: usize, height: usize) -> Result<Self, Error> {
        let stage = Reprojection::new(cfg, reject, width, height)?;
        // FLR's channel order: normal (3), depth, position (3), AO, user channels
        let in_flr = [(fit.normal, 0), (fit.position, 3 * fit.normal as usize + fit.depth as usize), (fit.depth, 3 * fit.normal as usize)];
        let wanted = [reject.normal, reject.position, reject.depth];
        let mut sources = [None; 3];
        let mut extra = 0;
        for (k, ((flr, channel), want)) in in_flr.into_iter().zip(wanted).enumerate() {
            sources[k] = match (want, flr) {
                (false, _) => None,
                (true, true) => Some(Source::Flr(channel)),
                (true, false) => {
                    let at = extra;
                    extra += [3, 3, 1][k];
                    Some(Source::Work(at))
                }
            };
        }
        let plan = GpuTemporalPlan { stage, sources };
        if plan.stage.history_len() >= GUIDE_IN_WORK as usize || plan.work_len() >= GUIDE_IN_WORK as usize {
            return Err(Error::Unsupported("the GPU temporal stage at this frame size (history beyond 31-bit indices)"));
        }
        Ok(plan)
    }

    /// The CPU stage this plan mirrors (its history length, its counts).
    pub fn stage(&self) -> &Reprojection {
        &self.stage
    }

    /// Planes of rejection guides in the work buffer.
    fn work_guide_planes(&self) -> usize {
        self.sources.iter().zip([3, 3, 1]).map(|(s, n)| if matches!(s, Some(Source::Work(_))) { n } else { 0 }).sum()
    }

    /// f32 values of the work buffer.
    fn work_len(&self) -> usize {
        let (w, h) = (self.stage.width, self.stage.height);
        4 * fireflies::cells(w) * h.div_ceil(fireflies::CELL) + (5 + self.work_guide_planes()) * w * h
    }

    /// Byte offsets in [`TemporalBuffer::Work`] of the normal (3 planes:
    /// x, y, z), the position (3 planes) and the depth (1 plane) where the
    /// stage judges history by them and FLR does not read them (`None`: not
    /// uploaded). They follow the motion's planes, in this order, so the
    /// motion and these are one upload of consecutive planes.
    pub fn work_guides(&self) -> [Option<u64>; 3] {
        let plane = (self.stage.width * self.stage.height) as u64;
        self.sources.map(|s| match s {
            Some(Source::Work(p)) => Some(self.motion_offset() + 4 * plane * (2 + p as u64)),
            _ => None,
        })
    }

    /// Byte offset in [`TemporalBuffer::Work`] of the motion's two planes
    /// (x, then y; `width · height` f32 each).
    pub fn motion_offset(&self) -> u64 {
        let (w, h) = (self.stage.width, self.stage.height);
        4 * (4 * fireflies::cells(w) * h.div_ceil(fireflies::CELL) + 3 * w * h) as u64
    }

    /// The bind group's buffers, in binding order, with their sizes.
    pub fn buffers(&self) -> [TemporalBufferDesc; 9] {
        use crate::flr::gpu::Access::*;
        let plane = (self.stage.width * self.stage.height) as u64;
        let guides = self
            .sources
            .iter()
            .zip([3u64, 3, 1])
            .filter_map(|(s, n)| match s {
                Some(Source::Flr(c)) => Some(*c as u64 + n),
                _ => None,
            })
            .max()
            .unwrap_or(1);
        let f = 4u64;
        let list = [
            (TemporalBuffer::Params, Uniform, core::mem::size_of::<GpuTemporalParams>() as u64),
            (TemporalBuffer::Light, ReadWriteStorage, 3 * plane * f),
            (TemporalBuffer::Guides, ReadOnlyStorage, guides * plane * f),
            (TemporalBuffer::HistoryIn, ReadOnlyStorage, self.stage.slot_len() as u64 * f),
            (TemporalBuffer::Work, ReadWriteStorage, self.work_len() as u64 * f),
            (TemporalBuffer::Counters, ReadWriteStorage, COUNTERS_BYTES),
            (TemporalBuffer::Fitted, ReadOnlyStorage, 3 * plane * f),
            (TemporalBuffer::Output, ReadWriteStorage, 3 * plane * f),
            (TemporalBuffer::HistoryOut, ReadWriteStorage, self.stage.slot_len() as u64 * f),
        ];
        list.map(|(buffer, access, bytes)| TemporalBufferDesc { buffer, binding: buffer as u32, access, bytes })
    }

    /// The passes before FLR's: `t_cells`, `t_taps`, `t_thresholds`, `t_accumulate`.
    pub fn passes_before(&self) -> [TemporalPass; 4] {
        let cells = [self.cells().div_ceil(64) as u32, self.bands() as u32, 1];
        let pixels = self.pixel_groups();
        [
            TemporalPass { entry: c"t_cells", workgroups: cells },
            TemporalPass { entry: c"t_taps", workgroups: pixels },
            TemporalPass { entry: c"t_thresholds", workgroups: cells },
            TemporalPass { entry: c"t_accumulate", workgroups: pixels },
        ]
    }

    /// The pass after FLR's: `t_resolve`.
    pub fn pass_after(&self) -> TemporalPass {
        TemporalPass { entry: c"t_resolve", workgroups: self.pixel_groups() }
    }

    fn cells(&self) -> usize {
        fireflies::cells(self.stage.width)
    }
    fn bands(&self) -> usize {
        self.stage.height.div_ceil(fireflies::CELL)
    }
    fn pixel_groups(&self) -> [u32; 3] {
        [self.stage.width.div_ceil(8) as u32, self.stage.height.div_ceil(8) as u32, 1]
    }

    /// The history slots of the frame whose history holds `frames` frames,
    /// as `(read, write)`: slot 1 is read and slot 0 written when `frames` is
    /// even, as the CPU's [`crate::temporal::History`] does. Bind the buffer
    /// of the read slot as [`TemporalBuffer::HistoryIn`] and the other as
    /// [`TemporalBuffer::HistoryOut`].
    pub fn slots(frames: u32) -> (usize, usize) {
        if frames.is_multiple_of(2) {
            (1, 0)
        } else {
            (0, 1)
        }
    }

    /// The parameter block of the frame whose history holds `frames` frames
    /// (the CPU's [`crate::temporal::History::frames`]: its parity picks the
    /// slots), with the firefly clamp's factor (`None`: off) and whether
    /// negative output becomes 0.
    pub fn params(&self, frames: u32, fireflies: Option<f32>, clamp_negative: bool) -> Result<GpuTemporalParams, Error> {
        if fireflies.is_some_and(|k| !fireflies::valid_strength(k)) {
            return Err(Error::InvalidConfig("fireflies strength (must be finite and >= 1)"));
        }
        let s = &self.stage;
        let (w, h) = (s.width, s.height);
        let cfg = s.config();
        let (n_at, p_at, d_at) = s.guide_fields();
        let field = |on: bool, at: usize| if on { at as u32 } else { NONE };
        let plane = (w * h) as u32;
        let motion_at = (self.motion_offset() / 4) as u32;
        let offset = |s: Option<Source>| match s {
            None => NONE,
            Some(Source::Flr(c)) => c as u32 * plane,
            Some(Source::Work(p)) => GUIDE_IN_WORK | (motion_at + (2 + p as u32) * plane),
        };
        Ok(GpuTemporalParams {
            width: w as u32,
            height: h as u32,
            nc: self.cells() as u32,
            bands: self.bands() as u32,
            record: s.record() as u32,
            n_at: field(s.normal, n_at),
            p_at: field(s.position, p_at),
            d_at: field(s.depth, d_at),
            cells_at: (s.record() * s.plane()) as u32,
            has_history: (frames > 0) as u32,
            g_normal: offset(self.sources[0]),
            g_position: offset(self.sources[1]),
            g_depth: offset(self.sources[2]),
            clamp_negative: clamp_negative as u32,
            fireflies: fireflies.unwrap_or(0.0),
            firefly_history: cfg.firefly_history,
            max_history: cfg.max_history,
            normal_limit: cfg.normal_limit,
            position_limit: cfg.position_limit,
            depth_limit: cfg.depth_limit,
            clip_gamma: cfg.clip_gamma,
            output_alpha: cfg.output_alpha,
            // `Reprojection::is_cut` in integers: rejected > f · n ⇔ rejected > ⌊f · n⌋
            cut_limit: libm::floor(cfg.cut_fraction as f64 * s.plane() as f64).min(u32::MAX as f64) as u32,
            max_motion: s.max_motion(),
            footprint_limit2: s.footprint_limit2(),
            pad: [0; 3],
        })
    }

    /// The frame's counts from the counters buffer's bytes (rejected, invalid
    /// motion, NaN/Inf samples, clamped samples) as [`Reprojection::accumulate`]
    /// reports them, for the frame `params` was made for.
    pub fn counts(&self, counters: &[u8], params: &GpuTemporalParams) -> Counts {
        let at = |i: usize| counters.get(4 * i..4 * i + 4).map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])) as u64;
        let cut = params.has_history != 0 && at(0) > params.cut_limit as u64;
        Counts { rejected: if cut { 0 } else { at(0) }, invalid_motion: at(1), nonfinite: at(2), clamped: at(3), cut: cut as u64 }
    }
}
