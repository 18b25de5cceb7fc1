//! The floating-point type the renderer is generic over (`f32` for speed, `f64` for
//! gradient checks and exactness tests).

use num_traits::{Float, FromPrimitive, ToPrimitive};

/// A real number type usable by the renderer: `f32` or `f64`.
pub trait Real:
    Float + FromPrimitive + ToPrimitive + Send + Sync + Copy + Default + std::fmt::Debug + 'static
{
    /// Converts an `f64` constant to this type (rounding for `f32`).
    fn c(x: f64) -> Self;
    /// Converts to `f64` exactly.
    fn f64(self) -> f64;
}

impl Real for f32 {
    #[inline(always)]
    fn c(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}

impl Real for f64 {
    #[inline(always)]
    fn c(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}
