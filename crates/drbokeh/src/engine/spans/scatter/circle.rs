//! The circle's two-phase sweep of one disc row `dy = +-ady` of a source row: the ring
//! profile of every distinct radius is evaluated first, then every source adds its
//! interior and ring (runs of equal radius in adjacent columns as whole vectors,
//! `runs.rs`).

use super::runs::{add_run, RunScratch, RUN_MIN};
use super::COMPONENTS;
use super::{chunk_runs, in_run, interior, ring_add, Acc, BandLayer, Coefficients, Source};
use crate::engine::spans::geometry::{floor_sqrt, ring_steps, DiscRow, LANES};
use crate::Real;

/// The ring profiles of one disc row of a source row's sources (the circle's two-phase
/// sweep): the steps of every distinct radius are evaluated first (independent chunks,
/// which the processor overlaps), then every source adds its row.
#[derive(Default)]
pub(super) struct Profiles<T> {
    /// Steps, each profile's run of chunks followed by [`LANES`] zeros.
    pub(super) values: Vec<T>,
    /// The evaluated profiles.
    pub(super) rows: Vec<Profile>,
    /// The source row's maximal runs of sources of equal radius in adjacent columns,
    /// `(first, end)` (they share a profile on every disc row).
    pub(super) segments: Vec<(usize, usize)>,
    /// Per segment: the index of its profile on this disc row, or [`NO_ROW`].
    pub(super) of_segment: Vec<u32>,
    /// The source row's weights `v` per component (`[component][source]`) ...
    pub(super) v_planes: [Vec<T>; COMPONENTS],
    /// ... and in f64, `[source][component]`.
    pub(super) v64: Vec<f64>,
    /// Working memory of [`add_run`].
    pub(super) scratch: RunScratch<T>,
}

/// [`Profiles::of_segment`] of sources without taps on this disc row.
const NO_ROW: u32 = u32::MAX;

/// One disc row's intervals and where its steps are.
#[derive(Clone, Copy)]
pub(super) struct Profile {
    pub(super) disc: DiscRow,
    /// The offset of `|dx| = 0` in the values (`dx = 0` for rows without an interior,
    /// whose profile is stored mirrored).
    pub(super) base: isize,
    /// For rows with an interior: the offset of `dx = 0` in the reversed left ring, whose
    /// lane `dx` (negative) is at `left + dx`.
    pub(super) left: isize,
    /// `Some(k0)` for the common row: an interior `-(k0 - 1) ..= k0 - 1` and a ring of at
    /// most one chunk on each side (its profile then holds zeros beyond the ring's end).
    pub(super) one_chunk: Option<isize>,
}

