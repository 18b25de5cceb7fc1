//! Benchmark evaluation: every method on every scene of a ray-traced benchmark
//! (`drbokeh benchmark make`), scored against the ground truth, written as a report.
//!
//! Methods ([`Method`]) and their inputs (each scene directory provides them):
//! - on the all-in-focus image `aif.png` + `disparity.npy`: the baselines `gather`,
//!   `scatter`, `layered`, `gausspsf` ([`crate::baselines`]) and `paper-aif` (the `paper`
//!   preset on a single opaque layer);
//! - on the ground-truth layer stack `layers.npz`: `layered-gt` (the layered baseline) and
//!   `paper-gt` (the `paper` preset); `physical-aif` and `physical-gt`, the `physical` preset on
//!   the same inputs.
//!
//! All methods use the scene's `blur` (K) and `focus` from `scene.json`, gamma 2.2 (the
//! `paper` preset's and the classical baselines' transfer for a display-encoded photo; the
//! benchmark's images are sRGB-encoded, like photos) and a window wide enough for the largest blur; every
//! render is clipped to [0, 1] and compared with `bokeh.png` (display-encoded, clipped) by
//! PSNR, SSIM and MS-SSIM ([`super::metrics`]). Renders are multi-threaded within a method
//! (rows); scenes and methods run one after another, so every number except the timings is
//! the same on every run and thread count.
//!
//! [`write_report`] writes `results.json`, `results.csv`, `summary.md`, one SVG plot per
//! metric (`psnr_vs_blur.svg`, ...) and `index.html` (see `docs/evaluation.md` for the
//! schema); [`write_scene_images`] writes the pictures the gallery shows.

use super::metrics;
use crate::baselines::{self, Baseline};
use crate::camera::{Camera, Window, AUTO_WINDOW_MARGIN_PX, MAX_WINDOW_SIZE};
use crate::image::Image;
use crate::io;
use crate::presets::{Preset, RenderSettings};
use crate::stack::LayerStack;
use crate::{Engine, Error, NoProgress, Progress, Result};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The version of the `results.json` schema.
pub const SCHEMA_VERSION: u32 = 1;

/// Gamma with which `paper` and the baselines decode the benchmark's (sRGB) images.
pub const BENCHMARK_GAMMA: f64 = 2.2;

/// Error maps are drawn from black (no error) to white at this mean absolute error.
pub const ERROR_MAP_FULL_SCALE: f64 = 0.25;

/// A method evaluated on the benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Naive gather ([`baselines::naive_gather`]) on image + disparity.
    Gather,
    /// Naive scatter ([`baselines::naive_scatter`]) on image + disparity.
    Scatter,
    /// Layered disc blur ([`baselines::layered_disc`]) on image + disparity.
    Layered,
    /// Layered disc blur on the ground-truth layer stack.
    LayeredGt,
    /// GaussPSF ([`baselines::gauss_psf`]) on image + disparity.
    GaussPsf,
    /// The `paper` preset on a single opaque layer (image + disparity).
    PaperAif,
    /// The `paper` preset on the ground-truth layer stack.
    PaperGt,
    /// The `physical` preset on one opaque layer (the all-in-focus image).
    PhysicalAif,
    /// The `physical` preset on the ground-truth layer stack.
    PhysicalGt,
}

/// What a method is fed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum MethodInput {
    /// The all-in-focus image and its disparity map.
    #[serde(rename = "aif+disparity")]
    AifDisparity,
    /// The ground-truth layer stack.
    #[serde(rename = "layers")]
    Layers,
}

impl MethodInput {
    /// The name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            MethodInput::AifDisparity => "aif+disparity",
            MethodInput::Layers => "layers",
        }
    }
}

impl Method {
    /// All methods, in report order.
    pub const ALL: [Method; 9] = [
        Method::Gather,
        Method::Scatter,
        Method::GaussPsf,
        Method::Layered,
        Method::PaperAif,
        Method::PhysicalAif,
        Method::LayeredGt,
        Method::PaperGt,
        Method::PhysicalGt,
    ];

    /// The method's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Gather => "gather",
            Method::Scatter => "scatter",
            Method::Layered => "layered",
            Method::LayeredGt => "layered-gt",
            Method::GaussPsf => "gausspsf",
            Method::PaperAif => "paper-aif",
            Method::PaperGt => "paper-gt",
            Method::PhysicalAif => "physical-aif",
            Method::PhysicalGt => "physical-gt",
        }
    }

    /// What the method is fed.
    pub fn input(self) -> MethodInput {
        match self {
            Method::LayeredGt | Method::PaperGt | Method::PhysicalGt => MethodInput::Layers,
            _ => MethodInput::AifDisparity,
        }
    }

    /// One line on what the method models and ignores.
    pub fn description(self) -> &'static str {
        match self {
            Method::Gather => "naive gather: each pixel averages the disc of its own blur radius (ignores occlusion; colour bleeding)",
            Method::Scatter => "naive scatter: each pixel splats its disc, no depth test (blurred background spreads over sharp foreground)",
            Method::GaussPsf => "GaussPSF (Gur & Wolf 2019): normalised Gaussian scatter, sigma ~ radius/2 (no occlusion, no disc shape)",
            Method::Layered => "layered disc blur: 32 disparity planes blurred by their disc, composited back to front (holes where the image hides background)",
            Method::PaperAif => "Dr.Bokeh paper preset on one opaque layer (image + disparity)",
            Method::LayeredGt => "layered disc blur on the ground-truth layers (hidden background available)",
            Method::PaperGt => "Dr.Bokeh paper preset on the ground-truth layers",
            Method::PhysicalAif => "drbokeh physical preset on one opaque layer (image + disparity)",
            Method::PhysicalGt => "drbokeh physical preset on the ground-truth layers",
        }
    }

    /// Parses a comma-separated list of method names; `all` means [`Method::ALL`].
    pub fn parse_list(list: &str) -> Result<Vec<Method>> {
        let mut out = Vec::new();
        for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            if name == "all" {
                for m in Method::ALL {
                    if !out.contains(&m) {
                        out.push(m);
                    }
                }
                continue;
            }
            let m: Method = name.parse()?;
            if !out.contains(&m) {
                out.push(m);
            }
        }
        if out.is_empty() {
            return Err(Error::param("--methods", "no method given"));
        }
        Ok(out)
    }
}

