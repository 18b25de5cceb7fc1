//! `drbokeh dfd` and `drbokeh dfd-eval`: depth from defocus through a rendering layer.

use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::Args;
use drbokeh::dfd::benchmark::{self, DfdBenchmarkConfig, DfdLayer, LossCombo, SceneGroup};
use drbokeh::dfd::experiment::{markdown_table, paper_combos, run_experiment, synthetic_pair};
use drbokeh::dfd::{
    estimate_disparity, report, DfdOptions, Highlights, Init, LayeredObjective, LossWeights,
    MedianRefine, Optimiser, Parameterisation, RenderLayer, DEFAULT_REDECOMPOSE_EVERY,
};
use drbokeh::{io, Preset, Progress, RenderSettings};
use std::path::{Path, PathBuf};

/// Optimiser options shared by `dfd` and `dfd-eval`.
#[derive(Args, Debug, Clone)]
pub struct OptimiserArgs {
    /// Finest scale optimised: scale S is the pair halved S times (pooled in linear light)
    /// with K halved S times; the result is upsampled to full resolution. Default: the
    /// finest whose iteration stays under a cost budget (pixels x disc area of the largest
    /// blur <= 5e6), so strongly blurred or large pairs are optimised at a coarser scale;
    /// where the largest blur there is under 3 px, finer while it is and an iteration stays
    /// under 3e7 (256 px pairs with blurs under 6 px: full resolution; docs/dfd.md "Small
    /// blurs").
    #[arg(long, value_name = "S")]
    pub finest_scale: Option<usize>,
    /// Coarser scales optimised first, each starting the next (coarse to fine). Default 0:
    /// on ray-traced pairs the coarse scales led away from the true depth (docs/dfd.md).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub coarse_scales: usize,
    /// Most Adam iterations at each coarse scale.
    #[arg(long, default_value_t = 100, value_name = "N")]
    pub iterations: usize,
    /// Most Adam iterations at the finest scale optimised. Default: 40, fewer where an
    /// iteration is costly (pairs optimised at full resolution with a small blur: about 25 at
    /// 256 px, docs/dfd.md "Small blurs"); given, at most that many, whatever they cost
    #[arg(long, value_name = "N")]
    pub fine_iterations: Option<usize>,
    /// Stop a scale after this many iterations without a 0.1 % lower loss (0: never).
    #[arg(long, default_value_t = 10, value_name = "N")]
    pub patience: usize,
    /// Learning rate at the coarsest scale (in units of the parameterisation's variable).
    #[arg(long, default_value_t = 0.1)]
    pub lr: f64,
    /// Factor on the learning rate at each finer scale.
    #[arg(long, default_value_t = 0.7, value_name = "F")]
    pub lr_decay: f64,
    /// How disparity stays in [0, 1]: sigmoid (of an unbounded variable) or clamped.
    #[arg(long = "param", default_value = "sigmoid", value_name = "P")]
    pub parameterisation: String,
    /// Optimiser: adam (per-pixel step sizes) or shared-adam (one step scale for the map:
    /// pixels the pair says little about move little).
    #[arg(long, default_value = "adam", value_name = "OPT")]
    pub optimiser: String,
    /// Pixels clipped (white) in the all-in-focus image: model (optimise their true
    /// brightness with the disparity), mask (leave every pixel they can reach out of the
    /// loss) or ignore. (Formerly --highlights, kept as an alias: render's --highlight is
    /// another thing.)
    #[arg(
        long = "clipped",
        alias = "highlights",
        default_value = "model",
        value_name = "MODE"
    )]
    pub highlights: String,
    /// Initial disparity: sweepN (default sweep9: render the pair at N constant
    /// disparities, keep per pixel the one that matches best over an edge-aware window),
    /// or a number in [0, 1] (everywhere).
    #[arg(long, default_value = "sweep9", value_name = "INIT")]
    pub init: String,
    /// Edge sensitivity s of the smoothness term, whose weight across a colour step dI is
    /// exp(-s |dI|): larger lets disparity edges form at colour edges (the paper: 1).
    #[arg(long, value_name = "S")]
    pub edge_sensitivity: Option<f64>,
    /// Window radius of the edge-aware weighted-median refinement of the result, as a
    /// fraction of the largest blur radius (default 1.5; 0 turns the refinement off).
    #[arg(long, value_name = "F")]
    pub median_radius: Option<f64>,
    /// Colour distance (display-encoded, RMS over channels) at which a neighbour's weight
    /// in the weighted median falls to exp(-1/2) (default 0.05).
    #[arg(long, value_name = "SIGMA")]
    pub median_sigma: Option<f64>,
    /// Second pass of the plane sweep: its candidates are rendered behind the first pass's
    /// estimate eroded by F times the largest blur radius, so pixels beside a nearer object
    /// are judged with the object in front of them (default 0.5; 0: one pass).
    #[arg(long, value_name = "F")]
    pub sweep_context: Option<f64>,
    /// Colour vote on the result, with N bins per channel (default 0: off; 16 was tuned):
    /// pixels whose all-in-focus colour falls in one of N^3 cubes take the median disparity
    /// of all of them, where at least half of the cube agrees. A prior that each surface has
    /// its own palette: it helps where that holds (the benchmark's billboards) and flattens
    /// a texture that spans several depths (docs/dfd.md).
    #[arg(long, value_name = "N")]
    pub colour_bins: Option<usize>,
    /// Layers of the occlusion-aware objective of the drbokeh method: the all-in-focus
    /// image is rendered as the layer stack that `render --image --disparity` makes of it
    /// at the current estimate (the hidden background filled in behind nearer layers), at
    /// most N layers (0 or 1: one opaque layer). GaussPSF and aperture ignore it.
    #[arg(long, value_name = "N")]
    pub occlusion_layers: Option<usize>,
    /// Iterations between re-decompositions of the occlusion-aware objective.
    #[arg(long, value_name = "N")]
    pub redecompose_every: Option<usize>,
    /// Gamma of the display encoding.
    #[arg(long, default_value_t = 2.2)]
    pub gamma: f64,
    /// Engine of the drbokeh layer's render and gradient: fast (default; gradients within
    /// 1e-5 of the exact ones' largest value), threaded (every window tap, the exact
    /// gradient) or reference.
    #[arg(long, default_value = "fast", value_name = "ENGINE")]
    pub engine: String,
}

