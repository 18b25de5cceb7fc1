//! How far to trust a depth-from-defocus estimate, pixel by pixel, and how to score such a
//! map against the truth (`docs/dfd.md`, section "Confidence").
//!
//! Two signals, both computed from what a user has (the pair, K, focus and the estimate):
//! - the render's **sensitivity** to the disparity (computed in `optimise.rs`, where the
//!   render is at hand): near 0 where the pair carries no depth information;
//! - the **occlusion band** ([`occlusion_band`]): near 0 within the blur radius of a step
//!   in the estimate, where one surface's blurred light falls on another's pixels and the
//!   single-layer objective fattens near structures over the background behind them. A
//!   structure thinner than its blur lies wholly inside its own band.
//!
//! And the score of a confidence map ([`sparsification`]): the MAE of the most confident
//! fraction of pixels, against the best any map could do (the pixels ranked by their true
//! error).

use super::maps::{pool, upsample};
use rayon::prelude::*;

/// The occlusion band's two scales.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OcclusionBand {
    /// The band's half-width as a multiple of the larger blur radius of the two sides of a
    /// step (`K |disparity - focus|`, in pixels of the map).
    pub reach: f64,
    /// The disparity difference that counts as a whole step; smaller differences lower the
    /// confidence in proportion.
    pub step: f64,
}

impl OcclusionBand {
    /// The values `dfd` uses (set before any measurement and not tuned: the other settings
    /// tried on the tuning seeds rank within 0.001 AUSE of it, `docs/dfd.md`).
    pub const DEFAULT: OcclusionBand = OcclusionBand {
        reach: 1.0,
        step: 0.1,
    };

    /// The band's widest reach in pixels, `reach * blur_px * max(focus, 1 - focus)`: the
    /// largest blur radius any disparity in [0, 1] can have, times `reach`.
    pub fn widest_px(self, blur_px: f64, focus: f64) -> f64 {
        self.reach * blur_px * focus.max(1.0 - focus)
    }
}

/// Most pixel pairs [`occlusion_band_within_budget`] compares: about 0.3 s on two cores.
pub const OCCLUSION_BAND_BUDGET: f64 = 4e8;

/// [`occlusion_band`] at the finest resolution whose cost (`w h (2R + 1)^2` pixel pairs at
/// that resolution) is at most `budget`: the map is 2x2-pooled until it fits (K halving with
/// it), the band computed there and upsampled bilinearly to `w x h`.
pub fn occlusion_band_within_budget(
    disparity: &[f64],
    w: usize,
    h: usize,
    blur_px: f64,
    focus: f64,
    band: OcclusionBand,
    budget: f64,
) -> Vec<f64> {
    let (mut small, mut sw, mut sh, mut k) = (disparity.to_vec(), w, h, blur_px);
    let cost = |sw: usize, sh: usize, k: f64| {
        let reach = band.widest_px(k, focus).ceil();
        (sw * sh) as f64 * (2.0 * reach + 1.0).powi(2)
    };
    while cost(sw, sh, k) > budget && sw >= 4 && sh >= 4 {
        small = pool(&small, sw, sh, 1);
        (sw, sh, k) = (sw / 2, sh / 2, k / 2.0);
    }
    let c = occlusion_band(&small, sw, sh, k, focus, band);
    if (sw, sh) == (w, h) {
        c
    } else {
        upsample(&c, sw, sh, w, h)
    }
}

