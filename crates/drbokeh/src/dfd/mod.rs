//! Depth from defocus (supplement sec. 3.2): recover a disparity map from an all-in-focus
//! image and a defocused image of the same view (known K and focus) by optimising through
//! a rendering layer, minimising `L = w1 |render - target|_1 + wg G + wh HSSIM`.
//!
//! How ([`estimate_disparity`], `docs/dfd.md` for the measurements behind each choice):
//! - **Coarse to fine.** Both images are pooled `2^s` times in linear light and K is divided
//!   by `2^s`; an iteration at scale `s` costs about `16^-s` of a full-resolution one (a
//!   quarter of the pixels, a quarter of the disc area), so the coarse scales do most of
//!   the work and the finest scale refines. Each scale stops on a plateau of its loss.
//! - **Adam** on the disparity, parameterised as a sigmoid of an unbounded variable (or
//!   clamped to [0, 1]).
//! - **Clipped highlights.** A pixel clipped in the all-in-focus image may have been much
//!   brighter; its true brightness shows in the defocused image as a bright ball. With
//!   [`Highlights::Model`] the linear brightness of every clipped pixel is a second unknown,
//!   optimised jointly with the disparity (the render's colour gradient); with
//!   [`Highlights::Mask`] the pixels such a highlight could reach are left out of the
//!   loss. Pixels clipped in the defocused image are always left out (the sensor clipped
//!   them), and the render is clipped to [0, 1] as the sensor would.
//! - **Confidence.** [`DfdResult`] has two maps: a confidence (low within the blur radius
//!   of the estimate's steps, where the single-layer objective fattens near objects;
//!   [`confidence`]) and the render's sensitivity to disparity (low where the pair carries
//!   no depth information: flat or in-focus regions).
//!
//! The log ([`log::DfdLog`]) records every option, every iteration's loss terms and the
//! time spent per scale.

pub mod benchmark;
pub mod confidence;
pub mod experiment;
mod highlights;
pub mod layered;
pub mod layers;
pub mod log;
mod maps;
mod objective;
mod optimise;
pub mod report;
mod sweep;

pub use layers::{
    render_layer, render_layer_on, render_layer_vjp, render_layer_vjp_on, RenderLayer,
};
pub use log::{DfdLog, DfdNote, LogEntry, RunOptions, ScaleLog, SMALL_BLUR_PX};
pub use optimise::estimate_disparity;

use crate::image::Image;
use crate::presets::RenderSettings;
use crate::{Engine, Error, Real, Result};
use serde::{Deserialize, Serialize};

/// Weight of the edge-aware smoothness in [`LossWeights::DEFAULT`].
pub const DEFAULT_SMOOTHNESS_WEIGHT: f64 = 20.0;

/// Default [`LayeredObjective::every`].
pub const DEFAULT_REDECOMPOSE_EVERY: usize = 10;

/// Weights of the three loss terms; 0 turns a term off.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    /// Weight of the mean absolute error between render and target.
    pub l1: f64,
    /// Weight of the edge-aware smoothness of the disparity.
    pub smoothness: f64,
    /// Weight of HSSIM (sum over windows 3..31 of 1 - SSIM).
    pub hssim: f64,
}

impl LossWeights {
    /// The published training configuration: L1 0.5, smoothness 0.5, HSSIM 10.
    pub const PAPER: LossWeights = LossWeights {
        l1: 0.5,
        smoothness: 0.5,
        hssim: 10.0,
    };

    /// The defaults: the paper's L1 and HSSIM weights with a stronger smoothness
    /// ([`DEFAULT_SMOOTHNESS_WEIGHT`]; one disparity map is optimised, not a network, and
    /// the paper's 0.5 leaves flat regions to noise: `docs/dfd.md`).
    pub const DEFAULT: LossWeights = LossWeights {
        l1: 0.5,
        smoothness: DEFAULT_SMOOTHNESS_WEIGHT,
        hssim: 10.0,
    };

