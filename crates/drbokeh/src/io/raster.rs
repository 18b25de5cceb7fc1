//! Raster images through the `image` crate: PNG (8/16-bit), JPEG, TIFF, EXR.
//! Colour read from PNG/JPEG/TIFF is display-encoded; EXR holds linear light.

use super::files::{extension, open, write_atomic};
use super::npz::read_any;
use crate::image::{check_dimensions, Image};
use crate::{Error, Real, Result};
use image::{DynamicImage, ImageFormat};
use std::path::Path;

/// Decodes any supported raster file, with errors naming the file.
pub(crate) fn decode(path: &Path) -> Result<DynamicImage> {
    let reader = image::ImageReader::new(std::io::BufReader::new(open(path)?))
        .with_guessed_format()
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    if reader.format().is_none() {
        return Err(Error::file(
            path,
            "unrecognised image format (supported: PNG, JPEG, TIFF, EXR)",
        ));
    }
    let img = reader
        .decode()
        .map_err(|e| Error::file(path, format!("corrupt or unsupported image: {e}")))?;
    check_dimensions("image", img.width() as usize, img.height() as usize)
        .map_err(|e| e.in_file(path))?;
    Ok(img)
}

/// Whether the file holds linear light (EXR) rather than display-encoded values.
pub(crate) fn is_linear(path: &Path) -> bool {
    extension(path) == "exr"
}

fn channel_name(n: u8) -> &'static str {
    match n {
        1 => "grey",
        2 => "grey+alpha",
        3 => "RGB",
        4 => "RGBA",
        _ => "unusual",
    }
}

