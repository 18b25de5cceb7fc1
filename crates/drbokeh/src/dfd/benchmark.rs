//! `drbokeh dfd-eval --benchmark`: depth from defocus on ray-traced pairs
//! (`drbokeh benchmark make`), scored against their true disparity.
//!
//! Each scene gives its all-in-focus image `aif.png`, its defocused image `bokeh.png`, K and
//! focus (`scene.json`), and the truth: `disparity.npy`, the layers `layers.npz` (for the
//! foreground mask) and the billboards' depths (for the depth ratio of `delta < 1.25`).
//! Every method recovers a disparity map from the pair alone.
//!
//! Methods ([`DfdMethod`]): the rendering layers (drbokeh with preset `physical`, drbokeh
//! with `paper`, GaussPSF, aperture compositing) crossed with loss combinations (L1+G,
//! L1+G+SSIM, L1+G+HSSIM), and the constant guess (the median of the *true* disparity: an
//! oracle constant, a generous baseline).
//!
//! Scenes are grouped ([`SceneGroup`]): the sign of `d = disp - focus` is determined when
//! the focus lies at an end of the scene's visible disparity range (focus on the nearest
//! or the farthest billboard), and ambiguous otherwise (the same blur on both sides of the
//! focus); determined scenes are split by their largest circle of confusion.

use super::confidence::sparsification;
use super::{
    estimate_disparity, masked_disparity_errors, DepthRange, DfdOptions, DisparityErrors,
    LossTerms, LossWeights, RenderLayer,
};
use crate::eval::report::SceneInputs;
use crate::image::Image;
use crate::presets::{Preset, RenderSettings};
use crate::{Error, Progress, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Version of the [`DfdBenchmarkReport`] schema.
pub const DFD_BENCHMARK_SCHEMA_VERSION: u32 = 2;

/// Largest CoC (pixels) from which a determined scene is in the main group.
pub const MAIN_GROUP_MIN_COC_PX: f64 = 6.0;

/// Confidence at or above which a pixel counts as confident.
pub const CONFIDENT: f64 = 0.5;

/// A loss combination of the HSSIM ablation (supplement fig. 10).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LossCombo {
    /// L1 + edge-aware smoothness.
    #[serde(rename = "L1+G")]
    L1G,
    /// L1 + G + one 11-window SSIM (weighted as HSSIM's five windows).
    #[serde(rename = "L1+G+SSIM")]
    L1GSsim,
    /// L1 + G + HSSIM (the default).
    #[serde(rename = "L1+G+HSSIM")]
    L1GHssim,
}

impl LossCombo {
    /// All three, in the ablation's order.
    pub const ALL: [LossCombo; 3] = [LossCombo::L1G, LossCombo::L1GSsim, LossCombo::L1GHssim];

    /// Display name.
    pub fn name(self) -> &'static str {
        match self {
            LossCombo::L1G => "L1+G",
            LossCombo::L1GSsim => "L1+G+SSIM",
            LossCombo::L1GHssim => "L1+G+HSSIM",
        }
    }

    /// CLI name.
    pub fn key(self) -> &'static str {
        match self {
            LossCombo::L1G => "l1g",
            LossCombo::L1GSsim => "ssim",
            LossCombo::L1GHssim => "hssim",
        }
    }

    /// Loss weights and structural term, from the defaults `base`.
    pub fn weights(self, base: LossWeights) -> (LossWeights, LossTerms) {
        match self {
            LossCombo::L1G => (LossWeights { hssim: 0.0, ..base }, LossTerms::Hssim),
            LossCombo::L1GSsim => (base, LossTerms::SingleSsim),
            LossCombo::L1GHssim => (base, LossTerms::Hssim),
        }
    }

    /// Parses a comma-separated list of CLI names (`l1g`, `ssim`, `hssim`) or `all`.
    pub fn parse_list(list: &str) -> Result<Vec<LossCombo>> {
        if list.trim() == "all" {
            return Ok(Self::ALL.to_vec());
        }
        list.split(',')
            .map(str::trim)
            .map(|k| {
                Self::ALL.into_iter().find(|c| c.key() == k).ok_or_else(|| {
                    Error::param(
                        "losses",
                        format!("unknown loss combination '{k}' (l1g, ssim, hssim or all)"),
                    )
                })
            })
            .collect()
    }
}

