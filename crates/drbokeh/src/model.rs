//! THE EQUATION, once. Every term of `shared/spec/rendering-model.md` is a function here;
//! engines (reference, threaded, ...) call these and never re-derive them.
//!
//! Notation (spec): `d(y) = disp(y) - f` relative disparity, `r(y) = K|d(y)| + 1` scatter
//! radius in pixels, `S` soft scatter, `A = r^2` area, `O` soft occlusion, `c(y,x)` tap
//! weight, `B_l` layer colour, `o_l` layer coverage, `T_l` transmittance.

use crate::aperture::{Aperture, ApertureEval};
use crate::presets::{CoverageRadius, RenderSettings, ScatterStep, Transfer};
use crate::stack::Layer;
use crate::Real;

/// The regulariser in `B = C / (W + 1e-8)`.
pub const WEIGHT_EPSILON: f64 = 1e-8;

/// Relative disparity `d = disp - f` (spec: "Relative disparity").
#[inline(always)]
pub fn relative_disparity<T: Real>(disparity: T, focus: T) -> T {
    disparity - focus
}

/// Scatter radius in pixels `r = K |d| + footprint`: the paper's footprint is 1
/// ([`crate::presets::Footprint`]); `dr/dd = K sign(d)`, `dr/dK = |d|` either way.
#[inline(always)]
pub fn scatter_radius_px<T: Real>(blur_k: T, rel_disp: T, footprint_px: T) -> T {
    blur_k * rel_disp.abs() + footprint_px
}

/// Soft scatter step `S = 1 / (1 + 10 exp(-3 (r - dist)))` (supplement eq. 2, distance not
/// squared), as a function of `r - dist`.
#[inline(always)]
pub fn soft_step<T: Real>(r_minus_dist: T) -> T {
    T::one() / (T::one() + T::c(10.0) * (T::c(-3.0) * r_minus_dist).exp())
}

/// [`soft_step`] with [`Real::exp_fast`] (the fast engine's form; same formula).
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
pub const SCATTER_TAIL_PX: f64 = 4.5;

/// Derivative of [`soft_step`] with respect to `r - dist`, from its value: `3 S (1 - S)`.
#[inline(always)]
pub fn soft_step_derivative<T: Real>(s: T) -> T {
    T::c(3.0) * s * (T::one() - s)
}

/// The sharp step of preset `physical` ([`ScatterStep::Sharp`]):
/// `S = 1 / (1 + exp(-6 (r - dist)))`, half weight at `dist = r`.
#[inline(always)]
pub fn sharp_step<T: Real>(r_minus_dist: T) -> T {
    T::one() / (T::one() + (T::c(-6.0) * r_minus_dist).exp())
}

/// [`sharp_step`] with [`Real::exp_fast`] (the fast engine's form; same formula).
#[inline(always)]
pub fn sharp_step_fast<T: Real>(r_minus_dist: T) -> T {
    T::one() / (T::one() + (T::c(-6.0) * r_minus_dist).exp_fast())
}

/// The scatter term's soft step under `step`: [`soft_step`] or [`sharp_step`].
#[inline(always)]
pub fn scatter_step<T: Real>(step: ScatterStep, r_minus_dist: T) -> T {
    match step {
        ScatterStep::Paper => soft_step(r_minus_dist),
        ScatterStep::Sharp => sharp_step(r_minus_dist),
    }
}

/// [`scatter_step`] through [`Real::exp_fast`].
#[inline(always)]
pub fn scatter_step_fast<T: Real>(step: ScatterStep, r_minus_dist: T) -> T {
    match step {
        ScatterStep::Paper => soft_step_fast(r_minus_dist),
        ScatterStep::Sharp => sharp_step_fast(r_minus_dist),
    }
}

/// Derivative of [`scatter_step`] with respect to `r - dist`, from its value:
/// `3 S (1 - S)` (paper) or `6 S (1 - S)` (sharp).
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
#[inline(always)]
pub fn source_area<T: Real>(step: ScatterStep, radius_px: T) -> T {
    match step {
        ScatterStep::Paper => radius_px * radius_px,
        ScatterStep::Sharp => T::c(std::f64::consts::PI) * radius_px * radius_px + T::c(0.5),
    }
}

