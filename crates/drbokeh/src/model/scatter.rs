//! The scatter term's radius, soft step, source area and tail (docs/model.md, "Scatter
//! radius", "Scatter step", "Source area", "Tail"): each beside its derivative and, where the
//! fast engine needs it, its [`Real::exp_fast`] form.

use super::options::{Footprint, ScatterStep};
use crate::camera::{Window, WindowCap};
use crate::Real;

/// Relative disparity `d = disp - f`.
/// Equation M1 of docs/model.md.
#[inline(always)]
pub fn relative_disparity<T: Real>(disparity: T, focus: T) -> T {
    disparity - focus
}

/// Scatter radius in pixels `r = K |d| + footprint`: the paper's footprint is 1
/// ([`Footprint`]); `dr/dd = K sign(d)`, `dr/dK = |d|` either way.
/// Equation M2 of docs/model.md.
#[inline(always)]
pub fn scatter_radius_px<T: Real>(blur_k: T, rel_disp: T, footprint_px: T) -> T {
    blur_k * rel_disp.abs() + footprint_px
}

/// `d|d|/dd`, the sign of `d` (0 at the kink): `dr/dd = K` times this and `dr/dK = |d|`
/// ([`scatter_radius_px`]).
/// Equation M2 of docs/model.md.
#[inline(always)]
pub fn scatter_radius_sign<T: Real>(rel_disp: T) -> T {
    if rel_disp > T::zero() {
        T::one()
    } else if rel_disp < T::zero() {
        -T::one()
    } else {
        T::zero()
    }
}

/// The largest scatter radius any preset gives a pixel of relative disparity
/// `max_defocus`: `K max|d| + 1`, with the largest pixel footprint of any preset
/// ([`Footprint::LARGEST_PX`]), so that one window serves every preset and method compared
/// on a scene.
/// Equation M22 of docs/model.md.
pub fn largest_scatter_radius_px(blur_k: f64, max_defocus: f64) -> f64 {
    scatter_radius_px(blur_k.abs(), max_defocus, Footprint::LARGEST_PX)
}

/// The automatic window for a stack whose largest relative disparity over pixels with
/// alpha > 0 is `max_defocus` ([`largest_scatter_radius_px`] and [`Window::automatic`]):
/// the one rule of every automatic window (front ends, evaluation, gallery, benchmarks).
/// Equation M22 of docs/model.md.
pub fn automatic_window(blur_k: f64, max_defocus: f64, cap: WindowCap) -> Window {
    Window::automatic(largest_scatter_radius_px(blur_k, max_defocus), cap)
}

/// Soft scatter step `S = 1 / (1 + 10 exp(-3 (r - dist)))` (supplement eq. 2, distance not
/// squared), as a function of `r - dist`.
/// Equation M3 of docs/model.md.
#[inline(always)]
pub fn soft_step<T: Real>(r_minus_dist: T) -> T {
    T::one() / (T::one() + T::c(10.0) * (T::c(-3.0) * r_minus_dist).exp())
}

/// [`soft_step`] with [`Real::exp_fast`] (the fast engine's form; same formula).
/// Equation M3 of docs/model.md.
#[inline(always)]
pub fn soft_step_fast<T: Real>(r_minus_dist: T) -> T {
    T::one() / (T::one() + T::c(10.0) * (T::c(-3.0) * r_minus_dist).exp_fast())
}

/// How far beyond its radius a source's soft step is kept by the fast engine. Beyond
/// `dist = r + 4.5`, `S <= 0.1 e^{-3 (dist - r)}` is at most 1.4e-7, and the dropped ring
/// sums to at most `integral_{r+4.5}^inf 2 pi rho 0.1 e^{-3 (rho - r)} drho / r^2
/// = 0.21 (r + 4.83) e^{-13.5} / r^2 < 2e-6` of weight per unit alpha (largest at r = 1),
/// against a weight sum of at least `S(r)/r^2 ~ 0.67/r^2` from the receiver's own
/// neighbourhood wherever the layer is opaque: a relative error below about 3e-6 / r^0.
/// With the half-pixel footprint (r >= 0.5) the bound is
/// `0.21 * 5.33 e^{-13.5} / 0.25 < 6.2e-6` against at least `S(0.5)/0.25 = 1.24`: 5e-6.
/// The sharp step of preset `physical` ([`sharp_step`], `S <= e^{-6 (dist - r)}` beyond r)
/// drops at most `(pi/3) (r + 4.67) e^{-27} / (pi r^2 + 1/2) < 1e-11` of weight there.
/// Equation M21 of docs/model.md.
pub const SCATTER_TAIL_PX: f64 = 4.5;