/// A rendering layer as dfd-eval runs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DfdLayer {
    /// Dr.Bokeh with preset `physical`.
    Physical,
    /// Dr.Bokeh with preset `paper`.
    Paper,
    /// GaussPSF.
    GaussPsf,
    /// Aperture compositing.
    Aperture,
}

impl DfdLayer {
    /// All four, in the report's order.
    pub const ALL: [DfdLayer; 4] = [
        DfdLayer::Physical,
        DfdLayer::Paper,
        DfdLayer::GaussPsf,
        DfdLayer::Aperture,
    ];

    /// Name in tables and on the CLI.
    pub fn name(self) -> &'static str {
        match self {
            DfdLayer::Physical => "drbokeh-physical",
            DfdLayer::Paper => "drbokeh-paper",
            DfdLayer::GaussPsf => "gausspsf",
            DfdLayer::Aperture => "aperture",
        }
    }

    /// The rendering layer and preset.
    pub fn layer_and_preset(self) -> (RenderLayer, Preset) {
        match self {
            DfdLayer::Physical => (RenderLayer::DrBokeh, Preset::Physical),
            DfdLayer::Paper => (RenderLayer::DrBokeh, Preset::Paper),
            DfdLayer::GaussPsf => (RenderLayer::GaussPsf, Preset::Physical),
            DfdLayer::Aperture => (RenderLayer::Aperture, Preset::Physical),
        }
    }

    /// Parses a comma-separated list of names (`physical`, `paper`, `gausspsf`, `aperture`,
    /// with or without the `drbokeh-` prefix) or `all`.
    pub fn parse_list(list: &str) -> Result<Vec<DfdLayer>> {
        if list.trim() == "all" {
            return Ok(Self::ALL.to_vec());
        }
        list.split(',')
            .map(str::trim)
            .map(|k| {
                let k = k.strip_prefix("drbokeh-").unwrap_or(k);
                Self::ALL
                    .into_iter()
                    .find(|l| l.name().strip_prefix("drbokeh-").unwrap_or(l.name()) == k)
                    .ok_or_else(|| {
                        Error::param(
                            "layers",
                            format!(
                                "unknown layer '{k}' (physical, paper, gausspsf, aperture or all)"
                            ),
                        )
                    })
            })
            .collect()
    }
}

/// One row of the evaluation: a layer with a loss combination, or the constant guess.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DfdMethod {
    /// Optimisation through a layer with a loss combination.
    Optimised {
        /// The layer.
        layer: DfdLayer,
        /// The losses.
        losses: LossCombo,
    },
    /// The median of the true disparity everywhere.
    ConstantMedian,
}

impl DfdMethod {
    /// Name in tables, e.g. `drbokeh-physical L1+G+HSSIM`.
    pub fn name(self) -> String {
        match self {
            DfdMethod::Optimised { layer, losses } => format!("{} {}", layer.name(), losses.name()),
            DfdMethod::ConstantMedian => "constant (true median)".to_string(),
        }
    }

    /// A file-name-safe key, e.g. `drbokeh-physical_hssim`.
    pub fn key(self) -> String {
        match self {
            DfdMethod::Optimised { layer, losses } => format!("{}_{}", layer.name(), losses.key()),
            DfdMethod::ConstantMedian => "constant".to_string(),
        }
    }
}

/// Which group a scene is reported in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneGroup {
    /// Sign of `d` determined (focus on the nearest or farthest billboard), largest CoC at
    /// least [`MAIN_GROUP_MIN_COC_PX`]: the target group.
    Determined,
    /// Sign determined, smaller blur.
    DeterminedSmallBlur,
    /// Focus inside the scene's depth range: the same blur on both sides of the focus.
    SignAmbiguous,
}

