//! `render`, `render_with_tape` / `Tape.backward` and `vjp` on layer stacks.

use crate::convert::{
    image_to_py, planes_to_py, scalar_to_py, shape_str, stack_from, ArrayArg, Float, Precision,
};
use crate::errors::{value_error, OrRaise};
use crate::policy::{resolve, ViewArgs};
use crate::pool::Workers;
use drbokeh::scene::Source;
use drbokeh::{Engine, Gradients, LayerStack, NoProgress, RenderSettings};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pyo3::create_exception!(
    drbokeh,
    DrBokehWarning,
    pyo3::exceptions::PyUserWarning,
    "Notes about a render: the automatic window clips the blur, the decomposition fell back to one layer."
);

/// Issues a note as a `DrBokehWarning`.
pub fn warn(py: Python<'_>, note: &str) -> PyResult<()> {
    let msg =
        std::ffi::CString::new(note.replace('\0', " ")).map_err(|e| value_error(e.to_string()))?;
    PyErr::warn(py, &py.get_type::<DrBokehWarning>().into_any(), &msg, 1)
}

/// A layer stack argument, checked and converted, with the settings it renders with.
pub struct Prepared<T> {
    pub stack: LayerStack<T>,
    pub settings: RenderSettings,
    pub engine: Engine,
}

/// Converts the stack and resolves the settings as the CLI does (`drbokeh::scene::resolve`,
/// warning about a clipped window).
pub fn prepare<T: Float>(
    py: Python<'_>,
    arrays: &[ArrayArg<'_>; 3],
    c: &ViewArgs,
    aperture: Option<&Bound<'_, PyAny>>,
    workers: &Workers,
) -> PyResult<Prepared<T>> {
    let engine = c.engine(T::PRECISION)?;
    let view = c.view(aperture)?;
    let stack = stack_from::<T>(&arrays[0], &arrays[1], &arrays[2])?;
    let scene = resolve(py, Source::Stack(stack), &view, engine, workers)?;
    Ok(Prepared {
        stack: scene.stack,
        settings: scene.settings,
        engine,
    })
}

/// The three stack arguments.
pub fn stack_args<'py>(
    rgb: &Bound<'py, PyAny>,
    alpha: &Bound<'py, PyAny>,
    disparity: &Bound<'py, PyAny>,
) -> PyResult<[ArrayArg<'py>; 3]> {
    Ok([
        ArrayArg::new("rgb", rgb)?,
        ArrayArg::new("alpha", alpha)?,
        ArrayArg::new("disparity", disparity)?,
    ])
}

