//! The caller's images and frames (`LrdImage`, `LrdFrame`, ...) as library
//! views: layout and alignment checks, the overlap checks of the output
//! against every other buffer of a call, and the scratch pointer check.

use crate::status::{status_of, LrdStatus, LrdStatus::*};
#[cfg(doc)]
use crate::LrdFlrConfig;
use core::ffi::c_void;
use lrdenoise_core::{Frame, GuideSet, Guides, ImageView, ImageViewMut, Layout};

/// Sample format of an image.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LrdFormat {
    /// IEEE 754 binary32 (`float`): 4-byte elements, 4-byte aligned.
    LRD_FORMAT_F32 = 0,
    /// IEEE 754 binary16 (half): 2-byte elements, 2-byte aligned.
    LRD_FORMAT_F16 = 1,
}

/// A read-only image, OIDN-style. `data == NULL` means "absent" (for guides).
/// Strides are in bytes; 0 means "packed": `channel_stride` = element size,
/// `pixel_stride` = channels × element size, `row_stride` = width × pixel_stride.
/// The buffer must span `(height−1)·row_stride + (width−1)·pixel_stride +
/// (channels−1)·channel_stride + element size` bytes and be aligned to the element size.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdImage {
    /// First element: channel 0 of pixel (0, 0). Aligned to the element size.
    /// NULL marks an absent guide; the noisy image must not be NULL.
    pub data: *const c_void,
    /// An LrdFormat value (LRD_FORMAT_F32 or LRD_FORMAT_F16); any other value
    /// returns LRD_STATUS_INVALID_ARGUMENT.
    pub format: u32,
    /// Width in pixels, > 0.
    pub width: u32,
    /// Height in pixels, > 0.
    pub height: u32,
    /// Bytes from one pixel to the next in a row, a multiple of the element
    /// size; 0: channels × `channel_stride` (packed). A larger stride skips
    /// extra channels (e.g. the alpha of RGBA).
    pub pixel_stride: usize,
    /// Bytes from one row to the next, a multiple of the element size;
    /// 0: `width` × `pixel_stride`.
    pub row_stride: usize,
    /// Bytes from one channel to the next within a pixel, a multiple of the
    /// element size; 0: the element size (interleaved). Planar images set it
    /// to the distance between planes in bytes and `pixel_stride` to the
    /// element size.
    pub channel_stride: usize,
}

/// A writable image (the output), same conventions as [`LrdImage`].
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdImageMut {
    /// First element: channel 0 of pixel (0, 0); not NULL, aligned to the
    /// element size. Receives RGB (3 channels). The image must not overlap
    /// any other buffer of the call, and no two of its elements may share
    /// memory (LRD_STATUS_INVALID_ARGUMENT).
    pub data: *mut c_void,
    /// An LrdFormat value (LRD_FORMAT_F32 or LRD_FORMAT_F16).
    pub format: u32,
    /// Width in pixels, > 0: the output size the call denoises to.
    pub width: u32,
    /// Height in pixels, > 0.
    pub height: u32,
    /// Bytes from one pixel to the next in a row (0: 3 × `channel_stride`);
    /// a larger stride leaves extra channels (e.g. alpha) untouched.
    pub pixel_stride: usize,
    /// Bytes from one row to the next (0: `width` × `pixel_stride`).
    pub row_stride: usize,
    /// Bytes from one channel to the next within a pixel (0: the element size).
    pub channel_stride: usize,
}

/// Guide images of one frame; absent guides have `data == NULL`.
/// normal: 3 channels, depth: 1, position: 3, ao: 1, user: 1 each.
/// The guides present must be exactly the call's guide set (the
/// configuration's `guides` bits and `user_guides`; FLNR: normal, depth and
/// AO), else LRD_STATUS_GUIDE_MISMATCH.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdGuides {
    /// Shading normal (x, y, z), 3 channels (LRD_GUIDE_NORMAL).
    pub normal: LrdImage,
    /// Camera distance, 1 channel (LRD_GUIDE_DEPTH).
    pub depth: LrdImage,
    /// World-space position (x, y, z), 3 channels (LRD_GUIDE_POSITION).
    pub position: LrdImage,
    /// Ambient occlusion in [0, 1] (0: occluded, 1: open), 1 channel (LRD_GUIDE_AO).
    pub ao: LrdImage,
    /// Single-channel user guides: the first `user_guides` (configuration)
    /// entries present, the rest NULL.
    pub user: [LrdImage; 4],
}

