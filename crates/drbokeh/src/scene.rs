//! From what the user gave to what a render needs: the one path by which the CLI, the
//! Python module and other front ends turn a scene ([`Source`]: a stack file, an image +
//! disparity or depth map (+ optional matte), arrays in memory, or the demo) and a view
//! ([`View`]: a focus value or point, blur, window, tone, aperture, preset) into a
//! [`Scene`]: the [`LayerStack`], the [`RenderSettings`] and notes for the user.
//!
//! ```
//! use drbokeh::scene::{self, Focus, Source, View};
//! let view = View { focus: Focus::At { x: 40, y: 30 }, blur_k: 20.0, ..View::default() };
//! let s = scene::resolve::<f32>(Source::Demo { width: 80, height: 60 }, &view, drbokeh::Engine::Fast)
//!     .unwrap();
//! assert_eq!(s.stack.layers.len(), 3);
//! assert_eq!(s.settings.camera.blur_k, 20.0);
//! ```
//!
//! Policy that lives here rather than in a front end:
//! - **Focus.** [`Focus::At`] takes the disparity of the frontmost layer whose alpha is at
//!   least 0.5 at that pixel; [`Focus::Auto`] is the demo's subject for the demo and the
//!   centre pixel otherwise.
//! - **Window.** Without an explicit size, the automatic window ([`Window::automatic`])
//!   holds the largest scatter radius of the stack ([`model::largest_scatter_radius_px`]); it is capped at
//!   [`crate::camera::MAX_AUTO_WINDOW_SIZE`] except for the fast engine, whose cost follows
//!   the blur radii rather than the window, and a note says when the cap clips the blur.
//! - **Photos.** An image and a disparity map are decomposed into depth layers for the
//!   render's focus and blur (cuts that cannot change the render are left out,
//!   [`crate::layering::layers_from_disparity`]); with a matte, the paper's two layers; or
//!   one opaque layer on request ([`Layering::SingleLayer`]). Linear (EXR) colour is
//!   display-encoded with the transfer the renderer will undo ([`read_display_image`]).
//! - **Highlights.** A display-encoded photo's clipped highlights are recovered before the
//!   decomposition by default (each clipped region's gain and tint read from its rim), and
//!   the model's highlight boost is applied on top with its photo constants
//!   ([`View::photo_highlights`], [`crate::model::HighlightBoost::PHOTO`], docs/highlights.md).
//!
//! - **Budget.** The work a source implies (demo size, or the image's size from its header
//!   times the layers its decomposition may make) is checked against the input budget
//!   ([`crate::budget`]) before anything is read or generated.
//! - **Focus.** A focus within [`UNIT_INTERVAL_SLACK`] of [0, 1] (floating-point rounding,
//!   as in a benchmark's `scene.json`) is snapped into it; a focus read from the map that
//!   lies outside [0, 1] is reported as the map's problem, not the focus parameter's.
//!
//! Errors name the parameter as this module spells it (`focus`, `focus_at`, `blur`,
//! `window`, `gamma`, `offset`, `aperture`, `preset`, `max_layers`, `demo_size`); front ends
//! map those names to their own (the CLI to `--focus`, ...).

use crate::aperture::{Aperture, KernelImage};
use crate::budget;
use crate::camera::{Camera, Window, WindowCap};
use crate::demo;
use crate::engine::Engine;
use crate::highlight::PhotoHighlights;
use crate::image::{check_dimensions, Image};
use crate::io::{self, DepthKind, DisparityOptions};
use crate::layering::{self, LayeringOptions};
use crate::model::{self, HighlightBoost, Tone};
use crate::presets::{Preset, RenderSettings};
use crate::stack::{Layer, LayerStack};
use crate::{Error, Real, Result};
use std::path::{Path, PathBuf};

/// Where the scene comes from.
#[derive(Clone, Debug)]
pub enum Source<T> {
    /// A layer stack file (NPZ: `rgb` (N,H,W,3), `alpha` (N,H,W), `disparity` (N,H,W)).
    StackFile(PathBuf),
    /// A layer stack in memory.
    Stack(LayerStack<T>),
    /// An image and a disparity or depth map in files, with an optional matte.
    PhotoFiles(PhotoFiles),
    /// An image and its disparity in memory, with an optional matte.
    Photo(Photo<T>),
    /// The built-in procedural demo scene ([`crate::demo`]) at this size in pixels.
    Demo {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
}

/// How an image + disparity pair without a matte becomes layers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layering {
    /// One opaque layer: the image at its disparity.
    SingleLayer,
    /// Depth layers cut at disparity discontinuities, at most `max_layers`
    /// ([`crate::layering::layers_from_disparity`]), made for the render's focus and blur.
    Decompose {
        /// The most layers made (1 to [`crate::layering::MAX_LAYERS_LIMIT`]).
        max_layers: usize,
    },
}

