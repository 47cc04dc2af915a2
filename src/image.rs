//! Borrowed, validated image views (OIDN-style layouts).
//!
//! Element `(x, y, c)` of a view lives at
//! `offset + y * row_stride + x * pixel_stride + c * channel_stride`
//! in the underlying slice (all in *elements*, not bytes). Interleaved RGB is
//! `Layout::interleaved(width, 3)`; a planar buffer has `pixel_stride = 1`,
//! `row_stride = width` and `channel_stride = width * height`. Every view is
//! checked once, at construction: after that, reads and writes are in bounds.

use crate::error::{Arg, Error};
use half::f16;

/// Where each element of an image lives in its slice (element units).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Index of element (0, 0, 0).
    pub offset: usize,
    /// Distance between horizontally adjacent pixels.
    pub pixel_stride: usize,
    /// Distance between vertically adjacent pixels.
    pub row_stride: usize,
    /// Distance between the channels of one pixel.
    pub channel_stride: usize,
}

impl Layout {
    /// Tightly packed, channels interleaved (RGBRGB...).
    pub const fn interleaved(width: usize, channels: usize) -> Self {
        Layout { offset: 0, pixel_stride: channels, row_stride: width * channels, channel_stride: 1 }
    }
    /// One plane per channel (RRR...GGG...BBB...).
    pub const fn planar(width: usize, height: usize) -> Self {
        Layout { offset: 0, pixel_stride: 1, row_stride: width, channel_stride: width * height }
    }
    /// Whether every (pixel, channel) of a `width`×`height`×`channels` image
    /// has an element of its own: sorted by stride, each dimension's stride
    /// clears everything the smaller ones span. (Sufficient; exotic
    /// interleavings that are injective in other ways are refused too.)
    pub fn elements_distinct(&self, width: usize, height: usize, channels: usize) -> bool {
        let mut dims = [(self.pixel_stride, width), (self.row_stride, height), (self.channel_stride, channels)];
        dims.sort_unstable();
        let mut span = 0usize; // largest index offset reached by the smaller dimensions
        for (stride, n) in dims {
            if n <= 1 {
                continue;
            }
            if stride <= span || stride == 0 {
                return false;
            }
            let Some(s) = stride.checked_mul(n - 1).and_then(|e| e.checked_add(span)) else { return false };
            span = s;
        }
        true
    }
    /// One past the largest element index used, or `None` on overflow.
    fn end(&self, width: usize, height: usize, channels: usize) -> Option<usize> {
        let last = self
            .offset
            .checked_add((height - 1).checked_mul(self.row_stride)?)?
            .checked_add((width - 1).checked_mul(self.pixel_stride)?)?
            .checked_add((channels - 1).checked_mul(self.channel_stride)?)?;
        last.checked_add(1)
    }
}

/// Read-only samples: f32 or f16.
#[derive(Clone, Copy, Debug)]
pub enum Samples<'a> {
    /// 32-bit float samples.
    F32(&'a [f32]),
    /// IEEE half-float samples.
    F16(&'a [f16]),
}

impl Samples<'_> {
    fn len(&self) -> usize {
        match self {
            Samples::F32(s) => s.len(),
            Samples::F16(s) => s.len(),
        }
    }
}

/// f16 → f32, exact for every input (NaN stays NaN), branch-free so it
/// vectorises: F. Giesen's "half_to_float_fast5" (magic-number denormals).
/// `half::f16::to_f32` is a branchy software routine unless F16C is compiled in.
/// With F16C compiled in (e.g. `-C target-cpu=x86-64-v3`), `half`'s hardware
/// conversion is used instead.
#[inline(always)]
pub fn f16_to_f32(h: f16) -> f32 {
    if cfg!(all(target_arch = "x86_64", target_feature = "f16c")) {
        return h.to_f32();
    }
    const MAGIC: f32 = f32::from_bits((254 - 15) << 23); // 2^112
    let b = h.to_bits() as u32;
    let sign = (b & 0x8000) << 16;
    let em = (b & 0x7fff) << 13; // exponent + mantissa in f32 position
    let scaled = f32::from_bits(em) * MAGIC; // rebias; denormals become normal
    let inf_nan = em >= (0x7c00 << 13);
    let bits = if inf_nan { em | (0xff << 23) } else { scaled.to_bits() };
    f32::from_bits(bits | sign)
}

/// Hints that `s[i]` will be read soon (nothing when out of range or not x86-64).
#[inline(always)]
pub(crate) fn prefetch<T>(s: &[T], i: usize) {
    prefetch_into::<T, false>(s, i);
}

/// [`prefetch`] into the L2 cache only (a line further ahead than L1 can hold
/// in flight).
#[inline(always)]
pub(crate) fn prefetch_l2<T>(s: &[T], i: usize) {
    prefetch_into::<T, true>(s, i);
}

