//! Gaussian-window SSIM, its gradient, and the multi-window HSSIM loss.
//!
//! # Definition
//! This is the single SSIM implementation of the crate (the evaluation metric
//! [`crate::eval::metrics::ssim`] calls it too). Per channel, with a normalised 2-D Gaussian
//! window `w` (an [`SsimWindow`]: radius `r`, so `2r + 1` taps per axis, standard deviation
//! `sigma`), applied as a separable filter with **reflect** borders (half-sample symmetric,
//! `d c b a | a b c d | d c b a`, as `scipy.ndimage` `mode='reflect'`):
//!
//! ```text
//! ux = w * x,  uy = w * y,  vx = w * x^2 - ux^2,  vy = w * y^2 - uy^2,  vxy = w * (x y) - ux uy
//! S  = (2 ux uy + C1)(2 vxy + C2) / ((ux^2 + uy^2 + C1)(vx + vy + C2))
//! ```
//!
//! with `C1 = (0.01 R)^2`, `C2 = (0.03 R)^2` for data range `R = 1`, and population
//! (not sample) covariances. The SSIM value is the mean of `S` over the pixels at least `r`
//! from every border (the `r`-pixel strip is cropped), then the mean over channels. This is
//! scikit-image's `structural_similarity(gaussian_weights=True, use_sample_covariance=False,
//! data_range=1, channel_axis=-1)` computation; [`SsimWindow::skimage`] gives the window it
//! uses for a given `sigma` (radius `int(3.5 sigma + 0.5)`, 11 taps for `sigma = 1.5`).
//!
//! # Loss windows and HSSIM
//! The depth-from-defocus loss uses SSIM at window sizes `k` in [`HSSIM_WINDOWS`]
//! (`HSSIM = sum_k (1 - SSIM_k)`). [`SsimWindow::sized`]`(k)` is a `k`-tap Gaussian
//! (radius `(k-1)/2`, crop `(k-1)/2`) with `sigma = k/6`, so that the window spans
//! `+-3 sigma`. The standard deviation must grow with `k`: with the usual fixed
//! `sigma = 1.5`, the weights beyond radius 5 are below `exp(-(6^2)/(2 * 1.5^2)) ~ 3e-4` of
//! the centre, so the 21- and 31-tap windows would measure practically the same thing as
//! the 11-tap one, and the larger windows would add no regional feedback. Note that this is
//! *not* what scikit-image does when handed `sigma = k/6`: it always truncates its Gaussian
//! at `3.5 sigma` (a 13-tap filter, radius 6, for `sigma = 11/6`), whatever `win_size` says.

use super::check::check_same_shape;
use crate::{Error, Image, Real, Result};

/// The window sizes `k` of the HSSIM loss.
pub const HSSIM_WINDOWS: [usize; 5] = [3, 5, 11, 21, 31];

/// scikit-image's truncation of its SSIM Gaussian, in standard deviations.
pub const SKIMAGE_TRUNCATE: f64 = 3.5;

/// scikit-image's default SSIM Gaussian standard deviation.
pub const SKIMAGE_SIGMA: f64 = 1.5;

/// SSIM's `K1` (luminance stabiliser `C1 = (K1 R)^2`, data range `R = 1`).
pub const K1: f64 = 0.01;

/// SSIM's `K2` (contrast stabiliser `C2 = (K2 R)^2`, data range `R = 1`).
pub const K2: f64 = 0.03;

/// The largest accepted window radius.
pub const MAX_RADIUS: usize = 4096;

/// A Gaussian SSIM window: `2 * radius + 1` taps per axis, standard deviation `sigma`,
/// normalised to sum 1. The SSIM map is also cropped by `radius` pixels on every side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SsimWindow {
    radius: usize,
    sigma: f64,
}