    /// Keeps the default weights for the named terms (`l1`, `smooth`, `ssim`, `hssim`; see
    /// [`LossTerms`]) and zeroes the others. A term may carry its own weight, `TERM=W`
    /// (finite, >= 0), e.g. `l1,smooth=2,hssim` (docs/dfd.md: five layers with smoothness
    /// 2 was the best held-out setting of session 34).
    pub fn from_terms(terms: &str) -> Result<(Self, LossTerms)> {
        let mut w = LossWeights {
            l1: 0.0,
            smoothness: 0.0,
            hssim: 0.0,
        };
        let mut single_ssim = false;
        for t in terms.split(',').map(str::trim) {
            let (name, weight) = match t.split_once('=') {
                Some((name, v)) => {
                    let (name, v) = (name.trim(), v.trim());
                    let weight = v.parse::<f64>().ok().filter(|v| v.is_finite() && *v >= 0.0);
                    let weight = weight.ok_or_else(|| {
                        Error::param(
                            "losses",
                            format!(
                                "the weight of '{name}' must be a finite number >= 0, got '{v}'"
                            ),
                        )
                    })?;
                    (name, Some(weight))
                }
                None => (t, None),
            };
            match name {
                "l1" => w.l1 = weight.unwrap_or(Self::DEFAULT.l1),
                "smooth" | "smoothness" | "g" => {
                    w.smoothness = weight.unwrap_or(Self::DEFAULT.smoothness)
                }
                "hssim" => w.hssim = weight.unwrap_or(Self::DEFAULT.hssim),
                "ssim" => {
                    // A single 11-window SSIM with the same total weight as HSSIM's five.
                    w.hssim = weight.unwrap_or(Self::DEFAULT.hssim);
                    single_ssim = true;
                }
                _ => {
                    return Err(Error::param(
                        "losses",
                        format!("unknown loss term '{name}' (use l1, smooth, ssim, hssim, each optionally TERM=WEIGHT)"),
                    ))
                }
            }
        }
        if w.l1 == 0.0 && w.smoothness == 0.0 && w.hssim == 0.0 {
            return Err(Error::param("losses", "no loss term selected"));
        }
        Ok((
            w,
            if single_ssim {
                LossTerms::SingleSsim
            } else {
                LossTerms::Hssim
            },
        ))
    }
}

/// Which structural term the `hssim` weight applies to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LossTerms {
    /// HSSIM over windows 3, 5, 11, 21, 31.
    Hssim,
    /// One SSIM with an 11-window, scaled by 5 (as many terms as HSSIM has).
    SingleSsim,
}

/// How the optimiser keeps the disparity in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Parameterisation {
    /// Adam on the disparity itself, clamped to [0, 1] after each step.
    Clamped,
    /// Adam on an unbounded `u`, disparity `= 1 / (1 + exp(-u))`.
    Sigmoid,
}

impl std::str::FromStr for Parameterisation {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "clamped" => Ok(Parameterisation::Clamped),
            "sigmoid" => Ok(Parameterisation::Sigmoid),
            _ => Err(Error::param(
                "param",
                format!("unknown parameterisation '{s}' (sigmoid, clamped)"),
            )),
        }
    }
}

/// The optimiser of the disparity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Optimiser {
    /// Adam: momentum and second moment per pixel, so every pixel steps about the learning
    /// rate, however little its gradient says.
    Adam,
    /// Adam with one second moment for the whole map (the mean squared gradient): a pixel's
    /// step is proportional to its gradient, so pixels the data says little about move
    /// little and the smoothness term fills them in. Steps are capped at 3 learning rates.
    SharedAdam,
}

impl std::str::FromStr for Optimiser {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "adam" => Ok(Optimiser::Adam),
            "shared-adam" => Ok(Optimiser::SharedAdam),
            _ => Err(Error::param(
                "optimiser",
                format!("unknown optimiser '{s}' (shared-adam, adam)"),
            )),
        }
    }
}

/// The edge-aware weighted median that refines the optimised disparity
/// (`maps::weighted_median`): classical disparity refinement, which moves depth edges onto
/// colour edges and removes isolated errors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MedianRefine {
    /// Window radius as a fraction of the largest blur radius `K max|d|` (at least 1 px).
    pub radius_blur_fraction: f64,
    /// Colour distance (encoded, RMS over channels) of weight `exp(-1/2)`.
    pub sigma: f64,
}

