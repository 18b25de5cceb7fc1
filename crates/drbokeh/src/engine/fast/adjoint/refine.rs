//! Before the fast adjoint's chain rule: the recorded sums of receivers whose weight sum is
//! of the order of the dropped tail, summed again over the whole window.
//!
//! Only sources with alpha != 0 add to `W`, `C` and the soft disc's `sum S a`: each window
//! row is cut into the runs of such sources ([`AlphaRuns`]; zero gaps of at most [`GAP`]
//! taps stay inside a run, where their terms are exactly 0), and each run is summed in
//! [`LANES`] lanes kept over the receiver's whole window and reduced once (the fast
//! engine's tap weight, the model's terms in their fast form: `exp` through
//! [`Real::exp_fast`], below 4e-7 relative error for f32, the standard `exp` for f64;
//! kernel apertures through the forward's [`gather_segment`]). The soft disc's `Z = sum S` over the whole window depends on `r_c` only
//! and is summed once per run of receivers with the same `r_c`. Every tap of the window
//! is summed: the result is the scalar whole-window sum (`tests::reference_row`) up to
//! float rounding (tested to 1e-12 relative in f64, 1e-5 in f32).

use crate::engine::fast::runs::{centre_scatter, gather_segment, lane_sum, LANES};
use crate::engine::fast::tiles::{source_block_max, WindowTables, FOCUS_WEIGHT_CUTOFF, ROW_BLOCK};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::model::ScatterStep;
use crate::model::{self, ApertureEval, Coverage, CoverageRadius, DiscCoverage, LayerAtPixel};
use crate::presets::RenderSettings;
use crate::Real;
use rayon::prelude::*;

/// Recorded weight sums below this are recomputed over the whole window before the
/// backward pass ([`refine_small_weights`]). The dropped tail weighs at most about 6e-6 per
/// unit alpha (`model::SCATTER_TAIL_PX`), so above this B is within 6e-4 of the exact
/// value even in the worst case (measured: ~1e-8 on the test scenes), and below it the
/// exact sums are cheap enough: such receivers lie in a layer's (nearly) empty regions.
pub(in crate::engine) const REFINE_WEIGHT_BELOW: f64 = 1e-2;

/// Zero-alpha gaps of at most this many taps inside a window row are summed with the run
/// around them (their terms are exactly 0) rather than starting a new run: a run's setup
/// and lane reduction cost about as much as this many taps.
const GAP: usize = 16;

/// The recorded sums of one layer, with `W` and `B` recomputed over every window tap
/// (no reach bound) where `W < REFINE_WEIGHT_BELOW` and some source with alpha > 0 lies in
/// the receiver's window (elsewhere `W = 0` exactly in both schedules).
pub(super) fn refine_small_weights<T: Real>(
    saved: &[LayerAtPixel<T>],
    src: &Planes<T>,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    settings: &RenderSettings,
) -> Vec<LayerAtPixel<T>> {
    let w = src.stride - 2 * tables.big_r;
    let ctx = RefineCtx::new(src, tables, aperture, settings);
    saved
        .par_chunks(w)
        .enumerate()
        .flat_map_iter(|(y, row)| refine_row_dispatch(&ctx, row, y))
        .collect()
}

/// Per padded source pixel, within its padded row: the column of the first source at or
/// after it with alpha != 0, and of the first with alpha == 0 (`stride` where there is
/// none). Columns as `u32`: a padded row is far shorter than 2^32 pixels.
struct AlphaRuns {
    next_alpha: Vec<u32>,
    next_zero: Vec<u32>,
}

impl AlphaRuns {
    fn new<T: Real>(src: &Planes<T>) -> Self {
        let stride = src.stride;
        let mut next_alpha = vec![0u32; src.alpha.len()];
        let mut next_zero = vec![0u32; src.alpha.len()];
        next_alpha
            .par_chunks_mut(stride)
            .zip(next_zero.par_chunks_mut(stride))
            .zip(src.alpha.par_chunks(stride))
            .for_each(|((na, nz), alpha)| {
                let (mut a, mut z) = (stride as u32, stride as u32);
                for c in (0..stride).rev() {
                    if alpha[c] == T::zero() {
                        z = c as u32;
                    } else {
                        a = c as u32;
                    }
                    na[c] = a;
                    nz[c] = z;
                }
            });
        AlphaRuns {
            next_alpha,
            next_zero,
        }
    }

