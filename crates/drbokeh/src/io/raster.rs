//! Raster images through the `image` crate: PNG (8/16-bit), JPEG, TIFF, EXR.
//! Colour read from PNG/JPEG/TIFF is display-encoded; EXR holds linear light.

use super::encode::{quantize_u16, quantize_u8};
use super::files::{extension, open};
use super::npy::{self, Integers};
use super::npz::Npz;
use super::staging::Staging;
use crate::image::{check_dimensions, Image};
use crate::{budget, Error, Real, Result};
use image::{DynamicImage, ImageDecoder, ImageFormat};
use std::path::Path;

/// The decoder limits: at most [`crate::image::MAX_DIMENSION`] per side and
/// [`budget::max_decoder_bytes`] of allocations (set explicitly: the `image` crate's default
/// of 512 MiB rejects valid 16-bit images of 90 MP and more).
fn decoder_limits() -> image::Limits {
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(crate::image::MAX_DIMENSION as u32);
    limits.max_image_height = Some(crate::image::MAX_DIMENSION as u32);
    limits.max_alloc = Some(budget::max_decoder_bytes());
    limits
}

/// Decodes any supported raster file, with errors naming the file; `what` names its role.
/// The header is read first: dimensions are checked (per-image limits and the input budget)
/// before the pixels are decoded.
pub(crate) fn decode(path: &Path) -> Result<DynamicImage> {
    decode_as(path, "image")
}

/// [`decode`] with the file's role (`"texture"`, `"image"`) in messages.
pub(crate) fn decode_as(path: &Path, what: &str) -> Result<DynamicImage> {
    let mut reader = image::ImageReader::new(std::io::BufReader::new(open(path)?))
        .with_guessed_format()
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    if reader.format().is_none() {
        return Err(Error::file(
            path,
            format!("unrecognised {what} format (supported: PNG, JPEG, TIFF, EXR)"),
        ));
    }
    reader.limits(decoder_limits());
    let decoder = reader
        .into_decoder()
        .map_err(|e| decode_error(path, what, e))?;
    let (w, h) = decoder.dimensions();
    check_dimensions(what, w as usize, h as usize).map_err(|e| e.in_file(path))?;
    budget::check_work(&path.display().to_string(), w as u64, h as u64, 1)?;
    DynamicImage::from_decoder(decoder).map_err(|e| decode_error(path, what, e))
}

/// The dimensions of an image file from its header (nothing decoded); `what` names its role.
pub fn image_dimensions(path: &Path, what: &str) -> Result<(u32, u32)> {
    let mut reader = image::ImageReader::new(std::io::BufReader::new(open(path)?))
        .with_guessed_format()
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    if reader.format().is_none() {
        return Err(Error::file(
            path,
            format!("unrecognised {what} format (supported: PNG, JPEG, TIFF, EXR)"),
        ));
    }
    reader.limits(decoder_limits());
    let (w, h) = reader
        .into_dimensions()
        .map_err(|e| decode_error(path, what, e))?;
    check_dimensions(what, w as usize, h as usize).map_err(|e| e.in_file(path))?;
    Ok((w, h))
}

