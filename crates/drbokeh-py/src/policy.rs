//! From Python arguments to the library's entry point, `drbokeh::scene`: the keyword
//! arguments become a [`View`] ([`ViewArgs::view`]), the engine name is resolved by
//! [`Engine::parse_or_auto`] (`"auto"`: spans or fast taps in float32, threaded in float64, as `--f64`),
//! and [`resolve`] hands the scene to [`scene::resolve`], which decides the focus (a value,
//! a pixel, or the centre pixel), the automatic window and a photo's layers. This is the
//! path `drbokeh render` takes, so Python and the CLI render the same stack with the same
//! settings. (Until the library had `drbokeh::scene`, this module kept a copy of the
//! CLI's policy; that copy is gone.)
//!
//! What stays here is Python's own: the aperture may be a NumPy kernel array besides the
//! textual forms ([`aperture_from`]), and sizes of array arguments are checked with the
//! library's [`scene::check_same_size`] but raised as `ValueError` naming the arguments.
//!
//! Errors: the library names parameters as the Python keyword arguments are named
//! (`focus`, `focus_at`, `blur`, `window`, `gamma`, `offset`, `aperture`, `preset`,
//! `engine`, `max_layers`, `jump`, `band`), so its messages pass through unchanged.

use crate::convert::{ArrayArg, Float, Precision};
use crate::errors::{value_error, OrRaise};
use crate::pool::Workers;
use crate::render::warn;
use drbokeh::aperture::KernelImage;
use drbokeh::scene::{self, Focus, Scene, Source, View};
use drbokeh::{Aperture, Engine, Image};
use pyo3::prelude::*;
use pyo3::types::PyString;
use std::path::Path;

/// The view and engine arguments shared by every rendering call, as Python passed them.
pub struct ViewArgs<'a> {
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

impl ViewArgs<'_> {
    /// The engine for inputs of this precision ([`Engine::parse_or_auto`]).
    pub fn engine(&self, precision: Precision) -> PyResult<Engine> {
        Engine::parse_or_auto(self.engine, precision == Precision::F64).or_raise()
    }

    /// The library's view of these arguments with this aperture ([`aperture_from`]).
    pub fn view(&self, aperture: Option<&Bound<'_, PyAny>>) -> PyResult<View> {
        let focus = match (self.focus, self.focus_at) {
            (Some(f), _) => Focus::Disparity(f),
            (None, Some((x, y))) => Focus::At { x, y },
            (None, None) => Focus::Auto,
        };
        Ok(View {
            focus,
            blur_k: self.blur,
            window: self.window,
            gamma: self.gamma,
            offset: self.offset,
            highlight: self.highlight,
            aperture: aperture_from(aperture)?,
            preset: self.preset.parse().or_raise()?,
            // A photo's highlights as the CLI treats them (docs/highlights.md): its default
            // without `highlight`, the paper's boost alone with it (as `--highlight`).
            photo_highlights: if self.highlight {
                drbokeh::highlight::PhotoHighlights::PaperBoost
            } else {
                drbokeh::highlight::PhotoHighlights::default()
            },
        })
    }
}

/// The aperture: `None` (the circle), a string as the CLI's `--aperture` takes it
/// ([`scene::parse_aperture`]: a shape name, `polygon:N[:DEG]`, `kernel:PATH`), or a grey
/// kernel array (Python only).
pub fn aperture_from(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Aperture> {
    let Some(obj) = obj else {
        return Ok(Aperture::Circle);
    };
    if let Ok(s) = obj.cast::<PyString>() {
        return scene::parse_aperture(&s.to_cow()?).or_raise();
    }
    let grey = ArrayArg::new("aperture", obj)?.image::<f64>(1)?;
    Ok(Aperture::Kernel(KernelImage::new(&grey).or_raise()?))
}

/// Resolves a scene with the GIL released ([`scene::resolve`]) and issues its notes (a
/// fallback to one layer, a clipped window) as `DrBokehWarning`s.
pub fn resolve<T: Float>(
    py: Python<'_>,
    source: Source<T>,
    view: &View,
    engine: Engine,
    workers: &Workers,
) -> PyResult<Scene<T>> {
    let s = py
        .detach(|| workers.run(|| scene::resolve(source, view, engine)))
        .or_raise()?;
    for n in &s.notes {
        warn(py, n)?;
    }
    Ok(s)
}

/// Fails unless two array arguments have the same size: the library's
/// [`scene::check_same_size`] with the arguments' names for file names, raised as a
/// `ValueError` (`"disparity: size 9x7 does not match image (9x8)"`).
pub fn check_same_size<A, B>(
    a_name: &str,
    a: &Image<A>,
    b_name: &str,
    b: &Image<B>,
) -> PyResult<()> {
    scene::check_same_size(Path::new(a_name), a, Path::new(b_name), b)
        .map_err(|e| value_error(e.to_string()))
}