impl OptimiserArgs {
    /// Applies these options to `o`.
    fn apply(&self, o: &mut DfdOptions) -> Result<()> {
        o.schedule.finest_scale = self.finest_scale;
        o.schedule.coarse_scales = self.coarse_scales;
        o.schedule.iterations = self.iterations;
        if let Some(n) = self.fine_iterations {
            o.schedule.fine_iterations = n;
            o.schedule.fine_cost_per_pixel = None;
        }
        o.schedule.patience = self.patience;
        o.schedule.learning_rate = self.lr;
        o.schedule.learning_rate_decay = self.lr_decay;
        o.parameterisation = self.parameterisation.parse::<Parameterisation>()?;
        o.optimiser = self.optimiser.parse::<Optimiser>()?;
        o.highlights = self.highlights.parse::<Highlights>()?;
        o.init = parse_init(&self.init)?;
        if let Some(e) = self.edge_sensitivity {
            o.edge_sensitivity = e;
        }
        if let Some(r) = self.median_radius {
            o.median = if r == 0.0 {
                None
            } else {
                Some(MedianRefine {
                    radius_blur_fraction: r,
                    sigma: o.median.map_or(0.05, |m| m.sigma),
                })
            };
        }
        if let Some(sigma) = self.median_sigma {
            match o.median.as_mut() {
                Some(m) => m.sigma = sigma,
                None => bail!("invalid parameter --median-sigma: the median refinement is off (--median-radius 0)"),
            }
        }
        if let Some(f) = self.sweep_context {
            o.sweep_context = (f != 0.0).then_some(f);
        }
        if let Some(b) = self.colour_bins {
            o.colour_vote = (b > 0).then_some(b);
        }
        if let Some(n) = self.occlusion_layers {
            o.layered = (n > 1).then(|| LayeredObjective {
                max_layers: n,
                every: o.layered.map_or(DEFAULT_REDECOMPOSE_EVERY, |l| l.every),
            });
        }
        if let Some(every) = self.redecompose_every {
            match o.layered.as_mut() {
                Some(l) => l.every = every,
                None => bail!("invalid parameter --redecompose-every: the occlusion-aware objective is off (--occlusion-layers 1)"),
            }
        }
        o.settings.camera.gamma = self.gamma;
        o.engine = self.engine.parse()?;
        o.validate()?;
        Ok(())
    }
}

