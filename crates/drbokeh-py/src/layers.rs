//! `aperture_layer`: the aperture-compositing rendering layer of the library
//! (`drbokeh::baselines::aperture_compositing`, Srinivasan et al. 2018) and its gradient with
//! respect to the disparity, so that `drbokeh.dfdnet` can train a network through it without
//! PyTorch's per-sample resampling (`drbokeh.dfdnet.layers.aperture`, the plain reference
//! this is tested against).

use crate::convert::{image_to_py, ArrayArg, Float, Precision};
use crate::errors::OrRaise;
use crate::policy::check_same_size;
use crate::pool::Workers;
use drbokeh::baselines::aperture_compositing;
use drbokeh::presets::RenderSettings;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// The layer's settings: blur `K`, focus and a gamma transfer (no offset, no highlight
/// boost), validated as the renderer validates them.
fn settings(focus: f64, blur: f64, gamma: f64) -> PyResult<RenderSettings> {
    let mut s = RenderSettings::paper(focus);
    s.camera.blur_k = blur;
    s.camera.gamma = gamma;
    s.camera.validate().or_raise()?;
    Ok(s)
}

/// Renders (and, with `grad_output`, back-propagates) one image in precision `T`.
fn run<'py, T: Float>(
    py: Python<'py>,
    image: &ArrayArg,
    disparity: &ArrayArg,
    grad_output: Option<&ArrayArg>,
    s: &RenderSettings,
    workers: &Workers,
) -> PyResult<Bound<'py, PyAny>> {
    let rgb = image.image::<T>(3)?;
    let disp = disparity.image::<T>(1)?;
    rgb.check_finite(image.name).or_raise()?;
    disp.check_finite(disparity.name).or_raise()?;
    check_same_size(image.name, &rgb, disparity.name, &disp)?;
    let Some(g) = grad_output else {
        let out = py
            .detach(|| workers.run(|| aperture_compositing::render(&rgb, &disp, s)))
            .or_raise()?;
        return Ok(image_to_py(py, out));
    };
    let name = g.name;
    let g = g.image::<T>(3)?;
    g.check_finite(name).or_raise()?;
    check_same_size(image.name, &rgb, name, &g)?;
    // One pass: the gradient is known before the render.
    let v = py
        .detach(|| workers.run(|| aperture_compositing::vjp(&rgb, &disp, s, false, &g)))
        .or_raise()?;
    Ok(PyTuple::new(
        py,
        [image_to_py(py, v.render), image_to_py(py, v.d_disparity)],
    )?
    .into_any())
}

/// Aperture compositing (Srinivasan et al. 2018) as a rendering layer: the image
/// (display-encoded `(H,W,3)`) resampled bilinearly, with clamped borders, at
/// `x + K (disparity(x) - focus) u_j` for 128 golden-angle samples `u_j` of the unit disc,
/// averaged in linear light (`linear = encoded^gamma`) and encoded again. Returns the render
/// `(H,W,3)`; with `grad_output` (`(H,W,3)`, the gradient of a loss on the render), the
/// tuple `(render, d_disparity)` where `d_disparity` `(H,W)` is the gradient of
/// `sum(grad_output * render)` with respect to the disparity. float64 if any array is
/// float64, float32 otherwise; the output does not depend on `threads`.
#[pyfunction]
#[pyo3(signature = (image, disparity, *, focus, blur, gamma=2.2, grad_output=None, threads=None))]
#[pyo3(
    text_signature = "(image, disparity, *, focus, blur, gamma=2.2, grad_output=None, threads=None)"
)]
#[allow(clippy::too_many_arguments)]
pub fn aperture_layer<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    disparity: &Bound<'py, PyAny>,
    focus: f64,
    blur: f64,
    gamma: f64,
    grad_output: Option<Bound<'py, PyAny>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    let workers = Workers::new(threads)?;
    let s = settings(focus, blur, gamma)?;
    let image = ArrayArg::new("image", image)?;
    let disparity = ArrayArg::new("disparity", disparity)?;
    let grad = grad_output
        .as_ref()
        .map(|g| ArrayArg::new("grad_output", g))
        .transpose()?;
    let mut all = vec![&image, &disparity];
    all.extend(grad.as_ref());
    match Precision::of(&all) {
        Precision::F32 => run::<f32>(py, &image, &disparity, grad.as_ref(), &s, &workers),
        Precision::F64 => run::<f64>(py, &image, &disparity, grad.as_ref(), &s, &workers),
    }
}