impl std::str::FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                Error::param(
                    "--methods",
                    format!(
                        "unknown method '{s}' (available: {}, or all)",
                        Method::ALL.map(|m| m.name()).join(", ")
                    ),
                )
            })
    }
}

/// A blur-size bucket: scenes whose largest CoC radius is in `[min_px, max_px)`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Bucket {
    /// Label, e.g. `8-16 px`.
    pub name: String,
    /// Lower bound (inclusive), pixels.
    pub min_px: f64,
    /// Upper bound (exclusive), pixels; `null` in JSON for the open last bucket.
    pub max_px: Option<f64>,
}

/// The blur-size buckets (largest CoC radius of a scene, pixels): <8, 8-16, 16-32, >=32.
pub fn buckets() -> Vec<Bucket> {
    let edges = [0.0, 8.0, 16.0, 32.0];
    edges
        .iter()
        .enumerate()
        .map(|(i, &lo)| {
            let hi = edges.get(i + 1).copied();
            Bucket {
                name: match hi {
                    Some(h) if lo == 0.0 => format!("<{h} px"),
                    Some(h) => format!("{lo}-{h} px"),
                    None => format!(">={lo} px"),
                },
                min_px: lo,
                max_px: hi,
            }
        })
        .collect()
}

/// The bucket of a scene with largest CoC radius `max_coc_px`.
pub fn bucket_of(max_coc_px: f64) -> String {
    buckets()
        .into_iter()
        .rev()
        .find(|b| max_coc_px >= b.min_px)
        .map(|b| b.name)
        .unwrap_or_else(|| buckets()[0].name.clone())
}

/// One benchmark scene, loaded.
#[derive(Clone, Debug)]
pub struct SceneInputs {
    /// The scene's directory name (e.g. `scene_000`).
    pub name: String,
    /// The scene directory.
    pub dir: PathBuf,
    /// All-in-focus image (display-encoded), `aif.png`.
    pub aif: Image<f32>,
    /// Normalised disparity of the most visible billboard, `disparity.npy`.
    pub disparity: Image<f32>,
    /// The layered ground truth, `layers.npz`.
    pub layers: LayerStack<f32>,
    /// The ground-truth defocused image (display-encoded, clipped), `bokeh.png`.
    pub ground_truth: Image<f32>,
    /// Blur strength K (pixels per unit disparity), from `scene.json`.
    pub blur_k: f64,
    /// Focus disparity, from `scene.json`.
    pub focus: f64,
    /// Largest CoC radius `K |disp - focus|` over the visible layer content, pixels.
    pub max_coc_px: f64,
}

/// The files a benchmark scene directory must hold.
pub const SCENE_FILES: [&str; 5] = [
    "scene.json",
    "aif.png",
    "disparity.npy",
    "layers.npz",
    "bokeh.png",
];

fn json_number(v: &serde_json::Value, key: &str) -> Option<f64> {
    v.get(key).and_then(|x| x.as_f64()).or_else(|| {
        v.get("derived")
            .and_then(|d| d.get(key))
            .and_then(|x| x.as_f64())
    })
}

impl SceneInputs {
    /// Loads a scene directory written by `drbokeh benchmark make` or `drbokeh trace`.
    /// Fails with a message naming the missing or malformed file.
    pub fn load(dir: &Path) -> Result<Self> {
        if !dir.is_dir() {
            return Err(Error::file(dir, "not a directory"));
        }
        for f in SCENE_FILES {
            if !dir.join(f).is_file() {
                return Err(Error::file(
                    dir.join(f),
                    "missing (a benchmark scene needs scene.json, aif.png, disparity.npy, layers.npz and bokeh.png)",
                ));
            }
        }
        let json_path = dir.join("scene.json");
        let text = std::fs::read_to_string(&json_path)
            .map_err(|e| Error::file(&json_path, format!("cannot read: {e}")))?;
        let json: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| Error::file(&json_path, format!("invalid JSON: {e}")))?;
        let blur_k = json_number(&json, "blur")
            .ok_or_else(|| Error::file(&json_path, "no numeric 'blur' (K) (nor derived.blur)"))?;
        let focus = json_number(&json, "focus")
            .ok_or_else(|| Error::file(&json_path, "no numeric 'focus' (nor derived.focus)"))?;
        // Rounding can put a far/near focus a hair outside [0, 1].
        let focus = if (-1e-6..=1.0 + 1e-6).contains(&focus) {
            focus.clamp(0.0, 1.0)
        } else {
            focus
        };
        let aif: Image<f32> = io::read_rgb(&dir.join("aif.png"))?;
        let disparity: Image<f32> = io::read_grey(&dir.join("disparity.npy"), "disparity map")?;
        let layers: LayerStack<f32> = io::read_stack(&dir.join("layers.npz"))?;
        let ground_truth: Image<f32> = io::read_rgb(&dir.join("bokeh.png"))?;
        let (w, h) = (aif.width, aif.height);
        for (file, iw, ih) in [
            ("disparity.npy", disparity.width, disparity.height),
            ("layers.npz", layers.width, layers.height),
            ("bokeh.png", ground_truth.width, ground_truth.height),
        ] {
            if (iw, ih) != (w, h) {
                return Err(Error::file(
                    dir.join(file),
                    format!("is {iw}x{ih}, but aif.png is {w}x{h}"),
                ));
            }
        }
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into());
        let mut scene = SceneInputs {
            name,
            dir: dir.to_path_buf(),
            aif,
            disparity,
            layers,
            ground_truth,
            blur_k,
            focus,
            max_coc_px: 0.0,
        };
        scene
            .camera()
            .validate()
            .map_err(|e| e.in_file(&json_path))?;
        scene.max_coc_px = blur_k * scene.layers.max_defocus(focus);
        Ok(scene)
    }

    /// The camera every method uses: the scene's K and focus, gamma 2.2, offset 0, no
    /// highlight boost, and a window holding the largest scatter radius `K max|d| + 1` plus
    /// the auto-window margin (capped at [`MAX_WINDOW_SIZE`]).
    pub fn camera(&self) -> Camera {
        let mut cam = Camera::paper_default(self.focus);
        cam.blur_k = self.blur_k;
        cam.gamma = BENCHMARK_GAMMA;
        let r = self.max_coc_px + 1.0 + AUTO_WINDOW_MARGIN_PX;
        let radius = (r.ceil().max(1.0) as usize).min(MAX_WINDOW_SIZE / 2);
        cam.window = Window::from_size(2 * radius + 1).expect("window size in range");
        cam
    }
}

