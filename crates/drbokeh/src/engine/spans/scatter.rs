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
use super::geometry::{disc_row, ring_step, GaugeTable, Rings, Shape, LANES, MARGIN};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::model::{self, ScatterStep};
use crate::Real;

/// Receiver rows per sub-band (one task, one set of accumulators).
pub const SUB_ROWS: usize = 32;

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
    rel_disp: T,
    v: [T; COMPONENTS],
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
        transmittance: &mut [T]
    ) -> u64
);

/// Renders one layer over receiver rows `y0 .. y1` of the band and composites it into
/// `linear` and `transmittance` (those rows only). Returns the ring taps and span writes
/// made (the work done).
pub(super) fn render_sub_band<T: Real>(
    ctx: &BandLayer<'_, T>,
    rows: (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
) -> u64 {
    sub_band_dispatch(ctx, rows, linear, transmittance)
}

#[inline(always)]
fn sub_band<T: Real>(
    ctx: &BandLayer<'_, T>,
    (y0, y1): (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
) -> u64 {
    let mut acc = new_acc(ctx, (y0, y1));
    let work = match ctx.b.step {
        ScatterStep::Sharp => scatter_sources::<T, true>(ctx, (y0, y1), &mut acc),
        ScatterStep::Paper => scatter_sources::<T, false>(ctx, (y0, y1), &mut acc),
    };
    let cover = finish::<T>(ctx, (y0, y1), &acc, linear, transmittance);
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
            rel_disp[MARGIN..MARGIN + x1 - x0 + 1].copy_from_slice(&b.rel_disp[row + x0..=row + x1]);
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
/// (ring lanes plus span writes).
#[inline(always)]
fn scatter_sources<T: Real, const SHARP: bool>(
    ctx: &BandLayer<'_, T>,
    (y0, y1): (usize, usize),
    acc: &mut Acc<T>,
) -> u64 {
    let b = ctx.b;
    let (pad, stride) = (b.pad as isize, b.stride);
    let big_r = ctx.table.big_r as isize;
    let outer = ctx.rings.outer_px;
    let mut work = 0u64;
    // Padded rows whose sources can reach y0 .. y1 (the window bounds every reach).
    let py0 = (y0 as isize + pad - big_r).max(0) as usize;
    let py1 = ((y1 as isize + pad + big_r) as usize).min(b.rows);
    let w = ctx.width as isize;
    for py in py0..py1 {
        let ys = py as isize - pad;
        for px in 0..stride {
            let i = py * stride + px;
            let a = b.alpha[i];
            if a == T::zero() {
                continue;
            }
            let r = b.radius[i];
            let reach = (r.f64() + outer).min(big_r as f64).floor() as isize;
            let dy0 = (y0 as isize - ys).max(-reach);
            let dy1 = (y1 as isize - 1 - ys).min(reach);
            let xs = px as isize - pad;
            if dy0 > dy1 || xs + reach < 0 || xs - reach >= w {
                continue;
            }
            let wa = a * b.inv_area[i];
            let src = Source {
                xs,
                r,
                rel_disp: b.rel_disp[i],
                v: [wa * b.red[i], wa * b.green[i], wa * b.blue[i], wa],
            };
            let mut coefficients = None;
            for dy in dy0..=dy1 {
                work += scatter_row::<T, SHARP>(ctx, &src, dy, (ys + dy) as usize - y0, acc, &mut coefficients);
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

/// One row `dy` of a source's disc into receiver row `row` of the sub-band.
#[inline(always)]
fn scatter_row<T: Real, const SHARP: bool>(
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
    let w = ctx.width as isize;
    let mut work = 0u64;
    let has_focus = acc.focus[row].is_some();
    if let Some((lo, hi)) = disc.interior {
        let (xa, xb) = ((src.xs + lo).max(0), (src.xs + hi).min(w - 1));
        if xa <= xb {
            work += 2;
            let base = row * (acc.width + 1) * COMPONENTS;
            for c in 0..COMPONENTS {
                acc.diff[base + xa as usize * COMPONENTS + c] += src.v[c].f64();
                acc.diff[base + (xb as usize + 1) * COMPONENTS + c] -= src.v[c].f64();
            }
            if has_focus {
                let nodes = ctx.nodes.expect("focus rows need nodes");
                let f = acc.focus[row].as_mut().expect("checked");
                let (qa, qb) = (xa.max(f.x0 as isize), xb.min(f.x1 as isize));
                if qa <= qb && f.any_in(qa, qb) {
                    let k = coefficients(nodes, src.rel_disp, cache);
                    interior_focus(f, nodes.len(), k, &src.v, (qa as usize, qb as usize));
                    work += 2;
                }
            }
        }
    }
    // Ring runs, extended outwards to whole chunks (their extra taps are exact model
    // values, or 0 outside the window).
    let mut chunk = |start: isize| {
        ring_chunk::<T, SHARP>(ctx, src, dy, row, start, acc, cache);
    };
    let mut n = 0u64;
    match (disc.interior, disc.left, disc.right) {
        (None, Some((lo, hi)), _) => {
            let (xa, xb) = ((src.xs + lo).max(0), (src.xs + hi).min(w - 1));
            let mut c = xa;
            while c <= xb {
                chunk(c);
                n += 1;
                c += LANES as isize;
            }
        }
        (Some(_), left, right) => {
            if let Some((lo, hi)) = left {
                let (xa, xb) = ((src.xs + lo).max(0), (src.xs + hi).min(w - 1));
                let mut c = xb - (LANES as isize - 1);
                while c + LANES as isize - 1 >= xa {
                    chunk(c);
                    n += 1;
                    c -= LANES as isize;
                }
            }
            if let Some((lo, hi)) = right {
                let (xa, xb) = ((src.xs + lo).max(0), (src.xs + hi).min(w - 1));
                let mut c = xa;
                while c <= xb {
                    chunk(c);
                    n += 1;
                    c += LANES as isize;
                }
            }
        }
        (None, None, _) => {}
    }
    work + n * LANES as u64
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

/// One chunk of [`LANES`] ring taps at receivers `start .. start + LANES` of row `row`.
#[inline(always)]
fn ring_chunk<T: Real, const SHARP: bool>(
    ctx: &BandLayer<'_, T>,
    src: &Source<T>,
    dy: isize,
    row: usize,
    start: isize,
    acc: &mut Acc<T>,
    cache: &mut Option<Coefficients<T>>,
) {
    let g = ctx.table.chunk(dy, start - src.xs);
    let mut s = [T::zero(); LANES];
    for l in 0..LANES {
        s[l] = ring_step::<T, SHARP>(src.r, g[l]);
    }
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
/// coverage's work.
fn finish<T: Real>(
    ctx: &BandLayer<'_, T>,
    (y0, y1): (usize, usize),
    acc: &Acc<T>,
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
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
        let g0 = ctx.table.chunk(0, -(LANES as isize / 2))[LANES / 2];
        let s = match b.step {
            ScatterStep::Sharp => ring_step::<T, true>(r, g0),
            ScatterStep::Paper => ring_step::<T, false>(r, g0),
        };
        (model::depth_step_fast(T::zero()), s)
    };
    let wa = a * b.inv_area[xi];
    let v = [wa * b.red[xi], wa * b.green[xi], wa * b.blue[xi], wa];
    std::array::from_fn(|c| {
        (T::one() - e) * p[c] + e * q[c] + e * v[c] * step * (T::one() - s_used)
    })
}
