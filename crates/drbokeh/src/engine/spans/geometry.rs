//! The span engine's geometry: where a disc's soft step is flat (its interior, summed as
//! spans) and where it is not (its ring, evaluated tap by tap), row by row, for circle and
//! polygon apertures; and the padded gauge tables the ring reads.
//!
//! A source of radius `r` weighs `S(r - g)` at a receiver whose tap offset has gauge `g`
//! (the distance for the circle). Per receiver row the set `{g <= c}` is one interval of
//! columns (the gauge is convex), so a disc row splits into
//! - the **interior** `g <= r - u_in`, where `S` is replaced by 1 ([`Rings::inner_px`]);
//! - the **ring** `r - u_in < g <= r + u_out` (at most two runs), evaluated exactly;
//! - the **tail** `g > r + u_out`, dropped ([`Rings::outer_px`]).

use crate::aperture::Aperture;
use crate::model::{self, ScatterStep};
use crate::Real;

/// The relative weight error allowed per interior tap: `1 - S <= INTERIOR_DEFECT` wherever
/// the span engine takes `S = 1`.
pub const INTERIOR_DEFECT: f64 = 1e-5;

/// The sharp step's tail cut in the span render ([`Rings::forward`]), px.
pub const FORWARD_SHARP_TAIL_PX: f64 = 2.3;

/// Lanes of a ring chunk: receivers evaluated together (one AVX2 register of f32).
pub const LANES: usize = 8;

/// Columns of margin on each side of the row accumulators: a ring chunk is extended
/// outwards to [`LANES`] taps, so it reaches at most `LANES - 1` columns beyond its run.
pub const MARGIN: usize = LANES;

/// Columns of margin on each side of the gauge tables: a circle's ring profile is
/// evaluated in whole chunks from the run's inner end to `LANES - 1` columns beyond its
/// outer end, so up to `2 LANES - 2` columns beyond the window.
pub const TABLE_MARGIN: usize = 2 * LANES;

/// Ring chunks are extended outwards (away from the interior), so they evaluate some taps
/// beyond `r + u_out`; their argument `r - g` is clamped at this value, where the step is
/// below `5.4e-32` (sharp) or `2.3e-17` (paper) and stays a normal f32 (no denormal
/// stalls). Unclamped taps beyond `r + u_out` are exact model values.
pub const STEP_ARGUMENT_MIN: f64 = -12.0;

/// The widths of a disc's ring for one scatter step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rings {
    /// `u_in`: where `r - g >= u_in`, `1 - S <= INTERIOR_DEFECT`.
    pub inner_px: f64,
    /// `u_out`: where `r - g < -u_out`, the tap is dropped.
    pub outer_px: f64,
}

impl Rings {
    /// The ring widths of `step`.
    ///
    /// - Interior. Paper: `1 - S = 10 e^{-3u} / (1 + 10 e^{-3u}) <= 10 e^{-3u}`, so
    ///   `u_in = ln(10 / 1e-5) / 3 = 4.61` px; sharp: `1 - S = 1 / (1 + e^{6u}) <= e^{-6u}`,
    ///   `u_in = ln(1e5) / 6 = 1.92` px. Every interior weight is overestimated by a factor
    ///   in `[1, 1 / (1 - 1e-5)]`, so `C`, `W`, the soft-disc sums and hence `B`, `o` and
    ///   `1 - o` (weighted means of non-negative values) carry relative errors of at most
    ///   `2e-5`.
    /// - Tail. Paper: the render's own [`model::SCATTER_TAIL_PX`] (4.5 px, `S <= 1.4e-7`),
    ///   so every tap the fast engine keeps for a source alone is kept; sharp: 2.75 px,
    ///   where `S <= e^{-16.5} = 6.8e-8`, a smaller per-tap weight than the paper's tail
    ///   (the fast engine keeps the sharp step out to 4.5 px, where `S <= 2e-12`; the
    ///   difference is at most `(2 pi (r + 3) / 6) e^{-16.5} / (pi r^2 + 1/2)` of a
    ///   source's weight: below `1e-7` for every `r`).
    pub fn of(step: ScatterStep) -> Self {
        match step {
            ScatterStep::Paper => Rings {
                inner_px: (10.0 / INTERIOR_DEFECT).ln() / 3.0,
                outer_px: model::SCATTER_TAIL_PX,
            },
            ScatterStep::Sharp => Rings {
                inner_px: (1.0 / INTERIOR_DEFECT).ln() / 6.0,
                outer_px: 2.75,
            },
        }
    }