/// `dA/dr` of [`source_area`]: `2 r` or `2 pi r`.
#[inline(always)]
pub fn source_area_derivative<T: Real>(step: ScatterStep, radius_px: T) -> T {
    match step {
        ScatterStep::Paper => T::c(2.0) * radius_px,
        ScatterStep::Sharp => T::c(2.0 * std::f64::consts::PI) * radius_px,
    }
}

/// Radius of the in-focus footprint a kernel aperture is unioned with: the paper's 1, or
/// half a pixel for the sharp step (the centre pixel only).
#[inline(always)]
pub fn kernel_footprint_radius_px<T: Real>(step: ScatterStep) -> T {
    match step {
        ScatterStep::Paper => T::one(),
        ScatterStep::Sharp => T::c(0.5),
    }
}

/// Window mask `M(x - y) = 1` iff `dist < R` (strict).
#[inline(always)]
pub fn in_window(dx: isize, dy: isize, window_radius_px: usize) -> bool {
    ((dx * dx + dy * dy) as f64).sqrt() < window_radius_px as f64
}

/// Focus weight of a receiver `e(x) = exp(-3 (K d(x))^2)`: 1 in focus, 0 when very blurred.
#[inline(always)]
pub fn focus_weight<T: Real>(blur_k: T, rel_disp_x: T) -> T {
    let kd = blur_k * rel_disp_x;
    (T::c(-3.0) * kd * kd).exp()
}

/// Partial derivatives of [`focus_weight`] from its value `e`:
/// `(de/dd_x, de/dK) = (-6 K^2 d_x e, -6 K d_x^2 e)`.
#[inline(always)]
pub fn focus_weight_derivatives<T: Real>(blur_k: T, rel_disp_x: T, e: T) -> (T, T) {
    let six = T::c(6.0);
    (
        -six * blur_k * blur_k * rel_disp_x * e,
        -six * blur_k * rel_disp_x * rel_disp_x * e,
    )
}

/// Depth step `s(D) = 1/2 + 1/2 tanh(10 (D - 0.1))`.
#[inline(always)]
pub fn depth_step<T: Real>(disp_difference: T) -> T {
    T::c(0.5) + T::c(0.5) * (T::c(10.0) * (disp_difference - T::c(0.1))).tanh()
}

/// [`depth_step`] with `tanh(z) = 1 - 2 / (exp(2z) + 1)` through [`Real::exp_fast`].
#[inline(always)]
pub fn depth_step_fast<T: Real>(disp_difference: T) -> T {
    let z = T::c(20.0) * (disp_difference - T::c(0.1));
    // 1/2 + 1/2 tanh(z/2)... with z = 2 * 10 (D - 0.1): 1/2 + 1/2 (1 - 2/(e^z + 1)) = 1 - 1/(e^z + 1)
    T::one() - T::one() / (z.exp_fast() + T::one())
}

/// Derivative of [`depth_step`]: `5 (1 - tanh^2(10 (D - 0.1)))`.
#[inline(always)]
pub fn depth_step_derivative<T: Real>(disp_difference: T) -> T {
    let t = (T::c(10.0) * (disp_difference - T::c(0.1))).tanh();
    T::c(5.0) * (T::one() - t * t)
}

/// Derivative of [`depth_step`] from its value `s`: `20 s (1 - s)`. Since
/// `s = 1/2 + 1/2 tanh(u)` gives `1 - tanh^2(u) = 4 s (1 - s)`, this equals
/// [`depth_step_derivative`]; with [`depth_step_fast`] it is the fast engine's form (no
/// second transcendental).
#[inline(always)]
pub fn depth_step_derivative_from_value<T: Real>(s: T) -> T {
    T::c(20.0) * s * (T::one() - s)
}