/// What to do about pixels clipped (at or above white) in the all-in-focus image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Highlights {
    /// Render them as they are (at most white).
    Ignore,
    /// Leave out of the loss every pixel within the largest possible blur radius of one.
    Mask,
    /// Optimise their linear brightness (at least white) together with the disparity.
    Model,
}

impl std::str::FromStr for Highlights {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "ignore" => Ok(Highlights::Ignore),
            "mask" => Ok(Highlights::Mask),
            "model" => Ok(Highlights::Model),
            _ => Err(Error::param(
                "highlights",
                format!("unknown highlight handling '{s}' (model, mask, ignore)"),
            )),
        }
    }
}

/// The occlusion-aware objective of the Dr.Bokeh layer (`layered.rs`): the all-in-focus
/// image is rendered as the layer stack that the photo pipeline makes of it at the current
/// disparity estimate (depth layers, each filled in behind the nearer ones), re-made every
/// [`LayeredObjective::every`] iterations; the GaussPSF and aperture layers ignore it
/// (single-layer models by design).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayeredObjective {
    /// Most layers of the decomposition (1 to 16).
    pub max_layers: usize,
    /// Iterations between re-decompositions (at least 1).
    pub every: usize,
}

/// The default erosion of the sweep's second pass, as a fraction of the largest blur
/// radius ([`DfdOptions::sweep_context`]). Chosen on the tuning seeds among 0.25, 0.5, 0.75
/// and 1 (MAE 0.0736, 0.0732, 0.0742, 0.0753 against 0.0767 with one pass); held out
/// 0.104 -> 0.0995 (`docs/dfd.md`).
pub const DEFAULT_SWEEP_CONTEXT: f64 = 0.5;

/// The largest accepted [`DfdOptions::sweep_context`].
pub const MAX_SWEEP_CONTEXT: f64 = 4.0;

/// How the disparity starts.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Init {
    /// The same disparity everywhere.
    Constant(f64),
    /// At the coarsest scale, the best of `n` constant disparities per pixel (the render
    /// at each constant disparity compared with the target over a small neighbourhood):
    /// a plane sweep.
    Sweep(usize),
}

/// Scales, iterations, steps and stopping rule.
///
/// Scale `s` is the pair pooled `2^s` times (in linear light) with K divided by `2^s`.
/// The optimiser runs at the finest scale [`Schedule::finest_scale`] and, before it, at
/// [`Schedule::coarse_scales`] coarser ones; the result is upsampled (bilinear) to full
/// resolution.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Schedule {
    /// The finest scale optimised (0 = full resolution). `None` chooses the finest scale
    /// whose iteration costs at most [`Schedule::AUTO_FINEST_TAPS`] (pixels times the disc
    /// area of the largest blur), keeping at least [`Schedule::MIN_SIDE`] pixels a side;
    /// where the largest blur there is under [`SMALL_BLUR_PX`], a finer one while it is
    /// and an iteration costs at most [`Schedule::AUTO_FINER_TAPS`].
    pub finest_scale: Option<usize>,
    /// Coarser scales optimised before the finest one (each initialises the next).
    pub coarse_scales: usize,
    /// Most Adam iterations at each coarse scale.
    pub iterations: usize,
    /// Most Adam iterations at the finest scale optimised (lowered by
    /// [`Schedule::fine_cost_per_pixel`]: [`Schedule::fine_iterations_for`]).
    pub fine_iterations: usize,
    /// Cost budget of the finest scale's iterations per pixel of the pair, in disc taps:
    /// where `fine_iterations` iterations would cost more, fewer run (at least
    /// [`Schedule::MIN_FINE_ITERATIONS`]). `None`: `fine_iterations` as given. The default
    /// ([`Schedule::AUTO_FINE_COST_PER_PIXEL`]) keeps 256 px pairs optimised at full
    /// resolution (blurs under about 4 px) within the time target.
    #[serde(default)]
    pub fine_cost_per_pixel: Option<f64>,
    /// Adam learning rate (parameter units per step, roughly) at the coarsest scale.
    pub learning_rate: f64,
    /// Factor on the learning rate at each finer scale.
    pub learning_rate_decay: f64,
    /// Stop a scale when its loss has not improved by [`Schedule::min_improvement`] (relative)
    /// over this many iterations; 0 never stops early.
    pub patience: usize,
    /// Relative improvement that counts for [`Schedule::patience`].
    pub min_improvement: f64,
}

