//! Pass B over a row's runs of equal-radius sources for a circular aperture, as row
//! correlations: the transpose of the forward's ring convolution (`scatter/runs.rs`).
//!
//! A circle's disc row `dy` is symmetric in `dx` and the same for `+-dy`, and with `O = 1`
//! every ring sum of pass B is linear in the receivers' upstream gradients `gC`, `gW`
//! (`gc = gC . Ilin(y) + gW`, `Ilin(y)` a per-source factor outside the sum). So for the
//! sources `xs` of a run (adjacent columns, one radius) and a receiver row pair `ys +- dy`,
//! the eight sums `sum g S` and `sum g S'` (`g` each of `gC` and `gW`) are one correlation
//! of the pair's summed rows `G(x) = g(ys + dy, x) + g(ys - dy, x)` with the row's profile:
//! `sum_dx S(dx, dy) (G(xs + dx) + G(xs - dx))`, [`LANES`] sources at a time, the profile's
//! `S` and `S'` read once per offset for all of them. From those,
//! `sum gc S = Ilin . sum gC S + sum gW S` and
//! `sum gc (S' - S A'/A) = Ilin . sum gC S' + sum gW S' - (A'/A) sum gc S`, as the fast
//! adjoint's terms ([`super::add_tap`] with `O = 1`).
//!
//! Which taps a row takes is [`super::source_sums`]'s choice, unchanged: on a span row the
//! interior from prefix sums (`S = 1`, `S' = 0`), the forward's ring (`Rings::of`) from
//! the receivers' planes and the tail receivers beyond it out to `r + 6` from the same
//! planes times their tail membership (1 or 0); on a tap row every tap out to `r + 6`.
//! Receivers outside the image are zero columns of the correlated rows ([`fill_rows`]),
//! which clips as the source by source code does. Receivers whose occlusion term is evaluated (`e(x) > 0`) get the
//! exact `O` as a correction `O - 1` on top, one by one (their `S`, `S'` from the same
//! profile), as the interior's do. The same terms as source by source, in another fixed
//! order: identical for any thread count.

use super::{add_tap, occlusion, source_out, RowData, Source, Sums, COMPONENTS, TAP_ROW_TAIL_PX};
use crate::engine::fast::adjoint::{Ctx, SourceTerms};
use crate::engine::spans::geometry::{
    disc_row, ring_step, GaugeTable, Rings, Shape, LANES, TABLE_MARGIN,
};
use crate::model;
use crate::Real;

/// The most sources correlated together: a run is cut into segments of this many, each
/// skipped where no receiver within its reach has a non-zero upstream gradient.
pub(super) const SEGMENT: usize = 64;

/// The shortest run taken as a correlation (shorter ones go source by source).
pub(super) const RUN_MIN: usize = 8;

/// Whether `table` (a circle's gauges, window mask folded in) is symmetric in `dx` and in
/// `dy`, as the correlation assumes.
pub(super) fn symmetric<T: Real>(table: &GaugeTable<T>) -> bool {
    let r = table.big_r as isize;
    let at = |dx: isize, dy: isize| {
        let i = (dy + r) as usize * table.stride + (dx + r) as usize + TABLE_MARGIN;
        (table.gauge[i], table.mask[i])
    };
    let mut same = true;
    for dy in 0..=r {
        for dx in 0..=r {
            let v = at(dx, dy);
            same &= at(-dx, dy) == v && at(dx, -dy) == v && at(-dx, -dy) == v;
        }
    }
    same
}

/// One row offset's taps: `(|dx|, S, S')` of the ring (or of every tap, on a tap row) and
/// of the taps beyond the ring that only tail receivers take, each `|dx| > 0`; the
/// centre's apart; and per `|dx| <= reach` the tap's `S`, `S'` and whether it is a tail tap
/// (the interior's `S = 1`, `S' = 0`).
#[derive(Default)]
struct Profile<T> {
    ring: Vec<(usize, T, T)>,
    centre: Option<(T, T)>,
    tail: Vec<(usize, T, T)>,
    tail_centre: Option<(T, T)>,
    /// The interior's half-width (span rows with an interior).
    interior: Option<usize>,
    /// Per `|dx| <= reach`: `(S, S', tail tap)`.
    dense: Vec<(T, T, bool)>,
}