/// Soft occlusion `O(y,x) = 1 + e(x) (s(d(y) - d(x)) - 1)` (supplement eq. 1 with its sign
/// slip corrected); the centre tap has `O(x,x) = 1`, which callers handle.
#[inline(always)]
pub fn occlusion<T: Real>(focus_weight_x: T, rel_disp_y: T, rel_disp_x: T) -> T {
    T::one() + focus_weight_x * (depth_step(rel_disp_y - rel_disp_x) - T::one())
}

/// Partial derivatives of [`occlusion`] (non-centre taps):
/// `dO/dd_y = e s'(D)`, `dO/dd_x|_e = -e s'(D)`, `dO/de = s(D) - 1`, with `D = d_y - d_x`.
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

/// Half-size of the paper's coverage box: `min(floor(r(x) / 2), R)`.
#[inline(always)]
pub fn coverage_half_size_px<T: Real>(radius_x_px: T, window_radius_px: usize) -> usize {
    let h = (radius_x_px.f64() / 2.0).floor();
    (h.max(0.0) as usize).min(window_radius_px)
}

/// Layer coverage `o(x)`: the mean of alpha over the square of half-size `h` around x.
/// `alpha_at(dx, dy)` returns alpha at offset (dx, dy) from x (borders already handled).
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
pub const MIN_COVERAGE_RADIUS_PX: f64 = 1e-6;

/// Radius of the receiver's disc in the soft-disc coverage, from its scatter radius
/// `r(x)`, and its derivative `dr_c/dr(x)`: `r(x)` itself ([`CoverageRadius::Scatter`]) or
/// the circle of confusion `r(x) - footprint = K |d(x)|`
/// ([`CoverageRadius::CircleOfConfusion`], at least [`MIN_COVERAGE_RADIUS_PX`]).
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

/// Soft-disc layer coverage (spec "Beyond the paper"; preset `physical`): alpha averaged
/// over the receiver's own soft aperture,
/// `o(x) = sum_y M(x-y) S(r(x), y) a(y) / sum_y M(x-y) S(r(x), y)`,
/// with the scatter term's S, M and aperture ([`scatter_term`]) but the radius `r(x)` of
/// the receiver. Derivatives: `do/da(y) = S(r(x), y) / Z`, `do/dr(x) = sum_y S'(a(y) - o) / Z`
/// with `Z = sum_y M S(r(x), y)` (at least `S(r(x), 0) >= 2/3`, the centre tap).
/// Accumulate every masked tap with [`DiscCoverage::add`] (or `add_with_derivative`).
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
    #[inline(always)]
    pub fn add(&mut self, scatter: T, alpha_y: T) {
        self.alpha_sum = self.alpha_sum + scatter * alpha_y;
        self.weight = self.weight + scatter;
    }

    /// Adds one tap with the derivative of its scatter term with respect to `r(x)`.
    #[inline(always)]
    pub fn add_with_derivative(&mut self, scatter: T, d_scatter_dr: T, alpha_y: T) {
        self.add(scatter, alpha_y);
        self.d_alpha_sum = self.d_alpha_sum + d_scatter_dr * alpha_y;
        self.d_weight = self.d_weight + d_scatter_dr;
    }

    /// The coverage `o(x) = sum S a / Z`.
    #[inline(always)]
    pub fn value(&self) -> T {
        self.alpha_sum / self.weight
    }

    /// `do/dr(x) = (sum S' a - o sum S') / Z` (needs `add_with_derivative`).
    #[inline(always)]
    pub fn derivative_radius(&self) -> T {
        (self.d_alpha_sum - self.value() * self.d_weight) / self.weight
    }
}

/// Display encoding to linear: `lin = (I + offset)^g`.
#[inline(always)]
pub fn linearize<T: Real>(encoded: T, gamma: T, offset: T) -> T {
    (encoded + offset).powf(gamma)
}

/// Linear to display encoding: `out = lin^(1/g) - offset`.
#[inline(always)]
pub fn encode<T: Real>(linear: T, gamma: T, offset: T) -> T {
    linear.powf(T::one() / gamma) - offset
}

