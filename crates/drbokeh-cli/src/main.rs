//! `drbokeh`: the command-line front end. Argument parsing, progress and exit codes only;
//! all work is done by the `drbokeh` library.

mod args;
mod progress;
mod render;

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
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::run(&a),
    };
    if let Err(e) = result {
        eprintln!("drbokeh: error: {e:#}");
        std::process::exit(1);
    }
}
