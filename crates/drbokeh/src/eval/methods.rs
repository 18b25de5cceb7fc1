//! The methods evaluated on a benchmark ([`Method`]) and how each renders: a renderer (a
//! classical baseline or a drbokeh preset) fed either the all-in-focus image + disparity or
//! the ground-truth layer stack.

use crate::baselines::Baseline;
use crate::camera::Camera;
use crate::image::Image;
use crate::presets::{Preset, RenderSettings};
use crate::scene::{self, Focus, Layering, Photo, Source, View};
use crate::stack::LayerStack;
use crate::{Engine, Error, NoProgress, Result};
use serde::Serialize;

/// A method evaluated on the benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Naive gather ([`crate::baselines::naive_gather`]) on image + disparity.
    Gather,
    /// Naive scatter ([`crate::baselines::naive_scatter`]) on image + disparity.
    Scatter,
    /// Layered disc blur ([`crate::baselines::layered_disc`]) on image + disparity.
    Layered,
    /// Layered disc blur on the ground-truth layer stack.
    LayeredGt,
    /// GaussPSF ([`crate::baselines::gauss_psf`]) on image + disparity.
    GaussPsf,
    /// The `paper` preset on a single opaque layer (image + disparity).
    PaperAif,
    /// The `paper` preset on the ground-truth layer stack.
    PaperGt,
    /// The `physical` preset on one opaque layer (the all-in-focus image).
    PhysicalAif,
    /// The `physical` preset on the ground-truth layer stack.
    PhysicalGt,
    /// The photo pipeline as `drbokeh render --image --disparity` runs it with the `paper`
    /// preset: highlights at their default ([`crate::highlight::PhotoHighlights`]),
    /// decomposition into layers, render.
    PhotoPaper,
    /// The photo pipeline with the `physical` preset (the CLI's default render of a photo).
    PhotoPhysical,
}

/// What a method is fed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum MethodInput {
    /// The all-in-focus image and its disparity map.
    #[serde(rename = "aif+disparity")]
    AifDisparity,
    /// The ground-truth layer stack.
    #[serde(rename = "layers")]
    Layers,
}

impl MethodInput {
    /// The name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            MethodInput::AifDisparity => "aif+disparity",
            MethodInput::Layers => "layers",
        }
    }
}

impl Method {
    /// All methods, in report order.
    pub const ALL: [Method; 11] = [
        Method::PhotoPhysical,
        Method::PhotoPaper,
        Method::Gather,
        Method::Scatter,
        Method::GaussPsf,
        Method::Layered,
        Method::PaperAif,
        Method::PhysicalAif,
        Method::LayeredGt,
        Method::PaperGt,
        Method::PhysicalGt,
    ];

    /// The method's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Gather => "gather",
            Method::Scatter => "scatter",
            Method::Layered => "layered",
            Method::LayeredGt => "layered-gt",
            Method::GaussPsf => "gausspsf",
            Method::PaperAif => "paper-aif",
            Method::PaperGt => "paper-gt",
            Method::PhysicalAif => "physical-aif",
            Method::PhysicalGt => "physical-gt",
            Method::PhotoPaper => "photo-paper",
            Method::PhotoPhysical => "photo-physical",
        }
    }

    /// What the method is fed.
    pub fn input(self) -> MethodInput {
        match self {
            Method::LayeredGt | Method::PaperGt | Method::PhysicalGt => MethodInput::Layers,
            _ => MethodInput::AifDisparity,
        }
    }

    /// One line on what the method models and ignores.
    pub fn description(self) -> &'static str {
        match self {
            Method::Gather => "naive gather: each pixel averages the disc of its own blur radius (ignores occlusion; colour bleeding)",
            Method::Scatter => "naive scatter: each pixel splats its disc, no depth test (blurred background spreads over sharp foreground)",
            Method::GaussPsf => "GaussPSF (Gur & Wolf 2019): normalised Gaussian scatter, sigma ~ radius/2 (no occlusion, no disc shape)",
            Method::Layered => "layered disc blur: 32 disparity planes blurred by their disc, composited back to front (holes where the image hides background)",
            Method::PaperAif => "Dr.Bokeh paper preset on one opaque layer (image + disparity)",
            Method::LayeredGt => "layered disc blur on the ground-truth layers (hidden background available)",
            Method::PaperGt => "Dr.Bokeh paper preset on the ground-truth layers",
            Method::PhysicalAif => "drbokeh physical preset on one opaque layer (image + disparity)",
            Method::PhysicalGt => "drbokeh physical preset on the ground-truth layers",
            Method::PhotoPaper => "the photo pipeline as the CLI runs it (default highlight treatment, decomposition into layers) with the paper preset",
            Method::PhotoPhysical => "the photo pipeline as the CLI runs it (default highlight treatment, decomposition into layers) with the physical preset: what a user gets from `drbokeh render --image --disparity`",
        }
    }

    /// Parses a comma-separated list of method names; `all` means [`Method::ALL`].
    pub fn parse_list(list: &str) -> Result<Vec<Method>> {
        let mut out = Vec::new();
        for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            if name == "all" {
                for m in Method::ALL {
                    if !out.contains(&m) {
                        out.push(m);
                    }
                }
                continue;
            }
            let m: Method = name.parse()?;
            if !out.contains(&m) {
                out.push(m);
            }
        }
        if out.is_empty() {
            return Err(Error::param("methods", "no method given"));
        }
        Ok(out)
    }
}

