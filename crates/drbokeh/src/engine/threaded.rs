//! The threaded engine: rows in parallel (rayon); each layer's planes are reflection-padded
//! once, and the window's taps (offset, distance, gauge) are precomputed. Sources with zero
//! alpha are skipped (their tap weight is exactly 0). Same model functions, same summation
//! order as the reference, so results agree to the last bit.

use super::Progress;
use crate::aperture::ApertureEval;
use crate::image::Image;
use crate::model::{self, Accumulator, PreparedLayer, Tap};
use crate::presets::{Coverage, RenderSettings};
use crate::stack::LayerStack;
use crate::Real;
use rayon::prelude::*;

/// One layer's per-pixel terms, reflection-padded by `R` on every side.
pub(super) struct PaddedLayer<T> {
    pub stride: usize,
    pub rgb_linear: Vec<[T; 3]>,
    pub alpha: Vec<T>,
    pub rel_disp: Vec<T>,
    pub radius_px: Vec<T>,
    pub focus_weight: Vec<T>,
    /// For each padded pixel, the index of the source pixel it mirrors.
    pub source: Vec<usize>,
}

impl<T: Real> PaddedLayer<T> {
    pub fn new(layer: &PreparedLayer<T>, pad: usize) -> Self {
        let (w, h) = (layer.width, layer.height);
        let (pw, ph) = (w + 2 * pad, h + 2 * pad);
        let source: Vec<usize> = (0..ph)
            .flat_map(|py| {
                let sy = model::reflect(py as isize - pad as isize, h);
                (0..pw).map(move |px| sy * w + model::reflect(px as isize - pad as isize, w))
            })
            .collect();
        let gather = |plane: &[T]| source.iter().map(|&i| plane[i]).collect::<Vec<T>>();
        PaddedLayer {
            stride: pw,
            rgb_linear: source
                .iter()
                .map(|&i| {
                    let c = &layer.rgb_linear[3 * i..3 * i + 3];
                    [c[0], c[1], c[2]]
                })
                .collect(),
            alpha: gather(&layer.alpha),
            rel_disp: gather(&layer.rel_disp),
            radius_px: gather(&layer.radius_px),
            focus_weight: gather(&layer.focus_weight),
            source,
        }
    }
}

/// What every pass over the window needs: the taps, their padded-index offsets and geometry.
pub(super) struct Kernel<T> {
    pub big_r: usize,
    pub aperture: ApertureEval<T>,
    pub taps: Vec<Tap>,
    pub offsets: Vec<isize>,
    pub geometry: Vec<(T, T)>,
    pub coverage: Coverage,
    pub coverage_radius: crate::presets::CoverageRadius,
    pub footprint_px: T,
    pub step: crate::presets::ScatterStep,
}

impl<T: Real> Kernel<T> {
    pub fn new(settings: &RenderSettings, stride: usize) -> Self {
        let big_r = settings.camera.window.radius_px();
        let taps = model::window_taps(big_r, &settings.aperture);
        Kernel {
            big_r,
            aperture: ApertureEval::new(&settings.aperture),
            offsets: taps.iter().map(|t| t.dy * stride as isize + t.dx).collect(),
            geometry: taps.iter().map(|t| (T::c(t.dist), T::c(t.gauge))).collect(),
            taps,
            coverage: settings.model().coverage,
            coverage_radius: settings.model().coverage_radius,
            footprint_px: T::c(settings.model().footprint.px()),
            step: settings.model().step,
        }
    }

