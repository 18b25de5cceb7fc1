//! `drbokeh layers`: from a photo (image + disparity, optional matte) to a layer stack.

use anyhow::{bail, Result};
use clap::Args;
use drbokeh::io::{self, DepthKind, DisparityOptions};
use drbokeh::layering::{self, LayeringOptions};
use drbokeh::model::Tone;
use drbokeh::presets::Transfer;
use drbokeh::scene::{self, Layering, Photo, PhotoFiles};
use std::path::PathBuf;
use std::time::Instant;

/// Decompose a photo (image + disparity, optional matte) into an inpainted layer stack.
///
/// No learned model, no downloads. With --alpha: the paper's two layers (foreground =
/// matte; background inpainted under it). Without: up to --max-layers depth layers cut at
/// disparity discontinuities, each layer's hidden part inpainted (colour by fast marching,
/// disparity by a smooth fill from the far side). Writes STACK.npz (input to `drbokeh
/// render --layers`) and, unless --no-preview, STACK.layerK.png (colour over a checkerboard
/// by alpha) and STACK.layerK.disparity.png for every layer K (0 = front). See
/// docs/layering.md.
///
/// Examples:
///   drbokeh layers --image examples/photo.png \
///       --disparity examples/photo.disp.png -o stack.npz
///   drbokeh layers --image photo.jpg --depth depth.exr --alpha matte.png \
///       -o stack.npz
///   drbokeh render --layers stack.npz --focus-at 300,150 -o out.png
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct LayersArgs {
    /// All-in-focus image (PNG 8/16-bit, JPEG, TIFF, or linear EXR).
    #[arg(long, value_name = "IMAGE")]
    pub image: PathBuf,

    /// Disparity map (larger = nearer): 16-bit PNG, EXR, NPY, or NPZ key `data`.
    #[arg(long, value_name = "MAP", conflicts_with = "depth")]
    pub disparity: Option<PathBuf>,

    /// Metric depth map (larger = farther); converted to disparity 1/z.
    #[arg(long, value_name = "MAP")]
    pub depth: Option<PathBuf>,

    /// Keep the map's values instead of min-max normalising disparity to [0, 1].
    #[arg(long)]
    pub no_normalize: bool,

    /// Alpha matte (grey image, or the alpha of an RGBA PNG): two layers from the matte.
    #[arg(long, value_name = "MATTE")]
    pub alpha: Option<PathBuf>,

    /// Most layers to make without a matte (1 to 16).
    #[arg(long, value_name = "N", default_value_t = layering::DEFAULT_MAX_LAYERS)]
    pub max_layers: usize,

    /// Discontinuity threshold: a neighbour step in disparity larger than this fraction of
    /// the map's range may separate layers.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.05)]
    pub jump: f64,

    /// How far (pixels) a middle layer is filled in behind nearer ones (default: 5 % of
    /// the larger image side, at least 16). The back layer is always filled entirely.
    #[arg(long, value_name = "PX")]
    pub band: Option<f64>,

    /// Make the stack for a render at this focus disparity (with --blur): cuts where the
    /// nearer side would be less blurred than the farther one are left out, as
    /// `drbokeh render --image` does.
    #[arg(long, value_name = "F", requires = "blur", value_parser = crate::values::focus)]
    pub focus: Option<f64>,

    /// The render's blur K (pixels per unit of disparity), with --focus.
    #[arg(long, value_name = "K", requires = "focus")]
    pub blur: Option<f64>,

    /// Output layer stack (.npz). Written only once complete.
    #[arg(long, short, value_name = "STACK.npz")]
    pub output: PathBuf,

    /// Do not write the preview PNGs.
    #[arg(long)]
    pub no_preview: bool,

    /// Number of worker threads (default: all cores). Output does not depend on it.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,

    /// No notes on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: &LayersArgs) -> Result<()> {
    // Every output (the stack and each possible preview) checked before any work.
    let mut plan = io::OutputPlan::new();
    plan.input(&a.image, "--image");
    for (p, option) in [
        (&a.disparity, "--disparity"),
        (&a.depth, "--depth"),
        (&a.alpha, "--alpha"),
    ] {
        if let Some(p) = p {
            plan.input(p, option);
        }
    }
    plan.file(&a.output, "--output", &["npz"]);
    let most_layers = if a.alpha.is_some() {
        2
    } else {
        a.max_layers.clamp(1, 16)
    };
    if !a.no_preview {
        for k in 0..most_layers {
            plan.file(
                layering::sibling(&a.output, &format!("layer{k}.png")),
                "a preview",
                &["png"],
            );
            plan.file(
                layering::sibling(&a.output, &format!("layer{k}.disparity.png")),
                "a preview",
                &["png"],
            );
        }
    }
    plan.check()?;
    let opts = LayeringOptions {
        max_layers: a.max_layers,
        jump_fraction: a.jump,
        occlusion_band_px: a.band,
        focus_hint: a.focus.zip(a.blur),
        ..LayeringOptions::default()
    };
    opts.validate()?;
    crate::args::init_threads(a.threads)?;
    let (map, kind) = match (&a.disparity, &a.depth) {
        (Some(p), None) => (p, DepthKind::Disparity),
        (None, Some(p)) => (p, DepthKind::Depth),
        _ => bail!(
            "drbokeh layers needs a disparity map (--disparity MAP) or a depth map (--depth MAP)"
        ),
    };
    let files = PhotoFiles {
        map_options: DisparityOptions {
            kind,
            normalize: !a.no_normalize,
        },
        matte: a.alpha.clone(),
        // What the budget is checked against (the decomposition itself follows `opts`).
        layering: Layering::Decompose {
            max_layers: most_layers,
        },
        ..PhotoFiles::new(&a.image, map, kind)
    };
    // Linear EXR colour is display-encoded with the default transfer (gamma 2.2).
    let tone = Tone::new(Transfer::Gamma, 2.2, 0.0);
    let photo: Photo<f32> = scene::read_photo(&files, &tone)?;
    let t0 = Instant::now();
    let d = layering::decompose(
        &photo.rgb_encoded,
        &photo.disparity,
        photo.matte.as_ref(),
        &opts,
    )?;
    let elapsed = t0.elapsed().as_secs_f64();
    // The stack and its previews appear together, once all are written.
    let mut staging = io::Staging::new();
    staging.stack(&a.output, &d.stack)?;
    if !a.no_preview {
        layering::write_previews(&mut staging, &a.output, &d.stack)?;
    }
    staging.commit()?;
    if !a.quiet {
        for n in &d.notes {
            eprintln!("drbokeh: note: {n}");
        }
        let cuts = if d.thresholds.is_empty() {
            String::new()
        } else {
            format!(
                ", cut at disparity {}",
                d.thresholds
                    .iter()
                    .map(|t| format!("{t:.3}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        eprintln!(
            "drbokeh: {} layer(s){cuts} for {}x{} in {elapsed:.2} s -> {}",
            d.stack.layers.len(),
            d.stack.width,
            d.stack.height,
            a.output.display()
        );
    }
    Ok(())
}
