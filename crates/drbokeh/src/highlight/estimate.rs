//! Per-region gain and tint read from each clipped region's rim (`--highlight auto`, the
//! default for photos; docs/highlights.md): [`HighlightEstimate`].

use super::{
    check_inputs, clipped_regions, largest_channel, recover_regions, HighlightRecovery, Profile,
    CLIPPED_LEVEL,
};
use crate::image::Image;
use crate::model::{HighlightBoost, Tone};
use crate::{Error, Real, Result};

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
/// [`HighlightRecovery`]). The defocus gate applies. Then the highlight boost
/// (docs/model.md, M20) is applied on top in the model (`boost`: by default with
/// [`HighlightBoost::PHOTO`]'s constants).
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
    /// The highlight boost (docs/model.md, M20) applied on top, in the model, if any
    /// ([`HighlightBoost::PHOTO`] by default; [`HighlightBoost::PAPER`] is the paper's,
    /// the default before session 40).
    pub boost: Option<HighlightBoost>,
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
    /// One exposure per photo (docs/highlights.md, "One exposure per photo"): with
    /// `pool > 0`, the cap and the rim constant are set per image from the quantile
    /// `pool_quantile` (`S`) of all its clipped regions' uncapped rim gains `K / x`: the cap
    /// becomes `clamp(pool S, max_gain, pool_max)` and the rim constant
    /// `K (cap / max_gain)^pool_k_power`. An image whose rims look dim keeps `max_gain`
    /// and `K`. 0: off; the default is 0.9.
    pub pool: f64,
    /// The quantile of the regions' rim gains that `pool` scales, in [0, 1].
    pub pool_quantile: f64,
    /// The largest cap that pooling gives (>= `max_gain`).
    pub pool_max: f64,
    /// Power of `cap / max_gain` on the rim constant under pooling (>= 0).
    pub pool_k_power: f64,
    /// Whether a region in which some channel did not clip at any of its clipped pixels
    /// gets no gain of its own (docs/highlights.md, "A channel that did not clip"): its
    /// source is at most `1 / t` times white in the other channels (`t` that channel's
    /// share of the tint), little enough that the boost alone covers it.
    pub unclipped_channel: bool,
}

impl HighlightEstimate {
    /// The defaults of `auto` (and of photos), chosen on the tuning benchmarks of
    /// docs/highlights.md (seeds 101, 102 and 103, highlights 2-10 and 5-50); `pool` 0.9
    /// since session 36 (`auto:pool=0` gives the earlier default).
    pub const DEFAULT: HighlightEstimate = HighlightEstimate {
        rim_k: 0.2,
        max_gain: 3.5,
        threshold: 0.9,
        tint: true,
        edge: 0.25,
        boost: Some(HighlightBoost::PHOTO),
        white_rim: 0.01,
        keep: true,
        rim_ramp: 0.0,
        edge_power: Some(0.65),
        ring_cue: true,
        tint_weighted: true,
        pool: 0.9,
        pool_quantile: 0.9,
        pool_max: 10.0,
        pool_k_power: 1.0,
        unclipped_channel: true,
    };

