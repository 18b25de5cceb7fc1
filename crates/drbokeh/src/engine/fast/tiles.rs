//! The fast schedule's geometry, shared by its forward and adjoint: band and tile sizes,
//! the window's per-row tables, and the reach that bounds the taps of a tile.

use crate::engine::planes::Planes;
use crate::model::{self, ApertureEval, ScatterStep};
use crate::presets::RenderSettings;
use crate::Real;
use rayon::prelude::*;

/// Output rows per band.
pub const BAND_ROWS: usize = 32;
/// Receiver columns per tile.
pub const TILE: usize = 32;
/// Receiver rows per tile.
pub const TILE_ROWS: usize = 16;
/// Rows per block of the per-column radius maxima.
pub(super) const ROW_BLOCK: usize = 8;
/// Receivers with a focus weight below this treat the occlusion term as exactly 1.
pub const FOCUS_WEIGHT_CUTOFF: f64 = 1e-9;

/// How much further than the render ([`crate::model::SCATTER_TAIL_PX`]) the adjoint keeps
/// the soft step's tail, and so how much further the sums recorded for it reach: gradient
/// sums cancel (`sum_y c(y,x) (Ilin(y) - B(x)) = 0`), so the tail matters more to them,
/// relative to their size, than to the render. With `4.5 + 1.5 = 6` px the dropped kernel
/// mass shrinks by `e^{-4.5} = 1/90`.
pub(super) const BACKWARD_EXTRA_TAIL_PX: f64 = 1.5;

/// The backward passes' reach of a source (or disc) of radius `r`.
#[inline(always)]
pub(super) fn backward_reach<T: Real>(aperture: &ApertureEval<T>, r: f64) -> f64 {
    aperture.reach_px(r) + BACKWARD_EXTRA_TAIL_PX
}

/// Per-window tables: for each row `dy`, the gauge and distance of every `dx` (`-R..=R`).
pub(in crate::engine) struct WindowTables<T> {
    pub big_r: usize,
    pub gauge: Vec<Vec<T>>,
    pub dist: Vec<Vec<f64>>,
}

impl<T: Real> WindowTables<T> {
    pub fn new(settings: &RenderSettings) -> Self {
        let big_r = settings.camera.window.radius_px();
        let r = big_r as isize;
        let rows = (-r..=r)
            .map(|dy| {
                (-r..=r)
                    .map(|dx| {
                        let dist = ((dx * dx + dy * dy) as f64).sqrt();
                        (T::c(settings.aperture.gauge(dx as f64, dy as f64)), dist)
                    })
                    .unzip::<T, f64, Vec<T>, Vec<f64>>()
            })
            .collect::<Vec<_>>();
        let (gauge, dist) = rows.into_iter().unzip();
        WindowTables { big_r, gauge, dist }
    }

    /// For row `dy`, the largest `|dx|` with `M = 1` (`dist < R`) and `dist <= reach`;
    /// `None` if no tap of the row qualifies.
    pub fn half_width(&self, dy: isize, reach: f64) -> Option<usize> {
        let row = &self.dist[(dy + self.big_r as isize) as usize];
        let r = self.big_r as f64;
        (0..=self.big_r).rev().find(|&dx| {
            let d = row[self.big_r + dx];
            d < r && d <= reach
        })
    }

    /// The model's scatter term at window offset `(dx, dy)` (`y - x`) for a source (or
    /// disc) of radius `radius_px`, with its derivative when `DERIV`: the scalar path of
    /// kernel apertures.
    #[inline(always)]
    pub fn scatter_at<const DERIV: bool>(
        &self,
        step: ScatterStep,
        aperture: &ApertureEval<T>,
        (dx, dy): (isize, isize),
        radius_px: T,
    ) -> (T, T) {
        let (dist, gauge) = self.geometry(dx, dy);
        model::scatter_term_and::<T, DERIV>(step, aperture, dx, dy, dist, gauge, radius_px)
    }

    /// The distance and gauge of window offset `(dx, dy)`.
    #[inline(always)]
    pub fn geometry(&self, dx: isize, dy: isize) -> (T, T) {
        let r = self.big_r as isize;
        let (t, g) = ((dy + r) as usize, (dx + r) as usize);
        (T::c(self.dist[t][g]), self.gauge[t][g])
    }

    /// [`WindowTables::half_width`] of every row `dy = -R ..= R`.
    pub fn half_widths(&self, reach: f64) -> Vec<Option<usize>> {
        let r = self.big_r as isize;
        (-r..=r).map(|dy| self.half_width(dy, reach)).collect()
    }

    /// The tables of the flipped offsets: `[ddy + R][ddx + R]` holds the gauge of the tap
    /// from a source y to the receiver `x = y + (ddx, ddy)`, i.e. of the offset
    /// `y - x = (-ddx, -ddy)`.
    pub fn flipped_gauge(&self) -> Vec<Vec<T>> {
        let big_r = self.big_r;
        (0..=2 * big_r)
            .map(|row| self.gauge[2 * big_r - row].iter().rev().copied().collect())
            .collect()
    }
}

/// Per block of [`ROW_BLOCK`] padded rows and per padded column, the largest source radius
/// among the pixels that `keep` (`-inf` where none does).
pub(in crate::engine) fn source_block_max<T: Real>(
    src: &Planes<T>,
    keep: impl Fn(usize) -> bool + Sync,
) -> Vec<f64> {
    let blocks = src.rows.div_ceil(ROW_BLOCK);
    (0..blocks)
        .into_par_iter()
        .flat_map_iter(|b| {
            let keep = &keep;
            (0..src.stride).map(move |px| {
                let mut m = f64::NEG_INFINITY;
                for py in b * ROW_BLOCK..((b + 1) * ROW_BLOCK).min(src.rows) {
                    let i = py * src.stride + px;
                    if keep(i) {
                        m = m.max(src.radius[i].f64());
                    }
                }
                m
            })
        })
        .collect()
}

/// The largest radius in `block_max` ([`source_block_max`]) over the window of the
/// receivers in columns `x0..x1` and rows `y0..y1` (padded coordinates: receiver (x, y)
/// sits at (x + R, y + R); its window spans x .. x + 2R, y .. y + 2R); `-inf` if none.
pub(in crate::engine) fn tile_max_radius(
    block_max: &[f64],
    stride: usize,
    big_r: usize,
    (x0, x1): (usize, usize),
    (y0, y1): (usize, usize),
) -> f64 {
    let mut max_r = f64::NEG_INFINITY;
    for block in y0 / ROW_BLOCK..=(y1 - 1 + 2 * big_r) / ROW_BLOCK {
        let row = &block_max[block * stride..(block + 1) * stride];
        max_r = row[x0..x1 + 2 * big_r]
            .iter()
            .copied()
            .fold(max_r, f64::max);
    }
    max_r
}