impl SsimWindow {
    /// A window of `2 * radius + 1` taps and standard deviation `sigma`.
    ///
    /// Fails unless `sigma` is finite and positive and `radius <= MAX_RADIUS`.
    pub fn new(radius: usize, sigma: f64) -> Result<Self> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(Error::param(
                "SSIM sigma",
                format!("must be finite and positive, got {sigma}"),
            ));
        }
        if radius > MAX_RADIUS {
            return Err(Error::param(
                "SSIM window radius",
                format!("{radius} exceeds the limit {MAX_RADIUS}"),
            ));
        }
        Ok(SsimWindow { radius, sigma })
    }

    /// The loss window `SSIM_k`: `k` taps (radius `(k-1)/2`) and `sigma = k/6`.
    ///
    /// Fails unless `k` is odd and at least 3.
    pub fn sized(k: usize) -> Result<Self> {
        if k < 3 || k % 2 == 0 {
            return Err(Error::param(
                "SSIM window size",
                format!("must be odd and at least 3, got {k}"),
            ));
        }
        SsimWindow::new((k - 1) / 2, k as f64 / 6.0)
    }

    /// scikit-image's window for `sigma`: radius `int(3.5 sigma + 0.5)` (as
    /// `structural_similarity(gaussian_weights=True, sigma=sigma)` with no `win_size`).
    pub fn skimage(sigma: f64) -> Result<Self> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(Error::param(
                "SSIM sigma",
                format!("must be finite and positive, got {sigma}"),
            ));
        }
        let radius = (SKIMAGE_TRUNCATE * sigma + 0.5).floor();
        if radius > MAX_RADIUS as f64 {
            return Err(Error::param(
                "SSIM sigma",
                format!("{sigma} gives a window radius above {MAX_RADIUS}"),
            ));
        }
        SsimWindow::new(radius as usize, sigma)
    }

    /// scikit-image's default window: `sigma = 1.5`, 11 taps.
    pub fn skimage_default() -> Self {
        SsimWindow {
            radius: 5,
            sigma: SKIMAGE_SIGMA,
        }
    }

    /// The radius (also the width of the cropped border).
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// The standard deviation in pixels.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The number of taps per axis, `2 * radius + 1`.
    pub fn size(&self) -> usize {
        2 * self.radius + 1
    }

    /// The normalised 1-D weights `exp(-t^2 / (2 sigma^2)) / sum`, for `t = -radius..=radius`.
    pub fn weights(&self) -> Vec<f64> {
        let r = self.radius as isize;
        let w: Vec<f64> = (-r..=r)
            .map(|t| (-0.5 * (t * t) as f64 / (self.sigma * self.sigma)).exp())
            .collect();
        let sum: f64 = w.iter().sum();
        w.into_iter().map(|v| v / sum).collect()
    }
}

/// The SSIM of `x` against `y` with `window` (see the [module documentation](self)).
///
/// Fails if the images differ in shape or a side is shorter than the window.
pub fn ssim<T: Real>(x: &Image<T>, y: &Image<T>, window: &SsimWindow) -> Result<T> {
    check_ssim_inputs(x, y, window)?;
    let s = ssim_parts(x, y, window, window.radius, false);
    Ok(T::c(s.ssim))
}

/// [`ssim`] and its gradient with respect to the first image `x`.
pub fn ssim_grad<T: Real>(
    x: &Image<T>,
    y: &Image<T>,
    window: &SsimWindow,
) -> Result<(T, Image<T>)> {
    check_ssim_inputs(x, y, window)?;
    let s = ssim_parts(x, y, window, window.radius, true);
    let grad = s
        .grad
        .ok_or_else(|| Error::input("SSIM", "gradient missing"))?;
    Ok((T::c(s.ssim), grad))
}

/// `HSSIM = sum_{k in HSSIM_WINDOWS} (1 - SSIM_k(x, y))` with the windows
/// [`SsimWindow::sized`]`(k)`.
///
/// Fails if the images differ in shape or a side is shorter than 31 pixels.
pub fn hssim<T: Real>(x: &Image<T>, y: &Image<T>) -> Result<T> {
    check_hssim_inputs(x, y)?;
    let mut total = 0.0;
    for k in HSSIM_WINDOWS {
        total += 1.0 - ssim(x, y, &SsimWindow::sized(k)?)?.f64();
    }
    Ok(T::c(total))
}