#[inline(always)]
fn prefetch_into<T, const L2: bool>(s: &[T], i: usize) {
    #[cfg(target_arch = "x86_64")]
    if i < s.len() {
        use core::arch::x86_64::{_mm_prefetch, _MM_HINT_T0, _MM_HINT_T1};
        let p = s[i..].as_ptr() as *const i8;
        // SAFETY: `p` points into the slice; a prefetch reads nothing
        // architecturally and cannot fault.
        unsafe {
            if L2 {
                _mm_prefetch(p, _MM_HINT_T1)
            } else {
                _mm_prefetch(p, _MM_HINT_T0)
            }
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (s, i);
}

/// [`prefetch`] (or with `l2`, [`prefetch_l2`]) of every 64-byte line of `s[a..b]`.
#[inline]
fn prefetch_lines<T>(s: &[T], a: usize, b: usize, l2: bool) {
    let line = (64 / core::mem::size_of::<T>()).max(1);
    let one = |i| if l2 { prefetch_l2(s, i) } else { prefetch(s, i) };
    let mut i = a;
    while i < b {
        one(i);
        i += line;
    }
    one(b.saturating_sub(1));
}

/// How far ahead (pixels) [`ImageView::read_row_n`] asks for interleaved RGB.
const DEINTERLEAVE_AHEAD: usize = 256;

/// Output images of at least this many bytes get their interleaved RGB f32
/// rows written with non-temporal (streaming) stores: far larger than the
/// caches, so writing around them saves reading each line in before it is
/// overwritten (a third of the apply stage's memory traffic). Smaller outputs
/// may well be read again from cache, so they are stored as usual.
pub const STREAM_MIN_BYTES: usize = 8 << 20;

/// Four pixels' planar `a`, `b`, `c` lanes as interleaved `[a0 b0 c0 a1]`,
/// `[b1 c1 a2 b2]`, `[c2 a3 b3 c3]` (SSE shuffles; RGB output rows).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn interleave4(
    a: core::arch::x86_64::__m128,
    b: core::arch::x86_64::__m128,
    c: core::arch::x86_64::__m128,
) -> [core::arch::x86_64::__m128; 3] {
    use core::arch::x86_64::{_mm_shuffle_ps, _mm_unpackhi_ps, _mm_unpacklo_ps};
    // SAFETY: SSE is part of x86-64; the shuffles only move register lanes.
    unsafe {
        let ab_lo = _mm_unpacklo_ps(a, b); // a0 b0 a1 b1
        let ab_hi = _mm_unpackhi_ps(a, b); // a2 b2 a3 b3

        // _mm_shuffle_ps::<imm>(x, y) = [x[i0], x[i1], y[i2], y[i3]], imm = i3 i2 i1 i0 (2 bits each)
        let c0a1 = _mm_shuffle_ps::<0b10_10_00_00>(c, ab_lo); // c0 c0 a1 a1
        let o0 = _mm_shuffle_ps::<0b10_00_01_00>(ab_lo, c0a1); // a0 b0 c0 a1
        let b1c1 = _mm_shuffle_ps::<0b01_01_11_11>(ab_lo, c); // b1 b1 c1 c1
        let o1 = _mm_shuffle_ps::<0b01_00_10_00>(b1c1, ab_hi); // b1 c1 a2 b2
        let c2a3 = _mm_shuffle_ps::<0b10_10_10_10>(c, ab_hi); // c2 c2 a3 a3
        let b3c3 = _mm_shuffle_ps::<0b11_11_11_11>(ab_hi, c); // b3 b3 c3 c3
        let o2 = _mm_shuffle_ps::<0b10_00_10_00>(c2a3, b3c3); // c2 a3 b3 c3
        [o0, o1, o2]
    }
}

/// `dst = [p0[0], p1[0], p2[0], p0[1], …]` (RGB interleave, `dst.len() ==
/// 3 * p0.len()`) with SSE non-temporal stores on the 16-byte aligned part;
/// ends with a store fence, so later stores (e.g. a flag telling another
/// thread the row is done) are ordered after these.
#[cfg(target_arch = "x86_64")]
fn interleave3_streaming(dst: &mut [f32], p0: &[f32], p1: &[f32], p2: &[f32]) {
    use core::arch::x86_64::{_mm_loadu_ps, _mm_sfence, _mm_stream_ps};
    let len = p0.len().min(p1.len()).min(p2.len()).min(dst.len() / 3);
    let scalar = |dst: &mut [f32], i: usize| dst[3 * i..3 * i + 3].copy_from_slice(&[p0[i], p1[i], p2[i]]);
    // Pixels up to the first whose start is 16-byte aligned (f32s are 4-byte
    // aligned, so one of the first four is); groups of four pixels (48 bytes)
    // from there stay aligned.
    let head = (0..4).find(|k| (dst.as_ptr() as usize + 12 * k).is_multiple_of(16)).unwrap_or(len).min(len);
    for i in 0..head {
        scalar(dst, i);
    }
    let mut i = head;
    while i + 4 <= len {
        // SAFETY: SSE is part of x86-64; the loads read p0/p1/p2[i..i + 4] and the
        // stores write dst[3i..3i + 12], all inside the slices (i + 4 <= len); each
        // store address is 16-byte aligned (dst + 12·head is, and 48 · n keeps it).
        unsafe {
            let (a, b, c) = (_mm_loadu_ps(p0.as_ptr().add(i)), _mm_loadu_ps(p1.as_ptr().add(i)), _mm_loadu_ps(p2.as_ptr().add(i)));
            let [o0, o1, o2] = interleave4(a, b, c);
            let d = dst.as_mut_ptr().add(3 * i);
            _mm_stream_ps(d, o0);
            _mm_stream_ps(d.add(4), o1);
            _mm_stream_ps(d.add(8), o2);
        }
        i += 4;
    }
    for i in i..len {
        scalar(dst, i);
    }
    // SAFETY: a store fence has no operands and no preconditions.
    unsafe { _mm_sfence() };
}

/// Widest pixel (in values) whose interleaved halves [`halves_strided`] converts
/// in bulk; wider pixels waste most of each conversion and go value by value.
const MAX_BULK_STRIDE: usize = 8;

/// Channels `0..N` of `ps`-interleaved halves into `N` f32 planes of
/// `dst[0].len()` values (`1 ≤ N ≤ ps ≤ MAX_BULK_STRIDE`): channel `c` of pixel `i`
/// is `src[i * ps + c]`, and `src` ends after the last pixel's channel `N − 1`.
/// Exact, like every f16 → f32. See [`halves_strided_ps`].
#[inline]
fn halves_strided<const N: usize>(src: &[f16], ps: usize, dst: [&mut [f32]; N]) {
    match ps {
        2 => halves_strided_ps::<N, 2>(src, dst),
        3 => halves_strided_ps::<N, 3>(src, dst),
        4 => halves_strided_ps::<N, 4>(src, dst),
        5 => halves_strided_ps::<N, 5>(src, dst),
        6 => halves_strided_ps::<N, 6>(src, dst),
        7 => halves_strided_ps::<N, 7>(src, dst),
        _ => halves_strided_ps::<N, 8>(src, dst),
    }
}

/// [`halves_strided`] for a pixel stride `PS` known at compile time: 64 pixels
/// at a time are converted in bulk into a small buffer (F16C where the CPU has
/// it; [`crate::convert`]), then picked with a constant stride, which the
/// compiler vectorises. (A conversion per value cannot be vectorised across a
/// stride: it measured 20 % of FLR's time on RGBA16F inputs.)
#[inline]
fn halves_strided_ps<const N: usize, const PS: usize>(src: &[f16], mut dst: [&mut [f32]; N]) {
    const PX: usize = 64;
    let len = dst[0].len();
    debug_assert!(N <= PS && PS <= MAX_BULK_STRIDE && dst.iter().all(|d| d.len() == len));
    let mut buf = [0f32; PX * MAX_BULK_STRIDE];
    let b = &mut buf[..PX * PS];
    let mut i = 0;
    // whole chunks of pixels (the row's last pixel may end after channel N − 1)
    while i + PX <= len && (i + PX) * PS <= src.len() {
        // the lines `DEINTERLEAVE_AHEAD` pixels ahead: without, the conversion's
        // loads waited on memory
        let ahead = (i + DEINTERLEAVE_AHEAD) * PS;
        let mut l = 0;
        while l < PX * PS {
            prefetch(src, ahead + l);
            l += 32;
        }
        crate::convert::f16_to_f32(&src[i * PS..(i + PX) * PS], b);
        for (c, d) in dst.iter_mut().enumerate() {
            for (d, px) in d[i..i + PX].iter_mut().zip(b.chunks_exact(PS)) {
                *d = px[c];
            }
        }
        i += PX;
    }
    for i in i..len {
        for (c, d) in dst.iter_mut().enumerate() {
            d[i] = f16_to_f32(src[i * PS + c]);
        }
    }
}

/// Channels 0..3 of `PS`-interleaved pixels (RGB or RGBA) into three planes of
/// `d0.len()` values; `src` ends after the last pixel's third value. Constant
/// strides, so the compiler vectorises it (a generic stride cannot be). 64
/// pixels at a time, asking for the lines `DEINTERLEAVE_AHEAD` pixels ahead
/// first: the hardware prefetchers alone left this loop waiting on memory.
#[inline]
fn deinterleave3<const PS: usize>(src: &[f32], d0: &mut [f32], d1: &mut [f32], d2: &mut [f32]) {
    let len = d0.len();
    let mut i = 0;
    while i < len {
        let e = (i + 64).min(len);
        let ahead = PS * (i + DEINTERLEAVE_AHEAD);
        let mut l = 0;
        while l < PS * 64 {
            prefetch(src, ahead + l);
            l += 16;
        }
        // whole pixels; the row's last one may lack its fourth value
        let whole = if e == len { e - 1 } else { e };
        let (a, (b, c)) = (&mut d0[i..whole], (&mut d1[i..whole], &mut d2[i..whole]));
        for (((px, a), b), c) in src[PS * i..PS * whole].chunks_exact(PS).zip(a.iter_mut()).zip(b.iter_mut()).zip(c.iter_mut()) {
            (*a, *b, *c) = (px[0], px[1], px[2]);
        }
        if whole < e {
            let px = &src[PS * whole..PS * whole + 3];
            (d0[whole], d1[whole], d2[whole]) = (px[0], px[1], px[2]);
        }
        i = e;
    }
}

/// Interleaved RGB `src` (`3 · r.len()` values) into the planes `r`, `g`, `b`
/// ([`deinterleave3`]).
pub(crate) fn deinterleave_rgb(src: &[f32], r: &mut [f32], g: &mut [f32], b: &mut [f32]) {
    deinterleave3::<3>(src, r, g, b)
}

/// Largest width or height accepted (keeps every index computation far from overflow).
pub const MAX_DIM: usize = 1 << 16;

fn check(arg: Arg, len: usize, width: usize, height: usize, channels: usize, layout: &Layout) -> Result<(), Error> {
    if width == 0 || height == 0 || width > MAX_DIM || height > MAX_DIM {
        return Err(Error::InvalidSize { arg, width, height });
    }
    if channels == 0 {
        return Err(Error::ChannelCount { arg, expected: 1, got: 0 });
    }
    let needed = layout.end(width, height, channels).ok_or(Error::InvalidStride { arg })?;
    if needed > len {
        return Err(Error::BufferTooSmall { arg, needed, len });
    }
    Ok(())
}

/// A read-only, validated view of `channels` channels of a `width`×`height` image.
#[derive(Clone, Copy, Debug)]
pub struct ImageView<'a> {
    samples: Samples<'a>,
    width: usize,
    height: usize,
    channels: usize,
    layout: Layout,
}

