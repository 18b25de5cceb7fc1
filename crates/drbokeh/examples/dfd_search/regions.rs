//! `colsplit=1`: moves that split a region of the estimate by colour. A thin near structure
//! (strands, a grid) over a plain far background comes out of the sweep as one fattened
//! block at the structure's disparity; no one-pixel or one-segment move to a neighbour's
//! value separates the structure from the gaps inside the block. Here each region of the
//! estimate (4-connected, within `tol` of a seed) is cut into two colour classes of the
//! all-in-focus image (2-means), and each class in turn is proposed the disparity of the
//! farther pixels around the region (what the gaps would show); the better proposal is
//! kept where the judge's loss on the crop falls.
use crate::search::Search;
use crate::segments::{median, neighbours4};

use drbokeh::Image;

/// What the region moves did.
pub struct RegionReport {
    pub regions: usize,
    pub proposed: usize,
    pub kept: usize,
}

/// The 4-connected regions grown from each seed pixel `s` over the pixels `n` for which
/// `joins(s, n)`, at least `min_px` pixels each.
fn flood(
    w: usize,
    h: usize,
    min_px: usize,
    joins: impl Fn(usize, usize) -> bool,
) -> Vec<Vec<usize>> {
    let mut seen = vec![false; w * h];
    let mut out = Vec::new();
    for s in 0..w * h {
        if seen[s] {
            continue;
        }
        seen[s] = true;
        let mut members = vec![s];
        let mut k = 0;
        while k < members.len() {
            let i = members[k];
            k += 1;
            for n in neighbours4(i, w, h) {
                if !seen[n] && joins(s, n) {
                    seen[n] = true;
                    members.push(n);
                }
            }
        }
        if members.len() >= min_px {
            out.push(members);
        }
    }
    out
}

/// Two colour classes of `pixels` in `aif` (2-means from the darkest and the brightest
/// pixel); `None` where a class is under 5 % of the pixels or the classes' centres are
/// closer than 0.1.
fn two_classes(aif: &Image<f32>, pixels: &[usize]) -> Option<(Vec<usize>, Vec<usize>)> {
    let rgb = |i: usize| [aif.data[3 * i], aif.data[3 * i + 1], aif.data[3 * i + 2]];
    let lum = |i: usize| rgb(i).iter().sum::<f32>();
    let dark = *pixels.iter().min_by(|&&a, &&b| lum(a).total_cmp(&lum(b)))?;
    let bright = *pixels.iter().max_by(|&&a, &&b| lum(a).total_cmp(&lum(b)))?;
    let mut c = [rgb(dark), rgb(bright)];
    let dist = |p: [f32; 3], q: [f32; 3]| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>();
    let mut assign = vec![0usize; pixels.len()];
    for _ in 0..10 {
        let mut sum = [[0f32; 3]; 2];
        let mut n = [0usize; 2];
        for (j, &i) in pixels.iter().enumerate() {
            let p = rgb(i);
            let a = usize::from(dist(p, c[1]) < dist(p, c[0]));
            assign[j] = a;
            n[a] += 1;
            for k in 0..3 {
                sum[a][k] += p[k];
            }
        }
        for a in 0..2 {
            if n[a] > 0 {
                c[a] = std::array::from_fn(|k| sum[a][k] / n[a] as f32);
            }
        }
    }
    let class = |k: usize| -> Vec<usize> {
        pixels
            .iter()
            .zip(&assign)
            .filter(|&(_, &a)| a == k)
            .map(|(&i, _)| i)
            .collect()
    };
    let (a, b) = (class(0), class(1));
    let min = (pixels.len() / 20).max(1);
    if a.len() < min || b.len() < min || dist(c[0], c[1]).sqrt() < 0.1 {
        return None;
    }
    Some((a, b))
}

/// One pass of colour-split moves over the regions of `cur` (largest first); the value
/// proposed is the `quantile` of the farther values just outside the region.
pub fn colour_split(
    search: &Search,
    aif: &Image<f32>,
    cur: &mut Image<f32>,
    tol: f32,
    min_px: usize,
    quantile: f32,
) -> RegionReport {
    let (w, h) = (cur.width, cur.height);
    // tol < 0: the regions are the connected pieces of the layers of the decomposition of
    // `cur` into at most -tol layers (its cuts); else regions grown from a seed over values
    // within `tol` of the seed's (so that a smooth ramp does not chain into one region).
    let mut regs = if tol < 0.0 {
        let opts = drbokeh::layering::LayeringOptions {
            max_layers: (-tol) as usize,
            ..Default::default()
        };
        let (_, owner) = crate::edges::cut(aif, cur, &opts);
        flood(w, h, min_px, |s, n| owner[n] == owner[s])
    } else {
        flood(w, h, min_px, |s, n| (cur.data[n] - cur.data[s]).abs() < tol)
    };
    regs.sort_by_key(|r| std::cmp::Reverse(r.len()));
    let mut report = RegionReport {
        regions: regs.len(),
        proposed: 0,
        kept: 0,
    };
    let mut inside = vec![false; w * h];
    for reg in &regs {
        for &i in reg {
            inside[i] = true;
        }
        let level = median(reg.iter().map(|&i| cur.data[i]).collect());
        // The farther pixels just outside the region.
        let mut around = Vec::new();
        for &i in reg {
            for n in neighbours4(i, w, h) {
                if !inside[n] && cur.data[n] < level - search.mindiff {
                    around.push(cur.data[n]);
                }
            }
        }
        for &i in reg {
            inside[i] = false;
        }
        if around.len() < 10 {
            continue;
        }
        around.sort_by(f32::total_cmp);
        let behind = around[((around.len() - 1) as f32 * quantile).round() as usize];
        let Some((a, b)) = two_classes(aif, reg) else {
            continue;
        };
        report.proposed += 1;
        let mut best: Option<(f64, &Vec<usize>)> = None;
        for class in [&a, &b] {
            let (base, l) = search.losses(cur, class, &[behind]);
            let g = (base - l[0]) / base;
            eprintln!(
                "    region {} px at {level:.2}: class of {} px -> {behind:.2}: gain {g:+.4}",
                reg.len(),
                class.len()
            );
            if g > search.gain && best.map_or(true, |(bg, _)| g > bg) {
                best = Some((g, class));
            }
        }
        if let Some((_, class)) = best {
            report.kept += 1;
            for &i in class {
                cur.data[i] = behind;
            }
        }
    }
    report
}
