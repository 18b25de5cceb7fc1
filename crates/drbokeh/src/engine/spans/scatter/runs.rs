//! Runs of sources in adjacent columns sharing one disc-row profile (equal radius, the
//! common case in layers of constant or row-constant disparity), added as whole vectors:
//! the interior spans as shifted copies of the run's weights into the difference arrays,
//! and the ring as one convolution of the weights with the profile's exact taps, computed
//! once for the disc rows `+-dy`. The same terms as source by source, summed in another
//! fixed order.

use super::circle::Profile;
use super::{interior, Acc, BandLayer, Coefficients, Source, COMPONENTS};
use crate::engine::spans::geometry::{LANES, MARGIN};
use crate::Real;

/// Working memory of [`add_run`], kept across calls.
#[derive(Default)]
pub(super) struct RunScratch<T> {
    /// The profile's ring taps `(dx, S)` for `dx > 0` (each also at `-dx`: a circle's
    /// row is symmetric).
    taps: Vec<(isize, T)>,
    /// The run's weights per component, between zeros ([`add_run`]).
    padded: Vec<T>,
}

/// The shortest run of sources added as whole vectors ([`super::circle::scatter_rows_circle`]).
pub(super) const RUN_MIN: usize = 4;

/// The interior spans of a run of `v.len() / COMPONENTS` sources in adjacent columns
/// into the difference arrays `outs` (one per row): each source `k` of the run adds its
/// `v` at `xa + k` and subtracts it at `xb1 + k`. Where the two overlap, each column takes
/// the difference of the two weights once (computed once for both rows).
#[inline(always)]
fn run_span_write(outs: [Option<&mut [f64]>; 2], xa: usize, xb1: usize, v: &[f64]) {
    let (a, b) = (xa * COMPONENTS, xb1 * COMPONENTS);
    match outs {
        [Some(d1), Some(d2)] => span_pass([d1, d2], a, b, v),
        [Some(d), None] | [None, Some(d)] => span_pass([d], a, b, v),
        [None, None] => {}
    }
}

/// [`run_span_write`] into `N` rows, `a < b` the flat offsets of `xa` and `xb1`.
#[inline(always)]
fn span_pass<const N: usize>(mut outs: [&mut [f64]; N], a: usize, b: usize, v: &[f64]) {
    let n = v.len();
    let mid = b.min(a + n);
    for o in outs.iter_mut() {
        for (d, v) in o[a..mid].iter_mut().zip(&v[..mid - a]) {
            *d += *v;
        }
    }
    if b < a + n {
        // Columns b .. a + n: + v[x - a] - v[x - b]; then a + n .. b + n: - v[x - b].
        let len = a + n - b;
        let (plus, minus) = (&v[b - a..], &v[..len]);
        let mut seg = outs.each_mut().map(|o| &mut o[b..b + len]);
        for x in 0..len {
            let t = plus[x] - minus[x];
            for o in seg.iter_mut() {
                o[x] += t;
            }
        }
        for o in outs.iter_mut() {
            for (d, v) in o[a + n..b + n].iter_mut().zip(&v[len..]) {
                *d -= *v;
            }
        }
    } else {
        for o in outs.iter_mut() {
            for (d, v) in o[b..b + n].iter_mut().zip(v) {
                *d -= *v;
            }
        }
    }
}

