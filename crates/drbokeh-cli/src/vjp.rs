//! `drbokeh vjp`: gradients of `sum(G * render)` with respect to every input.

use crate::args::{resolve, CameraArgs, ExecArgs, SceneArgs};
use crate::progress::Bar;
use anyhow::{bail, Result};
use clap::Args;
use drbokeh::Real;
use std::path::PathBuf;

/// Exact gradients of sum(G * render) w.r.t. colour, alpha, disparity, blur and focus.
///
/// The vector-Jacobian product of the render. `render` is what `drbokeh render -o x.npy`
/// writes with the same flags (display-encoded values). The output NPZ holds `rgb`
/// (N,H,W,3), `alpha` (N,H,W), `disparity` (N,H,W) and the scalars `blur` (d/dK) and
/// `focus` (d/df); float64 with --f64. With --image/--disparity the image is decomposed
/// into layers exactly as `render` does for the same focus and blur (one opaque layer
/// with --single-layer), and N is that stack's layer count.
///
/// --engine auto (the default) runs forward and backward on the span engine in f32 (row
/// spans where they are cheaper, the fast engine's taps elsewhere; within 1e-3 of the exact
/// gradient's largest value, tested) and on the threaded engine with --f64 (the exact
/// gradient, every window tap); spans, fast, threaded and reference choose explicitly
/// (fast: only the taps that can contribute, within 1e-5; reference runs the threaded
/// adjoint).
///
/// Examples (the first writes a render to use as G):
///   drbokeh render --demo --demo-size 160x107 -o g.npy
///   drbokeh vjp --demo --demo-size 160x107 --grad-output g.npy -o grads.npz
///   drbokeh vjp --layers stack.npz --grad-output g.npy --focus 0.4 --blur 30 \
///       --window 71 --f64 -o grads.npz
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct VjpArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub exec: ExecArgs,

    /// Upstream gradient G: NPY (H, W, 3), float32 or float64, the render's shape.
    #[arg(long, value_name = "G.npy")]
    pub grad_output: PathBuf,

    /// Apply the published kernel's gradient rescaling (magnitudes in [1e-6, 1e-2) raised to
    /// 1e-2). A training heuristic: the result is no longer the exact gradient.
    #[arg(long)]
    pub rescale_small_gradients: bool,

    /// Output NPZ of gradients.
    #[arg(long, short, value_name = "GRADS.npz")]
    pub output: PathBuf,
}

pub fn run(a: &VjpArgs) -> Result<()> {
    crate::outputs::plan_for_scene(&a.scene, &a.camera)
        .input(&a.grad_output, "--grad-output")
        .file(&a.output, "--output", &["npz"])
        .check()?;
    drbokeh::budget::set_work_kind(drbokeh::budget::WorkKind::new(a.exec.f64, true));
    a.exec.engine()?;
    a.exec.init_threads()?;
    if a.exec.f64 {
        run_typed::<f64>(a)
    } else {
        run_typed::<f32>(a)
    }
}

fn run_typed<T: Real>(a: &VjpArgs) -> Result<()> {
    let engine = a.exec.engine()?;
    // The same stack as `render` with these options (an image is decomposed for this
    // focus and blur), so the forward pass here is the render the gradient belongs to.
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
    let g = drbokeh::io::read_npy_image::<T>(&a.grad_output, 3, "output gradient")?;
    if g.width != stack.width || g.height != stack.height {
        bail!(
            "{}: gradient is {}x{}, but the render is {}x{}",
            a.grad_output.display(),
            g.width,
            g.height,
            stack.width,
            stack.height
        );
    }
    let bar = Bar::new("forward", a.exec.quiet);
    let (_, tape) = drbokeh::render_with_tape_on(&stack, &settings, engine, &bar)?;
    bar.finish();
    let bar = Bar::new("backward", a.exec.quiet);
    let mut grads = tape.backward(&g, &bar)?;
    bar.finish();
    if a.rescale_small_gradients {
        grads.rescale_small(1e-6, 1e-2);
    }
    drbokeh::io::write_gradients(&a.output, &grads, stack.width, stack.height)?;
    if !a.exec.quiet {
        eprintln!(
            "drbokeh: gradients of {} layer(s) -> {} (d/dK = {:.6e}, d/df = {:.6e})",
            stack.layers.len(),
            a.output.display(),
            grads.blur_k,
            grads.focus
        );
    }
    Ok(())
}
