//! The exact adjoint on the threaded schedule: forward and backward share the padded
//! planes and visit every tap of the full `L x L` window in every pass; the output is the
//! threaded render, bit for bit ([`super::forward::render_with_tape`]).
//!
//! Passes per layer, around the shared chain rule ([`crate::engine::backward`]):
//! (A) over receivers x: the gradient reaching `d(x)` and K through `O`/`e` (and the soft
//! disc's radius); (B) over padded source pixels y: gradients reaching `Ilin(y)`, `a(y)`,
//! `d(y)` and K through S, A and O; (C) over padded pixels: the coverage's gradient to
//! alpha (the paper's box: its half-size `floor(r/2)` is piecewise constant and contributes
//! nothing through r; the soft disc: `do/da(y) = S / Z`). Padded gradients are folded back
//! onto their mirrored source pixels in a fixed order. The backward is a *gather*: every
//! output element is written by exactly one task, so it is race-free and deterministic for
//! any thread count.

use super::kernel::Kernel;
use crate::engine::backward::{self, fold_padded, LayerPartials, ReceiverGrads};
use crate::engine::planes::Planes;
use crate::engine::tape::{Backward, Gradients};
use crate::image::Image;
use crate::model::{self, Coverage, LayerAtPixel};
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::stack::LayerStack;
use crate::{Real, Result};
use rayon::prelude::*;
use std::borrow::Cow;

/// The threaded (exact, every window tap) schedule's tape.
pub(crate) struct ThreadedTape<T> {
    pub(super) settings: RenderSettings,
    pub(super) stack: LayerStack<T>,
    pub(super) layers: Vec<Planes<T>>,
    /// Per pixel, per layer.
    pub(super) saved: Vec<Vec<LayerAtPixel<T>>>,
    /// Linear composite per pixel.
    pub(super) linear: Vec<[T; 3]>,
}

impl<T: Real> Backward<T> for ThreadedTape<T> {
    fn backward(&self, grad_output: &Image<T>, progress: &dyn Progress) -> Result<Gradients<T>> {
        let k = T::c(self.settings.camera.blur_k);
        backward::run(
            &self.stack,
            &self.settings,
            grad_output,
            progress,
            || (),
            |_| {
                (
                    |i: usize, l: usize| self.saved[i][l],
                    Cow::Borrowed(&self.linear[..]),
                )
            },
            |_, l, rg, progress| {
                let layer = &self.layers[l];
                let kernel = Kernel::new(&self.settings, layer.stride);
                let (g_disp_receiver, k_a) = self.pass_receivers(layer, &kernel, &rg, k);
                progress.advance(1);
                let (g_lin, g_alpha_scatter, g_disp_source, k_b) =
                    self.pass_sources(layer, &kernel, &rg, k);
                progress.advance(1);
                let g_alpha_coverage = self.pass_coverage(layer, &kernel, &rg);
                progress.advance(1);
                LayerPartials {
                    g_lin,
                    g_alpha_scatter,
                    g_alpha_coverage,
                    g_disp_receiver,
                    g_disp_source,
                    blur_k: (k_a, k_b),
                }
            },
        )
    }
}

impl<T: Real> ThreadedTape<T> {
    fn width(&self) -> usize {
        self.stack.width
    }

    fn height(&self) -> usize {
        self.stack.height
    }

    /// `f(px, py)` for every padded pixel of `layer`, rows in parallel, folded onto the
    /// image pixels they mirror (in padded order, so deterministic): the adjoint of
    /// reflection padding applied to a per-padded-pixel gather.
    fn gather_padded(&self, layer: &Planes<T>, f: impl Fn(usize, usize) -> T + Sync) -> Vec<T> {
        let stride = layer.stride;
        let f = &f;
        let padded: Vec<T> = (0..layer.rows)
            .into_par_iter()
            .flat_map_iter(|py| (0..stride).map(move |px| f(px, py)))
            .collect();
        fold_padded(&layer.source, padded, self.width() * self.height())
    }

    /// Unpadded index of padded index `p`, if it lies inside the image.
    #[inline(always)]
    fn inner(&self, p: isize, stride: usize, big_r: usize) -> Option<usize> {
        if p < 0 {
            return None;
        }
        let (py, px) = (p as usize / stride, p as usize % stride);
        if px < big_r || py < big_r || px >= big_r + self.width() || py >= big_r + self.height() {
            return None;
        }
        Some((py - big_r) * self.width() + (px - big_r))
    }