impl SceneGroup {
    /// All groups, in report order.
    pub const ALL: [SceneGroup; 3] = [
        SceneGroup::Determined,
        SceneGroup::DeterminedSmallBlur,
        SceneGroup::SignAmbiguous,
    ];

    /// Heading in tables.
    pub fn title(self) -> &'static str {
        match self {
            SceneGroup::Determined => "sign determined (near or far focus), largest CoC >= 6 px",
            SceneGroup::DeterminedSmallBlur => "sign determined, largest CoC < 6 px",
            SceneGroup::SignAmbiguous => "sign ambiguous (focus inside the depth range)",
        }
    }
}

/// How well a run's maps rank its pixels by their error (each null for the constant guess,
/// which has no maps; in a [`SummaryRow`], the means over the scenes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RankingScores {
    /// MAE over the most confident half of the pixels.
    pub mae_confident_half: Option<f64>,
    /// The area between the confidence map's sparsification curve and the oracle's
    /// ([`super::confidence::Sparsification::ause`]; 0 is a perfect ranking).
    pub ause: Option<f64>,
    /// The same area for the sensitivity map ([`super::DfdResult::sensitivity`]).
    pub ause_sensitivity: Option<f64>,
    /// The same area for a map that says nothing, to compare the two with.
    pub ause_uninformative: Option<f64>,
}

impl RankingScores {
    /// The scores of an estimate's confidence and sensitivity maps.
    fn of(abs_error: &[f64], confidence: &Image<f32>, sensitivity: &Image<f32>) -> Self {
        let ranked = |m: &Image<f32>| {
            let c: Vec<f64> = m.data.iter().map(|&v| v as f64).collect();
            sparsification(abs_error, &c)
        };
        let (c, s) = (ranked(confidence), ranked(sensitivity));
        RankingScores {
            mae_confident_half: Some(c.mae_confident_half),
            ause: Some(c.ause),
            ause_sensitivity: Some(s.ause),
            ause_uninformative: Some(c.ause_uninformative),
        }
    }

    /// Field by field, the mean over the runs that have it.
    fn mean<'a>(runs: impl Iterator<Item = &'a RankingScores> + Clone) -> Self {
        RankingScores {
            mae_confident_half: mean(runs.clone().filter_map(|r| r.mae_confident_half)),
            ause: mean(runs.clone().filter_map(|r| r.ause)),
            ause_sensitivity: mean(runs.clone().filter_map(|r| r.ause_sensitivity)),
            ause_uninformative: mean(runs.filter_map(|r| r.ause_uninformative)),
        }
    }
}

/// The scores of one method on one scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    /// [`DfdMethod::name`].
    pub method: String,
    /// [`DfdMethod::key`].
    pub key: String,
    /// Over all pixels (`within_1_25` on depth).
    pub errors: DisparityErrors,
    /// MAE over the foreground pixels (null if there are none).
    pub mae_foreground: Option<f64>,
    /// MAE over the background pixels (null if there are none).
    pub mae_background: Option<f64>,
    /// MAE over the pixels whose confidence is at least [`CONFIDENT`] (null if none or no
    /// confidence map).
    pub mae_confident: Option<f64>,
    /// Fraction of pixels that are confident (null for the constant guess).
    pub confident_fraction: Option<f64>,
    /// How well its confidence and sensitivity maps rank the pixels by their error.
    #[serde(flatten)]
    pub ranking: RankingScores,
    /// Wall time of the run (seconds; not deterministic).
    pub seconds: f64,
    /// Adam iterations run, all scales together.
    pub iterations: usize,
}

/// One scene's results.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneReport {
    /// Scene directory name.
    pub scene: String,
    /// K.
    pub blur: f64,
    /// Focus disparity.
    pub focus: f64,
    /// Largest CoC radius over the visible content, pixels.
    pub max_coc_px: f64,
    /// The group it is reported in.
    pub group: SceneGroup,
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Fraction of pixels in the foreground mask.
    pub foreground_fraction: f64,
    /// Pixels clipped in the all-in-focus image (any channel).
    pub clipped_aif_fraction: f64,
    /// One entry per method.
    pub results: Vec<RunResult>,
}

