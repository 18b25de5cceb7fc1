//! Blocks of up to [`LANES`] sources in adjacent columns of distinct radii (a circle, no
//! focus rows, the ring steps by [`ExpTable`]), one disc row at a time, vectorised across
//! the sources instead of across the taps: where radii vary continuously (no two sources
//! share a profile, the GEGL workload), a ring column `|dx| = k` of the whole block is one
//! vector of steps (one per source), added at receivers `x0 + l +- k` of both rows `+-dy`.
//!
//! Per block and disc row, the interior is the smallest of its sources' interiors
//! (`|dx| <= hi_min`, a span per source), and the ring runs from `hi_min + 1` to the
//! largest outer end; a lane beyond its own source's outer end (`r + u_out`) is 0, so
//! every source keeps exactly the taps of [`super::circle::circle_row`]'s ring and tail cut, and
//! the columns `hi_min < |dx| <= hi` of a source with a larger interior are evaluated
//! exactly instead of taken as 1 (within the interior's bound, `1 - S <= 1e-5`, of the
//! source-by-source sums). Each tap's step is [`ExpTable::steps`]'s value; the sums are
//! the same terms in another fixed order.

use super::circle::circle_half_widths;
use super::{interior, Acc, BandLayer, Source, COMPONENTS};
use crate::engine::spans::geometry::{ExpTable, LANES, MARGIN};
use crate::Real;

/// A block's extra ring columns allowed beyond its widest source's own ring (a block ends
/// where a source would widen it further, so that a depth edge does not make a block's
/// ring as wide as its largest disc).
const SPREAD_SLACK: isize = 3;

/// One source's disc row `ady`: `(hi, ho)`, its interior `|dx| <= hi` (`hi = -1`: none)
/// and its ring's outer end `ho` (both clipped to the window half-width `hw`), or `None`
/// without taps on this row or beyond the source's reach ([`circle_half_widths`], the
/// intervals of [`super::circle::circle_row`]).
#[inline(always)]
fn row_ends<T: Real>(
    src: &Source<T>,
    ady: isize,
    hw: isize,
    guess: &mut (isize, isize),
) -> Option<(isize, isize)> {
    if src.reach < ady {
        return None;
    }
    match circle_half_widths(src, ady, hw, guess)? {
        (Some(hi), ho) => Some((hi, ho)),
        (None, ho) => Some((-1, ho)),
    }
}

