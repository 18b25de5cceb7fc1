//! The backward driver shared by the schedules: the same chain rule around each schedule's
//! own passes over the taps.
//!
//! Chain (per layer, receiver x, source y; docs/model.md, "Derivatives"):
//! - tone: `dout/dlin` ([`model::Tone::encode_derivative`]);
//! - compositing and normalisation: [`model::composite_backward`] gives, per layer and
//!   receiver, `dL/dC(x)`, `dL/dW(x)` and `dL/do(x)` ([`ReceiverGrads`]);
//! - the schedule's passes ([`LayerPartials`]): through the tap weights
//!   `c = a(y) S(r(y), .) / A(r(y)) O(d(y), d(x), e(x))` to `Ilin(y)`, `a(y)`, `d(y)`,
//!   `d(x)` and K, and through the coverage to `a` (and `r(x)` for the soft disc);
//! - sources: `dlin/dI` and `dlin/dd` (highlight boost and transfer,
//!   [`model::source_linear_with_derivatives`]); `dL/df = -sum dL/d disp`.
//!
//! Every output element is written by one task in a fixed order, so results are the same
//! bytes for any thread count.

use super::tape::{Gradients, LayerGradients};
use crate::image::Image;
use crate::model::{self, LayerAtPixel, PixelModel};
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::stack::LayerStack;
use crate::{Error, Real, Result};
use rayon::prelude::*;
use std::borrow::Cow;

/// Upstream gradients of one layer at each receiver: `dL/dC` (3), `dL/dW`, `dL/do`.
pub(crate) struct ReceiverGrads<T> {
    /// `dL/dC(x)` per channel.
    pub d_colour_sum: Vec<[T; 3]>,
    /// `dL/dW(x)`.
    pub d_weight_sum: Vec<T>,
    /// `dL/do(x)`.
    pub d_coverage: Vec<T>,
}

/// What a schedule's passes over one layer give, per image pixel.
pub(crate) struct LayerPartials<T> {
    /// `dL/dIlin(y)` per channel.
    pub g_lin: Vec<[T; 3]>,
    /// `dL/da(y)` through the tap weights.
    pub g_alpha_scatter: Vec<T>,
    /// `dL/da(y)` through the coverage.
    pub g_alpha_coverage: Vec<T>,
    /// `dL/dd(x)` as a receiver (through `O`, `e` and the soft disc's radius).
    pub g_disp_receiver: Vec<T>,
    /// `dL/dd(y)` as a source (through `S`, `A` and `O`).
    pub g_disp_source: Vec<T>,
    /// `dL/dK` through the receivers (pass A) and through the sources (pass B).
    pub blur_k: (f64, f64),
}

/// Runs the backward pass of a recorded forward pass over `stack` with `settings`:
/// checks `grad_output`; `prepare()` builds the schedule's state; `record(&state)` gives the
/// per-layer sums (`saved(pixel, layer)`) and the linear composite they make; tone and
/// compositing are differentiated; then `passes(&state, layer, receiver gradients,
/// progress)` runs the schedule's passes over each layer (advancing `progress` by 3), and
/// the gradients are assembled.
pub(crate) fn run<'r, T: Real, P, S>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    grad_output: &Image<T>,
    progress: &dyn Progress,
    prepare: impl FnOnce() -> P,
    record: impl FnOnce(&P) -> (S, Cow<'r, [[T; 3]]>),
    mut passes: impl FnMut(&P, usize, ReceiverGrads<T>, &dyn Progress) -> LayerPartials<T>,
) -> Result<Gradients<T>>
where
    S: Fn(usize, usize) -> LayerAtPixel<T> + Sync,
{
    let (w, h) = (stack.width, stack.height);
    check_grad_output(grad_output, w, h)?;
    let n_layers = stack.layers.len();
    progress.start((n_layers * 3) as u64 + 1);
    let state = prepare();
    let (saved, linear) = record(&state);
    let receivers = receiver_gradients(n_layers, saved, &linear, grad_output, &settings.tone());
    drop(linear);
    progress.advance(1);
    let (dlin_dencoded, dlin_ddisp) = source_derivatives(stack, settings);
    let mut blur_k = 0.0f64;
    let mut layers_out = Vec::with_capacity(n_layers);
    for (l, rg) in receivers.into_iter().enumerate() {
        let p = passes(&state, l, rg, progress);
        blur_k += p.blur_k.0 + p.blur_k.1;
        layers_out.push(layer_gradients(
            (w, h),
            &p.g_lin,
            |i| p.g_alpha_scatter[i] + p.g_alpha_coverage[i],
            |i| p.g_disp_receiver[i] + p.g_disp_source[i],
            &dlin_dencoded[l],
            &dlin_ddisp[l],
        ));
    }
    let focus = focus_gradient(&layers_out);
    Ok(Gradients {
        layers: layers_out,
        blur_k,
        focus,
    })
}

/// Checks that `grad_output` is finite and shaped like a `w x h` RGB render.
fn check_grad_output<T: Real>(grad_output: &Image<T>, w: usize, h: usize) -> Result<()> {
    if grad_output.width != w || grad_output.height != h || grad_output.channels != 3 {
        return Err(Error::input(
            "output gradient",
            format!(
                "is {}x{}x{}, but the render is {w}x{h}x3",
                grad_output.width, grad_output.height, grad_output.channels
            ),
        ));
    }
    grad_output.check_finite("output gradient")
}

