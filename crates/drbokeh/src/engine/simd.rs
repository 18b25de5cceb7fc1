//! The one SIMD dispatch mechanism: a kernel is written once as a generic `#[inline(always)]`
//! function and `avx2_dispatch!` compiles it twice, for the baseline target and with AVX2
//! enabled, choosing at run time. Both copies do the same arithmetic in the same order
//! (lanes are explicit in the source, FMA is not enabled), so they give the same bytes;
//! only the vector width differs. `tests/simd.rs` checks that by forcing the baseline copy
//! ([`force_baseline`]) on the same inputs.

use std::sync::atomic::{AtomicBool, Ordering};

static FORCE_BASELINE: AtomicBool = AtomicBool::new(false);

/// Makes every dispatched kernel run its baseline (non-AVX2) copy from now on (`true`), or
/// lets them use AVX2 where the CPU has it again (`false`, the default). Process-wide; for
/// tests that compare the two copies.
pub fn force_baseline(on: bool) {
    FORCE_BASELINE.store(on, Ordering::SeqCst);
}

/// Whether dispatched kernels run their AVX2 copy: the CPU has AVX2 and
/// [`force_baseline`] is off.
pub fn avx2_active() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !FORCE_BASELINE.load(Ordering::Relaxed) && std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `avx2_dispatch!(name, name_avx2, kernel, (arg: Type, ...) -> Ret)` defines `name`, which
/// calls `kernel` compiled with AVX2 enabled when [`avx2_active`], else the baseline copy.
/// `kernel` must be generic over `T: Real` and `#[inline(always)]`.
macro_rules! avx2_dispatch {
    ($name:ident, $avx:ident, $f:ident, ($($arg:ident : $ty:ty),*) -> $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        #[allow(clippy::too_many_arguments)]
        unsafe fn $avx<T: Real>($($arg: $ty),*) -> $ret {
            $f($($arg),*)
        }
        #[allow(clippy::too_many_arguments)]
        fn $name<T: Real>($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                if $crate::engine::simd::avx2_active() {
                    // SAFETY: the CPU supports AVX2 (checked by `avx2_active`).
                    return unsafe { $avx($($arg),*) };
                }
            }
            $f($($arg),*)
        }
    };
}
pub(crate) use avx2_dispatch;
