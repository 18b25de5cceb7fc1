//! NPZ layer stacks: keys `rgb` (N,H,W,3), `alpha` (N,H,W), `disparity` (N,H,W); float32 or
//! float64; uint8/uint16 colour is scaled to [0, 1].

use super::files::open;
use super::npy::{self, Header, Integers};
use super::staging::Staging;
use crate::engine::Gradients;
use crate::image::{check_dimensions, Image};
use crate::stack::{Layer, LayerStack};
use crate::{budget, Error, Real, Result};
use ndarray_npy::NpzWriter;
use std::io::Read;
use std::path::Path;

/// An NPZ archive opened for header-first reads.
pub(crate) struct Npz {
    zip: zip::ZipArchive<std::io::BufReader<std::fs::File>>,
    path: std::path::PathBuf,
}

impl Npz {
    /// Opens an archive (reads only its central directory).
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let zip = zip::ZipArchive::new(std::io::BufReader::new(open(path)?))
            .map_err(|e| Error::file(path, format!("not a readable NPZ archive: {e}")))?;
        Ok(Npz {
            zip,
            path: path.to_path_buf(),
        })
    }

    /// The array names (entry names without `.npy`).
    pub(crate) fn names(&self) -> Vec<String> {
        self.zip
            .file_names()
            .map(|n| n.strip_suffix(".npy").unwrap_or(n).to_string())
            .collect()
    }

    fn fail(&self, key: &str, problem: impl std::fmt::Display) -> Error {
        Error::file(&self.path, format!("key '{key}': {problem}"))
    }

    /// The header of array `key` (decompresses only the header's bytes).
    pub(crate) fn header(&mut self, key: &str) -> Result<Header> {
        let path = self.path.clone();
        let mut entry = self
            .zip
            .by_name(&format!("{key}.npy"))
            .map_err(|e| Error::file(&path, format!("key '{key}': {e}")))?;
        let h = npy::read_header(&mut entry)
            .map_err(|e| Error::file(&path, format!("key '{key}': {e}")))?;
        let stored = entry.size();
        drop(entry);
        if h.data_offset.saturating_add(h.data_bytes()) > stored {
            // Budget first: a huge claimed shape is reported as too large, not truncated.
            h.check_budget(&format!("{}: key '{key}'", path.display()))?;
            return Err(Error::file(
                &path,
                format!(
                    "key '{key}': truncated: the header claims shape {:?} of {} ({} bytes of data), the entry holds {}",
                    h.shape,
                    h.dtype.name(),
                    h.data_bytes(),
                    stored.saturating_sub(h.data_offset)
                ),
            ));
        }
        Ok(h)
    }

    /// Opens array `key`'s data stream positioned after its header.
    fn stream(
        &mut self,
        key: &str,
        h: &Header,
    ) -> Result<zip::read::ZipFile<'_, std::io::BufReader<std::fs::File>>> {
        let path = self.path.clone();
        let mut entry = self
            .zip
            .by_name(&format!("{key}.npy"))
            .map_err(|e| Error::file(&path, format!("key '{key}': {e}")))?;
        std::io::copy(&mut (&mut entry).take(h.data_offset), &mut std::io::sink())
            .map_err(|e| Error::file(&path, format!("key '{key}': corrupt entry: {e}")))?;
        Ok(entry)
    }

    /// Reads array `key` whose header is `h` (already checked by the caller: shape,
    /// dtype, budget) as `T` values in C order. Reads exactly the claimed data: a lying
    /// entry cannot make us read or allocate more than the checked header says.
    pub(crate) fn data<T: Real>(&mut self, key: &str, h: &Header) -> Result<Vec<T>> {
        let path = self.path.clone();
        let mut entry = self.stream(key, h)?;
        npy::read_data::<T, _>(&mut entry, h)
            .map_err(|e| Error::file(&path, format!("key '{key}': {e}")))
    }

    /// Reads array `key` (C order, checked header `h`) as `parts` consecutive pieces of
    /// `part_len` values each: one buffer per layer, without a copy of the whole array.
    pub(crate) fn data_parts<T: Real>(
        &mut self,
        key: &str,
        h: &Header,
        parts: usize,
        part_len: usize,
    ) -> Result<Vec<Vec<T>>> {
        if h.fortran_order && h.shape.len() > 1 {
            let all = self.data::<T>(key, h)?;
            return Ok(all.chunks(part_len.max(1)).map(|c| c.to_vec()).collect());
        }
        let path = self.path.clone();
        let mut entry = self.stream(key, h)?;
        (0..parts)
            .map(|i| {
                npy::read_values::<T, _>(&mut entry, h, part_len, i * part_len)
                    .map_err(|e| Error::file(&path, format!("key '{key}': {e}")))
            })
            .collect()
    }

    /// Reads array `key` entirely after checking it against the budget, its dtype policy
    /// and the accepted shapes (`shape_ok`, described by `expected` in messages).
    pub(crate) fn array<T: Real>(
        &mut self,
        key: &str,
        integers: Integers,
        shape_ok: impl Fn(&[u64]) -> bool,
        expected: &str,
    ) -> Result<(Vec<u64>, Vec<T>)> {
        let h = self.header(key)?;
        let what = format!("{}: key '{key}'", self.path.display());
        npy::check_dtype(&h, integers, &what)?;
        if !shape_ok(&h.shape) {
            return Err(self.fail(key, format!("has shape {:?}, expected {expected}", h.shape)));
        }
        h.check_budget(&what)?;
        let data = self.data(key, &h)?;
        Ok((h.shape.clone(), data))
    }
}

