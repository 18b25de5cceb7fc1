//! Parsers for option values and the usage-error test behind the exit codes.

/// A focus disparity: a number, snapped into [0, 1] when within
/// [`drbokeh::scene::UNIT_INTERVAL_SLACK`] of
/// it ([`drbokeh::scene::unit_interval`]). Other values pass through, for the camera's validation to report on one line.
pub fn focus(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("expected a number in [0, 1], got '{s}'"))?;
    Ok(drbokeh::scene::unit_interval(v).unwrap_or(v))
}

/// A finite number > 0.
pub fn positive_f64(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a positive number, got '{s}'")),
    }
}

/// Bits per channel: 8 or 16.
pub fn bit_depth(s: &str) -> Result<u8, String> {
    match s.trim() {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("must be 8 or 16, got '{s}'")),
    }
}

/// Whether an error is a bad option value (exit code 2, like clap's own usage errors):
/// the library's [`drbokeh::Error::InvalidParameter`], or a command's own
/// `invalid parameter --name: ...` message.
pub fn is_usage_error(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        matches!(
            c.downcast_ref::<drbokeh::Error>(),
            Some(drbokeh::Error::InvalidParameter { .. })
        )
    }) || e.root_cause().to_string().starts_with("invalid parameter ")
        || e.to_string().starts_with("invalid parameter ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn focus_accepts_rounding_outside_the_unit_interval() {
        assert_eq!(focus("1.0000000000000002"), Ok(1.0));
        assert_eq!(focus("-1e-17"), Ok(0.0));
        assert_eq!(focus("0.25"), Ok(0.25));
        assert_eq!(focus("1.001"), Ok(1.001));
        assert!(focus("x").is_err());
        assert!(is_usage_error(&anyhow::anyhow!(
            "invalid parameter --threads: 0"
        )));
        assert!(!is_usage_error(&anyhow::anyhow!("a.png: cannot open")));
    }
}
