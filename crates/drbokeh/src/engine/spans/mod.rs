//! The span engine: the model's scatter evaluated in O(r) per source instead of O(r^2).
//!
//! A source's soft disc is flat (`S` within `1e-5` of 1) except in a ring a few pixels
//! wide around its edge. Per receiver row, the flat interior is one span, added as two
//! writes into a difference array and summed by a prefix sum per row; the ring is evaluated
//! tap by tap (exactly, in vectorised chunks); the tail beyond the ring is dropped, as the
//! fast engine drops it. Circle and polygon apertures are spans (a row of a convex shape is
//! one interval); kernel apertures stay on the tap path. Forward and adjoint side by side:
//! `scatter.rs` and `coverage.rs` (the render), `focus.rs` (the occlusion of in-focus
//! receivers), `geometry.rs` (rows, rings, gauge tables), `choice.rs` (spans or taps, per
//! band and layer).
//!
//! **Schedule.** Bands of receiver rows as in the fast engine (each with its own padded
//! planes, so memory follows the band, not the image), in parallel; per band and layer,
//! the spans or the fast engine's tap path ([`Choice`]); per sub-band of
//! [`SUB_ROWS`](scatter::SUB_ROWS) rows, every source reaching it in a fixed order, so
//! the output is the same bytes for any thread count.
//!
//! **Shared profiles.** A disc row's intervals and ring steps depend only on the radius,
//! the row offset and the window, so consecutive sources of equal radius share one
//! evaluated profile, and coverage receivers of equal coverage
//! radius share one gathered disc: exact (the same values summed in the same order), and
//! the common case in layers of constant or row-constant disparity. A run of sources in
//! adjacent columns sharing a profile is added as whole vectors (`scatter/runs.rs`: the
//! span writes as shifted copies of the run's weights, the ring as one convolution of
//! the weights with the profile's taps, once for rows `+-dy`), not source by source: the
//! same terms, summed in another fixed order. A source row of mostly distinct radii
//! (radii that vary continuously) is added in blocks of up to 8 adjacent sources instead,
//! vectorised across the sources (`scatter/blocks.rs`): one vector of steps per ring
//! column, the block's interior its smallest (columns beyond a source's own interior
//! evaluated exactly). A circle's
//! ring steps come from a table of exponentials over the window times one exponential
//! per source ([`geometry::ExpTable`]), not from an `exp` per tap: no new approximation
//! (closer to the exact step than the per-tap `exp`).
//!
//! **Approximations and their bounds** (all relative; each tested at its worst case in
//! `tests/spans.rs`):
//! 1. Interior `S := 1` where `1 - S <= 1e-5` ([`geometry::Rings::of`]): `C`, `W` and the
//!    soft-disc sums are overestimated by a factor within `1 + 1e-5`, so the layer colour
//!    `B`, the coverage `o` and `1 - o` (weighted means of non-negative values) err by at
//!    most `2e-5` relative, and the composite by at most `2e-5 (2L + 1)` relative for `L`
//!    layers.
//! 2. Tail beyond `r + u_out` dropped (paper: the fast engine's 4.5 px; sharp: 2.3 px,
//!    `S <= 1.01e-6` per tap, at most `6.4e-6` of a source's weight,
//!    [`geometry::Rings::forward`]): as the fast engine, which keeps the sharp tail to
//!    4.5 px.
//! 3. Occlusion: receivers with `e(x) < 1e-6` take `O = 1` (relative error below `1e-6`);
//!    in-focus receivers interpolate the depth step at Chebyshev points in their own
//!    disparity, `|error| <= 1e-6` per tap, so `C`, `W` err by at most `2e-6 e P`, with `P`
//!    the receiver's unoccluded weight sum ([`focus`]).
//!
//! Where the spans cannot bound these (kernel apertures; more than
//! [`MAX_NODES`](focus::MAX_NODES) interpolation points, i.e. in-focus receivers whose
//! disparities spread over more than about `0.35`, at small K), the band-layer takes the
//! tap path.

pub(super) mod adjoint;
mod choice;
mod coverage;
mod focus;
mod geometry;
mod scatter;

pub use choice::Choice;

use crate::engine::fast::forward::{band_layer_taps, AlphaSat};
use crate::engine::fast::tiles::{WindowTables, BAND_ROWS};
use crate::engine::longest_first::map_longest_first;
use crate::engine::planes::Planes;
use crate::image::Image;
use crate::model::{ApertureEval, Coverage, LayerAtPixel, PixelModel};
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::stack::LayerStack;
use crate::Real;
use coverage::{CoverageCtx, DiscGather};
use focus::{Nodes, FOCUS_CUTOFF};
use geometry::{ExpTable, GaugeTable, Rings, Shape};
use scatter::{BandLayer, SUB_ROWS};

