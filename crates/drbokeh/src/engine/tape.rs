//! What the forward pass records for the backward pass ([`Tape`]), and what the backward
//! pass returns ([`Gradients`]).

use super::schedule::Engine;
use crate::image::Image;
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::{Real, Result};

/// A schedule's recording of a forward pass, able to run its backward pass.
pub(crate) trait Backward<T>: Send + Sync {
    /// Back-propagates `grad_output` to every input.
    fn backward(&self, grad_output: &Image<T>, progress: &dyn Progress) -> Result<Gradients<T>>;
}

/// Everything the backward pass needs, recorded by [`crate::render_with_tape`] or
/// [`crate::render_with_tape_on`].
pub struct Tape<T> {
    settings: RenderSettings,
    engine: Engine,
    inner: Box<dyn Backward<T>>,
}

impl<T: Real> Tape<T> {
    /// Wraps the recording of schedule `engine` made with `settings`.
    pub(crate) fn new(
        settings: &RenderSettings,
        engine: Engine,
        inner: Box<dyn Backward<T>>,
    ) -> Self {
        Tape {
            settings: settings.clone(),
            engine,
            inner,
        }
    }

    /// The settings this tape was recorded with.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// The schedule the backward pass runs on: [`Engine::Threaded`] (exact),
    /// [`Engine::Fast`], or [`Engine::Spans`] / [`Engine::Auto`] (the span adjoint, spans or
    /// taps per band-layer as the forward chose).
    pub fn engine(&self) -> Engine {
        self.engine
    }

    /// Back-propagates `grad_output` (d loss / d output, shaped like the rendered image)
    /// to every input. Deterministic for any thread count.
    pub fn backward(
        &self,
        grad_output: &Image<T>,
        progress: &dyn Progress,
    ) -> Result<Gradients<T>> {
        self.inner.backward(grad_output, progress)
    }
}

/// Gradients of one layer, shaped like the layer.
#[derive(Clone, Debug)]
pub struct LayerGradients<T> {
    /// d loss / d encoded colour (3 channels).
    pub rgb: Image<T>,
    /// d loss / d alpha.
    pub alpha: Image<T>,
    /// d loss / d disparity.
    pub disparity: Image<T>,
}

/// Gradients of a scalar loss with respect to all inputs of a render.
#[derive(Clone, Debug)]
pub struct Gradients<T> {
    /// One entry per layer, front first.
    pub layers: Vec<LayerGradients<T>>,
    /// d loss / d K (blur strength).
    pub blur_k: f64,
    /// d loss / d f (focus disparity).
    pub focus: f64,
}

impl<T: Real> Gradients<T> {
    /// The published kernel's training heuristic ("gradient clipping"), offered as an
    /// explicit option and off by default: per-pixel gradient values whose magnitude lies
    /// in `[lo, hi)` are raised to `hi`, keeping their sign (the paper's `lo = 1e-6`,
    /// `hi = 1e-2`). The result is no longer the gradient of the loss.
    pub fn rescale_small(&mut self, lo: f64, hi: f64) {
        let (lo, hi) = (T::c(lo), T::c(hi));
        for l in &mut self.layers {
            for v in l
                .rgb
                .data
                .iter_mut()
                .chain(&mut l.alpha.data)
                .chain(&mut l.disparity.data)
            {
                let m = v.abs();
                if m >= lo && m < hi {
                    *v = if *v > T::zero() { hi } else { -hi };
                }
            }
        }
    }
}
