//! NPZ layer stacks: keys `rgb` (N,H,W,3), `alpha` (N,H,W), `disparity` (N,H,W); float32 or
//! float64; uint8/uint16 colour is scaled to [0, 1].

use super::files::{open, write_atomic};
use crate::engine::Gradients;
use crate::image::{check_dimensions, Image};
use crate::stack::{Layer, LayerStack};
use crate::{Error, Real, Result};
use ndarray::{ArrayD, IxDyn};
use ndarray_npy::{NpzReader, NpzWriter};
use std::path::Path;

/// Reads array `name` of any supported dtype as f64; integer arrays are scaled to [0, 1]
/// when `scale_integers` (colour), rejected otherwise.
pub(crate) fn read_any<R: std::io::Read + std::io::Seek>(
    npz: &mut NpzReader<R>,
    name: &str,
    scale_integers: bool,
) -> std::result::Result<ArrayD<f64>, String> {
    let first_err = match npz.by_name::<ndarray::OwnedRepr<f32>, IxDyn>(name) {
        Ok(a) => return Ok(a.mapv(|v| v as f64)),
        Err(e) => e.to_string(),
    };
    if let Ok(a) = npz.by_name::<ndarray::OwnedRepr<f64>, IxDyn>(name) {
        return Ok(a);
    }
    if let Ok(a) = npz.by_name::<ndarray::OwnedRepr<u8>, IxDyn>(name) {
        return if scale_integers {
            Ok(a.mapv(|v| v as f64 / 255.0))
        } else {
            Err(format!(
                "key '{name}' is uint8; expected float32 or float64"
            ))
        };
    }
    if let Ok(a) = npz.by_name::<ndarray::OwnedRepr<u16>, IxDyn>(name) {
        return if scale_integers {
            Ok(a.mapv(|v| v as f64 / 65535.0))
        } else {
            Err(format!(
                "key '{name}' is uint16; expected float32 or float64"
            ))
        };
    }
    Err(format!(
        "cannot read key '{name}' as float32, float64, uint8 or uint16: {first_err}"
    ))
}

/// Reads a layer stack from an NPZ file and validates it.
pub fn read_stack<T: Real>(path: &Path) -> Result<LayerStack<T>> {
    let fail = |p: String| Error::file(path, p);
    let mut npz = NpzReader::new(open(path)?)
        .map_err(|e| fail(format!("not a readable NPZ archive: {e}")))?;
    let names = npz
        .names()
        .map_err(|e| fail(format!("corrupt NPZ archive: {e}")))?;
    for key in ["rgb", "alpha", "disparity"] {
        if !names.iter().any(|n| n == key) {
            return Err(fail(format!(
                "missing key '{key}' (found: {}); a stack needs rgb (N,H,W,3), alpha (N,H,W), disparity (N,H,W)",
                names.join(", ")
            )));
        }
    }
    let rgb = read_any(&mut npz, "rgb", true).map_err(fail)?;
    let alpha = read_any(&mut npz, "alpha", false).map_err(fail)?;
    let disparity = read_any(&mut npz, "disparity", false).map_err(fail)?;
    let s = rgb.shape().to_vec();
    if s.len() != 4 || s[3] != 3 {
        return Err(fail(format!(
            "key 'rgb' has shape {s:?}, expected (N, H, W, 3)"
        )));
    }
    let (n, h, w) = (s[0], s[1], s[2]);
    if n == 0 {
        return Err(fail("the stack has no layers (N = 0)".into()));
    }
    check_dimensions("layer stack", w, h).map_err(|e| e.in_file(path))?;
    for (key, arr) in [("alpha", &alpha), ("disparity", &disparity)] {
        if arr.shape() != [n, h, w] {
            return Err(fail(format!(
                "key '{key}' has shape {:?}, expected {:?} to match 'rgb'",
                arr.shape(),
                [n, h, w]
            )));
        }
    }
    let plane = |arr: &ArrayD<f64>, l: usize| -> Vec<T> {
        arr.index_axis(ndarray::Axis(0), l)
            .iter()
            .map(|&v| T::c(v))
            .collect()
    };
    let layers = (0..n)
        .map(|l| Layer {
            rgb_encoded: Image::from_vec(w, h, 3, plane(&rgb, l)).unwrap(),
            alpha: Image::from_vec(w, h, 1, plane(&alpha, l)).unwrap(),
            disparity: Image::from_vec(w, h, 1, plane(&disparity, l)).unwrap(),
        })
        .collect();
    LayerStack::new(layers).map_err(|e| e.in_file(path))
}

