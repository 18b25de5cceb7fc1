//! Benchmark evaluation: every method on every scene of a ray-traced benchmark
//! (`drbokeh benchmark make`), scored against the ground truth, written as a report.
//!
//! Methods ([`Method`]) and their inputs (each scene directory provides them):
//! - on the all-in-focus image `aif.png` + `disparity.npy`: the baselines `gather`,
//!   `scatter`, `layered`, `gausspsf` ([`crate::baselines`]) and `paper-aif` (the `paper`
//!   preset on a single opaque layer);
//! - on the ground-truth layer stack `layers.npz`: `layered-gt` (the layered baseline) and
//!   `paper-gt` (the `paper` preset); `physical-aif` and `physical-gt`, the `physical` preset on
//!   the same inputs.
//!
//! All methods use the scene's `blur` (K) and `focus` from `scene.json`, gamma 2.2 (the
//! `paper` preset's and the classical baselines' transfer for a display-encoded photo; the
//! benchmark's images are sRGB-encoded, like photos) and a window wide enough for the largest blur; every
//! render is clipped to [0, 1] and compared with `bokeh.png` (display-encoded, clipped) by
//! PSNR, SSIM and MS-SSIM ([`super::metrics`]). Renders are multi-threaded within a method
//! (rows); scenes and methods run one after another, so every number except the timings is
//! the same on every run and thread count.
//!
//! This module writes a report ([`write_report`]) and gathers, for callers, the evaluation's
//! pieces from the modules that hold them: methods (`methods.rs`), scene loading
//! (`scenes.rs`), scoring (`scoring.rs`), running (`run.rs`), aggregates (`summary.rs`),
//! pictures (`images.rs`), CSV/Markdown (`tables.rs`), SVG (`plots.rs`) and HTML
//! (`html.rs`).
//!
//! [`write_report`] writes `results.json`, `results.csv`, `summary.md`, one SVG plot per
//! metric (`psnr_vs_blur.svg`, ...) and `index.html` (see `docs/evaluation.md` for the
//! schema); [`write_scene_images`] writes the pictures the gallery shows.

pub use super::html::report_html;
pub use super::images::{
    heat_colour, method_image_names, write_disparity_preview, write_error_map, write_preview,
    write_scene_images, ERROR_MAP_FULL_SCALE,
};
pub use super::methods::{
    photo_view_defaults, render_paper, render_photo, render_photo_pipeline, render_preset, Method,
    MethodInput, Renderer,
};
pub use super::plots::{metric_plot_svg, plot_files, MetricAccessor};
pub use super::run::{evaluate_benchmark, evaluate_scene, render_method};
pub use super::scenes::{list_scenes, SceneInputs, BENCHMARK_GAMMA, SCENE_FILES};
pub use super::scoring::{score, MethodResult, SceneResult};
pub use super::summary::{
    bucket_of, buckets, mean_std, Bucket, BucketSummary, MethodInfo, Report, Summary, SummaryRow,
    SCHEMA_VERSION,
};
pub use super::tables::{results_csv, summary_markdown};

use crate::io;
use crate::{Error, Result};
use std::path::Path;

fn write_text(path: &Path, text: &str) -> Result<()> {
    io::write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

/// Writes a report into directory `out` (created if missing): `results.json`,
/// `results.csv`, `summary.md`, the SVG plots and `index.html`. Scene pictures are written
/// separately, by [`evaluate_benchmark`] / [`write_scene_images`].
pub fn write_report(out: &Path, report: &Report) -> Result<()> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, "cannot create", e))?;
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| Error::file(out.join("results.json"), e.to_string()))?;
    write_text(&out.join("results.json"), &(json + "\n"))?;
    write_text(&out.join("results.csv"), &results_csv(report))?;
    write_text(&out.join("summary.md"), &summary_markdown(report))?;
    for (file, title, get) in plot_files() {
        write_text(&out.join(file), &metric_plot_svg(report, title, get))?;
    }
    write_text(&out.join("index.html"), &report_html(report))?;
    Ok(())
}
