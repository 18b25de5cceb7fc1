//! The threaded schedule's forward pass: the render, and the render that records the exact
//! adjoint's tape ([`super::adjoint::ThreadedTape`]).

use super::adjoint::ThreadedTape;
use super::kernel::Kernel;
use crate::engine::planes::Planes;
use crate::image::Image;
use crate::model::{self, LayerAtPixel};
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::stack::LayerStack;
use crate::Real;
use rayon::prelude::*;

/// Prepares and pads every layer of a stack by the window radius.
pub(super) fn pad_layers<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
) -> Vec<Planes<T>> {
    let big_r = settings.camera.window.radius_px();
    let options = settings.model();
    stack
        .layers
        .par_iter()
        .map(|l| {
            let prepared = model::prepare_layer(l, &settings.camera, &options);
            Planes::padded(&prepared, big_r, options.step)
        })
        .collect()
}

/// Renders with every window tap, rows in parallel.
pub(crate) fn render<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Image<T> {
    let layers = pad_layers(stack, settings);
    let kernel = Kernel::new(settings, layers[0].stride);
    let (w, h) = (stack.width, stack.height);
    let tone = settings.tone();
    let mut out = Image::new(w, h, 3);
    out.data
        .par_chunks_mut(3 * w)
        .enumerate()
        .for_each(|(py, row)| {
            for px in 0..w {
                let xi = layers[0].index(px, py);
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

/// One pixel of the recorded forward pass: per-layer sums and the linear composite.
type PixelRecord<T> = (Vec<LayerAtPixel<T>>, [T; 3]);

/// [`render`] (the same bytes), recording per pixel and layer the sums `W`, `B` and `o`
/// for the exact adjoint.
pub(crate) fn render_with_tape<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> (Image<T>, ThreadedTape<T>) {
    let tone = settings.tone();
    let layers = pad_layers(stack, settings);
    let kernel = Kernel::new(settings, layers[0].stride);
    let (w, h) = (stack.width, stack.height);
    let rows: Vec<Vec<PixelRecord<T>>> = (0..h)
        .into_par_iter()
        .map(|py| {
            let row = (0..w)
                .map(|px| {
                    let xi = layers[0].index(px, py);
                    let saved: Vec<LayerAtPixel<T>> = layers
                        .iter()
                        .map(|layer| {
                            let (acc, coverage) = kernel.gather(layer, xi);
                            LayerAtPixel {
                                weight: acc.weight,
                                colour: acc.layer_colour(),
                                coverage,
                            }
                        })
                        .collect();
                    let lin = model::composite(saved.iter().map(|s| (s.colour, s.coverage)));
                    (saved, lin)
                })
                .collect();
            progress.advance(1);
            row
        })
        .collect();
    let mut out = Image::new(w, h, 3);
    let mut saved = Vec::with_capacity(w * h);
    let mut linear = Vec::with_capacity(w * h);
    for (i, (s, lin)) in rows.into_iter().flatten().enumerate() {
        for c in 0..3 {
            out.data[3 * i + c] = tone.encode(lin[c]);
        }
        saved.push(s);
        linear.push(lin);
    }
    (
        out,
        ThreadedTape {
            settings: settings.clone(),
            stack: stack.clone(),
            layers,
            saved,
            linear,
        },
    )
}