/// Renders a layer stack, as `drbokeh render --layers`.
///
/// Args:
///     rgb: display-encoded colour (N, H, W, 3), layers front first.
///     alpha: coverage in [0, 1], (N, H, W).
///     disparity: normalised disparity, larger = nearer, (N, H, W).
///     focus: the in-focus disparity, in [0, 1].
///     blur: blur strength K, the blur radius in pixels per unit of relative disparity.
///     preset: "physical" (measured closer to a real lens) or "paper" (the published
///         Dr.Bokeh model, exactly).
///     aperture: "circle", "hexagon", "polygon:N[:DEG]" (and the other shape names of
///         the command line), "kernel:PATH" (a grey image file), or a grey (h, w) array.
///     window: odd gather window L = 2R + 1; None: just holds the largest blur (at most 71
///         except for the fast engine; a clipped blur issues a DrBokehWarning).
///     gamma, offset: the display transfer, linear = (encoded + offset) ** gamma.
///     highlight: boost bright, defocused highlights.
///     engine: "auto" (in float32 spans or the fast engine's taps, whichever is
///         cheaper per band and layer; the exact threaded engine in float64, as --f64),
///         "spans", "fast", "threaded" or "reference".
///     threads: worker threads (default: all cores); the output never depends on it.
///
/// Arrays may be float32 or float64, contiguous or not; each is copied once.
///
/// Returns:
///     The display-encoded image (H, W, 3): float64 if any input is float64, else float32.
///
/// Raises:
///     ValueError: bad shapes, dtypes, values (NaN, alpha outside [0, 1], negative colour)
///         or parameters, with the library's messages (parameters named as the keyword
///         arguments are).
///     OSError: an aperture kernel file that cannot be read.
#[pyfunction]
#[pyo3(signature = (rgb, alpha, disparity, *, focus, blur, preset="physical", aperture=None, window=None, gamma=2.2, offset=0.0, highlight=false, engine="auto", threads=None))]
#[pyo3(
    text_signature = "(rgb, alpha, disparity, *, focus, blur, preset='physical', aperture='circle', window=None, gamma=2.2, offset=0.0, highlight=False, engine='auto', threads=None)"
)]
#[allow(clippy::too_many_arguments)]
pub fn render<'py>(
    py: Python<'py>,
    rgb: &Bound<'py, PyAny>,
    alpha: &Bound<'py, PyAny>,
    disparity: &Bound<'py, PyAny>,
    focus: f64,
    blur: f64,
    preset: &str,
    aperture: Option<Bound<'py, PyAny>>,
    window: Option<usize>,
    gamma: f64,
    offset: f64,
    highlight: bool,
    engine: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    let workers = Workers::new(threads)?;
    let arrays = stack_args(rgb, alpha, disparity)?;
    let c = ViewArgs {
        focus: Some(focus),
        focus_at: None,
        blur,
        preset,
        window,
        gamma,
        offset,
        highlight,
        engine,
    };
    match Precision::of(&[&arrays[0], &arrays[1], &arrays[2]]) {
        Precision::F32 => render_prepared(
            py,
            prepare::<f32>(py, &arrays, &c, aperture.as_ref(), &workers)?,
            &workers,
        ),
        Precision::F64 => render_prepared(
            py,
            prepare::<f64>(py, &arrays, &c, aperture.as_ref(), &workers)?,
            &workers,
        ),
    }
}

/// Renders a prepared stack with the GIL released.
pub fn render_prepared<'py, T: Float>(
    py: Python<'py>,
    p: Prepared<T>,
    workers: &Workers,
) -> PyResult<Bound<'py, PyAny>> {
    let out = py
        .detach(|| workers.run(|| drbokeh::render(&p.stack, &p.settings, p.engine, &NoProgress)))
        .or_raise()?;
    Ok(image_to_py(py, out))
}

enum TapeInner {
    F32(drbokeh::Tape<f32>),
    F64(drbokeh::Tape<f64>),
}

/// What `render_with_tape` recorded for the backward pass of one render.
#[pyclass(module = "drbokeh", frozen)]
pub struct Tape {
    inner: TapeInner,
    shape: [usize; 3],
}

