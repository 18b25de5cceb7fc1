//! Sweeps highlight recovery settings of the photo pipeline on ray-traced benchmarks
//! (docs/highlights.md): mean PSNR against `bokeh.png` per blur bucket, next to naive scatter.
//!
//! ```text
//! cargo run --release -p drbokeh --example highlight_sweep -- PRESET SPEC[,SPEC...] BENCHMARK...
//! ```
//! `PRESET` is `physical` or `paper`; each `SPEC` is `off`, `paper` (the paper's boost) or
//! `GAIN:THRESHOLD`, optionally followed by `+paper` (with the paper's boost as well) and `/single` (one opaque layer instead of the
//! decomposition).
//!
//! `SWEEP_SCENES=1` also prints each scene's PSNR; `SWEEP_DUMP=DIR` writes, per scene,
//! `DIR/<benchmark>/<scene>/<spec>.npy` (display-encoded renders, float32) next to
//! `scatter.npy`, `gt.npy` (physical on the true layers), `truth.npy` and `aif.npy`, for
//! looking at where the error lies.

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
    let specs: Vec<&str> = if args[1].contains(' ') {
        args[1].split_whitespace().collect()
    } else {
        args[1].split(',').collect()
    };
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
            let dump = std::env::var_os("SWEEP_DUMP").map(|d| {
                std::path::PathBuf::from(d)
                    .join(std::path::Path::new(bench).file_name().unwrap_or_default())
                    .join(dir.file_name().unwrap_or_default())
            });
            let save = |name: &str,
                        img: &drbokeh::image::Image<f32>|
             -> Result<(), Box<dyn std::error::Error>> {
                if let Some(d) = &dump {
                    std::fs::create_dir_all(d)?;
                    let file = d.join(format!("{}.npy", name.replace([':', '/', ',', '='], "_")));
                    drbokeh::io::write_output(&file, img, drbokeh::io::BitDepth::Sixteen, |v| v)?;
                }
                Ok(())
            };
            let scatter = render_method(Method::Scatter, &scene)?;
            push("scatter", psnr(&scatter, &scene.ground_truth)?);
            save("scatter", &scatter)?;
            if dump.is_some() {
                let gt = render_method(Method::PhysicalGt, &scene)?;
                save("gt", &gt)?;
                save("truth", &scene.ground_truth)?;
                let aif: drbokeh::image::Image<f32> = drbokeh::io::read_rgb(&dir.join("aif.png"))?;
                save("aif", &aif)?;
            }
            for spec in &specs {
                if let Some(mode) = spec.strip_prefix("oracle:") {
                    let out = oracle(mode, &dir, &scene, preset)?;
                    push(spec, psnr(&out, &scene.ground_truth)?);
                    save(spec, &out)?;
                    continue;
                }
                let mut view = View::default();
                let (spec_core, single) = match spec.strip_suffix("/single") {
                    Some(c) => (c, true),
                    None => (*spec, false),
                };
                let (spec_core, with_paper) = match spec_core.strip_suffix("+paper") {
                    Some(c) => (c, true),
                    None => (spec_core, false),
                };
                let (spec_core, exr) = match spec_core.strip_prefix("exr") {
                    Some(_) => ("off", true),
                    None => (spec_core, false),
                };
                view.photo_highlights = PhotoHighlights::parse(spec_core)?;
                let mut files = PhotoFiles::new(
                    dir.join(if exr { "aif.exr" } else { "aif.png" }),
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
                let p = psnr(&out, &scene.ground_truth)?;
                if std::env::var_os("SWEEP_SCENES").is_some() {
                    println!("{bench} {} {spec} {p:.2}", dir.display());
                }
                push(spec, p);
                save(spec, &out)?;
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

/// Analysis only: the photo with its clipped pixels (any channel >= 254.5/255) replaced
/// from `aif.exr`: per pixel (`px`), or per 8-connected clipped region by its mean colour
/// (`tint`) or mean grey (`white`); defocused pixels only (radius >= 2 px) with `+gate`.
fn oracle(
    mode: &str,
    dir: &std::path::Path,
    scene: &SceneInputs,
    preset: drbokeh::Preset,
) -> Result<drbokeh::image::Image<f32>, Box<dyn std::error::Error>> {
    let png: drbokeh::image::Image<f32> = drbokeh::io::read_rgb(&dir.join("aif.png"))?;
    let exr: drbokeh::image::Image<f32> = drbokeh::io::read_rgb(&dir.join("aif.exr"))?;
    let cam = scene.camera();
    let view = View {
        photo_highlights: PhotoHighlights::Off,
        gamma: cam.gamma,
        preset,
        ..View::default()
    };
    let tone = view.tone();
    let (w, h) = (png.width, png.height);
    let clipped: Vec<bool> = png
        .data
        .chunks_exact(3)
        .map(|p| p.iter().any(|&v| v >= 254.5 / 255.0))
        .collect();
    let (mode, gate) = match mode.strip_suffix("+gate") {
        Some(m) => (m, true),
        None => (mode, false),
    };
    let mut out = png.clone();
    for reg in drbokeh::highlight::regions(w, h, |i| clipped[i]) {
        let mut m = [0.0f64; 3];
        for &i in &reg {
            for c in 0..3 {
                m[c] += exr.data[3 * i + c].max(0.0) as f64 / reg.len() as f64;
            }
        }
        let grey = (m[0] + m[1] + m[2]) / 3.0;
        for &i in &reg {
            let r = scene.blur_k * (scene.disparity.data[i] as f64 - scene.focus).abs();
            if gate && r < 2.0 {
                continue;
            }
            for c in 0..3 {
                let lin = match mode {
                    "px" => exr.data[3 * i + c].max(0.0) as f64,
                    "tint" => m[c],
                    _ => grey,
                };
                // never below the photo
                let lin = lin.max(tone.linearize(png.data[3 * i + c] as f64));
                out.data[3 * i + c] = tone.encode(lin) as f32;
            }
        }
    }
    let photo = drbokeh::scene::Photo {
        rgb_encoded: out,
        disparity: scene.disparity.clone(),
        matte: None,
        layering: Layering::Decompose { max_layers: 5 },
    };
    let mut img = render_photo_pipeline(preset, Source::Photo(photo), &cam, view)?;
    img.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    Ok(img)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}
