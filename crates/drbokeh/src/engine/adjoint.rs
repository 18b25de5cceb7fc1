//! The adjoint (vector-Jacobian product) of the whole forward pass: gradients of a scalar
//! loss with respect to every layer's colour, alpha and disparity, and to the camera's
//! blur strength K and focus disparity f.
//!
//! Two schedules ([`render_with_tape_on`]):
//! - [`Engine::Threaded`] (also [`Engine::Reference`], and [`render_with_tape`]): this
//!   module, the exact adjoint. Forward and backward share the threaded engine's padded
//!   planes and visit every tap of the full `L x L` window in every pass; the output is the
//!   threaded render, bit for bit.
//! - [`Engine::Fast`]: `engine/fast_adjoint.rs`, the fast engine's schedule (tiles bounded
//!   by the blur radii that reach them, the soft step's far tail dropped, vectorised runs);
//!   the output is the fast render, bit for bit, and the gradients agree with the exact
//!   ones to 1e-5 of their largest value (tested; typically 1e-6). At 512x512, 2 layers,
//!   K 30, L 71 its backward takes about 2x the fast forward (seconds, against minutes).
//!
//! Both use the model's terms ([`crate::model`], each soft term beside its derivative).
//! The backward pass is a *gather*: every output element is written by exactly one task,
//! so it is race-free and deterministic for any thread count.
//!
//! Chain (per layer, receiver x, source y; see the spec's "Differentiability"):
//! - tone: `dout/dlin = (1/g) lin^(1/g - 1)`;
//! - compositing, with `U_l = B_l o_l + (1 - o_l) U_{l+1}`: `dU_l/dB_l = o_l`,
//!   `dU_l/do_l = B_l - U_{l+1}`, `dU_l/dU_{l+1} = 1 - o_l`;
//! - normalisation: `dB/dc(y,x) = (Ilin(y) - B(x)) / (W(x) + 1e-8)`;
//! - tap weight `c = a(y) S(r(y), .) / r(y)^2 O(d(y), d(x), e(x))`, `r = K|d| + 1`,
//!   `e = exp(-3 (K d(x))^2)`, `d = disp - f`;
//! - coverage, [`Coverage::PaperBox`]: a box mean of alpha; its half-size `floor(r/2)` is
//!   piecewise constant, so it contributes nothing through r (as in the paper);
//! - coverage, [`Coverage::SoftDisc`]: `o = sum S(r(x), y) a(y) / Z`, with
//!   `do/da(y) = S / Z` and `do/dr(x) = sum S' (a(y) - o) / Z` ([`model::DiscCoverage`]);
//! - tone: gamma or exact sRGB ([`model::Tone`]), both in the model beside their derivatives.
//!
//! Passes: (A) over receivers x: the gradient reaching `d(x)` and K through `O`/`e`;
//! (B) over padded source pixels y: gradients reaching `Ilin(y)`, `a(y)`, `d(y)` and K
//! through S, A and O; (C) over padded pixels: coverage's gradient to alpha. Padded
//! gradients are folded back onto their mirrored source pixels in a fixed order.

use super::threaded::{pad_layers, Kernel, PaddedLayer};
use super::{Engine, Progress};
use crate::image::Image;
use crate::model;
use crate::presets::{Coverage, RenderSettings};
use crate::stack::LayerStack;
use crate::{Error, Real, Result};
use rayon::prelude::*;

/// Per-layer, per-pixel sums saved by the forward pass.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Saved<T> {
    /// Weight sum `W`.
    pub weight: T,
    /// Layer colour `B = C / (W + 1e-8)`.
    pub colour: [T; 3],
    /// Layer coverage `o`.
    pub coverage: T,
}

/// One pixel of the recorded forward pass: per-layer sums and the linear composite.
type PixelRecord<T> = (Vec<Saved<T>>, [T; 3]);

/// Everything the backward pass needs, recorded by [`render_with_tape`] or
/// [`render_with_tape_on`].
pub struct Tape<T> {
    inner: TapeInner<T>,
}

enum TapeInner<T> {
    Threaded(ThreadedTape<T>),
    Fast(super::fast_adjoint::FastTape<T>),
}

