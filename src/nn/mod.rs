//! Allocation-free inference of FLNR's guide network (Salmi, Cséfalvay & Imber,
//! "Fast Local Neural Regression for Low-Cost, Path Traced Lambertian Global
//! Illumination"): a small U-Net read from a weight blob ([`blob`]), run layer by layer on
//! planar f32 tensors in a caller-provided scratch ([`UNet::forward`]).
//!
//! Architecture (the blob's header gives `in`, `out`, and the widths
//! `c_0..c_L` of the `L` levels):
//!
//! ```text
//! input   conv3×3(in → c0) LReLU, conv1×1(c0 → c0) LReLU          = s_0 (full res)
//! enc l   conv3×3(c_{l−1} → c_l) LReLU, conv3×3 stride 2 (c_l → c_l) LReLU = s_l (1/2^l), l = 1..L
//! dec l   up×2 (nearest, cropped to s_{l−1}), concat s_{l−1},
//!         conv3×3(c_l + c_{l−1} → c_{l−1}) LReLU, conv3×3(c_{l−1} → c_{l−1}) LReLU, l = L..1
//! output  conv3×3(c0 → c0) LReLU, conv1×1(c0 → out), sigmoid
//! ```
//!
//! Convolutions pad with zeros (PyTorch's `padding=1`); a stride-2 output has
//! `⌈n/2⌉` rows and columns, so any frame size works without padding the input.
//! LeakyReLU slope 0.01 (PyTorch's default). `train/flnr.py` builds the same
//! network; `tests/nn.rs` checks parity on an exported test vector.

pub mod blob;
pub mod conv;

use crate::error::{Arg, Error};
use crate::parallel::{run_bands, Executor, MAX_BANDS};
pub use blob::{UNet, MAX_LEVELS};
pub use conv::Isa;
use conv::{split_rows, splits, Act, Concat, ConvDesc, Layer, Planes};

/// Distance (in f32) between two channel planes of a `w × h` tensor inside
/// the network: `w·h` rounded up to whole 64-byte cache lines, and to an
/// *odd* number of them. A 3×3 layer reads three rows of every input
/// channel for one output row; with planes a multiple of 4 KiB apart (any
/// `w·h` divisible by 1024, e.g. 256×256 or 512×512) all those rows fall in
/// the same L1 and L2 cache sets and evict each other. An odd number of lines
/// puts the planes' rows in different sets (measured on 256×256 frames, one
/// thread: FLNR 5 % faster in the default build, no change in an x86-64-v3
/// build).
/// The caller's input and output tensors keep `w·h`.
pub const fn plane_stride(w: usize, h: usize) -> usize {
    let lines = (w * h).div_ceil(16);
    (if lines.is_multiple_of(2) { lines + 1 } else { lines }) * 16
}

/// Elements of one planar tensor of `c` channels.
const fn tensor_len(c: usize, w: usize, h: usize) -> usize {
    c * plane_stride(w, h)
}

/// Size of level `l` (⌈n / 2^l⌉ per axis).
pub const fn level_size(w: usize, h: usize, l: usize) -> (usize, usize) {
    let mut s = (w, h);
    let mut i = 0;
    while i < l {
        s = (s.0.div_ceil(2), s.1.div_ceil(2));
        i += 1;
    }
    s
}

