//! The input budget: how much work a command may take on, checked from file headers before
//! any pixel is allocated.
//!
//! Work is counted in **megapixel-layers**: `width x height x layers / 10^6`, where a layer is
//! one plane set of the renderer (colour, alpha, disparity). A single image or map counts as
//! one layer; a layer stack as its N layers; an image that `render`/`layers` decompose as
//! `--max-layers` layers (the most the decomposition may make); a ray-traced scene as its
//! billboards plus [`TRACE_EXTRA_LAYERS`] image planes, plus its textures' texels. Two
//! multipliers account for larger per-pixel state: double precision ([`WorkKind::F64`],
//! x2) and a recorded tape for gradients ([`WorkKind::Tape`], x4; both: x8).
//!
//! The budget is [`DEFAULT_MAX_MEGAPIXELS`] unless raised (`--max-megapixels`, the
//! `DRBOKEH_MAX_MEGAPIXELS` environment variable, or [`set_max_megapixels`]). Independently of
//! the budget, no image may exceed [`crate::image::MAX_DIMENSION`] per side or
//! [`crate::image::MAX_PIXELS`] pixels.
//!
//! Memory: every command's peak resident memory stays below [`BYTES_PER_WORK_PIXEL`] bytes
//! per counted pixel-layer of work plus [`BASE_BYTES`]. Measured with `/usr/bin/time -v`
//! at 1 and 4 MP (docs/limits.md): 12 to 82 bytes per unit, the most for the threaded
//! engine in f32 (82) and for f64 renders (79); the default fast f32 render needs 28. So
//! the default budget of 128 megapixel-layers stays under 12.5 GB whatever the command
//! (3.6 GB for a fast f32 render), and a 400-MP single-layer f32 render
//! (`--max-megapixels 400`) under 39 GB (11 GB on the fast engine).
//!
//! A `render --layers` run (f32) peaks at about `20 N P + 12 P` bytes plus the engine's
//! per-thread bands and ~100 MB, for `P` pixels and `N` layers: the decoded stack once
//! (NPZ arrays read layer by layer into their planes) and the rendered image; the stack is
//! freed and PNG/EXR are encoded row by row before anything else is allocated. Measured:
//! 1.43 GB at 24 MP, 2 layers, K 30 and K 100 (about 30 bytes per pixel-layer;
//! docs/limits.md).

use crate::{Error, Result};
use std::sync::atomic::{AtomicU64, Ordering};

/// The default budget, in megapixel-layers: a 25-MP photo decomposed into 5 layers, a 128-MP
/// single image, or a 2-MP stack of 64 layers.
pub const DEFAULT_MAX_MEGAPIXELS: f64 = 128.0;

/// Upper bound on peak resident memory per counted pixel-layer of work, in bytes (the
/// documented memory constant: the largest measured, 82, plus margin; docs/limits.md).
pub const BYTES_PER_WORK_PIXEL: u64 = 96;

/// Memory a command needs whatever its size (binary, thread stacks, small tables), bytes.
pub const BASE_BYTES: u64 = 256 << 20;

/// Image planes a traced scene holds besides one per billboard (defocused and all-in-focus
/// images, their encoded copies, depth and disparity).
pub const TRACE_EXTRA_LAYERS: u64 = 4;

/// Layers a depth-from-defocus run counts per pixel of its images (its pyramids, renders,
/// gradients and optimiser state: about 350 bytes per pixel, measured).
pub const DFD_WORK_LAYERS: u64 = 4;

/// The most billboards a scene file may have.
pub const MAX_BILLBOARDS: usize = 256;

/// How a command's per-pixel state scales.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum WorkKind {
    /// A forward pass (render, decomposition, trace) in single precision.
    #[default]
    F32,
    /// A forward pass in double precision (x2).
    F64,
    /// A forward pass with a gradient tape, single precision (x4).
    Tape,
    /// A forward pass with a gradient tape, double precision (x8).
    TapeF64,
}

impl WorkKind {
    /// The multiplier on pixel-layers.
    pub fn factor(self) -> u64 {
        match self {
            WorkKind::F32 => 1,
            WorkKind::F64 => 2,
            WorkKind::Tape => 4,
            WorkKind::TapeF64 => 8,
        }
    }

    /// The kind for a precision and whether gradients are recorded.
    pub fn new(f64: bool, tape: bool) -> Self {
        match (f64, tape) {
            (false, false) => WorkKind::F32,
            (true, false) => WorkKind::F64,
            (false, true) => WorkKind::Tape,
            (true, true) => WorkKind::TapeF64,
        }
    }

    fn note(self) -> &'static str {
        match self {
            WorkKind::F32 => "",
            WorkKind::F64 => " x 2 (--f64)",
            WorkKind::Tape => " x 4 (gradient tape)",
            WorkKind::TapeF64 => " x 8 (gradient tape, --f64)",
        }
    }
}

