//! From a photo to a layer stack: layer decomposition and inpainting, with no learned model.
//!
//! Occlusion-aware bokeh needs what a photo does not contain: the background hidden
//! behind the foreground, which a blurred foreground rim reveals. This module builds a
//! [`LayerStack`] from an image and its disparity map, with or without an alpha matte.
//! See `docs/layering.md` for a walk-through with its limits.
//!
//! **With a matte** ([`layers_from_matte`], the paper's two-layer recipe): the foreground
//! layer is the image with alpha = matte and its disparity extended outward beyond the
//! matte by a smooth fill; the background layer is the image with the region under the
//! matte (dilated by [`BACKGROUND_DILATION_PX`]) inpainted, colour by fast marching
//! ([`inpaint_telea`]) and disparity by a smooth membrane fill ([`smooth_fill`]), both
//! reading the visible background only; its alpha is 1.
//!
//! **Without a matte** ([`layers_from_disparity`]): the disparity map is cut into up to
//! `max_layers` depth intervals at thresholds chosen where many neighbouring pixels jump
//! in disparity by more than a threshold, and few continuous surfaces are crossed (see
//! the `cuts` module). Each pixel belongs to the layer of its interval (layer 0 =
//! nearest). When the render's focus and blur are known ([`LayeringOptions::focus_hint`]),
//! cuts whose nearer side is less blurred than its farther side (by default; a margin is
//! [`LayeringOptions::min_blur_gain_px`]) are dropped: a sharp edge over a blurred
//! background renders the same with or without layers, and the cut only adds seams.
//! Layer `k` then gets:
//! - colour: the image on its own pixels; behind the nearer layers, a fast-marching fill
//!   from its own pixels only (optionally excluding those within
//!   [`LayeringOptions::colour_guard_px`] of a nearer pixel), out to
//!   [`LayeringOptions::occlusion_band_px`] behind the occluder (the last layer: all of it);
//! - alpha: 1 on its own pixels; on the filled band behind nearer layers, its local
//!   coverage continued under them ([`LayeringOptions::band_alpha_fill`]: a fence stays
//!   see-through); the pixels just beyond its cut edges get partial alpha (a box of radius
//!   [`LayeringOptions::feather_px`]), so the edges are soft while the layer's own pixels
//!   stay opaque (an in-focus render reproduces the image); the last layer is opaque
//!   (optionally, [`LayeringOptions::matting_px`] estimates edge alpha from local colour
//!   models instead; it did not help on the ray-traced benchmark and is off by default);
//! - disparity: its own values, extended everywhere else by a smooth fill from its own
//!   pixels (so behind a nearer layer it continues the *background* side of the edge).
//!
//! Limits: a depth edge whose disparity changes gradually (no single neighbour step above
//! the threshold) is not cut; the layers are disparity intervals, so a surface that spans
//! a cut (a floor) is split along an iso-disparity line; the hidden content is a guess
//! that continues the visible surroundings (no texture synthesis), good for smooth or
//! stochastic backgrounds and for the narrow rims that bokeh reveals, poor for large
//! structured holes; an intermediate layer's fill extends a fixed band behind its
//! occluders, whatever lies there.

mod cuts;
mod fill;
mod preview;
mod telea;

pub use fill::{push_pull_fill, smooth_fill};
pub use preview::{sibling, write_previews};
pub use telea::{inpaint_telea, Inpainted, Region, TeleaOptions};

use crate::image::{check_dimensions, Image};
use crate::stack::{Layer, LayerStack};
use crate::{Error, Real, Result};
use rayon::prelude::*;

/// Matte values at or above this count as foreground when extending its disparity.
pub const FOREGROUND_THRESHOLD: f64 = 0.5;
/// Pixels within this distance of any matte value above zero are filled in the background.
pub const BACKGROUND_DILATION_PX: usize = 2;
/// Default for [`LayeringOptions::max_layers`].
pub const DEFAULT_MAX_LAYERS: usize = 5;
/// The largest accepted [`LayeringOptions::max_layers`].
pub const MAX_LAYERS_LIMIT: usize = 16;

