//! THE EQUATION, once. Every term of the rendering model (`docs/model.md`) is a function
//! here, beside its derivative and, where the fast engine needs one, its
//! [`Real::exp_fast`](crate::Real::exp_fast) form; engines (reference, threaded, fast) call
//! these and never re-derive them.
//!
//! Notation (docs/model.md, "Notation"): `d(y) = disp(y) - f` relative disparity,
//! `r(y) = K|d(y)| + footprint` scatter radius in pixels, `S` soft scatter step, `A` source
//! area, `O` soft occlusion, `c(y,x)` tap weight, `B_l` layer colour, `o_l` layer coverage,
//! `T_l` transmittance.
//!
//! | file | terms | docs/model.md |
//! | --- | --- | --- |
//! | `options.rs` | the replaceable terms ([`ModelOptions`]) | Presets |
//! | `scatter.rs` | `d`, `r`, `S` (paper and sharp), `A`, tail, automatic window | Scatter radius, Scatter step, Source area, Tail |
//! | `tap.rs` | mask `M`, borders, aperture, tap weight `c` | Window and borders, Aperture, Tap weight |
//! | `occlusion.rs` | `e`, `s`, `O` | Occlusion |
//! | `coverage.rs` | box and soft-disc `o` | Coverage |
//! | `tone.rs` | gamma, sRGB, highlight boost | Tone |
//! | `composite.rs` | `W`, `B`, front-to-back compositing and its backward | Layer colour, Compositing |
//! | `prepare.rs` | per-pixel terms of a layer | Per-pixel terms |

mod composite;
mod coverage;
mod occlusion;
mod options;
mod prepare;
mod scatter;
mod tap;
mod tone;

pub use composite::{
    composite, composite_backward, composite_backward_into, Accumulator, LayerAtPixel,
    LayerSumGradients, WEIGHT_EPSILON,
};
pub use coverage::{
    box_coverage, coverage_half_size_px, coverage_radius_px, DiscCoverage, MIN_COVERAGE_RADIUS_PX,
};
pub use occlusion::{
    depth_step, depth_step_derivative, depth_step_derivative_from_value, depth_step_fast,
    depth_step_fast_with_derivative, focus_weight, focus_weight_derivatives, occlusion,
    occlusion_derivatives, occlusion_fast, occlusion_fast_with_derivative, occlusion_from_step,
    occlusion_receiver_factors_fast,
};
pub use options::{Coverage, CoverageRadius, Footprint, ModelOptions, ScatterStep, Transfer};
pub use prepare::{prepare_layer, PixelModel, PreparedLayer};
pub use scatter::{
    automatic_window, kernel_footprint_radius_px, largest_scatter_radius_px,
    normalised_scatter_radius_factor, relative_disparity, scatter_radius_px, scatter_radius_sign,
    scatter_step, scatter_step_derivative, scatter_step_fast, sharp_step, sharp_step_fast,
    soft_step, soft_step_derivative, soft_step_fast, source_area, source_area_derivative,
    source_area_log_derivative, SCATTER_TAIL_PX,
};
pub use tap::{in_window, reflect, tap_weight, tap_weight_inv_area, window_taps, Tap};
pub(crate) use tap::{masked_tap_weight, scatter_term, scatter_term_and, ApertureEval};
pub use tone::{
    encode, encode_derivative, linear_to_srgb, linear_to_srgb_derivative, linearize,
    source_linear_with_derivatives, srgb_to_linear_with_derivative, HighlightBoost, Tone,
};
