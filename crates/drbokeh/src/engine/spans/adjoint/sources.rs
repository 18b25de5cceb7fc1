//! Pass B of the span adjoint: per padded source, the gradients reaching `Ilin(y)`, `a(y)`,
//! `d(y)` (through `S`, `A` and `O`) and K (through `r(y)`), summed over its disc row by
//! row: on span rows the interior from prefix sums of the receivers' upstream gradients,
//! the ring and the in-focus receivers tap by tap; on tap rows every tap within the fast
//! adjoint's reach. The transpose of `scatter.rs`.

use super::super::geometry::{disc_row, GaugeTable, Rings, Shape, STEP_ARGUMENT_MIN, TABLE_MARGIN};
use crate::engine::fast::adjoint::{Ctx, SourceGradients};
use crate::engine::simd::avx2_dispatch;
use crate::model::{self, SCATTER_TAIL_PX};
use crate::Real;
use rayon::prelude::*;

/// Components of the receivers' upstream gradient: `dL/dC` (3) and `dL/dW`.
const COMPONENTS: usize = 4;

/// How far beyond `r` pass B reaches (in gauge units), on span rows (the ring's outer
/// edge) and tap rows alike: the fast adjoint's `r + 4.5 + 1.5` (`engine/fast/tiles.rs`,
/// `backward_reach`). Not the forward's `r + u_out` (2.75 px for the sharp step): where a
/// layer ends, receivers just beyond a disc's edge have a weight sum `W` of the order of
/// the tail (refined over the whole window, `engine/fast/adjoint/refine.rs`) but a soft-disc
/// coverage `o` of the receiver's own radius that is not small, so their upstream factors
/// `dL/dW ~ o / W` are huge and the tail taps carry O(1) gradients (measured: 1.8e-2 of
/// the largest alpha gradient with the ring ending at 2.75 px, preset physical).
const TAP_ROW_TAIL_PX: f64 = SCATTER_TAIL_PX + 1.5;

/// The receivers' side of pass B, per image row.
struct RowData {
    /// Prefix sums `[y][x][component]` (`w + 1` entries per row) of `gC` and `gW`.
    prefix: Vec<f64>,
    /// Per row, the prefix count of receivers whose occlusion term is evaluated
    /// (`w + 1` entries per row).
    focus_count: Vec<u32>,
    /// Per row, their columns (row `y`'s from `focus_start[y]`).
    focus_cols: Vec<u32>,
    focus_start: Vec<usize>,
}

/// Pass B over every padded source of the layer (`span_rows[y]`: whether receiver row `y`
/// was rendered as spans).
pub(super) fn pass_sources<T: Real>(
    ctx: &Ctx<'_, T>,
    shape: &Shape,
    table: &GaugeTable<T>,
    span_rows: &[bool],
) -> SourceGradients<T> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let (w, h) = (rcv.width, rcv.height);
    let prefix: Vec<f64> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut row = vec![0.0f64; (w + 1) * COMPONENTS];
            let mut run = [0.0f64; COMPONENTS];
            for x in 0..w {
                let i = y * w + x;
                let g = [rcv.g_red[i], rcv.g_green[i], rcv.g_blue[i], rcv.g_weight[i]];
                for c in 0..COMPONENTS {
                    run[c] += g[c].f64();
                    row[(x + 1) * COMPONENTS + c] = run[c];
                }
            }
            row
        })
        .collect();
    let mut focus_count = vec![0u32; h * (w + 1)];
    let mut focus_cols = Vec::new();
    let mut focus_start = Vec::with_capacity(h + 1);
    for y in 0..h {
        focus_start.push(focus_cols.len());
        for x in 0..w {
            let inside = rcv.focus_weight[y * w + x] > T::zero();
            focus_count[y * (w + 1) + x + 1] = focus_count[y * (w + 1) + x] + u32::from(inside);
            if inside {
                focus_cols.push(x as u32);
            }
        }
    }
    focus_start.push(focus_cols.len());
    let data = RowData {
        prefix,
        focus_count,
        focus_cols,
        focus_start,
    };
    let rows: Vec<(Vec<[T; 5]>, f64)> = (0..src.rows)
        .into_par_iter()
        .map(|py| source_row_dispatch(ctx, shape, table, span_rows, &data, py))
        .collect();
    let n = w * h;
    let (mut g_lin, mut g_a, mut g_d) = (
        vec![[T::zero(); 3]; n],
        vec![T::zero(); n],
        vec![T::zero(); n],
    );
    let mut k_total = 0.0;
    let mut p = 0;
    for (row, k) in rows {
        k_total += k;
        for v in row {
            let s = src.source[p];
            for c in 0..3 {
                g_lin[s][c] = g_lin[s][c] + v[c];
            }
            g_a[s] = g_a[s] + v[3];
            g_d[s] = g_d[s] + v[4];
            p += 1;
        }
    }
    (g_lin, g_a, g_d, k_total)
}

