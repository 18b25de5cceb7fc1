//! The record of one depth-from-defocus run (`drbokeh dfd --log`, schema below): the
//! options, one entry per iteration, and the time spent per scale.
//!
//! ```text
//! {
//!   "schema_version": 1, "drbokeh_version": "...",
//!   "width", "height", "focus", "blur",
//!   "layer": "drbokeh" | "gausspsf" | "aperture", "preset": "physical" | "paper" | "custom",
//!   "gamma",
//!   "weights": { "l1", "smoothness", "hssim" }, "terms": "hssim" | "single_ssim",
//!   "edge_sensitivity",
//!   "schedule": { "scales", "finest_scale", "iterations", "fine_iterations", "learning_rate",
//!                 "learning_rate_decay", "patience", "min_improvement" },
//!   "parameterisation": "sigmoid" | "clamped", "optimiser": "shared_adam" | "adam",
//!   "highlights": "model" | "mask" | "ignore",
//!   "median": { "radius_blur_fraction", "sigma" } | null, "colour_vote": bins (absent: off),
//!   "init": { "constant": v } | { "sweep": n }, "sweep_context": fraction (absent: one pass),
//!   "initial_disparity_given": bool, "engine": "fast" | "threaded" | "reference",
//!   "clipped_aif_pixels", "clipped_target_pixels", "masked_fraction",
//!   "scales": [ { "scale", "width", "height", "blur", "iterations", "stopped_on_plateau",
//!                 "seconds", "seconds_per_iteration", "final_loss" } ],
//!   "entries": [ { "scale", "iteration", "loss", "l1", "smoothness", "structure" } ],
//!   "seconds": total
//! }
//! ```
//! Scale 0 is full resolution; scales are listed coarse first. `l1`, `smoothness` and
//! `structure` are unweighted and `null` where the term is off (or the scale too small).

use super::{
    DfdOptions, Highlights, Init, LossTerms, LossWeights, MedianRefine, Optimiser,
    Parameterisation, RenderLayer, Schedule,
};
use serde::{Deserialize, Serialize};

/// Version of the [`DfdLog`] schema.
pub const DFD_LOG_SCHEMA_VERSION: u32 = 1;

/// One iteration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LogEntry {
    /// Scale (0 = full resolution).
    pub scale: usize,
    /// Iteration within the scale.
    pub iteration: usize,
    /// Weighted total loss.
    pub loss: f64,
    /// Unweighted L1 (null if off).
    pub l1: Option<f64>,
    /// Unweighted smoothness (null if off or the scale is too small).
    pub smoothness: Option<f64>,
    /// Unweighted structural term (null if off or the scale is too small).
    pub structure: Option<f64>,
}

/// One scale of the run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScaleLog {
    /// Scale (0 = full resolution).
    pub scale: usize,
    /// Width of the pooled images.
    pub width: usize,
    /// Height of the pooled images.
    pub height: usize,
    /// K at this scale (the full K divided by `2^scale`).
    pub blur: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the scale stopped on a plateau (before its iteration limit).
    pub stopped_on_plateau: bool,
    /// Wall time of the scale.
    pub seconds: f64,
    /// Wall time per iteration.
    pub seconds_per_iteration: f64,
    /// Loss of the last iteration.
    pub final_loss: f64,
}

/// The options of a run, as recorded.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunOptions {
    /// Rendering layer.
    pub layer: RenderLayer,
    /// Preset of the Dr.Bokeh layer.
    pub preset: String,
    /// Gamma of the transfer.
    pub gamma: f64,
    /// Loss weights.
    pub weights: LossWeights,
    /// Structural term.
    pub terms: LossTerms,
    /// Edge sensitivity of the smoothness term.
    pub edge_sensitivity: f64,
    /// Schedule.
    pub schedule: Schedule,
    /// Parameterisation.
    pub parameterisation: Parameterisation,
    /// Optimiser.
    pub optimiser: Optimiser,
    /// Highlight handling.
    pub highlights: Highlights,
    /// Weighted-median refinement (null: off).
    pub median: Option<MedianRefine>,
    /// Bins per channel of the colour vote (absent: off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour_vote: Option<usize>,
    /// Initialisation.
    pub init: Init,
    /// Erosion of the sweep's second pass, as a fraction of the largest blur (absent: one
    /// pass).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep_context: Option<f64>,
    /// Whether a starting disparity map was given (it replaces `init`).
    pub initial_disparity_given: bool,
    /// Engine of the Dr.Bokeh layer.
    pub engine: String,
    /// The occlusion-aware objective (absent: one opaque layer).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layered: Option<super::LayeredObjective>,
}

impl RunOptions {
    /// The record of `options`.
    pub fn of(options: &DfdOptions) -> Self {
        RunOptions {
            layer: options.layer,
            preset: options.settings.preset.name().to_string(),
            gamma: options.settings.camera.gamma,
            weights: options.weights,
            terms: options.terms,
            edge_sensitivity: options.edge_sensitivity,
            schedule: options.schedule,
            parameterisation: options.parameterisation,
            optimiser: options.optimiser,
            highlights: options.highlights,
            median: options.median,
            colour_vote: options.colour_vote,
            init: options.init,
            sweep_context: options.sweep_context,
            initial_disparity_given: options.initial_disparity.is_some(),
            engine: format!("{:?}", options.engine).to_lowercase(),
            layered: options.layered,
        }
    }
}

/// Everything one run did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DfdLog {
    /// [`DFD_LOG_SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The library version that wrote it.
    pub drbokeh_version: String,
    /// Width of the pair.
    pub width: usize,
    /// Height of the pair.
    pub height: usize,
    /// Focus disparity.
    pub focus: f64,
    /// Blur strength K.
    pub blur: f64,
    /// The options (flattened into the log's top level).
    #[serde(flatten)]
    pub options: RunOptions,
    /// Pixel channels at or above white in the all-in-focus image.
    pub clipped_aif_pixels: usize,
    /// Pixels with a channel at or above white in the defocused image (left out of the loss).
    pub clipped_target_pixels: usize,
    /// Fraction of full-resolution pixels left out of the loss.
    pub masked_fraction: f64,
    /// Per scale, coarse first.
    pub scales: Vec<ScaleLog>,
    /// Per iteration.
    pub entries: Vec<LogEntry>,
    /// Total wall time.
    pub seconds: f64,
}
