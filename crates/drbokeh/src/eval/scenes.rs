//! Benchmark scenes (`drbokeh benchmark make`, `drbokeh trace`): loading a scene
//! directory, listing a benchmark, and the camera every method uses on a scene.

use crate::camera::{Camera, WindowCap};
use crate::image::Image;
use crate::io;
use crate::model;
use crate::stack::LayerStack;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Gamma with which `paper` and the baselines decode the benchmark's (sRGB) images.
pub const BENCHMARK_GAMMA: f64 = 2.2;

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
            .map_err(|e| Error::io(&json_path, "cannot read", e))?;
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
    /// highlight boost, and the automatic window ([`model::automatic_window`], not capped
    /// at L = 71): it holds the largest scatter radius any preset gives the layers.
    pub fn camera(&self) -> Camera {
        let mut cam = Camera::paper_default(self.focus);
        cam.blur_k = self.blur_k;
        cam.gamma = BENCHMARK_GAMMA;
        cam.window = model::automatic_window(
            self.blur_k,
            self.layers.max_defocus(self.focus),
            WindowCap::Unclipped,
        );
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
    let entries =
        std::fs::read_dir(benchmark).map_err(|e| Error::io(benchmark, "cannot list", e))?;
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
