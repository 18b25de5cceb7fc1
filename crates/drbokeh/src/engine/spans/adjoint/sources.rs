//! Pass B of the span adjoint: per padded source, the gradients reaching `Ilin(y)`, `a(y)`,
//! `d(y)` (through `S`, `A` and `O`) and K (through `r(y)`), summed over its disc row by
//! row: on span rows the interior from prefix sums of the receivers' upstream gradients,
//! the ring (the forward's) in 8-lane runs (the fast adjoint's [`source_run`]), the
//! in-focus receivers of the interior and the tail receivers (below) tap by tap; on tap
//! rows every tap within the fast adjoint's reach, in runs. The transpose of `scatter.rs`.
//!
//! **Tail receivers.** Beyond the forward's ring (`r + u_out`) a tap weighs at most
//! `1.4e-7` (paper) or `6.8e-8` (sharp) of a unit tap, which matters only where the
//! receiver's upstream factor `dL/dW ~ o / W` is large: receivers whose recorded weight
//! sum is below the refinement threshold (`W < 1e-2`, summed over the whole window before
//! the chain rule, `engine/fast/adjoint/refine.rs`). Those get every tap out to the fast
//! adjoint's reach `r + 6` (measured without them: 1.8e-2 of the largest alpha gradient at
//! a layer's edge, preset physical); elsewhere `dL/dW <= |dL/dB| o / 1e-2` and the dropped
//! tail is at most `1e-5` of a unit tap's gradient per source row.
//!
//! **Runs.** Sources of one radius in adjacent columns share their work: for a circle,
//! a run is a row correlation of the receivers' gradients with the disc row's profile
//! ([`conv`]); for a polygon, groups of [`LANES`] share the row geometry and each ring
//! step ([`runs`]). `engine::paths::force_source_by_source` turns both off (the plain
//! path, for `tests/spans_adjoint_runs.rs`).
//!
//! **Skipped sources.** A source none of whose reachable receivers (the bounding box of
//! `r + 6`) has a non-zero `dL/dC` or `dL/dW` has all sums exactly zero (a summed-area
//! count decides it in O(1)); zero-alpha sources need only `sum gc S O` (their alpha
//! gradient), the runs' alpha-only variant.

use super::super::geometry::{
    disc_row, ring_step, GaugeTable, Rings, Shape, LANES, STEP_ARGUMENT_MIN, TABLE_MARGIN,
};
use crate::engine::fast::adjoint::{
    gather_source_terms, Ctx, Receivers, SourceGradients, SourceTerms,
};
use crate::engine::simd::avx2_dispatch;
use crate::engine::summed_area::fill_summed_area;
use crate::model::{self, SCATTER_TAIL_PX};
use crate::Real;
use rayon::prelude::*;

mod conv;
mod runs;

/// Components of the receivers' upstream gradient: `dL/dC` (3) and `dL/dW`.
const COMPONENTS: usize = 4;

/// How far beyond `r` pass B reaches (in gauge units) on tap rows, and for tail receivers
/// on span rows: the fast adjoint's `r + 4.5 + 1.5` (`engine/fast/tiles.rs`,
/// `backward_reach`).
pub(super) const TAP_ROW_TAIL_PX: f64 = SCATTER_TAIL_PX + 1.5;

/// The reach of pass B for a source of radius `r`: `r + 6` clipped to the window, whole
/// pixels (every path of pass B: source by source, groups, correlations).
#[inline(always)]
fn reach<T: Real>(r: T, table: &GaugeTable<T>) -> isize {
    (r.f64() + TAP_ROW_TAIL_PX).min(table.big_r as f64).floor() as isize
}

/// A sparse set of receivers per image row: prefix counts (`w + 1` per row) and columns.
struct RowSet {
    count: Vec<u32>,
    cols: Vec<u32>,
    start: Vec<usize>,
}

