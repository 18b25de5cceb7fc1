//! Evaluation: image-quality metrics for comparing renders with references.
//!
//! [`metrics`] holds PSNR, SSIM (matching scikit-image), MS-SSIM and per-pixel error maps,
//! all computed on display-encoded images with data range 1.

pub mod gallery;
pub mod metrics;
pub mod report;