impl<'a> ImageView<'a> {
    /// Validates the layout against the slice. `Samples::F32(&data)` or `Samples::F16(&data)`.
    pub fn new(samples: Samples<'a>, width: usize, height: usize, channels: usize, layout: Layout) -> Result<Self, Error> {
        check(Arg::Noisy, samples.len(), width, height, channels, &layout)?;
        Ok(ImageView { samples, width, height, channels, layout })
    }
    /// Shorthand for an f32 view.
    pub fn f32(data: &'a [f32], width: usize, height: usize, channels: usize, layout: Layout) -> Result<Self, Error> {
        Self::new(Samples::F32(data), width, height, channels, layout)
    }
    /// Shorthand for an f16 view.
    pub fn f16(data: &'a [f16], width: usize, height: usize, channels: usize, layout: Layout) -> Result<Self, Error> {
        Self::new(Samples::F16(data), width, height, channels, layout)
    }
    /// Shorthand for a tightly packed, interleaved f32 image.
    pub fn interleaved(data: &'a [f32], width: usize, height: usize, channels: usize) -> Result<Self, Error> {
        Self::f32(data, width, height, channels, Layout::interleaved(width, channels))
    }
    /// The view of channels `first..first + count` of this view.
    pub fn channels(&self, first: usize, count: usize) -> Result<Self, Error> {
        if count == 0 || first.checked_add(count).is_none_or(|e| e > self.channels) {
            return Err(Error::ChannelCount { arg: Arg::Guide, expected: self.channels, got: first + count });
        }
        let mut layout = self.layout;
        layout.offset += first * layout.channel_stride;
        Ok(ImageView { channels: count, layout, ..*self })
    }
    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Channels per pixel.
    pub fn channel_count(&self) -> usize {
        self.channels
    }
    /// Where the samples lie in the slice.
    pub fn layout(&self) -> Layout {
        self.layout
    }
    /// The whole underlying slice.
    pub fn samples(&self) -> Samples<'a> {
        self.samples
    }

    /// Reads channel `c` of row `y` for pixels `x0..x0 + dst.len()` into `dst`,
    /// converting to f32. Returns `None` (and reads nothing) if out of range.
    #[inline]
    pub fn read_row(&self, y: usize, c: usize, x0: usize, dst: &mut [f32]) -> Option<()> {
        if y >= self.height || c >= self.channels || x0.checked_add(dst.len())? > self.width {
            return None;
        }
        let l = &self.layout;
        let start = l.offset + y * l.row_stride + c * l.channel_stride + x0 * l.pixel_stride;
        let ps = l.pixel_stride;
        match self.samples {
            Samples::F32(s) => {
                if ps == 1 {
                    dst.copy_from_slice(&s[start..start + dst.len()]);
                } else if ps == 3 || ps == 4 {
                    // One channel of interleaved RGB / RGBA (normals, positions): a
                    // constant stride lets the compiler vectorise the extraction
                    // (the generic stride below is one scalar load per value).
                    let n = dst.len();
                    let src = s.get(start..start + (n - 1) * ps + 1)?;
                    if ps == 3 {
                        extract_strided::<3>(src, dst);
                    } else {
                        extract_strided::<4>(src, dst);
                    }
                } else {
                    for (i, d) in dst.iter_mut().enumerate() {
                        // SAFETY: validated at construction: every (x, y, c) inside the
                        // image maps below `len`, and x0 + i < width, y < height, c < channels.
                        *d = unsafe { *s.get_unchecked(start + i * ps) };
                    }
                }
            }
            Samples::F16(s) if ps == 1 => {
                // contiguous halves: converted 8 at a time (F16C where the CPU has it)
                crate::convert::f16_to_f32(s.get(start..start + dst.len())?, dst);
            }
            Samples::F16(s) if (2..=MAX_BULK_STRIDE).contains(&ps) && !dst.is_empty() => {
                // one channel of interleaved halves (e.g. depth in an RGBA16F
                // normal buffer's fourth channel): converted in bulk, then picked
                let n = dst.len();
                halves_strided(s.get(start..start + (n - 1) * ps + 1)?, ps, [dst]);
            }
            Samples::F16(s) => {
                for (i, d) in dst.iter_mut().enumerate() {
                    // SAFETY: as above.
                    *d = f16_to_f32(unsafe { *s.get_unchecked(start + i * ps) });
                }
            }
        }
        Some(())
    }

    /// Hints that channels `0..channels` of row `y`, pixels `x0..x0 + len`
    /// (clamped to the image), will be read soon: one prefetch per 64-byte line.
    /// Reads nothing; a no-op off x86-64. For callers whose reads jump between
    /// more row streams than the hardware prefetchers follow (BMFR's blocks).
    #[inline]
    pub fn prefetch_span(&self, y: usize, x0: usize, len: usize) {
        self.prefetch_span_to(y, x0, len, false);
    }

    /// [`ImageView::prefetch_span`] into the L2 cache only: for lines wanted
    /// later than the next few thousand cycles (FLR's next band of rows).
    #[inline]
    pub fn prefetch_span_l2(&self, y: usize, x0: usize, len: usize) {
        self.prefetch_span_to(y, x0, len, true);
    }

    #[inline]
    fn prefetch_span_to(&self, y: usize, x0: usize, len: usize, l2: bool) {
        let x1 = x0.saturating_add(len).min(self.width);
        if y >= self.height || x0 >= x1 {
            return;
        }
        let l = &self.layout;
        let (ps, cs) = (l.pixel_stride, l.channel_stride);
        let start = l.offset + y * l.row_stride + x0 * ps;
        let span = (x1 - x0 - 1) * ps + 1;
        // interleaved channels share lines: one range; otherwise one range per channel
        let (ranges, extra) = if cs < ps { (1, (self.channels - 1) * cs) } else { (self.channels, 0) };
        for c in 0..ranges {
            let a = start + c * cs;
            match self.samples {
                Samples::F32(s) => prefetch_lines(s, a, a + span + extra, l2),
                Samples::F16(s) => prefetch_lines(s, a, a + span + extra, l2),
            }
        }
    }

    /// The three single-channel views `v` as one 3-channel view, when they are
    /// consecutive channels of one pixel-interleaved f32 or f16 image (interleaved
    /// RGB/RGBA normals or positions, split by [`ImageView::channels`]), so a
    /// row of all three is read in one de-interleaving pass
    /// ([`ImageView::read_row_n`]) instead of three strided ones. `None`
    /// otherwise. (Every access of the merged view is an access one of the
    /// three validated views makes: same slice, same strides, channel `c` at
    /// view `c`'s offset.)
    pub fn merged3(v: [&ImageView<'a>; 3]) -> Option<ImageView<'a>> {
        let (a, l) = (v[0], v[0].layout);
        let interleaved = l.channel_stride == 1 && (l.pixel_stride == 3 || l.pixel_stride == 4);
        let sibling = |c: usize| {
            let (b, m) = (v[c], v[c].layout);
            let same_slice = match (a.samples, b.samples) {
                (Samples::F32(s), Samples::F32(t)) => core::ptr::eq(s, t),
                (Samples::F16(s), Samples::F16(t)) => core::ptr::eq(s, t),
                _ => false,
            };
            same_slice
                && b.channels == 1
                && (b.width, b.height) == (a.width, a.height)
                && (m.pixel_stride, m.row_stride, m.channel_stride) == (l.pixel_stride, l.row_stride, l.channel_stride)
                && m.offset == l.offset + c
        };
        (a.channels == 1 && interleaved && sibling(1) && sibling(2)).then_some(ImageView { channels: 3, ..*a })
    }

    /// Channel `c` of row `y`, pixels `x0..x0 + len`, borrowed without a copy
    /// when the samples are f32 with pixel stride 1 (planar); `None` otherwise
    /// or when out of range (then use [`ImageView::read_row`]).
    #[inline]
    pub fn row_f32(&self, y: usize, c: usize, x0: usize, len: usize) -> Option<&'a [f32]> {
        if y >= self.height || c >= self.channels || x0.checked_add(len)? > self.width || self.layout.pixel_stride != 1 {
            return None;
        }
        let l = &self.layout;
        let start = l.offset + y * l.row_stride + c * l.channel_stride + x0;
        match self.samples {
            Samples::F32(s) => s.get(start..start + len),
            Samples::F16(_) => None,
        }
    }

    /// Reads channels `0..N` of row `y`, pixels `x0..x0 + len`, into `N` planes in one
    /// pass over the row (interleaved data is touched once, not once per channel).
    #[inline]
    pub fn read_row_n<const N: usize>(&self, y: usize, x0: usize, dst: [&mut [f32]; N]) -> Option<()> {
        let len = dst[0].len();
        if N == 0 || y >= self.height || N > self.channels || x0.checked_add(len)? > self.width || dst.iter().any(|d| d.len() != len) {
            return None;
        }
        if len == 0 {
            return Some(());
        }
        let l = &self.layout;
        let start = l.offset + y * l.row_stride + x0 * l.pixel_stride;
        let (ps, cs) = (l.pixel_stride, l.channel_stride);
        let mut dst = dst;
        match self.samples {
            Samples::F32(s) if cs == 1 && (ps == 3 || ps == 4) && N == 3 => {
                // Interleaved RGB / RGBA: constant strides, so the compiler vectorises
                // the de-interleave (a generic stride cannot be).
                let src = &s[start..start + (len - 1) * ps + N];
                let [d0, d1, d2] = &mut dst[..] else { return None };
                if ps == 3 {
                    deinterleave3::<3>(src, d0, d1, d2);
                } else {
                    deinterleave3::<4>(src, d0, d1, d2);
                }
            }
            Samples::F32(s) if ps == 1 => {
                // planar: each channel's row is contiguous
                for (c, d) in dst.iter_mut().enumerate() {
                    d.copy_from_slice(s.get(start + c * cs..start + c * cs + len)?);
                }
            }
            Samples::F32(s) if cs == 1 && ps == 2 && N == 2 => {
                // Interleaved pairs (motion vectors): a constant stride, as above.
                let src = s.get(start..start + 2 * len)?;
                let [d0, d1] = &mut dst[..] else { return None };
                for ((px, a), b) in src.chunks_exact(2).zip(d0.iter_mut()).zip(d1.iter_mut()) {
                    (*a, *b) = (px[0], px[1]);
                }
            }
            Samples::F32(s) => {
                for i in 0..len {
                    for (c, d) in dst.iter_mut().enumerate() {
                        // SAFETY: validated at construction (see `read_row`); i < len, c < N ≤ channels.
                        unsafe { *d.get_unchecked_mut(i) = *s.get_unchecked(start + i * ps + c * cs) };
                    }
                }
            }
            Samples::F16(_) if ps == 1 => {
                // planar: each channel's halves are contiguous, `read_row` converts them in bulk
                for (c, d) in dst.iter_mut().enumerate() {
                    self.read_row(y, c, x0, d)?;
                }
            }
            Samples::F16(s) if cs == 1 && N <= ps && ps <= MAX_BULK_STRIDE => {
                // Interleaved halves (RGB, RGBA, RG, ...): converted in bulk, then
                // de-interleaved as f32.
                halves_strided(s.get(start..start + (len - 1) * ps + N)?, ps, dst);
            }
            Samples::F16(s) => {
                for i in 0..len {
                    for (c, d) in dst.iter_mut().enumerate() {
                        // SAFETY: as above.
                        unsafe { *d.get_unchecked_mut(i) = f16_to_f32(*s.get_unchecked(start + i * ps + c * cs)) };
                    }
                }
            }
        }
        Some(())
    }

    /// The three single-channel views `a`, `b`, `c` as one 3-channel view, when
    /// they are consecutive channels of the same samples (a normal or position
    /// layer split by [`crate::Guides::channel_views`]), so that
    /// [`ImageView::read_row_n`] can read them in one pass; `None` otherwise.
    pub fn join3(a: &Self, b: &Self, c: &Self) -> Option<Self> {
        let same = |v: &Self| match (a.samples, v.samples) {
            (Samples::F32(x), Samples::F32(y)) => core::ptr::eq(x, y),
            (Samples::F16(x), Samples::F16(y)) => core::ptr::eq(x, y),
            _ => false,
        };
        let (la, lb, lc) = (a.layout, b.layout, c.layout);
        let cs = la.channel_stride;
        let ok = [b, c].iter().all(|v| same(v) && v.width == a.width && v.height == a.height && v.channels == 1)
            && a.channels == 1
            && [lb, lc].iter().all(|l| l.pixel_stride == la.pixel_stride && l.row_stride == la.row_stride && l.channel_stride == cs)
            && Some(lb.offset) == la.offset.checked_add(cs)
            && Some(lc.offset) == lb.offset.checked_add(cs);
        // Channel 1 and 2 of the joined view are exactly `b` and `c`, both validated.
        ok.then_some(ImageView { channels: 3, ..*a })
    }

    /// One element, bounds-checked (slow path, for tests and tools).
    pub fn get(&self, x: usize, y: usize, c: usize) -> Option<f32> {
        let mut v = [0.0f32];
        self.read_row(y, c, x, &mut v)?;
        Some(v[0])
    }
}

