//! The judges: the loss a proposal is kept or dropped by, 0.5 L1 + 10 HSSIM of the clamped
//! render of a crop against the same crop of the traced defocused image.
use crate::edges::{cut, purify, split_opts, Split};
use crate::oracle::TrueLayers;
use drbokeh::dfd::layered::LayeredModel;
use drbokeh::dfd::{render_layer_on, RenderLayer};
use drbokeh::layering::{layers_from_disparity, LayeringOptions};
use drbokeh::{Engine, Image, NoProgress, RenderSettings};

/// A judge and what it renders with.
pub struct Judge<'a> {
    /// `layered`, `single`, `truelayers`, or a layer's own render (`aperture`, `gausspsf`).
    pub kind: String,
    /// The layer of the `aperture` / `gausspsf` judges (and of the start's estimate).
    pub layer: RenderLayer,
    pub settings: RenderSettings,
    /// The all-in-focus image the judge renders (the PNG, or with `src=exr` the unclipped one).
    pub aif: Image<f32>,
    /// The image's width (the crops' offsets index into it).
    pub width: usize,
    /// The decomposition's largest number of layers.
    pub layers: usize,
    pub matting_px: usize,
    pub colour_guard_px: usize,
    pub pure_px: usize,
    /// `fit=N`: the start's mixed edge pixels and their fitted colours (full image, RGB).
    pub fitted: Option<(Vec<bool>, Vec<f32>)>,
    /// `split=N`: the fitted split of the mixed edge pixels.
    pub split: Option<Split>,
    /// `judge=truelayers`.
    pub truth: Option<TrueLayers<'a>>,
}

impl Judge<'_> {
    /// The loss of the whole image at the disparity `d`.
    pub fn whole(&self, d: &Image<f32>, target: &Image<f32>) -> f64 {
        self.loss(&self.aif, d, target, 0, 0)
    }

    /// The loss of the crop at `x0, y0` rendered from `aif` (that crop of [`Judge::aif`])
    /// at the disparity `d`, against `target` (the same crop of the defocused image).
    pub fn loss(
        &self,
        aif: &Image<f32>,
        d: &Image<f32>,
        target: &Image<f32>,
        x0: usize,
        y0: usize,
    ) -> f64 {
        let s = &self.settings;
        let render = |st: &drbokeh::LayerStack<f32>| {
            drbokeh::render(st, s, Engine::Fast, &NoProgress).unwrap()
        };
        let r = match self.kind.as_str() {
            "truelayers" => render(&self.truth.as_ref().unwrap().stack_at(d, x0, y0)),
            "layered" if self.split.is_some() => {
                let (mut st, own) = cut(aif, d, &split_opts(self.layers));
                self.split.as_ref().unwrap().apply(
                    &mut st,
                    &own,
                    &self.aif.data,
                    x0,
                    y0,
                    d.width,
                    d.height,
                    self.width,
                );
                render(&st)
            }
            "layered" if self.fitted.is_some() => {
                // The decomposition at the proposal, with the fitted colours on the pixels
                // of the start's mixed edge, in whichever layer owns them now.
                let (mut st, own) = cut(aif, d, &self.plain());
                let (edge, rgb) = self.fitted.as_ref().unwrap();
                for y in 0..d.height {
                    for x in 0..d.width {
                        let (j, g) = (y * d.width + x, (y0 + y) * self.width + x0 + x);
                        if edge[g] {
                            st.layers[own[j]].rgb_encoded.data[3 * j..3 * j + 3]
                                .copy_from_slice(&rgb[3 * g..3 * g + 3]);
                        }
                    }
                }
                render(&st)
            }
            "layered" if self.pure_px > 0 => {
                let dec = layers_from_disparity(aif, d, &self.plain()).unwrap();
                render(&purify(dec, aif, d, self.pure_px))
            }
            "layered" if self.matting_px > 0 || self.colour_guard_px > 0 => {
                // The decomposition with soft alpha at its cut edges (the photo pipeline's
                // edge matting) or fills that skip edge pixels, rendered as it is.
                let opts = LayeringOptions {
                    matting_px: self.matting_px,
                    colour_guard_px: self.colour_guard_px,
                    ..self.plain()
                };
                render(&layers_from_disparity(aif, d, &opts).unwrap().stack)
            }
            "layered" => LayeredModel::decompose(aif, d, self.layers)
                .unwrap()
                .render(Engine::Fast, aif, d, s)
                .unwrap(),
            "single" => render_layer_on(RenderLayer::DrBokeh, Engine::Fast, aif, d, s).unwrap(),
            _ => render_layer_on(self.layer, Engine::Fast, aif, d, s).unwrap(),
        };
        let c = Image::from_vec(
            r.width,
            r.height,
            3,
            r.data.iter().map(|v| v.clamp(0.0, 1.0)).collect(),
        )
        .unwrap();
        0.5 * drbokeh::loss::l1(&c, target).unwrap() as f64
            + 10.0 * drbokeh::loss::hssim(&c, target).unwrap() as f64
    }

    /// The decomposition `judge=layered` makes (as `LayeredModel::decompose`).
    fn plain(&self) -> LayeringOptions {
        LayeringOptions {
            max_layers: self.layers,
            ..Default::default()
        }
    }
}