    /// Every masked tap with its padded-index offset, distance and gauge.
    #[inline(always)]
    pub fn taps(&self) -> impl Iterator<Item = (&Tap, isize, T, T)> + '_ {
        self.taps
            .iter()
            .zip(&self.offsets)
            .zip(&self.geometry)
            .map(|((tap, &offset), &(dist, gauge))| (tap, offset, dist, gauge))
    }

    /// Gathers one layer at padded receiver index `xi`: the accumulated sums and coverage.
    #[inline]
    pub fn gather(&self, layer: &PaddedLayer<T>, xi: usize) -> (Accumulator<T>, T) {
        let (d_x, e_x) = (layer.rel_disp[xi], layer.focus_weight[xi]);
        let mut acc = Accumulator::default();
        for (tap, offset, dist, gauge) in self.taps() {
            let yi = (xi as isize + offset) as usize;
            let a_y = layer.alpha[yi];
            if a_y == T::zero() {
                continue;
            }
            let r_y = layer.radius_px[yi];
            let s =
                model::scatter_term(self.step, &self.aperture, tap.dx, tap.dy, dist, gauge, r_y);
            let o = if offset == 0 {
                T::one()
            } else {
                model::occlusion(e_x, layer.rel_disp[yi], d_x)
            };
            acc.add(
                layer.rgb_linear[yi],
                model::tap_weight(self.step, a_y, s, r_y, o),
            );
        }
        (acc, self.coverage(layer, xi))
    }

    /// The layer coverage `o(x)` at padded receiver index `xi`.
    #[inline]
    pub fn coverage(&self, layer: &PaddedLayer<T>, xi: usize) -> T {
        match self.coverage {
            Coverage::PaperBox => {
                let half = model::coverage_half_size_px(layer.radius_px[xi], self.big_r);
                let stride = layer.stride as isize;
                model::box_coverage(half, |dx, dy| {
                    layer.alpha[(xi as isize + dy * stride + dx) as usize]
                })
            }
            Coverage::SoftDisc => self.disc_coverage(layer, xi, false).value(),
        }
    }

    /// The soft-disc coverage sums at padded receiver index `xi`, in tap order; with
    /// `derivative`, also the sums of `dS/dr(x)` (already times `dr_c/dr(x)`).
    #[inline]
    pub fn disc_coverage(
        &self,
        layer: &PaddedLayer<T>,
        xi: usize,
        derivative: bool,
    ) -> model::DiscCoverage<T> {
        let (r_x, dr) =
            model::coverage_radius_px(layer.radius_px[xi], self.coverage_radius, self.footprint_px);
        let mut disc = model::DiscCoverage::default();
        for (tap, offset, dist, gauge) in self.taps() {
            let a_y = layer.alpha[(xi as isize + offset) as usize];
            if derivative {
                let (s, ds) = model::scatter_term_with_derivative(
                    self.step,
                    &self.aperture,
                    tap.dx,
                    tap.dy,
                    dist,
                    gauge,
                    r_x,
                );
                disc.add_with_derivative(s, ds * dr, a_y);
            } else {
                let s = model::scatter_term(
                    self.step,
                    &self.aperture,
                    tap.dx,
                    tap.dy,
                    dist,
                    gauge,
                    r_x,
                );
                disc.add(s, a_y);
            }
        }
        disc
    }
}

/// Prepares and pads every layer of a stack.
pub(super) fn pad_layers<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
) -> Vec<PaddedLayer<T>> {
    let big_r = settings.camera.window.radius_px();
    stack
        .layers
        .par_iter()
        .map(|l| PaddedLayer::new(&model::prepare_layer(l, settings), big_r))
        .collect()
}

pub(super) fn render<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Image<T> {
    let layers = pad_layers(stack, settings);
    let stride = layers[0].stride;
    let kernel = Kernel::new(settings, stride);
    let big_r = kernel.big_r;
    let (w, h) = (stack.width, stack.height);
    let tone = settings.tone();
    let mut out = Image::new(w, h, 3);
    out.data
        .par_chunks_mut(3 * w)
        .enumerate()
        .for_each(|(py, row)| {
            for px in 0..w {
                let xi = (py + big_r) * stride + px + big_r;
                let linear = model::composite(layers.iter().map(|layer| {
                    let (acc, coverage) = kernel.gather(layer, xi);
                    (acc.layer_colour(), coverage)
                }));
                for (c, v) in linear.into_iter().enumerate() {
                    row[3 * px + c] = tone.encode(v);
                }
            }
            progress.advance(1);
        });
    out
}