/// Mutable samples of an output image.
#[derive(Debug)]
pub enum SamplesMut<'a> {
    /// 32-bit float samples.
    F32(&'a mut [f32]),
    /// IEEE half-float samples.
    F16(&'a mut [f16]),
}

impl SamplesMut<'_> {
    fn len(&self) -> usize {
        match self {
            SamplesMut::F32(s) => s.len(),
            SamplesMut::F16(s) => s.len(),
        }
    }
}

/// A mutable, validated view of an output image.
#[derive(Debug)]
pub struct ImageViewMut<'a> {
    samples: SamplesMut<'a>,
    width: usize,
    height: usize,
    channels: usize,
    layout: Layout,
}

impl<'a> ImageViewMut<'a> {
    /// Validates the layout against the slice. Strides must be non-zero.
    pub fn new(samples: SamplesMut<'a>, width: usize, height: usize, channels: usize, layout: Layout) -> Result<Self, Error> {
        check(Arg::Output, samples.len(), width, height, channels, &layout)?;
        if layout.pixel_stride == 0 || (height > 1 && layout.row_stride == 0) || (channels > 1 && layout.channel_stride == 0) {
            return Err(Error::InvalidStride { arg: Arg::Output });
        }
        // Two pixels or channels on one element would make the output depend
        // on the write order: refused.
        if !layout.elements_distinct(width, height, channels) {
            return Err(Error::InvalidStride { arg: Arg::Output });
        }
        Ok(ImageViewMut { samples, width, height, channels, layout })
    }
    /// Shorthand for a tightly packed, interleaved f32 image.
    pub fn interleaved(data: &'a mut [f32], width: usize, height: usize, channels: usize) -> Result<Self, Error> {
        Self::new(SamplesMut::F32(data), width, height, channels, Layout::interleaved(width, channels))
    }
    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Channels per pixel.
    pub fn channel_count(&self) -> usize {
        self.channels
    }