#[pymethods]
impl Tape {
    /// Gradients of `sum(grad_output * render)` with respect to every input: a dict with
    /// `rgb (N,H,W,3)`, `alpha (N,H,W)`, `disparity (N,H,W)` and the 0-d arrays `blur`
    /// (d/dK) and `focus` (d/df), in the tape's dtype. `grad_output` is `(H,W,3)`.
    /// `rescale_small_gradients` applies the published kernel's training heuristic (values
    /// with magnitude in [1e-6, 1e-2) raised to 1e-2): no longer the exact gradient.
    #[pyo3(signature = (grad_output, *, rescale_small_gradients=false, threads=None))]
    fn backward<'py>(
        &self,
        py: Python<'py>,
        grad_output: &Bound<'py, PyAny>,
        rescale_small_gradients: bool,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let workers = Workers::new(threads)?;
        let g = ArrayArg::new("grad_output", grad_output)?;
        match &self.inner {
            TapeInner::F32(t) => {
                backward_typed(py, t, &g, self.shape, rescale_small_gradients, &workers)
            }
            TapeInner::F64(t) => {
                backward_typed(py, t, &g, self.shape, rescale_small_gradients, &workers)
            }
        }
    }

    /// `"float32"` or `"float64"`: the precision of the render and of the gradients.
    #[getter]
    fn dtype(&self) -> &'static str {
        match self.inner {
            TapeInner::F32(_) => "float32",
            TapeInner::F64(_) => "float64",
        }
    }

    /// The schedule of the backward pass: `"threaded"` (exact, every window tap), `"fast"`
    /// or `"spans"` (the span adjoint: `engine="spans"` and float32 `"auto"`).
    #[getter]
    fn engine(&self) -> &'static str {
        let e = match &self.inner {
            TapeInner::F32(t) => t.engine(),
            TapeInner::F64(t) => t.engine(),
        };
        match e {
            Engine::Fast => "fast",
            Engine::Spans | Engine::Auto => "spans",
            _ => "threaded",
        }
    }

    /// `(N, H, W)` of the stack this tape was recorded for.
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        (self.shape[0], self.shape[1], self.shape[2])
    }

    fn __repr__(&self) -> String {
        format!(
            "Tape(shape={}, dtype={}, engine={})",
            shape_str(&self.shape),
            self.dtype(),
            self.engine()
        )
    }
}

fn backward_typed<'py, T: Float>(
    py: Python<'py>,
    tape: &drbokeh::Tape<T>,
    g: &ArrayArg<'py>,
    [n, h, w]: [usize; 3],
    rescale: bool,
    workers: &Workers,
) -> PyResult<Bound<'py, PyDict>> {
    check_grad_shape(g, [n, h, w])?;
    let g = g.image::<T>(3)?;
    let mut grads = py
        .detach(|| workers.run(|| tape.backward(&g, &NoProgress)))
        .or_raise()?;
    if rescale {
        grads.rescale_small(1e-6, 1e-2);
    }
    debug_assert_eq!(grads.layers.len(), n);
    gradients_to_py(py, &grads)
}

/// Gradients as the dict `drbokeh vjp` writes as NPZ.
fn gradients_to_py<'py, T: Float>(
    py: Python<'py>,
    grads: &Gradients<T>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let l = &grads.layers;
    d.set_item(
        "rgb",
        planes_to_py(py, &l.iter().map(|g| &g.rgb).collect::<Vec<_>>()),
    )?;
    d.set_item(
        "alpha",
        planes_to_py(py, &l.iter().map(|g| &g.alpha).collect::<Vec<_>>()),
    )?;
    d.set_item(
        "disparity",
        planes_to_py(py, &l.iter().map(|g| &g.disparity).collect::<Vec<_>>()),
    )?;
    d.set_item("blur", scalar_to_py::<T>(py, grads.blur_k))?;
    d.set_item("focus", scalar_to_py::<T>(py, grads.focus))?;
    Ok(d)
}

