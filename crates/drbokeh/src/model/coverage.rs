//! The layer coverage `o(x)` (docs/model.md, "Coverage"): the paper's box mean of alpha,
//! and the soft-disc coverage of preset `physical`, with its radius and derivatives.

use super::options::CoverageRadius;
use crate::Real;

/// Half-size of the paper's coverage box: `min(floor(r(x) / 2), R)`.
/// Equation M15 of docs/model.md.
#[inline(always)]
pub fn coverage_half_size_px<T: Real>(radius_x_px: T, window_radius_px: usize) -> usize {
    let h = (radius_x_px.f64() / 2.0).floor();
    (h.max(0.0) as usize).min(window_radius_px)
}

/// Layer coverage `o(x)`: the mean of alpha over the square of half-size `h` around x.
/// `alpha_at(dx, dy)` returns alpha at offset (dx, dy) from x (borders already handled).
/// Equation M15 of docs/model.md.
#[inline]
pub fn box_coverage<T: Real>(half_size_px: usize, alpha_at: impl Fn(isize, isize) -> T) -> T {
    let h = half_size_px as isize;
    let mut sum = T::zero();
    for dy in -h..=h {
        for dx in -h..=h {
            sum = sum + alpha_at(dx, dy);
        }
    }
    let n = (2 * half_size_px + 1) * (2 * half_size_px + 1);
    sum / T::c(n as f64)
}

/// Smallest radius of the soft-disc coverage (keeps a kernel aperture's `v / r` finite).
/// Equation M16 of docs/model.md.
pub const MIN_COVERAGE_RADIUS_PX: f64 = 1e-6;

/// Radius of the receiver's disc in the soft-disc coverage, from its scatter radius
/// `r(x)`, and its derivative `dr_c/dr(x)`: `r(x)` itself ([`CoverageRadius::Scatter`]) or
/// the circle of confusion `r(x) - footprint = K |d(x)|`
/// ([`CoverageRadius::CircleOfConfusion`], at least [`MIN_COVERAGE_RADIUS_PX`]).
/// Equation M16 of docs/model.md.
#[inline(always)]
pub fn coverage_radius_px<T: Real>(
    radius_x_px: T,
    kind: CoverageRadius,
    footprint_px: T,
) -> (T, T) {
    match kind {
        CoverageRadius::Scatter => (radius_x_px, T::one()),
        CoverageRadius::CircleOfConfusion => {
            let r = radius_x_px - footprint_px;
            let min = T::c(MIN_COVERAGE_RADIUS_PX);
            if r > min {
                (r, T::one())
            } else {
                (min, T::zero())
            }
        }
    }
}

/// Soft-disc layer coverage (preset `physical`): alpha averaged
/// over the receiver's own soft aperture,
/// `o(x) = sum_y M(x-y) S(r(x), y) a(y) / sum_y M(x-y) S(r(x), y)`,
/// with the scatter term's S, M and aperture (`scatter_term`, M5, M6) but the radius `r(x)` of
/// the receiver. Derivatives: `do/da(y) = S(r(x), y) / Z`, `do/dr(x) = sum_y S'(a(y) - o) / Z`
/// with `Z = sum_y M S(r(x), y)` (at least `S(r(x), 0)`, the centre tap).
/// Accumulate every masked tap with [`DiscCoverage::add`] (or `add_with_derivative`).
/// Equation M16 of docs/model.md.
#[derive(Clone, Copy, Debug, Default)]
pub struct DiscCoverage<T> {
    /// `sum_y S a(y)`.
    pub alpha_sum: T,
    /// `Z = sum_y S`.
    pub weight: T,
    /// `sum_y S' a(y)` (`S' = dS/dr(x)`), when derivatives are accumulated.
    pub d_alpha_sum: T,
    /// `sum_y S'`, when derivatives are accumulated.
    pub d_weight: T,
}

impl<T: Real> DiscCoverage<T> {
    /// Adds one tap: its scatter term `S(r(x), y)` and alpha `a(y)`.
    /// Equation M16 of docs/model.md.
    #[inline(always)]
    pub fn add(&mut self, scatter: T, alpha_y: T) {
        self.alpha_sum = self.alpha_sum + scatter * alpha_y;
        self.weight = self.weight + scatter;
    }

    /// Adds one tap with the derivative of its scatter term with respect to `r(x)`.
    /// Equation M16 of docs/model.md.
    #[inline(always)]
    pub fn add_with_derivative(&mut self, scatter: T, d_scatter_dr: T, alpha_y: T) {
        self.add(scatter, alpha_y);
        self.d_alpha_sum = self.d_alpha_sum + d_scatter_dr * alpha_y;
        self.d_weight = self.d_weight + d_scatter_dr;
    }

    /// The coverage `o(x) = sum S a / Z`.
    /// Equation M16 of docs/model.md.
    #[inline(always)]
    pub fn value(&self) -> T {
        self.alpha_sum / self.weight
    }

    /// `do/dr(x) = (sum S' a - o sum S') / Z` (needs `add_with_derivative`).
    /// Equation M16 of docs/model.md.
    #[inline(always)]
    pub fn derivative_radius(&self) -> T {
        (self.d_alpha_sum - self.value() * self.d_weight) / self.weight
    }
}
