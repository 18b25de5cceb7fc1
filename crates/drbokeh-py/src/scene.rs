//! The photo path: `render_image` (what `drbokeh render --image` renders) and `decompose`
//! (what `drbokeh layers` writes).

use crate::convert::{stack_to_py, ArrayArg, Float, Precision};
use crate::errors::{value_error, OrRaise};
use crate::policy::{check_same_size, resolve, ViewArgs};
use crate::pool::Workers;
use crate::render::{render_prepared, Prepared};
use drbokeh::layering::{self, LayeringOptions};
use drbokeh::model::Tone;
use drbokeh::scene::{self, Layering, Photo, Source};
use drbokeh::Image;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Colour, disparity and the optional matte of a photo.
type PhotoImages<T> = (Image<T>, Image<T>, Option<Image<T>>);

/// The photo arguments, converted: colour (display-encoded; a linear one is encoded with
/// `linear`, the render's transfer, as the CLI does for EXR: [`scene::encode_linear`]),
/// disparity and the optional matte, all of one size.
fn photo<T: Float>(
    image: &ArrayArg,
    disparity: &ArrayArg,
    matte: Option<&ArrayArg>,
    linear: Option<&Tone>,
) -> PyResult<PhotoImages<T>> {
    let mut rgb = image.image::<T>(3)?;
    if let Some(tone) = linear {
        scene::encode_linear(&mut rgb, tone);
    }
    let disp = disparity.image::<T>(1)?;
    check_same_size(image.name, &rgb, disparity.name, &disp)?;
    let matte = match matte {
        Some(m) => {
            let m_img = m.image::<T>(1)?;
            check_same_size(image.name, &rgb, m.name, &m_img)?;
            Some(m_img)
        }
        None => None,
    };
    Ok((rgb, disp, matte))
}

