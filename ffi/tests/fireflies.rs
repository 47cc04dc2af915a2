//! The `fireflies` field of the BMFR and WALR C configurations: its default is
//! the core's, 0 turns the clamp off, a factor below 1 is refused, and the C
//! entry points clamp exactly as the Rust API does (outputs and counts).

use lrdenoise::*;
use lrdenoise_core::walr::{Walr, WalrConfig};
use lrdenoise_core::{fireflies, Bmfr, BmfrConfig, Frame, Guides, ImageView, ImageViewMut};
use std::ptr::null;

fn img(data: *const f32, w: u32, h: u32, ch: usize) -> LrdImage {
    LrdImage { data: data as *const _, format: 0, width: w, height: h, pixel_stride: ch * 4, row_stride: 0, channel_stride: 0 }
}
fn none() -> LrdImage {
    LrdImage { data: null(), format: 0, width: 0, height: 0, pixel_stride: 0, row_stride: 0, channel_stride: 0 }
}

/// A frame of light with a few outliers, normals, depth and positions.
struct Scene {
    w: u32,
    h: u32,
    noisy: Vec<f32>,
    normal: Vec<f32>,
    depth: Vec<f32>,
    position: Vec<f32>,
}

impl Scene {
    fn new(w: u32, h: u32) -> Self {
        let (wu, n) = (w as usize, (w * h) as usize);
        let mut noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 500.0).collect();
        for i in [5, n / 3, n / 2 + 7, n - 1] {
            noisy[3 * i..3 * i + 3].fill(1e4);
        }
        let normal = (0..3 * n).map(|i| if i % 3 == 2 { 1.0 } else { 0.0 }).collect();
        let depth = (0..n).map(|i| 2.0 + (i / wu) as f32 * 0.01).collect();
        let position = (0..3 * n).map(|i| ((i / 3) % wu) as f32 * 0.1 + (i % 3) as f32 + ((i / 3) / wu) as f32 * 0.05).collect();
        Scene { w, h, noisy, normal, depth, position }
    }
    /// The frame for the C API; `depth`: with the depth guide.
    fn c_frame(&self, depth: bool) -> LrdFrame {
        let (w, h) = (self.w, self.h);
        let empty = LrdGuides { normal: none(), depth: none(), position: none(), ao: none(), user: [none(); 4] };
        let guides = LrdGuides {
            normal: img(self.normal.as_ptr(), w, h, 3),
            depth: if depth { img(self.depth.as_ptr(), w, h, 1) } else { none() },
            position: img(self.position.as_ptr(), w, h, 3),
            ..empty
        };
        LrdFrame { noisy: img(self.noisy.as_ptr(), w, h, 3), guides, guides_low: empty, sample_weights: none() }
    }
    /// The same frame for the Rust API.
    fn rust_frame(&self, depth: bool) -> Frame<'_> {
        let (w, h) = (self.w as usize, self.h as usize);
        let guides = Guides {
            normal: Some(ImageView::interleaved(&self.normal, w, h, 3).unwrap()),
            depth: depth.then(|| ImageView::interleaved(&self.depth, w, h, 1).unwrap()),
            position: Some(ImageView::interleaved(&self.position, w, h, 3).unwrap()),
            ..Default::default()
        };
        Frame::new(ImageView::interleaved(&self.noisy, w, h, 3).unwrap(), guides)
    }
}

/// Runs a C single-frame entry point (`size` gives the scratch bytes) on `frame`.
fn run_c(
    s: &Scene,
    frame: LrdFrame,
    size: &dyn Fn(*mut usize) -> LrdStatus,
    denoise: &dyn Fn(*const LrdFrame, *const LrdImageMut, *mut core::ffi::c_void, usize, *mut LrdReport) -> LrdStatus,
) -> (Vec<f32>, LrdReport) {
    let mut bytes = 0usize;
    assert_eq!(size(&mut bytes), LrdStatus::LRD_STATUS_OK);
    let mut scratch = vec![0f64; bytes / 8];
    let mut out = vec![0f32; 3 * (s.w * s.h) as usize];
    let o = LrdImageMut {
        data: out.as_mut_ptr() as *mut _,
        format: 0,
        width: s.w,
        height: s.h,
        pixel_stride: 0,
        row_stride: 0,
        channel_stride: 0,
    };
    let mut rep = LrdReport::default();
    assert_eq!(denoise(&frame, &o, scratch.as_mut_ptr() as *mut _, bytes, &mut rep), LrdStatus::LRD_STATUS_OK);
    (out, rep)
}

