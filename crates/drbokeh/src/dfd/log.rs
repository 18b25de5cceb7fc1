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
//!   "notes": [ { "kind": "small_blur", "scale", "width", "height", "blur_px",
//!                "full_blur_px", "finer_scale", "finer_blur_px", "finer_cost" }
//!            | { "kind": "focus_inside", "focus" } ],
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

/// Version of the [`DfdLog`] schema (2: `notes` added).
pub const DFD_LOG_SCHEMA_VERSION: u32 = 2;

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
    /// What about the inputs makes the estimate less reliable ([`DfdNote::for_run`]).
    #[serde(default)]
    pub notes: Vec<DfdNote>,
    /// Total wall time.
    pub seconds: f64,
}

/// The largest blur radius (px) at the scale optimised under which `dfd` notes that the
/// pair says little about depth (docs/dfd.md, "Small blurs").
pub const SMALL_BLUR_PX: f64 = 3.0;

/// Focus disparities within this distance of 0 or 1 count as focused on the farthest or
/// nearest object: no sign ambiguity is noted.
pub const FOCUS_END_MARGIN: f64 = 0.02;

/// Something about a run's inputs that makes its estimate less reliable, said to the user
/// (`drbokeh dfd` prints each on stderr) and kept in the log.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DfdNote {
    /// The largest blur at the scale optimised is under [`SMALL_BLUR_PX`].
    SmallBlur {
        /// The scale optimised (0 = full resolution).
        scale: usize,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
        /// The largest blur radius there, in pixels of that scale.
        blur_px: f64,
        /// The largest blur radius at full resolution.
        full_blur_px: f64,
        /// A finer scale whose largest blur reaches [`SMALL_BLUR_PX`] (or full resolution),
        /// if the scale optimised is not already full resolution.
        finer_scale: Option<usize>,
        /// The largest blur at `finer_scale`.
        finer_blur_px: Option<f64>,
        /// The cost of an iteration at `finer_scale` over one at `scale` (pixels x
        /// ([`Schedule::FINE_PIXEL_TAPS`] + area of the largest blur disc)).
        finer_cost: Option<f64>,
    },
    /// The focus is inside the disparity range, so the sign of `disparity - focus` is not
    /// determined by the blur.
    FocusInside {
        /// The focus disparity.
        focus: f64,
    },
}

impl DfdNote {
    /// The notes for a `width` x `height` pair with focus disparity `focus` and blur strength
    /// `blur_k` (px per unit disparity), optimised at scale `finest`.
    pub fn for_run(
        width: usize,
        height: usize,
        focus: f64,
        blur_k: f64,
        finest: usize,
    ) -> Vec<Self> {
        let mut notes = Vec::new();
        let full_blur_px = blur_k * focus.max(1.0 - focus);
        let at = |s: usize| full_blur_px / (1u64 << s) as f64;
        let cost = |s: usize| Schedule::iteration_cost_per_pixel(s, full_blur_px);
        let blur_px = at(finest);
        if blur_px < SMALL_BLUR_PX {
            let finer = (finest > 0).then(|| {
                (0..finest)
                    .rev()
                    .find(|&s| at(s) >= SMALL_BLUR_PX)
                    .unwrap_or(0)
            });
            notes.push(DfdNote::SmallBlur {
                scale: finest,
                width: width >> finest,
                height: height >> finest,
                blur_px,
                full_blur_px,
                finer_scale: finer,
                finer_blur_px: finer.map(at),
                finer_cost: finer.map(|s| cost(s) / cost(finest)),
            });
        }
        if focus > FOCUS_END_MARGIN && focus < 1.0 - FOCUS_END_MARGIN {
            notes.push(DfdNote::FocusInside { focus });
        }
        notes
    }
}

