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
}

impl Engine {
    /// The default schedule: [`Engine::Fast`] in single precision, [`Engine::Threaded`] in
    /// double precision (every window tap: the equation and its gradient exactly, for
    /// checks).
    pub fn auto(double_precision: bool) -> Engine {
        if double_precision {
            Engine::Threaded
        } else {
            Engine::Fast
        }
    }

    /// Parses `fast`, `threaded`, `reference`, or `auto` ([`Engine::auto`] for the
    /// precision).
    pub fn parse_or_auto(name: &str, double_precision: bool) -> Result<Engine> {
        match name {
            "auto" => Ok(Engine::auto(double_precision)),
            other => other.parse(),
        }
    }
}

impl std::str::FromStr for Engine {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "reference" => Ok(Engine::Reference),
            "threaded" => Ok(Engine::Threaded),
            "fast" => Ok(Engine::Fast),
            _ => Err(Error::param(
                "engine",
                format!("unknown engine '{s}' (available: fast, threaded, reference)"),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Engine;

    #[test]
    fn auto_is_fast_in_f32_and_threaded_in_f64() {
        assert_eq!(Engine::parse_or_auto("auto", false).unwrap(), Engine::Fast);
        assert_eq!(
            Engine::parse_or_auto("auto", true).unwrap(),
            Engine::Threaded
        );
        assert_eq!(
            Engine::parse_or_auto("reference", false).unwrap(),
            Engine::Reference
        );
        let e = Engine::parse_or_auto("warp", true).unwrap_err();
        assert!(matches!(e, crate::Error::InvalidParameter { ref name, .. } if name == "engine"));
    }
}