    /// The first run of sources with alpha != 0 among columns `from..=last` of the padded
    /// row starting at index `row`: `(start, end)`, `end` exclusive, extended over zero gaps
    /// of at most [`GAP`] columns; `start > last` where there is none.
    #[inline(always)]
    fn next_run(&self, row: usize, from: usize, last: usize) -> (usize, usize) {
        let start = self.next_alpha[row + from] as usize;
        if start > last {
            return (start, start);
        }
        let mut end = self.next_zero[row + start] as usize;
        while end <= last {
            let resume = self.next_alpha[row + end] as usize;
            if resume > last || resume - end > GAP {
                break;
            }
            end = self.next_zero[row + resume] as usize;
        }
        (start, end.min(last + 1))
    }
}

/// What the rows of [`refine_small_weights`] share.
struct RefineCtx<'a, T> {
    src: &'a Planes<T>,
    tables: &'a WindowTables<T>,
    aperture: &'a ApertureEval<T>,
    /// [`source_block_max`] of the sources with alpha > 0.
    block_max: Vec<f64>,
    /// The runs of sources with alpha != 0.
    runs: AlphaRuns,
    /// The whole window's half-widths.
    widths: Vec<Option<usize>>,
    coverage: Coverage,
    coverage_radius: CoverageRadius,
    footprint: T,
}

impl<'a, T: Real> RefineCtx<'a, T> {
    fn new(
        src: &'a Planes<T>,
        tables: &'a WindowTables<T>,
        aperture: &'a ApertureEval<T>,
        settings: &RenderSettings,
    ) -> Self {
        let opts = settings.model();
        RefineCtx {
            src,
            tables,
            aperture,
            block_max: source_block_max(src, |i| src.alpha[i] > T::zero()),
            runs: AlphaRuns::new(src),
            widths: tables.half_widths(tables.big_r as f64),
            coverage: opts.coverage,
            coverage_radius: opts.coverage_radius,
            footprint: T::c(opts.footprint.px()),
        }
    }

    /// For image row `y`: per padded column `px`, how many of the columns `0..px` hold a
    /// source with alpha > 0 in the blocks of [`ROW_BLOCK`] rows that the windows of the
    /// row span; receiver `x`'s bounding square holds one iff the count grows over
    /// `x ..= x + 2R`.
    #[inline(always)]
    fn occupied_columns(&self, y: usize) -> Vec<u32> {
        let (stride, big_r) = (self.src.stride, self.tables.big_r);
        let mut column = vec![false; stride];
        for b in y / ROW_BLOCK..=(y + 2 * big_r) / ROW_BLOCK {
            let maxima = &self.block_max[b * stride..(b + 1) * stride];
            for px in 0..stride {
                column[px] |= maxima[px] > f64::NEG_INFINITY;
            }
        }
        let mut count = vec![0u32; stride + 1];
        for px in 0..stride {
            count[px + 1] = count[px] + u32::from(column[px]);
        }
        count
    }
}