/// The scene directories of a benchmark: subdirectories holding a `scene.json`, sorted by
/// name. Fails if `benchmark` is not a directory or holds no scene.
pub fn list_scenes(benchmark: &Path) -> Result<Vec<PathBuf>> {
    if !benchmark.is_dir() {
        return Err(Error::file(
            benchmark,
            "benchmark directory does not exist (make one with `drbokeh benchmark make`)",
        ));
    }
    let entries = std::fs::read_dir(benchmark)
        .map_err(|e| Error::file(benchmark, format!("cannot list: {e}")))?;
    let mut dirs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir() && p.join("scene.json").is_file())
        .collect();
    dirs.sort();
    if dirs.is_empty() {
        return Err(Error::file(
            benchmark,
            "no scene directories (subdirectories with a scene.json) found; make a benchmark with `drbokeh benchmark make`",
        ));
    }
    Ok(dirs)
}

/// Renders `scene` with `method`; the display-encoded result, clipped to [0, 1].
pub fn render_method(method: Method, scene: &SceneInputs) -> Result<Image<f32>> {
    let cam = scene.camera();
    let single = || LayerStack::single(scene.aif.clone(), scene.disparity.clone());
    let mut out = match method {
        Method::Gather => baselines::naive_gather(&scene.aif, &scene.disparity, &cam)?,
        Method::Scatter => baselines::naive_scatter(&scene.aif, &scene.disparity, &cam)?,
        Method::GaussPsf => baselines::gauss_psf(&scene.aif, &scene.disparity, &cam)?,
        Method::Layered => Baseline::LayeredDisc.render(&single()?, &cam)?,
        Method::LayeredGt => Baseline::LayeredDisc.render(&scene.layers, &cam)?,
        Method::PaperAif => render_paper(&single()?, &cam)?,
        Method::PaperGt => render_paper(&scene.layers, &cam)?,
        Method::PhysicalAif => render_preset(Preset::Physical, &single()?, &cam)?,
        Method::PhysicalGt => render_preset(Preset::Physical, &scene.layers, &cam)?,
    };
    out.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    Ok(out)
}

/// The `paper` preset with `camera`, fast engine.
pub fn render_paper(stack: &LayerStack<f32>, camera: &Camera) -> Result<Image<f32>> {
    render_preset(Preset::Paper, stack, camera)
}

/// Renders a stack with a preset, the camera given and a circular aperture (fast engine).
pub fn render_preset(
    preset: Preset,
    stack: &LayerStack<f32>,
    camera: &Camera,
) -> Result<Image<f32>> {
    let mut settings = RenderSettings::paper(camera.focus_disparity);
    settings.camera = camera.clone();
    settings.preset = preset;
    crate::render(stack, &settings, Engine::Fast, &NoProgress)
}

/// One method's scores on one scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MethodResult {
    /// Method name.
    pub method: String,
    /// PSNR in dB (`null` in JSON when the images are identical).
    #[serde(serialize_with = "metrics::serialize_psnr")]
    pub psnr: f64,
    /// SSIM (scikit-image's definition).
    pub ssim: f64,
    /// MS-SSIM.
    pub ms_ssim: f64,
    /// Wall-clock render time, seconds (not deterministic).
    pub time_s: f64,
}

/// Every method's scores on one scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneResult {
    /// Scene name (its directory name).
    pub scene: String,
    /// Blur strength K.
    pub blur: f64,
    /// Focus disparity.
    pub focus: f64,
    /// Largest CoC radius in the scene, pixels.
    pub max_coc_px: f64,
    /// Blur-size bucket (see [`buckets`]).
    pub bucket: String,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// One entry per method, in the order evaluated.
    pub results: Vec<MethodResult>,
}

