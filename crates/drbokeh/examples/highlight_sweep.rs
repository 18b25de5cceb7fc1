//! Sweeps highlight recovery settings of the photo pipeline on ray-traced benchmarks
//! (docs/highlights.md): mean PSNR against `bokeh.png` per blur bucket, next to naive scatter.
//!
//! ```text
//! cargo run --release -p drbokeh --example highlight_sweep -- PRESET SPEC[,SPEC...] BENCHMARK...
//! ```
//! `PRESET` is `physical` or `paper`; each `SPEC` is `off`, `paper` (the paper's boost) or
//! `GAIN:THRESHOLD`, optionally followed by `+paper` (with the paper's boost as well) and `/single` (one opaque layer instead of the
//! decomposition).

use drbokeh::eval::metrics::psnr;
use drbokeh::eval::report::{
    bucket_of, list_scenes, render_method, render_photo_pipeline, Method, SceneInputs,
};
use drbokeh::highlight::PhotoHighlights;
use drbokeh::io::DepthKind;
use drbokeh::scene::{Layering, PhotoFiles, Source, View};
use std::collections::BTreeMap;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        return Err("usage: highlight_sweep PRESET SPEC[,SPEC...] BENCHMARK...".into());
    }
    let preset: drbokeh::Preset = args[0].parse()?;
    let specs: Vec<&str> = args[1].split(',').collect();
    for bench in &args[2..] {
        // (bucket -> (config -> PSNRs)); config "scatter" is the baseline.
        let mut table: BTreeMap<String, BTreeMap<String, Vec<f64>>> = BTreeMap::new();
        for dir in list_scenes(bench.as_ref())? {
            let scene = SceneInputs::load(&dir)?;
            let bucket = bucket_of(scene.max_coc_px);
            let mut push = |name: &str, v: f64| {
                for b in [bucket.clone(), "all".to_string()] {
                    table
                        .entry(b)
                        .or_default()
                        .entry(name.to_string())
                        .or_default()
                        .push(v);
                }
            };
            let scatter = render_method(Method::Scatter, &scene)?;
            push("scatter", psnr(&scatter, &scene.ground_truth)?);
            for spec in &specs {
                let mut view = View::default();
                let (spec_core, single) = match spec.strip_suffix("/single") {
                    Some(c) => (c, true),
                    None => (*spec, false),
                };
                let (spec_core, with_paper) = match spec_core.strip_suffix("+paper") {
                    Some(c) => (c, true),
                    None => (spec_core, false),
                };
                view.photo_highlights = PhotoHighlights::parse(spec_core)?;
                let mut files = PhotoFiles::new(
                    dir.join("aif.png"),
                    dir.join("disparity.npy"),
                    DepthKind::Disparity,
                );
                view.highlight |= with_paper;
                if single {
                    files.layering = Layering::SingleLayer;
                }
                let mut out = render_photo_pipeline(
                    preset,
                    Source::PhotoFiles(files),
                    &scene.camera(),
                    view,
                )?;
                out.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
                push(spec, psnr(&out, &scene.ground_truth)?);
            }
        }
        println!("## {bench} ({preset:?})");
        for (bucket, rows) in &table {
            let base = mean(&rows["scatter"]);
            let line: Vec<String> = rows
                .iter()
                .map(|(k, v)| format!("{k} {:.2} ({:+.2})", mean(v), mean(v) - base))
                .collect();
            println!(
                "{bucket} (n={}): {}",
                rows["scatter"].len(),
                line.join(" | ")
            );
        }
    }
    Ok(())
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}