/// What one render did: work on each path (for `RenderStats` and the benchmarks).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct SpanStats {
    /// Taps visited on the tap path.
    pub taps: u64,
    /// Ring lanes and span writes on the span path.
    pub span_work: u64,
    /// Band-layers rendered as spans.
    pub span_layers: u64,
    /// Band-layers rendered as taps.
    pub tap_layers: u64,
}

/// Renders `stack` with the span engine; `choice` says when the tap path is taken.
pub(crate) fn render<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
    choice: Choice,
) -> (Image<T>, SpanStats) {
    let (img, stats, _) = render_recording(stack, settings, progress, choice, false);
    (img, stats)
}

/// What the span adjoint needs from the forward pass ([`render_recording`]).
pub(crate) struct SpanRecording<T> {
    /// Per layer, per pixel: `W`, `B` and `o` as the composite used them (the tap path's
    /// band-layers: out to the fast adjoint's reach, as the fast tape records them).
    pub saved: Vec<Vec<LayerAtPixel<T>>>,
    /// Per layer, per image row: whether the row's band-layer took the span path.
    pub span_rows: Vec<Vec<bool>>,
}

/// [`render`], and with `record` the sums and per-row choices the adjoint needs (the
/// same bytes either way).
pub(crate) fn render_recording<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
    choice: Choice,
    record: bool,
) -> (Image<T>, SpanStats, Option<SpanRecording<T>>) {
    render_recording_to(stack, settings, progress, choice, record, None)
}

/// [`render_recording`] with the span band-layers' rings reaching `r + outer_px` instead
/// of the forward's `r + u_out` (`None`: the forward's). The band-layers' choice of spans
/// or taps is the forward's either way (it does not depend on the ring). With
/// `Some(outer_px)` the output is not the span render's bytes: only its recording is used
/// (the span adjoint's sums out to the backward's reach, `adjoint/mod.rs`).
pub(crate) fn render_recording_to<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
    choice: Choice,
    record: bool,
    outer_px: Option<f64>,
) -> (Image<T>, SpanStats, Option<SpanRecording<T>>) {
    let rings = {
        let forward = Rings::forward(settings.model().step);
        Rings {
            inner_px: forward.inner_px,
            outer_px: outer_px.unwrap_or(forward.outer_px),
        }
    };
    let (w, h) = (stack.width, stack.height);
    let tables = WindowTables::<T>::new(settings);
    let big_r = tables.big_r;
    let band_rows = SUB_ROWS.max(BAND_ROWS).max(2 * big_r);
    let aperture = ApertureEval::<T>::new(&settings.aperture);
    let shape = Shape::of(&settings.aperture);
    let options = settings.model();
    let tone = settings.tone();
    let pixel = PixelModel::<T>::new(&settings.camera, &options);
    let scatter_table = shape
        .as_ref()
        .map(|_| GaugeTable::<T>::new(&settings.aperture, big_r, -1));
    let gather_table = (shape.is_some() && options.coverage == Coverage::SoftDisc)
        .then(|| GaugeTable::<T>::new(&settings.aperture, big_r, 1));
    let exp_table = matches!(shape, Some(Shape::Circle))
        .then(|| ExpTable::new(options.step, big_r))
        .flatten();
    let mut out = Image::new(w, h, 3);
    type BandRecord<T> = (Vec<Vec<LayerAtPixel<T>>>, Vec<bool>);
    let chunks: Vec<&mut [T]> = out.data.chunks_mut(3 * w * band_rows).collect();
    let costs: Vec<f64> = (0..chunks.len())
        .map(|band| {
            let y0 = band * band_rows;
            band_cost(stack, &pixel, (y0, (y0 + band_rows).min(h)))
        })
        .collect();
    let bands: Vec<(SpanStats, BandRecord<T>)> =
        map_longest_first(chunks, &costs, |band, chunk| {
            let y0 = band * band_rows;
            let y1 = (y0 + band_rows).min(h);
            let rows = y1 - y0;
            let mut stats = SpanStats::default();
            let mut linear = vec![[T::zero(); 3]; rows * w];
            let mut transmittance = vec![T::one(); rows * w];
            let mut record_saved = Vec::new();
            let mut record_spans = Vec::new();
            for layer in &stack.layers {
                let mut saved = if record {
                    vec![LayerAtPixel::default(); rows * w]
                } else {
                    Vec::new()
                };
                let b = Planes::band(layer, &pixel, options.step, (y0, y1), big_r);
                let plan = match (&shape, &scatter_table) {
                    (Some(shape), Some(table)) => {
                        let nodes = band_nodes(&b, (rows, w));
                        match nodes {
                            Ok(nodes) if choice.spans(&b, settings, &tables, (rows, w)) => {
                                Some((shape, table, nodes))
                            }
                            _ => None,
                        }
                    }
                    _ => None,
                };
                let Some((shape, table, nodes)) = plan else {
                    stats.tap_layers += 1;
                    stats.taps += band_layer_taps(
                        &b,
                        settings,
                        &tables,
                        &aperture,
                        (rows, w),
                        &mut linear,
                        &mut transmittance,
                        &mut saved,
                    );
                    record_saved.push(saved);
                    record_spans.push(false);
                    continue;
                };
                stats.span_layers += 1;
                let coverage = match options.coverage {
                    Coverage::PaperBox => CoverageCtx::Box {
                        b: &b,
                        sat: AlphaSat::new(&b),
                        big_r,
                    },
                    Coverage::SoftDisc => CoverageCtx::Disc(Box::new(DiscGather::new(
                        &b,
                        shape,
                        gather_table.as_ref().expect("built for the soft disc"),
                        options.coverage_radius,
                        options.footprint.px(),
                    ))),
                };
                let ctx = BandLayer {
                    b: &b,
                    width: w,
                    rows,
                    shape,
                    rings,
                    table,
                    exp: exp_table.as_ref(),
                    nodes: nodes.as_ref(),
                    coverage: &coverage,
                };
                for (s, (lin, tr)) in linear
                    .chunks_mut(SUB_ROWS * w)
                    .zip(transmittance.chunks_mut(SUB_ROWS * w))
                    .enumerate()
                {
                    let sy0 = s * SUB_ROWS;
                    let sy1 = (sy0 + SUB_ROWS).min(ctx.rows);
                    let sv = if record {
                        &mut saved[sy0 * w..sy1 * w]
                    } else {
                        &mut []
                    };
                    stats.span_work += scatter::render_sub_band(&ctx, (sy0, sy1), lin, tr, sv);
                }
                record_saved.push(saved);
                record_spans.push(true);
            }
            for (i, lin) in linear.iter().enumerate() {
                for c in 0..3 {
                    chunk[3 * i + c] = tone.encode(lin[c]);
                }
            }
            progress.advance(rows as u64);
            (stats, (record_saved, record_spans))
        });
    let total = bands
        .iter()
        .map(|b| &b.0)
        .fold(SpanStats::default(), |a, s| SpanStats {
            taps: a.taps + s.taps,
            span_work: a.span_work + s.span_work,
            span_layers: a.span_layers + s.span_layers,
            tap_layers: a.tap_layers + s.tap_layers,
        });
    let recording = record.then(|| {
        let n = stack.layers.len();
        let mut rec = SpanRecording {
            saved: (0..n).map(|_| Vec::with_capacity(w * h)).collect(),
            span_rows: (0..n).map(|_| Vec::with_capacity(h)).collect(),
        };
        for (band, (_, (saved, spans))) in bands.into_iter().enumerate() {
            let rows = (h - band * band_rows).min(band_rows);
            for (l, (s, span)) in saved.into_iter().zip(spans).enumerate() {
                rec.saved[l].extend(s);
                rec.span_rows[l].extend(std::iter::repeat(span).take(rows));
            }
        }
        rec
    });
    (out, total, recording)
}

