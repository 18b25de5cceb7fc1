//! The layer coverage on the span engine's bands.
//!
//! - The paper's box: the fast engine's summed-area table, O(1) per receiver.
//! - The soft disc (preset `physical`), `o(x) = sum_y S(r_c(x) - g) a(y) / sum_y S(r_c(x) - g)`:
//!   where every alpha within the receiver's reach is 1 (or 0) it is exactly 1 (or 0), which
//!   two integer summed-area tables tell in O(1) (an opaque layer costs nothing); elsewhere
//!   a gather as spans: per disc row, the interior from a row prefix sum of alpha (S taken
//!   as 1, relative error at most `2e-5`, see [`super::geometry::Rings::of`]) and the ring
//!   tap by tap in chunks of [`LANES`]. O(r) per receiver.

use super::geometry::{disc_row, ring_steps, GaugeTable, Rings, Shape, LANES, MARGIN};
use crate::engine::fast::forward::AlphaSat;
use crate::engine::planes::Planes;
use crate::model::{self, CoverageRadius, ScatterStep};
use crate::Real;
use std::cell::RefCell;

/// How a band-layer's coverage is computed.
pub(super) enum CoverageCtx<'a, T> {
    /// The paper's box mean.
    Box {
        /// The band's planes.
        b: &'a Planes<T>,
        /// Summed-area table of alpha.
        sat: AlphaSat,
        /// Window radius.
        big_r: usize,
    },
    /// The soft disc.
    Disc(Box<DiscGather<'a, T>>),
}

impl<'a, T: Real> CoverageCtx<'a, T> {
    /// The coverage of receiver `(x, y)` (band rows); adds the gather's work to `work`.
    #[inline]
    pub fn at(&self, x: usize, y: usize, work: &mut u64) -> T {
        match self {
            CoverageCtx::Box { b, sat, big_r } => sat.box_coverage(b, x, y, *big_r),
            CoverageCtx::Disc(d) => d.at(x, y, work),
        }
    }
}

/// The soft-disc gather's state over one band.
pub(super) struct DiscGather<'a, T> {
    b: &'a Planes<T>,
    shape: &'a Shape,
    rings: Rings,
    /// Gauges of tap offsets `y - x`.
    table: &'a GaugeTable<T>,
    kind: CoverageRadius,
    footprint: T,
    /// Integer summed-area tables over the padded planes (`(rows + 1) x (stride + 1)`):
    /// pixels with alpha > 0, pixels with alpha < 1.
    positive: Vec<u32>,
    partial: Vec<u32>,
    /// Alpha, each padded row extended by [`MARGIN`] zeros on both sides (empty when no
    /// receiver needs the gather).
    alpha_ext: Vec<T>,
    /// Per padded row, the prefix sums of alpha (f64, `stride + 1` each).
    prefix: Vec<f64>,
    /// The last gathered disc's rows, ring steps and weight, reused by the next receiver
    /// of the same coverage radius (the band's receivers are gathered by one thread).
    profile: RefCell<GatherProfile<T>>,
}

/// Columns `lo ..= hi` relative to the receiver.
type Run = (isize, isize);

/// One coverage disc of radius `r_c` as the gather walks it: per row its offset, interior
/// and ring chunks; the chunks' steps; and the weight `sum S` (which does not depend on
/// alpha). A function of `r_c` (and the band's fixed shape, rings and window) only, so
/// receivers of equal `r_c` share it exactly: the same values, summed in the same order.
struct GatherProfile<T> {
    r_c: Option<T>,
    /// `(dy, interior, first chunk, end chunk)` per row with taps.
    rows: Vec<(isize, Option<Run>, usize, usize)>,
    /// Column offset of each ring chunk.
    chunk_dx: Vec<isize>,
    /// Steps of each ring chunk.
    steps: Vec<[T; LANES]>,
    /// `sum S` over the disc (interior counted as 1 per tap).
    weight: f64,
}

impl<'a, T: Real> DiscGather<'a, T> {
    /// The gather's state for band planes `b`.
    pub fn new(
        b: &'a Planes<T>,
        shape: &'a Shape,
        table: &'a GaugeTable<T>,
        kind: CoverageRadius,
        footprint_px: f64,
    ) -> Self {
        let (rows, stride) = (b.rows, b.stride);
        let s1 = stride + 1;
        let mut positive = vec![0u32; (rows + 1) * s1];
        let mut partial = vec![0u32; (rows + 1) * s1];
        for py in 0..rows {
            let (mut rp, mut rq) = (0u32, 0u32);
            for px in 0..stride {
                let a = b.alpha[py * stride + px];
                rp += u32::from(a > T::zero());
                rq += u32::from(a < T::one());
                positive[(py + 1) * s1 + px + 1] = positive[py * s1 + px + 1] + rp;
                partial[(py + 1) * s1 + px + 1] = partial[py * s1 + px + 1] + rq;
            }
        }
        let any_partial = partial[rows * s1 + stride] > 0;
        let any_positive = positive[rows * s1 + stride] > 0;
        let (alpha_ext, prefix) = if any_partial && any_positive {
            let ext = stride + 2 * MARGIN;
            let mut alpha_ext = vec![T::zero(); rows * ext];
            let mut prefix = vec![0.0f64; rows * s1];
            for py in 0..rows {
                let src = &b.alpha[py * stride..(py + 1) * stride];
                alpha_ext[py * ext + MARGIN..py * ext + MARGIN + stride].copy_from_slice(src);
                let mut run = 0.0;
                for (px, a) in src.iter().enumerate() {
                    run += a.f64();
                    prefix[py * s1 + px + 1] = run;
                }
            }
            (alpha_ext, prefix)
        } else {
            (Vec::new(), Vec::new())
        };
        DiscGather {
            b,
            shape,
            rings: Rings::of(b.step),
            table,
            kind,
            footprint: T::c(footprint_px),
            positive,
            partial,
            alpha_ext,
            prefix,
            profile: RefCell::new(GatherProfile {
                r_c: None,
                rows: Vec::new(),
                chunk_dx: Vec::new(),
                steps: Vec::new(),
                weight: 0.0,
            }),
        }
    }