impl Schedule {
    /// Smallest side of any optimised scale.
    pub const MIN_SIDE: usize = 32;

    /// Cost budget of one iteration at the finest scale when [`Schedule::finest_scale`] is
    /// `None`: pixels times the disc area `pi (K max|d| + 1)^2` of the largest blur.
    pub const AUTO_FINEST_TAPS: f64 = 5.0e6;

    /// Cost budget of one iteration (pixels times [`Schedule::FINE_PIXEL_TAPS`] plus the disc
    /// area) at a scale finer than [`Schedule::AUTO_FINEST_TAPS`] allows, taken when the
    /// largest blur there is under [`SMALL_BLUR_PX`]. A 256 px pair with a 4.9 px blur at
    /// full resolution costs 2.4e7 (measured better there, docs/dfd.md "Small blurs"); a
    /// 1024 px pair with a 4 px blur at 512 px costs 8.6e7 (measured no better, at 5x the
    /// time) and stays at its coarser scale.
    pub const AUTO_FINER_TAPS: f64 = 3.0e7;

    /// The cost of one iteration per pixel of a scale, in disc taps, besides the disc itself:
    /// measured on 256 px benchmark pairs at full resolution (seeds 101, 102: 18-24 s for 40
    /// iterations at blurs of 2-3.6 px, about 0.45 s per iteration of which the disc is a
    /// small part), rounded.
    pub const FINE_PIXEL_TAPS: f64 = 250.0;

    /// Default of [`Schedule::fine_cost_per_pixel`]: about 25 iterations for a pair optimised
    /// at full resolution with a small blur, no cap at the coarser scales.
    pub const AUTO_FINE_COST_PER_PIXEL: f64 = 7500.0;

    /// The fewest iterations [`Schedule::fine_cost_per_pixel`] leaves at the finest scale.
    pub const MIN_FINE_ITERATIONS: usize = 10;

    /// The cost of one iteration at scale `scale` per full-resolution pixel of a pair with
    /// largest blur radius `max_blur_px` (at full resolution), in disc taps:
    /// `(FINE_PIXEL_TAPS + pi (b_s + 1)^2) / 4^s`, `b_s` the largest blur at that scale.
    pub fn iteration_cost_per_pixel(scale: usize, max_blur_px: f64) -> f64 {
        let f = (1u64 << scale.min(62)) as f64;
        let r = max_blur_px / f + 1.0;
        (Self::FINE_PIXEL_TAPS + std::f64::consts::PI * r * r) / (f * f)
    }

    /// Most iterations at the finest scale `finest` for a `width x height` pair with largest
    /// blur radius `max_blur_px` (at full resolution): [`Schedule::fine_iterations`], fewer
    /// where they would cost more than [`Schedule::fine_cost_per_pixel`] per pixel of the
    /// pair, an iteration at scale `s` costing `(FINE_PIXEL_TAPS + pi (b_s + 1)^2) / 4^s`
    /// per full-resolution pixel (`b_s` the largest blur there).
    pub fn fine_iterations_for(&self, finest: usize, max_blur_px: f64) -> usize {
        let Some(budget) = self.fine_cost_per_pixel else {
            return self.fine_iterations;
        };
        let cap = (budget / Self::iteration_cost_per_pixel(finest, max_blur_px)).floor();
        let cap = if cap.is_finite() && cap >= 0.0 {
            (cap.min(usize::MAX as f64) as usize).max(Self::MIN_FINE_ITERATIONS)
        } else {
            Self::MIN_FINE_ITERATIONS
        };
        self.fine_iterations.min(cap)
    }

