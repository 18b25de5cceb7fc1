//! Classical bokeh renderers and rendering layers, the baselines Dr.Bokeh is compared with,
//! shared by the evaluation ([`crate::eval`]) and depth from defocus ([`crate::dfd`]).
//!
//! Every baseline takes the renderer's inputs (an all-in-focus image + disparity map, or a
//! [`LayerStack`]) and a camera (blur `K`, focus `f`, gamma, offset), works in linear light
//! and encodes its output with the same transfer, so all methods are compared on equal
//! terms. The optional highlight boost is not applied.
//!
//! **Blur size convention.** The circle of confusion (CoC) of a pixel of disparity `disp`
//! has radius `rho = K |disp - f|` pixels, exactly the renderer's `r = K|d| + 1` without the
//! `+1` pixel footprint: the renderer needs the `+1` because its soft step
//! `S(r - dist)` falls to one half at `dist = r - ln(10)/3 = r - 0.77`, whereas the
//! baselines' discs are area-sampled (each pixel weighted by how much of it the disc
//! covers), so a disc of radius `rho` already has its edge at `rho`. A disc never gets
//! smaller than [`MIN_DISC_RADIUS_PX`] (one pixel: an in-focus pixel maps onto itself).
//!
//! **Borders.** Sums run over in-image pixels only and are normalised by the in-image
//! weight (no padding).
//!
//! The baselines ([`Baseline`]):
//! - [`naive_gather`]: each pixel averages the disc of its *own* CoC. Models blur size;
//!   ignores occlusion and the fact that light comes from the *sources'* discs: a blurred
//!   pixel next to a sharp object averages that object in (colour bleeding, a halo of the
//!   sharp object's colour), and a sharp pixel never receives light from blurred
//!   neighbours.
//! - [`naive_scatter`]: each pixel splats its disc (unit energy, weight `1/area`), and each
//!   receiver normalises by the weights it received (the classical half of BokehMe). Models
//!   where light goes; ignores depth order: a blurred background's discs spread over an
//!   in-focus foreground.
//! - [`layered_disc`]: disparity is cut into planes (default [`LAYERED_PLANES`]), each
//!   plane's premultiplied colour and alpha is blurred by the disc of the plane's CoC, and
//!   planes are composited back to front with `over` (the classical core of MPI/MPIB-style
//!   methods). Models occlusion between planes; ignores what an all-in-focus image does
//!   not show: a background plane has holes where the foreground covered it, which its blur
//!   turns into missing coverage (dark fringes), exactly as a classical layered renderer
//!   without inpainting does. Fed the ground-truth layer stack, it has the hidden content.
//!   It also quantises continuous disparity to the planes.
//! - [`gauss_psf`] ([`mod@gauss_psf`]): GaussPSF (Gur & Wolf 2019): each source spreads a
//!   Gaussian of `sigma ~ rho / 2`, gathered and normalised. Models blur size with a smooth
//!   kernel; ignores occlusion (like the naive scatter) and the disc shape of real bokeh.
//!
//! Two of them are also differentiable rendering layers for depth from defocus, each with
//! its adjoint beside its forward pass (`render` and `render_vjp`, gradients with respect
//! to disparity and, on request, colour; tested against finite differences):
//! [`mod@gauss_psf`] and [`aperture_compositing`] (Srinivasan et al. 2018: shifted copies
//! of the image averaged over aperture samples).

pub mod aperture_compositing;
mod disc;
pub mod gauss_psf;

pub use disc::{
    coc_radius_px, layered_disc, naive_gather, naive_scatter, LAYERED_PLANES, MIN_DISC_RADIUS_PX,
};

use crate::camera::Camera;
use crate::image::Image;
use crate::model::{self, Tone};
use crate::stack::LayerStack;
use crate::{Error, Real, Result};

/// A classical baseline renderer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Baseline {
    /// [`naive_gather`].
    NaiveGather,
    /// [`naive_scatter`].
    NaiveScatter,
    /// [`layered_disc`] with [`LAYERED_PLANES`] planes.
    LayeredDisc,
    /// [`gauss_psf`].
    GaussPsf,
}

impl Baseline {
    /// All baselines.
    pub const ALL: [Baseline; 4] = [
        Baseline::NaiveGather,
        Baseline::NaiveScatter,
        Baseline::LayeredDisc,
        Baseline::GaussPsf,
    ];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Baseline::NaiveGather => "gather",
            Baseline::NaiveScatter => "scatter",
            Baseline::LayeredDisc => "layered",
            Baseline::GaussPsf => "gausspsf",
        }
    }

    /// Renders a layer stack. [`Baseline::LayeredDisc`] uses the layers as they are; the
    /// others see the stack as an image + disparity pair ([`flatten`]; a single-layer stack
    /// is exactly its colour and disparity).
    pub fn render<T: Real>(self, stack: &LayerStack<T>, camera: &Camera) -> Result<Image<T>> {
        stack.validate()?;
        if self == Baseline::LayeredDisc {
            return layered_disc(stack, camera, LAYERED_PLANES);
        }
        let (aif, disparity) = flatten(stack, camera)?;
        match self {
            Baseline::NaiveGather => naive_gather(&aif, &disparity, camera),
            Baseline::NaiveScatter => naive_scatter(&aif, &disparity, camera),
            Baseline::GaussPsf => gauss_psf(&aif, &disparity, camera),
            Baseline::LayeredDisc => unreachable!(),
        }
    }
}