fn parse_init(s: &str) -> Result<Init> {
    if let Some(n) = s.strip_prefix("sweep") {
        let n: usize = n.parse().with_context(|| {
            format!("invalid parameter --init: '{s}' (use sweepN, e.g. sweep9)")
        })?;
        return Ok(Init::Sweep(n));
    }
    let v: f64 = s.parse().with_context(|| {
        format!("invalid parameter --init: '{s}' (a disparity in [0, 1] or sweepN)")
    })?;
    Ok(Init::Constant(v))
}

/// Depth from defocus: recover disparity from an all-in-focus + defocused pair.
///
/// Recovers a disparity map from an (all-in-focus, defocused) pair of the same view by
/// optimising it through a differentiable renderer until the render of the all-in-focus
/// image matches the defocused one (supplement sec. 3.2).
///
/// You need the camera of the defocused image: its focus disparity and blur strength K
/// (blur radius in pixels per unit of disparity; `drbokeh benchmark make` writes both to
/// scene.json as "focus" and "blur"). Depth is only recoverable where the pair shows it:
/// textured regions that the blur changes. The sign of disparity - focus is not: with the
/// focus inside the scene, a pixel as far in front of it as another is behind blurs the
/// same. Focus on the nearest (focus 1) or the farthest (focus 0) object if you can.
///
/// Loss: 0.5 L1 + 20 G (edge-aware smoothness) + 10 HSSIM (SSIM at windows 3 to 31),
/// started from a plane sweep in two passes (the second renders each candidate plane
/// behind the first pass's nearer objects, so their edges do not spread over what lies
/// behind them), at the finest scale a cost budget allows; clipped
/// highlights of the all-in-focus image are modelled (their lost energy is found in the
/// defocused image); pixels the defocused image clips are left out. The result is refined
/// by an edge-aware weighted median (and, with --colour-bins 16, a colour vote: pixels of
/// one colour take their median disparity, right where each surface has its own colours,
/// wrong where a texture spans several depths). Writes the disparity
/// (near = 1), a confidence map (low within the blur of depth steps, where the estimate is
/// least reliable), optionally the sensitivity map (low where the pair carries no depth
/// information), a preview and a JSON log of every iteration and the time per scale.
///
/// Examples (a ray-traced pair with its camera, then a pair from a benchmark scene):
///   drbokeh trace examples/photo-scene.json -o photo-trace
///   drbokeh dfd --all-in-focus photo-trace/aif.png \
///       --defocused photo-trace/bokeh.png --focus 0.351 --blur 18.38 \
///       -o disp.png
///   drbokeh dfd --all-in-focus bench/scene_003/aif.png \
///       --defocused bench/scene_003/bokeh.png --focus 1 --blur 8.98 \
///       --method gausspsf -o disp.png
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct DfdArgs {
    /// All-in-focus image (PNG, JPEG, TIFF; display-encoded).
    #[arg(long, value_name = "IMAGE")]
    pub all_in_focus: PathBuf,
    /// Defocused image of the same view, same size.
    #[arg(long, value_name = "IMAGE")]
    pub defocused: PathBuf,
    /// Focus disparity of the defocused image, in [0, 1] (1 = nearest).
    #[arg(long, value_parser = crate::values::focus)]
    pub focus: f64,
    /// Blur strength K of the defocused image (pixels of blur radius per unit disparity).
    #[arg(long = "blur", value_name = "K")]
    pub blur_k: f64,
    /// Model preset of the drbokeh layer: physical (default; measured closer to a real
    /// lens, docs/physical.md) or paper (the published model).
    #[arg(long, default_value = "physical", value_name = "NAME")]
    pub preset: String,
    // Formerly --layer (kept as a hidden alias).
    #[arg(long = "method", alias = "layer", default_value = "drbokeh", value_name = "NAME", help = crate::names::dfd_method_help())]
    pub layer: String,
    /// Loss terms, comma-separated: l1, smooth, hssim, ssim (a single 11-window SSIM),
    /// each at its default weight (l1 0.5, smooth 20, hssim or ssim 10) or TERM=WEIGHT,
    /// e.g. l1,smooth=2,hssim.
    #[arg(long, default_value = "l1,smooth,hssim")]
    pub losses: String,
    /// Start from this disparity map (same size; PNG/NPY/EXR/TIFF, near = 1) instead of
    /// --init.
    #[arg(long, value_name = "FILE")]
    pub initial_disparity: Option<PathBuf>,
    #[command(flatten)]
    pub opt: OptimiserArgs,
    /// Output disparity: .png (16-bit), .npy (float32) or .exr.
    #[arg(long, short, value_name = "FILE")]
    pub output: PathBuf,
    /// Confidence map, in [0, 1] (default: OUTPUT with .confidence.png): 1 where the
    /// estimate can be trusted, falling to 0 within the blur radius of a depth step (the
    /// edges of near objects, structures thinner than their blur), where a single-layer
    /// fit spreads near objects over what lies behind them (docs/dfd.md, "Confidence").
    #[arg(long, value_name = "FILE")]
    pub confidence: Option<PathBuf>,
    /// Also write the sensitivity map, in [0, 1]: how much the render changes with the
    /// disparity; near 0 where the pair carries no depth information (flat or in-focus
    /// regions, filled in by the smoothness). Not written unless given.
    #[arg(long, value_name = "FILE")]
    pub sensitivity: Option<PathBuf>,
    /// JSON log: options, loss terms per iteration, time per scale (default: OUTPUT with
    /// .log.json).
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Preview PNG of the disparity (default: OUTPUT with .preview.png).
    #[arg(long, value_name = "FILE")]
    pub preview: Option<PathBuf>,
    /// No progress bar or summary (notes on the estimate's reliability, such as a blur too
    /// small at the scale optimised, are still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

fn with_suffix(p: &Path, suffix: &str) -> PathBuf {
    let stem = p
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    p.with_file_name(format!("{stem}{suffix}"))
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
    let confidence = a
        .confidence
        .clone()
        .unwrap_or_else(|| with_suffix(&a.output, ".confidence.png"));
    let mut plan = io::OutputPlan::new();
    plan.input(&a.all_in_focus, "--all-in-focus")
        .input(&a.defocused, "--defocused");
    if let Some(i) = &a.initial_disparity {
        plan.input(i, "--initial-disparity");
    }
    plan.file(&a.output, "--output", &["png", "npy", "exr"])
        .file(&confidence, "--confidence", &["png", "npy", "exr"]);
    if let Some(p) = &a.sensitivity {
        plan.file(p, "--sensitivity", &["png", "npy", "exr"]);
    }
    plan.file(&log_path, "--log", &[])
        .file(&preview, "--preview", &["png"])
        .check()?;

    let mut settings = RenderSettings::physical(a.focus);
    settings.preset = a.preset.parse::<Preset>()?;
    settings.camera.blur_k = a.blur_k;
    let mut o = DfdOptions::new(settings, a.layer.parse::<RenderLayer>()?);
    let (weights, terms) = LossWeights::from_terms(&a.losses)?;
    o.weights = weights;
    o.terms = terms;
    a.opt.apply(&mut o)?;
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
    if let Some(path) = &a.initial_disparity {
        let d: drbokeh::Image<f32> = io::read_grey(path, "initial disparity")?;
        if (d.width, d.height) != (aif.width, aif.height) {
            bail!(
                "{}: size {}x{} does not match {} ({}x{})",
                path.display(),
                d.width,
                d.height,
                a.all_in_focus.display(),
                aif.width,
                aif.height
            );
        }
        if let Some(i) = d.data.iter().position(|v| !(0.0..=1.0).contains(v)) {
            bail!(
                "{}: initial disparity {} at pixel x={}, y={} is outside [0, 1] \
                 (normalised disparity: 0 far, 1 near)",
                path.display(),
                d.data[i],
                i % d.width,
                i / d.width
            );
        }
        o.initial_disparity = Some(d);
    }
    let bar = Bar::new("dfd", a.quiet);
    let largest_blur_px = a.blur_k * a.focus.max(1.0 - a.focus);
    let finest = o
        .schedule
        .finest_for(aif.width, aif.height, largest_blur_px);
    bar.start(
        o.schedule.iterations as u64 * o.schedule.coarse_scales as u64
            + o.schedule.fine_iterations_for(finest, largest_blur_px) as u64,
    );
    let result = estimate_disparity(&aif, &target, &o, &mut |_| bar.advance(1))?;
    bar.finish();
    // All outputs appear together, once all are written.
    let json = serde_json::to_vec_pretty(&result.log)?;
    let rgb = drbokeh::Image::from_vec(
        result.disparity.width,
        result.disparity.height,
        3,
        result.disparity.data.iter().flat_map(|&v| [v; 3]).collect(),
    )?;
    let mut staging = io::Staging::new();
    staging.grey(&a.output, &result.disparity)?;
    staging.grey(&confidence, &result.confidence)?;
    if let Some(p) = &a.sensitivity {
        staging.grey(p, &result.sensitivity)?;
    }
    staging.output(&preview, &rgb, io::BitDepth::Eight, |v| v)?;
    staging.bytes(&log_path, &json)?;
    staging.commit()?;
    // Notes speak of the estimate's reliability: printed even with --quiet.
    for note in &result.log.notes {
        eprintln!("drbokeh: note: {note}");
    }
    if !a.quiet {
        let last = result
            .log
            .entries
            .last()
            .map(|e| e.loss)
            .unwrap_or(f64::NAN);
        let scales: Vec<String> = result
            .log
            .scales
            .iter()
            .map(|s| {
                format!(
                    "{}x{}: {} it, {:.3} s/it",
                    s.width, s.height, s.iterations, s.seconds_per_iteration
                )
            })
            .collect();
        eprintln!(
            "drbokeh: disparity -> {} in {:.1} s (final loss {last:.5}; {}); confidence {}, log {}, preview {}",
            a.output.display(),
            result.log.seconds,
            scales.join(", "),
            confidence.display(),
            log_path.display(),
            preview.display()
        );
    }
    Ok(())
}

/// Depth-from-defocus experiment: rendering layers x loss combinations, scored against the truth.
///
/// Rendering layers (--methods) x loss combinations (L1+G, L1+G+SSIM, L1+G+HSSIM),
/// scored against the true disparity.
///
/// --benchmark DIR: ray-traced pairs made by `drbokeh benchmark make` (aif.png, bokeh.png,
/// scene.json's K and focus; truth disparity.npy). Rows: drbokeh with preset physical and
/// paper, GaussPSF and aperture compositing, each with the three loss combinations, and the
/// constant guess (the median of the true disparity). Per scene and per group: MAE, RMSE,
/// delta < 1.25 (metric depth ratio), MAE inside and outside the foreground masks, MAE
/// where the run is confident. Scenes whose focus lies inside their depth range (the sign
/// of disparity - focus is ambiguous) are reported apart. Writes results.json, results.md,
/// index.html (estimates beside the truth) and scenes/<scene>/*.png.
///
/// --synthetic: pairs rendered by our own renderer from a known disparity (the sanity
/// check: the renderer recovers what it rendered).
///
/// Examples:
///   drbokeh dfd-eval --synthetic --pairs 2 --size 64 --methods drbokeh \
///       --losses hssim -o report
///   drbokeh benchmark make --scenes 24 --seed 201 --size 256 --spp 256 \
///       -o bench
///   drbokeh dfd-eval --benchmark bench --groups determined \
///       --methods physical,gausspsf -o report
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct DfdEvalArgs {
    /// Ray-traced benchmark directory.
    #[arg(
        long,
        value_name = "DIR",
        conflicts_with = "synthetic",
        required_unless_present = "synthetic"
    )]
    pub benchmark: Option<PathBuf>,
    /// Synthetic pairs rendered by our renderer instead.
    #[arg(long)]
    pub synthetic: bool,
    // Formerly --layers (kept as a hidden alias; render's --layers is a stack file).
    #[arg(long = "methods", alias = "layers", value_name = "LIST", help = crate::names::dfd_eval_methods_help())]
    pub layers: Option<String>,
    /// Loss combinations, comma-separated: l1g (L1+G), ssim (L1+G+SSIM), hssim
    /// (L1+G+HSSIM), or all.
    #[arg(long, default_value = "all", value_name = "LIST")]
    pub losses: String,
    /// Benchmark: scene groups to run, comma-separated: determined (near or far focus,
    /// largest CoC >= 6 px), small (near or far focus, smaller blur), ambiguous (focus
    /// inside the depth range), or all.
    #[arg(long, default_value = "all", value_name = "LIST")]
    pub groups: String,
    /// Benchmark: at most this many scenes (after the group filter).
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
    /// Synthetic: number of pairs.
    #[arg(long, default_value_t = 4)]
    pub pairs: usize,
    /// Synthetic: side of each square pair, in pixels.
    #[arg(long, default_value_t = 64)]
    pub size: usize,
    /// Synthetic: seed of the first pair.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Synthetic: blur strength K of the pairs.
    #[arg(long = "blur", value_name = "K", default_value_t = 10.0)]
    pub blur_k: f64,
    /// Synthetic: preset that renders the pairs and that the drbokeh layer optimises with.
    #[arg(long, default_value = "physical", value_name = "NAME")]
    pub preset: String,
    #[command(flatten)]
    pub opt: OptimiserArgs,
    /// Output directory (created if missing). --out is an alias.
    #[arg(long = "output", short = 'o', alias = "out", value_name = "DIR")]
    pub out: PathBuf,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

