//! The soft-disc coverage (preset `physical`) in the span adjoint, O(r) per receiver
//! instead of the fast adjoint's O(r^2):
//!
//! - the sums `sum S a`, `Z = sum S`, `sum S' a`, `sum S'` of every receiver over its
//!   coverage disc (radius `r_c(x)`, out to the forward's ring `r_c + u_out`, [`Rings`]):
//!   the interior (`1 - S <= 1e-5`) from row prefix sums of alpha (`S := 1`, `S' := 0`)
//!   and a count, the ring tap by tap (AVX2 where present; a circle's steps from the
//!   forward's [`ExpTable`], one `exp` per receiver instead of one per tap: `vjp` 512 px
//!   K 30 physical 7.9-8.8 -> 5.8-6.5 s of CPU, low load);
//! - pass C, `dL/da(y) += sum_x share(x) S(r_c(x), y)` with `share = dL/do / Z`: the
//!   transpose, each receiver scattering `share(x)` over its disc's rows as spans (two
//!   writes into a difference array per row, prefix-summed per source row) and its ring
//!   tap by tap, in bands of source rows (one task each, receivers in a fixed order: the
//!   same bytes for any thread count).
//!
//! Runs of [`LANES`] receivers of one coverage radius in adjacent columns (a layer of
//! constant or row-constant disparity) share one disc: both directions then evaluate each
//! ring step once per offset for the whole run ([`group_sums`], [`group_scatter`]).
//!
//! **Bound.** The interior's `S := 1` overestimates each interior tap by at most `1e-5` of
//! itself, so `o`, `Z` and pass C's sums err by at most `2e-5` relative (as the forward's
//! soft disc, `spans/mod.rs`); the dropped interior `S'` integrates along each ray to at
//! most `1e-5` of the ring's, so `do/dr` errs by at most `1e-5` of its ring sum. The tail
//! beyond `r_c + u_out` (the fast adjoint keeps it to `r_c + 6`) weighs at most `6.8e-8`
//! (sharp) or `1.4e-7` (paper) per tap against `Z >= S(r_c, 0) >= 1/2`: with at most
//! `pi (6^2 - 2.75^2)` such taps at `r_c ~ 0`, under `2e-5` relative.

use super::super::geometry::{
    ExpTable, GaugeTable, Rings, Shape, LANES, STEP_ARGUMENT_MIN, TABLE_MARGIN,
};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::model::{self, CoverageRadius, DiscCoverage};
use crate::Real;
use rayon::prelude::*;

/// Source rows per task of pass C.
const BAND: usize = 16;

/// A disc row's reach and interior columns (offsets).
type DiscRowSpan = ((isize, isize), Option<(isize, isize)>);

/// A receiver's coverage radius `r_c`, its step factor `e_r` ([`DiscCtx::factor`]) and
/// `dr_c/dr`.
#[derive(Clone, Copy)]
struct RadiusTerms<T> {
    r_c: T,
    e_r: f64,
    dr: T,
}

/// What both directions share: the padded source planes, the gather table (tap offsets
/// `y - x`), the shape and the coverage radius of each receiver.
pub(super) struct DiscCtx<'a, T> {
    pub src: &'a Planes<T>,
    pub shape: &'a Shape,
    pub table: &'a GaugeTable<T>,
    pub width: usize,
    pub height: usize,
    /// Per receiver (image index): `r_c(x)` and `dr_c/dr(x)`.
    pub rc: Vec<(T, T)>,
    /// A circle's steps by table ([`ExpTable`], as the forward's ring; `None`: polygon
    /// apertures, or a window too large for the table).
    exp: Option<ExpTable>,
}

impl<'a, T: Real> DiscCtx<'a, T> {
    pub fn new(
        src: &'a Planes<T>,
        shape: &'a Shape,
        table: &'a GaugeTable<T>,
        (width, height): (usize, usize),
        (kind, footprint_px): (CoverageRadius, f64),
    ) -> Self {
        let footprint = T::c(footprint_px);
        let rc = (0..width * height)
            .map(|i| {
                let r = src.radius[src.index(i % width, i / width)];
                model::coverage_radius_px(r, kind, footprint)
            })
            .collect();
        let exp = matches!(shape, Shape::Circle)
            .then(|| ExpTable::new(src.step, table.big_r))
            .flatten();
        DiscCtx {
            src,
            shape,
            table,
            width,
            height,
            rc,
            exp,
        }
    }