    /// The ring widths of the span render (forward): [`Rings::of`], except that the sharp
    /// step's tail is cut at `u_out = FORWARD_SHARP_TAIL_PX = 2.3` px, where
    /// `S <= e^{-13.8} = 1.01e-6` per tap. Dropped per source: at most
    /// `(2 pi (r + 3) / 6) e^{-13.8} / (pi r^2 + 1/2)` of its weight (the tail's taps,
    /// `2 pi (r + u) du` of them per `du`, weigh `e^{-6 u}`; the source's weight sums to at
    /// least its area `pi r^2 + 1/2` times `S` inside), largest at `r = 0`: `6.4e-6`, so
    /// `C`, `W`, `B` and the coverage err by at most `6.4e-6` relative (below the
    /// interior's `2e-5`; display-encoded, at most `0.44 x` that). A tap the ring still
    /// reaches beyond `r + 2.3` (chunk padding) is the exact model value. The adjoint and
    /// the coverage keep [`Rings::of`] (their sums out to `r + 2.75` or more).
    pub fn forward(step: ScatterStep) -> Self {
        match step {
            ScatterStep::Paper => Rings::of(step),
            ScatterStep::Sharp => Rings {
                outer_px: FORWARD_SHARP_TAIL_PX,
                ..Rings::of(step)
            },
        }
    }
}

/// A convex aperture's row intervals: for a gauge bound `c` and a row offset, the columns
/// whose gauge is at most `c`.
#[derive(Clone, Debug)]
pub enum Shape {
    /// `g = |v|`.
    Circle,
    /// `g(v) = max_k (n_k . v) / cos(pi / n)` over the edge normals `n_k`.
    Polygon {
        /// `(cos a_k, sin a_k)` of each edge normal.
        normals: Vec<(f64, f64)>,
        /// The apothem of the unit polygon, `cos(pi / n)`.
        apothem: f64,
    },
}

impl Shape {
    /// The shape of a circle or polygon aperture (`None` for a kernel image).
    pub fn of(aperture: &Aperture) -> Option<Self> {
        match aperture {
            Aperture::Circle => Some(Shape::Circle),
            Aperture::Polygon {
                blades,
                rotation_deg,
            } => {
                let n = *blades as f64;
                let sector = 2.0 * std::f64::consts::PI / n;
                // Aperture::gauge is largest (|v| / cos(pi/n)) where its angle to the
                // nearest normal is 0: at angles rotation + k sector.
                let rot = rotation_deg.to_radians();
                let normals = (0..*blades)
                    .map(|k| {
                        let a = rot + k as f64 * sector;
                        (a.cos(), a.sin())
                    })
                    .collect();
                Some(Shape::Polygon {
                    normals,
                    apothem: (sector / 2.0).cos(),
                })
            }
            Aperture::Kernel(_) => None,
        }
    }

    /// The gauge of offset `(vx, vy)` by this shape's formula (for tests against
    /// [`Aperture::gauge`]).
    #[cfg(test)]
    pub fn gauge(&self, vx: f64, vy: f64) -> f64 {
        match self {
            Shape::Circle => (vx * vx + vy * vy).sqrt(),
            Shape::Polygon { normals, apothem } => {
                normals
                    .iter()
                    .map(|&(nx, ny)| nx * vx + ny * vy)
                    .fold(f64::NEG_INFINITY, f64::max)
                    / apothem
            }
        }
    }