/// Scores a render against the ground truth; `time_s` is filled in by the caller.
pub fn score(method: Method, render: &Image<f32>, truth: &Image<f32>) -> Result<MethodResult> {
    Ok(MethodResult {
        method: method.name().to_string(),
        psnr: metrics::psnr(render, truth)?,
        ssim: metrics::ssim(render, truth)?,
        ms_ssim: metrics::ms_ssim(render, truth)?,
        time_s: 0.0,
    })
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

/// Writes an 8-bit RGB PNG from 3-channel values in [0, 1].
fn write_png_rgb8(path: &Path, w: usize, h: usize, rgb: Vec<u8>) -> Result<()> {
    let buf = image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .ok_or_else(|| Error::file(path, "bad image size"))?;
    io::write_atomic(path, |out| {
        image::DynamicImage::ImageRgb8(buf)
            .write_to(out, image::ImageFormat::Png)
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

/// A black-red-yellow-white colour ramp for `t` in [0, 1].
pub fn heat_colour(t: f64) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let stops = [
        [0.0, 0.0, 0.0],
        [0.55, 0.0, 0.35],
        [0.95, 0.3, 0.0],
        [1.0, 0.85, 0.1],
        [1.0, 1.0, 1.0],
    ];
    let s = t * (stops.len() - 1) as f64;
    let i = (s.floor() as usize).min(stops.len() - 2);
    let f = s - i as f64;
    [0, 1, 2].map(|c| ((stops[i][c] * (1.0 - f) + stops[i + 1][c] * f) * 255.0).round() as u8)
}

/// Writes an error map (mean absolute error over channels) as a colour PNG, black at 0 and
/// white at [`ERROR_MAP_FULL_SCALE`].
pub fn write_error_map(path: &Path, render: &Image<f32>, truth: &Image<f32>) -> Result<()> {
    let err = metrics::error_map(render, truth)?;
    let rgb = err
        .data
        .iter()
        .flat_map(|&e| heat_colour(e as f64 / ERROR_MAP_FULL_SCALE))
        .collect();
    write_png_rgb8(path, err.width, err.height, rgb)
}

/// Writes a disparity map as an 8-bit grey PNG (near = bright).
pub fn write_disparity_preview(path: &Path, disparity: &Image<f32>) -> Result<()> {
    let rgb = disparity
        .data
        .iter()
        .flat_map(|&d| [(d.clamp(0.0, 1.0) * 255.0).round() as u8; 3])
        .collect();
    write_png_rgb8(path, disparity.width, disparity.height, rgb)
}

/// Writes a display-encoded image as a JPEG (quality 92) for the gallery.
pub fn write_preview(path: &Path, img: &Image<f32>) -> Result<()> {
    io::write_output(path, img, io::BitDepth::Eight, |v| v)
}

/// The gallery's file names for a scene: `aif.jpg`, `disparity.png`, `gt.jpg`, and per
/// method `<method>.jpg` and `<method>.err.png`.
pub fn method_image_names(method: Method) -> (String, String) {
    (
        format!("{}.jpg", method.name()),
        format!("{}.err.png", method.name()),
    )
}

/// Writes a scene's pictures into `dir` (created if missing): inputs, ground truth, and
/// each method's render and error map.
pub fn write_scene_images(
    dir: &Path,
    scene: &SceneInputs,
    renders: &[(Method, Image<f32>)],
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, format!("cannot create: {e}")))?;
    write_preview(&dir.join("aif.jpg"), &scene.aif)?;
    write_disparity_preview(&dir.join("disparity.png"), &scene.disparity)?;
    write_preview(&dir.join("gt.jpg"), &scene.ground_truth)?;
    for (m, img) in renders {
        let (render_name, err_name) = method_image_names(*m);
        write_preview(&dir.join(render_name), img)?;
        write_error_map(&dir.join(err_name), img, &scene.ground_truth)?;
    }
    Ok(())
}

/// Mean and sample standard deviation (0 for fewer than two values) of the finite values;
/// `None` if there are none.
pub fn mean_std(values: &[f64]) -> Option<(f64, f64)> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    Some((mean, var.sqrt()))
}

/// Aggregate scores of one method over a set of scenes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SummaryRow {
    /// Method name.
    pub method: String,
    /// Number of scenes.
    pub n: usize,
    /// Scenes whose PSNR is infinite (identical images), left out of the PSNR statistics.
    pub psnr_infinite: usize,
    /// Mean PSNR (dB) over scenes with a finite PSNR.
    pub psnr_mean: Option<f64>,
    /// Sample standard deviation of the PSNR.
    pub psnr_std: Option<f64>,
    /// Mean SSIM.
    pub ssim_mean: Option<f64>,
    /// Sample standard deviation of the SSIM.
    pub ssim_std: Option<f64>,
    /// Mean MS-SSIM.
    pub ms_ssim_mean: Option<f64>,
    /// Sample standard deviation of the MS-SSIM.
    pub ms_ssim_std: Option<f64>,
    /// Mean render time, seconds.
    pub time_mean_s: Option<f64>,
}

/// The summary of one blur-size bucket.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BucketSummary {
    /// Bucket name.
    pub bucket: String,
    /// Number of scenes in the bucket.
    pub scenes: usize,
    /// One row per method.
    pub methods: Vec<SummaryRow>,
}

/// Aggregates: overall and per blur bucket.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Summary {
    /// One row per method, over all scenes.
    pub overall: Vec<SummaryRow>,
    /// Per blur bucket (only buckets with scenes).
    pub by_bucket: Vec<BucketSummary>,
}

/// A method's description in the report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MethodInfo {
    /// Name.
    pub name: String,
    /// Input it is fed.
    pub input: MethodInput,
    /// What it models and ignores.
    pub description: String,
}

/// A full evaluation report (the content of `results.json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The drbokeh version that wrote it.
    pub drbokeh_version: String,
    /// The benchmark directory evaluated.
    pub benchmark: String,
    /// Number of scenes.
    pub scene_count: usize,
    /// Metric definitions.
    pub metrics: serde_json::Value,
    /// The methods, in evaluation order.
    pub methods: Vec<MethodInfo>,
    /// The blur-size buckets.
    pub buckets: Vec<Bucket>,
    /// Per-scene results.
    pub scenes: Vec<SceneResult>,
    /// Aggregates.
    pub summary: Summary,
}

