//! The layer stack: the renderer's input. Layers are ordered **front to back**.

use crate::image::{check_dimensions, first_where, Image};
use crate::{Error, Real, Result};

/// One layer: display-encoded colour, alpha (coverage) and normalised disparity
/// (larger = nearer), all of the stack's size.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer<T> {
    /// Display-encoded colour in [0, 1], 3 channels.
    pub rgb_encoded: Image<T>,
    /// Alpha (coverage) in [0, 1], 1 channel.
    pub alpha: Image<T>,
    /// Normalised disparity, 1 channel; larger means nearer.
    pub disparity: Image<T>,
}

/// A stack of layers, front first. The last layer is normally opaque (the background).
#[derive(Clone, Debug, PartialEq)]
pub struct LayerStack<T> {
    /// Width of every layer, in pixels.
    pub width: usize,
    /// Height of every layer, in pixels.
    pub height: usize,
    /// Layers, front to back.
    pub layers: Vec<Layer<T>>,
}

impl<T: Real> Layer<T> {
    /// A layer of constant colour, alpha and disparity.
    pub fn constant(
        width: usize,
        height: usize,
        rgb: [f64; 3],
        alpha: f64,
        disparity: f64,
    ) -> Self {
        let mut rgb_encoded = Image::new(width, height, 3);
        for px in rgb_encoded.data.chunks_exact_mut(3) {
            for c in 0..3 {
                px[c] = T::c(rgb[c]);
            }
        }
        Layer {
            rgb_encoded,
            alpha: Image::from_vec(width, height, 1, vec![T::c(alpha); width * height]).unwrap(),
            disparity: Image::from_vec(width, height, 1, vec![T::c(disparity); width * height])
                .unwrap(),
        }
    }
}

impl<T: Real> LayerStack<T> {
    /// Builds and validates a stack from its layers (front first).
    pub fn new(layers: Vec<Layer<T>>) -> Result<Self> {
        let first = layers
            .first()
            .ok_or_else(|| Error::input("layer stack", "has no layers"))?;
        let (width, height) = (first.alpha.width, first.alpha.height);
        let stack = LayerStack {
            width,
            height,
            layers,
        };
        stack.validate()?;
        Ok(stack)
    }

    /// A single opaque layer from an image and its disparity map.
    pub fn single(rgb_encoded: Image<T>, disparity: Image<T>) -> Result<Self> {
        let alpha = Image::from_vec(
            rgb_encoded.width,
            rgb_encoded.height,
            1,
            vec![T::one(); rgb_encoded.pixels()],
        )?;
        Self::new(vec![Layer {
            rgb_encoded,
            alpha,
            disparity,
        }])
    }

    /// Checks shapes, channel counts and value ranges: finite everywhere, colour >= 0,
    /// alpha in [0, 1]. Messages name the layer and the plane.
    pub fn validate(&self) -> Result<()> {
        if self.layers.is_empty() {
            return Err(Error::input("layer stack", "has no layers"));
        }
        check_dimensions("layer stack", self.width, self.height)?;
        for (i, l) in self.layers.iter().enumerate() {
            for (name, img, ch) in [
                ("rgb", &l.rgb_encoded, 3),
                ("alpha", &l.alpha, 1),
                ("disparity", &l.disparity, 1),
            ] {
                let what = format!("layer {i} {name}");
                if img.channels != ch {
                    return Err(Error::input(
                        &what,
                        format!("has {} channels, expected {ch}", img.channels),
                    ));
                }
                if img.width != self.width || img.height != self.height {
                    return Err(Error::input(
                        &what,
                        format!(
                            "is {}x{}, but the stack is {}x{}",
                            img.width, img.height, self.width, self.height
                        ),
                    ));
                }
                if img.data.len() != img.width * img.height * ch {
                    return Err(Error::input(
                        &what,
                        "buffer length does not match its shape",
                    ));
                }
                img.check_finite(&what)?;
            }
            let rgb = &l.rgb_encoded.data;
            if let Some(v) = first_where(rgb, |v| v < T::zero()).map(|i| rgb[i]) {
                return Err(Error::input(
                    format!("layer {i} rgb"),
                    format!("negative colour value {v:?} (display-encoded colour must be >= 0)"),
                ));
            }
            let alpha = &l.alpha.data;
            if let Some(v) = first_where(alpha, |v| v < T::zero() || v > T::one()).map(|i| alpha[i])
            {
                return Err(Error::input(
                    format!("layer {i} alpha"),
                    format!("value {v:?} outside [0, 1]"),
                ));
            }
        }
        Ok(())
    }

    /// Converts the element type.
    pub fn cast<U: Real>(&self) -> LayerStack<U> {
        LayerStack {
            width: self.width,
            height: self.height,
            layers: self
                .layers
                .iter()
                .map(|l| Layer {
                    rgb_encoded: l.rgb_encoded.cast(),
                    alpha: l.alpha.cast(),
                    disparity: l.disparity.cast(),
                })
                .collect(),
        }
    }

    /// The disparity seen at pixel (x, y): that of the frontmost layer whose alpha there
    /// is at least 0.5 (the last layer if none is). Used for tap-to-focus.
    pub fn disparity_at(&self, x: usize, y: usize) -> Result<f64> {
        if x >= self.width || y >= self.height {
            return Err(Error::param(
                "focus_at",
                format!(
                    "pixel ({x}, {y}) is outside the {}x{} image",
                    self.width, self.height
                ),
            ));
        }
        let layer = self
            .layers
            .iter()
            .find(|l| l.alpha.at(x, y, 0).f64() >= 0.5)
            .unwrap_or_else(|| self.layers.last().unwrap());
        Ok(layer.disparity.at(x, y, 0).f64())
    }

    /// Largest absolute relative disparity |disp - focus| over all pixels with alpha > 0.
    pub fn max_defocus(&self, focus: f64) -> f64 {
        self.layers
            .iter()
            .flat_map(|l| l.alpha.data.iter().zip(&l.disparity.data))
            .filter(|(a, _)| a.f64() > 0.0)
            .map(|(_, d)| (d.f64() - focus).abs())
            .fold(0.0, f64::max)
    }
}
