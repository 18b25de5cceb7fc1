//! The threaded engine: rows in parallel (rayon); each layer's planes are reflection-padded
//! once ([`Planes`](super::planes::Planes)), and the window's taps (offset, distance, gauge)
//! are precomputed ([`kernel`]). Sources with zero alpha are skipped (their tap weight is
//! exactly 0). Same model functions, same summation order as the reference, so results
//! agree to the last bit.
//!
//! - `forward.rs`: the render, and the render that records the exact adjoint's tape;
//! - `adjoint.rs`: the exact adjoint (every window tap in every pass);
//! - `kernel.rs`: the window's taps and the gathers both use.

pub(super) mod adjoint;
pub(super) mod forward;
mod kernel;
