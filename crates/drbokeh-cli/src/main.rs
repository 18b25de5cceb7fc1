//! `drbokeh`: the command-line front end. Argument parsing, progress and exit codes only;
//! all work is done by the `drbokeh` library.

mod args;
mod bench_cmd;
mod dfd;
mod eval_cmd;
mod layers_cmd;
mod progress;
mod render;
mod trace_cmd;
mod vjp;

use clap::{Parser, Subcommand};

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
    let cli = Cli::parse();
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
        eprintln!("drbokeh: error: {}", args::describe(&e));
        std::process::exit(1);
    }
}
