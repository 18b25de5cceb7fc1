//! The image part of the depth-from-defocus loss, `w1 L1 + wh HSSIM` (or one SSIM), on a
//! render clipped to [0, 1] (as a sensor clips) with some pixels left out; and the
//! edge-aware smoothness on the disparity.

use super::{LogEntry, LossTerms, LossWeights};
use crate::image::Image;
use crate::loss;
use crate::{Real, Result};

/// Smallest side for the structural term (the largest HSSIM window is 31 pixels).
pub(super) fn structure_min_side(terms: LossTerms) -> usize {
    match terms {
        LossTerms::Hssim => 31,
        LossTerms::SingleSsim => 11,
    }
}

/// Smallest side for the smoothness term (its 4-level pyramid).
pub(super) const SMOOTHNESS_MIN_SIDE: usize = 16;

/// The image loss at one scale.
pub(super) struct ImageObjective<'a, T> {
    pub weights: LossWeights,
    pub terms: LossTerms,
    pub use_structure: bool,
    pub target: &'a Image<T>,
    /// Per pixel: left out of the loss (the render there is replaced by the target).
    pub excluded: &'a [bool],
}

impl<T: Real> ImageObjective<'_, T> {
    /// Adds the weighted image terms of `render` to `entry` and returns the gradient of
    /// their weighted sum with respect to `render`. The loss sees `clip(render, 0, 1)` where
    /// a pixel is kept (gradient passed straight through the clip) and the target where it
    /// is left out (no gradient).
    pub fn evaluate(&self, render: &Image<T>, entry: &mut LogEntry) -> Result<Image<T>> {
        let mut seen = render.clone();
        let mut pass = vec![true; render.data.len()];
        for (k, v) in seen.data.iter_mut().enumerate() {
            if self.excluded[k / 3] {
                *v = self.target.data[k];
                pass[k] = false;
            } else {
                // Straight through: a render above white still feels the pull back down.
                *v = v.max(T::zero()).min(T::one());
            }
        }
        let mut g = Image::new(render.width, render.height, 3);
        if self.weights.l1 > 0.0 {
            let (val, gl) = loss::l1_grad(&seen, self.target)?;
            entry.l1 = Some(val.f64());
            entry.loss += self.weights.l1 * val.f64();
            for (a, b) in g.data.iter_mut().zip(&gl.data) {
                *a = *a + T::c(self.weights.l1) * *b;
            }
        }
        if self.use_structure && self.weights.hssim > 0.0 {
            let (val, gs) = match self.terms {
                LossTerms::Hssim => loss::hssim_grad(&seen, self.target)?,
                LossTerms::SingleSsim => {
                    let (s, gs) =
                        loss::ssim_grad(&seen, self.target, &loss::SsimWindow::sized(11)?)?;
                    let k = T::c(loss::HSSIM_WINDOWS.len() as f64);
                    (
                        k * (T::one() - s),
                        Image {
                            data: gs.data.iter().map(|&v| -k * v).collect(),
                            ..gs
                        },
                    )
                }
            };
            entry.structure = Some(val.f64());
            entry.loss += self.weights.hssim * val.f64();
            for (a, b) in g.data.iter_mut().zip(&gs.data) {
                *a = *a + T::c(self.weights.hssim) * *b;
            }
        }
        for (v, p) in g.data.iter_mut().zip(&pass) {
            if !p {
                *v = T::zero();
            }
        }
        Ok(g)
    }
}
