//! `drbokeh`: the command-line front end. Argument parsing, progress and exit codes only;
//! all work is done by the `drbokeh` library.

mod args;
mod bench_cmd;
mod dfd;
mod eval_cmd;
mod layers_cmd;
mod outputs;
mod progress;
mod render;
mod signals;
mod trace_cmd;
mod values;
mod vjp;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// Occlusion-aware, differentiable bokeh rendering (Dr.Bokeh).
///
/// Renders a shallow depth of field from an all-in-focus image plus disparity (and an
/// optional alpha matte), or from a layer stack. Start with:
///
///   drbokeh render --demo --output bokeh.png
#[derive(Parser)]
#[command(
    name = "drbokeh",
    version,
    propagate_version = true,
    max_term_width = 100
)]
struct Cli {
    #[command(subcommand)]
    command: Command,

    /// Input budget in megapixel-layers (width x height x layers / 10^6; f64 counts twice,
    /// a gradient tape four times): every input's size is checked from its header against
    /// it before anything is read. Default 128 (env DRBOKEH_MAX_MEGAPIXELS); raise it if you
    /// have the memory (at most 96 bytes per pixel-layer; see docs/limits.md).
    #[arg(long, global = true, value_name = "MP", value_parser = values::positive_f64)]
    max_megapixels: Option<f64>,
}

#[derive(Subcommand)]
enum Command {
    /// Render lens blur from a layer stack, an image + disparity map, or the built-in demo.
    Render(Box<render::RenderArgs>),
    /// Exact gradients of sum(G * render) w.r.t. colour, alpha, disparity, blur and focus.
    Vjp(Box<vjp::VjpArgs>),
    /// Performance report: fast vs threaded vs reference engines on standard workloads.
    Bench(Box<bench_cmd::BenchArgs>),
    /// Depth from defocus: recover disparity from an all-in-focus + defocused pair.
    Dfd(Box<dfd::DfdArgs>),
    /// Depth-from-defocus experiment over synthetic pairs: layers x loss combinations.
    DfdEval(Box<dfd::DfdEvalArgs>),
    /// Path-trace a billboard scene through a real (thick, spherical) lens: ground truth.
    Trace(Box<trace_cmd::TraceArgs>),
    /// Make the ray-traced ground-truth benchmark.
    Benchmark(Box<trace_cmd::BenchmarkArgs>),
    /// Decompose a photo (image + disparity, optional matte) into an inpainted layer stack.
    Layers(Box<layers_cmd::LayersArgs>),
    /// Evaluate every method on a ray-traced benchmark: scores, tables, plots, HTML gallery.
    Eval(Box<eval_cmd::EvalArgs>),
    /// Refocus gallery of image + disparity pairs, methods side by side (HTML).
    Gallery(Box<eval_cmd::GalleryArgs>),
}

fn main() {
    // Negative numbers are values, not options: `--focus -1` reaches the range check.
    let command = Cli::command().mut_subcommands(|c| {
        c.allow_negative_numbers(true)
            .mut_subcommands(|c| c.allow_negative_numbers(true))
    });
    let cli = match Cli::from_arg_matches(&command.get_matches()) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    signals::install();
    if let Some(mp) = cli.max_megapixels {
        if let Err(e) = drbokeh::budget::set_max_megapixels(mp) {
            fail(&anyhow::Error::from(e));
        }
    }
    let result = match cli.command {
        Command::Render(a) => render::run(&a),
        Command::Vjp(a) => vjp::run(&a),
        Command::Bench(a) => bench_cmd::run(&a),
        Command::Dfd(a) => dfd::run(&a),
        Command::DfdEval(a) => dfd::run_eval(&a),
        Command::Trace(a) => trace_cmd::run_trace(&a),
        Command::Benchmark(a) => trace_cmd::run_benchmark(&a),
        Command::Layers(a) => layers_cmd::run(&a),
        Command::Eval(a) => eval_cmd::run_eval(&a),
        Command::Gallery(a) => eval_cmd::run_gallery(&a),
    };
    if let Err(e) = result {
        fail(&e);
    }
}

/// Prints the error and exits: 2 for a bad option value (a usage error, as clap reports
/// its own), 1 for everything else (bad files, failed work).
fn fail(e: &anyhow::Error) -> ! {
    eprintln!("drbokeh: error: {}", args::describe(e));
    std::process::exit(if values::is_usage_error(e) { 2 } else { 1 });
}