    /// The columns `vx` (an integer interval) with `gauge(sign * vx, sign * vy) <= c` (up to
    /// [`GAUGE_TOLERANCE`], so that offsets exactly on a polygon's edge are inside whatever
    /// the rounding of `b / a`) on row `vy`, or `None`. `sign = 1` for tap offsets `y - x`, `-1` for receiver offsets
    /// `x - y`. Monotone in `c`: a smaller bound gives a sub-interval.
    #[inline]
    pub fn interval(&self, c: f64, vy: isize, sign: f64) -> Option<(isize, isize)> {
        if c < 0.0 {
            return None;
        }
        let vy = vy as f64;
        match self {
            Shape::Circle => {
                let q = c * c - vy * vy;
                if q < 0.0 {
                    return None;
                }
                let h = floor_sqrt(q, q.sqrt() as isize);
                Some((-h, h))
            }
            Shape::Polygon { normals, apothem } => {
                // For all k: nx (s vx) + ny (s vy) <= c apothem.
                let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
                let cc = (c + GAUGE_TOLERANCE) * apothem;
                for &(nx, ny) in normals {
                    let a = sign * nx;
                    let b = cc - sign * ny * vy;
                    if a > 1e-12 {
                        hi = hi.min(b / a);
                    } else if a < -1e-12 {
                        lo = lo.max(b / a);
                    } else if b < 0.0 {
                        return None;
                    }
                }
                let (lo, hi) = (lo.ceil(), hi.floor());
                (lo <= hi).then_some((lo as isize, hi as isize))
            }
        }
    }
}

/// Slack of [`Shape::interval`]'s polygon test: an offset whose gauge exceeds the bound by
/// less than this counts as inside (a tie decided by rounding otherwise; either way the
/// offset's exact weight is within the interior's defect bound of 1).
pub const GAUGE_TOLERANCE: f64 = 1e-9;

/// The largest integer `h` with `h^2 <= q` (`q >= 0`), found from a guess (exact: the
/// circle's row half-width, [`Shape::interval`]; a neighbouring source's is usually right).
#[inline(always)]
pub fn floor_sqrt(q: f64, guess: isize) -> isize {
    let mut h = guess.max(0);
    while (h * h) as f64 > q {
        h -= 1;
    }
    while ((h + 1) * (h + 1)) as f64 <= q {
        h += 1;
    }
    h
}

/// The gauge of every window offset, padded by [`TABLE_MARGIN`] columns on each side, with
/// the window mask `M` folded in: entries outside the window (and in the margins) hold
/// [`GaugeTable::MASKED`] and mask 0. Row `t` is the vertical offset `t - R`, column `m` the
/// horizontal offset `m - R - TABLE_MARGIN`.
pub struct GaugeTable<T> {
    /// The window radius `R`.
    pub big_r: usize,
    /// Row length, `2R + 1 + 2 TABLE_MARGIN`.
    pub stride: usize,
    /// `(2R + 1) * stride` gauges.
    pub gauge: Vec<T>,
    /// The window mask `M` (1 inside the window, 0 outside and in the margins), laid out
    /// as the gauges.
    pub mask: Vec<T>,
    /// Per row, the largest `|offset|` inside the window (`None` if none).
    pub half_width: Vec<Option<usize>>,
}

impl<T: Real> GaugeTable<T> {
    /// Gauge value of masked entries (their mask is 0; the value keeps the step finite).
    pub const MASKED: f64 = 1.0e6;