impl<T: Real> Profile<T> {
    /// The largest `|dx|` of any tap, if any.
    #[inline(always)]
    fn reach(&self) -> Option<usize> {
        self.dense.len().checked_sub(1)
    }
}

/// The taps of row offset `dy` of a source of radius `r` (`hw` the window's half-width
/// there), into `out`: a span row's (`span`: interior, the forward's ring, the tail) or a
/// tap row's (every tap out to `r + 6`), as [`super::source_sums`] takes them.
fn profile<T: Real, const SHARP: bool>(
    (shape, table): (&Shape, &GaugeTable<T>),
    r: T,
    (dy, hw): (isize, usize),
    span: bool,
    out: &mut Profile<T>,
) {
    let step = if SHARP {
        model::ScatterStep::Sharp
    } else {
        model::ScatterStep::Paper
    };
    let rf = r.f64();
    out.ring.clear();
    out.tail.clear();
    out.dense.clear();
    out.centre = None;
    out.tail_centre = None;
    out.interior = None;
    let t = (dy + table.big_r as isize) as usize * table.stride + table.big_r + TABLE_MARGIN;
    let Some((_, hi)) = shape.interval(rf + TAP_ROW_TAIL_PX, dy, -1.0) else {
        return;
    };
    let f = hi.min(hw as isize);
    if f < 0 {
        return;
    }
    // The ring's `|dx|` range (empty: `k0 > e`); beyond it, tail taps.
    let (k0, e) = if span {
        match disc_row(shape, Rings::of(step), rf, dy, hw, -1.0) {
            None => (1, 0),
            Some(d) => {
                out.interior = d.interior.map(|(_, hi)| hi as usize);
                let k0 = d.interior.map_or(0, |(_, hi)| hi + 1);
                let e = match (d.interior, d.left, d.right) {
                    (Some(_), _, Some((_, hi))) | (None, Some((_, hi)), _) => hi,
                    (Some((_, hi)), _, None) => hi,
                    (None, None, _) => -1,
                };
                (k0, e)
            }
        }
    } else {
        (0, f)
    };
    for a in 0..=f {
        let (s, sd, tail) = if out.interior.is_some_and(|hi| a as usize <= hi) {
            (T::one(), T::zero(), false)
        } else {
            let s =
                ring_step::<T, SHARP>(r, table.gauge[t + a as usize], table.mask[t + a as usize]);
            let sd = model::scatter_step_derivative(step, s);
            let ring = k0 <= a && a <= e;
            match (ring, a) {
                (true, 0) => out.centre = Some((s, sd)),
                (true, _) => out.ring.push((a as usize, s, sd)),
                (false, 0) => out.tail_centre = Some((s, sd)),
                (false, _) => out.tail.push((a as usize, s, sd)),
            }
            (s, sd, !ring)
        };
        out.dense.push((s, sd, tail));
    }
}

/// Working memory of [`segment`], kept across calls: the correlated rows, and the
/// profiles of the radius last used (per row offset, a span row's and a tap row's).
pub(super) struct Scratch<T> {
    /// The correlated rows (`COMPONENTS` planes of `len`).
    g: Vec<T>,
    /// The radius of `profiles`.
    radius: Option<T>,
    /// Per `dy >= 0`, `[tap row, span row]` (computed when first needed).
    profiles: Vec<[Option<Profile<T>>; 2]>,
}

impl<T: Real> Default for Scratch<T> {
    fn default() -> Self {
        Scratch {
            g: Vec::new(),
            radius: None,
            profiles: Vec::new(),
        }
    }
}

/// Per source of a segment, the correlations `[sum gC S (3), sum gW S, sum gC S' (3),
/// sum gW S']`.
type Correlations = [[f64; SEGMENT]; 2 * COMPONENTS];