/// Adds the disc rows `+-ady` (`rows`: their sub-band rows) of every source of a source
/// row (`v64`: their weights in f64, `[source][component]`), block by block. Returns the work done (ring lanes plus span writes).
#[inline(always)]
pub(super) fn add_blocks<T: Real>(
    ctx: &BandLayer<'_, T>,
    exp: &ExpTable,
    (sources, v64): (&[Source<T>], &[f64]),
    ady: isize,
    rows: [Option<usize>; 2],
    acc: &mut Acc<T>,
) -> u64 {
    let Some(hw) = ctx.table.window_half_width(ady) else {
        return 0;
    };
    let (hw, w) = (hw as isize, ctx.width as isize);
    let len = acc.ring_len();
    let mut work = 0;
    let mut guess = (0isize, 0isize);
    let mut none = None;
    let mut i = 0;
    // The first source of the next block, its ends already found.
    let mut carried: Option<Option<(isize, isize)>> = None;
    while i < sources.len() {
        let x0 = sources[i].xs;
        let mut e_r = [0.0f64; LANES];
        let mut ho = [T::c(-1.0); LANES];
        let mut v = [[T::zero(); LANES]; COMPONENTS];
        let (mut hi_min, mut ho_max, mut widest) = (isize::MAX, -1isize, 0isize);
        let mut j = i;
        let mut live = 0;
        while j < sources.len() && j - i < LANES && sources[j].xs == x0 + (j - i) as isize {
            let src = &sources[j];
            let ends = match carried.take() {
                Some(ends) => ends,
                None => row_ends(src, ady, hw, &mut guess),
            };
            if let Some((hi, o)) = ends {
                let (lo2, hi2, wide2) = (hi_min.min(hi), ho_max.max(o), widest.max(o - hi));
                if j > i && hi2 - lo2 > wide2 + SPREAD_SLACK {
                    carried = Some(ends);
                    break;
                }
                (hi_min, ho_max, widest) = (lo2, hi2, wide2);
                live += 1;
                let l = j - i;
                e_r[l] = src.e_r;
                ho[l] = T::c(o as f64);
                for c in 0..COMPONENTS {
                    v[c][l] = src.v[c];
                }
            }
            j += 1;
        }
        let block = &sources[i..j];
        let i0 = i;
        i = j;
        if ho_max < 0 {
            continue;
        }
        let n = block.len();
        let (xa, xb1) = (x0 - hi_min, x0 + hi_min + 1);
        if hi_min >= 0 && live == n && xa >= 0 && xb1 + n as isize - 1 <= w {
            // Every source's span unclipped: source l adds its weights at xa + l and
            // subtracts them at xb1 + l, as two contiguous vector passes per row.
            let v = &v64[i0 * COMPONENTS..(i0 + n) * COMPONENTS];
            let (a, b) = (xa as usize * COMPONENTS, xb1 as usize * COMPONENTS);
            for row in rows.into_iter().flatten() {
                let d = &mut acc.diff[row * (acc.width + 1) * COMPONENTS..];
                for (o, v) in d[a..a + v.len()].iter_mut().zip(v) {
                    *o += *v;
                }
                for (o, v) in d[b..b + v.len()].iter_mut().zip(v) {
                    *o -= *v;
                }
                work += 2 * n as u64;
            }
        } else if hi_min >= 0 {
            for (l, src) in block.iter().enumerate() {
                if ho[l] >= T::zero() {
                    for row in rows.into_iter().flatten() {
                        work +=
                            interior::<T, false>(ctx, src, (-hi_min, hi_min), row, acc, &mut none);
                    }
                }
            }
        }
        for k in hi_min + 1..=ho_max {
            let f = exp.factor_at(ady, k);
            if f == 0.0 {
                continue;
            }
            // 1 where k <= ho (integers), else 0, branch-free.
            let next = T::c((k - 1) as f64);
            let mut keep = [T::zero(); LANES];
            for l in 0..LANES {
                keep[l] = (ho[l] - next).max(T::zero()).min(T::one());
            }
            let s = exp.steps_across::<T>(f, &e_r, &keep);
            for row in rows.into_iter().flatten() {
                let base = row * COMPONENTS * len;
                add_chunk(&mut acc.ring, (base, len), x0 + k, w, &s, &v);
                if k > 0 {
                    add_chunk(&mut acc.ring, (base, len), x0 - k, w, &s, &v);
                }
                work += 2 * LANES as u64;
            }
        }
    }
    work
}

/// Adds `s v` (per lane, per component) at receivers `start .. start + LANES` of the
/// ring row at `base` (component stride `len`), unless all of them are outside the image.
#[inline(always)]
fn add_chunk<T: Real>(
    ring: &mut [T],
    (base, len): (usize, usize),
    start: isize,
    w: isize,
    s: &[T; LANES],
    v: &[[T; LANES]; COMPONENTS],
) {
    if start + (LANES as isize) <= 0 || start >= w {
        return;
    }
    // start >= 1 - LANES >= -MARGIN, start + LANES <= w + LANES - 1 < w + MARGIN.
    let at = base + (start + MARGIN as isize) as usize;
    for c in 0..COMPONENTS {
        let out: &mut [T; LANES] = (&mut ring[at + c * len..at + c * len + LANES])
            .try_into()
            .expect("LANES");
        for l in 0..LANES {
            out[l] = out[l] + s[l] * v[c][l];
        }
    }
}
