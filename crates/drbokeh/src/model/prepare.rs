//! Per-pixel terms of a layer, computed once before the gather (docs/model.md,
//! "Per-pixel terms"): linear colour, relative disparity, scatter radius, focus weight.

use super::occlusion::focus_weight;
use super::options::ModelOptions;
use super::scatter::{relative_disparity, scatter_radius_px};
use super::tone::{source_linear_with_derivatives, HighlightBoost, Tone};
use crate::camera::Camera;
use crate::stack::Layer;
use crate::Real;
use rayon::prelude::*;

/// The camera and model options in float type `T`, for evaluating per-pixel terms.
/// Equations M1, M2, M10, M18-M20 of docs/model.md.
#[derive(Clone, Copy, Debug)]
pub struct PixelModel<T> {
    /// Blur strength `K`.
    pub blur_k: T,
    /// Focus disparity `f`.
    pub focus_disparity: T,
    /// Pixel footprint of the scatter radius.
    pub footprint_px: T,
    /// Highlight boost, if on.
    pub highlight: Option<HighlightBoost>,
    /// Display transfer.
    pub tone: Tone,
}

impl<T: Real> PixelModel<T> {
    /// The per-pixel model of a camera under `options`.
    /// Section "Per-pixel terms" of docs/model.md.
    pub fn new(camera: &Camera, options: &ModelOptions) -> Self {
        PixelModel {
            blur_k: T::c(camera.blur_k),
            focus_disparity: T::c(camera.focus_disparity),
            footprint_px: T::c(options.footprint.px()),
            highlight: camera.highlight,
            tone: Tone::new(options.transfer, camera.gamma, camera.offset),
        }
    }

    /// Relative disparity `d = disp - f`.
    /// Equation M1 of docs/model.md.
    #[inline(always)]
    pub fn rel_disp(&self, disparity: T) -> T {
        relative_disparity(disparity, self.focus_disparity)
    }

    /// Scatter radius `r = K |d| + footprint`.
    /// Equation M2 of docs/model.md.
    #[inline(always)]
    pub fn radius_px(&self, rel_disp: T) -> T {
        scatter_radius_px(self.blur_k, rel_disp, self.footprint_px)
    }

    /// Focus weight `e = exp(-3 (K d)^2)`.
    /// Equation M10 of docs/model.md.
    #[inline(always)]
    pub fn focus_weight(&self, rel_disp: T) -> T {
        focus_weight(self.blur_k, rel_disp)
    }

    /// Linear colour of a display-encoded channel value (with the highlight boost) and its
    /// derivatives `(lin, dlin/dI, dlin/dd)` ([`source_linear_with_derivatives`]).
    /// Equation M20 of docs/model.md.
    #[inline(always)]
    pub fn linear_with_derivatives(&self, encoded: T, rel_disp: T) -> (T, T, T) {
        source_linear_with_derivatives(encoded, rel_disp, self.highlight.as_ref(), &self.tone)
    }

    /// Linear colour of a display-encoded channel value.
    /// Equations M18-M20 of docs/model.md.
    #[inline(always)]
    pub fn linear(&self, encoded: T, rel_disp: T) -> T {
        self.linear_with_derivatives(encoded, rel_disp).0
    }
}

/// Per-pixel terms of one layer, computed once before the gather: linear colour (after
/// the optional highlight boost), alpha, relative disparity `d`, radius `r`, focus weight `e`.
/// Equations M1, M2, M10, M18-M20 of docs/model.md.
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

/// Computes the per-pixel terms of a layer for a camera under model `options`.
/// Equations M1, M2, M10, M18-M20 of docs/model.md.
pub fn prepare_layer<T: Real>(
    layer: &Layer<T>,
    camera: &Camera,
    options: &ModelOptions,
) -> PreparedLayer<T> {
    let pixel = PixelModel::<T>::new(camera, options);
    // Per pixel and independent: in parallel, each value as computed alone.
    let rel_disp: Vec<T> = layer
        .disparity
        .data
        .par_iter()
        .map(|&v| pixel.rel_disp(v))
        .collect();
    let mut rgb_linear = vec![T::zero(); layer.rgb_encoded.data.len()];
    rgb_linear
        .par_chunks_mut(3)
        .zip(layer.rgb_encoded.data.par_chunks_exact(3))
        .zip(rel_disp.par_iter())
        .for_each(|((out, px), &d)| {
            for (o, &encoded) in out.iter_mut().zip(px) {
                *o = pixel.linear(encoded, d);
            }
        });
    PreparedLayer {
        width: layer.alpha.width,
        height: layer.alpha.height,
        rgb_linear,
        alpha: layer.alpha.data.clone(),
        radius_px: rel_disp.par_iter().map(|&d| pixel.radius_px(d)).collect(),
        focus_weight: rel_disp
            .par_iter()
            .map(|&d| pixel.focus_weight(d))
            .collect(),
        rel_disp,
    }
}
