//! The one padded plane type of the engines: a layer's per-pixel terms, reflection-padded
//! (docs/model.md, "Window and borders") and stored as separate planes (struct of arrays),
//! for the whole image or for a band of rows.

use crate::model::{self, PixelModel, PreparedLayer, ScatterStep};
use crate::stack::Layer;
use crate::Real;
use rayon::prelude::*;

/// One layer's per-pixel terms over padded rows `row0 - pad .. row0 + rows - pad` and
/// columns `-pad .. width + pad`, row-major with `stride = width + 2 pad`.
pub(crate) struct Planes<T> {
    /// Padding in pixels on every side.
    pub pad: usize,
    /// Padded width.
    pub stride: usize,
    /// Padded rows held.
    pub rows: usize,
    /// Linear colour, per channel.
    pub red: Vec<T>,
    /// Green channel.
    pub green: Vec<T>,
    /// Blue channel.
    pub blue: Vec<T>,
    /// Alpha `a`.
    pub alpha: Vec<T>,
    /// Relative disparity `d`.
    pub rel_disp: Vec<T>,
    /// Scatter radius `r` in pixels.
    pub radius: Vec<T>,
    /// `1 / A(r)`.
    pub inv_area: Vec<T>,
    /// Focus weight `e`.
    pub focus_weight: Vec<T>,
    /// The scatter step's shape (for [`model::scatter_step`] and [`model::source_area`]).
    pub step: ScatterStep,
    /// The image pixel each padded pixel mirrors.
    pub source: Vec<usize>,
}

/// For padded rows `y0 - pad .. y1 + pad` and columns `-pad .. w + pad`, the index of the
/// image pixel each mirrors ([`model::reflect`]).
fn mirror_indices(w: usize, h: usize, (y0, y1): (usize, usize), pad: usize) -> Vec<usize> {
    let stride = w + 2 * pad;
    let mut out = vec![0usize; (y1 - y0 + 2 * pad) * stride];
    out.par_chunks_mut(stride)
        .enumerate()
        .for_each(|(py, row)| {
            let sy = model::reflect(y0 as isize + py as isize - pad as isize, h);
            for (px, v) in row.iter_mut().enumerate() {
                *v = sy * w + model::reflect(px as isize - pad as isize, w);
            }
        });
    out
}

impl<T: Real> Planes<T> {
    /// The whole image, padded by `pad`, from prepared terms (each image pixel's terms
    /// computed once, then mirrored).
    pub fn padded(layer: &PreparedLayer<T>, pad: usize, step: ScatterStep) -> Self {
        let (w, h) = (layer.width, layer.height);
        let source = mirror_indices(w, h, (0, h), pad);
        let gather = |plane: &[T]| source.par_iter().map(|&i| plane[i]).collect::<Vec<T>>();
        let channel = |c: usize| {
            source
                .par_iter()
                .map(|&i| layer.rgb_linear[3 * i + c])
                .collect::<Vec<T>>()
        };
        let radius = gather(&layer.radius_px);
        Planes {
            pad,
            stride: w + 2 * pad,
            rows: h + 2 * pad,
            red: channel(0),
            green: channel(1),
            blue: channel(2),
            alpha: gather(&layer.alpha),
            rel_disp: gather(&layer.rel_disp),
            inv_area: radius
                .par_iter()
                .map(|&r| T::one() / model::source_area(step, r))
                .collect(),
            focus_weight: gather(&layer.focus_weight),
            radius,
            step,
            source,
        }
    }

    /// Padded rows `y0 - pad .. y1 + pad` of `layer`, each padded pixel's terms computed
    /// from the layer (memory bounded by the band, not the image).
    pub fn band(
        layer: &Layer<T>,
        pixel: &PixelModel<T>,
        step: ScatterStep,
        (y0, y1): (usize, usize),
        pad: usize,
    ) -> Self {
        let (w, h) = (layer.alpha.width, layer.alpha.height);
        let source = mirror_indices(w, h, (y0, y1), pad);
        let n = source.len();
        let mut b = Planes {
            pad,
            stride: w + 2 * pad,
            rows: y1 - y0 + 2 * pad,
            red: Vec::with_capacity(n),
            green: Vec::with_capacity(n),
            blue: Vec::with_capacity(n),
            alpha: Vec::with_capacity(n),
            rel_disp: Vec::with_capacity(n),
            radius: Vec::with_capacity(n),
            inv_area: Vec::with_capacity(n),
            focus_weight: Vec::with_capacity(n),
            step,
            source: Vec::new(),
        };
        for &i in &source {
            let d = pixel.rel_disp(layer.disparity.data[i]);
            let r = pixel.radius_px(d);
            let rgb = &layer.rgb_encoded.data[3 * i..3 * i + 3];
            b.red.push(pixel.linear(rgb[0], d));
            b.green.push(pixel.linear(rgb[1], d));
            b.blue.push(pixel.linear(rgb[2], d));
            b.alpha.push(layer.alpha.data[i]);
            b.rel_disp.push(d);
            b.radius.push(r);
            b.inv_area.push(T::one() / model::source_area(step, r));
            b.focus_weight.push(pixel.focus_weight(d));
        }
        b.source = source;
        b
    }

    /// Linear colour at padded index `i`.
    #[inline(always)]
    pub fn rgb(&self, i: usize) -> [T; 3] {
        [self.red[i], self.green[i], self.blue[i]]
    }

    /// Padded index of image pixel `(x, y)` (rows counted from the planes' first image row).
    #[inline(always)]
    pub fn index(&self, x: usize, y: usize) -> usize {
        (y + self.pad) * self.stride + x + self.pad
    }
}
