//! `drbokeh dfd` and `drbokeh dfd-eval`: depth from defocus through a rendering layer.

use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::Args;
use drbokeh::dfd::experiment::{markdown_table, paper_combos, run_experiment, synthetic_pair};
use drbokeh::dfd::{estimate_disparity, DfdOptions, LossWeights, RenderLayer};
use drbokeh::{io, Progress, RenderSettings};
use std::path::PathBuf;

/// Camera and optimiser options shared by `dfd` and `dfd-eval`.
#[derive(Args, Debug, Clone)]
pub struct OptimiserArgs {
    /// Rendering layer to optimise through: drbokeh, gausspsf or aperture.
    #[arg(long, default_value = "drbokeh")]
    pub layer: String,
    /// Adam iterations per scale.
    #[arg(long, default_value_t = 200)]
    pub iterations: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 0.02)]
    pub lr: f64,
    /// Coarse-to-fine scales (1 = full resolution only).
    #[arg(long, default_value_t = 2)]
    pub scales: usize,
    /// Gamma of the display encoding.
    #[arg(long, default_value_t = 2.2)]
    pub gamma: f64,
}

/// Recover a disparity map from an (all-in-focus, defocused) pair by optimising through a
/// differentiable renderer (Adam on L = 0.5 L1 + 0.5 G + 10 HSSIM by default).
///
/// Example:
///   drbokeh dfd --all-in-focus aif.png --defocused blurred.png --focus 1 --blur 10 --output disp.png
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct DfdArgs {
    /// All-in-focus image.
    #[arg(long, value_name = "IMAGE")]
    pub all_in_focus: PathBuf,
    /// Defocused image of the same view.
    #[arg(long, value_name = "IMAGE")]
    pub defocused: PathBuf,
    /// Focus disparity of the defocused image, in [0, 1].
    #[arg(long, value_parser = crate::values::focus)]
    pub focus: f64,
    /// Blur strength K of the defocused image.
    #[arg(long = "blur", value_name = "K")]
    pub blur_k: f64,
    /// Loss terms, comma-separated: l1, smooth, hssim, ssim (a single 11-window SSIM).
    #[arg(long, default_value = "l1,smooth,hssim")]
    pub losses: String,
    #[command(flatten)]
    pub opt: OptimiserArgs,
    /// Output disparity: .png (16-bit), .npy (float32) or .exr.
    #[arg(long, short, value_name = "FILE")]
    pub output: PathBuf,
    /// JSON log of the loss curve (default: OUTPUT with .log.json).
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Preview PNG of the disparity (default: OUTPUT with .preview.png).
    #[arg(long, value_name = "FILE")]
    pub preview: Option<PathBuf>,
    /// Engine of the drbokeh layer's render and gradient. auto (default) and fast: the fast
    /// engine (only the taps that can contribute; gradients within 1e-5 of the exact ones'
    /// largest value). threaded: every window tap, the exact gradient. reference: the
    /// threaded adjoint.
    #[arg(long, default_value = "auto", value_name = "ENGINE")]
    pub engine: String,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

fn with_suffix(p: &std::path::Path, suffix: &str) -> PathBuf {
    let stem = p
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    p.with_file_name(format!("{stem}{suffix}"))
}

fn options(opt: &OptimiserArgs, focus: f64, blur_k: f64) -> Result<DfdOptions> {
    let mut settings = RenderSettings::paper(focus);
    settings.camera.blur_k = blur_k;
    settings.camera.gamma = opt.gamma;
    settings.validate()?;
    let layer: RenderLayer = opt.layer.parse()?;
    let mut o = DfdOptions::new(settings, layer);
    if opt.iterations == 0 || opt.iterations > 100_000 {
        bail!("invalid parameter --iterations: must be between 1 and 100000");
    }
    o.iterations = opt.iterations;
    o.learning_rate = opt.lr;
    o.scales = opt.scales;
    Ok(o)
}

pub fn run(a: &DfdArgs) -> Result<()> {
    let log_path = a
        .log
        .clone()
        .unwrap_or_else(|| with_suffix(&a.output, ".log.json"));
    let preview = a
        .preview
        .clone()
        .unwrap_or_else(|| with_suffix(&a.output, ".preview.png"));
    io::OutputPlan::new()
        .input(&a.all_in_focus, "--all-in-focus")
        .input(&a.defocused, "--defocused")
        .file(&a.output, "--output", &["png", "npy", "exr"])
        .file(&log_path, "--log", &[])
        .file(&preview, "--preview", crate::outputs::RENDER_EXTENSIONS)
        .check()?;
    let mut o = options(&a.opt, a.focus, a.blur_k)?;
    // dfd computes in f32: auto is the fast engine (as for render).
    o.engine = match a.engine.as_str() {
        "auto" => drbokeh::Engine::Fast,
        other => other.parse()?,
    };
    let (weights, terms) = LossWeights::from_terms(&a.losses)?;
    o.weights = weights;
    o.terms = terms;
    let (w, h) = io::image_dimensions(&a.all_in_focus, "image")?;
    drbokeh::budget::check_work(
        &a.all_in_focus.display().to_string(),
        w as u64,
        h as u64,
        drbokeh::budget::DFD_WORK_LAYERS,
    )?;
    let aif = io::read_rgb::<f32>(&a.all_in_focus)?;
    let target = io::read_rgb::<f32>(&a.defocused)?;
    if (aif.width, aif.height) != (target.width, target.height) {
        bail!(
            "{}: size {}x{} does not match {} ({}x{})",
            a.defocused.display(),
            target.width,
            target.height,
            a.all_in_focus.display(),
            aif.width,
            aif.height
        );
    }
    let bar = Bar::new("dfd", a.quiet);
    bar.start((o.iterations * o.scales) as u64);
    let (disp, log) = estimate_disparity(&aif, &target, &o, &mut |_| bar.advance(1))?;
    bar.finish();
    // All three outputs appear together, once all are written.
    let mut staging = io::Staging::new();
    staging.grey(&a.output, &disp)?;
    let json = serde_json::to_vec_pretty(&serde_json::json!({
        "layer": o.layer.name(),
        "weights": o.weights,
        "terms": o.terms,
        "iterations_per_scale": o.iterations,
        "learning_rate": o.learning_rate,
        "scales": o.scales,
        "focus": a.focus,
        "blur": a.blur_k,
        "log": log,
    }))?;
    staging.bytes(&log_path, &json)?;
    let rgb = drbokeh::Image::from_vec(
        disp.width,
        disp.height,
        3,
        disp.data.iter().flat_map(|&v| [v; 3]).collect(),
    )?;
    staging.output(&preview, &rgb, io::BitDepth::Eight, |v| v)?;
    staging.commit()?;
    if !a.quiet {
        let last = log.last().map(|e| e.loss).unwrap_or(f64::NAN);
        eprintln!(
            "drbokeh: disparity -> {} (final loss {last:.5}; log {}, preview {})",
            a.output.display(),
            log_path.display(),
            preview.display()
        );
    }
    Ok(())
}

/// Depth-from-defocus experiment on synthetic pairs rendered by the `paper` preset from a
/// known disparity: disparity MAE, RMSE and fraction within 1.25x for each rendering layer
/// and each loss combination (L1+G, L1+G+SSIM, L1+G+HSSIM).
///
/// Example:
///   drbokeh dfd-eval --pairs 4 --size 64 --out report/
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct DfdEvalArgs {
    /// Number of synthetic pairs.
    #[arg(long, default_value_t = 4)]
    pub pairs: usize,
    /// Side of each square pair, in pixels (at least 64 for HSSIM at two scales).
    #[arg(long, default_value_t = 64)]
    pub size: usize,
    /// Seed of the first pair.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Blur strength K of the pairs.
    #[arg(long = "blur", value_name = "K", default_value_t = 10.0)]
    pub blur_k: f64,
    /// Layers to evaluate, comma-separated (default: all three).
    #[arg(long, default_value = "drbokeh,gausspsf,aperture")]
    pub layers: String,
    #[command(flatten)]
    pub opt: OptimiserArgs,
    /// Output directory (results.json, results.md).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run_eval(a: &DfdEvalArgs) -> Result<()> {
    if a.pairs == 0 || a.pairs > 1000 {
        bail!("invalid parameter --pairs: must be between 1 and 1000");
    }
    if !(32..=1024).contains(&a.size) {
        bail!("invalid parameter --size: must be between 32 and 1024");
    }
    let layers = a
        .layers
        .split(',')
        .map(|s| {
            s.trim().parse::<RenderLayer>().map_err(|e| match e {
                // The parser speaks of dfd's --layer; here the option is --layers.
                drbokeh::Error::InvalidParameter { problem, .. } => {
                    drbokeh::Error::param("--layers", problem)
                }
                e => e,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let template = options(&a.opt, 1.0, a.blur_k)?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("{}: cannot create directory", a.out.display()))?;
    let pairs = (0..a.pairs)
        .map(|i| synthetic_pair::<f32>(a.seed + i as u64, a.size, &template.settings))
        .collect::<Result<Vec<_>, _>>()?;
    let combos = paper_combos();
    let bar = Bar::new("dfd-eval", a.quiet);
    bar.start((layers.len() * combos.len() * pairs.len()) as u64);
    let rows = run_experiment(&pairs, &layers, &combos, &template, &mut |_| bar.advance(1))?;
    bar.finish();
    let table = markdown_table(&rows);
    let md = a.out.join("results.md");
    let json_path = a.out.join("results.json");
    let json = serde_json::to_vec_pretty(&serde_json::json!({
        "pairs": a.pairs, "size": a.size, "seed": a.seed, "blur": a.blur_k, "focus": 1.0,
        "iterations_per_scale": template.iterations, "scales": template.scales, "learning_rate": template.learning_rate,
        "rows": rows,
    }))?;
    io::write_atomic(&json_path, |w| {
        use std::io::Write;
        w.write_all(&json)
            .map_err(|e| drbokeh::Error::file(&json_path, e.to_string()))
    })?;
    io::write_atomic(&md, |w| {
        use std::io::Write;
        w.write_all(table.as_bytes())
            .map_err(|e| drbokeh::Error::file(&md, e.to_string()))
    })?;
    print!("{table}");
    Ok(())
}
