//! Scene files: the JSON a user writes to describe a camera, a lens and billboards.
//!
//! ```json
//! {
//!   "name": "garden",
//!   "camera": {
//!     "lens": { "model": "spherical", "curvature_radius_mm": 50.0,
//!               "rim_radius_mm": 10.0, "eta": 1.5, "aperture_radius_mm": 4.0 },
//!     "width_px": 512, "height_px": 512, "fov_deg": 20.0,
//!     "focus_distance_mm": 1000.0
//!   },
//!   "render": { "spp": 1024, "seed": 1 },
//!   "billboards": [
//!     { "depth_mm": 400.0, "center": [0.3, 0.6], "size": [0.5, 0.6],
//!       "texture": { "type": "image", "path": "leaf.png" } },
//!     { "depth_mm": 4000.0, "center": [0.5, 0.5], "size": [1.6, 1.6],
//!       "texture": { "type": "procedural", "kind": "background", "seed": 7 } }
//!   ]
//! }
//! ```
//!
//! - `camera.lens.model`: `"spherical"` (thick biconvex lens: `curvature_radius_mm` Rc,
//!   `rim_radius_mm` Ra < Rc, `eta`, optional `aperture_radius_mm` <= Ra, default Ra) or
//!   `"thin"` (ideal thin lens: `focal_length_mm`, `aperture_radius_mm`).
//! - Exactly one of `camera.sensor_distance_mm` (D_I, from the rear principal plane, > f)
//!   and `camera.focus_distance_mm` (object distance in focus, from the front principal
//!   plane, > f) places the sensor. `fov_deg` is the horizontal field of view; it fixes
//!   the sensor width `2 D_I tan(fov/2)` and hence the pixel pitch.
//! - Billboards are fronto-parallel planes at `depth_mm` (from the front principal
//!   plane). `center` and `size` are in fractions of the image: center `[0.5, 0.5]` with
//!   size `[1, 1]` exactly fills the frame (through the paraxial chief ray). Make the
//!   background larger than the frame (e.g. 1.6) so that blurred rays still meet it.
//! - Textures: `{"type": "image", "path": ..., "alpha": optional matte, "gain": 1.0}`
//!   (PNG/JPEG/TIFF gamma 2.2, or linear EXR; paths relative to the scene file),
//!   `{"type": "solid", "color": [r, g, b], "alpha": 1.0, "gain": 1.0}` (display-encoded
//!   colour), or `{"type": "procedural", "kind": "background" | "foliage" | "strands" |
//!   "fence" | "fluff", "seed": N}`.
//! - `render.spp` (samples per pixel, a perfect square), `render.aif_spp` (pixel samples of
//!   the pinhole passes, a perfect square) and `render.seed` are optional.

use super::optics::{LensModel, Optics, SphericalLens};
use super::procedural::{self, HighlightRange, ProceduralKind};
use super::sampling::strata_side;
use super::texture::{decode_display, Texture};
use crate::image::Image;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Normalised disparity of a depth: `(1/z - 1/z_far) / (1/z_near - 1/z_far)` (1 at
/// `near_mm`, 0 at `far_mm`; the two must differ).
pub fn normalised_disparity(depth_mm: f64, near_mm: f64, far_mm: f64) -> f64 {
    (1.0 / depth_mm - 1.0 / far_mm) / (1.0 / near_mm - 1.0 / far_mm)
}

/// The standard number of samples per pixel (pixel area x pupil).
pub const STANDARD_SPP: usize = 1024;
/// The standard number of pixel-area samples of the pinhole (all-in-focus) passes.
pub const STANDARD_AIF_SPP: usize = 64;

/// The lens in a scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum LensSpec {
    /// A thick biconvex spherical lens, traced with Snell's law.
    Spherical {
        /// Radius of curvature Rc of both surfaces, mm.
        curvature_radius_mm: f64,
        /// Rim radius Ra (half the lens diameter), mm; Ra < Rc.
        rim_radius_mm: f64,
        /// Refractive index.
        eta: f64,
        /// Radius of the aperture stop at the rear vertex, mm (default: Ra).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        aperture_radius_mm: Option<f64>,
    },
    /// An ideal thin lens (for validation against other renderers).
    Thin {
        /// Focal length, mm.
        focal_length_mm: f64,
        /// Aperture radius, mm.
        aperture_radius_mm: f64,
    },
}