/// One frame: noisy RGB (3 channels) and its guides. `guides_low`, if any of
/// its `data` is set, holds the guides the regression is fitted on, at the
/// noisy image's resolution: for joint denoise + upsample (config.upsample > 1)
/// the low-resolution guides; at upsample 1 a second guide set (the model is
/// then applied to `guides`). Leave all its `data` NULL for plain FLR.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdFrame {
    /// Noisy RGB, 3 channels (not NULL): the output's size, or for FLR
    /// with `upsample` > 1 the output's size / upsample, rounded up.
    pub noisy: LrdImage,
    /// Guides at the output's size.
    pub guides: LrdGuides,
    /// FLR only: guides at the noisy image's size (see above); all `data`
    /// NULL otherwise (BMFR, WALR and FLNR return LRD_STATUS_UNSUPPORTED if
    /// any is set).
    pub guides_low: LrdGuides,
    /// Single-frame FLR only: per-pixel sample weights of the fit, 1 channel
    /// at the noisy image's size, or `data` NULL for none. Each pixel counts
    /// `w` times in its windows: a pixel's sample count under adaptive
    /// sampling, or 0 for a pixel without a sample this frame (it is then
    /// predicted from its neighbours through its guides). A weight that is
    /// not finite and positive excludes its pixel; only ratios matter. The
    /// firefly clamp still measures every finite pixel. FLNR, BMFR, WALR and
    /// the temporal pipelines return LRD_STATUS_UNSUPPORTED when it is set.
    pub sample_weights: LrdImage,
}

/// Guide bits for [`LrdFlrConfig::guides`] and the `guides` of LrdBmfrConfig
/// and LrdWalrConfig; other bits return LRD_STATUS_INVALID_CONFIG.
/// LRD_GUIDE_NORMAL: the normal guide (`LrdGuides.normal`, 3 channels).
pub const LRD_GUIDE_NORMAL: u32 = 1;
/// Guide bit: the depth guide (`LrdGuides.depth`, 1 channel).
pub const LRD_GUIDE_DEPTH: u32 = 2;
/// Guide bit: the world-position guide (`LrdGuides.position`, 3 channels).
pub const LRD_GUIDE_POSITION: u32 = 4;
/// Guide bit: the ambient-occlusion guide (`LrdGuides.ao`, 1 channel).
pub const LRD_GUIDE_AO: u32 = 8;

