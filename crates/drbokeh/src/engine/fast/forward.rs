//! The fast schedule's forward pass: bands of rows, each with its own padded planes
//! ([`Planes::band`]); per layer, tiles of receivers bounded by the largest radius that
//! reaches them ([`super::tiles`]); runs of taps in lanes ([`super::runs`]); coverage from a
//! summed-area table (the paper's box) or a reach-bounded gather (the soft disc). With
//! recording, also the per-layer sums the adjoint needs ([`Recording`]): the same values
//! the composite used plus the ring out to the adjoint's longer reach, so a render with or
//! without recording gives the same bytes.

use super::runs::{centre_scatter, disc_sums, gather_segment, LaneReduction};
use super::tiles::{
    backward_reach, source_block_max, tile_max_radius, WindowTables, BAND_ROWS,
    FOCUS_WEIGHT_CUTOFF, TILE, TILE_ROWS,
};
use crate::engine::planes::Planes;
use crate::engine::simd::avx2_dispatch;
use crate::image::Image;
use crate::model::{self, ApertureEval, Coverage, LayerAtPixel, PixelModel};
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::stack::LayerStack;
use crate::Real;
use rayon::prelude::*;

/// Renders and counts the taps visited (source-receiver pairs evaluated).
pub(crate) fn render<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> (Image<T>, u64) {
    let (img, taps, _) = render_recording(stack, settings, progress, false);
    (img, taps)
}

/// What the fast adjoint needs from the forward pass ([`render_recording`]).
pub(super) struct Recording<T> {
    /// Per layer, per pixel: the weight sum `W`, layer colour `B` and coverage `o`.
    pub saved: Vec<Vec<LayerAtPixel<T>>>,
    /// The linear composite per pixel (before encoding).
    pub linear: Vec<[T; 3]>,
}

/// [`render`], and with `record` also the per-layer sums of every pixel (the same values
/// the composite used, so a render with or without recording gives identical bytes).
pub(super) fn render_recording<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
    record: bool,
) -> (Image<T>, u64, Option<Recording<T>>) {
    let (w, h) = (stack.width, stack.height);
    let tables = WindowTables::<T>::new(settings);
    let band_rows = BAND_ROWS.max(2 * tables.big_r);
    let aperture = ApertureEval::<T>::new(&settings.aperture);
    let tone = settings.tone();
    let options = settings.model();
    let pixel = PixelModel::<T>::new(&settings.camera, &options);
    let mut out = Image::new(w, h, 3);
    type BandRecord<T> = (Vec<Vec<LayerAtPixel<T>>>, Vec<[T; 3]>);
    let bands: Vec<(u64, Option<BandRecord<T>>)> = out
        .data
        .par_chunks_mut(3 * w * band_rows)
        .enumerate()
        .map(|(band, chunk)| {
            let y0 = band * band_rows;
            let y1 = (y0 + band_rows).min(h);
            let mut taps = 0;
            let mut linear = vec![[T::zero(); 3]; (y1 - y0) * w];
            let mut transmittance = vec![T::one(); (y1 - y0) * w];
            let mut saved = Vec::new();
            for layer in &stack.layers {
                let b = Planes::band(layer, &pixel, options.step, (y0, y1), tables.big_r);
                let mut layer_saved = if record {
                    vec![LayerAtPixel::default(); (y1 - y0) * w]
                } else {
                    Vec::new()
                };
                taps += render_band_layer_dispatch(
                    &b,
                    settings,
                    &tables,
                    &aperture,
                    (y1 - y0, w),
                    &mut linear,
                    &mut transmittance,
                    &mut layer_saved,
                );
                saved.push(layer_saved);
            }
            for (i, lin) in linear.iter().enumerate() {
                for c in 0..3 {
                    chunk[3 * i + c] = tone.encode(lin[c]);
                }
            }
            progress.advance((y1 - y0) as u64);
            (taps, record.then_some((saved, linear)))
        })
        .collect();
    let taps = bands.iter().map(|b| b.0).sum();
    let recording = record.then(|| {
        let mut rec = Recording {
            saved: (0..stack.layers.len())
                .map(|_| Vec::with_capacity(w * h))
                .collect(),
            linear: Vec::with_capacity(w * h),
        };
        for (_, band) in bands.into_iter() {
            let (saved, linear) = band.expect("recorded");
            for (all, s) in rec.saved.iter_mut().zip(saved) {
                all.extend(s);
            }
            rec.linear.extend(linear);
        }
        rec
    });
    (out, taps, recording)
}

/// Summed-area table (f64) of a band's padded alpha, `(rows + 1) x (stride + 1)`: the
/// paper's box coverage in O(1) per receiver (also the span engine's).
pub(in crate::engine) struct AlphaSat {
    stride: usize,
    sat: Vec<f64>,
}