impl Default for Layering {
    fn default() -> Self {
        Layering::Decompose {
            max_layers: layering::DEFAULT_MAX_LAYERS,
        }
    }
}

/// An image + disparity (or depth) map in files, with an optional alpha matte.
#[derive(Clone, Debug, PartialEq)]
pub struct PhotoFiles {
    /// All-in-focus image: PNG (8/16-bit), JPEG, TIFF (display-encoded) or EXR (linear).
    pub image: PathBuf,
    /// Disparity or depth map: 16-bit PNG, EXR, NPY or NPZ key `data`.
    pub map: PathBuf,
    /// How the map becomes normalised disparity (what it holds; min-max normalised or not).
    pub map_options: DisparityOptions,
    /// Alpha matte (grey image, the alpha of an RGBA PNG, or NPY): the paper's two layers.
    pub matte: Option<PathBuf>,
    /// Without a matte: one layer, or a decomposition.
    pub layering: Layering,
}

impl PhotoFiles {
    /// An image and a map holding `kind`, normalised, no matte, decomposed by default.
    pub fn new(image: impl Into<PathBuf>, map: impl Into<PathBuf>, kind: DepthKind) -> Self {
        PhotoFiles {
            image: image.into(),
            map: map.into(),
            map_options: DisparityOptions {
                kind,
                normalize: true,
            },
            matte: None,
            layering: Layering::default(),
        }
    }
}

/// An image and its disparity in memory, with an optional matte (all the same size).
#[derive(Clone, Debug, PartialEq)]
pub struct Photo<T> {
    /// Display-encoded colour, 3 channels.
    pub rgb_encoded: Image<T>,
    /// Normalised disparity (larger = nearer), 1 channel.
    pub disparity: Image<T>,
    /// Alpha matte of the foreground, 1 channel.
    pub matte: Option<Image<T>>,
    /// Without a matte: one layer, or a decomposition.
    pub layering: Layering,
}

/// Which disparity is in focus.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Focus {
    /// This normalised disparity, in [0, 1].
    Disparity(f64),
    /// The disparity seen at pixel (x, y): the frontmost layer with alpha >= 0.5 there.
    At {
        /// Column.
        x: usize,
        /// Row.
        y: usize,
    },
    /// The demo's subject for the demo scene, the centre pixel otherwise.
    #[default]
    Auto,
}

/// The camera and model as the user states them; [`resolve`] turns them into
/// [`RenderSettings`] for a stack.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// Focus.
    pub focus: Focus,
    /// Blur strength K: blur radius in pixels per unit of relative disparity.
    pub blur_k: f64,
    /// Window size `L` (odd); `None`: automatic (see the module documentation).
    pub window: Option<usize>,
    /// Gamma of the display encoding.
    pub gamma: f64,
    /// Offset of the display encoding.
    pub offset: f64,
    /// The paper's highlight boost inside the model (docs/model.md, M20).
    pub highlight: bool,
    /// How a display-encoded photo's clipped highlights are treated ([`PhotoHighlights`],
    /// docs/highlights.md): not at all, the paper's boost, or recovery before the photo
    /// becomes layers (the default: the rim estimate, then the boost with its photo
    /// constants). Not applied to stacks, the demo or linear (EXR) images.
    pub photo_highlights: PhotoHighlights,
    /// Aperture shape ([`parse_aperture`] reads the textual form).
    pub aperture: Aperture,
    /// Model preset.
    pub preset: Preset,
}

impl Default for View {
    /// Automatic focus and window, K = 30, gamma 2.2, offset 0, no highlight boost
    /// except for photos ([`PhotoHighlights::default`]: recovery, then the boost), a circular
    /// aperture and the `physical` preset (the CLI's and the Python module's defaults).
    fn default() -> Self {
        let cam = Camera::paper_default(0.5);
        View {
            focus: Focus::Auto,
            blur_k: cam.blur_k,
            window: None,
            gamma: cam.gamma,
            offset: cam.offset,
            highlight: cam.highlight.is_some(),
            photo_highlights: PhotoHighlights::default(),
            aperture: Aperture::Circle,
            preset: Preset::Physical,
        }
    }
}

