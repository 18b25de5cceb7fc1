//! The pictures of an evaluation: previews, disparity maps and error maps.

use super::methods::Method;
use super::metrics;
use super::scenes::SceneInputs;
use crate::image::Image;
use crate::io;
use crate::{Error, Result};
use std::path::Path;

/// Error maps are drawn from black (no error) to white at this mean absolute error.
pub const ERROR_MAP_FULL_SCALE: f64 = 0.25;

/// Writes an 8-bit RGB PNG from 3-channel values in [0, 1].
fn write_png_rgb8(path: &Path, w: usize, h: usize, rgb: Vec<u8>) -> Result<()> {
    let buf = image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .ok_or_else(|| Error::file(path, "bad image size"))?;
    io::write_atomic(path, |out| {
        image::DynamicImage::ImageRgb8(buf)
            .write_to(out, image::ImageFormat::Png)
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

/// A black-red-yellow-white colour ramp for `t` in [0, 1].
pub fn heat_colour(t: f64) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let stops = [
        [0.0, 0.0, 0.0],
        [0.55, 0.0, 0.35],
        [0.95, 0.3, 0.0],
        [1.0, 0.85, 0.1],
        [1.0, 1.0, 1.0],
    ];
    let s = t * (stops.len() - 1) as f64;
    let i = (s.floor() as usize).min(stops.len() - 2);
    let f = s - i as f64;
    [0, 1, 2].map(|c| ((stops[i][c] * (1.0 - f) + stops[i + 1][c] * f) * 255.0).round() as u8)
}

/// Writes an error map (mean absolute error over channels) as a colour PNG, black at 0 and
/// white at [`ERROR_MAP_FULL_SCALE`].
pub fn write_error_map(path: &Path, render: &Image<f32>, truth: &Image<f32>) -> Result<()> {
    let err = metrics::error_map(render, truth)?;
    let rgb = err
        .data
        .iter()
        .flat_map(|&e| heat_colour(e as f64 / ERROR_MAP_FULL_SCALE))
        .collect();
    write_png_rgb8(path, err.width, err.height, rgb)
}

/// Writes a disparity map as an 8-bit grey PNG (near = bright).
pub fn write_disparity_preview(path: &Path, disparity: &Image<f32>) -> Result<()> {
    let rgb = disparity
        .data
        .iter()
        .flat_map(|&d| [(d.clamp(0.0, 1.0) * 255.0).round() as u8; 3])
        .collect();
    write_png_rgb8(path, disparity.width, disparity.height, rgb)
}

/// Writes a display-encoded image as a JPEG (quality 92) for the gallery.
pub fn write_preview(path: &Path, img: &Image<f32>) -> Result<()> {
    io::write_output(path, img, io::BitDepth::Eight, |v| v)
}

/// The gallery's file names for a scene: `aif.jpg`, `disparity.png`, `gt.jpg`, and per
/// method `<method>.jpg` and `<method>.err.png`.
pub fn method_image_names(method: Method) -> (String, String) {
    (
        format!("{}.jpg", method.name()),
        format!("{}.err.png", method.name()),
    )
}

/// Writes a scene's pictures into `dir` (created if missing): inputs, ground truth, and
/// each method's render and error map.
pub fn write_scene_images(
    dir: &Path,
    scene: &SceneInputs,
    renders: &[(Method, Image<f32>)],
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, "cannot create", e))?;
    write_preview(&dir.join("aif.jpg"), &scene.aif)?;
    write_disparity_preview(&dir.join("disparity.png"), &scene.disparity)?;
    write_preview(&dir.join("gt.jpg"), &scene.ground_truth)?;
    for (m, img) in renders {
        let (render_name, err_name) = method_image_names(*m);
        write_preview(&dir.join(render_name), img)?;
        write_error_map(&dir.join(err_name), img, &scene.ground_truth)?;
    }
    Ok(())
}