fn summary_row(method: &str, rows: &[&MethodResult]) -> SummaryRow {
    let col = |f: &dyn Fn(&MethodResult) -> f64| rows.iter().map(|r| f(r)).collect::<Vec<_>>();
    let psnr = mean_std(&col(&|r| r.psnr));
    let ssim = mean_std(&col(&|r| r.ssim));
    let ms = mean_std(&col(&|r| r.ms_ssim));
    let time = mean_std(&col(&|r| r.time_s));
    SummaryRow {
        method: method.to_string(),
        n: rows.len(),
        psnr_infinite: rows.iter().filter(|r| r.psnr == f64::INFINITY).count(),
        psnr_mean: psnr.map(|p| p.0),
        psnr_std: psnr.map(|p| p.1),
        ssim_mean: ssim.map(|p| p.0),
        ssim_std: ssim.map(|p| p.1),
        ms_ssim_mean: ms.map(|p| p.0),
        ms_ssim_std: ms.map(|p| p.1),
        time_mean_s: time.map(|p| p.0),
    }
}

fn summarise_scenes(methods: &[String], scenes: &[&SceneResult]) -> Vec<SummaryRow> {
    methods
        .iter()
        .map(|m| {
            let rows: Vec<&MethodResult> = scenes
                .iter()
                .flat_map(|s| s.results.iter().filter(|r| &r.method == m))
                .collect();
            summary_row(m, &rows)
        })
        .collect()
}

