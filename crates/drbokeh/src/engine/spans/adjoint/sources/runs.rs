//! Pass B over runs of [`LANES`] sources in adjacent columns of one row that share a
//! radius (bitwise; the common case in layers of constant or row-constant disparity, as
//! the forward's `scatter/runs.rs`): their discs are one disc shifted by a column each, so
//! the row geometry (the reach, the forward's disc row, the interior and the ring runs) is
//! computed once for the group, and each ring tap's `S`, `S'` and `S' - S A'/A` once per
//! offset for all of it. Lane `l` is the source `xs + l`; the receivers under offset `dx`
//! of the group are the adjacent columns `xs + dx ..= xs + dx + 7`, read as one vector.
//! The interior's prefix sums, the in-focus corrections and the tail receivers are the
//! source-by-source terms of [`super::source_sums`]; the ring's are summed per lane over a
//! row in `T`, then over rows in f64 (source by source: in [`LANES`] partial sums over the
//! whole disc). The same terms, in another fixed order.
//!
//! A group is taken only where every source's reach (`r + 6`, clipped to the window) lies
//! within the image's columns ([`groupable`]): no tap of it is clipped.

use super::{
    add_tap, load, occlusion, reach, source_out, LaneSums, RowData, Source, Sums, COMPONENTS,
    TAP_ROW_TAIL_PX,
};
use crate::engine::fast::adjoint::{Ctx, SourceTerms};
use crate::engine::spans::geometry::{disc_row, ring_steps, GaugeTable, Rings, Shape, LANES};
use crate::model;
use crate::Real;

/// A group's sources: the shared radius and its terms, per lane the colour and relative
/// disparity.
struct Group<T> {
    r: T,
    dlog_area: T,
    /// `Ilin` per channel, per lane.
    lin: [[T; LANES]; 3],
    rel: [T; LANES],
    /// Image column of lane 0.
    xs: isize,
    /// Some source has alpha > 0: every sum; else only `sum gc S O`.
    full: bool,
}

/// Whether the padded sources `px .. px + LANES` of row `py` form a group: one radius
/// (bitwise), and every tap of their reach within the image's columns.
#[inline(always)]
pub(super) fn groupable<T: Real>(
    ctx: &Ctx<'_, T>,
    table: &GaugeTable<T>,
    (px, py): (usize, usize),
) -> bool {
    let src = ctx.src;
    if px + LANES > src.stride {
        return false;
    }
    let p = py * src.stride + px;
    let r = src.radius[p];
    let mut same = true;
    for l in 1..LANES {
        same &= src.radius[p + l] == r;
    }
    let reach = reach(r, table);
    let xs = px as isize - src.pad as isize;
    same && xs - reach >= 0 && xs + (LANES as isize - 1) + reach < ctx.rcv.width as isize
}