impl AlphaSat {
    pub(in crate::engine) fn new<T: Real>(b: &Planes<T>) -> Self {
        let s1 = b.stride + 1;
        let mut sat = vec![0.0; (b.rows + 1) * s1];
        for py in 0..b.rows {
            let mut run = 0.0;
            for px in 0..b.stride {
                run += b.alpha[py * b.stride + px].f64();
                sat[(py + 1) * s1 + px + 1] = sat[py * s1 + px + 1] + run;
            }
        }
        AlphaSat {
            stride: b.stride,
            sat,
        }
    }

    /// Sum of alpha over padded rows `r0..r1`, columns `c0..c1` (half-open).
    #[inline(always)]
    fn sum(&self, r0: usize, r1: usize, c0: usize, c1: usize) -> f64 {
        let s1 = self.stride + 1;
        self.sat[r1 * s1 + c1] - self.sat[r0 * s1 + c1] - self.sat[r1 * s1 + c0]
            + self.sat[r0 * s1 + c0]
    }

    /// The paper's box coverage of receiver `(x, y)` of the band planes `b`: the mean of
    /// alpha over the square of half-size [`model::coverage_half_size_px`].
    #[inline(always)]
    pub(in crate::engine) fn box_coverage<T: Real>(
        &self,
        b: &Planes<T>,
        x: usize,
        y: usize,
        big_r: usize,
    ) -> T {
        let half = model::coverage_half_size_px(b.radius[b.index(x, y)], big_r);
        let (r0, c0) = (y + big_r - half, x + big_r - half);
        let n = (2 * half + 1) as f64;
        T::c(self.sum(r0, r0 + 2 * half + 1, c0, c0 + 2 * half + 1) / (n * n))
    }
}