    /// Parses `auto` or `auto:KEY=VALUE,...` with keys `k` (rim constant), `max` (largest
    /// gain), `t` (threshold), `edgep` (power of the gain on the clipped edge pixels),
    /// `edge` (share of `g - 1` on them instead), `white`, `tint`, `keep`, `cue`,
    /// `tintw` (0 or 1), `rim` (share of the ramp on bright unclipped pixels), `pool`,
    /// `poolq`, `poolmax`, `poolk` (one exposure per photo, [`HighlightEstimate::pool`]),
    /// `chan` (0 or 1, [`HighlightEstimate::unclipped_channel`]), and the boost on top:
    /// `paper` (1: the paper's constants, 0: no boost), `boost` (its amount) and `boostt`
    /// (its threshold), applied in the order given.
    pub fn parse(spec: &str) -> Result<Self> {
        let bad = || {
            Error::param(
                "highlight",
                format!(
                    "expected auto or auto:KEY=VALUE,... (keys k, max, t, edgep, edge, white, tint, keep, cue, tintw, rim, pool, poolq, poolmax, poolk, chan, paper, boost, boostt; e.g. auto:k=0.3,max=8 or auto:pool=0.9), got '{spec}'"
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
                "paper" if v == 0.0 || v == 1.0 => {
                    e.boost = (v == 1.0).then_some(HighlightBoost::PAPER)
                }
                "boost" => {
                    e.boost = Some(HighlightBoost {
                        amount: v,
                        ..e.boost.unwrap_or(HighlightBoost::PHOTO)
                    })
                }
                "boostt" => {
                    e.boost = Some(HighlightBoost {
                        threshold_encoded: v,
                        ..e.boost.unwrap_or(HighlightBoost::PHOTO)
                    })
                }
                "keep" if v == 0.0 || v == 1.0 => e.keep = v == 1.0,
                "rim" => e.rim_ramp = v,
                "tintw" if v == 0.0 || v == 1.0 => e.tint_weighted = v == 1.0,
                "cue" if v == 0.0 || v == 1.0 => e.ring_cue = v == 1.0,
                "edgep" if (0.0..=1.0).contains(&v) => e.edge_power = Some(v),
                "pool" => e.pool = v,
                "poolq" => e.pool_quantile = v,
                "poolmax" => e.pool_max = v,
                "poolk" => e.pool_k_power = v,
                "chan" if v == 0.0 || v == 1.0 => e.unclipped_channel = v == 1.0,
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
        let pool_ok = self.pool.is_finite()
            && (0.0..=1000.0).contains(&self.pool)
            && (0.0..=1.0).contains(&self.pool_quantile)
            && self.pool_max.is_finite()
            && self.pool_max >= self.max_gain
            && self.pool_max <= 1000.0
            && (0.0..=10.0).contains(&self.pool_k_power);
        if !pool_ok {
            return Err(Error::param(
                "highlight",
                format!(
                    "pooling needs pool in [0, 1000], poolq in [0, 1], poolmax in [max, 1000] and poolk in [0, 10], got pool {}, poolq {}, poolmax {} (max {}), poolk {}",
                    self.pool, self.pool_quantile, self.pool_max, self.max_gain, self.pool_k_power
                ),
            ));
        }
        if let Some(boost) = &self.boost {
            boost.validate()?;
        }
        HighlightRecovery {
            gain: self.max_gain,
            threshold: self.threshold,
        }
        .validate()
    }

    /// The rim constant and cap for one image: `(rim_k, max_gain)`, or under pooling the
    /// values read from the rim cues `x` of all its clipped regions (see `pool`).
    fn pooled(&self, cues: impl Iterator<Item = f64>) -> (f64, f64) {
        if self.pool <= 0.0 {
            return (self.rim_k, self.max_gain);
        }
        // The regions' uncapped rim gains.
        let mut gains: Vec<f64> = cues.map(|x| rim_gain(self.rim_k, x, 1000.0)).collect();
        if gains.is_empty() {
            return (self.rim_k, self.max_gain);
        }
        gains.sort_by(f64::total_cmp);
        let at = ((gains.len() as f64 * self.pool_quantile) as usize).min(gains.len() - 1);
        let cap = (self.pool * gains[at]).clamp(self.max_gain, self.pool_max);
        let rim_k = self.rim_k * (cap / self.max_gain).powf(self.pool_k_power);
        (rim_k, cap)
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
        // Each region's rim cue and tint, read once; then the image's rim constant and
        // cap (pooled over the cues, or the fixed ones).
        let value = largest_channel(rgb_encoded);
        let regions = clipped_regions(w, h, &value, self.threshold);
        let mut mark = vec![0u32; w * h];
        let mut stamp = 1u32;
        let cues: Vec<RegionCue> = regions
            .iter()
            .map(|region| {
                stamp += 5;
                self.cue_and_tint(region, &value, &lin, w, h, &mut mark, stamp)
            })
            .collect();
        let (rim_k, max_gain) = self.pooled(cues.iter().map(|cue| cue.rim));
        recover_regions(
            rgb_encoded,
            &value,
            &regions,
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
            |n, region| {
                let cue = &cues[n];
                let g = if self.unclipped_channel && cue.channel_unclipped {
                    1.0
                } else {
                    rim_gain(rim_k, cue.rim, max_gain)
                };
                let (g, tint) = adjust(region, g, cue.tint);
                (g, Some(tint))
            },
        );
        Ok(out)
    }

    /// The rim cue, tint and unclipped channel of one region; `mark` is scratch, values
    /// `stamp..stamp + 4` unused before this call.
    #[allow(clippy::too_many_arguments)]
    fn cue_and_tint<T: Real>(
        &self,
        region: &[usize],
        value: &[f64],
        lin: &LinearPhoto<'_, T>,
        w: usize,
        h: usize,
        mark: &mut [u32],
        stamp: u32,
    ) -> RegionCue {
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
        let bg = lin.channel_medians(&ring, [0.0; 3]);
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
        let bg_next = lin.channel_medians(&next, bg);
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
        let tint = if self.tint {
            // Towards white where the rim holds little light.
            let eps = self.white_rim * edge.max(1) as f64 + 1e-12;
            let m = rim.iter().copied().fold(0.0, f64::max) + eps;
            [(rim[0] + eps) / m, (rim[1] + eps) / m, (rim[2] + eps) / m]
        } else {
            [1.0; 3]
        };
        // A channel that none of the clipped pixels clipped (a warm light clipped in red
        // and green only).
        let channel_unclipped = (0..3).any(|c| {
            clipped
                .iter()
                .all(|&i| lin.encoded[3 * i + c].f64() < CLIPPED_LEVEL)
        });
        RegionCue {
            rim: x,
            tint,
            channel_unclipped: !clipped.is_empty() && channel_unclipped,
        }
    }
}

/// What the estimate reads from one clipped region.
struct RegionCue {
    /// The rim cue `x` (light per rim pixel above the local background).
    rim: f64,
    /// The source's tint read from the rim (largest channel 1).
    tint: [f64; 3],
    /// Whether some channel did not clip at any of the region's clipped pixels.
    channel_unclipped: bool,
}

/// A region's gain from its rim cue `x` (docs/highlights.md, recovery step 1):
/// `g = clamp(K / x, 1, cap)`.
fn rim_gain(rim_k: f64, x: f64, cap: f64) -> f64 {
    (rim_k / x.max(1e-6)).clamp(1.0, cap)
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

    /// The per-channel median (the upper one of an even count) of the linear values of
    /// `pixels`; `empty` where there are none.
    fn channel_medians(&self, pixels: &[usize], empty: [f64; 3]) -> [f64; 3] {
        let mut m = empty;
        for (c, mc) in m.iter_mut().enumerate() {
            let mut v: Vec<f64> = pixels.iter().map(|&j| self.at(3 * j + c)).collect();
            v.sort_by(f64::total_cmp);
            if let Some(&mid) = v.get(v.len() / 2) {
                *mc = mid;
            }
        }
        m
    }
}