impl View {
    /// The display transfer this view implies (the preset's curve with this gamma and
    /// offset): how linear input colour is encoded before rendering.
    pub fn tone(&self) -> Tone {
        Tone::new(self.preset.options().transfer, self.gamma, self.offset)
    }

    /// The settings for rendering `stack` with `engine`, and a note when the automatic
    /// window clips the largest blur. [`Focus::Auto`] is the centre pixel here
    /// ([`resolve`] gives the demo its subject).
    pub fn settings_for<T: Real>(
        &self,
        stack: &LayerStack<T>,
        engine: Engine,
    ) -> Result<(RenderSettings, Option<String>)> {
        let (focus, place) = match self.focus {
            Focus::Disparity(f) => (f, None),
            Focus::At { x, y } => (stack.disparity_at(x, y)?, Some(format!("pixel {x},{y}"))),
            Focus::Auto => (
                stack.disparity_at(stack.width / 2, stack.height / 2)?,
                Some("centre pixel".to_string()),
            ),
        };
        let focus = match (unit_interval(focus), place) {
            (Some(f), _) => f,
            // Out of range as given: validation below reports the parameter.
            (None, None) => focus,
            // Read from the map: the map's problem, not the focus parameter's.
            (None, Some(place)) => {
                return Err(Error::input(
                    "disparity map",
                    format!(
                        "the disparity {focus} at the {place} lies outside [0, 1] and cannot be the focus; give the focus explicitly, or normalise the map"
                    ),
                ))
            }
        };
        self.settings_with_focus(focus, |f| stack.max_defocus(f), engine)
    }

    /// The settings for focus `focus`, where `max_defocus(f)` is the stack's largest
    /// `|disp - f|` over pixels with alpha > 0.
    fn settings_with_focus(
        &self,
        focus: f64,
        max_defocus: impl FnOnce(f64) -> f64,
        engine: Engine,
    ) -> Result<(RenderSettings, Option<String>)> {
        let mut note = None;
        let window = match self.window {
            Some(size) => Window::from_size(size)?,
            // An invalid focus is reported by validation below.
            None if !focus.is_finite() || !(0.0..=1.0).contains(&focus) => {
                Window::automatic(1.0, WindowCap::Clipped)
            }
            None => {
                let needed = model::largest_scatter_radius_px(self.blur_k, max_defocus(focus));
                let cap = if matches!(engine, Engine::Fast | Engine::Spans | Engine::Auto) {
                    WindowCap::Unclipped
                } else {
                    WindowCap::Clipped
                };
                let w = Window::automatic(needed, cap);
                if let Some(size) = w.clips(needed) {
                    note = Some(format!(
                        "largest blur radius is {needed:.1} px but the automatic window is capped at L = {} (R = {}); a window of L = {size} (or the fast engine) renders it unclipped",
                        w.size(),
                        w.radius_px(),
                    ));
                }
                w
            }
        };
        let settings = RenderSettings {
            camera: Camera {
                focus_disparity: focus,
                blur_k: self.blur_k,
                window,
                gamma: self.gamma,
                offset: self.offset,
                highlight: self.highlight.then_some(HighlightBoost::PAPER),
            },
            aperture: self.aperture.clone(),
            preset: self.preset,
        };
        settings.validate()?;
        Ok((settings, note))
    }
}

/// A scene ready to render.
#[derive(Clone, Debug)]
pub struct Scene<T> {
    /// The layers, front to back.
    pub stack: LayerStack<T>,
    /// Camera, aperture and model.
    pub settings: RenderSettings,
    /// What the user should know (e.g. why an image became a single layer, or that the
    /// automatic window clips the blur), one sentence each.
    pub notes: Vec<String>,
}