    /// Count in a summed-area table over padded rows `r0..r1`, columns `c0..c1`.
    #[inline(always)]
    fn count(&self, sat: &[u32], (r0, r1): (usize, usize), (c0, c1): (usize, usize)) -> u32 {
        let s1 = self.b.stride + 1;
        sat[r1 * s1 + c1] + sat[r0 * s1 + c0] - sat[r0 * s1 + c1] - sat[r1 * s1 + c0]
    }

    /// The soft-disc coverage of receiver `(x, y)` (band rows).
    #[inline]
    pub fn at(&self, x: usize, y: usize, work: &mut u64) -> T {
        let b = self.b;
        let xi = b.index(x, y);
        let (r_c, _) = model::coverage_radius_px(b.radius[xi], self.kind, self.footprint);
        let big_r = self.table.big_r;
        let reach = ((r_c.f64() + self.rings.outer_px).floor() as usize).min(big_r);
        let (px, py) = (x + b.pad, y + b.pad);
        let rows = (py - reach, py + reach + 1);
        let cols = (px - reach, px + reach + 1);
        if self.count(&self.partial, rows, cols) == 0 {
            return T::one();
        }
        if self.count(&self.positive, rows, cols) == 0 {
            return T::zero();
        }
        match b.step {
            ScatterStep::Sharp => self.gather::<true>((px, py), r_c, reach, work),
            ScatterStep::Paper => self.gather::<false>((px, py), r_c, reach, work),
        }
    }

    /// `sum S a / sum S` over the disc of radius `r_c` around padded receiver `(px, py)`.
    #[inline(always)]
    fn gather<const SHARP: bool>(
        &self,
        (px, py): (usize, usize),
        r_c: T,
        reach: usize,
        work: &mut u64,
    ) -> T {
        let mut profile = self.profile.borrow_mut();
        if profile.r_c != Some(r_c) {
            self.build_profile::<SHARP>(&mut profile, r_c, reach);
        }
        let (s1, ext) = (self.b.stride + 1, self.b.stride + 2 * MARGIN);
        let mut alpha_sum = 0.0f64;
        let mut lane_a = [T::zero(); LANES];
        let centre = px as isize;
        for &(dy, interior, c0, c1) in &profile.rows {
            let row = (py as isize + dy) as usize;
            if let Some((lo, hi)) = interior {
                let p = &self.prefix[row * s1..(row + 1) * s1];
                alpha_sum += p[(centre + hi + 1) as usize] - p[(centre + lo) as usize];
                *work += 1;
            }
            let alpha = &self.alpha_ext[row * ext..(row + 1) * ext];
            for (&dx0, s) in profile.chunk_dx[c0..c1].iter().zip(&profile.steps[c0..c1]) {
                let start = (centre + dx0 + MARGIN as isize) as usize;
                let a: &[T; LANES] = alpha[start..start + LANES].try_into().expect("LANES");
                for l in 0..LANES {
                    lane_a[l] = lane_a[l] + s[l] * a[l];
                }
                *work += LANES as u64;
            }
        }
        for a in lane_a {
            alpha_sum += a.f64();
        }
        T::c(alpha_sum / profile.weight)
    }

    /// Walks the disc of radius `r_c` (rows `-reach ..= reach`) into `profile`: its rows,
    /// ring chunks (inner end outwards, as the spans' runs), their steps and `sum S`.
    fn build_profile<const SHARP: bool>(
        &self,
        profile: &mut GatherProfile<T>,
        r_c: T,
        reach: usize,
    ) {
        profile.r_c = Some(r_c);
        profile.rows.clear();
        profile.chunk_dx.clear();
        profile.steps.clear();
        let mut weight = 0.0f64;
        let mut lane_w = [T::zero(); LANES];
        let reach = reach as isize;
        let lanes = LANES as isize;
        for dy in -reach..=reach {
            let Some(hw) = self.table.window_half_width(dy) else {
                continue;
            };
            let Some(disc) = disc_row(self.shape, self.rings, r_c.f64(), dy, hw, 1.0) else {
                continue;
            };
            if let Some((lo, hi)) = disc.interior {
                weight += (hi - lo + 1) as f64;
            }
            let c0 = profile.chunk_dx.len();
            let mut chunk = |dx0: isize| {
                let s = ring_steps::<T, SHARP>(self.table, r_c, dy, dx0);
                for l in 0..LANES {
                    lane_w[l] = lane_w[l] + s[l];
                }
                profile.chunk_dx.push(dx0);
                profile.steps.push(s);
            };
            match (disc.interior, disc.left, disc.right) {
                (None, Some((lo, hi)), _) => {
                    let mut c = lo;
                    while c <= hi {
                        chunk(c);
                        c += lanes;
                    }
                }
                (Some(_), left, right) => {
                    if let Some((lo, hi)) = left {
                        let mut c = hi - (lanes - 1);
                        while c + lanes > lo {
                            chunk(c);
                            c -= lanes;
                        }
                    }
                    if let Some((lo, hi)) = right {
                        let mut c = lo;
                        while c <= hi {
                            chunk(c);
                            c += lanes;
                        }
                    }
                }
                (None, None, _) => {}
            }
            let c1 = profile.chunk_dx.len();
            profile.rows.push((dy, disc.interior, c0, c1));
        }
        for w in lane_w {
            weight += w.f64();
        }
        profile.weight = weight;
    }
}