impl RowSet {
    /// The set of `member` (one flag per pixel of a `w x h` image), rows in parallel.
    fn new(w: usize, h: usize, member: &[bool]) -> Self {
        let rows: Vec<(Vec<u32>, Vec<u32>)> = member
            .par_chunks(w)
            .map(|row| {
                let mut count = vec![0u32; w + 1];
                let mut cols = Vec::new();
                for (x, &inside) in row.iter().enumerate() {
                    count[x + 1] = count[x] + u32::from(inside);
                    if inside {
                        cols.push(x as u32);
                    }
                }
                (count, cols)
            })
            .collect();
        let mut count = Vec::with_capacity(h * (w + 1));
        let mut cols = Vec::new();
        let mut start = Vec::with_capacity(h + 1);
        for (c, members) in rows {
            start.push(cols.len());
            count.extend_from_slice(&c);
            cols.extend_from_slice(&members);
        }
        start.push(cols.len());
        RowSet { count, cols, start }
    }

    /// The members of row `y` in columns `xa ..= xb`.
    #[inline(always)]
    fn within(&self, w: usize, y: usize, (xa, xb): (isize, isize)) -> &[u32] {
        if xa > xb {
            return &[];
        }
        let count = &self.count[y * (w + 1)..];
        let (ca, cb) = (count[xa as usize] as usize, count[xb as usize + 1] as usize);
        &self.cols[self.start[y]..self.start[y + 1]][ca..cb]
    }

    /// Whether row `y` has a member in columns `xa ..= xb`.
    #[inline(always)]
    fn any(&self, w: usize, y: usize, (xa, xb): (isize, isize)) -> bool {
        let count = &self.count[y * (w + 1)..];
        count[xb as usize + 1] > count[xa as usize]
    }
}

/// The receivers' planes of pass B, each image row followed by [`LANES`] zero columns, so
/// that a chunk of [`LANES`] receivers from any column of a row lies in the plane.
struct PaddedRows<T> {
    width: usize,
    /// `width + LANES`.
    stride: usize,
    g_red: Vec<T>,
    g_green: Vec<T>,
    g_blue: Vec<T>,
    g_weight: Vec<T>,
    focus_weight: Vec<T>,
    rel_disp: Vec<T>,
    /// 1 for a tail receiver (see the module documentation), else 0.
    tail: Vec<T>,
}

impl<T: Real> PaddedRows<T> {
    fn new(rcv: &Receivers<T>, tail: &[T]) -> Self {
        let (w, h) = (rcv.width, rcv.height);
        let stride = w + LANES;
        let pad = |v: &[T]| {
            let mut out = vec![T::zero(); h * stride];
            out.par_chunks_mut(stride)
                .zip(v.par_chunks(w))
                .for_each(|(out, row)| out[..w].copy_from_slice(row));
            out
        };
        PaddedRows {
            width: w,
            stride,
            g_red: pad(&rcv.g_red),
            g_green: pad(&rcv.g_green),
            g_blue: pad(&rcv.g_blue),
            g_weight: pad(&rcv.g_weight),
            focus_weight: pad(&rcv.focus_weight),
            rel_disp: pad(&rcv.rel_disp),
            tail: pad(tail),
        }
    }
}

/// The receivers' side of pass B.
struct RowData<T> {
    /// The receivers' planes, padded for whole chunks.
    rows: PaddedRows<T>,
    /// Prefix sums `[component][y][x]` (`w + 1` entries per row) of `gC` and `gW`.
    prefix: [Vec<f64>; COMPONENTS],
    /// Receivers whose occlusion term is evaluated (`e(x) > 0` after the cutoff).
    focus: RowSet,
    /// Tail receivers (see the module documentation).
    tail: RowSet,
    /// Receivers with a non-zero `gC` or `gW`.
    nonzero: Area,
    /// Tail receivers, as an area count.
    tail_area: Area,
    /// Whether runs of sources of one radius share their row geometry ([`runs`]).
    groups: bool,
    /// Whether runs take [`conv`]'s correlations (a circle whose gauge table is symmetric).
    conv: bool,
}

/// A summed-area count (`(h + 1) x (w + 1)`) of a set of receivers.
struct Area {
    width: usize,
    height: usize,
    count: Vec<u32>,
}

impl Area {
    /// The summed-area count of `member` (one flag per pixel of a `w x h` image): row
    /// prefix counts in parallel, then the rows accumulated downwards.
    fn new(w: usize, h: usize, member: &[bool]) -> Self {
        let mut count = vec![0u32; (h + 1) * (w + 1)];
        fill_summed_area(&mut count, w, h, |x, y| u32::from(member[y * w + x]));
        Area {
            width: w,
            height: h,
            count,
        }
    }

