//! The fast engine: the same model, evaluated only where it matters. Forward and adjoint
//! side by side: `forward.rs` (the render, and the render that records the adjoint's tape),
//! `adjoint/` (the backward on the same schedule); `tiles.rs` (bands, tiles, reach) and
//! `runs.rs` (the vectorised runs) serve both.
//!
//! - **Bands**: output rows are processed in bands of at least [`BAND_ROWS`](tiles::BAND_ROWS) (and `2R`,
//!   so padding stays at most half of a band's work); each band builds its
//!   own reflection-padded planes (rows `y0 - R .. y1 + R`), so memory is bounded by the
//!   band size, not the image (a 24-MP render never holds full-size padded planes).
//! - **Tiles and reach**: a source of radius `r` reaches at most `r + 4.5` pixels
//!   ([`crate::model::SCATTER_TAIL_PX`]: beyond it `S <= 1.4e-7`, and the dropped ring weighs
//!   below 6e-6 of the kept weight). For each tile of
//!   [`TILE`](tiles::TILE) x [`TILE_ROWS`](tiles::TILE_ROWS) receivers, the largest radius among sources with alpha > 0 inside the
//!   tile's window bounds the taps every receiver in it must visit; a tile whose window
//!   holds no source skips the layer entirely. Cost grows with the actual blur radii, not
//!   with `L^2`.
//! - **Precomputed terms**: per padded pixel `r`, `1/r^2`, `d`, alpha and linear colour
//!   in separate planes (struct of arrays); per receiver `e(x)`.
//! - **Vectorisable inner loop**: contiguous `dx` runs with a branch-free body;
//!   `exp` is [`crate::Real::exp_fast`] (f32: polynomial, < 4e-7 relative error) and `tanh` is
//!   written through it. Where `e(x) < 1e-9` the occlusion term is 1 to within 1e-9 and
//!   is not evaluated.
//! - **Coverage**: the paper's box from a summed-area table (f64) of the padded alpha, O(1)
//!   per pixel; the soft-disc coverage (preset `physical`) as a gather bounded by the
//!   receiver's own reach `r(x) + tail` (`ApertureEval::reach_px`): the dropped ring
//!   weighs below 2e-6 against a weight sum of at least 2/3 (the centre tap).
//!
//! Kernel apertures use the model's scalar scatter term inside the same tile bounds.
//! Output agrees with the reference engine to about 1e-6 in linear light (tested to
//! 1e-5), and is identical for any thread count (each pixel is computed by one task in a
//! fixed order).

pub(super) mod adjoint;
pub(super) mod forward;
mod runs;
mod tiles;
