//! FLR on GPUs: the WGSL compute shaders ([`FLR_WGSL`]) and a description of
//! how to run them — buffers, bindings, entry points, workgroup counts and the
//! parameter block — for engines that drive their own graphics API (as NVIDIA's
//! NRD hands out shaders plus dispatch descriptions). `no_std`, no allocation.
//! The `lrdenoise-gpu` crate executes the same description with `wgpu`, and
//! `lrd shaders --out DIR` writes the shaders as WGSL, SPIR-V, MSL and HLSL.
//!
//! Running one frame with your own API:
//! 1. Compile [`FLR_WGSL`] (or the SPIR-V/MSL/HLSL from `lrd shaders`) once.
//! 2. Create the buffers of [`GpuPlan::buffers`] once; every entry point uses
//!    the same bind group: binding `i` = buffer `i` of that list.
//! 3. Each frame: upload the [`GpuParams`] of [`GpuPlan::params`] (only when a
//!    layout changes), the noisy image and the guides; dispatch the
//!    [`GpuPlan::passes`] in order (7, or up to 15 with the adaptive window),
//!    with a storage barrier between them.
//! 4. Read the output buffer; optionally the stats buffer for the [`Report`]
//!    ([`GpuPlan::report`]).
//!
//! The shaders compute in f32 (WGSL has no f64): moments are shifted to the
//! frame reference and blurred in f32, where the CPU path uses f64. Results
//! match the CPU path within the tolerance `tests/` of `lrdenoise-gpu` state;
//! accuracy drops, as for any f32 implementation, for guides whose offset
//! from the frame's reference sample dwarfs their local variation.
//!
//! The firefly clamp ([`FlrConfig::fireflies`], [`crate::fireflies`]) runs in
//! the `reference` and `moments` passes, its thresholds in f32; a sample whose
//! luminance is within rounding of its threshold may be clamped on one path
//! and not on the other (by a factor within rounding of 1).

use super::config::FlrConfig;
use super::schedule::Stage;
use crate::error::Error;
use crate::fireflies;
use crate::flr::{Flr, Grid, Report, MAX_SCALES};
use crate::image::Layout;
use crate::kernels::blur::Taps;
use crate::kernels::solve::Regularization;
use crate::kernels::{model_len, moment_count};

/// The FLR shader module: entry points `reference`, `moments`, `finish_stats`,
/// `blur_rows`, `blur_cols`, `solve`, `apply`.
pub const FLR_WGSL: &str = include_str!("flr.wgsl");

/// Most guide channels the shaders take (their arrays are sized for it).
pub const GPU_MAX_GUIDES: usize = 8;
/// Blur taps the parameter block holds (radius ≤ 67 cells).
const TAPS: usize = 68;
/// Largest workgroup count per dimension every WebGPU device accepts.
const MAX_GROUPS: usize = 65535;
/// Bytes of the stats buffer: reference, mean, scale (8 f32 each) + 7 counters
/// (the [`Report`] counts [`GpuPlan::report`] reads), padded to 16 bytes.
pub const STATS_BYTES: u64 = 128;

