//! The fast engine: the same model, evaluated only where it matters.
//!
//! - **Bands**: output rows are processed in bands of at least [`BAND_ROWS`] (and `2R`,
//!   so padding stays at most half of a band's work); each band builds its
//!   own reflection-padded planes (rows `y0 - R .. y1 + R`), so memory is bounded by the
//!   band size, not the image (a 24-MP render never holds full-size padded planes).
//! - **Tiles and reach**: a source of radius `r` reaches at most `r + 4.5` pixels
//!   ([`model::SCATTER_TAIL_PX`]: beyond it `S <= 1.4e-7`, and the dropped ring weighs
//!   below 6e-6 of the kept weight). For each tile of
//!   [`TILE`] x [`TILE_ROWS`] receivers, the largest radius among sources with alpha > 0 inside the
//!   tile's window bounds the taps every receiver in it must visit; a tile whose window
//!   holds no source skips the layer entirely. Cost grows with the actual blur radii, not
//!   with `L^2`.
//! - **Precomputed terms**: per padded pixel `r`, `1/r^2`, `d`, alpha and linear colour
//!   in separate planes (struct of arrays); per receiver `e(x)`.
//! - **Vectorisable inner loop**: contiguous `dx` runs with a branch-free body;
//!   `exp` is [`Real::exp_fast`] (f32: polynomial, < 4e-7 relative error) and `tanh` is
//!   written through it. Where `e(x) < 1e-9` the occlusion term is 1 to within 1e-9 and
//!   is not evaluated.
//! - **Coverage**: the paper's box from a summed-area table (f64) of the padded alpha, O(1)
//!   per pixel; the soft-disc coverage (preset `physical`) as a gather bounded by the
//!   receiver's own reach `r(x) + tail` ([`ApertureEval::reach_px`]): the dropped ring
//!   weighs below 2e-6 against a weight sum of at least 2/3 (the centre tap).
//!
//! Kernel apertures use the model's scalar scatter term inside the same tile bounds.
//! Output agrees with the reference engine to about 1e-6 in linear light (tested to
//! 1e-5), and is identical for any thread count (each pixel is computed by one task in a
//! fixed order).

use super::adjoint::Saved;
use super::Progress;
use crate::aperture::ApertureEval;
use crate::image::Image;
use crate::model;
use crate::presets::{Coverage, RenderSettings, ScatterStep};
use crate::stack::{Layer, LayerStack};
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

/// One layer's per-pixel terms over a band's padded rows, as separate planes.
struct BandLayer<T> {
    stride: usize,
    rows: usize,
    red: Vec<T>,
    green: Vec<T>,
    blue: Vec<T>,
    alpha: Vec<T>,
    rel_disp: Vec<T>,
    radius: Vec<T>,
    inv_area: Vec<T>,
    /// The scatter step's shape (for [`model::scatter_step`] and [`model::source_area`]).
    step: ScatterStep,
    /// Summed-area table of alpha, (rows + 1) x (stride + 1), f64.
    alpha_sat: Vec<f64>,
}