avx2_dispatch!(
    source_row_dispatch,
    source_row_avx2,
    source_row,
    (
        ctx: &Ctx<'_, T>,
        shape: &Shape,
        table: &GaugeTable<T>,
        span_rows: &[bool],
        data: &RowData,
        py: usize
    ) -> (Vec<[T; 5]>, f64)
);

/// A source's terms.
#[derive(Clone, Copy)]
struct Source<T> {
    radius: T,
    /// `A'(r) / A(r)`.
    dlog_area: T,
    rel_disp: T,
    lin: [T; 3],
    /// Image column and row.
    xs: isize,
    ys: isize,
}

/// The sums of pass B for one source: `[sum gC S O (3), sum gc S O, sum gc O (S' - S A'/A),
/// sum gc S dO/dd_y]`.
type Sums<T> = [T; 6];

/// Pass B over the padded source row `py`: per padded pixel
/// `[g_lin r, g, b, g_alpha, g_disp]` and K's share.
#[inline(always)]
fn source_row<T: Real>(
    ctx: &Ctx<'_, T>,
    shape: &Shape,
    table: &GaugeTable<T>,
    span_rows: &[bool],
    data: &RowData,
    py: usize,
) -> (Vec<[T; 5]>, f64) {
    let src = ctx.src;
    let (stride, pad) = (src.stride, src.pad);
    let k = ctx.k;
    let mut out = vec![[T::zero(); 5]; stride];
    let mut k_row = 0.0f64;
    for px in 0..stride {
        let p = py * stride + px;
        let (a, r) = (src.alpha[p], src.radius[p]);
        let s = Source {
            radius: r,
            dlog_area: model::source_area_log_derivative(src.step, r),
            rel_disp: src.rel_disp[p],
            lin: [src.red[p], src.green[p], src.blue[p]],
            xs: px as isize - pad as isize,
            ys: py as isize - pad as isize,
        };
        let acc = match src.step {
            model::ScatterStep::Sharp => {
                source_sums::<T, true>(ctx, shape, table, span_rows, data, s)
            }
            model::ScatterStep::Paper => {
                source_sums::<T, false>(ctx, shape, table, span_rows, data, s)
            }
        };
        let inv_area = src.inv_area[p];
        let a_inv = a * inv_area;
        let g_r = acc[4] * a_inv;
        let d_y = s.rel_disp;
        out[px] = [
            acc[0] * a_inv,
            acc[1] * a_inv,
            acc[2] * a_inv,
            acc[3] * inv_area,
            acc[5] * a_inv + g_r * k * model::scatter_radius_sign(d_y),
        ];
        k_row += (g_r * d_y.abs()).f64();
    }
    (out, k_row)
}

/// One tap of pass B: receiver `i` (image index) with scatter term `s`, its derivative
/// `sd` with respect to `r`, occlusion `o` and `dO/dd_y`, added to `acc`.
#[inline(always)]
fn add_tap<T: Real>(
    ctx: &Ctx<'_, T>,
    src: &Source<T>,
    i: usize,
    (s, sd): (T, T),
    (o, d_o): (T, T),
    acc: &mut Sums<T>,
) {
    let rcv = ctx.rcv;
    let g = [rcv.g_red[i], rcv.g_green[i], rcv.g_blue[i]];
    let gc = g[0] * src.lin[0] + g[1] * src.lin[1] + g[2] * src.lin[2] + rcv.g_weight[i];
    let so = s * o;
    for c in 0..3 {
        acc[c] = acc[c] + g[c] * so;
    }
    acc[3] = acc[3] + gc * so;
    acc[4] = acc[4] + gc * o * model::normalised_scatter_radius_factor(s, sd, src.dlog_area);
    acc[5] = acc[5] + gc * s * d_o;
}

/// The occlusion term of receiver `i` for the source, with its derivative with respect to
/// the source's disparity: `(1, 0)` where the fast adjoint takes `O = 1` (`e(x) < 1e-9`,
/// and the centre tap).
#[inline(always)]
fn occlusion<T: Real>(ctx: &Ctx<'_, T>, src: &Source<T>, i: usize, centre: bool) -> (T, T) {
    let e = ctx.rcv.focus_weight[i];
    if e > T::zero() && !centre {
        model::occlusion_fast_with_derivative(e, src.rel_disp, ctx.rcv.rel_disp[i])
    } else {
        (T::one(), T::zero())
    }
}

