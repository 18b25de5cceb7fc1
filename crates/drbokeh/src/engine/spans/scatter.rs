//! The span scatter of one layer over one sub-band of receiver rows: every source with
//! alpha > 0 whose disc reaches the sub-band adds, per receiver row, its interior as one
//! span (two writes into f64 difference arrays, summed by a prefix sum per row) and its
//! ring tap by tap, in chunks of [`LANES`] receivers (branch-free, vectorised). Receivers
//! in focus also get the occlusion sums of `focus.rs`. Then each receiver's layer colour
//! and coverage are composited (front to back).
//!
//! Sources are visited in a fixed order (padded rows, then columns) by one task per
//! sub-band, so the output does not depend on the number of threads.

use super::coverage::CoverageCtx;
use super::focus::{classify, Nodes, StepClass, FOCUS_CUTOFF, MAX_NODES};
use super::geometry::{
    disc_row, ring_steps, DiscRow, ExpTable, GaugeTable, Rings, Shape, LANES, MARGIN,
};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::model::{self, LayerAtPixel, ScatterStep};
use crate::Real;
use circle::{scatter_rows_circle, Profiles};

mod blocks;
mod circle;
mod runs;

/// Receiver rows per sub-band (one task, one set of accumulators).
pub const SUB_ROWS: usize = 128;

/// Colour and weight: the 4 components of a source's weight `v = a / A (Ilin, 1)`.
const COMPONENTS: usize = 4;

/// The read-only state of one layer over one band of receiver rows.
pub(super) struct BandLayer<'a, T> {
    /// The band's padded planes.
    pub b: &'a Planes<T>,
    /// Image width.
    pub width: usize,
    /// Receiver rows of the band.
    pub rows: usize,
    /// The aperture's row intervals.
    pub shape: &'a Shape,
    /// Ring widths of the scatter step.
    pub rings: Rings,
    /// Gauges of receiver offsets `x - y`, with the window mask.
    pub table: &'a GaugeTable<T>,
    /// The circle's ring steps by table ([`ExpTable`]; `None`: by [`ring_steps`]).
    pub exp: Option<&'a ExpTable>,
    /// Interpolation points for the band's in-focus receivers (`None`: none in the band).
    pub nodes: Option<&'a Nodes>,
    /// The coverage term.
    pub coverage: &'a CoverageCtx<'a, T>,
}

/// The occlusion sums of one receiver row that holds in-focus receivers, over its columns
/// `x0 ..= x1`.
struct FocusRow<T> {
    x0: usize,
    x1: usize,
    /// Prefix count of in-focus receivers over the whole row (`w + 1` entries).
    count: Vec<u32>,
    /// Difference arrays, `[x - x0][channel][component]`, channel 0 for sources whose step
    /// is 1 throughout, channel `1 + j` for interpolation point `j`.
    diff: Vec<f64>,
    /// The ring's exact `sum v S s`, `[component][x - x0 + MARGIN]`.
    ring: Vec<T>,
    /// Receivers' relative disparity, `[x - x0 + MARGIN]` (0 in the margins).
    rel_disp: Vec<T>,
}

impl<T: Real> FocusRow<T> {
    fn span(&self) -> usize {
        self.x1 - self.x0 + 1 + 2 * MARGIN
    }

    /// Whether any receiver in `a ..= b` is in focus.
    #[inline(always)]
    fn any_in(&self, a: isize, b: isize) -> bool {
        let w = self.count.len() as isize - 1;
        let (a, b) = (a.max(0), b.min(w - 1));
        a <= b && self.count[b as usize + 1] > self.count[a as usize]
    }
}

/// The accumulators of one sub-band.
struct Acc<T> {
    width: usize,
    /// `[row][x][component]`, `w + 1` entries per row.
    diff: Vec<f64>,
    /// `[row][component][x + MARGIN]`, `w + 2 MARGIN` entries per component.
    ring: Vec<T>,
    focus: Vec<Option<FocusRow<T>>>,
}