impl<T: Real> BandLayer<T> {
    /// Padded rows `y0 - pad .. y1 + pad` and columns `-pad .. w + pad` of `layer`.
    fn new(layer: &Layer<T>, settings: &RenderSettings, y0: usize, y1: usize, pad: usize) -> Self {
        let cam = &settings.camera;
        let (w, h) = (layer.alpha.width, layer.alpha.height);
        let (stride, rows) = (w + 2 * pad, y1 - y0 + 2 * pad);
        let (k, f) = (T::c(cam.blur_k), T::c(cam.focus_disparity));
        let tone = settings.tone();
        let footprint = T::c(settings.model().footprint.px());
        let step = settings.model().step;
        let n = stride * rows;
        let mut b = BandLayer {
            stride,
            rows,
            red: Vec::with_capacity(n),
            green: Vec::with_capacity(n),
            blue: Vec::with_capacity(n),
            alpha: Vec::with_capacity(n),
            rel_disp: Vec::with_capacity(n),
            radius: Vec::with_capacity(n),
            inv_area: Vec::with_capacity(n),
            step,
            alpha_sat: vec![0.0; (rows + 1) * (stride + 1)],
        };
        // Linear colour per source pixel of the rows we need (highlight needs d).
        for py in 0..rows {
            let sy = model::reflect(y0 as isize + py as isize - pad as isize, h);
            for px in 0..stride {
                let sx = model::reflect(px as isize - pad as isize, w);
                let i = sy * w + sx;
                let d = model::relative_disparity(layer.disparity.data[i], f);
                let r = model::scatter_radius_px(k, d, footprint);
                let rgb = &layer.rgb_encoded.data[3 * i..3 * i + 3];
                let lin =
                    |v: T| model::source_linear_with_derivatives(v, d, cam.highlight, &tone).0;
                b.red.push(lin(rgb[0]));
                b.green.push(lin(rgb[1]));
                b.blue.push(lin(rgb[2]));
                b.alpha.push(layer.alpha.data[i]);
                b.rel_disp.push(d);
                b.radius.push(r);
                b.inv_area.push(T::one() / model::source_area(step, r));
            }
        }
        let s1 = stride + 1;
        for py in 0..rows {
            let mut run = 0.0;
            for px in 0..stride {
                run += b.alpha[py * stride + px].f64();
                b.alpha_sat[(py + 1) * s1 + px + 1] = b.alpha_sat[py * s1 + px + 1] + run;
            }
        }
        b
    }

    /// Sum of alpha over padded rows `r0..r1`, columns `c0..c1` (half-open).
    #[inline(always)]
    fn alpha_box_sum(&self, r0: usize, r1: usize, c0: usize, c1: usize) -> f64 {
        let s1 = self.stride + 1;
        self.alpha_sat[r1 * s1 + c1] - self.alpha_sat[r0 * s1 + c1] - self.alpha_sat[r1 * s1 + c0]
            + self.alpha_sat[r0 * s1 + c0]
    }
}

/// Per-window tables: for each row `dy`, the gauge of every `dx` (`-R..=R`).
pub(super) struct WindowTables<T> {
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
}