/// Camera: lens, sensor and image size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// The lens.
    pub lens: LensSpec,
    /// Image width, pixels.
    pub width_px: usize,
    /// Image height, pixels.
    pub height_px: usize,
    /// Horizontal field of view, degrees (0, 170).
    pub fov_deg: f64,
    /// Sensor distance D_I from the rear principal plane, mm (give this or `focus_distance_mm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_distance_mm: Option<f64>,
    /// Object distance in focus, mm (give this or `sensor_distance_mm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_distance_mm: Option<f64>,
}

/// Sampling controls.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSpec {
    /// Samples per pixel of the defocused image (pixel area x pupil); a perfect square.
    #[serde(default = "default_spp")]
    pub spp: usize,
    /// Pixel-area samples of the all-in-focus, depth and layer passes; a perfect square.
    #[serde(default = "default_aif_spp")]
    pub aif_spp: usize,
    /// Seed of the sample patterns.
    #[serde(default)]
    pub seed: u64,
}

fn default_spp() -> usize {
    STANDARD_SPP
}
fn default_aif_spp() -> usize {
    STANDARD_AIF_SPP
}

impl Default for RenderSpec {
    fn default() -> Self {
        RenderSpec {
            spp: STANDARD_SPP,
            aif_spp: STANDARD_AIF_SPP,
            seed: 0,
        }
    }
}

fn one() -> f64 {
    1.0
}

/// A billboard's content.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum TextureSpec {
    /// An image file (its alpha channel, or `alpha`, gives the coverage).
    Image {
        /// Colour image (relative paths are relative to the scene file).
        path: PathBuf,
        /// Optional separate alpha matte of the same size.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha: Option<PathBuf>,
        /// Multiplier on linear colour.
        #[serde(default = "one")]
        gain: f64,
    },
    /// A constant colour.
    Solid {
        /// Display-encoded colour in [0, 1].
        color: [f64; 3],
        /// Alpha in [0, 1].
        #[serde(default = "one")]
        alpha: f64,
        /// Multiplier on linear colour.
        #[serde(default = "one")]
        gain: f64,
    },
    /// Procedural content.
    Procedural {
        /// What to draw.
        kind: ProceduralKind,
        /// Its seed.
        seed: u64,
        /// Range of the highlights' linear gains (default 2 to 10).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        highlight_range: Option<HighlightRange>,
        /// Strength in [0, 1] of the fine detail on a background's surfaces (default none;
        /// [`procedural::generate_with`]).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        background_detail: Option<f64>,
    },
}

/// A fronto-parallel billboard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BillboardSpec {
    /// A label.
    #[serde(default)]
    pub name: String,
    /// Distance from the front principal plane, mm.
    pub depth_mm: f64,
    /// Centre in image fractions (x right, y down); `[0.5, 0.5]` is the image centre.
    #[serde(default = "centre")]
    pub center: [f64; 2],
    /// Size in image fractions (width, height); `[1, 1]` fills the frame.
    pub size: [f64; 2],
    /// Content.
    pub texture: TextureSpec,
}

fn centre() -> [f64; 2] {
    [0.5, 0.5]
}

/// A scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// A label.
    #[serde(default)]
    pub name: String,
    /// Camera and lens.
    pub camera: CameraSpec,
    /// Sampling.
    #[serde(default)]
    pub render: RenderSpec,
    /// Billboards, in any order (sorted front to back when loaded).
    pub billboards: Vec<BillboardSpec>,
    /// Derived values written by the tracer (ignored on input).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub derived: Option<serde_json::Value>,
}

impl SceneSpec {
    /// Parses a scene file's text; `what` names it in errors.
    pub fn from_json(text: &str, what: &Path) -> Result<Self> {
        serde_json::from_str(text)
            .map_err(|e| Error::file(what, format!("invalid scene JSON: {e}")))
    }