impl<T: Real> Acc<T> {
    fn ring_len(&self) -> usize {
        self.width + 2 * MARGIN
    }
}

/// A source's terms for one visit.
#[derive(Clone, Copy)]
struct Source<T> {
    /// Column relative to the band's first receiver.
    xs: isize,
    r: T,
    /// Rows reached above and below (`r + u_out`, at most the window).
    reach: isize,
    /// `(r - u_in)^2` (negative when `r < u_in`: no interior) and `(r + u_out)^2`.
    inner_sq: f64,
    outer_sq: f64,
    rel_disp: T,
    /// [`ExpTable::source_factor`] (0 without the table).
    e_r: f64,
    v: [T; COMPONENTS],
    /// `v` in f64, for the span writes.
    v64: [f64; COMPONENTS],
}

/// The depth-step coefficients of a source at the interpolation points.
struct Coefficients<T> {
    class: StepClass,
    values: [T; MAX_NODES],
}

avx2_dispatch!(
    sub_band_dispatch,
    sub_band_avx2,
    sub_band,
    (
        ctx: &BandLayer<'_, T>,
        rows: (usize, usize),
        linear: &mut [[T; 3]],
        transmittance: &mut [T],
        saved: &mut [LayerAtPixel<T>]
    ) -> u64
);