/// Element layout of an image: (element size, channel/pixel/row strides in elements, elements spanned).
fn layout_of(
    data: *const c_void,
    format: u32,
    w: u32,
    h: u32,
    ch: usize,
    strides: (usize, usize, usize),
) -> Result<(usize, Layout, usize), LrdStatus> {
    let elem = match format {
        0 => 4usize,
        1 => 2usize,
        _ => return Err(LRD_STATUS_INVALID_ARGUMENT),
    };
    let (ps, rs, cs) = strides;
    if w == 0 || h == 0 || !(data as usize).is_multiple_of(elem) {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    let cs = if cs == 0 { elem } else { cs };
    let ps = if ps == 0 { ch.checked_mul(cs).ok_or(LRD_STATUS_INVALID_ARGUMENT)? } else { ps };
    let rs = if rs == 0 { (w as usize).checked_mul(ps).ok_or(LRD_STATUS_INVALID_ARGUMENT)? } else { rs };
    if ps % elem != 0 || rs % elem != 0 || cs % elem != 0 {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    let layout = Layout { offset: 0, pixel_stride: ps / elem, row_stride: rs / elem, channel_stride: cs / elem };
    let span = (h as usize - 1)
        .checked_mul(layout.row_stride)
        .and_then(|a| a.checked_add((w as usize - 1).checked_mul(layout.pixel_stride)?))
        .and_then(|a| a.checked_add((ch - 1).checked_mul(layout.channel_stride)?))
        .and_then(|a| a.checked_add(1))
        .filter(|&n| n.checked_mul(elem).is_some_and(|b| b <= isize::MAX as usize))
        .ok_or(LRD_STATUS_INVALID_ARGUMENT)?;
    Ok((elem, layout, span))
}

/// A view of `img` with `ch` channels, or `None` if `img.data` is NULL.
///
/// # Safety
/// `img.data`, if not NULL, must point to a buffer spanning its layout (see
/// [`LrdImage`]) that stays valid and unmodified for `'a`.
pub(crate) unsafe fn view<'a>(img: &LrdImage, ch: usize) -> Result<Option<ImageView<'a>>, LrdStatus> {
    if img.data.is_null() {
        return Ok(None);
    }
    let (elem, layout, span) =
        layout_of(img.data, img.format, img.width, img.height, ch, (img.pixel_stride, img.row_stride, img.channel_stride))?;
    let (w, h) = (img.width as usize, img.height as usize);
    let v = if elem == 4 {
        // SAFETY: non-null, aligned (checked), spans `span` elements (caller's contract).
        let s = unsafe { core::slice::from_raw_parts(img.data as *const f32, span) };
        ImageView::f32(s, w, h, ch, layout)
    } else {
        // SAFETY: as above, for 2-byte elements.
        let s = unsafe { core::slice::from_raw_parts(img.data as *const half::f16, span) };
        ImageView::f16(s, w, h, ch, layout)
    };
    v.map(Some).map_err(status_of)
}

/// A mutable view of output rows `y0..y0 + rows`.
///
/// # Safety
/// `img.data` must point to a buffer spanning its layout, valid for `'a`, and no
/// other live reference may overlap the elements this band spans.
pub(crate) unsafe fn view_mut<'a>(img: &LrdImageMut, y0: usize, rows: usize) -> Result<ImageViewMut<'a>, LrdStatus> {
    if img.data.is_null() {
        return Err(LRD_STATUS_NULL_POINTER);
    }
    let (elem, layout, _) =
        layout_of(img.data, img.format, img.width, img.height, 3, (img.pixel_stride, img.row_stride, img.channel_stride))?;
    if rows == 0 || y0 + rows > img.height as usize {
        return Err(LRD_STATUS_INVALID_TILE);
    }
    let w = img.width as usize;
    let extent = (w - 1) * layout.pixel_stride + 2 * layout.channel_stride + 1;
    let span = (rows - 1) * layout.row_stride + extent;
    let base = y0 * layout.row_stride;
    let v = if elem == 4 {
        // SAFETY: inside the caller's buffer (band of the validated layout), aligned.
        let s = unsafe { core::slice::from_raw_parts_mut((img.data as *mut f32).add(base), span) };
        ImageViewMut::new(lrdenoise_core::SamplesMut::F32(s), w, rows, 3, layout)
    } else {
        // SAFETY: as above.
        let s = unsafe { core::slice::from_raw_parts_mut((img.data as *mut half::f16).add(base), span) };
        ImageViewMut::new(lrdenoise_core::SamplesMut::F16(s), w, rows, 3, layout)
    };
    v.map_err(status_of)
}

/// # Safety
/// Every non-NULL image in `g` must satisfy the contract of [`view`].
unsafe fn guides<'a>(g: &LrdGuides) -> Result<Guides<'a>, LrdStatus> {
    // SAFETY: forwarded contract.
    unsafe {
        let mut user = [None; 4];
        for (u, img) in user.iter_mut().zip(&g.user) {
            *u = view(img, 1)?;
        }
        Ok(Guides { normal: view(&g.normal, 3)?, depth: view(&g.depth, 1)?, position: view(&g.position, 3)?, ao: view(&g.ao, 1)?, user })
    }
}

fn all_null(g: &LrdGuides) -> bool {
    [&g.normal, &g.depth, &g.position, &g.ao].iter().all(|i| i.data.is_null()) && g.user.iter().all(|i| i.data.is_null())
}

pub(crate) fn guide_set(bits: u32, user: u32) -> Result<GuideSet, LrdStatus> {
    if bits & !15 != 0 || user > 4 {
        return Err(LRD_STATUS_INVALID_CONFIG);
    }
    Ok(GuideSet {
        normal: bits & LRD_GUIDE_NORMAL != 0,
        depth: bits & LRD_GUIDE_DEPTH != 0,
        position: bits & LRD_GUIDE_POSITION != 0,
        ao: bits & LRD_GUIDE_AO != 0,
        user: user as u8,
    })
}

/// A frame's images as library views (`guides_low` must be absent unless `low_ok`).
///
/// # Safety
/// Every non-NULL image of `frame` must satisfy the contract of [`view`] for `'a`.
pub(crate) unsafe fn frame_views<'a>(frame: &LrdFrame, low_ok: bool) -> Result<Frame<'a>, LrdStatus> {
    // SAFETY: forwarded contract.
    unsafe {
        let low = all_null(&frame.guides_low);
        if !low && !low_ok {
            return Err(LRD_STATUS_UNSUPPORTED);
        }
        Ok(Frame {
            noisy: view(&frame.noisy, 3)?.ok_or(LRD_STATUS_NULL_POINTER)?,
            guides: guides(&frame.guides)?,
            guides_low: if low { None } else { Some(guides(&frame.guides_low)?) },
            sample_weights: view(&frame.sample_weights, 1)?,
        })
    }
}

/// The frame and output image behind the caller's pointers;
/// LRD_STATUS_NULL_POINTER if either is NULL.
///
/// # Safety
/// Each pointer is NULL or points to a value valid for `'a`.
pub(crate) unsafe fn frame_and_out<'a>(
    frame: *const LrdFrame,
    out: *const LrdImageMut,
) -> Result<(&'a LrdFrame, &'a LrdImageMut), LrdStatus> {
    // SAFETY: the caller's contract above; `as_ref` checks for NULL.
    unsafe { Ok((frame.as_ref().ok_or(LRD_STATUS_NULL_POINTER)?, out.as_ref().ok_or(LRD_STATUS_NULL_POINTER)?)) }
}

/// A scratch pointer must be non-NULL and 8-byte aligned (f64 inside).
pub(crate) fn check_scratch(scratch: *mut c_void) -> Result<(), LrdStatus> {
    if scratch.is_null() {
        Err(LRD_STATUS_NULL_POINTER)
    } else if !(scratch as usize).is_multiple_of(8) {
        Err(LRD_STATUS_INVALID_ARGUMENT)
    } else {
        Ok(())
    }
}

/// Every image of a frame with its channel count: noisy, guides, low-resolution guides, weights.
pub(crate) fn images(frame: &LrdFrame) -> impl Iterator<Item = (&LrdImage, usize)> + '_ {
    fn guides(g: &LrdGuides) -> impl Iterator<Item = (&LrdImage, usize)> + '_ {
        [(&g.normal, 3), (&g.depth, 1), (&g.position, 3), (&g.ao, 1)].into_iter().chain(g.user.iter().map(|u| (u, 1)))
    }
    core::iter::once((&frame.noisy, 3))
        .chain(guides(&frame.guides))
        .chain(guides(&frame.guides_low))
        .chain(core::iter::once((&frame.sample_weights, 1)))
}

