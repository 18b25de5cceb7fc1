//! Aggregates of a benchmark evaluation: blur-size buckets, mean and standard deviation per
//! method, and the [`Report`] (the content of `results.json`).

use super::methods::{Method, MethodInput};
use super::scoring::{MethodResult, SceneResult};
use serde::Serialize;
use std::path::Path;

/// The version of the `results.json` schema.
pub const SCHEMA_VERSION: u32 = 1;

/// A blur-size bucket: scenes whose largest CoC radius is in `[min_px, max_px)`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Bucket {
    /// Label, e.g. `8-16 px`.
    pub name: String,
    /// Lower bound (inclusive), pixels.
    pub min_px: f64,
    /// Upper bound (exclusive), pixels; `null` in JSON for the open last bucket.
    pub max_px: Option<f64>,
}

/// The blur-size buckets (largest CoC radius of a scene, pixels): <8, 8-16, 16-32, >=32.
pub fn buckets() -> Vec<Bucket> {
    let edges = [0.0, 8.0, 16.0, 32.0];
    edges
        .iter()
        .enumerate()
        .map(|(i, &lo)| {
            let hi = edges.get(i + 1).copied();
            Bucket {
                name: match hi {
                    Some(h) if lo == 0.0 => format!("<{h} px"),
                    Some(h) => format!("{lo}-{h} px"),
                    None => format!(">={lo} px"),
                },
                min_px: lo,
                max_px: hi,
            }
        })
        .collect()
}

/// The bucket of a scene with largest CoC radius `max_coc_px`.
pub fn bucket_of(max_coc_px: f64) -> String {
    buckets()
        .into_iter()
        .rev()
        .find(|b| max_coc_px >= b.min_px)
        .map(|b| b.name)
        .unwrap_or_else(|| buckets()[0].name.clone())
}

/// Mean and sample standard deviation (0 for fewer than two values) of the finite values;
/// `None` if there are none.
pub fn mean_std(values: &[f64]) -> Option<(f64, f64)> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    Some((mean, var.sqrt()))
}

/// Aggregate scores of one method over a set of scenes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SummaryRow {
    /// Method name.
    pub method: String,
    /// Number of scenes.
    pub n: usize,
    /// Scenes whose PSNR is infinite (identical images), left out of the PSNR statistics.
    pub psnr_infinite: usize,
    /// Mean PSNR (dB) over scenes with a finite PSNR.
    pub psnr_mean: Option<f64>,
    /// Sample standard deviation of the PSNR.
    pub psnr_std: Option<f64>,
    /// Mean SSIM.
    pub ssim_mean: Option<f64>,
    /// Sample standard deviation of the SSIM.
    pub ssim_std: Option<f64>,
    /// Mean MS-SSIM.
    pub ms_ssim_mean: Option<f64>,
    /// Sample standard deviation of the MS-SSIM.
    pub ms_ssim_std: Option<f64>,
    /// Mean render time, seconds.
    pub time_mean_s: Option<f64>,
}

/// The summary of one blur-size bucket.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BucketSummary {
    /// Bucket name.
    pub bucket: String,
    /// Number of scenes in the bucket.
    pub scenes: usize,
    /// One row per method.
    pub methods: Vec<SummaryRow>,
}

/// Aggregates: overall and per blur bucket.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Summary {
    /// One row per method, over all scenes.
    pub overall: Vec<SummaryRow>,
    /// Per blur bucket (only buckets with scenes).
    pub by_bucket: Vec<BucketSummary>,
}

/// A method's description in the report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MethodInfo {
    /// Name.
    pub name: String,
    /// Input it is fed.
    pub input: MethodInput,
    /// What it models and ignores.
    pub description: String,
}

