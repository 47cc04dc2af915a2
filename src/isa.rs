//! Which vector instruction set a kernel may use on this CPU, detected at run
//! time with `core::arch` (so `no_std` builds get it too).

#[cfg(all(
    target_arch = "x86_64",
    not(all(target_feature = "avx2", target_feature = "fma", target_feature = "f16c", target_feature = "avx512f"))
))]
use core::sync::atomic::{AtomicU8, Ordering};

/// The instruction set of a kernel's vector loops: the network's 3×3 layers
/// (`nn::conv`, 8 lanes, or 16 with [`Isa::Avx512`]), the temporal stage's
/// pixel groups (`wide`'s 4 or 8 lanes, 8 AVX2 lanes, or 16 with
/// [`Isa::Avx512`]), the QR's column updates (`kernels::qr`), and FLR's block
/// accumulation (`kernels::moments`), four-cell solve (`kernels::solve`, in
/// `f64` lanes), the adaptive window's four-cell variances and blend
/// (`flr::adaptive`, `f64` lanes) and model application (`kernels::apply`).
///
/// `wide` picks SSE2/AVX/NEON at compile time, so a plain x86-64 build runs
/// them in SSE2 without fused multiply-adds. [`Isa::detect`] therefore chooses AVX2 + FMA whenever
/// the build enables them or the CPU reports them at run time. The check is
/// the one `std::is_x86_feature_detected!` makes, written with `core::arch`
/// so that `no_std` builds get it too: CPUID says the CPU has AVX2 and FMA,
/// and XGETBV says the OS saves the YMM registers. A Rust user on the
/// default features (which lack `std`) therefore gets the AVX2 + FMA kernels
/// too.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Isa {
    /// `wide`'s lanes (the build's instruction set).
    Portable,
    /// `core::arch` AVX2 + FMA intrinsics (x86-64 only).
    Avx2Fma,
    /// AVX-512F intrinsics (x86-64 only) for the kernels that have an
    /// AVX-512 version (the network's 3×3 layers, `nn::conv`, and the
    /// temporal stage's pixel groups); every other
    /// kernel runs its AVX2 + FMA version. Chosen by [`Isa::detect_widest`].
    Avx512,
}

impl Isa {
    /// The fastest instruction set this build may use on this CPU.
    pub fn detect() -> Isa {
        if Isa::Avx2Fma.available() {
            Isa::Avx2Fma
        } else {
            Isa::Portable
        }
    }

    /// The fastest instruction set for a kernel that has an AVX-512 version:
    /// [`Isa::Avx512`] where the CPU has AVX-512F (with AVX2 and FMA) and
    /// the OS saves its registers, else [`Isa::detect`]. 16-lane vectors
    /// and 32 registers hold twice the accumulators of the AVX2 version.
    pub fn detect_widest() -> Isa {
        if Isa::Avx512.available() {
            Isa::Avx512
        } else {
            Isa::detect()
        }
    }

    /// Whether this build can run `self` on this CPU.
    pub fn available(self) -> bool {
        match self {
            Isa::Portable => true,
            Isa::Avx2Fma => avx2_fma_available(),
            Isa::Avx512 => avx2_fma_available() && avx512_available(),
        }
    }

    /// Whether a kernel asked to run on `self` takes its `avx2.rs` intrinsics
    /// file: the build's `wide` lacks AVX2 + FMA (a plain x86-64 build, whose
    /// lanes are SSE2), `self` is [`Isa::Avx2Fma`] (or [`Isa::Avx512`], which implies it) and the CPU has it. The
    /// one rule of every kernel's dispatch (`qr`, `moments`, `solve`, the
    /// adaptive window's blend, `apply`, `blur`, the temporal stage's 8 lanes; `conv` and the temporal
    /// stage's AVX-512 lanes run their files in every build). An `x86-64-v3`
    /// build keeps `wide`'s lanes, which compile to the same instructions and
    /// are faster there than the intrinsics files (whose functions do not
    /// inline into their callers). The call stays behind
    /// `#[cfg(target_arch = "x86_64")]`: the intrinsics files exist only there.
    #[inline]
    pub fn intrinsics(self) -> bool {
        !cfg!(all(target_feature = "avx2", target_feature = "fma")) && self != Isa::Portable && self.available()
    }
}

#[cfg(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"))]
fn avx2_fma_available() -> bool {
    true
}

#[cfg(all(target_arch = "x86_64", not(all(target_feature = "avx2", target_feature = "fma"))))]
fn avx2_fma_available() -> bool {
    static KNOWN: AtomicU8 = AtomicU8::new(0);
    cached(&KNOWN, cpu_has_avx2_fma)
}