    /// The finest scale to optimise for a `width x height` pair with largest blur radius
    /// `max_blur_px` (at full resolution).
    pub fn finest_for(&self, width: usize, height: usize, max_blur_px: f64) -> usize {
        let mut deepest = 0;
        while (width.min(height) >> (deepest + 1)) >= Self::MIN_SIDE && deepest < 8 {
            deepest += 1;
        }
        if let Some(s) = self.finest_scale {
            return s.min(deepest);
        }
        let pixels = |s: usize| {
            let f = (1u64 << s) as f64;
            (width as f64 / f) * (height as f64 / f)
        };
        let disc = |s: usize| {
            let r = max_blur_px / (1u64 << s) as f64 + 1.0;
            std::f64::consts::PI * r * r
        };
        let mut s = 0;
        while s < deepest && pixels(s) * disc(s) > Self::AUTO_FINEST_TAPS {
            s += 1;
        }
        // A blur under SMALL_BLUR_PX says little about depth: go finer while it is, as long
        // as an iteration there stays within AUTO_FINER_TAPS (docs/dfd.md, "Small blurs").
        let blur_px = |s: usize| max_blur_px / (1u64 << s) as f64;
        while s > 0
            && blur_px(s) < SMALL_BLUR_PX
            && pixels(0) * Self::iteration_cost_per_pixel(s - 1, max_blur_px)
                <= Self::AUTO_FINER_TAPS
        {
            s -= 1;
        }
        s
    }

    /// The number of pyramid levels (full resolution included) for `finest`: the finest
    /// scale plus the coarse ones, as long as a side keeps [`Schedule::MIN_SIDE`] pixels.
    pub fn levels_for(&self, width: usize, height: usize, finest: usize) -> usize {
        let mut n = finest + 1;
        while n < finest + 1 + self.coarse_scales && (width.min(height) >> n) >= Self::MIN_SIDE {
            n += 1;
        }
        n
    }
}

/// Options of one depth-from-defocus run.
#[derive(Clone, Debug)]
pub struct DfdOptions {
    /// Camera of the defocused image (focus, K, gamma) and preset; the window is chosen per
    /// scale.
    pub settings: RenderSettings,
    /// Rendering layer to optimise through.
    pub layer: RenderLayer,
    /// Loss weights.
    pub weights: LossWeights,
    /// Structural term.
    pub terms: LossTerms,
    /// Edge sensitivity `s` of the smoothness term: its edge weight is `exp(-s |dI|)` (the
    /// paper's G has `s = 1`); larger lets disparity edges form at colour edges.
    pub edge_sensitivity: f64,
    /// Iterations and steps.
    pub schedule: Schedule,
    /// How the disparity is kept in range.
    pub parameterisation: Parameterisation,
    /// The optimiser.
    pub optimiser: Optimiser,
    /// Clipped highlights of the all-in-focus image.
    pub highlights: Highlights,
    /// Weighted-median refinement of the result (`None`: off).
    pub median: Option<MedianRefine>,
    /// Non-local colour vote on the full-resolution result, with this many bins per
    /// channel (`None`: off, the default): pixels of one colour take their median disparity
    /// (`docs/dfd.md`). Off by default: it assumes each surface has its own palette, which
    /// holds on the benchmark's billboards (16 bins: held-out MAE 0.104 -> 0.076) but not
    /// where one texture spans several depths (synthetic check 0.059 -> 0.094).
    pub colour_vote: Option<usize>,
    /// Initial disparity.
    pub init: Init,
    /// A second pass of the plane sweep ([`Init::Sweep`]; `None`: one pass). The first
    /// pass's estimate, eroded (a minimum filter) by this fraction of the largest blur
    /// radius, is kept in front of every candidate plane, and a pixel takes only its eroded
    /// estimate or the candidates behind it (refined between them). So a pixel beside a
    /// nearer object is judged with that object rendered in front of it, not with the
    /// object spread over it at the candidate's depth: the first pass labels such pixels
    /// with the nearer depth (the foreground fattened by about a blur radius). Default
    /// [`DEFAULT_SWEEP_CONTEXT`] (`docs/dfd.md`).
    pub sweep_context: Option<f64>,
    /// A starting disparity map (the pair's size, one channel) instead of [`DfdOptions::init`];
    /// pooled to the coarsest scale.
    pub initial_disparity: Option<Image<f32>>,
    /// Engine of the Dr.Bokeh layer's forward and adjoint ([`crate::render_with_tape_on`]).
    pub engine: Engine,
    /// Render the Dr.Bokeh layer's objective through a layer decomposition (`None`: one
    /// opaque layer).
    pub layered: Option<LayeredObjective>,
}