    /// Writes `src` to channel `c` of row `y`, pixels `x0..x0 + src.len()`.
    #[inline]
    pub fn write_row(&mut self, y: usize, c: usize, x0: usize, src: &[f32]) -> Option<()> {
        if y >= self.height || c >= self.channels || x0.checked_add(src.len())? > self.width {
            return None;
        }
        let l = &self.layout;
        let start = l.offset + y * l.row_stride + c * l.channel_stride + x0 * l.pixel_stride;
        let ps = l.pixel_stride;
        match &mut self.samples {
            SamplesMut::F32(s) => {
                for (i, v) in src.iter().enumerate() {
                    // SAFETY: validated at construction (see `ImageView::read_row`).
                    unsafe { *s.get_unchecked_mut(start + i * ps) = *v };
                }
            }
            SamplesMut::F16(s) if ps == 1 => crate::convert::f32_to_f16(src, s.get_mut(start..start + src.len())?),
            SamplesMut::F16(s) => {
                for (i, v) in src.iter().enumerate() {
                    // SAFETY: as above.
                    unsafe { *s.get_unchecked_mut(start + i * ps) = f16::from_f32(*v) };
                }
            }
        }
        Some(())
    }

    /// Writes `N` planes to channels `0..N` of row `y` in one pass over the row.
    #[inline]
    pub fn write_row_n<const N: usize>(&mut self, y: usize, x0: usize, src: [&[f32]; N]) -> Option<()> {
        let len = src[0].len();
        if N == 0 || y >= self.height || N > self.channels || x0.checked_add(len)? > self.width || src.iter().any(|d| d.len() != len) {
            return None;
        }
        if len == 0 {
            return Some(());
        }
        let l = &self.layout;
        let start = l.offset + y * l.row_stride + x0 * l.pixel_stride;
        let (ps, cs) = (l.pixel_stride, l.channel_stride);
        match &mut self.samples {
            SamplesMut::F32(s) if cs == 1 && ps == 3 && N == 3 => {
                // Interleaved RGB: constant strides, vectorised interleave.
                #[cfg(target_arch = "x86_64")]
                let streaming = core::mem::size_of_val(*s) >= STREAM_MIN_BYTES;
                let dst = &mut s[start..start + 3 * len];
                let [p0, p1, p2] = &src[..] else { return None };
                // (An AVX2 permute/blend version measured no faster: the stores wait on memory.)
                #[cfg(target_arch = "x86_64")]
                if streaming {
                    interleave3_streaming(dst, p0, p1, p2);
                    return Some(());
                }
                for (((px, a), b), c) in dst.chunks_exact_mut(3).zip(p0.iter()).zip(p1.iter()).zip(p2.iter()) {
                    px.copy_from_slice(&[*a, *b, *c]);
                }
            }
            SamplesMut::F32(s) if cs == 1 && ps == 4 && N == 3 => {
                // Interleaved RGBA: the same, the fourth channel left as it was.
                let dst = &mut s[start..start + 4 * (len - 1) + 3];
                let [p0, p1, p2] = &src[..] else { return None };
                let whole = len - 1; // the last pixel's slice ends after its third value
                for (((px, a), b), c) in dst.chunks_exact_mut(4).zip(&p0[..whole]).zip(&p1[..whole]).zip(&p2[..whole]) {
                    px[..3].copy_from_slice(&[*a, *b, *c]);
                }
                dst[4 * whole..].copy_from_slice(&[p0[whole], p1[whole], p2[whole]]);
            }
            SamplesMut::F32(s) => {
                for i in 0..len {
                    for (c, p) in src.iter().enumerate() {
                        // SAFETY: validated at construction; i < len ≤ width − x0, c < N ≤ channels.
                        unsafe { *s.get_unchecked_mut(start + i * ps + c * cs) = *p.get_unchecked(i) };
                    }
                }
            }
            SamplesMut::F16(s) if cs == 1 && (ps == 3 || ps == 4) && N == 3 => {
                // Interleaved RGB / RGBA halves: 16 pixels at a time interleaved
                // into a small f32 buffer, then converted in bulk (an RGBA
                // pixel's fourth channel is left as it was).
                const PX: usize = 16;
                let dst = s.get_mut(start..start + (len - 1) * ps + N)?;
                let [p0, p1, p2] = &src[..] else { return None };
                let mut buf = [0f32; PX * 3];
                let mut halves = [f16::ZERO; PX * 3];
                let mut i = 0;
                while i < len {
                    let e = (i + PX).min(len);
                    let b = &mut buf[..3 * (e - i)];
                    for (j, px) in b.chunks_exact_mut(3).enumerate() {
                        px.copy_from_slice(&[p0[i + j], p1[i + j], p2[i + j]]);
                    }
                    let h = &mut halves[..3 * (e - i)];
                    crate::convert::f32_to_f16(b, h);
                    if ps == 3 {
                        dst[3 * i..3 * e].copy_from_slice(h);
                    } else {
                        for (j, px) in h.chunks_exact(3).enumerate() {
                            dst[4 * (i + j)..4 * (i + j) + 3].copy_from_slice(px);
                        }
                    }
                    i = e;
                }
            }
            SamplesMut::F16(s) => {
                for i in 0..len {
                    for (c, p) in src.iter().enumerate() {
                        // SAFETY: as above.
                        unsafe { *s.get_unchecked_mut(start + i * ps + c * cs) = f16::from_f32(*p.get_unchecked(i)) };
                    }
                }
            }
        }
        Some(())
    }

