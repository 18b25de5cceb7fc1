//! Help texts that list the valid names of an option, generated from the library's own
//! lists (so `--help` cannot go stale when a preset, method or workload is added).

use drbokeh::dfd::benchmark::DfdLayer;
use drbokeh::dfd::RenderLayer;
use drbokeh::eval::report::Method;
use drbokeh::Preset;

/// The engines `--engine` accepts, in the order `--help` lists them. The library has no
/// list of them; a unit test checks that each parses and that the library's own message
/// for an unknown engine names exactly these.
pub const ENGINES: [&str; 5] = ["auto", "spans", "fast", "threaded", "reference"];

/// `--preset`: the named presets with their one-line descriptions.
pub fn preset_help() -> String {
    let names: Vec<String> = Preset::ALL
        .iter()
        .map(|(name, what)| format!("{name}: {what}"))
        .collect();
    format!(
        "Model preset; one of: {}. physical is measured closer to a real lens: +4.4 to +4.6 dB \
         PSNR over paper, better on all 32 scenes of two ray-traced benchmark sets \
         (docs/physical.md)",
        names.join("; ")
    )
}

/// `--engine` of the rendering commands.
pub fn engine_help() -> String {
    format!(
        "Execution engine; one of: {}. auto (default): in f32, per band and layer the span \
         engine or the fast engine's taps, whichever is predicted cheaper; threaded with \
         --f64 (bit-exact, for checks). spans: O(r) row spans (within ~2e-5 relative of \
         fast). fast: skips taps that cannot contribute (agrees with the reference to ~1e-6 \
         in linear light) and has no practical window limit. threaded: every window tap, \
         all cores. reference: plain loops, the oracle (slow)",
        ENGINES.join(", ")
    )
}

/// `eval --methods`.
pub fn eval_methods_help() -> String {
    format!(
        "Comma-separated methods, or all. Methods: {}",
        Method::ALL.map(|m| m.name()).join(", ")
    )
}

/// `gallery --methods`.
pub fn gallery_methods_help() -> String {
    let names: Vec<&str> = drbokeh::eval::gallery::gallery_methods()
        .into_iter()
        .map(|m| m.name())
        .collect();
    format!(
        "Comma-separated methods, or all (every method below). Methods: {}",
        names.join(", ")
    )
}

/// `bench --only`.
pub fn bench_only_help() -> String {
    format!(
        "Run only the workloads whose name contains this text. Workloads (--quick: the \
         small ones): {}, {}",
        drbokeh::bench::workload_names(false).join(", "),
        drbokeh::bench::ADJOINT_WORKLOAD_NAME
    )
}

/// `dfd --method`.
pub fn dfd_method_help() -> String {
    format!(
        "Rendering layer (method) to optimise through; one of: {} (default drbokeh, with \
         --preset)",
        RenderLayer::ALL.map(|l| l.name()).join(", ")
    )
}

/// `dfd-eval --methods`.
pub fn dfd_eval_methods_help() -> String {
    let benchmark: Vec<&str> = DfdLayer::ALL
        .iter()
        .map(|l| l.name().strip_prefix("drbokeh-").unwrap_or(l.name()))
        .collect();
    format!(
        "Rendering layers (methods) to optimise through, comma-separated, or all (the \
         default). With --benchmark: {} (physical and paper are drbokeh with that preset). \
         With --synthetic: {} (drbokeh with --preset)",
        benchmark.join(", "),
        RenderLayer::ALL.map(|l| l.name()).join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_engine_parses_and_the_library_lists_the_same() {
        for name in ENGINES {
            drbokeh::Engine::parse_or_auto(name, false).unwrap();
        }
        let e = "bogus".parse::<drbokeh::Engine>().unwrap_err().to_string();
        let listed = e
            .split("available: ")
            .nth(1)
            .and_then(|s| s.split(')').next())
            .unwrap_or_else(|| panic!("no list in {e}"));
        let mut a: Vec<&str> = listed.split(", ").collect();
        let mut b = ENGINES.to_vec();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b, "{e}");
    }

    #[test]
    fn help_lists_every_name() {
        for (p, _) in Preset::ALL {
            assert!(preset_help().contains(p));
        }
        for m in Method::ALL {
            assert!(eval_methods_help().contains(m.name()));
        }
        for w in drbokeh::bench::workload_names(false) {
            assert!(bench_only_help().contains(&w));
        }
        for l in RenderLayer::ALL {
            assert!(dfd_method_help().contains(l.name()));
            assert!(dfd_eval_methods_help().contains(l.name()));
        }
        assert!(gallery_methods_help().contains("photo-physical"));
    }
}