/// Reads a colour image as 3-channel values in [0, 1] as stored (display-encoded for
/// PNG/JPEG/TIFF, linear for EXR; see [`is_linear`]). Grey images are replicated to RGB;
/// an alpha channel is ignored (pass it as a matte).
pub fn read_rgb<T: Real>(path: &Path) -> Result<Image<T>> {
    let img = decode(path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let rgb = img.to_rgb32f();
    let out = Image::from_vec(
        w,
        h,
        3,
        rgb.into_raw().into_iter().map(|v| T::c(v as f64)).collect(),
    )?;
    out.check_finite("image").map_err(|e| e.in_file(path))?;
    if out.data.iter().any(|v| *v < T::zero()) {
        return Err(Error::file(path, "negative colour values"));
    }
    Ok(out)
}

/// Reads a single-channel image (grey, or the first channel of an EXR) as values scaled to
/// [0, 1] for integer formats, as stored for float formats. Multi-channel PNG/JPEG/TIFF are
/// rejected: `what` names the role ("disparity map", "aperture kernel") in the message.
pub fn read_grey<T: Real>(path: &Path, what: &str) -> Result<Image<T>> {
    if extension(path) == "npy" || extension(path) == "npz" {
        return read_grey_array(path, what);
    }
    let img = decode(path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let n = img.color().channel_count();
    let data: Vec<f32> = if is_linear(path) {
        // EXR: take the first channel (depth is often stored as R=G=B or as Y).
        img.to_rgba32f()
            .into_raw()
            .chunks_exact(4)
            .map(|p| p[0])
            .collect()
    } else if n == 1 {
        img.to_luma32f().into_raw()
    } else {
        return Err(Error::file(
            path,
            format!(
                "{what} must be a single-channel (grey) image, got {} ({n} channels)",
                channel_name(n)
            ),
        ));
    };
    let out = Image::from_vec(w, h, 1, data.into_iter().map(|v| T::c(v as f64)).collect())?;
    out.check_finite(what).map_err(|e| e.in_file(path))?;
    Ok(out)
}

/// Reads a 2-D array (H, W) or (H, W, 1) from NPY, or key `data` from NPZ (the official
/// tool's convention).
fn read_grey_array<T: Real>(path: &Path, what: &str) -> Result<Image<T>> {
    let fail = |p: String| Error::file(path, p);
    let arr: ndarray::ArrayD<f64> = if extension(path) == "npz" {
        let mut npz = ndarray_npy::NpzReader::new(open(path)?)
            .map_err(|e| fail(format!("not a readable NPZ archive: {e}")))?;
        let names = npz
            .names()
            .map_err(|e| fail(format!("corrupt NPZ archive: {e}")))?;
        if !names.iter().any(|n| n == "data") {
            return Err(fail(format!(
                "missing key 'data' (found: {})",
                names.join(", ")
            )));
        }
        read_any(&mut npz, "data", true).map_err(fail)?
    } else {
        read_npy_any(path)?
    };
    let s = arr.shape().to_vec();
    let (h, w) = match s.as_slice() {
        [h, w] | [h, w, 1] => (*h, *w),
        _ => {
            return Err(fail(format!(
                "{what} array has shape {s:?}, expected (H, W) or (H, W, 1)"
            )))
        }
    };
    check_dimensions(what, w, h).map_err(|e| e.in_file(path))?;
    let out = Image::from_vec(w, h, 1, arr.iter().map(|&v| T::c(v)).collect())?;
    out.check_finite(what).map_err(|e| e.in_file(path))?;
    Ok(out)
}

fn read_npy_any(path: &Path) -> Result<ndarray::ArrayD<f64>> {
    use ndarray::{ArrayD, OwnedRepr};
    use ndarray_npy::ReadNpyExt;
    let read = |f: &dyn Fn(std::fs::File) -> std::result::Result<ArrayD<f64>, String>| {
        f(open(path)?).map_err(|e| Error::file(path, e))
    };
    let first = read(&|f| {
        ndarray::ArrayBase::<OwnedRepr<f32>, _>::read_npy(f)
            .map(|a| a.mapv(|v| v as f64))
            .map_err(|e| e.to_string())
    });
    first
        .or_else(|_| read(&|f| ArrayD::<f64>::read_npy(f).map_err(|e| e.to_string())))
        .or_else(|_| {
            read(&|f| {
                ndarray::ArrayBase::<OwnedRepr<u16>, _>::read_npy(f)
                    .map(|a| a.mapv(|v| v as f64 / 65535.0))
                    .map_err(|e| e.to_string())
            })
        })
        .map_err(|_| {
            Error::file(
                path,
                "not a readable NPY array of float32, float64 or uint16 (corrupt, truncated or unsupported dtype)",
            )
        })
}

/// Reads an `(H, W, C)` NPY array (float32, float64 or uint16) as an image with `channels`
/// channels; `what` names its role in messages.
pub fn read_npy_image<T: Real>(path: &Path, channels: usize, what: &str) -> Result<Image<T>> {
    let arr = read_npy_any(path)?;
    let s = arr.shape().to_vec();
    let (h, w) = match s.as_slice() {
        [h, w, c] if *c == channels => (*h, *w),
        [h, w] if channels == 1 => (*h, *w),
        _ => {
            return Err(Error::file(
                path,
                format!("{what} has shape {s:?}, expected (H, W, {channels})"),
            ))
        }
    };
    check_dimensions(what, w, h).map_err(|e| e.in_file(path))?;
    let out = Image::from_vec(w, h, channels, arr.iter().map(|&v| T::c(v)).collect())?;
    out.check_finite(what).map_err(|e| e.in_file(path))?;
    Ok(out)
}

/// Reads an alpha matte: a grey image, or the alpha channel of a grey+alpha / RGBA image.
pub fn read_matte<T: Real>(path: &Path) -> Result<Image<T>> {
    if extension(path) == "npy" || extension(path) == "npz" {
        return read_grey_array(path, "alpha matte");
    }
    let img = decode(path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let n = img.color().channel_count();
    let data: Vec<f32> = match n {
        1 => img.to_luma32f().into_raw(),
        2 | 4 => img
            .to_rgba32f()
            .into_raw()
            .chunks_exact(4)
            .map(|p| p[3])
            .collect(),
        _ => {
            return Err(Error::file(
                path,
                format!(
                    "an alpha matte must be grey or have an alpha channel, got {} ({n} channels)",
                    channel_name(n)
                ),
            ))
        }
    };
    let out = Image::from_vec(w, h, 1, data.into_iter().map(|v| T::c(v as f64)).collect())?;
    out.check_finite("alpha matte")
        .map_err(|e| e.in_file(path))?;
    if out.data.iter().any(|v| *v < T::zero() || *v > T::one()) {
        return Err(Error::file(path, "alpha matte values must be in [0, 1]"));
    }
    Ok(out)
}

/// Bits per channel for integer outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BitDepth {
    /// 8 bits per channel.
    #[default]
    Eight,
    /// 16 bits per channel.
    Sixteen,
}

/// Output formats, chosen by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// PNG, display-encoded, 8 or 16 bits, clipped to [0, 1].
    Png,
    /// TIFF, display-encoded, 8 or 16 bits, clipped to [0, 1].
    Tiff,
    /// OpenEXR, linear float RGB (display values decoded with the camera's transfer).
    Exr,
    /// JPEG (quality 92), display-encoded, 8 bits.
    Jpeg,
    /// NPY, (H, W, 3) display-encoded values, not clipped or quantised (float32, or float64
    /// for f64 renders).
    Npy,
}

impl OutputFormat {
    /// Chooses the format from the path's extension.
    pub fn from_path(path: &Path) -> Result<Self> {
        match extension(path).as_str() {
            "png" => Ok(OutputFormat::Png),
            "tif" | "tiff" => Ok(OutputFormat::Tiff),
            "exr" => Ok(OutputFormat::Exr),
            "npy" => Ok(OutputFormat::Npy),
            "jpg" | "jpeg" => Ok(OutputFormat::Jpeg),
            e => Err(Error::file(
                path,
                format!("unsupported output extension '.{e}' (use .png, .tif, .exr, .npy or .jpg)"),
            )),
        }
    }
}

/// Writes a rendered, display-encoded RGB image. `to_linear` maps a display value to linear
/// light for EXR output. The file appears only once completely written.
pub fn write_output<T: Real>(
    path: &Path,
    image: &Image<T>,
    bit_depth: BitDepth,
    to_linear: impl Fn(f64) -> f64,
) -> Result<()> {
    let format = OutputFormat::from_path(path)?;
    let (w, h) = (image.width as u32, image.height as u32);
    let fail = |e: image::ImageError| Error::file(path, format!("write failed: {e}"));
    match format {
        OutputFormat::Npy => {
            use ndarray_npy::WriteNpyExt;
            let shape = (image.height, image.width, image.channels);
            write_atomic(path, |out| {
                let err =
                    |e: ndarray_npy::WriteNpyError| Error::file(path, format!("write failed: {e}"));
                if std::any::TypeId::of::<T>() == std::any::TypeId::of::<f64>() {
                    let data: Vec<f64> = image.data.iter().map(|v| v.f64()).collect();
                    ndarray::Array3::from_shape_vec(shape, data)
                        .unwrap()
                        .write_npy(out)
                        .map_err(err)
                } else {
                    let data: Vec<f32> = image.data.iter().map(|v| v.f64() as f32).collect();
                    ndarray::Array3::from_shape_vec(shape, data)
                        .unwrap()
                        .write_npy(out)
                        .map_err(err)
                }
            })
        }
        OutputFormat::Exr => {
            let data: Vec<f32> = image
                .data
                .iter()
                .map(|v| to_linear(v.f64()) as f32)
                .collect();
            let buf = image::Rgb32FImage::from_raw(w, h, data).unwrap();
            write_atomic(path, |out| {
                DynamicImage::ImageRgb32F(buf)
                    .write_to(out, ImageFormat::OpenExr)
                    .map_err(fail)
            })
        }
        OutputFormat::Jpeg => {
            let data = image
                .data
                .iter()
                .map(|&v| (v.f64().clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect();
            let buf = image::RgbImage::from_raw(w, h, data).unwrap();
            write_atomic(path, |out| {
                image::codecs::jpeg::JpegEncoder::new_with_quality(out, 92)
                    .encode_image(&buf)
                    .map_err(fail)
            })
        }
        OutputFormat::Png | OutputFormat::Tiff => {
            let fmt = if format == OutputFormat::Png {
                ImageFormat::Png
            } else {
                ImageFormat::Tiff
            };
            let clip = |v: T| v.f64().clamp(0.0, 1.0);
            let dynimg = match bit_depth {
                BitDepth::Eight => DynamicImage::ImageRgb8(
                    image::RgbImage::from_raw(
                        w,
                        h,
                        image
                            .data
                            .iter()
                            .map(|&v| (clip(v) * 255.0).round() as u8)
                            .collect(),
                    )
                    .unwrap(),
                ),
                BitDepth::Sixteen => DynamicImage::ImageRgb16(
                    image::ImageBuffer::from_raw(
                        w,
                        h,
                        image
                            .data
                            .iter()
                            .map(|&v| (clip(v) * 65535.0).round() as u16)
                            .collect(),
                    )
                    .unwrap(),
                ),
            };
            write_atomic(path, |out| dynimg.write_to(out, fmt).map_err(fail))
        }
    }
}

/// Writes a one-channel map (e.g. disparity in [0, 1]): `.png` as 16-bit grey (clipped to
/// [0, 1]), `.npy` as float32 (H, W), `.exr` as linear float (grey in all channels).
pub fn write_grey<T: Real>(path: &Path, image: &Image<T>) -> Result<()> {
    let (w, h) = (image.width as u32, image.height as u32);
    let fail = |e: image::ImageError| Error::file(path, format!("write failed: {e}"));
    match extension(path).as_str() {
        "png" => {
            let data = image
                .data
                .iter()
                .map(|v| (v.f64().clamp(0.0, 1.0) * 65535.0).round() as u16)
                .collect();
            let buf =
                image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(w, h, data).unwrap();
            write_atomic(path, |out| {
                DynamicImage::ImageLuma16(buf)
                    .write_to(out, ImageFormat::Png)
                    .map_err(fail)
            })
        }
        "npy" => {
            use ndarray_npy::WriteNpyExt;
            let data: Vec<f32> = image.data.iter().map(|v| v.f64() as f32).collect();
            let arr = ndarray::Array2::from_shape_vec((image.height, image.width), data).unwrap();
            write_atomic(path, |out| {
                arr.write_npy(out)
                    .map_err(|e| Error::file(path, format!("write failed: {e}")))
            })
        }
        "exr" => {
            let data: Vec<f32> = image
                .data
                .iter()
                .flat_map(|v| [v.f64() as f32; 3])
                .collect();
            let buf = image::Rgb32FImage::from_raw(w, h, data).unwrap();
            write_atomic(path, |out| {
                DynamicImage::ImageRgb32F(buf)
                    .write_to(out, ImageFormat::OpenExr)
                    .map_err(fail)
            })
        }
        e => Err(Error::file(
            path,
            format!("unsupported extension '.{e}' for a map (use .png, .npy or .exr)"),
        )),
    }
}
