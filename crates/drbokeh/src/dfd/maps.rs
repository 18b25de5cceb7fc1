//! Per-pixel maps of the optimiser: 2x2 pooling and its adjoint, bilinear upsampling, box
//! and edge-aware window means, dilation.

use crate::image::Image;
use crate::model::Tone;
use crate::Real;

/// 2x2 average pooling of a per-pixel vector (`ch` values per pixel), dropping an odd last
/// row or column (as [`loss::pyramid::avg_pool2`]).
pub(super) fn pool(data: &[f64], w: usize, h: usize, ch: usize) -> Vec<f64> {
    let (pw, ph) = (w / 2, h / 2);
    let mut out = vec![0.0; pw * ph * ch];
    for y in 0..ph {
        for x in 0..pw {
            for c in 0..ch {
                let at = |xx: usize, yy: usize| data[(yy * w + xx) * ch + c];
                out[(y * pw + x) * ch + c] = 0.25
                    * (at(2 * x, 2 * y)
                        + at(2 * x + 1, 2 * y)
                        + at(2 * x, 2 * y + 1)
                        + at(2 * x + 1, 2 * y + 1));
            }
        }
    }
    out
}

/// The adjoint of [`pool`]: spreads a pooled gradient back onto `w x h`.
pub(super) fn pool_adjoint(grad: &[f64], w: usize, h: usize, ch: usize) -> Vec<f64> {
    let (pw, ph) = (w / 2, h / 2);
    let mut out = vec![0.0; w * h * ch];
    for y in 0..ph {
        for x in 0..pw {
            for c in 0..ch {
                let g = 0.25 * grad[(y * pw + x) * ch + c];
                for (xx, yy) in [
                    (2 * x, 2 * y),
                    (2 * x + 1, 2 * y),
                    (2 * x, 2 * y + 1),
                    (2 * x + 1, 2 * y + 1),
                ] {
                    out[(yy * w + xx) * ch + c] += g;
                }
            }
        }
    }
    out
}

/// Bilinear upsampling of a one-channel map from `sw x sh` to `w x h` (pixel centres
/// aligned as for 2x pooling: fine pixel `x` sits at coarse `(x + 0.5) / 2 - 0.5`).
pub(super) fn upsample(data: &[f64], sw: usize, sh: usize, w: usize, h: usize) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    let (fx_scale, fy_scale) = (sw as f64 / w as f64, sh as f64 / h as f64);
    for y in 0..h {
        let fy = ((y as f64 + 0.5) * fy_scale - 0.5).clamp(0.0, (sh - 1) as f64);
        let (y0, ty) = (fy.floor() as usize, fy - fy.floor());
        let y1 = (y0 + 1).min(sh - 1);
        for x in 0..w {
            let fx = ((x as f64 + 0.5) * fx_scale - 0.5).clamp(0.0, (sw - 1) as f64);
            let (x0, tx) = (fx.floor() as usize, fx - fx.floor());
            let x1 = (x0 + 1).min(sw - 1);
            out[y * w + x] = (1.0 - ty)
                * ((1.0 - tx) * data[y0 * sw + x0] + tx * data[y0 * sw + x1])
                + ty * ((1.0 - tx) * data[y1 * sw + x0] + tx * data[y1 * sw + x1]);
        }
    }
    out
}

/// Mean over a `(2r+1)^2` box (clamped to the image) of a one-channel map (summed-area
/// table).
pub(super) fn box_mean(data: &[f64], w: usize, h: usize, r: usize) -> Vec<f64> {
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0.0;
        for x in 0..w {
            row += data[y * w + x];
            sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
            let s = sat[y1 * (w + 1) + x1] - sat[y0 * (w + 1) + x1] - sat[y1 * (w + 1) + x0]
                + sat[y0 * (w + 1) + x0];
            out[y * w + x] = s / ((y1 - y0) * (x1 - x0)) as f64;
        }
    }
    out
}

/// Marks every pixel within `radius` of a pixel where `seed` holds.
pub(super) fn dilate(seed: &[bool], w: usize, h: usize, radius: f64) -> Vec<bool> {
    let r = radius.ceil() as isize;
    let mut out = vec![false; w * h];
    let offsets: Vec<(isize, isize)> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .filter(|&(dx, dy)| ((dx * dx + dy * dy) as f64) <= radius * radius)
        .collect();
    for y in 0..h as isize {
        for x in 0..w as isize {
            if !seed[y as usize * w + x as usize] {
                continue;
            }
            for &(dx, dy) in &offsets {
                let (xx, yy) = (x + dx, y + dy);
                if xx >= 0 && yy >= 0 && xx < w as isize && yy < h as isize {
                    out[yy as usize * w + xx as usize] = true;
                }
            }
        }
    }
    out
}

/// A per-pixel vector as an image.
pub(super) fn to_image<T: Real>(data: &[f64], w: usize, h: usize, ch: usize) -> Image<T> {
    Image {
        width: w,
        height: h,
        channels: ch,
        data: data.iter().map(|&v| T::c(v)).collect(),
    }
}