/// Renders one layer over receiver rows `y0 .. y1` of the band and composites it into
/// `linear` and `transmittance` (those rows only). Returns the ring taps and span writes
/// made (the work done). With a non-empty `saved` (those rows), also records each
/// receiver's `W`, `B` and `o` for the adjoint (the values the composite used).
pub(super) fn render_sub_band<T: Real>(
    ctx: &BandLayer<'_, T>,
    rows: (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [LayerAtPixel<T>],
) -> u64 {
    sub_band_dispatch(ctx, rows, linear, transmittance, saved)
}

#[inline(always)]
fn sub_band<T: Real>(
    ctx: &BandLayer<'_, T>,
    (y0, y1): (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [LayerAtPixel<T>],
) -> u64 {
    let mut acc = new_acc(ctx, (y0, y1));
    let focus = acc.focus.iter().any(Option::is_some);
    let rows = (y0, y1);
    let work = match (ctx.b.step, focus) {
        (ScatterStep::Sharp, false) => scatter_sources::<T, true, false>(ctx, rows, &mut acc),
        (ScatterStep::Sharp, true) => scatter_sources::<T, true, true>(ctx, rows, &mut acc),
        (ScatterStep::Paper, false) => scatter_sources::<T, false, false>(ctx, rows, &mut acc),
        (ScatterStep::Paper, true) => scatter_sources::<T, false, true>(ctx, rows, &mut acc),
    };
    let cover = finish::<T>(ctx, (y0, y1), &acc, linear, transmittance, saved);
    work + cover
}

/// Zeroed accumulators for rows `y0 .. y1`, with focus rows where receivers are in focus.
fn new_acc<T: Real>(ctx: &BandLayer<'_, T>, (y0, y1): (usize, usize)) -> Acc<T> {
    let (w, b) = (ctx.width, ctx.b);
    let rows = y1 - y0;
    let cutoff = T::c(FOCUS_CUTOFF);
    let channels = ctx.nodes.map_or(0, |n| n.len() + 1);
    let focus = (y0..y1)
        .map(|y| {
            ctx.nodes?;
            let row = b.index(0, y);
            let e = &b.focus_weight[row..row + w];
            let x0 = e.iter().position(|&e| e >= cutoff)?;
            let x1 = w - 1 - e.iter().rev().position(|&e| e >= cutoff)?;
            let mut count = vec![0u32; w + 1];
            for x in 0..w {
                count[x + 1] = count[x] + u32::from(e[x] >= cutoff);
            }
            let mut rel_disp = vec![T::zero(); x1 - x0 + 1 + 2 * MARGIN];
            rel_disp[MARGIN..MARGIN + x1 - x0 + 1]
                .copy_from_slice(&b.rel_disp[row + x0..=row + x1]);
            let mut f = FocusRow {
                x0,
                x1,
                count,
                diff: vec![0.0; (x1 - x0 + 2) * channels * COMPONENTS],
                ring: Vec::new(),
                rel_disp,
            };
            f.ring = vec![T::zero(); COMPONENTS * f.span()];
            Some(f)
        })
        .collect();
    Acc {
        width: w,
        diff: vec![0.0; rows * (w + 1) * COMPONENTS],
        ring: vec![T::zero(); rows * COMPONENTS * (w + 2 * MARGIN)],
        focus,
    }
}

/// Adds every source whose disc reaches rows `y0 .. y1` into `acc`. Returns the work done
/// (ring lanes plus span writes). Source row by source row; within one, disc row by disc
/// row across all its sources, so that the receiver rows being written stay in cache.
#[inline(always)]
fn scatter_sources<T: Real, const SHARP: bool, const FOCUS: bool>(
    ctx: &BandLayer<'_, T>,
    (y0, y1): (usize, usize),
    acc: &mut Acc<T>,
) -> u64 {
    let b = ctx.b;
    let (pad, stride) = (b.pad as isize, b.stride);
    let big_r = ctx.table.big_r as isize;
    let outer = ctx.rings.outer_px;
    let circle = matches!(ctx.shape, Shape::Circle);
    let mut profiles = Profiles::default();
    let mut work = 0u64;
    // Padded rows whose sources can reach y0 .. y1 (the window bounds every reach).
    let py0 = (y0 as isize + pad - big_r).max(0) as usize;
    let py1 = ((y1 as isize + pad + big_r) as usize).min(b.rows);
    let w = ctx.width as isize;
    let mut sources: Vec<Source<T>> = Vec::with_capacity(stride);
    let mut caches: Vec<Option<Coefficients<T>>> = Vec::with_capacity(stride);
    for py in py0..py1 {
        let ys = py as isize - pad;
        // This row's sources that reach the sub-band.
        sources.clear();
        let (lo, hi) = (y0 as isize - ys, y1 as isize - 1 - ys);
        let mut max_reach = -1;
        for px in 0..stride {
            let i = py * stride + px;
            let a = b.alpha[i];
            if a == T::zero() {
                continue;
            }
            let r = b.radius[i];
            let reach = (r.f64() + outer).min(big_r as f64).floor() as isize;
            let xs = px as isize - pad;
            if lo.max(-reach) > hi.min(reach) || xs + reach < 0 || xs - reach >= w {
                continue;
            }
            let wa = a * b.inv_area[i];
            let v = [wa * b.red[i], wa * b.green[i], wa * b.blue[i], wa];
            let (rf, rings) = (r.f64(), ctx.rings);
            let inner = rf - rings.inner_px;
            sources.push(Source {
                xs,
                r,
                reach,
                inner_sq: if inner >= 0.0 { inner * inner } else { -1.0 },
                outer_sq: (rf + rings.outer_px).powi(2),
                rel_disp: b.rel_disp[i],
                e_r: ctx.exp.map_or(0.0, |e| e.source_factor(rf)),
                v,
                v64: v.map(|c| c.f64()),
            });
            max_reach = max_reach.max(reach);
        }
        if sources.is_empty() {
            continue;
        }
        caches.clear();
        caches.resize_with(sources.len(), || None);
        if circle {
            for (c, plane) in profiles.v_planes.iter_mut().enumerate() {
                plane.clear();
                plane.extend(sources.iter().map(|s| s.v[c]));
            }
            profiles.v64.clear();
            profiles.v64.extend(sources.iter().flat_map(|s| s.v64));
            // Maximal runs of sources of equal radius in adjacent columns.
            profiles.segments.clear();
            let mut start = 0;
            for k in 1..=sources.len() {
                if k == sources.len()
                    || sources[k].r != sources[start].r
                    || sources[k].xs != sources[start].xs + (k - start) as isize
                {
                    profiles.segments.push((start, k));
                    start = k;
                }
            }
        }
        // Mostly distinct radii (no shared profiles): blocks across the sources.
        let blocks = match ctx.exp {
            Some(e) if circle && !FOCUS && 2 * profiles.segments.len() > sources.len() => Some(e),
            _ => None,
        };
        let (dy0, dy1) = (lo.max(-max_reach), hi.min(max_reach));
        if circle {
            // Rows dy and -dy share their intervals and ring profile.
            let top = dy0.abs().max(dy1.abs());
            let bottom = if dy0 <= 0 && dy1 >= 0 {
                0
            } else {
                dy0.abs().min(dy1.abs())
            };
            for ady in bottom..=top {
                let rows =
                    [ady, -ady].map(|dy| (dy >= dy0 && dy <= dy1).then(|| (ys + dy) as usize - y0));
                let rows = [rows[0], if ady == 0 { None } else { rows[1] }];
                if rows == [None, None] {
                    continue;
                }
                if let Some(exp) = blocks {
                    work += blocks::add_blocks(ctx, exp, (&sources, &profiles.v64), ady, rows, acc);
                    continue;
                }
                work += scatter_rows_circle::<T, SHARP, FOCUS>(
                    ctx,
                    (&sources, &mut caches),
                    ady,
                    rows,
                    acc,
                    &mut profiles,
                );
            }
        } else {
            for dy in dy0..=dy1 {
                let row = (ys + dy) as usize - y0;
                for (src, cache) in sources.iter().zip(caches.iter_mut()) {
                    if src.reach >= dy.abs() {
                        work += scatter_row::<T, SHARP, FOCUS>(ctx, src, dy, row, acc, cache);
                    }
                }
            }
        }
    }
    work
}

/// The source's depth-step coefficients at the interpolation points (computed once per
/// visit, when first needed).
fn coefficients<'c, T: Real>(
    nodes: &Nodes,
    rel_disp: T,
    cache: &'c mut Option<Coefficients<T>>,
) -> &'c Coefficients<T> {
    cache.get_or_insert_with(|| {
        let class = classify(nodes, rel_disp.f64());
        let mut values = [T::zero(); MAX_NODES];
        if class == StepClass::Interpolated {
            for (v, &d) in values.iter_mut().zip(&nodes.delta) {
                *v = model::depth_step_fast(rel_disp - T::c(d));
            }
        }
        Coefficients { class, values }
    })
}

