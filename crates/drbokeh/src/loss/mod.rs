//! Image losses for depth from defocus, each with its exact gradient beside it.
//!
//! The depth-from-defocus objective (docs/model.md, "Depth from defocus") is
//! `L = w1 |render - target|_1 + wg G + wh HSSIM`. Every term here comes as a pair:
//! a forward function returning the loss value, and a `*_grad` function returning the value
//! together with its gradient (the vector-Jacobian product for an upstream gradient of 1)
//! with respect to the optimised image, as an [`Image`](crate::Image) of the same shape.
//!
//! - [`l1`](mod@l1): mean absolute difference ([`l1::l1`], [`l1::l1_grad`]).
//! - [`smoothness`]: edge-aware disparity smoothness over a 4-level pyramid.
//! - [`ssim`](mod@ssim): Gaussian-window SSIM for any window, and the multi-window HSSIM.
//! - [`pyramid`]: 2x2 average pooling and its adjoint, shared by the above and by
//!   [`crate::eval::metrics`].
//!
//! All functions are generic over [`Real`](crate::Real) (`f32`, `f64`); sums are
//! accumulated in `f64`. Inputs with mismatched shapes, or too small for a window or
//! pyramid, are reported as [`Error`](crate::Error), never a panic.

mod check;
pub mod l1;
pub mod pyramid;
pub mod smoothness;
pub mod ssim;
#[cfg(test)]
pub(crate) mod testutil;

pub(crate) use check::check_same_shape;
pub use l1::{l1, l1_grad};
pub use smoothness::{edge_aware_smoothness, edge_aware_smoothness_grad, SMOOTHNESS_LEVELS};
pub use ssim::{hssim, hssim_grad, ssim, ssim_grad, SsimWindow, HSSIM_WINDOWS};