/// The threaded (exact, every window tap) schedule's tape.
struct ThreadedTape<T> {
    settings: RenderSettings,
    width: usize,
    height: usize,
    layers: Vec<PaddedLayer<T>>,
    /// Per layer, per source pixel: `dlin/dI` for each channel.
    dlin_dencoded: Vec<Vec<[T; 3]>>,
    /// Per layer, per source pixel: `dlin/dd` for each channel.
    dlin_ddisp: Vec<Vec<[T; 3]>>,
    /// Per pixel, per layer.
    saved: Vec<Vec<Saved<T>>>,
    /// Linear composite per pixel.
    linear: Vec<[T; 3]>,
}

/// Gradients of one layer, shaped like the layer.
#[derive(Clone, Debug)]
pub struct LayerGradients<T> {
    /// d loss / d encoded colour (3 channels).
    pub rgb: Image<T>,
    /// d loss / d alpha.
    pub alpha: Image<T>,
    /// d loss / d disparity.
    pub disparity: Image<T>,
}

/// Gradients of a scalar loss with respect to all inputs of a render.
#[derive(Clone, Debug)]
pub struct Gradients<T> {
    /// One entry per layer, front first.
    pub layers: Vec<LayerGradients<T>>,
    /// d loss / d K (blur strength).
    pub blur_k: f64,
    /// d loss / d f (focus disparity).
    pub focus: f64,
}

/// Renders like [`crate::render`] with the threaded engine (bit-identical output) and
/// records what [`Tape::backward`] needs: the exact adjoint, every window tap
/// (`render_with_tape_on(.., Engine::Threaded, ..)`).
pub fn render_with_tape<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Image<T>, Tape<T>)> {
    render_with_tape_on(stack, settings, Engine::Threaded, progress)
}

/// Renders with the chosen engine and records what [`Tape::backward`] needs.
///
/// - [`Engine::Reference`] and [`Engine::Threaded`]: the exact adjoint on the threaded
///   schedule (every window tap); the output is the threaded render, bit for bit.
/// - [`Engine::Fast`]: forward and backward on the fast engine's schedule (tiles bounded by
///   the blur radii that reach them, the soft step's tail beyond `r + 4.5` px dropped; see
///   `engine/fast_adjoint.rs`); the output is `render(.., Engine::Fast, ..)`, bit for bit,
///   and the gradients agree with the exact adjoint to about 1e-6 of their largest value.
pub fn render_with_tape_on<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    engine: Engine,
    progress: &dyn Progress,
) -> Result<(Image<T>, Tape<T>)> {
    stack.validate()?;
    settings.validate()?;
    progress.start(stack.height as u64);
    match engine {
        Engine::Reference | Engine::Threaded => {
            let (img, tape) = threaded_with_tape(stack, settings, progress);
            Ok((
                img,
                Tape {
                    inner: TapeInner::Threaded(tape),
                },
            ))
        }
        Engine::Fast => {
            let (img, tape) = super::fast_adjoint::render_with_tape(stack, settings, progress);
            Ok((
                img,
                Tape {
                    inner: TapeInner::Fast(tape),
                },
            ))
        }
    }
}

/// Per layer, per source pixel: `dlin/dI` and `dlin/dd` for each channel (highlight boost
/// and display transfer, [`model::source_linear_with_derivatives`]).
#[allow(clippy::type_complexity)]
pub(super) fn source_derivatives<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
) -> (Vec<Vec<[T; 3]>>, Vec<Vec<[T; 3]>>) {
    let cam = &settings.camera;
    let tone = settings.tone();
    let f = T::c(cam.focus_disparity);
    let (w, h) = (stack.width, stack.height);
    let (mut dlin_dencoded, mut dlin_ddisp) = (Vec::new(), Vec::new());
    for layer in &stack.layers {
        let (mut di, mut dd) = (Vec::with_capacity(w * h), Vec::with_capacity(w * h));
        for (px, &disp) in layer
            .rgb_encoded
            .data
            .chunks_exact(3)
            .zip(&layer.disparity.data)
        {
            let d = model::relative_disparity(disp, f);
            let (mut a, mut b) = ([T::zero(); 3], [T::zero(); 3]);
            for c in 0..3 {
                let (_, x, y) =
                    model::source_linear_with_derivatives(px[c], d, cam.highlight, &tone);
                a[c] = x;
                b[c] = y;
            }
            di.push(a);
            dd.push(b);
        }
        dlin_dencoded.push(di);
        dlin_ddisp.push(dd);
    }
    (dlin_dencoded, dlin_ddisp)
}