    /// The factor of radius `r_c` for [`DiscCtx::steps`] (one `exp` per receiver).
    #[inline(always)]
    fn factor(&self, r_c: T) -> f64 {
        self.exp
            .as_ref()
            .map_or(0.0, |e| e.source_factor(r_c.f64()))
    }

    /// The rows of a disc of radius `r_c` reach `-reach ..= reach` (clipped to the window).
    #[inline(always)]
    fn reach(&self, r_c: f64) -> isize {
        let outer_px = Rings::of(self.src.step).outer_px;
        (r_c + outer_px).min(self.table.big_r as f64).floor() as isize
    }

    /// Row `dy` of a disc of radius `r_c`: the reach's columns and the interior's (offsets),
    /// clipped to the window; `None` if the row holds no tap. (Plain functions rather than
    /// a visitor taking closures: a closure is compiled apart from its caller and would
    /// lose the caller's AVX2 code path.)
    #[inline(always)]
    fn row(&self, r_c: f64, dy: isize) -> Option<DiscRowSpan> {
        let Rings { inner_px, outer_px } = Rings::of(self.src.step);
        let hw = self.table.window_half_width(dy)? as isize;
        let clip = |(lo, hi): (isize, isize)| {
            let (lo, hi) = (lo.max(-hw), hi.min(hw));
            (lo <= hi).then_some((lo, hi))
        };
        let outer = self
            .shape
            .interval(r_c + outer_px, dy, 1.0)
            .and_then(clip)?;
        let interior = self.shape.interval(r_c - inner_px, dy, 1.0).and_then(clip);
        Some((outer, interior))
    }

    /// The steps of radius `r_c` at the [`LANES`] offsets `(dx0 + l, dy)`, lanes `l >= n`
    /// set to 0: by the circle's table, else through the gauge table (both with the window
    /// mask).
    #[inline(always)]
    fn steps(&self, (dx0, dy): (isize, isize), n: usize, r_c: T, e_r: f64) -> [T; LANES] {
        let s = match &self.exp {
            Some(e) => e.steps::<T>(e_r, dy, dx0),
            None => {
                let m = self.table_index(dx0, dy);
                let g: &[T; LANES] = self.table.gauge[m..m + LANES].try_into().expect("LANES");
                let mask: &[T; LANES] = self.table.mask[m..m + LANES].try_into().expect("LANES");
                let mut s = [T::zero(); LANES];
                for l in 0..LANES {
                    let u = (r_c - g[l]).max(T::c(STEP_ARGUMENT_MIN));
                    s[l] = model::scatter_step_fast(self.src.step, u) * mask[l];
                }
                s
            }
        };
        let mut out = [T::zero(); LANES];
        for l in 0..LANES {
            out[l] = if l < n { s[l] } else { T::zero() };
        }
        out
    }

    /// Adds the soft-disc terms `[S a, S, S' a, S']` (`S'` times `dr`) of radius `r_c` over
    /// the taps `a ..= b` of row offset `dy` to `lanes` (lane `l` of the chunk from `dx0`:
    /// tap `dx0 + l`, a fixed order), `row`: the padded index of the receiver's column on
    /// that row. Whole chunks of [`LANES`] taps, the lanes past `b` masked to 0.
    #[inline(always)]
    fn ring_sums(
        &self,
        row: usize,
        dy: isize,
        (a, b): (isize, isize),
        rc: RadiusTerms<T>,
        lanes: &mut [[T; LANES]; 4],
    ) {
        let alpha = &self.src.alpha;
        let mut dx0 = a;
        while dx0 <= b {
            let n = (b - dx0 + 1).min(LANES as isize) as usize;
            let s = self.steps((dx0, dy), n, rc.r_c, rc.e_r);
            let at = (row as isize + dx0) as usize;
            // The last rows of the plane may end inside the chunk (masked lanes).
            let al: [T; LANES] = match alpha.get(at..at + LANES) {
                Some(v) => v.try_into().expect("LANES"),
                None => std::array::from_fn(|l| alpha.get(at + l).copied().unwrap_or(T::zero())),
            };
            for l in 0..LANES {
                let ds = model::scatter_step_derivative(self.src.step, s[l]) * rc.dr;
                lanes[0][l] = lanes[0][l] + s[l] * al[l];
                lanes[1][l] = lanes[1][l] + s[l];
                lanes[2][l] = lanes[2][l] + ds * al[l];
                lanes[3][l] = lanes[3][l] + ds;
            }
            dx0 += LANES as isize;
        }
    }

