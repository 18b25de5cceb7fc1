//! One tap of the window: the mask `M`, the borders, the aperture's scatter term and the
//! tap weight `c(y,x) = a(y) M S(y,x) / A(y) O(y,x)` (docs/model.md, "Window and borders",
//! "Aperture", "Tap weight").

use super::coverage::MIN_COVERAGE_RADIUS_PX;
use super::occlusion::occlusion;
use super::options::ScatterStep;
use super::scatter::{
    kernel_footprint_radius_px, scatter_step, scatter_step_derivative, source_area, SCATTER_TAIL_PX,
};
use crate::aperture::{Aperture, KernelImage};
use crate::Real;

/// Window mask `M(x - y) = 1` iff `dist < R` (strict).
/// Equation M8 of docs/model.md.
#[inline(always)]
pub fn in_window(dx: isize, dy: isize, window_radius_px: usize) -> bool {
    ((dx * dx + dy * dy) as f64).sqrt() < window_radius_px as f64
}

/// Reflection padding index (mirror without repeating the edge pixel), folded as often as
/// needed so that any offset maps into `0..n`.
/// Equation M9 of docs/model.md.
#[inline(always)]
pub fn reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let m = i.rem_euclid(period);
    (if m < n as isize { m } else { period - m }) as usize
}

/// The aperture prepared for evaluation in float type `T`.
/// Equations M5, M6, M21 of docs/model.md.
#[derive(Clone, Debug)]
pub(crate) enum ApertureEval<T> {
    /// Circle and polygon: `S(r - gauge)`, the gauge precomputed per tap.
    Gauge,
    /// A kernel image.
    Kernel(KernelImage, std::marker::PhantomData<T>),
}

impl<T: Real> ApertureEval<T> {
    /// Distance beyond which a source of radius `r` contributes at most the soft step's
    /// dropped tail ([`SCATTER_TAIL_PX`]): the polygon lies inside the
    /// circle (its gauge is at least the distance), and a kernel reaches the corner of its
    /// square, `sqrt(2) r`, plus one texel of bilinear support.
    /// Equations M6, M21 of docs/model.md.
    pub(crate) fn reach_px(&self, radius_px: f64) -> f64 {
        let tail = SCATTER_TAIL_PX;
        match self {
            ApertureEval::Gauge => radius_px + tail,
            ApertureEval::Kernel(k, _) => {
                let (w, h) = k.size();
                let texel = 2.0 / w.max(h) as f64;
                (std::f64::consts::SQRT_2 * radius_px * (1.0 + texel) + 1.0).max(1.0 + tail)
            }
        }
    }

    /// Prepares an aperture for evaluation (equations M5, M6 of docs/model.md).
    pub(crate) fn new(a: &Aperture) -> Self {
        match a {
            Aperture::Kernel(k) => ApertureEval::Kernel(k.clone(), std::marker::PhantomData),
            _ => ApertureEval::Gauge,
        }
    }
}

/// The soft scatter term of a tap for a source of radius `r` under the given aperture:
/// `S(r - gauge)` for circle and polygon, the kernel image sampled at `(dx, dy) / r` and
/// unioned with the in-focus footprint for a kernel aperture; with `DERIV`, also its
/// derivative with respect to `r` (else 0).
/// Equations M5, M6 of docs/model.md.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn scatter_term_and<T: Real, const DERIV: bool>(
    step: ScatterStep,
    aperture: &ApertureEval<T>,
    dx: isize,
    dy: isize,
    dist: T,
    gauge: T,
    radius_y_px: T,
) -> (T, T) {
    match aperture {
        ApertureEval::Gauge => {
            let s = scatter_step(step, radius_y_px - gauge);
            let ds = if DERIV {
                scatter_step_derivative(step, s)
            } else {
                T::zero()
            };
            (s, ds)
        }
        ApertureEval::Kernel(k, _) => {
            let r = radius_y_px.f64().max(MIN_COVERAGE_RADIUS_PX);
            let (u, v) = (dx as f64 / r, dy as f64 / r);
            let (shape, du, dv) = k.sample_with_gradient(u, v);
            let footprint = scatter_step(step, kernel_footprint_radius_px::<T>(step) - dist);
            if T::c(shape) >= footprint {
                // d/dr k(dx/r, dy/r) = -(du * dx + dv * dy) / r^2
                let ds = if DERIV {
                    T::c(-(du * dx as f64 + dv * dy as f64) / (r * r))
                } else {
                    T::zero()
                };
                (T::c(shape), ds)
            } else {
                (footprint, T::zero())
            }
        }
    }
}

