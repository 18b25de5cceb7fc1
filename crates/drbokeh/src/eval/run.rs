//! Running an evaluation: every method on every scene of a benchmark, rendered, scored and
//! (optionally) pictured.

use super::images::write_scene_images;
use super::methods::Method;
use super::scenes::{list_scenes, SceneInputs};
use super::scoring::{score, SceneResult};
use super::summary::{bucket_of, Report};
use crate::{Progress, Result};
use std::path::Path;
use std::time::Instant;

/// Renders `scene` with `method` (its K, focus and camera, [`SceneInputs::camera`]): the
/// display-encoded result, clipped to [0, 1].
pub fn render_method(method: Method, scene: &SceneInputs) -> Result<crate::Image<f32>> {
    let cam = scene.camera();
    match method.input() {
        super::methods::MethodInput::AifDisparity => {
            super::methods::render_photo(method, &scene.aif, &scene.disparity, &cam)
        }
        super::methods::MethodInput::Layers => method.render(&scene.layers, &cam),
    }
}

/// Renders and scores every method on one scene. With `images`, writes the gallery's
/// pictures for the scene into that directory ([`write_scene_images`]). `progress` advances
/// by one per method.
pub fn evaluate_scene(
    scene: &SceneInputs,
    methods: &[Method],
    images: Option<&Path>,
    progress: &dyn Progress,
) -> Result<SceneResult> {
    let mut results = Vec::new();
    let mut renders = Vec::new();
    for &m in methods {
        let t = Instant::now();
        let out = render_method(m, scene)?;
        let time_s = t.elapsed().as_secs_f64();
        let mut r = score(m, &out, &scene.ground_truth)?;
        r.time_s = time_s;
        results.push(r);
        if images.is_some() {
            renders.push((m, out));
        }
        progress.advance(1);
    }
    if let Some(dir) = images {
        write_scene_images(dir, scene, &renders)?;
    }
    Ok(SceneResult {
        scene: scene.name.clone(),
        blur: scene.blur_k,
        focus: scene.focus,
        max_coc_px: scene.max_coc_px,
        bucket: bucket_of(scene.max_coc_px),
        width: scene.aif.width,
        height: scene.aif.height,
        results,
    })
}

/// Evaluates every scene of a benchmark directory with `methods`, writing the scene
/// pictures under `out/scenes/<scene>/` when `out` is given. `progress` counts
/// scenes x methods.
pub fn evaluate_benchmark(
    benchmark: &Path,
    methods: &[Method],
    out: Option<&Path>,
    limit: Option<usize>,
    progress: &dyn Progress,
) -> Result<Report> {
    let mut dirs = list_scenes(benchmark)?;
    if let Some(n) = limit {
        dirs.truncate(n.max(1));
    }
    progress.start((dirs.len() * methods.len()) as u64);
    let mut results = Vec::new();
    for dir in &dirs {
        let scene = SceneInputs::load(dir)?;
        let images = out.map(|o| o.join("scenes").join(&scene.name));
        results.push(evaluate_scene(
            &scene,
            methods,
            images.as_deref(),
            progress,
        )?);
    }
    Ok(Report::new(benchmark, methods, results))
}