    /// Pass C's ring: `out_row[cx + dx] += share S(r_c, (dx, dy))` for `dx` in `a ..= b`
    /// (`tap`: `(cx, dy, r_c, e_r, share)`, `out_row`: the source row at offset `dy`
    /// followed by at least [`LANES`] entries, to which the masked lanes add 0). Whole
    /// chunks of [`LANES`] taps; each entry gets its terms in the same order as tap by tap.
    #[inline(always)]
    fn ring_scatter(
        &self,
        out_row: &mut [f64],
        (cx, dy, r_c, e_r, sh): (usize, isize, T, f64, T),
        (a, b): (isize, isize),
    ) {
        let mut dx0 = a;
        while dx0 <= b {
            let n = (b - dx0 + 1).min(LANES as isize) as usize;
            let s = self.steps((dx0, dy), n, r_c, e_r);
            let at = (cx as isize + dx0) as usize;
            let out: &mut [f64; LANES] = (&mut out_row[at..at + LANES]).try_into().expect("LANES");
            for l in 0..LANES {
                out[l] += (sh * s[l]).f64();
            }
            dx0 += LANES as isize;
        }
    }

    /// The gauge-table index of offset `(dx, dy)`.
    #[inline(always)]
    fn table_index(&self, dx: isize, dy: isize) -> usize {
        let t = (dy + self.table.big_r as isize) as usize;
        ((t * self.table.stride + self.table.big_r + TABLE_MARGIN) as isize + dx) as usize
    }
}

/// Rows of a disc whose ring sums [`disc_sums`] accumulates in `T` before it adds them to
/// its f64 sums (fewer conversions than per row). Measured at 512 px K 30, preset
/// physical, against the exact adjoint: gradients within 4.1e-6 of each kind's largest
/// value this way, 9.3e-6 with the sums in `T` over the whole disc, 6.8e-6 with the ring
/// runs summed one by one in `T` (before the chunks).
const FLUSH_ROWS: usize = 8;

/// Adds the `T` lanes to the f64 lanes and clears them.
#[inline(always)]
fn flush<T: Real>(lanes: &mut [[T; LANES]; 4], lanes_f64: &mut [[f64; LANES]; 4]) {
    for c in 0..4 {
        for l in 0..LANES {
            lanes_f64[c][l] += lanes[c][l].f64();
            lanes[c][l] = T::zero();
        }
    }
}

/// Every receiver's soft-disc sums with derivatives (the fast adjoint's
/// `disc_sums::<_, true>` over its reach, as spans).
pub(super) fn disc_sums<T: Real>(ctx: &DiscCtx<'_, T>) -> Vec<DiscCoverage<T>> {
    let src = ctx.src;
    let s1 = src.stride + 1;
    // Row prefix sums of alpha over the padded plane.
    let prefix: Vec<f64> = (0..src.rows)
        .into_par_iter()
        .flat_map_iter(|py| {
            let mut row = vec![0.0f64; s1];
            for px in 0..src.stride {
                row[px + 1] = row[px] + src.alpha[py * src.stride + px].f64();
            }
            row
        })
        .collect();
    (0..ctx.height)
        .into_par_iter()
        .flat_map_iter(|y| disc_sums_row_dispatch(ctx, &prefix, y))
        .collect()
}