    /// A view of rows `y0..y0 + n` (reborrowed; rows numbered from 0).
    pub fn rows(&mut self, y0: usize, n: usize) -> Result<ImageViewMut<'_>, Error> {
        if n == 0 || y0.checked_add(n).is_none_or(|e| e > self.height) {
            return Err(Error::InvalidTile { index: y0, count: self.height });
        }
        let mut layout = self.layout;
        layout.offset += y0 * layout.row_stride;
        let samples = match &mut self.samples {
            SamplesMut::F32(s) => SamplesMut::F32(s),
            SamplesMut::F16(s) => SamplesMut::F16(s),
        };
        Ok(ImageViewMut { samples, width: self.width, height: n, channels: self.channels, layout })
    }

    /// Row `y` as `3 · width` values when the image is interleaved RGB f32
    /// (pixel stride 3, channel stride 1), for a kernel that interleaves as it
    /// computes; and whether rows of this image are best written with
    /// non-temporal stores (x86-64, at least [`STREAM_MIN_BYTES`], as
    /// [`Self::write_row_n`] does). `None` for any other layout.
    pub fn rgb_row_f32(&mut self, y: usize) -> Option<(&mut [f32], bool)> {
        let l = self.layout;
        let SamplesMut::F32(s) = &mut self.samples else { return None };
        if y >= self.height || l.pixel_stride != 3 || l.channel_stride != 1 || self.channels < 3 {
            return None;
        }
        let streaming = cfg!(target_arch = "x86_64") && core::mem::size_of_val(*s) >= STREAM_MIN_BYTES;
        let start = l.offset + y * l.row_stride;
        Some((s.get_mut(start..start + 3 * self.width)?, streaming))
    }

    /// Whether each row's elements lie in `[offset + y*row_stride, offset + (y+1)*row_stride)`,
    /// so that row bands are disjoint sub-slices and can be written in parallel.
    pub fn rows_are_separable(&self) -> bool {
        let l = &self.layout;
        let extent = (self.width - 1) * l.pixel_stride + (self.channels - 1) * l.channel_stride + 1;
        self.height == 1 || extent <= l.row_stride
    }

    /// Splits off rows `0..rows` into their own view; `self` keeps the rest.
    /// Requires [`Self::rows_are_separable`]. Row numbering of both views starts at 0.
    pub fn split_rows(self, rows: usize) -> Result<(Self, Option<Self>), Error> {
        if rows == 0 || rows > self.height {
            return Err(Error::InvalidTile { index: rows, count: self.height });
        }
        if rows == self.height {
            return Ok((self, None));
        }
        if !self.rows_are_separable() {
            return Err(Error::Unsupported("output rows overlap in memory; cannot split into bands"));
        }
        let at = self.layout.offset + rows * self.layout.row_stride;
        let (w, h, c, l) = (self.width, self.height, self.channels, self.layout);
        let top_layout = l;
        let bottom_layout = Layout { offset: 0, ..l };
        let (top, bottom) = match self.samples {
            SamplesMut::F32(s) => {
                let (a, b) = s.split_at_mut(at);
                (SamplesMut::F32(a), SamplesMut::F32(b))
            }
            SamplesMut::F16(s) => {
                let (a, b) = s.split_at_mut(at);
                (SamplesMut::F16(a), SamplesMut::F16(b))
            }
        };
        let top = ImageViewMut::new(top, w, rows, c, top_layout)?;
        let bottom = ImageViewMut::new(bottom, w, h - rows, c, bottom_layout)?;
        Ok((top, Some(bottom)))
    }
}

/// Row bands of one output image for concurrent writers: each band is a view
/// of its own rows only. Made from an image whose rows do not overlap.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
#[derive(Debug)]
pub(crate) struct RowBands<'a, 'o> {
    f32s: Option<*mut f32>,
    f16s: Option<*mut f16>,
    width: usize,
    height: usize,
    channels: usize,
    layout: Layout,
    _out: core::marker::PhantomData<&'a mut ImageViewMut<'o>>,
}

// SAFETY: a band is made only through the unsafe `band`, whose callers keep
// the bands of concurrent threads apart; the output is borrowed mutably for 'a.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
unsafe impl Sync for RowBands<'_, '_> {}

#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
impl<'a, 'o> RowBands<'a, 'o> {
    /// Bands of `out`; `None` unless its rows are separable.
    pub(crate) fn new(out: &'a mut ImageViewMut<'o>) -> Option<Self> {
        if !out.rows_are_separable() {
            return None;
        }
        let (f32s, f16s) = match &mut out.samples {
            SamplesMut::F32(s) => (Some(s.as_mut_ptr()), None),
            SamplesMut::F16(s) => (None, Some(s.as_mut_ptr())),
        };
        Some(RowBands {
            f32s,
            f16s,
            width: out.width,
            height: out.height,
            channels: out.channels,
            layout: out.layout,
            _out: core::marker::PhantomData,
        })
    }

