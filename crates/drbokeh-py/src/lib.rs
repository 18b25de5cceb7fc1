//! `drbokeh._native`: the Python bindings of the drbokeh library (PyO3 + NumPy). The
//! `drbokeh` Python package (`python/drbokeh`) re-exports these functions and adds the
//! PyTorch layer (`drbokeh.torch`). This crate only converts arrays and options and calls
//! the library; the GIL is released while the library works.

mod convert;
mod data;
mod errors;
mod layers;
mod policy;
mod pool;
mod render;
mod scene;

use pyo3::prelude::*;

/// The compiled part of the `drbokeh` package (use `drbokeh`, not this module).
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add(
        "DrBokehWarning",
        m.py().get_type::<render::DrBokehWarning>(),
    )?;
    m.add_class::<render::Tape>()?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_with_tape, m)?)?;
    m.add_function(wrap_pyfunction!(render::vjp, m)?)?;
    m.add_function(wrap_pyfunction!(render::time_library_render, m)?)?;
    m.add_function(wrap_pyfunction!(layers::aperture_layer, m)?)?;
    m.add_function(wrap_pyfunction!(scene::render_image, m)?)?;
    m.add_function(wrap_pyfunction!(scene::decompose, m)?)?;
    m.add_function(wrap_pyfunction!(data::load_stack, m)?)?;
    m.add_function(wrap_pyfunction!(data::save_stack, m)?)?;
    m.add_function(wrap_pyfunction!(data::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(data::read_disparity, m)?)?;
    m.add_function(wrap_pyfunction!(data::read_matte, m)?)?;
    m.add_function(wrap_pyfunction!(data::benchmark_scenes, m)?)?;
    m.add_function(wrap_pyfunction!(data::load_benchmark_scene, m)?)?;
    m.add_function(wrap_pyfunction!(data::trace_scene, m)?)?;
    m.add_function(wrap_pyfunction!(data::demo, m)?)?;
    Ok(())
}
