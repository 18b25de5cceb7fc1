//! A refocus gallery for arbitrary image + disparity pairs (`drbokeh gallery`): every
//! method that works from an image and a disparity map renders a sweep of focal planes,
//! shown side by side in a self-contained HTML page.
//!
//! **Inputs.** A folder of pairs named `NAME.EXT` + `NAME.disp.DEXT`, where `EXT` is
//! `png`, `jpg`, `jpeg`, `tif`, `tiff` or `exr` (the image; EXR is read as linear light
//! and encoded with the gamma) and `DEXT` is `png`, `tif`, `tiff`, `exr`, `npy` or `npz`
//! (key `data`): a disparity map, larger = nearer, min-max normalised to [0, 1] as
//! `drbokeh render --disparity` does. Images without a disparity file are skipped (and
//! reported).
//!
//! **Output.** `OUT/index.html`, and per input `OUT/NAME/input.jpg`,
//! `OUT/NAME/disparity.png`, and `OUT/NAME/fNN_<method>.jpg` for focal plane `NN`. Focal
//! planes are spread evenly over the normalised disparity range `[0, 1]`:
//! `f_i = i / (N - 1)` (far to near).

use super::images::{write_disparity_preview, write_preview};
use super::methods::{render_photo, require_photo_input, Method, MethodInput};
use crate::camera::{Camera, WindowCap};
use crate::image::Image;
use crate::io::{self, DisparityOptions};
use crate::model::{self, Tone, Transfer};
use crate::scene::read_display_image;
use crate::{Error, Progress, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Image extensions recognised as gallery inputs.
pub const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "tif", "tiff", "exr"];
/// Disparity extensions recognised (as `NAME.disp.EXT`).
pub const DISPARITY_EXTENSIONS: [&str; 6] = ["png", "tif", "tiff", "exr", "npy", "npz"];

/// One image + disparity pair.
#[derive(Clone, Debug, PartialEq)]
pub struct GalleryInput {
    /// The pair's name (the image's file name without extension).
    pub name: String,
    /// The image file.
    pub image: PathBuf,
    /// The disparity file.
    pub disparity: PathBuf,
}

/// Finds the `NAME.EXT` + `NAME.disp.DEXT` pairs in `dir`, sorted by name. Returns the
/// pairs and the images that have no disparity file. Fails if `dir` is not a directory or
/// holds no pair.
pub fn find_inputs(dir: &Path) -> Result<(Vec<GalleryInput>, Vec<PathBuf>)> {
    if !dir.is_dir() {
        return Err(Error::file(dir, "image directory does not exist"));
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, "cannot list", e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    let ext = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase()
    };
    let (mut pairs, mut unpaired) = (Vec::new(), Vec::new());
    for f in &files {
        let Some(stem) = f.file_stem().and_then(|s| s.to_str()) else {
            continue;
        };
        if stem.ends_with(".disp") || stem.starts_with('.') {
            continue;
        }
        if !IMAGE_EXTENSIONS.contains(&ext(f).as_str()) {
            continue;
        }
        let disp = DISPARITY_EXTENSIONS
            .iter()
            .map(|e| dir.join(format!("{stem}.disp.{e}")))
            .find(|p| p.is_file());
        match disp {
            Some(d) => pairs.push(GalleryInput {
                name: stem.to_string(),
                image: f.clone(),
                disparity: d,
            }),
            None => unpaired.push(f.clone()),
        }
    }
    if pairs.is_empty() {
        return Err(Error::file(
            dir,
            "no image + disparity pairs found (name them NAME.png + NAME.disp.png; see docs/evaluation.md)",
        ));
    }
    Ok((pairs, unpaired))
}

/// Gallery settings.
#[derive(Clone, Debug, PartialEq)]
pub struct GalleryOptions {
    /// Number of focal planes (>= 1).
    pub focal_planes: usize,
    /// Blur strength K (pixels of CoC radius per unit of disparity).
    pub blur_k: f64,
    /// Display gamma.
    pub gamma: f64,
    /// Methods (image + disparity methods only).
    pub methods: Vec<Method>,
}

/// The methods the gallery can run (those fed an image + disparity).
pub fn gallery_methods() -> Vec<Method> {
    Method::ALL
        .into_iter()
        .filter(|m| m.input() == MethodInput::AifDisparity)
        .collect()
}

/// The focal planes of a sweep of `n`: `i / (n - 1)`, or 0.5 for one plane.
pub fn focal_planes(n: usize) -> Vec<f64> {
    if n <= 1 {
        return vec![0.5];
    }
    (0..n).map(|i| i as f64 / (n - 1) as f64).collect()
}

/// The file name of a sweep render.
pub fn sweep_file(plane: usize, method: Method) -> String {
    format!("f{plane:02}_{}.jpg", method.name())
}

fn load_input(input: &GalleryInput, gamma: f64) -> Result<(Image<f32>, Image<f32>)> {
    let img: Image<f32> =
        read_display_image(&input.image, &Tone::new(Transfer::Gamma, gamma, 0.0))?;
    let disp: Image<f32> = io::read_disparity(&input.disparity, DisparityOptions::default())?;
    if (disp.width, disp.height) != (img.width, img.height) {
        return Err(Error::file(
            &input.disparity,
            format!(
                "is {}x{}, but {} is {}x{}",
                disp.width,
                disp.height,
                input.image.display(),
                img.width,
                img.height
            ),
        ));
    }
    Ok((img, disp))
}