/// Mean scores of one method over a group of scenes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SummaryRow {
    /// Method name.
    pub method: String,
    /// Method key.
    pub key: String,
    /// Scenes.
    pub n: usize,
    /// Mean MAE.
    pub mae: f64,
    /// Mean RMSE.
    pub rmse: f64,
    /// Mean fraction within 1.25 (depth ratio).
    pub within_1_25: f64,
    /// Mean foreground MAE (over scenes with a foreground).
    pub mae_foreground: Option<f64>,
    /// Mean background MAE.
    pub mae_background: Option<f64>,
    /// Mean confident-pixel MAE.
    pub mae_confident: Option<f64>,
    /// Mean confident fraction.
    pub confident_fraction: Option<f64>,
    /// The means of the runs' [`RunResult::ranking`].
    #[serde(flatten)]
    pub ranking: RankingScores,
    /// Mean seconds per scene.
    pub seconds: f64,
}

/// A group's summary.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupSummary {
    /// The group.
    pub group: SceneGroup,
    /// Its heading.
    pub title: String,
    /// Scenes in it.
    pub scenes: Vec<String>,
    /// One row per method.
    pub rows: Vec<SummaryRow>,
}

/// The whole evaluation (the content of `results.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DfdBenchmarkReport {
    /// [`DFD_BENCHMARK_SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The library version that wrote it.
    pub drbokeh_version: String,
    /// The benchmark directory.
    pub benchmark: String,
    /// Metric definitions, in words.
    pub metrics: Vec<(String, String)>,
    /// The options of the runs (the default run's; each method changes layer, preset and
    /// losses).
    pub options: super::log::RunOptions,
    /// Per scene.
    pub scenes: Vec<SceneReport>,
    /// Per group (only groups with scenes).
    pub summary: Vec<GroupSummary>,
}

/// What to evaluate.
#[derive(Clone, Debug)]
pub struct DfdBenchmarkConfig {
    /// The benchmark directory.
    pub benchmark: PathBuf,
    /// Layers to run.
    pub layers: Vec<DfdLayer>,
    /// Loss combinations to run with each layer.
    pub losses: Vec<LossCombo>,
    /// Options shared by all runs (schedule, highlights, ...); layer, preset and losses are
    /// set per method, camera per scene.
    pub template: DfdOptions,
    /// Groups to evaluate (others are skipped).
    pub groups: Vec<SceneGroup>,
    /// At most this many scenes (after the group filter).
    pub limit: Option<usize>,
}

/// A loaded scene with its truth and classification.
pub struct DfdScene {
    /// The benchmark scene.
    pub inputs: SceneInputs,
    /// Its group.
    pub group: SceneGroup,
    /// Per pixel: in the foreground (the front billboards' combined alpha >= 1/2).
    pub foreground: Vec<bool>,
    /// The metric depth range behind the normalised disparity (null if `scene.json` does
    /// not list billboard depths).
    pub depth_range: Option<DepthRange>,
}

/// The depth range from `scene.json`'s `derived.billboards_front_to_back[].depth_mm`.
fn depth_range(dir: &Path) -> Option<DepthRange> {
    let text = std::fs::read_to_string(dir.join("scene.json")).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    let depths: Vec<f64> = json
        .get("derived")?
        .get("billboards_front_to_back")?
        .as_array()?
        .iter()
        .filter_map(|b| b.get("depth_mm")?.as_f64())
        .collect();
    let near = depths.iter().cloned().fold(f64::INFINITY, f64::min);
    let far = depths.iter().cloned().fold(0.0, f64::max);
    (near > 0.0 && far > near).then_some(DepthRange { near, far })
}

