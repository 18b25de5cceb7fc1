//! Ablation of the `physical` preset's options on the ray-traced benchmark.
//!
//! For every scene of a benchmark directory (`drbokeh benchmark make`), renders the
//! ground-truth layer stack (`layers.npz`: sRGB-encoded, highlights above white kept) with
//! the scene's K and focus (`scene.json`) under each model variant, clips the output to
//! [0, 1] and scores it against the ray-traced `bokeh.png` (sRGB, clipped) with PSNR and
//! SSIM. Variants with the gamma transfer decode with gamma 2.2, as `paper` does a photo. Prints per-scene scores, the means, and how often
//! each variant beats `paper`.
//!
//!   cargo run --release -p drbokeh --example physical_ablation -- /tmp/pb7
//!
//! The measurement reported in `docs/physical.md` used
//! `drbokeh benchmark make --scenes 16 --seed 7 --size 256 --spp 256 --output /tmp/pb7` (tuning)
//! and the same with `--seed 8` (held out).

use drbokeh::eval::metrics::{psnr, ssim};
use drbokeh::eval::report::SceneInputs;
use drbokeh::presets::{Coverage, CoverageRadius, Footprint, ModelOptions, ScatterStep, Transfer};
use drbokeh::{render, Aperture, Engine, NoProgress, RenderSettings};
use std::path::PathBuf;

fn variants() -> Vec<(&'static str, ModelOptions)> {
    let options = |coverage, coverage_radius, transfer, footprint, step| ModelOptions {
        coverage,
        coverage_radius,
        transfer,
        footprint,
        step,
    };
    use Coverage::{PaperBox, SoftDisc};
    use CoverageRadius::{CircleOfConfusion as Coc, Scatter};
    use Footprint::{HalfPixel, Pixel, Point};
    use ScatterStep::{Paper, Sharp};
    use Transfer::{Gamma, Srgb};
    vec![
        ("paper", ModelOptions::PAPER),
        (
            "+disc r(x)",
            options(SoftDisc, Scatter, Gamma, Pixel, Paper),
        ),
        ("+disc K|d|", options(SoftDisc, Coc, Gamma, Pixel, Paper)),
        ("+fp 0.5", options(SoftDisc, Coc, Gamma, HalfPixel, Paper)),
        ("+sharp", options(SoftDisc, Coc, Gamma, HalfPixel, Sharp)),
        ("physical", ModelOptions::PHYSICAL),
        ("phys+srgb", options(SoftDisc, Coc, Srgb, Point, Sharp)),
        ("srgb only", options(PaperBox, Scatter, Srgb, Pixel, Paper)),
        (
            "sharp only",
            options(PaperBox, Scatter, Gamma, Pixel, Sharp),
        ),
        ("phys, box", options(PaperBox, Scatter, Gamma, Point, Sharp)),
    ]
}

fn main() -> drbokeh::Result<()> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "/tmp/physbench".to_string()),
    );
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map_err(|e| drbokeh::Error::file(&dir, format!("cannot read: {e}")))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("scene.json").is_file())
        .collect();
    scenes.sort();
    let vs = variants();
    let mut scores = vec![Vec::new(); vs.len()];
    print!("{:<12} {:>6} {:>6}", "scene", "K", "f");
    for (name, _) in &vs {
        print!(" | {name:>10} psnr  ssim");
    }
    println!();
    for path in &scenes {
        let scene = SceneInputs::load(path)?;
        let camera = scene.camera();
        print!(
            "{:<12} {:>6.1} {:>6.3}",
            scene.name, camera.blur_k, camera.focus_disparity
        );
        for (v, (_, options)) in vs.iter().enumerate() {
            let settings = RenderSettings {
                camera: camera.clone(),
                aperture: Aperture::Circle,
                preset: drbokeh::Preset::Paper,
            }
            .with_model(*options);
            let mut out = render(&scene.layers, &settings, Engine::Fast, &NoProgress)?;
            out.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
            let (p, s) = (
                psnr(&out, &scene.ground_truth)?,
                ssim(&out, &scene.ground_truth)?,
            );
            print!(" | {:>15.2} {:.4}", p, s);
            scores[v].push((p, s));
        }
        println!();
    }
    let n = scenes.len() as f64;
    println!("\nvariant       mean PSNR  mean SSIM  dPSNR vs paper  wins vs paper (PSNR)");
    for (v, (name, _)) in vs.iter().enumerate() {
        let mp = scores[v].iter().map(|s| s.0).sum::<f64>() / n;
        let ms = scores[v].iter().map(|s| s.1).sum::<f64>() / n;
        let base = scores[0].iter().map(|s| s.0).sum::<f64>() / n;
        let wins = scores[v]
            .iter()
            .zip(&scores[0])
            .filter(|(a, b)| a.0 > b.0)
            .count();
        println!(
            "{name:<12} {mp:>10.2} {ms:>10.4} {:>+15.2} {wins:>10}/{}",
            mp - base,
            scenes.len()
        );
    }
    Ok(())
}
