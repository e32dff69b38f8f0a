//! CPU features, detected once per call site family and shared by every
//! kernel of the crate (and by `dend`'s rotation lanes, through
//! [`with_avx2_fma`], so that `dend` itself needs no `unsafe`).

/// Whether the CPU runs AVX2 and FMA (x86-64 only; false elsewhere).
pub fn has_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the CPU runs AVX-512F besides AVX2 and FMA.
pub fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        has_fma() && std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Runs `f` compiled with AVX2 and FMA enabled when the CPU has them
/// ([`has_fma`]), else as compiled for the baseline target. `f` should be
/// `#[inline(always)]` code (a closure calling such functions), so that it
/// is generated inside the feature-enabled frame. The result is the same
/// either way up to the rounding FMA contraction may change; callers that
/// need bit-identical results must not rely on contraction (Rust never
/// contracts `a * b + c` on its own).
#[inline(always)]
pub fn with_avx2_fma<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if has_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above), the only
        // requirement of a `target_feature(enable = "avx2,fma")` function.
        return unsafe { avx2_fma(f) };
    }
    f()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn avx2_fma<R>(f: impl FnOnce() -> R) -> R {
    f()
}