/// Parameters of the decomposition.
#[derive(Clone, Debug, PartialEq)]
pub struct LayeringOptions {
    /// Most layers produced without a matte (1 to [`MAX_LAYERS_LIMIT`]).
    pub max_layers: usize,
    /// A disparity step between neighbours larger than this fraction of the map's
    /// disparity range is a discontinuity (0 < value < 1).
    pub jump_fraction: f64,
    /// A layer must hold at least this fraction of the pixels (and at least 4 pixels).
    pub min_layer_fraction: f64,
    /// Radius of the box that softens alpha at cut edges (0 = hard edges).
    pub feather_px: usize,
    /// Pixels of a layer this close to a nearer layer are not used as colour fill sources
    /// (edge pixels mix both colours). 0 by default: on the ray-traced benchmark, fills
    /// that skip the edge pixels come from too far away behind thin structures (strands,
    /// fence wires, where every visible background pixel is near an edge), which costs
    /// more than the mixed edge colour does.
    pub colour_guard_px: usize,
    /// Pixels of a layer this close to any other layer are not used as disparity fill
    /// sources (estimated disparity maps blend the two sides across an edge).
    pub disparity_guard_px: usize,
    /// How far (pixels) an intermediate layer is filled in behind nearer layers; `None`:
    /// 5 % of the larger image side, at least 16. The last layer is always filled entirely.
    pub occlusion_band_px: Option<f64>,
    /// Fast-marching inpainting parameters (its `max_distance` is set per layer).
    pub inpaint: TeleaOptions,
    /// Width (pixels, each side) of the band around each cut edge whose alpha is
    /// estimated from local colour models (0 = no matting: hard labels and a feather).
    pub matting_px: usize,
    /// Colour of the nearer layer on matted edge pixels: `true` un-premultiplies the
    /// image by the estimated alpha and background, `false` uses the fill from the
    /// layer's interior.
    pub matting_unpremultiply: bool,
    /// Alpha of an intermediate layer where it is filled in behind nearer layers: `true`
    /// continues the layer's local coverage (a smooth fill of 1 on its pixels and 0 on
    /// farther ones, so a fence stays see-through), `false` makes the band opaque.
    pub band_alpha_fill: bool,
    /// The render the stack is made for, when known: `(focus, blur K)`. A cut is then
    /// kept only where, on average over the depth edges it separates, the nearer side is
    /// blurred at least as much as the farther side, plus
    /// [`LayeringOptions::min_blur_gain_px`] (elsewhere the layers cannot change the
    /// render much, and a cut only adds seams).
    pub focus_hint: Option<(f64, f64)>,
    /// See [`LayeringOptions::focus_hint`] (pixels of blur radius, >= 0). 0 by default
    /// (since session 39; 1 px before): on the ray-traced benchmark, cuts whose nearer
    /// side is blurred by less than a pixel more than the farther one still changed
    /// the photo pipeline's render for the better (docs/layering.md, "The cut filter").
    pub min_blur_gain_px: f64,
}

impl Default for LayeringOptions {
    fn default() -> Self {
        LayeringOptions {
            max_layers: DEFAULT_MAX_LAYERS,
            jump_fraction: 0.05,
            min_layer_fraction: 0.002,
            feather_px: 1,
            colour_guard_px: 0,
            disparity_guard_px: 2,
            occlusion_band_px: None,
            inpaint: TeleaOptions::default(),
            matting_px: 0,
            matting_unpremultiply: true,
            band_alpha_fill: true,
            focus_hint: None,
            min_blur_gain_px: 0.0,
        }
    }
}

