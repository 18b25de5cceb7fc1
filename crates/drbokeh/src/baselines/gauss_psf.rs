//! GaussPSF (Gur & Wolf 2019) as a differentiable rendering layer: each source pixel
//! spreads a Gaussian of `sigma = sqrt((K d / 2)^2 + 1/4)` (a disc of radius `K|d|` has a
//! standard deviation of `K|d|/2` per axis; the 1/2-pixel floor keeps it smooth at focus),
//! gathered and normalised: `out(x) = sum_y w I(y) / sum_y w`,
//! `w = exp(-|x-y|^2 / (2 sigma_y^2)) / sigma_y^2`. Models blur size; ignores occlusion.
//!
//! Works in linear light with the settings' transfer ([`RenderSettings::tone`]) and encodes
//! its output with the same transfer. Sums run over in-image pixels only (no padding),
//! normalised by the in-image weight.

use super::{check_pair, linear_rgb, LayerVjp};
use crate::camera::{Camera, Window, MAX_WINDOW_SIZE};
use crate::image::Image;
use crate::presets::RenderSettings;
use crate::{Real, Result};
use rayon::prelude::*;

/// GaussPSF sigma and its derivative with respect to the relative disparity.
#[inline(always)]
fn sigma<T: Real>(k: T, d: T) -> (T, T) {
    let half = k * d * T::c(0.5);
    let s = (half * half + T::c(0.25)).sqrt();
    (s, k * half * T::c(0.5) / s)
}

/// What the adjoint needs: per-pixel linear output and weight sums.
struct Saved<T> {
    out_linear: Vec<[T; 3]>,
    weight: Vec<T>,
    radius: isize,
}

/// Gather radius: three standard deviations of the largest Gaussian, capped by the
/// settings' window.
fn gather_radius<T: Real>(disparity: &Image<T>, s: &RenderSettings) -> isize {
    let k = s.camera.blur_k;
    let max_sigma = disparity
        .data
        .iter()
        .map(|&d| sigma(T::c(k), d - T::c(s.camera.focus_disparity)).0.f64())
        .fold(0.5, f64::max);
    ((3.0 * max_sigma).ceil() as isize)
        .min(s.camera.window.radius_px() as isize)
        .max(1)
}

fn forward<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    s: &RenderSettings,
) -> (Image<T>, Saved<T>) {
    let (w, h) = (aif.width, aif.height);
    let tone = s.tone();
    let lin = linear_rgb(aif, &tone);
    let (k, f) = (T::c(s.camera.blur_k), T::c(s.camera.focus_disparity));
    let sig: Vec<T> = disparity.data.iter().map(|&d| sigma(k, d - f).0).collect();
    let r = gather_radius(disparity, s);
    let per: Vec<([T; 3], T)> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w) as isize, (i / w) as isize);
            let (mut c, mut wsum) = ([T::zero(); 3], T::zero());
            for dy in -r..=r {
                for dx in -r..=r {
                    let (sx, sy) = (x + dx, y + dy);
                    if sx < 0 || sy < 0 || sx >= w as isize || sy >= h as isize {
                        continue;
                    }
                    let j = sy as usize * w + sx as usize;
                    let sg = sig[j];
                    let wt = (-T::c((dx * dx + dy * dy) as f64) / (T::c(2.0) * sg * sg)).exp()
                        / (sg * sg);
                    for ch in 0..3 {
                        c[ch] = c[ch] + wt * lin[j][ch];
                    }
                    wsum = wsum + wt;
                }
            }
            (c.map(|v| v / wsum), wsum)
        })
        .collect();
    let mut out = Image::new(w, h, 3);
    for (i, (c, _)) in per.iter().enumerate() {
        for ch in 0..3 {
            out.data[3 * i + ch] = tone.encode(c[ch]);
        }
    }
    let saved = Saved {
        out_linear: per.iter().map(|p| p.0).collect(),
        weight: per.iter().map(|p| p.1).collect(),
        radius: r,
    };
    (out, saved)
}

/// Renders `aif` (display-encoded RGB) with `disparity` through GaussPSF, with the
/// settings' K, focus, transfer and window (the window caps the gather radius).
pub fn render<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
) -> Result<Image<T>> {
    check_pair(aif, disparity)?;
    settings.camera.validate()?;
    Ok(forward(aif, disparity, settings).0)
}

