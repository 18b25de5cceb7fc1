//! The choice of schedule ([`Engine`]).

use crate::{Error, Result};

/// Which schedule evaluates the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Engine {
    /// Plain single-threaded loops, the equation as written (slow; the oracle).
    Reference,
    /// Multi-threaded over rows (rayon), with pre-padded planes and a precomputed tap list.
    #[default]
    Threaded,
    /// Bands, tiles bounded by the largest blur that reaches them, vectorised f32 inner
    /// loops; agrees with the reference to ~1e-6 in linear light.
    Fast,
    /// Row spans: O(r) per source instead of the fast engine's O(r^2) taps, with bounded
    /// approximations (relative errors of at most a few 1e-5; `engine/spans/`); the tap
    /// path where spans are not bounded (kernel apertures, wide in-focus disparity ranges).
    Spans,
    /// Per band and layer, spans or the fast engine's taps, whichever is predicted cheaper.
    Auto,
}

impl std::str::FromStr for Engine {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "reference" => Ok(Engine::Reference),
            "threaded" => Ok(Engine::Threaded),
            "fast" => Ok(Engine::Fast),
            "spans" => Ok(Engine::Spans),
            "auto" => Ok(Engine::Auto),
            _ => Err(Error::param(
                "engine",
                format!("unknown engine '{s}' (available: auto, spans, fast, threaded, reference)"),
            )),
        }
    }
}
