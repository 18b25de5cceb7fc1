//! Highlight recovery (docs/highlights.md): a photo's light sources and speculars are
//! clipped at white, so a renderer that spreads them into bokeh balls spreads too little
//! light. This estimates, per clipped region, how much brighter the scene was, in linear
//! light, before the photo is decomposed into layers and rendered.
//!
//! The model, for a recovery with gain `G` and threshold `T` (display-encoded, in (0, 1)):
//! 1. A pixel is *bright* where its largest encoded channel `v >= T`; bright pixels that
//!    touch (8-neighbours) form a region.
//! 2. A region with no clipped pixel (`v >= CLIPPED`, [`CLIPPED_LEVEL`]) lost nothing and
//!    keeps its colour.
//! 3. A clipped region of `A` pixels gets the gain `g = 1 + (G - 1) w`, with the size
//!    weight `w = min(1, A_point / A)`: small blobs (point lights, speculars) get the full
//!    gain; a large clipped area (a white wall, the sky) gets the light of one point-sized
//!    blob spread over it, since large bright surfaces are rarely many times brighter than
//!    white. `A_point` is [`point_area_px`] (16 px, or more for large images).
//! 4. Inside the region, each pixel's linear colour is multiplied by
//!    `1 + (g - 1) s(t)`, with `t = (v - T) / (1 - T)` and the smoothstep
//!    `s(t) = t^2 (3 - 2t)`: the full gain on clipped pixels, none at the threshold, so the
//!    region's rim stays continuous with its surroundings. The colour's hue is kept.
//! 5. The gain is faded in with the blur radius `K |disp - f|` ([`defocus_gate`]): none
//!    below 1 px, all from 3 px. An in-focus highlight renders as the photo shows it
//!    (clipped, like the camera's), and its extra light cannot leak into its neighbours.
//!    The radius is the smaller of the pixel's and the region's *source* radius, the least
//!    blurred of its clipped pixels at its depth or farther ([`SourceRadii`]): a clipped source seen in focus
//!    past a blurred foreground's edge gives no gain to the mixed edge pixels that the depth
//!    map puts on the foreground (they would spread its light into a bright ring).
//!
//! The result is display-encoded again with the same transfer and may exceed 1; the
//! renderer linearises it back to the recovered light. Recovery is a fixed preprocessing of
//! the photo: its colour values are not differentiated through it.

use crate::image::Image;
use crate::model::{HighlightBoost, Tone};
use crate::{Error, Real, Result};

mod depth;
mod estimate;
pub use depth::{
    lights_at_farthest_depth, LIGHT_REGION_LEVEL, MAX_LIGHT_POINT_AREAS, MIN_FARTHEST_SHARE,
    SAME_DEPTH_FRACTION,
};
pub use estimate::HighlightEstimate;

/// Encoded level at or above which a channel counts as clipped (254.5/255).
pub const CLIPPED_LEVEL: f64 = 254.5 / 255.0;

/// How a display-encoded photo's highlights are treated ([`crate::scene::View`]); stacks,
/// the demo and linear (EXR) photos are not touched by it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PhotoHighlights {
    /// As the photo shows them.
    Off,
    /// The paper's boost inside the model (docs/model.md, M20; the camera's `highlight`).
    PaperBoost,
    /// Per-region recovery (this module).
    Recover(HighlightRecovery),
    /// Per-region recovery with each region's gain and tint estimated from its rim
    /// ([`HighlightEstimate`]), then the highlight boost with its photo constants
    /// ([`HighlightBoost::PHOTO`]): the default
    /// ([`HighlightEstimate::DEFAULT`]), the best of the settings measured in
    /// docs/highlights.md over both highlight ranges.
    Estimate(HighlightEstimate),
}

impl Default for PhotoHighlights {
    fn default() -> Self {
        PhotoHighlights::Estimate(HighlightEstimate::DEFAULT)
    }
}

impl PhotoHighlights {
    /// Parses `off`, `paper`, or `GAIN[:THRESHOLD]` ([`HighlightRecovery::parse`]).
    pub fn parse(spec: &str) -> Result<Self> {
        Ok(match spec.trim() {
            "off" => PhotoHighlights::Off,
            "paper" => PhotoHighlights::PaperBoost,
            s if s == "auto" || s.starts_with("auto:") => {
                PhotoHighlights::Estimate(HighlightEstimate::parse(s)?)
            }
            s => PhotoHighlights::Recover(HighlightRecovery::parse(s)?),
        })
    }