/// The uniform parameter block (binding 0), laid out as the WGSL `Params`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuParams {
    /// Output width in pixels.
    pub width: u32,
    /// Output height in pixels.
    pub height: u32,
    /// Model grid width in cells (the output models' grid).
    pub cells_x: u32,
    /// Model grid height in cells.
    pub cells_y: u32,
    /// Block size B in output pixels ([`FlrConfig::block`]).
    pub block: u32,
    /// Guide channel count Q.
    pub q: u32,
    /// Moments per cell ([`moment_count`] of Q).
    pub k: u32,
    /// Model length per cell ([`model_len`] of Q).
    pub ml: u32,
    /// Window 0's blur radius in cells (`taps[0..=radius]` are used).
    pub radius: u32,
    /// 1: clamp negative output to 0 ([`FlrConfig::clamp_negative`]).
    pub clamp_negative: u32,
    /// 1: [`Regularization::Tikhonov`]; 0: [`Regularization::Normalized`].
    pub tikhonov: u32,
    /// 1 when noisy and guides are f16.
    pub input_f16: u32,
    /// ε of [`Regularization::Normalized`] (0 with Tikhonov).
    pub eps_mul: f32,
    /// ϵ of [`Regularization::Normalized`] (0 with Tikhonov).
    pub eps_add: f32,
    /// ε of [`Regularization::Tikhonov`] (0 with the normalized regulariser).
    pub eps_tikhonov: f32,
    /// 1 / (window 0's total window weight).
    pub weight_norm: f32,
    /// A cell of window 0 whose window weight is at most this is empty.
    pub min_weight: f32,
    /// Noisy and fit-guide width (`width` unless upsampling).
    pub in_width: u32,
    /// Noisy and fit-guide height (`height` unless upsampling).
    pub in_height: u32,
    /// Block size at the noisy resolution (`block / upsample`).
    pub fit_block: u32,
    /// Noisy layout: offset, pixel stride, row stride, channel stride (elements).
    pub noisy: [u32; 4],
    /// Output layout, as `noisy`.
    pub output: [u32; 4],
    /// Per guide channel: offset, pixel stride, row stride, 0 (output resolution).
    pub guide: [[u32; 4]; GPU_MAX_GUIDES],
    /// The same for the guides the moments are taken from (noisy resolution).
    pub guide_fit: [[u32; 4]; GPU_MAX_GUIDES],
    /// Window 0's blur taps `w[0..=radius]`, zero beyond.
    pub taps: [f32; TAPS],
    /// 1, or 3 with the adaptive window.
    pub windows: u32,
    /// The 2×2-pooled moment grid's element offset in `tmp` (`u32::MAX`
    /// without).
    pub pooled_off: u32,
    /// The pooled grid's width in cells (0 without).
    pub pooled_x: u32,
    /// The pooled grid's height in cells (0 without).
    pub pooled_y: u32,
    /// Each window's grid and buffer regions (unused entries zero).
    pub win: [GpuWindow; 3],
    /// Taps of windows 1 and 2.
    pub taps_12: [[f32; TAPS]; 2],
    /// [`FlrConfig::adaptive_without_ao`]: the guide channel (AO) window 0
    /// is also fitted without (`u32::MAX`: off).
    pub without: u32,
    /// Element offset in `models` of that fit's models (`u32::MAX`: off).
    pub without_model_off: u32,
    /// Element offset in `models` of that fit's variances (`u32::MAX`: off).
    pub without_var_off: u32,
    /// [`FlrConfig::ao_demodulation`] where it applies: the AO channel
    /// (`u32::MAX`: off).
    pub demod_ao: u32,
    /// The offset `c` of the demodulation `s = √(ao + c)`.
    pub demod_offset: f32,
    /// [`FlrConfig::fireflies`]: the firefly clamp's factor `k` (0: off).
    pub fireflies: f32,
    /// Padding to the WGSL layout; zero.
    pub pad_fireflies: [u32; 2],
}

/// One window of the fit in the parameter block, laid out as the WGSL
/// `Window`: its grid and where its stages read and write (buffer 0 = cells,
/// 1 = tmp; element offsets).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuWindow {
    /// Grid width in cells.
    pub cells_x: u32,
    /// Grid height in cells.
    pub cells_y: u32,
    /// Block cells per cell side: 1, or 2 on the pooled grid.
    pub factor: u32,
    /// Blur radius in cells.
    pub radius: u32,
    /// Buffer the blur reads the moments from (0 = cells, 1 = tmp).
    pub src_buf: u32,
    /// Element offset of those moments in `src_buf`.
    pub src_off: u32,
    /// Buffer the blurred grid goes to (what the solve reads).
    pub out_buf: u32,
    /// Element offset of the blurred grid in `out_buf`.
    pub out_off: u32,
    /// Element offset of the row-blurred grid in `tmp`.
    pub tmp_off: u32,
    /// Element offset of this window's models in `models`.
    pub model_off: u32,
    /// Element offset of the variance estimates in `models`; `u32::MAX`: no
    /// variance estimates (one window).
    pub var_off: u32,
    /// 1 / (this window's total window weight).
    pub weight_norm: f32,
    /// A cell whose window weight is at most this is empty.
    pub min_weight: f32,
    /// 4πσ² in input pixels.
    pub area: f32,
    /// Padding to the WGSL layout; zero.
    pub pad: [u32; 2],
}