fn decode_error(path: &Path, what: &str, e: image::ImageError) -> Error {
    match e {
        image::ImageError::Limits(l) => Error::file(
            path,
            format!(
                "the {what} decoder needs more memory than allowed ({l}; the limit is {} MiB, \
                 set by --max-megapixels)",
                budget::max_decoder_bytes() >> 20
            ),
        ),
        e => Error::file(path, format!("corrupt or unsupported {what}: {e}")),
    }
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
/// tool's convention). Header first: shape and budget are checked before the data is read.
fn read_grey_array<T: Real>(path: &Path, what: &str) -> Result<Image<T>> {
    let grey = |s: &[u64]| matches!(s, [_, _] | [_, _, 1]);
    let expected = "(H, W) or (H, W, 1)";
    let (shape, data) = if extension(path) == "npz" {
        let mut npz = Npz::open(path)?;
        let names = npz.names();
        if !names.iter().any(|n| n == "data") {
            return Err(Error::file(
                path,
                format!("missing key 'data' (found: {})", names.join(", ")),
            ));
        }
        npz.array::<T>("data", Integers::Scale, grey, expected)?
    } else {
        read_npy_checked(path, Integers::Scale, grey, what, expected)?
    };
    let (h, w) = (shape[0] as usize, shape[1] as usize);
    check_dimensions(what, w, h).map_err(|e| e.in_file(path))?;
    let out = Image::from_vec(w, h, 1, data)?;
    out.check_finite(what).map_err(|e| e.in_file(path))?;
    Ok(out)
}

/// Reads an NPY file after checking its header: dtype policy, accepted shape
/// (`expected` describes it), size against the file and the input budget.
fn read_npy_checked<T: Real>(
    path: &Path,
    integers: Integers,
    shape_ok: impl Fn(&[u64]) -> bool,
    what: &str,
    expected: &str,
) -> Result<(Vec<u64>, Vec<T>)> {
    let (mut r, h) = npy::open_npy(path)?;
    let file = path.display().to_string();
    npy::check_dtype(&h, integers, &file)?;
    if !shape_ok(&h.shape) {
        return Err(Error::file(
            path,
            format!("{what} has shape {:?}, expected {expected}", h.shape),
        ));
    }
    h.check_budget(&file)?;
    let data = npy::read_data::<T, _>(&mut r, &h).map_err(|e| Error::file(path, e))?;
    Ok((h.shape, data))
}

/// Reads an `(H, W, C)` NPY array (float32, float64, uint8 or uint16) as an image with
/// `channels` channels; `what` names its role in messages. The header is checked (shape,
/// size, budget) before the data is read.
pub fn read_npy_image<T: Real>(path: &Path, channels: usize, what: &str) -> Result<Image<T>> {
    let c = channels as u64;
    let (shape, data) = read_npy_checked::<T>(
        path,
        Integers::Scale,
        |s| matches!(s, [_, _, ch] if *ch == c) || (channels == 1 && s.len() == 2),
        what,
        &format!("(H, W, {channels})"),
    )?;
    let (h, w) = (shape[0] as usize, shape[1] as usize);
    check_dimensions(what, w, h).map_err(|e| e.in_file(path))?;
    let out = Image::from_vec(w, h, channels, data)?;
    out.check_finite(what).map_err(|e| e.in_file(path))?;
    Ok(out)
}

/// Reads an alpha matte: a grey image, or the alpha channel of a grey+alpha / RGBA image.
pub fn read_matte<T: Real>(path: &Path) -> Result<Image<T>> {
    let out: Image<T> = if extension(path) == "npy" || extension(path) == "npz" {
        read_grey_array(path, "alpha matte")?
    } else {
        read_matte_image(path)?
    };
    if let Some(v) = out.data.iter().find(|v| **v < T::zero() || **v > T::one()) {
        return Err(Error::file(
            path,
            format!("alpha matte values must be in [0, 1], found {}", v.f64()),
        ));
    }
    Ok(out)
}

/// The matte of an image file: grey, or its alpha channel.
fn read_matte_image<T: Real>(path: &Path) -> Result<Image<T>> {
    let img = decode_as(path, "alpha matte")?;
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
    to_linear: impl Fn(f64) -> f64 + Sync,
) -> Result<()> {
    let mut s = Staging::new();
    s.output(path, image, bit_depth, to_linear)?;
    s.commit()
}

/// Writes a one-channel map (e.g. disparity in [0, 1]): `.png` as 16-bit grey (clipped to
/// [0, 1]), `.npy` as float32 (H, W), `.exr` as linear float (grey in all channels).
pub fn write_grey<T: Real>(path: &Path, image: &Image<T>) -> Result<()> {
    let mut s = Staging::new();
    s.grey(path, image)?;
    s.commit()
}

impl Staging {
    /// Stages a rendered image (see [`write_output`]); visible at [`Staging::commit`].
    pub fn output<T: Real>(
        &mut self,
        path: &Path,
        image: &Image<T>,
        bit_depth: BitDepth,
        to_linear: impl Fn(f64) -> f64 + Sync,
    ) -> Result<()> {
        let format = OutputFormat::from_path(path)?;
        let (w, h) = (image.width as u32, image.height as u32);
        let fail = |e: image::ImageError| Error::file(path, format!("write failed: {e}"));
        match format {
            OutputFormat::Npy => {
                use ndarray_npy::WriteNpyExt;
                let shape = (image.height, image.width, image.channels);
                self.file(path, |out| {
                    let err = |e: ndarray_npy::WriteNpyError| {
                        Error::file(path, format!("write failed: {e}"))
                    };
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
            OutputFormat::Exr => self.file(path, |out| {
                super::encode::exr_rows(path, out, image, to_linear)
            }),
            OutputFormat::Jpeg => {
                let data = image.data.iter().map(|&v| quantize_u8(v.f64())).collect();
                let buf = image::RgbImage::from_raw(w, h, data).unwrap();
                self.file(path, |out| {
                    image::codecs::jpeg::JpegEncoder::new_with_quality(out, 92)
                        .encode_image(&buf)
                        .map_err(fail)
                })
            }
            OutputFormat::Png => self.file(path, |out| {
                super::encode::png_rows(path, out, image, bit_depth == BitDepth::Sixteen)
            }),
            OutputFormat::Tiff => {
                let dynimg = match bit_depth {
                    BitDepth::Eight => DynamicImage::ImageRgb8(
                        image::RgbImage::from_raw(
                            w,
                            h,
                            image.data.iter().map(|&v| quantize_u8(v.f64())).collect(),
                        )
                        .unwrap(),
                    ),
                    BitDepth::Sixteen => DynamicImage::ImageRgb16(
                        image::ImageBuffer::from_raw(
                            w,
                            h,
                            image.data.iter().map(|&v| quantize_u16(v.f64())).collect(),
                        )
                        .unwrap(),
                    ),
                };
                self.file(path, |out| {
                    dynimg.write_to(out, ImageFormat::Tiff).map_err(fail)
                })
            }
        }
    }

    /// Stages a one-channel map (see [`write_grey`]); visible at [`Staging::commit`].
    pub fn grey<T: Real>(&mut self, path: &Path, image: &Image<T>) -> Result<()> {
        match extension(path).as_str() {
            "png" => self.file(path, |out| super::encode::png_rows(path, out, image, true)),
            "npy" => {
                use ndarray_npy::WriteNpyExt;
                let data: Vec<f32> = image.data.iter().map(|v| v.f64() as f32).collect();
                let arr =
                    ndarray::Array2::from_shape_vec((image.height, image.width), data).unwrap();
                self.file(path, |out| {
                    arr.write_npy(out)
                        .map_err(|e| Error::file(path, format!("write failed: {e}")))
                })
            }
            "exr" => self.file(path, |out| super::encode::exr_rows(path, out, image, |v| v)),
            e => Err(Error::file(
                path,
                format!("unsupported extension '.{e}' for a map (use .png, .npy or .exr)"),
            )),
        }
    }
}
