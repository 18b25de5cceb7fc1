//! `drbokeh bench`: the standard performance report.

use anyhow::Result;
use clap::Args;
use drbokeh::bench::{run_workload, workloads, BenchRow};
use std::path::PathBuf;

/// Measure the engines on standard workloads (0.25 to 24 MP, K = 10/30/60, 1-3 layers, the
/// demo, a uniformly blurred worst case, a 200-px blur): the fast engine against the plain
/// multi-threaded engine (and the single-threaded reference on the demo), in one run.
/// Prints time, taps visited, taps/s, speed-up and the largest difference in linear light.
///
/// Example:
///   drbokeh bench --quick --json bench.json
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct BenchArgs {
    /// Only the small workloads (a minute or two).
    #[arg(long)]
    pub quick: bool,
    /// Run only workloads whose name contains this text.
    #[arg(long, value_name = "TEXT")]
    pub only: Option<String>,
    /// Also write the rows as JSON.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
}

fn print_row(r: &BenchRow) {
    println!(
        "| {} | {:.2} | {} | {} | {} | {} | {:.3} | {:.3e} | {:.3e} | {} | {} | {:.3e} |",
        r.workload,
        r.megapixels,
        r.layers,
        r.blur_k,
        r.window,
        r.engine,
        r.seconds,
        r.taps as f64,
        r.taps_per_second,
        r.speedup_vs_threaded
            .map(|s| format!("{s:.1}x"))
            .unwrap_or_else(|| "-".into()),
        r.max_linear_diff
            .map(|d| format!("{d:.1e}"))
            .unwrap_or_else(|| "-".into()),
        r.disc_area,
    );
}

pub fn run(a: &BenchArgs) -> Result<()> {
    crate::args::init_threads(a.threads)?;
    println!("threads: {}", rayon::current_num_threads());
    println!("| workload | MP | layers | K | L | engine | seconds | taps | taps/s | speed-up vs threaded | max diff (linear) | disc area |");
    println!("| --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |");
    let mut rows = Vec::new();
    for w in workloads(a.quick) {
        if a.only
            .as_ref()
            .is_some_and(|o| !w.name.contains(o.as_str()))
        {
            continue;
        }
        rows.extend(run_workload(&w, &mut print_row)?);
    }
    if let Some(p) = &a.json {
        let json = serde_json::to_vec_pretty(&rows)?;
        drbokeh::io::write_atomic(p, |w| {
            use std::io::Write;
            w.write_all(&json)
                .map_err(|e| drbokeh::Error::file(p, e.to_string()))
        })?;
    }
    Ok(())
}
