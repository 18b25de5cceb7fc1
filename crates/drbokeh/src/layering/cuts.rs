//! Choosing the disparity thresholds that cut a disparity map into depth layers.
//!
//! A neighbour pair (4-connected) is a *discontinuity* when its disparities differ by more
//! than the jump threshold. A threshold `t` on disparity *cuts* a pair when one value lies
//! below `t` and the other at or above it. A good cut separates many discontinuities and
//! crosses few continuous pairs (a slanted floor crossing `t` must be cut somewhere, which
//! costs a seam), so each candidate `t` on a 1024-bin grid over the disparity range is
//! scored `discontinuities cut - continuous pairs cut`. Cuts are chosen greedily: the best
//! `t` (the middle of the best plateau) is taken, the discontinuities it explains are
//! removed, and the search repeats, up to `max_layers - 1` cuts. A cut must separate at
//! least `min_edges` discontinuities, score above zero, and leave every layer at least
//! `min_area` *interior* pixels (pixels whose 4-neighbours all lie in the same layer), so
//! a thin band of mixed edge pixels never becomes a layer of its own.

use rayon::prelude::*;

/// Number of candidate thresholds over the disparity range.
pub(crate) const BINS: usize = 1024;

/// The cuts found in a disparity map.
pub(crate) struct Cuts {
    /// Per-pixel layer index, 0 = nearest (largest disparity).
    pub labels: Vec<u8>,
    /// Number of layers (cuts + 1).
    pub layers: usize,
    /// The thresholds, in disparity units, nearest first (descending).
    pub thresholds: Vec<f64>,
    /// The chosen bins, ascending (threshold `j` puts bins `>= j` on its near side).
    chosen: Vec<usize>,
    /// Lowest disparity and range of the map (bin geometry).
    lo: f32,
    range: f32,
}

/// Keeps only the cuts for which `keep(mean near disparity, mean far disparity)` over the
/// discontinuities (neighbour steps above `jump`) that the cut separates holds, and
/// relabels the pixels for the remaining cuts.
pub(crate) fn keep_blur_relevant(
    cuts: Cuts,
    disp: &[f32],
    w: usize,
    h: usize,
    jump: f32,
    keep: impl Fn(f32, f32) -> bool,
) -> Cuts {
    if cuts.layers < 2 {
        return cuts;
    }
    let nc = cuts.layers - 1;
    // Per cut c (between layers c and c+1): sums of near and far disparities, and counts.
    let mut sums = vec![(0f64, 0f64, 0u64); nc];
    let labels = &cuts.labels;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            for k in [(x + 1 < w).then_some(i + 1), (y + 1 < h).then_some(i + w)]
                .into_iter()
                .flatten()
            {
                if (disp[i] - disp[k]).abs() <= jump || labels[i] == labels[k] {
                    continue;
                }
                let (n, f) = if labels[i] < labels[k] {
                    (i, k)
                } else {
                    (k, i)
                };
                for s in sums
                    .iter_mut()
                    .take(labels[f] as usize)
                    .skip(labels[n] as usize)
                {
                    s.0 += disp[n] as f64;
                    s.1 += disp[f] as f64;
                    s.2 += 1;
                }
            }
        }
    }
    // Cut c has threshold chosen[nc - 1 - c] (chosen is ascending, layers nearest first).
    let kept: Vec<usize> = (0..nc)
        .filter(|&c| {
            let (sn, sf, m) = sums[c];
            m > 0 && keep((sn / m as f64) as f32, (sf / m as f64) as f32)
        })
        .map(|c| cuts.chosen[nc - 1 - c])
        .collect();
    if kept.len() == nc {
        return cuts;
    }
    relabel(disp, kept, cuts.lo, cuts.range)
}

/// Labels and thresholds for the chosen bins.
fn relabel(disp: &[f32], mut chosen: Vec<usize>, lo: f32, range: f32) -> Cuts {
    chosen.sort_unstable();
    let k = chosen.len();
    if k == 0 {
        return Cuts {
            labels: vec![0; disp.len()],
            layers: 1,
            thresholds: vec![],
            chosen,
            lo,
            range,
        };
    }
    let bin_of = |v: f32| (((v - lo) / range * BINS as f32) as usize).min(BINS - 1);
    let labels = disp
        .par_iter()
        .map(|&v| (k - chosen.iter().filter(|&&j| bin_of(v) >= j).count()) as u8)
        .collect();
    let thresholds = chosen
        .iter()
        .rev()
        .map(|&j| lo as f64 + j as f64 * range as f64 / BINS as f64)
        .collect();
    Cuts {
        labels,
        layers: k + 1,
        thresholds,
        chosen,
        lo,
        range,
    }
}

