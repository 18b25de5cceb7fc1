//! Rendering layers that depth from defocus can optimise through, all with the same
//! interface: render an all-in-focus image with a per-pixel disparity map, and return the
//! gradient of `sum(G * render)` with respect to that disparity.
//!
//! - [`RenderLayer::DrBokeh`]: our renderer (preset `paper`) on a single opaque layer.
//! - [`RenderLayer::GaussPsf`]: GaussPSF (Gur & Wolf 2019): each source pixel spreads a
//!   Gaussian of `sigma = sqrt((K d / 2)^2 + 1/4)` (a disc of radius `K|d|` has a standard
//!   deviation of `K|d|/2` per axis; the 1/2-pixel floor keeps it smooth at focus),
//!   gathered and normalised: `out(x) = sum_y w I(y) / sum_y w`, `w = exp(-|x-y|^2 /
//!   (2 sigma_y^2)) / sigma_y^2`. Models blur size; ignores occlusion.
//! - [`RenderLayer::Aperture`]: aperture compositing (Srinivasan et al. 2018): the image is
//!   resampled at `x + K d(x) u_j` for aperture samples `u_j` on the unit disc and averaged.
//!   Models the lens's shift-and-add with the receiver's own disparity; ignores occlusion
//!   and the sources' own blur sizes.
//!
//! All three work in linear light (`(I + offset)^gamma`) and encode their output with the
//! same transfer, so they are compared on equal terms. Baselines sum over in-image pixels
//! only (no padding); DrBokeh uses the model's reflection padding.

use crate::image::Image;
use crate::model;
use crate::presets::RenderSettings;
use crate::stack::LayerStack;
use crate::{Error, NoProgress, Real, Result};
use rayon::prelude::*;

/// Which rendering layer to optimise through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum RenderLayer {
    /// Dr.Bokeh (`paper` preset), single opaque layer.
    DrBokeh,
    /// Gaussian PSF, normalised gather.
    GaussPsf,
    /// Aperture compositing (shift-and-add).
    Aperture,
}

impl RenderLayer {
    /// All layers, for experiments.
    pub const ALL: [RenderLayer; 3] = [
        RenderLayer::DrBokeh,
        RenderLayer::GaussPsf,
        RenderLayer::Aperture,
    ];

    /// CLI name.
    pub fn name(self) -> &'static str {
        match self {
            RenderLayer::DrBokeh => "drbokeh",
            RenderLayer::GaussPsf => "gausspsf",
            RenderLayer::Aperture => "aperture",
        }
    }
}

impl std::str::FromStr for RenderLayer {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        RenderLayer::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| {
                Error::param(
                    "--layer",
                    format!("unknown layer '{s}' (drbokeh, gausspsf, aperture)"),
                )
            })
    }
}

/// Number of aperture samples of the aperture-compositing layer.
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

fn check_pair<T>(aif: &Image<T>, disparity: &Image<T>) -> Result<()> {
    if aif.channels != 3
        || disparity.channels != 1
        || aif.width != disparity.width
        || aif.height != disparity.height
    {
        return Err(Error::input(
            "depth from defocus",
            format!(
                "image {}x{}x{} and disparity {}x{}x{} must be HxWx3 and HxWx1 of one size",
                aif.width,
                aif.height,
                aif.channels,
                disparity.width,
                disparity.height,
                disparity.channels
            ),
        ));
    }
    Ok(())
}

/// Renders `aif` (display-encoded RGB) with `disparity` through `layer`.
pub fn render_layer<T: Real>(
    layer: RenderLayer,
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
) -> Result<Image<T>> {
    check_pair(aif, disparity)?;
    match layer {
        RenderLayer::DrBokeh => {
            let stack = LayerStack::single(aif.clone(), disparity.clone())?;
            crate::render(&stack, settings, crate::Engine::Threaded, &NoProgress)
        }
        RenderLayer::GaussPsf => Ok(gauss_psf(aif, disparity, settings, None).0),
        RenderLayer::Aperture => Ok(aperture(aif, disparity, settings, None).0),
    }
}