    /// The table of `aperture`'s gauge at offsets `sign * (dx, dy)` (`sign = 1`: tap
    /// offsets `y - x`, for gathers; `-1`: receiver offsets `x - y`, for scatters).
    pub fn new(aperture: &Aperture, big_r: usize, sign: isize) -> Self {
        let r = big_r as isize;
        let stride = 2 * big_r + 1 + 2 * TABLE_MARGIN;
        let mut gauge = vec![T::c(Self::MASKED); (2 * big_r + 1) * stride];
        let mut mask = vec![T::zero(); (2 * big_r + 1) * stride];
        let mut half_width = vec![None; 2 * big_r + 1];
        for dy in -r..=r {
            let t = (dy + r) as usize;
            for dx in -r..=r {
                let (tx, ty) = (sign * dx, sign * dy);
                if model::in_window(tx, ty, big_r) {
                    gauge[t * stride + (dx + r) as usize + TABLE_MARGIN] =
                        T::c(aperture.gauge(tx as f64, ty as f64));
                    mask[t * stride + (dx + r) as usize + TABLE_MARGIN] = T::one();
                    let hw: &mut Option<usize> = &mut half_width[t];
                    *hw = Some(hw.unwrap_or(0).max(dx.unsigned_abs()));
                }
            }
        }
        GaugeTable {
            big_r,
            stride,
            gauge,
            mask,
            half_width,
        }
    }

    /// The [`LANES`] gauges of row offset `dy` from column offset `dx0`.
    #[inline(always)]
    pub fn chunk(&self, dy: isize, dx0: isize) -> &[T; LANES] {
        let t = (dy + self.big_r as isize) as usize;
        let m = (dx0 + (self.big_r + TABLE_MARGIN) as isize) as usize;
        self.gauge[t * self.stride + m..t * self.stride + m + LANES]
            .try_into()
            .expect("LANES gauges")
    }

    /// The [`LANES`] window masks of row offset `dy` from column offset `dx0`.
    #[inline(always)]
    pub fn mask_chunk(&self, dy: isize, dx0: isize) -> &[T; LANES] {
        let t = (dy + self.big_r as isize) as usize;
        let m = (dx0 + (self.big_r + TABLE_MARGIN) as isize) as usize;
        self.mask[t * self.stride + m..t * self.stride + m + LANES]
            .try_into()
            .expect("LANES")
    }

    /// The window's half-width on row `dy` (`None` if the row is outside the window).
    #[inline(always)]
    pub fn window_half_width(&self, dy: isize) -> Option<usize> {
        let r = self.big_r as isize;
        if dy < -r || dy > r {
            return None;
        }
        self.half_width[(dy + r) as usize]
    }
}

/// A circle's ring steps without a transcendental per tap. The step is
/// `S(u) = 1 / (1 + c e^{-a u})` with `u = r - g` (sharp: `a = 6, c = 1`; paper: `a = 3,
/// c = 10`), and `c e^{-a (r - g)} = [c e^{a (m - r)}] [e^{a (g - m)}]` for a fixed centre
/// `m = R / 2`: the first factor is one scalar per source ([`ExpTable::source_factor`]),
/// the second a table over the window's offsets, both in f64 (no overflow while
/// `a (R / 2 + 2 LANES + 20) < 700`, else [`ExpTable::new`] gives `None` and the ring takes
/// [`ring_steps`]). The product is clamped where [`ring_step`] clamps its argument
/// ([`STEP_ARGUMENT_MIN`]), rounded to `T`, and `S = 1 / (1 + t)` evaluated in `T`: within
/// 2 ulp of the exact step in f64 products plus `T`'s rounding of `t` and of the quotient
/// (`3e-7` relative in f32), against [`ring_step`]'s `4e-7` of its polynomial `exp` plus the
/// rounding of `g` and `r - g` to `T` (up to `6 ulp(R)`, `5e-5` relative at `R = 100`).
pub struct ExpTable {
    /// Row length (columns `dx = -origin ..= origin` of each row `|dy| = 0 ..= R`).
    stride: usize,
    /// The column of `dx = 0`, `R + 2 LANES`.
    origin: usize,
    /// `e^{a (g(dx, dy) - m)}`, 0 outside the window.
    factor: Vec<f64>,
    /// `a`, `c` and `m`.
    rate: f64,
    scale: f64,
    centre: f64,
    /// The clamp of the product, `c e^{-a STEP_ARGUMENT_MIN}`.
    max: f64,
}