/// A full evaluation report (the content of `results.json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The drbokeh version that wrote it.
    pub drbokeh_version: String,
    /// The benchmark directory evaluated.
    pub benchmark: String,
    /// Number of scenes.
    pub scene_count: usize,
    /// Metric definitions.
    pub metrics: serde_json::Value,
    /// The methods, in evaluation order.
    pub methods: Vec<MethodInfo>,
    /// The blur-size buckets.
    pub buckets: Vec<Bucket>,
    /// Per-scene results.
    pub scenes: Vec<SceneResult>,
    /// Aggregates.
    pub summary: Summary,
}

fn summary_row(method: &str, rows: &[&MethodResult]) -> SummaryRow {
    let col = |f: &dyn Fn(&MethodResult) -> f64| rows.iter().map(|r| f(r)).collect::<Vec<_>>();
    let psnr = mean_std(&col(&|r| r.psnr));
    let ssim = mean_std(&col(&|r| r.ssim));
    let ms = mean_std(&col(&|r| r.ms_ssim));
    let time = mean_std(&col(&|r| r.time_s));
    SummaryRow {
        method: method.to_string(),
        n: rows.len(),
        psnr_infinite: rows.iter().filter(|r| r.psnr == f64::INFINITY).count(),
        psnr_mean: psnr.map(|p| p.0),
        psnr_std: psnr.map(|p| p.1),
        ssim_mean: ssim.map(|p| p.0),
        ssim_std: ssim.map(|p| p.1),
        ms_ssim_mean: ms.map(|p| p.0),
        ms_ssim_std: ms.map(|p| p.1),
        time_mean_s: time.map(|p| p.0),
    }
}

fn summarise_scenes(methods: &[String], scenes: &[&SceneResult]) -> Vec<SummaryRow> {
    methods
        .iter()
        .map(|m| {
            let rows: Vec<&MethodResult> = scenes
                .iter()
                .flat_map(|s| s.results.iter().filter(|r| &r.method == m))
                .collect();
            summary_row(m, &rows)
        })
        .collect()
}

impl Report {
    /// The input name of the method called `method` (empty if unknown).
    pub fn input_of(&self, method: &str) -> &'static str {
        self.methods
            .iter()
            .find(|m| m.name == method)
            .map(|m| m.input.name())
            .unwrap_or("")
    }

    /// Builds a report (with its summary) from per-scene results.
    pub fn new(benchmark: &Path, methods: &[Method], scenes: Vec<SceneResult>) -> Self {
        let names: Vec<String> = methods.iter().map(|m| m.name().to_string()).collect();
        let all: Vec<&SceneResult> = scenes.iter().collect();
        let overall = summarise_scenes(&names, &all);
        let by_bucket = buckets()
            .into_iter()
            .filter_map(|b| {
                let sel: Vec<&SceneResult> = scenes.iter().filter(|s| s.bucket == b.name).collect();
                (!sel.is_empty()).then(|| BucketSummary {
                    bucket: b.name.clone(),
                    scenes: sel.len(),
                    methods: summarise_scenes(&names, &sel),
                })
            })
            .collect();
        Report {
            schema_version: SCHEMA_VERSION,
            drbokeh_version: env!("CARGO_PKG_VERSION").to_string(),
            benchmark: benchmark.display().to_string(),
            scene_count: scenes.len(),
            metrics: serde_json::json!({
                "psnr": "dB, data range 1, on display-encoded images clipped to [0, 1]; null when render and ground truth are identical (infinite PSNR)",
                "ssim": "scikit-image structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1, channel_axis=-1)",
                "ms_ssim": "multi-scale SSIM (Wang et al. 2003), 5 scales, same window as ssim",
                "time_s": "wall-clock render time in seconds (multi-threaded within the method; not deterministic)",
                "max_coc_px": "largest circle-of-confusion radius K|disp - focus| over the visible layer content, pixels",
                "std": "sample standard deviation (n - 1); 0 for one scene",
            }),
            methods: methods
                .iter()
                .map(|m| MethodInfo {
                    name: m.name().to_string(),
                    input: m.input(),
                    description: m.description().to_string(),
                })
                .collect(),
            buckets: buckets(),
            scenes,
            summary: Summary { overall, by_bucket },
        }
    }
}