impl LayeringOptions {
    /// Checks every parameter; messages name the parameter (`max_layers`, `jump`, ...).
    pub fn validate(&self) -> Result<()> {
        if self.max_layers == 0 || self.max_layers > MAX_LAYERS_LIMIT {
            return Err(Error::param(
                "max_layers",
                format!(
                    "must be between 1 and {MAX_LAYERS_LIMIT}, got {}",
                    self.max_layers
                ),
            ));
        }
        if !(self.jump_fraction > 0.0 && self.jump_fraction < 1.0) {
            return Err(Error::param(
                "jump",
                format!(
                    "must be a fraction of the disparity range in (0, 1), got {}",
                    self.jump_fraction
                ),
            ));
        }
        if !(0.0..0.5).contains(&self.min_layer_fraction) {
            return Err(Error::param(
                "min_layer_fraction",
                format!("must be in [0, 0.5), got {}", self.min_layer_fraction),
            ));
        }
        if self.feather_px > 64
            || self.colour_guard_px > 64
            || self.disparity_guard_px > 64
            || self.matting_px > 64
        {
            return Err(Error::param(
                "feather_px/colour_guard_px/disparity_guard_px/matting_px",
                "must be at most 64 pixels",
            ));
        }
        if let Some(b) = self.occlusion_band_px {
            if b.is_nan() || b < 0.0 {
                return Err(Error::param(
                    "band",
                    format!("must be a non-negative number of pixels, got {b}"),
                ));
            }
        }
        if let Some((f, k)) = self.focus_hint {
            if !(0.0..=1.0).contains(&f) {
                return Err(Error::param(
                    "focus",
                    format!("must be a disparity in [0, 1], got {f}"),
                ));
            }
            if !(k.is_finite() && k >= 0.0) {
                return Err(Error::param(
                    "blur",
                    format!("must be a finite number >= 0, got {k}"),
                ));
            }
        }
        if !(self.min_blur_gain_px.is_finite() && self.min_blur_gain_px >= 0.0) {
            return Err(Error::param(
                "min_blur_gain_px",
                format!(
                    "must be a finite number >= 0, got {}",
                    self.min_blur_gain_px
                ),
            ));
        }
        let r = self.inpaint.radius;
        if !(1.0..=32.0).contains(&r) {
            return Err(Error::param(
                "inpaint radius",
                format!("must be between 1 and 32 pixels, got {r}"),
            ));
        }
        Ok(())
    }
}

/// A layer stack built from a photo, with what the user should know about it.
#[derive(Clone, Debug)]
pub struct Decomposition<T> {
    /// The layers, front to back.
    pub stack: LayerStack<T>,
    /// Disparity thresholds between consecutive layers, nearest first (empty with a matte
    /// or a single layer).
    pub thresholds: Vec<f64>,
    /// Notes for the user (e.g. why a single layer was produced).
    pub notes: Vec<String>,
}

/// Builds a layer stack from an image and its disparity, using the matte when given
/// ([`layers_from_matte`]) and the automatic decomposition otherwise
/// ([`layers_from_disparity`]).
pub fn decompose<T: Real>(
    rgb_encoded: &Image<T>,
    disparity: &Image<T>,
    matte: Option<&Image<T>>,
    opts: &LayeringOptions,
) -> Result<Decomposition<T>> {
    match matte {
        Some(m) => layers_from_matte(rgb_encoded, disparity, m, opts),
        None => layers_from_disparity(rgb_encoded, disparity, opts),
    }
}

/// Builds a two-layer stack (foreground, background) from an image, its disparity and an
/// alpha matte, all of the same size. An empty matte gives a single opaque layer.
pub fn two_layers_from_matte<T: Real>(
    rgb_encoded: &Image<T>,
    disparity: &Image<T>,
    matte: &Image<T>,
) -> Result<LayerStack<T>> {
    Ok(layers_from_matte(rgb_encoded, disparity, matte, &LayeringOptions::default())?.stack)
}

/// Checks shapes, channel counts and values of the inputs.
fn check_inputs<T: Real>(
    rgb: &Image<T>,
    disparity: &Image<T>,
    matte: Option<&Image<T>>,
) -> Result<()> {
    let (w, h) = (rgb.width, rgb.height);
    check_dimensions("image", w, h)?;
    let mut planes = vec![("image", rgb, 3), ("disparity map", disparity, 1)];
    if let Some(m) = matte {
        planes.push(("alpha matte", m, 1));
    }
    for (name, img, ch) in planes {
        if img.width != w || img.height != h {
            return Err(Error::input(
                name,
                format!("is {}x{}, but the image is {w}x{h}", img.width, img.height),
            ));
        }
        if img.channels != ch || img.data.len() != w * h * ch {
            return Err(Error::input(
                name,
                format!("has {} channels, expected {ch}", img.channels),
            ));
        }
        img.check_finite(name)?;
    }
    if let Some(v) = rgb.data.iter().find(|v| **v < T::zero()) {
        return Err(Error::input(
            "image",
            format!("negative colour value {v:?}"),
        ));
    }
    if let Some(m) = matte {
        if let Some(v) = m.data.iter().find(|v| **v < T::zero() || **v > T::one()) {
            return Err(Error::input(
                "alpha matte",
                format!("value {v:?} outside [0, 1]"),
            ));
        }
    }
    Ok(())
}