/// A run of sources `i .. j` in adjacent columns sharing one disc-row profile `prof`
/// (a circle, no focus rows) into `rows`: the interior spans as whole-vector writes
/// (those the image does not clip; the others source by source), and the ring as one
/// convolution of the run's weights with the profile's taps, computed once for both rows
/// and clipped to the image. The taps are the ring's exactly (`r + u_out` and in), not
/// padded to chunks. Returns the work done.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn add_run<T: Real>(
    ctx: &BandLayer<'_, T>,
    (sources, caches): (&[Source<T>], &mut [Option<Coefficients<T>>]),
    (i, j): (usize, usize),
    (prof, values): (&Profile, &[T]),
    (v_planes, v64): (&[Vec<T>; COMPONENTS], &[f64]),
    rows: [Option<usize>; 2],
    acc: &mut Acc<T>,
    scratch: &mut RunScratch<T>,
) -> u64 {
    let w = ctx.width as isize;
    let (m, xs0, disc) = (j - i, sources[i].xs, prof.disc);
    let mut work = 0;
    if let Some((lo, hi)) = disc.interior {
        // Sources k whose span xs0 + k + (lo ..= hi) lies within the image: ka .. kb.
        let ka = (-lo - xs0).clamp(0, m as isize) as usize;
        let kb = (w - hi - xs0).clamp(ka as isize, m as isize) as usize;
        let d_len = (ctx.width + 1) * COMPONENTS;
        if kb > ka {
            let xa = (xs0 + ka as isize + lo) as usize;
            let xb1 = (xs0 + ka as isize + hi + 1) as usize;
            run_span_write(
                rows_mut(&mut acc.diff, d_len, rows),
                xa,
                xb1,
                &v64[(i + ka) * COMPONENTS..(i + kb) * COMPONENTS],
            );
            work += (2 * (kb - ka) * rows.iter().flatten().count()) as u64;
        }
        for row in rows.into_iter().flatten() {
            for k in (0..ka).chain(kb..m) {
                work += interior::<T, false>(
                    ctx,
                    &sources[i + k],
                    (lo, hi),
                    row,
                    acc,
                    &mut caches[i + k],
                );
            }
        }
    }
    // The ring: |dx| in k0 ..= e, S(|dx|) at `base + |dx|` (either layout of the profile).
    let k0 = disc.interior.map_or(0, |(_, hi)| hi + 1);
    let e = match (disc.interior, disc.left, disc.right) {
        (Some(_), _, Some((_, hi))) | (None, Some((_, hi)), _) => hi,
        _ => return work,
    };
    let centre = (k0 == 0).then(|| values[prof.base as usize]);
    scratch.taps.clear();
    scratch
        .taps
        .extend((k0.max(1)..=e).map(|dx| (dx, values[(prof.base + dx) as usize])));
    // Receiver column xs0 - e + q takes sum_dx S(dx) v[q - e - dx], and v[k] is at
    // `2 e + k` of its padded plane; q in q0 .. q1 (within the image), in whole chunks.
    let eu = e as usize;
    let plane = m + 4 * eu + LANES;
    if scratch.padded.len() < COMPONENTS * plane {
        scratch.padded.resize(COMPONENTS * plane, T::zero());
    }
    for (c, v) in v_planes.iter().enumerate() {
        let out = &mut scratch.padded[c * plane..(c + 1) * plane];
        out[..2 * eu].fill(T::zero());
        out[2 * eu..2 * eu + m].copy_from_slice(&v[i..j]);
        out[2 * eu + m..].fill(T::zero());
    }
    let q0 = (e - xs0).max(0);
    let q1 = (m as isize + 2 * e).min(w + e - xs0);
    if q1 <= q0 {
        return work;
    }
    // Chunks run up to LANES - 1 columns past the image, into the margin.
    let nq = ((q1 - q0) as usize).div_ceil(LANES) * LANES;
    let x0 = (xs0 - e + q0) as usize + MARGIN;
    let len = acc.ring_len();
    run_conv(
        (centre, &scratch.taps),
        (&scratch.padded[..COMPONENTS * plane], plane),
        (q0 as usize + eu, nq),
        rows_mut(&mut acc.ring, COMPONENTS * len, rows),
        (x0, len),
    );
    let rows_written = rows.iter().flatten().count();
    let taps = 2 * scratch.taps.len() + usize::from(centre.is_some());
    work + (rows_written * taps * m) as u64
}

/// The rows `rows` of `data` (rows of `size` values), mutably.
fn rows_mut<T>(data: &mut [T], size: usize, rows: [Option<usize>; 2]) -> [Option<&mut [T]>; 2] {
    match rows {
        [Some(a), Some(b)] if a != b => {
            let (lo, hi) = data.split_at_mut(a.max(b) * size);
            let first = &mut lo[a.min(b) * size..(a.min(b) + 1) * size];
            let second = &mut hi[..size];
            if a < b {
                [Some(first), Some(second)]
            } else {
                [Some(second), Some(first)]
            }
        }
        [Some(a), _] | [None, Some(a)] => [Some(&mut data[a * size..(a + 1) * size]), None],
        [None, None] => [None, None],
    }
}

/// Adds `centre padded[c][at + q]` plus, over the taps `(dx, s)`,
/// `s (padded[c][at + q - dx] + padded[c][at + q + dx])` to `out[c][x0 + q]` of each of
/// `outs` (rows `[component][column]`, `len` columns each), for `q < nq` (a multiple of
/// [`LANES`]), chunk by chunk with the chunk's sums in registers.
#[inline(always)]
fn run_conv<T: Real>(
    (centre, taps): (Option<T>, &[(isize, T)]),
    (padded, plane): (&[T], usize),
    (at, nq): (usize, usize),
    mut outs: [Option<&mut [T]>; 2],
    (x0, len): (usize, usize),
) {
    let planes: [&[T]; COMPONENTS] = std::array::from_fn(|c| &padded[c * plane..(c + 1) * plane]);
    for q in (0..nq).step_by(LANES) {
        let mut sum = [[T::zero(); LANES]; COMPONENTS];
        if let Some(s) = centre {
            for c in 0..COMPONENTS {
                let v: &[T; LANES] = planes[c][at + q..at + q + LANES].try_into().expect("LANES");
                for l in 0..LANES {
                    sum[c][l] = s * v[l];
                }
            }
        }
        for &(dx, s) in taps {
            let (fa, fb) = (at + q - dx as usize, at + q + dx as usize);
            for c in 0..COMPONENTS {
                let a: &[T; LANES] = planes[c][fa..fa + LANES].try_into().expect("LANES");
                let b: &[T; LANES] = planes[c][fb..fb + LANES].try_into().expect("LANES");
                for l in 0..LANES {
                    sum[c][l] = sum[c][l] + s * (a[l] + b[l]);
                }
            }
        }
        for out in outs.iter_mut().flatten() {
            for (c, sum) in sum.iter().enumerate() {
                let at = c * len + x0 + q;
                let o: &mut [T; LANES] = (&mut out[at..at + LANES]).try_into().expect("LANES");
                for l in 0..LANES {
                    o[l] = o[l] + sum[l];
                }
            }
        }
    }
}
