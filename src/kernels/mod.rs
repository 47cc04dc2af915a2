//! The FLR kernels, each callable on its own on one band of cells.
//!
//! Cell layout (f64, `k = moment_count(Q)` values per cell), eq. 12:
//! `[n, s_0..s_Q, S (upper triangle, row-major), t_0..t_2, P (Q×3, guide-major), e]`
//! with `n = Σw`, `s = Σw g`, `S = Σw g gᵀ`, `t = Σw y`, `P = Σw g yᵀ`,
//! `e = Σw ℓ²` (ℓ = [`LUMA`]·y, the light's luminance: the residual variance of
//! the adaptive window, `flr::adaptive`); guides relative to the frame
//! reference `m` (see `flr::Stats`).
//!
//! Index loops are kept where they mirror the equations (`needless_range_loop`),
//! and `!(x > floor)` is used on purpose: it is also true for NaN.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod apply;
pub mod blur;
pub mod cholesky;
pub mod demodulation;
#[cfg(target_arch = "x86_64")]
pub(crate) mod f64x4_avx2;
pub mod moments;
pub mod qr;
pub mod solve;

/// Number of upper-triangle entries of a Q×Q matrix.
pub const fn packed_len(q: usize) -> usize {
    q * (q + 1) / 2
}

/// Moments per cell for `q` guides: n, s, S, t, P, e.
pub const fn moment_count(q: usize) -> usize {
    1 + q + packed_len(q) + 3 + 3 * q + 1
}

/// Luminance weights (Rec. 709) of the energy moment `e = Σw ℓ²`.
pub const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// Model floats per cell: intercept (3), coefficients (Q×3), local mean of y (3).
pub const fn model_len(q: usize) -> usize {
    3 + 3 * q + 3
}

/// Offsets of each moment group inside a cell.
#[derive(Clone, Copy, Debug)]
pub struct CellLayout {
    /// Guide channel count Q.
    pub q: usize,
    /// `s = Σw g` (Q values; `n = Σw` is at 0).
    pub s: usize,
    /// `S = Σw g gᵀ`, upper triangle row-major ([`packed_len`] values).
    pub ss: usize,
    /// `t = Σw y` (3 values).
    pub t: usize,
    /// `P = Σw g yᵀ` (Q×3, guide-major).
    pub p: usize,
    /// The energy moment `e = Σw ℓ²`.
    pub e: usize,
    /// Moments per cell ([`moment_count`]).
    pub k: usize,
}

impl CellLayout {
    /// The layout for `q` guide channels.
    pub const fn new(q: usize) -> Self {
        let s = 1;
        let ss = s + q;
        let t = ss + packed_len(q);
        let p = t + 3;
        CellLayout { q, s, ss, t, p, e: p + 3 * q, k: p + 3 * q + 1 }
    }
}

/// Calls `$f::<Q>(args)` for the runtime guide count `$q` (0..=12).
#[allow(unused_macros)] // only FLR uses it
macro_rules! dispatch_q {
    ($q:expr, $f:ident ( $($a:expr),* $(,)? )) => {
        match $q {
            0 => $f::<0>($($a),*),
            1 => $f::<1>($($a),*),
            2 => $f::<2>($($a),*),
            3 => $f::<3>($($a),*),
            4 => $f::<4>($($a),*),
            5 => $f::<5>($($a),*),
            6 => $f::<6>($($a),*),
            7 => $f::<7>($($a),*),
            8 => $f::<8>($($a),*),
            9 => $f::<9>($($a),*),
            10 => $f::<10>($($a),*),
            11 => $f::<11>($($a),*),
            12 => $f::<12>($($a),*),
            _ => return Err($crate::Error::TooManyGuides { got: $q }),
        }
    };
}
#[allow(unused_imports)]
pub(crate) use dispatch_q;

/// √x in f64. On x86-64 through the SSE2 intrinsic, which the compiler encodes
/// to match the surrounding code (VEX under AVX): `libm::sqrt` uses inline asm
/// with the legacy encoding, and mixing the two costs ~6× in the solve on AVX2
/// builds (measured).
#[inline(always)]
pub fn sqrt(x: f64) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_mm_cvtsd_f64, _mm_set_sd, _mm_sqrt_pd};
        // SAFETY: SSE2 is part of the x86-64 baseline, so these intrinsics are always available.
        unsafe { _mm_cvtsd_f64(_mm_sqrt_pd(_mm_set_sd(x))) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        libm::sqrt(x)
    }
}