/// Linear values to an encoded image.
pub(super) fn encode_image<T: Real>(lin: &[f64], w: usize, h: usize, tone: &Tone) -> Image<T> {
    Image {
        width: w,
        height: h,
        channels: 3,
        data: lin.iter().map(|&v| T::c(tone.encode(v.max(0.0)))).collect(),
    }
}

/// Bins of [`weighted_median`]'s histogram over [0, 1].
const MEDIAN_BINS: usize = 256;

/// Edge-aware weighted median of a one-channel map with values in [0, 1] over a
/// `(2r+1)^2` window: each neighbour `y` of `x` weighs `exp(-|I(x) - I(y)|^2 / (2
/// sigma^2))` (`|.|^2` the mean over channels of the guide's squared difference), and `x`
/// takes the value where the cumulative weight reaches one half. Values are binned into
/// [`MEDIAN_BINS`] bins, and the result is the centre of the median bin, refined linearly
/// within it.
pub(super) fn weighted_median(
    data: &[f64],
    guide: &[[f64; 3]],
    w: usize,
    h: usize,
    r: usize,
    sigma: f64,
) -> Vec<f64> {
    use rayon::prelude::*;
    let inv = 1.0 / (2.0 * 3.0 * sigma * sigma);
    let bin_of = |v: f64| ((v.clamp(0.0, 1.0) * MEDIAN_BINS as f64) as usize).min(MEDIAN_BINS - 1);
    let bins: Vec<usize> = data.iter().map(|&v| bin_of(v)).collect();
    (0..w * h)
        .into_par_iter()
        .map_init(
            || vec![0.0f64; MEDIAN_BINS],
            |hist, i| {
                hist.iter_mut().for_each(|v| *v = 0.0);
                let (x, y) = (i % w, i / w);
                let g = guide[i];
                let mut total = 0.0;
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        let j = yy * w + xx;
                        let q = guide[j];
                        let d2 =
                            (g[0] - q[0]).powi(2) + (g[1] - q[1]).powi(2) + (g[2] - q[2]).powi(2);
                        let wt = (-d2 * inv).exp();
                        hist[bins[j]] += wt;
                        total += wt;
                    }
                }
                let half = 0.5 * total;
                let mut acc = 0.0;
                for (b, &v) in hist.iter().enumerate() {
                    if acc + v >= half && v > 0.0 {
                        let t = ((half - acc) / v).clamp(0.0, 1.0);
                        return (b as f64 + t) / MEDIAN_BINS as f64;
                    }
                    acc += v;
                }
                data[i]
            },
        )
        .collect()
}

/// Non-local colour vote: every pixel whose all-in-focus colour (display-encoded, in
/// [0, 1]) falls in the same cube of a `bins`^3 grid takes the median disparity of all
/// such pixels in the image (the lower median), provided at least
/// [`COLOUR_VOTE_MAJORITY`] of them lie within [`COLOUR_VOTE_TOLERANCE`] of it. Pixels marked `keep` (clipped highlights,
/// whose colour says nothing about their depth) neither vote nor change. The prior: one
/// surface has one palette, so pixels the sweep and the optimiser got wrong (holes of a
/// fence filled with its disparity, a foreground's blur spread over the background) are
/// outvoted by the many pixels of the same colour elsewhere.
pub(super) fn colour_vote(
    data: &[f64],
    guide: &[[f64; 3]],
    keep: &[bool],
    bins: usize,
) -> Vec<f64> {
    let cube = |c: &[f64; 3]| -> usize {
        c.iter().fold(0, |acc, &v| {
            acc * bins + ((v.clamp(0.0, 1.0) * bins as f64) as usize).min(bins - 1)
        })
    };
    let mut members: Vec<(usize, f64)> = (0..data.len())
        .filter(|&i| !keep[i])
        .map(|i| (cube(&guide[i]), data[i]))
        .collect();
    members.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    // The median of each cube, where its members agree on it.
    let mut median = std::collections::HashMap::new();
    let mut start = 0;
    while start < members.len() {
        let key = members[start].0;
        let end = start + members[start..].partition_point(|m| m.0 == key);
        let m = members[(start + end - 1) / 2].1;
        let near = members[start..end]
            .iter()
            .filter(|v| (v.1 - m).abs() <= COLOUR_VOTE_TOLERANCE)
            .count();
        if near as f64 >= COLOUR_VOTE_MAJORITY * (end - start) as f64 {
            median.insert(key, m);
        }
        start = end;
    }
    (0..data.len())
        .map(|i| match keep[i] {
            true => data[i],
            false => *median.get(&cube(&guide[i])).unwrap_or(&data[i]),
        })
        .collect()
}

