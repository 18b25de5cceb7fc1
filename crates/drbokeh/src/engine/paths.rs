//! Process-wide switches that make an engine take its plain path where it has a faster
//! one, for tests that compare the two (as [`super::simd::force_baseline`] does for the
//! SIMD copies). Off by default; set them only in a test binary of their own (they would
//! race other tests of the same process).

use std::sync::atomic::{AtomicBool, Ordering};

static SOURCE_BY_SOURCE: AtomicBool = AtomicBool::new(false);

/// Makes the span adjoint's pass B sum every source on its own from now on (`true`): no
/// runs of equal-radius sources sharing their row geometry (groups of 8, correlations
/// of a row's run); or lets it share them again (`false`, the default). Both sum the same
/// terms, in another order.
pub fn force_source_by_source(on: bool) {
    SOURCE_BY_SOURCE.store(on, Ordering::SeqCst);
}

/// Whether [`force_source_by_source`] is on.
pub fn source_by_source() -> bool {
    SOURCE_BY_SOURCE.load(Ordering::Relaxed)
}