    /// Whether a member lies in image columns `x0 ..= x1`, rows `y0 ..= y1` (clipped).
    #[inline(always)]
    fn any(&self, (x0, x1): (isize, isize), (y0, y1): (isize, isize)) -> bool {
        let (w, h) = (self.width as isize, self.height as isize);
        let (x0, x1) = (x0.max(0) as usize, (x1 + 1).clamp(0, w) as usize);
        let (y0, y1) = (y0.max(0) as usize, (y1 + 1).clamp(0, h) as usize);
        if x0 >= x1 || y0 >= y1 {
            return false;
        }
        let (s1, c) = (self.width + 1, &self.count);
        c[y1 * s1 + x1] + c[y0 * s1 + x0] > c[y0 * s1 + x1] + c[y1 * s1 + x0]
    }
}

/// Pass B over every padded source of the layer (`span_rows[y]`: whether receiver row `y`
/// was rendered as spans; `tail[i]`: whether receiver `i` is a tail receiver).
pub(super) fn pass_sources<T: Real>(
    ctx: &Ctx<'_, T>,
    shape: &Shape,
    table: &GaugeTable<T>,
    span_rows: &[bool],
    tail: &[bool],
) -> SourceGradients<T> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let (w, h) = (rcv.width, rcv.height);
    let nonzero: Vec<bool> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            rcv.g_red[i] != T::zero()
                || rcv.g_green[i] != T::zero()
                || rcv.g_blue[i] != T::zero()
                || rcv.g_weight[i] != T::zero()
        })
        .collect();
    let planes = [&rcv.g_red, &rcv.g_green, &rcv.g_blue, &rcv.g_weight];
    let prefix = planes.map(|plane| {
        let mut prefix = vec![0.0f64; h * (w + 1)];
        prefix
            .par_chunks_mut(w + 1)
            .zip(plane.par_chunks(w))
            .for_each(|(out, row)| {
                for (x, v) in row.iter().enumerate() {
                    out[x + 1] = out[x] + v.f64();
                }
            });
        prefix
    });
    let is_tail: Vec<bool> = tail
        .par_iter()
        .zip(&nonzero)
        .map(|(&t, &n)| t && n)
        .collect();
    let tail_plane: Vec<T> = is_tail
        .par_iter()
        .map(|&t| if t { T::one() } else { T::zero() })
        .collect();
    let focus: Vec<bool> = rcv
        .focus_weight
        .par_iter()
        .map(|&e| e > T::zero())
        .collect();
    let shared = !crate::engine::paths::source_by_source();
    let circle = matches!(shape, Shape::Circle);
    let conv = shared && circle && conv::symmetric(table);
    let data = RowData {
        conv,
        rows: PaddedRows::new(rcv, &tail_plane),
        prefix,
        groups: shared,
        focus: RowSet::new(w, h, &focus),
        tail: RowSet::new(w, h, &is_tail),
        nonzero: Area::new(w, h, &nonzero),
        tail_area: Area::new(w, h, &is_tail),
    };
    let rows: Vec<(Vec<[T; 5]>, f64)> = (0..src.rows)
        .into_par_iter()
        .map(|py| source_row_dispatch(ctx, shape, table, span_rows, &data, py))
        .collect();
    gather_source_terms(rows, src, (w, h))
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
        data: &RowData<T>,
        py: usize
    ) -> (Vec<[T; 5]>, f64)
);

/// A source's terms.
#[derive(Clone, Copy)]
struct Source<T> {
    terms: SourceTerms<T>,
    /// Image column and row.
    xs: isize,
    ys: isize,
    /// Alpha > 0: every sum; else only `sum gc S O`.
    full: bool,
}

/// The sums of pass B for one source: `[sum gC S O (3), sum gc S O, sum gc O (S' - S A'/A),
/// sum gc S dO/dd_y]`.
type Sums<T> = [T; 6];

