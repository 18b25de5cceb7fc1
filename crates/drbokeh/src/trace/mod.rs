//! Ray-traced ground truth: a path tracer through a real (thick, spherical) lens, billboard
//! scenes, and the standard benchmark.
//!
//! - [`optics`]: the lens (Snell refraction at both spherical surfaces, or an ideal thin
//!   lens), aperture stop and sensor.
//! - [`scene`]: the JSON scene format and the traceable [`Scene`].
//! - [`render`]: the Monte Carlo passes (defocused image; all-in-focus, layers and depth
//!   through the chief ray).
//! - [`benchmark`]: the seeded procedural scenes of the standard benchmark.
//! - [`write_scene_dir`]: writes one scene's outputs atomically.
//!
//! Display encoding: every display-encoded output (PNG, the layer stack's `rgb`) uses the
//! exact sRGB curve, as camera photos do ([`texture::DISPLAY_ENCODING`]). The layer stack
//! is not clipped: highlights above white keep their linear energy (encoded values > 1),
//! so that a renderer fed the true layers can reproduce the traced bokeh balls.
//! See `docs/ground-truth.md` for the full description.

pub mod benchmark;
pub mod optics;
pub mod procedural;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod texture;

pub use optics::{LensModel, Optics, SphericalLens};
pub use render::{render_defocus, render_pinhole, PinholeImages};
pub use scene::{Scene, SceneSpec};

use crate::image::Image;
use crate::io::{self, BitDepth};
use crate::stack::{Layer, LayerStack};
use crate::{Error, Progress, Result};
use std::path::Path;
use texture::{decode_display, encode_display, DISPLAY_ENCODING};

/// Everything traced for one scene.
#[derive(Clone, Debug)]
pub struct TraceOutputs {
    /// The ground-truth defocused image, linear light.
    pub defocus_linear: Image<f32>,
    /// All-in-focus image, layers and depth.
    pub pinhole: PinholeImages,
}

/// Traces a loaded scene: the defocused image at `spec.render.spp` and the pinhole passes
/// at `spec.render.aif_spp`. Progress counts rows of both passes.
pub fn trace_scene(
    scene: &Scene,
    spec: &scene::RenderSpec,
    progress: &dyn Progress,
) -> Result<TraceOutputs> {
    let h = scene.optics.height_px as u64;
    progress.start(2 * h);
    let pinhole = render_pinhole(scene, spec.aif_spp, spec.seed, progress)?;
    let defocus_linear = render_defocus(scene, spec.spp, spec.seed, progress)?;
    Ok(TraceOutputs {
        defocus_linear,
        pinhole,
    })
}

/// Display-encodes a linear image (sRGB, not clipped).
pub fn encode_image(linear: &Image<f32>) -> Image<f32> {
    Image {
        width: linear.width,
        height: linear.height,
        channels: linear.channels,
        data: linear
            .data
            .iter()
            .map(|&v| encode_display(v as f64) as f32)
            .collect(),
    }
}

