//! `drbokeh render`.

use crate::args::{resolve, CameraArgs, ExecArgs, SceneArgs};
use crate::progress::Bar;
use anyhow::Result;
use clap::Args;
use drbokeh::io::{self, BitDepth, OutputFormat};
use drbokeh::{Engine, Real};
use std::path::PathBuf;
use std::time::Instant;

/// Render lens blur from a layer stack, an image + disparity map, or the built-in demo.
///
/// The scene is a layer stack (--layers), a photo with its disparity or depth map
/// (--image with --disparity or --depth; decomposed into depth layers, or the paper's two
/// layers with an --alpha matte), or the built-in demo (--demo). Focus with --focus (a
/// disparity) or --focus-at (tap a pixel); --blur sets the blur strength.
///
/// Examples:
///   drbokeh render --demo -o bokeh.png
///   drbokeh render --image examples/photo.png \
///       --disparity examples/photo.disp.png --focus-at 300,150 -o out.png
///   drbokeh render --image examples/photo.png \
///       --disparity examples/photo.disp.png --aperture hexagon --blur 40 \
///       -o out.exr
///   drbokeh render --layers stack.npz --preset paper --focus 0.4 --blur 30 \
///       --window 71 --f64 -o out.npy
///
/// Output format follows the extension: .png (8-bit, or --bit-depth 16), .tif, .jpg, .exr
/// (linear float) or .npy (float32 (H,W,3) display-encoded values, float64 with --f64;
/// unclipped).
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct RenderArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub exec: ExecArgs,

    /// Output file (.png, .tif, .jpg, .exr or .npy). Written only once complete.
    #[arg(long, short, value_name = "FILE")]
    pub output: PathBuf,

    /// Bits per channel for PNG and TIFF output.
    #[arg(long, default_value_t = 8, value_parser = crate::values::bit_depth)]
    pub bit_depth: u8,
}

pub fn run(a: &RenderArgs) -> Result<()> {
    // Fail on a bad output name before any work.
    let format = OutputFormat::from_path(&a.output)?;
    if a.bit_depth == 16 && !matches!(format, OutputFormat::Png | OutputFormat::Tiff) {
        anyhow::bail!(
            "invalid parameter --bit-depth: 16 bits need a .png or .tif output; {} is {}",
            a.output.display(),
            match format {
                OutputFormat::Jpeg => "JPEG (8 bits only)",
                _ => "floating point (no bit depth)",
            }
        );
    }
    crate::outputs::plan_for_scene(&a.scene, &a.camera)
        .file(&a.output, "--output", crate::outputs::RENDER_EXTENSIONS)
        .check()?;
    drbokeh::budget::set_work_kind(drbokeh::budget::WorkKind::new(a.exec.f64, false));
    a.exec.init_threads()?;
    if a.exec.f64 {
        run_typed::<f64>(a)
    } else {
        run_typed::<f32>(a)
    }
}

fn run_typed<T: Real>(a: &RenderArgs) -> Result<()> {
    let engine: Engine = a.exec.engine()?;
    let drbokeh::scene::Scene {
        stack,
        settings,
        notes,
    } = resolve::<T>(&a.scene, &a.camera, engine)?;
    if !a.exec.quiet {
        for n in &notes {
            eprintln!("drbokeh: note: {n}");
        }
    }
    let bar = Bar::new("render", a.exec.quiet);
    let t0 = Instant::now();
    let out = drbokeh::render(&stack, &settings, engine, &bar)?;
    bar.finish();
    // The stack is not needed to encode: free it first, so that the peak is the render's
    // (stack + output), not stack + output + encoder (docs/limits.md).
    let (width, height, layers) = (stack.width, stack.height, stack.layers.len());
    drop(stack);
    let cam = &settings.camera;
    let tone = settings.tone();
    let bit_depth = if a.bit_depth == 16 {
        BitDepth::Sixteen
    } else {
        BitDepth::Eight
    };
    io::write_output(&a.output, &out, bit_depth, |v| tone.linearize(v))?;
    if !a.exec.quiet {
        eprintln!(
            "drbokeh: rendered {}x{}, {} layer(s), focus {:.4}, K {}, L {} in {:.2} s -> {}",
            width,
            height,
            layers,
            cam.focus_disparity,
            cam.blur_k,
            cam.window.size(),
            t0.elapsed().as_secs_f64(),
            a.output.display()
        );
    }
    Ok(())
}