impl UNet<'_> {
    /// How far (in input pixels, per axis) an output value can see: the
    /// receptive radius. Each 3×3 layer at level `l` adds `2^l`, a stride-2
    /// layer from level `l − 1` adds `2^(l−1)`, and a nearest ×2 upsampling
    /// from level `l` adds `2^(l−1)` (the other half of the low-resolution
    /// pixel); the skip branches see less than the path through the bottom.
    /// 17 for two levels. A tile computed on its input grown by this much on
    /// every side is exact (see [`crate::flnr`]).
    pub fn receptive_radius(&self) -> usize {
        let l = self.levels();
        let mut r = 1; // input 3×3 (the 1×1 adds nothing)
        for lv in 1..=l {
            r += 1 << (lv - 1); // 3×3 at level lv − 1
            r += 1 << (lv - 1); // stride 2 from level lv − 1
        }
        for lv in (1..=l).rev() {
            r += 1 << (lv - 1); // upsampling to level lv − 1
            r += 2 << (lv - 1); // two 3×3 at level lv − 1
        }
        r + 1 // output 3×3
    }

    /// f32 of scratch [`UNet::forward`] needs for a `w × h` input: the skip
    /// tensors of every level, the f32 weights of the largest layer, and two
    /// work tensors of the largest layer.
    pub fn scratch_len(&self, w: usize, h: usize) -> usize {
        self.tensors_len(w, h) + self.weights_len()
    }

    /// The largest layer's weights in f32 (converted from the blob's f16
    /// once per layer and call).
    fn weights_len(&self) -> usize {
        (0..self.layer_count()).filter_map(|i| self.conv(i).ok()).map(|d| d.weights_len()).max().unwrap_or(0)
    }

    /// The skip and work tensors of [`UNet::scratch_len`].
    fn tensors_len(&self, w: usize, h: usize) -> usize {
        let c = self.widths();
        let mut skips = 0;
        let mut work = 0;
        for l in 0..=self.levels() {
            let (lw, lh) = level_size(w, h, l);
            skips += tensor_len(c[l], lw, lh);
            // the widest tensor at this level: a concat (c_l + c_{l+1}) or c_l
            let up = if l < self.levels() { c[l + 1] } else { 0 };
            work = work.max(tensor_len(c[l] + up, lw, lh));
        }
        skips + 2 * work
    }

    /// Runs the network on `input` (`in_channels()` planes of `w × h`,
    /// plane-major) into `out` (`out_channels()` planes). `scratch`: at least
    /// [`UNet::scratch_len`] f32. Allocates nothing.
    /// The 3×3 layers use the fastest instruction set available ([`Isa::detect_widest`]).
    pub fn forward(&self, input: &[f32], w: usize, h: usize, scratch: &mut [f32], out: &mut [f32]) -> Result<(), Error> {
        self.forward_with(Isa::detect_widest(), input, w, h, scratch, out)
    }

    /// [`UNet::forward`] with the 3×3 layers' instruction set chosen by the
    /// caller (tests compare them; one that is not available runs portable).
    pub fn forward_with(&self, isa: Isa, input: &[f32], w: usize, h: usize, scratch: &mut [f32], out: &mut [f32]) -> Result<(), Error> {
        self.forward_on(isa, input, w, h, scratch, out, None)
    }

    /// [`UNet::forward`] with each layer's output rows split into bands over
    /// the caller's executor (up to `4 · workers` bands per layer; the layers
    /// still run one after another). Bit-identical to [`UNet::forward`]: a
    /// band computes its rows exactly as the whole layer would. For one input
    /// too small to split into tiles for every thread.
    #[allow(clippy::too_many_arguments)]
    pub fn forward_parallel(
        &self,
        isa: Isa,
        input: &[f32],
        w: usize,
        h: usize,
        scratch: &mut [f32],
        out: &mut [f32],
        workers: usize,
        for_each: Executor<'_>,
    ) -> Result<(), Error> {
        if workers == 0 {
            return Err(Error::InvalidConfig("workers must be at least 1"));
        }
        self.forward_on(isa, input, w, h, scratch, out, Some((workers, for_each)))
    }

    /// The forward pass, each layer's rows on this thread (`threads` = `None`)
    /// or in bands over `(workers, executor)`.
    #[allow(clippy::too_many_arguments)]
    fn forward_on(
        &self,
        isa: Isa,
        input: &[f32],
        w: usize,
        h: usize,
        scratch: &mut [f32],
        out: &mut [f32],
        threads: Option<(usize, Executor<'_>)>,
    ) -> Result<(), Error> {
        if w == 0 || h == 0 {
            return Err(Error::InvalidSize { arg: Arg::Noisy, width: w, height: h });
        }
        let n = w * h;
        if input.len() != self.in_channels() * n {
            return Err(Error::BufferTooSmall { arg: Arg::Noisy, needed: self.in_channels() * n, len: input.len() });
        }
        if out.len() != self.out_channels() * n {
            return Err(Error::BufferTooSmall { arg: Arg::Output, needed: self.out_channels() * n, len: out.len() });
        }
        let need = self.scratch_len(w, h);
        if scratch.len() < need {
            return Err(Error::ScratchTooSmall { needed: need, got: scratch.len() });
        }
        let c = self.widths();
        let levels = self.levels();
        let plane = |l: usize| {
            let (lw, lh) = level_size(w, h, l);
            plane_stride(lw, lh)
        };
        // carve the skips, then two work tensors
        let mut skip_store: [&mut [f32]; MAX_LEVELS + 1] = Default::default();
        let mut rest = &mut scratch[..need];
        for l in 0..=levels {
            let (lw, lh) = level_size(w, h, l);
            let (a, b) = rest.split_at_mut(tensor_len(c[l], lw, lh));
            skip_store[l] = a;
            rest = b;
        }
        let (wts, rest) = rest.split_at_mut(self.weights_len());
        let (wa, wb) = rest.split_at_mut(rest.len() / 2);
        let mut layer = 0;
        // input block → s_0 (the caller's input has planes `n` apart)
        let p0 = plane(0);
        run_layer(threads, isa, self.conv(layer)?, input, n, w, h, wa, p0, Act::Leaky, wts, &mut [])?;
        layer += 1;
        run_layer(threads, isa, self.conv(layer)?, &wa[..c[0] * p0], p0, w, h, skip_store[0], p0, Act::Leaky, wts, &mut [])?;
        layer += 1;
        // encoder
        for l in 1..=levels {
            let (pw, ph) = level_size(w, h, l - 1);
            let (pp, pl) = (plane(l - 1), plane(l));
            let (prev, cur) = skip_store.split_at_mut(l);
            run_layer(threads, isa, self.conv(layer)?, prev[l - 1], pp, pw, ph, wa, pp, Act::Leaky, wts, &mut [])?;
            layer += 1;
            // stride 2: `wb` (free until the decoder) holds the even/odd split rows
            run_layer(threads, isa, self.conv(layer)?, &wa[..c[l] * pp], pp, pw, ph, cur[0], pl, Act::Leaky, wts, wb)?;
            layer += 1;
        }
        // decoder: the current tensor lives in `y` (or s_L at first); each
        // level concatenates into `x`, convolves x → y → x and swaps the two
        // names, so the result is in `y` again without a copy
        let (mut x, mut y) = (wa, wb);
        for l in (1..=levels).rev() {
            let (lw, lh) = level_size(w, h, l);
            let (sw, sh) = level_size(w, h, l - 1);
            let (lp, sp) = (plane(l), plane(l - 1));
            let cur_c = c[l];
            {
                let low: &[f32] = if l == levels { &*skip_store[l] } else { &y[..cur_c * lp] };
                let out = Planes::new(x, cur_c + c[l - 1], sp, sw, sh)?;
                let cat = Concat::new(low, cur_c, (lw, lh, lp), skip_store[l - 1], c[l - 1], sp, &out)?;
                // SAFETY: `out` borrows `x` exclusively; each band writes its own rows.
                for_rows(threads, sh, &|y0, y1| unsafe { cat.rows(&out, y0, y1) })?;
            }
            run_layer(threads, isa, self.conv(layer)?, &x[..(cur_c + c[l - 1]) * sp], sp, sw, sh, y, sp, Act::Leaky, wts, &mut [])?;
            layer += 1;
            run_layer(threads, isa, self.conv(layer)?, &y[..c[l - 1] * sp], sp, sw, sh, x, sp, Act::Leaky, wts, &mut [])?;
            layer += 1;
            core::mem::swap(&mut x, &mut y);
        }
        let cur: &[f32] = if levels == 0 { &*skip_store[0] } else { &y[..c[0] * p0] };
        run_layer(threads, isa, self.conv(layer)?, cur, p0, w, h, x, p0, Act::Leaky, wts, &mut [])?;
        layer += 1;
        // the output has planes `n` apart, as the caller's input
        run_layer(threads, isa, self.conv(layer)?, &x[..c[0] * p0], p0, w, h, out, n, Act::Sigmoid, wts, &mut [])?;
        Ok(())
    }
}