/// [`hssim`] and its gradient with respect to the first image `x`
/// (`-sum_k dSSIM_k/dx`).
pub fn hssim_grad<T: Real>(x: &Image<T>, y: &Image<T>) -> Result<(T, Image<T>)> {
    check_hssim_inputs(x, y)?;
    let mut total = 0.0;
    let mut grad = Image::new(x.width, x.height, x.channels);
    for k in HSSIM_WINDOWS {
        let (v, g) = ssim_grad(x, y, &SsimWindow::sized(k)?)?;
        total += 1.0 - v.f64();
        for (a, b) in grad.data.iter_mut().zip(&g.data) {
            *a = *a - *b;
        }
    }
    Ok((T::c(total), grad))
}

/// Validates HSSIM inputs against the largest window.
fn check_hssim_inputs<T>(x: &Image<T>, y: &Image<T>) -> Result<()> {
    let largest = HSSIM_WINDOWS.iter().copied().max().unwrap_or(3);
    check_ssim_inputs(x, y, &SsimWindow::sized(largest)?)
}

/// Validates SSIM inputs: same shape, each side at least the window size.
pub(crate) fn check_ssim_inputs<T>(x: &Image<T>, y: &Image<T>, window: &SsimWindow) -> Result<()> {
    check_same_shape("SSIM first image", x, "SSIM second image", y)?;
    let k = window.size();
    if x.width < k || x.height < k {
        return Err(Error::input(
            "SSIM",
            format!(
                "images of {}x{} are smaller than the {k}x{k} window",
                x.width, x.height
            ),
        ));
    }
    Ok(())
}

/// The pieces of one SSIM evaluation.
pub(crate) struct SsimParts<T> {
    /// Mean of the SSIM map over the uncropped area and the channels.
    pub ssim: f64,
    /// Mean of the contrast-structure map `(2 vxy + C2) / (vx + vy + C2)`, likewise.
    pub cs: f64,
    /// Gradient of `ssim` with respect to the first image, if asked for.
    pub grad: Option<Image<T>>,
}

