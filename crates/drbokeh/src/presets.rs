//! Presets: named bundles of model choices, and the settings a render needs.
//!
//! A preset fixes the [`ModelOptions`]: which form of each replaceable model term is used.
//! `paper` is the published model; `physical` keeps the paper's equation and replaces the
//! terms that a ray-traced benchmark shows to be furthest from a real lens (docs/model.md,
//! "Preset physical", and `docs/physical.md`). For ablations, [`Preset::Custom`] takes any
//! combination of options, one changed at a time.

use crate::aperture::Aperture;
use crate::camera::Camera;
use crate::model::Tone;
use crate::{Error, Result};

pub use crate::model::{Coverage, CoverageRadius, Footprint, ModelOptions, ScatterStep, Transfer};

/// A named bundle of model choices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Preset {
    /// The published Dr.Bokeh model, exactly as docs/model.md states it: box coverage of
    /// half-size `floor(r/2)`, gamma transfer.
    #[default]
    Paper,
    /// The paper's equation with the terms measured to be closer to a real lens: coverage
    /// averaged over the receiver's soft aperture disc of radius `K |d(x)|` (its circle of
    /// confusion), a sharp soft step centred on the circle of confusion (`r = K |d|`, no
    /// pixel footprint) with area normalisation `pi r^2 + 1/2`; the paper's gamma transfer
    /// (the exact sRGB curve did not win on the benchmark: `docs/physical.md`). The CLI's
    /// default.
    Physical,
    /// Any combination of options (for ablations); not selectable by name.
    Custom(ModelOptions),
}

impl Preset {
    /// All named presets, for `--help` and error messages.
    pub const ALL: &'static [(&'static str, &'static str)] = &[
        ("paper", "the published Dr.Bokeh model, exactly"),
        (
            "physical",
            "the paper's equation with disc coverage and a sharp step centred on the circle of confusion (default)",
        ),
    ];

    /// The preset's CLI name (`custom` for [`Preset::Custom`]).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Paper => "paper",
            Preset::Physical => "physical",
            Preset::Custom(_) => "custom",
        }
    }

    /// The model options this preset stands for.
    pub fn options(self) -> ModelOptions {
        match self {
            Preset::Paper => ModelOptions::PAPER,
            Preset::Physical => ModelOptions::PHYSICAL,
            Preset::Custom(o) => o,
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "paper" => Ok(Preset::Paper),
            "physical" => Ok(Preset::Physical),
            _ => Err(Error::param(
                "preset",
                format!(
                    "unknown preset '{s}' (available: {})",
                    Preset::ALL
                        .iter()
                        .map(|(n, _)| *n)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
        }
    }
}

/// Everything a render needs besides the layer stack.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Camera controls.
    pub camera: Camera,
    /// Aperture shape.
    pub aperture: Aperture,
    /// Model preset (its [`Preset::options`] select the model's terms).
    pub preset: Preset,
}

impl RenderSettings {
    /// Paper defaults with a circular aperture, focused at `focus_disparity`.
    pub fn paper(focus_disparity: f64) -> Self {
        RenderSettings {
            camera: Camera::paper_default(focus_disparity),
            aperture: Aperture::Circle,
            preset: Preset::Paper,
        }
    }

    /// Like [`RenderSettings::paper`] with the `physical` preset.
    pub fn physical(focus_disparity: f64) -> Self {
        RenderSettings {
            preset: Preset::Physical,
            ..RenderSettings::paper(focus_disparity)
        }
    }

    /// The model options in effect.
    pub fn model(&self) -> ModelOptions {
        self.preset.options()
    }

    /// These settings with the model options replaced (as [`Preset::Custom`] unless they
    /// equal a named preset's).
    pub fn with_model(mut self, options: ModelOptions) -> Self {
        self.preset = if options == ModelOptions::PAPER {
            Preset::Paper
        } else if options == ModelOptions::PHYSICAL {
            Preset::Physical
        } else {
            Preset::Custom(options)
        };
        self
    }

    /// The display transfer of these settings.
    pub fn tone(&self) -> Tone {
        Tone::new(self.model().transfer, self.camera.gamma, self.camera.offset)
    }

    /// Validates camera and aperture.
    pub fn validate(&self) -> Result<()> {
        self.camera.validate()?;
        let m = self.model();
        if m.footprint == Footprint::Point && m.step == ScatterStep::Paper {
            return Err(Error::input(
                "model options",
                "footprint `point` needs the sharp scatter step (the paper's area r^2 is 0 in focus)",
            ));
        }
        self.aperture.validate()
    }
}