/// Renders like `render` and records what the backward pass needs: returns
/// `(image, Tape)`. The image equals `render`'s with the same arguments bit for bit
/// (`engine="reference"` records on the threaded schedule, whose output is the
/// reference's). `engine="auto"`: the span engine's adjoint in float32 (within 1e-3 of
/// the exact gradient's largest value, measured within 1e-4), the exact threaded adjoint
/// in float64; `"fast"`: the fast engine's (within 1e-5).
#[pyfunction]
#[pyo3(signature = (rgb, alpha, disparity, *, focus, blur, preset="physical", aperture=None, window=None, gamma=2.2, offset=0.0, highlight=false, engine="auto", threads=None))]
#[pyo3(
    text_signature = "(rgb, alpha, disparity, *, focus, blur, preset='physical', aperture='circle', window=None, gamma=2.2, offset=0.0, highlight=False, engine='auto', threads=None)"
)]
#[allow(clippy::too_many_arguments)]
pub fn render_with_tape<'py>(
    py: Python<'py>,
    rgb: &Bound<'py, PyAny>,
    alpha: &Bound<'py, PyAny>,
    disparity: &Bound<'py, PyAny>,
    focus: f64,
    blur: f64,
    preset: &str,
    aperture: Option<Bound<'py, PyAny>>,
    window: Option<usize>,
    gamma: f64,
    offset: f64,
    highlight: bool,
    engine: &str,
    threads: Option<usize>,
) -> PyResult<(Bound<'py, PyAny>, Tape)> {
    let workers = Workers::new(threads)?;
    let arrays = stack_args(rgb, alpha, disparity)?;
    let c = ViewArgs {
        focus: Some(focus),
        focus_at: None,
        blur,
        preset,
        window,
        gamma,
        offset,
        highlight,
        engine,
    };
    match Precision::of(&[&arrays[0], &arrays[1], &arrays[2]]) {
        Precision::F32 => {
            let (img, t, shape) = record(
                py,
                prepare::<f32>(py, &arrays, &c, aperture.as_ref(), &workers)?,
                &workers,
            )?;
            Ok((
                img,
                Tape {
                    inner: TapeInner::F32(t),
                    shape,
                },
            ))
        }
        Precision::F64 => {
            let (img, t, shape) = record(
                py,
                prepare::<f64>(py, &arrays, &c, aperture.as_ref(), &workers)?,
                &workers,
            )?;
            Ok((
                img,
                Tape {
                    inner: TapeInner::F64(t),
                    shape,
                },
            ))
        }
    }
}

type Recorded<'py, T> = (Bound<'py, PyAny>, drbokeh::Tape<T>, [usize; 3]);

fn record<'py, T: Float>(
    py: Python<'py>,
    p: Prepared<T>,
    workers: &Workers,
) -> PyResult<Recorded<'py, T>> {
    let shape = [p.stack.layers.len(), p.stack.height, p.stack.width];
    let (img, tape) = py
        .detach(|| {
            workers
                .run(|| drbokeh::render_with_tape_on(&p.stack, &p.settings, p.engine, &NoProgress))
        })
        .or_raise()?;
    Ok((image_to_py(py, img), tape, shape))
}

/// Vector-Jacobian product of `render`: the gradient of `sum(grad_output * render)` with
/// respect to every input, exactly what `drbokeh vjp` writes: a dict with `rgb (N,H,W,3)`,
/// `alpha (N,H,W)`, `disparity (N,H,W)`, and 0-d arrays `blur` (d/dK) and `focus` (d/df).
/// float64 if any array (`grad_output` included) is float64. Options as `render`;
/// `rescale_small_gradients` applies the published kernel's training heuristic (values
/// of magnitude in [1e-6, 1e-2) raised to 1e-2), after which it is no longer the exact
/// gradient.
#[pyfunction]
#[pyo3(signature = (rgb, alpha, disparity, grad_output, *, focus, blur, preset="physical", aperture=None, window=None, gamma=2.2, offset=0.0, highlight=false, engine="auto", threads=None, rescale_small_gradients=false))]
#[pyo3(
    text_signature = "(rgb, alpha, disparity, grad_output, *, focus, blur, preset='physical', aperture='circle', window=None, gamma=2.2, offset=0.0, highlight=False, engine='auto', threads=None, rescale_small_gradients=False)"
)]
#[allow(clippy::too_many_arguments)]
pub fn vjp<'py>(
    py: Python<'py>,
    rgb: &Bound<'py, PyAny>,
    alpha: &Bound<'py, PyAny>,
    disparity: &Bound<'py, PyAny>,
    grad_output: &Bound<'py, PyAny>,
    focus: f64,
    blur: f64,
    preset: &str,
    aperture: Option<Bound<'py, PyAny>>,
    window: Option<usize>,
    gamma: f64,
    offset: f64,
    highlight: bool,
    engine: &str,
    threads: Option<usize>,
    rescale_small_gradients: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let workers = Workers::new(threads)?;
    let arrays = stack_args(rgb, alpha, disparity)?;
    let g = ArrayArg::new("grad_output", grad_output)?;
    let c = ViewArgs {
        focus: Some(focus),
        focus_at: None,
        blur,
        preset,
        window,
        gamma,
        offset,
        highlight,
        engine,
    };
    match Precision::of(&[&arrays[0], &arrays[1], &arrays[2], &g]) {
        Precision::F32 => {
            let p = prepare::<f32>(py, &arrays, &c, aperture.as_ref(), &workers)?;
            let shape = [p.stack.layers.len(), p.stack.height, p.stack.width];
            check_grad_shape(&g, shape)?;
            let (_, tape, shape) = record(py, p, &workers)?;
            backward_typed(py, &tape, &g, shape, rescale_small_gradients, &workers)
        }
        Precision::F64 => {
            let p = prepare::<f64>(py, &arrays, &c, aperture.as_ref(), &workers)?;
            let shape = [p.stack.layers.len(), p.stack.height, p.stack.width];
            check_grad_shape(&g, shape)?;
            let (_, tape, shape) = record(py, p, &workers)?;
            backward_typed(py, &tape, &g, shape, rescale_small_gradients, &workers)
        }
    }
}

