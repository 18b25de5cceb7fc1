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
use crate::model::Tone;
use crate::{Error, Real, Result};

mod depth;
pub use depth::{
    lights_at_farthest_depth, LIGHT_REGION_LEVEL, MAX_LIGHT_POINT_AREAS, MIN_FARTHEST_SHARE,
    SAME_DEPTH_FRACTION,
};

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
    /// ([`HighlightEstimate`]), then the paper's boost: the default
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

    /// Whether the paper's boost (docs/model.md, M20) is on for a photo.
    pub fn paper_boost(&self) -> bool {
        match self {
            PhotoHighlights::PaperBoost => true,
            PhotoHighlights::Estimate(e) => e.paper,
            PhotoHighlights::Off | PhotoHighlights::Recover(_) => false,
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
        recover_regions(
            rgb_encoded,
            disparity,
            focus_disparity,
            blur_k,
            tone,
            self.threshold,
            &Profile::FLAT,
            &mut out,
            |region, _value| {
                let weight = (a_point / region.len() as f64).min(1.0);
                (1.0 + (gain - 1.0) * weight, None)
            },
        );
        Ok(out)
    }
}

/// Per-region gain and tint estimated from the region's rim: `--highlight auto` (the
/// default for photos; `auto:KEY=VALUE,...` to change its constants).
///
/// A clipped blob's edge falls from white to the background over the camera's edge
/// spread; the brighter the source, the narrower the unclipped part of that fall (for a
/// linear ramp of one pixel and a source `g` times white, the unclipped rim holds
/// `1 / (2 g)` of light per unit of edge length). So with `x` the region's rim cue, the
/// region's gain is `g = clamp(K / x, 1, GMAX)`. The default cue (`ring_cue`) is the rim's
/// light (its unclipped pixels 8-touching a clipped one, linear) above the local
/// background, the per-channel median of the next ring out (2 px from the clipped
/// pixels), per rim pixel; the older cue is that light above the median of the ring
/// 3-4 px out, per clipped edge pixel. The rim's colour above the background is the
/// source's tint (it is not clipped there), each rim pixel weighted by its light
/// (`tint_weighted`): clipped pixels get `g` times that tint (normalised to its largest
/// channel; blended towards white where the rim holds little light), never less than the
/// photo shows. Profile: interior clipped pixels get `g`; clipped pixels on the region's
/// edge are only partly covered by the source and get `g^p` (`edge_power`; or the share
/// `edge` of `g - 1`). Channels that did not clip keep their value (`keep`), and so do the
/// region's bright unclipped pixels (`rim_ramp` 0; else they ramp in as in
/// [`HighlightRecovery`]). The defocus gate applies. With `paper`, the paper's boost
/// (docs/model.md, M20) is applied on top in the model, as for `paper`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HighlightEstimate {
    /// Rim constant `K` (> 0).
    pub rim_k: f64,
    /// Largest gain `GMAX` (>= 1).
    pub max_gain: f64,
    /// Display-encoded threshold of the region (as [`HighlightRecovery::threshold`]).
    pub threshold: f64,
    /// Whether clipped pixels take the rim's tint (else white).
    pub tint: bool,
    /// Share of the gain `g - 1` that the region's clipped edge pixels (a 4-neighbour not
    /// clipped) get, in [0, 1]: they are partly covered by the source.
    pub edge: f64,
    /// Whether the paper's boost (docs/model.md, M20) is applied on top, in the model.
    pub paper: bool,
    /// Rim light (linear, per clipped edge pixel) that weighs as much as white in the
    /// tint: the tint fades to white where the rim holds less light than this.
    pub white_rim: f64,
    /// Whether the unclipped channels of clipped pixels keep their value (they are what
    /// the scene showed; a tinted source often clips in one channel only).
    pub keep: bool,
    /// Share of the ramp `s(t)` that the region's bright *unclipped* pixels get, in [0, 1]
    /// (0: they keep their value).
    pub rim_ramp: f64,
    /// With `Some(p)`, clipped edge pixels get the gain `g^p` (the profile of a source
    /// partly covering them) instead of the share `edge` of `g - 1`.
    pub edge_power: Option<f64>,
    /// Whether the rim cue `x` is the rim's light per rim pixel above the median of the
    /// next ring out (the ring cue), else per clipped edge pixel above the 3-4 px ring.
    pub ring_cue: bool,
    /// Whether the tint weighs each rim pixel by its light above the next ring.
    pub tint_weighted: bool,
}