impl ExpTable {
    /// The table of a circle window of radius `big_r` for `step` (`None` where f64 would
    /// overflow).
    pub fn new(step: ScatterStep, big_r: usize) -> Option<Self> {
        let (rate, scale) = match step {
            ScatterStep::Sharp => (6.0, 1.0),
            ScatterStep::Paper => (3.0, 10.0),
        };
        let centre = big_r as f64 / 2.0;
        if rate * (centre + (2 * LANES) as f64 + 20.0) >= 700.0 {
            return None;
        }
        let origin = big_r + 2 * LANES;
        let stride = 2 * origin + 1;
        let mut factor = vec![0.0; (big_r + 1) * stride];
        for dy in 0..=big_r {
            for dx in 0..=origin {
                let (x, y) = (dx as isize, dy as isize);
                if model::in_window(-x, -y, big_r) {
                    let g = ((dx * dx + dy * dy) as f64).sqrt();
                    // The circle is symmetric in dx: the same value on both sides.
                    let f = (rate * (g - centre)).exp();
                    factor[dy * stride + origin + dx] = f;
                    factor[dy * stride + origin - dx] = f;
                }
            }
        }
        Some(ExpTable {
            stride,
            origin,
            factor,
            rate,
            scale,
            centre,
            max: scale * (-rate * STEP_ARGUMENT_MIN).exp(),
        })
    }

    /// A source's factor `c e^{a (m - r)}`.
    #[inline(always)]
    pub fn source_factor(&self, r: f64) -> f64 {
        self.scale * (self.rate * (self.centre - r)).exp()
    }

    /// The table's factor `e^{a (g - m)}` at offset `(dx, dy)`, `|dx| <= R + 2 LANES`,
    /// `|dy| <= R` (0 outside the window).
    #[inline(always)]
    pub fn factor_at(&self, dy: isize, dx: isize) -> f64 {
        self.factor[dy.unsigned_abs() * self.stride + (self.origin as isize + dx) as usize]
    }

    /// The step at one offset with table factor `f > 0` ([`ExpTable::factor_at`]) for
    /// [`LANES`] sources with factors `e_r`, times `keep` (1 or 0 per lane): where kept,
    /// the same values as [`ExpTable::steps`]. Branch-free.
    #[inline(always)]
    pub fn steps_across<T: Real>(
        &self,
        f: f64,
        e_r: &[f64; LANES],
        keep: &[T; LANES],
    ) -> [T; LANES] {
        let mut s = [T::zero(); LANES];
        for l in 0..LANES {
            let t = T::c((f * e_r[l]).min(self.max));
            s[l] = keep[l] / (T::one() + t);
        }
        s
    }

    /// The steps of a source with factor `e_r` ([`ExpTable::source_factor`]) at the
    /// [`LANES`] offsets `(dx0 + l, dy)`, `-R - 2 LANES <= dx0 <= R + LANES`, times the
    /// window mask (0 outside).
    #[inline(always)]
    pub fn steps<T: Real>(&self, e_r: f64, dy: isize, dx0: isize) -> [T; LANES] {
        let at = dy.unsigned_abs() * self.stride + (self.origin as isize + dx0) as usize;
        let f: &[f64; LANES] = self.factor[at..at + LANES].try_into().expect("LANES");
        let mut s = [T::zero(); LANES];
        for l in 0..LANES {
            let t = T::c((f[l] * e_r).min(self.max));
            let inside = if f[l] > 0.0 { T::one() } else { T::zero() };
            s[l] = inside / (T::one() + t);
        }
        s
    }
}