impl std::fmt::Display for DfdNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DfdNote::SmallBlur {
                scale,
                width,
                height,
                blur_px,
                full_blur_px,
                finer_scale,
                finer_blur_px,
                finer_cost,
            } => {
                if *scale == 0 {
                    write!(
                        f,
                        "the largest blur is {blur_px:.1} px: under {SMALL_BLUR_PX} px the pair \
                         says little about depth, and the estimate may be no better than a \
                         constant (docs/dfd.md, \"Small blurs\")"
                    )
                } else {
                    write!(
                        f,
                        "optimised at {width}x{height} (scale {scale}), where the largest blur is \
                         {blur_px:.1} px ({full_blur_px:.1} px at full size); under \
                         {SMALL_BLUR_PX} px the pair says little about depth"
                    )?;
                    if let (Some(s), Some(b), Some(c)) = (finer_scale, finer_blur_px, finer_cost) {
                        write!(
                            f,
                            ": --finest-scale {s} optimises where it is {b:.1} px, at about \
                             {c:.0}x the time per iteration"
                        )?;
                    }
                    write!(f, " (docs/dfd.md, \"Small blurs\")")
                }
            }
            DfdNote::FocusInside { focus } => write!(
                f,
                "focus {focus} is inside the disparity range: a pixel as far in front of it as \
                 another is behind blurs the same, so the estimate may put it on the wrong side \
                 (focus on the nearest object, 1, or the farthest, 0, if you can)"
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_blur_at_the_scale_optimised_is_noted_with_a_finer_scale() {
        // 1024 px, K 8 at focus 1: optimised at scale 2 (256 px) the blur is 2 px.
        let notes = DfdNote::for_run(1024, 1024, 1.0, 8.0, 2);
        assert_eq!(notes.len(), 1);
        match &notes[0] {
            DfdNote::SmallBlur {
                scale,
                width,
                blur_px,
                finer_scale,
                finer_blur_px,
                finer_cost,
                ..
            } => {
                assert_eq!((*scale, *width), (2, 256));
                assert!((blur_px - 2.0).abs() < 1e-12);
                // Scale 1 (512 px) has a blur of 4 px: the coarsest finer scale that reaches 3.
                assert_eq!(*finer_scale, Some(1));
                assert!((finer_blur_px.unwrap() - 4.0).abs() < 1e-12);
                // 4x the pixels, each with the disc of radius 4 + 1 instead of 2 + 1.
                let pi = std::f64::consts::PI;
                let per_pixel = |r: f64| Schedule::FINE_PIXEL_TAPS + pi * r * r;
                let expected = 4.0 * per_pixel(5.0) / per_pixel(3.0);
                assert!((finer_cost.unwrap() - expected).abs() < 1e-9);
            }
            other => panic!("expected a small-blur note, got {other:?}"),
        }
        let text = notes[0].to_string();
        assert!(
            text.contains("256x256") && text.contains("--finest-scale 1"),
            "{text}"
        );
    }

    #[test]
    fn enough_blur_and_an_end_focus_give_no_note() {
        assert!(DfdNote::for_run(256, 256, 1.0, 9.0, 1).is_empty());
        assert!(DfdNote::for_run(256, 256, 0.0, 20.0, 2).is_empty());
        // Full resolution with a small blur: noted, with no finer scale to suggest.
        let notes = DfdNote::for_run(64, 64, 0.0, 2.0, 0);
        assert!(matches!(
            notes.as_slice(),
            [DfdNote::SmallBlur {
                finer_scale: None,
                ..
            }]
        ));
    }

    #[test]
    fn a_focus_inside_the_range_is_noted() {
        let notes = DfdNote::for_run(256, 256, 0.4, 20.0, 1);
        assert_eq!(notes, vec![DfdNote::FocusInside { focus: 0.4 }]);
        assert!(notes[0].to_string().contains("wrong side"));
        assert!(DfdNote::for_run(256, 256, 0.99, 20.0, 1).is_empty());
    }

    #[test]
    fn notes_survive_the_json_log() {
        let notes = DfdNote::for_run(1024, 1024, 0.5, 8.0, 2);
        let json = serde_json::to_string(&notes).unwrap();
        assert!(json.contains("\"kind\":\"small_blur\"") && json.contains("focus_inside"));
        let back: Vec<DfdNote> = serde_json::from_str(&json).unwrap();
        assert_eq!(back, notes);
    }
}
