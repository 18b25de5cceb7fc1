//! Edge-aware smoothness of a disparity map, guided by an image.
//!
//! ```text
//! G = (1/N) sum_{i<N} [ mean(|dx D_i| exp(-|dx I_i|)) + mean(|dy D_i| exp(-|dy I_i|)) ]
//! ```
//!
//! with `N` = [`SMOOTHNESS_LEVELS`] = 4. `D_0` is the disparity and `I_0` the guide image;
//! `D_{i+1}`, `I_{i+1}` are the 2x2 average-pooled ([`avg_pool2`]) levels below them.
//! `dx D(x, y) = D(x+1, y) - D(x, y)` (forward differences; the `x` mean runs over the
//! `(w-1) h` horizontal differences of the level, the `y` mean over the `w (h-1)` vertical
//! ones). For a guide with several channels, `|dx I|` is the **mean over channels** of
//! `|dx I_c|`, so the edge weight `exp(-|dx I|)` is one number per difference. The guide is
//! a constant: gradients are taken with respect to the disparity only.

use super::check::check_image;
use super::pyramid::{avg_pool2, avg_pool2_adjoint};
use crate::{Error, Image, Real, Result};

/// Number of pyramid levels `N` in the smoothness term.
pub const SMOOTHNESS_LEVELS: usize = 4;

/// The edge-aware smoothness `G` of a one-channel `disparity` map guided by `guide` (any
/// number of channels, same width and height); see the [module documentation](self).
///
/// Fails if the disparity has more than one channel, the sizes differ, or a side is shorter
/// than 16 pixels (so that the coarsest of the 4 levels still has 2 pixels per side).
pub fn edge_aware_smoothness<T: Real>(disparity: &Image<T>, guide: &Image<T>) -> Result<T> {
    Ok(evaluate(disparity, guide, false)?.0)
}

/// [`edge_aware_smoothness`] and its gradient with respect to `disparity` (a one-channel
/// image of the disparity's size). Where a disparity difference is exactly zero, the
/// subgradient 0 of `|.|` is used.
pub fn edge_aware_smoothness_grad<T: Real>(
    disparity: &Image<T>,
    guide: &Image<T>,
) -> Result<(T, Image<T>)> {
    let (value, grad) = evaluate(disparity, guide, true)?;
    // `evaluate` always returns a gradient when asked for one.
    let grad = grad.ok_or_else(|| Error::input("smoothness", "gradient missing"))?;
    Ok((value, grad))
}

fn evaluate<T: Real>(
    disparity: &Image<T>,
    guide: &Image<T>,
    want_grad: bool,
) -> Result<(T, Option<Image<T>>)> {
    check_image("smoothness disparity", disparity)?;
    check_image("smoothness guide", guide)?;
    if disparity.channels != 1 {
        return Err(Error::input(
            "smoothness disparity",
            format!("must have 1 channel, has {}", disparity.channels),
        ));
    }
    if (disparity.width, disparity.height) != (guide.width, guide.height) {
        return Err(Error::input(
            "smoothness guide",
            format!(
                "is {}x{}, disparity is {}x{}",
                guide.width, guide.height, disparity.width, disparity.height
            ),
        ));
    }
    let min_side = 2usize << (SMOOTHNESS_LEVELS - 1);
    if disparity.width < min_side || disparity.height < min_side {
        return Err(Error::input(
            "smoothness disparity",
            format!(
                "{}x{} is too small for a {SMOOTHNESS_LEVELS}-level pyramid (needs at least {min_side}x{min_side})",
                disparity.width, disparity.height
            ),
        ));
    }

    let mut ds = vec![disparity.clone()];
    let mut gs = vec![guide.clone()];
    for i in 1..SMOOTHNESS_LEVELS {
        let d = avg_pool2(&ds[i - 1])?;
        let g = avg_pool2(&gs[i - 1])?;
        ds.push(d);
        gs.push(g);
    }

    let inv_levels = 1.0 / SMOOTHNESS_LEVELS as f64;
    let mut total = 0.0;
    let mut level_grads = Vec::new();
    for (d, g) in ds.iter().zip(&gs) {
        let (value, grad) = level(d, g, T::c(inv_levels), want_grad);
        total += value;
        level_grads.push(grad);
    }
    let value = T::c(total * inv_levels);
    if !want_grad {
        return Ok((value, None));
    }

    // Back through the pyramid, coarsest level first.
    let mut acc: Option<Image<T>> = None;
    for i in (0..SMOOTHNESS_LEVELS).rev() {
        let mut g = level_grads[i]
            .take()
            .unwrap_or_else(|| Image::new(ds[i].width, ds[i].height, 1));
        if let Some(coarser) = acc {
            let spread = avg_pool2_adjoint(&coarser, ds[i].width, ds[i].height)?;
            for (a, b) in g.data.iter_mut().zip(&spread.data) {
                *a = *a + *b;
            }
        }
        acc = Some(g);
    }
    Ok((value, acc))
}