/// Derivative of [`encode`]: `(1/g) lin^(1/g - 1)`; 0 where `lin <= 0` (undefined there).
#[inline(always)]
pub fn encode_derivative<T: Real>(linear: T, gamma: T) -> T {
    if linear <= T::zero() {
        return T::zero();
    }
    linear.powf(T::one() / gamma - T::one()) / gamma
}

/// Exact sRGB decoding (IEC 61966-2-1; spec "Beyond the paper", preset `physical`) and its
/// derivative `(lin, dlin/dI)`:
/// `lin = I / 12.92` if `I <= 0.04045`, else `((I + 0.055) / 1.055)^2.4`;
/// `dlin/dI = 1 / 12.92`, else `(2.4 / 1.055) ((I + 0.055) / 1.055)^1.4`.
#[inline(always)]
pub fn srgb_to_linear_with_derivative<T: Real>(encoded: T) -> (T, T) {
    if encoded <= T::c(0.04045) {
        (encoded / T::c(12.92), T::one() / T::c(12.92))
    } else {
        let b = (encoded + T::c(0.055)) / T::c(1.055);
        (b.powf(T::c(2.4)), T::c(2.4 / 1.055) * b.powf(T::c(1.4)))
    }
}

/// Exact sRGB encoding, the inverse of [`srgb_to_linear_with_derivative`]:
/// `I = 12.92 lin` if `lin <= 0.0031308`, else `1.055 lin^(1/2.4) - 0.055`.
#[inline(always)]
pub fn linear_to_srgb<T: Real>(linear: T) -> T {
    if linear <= T::c(0.0031308) {
        T::c(12.92) * linear
    } else {
        T::c(1.055) * linear.powf(T::c(1.0 / 2.4)) - T::c(0.055)
    }
}

/// Derivative of [`linear_to_srgb`]: `12.92`, else `(1.055 / 2.4) lin^(1/2.4 - 1)`.
#[inline(always)]
pub fn linear_to_srgb_derivative<T: Real>(linear: T) -> T {
    if linear <= T::c(0.0031308) {
        T::c(12.92)
    } else {
        T::c(1.055 / 2.4) * linear.powf(T::c(1.0 / 2.4 - 1.0))
    }
}

/// The display transfer of a render: the model option [`Transfer`] with the camera's gamma
/// and offset (used by [`Transfer::Gamma`] only).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tone {
    /// Which curve.
    pub transfer: Transfer,
    /// Gamma `g` of [`Transfer::Gamma`].
    pub gamma: f64,
    /// Offset of [`Transfer::Gamma`].
    pub offset: f64,
}

impl Tone {
    /// A transfer with the camera's gamma and offset.
    pub fn new(transfer: Transfer, gamma: f64, offset: f64) -> Self {
        Tone {
            transfer,
            gamma,
            offset,
        }
    }

    /// The tone of a render's settings.
    pub fn of(settings: &RenderSettings) -> Self {
        settings.tone()
    }

    /// Display-encoded value to linear, and its derivative `dlin/dI`. For the gamma curve:
    /// [`linearize`] and `g (I + offset)^(g-1)` (0 where `I + offset <= 0`).
    #[inline(always)]
    pub fn linearize_with_derivative<T: Real>(&self, encoded: T) -> (T, T) {
        match self.transfer {
            Transfer::Gamma => {
                let (gamma, offset) = (T::c(self.gamma), T::c(self.offset));
                let base = encoded + offset;
                let lin = base.powf(gamma);
                let dlin = if base > T::zero() {
                    gamma * base.powf(gamma - T::one())
                } else {
                    T::zero()
                };
                (lin, dlin)
            }
            Transfer::Srgb => srgb_to_linear_with_derivative(encoded),
        }
    }

    /// Display-encoded value to linear.
    #[inline(always)]
    pub fn linearize<T: Real>(&self, encoded: T) -> T {
        match self.transfer {
            Transfer::Gamma => linearize(encoded, T::c(self.gamma), T::c(self.offset)),
            Transfer::Srgb => srgb_to_linear_with_derivative(encoded).0,
        }
    }