/// Disparity distance from a colour cube's median within which a member agrees with it.
const COLOUR_VOTE_TOLERANCE: f64 = 0.1;
/// Fraction of a colour cube's members that must agree with its median for the cube to
/// vote; a colour shared by surfaces at several depths (a texture spanning a depth edge)
/// has no such majority, and its pixels keep their own disparity.
const COLOUR_VOTE_MAJORITY: f64 = 0.5;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pool_adjoint_is_the_transpose_of_pool() {
        let (w, h, ch) = (7, 6, 2);
        let x: Vec<f64> = (0..w * h * ch)
            .map(|i| ((i * 37) % 11) as f64 - 5.0)
            .collect();
        let g: Vec<f64> = (0..(w / 2) * (h / 2) * ch)
            .map(|i| ((i * 13) % 7) as f64 - 3.0)
            .collect();
        let lhs: f64 = pool(&x, w, h, ch).iter().zip(&g).map(|(a, b)| a * b).sum();
        let rhs: f64 = x
            .iter()
            .zip(&pool_adjoint(&g, w, h, ch))
            .map(|(a, b)| a * b)
            .sum();
        assert!((lhs - rhs).abs() < 1e-9);
    }

    #[test]
    fn upsample_keeps_constants_and_ramps() {
        let c = upsample(&[0.3; 12], 4, 3, 8, 6);
        assert!(c.iter().all(|v| (v - 0.3).abs() < 1e-12));
        // A ramp in x stays monotonic.
        let ramp: Vec<f64> = (0..12).map(|i| (i % 4) as f64).collect();
        let up = upsample(&ramp, 4, 3, 8, 6);
        for row in up.chunks(8) {
            assert!(row.windows(2).all(|p| p[1] >= p[0]));
        }
    }

    #[test]
    fn box_mean_matches_a_direct_sum() {
        let (w, h) = (9, 7);
        let d: Vec<f64> = (0..w * h).map(|i| ((i * 31) % 13) as f64).collect();
        let fast = box_mean(&d, w, h, 2);
        for y in 0..h {
            for x in 0..w {
                let (mut s, mut n) = (0.0, 0.0);
                for yy in y.saturating_sub(2)..(y + 3).min(h) {
                    for xx in x.saturating_sub(2)..(x + 3).min(w) {
                        s += d[yy * w + xx];
                        n += 1.0;
                    }
                }
                assert!((fast[y * w + x] - s / n).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn weighted_median_keeps_edges_and_removes_outliers() {
        // Two flat colour regions (left dark, right bright) with a disparity that is 0.2 on
        // the left and 0.8 on the right, plus isolated wrong values: the median removes the
        // outliers and keeps the edge where the colour changes.
        let (w, h) = (16, 9);
        let guide: Vec<[f64; 3]> = (0..w * h)
            .map(|i| if i % w < 8 { [0.1; 3] } else { [0.9; 3] })
            .collect();
        let mut d: Vec<f64> = (0..w * h)
            .map(|i| if i % w < 8 { 0.2 } else { 0.8 })
            .collect();
        d[4 * w + 3] = 0.9;
        d[2 * w + 12] = 0.1;
        let m = weighted_median(&d, &guide, w, h, 3, 0.05);
        for i in 0..w * h {
            let want = if i % w < 8 { 0.2 } else { 0.8 };
            assert!(
                (m[i] - want).abs() < 1.0 / MEDIAN_BINS as f64,
                "{i}: {}",
                m[i]
            );
        }
    }

    #[test]
    fn dilate_reaches_the_radius_only() {
        let (w, h) = (11, 11);
        let mut seed = vec![false; w * h];
        seed[5 * w + 5] = true;
        let d = dilate(&seed, w, h, 3.0);
        assert!(d[5 * w + 8] && d[8 * w + 5] && !d[5 * w + 9] && !d[8 * w + 8]);
    }

    #[test]
    fn colour_vote_outvotes_a_minority_and_keeps_kept_pixels() {
        // Two colours: red pixels mostly at 0.2 (one wrong at 0.9), blue at 0.7; a kept
        // (clipped) pixel of the red colour stays as it was and does not vote.
        let red = [0.9, 0.1, 0.1];
        let blue = [0.1, 0.1, 0.9];
        let guide = [red, red, red, red, blue, blue, blue, red];
        let data = [0.2, 0.2, 0.9, 0.2, 0.7, 0.7, 0.15, 0.95];
        let mut keep = [false; 8];
        keep[7] = true;
        let out = colour_vote(&data, &guide, &keep, 16);
        assert_eq!(&out[..4], &[0.2; 4]);
        assert_eq!(&out[4..7], &[0.7; 3]);
        assert_eq!(out[7], 0.95);
        // One bin per channel merges the colours: of 0.15, 0.2 x3, 0.7 x2 and 0.9, four
        // lie within 0.1 of their median 0.2, a majority.
        let one = colour_vote(&data, &guide, &keep, 1);
        assert!(one[..7].iter().all(|&v| v == 0.2));
        // A colour spread over many depths (a texture across a depth edge) has no
        // majority: its pixels keep their own disparity.
        let spread = [0.1, 0.3, 0.5, 0.7, 0.9, 0.2, 0.4, 0.6];
        let out = colour_vote(&spread, &[red; 8], &[false; 8], 16);
        assert_eq!(out, spread);
    }
}
