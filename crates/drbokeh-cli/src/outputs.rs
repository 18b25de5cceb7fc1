//! The inputs each command reads, for the output checks made before any work
//! ([`drbokeh::io::OutputPlan`]: directory exists and is writable, extension supported,
//! no output is an input or another output).

use crate::args::{CameraArgs, SceneArgs};
use drbokeh::io::OutputPlan;
use std::path::Path;

/// Extensions `render` writes (see [`drbokeh::io::OutputFormat`]).
pub const RENDER_EXTENSIONS: &[&str] = &["png", "tif", "tiff", "exr", "npy", "jpg", "jpeg"];

/// A plan holding every input file named by the scene and camera options.
pub fn plan_for_scene(scene: &SceneArgs, camera: &CameraArgs) -> OutputPlan {
    let mut plan = OutputPlan::new();
    for (path, option) in [
        (&scene.layers, "--layers"),
        (&scene.image, "--image"),
        (&scene.disparity, "--disparity"),
        (&scene.depth, "--depth"),
        (&scene.alpha, "--alpha"),
    ] {
        if let Some(p) = path {
            plan.input(p, option);
        }
    }
    if let Some(kernel) = camera.aperture.strip_prefix("kernel:") {
        plan.input(Path::new(kernel), "--aperture kernel:");
    }
    plan
}