/// One level's `mean(|dx D| e^{-|dx I|}) + mean(|dy D| e^{-|dy I|})`, and, if asked, its
/// gradient with respect to `d`, scaled by `scale`.
fn level<T: Real>(
    d: &Image<T>,
    guide: &Image<T>,
    scale: T,
    want_grad: bool,
) -> (f64, Option<Image<T>>) {
    let (w, h, c) = (d.width, d.height, guide.channels);
    let inv_c = T::c(1.0 / c as f64);
    let mut grad = want_grad.then(|| Image::new(w, h, 1));
    let mut value = 0.0;

    // One difference between pixels p -> q; `count` is the number of such differences.
    let mut term = |p: (usize, usize), q: (usize, usize), count: usize, sum: &mut f64| {
        let mut e = T::zero();
        for ch in 0..c {
            e = e + (guide.at(q.0, q.1, ch) - guide.at(p.0, p.1, ch)).abs();
        }
        let weight = (-(e * inv_c)).exp();
        let dd = d.at(q.0, q.1, 0) - d.at(p.0, p.1, 0);
        *sum += (dd.abs() * weight).f64();
        if let Some(g) = grad.as_mut() {
            if dd != T::zero() {
                let s = dd.signum() * weight * scale / T::c(count as f64);
                *g.at_mut(q.0, q.1, 0) = g.at(q.0, q.1, 0) + s;
                *g.at_mut(p.0, p.1, 0) = g.at(p.0, p.1, 0) - s;
            }
        }
    };

    let nx = (w - 1) * h;
    let mut sum_x = 0.0;
    for y in 0..h {
        for x in 0..w - 1 {
            term((x, y), (x + 1, y), nx, &mut sum_x);
        }
    }
    let ny = w * (h - 1);
    let mut sum_y = 0.0;
    for y in 0..h - 1 {
        for x in 0..w {
            term((x, y), (x, y + 1), ny, &mut sum_y);
        }
    }
    value += sum_x / nx as f64 + sum_y / ny as f64;
    (value, grad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::testutil::{check_gradient, Rng};

    #[test]
    fn constant_disparity_is_zero_and_ramp_is_exact() {
        let guide = Image::<f64>::new(16, 16, 3);
        let flat = Image::from_vec(16, 16, 1, vec![0.7; 256]).unwrap();
        assert_eq!(edge_aware_smoothness(&flat, &guide).unwrap(), 0.0);
        // D = x on a constant guide: |dx D_i| = 2^i at level i (pooling halves the
        // resolution, keeps the ramp's values), |dy D_i| = 0; the weights are exp(0) = 1.
        let ramp: Vec<f64> = (0..256).map(|i| (i % 16) as f64).collect();
        let ramp = Image::from_vec(16, 16, 1, ramp).unwrap();
        let expected = (1.0 + 2.0 + 4.0 + 8.0) / 4.0;
        let v = edge_aware_smoothness(&ramp, &guide).unwrap();
        assert!((v - expected).abs() < 1e-12, "{v}");
    }

    #[test]
    fn colour_guide_edges_use_channel_mean() {
        // A vertical edge in the guide between x = 7 and x = 8 at level 0 only shrinks the
        // weight of that column of differences, by exp(-mean_c |dx I_c|).
        let mut guide = Image::<f64>::new(16, 16, 3);
        for y in 0..16 {
            for x in 8..16 {
                *guide.at_mut(x, y, 0) = 0.9;
                *guide.at_mut(x, y, 1) = 0.3;
            }
        }
        let ramp: Vec<f64> = (0..256).map(|i| (i % 16) as f64).collect();
        let ramp = Image::from_vec(16, 16, 1, ramp).unwrap();
        let flat_guide = Image::<f64>::new(16, 16, 3);
        let v_flat = edge_aware_smoothness(&ramp, &flat_guide).unwrap();
        let v = edge_aware_smoothness(&ramp, &guide).unwrap();
        // Level 0: one of 15 columns of x-differences gets weight exp(-0.4). The edge sits on
        // a pooling-block boundary at every level (x = 7 | 8, then 3 | 4, 1 | 2, 0 | 1), so
        // it persists with the same strength; the ramp's differences are 2^i at level i.
        let w0 = (-0.4f64).exp();
        let level0 = (14.0 + w0) / 15.0;
        let level1 = 2.0 * (6.0 + w0) / 7.0;
        let level2 = 4.0 * (2.0 + w0) / 3.0;
        let level3 = 8.0 * w0;
        let expected = (level0 + level1 + level2 + level3) / 4.0;
        assert!((v - expected).abs() < 1e-12, "{v} vs {expected}");
        assert!(v < v_flat);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let mut rng = Rng::new(5);
        let guide = rng.image(19, 17, 3, 0.0, 1.0);
        let disp = rng.image(19, 17, 1, 0.0, 1.0);
        // The random point must be away from the kinks of |.|: check all level differences.
        let mut level = disp.clone();
        for i in 0..SMOOTHNESS_LEVELS {
            if i > 0 {
                level = avg_pool2(&level).unwrap();
            }
            for y in 0..level.height {
                for x in 0..level.width {
                    if x + 1 < level.width {
                        assert!((level.at(x + 1, y, 0) - level.at(x, y, 0)).abs() > 1e-4);
                    }
                    if y + 1 < level.height {
                        assert!((level.at(x, y + 1, 0) - level.at(x, y, 0)).abs() > 1e-4);
                    }
                }
            }
        }
        let (v, grad) = edge_aware_smoothness_grad(&disp, &guide).unwrap();
        assert_eq!(v, edge_aware_smoothness(&disp, &guide).unwrap());
        let f = |d: &Image<f64>| edge_aware_smoothness(d, &guide).unwrap();
        check_gradient(&f, &disp, &grad, 60, &mut rng);
    }

    #[test]
    fn rejects_bad_inputs() {
        let g = Image::<f32>::new(16, 16, 3);
        assert!(edge_aware_smoothness(&Image::<f32>::new(16, 16, 2), &g).is_err());
        assert!(edge_aware_smoothness(&Image::<f32>::new(16, 17, 1), &g).is_err());
        let small = Image::<f32>::new(15, 15, 1);
        assert!(edge_aware_smoothness_grad(&small, &Image::<f32>::new(15, 15, 1)).is_err());
        assert!(edge_aware_smoothness(&Image::<f32>::new(16, 16, 1), &g).is_ok());
    }
}