/// [`Sums`] in [`LANES`] partial sums each, kept over a whole source and reduced once.
type LaneSums<T> = [[T; LANES]; 6];

/// Pass B over the padded source row `py`: per padded pixel
/// `[g_lin r, g, b, g_alpha, g_disp]` and K's share.
#[inline(always)]
fn source_row<T: Real>(
    ctx: &Ctx<'_, T>,
    shape: &Shape,
    table: &GaugeTable<T>,
    span_rows: &[bool],
    data: &RowData<T>,
    py: usize,
) -> (Vec<[T; 5]>, f64) {
    let src = ctx.src;
    let (stride, pad) = (src.stride, src.pad);
    let mut out = vec![[T::zero(); 5]; stride];
    let mut k_row = 0.0f64;
    let mut px = 0;
    let mut scratch = conv::Scratch::default();
    while px < stride {
        if data.conv {
            // A run of sources of one radius: correlations, a segment at a time.
            let p = py * stride + px;
            let mut n = 1;
            while px + n < stride && src.radius[p + n] == src.radius[p] {
                n += 1;
            }
            if n >= conv::RUN_MIN {
                let st = (shape, table);
                let mut q = px;
                while q < px + n {
                    let m = (px + n - q).min(conv::SEGMENT);
                    let at = (q, m, py);
                    let outs = (&mut out[q..q + m], &mut k_row);
                    match src.step {
                        model::ScatterStep::Sharp => conv::segment::<T, true>(
                            ctx,
                            st,
                            span_rows,
                            data,
                            at,
                            outs,
                            &mut scratch,
                        ),
                        model::ScatterStep::Paper => conv::segment::<T, false>(
                            ctx,
                            st,
                            span_rows,
                            data,
                            at,
                            outs,
                            &mut scratch,
                        ),
                    }
                    q += m;
                }
                px += n;
                continue;
            }
        }
        if data.groups && runs::groupable(ctx, table, (px, py)) {
            let outs = (&mut out[px..px + LANES], &mut k_row);
            match src.step {
                model::ScatterStep::Sharp => {
                    runs::group::<T, true>(ctx, (shape, table), span_rows, data, (px, py), outs)
                }
                model::ScatterStep::Paper => {
                    runs::group::<T, false>(ctx, (shape, table), span_rows, data, (px, py), outs)
                }
            }
            px += LANES;
            continue;
        }
        let (q, p) = (px, py * stride + px);
        px += 1;
        let (a, r) = (src.alpha[p], src.radius[p]);
        let (xs, ys) = (q as isize - pad as isize, py as isize - pad as isize);
        let reach = reach(r, table);
        if !data
            .nonzero
            .any((xs - reach, xs + reach), (ys - reach, ys + reach))
        {
            continue;
        }
        let s = Source {
            terms: SourceTerms {
                step: src.step,
                radius: r,
                dlog_area: model::source_area_log_derivative(src.step, r),
                rel_disp: src.rel_disp[p],
                lin: [src.red[p], src.green[p], src.blue[p]],
            },
            xs,
            ys,
            full: a != T::zero(),
        };
        let st = (shape, table);
        let acc = match src.step {
            model::ScatterStep::Sharp => source_sums::<T, true>(ctx, st, span_rows, data, s),
            model::ScatterStep::Paper => source_sums::<T, false>(ctx, st, span_rows, data, s),
        };
        let (o, k_share) = source_out(ctx, p, &acc);
        out[q] = o;
        k_row += k_share;
    }
    (out, k_row)
}

/// The padded source `p`'s gradients `[g_lin r, g, b, g_alpha, g_disp]` and K's share
/// from its sums.
#[inline(always)]
fn source_out<T: Real>(ctx: &Ctx<'_, T>, p: usize, acc: &Sums<T>) -> ([T; 5], f64) {
    let src = ctx.src;
    let inv_area = src.inv_area[p];
    let a_inv = src.alpha[p] * inv_area;
    let g_r = acc[4] * a_inv;
    let d_y = src.rel_disp[p];
    let out = [
        acc[0] * a_inv,
        acc[1] * a_inv,
        acc[2] * a_inv,
        acc[3] * inv_area,
        acc[5] * a_inv + g_r * ctx.k * model::scatter_radius_sign(d_y),
    ];
    (out, (g_r * d_y.abs()).f64())
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
    let lin = src.terms.lin;
    let g = [rcv.g_red[i], rcv.g_green[i], rcv.g_blue[i]];
    let gc = g[0] * lin[0] + g[1] * lin[1] + g[2] * lin[2] + rcv.g_weight[i];
    let so = s * o;
    for c in 0..3 {
        acc[c] = acc[c] + g[c] * so;
    }
    acc[3] = acc[3] + gc * so;
    acc[4] = acc[4] + gc * o * model::normalised_scatter_radius_factor(s, sd, src.terms.dlog_area);
    acc[5] = acc[5] + gc * s * d_o;
}

