//! `drbokeh`: the command-line front end. Argument parsing, progress and exit codes only;
//! all work is done by the `drbokeh` library.

mod args;
mod bench_cmd;
mod dfd;
mod eval_cmd;
mod layers_cmd;
mod names;
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
/// optional alpha matte), or from a layer stack. `drbokeh COMMAND --help` describes a
/// command with examples (`-h`: the short form).
///
/// Examples:
///   drbokeh render --demo -o bokeh.png
///   drbokeh render --image examples/photo.png \
///       --disparity examples/photo.disp.png -o out.png
///   drbokeh render --help
#[derive(Parser)]
#[command(
    name = "drbokeh",
    version,
    verbatim_doc_comment,
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

// The variants carry no doc comments: a variant's doc comment would replace the help of
// its arguments' struct (clap sets `about` and clears `long_about`), and it is the struct's
// doc comment that holds each command's description and examples.
#[derive(Subcommand)]
enum Command {
    Render(Box<render::RenderArgs>),
    Vjp(Box<vjp::VjpArgs>),
    Bench(Box<bench_cmd::BenchArgs>),
    Dfd(Box<dfd::DfdArgs>),
    DfdEval(Box<dfd::DfdEvalArgs>),
    Trace(Box<trace_cmd::TraceArgs>),
    Benchmark(Box<trace_cmd::BenchmarkArgs>),
    Layers(Box<layers_cmd::LayersArgs>),
    Eval(Box<eval_cmd::EvalArgs>),
    Gallery(Box<eval_cmd::GalleryArgs>),
}

/// The command line as `main` parses it (negative numbers are values, not options:
/// `--focus -1` reaches the range check).
fn cli_command() -> clap::Command {
    Cli::command().mut_subcommands(|c| {
        c.allow_negative_numbers(true)
            .mut_subcommands(|c| c.allow_negative_numbers(true))
    })
}

fn main() {
    let cli = match Cli::from_arg_matches(&cli_command().get_matches()) {
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

#[cfg(test)]
mod help_tests;
