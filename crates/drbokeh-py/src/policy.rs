//! How user options resolve into what the library renders: the engine for `"auto"`, the
//! aperture, the focus (a value, a pixel, or the centre pixel), the automatic window, and a
//! photo's layer stack. This mirrors the CLI's `args.rs` (`settings_for`,
//! `load_scene_for_render`) step for step, so that Python and the CLI render the same
//! thing; when the library gains its own entry point for this policy, [`settings_for`] and
//! [`stack_for_image`] become calls to it.

use crate::convert::{ArrayArg, Float, Precision};
use crate::errors::{value_error, OrRaise};
use drbokeh::layering::{self, LayeringOptions};
use drbokeh::{
    Aperture, Camera, Engine, Image, LayerStack, Preset, RenderSettings, Result, Window,
};
use pyo3::prelude::*;
use pyo3::types::PyString;
use std::path::Path;

/// Camera, model and engine options shared by every rendering call (plain data, so that
/// work using them can run without the GIL).
pub struct CameraOptions<'a> {
    /// Focus disparity; `None`: `focus_at`, else the centre pixel.
    pub focus: Option<f64>,
    /// Tap to focus: the disparity seen at pixel `(x, y)`.
    pub focus_at: Option<(usize, usize)>,
    /// Blur strength K.
    pub blur: f64,
    /// Preset name.
    pub preset: &'a str,
    /// Window size L; `None`: automatic.
    pub window: Option<usize>,
    /// Gamma of the display encoding.
    pub gamma: f64,
    /// Offset of the display encoding.
    pub offset: f64,
    /// Highlight boost.
    pub highlight: bool,
    /// Engine name (`auto`, `fast`, `threaded`, `reference`).
    pub engine: &'a str,
}

impl CameraOptions<'_> {
    /// The engine: `auto` is fast in float32 and threaded (exact) in float64, as `--f64`.
    pub fn engine(&self, precision: Precision) -> PyResult<Engine> {
        match (self.engine, precision) {
            ("auto", Precision::F64) => Ok(Engine::Threaded),
            ("auto", Precision::F32) => Ok(Engine::Fast),
            (other, _) => other.parse().or_raise(),
        }
    }

    /// The preset.
    pub fn preset(&self) -> PyResult<Preset> {
        self.preset.parse().or_raise()
    }

    /// The settings without a stack (focus must be given): for the display transfer.
    pub fn tone_settings(&self) -> PyResult<RenderSettings> {
        let mut s = RenderSettings::paper(self.focus.unwrap_or(0.5));
        s.preset = self.preset()?;
        s.camera.gamma = self.gamma;
        s.camera.offset = self.offset;
        Ok(s)
    }
}

