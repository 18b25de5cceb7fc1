//! `drbokeh bench`: the standard performance report.

use anyhow::Result;
use clap::Args;
use drbokeh::bench::{
    adjoint_workload, run_adjoint, run_workload, workloads_where, AdjointRow, BenchRow,
};
use std::path::PathBuf;

/// Performance report: the engines (spans, auto, fast, threaded, reference) on standard workloads.
///
/// Measures the engines on standard workloads (0.25 to 24 MP, K = 10 to 100, 1-3 layers, the
/// demo, a uniformly blurred worst case, 100- and 200-px blurs, the GEGL-equivalent workload
/// of issue 18 with both presets, and a radius sweep 5..200 px of the span engine): the span
/// engine (spans, and auto: spans or taps per band and layer) against the fast engine, the
/// fast engine against the plain multi-threaded engine (and the single-threaded reference on
/// the demo), in one run. Prints time, time per pixel and layer, work, speed-ups and the
/// largest differences to the fast engine (display-encoded and in linear light).
/// Then the adjoint at 512x512, 2 layers, K 30, L 71: forward, forward with tape, backward
/// and backward/forward ratio for the fast adjoint and for auto's span adjoint, with the
/// largest gradient difference between them; without --quick also the exact threaded
/// adjoint (about a minute on 2 cores) and the fast one's largest difference to it.
/// --json writes {"rows": [...], "adjoint": {...}}.
///
/// Examples:
///   drbokeh bench --quick
///   drbokeh bench --quick --json bench.json
///   drbokeh bench --only demo
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct BenchArgs {
    /// Only the small workloads (a minute or two).
    #[arg(long)]
    pub quick: bool,
    #[arg(long, value_name = "TEXT", help = crate::names::bench_only_help())]
    pub only: Option<String>,
    /// Also write the rows as JSON.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
}

fn print_row(r: &BenchRow) {
    let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map(f).unwrap_or_else(|| "-".into());
    println!(
        "| {} | {:.2} | {} | {} | {} | {} | {:.3} | {:.0} | {:.3e} | {} | {} | {} | {} | {} | {}/{} | {:.3e} |",
        r.workload,
        r.megapixels,
        r.layers,
        r.blur_k,
        r.window,
        r.engine,
        r.seconds,
        r.ns_per_pixel_layer,
        r.taps as f64,
        opt(r.speedup_vs_fast, &|s| format!("{s:.2}x")),
        opt(r.speedup_vs_threaded, &|s| format!("{s:.1}x")),
        opt(r.max_display_diff, &|d| format!("{d:.1e}")),
        opt(r.mean_display_diff, &|d| format!("{d:.1e}")),
        opt(r.max_linear_diff, &|d| format!("{d:.1e}")),
        r.span_layers,
        r.tap_layers,
        r.disc_area,
    );
}

fn print_adjoint(r: &AdjointRow) {
    let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map(f).unwrap_or_else(|| "-".into());
    println!();
    println!("| adjoint workload | forward (fast) s | forward+tape (fast) s | backward (fast) s | backward/forward | forward (auto) s | forward+tape (auto) s | backward (spans) s | backward/forward (auto) | spans vs fast max grad diff | forward+tape (threaded) s | backward (threaded) s | max grad diff | max grad |");
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    println!(
        "| {} | {:.3} | {:.3} | {:.3} | {:.2}x | {:.3} | {:.3} | {:.3} | {:.2}x | {:.2e} | {} | {} | {} | {} |",
        r.workload,
        r.forward_fast,
        r.forward_tape_fast,
        r.backward_fast,
        r.backward_over_forward,
        r.forward_auto,
        r.forward_tape_auto,
        r.backward_auto,
        r.backward_over_forward_auto,
        r.max_grad_diff_auto_fast,
        opt(r.forward_tape_threaded, &|v| format!("{v:.3}")),
        opt(r.backward_threaded, &|v| format!("{v:.3}")),
        opt(r.max_grad_diff, &|v| format!("{v:.2e}")),
        opt(r.max_grad, &|v| format!("{v:.2e}")),
    );
}

pub fn run(a: &BenchArgs) -> Result<()> {
    let matches = |name: &str| a.only.as_ref().map_or(true, |o| name.contains(o.as_str()));
    let names = drbokeh::bench::workload_names(a.quick);
    if !names.iter().any(|n| matches(n)) && !matches(drbokeh::bench::ADJOINT_WORKLOAD_NAME) {
        anyhow::bail!(
            "invalid parameter --only: '{}' matches no workload (names: {}, {})",
            a.only.as_deref().unwrap_or(""),
            names.join(", "),
            drbokeh::bench::ADJOINT_WORKLOAD_NAME
        );
    }
    if let Some(p) = &a.json {
        drbokeh::io::OutputPlan::new()
            .file(p, "--json", &["json"])
            .check()?;
    }
    crate::args::init_threads(a.threads)?;
    println!("threads: {}", rayon::current_num_threads());
    println!("| workload | MP | layers | K | L | engine | seconds | ns/px/layer | taps (spans: work) | speed-up vs fast | vs threaded | max diff vs fast (display) | mean diff (display) | max diff (linear) | band-layers spans/taps | disc area |");
    println!("| --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    let mut rows = Vec::new();
    for w in workloads_where(a.quick, matches) {
        rows.extend(run_workload(&w, &mut print_row)?);
    }
    let aw = adjoint_workload();
    let adjoint = if a
        .only
        .as_ref()
        .map_or(true, |o| aw.name.contains(o.as_str()))
    {
        let r = run_adjoint(&aw, !a.quick)?;
        print_adjoint(&r);
        Some(r)
    } else {
        None
    };
    if let Some(p) = &a.json {
        let json =
            serde_json::to_vec_pretty(&serde_json::json!({ "rows": rows, "adjoint": adjoint }))?;
        drbokeh::io::write_atomic(p, |w| {
            use std::io::Write;
            w.write_all(&json)
                .map_err(|e| drbokeh::Error::file(p, e.to_string()))
        })?;
    }
    Ok(())
}