/// The occlusion term of receiver `i` for the source, with its derivative with respect to
/// the source's disparity: `(1, 0)` where the fast adjoint takes `O = 1` (`e(x) < 1e-9`,
/// and the centre tap).
#[inline(always)]
fn occlusion<T: Real>(ctx: &Ctx<'_, T>, src: &Source<T>, i: usize, centre: bool) -> (T, T) {
    let e = ctx.rcv.focus_weight[i];
    if e > T::zero() && !centre {
        model::occlusion_fast_with_derivative(e, src.terms.rel_disp, ctx.rcv.rel_disp[i])
    } else {
        (T::one(), T::zero())
    }
}

/// The exact tap of receiver column `x` of image row `yr` (row offset `dy`), scalar.
#[inline(always)]
fn exact_tap<T: Real, const SHARP: bool>(
    ctx: &Ctx<'_, T>,
    table: &GaugeTable<T>,
    src: &Source<T>,
    (yr, dy): (usize, isize),
    x: isize,
    acc: &mut Sums<T>,
) {
    let w = ctx.rcv.width;
    let t = (dy + table.big_r as isize) as usize;
    let m = (t * table.stride + table.big_r + TABLE_MARGIN) as isize + x - src.xs;
    let (g, mask) = (table.gauge[m as usize], table.mask[m as usize]);
    let u = (src.terms.radius - g).max(T::c(STEP_ARGUMENT_MIN));
    let s = if SHARP {
        model::sharp_step_fast(u)
    } else {
        model::soft_step_fast(u)
    } * mask;
    let sd = model::scatter_step_derivative(ctx.src.step, s);
    let i = yr * w + x as usize;
    let centre = dy == 0 && x == src.xs;
    let o = occlusion(ctx, src, i, centre);
    add_tap(ctx, src, i, (s, sd), o, acc);
}

/// The taps of receiver columns `xa ..= xb` of image row `yr` (row offset `dy`) in chunks
/// of [`LANES`] ([`run_chunks`]), the centre tap (`O = 1`) scalar. Not recursive, so that
/// it inlines into the caller's AVX2 code path.
#[inline(always)]
fn run_taps<T: Real, const SHARP: bool>(
    ctx: &Ctx<'_, T>,
    (table, data): (&GaugeTable<T>, &RowData<T>),
    src: &Source<T>,
    (yr, dy): (usize, isize),
    (xa, xb): (isize, isize),
    (acc, lanes): (&mut Sums<T>, &mut LaneSums<T>),
) {
    let at = (yr, dy);
    if dy == 0 && (xa..=xb).contains(&src.xs) {
        run_part::<T, SHARP>(table, data, src, at, (xa, src.xs - 1), lanes);
        exact_tap::<T, SHARP>(ctx, table, src, at, src.xs, acc);
        run_part::<T, SHARP>(table, data, src, at, (src.xs + 1, xb), lanes);
    } else {
        run_part::<T, SHARP>(table, data, src, at, (xa, xb), lanes);
    }
}