impl DfdOptions {
    /// The defaults, measured on ray-traced tuning scenes (`docs/dfd.md`): L1 0.5, edge-aware
    /// smoothness [`DEFAULT_SMOOTHNESS_WEIGHT`], HSSIM 10; a plane sweep of 9 disparities
    /// as the start; one scale, the finest within the cost budget; at most 40 iterations,
    /// stopping after 10 without a 0.1 % improvement; Adam at learning rate 0.1 on the
    /// sigmoid's variable; highlights modelled (energy start, then optimised); the fast
    /// engine.
    pub fn new(settings: RenderSettings, layer: RenderLayer) -> Self {
        DfdOptions {
            settings,
            layer,
            weights: LossWeights::DEFAULT,
            terms: LossTerms::Hssim,
            edge_sensitivity: 10.0,
            schedule: Schedule {
                finest_scale: None,
                coarse_scales: 0,
                iterations: 100,
                fine_iterations: 40,
                fine_cost_per_pixel: Some(Schedule::AUTO_FINE_COST_PER_PIXEL),
                learning_rate: 0.1,
                learning_rate_decay: 0.7,
                patience: 10,
                min_improvement: 1e-3,
            },
            parameterisation: Parameterisation::Sigmoid,
            optimiser: Optimiser::Adam,
            highlights: Highlights::Model,
            median: Some(MedianRefine {
                radius_blur_fraction: 1.5,
                sigma: 0.05,
            }),
            colour_vote: None,
            init: Init::Sweep(9),
            sweep_context: Some(DEFAULT_SWEEP_CONTEXT),
            initial_disparity: None,
            engine: Engine::Fast,
            layered: None,
        }
    }

    /// Checks every option's range; messages name the CLI options.
    pub fn validate(&self) -> Result<()> {
        self.settings.validate()?;
        let s = &self.schedule;
        if s.coarse_scales > 8 {
            return Err(Error::param("coarse_scales", "must be between 0 and 8"));
        }
        if s.finest_scale.is_some_and(|f| f > 8) {
            return Err(Error::param("finest_scale", "must be between 0 and 8"));
        }
        if s.iterations == 0 || s.iterations > 100_000 {
            return Err(Error::param("iterations", "must be between 1 and 100000"));
        }
        if s.fine_iterations == 0 || s.fine_iterations > 100_000 {
            return Err(Error::param(
                "fine_iterations",
                "must be between 1 and 100000",
            ));
        }
        if !(s.learning_rate > 0.0 && s.learning_rate.is_finite() && s.learning_rate <= 100.0) {
            return Err(Error::param("lr", "learning rate must be in (0, 100]"));
        }
        if !(s.learning_rate_decay > 0.0 && s.learning_rate_decay <= 1.0) {
            return Err(Error::param("lr_decay", "must be in (0, 1]"));
        }
        if !(s.min_improvement >= 0.0 && s.min_improvement < 1.0) {
            return Err(Error::param("min_improvement", "must be in [0, 1)"));
        }
        if !(self.edge_sensitivity >= 0.0 && self.edge_sensitivity <= 1000.0) {
            return Err(Error::param("edge_sensitivity", "must be in [0, 1000]"));
        }
        if let Some(m) = self.median {
            if !(m.radius_blur_fraction > 0.0 && m.radius_blur_fraction <= 10.0) {
                return Err(Error::param("median_radius", "must be in (0, 10]"));
            }
            if !(m.sigma > 0.0 && m.sigma <= 10.0) {
                return Err(Error::param("median_sigma", "must be in (0, 10]"));
            }
        }
        if self
            .sweep_context
            .is_some_and(|f| !(f > 0.0 && f <= MAX_SWEEP_CONTEXT))
        {
            return Err(Error::param(
                "sweep_context",
                format!("must be in (0, {MAX_SWEEP_CONTEXT}] (0 on the command line: one pass)"),
            ));
        }
        if self.colour_vote.is_some_and(|b| !(1..=256).contains(&b)) {
            return Err(Error::param("colour_bins", "must be between 0 and 256"));
        }
        for (name, w) in [
            ("l1", self.weights.l1),
            ("smoothness", self.weights.smoothness),
            ("hssim", self.weights.hssim),
        ] {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(Error::param(
                    "losses",
                    format!("weight of {name} must be finite and >= 0, got {w}"),
                ));
            }
        }
        if let Some(l) = self.layered {
            if !(1..=crate::layering::MAX_LAYERS_LIMIT).contains(&l.max_layers) {
                return Err(Error::param("occlusion_layers", "must be between 1 and 16"));
            }
            if l.every == 0 || l.every > 100_000 {
                return Err(Error::param("redecompose", "must be between 1 and 100000"));
            }
        }
        match self.init {
            Init::Constant(v) if !(0.0..=1.0).contains(&v) => Err(Error::param(
                "init",
                format!("initial disparity must be in [0, 1], got {v}"),
            )),
            Init::Sweep(n) if !(2..=sweep::MAX_PLANES).contains(&n) => Err(Error::param(
                "init",
                format!(
                    "a sweep needs 2 to {} disparities, got {n}",
                    sweep::MAX_PLANES
                ),
            )),
            _ => Ok(()),
        }
    }
}