fn threaded_with_tape<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> (Image<T>, ThreadedTape<T>) {
    let tone = settings.tone();
    let layers = pad_layers(stack, settings);
    let stride = layers[0].stride;
    let kernel = Kernel::new(settings, stride);
    let big_r = kernel.big_r;
    let (w, h) = (stack.width, stack.height);
    let rows: Vec<Vec<PixelRecord<T>>> = (0..h)
        .into_par_iter()
        .map(|py| {
            let row = (0..w)
                .map(|px| {
                    let xi = (py + big_r) * stride + px + big_r;
                    let saved: Vec<Saved<T>> = layers
                        .iter()
                        .map(|layer| {
                            let (acc, coverage) = kernel.gather(layer, xi);
                            Saved {
                                weight: acc.weight,
                                colour: acc.layer_colour(),
                                coverage,
                            }
                        })
                        .collect();
                    let lin = model::composite(saved.iter().map(|s| (s.colour, s.coverage)));
                    (saved, lin)
                })
                .collect();
            progress.advance(1);
            row
        })
        .collect();
    let mut out = Image::new(w, h, 3);
    let mut saved = Vec::with_capacity(w * h);
    let mut linear = Vec::with_capacity(w * h);
    for (i, (s, lin)) in rows.into_iter().flatten().enumerate() {
        for c in 0..3 {
            out.data[3 * i + c] = tone.encode(lin[c]);
        }
        saved.push(s);
        linear.push(lin);
    }
    let (dlin_dencoded, dlin_ddisp) = source_derivatives(stack, settings);
    (
        out,
        ThreadedTape {
            settings: settings.clone(),
            width: w,
            height: h,
            layers,
            dlin_dencoded,
            dlin_ddisp,
            saved,
            linear,
        },
    )
}

/// Upstream gradients of one layer at each receiver: `dL/dC` (3), `dL/dW`, `dL/do`.
pub(super) struct ReceiverGrads<T> {
    /// `dL/dC(x)` per channel.
    pub d_colour_sum: Vec<[T; 3]>,
    /// `dL/dW(x)`.
    pub d_weight_sum: Vec<T>,
    /// `dL/do(x)`.
    pub d_coverage: Vec<T>,
}