// SAFETY: `repr(C)`, only u32/f32 fields and arrays of them, 4-byte aligned
// throughout with no padding (1424 bytes: checked below); any bit pattern is valid.
unsafe impl bytemuck::Zeroable for GpuParams {}
// SAFETY: as above.
unsafe impl bytemuck::Pod for GpuParams {}
// SAFETY: `repr(C)`, 16 four-byte fields, no padding (checked below).
unsafe impl bytemuck::Zeroable for GpuWindow {}
// SAFETY: as above.
unsafe impl bytemuck::Pod for GpuWindow {}
const _: () = assert!(core::mem::size_of::<GpuWindow>() == 64);
/// Bytes of the parameter block.
pub const PARAMS_BYTES: usize = 1424;
const _: () = assert!(core::mem::size_of::<GpuParams>() == PARAMS_BYTES);

impl GpuParams {
    /// The block's bytes, as the uniform buffer holds them.
    pub fn as_bytes(&self) -> &[u8] {
        bytemuck::bytes_of(self)
    }
}

/// The buffers of the bind group, in binding order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GpuBuffer {
    /// [`GpuParams`], uniform.
    Params,
    /// Noisy RGB, f32 or f16 ([`InputFormat`]), read-only storage.
    Noisy,
    /// Every guide channel, f32 or f16, read-only storage.
    Guides,
    /// Frame reference, mean, scale and report counters.
    Stats,
    /// Moment grid, then the blurred grid.
    Cells,
    /// Horizontally blurred grid.
    Tmp,
    /// Per-cell models.
    Models,
    /// Denoised RGB, f32, written by `apply`.
    Output,
}

/// How a buffer is bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// Uniform buffer.
    Uniform,
    /// Read-only storage buffer.
    ReadOnlyStorage,
    /// Read-write storage buffer.
    ReadWriteStorage,
}

/// One buffer of the bind group.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BufferDesc {
    /// Which buffer.
    pub buffer: GpuBuffer,
    /// Its binding index in group 0.
    pub binding: u32,
    /// How it is bound.
    pub access: Access,
    /// Minimum size in bytes (for inputs and output: for the layouts given).
    pub bytes: u64,
}

/// One dispatch: the CPU stage it computes, the entry point and its workgroup counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pass {
    /// The stage of [`Stage::ALL`] this dispatch computes (for the window
    /// `window` of the adaptive window's per-window stages).
    pub stage: Stage,
    /// The window a per-window pass (blur, solve) works on; 0 otherwise.
    pub window: u8,
    /// The entry point's name, NUL-terminated (the C API hands it out as is).
    pub entry: &'static core::ffi::CStr,
    /// Workgroups along x, y and z.
    pub workgroups: [u32; 3],
}

impl Pass {
    /// The entry point's name.
    pub fn name(&self) -> &'static str {
        // the names are ASCII literals (see `GpuPlan::passes`)
        self.entry.to_str().unwrap_or("")
    }
}

/// Sample format of the noisy and guide buffers (the output is always f32).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum InputFormat {
    /// 32-bit IEEE floats (the default).
    #[default]
    F32,
    /// IEEE half floats, read with `unpack2x16float` (core WGSL: no device
    /// feature needed); halves the input bytes.
    F16,
}

impl InputFormat {
    fn bytes(self) -> u64 {
        match self {
            InputFormat::F32 => 4,
            InputFormat::F16 => 2,
        }
    }
}

