//! The soft occlusion term (docs/model.md, "Occlusion"): the receiver's focus weight `e`,
//! the depth step `s`, and `O = 1 + e (s - 1)`, each beside its derivatives and its
//! [`Real::exp_fast`] form.

use crate::Real;

/// Focus weight of a receiver `e(x) = exp(-3 (K d(x))^2)`: 1 in focus, 0 when very blurred.
/// Equation M10 of docs/model.md.
#[inline(always)]
pub fn focus_weight<T: Real>(blur_k: T, rel_disp_x: T) -> T {
    let kd = blur_k * rel_disp_x;
    (T::c(-3.0) * kd * kd).exp()
}

/// Partial derivatives of [`focus_weight`] from its value `e`:
/// `(de/dd_x, de/dK) = (-6 K^2 d_x e, -6 K d_x^2 e)`.
/// Equation M10 of docs/model.md.
#[inline(always)]
pub fn focus_weight_derivatives<T: Real>(blur_k: T, rel_disp_x: T, e: T) -> (T, T) {
    let six = T::c(6.0);
    (
        -six * blur_k * blur_k * rel_disp_x * e,
        -six * blur_k * rel_disp_x * rel_disp_x * e,
    )
}

/// Depth step `s(D) = 1/2 + 1/2 tanh(10 (D - 0.1))`.
/// Equation M11 of docs/model.md.
#[inline(always)]
pub fn depth_step<T: Real>(disp_difference: T) -> T {
    T::c(0.5) + T::c(0.5) * (T::c(10.0) * (disp_difference - T::c(0.1))).tanh()
}

/// [`depth_step`] with `tanh(z) = 1 - 2 / (exp(2z) + 1)` through [`Real::exp_fast`].
/// Equation M11 of docs/model.md.
#[inline(always)]
pub fn depth_step_fast<T: Real>(disp_difference: T) -> T {
    let z = T::c(20.0) * (disp_difference - T::c(0.1));
    // 1/2 + 1/2 tanh(z/2)... with z = 2 * 10 (D - 0.1): 1/2 + 1/2 (1 - 2/(e^z + 1)) = 1 - 1/(e^z + 1)
    T::one() - T::one() / (z.exp_fast() + T::one())
}

/// Derivative of [`depth_step`]: `5 (1 - tanh^2(10 (D - 0.1)))`.
/// Equation M11 of docs/model.md.
#[inline(always)]
pub fn depth_step_derivative<T: Real>(disp_difference: T) -> T {
    let t = (T::c(10.0) * (disp_difference - T::c(0.1))).tanh();
    T::c(5.0) * (T::one() - t * t)
}

/// Derivative of [`depth_step`] from its value `s`: `20 s (1 - s)`. Since
/// `s = 1/2 + 1/2 tanh(u)` gives `1 - tanh^2(u) = 4 s (1 - s)`, this equals
/// [`depth_step_derivative`]; with [`depth_step_fast`] it is the fast engine's form (no
/// second transcendental).
/// Equation M11 of docs/model.md.
#[inline(always)]
pub fn depth_step_derivative_from_value<T: Real>(s: T) -> T {
    T::c(20.0) * s * (T::one() - s)
}

/// [`depth_step_fast`] and its derivative from the value, `(s, 20 s (1 - s))`.
/// Equation M11 of docs/model.md.
#[inline(always)]
pub fn depth_step_fast_with_derivative<T: Real>(disp_difference: T) -> (T, T) {
    let s = depth_step_fast(disp_difference);
    (s, depth_step_derivative_from_value(s))
}

/// The occlusion from the receiver's focus weight `e` and the depth step's value `s`:
/// `O = 1 + e (s - 1)`.
/// Equation M12 of docs/model.md.
#[inline(always)]
pub fn occlusion_from_step<T: Real>(focus_weight_x: T, s: T) -> T {
    T::one() + focus_weight_x * (s - T::one())
}

/// Soft occlusion `O(y,x) = 1 + e(x) (s(d(y) - d(x)) - 1)` (supplement eq. 1 with its sign
/// slip corrected); the centre tap has `O(x,x) = 1`, which callers handle.
/// Equation M12 of docs/model.md.
#[inline(always)]
pub fn occlusion<T: Real>(focus_weight_x: T, rel_disp_y: T, rel_disp_x: T) -> T {
    occlusion_from_step(focus_weight_x, depth_step(rel_disp_y - rel_disp_x))
}