/// [`run_taps`] over columns `xa ..= xb` that do not hold the centre tap: [`run_chunks`]
/// with or without the occlusion term (whether a receiver of the run has `e > 0`).
#[inline(always)]
fn run_part<T: Real, const SHARP: bool>(
    table: &GaugeTable<T>,
    data: &RowData<T>,
    src: &Source<T>,
    at: (usize, isize),
    cols: (isize, isize),
    lanes: &mut LaneSums<T>,
) {
    if cols.0 > cols.1 {
        return;
    }
    let occ = data.focus.any(data.rows.width, at.0, cols);
    let td = (table, data);
    match (occ, src.full) {
        (true, true) => run_chunks::<T, SHARP, true, true>(td, src, at, cols, lanes),
        (true, false) => run_chunks::<T, SHARP, true, false>(td, src, at, cols, lanes),
        (false, true) => run_chunks::<T, SHARP, false, true>(td, src, at, cols, lanes),
        (false, false) => run_chunks::<T, SHARP, false, false>(td, src, at, cols, lanes),
    }
}

/// Pass B's terms of the taps of receiver columns `xa ..= xb` (none the centre) of image
/// row `yr` (row offset `dy`), added to the source's lanes: whole chunks of [`LANES`]
/// receivers (the padded rows, [`PaddedRows`]), the lanes past `xb` masked to 0 with the
/// window mask ([`ring_step`]), so that every chunk is one branch-free vector body. Lane
/// `l` of the chunk from column `x0` sums the tap `x0 + l`: a fixed order (the same bytes
/// for any thread count and vector width). `OCC = false`: every receiver has `O = 1`;
/// `FULL = false` (alpha = 0): only `sum gc S O`.
#[inline(always)]
fn run_chunks<T: Real, const SHARP: bool, const OCC: bool, const FULL: bool>(
    (table, data): (&GaugeTable<T>, &RowData<T>),
    src: &Source<T>,
    (yr, dy): (usize, isize),
    (xa, xb): (isize, isize),
    lanes: &mut LaneSums<T>,
) {
    let rows = &data.rows;
    let terms = src.terms;
    let step = if SHARP {
        model::ScatterStep::Sharp
    } else {
        model::ScatterStep::Paper
    };
    let mut x0 = xa;
    while x0 <= xb {
        let n = (xb - x0 + 1).min(LANES as isize) as usize;
        let (g, m) = (
            table.chunk(dy, x0 - src.xs),
            table.mask_chunk(dy, x0 - src.xs),
        );
        let at = yr * rows.stride + x0 as usize;
        let (gr, gg, gb, gw) = (
            load(&rows.g_red, at),
            load(&rows.g_green, at),
            load(&rows.g_blue, at),
            load(&rows.g_weight, at),
        );
        let (e, dx) = (load(&rows.focus_weight, at), load(&rows.rel_disp, at));
        for l in 0..LANES {
            let keep = if l < n { m[l] } else { T::zero() };
            let s = ring_step::<T, SHARP>(terms.radius, g[l], keep);
            let (o, d_o) = if OCC {
                model::occlusion_fast_with_derivative(e[l], terms.rel_disp, dx[l])
            } else {
                (T::one(), T::zero())
            };
            let gc = gr[l] * terms.lin[0] + gg[l] * terms.lin[1] + gb[l] * terms.lin[2] + gw[l];
            let so = s * o;
            lanes[3][l] = lanes[3][l] + gc * so;
            if FULL {
                lanes[0][l] = lanes[0][l] + gr[l] * so;
                lanes[1][l] = lanes[1][l] + gg[l] * so;
                lanes[2][l] = lanes[2][l] + gb[l] * so;
                let sd = model::scatter_step_derivative(step, s);
                lanes[4][l] = lanes[4][l]
                    + gc * o * model::normalised_scatter_radius_factor(s, sd, terms.dlog_area);
                if OCC {
                    lanes[5][l] = lanes[5][l] + gc * s * d_o;
                }
            }
        }
        x0 += LANES as isize;
    }
}

/// The [`LANES`] values of `v` from index `at`.
#[inline(always)]
fn load<T: Real>(v: &[T], at: usize) -> &[T; LANES] {
    v[at..at + LANES].try_into().expect("LANES")
}

/// Image columns `xs + lo ..= xs + hi`, clipped to the image's `w` columns.
#[inline(always)]
fn clip(xs: isize, w: isize, (lo, hi): (isize, isize)) -> (isize, isize) {
    ((xs + lo).max(0), (xs + hi).min(w - 1))
}