    /// The highlight boost (docs/model.md, M20) in the model for a photo, if any: the
    /// paper's for `paper`, the estimate's own (by default [`HighlightBoost::PHOTO`]) for
    /// `auto`.
    pub fn boost(&self) -> Option<HighlightBoost> {
        match self {
            PhotoHighlights::PaperBoost => Some(HighlightBoost::PAPER),
            PhotoHighlights::Estimate(e) => e.boost,
            PhotoHighlights::Off | PhotoHighlights::Recover(_) => None,
        }
    }
}

/// Highlight recovery parameters (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HighlightRecovery {
    /// Linear gain `G` of a point-sized clipped blob (>= 1; 1 changes nothing).
    pub gain: f64,
    /// Display-encoded threshold `T` in (0, 1) at which the gain starts to ramp in.
    pub threshold: f64,
}

impl HighlightRecovery {
    /// The best recovery measured on the tuning benchmarks of docs/highlights.md: gain 2,
    /// threshold 0.95 (the threshold of `GAIN` without one).
    pub const DEFAULT: HighlightRecovery = HighlightRecovery {
        gain: 2.0,
        threshold: 0.95,
    };

    /// Checks `1 <= gain <= 1000` and `0 < threshold < 1`; messages name `highlight`.
    pub fn validate(&self) -> Result<()> {
        if !(self.gain.is_finite() && (1.0..=1000.0).contains(&self.gain)) {
            return Err(Error::param(
                "highlight",
                format!("gain must be in [1, 1000], got {}", self.gain),
            ));
        }
        if !(self.threshold.is_finite() && self.threshold > 0.0 && self.threshold < 1.0) {
            return Err(Error::param(
                "highlight",
                format!("threshold must be in (0, 1), got {}", self.threshold),
            ));
        }
        Ok(())
    }

    /// Parses `GAIN[:THRESHOLD]` (threshold default [`HighlightRecovery::DEFAULT`]'s).
    pub fn parse(spec: &str) -> Result<Self> {
        let bad = || {
            Error::param(
                "highlight",
                format!("expected GAIN[:THRESHOLD] (e.g. 2 or 2:0.95), got '{spec}'"),
            )
        };
        let (g, t) = match spec.split_once(':') {
            Some((g, t)) => (g, Some(t)),
            None => (spec, None),
        };
        let gain: f64 = g.trim().parse().map_err(|_| bad())?;
        let threshold = match t {
            Some(t) => t.trim().parse().map_err(|_| bad())?,
            None => Self::DEFAULT.threshold,
        };
        let r = HighlightRecovery { gain, threshold };
        r.validate()?;
        Ok(r)
    }

    /// The photo `rgb_encoded` (3 channels, display-encoded with `tone`) with its clipped
    /// highlights recovered where they will be defocused (blur radius `K |disp - focus|`
    /// from `disparity`); values may exceed 1.
    pub fn apply<T: Real>(
        &self,
        rgb_encoded: &Image<T>,
        disparity: &Image<T>,
        focus_disparity: f64,
        blur_k: f64,
        tone: &Tone,
    ) -> Result<Image<T>> {
        self.validate()?;
        check_inputs(rgb_encoded, disparity)?;
        let mut out = rgb_encoded.clone();
        let (w, h) = (rgb_encoded.width, rgb_encoded.height);
        if self.gain == 1.0 || w == 0 || h == 0 {
            return Ok(out);
        }
        let a_point = point_area_px(w, h);
        let gain = self.gain;
        let value = largest_channel(rgb_encoded);
        let regions = clipped_regions(w, h, &value, self.threshold);
        recover_regions(
            rgb_encoded,
            &value,
            &regions,
            disparity,
            focus_disparity,
            blur_k,
            tone,
            self.threshold,
            &Profile::FLAT,
            &mut out,
            |_, region| {
                let weight = (a_point / region.len() as f64).min(1.0);
                (1.0 + (gain - 1.0) * weight, None)
            },
        );
        Ok(out)
    }
}