/// One row of a disc: the interior columns and the ring runs (offsets relative to the
/// disc's centre column), clipped to the window.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiscRow {
    /// The interior `[lo, hi]`, if any.
    pub interior: Option<(isize, isize)>,
    /// The ring left of the interior (or the whole ring when there is no interior).
    pub left: Option<(isize, isize)>,
    /// The ring right of the interior.
    pub right: Option<(isize, isize)>,
}

/// The row `dy` of a disc of radius `r` with ring widths `rings`, clipped to the window's
/// half-width `window_hw`; `sign` as in [`Shape::interval`]. `None` if the row holds no tap.
#[inline(always)]
pub fn disc_row(
    shape: &Shape,
    rings: Rings,
    r: f64,
    dy: isize,
    window_hw: usize,
    sign: f64,
) -> Option<DiscRow> {
    let hw = window_hw as isize;
    let clip = |(lo, hi): (isize, isize)| {
        let (lo, hi) = (lo.max(-hw), hi.min(hw));
        (lo <= hi).then_some((lo, hi))
    };
    let outer = clip(shape.interval(r + rings.outer_px, dy, sign)?)?;
    let inner = shape.interval(r - rings.inner_px, dy, sign).and_then(clip);
    Some(match inner {
        None => DiscRow {
            interior: None,
            left: Some(outer),
            right: None,
        },
        Some((lo, hi)) => DiscRow {
            interior: Some((lo, hi)),
            left: (outer.0 < lo).then_some((outer.0, lo - 1)),
            right: (hi < outer.1).then_some((hi + 1, outer.1)),
        },
    })
}

/// The soft step of a ring tap, `S(max(r - g, STEP_ARGUMENT_MIN)) M`, with the window
/// mask `m` (1 or 0, [`GaugeTable::mask_chunk`]): branch-free.
#[inline(always)]
pub fn ring_step<T: Real, const SHARP: bool>(r: T, g: T, m: T) -> T {
    let u = (r - g).max(T::c(STEP_ARGUMENT_MIN));
    let s = if SHARP {
        model::sharp_step_fast(u)
    } else {
        model::soft_step_fast(u)
    };
    s * m
}

