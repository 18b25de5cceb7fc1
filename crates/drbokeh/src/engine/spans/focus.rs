//! The occlusion term of in-focus receivers, as spans.
//!
//! For a non-centre tap `O(y,x) = (1 - e(x)) + e(x) s(d(y) - d(x))` (docs/model.md,
//! "Occlusion"), so a receiver's sums split into a plain scatter `P(x) = sum_y v(y) S` and
//! `Q(x) = sum_y v(y) S s(d(y) - d(x))`: `C = (1 - e) P + e Q` (plus the centre tap, whose
//! `O = 1`). `Q` depends on the receiver's own `d(x)`, so it is not a scatter; but it is
//! needed only where `e(x) >= FOCUS_CUTOFF` ([`FOCUS_CUTOFF`]), where `d(x)` lies in a
//! short interval `[lo, hi]` (at most `2 sqrt(ln(1/FOCUS_CUTOFF) / 3) / K` wide). On it,
//! `s(d(y) - delta)` is interpolated in `delta` at `J` Chebyshev points `delta_j`:
//! `s(d(y) - delta) ~ sum_j l_j(delta) s(d(y) - delta_j)`, so
//! `Q(x) ~ sum_j l_j(d(x)) Q_j(x)` with `Q_j(x) = sum_y v(y) S s(d(y) - delta_j)`: `J`
//! plain scatters with per-source weights ([`Nodes`]).
//!
//! **Bound.** `s(D) = 1/2 + 1/2 tanh(10 (D - 0.1))` is the logistic `1 / (1 + e^{-z})` of
//! `z = 20 (D - 0.1)`, whose poles lie at `Im z = +-pi`. In the strip `|Im z| <= b`
//! (`pi/2 < b < pi`) `|1 + e^{-z}| >= sin b`, so `|s| <= 1 / sin b`. With `delta` in an
//! interval of half-width `h` (`z`-half-width `20 h`), the Bernstein ellipse of the
//! interval whose semi-minor axis is `b / 20` has `rho = b / (20 h) + sqrt(1 + (b / (20 h))^2)`,
//! and the Chebyshev interpolant through `J` points of the second kind errs by at most
//! `4 M rho^{-(J-1)} / (rho - 1)` (Trefethen, *Approximation Theory and Approximation
//! Practice*, Thm 8.2) for every `d(y)`. [`Nodes::new`] takes the smallest `J` whose bound
//! (minimised over `b`) is at most [`INTERPOLATION_ERROR`]. Sources whose `s` stays within
//! [`INTERPOLATION_ERROR`] of 0 or 1 over the interval are summed as 0 or 1.
//! Each `Q` sum then errs by at most `2e-6 P` (all weights are positive), and the receiver's
//! `C` and `W` by at most `e 2e-6 P`.
//!
//! Receivers with `e(x) < FOCUS_CUTOFF` take `O = 1`: `C` and `W` are overestimated by
//! `e (P - Q) <= e P < FOCUS_CUTOFF P`, a relative error below `FOCUS_CUTOFF / (1 - e)`.

use crate::model;

/// Receivers with a focus weight `e(x)` below this take `O = 1` (relative error below
/// `1e-6` in `C` and `W`).
pub const FOCUS_CUTOFF: f64 = 1e-6;

/// The largest error allowed of the interpolated depth step, and of treating a source's
/// depth step as exactly 0 or 1.
pub const INTERPOLATION_ERROR: f64 = 1e-6;

/// The most interpolation points: wider intervals (small K) leave in-focus receivers to the
/// tap path.
pub const MAX_NODES: usize = 24;

/// Chebyshev points on the receivers' disparity interval, with barycentric weights.
#[derive(Clone, Debug)]
pub struct Nodes {
    /// `delta_j` (second kind, `J >= 2` points, or one point for an empty interval).
    pub delta: Vec<f64>,
    /// Barycentric weights `(-1)^j`, halved at both ends.
    weights: Vec<f64>,
    /// The interval.
    pub lo: f64,
    /// The interval's upper end.
    pub hi: f64,
}

/// The interpolation error bound with `J` points on an interval of half-width `h` (in
/// disparity), minimised over the strip half-width `b` (see the module documentation).
pub fn interpolation_bound(half_width: f64, points: usize) -> f64 {
    if half_width <= 0.0 {
        return 0.0;
    }
    let zh = 20.0 * half_width;
    (1..=19)
        .map(|i| {
            let b = std::f64::consts::FRAC_PI_2 + std::f64::consts::FRAC_PI_2 * i as f64 / 20.0;
            let m = 1.0 / b.sin();
            let q = b / zh;
            let rho = q + (1.0 + q * q).sqrt();
            4.0 * m * rho.powi(-(points as i32 - 1)) / (rho - 1.0)
        })
        .fold(f64::INFINITY, f64::min)
}