impl std::str::FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                Error::param(
                    "methods",
                    format!(
                        "unknown method '{s}' (available: {}, or all)",
                        Method::ALL.map(|m| m.name()).join(", ")
                    ),
                )
            })
    }
}

/// What renders a method's input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Renderer {
    /// A classical baseline ([`Baseline::render`]).
    Baseline(Baseline),
    /// A drbokeh preset on the fast engine ([`render_preset`]).
    Preset(Preset),
    /// The photo pipeline ([`crate::scene::resolve`] of a photo, then the fast engine)
    /// with a preset ([`render_photo_pipeline`]).
    PhotoPipeline(Preset),
}

impl Method {
    /// The renderer of this method.
    pub fn renderer(self) -> Renderer {
        match self {
            Method::Gather => Renderer::Baseline(Baseline::NaiveGather),
            Method::Scatter => Renderer::Baseline(Baseline::NaiveScatter),
            Method::GaussPsf => Renderer::Baseline(Baseline::GaussPsf),
            Method::Layered | Method::LayeredGt => Renderer::Baseline(Baseline::LayeredDisc),
            Method::PaperAif | Method::PaperGt => Renderer::Preset(Preset::Paper),
            Method::PhysicalAif | Method::PhysicalGt => Renderer::Preset(Preset::Physical),
            Method::PhotoPaper => Renderer::PhotoPipeline(Preset::Paper),
            Method::PhotoPhysical => Renderer::PhotoPipeline(Preset::Physical),
        }
    }

    /// Renders this method's input: the display-encoded result, clipped to [0, 1]. A
    /// method fed the image + disparity ([`MethodInput::AifDisparity`]) sees `stack` as that
    /// pair (pass the image as a single opaque layer, [`render_photo`]).
    pub fn render(self, stack: &LayerStack<f32>, camera: &Camera) -> Result<Image<f32>> {
        let mut out = match self.renderer() {
            Renderer::Baseline(b) => b.render(stack, camera)?,
            Renderer::Preset(p) => render_preset(p, stack, camera)?,
            Renderer::PhotoPipeline(p) => {
                let [layer] = stack.layers.as_slice() else {
                    return Err(Error::param(
                        "methods",
                        format!(
                            "method '{}' needs an image + disparity (one layer), got {} layers",
                            self.name(),
                            stack.layers.len()
                        ),
                    ));
                };
                let photo = Photo {
                    rgb_encoded: layer.rgb_encoded.clone(),
                    disparity: layer.disparity.clone(),
                    matte: None,
                    layering: Layering::default(),
                };
                render_photo_pipeline(p, Source::Photo(photo), camera, photo_view_defaults())?
            }
        };
        out.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
        Ok(out)
    }
}

/// Fails unless `method` is fed an image + disparity pair (naming the parameter
/// `methods`).
pub fn require_photo_input(method: Method) -> Result<()> {
    if method.input() != MethodInput::AifDisparity {
        return Err(Error::param(
            "methods",
            format!(
                "method '{}' needs a ground-truth layer stack; the gallery has image + disparity only",
                method.name()
            ),
        ));
    }
    Ok(())
}

/// Renders a method fed an image + disparity pair (display-encoded, clipped); fails for a
/// method that needs a ground-truth layer stack (naming the parameter `methods`).
pub fn render_photo(
    method: Method,
    image: &Image<f32>,
    disparity: &Image<f32>,
    camera: &Camera,
) -> Result<Image<f32>> {
    require_photo_input(method)?;
    method.render(
        &LayerStack::single(image.clone(), disparity.clone())?,
        camera,
    )
}

/// The view options of the photo rows that the camera does not carry: the CLI's defaults
/// (highlights at their default, [`crate::highlight::PhotoHighlights::default`]).
pub fn photo_view_defaults() -> View {
    View::default()
}

/// Renders a photo `source` as the CLI does with `base`'s options (highlights, aperture) and the camera's focus, K, gamma and offset, the automatic window and the
/// fast engine: [`crate::scene::resolve`], then [`crate::render`]. Display-encoded, not
/// clipped.
pub fn render_photo_pipeline(
    preset: Preset,
    source: Source<f32>,
    camera: &Camera,
    base: View,
) -> Result<Image<f32>> {
    let view = View {
        focus: Focus::Disparity(camera.focus_disparity),
        blur_k: camera.blur_k,
        window: None,
        gamma: camera.gamma,
        offset: camera.offset,
        preset,
        ..base
    };
    let scene = scene::resolve::<f32>(source, &view, Engine::Fast)?;
    crate::render(&scene.stack, &scene.settings, Engine::Fast, &NoProgress)
}

/// The `paper` preset with `camera`, fast engine.
pub fn render_paper(stack: &LayerStack<f32>, camera: &Camera) -> Result<Image<f32>> {
    render_preset(Preset::Paper, stack, camera)
}

/// Renders a stack with a preset, the camera given and a circular aperture (fast engine).
pub fn render_preset(
    preset: Preset,
    stack: &LayerStack<f32>,
    camera: &Camera,
) -> Result<Image<f32>> {
    let mut settings = RenderSettings::paper(camera.focus_disparity);
    settings.camera = camera.clone();
    settings.preset = preset;
    crate::render(stack, &settings, Engine::Fast, &NoProgress)
}
