//! The plane-sweep initialisation ([`super::Init::Sweep`]).

use super::maps::to_image;
use super::{render_layer_on, DfdOptions};
use crate::image::Image;
use crate::{Real, Result};

/// The candidate planes of one sweep pass.
pub(super) struct Planes<'a> {
    /// Number of constant disparities, evenly spaced over [0, 1].
    pub count: usize,
    /// Radius of the cost window, px.
    pub window_radius: usize,
    /// A disparity kept in front of every candidate (the second pass,
    /// [`super::DfdOptions::sweep_context`]): the candidate `d` renders `max(front, d)`,
    /// and a pixel takes only `front` itself or candidates `d >= front`. `None`: plain
    /// planes.
    pub front: Option<&'a [f64]>,
}

/// Plane sweep at one scale: for each of `planes.count` constant disparities, the absolute
/// difference between its render and the target, averaged over a `(2 radius + 1)^2`
/// window with edge-aware weights (pixels of a similar colour in the all-in-focus image
/// count more: [`guided_mean`]; left-out pixels count zero); each pixel takes the
/// disparity with the smallest difference, refined between the sampled disparities by a
/// parabola through the smallest difference and its two neighbours.
pub(super) fn sweep<T: Real>(
    options: &DfdOptions,
    settings: &crate::RenderSettings,
    aif: &Image<T>,
    target: &Image<T>,
    excluded: &[bool],
    planes: &Planes,
) -> Result<Vec<f64>> {
    let (n, radius, behind) = (planes.count, planes.window_radius, planes.front);
    let (w, h) = (aif.width, aif.height);
    let guide: Vec<[f64; 3]> = aif
        .data
        .chunks_exact(3)
        .map(|p| [p[0].f64(), p[1].f64(), p[2].f64()])
        .collect();
    let mut costs: Vec<Vec<f64>> = Vec::with_capacity(n);
    for k in 0..n {
        let d = k as f64 / (n - 1) as f64;
        let plane: Vec<f64> = match behind {
            Some(front) => front.iter().map(|&f| f.max(d)).collect(),
            None => vec![d; w * h],
        };
        let disp: Image<T> = to_image(&plane, w, h, 1);
        let render = render_layer_on(options.layer, options.engine, aif, &disp, settings)?;
        let err: Vec<f64> = (0..w * h)
            .map(|i| {
                if excluded[i] {
                    return 0.0;
                }
                (0..3)
                    .map(|c| {
                        (render.data[3 * i + c].f64().clamp(0.0, 1.0)
                            - target.data[3 * i + c].f64())
                        .abs()
                    })
                    .sum::<f64>()
            })
            .collect();
        costs.push(guided_mean(&err, &guide, w, h, radius));
    }
    let step = 1.0 / (n - 1) as f64;
    Ok((0..w * h)
        .map(|i| pick_behind(&costs, i, step, behind.map_or(0.0, |front| front[i])))
        .collect())
}

/// The second pass's pick for pixel `i`, whose eroded first estimate is `front`: among
/// `front` itself and the samples behind it (`d >= front`). The first plane renders
/// `max(front, 0) = front` everywhere, so its cost is the cost of `front` at this pixel;
/// with it as the lower sample, a pixel whose best sample is the first one behind `front`
/// is refined between the two as well (a parabola through three unevenly spaced samples),
/// instead of keeping the sweep's step. With `front` 0 (the first pass: nothing in front)
/// every plane is a sample.
fn pick_behind(costs: &[Vec<f64>], i: usize, step: f64, front: f64) -> f64 {
    let n = costs.len();
    let first = ((front / step - 1e-9).ceil().max(0.0) as usize).min(n - 1);
    let mut samples = [(0.0, 0.0); MAX_PLANES + 1];
    let mut len = 0;
    if first > 0 && front < first as f64 * step - 1e-9 {
        samples[0] = (front, costs[0][i]);
        len = 1;
    }
    for (k, plane) in costs.iter().enumerate().skip(first) {
        samples[len] = (k as f64 * step, plane[i]);
        len += 1;
    }
    pick(&samples[..len]).clamp(front.clamp(0.0, 1.0), 1.0)
}

/// The largest number of planes of one pass ([`super::Init::Sweep`]).
pub(super) const MAX_PLANES: usize = 64;

/// The pick among `(disparity, cost)` samples in increasing disparity (the same for both
/// passes): the sample of least cost (the first of equals), refined by the parabola through
/// it and its two neighbours where it has both.
fn pick(samples: &[(f64, f64)]) -> f64 {
    let best = (0..samples.len()).fold(0, |b, j| if samples[j].1 < samples[b].1 { j } else { b });
    let d = samples[best].0;
    if best == 0 || best + 1 == samples.len() {
        return d;
    }
    parabola_vertex(samples[best - 1], samples[best], samples[best + 1]).unwrap_or(d)
}

/// The vertex of the parabola through three samples `(x, y)` with `x0 < x1 < x2` and
/// `y1` the least, clamped to `[x0, x2]`; `None` where the three are (nearly) collinear.
fn parabola_vertex(
    (x0, y0): (f64, f64),
    (x1, y1): (f64, f64),
    (x2, y2): (f64, f64),
) -> Option<f64> {
    let (a, b) = (x1 - x0, x1 - x2);
    let num = a * a * (y1 - y2) - b * b * (y1 - y0);
    let den = a * (y1 - y2) - b * (y1 - y0);
    if den.abs() < 1e-15 {
        return None;
    }
    Some((x1 - 0.5 * num / den).clamp(x0, x2))
}