/// The layered ground truth as the renderer's layer stack (front first): colour
/// display-encoded (sRGB) and *not* clipped (a highlight 10x above white stays 10x above
/// white after decoding), alpha, and constant normalised disparity.
pub fn layer_stack(scene: &Scene, pinhole: &PinholeImages) -> Result<LayerStack<f32>> {
    let (w, h) = (scene.optics.width_px, scene.optics.height_px);
    let layers = scene
        .billboards
        .iter()
        .zip(&pinhole.layers)
        .map(|(b, l)| {
            let rgb = encode_image(&l.rgb_linear);
            let d = scene.disparity_of_depth(b.depth_mm) as f32;
            Ok(Layer {
                rgb_encoded: rgb,
                alpha: l.alpha.clone(),
                disparity: Image::from_vec(w, h, 1, vec![d; w * h])?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    LayerStack::new(layers)
}

/// The derived parameters recorded in `scene.json` (`derived`).
pub fn derived_record(scene: &Scene) -> serde_json::Value {
    let o = &scene.optics;
    let (near, far) = scene.depth_range_mm();
    let lens = match o.lens {
        LensModel::Spherical(l) => serde_json::json!({
            "model": "spherical",
            "curvature_radius_mm": l.curvature_radius_mm,
            "rim_radius_mm": l.rim_radius_mm,
            "eta": l.eta,
            "thickness_mm": l.thickness_mm(),
            "sphere_centre_distance_mm": l.centre_distance_mm(),
            "focal_length_mm": l.focal_length_mm(),
            "front_principal_plane_z_mm": l.front_principal_plane_z_mm(),
            "rear_principal_plane_z_mm": l.rear_principal_plane_z_mm(),
            "aperture_stop": "at the rear vertex",
        }),
        LensModel::Thin { focal_length_mm } => serde_json::json!({
            "model": "thin",
            "focal_length_mm": focal_length_mm,
        }),
    };
    let billboards: Vec<_> = scene
        .billboards
        .iter()
        .map(|b| {
            serde_json::json!({
                "name": b.name,
                "depth_mm": b.depth_mm,
                "disparity": scene.disparity_of_depth(b.depth_mm),
                "coc_radius_px": o.coc_radius_px(b.depth_mm),
                "texture_size": [b.texture.width, b.texture.height],
            })
        })
        .collect();
    let max_coc = scene
        .billboards
        .iter()
        .map(|b| o.coc_radius_px(b.depth_mm))
        .fold(0.0, f64::max);
    serde_json::json!({
        "lens": lens,
        "aperture_radius_mm": o.aperture_radius_mm,
        "f_number": o.focal_length_mm() / (2.0 * o.aperture_radius_mm),
        "sensor_distance_mm": o.sensor_distance_mm,
        "focus_distance_mm": o.focus_distance_mm(),
        "pixel_pitch_mm": o.pixel_pitch_mm,
        "sensor_size_mm": [o.sensor_width_mm(), o.sensor_height_mm()],
        "disparity_definition": "(1/z - 1/z_far) / (1/z_near - 1/z_far), z from the front principal plane; 1 = nearest billboard",
        "disparity_near_depth_mm": near,
        "disparity_far_depth_mm": far,
        "coc_definition": "r_px = Ra D_I |1/z - 1/z_f| / pixel_pitch (paraxial); renderer radius = blur |disp - focus| + 1",
        "blur": scene.blur_k_px(),
        "focus": scene.focus_disparity(),
        "max_coc_radius_px": max_coc,
        "display_encoding": format!("{DISPLAY_ENCODING}; EXR files are linear; layers.npz rgb is encoded but not clipped"),
        "billboards_front_to_back": billboards,
        "files": {
            "bokeh.png": "ground-truth defocused image, 16-bit, display-encoded, clipped",
            "bokeh.exr": "ground-truth defocused image, linear float",
            "aif.png": "all-in-focus image (chief ray), 16-bit, display-encoded, clipped",
            "aif.exr": "all-in-focus image, linear float",
            "depth.npy": "metric depth (mm) of the most visible billboard, float32 (H, W)",
            "disparity.npy": "normalised disparity, float32 (H, W)",
            "disparity.png": "normalised disparity, 16-bit grey",
            "layers.npz": "layered ground truth: rgb (N,H,W,3) display-encoded, alpha (N,H,W), disparity (N,H,W); front first",
            "scene.json": "this record; also a valid input to `drbokeh trace`",
        },
        "drbokeh_version": env!("CARGO_PKG_VERSION"),
    })
}

fn write_npy(path: &Path, img: &Image<f32>) -> Result<()> {
    use ndarray_npy::WriteNpyExt;
    let arr = ndarray::Array2::from_shape_vec((img.height, img.width), img.data.clone())
        .map_err(|e| Error::file(path, e.to_string()))?;
    io::write_atomic(path, |out| {
        arr.write_npy(out)
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

fn write_grey16(path: &Path, img: &Image<f32>) -> Result<()> {
    let data: Vec<u16> = img
        .data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
        .collect();
    let buf: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
        image::ImageBuffer::from_raw(img.width as u32, img.height as u32, data)
            .ok_or_else(|| Error::file(path, "bad image size"))?;
    io::write_atomic(path, |out| {
        image::DynamicImage::ImageLuma16(buf)
            .write_to(out, image::ImageFormat::Png)
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

/// Writes one scene's outputs into directory `dir`, atomically: everything is written into
/// a temporary directory beside it, which is renamed to `dir` only when complete. Fails if
/// `dir` already exists. `spec` is recorded (with `derived` filled in) as `scene.json`.
pub fn write_scene_dir(
    dir: &Path,
    spec: &SceneSpec,
    scene: &Scene,
    out: &TraceOutputs,
) -> Result<()> {
    if dir.exists() {
        return Err(Error::file(dir, "output directory already exists"));
    }
    let mut staging = io::Staging::new();
    stage_scene_dir(&mut staging, dir, false, spec, scene, out)?;
    staging.commit()
}

/// Stages one scene's directory `dir` (see [`write_scene_dir`]); with `replace`, an existing
/// `dir` is replaced as a whole at [`io::Staging::commit`].
pub fn stage_scene_dir(
    staging: &mut io::Staging,
    dir: &Path,
    replace: bool,
    spec: &SceneSpec,
    scene: &Scene,
    out: &TraceOutputs,
) -> Result<()> {
    let tmp = staging.dir(dir, replace)?;
    let t = tmp.as_path();
    let to_linear = |v: f64| decode_display(v);
    let bokeh = encode_image(&out.defocus_linear);
    let aif = encode_image(&out.pinhole.aif_linear);
    io::write_output(&t.join("bokeh.png"), &bokeh, BitDepth::Sixteen, to_linear)?;
    io::write_output(&t.join("bokeh.exr"), &bokeh, BitDepth::Sixteen, to_linear)?;
    io::write_output(&t.join("aif.png"), &aif, BitDepth::Sixteen, to_linear)?;
    io::write_output(&t.join("aif.exr"), &aif, BitDepth::Sixteen, to_linear)?;
    let disparity = scene.disparity_map(&out.pinhole.depth_mm);
    write_npy(&t.join("depth.npy"), &out.pinhole.depth_mm)?;
    write_npy(&t.join("disparity.npy"), &disparity)?;
    write_grey16(&t.join("disparity.png"), &disparity)?;
    io::write_stack(&t.join("layers.npz"), &layer_stack(scene, &out.pinhole)?)?;
    let mut record = spec.clone();
    record.derived = Some(derived_record(scene));
    let json =
        serde_json::to_string_pretty(&record).map_err(|e| Error::file(dir, e.to_string()))?;
    let scene_json = t.join("scene.json");
    io::write_atomic(&scene_json, |w| {
        use std::io::Write;
        w.write_all(json.as_bytes())
            .and_then(|_| w.write_all(b"\n"))
            .map_err(|e| Error::file(&scene_json, format!("write failed: {e}")))
    })?;
    Ok(())
}

/// Makes texture paths absolute (relative to `base_dir`) so the recorded scene can be
/// traced again from anywhere.
pub fn absolutize_paths(spec: &mut SceneSpec, base_dir: &Path) {
    let abs = |p: &Path| {
        let j = base_dir.join(p);
        std::fs::canonicalize(&j).unwrap_or(j)
    };
    for b in &mut spec.billboards {
        if let scene::TextureSpec::Image { path, alpha, .. } = &mut b.texture {
            *path = abs(path);
            if let Some(a) = alpha {
                *a = abs(a);
            }
        }
    }
}
