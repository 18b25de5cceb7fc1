//! Images as row-major, channel-interleaved buffers (the `(H, W, C)` layout of NPY files).

use crate::{Error, Real, Result};

/// The largest width or height accepted for any image (a guard against absurd or corrupt headers).
pub const MAX_DIMENSION: usize = 1 << 16;
/// The largest pixel count accepted for any image (about 400 megapixels).
pub const MAX_PIXELS: usize = 400_000_000;

/// The index of the first value for which `bad` holds. Scans blocks without stopping
/// early (a reduction the compiler vectorises), then finds the value inside the first
/// failing block: the same answer as `iter().position(bad)`, about ten times faster on
/// valid input, which is the common case (the input checks run on every value of every
/// input, before the render, on one thread).
#[inline]
pub(crate) fn first_where<T: Copy>(data: &[T], bad: impl Fn(T) -> bool) -> Option<usize> {
    const BLOCK: usize = 1024;
    let block = data
        .chunks(BLOCK)
        .position(|b| b.iter().fold(false, |any, &v| any | bad(v)))?;
    let start = block * BLOCK;
    data[start..]
        .iter()
        .position(|&v| bad(v))
        .map(|i| start + i)
}

/// A row-major image with `channels` interleaved values per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Image<T> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Values per pixel (1 for grey/alpha/disparity, 3 for RGB).
    pub channels: usize,
    /// `height * width * channels` values, row-major, channels interleaved.
    pub data: Vec<T>,
}

/// Checks that `width x height` is a usable image size; `what` names the source in messages.
pub fn check_dimensions(what: &str, width: usize, height: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::input(
            what,
            format!("empty image ({width}x{height})"),
        ));
    }
    if width > MAX_DIMENSION || height > MAX_DIMENSION || width * height > MAX_PIXELS {
        return Err(Error::input(
            what,
            format!(
                "absurd dimensions {width}x{height} (limits: {MAX_DIMENSION} per side, {MAX_PIXELS} pixels)"
            ),
        ));
    }
    Ok(())
}

impl<T: Copy + Default> Image<T> {
    /// A zero-filled image.
    pub fn new(width: usize, height: usize, channels: usize) -> Self {
        Image {
            width,
            height,
            channels,
            data: vec![T::default(); width * height * channels],
        }
    }

    /// Wraps a buffer, checking its length.
    pub fn from_vec(width: usize, height: usize, channels: usize, data: Vec<T>) -> Result<Self> {
        if data.len() != width * height * channels {
            return Err(Error::input(
                "image buffer",
                format!(
                    "has {} values, expected {width}x{height}x{channels} = {}",
                    data.len(),
                    width * height * channels
                ),
            ));
        }
        Ok(Image {
            width,
            height,
            channels,
            data,
        })
    }

    /// The value of channel `c` at column `x`, row `y`.
    #[inline(always)]
    pub fn at(&self, x: usize, y: usize, c: usize) -> T {
        self.data[(y * self.width + x) * self.channels + c]
    }

    /// Mutable access to channel `c` at column `x`, row `y`.
    #[inline(always)]
    pub fn at_mut(&mut self, x: usize, y: usize, c: usize) -> &mut T {
        &mut self.data[(y * self.width + x) * self.channels + c]
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }
}

impl<T: Real> Image<T> {
    /// Converts the element type.
    pub fn cast<U: Real>(&self) -> Image<U> {
        Image {
            width: self.width,
            height: self.height,
            channels: self.channels,
            data: self.data.iter().map(|&v| U::c(v.f64())).collect(),
        }
    }

    /// Fails with a message naming `what` if any value is NaN or infinite.
    pub fn check_finite(&self, what: &str) -> Result<()> {
        if let Some(i) = first_where(&self.data, |v| !v.is_finite()) {
            let p = i / self.channels;
            return Err(Error::input(
                what,
                format!(
                    "non-finite value ({:?}) at pixel x={}, y={}",
                    self.data[i],
                    p % self.width,
                    p / self.width
                ),
            ));
        }
        Ok(())
    }

    /// Largest absolute difference to another image of the same shape.
    pub fn max_abs_diff(&self, other: &Image<T>) -> f64 {
        assert_eq!(self.data.len(), other.data.len(), "image shapes differ");
        self.data
            .iter()
            .zip(&other.data)
            .map(|(a, b)| (a.f64() - b.f64()).abs())
            .fold(0.0, f64::max)
    }
}