    /// Reads a scene file.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read scene file: {e}")))?;
        Self::from_json(&text, path)
    }

    /// Builds the camera, checking every lens and sensor parameter.
    pub fn optics(&self) -> Result<Optics> {
        let cam = &self.camera;
        crate::image::check_dimensions("camera", cam.width_px, cam.height_px)?;
        let (lens, aperture) = match cam.lens {
            LensSpec::Spherical {
                curvature_radius_mm,
                rim_radius_mm,
                eta,
                aperture_radius_mm,
            } => (
                LensModel::Spherical(SphericalLens::new(curvature_radius_mm, rim_radius_mm, eta)?),
                aperture_radius_mm.unwrap_or(rim_radius_mm),
            ),
            LensSpec::Thin {
                focal_length_mm,
                aperture_radius_mm,
            } => (LensModel::Thin { focal_length_mm }, aperture_radius_mm),
        };
        let f = match lens {
            LensModel::Spherical(l) => l.focal_length_mm(),
            LensModel::Thin { focal_length_mm } => focal_length_mm,
        };
        let d_i = match (cam.sensor_distance_mm, cam.focus_distance_mm) {
            (Some(d), None) => d,
            (None, Some(z)) => {
                if !z.is_finite() || z <= f {
                    return Err(Error::param(
                        "camera.focus_distance_mm",
                        format!("focus distance {z} mm must exceed the focal length f = {f:.4} mm"),
                    ));
                }
                1.0 / (1.0 / f - 1.0 / z)
            }
            _ => {
                return Err(Error::param(
                    "camera",
                    "give exactly one of sensor_distance_mm and focus_distance_mm",
                ))
            }
        };
        if !cam.fov_deg.is_finite() || cam.fov_deg <= 0.0 || cam.fov_deg >= 170.0 {
            return Err(Error::param(
                "camera.fov_deg",
                format!(
                    "field of view must be in (0, 170) degrees, got {}",
                    cam.fov_deg
                ),
            ));
        }
        let pitch = 2.0 * d_i * (0.5 * cam.fov_deg.to_radians()).tan() / cam.width_px as f64;
        Optics::new(lens, aperture, d_i, pitch, cam.width_px, cam.height_px)
    }

    /// Checks sampling and billboard parameters (not the texture files).
    pub fn validate(&self) -> Result<()> {
        self.optics()?;
        for (name, v) in [
            ("render.spp", self.render.spp),
            ("render.aif_spp", self.render.aif_spp),
        ] {
            if strata_side(v).is_none() || v > 1 << 20 {
                return Err(Error::param(
                    name,
                    format!(
                        "must be a perfect square between 1 and 2^20 (e.g. 256, 1024), got {v}"
                    ),
                ));
            }
        }
        if self.billboards.is_empty() {
            return Err(Error::input("scene", "has no billboards"));
        }
        if self.billboards.len() > crate::budget::MAX_BILLBOARDS {
            return Err(Error::input(
                "scene",
                format!(
                    "has {} billboards; at most {} are supported",
                    self.billboards.len(),
                    crate::budget::MAX_BILLBOARDS
                ),
            ));
        }
        let mut depths: Vec<(f64, &str)> = self
            .billboards
            .iter()
            .map(|b| (b.depth_mm, b.name.as_str()))
            .collect();
        depths.sort_by(|a, b| a.0.total_cmp(&b.0));
        if let Some(w) = depths.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(Error::input(
                "scene",
                format!(
                    "billboards '{}' and '{}' share depth {} mm; depths must be distinct",
                    w[0].1, w[1].1, w[0].0
                ),
            ));
        }
        let f = self.optics()?.focal_length_mm();
        for (i, b) in self.billboards.iter().enumerate() {
            let what = format!("billboards[{i}]");
            if !b.depth_mm.is_finite() || b.depth_mm <= f {
                return Err(Error::param(
                    format!("{what}.depth_mm"),
                    format!(
                        "depth must exceed the focal length f = {f:.4} mm, got {}",
                        b.depth_mm
                    ),
                ));
            }
            if b.size
                .iter()
                .any(|v| !v.is_finite() || *v <= 0.0 || *v > 100.0)
                || b.center.iter().any(|v| !v.is_finite() || v.abs() > 100.0)
            {
                return Err(Error::param(
                    format!("{what}.size/center"),
                    "sizes must be in (0, 100] and centres finite image fractions",
                ));
            }
            match &b.texture {
                TextureSpec::Solid { color, alpha, gain } => {
                    if color.iter().any(|c| !c.is_finite() || *c < 0.0)
                        || !(0.0..=1.0).contains(alpha)
                        || !gain.is_finite()
                        || *gain < 0.0
                    {
                        return Err(Error::param(
                            format!("{what}.texture"),
                            "solid colour must be >= 0, alpha in [0, 1], gain >= 0",
                        ));
                    }
                    if color
                        .iter()
                        .any(|&c| !((decode_display(c) * gain * alpha) as f32).is_finite())
                    {
                        return Err(Error::param(
                            format!("{what}.texture"),
                            format!("colour times gain {gain} overflows (not finite in float32)"),
                        ));
                    }
                }
                TextureSpec::Image { gain, .. } => {
                    if !gain.is_finite() || *gain < 0.0 {
                        return Err(Error::param(format!("{what}.texture.gain"), "must be >= 0"));
                    }
                }
                TextureSpec::Procedural {
                    highlight_range,
                    background_detail,
                    ..
                } => {
                    if let Some(r) = highlight_range {
                        r.validate()?;
                    }
                    if let Some(d) = background_detail {
                        procedural::validate_background_detail(*d)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Procedural textures get about two texels per image pixel (at most 4096 per side).
    fn procedural_size(b: &BillboardSpec, optics: &Optics) -> (usize, usize) {
        let tw = ((b.size[0] * optics.width_px as f64 * 2.0).ceil() as usize).clamp(2, 4096);
        let th = ((b.size[1] * optics.height_px as f64 * 2.0).ceil() as usize).clamp(2, 4096);
        (tw, th)
    }

    /// Checks the scene's work against the input budget ([`crate::budget`]) before anything
    /// is generated: the image planes (one per billboard plus
    /// [`crate::budget::TRACE_EXTRA_LAYERS`]) and every texture's texels (image textures'
    /// sizes read from their headers, counted twice for their decoded copies).
    pub fn check_budget(&self, base_dir: &Path) -> Result<()> {
        let optics = self.optics()?;
        let (w, h) = (optics.width_px as u64, optics.height_px as u64);
        let planes = self.billboards.len() as u64 + crate::budget::TRACE_EXTRA_LAYERS;
        let mut texels = 0u64;
        for b in &self.billboards {
            texels = texels.saturating_add(match &b.texture {
                TextureSpec::Image { path, alpha, .. } => {
                    let (tw, th) = crate::io::image_dimensions(&base_dir.join(path), "texture")?;
                    if let Some(a) = alpha {
                        crate::io::image_dimensions(&base_dir.join(a), "alpha matte")?;
                    }
                    2 * tw as u64 * th as u64
                }
                TextureSpec::Solid { .. } => 1,
                TextureSpec::Procedural { .. } => {
                    let (tw, th) = Self::procedural_size(b, &optics);
                    tw as u64 * th as u64
                }
            });
        }
        let units = w
            .saturating_mul(h)
            .saturating_mul(planes)
            .saturating_add(texels);
        crate::budget::check_work_units(
            "scene",
            &format!(
                "{w}x{h} x {planes} planes ({} billboards + {}) + {texels} texels",
                self.billboards.len(),
                crate::budget::TRACE_EXTRA_LAYERS
            ),
            units,
        )
    }

    /// Loads textures (relative paths from `base_dir`) and builds the traceable scene.
    /// Checks the parameters and the input budget before generating or reading any texture.
    pub fn load(&self, base_dir: &Path) -> Result<Scene> {
        self.validate()?;
        self.check_budget(base_dir)?;
        let optics = self.optics()?;
        let mut billboards = Vec::with_capacity(self.billboards.len());
        for b in &self.billboards {
            let (tw, th) = Self::procedural_size(b, &optics);
            let texture = match &b.texture {
                TextureSpec::Image { path, alpha, gain } => {
                    let p = base_dir.join(path);
                    let a = alpha.as_ref().map(|a| base_dir.join(a));
                    Texture::from_files(&p, a.as_deref(), *gain)?
                }
                TextureSpec::Solid { color, alpha, gain } => {
                    Texture::solid(color.map(|c| decode_display(c) * gain), *alpha)
                }
                TextureSpec::Procedural {
                    kind,
                    seed,
                    highlight_range,
                    background_detail,
                } => procedural::generate_with(
                    *kind,
                    *seed,
                    tw,
                    th,
                    highlight_range.unwrap_or_default(),
                    background_detail.unwrap_or(0.0),
                ),
            };
            billboards.push(Billboard::place(
                &optics,
                b.name.clone(),
                b.depth_mm,
                b.center,
                b.size,
                texture,
            ));
        }
        Scene::new(optics, billboards)
    }
}

/// A billboard placed in the world.
#[derive(Clone, Debug)]
pub struct Billboard {
    /// Label.
    pub name: String,
    /// Distance from the front principal plane, mm.
    pub depth_mm: f64,
    /// `z` of its plane.
    pub z_mm: f64,
    /// World extent: x from `x0_mm` to `x1_mm`, y from `y0_mm` to `y1_mm` (y grows down
    /// the image).
    pub x0_mm: f64,
    /// See `x0_mm`.
    pub x1_mm: f64,
    /// See `x0_mm`.
    pub y0_mm: f64,
    /// See `x0_mm`.
    pub y1_mm: f64,
    /// Content (premultiplied linear RGBA).
    pub texture: Arc<Texture>,
    /// Its mip pyramid (level 0 = `texture`), for footprint-filtered lookups.
    pub levels: Arc<Vec<Texture>>,
}

impl Billboard {
    /// Places a billboard at `depth_mm` covering the image rectangle given by `center` and
    /// `size` (image fractions) as seen through the paraxial chief ray.
    pub fn place(
        optics: &Optics,
        name: String,
        depth_mm: f64,
        center: [f64; 2],
        size: [f64; 2],
        texture: Texture,
    ) -> Self {
        let scale = depth_mm / optics.sensor_distance_mm; // world mm per sensor mm
        let (sw, sh) = (optics.sensor_width_mm(), optics.sensor_height_mm());
        let x0 = (center[0] - 0.5 * size[0] - 0.5) * sw * scale;
        let x1 = (center[0] + 0.5 * size[0] - 0.5) * sw * scale;
        let y0 = (center[1] - 0.5 * size[1] - 0.5) * sh * scale;
        let y1 = (center[1] + 0.5 * size[1] - 0.5) * sh * scale;
        Billboard {
            name,
            depth_mm,
            z_mm: optics.object_plane_z_mm(depth_mm),
            x0_mm: x0,
            x1_mm: x1,
            y0_mm: y0,
            y1_mm: y1,
            levels: Arc::new(texture.clone().pyramid()),
            texture: Arc::new(texture),
        }
    }

    /// Premultiplied linear RGBA where the ray meets this billboard (transparent if it misses).
    #[inline]
    pub fn lookup(&self, ray: &super::optics::Ray) -> [f32; 4] {
        self.lookup_level(ray, 0)
    }

    /// As [`Billboard::lookup`], from mip level `level` (0 = full resolution).
    #[inline]
    pub fn lookup_level(&self, ray: &super::optics::Ray, level: usize) -> [f32; 4] {
        match super::optics::hit_plane_z(ray, self.z_mm) {
            Some((x, y)) => self.levels[level.min(self.levels.len() - 1)].sample(
                (x - self.x0_mm) / (self.x1_mm - self.x0_mm),
                (y - self.y0_mm) / (self.y1_mm - self.y0_mm),
            ),
            None => [0.0; 4],
        }
    }
}

impl Billboard {
    /// The mip level whose texel matches the footprint of one pupil stratum on this
    /// billboard when a pixel's `spp` rays are spread over the aperture: the cone of rays
    /// from the stop (radius A) to the focus plane is `2 A |1 - z/z_f|` wide at depth z
    /// (paraxially); one of `spp` strata covers `1/sqrt(spp)` of that width. The level is
    /// rounded down (under-filtering), so in-focus billboards use full resolution and the
    /// added blur is a fraction of a pixel next to the defocus blur it hides in.
    pub fn footprint_level(&self, optics: &super::optics::Optics, spp: usize) -> usize {
        let cone_mm = 2.0
            * optics.aperture_radius_mm
            * (1.0 - self.depth_mm / optics.focus_distance_mm()).abs();
        let stratum_mm = cone_mm / (spp.max(1) as f64).sqrt();
        let texel_mm = ((self.x1_mm - self.x0_mm) / self.texture.width as f64)
            .max((self.y1_mm - self.y0_mm) / self.texture.height as f64);
        let ratio = stratum_mm / texel_mm;
        if ratio < 2.0 {
            0
        } else {
            (ratio.log2().floor() as usize).min(self.levels.len() - 1)
        }
    }
}

/// A scene ready to trace: camera and billboards sorted front (nearest) to back.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The camera.
    pub optics: Optics,
    /// Billboards, nearest first.
    pub billboards: Vec<Billboard>,
}

impl Scene {
    /// Sorts the billboards front to back and checks that their depths are distinct.
    pub fn new(optics: Optics, mut billboards: Vec<Billboard>) -> Result<Self> {
        if billboards.is_empty() {
            return Err(Error::input("scene", "has no billboards"));
        }
        billboards.sort_by(|a, b| a.depth_mm.total_cmp(&b.depth_mm));
        for w in billboards.windows(2) {
            if w[0].depth_mm == w[1].depth_mm {
                return Err(Error::input(
                    "scene",
                    format!(
                        "billboards '{}' and '{}' share depth {} mm; depths must be distinct",
                        w[0].name, w[1].name, w[0].depth_mm
                    ),
                ));
            }
        }
        Ok(Scene { optics, billboards })
    }

    /// Normalised disparity of a depth over the scene's nearest and farthest billboards
    /// ([`normalised_disparity`]; 1 for a scene whose billboards share one depth).
    pub fn disparity_of_depth(&self, depth_mm: f64) -> f64 {
        let (near, far) = self.depth_range_mm();
        if near == far {
            return 1.0;
        }
        normalised_disparity(depth_mm, near, far)
    }

    /// Normalised disparity of every pixel of a depth map in mm (the tracer's pinhole
    /// pass). The depths there are `f32`, so the
    /// nearest and farthest billboards give 1 and 0 only up to that rounding (e.g.
    /// -1.02e-9); values within [`PIXEL_DISPARITY_SNAP`] of [0, 1] are snapped into it,
    /// so the map is a valid disparity for every command (`drbokeh dfd
    /// --initial-disparity` refuses values outside [0, 1]).
    pub fn disparity_map(&self, depth_mm: &Image<f32>) -> Image<f32> {
        Image {
            width: depth_mm.width,
            height: depth_mm.height,
            channels: 1,
            data: depth_mm
                .data
                .iter()
                .map(|&z| {
                    snap_into_unit(self.disparity_of_depth(z as f64), PIXEL_DISPARITY_SNAP) as f32
                })
                .collect(),
        }
    }

    /// Depths of the nearest and farthest billboards, mm.
    pub fn depth_range_mm(&self) -> (f64, f64) {
        (
            self.billboards.first().unwrap().depth_mm,
            self.billboards.last().unwrap().depth_mm,
        )
    }

    /// The renderer-equivalent blur strength K (pixels per unit normalised disparity):
    /// `Ra D_I (1/z_near - 1/z_far) / pixel_pitch`.
    pub fn blur_k_px(&self) -> f64 {
        let (near, far) = self.depth_range_mm();
        let o = &self.optics;
        o.aperture_radius_mm * o.sensor_distance_mm * (1.0 / near - 1.0 / far) / o.pixel_pitch_mm
    }

    /// The renderer-equivalent focus disparity (may fall outside [0, 1] if the focus plane
    /// is outside the billboards' depth range).
    pub fn focus_disparity(&self) -> f64 {
        snap_unit(self.disparity_of_depth(self.optics.focus_distance_mm()))
    }
}

/// A normalised disparity within 1e-9 of [0, 1] snapped into it: focusing on the nearest or
/// farthest billboard computes 1 or 0 up to rounding (e.g. 1.0000000000000002), and the
/// recorded value must be a valid `--focus`.
pub fn snap_unit(v: f64) -> f64 {
    snap_into_unit(v, 1e-9)
}

/// How far outside [0, 1] a pixel's disparity may fall from the `f32` rounding of its
/// depth and still be snapped into it ([`Scene::disparity_map`]): the rounding moves a
/// disparity by about 1e-7 times `(1/z) / (1/z_near - 1/z_far)`.
pub const PIXEL_DISPARITY_SNAP: f64 = 1e-5;

/// `v` clamped into [0, 1] when it lies within `tolerance` of it; unchanged otherwise.
fn snap_into_unit(v: f64, tolerance: f64) -> f64 {
    if (-tolerance..=1.0 + tolerance).contains(&v) {
        v.clamp(0.0, 1.0)
    } else {
        v
    }
}