/// Pass B of the group of padded sources `px .. px + LANES` of row `py` ([`groupable`]):
/// their gradients into `out` and K's shares added to `k_row`, in lane order.
#[inline(always)]
pub(super) fn group<T: Real, const SHARP: bool>(
    ctx: &Ctx<'_, T>,
    (shape, table): (&Shape, &GaugeTable<T>),
    span_rows: &[bool],
    data: &RowData<T>,
    (px, py): (usize, usize),
    (out, k_row): (&mut [[T; 5]], &mut f64),
) {
    let src = ctx.src;
    let (w, h) = (ctx.rcv.width, ctx.rcv.height as isize);
    let p0 = py * src.stride + px;
    let (xs, ys) = (
        px as isize - src.pad as isize,
        py as isize - src.pad as isize,
    );
    let r = src.radius[p0];
    let rf = r.f64();
    let reach = reach(r, table);
    let last = LANES as isize - 1;
    let (cols, rows) = ((xs - reach, xs + last + reach), (ys - reach, ys + reach));
    if !data.nonzero.any(cols, rows) {
        return;
    }
    let dlog_area = model::source_area_log_derivative(src.step, r);
    let mut g = Group {
        r,
        dlog_area,
        lin: [[T::zero(); LANES]; 3],
        rel: [T::zero(); LANES],
        xs,
        full: false,
    };
    let mut srcs = [Source {
        terms: SourceTerms {
            step: src.step,
            radius: r,
            dlog_area,
            rel_disp: T::zero(),
            lin: [T::zero(); 3],
        },
        xs,
        ys,
        full: true,
    }; LANES];
    for l in 0..LANES {
        let p = p0 + l;
        g.lin[0][l] = src.red[p];
        g.lin[1][l] = src.green[p];
        g.lin[2][l] = src.blue[p];
        g.rel[l] = src.rel_disp[p];
        g.full |= src.alpha[p] != T::zero();
        srcs[l].terms.rel_disp = src.rel_disp[p];
        srcs[l].terms.lin = [src.red[p], src.green[p], src.blue[p]];
        srcs[l].xs = xs + l as isize;
    }
    let tails = data.tail_area.any(cols, rows);
    let rings = Rings::of(src.step);
    let mut ring = [[0.0f64; LANES]; 6];
    let mut interior = [[0.0f64; LANES]; COMPONENTS];
    let mut singles: [Sums<T>; LANES] = [[T::zero(); 6]; LANES];
    for dy in -reach..=reach {
        let yr = ys + dy;
        if yr < 0 || yr >= h {
            continue;
        }
        let Some(hw) = table.window_half_width(dy) else {
            continue;
        };
        let yr = yr as usize;
        let Some((lo, hi)) = shape.interval(rf + TAP_ROW_TAIL_PX, dy, -1.0) else {
            continue;
        };
        let hwi = hw as isize;
        let (fa, fb) = (lo.max(-hwi), hi.min(hwi));
        if fa > fb {
            continue;
        }
        let mut lanes: LaneSums<T> = [[T::zero(); LANES]; 6];
        let at = (yr, dy);
        if !span_rows[yr] {
            // Every tap within the reach.
            taps::<T, SHARP, false>(table, data, &g, at, (fa, fb), &mut lanes);
        } else {
            let disc = disc_row(shape, rings, rf, dy, hw, -1.0);
            if tails {
                // Tail receivers beyond the forward's disc row: exact taps.
                let (da, db) = match disc {
                    None => (fb + 1, fb),
                    Some(d) => (
                        d.left.or(d.interior).map_or(0, |r| r.0),
                        d.right.or(d.interior).or(d.left).map_or(-1, |r| r.1),
                    ),
                };
                taps::<T, SHARP, true>(table, data, &g, at, (fa, fb.min(da - 1)), &mut lanes);
                taps::<T, SHARP, true>(table, data, &g, at, (fa.max(db + 1), fb), &mut lanes);
            }
            if let Some(disc) = disc {
                if let Some((ia, ib)) = disc.interior {
                    // Interior sums of gC and gW (S = 1, O = 1), per lane.
                    let row = yr * (w + 1);
                    let (a, b) = (row + (xs + ia) as usize, row + (xs + ib) as usize + 1);
                    for c in 0..COMPONENTS {
                        let pre = &data.prefix[c];
                        let (pa, pb) = (load(pre, a), load(pre, b));
                        for l in 0..LANES {
                            interior[c][l] += pb[l] - pa[l];
                        }
                    }
                    // Receivers whose occlusion term is evaluated: O - 1 and dO/dd_y on
                    // top, for each lane whose interior holds them.
                    for &x in data.focus.within(w, yr, (xs + ia, xs + last + ib)) {
                        let x = x as isize;
                        let (l0, l1) = ((x - xs - ib).max(0), (x - xs - ia).min(last));
                        for l in l0..=l1 {
                            if dy == 0 && x == xs + l {
                                continue;
                            }
                            let (s, i) = (&srcs[l as usize], yr * w + x as usize);
                            let (o, d_o) = occlusion(ctx, s, i, false);
                            let one = (T::one(), T::zero());
                            let acc = &mut singles[l as usize];
                            add_tap(ctx, s, i, one, (o - T::one(), d_o), acc);
                        }
                    }
                }
                let runs = [disc.left, disc.right];
                for k in 0..2 {
                    if let Some(run) = runs[k] {
                        taps::<T, SHARP, false>(table, data, &g, at, run, &mut lanes);
                    }
                }
            }
        }
        for c in 0..6 {
            for l in 0..LANES {
                ring[c][l] += lanes[c][l].f64();
            }
        }
    }
    for l in 0..LANES {
        let mut acc: Sums<T> = [T::zero(); 6];
        for c in 0..6 {
            acc[c] = T::c(ring[c][l]) + singles[l][c];
        }
        // The interior's terms: S = 1, S' = 0, O = 1.
        let ic = [0, 1, 2, 3].map(|c| T::c(interior[c][l]));
        let gc = ic[0] * g.lin[0][l] + ic[1] * g.lin[1][l] + ic[2] * g.lin[2][l] + ic[3];
        for c in 0..3 {
            acc[c] = acc[c] + ic[c];
        }
        acc[3] = acc[3] + gc;
        acc[4] =
            acc[4] + gc * model::normalised_scatter_radius_factor(T::one(), T::zero(), dlog_area);
        let (o, k_share) = source_out(ctx, p0 + l, &acc);
        out[l] = o;
        *k_row += k_share;
    }
}