/// The aperture: `None` (the circle), a shape name (`circle`, `hexagon`,
/// `polygon:N[:DEG]`, ...), `kernel:PATH` (a grey image file), or a grey kernel array.
pub fn aperture_from(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Aperture> {
    let Some(obj) = obj else {
        return Ok(Aperture::Circle);
    };
    if let Ok(s) = obj.cast::<PyString>() {
        let s = s.to_cow()?;
        return match s.strip_prefix("kernel:") {
            Some(path) => {
                let path = Path::new(path);
                let grey = drbokeh::io::read_grey::<f64>(path, "aperture kernel").or_raise()?;
                Ok(Aperture::Kernel(
                    drbokeh::aperture::KernelImage::new(&grey)
                        .map_err(|e| e.in_file(path))
                        .or_raise()?,
                ))
            }
            None => Aperture::parse_shape(&s).or_raise(),
        };
    }
    let grey = ArrayArg::new("aperture", obj)?.image::<f64>(1)?;
    Ok(Aperture::Kernel(
        drbokeh::aperture::KernelImage::new(&grey).or_raise()?,
    ))
}

/// Resolves the settings for a loaded stack, as the CLI's `settings_for`: the focus, then
/// the window (automatic: just holds the largest blur radius, at most 71 except for the
/// fast engine), then validation. Returns a note when the automatic window clips the blur.
pub fn settings_for<T: drbokeh::Real>(
    c: &CameraOptions,
    stack: &LayerStack<T>,
    engine: Engine,
    aperture: Aperture,
    preset: Preset,
) -> Result<(RenderSettings, Option<String>)> {
    let focus = match (c.focus, c.focus_at) {
        (Some(f), _) => f,
        (None, Some((x, y))) => stack.disparity_at(x, y)?,
        (None, None) => stack.disparity_at(stack.width / 2, stack.height / 2)?,
    };
    let mut note = None;
    let window = match c.window {
        Some(l) => Window::from_size(l)?,
        None => {
            if !(0.0..=1.0).contains(&focus) || !focus.is_finite() {
                // Let validation below report it.
                Window::auto(1.0)
            } else {
                let needed = c.blur.abs() * stack.max_defocus(focus) + 1.0;
                let w = if engine == Engine::Fast {
                    Window::auto_unclipped(needed)
                } else {
                    Window::auto(needed)
                };
                if needed + drbokeh::camera::AUTO_WINDOW_MARGIN_PX > w.radius_px() as f64 + 0.5 {
                    note = Some(format!(
                        "largest blur radius is {needed:.1} px but the automatic window is capped at L = {} (R = {}); pass window={} (or use the fast engine) for unclipped bokeh",
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
            blur_k: c.blur,
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

/// How a photo becomes a layer stack.
pub struct ImageScene<T> {
    /// Display-encoded colour (H, W, 3).
    pub rgb: Image<T>,
    /// Disparity (H, W).
    pub disparity: Image<T>,
    /// Optional alpha matte (H, W): the paper's two-layer stack.
    pub matte: Option<Image<T>>,
    /// One opaque layer instead of the automatic decomposition.
    pub single_layer: bool,
    /// Most layers of the automatic decomposition (default 5).
    pub max_layers: Option<usize>,
}

/// Fails unless two images have the same size (the CLI's `check_same_size`).
pub fn check_same_size<A, B>(
    a_name: &str,
    a: &Image<A>,
    b_name: &str,
    b: &Image<B>,
) -> PyResult<()> {
    if a.width != b.width || a.height != b.height {
        return Err(value_error(format!(
            "{b_name}: size {}x{} does not match {a_name} ({}x{})",
            b.width, b.height, a.width, a.height
        )));
    }
    Ok(())
}

/// The stack `drbokeh render --image` renders, as the CLI's `load_scene_for_render`: one
/// opaque layer (`single_layer`), the paper's two layers from a matte, or the automatic
/// decomposition made for this render's focus and blur (resolved on the single-layer stack).
/// Returns the stack and the decomposition's notes.
pub fn stack_for_image<T: Float>(
    scene: ImageScene<T>,
    c: &CameraOptions,
    engine: Engine,
    preset: Preset,
) -> Result<(LayerStack<T>, Vec<String>)> {
    let ImageScene {
        rgb,
        disparity,
        matte,
        single_layer,
        max_layers,
    } = scene;
    if let Some(m) = matte {
        return Ok((
            layering::two_layers_from_matte(&rgb, &disparity, &m)?,
            vec![],
        ));
    }
    if single_layer {
        return Ok((LayerStack::single(rgb, disparity)?, vec![]));
    }
    let single = LayerStack::single(rgb.clone(), disparity.clone())?;
    // The circle stands in for the aperture here: focus and window do not depend on it.
    let (settings, _) = settings_for(c, &single, engine, Aperture::Circle, preset)?;
    let opts = LayeringOptions {
        max_layers: max_layers.unwrap_or(layering::DEFAULT_MAX_LAYERS),
        focus_hint: Some((
            settings.camera.focus_disparity,
            settings.camera.blur_k.abs(),
        )),
        ..Default::default()
    };
    let d = layering::layers_from_disparity(&rgb, &disparity, &opts)?;
    Ok((d.stack, d.notes))
}