/// The paper's two-layer recipe (see the module docs), returning notes: an empty matte
/// gives a single opaque layer, and a matte that covers every pixel leaves nothing to fill
/// the background from (the image is used as the background).
pub fn layers_from_matte<T: Real>(
    rgb_encoded: &Image<T>,
    disparity: &Image<T>,
    matte: &Image<T>,
    opts: &LayeringOptions,
) -> Result<Decomposition<T>> {
    opts.validate()?;
    check_inputs(rgb_encoded, disparity, Some(matte))?;
    let (w, h) = (rgb_encoded.width, rgb_encoded.height);
    let mut notes = Vec::new();
    let fg_known: Vec<bool> = matte
        .data
        .iter()
        .map(|a| a.f64() >= FOREGROUND_THRESHOLD)
        .collect();
    if !fg_known.iter().any(|k| *k) {
        notes.push(format!(
            "the alpha matte has no value >= {FOREGROUND_THRESHOLD}: rendering a single opaque layer"
        ));
        return Ok(Decomposition {
            stack: LayerStack::single(rgb_encoded.clone(), disparity.clone())?,
            thresholds: vec![],
            notes,
        });
    }
    // Background is known where no matte value > 0 lies within the dilation radius.
    let any_matte: Vec<bool> = matte.data.iter().map(|a| a.f64() > 0.0).collect();
    let under = dilate(&any_matte, w, h, BACKGROUND_DILATION_PX);
    let bg_known: Vec<bool> = under.iter().map(|u| !u).collect();
    let (fg_disp, (bg_rgb, bg_disp)) = rayon::join(
        || smooth_fill(disparity, &fg_known),
        || {
            if bg_known.iter().any(|k| *k) {
                let region: Vec<Region> = bg_known
                    .iter()
                    .map(|&k| if k { Region::Known } else { Region::Fill })
                    .collect();
                let mut topts = opts.inpaint;
                topts.max_distance = f64::INFINITY;
                rayon::join(
                    || inpaint_telea(rgb_encoded, &region, &topts).image,
                    || smooth_fill(disparity, &bg_known),
                )
            } else {
                (rgb_encoded.clone(), disparity.clone())
            }
        },
    );
    if !bg_known.iter().any(|k| *k) {
        notes.push(
            "the alpha matte covers the whole image: no visible background to fill from, the background layer is the image itself"
                .to_string(),
        );
    }
    let ones = Image::from_vec(w, h, 1, vec![T::one(); w * h])?;
    Ok(Decomposition {
        stack: LayerStack::new(vec![
            Layer {
                rgb_encoded: rgb_encoded.clone(),
                alpha: matte.clone(),
                disparity: fg_disp,
            },
            Layer {
                rgb_encoded: bg_rgb,
                alpha: ones,
                disparity: bg_disp,
            },
        ])?,
        thresholds: vec![],
        notes,
    })
}