/// Turns what the user gave into a stack, settings and notes (see the module
/// documentation for the policy). `engine` is the engine that will render: the automatic
/// window is not capped for the radius-bounded engines ([`Engine::Fast`], [`Engine::Spans`],
/// [`Engine::Auto`]).
pub fn resolve<T: Real>(source: Source<T>, view: &View, engine: Engine) -> Result<Scene<T>> {
    let demo_view;
    let photo_view;
    let mut view = match (&source, view.focus) {
        (Source::Demo { .. }, Focus::Auto) => {
            demo_view = View {
                focus: Focus::Disparity(demo::DEMO_FOCUS),
                ..view.clone()
            };
            &demo_view
        }
        _ => view,
    };
    let is_photo = matches!(source, Source::PhotoFiles(_) | Source::Photo(_));
    let (stack, mut notes) = match source {
        Source::Stack(stack) => (stack, vec![]),
        Source::StackFile(path) => (io::read_stack(&path)?, vec![]),
        Source::Demo { width, height } => {
            check_dimensions("demo_size", width, height)?;
            budget::check_work("demo_size", width as u64, height as u64, demo::LAYERS)?;
            (demo::scene(width, height), vec![])
        }
        Source::PhotoFiles(files) => {
            let photo = read_photo(&files, &view.tone())?;
            if io::is_linear(&files.image) {
                photo_view = View {
                    photo_highlights: PhotoHighlights::Off,
                    ..view.clone()
                };
                view = &photo_view;
            }
            photo_stack(photo, view, engine)?
        }
        Source::Photo(photo) => photo_stack(photo, view, engine)?,
    };
    let (mut settings, note) = view.settings_for(&stack, engine)?;
    notes.extend(note);
    if let Some(boost) = view.photo_highlights.boost().filter(|_| is_photo) {
        settings.camera.highlight = Some(boost);
    }
    Ok(Scene {
        stack,
        settings,
        notes,
    })
}

/// The layer stack of a photo: its highlights recovered (`view.highlight_recovery`), then
/// the matte's two layers, one layer, or a decomposition for the focus and blur the view
/// resolves to on the image as one layer.
fn photo_stack<T: Real>(
    photo: Photo<T>,
    view: &View,
    engine: Engine,
) -> Result<(LayerStack<T>, Vec<String>)> {
    let Photo {
        rgb_encoded,
        disparity,
        matte,
        layering,
    } = photo;
    // A clipped light seen past a nearer object's edge is one source at one depth: the
    // farthest its region shows (highlight::lights_at_farthest_depth). Its mixed edge
    // pixels are gated, cut and blurred with the light, not with the nearer object.
    let disparity = match &matte {
        None => crate::highlight::lights_at_farthest_depth(&rgb_encoded, &disparity)
            .unwrap_or(disparity),
        Some(_) => disparity,
    };
    let rgb_encoded = match &view.photo_highlights {
        PhotoHighlights::Recover(r) => {
            // Focus and blur as they resolve on the image as one layer.
            let probe = LayerStack::single(rgb_encoded.clone(), disparity.clone())?;
            let (settings, _) = view.settings_for(&probe, engine)?;
            let cam = &settings.camera;
            r.apply(
                &rgb_encoded,
                &disparity,
                cam.focus_disparity,
                cam.blur_k,
                &view.tone(),
            )?
        }
        PhotoHighlights::Estimate(e) => {
            let probe = LayerStack::single(rgb_encoded.clone(), disparity.clone())?;
            let (settings, _) = view.settings_for(&probe, engine)?;
            let cam = &settings.camera;
            e.apply(
                &rgb_encoded,
                &disparity,
                cam.focus_disparity,
                cam.blur_k,
                &view.tone(),
            )?
        }
        _ => rgb_encoded,
    };
    if let Some(matte) = matte {
        let stack = layering::two_layers_from_matte(&rgb_encoded, &disparity, &matte)?;
        return Ok((stack, vec![]));
    }
    let mut single = LayerStack::single(rgb_encoded, disparity)?;
    let max_layers = match layering {
        Layering::SingleLayer => return Ok((single, vec![])),
        Layering::Decompose { max_layers } => max_layers,
    };
    // Focus and blur as they resolve on the image as one layer (same disparity); this
    // also checks the view before the decomposition's work.
    let (settings, _) = view.settings_for(&single, engine)?;
    let Layer {
        rgb_encoded,
        disparity,
        ..
    } = single.layers.pop().expect("a single-layer stack");
    let opts = LayeringOptions {
        max_layers,
        focus_hint: Some((
            settings.camera.focus_disparity,
            settings.camera.blur_k.abs(),
        )),
        ..LayeringOptions::default()
    };
    let d = layering::layers_from_disparity(&rgb_encoded, &disparity, &opts)?;
    Ok((d.stack, d.notes))
}

