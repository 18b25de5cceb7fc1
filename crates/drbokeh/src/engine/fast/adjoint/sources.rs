//! Pass B of the fast adjoint, over padded source pixels in tiles bounded by the largest
//! radius in the tile (every alpha), receivers clipped to the image: the gradients reaching
//! `Ilin(y)`, `a(y)`, `d(y)` (through S, A and O) and K (through `r(y)`). Runs along
//! receiver rows, 8 lanes, in four variants: with/without occlusion (no receiver in the
//! tile's reach with `e >= 1e-9`: `O = 1`, one `exp` per tap) and full/alpha-only (a
//! zero-alpha source needs only `sum gc S O`, its alpha gradient).

use super::context::{Ctx, Receivers};
use super::SourceGradients;
use crate::engine::fast::runs::{centre_scatter, for_each_lane, lane_sum, CHUNK, LANES};
use crate::engine::fast::tiles::{backward_reach, TILE, TILE_ROWS};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::model::{self, ApertureEval, ScatterStep};
use crate::Real;
use rayon::prelude::*;

/// Gradients per image pixel: linear colour, alpha (scatter part), disparity (source
/// part), and K's total.
#[allow(clippy::type_complexity)]
pub(in crate::engine) fn pass_sources<T: Real>(
    ctx: &Ctx<'_, T>,
) -> (Vec<[T; 3]>, Vec<T>, Vec<T>, f64) {
    let src = ctx.src;
    let occluding = occluding_table(ctx);
    let tiles: Vec<(Vec<[T; 5]>, f64)> = (0..src.rows)
        .step_by(TILE_ROWS)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y0| sources_tile_row_dispatch(ctx, &occluding, y0))
        .collect();
    gather_source_terms(tiles, src, (ctx.rcv.width, ctx.rcv.height))
}

/// Adds per-source terms `[dIlin (3), da, dd]`, produced in source order in chunks of
/// whole padded rows (each with its share of K's gradient), onto the image pixels
/// `src.source[p]` they belong to (padded sources fold onto their mirrored pixel), in a
/// fixed order: each pixel's own term first (image rows in parallel), then the padding's
/// terms in padded order. Deterministic for any thread count.
pub(in crate::engine) fn gather_source_terms<T: Real>(
    chunks: Vec<(Vec<[T; 5]>, f64)>,
    src: &Planes<T>,
    (w, h): (usize, usize),
) -> SourceGradients<T> {
    let (stride, pad) = (src.stride, src.pad);
    let k_total: f64 = chunks.iter().map(|c| c.1).sum();
    let rows: Vec<&[[T; 5]]> = chunks
        .iter()
        .flat_map(|(chunk, _)| chunk.chunks(stride))
        .collect();
    debug_assert_eq!(rows.len(), src.rows);
    let n = w * h;
    let (mut g_lin, mut g_a, mut g_d) = (
        vec![[T::zero(); 3]; n],
        vec![T::zero(); n],
        vec![T::zero(); n],
    );
    g_lin
        .par_chunks_mut(w)
        .zip(g_a.par_chunks_mut(w))
        .zip(g_d.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((lin, a), d))| {
            let own = &rows[y + pad][pad..pad + w];
            for x in 0..w {
                let v = own[x];
                lin[x] = [v[0], v[1], v[2]];
                a[x] = v[3];
                d[x] = v[4];
            }
        });
    for (py, row) in rows.iter().enumerate() {
        let inside = py >= pad && py < h + pad;
        for (px, v) in row.iter().enumerate() {
            if inside && px >= pad && px < w + pad {
                continue;
            }
            let s = src.source[py * stride + px];
            for c in 0..3 {
                g_lin[s][c] = g_lin[s][c] + v[c];
            }
            g_a[s] = g_a[s] + v[3];
            g_d[s] = g_d[s] + v[4];
        }
    }
    (g_lin, g_a, g_d, k_total)
}

