//! `judge=truelayers`, an oracle: the scene's true layer stack (true alpha and hidden
//! colours), each pixel's proposed disparity written into the layer that owns it (the
//! billboard whose disparity is the pixel's true disparity); at the true disparity it
//! renders the true layers exactly. Degraded versions tell which part of the true layers
//! the truth's minimum needs.
use crate::segments::crop;
use drbokeh::eval::report::SceneInputs;
use drbokeh::layering::Region;
use drbokeh::{Image, Layer, LayerStack};

/// The true layers as the judge renders them.
pub struct TrueLayers<'a> {
    scene: &'a SceneInputs,
    /// The layer that owns each pixel (its disparity is the pixel's true disparity).
    owner: Vec<usize>,
    /// Each layer's colour, true or degraded (`tcolour`).
    colours: Vec<Image<f32>>,
    /// `talpha=hard`: alpha thresholded at 1/2 (the last layer opaque), as a decomposition
    /// by pixel labels has it.
    hard_alpha: bool,
    /// `recut=1`: ownership follows the proposal, as in a decomposition cut at the proposed
    /// disparity: a pixel whose proposed disparity is nearest another layer's plane moves
    /// into that layer (opaque, the all-in-focus colour), and where it moves farther the
    /// layers in front of it there turn transparent.
    recut: bool,
}

impl<'a> TrueLayers<'a> {
    /// `tcolour`: `true` (the layers' colours); `fill` keeps each layer's true colour on the
    /// pixels it owns and fills the rest (hidden behind nearer layers) by Telea inpainting of
    /// them, as the decomposition guesses hidden colours; `aif` also puts the all-in-focus
    /// colour (the mix at soft edges) on the owned pixels before the fill, as the
    /// decomposition does; `aifown` the all-in-focus colour on the owned pixels and the true
    /// colours behind them.
    pub fn new(scene: &'a SceneInputs, talpha: &str, tcolour: &str, recut: bool) -> Self {
        let layers = &scene.layers.layers;
        let nearest = |i: usize, v: f32| {
            (0..layers.len())
                .min_by(|&a, &b| {
                    let da = (layers[a].disparity.data[i] - v).abs();
                    let db = (layers[b].disparity.data[i] - v).abs();
                    da.total_cmp(&db)
                })
                .unwrap()
        };
        let owner: Vec<usize> = (0..scene.disparity.data.len())
            .map(|i| nearest(i, scene.disparity.data[i]))
            .collect();
        let colours = (0..layers.len())
            .map(|k| {
                let l = &layers[k];
                if tcolour == "true" {
                    return l.rgb_encoded.clone();
                }
                if tcolour == "aifown" {
                    let mut c = l.rgb_encoded.clone();
                    for (i, &o) in owner.iter().enumerate() {
                        if o == k {
                            c.data[3 * i..3 * i + 3]
                                .copy_from_slice(&scene.aif.data[3 * i..3 * i + 3]);
                        }
                    }
                    return c;
                }
                let src = if tcolour == "aif" {
                    &scene.aif
                } else {
                    &l.rgb_encoded
                };
                let region: Vec<Region> = owner
                    .iter()
                    .map(|&o| if o == k { Region::Known } else { Region::Fill })
                    .collect();
                if !region.contains(&Region::Known) {
                    return l.rgb_encoded.clone();
                }
                drbokeh::layering::inpaint_telea(src, &region, &Default::default()).image
            })
            .collect();
        TrueLayers {
            scene,
            owner,
            colours,
            hard_alpha: talpha == "hard",
            recut,
        }
    }

    /// The stack of the crop at `x0, y0` the size of `d`, with `d` written into the layers.
    pub fn stack_at(&self, d: &Image<f32>, x0: usize, y0: usize) -> LayerStack<f32> {
        let truth = &self.scene.layers.layers;
        let (nl, w) = (truth.len(), self.scene.disparity.width);
        let mut layers: Vec<Layer<f32>> = truth
            .iter()
            .enumerate()
            .map(|(k, l)| {
                let mut alpha = crop(&l.alpha, x0, y0, d.width, d.height);
                if self.hard_alpha && k + 1 < nl {
                    for a in &mut alpha.data {
                        *a = if *a >= 0.5 { 1.0 } else { 0.0 };
                    }
                }
                Layer {
                    rgb_encoded: crop(&self.colours[k], x0, y0, d.width, d.height),
                    alpha,
                    disparity: crop(&l.disparity, x0, y0, d.width, d.height),
                }
            })
            .collect();
        for y in 0..d.height {
            for x in 0..d.width {
                let (j, g) = (y * d.width + x, (y0 + y) * w + x0 + x);
                let t = self.owner[g];
                let v = d.data[j];
                let k = if self.recut {
                    (0..nl)
                        .min_by(|&a, &b| {
                            let da = (truth[a].disparity.data[g] - v).abs();
                            let db = (truth[b].disparity.data[g] - v).abs();
                            da.total_cmp(&db)
                        })
                        .unwrap()
                } else {
                    t
                };
                layers[k].disparity.data[j] = v;
                if k != t {
                    layers[k].alpha.data[j] = 1.0;
                    for c in 0..3 {
                        layers[k].rgb_encoded.data[3 * j + c] = self.scene.aif.data[3 * g + c];
                    }
                    for l in layers.iter_mut().take(k).skip(t) {
                        l.alpha.data[j] = 0.0;
                    }
                }
            }
        }
        LayerStack::new(layers).unwrap()
    }
}