impl DfdScene {
    /// Loads and classifies a benchmark scene directory.
    pub fn load(dir: &Path) -> Result<Self> {
        let inputs = SceneInputs::load(dir)?;
        let (w, h) = (inputs.aif.width, inputs.aif.height);
        let layers = &inputs.layers.layers;
        let mut foreground = vec![false; w * h];
        if layers.len() > 1 {
            for (i, f) in foreground.iter_mut().enumerate() {
                let through: f64 = layers[..layers.len() - 1]
                    .iter()
                    .map(|l| 1.0 - (l.alpha.data[i] as f64).clamp(0.0, 1.0))
                    .product();
                *f = 1.0 - through >= 0.5;
            }
        }
        // The visible disparity range: disparities of layers with some alpha.
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for l in layers {
            for (a, d) in l.alpha.data.iter().zip(&l.disparity.data) {
                if *a > 0.0 {
                    lo = lo.min(*d as f64);
                    hi = hi.max(*d as f64);
                }
            }
        }
        let tol = 1e-3;
        let determined = inputs.focus >= hi - tol || inputs.focus <= lo + tol;
        let group = if !determined {
            SceneGroup::SignAmbiguous
        } else if inputs.max_coc_px >= MAIN_GROUP_MIN_COC_PX {
            SceneGroup::Determined
        } else {
            SceneGroup::DeterminedSmallBlur
        };
        Ok(DfdScene {
            depth_range: depth_range(dir),
            inputs,
            group,
            foreground,
        })
    }

    /// The camera of the scene for depth from defocus: its K and focus, `preset`, and the
    /// benchmark's gamma.
    pub fn settings(&self, preset: Preset) -> RenderSettings {
        let mut s = RenderSettings::physical(self.inputs.focus);
        s.camera = self.inputs.camera();
        s.preset = preset;
        s
    }

    /// The constant guess: the median of the true disparity.
    pub fn median_guess(&self) -> Image<f32> {
        let mut v = self.inputs.disparity.data.clone();
        v.sort_by(f32::total_cmp);
        let med = v[v.len() / 2];
        Image {
            data: vec![med; v.len()],
            ..self.inputs.disparity.clone()
        }
    }

    /// Scores an estimate (and its confidence and sensitivity maps, if any).
    pub fn score(
        &self,
        method: DfdMethod,
        estimate: &Image<f32>,
        maps: Option<(&Image<f32>, &Image<f32>)>,
        seconds: f64,
        iterations: usize,
    ) -> RunResult {
        let confidence = maps.map(|m| m.0);
        let truth = &self.inputs.disparity;
        let errors = masked_disparity_errors(estimate, truth, self.depth_range, |_| true)
            .expect("a scene has pixels");
        let fg = masked_disparity_errors(estimate, truth, None, |i| self.foreground[i]);
        let bg = masked_disparity_errors(estimate, truth, None, |i| !self.foreground[i]);
        let (mae_confident, confident_fraction) = match confidence {
            Some(c) => {
                let keep = |i: usize| c.data[i] as f64 >= CONFIDENT;
                let n = (0..c.data.len()).filter(|&i| keep(i)).count();
                (
                    masked_disparity_errors(estimate, truth, None, keep).map(|e| e.mae),
                    Some(n as f64 / c.data.len() as f64),
                )
            }
            None => (None, None),
        };
        let abs_error: Vec<f64> = estimate
            .data
            .iter()
            .zip(&truth.data)
            .map(|(e, t)| (*e as f64 - *t as f64).abs())
            .collect();
        let ranking = maps
            .map(|(c, s)| RankingScores::of(&abs_error, c, s))
            .unwrap_or_default();
        RunResult {
            method: method.name(),
            key: method.key(),
            errors,
            mae_foreground: fg.map(|e| e.mae),
            mae_background: bg.map(|e| e.mae),
            mae_confident,
            confident_fraction,
            ranking,
            seconds,
            iterations,
        }
    }
}

/// The methods of a configuration, in report order (layers x losses, then the constant).
pub fn methods(config: &DfdBenchmarkConfig) -> Vec<DfdMethod> {
    let mut m: Vec<DfdMethod> = config
        .layers
        .iter()
        .flat_map(|&layer| {
            config
                .losses
                .iter()
                .map(move |&losses| DfdMethod::Optimised { layer, losses })
        })
        .collect();
    m.push(DfdMethod::ConstantMedian);
    m
}

