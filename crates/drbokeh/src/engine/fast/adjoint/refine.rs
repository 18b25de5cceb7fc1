//! Before the fast adjoint's chain rule: the recorded sums of receivers whose weight sum is
//! of the order of the dropped tail, summed again over the whole window.

use crate::engine::fast::tiles::{source_block_max, WindowTables, FOCUS_WEIGHT_CUTOFF, ROW_BLOCK};
use crate::engine::planes::Planes;
use crate::model::{self, ApertureEval, Coverage, LayerAtPixel};
use crate::presets::RenderSettings;
use crate::Real;
use rayon::prelude::*;

/// Recorded weight sums below this are recomputed over the whole window before the
/// backward pass ([`refine_small_weights`]). The dropped tail weighs at most about 6e-6 per
/// unit alpha (`model::SCATTER_TAIL_PX`), so above this B is within 6e-4 of the exact
/// value even in the worst case (measured: ~1e-8 on the test scenes), and below it the
/// exact sums are cheap enough: such receivers lie in a layer's (nearly) empty regions.
pub(in crate::engine) const REFINE_WEIGHT_BELOW: f64 = 1e-2;

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
    let big_r = tables.big_r;
    let (w, stride) = (src.stride - 2 * big_r, src.stride);
    let block_max = source_block_max(src, |i| src.alpha[i] > T::zero());
    let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
    let eps = T::c(model::WEIGHT_EPSILON);
    let below = T::c(REFINE_WEIGHT_BELOW);
    let opts = settings.model();
    let footprint = T::c(opts.footprint.px());
    let window = tables.big_r as f64;
    let widths = tables.half_widths(window);
    saved
        .par_chunks(w)
        .enumerate()
        .flat_map_iter(|(y, row)| {
            // Any source with alpha > 0 in the window of this row's receivers?
            let blocks = y / ROW_BLOCK..=(y + 2 * big_r) / ROW_BLOCK;
            let occupied: Vec<bool> = (0..w)
                .map(|x| {
                    blocks.clone().any(|b| {
                        block_max[b * stride + x..b * stride + x + 2 * big_r + 1]
                            .iter()
                            .any(|m| *m > f64::NEG_INFINITY)
                    })
                })
                .collect();
            let widths = &widths;
            row.iter().enumerate().map(move |(x, s)| {
                if s.weight >= below || !occupied[x] {
                    return *s;
                }
                let xi = src.index(x, y);
                let d_x = src.rel_disp[xi];
                // Below the cutoff the fast engine takes O = 1 (a zero focus weight).
                let e_x = match src.focus_weight[xi] {
                    e if e < cutoff => T::zero(),
                    e => e,
                };
                let mut acc = model::Accumulator::<T>::default();
                for (dx, dy) in tables.taps_within(widths) {
                    let yi = (xi as isize + dy * stride as isize + dx) as usize;
                    let a = src.alpha[yi];
                    if a == T::zero() {
                        continue;
                    }
                    let (dist, gauge) = tables.geometry(dx, dy);
                    let c = model::masked_tap_weight(
                        src.step,
                        aperture,
                        (dx, dy),
                        dist,
                        gauge,
                        (a, src.radius[yi], src.rel_disp[yi]),
                        (e_x, d_x),
                    );
                    acc.add(src.rgb(yi), c);
                }
                let inv = T::one() / (acc.weight + eps);
                // The soft-disc coverage has a tail as well, and dL/dC = dL/dB o / (W + eps)
                // is a ratio of the two tails there.
                let coverage = match opts.coverage {
                    Coverage::PaperBox => s.coverage,
                    Coverage::SoftDisc => {
                        let (r_c, _) = model::coverage_radius_px(
                            src.radius[xi],
                            opts.coverage_radius,
                            footprint,
                        );
                        let mut disc = model::DiscCoverage::<T>::default();
                        for (dx, dy) in tables.taps_within(widths) {
                            let yi = (xi as isize + dy * stride as isize + dx) as usize;
                            let (sc, _) =
                                tables.scatter_at::<false>(src.step, aperture, (dx, dy), r_c);
                            disc.add(sc, src.alpha[yi]);
                        }
                        disc.value()
                    }
                };
                LayerAtPixel {
                    weight: acc.weight,
                    colour: acc.colour.map(|c| c * inv),
                    coverage,
                }
            })
        })
        .collect()
}
