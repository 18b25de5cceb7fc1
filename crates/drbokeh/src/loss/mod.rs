//! Image losses for depth from defocus, each with its exact gradient beside it.
//!
//! The depth-from-defocus objective (spec, "Depth from defocus") is
//! `L = w1 |render - target|_1 + wg G + wh HSSIM`. Every term here comes as a pair:
//! a forward function returning the loss value, and a `*_grad` function returning the value
//! together with its gradient (the vector-Jacobian product for an upstream gradient of 1)
//! with respect to the optimised image, as an [`Image`] of the same shape.
//!
//! - [`l1`](mod@l1): mean absolute difference ([`l1::l1`], [`l1::l1_grad`]).
//! - [`smoothness`]: edge-aware disparity smoothness over a 4-level pyramid.
//! - [`ssim`](mod@ssim): Gaussian-window SSIM for any window, and the multi-window HSSIM.
//! - [`pyramid`]: 2x2 average pooling and its adjoint, shared by the above and by
//!   [`crate::eval::metrics`].
//!
//! All functions are generic over [`Real`](crate::Real) (`f32`, `f64`); sums are
//! accumulated in `f64`. Inputs with mismatched shapes, or too small for a window or
//! pyramid, are reported as [`Error`], never a panic.

pub mod l1;
pub mod pyramid;
pub mod smoothness;
pub mod ssim;

pub use l1::{l1, l1_grad};
pub use smoothness::{edge_aware_smoothness, edge_aware_smoothness_grad, SMOOTHNESS_LEVELS};
pub use ssim::{hssim, hssim_grad, ssim, ssim_grad, SsimWindow, HSSIM_WINDOWS};

use crate::image::check_dimensions;
use crate::{Error, Image, Result};

/// Checks that `img` is a well-formed, non-empty image; `what` names it in messages.
pub(crate) fn check_image<T>(what: &str, img: &Image<T>) -> Result<()> {
    check_dimensions(what, img.width, img.height)?;
    if img.channels == 0 {
        return Err(Error::input(what, "image has zero channels"));
    }
    let expected = img
        .width
        .checked_mul(img.height)
        .and_then(|p| p.checked_mul(img.channels));
    if expected != Some(img.data.len()) {
        return Err(Error::input(
            what,
            format!(
                "buffer has {} values, expected {}x{}x{}",
                img.data.len(),
                img.width,
                img.height,
                img.channels
            ),
        ));
    }
    Ok(())
}

/// Checks that both images are well formed and have the same width, height and channels.
pub(crate) fn check_same_shape<T>(
    a_name: &str,
    a: &Image<T>,
    b_name: &str,
    b: &Image<T>,
) -> Result<()> {
    check_image(a_name, a)?;
    check_image(b_name, b)?;
    if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
        return Err(Error::input(
            format!("{a_name} / {b_name}"),
            format!(
                "shapes differ: {}x{}x{} vs {}x{}x{}",
                a.width, a.height, a.channels, b.width, b.height, b.channels
            ),
        ));
    }
    Ok(())
}

/// Test helpers shared by the loss modules: a deterministic generator and gradient checks.
#[cfg(test)]
pub(crate) mod testutil {
    use crate::Image;

    /// A small deterministic generator (SplitMix64) for reproducible random test points.
    pub struct Rng(u64);

    impl Rng {
        pub fn new(seed: u64) -> Self {
            Rng(seed)
        }

        /// A uniform value in `[0, 1)`.
        pub fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 53) as f64
        }

        /// An image with values uniform in `[lo, hi)`.
        pub fn image(&mut self, w: usize, h: usize, c: usize, lo: f64, hi: f64) -> Image<f64> {
            let data = (0..w * h * c)
                .map(|_| lo + (hi - lo) * self.uniform())
                .collect();
            Image::from_vec(w, h, c, data).unwrap()
        }
    }

    /// Compares an analytic gradient with central finite differences of `f` at `x`:
    /// on `samples` random components and along one random direction. Fails if a relative
    /// error exceeds `1e-4`.
    pub fn check_gradient(
        f: &dyn Fn(&Image<f64>) -> f64,
        x: &Image<f64>,
        grad: &Image<f64>,
        samples: usize,
        rng: &mut Rng,
    ) {
        const H: f64 = 1e-6;
        const TOL: f64 = 1e-4;
        assert_eq!(grad.data.len(), x.data.len());
        let n = x.data.len();
        let gmax = grad.data.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        assert!(gmax > 0.0, "gradient is identically zero");
        for _ in 0..samples {
            let i = ((rng.uniform() * n as f64) as usize).min(n - 1);
            let mut p = x.clone();
            p.data[i] += H;
            let mut m = x.clone();
            m.data[i] -= H;
            let fd = (f(&p) - f(&m)) / (2.0 * H);
            let an = grad.data[i];
            // Relative to the component itself; components far below the gradient's scale
            // are compared relative to 1e-3 of the largest component instead.
            let scale = an.abs().max(1e-3 * gmax);
            assert!(
                (fd - an).abs() <= TOL * scale,
                "component {i}: finite difference {fd:e}, analytic {an:e}"
            );
        }
        // Directional derivative along a random direction.
        let dir: Vec<f64> = (0..n).map(|_| rng.uniform() * 2.0 - 1.0).collect();
        let mut p = x.clone();
        let mut m = x.clone();
        for i in 0..n {
            p.data[i] += H * dir[i];
            m.data[i] -= H * dir[i];
        }
        let fd = (f(&p) - f(&m)) / (2.0 * H);
        let an: f64 = grad.data.iter().zip(&dir).map(|(g, d)| g * d).sum();
        assert!(
            (fd - an).abs() <= TOL * an.abs(),
            "directional derivative: finite difference {fd:e}, analytic {an:e}"
        );
    }
}