impl Nodes {
    /// The fewest Chebyshev points on `[lo, hi]` whose bound is at most
    /// [`INTERPOLATION_ERROR`]; `None` if that needs more than [`MAX_NODES`].
    pub fn new(lo: f64, hi: f64) -> Option<Self> {
        let h = (hi - lo) / 2.0;
        if h <= 1e-12 {
            // Every receiver has the same disparity: interpolation is exact.
            return Some(Nodes {
                delta: vec![(lo + hi) / 2.0],
                weights: vec![1.0],
                lo,
                hi,
            });
        }
        let j = (2..=MAX_NODES).find(|&j| interpolation_bound(h, j) <= INTERPOLATION_ERROR)?;
        let mid = (lo + hi) / 2.0;
        let delta = (0..j)
            .map(|k| mid + h * (std::f64::consts::PI * k as f64 / (j - 1) as f64).cos())
            .collect();
        let weights = (0..j)
            .map(|k| {
                let w = if k % 2 == 0 { 1.0 } else { -1.0 };
                if k == 0 || k == j - 1 {
                    w / 2.0
                } else {
                    w
                }
            })
            .collect();
        Some(Nodes {
            delta,
            weights,
            lo,
            hi,
        })
    }

    /// Number of points `J`.
    pub fn len(&self) -> usize {
        self.delta.len()
    }

    /// The Lagrange basis `l_j(delta)` at `delta` (barycentric formula), into `out`.
    pub fn basis(&self, delta: f64, out: &mut [f64]) {
        if let Some(k) = self.delta.iter().position(|&d| d == delta) {
            out.iter_mut().for_each(|v| *v = 0.0);
            out[k] = 1.0;
            return;
        }
        let mut sum = 0.0;
        for (o, (&d, &w)) in out.iter_mut().zip(self.delta.iter().zip(&self.weights)) {
            *o = w / (delta - d);
            sum += *o;
        }
        out.iter_mut().for_each(|v| *v /= sum);
    }
}

/// How a source's depth step behaves over the receivers' interval.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepClass {
    /// `s < INTERPOLATION_ERROR` everywhere: the source adds nothing to `Q`.
    Zero,
    /// `s > 1 - INTERPOLATION_ERROR` everywhere: the source adds `v S` to `Q`.
    One,
    /// In between: the source adds `v S s(d(y) - delta_j)` to each `Q_j`.
    Interpolated,
}

/// The class of a source of relative disparity `rel_disp_y` for receivers in
/// `[nodes.lo, nodes.hi]` (`s` decreases with the receiver's disparity).
#[inline]
pub fn classify(nodes: &Nodes, rel_disp_y: f64) -> StepClass {
    if model::depth_step(rel_disp_y - nodes.hi) >= 1.0 - INTERPOLATION_ERROR {
        StepClass::One
    } else if model::depth_step(rel_disp_y - nodes.lo) <= INTERPOLATION_ERROR {
        StepClass::Zero
    } else {
        StepClass::Interpolated
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bound holds where it matters most: sources whose step's inflection lies inside
    /// the interval, for the intervals of K = 10 .. 100.
    #[test]
    fn interpolation_meets_its_bound_at_the_worst_case() {
        for k in [12.0, 20.0, 30.0, 50.0, 100.0, 300.0] {
            let h = ((1.0f64 / FOCUS_CUTOFF).ln() / 3.0).sqrt() / k;
            let nodes = Nodes::new(-h, h).expect("few enough points");
            let mut basis = vec![0.0; nodes.len()];
            let mut worst = 0.0f64;
            for i in -600..=600 {
                let d_y = 0.1 + i as f64 * h / 300.0;
                let values: Vec<f64> = nodes
                    .delta
                    .iter()
                    .map(|&d| model::depth_step(d_y - d))
                    .collect();
                for t in 0..=200 {
                    let delta = -h + 2.0 * h * t as f64 / 200.0;
                    nodes.basis(delta, &mut basis);
                    let approx: f64 = basis.iter().zip(&values).map(|(b, v)| b * v).sum();
                    worst = worst.max((approx - model::depth_step(d_y - delta)).abs());
                }
            }
            assert!(
                worst <= INTERPOLATION_ERROR,
                "K {k}: {} points, worst {worst:e}",
                nodes.len()
            );
            assert!(interpolation_bound(h, nodes.len()) <= INTERPOLATION_ERROR);
        }
    }

    #[test]
    fn saturated_classes_are_within_the_error() {
        let nodes = Nodes::new(-0.05, 0.07).unwrap();
        for i in -300..=300 {
            let d_y = i as f64 * 0.005;
            let class = classify(&nodes, d_y);
            for t in 0..=20 {
                let delta = -0.05 + 0.12 * t as f64 / 20.0;
                let s = model::depth_step(d_y - delta);
                match class {
                    StepClass::Zero => assert!(s <= INTERPOLATION_ERROR),
                    StepClass::One => assert!(s >= 1.0 - INTERPOLATION_ERROR),
                    StepClass::Interpolated => {}
                }
            }
        }
    }
}