    /// Rows `y0..y0 + n` as a view of their own.
    ///
    /// # Safety
    /// No other live view made by this `RowBands` covers any of these rows.
    pub(crate) unsafe fn band(&self, y0: usize, n: usize) -> Result<ImageViewMut<'a>, Error> {
        if n == 0 || y0.checked_add(n).is_none_or(|e| e > self.height) {
            return Err(Error::InvalidTile { index: y0, count: self.height });
        }
        let l = self.layout;
        let start = l.offset + y0 * l.row_stride;
        // elements of the band's last row, and of the rows before it
        let extent = (self.width - 1) * l.pixel_stride + (self.channels - 1) * l.channel_stride + 1;
        let len = (n - 1) * l.row_stride + extent;
        let layout = Layout { offset: 0, ..l };
        // SAFETY: rows are separable (checked in `new`), so rows y0..y0+n lie
        // in [start, start + len) inside the image's slice, which no other band
        // covers (the caller's contract); the slice lives for 'a.
        let samples = unsafe {
            match (self.f32s, self.f16s) {
                (Some(p), _) => SamplesMut::F32(core::slice::from_raw_parts_mut(p.add(start), len)),
                (_, Some(p)) => SamplesMut::F16(core::slice::from_raw_parts_mut(p.add(start), len)),
                _ => return Err(Error::InvalidStride { arg: Arg::Output }),
            }
        };
        ImageViewMut::new(samples, self.width, n, self.channels, layout)
    }
}