fn check_inputs<T: Real>(rgb_encoded: &Image<T>, disparity: &Image<T>) -> Result<()> {
    if (disparity.width, disparity.height) != (rgb_encoded.width, rgb_encoded.height) {
        return Err(Error::param(
            "highlight",
            "the disparity map and the image differ in size",
        ));
    }
    if rgb_encoded.channels != 3 {
        return Err(Error::param(
            "highlight",
            format!(
                "highlight recovery needs a 3-channel image, got {}",
                rgb_encoded.channels
            ),
        ));
    }
    Ok(())
}

/// The 8-connected regions of the `w` x `h` pixels for which `inside(index)` holds, each
/// as its pixel indices (row-major), in the order of their first pixel; each region's
/// pixels in flood order from that pixel (a fixed order, so sums over a region are
/// deterministic).
pub fn regions(w: usize, h: usize, inside: impl Fn(usize) -> bool) -> Vec<Vec<usize>> {
    let mut seen = vec![false; w * h];
    let mut stack = Vec::new();
    let mut out = Vec::new();
    for start in 0..w * h {
        if seen[start] || !inside(start) {
            continue;
        }
        let mut region = Vec::new();
        seen[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            region.push(i);
            let (x, y) = (i % w, i / w);
            for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    let j = ny * w + nx;
                    if !seen[j] && inside(j) {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        out.push(region);
    }
    out
}

/// Each pixel's largest channel (display-encoded), the value the regions are cut by.
pub(crate) fn largest_channel<T: Real>(rgb_encoded: &Image<T>) -> Vec<f64> {
    rgb_encoded
        .data
        .chunks_exact(3)
        .map(|p| p.iter().map(|v| v.f64()).fold(f64::NEG_INFINITY, f64::max))
        .collect()
}

/// The [`regions`] of pixels whose `value` is at least `t0` that hold a clipped pixel
/// ([`CLIPPED_LEVEL`]): the lights and speculars that lost light.
pub(crate) fn clipped_regions(w: usize, h: usize, value: &[f64], t0: f64) -> Vec<Vec<usize>> {
    let mut out = regions(w, h, |i| value[i] >= t0);
    out.retain(|region| region.iter().any(|&i| value[i] >= CLIPPED_LEVEL));
    out
}

/// Scales each pixel of the clipped `regions` of `rgb_encoded` (from [`clipped_regions`]
/// at threshold `t0` over `value`, its [`largest_channel`]) in linear light by `g` (tint
/// `None`) or towards `g tint` (per channel, never below the photo's), with `(g, tint)`
/// from `gain_of(index of the region, region)`, ramped by `s(t)` and the defocus gate;
/// writes `out`.
#[allow(clippy::too_many_arguments)]
fn recover_regions<T: Real>(
    rgb_encoded: &Image<T>,
    value: &[f64],
    regions: &[Vec<usize>],
    disparity: &Image<T>,
    focus_disparity: f64,
    blur_k: f64,
    tone: &Tone,
    t0: f64,
    profile: &Profile,
    out: &mut Image<T>,
    mut gain_of: impl FnMut(usize, &[usize]) -> (f64, Option<[f64; 3]>),
) {
    let (w, h) = (rgb_encoded.width, rgb_encoded.height);
    for (n, region) in regions.iter().enumerate() {
        let (g_region, tint) = gain_of(n, region);
        let clipped = |j: usize| value[j] >= CLIPPED_LEVEL;
        let radius_of = |j: usize| blur_k * (disparity.data[j].f64() - focus_disparity).abs();
        let sources = SourceRadii::new(region, clipped, |j| disparity.data[j].f64(), radius_of);
        for &i in region {
            let (x, y) = (i % w, i / w);
            let on_edge = clipped(i)
                && (x == 0
                    || y == 0
                    || x + 1 == w
                    || y + 1 == h
                    || !clipped(i - 1)
                    || !clipped(i + 1)
                    || !clipped(i - w)
                    || !clipped(i + w));
            // Profile: interior clipped pixels the full gain, edge pixels a part of it.
            let g = match (on_edge, profile.edge_power) {
                (true, Some(p)) => g_region.powf(p),
                (true, None) => 1.0 + (g_region - 1.0) * profile.edge,
                (false, _) => g_region,
            };
            let t = ((value[i] - t0) / (1.0 - t0)).clamp(0.0, 1.0);
            let radius_px = radius_of(i).min(sources.behind(disparity.data[i].f64()));
            let mut ramp = smoothstep(t) * defocus_gate(radius_px);
            if !clipped(i) {
                ramp *= profile.rim_ramp;
            }
            for (c, v) in out.data[3 * i..3 * i + 3].iter_mut().enumerate() {
                if profile.keep && clipped(i) && v.f64() < CLIPPED_LEVEL {
                    // An unclipped channel of a clipped pixel is what the scene showed.
                    continue;
                }
                let lin = tone.linearize(v.f64().max(0.0));
                let new = match tint {
                    // The gain on every channel: the hue is kept.
                    None => lin * (1.0 + (g - 1.0) * ramp),
                    // Towards `g tint`, never below the photo.
                    Some(tint) => lin + ((g * tint[c]).max(lin) - lin) * ramp,
                };
                *v = T::c(tone.encode(new).max(0.0));
            }
        }
    }
}

/// The blur radii of a clipped region's light sources by depth: a pixel of the region
/// carries light from its own surface or from a source behind it, so its *source radius*
/// is the smallest blur radius of the region's clipped pixels at its disparity or farther
/// ([`SourceRadii::behind`]). A mixed edge pixel that the depth map puts on a blurred
/// foreground, around a light in focus behind it, gets the light's (small) radius; a light
/// behind an in-focus wire keeps its own.
pub struct SourceRadii {
    /// `(disparity, smallest radius of the clipped pixels at this disparity or farther)`,
    /// by increasing disparity (farthest first).
    by_disparity: Vec<(f64, f64)>,
}

impl SourceRadii {
    /// From the region's pixels, which of them are clipped, and each pixel's disparity and
    /// blur radius (px).
    pub fn new(
        region: &[usize],
        clipped: impl Fn(usize) -> bool,
        disparity_of: impl Fn(usize) -> f64,
        radius_of: impl Fn(usize) -> f64,
    ) -> Self {
        let mut by_disparity: Vec<(f64, f64)> = region
            .iter()
            .filter(|&&j| clipped(j))
            .map(|&j| (disparity_of(j), radius_of(j)))
            .collect();
        by_disparity.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut least = f64::INFINITY;
        for e in &mut by_disparity {
            least = least.min(e.1);
            e.1 = least;
        }
        SourceRadii { by_disparity }
    }

    /// The smallest radius of the clipped pixels at `disparity` or farther (smaller
    /// disparity); infinite when there is none.
    pub fn behind(&self, disparity: f64) -> f64 {
        let n = self.by_disparity.partition_point(|e| e.0 <= disparity);
        if n == 0 {
            f64::INFINITY
        } else {
            self.by_disparity[n - 1].1
        }
    }
}

/// How a region's gain is spread over its pixels ([`recover_regions`]).
struct Profile {
    /// Share of `g - 1` on clipped pixels with an unclipped 4-neighbour.
    edge: f64,
    /// Unclipped channels of clipped pixels keep their value.
    keep: bool,
    /// Scale of the ramp on the region's unclipped (bright) pixels.
    rim_ramp: f64,
    /// With `Some(p)`, clipped edge pixels get the gain `g^p` instead of the share `edge`.
    edge_power: Option<f64>,
}

impl Profile {
    /// The gain on every pixel of the region.
    const FLAT: Profile = Profile {
        edge: 1.0,
        keep: false,
        rim_ramp: 1.0,
        edge_power: None,
    };
}

/// `s(t) = t^2 (3 - 2t)` for `t` in [0, 1].
fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// How much of the gain a pixel of blur radius `radius_px` gets: none at or below
/// [`GATE_START_PX`], all from [`GATE_FULL_PX`] (smoothstep between). An in-focus
/// highlight renders as the photo shows it, clipped.
pub fn defocus_gate(radius_px: f64) -> f64 {
    smoothstep((radius_px - GATE_START_PX) / (GATE_FULL_PX - GATE_START_PX))
}

/// Blur radius (px) below which a highlight keeps its photo's colour.
pub const GATE_START_PX: f64 = 1.0;
/// Blur radius (px) from which a highlight gets its region's full gain.
pub const GATE_FULL_PX: f64 = 3.0;

/// The area of a point-sized blob for a `width x height` image: 16 px, or 1/4096 of the
/// image when that is larger.
pub fn point_area_px(width: usize, height: usize) -> f64 {
    (width as f64 * height as f64 / 4096.0).max(16.0)
}

#[cfg(test)]
mod tests;