/// Renders a photo: the image (display-encoded `(H,W,3)`; `linear=True` for linear light,
/// which is encoded with the render's transfer first) and its disparity `(H,W)` (larger =
/// nearer, normalised to [0, 1]) become a layer stack exactly as `drbokeh render --image`
/// makes it: with `alpha` (a matte), the paper's two layers; with `single_layer`, one
/// opaque layer; otherwise up to `max_layers` depth layers cut for this focus and blur.
/// `focus`: a disparity; `focus_at=(x, y)`: the disparity seen at that pixel; neither: the
/// centre pixel's. Notes (a fallback to one layer, a clipped window) are issued as
/// `DrBokehWarning`s. Other options as `render`.
#[pyfunction]
#[pyo3(signature = (image, disparity, *, focus=None, focus_at=None, blur=30.0, alpha=None, single_layer=false, max_layers=None, linear=false, preset="physical", aperture=None, window=None, gamma=2.2, offset=0.0, highlight=false, engine="auto", threads=None))]
#[pyo3(
    text_signature = "(image, disparity, *, focus=None, focus_at=None, blur=30.0, alpha=None, single_layer=False, max_layers=None, linear=False, preset='physical', aperture='circle', window=None, gamma=2.2, offset=0.0, highlight=False, engine='auto', threads=None)"
)]
#[allow(clippy::too_many_arguments)]
pub fn render_image<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    disparity: &Bound<'py, PyAny>,
    focus: Option<f64>,
    focus_at: Option<(usize, usize)>,
    blur: f64,
    alpha: Option<Bound<'py, PyAny>>,
    single_layer: bool,
    max_layers: Option<usize>,
    linear: bool,
    preset: &str,
    aperture: Option<Bound<'py, PyAny>>,
    window: Option<usize>,
    gamma: f64,
    offset: f64,
    highlight: bool,
    engine: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    if focus.is_some() && focus_at.is_some() {
        return Err(value_error("pass focus or focus_at, not both"));
    }
    if alpha.is_some() && (single_layer || max_layers.is_some()) {
        return Err(value_error(
            "alpha (a matte) makes the paper's two layers: it cannot be combined with single_layer or max_layers",
        ));
    }
    if single_layer && max_layers.is_some() {
        return Err(value_error(
            "single_layer and max_layers cannot be combined",
        ));
    }
    let workers = Workers::new(threads)?;
    let image = ArrayArg::new("image", image)?;
    let disparity = ArrayArg::new("disparity", disparity)?;
    let matte = alpha
        .as_ref()
        .map(|a| ArrayArg::new("alpha", a))
        .transpose()?;
    let mut all = vec![&image, &disparity];
    all.extend(matte.as_ref());
    let c = ViewArgs {
        focus,
        focus_at,
        blur,
        preset,
        window,
        gamma,
        offset,
        highlight,
        engine,
    };
    let aperture = aperture.as_ref();
    match Precision::of(&all) {
        Precision::F32 => {
            let p = prepare_image::<f32>(
                py,
                &image,
                &disparity,
                matte.as_ref(),
                single_layer,
                max_layers,
                linear,
                &c,
                aperture,
                &workers,
            )?;
            render_prepared(py, p, &workers)
        }
        Precision::F64 => {
            let p = prepare_image::<f64>(
                py,
                &image,
                &disparity,
                matte.as_ref(),
                single_layer,
                max_layers,
                linear,
                &c,
                aperture,
                &workers,
            )?;
            render_prepared(py, p, &workers)
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn prepare_image<T: Float>(
    py: Python<'_>,
    image: &ArrayArg,
    disparity: &ArrayArg,
    matte: Option<&ArrayArg>,
    single_layer: bool,
    max_layers: Option<usize>,
    linear: bool,
    c: &ViewArgs,
    aperture: Option<&Bound<'_, PyAny>>,
    workers: &Workers,
) -> PyResult<Prepared<T>> {
    let engine = c.engine(T::PRECISION)?;
    let mut view = c.view(aperture)?;
    let tone = linear.then(|| view.tone());
    if linear {
        // Linear light keeps its highlights' energy: no recovery or boost by default, as the
        // CLI does for an EXR image (docs/highlights.md).
        view.photo_highlights = drbokeh::highlight::PhotoHighlights::Off;
    }
    let (rgb_encoded, disparity, matte) = photo::<T>(image, disparity, matte, tone.as_ref())?;
    let layering = if single_layer {
        Layering::SingleLayer
    } else {
        Layering::Decompose {
            max_layers: max_layers.unwrap_or(layering::DEFAULT_MAX_LAYERS),
        }
    };
    let source = Source::Photo(Photo {
        rgb_encoded,
        disparity,
        matte,
        layering,
    });
    let scene = resolve(py, source, &view, engine, workers)?;
    Ok(Prepared {
        stack: scene.stack,
        settings: scene.settings,
        engine,
    })
}

/// Decomposes a photo into a layer stack, as `drbokeh layers`: with `alpha` (a matte), the
/// paper's two layers (foreground = matte, background inpainted under it); otherwise up to
/// `max_layers` depth layers cut at disparity discontinuities (a neighbour step above
/// `jump` of the disparity range), each layer's hidden part inpainted; `band` is how far
/// (pixels) a middle layer is filled in behind nearer ones. With `focus` and `blur`, cuts
/// that cannot change that render are left out (as `render_image` does). Returns a dict:
/// `rgb (N,H,W,3)`, `alpha (N,H,W)`, `disparity (N,H,W)`, `thresholds` (the cut
/// disparities, nearest first) and `notes`.
#[pyfunction]
#[pyo3(signature = (image, disparity, *, alpha=None, max_layers=5, jump=0.05, band=None, focus=None, blur=None, threads=None))]
#[allow(clippy::too_many_arguments)]
pub fn decompose<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    disparity: &Bound<'py, PyAny>,
    alpha: Option<Bound<'py, PyAny>>,
    max_layers: usize,
    jump: f64,
    band: Option<f64>,
    focus: Option<f64>,
    blur: Option<f64>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    if focus.is_some() != blur.is_some() {
        return Err(value_error(
            "focus and blur go together: pass both or neither",
        ));
    }
    let workers = Workers::new(threads)?;
    let opts = LayeringOptions {
        max_layers,
        jump_fraction: jump,
        occlusion_band_px: band,
        focus_hint: focus.zip(blur),
        ..LayeringOptions::default()
    };
    opts.validate().or_raise()?;
    let image = ArrayArg::new("image", image)?;
    let disparity = ArrayArg::new("disparity", disparity)?;
    let matte = alpha
        .as_ref()
        .map(|a| ArrayArg::new("alpha", a))
        .transpose()?;
    let mut all = vec![&image, &disparity];
    all.extend(matte.as_ref());
    match Precision::of(&all) {
        Precision::F32 => {
            decompose_typed::<f32>(py, &image, &disparity, matte.as_ref(), &opts, &workers)
        }
        Precision::F64 => {
            decompose_typed::<f64>(py, &image, &disparity, matte.as_ref(), &opts, &workers)
        }
    }
}

fn decompose_typed<'py, T: Float>(
    py: Python<'py>,
    image: &ArrayArg,
    disparity: &ArrayArg,
    matte: Option<&ArrayArg>,
    opts: &LayeringOptions,
    workers: &Workers,
) -> PyResult<Bound<'py, PyDict>> {
    let (rgb, disp, matte) = photo::<T>(image, disparity, matte, None)?;
    let d = py
        .detach(|| workers.run(|| layering::decompose(&rgb, &disp, matte.as_ref(), opts)))
        .or_raise()?;
    let out = stack_to_py(py, &d.stack)?;
    out.set_item("thresholds", d.thresholds)?;
    out.set_item("notes", d.notes)?;
    Ok(out)
}
