//! The display transfer (docs/model.md, "Tone"): gamma or exact sRGB, each beside its
//! derivative, and the source colour with the optional highlight boost.

use super::options::Transfer;
use crate::Real;

/// Display encoding to linear: `lin = (I + offset)^g`.
/// Equation M18 of docs/model.md.
#[inline(always)]
pub fn linearize<T: Real>(encoded: T, gamma: T, offset: T) -> T {
    (encoded + offset).powf(gamma)
}

/// Linear to display encoding: `out = lin^(1/g) - offset`.
/// Equation M18 of docs/model.md.
#[inline(always)]
pub fn encode<T: Real>(linear: T, gamma: T, offset: T) -> T {
    linear.powf(T::one() / gamma) - offset
}

/// Derivative of [`encode`]: `(1/g) lin^(1/g - 1)`; 0 where `lin <= 0` (undefined there).
/// Equation M18 of docs/model.md.
#[inline(always)]
pub fn encode_derivative<T: Real>(linear: T, gamma: T) -> T {
    if linear <= T::zero() {
        return T::zero();
    }
    linear.powf(T::one() / gamma - T::one()) / gamma
}

/// Exact sRGB decoding (IEC 61966-2-1; the `Srgb` transfer option) and its
/// derivative `(lin, dlin/dI)`:
/// `lin = I / 12.92` if `I <= 0.04045`, else `((I + 0.055) / 1.055)^2.4`;
/// `dlin/dI = 1 / 12.92`, else `(2.4 / 1.055) ((I + 0.055) / 1.055)^1.4`.
/// Equation M19 of docs/model.md.
#[inline(always)]
pub fn srgb_to_linear_with_derivative<T: Real>(encoded: T) -> (T, T) {
    if encoded <= T::c(0.04045) {
        (encoded / T::c(12.92), T::one() / T::c(12.92))
    } else {
        let b = (encoded + T::c(0.055)) / T::c(1.055);
        (b.powf(T::c(2.4)), T::c(2.4 / 1.055) * b.powf(T::c(1.4)))
    }
}

/// Exact sRGB encoding, the inverse of [`srgb_to_linear_with_derivative`]:
/// `I = 12.92 lin` if `lin <= 0.0031308`, else `1.055 lin^(1/2.4) - 0.055`.
/// Equation M19 of docs/model.md.
#[inline(always)]
pub fn linear_to_srgb<T: Real>(linear: T) -> T {
    if linear <= T::c(0.0031308) {
        T::c(12.92) * linear
    } else {
        T::c(1.055) * linear.powf(T::c(1.0 / 2.4)) - T::c(0.055)
    }
}

/// Derivative of [`linear_to_srgb`]: `12.92`, else `(1.055 / 2.4) lin^(1/2.4 - 1)`.
/// Equation M19 of docs/model.md.
#[inline(always)]
pub fn linear_to_srgb_derivative<T: Real>(linear: T) -> T {
    if linear <= T::c(0.0031308) {
        T::c(12.92)
    } else {
        T::c(1.055 / 2.4) * linear.powf(T::c(1.0 / 2.4 - 1.0))
    }
}

/// The display transfer of a render: the model option [`Transfer`] with the camera's gamma
/// and offset (used by [`Transfer::Gamma`] only).
/// Equations M18, M19 of docs/model.md.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tone {
    /// Which curve.
    pub transfer: Transfer,
    /// Gamma `g` of [`Transfer::Gamma`].
    pub gamma: f64,
    /// Offset of [`Transfer::Gamma`].
    pub offset: f64,
}

impl Tone {
    /// A transfer with the camera's gamma and offset.
    /// Equations M18, M19 of docs/model.md.
    pub fn new(transfer: Transfer, gamma: f64, offset: f64) -> Self {
        Tone {
            transfer,
            gamma,
            offset,
        }
    }

    /// Display-encoded value to linear, and its derivative `dlin/dI`. For the gamma curve:
    /// [`linearize`] and `g (I + offset)^(g-1)` (0 where `I + offset <= 0`).
    /// Equations M18, M19 of docs/model.md.
    #[inline(always)]
    pub fn linearize_with_derivative<T: Real>(&self, encoded: T) -> (T, T) {
        match self.transfer {
            Transfer::Gamma => {
                let (gamma, offset) = (T::c(self.gamma), T::c(self.offset));
                let base = encoded + offset;
                let lin = base.powf(gamma);
                // g base^(g-1) = g lin / base: one power instead of two.
                let dlin = if base > T::zero() {
                    gamma * lin / base
                } else {
                    T::zero()
                };
                (lin, dlin)
            }
            Transfer::Srgb => srgb_to_linear_with_derivative(encoded),
        }
    }

    /// Display-encoded value to linear.
    /// Equations M18, M19 of docs/model.md.
    #[inline(always)]
    pub fn linearize<T: Real>(&self, encoded: T) -> T {
        match self.transfer {
            Transfer::Gamma => linearize(encoded, T::c(self.gamma), T::c(self.offset)),
            Transfer::Srgb => srgb_to_linear_with_derivative(encoded).0,
        }
    }