/// CPUID leaf 1: FMA (ECX bit 12) with AVX usable; CPUID leaf 7: AVX2 (EBX bit 5).
#[cfg(all(target_arch = "x86_64", not(all(target_feature = "avx2", target_feature = "fma"))))]
#[allow(unused_unsafe)] // the CPUID intrinsics are safe in recent Rust, unsafe in older ones
fn cpu_has_avx2_fma() -> bool {
    use core::arch::x86_64::{__cpuid, __cpuid_count};
    // SAFETY: every x86-64 CPU has CPUID leaf 0.
    let max_leaf = unsafe { __cpuid(0) }.eax;
    // SAFETY: leaf 7 exists (max_leaf >= 7, checked first).
    avx_ecx().is_some_and(|ecx| ecx & (1 << 12) != 0) && max_leaf >= 7 && unsafe { __cpuid_count(7, 0) }.ebx & (1 << 5) != 0
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_fma_available() -> bool {
    false
}

#[cfg(all(target_arch = "x86_64", target_feature = "avx512f"))]
fn avx512_available() -> bool {
    true
}

#[cfg(all(target_arch = "x86_64", not(target_feature = "avx512f")))]
fn avx512_available() -> bool {
    static KNOWN: AtomicU8 = AtomicU8::new(0);
    cached(&KNOWN, cpu_has_avx512f)
}

/// CPUID leaf 7: AVX-512F (EBX bit 16); CPUID leaf 1: OSXSAVE (ECX bit 27);
/// XCR0 bits 1, 2 and 5–7: the OS saves the XMM, YMM, opmask and upper ZMM
/// registers.
#[cfg(all(target_arch = "x86_64", not(target_feature = "avx512f")))]
#[allow(unused_unsafe)] // the CPUID intrinsics are safe in recent Rust, unsafe in older ones
fn cpu_has_avx512f() -> bool {
    use core::arch::x86_64::{__cpuid, __cpuid_count, _xgetbv};
    // SAFETY: every x86-64 CPU has CPUID leaves 0 and 1.
    let (max_leaf, ecx) = unsafe { (__cpuid(0).eax, __cpuid(1).ecx) };
    if max_leaf < 7 || ecx & (1 << 27) == 0 {
        return false;
    }
    // SAFETY: OSXSAVE (checked above) means the OS has enabled XGETBV; leaf 7 exists.
    unsafe { _xgetbv(0) & 0xe6 == 0xe6 && __cpuid_count(7, 0).ebx & (1 << 16) != 0 }
}

#[cfg(not(target_arch = "x86_64"))]
fn avx512_available() -> bool {
    false
}

/// Whether the CPU converts halves in hardware: F16C, with the AVX state saved
/// by the OS (its instructions are VEX-encoded). Used by `convert`, which
/// `half` leaves to software in a `no_std` build without F16C compiled in.
pub fn f16c_available() -> bool {
    #[cfg(all(target_arch = "x86_64", target_feature = "f16c"))]
    return true;
    #[cfg(all(target_arch = "x86_64", not(target_feature = "f16c")))]
    {
        static KNOWN: AtomicU8 = AtomicU8::new(0);
        // CPUID leaf 1: F16C (ECX bit 29) with AVX usable.
        cached(&KNOWN, || avx_ecx().is_some_and(|ecx| ecx & (1 << 29) != 0))
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// `detect()`, asked once per process: its answer is kept in `known` (0: not
/// asked yet, 1: no, 2: yes), since CPUID is slow in virtual machines.
#[cfg(all(
    target_arch = "x86_64",
    not(all(target_feature = "avx2", target_feature = "fma", target_feature = "f16c", target_feature = "avx512f"))
))]
fn cached(known: &AtomicU8, detect: fn() -> bool) -> bool {
    match known.load(Ordering::Relaxed) {
        0 => {
            let yes = detect();
            known.store(1 + yes as u8, Ordering::Relaxed);
            yes
        }
        k => k == 2,
    }
}

/// CPUID leaf 1's ECX when AVX is usable: the CPU has OSXSAVE (ECX bit 27) and
/// AVX (28), and XCR0 bits 1 and 2 say the OS saves the XMM and YMM registers.
#[cfg(all(target_arch = "x86_64", not(all(target_feature = "avx2", target_feature = "fma", target_feature = "f16c"))))]
#[allow(unused_unsafe)] // the CPUID intrinsics are safe in recent Rust, unsafe in older ones
fn avx_ecx() -> Option<u32> {
    use core::arch::x86_64::{__cpuid, _xgetbv};
    // SAFETY: every x86-64 CPU has CPUID leaf 1.
    let ecx = unsafe { __cpuid(1) }.ecx;
    if ecx & (0b11 << 27) != 0b11 << 27 {
        return None;
    }
    // SAFETY: OSXSAVE (checked above) means the OS has enabled XGETBV.
    (unsafe { _xgetbv(0) } & 0b110 == 0b110).then_some(ecx)
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    extern crate std;

    /// The `core::arch` check agrees with the standard library's.
    #[test]
    fn detection_agrees_with_std() {
        let std_says = std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma");
        assert_eq!(super::Isa::Avx2Fma.available(), std_says);
        assert_eq!(super::Isa::detect() == super::Isa::Avx2Fma, std_says);
        assert_eq!(super::f16c_available(), std::is_x86_feature_detected!("f16c"));
        assert_eq!(super::Isa::Avx512.available(), std_says && std::is_x86_feature_detected!("avx512f"));
    }
}

/// Which kernel implementation runs (for testing SIMD against scalar).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Kernel {
    /// SIMD where the block size allows it, scalar elsewhere.
    #[default]
    Simd,
    /// Portable scalar code everywhere (the oracle for the SIMD paths).
    Scalar,
}