/// Reads a layer stack from an NPZ file and validates it. Every array's header is checked
/// (shapes agree, the stack fits the input budget) before any array is decompressed.
pub fn read_stack<T: Real>(path: &Path) -> Result<LayerStack<T>> {
    let fail = |p: String| Error::file(path, p);
    let mut npz = Npz::open(path)?;
    let names = npz.names();
    for key in ["rgb", "alpha", "disparity"] {
        if !names.iter().any(|n| n == key) {
            return Err(fail(format!(
                "missing key '{key}' (found: {}); a stack needs rgb (N,H,W,3), alpha (N,H,W), disparity (N,H,W)",
                names.join(", ")
            )));
        }
    }
    let rgb = npz.header("rgb")?;
    let alpha = npz.header("alpha")?;
    let disparity = npz.header("disparity")?;
    let s = &rgb.shape;
    if s.len() != 4 || s[3] != 3 {
        return Err(fail(format!(
            "key 'rgb' has shape {s:?}, expected (N, H, W, 3)"
        )));
    }
    let (n, h, w) = (s[0], s[1], s[2]);
    if n == 0 {
        return Err(fail("the stack has no layers (N = 0)".into()));
    }
    for (key, hdr) in [("alpha", &alpha), ("disparity", &disparity)] {
        npy::check_dtype(
            hdr,
            Integers::Reject,
            &format!("{}: key '{key}'", path.display()),
        )?;
        if hdr.shape != [n, h, w] {
            return Err(fail(format!(
                "key '{key}' has shape {:?}, expected {:?} to match 'rgb'",
                hdr.shape,
                [n, h, w]
            )));
        }
    }
    check_dimensions(
        "layer stack",
        usize::try_from(w).unwrap_or(usize::MAX),
        usize::try_from(h).unwrap_or(usize::MAX),
    )
    .map_err(|e| e.in_file(path))?;
    budget::check_work(&path.display().to_string(), w, h, n)?;
    let (n, h, w) = (n as usize, h as usize, w as usize);
    let rgb = npz.data_parts::<T>("rgb", &rgb, n, w * h * 3)?;
    let alpha = npz.data_parts::<T>("alpha", &alpha, n, w * h)?;
    let disparity = npz.data_parts::<T>("disparity", &disparity, n, w * h)?;
    let layers = rgb
        .into_iter()
        .zip(alpha)
        .zip(disparity)
        .map(|((rgb, alpha), disparity)| {
            Ok(Layer {
                rgb_encoded: Image::from_vec(w, h, 3, rgb)?,
                alpha: Image::from_vec(w, h, 1, alpha)?,
                disparity: Image::from_vec(w, h, 1, disparity)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    LayerStack::new(layers).map_err(|e| e.in_file(path))
}

/// Writes a layer stack as an NPZ file (float32 arrays `rgb`, `alpha`, `disparity`).
pub fn write_stack<T: Real>(path: &Path, stack: &LayerStack<T>) -> Result<()> {
    let mut s = Staging::new();
    s.stack(path, stack)?;
    s.commit()
}

/// Writes gradients as NPZ: `rgb` (N,H,W,3), `alpha` (N,H,W), `disparity` (N,H,W), and the
/// scalars `blur` and `focus` (0-d arrays). float64 when `T` is f64, float32 otherwise.
pub fn write_gradients<T: Real>(
    path: &Path,
    grads: &Gradients<T>,
    width: usize,
    height: usize,
) -> Result<()> {
    let mut s = Staging::new();
    s.gradients(path, grads, width, height)?;
    s.commit()
}

impl Staging {
    /// Stages a layer stack as NPZ (see [`write_stack`]).
    pub fn stack<T: Real>(&mut self, path: &Path, stack: &LayerStack<T>) -> Result<()> {
        let (n, h, w) = (stack.layers.len(), stack.height, stack.width);
        let collect = |f: &dyn Fn(&Layer<T>) -> &Image<T>| -> Vec<f32> {
            stack
                .layers
                .iter()
                .flat_map(|l| f(l).data.iter().map(|v| v.f64() as f32))
                .collect()
        };
        let rgb =
            ndarray::Array4::from_shape_vec((n, h, w, 3), collect(&|l| &l.rgb_encoded)).unwrap();
        let alpha = ndarray::Array3::from_shape_vec((n, h, w), collect(&|l| &l.alpha)).unwrap();
        let disp = ndarray::Array3::from_shape_vec((n, h, w), collect(&|l| &l.disparity)).unwrap();
        self.file(path, |out| {
            let err =
                |e: ndarray_npy::WriteNpzError| Error::file(path, format!("write failed: {e}"));
            let mut npz = NpzWriter::new_compressed(out);
            npz.add_array("rgb", &rgb).map_err(err)?;
            npz.add_array("alpha", &alpha).map_err(err)?;
            npz.add_array("disparity", &disp).map_err(err)?;
            npz.finish().map_err(err)?;
            Ok(())
        })
    }

    /// Stages gradients as NPZ (see [`write_gradients`]). Fails, naming the file, if any
    /// gradient is not finite (an overflow: the upstream gradient was too large).
    pub fn gradients<T: Real>(
        &mut self,
        path: &Path,
        grads: &Gradients<T>,
        width: usize,
        height: usize,
    ) -> Result<()> {
        let f32_out = std::any::TypeId::of::<T>() != std::any::TypeId::of::<f64>();
        let finite = |v: f64| {
            if f32_out {
                (v as f32).is_finite()
            } else {
                v.is_finite()
            }
        };
        for (l, g) in grads.layers.iter().enumerate() {
            for (name, img) in [
                ("rgb", &g.rgb),
                ("alpha", &g.alpha),
                ("disparity", &g.disparity),
            ] {
                if let Some(i) = img.data.iter().position(|v| !finite(v.f64())) {
                    let p = i / img.channels;
                    return Err(Error::file(
                    path,
                    format!(
                        "the gradient overflowed ({} in layer {l} {name} at x={}, y={}); nothing written: scale the upstream gradient down",
                        img.data[i].f64(),
                        p % img.width,
                        p / img.width
                    ),
                ));
                }
            }
        }
        for (name, v) in [("blur", grads.blur_k), ("focus", grads.focus)] {
            if !finite(v) {
                return Err(Error::file(
                path,
                format!("the gradient overflowed (d/d{name} = {v}); nothing written: scale the upstream gradient down"),
            ));
            }
        }
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
        self.file(path, |out| {
            let err =
                |e: ndarray_npy::WriteNpzError| Error::file(path, format!("write failed: {e}"));
            if std::any::TypeId::of::<T>() == std::any::TypeId::of::<f64>() {
                write_typed(out, grads, (width, height), |v: T| v.f64(), err)
            } else {
                write_typed(out, grads, (width, height), |v: T| v.f64() as f32, err)
            }
        })
    }
}
