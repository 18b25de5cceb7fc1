//! Arguments shared by every command that renders: scene input, camera, model, execution.

use anyhow::{bail, Context, Result};
use clap::Args;
use drbokeh::highlight::PhotoHighlights;
use drbokeh::io::{DepthKind, DisparityOptions};
use drbokeh::scene::{self, Focus, Layering, PhotoFiles, Scene, Source, View};
use drbokeh::Real;
use std::path::PathBuf;

/// Where the scene comes from.
#[derive(Args, Debug, Clone)]
pub struct SceneArgs {
    /// Layer stack (NPZ with rgb (N,H,W,3), alpha (N,H,W), disparity (N,H,W); front first).
    #[arg(long, value_name = "STACK.npz", conflicts_with_all = ["image", "demo"])]
    pub layers: Option<PathBuf>,

    /// All-in-focus image (PNG 8/16-bit, JPEG, TIFF, or linear EXR). Needs --disparity or --depth.
    #[arg(long, value_name = "IMAGE", conflicts_with = "demo")]
    pub image: Option<PathBuf>,

    /// Disparity map for --image (larger = nearer): 16-bit PNG, EXR, NPY, or NPZ key `data`.
    #[arg(long, value_name = "MAP", requires = "image", conflicts_with = "depth")]
    pub disparity: Option<PathBuf>,

    /// Metric depth map for --image (larger = farther); converted to disparity 1/z.
    #[arg(long, value_name = "MAP", requires = "image")]
    pub depth: Option<PathBuf>,

    /// What the map holds; overrides the choice implied by --disparity/--depth.
    #[arg(long, value_enum, value_name = "KIND")]
    pub depth_kind: Option<DepthKindArg>,

    /// Keep the map's values instead of min-max normalising disparity to [0, 1].
    #[arg(long)]
    pub no_normalize: bool,

    /// Alpha matte for --image (grey image, or the alpha of an RGBA PNG): renders the
    /// paper's two-layer stack (foreground = matte, background filled in behind it).
    #[arg(long, value_name = "MATTE", requires = "image")]
    pub alpha: Option<PathBuf>,

    /// With --image and no --alpha: render the image as one opaque layer instead of
    /// decomposing it into depth layers at disparity discontinuities (the default).
    #[arg(long, requires = "image", conflicts_with = "alpha")]
    pub single_layer: bool,

    /// With --image and no --alpha: the most depth layers the decomposition makes
    /// (default 5; see `drbokeh layers`).
    #[arg(long, value_name = "N", requires = "image", conflicts_with_all = ["alpha", "single_layer"])]
    pub max_layers: Option<usize>,

    /// Render the built-in procedural demo scene (no files needed).
    #[arg(long)]
    pub demo: bool,

    /// Size of the demo scene, WIDTHxHEIGHT.
    #[arg(long, value_name = "WxH", default_value = "640x426", requires = "demo")]
    pub demo_size: String,
}

/// What a depth/disparity map holds.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum DepthKindArg {
    /// Disparity, larger = nearer.
    Disparity,
    /// Metric depth, larger = farther.
    Depth,
}

/// Camera and model controls.
#[derive(Args, Debug, Clone)]
pub struct CameraArgs {
    /// Focus disparity in [0, 1] (the normalised disparity that is sharp).
    #[arg(long, value_name = "F", conflicts_with = "focus_at", value_parser = crate::values::focus)]
    pub focus: Option<f64>,