impl HighlightEstimate {
    /// The defaults of `auto` (and of photos), chosen on the tuning benchmarks of
    /// docs/highlights.md (seeds 101 and 102, highlights 2-10 and 5-50).
    pub const DEFAULT: HighlightEstimate = HighlightEstimate {
        rim_k: 0.2,
        max_gain: 3.5,
        threshold: 0.9,
        tint: true,
        edge: 0.25,
        paper: true,
        white_rim: 0.01,
        keep: true,
        rim_ramp: 0.0,
        edge_power: Some(0.65),
        ring_cue: true,
        tint_weighted: true,
    };

    /// Parses `auto` or `auto:KEY=VALUE,...` with keys `k` (rim constant), `max` (largest
    /// gain), `t` (threshold), `edgep` (power of the gain on the clipped edge pixels),
    /// `edge` (share of `g - 1` on them instead), `white`, `tint`, `paper`, `keep`, `cue`,
    /// `tintw` (0 or 1) and `rim` (share of the ramp on bright unclipped pixels).
    pub fn parse(spec: &str) -> Result<Self> {
        let bad = || {
            Error::param(
                "highlight",
                format!(
                    "expected auto or auto:KEY=VALUE,... (keys k, max, t, edgep, edge, white, tint, paper, keep, cue, tintw, rim; e.g. auto:k=0.3,max=8), got '{spec}'"
                ),
            )
        };
        let rest = match spec.trim().strip_prefix("auto") {
            Some("") => "",
            Some(r) => r.strip_prefix(':').ok_or_else(bad)?,
            None => return Err(bad()),
        };
        let mut e = Self::DEFAULT;
        for kv in rest.split(',').filter(|s| !s.trim().is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(bad)?;
            let v: f64 = v.trim().parse().map_err(|_| bad())?;
            match k.trim() {
                "k" => e.rim_k = v,
                "max" => e.max_gain = v,
                "t" => e.threshold = v,
                "edge" => {
                    e.edge = v;
                    e.edge_power = None;
                }
                "white" if v >= 0.0 && v.is_finite() => e.white_rim = v,
                "tint" if v == 0.0 || v == 1.0 => e.tint = v == 1.0,
                "paper" if v == 0.0 || v == 1.0 => e.paper = v == 1.0,
                "keep" if v == 0.0 || v == 1.0 => e.keep = v == 1.0,
                "rim" => e.rim_ramp = v,
                "tintw" if v == 0.0 || v == 1.0 => e.tint_weighted = v == 1.0,
                "cue" if v == 0.0 || v == 1.0 => e.ring_cue = v == 1.0,
                "edgep" if (0.0..=1.0).contains(&v) => e.edge_power = Some(v),
                _ => return Err(bad()),
            }
        }
        e.validate()?;
        Ok(e)
    }