/// The interior span of a disc row into sub-band row `row` (and its focus row).
#[inline(always)]
fn interior<T: Real, const FOCUS: bool>(
    ctx: &BandLayer<'_, T>,
    src: &Source<T>,
    (lo, hi): (isize, isize),
    row: usize,
    acc: &mut Acc<T>,
    cache: &mut Option<Coefficients<T>>,
) -> u64 {
    let w = ctx.width as isize;
    let (xa, xb) = ((src.xs + lo).max(0), (src.xs + hi).min(w - 1));
    if xa > xb {
        return 0;
    }
    let base = row * (acc.width + 1) * COMPONENTS;
    let (ia, ib) = (
        base + xa as usize * COMPONENTS,
        base + (xb as usize + 1) * COMPONENTS,
    );
    let start: &mut [f64; COMPONENTS] = (&mut acc.diff[ia..ia + COMPONENTS])
        .try_into()
        .expect("COMPONENTS");
    for c in 0..COMPONENTS {
        start[c] += src.v64[c];
    }
    let end: &mut [f64; COMPONENTS] = (&mut acc.diff[ib..ib + COMPONENTS])
        .try_into()
        .expect("COMPONENTS");
    for c in 0..COMPONENTS {
        end[c] -= src.v64[c];
    }
    if !FOCUS {
        return 2;
    }
    let Some(f) = acc.focus[row].as_mut() else {
        return 2;
    };
    let (qa, qb) = (xa.max(f.x0 as isize), xb.min(f.x1 as isize));
    if qa > qb || !f.any_in(qa, qb) {
        return 2;
    }
    let nodes = ctx.nodes.expect("focus rows need nodes");
    let k = coefficients(nodes, src.rel_disp, cache);
    interior_focus(f, nodes.len(), k, &src.v, (qa as usize, qb as usize));
    4
}

