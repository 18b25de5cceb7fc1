//! Sweeps highlight recovery settings of the photo pipeline on ray-traced benchmarks
//! (docs/highlights.md): mean PSNR against `bokeh.png` per blur bucket, next to naive scatter.
//!
//! ```text
//! cargo run --release -p drbokeh --example highlight_sweep -- PRESET SPEC[,SPEC...] BENCHMARK...
//! ```
//! `PRESET` is `physical` or `paper`; each `SPEC` is `off`, `paper` (the paper's boost) or
//! `GAIN:THRESHOLD`, optionally followed by `+paper` (with the paper's boost as well) and `/single` (one opaque layer instead of the
//! decomposition). Oracles (from `aif.exr`, the unclipped all-in-focus image): `exr` (it
//! as the photo), `oracle:px|tint|white[+gate]` (its clipped pixels or regions put back
//! into the photo), `ogain[tint][-np]` (the default estimate with each region's gain, and
//! with `tint` its tint, replaced by the true one; `-np` without the paper's boost).
//! Prototype (not an oracle): `scene:C,LO,HI[,KPOW[,Q]]`, the default estimate with its
//! cap and rim constant set per scene from the quantile `Q` of the regions' uncapped rim
//! gains (`scene_pooled`; docs/highlights.md, "One exposure per photo").
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
                let (aif, exr) = read_png_exr(&dir)?;
                save("aif", &aif)?;
                save("exr", &exr)?;
            }
            for spec in &specs {
                let oracle_out = if let Some(mode) = spec.strip_prefix("scene:") {
                    Some(scene_pooled(mode, &dir, &scene, preset)?)
                } else if let Some(mode) = spec.strip_prefix("ogain") {
                    Some(oracle_gain(mode, &dir, &scene, preset)?)
                } else if let Some(mode) = spec.strip_prefix("oracle:") {
                    Some(oracle(mode, &dir, &scene, preset)?)
                } else {
                    None
                };
                if let Some(out) = oracle_out {
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
    let (png, exr) = read_png_exr(dir)?;
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
    render_decomposed(preset, out, scene.disparity.clone(), &cam, view)
}

/// Analysis only: the default estimate ([`drbokeh::highlight::HighlightEstimate`]) with
/// each region's gain replaced by the true one, the gain `g` for which its profile
/// (interior clipped pixels `g`, edge ones `g^p`) holds the clipped pixels' true light
/// (largest channel, from `aif.exr`); with `tint` in `mode` the tint too (the true mean
/// colour over its largest channel); `-np`: without the paper's boost on top.
fn oracle_gain(
    mode: &str,
    dir: &std::path::Path,
    scene: &SceneInputs,
    preset: drbokeh::Preset,
) -> Result<drbokeh::image::Image<f32>, Box<dyn std::error::Error>> {
    let (png, exr) = read_png_exr(dir)?;
    let cam = scene.camera();
    let (mode, paper) = match mode.strip_suffix("-np") {
        Some(m) => (m, false),
        None => (mode, true),
    };
    let with_tint = mode == "tint";
    let est = drbokeh::highlight::HighlightEstimate::DEFAULT;
    let p = est.edge_power.unwrap_or(1.0);
    let view = View {
        // The recovery is done here; the boost (or nothing) is left to the pipeline.
        photo_highlights: if paper {
            PhotoHighlights::PaperBoost
        } else {
            PhotoHighlights::Off
        },
        gamma: cam.gamma,
        preset,
        ..View::default()
    };
    let (w, h) = (png.width, png.height);
    // As the pipeline: lights at their farthest depth first (idempotent there).
    let disparity = drbokeh::highlight::lights_at_farthest_depth(&png, &scene.disparity)
        .unwrap_or_else(|| scene.disparity.clone());
    let clipped = |i: usize| {
        png.data[3 * i..3 * i + 3]
            .iter()
            .any(|&v| v as f64 >= drbokeh::highlight::CLIPPED_LEVEL)
    };
    let recovered = est.apply_with(
        &png,
        &disparity,
        scene.focus,
        scene.blur_k,
        &view.tone(),
        |region, g, tint| {
            let (mut interior, mut edge, mut light) = (0.0, 0.0, 0.0);
            let mut colour = [0.0f64; 3];
            // A clipped 4-neighbour of a region's pixel is in the same region.
            for &i in region.iter().filter(|&&i| clipped(i)) {
                let (x, y) = (i % w, i / w);
                let on_edge = x == 0
                    || y == 0
                    || x + 1 == w
                    || y + 1 == h
                    || [i - 1, i + 1, i - w, i + w].iter().any(|&j| !clipped(j));
                if on_edge {
                    edge += 1.0;
                } else {
                    interior += 1.0;
                }
                let v = &exr.data[3 * i..3 * i + 3];
                light += v.iter().fold(0.0f64, |m, &c| m.max(c as f64));
                for c in 0..3 {
                    colour[c] += v[c].max(0.0) as f64;
                }
            }
            if interior + edge == 0.0 {
                return (g, tint);
            }
            // interior g + edge g^p = light, g >= 1 (bisection in log g).
            let excess = |g: f64| interior * g + edge * g.powf(p) - light;
            let (mut lo, mut hi) = (1.0f64, 1000.0f64);
            if excess(lo) >= 0.0 {
                hi = 1.0;
            }
            for _ in 0..60 {
                let m = (lo * hi).sqrt();
                if excess(m) > 0.0 {
                    hi = m;
                } else {
                    lo = m;
                }
            }
            let tint = if with_tint {
                let m = colour.iter().fold(1e-12f64, |a, &b| a.max(b));
                colour.map(|c| c / m)
            } else {
                tint
            };
            (hi, tint)
        },
    )?;
    render_decomposed(preset, recovered, disparity, &cam, view)
}

/// Prototype of `auto:pool` (it lifts regions whose rim gain is below 1 to `kf` where the
/// library keeps them at 1): the default estimate with the cap set per scene from the
/// quantile `q` (0.5 when left out) of the regions' uncapped rim gains `k / x`:
/// `cap = clamp(c * quantile, lo, hi)`; mode `c,lo,hi[,kscale[,q]]` (`kscale`: the rim
/// constant also multiplied by `(cap / default max)^kscale`). Prints each scene's
/// quantiles with `SWEEP_SCENES`.
fn scene_pooled(
    mode: &str,
    dir: &std::path::Path,
    scene: &SceneInputs,
    preset: drbokeh::Preset,
) -> Result<drbokeh::image::Image<f32>, Box<dyn std::error::Error>> {
    let v: Vec<f64> = mode
        .split(',')
        .map(|t| t.parse::<f64>())
        .collect::<Result<_, _>>()?;
    let (c, lo, hi) = (v[0], v[1], v[2]);
    let kscale = v.get(3).copied().unwrap_or(0.0);
    let png = drbokeh::io::read_rgb(&dir.join("aif.png"))?;
    let cam = scene.camera();
    let view = View {
        photo_highlights: PhotoHighlights::PaperBoost,
        gamma: cam.gamma,
        preset,
        ..View::default()
    };
    let disparity = drbokeh::highlight::lights_at_farthest_depth(&png, &scene.disparity)
        .unwrap_or_else(|| scene.disparity.clone());
    let mut est = drbokeh::highlight::HighlightEstimate::DEFAULT;
    est.max_gain = 1000.0;
    est.pool_max = 1000.0;
    let mut raw = Vec::new();
    est.apply_with(
        &png,
        &disparity,
        scene.focus,
        scene.blur_k,
        &view.tone(),
        |_, g, t| {
            raw.push(g);
            (g, t)
        },
    )?;
    raw.sort_by(f64::total_cmp);
    let q = |f: f64| {
        raw.get(((raw.len() as f64 * f) as usize).min(raw.len().saturating_sub(1)))
            .copied()
            .unwrap_or(1.0)
    };
    let quant = v.get(4).copied().unwrap_or(0.5);
    let cap = (c * q(quant)).clamp(lo, hi);
    let kf = (cap / drbokeh::highlight::HighlightEstimate::DEFAULT.max_gain).powf(kscale);
    if std::env::var_os("SWEEP_SCENES").is_some() {
        println!(
            "{} regions {} q50 {:.2} q75 {:.2} q90 {:.2} cap {cap:.2}",
            dir.display(),
            raw.len(),
            q(0.5),
            q(0.75),
            q(0.9)
        );
    }
    let recovered = est.apply_with(
        &png,
        &disparity,
        scene.focus,
        scene.blur_k,
        &view.tone(),
        |_, g, t| ((g * kf).clamp(1.0, cap), t),
    )?;
    render_decomposed(preset, recovered, disparity, &cam, view)
}

/// The photo pipeline on a prepared photo (decomposed into the default number of layers),
/// clipped to [0, 1] as `bokeh.png` is.
fn render_decomposed(
    preset: drbokeh::Preset,
    rgb_encoded: drbokeh::image::Image<f32>,
    disparity: drbokeh::image::Image<f32>,
    cam: &drbokeh::camera::Camera,
    view: View,
) -> Result<drbokeh::image::Image<f32>, Box<dyn std::error::Error>> {
    let photo = drbokeh::scene::Photo {
        rgb_encoded,
        disparity,
        matte: None,
        layering: Layering::Decompose {
            max_layers: drbokeh::layering::DEFAULT_MAX_LAYERS,
        },
    };
    let mut img = render_photo_pipeline(preset, Source::Photo(photo), cam, view)?;
    img.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    Ok(img)
}

/// `aif.png` and `aif.exr` of a scene (display-encoded and linear).
type PngExr = (drbokeh::image::Image<f32>, drbokeh::image::Image<f32>);
fn read_png_exr(dir: &std::path::Path) -> Result<PngExr, Box<dyn std::error::Error>> {
    Ok((
        drbokeh::io::read_rgb(&dir.join("aif.png"))?,
        drbokeh::io::read_rgb(&dir.join("aif.exr"))?,
    ))
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}