/// Evaluates SSIM (and the contrast-structure mean) with an explicit crop width. The inputs
/// must already be validated to have the same shape and `2 * crop < width, height`.
pub(crate) fn ssim_parts<T: Real>(
    x: &Image<T>,
    y: &Image<T>,
    window: &SsimWindow,
    crop: usize,
    want_grad: bool,
) -> SsimParts<T> {
    let (w, h, nc) = (x.width, x.height, x.channels);
    let filter = Filter::new(window, w, h);
    let c1 = T::c((K1 * 1.0) * (K1 * 1.0));
    let c2 = T::c((K2 * 1.0) * (K2 * 1.0));
    let two = T::c(2.0);
    let count = (w - 2 * crop) * (h - 2 * crop);
    let inv_count = T::c(1.0 / (count * nc) as f64);

    let mut grad = want_grad.then(|| Image::new(w, h, nc));
    let (mut ssim_sum, mut cs_sum) = (0.0, 0.0);
    let n = w * h;
    let mut xs = vec![T::zero(); n];
    let mut ys = vec![T::zero(); n];
    let mut prod = vec![T::zero(); n];
    let mut tmp = vec![T::zero(); n];
    for ch in 0..nc {
        for i in 0..n {
            xs[i] = x.data[i * nc + ch];
            ys[i] = y.data[i * nc + ch];
        }
        let ux = filter.apply(&xs, &mut tmp);
        let uy = filter.apply(&ys, &mut tmp);
        prod.iter_mut().zip(&xs).for_each(|(p, &a)| *p = a * a);
        let uxx = filter.apply(&prod, &mut tmp);
        prod.iter_mut().zip(&ys).for_each(|(p, &b)| *p = b * b);
        let uyy = filter.apply(&prod, &mut tmp);
        prod.iter_mut()
            .zip(xs.iter().zip(&ys))
            .for_each(|(p, (&a, &b))| *p = a * b);
        let uxy = filter.apply(&prod, &mut tmp);

        // Upstream gradients on ux, uxx, uxy (zero in the cropped border).
        let mut g_ux = vec![T::zero(); if want_grad { n } else { 0 }];
        let mut g_uxx = g_ux.clone();
        let mut g_uxy = g_ux.clone();
        for py in crop..h - crop {
            for px in crop..w - crop {
                let i = py * w + px;
                let (mx, my) = (ux[i], uy[i]);
                let vx = uxx[i] - mx * mx;
                let vy = uyy[i] - my * my;
                let vxy = uxy[i] - mx * my;
                let a1 = two * mx * my + c1;
                let a2 = two * vxy + c2;
                let b1 = mx * mx + my * my + c1;
                let b2 = vx + vy + c2;
                let d = b1 * b2;
                let s = a1 * a2 / d;
                ssim_sum += s.f64();
                cs_sum += (a2 / b2).f64();
                if want_grad {
                    // S = N / D with N = A1 A2, D = B1 B2:
                    // dS/dux  = (dN/dux - S dD/dux) / D,  dN/dux = 2 uy (A2 - A1),
                    //           dD/dux = 2 ux (B2 - B1)   (vx, vxy depend on ux too);
                    // dS/duxx = -S B1 / D;  dS/duxy = 2 A1 / D.
                    let inv_d = inv_count / d;
                    g_ux[i] = (two * my * (a2 - a1) - s * two * mx * (b2 - b1)) * inv_d;
                    g_uxx[i] = -s * b1 * inv_d;
                    g_uxy[i] = two * a1 * inv_d;
                }
            }
        }
        if let Some(grad) = grad.as_mut() {
            let gx = filter.adjoint(&g_ux, &mut tmp);
            let gxx = filter.adjoint(&g_uxx, &mut tmp);
            let gxy = filter.adjoint(&g_uxy, &mut tmp);
            for i in 0..n {
                grad.data[i * nc + ch] = gx[i] + two * xs[i] * gxx[i] + ys[i] * gxy[i];
            }
        }
    }
    let denom = (count * nc) as f64;
    SsimParts {
        ssim: ssim_sum / denom,
        cs: cs_sum / denom,
        grad,
    }
}

/// Index of `i` reflected into `0..n` (half-sample symmetric, periodic with period `2n`).
fn reflect(i: isize, n: usize) -> usize {
    let period = 2 * n as isize;
    let m = i.rem_euclid(period) as usize;
    if m < n {
        m
    } else {
        2 * n - 1 - m
    }
}

/// A separable Gaussian filter with reflect borders for `width x height` planes, and its
/// adjoint (transpose).
struct Filter<T> {
    width: usize,
    height: usize,
    weights: Vec<T>,
    /// `x_taps[x * taps + j]`: the source column of tap `j` for output column `x`.
    x_taps: Vec<usize>,
    /// `y_taps[y * taps + j]`: the source row of tap `j` for output row `y`.
    y_taps: Vec<usize>,
}

impl<T: Real> Filter<T> {
    fn new(window: &SsimWindow, width: usize, height: usize) -> Self {
        let r = window.radius as isize;
        let taps = |n: usize| -> Vec<usize> {
            (0..n as isize)
                .flat_map(|i| (-r..=r).map(move |t| reflect(i + t, n)))
                .collect()
        };
        Filter {
            width,
            height,
            weights: window.weights().into_iter().map(T::c).collect(),
            x_taps: taps(width),
            y_taps: taps(height),
        }
    }

