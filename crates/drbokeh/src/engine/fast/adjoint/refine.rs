//! Before the fast adjoint's chain rule: the recorded sums of receivers whose weight sum is
//! of the order of the dropped tail, summed again over the whole window.

use crate::engine::fast::tiles::{source_block_max, WindowTables, FOCUS_WEIGHT_CUTOFF, ROW_BLOCK};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::model::{self, ApertureEval, Coverage, CoverageRadius, LayerAtPixel};
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
    let w = src.stride - 2 * big_r;
    let opts = settings.model();
    let ctx = RefineCtx {
        src,
        tables,
        aperture,
        block_max: source_block_max(src, |i| src.alpha[i] > T::zero()),
        widths: tables.half_widths(big_r as f64),
        coverage: opts.coverage,
        coverage_radius: opts.coverage_radius,
        footprint: T::c(opts.footprint.px()),
    };
    let rows: Vec<Vec<LayerAtPixel<T>>> = saved
        .par_chunks(w)
        .enumerate()
        .map(|(y, row)| refine_row_dispatch(&ctx, row, y))
        .collect();
    rows.concat()
}

/// What the rows of [`refine_small_weights`] share.
struct RefineCtx<'a, T> {
    src: &'a Planes<T>,
    tables: &'a WindowTables<T>,
    aperture: &'a ApertureEval<T>,
    /// [`source_block_max`] of the sources with alpha > 0.
    block_max: Vec<f64>,
    /// The whole window's half-widths.
    widths: Vec<Option<usize>>,
    coverage: Coverage,
    coverage_radius: CoverageRadius,
    footprint: T,
}

avx2_dispatch!(
    refine_row_dispatch,
    refine_row_avx2,
    refine_row,
    (ctx: &RefineCtx<'_, T>, row: &[LayerAtPixel<T>], y: usize) -> Vec<LayerAtPixel<T>>
);

/// [`refine_small_weights`] of the receivers of image row `y`. Plain loops (an iterator
/// adapter's closure would be compiled apart from this function and lose its AVX2 code
/// path); the taps in the window's row-major order.
#[inline(always)]
fn refine_row<T: Real>(
    ctx: &RefineCtx<'_, T>,
    row: &[LayerAtPixel<T>],
    y: usize,
) -> Vec<LayerAtPixel<T>> {
    let (src, tables, aperture) = (ctx.src, ctx.tables, ctx.aperture);
    let big_r = tables.big_r as isize;
    let stride = src.stride;
    let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
    let eps = T::c(model::WEIGHT_EPSILON);
    let below = T::c(REFINE_WEIGHT_BELOW);
    let blocks = y / ROW_BLOCK..=(y + 2 * tables.big_r) / ROW_BLOCK;
    // The soft disc's weight sum `Z = sum S` over the whole window depends on `r_c` only:
    // the last one evaluated, reused for the same `r_c` (the same sum, the same bits).
    let mut last_z: Option<(T, T)> = None;
    let mut out = Vec::with_capacity(row.len());
    for (x, s) in row.iter().enumerate() {
        if s.weight >= below {
            out.push(*s);
            continue;
        }
        // Any source with alpha > 0 in the window of this receiver?
        let mut occupied = false;
        for b in blocks.clone() {
            let from = b * stride + x;
            for m in &ctx.block_max[from..from + 2 * tables.big_r + 1] {
                occupied |= *m > f64::NEG_INFINITY;
            }
        }
        if !occupied {
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
        let mut acc = model::Accumulator::<T>::default();
        for dy in -big_r..=big_r {
            let Some(hw) = ctx.widths[(dy + big_r) as usize] else {
                continue;
            };
            let hw = hw as isize;
            for dx in -hw..=hw {
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
        }
        let inv = T::one() / (acc.weight + eps);
        // The soft-disc coverage has a tail as well, and dL/dC = dL/dB o / (W + eps)
        // is a ratio of the two tails there.
        let coverage = match ctx.coverage {
            Coverage::PaperBox => s.coverage,
            Coverage::SoftDisc => {
                let (r_c, _) =
                    model::coverage_radius_px(src.radius[xi], ctx.coverage_radius, ctx.footprint);
                let known = match last_z {
                    Some((r, z)) if r == r_c => Some(z),
                    _ => None,
                };
                let mut disc = model::DiscCoverage::<T>::default();
                for dy in -big_r..=big_r {
                    let Some(hw) = ctx.widths[(dy + big_r) as usize] else {
                        continue;
                    };
                    let hw = hw as isize;
                    for dx in -hw..=hw {
                        let yi = (xi as isize + dy * stride as isize + dx) as usize;
                        let a = src.alpha[yi];
                        // With `Z` known only the taps with alpha > 0 add anything (a
                        // zero term leaves the sum's bits as they are).
                        if known.is_some() && a == T::zero() {
                            continue;
                        }
                        let (sc, _) = tables.scatter_at::<false>(src.step, aperture, (dx, dy), r_c);
                        disc.add(sc, a);
                    }
                }
                match known {
                    Some(z) => disc.weight = z,
                    None => last_z = Some((r_c, disc.weight)),
                }
                disc.value()
            }
        };
        out.push(LayerAtPixel {
            weight: acc.weight,
            colour: acc.colour.map(|c| c * inv),
            coverage,
        });
    }
    out
}