/// What [`estimate_disparity`] returns.
#[derive(Clone, Debug)]
pub struct DfdResult<T> {
    /// Estimated disparity (HxWx1, in [0, 1]).
    pub disparity: Image<T>,
    /// Confidence in [0, 1] (HxWx1): how far to trust each pixel of the estimate, the
    /// occlusion band of [`confidence::occlusion_band`] with [`confidence::OcclusionBand::DEFAULT`].
    /// Near 0 within the blur radius of a step in the estimate (at the edges of near objects
    /// and across structures thinner than their blur), where the single-layer objective
    /// fattens near objects over what lies behind them; 1 elsewhere. On the benchmark the
    /// most confident half of the pixels has about a third of the whole map's error
    /// (`docs/dfd.md`, "Confidence").
    pub confidence: Image<T>,
    /// Sensitivity in [0, 1] (HxWx1): how much the render changes with the disparity around
    /// each pixel, `s / (s + s0)` with `s` the mean absolute change of the encoded render per
    /// unit disparity over a 5x5 neighbourhood and `s0` = [`CONFIDENCE_HALF_SENSITIVITY`].
    /// Near 0 where the pair carries no depth information (flat or in-focus regions: there
    /// the estimate comes from the smoothness and the median, not from the pair). It is
    /// *high* at edges, where the estimate is least reliable, so it is not a confidence.
    pub sensitivity: Image<T>,
    /// Everything the run did.
    pub log: DfdLog,
}

/// The sensitivity (encoded intensity per unit disparity) at which [`DfdResult::sensitivity`]
/// is 1/2.
pub const CONFIDENCE_HALF_SENSITIVITY: f64 = 0.05;

/// Disparity error statistics against ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DisparityErrors {
    /// Mean absolute error (normalised disparity).
    pub mae: f64,
    /// Root mean squared error (normalised disparity).
    pub rmse: f64,
    /// Fraction of pixels with `max(est/gt, gt/est) < 1.25`, the ratio taken of depths when
    /// a [`DepthRange`] is known (a normalised disparity of 0 is a finite depth), else of
    /// the disparities.
    pub within_1_25: f64,
}

/// The metric range behind a normalised disparity: `disp = (1/z - 1/z_far) / (1/z_near -
/// 1/z_far)`, so `z = 1 / (1/z_far + disp (1/z_near - 1/z_far))`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthRange {
    /// Nearest depth (any unit, > 0).
    pub near: f64,
    /// Farthest depth (same unit, > near).
    pub far: f64,
}

impl DepthRange {
    /// Depth of a normalised disparity (clamped to [0, 1]).
    pub fn depth(&self, disparity: f64) -> f64 {
        let d = disparity.clamp(0.0, 1.0);
        1.0 / (1.0 / self.far + d * (1.0 / self.near - 1.0 / self.far))
    }
}

