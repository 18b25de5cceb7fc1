//! The threaded engine: rows in parallel (rayon); each layer's planes are reflection-padded
//! once, and the window's taps (offset, distance, gauge) are precomputed. Sources with zero
//! alpha are skipped (their tap weight is exactly 0). Same model functions, same summation
//! order as the reference, so results agree to the last bit.

use super::Progress;
use crate::aperture::ApertureEval;
use crate::image::Image;
use crate::model::{self, Accumulator, PreparedLayer, Tap};
use crate::presets::RenderSettings;
use crate::stack::LayerStack;
use crate::Real;
use rayon::prelude::*;

/// One layer's per-pixel terms, reflection-padded by `R` on every side.
struct PaddedLayer<T> {
    stride: usize,
    rgb_linear: Vec<[T; 3]>,
    alpha: Vec<T>,
    rel_disp: Vec<T>,
    radius_px: Vec<T>,
    focus_weight: Vec<T>,
}

impl<T: Real> PaddedLayer<T> {
    fn new(layer: &PreparedLayer<T>, pad: usize) -> Self {
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
        }
    }
}

pub(super) fn render<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Image<T> {
    let camera = &settings.camera;
    let big_r = camera.window.radius_px();
    let aperture = ApertureEval::<T>::new(&settings.aperture);
    let taps: Vec<Tap> = model::window_taps(big_r, &settings.aperture);
    let layers: Vec<PaddedLayer<T>> = stack
        .layers
        .par_iter()
        .map(|l| PaddedLayer::new(&model::prepare_layer(l, camera), big_r))
        .collect();
    let stride = layers[0].stride;
    let offsets: Vec<isize> = taps.iter().map(|t| t.dy * stride as isize + t.dx).collect();
    let tap_geometry: Vec<(T, T)> = taps.iter().map(|t| (T::c(t.dist), T::c(t.gauge))).collect();
    let (w, h) = (stack.width, stack.height);
    let (g, off) = (T::c(camera.gamma), T::c(camera.offset));
    let mut out = Image::new(w, h, 3);
    out.data
        .par_chunks_mut(3 * w)
        .enumerate()
        .for_each(|(py, row)| {
            for px in 0..w {
                let xi = (py + big_r) * stride + px + big_r;
                let per_layer = layers.iter().map(|layer| {
                    let (d_x, e_x) = (layer.rel_disp[xi], layer.focus_weight[xi]);
                    let mut acc = Accumulator::default();
                    for ((tap, &offset), &(dist, gauge)) in
                        taps.iter().zip(&offsets).zip(&tap_geometry)
                    {
                        let yi = (xi as isize + offset) as usize;
                        let a_y = layer.alpha[yi];
                        if a_y == T::zero() {
                            continue;
                        }
                        let r_y = layer.radius_px[yi];
                        let s = model::scatter_term(&aperture, tap.dx, tap.dy, dist, gauge, r_y);
                        let o = if offset == 0 {
                            T::one()
                        } else {
                            model::occlusion(e_x, layer.rel_disp[yi], d_x)
                        };
                        acc.add(layer.rgb_linear[yi], model::tap_weight(a_y, s, r_y, o));
                    }
                    let half = model::coverage_half_size_px(layer.radius_px[xi], big_r);
                    let coverage = model::box_coverage(half, |dx, dy| {
                        layer.alpha[(xi as isize + dy * stride as isize + dx) as usize]
                    });
                    (acc.layer_colour(), coverage)
                });
                let linear = model::composite(per_layer);
                for (c, v) in linear.into_iter().enumerate() {
                    row[3 * px + c] = model::encode(v, g, off);
                }
            }
            progress.advance(1);
        });
    out
}