fn parse_groups(list: &str) -> Result<Vec<SceneGroup>> {
    if list.trim() == "all" {
        return Ok(SceneGroup::ALL.to_vec());
    }
    list.split(',')
        .map(|g| match g.trim() {
            "determined" => Ok(SceneGroup::Determined),
            "small" => Ok(SceneGroup::DeterminedSmallBlur),
            "ambiguous" => Ok(SceneGroup::SignAmbiguous),
            other => bail!(
                "invalid parameter --groups: unknown group '{other}' (determined, small, ambiguous or all)"
            ),
        })
        .collect()
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    io::write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(bytes)
            .map_err(|e| drbokeh::Error::file(path, e.to_string()))
    })?;
    Ok(())
}

pub fn run_eval(a: &DfdEvalArgs) -> Result<()> {
    match &a.benchmark {
        Some(dir) => run_benchmark(a, dir),
        None => run_synthetic(a),
    }
}

fn create_out(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("{}: cannot create directory", out.display()))
}

fn run_benchmark(a: &DfdEvalArgs, dir: &Path) -> Result<()> {
    let layers = DfdLayer::parse_list(a.layers.as_deref().unwrap_or("all"))?;
    let losses = LossCombo::parse_list(&a.losses)?;
    let groups = parse_groups(&a.groups)?;
    if a.limit == Some(0) {
        bail!("invalid parameter --limit: must be at least 1");
    }
    let mut template = DfdOptions::new(RenderSettings::physical(1.0), RenderLayer::DrBokeh);
    a.opt.apply(&mut template)?;
    let config = DfdBenchmarkConfig {
        benchmark: dir.to_path_buf(),
        layers,
        losses,
        template,
        groups,
        limit: a.limit,
    };
    // Load (and so check) every selected scene before creating anything.
    benchmark::select_scenes(&config)?;
    create_out(&a.out)?;
    let bar = Bar::new("dfd-eval", a.quiet);
    let scenes_dir = a.out.join("scenes");
    let report = benchmark::evaluate(&config, &bar, &mut |pictures| {
        report::write_scene_pictures(&scenes_dir.join(&pictures.0.inputs.name), pictures)
    })?;
    bar.finish();
    let methods = benchmark::methods(&config);
    report::write_report(&a.out, &report, &methods)?;
    print!("{}", report::results_markdown(&report));
    Ok(())
}