/// `dst[i] = src[i · P]` for every `i` (`src` holds at least `(len − 1)·P + 1` values).
#[inline(always)]
fn extract_strided<const P: usize>(src: &[f32], dst: &mut [f32]) {
    let n = dst.len();
    let whole = (src.len() / P).min(n);
    for (d, px) in dst[..whole].iter_mut().zip(src.chunks_exact(P)) {
        *d = px[0];
    }
    for (i, d) in dst.iter_mut().enumerate().skip(whole) {
        *d = src[i * P];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads channels 0..3 of row 1, pixels `x0..x0 + len`, with `read_row_n`
    /// and asserts each value equals element access (`get`); returns the planes.
    fn read3_equals_get<const W: usize>(v: &ImageView<'_>, x0: usize, len: usize) -> [[f32; W]; 3] {
        let mut p = [[0f32; W]; 3];
        let [a, b, c] = &mut p;
        v.read_row_n(1, x0, [&mut a[..len], &mut b[..len], &mut c[..len]]).unwrap();
        for i in 0..len {
            for (ch, plane) in p.iter().enumerate() {
                assert_eq!(Some(plane[i]), v.get(x0 + i, 1, ch), "x0 {x0} len {len} i {i}");
            }
        }
        p
    }

    /// RGBA f32 rows (the fourth channel skipped on reads and left as it was
    /// on writes) equal element access, around the 64-pixel read chunks, on a
    /// buffer that ends right after the last pixel's third channel.
    #[test]
    fn rgba_rows_equal_element_access() {
        const W: usize = 300;
        const LEN: usize = W * 2 * 4 - 1;
        let data: [f32; LEN] = core::array::from_fn(|i| i as f32 * 0.25);
        let v = ImageView::f32(&data, W, 2, 3, Layout::interleaved(W, 4)).unwrap();
        for x0 in [0usize, 1, 63, 64, 100] {
            for len in [0usize, 1, 7, 63, 64, 65, 129, 200] {
                let p = read3_equals_get::<W>(&v, x0, len);
                let mut out = [-1f32; LEN];
                let mut o = ImageViewMut::new(SamplesMut::F32(&mut out), W, 2, 3, Layout::interleaved(W, 4)).unwrap();
                o.write_row_n(1, x0, [&p[0][..len], &p[1][..len], &p[2][..len]]).unwrap();
                for (i, got) in out.iter().enumerate() {
                    let (x, ch) = ((i % (4 * W)) / 4, i % 4);
                    let written = i >= 4 * W && ch < 3 && (x0..x0 + len).contains(&x);
                    let want = if written { data[i] } else { -1.0 };
                    assert_eq!(*got, want, "x0 {x0} len {len} at {i}");
                }
            }
        }
    }

    /// RGB rows of an output large enough for streaming stores
    /// ([`STREAM_MIN_BYTES`]) land exactly where element access puts them, and
    /// nothing else changes, at every alignment of the buffer and of the row
    /// start, and at lengths around the 4-pixel groups.
    #[test]
    fn streamed_rgb_rows_equal_element_access() {
        const W: usize = 1024;
        let h = STREAM_MIN_BYTES / (3 * 4 * W) + 1;
        let vals: [f32; 3 * 67] = core::array::from_fn(|i| i as f32 + 0.5);
        extern crate std;
        let mut buf = std::vec![-1f32; 3 * W * h + 4];
        for shift in 0..4 {
            let data = &mut buf[shift..shift + 3 * W * h];
            let mut o = ImageViewMut::interleaved(data, W, h, 3).unwrap();
            let cases = [(0usize, 0usize), (0, 1), (1, 3), (2, 4), (3, 5), (5, 9), (0, 64), (7, 67)];
            for (row, &(x0, len)) in cases.iter().enumerate() {
                let [a, b, c] = [&vals[..len], &vals[67..67 + len], &vals[134..134 + len]];
                o.write_row_n(row, x0, [a, b, c]).unwrap();
            }
            for (row, &(x0, len)) in cases.iter().enumerate() {
                for x in 0..W {
                    for ch in 0..3 {
                        let want = if (x0..x0 + len).contains(&x) { vals[67 * ch + x - x0] } else { -1.0 };
                        assert_eq!(data[3 * (row * W + x) + ch], want, "shift {shift} row {row} x {x} ch {ch}");
                    }
                }
            }
            assert!(data[3 * W * cases.len()..].iter().all(|&v| v == -1.0), "shift {shift}: rows below were written");
            data.fill(-1.0);
        }
    }

    /// One channel, and the first N channels, of interleaved halves with any
    /// pixel stride (the bulk path up to 8 values per pixel, value by value
    /// beyond): the bits of `half`'s software conversion of each element,
    /// around the 16-pixel chunks, on buffers that end right after the last
    /// value the view covers, for every kind of half (NaN, ±∞, subnormal).
    #[test]
    fn f16_strided_rows_match_per_element_conversion() {
        const W: usize = 37;
        const H: usize = 2;
        let all: [f16; 9 * W * H] = core::array::from_fn(|i| f16::from_bits(((i as u32).wrapping_mul(2_654_435_761) >> 16) as u16));
        let same = |got: f32, h: f16| {
            let want = h.to_f32_const();
            if want.is_nan() {
                got.is_nan()
            } else {
                got.to_bits() == want.to_bits()
            }
        };
        for ps in [2usize, 3, 4, 5, 8, 9] {
            for channels in 1..=ps.min(4) {
                // the view's channels start at `offset` (e.g. depth in an RGBA
                // buffer's fourth value: ps 4, offset 3, one channel)
                for offset in [0usize, ps - channels] {
                    let layout = Layout { offset, ..Layout::interleaved(W, ps) };
                    let n = offset + (H - 1) * W * ps + (W - 1) * ps + channels;
                    let v = ImageView::f16(&all[..n], W, H, channels, layout).unwrap();
                    for (x0, len) in [(0usize, 0usize), (0, 1), (1, 15), (3, 16), (0, 17), (4, 33), (0, W)] {
                        for c in 0..channels {
                            let mut r = [0f32; W];
                            v.read_row(H - 1, c, x0, &mut r[..len]).unwrap();
                            for (i, &got) in r[..len].iter().enumerate() {
                                let at = offset + (H - 1) * W * ps + (x0 + i) * ps + c;
                                assert!(same(got, all[at]), "ps {ps} ch {channels} offset {offset} c {c} x0 {x0} i {i}");
                            }
                        }
                        let mut p = [[0f32; W]; 4];
                        let [a, b, c, d] = &mut p;
                        match channels {
                            1 => v.read_row_n(H - 1, x0, [&mut a[..len]]),
                            2 => v.read_row_n(H - 1, x0, [&mut a[..len], &mut b[..len]]),
                            3 => v.read_row_n(H - 1, x0, [&mut a[..len], &mut b[..len], &mut c[..len]]),
                            _ => v.read_row_n(H - 1, x0, [&mut a[..len], &mut b[..len], &mut c[..len], &mut d[..len]]),
                        }
                        .unwrap();
                        for (k, plane) in p[..channels].iter().enumerate() {
                            for (i, &got) in plane[..len].iter().enumerate() {
                                let at = offset + (H - 1) * W * ps + (x0 + i) * ps + k;
                                assert!(same(got, all[at]), "N: ps {ps} ch {channels} offset {offset} k {k} x0 {x0} i {i}");
                            }
                        }
                    }
                }
            }
        }
    }

    /// Half-precision rows: `read_row`, `read_row_n`, `write_row` and
    /// `write_row_n` (bulk conversions, F16C where the CPU has it) give the
    /// bits of `half`'s software conversion per element, for planar, RGB and
    /// RGBA layouts, around the 8- and 16-value chunks; an RGBA pixel's fourth
    /// channel is left as it was.
    #[test]
    fn f16_rows_match_per_element_conversion() {
        const W: usize = 41;
        let vals: [f32; 4 * W * 2] = core::array::from_fn(|i| ((i * 7919) % 997) as f32 * 0.37 - 150.0 + (i % 3) as f32 * 1e-3);
        for ch in [3usize, 4] {
            let halves: [f16; 4 * W * 2] = core::array::from_fn(|i| f16::from_f32_const(vals[i]));
            let n = ch * W * 2;
            let v = ImageView::f16(&halves[..n], W, 2, ch, Layout::interleaved(W, ch)).unwrap();
            let planar = ImageView::f16(&halves[..n], W, 2, ch, Layout::planar(W, 2)).unwrap();
            for (x0, len) in [(0usize, 1usize), (0, 8), (1, 15), (3, 16), (0, 17), (5, 33), (0, W)] {
                let mut p = [[0f32; W]; 3];
                let [a, b, c] = &mut p;
                v.read_row_n(1, x0, [&mut a[..len], &mut b[..len], &mut c[..len]]).unwrap();
                let mut r = [0f32; W];
                planar.read_row(1, 2, x0, &mut r[..len]).unwrap();
                for i in 0..len {
                    for (k, plane) in p.iter().enumerate() {
                        assert_eq!(plane[i].to_bits(), halves[W * ch + (x0 + i) * ch + k].to_f32_const().to_bits());
                    }
                    assert_eq!(r[i].to_bits(), halves[2 * W * 2 + W + x0 + i].to_f32_const().to_bits());
                }
                let mut out = [f16::from_f32_const(-7.0); 4 * W * 2];
                let mut o = ImageViewMut::new(SamplesMut::F16(&mut out[..n]), W, 2, ch, Layout::interleaved(W, ch)).unwrap();
                let src: [&[f32]; 3] = [&vals[..len], &vals[W..W + len], &vals[2 * W..2 * W + len]];
                o.write_row_n(1, x0, src).unwrap();
                for x in 0..W {
                    for k in 0..ch {
                        let got = out[W * ch + x * ch + k];
                        let want = if (x0..x0 + len).contains(&x) && k < 3 {
                            f16::from_f32_const(src[k][x - x0])
                        } else {
                            f16::from_f32_const(-7.0)
                        };
                        assert_eq!(got.to_bits(), want.to_bits(), "ch {ch} x0 {x0} len {len} x {x} k {k}");
                    }
                }
                let mut out = [f16::from_f32_const(-7.0); 4 * W * 2];
                let mut o = ImageViewMut::new(SamplesMut::F16(&mut out[..n]), W, 2, ch, Layout::planar(W, 2)).unwrap();
                o.write_row(1, 1, x0, &vals[..len]).unwrap();
                for x in 0..W {
                    let want = if (x0..x0 + len).contains(&x) { f16::from_f32_const(vals[x - x0]) } else { f16::from_f32_const(-7.0) };
                    assert_eq!(out[W * 2 + W + x].to_bits(), want.to_bits());
                }
            }
        }
    }

    /// The chunked RGB de-interleave (with its prefetches) equals element reads,
    /// for lengths and starts around its 64-pixel chunks.
    #[test]
    fn read_row_n_rgb_equals_get() {
        const W: usize = 300;
        let data: [f32; W * 2 * 3] = core::array::from_fn(|i| i as f32 * 0.5);
        let v = ImageView::interleaved(&data, W, 2, 3).unwrap();
        for x0 in [0usize, 1, 63, 64, 100] {
            for len in [1usize, 7, 63, 64, 65, 129, 200] {
                read3_equals_get::<W>(&v, x0, len);
            }
        }
        let mut p = [[0f32; W]; 3];
        let [a, b, c] = &mut p;
        assert!(v.read_row_n(1, 290, [&mut a[..11], &mut b[..11], &mut c[..11]]).is_none(), "past the row's end");
    }

    /// `read_row_n` of two channels (motion vectors: the pairs' fast path,
    /// two channels of RGB / RGBA, and planar channels) gives `get`'s values,
    /// at offsets into the buffer, on buffers that end right after the last
    /// value the view covers.
    #[test]
    fn read_row_n_pairs_equal_get() {
        const W: usize = 257;
        const H: usize = 2;
        let data: [f32; W * H * 4 + 8] = core::array::from_fn(|i| i as f32 * 0.25 - 7.0);
        let layouts = [2usize, 3, 4].map(|ps| Layout::interleaved(W, ps)).into_iter().chain([Layout::planar(W, H)]);
        for layout in layouts.flat_map(|l| [0usize, 3].map(|offset| Layout { offset, ..l })) {
            let last = layout.offset + (H - 1) * layout.row_stride + (W - 1) * layout.pixel_stride + layout.channel_stride;
            let v = ImageView::new(Samples::F32(&data[..last + 1]), W, H, 2, layout).unwrap();
            for (x0, len) in [(0usize, 1usize), (0, 7), (1, 64), (5, 200), (0, W), (W - 1, 1)] {
                let (mut a, mut b) = ([0f32; W], [0f32; W]);
                v.read_row_n(H - 1, x0, [&mut a[..len], &mut b[..len]]).unwrap();
                for i in 0..len {
                    assert_eq!((Some(a[i]), Some(b[i])), (v.get(x0 + i, H - 1, 0), v.get(x0 + i, H - 1, 1)), "{layout:?} x0 {x0} i {i}");
                }
            }
            let (mut a, mut b) = ([0f32; 8], [0f32; 8]);
            assert!(v.read_row_n(1, W - 4, [&mut a[..], &mut b[..]]).is_none(), "past the row's end");
        }
    }
}
