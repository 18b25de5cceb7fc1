//! Push-pull hole filling: known pixels are averaged down a 2x pyramid (weights carried),
//! then holes are filled from the coarsest level that has data, back up to full size.

use crate::image::Image;
use crate::Real;

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