    /// Linear to display encoding ([`encode`] or [`linear_to_srgb`]).
    /// Equations M18, M19 of docs/model.md.
    #[inline(always)]
    pub fn encode<T: Real>(&self, linear: T) -> T {
        match self.transfer {
            Transfer::Gamma => encode(linear, T::c(self.gamma), T::c(self.offset)),
            Transfer::Srgb => linear_to_srgb(linear),
        }
    }

    /// Derivative of [`Tone::encode`] ([`encode_derivative`] or [`linear_to_srgb_derivative`]).
    /// Equations M18, M19 of docs/model.md.
    #[inline(always)]
    pub fn encode_derivative<T: Real>(&self, linear: T) -> T {
        match self.transfer {
            Transfer::Gamma => encode_derivative(linear, T::c(self.gamma)),
            Transfer::Srgb => linear_to_srgb_derivative(linear),
        }
    }
}

/// The constants of the highlight boost (equation M20 of docs/model.md): a bright,
/// defocused pixel's display-encoded value is multiplied by up to `1 + amount`, ramping
/// in above `threshold_encoded`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HighlightBoost {
    /// Largest relative increase `a` of the encoded value (the paper's 0.2).
    pub amount: f64,
    /// Display-encoded level `T` above which the boost ramps in (the paper's 200/255).
    pub threshold_encoded: f64,
}

impl HighlightBoost {
    /// The paper's boost: `a = 0.2`, `T = 200/255` (`--highlight paper` and plain
    /// `--highlight`; a stack's `highlight`).
    pub const PAPER: HighlightBoost = HighlightBoost {
        amount: 0.2,
        threshold_encoded: 200.0 / 255.0,
    };

    /// The boost on top of a photo's highlight recovery (the `auto` default of
    /// docs/highlights.md): `a = 0.25`, `T = 0.9`. The recovery has already raised the
    /// clipped pixels; the paper's threshold also brightened the photo's unclipped bright
    /// pixels, whose value is right.
    pub const PHOTO: HighlightBoost = HighlightBoost {
        amount: 0.25,
        threshold_encoded: 0.9,
    };

    /// Checks `0 <= amount <= 10` and `0 <= threshold_encoded < 1`; messages name
    /// `highlight`.
    pub fn validate(&self) -> crate::Result<()> {
        if !(self.amount.is_finite() && (0.0..=10.0).contains(&self.amount)) {
            return Err(crate::Error::param(
                "highlight",
                format!("boost amount must be in [0, 10], got {}", self.amount),
            ));
        }
        let t = self.threshold_encoded;
        if !(t.is_finite() && (0.0..1.0).contains(&t)) {
            return Err(crate::Error::param(
                "highlight",
                format!("boost threshold must be in [0, 1), got {t}"),
            ));
        }
        Ok(())
    }
}

/// Linear colour of a source pixel, and its partial derivatives. With a `boost`, the
/// display-encoded value is first multiplied by `1 + a m`, with
/// `m = clip(tanh(200 ((disp - f)^2 - 0.01)), 0, 1) * clip(tanh(10 (I - T)), 0, 1)`
/// (`a`, `T`: the boost's amount and threshold; the paper's 0.2 and 200/255).
/// Returns `(lin, dlin/dI, dlin/dd)`: the linear colour and its partial derivatives with
/// respect to the encoded value `I` and the relative disparity `d`. (`tanh < 1`, so only
/// the lower clip can be active.)
/// Equation M20 of docs/model.md.
#[inline]
pub fn source_linear_with_derivatives<T: Real>(
    encoded: T,
    rel_disp: T,
    boost: Option<&HighlightBoost>,
    tone: &Tone,
) -> (T, T, T) {
    // Below the threshold (`10 (I - T) <= 0`) the boost is exactly 1 with zero
    // derivatives (`q = 0` and `dq = 0`), so the two tanh are skipped.
    let (boosted, d_boost_di, d_boost_dd) = match boost {
        Some(b) if encoded > T::c(b.threshold_encoded) => {
            let amount = T::c(b.amount);
            let arg_p = T::c(200.0) * (rel_disp * rel_disp - T::c(0.01));
            let arg_q = T::c(10.0) * (encoded - T::c(b.threshold_encoded));
            let (tp, tq) = (arg_p.tanh(), arg_q.tanh());
            let (p, q) = (tp.max(T::zero()), tq.max(T::zero()));
            let dp = if arg_p > T::zero() {
                T::c(400.0) * rel_disp * (T::one() - tp * tp)
            } else {
                T::zero()
            };
            let dq = if arg_q > T::zero() {
                T::c(10.0) * (T::one() - tq * tq)
            } else {
                T::zero()
            };
            let gain = T::one() + amount * p * q;
            (
                encoded * gain,
                gain + encoded * amount * p * dq,
                encoded * amount * dp * q,
            )
        }
        _ => (encoded, T::one(), T::zero()),
    };
    let (lin, dlin) = tone.linearize_with_derivative(boosted);
    (lin, dlin * d_boost_di, dlin * d_boost_dd)
}
