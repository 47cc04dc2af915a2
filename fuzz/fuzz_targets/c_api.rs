//! (c) The C entry points (FLR; BMFR and WALR, single frame + temporal; FLNR
//! with the bundled weights, a byte of them sometimes corrupted) with
//! arbitrary sizes, strides, formats, configs and NULL pointers. Buffers are allocated to span whatever layout is passed (the
//! C contract), so any crash or non-finite output is a library bug.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lrdenoise_ffi::*;
use std::ptr::{null, null_mut};

fn u32_at(d: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([0, 1, 2, 3].map(|k| d.get(i + k).copied().unwrap_or(0)))
}

/// An image with fuzzed layout, backed by `buf` sized to its span (capped).
fn image(d: &[u8], at: usize, ch: usize, w: u32, h: u32, buf: &mut Vec<u32>) -> LrdImage {
    let fmt = d.get(at).copied().unwrap_or(0) as u32 % 3; // 2 = invalid
    let elem = if fmt == 1 { 2 } else { 4 };
    let ps = (d.get(at + 1).copied().unwrap_or(0) as usize % 6) * elem + if d.get(at + 2).copied().unwrap_or(0) == 7 { 1 } else { 0 };
    let rs = (d.get(at + 3).copied().unwrap_or(0) as usize) * elem;
    let cs = (d.get(at + 4).copied().unwrap_or(0) as usize % 3) * elem;
    let eff = |s: usize, dflt: usize| if s == 0 { dflt } else { s };
    let cs_e = eff(cs, elem);
    let ps_e = eff(ps, ch * cs_e);
    let rs_e = eff(rs, w as usize * ps_e);
    let span = (h as usize).saturating_sub(1) * rs_e + (w as usize).saturating_sub(1) * ps_e + (ch - 1) * cs_e + elem;
    buf.clear();
    buf.resize(span.min(1 << 22) / 4 + 2, 0x3f000000); // 0.5f (or a small f16 pair)
    if span > 1 << 22 {
        return LrdImage { data: null(), format: fmt, width: w, height: h, pixel_stride: ps, row_stride: rs, channel_stride: cs };
    }
    for (i, v) in buf.iter_mut().enumerate() {
        *v = 0x3e000000 + ((i as u32).wrapping_mul(2654435761) >> 12);
    }
    LrdImage { data: buf.as_ptr() as *const _, format: fmt, width: w, height: h, pixel_stride: ps, row_stride: rs, channel_stride: cs }
}