/// The scene directories of a benchmark that fall in the configured groups (loaded).
pub fn select_scenes(config: &DfdBenchmarkConfig) -> Result<Vec<DfdScene>> {
    let dirs = crate::eval::report::list_scenes(&config.benchmark)?;
    let mut scenes = Vec::new();
    for d in dirs {
        let s = DfdScene::load(&d)?;
        if config.groups.contains(&s.group) {
            scenes.push(s);
        }
        if config.limit.is_some_and(|n| scenes.len() >= n) {
            break;
        }
    }
    if scenes.is_empty() {
        return Err(Error::file(
            &config.benchmark,
            "no scene in the selected groups (see --groups)",
        ));
    }
    Ok(scenes)
}

/// The options one optimised row runs with on `scene`: `template` with the scene's camera
/// (`template`'s transfer gamma kept), `layer`'s rendering layer and preset, and the loss
/// weights and structural term of `losses`.
pub fn method_options(
    scene: &DfdScene,
    layer: DfdLayer,
    losses: LossCombo,
    template: &DfdOptions,
) -> DfdOptions {
    let (render_layer, preset) = layer.layer_and_preset();
    let mut o = template.clone();
    o.settings = scene.settings(preset);
    o.settings.camera.gamma = template.settings.camera.gamma;
    o.layer = render_layer;
    (o.weights, o.terms) = losses.weights(template.weights);
    o
}

/// Runs one method on one scene: the estimate, its confidence map (not for the constant)
/// and its scores.
pub fn run_method(
    scene: &DfdScene,
    method: DfdMethod,
    template: &DfdOptions,
) -> Result<(RunResult, Image<f32>, Option<Image<f32>>)> {
    match method {
        DfdMethod::ConstantMedian => {
            let est = scene.median_guess();
            let r = scene.score(method, &est, None, 0.0, 0);
            Ok((r, est, None))
        }
        DfdMethod::Optimised { layer, losses } => {
            let o = method_options(scene, layer, losses, template);
            let r = estimate_disparity(
                &scene.inputs.aif,
                &scene.inputs.ground_truth,
                &o,
                &mut |_| {},
            )
            .map_err(|e| e.in_file(&scene.inputs.dir))?;
            let iterations = r.log.scales.iter().map(|s| s.iterations).sum();
            let res = scene.score(
                method,
                &r.disparity,
                Some((&r.confidence, &r.sensitivity)),
                r.log.seconds,
                iterations,
            );
            Ok((res, r.disparity, Some(r.confidence)))
        }
    }
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = v.filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The per-group summaries of per-scene results.
pub fn summarise(methods: &[DfdMethod], scenes: &[SceneReport]) -> Vec<GroupSummary> {
    SceneGroup::ALL
        .into_iter()
        .filter_map(|group| {
            let sel: Vec<&SceneReport> = scenes.iter().filter(|s| s.group == group).collect();
            if sel.is_empty() {
                return None;
            }
            let rows = methods
                .iter()
                .map(|m| {
                    let key = m.key();
                    let runs: Vec<&RunResult> = sel
                        .iter()
                        .filter_map(|s| s.results.iter().find(|r| r.key == key))
                        .collect();
                    SummaryRow {
                        method: m.name(),
                        key,
                        n: runs.len(),
                        mae: mean(runs.iter().map(|r| r.errors.mae)).unwrap_or(f64::NAN),
                        rmse: mean(runs.iter().map(|r| r.errors.rmse)).unwrap_or(f64::NAN),
                        within_1_25: mean(runs.iter().map(|r| r.errors.within_1_25))
                            .unwrap_or(f64::NAN),
                        mae_foreground: mean(runs.iter().filter_map(|r| r.mae_foreground)),
                        mae_background: mean(runs.iter().filter_map(|r| r.mae_background)),
                        mae_confident: mean(runs.iter().filter_map(|r| r.mae_confident)),
                        confident_fraction: mean(runs.iter().filter_map(|r| r.confident_fraction)),
                        ranking: RankingScores::mean(runs.iter().map(|r| &r.ranking)),
                        seconds: mean(runs.iter().map(|r| r.seconds)).unwrap_or(0.0),
                    }
                })
                .collect();
            Some(GroupSummary {
                group,
                title: group.title().to_string(),
                scenes: sel.iter().map(|s| s.scene.clone()).collect(),
                rows,
            })
        })
        .collect()
}

/// Pictures of one scene handed to `on_scene` by [`evaluate`]: the scene and each
/// method's estimate and confidence.
pub type ScenePictures<'a> = (
    &'a DfdScene,
    &'a [(DfdMethod, Image<f32>, Option<Image<f32>>)],
);