/// Automatic decomposition without a matte (see the module docs): up to
/// `opts.max_layers` layers cut at disparity discontinuities, each layer's occluded part
/// filled in. A map with no discontinuity gives a single opaque layer and a note.
pub fn layers_from_disparity<T: Real>(
    rgb_encoded: &Image<T>,
    disparity: &Image<T>,
    opts: &LayeringOptions,
) -> Result<Decomposition<T>> {
    opts.validate()?;
    check_inputs(rgb_encoded, disparity, None)?;
    let (w, h) = (rgb_encoded.width, rgb_encoded.height);
    let n = w * h;
    // A clipped light seen past a nearer object's edge (between strands, through a fence)
    // is one source at one depth: its mixed edge pixels are cut with the light, not with
    // the nearer object (docs/layering.md). A single-layer result keeps the map as given.
    let lights = crate::highlight::lights_at_farthest_depth(rgb_encoded, disparity);
    let given = disparity;
    let disparity = lights.as_ref().unwrap_or(given);
    let disp32: Vec<f32> = disparity.data.iter().map(|v| v.f64() as f32).collect();
    let (lo, hi) = disp32
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let jump = (opts.jump_fraction * (hi - lo) as f64) as f32;
    let min_area = ((opts.min_layer_fraction * n as f64).ceil() as u64).max(4);
    let min_edges = ((w + h) as u64 / 100).max(3);
    let mut cuts = cuts::find_cuts(&disp32, w, h, opts.max_layers, jump, min_edges, min_area);
    let mut dropped = 0;
    if let Some((focus, blur)) = opts.focus_hint {
        let before = cuts.layers;
        cuts = cuts::keep_blur_relevant(cuts, &disp32, w, h, jump, |near, far| {
            blur * ((near as f64 - focus).abs() - (far as f64 - focus).abs())
                >= opts.min_blur_gain_px
        });
        dropped = before - cuts.layers;
    }
    if cuts.layers < 2 {
        let why = if opts.max_layers == 1 {
            "at most one layer was asked for (max_layers = 1)".to_string()
        } else if dropped > 0 {
            let by = if opts.min_blur_gain_px > 0.0 {
                format!("{} px more than", opts.min_blur_gain_px)
            } else {
                "as much as".to_string()
            };
            format!("at this focus and blur, no depth edge has its nearer side blurred at least {by} the farther one (layers would not change the render)")
        } else if hi - lo <= 0.0 {
            "the disparity map is constant".to_string()
        } else {
            format!(
                "no disparity discontinuity (a neighbour step > {:.3}, {} % of the disparity range) separates the image into layers",
                jump,
                opts.jump_fraction * 100.0
            )
        };
        return Ok(Decomposition {
            stack: LayerStack::single(rgb_encoded.clone(), given.clone())?,
            thresholds: vec![],
            notes: vec![format!("{why}: using a single opaque layer")],
        });
    }
    let band = opts
        .occlusion_band_px
        .unwrap_or_else(|| (0.05 * w.max(h) as f64).max(16.0));
    let mut layers = (0..cuts.layers)
        .into_par_iter()
        .map(|k| build_layer(k, &cuts, rgb_encoded, disparity, opts, band))
        .collect::<Vec<_>>();
    if opts.matting_px > 0 {
        for k in 0..cuts.layers - 1 {
            matte_edges(k, &cuts.labels, rgb_encoded, &mut layers, opts);
        }
    }
    let stack = LayerStack::new(layers)?;
    Ok(Decomposition {
        stack,
        thresholds: cuts.thresholds,
        notes: vec![],
    })
}