/// The occlusion-band confidence of a disparity map (`w x h`, one value per pixel, in
/// [0, 1]), for a defocused image of blur `blur_px` (K in pixels of this map) focused at
/// disparity `focus`.
///
/// For pixels `p` and `q` at distance `r` with disparities `d_p`, `d_q`, let `b` be the
/// larger of their blur radii, `blur_px |d - focus|`, times `band.reach`. The confidence of
/// `p` is the least, over every `q` with `r < b`, of `max(r / b, 1 - |d_p - d_q| / step)`,
/// and 1 where no such `q` exists: 0 at a whole step, rising linearly to 1 at the band's
/// edge; a smaller step lowers it less. Cost: `w h (2R + 1)^2` with `R` the band's widest
/// reach, `band.reach * blur_px * max(focus, 1 - focus)`.
pub fn occlusion_band(
    disparity: &[f64],
    w: usize,
    h: usize,
    blur_px: f64,
    focus: f64,
    band: OcclusionBand,
) -> Vec<f64> {
    debug_assert_eq!(disparity.len(), w * h);
    let widest = band.widest_px(blur_px, focus);
    if !(widest.is_finite() && widest > 0.0 && band.step > 0.0) {
        return vec![1.0; w * h];
    }
    let reach_px = widest.ceil() as isize;
    let radius = |d: f64| band.reach * blur_px * (d - focus).abs();
    let mut out = vec![1.0; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let y = y as isize;
        for x in 0..w as isize {
            let i = y as usize * w + x as usize;
            let dp = disparity[i];
            let rp = radius(dp);
            let mut c: f64 = 1.0;
            for yy in (y - reach_px).max(0)..(y + reach_px + 1).min(h as isize) {
                for xx in (x - reach_px).max(0)..(x + reach_px + 1).min(w as isize) {
                    let dq = disparity[yy as usize * w + xx as usize];
                    let near = 1.0 - (dp - dq).abs() / band.step;
                    if near >= c {
                        continue;
                    }
                    let b = rp.max(radius(dq));
                    let r = (((xx - x) * (xx - x) + (yy - y) * (yy - y)) as f64).sqrt();
                    if r < b {
                        c = c.min(near.max(r / b));
                    }
                }
            }
            row[x as usize] = c.max(0.0);
        }
    });
    out
}

/// The kept fractions at which [`sparsification`] samples the curve: 5 %, 10 %, ..., 100 %.
pub const SPARSIFICATION_STEPS: usize = 20;

/// How well a confidence map ranks the pixels by their error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sparsification {
    /// MAE over the most confident half of the pixels.
    pub mae_confident_half: f64,
    /// Area between the sparsification curve (the MAE of the most confident fraction, at
    /// 5 %, 10 %, ..., 100 % kept) and the oracle's (the pixels of least true error first),
    /// as the mean over the samples: 0 for a perfect ranking.
    pub ause: f64,
    /// The same area for a map that says nothing (every kept fraction has the whole map's
    /// MAE): what [`Sparsification::ause`] should be compared with.
    pub ause_uninformative: f64,
}