/// Renders and counts the taps visited (source-receiver pairs evaluated).
pub(super) fn render<T: Real>(
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
    pub saved: Vec<Vec<Saved<T>>>,
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
    let mut out = Image::new(w, h, 3);
    type BandRecord<T> = (Vec<Vec<Saved<T>>>, Vec<[T; 3]>);
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
                let b = BandLayer::new(layer, settings, y0, y1, tables.big_r);
                let mut layer_saved = if record {
                    vec![Saved::default(); (y1 - y0) * w]
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

/// Calls [`render_band_layer`] compiled for AVX2 when the CPU has it (same arithmetic in
/// the same order, so the same bytes; only the vector width differs), else for the
/// baseline target.
#[allow(clippy::too_many_arguments)]
fn render_band_layer_dispatch<T: Real>(
    b: &BandLayer<T>,
    settings: &RenderSettings,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    size: (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [Saved<T>],
) -> u64 {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe {
                render_band_layer_avx2(
                    b,
                    settings,
                    tables,
                    aperture,
                    size,
                    linear,
                    transmittance,
                    saved,
                )
            };
        }
    }
    render_band_layer(
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

/// [`render_band_layer`] compiled with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn render_band_layer_avx2<T: Real>(
    b: &BandLayer<T>,
    settings: &RenderSettings,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    size: (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [Saved<T>],
) -> u64 {
    render_band_layer(
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

/// Gathers one layer over a band and composites it into `linear` (front to back).
/// Returns the number of taps visited.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn render_band_layer<T: Real>(
    b: &BandLayer<T>,
    settings: &RenderSettings,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    (rows, w): (usize, usize),
    linear: &mut [[T; 3]],
    transmittance: &mut [T],
    saved: &mut [Saved<T>],
) -> u64 {
    let big_r = tables.big_r;
    let mut taps = 0u64;
    let k = T::c(settings.camera.blur_k);
    let eps = T::c(model::WEIGHT_EPSILON);
    let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
    let coverage_kind = settings.model().coverage;
    let coverage_radius = settings.model().coverage_radius;
    let footprint = T::c(settings.model().footprint.px());
    // Per block of ROW_BLOCK padded rows and per padded column, the largest radius among
    // sources with alpha > 0.
    let blocks = b.rows.div_ceil(ROW_BLOCK);
    let mut block_max = vec![f64::NEG_INFINITY; blocks * b.stride];
    for py in 0..b.rows {
        let row = &mut block_max[(py / ROW_BLOCK) * b.stride..(py / ROW_BLOCK + 1) * b.stride];
        for (px, m) in row.iter_mut().enumerate() {
            let i = py * b.stride + px;
            if b.alpha[i] > T::zero() {
                *m = m.max(b.radius[i].f64());
            }
        }
    }
    for (tile_y0, tile_x0) in (0..rows)
        .step_by(TILE_ROWS)
        .flat_map(|ty| (0..w).step_by(TILE).map(move |tx| (ty, tx)))
    {
        let tile_x1 = (tile_x0 + TILE).min(w);
        let tile_y1 = (tile_y0 + TILE_ROWS).min(rows);
        // Largest radius among sources with alpha > 0 in the tile's window (padded coords:
        // receiver (x, y) sits at (x + R, y + R); its window spans x .. x + 2R, y .. y + 2R).
        let mut max_r = f64::NEG_INFINITY;
        for block in tile_y0 / ROW_BLOCK..=(tile_y1 - 1 + 2 * big_r) / ROW_BLOCK {
            let row = &block_max[block * b.stride..(block + 1) * b.stride];
            max_r = row[tile_x0..tile_x1 + 2 * big_r]
                .iter()
                .copied()
                .fold(max_r, f64::max);
        }
        // Half-width of each tap row for this tile's reach (None: row unused).
        let widths: Vec<Option<usize>> = if max_r > f64::NEG_INFINITY {
            let reach = aperture.reach_px(max_r);
            (-(big_r as isize)..=big_r as isize)
                .map(|dy| tables.half_width(dy, reach))
                .collect()
        } else {
            Vec::new()
        };
        // When recording for the adjoint: the half-widths out to the backward's longer
        // reach (the ring between the two is summed into the recorded sums only).
        let ring_widths: Vec<Option<usize>> = if !saved.is_empty() && !widths.is_empty() {
            let reach = aperture.reach_px(max_r) + RECORD_EXTRA_TAIL_PX;
            (-(big_r as isize)..=big_r as isize)
                .map(|dy| tables.half_width(dy, reach))
                .collect()
        } else {
            Vec::new()
        };
        for y in tile_y0..tile_y1 {
            for x in tile_x0..tile_x1 {
                let xi = (y + big_r) * b.stride + x + big_r;
                let d_x = b.rel_disp[xi];
                let e_x = model::focus_weight(k, d_x);
                let mut acc = [T::zero(); 3];
                let mut weight = T::zero();
                if !widths.is_empty() {
                    let occluding = e_x >= cutoff;
                    for dy in -(big_r as isize)..=big_r as isize {
                        let Some(hw) = widths[(dy + big_r as isize) as usize] else {
                            continue;
                        };
                        let row = (xi as isize + dy * b.stride as isize) as usize;
                        let gauge_row = &tables.gauge[(dy + big_r as isize) as usize];
                        let lo = row - hw;
                        let g0 = big_r - hw;
                        let n = 2 * hw + 1;
                        taps += n as u64;
                        let (sums, wsum) = match aperture {
                            ApertureEval::Gauge => {
                                gather_run(b, lo, n, &gauge_row[g0..g0 + n], d_x, e_x, occluding)
                            }
                            ApertureEval::Kernel(..) => {
                                let dist_row = &tables.dist[(dy + big_r as isize) as usize];
                                gather_run_kernel(
                                    b,
                                    aperture,
                                    lo,
                                    n,
                                    dy,
                                    -(hw as isize),
                                    &gauge_row[g0..g0 + n],
                                    &dist_row[g0..g0 + n],
                                    d_x,
                                    e_x,
                                    occluding,
                                )
                            }
                        };
                        for c in 0..3 {
                            acc[c] = acc[c] + sums[c];
                        }
                        weight = weight + wsum;
                        if dy == 0 && occluding {
                            // The centre tap has O = 1; the run used O(x,x) = 1 + e (s(0) - 1).
                            let a = b.alpha[xi];
                            let sc = match aperture {
                                ApertureEval::Gauge => model::scatter_step_fast(
                                    b.step,
                                    b.radius[xi] - gauge_row[big_r],
                                ),
                                ApertureEval::Kernel(..) => model::scatter_term(
                                    b.step,
                                    aperture,
                                    0,
                                    0,
                                    T::zero(),
                                    T::zero(),
                                    b.radius[xi],
                                ),
                            };
                            let base = a * sc * b.inv_area[xi];
                            let o_run =
                                T::one() + e_x * (model::depth_step_fast(T::zero()) - T::one());
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
                    Coverage::PaperBox => {
                        let half = model::coverage_half_size_px(b.radius[xi], big_r);
                        let (r0, c0) = (y + big_r - half, x + big_r - half);
                        let n = (2 * half + 1) as f64;
                        T::c(
                            b.alpha_box_sum(r0, r0 + 2 * half + 1, c0, c0 + 2 * half + 1) / (n * n),
                        )
                    }
                    // No source with alpha > 0 in the window: o = 0 exactly.
                    Coverage::SoftDisc if widths.is_empty() => T::zero(),
                    Coverage::SoftDisc => {
                        let (c, n) =
                            disc_coverage(b, tables, aperture, xi, coverage_radius, footprint);
                        taps += n;
                        c
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
                    *s = Saved {
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

/// How much further the sums recorded for the adjoint reach than the rendered ones
/// (`engine/fast_adjoint.rs`, `BACKWARD_EXTRA_TAIL_PX`).
pub(super) const RECORD_EXTRA_TAIL_PX: f64 = 1.5;

/// The taps between the half-widths `inner` and `outer` of each row (the ring the recorded
/// sums add to the rendered ones): their `sum c Ilin` and `sum c`.
#[inline(always)]
fn gather_ring<T: Real>(
    b: &BandLayer<T>,
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
            let g0 = (from + big_r as isize) as usize;
            let gauge = &tables.gauge[t][g0..g0 + n];
            let (sums, wsum) = match aperture {
                ApertureEval::Gauge => gather_run(b, lo, n, gauge, d_x, e_x, occluding),
                ApertureEval::Kernel(..) => gather_run_kernel(
                    b,
                    aperture,
                    lo,
                    n,
                    dy,
                    from,
                    gauge,
                    &tables.dist[t][g0..g0 + n],
                    d_x,
                    e_x,
                    occluding,
                ),
            };
            for c in 0..3 {
                acc[c] = acc[c] + sums[c];
            }
            weight = weight + wsum;
        }
    }
    (acc, weight)
}

/// Soft-disc coverage `o(x)` ([`model::DiscCoverage`]) at padded receiver `xi`, over the
/// taps within the receiver's reach `r(x) + tail`; returns it and the number of taps.
#[inline(always)]
fn disc_coverage<T: Real>(
    b: &BandLayer<T>,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    xi: usize,
    radius_kind: crate::presets::CoverageRadius,
    footprint: T,
) -> (T, u64) {
    let big_r = tables.big_r as isize;
    let (r_x, _) = model::coverage_radius_px(b.radius[xi], radius_kind, footprint);
    let reach = aperture.reach_px(r_x.f64());
    let mut disc = model::DiscCoverage::<T>::default();
    let mut taps = 0u64;
    for dy in -big_r..=big_r {
        let Some(hw) = tables.half_width(dy, reach) else {
            continue;
        };
        let row = (xi as isize + dy * b.stride as isize) as usize;
        let t = (dy + big_r) as usize;
        let g0 = tables.big_r - hw;
        let n = 2 * hw + 1;
        taps += n as u64;
        let alpha = &b.alpha[row - hw..row - hw + n];
        let gauge = &tables.gauge[t][g0..g0 + n];
        match aperture {
            ApertureEval::Gauge => {
                let (mut sa, mut sw) = ([T::zero(); LANES], [T::zero(); LANES]);
                for i in 0..n {
                    let s = model::scatter_step_fast(b.step, r_x - gauge[i]);
                    sa[i % LANES] = sa[i % LANES] + s * alpha[i];
                    sw[i % LANES] = sw[i % LANES] + s;
                }
                for l in 0..LANES {
                    disc.alpha_sum = disc.alpha_sum + sa[l];
                    disc.weight = disc.weight + sw[l];
                }
            }
            ApertureEval::Kernel(..) => {
                let dist = &tables.dist[t][g0..g0 + n];
                for i in 0..n {
                    let dx = i as isize - hw as isize;
                    let s =
                        model::scatter_term(b.step, aperture, dx, dy, T::c(dist[i]), gauge[i], r_x);
                    disc.add(s, alpha[i]);
                }
            }
        }
    }
    (disc.value(), taps)
}

/// Accumulator lanes of the gather run: independent partial sums that the compiler can
/// keep in one SIMD register each (float sums cannot be reordered otherwise).
pub(super) const LANES: usize = 8;

/// Sums `c(y,x) Ilin(y)` and `c(y,x)` over a contiguous run of `n` sources starting at
/// padded index `lo`, with the run's gauges. Branch-free body in [`LANES`] lanes
/// (vectorisable); the lane order is fixed, so results do not depend on threads.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn gather_run<T: Real>(
    b: &BandLayer<T>,
    lo: usize,
    n: usize,
    gauge: &[T],
    d_x: T,
    e_x: T,
    occluding: bool,
) -> ([T; 3], T) {
    // The step shape and occlusion are loop-invariant: one monomorphised loop each.
    match (b.step, occluding) {
        (ScatterStep::Paper, true) => gather_run_lanes::<T, true, false>(b, lo, n, gauge, d_x, e_x),
        (ScatterStep::Paper, false) => {
            gather_run_lanes::<T, false, false>(b, lo, n, gauge, d_x, e_x)
        }
        (ScatterStep::Sharp, true) => gather_run_lanes::<T, true, true>(b, lo, n, gauge, d_x, e_x),
        (ScatterStep::Sharp, false) => {
            gather_run_lanes::<T, false, true>(b, lo, n, gauge, d_x, e_x)
        }
    }
}

/// One tap's weight `c(y,x)` in the fast engine's form; `OCCLUDING = false` means `O = 1`;
/// `SHARP` selects [`ScatterStep::Sharp`] (else the paper's step).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn tap_weight_fast<T: Real, const OCCLUDING: bool, const SHARP: bool>(
    alpha: T,
    radius: T,
    gauge: T,
    inv_area: T,
    disp: T,
    d_x: T,
    e_x: T,
) -> T {
    let s = if SHARP {
        model::sharp_step_fast(radius - gauge)
    } else {
        model::soft_step_fast(radius - gauge)
    };
    let o = if OCCLUDING {
        T::one() + e_x * (model::depth_step_fast(disp - d_x) - T::one())
    } else {
        T::one()
    };
    alpha * s * inv_area * o
}

/// Taps per chunk of the gather run: weights are first computed for a chunk into a
/// scratch array (a plain map, which the compiler vectorises), then reduced in lanes.
const CHUNK: usize = 64;

#[inline(always)]
fn gather_run_lanes<T: Real, const OCCLUDING: bool, const SHARP: bool>(
    b: &BandLayer<T>,
    lo: usize,
    n: usize,
    gauge: &[T],
    d_x: T,
    e_x: T,
) -> ([T; 3], T) {
    let (mut lr, mut lg, mut lb, mut lw) = (
        [T::zero(); LANES],
        [T::zero(); LANES],
        [T::zero(); LANES],
        [T::zero(); LANES],
    );
    let mut c = [T::zero(); CHUNK];
    let mut start = 0;
    while start < n {
        let m = (n - start).min(CHUNK);
        let s0 = lo + start;
        let (alpha, radius, inv_area, disp) = (
            &b.alpha[s0..s0 + m],
            &b.radius[s0..s0 + m],
            &b.inv_area[s0..s0 + m],
            &b.rel_disp[s0..s0 + m],
        );
        let g = &gauge[start..start + m];
        for i in 0..m {
            c[i] = tap_weight_fast::<T, OCCLUDING, SHARP>(
                alpha[i],
                radius[i],
                g[i],
                inv_area[i],
                disp[i],
                d_x,
                e_x,
            );
        }
        let (red, green, blue) = (
            &b.red[s0..s0 + m],
            &b.green[s0..s0 + m],
            &b.blue[s0..s0 + m],
        );
        // Lane l sums the taps i with i % LANES == l (CHUNK is a multiple of LANES).
        let full = m / LANES * LANES;
        for base in (0..full).step_by(LANES) {
            for l in 0..LANES {
                let i = base + l;
                lr[l] = lr[l] + c[i] * red[i];
                lg[l] = lg[l] + c[i] * green[i];
                lb[l] = lb[l] + c[i] * blue[i];
                lw[l] = lw[l] + c[i];
            }
        }
        for i in full..m {
            let l = i - full;
            lr[l] = lr[l] + c[i] * red[i];
            lg[l] = lg[l] + c[i] * green[i];
            lb[l] = lb[l] + c[i] * blue[i];
            lw[l] = lw[l] + c[i];
        }
        start += m;
    }
    let sum = |v: [T; LANES]| v.iter().fold(T::zero(), |a, &b| a + b);
    ([sum(lr), sum(lg), sum(lb)], sum(lw))
}

/// [`gather_run`] for kernel apertures (scalar scatter term from the model).
#[allow(clippy::too_many_arguments)]
fn gather_run_kernel<T: Real>(
    b: &BandLayer<T>,
    aperture: &ApertureEval<T>,
    lo: usize,
    n: usize,
    dy: isize,
    dx0: isize,
    gauge: &[T],
    dist: &[f64],
    d_x: T,
    e_x: T,
    occluding: bool,
) -> ([T; 3], T) {
    let (mut acc, mut sw) = ([T::zero(); 3], T::zero());
    for i in 0..n {
        let yi = lo + i;
        let a = b.alpha[yi];
        if a == T::zero() {
            continue;
        }
        let dx = dx0 + i as isize;
        let s = model::scatter_term(
            b.step,
            aperture,
            dx,
            dy,
            T::c(dist[i]),
            gauge[i],
            b.radius[yi],
        );
        let o = if occluding {
            T::one() + e_x * (model::depth_step_fast(b.rel_disp[yi] - d_x) - T::one())
        } else {
            T::one()
        };
        let c = a * s * b.inv_area[yi] * o;
        acc[0] = acc[0] + c * b.red[yi];
        acc[1] = acc[1] + c * b.green[yi];
        acc[2] = acc[2] + c * b.blue[yi];
        sw = sw + c;
    }
    (acc, sw)
}