/// Summed-area table (padded coordinates, `(rows + 1) x (stride + 1)`) of the receivers
/// whose occlusion term is evaluated (`e(x) > 0` after the cutoff).
fn occluding_table<T: Real>(ctx: &Ctx<'_, T>) -> Vec<u32> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let s1 = src.stride + 1;
    let mut sat = vec![0u32; (src.rows + 1) * s1];
    for py in 0..src.rows {
        let mut run = 0u32;
        for px in 0..src.stride {
            let (y, x) = (
                py as isize - src.pad as isize,
                px as isize - src.pad as isize,
            );
            if y >= 0
                && x >= 0
                && (y as usize) < rcv.height
                && (x as usize) < rcv.width
                && rcv.focus_weight[y as usize * rcv.width + x as usize] > T::zero()
            {
                run += 1;
            }
            sat[(py + 1) * s1 + px + 1] = sat[py * s1 + px + 1] + run;
        }
    }
    sat
}

avx2_dispatch!(
    sources_tile_row_dispatch,
    sources_tile_row_avx2,
    sources_tile_row,
    (ctx: &Ctx<'_, T>, occluding: &[u32], y0: usize) -> (Vec<[T; 5]>, f64)
);

/// Source terms of one padded pixel, for [`source_run`].
#[derive(Clone, Copy)]
pub(in crate::engine) struct SourceTerms<T> {
    pub step: ScatterStep,
    pub radius: T,
    /// `A'(r) / A(r)` of the source area ([`model::source_area`]): `2 / r` for the paper.
    pub dlog_area: T,
    pub rel_disp: T,
    pub lin: [T; 3],
}

/// Pass B over the padded source rows `y0 .. y0 + TILE_ROWS`, tile by tile. Returns per
/// padded pixel `[g_lin r, g, b, g_alpha, g_disp]` and K's share.
#[inline(always)]
fn sources_tile_row<T: Real>(ctx: &Ctx<'_, T>, occluding: &[u32], y0: usize) -> (Vec<[T; 5]>, f64) {
    let (src, rcv, tables) = (ctx.src, ctx.rcv, ctx.tables);
    let (stride, big_r, pad) = (src.stride, tables.big_r, src.pad);
    let y1 = (y0 + TILE_ROWS).min(src.rows);
    let k = ctx.k;
    let mut out = vec![[T::zero(); 5]; (y1 - y0) * stride];
    let mut k_rows = vec![0.0f64; (y1 - y0) * stride];
    // Receivers occupy padded rows pad .. pad + h and columns pad .. pad + w.
    let (ry0, ry1, rx0, rx1) = (pad, pad + rcv.height, pad, pad + rcv.width);
    for x0 in (0..stride).step_by(TILE) {
        let x1 = (x0 + TILE).min(stride);
        let mut max_r = f64::NEG_INFINITY;
        for py in y0..y1 {
            for &r in &src.radius[py * stride + x0..py * stride + x1] {
                max_r = max_r.max(r.f64());
            }
        }
        let reach = backward_reach(ctx.aperture, max_r).min(big_r as f64);
        let reach_px = reach.ceil() as usize;
        // Receiver rectangle any source of the tile can reach, clipped to the image.
        let qy0 = y0.saturating_sub(reach_px).max(ry0);
        let qy1 = (y1 + reach_px).min(ry1);
        let qx0 = x0.saturating_sub(reach_px).max(rx0);
        let qx1 = (x1 + reach_px).min(rx1);
        if qy0 >= qy1 || qx0 >= qx1 {
            continue;
        }
        let s1 = stride + 1;
        let occ_count = occluding[qy1 * s1 + qx1] + occluding[qy0 * s1 + qx0]
            - occluding[qy0 * s1 + qx1]
            - occluding[qy1 * s1 + qx0];
        let occ = occ_count > 0;
        let widths = tables.half_widths(reach);
        for py in y0..y1 {
            for px in x0..x1 {
                let p = py * stride + px;
                let a = src.alpha[p];
                let r = src.radius[p];
                let terms = SourceTerms {
                    step: src.step,
                    radius: r,
                    dlog_area: model::source_area_log_derivative(src.step, r),
                    rel_disp: src.rel_disp[p],
                    lin: [src.red[p], src.green[p], src.blue[p]],
                };
                let full = a != T::zero();
                let mut acc = [T::zero(); 6];
                for ddy in -(big_r as isize)..=big_r as isize {
                    let t = (ddy + big_r as isize) as usize;
                    let Some(hw) = widths[t] else {
                        continue;
                    };
                    let qy = py as isize + ddy;
                    if qy < ry0 as isize || qy >= ry1 as isize {
                        continue;
                    }
                    // Receivers qx in [px - hw, px + hw] within the image.
                    let lo = (px as isize - hw as isize).max(rx0 as isize);
                    let hi = (px as isize + hw as isize).min(rx1 as isize - 1);
                    if lo > hi {
                        continue;
                    }
                    let row = (qy as usize - pad) * rcv.width;
                    let centre_inside = ddy == 0 && (lo..=hi).contains(&(px as isize));
                    let seg = RowSegment { row, px, pad, t };
                    if centre_inside {
                        source_row_run(ctx, seg, lo, px as isize - 1, (occ, full), terms, &mut acc);
                        source_row_run(ctx, seg, px as isize + 1, hi, (occ, full), terms, &mut acc);
                        // The centre tap: O(x, x) = 1.
                        let i = row + (px - pad);
                        let (s, ds) = centre_scatter(src.step, ctx.aperture, r);
                        let gc = rcv.g_red[i] * terms.lin[0]
                            + rcv.g_green[i] * terms.lin[1]
                            + rcv.g_blue[i] * terms.lin[2]
                            + rcv.g_weight[i];
                        acc[0] = acc[0] + rcv.g_red[i] * s;
                        acc[1] = acc[1] + rcv.g_green[i] * s;
                        acc[2] = acc[2] + rcv.g_blue[i] * s;
                        acc[3] = acc[3] + gc * s;
                        acc[4] = acc[4]
                            + gc * model::normalised_scatter_radius_factor(s, ds, terms.dlog_area);
                    } else {
                        source_row_run(ctx, seg, lo, hi, (occ, full), terms, &mut acc);
                    }
                }
                let inv_area = src.inv_area[p];
                let a_inv = a * inv_area;
                let g_r = acc[4] * a_inv;
                let d_y = terms.rel_disp;
                let o = (py - y0) * stride + px;
                out[o] = [
                    acc[0] * a_inv,
                    acc[1] * a_inv,
                    acc[2] * a_inv,
                    acc[3] * inv_area,
                    acc[5] * a_inv + g_r * k * model::scatter_radius_sign(d_y),
                ];
                k_rows[o] = (g_r * d_y.abs()).f64();
            }
        }
    }
    (out, k_rows.iter().sum())
}

/// Where a run of receivers lies: the image index of its row's start, the source column
/// `px` and the padding (padded coordinates), and the flipped tables' row `t`.
#[derive(Clone, Copy)]
struct RowSegment {
    row: usize,
    px: usize,
    pad: usize,
    t: usize,
}

/// Pass B over the receivers in padded columns `from ..= to` of one row, added to `acc`.
#[inline(always)]
fn source_row_run<T: Real>(
    ctx: &Ctx<'_, T>,
    seg: RowSegment,
    from: isize,
    to: isize,
    (occ, full): (bool, bool),
    terms: SourceTerms<T>,
    acc: &mut [T; 6],
) {
    if from > to {
        return;
    }
    let big_r = ctx.tables.big_r as isize;
    let (i0, n) = (
        seg.row + (from as usize - seg.pad),
        (to - from + 1) as usize,
    );
    let g0 = (from - seg.px as isize + big_r) as usize;
    let rcv = ctx.rcv;
    let v = match ctx.aperture {
        ApertureEval::Gauge => {
            let gauge = &ctx.gauge_flip[seg.t][g0..g0 + n];
            match (occ, full) {
                (true, true) => source_run::<T, true, true>(rcv, i0, gauge, terms),
                (true, false) => source_run::<T, true, false>(rcv, i0, gauge, terms),
                (false, true) => source_run::<T, false, true>(rcv, i0, gauge, terms),
                (false, false) => source_run::<T, false, false>(rcv, i0, gauge, terms),
            }
        }
        ApertureEval::Kernel(..) => source_run_kernel(ctx, i0, n, (g0, seg.t), terms, full),
    };
    for (a, b) in acc.iter_mut().zip(v) {
        *a = *a + b;
    }
}

/// Pass B's run over receivers `i0 .. i0 + gauge.len()` (image indices of one row) for one
/// source: `[sum gC S O (3), sum gc S O, sum gc O (S' - S A'/A), sum gc S dO/dd_y]` with
/// `gc = dL/dC . Ilin(y) + dL/dW`. `OCC = false`: every receiver has `O = 1`. `FULL =
/// false` (alpha = 0): only the alpha gradient's sum is needed.
#[inline(always)]
fn source_run<T: Real, const OCC: bool, const FULL: bool>(
    rcv: &Receivers<T>,
    i0: usize,
    gauge: &[T],
    src: SourceTerms<T>,
) -> [T; 6] {
    let n = gauge.len();
    let mut lanes = [[T::zero(); LANES]; 6];
    let (mut so, mut ga, mut rad, mut dyv) = (
        [T::zero(); CHUNK],
        [T::zero(); CHUNK],
        [T::zero(); CHUNK],
        [T::zero(); CHUNK],
    );
    let mut start = 0;
    while start < n {
        let m = (n - start).min(CHUNK);
        let s0 = i0 + start;
        let (gr, gg, gb, gw) = (
            &rcv.g_red[s0..s0 + m],
            &rcv.g_green[s0..s0 + m],
            &rcv.g_blue[s0..s0 + m],
            &rcv.g_weight[s0..s0 + m],
        );
        let (e, dx) = (&rcv.focus_weight[s0..s0 + m], &rcv.rel_disp[s0..s0 + m]);
        let g = &gauge[start..start + m];
        for i in 0..m {
            let s = model::scatter_step_fast(src.step, src.radius - g[i]);
            let (o, d_o) = if OCC {
                model::occlusion_fast_with_derivative(e[i], src.rel_disp, dx[i])
            } else {
                (T::one(), T::zero())
            };
            let gc = gr[i] * src.lin[0] + gg[i] * src.lin[1] + gb[i] * src.lin[2] + gw[i];
            so[i] = s * o;
            ga[i] = gc * so[i];
            if FULL {
                let sd = model::scatter_step_derivative(src.step, s);
                rad[i] = gc * o * model::normalised_scatter_radius_factor(s, sd, src.dlog_area);
                if OCC {
                    dyv[i] = gc * s * d_o;
                }
            }
        }
        // Lane l sums the taps i with i % LANES == l (CHUNK is a multiple of LANES).
        for_each_lane(m, |l, i| {
            lanes[3][l] = lanes[3][l] + ga[i];
            if FULL {
                lanes[0][l] = lanes[0][l] + gr[i] * so[i];
                lanes[1][l] = lanes[1][l] + gg[i] * so[i];
                lanes[2][l] = lanes[2][l] + gb[i] * so[i];
                lanes[4][l] = lanes[4][l] + rad[i];
                if OCC {
                    lanes[5][l] = lanes[5][l] + dyv[i];
                }
            }
        });
        start += m;
    }
    lanes.map(|l| lane_sum(&l))
}

/// [`source_run`] for kernel apertures (the model's scalar scatter term). `g0` is the
/// first tap's column in the flipped tables, `t` their row.
fn source_run_kernel<T: Real>(
    ctx: &Ctx<'_, T>,
    i0: usize,
    n: usize,
    (g0, t): (usize, usize),
    src: SourceTerms<T>,
    full: bool,
) -> [T; 6] {
    let (rcv, tables) = (ctx.rcv, ctx.tables);
    let big_r = tables.big_r as isize;
    let mut acc = [T::zero(); 6];
    for j in 0..n {
        let i = i0 + j;
        // Receiver offset x - y = (ddx, ddy); the tap offset is y - x.
        let (ddx, ddy) = ((g0 + j) as isize - big_r, t as isize - big_r);
        let (s, sd) = tables.scatter_at::<true>(src.step, ctx.aperture, (-ddx, -ddy), src.radius);
        let e = rcv.focus_weight[i];
        let (o, d_o) = if e > T::zero() {
            model::occlusion_fast_with_derivative(e, src.rel_disp, rcv.rel_disp[i])
        } else {
            (T::one(), T::zero())
        };
        let so = s * o;
        let gc = rcv.g_red[i] * src.lin[0]
            + rcv.g_green[i] * src.lin[1]
            + rcv.g_blue[i] * src.lin[2]
            + rcv.g_weight[i];
        acc[3] = acc[3] + gc * so;
        if full {
            acc[0] = acc[0] + rcv.g_red[i] * so;
            acc[1] = acc[1] + rcv.g_green[i] * so;
            acc[2] = acc[2] + rcv.g_blue[i] * so;
            acc[4] =
                acc[4] + gc * o * model::normalised_scatter_radius_factor(s, sd, src.dlog_area);
            acc[5] = acc[5] + gc * s * d_o;
        }
    }
    acc
}