/// [`ring_step`] of a chunk of [`LANES`] taps of row `dy` from offset `dx0`.
#[inline(always)]
pub fn ring_steps<T: Real, const SHARP: bool>(
    table: &GaugeTable<T>,
    r: T,
    dy: isize,
    dx0: isize,
) -> [T; LANES] {
    let (g, m) = (table.chunk(dy, dx0), table.mask_chunk(dy, dx0));
    let mut s = [T::zero(); LANES];
    for l in 0..LANES {
        s[l] = ring_step::<T, SHARP>(r, g[l], m[l]);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn polygons() -> Vec<Aperture> {
        vec![
            Aperture::Polygon {
                blades: 6,
                rotation_deg: 10.0,
            },
            Aperture::Polygon {
                blades: 3,
                rotation_deg: 0.0,
            },
            Aperture::Polygon {
                blades: 5,
                rotation_deg: -33.0,
            },
        ]
    }

    #[test]
    fn shape_gauge_matches_the_aperture() {
        for a in polygons().into_iter().chain([Aperture::Circle]) {
            let shape = Shape::of(&a).unwrap();
            for i in 0..400 {
                let (vx, vy) = ((i % 29) as f64 - 14.0, (i / 29) as f64 - 7.0);
                let (g, want) = (shape.gauge(vx, vy), a.gauge(vx, vy));
                assert!((g - want).abs() < 1e-9, "{a:?} ({vx}, {vy}): {g} vs {want}");
            }
        }
    }

    #[test]
    fn intervals_hold_exactly_the_columns_within_the_gauge_bound() {
        for a in polygons().into_iter().chain([Aperture::Circle]) {
            let shape = Shape::of(&a).unwrap();
            for sign in [1.0, -1.0] {
                for c in [0.0, 0.4, 1.0, 2.5, 7.3, 19.9] {
                    for vy in -22isize..=22 {
                        let inside: Vec<isize> = (-40isize..=40)
                            .filter(|&vx| {
                                a.gauge(sign * vx as f64, sign * vy as f64) <= c + GAUGE_TOLERANCE
                            })
                            .collect();
                        let got = shape.interval(c, vy, sign);
                        match got {
                            None => assert!(inside.is_empty(), "{a:?} c {c} vy {vy}"),
                            Some((lo, hi)) => {
                                assert_eq!(
                                    inside,
                                    (lo..=hi).collect::<Vec<_>>(),
                                    "{a:?} c {c} vy {vy} sign {sign}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn ring_widths_meet_their_bounds() {
        for step in [ScatterStep::Paper, ScatterStep::Sharp] {
            let rings = Rings::of(step);
            let s_in = model::scatter_step(step, rings.inner_px);
            assert!(
                1.0 - s_in <= INTERIOR_DEFECT * 1.0001,
                "{step:?}: {}",
                1.0 - s_in
            );
            let s_out = model::scatter_step(step, -rings.outer_px);
            assert!(s_out <= 1.4e-7, "{step:?}: {s_out}");
            let forward = Rings::forward(step);
            assert_eq!(forward.inner_px, rings.inner_px);
            let s_fwd = model::scatter_step(step, -forward.outer_px);
            assert!(s_fwd <= 1.02e-6, "{step:?}: {s_fwd}");
            let s_min = model::scatter_step(step, STEP_ARGUMENT_MIN) as f32;
            assert!(s_min.is_normal() && s_min < 3e-17, "{step:?}: {s_min}");
        }
    }

    #[test]
    fn exp_table_steps_match_the_exact_step() {
        for step in [ScatterStep::Sharp, ScatterStep::Paper] {
            for big_r in [5usize, 40, 105] {
                let table = ExpTable::new(step, big_r).expect("in range");
                let mut worst: f64 = 0.0;
                for i in 0..400 {
                    let r = 0.37 + (i as f64) * (big_r as f64 + 3.0) / 400.0;
                    let e_r = table.source_factor(r);
                    let rows = [0isize, 1, 7, (big_r / 2) as isize, big_r as isize];
                    // The table holds the window's rows 0..=R only.
                    for dy in rows.into_iter().filter(|&dy| dy <= big_r as isize) {
                        let (lo, hi) = (-((big_r + 2 * LANES) as isize), big_r as isize);
                        for dx0 in (lo..=hi).step_by(3) {
                            let s32 = table.steps::<f32>(e_r, dy, dx0);
                            let s64 = table.steps::<f64>(e_r, dy, dx0);
                            for l in 0..LANES {
                                let (x, y) = (dx0 + l as isize, dy);
                                if !model::in_window(-x, -y, big_r) {
                                    assert_eq!((s32[l], s64[l]), (0.0, 0.0));
                                    continue;
                                }
                                // The circle is symmetric: lane 0 at any sign is the same.
                                for (sx, sy) in [(x, y), (-x, y), (x, -y), (-x, -y)] {
                                    assert_eq!(table.steps::<f64>(e_r, sy, sx)[0], s64[l]);
                                }
                                let g = ((x * x + y * y) as f64).sqrt();
                                let u = (r - g).max(STEP_ARGUMENT_MIN);
                                let exact = model::scatter_step(step, u);
                                for got in [s32[l] as f64, s64[l]] {
                                    worst = worst.max((got - exact).abs() / exact);
                                }
                            }
                        }
                    }
                }
                assert!(worst < 4e-7, "{step:?} R {big_r}: {worst}");
            }
        }
        assert!(ExpTable::new(ScatterStep::Sharp, 170).is_none());
        assert!(ExpTable::new(ScatterStep::Paper, 170).is_some());
    }
}