/// Rows `dy = +-ady` (`rows`: their sub-band rows, where in the sub-band) of every source
/// of a source row (a circle): intervals and ring profile computed once for both rows.
#[inline(always)]
pub(super) fn scatter_rows_circle<T: Real, const SHARP: bool, const FOCUS: bool>(
    ctx: &BandLayer<'_, T>,
    (sources, caches): (&[Source<T>], &mut [Option<Coefficients<T>>]),
    ady: isize,
    rows: [Option<usize>; 2],
    acc: &mut Acc<T>,
    profiles: &mut Profiles<T>,
) -> u64 {
    let Some(hw) = ctx.table.window_half_width(ady) else {
        return 0;
    };
    let lanes = LANES as isize;
    // Phase 1: intervals and steps. The profile S(r - g(dx, ady)) is evaluated at ring
    // columns |dx| = k0 ..= outer_hi (the circle is symmetric in dx), followed by zeros so
    // that the outward extension of the chunks adds nothing.
    profiles.rows.clear();
    profiles.of_segment.clear();
    profiles.of_segment.resize(profiles.segments.len(), NO_ROW);
    // At most 3 n + 2 LANES values per source (a mirrored run of n = R + 1 steps).
    let need = sources.len() * (3 * (ctx.table.big_r + 1) + 3 * LANES);
    if profiles.values.len() < need {
        profiles.values.resize(need, T::zero());
    }
    let values = &mut profiles.values;
    let mut next = 0usize;
    // The previous source's half-widths guess the next one's.
    let mut guess = (0, 0);
    // The last source whose profile was evaluated: its radius and profile. A source with
    // the same radius has the same row intervals and profile (they depend on `r`, `ady`
    // and the window only), so it shares that profile: exact, and the common case in
    // layers of constant (or row-constant) disparity.
    let mut last: Option<(T, u32)> = None;
    for (g, &(i, _)) in profiles.segments.iter().enumerate() {
        let src = &sources[i];
        if src.reach < ady {
            continue;
        }
        if let Some((r, p)) = last {
            if src.r == r {
                profiles.of_segment[g] = p;
                continue;
            }
        }
        let Some(disc) = circle_row(src, ady, hw, &mut guess) else {
            continue;
        };
        let p = profiles.rows.len() as u32;
        last = Some((src.r, p));
        profiles.of_segment[g] = p;
        let k0 = disc.interior.map_or(0, |(_, hi)| hi + 1);
        let outer_hi = match (disc.interior, disc.left, disc.right) {
            (Some(_), _, Some((_, hi))) | (None, Some((_, hi)), _) => hi,
            _ => k0 - 1,
        };
        let n = (outer_hi + 1 - k0).max(0) as usize;
        let one_chunk = disc.interior.is_some()
            && disc.right.is_some()
            && outer_hi - k0 < lanes
            && disc.left == Some((-outer_hi, -k0));
        if one_chunk {
            // The common row: [S(k0) .. S(outer_hi), zeros | zeros | the same reversed],
            // the reversed chunk (the left ring) built in registers.
            let s = circle_steps::<T, SHARP>(ctx, src, ady, k0);
            let s: [T; LANES] = std::array::from_fn(|l| if l < n { s[l] } else { T::zero() });
            let rev: [T; LANES] = std::array::from_fn(|l| s[LANES - 1 - l]);
            values[next..next + LANES].copy_from_slice(&s);
            values[next + LANES..next + 2 * LANES].fill(T::zero());
            values[next + 2 * LANES..next + 3 * LANES].copy_from_slice(&rev);
            // Lanes |dx| = k0 .. k0 + LANES - 1 of the reversed chunk at `left - |dx|`;
            // up to LANES beyond it, zeros.
            profiles.rows.push(Profile {
                disc,
                base: next as isize - k0,
                left: (next + 2 * LANES + LANES - 1) as isize + k0,
                one_chunk: Some(k0),
            });
            next += 3 * LANES;
            continue;
        }
        let mut k = k0;
        while k <= outer_hi {
            let s = circle_steps::<T, SHARP>(ctx, src, ady, k);
            let at = next + (k - k0) as usize;
            values[at..at + LANES].copy_from_slice(&s);
            k += lanes;
        }
        // Zeros from outer_hi + 1 on (over the last chunk's excess).
        values[next + n..next + n + LANES].fill(T::zero());
        if disc.interior.is_none() {
            // A run across dx = 0: mirror into [zeros | S(n-1) .. S(1) | S(0) .. | zeros]
            // after the right half, with dx = 0 at `centre`.
            let centre = next + n + LANES + n - 1;
            for kk in 0..n + LANES {
                values[centre + kk] = values[next + kk];
            }
            for kk in 1..n {
                values[centre - kk] = values[next + kk];
            }
            profiles.rows.push(Profile {
                disc,
                base: centre as isize,
                left: 0,
                one_chunk: None,
            });
            next = centre + n + LANES;
        } else {
            // The left ring reversed after the right one, [zeros | S(outer_hi) .. S(k0)],
            // so that a left chunk is one contiguous load: lanes of a chunk from
            // dx0 <= -k0 - (LANES - 1) hold |dx| = -(dx0 + l), at `left + dx0 + l`.
            let rev = next + n + LANES;
            for q in 0..n + LANES {
                values[rev + q] = values[next + n + LANES - 1 - q];
            }
            profiles.rows.push(Profile {
                disc,
                base: next as isize - k0,
                left: (rev + n + LANES - 1) as isize + k0,
                one_chunk: None,
            });
            next = rev + n + LANES;
        }
    }
    // Phase 2: interiors and ring chunks; a run of at least RUN_MIN sources in adjacent
    // columns (sharing the profile) as whole vectors (`runs.rs`), others source by source.
    let values = &profiles.values;
    let mut work = 0;
    for (&(i, j), &p) in profiles.segments.iter().zip(&profiles.of_segment) {
        if p == NO_ROW {
            continue;
        }
        let prof = &profiles.rows[p as usize];
        if !FOCUS && j - i >= RUN_MIN {
            work += add_run(
                ctx,
                (sources, &mut *caches),
                (i, j),
                (prof, values),
                (&profiles.v_planes, &profiles.v64),
                rows,
                acc,
                &mut profiles.scratch,
            );
            continue;
        }
        for k in i..j {
            work +=
                add_general::<T, FOCUS>(ctx, &sources[k], prof, values, rows, acc, &mut caches[k]);
        }
    }
    work
}

