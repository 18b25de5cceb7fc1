//! The data path: layer stacks (NPZ), images, disparity maps and mattes, the ray-traced
//! benchmark and the path tracer, and the built-in demo scene.

use crate::convert::{image_to_py, stack_from, stack_to_py, Precision};
use crate::errors::{value_error, OrRaise};
use crate::pool::Workers;
use crate::render::stack_args;
use drbokeh::io::{self, DepthKind, DisparityOptions};
use drbokeh::trace::{self, SceneSpec};
use drbokeh::NoProgress;
use numpy::{PyArrayDescr, PyArrayDescrMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};

/// The precision a `dtype=` argument asks for (float32 when `None`).
fn precision_arg(py: Python<'_>, dtype: Option<&Bound<'_, PyAny>>) -> PyResult<Precision> {
    let Some(d) = dtype else {
        return Ok(Precision::F32);
    };
    let d = py
        .import("numpy")?
        .call_method1("dtype", (d,))?
        .cast_into::<PyArrayDescr>()
        .map_err(|_| value_error("dtype: not a NumPy dtype"))?;
    if d.is_equiv_to(&numpy::dtype::<f32>(py)) {
        Ok(Precision::F32)
    } else if d.is_equiv_to(&numpy::dtype::<f64>(py)) {
        Ok(Precision::F64)
    } else {
        Err(value_error(format!(
            "dtype must be float32 or float64, got {d}"
        )))
    }
}

/// Runs `$body` with `$t` bound to `f32` or `f64` as `$precision` says.
macro_rules! typed {
    ($precision:expr, $t:ident => $body:expr) => {
        match $precision {
            Precision::F32 => {
                type $t = f32;
                $body
            }
            Precision::F64 => {
                type $t = f64;
                $body
            }
        }
    };
}

/// Reads a layer stack NPZ (`rgb (N,H,W,3)`, `alpha (N,H,W)`, `disparity (N,H,W)`; uint8
/// and uint16 colour scaled to [0, 1]) and validates it, as `drbokeh render --layers`.
/// Returns `{"rgb", "alpha", "disparity"}` arrays of `dtype` (float32 by default).
#[pyfunction]
#[pyo3(signature = (path, *, dtype=None))]
pub fn load_stack<'py>(
    py: Python<'py>,
    path: PathBuf,
    dtype: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    typed!(precision_arg(py, dtype.as_ref())?, T => {
        let stack = py.detach(|| io::read_stack::<T>(&path)).or_raise()?;
        stack_to_py(py, &stack)
    })
}

/// Writes a layer stack as NPZ (float32 `rgb`, `alpha`, `disparity`), atomically (the file
/// appears only once complete). The stack is validated first.
#[pyfunction]
pub fn save_stack(
    py: Python<'_>,
    path: PathBuf,
    rgb: &Bound<'_, PyAny>,
    alpha: &Bound<'_, PyAny>,
    disparity: &Bound<'_, PyAny>,
) -> PyResult<()> {
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npz"))
    {
        return Err(value_error(format!(
            "{}: the layer stack is written as NPZ: use a .npz output name",
            path.display()
        )));
    }
    let arrays = stack_args(rgb, alpha, disparity)?;
    typed!(Precision::of(&[&arrays[0], &arrays[1], &arrays[2]]), T => {
        let stack = stack_from::<T>(&arrays[0], &arrays[1], &arrays[2])?;
        py.detach(|| io::write_stack(&path, &stack)).or_raise()
    })
}

/// Whether an image file holds linear light (EXR) rather than display-encoded values.
fn is_linear(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// Reads a colour image (PNG 8/16-bit, JPEG, TIFF, EXR) as `(H,W,3)` values as stored:
/// returns `(rgb, encoding)` where `encoding` is `"encoded"` (display-encoded, PNG, JPEG,
/// TIFF; scaled to [0, 1]) or `"linear"` (EXR, linear light: pass `linear=True` to
/// `render_image`). Grey images are replicated to RGB; an alpha channel is ignored.
#[pyfunction]
#[pyo3(signature = (path, *, dtype=None))]
pub fn read_image<'py>(
    py: Python<'py>,
    path: PathBuf,
    dtype: Option<Bound<'py, PyAny>>,
) -> PyResult<(Bound<'py, PyAny>, &'static str)> {
    let encoding = if is_linear(&path) {
        "linear"
    } else {
        "encoded"
    };
    typed!(precision_arg(py, dtype.as_ref())?, T => {
        let img = py.detach(|| io::read_rgb::<T>(&path)).or_raise()?;
        Ok((image_to_py(py, img), encoding))
    })
}

/// Reads a disparity map (larger = nearer; 16-bit PNG, EXR, NPY, or NPZ key `data`) as
/// `(H,W)`, as `drbokeh render --disparity` does: min-max normalised to [0, 1] unless
/// `normalize=False`. `depth=True` reads metric depth (larger = farther) and converts it to
/// disparity 1/z first, as `--depth`.
#[pyfunction]
#[pyo3(signature = (path, *, depth=false, normalize=true, dtype=None))]
pub fn read_disparity<'py>(
    py: Python<'py>,
    path: PathBuf,
    depth: bool,
    normalize: bool,
    dtype: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let options = DisparityOptions {
        kind: if depth {
            DepthKind::Depth
        } else {
            DepthKind::Disparity
        },
        normalize,
    };
    typed!(precision_arg(py, dtype.as_ref())?, T => {
        let img = py.detach(|| io::read_disparity::<T>(&path, options)).or_raise()?;
        Ok(image_to_py(py, img))
    })
}