/// The chunk runs of a disc row's ring (receiver columns), each extended outwards to whole
/// chunks: `(first start, last start, step)`; left of the interior from its inner end
/// leftwards, right of it (or the whole ring when there is no interior) from its inner end
/// rightwards. Iterate with [`next_chunk`].
#[inline(always)]
fn chunk_runs(disc: &DiscRow, xs: isize, w: isize) -> [(isize, isize, isize); 2] {
    let lanes = LANES as isize;
    let mut runs = [(0isize, -1isize, lanes); 2];
    let clip = |(lo, hi): (isize, isize)| ((xs + lo).max(0), (xs + hi).min(w - 1));
    match (disc.interior, disc.left, disc.right) {
        (None, Some(run), _) => {
            let (xa, xb) = clip(run);
            runs[0] = (xa, xb, lanes);
        }
        (Some(_), left, right) => {
            if let Some(run) = left {
                let (xa, xb) = clip(run);
                // Down to the last start whose chunk still reaches xa.
                runs[0] = (xb - (lanes - 1), xa - (lanes - 1), -lanes);
            }
            if let Some(run) = right {
                let (xa, xb) = clip(run);
                runs[1] = (xa, xb, lanes);
            }
        }
        (None, None, _) => {}
    }
    runs
}

/// Whether chunk start `c` lies within the run `(first, last, step)`.
#[inline(always)]
fn in_run(c: isize, (_, last, step): (isize, isize, isize)) -> bool {
    if step > 0 {
        c <= last
    } else {
        c >= last
    }
}

/// One row `dy` of a source's disc into receiver row `row` of the sub-band (any convex
/// shape: the ring is evaluated chunk by chunk from the gauge table).
#[inline(always)]
fn scatter_row<T: Real, const SHARP: bool, const FOCUS: bool>(
    ctx: &BandLayer<'_, T>,
    src: &Source<T>,
    dy: isize,
    row: usize,
    acc: &mut Acc<T>,
    cache: &mut Option<Coefficients<T>>,
) -> u64 {
    let Some(hw) = ctx.table.window_half_width(dy) else {
        return 0;
    };
    let Some(disc) = disc_row(ctx.shape, ctx.rings, src.r.f64(), dy, hw, -1.0) else {
        return 0;
    };
    let mut work = 0;
    if let Some(run) = disc.interior {
        work += interior::<T, FOCUS>(ctx, src, run, row, acc, cache);
    }
    let w = ctx.width as isize;
    for run in chunk_runs(&disc, src.xs, w) {
        let mut start = run.0;
        while in_run(start, run) {
            let s = ring_steps::<T, SHARP>(ctx.table, src.r, dy, start - src.xs);
            ring_add::<T, FOCUS>(ctx, src, row, start, s, acc, cache);
            work += LANES as u64;
            start += run.2;
        }
    }
    work
}