avx2_dispatch!(
    disc_sums_row_dispatch,
    disc_sums_row_avx2,
    disc_sums_row,
    (ctx: &DiscCtx<'_, T>, prefix: &[f64], y: usize) -> Vec<DiscCoverage<T>>
);

/// [`disc_sums`] of the receivers of image row `y`.
#[inline(always)]
fn disc_sums_row<T: Real>(ctx: &DiscCtx<'_, T>, prefix: &[f64], y: usize) -> Vec<DiscCoverage<T>> {
    let src = ctx.src;
    let s1 = src.stride + 1;
    // A plain loop: an iterator adapter's closure would be compiled apart from this
    // function and lose its AVX2 code path.
    let mut out = Vec::with_capacity(ctx.width);
    let mut x = 0;
    while x < ctx.width {
        let i = y * ctx.width + x;
        if x + LANES <= ctx.width && equal_radii(&ctx.rc[i..i + LANES]) {
            group_sums(ctx, prefix, (x, y), &mut out);
            x += LANES;
            continue;
        }
        let xi = src.index(x, y);
        let (r_c, dr) = ctx.rc[i];
        let rc = RadiusTerms {
            r_c,
            e_r: ctx.factor(r_c),
            dr,
        };
        let mut sums = [0.0f64; 4];
        // The rings' sums in lanes, in T over up to FLUSH_ROWS rows, then in f64.
        let mut lanes = [[T::zero(); LANES]; 4];
        let mut lanes_f64 = [[0.0f64; LANES]; 4];
        let mut rows = 0;
        let reach = ctx.reach(r_c.f64());
        for dy in -reach..=reach {
            let Some(((lo, hi), interior)) = ctx.row(r_c.f64(), dy) else {
                continue;
            };
            let row = (xi as isize + dy * src.stride as isize) as usize;
            match interior {
                None => ctx.ring_sums(row, dy, (lo, hi), rc, &mut lanes),
                Some((ia, ib)) => {
                    ctx.ring_sums(row, dy, (lo, ia - 1), rc, &mut lanes);
                    ctx.ring_sums(row, dy, (ib + 1, hi), rc, &mut lanes);
                    let base = (y as isize + src.pad as isize + dy) as usize * s1;
                    let cx = (x + src.pad) as isize;
                    let (ca, cb) = ((cx + ia) as usize, (cx + ib) as usize);
                    sums[0] += prefix[base + cb + 1] - prefix[base + ca];
                    sums[1] += (ib - ia + 1) as f64;
                }
            }
            rows += 1;
            if rows == FLUSH_ROWS {
                flush(&mut lanes, &mut lanes_f64);
                rows = 0;
            }
        }
        // The rings' lanes, in lane order.
        flush(&mut lanes, &mut lanes_f64);
        for c in 0..4 {
            for l in 0..LANES {
                sums[c] += lanes_f64[c][l];
            }
        }
        let [a_sum, weight, da_sum, d_weight] = sums;
        out.push(DiscCoverage {
            alpha_sum: T::c(a_sum),
            weight: T::c(weight),
            d_alpha_sum: T::c(da_sum),
            d_weight: T::c(d_weight),
        });
        x += 1;
    }
    out
}

/// Whether the [`LANES`] receivers share one coverage radius `r_c` (bitwise).
#[inline(always)]
fn equal_radii<T: Real>(rc: &[(T, T)]) -> bool {
    let r0 = rc[0].0;
    let mut same = true;
    for &(r, _) in rc {
        same &= r == r0;
    }
    same
}

/// [`disc_sums`] of the [`LANES`] receivers `x0 ..` of image row `y`, which share one
/// coverage radius `r_c` and so one disc: the same taps at the same offsets, lane `l` the
/// receiver `x0 + l`. Each ring step `S` (and `S'`) is evaluated once per offset for the
/// whole group and multiplied into [`LANES`] alphas read as one vector (the alphas under
/// offset `dx` of receivers `x0 ..= x0 + 7` are adjacent); `Z` and `sum S'` are the same
/// for every receiver of the group. The same terms as receiver by receiver, summed in
/// another fixed order (the ring's per row, as [`FLUSH_ROWS`] rows there), and `S' dr` as
/// `(sum S' a) dr`.
#[inline(always)]
fn group_sums<T: Real>(
    ctx: &DiscCtx<'_, T>,
    prefix: &[f64],
    (x0, y): (usize, usize),
    out: &mut Vec<DiscCoverage<T>>,
) {
    let src = ctx.src;
    let s1 = src.stride + 1;
    let i0 = y * ctx.width + x0;
    let xi = src.index(x0, y);
    let r_c = ctx.rc[i0].0;
    let e_r = ctx.factor(r_c);
    let step = src.step;
    // Per receiver: sum S a, sum S' a (f64 across rows; T within a row's ring).
    let (mut a_sum, mut da_sum) = ([0.0f64; LANES], [0.0f64; LANES]);
    // Shared: Z and sum S'.
    let (mut weight, mut d_weight) = (0.0f64, 0.0f64);
    let reach = ctx.reach(r_c.f64());
    for dy in -reach..=reach {
        let Some(((lo, hi), interior)) = ctx.row(r_c.f64(), dy) else {
            continue;
        };
        let row = (xi as isize + dy * src.stride as isize) as usize;
        let (mut la, mut lda) = ([T::zero(); LANES], [T::zero(); LANES]);
        let (mut ls, mut lds) = (T::zero(), T::zero());
        let parts = match interior {
            None => [(lo, hi), (1, 0)],
            Some((ia, ib)) => {
                let base = (y as isize + src.pad as isize + dy) as usize * s1;
                let cx = (x0 + src.pad) as isize;
                let (ca, cb) = ((cx + ia) as usize, (cx + ib) as usize);
                let (pa, pb) = (&prefix[base + ca..], &prefix[base + cb + 1..]);
                for l in 0..LANES {
                    a_sum[l] += pb[l] - pa[l];
                }
                weight += (ib - ia + 1) as f64;
                [(lo, ia - 1), (ib + 1, hi)]
            }
        };
        for (a, b) in parts {
            let mut dx0 = a;
            while dx0 <= b {
                let n = (b - dx0 + 1).min(LANES as isize) as usize;
                let s = ctx.steps((dx0, dy), n, r_c, e_r);
                for k in 0..n {
                    let sd = model::scatter_step_derivative(step, s[k]);
                    let at = (row as isize + dx0) as usize + k;
                    let al: &[T; LANES] = src.alpha[at..at + LANES].try_into().expect("LANES");
                    for l in 0..LANES {
                        la[l] = la[l] + s[k] * al[l];
                        lda[l] = lda[l] + sd * al[l];
                    }
                    ls = ls + s[k];
                    lds = lds + sd;
                }
                dx0 += LANES as isize;
            }
        }
        for l in 0..LANES {
            a_sum[l] += la[l].f64();
            da_sum[l] += lda[l].f64();
        }
        weight += ls.f64();
        d_weight += lds.f64();
    }
    for l in 0..LANES {
        let dr = ctx.rc[i0 + l].1;
        out.push(DiscCoverage {
            alpha_sum: T::c(a_sum[l]),
            weight: T::c(weight),
            d_alpha_sum: T::c(da_sum[l]) * dr,
            d_weight: T::c(d_weight) * dr,
        });
    }
}

/// Pass C of the [`LANES`] receivers `qx ..` of image row `qy`, which share one coverage
/// radius (as [`group_sums`]), into the band's source rows `y0 .. y1` (`out`, `diff` as in
/// [`coverage_band`]): each ring step once per offset for the group, multiplied into the
/// [`LANES`] shares and added to the adjacent entries under it; the interiors' spans as
/// [`LANES`] pairs of writes into the difference array. The same terms (`share S` rounded
/// to `T`, then added in f64) as receiver by receiver, added in another fixed order.
#[inline(always)]
fn group_scatter<T: Real>(
    ctx: &DiscCtx<'_, T>,
    sh: &[T],
    (qx, qy): (usize, usize),
    (y0, y1, out, diff): (usize, usize, &mut [f64], &mut [f64]),
) {
    let src = ctx.src;
    let stride = src.stride;
    let mut any = false;
    for l in 0..LANES {
        any |= sh[l] != T::zero();
    }
    if !any {
        return;
    }
    let r_c = ctx.rc[qy * ctx.width + qx].0;
    let e_r = ctx.factor(r_c);
    let (cy, cx) = (qy + src.pad, qx + src.pad);
    let (dy0, dy1) = (y0 as isize - cy as isize, y1 as isize - 1 - cy as isize);
    let reach = ctx.reach(r_c.f64());
    for dy in (-reach).max(dy0)..=reach.min(dy1) {
        let Some(((lo, hi), interior)) = ctx.row(r_c.f64(), dy) else {
            continue;
        };
        let r = (cy as isize + dy) as usize - y0;
        let parts = match interior {
            None => [(lo, hi), (1, 0)],
            Some((ia, ib)) => {
                let d = &mut diff[r * (stride + 1)..];
                let (a, b) = ((cx as isize + ia) as usize, (cx as isize + ib + 1) as usize);
                for l in 0..LANES {
                    d[a + l] += sh[l].f64();
                }
                for l in 0..LANES {
                    d[b + l] -= sh[l].f64();
                }
                [(lo, ia - 1), (ib + 1, hi)]
            }
        };
        let out_row = &mut out[r * stride..(r + 1) * stride + LANES];
        for (a, b) in parts {
            let mut dx0 = a;
            while dx0 <= b {
                let n = (b - dx0 + 1).min(LANES as isize) as usize;
                let s = ctx.steps((dx0, dy), n, r_c, e_r);
                for k in 0..n {
                    let at = (cx as isize + dx0) as usize + k;
                    let o: &mut [f64; LANES] =
                        (&mut out_row[at..at + LANES]).try_into().expect("LANES");
                    for l in 0..LANES {
                        o[l] += (sh[l] * s[k]).f64();
                    }
                }
                dx0 += LANES as isize;
            }
        }
    }
}

/// Pass C for the soft disc: per image pixel, `sum_x share(x) S(r_c(x), y)` over the
/// receivers whose disc holds it, folded from the padded plane by `fold`.
pub(super) fn pass_coverage<T: Real>(ctx: &DiscCtx<'_, T>, share: &[T]) -> Vec<f64> {
    let rows = ctx.src.rows;
    let bands: Vec<Vec<f64>> = (0..rows)
        .step_by(BAND)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y0| coverage_band_dispatch(ctx, share, y0))
        .collect();
    bands.into_iter().flatten().collect()
}

