//! Aperture compositing (Srinivasan et al. 2018) as a differentiable rendering layer: the
//! image is resampled at `x + K d(x) u_j` for aperture samples `u_j` on the unit disc and
//! averaged. Models the lens's shift-and-add with the receiver's own disparity; ignores
//! occlusion and the sources' own blur sizes.
//!
//! Works in linear light with the settings' transfer ([`RenderSettings::tone`]) and encodes
//! its output with the same transfer. Samples are bilinear with clamped borders.

use super::{check_pair, linear_rgb, LayerVjp};
use crate::image::Image;
use crate::presets::RenderSettings;
use crate::{Real, Result};
use rayon::prelude::*;

/// Number of aperture samples.
pub const APERTURE_SAMPLES: usize = 128;

/// Aperture samples on the unit disc: a Fibonacci (golden-angle) spiral, area-uniform.
pub fn aperture_samples(n: usize) -> Vec<(f64, f64)> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let r = ((i as f64 + 0.5) / n as f64).sqrt();
            let t = i as f64 * golden;
            (r * t.cos(), r * t.sin())
        })
        .collect()
}

/// Bilinear sample position: the four corner indices and weights (coordinates clamped to
/// the image).
#[inline]
fn corners(w: usize, h: usize, fx: f64, fy: f64) -> ([usize; 4], [f64; 4], f64, f64) {
    let fx = fx.clamp(0.0, (w - 1) as f64);
    let fy = fy.clamp(0.0, (h - 1) as f64);
    // Truncation is the floor of these non-negative coordinates (and 0 for NaN, as
    // `floor` then `as` gives), without a call to libm's `floor` per sample.
    let (x0, y0) = (fx as usize, fy as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
    (
        [y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1],
        [
            (1.0 - tx) * (1.0 - ty),
            tx * (1.0 - ty),
            (1.0 - tx) * ty,
            tx * ty,
        ],
        tx,
        ty,
    )
}

/// Bilinear sample of a linear image with clamped borders, and its spatial gradient.
#[inline]
fn bilinear<T: Real>(
    lin: &[[T; 3]],
    w: usize,
    h: usize,
    fx: f64,
    fy: f64,
) -> ([T; 3], [T; 3], [T; 3]) {
    let (idx, _, tx, ty) = corners(w, h, fx, fy);
    let (tx, ty) = (T::c(tx), T::c(ty));
    let (a, b, c, d) = (lin[idx[0]], lin[idx[1]], lin[idx[2]], lin[idx[3]]);
    let mut v = [T::zero(); 3];
    let (mut gx, mut gy) = ([T::zero(); 3], [T::zero(); 3]);
    for ch in 0..3 {
        v[ch] = (T::one() - ty) * ((T::one() - tx) * a[ch] + tx * b[ch])
            + ty * ((T::one() - tx) * c[ch] + tx * d[ch]);
        gx[ch] = (T::one() - ty) * (b[ch] - a[ch]) + ty * (d[ch] - c[ch]);
        gy[ch] = (T::one() - tx) * (c[ch] - a[ch]) + tx * (d[ch] - b[ch]);
    }
    (v, gx, gy)
}

fn forward<T: Real>(aif: &Image<T>, disparity: &Image<T>, s: &RenderSettings) -> Image<T> {
    let (w, h) = (aif.width, aif.height);
    let tone = s.tone();
    let lin = linear_rgb(aif, &tone);
    let samples = aperture_samples(APERTURE_SAMPLES);
    let (k, f) = (s.camera.blur_k, s.camera.focus_disparity);
    let data: Vec<T> = (0..w * h)
        .into_par_iter()
        .flat_map_iter(|i| {
            let shift = k * (disparity.data[i].f64() - f);
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let mut acc = [T::zero(); 3];
            for &(u, v) in &samples {
                let (val, _, _) = bilinear(&lin, w, h, x + shift * u, y + shift * v);
                for c in 0..3 {
                    acc[c] = acc[c] + val[c];
                }
            }
            let n = T::c(samples.len() as f64);
            acc.map(|v| tone.encode(v / n))
        })
        .collect();
    Image::from_vec(w, h, 3, data).expect("shape of the input")
}

/// Renders `aif` (display-encoded RGB) with `disparity` through aperture compositing, with
/// the settings' K, focus and transfer.
pub fn render<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
) -> Result<Image<T>> {
    check_pair(aif, disparity)?;
    settings.camera.validate()?;
    Ok(forward(aif, disparity, settings))
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
    let out = forward(aif, disparity, settings);
    let g = upstream(&out)?;
    super::check_upstream(&out, &g)?;
    let (_, d_disparity, d_rgb) = backward(aif, disparity, settings, colour_gradient, &g)?;
    Ok(LayerVjp {
        render: out,
        d_disparity,
        d_rgb,
    })
}

