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
//! 5. The gain is faded in with the pixel's blur radius `K |disp - f|` ([`defocus_gate`]):
//!    none below 1 px, all from 3 px. An in-focus highlight renders as the photo shows it
//!    (clipped, like the camera's), and its extra light cannot leak into its neighbours.
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
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum PhotoHighlights {
    /// As the photo shows them.
    Off,
    /// The paper's boost inside the model (docs/model.md, M20; the camera's `highlight`):
    /// the default, the best of the settings measured in docs/highlights.md.
    #[default]
    PaperBoost,
    /// Per-region recovery (this module).
    Recover(HighlightRecovery),
}

impl PhotoHighlights {
    /// Parses `off`, `paper`, or `GAIN[:THRESHOLD]` ([`HighlightRecovery::parse`]).
    pub fn parse(spec: &str) -> Result<Self> {
        Ok(match spec.trim() {
            "off" => PhotoHighlights::Off,
            "paper" => PhotoHighlights::PaperBoost,
            s => PhotoHighlights::Recover(HighlightRecovery::parse(s)?),
        })
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
        let mut out = rgb_encoded.clone();
        let (w, h) = (rgb_encoded.width, rgb_encoded.height);
        if self.gain == 1.0 || w == 0 || h == 0 {
            return Ok(out);
        }
        let value: Vec<f64> = rgb_encoded
            .data
            .chunks_exact(3)
            .map(|p| p.iter().map(|v| v.f64()).fold(f64::NEG_INFINITY, f64::max))
            .collect();
        let t0 = self.threshold;
        let a_point = point_area_px(w, h);
        let mut seen = vec![false; w * h];
        let mut stack = Vec::new();
        let mut region = Vec::new();
        for start in 0..w * h {
            if seen[start] || value[start].is_nan() || value[start] < t0 {
                continue;
            }
            // Flood the 8-connected bright region holding `start`.
            region.clear();
            seen[start] = true;
            stack.push(start);
            while let Some(i) = stack.pop() {
                region.push(i);
                let (x, y) = (i % w, i / w);
                for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                    for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                        let j = ny * w + nx;
                        if !seen[j] && value[j] >= t0 {
                            seen[j] = true;
                            stack.push(j);
                        }
                    }
                }
            }
            if !region.iter().any(|&i| value[i] >= CLIPPED_LEVEL) {
                continue;
            }
            let weight = (a_point / region.len() as f64).min(1.0);
            let g = 1.0 + (self.gain - 1.0) * weight;
            for &i in &region {
                let t = ((value[i] - t0) / (1.0 - t0)).clamp(0.0, 1.0);
                let radius_px = blur_k * (disparity.data[i].f64() - focus_disparity).abs();
                let factor = 1.0 + (g - 1.0) * smoothstep(t) * defocus_gate(radius_px);
                for v in &mut out.data[3 * i..3 * i + 3] {
                    let lin = tone.linearize(v.f64().max(0.0));
                    *v = T::c(tone.encode(lin * factor).max(0.0));
                }
            }
        }
        Ok(out)
    }
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
}