/// Pass B of the padded sources `q0 .. q0 + m` (`m <= SEGMENT`, one radius) of padded
/// row `py`: their gradients into `out` (`m` entries) and K's shares added to `k_row`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn segment<T: Real, const SHARP: bool>(
    ctx: &Ctx<'_, T>,
    (shape, table): (&Shape, &GaugeTable<T>),
    span_rows: &[bool],
    data: &RowData<T>,
    (q0, m, py): (usize, usize, usize),
    (out, k_row): (&mut [[T; 5]], &mut f64),
    scratch: &mut Scratch<T>,
) {
    let src = ctx.src;
    let (w, h) = (ctx.rcv.width, ctx.rcv.height as isize);
    let p0 = py * src.stride + q0;
    let (xs0, ys) = (
        q0 as isize - src.pad as isize,
        py as isize - src.pad as isize,
    );
    let r = src.radius[p0];
    let reach = super::reach(r, table);
    let last = m as isize - 1;
    let (cols, rows) = ((xs0 - reach, xs0 + last + reach), (ys - reach, ys + reach));
    if !data.nonzero.any(cols, rows) {
        return;
    }
    let tails = data.tail_area.any(cols, rows);
    let step = src.step;
    let dlog_area = model::source_area_log_derivative(step, r);
    if scratch.radius != Some(r) {
        scratch.radius = Some(r);
        scratch.profiles.clear();
    }
    if scratch.profiles.len() <= reach as usize {
        scratch
            .profiles
            .resize_with(reach as usize + 1, || [None, None]);
    }
    let mut corr: Correlations = [[0.0; SEGMENT]; 2 * COMPONENTS];
    let mut interior = [[0.0f64; SEGMENT]; COMPONENTS];
    let mut singles: [Sums<T>; SEGMENT] = [[T::zero(); 6]; SEGMENT];
    let source = |k: usize| {
        let p = p0 + k;
        Source {
            terms: SourceTerms {
                step,
                radius: r,
                dlog_area,
                rel_disp: src.rel_disp[p],
                lin: [src.red[p], src.green[p], src.blue[p]],
            },
            xs: xs0 + k as isize,
            ys,
            full: true,
        }
    };
    for dy in 0..=reach {
        let Some(hw) = table.window_half_width(dy) else {
            continue;
        };
        // The receiver rows `ys + dy`, `ys - dy` within the image, each with its kind.
        let mut cand: [Option<(usize, bool)>; 2] = [None; 2];
        for (j, yr) in [ys + dy, ys - dy].into_iter().enumerate() {
            if (j == 0 || dy != 0) && (0..h).contains(&yr) {
                let yr = yr as usize;
                if data.nonzero.any(cols, (yr as isize, yr as isize)) {
                    cand[j] = Some((yr, span_rows[yr]));
                }
            }
        }
        let kinds = [false, true];
        for span in kinds {
            let rows_of_kind =
                [cand[0], cand[1]].map(|c| c.filter(|&(_, s)| s == span).map(|(y, _)| y));
            if rows_of_kind.iter().all(Option::is_none) {
                continue;
            }
            let slot = &mut scratch.profiles[dy as usize][usize::from(span)];
            if slot.is_none() {
                let mut p = Profile::default();
                profile::<T, SHARP>((shape, table), r, (dy, hw), span, &mut p);
                *slot = Some(p);
            }
            let Some(prof) = &scratch.profiles[dy as usize][usize::from(span)] else {
                continue;
            };
            let Some(f) = prof.reach() else {
                continue;
            };
            // The ring (every tap on a tap row) over every receiver.
            let len = m.div_ceil(LANES) * LANES + 2 * f + LANES;
            let x0 = xs0 - f as isize;
            let rcv = ctx.rcv;
            let planes = [&rcv.g_red[..], &rcv.g_green, &rcv.g_blue, &rcv.g_weight];
            let rows = (rows_of_kind, w);
            fill_rows::<T, false>(&mut scratch.g, len, planes, &data.rows, rows, x0);
            correlate(&prof.ring, prof.centre, (&scratch.g, len, f), m, &mut corr);
            // Beyond the ring, the tail receivers only.
            if tails && (!prof.tail.is_empty() || prof.tail_centre.is_some()) {
                let mut any_tail = false;
                for yr in rows_of_kind.into_iter().flatten() {
                    any_tail |= data.tail_area.any(cols, (yr as isize, yr as isize));
                }
                if any_tail {
                    fill_rows::<T, true>(&mut scratch.g, len, planes, &data.rows, rows, x0);
                    let g = (&scratch.g[..], len, f);
                    correlate(&prof.tail, prof.tail_centre, g, m, &mut corr);
                }
            }
            for yr in rows_of_kind.into_iter().flatten() {
                // The interior's prefix sums (S = 1, S' = 0, O = 1).
                if let Some(hi) = prof.interior {
                    interior_sums(&data.prefix, (yr, w), (xs0, m), hi as isize, &mut interior);
                }
                // Receivers whose occlusion term is evaluated: O - 1 and dO/dd_y on top.
                let fi = f as isize;
                let range = ((xs0 - fi).max(0), (xs0 + last + fi).min(w as isize - 1));
                for &x in data.focus.within(w, yr, range) {
                    let x = x as isize;
                    let i = yr * w + x as usize;
                    let is_tail = data.rows.tail[yr * data.rows.stride + x as usize] != T::zero();
                    let (k0, k1) = ((x - fi - xs0).max(0), (x + fi - xs0).min(last));
                    for k in k0..=k1 {
                        let xs = xs0 + k;
                        if dy == 0 && x == xs {
                            continue;
                        }
                        let (s, sd, tail_tap) = prof.dense[(x - xs).unsigned_abs()];
                        if tail_tap && !is_tail {
                            continue;
                        }
                        let s_k = source(k as usize);
                        let (o, d_o) = occlusion(ctx, &s_k, i, false);
                        add_tap(
                            ctx,
                            &s_k,
                            i,
                            (s, sd),
                            (o - T::one(), d_o),
                            &mut singles[k as usize],
                        );
                    }
                }
            }
        }
    }
    for k in 0..m {
        let p = p0 + k;
        let lin = [src.red[p], src.green[p], src.blue[p]];
        let c64 = |c: usize| corr[c][k];
        // The ring's sums (O = 1).
        let gc_s =
            lin[0] * T::c(c64(0)) + lin[1] * T::c(c64(1)) + lin[2] * T::c(c64(2)) + T::c(c64(3));
        let gc_sd =
            lin[0] * T::c(c64(4)) + lin[1] * T::c(c64(5)) + lin[2] * T::c(c64(6)) + T::c(c64(7));
        let mut acc: Sums<T> = singles[k];
        for c in 0..3 {
            acc[c] = acc[c] + T::c(c64(c));
        }
        acc[3] = acc[3] + gc_s;
        acc[4] = acc[4] + model::normalised_scatter_radius_factor(gc_s, gc_sd, dlog_area);
        // The interior's terms: S = 1, S' = 0, O = 1.
        let ic = [0, 1, 2, 3].map(|c| T::c(interior[c][k]));
        let gc = ic[0] * lin[0] + ic[1] * lin[1] + ic[2] * lin[2] + ic[3];
        for c in 0..3 {
            acc[c] = acc[c] + ic[c];
        }
        acc[3] = acc[3] + gc;
        acc[4] =
            acc[4] + gc * model::normalised_scatter_radius_factor(T::one(), T::zero(), dlog_area);
        let (o, k_share) = source_out(ctx, p, &acc);
        out[k] = o;
        *k_row += k_share;
    }
}