/// Finds up to `max_layers - 1` cuts. `jump` is in disparity units.
pub(crate) fn find_cuts(
    disp: &[f32],
    w: usize,
    h: usize,
    max_layers: usize,
    jump: f32,
    min_edges: u64,
    min_area: u64,
) -> Cuts {
    let n = w * h;
    let (lo, hi) = disp
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let single = Cuts {
        labels: vec![0; n],
        layers: 1,
        thresholds: vec![],
        chosen: vec![],
        lo,
        range: hi - lo,
    };
    let range = hi - lo;
    if range.is_nan() || range <= 0.0 || !range.is_finite() || max_layers < 2 {
        return single;
    }
    let bin_of = |v: f32| (((v - lo) / range * BINS as f32) as usize).min(BINS - 1);
    let bins: Vec<u16> = disp.par_iter().map(|&v| bin_of(v) as u16).collect();
    // Per pixel, the lowest and highest bin over itself and its 4-neighbours: a pixel is
    // *interior* to a layer when no cut falls between them.
    let (mn, mx): (Vec<u16>, Vec<u16>) = (0..n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut lo_b = bins[i];
            let mut hi_b = bins[i];
            for (ok, k) in [
                (x > 0, i.wrapping_sub(1)),
                (x + 1 < w, i + 1),
                (y > 0, i.wrapping_sub(w)),
                (y + 1 < h, i + w),
            ] {
                if ok {
                    lo_b = lo_b.min(bins[k]);
                    hi_b = hi_b.max(bins[k]);
                }
            }
            (lo_b, hi_b)
        })
        .unzip();
    let mut chosen: Vec<usize> = Vec::new();
    while chosen.len() + 1 < max_layers {
        let explained = |a: usize, b: usize| chosen.iter().any(|&j| a < j && j <= b);
        // Difference arrays of discontinuous / continuous pairs cut by each threshold j
        // (a pair with bins a < b is cut by j in a+1..=b).
        let (disc, cont) = (0..h)
            .into_par_iter()
            .fold(
                || (vec![0i64; BINS + 1], vec![0i64; BINS + 1]),
                |(mut disc, mut cont), y| {
                    let mut pair = |i: usize, k: usize| {
                        let (bi, bk) = (bins[i] as usize, bins[k] as usize);
                        if bi == bk {
                            return;
                        }
                        let (a, b) = (bi.min(bk), bi.max(bk));
                        let is_disc = (disp[i] - disp[k]).abs() > jump;
                        if is_disc && explained(a, b) {
                            return;
                        }
                        let arr = if is_disc { &mut disc } else { &mut cont };
                        arr[a + 1] += 1;
                        arr[b + 1] -= 1;
                    };
                    for x in 0..w {
                        let i = y * w + x;
                        if x + 1 < w {
                            pair(i, i + 1);
                        }
                        if y + 1 < h {
                            pair(i, i + w);
                        }
                    }
                    (disc, cont)
                },
            )
            .reduce(
                || (vec![0i64; BINS + 1], vec![0i64; BINS + 1]),
                |(mut d1, mut c1), (d2, c2)| {
                    for j in 0..=BINS {
                        d1[j] += d2[j];
                        c1[j] += c2[j];
                    }
                    (d1, c1)
                },
            );
        // Interior pixels per side: both sides of a cut must keep min_area of them, so a
        // thin band of mixed edge pixels never becomes a layer of its own. A pixel is
        // interior to the lower side of cut j in interval [A, B) when its neighbourhood
        // lies in [A, j), to the upper side when it lies in [j, B).
        let interval = |b: usize| chosen.iter().filter(|&&k| b >= k).count();
        let mut hist_mx = vec![0u64; BINS];
        let mut hist_mn = vec![0u64; BINS];
        for i in 0..n {
            let (a, b) = (mn[i] as usize, mx[i] as usize);
            if interval(a) == interval(b) {
                hist_mx[b] += 1;
                hist_mn[a] += 1;
            }
        }
        let mut interior_below = vec![0u64; BINS]; // pixels of j's interval with mx < j
        let mut interior_above = vec![0u64; BINS + 1]; // pixels of j's interval with mn >= j
        for j in 1..BINS {
            interior_below[j] = if chosen.contains(&j) {
                0
            } else {
                interior_below[j - 1] + hist_mx[j - 1]
            };
        }
        for j in (0..BINS).rev() {
            interior_above[j] = hist_mn[j]
                + if chosen.contains(&(j + 1)) {
                    0
                } else {
                    interior_above[j + 1]
                };
        }
        let mut score = vec![i64::MIN; BINS];
        let (mut d, mut c) = (0i64, 0i64);
        for j in 1..BINS {
            d += disc[j];
            c += cont[j];
            if chosen.contains(&j)
                || d < min_edges as i64
                || d - c <= 0
                || interior_below[j] < min_area
                || interior_above[j] < min_area
            {
                continue;
            }
            score[j] = d - c;
        }
        let Some(best) = (1..BINS).max_by_key(|&j| (score[j], std::cmp::Reverse(j))) else {
            break;
        };
        if score[best] == i64::MIN {
            break;
        }
        let mut end = best;
        while end + 1 < BINS && score[end + 1] == score[best] {
            end += 1;
        }
        chosen.push((best + end) / 2);
    }
    if chosen.is_empty() {
        return single;
    }
    relabel(disp, chosen, lo, range)
}