avx2_dispatch!(
    coverage_band_dispatch,
    coverage_band_avx2,
    coverage_band,
    (ctx: &DiscCtx<'_, T>, share: &[T], y0: usize) -> Vec<f64>
);

/// [`pass_coverage`] over the padded source rows `y0 .. y0 + BAND`.
#[inline(always)]
fn coverage_band<T: Real>(ctx: &DiscCtx<'_, T>, share: &[T], y0: usize) -> Vec<f64> {
    let src = ctx.src;
    let (stride, pad, rows) = (src.stride, src.pad, src.rows);
    let (w, h) = (ctx.width, ctx.height);
    let big_r = ctx.table.big_r;
    let y1 = (y0 + BAND).min(rows);
    // Each source row followed by LANES entries for the rings' masked lanes (which add 0).
    let mut out = vec![0.0f64; (y1 - y0) * stride + LANES];
    let mut diff = vec![0.0f64; (y1 - y0) * (stride + 1)];
    // Receivers (image rows) whose window reaches source rows y0 .. y1.
    let q0 = (y0 as isize - pad as isize - big_r as isize).max(0) as usize;
    let q1 = ((y1 + big_r) as isize - pad as isize).clamp(0, h as isize) as usize;
    for qy in q0..q1 {
        let mut next = 0;
        for qx in 0..w {
            if qx < next {
                continue;
            }
            let i = qy * w + qx;
            if qx + LANES <= w && equal_radii(&ctx.rc[i..i + LANES]) {
                let band = (y0, y1, &mut out[..], &mut diff[..]);
                group_scatter(ctx, &share[i..i + LANES], (qx, qy), band);
                next = qx + LANES;
                continue;
            }
            let sh = share[i];
            if sh == T::zero() {
                continue;
            }
            let (r_c, _) = ctx.rc[i];
            let e_r = ctx.factor(r_c);
            let shf = sh.f64();
            let (cy, cx) = (qy + pad, qx + pad);
            let (dy0, dy1) = (y0 as isize - cy as isize, y1 as isize - 1 - cy as isize);
            let reach = ctx.reach(r_c.f64());
            for dy in (-reach).max(dy0)..=reach.min(dy1) {
                let Some(((lo, hi), interior)) = ctx.row(r_c.f64(), dy) else {
                    continue;
                };
                let r = (cy as isize + dy) as usize - y0;
                let out_row = &mut out[r * stride..(r + 1) * stride + LANES];
                let tap = (cx, dy, r_c, e_r, sh);
                match interior {
                    None => ctx.ring_scatter(out_row, tap, (lo, hi)),
                    Some((ia, ib)) => {
                        ctx.ring_scatter(out_row, tap, (lo, ia - 1));
                        ctx.ring_scatter(out_row, tap, (ib + 1, hi));
                        let d = &mut diff[r * (stride + 1)..];
                        d[(cx as isize + ia) as usize] += shf;
                        d[(cx as isize + ib + 1) as usize] -= shf;
                    }
                }
            }
        }
    }
    for r in 0..y1 - y0 {
        let mut run = 0.0;
        for px in 0..stride {
            run += diff[r * (stride + 1) + px];
            out[r * stride + px] += run;
        }
    }
    out.truncate((y1 - y0) * stride);
    out
}