/// Where the inputs and the output live in their buffers (element layouts, as
/// [`Layout`] for the CPU views). `guides[q]` is guide channel `q`'s layout
/// (its `channel_stride` unused), in kernel order: normal x, y, z, depth,
/// position x, y, z, AO, user channels — those of the configured guide set.
/// `guides` are at the output resolution (the model is applied to them);
/// `guides_fit` (in the same buffer) are those the moments are taken from, at
/// the noisy image's resolution: the same as `guides` unless upsampling or
/// fitting on a separate guide set (the CPU's `Frame::guides_low`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpuLayouts {
    /// Sample format of `noisy` and `guides`.
    pub input: InputFormat,
    /// At the noisy resolution (output size / upsample).
    pub noisy: Layout,
    /// Guide channel `q`'s layout at the output resolution, for `q` < Q.
    pub guides: [Layout; GPU_MAX_GUIDES],
    /// Guide channel `q`'s layout at the noisy resolution (the moments').
    pub guides_fit: [Layout; GPU_MAX_GUIDES],
    /// The output's layout (f32, 3 channels).
    pub output: Layout,
}

impl GpuLayouts {
    /// Tightly packed planes: noisy R, G, B; guide channels one after another;
    /// output R, G, B (what `lrdenoise-gpu` uploads); inputs in `input` format.
    /// The guides are also the fit guides.
    pub fn planar(width: usize, height: usize, input: InputFormat) -> Self {
        let pl = Layout::planar(width, height);
        let n = width * height;
        let guides = core::array::from_fn(|q| Layout { offset: q * n, ..pl });
        GpuLayouts { input, noisy: pl, guides, guides_fit: guides, output: pl }
    }

    /// As [`GpuLayouts::planar`] with a separate set of `q` fit guides at the
    /// noisy resolution `in_width`×`in_height` (upsampling, or FLNR's two sets),
    /// stored after the `q` output-resolution guide planes; noisy at the noisy
    /// resolution.
    pub fn planar_with_fit(width: usize, height: usize, in_width: usize, in_height: usize, q: usize, input: InputFormat) -> Self {
        let pl = Layout::planar(width, height);
        let low = Layout::planar(in_width, in_height);
        let (n, nl) = (width * height, in_width * in_height);
        GpuLayouts {
            input,
            noisy: low,
            guides: core::array::from_fn(|c| Layout { offset: c * n, ..pl }),
            guides_fit: core::array::from_fn(|c| Layout { offset: q * n + c * nl, ..low }),
            output: pl,
        }
    }
}

/// FLR's GPU dispatch description for one frame size and configuration.
#[derive(Clone, Copy, Debug)]
pub struct GpuPlan {
    /// The CPU plan: sizes, configuration and each window's grid, taps,
    /// weight and area.
    flr: Flr,
}

/// Most dispatches per frame (the adaptive window with a pooled grid).
pub const MAX_PASSES: usize = 15;

/// The dispatches of one frame, in order ([`GpuPlan::passes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Passes {
    list: [Pass; MAX_PASSES],
    len: usize,
}

impl Passes {
    /// Appends a pass ([`GpuPlan::passes`] never makes more than [`MAX_PASSES`]).
    fn push(&mut self, stage: Stage, window: usize, entry: &'static core::ffi::CStr, workgroups: [u32; 3]) {
        if let Some(slot) = self.list.get_mut(self.len) {
            *slot = Pass { stage, window: window as u8, entry, workgroups };
            self.len += 1;
        }
    }
}

impl core::ops::Deref for Passes {
    type Target = [Pass];
    fn deref(&self) -> &[Pass] {
        &self.list[..self.len]
    }
}

impl IntoIterator for Passes {
    type Item = Pass;
    type IntoIter = core::iter::Take<core::array::IntoIter<Pass, MAX_PASSES>>;
    fn into_iter(self) -> Self::IntoIter {
        self.list.into_iter().take(self.len)
    }
}

/// Where each window's grids live in `tmp` and `models` (element offsets).
struct Regions {
    /// `tmp` and `models` lengths (f32 elements).
    tmp_len: usize,
    models_len: usize,
    pooled_off: Option<usize>,
    /// Per window: blur source (buffer, offset), blurred grid (buffer,
    /// offset), models, variances. Every window's row-blurred grid is at the
    /// start of `tmp` (the windows run one after another).
    src: [(u32, usize); MAX_SCALES],
    out: [(u32, usize); MAX_SCALES],
    model: [usize; MAX_SCALES],
    var: [Option<usize>; MAX_SCALES],
    /// Window 0's fit without a guide ([`FlrConfig::adaptive_without_ao`]):
    /// its models and variances.
    without: Option<(usize, usize)>,
}

