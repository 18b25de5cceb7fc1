//! The reference engine: single-threaded loops that read like docs/model.md. Borders are
//! reflected on the fly; every term comes from [`crate::model`].

use crate::image::Image;
use crate::model::{self, Accumulator, ApertureEval, Coverage, PreparedLayer};
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::stack::LayerStack;
use crate::Real;

/// Renders with plain loops over every pixel, layer and window tap.
pub(crate) fn render<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Image<T> {
    let camera = &settings.camera;
    let big_r = camera.window.radius_px();
    let ri = big_r as isize;
    let aperture = ApertureEval::<T>::new(&settings.aperture);
    let tone = settings.tone();
    let coverage_kind = settings.model().coverage;
    let step = settings.model().step;
    let layers: Vec<PreparedLayer<T>> = stack
        .layers
        .iter()
        .map(|l| model::prepare_layer(l, &settings.camera, &settings.model()))
        .collect();
    let (w, h) = (stack.width, stack.height);
    let mut out = Image::new(w, h, 3);
    for py in 0..h {
        for px in 0..w {
            let at = |dx: isize, dy: isize| {
                model::reflect(py as isize + dy, h) * w + model::reflect(px as isize + dx, w)
            };
            let xi = py * w + px;
            let per_layer = layers.iter().map(|layer| {
                let (d_x, e_x) = (layer.rel_disp[xi], layer.focus_weight[xi]);
                let mut acc = Accumulator::default();
                for dy in -ri..=ri {
                    for dx in -ri..=ri {
                        if !model::in_window(dx, dy, big_r) {
                            continue; // M(x - y) = 0
                        }
                        let yi = at(dx, dy);
                        let dist = ((dx * dx + dy * dy) as f64).sqrt();
                        let gauge = settings.aperture.gauge(dx as f64, dy as f64);
                        let source = (layer.alpha[yi], layer.radius_px[yi], layer.rel_disp[yi]);
                        let c = model::masked_tap_weight(
                            step,
                            &aperture,
                            (dx, dy),
                            T::c(dist),
                            T::c(gauge),
                            source,
                            (e_x, d_x),
                        );
                        let rgb = &layer.rgb_linear[3 * yi..3 * yi + 3];
                        acc.add([rgb[0], rgb[1], rgb[2]], c);
                    }
                }
                let coverage = match coverage_kind {
                    Coverage::PaperBox => {
                        let half = model::coverage_half_size_px(layer.radius_px[xi], big_r);
                        model::box_coverage(half, |dx, dy| layer.alpha[at(dx, dy)])
                    }
                    Coverage::SoftDisc => {
                        let (r_x, _) = model::coverage_radius_px(
                            layer.radius_px[xi],
                            settings.model().coverage_radius,
                            T::c(settings.model().footprint.px()),
                        );
                        let mut disc = model::DiscCoverage::default();
                        for dy in -ri..=ri {
                            for dx in -ri..=ri {
                                if !model::in_window(dx, dy, big_r) {
                                    continue; // M(x - y) = 0
                                }
                                let dist = ((dx * dx + dy * dy) as f64).sqrt();
                                let gauge = settings.aperture.gauge(dx as f64, dy as f64);
                                let s = model::scatter_term(
                                    step,
                                    &aperture,
                                    dx,
                                    dy,
                                    T::c(dist),
                                    T::c(gauge),
                                    r_x,
                                );
                                disc.add(s, layer.alpha[at(dx, dy)]);
                            }
                        }
                        disc.value()
                    }
                };
                (acc.layer_colour(), coverage)
            });
            let linear = model::composite(per_layer);
            for (c, v) in linear.into_iter().enumerate() {
                *out.at_mut(px, py, c) = tone.encode(v);
            }
        }
        progress.advance(1);
    }
    out
}