avx2_dispatch!(
    refine_row_dispatch,
    refine_row_avx2,
    refine_row,
    (ctx: &RefineCtx<'_, T>, row: &[LayerAtPixel<T>], y: usize) -> Vec<LayerAtPixel<T>>
);

/// [`refine_small_weights`] of the receivers of image row `y`. Plain loops (an iterator
/// adapter's closure would be compiled apart from this function and lose its AVX2 code
/// path).
#[inline(always)]
fn refine_row<T: Real>(
    ctx: &RefineCtx<'_, T>,
    row: &[LayerAtPixel<T>],
    y: usize,
) -> Vec<LayerAtPixel<T>> {
    let src = ctx.src;
    let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
    let eps = T::c(model::WEIGHT_EPSILON);
    let below = T::c(REFINE_WEIGHT_BELOW);
    // The soft disc's `Z` of the last `r_c` summed, reused for the same `r_c` (the same
    // sum, the same bits).
    let mut last_z: Option<(T, T)> = None;
    let occupied = ctx.occupied_columns(y);
    let span = 2 * ctx.tables.big_r + 1;
    let mut out = Vec::with_capacity(row.len());
    for (x, s) in row.iter().enumerate() {
        // Receivers with no source with alpha > 0 in their window's bounding square keep
        // W = 0.
        if s.weight >= below || occupied[x + span] == occupied[x] {
            out.push(*s);
            continue;
        }
        let xi = src.index(x, y);
        let d_x = src.rel_disp[xi];
        // Below the cutoff the fast engine takes O = 1 (a zero focus weight).
        let e_x = match src.focus_weight[xi] {
            e if e < cutoff => T::zero(),
            e => e,
        };
        let (colour, weight) = window_sums(ctx, xi, d_x, e_x);
        let inv = T::one() / (weight + eps);
        // The soft-disc coverage has a tail as well, and dL/dC = dL/dB o / (W + eps)
        // is a ratio of the two tails there.
        let coverage = match ctx.coverage {
            Coverage::PaperBox => s.coverage,
            Coverage::SoftDisc => {
                let (r_c, _) =
                    model::coverage_radius_px(src.radius[xi], ctx.coverage_radius, ctx.footprint);
                let z = match last_z {
                    Some((r, z)) if r == r_c => z,
                    _ => {
                        let z = disc_weight(ctx, r_c);
                        last_z = Some((r_c, z));
                        z
                    }
                };
                DiscCoverage {
                    alpha_sum: disc_alpha_sum(ctx, xi, r_c),
                    weight: z,
                    ..DiscCoverage::default()
                }
                .value()
            }
        };
        out.push(LayerAtPixel {
            weight,
            colour: colour.map(|c| c * inv),
            coverage,
        });
    }
    out
}

/// `C = sum c Ilin` and `W = sum c` over the whole window of padded receiver `xi`, in
/// the fast forward's form (`O = 1` where `e_x = 0`; the centre tap's `O = 1` restored as
/// the forward does): the runs of sources with alpha != 0 of each window row, in
/// [`LANES`] lanes ([`run_lanes`]) for circle and polygon, through the forward's
/// [`gather_segment`] for kernel apertures.
/// Equations M13, M14 of docs/model.md.
#[inline(always)]
fn window_sums<T: Real>(ctx: &RefineCtx<'_, T>, xi: usize, d_x: T, e_x: T) -> ([T; 3], T) {
    let occluding = e_x > T::zero();
    let (mut acc, mut weight) = match (ctx.aperture, ctx.src.step, occluding) {
        (ApertureEval::Gauge, ScatterStep::Paper, false) => window_runs::<T, 1>(ctx, xi, d_x, e_x),
        (ApertureEval::Gauge, ScatterStep::Paper, true) => window_runs::<T, 2>(ctx, xi, d_x, e_x),
        (ApertureEval::Gauge, ScatterStep::Sharp, false) => window_runs::<T, 3>(ctx, xi, d_x, e_x),
        (ApertureEval::Gauge, ScatterStep::Sharp, true) => window_runs::<T, 4>(ctx, xi, d_x, e_x),
        (ApertureEval::Kernel(..), _, _) => window_runs::<T, 0>(ctx, xi, d_x, e_x),
    };
    if occluding {
        // The centre tap has O = 1; the run used O(x,x) = 1 + e (s(0) - 1).
        let src = ctx.src;
        let a = src.alpha[xi];
        let (sc, _) = centre_scatter(src.step, ctx.aperture, src.radius[xi]);
        let base = model::tap_weight_inv_area(a, sc, src.inv_area[xi], T::one());
        let fix = base * (T::one() - model::occlusion_fast(e_x, d_x, d_x));
        acc[0] = acc[0] + fix * src.red[xi];
        acc[1] = acc[1] + fix * src.green[xi];
        acc[2] = acc[2] + fix * src.blue[xi];
        weight = weight + fix;
    }
    (acc, weight)
}

/// [`window_sums`] without the centre's fix, for one kernel (`KIND`): 0 kernel aperture
/// ([`gather_segment`]), else circle or polygon in lanes: 1 paper step, 2 paper step
/// occluding, 3 sharp step, 4 sharp step occluding.
#[inline(always)]
fn window_runs<T: Real, const KIND: u8>(
    ctx: &RefineCtx<'_, T>,
    xi: usize,
    d_x: T,
    e_x: T,
) -> ([T; 3], T) {
    let (src, tables) = (ctx.src, ctx.tables);
    let big_r = tables.big_r as isize;
    let stride = src.stride;
    let col = xi % stride;
    let mut acc = [T::zero(); 3];
    let mut weight = T::zero();
    // The lanes of every run of the window, reduced once at the end (in lane order).
    let mut lanes = [[T::zero(); LANES]; 4];
    for dy in -big_r..=big_r {
        let Some(hw) = ctx.widths[(dy + big_r) as usize] else {
            continue;
        };
        let t = (dy + big_r) as usize;
        let row = (xi as isize + dy * stride as isize) as usize - col;
        let last = col + hw;
        let mut from = col - hw;
        loop {
            let (start, end) = ctx.runs.next_run(row, from, last);
            if start > last {
                break;
            }
            let n = end - start;
            // Window offsets dx = start - col .., at gauge columns dx + R.
            let run = (row + start, n);
            let gauge = (&tables.gauge[t][..], start + tables.big_r - col);
            match KIND {
                1 => run_lanes::<T, false, false>(src, run, gauge, d_x, e_x, &mut lanes),
                2 => run_lanes::<T, true, false>(src, run, gauge, d_x, e_x, &mut lanes),
                3 => run_lanes::<T, false, true>(src, run, gauge, d_x, e_x, &mut lanes),
                4 => run_lanes::<T, true, true>(src, run, gauge, d_x, e_x, &mut lanes),
                _ => {
                    let (sums, wsum) = gather_segment(
                        src,
                        tables,
                        ctx.aperture,
                        row + start,
                        n,
                        (start as isize - col as isize, dy),
                        d_x,
                        e_x,
                        e_x > T::zero(),
                    );
                    for c in 0..3 {
                        acc[c] = acc[c] + sums[c];
                    }
                    weight = weight + wsum;
                }
            }
            if end > last {
                break;
            }
            from = end;
        }
    }
    if KIND != 0 {
        for c in 0..3 {
            acc[c] = lane_sum(&lanes[c]);
        }
        weight = lane_sum(&lanes[3]);
    }
    (acc, weight)
}

/// The sums `sum c Ilin` and `sum c` of the run of `n` sources from padded index `at`,
/// at gauge columns `g0..` of `gauge` (the window row's), added to the [`LANES`] lanes
/// `sums` (`[C_r, C_g, C_b, W]`, reduced by the caller once per receiver): the fast
/// forward's tap weight (`gather_segment`) with the step `SHARP` and the occlusion when
/// `OCCLUDING`. The last partial chunk is a whole chunk of neighbouring taps (inside the
/// planes and the window row) with alpha taken as 0 outside the run, whose weight is then
/// exactly 0.
/// Equations M13, M14 of docs/model.md.
#[inline(always)]
fn run_lanes<T: Real, const OCCLUDING: bool, const SHARP: bool>(
    src: &Planes<T>,
    (at, n): (usize, usize),
    (gauge, g0): (&[T], usize),
    d_x: T,
    e_x: T,
    sums: &mut [[T; LANES]; 4],
) {
    let mut i = 0;
    while i + LANES <= n {
        tap_lanes::<T, OCCLUDING, SHARP>(src, at + i, &gauge[g0 + i..], 0..LANES, d_x, e_x, sums);
        i += LANES;
    }
    if i < n {
        let m = n - i;
        if i > 0 {
            // The run's last LANES taps, the first LANES - m of them already summed.
            let back = LANES - m;
            tap_lanes::<T, OCCLUDING, SHARP>(
                src,
                at + i - back,
                &gauge[g0 + i - back..],
                back..LANES,
                d_x,
                e_x,
                sums,
            );
        } else if at + LANES <= src.alpha.len() && g0 + LANES <= gauge.len() {
            tap_lanes::<T, OCCLUDING, SHARP>(src, at, &gauge[g0..], 0..m, d_x, e_x, sums);
        } else if at >= LANES - m && g0 >= LANES - m {
            let back = LANES - m;
            tap_lanes::<T, OCCLUDING, SHARP>(
                src,
                at - back,
                &gauge[g0 - back..],
                back..LANES,
                d_x,
                e_x,
                sums,
            );
        } else {
            // A window narrower than LANES at the planes' corner: tap by tap.
            for j in 0..m {
                let y = at + j;
                let s = step_fast::<T, SHARP>(src.radius[y] - gauge[g0 + j]);
                let o = if OCCLUDING {
                    model::occlusion_fast(e_x, src.rel_disp[y], d_x)
                } else {
                    T::one()
                };
                let c = model::tap_weight_inv_area(src.alpha[y], s, src.inv_area[y], o);
                sums[0][j] = sums[0][j] + c * src.red[y];
                sums[1][j] = sums[1][j] + c * src.green[y];
                sums[2][j] = sums[2][j] + c * src.blue[y];
                sums[3][j] = sums[3][j] + c;
            }
        }
    }
}

/// The [`LANES`] values of `plane` from index `at`.
#[inline(always)]
fn lanes<T: Real>(plane: &[T], at: usize) -> &[T; LANES] {
    plane[at..at + LANES].try_into().expect("LANES")
}

/// Adds the [`LANES`] taps of sources `at..at + LANES` (gauges `gauge[..LANES]`) to the
/// lane sums `[C_r, C_g, C_b, W]`, with alpha taken as 0 in the lanes outside `keep`
/// (their weight is then exactly 0).
/// Equations M3, M4, M12, M13 of docs/model.md.
#[inline(always)]
fn tap_lanes<T: Real, const OCCLUDING: bool, const SHARP: bool>(
    src: &Planes<T>,
    at: usize,
    gauge: &[T],
    keep: std::ops::Range<usize>,
    d_x: T,
    e_x: T,
    sums: &mut [[T; LANES]; 4],
) {
    let (alpha, radius, inv_area) = (
        lanes(&src.alpha, at),
        lanes(&src.radius, at),
        lanes(&src.inv_area, at),
    );
    let (disp, gauge) = (lanes(&src.rel_disp, at), lanes(gauge, 0));
    let (red, green, blue) = (
        lanes(&src.red, at),
        lanes(&src.green, at),
        lanes(&src.blue, at),
    );
    for l in 0..LANES {
        let a = if l >= keep.start && l < keep.end {
            alpha[l]
        } else {
            T::zero()
        };
        let s = step_fast::<T, SHARP>(radius[l] - gauge[l]);
        let o = if OCCLUDING {
            model::occlusion_fast(e_x, disp[l], d_x)
        } else {
            T::one()
        };
        let c = model::tap_weight_inv_area(a, s, inv_area[l], o);
        sums[0][l] = sums[0][l] + c * red[l];
        sums[1][l] = sums[1][l] + c * green[l];
        sums[2][l] = sums[2][l] + c * blue[l];
        sums[3][l] = sums[3][l] + c;
    }
}

/// The scatter step in its fast form, `SHARP` selecting [`ScatterStep::Sharp`].
/// Equations M3, M4 of docs/model.md.
#[inline(always)]
fn step_fast<T: Real, const SHARP: bool>(r_minus_dist: T) -> T {
    if SHARP {
        model::sharp_step_fast(r_minus_dist)
    } else {
        model::soft_step_fast(r_minus_dist)
    }
}

/// `sum_i S(r_c - gauge[i])` (with `alpha`, `sum_i S a[i]`) in [`LANES`] lanes.
/// Equation M16 of docs/model.md.
#[inline(always)]
fn disc_run_lanes<T: Real, const SHARP: bool, const ALPHA: bool>(
    gauge: &[T],
    alpha: &[T],
    r_c: T,
) -> T {
    let n = gauge.len();
    let full = n / LANES * LANES;
    let mut lanes = [T::zero(); LANES];
    let mut i = 0;
    while i < full {
        let g: &[T; LANES] = gauge[i..i + LANES].try_into().expect("LANES");
        if ALPHA {
            let a: &[T; LANES] = alpha[i..i + LANES].try_into().expect("LANES");
            for l in 0..LANES {
                lanes[l] = lanes[l] + step_fast::<T, SHARP>(r_c - g[l]) * a[l];
            }
        } else {
            for l in 0..LANES {
                lanes[l] = lanes[l] + step_fast::<T, SHARP>(r_c - g[l]);
            }
        }
        i += LANES;
    }
    for j in full..n {
        let s = step_fast::<T, SHARP>(r_c - gauge[j]);
        lanes[j - full] = lanes[j - full] + if ALPHA { s * alpha[j] } else { s };
    }
    lane_sum(&lanes)
}

/// The soft disc's `Z = sum_y M S(r_c, y)` over the whole window (no alpha).
/// Equation M16 of docs/model.md.
#[inline(always)]
fn disc_weight<T: Real>(ctx: &RefineCtx<'_, T>, r_c: T) -> T {
    let (src, tables, aperture) = (ctx.src, ctx.tables, ctx.aperture);
    let big_r = tables.big_r as isize;
    let mut z = T::zero();
    for dy in -big_r..=big_r {
        let Some(hw) = ctx.widths[(dy + big_r) as usize] else {
            continue;
        };
        let t = (dy + big_r) as usize;
        let gauge = &tables.gauge[t][tables.big_r - hw..=tables.big_r + hw];
        z = z + match (aperture, src.step) {
            (ApertureEval::Gauge, ScatterStep::Paper) => {
                disc_run_lanes::<T, false, false>(gauge, &[], r_c)
            }
            (ApertureEval::Gauge, ScatterStep::Sharp) => {
                disc_run_lanes::<T, true, false>(gauge, &[], r_c)
            }
            (ApertureEval::Kernel(..), _) => {
                let mut sum = T::zero();
                for dx in -(hw as isize)..=hw as isize {
                    sum = sum
                        + tables
                            .scatter_at::<false>(src.step, aperture, (dx, dy), r_c)
                            .0;
                }
                sum
            }
        };
    }
    z
}

/// The soft disc's `sum_y M S(r_c, y) a(y)` over the whole window of padded receiver
/// `xi`, over the runs of sources with alpha != 0.
/// Equation M16 of docs/model.md.
#[inline(always)]
fn disc_alpha_sum<T: Real>(ctx: &RefineCtx<'_, T>, xi: usize, r_c: T) -> T {
    let (src, tables, aperture) = (ctx.src, ctx.tables, ctx.aperture);
    let big_r = tables.big_r as isize;
    let stride = src.stride;
    let col = xi % stride;
    let mut sum = T::zero();
    for dy in -big_r..=big_r {
        let Some(hw) = ctx.widths[(dy + big_r) as usize] else {
            continue;
        };
        let t = (dy + big_r) as usize;
        let row = (xi as isize + dy * stride as isize) as usize - col;
        let last = col + hw;
        let mut from = col - hw;
        loop {
            let (start, end) = ctx.runs.next_run(row, from, last);
            if start > last {
                break;
            }
            // Window offsets dx = start - col .. end - col, at gauge columns dx + R.
            let (g0, g1) = (start + tables.big_r - col, end + tables.big_r - col);
            let gauge = &tables.gauge[t][g0..g1];
            let alpha = &src.alpha[row + start..row + end];
            sum = sum
                + match (aperture, src.step) {
                    (ApertureEval::Gauge, ScatterStep::Paper) => {
                        disc_run_lanes::<T, false, true>(gauge, alpha, r_c)
                    }
                    (ApertureEval::Gauge, ScatterStep::Sharp) => {
                        disc_run_lanes::<T, true, true>(gauge, alpha, r_c)
                    }
                    (ApertureEval::Kernel(..), _) => {
                        let mut s = T::zero();
                        for i in 0..end - start {
                            let dx = (start + i) as isize - col as isize;
                            let (sc, _) =
                                tables.scatter_at::<false>(src.step, aperture, (dx, dy), r_c);
                            s = s + sc * alpha[i];
                        }
                        s
                    }
                };
            if end > last {
                break;
            }
            from = end;
        }
    }
    sum
}

#[cfg(test)]
mod tests;