/// Checks that `grad_output` is finite and shaped like a `w x h` RGB render.
pub(super) fn check_grad_output<T: Real>(grad_output: &Image<T>, w: usize, h: usize) -> Result<()> {
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
pub(super) fn receiver_gradients<T: Real>(
    n_layers: usize,
    saved: impl Fn(usize, usize) -> Saved<T> + Sync,
    linear: &[[T; 3]],
    grad_output: &Image<T>,
    tone: &model::Tone,
) -> Vec<ReceiverGrads<T>> {
    let eps = T::c(model::WEIGHT_EPSILON);
    let per_pixel: Vec<Vec<([T; 3], T, T)>> = (0..linear.len())
        .into_par_iter()
        .map(|i| {
            let saved: Vec<Saved<T>> = (0..n_layers).map(|l| saved(i, l)).collect();
            let mut g_lin = [T::zero(); 3];
            for c in 0..3 {
                g_lin[c] = grad_output.data[3 * i + c] * tone.encode_derivative(linear[i][c]);
            }
            // U_l from the back.
            let mut behind = vec![[T::zero(); 3]; n_layers + 1];
            for l in (0..n_layers).rev() {
                let s = &saved[l];
                for c in 0..3 {
                    behind[l][c] =
                        s.colour[c] * s.coverage + (T::one() - s.coverage) * behind[l + 1][c];
                }
            }
            let mut g_u = g_lin;
            (0..n_layers)
                .map(|l| {
                    let s = &saved[l];
                    let mut g_b = [T::zero(); 3];
                    let mut g_o = T::zero();
                    for c in 0..3 {
                        g_b[c] = g_u[c] * s.coverage;
                        g_o = g_o + g_u[c] * (s.colour[c] - behind[l + 1][c]);
                        g_u[c] = g_u[c] * (T::one() - s.coverage);
                    }
                    // B = C / (W + eps): dL/dC = gB / (W + eps), dL/dW = -sum gB B / (W + eps).
                    let inv = T::one() / (s.weight + eps);
                    let g_c = g_b.map(|v| v * inv);
                    let g_w =
                        -(g_b[0] * s.colour[0] + g_b[1] * s.colour[1] + g_b[2] * s.colour[2]) * inv;
                    (g_c, g_w, g_o)
                })
                .collect()
        })
        .collect();
    (0..n_layers)
        .map(|l| ReceiverGrads {
            d_colour_sum: per_pixel.iter().map(|p| p[l].0).collect(),
            d_weight_sum: per_pixel.iter().map(|p| p[l].1).collect(),
            d_coverage: per_pixel.iter().map(|p| p[l].2).collect(),
        })
        .collect()
}

/// One layer's input gradients from the gradients reaching its linear colour, alpha and
/// relative disparity (chain through `dlin/dI` and `dlin/dd`).
pub(super) fn layer_gradients<T: Real>(
    (w, h): (usize, usize),
    g_lin: &[[T; 3]],
    g_alpha: impl Fn(usize) -> T,
    g_disp: impl Fn(usize) -> T,
    dlin_dencoded: &[[T; 3]],
    dlin_ddisp: &[[T; 3]],
) -> LayerGradients<T> {
    let mut rgb = Image::new(w, h, 3);
    let mut alpha = Image::new(w, h, 1);
    let mut disparity = Image::new(w, h, 1);
    for i in 0..w * h {
        let mut g_d = g_disp(i);
        for c in 0..3 {
            rgb.data[3 * i + c] = g_lin[i][c] * dlin_dencoded[i][c];
            g_d = g_d + g_lin[i][c] * dlin_ddisp[i][c];
        }
        alpha.data[i] = g_alpha(i);
        disparity.data[i] = g_d;
    }
    LayerGradients {
        rgb,
        alpha,
        disparity,
    }
}

/// Every `d = disp - f`: `dL/df = -sum dL/d disp`.
pub(super) fn focus_gradient<T: Real>(layers: &[LayerGradients<T>]) -> f64 {
    -layers
        .iter()
        .flat_map(|l| l.disparity.data.iter())
        .map(|v| v.f64())
        .sum::<f64>()
}

impl<T: Real> Tape<T> {
    /// The settings this tape was recorded with.
    pub fn settings(&self) -> &RenderSettings {
        match &self.inner {
            TapeInner::Threaded(t) => &t.settings,
            TapeInner::Fast(t) => t.settings(),
        }
    }

    /// The schedule the backward pass runs on: [`Engine::Threaded`] (exact) or
    /// [`Engine::Fast`].
    pub fn engine(&self) -> Engine {
        match &self.inner {
            TapeInner::Threaded(_) => Engine::Threaded,
            TapeInner::Fast(_) => Engine::Fast,
        }
    }

    /// Back-propagates `grad_output` (d loss / d output, shaped like the rendered image)
    /// to every input. Deterministic for any thread count.
    pub fn backward(
        &self,
        grad_output: &Image<T>,
        progress: &dyn Progress,
    ) -> Result<Gradients<T>> {
        match &self.inner {
            TapeInner::Threaded(t) => t.backward(grad_output, progress),
            TapeInner::Fast(t) => t.backward(grad_output, progress),
        }
    }
}

impl<T: Real> ThreadedTape<T> {
    fn backward(&self, grad_output: &Image<T>, progress: &dyn Progress) -> Result<Gradients<T>> {
        let (w, h) = (self.width, self.height);
        check_grad_output(grad_output, w, h)?;
        let n_layers = self.layers.len();
        let tone = self.settings.tone();
        progress.start((n_layers * 3) as u64 + 1);

        // Tone and compositing: per layer, per pixel receiver gradients.
        let receivers = receiver_gradients(
            n_layers,
            |i, l| self.saved[i][l],
            &self.linear,
            grad_output,
            &tone,
        );
        progress.advance(1);

        let cam = &self.settings.camera;
        let k = T::c(cam.blur_k);
        let mut blur_k = 0.0f64;
        let mut layers_out = Vec::with_capacity(n_layers);
        for (l, rg) in receivers.iter().enumerate() {
            let layer = &self.layers[l];
            let kernel = Kernel::new(&self.settings, layer.stride);
            let (g_disp_receiver, k_a) = self.pass_receivers(layer, &kernel, rg, k);
            progress.advance(1);
            let (g_lin, g_alpha_scatter, g_disp_source, k_b) =
                self.pass_sources(layer, &kernel, rg, k);
            progress.advance(1);
            let g_alpha_cov = self.pass_coverage(layer, &kernel, rg);
            progress.advance(1);
            blur_k += k_a + k_b;
            layers_out.push(layer_gradients(
                (w, h),
                &g_lin,
                |i| g_alpha_scatter[i] + g_alpha_cov[i],
                |i| g_disp_receiver[i] + g_disp_source[i],
                &self.dlin_dencoded[l],
                &self.dlin_ddisp[l],
            ));
        }
        let focus = focus_gradient(&layers_out);
        Ok(Gradients {
            layers: layers_out,
            blur_k,
            focus,
        })
    }

    /// Unpadded index of padded index `p`, if it lies inside the image.
    #[inline(always)]
    fn inner(&self, p: isize, stride: usize, big_r: usize) -> Option<usize> {
        if p < 0 {
            return None;
        }
        let (py, px) = (p as usize / stride, p as usize % stride);
        if px < big_r || py < big_r || px >= big_r + self.width || py >= big_r + self.height {
            return None;
        }
        Some((py - big_r) * self.width + (px - big_r))
    }

    /// Pass A: gradient reaching each receiver's own disparity through `O` and `e`, and
    /// K's share through `e`. Returns per-pixel values and K's total (summed in row order).
    fn pass_receivers(
        &self,
        layer: &PaddedLayer<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
        k: T,
    ) -> (Vec<T>, f64) {
        let (w, h, big_r, stride) = (self.width, self.height, kernel.big_r, layer.stride);
        let rows: Vec<(Vec<T>, f64)> = (0..h)
            .into_par_iter()
            .map(|py| {
                let mut k_sum = 0.0;
                let row = (0..w)
                    .map(|px| {
                        let i = py * w + px;
                        let xi = (py + big_r) * stride + px + big_r;
                        let (d_x, e_x) = (layer.rel_disp[xi], layer.focus_weight[xi]);
                        let (de_dd, de_dk) = model::focus_weight_derivatives(k, d_x, e_x);
                        let (gc_rgb, gw) = (rg.d_colour_sum[i], rg.d_weight_sum[i]);
                        let (mut g_d, mut g_k) = (T::zero(), T::zero());
                        for (tap, offset, dist, gauge) in kernel.taps() {
                            if offset == 0 {
                                continue; // O(x, x) = 1
                            }
                            let yi = (xi as isize + offset) as usize;
                            let a_y = layer.alpha[yi];
                            if a_y == T::zero() {
                                continue;
                            }
                            let r_y = layer.radius_px[yi];
                            let lin = layer.rgb_linear[yi];
                            let gc =
                                gc_rgb[0] * lin[0] + gc_rgb[1] * lin[1] + gc_rgb[2] * lin[2] + gw;
                            let s = model::scatter_term(
                                kernel.step,
                                &kernel.aperture,
                                tap.dx,
                                tap.dy,
                                dist,
                                gauge,
                                r_y,
                            );
                            let base = gc * a_y * s / model::source_area(kernel.step, r_y);
                            let (_, do_ddx, do_de) =
                                model::occlusion_derivatives(e_x, layer.rel_disp[yi], d_x);
                            g_d = g_d + base * (do_ddx + do_de * de_dd);
                            g_k = g_k + base * do_de * de_dk;
                        }
                        if kernel.coverage == Coverage::SoftDisc {
                            // o(x) depends on r(x) = K |d(x)| + 1.
                            let g_r = rg.d_coverage[i]
                                * kernel.disc_coverage(layer, xi, true).derivative_radius();
                            g_d = g_d + g_r * k * sign(d_x);
                            g_k = g_k + g_r * d_x.abs();
                        }
                        k_sum += g_k.f64();
                        g_d
                    })
                    .collect();
                (row, k_sum)
            })
            .collect();
        let k_total = rows.iter().map(|r| r.1).sum();
        (rows.into_iter().flat_map(|r| r.0).collect(), k_total)
    }

    /// Pass B: over padded source pixels, gradients reaching `Ilin(y)`, `a(y)`, `d(y)`
    /// (through S, A and O) and K (through r); folded onto the mirrored source pixels.
    #[allow(clippy::type_complexity)]
    fn pass_sources(
        &self,
        layer: &PaddedLayer<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
        k: T,
    ) -> (Vec<[T; 3]>, Vec<T>, Vec<T>, f64) {
        let (stride, big_r) = (layer.stride, kernel.big_r);
        let padded_h = layer.alpha.len() / stride;
        let rows: Vec<(Vec<([T; 3], T, T)>, f64)> = (0..padded_h)
            .into_par_iter()
            .map(|py| {
                let mut k_sum = 0.0;
                let row = (0..stride)
                    .map(|px| {
                        let yi = py * stride + px;
                        let (a_y, r_y, d_y, lin) = (
                            layer.alpha[yi],
                            layer.radius_px[yi],
                            layer.rel_disp[yi],
                            layer.rgb_linear[yi],
                        );
                        let inv_area = T::one() / model::source_area(kernel.step, r_y);
                        let dlog_area = model::source_area_derivative(kernel.step, r_y) * inv_area;
                        let (mut g_lin, mut g_a, mut g_r, mut g_dy) =
                            ([T::zero(); 3], T::zero(), T::zero(), T::zero());
                        for (tap, offset, dist, gauge) in kernel.taps() {
                            let xp = yi as isize - offset;
                            let Some(x) = self.inner(xp, stride, big_r) else {
                                continue;
                            };
                            let xp = xp as usize;
                            let (gc_rgb, gw) = (rg.d_colour_sum[x], rg.d_weight_sum[x]);
                            let gc =
                                gc_rgb[0] * lin[0] + gc_rgb[1] * lin[1] + gc_rgb[2] * lin[2] + gw;
                            let (s, ds_dr) = model::scatter_term_with_derivative(
                                kernel.step,
                                &kernel.aperture,
                                tap.dx,
                                tap.dy,
                                dist,
                                gauge,
                                r_y,
                            );
                            let (o, do_ddy) = if offset == 0 {
                                (T::one(), T::zero())
                            } else {
                                let (e_x, d_x) = (layer.focus_weight[xp], layer.rel_disp[xp]);
                                (
                                    model::occlusion(e_x, d_y, d_x),
                                    model::occlusion_derivatives(e_x, d_y, d_x).0,
                                )
                            };
                            let c_per_alpha = s * inv_area * o;
                            for c in 0..3 {
                                g_lin[c] = g_lin[c] + gc_rgb[c] * a_y * c_per_alpha;
                            }
                            g_a = g_a + gc * c_per_alpha;
                            // d(S / A(r))/dr = (S' - S A'/A) / A
                            g_r = g_r + gc * a_y * o * (ds_dr - s * dlog_area) * inv_area;
                            g_dy = g_dy + gc * a_y * s * inv_area * do_ddy;
                        }
                        // r = K |d| + 1
                        k_sum += (g_r * d_y.abs()).f64();
                        (g_lin, g_a, g_dy + g_r * k * sign(d_y))
                    })
                    .collect();
                (row, k_sum)
            })
            .collect();
        let k_total = rows.iter().map(|r| r.1).sum();
        let n = self.width * self.height;
        let (mut g_lin, mut g_a, mut g_d) = (
            vec![[T::zero(); 3]; n],
            vec![T::zero(); n],
            vec![T::zero(); n],
        );
        for (p, (gl, ga, gd)) in rows.into_iter().flat_map(|r| r.0).enumerate() {
            let s = layer.source[p];
            for c in 0..3 {
                g_lin[s][c] = g_lin[s][c] + gl[c];
            }
            g_a[s] = g_a[s] + ga;
            g_d[s] = g_d[s] + gd;
        }
        (g_lin, g_a, g_d, k_total)
    }

    /// Pass C: coverage's gradient to alpha, for the model's coverage term.
    fn pass_coverage(
        &self,
        layer: &PaddedLayer<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
    ) -> Vec<T> {
        match kernel.coverage {
            Coverage::PaperBox => self.pass_coverage_box(layer, kernel, rg),
            Coverage::SoftDisc => self.pass_coverage_disc(layer, kernel, rg),
        }
    }

    /// Soft-disc coverage `o(x) = sum_y S(r(x), y) a(y) / Z(x)`: each padded pixel y
    /// gathers `dL/do(x) S(r(x), y) / Z(x)` from the receivers whose window holds it.
    fn pass_coverage_disc(
        &self,
        layer: &PaddedLayer<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
    ) -> Vec<T> {
        let (w, h, stride, big_r) = (self.width, self.height, layer.stride, kernel.big_r);
        let share: Vec<T> = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let xi = (i / w + big_r) * stride + i % w + big_r;
                rg.d_coverage[i] / kernel.disc_coverage(layer, xi, false).weight
            })
            .collect();
        let padded_h = layer.alpha.len() / stride;
        let padded: Vec<T> = (0..padded_h)
            .into_par_iter()
            .flat_map_iter(|py| {
                let share = &share;
                (0..stride).map(move |px| {
                    let yi = py * stride + px;
                    let mut acc = T::zero();
                    for (tap, offset, dist, gauge) in kernel.taps() {
                        let xp = yi as isize - offset;
                        let Some(x) = self.inner(xp, stride, big_r) else {
                            continue;
                        };
                        let (r_x, _) = model::coverage_radius_px(
                            layer.radius_px[xp as usize],
                            kernel.coverage_radius,
                            kernel.footprint_px,
                        );
                        let s = model::scatter_term(
                            kernel.step,
                            &kernel.aperture,
                            tap.dx,
                            tap.dy,
                            dist,
                            gauge,
                            r_x,
                        );
                        acc = acc + share[x] * s;
                    }
                    acc
                })
            })
            .collect();
        fold_padded(layer, padded, w * h)
    }

    /// Paper coverage `o(x) = mean of alpha over a box of half-size h(x)`; each padded
    /// pixel gathers `dL/do(x) / n(x)` from the receivers whose box holds it.
    fn pass_coverage_box(
        &self,
        layer: &PaddedLayer<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
    ) -> Vec<T> {
        let (w, h, stride, big_r) = (self.width, self.height, layer.stride, kernel.big_r);
        let half: Vec<usize> = (0..w * h)
            .map(|i| {
                let xi = (i / w + big_r) * stride + i % w + big_r;
                model::coverage_half_size_px(layer.radius_px[xi], big_r)
            })
            .collect();
        let share: Vec<T> = (0..w * h)
            .map(|i| rg.d_coverage[i] / T::c(((2 * half[i] + 1) * (2 * half[i] + 1)) as f64))
            .collect();
        let h_max = half.iter().copied().max().unwrap_or(0) as isize;
        let padded_h = layer.alpha.len() / stride;
        let padded: Vec<T> = (0..padded_h)
            .into_par_iter()
            .flat_map_iter(|py| {
                let half = &half;
                let share = &share;
                (0..stride).map(move |px| {
                    let mut acc = T::zero();
                    for dy in -h_max..=h_max {
                        for dx in -h_max..=h_max {
                            let (qx, qy) = (px as isize - dx, py as isize - dy);
                            if qx < big_r as isize
                                || qy < big_r as isize
                                || qx >= (big_r + w) as isize
                                || qy >= (big_r + h) as isize
                            {
                                continue;
                            }
                            let x = (qy as usize - big_r) * w + (qx as usize - big_r);
                            let hx = half[x] as isize;
                            if dx.abs() <= hx && dy.abs() <= hx {
                                acc = acc + share[x];
                            }
                        }
                    }
                    acc
                })
            })
            .collect();
        fold_padded(layer, padded, w * h)
    }
}

