//! Presets: named bundles of model choices, and the settings a render needs.

use crate::aperture::Aperture;
use crate::camera::Camera;
use crate::{Error, Result};

/// A named bundle of model choices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Preset {
    /// The published Dr.Bokeh model, exactly as `shared/spec/rendering-model.md` states it:
    /// box coverage of half-size `floor(r/2)`, gamma transfer.
    #[default]
    Paper,
}

impl Preset {
    /// All presets, for `--help` and error messages.
    pub const ALL: &'static [(&'static str, &'static str)] =
        &[("paper", "the published Dr.Bokeh model, exactly")];

    /// The preset's CLI name.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Paper => "paper",
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "paper" => Ok(Preset::Paper),
            _ => Err(Error::param(
                "--preset",
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
    /// Model preset.
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

    /// Validates camera and aperture.
    pub fn validate(&self) -> Result<()> {
        self.camera.validate()?;
        self.aperture.validate()
    }
}
