//! Pass C of the fast adjoint: the coverage's gradient to alpha. The paper's box through
//! one summed-area table (f64) per half-size that occurs; the soft disc as a gather bounded
//! by the largest `r_c` within the window of each source tile.

use super::context::Ctx;
use crate::engine::backward::fold_padded;
use crate::engine::fast::runs::{for_each_lane, lane_sum, LANES};
use crate::engine::fast::tiles::{backward_reach, ROW_BLOCK, TILE, TILE_ROWS};
use crate::engine::simd::avx2_dispatch;
use crate::engine::summed_area::fill_summed_area;
use crate::model::{self, ApertureEval, ScatterStep};
use crate::Real;
use rayon::prelude::*;

/// Paper box coverage `o(x) = mean of alpha over the box of half-size h(x)`: each padded
/// pixel y gathers `dL/do(x) / n(x)` from the receivers whose box holds it, i.e. the
/// receivers with `h(x) = h` in the box of half-size `h` around y, for each `h` that occurs:
/// one summed-area table (f64) per distinct half-size.
pub(super) fn pass_coverage_box<T: Real>(ctx: &Ctx<'_, T>) -> Vec<T> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let (w, h, pad, stride) = (rcv.width, rcv.height, src.pad, src.stride);
    let big_r = ctx.tables.big_r;
    let half: Vec<usize> = rcv
        .radius
        .par_iter()
        .map(|&r| model::coverage_half_size_px(r, big_r))
        .collect();
    // The half-sizes that occur (at most R + 1 of them), in increasing order.
    let mut occurs = vec![false; big_r + 1];
    for &hs in &half {
        occurs[hs.min(big_r)] = true;
    }
    let sizes: Vec<usize> = (0..=big_r).filter(|&hs| occurs[hs]).collect();
    let s1 = w + 1;
    let mut padded = vec![0.0f64; src.rows * stride];
    // One table for every half-size: each fills all of it but the first row and column,
    // which stay 0.
    let mut sat = vec![0.0f64; (h + 1) * s1];
    for &hs in &sizes {
        let n = ((2 * hs + 1) * (2 * hs + 1)) as f64;
        // SAT over the image receivers of share(x) where h(x) == hs.
        fill_summed_area(&mut sat, w, h, |x, y| {
            let i = y * w + x;
            if half[i] == hs {
                rcv.g_coverage[i].f64() / n
            } else {
                0.0
            }
        });
        let hs = hs as isize;
        padded
            .par_chunks_mut(stride)
            .enumerate()
            .for_each(|(py, row)| {
                // Receivers (image coords) within the box around y, clipped to the image.
                let y = py as isize - pad as isize;
                let (r0, r1) = ((y - hs).max(0), (y + hs + 1).min(h as isize));
                if r0 >= r1 {
                    return;
                }
                for (px, v) in row.iter_mut().enumerate() {
                    let x = px as isize - pad as isize;
                    let (c0, c1) = ((x - hs).max(0), (x + hs + 1).min(w as isize));
                    if c0 >= c1 {
                        continue;
                    }
                    let (r0, r1, c0, c1) = (r0 as usize, r1 as usize, c0 as usize, c1 as usize);
                    *v += sat[r1 * s1 + c1] - sat[r0 * s1 + c1] - sat[r1 * s1 + c0]
                        + sat[r0 * s1 + c0];
                }
            });
    }
    fold_padded(&src.source, padded.into_iter().map(T::c).collect(), w * h)
}