/// The exact taps of receiver columns `xa ..= xb` of image row `yr` (row offset `dy`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn exact_taps<T: Real, const SHARP: bool>(
    ctx: &Ctx<'_, T>,
    table: &GaugeTable<T>,
    src: &Source<T>,
    yr: usize,
    dy: isize,
    (xa, xb): (isize, isize),
    acc: &mut Sums<T>,
) {
    let w = ctx.rcv.width;
    let step = ctx.src.step;
    let t = (dy + table.big_r as isize) as usize;
    let base = t * table.stride + table.big_r + TABLE_MARGIN;
    for x in xa..=xb {
        let m = (base as isize + x - src.xs) as usize;
        let (g, mask) = (table.gauge[m], table.mask[m]);
        let u = (src.radius - g).max(T::c(STEP_ARGUMENT_MIN));
        let s = if SHARP {
            model::sharp_step_fast(u)
        } else {
            model::soft_step_fast(u)
        } * mask;
        let sd = model::scatter_step_derivative(step, s);
        let i = yr * w + x as usize;
        let centre = dy == 0 && x == src.xs;
        let o = occlusion(ctx, src, i, centre);
        add_tap(ctx, src, i, (s, sd), o, acc);
    }
}

/// Pass B's sums of one source over its disc.
#[inline(always)]
fn source_sums<T: Real, const SHARP: bool>(
    ctx: &Ctx<'_, T>,
    shape: &Shape,
    table: &GaugeTable<T>,
    span_rows: &[bool],
    data: &RowData,
    src: Source<T>,
) -> Sums<T> {
    let (w, h) = (ctx.rcv.width as isize, ctx.rcv.height as isize);
    // The forward's interior; the ring out to the tap rows' reach (see TAP_ROW_TAIL_PX).
    let rings = Rings {
        inner_px: Rings::of(ctx.src.step).inner_px,
        outer_px: TAP_ROW_TAIL_PX,
    };
    let big_r = table.big_r as f64;
    let rf = src.radius.f64();
    let span_reach = (rf + rings.outer_px).min(big_r).floor() as isize;
    let tap_reach = (rf + TAP_ROW_TAIL_PX).min(big_r).floor() as isize;
    let reach = span_reach.max(tap_reach);
    let mut acc: Sums<T> = [T::zero(); 6];
    // Interior sums of gC and gW (S = 1, O = 1).
    let mut interior = [0.0f64; COMPONENTS];
    for dy in -reach..=reach {
        let yr = src.ys + dy;
        if yr < 0 || yr >= h {
            continue;
        }
        let Some(hw) = table.window_half_width(dy) else {
            continue;
        };
        let yr = yr as usize;
        let clip = |(lo, hi): (isize, isize)| ((src.xs + lo).max(0), (src.xs + hi).min(w - 1));
        if !span_rows[yr] {
            if dy.abs() > tap_reach {
                continue;
            }
            if let Some((lo, hi)) = shape.interval(rf + TAP_ROW_TAIL_PX, dy, -1.0) {
                let hw = hw as isize;
                let (xa, xb) = clip((lo.max(-hw), hi.min(hw)));
                if xa <= xb {
                    exact_taps::<T, SHARP>(ctx, table, &src, yr, dy, (xa, xb), &mut acc);
                }
            }
            continue;
        }
        if dy.abs() > span_reach {
            continue;
        }
        let Some(disc) = disc_row(shape, rings, rf, dy, hw, -1.0) else {
            continue;
        };
        if let Some(run) = disc.interior {
            let (xa, xb) = clip(run);
            if xa <= xb {
                let row = &data.prefix[yr * (ctx.rcv.width + 1) * COMPONENTS..];
                let (ia, ib) = (xa as usize * COMPONENTS, (xb as usize + 1) * COMPONENTS);
                for c in 0..COMPONENTS {
                    interior[c] += row[ib + c] - row[ia + c];
                }
                // Receivers whose occlusion term is evaluated: O - 1 and dO/dd_y on top.
                let count = &data.focus_count[yr * (ctx.rcv.width + 1)..];
                let (ca, cb) = (count[xa as usize] as usize, count[xb as usize + 1] as usize);
                if cb > ca {
                    let cols = &data.focus_cols[data.focus_start[yr]..data.focus_start[yr + 1]];
                    for &x in &cols[ca..cb] {
                        let i = yr * ctx.rcv.width + x as usize;
                        let centre = dy == 0 && x as isize == src.xs;
                        if centre {
                            continue;
                        }
                        let (o, d_o) = occlusion(ctx, &src, i, false);
                        add_tap(
                            ctx,
                            &src,
                            i,
                            (T::one(), T::zero()),
                            (o - T::one(), d_o),
                            &mut acc,
                        );
                    }
                }
            }
        }
        for run in [disc.left, disc.right].into_iter().flatten() {
            let (xa, xb) = clip(run);
            if xa <= xb {
                exact_taps::<T, SHARP>(ctx, table, &src, yr, dy, (xa, xb), &mut acc);
            }
        }
    }
    // The interior's terms: S = 1, S' = 0, O = 1.
    let ic: [T; COMPONENTS] = interior.map(T::c);
    let gc = ic[0] * src.lin[0] + ic[1] * src.lin[1] + ic[2] * src.lin[2] + ic[3];
    for c in 0..3 {
        acc[c] = acc[c] + ic[c];
    }
    acc[3] = acc[3] + gc;
    acc[4] =
        acc[4] + gc * model::normalised_scatter_radius_factor(T::one(), T::zero(), src.dlog_area);
    acc
}
