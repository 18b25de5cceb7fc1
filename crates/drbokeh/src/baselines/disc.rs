//! The disc baselines: naive gather, naive scatter and the layered disc blur (module docs
//! of [`crate::baselines`] say what each models and ignores).
//!
//! **The anti-aliased disc.** Each pixel row of a disc of radius `rho` is sampled at four
//! sub-rows `t`; a sub-row is the chord `|dx| <= h = sqrt(rho^2 - t^2)`, and each pixel
//! column gets the length of the chord inside it (full pixels 1, the two end pixels a
//! fraction). So the kernel is round even for small radii, its weight is continuous in
//! `rho`, and its area is close to `pi rho^2`. Chords are summed with per-row prefix sums,
//! so a disc costs `O(rho)` per pixel, not `O(rho^2)`.

use crate::camera::Camera;
use crate::image::Image;
use crate::model;
use crate::stack::LayerStack;
use crate::{Error, Real, Result};
use rayon::prelude::*;

/// Default number of disparity planes of [`layered_disc`].
pub const LAYERED_PLANES: usize = 32;

/// The smallest disc radius (pixels): a disc of radius 1/2 is exactly one pixel.
pub const MIN_DISC_RADIUS_PX: f64 = 0.5;

/// The CoC radius of a pixel: `max(K |disp - f|, MIN_DISC_RADIUS_PX)` pixels.
pub fn coc_radius_px(camera: &Camera, disparity: f64) -> f64 {
    (camera.blur_k * (disparity - camera.focus_disparity).abs()).max(MIN_DISC_RADIUS_PX)
}

/// Sub-rows per pixel row when the disc is area-sampled vertically.
const SUB_ROWS: usize = 4;

/// One horizontal run of the disc within a pixel row: columns `|dx| <= full` weigh
/// `inner`, columns `|dx| = full + 1` weigh `edge`.
#[derive(Clone, Copy, Debug)]
struct Run {
    full: isize,
    inner: f64,
    edge: f64,
}

/// Pixel row `dy` of the anti-aliased disc of radius `rho`, as [`SUB_ROWS`] runs (one per
/// sub-row, each weighted `1 / SUB_ROWS`): sub-row `t` is the chord `|dx| <= h =
/// sqrt(rho^2 - t^2)`, and each pixel column gets the length of the chord inside it (a chord
/// shorter than a pixel puts all of it on `dx = 0`). Sub-rows outside the disc weigh 0.
#[inline]
fn disc_row(rho: f64, dy: isize) -> [Run; SUB_ROWS] {
    let sub = SUB_ROWS as f64;
    std::array::from_fn(|k| {
        let t = dy as f64 + (k as f64 + 0.5) / sub - 0.5;
        let h2 = rho * rho - t * t;
        if h2 <= 0.0 {
            return Run {
                full: 0,
                inner: 0.0,
                edge: 0.0,
            };
        }
        let h = h2.sqrt();
        let f = h - 0.5;
        if f < 0.0 {
            return Run {
                full: 0,
                inner: 2.0 * h / sub,
                edge: 0.0,
            };
        }
        let full = f.floor();
        Run {
            full: full as isize,
            inner: 1.0 / sub,
            edge: (f - full) / sub,
        }
    })
}

/// Rows `-n..=n` reached by the disc of radius `rho`.
#[inline]
fn disc_rows(rho: f64) -> isize {
    (rho + 0.5).ceil() as isize
}

/// The total weight (area) of the anti-aliased disc of radius `rho`.
fn disc_area(rho: f64) -> f64 {
    let n = disc_rows(rho);
    (-n..=n)
        .flat_map(|dy| disc_row(rho, dy))
        .map(|r| r.inner * (2 * r.full + 1) as f64 + 2.0 * r.edge)
        .sum()
}

/// Per-row prefix sums of `ch`-channel data: `p[(y * (w + 1) + x) * ch + c]` is the sum of
/// columns `< x` of row `y`.
fn row_prefix_sums(data: &[f32], w: usize, h: usize, ch: usize) -> Vec<f64> {
    let mut p = vec![0.0f64; h * (w + 1) * ch];
    p.par_chunks_mut((w + 1) * ch)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                for c in 0..ch {
                    row[(x + 1) * ch + c] = row[x * ch + c] + data[(y * w + x) * ch + c] as f64;
                }
            }
        });
    p
}

