//! Arguments shared by every command that renders: scene input, camera, model, execution.

use anyhow::{bail, Context, Result};
use clap::Args;
use drbokeh::io::{self, DepthKind, DisparityOptions};
use drbokeh::{Aperture, Camera, LayerStack, Preset, Real, RenderSettings, Window};
use std::path::{Path, PathBuf};

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
    #[arg(long, value_name = "X,Y")]
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

    /// Boost bright, defocused highlights (brighter bokeh balls), as in the paper's tool.
    #[arg(long)]
    pub highlight: bool,

    /// Aperture shape: circle, polygon:N[:DEG] (N blades rotated by DEG degrees), a name
    /// (triangle, square, pentagon, hexagon, heptagon, octagon), or kernel:IMAGE (a grey
    /// image of the bokeh shape).
    #[arg(long, default_value = "circle", value_name = "SHAPE")]
    pub aperture: String,

    /// Model preset. physical (default): the paper's equation with layer coverage averaged
    /// over the receiver's soft aperture disc (radius K|d|, its circle of confusion) and a
    /// sharp scatter step centred on the circle of confusion (in-focus pixels stay sharp);
    /// +4.4 to +4.6 dB PSNR over paper, better on all 32 scenes of two ray-traced
    /// benchmark sets (docs/physical.md). paper: the published Dr.Bokeh model, exactly.
    #[arg(long, default_value = "physical", value_name = "NAME")]
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

    /// Execution engine. auto (default): fast in f32, threaded with --f64 (bit-exact, for
    /// checks). fast: skips taps that cannot contribute (agrees with the reference to ~1e-6
    /// in linear light) and has no practical window limit. threaded: every window tap, all
    /// cores. reference: plain loops, the oracle (slow).
    #[arg(long, default_value = "auto", value_name = "ENGINE")]
    pub engine: String,

    /// No progress bar or notes on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

impl ExecArgs {
    /// The engine to use: `auto` resolves to fast in f32 and threaded in f64.
    pub fn engine(&self) -> Result<drbokeh::Engine> {
        Ok(match self.engine.as_str() {
            "auto" if self.f64 => drbokeh::Engine::Threaded,
            "auto" => drbokeh::Engine::Fast,
            other => other.parse()?,
        })
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
    let (w, h) = (parse(w)?, parse(h)?);
    drbokeh::image::check_dimensions("--demo-size", w, h)?;
    drbokeh::budget::check_work("--demo-size", w as u64, h as u64, drbokeh::demo::LAYERS)?;
    Ok((w, h))
}

/// Loads the scene as a layer stack.
/// The display transfer the camera options and preset imply (used to read linear EXR
/// inputs into display encoding before rendering).
pub fn tone_for(c: &CameraArgs) -> Result<drbokeh::model::Tone> {
    let preset: Preset = c.preset.parse()?;
    Ok(drbokeh::model::Tone::new(
        preset.options().transfer,
        c.gamma,
        c.offset,
    ))
}

/// A scene as read from the command line: a ready stack, or an image and disparity map
/// to decompose into layers.
enum Parts<T> {
    Stack(LayerStack<T>),
    Decompose {
        rgb: drbokeh::Image<T>,
        disparity: drbokeh::Image<T>,
    },
}

/// The automatic decomposition's options from the scene arguments.
fn layering_options(a: &SceneArgs) -> drbokeh::layering::LayeringOptions {
    drbokeh::layering::LayeringOptions {
        max_layers: a
            .max_layers
            .unwrap_or(drbokeh::layering::DEFAULT_MAX_LAYERS),
        ..Default::default()
    }
}

/// Loads the scene for a render with these camera options. Unless `--single-layer`, an image
/// is decomposed for the render's focus and blur (cuts that cannot change the render are
/// left out); returns the stack and the decomposition's notes for the user (e.g. why it
/// fell back to a single layer).
pub fn load_scene_for_render<T: Real>(
    a: &SceneArgs,
    c: &CameraArgs,
    engine: drbokeh::Engine,
) -> Result<(LayerStack<T>, Vec<String>)> {
    match load_parts(a, tone_for(c)?)? {
        Parts::Stack(s) => Ok((s, vec![])),
        Parts::Decompose { rgb, disparity } => {
            // Focus and blur as they resolve on the single-layer stack (same disparity).
            let single = LayerStack::single(rgb.clone(), disparity.clone())?;
            let (settings, _) = settings_for(c, a, &single, engine)?;
            let mut opts = layering_options(a);
            opts.focus_hint = Some((
                settings.camera.focus_disparity,
                settings.camera.blur_k.abs(),
            ));
            let d = drbokeh::layering::layers_from_disparity(&rgb, &disparity, &opts)?;
            Ok((d.stack, d.notes))
        }
    }
}

fn load_parts<T: Real>(a: &SceneArgs, tone: drbokeh::model::Tone) -> Result<Parts<T>> {
    if a.demo {
        let (w, h) = parse_size(&a.demo_size)?;
        return Ok(Parts::Stack(drbokeh::demo::scene(w, h)));
    }
    if let Some(p) = &a.layers {
        return Ok(Parts::Stack(io::read_stack(p)?));
    }
    let Some(image_path) = &a.image else {
        bail!("no scene given: use --layers STACK.npz, --image IMAGE --disparity MAP, or --demo");
    };
    let (map_path, implied) = match (&a.disparity, &a.depth) {
        (Some(p), None) => (p, DepthKind::Disparity),
        (None, Some(p)) => (p, DepthKind::Depth),
        _ => bail!("--image needs a disparity map (--disparity MAP) or a depth map (--depth MAP)"),
    };
    let kind = match a.depth_kind {
        Some(DepthKindArg::Disparity) => DepthKind::Disparity,
        Some(DepthKindArg::Depth) => DepthKind::Depth,
        None => implied,
    };
    // The decomposition may make up to max_layers layers: check that work against the
    // input budget from the image's header, before reading anything.
    let layers = match (&a.alpha, a.single_layer) {
        (Some(_), _) => 2,
        (None, true) => 1,
        (None, false) => layering_options(a).max_layers as u64,
    };
    let (iw, ih) = io::image_dimensions(image_path, "image")?;
    drbokeh::budget::check_work(
        &image_path.display().to_string(),
        iw as u64,
        ih as u64,
        layers,
    )?;
    let mut rgb: drbokeh::Image<T> = io::read_rgb(image_path)?;
    if image_path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        // Linear EXR colour: encode with the same transfer the renderer will undo.
        for v in rgb.data.iter_mut() {
            *v = T::c(tone.encode(v.f64()).max(0.0));
        }
    }
    let disparity = io::read_disparity(
        map_path,
        DisparityOptions {
            kind,
            normalize: !a.no_normalize,
        },
    )?;
    check_same_size(image_path, &rgb, map_path, &disparity)?;
    match &a.alpha {
        None if a.single_layer => Ok(Parts::Stack(LayerStack::single(rgb, disparity)?)),
        None => Ok(Parts::Decompose { rgb, disparity }),
        Some(matte_path) => {
            let matte = io::read_matte(matte_path)?;
            check_same_size(image_path, &rgb, matte_path, &matte)?;
            Ok(Parts::Stack(drbokeh::layering::two_layers_from_matte(
                &rgb, &disparity, &matte,
            )?))
        }
    }
}