/// Adds to `interior[c][k]` (`k < m`) the sum of component `c` over receiver row `yr`'s
/// columns `xs0 + k - hi ..= xs0 + k + hi` clipped to the image's `w`, from the row's
/// prefix sums: the unclipped sources as whole slices, the others one by one.
#[inline(always)]
fn interior_sums(
    prefix: &[Vec<f64>; COMPONENTS],
    (yr, w): (usize, usize),
    (xs0, m): (isize, usize),
    hi: isize,
    interior: &mut [[f64; SEGMENT]; COMPONENTS],
) {
    let (wi, row) = (w as isize, yr * (w + 1));
    // Sources ka .. kb see their whole span within the image.
    let ka = (hi - xs0).clamp(0, m as isize) as usize;
    let kb = (wi - hi - xs0).clamp(ka as isize, m as isize) as usize;
    for k in (0..ka).chain(kb..m) {
        let xs = xs0 + k as isize;
        let (xa, xb) = ((xs - hi).max(0), (xs + hi).min(wi - 1));
        if xa <= xb {
            let (ia, ib) = (row + xa as usize, row + xb as usize + 1);
            for c in 0..COMPONENTS {
                interior[c][k] += prefix[c][ib] - prefix[c][ia];
            }
        }
    }
    if kb > ka {
        let n = kb - ka;
        let ia = (row as isize + xs0 + ka as isize - hi) as usize;
        let ib = (row as isize + xs0 + ka as isize + hi + 1) as usize;
        for c in 0..COMPONENTS {
            let (pa, pb) = (&prefix[c][ia..ia + n], &prefix[c][ib..ib + n]);
            let out = &mut interior[c][ka..kb];
            for j in 0..n {
                out[j] += pb[j] - pa[j];
            }
        }
    }
}