/// Normalised disc average of `ch`-channel `data` around every pixel, with the disc radius
/// of pixel `i` given by `radius(i)`: `sum_y k(x - y) v(y) / sum_y k(x - y)` over in-image
/// pixels. Parallel over rows; deterministic.
fn disc_gather(
    data: &[f32],
    w: usize,
    h: usize,
    ch: usize,
    radius: &(dyn Fn(usize) -> f64 + Sync),
) -> Vec<f32> {
    let p = row_prefix_sums(data, w, h, ch);
    let mut out = vec![0.0f32; w * h * ch];
    out.par_chunks_mut(w * ch).enumerate().for_each(|(y, row)| {
        let mut acc = vec![0.0f64; ch];
        for x in 0..w {
            let rho = radius(y * w + x);
            let n = disc_rows(rho);
            acc.iter_mut().for_each(|a| *a = 0.0);
            let mut wsum = 0.0f64;
            for dy in -n..=n {
                let sy = y as isize + dy;
                if sy < 0 || sy >= h as isize {
                    continue;
                }
                let sy = sy as usize;
                let base = sy * (w + 1) * ch;
                for run in disc_row(rho, dy) {
                    if run.inner <= 0.0 {
                        continue;
                    }
                    let lo = (x as isize - run.full).max(0) as usize;
                    let hi = (x as isize + run.full).min(w as isize - 1) as usize;
                    for c in 0..ch {
                        acc[c] += run.inner * (p[base + (hi + 1) * ch + c] - p[base + lo * ch + c]);
                    }
                    wsum += run.inner * (hi + 1 - lo) as f64;
                    if run.edge > 0.0 {
                        for sx in [x as isize - run.full - 1, x as isize + run.full + 1] {
                            if sx >= 0 && sx < w as isize {
                                for c in 0..ch {
                                    acc[c] +=
                                        run.edge * data[(sy * w + sx as usize) * ch + c] as f64;
                                }
                                wsum += run.edge;
                            }
                        }
                    }
                }
            }
            for c in 0..ch {
                row[x * ch + c] = (acc[c] / wsum) as f32;
            }
        }
    });
    out
}

/// Validated camera and image + disparity pair; returns the linear colour (f32, 3 channels).
fn linear_input<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    camera: &Camera,
) -> Result<Vec<f32>> {
    camera.validate()?;
    LayerStack::single(aif.clone(), disparity.clone())?;
    let (g, off) = (camera.gamma, camera.offset);
    Ok(aif
        .data
        .iter()
        .map(|v| model::linearize(v.f64(), g, off) as f32)
        .collect())
}

/// Encodes linear RGB with the camera's transfer.
fn encode_output<T: Real>(lin: &[f32], w: usize, h: usize, camera: &Camera) -> Image<T> {
    let (g, off) = (camera.gamma, camera.offset);
    Image {
        width: w,
        height: h,
        channels: 3,
        data: lin
            .iter()
            .map(|&v| T::c(model::encode((v as f64).max(0.0), g, off)))
            .collect(),
    }
}

/// Naive gather: every pixel is the average of the linear colour over the anti-aliased
/// disc of its own CoC radius `max(K |disp - f|, 1/2)`. See the module docs for what it
/// models and ignores.
pub fn naive_gather<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    camera: &Camera,
) -> Result<Image<T>> {
    let lin = linear_input(aif, disparity, camera)?;
    let (w, h) = (aif.width, aif.height);
    let radii: Vec<f64> = disparity
        .data
        .iter()
        .map(|d| coc_radius_px(camera, d.f64()))
        .collect();
    let out = disc_gather(&lin, w, h, 3, &|i| radii[i]);
    Ok(encode_output(&out, w, h, camera))
}

