//! Hole filling for smooth maps: push-pull (mean pyramid) and a smooth membrane fill.
//!
//! Push-pull: known pixels are averaged down a 2x pyramid (weights carried),
//! then holes are filled from the coarsest level that has data, back up to full size.

use crate::image::Image;
use crate::Real;
use rayon::prelude::*;

/// Fills the pixels where `known` is false from the known ones; known pixels are kept
/// exactly. With no known pixel at all the image is returned unchanged.
pub fn push_pull_fill<T: Real>(image: &Image<T>, known: &[bool]) -> Image<T> {
    let ch = image.channels;
    let mut levels: Vec<(usize, usize, Vec<f64>, Vec<f64>)> = Vec::new();
    let values: Vec<f64> = image
        .data
        .iter()
        .enumerate()
        .map(|(i, v)| if known[i / ch] { v.f64() } else { 0.0 })
        .collect();
    let weights: Vec<f64> = known.iter().map(|&k| if k { 1.0 } else { 0.0 }).collect();
    if !weights.iter().any(|w| *w > 0.0) {
        return image.clone();
    }
    levels.push((image.width, image.height, values, weights));
    // Push: premultiplied sums over 2x2 blocks.
    while {
        let (w, h, _, _) = levels.last().unwrap();
        *w > 1 || *h > 1
    } {
        let (w, h, v, wt) = levels.last().unwrap();
        let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
        let mut nv = vec![0.0; nw * nh * ch];
        let mut nwt = vec![0.0; nw * nh];
        for y in 0..*h {
            for x in 0..*w {
                let (i, j) = (y * w + x, (y / 2) * nw + x / 2);
                nwt[j] += wt[i];
                for c in 0..ch {
                    nv[j * ch + c] += v[i * ch + c] * wt[i];
                }
            }
        }
        for j in 0..nw * nh {
            if nwt[j] > 0.0 {
                for c in 0..ch {
                    nv[j * ch + c] /= nwt[j];
                }
                nwt[j] = nwt[j].min(1.0);
            }
        }
        levels.push((nw, nh, nv, nwt));
    }
    // Pull: fill each level's holes from the (already filled) coarser level.
    for l in (0..levels.len() - 1).rev() {
        let (cw, _, cv, _) = levels[l + 1].clone();
        let (w, h, v, wt) = &mut levels[l];
        for y in 0..*h {
            for x in 0..*w {
                let i = y * *w + x;
                if wt[i] < 1.0 {
                    let j = (y / 2) * cw + x / 2;
                    for c in 0..ch {
                        v[i * ch + c] = v[i * ch + c] * wt[i] + cv[j * ch + c] * (1.0 - wt[i]);
                    }
                    wt[i] = 1.0;
                }
            }
        }
    }
    let mut out = image.clone();
    for (i, o) in out.data.iter_mut().enumerate() {
        if !known[i / ch] {
            *o = T::c(levels[0].2[i]);
        }
    }
    out
}

/// Smooth (membrane) fill: the pixels where `known` is false are set to an approximately
/// harmonic interpolation of the known ones (the solution of Laplace's equation with the
/// known pixels fixed and zero-gradient conditions at the image border). Known pixels are kept
/// exactly. Every filled value is a convex combination of known values, so it stays
/// within their range per channel, and only known pixels are ever read: a fill from the
/// background side of an edge never takes a foreground value.
///
/// Solved coarse to fine: known pixels are averaged down a 2x pyramid, the coarsest level
/// is filled first, and each finer level starts its unknown pixels from a bilinear
/// upsampling of the level below and relaxes them with damped Jacobi sweeps (parallel
/// over rows, deterministic). Cost is linear in the pixel count. With no known pixel at
/// all the image is returned unchanged.
pub fn smooth_fill<T: Real>(image: &Image<T>, known: &[bool]) -> Image<T> {
    let (w, h, ch) = (image.width, image.height, image.channels);
    assert_eq!(known.len(), w * h, "known mask size");
    if !known.iter().any(|k| *k) {
        return image.clone();
    }
    let vals: Vec<f32> = image
        .data
        .iter()
        .enumerate()
        .map(|(i, v)| if known[i / ch] { v.f64() as f32 } else { 0.0 })
        .collect();
    let filled = membrane(w, h, ch, vals, known.to_vec(), 0);
    let mut out = image.clone();
    for (i, o) in out.data.iter_mut().enumerate() {
        if !known[i / ch] {
            *o = T::c(filled[i] as f64);
        }
    }
    out
}

fn membrane(w: usize, h: usize, ch: usize, v: Vec<f32>, known: Vec<bool>, level: u32) -> Vec<f32> {
    if known.iter().all(|k| *k) {
        return v;
    }
    let (cw, chh) = (w.div_ceil(2), h.div_ceil(2));
    let mut cv = vec![0f32; cw * chh * ch];
    let mut cn = vec![0u32; cw * chh];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if known[i] {
                let j = (y / 2) * cw + x / 2;
                cn[j] += 1;
                for c in 0..ch {
                    cv[j * ch + c] += v[i * ch + c];
                }
            }
        }
    }
    for j in 0..cw * chh {
        if cn[j] > 0 {
            for c in 0..ch {
                cv[j * ch + c] /= cn[j] as f32;
            }
        }
    }
    let cknown: Vec<bool> = cn.iter().map(|n| *n > 0).collect();
    let coarse = membrane(cw, chh, ch, cv, cknown, level + 1);
    // Bilinear upsampling into the unknown pixels.
    let mut cur = v;
    let coord = |x: usize, n: usize| -> (usize, usize, f32) {
        let f = ((x as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (n - 1) as f32);
        let x0 = f.floor() as usize;
        (x0, (x0 + 1).min(n - 1), f - x0 as f32)
    };
    cur.par_chunks_mut(w * ch).enumerate().for_each(|(y, row)| {
        let (y0, y1, b) = coord(y, chh);
        for x in 0..w {
            if known[y * w + x] {
                continue;
            }
            let (x0, x1, a) = coord(x, cw);
            for c in 0..ch {
                let g = |xx: usize, yy: usize| coarse[(yy * cw + xx) * ch + c];
                row[x * ch + c] = (1.0 - b) * ((1.0 - a) * g(x0, y0) + a * g(x1, y0))
                    + b * ((1.0 - a) * g(x0, y1) + a * g(x1, y1));
            }
        }
    });
    // Damped Jacobi relaxation of Laplace's equation on the unknown pixels.
    const OMEGA: f32 = 0.8;
    let iterations = (6usize << level.min(4)).min(64);
    let mut next = cur.clone();
    for _ in 0..iterations {
        next.par_chunks_mut(w * ch)
            .enumerate()
            .for_each(|(y, row)| {
                for x in 0..w {
                    let i = y * w + x;
                    if known[i] {
                        continue;
                    }
                    for c in 0..ch {
                        let mut s = 0.0f32;
                        let mut n = 0.0f32;
                        if x > 0 {
                            s += cur[(i - 1) * ch + c];
                            n += 1.0;
                        }
                        if x + 1 < w {
                            s += cur[(i + 1) * ch + c];
                            n += 1.0;
                        }
                        if y > 0 {
                            s += cur[(i - w) * ch + c];
                            n += 1.0;
                        }
                        if y + 1 < h {
                            s += cur[(i + w) * ch + c];
                            n += 1.0;
                        }
                        let old = cur[i * ch + c];
                        row[x * ch + c] = if n > 0.0 {
                            (1.0 - OMEGA) * old + OMEGA * s / n
                        } else {
                            old
                        };
                    }
                }
            });
        std::mem::swap(&mut cur, &mut next);
    }
    cur
}