/// A source's disc row `prof` into `rows`: its interior span and its ring chunk by chunk
/// (any row of a circle, and in-focus receivers).
#[inline(always)]
fn add_general<T: Real, const FOCUS: bool>(
    ctx: &BandLayer<'_, T>,
    src: &Source<T>,
    prof: &Profile,
    values: &[T],
    rows: [Option<usize>; 2],
    acc: &mut Acc<T>,
    cache: &mut Option<Coefficients<T>>,
) -> u64 {
    let (disc, lanes, w) = (prof.disc, LANES as isize, ctx.width as isize);
    let mut work = 0;
    if let Some(run) = disc.interior {
        for row in rows.into_iter().flatten() {
            work += interior::<T, FOCUS>(ctx, src, run, row, acc, cache);
        }
    }
    if let Some(k0) = prof.one_chunk {
        if src.xs >= k0 && src.xs + k0 <= w {
            let at = (prof.base + k0) as usize;
            let right: [T; LANES] = values[at..at + LANES].try_into().expect("LANES");
            let at = (prof.left - k0 - (lanes - 1)) as usize;
            let left: [T; LANES] = values[at..at + LANES].try_into().expect("LANES");
            for row in rows.into_iter().flatten() {
                ring_add::<T, FOCUS>(ctx, src, row, src.xs + k0, right, acc, cache);
                ring_add::<T, FOCUS>(ctx, src, row, src.xs - k0 - (lanes - 1), left, acc, cache);
                work += 2 * LANES as u64;
            }
            return work;
        }
    }
    let runs = chunk_runs(&disc, src.xs, w);
    for row in rows.into_iter().flatten() {
        for run in runs {
            let mut start = run.0;
            while in_run(start, run) {
                let dx0 = start - src.xs;
                let at = if dx0 < 0 && disc.interior.is_some() {
                    // Left of the interior (dx0 + LANES - 1 < 0): |dx| = -(dx0 + l), from
                    // the reversed copy.
                    prof.left + dx0
                } else {
                    prof.base + dx0
                } as usize;
                let s: [T; LANES] = values[at..at + LANES].try_into().expect("LANES");
                ring_add::<T, FOCUS>(ctx, src, row, start, s, acc, cache);
                work += LANES as u64;
                start += run.2;
            }
        }
    }
    work
}

/// A circle's disc row `ady` ([`disc_row`] for [`Shape::Circle`], the same intervals),
/// with the half-widths found from `guess` (the previous source's, updated).
#[inline(always)]
pub(super) fn circle_row<T: Real>(
    src: &Source<T>,
    ady: isize,
    hw: usize,
    guess: &mut (isize, isize),
) -> Option<DiscRow> {
    let (hi, ho) = circle_half_widths(src, ady, hw as isize, guess)?;
    Some(match hi {
        None => DiscRow {
            interior: None,
            left: Some((-ho, ho)),
            right: None,
        },
        Some(hi) => DiscRow {
            interior: Some((-hi, hi)),
            left: (-ho < -hi).then_some((-ho, -hi - 1)),
            right: (hi < ho).then_some((hi + 1, ho)),
        },
    })
}

/// The half-widths of a circle's disc row `ady`: `(hi, ho)`, the interior `|dx| <= hi`
/// (`None`: no interior on this row) and the ring's outer end `ho`, both clipped to the
/// window half-width `hw`, found from `guess` (the previous source's, updated); `None`
/// without taps on this row. [`circle_row`] and the block path's rows share it.
#[inline(always)]
pub(super) fn circle_half_widths<T: Real>(
    src: &Source<T>,
    ady: isize,
    hw: isize,
    guess: &mut (isize, isize),
) -> Option<(Option<isize>, isize)> {
    let dy2 = (ady * ady) as f64;
    let q_out = src.outer_sq - dy2;
    if src.outer_sq < 0.0 || q_out < 0.0 {
        return None;
    }
    guess.1 = floor_sqrt(q_out, guess.1);
    let ho = guess.1.min(hw);
    let q_in = src.inner_sq - dy2;
    let hi = if src.inner_sq >= 0.0 && q_in >= 0.0 {
        guess.0 = floor_sqrt(q_in, guess.0);
        Some(guess.0.min(hw))
    } else {
        None
    };
    Some((hi, ho))
}

/// The ring steps of a circle's disc row `ady` at columns `dx0 ..` (`dx0 >= 0`).
#[inline(always)]
fn circle_steps<T: Real, const SHARP: bool>(
    ctx: &BandLayer<'_, T>,
    src: &Source<T>,
    ady: isize,
    dx0: isize,
) -> [T; LANES] {
    match ctx.exp {
        Some(e) => e.steps(src.e_r, ady, dx0),
        None => ring_steps::<T, SHARP>(ctx.table, src.r, ady, dx0),
    }
}