    /// Pass A: gradient reaching each receiver's own disparity through `O` and `e`, and
    /// K's share through `e`. Returns per-pixel values and K's total (summed in row order).
    fn pass_receivers(
        &self,
        layer: &Planes<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
        k: T,
    ) -> (Vec<T>, f64) {
        let (w, h) = (self.width(), self.height());
        let rows: Vec<(Vec<T>, f64)> = (0..h)
            .into_par_iter()
            .map(|py| {
                let mut k_sum = 0.0;
                let row = (0..w)
                    .map(|px| {
                        let i = py * w + px;
                        let xi = layer.index(px, py);
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
                            let r_y = layer.radius[yi];
                            let lin = layer.rgb(yi);
                            let gc =
                                gc_rgb[0] * lin[0] + gc_rgb[1] * lin[1] + gc_rgb[2] * lin[2] + gw;
                            let s = kernel.scatter::<false>(tap, dist, gauge, r_y).0;
                            let base = gc * a_y * s / model::source_area(kernel.step, r_y);
                            let (_, do_ddx, do_de) =
                                model::occlusion_derivatives(e_x, layer.rel_disp[yi], d_x);
                            g_d = g_d + base * (do_ddx + do_de * de_dd);
                            g_k = g_k + base * do_de * de_dk;
                        }
                        if kernel.coverage == Coverage::SoftDisc {
                            // o(x) depends on r(x) = K |d(x)| + 1.
                            let g_r = rg.d_coverage[i]
                                * kernel.disc_coverage::<true>(layer, xi).derivative_radius();
                            g_d = g_d + g_r * k * model::scatter_radius_sign(d_x);
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
        layer: &Planes<T>,
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
                            layer.radius[yi],
                            layer.rel_disp[yi],
                            layer.rgb(yi),
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
                            let (s, ds_dr) = kernel.scatter::<true>(tap, dist, gauge, r_y);
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
                            g_r = g_r
                                + gc * a_y
                                    * o
                                    * model::normalised_scatter_radius_factor(s, ds_dr, dlog_area)
                                    * inv_area;
                            g_dy = g_dy + gc * a_y * s * inv_area * do_ddy;
                        }
                        // r = K |d| + 1
                        k_sum += (g_r * d_y.abs()).f64();
                        (g_lin, g_a, g_dy + g_r * k * model::scatter_radius_sign(d_y))
                    })
                    .collect();
                (row, k_sum)
            })
            .collect();
        let k_total = rows.iter().map(|r| r.1).sum();
        let n = self.width() * self.height();
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
        layer: &Planes<T>,
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
        layer: &Planes<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
    ) -> Vec<T> {
        let (w, h, stride, big_r) = (self.width(), self.height(), layer.stride, kernel.big_r);
        let share: Vec<T> = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let xi = layer.index(i % w, i / w);
                rg.d_coverage[i] / kernel.disc_coverage::<false>(layer, xi).weight
            })
            .collect();
        self.gather_padded(layer, |px, py| {
            let yi = py * stride + px;
            let mut acc = T::zero();
            for (tap, offset, dist, gauge) in kernel.taps() {
                let xp = yi as isize - offset;
                let Some(x) = self.inner(xp, stride, big_r) else {
                    continue;
                };
                let (r_x, _) = model::coverage_radius_px(
                    layer.radius[xp as usize],
                    kernel.coverage_radius,
                    kernel.footprint_px,
                );
                let s = kernel.scatter::<false>(tap, dist, gauge, r_x).0;
                acc = acc + share[x] * s;
            }
            acc
        })
    }

    /// Paper coverage `o(x) = mean of alpha over a box of half-size h(x)`; each padded
    /// pixel gathers `dL/do(x) / n(x)` from the receivers whose box holds it.
    fn pass_coverage_box(
        &self,
        layer: &Planes<T>,
        kernel: &Kernel<T>,
        rg: &ReceiverGrads<T>,
    ) -> Vec<T> {
        let (w, h, big_r) = (self.width(), self.height(), kernel.big_r);
        let half: Vec<usize> = (0..w * h)
            .map(|i| {
                let xi = layer.index(i % w, i / w);
                model::coverage_half_size_px(layer.radius[xi], big_r)
            })
            .collect();
        let share: Vec<T> = (0..w * h)
            .map(|i| rg.d_coverage[i] / T::c(((2 * half[i] + 1) * (2 * half[i] + 1)) as f64))
            .collect();
        let h_max = half.iter().copied().max().unwrap_or(0) as isize;
        self.gather_padded(layer, |px, py| {
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
    }
}