fn check_grad_shape(g: &ArrayArg, [_, h, w]: [usize; 3]) -> PyResult<()> {
    if g.shape() != [h, w, 3] {
        return Err(value_error(format!(
            "grad_output has shape {}, but the render is {}",
            shape_str(&g.shape()),
            shape_str(&[h, w, 3])
        )));
    }
    Ok(())
}

/// For the overhead benchmark (`crates/drbokeh-py/bench/overhead.py`): converts the stack
/// once, then times `repeats` calls of the library's `drbokeh::render` alone (no argument
/// conversion, no output array), with the GIL released. Returns the seconds of each call.
#[pyfunction]
#[pyo3(signature = (rgb, alpha, disparity, *, focus, blur, preset="physical", window=None, engine="auto", threads=None, repeats=1))]
#[allow(clippy::too_many_arguments)]
pub fn time_library_render(
    py: Python<'_>,
    rgb: &Bound<'_, PyAny>,
    alpha: &Bound<'_, PyAny>,
    disparity: &Bound<'_, PyAny>,
    focus: f64,
    blur: f64,
    preset: &str,
    window: Option<usize>,
    engine: &str,
    threads: Option<usize>,
    repeats: usize,
) -> PyResult<Vec<f64>> {
    fn timed<T: Float>(
        py: Python<'_>,
        p: Prepared<T>,
        workers: &Workers,
        repeats: usize,
    ) -> PyResult<Vec<f64>> {
        py.detach(|| {
            workers.run(|| {
                (0..repeats)
                    .map(|_| {
                        let t0 = std::time::Instant::now();
                        let out = drbokeh::render(&p.stack, &p.settings, p.engine, &NoProgress)?;
                        let s = t0.elapsed().as_secs_f64();
                        drop(out);
                        Ok(s)
                    })
                    .collect::<drbokeh::Result<Vec<f64>>>()
            })
        })
        .or_raise()
    }
    let workers = Workers::new(threads)?;
    let arrays = stack_args(rgb, alpha, disparity)?;
    let c = ViewArgs {
        focus: Some(focus),
        focus_at: None,
        blur,
        preset,
        window,
        gamma: 2.2,
        offset: 0.0,
        highlight: false,
        engine,
    };
    match Precision::of(&[&arrays[0], &arrays[1], &arrays[2]]) {
        Precision::F32 => timed(
            py,
            prepare::<f32>(py, &arrays, &c, None, &workers)?,
            &workers,
            repeats,
        ),
        Precision::F64 => timed(
            py,
            prepare::<f64>(py, &arrays, &c, None, &workers)?,
            &workers,
            repeats,
        ),
    }
}