/// Renders and back-propagates: returns the render and the gradient of `sum(G * render)`
/// with respect to the disparity, where `upstream(render)` returns `G`. The Dr.Bokeh layer
/// runs on the threaded engine (the exact gradient); see [`render_layer_vjp_on`].
pub fn render_layer_vjp<T: Real>(
    layer: RenderLayer,
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
    upstream: impl FnOnce(&Image<T>) -> Result<Image<T>>,
) -> Result<(Image<T>, Image<T>)> {
    render_layer_vjp_on(
        layer,
        crate::Engine::Threaded,
        aif,
        disparity,
        settings,
        upstream,
    )
}

/// [`render_layer_vjp`] with the Dr.Bokeh layer's forward and adjoint on `engine`
/// ([`crate::render_with_tape_on`]; the other layers ignore it).
pub fn render_layer_vjp_on<T: Real>(
    layer: RenderLayer,
    engine: crate::Engine,
    aif: &Image<T>,
    disparity: &Image<T>,
    settings: &RenderSettings,
    upstream: impl FnOnce(&Image<T>) -> Result<Image<T>>,
) -> Result<(Image<T>, Image<T>)> {
    check_pair(aif, disparity)?;
    match layer {
        RenderLayer::DrBokeh => {
            let stack = LayerStack::single(aif.clone(), disparity.clone())?;
            let (out, tape) = crate::render_with_tape_on(&stack, settings, engine, &NoProgress)?;
            let g = upstream(&out)?;
            let grads = tape.backward(&g, &NoProgress)?;
            Ok((out, grads.layers.into_iter().next().unwrap().disparity))
        }
        RenderLayer::GaussPsf => {
            let (out, saved) = gauss_psf(aif, disparity, settings, Some(()));
            let g = upstream(&out)?;
            Ok((
                out.clone(),
                gauss_psf_vjp(aif, disparity, settings, &saved.unwrap(), &g),
            ))
        }
        RenderLayer::Aperture => {
            let (out, _) = aperture(aif, disparity, settings, None);
            let g = upstream(&out)?;
            Ok((out, aperture_vjp(aif, disparity, settings, &g)))
        }
    }
}

fn linear<T: Real>(aif: &Image<T>, s: &RenderSettings) -> Vec<[T; 3]> {
    let (g, off) = (T::c(s.camera.gamma), T::c(s.camera.offset));
    aif.data
        .chunks_exact(3)
        .map(|p| [0, 1, 2].map(|c| model::linearize(p[c], g, off)))
        .collect()
}

/// GaussPSF sigma and its derivative with respect to the relative disparity.
#[inline(always)]
fn sigma<T: Real>(k: T, d: T) -> (T, T) {
    let half = k * d * T::c(0.5);
    let s = (half * half + T::c(0.25)).sqrt();
    (s, k * half * T::c(0.5) / s)
}

/// What the GaussPSF adjoint needs: per-pixel linear output and weight sums.
struct GaussSaved<T> {
    out_linear: Vec<[T; 3]>,
    weight: Vec<T>,
    radius: isize,
}

fn gauss_radius<T: Real>(disparity: &Image<T>, s: &RenderSettings) -> isize {
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

fn gauss_psf<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    s: &RenderSettings,
    save: Option<()>,
) -> (Image<T>, Option<GaussSaved<T>>) {
    let (w, h) = (aif.width, aif.height);
    let lin = linear(aif, s);
    let (k, f) = (T::c(s.camera.blur_k), T::c(s.camera.focus_disparity));
    let sig: Vec<T> = disparity.data.iter().map(|&d| sigma(k, d - f).0).collect();
    let r = gauss_radius(disparity, s);
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
    let (g, off) = (T::c(s.camera.gamma), T::c(s.camera.offset));
    let mut out = Image::new(w, h, 3);
    for (i, (c, _)) in per.iter().enumerate() {
        for ch in 0..3 {
            out.data[3 * i + ch] = model::encode(c[ch], g, off);
        }
    }
    let saved = save.map(|_| GaussSaved {
        out_linear: per.iter().map(|p| p.0).collect(),
        weight: per.iter().map(|p| p.1).collect(),
        radius: r,
    });
    (out, saved)
}