    /// Tap to focus: focus on the disparity at pixel X,Y (frontmost layer with alpha >= 0.5).
    /// Without --focus or --focus-at, the demo focuses on its subject and other inputs on
    /// the centre pixel.
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true)]
    pub focus_at: Option<String>,

    /// Blur strength K: blur radius in pixels per unit of relative disparity.
    #[arg(long = "blur", value_name = "K", default_value_t = 30.0)]
    pub blur_k: f64,

    /// Window size L (odd, L = 2R + 1): the largest neighbourhood a pixel gathers from.
    /// Default: just large enough for the largest blur radius in the image, at most 71
    /// (the paper's demo setting); larger blurs are clipped unless you ask for more (max 1001).
    #[arg(long, value_name = "L")]
    pub window: Option<usize>,

    /// Gamma of the display encoding (linear = (encoded + offset)^gamma).
    #[arg(long, default_value_t = 2.2)]
    pub gamma: f64,

    /// Offset of the display encoding.
    #[arg(long, default_value_t = 0.0)]
    pub offset: f64,

    /// Bright, defocused highlights (brighter bokeh balls; docs/highlights.md): `auto`
    /// (each clipped region of a photo recovered in linear light with a gain and tint
    /// estimated from its rim, its cap set from all the photo's regions together, no gain
    /// where a channel did not clip, plus a boost of the pixels above 0.9 by up to 1.25;
    /// the default for photos; auto:pool=0 without that pooling, auto:chan=0 with a gain
    /// there too, auto:paper=1 with the paper's boost on top instead), `paper`
    /// (the paper's 1 + 0.2 m boost; plain --highlight), `off`, or GAIN[:THRESHOLD] (one
    /// gain for every clipped region, e.g. 2:0.95). Without the flag: `auto` for --image,
    /// off for stacks and the demo.
    #[arg(long, value_name = "auto|paper|off|GAIN[:THRESHOLD]", num_args = 0..=1, default_missing_value = "paper")]
    pub highlight: Option<String>,

    /// Aperture shape: circle, polygon:N[:DEG] (N blades rotated by DEG degrees), a name
    /// (triangle, square, pentagon, hexagon, heptagon, octagon), or kernel:IMAGE (a grey
    /// image of the bokeh shape).
    #[arg(long, default_value = "circle", value_name = "SHAPE")]
    pub aperture: String,

    // Help generated from the library's list of presets (crate::names).
    #[arg(long, default_value = "physical", value_name = "NAME", help = crate::names::preset_help())]
    pub preset: String,
}

/// How the work is executed.
#[derive(Args, Debug, Clone)]
pub struct ExecArgs {
    /// Compute in double precision (slower; for exactness checks).
    #[arg(long)]
    pub f64: bool,

    /// Number of worker threads (default: all cores). Output does not depend on it.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,

    #[arg(long, default_value = "auto", value_name = "ENGINE", help = crate::names::engine_help())]
    pub engine: String,

    /// No progress bar or notes on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

impl ExecArgs {
    /// The engine to use: `auto` is [`drbokeh::Engine::auto`] (spans or taps per band and
    /// layer in f32, threaded in f64).
    pub fn engine(&self) -> Result<drbokeh::Engine> {
        Ok(drbokeh::Engine::parse_or_auto(&self.engine, self.f64)?)
    }

    /// Sets up the global thread pool.
    pub fn init_threads(&self) -> Result<()> {
        init_threads(self.threads)
    }
}

/// Sets up the global thread pool with `threads` workers (all cores when `None`).
pub fn init_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 || n > 1024 {
            bail!("invalid parameter --threads: must be between 1 and 1024, got {n}");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot start the thread pool")?;
    }
    Ok(())
}

fn parse_size(s: &str) -> Result<(usize, usize)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("invalid parameter --demo-size: expected WxH, got '{s}'"))?;
    let parse = |v: &str| -> Result<usize> {
        v.trim()
            .parse()
            .with_context(|| format!("invalid parameter --demo-size: bad number '{v}'"))
    };
    Ok((parse(w)?, parse(h)?))
}

impl SceneArgs {
    /// The scene these arguments name (files are read by [`scene::resolve`]).
    pub fn source<T: Real>(&self) -> Result<Source<T>> {
        if self.demo {
            let (width, height) = parse_size(&self.demo_size)?;
            return Ok(Source::Demo { width, height });
        }
        if let Some(p) = &self.layers {
            return Ok(Source::StackFile(p.clone()));
        }
        let Some(image) = &self.image else {
            bail!(
                "no scene given: use --layers STACK.npz, --image IMAGE --disparity MAP, or --demo"
            );
        };
        let (map, implied) = match (&self.disparity, &self.depth) {
            (Some(p), None) => (p, DepthKind::Disparity),
            (None, Some(p)) => (p, DepthKind::Depth),
            _ => bail!(
                "--image needs a disparity map (--disparity MAP) or a depth map (--depth MAP)"
            ),
        };
        let kind = match self.depth_kind {
            Some(DepthKindArg::Disparity) => DepthKind::Disparity,
            Some(DepthKindArg::Depth) => DepthKind::Depth,
            None => implied,
        };
        Ok(Source::PhotoFiles(PhotoFiles {
            image: image.clone(),
            map: map.clone(),
            map_options: DisparityOptions {
                kind,
                normalize: !self.no_normalize,
            },
            matte: self.alpha.clone(),
            layering: if self.single_layer {
                Layering::SingleLayer
            } else {
                Layering::Decompose {
                    max_layers: self
                        .max_layers
                        .unwrap_or(drbokeh::layering::DEFAULT_MAX_LAYERS),
                }
            },
        }))
    }
}

