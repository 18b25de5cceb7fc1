//! Spans or taps, per band and layer: the predicted work of each path.
//!
//! - Taps (the fast engine): per tile of receivers, the window taps within the reach of
//!   the largest radius that reaches the tile (`model::SCATTER_TAIL_PX` beyond it), as the
//!   fast engine visits them: `~ pi (r_max + 4.5)^2` per receiver.
//! - Spans: per source with alpha > 0 and per disc row in the band, about
//!   [`SPAN_ROW_COST`] tap-equivalents (two ring chunks of 8 lanes and the span's writes),
//!   plus the scan of candidate sources per sub-band.
//!
//! The costs are in units of one tap of the fast engine's inner loop; the constants were
//! measured with `drbokeh bench` (radius sweep, spans vs fast rows).

use super::geometry::Rings;
use super::scatter::SUB_ROWS;
use crate::engine::fast::tiles::{
    source_block_max, tile_max_radius, WindowTables, TILE, TILE_ROWS,
};
use crate::engine::planes::Planes;
use crate::model;
use crate::presets::RenderSettings;
use crate::Real;

/// The cost of one disc row on the span path, in taps of the fast engine. Measured with
/// `drbokeh bench --quick` (radius sweep, spans and fast rows of one run, preset physical,
/// 256 x 256, uniform radius): r 5 px, fast 19.3 ns per tap, spans 95 ns per disc row
/// (4.9 taps); r 10 px, 14.1 ns per tap, 82 ns per disc row (5.8 taps). The earlier 12
/// made `auto` take the taps on band-layers where the spans were faster (`auto` 1.26-1.4x
/// slower than `spans` on the mixed workloads of the same run).
pub const SPAN_ROW_COST: f64 = 5.5;

/// The cost of scanning one candidate source of a sub-band, in taps.
pub const SCAN_COST: f64 = 0.5;

/// When the span engine takes the tap path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Choice {
    /// Spans wherever they are bounded (circle and polygon apertures, few enough
    /// interpolation points).
    Spans,
    /// Per band and layer, the path with the smaller predicted work.
    Auto,
}

impl Choice {
    /// Whether the band-layer `b` (receivers `rows x w`) takes the span path.
    pub(super) fn spans<T: Real>(
        self,
        b: &Planes<T>,
        settings: &RenderSettings,
        tables: &WindowTables<T>,
        size: (usize, usize),
    ) -> bool {
        match self {
            Choice::Spans => true,
            Choice::Auto => {
                let (spans, taps) = predicted_work(b, settings, tables, size);
                spans < taps
            }
        }
    }
}

/// The predicted work `(spans, taps)` of a band-layer, in taps of the fast engine.
pub(super) fn predicted_work<T: Real>(
    b: &Planes<T>,
    settings: &RenderSettings,
    tables: &WindowTables<T>,
    (rows, w): (usize, usize),
) -> (f64, f64) {
    let big_r = tables.big_r;
    let outer = Rings::of(b.step).outer_px;
    let mut spans = 0.0;
    let pad = b.pad as isize;
    for py in 0..b.rows {
        let ys = py as isize - pad;
        for px in 0..b.stride {
            let i = py * b.stride + px;
            if b.alpha[i] == T::zero() {
                continue;
            }
            let reach = (b.radius[i].f64() + outer).min(big_r as f64).floor() as isize;
            let lo = (ys - reach).max(0);
            let hi = (ys + reach).min(rows as isize - 1);
            if lo <= hi {
                spans += (hi - lo + 1) as f64;
            }
        }
    }
    spans *= SPAN_ROW_COST;
    let sub_bands = rows.div_ceil(SUB_ROWS) as f64;
    spans += SCAN_COST * sub_bands * (SUB_ROWS + 2 * big_r) as f64 * b.stride as f64;
    let block_max = source_block_max(b, |i| b.alpha[i] > T::zero());
    let options = settings.model();
    let footprint = options.footprint.px();
    let mut taps = 0.0;
    let window = std::f64::consts::PI * (big_r as f64).powi(2);
    for ty in (0..rows).step_by(TILE_ROWS) {
        for tx in (0..w).step_by(TILE) {
            let (x1, y1) = ((tx + TILE).min(w), (ty + TILE_ROWS).min(rows));
            let r = tile_max_radius(&block_max, b.stride, big_r, (tx, x1), (ty, y1));
            if r > f64::NEG_INFINITY {
                let reach = r + model::SCATTER_TAIL_PX;
                let per = (std::f64::consts::PI * reach * reach).min(window);
                taps += per * ((x1 - tx) * (y1 - ty)) as f64;
                if options.coverage == model::Coverage::SoftDisc {
                    // The fast engine gathers every receiver's soft disc.
                    for y in ty..y1 {
                        for x in tx..x1 {
                            let (r_c, _) = model::coverage_radius_px(
                                b.radius[b.index(x, y)].f64(),
                                options.coverage_radius,
                                footprint,
                            );
                            let reach = r_c + model::SCATTER_TAIL_PX;
                            taps += (std::f64::consts::PI * reach * reach).min(window);
                        }
                    }
                }
            }
        }
    }
    (spans, taps)
}
