//! `drbokeh eval` (every method on a ray-traced benchmark, scored and reported) and
//! `drbokeh gallery` (a refocus sweep of arbitrary image + disparity pairs).

use crate::progress::Bar;
use anyhow::{bail, Result};
use clap::Args;
use drbokeh::eval::gallery::{self, GalleryOptions};
use drbokeh::eval::report::{self, Method};
use std::path::PathBuf;
use std::time::Instant;

/// Evaluate every method on a ray-traced benchmark: scores, tables, plots, HTML gallery.
///
/// Methods: photo-physical and photo-paper (the headline: `drbokeh render --image aif.png
/// --disparity disparity.npy` as a user runs it), gather, scatter, gausspsf, layered
/// (classical baselines on the all-in-focus image + disparity), paper-aif and physical-aif
/// (a preset on the same single layer), layered-gt, paper-gt and physical-gt (on the
/// ground-truth layer stack). Every method uses the scene's K and focus from scene.json.
///
/// Writes into REPORT: results.json and results.csv (per scene and method: PSNR, SSIM,
/// MS-SSIM, time), summary.md (mean and standard deviation per method and per blur size),
/// psnr_vs_blur.svg, ssim_vs_blur.svg, ms_ssim_vs_blur.svg, index.html (a gallery with
/// every render and its error map; the folder is self-contained) and scenes/<scene>/*.
///
/// Examples:
///   drbokeh benchmark make --scenes 4 --size 128 --spp 64 -o bench
///   drbokeh eval --benchmark bench -o report
///   drbokeh eval --benchmark bench --methods photo-physical,scatter \
///       --limit 2 -o report
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct EvalArgs {
    /// Benchmark directory (from `drbokeh benchmark make`): scene subdirectories.
    #[arg(long, value_name = "DIR")]
    pub benchmark: PathBuf,

    /// Report directory (created if missing; existing report files are replaced). --out is
    /// an alias.
    #[arg(long = "output", short = 'o', alias = "out", value_name = "REPORT")]
    pub out: PathBuf,

    #[arg(long, default_value = "all", value_name = "LIST", help = crate::names::eval_methods_help())]
    pub methods: String,

    /// Evaluate only the first N scenes (sorted by name).
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,

    /// Do not write the per-scene pictures (index.html then shows broken images).
    #[arg(long)]
    pub no_images: bool,

    /// Number of worker threads (default: all cores). Scores do not depend on it.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,

    /// No progress bar or summary on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Refocus gallery of image + disparity pairs: a focal sweep, methods side by side (HTML).
///
/// Inputs: DIR holds pairs NAME.png (or .jpg/.jpeg/.tif/.tiff/.exr) and NAME.disp.png (or
/// .disp.tif/.disp.exr/.disp.npy/.disp.npz): a disparity map, larger = nearer, min-max
/// normalised. Focal planes are spread evenly over the normalised disparity, far to near.
///
/// Writes REPORT/index.html and REPORT/NAME/{input.jpg, disparity.png, fNN_<method>.jpg}.
///
/// Examples:
///   drbokeh gallery --images examples --focal-planes 3 -o gallery
///   drbokeh gallery --images photos --methods photo-physical,scatter \
///       --blur 20 -o gallery
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct GalleryArgs {
    /// Folder of NAME.png + NAME.disp.png pairs.
    #[arg(long, value_name = "DIR")]
    pub images: PathBuf,

    /// Number of focal planes in the sweep.
    #[arg(long, default_value_t = 10, value_name = "N")]
    pub focal_planes: usize,

    /// Output directory (created if missing). --out is an alias.
    #[arg(long = "output", short = 'o', alias = "out", value_name = "REPORT")]
    pub out: PathBuf,

    /// Blur strength K: CoC radius in pixels per unit of normalised disparity.
    #[arg(long, default_value_t = 30.0, value_name = "K")]
    pub blur: f64,

    /// Display gamma of the images.
    #[arg(long, default_value_t = 2.2)]
    pub gamma: f64,

    #[arg(long, default_value = "all", value_name = "LIST", help = crate::names::gallery_methods_help())]
    pub methods: String,

    /// Number of worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,

    /// No progress bar or summary on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

/// `drbokeh eval`.
pub fn run_eval(a: &EvalArgs) -> Result<()> {
    crate::args::init_threads(a.threads)?;
    let methods = Method::parse_list(&a.methods)?;
    if a.limit == Some(0) {
        bail!("invalid parameter --limit: must be at least 1");
    }
    // Fails early, with a clear message, on a missing or empty benchmark.
    let scenes = report::list_scenes(&a.benchmark)?;
    let count = a.limit.map_or(scenes.len(), |n| n.min(scenes.len()));
    drbokeh::io::OutputPlan::new()
        .input(&a.benchmark, "--benchmark")
        .dir(&a.out, "--output", drbokeh::io::DirMode::Merge)
        .check()?;
    // The whole report is written into a temporary tree, merged into --out only once
    // every scene has been evaluated (a corrupt scene leaves nothing behind).
    let mut staging = drbokeh::io::Staging::new();
    let root = staging.tree(&a.out)?;
    let start = Instant::now();
    let bar = Bar::new("evaluating", a.quiet);
    let images = (!a.no_images).then_some(root.as_path());
    let rep = report::evaluate_benchmark(&a.benchmark, &methods, images, a.limit, &bar);
    bar.finish();
    let rep = rep?;
    report::write_report(&root, &rep)?;
    staging.commit()?;
    if !a.quiet {
        eprintln!(
            "drbokeh: evaluated {} methods on {count} scenes in {:.1} s -> {}",
            methods.len(),
            start.elapsed().as_secs_f64(),
            a.out.display()
        );
        eprint!("{}", summary_lines(&rep));
    }
    Ok(())
}

fn summary_lines(rep: &report::Report) -> String {
    let mut rows: Vec<_> = rep.summary.overall.iter().collect();
    rows.sort_by(|a, b| {
        b.psnr_mean
            .unwrap_or(f64::NEG_INFINITY)
            .total_cmp(&a.psnr_mean.unwrap_or(f64::NEG_INFINITY))
    });
    rows.iter()
        .map(|r| {
            format!(
                "  {:<11} PSNR {:>6} dB  SSIM {:>6}  MS-SSIM {:>6}\n",
                r.method,
                r.psnr_mean.map_or("-".into(), |v| format!("{v:.2}")),
                r.ssim_mean.map_or("-".into(), |v| format!("{v:.4}")),
                r.ms_ssim_mean.map_or("-".into(), |v| format!("{v:.4}")),
            )
        })
        .collect()
}

/// `drbokeh gallery`.
pub fn run_gallery(a: &GalleryArgs) -> Result<()> {
    crate::args::init_threads(a.threads)?;
    let methods = Method::parse_list(&a.methods)?;
    let methods: Vec<Method> = if a.methods.split(',').any(|m| m.trim() == "all") {
        gallery::gallery_methods()
    } else {
        methods
    };
    let (inputs, unpaired) = gallery::find_inputs(&a.images)?;
    if !a.quiet {
        for u in &unpaired {
            eprintln!(
                "drbokeh: skipping {} (no NAME.disp.png / .npy / .exr beside it)",
                u.display()
            );
        }
    }
    let options = GalleryOptions {
        focal_planes: a.focal_planes,
        blur_k: a.blur,
        gamma: a.gamma,
        methods,
    };
    drbokeh::io::OutputPlan::new()
        .input(&a.images, "--images")
        .dir(&a.out, "--output", drbokeh::io::DirMode::Merge)
        .check()?;
    // Written into a temporary tree, merged into --out only once complete.
    let mut staging = drbokeh::io::Staging::new();
    let root = staging.tree(&a.out)?;
    let start = Instant::now();
    let bar = Bar::new("gallery", a.quiet);
    let result = gallery::make_gallery(&inputs, &root, &options, &bar);
    bar.finish();
    result?;
    staging.commit()?;
    if !a.quiet {
        eprintln!(
            "drbokeh: gallery of {} inputs x {} focal planes x {} methods in {:.1} s -> {}",
            inputs.len(),
            a.focal_planes,
            options.methods.len(),
            start.elapsed().as_secs_f64(),
            a.out.join("index.html").display()
        );
    }
    Ok(())
}