fuzz_target!(|d: &[u8]| {
    if d.len() < 24 {
        return;
    }
    let w = 1 + u32_at(d, 0) % 48;
    let h = 1 + u32_at(d, 4) % 48;
    let mut cfg = lrd_flr_config_default();
    cfg.guides = d[8] as u32 & 0x1f; // may include an invalid bit
    cfg.block = [1, 2, 4, 8, 16, 3, 0][d[9] as usize % 7];
    cfg.blur = d[10] as u32 % 3;
    cfg.sigma = d[11] as f32 / 10.0;
    cfg.radius = d[12] as f32 - 8.0;
    cfg.regularization = d[13] as u32 % 3;
    cfg.upsample = [1, 1, 2, 4, 3][d[14] as usize % 5];
    // the adaptive window's sigmas (equal ones are invalid)
    let s0 = 0.5 + d[23] as f32 / 16.0;
    cfg.sigmas = [s0, 2.0 * s0, if d[23] % 5 == 0 { s0 } else { 3.5 * s0 }];
    // the GPU dispatch description of the same config (no device needed)
    {
        let mut g = std::mem::MaybeUninit::<LrdGpuDispatch>::zeroed();
        let r = unsafe { lrd_gpu_dispatch(&cfg, w, h, d[20] as u32 % 3, g.as_mut_ptr()) };
        assert_ne!(r, LrdStatus::LRD_STATUS_PANIC);
        if r == LrdStatus::LRD_STATUS_OK {
            let g = unsafe { g.assume_init() };
            assert!((7..=15).contains(&g.pass_count), "{} passes", g.pass_count);
        }
    }
    let (lw, lh) = (w.div_ceil(cfg.upsample.max(1)), h.div_ceil(cfg.upsample.max(1)));
    let mut bufs: Vec<Vec<u32>> = (0..13).map(|_| Vec::new()).collect();
    let none = LrdImage { data: null(), format: 0, width: 0, height: 0, pixel_stride: 0, row_stride: 0, channel_stride: 0 };
    let mut it = bufs.iter_mut();
    let mut next = || it.next().unwrap();
    let noisy = image(d, 15, 3, lw, lh, next());
    let mut gs = LrdGuides { normal: none, depth: none, position: none, ao: none, user: [none; 4] };
    let mut gl = gs;
    if cfg.guides & LRD_GUIDE_NORMAL != 0 {
        gs.normal = image(d, 20, 3, w, h, next());
    }
    if cfg.guides & LRD_GUIDE_DEPTH != 0 {
        gs.depth = image(d, 16, 1, w, h, next());
    }
    if cfg.guides & LRD_GUIDE_AO != 0 {
        gs.ao = image(d, 17, 1, w, h, next());
    }
    if cfg.upsample > 1 && cfg.guides & LRD_GUIDE_DEPTH != 0 {
        gl.depth = image(d, 18, 1, lw, lh, next());
    }
    // sample weights at the noisy size (any layout and values) in one case of three
    let sample_weights = if d[22] % 3 == 0 { image(d, 21, 1, lw, lh, next()) } else { none };
    let frame = LrdFrame { noisy: if d[19] == 0 { none } else { noisy }, guides: gs, guides_low: gl, sample_weights };
    let mut out = vec![0f32; (w * h * 4) as usize];
    let o = LrdImageMut {
        data: out.as_mut_ptr() as *mut _,
        format: 0,
        width: w,
        height: h,
        pixel_stride: 16,
        row_stride: 0,
        channel_stride: 0,
    };
    // BMFR on the same images: its own guide bits (no positions here), block
    // size, two temporal frames with a fuzzed motion image (or none).
    {
        let mut b = lrd_bmfr_config_default();
        b.guides = cfg.guides & !LRD_GUIDE_POSITION;
        b.block = [8, 32, 9, 64, 4, 65][d[9] as usize % 6];
        b.noise = [0.01, 0.0, 1.0][d[10] as usize % 3];
        let mut bf = frame;
        bf.guides_low = LrdGuides { normal: none, depth: none, position: none, ao: none, user: [none; 4] };
        if d[14] % 2 == 1 {
            bf.noisy = image(d, 15, 3, w, h, next());
        }
        let mv = image(d, 21, 2, w, h, next());
        let (mut sb, mut hb) = (0usize, 0usize);
        let st = unsafe { lrd_bmfr_temporal_sizes(&b, w, h, &mut sb, &mut hb) };
        assert_ne!(st, LrdStatus::LRD_STATUS_PANIC);
        if st == LrdStatus::LRD_STATUS_OK {
            let (mut s, mut hd) = (vec![0f64; sb / 8], vec![0f32; hb / 4]);
            let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
            for k in 0..2 {
                let m = if d[22] % 2 == 0 { null() } else { &mv as *const LrdImage };
                let r = unsafe { lrd_bmfr_denoise_temporal(&b, &bf, m, &mut hist, &o, s.as_mut_ptr() as *mut _, sb, null_mut()) };
                assert_ne!(r, LrdStatus::LRD_STATUS_PANIC);
                if r == LrdStatus::LRD_STATUS_OK {
                    assert!(out.iter().all(|v| v.is_finite()), "temporal frame {k}");
                }
                let r = unsafe { lrd_bmfr_denoise(&b, &bf, k, &o, s.as_mut_ptr() as *mut _, sb, null_mut()) };
                assert_ne!(r, LrdStatus::LRD_STATUS_PANIC);
                if r == LrdStatus::LRD_STATUS_OK {
                    assert!(out.iter().all(|v| v.is_finite()));
                }
            }
        }
    }
    // WALR (needs positions): single frame and one temporal frame.
    {
        let mut c = lrd_walr_config_default();
        c.guides = (cfg.guides | LRD_GUIDE_POSITION) & !LRD_GUIDE_AO;
        c.iterations = d[13] as u32 % 7; // 0, 6: invalid
        c.tracing = d[12] % 2 == 0;
        c.storage_f16 = d[11] % 3 == 0;
        let mut wf = frame;
        wf.guides_low = LrdGuides { normal: none, depth: none, position: none, ao: none, user: [none; 4] };
        wf.guides.ao = none;
        wf.guides.position = image(d, 19, 3, w, h, next());
        let (mut sb, mut hb) = (0usize, 0usize);
        let st = unsafe { lrd_walr_temporal_sizes(&c, w, h, &mut sb, &mut hb) };
        assert_ne!(st, LrdStatus::LRD_STATUS_PANIC);
        if st == LrdStatus::LRD_STATUS_OK {
            let (mut s, mut hd) = (vec![0f64; sb / 8], vec![0f32; hb / 4]);
            let mut hist = LrdHistory { data: hd.as_mut_ptr() as *mut _, bytes: hb, frames: 0 };
            let r = unsafe { lrd_walr_denoise_temporal(&c, &wf, null(), &mut hist, &o, s.as_mut_ptr() as *mut _, sb, null_mut()) };
            assert_ne!(r, LrdStatus::LRD_STATUS_PANIC);
            if r == LrdStatus::LRD_STATUS_OK {
                assert!(out.iter().all(|v| v.is_finite()));
            }
            let r = unsafe { lrd_walr_denoise(&c, &wf, 1, &o, s.as_mut_ptr() as *mut _, sb, null_mut()) };
            assert_ne!(r, LrdStatus::LRD_STATUS_PANIC);
            if r == LrdStatus::LRD_STATUS_OK {
                assert!(out.iter().all(|v| v.is_finite()));
            }
        }
    }
    // FLNR with the bundled network (on a quarter of the inputs: the network
    // is slow next to the rest); a fuzzed byte of the blob may be corrupted.
    if d[12] % 4 == 0 {
        static BLOB: &[u8] = include_bytes!("../../train/flnr.bin");
        let mut blob = BLOB.to_vec();
        if d[13] % 2 == 1 {
            let i = u32_at(d, 0) as usize % blob.len();
            blob[i] ^= d[14] | 1;
        }
        let len = if d[15] % 8 == 0 { blob.len() / 2 } else { blob.len() };
        let tile = [0, 64, 8, 100][d[16] as usize % 4];
        let fireflies = [1.5, 0.0, 0.5, f32::NAN][d[16] as usize / 4 % 4];
        let cfg = LrdFlnrConfig { tile, fireflies, ..lrd_flnr_config_default(blob.as_ptr(), len) };
        let mut fb = 0usize;
        let st = unsafe { lrd_flnr_scratch_size(&cfg, w, h, &mut fb) };
        assert_ne!(st, LrdStatus::LRD_STATUS_PANIC);
        if st == LrdStatus::LRD_STATUS_OK {
            let mut s = vec![0f64; fb / 8 + 1];
            let r = unsafe { lrd_flnr_denoise(&cfg, &frame, &o, s.as_mut_ptr() as *mut _, fb, null_mut()) };
            assert_ne!(r, LrdStatus::LRD_STATUS_PANIC);
            if r == LrdStatus::LRD_STATUS_OK {
                assert!(out.iter().all(|v| v.is_finite()), "flnr");
            }
            let mut tb = 0usize;
            if unsafe { lrd_flnr_tiled_scratch_size(&cfg, w, h, 1, &mut tb) } == LrdStatus::LRD_STATUS_OK {
                let mut ts = vec![0f64; tb / 8 + 1];
                for (stage, t) in [(d[17] as u32 % 4, d[18] as u32 % 3), (0, 0), (1, 0), (2, 0)] {
                    let r = unsafe { lrd_flnr_run_tile(&cfg, &frame, &o, ts.as_mut_ptr() as *mut _, tb, 1, stage, t, 0, null_mut()) };
                    assert_ne!(r, LrdStatus::LRD_STATUS_PANIC);
                }
            }
        }
    }
    let mut bytes = 0usize;
    let st = unsafe { lrd_flr_scratch_size(&cfg, w, h, &mut bytes) };
    if st != LrdStatus::LRD_STATUS_OK {
        return;
    }
    let mut scratch = vec![0f64; bytes / 8 + 1];
    let sp = scratch.as_mut_ptr() as *mut _;
    let s = unsafe { lrd_flr_denoise(&cfg, &frame, &o, sp, bytes, null_mut()) };
    if s == LrdStatus::LRD_STATUS_OK {
        assert!(out.iter().all(|v| v.is_finite()));
    }
    assert_ne!(s, LrdStatus::LRD_STATUS_PANIC);
    let t = unsafe { lrd_flr_run_tile(&cfg, &frame, &o, sp, bytes, 1, d[21] as u32 % 8, d[22] as u32 % 4, d[23] as u32 % 2, null_mut()) };
    assert_ne!(t, LrdStatus::LRD_STATUS_PANIC);
    let _ = unsafe { lrd_flr_denoise(&cfg, null(), &o, sp, bytes, null_mut()) };
});