/// Evaluates the configured methods on the selected scenes. `progress` counts runs;
/// `on_scene` receives each scene's pictures as soon as the scene is done (the CLI writes
/// them).
pub fn evaluate(
    config: &DfdBenchmarkConfig,
    progress: &dyn Progress,
    on_scene: &mut dyn FnMut(ScenePictures) -> Result<()>,
) -> Result<DfdBenchmarkReport> {
    config.template.validate()?;
    let scenes = select_scenes(config)?;
    let methods = methods(config);
    progress.start((scenes.len() * methods.len()) as u64);
    let mut reports = Vec::new();
    for scene in &scenes {
        let mut results = Vec::new();
        let mut pictures = Vec::new();
        for &m in &methods {
            let (r, est, conf) = run_method(scene, m, &config.template)?;
            results.push(r);
            pictures.push((m, est, conf));
            progress.advance(1);
        }
        on_scene((scene, &pictures))?;
        let i = &scene.inputs;
        let n = (i.aif.width * i.aif.height) as f64;
        reports.push(SceneReport {
            scene: i.name.clone(),
            blur: i.blur_k,
            focus: i.focus,
            max_coc_px: i.max_coc_px,
            group: scene.group,
            width: i.aif.width,
            height: i.aif.height,
            foreground_fraction: scene.foreground.iter().filter(|&&f| f).count() as f64 / n,
            clipped_aif_fraction: i
                .aif
                .data
                .chunks_exact(3)
                .filter(|p| p.iter().any(|&v| v as f64 >= super::optimise::CLIP_LEVEL))
                .count() as f64
                / n,
            results,
        });
    }
    let summary = summarise(&methods, &reports);
    Ok(DfdBenchmarkReport {
        schema_version: DFD_BENCHMARK_SCHEMA_VERSION,
        drbokeh_version: env!("CARGO_PKG_VERSION").to_string(),
        benchmark: config.benchmark.display().to_string(),
        metrics: vec![
            ("mae".into(), "mean absolute error of the normalised disparity (0 = farthest billboard, 1 = nearest)".into()),
            ("rmse".into(), "root mean squared error of the normalised disparity".into()),
            ("within_1_25".into(), "fraction of pixels whose estimated and true metric depths differ by a ratio below 1.25".into()),
            ("mae_foreground".into(), "MAE over the pixels where the four front billboards' combined alpha is at least 1/2".into()),
            ("mae_background".into(), "MAE over the other pixels (the background billboard)".into()),
            ("mae_confident".into(), format!("MAE over the pixels whose confidence is at least {CONFIDENT}")),
            ("mae_confident_half".into(), "MAE over the most confident half of the pixels".into()),
            ("ause".into(), "area between the confidence map's sparsification curve (MAE of the most confident 5 %, 10 %, ..., 100 %) and the oracle's (pixels of least error first), mean over the 20 samples; 0 is a perfect ranking".into()),
            ("ause_sensitivity".into(), "the same for the sensitivity map (where the render changes with the disparity)".into()),
            ("ause_uninformative".into(), "the same for a map that says nothing (every fraction has the whole MAE)".into()),
            ("constant".into(), "the median of the true disparity everywhere (an oracle constant)".into()),
        ],
        options: super::log::RunOptions::of(&config.template),
        scenes: reports,
        summary,
    })
}