/// Scores a confidence map against the absolute errors of an estimate (same length, not
/// empty). Ties in confidence keep pixel order, so the score is deterministic.
pub fn sparsification(abs_error: &[f64], confidence: &[f64]) -> Sparsification {
    debug_assert_eq!(abs_error.len(), confidence.len());
    let n = abs_error.len();
    let mut by_conf: Vec<usize> = (0..n).collect();
    by_conf.sort_by(|&a, &b| confidence[b].total_cmp(&confidence[a]));
    let mut by_error: Vec<f64> = abs_error.to_vec();
    by_error.sort_by(f64::total_cmp);
    let prefix = |v: &mut dyn Iterator<Item = f64>| {
        let mut acc = 0.0;
        let mut out = Vec::with_capacity(n);
        for e in v {
            acc += e;
            out.push(acc);
        }
        out
    };
    let curve = prefix(&mut by_conf.iter().map(|&i| abs_error[i]));
    let oracle = prefix(&mut by_error.iter().copied());
    let mae_at = |sums: &[f64], k: usize| {
        let m = ((k as f64 / SPARSIFICATION_STEPS as f64) * n as f64).ceil() as usize;
        let m = m.clamp(1, n);
        sums[m - 1] / m as f64
    };
    let all = curve[n - 1] / n as f64;
    let (mut area, mut flat) = (0.0, 0.0);
    for k in 1..=SPARSIFICATION_STEPS {
        let best = mae_at(&oracle, k);
        area += mae_at(&curve, k) - best;
        flat += all - best;
    }
    Sparsification {
        mae_confident_half: mae_at(&curve, SPARSIFICATION_STEPS / 2),
        ause: area / SPARSIFICATION_STEPS as f64,
        ause_uninformative: flat / SPARSIFICATION_STEPS as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A near square (disparity 0.9) over a far background (0.1), focused on the background.
    fn square(w: usize, lo: usize, hi: usize) -> Vec<f64> {
        (0..w * w)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if (lo..hi).contains(&x) && (lo..hi).contains(&y) {
                    0.9
                } else {
                    0.1
                }
            })
            .collect()
    }

    #[test]
    fn the_band_follows_the_blur_of_the_step() {
        let w = 64;
        let d = square(w, 16, 48);
        // K 10, focus 0.1: the square's blur radius is 8 px, the background's 0.
        let c = occlusion_band(&d, w, w, 10.0, 0.1, OcclusionBand::DEFAULT);
        let at = |x: usize, y: usize| c[y * w + x];
        // Far from the edge, on either side: trusted.
        assert_eq!(at(32, 32), 1.0);
        assert_eq!(at(2, 2), 1.0);
        // At the edge, on either side: not trusted.
        assert!(
            at(16, 32) < 0.2 && at(15, 32) < 0.2,
            "{} {}",
            at(16, 32),
            at(15, 32)
        );
        // Half a band out (4 px of 8): a half.
        assert!((at(12, 32) - 0.5).abs() < 1e-12, "{}", at(12, 32));
        // The band's reach is the blur: 9 px out is beyond it.
        assert_eq!(at(7, 32), 1.0);
        // Focused on the square, the background's blur sets the band (same width here).
        let c2 = occlusion_band(&d, w, w, 10.0, 0.9, OcclusionBand::DEFAULT);
        assert!(c2[32 * w + 15] < 0.2 && c2[32 * w + 6] == 1.0);
        // No blur, no band.
        let c0 = occlusion_band(&d, w, w, 0.0, 0.1, OcclusionBand::DEFAULT);
        assert!(c0.iter().all(|&v| v == 1.0));
    }

    #[test]
    fn the_budget_pools_only_when_it_must() {
        let w = 64;
        let d = square(w, 16, 48);
        let b = OcclusionBand::DEFAULT;
        let full = occlusion_band(&d, w, w, 10.0, 0.1, b);
        // 64 x 64 x 19^2 pairs fit in the default budget: the same map.
        let within = occlusion_band_within_budget(&d, w, w, 10.0, 0.1, b, OCCLUSION_BAND_BUDGET);
        assert_eq!(full, within);
        // A budget of a quarter of that pools once: the band is there, at about its width.
        let pooled =
            occlusion_band_within_budget(&d, w, w, 10.0, 0.1, b, 64.0 * 64.0 * 361.0 / 4.0);
        assert_ne!(full, pooled);
        assert!(
            pooled[32 * w + 16] < 0.3 && pooled[32 * w + 32] > 0.99 && pooled[2 * w + 2] > 0.99
        );
        let mean_abs = full
            .iter()
            .zip(&pooled)
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / (w * w) as f64;
        assert!(mean_abs < 0.05, "{mean_abs}");
    }

    #[test]
    fn a_structure_thinner_than_its_blur_is_all_band() {
        let w = 64;
        // A bar 3 px wide at disparity 0.9 over 0.1, K 20, focus 0.1: 16 px of blur.
        let d: Vec<f64> = (0..w * w)
            .map(|i| {
                if (30..33).contains(&(i % w)) {
                    0.9
                } else {
                    0.1
                }
            })
            .collect();
        let c = occlusion_band(&d, w, w, 20.0, 0.1, OcclusionBand::DEFAULT);
        for y in 0..w {
            assert!(c[y * w + 31] < 0.2);
        }
        // A small step (0.02 of a 0.1 step) lowers the confidence by at most a fifth.
        let d2: Vec<f64> = (0..w * w)
            .map(|i| if i % w < 32 { 0.5 } else { 0.52 })
            .collect();
        let c2 = occlusion_band(&d2, w, w, 10.0, 0.0, OcclusionBand::DEFAULT);
        assert!(c2.iter().all(|&v| v >= 0.8 - 1e-12));
    }

    #[test]
    fn sparsification_scores_rankings() {
        let err: Vec<f64> = (0..100).map(|i| (i % 10) as f64 / 10.0).collect();
        // Confidence that ranks exactly by error: the oracle's curve, area 0.
        let perfect: Vec<f64> = err.iter().map(|e| 1.0 - e).collect();
        let s = sparsification(&err, &perfect);
        assert!(s.ause.abs() < 1e-12);
        // The most confident half holds the errors 0 .. 0.4.
        assert!((s.mae_confident_half - 0.2).abs() < 1e-12);
        // The reverse ranking is worse than saying nothing.
        let reverse: Vec<f64> = err.clone();
        let r = sparsification(&err, &reverse);
        assert!(r.ause > r.ause_uninformative && r.ause_uninformative > 0.0);
        assert!((r.mae_confident_half - 0.7).abs() < 1e-12);
        // A constant map (pixel order) lies between the two.
        let flat = sparsification(&err, &[0.5; 100]);
        assert!(flat.ause > s.ause && flat.ause < r.ause);
    }
}