/// The budget in force: megapixel-layers (bits of an f64) and the work kind.
static MAX_MEGAPIXELS_BITS: AtomicU64 = AtomicU64::new(0);
static KIND: AtomicU64 = AtomicU64::new(0);

/// Sets the process-wide budget in megapixel-layers (finite, > 0).
pub fn set_max_megapixels(megapixels: f64) -> Result<()> {
    if !megapixels.is_finite() || megapixels <= 0.0 || megapixels > 1e6 {
        return Err(Error::param(
            "--max-megapixels",
            format!("must be a number in (0, 1000000], got {megapixels}"),
        ));
    }
    MAX_MEGAPIXELS_BITS.store(megapixels.to_bits(), Ordering::Relaxed);
    Ok(())
}

/// Sets how this process's work scales (precision, gradient tape).
pub fn set_work_kind(kind: WorkKind) {
    KIND.store(kind as u64, Ordering::Relaxed);
}

/// The budget in force, megapixel-layers: [`set_max_megapixels`], else the environment
/// variable `DRBOKEH_MAX_MEGAPIXELS`, else [`DEFAULT_MAX_MEGAPIXELS`].
pub fn max_megapixels() -> f64 {
    let bits = MAX_MEGAPIXELS_BITS.load(Ordering::Relaxed);
    if bits != 0 {
        return f64::from_bits(bits);
    }
    std::env::var("DRBOKEH_MAX_MEGAPIXELS")
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|v| v.is_finite() && *v > 0.0)
        .unwrap_or(DEFAULT_MAX_MEGAPIXELS)
}

/// The work kind in force.
pub fn work_kind() -> WorkKind {
    match KIND.load(Ordering::Relaxed) {
        1 => WorkKind::F64,
        2 => WorkKind::Tape,
        3 => WorkKind::TapeF64,
        _ => WorkKind::F32,
    }
}

/// The budget in pixel-layers (before the work kind's multiplier).
pub fn max_pixel_layers() -> u64 {
    (max_megapixels() * 1e6) as u64
}

/// The most bytes a decoder may allocate for one image: its pixels at 16 bytes each (RGBA
/// float, the widest decoded layout) within the budget, plus 64 MiB of working space.
pub fn max_decoder_bytes() -> u64 {
    max_pixel_layers()
        .saturating_mul(16)
        .saturating_add(64 << 20)
}

/// Fails unless `width x height x layers` pixel-layers (times the work kind's multiplier)
/// fit the budget. `what` names the source (a file, `--demo-size`, a scene) in the message.
pub fn check_work(what: &str, width: u64, height: u64, layers: u64) -> Result<()> {
    check_work_units(what, &format!("{width}x{height} x {layers} layer(s)"), {
        width.saturating_mul(height).saturating_mul(layers.max(1))
    })
}

/// As [`check_work`] for a count already in pixel-layers, described by `detail`.
pub fn check_work_units(what: &str, detail: &str, pixel_layers: u64) -> Result<()> {
    let kind = work_kind();
    let work = pixel_layers.saturating_mul(kind.factor());
    let max = max_pixel_layers();
    if work > max {
        let need = (work as f64 / 1e6).ceil();
        return Err(Error::input(
            what,
            format!(
                "too large for the input budget: {detail}{} = {:.1} megapixel-layers, budget {} \
                 (raise it with --max-megapixels {need} if you have about {:.1} GB of memory)",
                kind.note(),
                work as f64 / 1e6,
                fmt_mp(max_megapixels()),
                (work * BYTES_PER_WORK_PIXEL + BASE_BYTES) as f64 / 1e9,
            ),
        ));
    }
    Ok(())
}

/// Fails unless an array of this shape fits the budget, counted in pixel-layers: its values,
/// divided by the last axis when that is a channel axis (3-D or more, at most 4 long). So
/// an `(H, W)` map, an `(H, W, 3)` image and an `(N, H, W)` or `(N, H, W, 3)` stack count
/// H x W, H x W and N x H x W.
pub fn check_array(what: &str, shape: &[u64]) -> Result<()> {
    let values = shape.iter().fold(1u64, |a, &d| a.saturating_mul(d));
    let channels = match shape {
        [.., c] if shape.len() >= 3 && (1..=4).contains(c) => *c,
        _ => 1,
    };
    check_work_units(
        what,
        &format!("array of shape {shape:?}"),
        values / channels,
    )
}

fn fmt_mp(v: f64) -> String {
    if v.fract() == 0.0 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_scale_and_messages_name_the_override() {
        assert_eq!(WorkKind::new(true, true).factor(), 8);
        // 64 layers of 2000x2000 exceed the default budget of 128 megapixel-layers.
        let e = check_work("z.npz", 2000, 2000, 64).unwrap_err().to_string();
        assert!(
            e.contains("z.npz") && e.contains("--max-megapixels 256"),
            "{e}"
        );
        check_work("ok", 4000, 3000, 5).unwrap();
    }
}