/// Derivative of [`soft_step`] with respect to `r - dist`, from its value: `3 S (1 - S)`.
/// Equation M3 of docs/model.md.
#[inline(always)]
pub fn soft_step_derivative<T: Real>(s: T) -> T {
    T::c(3.0) * s * (T::one() - s)
}

/// The sharp step of preset `physical` ([`ScatterStep::Sharp`]):
/// `S = 1 / (1 + exp(-6 (r - dist)))`, half weight at `dist = r`.
/// Equation M4 of docs/model.md.
#[inline(always)]
pub fn sharp_step<T: Real>(r_minus_dist: T) -> T {
    T::one() / (T::one() + (T::c(-6.0) * r_minus_dist).exp())
}

/// [`sharp_step`] with [`Real::exp_fast`] (the fast engine's form; same formula).
/// Equation M4 of docs/model.md.
#[inline(always)]
pub fn sharp_step_fast<T: Real>(r_minus_dist: T) -> T {
    T::one() / (T::one() + (T::c(-6.0) * r_minus_dist).exp_fast())
}

/// The scatter term's soft step under `step`: [`soft_step`] or [`sharp_step`].
/// Equations M3, M4 of docs/model.md.
#[inline(always)]
pub fn scatter_step<T: Real>(step: ScatterStep, r_minus_dist: T) -> T {
    match step {
        ScatterStep::Paper => soft_step(r_minus_dist),
        ScatterStep::Sharp => sharp_step(r_minus_dist),
    }
}

/// [`scatter_step`] through [`Real::exp_fast`].
/// Equations M3, M4 of docs/model.md.
#[inline(always)]
pub fn scatter_step_fast<T: Real>(step: ScatterStep, r_minus_dist: T) -> T {
    match step {
        ScatterStep::Paper => soft_step_fast(r_minus_dist),
        ScatterStep::Sharp => sharp_step_fast(r_minus_dist),
    }
}

/// Derivative of [`scatter_step`] with respect to `r - dist`, from its value:
/// `3 S (1 - S)` (paper) or `6 S (1 - S)` (sharp).
/// Equations M3, M4 of docs/model.md.
#[inline(always)]
pub fn scatter_step_derivative<T: Real>(step: ScatterStep, s: T) -> T {
    match step {
        ScatterStep::Paper => soft_step_derivative(s),
        ScatterStep::Sharp => T::c(6.0) * s * (T::one() - s),
    }
}

/// Area normalisation of a source of radius `r`: the paper's `A = r^2`, or for the sharp
/// step its kernel's area `A = pi r^2 + 1/2` (the sum of `S` over the pixel grid: `pi r^2`
/// for large r, 0.51 at `r = 0`, 1.16 at 0.5, 3.3 at 1, against 0.5, 1.29 and 3.64).
/// Equation M7 of docs/model.md.
#[inline(always)]
pub fn source_area<T: Real>(step: ScatterStep, radius_px: T) -> T {
    match step {
        ScatterStep::Paper => radius_px * radius_px,
        ScatterStep::Sharp => T::c(std::f64::consts::PI) * radius_px * radius_px + T::c(0.5),
    }
}

/// `dA/dr` of [`source_area`]: `2 r` or `2 pi r`.
/// Equation M7 of docs/model.md.
#[inline(always)]
pub fn source_area_derivative<T: Real>(step: ScatterStep, radius_px: T) -> T {
    match step {
        ScatterStep::Paper => T::c(2.0) * radius_px,
        ScatterStep::Sharp => T::c(2.0 * std::f64::consts::PI) * radius_px,
    }
}

/// `A'(r) / A(r)` of [`source_area`] (`2 / r` for the paper's `r^2`).
/// Equation M7 of docs/model.md.
#[inline(always)]
pub fn source_area_log_derivative<T: Real>(step: ScatterStep, radius_px: T) -> T {
    source_area_derivative(step, radius_px) / source_area(step, radius_px)
}

/// The derivative of the normalised scatter term with respect to the source radius,
/// times the area: `A d(S/A)/dr = S' - S A'/A`, from `S`, `S' = dS/dr` and `A'/A`.
/// Equation M23 of docs/model.md.
#[inline(always)]
pub fn normalised_scatter_radius_factor<T: Real>(s: T, ds_dr: T, dlog_area: T) -> T {
    ds_dr - s * dlog_area
}

/// Radius of the in-focus footprint a kernel aperture is unioned with: the paper's 1, or
/// half a pixel for the sharp step (the centre pixel only).
/// Equation M6 of docs/model.md.
#[inline(always)]
pub fn kernel_footprint_radius_px<T: Real>(step: ScatterStep) -> T {
    match step {
        ScatterStep::Paper => T::one(),
        ScatterStep::Sharp => T::c(0.5),
    }
}