/// Reads a photo's files: the image ([`read_display_image`] with `tone`), the map as
/// normalised disparity, the matte; checks that their sizes agree.
pub fn read_photo<T: Real>(files: &PhotoFiles, tone: &Tone) -> Result<Photo<T>> {
    // The decomposition may make up to max_layers layers: check that work against the
    // input budget from the image's header, before reading anything.
    let layers = match (&files.matte, files.layering) {
        (Some(_), _) => 2,
        (None, Layering::SingleLayer) => 1,
        (None, Layering::Decompose { max_layers }) => max_layers as u64,
    };
    let (w, h) = io::image_dimensions(&files.image, "image")?;
    budget::check_work(
        &files.image.display().to_string(),
        w as u64,
        h as u64,
        layers,
    )?;
    let rgb_encoded: Image<T> = read_display_image(&files.image, tone)?;
    let disparity = io::read_disparity(&files.map, files.map_options)?;
    check_same_size(&files.image, &rgb_encoded, &files.map, &disparity)?;
    let matte = match &files.matte {
        Some(path) => {
            let m = io::read_matte(path)?;
            check_same_size(&files.image, &rgb_encoded, path, &m)?;
            Some(m)
        }
        None => None,
    };
    Ok(Photo {
        rgb_encoded,
        disparity,
        matte,
        layering: files.layering,
    })
}

/// Reads a colour image as display-encoded values: as stored for PNG, JPEG and TIFF; for
/// linear EXR, encoded with `tone` (the transfer the renderer will undo), negative values
/// clipped to 0.
pub fn read_display_image<T: Real>(path: &Path, tone: &Tone) -> Result<Image<T>> {
    let mut rgb: Image<T> = io::read_rgb(path)?;
    if io::is_linear(path) {
        encode_linear(&mut rgb, tone);
    }
    Ok(rgb)
}

/// How far outside [0, 1] a focus may lie and still be taken as the nearest end: a focus
/// computed in floating point (`benchmark make` writes `(1/z_f - 1/z_far) / (1/z_near -
/// 1/z_far)`) can land a few ulps outside, and our own outputs must be valid inputs.
pub const UNIT_INTERVAL_SLACK: f64 = 1e-9;

/// `v` if it lies in [0, 1], snapped to the nearest end if within [`UNIT_INTERVAL_SLACK`];
/// `None` otherwise.
pub fn unit_interval(v: f64) -> Option<f64> {
    if (-UNIT_INTERVAL_SLACK..=1.0 + UNIT_INTERVAL_SLACK).contains(&v) {
        Some(v.clamp(0.0, 1.0))
    } else {
        None
    }
}

/// Display-encodes linear colour in place with `tone` (the transfer the renderer will
/// undo), negative values clipped to 0: how linear colour (an EXR file, a linear array
/// given to the Python module) enters a render.
pub fn encode_linear<T: Real>(rgb: &mut Image<T>, tone: &Tone) {
    for v in rgb.data.iter_mut() {
        *v = T::c(tone.encode(v.f64()).max(0.0));
    }
}

/// Fails unless two images (read from the named files) have the same size; the message
/// names the second file.
pub fn check_same_size<A, B>(
    a_path: &Path,
    a: &Image<A>,
    b_path: &Path,
    b: &Image<B>,
) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        return Err(Error::file(
            b_path,
            format!(
                "size {}x{} does not match {} ({}x{})",
                b.width,
                b.height,
                a_path.display(),
                a.width,
                a.height
            ),
        ));
    }
    Ok(())
}

/// Parses an aperture: `circle`, `polygon:N[:DEG]`, a polygon's name (`hexagon`, ...), or
/// `kernel:IMAGE` (a grey image of the bokeh shape, read here).
pub fn parse_aperture(spec: &str) -> Result<Aperture> {
    match spec.strip_prefix("kernel:") {
        Some("") => Err(Error::param(
            "aperture",
            "kernel: needs an image, as in kernel:IMAGE",
        )),
        Some(path) => {
            let path = Path::new(path);
            let grey = io::read_grey::<f64>(path, "aperture kernel")?;
            Ok(Aperture::Kernel(
                KernelImage::new(&grey).map_err(|e| e.in_file(path))?,
            ))
        }
        None => Aperture::parse_shape(spec),
    }
}