fn gauss_psf_vjp<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    s: &RenderSettings,
    saved: &GaussSaved<T>,
    g: &Image<T>,
) -> Image<T> {
    let (w, h) = (aif.width, aif.height);
    let lin = linear(aif, s);
    let (k, f, gamma) = (
        T::c(s.camera.blur_k),
        T::c(s.camera.focus_disparity),
        T::c(s.camera.gamma),
    );
    // Upstream gradient on each receiver's normalised linear colour, divided by W(x).
    let g_rel: Vec<[T; 3]> = (0..w * h)
        .map(|i| {
            [0, 1, 2].map(|c| {
                g.data[3 * i + c] * model::encode_derivative(saved.out_linear[i][c], gamma)
                    / saved.weight[i]
            })
        })
        .collect();
    let r = saved.radius;
    let grad: Vec<T> = (0..w * h)
        .into_par_iter()
        .map(|j| {
            let (sx, sy) = ((j % w) as isize, (j / w) as isize);
            let (sg, dsg) = sigma(k, disparity.data[j] - f);
            let mut acc = T::zero();
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
                    }
                    acc = acc + gc * dw;
                }
            }
            acc * dsg
        })
        .collect();
    Image::from_vec(w, h, 1, grad).unwrap()
}

/// Bilinear sample of a linear image with clamped borders, and its spatial gradient.
#[inline]
fn bilinear<T: Real>(lin: &[[T; 3]], w: usize, h: usize, fx: T, fy: T) -> ([T; 3], [T; 3], [T; 3]) {
    let fx = fx.max(T::zero()).min(T::c((w - 1) as f64));
    let fy = fy.max(T::zero()).min(T::c((h - 1) as f64));
    let (x0, y0) = (fx.floor().f64() as usize, fy.floor().f64() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (tx, ty) = (fx - T::c(x0 as f64), fy - T::c(y0 as f64));
    let (a, b, c, d) = (
        lin[y0 * w + x0],
        lin[y0 * w + x1],
        lin[y1 * w + x0],
        lin[y1 * w + x1],
    );
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

fn aperture<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    s: &RenderSettings,
    _: Option<()>,
) -> (Image<T>, ()) {
    let (w, h) = (aif.width, aif.height);
    let lin = linear(aif, s);
    let samples = aperture_samples(APERTURE_SAMPLES);
    let (k, f, g, off) = (
        s.camera.blur_k,
        s.camera.focus_disparity,
        T::c(s.camera.gamma),
        T::c(s.camera.offset),
    );
    let data: Vec<T> = (0..w * h)
        .into_par_iter()
        .flat_map_iter(|i| {
            let shift = k * (disparity.data[i].f64() - f);
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let mut acc = [T::zero(); 3];
            for &(u, v) in &samples {
                let (val, _, _) = bilinear(&lin, w, h, T::c(x + shift * u), T::c(y + shift * v));
                for c in 0..3 {
                    acc[c] = acc[c] + val[c];
                }
            }
            let n = T::c(samples.len() as f64);
            acc.map(|v| model::encode(v / n, g, off))
        })
        .collect();
    (Image::from_vec(w, h, 3, data).unwrap(), ())
}

fn aperture_vjp<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    s: &RenderSettings,
    g: &Image<T>,
) -> Image<T> {
    let (w, h) = (aif.width, aif.height);
    let lin = linear(aif, s);
    let samples = aperture_samples(APERTURE_SAMPLES);
    let (k, f, gamma) = (
        s.camera.blur_k,
        s.camera.focus_disparity,
        T::c(s.camera.gamma),
    );
    let grad: Vec<T> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let shift = k * (disparity.data[i].f64() - f);
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let (mut acc, mut dacc) = ([T::zero(); 3], [T::zero(); 3]);
            for &(u, v) in &samples {
                let (fx, fy) = (x + shift * u, y + shift * v);
                let (val, gx, gy) = bilinear(&lin, w, h, T::c(fx), T::c(fy));
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
            let n = T::c(samples.len() as f64);
            let mut total = T::zero();
            for c in 0..3 {
                total = total
                    + g.data[3 * i + c] * model::encode_derivative(acc[c] / n, gamma) * dacc[c] / n;
            }
            total
        })
        .collect();
    Image::from_vec(w, h, 1, grad).unwrap()
}