/// One layer over one band on the fast schedule (the span engine's tap path): gathers it
/// and composites it into `linear` and `transmittance` (front to back); with a non-empty
/// `saved`, also records the layer's sums out to the adjoint's reach (as the fast tape).
/// Returns the taps visited.
#[allow(clippy::too_many_arguments)]
pub(in crate::engine) fn band_layer_taps<T: Real>(
    b: &Planes<T>,
    settings: &RenderSettings,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    size: (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [LayerAtPixel<T>],
) -> u64 {
    render_band_layer_dispatch(
        b,
        settings,
        tables,
        aperture,
        size,
        linear,
        transmittance,
        saved,
    )
}

avx2_dispatch!(
    render_band_layer_dispatch,
    render_band_layer_avx2,
    render_band_layer,
    (
        b: &Planes<T>,
        settings: &RenderSettings,
        tables: &WindowTables<T>,
        aperture: &ApertureEval<T>,
        size: (usize, usize),
        linear: &mut [[T; 3]],
        transmittance: &mut [T],
        saved: &mut [LayerAtPixel<T>]
    ) -> u64
);

/// Gathers one layer over a band and composites it into `linear` (front to back); with a
/// non-empty `saved`, also records the layer's sums out to the adjoint's reach. Returns the
/// number of taps visited.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn render_band_layer<T: Real>(
    b: &Planes<T>,
    settings: &RenderSettings,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    (rows, w): (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [LayerAtPixel<T>],
) -> u64 {
    let big_r = tables.big_r;
    let mut taps = 0u64;
    let eps = T::c(model::WEIGHT_EPSILON);
    let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
    let coverage_kind = settings.model().coverage;
    let coverage_radius = settings.model().coverage_radius;
    let footprint = T::c(settings.model().footprint.px());
    // Per block of ROW_BLOCK padded rows and per padded column, the largest radius among
    // sources with alpha > 0.
    let block_max = source_block_max(b, |i| b.alpha[i] > T::zero());
    let alpha_sat = (coverage_kind == Coverage::PaperBox).then(|| AlphaSat::new(b));
    for (tile_y0, tile_x0) in (0..rows)
        .step_by(TILE_ROWS)
        .flat_map(|ty| (0..w).step_by(TILE).map(move |tx| (ty, tx)))
    {
        let tile_x1 = (tile_x0 + TILE).min(w);
        let tile_y1 = (tile_y0 + TILE_ROWS).min(rows);
        // Largest radius among sources with alpha > 0 in the tile's window.
        let max_r = tile_max_radius(
            &block_max,
            b.stride,
            big_r,
            (tile_x0, tile_x1),
            (tile_y0, tile_y1),
        );
        // Half-width of each tap row for this tile's reach (None: row unused).
        let widths: Vec<Option<usize>> = if max_r > f64::NEG_INFINITY {
            tables.half_widths(aperture.reach_px(max_r))
        } else {
            Vec::new()
        };
        // When recording for the adjoint: the half-widths out to the backward's longer
        // reach (the ring between the two is summed into the recorded sums only).
        let ring_widths: Vec<Option<usize>> = if !saved.is_empty() && !widths.is_empty() {
            tables.half_widths(backward_reach(aperture, max_r))
        } else {
            Vec::new()
        };
        for y in tile_y0..tile_y1 {
            for x in tile_x0..tile_x1 {
                let xi = b.index(x, y);
                let (d_x, e_x) = (b.rel_disp[xi], b.focus_weight[xi]);
                let mut acc = [T::zero(); 3];
                let mut weight = T::zero();
                if !widths.is_empty() {
                    let occluding = e_x >= cutoff;
                    for dy in -(big_r as isize)..=big_r as isize {
                        let Some(hw) = widths[(dy + big_r as isize) as usize] else {
                            continue;
                        };
                        let row = (xi as isize + dy * b.stride as isize) as usize;
                        let n = 2 * hw + 1;
                        taps += n as u64;
                        let (sums, wsum) = gather_segment(
                            b,
                            tables,
                            aperture,
                            row - hw,
                            n,
                            (-(hw as isize), dy),
                            d_x,
                            e_x,
                            occluding,
                        );
                        for c in 0..3 {
                            acc[c] = acc[c] + sums[c];
                        }
                        weight = weight + wsum;
                        if dy == 0 && occluding {
                            // The centre tap has O = 1; the run used O(x,x) = 1 + e (s(0) - 1).
                            let a = b.alpha[xi];
                            let (sc, _) = centre_scatter(b.step, aperture, b.radius[xi]);
                            let base = model::tap_weight_inv_area(a, sc, b.inv_area[xi], T::one());
                            let o_run = model::occlusion_fast(e_x, d_x, d_x);
                            let fix = base * (T::one() - o_run);
                            acc[0] = acc[0] + fix * b.red[xi];
                            acc[1] = acc[1] + fix * b.green[xi];
                            acc[2] = acc[2] + fix * b.blue[xi];
                            weight = weight + fix;
                        }
                    }
                }
                let inv = T::one() / (weight + eps);
                let coverage = match coverage_kind {
                    Coverage::PaperBox => alpha_sat
                        .as_ref()
                        .expect("built for the box coverage")
                        .box_coverage(b, x, y, big_r),
                    // No source with alpha > 0 in the window: o = 0 exactly.
                    Coverage::SoftDisc if widths.is_empty() => T::zero(),
                    Coverage::SoftDisc => {
                        let r_c =
                            model::coverage_radius_px(b.radius[xi], coverage_radius, footprint);
                        let reach = aperture.reach_px(r_c.0.f64());
                        let (disc, n) = disc_sums::<T, false>(
                            b,
                            tables,
                            aperture,
                            xi,
                            r_c,
                            reach,
                            LaneReduction::EachLane,
                        );
                        taps += n;
                        disc.value()
                    }
                };
                let o = y * w + x;
                let t = transmittance[o];
                let colour = acc.map(|v| v * inv);
                for c in 0..3 {
                    linear[o][c] = linear[o][c] + colour[c] * coverage * t;
                }
                transmittance[o] = t * (T::one() - coverage);
                if let Some(s) = saved.get_mut(o) {
                    let (ring, ring_weight) =
                        gather_ring(b, tables, aperture, (&widths, &ring_widths), xi, d_x, e_x);
                    let weight = weight + ring_weight;
                    let inv = T::one() / (weight + eps);
                    *s = LayerAtPixel {
                        weight,
                        colour: [0, 1, 2].map(|c| (acc[c] + ring[c]) * inv),
                        coverage,
                    };
                }
            }
        }
    }
    taps
}

/// The taps between the half-widths `inner` and `outer` of each row (the ring the recorded
/// sums add to the rendered ones): their `sum c Ilin` and `sum c`.
#[inline(always)]
fn gather_ring<T: Real>(
    b: &Planes<T>,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    (inner, outer): (&[Option<usize>], &[Option<usize>]),
    xi: usize,
    d_x: T,
    e_x: T,
) -> ([T; 3], T) {
    let big_r = tables.big_r;
    let occluding = e_x >= T::c(FOCUS_WEIGHT_CUTOFF);
    let (mut acc, mut weight) = ([T::zero(); 3], T::zero());
    for (t, (&hw_in, &hw_out)) in inner.iter().zip(outer).enumerate() {
        let Some(hw2) = hw_out else {
            continue;
        };
        let dy = t as isize - big_r as isize;
        let row = (xi as isize + dy * b.stride as isize) as usize;
        // Offsets dx in -hw2 ..= hw2 outside -hw ..= hw (all of them if the row was unused).
        let segments = match hw_in {
            Some(hw) => [
                (-(hw2 as isize), -(hw as isize) - 1),
                (hw as isize + 1, hw2 as isize),
            ],
            None => [(-(hw2 as isize), hw2 as isize), (1, 0)],
        };
        for (from, to) in segments {
            if from > to {
                continue;
            }
            let n = (to - from + 1) as usize;
            let lo = (row as isize + from) as usize;
            let (sums, wsum) =
                gather_segment(b, tables, aperture, lo, n, (from, dy), d_x, e_x, occluding);
            for c in 0..3 {
                acc[c] = acc[c] + sums[c];
            }
            weight = weight + wsum;
        }
    }
    (acc, weight)
}