/// Layer `k` of a decomposition (see the module docs).
fn build_layer<T: Real>(
    k: usize,
    cuts: &cuts::Cuts,
    rgb: &Image<T>,
    disparity: &Image<T>,
    opts: &LayeringOptions,
    band: f64,
) -> Layer<T> {
    let (w, h) = (rgb.width, rgb.height);
    let last = k + 1 == cuts.layers;
    let own: Vec<bool> = cuts.labels.iter().map(|&l| l as usize == k).collect();
    let nearer: Vec<bool> = cuts.labels.iter().map(|&l| (l as usize) < k).collect();
    let near_zone = dilate(&nearer, w, h, opts.colour_guard_px);
    let other: Vec<bool> = own.iter().map(|o| !o).collect();
    let edge_zone = dilate(&other, w, h, opts.disparity_guard_px);
    // Colour sources: own pixels away from nearer layers (edge pixels mix both colours).
    let mut source: Vec<bool> = own.iter().zip(&near_zone).map(|(&o, &z)| o && !z).collect();
    if !source.iter().any(|s| *s) {
        source = own.clone(); // a thin layer: all of it is edge
    }
    // Disparity sources: own pixels away from every other layer (edge disparities are
    // often a blend of both sides).
    let mut disp_source: Vec<bool> = own.iter().zip(&edge_zone).map(|(&o, &z)| o && !z).collect();
    if !disp_source.iter().any(|s| *s) {
        disp_source = source.clone();
    }
    // (Beyond its cut edges the layer keeps the image's colour under the feathered alpha:
    // the edge pixels' own mix. Measured on the ray-traced benchmark, continuing the
    // layer's colour there instead scored lower.)
    let (colour, filled, disp) = {
        let region: Vec<Region> = (0..w * h)
            .map(|i| {
                if source[i] {
                    Region::Known
                } else if own[i] || nearer[i] {
                    Region::Fill
                } else {
                    Region::Skip
                }
            })
            .collect();
        let mut topts = opts.inpaint;
        // Distances run from the fill sources, `colour_guard_px` inside the layer's edge.
        topts.max_distance = if last {
            f64::INFINITY
        } else {
            band + opts.colour_guard_px as f64
        };
        let (painted, disp) = rayon::join(
            || inpaint_telea(rgb, &region, &topts),
            || smooth_fill(disparity, &disp_source),
        );
        let mut colour = painted.image;
        // Own pixels keep the image's colour (the guard zone was only excluded as a source).
        for i in 0..w * h {
            if own[i] {
                for c in 0..3 {
                    colour.data[i * 3 + c] = rgb.data[i * 3 + c];
                }
            }
        }
        let filled: Vec<bool> = painted
            .filled
            .iter()
            .zip(&nearer)
            .map(|(&f, &n)| f && n)
            .collect();
        (colour, filled, disp)
    };
    let mut disp = disp;
    for i in 0..w * h {
        if own[i] {
            disp.data[i] = disparity.data[i];
        }
    }
    let alpha = if last {
        Image::from_vec(w, h, 1, vec![T::one(); w * h]).expect("shape")
    } else {
        let mut hard: Vec<f32> = own
            .iter()
            .zip(&filled)
            .map(|(&o, &f)| if o || f { 1.0 } else { 0.0 })
            .collect();
        if opts.band_alpha_fill && filled.iter().any(|f| *f) {
            // Coverage behind the nearer layers continues the layer's own density.
            let cover = Image::from_vec(
                w,
                h,
                1,
                own.iter().map(|&o| if o { 1.0f32 } else { 0.0 }).collect(),
            )
            .expect("shape");
            let known: Vec<bool> = nearer.iter().map(|n| !n).collect();
            let cover = smooth_fill(&cover, &known);
            for i in 0..w * h {
                if filled[i] {
                    hard[i] = cover.data[i].clamp(0.0, 1.0);
                }
            }
        }
        // Feathered outward only: the layer's own pixels stay opaque (an in-focus render
        // reproduces the image), the pixels just beyond its cut edges get partial alpha.
        let mut soft = box_blur(&hard, w, h, opts.feather_px);
        // A clipped pixel beyond the cut edge is a light of the farther surface, not a mix
        // of the two: feathered into this layer, its light would spread with this layer's
        // blur (a ring around a light seen sharp between strands or through a fence).
        for (i, a) in soft.iter_mut().enumerate() {
            if hard[i] == 0.0 && is_clipped(rgb, i) {
                *a = 0.0;
            }
        }
        Image::from_vec(
            w,
            h,
            1,
            soft.iter()
                .zip(&hard)
                .map(|(&a, &h)| T::c(a.max(h).clamp(0.0, 1.0) as f64))
                .collect(),
        )
        .expect("shape")
    };
    Layer {
        rgb_encoded: colour,
        alpha,
        disparity: disp,
    }
}

/// Whether pixel `i` of a display-encoded image has a clipped channel
/// ([`crate::highlight::CLIPPED_LEVEL`]; recovered highlights lie above it).
fn is_clipped<T: Real>(rgb: &Image<T>, i: usize) -> bool {
    rgb.data[3 * i..3 * i + 3]
        .iter()
        .any(|v| v.f64() >= crate::highlight::CLIPPED_LEVEL)
}

/// Below this squared distance between the two colour models (encoded RGB), the alpha
/// of an edge pixel is not estimated (the colours cannot tell the layers apart).
const MATTING_MIN_CONTRAST2: f64 = 0.01;