/// The group's taps at offsets `a ..= b` of row offset `dy` (image row `yr`), the centre
/// tap (`dy = 0`, `dx = 0`: `O = 1`) apart; `TAIL`: tail receivers only.
#[inline(always)]
fn taps<T: Real, const SHARP: bool, const TAIL: bool>(
    table: &GaugeTable<T>,
    data: &RowData<T>,
    g: &Group<T>,
    (yr, dy): (usize, isize),
    (a, b): (isize, isize),
    lanes: &mut LaneSums<T>,
) {
    if a > b {
        return;
    }
    let at = (yr, dy);
    if dy == 0 && a <= 0 && 0 <= b {
        part::<T, SHARP, TAIL>(table, data, g, at, (a, -1), lanes);
        let td = (table, data);
        match g.full {
            true => chunks::<T, SHARP, false, true, TAIL>(td, g, at, (0, 0), lanes),
            false => chunks::<T, SHARP, false, false, TAIL>(td, g, at, (0, 0), lanes),
        }
        part::<T, SHARP, TAIL>(table, data, g, at, (1, b), lanes);
    } else {
        part::<T, SHARP, TAIL>(table, data, g, at, (a, b), lanes);
    }
}

/// [`taps`] at offsets `a ..= b` (no centre tap): [`chunks`] with or without the occlusion
/// term (whether a receiver under the offsets has `e > 0`), full or alpha-only.
#[inline(always)]
fn part<T: Real, const SHARP: bool, const TAIL: bool>(
    table: &GaugeTable<T>,
    data: &RowData<T>,
    g: &Group<T>,
    at: (usize, isize),
    (a, b): (isize, isize),
    lanes: &mut LaneSums<T>,
) {
    if a > b {
        return;
    }
    let cols = (g.xs + a, g.xs + (LANES as isize - 1) + b);
    let occ = data.focus.any(data.rows.width, at.0, cols);
    let td = (table, data);
    match (occ, g.full) {
        (true, true) => chunks::<T, SHARP, true, true, TAIL>(td, g, at, (a, b), lanes),
        (true, false) => chunks::<T, SHARP, true, false, TAIL>(td, g, at, (a, b), lanes),
        (false, true) => chunks::<T, SHARP, false, true, TAIL>(td, g, at, (a, b), lanes),
        (false, false) => chunks::<T, SHARP, false, false, TAIL>(td, g, at, (a, b), lanes),
    }
}

/// Pass B's terms of the group at offsets `a ..= b` (none the centre) of row offset `dy`
/// (image row `yr`), added to its lanes: the steps of [`LANES`] offsets at a time
/// ([`ring_steps`], with the window mask), then per offset one vector of [`LANES`]
/// receivers, one per source. `OCC = false`: every receiver has `O = 1`; `FULL = false`:
/// only `sum gc S O`; `TAIL`: each tap times the receiver's tail membership (1 or 0).
#[inline(always)]
fn chunks<T: Real, const SHARP: bool, const OCC: bool, const FULL: bool, const TAIL: bool>(
    (table, data): (&GaugeTable<T>, &RowData<T>),
    g: &Group<T>,
    (yr, dy): (usize, isize),
    (a, b): (isize, isize),
    lanes: &mut LaneSums<T>,
) {
    let rows = &data.rows;
    let step = if SHARP {
        model::ScatterStep::Sharp
    } else {
        model::ScatterStep::Paper
    };
    let mut dx0 = a;
    while dx0 <= b {
        let n = (b - dx0 + 1).min(LANES as isize) as usize;
        let s8 = ring_steps::<T, SHARP>(table, g.r, dy, dx0);
        for k in 0..n {
            let s = s8[k];
            let sd = model::scatter_step_derivative(step, s);
            let f = model::normalised_scatter_radius_factor(s, sd, g.dlog_area);
            let at = yr * rows.stride + (g.xs + dx0) as usize + k;
            let (gr, gg, gb, gw) = (
                load(&rows.g_red, at),
                load(&rows.g_green, at),
                load(&rows.g_blue, at),
                load(&rows.g_weight, at),
            );
            let (e, dx, tm) = (
                load(&rows.focus_weight, at),
                load(&rows.rel_disp, at),
                load(&rows.tail, at),
            );
            for l in 0..LANES {
                let m = if TAIL { tm[l] } else { T::one() };
                let (o, d_o) = if OCC {
                    model::occlusion_fast_with_derivative(e[l], g.rel[l], dx[l])
                } else {
                    (T::one(), T::zero())
                };
                let gc = gr[l] * g.lin[0][l] + gg[l] * g.lin[1][l] + gb[l] * g.lin[2][l] + gw[l];
                let sm = s * m;
                let so = sm * o;
                lanes[3][l] = lanes[3][l] + gc * so;
                if FULL {
                    lanes[0][l] = lanes[0][l] + gr[l] * so;
                    lanes[1][l] = lanes[1][l] + gg[l] * so;
                    lanes[2][l] = lanes[2][l] + gb[l] * so;
                    lanes[4][l] = lanes[4][l] + gc * o * (f * m);
                    if OCC {
                        lanes[5][l] = lanes[5][l] + gc * sm * d_o;
                    }
                }
            }
        }
        dx0 += LANES as isize;
    }
}