    /// Checks `K > 0`, `1 <= GMAX <= 1000`, `0 < THRESHOLD < 1`.
    pub fn validate(&self) -> Result<()> {
        if !(self.rim_k.is_finite() && self.rim_k > 0.0 && self.rim_k <= 1000.0) {
            return Err(Error::param(
                "highlight",
                format!("the rim constant must be in (0, 1000], got {}", self.rim_k),
            ));
        }
        for (name, v) in [
            ("edge", self.edge),
            ("rim", self.rim_ramp),
            ("edgep", self.edge_power.unwrap_or(0.0)),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(Error::param(
                    "highlight",
                    format!("the {name} share must be in [0, 1], got {v}"),
                ));
            }
        }
        HighlightRecovery {
            gain: self.max_gain,
            threshold: self.threshold,
        }
        .validate()
    }

    /// As [`HighlightRecovery::apply`], with each region's gain and tint estimated from
    /// its rim.
    pub fn apply<T: Real>(
        &self,
        rgb_encoded: &Image<T>,
        disparity: &Image<T>,
        focus_disparity: f64,
        blur_k: f64,
        tone: &Tone,
    ) -> Result<Image<T>> {
        self.apply_with(
            rgb_encoded,
            disparity,
            focus_disparity,
            blur_k,
            tone,
            |_, g, t| (g, t),
        )
    }

    /// For analysis (`examples/highlight_sweep.rs`, its `ogain` oracle): as
    /// [`HighlightEstimate::apply`], with each region's estimated `(gain, tint)` replaced by
    /// `adjust(region's pixel indices, gain, tint)`.
    pub fn apply_with<T: Real>(
        &self,
        rgb_encoded: &Image<T>,
        disparity: &Image<T>,
        focus_disparity: f64,
        blur_k: f64,
        tone: &Tone,
        mut adjust: impl FnMut(&[usize], f64, [f64; 3]) -> (f64, [f64; 3]),
    ) -> Result<Image<T>> {
        self.validate()?;
        check_inputs(rgb_encoded, disparity)?;
        let mut out = rgb_encoded.clone();
        let (w, h) = (rgb_encoded.width, rgb_encoded.height);
        if w == 0 || h == 0 {
            return Ok(out);
        }
        let lin = LinearPhoto {
            encoded: &rgb_encoded.data,
            tone,
        };
        let est = *self;
        let mut mark = vec![0u32; w * h];
        let mut stamp = 1u32;
        recover_regions(
            rgb_encoded,
            disparity,
            focus_disparity,
            blur_k,
            tone,
            self.threshold,
            &Profile {
                edge: self.edge,
                keep: self.keep,
                rim_ramp: self.rim_ramp,
                edge_power: self.edge_power,
            },
            &mut out,
            |region, value| {
                stamp += 5;
                let (g, tint) = est.estimate(region, value, &lin, w, h, &mut mark, stamp);
                let (g, tint) = adjust(region, g, tint);
                (g, Some(tint))
            },
        );
        Ok(out)
    }

    /// (gain, tint) of one region; `mark` is scratch, values `stamp..stamp + 4` unused
    /// before this call.
    #[allow(clippy::too_many_arguments)]
    fn estimate<T: Real>(
        &self,
        region: &[usize],
        value: &[f64],
        lin: &LinearPhoto<'_, T>,
        w: usize,
        h: usize,
        mark: &mut [u32],
        stamp: u32,
    ) -> (f64, [f64; 3]) {
        let (far_m, near_m, clip_m, rim_m, next_m) =
            (stamp, stamp + 1, stamp + 2, stamp + 3, stamp + 4);
        let around = |i: usize, r: usize| {
            let (x, y) = (i % w, i / w);
            let ys = y.saturating_sub(r)..=(y + r).min(h - 1);
            let xs = x.saturating_sub(r)..=(x + r).min(w - 1);
            ys.flat_map(move |ny| xs.clone().map(move |nx| ny * w + nx))
        };
        // Background ring: 3-4 px out.
        for &i in region {
            for j in around(i, 4) {
                mark[j] = far_m;
            }
        }
        for &i in region {
            for j in around(i, 2) {
                mark[j] = near_m;
            }
        }
        let mut ring = Vec::new();
        for &i in region {
            for j in around(i, 4) {
                if mark[j] == far_m {
                    ring.push(j);
                    mark[j] = near_m;
                }
            }
        }
        let mut bg = [0.0; 3];
        for (c, b) in bg.iter_mut().enumerate() {
            let mut v: Vec<f64> = ring.iter().map(|&j| lin.at(3 * j + c)).collect();
            v.sort_by(f64::total_cmp);
            *b = v.get(v.len() / 2).copied().unwrap_or(0.0);
        }
        for &i in region {
            if value[i] >= CLIPPED_LEVEL {
                mark[i] = clip_m;
            }
        }
        let mut edge = 0usize;
        let mut rim = [0.0; 3];
        let mut rim_seen = Vec::new();
        let clipped: Vec<usize> = region
            .iter()
            .copied()
            .filter(|&i| value[i] >= CLIPPED_LEVEL)
            .collect();
        for &i in &clipped {
            let (x, y) = (i % w, i / w);
            let on_edge = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|&(dx, dy)| {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    nx < 0
                        || ny < 0
                        || nx >= w as i64
                        || ny >= h as i64
                        || mark[ny as usize * w + nx as usize] != clip_m
                });
            edge += on_edge as usize;
            for j in around(i, 1) {
                if mark[j] != clip_m && mark[j] != rim_m {
                    rim_seen.push(j);
                    mark[j] = rim_m;
                }
            }
        }
        for &j in &rim_seen {
            for c in 0..3 {
                rim[c] += (lin.at(3 * j + c) - bg[c]).max(0.0);
            }
        }
        let rim_light = (rim[0] + rim[1] + rim[2]) / 3.0;
        // The next ring out (2 px from the clipped pixels): a background estimate closer
        // to the rim than the 3-4 px ring.
        let mut next = Vec::new();
        for &i in &clipped {
            for j in around(i, 2) {
                if mark[j] != clip_m && mark[j] != rim_m && mark[j] != next_m {
                    next.push(j);
                    mark[j] = next_m;
                }
            }
        }
        let mut bg_next = [0.0; 3];
        for (c, b) in bg_next.iter_mut().enumerate() {
            let mut v: Vec<f64> = next.iter().map(|&j| lin.at(3 * j + c)).collect();
            v.sort_by(f64::total_cmp);
            *b = v.get(v.len() / 2).copied().unwrap_or(bg[c]);
        }
        let lift_of = |j: usize, c: usize| (lin.at(3 * j + c) - bg_next[c]).max(0.0);
        let lifts: Vec<f64> = rim_seen
            .iter()
            .map(|&j| (0..3).map(|c| lift_of(j, c)).sum::<f64>() / 3.0)
            .collect();
        let x = if self.ring_cue {
            // The rim's light per rim pixel above the next ring.
            lifts.iter().sum::<f64>() / rim_seen.len().max(1) as f64
        } else {
            rim_light / edge.max(1) as f64
        };
        if self.tint_weighted {
            // Each rim pixel's colour above the next ring, weighted by its lift: the
            // brightest rim pixels carry the source's colour, the rest mostly background.
            let wsum: f64 = lifts.iter().sum();
            if wsum > 0.0 {
                for (c, r) in rim.iter_mut().enumerate() {
                    let m: f64 = rim_seen
                        .iter()
                        .zip(&lifts)
                        .map(|(&j, &wj)| wj * lift_of(j, c))
                        .sum::<f64>()
                        / wsum;
                    *r = m * rim_seen.len() as f64;
                }
            }
        }
        let g = (self.rim_k / x.max(1e-6)).clamp(1.0, self.max_gain);
        let tint = if self.tint {
            // Towards white where the rim holds little light.
            let eps = self.white_rim * edge.max(1) as f64 + 1e-12;
            let m = rim.iter().copied().fold(0.0, f64::max) + eps;
            [(rim[0] + eps) / m, (rim[1] + eps) / m, (rim[2] + eps) / m]
        } else {
            [1.0; 3]
        };
        (g, tint)
    }
}