/// The interior span `qa ..= qb` of a source into a focus row's difference arrays.
#[inline(always)]
fn interior_focus<T: Real>(
    f: &mut FocusRow<T>,
    points: usize,
    k: &Coefficients<T>,
    v: &[T; COMPONENTS],
    (qa, qb): (usize, usize),
) {
    let channels = points + 1;
    let at = |x: usize| (x - f.x0) * channels * COMPONENTS;
    let (ia, ib) = (at(qa), at(qb + 1));
    match k.class {
        StepClass::Zero => {}
        StepClass::One => {
            for c in 0..COMPONENTS {
                f.diff[ia + c] += v[c].f64();
                f.diff[ib + c] -= v[c].f64();
            }
        }
        StepClass::Interpolated => {
            for j in 0..points {
                let s = k.values[j];
                for c in 0..COMPONENTS {
                    let val = (s * v[c]).f64();
                    f.diff[ia + (1 + j) * COMPONENTS + c] += val;
                    f.diff[ib + (1 + j) * COMPONENTS + c] -= val;
                }
            }
        }
    }
}

/// Adds one chunk of [`LANES`] ring taps with steps `s` at receivers
/// `start .. start + LANES` of row `row` (and, where they are in focus, their occlusion
/// sums with the exact depth step).
#[inline(always)]
fn ring_add<T: Real, const FOCUS: bool>(
    ctx: &BandLayer<'_, T>,
    src: &Source<T>,
    row: usize,
    start: isize,
    mut s: [T; LANES],
    acc: &mut Acc<T>,
    cache: &mut Option<Coefficients<T>>,
) {
    let len = acc.ring_len();
    let base = row * COMPONENTS * len + (start + MARGIN as isize) as usize;
    for c in 0..COMPONENTS {
        let out: &mut [T; LANES] = (&mut acc.ring[base + c * len..base + c * len + LANES])
            .try_into()
            .expect("LANES");
        let v = src.v[c];
        for l in 0..LANES {
            out[l] = out[l] + s[l] * v;
        }
    }
    if !FOCUS {
        return;
    }
    let Some(f) = acc.focus[row].as_mut() else {
        return;
    };
    if !f.any_in(start, start + LANES as isize - 1) {
        return;
    }
    let nodes = ctx.nodes.expect("focus rows need nodes");
    let class = coefficients(nodes, src.rel_disp, cache).class;
    if class == StepClass::Zero {
        return;
    }
    let len = f.span();
    let off = (start - f.x0 as isize + MARGIN as isize) as usize;
    if class == StepClass::Interpolated {
        let d: &[T; LANES] = f.rel_disp[off..off + LANES].try_into().expect("LANES");
        for l in 0..LANES {
            s[l] = s[l] * model::depth_step_fast(src.rel_disp - d[l]);
        }
    }
    for c in 0..COMPONENTS {
        let out: &mut [T; LANES] = (&mut f.ring[c * len + off..c * len + off + LANES])
            .try_into()
            .expect("LANES");
        let v = src.v[c];
        for l in 0..LANES {
            out[l] = out[l] + s[l] * v;
        }
    }
}