    /// Linear to display encoding ([`encode`] or [`linear_to_srgb`]).
    #[inline(always)]
    pub fn encode<T: Real>(&self, linear: T) -> T {
        match self.transfer {
            Transfer::Gamma => encode(linear, T::c(self.gamma), T::c(self.offset)),
            Transfer::Srgb => linear_to_srgb(linear),
        }
    }

    /// Derivative of [`Tone::encode`] ([`encode_derivative`] or [`linear_to_srgb_derivative`]).
    #[inline(always)]
    pub fn encode_derivative<T: Real>(&self, linear: T) -> T {
        match self.transfer {
            Transfer::Gamma => encode_derivative(linear, T::c(self.gamma)),
            Transfer::Srgb => linear_to_srgb_derivative(linear),
        }
    }
}

/// Linear colour of a source pixel, and its partial derivatives. With `highlight`, the
/// display-encoded value is first boosted by `1 + 0.2 m`, with
/// `m = clip(tanh(200 ((disp - f)^2 - 0.01)), 0, 1) * clip(tanh(10 (I - 200/255)), 0, 1)`.
/// Returns the linear colour of a source pixel with the optional highlight boost, and its partial
/// derivatives `(lin, dlin/dI, dlin/dd)` with respect to the encoded value `I` and the
/// relative disparity `d`. (`tanh < 1`, so only the lower clip can be active.)
#[inline]
pub fn source_linear_with_derivatives<T: Real>(
    encoded: T,
    rel_disp: T,
    highlight: bool,
    tone: &Tone,
) -> (T, T, T) {
    let (boosted, d_boost_di, d_boost_dd) = if highlight {
        let arg_p = T::c(200.0) * (rel_disp * rel_disp - T::c(0.01));
        let arg_q = T::c(10.0) * (encoded - T::c(200.0 / 255.0));
        let (tp, tq) = (arg_p.tanh(), arg_q.tanh());
        let (p, q) = (tp.max(T::zero()), tq.max(T::zero()));
        let dp = if arg_p > T::zero() {
            T::c(400.0) * rel_disp * (T::one() - tp * tp)
        } else {
            T::zero()
        };
        let dq = if arg_q > T::zero() {
            T::c(10.0) * (T::one() - tq * tq)
        } else {
            T::zero()
        };
        let gain = T::one() + T::c(0.2) * p * q;
        (
            encoded * gain,
            gain + encoded * T::c(0.2) * p * dq,
            encoded * T::c(0.2) * dp * q,
        )
    } else {
        (encoded, T::one(), T::zero())
    };
    let (lin, dlin) = tone.linearize_with_derivative(boosted);
    (lin, dlin * d_boost_di, dlin * d_boost_dd)
}

/// Reflection padding index (mirror without repeating the edge pixel), folded as often as
/// needed so that any offset maps into `0..n`.
#[inline(always)]
pub fn reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let m = i.rem_euclid(period);
    (if m < n as isize { m } else { period - m }) as usize
}

/// The soft scatter term of a tap for a source of radius `r` under the given aperture:
/// `S(r - gauge)` for circle and polygon, the kernel image for a kernel aperture.
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
    match aperture {
        ApertureEval::Gauge => scatter_step(step, radius_y_px - gauge),
        ApertureEval::Kernel(k, _) => {
            let r = radius_y_px.f64().max(MIN_COVERAGE_RADIUS_PX);
            let shape = T::c(k.sample(dx as f64 / r, dy as f64 / r));
            shape.max(scatter_step(
                step,
                kernel_footprint_radius_px::<T>(step) - dist,
            ))
        }
    }
}

/// [`scatter_term`] and its derivative with respect to the source radius `r`.
#[inline(always)]
pub(crate) fn scatter_term_with_derivative<T: Real>(
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
            (s, scatter_step_derivative(step, s))
        }
        ApertureEval::Kernel(k, _) => {
            let r = radius_y_px.f64().max(MIN_COVERAGE_RADIUS_PX);
            let (u, v) = (dx as f64 / r, dy as f64 / r);
            let (shape, du, dv) = k.sample_with_gradient(u, v);
            let footprint = scatter_step(step, kernel_footprint_radius_px::<T>(step) - dist);
            if T::c(shape) >= footprint {
                // d/dr k(dx/r, dy/r) = -(du * dx + dv * dy) / r^2
                (
                    T::c(shape),
                    T::c(-(du * dx as f64 + dv * dy as f64) / (r * r)),
                )
            } else {
                (footprint, T::zero())
            }
        }
    }
}

