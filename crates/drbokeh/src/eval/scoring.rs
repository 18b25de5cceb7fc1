//! Scores of a render against the ground truth ([`MethodResult`]) and of every method on a
//! scene ([`SceneResult`]).

use super::methods::Method;
use super::metrics;
use crate::image::Image;
use crate::Result;
use serde::Serialize;

/// One method's scores on one scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MethodResult {
    /// Method name.
    pub method: String,
    /// PSNR in dB (`null` in JSON when the images are identical).
    #[serde(serialize_with = "metrics::serialize_psnr")]
    pub psnr: f64,
    /// SSIM (scikit-image's definition).
    pub ssim: f64,
    /// MS-SSIM.
    pub ms_ssim: f64,
    /// Wall-clock render time, seconds (not deterministic).
    pub time_s: f64,
}

/// Every method's scores on one scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneResult {
    /// Scene name (its directory name).
    pub scene: String,
    /// Blur strength K.
    pub blur: f64,
    /// Focus disparity.
    pub focus: f64,
    /// Largest CoC radius in the scene, pixels.
    pub max_coc_px: f64,
    /// Blur-size bucket (see [`crate::eval::report::buckets`]).
    pub bucket: String,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// One entry per method, in the order evaluated.
    pub results: Vec<MethodResult>,
}

/// Scores a render against the ground truth; `time_s` is filled in by the caller.
pub fn score(method: Method, render: &Image<f32>, truth: &Image<f32>) -> Result<MethodResult> {
    Ok(MethodResult {
        method: method.name().to_string(),
        psnr: metrics::psnr(render, truth)?,
        ssim: metrics::ssim(render, truth)?,
        ms_ssim: metrics::ms_ssim(render, truth)?,
        time_s: 0.0,
    })
}
