//! Clipped highlights of the all-in-focus image ([`super::Highlights::Model`]).
//!
//! A pixel at white in the all-in-focus image may have been many times brighter; the
//! defocused image shows how bright, as the energy of its bokeh ball. Blur moves light but
//! keeps it: summed over a region that holds a highlight and every ball it can make (the
//! highlight's neighbourhood dilated by the largest blur radius), the linear defocused
//! image carries as much light as the true all-in-focus image. The missing light, target
//! minus clipped all-in-focus summed over that region, is the highlights' lost energy; it
//! is shared equally among the region's clipped pixels (per channel). Regions whose
//! neighbourhoods touch are merged. This gives the highlights a starting brightness that
//! does not depend on the disparity; the optimiser then refines each one.

/// Initial log gains of the clipped channels `clipped_idx` (indices into the interleaved
/// RGB data) from energy conservation (see the module documentation). `aif_lin` and
/// `target_lin` are linear RGB of `w x h`; `reach_px` is the largest blur radius.
pub(super) fn energy_log_gains(
    aif_lin: &[f64],
    target_lin: &[f64],
    clipped_idx: &[usize],
    w: usize,
    h: usize,
    reach_px: f64,
    max_log_gain: f64,
) -> Vec<f64> {
    if clipped_idx.is_empty() {
        return Vec::new();
    }
    let mut seed = vec![false; w * h];
    for &i in clipped_idx {
        seed[i / 3] = true;
    }
    let region = super::maps::dilate(&seed, w, h, reach_px);
    // Label the connected parts of the dilated region (4-connected).
    let mut label = vec![usize::MAX; w * h];
    let mut n_labels = 0;
    let mut stack = Vec::new();
    for start in 0..w * h {
        if !region[start] || label[start] != usize::MAX {
            continue;
        }
        label[start] = n_labels;
        stack.push(start);
        while let Some(p) = stack.pop() {
            let (x, y) = (p % w, p / w);
            let mut visit = |q: usize| {
                if region[q] && label[q] == usize::MAX {
                    label[q] = n_labels;
                    stack.push(q);
                }
            };
            if x > 0 {
                visit(p - 1);
            }
            if x + 1 < w {
                visit(p + 1);
            }
            if y > 0 {
                visit(p - w);
            }
            if y + 1 < h {
                visit(p + w);
            }
        }
        n_labels += 1;
    }
    // Per region and channel: missing energy and the clipped channels' linear sum.
    let mut missing = vec![[0.0f64; 3]; n_labels];
    for p in 0..w * h {
        if label[p] == usize::MAX {
            continue;
        }
        for c in 0..3 {
            missing[label[p]][c] += target_lin[3 * p + c] - aif_lin[3 * p + c];
        }
    }
    let mut clipped_sum = vec![[0.0f64; 3]; n_labels];
    for &i in clipped_idx {
        clipped_sum[label[i / 3]][i % 3] += aif_lin[i];
    }
    clipped_idx
        .iter()
        .map(|&i| {
            let (l, c) = (label[i / 3], i % 3);
            let gain = 1.0 + (missing[l][c] / clipped_sum[l][c].max(1e-12)).max(0.0);
            gain.ln().clamp(0.0, max_log_gain)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A highlight of 6x white blurred into a ball: the energy estimate finds the gain.
    #[test]
    fn energy_gain_recovers_a_blurred_highlight() {
        let (w, h) = (40, 40);
        let bg = 0.2;
        let mut aif = vec![bg; w * h * 3];
        let centre = 20 * w + 20;
        for c in 0..3 {
            aif[3 * centre + c] = 1.0; // clipped
        }
        // The target: 6x white spread over a disc of radius 5 on the background.
        let mut target = vec![bg; w * h * 3];
        let disc: Vec<usize> = (0..w * h)
            .filter(|&p| {
                let (x, y) = ((p % w) as f64 - 20.0, (p / w) as f64 - 20.0);
                x * x + y * y <= 25.0
            })
            .collect();
        let per = (6.0 - bg) / disc.len() as f64;
        for &p in &disc {
            for c in 0..3 {
                target[3 * p + c] += per;
            }
        }
        let idx: Vec<usize> = (0..3).map(|c| 3 * centre + c).collect();
        let g = energy_log_gains(&aif, &target, &idx, w, h, 7.0, 4.6);
        for v in g {
            assert!((v.exp() - 6.0).abs() < 0.05, "gain {}", v.exp());
        }
    }
}