/// Fails unless two images (read from the named files) have the same size.
pub fn check_same_size<A, B>(
    a_path: &Path,
    a: &drbokeh::Image<A>,
    b_path: &Path,
    b: &drbokeh::Image<B>,
) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        bail!(
            "{}: size {}x{} does not match {} ({}x{})",
            b_path.display(),
            b.width,
            b.height,
            a_path.display(),
            a.width,
            a.height
        );
    }
    Ok(())
}

/// Resolves the camera, aperture and preset for a loaded stack. Returns the settings and,
/// when the automatic window clips the largest blur, a note for the user.
pub fn settings_for<T: Real>(
    c: &CameraArgs,
    scene: &SceneArgs,
    stack: &LayerStack<T>,
    engine: drbokeh::Engine,
) -> Result<(RenderSettings, Option<String>)> {
    let focus = match (c.focus, &c.focus_at) {
        (Some(f), _) => f,
        (None, Some(xy)) => {
            let (x, y) = xy
                .split_once(',')
                .and_then(|(x, y)| Some((x.trim().parse().ok()?, y.trim().parse().ok()?)))
                .with_context(|| {
                    format!(
                        "invalid parameter --focus-at: expected X,Y pixel coordinates, got '{xy}'"
                    )
                })?;
            stack.disparity_at(x, y)?
        }
        (None, None) if scene.demo => drbokeh::demo::DEMO_FOCUS,
        (None, None) => stack.disparity_at(stack.width / 2, stack.height / 2)?,
    };
    // A focus read from the map (not given with --focus) is the map's problem, not --focus's.
    let focus = match (c.focus, crate::values::unit_interval(focus)) {
        (None, None) => bail!(
            "the disparity {focus} at the {} lies outside [0, 1] and cannot be the focus; pass --focus, or let the map be normalised (no --no-normalize)",
            c.focus_at
                .as_ref()
                .map_or("centre pixel".to_string(), |xy| format!("--focus-at pixel {xy}"))
        ),
        (_, Some(f)) => f,
        (Some(f), None) => f,
    };
    let aperture = match c.aperture.strip_prefix("kernel:") {
        Some("") => {
            bail!("invalid parameter --aperture: kernel: needs an image, as in kernel:IMAGE")
        }
        Some(path) => {
            let grey = io::read_grey::<f64>(Path::new(path), "aperture kernel")?;
            Aperture::Kernel(
                drbokeh::aperture::KernelImage::new(&grey)
                    .map_err(|e| e.in_file(Path::new(path)))?,
            )
        }
        None => Aperture::parse_shape(&c.aperture)?,
    };
    let preset: Preset = c.preset.parse()?;
    let mut note = None;
    let window = match c.window {
        Some(l) => Window::from_size(l)?,
        None => {
            if !(0.0..=1.0).contains(&focus) || !focus.is_finite() {
                // Let validation below report it.
                Window::auto(1.0)
            } else {
                let needed = c.blur_k.abs() * stack.max_defocus(focus) + 1.0;
                let w = if engine == drbokeh::Engine::Fast {
                    Window::auto_unclipped(needed)
                } else {
                    Window::auto(needed)
                };
                if needed + drbokeh::camera::AUTO_WINDOW_MARGIN_PX > w.radius_px() as f64 + 0.5 {
                    note = Some(format!(
                        "largest blur radius is {needed:.1} px but the automatic window is capped at L = {} (R = {}); pass --window {} (or use the fast engine) for unclipped bokeh",
                        w.size(),
                        w.radius_px(),
                        2 * (needed + drbokeh::camera::AUTO_WINDOW_MARGIN_PX).ceil() as usize + 1
                    ));
                }
                w
            }
        }
    };
    let settings = RenderSettings {
        camera: Camera {
            focus_disparity: focus,
            blur_k: c.blur_k,
            window,
            gamma: c.gamma,
            offset: c.offset,
            highlight: c.highlight,
        },
        aperture,
        preset,
    };
    settings.validate()?;
    Ok((settings, note))
}