    /// Filters a plane: along columns (y) first, then along rows (x), like
    /// `scipy.ndimage.gaussian_filter` on a 2-D array. `tmp` is scratch of the plane's size.
    fn apply(&self, src: &[T], tmp: &mut [T]) -> Vec<T> {
        let (w, h, k) = (self.width, self.height, self.weights.len());
        for y in 0..h {
            let row = &mut tmp[y * w..(y + 1) * w];
            row.fill(T::zero());
            for (j, &wj) in self.weights.iter().enumerate() {
                let sy = self.y_taps[y * k + j];
                let src_row = &src[sy * w..(sy + 1) * w];
                for (o, &s) in row.iter_mut().zip(src_row) {
                    *o = *o + wj * s;
                }
            }
        }
        let mut out = vec![T::zero(); w * h];
        for y in 0..h {
            let row = &tmp[y * w..(y + 1) * w];
            for x in 0..w {
                let taps = &self.x_taps[x * k..(x + 1) * k];
                let mut acc = T::zero();
                for (&wj, &sx) in self.weights.iter().zip(taps) {
                    acc = acc + wj * row[sx];
                }
                out[y * w + x] = acc;
            }
        }
        out
    }

    /// The transpose of [`Filter::apply`]: scatters `g` back through the x pass, then the
    /// y pass.
    fn adjoint(&self, g: &[T], tmp: &mut [T]) -> Vec<T> {
        let (w, h, k) = (self.width, self.height, self.weights.len());
        tmp.fill(T::zero());
        for y in 0..h {
            let row = &mut tmp[y * w..(y + 1) * w];
            for x in 0..w {
                let gx = g[y * w + x];
                if gx == T::zero() {
                    continue;
                }
                let taps = &self.x_taps[x * k..(x + 1) * k];
                for (&wj, &sx) in self.weights.iter().zip(taps) {
                    row[sx] = row[sx] + wj * gx;
                }
            }
        }
        let mut out = vec![T::zero(); w * h];
        for y in 0..h {
            let row = &tmp[y * w..(y + 1) * w];
            for (j, &wj) in self.weights.iter().enumerate() {
                let sy = self.y_taps[y * k + j];
                let dst = &mut out[sy * w..(sy + 1) * w];
                for (o, &v) in dst.iter_mut().zip(row) {
                    *o = *o + wj * v;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::testutil::{check_gradient, Rng};

    #[test]
    fn reflect_is_half_sample_symmetric() {
        let got: Vec<usize> = (-5..9).map(|i| reflect(i, 4)).collect();
        // i = -5..-1 | 0..3 | 4..8:  d d c b a | a b c d | d c b a a
        assert_eq!(got, vec![3, 3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0, 0]);
        // A 1-pixel plane reflects onto itself; small planes repeat periodically.
        assert!((-7..7).all(|i| reflect(i, 1) == 0));
    }

    #[test]
    fn windows() {
        let w = SsimWindow::skimage(1.5).unwrap();
        assert_eq!(w, SsimWindow::skimage_default());
        assert_eq!(w.size(), 11);
        assert_eq!(SsimWindow::skimage(11.0 / 6.0).unwrap().size(), 13);
        let k = SsimWindow::sized(21).unwrap();
        assert_eq!((k.radius(), k.sigma()), (10, 3.5));
        let weights = k.weights();
        assert!((weights.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert_eq!(weights[0], weights[20]);
        assert!(SsimWindow::sized(4).is_err());
        assert!(SsimWindow::sized(1).is_err());
        assert!(SsimWindow::new(3, 0.0).is_err());
        assert!(SsimWindow::new(3, f64::NAN).is_err());
        assert!(SsimWindow::skimage(-1.0).is_err());
    }

    #[test]
    fn filter_adjoint_satisfies_dot_product_identity() {
        let mut rng = Rng::new(9);
        // A plane smaller than the window exercises repeated reflection.
        for &(w, h, r) in &[(9usize, 7usize, 2usize), (4, 3, 5)] {
            let f = Filter::<f64>::new(&SsimWindow::new(r, 1.3).unwrap(), w, h);
            let a = rng.image(w, h, 1, -1.0, 1.0).data;
            let b = rng.image(w, h, 1, -1.0, 1.0).data;
            let mut tmp = vec![0.0; w * h];
            let fa = f.apply(&a, &mut tmp);
            let ftb = f.adjoint(&b, &mut tmp);
            let lhs: f64 = fa.iter().zip(&b).map(|(p, q)| p * q).sum();
            let rhs: f64 = a.iter().zip(&ftb).map(|(p, q)| p * q).sum();
            assert!((lhs - rhs).abs() < 1e-12, "{lhs} vs {rhs}");
            // Filtering a constant gives the constant (weights sum to 1 even when reflected).
            let ones = f.apply(&vec![1.0; w * h], &mut tmp);
            assert!(ones.iter().all(|v| (v - 1.0).abs() < 1e-14));
        }
    }

    #[test]
    fn identical_images_have_ssim_one() {
        let mut rng = Rng::new(1);
        let x = rng.image(12, 13, 3, 0.0, 1.0);
        let (v, g) = ssim_grad(&x, &x, &SsimWindow::sized(5).unwrap()).unwrap();
        assert!((v - 1.0).abs() < 1e-12);
        // SSIM is maximal at x = y, so the gradient vanishes there.
        assert!(g.data.iter().all(|v| v.abs() < 1e-12));
        assert!(
            hssim(
                &rng.image(31, 31, 1, 0.0, 1.0),
                &rng.image(31, 31, 1, 0.0, 1.0)
            )
            .unwrap()
                > 0.0
        );
    }

    #[test]
    fn ssim_gradient_matches_finite_differences() {
        let mut rng = Rng::new(21);
        let x = rng.image(14, 12, 2, 0.0, 1.0);
        let y = rng.image(14, 12, 2, 0.0, 1.0);
        for window in [SsimWindow::sized(3).unwrap(), SsimWindow::skimage_default()] {
            let (v, grad) = ssim_grad(&x, &y, &window).unwrap();
            assert_eq!(v, ssim(&x, &y, &window).unwrap());
            let f = |p: &Image<f64>| ssim(p, &y, &window).unwrap();
            check_gradient(&f, &x, &grad, 40, &mut rng);
        }
    }

    #[test]
    fn hssim_gradient_matches_finite_differences() {
        let mut rng = Rng::new(22);
        let y = rng.image(33, 32, 3, 0.0, 1.0);
        // A correlated pair, so every window's SSIM is far from 0 and from 1.
        let mut x = y.clone();
        for v in &mut x.data {
            *v = 0.7 * *v + 0.3 * rng.uniform();
        }
        let (v, grad) = hssim_grad(&x, &y).unwrap();
        assert_eq!(v, hssim(&x, &y).unwrap());
        assert!(v > 0.0 && v < 5.0);
        let f = |p: &Image<f64>| hssim(p, &y).unwrap();
        check_gradient(&f, &x, &grad, 25, &mut rng);
    }

    #[test]
    fn f32_agrees_with_f64() {
        let mut rng = Rng::new(4);
        let x = rng.image(32, 31, 3, 0.0, 1.0);
        let y = rng.image(32, 31, 3, 0.0, 1.0);
        let (v64, g64) = hssim_grad(&x, &y).unwrap();
        let (v32, g32) = hssim_grad(&x.cast::<f32>(), &y.cast::<f32>()).unwrap();
        assert!((v64 - v32 as f64).abs() < 1e-4, "{v64} vs {v32}");
        let gmax = g64.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(g32.cast::<f64>().max_abs_diff(&g64) < 1e-3 * gmax);
    }

    #[test]
    fn rejects_bad_inputs() {
        let w = SsimWindow::sized(11).unwrap();
        let a = Image::<f32>::new(10, 20, 1);
        assert!(ssim(&a, &a, &w).is_err());
        let b = Image::<f32>::new(20, 20, 1);
        let c = Image::<f32>::new(20, 20, 3);
        assert!(ssim(&b, &c, &w).is_err());
        assert!(ssim_grad(&b, &b, &w).is_ok());
        assert!(hssim(&b, &b).is_err());
        assert!(hssim_grad(&c, &c).is_err());
    }
}