#[test]
fn bmfr_fireflies_field() {
    let s = Scene::new(70, 45);
    let (w, h) = (s.w as usize, s.h as usize);
    let d = lrd_bmfr_config_default();
    assert_eq!(d.fireflies, fireflies::DEFAULT_STRENGTH);
    for k in [d.fireflies, 0.0, 4.0] {
        let cfg = LrdBmfrConfig { fireflies: k, ..d };
        // SAFETY: valid pointers for the duration of each call.
        let size = |b: *mut usize| unsafe { lrd_bmfr_scratch_size(&cfg, s.w, s.h, b) };
        let run = |f: *const LrdFrame, o: *const LrdImageMut, sp: *mut core::ffi::c_void, n: usize, r: *mut LrdReport| unsafe {
            lrd_bmfr_denoise(&cfg, f, 2, o, sp, n, r)
        };
        let (got, rep) = run_c(&s, s.c_frame(false), &size, &run);
        let rcfg = BmfrConfig { fireflies: (k != 0.0).then_some(k), ..BmfrConfig::default() };
        let b = Bmfr::new(rcfg, w, h).unwrap();
        let mut scratch = vec![0f32; b.scratch_len()];
        let mut want = vec![0f32; 3 * w * h];
        let r = b.denoise(&s.rust_frame(false), 2, &mut scratch, &mut ImageViewMut::interleaved(&mut want, w, h, 3).unwrap()).unwrap();
        assert_eq!(got, want, "k {k}");
        assert_eq!(rep.clamped_fireflies, r.clamped_fireflies, "k {k}");
        assert_eq!(rep.clamped_fireflies > 0, k != 0.0, "k {k}");
    }
    let bad = LrdBmfrConfig { fireflies: 0.5, ..d };
    let mut bytes = 0usize;
    // SAFETY: valid pointers for the duration of the call.
    assert_eq!(unsafe { lrd_bmfr_scratch_size(&bad, s.w, s.h, &mut bytes) }, LrdStatus::LRD_STATUS_INVALID_CONFIG);
}

#[test]
fn walr_fireflies_field() {
    let s = Scene::new(41, 29);
    let (w, h) = (s.w as usize, s.h as usize);
    let d = lrd_walr_config_default();
    assert_eq!(d.fireflies, fireflies::DEFAULT_STRENGTH);
    for k in [d.fireflies, 0.0, 4.0] {
        let cfg = LrdWalrConfig { fireflies: k, ..d };
        // SAFETY: valid pointers for the duration of each call.
        let size = |b: *mut usize| unsafe { lrd_walr_scratch_size(&cfg, s.w, s.h, b) };
        let run = |f: *const LrdFrame, o: *const LrdImageMut, sp: *mut core::ffi::c_void, n: usize, r: *mut LrdReport| unsafe {
            lrd_walr_denoise(&cfg, f, 2, o, sp, n, r)
        };
        let (got, rep) = run_c(&s, s.c_frame(true), &size, &run);
        let rcfg = WalrConfig { fireflies: (k != 0.0).then_some(k), ..WalrConfig::default() };
        let wl = Walr::new(rcfg, w, h).unwrap();
        let mut scratch = vec![0f32; wl.scratch_len()];
        let mut want = vec![0f32; 3 * w * h];
        let r = wl.denoise(&s.rust_frame(true), 2, &mut scratch, &mut ImageViewMut::interleaved(&mut want, w, h, 3).unwrap()).unwrap();
        assert_eq!(got, want, "k {k}");
        assert_eq!(rep.clamped_fireflies, r.clamped_fireflies, "k {k}");
        assert_eq!(rep.clamped_fireflies > 0, k != 0.0, "k {k}");
    }
    let bad = LrdWalrConfig { fireflies: f32::NAN, ..d };
    let mut bytes = 0usize;
    // SAFETY: valid pointers for the duration of the call.
    assert_eq!(unsafe { lrd_walr_scratch_size(&bad, s.w, s.h, &mut bytes) }, LrdStatus::LRD_STATUS_INVALID_CONFIG);
}