/// The GaussPSF baseline of `drbokeh eval`: [`render`] with the camera's `K`, focus, gamma
/// and offset (gamma transfer), and a window wide enough for three standard deviations of
/// the largest Gaussian (capped at [`MAX_WINDOW_SIZE`]), so no blur is clipped.
pub fn render_with_camera<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    camera: &Camera,
) -> Result<Image<T>> {
    camera.validate()?;
    let max_d = disparity
        .data
        .iter()
        .map(|d| (d.f64() - camera.focus_disparity).abs())
        .fold(0.0, f64::max);
    let half = 0.5 * camera.blur_k * max_d;
    let sigma = (half * half + 0.25).sqrt();
    let radius = ((3.0 * sigma).ceil() as usize).clamp(1, MAX_WINDOW_SIZE / 2);
    let mut settings = RenderSettings::paper(camera.focus_disparity);
    settings.camera = camera.clone();
    settings.camera.highlight = None;
    settings.camera.window = Window::from_size(2 * radius + 1)?;
    render(aif, disparity, &settings)
}

/// Renders and back-propagates: `upstream(render)` returns the gradient `G` of the loss on
/// the render; returns the render and the gradients of `sum(G * render)` with respect to
/// the disparity and (when `colour_gradient`) the encoded colour.
pub fn render_vjp<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
    colour_gradient: bool,
    upstream: impl FnOnce(&Image<T>) -> Result<Image<T>>,
) -> Result<LayerVjp<T>> {
    check_pair(aif, disparity)?;
    settings.camera.validate()?;
    let (out, saved) = forward(aif, disparity, settings);
    let g = upstream(&out)?;
    super::check_upstream(&out, &g)?;
    let (w, h) = (aif.width, aif.height);
    let tone = settings.tone();
    let lin = linear_rgb(aif, &tone);
    let (k, f) = (
        T::c(settings.camera.blur_k),
        T::c(settings.camera.focus_disparity),
    );
    // Upstream gradient on each receiver's normalised linear colour, divided by W(x).
    let g_rel: Vec<[T; 3]> = (0..w * h)
        .map(|i| {
            [0, 1, 2].map(|c| {
                g.data[3 * i + c] * tone.encode_derivative(saved.out_linear[i][c]) / saved.weight[i]
            })
        })
        .collect();
    let r = saved.radius;
    let per: Vec<(T, [T; 3])> = (0..w * h)
        .into_par_iter()
        .map(|j| {
            let (sx, sy) = ((j % w) as isize, (j / w) as isize);
            let (sg, dsg) = sigma(k, disparity.data[j] - f);
            let mut acc = T::zero();
            let mut acc_rgb = [T::zero(); 3];
            for dy in -r..=r {
                for dx in -r..=r {
                    let (x, y) = (sx - dx, sy - dy);
                    if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
                        continue;
                    }
                    let i = y as usize * w + x as usize;
                    let d2 = T::c((dx * dx + dy * dy) as f64);
                    let wt = (-d2 / (T::c(2.0) * sg * sg)).exp() / (sg * sg);
                    // dw/dsigma = w (d2 / sigma^3 - 2 / sigma)
                    let dw = wt * (d2 / (sg * sg * sg) - T::c(2.0) / sg);
                    let mut gc = T::zero();
                    for c in 0..3 {
                        gc = gc + g_rel[i][c] * (lin[j][c] - saved.out_linear[i][c]);
                        acc_rgb[c] = acc_rgb[c] + g_rel[i][c] * wt;
                    }
                    acc = acc + gc * dw;
                }
            }
            (acc * dsg, acc_rgb)
        })
        .collect();
    let d_disparity = Image::from_vec(w, h, 1, per.iter().map(|p| p.0).collect())?;
    let d_rgb = if colour_gradient {
        Some(super::linear_to_encoded_gradient(aif, &tone, |i, c| {
            per[i].1[c]
        })?)
    } else {
        None
    };
    Ok(LayerVjp {
        render: out,
        d_disparity,
        d_rgb,
    })
}