/// Soft-disc coverage `o(x) = sum_y S(r_c(x), y) a(y) / Z(x)`: each padded pixel y gathers
/// `dL/do(x) S(r_c(x), y) / Z(x)` from the receivers whose reach `r_c(x) + tail` holds it.
pub(super) fn pass_coverage_disc<T: Real>(ctx: &Ctx<'_, T>, share: &[T]) -> Vec<T> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let opts = ctx.settings.model();
    let footprint = T::c(opts.footprint.px());
    let rc: Vec<T> = rcv
        .radius
        .iter()
        .map(|&r| model::coverage_radius_px(r, opts.coverage_radius, footprint).0)
        .collect();
    // Per block of ROW_BLOCK image rows and per image column, the largest r_c.
    let (w, h) = (rcv.width, rcv.height);
    let blocks = h.div_ceil(ROW_BLOCK);
    let block_max: Vec<f64> = (0..blocks * w)
        .map(|bi| {
            let (b, x) = (bi / w, bi % w);
            (b * ROW_BLOCK..((b + 1) * ROW_BLOCK).min(h))
                .map(|y| rc[y * w + x].f64())
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect();
    let rows: Vec<Vec<T>> = (0..src.rows)
        .step_by(TILE_ROWS)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y0| disc_tile_row_dispatch(ctx, &rc, share, &block_max, y0))
        .collect();
    fold_padded(&src.source, rows.into_iter().flatten().collect(), w * h)
}

avx2_dispatch!(
    disc_tile_row_dispatch,
    disc_tile_row_avx2,
    disc_tile_row,
    (ctx: &Ctx<'_, T>, rc: &[T], share: &[T], block_max: &[f64], y0: usize) -> Vec<T>
);

/// Pass C (soft disc) over the padded source rows `y0 .. y0 + TILE_ROWS`, tile by tile.
#[inline(always)]
fn disc_tile_row<T: Real>(
    ctx: &Ctx<'_, T>,
    rc: &[T],
    share: &[T],
    block_max: &[f64],
    y0: usize,
) -> Vec<T> {
    let (src, rcv, tables) = (ctx.src, ctx.rcv, ctx.tables);
    let (stride, big_r, pad) = (src.stride, tables.big_r, src.pad);
    let (w, h) = (rcv.width, rcv.height);
    let y1 = (y0 + TILE_ROWS).min(src.rows);
    let mut out = vec![T::zero(); (y1 - y0) * stride];
    for x0 in (0..stride).step_by(TILE) {
        let x1 = (x0 + TILE).min(stride);
        // Receivers (image coords) within R of the tile.
        let qy0 = (y0 as isize - (pad + big_r) as isize).max(0) as usize;
        let qy1 = ((y1 + big_r) as isize - pad as isize).clamp(0, h as isize) as usize;
        let qx0 = (x0 as isize - (pad + big_r) as isize).max(0) as usize;
        let qx1 = ((x1 + big_r) as isize - pad as isize).clamp(0, w as isize) as usize;
        if qy0 >= qy1 || qx0 >= qx1 {
            continue;
        }
        let mut max_rc = f64::NEG_INFINITY;
        for b in qy0 / ROW_BLOCK..=(qy1 - 1) / ROW_BLOCK {
            for &m in &block_max[b * w + qx0..b * w + qx1] {
                max_rc = max_rc.max(m);
            }
        }
        let widths = tables.half_widths(backward_reach(ctx.aperture, max_rc));
        for py in y0..y1 {
            for px in x0..x1 {
                let mut acc = T::zero();
                for ddy in -(big_r as isize)..=big_r as isize {
                    let t = (ddy + big_r as isize) as usize;
                    let Some(hw) = widths[t] else {
                        continue;
                    };
                    let qy = py as isize + ddy - pad as isize;
                    if qy < 0 || qy >= h as isize {
                        continue;
                    }
                    let x = px as isize - pad as isize;
                    let lo = (x - hw as isize).max(0);
                    let hi = (x + hw as isize).min(w as isize - 1);
                    if lo > hi {
                        continue;
                    }
                    let i0 = qy as usize * w + lo as usize;
                    let n = (hi - lo + 1) as usize;
                    let g0 = (lo - x + big_r as isize) as usize;
                    acc = acc
                        + match ctx.aperture {
                            ApertureEval::Gauge => disc_run(
                                src.step,
                                &rc[i0..i0 + n],
                                &share[i0..i0 + n],
                                &ctx.gauge_flip[t][g0..g0 + n],
                            ),
                            ApertureEval::Kernel(..) => {
                                let mut a = T::zero();
                                for j in 0..n {
                                    // Receiver offset x - y = (ddx, ddy); the tap offset is y - x.
                                    let ddx = (g0 + j) as isize - big_r as isize;
                                    let (s, _) = tables.scatter_at::<false>(
                                        src.step,
                                        ctx.aperture,
                                        (-ddx, -ddy),
                                        rc[i0 + j],
                                    );
                                    a = a + share[i0 + j] * s;
                                }
                                a
                            }
                        };
                }
                out[(py - y0) * stride + px] = acc;
            }
        }
    }
    out
}

/// `sum share(x) S(r_c(x) - gauge)` over one run of receivers, in lanes.
#[inline(always)]
fn disc_run<T: Real>(step: ScatterStep, rc: &[T], share: &[T], gauge: &[T]) -> T {
    let n = gauge.len();
    let mut lanes = [T::zero(); LANES];
    for_each_lane(n, |l, i| {
        lanes[l] = lanes[l] + share[i] * model::scatter_step_fast(step, rc[i] - gauge[i]);
    });
    lane_sum(&lanes)
}