impl Report {
    /// Builds a report (with its summary) from per-scene results.
    pub fn new(benchmark: &Path, methods: &[Method], scenes: Vec<SceneResult>) -> Self {
        let names: Vec<String> = methods.iter().map(|m| m.name().to_string()).collect();
        let all: Vec<&SceneResult> = scenes.iter().collect();
        let overall = summarise_scenes(&names, &all);
        let by_bucket = buckets()
            .into_iter()
            .filter_map(|b| {
                let sel: Vec<&SceneResult> = scenes.iter().filter(|s| s.bucket == b.name).collect();
                (!sel.is_empty()).then(|| BucketSummary {
                    bucket: b.name.clone(),
                    scenes: sel.len(),
                    methods: summarise_scenes(&names, &sel),
                })
            })
            .collect();
        Report {
            schema_version: SCHEMA_VERSION,
            drbokeh_version: env!("CARGO_PKG_VERSION").to_string(),
            benchmark: benchmark.display().to_string(),
            scene_count: scenes.len(),
            metrics: serde_json::json!({
                "psnr": "dB, data range 1, on display-encoded images clipped to [0, 1]; null when render and ground truth are identical (infinite PSNR)",
                "ssim": "scikit-image structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1, channel_axis=-1)",
                "ms_ssim": "multi-scale SSIM (Wang et al. 2003), 5 scales, same window as ssim",
                "time_s": "wall-clock render time in seconds (multi-threaded within the method; not deterministic)",
                "max_coc_px": "largest circle-of-confusion radius K|disp - focus| over the visible layer content, pixels",
                "std": "sample standard deviation (n - 1); 0 for one scene",
            }),
            methods: methods
                .iter()
                .map(|m| MethodInfo {
                    name: m.name().to_string(),
                    input: m.input(),
                    description: m.description().to_string(),
                })
                .collect(),
            buckets: buckets(),
            scenes,
            summary: Summary { overall, by_bucket },
        }
    }
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

fn write_text(path: &Path, text: &str) -> Result<()> {
    io::write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

/// The CSV of a report: one row per scene and method. Header:
/// `scene,method,input,blur,focus,max_coc_px,bucket,psnr,ssim,ms_ssim,time_s`; an
/// infinite PSNR is written `inf`.
pub fn results_csv(report: &Report) -> String {
    let mut s =
        String::from("scene,method,input,blur,focus,max_coc_px,bucket,psnr,ssim,ms_ssim,time_s\n");
    for sc in &report.scenes {
        for r in &sc.results {
            let input = report
                .methods
                .iter()
                .find(|m| m.name == r.method)
                .map(|m| m.input.name())
                .unwrap_or("");
            let psnr = if r.psnr.is_finite() {
                format!("{:.6}", r.psnr)
            } else if r.psnr > 0.0 {
                "inf".to_string()
            } else {
                "nan".to_string()
            };
            let _ = writeln!(
                s,
                "{},{},{},{:.6},{:.6},{:.4},{},{},{:.6},{:.6},{:.4}",
                csv_field(&sc.scene),
                csv_field(&r.method),
                input,
                sc.blur,
                sc.focus,
                sc.max_coc_px,
                csv_field(&sc.bucket),
                psnr,
                r.ssim,
                r.ms_ssim,
                r.time_s
            );
        }
    }
    s
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn fmt_ms(m: Option<f64>, s: Option<f64>, digits: usize) -> String {
    match (m, s) {
        (Some(m), Some(s)) => format!("{m:.digits$} ± {s:.digits$}"),
        _ => "–".to_string(),
    }
}

/// The Markdown summary: overall mean ± standard deviation per method (ranked by mean
/// PSNR) and per blur-size bucket.
pub fn summary_markdown(report: &Report) -> String {
    let mut s = String::new();
    let (w, h) = report
        .scenes
        .first()
        .map(|sc| (sc.width, sc.height))
        .unwrap_or((0, 0));
    let _ = writeln!(s, "# drbokeh evaluation\n");
    let _ = writeln!(
        s,
        "Benchmark `{}`: {} scenes of {w}x{h} px. Every method renders from the same inputs with the scene's K and focus; scores against the ray-traced `bokeh.png` (display-encoded, clipped). Mean ± sample standard deviation over scenes; higher is better except time (wall clock per render, this machine).\n",
        report.benchmark, report.scene_count
    );
    let mut ranked: Vec<&SummaryRow> = report.summary.overall.iter().collect();
    ranked.sort_by(|a, b| {
        b.psnr_mean
            .unwrap_or(f64::NEG_INFINITY)
            .total_cmp(&a.psnr_mean.unwrap_or(f64::NEG_INFINITY))
    });
    let _ = writeln!(s, "## All scenes\n");
    let _ = writeln!(
        s,
        "| rank | method | input | PSNR (dB) | SSIM | MS-SSIM | time (s) |\n|---:|---|---|---:|---:|---:|---:|"
    );
    for (i, r) in ranked.iter().enumerate() {
        let input = report
            .methods
            .iter()
            .find(|m| m.name == r.method)
            .map(|m| m.input.name())
            .unwrap_or("");
        let inf = if r.psnr_infinite > 0 {
            format!(" ({} identical)", r.psnr_infinite)
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}{} | {} | {} | {} |",
            i + 1,
            r.method,
            input,
            fmt_ms(r.psnr_mean, r.psnr_std, 2),
            inf,
            fmt_ms(r.ssim_mean, r.ssim_std, 4),
            fmt_ms(r.ms_ssim_mean, r.ms_ssim_std, 4),
            r.time_mean_s
                .map(|t| format!("{t:.2}"))
                .unwrap_or_else(|| "–".into())
        );
    }
    let _ = writeln!(s, "\n## By blur size (largest CoC radius in the scene)\n");
    type Metric = fn(&SummaryRow) -> (Option<f64>, Option<f64>);
    let metric_list: [(&str, Metric, usize); 3] = [
        ("PSNR (dB)", |r| (r.psnr_mean, r.psnr_std), 2),
        ("SSIM", |r| (r.ssim_mean, r.ssim_std), 4),
        ("MS-SSIM", |r| (r.ms_ssim_mean, r.ms_ssim_std), 4),
    ];
    for (title, get, digits) in metric_list {
        let _ = writeln!(s, "### {title}\n");
        let mut head = String::from("| method |");
        let mut rule = String::from("|---|");
        for b in &report.summary.by_bucket {
            let _ = write!(head, " {} (n={}) |", b.bucket, b.scenes);
            rule.push_str("---:|");
        }
        let _ = writeln!(s, "{head}\n{rule}");
        for m in &report.methods {
            let _ = write!(s, "| {} |", m.name);
            for b in &report.summary.by_bucket {
                let cell = b
                    .methods
                    .iter()
                    .find(|r| r.method == m.name)
                    .map(|r| {
                        let (mean, std) = get(r);
                        fmt_ms(mean, std, digits)
                    })
                    .unwrap_or_else(|| "–".into());
                let _ = write!(s, " {cell} |");
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s, "## Methods\n");
    for m in &report.methods {
        let _ = writeln!(s, "- `{}` ({}): {}", m.name, m.input.name(), m.description);
    }
    s
}

/// Colours of the plot series.
const PALETTE: [&str; 8] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#d62728", "#8c564b", "#e377c2", "#17becf",
];

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

/// "Nice" tick values covering `[lo, hi]`.
fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= target as f64)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-9 * step {
        out.push(t);
        t += step;
    }
    out
}

/// An SVG plot of one metric against the scene's largest CoC radius: each scene a point,
/// each method a line through its per-bucket means.
pub fn metric_plot_svg(report: &Report, title: &str, get: MetricAccessor) -> String {
    let (w, h) = (760.0, 440.0);
    let (left, right, top, bottom) = (64.0, 190.0, 36.0, 48.0);
    let mut pts: Vec<(usize, f64, f64)> = Vec::new();
    for sc in &report.scenes {
        for r in &sc.results {
            if let Some(mi) = report.methods.iter().position(|m| m.name == r.method) {
                let v = get(r);
                if v.is_finite() {
                    pts.push((mi, sc.max_coc_px, v));
                }
            }
        }
    }
    let (mut x0, mut x1, mut y0, mut y1) = (0.0f64, 1.0f64, f64::INFINITY, f64::NEG_INFINITY);
    for &(_, x, y) in &pts {
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !y0.is_finite() {
        (y0, y1) = (0.0, 1.0);
    }
    let pad = ((y1 - y0) * 0.08).max(1e-3);
    y0 -= pad;
    y1 += pad;
    x1 *= 1.05;
    x0 = x0.min(0.0);
    let px = |x: f64| left + (x - x0) / (x1 - x0) * (w - left - right);
    let py = |y: f64| top + (1.0 - (y - y0) / (y1 - y0)) * (h - top - bottom);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="20" text-anchor="middle" font-size="15">{} vs blur size</text>"#,
        (left + w - right) / 2.0,
        xml_escape(title)
    );
    for t in ticks(x0, x1, 8) {
        let x = px(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{top}" x2="{x:.1}" y2="{:.1}" stroke="#e5e5e5"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{t}</text>"##,
            h - bottom,
            h - bottom + 16.0
        );
    }
    for t in ticks(y0, y1, 6) {
        let y = py(t);
        let label = if (y1 - y0) < 0.5 {
            format!("{t:.3}")
        } else {
            format!("{t}")
        };
        let _ = writeln!(
            s,
            r##"<line x1="{left}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#e5e5e5"/><text x="{:.1}" y="{:.1}" text-anchor="end">{label}</text>"##,
            w - right,
            left - 6.0,
            y + 4.0
        );
    }
    let _ = writeln!(
        s,
        r##"<rect x="{left}" y="{top}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
        w - left - right,
        h - top - bottom
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">largest CoC radius in the scene (px)</text>"#,
        (left + w - right) / 2.0,
        h - 10.0
    );
    let _ = writeln!(
        s,
        r#"<text transform="translate(16 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
        (top + h - bottom) / 2.0,
        xml_escape(title)
    );
    let bks = buckets();
    for (mi, m) in report.methods.iter().enumerate() {
        let colour = PALETTE[mi % PALETTE.len()];
        for &(_, x, y) in pts.iter().filter(|p| p.0 == mi) {
            let _ = writeln!(
                s,
                r#"<circle cx="{:.1}" cy="{:.1}" r="3" fill="{colour}" fill-opacity="0.45"/>"#,
                px(x),
                py(y)
            );
        }
        // Line through the per-bucket means (x: mean blur of the bucket's scenes).
        let mut line = Vec::new();
        for b in &bks {
            let sel: Vec<(f64, f64)> = pts
                .iter()
                .filter(|p| {
                    p.0 == mi && p.1 >= b.min_px && b.max_px.map(|hi| p.1 < hi).unwrap_or(true)
                })
                .map(|p| (p.1, p.2))
                .collect();
            if !sel.is_empty() {
                let n = sel.len() as f64;
                line.push((
                    sel.iter().map(|p| p.0).sum::<f64>() / n,
                    sel.iter().map(|p| p.1).sum::<f64>() / n,
                ));
            }
        }
        if line.len() > 1 {
            let d: Vec<String> = line
                .iter()
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2"/>"#,
                d.join(" ")
            );
        }
        for &(x, y) in &line {
            let _ = writeln!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="7" height="7" fill="{colour}"/>"#,
                px(x) - 3.5,
                py(y) - 3.5
            );
        }
        let ly = top + 10.0 + 20.0 * mi as f64;
        let lx = w - right + 14.0;
        let _ = writeln!(
            s,
            r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="3"/><text x="{}" y="{}">{}</text>"#,
            lx + 22.0,
            lx + 28.0,
            ly + 4.0,
            xml_escape(&m.name)
        );
    }
    for (i, line) in ["dots: scenes", "squares, lines: means", "per blur bucket"]
        .iter()
        .enumerate()
    {
        let _ = writeln!(
            s,
            r##"<text x="{:.1}" y="{:.1}" font-size="10" fill="#555">{line}</text>"##,
            w - right + 14.0,
            h - bottom - 28.0 + 13.0 * i as f64
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Reads one metric from a result.
pub type MetricAccessor = fn(&MethodResult) -> f64;

/// The SVG plots written by [`write_report`]: (file name, metric title, accessor).
pub fn plot_files() -> [(&'static str, &'static str, MetricAccessor); 3] {
    [
        ("psnr_vs_blur.svg", "PSNR (dB)", |r| r.psnr),
        ("ssim_vs_blur.svg", "SSIM", |r| r.ssim),
        ("ms_ssim_vs_blur.svg", "MS-SSIM", |r| r.ms_ssim),
    ]
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map(|v| format!("{v:.digits$}"))
        .unwrap_or_else(|| "–".into())
}

/// The self-contained HTML gallery of a report (`index.html`): summary table (click a
/// column to sort), the plots, and per scene the inputs, ground truth, each method's render
/// and error map; scenes can be sorted by name, blur or any method's metric. Images are
/// referenced relatively (`scenes/<scene>/...`), so the folder can be moved or zipped.
pub fn report_html(report: &Report) -> String {
    let mut s = String::new();
    s.push_str(HTML_HEAD);
    let _ = writeln!(s, "<h1>drbokeh evaluation</h1>");
    let _ = writeln!(
        s,
        "<p>Benchmark <code>{}</code>, {} scenes. Every method gets the same inputs and the scene's K and focus; scores against the ray-traced ground truth (display-encoded, clipped). Error maps: mean absolute error over channels, black = 0, white &ge; {ERROR_MAP_FULL_SCALE}.</p>",
        xml_escape(&report.benchmark),
        report.scene_count
    );
    s.push_str("<h2>Summary (mean ± sample std over scenes; click a column to sort)</h2>\n<table class=\"sortable\" id=\"summary\"><thead><tr><th>method</th><th>input</th><th>PSNR (dB)</th><th>SSIM</th><th>MS-SSIM</th><th>time (s)</th></tr></thead><tbody>\n");
    for r in &report.summary.overall {
        let m = report.methods.iter().find(|m| m.name == r.method);
        let _ = writeln!(
            s,
            "<tr><td data-v=\"{0}\" title=\"{1}\">{0}</td><td data-v=\"{2}\">{2}</td><td data-v=\"{3}\">{4}</td><td data-v=\"{5}\">{6}</td><td data-v=\"{7}\">{8}</td><td data-v=\"{9}\">{10}</td></tr>",
            xml_escape(&r.method),
            xml_escape(m.map(|m| m.description.as_str()).unwrap_or("")),
            m.map(|m| m.input.name()).unwrap_or(""),
            fmt_opt(r.psnr_mean, 4),
            fmt_ms(r.psnr_mean, r.psnr_std, 2),
            fmt_opt(r.ssim_mean, 6),
            fmt_ms(r.ssim_mean, r.ssim_std, 4),
            fmt_opt(r.ms_ssim_mean, 6),
            fmt_ms(r.ms_ssim_mean, r.ms_ssim_std, 4),
            fmt_opt(r.time_mean_s, 4),
            fmt_opt(r.time_mean_s, 2),
        );
    }
    s.push_str("</tbody></table>\n<h2>Quality vs blur size</h2>\n<div class=\"plots\">");
    for (file, title, _) in plot_files() {
        let _ = write!(s, "<img src=\"{file}\" alt=\"{title} vs blur size\">");
    }
    s.push_str("</div>\n<h2>Scenes</h2>\n<div class=\"controls\">Sort scenes by <select id=\"sortkey\"><option value=\"name\">scene name</option><option value=\"blur\">largest blur</option>");
    for m in &report.methods {
        for (key, label) in [("psnr", "PSNR"), ("ssim", "SSIM"), ("msssim", "MS-SSIM")] {
            let _ = write!(
                s,
                "<option value=\"{key}-{0}\">{label} of {0}</option>",
                xml_escape(&m.name)
            );
        }
    }
    s.push_str("</select> <select id=\"sortdir\"><option value=\"1\">ascending</option><option value=\"-1\">descending</option></select></div>\n<div id=\"scenes\">\n");
    for sc in &report.scenes {
        let dir = format!("scenes/{}", sc.scene);
        let mut attrs = format!(
            "data-name=\"{}\" data-blur=\"{}\"",
            xml_escape(&sc.scene),
            sc.max_coc_px
        );
        for r in &sc.results {
            let psnr = if r.psnr.is_finite() {
                r.psnr.to_string()
            } else {
                "Infinity".into()
            };
            let _ = write!(
                attrs,
                " data-psnr-{m}=\"{psnr}\" data-ssim-{m}=\"{}\" data-msssim-{m}=\"{}\"",
                r.ssim,
                r.ms_ssim,
                m = xml_escape(&r.method)
            );
        }
        let _ = writeln!(s, "<section class=\"scene\" {attrs}>");
        let _ = writeln!(
            s,
            "<h3>{} <small>K = {:.2}, focus = {:.3}, largest CoC {:.1} px ({})</small></h3>",
            xml_escape(&sc.scene),
            sc.blur,
            sc.focus,
            sc.max_coc_px,
            xml_escape(&sc.bucket)
        );
        s.push_str("<div class=\"grid\">");
        for (file, label) in [
            ("aif.jpg", "all-in-focus"),
            ("disparity.png", "disparity"),
            ("gt.jpg", "ground truth"),
        ] {
            let _ = write!(
                s,
                "<figure><img src=\"{dir}/{file}\" alt=\"{label}\"><figcaption>{label}</figcaption></figure>"
            );
        }
        s.push_str("</div>\n<div class=\"grid\">");
        for r in &sc.results {
            let Ok(m) = r.method.parse::<Method>() else {
                continue;
            };
            let (img, err) = method_image_names(m);
            let psnr = if r.psnr.is_finite() {
                format!("{:.2} dB", r.psnr)
            } else {
                "∞".into()
            };
            let _ = write!(
                s,
                "<figure class=\"pair\"><div><img src=\"{dir}/{img}\" alt=\"{n}\"><img src=\"{dir}/{err}\" alt=\"{n} error\"></div><figcaption><b>{n}</b> PSNR {psnr}, SSIM {:.4}, MS-SSIM {:.4}</figcaption></figure>",
                r.ssim,
                r.ms_ssim,
                n = xml_escape(&r.method)
            );
        }
        s.push_str("</div>\n</section>\n");
    }
    s.push_str("</div>\n");
    s.push_str(HTML_SCRIPT);
    s.push_str("</body>\n</html>\n");
    s
}

const HTML_HEAD: &str = r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>drbokeh evaluation</title>
<style>
body { font-family: sans-serif; margin: 16px; background: #fafafa; color: #222; }
table { border-collapse: collapse; margin: 8px 0; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
th { background: #eee; cursor: pointer; }
td:first-child, th:first-child { text-align: left; }
.plots img { max-width: 32%; min-width: 320px; border: 1px solid #ddd; margin: 2px; }
.scene { border-top: 2px solid #bbb; padding: 6px 0; }
.grid { display: flex; flex-wrap: wrap; gap: 8px; margin: 4px 0; }
figure { margin: 0; }
figure img { width: 200px; height: auto; display: block; }
figure.pair div { display: flex; gap: 2px; }
figcaption { font-size: 11px; max-width: 402px; }
small { color: #666; font-weight: normal; }
.controls { margin: 8px 0; }
</style>
</head>
<body>
"#;

const HTML_SCRIPT: &str = r#"<script>
(function () {
  function sortScenes() {
    var key = document.getElementById('sortkey').value;
    var dir = parseFloat(document.getElementById('sortdir').value);
    var box = document.getElementById('scenes');
    var items = Array.prototype.slice.call(box.querySelectorAll('section.scene'));
    items.sort(function (a, b) {
      if (key === 'name') {
        return dir * a.getAttribute('data-name').localeCompare(b.getAttribute('data-name'));
      }
      var va = parseFloat(a.getAttribute('data-' + key));
      var vb = parseFloat(b.getAttribute('data-' + key));
      if (isNaN(va)) va = -Infinity;
      if (isNaN(vb)) vb = -Infinity;
      return dir * (va === vb ? 0 : (va < vb ? -1 : 1));
    });
    items.forEach(function (el) { box.appendChild(el); });
  }
  document.getElementById('sortkey').addEventListener('change', sortScenes);
  document.getElementById('sortdir').addEventListener('change', sortScenes);
  Array.prototype.forEach.call(document.querySelectorAll('table.sortable'), function (table) {
    Array.prototype.forEach.call(table.querySelectorAll('th'), function (th, col) {
      var dir = -1;
      th.addEventListener('click', function () {
        dir = -dir;
        var body = table.tBodies[0];
        var rows = Array.prototype.slice.call(body.rows);
        rows.sort(function (a, b) {
          var x = a.cells[col].getAttribute('data-v'), y = b.cells[col].getAttribute('data-v');
          var fx = parseFloat(x), fy = parseFloat(y);
          if (!isNaN(fx) && !isNaN(fy)) return dir * (fx - fy);
          return dir * String(x).localeCompare(String(y));
        });
        rows.forEach(function (r) { body.appendChild(r); });
      });
    });
  });
})();
</script>
"#;

/// Writes a report into directory `out` (created if missing): `results.json`,
/// `results.csv`, `summary.md`, the SVG plots and `index.html`. Scene pictures are written
/// separately, by [`evaluate_benchmark`] / [`write_scene_images`].
pub fn write_report(out: &Path, report: &Report) -> Result<()> {
    std::fs::create_dir_all(out).map_err(|e| Error::file(out, format!("cannot create: {e}")))?;
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| Error::file(out.join("results.json"), e.to_string()))?;
    write_text(&out.join("results.json"), &(json + "\n"))?;
    write_text(&out.join("results.csv"), &results_csv(report))?;
    write_text(&out.join("summary.md"), &summary_markdown(report))?;
    for (file, title, get) in plot_files() {
        write_text(&out.join(file), &metric_plot_svg(report, title, get))?;
    }
    write_text(&out.join("index.html"), &report_html(report))?;
    Ok(())
}