/// Partial derivatives of [`occlusion`] (non-centre taps):
/// `dO/dd_y = e s'(D)`, `dO/dd_x|_e = -e s'(D)`, `dO/de = s(D) - 1`, with `D = d_y - d_x`.
/// Equation M12 of docs/model.md.
#[inline(always)]
pub fn occlusion_derivatives<T: Real>(
    focus_weight_x: T,
    rel_disp_y: T,
    rel_disp_x: T,
) -> (T, T, T) {
    let diff = rel_disp_y - rel_disp_x;
    let ds = focus_weight_x * depth_step_derivative(diff);
    (ds, -ds, depth_step(diff) - T::one())
}

/// [`occlusion`] through [`depth_step_fast`] (the fast engine's form).
/// Equation M12 of docs/model.md.
#[inline(always)]
pub fn occlusion_fast<T: Real>(focus_weight_x: T, rel_disp_y: T, rel_disp_x: T) -> T {
    occlusion_from_step(focus_weight_x, depth_step_fast(rel_disp_y - rel_disp_x))
}

/// [`occlusion_fast`] and its derivative with respect to the source's disparity,
/// `(O, dO/dd_y = e s'(D))`.
/// Equation M12 of docs/model.md.
#[inline(always)]
pub fn occlusion_fast_with_derivative<T: Real>(
    focus_weight_x: T,
    rel_disp_y: T,
    rel_disp_x: T,
) -> (T, T) {
    let (s, ds) = depth_step_fast_with_derivative(rel_disp_y - rel_disp_x);
    (occlusion_from_step(focus_weight_x, s), focus_weight_x * ds)
}

/// The receiver's factors of the occlusion's derivatives in the fast form, free of `e`:
/// `(s'(D), s(D) - 1)`, so that `dO/dd_x|_e = -e s'(D)` and `dO/de = s(D) - 1`
/// ([`occlusion_derivatives`]); summed over taps before `e` multiplies them.
/// Equation M12 of docs/model.md.
#[inline(always)]
pub fn occlusion_receiver_factors_fast<T: Real>(rel_disp_y: T, rel_disp_x: T) -> (T, T) {
    let (s, ds) = depth_step_fast_with_derivative(rel_disp_y - rel_disp_x);
    (ds, s - T::one())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_step_derivative_from_value_agrees_with_the_exact_one() {
        let mut worst = 0.0f64;
        for i in -2000..=2000 {
            let diff = i as f64 * 5e-4;
            let exact = depth_step_derivative(diff);
            let from_exact_value = depth_step_derivative_from_value(depth_step(diff));
            let fast32 = depth_step_derivative_from_value(depth_step_fast(diff as f32)) as f64;
            assert!((from_exact_value - exact).abs() <= 1e-12, "{diff}");
            worst = worst.max((fast32 - exact).abs());
        }
        // f32 with the polynomial exp: within a few f32 ulps of the peak value 5.
        assert!(worst < 5e-6, "worst {worst}");
    }

    #[test]
    fn the_fast_occlusion_agrees_with_the_exact_one_and_its_derivatives() {
        for i in -200..=200 {
            let d_y = i as f64 * 5e-3;
            for (e, d_x) in [(1.0, 0.1), (0.4, -0.3), (0.0, 0.5)] {
                let exact = occlusion(e, d_y, d_x);
                assert!((occlusion_fast(e, d_y, d_x) - exact).abs() < 1e-12);
                let (ddy, ddx, de) = occlusion_derivatives(e, d_y, d_x);
                let (o, ddy_fast) = occlusion_fast_with_derivative(e, d_y, d_x);
                let (ds, s_minus_1) = occlusion_receiver_factors_fast(d_y, d_x);
                assert!((o - exact).abs() < 1e-12);
                assert!((ddy_fast - ddy).abs() < 1e-9, "{d_y} {e}");
                assert!((-e * ds - ddx).abs() < 1e-9 && (s_minus_1 - de).abs() < 1e-12);
            }
        }
    }
}