/// Tap weight `c(y,x) = a(y) M S(y,x) / A(y) O(y,x)` (M already applied by the caller).
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

/// One window offset inside the mask, with its geometry precomputed.
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

/// Running sums `C = sum Ilin(y) c(y,x)` and `W = sum c(y,x)` for one receiver and layer.
#[derive(Clone, Copy, Debug, Default)]
pub struct Accumulator<T> {
    /// Weighted colour sum.
    pub colour: [T; 3],
    /// Weight sum.
    pub weight: T,
}

impl<T: Real> Accumulator<T> {
    /// Adds one tap.
    #[inline(always)]
    pub fn add(&mut self, rgb_linear: [T; 3], c: T) {
        for (acc, v) in self.colour.iter_mut().zip(rgb_linear) {
            *acc = *acc + v * c;
        }
        self.weight = self.weight + c;
    }

    /// Layer colour `B = C / (W + 1e-8)`.
    #[inline(always)]
    pub fn layer_colour(&self) -> [T; 3] {
        let w = self.weight + T::c(WEIGHT_EPSILON);
        self.colour.map(|c| c / w)
    }
}

/// Front-to-back compositing `out = sum_l B_l o_l T_l`, `T_0 = 1`, `T_{l+1} = T_l (1 - o_l)`.
#[inline]
pub fn composite<T: Real>(layers: impl IntoIterator<Item = ([T; 3], T)>) -> [T; 3] {
    let mut out = [T::zero(); 3];
    let mut transmittance = T::one();
    for (colour, coverage) in layers {
        for (o, c) in out.iter_mut().zip(colour) {
            *o = *o + c * coverage * transmittance;
        }
        transmittance = transmittance * (T::one() - coverage);
    }
    out
}

/// Per-pixel terms of one layer, computed once before the gather: linear colour (after
/// the optional highlight boost), alpha, relative disparity `d`, radius `r`, focus weight `e`.
#[derive(Clone, Debug)]
pub struct PreparedLayer<T> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear colour, 3 values per pixel.
    pub rgb_linear: Vec<T>,
    /// Alpha.
    pub alpha: Vec<T>,
    /// Relative disparity `d`.
    pub rel_disp: Vec<T>,
    /// Scatter radius `r` in pixels.
    pub radius_px: Vec<T>,
    /// Focus weight `e`.
    pub focus_weight: Vec<T>,
}

/// Computes the per-pixel terms of a layer for a render's settings (camera, display
/// transfer, footprint).
pub fn prepare_layer<T: Real>(layer: &Layer<T>, settings: &RenderSettings) -> PreparedLayer<T> {
    let camera = &settings.camera;
    let tone = &settings.tone();
    let footprint = T::c(settings.model().footprint.px());
    let (k, f) = (T::c(camera.blur_k), T::c(camera.focus_disparity));
    let rel_disp: Vec<T> = layer
        .disparity
        .data
        .iter()
        .map(|&v| relative_disparity(v, f))
        .collect();
    let mut rgb_linear = Vec::with_capacity(layer.rgb_encoded.data.len());
    for (px, &d) in layer.rgb_encoded.data.chunks_exact(3).zip(&rel_disp) {
        for &encoded in px {
            rgb_linear.push(source_linear_with_derivatives(encoded, d, camera.highlight, tone).0);
        }
    }
    PreparedLayer {
        width: layer.alpha.width,
        height: layer.alpha.height,
        rgb_linear,
        alpha: layer.alpha.data.clone(),
        radius_px: rel_disp
            .iter()
            .map(|&d| scatter_radius_px(k, d, footprint))
            .collect(),
        focus_weight: rel_disp.iter().map(|&d| focus_weight(k, d)).collect(),
        rel_disp,
    }
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
}
