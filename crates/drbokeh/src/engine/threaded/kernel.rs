//! What every pass of the threaded schedule over the window needs: the taps, their
//! padded-index offsets and geometry, and the gathers of one receiver.

use crate::engine::planes::Planes;
use crate::model::{self, Accumulator, ApertureEval, Coverage, CoverageRadius, ScatterStep, Tap};
use crate::presets::RenderSettings;
use crate::Real;

/// The window's taps over planes of one stride, and the model options they are evaluated
/// with.
pub(super) struct Kernel<T> {
    pub big_r: usize,
    pub aperture: ApertureEval<T>,
    pub taps: Vec<Tap>,
    pub offsets: Vec<isize>,
    pub geometry: Vec<(T, T)>,
    pub coverage: Coverage,
    pub coverage_radius: CoverageRadius,
    pub footprint_px: T,
    pub step: ScatterStep,
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

    /// The scatter term of `tap` for a source (or disc) of radius `radius_px`, with its
    /// derivative with respect to the radius when `DERIV`.
    #[inline(always)]
    pub fn scatter<const DERIV: bool>(&self, tap: &Tap, dist: T, gauge: T, radius_px: T) -> (T, T) {
        model::scatter_term_and::<T, DERIV>(
            self.step,
            &self.aperture,
            tap.dx,
            tap.dy,
            dist,
            gauge,
            radius_px,
        )
    }

    /// Gathers one layer at padded receiver index `xi`: the accumulated sums and coverage.
    #[inline]
    pub fn gather(&self, layer: &Planes<T>, xi: usize) -> (Accumulator<T>, T) {
        let receiver = (layer.focus_weight[xi], layer.rel_disp[xi]);
        let mut acc = Accumulator::default();
        for (tap, offset, dist, gauge) in self.taps() {
            let yi = (xi as isize + offset) as usize;
            let a_y = layer.alpha[yi];
            if a_y == T::zero() {
                continue;
            }
            let c = model::masked_tap_weight(
                self.step,
                &self.aperture,
                (tap.dx, tap.dy),
                dist,
                gauge,
                (a_y, layer.radius[yi], layer.rel_disp[yi]),
                receiver,
            );
            acc.add(layer.rgb(yi), c);
        }
        (acc, self.coverage(layer, xi))
    }

    /// The layer coverage `o(x)` at padded receiver index `xi`.
    #[inline]
    pub fn coverage(&self, layer: &Planes<T>, xi: usize) -> T {
        match self.coverage {
            Coverage::PaperBox => {
                let half = model::coverage_half_size_px(layer.radius[xi], self.big_r);
                let stride = layer.stride as isize;
                model::box_coverage(half, |dx, dy| {
                    layer.alpha[(xi as isize + dy * stride + dx) as usize]
                })
            }
            Coverage::SoftDisc => self.disc_coverage::<false>(layer, xi).value(),
        }
    }

    /// The soft-disc coverage sums at padded receiver index `xi`, in tap order; with
    /// `DERIV`, also the sums of `dS/dr(x)` (already times `dr_c/dr(x)`).
    #[inline]
    pub fn disc_coverage<const DERIV: bool>(
        &self,
        layer: &Planes<T>,
        xi: usize,
    ) -> model::DiscCoverage<T> {
        let (r_x, dr) =
            model::coverage_radius_px(layer.radius[xi], self.coverage_radius, self.footprint_px);
        let mut disc = model::DiscCoverage::default();
        for (tap, offset, dist, gauge) in self.taps() {
            let a_y = layer.alpha[(xi as isize + offset) as usize];
            let (s, ds) = self.scatter::<DERIV>(tap, dist, gauge, r_x);
            if DERIV {
                disc.add_with_derivative(s, ds * dr, a_y);
            } else {
                disc.add(s, a_y);
            }
        }
        disc
    }
}