impl CameraArgs {
    /// The view these arguments state (the aperture kernel, if any, is read here).
    pub fn view(&self) -> Result<View> {
        let focus = match (self.focus, &self.focus_at) {
            (Some(f), _) => Focus::Disparity(f),
            (None, Some(xy)) => {
                let (x, y) = xy
                    .split_once(',')
                    .and_then(|(x, y)| Some((x.trim().parse().ok()?, y.trim().parse().ok()?)))
                    .with_context(|| {
                        format!(
                            "invalid parameter --focus-at: expected X,Y pixel coordinates, got '{xy}'"
                        )
                    })?;
                Focus::At { x, y }
            }
            (None, None) => Focus::Auto,
        };
        let (highlight, photo_highlights) = match self.highlight.as_deref() {
            None => (false, PhotoHighlights::default()),
            Some("paper") => (true, PhotoHighlights::PaperBoost),
            Some(spec) => (false, PhotoHighlights::parse(spec)?),
        };
        Ok(View {
            focus,
            blur_k: self.blur_k,
            window: self.window,
            gamma: self.gamma,
            offset: self.offset,
            highlight,
            photo_highlights,
            aperture: scene::parse_aperture(&self.aperture)?,
            preset: self.preset.parse()?,
        })
    }
}

/// Resolves the scene and view of a rendering command for `engine`: the stack (an image
/// decomposed for this focus and blur unless `--single-layer`), its settings and the
/// notes for the user.
pub fn resolve<T: Real>(
    scene_args: &SceneArgs,
    camera: &CameraArgs,
    engine: drbokeh::Engine,
) -> Result<Scene<T>> {
    let view = camera.view()?;
    Ok(scene::resolve(scene_args.source()?, &view, engine)?)
}

/// The command-line flag of a library parameter name (`focus` -> `--focus`), for the
/// parameters that are flags.
pub fn flag_for(parameter: &str) -> Option<&'static str> {
    Some(match parameter {
        "focus" => "--focus",
        "focus_at" => "--focus-at",
        "blur" => "--blur",
        "window" => "--window",
        "gamma" => "--gamma",
        "offset" => "--offset",
        "aperture" => "--aperture",
        "preset" => "--preset",
        "engine" => "--engine",
        "max_layers" => "--max-layers",
        "jump" => "--jump",
        "band" => "--band",
        "demo_size" => "--demo-size",
        "methods" => "--methods",
        "focal_planes" => "--focal-planes",
        "highlight" => "--highlight",
        "highlight_range" => "--highlight-range",
        "background_detail" => "--background-detail",
        "coarse_scales" => "--coarse-scales",
        "edge_sensitivity" => "--edge-sensitivity",
        "colour_bins" => "--colour-bins",
        "fine_iterations" => "--fine-iterations",
        "finest_scale" => "--finest-scale",
        "highlights" => "--clipped",
        "init" => "--init",
        "iterations" => "--iterations",
        "layer" => "--method",
        "layers" => "--methods",
        "losses" => "--losses",
        "lr" => "--lr",
        "lr_decay" => "--lr-decay",
        "median_radius" => "--median-radius",
        "median_sigma" => "--median-sigma",
        "min_improvement" => "--min-improvement",
        "optimiser" => "--optimiser",
        "occlusion_layers" => "--occlusion-layers",
        "redecompose" => "--redecompose-every",
        "param" => "--param",
        _ => return None,
    })
}

/// The one-line message of an error: its chain, outermost first, joined by `: `, with the
/// library's parameter names spelled as flags. A library error ends the chain (its message
/// already includes its source's).
pub fn describe(e: &anyhow::Error) -> String {
    let mut parts = Vec::new();
    for cause in e.chain() {
        match cause.downcast_ref::<drbokeh::Error>() {
            Some(drbokeh::Error::InvalidParameter { name, problem }) => {
                let name = flag_for(name).unwrap_or(name);
                parts.push(format!("invalid parameter {name}: {problem}"));
                break;
            }
            Some(drbokeh::Error::InvalidInput { what, problem }) => {
                let what = flag_for(what).unwrap_or(what);
                parts.push(format!("{what}: {problem}"));
                break;
            }
            Some(other) => {
                parts.push(other.to_string());
                break;
            }
            None => parts.push(cause.to_string()),
        }
    }
    parts.join(": ")
}
