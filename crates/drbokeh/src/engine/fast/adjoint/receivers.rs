//! Pass A of the fast adjoint, over receivers in tiles bounded by the largest radius
//! among sources with alpha > 0 in the tile's window: the gradient reaching `d(x)` (and K)
//! through `O` and `e(x)` (only where `e(x) >= 1e-9`; below it the render takes `O = 1`),
//! and through the soft-disc coverage's radius `r(x)`; also each receiver's
//! `dL/do(x) / Z(x)` for pass C.

use super::context::Ctx;
use crate::engine::fast::runs::{for_each_lane, lane_sum, CHUNK, LANES};
use crate::engine::fast::tiles::{
    backward_reach, source_block_max, tile_max_radius, TILE, TILE_ROWS,
};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::model::{self, ApertureEval, Coverage};
use crate::Real;
use rayon::prelude::*;

/// Per receiver: the gradient to `d(x)`, `dL/do(x) / Z(x)` (soft-disc coverage only, else
/// empty) and K's total.
pub(super) fn pass_receivers<T: Real>(ctx: &Ctx<'_, T>) -> (Vec<T>, Vec<T>, f64) {
    let (w, h) = (ctx.rcv.width, ctx.rcv.height);
    let block_max = source_block_max(ctx.src, |i| ctx.src.alpha[i] > T::zero());
    let disc = ctx.settings.model().coverage == Coverage::SoftDisc;
    let tiles: Vec<(Vec<T>, Vec<T>, f64)> = (0..h)
        .step_by(TILE_ROWS)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y0| receivers_tile_row_dispatch(ctx, &block_max, y0))
        .collect();
    let mut g_d = Vec::with_capacity(w * h);
    let mut share = Vec::with_capacity(if disc { w * h } else { 0 });
    let mut k_total = 0.0;
    for (g, s, k) in tiles {
        g_d.extend(g);
        share.extend(s);
        k_total += k;
    }
    (g_d, share, k_total)
}

avx2_dispatch!(
    receivers_tile_row_dispatch,
    receivers_tile_row_avx2,
    receivers_tile_row,
    (ctx: &Ctx<'_, T>, block_max: &[f64], y0: usize) -> (Vec<T>, Vec<T>, f64)
);

/// Pass A over the receiver rows `y0 .. y0 + TILE_ROWS`, tile by tile.
#[inline(always)]
fn receivers_tile_row<T: Real>(
    ctx: &Ctx<'_, T>,
    block_max: &[f64],
    y0: usize,
) -> (Vec<T>, Vec<T>, f64) {
    let (src, rcv, tables) = (ctx.src, ctx.rcv, ctx.tables);
    let (w, h, big_r, stride) = (rcv.width, rcv.height, tables.big_r, src.stride);
    let y1 = (y0 + TILE_ROWS).min(h);
    let k = ctx.k;
    let model_opts = ctx.settings.model();
    let disc = model_opts.coverage == Coverage::SoftDisc;
    let mut g_d = vec![T::zero(); (y1 - y0) * w];
    let mut share = vec![T::zero(); if disc { (y1 - y0) * w } else { 0 }];
    let mut k_rows = vec![0.0f64; (y1 - y0) * w];
    for x0 in (0..w).step_by(TILE) {
        let x1 = (x0 + TILE).min(w);
        // Largest radius among sources with alpha > 0 in the tile's window.
        let max_r = tile_max_radius(block_max, stride, big_r, (x0, x1), (y0, y1));
        let widths: Vec<Option<usize>> = if max_r > f64::NEG_INFINITY {
            tables.half_widths(backward_reach(ctx.aperture, max_r))
        } else {
            Vec::new()
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let i = y * w + x;
                let o = (y - y0) * w + x;
                let xi = src.index(x, y);
                let (d_x, e_x) = (rcv.rel_disp[i], rcv.focus_weight[i]);
                let (mut gd, mut gk) = (T::zero(), T::zero());
                if e_x > T::zero() && !widths.is_empty() {
                    // sum over y != x of base = gc a S / A, times s'(D) and (s(D) - 1).
                    let gc = [rcv.g_red[i], rcv.g_green[i], rcv.g_blue[i], rcv.g_weight[i]];
                    let (mut p1, mut p2) = (T::zero(), T::zero());
                    for dy in -(big_r as isize)..=big_r as isize {
                        let t = (dy + big_r as isize) as usize;
                        let Some(hw) = widths[t] else {
                            continue;
                        };
                        let row = (xi as isize + dy * stride as isize) as usize;
                        let g0 = big_r - hw;
                        let n = 2 * hw + 1;
                        let gauge = &tables.gauge[t][g0..g0 + n];
                        // The centre tap has O(x, x) = 1: no dependence on d(x).
                        let segments = if dy == 0 {
                            [(0, hw), (hw + 1, n)]
                        } else {
                            [(0, n), (n, n)]
                        };
                        for (start, end) in segments {
                            if start >= end {
                                continue;
                            }
                            let (a, b) = match ctx.aperture {
                                ApertureEval::Gauge => occlusion_run(
                                    src,
                                    row - hw + start,
                                    &gauge[start..end],
                                    gc,
                                    d_x,
                                ),
                                ApertureEval::Kernel(..) => occlusion_run_kernel(
                                    ctx,
                                    row - hw,
                                    (start, end, hw, dy),
                                    gc,
                                    d_x,
                                ),
                            };
                            p1 = p1 + a;
                            p2 = p2 + b;
                        }
                    }
                    let (de_dd, de_dk) = model::focus_weight_derivatives(k, d_x, e_x);
                    // dO/dd_x|_e = -e s', dO/de = s - 1.
                    gd = -e_x * p1 + de_dd * p2;
                    gk = de_dk * p2;
                }
                if disc {
                    let cov = &ctx.discs[i];
                    let g_r = rcv.g_coverage[i] * cov.derivative_radius();
                    gd = gd + g_r * k * model::scatter_radius_sign(d_x);
                    gk = gk + g_r * d_x.abs();
                    share[o] = rcv.g_coverage[i] / cov.weight;
                }
                g_d[o] = gd;
                k_rows[o] = gk.f64();
            }
        }
    }
    (g_d, share, k_rows.iter().sum())
}