/// Soft alpha at the cut edges of layer `k` from local colour models. Within
/// `opts.matting_px` of the boundary between layer `k` and the farther layers, F (the
/// layer's colour, filled outward from its pixels away from the edge) and B (the colour
/// behind, filled inward from the farther pixels away from the edge) are estimated, and
/// each edge pixel's alpha is the projection of its colour on the segment from B to F.
/// The layer's colour there is the image un-premultiplied by alpha and B (or F); the
/// farther layer that shows at the pixel gets the colour behind (the image with the
/// nearer part removed, or B), so an in-focus render still composites to the image.
fn matte_edges<T: Real>(
    k: usize,
    labels: &[u8],
    rgb: &Image<T>,
    layers: &mut [Layer<T>],
    opts: &LayeringOptions,
) {
    let (w, h) = (rgb.width, rgb.height);
    let n = w * h;
    let m = opts.matting_px;
    let own: Vec<bool> = labels.iter().map(|&l| l as usize == k).collect();
    let far: Vec<bool> = labels.iter().map(|&l| l as usize > k).collect();
    let own_or_near: Vec<bool> = labels.iter().map(|&l| l as usize <= k).collect();
    let near_far = dilate(&far, w, h, m);
    let near_own = dilate(&own, w, h, m);
    let near_front = dilate(&own_or_near, w, h, m);
    let zone: Vec<bool> = (0..n)
        .map(|i| (own[i] && near_far[i]) || (far[i] && near_own[i]))
        .collect();
    if !zone.iter().any(|z| *z) {
        return;
    }
    // Known where the side's own pixels lie away from the other side; filled in the zone.
    let regions = |known: &dyn Fn(usize) -> bool| -> Vec<Region> {
        (0..n)
            .map(|i| {
                if known(i) {
                    Region::Known
                } else if zone[i] {
                    Region::Fill
                } else {
                    Region::Skip
                }
            })
            .collect()
    };
    let region_f = regions(&|i| own[i] && !near_far[i]);
    let region_b = regions(&|i| far[i] && !near_front[i]);
    let mut topts = opts.inpaint;
    topts.max_distance = 2.0 * m as f64 + 2.0;
    let (fo, bo) = rayon::join(
        || inpaint_telea(rgb, &region_f, &topts),
        || inpaint_telea(rgb, &region_b, &topts),
    );
    let valid = |r: &[Region], o: &Inpainted<T>, i: usize| r[i] == Region::Known || o.filled[i];
    for i in 0..n {
        if !zone[i] || !valid(&region_f, &fo, i) || !valid(&region_b, &bo, i) {
            continue;
        }
        let px = |img: &Image<T>| -> [f64; 3] {
            [
                img.data[i * 3].f64(),
                img.data[i * 3 + 1].f64(),
                img.data[i * 3 + 2].f64(),
            ]
        };
        let (c, f, b) = (px(rgb), px(&fo.image), px(&bo.image));
        let mut num = 0.0;
        let mut den = 0.0;
        for j in 0..3 {
            num += (c[j] - b[j]) * (f[j] - b[j]);
            den += (f[j] - b[j]) * (f[j] - b[j]);
        }
        if den < MATTING_MIN_CONTRAST2 {
            continue;
        }
        let a = (num / den).clamp(0.0, 1.0);
        let front = if opts.matting_unpremultiply && a > 0.5 {
            std::array::from_fn::<f64, 3, _>(|j| ((c[j] - (1.0 - a) * b[j]) / a).clamp(0.0, 1.0))
        } else {
            f
        };
        let back = if a < 0.5 {
            std::array::from_fn::<f64, 3, _>(|j| ((c[j] - a * f[j]) / (1.0 - a)).clamp(0.0, 1.0))
        } else {
            b
        };
        let lk = &mut layers[k];
        lk.alpha.data[i] = T::c(a);
        for j in 0..3 {
            lk.rgb_encoded.data[i * 3 + j] = T::c(front[j]);
        }
        // The farther layer that shows here: the pixel's own, or (for an own pixel of
        // layer k) the first farther layer that is opaque here.
        let start = if own[i] { k + 1 } else { labels[i] as usize };
        let last = layers.len() - 1;
        let target = (start..last)
            .find(|&j| layers[j].alpha.data[i].f64() >= 0.5)
            .unwrap_or(last);
        for j in 0..3 {
            layers[target].rgb_encoded.data[i * 3 + j] = T::c(back[j]);
        }
    }
}

/// Mean over a (2r+1)^2 box clipped to the image (normalised by the pixels inside).
fn box_blur(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    if r == 0 {
        return v.to_vec();
    }
    let mut rows = vec![0f32; w * h];
    rows.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r).min(w - 1));
            let s: f32 = v[y * w + a..=y * w + b].iter().sum();
            row[x] = s / (b - a + 1) as f32;
        }
    });
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        for x in 0..w {
            let s: f32 = (a..=b).map(|yy| rows[yy * w + x]).sum();
            row[x] = s / (b - a + 1) as f32;
        }
    });
    out
}

/// Square dilation of a mask by `radius` pixels.
fn dilate(mask: &[bool], w: usize, h: usize, radius: usize) -> Vec<bool> {
    if radius == 0 {
        return mask.to_vec();
    }
    let r = radius;
    let mut rows = vec![false; w * h];
    rows.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let src = &mask[y * w..(y + 1) * w];
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r).min(w - 1));
            row[x] = src[a..=b].iter().any(|m| *m);
        }
    });
    let mut out = vec![false; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        for x in 0..w {
            row[x] = (a..=b).any(|yy| rows[yy * w + x]);
        }
    });
    out
}