/// The photo's linear values, computed where they are read: the estimate reads the few
/// pixels around each clipped region, so linearising the whole image up front (one `powf`
/// per value, serial, before the render) was wasted work.
struct LinearPhoto<'a, T> {
    encoded: &'a [T],
    tone: &'a Tone,
}

impl<T: Real> LinearPhoto<'_, T> {
    /// The linear value of interleaved sample `k` (negative encodings read as 0).
    #[inline]
    fn at(&self, k: usize) -> f64 {
        self.tone.linearize(self.encoded[k].f64().max(0.0))
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

/// Finds the clipped regions of `rgb_encoded` (threshold `t0`) and scales each pixel's
/// linear colour by `g` (tint `None`) or towards `g tint` (per channel, never below the
/// photo's), with `(g, tint)` from `gain_of(region, value)`, ramped by `s(t)` and the
/// defocus gate; writes `out`.
#[allow(clippy::too_many_arguments)]
fn recover_regions<T: Real>(
    rgb_encoded: &Image<T>,
    disparity: &Image<T>,
    focus_disparity: f64,
    blur_k: f64,
    tone: &Tone,
    t0: f64,
    profile: &Profile,
    out: &mut Image<T>,
    mut gain_of: impl FnMut(&[usize], &[f64]) -> (f64, Option<[f64; 3]>),
) {
    let (w, h) = (rgb_encoded.width, rgb_encoded.height);
    let value = largest_channel(rgb_encoded);
    for region in clipped_regions(w, h, &value, t0) {
        let (g_region, tint) = gain_of(&region, &value);
        let clipped = |j: usize| value[j] >= CLIPPED_LEVEL;
        let radius_of = |j: usize| blur_k * (disparity.data[j].f64() - focus_disparity).abs();
        let sources = SourceRadii::new(&region, clipped, |j| disparity.data[j].f64(), radius_of);
        for &i in &region {
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