/// Pass A's run over sources `lo .. lo + gauge.len()` (padded) for one receiver:
/// `(sum base s'(D), sum base (s(D) - 1))` with `base = gc a S / A`,
/// `gc = dL/dC . Ilin(y) + dL/dW`, `D = d(y) - d(x)`.
#[inline(always)]
fn occlusion_run<T: Real>(src: &Planes<T>, lo: usize, gauge: &[T], gc: [T; 4], d_x: T) -> (T, T) {
    let n = gauge.len();
    let (red, green, blue) = (
        &src.red[lo..lo + n],
        &src.green[lo..lo + n],
        &src.blue[lo..lo + n],
    );
    let (alpha, radius, inv_area, disp) = (
        &src.alpha[lo..lo + n],
        &src.radius[lo..lo + n],
        &src.inv_area[lo..lo + n],
        &src.rel_disp[lo..lo + n],
    );
    let (mut l1, mut l2) = ([T::zero(); LANES], [T::zero(); LANES]);
    let (mut t1, mut t2) = ([T::zero(); CHUNK], [T::zero(); CHUNK]);
    let mut start = 0;
    while start < n {
        let m = (n - start).min(CHUNK);
        for j in 0..m {
            let i = start + j;
            let s = model::scatter_step_fast(src.step, radius[i] - gauge[i]);
            let g = gc[0] * red[i] + gc[1] * green[i] + gc[2] * blue[i] + gc[3];
            let base = g * alpha[i] * s * inv_area[i];
            let (ds, s_minus_1) = model::occlusion_receiver_factors_fast(disp[i], d_x);
            t1[j] = base * ds;
            t2[j] = base * s_minus_1;
        }
        for_each_lane(m, |l, j| {
            l1[l] = l1[l] + t1[j];
            l2[l] = l2[l] + t2[j];
        });
        start += m;
    }
    (lane_sum(&l1), lane_sum(&l2))
}

/// [`occlusion_run`] for kernel apertures (the model's scalar scatter term): taps
/// `start .. end` of the row `dy` of half-width `hw` starting at padded index `lo`.
fn occlusion_run_kernel<T: Real>(
    ctx: &Ctx<'_, T>,
    lo: usize,
    (start, end, hw, dy): (usize, usize, usize, isize),
    gc: [T; 4],
    d_x: T,
) -> (T, T) {
    let (src, tables) = (ctx.src, ctx.tables);
    let (mut p1, mut p2) = (T::zero(), T::zero());
    for j in start..end {
        let yi = lo + j;
        let a = src.alpha[yi];
        if a == T::zero() {
            continue;
        }
        let dx = j as isize - hw as isize;
        let (s, _) = tables.scatter_at::<false>(src.step, ctx.aperture, (dx, dy), src.radius[yi]);
        let g = gc[0] * src.red[yi] + gc[1] * src.green[yi] + gc[2] * src.blue[yi] + gc[3];
        let base = g * a * s * src.inv_area[yi];
        let (ds, s_minus_1) = model::occlusion_receiver_factors_fast(src.rel_disp[yi], d_x);
        p1 = p1 + base * ds;
        p2 = p2 + base * s_minus_1;
    }
    (p1, p2)
}