/// Bytes `[start, end)` an image spans (None for an absent or invalid image:
/// its own checks report it).
pub(crate) fn byte_range(
    data: *const c_void,
    format: u32,
    w: u32,
    h: u32,
    ch: usize,
    strides: (usize, usize, usize),
) -> Option<(usize, usize)> {
    if data.is_null() {
        return None;
    }
    let (elem, _, span) = layout_of(data, format, w, h, ch, strides).ok()?;
    Some((data as usize, (data as usize).checked_add(span * elem)?))
}

/// LRD_STATUS_INVALID_ARGUMENT if the output's bytes overlap any image of
/// `frame` or any of the `others` (address, bytes) ranges (scratch, history:
/// buffers the call writes), if one of the `others` overlaps an image of
/// `frame`, or if two of the output's pixels or channels share memory.
pub(crate) fn check_output_disjoint(out: &LrdImageMut, frame: &LrdFrame, others: &[(usize, usize)]) -> Result<(), LrdStatus> {
    let strides = (out.pixel_stride, out.row_stride, out.channel_stride);
    let (elem, layout, _) = layout_of(out.data, out.format, out.width, out.height, 3, strides)?;
    let _ = elem;
    if !layout.elements_distinct(out.width as usize, out.height as usize, 3) {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    let (o0, o1) = byte_range(out.data, out.format, out.width, out.height, 3, strides).ok_or(LRD_STATUS_INVALID_ARGUMENT)?;
    let overlaps = |(a, b): (usize, usize)| a < o1 && o0 < b;
    let inputs = || {
        images(frame)
            .filter_map(|(i, ch)| byte_range(i.data, i.format, i.width, i.height, ch, (i.pixel_stride, i.row_stride, i.channel_stride)))
    };
    let others = || others.iter().filter(|(_, n)| *n > 0).map(|&(a, n)| (a, a.saturating_add(n)));
    if inputs().chain(others()).any(overlaps) {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    // the scratch and the history are written too: no input may lie in them
    if others().any(|(a, b)| inputs().any(|(c, d)| a < d && c < b)) {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    Ok(())
}