/// Reads an alpha matte (a grey image, or the alpha channel of a grey+alpha or RGBA image;
/// NPY/NPZ arrays too) as `(H,W)` values in [0, 1], as `drbokeh render --alpha`.
#[pyfunction]
#[pyo3(signature = (path, *, dtype=None))]
pub fn read_matte<'py>(
    py: Python<'py>,
    path: PathBuf,
    dtype: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    typed!(precision_arg(py, dtype.as_ref())?, T => {
        let img = py.detach(|| io::read_matte::<T>(&path)).or_raise()?;
        Ok(image_to_py(py, img))
    })
}

/// The scene directories of a benchmark made by `drbokeh benchmark make`, sorted.
#[pyfunction]
pub fn benchmark_scenes(benchmark: PathBuf) -> PyResult<Vec<PathBuf>> {
    drbokeh::eval::report::list_scenes(&benchmark).or_raise()
}

/// Loads one benchmark scene directory as a dict (see `drbokeh.load_benchmark`).
#[pyfunction]
pub fn load_benchmark_scene<'py>(py: Python<'py>, dir: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let s = py
        .detach(|| drbokeh::eval::report::SceneInputs::load(&dir))
        .or_raise()?;
    let cam = s.camera();
    let d = PyDict::new(py);
    d.set_item("name", &s.name)?;
    d.set_item("path", &s.dir)?;
    d.set_item("aif", image_to_py(py, s.aif))?;
    d.set_item("disparity", image_to_py(py, s.disparity))?;
    d.set_item("layers", stack_to_py(py, &s.layers)?)?;
    d.set_item("ground_truth", image_to_py(py, s.ground_truth))?;
    d.set_item("camera", camera_dict(py, &cam)?)?;
    d.set_item("max_coc_px", s.max_coc_px)?;
    Ok(d)
}

/// A camera as `render`'s keyword arguments.
fn camera_dict<'py>(py: Python<'py>, cam: &drbokeh::Camera) -> PyResult<Bound<'py, PyDict>> {
    let c = PyDict::new(py);
    c.set_item("focus", cam.focus_disparity)?;
    c.set_item("blur", cam.blur_k)?;
    c.set_item("window", cam.window.size())?;
    c.set_item("gamma", cam.gamma)?;
    c.set_item("offset", cam.offset)?;
    c.set_item("highlight", cam.highlight.is_some())?;
    Ok(c)
}

/// Path-traces a billboard scene (JSON, as `drbokeh trace`) through its lens, in memory.
/// `spp` and `seed` override the scene's `render.spp` / `render.seed`. Returns a dict:
/// `bokeh` and `aif` (display-encoded with the exact sRGB curve, not clipped, `(H,W,3)`),
/// `bokeh_linear` and `aif_linear` (linear light), `depth_mm` and `disparity` `(H,W)`,
/// `layers` (the layered ground truth as a stack dict) and `camera` (`focus` and `blur`:
/// the renderer's equivalent of the lens). All float32.
#[pyfunction(name = "trace")]
#[pyo3(signature = (scene, *, spp=None, seed=None, threads=None))]
pub fn trace_scene<'py>(
    py: Python<'py>,
    scene: PathBuf,
    spp: Option<usize>,
    seed: Option<u64>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let workers = Workers::new(threads)?;
    let mut spec = SceneSpec::read(&scene).or_raise()?;
    if let Some(spp) = spp {
        spec.render.spp = spp;
    }
    if let Some(seed) = seed {
        spec.render.seed = seed;
    }
    spec.validate().map_err(|e| e.in_file(&scene)).or_raise()?;
    let base_dir = match scene.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let (loaded, outputs, stack) = py
        .detach(|| {
            workers.run(|| -> drbokeh::Result<_> {
                let loaded = spec.load(&base_dir)?;
                let outputs = trace::trace_scene(&loaded, &spec.render, &NoProgress)?;
                let stack = trace::layer_stack(&loaded, &outputs.pinhole)?;
                Ok((loaded, outputs, stack))
            })
        })
        .or_raise()?;
    let disparity = loaded.disparity_map(&outputs.pinhole.depth_mm);
    let d = PyDict::new(py);
    d.set_item(
        "bokeh",
        image_to_py(py, trace::encode_image(&outputs.defocus_linear)),
    )?;
    d.set_item(
        "aif",
        image_to_py(py, trace::encode_image(&outputs.pinhole.aif_linear)),
    )?;
    d.set_item("bokeh_linear", image_to_py(py, outputs.defocus_linear))?;
    d.set_item("aif_linear", image_to_py(py, outputs.pinhole.aif_linear))?;
    d.set_item("depth_mm", image_to_py(py, outputs.pinhole.depth_mm))?;
    d.set_item("disparity", image_to_py(py, disparity))?;
    d.set_item("layers", stack_to_py(py, &stack)?)?;
    let cam = PyDict::new(py);
    cam.set_item("focus", loaded.focus_disparity())?;
    cam.set_item("blur", loaded.blur_k_px())?;
    d.set_item("camera", cam)?;
    Ok(d)
}

/// The built-in demo scene (`drbokeh render --demo`): a three-layer stack dict (`rgb`,
/// `alpha`, `disparity`) of `width x height`, and `focus`, the disparity of its subject.
#[pyfunction]
#[pyo3(signature = (width=640, height=426, *, dtype=None))]
pub fn demo<'py>(
    py: Python<'py>,
    width: usize,
    height: usize,
    dtype: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    drbokeh::image::check_dimensions("demo size", width, height).or_raise()?;
    typed!(precision_arg(py, dtype.as_ref())?, T => {
        let stack = py.detach(|| drbokeh::demo::scene::<T>(width, height));
        let d = stack_to_py(py, &stack)?;
        d.set_item("focus", drbokeh::demo::DEMO_FOCUS)?;
        Ok(d)
    })
}