/// Elements a layout addresses for `channels` channels (one past the last), if it fits u32.
fn extent(l: &Layout, width: usize, height: usize, channels: usize) -> Option<u64> {
    let last = l
        .offset
        .checked_add((height - 1).checked_mul(l.row_stride)?)?
        .checked_add((width - 1).checked_mul(l.pixel_stride)?)?
        .checked_add((channels - 1).checked_mul(l.channel_stride)?)?;
    (last < u32::MAX as usize).then_some(last as u64 + 1)
}

impl GpuPlan {
    /// Plans FLR for `width`×`height` output frames (noisy input at
    /// 1/`upsample` of that). The GPU path takes at most [`GPU_MAX_GUIDES`]
    /// guide channels.
    pub fn new(cfg: FlrConfig, width: usize, height: usize) -> Result<Self, Error> {
        // The CPU plan validates the configuration and the size.
        let flr = Flr::new(cfg, width, height)?;
        let q = flr.guide_channels();
        if q > GPU_MAX_GUIDES {
            return Err(Error::TooManyGuides { got: q });
        }
        let plan = GpuPlan { flr };
        if (0..plan.windows()).any(|s| plan.taps(s).radius >= TAPS) {
            return Err(Error::Unsupported("the GPU path blurs at most 67 cells wide"));
        }
        let too_many = plan.passes().iter().any(|p| p.workgroups.iter().any(|&g| g as usize > MAX_GROUPS));
        let r = plan.regions();
        if too_many
            || width * height * 3 >= u32::MAX as usize
            || r.tmp_len >= u32::MAX as usize
            || r.models_len >= u32::MAX as usize
            || plan.cells_x() * plan.cells_y() * moment_count(q) >= u32::MAX as usize
        {
            return Err(Error::Unsupported("frame too large for one GPU dispatch"));
        }
        Ok(plan)
    }

    /// Windows fitted: 1, or 3 with the adaptive window.
    fn windows(&self) -> usize {
        self.flr.scale_count()
    }
    fn cells_x(&self) -> usize {
        self.flr.cells().0
    }
    fn cells_y(&self) -> usize {
        self.flr.cells().1
    }
    /// The larger window fitted on the 2×2-pooled grid, if any.
    fn pooled_grid(&self) -> Option<Grid> {
        self.flr.pooled_window().map(|s| self.grid(s))
    }
    /// Window `s`'s grid.
    fn grid(&self, s: usize) -> Grid {
        self.flr.window_grid_taps(s).0
    }
    /// Window `s`'s blur taps.
    fn taps(&self, s: usize) -> &Taps {
        self.flr.window_grid_taps(s).1
    }

    /// Where each window's grids live. With the firefly clamp, `tmp` first
    /// holds its cells' sum, count and maximum (3 values per cell, band after
    /// band), from `reference` to `moments`. One window: blurred in place in
    /// `cells`, models straight into the output models. Adaptive: `tmp` holds
    /// the row-blurred grid (shared, the windows run one after another),
    /// window 0's blurred grid, the pooled grid and windows 1 and 2's blurred
    /// grids; `models` the blended models, then each window's models, then
    /// each window's variances.
    fn regions(&self) -> Regions {
        let k = moment_count(self.guide_channels());
        let ml = model_len(self.guide_channels());
        let fine = self.cells_x() * self.cells_y();
        let mut r = Regions {
            // the firefly clamp's cell sums live at the start of `tmp` until
            // the moments are taken (`tmp` is first written after them)
            tmp_len: (fine * k).max(self.firefly_cells().map_or(0, |(x, y)| 3 * x * y)),
            models_len: fine * ml,
            pooled_off: None,
            src: [(0, 0); MAX_SCALES],
            out: [(0, 0); MAX_SCALES],
            model: [0; MAX_SCALES],
            var: [None; MAX_SCALES],
            without: None,
        };
        if self.windows() == 1 {
            return r;
        }
        r.out[0] = (1, r.tmp_len);
        r.tmp_len += fine * k;
        if let Some(g) = self.pooled_grid() {
            r.pooled_off = Some(r.tmp_len);
            r.tmp_len += g.cells_x * g.cells_y * k;
        }
        for s in 0..self.windows() {
            let cells = self.grid(s).cells_x * self.grid(s).cells_y;
            if s > 0 {
                r.src[s] = match (self.grid(s).factor, r.pooled_off) {
                    (2, Some(o)) => (1, o),
                    _ => (0, 0),
                };
                r.out[s] = (1, r.tmp_len);
                r.tmp_len += cells * k;
            }
            r.model[s] = r.models_len;
            r.models_len += cells * ml;
        }
        for s in 0..self.windows() {
            r.var[s] = Some(r.models_len);
            r.models_len += self.grid(s).cells_x * self.grid(s).cells_y;
        }
        if self.without_guide().is_some() {
            r.without = Some((r.models_len, r.models_len + fine * ml));
            r.models_len += fine * (ml + 1);
        }
        r
    }