/// Pass B's sums of one source over its disc.
#[inline(always)]
fn source_sums<T: Real, const SHARP: bool>(
    ctx: &Ctx<'_, T>,
    (shape, table): (&Shape, &GaugeTable<T>),
    span_rows: &[bool],
    data: &RowData<T>,
    src: Source<T>,
) -> Sums<T> {
    let (w, h) = (ctx.rcv.width as isize, ctx.rcv.height as isize);
    let rings = Rings::of(ctx.src.step);
    let rf = src.terms.radius.f64();
    let reach = reach(src.terms.radius, table);
    let mut acc: Sums<T> = [T::zero(); 6];
    let mut lanes: LaneSums<T> = [[T::zero(); LANES]; 6];
    // Whether a tail receiver lies within the reach's bounding box at all.
    let tails = data.tail_area.any(
        (src.xs - reach, src.xs + reach),
        (src.ys - reach, src.ys + reach),
    );
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
        // Every tap within the fast adjoint's reach on this row.
        let Some((lo, hi)) = shape.interval(rf + TAP_ROW_TAIL_PX, dy, -1.0) else {
            continue;
        };
        let hwi = hw as isize;
        let (fa, fb) = clip(src.xs, w, (lo.max(-hwi), hi.min(hwi)));
        if fa > fb {
            continue;
        }
        let td = (table, data);
        if !span_rows[yr] {
            let sums = (&mut acc, &mut lanes);
            run_taps::<T, SHARP>(ctx, td, &src, (yr, dy), (fa, fb), sums);
            continue;
        }
        let disc = disc_row(shape, rings, rf, dy, hw, -1.0);
        if tails {
            // The columns the forward's disc row covers (image columns; empty if none).
            let (da, db) = match disc {
                None => (fb + 1, fb),
                Some(d) => {
                    let first = d.left.or(d.interior).map_or(0, |r| r.0);
                    let last = d.right.or(d.interior).or(d.left).map_or(-1, |r| r.1);
                    clip(src.xs, w, (first, last))
                }
            };
            // Tail receivers beyond the forward's ring: exact taps.
            for part in [(fa, fb.min(da - 1)), (fa.max(db + 1), fb)] {
                for &x in data.tail.within(ctx.rcv.width, yr, part) {
                    exact_tap::<T, SHARP>(ctx, table, &src, (yr, dy), x as isize, &mut acc);
                }
            }
        }
        let Some(disc) = disc else {
            continue;
        };
        if let Some(run) = disc.interior {
            let (xa, xb) = clip(src.xs, w, run);
            if xa <= xb {
                let row = yr * (ctx.rcv.width + 1);
                let (ia, ib) = (row + xa as usize, row + xb as usize + 1);
                for c in 0..COMPONENTS {
                    interior[c] += data.prefix[c][ib] - data.prefix[c][ia];
                }
                // Receivers whose occlusion term is evaluated: O - 1 and dO/dd_y on top.
                for &x in data.focus.within(ctx.rcv.width, yr, (xa, xb)) {
                    if dy == 0 && x as isize == src.xs {
                        continue;
                    }
                    let i = yr * ctx.rcv.width + x as usize;
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
        let ring = [disc.left, disc.right];
        for k in 0..2 {
            if let Some(run) = ring[k] {
                let sums = (&mut acc, &mut lanes);
                run_taps::<T, SHARP>(ctx, td, &src, (yr, dy), clip(src.xs, w, run), sums);
            }
        }
    }
    // The runs' lanes, in lane order.
    for c in 0..6 {
        let mut sum = T::zero();
        for l in 0..LANES {
            sum = sum + lanes[c][l];
        }
        acc[c] = acc[c] + sum;
    }
    // The interior's terms: S = 1, S' = 0, O = 1.
    let ic: [T; COMPONENTS] = interior.map(T::c);
    let lin = src.terms.lin;
    let gc = ic[0] * lin[0] + ic[1] * lin[1] + ic[2] * lin[2] + ic[3];
    for c in 0..3 {
        acc[c] = acc[c] + ic[c];
    }
    acc[3] = acc[3] + gc;
    acc[4] = acc[4]
        + gc * model::normalised_scatter_radius_factor(T::one(), T::zero(), src.terms.dlog_area);
    acc
}