/// Rows a band of [`run_layer`] holds at least (fewer bands than `4 ·
/// workers` on small levels, so that a band is not mostly its call's overhead).
const MIN_BAND_ROWS: usize = 4;

/// Runs `body(y0, y1)` over bands of rows covering `0..rows`: one band on
/// this thread (`threads` = `None` or one worker), or up to `4 · workers`
/// bands over the executor. Bands may run concurrently, so `body` writes
/// only its own rows.
pub(crate) fn for_rows(threads: Option<(usize, Executor<'_>)>, rows: usize, body: &(dyn Fn(usize, usize) + Sync)) -> Result<(), Error> {
    match threads {
        Some((workers, for_each)) if workers > 1 && rows > MIN_BAND_ROWS => {
            let bands = workers.saturating_mul(4).min(rows.div_ceil(MIN_BAND_ROWS)).clamp(1, MAX_BANDS);
            let per = rows.div_ceil(bands).max(1);
            run_bands(rows.div_ceil(per), for_each, &|b| body(b * per, ((b + 1) * per).min(rows)))
        }
        _ => {
            body(0, rows);
            Ok(())
        }
    }
}

/// Runs one layer (`out = act(conv(input))`, see [`conv::conv`]) with its
/// rows (and a stride-2 layer's split input rows) on this thread or in
/// bands over `threads`' executor.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_layer(
    threads: Option<(usize, Executor<'_>)>,
    isa: Isa,
    d: ConvDesc<'_>,
    input: &[f32],
    in_plane: usize,
    w: usize,
    h: usize,
    out: &mut [f32],
    out_plane: usize,
    act: Act,
    weights: &mut [f32],
    split: &mut [f32],
) -> Result<(), Error> {
    let split = if splits(d, w, h, in_plane, split.len()) {
        let planes = Planes::new(split, d.cin, in_plane, w, h)?;
        // SAFETY: `planes` borrows `split` exclusively; each band writes its own rows.
        for_rows(threads, h, &|y0, y1| unsafe { split_rows(input, in_plane, &planes, y0, y1) })?;
        Some(&*split)
    } else {
        None
    };
    let layer = Layer::new(isa, d, input, in_plane, w, h, act, weights, split)?;
    let (ow, oh) = d.out_size(w, h);
    let out = Planes::new(out, d.cout, out_plane, ow, oh)?;
    // SAFETY: `out` borrows the caller's tensor exclusively; each band writes its own rows.
    for_rows(threads, oh, &|y0, y1| unsafe { layer.rows(&out, y0, y1) })
}

/// `f` of every value of `row`, in place, eight at a time in `wide`'s lanes;
/// the tail is padded to eight, so a value's result does not depend on its
/// position in the row (`wide`'s transcendental functions may round a lane
/// differently from a scalar call).
pub(crate) fn map8(row: &mut [f32], f: impl Fn(wide::f32x8) -> wide::f32x8) {
    let mut chunks = row.chunks_exact_mut(8);
    for c in &mut chunks {
        if let Ok(a) = <[f32; 8]>::try_from(&*c) {
            c.copy_from_slice(&f(wide::f32x8::from(a)).to_array());
        }
    }
    let tail = chunks.into_remainder();
    let n = tail.len();
    let mut a = [0f32; 8];
    a[..n].copy_from_slice(tail);
    tail.copy_from_slice(&f(wide::f32x8::from(a)).to_array()[..n]);
}