/// A band's predicted cost, for the order in which bands are rendered: `r + 1` summed
/// over every fourth row and column of its visible sources (a source's ring taps and
/// span writes grow with its radius `r`). Only the order of the bands depends on it.
fn band_cost<T: Real>(
    stack: &LayerStack<T>,
    pixel: &PixelModel<T>,
    (y0, y1): (usize, usize),
) -> f64 {
    let mut cost = 0.0;
    for layer in &stack.layers {
        for y in (y0..y1).step_by(4) {
            for x in (0..stack.width).step_by(4) {
                if layer.alpha.at(x, y, 0) > T::zero() {
                    let d = pixel.rel_disp(layer.disparity.at(x, y, 0));
                    cost += pixel.radius_px(d).f64() + 1.0;
                }
            }
        }
    }
    cost
}

/// The interpolation points for the band's in-focus receivers: `Ok(None)` if there are
/// none, `Err(())` if they need more than the most points (the tap path then).
fn band_nodes<T: Real>(b: &Planes<T>, (rows, w): (usize, usize)) -> Result<Option<Nodes>, ()> {
    let cutoff = T::c(FOCUS_CUTOFF);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for y in 0..rows {
        let row = b.index(0, y);
        for x in 0..w {
            if b.focus_weight[row + x] >= cutoff {
                let d = b.rel_disp[row + x].f64();
                lo = lo.min(d);
                hi = hi.max(d);
            }
        }
    }
    if lo > hi {
        return Ok(None);
    }
    Nodes::new(lo, hi).map(Some).ok_or(())
}
