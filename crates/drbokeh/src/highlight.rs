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
        self.validate()?;
        check_inputs(rgb_encoded, disparity)?;
        let mut out = rgb_encoded.clone();
        let (w, h) = (rgb_encoded.width, rgb_encoded.height);
        if w == 0 || h == 0 {
            return Ok(out);
        }
        let lin: Vec<f64> = rgb_encoded
            .data
            .iter()
            .map(|v| tone.linearize(v.f64().max(0.0)))
            .collect();
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
                (g, Some(tint))
            },
        );
        Ok(out)
    }

    /// (gain, tint) of one region; `mark` is scratch, values `stamp..stamp + 4` unused
    /// before this call.
    #[allow(clippy::too_many_arguments)]
    fn estimate(
        &self,
        region: &[usize],
        value: &[f64],
        lin: &[f64],
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
            let mut v: Vec<f64> = ring.iter().map(|&j| lin[3 * j + c]).collect();
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
                rim[c] += (lin[3 * j + c] - bg[c]).max(0.0);
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
            let mut v: Vec<f64> = next.iter().map(|&j| lin[3 * j + c]).collect();
            v.sort_by(f64::total_cmp);
            *b = v.get(v.len() / 2).copied().unwrap_or(bg[c]);
        }
        let lift_of = |j: usize, c: usize| (lin[3 * j + c] - bg_next[c]).max(0.0);
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
    let value: Vec<f64> = rgb_encoded
        .data
        .chunks_exact(3)
        .map(|p| p.iter().map(|v| v.f64()).fold(f64::NEG_INFINITY, f64::max))
        .collect();
    for region in regions(w, h, |i| value[i] >= t0) {
        if !region.iter().any(|&i| value[i] >= CLIPPED_LEVEL) {
            continue;
        }
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
mod tests {
    use super::*;

    #[test]
    fn regions_are_8_connected_in_first_pixel_order() {
        // 4 x 3:  # . . #
        //         . # . #
        //         . . . .
        let on = [0, 5, 3, 7];
        let r = regions(4, 3, |i| on.contains(&i));
        // 0 and 5 touch diagonally; 3 and 7 vertically.
        assert_eq!(r.len(), 2);
        let mut a = r[0].clone();
        a.sort_unstable();
        let mut b = r[1].clone();
        b.sort_unstable();
        assert_eq!((a, b), (vec![0, 5], vec![3, 7]));
        assert_eq!(r[0][0], 0, "a region starts at its first pixel");
        assert!(regions(0, 0, |_| true).is_empty());
    }
    use crate::model::Transfer;

    fn tone() -> Tone {
        Tone::new(Transfer::Gamma, 2.2, 0.0)
    }

    #[test]
    fn parse_and_validate() {
        assert_eq!(PhotoHighlights::parse("off").unwrap(), PhotoHighlights::Off);
        assert_eq!(
            PhotoHighlights::parse("paper").unwrap(),
            PhotoHighlights::PaperBoost
        );
        assert_eq!(
            PhotoHighlights::parse("3:0.9").unwrap(),
            PhotoHighlights::Recover(HighlightRecovery {
                gain: 3.0,
                threshold: 0.9
            })
        );
        let r = HighlightRecovery::parse("6").unwrap();
        assert_eq!(r.gain, 6.0);
        assert_eq!(r.threshold, HighlightRecovery::DEFAULT.threshold);
        let r = HighlightRecovery::parse("3:0.9").unwrap();
        assert_eq!((r.gain, r.threshold), (3.0, 0.9));
        for bad in ["", "x", "0.5", "3:1", "3:0", "3:x", "nan", "inf"] {
            assert!(HighlightRecovery::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn small_clipped_blob_gets_gain_large_area_less_unclipped_none() {
        // 40x40 grey image; a 2x2 clipped blob, a 20x10 clipped area, a bright unclipped blob.
        let mut img = Image::<f64>::new(40, 40, 3);
        img.data.iter_mut().for_each(|v| *v = 0.3);
        let set = |img: &mut Image<f64>, x0: usize, y0: usize, x1: usize, y1: usize, v: f64| {
            for y in y0..y1 {
                for x in x0..x1 {
                    for c in 0..3 {
                        img.data[3 * (y * 40 + x) + c] = v;
                    }
                }
            }
        };
        set(&mut img, 2, 2, 4, 4, 1.0);
        set(&mut img, 10, 20, 30, 30, 1.0);
        set(&mut img, 30, 2, 32, 4, 0.95);
        let r = HighlightRecovery {
            gain: 5.0,
            threshold: 0.85,
        };
        let mut disp = Image::<f64>::new(40, 40, 1);
        disp.data.iter_mut().for_each(|v| *v = 1.0);
        // In focus at the far right (x >= 36), defocused by 30 px elsewhere.
        for y in 0..40 {
            for x in 36..40 {
                disp.data[y * 40 + x] = 0.0;
            }
        }
        set(&mut img, 37, 30, 39, 32, 1.0);
        let out = r.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
        let lin =
            |img: &Image<f64>, x: usize, y: usize| tone().linearize(img.data[3 * (y * 40 + x)]);
        assert!((lin(&out, 2, 2) - 5.0).abs() < 1e-9, "{}", lin(&out, 2, 2));
        // 200 px area: gain 1 + 4 * 16/200.
        assert!((lin(&out, 15, 25) - (1.0 + 4.0 * 16.0 / 200.0)).abs() < 1e-9);
        assert_eq!(lin(&out, 30, 2), lin(&img, 30, 2));
        assert_eq!(lin(&out, 0, 0), lin(&img, 0, 0));
        // An in-focus clipped blob keeps its colour.
        assert_eq!(lin(&out, 37, 30), lin(&img, 37, 30));
        // Gain 1 is the identity.
        let id = HighlightRecovery { gain: 1.0, ..r };
        assert_eq!(id.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap(), img);
        assert!((defocus_gate(0.5), defocus_gate(2.0), defocus_gate(5.0)) == (0.0, 0.5, 1.0));
    }
    #[test]
    fn estimate_reads_gain_and_tint_from_the_rim() {
        // Two clipped 4x4 blobs on a grey background, defocused by 30 px: blob A with a
        // rim barely above the background (a bright source: its edge falls fast), blob B
        // with a brighter orange rim (a dimmer source). Linear values.
        let (w, h) = (48, 24);
        let bg = 0.05;
        let mut lin = vec![bg; w * h * 3];
        let mut put = |x: usize, y: usize, c: [f64; 3]| {
            lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&c);
        };
        for (x0, rim) in [(8usize, [0.07; 3]), (32, [0.2, 0.1, 0.06])] {
            for y in 8..16 {
                for x in x0..x0 + 8 {
                    let inner = (x0 + 2..x0 + 6).contains(&x) && (10..14).contains(&y);
                    put(x, y, if inner { [1.0; 3] } else { rim });
                }
            }
        }
        let tone = tone();
        let mut img = Image::<f64>::new(w, h, 3);
        for (v, l) in img.data.iter_mut().zip(&lin) {
            *v = tone.encode(*l);
        }
        let mut disp = Image::<f64>::new(w, h, 1);
        disp.data.iter_mut().for_each(|v| *v = 1.0);
        // The earlier cue, tint and profile (per clipped edge pixel, 3-4 px ring, a share
        // of the gain on edge pixels); the defaults are tested below.
        let est = HighlightEstimate {
            rim_k: 0.3,
            max_gain: 8.0,
            edge: 1.0,
            white_rim: 0.05,
            keep: false,
            rim_ramp: 1.0,
            edge_power: None,
            ring_cue: false,
            tint_weighted: false,
            ..HighlightEstimate::DEFAULT
        };
        let out = est.apply(&img, &disp, 0.0, 30.0, &tone).unwrap();
        let at = |im: &Image<f64>, x: usize, y: usize, c: usize| {
            tone.linearize(im.data[3 * (y * w + x) + c])
        };
        // Interior pixels of the blobs (not on the clipped edge).
        let (a, b) = (at(&out, 11, 11, 0), at(&out, 35, 11, 0));
        assert!(a > 2.0 * b, "bright-source blob {a} vs dim-source blob {b}");
        assert!(b > 1.5, "a clipped blob is recovered above white: {b}");
        assert!(
            (a - est.max_gain).abs() < 1e-9,
            "capped at the largest gain: {a}"
        );
        // B takes its rim's orange tint (red well above green, green >= blue), never
        // below the photo's white.
        let (r, g, bl) = (
            at(&out, 35, 11, 0),
            at(&out, 35, 11, 1),
            at(&out, 35, 11, 2),
        );
        assert!(r > 1.5 * g && g >= bl && bl >= 1.0 - 1e-9, "{r} {g} {bl}");
        // The clipped edge pixels get the share `edge` of the gain.
        let half = HighlightEstimate { edge: 0.5, ..est };
        let out_half = half.apply(&img, &disp, 0.0, 30.0, &tone).unwrap();
        let edge_px = at(&out_half, 10, 10, 0);
        assert!(
            (edge_px - (1.0 + 0.5 * (a - 1.0))).abs() < 1e-9,
            "{edge_px}"
        );
        assert_eq!(at(&out_half, 11, 11, 0), a);
        // The background and the unclipped rim outside the threshold are untouched.
        assert_eq!(at(&out, 0, 0, 0), at(&img, 0, 0, 0));
        // In focus: nothing changes.
        let focused = est.apply(&img, &disp, 1.0, 30.0, &tone).unwrap();
        assert_eq!(focused, img);
        // Parsing.
        assert_eq!(
            PhotoHighlights::parse("auto").unwrap(),
            PhotoHighlights::Estimate(HighlightEstimate::DEFAULT)
        );
        let e =
            HighlightEstimate::parse("auto:k=0.5,max=4,edge=0.5,tint=0,paper=0,white=0.1").unwrap();
        assert_eq!(
            (e.rim_k, e.max_gain, e.edge, e.tint, e.paper, e.white_rim),
            (0.5, 4.0, 0.5, false, false, 0.1)
        );
        assert_eq!(e.edge_power, None, "edge= switches to the share rule");
        let e = HighlightEstimate::parse("auto:edgep=0.5,keep=0,cue=0,tintw=0,rim=0.5").unwrap();
        assert_eq!(
            (
                e.edge_power,
                e.keep,
                e.ring_cue,
                e.tint_weighted,
                e.rim_ramp
            ),
            (Some(0.5), false, false, false, 0.5)
        );
        assert!(PhotoHighlights::parse("auto").unwrap().paper_boost());
        assert!(!PhotoHighlights::parse("auto:paper=0")
            .unwrap()
            .paper_boost());
        for bad in [
            "auto:k",
            "auto:k=0",
            "auto:tint=2",
            "auto:white=-1",
            "auto:max=0.5",
            "auto:edge=2",
            "auto:x=1",
            "auto:edgep=2",
            "auto:rim=-1",
            "auto:keep=2",
            "auto:cue=0.5",
            "autox",
        ] {
            assert!(PhotoHighlights::parse(bad).is_err(), "{bad}");
        }
    }

    /// Builds an encoded image from linear colours.
    fn encode_lin(lin: &[f64], w: usize, h: usize) -> Image<f64> {
        let mut img = Image::<f64>::new(w, h, 3);
        for (v, l) in img.data.iter_mut().zip(lin) {
            *v = tone().encode(*l);
        }
        img
    }

    #[test]
    fn ring_cue_reads_the_rim_against_the_next_ring() {
        // A clipped 4x4 blob whose 1 px rim and the next ring out lie on a bright patch
        // (0.3) in a dark scene (0.05): against the next ring the rim holds no light (a
        // bright source: the largest gain); against the 3-4 px ring it seems to hold
        // much (a dim source). Linear values, defocused by 30 px.
        let (w, h) = (24, 24);
        let mut lin = vec![0.05; w * h * 3];
        for y in 6..18 {
            for x in 6..18 {
                let v = if (10..14).contains(&x) && (10..14).contains(&y) {
                    1.0
                } else if (8..16).contains(&x) && (8..16).contains(&y) {
                    0.3
                } else {
                    0.05
                };
                lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[v; 3]);
            }
        }
        let img = encode_lin(&lin, w, h);
        let mut disp = Image::<f64>::new(w, h, 1);
        disp.data.iter_mut().for_each(|v| *v = 1.0);
        let ring = HighlightEstimate {
            tint: false,
            ..HighlightEstimate::DEFAULT
        };
        let old = HighlightEstimate {
            ring_cue: false,
            ..ring
        };
        let centre = |e: &HighlightEstimate| {
            let out = e.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
            tone().linearize(out.data[3 * (11 * w + 11)])
        };
        assert!(
            (centre(&ring) - ring.max_gain).abs() < 1e-9,
            "{}",
            centre(&ring)
        );
        assert!(centre(&old) < 0.5 * ring.max_gain, "{}", centre(&old));
    }

    #[test]
    fn weighted_tint_follows_the_brightest_rim_pixels() {
        // A clipped 2x2 blob; one rim pixel carries the source's orange light, the others
        // a faint bluish cast over the grey background. Weighted by light, the tint is
        // orange; summed unweighted, the many faint pixels make it bluish.
        let (w, h) = (20, 20);
        let mut lin = vec![0.1; w * h * 3];
        let mut put = |x: usize, y: usize, c: [f64; 3]| {
            lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&c);
        };
        for (x, y) in [(9, 9), (10, 9), (9, 10), (10, 10)] {
            put(x, y, [1.0; 3]);
        }
        for y in 8..12 {
            for x in 8..12 {
                if !(9..11).contains(&x) || !(9..11).contains(&y) {
                    put(x, y, [0.1, 0.1, 0.17]);
                }
            }
        }
        put(8, 9, [0.6, 0.35, 0.15]);
        let img = encode_lin(&lin, w, h);
        let mut disp = Image::<f64>::new(w, h, 1);
        disp.data.iter_mut().for_each(|v| *v = 1.0);
        let est = HighlightEstimate {
            white_rim: 0.0,
            ..HighlightEstimate::DEFAULT
        };
        let rgb = |e: &HighlightEstimate| {
            let out = e.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
            let i = 3 * (9 * w + 9);
            [0, 1, 2].map(|c| tone().linearize(out.data[i + c]))
        };
        let [r, _, b] = rgb(&est);
        assert!(r > 1.5 * b, "weighted: orange, got r {r} b {b}");
        let [r, _, b] = rgb(&HighlightEstimate {
            tint_weighted: false,
            ..est
        });
        assert!(b > r, "unweighted: bluish, got r {r} b {b}");
    }

    #[test]
    fn profile_keeps_unclipped_channels_and_the_rim() {
        // A clipped 6x6 blob with no rim light (the largest gain `G`): interior pixels get
        // `G`, edge pixels `G^p`; a pixel clipped in red and green only keeps its blue; a
        // bright unclipped pixel of the region keeps its value with `rim` 0.
        let (w, h) = (20, 20);
        let mut lin = vec![0.05; w * h * 3];
        for y in 7..13 {
            for x in 7..13 {
                lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[1.0; 3]);
            }
        }
        lin[3 * (9 * w + 9) + 2] = 0.5; // clipped in red and green only (interior)
        let bright = tone().linearize(0.95);
        lin[3 * (10 * w + 13)..3 * (10 * w + 13) + 3].copy_from_slice(&[bright; 3]);
        let img = encode_lin(&lin, w, h);
        let mut disp = Image::<f64>::new(w, h, 1);
        disp.data.iter_mut().for_each(|v| *v = 1.0);
        let est = HighlightEstimate {
            tint: false,
            rim_k: 100.0,
            ..HighlightEstimate::DEFAULT
        };
        let out = est.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
        let at = |im: &Image<f64>, x: usize, y: usize, c: usize| {
            tone().linearize(im.data[3 * (y * w + x) + c])
        };
        let g = est.max_gain;
        let p = est.edge_power.unwrap();
        assert!((at(&out, 10, 10, 0) - g).abs() < 1e-9);
        assert!((at(&out, 7, 10, 0) - g.powf(p)).abs() < 1e-9);
        assert!((at(&out, 7, 7, 1) - g.powf(p)).abs() < 1e-9);
        assert!((at(&out, 9, 9, 0) - g).abs() < 1e-9);
        assert_eq!(at(&out, 9, 9, 2), at(&img, 9, 9, 2));
        assert_eq!(at(&out, 13, 10, 0), at(&img, 13, 10, 0));
        // Without `keep` and with the full ramp, both change.
        let all = HighlightEstimate {
            keep: false,
            rim_ramp: 1.0,
            ..est
        };
        let out = all.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
        assert!((at(&out, 9, 9, 2) - g).abs() < 1e-9);
        assert!(at(&out, 13, 10, 0) > at(&img, 13, 10, 0) + 0.5);
    }

    #[test]
    fn gain_follows_the_least_blurred_clipped_pixel_behind() {
        // Two 4x4 clipped blobs on grey, each with a clipped column on its right that the
        // depth map puts on a blurred foreground (disparity 1, 30 px of blur): blob A's core
        // is in focus (disparity 0), blob B's core is defocused (disparity 0.5, 15 px).
        // Blob C: a defocused light (disparity -0.5, 15 px) crossed by an in-focus wire
        // (its middle column, disparity 0) in front of it.
        let (w, h) = (45, 12);
        let mut img = Image::<f64>::new(w, h, 3);
        img.data.iter_mut().for_each(|v| *v = 0.3);
        let mut disp = Image::<f64>::new(w, h, 1);
        for (x0, core, col, col_disp) in [(3, 0.0, 4, 1.0), (18, 0.5, 4, 1.0), (33, -0.5, 2, 0.0)] {
            for y in 4..8 {
                for x in x0..x0 + 5 {
                    img.data[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[1.0; 3]);
                    disp.data[y * w + x] = if x == x0 + col { col_disp } else { core };
                }
            }
        }
        let r = HighlightRecovery {
            gain: 5.0,
            threshold: 0.9,
        };
        let out = r.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
        let lin = |im: &Image<f64>, x: usize, y: usize| tone().linearize(im.data[3 * (y * w + x)]);
        // A: in-focus source, so neither its core nor its foreground-labelled edge gain.
        assert_eq!(lin(&out, 4, 5), 1.0);
        assert_eq!(lin(&out, 7, 5), 1.0);
        // B: a defocused source, so both gain (20 px area: 1 + 4 * 16 / 20).
        let g = 1.0 + 4.0 * 16.0 / 20.0;
        assert!((lin(&out, 19, 5) - g).abs() < 1e-9);
        assert!((lin(&out, 22, 5) - g).abs() < 1e-9);
        // C: the light behind the wire keeps its gain; the wire, in focus, keeps its colour.
        assert!((lin(&out, 34, 5) - g).abs() < 1e-9);
        assert!((lin(&out, 36, 5) - 1.0).abs() < 1e-12);
        // Pixels 0-3 (even ones clipped) at disparities 0.2, 0.9, 0.5, 0.0 with radii 4, 1,
        // 2, 0.5: behind disparity 0.5 lies pixel 0 (4) and pixel 2 (2).
        let clipped = |j: usize| j % 2 == 0;
        let d = |j: usize| [0.2, 0.9, 0.5, 0.0][j];
        let radius = |j: usize| [4.0, 1.0, 2.0, 0.5][j];
        let s = SourceRadii::new(&[0, 1, 2, 3], clipped, d, radius);
        assert_eq!(
            (s.behind(0.5), s.behind(1.0), s.behind(0.3)),
            (2.0, 2.0, 4.0)
        );
        assert_eq!(s.behind(0.1), f64::INFINITY);
        let none = SourceRadii::new(&[1, 3], clipped, d, radius);
        assert_eq!(none.behind(1.0), f64::INFINITY);
    }
}