fn run_synthetic(a: &DfdEvalArgs) -> Result<()> {
    if a.pairs == 0 || a.pairs > 1000 {
        bail!("invalid parameter --pairs: must be between 1 and 1000");
    }
    if !(32..=1024).contains(&a.size) {
        bail!("invalid parameter --size: must be between 32 and 1024");
    }
    let layers = a
        .layers
        .as_deref()
        .unwrap_or("drbokeh,gausspsf,aperture")
        .split(',')
        .map(|s| {
            s.trim().parse::<RenderLayer>().map_err(|e| match e {
                // The parser speaks of dfd's --method; here the option is --methods.
                drbokeh::Error::InvalidParameter { problem, .. } => {
                    drbokeh::Error::param("--methods", problem)
                }
                e => e,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut settings = RenderSettings::physical(1.0);
    settings.preset = a.preset.parse::<Preset>()?;
    settings.camera.blur_k = a.blur_k;
    let mut template = DfdOptions::new(settings, RenderLayer::DrBokeh);
    a.opt.apply(&mut template)?;
    let combos: Vec<_> = {
        let wanted = LossCombo::parse_list(&a.losses)?;
        paper_combos()
            .into_iter()
            .filter(|c| wanted.iter().any(|w| w.name() == c.name))
            .collect()
    };
    let pairs = (0..a.pairs)
        .map(|i| synthetic_pair::<f32>(a.seed + i as u64, a.size, &template.settings))
        .collect::<Result<Vec<_>, _>>()?;
    create_out(&a.out)?;
    let bar = Bar::new("dfd-eval", a.quiet);
    bar.start((layers.len() * combos.len() * pairs.len()) as u64);
    let rows = run_experiment(&pairs, &layers, &combos, &template, &mut |_| bar.advance(1))?;
    bar.finish();
    let table = markdown_table(&rows);
    let json = serde_json::to_vec_pretty(&serde_json::json!({
        "pairs": a.pairs, "size": a.size, "seed": a.seed, "blur": a.blur_k, "focus": 1.0,
        "preset": template.settings.preset.name(),
        "options": drbokeh::dfd::RunOptions::of(&template),
        "rows": rows,
    }))?;
    write_file(&a.out.join("results.json"), &json)?;
    write_file(&a.out.join("results.md"), table.as_bytes())?;
    print!("{table}");
    Ok(())
}
