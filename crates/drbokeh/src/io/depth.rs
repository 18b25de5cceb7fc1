//! Disparity from a file: a disparity or metric depth map (16-bit PNG, EXR, NPY, or NPZ
//! with key `data`), converted to the renderer's normalised disparity (larger = nearer).

use super::raster::read_grey;
use crate::image::Image;
use crate::{Error, Real, Result};
use std::path::Path;

/// What the map holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DepthKind {
    /// Disparity (larger = nearer), any scale.
    #[default]
    Disparity,
    /// Metric depth z > 0 (larger = farther); converted to disparity 1/z.
    Depth,
}

/// How to turn a map into normalised disparity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DisparityOptions {
    /// What the file holds.
    pub kind: DepthKind,
    /// Min-max normalise to [0, 1] (the paper's tool does); a constant map becomes 0.
    pub normalize: bool,
}

impl Default for DisparityOptions {
    fn default() -> Self {
        DisparityOptions {
            kind: DepthKind::Disparity,
            normalize: true,
        }
    }
}

/// Reads a disparity or depth map and converts it to normalised disparity.
pub fn read_disparity<T: Real>(path: &Path, options: DisparityOptions) -> Result<Image<T>> {
    let map: Image<f64> = read_grey(path, "disparity map")?;
    let mut disp = map;
    if options.kind == DepthKind::Depth {
        if let Some(z) = disp.data.iter().find(|z| **z <= 0.0) {
            return Err(Error::file(
                path,
                format!("depth must be positive to convert to disparity 1/z, found {z}"),
            ));
        }
        disp.data.iter_mut().for_each(|z| *z = 1.0 / *z);
    }
    if options.normalize {
        let lo = disp.data.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = disp.data.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let range = hi - lo;
        disp.data
            .iter_mut()
            .for_each(|v| *v = if range > 0.0 { (*v - lo) / range } else { 0.0 });
    }
    Ok(disp.cast())
}