/// Naive scatter: every source pixel spreads its linear colour over the anti-aliased disc
/// of its own CoC radius with weight `1 / area` (unit energy), with no depth test; each
/// receiver divides the colour it received by the weight it received. Computed as a gather
/// over source rows (one output row at a time, row segments accumulated in a difference
/// buffer), so it is parallel and deterministic.
pub fn naive_scatter<T: Real>(
    aif: &Image<T>,
    disparity: &Image<T>,
    camera: &Camera,
) -> Result<Image<T>> {
    let lin = linear_input(aif, disparity, camera)?;
    let (w, h) = (aif.width, aif.height);
    let radii: Vec<f64> = disparity
        .data
        .iter()
        .map(|d| coc_radius_px(camera, d.f64()))
        .collect();
    // Source weights 1/area, with areas cached per distinct radius (layers are often flat).
    let mut cache: Vec<(f64, f64)> = Vec::new();
    let inv_area: Vec<f64> = radii
        .iter()
        .map(|&r| {
            if let Some(&(_, a)) = cache.iter().find(|(cr, _)| *cr == r) {
                return a;
            }
            let a = 1.0 / disc_area(r);
            if cache.len() < 64 {
                cache.push((r, a));
            }
            a
        })
        .collect();
    let rmax = disc_rows(radii.iter().cloned().fold(0.0, f64::max));
    let mut out = vec![0.0f32; w * h * 3];
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        // diff[x] holds (r, g, b, weight) increments starting at column x.
        let mut diff = vec![[0.0f64; 4]; w + 1];
        for dy in -rmax..=rmax {
            let sy = y as isize + dy;
            if sy < 0 || sy >= h as isize {
                continue;
            }
            let sy = sy as usize;
            for sx in 0..w {
                let j = sy * w + sx;
                if (dy.unsigned_abs() as isize) > disc_rows(radii[j]) {
                    continue;
                }
                let wt = inv_area[j];
                let v = [
                    lin[3 * j] as f64 * wt,
                    lin[3 * j + 1] as f64 * wt,
                    lin[3 * j + 2] as f64 * wt,
                    wt,
                ];
                let mut add = |lo: isize, hi: isize, s: f64| {
                    let lo = lo.max(0);
                    let hi = hi.min(w as isize - 1);
                    if lo > hi {
                        return;
                    }
                    for c in 0..4 {
                        diff[lo as usize][c] += s * v[c];
                        diff[hi as usize + 1][c] -= s * v[c];
                    }
                };
                let sx = sx as isize;
                for run in disc_row(radii[j], dy) {
                    if run.inner <= 0.0 {
                        continue;
                    }
                    add(sx - run.full, sx + run.full, run.inner);
                    if run.edge > 0.0 {
                        add(sx - run.full - 1, sx - run.full - 1, run.edge);
                        add(sx + run.full + 1, sx + run.full + 1, run.edge);
                    }
                }
            }
        }
        let mut run = [0.0f64; 4];
        for x in 0..w {
            for c in 0..4 {
                run[c] += diff[x][c];
            }
            // Every pixel receives at least its own disc's centre, so run[3] > 0.
            let wsum = run[3].max(1e-300);
            for c in 0..3 {
                row[3 * x + c] = (run[c] / wsum) as f32;
            }
        }
    });
    Ok(encode_output(&out, w, h, camera))
}

