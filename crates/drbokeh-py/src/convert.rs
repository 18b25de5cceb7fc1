//! NumPy arrays in and out. Inputs are float32 or float64, C-contiguous or not (any
//! strides); each is copied once into the library's planes, converting on the way when the
//! computation's precision differs. Outputs hand the library's buffers to NumPy without a
//! copy.

use crate::errors::{value_error, OrRaise};
use drbokeh::{Image, Layer, LayerStack};
use numpy::ndarray::{Array, ArrayViewD, Axis, IxDyn};
use numpy::{
    IntoPyArray, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The precision a call computes in: float64 if any array argument is float64 (as NumPy
/// promotes), float32 otherwise. float64 also selects the exact engine for `engine="auto"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// float32.
    F32,
    /// float64.
    F64,
}

impl Precision {
    /// The promoted precision of several arguments.
    pub fn of(args: &[&ArrayArg<'_>]) -> Precision {
        if args.iter().any(|a| a.precision == Precision::F64) {
            Precision::F64
        } else {
            Precision::F32
        }
    }
}

/// The library's real types, as NumPy elements.
pub trait Float: drbokeh::Real + numpy::Element {
    /// This type's [`Precision`].
    const PRECISION: Precision;
    /// Converts (exactly, or rounding to nearest for f64 -> f32).
    fn of_f32(v: f32) -> Self;
    /// Converts (exactly, or rounding to nearest for f64 -> f32).
    fn of_f64(v: f64) -> Self;
}

impl Float for f32 {
    const PRECISION: Precision = Precision::F32;
    #[inline(always)]
    fn of_f32(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn of_f64(v: f64) -> Self {
        v as f32
    }
}

impl Float for f64 {
    const PRECISION: Precision = Precision::F64;
    #[inline(always)]
    fn of_f32(v: f32) -> Self {
        v as f64
    }
    #[inline(always)]
    fn of_f64(v: f64) -> Self {
        v
    }
}

/// A float32 or float64 array argument, named as the user passed it.
pub struct ArrayArg<'py> {
    /// The argument's name, for messages.
    pub name: &'static str,
    array: Bound<'py, PyUntypedArray>,
    /// Its element type.
    pub precision: Precision,
}

/// `(2, 3, 4)`, as NumPy prints shapes.
pub fn shape_str(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

impl<'py> ArrayArg<'py> {
    /// Takes a NumPy array (anything else goes through `numpy.asarray`); fails unless its
    /// dtype is float32 or float64.
    pub fn new(name: &'static str, obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        let py = obj.py();
        let array = match obj.cast::<PyUntypedArray>() {
            Ok(a) => a.clone(),
            Err(_) => py
                .import("numpy")?
                .call_method1("asarray", (obj,))?
                .cast_into::<PyUntypedArray>()
                .map_err(|_| value_error(format!("{name} is not an array")))?,
        };
        let dtype = array.dtype();
        let precision = if dtype.is_equiv_to(&numpy::dtype::<f32>(py)) {
            Precision::F32
        } else if dtype.is_equiv_to(&numpy::dtype::<f64>(py)) {
            Precision::F64
        } else {
            return Err(value_error(format!(
                "{name} has dtype {dtype}; expected float32 or float64"
            )));
        };
        Ok(ArrayArg {
            name,
            array,
            precision,
        })
    }

    /// The array's shape.
    pub fn shape(&self) -> Vec<usize> {
        self.array.shape().to_vec()
    }

    /// Copies the array (`split`: each sub-array along the first axis separately) into
    /// row-major buffers of `T`: one pass over the input, whatever its strides.
    pub fn planes<T: Float>(&self, split: bool) -> PyResult<Vec<Vec<T>>> {
        fn copy<S: Copy, T: Float>(
            view: ArrayViewD<'_, S>,
            split: bool,
            conv: impl Fn(S) -> T + Copy,
        ) -> Vec<Vec<T>> {
            let one = |v: ArrayViewD<'_, S>| -> Vec<T> {
                match v.as_slice() {
                    Some(s) => s.iter().map(|&x| conv(x)).collect(),
                    None => v.iter().map(|&x| conv(x)).collect(),
                }
            };
            if split {
                view.axis_iter(Axis(0)).map(one).collect()
            } else {
                vec![one(view)]
            }
        }
        let borrow_error = |e: numpy::BorrowError| {
            value_error(format!("{}: cannot read the array: {e}", self.name))
        };
        Ok(match self.precision {
            Precision::F32 => {
                let a = self.array.cast::<PyArrayDyn<f32>>()?;
                let r = a.try_readonly().map_err(borrow_error)?;
                copy(r.as_array(), split, T::of_f32)
            }
            Precision::F64 => {
                let a = self.array.cast::<PyArrayDyn<f64>>()?;
                let r = a.try_readonly().map_err(borrow_error)?;
                copy(r.as_array(), split, T::of_f64)
            }
        })
    }

    /// The array as one image: `(H, W, channels)`, or `(H, W)` for one channel.
    pub fn image<T: Float>(&self, channels: usize) -> PyResult<Image<T>> {
        let s = self.shape();
        let (h, w) = match s.as_slice() {
            [h, w, c] if *c == channels => (*h, *w),
            [h, w] if channels == 1 => (*h, *w),
            _ => {
                let want = if channels == 1 {
                    "(H, W)".to_string()
                } else {
                    format!("(H, W, {channels})")
                };
                return Err(value_error(format!(
                    "{} has shape {}, expected {want}",
                    self.name,
                    shape_str(&s)
                )));
            }
        };
        drbokeh::image::check_dimensions(self.name, w, h).or_raise()?;
        let data = self.planes::<T>(false)?.pop().unwrap_or_default();
        Image::from_vec(w, h, channels, data).or_raise()
    }
}

/// Checks the stack convention (`rgb (N,H,W,3)`, `alpha (N,H,W)`, `disparity (N,H,W)`) and
/// returns `(N, H, W)`.
pub fn stack_shape(rgb: &ArrayArg, alpha: &ArrayArg, disparity: &ArrayArg) -> PyResult<[usize; 3]> {
    let s = rgb.shape();
    if s.len() != 4 || s[3] != 3 {
        return Err(value_error(format!(
            "{} has shape {}, expected (N, H, W, 3) (layers front first)",
            rgb.name,
            shape_str(&s)
        )));
    }
    let (n, h, w) = (s[0], s[1], s[2]);
    if n == 0 {
        return Err(value_error("the stack has no layers (N = 0)"));
    }
    drbokeh::image::check_dimensions("layer stack", w, h).or_raise()?;
    for a in [alpha, disparity] {
        if a.shape() != [n, h, w] {
            return Err(value_error(format!(
                "{} has shape {}, expected {} to match {}",
                a.name,
                shape_str(&a.shape()),
                shape_str(&[n, h, w]),
                rgb.name
            )));
        }
    }
    Ok([n, h, w])
}

/// Builds (and validates: finite, colour >= 0, alpha in [0, 1]) a layer stack.
pub fn stack_from<T: Float>(
    rgb: &ArrayArg,
    alpha: &ArrayArg,
    disparity: &ArrayArg,
) -> PyResult<LayerStack<T>> {
    let [_, h, w] = stack_shape(rgb, alpha, disparity)?;
    let layers = rgb
        .planes::<T>(true)?
        .into_iter()
        .zip(alpha.planes::<T>(true)?)
        .zip(disparity.planes::<T>(true)?)
        .map(|((c, a), d)| {
            Ok(Layer {
                rgb_encoded: Image::from_vec(w, h, 3, c).or_raise()?,
                alpha: Image::from_vec(w, h, 1, a).or_raise()?,
                disparity: Image::from_vec(w, h, 1, d).or_raise()?,
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    LayerStack::new(layers).or_raise()
}

/// An image as a NumPy array `(H, W, C)` (`(H, W)` for one channel), without a copy.
pub fn image_to_py<T: Float>(py: Python<'_>, image: Image<T>) -> Bound<'_, PyAny> {
    let dims: Vec<usize> = if image.channels == 1 {
        vec![image.height, image.width]
    } else {
        vec![image.height, image.width, image.channels]
    };
    Array::from_shape_vec(IxDyn(&dims), image.data)
        .expect("an image's buffer matches its shape")
        .into_pyarray(py)
        .into_any()
}

/// Planes of one size stacked along a new first axis: `(N, H, W, C)` (`(N, H, W)` for one
/// channel).
pub fn planes_to_py<'py, T: Float>(py: Python<'py>, planes: &[&Image<T>]) -> Bound<'py, PyAny> {
    let first = planes[0];
    let mut dims = vec![planes.len(), first.height, first.width];
    if first.channels != 1 {
        dims.push(first.channels);
    }
    let mut data = Vec::with_capacity(planes.iter().map(|p| p.data.len()).sum());
    for p in planes {
        data.extend_from_slice(&p.data);
    }
    Array::from_shape_vec(IxDyn(&dims), data)
        .expect("planes of one size")
        .into_pyarray(py)
        .into_any()
}

/// A scalar as a 0-d array of `T` (as the NPZ files of `drbokeh vjp` store them).
pub fn scalar_to_py<T: Float>(py: Python<'_>, v: f64) -> Bound<'_, PyAny> {
    numpy::ndarray::arr0(T::of_f64(v))
        .into_dyn()
        .into_pyarray(py)
        .into_any()
}

/// A stack as `{"rgb": (N,H,W,3), "alpha": (N,H,W), "disparity": (N,H,W)}`.
pub fn stack_to_py<'py, T: Float>(
    py: Python<'py>,
    stack: &LayerStack<T>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let layers = &stack.layers;
    d.set_item(
        "rgb",
        planes_to_py(
            py,
            &layers.iter().map(|l| &l.rgb_encoded).collect::<Vec<_>>(),
        ),
    )?;
    d.set_item(
        "alpha",
        planes_to_py(py, &layers.iter().map(|l| &l.alpha).collect::<Vec<_>>()),
    )?;
    d.set_item(
        "disparity",
        planes_to_py(py, &layers.iter().map(|l| &l.disparity).collect::<Vec<_>>()),
    )?;
    Ok(d)
}