/// The scatter term of a tap ([`scatter_term_and`] without the derivative).
/// Equations M5, M6 of docs/model.md.
#[inline(always)]
pub(crate) fn scatter_term<T: Real>(
    step: ScatterStep,
    aperture: &ApertureEval<T>,
    dx: isize,
    dy: isize,
    dist: T,
    gauge: T,
    radius_y_px: T,
) -> T {
    scatter_term_and::<T, false>(step, aperture, dx, dy, dist, gauge, radius_y_px).0
}

/// Tap weight `c(y,x) = a(y) M S(y,x) / A(y) O(y,x)` (M already applied by the caller).
/// Equation M13 of docs/model.md.
#[inline(always)]
pub fn tap_weight<T: Real>(
    step: ScatterStep,
    alpha_y: T,
    scatter: T,
    radius_y_px: T,
    occlusion: T,
) -> T {
    alpha_y * scatter / source_area(step, radius_y_px) * occlusion
}

/// [`tap_weight`] with the source area's reciprocal precomputed:
/// `c = a S (1/A) O` (the fast engine's form: one multiplication instead of a division).
/// Equation M13 of docs/model.md.
#[inline(always)]
pub fn tap_weight_inv_area<T: Real>(alpha_y: T, scatter: T, inv_area_y: T, occlusion: T) -> T {
    alpha_y * scatter * inv_area_y * occlusion
}

/// The tap weight of one masked tap, every term from the model: the scatter term under the
/// aperture ([`scatter_term`]), the occlusion ([`occlusion`]; exactly 1 for the centre tap
/// `(dx, dy) = (0, 0)` and where the receiver's focus weight is 0) and the source area.
/// Equation M13 of docs/model.md.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn masked_tap_weight<T: Real>(
    step: ScatterStep,
    aperture: &ApertureEval<T>,
    (dx, dy): (isize, isize),
    dist: T,
    gauge: T,
    (alpha_y, radius_y_px, rel_disp_y): (T, T, T),
    (focus_weight_x, rel_disp_x): (T, T),
) -> T {
    let s = scatter_term(step, aperture, dx, dy, dist, gauge, radius_y_px);
    let o = if (dx == 0 && dy == 0) || focus_weight_x == T::zero() {
        T::one()
    } else {
        occlusion(focus_weight_x, rel_disp_y, rel_disp_x)
    };
    tap_weight(step, alpha_y, s, radius_y_px, o)
}

/// One window offset inside the mask, with its geometry precomputed.
/// Equation M8 of docs/model.md.
#[derive(Clone, Copy, Debug)]
pub struct Tap {
    /// Horizontal offset `y - x` in pixels.
    pub dx: isize,
    /// Vertical offset in pixels.
    pub dy: isize,
    /// Euclidean distance between pixel centres.
    pub dist: f64,
    /// The aperture's gauge of the offset (equals `dist` for the circle).
    pub gauge: f64,
}

/// All offsets of the `(2R+1)^2` window with `M = 1`, row-major.
/// Equation M8 of docs/model.md.
pub fn window_taps(window_radius_px: usize, aperture: &Aperture) -> Vec<Tap> {
    let r = window_radius_px as isize;
    let mut taps = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            if in_window(dx, dy, window_radius_px) {
                taps.push(Tap {
                    dx,
                    dy,
                    dist: ((dx * dx + dy * dy) as f64).sqrt(),
                    gauge: aperture.gauge(dx as f64, dy as f64),
                });
            }
        }
    }
    taps
}