/// Adds each padded pixel's value onto the source pixel it mirrors (fixed order, so
/// deterministic): the adjoint of reflection padding.
fn fold_padded<T: Real>(layer: &PaddedLayer<T>, padded: Vec<T>, pixels: usize) -> Vec<T> {
    let mut out = vec![T::zero(); pixels];
    for (p, v) in padded.into_iter().enumerate() {
        let s = layer.source[p];
        out[s] = out[s] + v;
    }
    out
}

/// `d|d|/dd`: the sign of `d` (0 at the kink).
#[inline(always)]
pub(super) fn sign<T: Real>(d: T) -> T {
    if d > T::zero() {
        T::one()
    } else if d < T::zero() {
        -T::one()
    } else {
        T::zero()
    }
}

impl<T: Real> Gradients<T> {
    /// The published kernel's training heuristic ("gradient clipping"), offered as an
    /// explicit option and off by default: per-pixel gradient values whose magnitude lies
    /// in `[lo, hi)` are raised to `hi`, keeping their sign (the paper's `lo = 1e-6`,
    /// `hi = 1e-2`). The result is no longer the gradient of the loss.
    pub fn rescale_small(&mut self, lo: f64, hi: f64) {
        let (lo, hi) = (T::c(lo), T::c(hi));
        for l in &mut self.layers {
            for v in l
                .rgb
                .data
                .iter_mut()
                .chain(&mut l.alpha.data)
                .chain(&mut l.disparity.data)
            {
                let m = v.abs();
                if m >= lo && m < hi {
                    *v = if *v > T::zero() { hi } else { -hi };
                }
            }
        }
    }
}
