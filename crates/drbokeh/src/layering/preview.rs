//! Previews of a layer stack for people: each layer's colour over a checkerboard (by
//! alpha) and its disparity as grey, written beside the stack file.

use crate::image::Image;
use crate::io::{self, BitDepth};
use crate::stack::LayerStack;
use crate::Result;
use std::path::{Path, PathBuf};

/// `dir/name.npz` -> `dir/name.SUFFIX`.
pub fn sibling(output: &Path, suffix: &str) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "stack".into());
    output.with_file_name(format!("{stem}.{suffix}"))
}

/// Writes, for every layer `K` of `stack` (0 = front), `STACK.layerK.png` (colour over a
/// checkerboard by alpha, 8-bit) and `STACK.layerK.disparity.png` (disparity rescaled to the
/// stack's disparity range, 16-bit grey) beside `output` (`STACK.npz`), staged: they
/// appear when `staging` commits, together with whatever else it holds.
pub fn write_previews(
    staging: &mut io::Staging,
    output: &Path,
    stack: &LayerStack<f32>,
) -> Result<()> {
    let (w, h) = (stack.width, stack.height);
    let (lo, hi) = stack
        .layers
        .iter()
        .flat_map(|l| l.disparity.data.iter())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let span = if hi > lo { hi - lo } else { 1.0 };
    for (k, l) in stack.layers.iter().enumerate() {
        let mut over = Image::<f32>::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let a = l.alpha.at(x, y, 0);
                let checker = if (x / 8 + y / 8) % 2 == 0 { 0.8 } else { 0.55 };
                for c in 0..3 {
                    *over.at_mut(x, y, c) = a * l.rgb_encoded.at(x, y, c) + (1.0 - a) * checker;
                }
            }
        }
        staging.output(
            &sibling(output, &format!("layer{k}.png")),
            &over,
            BitDepth::Eight,
            |v| v,
        )?;
        let disp = Image::from_vec(
            w,
            h,
            1,
            l.disparity.data.iter().map(|&d| (d - lo) / span).collect(),
        )?;
        staging.grey(&sibling(output, &format!("layer{k}.disparity.png")), &disp)?;
    }
    Ok(())
}