/// `g[c][j]` for `j < len`: the sum over `rows` (image rows of `w` columns) of
/// `planes[c]` (image-sized) at image column `x0 + j`, zero outside the image; `TAIL`:
/// each value times the receiver's tail membership (`padded.tail`, 1 or 0).
#[inline(always)]
fn fill_rows<T: Real, const TAIL: bool>(
    g: &mut Vec<T>,
    len: usize,
    planes: [&[T]; COMPONENTS],
    padded: &super::PaddedRows<T>,
    (rows, w): ([Option<usize>; 2], usize),
    x0: isize,
) {
    if g.len() < COMPONENTS * len {
        g.resize(COMPONENTS * len, T::zero());
    }
    // Image columns x0 + ja .. x0 + jb.
    let ja = (-x0).clamp(0, len as isize) as usize;
    let jb = (w as isize - x0).clamp(ja as isize, len as isize) as usize;
    let xa = (x0 + ja as isize).clamp(0, w as isize) as usize;
    let n = jb - ja;
    let row = |y: usize| {
        let m = &padded.tail[y * padded.stride + xa..y * padded.stride + xa + n];
        (y * w + xa, m)
    };
    for c in 0..COMPONENTS {
        let out = &mut g[c * len..(c + 1) * len];
        out[..ja].fill(T::zero());
        out[jb..].fill(T::zero());
        let out = &mut out[ja..jb];
        match rows {
            [Some(a), Some(b)] => {
                let ((ia, ma), (ib, mb)) = (row(a), row(b));
                let (pa, pb) = (&planes[c][ia..ia + n], &planes[c][ib..ib + n]);
                for j in 0..n {
                    out[j] = if TAIL {
                        pa[j] * ma[j] + pb[j] * mb[j]
                    } else {
                        pa[j] + pb[j]
                    };
                }
            }
            [Some(a), None] | [None, Some(a)] => {
                let (ia, ma) = row(a);
                let pa = &planes[c][ia..ia + n];
                for j in 0..n {
                    out[j] = if TAIL { pa[j] * ma[j] } else { pa[j] };
                }
            }
            [None, None] => out.fill(T::zero()),
        }
    }
}

/// Adds to `corr[c][k]` (`k < m`) the correlation of row `c` of `g` (`len` per component;
/// source `k` at `g`'s index `f + k`) with the taps: `S` into `c`, `S'` into
/// `COMPONENTS + c`, [`LANES`] sources at a time with their sums in registers.
#[inline(always)]
fn correlate<T: Real>(
    taps: &[(usize, T, T)],
    centre: Option<(T, T)>,
    (g, len, f): (&[T], usize, usize),
    m: usize,
    corr: &mut Correlations,
) {
    if taps.is_empty() && centre.is_none() {
        return;
    }
    let planes: [&[T]; COMPONENTS] = std::array::from_fn(|c| &g[c * len..(c + 1) * len]);
    let mut q = 0;
    while q < m {
        // Per component, the sums with S and with S'.
        let mut s_s = [[T::zero(); LANES]; COMPONENTS];
        let mut s_d = [[T::zero(); LANES]; COMPONENTS];
        if let Some((sv, dv)) = centre {
            for c in 0..COMPONENTS {
                let v: &[T; LANES] = planes[c][f + q..f + q + LANES].try_into().expect("LANES");
                for l in 0..LANES {
                    s_s[c][l] = sv * v[l];
                    s_d[c][l] = dv * v[l];
                }
            }
        }
        for c in 0..COMPONENTS {
            let plane = &planes[c][q..q + 2 * f + LANES];
            let (ss, sd) = (&mut s_s[c], &mut s_d[c]);
            for &(dx, sv, dv) in taps {
                let a: &[T; LANES] = plane[f - dx..f - dx + LANES].try_into().expect("LANES");
                let b: &[T; LANES] = plane[f + dx..f + dx + LANES].try_into().expect("LANES");
                for l in 0..LANES {
                    let t = a[l] + b[l];
                    ss[l] = ss[l] + sv * t;
                    sd[l] = sd[l] + dv * t;
                }
            }
        }
        let n = (m - q).min(LANES);
        for c in 0..COMPONENTS {
            for l in 0..n {
                corr[c][q + l] += s_s[c][l].f64();
                corr[COMPONENTS + c][q + l] += s_d[c][l].f64();
            }
        }
        q += LANES;
    }
}