impl std::str::FromStr for Baseline {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Baseline::ALL
            .into_iter()
            .find(|b| b.name() == s)
            .ok_or_else(|| {
                Error::param(
                    "methods",
                    format!("unknown baseline '{s}' (gather, scatter, layered, gausspsf)"),
                )
            })
    }
}

/// The image + disparity pair a layer stack shows the camera: colour composited front to
/// back with `over` in linear light (the camera's gamma and offset), disparity of the
/// frontmost layer whose alpha is at least 0.5 (the last layer where none is). A
/// single-layer stack returns its colour and disparity unchanged.
pub fn flatten<T: Real>(stack: &LayerStack<T>, camera: &Camera) -> Result<(Image<T>, Image<T>)> {
    stack.validate()?;
    camera.validate()?;
    if stack.layers.len() == 1 {
        let l = &stack.layers[0];
        return Ok((l.rgb_encoded.clone(), l.disparity.clone()));
    }
    let (w, h) = (stack.width, stack.height);
    let (g, off) = (camera.gamma, camera.offset);
    let mut rgb = Image::new(w, h, 3);
    let mut disp = Image::new(w, h, 1);
    for i in 0..w * h {
        let mut acc = [0.0f64; 3];
        let mut t = 1.0f64;
        let mut d = None;
        for l in &stack.layers {
            let a = l.alpha.data[i].f64();
            for c in 0..3 {
                acc[c] += t * a * model::linearize(l.rgb_encoded.data[3 * i + c].f64(), g, off);
            }
            t *= 1.0 - a;
            if d.is_none() && a >= 0.5 {
                d = Some(l.disparity.data[i]);
            }
        }
        for c in 0..3 {
            rgb.data[3 * i + c] = T::c(model::encode(acc[c].max(0.0), g, off).max(0.0));
        }
        disp.data[i] = d.unwrap_or(stack.layers.last().unwrap().disparity.data[i]);
    }
    Ok((rgb, disp))
}

/// The GaussPSF baseline of `drbokeh eval` ([`gauss_psf::render_with_camera`]): the camera's
/// `K`, focus, gamma and offset, and a window wide enough for three standard deviations of
/// the largest Gaussian, so no blur is clipped.
pub fn gauss_psf<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    camera: &Camera,
) -> Result<Image<T>> {
    gauss_psf::render_with_camera(aif, disparity, camera)
}

/// A differentiable layer's render and its gradients (of `sum(G * render)` for the
/// upstream gradient `G`).
#[derive(Clone, Debug)]
pub struct LayerVjp<T> {
    /// The render (display-encoded).
    pub render: Image<T>,
    /// Gradient with respect to the disparity (1 channel).
    pub d_disparity: Image<T>,
    /// Gradient with respect to the encoded colour (3 channels), when asked for.
    pub d_rgb: Option<Image<T>>,
}

/// Checks that `aif` is HxWx3 and `disparity` HxWx1 of the same size.
pub(crate) fn check_pair<T>(aif: &Image<T>, disparity: &Image<T>) -> Result<()> {
    if aif.channels != 3
        || disparity.channels != 1
        || aif.width != disparity.width
        || aif.height != disparity.height
        || aif.data.len() != aif.width * aif.height * 3
        || disparity.data.len() != disparity.width * disparity.height
    {
        return Err(Error::input(
            "rendering layer",
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

/// Checks that an upstream gradient has the render's shape.
pub(crate) fn check_upstream<T>(render: &Image<T>, g: &Image<T>) -> Result<()> {
    if (g.width, g.height, g.channels) != (render.width, render.height, render.channels)
        || g.data.len() != render.data.len()
    {
        return Err(Error::input(
            "upstream gradient",
            format!(
                "is {}x{}x{}, but the render is {}x{}x{}",
                g.width, g.height, g.channels, render.width, render.height, render.channels
            ),
        ));
    }
    Ok(())
}

/// Linear colour of every pixel of an encoded RGB image.
pub(crate) fn linear_rgb<T: Real>(aif: &Image<T>, tone: &Tone) -> Vec<[T; 3]> {
    aif.data
        .chunks_exact(3)
        .map(|p| [0, 1, 2].map(|c| tone.linearize(p[c])))
        .collect()
}

/// Turns a gradient on linear colour (`d_lin(pixel, channel)`) into one on encoded colour.
pub(crate) fn linear_to_encoded_gradient<T: Real>(
    aif: &Image<T>,
    tone: &Tone,
    d_lin: impl Fn(usize, usize) -> T,
) -> Result<Image<T>> {
    let data = aif
        .data
        .iter()
        .enumerate()
        .map(|(k, &v)| d_lin(k / 3, k % 3) * tone.linearize_with_derivative(v).1)
        .collect();
    Image::from_vec(aif.width, aif.height, 3, data)
}