/// Layered disc blur with `planes` disparity planes (see the module docs).
///
/// The disparity range of the stack's visible content (pixels with alpha > 0) is cut into
/// `planes` equal bins. Each layer pixel goes to the plane of its disparity, premultiplied
/// (`a * lin, a`); two layers meeting in one plane are composited there front over back.
/// A plane's disparity is the alpha-weighted mean disparity of its content, its disc the
/// CoC of that disparity. Planes are blurred (normalised disc average of premultiplied
/// colour and alpha) and composited back to front: `acc = P + (1 - A) acc`. The result is
/// not renormalised by the accumulated coverage: where no plane has content the output is
/// dark, as in a classical layered renderer without inpainting.
pub fn layered_disc<T: Real>(
    stack: &LayerStack<T>,
    camera: &Camera,
    planes: usize,
) -> Result<Image<T>> {
    stack.validate()?;
    camera.validate()?;
    if planes == 0 || planes > 4096 {
        return Err(Error::param(
            "planes",
            format!("number of planes must be in 1..=4096, got {planes}"),
        ));
    }
    let (w, h) = (stack.width, stack.height);
    let (g, off) = (camera.gamma, camera.offset);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for l in &stack.layers {
        for (a, d) in l.alpha.data.iter().zip(&l.disparity.data) {
            if a.f64() > 0.0 {
                lo = lo.min(d.f64());
                hi = hi.max(d.f64());
            }
        }
    }
    let mut acc = vec![0.0f32; w * h * 3];
    if !lo.is_finite() {
        // Nothing visible at all.
        return Ok(encode_output(&acc, w, h, camera));
    }
    let span = hi - lo;
    let bin = |d: f64| -> usize {
        if span <= 0.0 {
            0
        } else {
            (((d - lo) / span * planes as f64).floor() as usize).min(planes - 1)
        }
    };
    let lin: Vec<Vec<f32>> = stack
        .layers
        .iter()
        .map(|l| {
            l.rgb_encoded
                .data
                .iter()
                .map(|v| model::linearize(v.f64(), g, off) as f32)
                .collect()
        })
        .collect();
    // Far planes (small disparity) first.
    for p in 0..planes {
        let mut plane = vec![0.0f32; w * h * 4];
        let (mut dsum, mut asum) = (0.0f64, 0.0f64);
        for (l, layer) in stack.layers.iter().enumerate() {
            for i in 0..w * h {
                let a = layer.alpha.data[i].f64();
                let d = layer.disparity.data[i].f64();
                if a <= 0.0 || bin(d) != p {
                    continue;
                }
                // Layers come front first: the new one goes under what is already there.
                let t = 1.0 - plane[4 * i + 3];
                for c in 0..3 {
                    plane[4 * i + c] += t * a as f32 * lin[l][3 * i + c];
                }
                plane[4 * i + 3] += t * a as f32;
                dsum += a * d;
                asum += a;
            }
        }
        if asum <= 0.0 {
            continue;
        }
        let rho = coc_radius_px(camera, dsum / asum);
        let blurred = disc_gather(&plane, w, h, 4, &|_| rho);
        acc.par_chunks_mut(3)
            .zip(blurred.par_chunks(4))
            .for_each(|(o, b)| {
                let t = 1.0 - b[3];
                for c in 0..3 {
                    o[c] = b[c] + t * o[c];
                }
            });
    }
    Ok(encode_output(&acc, w, h, camera))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::baselines::Baseline;

    #[test]
    fn disc_area_is_close_to_pi_r2_and_continuous() {
        for rho in [0.5, 1.0, 1.5, 2.5, 7.3, 20.0] {
            let a = disc_area(rho);
            let exact = std::f64::consts::PI * rho * rho;
            assert!(
                (a - exact).abs() / exact < 0.06,
                "rho {rho}: {a} vs {exact}"
            );
        }
        // The smallest disc is the centre pixel alone.
        let n = disc_rows(MIN_DISC_RADIUS_PX);
        for dy in -n..=n {
            for r in disc_row(MIN_DISC_RADIUS_PX, dy) {
                assert!(r.full == 0 && r.edge == 0.0 && (dy == 0 || r.inner == 0.0));
            }
        }
        // Continuous in the radius, and round: as wide as it is tall.
        let (a, b) = (disc_area(2.0 - 1e-9), disc_area(2.0 + 1e-9));
        assert!((a - b).abs() < 1e-3);
        let rho = 3.2;
        let width: f64 = disc_row(rho, 0)
            .iter()
            .map(|r| r.inner * (2 * r.full + 1) as f64 + 2.0 * r.edge)
            .sum();
        let n = disc_rows(rho);
        let rows = (-n..=n)
            .filter(|&dy| disc_row(rho, dy).iter().any(|r| r.inner > 0.0))
            .count();
        assert_eq!(rows, 7);
        assert!((width - 2.0 * rho).abs() < 0.3, "{width}");
    }

    #[test]
    fn flat_images_stay_flat() {
        let aif = Image::from_vec(20, 14, 3, vec![0.4f64; 20 * 14 * 3]).unwrap();
        let disp = Image::from_vec(
            20,
            14,
            1,
            (0..20 * 14).map(|i| (i % 7) as f64 / 6.0).collect(),
        )
        .unwrap();
        let mut cam = Camera::paper_default(0.3);
        cam.blur_k = 8.0;
        for b in Baseline::ALL {
            let stack = LayerStack::single(aif.clone(), disp.clone()).unwrap();
            let out = b.render(&stack, &cam).unwrap();
            if b == Baseline::LayeredDisc {
                // Holes between planes make the layered renderer lose coverage.
                continue;
            }
            for v in &out.data {
                assert!((v - 0.4).abs() < 1e-5, "{}: {v}", b.name());
            }
        }
    }
}