/// The vector-Jacobian product for a gradient `g` on the render known beforehand (a
/// training step's backward pass, whose forward pass already rendered): the render (the
/// same bytes as [`render`]) and the gradients of `sum(g * render)` with respect to the
/// disparity and (when `colour_gradient`) the encoded colour, in one pass over the
/// samples instead of [`render_vjp`]'s two.
pub fn vjp<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
    colour_gradient: bool,
    g: &Image<T>,
) -> Result<LayerVjp<T>> {
    check_pair(aif, disparity)?;
    settings.camera.validate()?;
    // The render has the image's size and channels.
    super::check_upstream(aif, g)?;
    let (render, d_disparity, d_rgb) = backward(aif, disparity, settings, colour_gradient, g)?;
    Ok(LayerVjp {
        render,
        d_disparity,
        d_rgb,
    })
}

/// One pass over every receiver's samples: the render (accumulated as [`forward`] does,
/// so the same bytes), the disparity gradient of `sum(g * render)` and, when
/// `colour_gradient`, the encoded colour's.
#[allow(clippy::type_complexity)]
fn backward<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
    colour_gradient: bool,
    g: &Image<T>,
) -> Result<(Image<T>, Image<T>, Option<Image<T>>)> {
    let (w, h) = (aif.width, aif.height);
    let tone = settings.tone();
    let lin = linear_rgb(aif, &tone);
    let samples = aperture_samples(APERTURE_SAMPLES);
    let n = samples.len() as f64;
    let (k, f) = (settings.camera.blur_k, settings.camera.focus_disparity);
    // Per receiver: its encoded render, the gradient on its disparity, and on its mean
    // linear colour.
    let per: Vec<([T; 3], T, [T; 3])> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let shift = k * (disparity.data[i].f64() - f);
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let (mut acc, mut dacc) = ([T::zero(); 3], [T::zero(); 3]);
            for &(u, v) in &samples {
                let (fx, fy) = (x + shift * u, y + shift * v);
                let (val, gx, gy) = bilinear(&lin, w, h, fx, fy);
                // Clamped coordinates do not move with the shift.
                let ux = if fx > 0.0 && fx < (w - 1) as f64 {
                    u
                } else {
                    0.0
                };
                let vy = if fy > 0.0 && fy < (h - 1) as f64 {
                    v
                } else {
                    0.0
                };
                for c in 0..3 {
                    acc[c] = acc[c] + val[c];
                    dacc[c] = dacc[c] + (gx[c] * T::c(ux) + gy[c] * T::c(vy)) * T::c(k);
                }
            }
            let mean = acc.map(|v| v / T::c(n));
            let g_lin = [0, 1, 2].map(|c| g.data[3 * i + c] * tone.encode_derivative(mean[c]));
            let mut total = T::zero();
            for c in 0..3 {
                total = total + g_lin[c] * dacc[c] / T::c(n);
            }
            (mean.map(|v| tone.encode(v)), total, g_lin)
        })
        .collect();
    let render = Image::from_vec(w, h, 3, per.iter().flat_map(|p| p.0).collect())?;
    let d_disparity = Image::from_vec(w, h, 1, per.iter().map(|p| p.1).collect())?;
    let g_lin: Vec<[T; 3]> = per.iter().map(|p| p.2).collect();
    let d_rgb = if colour_gradient {
        // Scatter each sample's bilinear weights onto its four source pixels, in a fixed
        // (serial) order, so the sum is deterministic.
        let mut d_lin = vec![[0.0f64; 3]; w * h];
        for i in 0..w * h {
            let shift = k * (disparity.data[i].f64() - f);
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let gi = g_lin[i].map(|v| v.f64() / n);
            for &(u, v) in &samples {
                let (idx, wts, _, _) = corners(w, h, x + shift * u, y + shift * v);
                for q in 0..4 {
                    for c in 0..3 {
                        d_lin[idx[q]][c] += wts[q] * gi[c];
                    }
                }
            }
        }
        Some(super::linear_to_encoded_gradient(aif, &tone, |i, c| {
            T::c(d_lin[i][c])
        })?)
    } else {
        None
    };
    Ok((render, d_disparity, d_rgb))
}