/// Tone and compositing backward: per layer, the receiver gradients `dL/dC`, `dL/dW`,
/// `dL/do`, from the recorded per-layer sums (`saved(pixel, layer)`) and linear composite.
fn receiver_gradients<T: Real>(
    n_layers: usize,
    saved: impl Fn(usize, usize) -> LayerAtPixel<T> + Sync,
    linear: &[[T; 3]],
    grad_output: &Image<T>,
    tone: &model::Tone,
) -> Vec<ReceiverGrads<T>> {
    // Per pixel, every layer's gradients (pixel-major), a row of pixels per task with
    // its working memory reused.
    let n = linear.len();
    let row = 256;
    let mut per_pixel = vec![model::LayerSumGradients::<T>::default(); n * n_layers];
    per_pixel
        .par_chunks_mut(row * n_layers)
        .enumerate()
        .for_each(|(k, out)| {
            let mut layers = Vec::with_capacity(n_layers);
            let mut behind = Vec::with_capacity(n_layers + 1);
            for (j, out) in out.chunks_mut(n_layers).enumerate() {
                let i = k * row + j;
                layers.clear();
                for l in 0..n_layers {
                    layers.push(saved(i, l));
                }
                let mut g_lin = [T::zero(); 3];
                for c in 0..3 {
                    g_lin[c] = grad_output.data[3 * i + c] * tone.encode_derivative(linear[i][c]);
                }
                model::composite_backward_into(&layers, g_lin, &mut behind, out);
            }
        });
    (0..n_layers)
        .map(|l| {
            let layer = || (0..n).into_par_iter().map(|i| &per_pixel[i * n_layers + l]);
            ReceiverGrads {
                d_colour_sum: layer().map(|p| p.colour_sum).collect(),
                d_weight_sum: layer().map(|p| p.weight_sum).collect(),
                d_coverage: layer().map(|p| p.coverage).collect(),
            }
        })
        .collect()
}

/// Per layer, per source pixel: `dlin/dI` and `dlin/dd` for each channel (highlight boost
/// and display transfer, [`model::source_linear_with_derivatives`]).
#[allow(clippy::type_complexity)]
fn source_derivatives<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
) -> (Vec<Vec<[T; 3]>>, Vec<Vec<[T; 3]>>) {
    let pixel = PixelModel::<T>::new(&settings.camera, &settings.model());
    let (w, h) = (stack.width, stack.height);
    let (mut dlin_dencoded, mut dlin_ddisp) = (Vec::new(), Vec::new());
    for layer in &stack.layers {
        // Per pixel and independent: in parallel, each value as computed alone.
        let (di, dd): (Vec<[T; 3]>, Vec<[T; 3]>) = layer
            .rgb_encoded
            .data
            .par_chunks_exact(3)
            .zip(&layer.disparity.data)
            .map(|(px, &disp)| {
                let d = pixel.rel_disp(disp);
                let (mut a, mut b) = ([T::zero(); 3], [T::zero(); 3]);
                for c in 0..3 {
                    let (_, x, y) = pixel.linear_with_derivatives(px[c], d);
                    a[c] = x;
                    b[c] = y;
                }
                (a, b)
            })
            .unzip();
        debug_assert_eq!(di.len(), w * h);
        dlin_dencoded.push(di);
        dlin_ddisp.push(dd);
    }
    (dlin_dencoded, dlin_ddisp)
}

/// One layer's input gradients from the gradients reaching its linear colour, alpha and
/// relative disparity (chain through `dlin/dI` and `dlin/dd`).
fn layer_gradients<T: Real>(
    (w, h): (usize, usize),
    g_lin: &[[T; 3]],
    g_alpha: impl Fn(usize) -> T + Sync,
    g_disp: impl Fn(usize) -> T + Sync,
    dlin_dencoded: &[[T; 3]],
    dlin_ddisp: &[[T; 3]],
) -> LayerGradients<T> {
    let mut rgb = Image::new(w, h, 3);
    let mut alpha = Image::new(w, h, 1);
    let mut disparity = Image::new(w, h, 1);
    rgb.data
        .par_chunks_mut(3 * w)
        .zip(alpha.data.par_chunks_mut(w))
        .zip(disparity.data.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((rgb, alpha), disparity))| {
            for x in 0..w {
                let i = y * w + x;
                let mut g_d = g_disp(i);
                for c in 0..3 {
                    rgb[3 * x + c] = g_lin[i][c] * dlin_dencoded[i][c];
                    g_d = g_d + g_lin[i][c] * dlin_ddisp[i][c];
                }
                alpha[x] = g_alpha(i);
                disparity[x] = g_d;
            }
        });
    LayerGradients {
        rgb,
        alpha,
        disparity,
    }
}

/// Every `d = disp - f`: `dL/df = -sum dL/d disp`.
fn focus_gradient<T: Real>(layers: &[LayerGradients<T>]) -> f64 {
    -layers
        .iter()
        .flat_map(|l| l.disparity.data.iter())
        .map(|v| v.f64())
        .sum::<f64>()
}

/// Adds each padded pixel's value onto the image pixel it mirrors (`source[p]`), in padded
/// order (so deterministic): the adjoint of reflection padding.
pub(crate) fn fold_padded<T: Real>(source: &[usize], padded: Vec<T>, pixels: usize) -> Vec<T> {
    let mut out = vec![T::zero(); pixels];
    for (p, v) in padded.into_iter().enumerate() {
        let s = source[p];
        out[s] = out[s] + v;
    }
    out
}