    /// The firefly clamp's cells (per band, bands) at the noisy resolution,
    /// with [`FlrConfig::fireflies`].
    fn firefly_cells(&self) -> Option<(usize, usize)> {
        let (iw, ih) = self.input_size();
        self.config().fireflies.map(|_| (fireflies::cells(iw), ih.div_ceil(fireflies::CELL)))
    }

    /// The guide channel window 0 is also fitted without: AO, with
    /// [`FlrConfig::adaptive_without_ao`].
    fn without_guide(&self) -> Option<usize> {
        let cfg = self.config();
        cfg.guides.ao_channel().filter(|_| cfg.adaptive_without_ao && self.windows() > 1)
    }

    /// Output size.
    pub fn size(&self) -> (usize, usize) {
        self.flr.size()
    }
    /// Size of the noisy input and of the fit guides (output size / upsample, rounded up).
    pub fn input_size(&self) -> (usize, usize) {
        self.flr.input_size()
    }
    /// Guide channel count Q.
    pub fn guide_channels(&self) -> usize {
        self.flr.guide_channels()
    }
    /// The configuration planned for.
    pub fn config(&self) -> &FlrConfig {
        self.flr.config()
    }

    /// The dispatches of one frame, in order: seven with one window, up to
    /// [`MAX_PASSES`] with the adaptive window (see the shader's header).
    /// They follow FLR's stage order ([`Stage::ALL`]), except that the
    /// per-window stages run window after window (BlurRows and BlurColsSolve
    /// of window 0, then of window 1, ...: the windows share `tmp`).
    pub fn passes(&self) -> Passes {
        let k = moment_count(self.guide_channels());
        let g = |n: usize, d: usize| n.div_ceil(d) as u32;
        let (cx, cy) = (self.cells_x() as u32, self.cells_y() as u32);
        let grid = |s: usize| [g(self.grid(s).cells_x * k, 64), self.grid(s).cells_y as u32, 1];
        let solve = |s: usize| [g(self.grid(s).cells_x, 64), self.grid(s).cells_y as u32, 1];
        let none = Pass { stage: Stage::Prepare, window: 0, entry: c"", workgroups: [0; 3] };
        let mut p = Passes { list: [none; MAX_PASSES], len: 0 };
        // With the firefly clamp, `reference` also sums the clamp's 8×8 cells
        // of the noisy input (one invocation per cell, 64 per workgroup): the
        // Prepare stage, as they only read the input and every cell of a band
        // must be summed by the time `moments` (Moments stage) derives the
        // thresholds of its block's cells from them and clamps. No pass of
        // its own: the pass list keeps its length ([`MAX_PASSES`]).
        let reference = self.firefly_cells().map_or([1, 1, 1], |(x, y)| [g(x, 64), y as u32, 1]);
        p.push(Stage::Prepare, 0, c"reference", reference);
        p.push(Stage::Moments, 0, c"moments", [cx, cy, 1]);
        if let Some(s) = self.flr.pooled_window() {
            p.push(Stage::Moments, 0, c"pool", grid(s));
        }
        p.push(Stage::Stats, 0, c"finish_stats", [1, 1, 1]);
        const NAMES: [[&core::ffi::CStr; 3]; MAX_SCALES] = [
            [c"blur_rows", c"blur_cols", c"solve"],
            [c"blur_rows_1", c"blur_cols_1", c"solve_1"],
            [c"blur_rows_2", c"blur_cols_2", c"solve_2"],
        ];
        for (s, [rows, cols, solve_s]) in NAMES.iter().enumerate().take(self.windows()) {
            p.push(Stage::BlurRows, s, rows, grid(s));
            p.push(Stage::BlurColsSolve, s, cols, grid(s));
            p.push(Stage::BlurColsSolve, s, solve_s, solve(s));
        }
        if self.windows() > 1 {
            p.push(Stage::Blend, 0, c"blend", [g(self.cells_x(), 64), cy, 1]);
        }
        p.push(Stage::Apply, 0, c"apply", [g(self.size().0, 8), g(self.size().1, 8), 1]);
        p
    }

