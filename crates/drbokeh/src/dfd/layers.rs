//! The rendering layers depth from defocus can optimise through, behind one interface:
//! render an all-in-focus image with a per-pixel disparity map, and return the gradient of
//! `sum(G * render)` with respect to that disparity (and, on request, the colour).
//!
//! - [`RenderLayer::DrBokeh`]: our renderer on a single opaque layer, with the settings'
//!   preset (`physical` or `paper`): the one-layer [`super::layered::LayeredModel`], which
//!   renders through the public [`crate::render_with_tape_on`] and [`crate::Tape::backward`].
//! - [`RenderLayer::GaussPsf`]: the Gaussian-PSF layer, [`crate::baselines::gauss_psf`].
//! - [`RenderLayer::Aperture`]: aperture compositing, [`crate::baselines::aperture_compositing`].

use super::layered::LayeredModel;
use crate::baselines::{aperture_compositing, gauss_psf, LayerVjp};
use crate::image::Image;
use crate::presets::RenderSettings;
use crate::{Engine, Error, Real, Result};

/// Which rendering layer to optimise through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RenderLayer {
    /// Dr.Bokeh (the settings' preset), single opaque layer.
    DrBokeh,
    /// Gaussian PSF, normalised gather.
    GaussPsf,
    /// Aperture compositing (shift-and-add).
    Aperture,
}

impl RenderLayer {
    /// All layers, for experiments.
    pub const ALL: [RenderLayer; 3] = [
        RenderLayer::DrBokeh,
        RenderLayer::GaussPsf,
        RenderLayer::Aperture,
    ];

    /// CLI name.
    pub fn name(self) -> &'static str {
        match self {
            RenderLayer::DrBokeh => "drbokeh",
            RenderLayer::GaussPsf => "gausspsf",
            RenderLayer::Aperture => "aperture",
        }
    }
}

impl std::str::FromStr for RenderLayer {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        RenderLayer::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| {
                Error::param(
                    "layer",
                    format!("unknown layer '{s}' (drbokeh, gausspsf, aperture)"),
                )
            })
    }
}

/// Renders `aif` (display-encoded RGB) with `disparity` through `layer` (the Dr.Bokeh layer
/// on the threaded engine).
pub fn render_layer<T: Real>(
    layer: RenderLayer,
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
) -> Result<Image<T>> {
    render_layer_on(layer, Engine::Threaded, aif, disparity, settings)
}

/// [`render_layer`] with the Dr.Bokeh layer on `engine`.
pub fn render_layer_on<T: Real>(
    layer: RenderLayer,
    engine: Engine,
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
) -> Result<Image<T>> {
    match layer {
        RenderLayer::DrBokeh => {
            LayeredModel::single(aif, disparity)?.render(engine, aif, disparity, settings)
        }
        RenderLayer::GaussPsf => gauss_psf::render(aif, disparity, settings),
        RenderLayer::Aperture => aperture_compositing::render(aif, disparity, settings),
    }
}

/// Renders and back-propagates: returns the render and the gradient of `sum(G * render)`
/// with respect to the disparity, where `upstream(render)` returns `G`. The Dr.Bokeh layer
/// runs on the threaded engine (the exact gradient); see [`render_layer_vjp_on`].
pub fn render_layer_vjp<T: Real>(
    layer: RenderLayer,
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
    upstream: impl FnOnce(&Image<T>) -> Result<Image<T>>,
) -> Result<(Image<T>, Image<T>)> {
    let v = render_layer_vjp_on(
        layer,
        Engine::Threaded,
        aif,
        disparity,
        settings,
        false,
        upstream,
    )?;
    Ok((v.render, v.d_disparity))
}

/// [`render_layer_vjp`] with the Dr.Bokeh layer's forward and adjoint on `engine`
/// ([`crate::render_with_tape_on`]; the other layers ignore it), and the colour gradient
/// when `colour_gradient` is set.
pub fn render_layer_vjp_on<T: Real>(
    layer: RenderLayer,
    engine: Engine,
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
    colour_gradient: bool,
    upstream: impl FnOnce(&Image<T>) -> Result<Image<T>>,
) -> Result<LayerVjp<T>> {
    match layer {
        RenderLayer::DrBokeh => LayeredModel::single(aif, disparity)?.vjp(
            engine,
            aif,
            disparity,
            settings,
            colour_gradient,
            upstream,
        ),
        RenderLayer::GaussPsf => {
            gauss_psf::render_vjp(aif, disparity, settings, colour_gradient, upstream)
        }
        RenderLayer::Aperture => {
            aperture_compositing::render_vjp(aif, disparity, settings, colour_gradient, upstream)
        }
    }
}
