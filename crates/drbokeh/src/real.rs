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
    /// `exp(self)` for the fast engine: branch-free and vectorisable for `f32` (relative
    /// error below 4e-7 on [-87, 88], arguments clamped to that range); the standard
    /// library's `exp` for `f64`.
    fn exp_fast(self) -> Self;
}

/// `exp` for f32 by Cody-Waite range reduction `x = n ln2 + r`, `|r| <= ln2/2`, and the
/// degree-7 Taylor polynomial of `e^r`, whose remainder is below `0.347^8/8! < 5e-9`
/// relative; with float rounding the result is within 4e-7 relative of `exp(x)`.
/// Arguments are clamped to [-87, 88] (`exp(-87)` = 1.6e-38 stands in for smaller values).
#[inline(always)]
pub fn exp_f32(x: f32) -> f32 {
    const LOG2_E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    const ROUND: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    let x = x.clamp(-87.0, 88.0);
    // t = ROUND + n exactly, so n is also the difference of the bit patterns (no
    // float-to-int conversion, which would block vectorisation).
    let t = x * LOG2_E + ROUND;
    let n = t - ROUND;
    let n_int = t.to_bits() as i32 - ROUND.to_bits() as i32;
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0
                        + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    p * f32::from_bits(((n_int + 127) as u32) << 23)
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
    #[inline(always)]
    fn exp_fast(self) -> Self {
        exp_f32(self)
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
    #[inline(always)]
    fn exp_fast(self) -> Self {
        self.exp()
    }
}

#[cfg(test)]
mod tests {
    use super::exp_f32;

    #[test]
    fn exp_f32_is_within_its_bound() {
        let mut worst: f64 = 0.0;
        let mut x = -87.0f32;
        while x <= 88.0 {
            let exact = (x as f64).exp();
            worst = worst.max(((exp_f32(x) as f64) - exact).abs() / exact);
            x += 0.001_7;
        }
        assert!(worst < 4e-7, "worst relative error {worst}");
        assert_eq!(exp_f32(0.0), 1.0);
        assert!(exp_f32(-1000.0) < 2e-38 && exp_f32(1000.0).is_finite());
    }
}