    /// The parameter block for these layouts; checks that every index fits u32.
    pub fn params(&self, layouts: &GpuLayouts) -> Result<GpuParams, Error> {
        let (w, h) = self.size();
        self.buffers(layouts)?; // every layout fits u32
        let v = |l: &Layout| [l.offset as u32, l.pixel_stride as u32, l.row_stride as u32, l.channel_stride as u32];
        let (tikhonov, eps_mul, eps_add, eps_t) = match self.config().regularization {
            Regularization::Normalized { eps_mul, eps_add } => (0, eps_mul, eps_add, 0.0),
            Regularization::Tikhonov { eps } => (1, 0.0, 0.0, eps),
        };
        let b = self.config().block;
        let bin = b / self.config().upsample;
        let total = self.flr.window_weight(0);
        let taps_of = |s: usize| {
            let mut taps = [0f32; TAPS];
            for (t, w) in taps.iter_mut().zip(&self.taps(s).w[..=self.taps(s).radius]) {
                *t = *w as f32;
            }
            taps
        };
        let r = self.regions();
        let mut win = [GpuWindow::default(); 3];
        for (s, w) in win.iter_mut().enumerate().take(self.windows()) {
            let g = self.grid(s);
            *w = GpuWindow {
                cells_x: g.cells_x as u32,
                cells_y: g.cells_y as u32,
                factor: g.factor as u32,
                radius: self.taps(s).radius as u32,
                src_buf: r.src[s].0,
                src_off: r.src[s].1 as u32,
                out_buf: r.out[s].0,
                out_off: r.out[s].1 as u32,
                tmp_off: 0,
                model_off: r.model[s] as u32,
                var_off: r.var[s].map_or(u32::MAX, |o| o as u32),
                weight_norm: (1.0 / self.flr.window_weight(s)) as f32,
                min_weight: self.flr.min_weight(s) as f32,
                area: self.flr.window_area(s) as f32,
                pad: [0; 2],
            };
        }
        let pooled = r.pooled_off.and(self.pooled_grid());
        let guide_words = |ls: &[Layout; GPU_MAX_GUIDES]| {
            let mut g = [[0u32; 4]; GPU_MAX_GUIDES];
            for (g, l) in g.iter_mut().zip(ls).take(self.guide_channels()) {
                *g = [l.offset as u32, l.pixel_stride as u32, l.row_stride as u32, 0];
            }
            g
        };
        Ok(GpuParams {
            width: w as u32,
            height: h as u32,
            cells_x: self.cells_x() as u32,
            cells_y: self.cells_y() as u32,
            block: b as u32,
            q: self.guide_channels() as u32,
            k: moment_count(self.guide_channels()) as u32,
            ml: model_len(self.guide_channels()) as u32,
            radius: self.taps(0).radius as u32,
            clamp_negative: self.config().clamp_negative as u32,
            tikhonov,
            input_f16: (layouts.input == InputFormat::F16) as u32,
            eps_mul: eps_mul as f32,
            eps_add: eps_add as f32,
            eps_tikhonov: eps_t as f32,
            weight_norm: (1.0 / total) as f32,
            min_weight: (1e-12 * total) as f32,
            in_width: self.input_size().0 as u32,
            in_height: self.input_size().1 as u32,
            fit_block: bin as u32,
            noisy: v(&layouts.noisy),
            output: v(&layouts.output),
            guide: guide_words(&layouts.guides),
            guide_fit: guide_words(&layouts.guides_fit),
            taps: taps_of(0),
            windows: self.windows() as u32,
            pooled_off: r.pooled_off.map_or(u32::MAX, |o| o as u32),
            pooled_x: pooled.map_or(0, |g| g.cells_x as u32),
            pooled_y: pooled.map_or(0, |g| g.cells_y as u32),
            win,
            taps_12: [if self.windows() > 1 { taps_of(1) } else { [0.0; TAPS] }, if self.windows() > 2 { taps_of(2) } else { [0.0; TAPS] }],
            without: self.without_guide().map_or(u32::MAX, |d| d as u32),
            without_model_off: r.without.map_or(u32::MAX, |(m, _)| m as u32),
            without_var_off: r.without.map_or(u32::MAX, |(_, v)| v as u32),
            demod_ao: self.config().demodulation().map_or(u32::MAX, |(a, _)| a as u32),
            demod_offset: self.config().demodulation().map_or(0.0, |(_, c)| c),
            fireflies: self.config().fireflies.unwrap_or(0.0),
            pad_fireflies: [0; 2],
        })
    }