/// Prefix sums, layer colour, coverage and compositing of rows `y0 .. y1`. Returns the
/// coverage's work. Records `W`, `B`, `o` into a non-empty `saved`.
fn finish<T: Real>(
    ctx: &BandLayer<'_, T>,
    (y0, y1): (usize, usize),
    acc: &Acc<T>,
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [LayerAtPixel<T>],
) -> u64 {
    let (w, b) = (ctx.width, ctx.b);
    let eps = T::c(model::WEIGHT_EPSILON);
    let cutoff = T::c(FOCUS_CUTOFF);
    let len = acc.ring_len();
    let mut basis = [0.0f64; MAX_NODES];
    let mut work = 0u64;
    for y in y0..y1 {
        let row = y - y0;
        let diff = &acc.diff[row * (w + 1) * COMPONENTS..(row + 1) * (w + 1) * COMPONENTS];
        let ring = &acc.ring[row * COMPONENTS * len..(row + 1) * COMPONENTS * len];
        let mut run = [0.0f64; COMPONENTS];
        let focus = acc.focus[row].as_ref();
        let channels = ctx.nodes.map_or(0, |n| n.len() + 1);
        let mut q_run = vec![0.0f64; channels * COMPONENTS];
        for x in 0..w {
            for c in 0..COMPONENTS {
                run[c] += diff[x * COMPONENTS + c];
            }
            let p: [T; COMPONENTS] =
                std::array::from_fn(|c| T::c(run[c]) + ring[c * len + x + MARGIN]);
            let xi = b.index(x, y);
            let e = b.focus_weight[xi];
            let mut sums = p;
            if let Some(f) = focus.filter(|f| (f.x0..=f.x1).contains(&x)) {
                let q_diff = &f.diff[(x - f.x0) * channels * COMPONENTS..];
                for (q, d) in q_run.iter_mut().zip(q_diff) {
                    *q += *d;
                }
                if e >= cutoff {
                    let nodes = ctx.nodes.expect("focus rows need nodes");
                    sums = focus_sums(ctx, nodes, f, (x, y), &q_run, &mut basis, p);
                }
            }
            let coverage = ctx.coverage.at(x, y, &mut work);
            let o = y * w + x;
            let inv = T::one() / (sums[3] + eps);
            let t = transmittance[o - y0 * w];
            for c in 0..3 {
                let lin = &mut linear[o - y0 * w][c];
                *lin = *lin + sums[c] * inv * coverage * t;
            }
            transmittance[o - y0 * w] = t * (T::one() - coverage);
            if let Some(s) = saved.get_mut(o - y0 * w) {
                *s = LayerAtPixel {
                    weight: sums[3],
                    colour: [0, 1, 2].map(|c| sums[c] * inv),
                    coverage,
                };
            }
        }
    }
    work
}

/// `C` and `W` of an in-focus receiver: `(1 - e) P + e Q` with the centre tap's occlusion
/// restored to 1.
#[inline]
fn focus_sums<T: Real>(
    ctx: &BandLayer<'_, T>,
    nodes: &Nodes,
    f: &FocusRow<T>,
    (x, y): (usize, usize),
    q_run: &[f64],
    basis: &mut [f64; MAX_NODES],
    p: [T; COMPONENTS],
) -> [T; COMPONENTS] {
    let b = ctx.b;
    let xi = b.index(x, y);
    let (e, d_x) = (b.focus_weight[xi], b.rel_disp[xi]);
    let points = nodes.len();
    nodes.basis(d_x.f64(), &mut basis[..points]);
    let off = x - f.x0 + MARGIN;
    let len = f.span();
    let q: [T; COMPONENTS] = std::array::from_fn(|c| {
        let mut v = q_run[c];
        for j in 0..points {
            v += basis[j] * q_run[(1 + j) * COMPONENTS + c];
        }
        T::c(v) + f.ring[c * len + off]
    });
    // The centre tap: the sums used O = (1 - e) + e s_used; the model's O(x, x) is 1.
    let (a, r) = (b.alpha[xi], b.radius[xi]);
    let (s_used, step) = if r.f64() - ctx.rings.inner_px >= 0.0 {
        // Interior: S taken as 1, s interpolated.
        let mut s = 0.0;
        for j in 0..points {
            s += basis[j] * model::depth_step_fast(d_x - T::c(nodes.delta[j])).f64();
        }
        (T::c(s), T::one())
    } else {
        let s = match b.step {
            ScatterStep::Sharp => ring_steps::<T, true>(ctx.table, r, 0, 0)[0],
            ScatterStep::Paper => ring_steps::<T, false>(ctx.table, r, 0, 0)[0],
        };
        (model::depth_step_fast(T::zero()), s)
    };
    let wa = a * b.inv_area[xi];
    let v = [wa * b.red[xi], wa * b.green[xi], wa * b.blue[xi], wa];
    std::array::from_fn(|c| {
        (T::one() - e) * p[c] + e * q[c] + e * v[c] * step * (T::one() - s_used)
    })
}