/// Writes a layer stack as an NPZ file (float32 arrays `rgb`, `alpha`, `disparity`).
pub fn write_stack<T: Real>(path: &Path, stack: &LayerStack<T>) -> Result<()> {
    let (n, h, w) = (stack.layers.len(), stack.height, stack.width);
    let collect = |f: &dyn Fn(&Layer<T>) -> &Image<T>| -> Vec<f32> {
        stack
            .layers
            .iter()
            .flat_map(|l| f(l).data.iter().map(|v| v.f64() as f32))
            .collect()
    };
    let rgb = ndarray::Array4::from_shape_vec((n, h, w, 3), collect(&|l| &l.rgb_encoded)).unwrap();
    let alpha = ndarray::Array3::from_shape_vec((n, h, w), collect(&|l| &l.alpha)).unwrap();
    let disp = ndarray::Array3::from_shape_vec((n, h, w), collect(&|l| &l.disparity)).unwrap();
    write_atomic(path, |out| {
        let err = |e: ndarray_npy::WriteNpzError| Error::file(path, format!("write failed: {e}"));
        let mut npz = NpzWriter::new_compressed(out);
        npz.add_array("rgb", &rgb).map_err(err)?;
        npz.add_array("alpha", &alpha).map_err(err)?;
        npz.add_array("disparity", &disp).map_err(err)?;
        npz.finish().map_err(err)?;
        Ok(())
    })
}

/// Writes gradients as NPZ: `rgb` (N,H,W,3), `alpha` (N,H,W), `disparity` (N,H,W), and the
/// scalars `blur` and `focus` (0-d arrays). float64 when `T` is f64, float32 otherwise.
pub fn write_gradients<T: Real>(
    path: &Path,
    grads: &Gradients<T>,
    width: usize,
    height: usize,
) -> Result<()> {
    fn write_typed<
        E: ndarray_npy::WritableElement + Copy,
        T: Real,
        W: std::io::Write + std::io::Seek,
    >(
        out: W,
        grads: &Gradients<T>,
        (w, h): (usize, usize),
        conv: impl Fn(T) -> E,
        err: impl Fn(ndarray_npy::WriteNpzError) -> Error,
    ) -> Result<()> {
        let n = grads.layers.len();
        let cat = |f: &dyn Fn(&crate::engine::LayerGradients<T>) -> &Image<T>| -> Vec<E> {
            grads
                .layers
                .iter()
                .flat_map(|l| f(l).data.iter().map(|&v| conv(v)))
                .collect()
        };
        let mut npz = NpzWriter::new(out);
        npz.add_array(
            "rgb",
            &ndarray::Array4::from_shape_vec((n, h, w, 3), cat(&|l| &l.rgb)).unwrap(),
        )
        .map_err(&err)?;
        npz.add_array(
            "alpha",
            &ndarray::Array3::from_shape_vec((n, h, w), cat(&|l| &l.alpha)).unwrap(),
        )
        .map_err(&err)?;
        npz.add_array(
            "disparity",
            &ndarray::Array3::from_shape_vec((n, h, w), cat(&|l| &l.disparity)).unwrap(),
        )
        .map_err(&err)?;
        npz.add_array("blur", &ndarray::arr0(conv(T::c(grads.blur_k))))
            .map_err(&err)?;
        npz.add_array("focus", &ndarray::arr0(conv(T::c(grads.focus))))
            .map_err(&err)?;
        npz.finish().map_err(&err)?;
        Ok(())
    }
    write_atomic(path, |out| {
        let err = |e: ndarray_npy::WriteNpzError| Error::file(path, format!("write failed: {e}"));
        if std::any::TypeId::of::<T>() == std::any::TypeId::of::<f64>() {
            write_typed(out, grads, (width, height), |v: T| v.f64(), err)
        } else {
            write_typed(out, grads, (width, height), |v: T| v.f64() as f32, err)
        }
    })
}