    /// The eight buffers of the bind group, in binding order, sized for `layouts`.
    pub fn buffers(&self, layouts: &GpuLayouts) -> Result<[BufferDesc; 8], Error> {
        let (w, h) = self.size();
        let bad = Error::Unsupported("a layout addresses more than 2^32 elements");
        let (iw, ih) = self.input_size();
        let noisy = extent(&layouts.noisy, iw, ih, 3).ok_or(bad)?;
        let output = extent(&layouts.output, w, h, 3).ok_or(bad)?;
        let mut guides = 2; // a zero-sized binding is not allowed: at least one word
        for (map, fit) in layouts.guides.iter().zip(&layouts.guides_fit).take(self.guide_channels()) {
            guides = guides.max(extent(map, w, h, 1).ok_or(bad)?).max(extent(fit, iw, ih, 1).ok_or(bad)?);
        }
        // input bytes, rounded up to whole 32-bit words
        let input = |elements: u64| (elements * layouts.input.bytes()).next_multiple_of(4);
        let grid = (self.cells_x() * self.cells_y() * moment_count(self.guide_channels())) as u64 * 4;
        let r = self.regions();
        let d = |buffer, binding, access, bytes| BufferDesc { buffer, binding, access, bytes };
        use Access::*;
        Ok([
            d(GpuBuffer::Params, 0, Uniform, core::mem::size_of::<GpuParams>() as u64),
            d(GpuBuffer::Noisy, 1, ReadOnlyStorage, input(noisy)),
            d(GpuBuffer::Guides, 2, ReadOnlyStorage, input(guides)),
            d(GpuBuffer::Stats, 3, ReadWriteStorage, STATS_BYTES),
            d(GpuBuffer::Cells, 4, ReadWriteStorage, grid),
            d(GpuBuffer::Tmp, 5, ReadWriteStorage, r.tmp_len as u64 * 4),
            d(GpuBuffer::Models, 6, ReadWriteStorage, r.models_len as u64 * 4),
            d(GpuBuffer::Output, 7, ReadWriteStorage, output * 4),
        ])
    }

    /// The frame's [`Report`] from the stats buffer's bytes (after `apply`).
    pub fn report(&self, stats: &[u8]) -> Report {
        let counter = |i: usize| -> u64 {
            let o = 96 + 4 * i;
            stats.get(o..o + 4).map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64)
        };
        Report {
            nonfinite_noisy: counter(0),
            nonfinite_guides: counter(1),
            fallback_pixels: counter(2),
            empty_blocks: counter(3),
            empty_cells: counter(4),
            dropped_pivots: counter(5),
            clamped_fireflies: counter(6),
            ..Report::default()
        }
    }
}