/// Colour distance (encoded, RMS over channels) at which [`guided_mean`]'s weight is
/// `exp(-1/2)`.
const SWEEP_GUIDE_SIGMA: f64 = 0.1;

/// Edge-aware mean of a one-channel map over a `(2r+1)^2` window: weight
/// `exp(-|I(x) - I(y)|^2 / (2 sigma^2))` by the guide colours (a joint bilateral box), so
/// a window straddling an object boundary averages mostly the pixel's own side.
fn guided_mean(data: &[f64], guide: &[[f64; 3]], w: usize, h: usize, r: usize) -> Vec<f64> {
    use rayon::prelude::*;
    let inv = 1.0 / (2.0 * 3.0 * SWEEP_GUIDE_SIGMA * SWEEP_GUIDE_SIGMA);
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let g = guide[i];
            let (mut s, mut n) = (0.0, 0.0);
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    let j = yy * w + xx;
                    let q = guide[j];
                    let d2 = (g[0] - q[0]).powi(2) + (g[1] - q[1]).powi(2) + (g[2] - q[2]).powi(2);
                    let wt = (-d2 * inv).exp();
                    s += wt * data[j];
                    n += wt;
                }
            }
            s / n
        })
        .collect()
}

/// Minimum of a one-channel map over a `(2r+1)^2` window (separable): the erosion of the
/// nearer (larger) disparities.
pub(super) fn min_filter(data: &[f64], w: usize, h: usize, r: usize) -> Vec<f64> {
    let mut rows = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r + 1).min(w));
            rows[y * w + x] = data[y * w + a..y * w + b]
                .iter()
                .cloned()
                .fold(f64::INFINITY, f64::min);
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (y.saturating_sub(r), (y + r + 1).min(h));
            out[y * w + x] = (a..b)
                .map(|yy| rows[yy * w + x])
                .fold(f64::INFINITY, f64::min);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{parabola_vertex, pick_behind, MAX_PLANES};

    /// The one-pass pick (`front` 0) over evenly spaced planes is the closed-form vertex
    /// `x1 + step (a - c) / (2 (a - 2b + c))` of the three samples around the least cost
    /// (the formula of the one-pass code before the two picks shared [`super::pick`]), and
    /// the largest sweep fits.
    #[test]
    fn one_pass_pick_is_the_even_spacing_vertex() {
        for n in [2, 3, 9, MAX_PLANES] {
            let step = 1.0 / (n - 1) as f64;
            for centre in [0.0, 0.13, 0.5, 0.77, 1.0] {
                // An asymmetric bowl, so the vertex of three samples is not the minimum.
                let f = |x: f64| (x - centre).abs().powf(1.5) + 0.1;
                let costs: Vec<Vec<f64>> = (0..n).map(|k| vec![f(k as f64 * step)]).collect();
                let best = (0..n).fold(0, |b, k| if costs[k][0] < costs[b][0] { k } else { b });
                let mut want = best as f64 * step;
                if best > 0 && best + 1 < n {
                    let (a, b, c) = (costs[best - 1][0], costs[best][0], costs[best + 1][0]);
                    want += 0.5 * (a - c) / (a - 2.0 * b + c) * step;
                }
                let got = pick_behind(&costs, 0, step, 0.0);
                assert!(
                    (got - want).abs() < 1e-12,
                    "n {n} centre {centre}: {got} vs {want}"
                );
            }
        }
    }

    /// Unevenly spaced samples of `(x - 0.3)^2 + 1` give the vertex back; collinear ones
    /// give none.
    #[test]
    fn parabola_vertex_of_uneven_samples() {
        let f = |x: f64| (x - 0.3) * (x - 0.3) + 1.0;
        let v = parabola_vertex((0.1, f(0.1)), (0.25, f(0.25)), (0.5, f(0.5))).unwrap();
        assert!((v - 0.3).abs() < 1e-12, "vertex {v}");
        assert_eq!(parabola_vertex((0.0, 1.0), (0.5, 1.0), (1.0, 1.0)), None);
    }

    /// The second pass's pick takes the eroded estimate's own cost (plane 0) as its lowest
    /// sample: a pixel whose costs fall towards it is refined below the first sample behind
    /// it, and it never goes in front of it.
    #[test]
    fn second_pass_pick_refines_between_the_front_and_the_first_sample() {
        // Nine planes (step 1/8), front 0.3: the first sample behind it is 0.375.
        let f = |x: f64| (x - 0.34) * (x - 0.34);
        let costs: Vec<Vec<f64>> = (0..9).map(|k| vec![f((k as f64 / 8.0).max(0.3))]).collect();
        let d = pick_behind(&costs, 0, 1.0 / 8.0, 0.3);
        assert!((d - 0.34).abs() < 1e-9, "pick {d}");
        // Costs that fall in front of the front: the pick stays at the front.
        let g = |x: f64| x;
        let costs: Vec<Vec<f64>> = (0..9).map(|k| vec![g((k as f64 / 8.0).max(0.3))]).collect();
        assert_eq!(pick_behind(&costs, 0, 1.0 / 8.0, 0.3), 0.3);
    }
}
