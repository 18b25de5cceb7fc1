//! Accumulation, layer colour and front-to-back compositing (docs/model.md, "Layer colour",
//! "Compositing"), and their backward.

use crate::Real;

/// The regulariser in `B = C / (W + 1e-8)`.
/// Equation M14 of docs/model.md.
pub const WEIGHT_EPSILON: f64 = 1e-8;

/// Running sums `C = sum Ilin(y) c(y,x)` and `W = sum c(y,x)` for one receiver and layer.
/// Equation M14 of docs/model.md.
#[derive(Clone, Copy, Debug, Default)]
pub struct Accumulator<T> {
    /// Weighted colour sum.
    pub colour: [T; 3],
    /// Weight sum.
    pub weight: T,
}

impl<T: Real> Accumulator<T> {
    /// Adds one tap.
    /// Equation M14 of docs/model.md.
    #[inline(always)]
    pub fn add(&mut self, rgb_linear: [T; 3], c: T) {
        for (acc, v) in self.colour.iter_mut().zip(rgb_linear) {
            *acc = *acc + v * c;
        }
        self.weight = self.weight + c;
    }

    /// Layer colour `B = C / (W + 1e-8)`.
    /// Equation M14 of docs/model.md.
    #[inline(always)]
    pub fn layer_colour(&self) -> [T; 3] {
        let w = self.weight + T::c(WEIGHT_EPSILON);
        self.colour.map(|c| c / w)
    }
}

/// Front-to-back compositing `out = sum_l B_l o_l T_l`, `T_0 = 1`, `T_{l+1} = T_l (1 - o_l)`.
/// Equation M17 of docs/model.md.
#[inline]
pub fn composite<T: Real>(layers: impl IntoIterator<Item = ([T; 3], T)>) -> [T; 3] {
    let mut out = [T::zero(); 3];
    let mut transmittance = T::one();
    for (colour, coverage) in layers {
        for (o, c) in out.iter_mut().zip(colour) {
            *o = *o + c * coverage * transmittance;
        }
        transmittance = transmittance * (T::one() - coverage);
    }
    out
}

/// What one layer contributes at one pixel: the weight sum `W`, the layer colour
/// `B = C / (W + 1e-8)` and the coverage `o` (what the adjoint records of the forward).
/// Equation M17 of docs/model.md.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LayerAtPixel<T> {
    /// Weight sum `W`.
    pub weight: T,
    /// Layer colour `B = C / (W + 1e-8)`.
    pub colour: [T; 3],
    /// Layer coverage `o`.
    pub coverage: T,
}

/// The gradients reaching one layer's sums at one pixel.
/// Equation M17 of docs/model.md.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LayerSumGradients<T> {
    /// `dL/dC` per channel.
    pub colour_sum: [T; 3],
    /// `dL/dW`.
    pub weight_sum: T,
    /// `dL/do`.
    pub coverage: T,
}

/// Backward of [`composite`] and of the layer colour at one pixel: from `dL/d out` (the
/// linear composite) and each layer's [`LayerAtPixel`], front first, the gradients of the
/// layers' sums. With `U_l = B_l o_l + (1 - o_l) U_{l+1}`: `dU_l/dB_l = o_l`,
/// `dU_l/do_l = B_l - U_{l+1}`, `dU_l/dU_{l+1} = 1 - o_l`; `B = C / (W + 1e-8)` gives
/// `dL/dC = dL/dB / (W + 1e-8)` and `dL/dW = -sum_c dL/dB_c B_c / (W + 1e-8)`.
/// Equation M17 of docs/model.md.
pub fn composite_backward<T: Real>(
    layers: &[LayerAtPixel<T>],
    g_linear: [T; 3],
) -> Vec<LayerSumGradients<T>> {
    let mut out = vec![LayerSumGradients::default(); layers.len()];
    composite_backward_into(layers, g_linear, &mut Vec::new(), &mut out);
    out
}

/// [`composite_backward`] into `out` (one entry per layer), with `behind` as working
/// memory (no allocation once it holds `layers.len() + 1` entries).
/// Equation M17 of docs/model.md.
pub fn composite_backward_into<T: Real>(
    layers: &[LayerAtPixel<T>],
    g_linear: [T; 3],
    behind: &mut Vec<[T; 3]>,
    out: &mut [LayerSumGradients<T>],
) {
    let n_layers = layers.len();
    let eps = T::c(WEIGHT_EPSILON);
    // U_l from the back.
    behind.clear();
    behind.resize(n_layers + 1, [T::zero(); 3]);
    for l in (0..n_layers).rev() {
        let s = &layers[l];
        for c in 0..3 {
            behind[l][c] = s.colour[c] * s.coverage + (T::one() - s.coverage) * behind[l + 1][c];
        }
    }
    let mut g_u = g_linear;
    for l in 0..n_layers {
        let s = &layers[l];
        let mut g_b = [T::zero(); 3];
        let mut g_o = T::zero();
        for c in 0..3 {
            g_b[c] = g_u[c] * s.coverage;
            g_o = g_o + g_u[c] * (s.colour[c] - behind[l + 1][c]);
            g_u[c] = g_u[c] * (T::one() - s.coverage);
        }
        let inv = T::one() / (s.weight + eps);
        out[l] = LayerSumGradients {
            colour_sum: g_b.map(|v| v * inv),
            weight_sum: -(g_b[0] * s.colour[0] + g_b[1] * s.colour[1] + g_b[2] * s.colour[2]) * inv,
            coverage: g_o,
        };
    }
}