/// Compares an estimate with ground truth (same size, one channel); the ratio of
/// disparities for `within_1_25`.
pub fn disparity_errors<T: Real>(estimate: &Image<T>, truth: &Image<T>) -> DisparityErrors {
    masked_disparity_errors(estimate, truth, None, |_| true).unwrap_or(DisparityErrors {
        mae: f64::NAN,
        rmse: f64::NAN,
        within_1_25: f64::NAN,
    })
}

/// [`disparity_errors`] over the pixels `i` where `keep(i)`, with `within_1_25` on depths
/// when `depth` is given; `None` if no pixel is kept.
pub fn masked_disparity_errors<T: Real>(
    estimate: &Image<T>,
    truth: &Image<T>,
    depth: Option<DepthRange>,
    keep: impl Fn(usize) -> bool,
) -> Option<DisparityErrors> {
    let (mut n, mut abs, mut sq, mut ok) = (0.0, 0.0, 0.0, 0.0);
    for (i, (&e, &t)) in estimate.data.iter().zip(&truth.data).enumerate() {
        if !keep(i) {
            continue;
        }
        let (e, t) = (e.f64(), t.f64());
        n += 1.0;
        abs += (e - t).abs();
        sq += (e - t) * (e - t);
        let (a, b) = match depth {
            Some(r) => (r.depth(e), r.depth(t)),
            None => (e, t),
        };
        let ratio = if a > 0.0 && b > 0.0 {
            (a / b).max(b / a)
        } else if a == b {
            1.0
        } else {
            f64::INFINITY
        };
        if ratio < 1.25 {
            ok += 1.0;
        }
    }
    (n > 0.0).then(|| DisparityErrors {
        mae: abs / n,
        rmse: (sq / n).sqrt(),
        within_1_25: ok / n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn costly_finest_scales_get_fewer_iterations() {
        let s = DfdOptions::new(RenderSettings::physical(1.0), RenderLayer::DrBokeh).schedule;
        // 256 px at full resolution with a 2 px blur: (250 + 9 pi) per pixel, 26 iterations.
        assert_eq!(s.fine_iterations_for(0, 2.0), 26);
        // The benchmark's usual case, 128 px (scale 1) with a 4.5 px blur there: no cap.
        assert_eq!(s.fine_iterations_for(1, 9.0), 40);
        // A huge blur at full resolution: never under the floor.
        assert_eq!(
            s.fine_iterations_for(0, 500.0),
            Schedule::MIN_FINE_ITERATIONS
        );
        // No budget: as given; a smaller count than the cap is kept.
        let free = Schedule {
            fine_cost_per_pixel: None,
            ..s
        };
        assert_eq!(free.fine_iterations_for(0, 2.0), 40);
        let few = Schedule {
            fine_iterations: 3,
            ..s
        };
        assert_eq!(few.fine_iterations_for(0, 2.0), 3);
    }

    #[test]
    fn small_blurs_are_optimised_finer_within_the_budget() {
        let s = DfdOptions::new(RenderSettings::physical(1.0), RenderLayer::DrBokeh).schedule;
        // The disc budget alone: 256 px with K 9 -> 128 px (blur 4.5 there, enough).
        assert_eq!(s.finest_for(256, 256, 9.0), 1);
        // A 4.9 px blur -> 128 px by the disc budget, where it is 2.45 px: full resolution.
        assert_eq!(s.finest_for(256, 256, 4.9), 0);
        // 512 px with K 10: 128 px by the disc budget (blur 2.5 px), then 256 px (5 px).
        assert_eq!(s.finest_for(512, 512, 10.0), 1);
        // 1024 px with K 8: 256 px (blur 2 px); 512 px would cost 8.6e7, over the budget.
        assert_eq!(s.finest_for(1024, 1024, 8.0), 2);
        // A large blur is left at its coarse scale.
        assert_eq!(s.finest_for(256, 256, 20.0), 2);
        // Given explicitly: as given.
        let fixed = Schedule {
            finest_scale: Some(2),
            ..s
        };
        assert_eq!(fixed.finest_for(1024, 1024, 8.0), 2);
    }
}
