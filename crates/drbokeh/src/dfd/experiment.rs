//! The depth-from-defocus experiment: synthetic pairs rendered by our `paper` preset from a
//! known disparity, recovered through each rendering layer with each loss combination.
//! Reports disparity MAE, RMSE and the fraction within 1.25x (the paper's Fig. 8/10 claims
//! as numbers).
//!
//! Scenes: a colourful multi-scale texture (so defocus is observable everywhere) over a
//! piecewise-planar disparity: a slanted background plane, a rectangle and a disc at
//! distinct depths. Focus at disparity 1 (nearest), so blur grows monotonically with
//! distance and the sign ambiguity of `|d|` does not arise.

use super::{
    disparity_errors, estimate_disparity, DfdOptions, DisparityErrors, LossTerms, LossWeights,
    RenderLayer,
};
use crate::image::Image;
use crate::presets::RenderSettings;
use crate::stack::LayerStack;
use crate::{Engine, NoProgress, Real, Result};

/// One synthetic pair with its ground truth.
pub struct SyntheticPair<T> {
    /// All-in-focus image.
    pub all_in_focus: Image<T>,
    /// Defocused image (the `paper` render).
    pub defocused: Image<T>,
    /// True disparity.
    pub disparity: Image<T>,
}

fn hash01(i: u64) -> f64 {
    let mut x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

/// Builds a synthetic pair of `size x size` from `seed`, rendered with `settings`.
pub fn synthetic_pair<T: Real>(
    seed: u64,
    size: usize,
    settings: &RenderSettings,
) -> Result<SyntheticPair<T>> {
    let s = size as f64;
    let r = |k: u64| hash01(seed.wrapping_mul(1000) + k);
    let mut aif = Image::new(size, size, 3);
    let mut disp = Image::new(size, size, 1);
    let (rx0, ry0, rx1, ry1) = (
        s * (0.1 + 0.2 * r(1)),
        s * (0.15 + 0.2 * r(2)),
        s * (0.5 + 0.2 * r(3)),
        s * (0.45 + 0.2 * r(4)),
    );
    let (cx, cy, cr) = (
        s * (0.6 + 0.2 * r(5)),
        s * (0.6 + 0.2 * r(6)),
        s * (0.12 + 0.08 * r(7)),
    );
    let (bg0, bgx, bgy) = (0.2 + 0.1 * r(8), 0.15 * r(9), 0.1 * r(10));
    let (d_rect, d_disc) = (0.55 + 0.15 * r(11), 0.8 + 0.12 * r(12));
    for y in 0..size {
        for x in 0..size {
            let (xf, yf) = (x as f64 + 0.5, y as f64 + 0.5);
            let d = if (xf - cx).hypot(yf - cy) < cr {
                d_disc
            } else if xf > rx0 && xf < rx1 && yf > ry0 && yf < ry1 {
                d_rect
            } else {
                bg0 + bgx * xf / s + bgy * yf / s
            };
            *disp.at_mut(x, y, 0) = T::c(d);
            for c in 0..3u64 {
                let mut v = 0.5;
                for (o, scale) in [(0u64, 3.0), (1, 7.0), (2, 13.0)] {
                    let ph = r(20 + 3 * o + c) * std::f64::consts::TAU;
                    v += 0.15 * ((xf / scale + ph).sin() * (yf / (scale * 1.3) + 2.0 * ph).cos());
                }
                let cell =
                    hash01(seed ^ ((x as u64 / 3) * 7919 + (y as u64 / 3) * 104_729 + c * 31));
                v += 0.2 * (cell - 0.5);
                *aif.at_mut(x, y, c as usize) = T::c(v.clamp(0.02, 0.98));
            }
        }
    }
    let stack = LayerStack::single(aif.clone(), disp.clone())?;
    let defocused = crate::render(&stack, settings, Engine::Threaded, &NoProgress)?;
    Ok(SyntheticPair {
        all_in_focus: aif,
        defocused,
        disparity: disp,
    })
}

/// A loss combination of the experiment.
#[derive(Clone, Copy, Debug)]
pub struct LossCombo {
    /// Display name, e.g. `L1+G+HSSIM`.
    pub name: &'static str,
    /// Weights.
    pub weights: LossWeights,
    /// Structural term.
    pub terms: LossTerms,
}

/// The three combinations of the paper's ablation.
pub fn paper_combos() -> Vec<LossCombo> {
    let p = LossWeights::PAPER;
    vec![
        LossCombo {
            name: "L1+G",
            weights: LossWeights { hssim: 0.0, ..p },
            terms: LossTerms::Hssim,
        },
        LossCombo {
            name: "L1+G+SSIM",
            weights: p,
            terms: LossTerms::SingleSsim,
        },
        LossCombo {
            name: "L1+G+HSSIM",
            weights: p,
            terms: LossTerms::Hssim,
        },
    ]
}

/// One row of results: a layer and loss combination, averaged over pairs.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ExperimentRow {
    /// Rendering layer.
    pub layer: &'static str,
    /// Loss combination.
    pub losses: &'static str,
    /// Mean over pairs.
    pub errors: DisparityErrors,
    /// Per pair.
    pub per_pair: Vec<DisparityErrors>,
    /// Wall time in seconds for all pairs.
    pub seconds: f64,
}

/// Runs every layer with every combination on every pair. `template` gives the schedule
/// and the camera; `on_run` is called after each (layer, combo, pair).
pub fn run_experiment<T: Real>(
    pairs: &[SyntheticPair<T>],
    layers: &[RenderLayer],
    combos: &[LossCombo],
    template: &DfdOptions,
    on_run: &mut dyn FnMut(&str),
) -> Result<Vec<ExperimentRow>> {
    let mut rows = Vec::new();
    for &layer in layers {
        for combo in combos {
            let t0 = std::time::Instant::now();
            let mut per_pair = Vec::new();
            for (i, pair) in pairs.iter().enumerate() {
                let mut opts = template.clone();
                opts.layer = layer;
                opts.weights = combo.weights;
                opts.terms = combo.terms;
                let est =
                    estimate_disparity(&pair.all_in_focus, &pair.defocused, &opts, &mut |_| {})?;
                per_pair.push(disparity_errors(&est.disparity, &pair.disparity));
                on_run(&format!("{} {} pair {}", layer.name(), combo.name, i));
            }
            let n = per_pair.len() as f64;
            let mean = |f: fn(&DisparityErrors) -> f64| per_pair.iter().map(f).sum::<f64>() / n;
            rows.push(ExperimentRow {
                layer: layer.name(),
                losses: combo.name,
                errors: DisparityErrors {
                    mae: mean(|e| e.mae),
                    rmse: mean(|e| e.rmse),
                    within_1_25: mean(|e| e.within_1_25),
                },
                per_pair,
                seconds: t0.elapsed().as_secs_f64(),
            });
        }
    }
    Ok(rows)
}

/// Formats rows as a Markdown table.
pub fn markdown_table(rows: &[ExperimentRow]) -> String {
    let mut s = String::from("| layer | losses | MAE | RMSE | < 1.25x | seconds |\n| --- | --- | ---: | ---: | ---: | ---: |\n");
    for r in rows {
        s += &format!(
            "| {} | {} | {:.4} | {:.4} | {:.3} | {:.1} |\n",
            r.layer, r.losses, r.errors.mae, r.errors.rmse, r.errors.within_1_25, r.seconds
        );
    }
    s
}
