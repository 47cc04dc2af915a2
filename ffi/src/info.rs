//! What this build is: its version, the methods compiled in and the SIMD
//! level the kernels run at.

use core::ffi::c_char;

/// Feature bits returned by `lrd_features()`.
/// LRD_FEATURE_FLR: FLR's feature, with `lrd_gpu_dispatch`, is compiled in
/// (the CPU `lrd_flr_*` entry points are always present).
pub const LRD_FEATURE_FLR: u32 = 1;
/// Feature bit: BMFR (`lrd_bmfr_*`) is compiled in.
pub const LRD_FEATURE_BMFR: u32 = 2;
/// Feature bit: WALR (`lrd_walr_*`) is compiled in.
pub const LRD_FEATURE_WALR: u32 = 4;
/// Feature bit: FLNR (`lrd_flnr_*`) is compiled in.
pub const LRD_FEATURE_FLNR: u32 = 8;

/// The library version, e.g. "0.1.0" (static, NUL-terminated).
#[no_mangle]
pub extern "C" fn lrd_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr() as *const c_char
}

/// Bit set of LRD_FEATURE_* for the methods compiled in.
#[no_mangle]
pub extern "C" fn lrd_features() -> u32 {
    let mut f = 0;
    if cfg!(feature = "flr") {
        f |= LRD_FEATURE_FLR;
    }
    if cfg!(feature = "bmfr") {
        f |= LRD_FEATURE_BMFR;
    }
    if cfg!(feature = "walr") {
        f |= LRD_FEATURE_WALR;
    }
    if cfg!(feature = "flnr") {
        f |= LRD_FEATURE_FLNR;
    }
    f
}

/// The SIMD instruction set the kernels run on this CPU ("avx2+fma" when
/// the AVX2 + FMA kernels are chosen at run time, else the build's: "sse2",
/// "neon", ...).
#[no_mangle]
pub extern "C" fn lrd_simd_level() -> *const c_char {
    match lrdenoise_core::simd_level() {
        "avx2+fma" => c"avx2+fma".as_ptr(),
        "avx" => c"avx".as_ptr(),
        "sse4.1" => c"sse4.1".as_ptr(),
        "sse2" => c"sse2".as_ptr(),
        "neon" => c"neon".as_ptr(),
        _ => c"scalar".as_ptr(),
    }
}