/// Renders the gallery for `inputs` into `out` (created if missing) and writes
/// `out/index.html`. `progress` counts renders (inputs x planes x methods).
pub fn make_gallery(
    inputs: &[GalleryInput],
    out: &Path,
    options: &GalleryOptions,
    progress: &dyn Progress,
) -> Result<()> {
    if options.focal_planes == 0 || options.focal_planes > 100 {
        return Err(Error::param(
            "focal_planes",
            format!("must be between 1 and 100, got {}", options.focal_planes),
        ));
    }
    if options.methods.is_empty() {
        return Err(Error::param("methods", "no method given"));
    }
    for &m in &options.methods {
        require_photo_input(m)?;
    }
    let mut cam = Camera::paper_default(0.5);
    cam.blur_k = options.blur_k;
    cam.gamma = options.gamma;
    cam.validate()?;
    let planes = focal_planes(options.focal_planes);
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, "cannot create", e))?;
    progress.start((inputs.len() * planes.len() * options.methods.len()) as u64);
    let mut sizes = Vec::new();
    for input in inputs {
        let (img, disp) = load_input(input, options.gamma)?;
        sizes.push((img.width, img.height));
        let dir = out.join(&input.name);
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, "cannot create", e))?;
        write_preview(&dir.join("input.jpg"), &img)?;
        write_disparity_preview(&dir.join("disparity.png"), &disp)?;
        for (pi, &f) in planes.iter().enumerate() {
            let mut c = cam.clone();
            c.focus_disparity = f;
            let max_d = disp
                .data
                .iter()
                .map(|d| (*d as f64 - f).abs())
                .fold(0.0, f64::max);
            c.window = model::automatic_window(c.blur_k, max_d, WindowCap::Unclipped);
            for &m in &options.methods {
                let render = render_photo(m, &img, &disp, &c)?;
                write_preview(&dir.join(sweep_file(pi, m)), &render)?;
                progress.advance(1);
            }
        }
    }
    let html = gallery_html(inputs, &sizes, options, &planes);
    let path = out.join("index.html");
    io::write_atomic(&path, |w| {
        use std::io::Write;
        w.write_all(html.as_bytes())
            .map_err(|e| Error::file(&path, format!("write failed: {e}")))
    })
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Encodes a file name for a relative URL (every byte outside `[A-Za-z0-9._-]` escaped).
fn url_component(s: &str) -> String {
    s.bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() || b"._-".contains(&b) {
                (b as char).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect()
}

/// The gallery page: per input, the image and disparity, then a table with one row per
/// focal plane and one column per method.
pub fn gallery_html(
    inputs: &[GalleryInput],
    sizes: &[(usize, usize)],
    options: &GalleryOptions,
    planes: &[f64],
) -> String {
    let mut s = String::new();
    s.push_str(
        r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>drbokeh refocus gallery</title>
<style>
body { font-family: sans-serif; margin: 16px; background: #fafafa; color: #222; }
table { border-collapse: collapse; }
th, td { border: 1px solid #ccc; padding: 2px; font-size: 12px; vertical-align: top; }
th { background: #eee; }
img { width: 180px; height: auto; display: block; }
figure { margin: 0; }
figcaption { font-size: 12px; }
.inputs { display: flex; gap: 8px; margin: 6px 0; }
section { border-top: 2px solid #bbb; padding: 6px 0; }
</style>
</head>
<body>
<h1>drbokeh refocus gallery</h1>
"#,
    );
    let _ = writeln!(
        s,
        "<p>{} inputs, {} focal planes (normalised disparity from far to near), blur K = {}, gamma {}. Columns: methods fed the same image + disparity.</p>",
        inputs.len(),
        planes.len(),
        options.blur_k,
        options.gamma
    );
    for (i, input) in inputs.iter().enumerate() {
        let dir = url_component(&input.name);
        let (w, h) = sizes.get(i).copied().unwrap_or((0, 0));
        let _ = writeln!(
            s,
            "<section><h2>{} <small>({w}x{h})</small></h2><div class=\"inputs\"><figure><img src=\"{dir}/input.jpg\" alt=\"input\"><figcaption>input</figcaption></figure><figure><img src=\"{dir}/disparity.png\" alt=\"disparity\"><figcaption>disparity</figcaption></figure></div>",
            esc(&input.name)
        );
        s.push_str("<table><thead><tr><th>focus</th>");
        for m in &options.methods {
            let _ = write!(
                s,
                "<th title=\"{}\">{}</th>",
                esc(m.description()),
                m.name()
            );
        }
        s.push_str("</tr></thead><tbody>\n");
        for (pi, f) in planes.iter().enumerate() {
            let _ = write!(s, "<tr><th>{f:.3}</th>");
            for &m in &options.methods {
                let _ = write!(
                    s,
                    "<td><img src=\"{dir}/{}\" alt=\"{} at focus {f:.3}\"></td>",
                    sweep_file(pi, m),
                    m.name()
                );
            }
            s.push_str("</tr>\n");
        }
        s.push_str("</tbody></table></section>\n");
    }
    s.push_str("</body>\n</html>\n");
    s
}
