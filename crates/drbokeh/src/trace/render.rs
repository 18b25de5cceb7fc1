//! The Monte Carlo passes: the defocused image (pixel area x pupil) and the pinhole passes
//! through the chief ray (all-in-focus image, per-billboard layers, depth).
//!
//! Rows are traced in parallel; every pixel seeds its own generator from (seed, pass,
//! row, column), so the bytes do not depend on the number of threads.

use super::optics::Ray;
use super::sampling::{strata_side, stratified_pattern, Rng};
use super::scene::Scene;
use crate::image::Image;
use crate::{Error, Progress, Result};
use rayon::prelude::*;

const PASS_DEFOCUS: u64 = 0xD3F0;
const PASS_PINHOLE: u64 = 0x9141;

/// Composites the billboards along a ray, front to back (premultiplied linear RGB), each
/// looked up at its mip level.
#[inline]
fn composite(scene: &Scene, levels: &[usize], ray: &Ray) -> [f32; 3] {
    let mut acc = [0.0f32; 3];
    let mut transmit = 1.0f32;
    for (b, &level) in scene.billboards.iter().zip(levels) {
        let t = b.lookup_level(ray, level);
        if t[3] > 0.0 || t[0] > 0.0 {
            for c in 0..3 {
                acc[c] += transmit * t[c];
            }
            transmit *= 1.0 - t[3];
            if transmit <= 1e-6 {
                break;
            }
        }
    }
    acc
}

fn side(spp: usize, name: &str) -> Result<usize> {
    strata_side(spp).ok_or_else(|| {
        Error::param(
            name,
            format!("samples per pixel must be a perfect square (e.g. 256, 1024), got {spp}"),
        )
    })
}

/// Renders the ground-truth defocused image in linear light (3 channels): each pixel
/// averages `spp` rays (stratified over pixel area and over the aperture stop) through the
/// lens. Rays the lens blocks (outside the rim, total internal reflection) are left out of
/// the average, so vignetting does not darken the frame. Each billboard is looked up at the
/// mip level matching one pupil stratum's footprint ([`super::scene::Billboard::footprint_level`]):
/// cheap shading, much less noise from fine texture under large blur. Reports one progress
/// unit per row (the caller calls `progress.start`).
pub fn render_defocus(
    scene: &Scene,
    spp: usize,
    seed: u64,
    progress: &dyn Progress,
) -> Result<Image<f32>> {
    let n = side(spp, "render.spp")?;
    let o = &scene.optics;
    let (w, h) = (o.width_px, o.height_px);
    let levels: Vec<usize> = scene
        .billboards
        .iter()
        .map(|b| b.footprint_level(o, spp))
        .collect();
    let rows: Vec<Vec<f32>> = (0..h)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(pix, pupil), y| {
                let mut row = vec![0.0f32; w * 3];
                for x in 0..w {
                    let mut rng = Rng::from_words(&[seed, PASS_DEFOCUS, y as u64, x as u64]);
                    stratified_pattern(&mut rng, n, pix, pupil);
                    let mut sum = [0.0f64; 3];
                    let mut count = 0u32;
                    for (p, q) in pix.iter().zip(pupil.iter()) {
                        let sensor = o.sensor_point(x as f64 + p.0, y as f64 + p.1);
                        if let Some(ray) = o.trace(sensor, *q) {
                            let c = composite(scene, &levels, &ray);
                            for k in 0..3 {
                                sum[k] += c[k] as f64;
                            }
                            count += 1;
                        }
                    }
                    if count > 0 {
                        for k in 0..3 {
                            row[x * 3 + k] = (sum[k] / count as f64) as f32;
                        }
                    }
                }
                progress.advance(1);
                row
            },
        )
        .collect();
    Image::from_vec(w, h, 3, rows.concat())
}

/// One billboard as seen through the chief ray, averaged over pixel area.
#[derive(Clone, Debug)]
pub struct LayerImages {
    /// Straight (not premultiplied) linear colour, 3 channels (0 where alpha is 0).
    pub rgb_linear: Image<f32>,
    /// Coverage in [0, 1], 1 channel.
    pub alpha: Image<f32>,
}

/// The outputs of the pinhole (chief-ray) passes.
#[derive(Clone, Debug)]
pub struct PinholeImages {
    /// All-in-focus image in linear light (front-to-back composite per ray, averaged).
    pub aif_linear: Image<f32>,
    /// One layer per billboard, front first.
    pub layers: Vec<LayerImages>,
    /// Metric depth (mm, from the front principal plane) of the most visible billboard.
    pub depth_mm: Image<f32>,
}

/// Renders the all-in-focus image, the per-billboard layers and the depth map through the
/// chief ray (the lens stopped down to the centre of its stop, so the projection equals
/// that of the defocused image), with `spp` stratified pixel-area samples.
pub fn render_pinhole(
    scene: &Scene,
    spp: usize,
    seed: u64,
    progress: &dyn Progress,
) -> Result<PinholeImages> {
    let n = side(spp, "render.aif_spp")?;
    let o = &scene.optics;
    let (w, h) = (o.width_px, o.height_px);
    let nl = scene.billboards.len();
    // Per row: aif (w*3), layers premultiplied (nl * w * 4), visibility weights (nl * w).
    let rows: Vec<(Vec<f32>, Vec<f32>, Vec<f32>)> = (0..h)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(pix, pupil), y| {
                let mut aif = vec![0.0f32; w * 3];
                let mut layers = vec![0.0f32; nl * w * 4];
                let mut vis = vec![0.0f32; nl * w];
                let mut lsum = vec![[0.0f64; 5]; nl];
                for x in 0..w {
                    let mut rng = Rng::from_words(&[seed, PASS_PINHOLE, y as u64, x as u64]);
                    stratified_pattern(&mut rng, n, pix, pupil);
                    lsum.iter_mut().for_each(|v| *v = [0.0; 5]);
                    let mut sum = [0.0f64; 3];
                    let mut count = 0u32;
                    for p in pix.iter() {
                        let sensor = o.sensor_point(x as f64 + p.0, y as f64 + p.1);
                        let Some(ray) = o.chief_ray(sensor) else {
                            continue;
                        };
                        count += 1;
                        let mut transmit = 1.0f64;
                        for (l, b) in scene.billboards.iter().enumerate() {
                            let t = b.lookup(&ray);
                            for c in 0..4 {
                                lsum[l][c] += t[c] as f64;
                            }
                            lsum[l][4] += transmit * t[3] as f64;
                            for c in 0..3 {
                                sum[c] += transmit * t[c] as f64;
                            }
                            transmit *= 1.0 - t[3] as f64;
                        }
                    }
                    if count == 0 {
                        continue;
                    }
                    let inv = 1.0 / count as f64;
                    for c in 0..3 {
                        aif[x * 3 + c] = (sum[c] * inv) as f32;
                    }
                    for l in 0..nl {
                        let a = lsum[l][3] * inv;
                        let base = (l * w + x) * 4;
                        for c in 0..3 {
                            layers[base + c] = if a > 0.0 {
                                (lsum[l][c] * inv / a) as f32
                            } else {
                                0.0
                            };
                        }
                        layers[base + 3] = a.clamp(0.0, 1.0) as f32;
                        vis[l * w + x] = (lsum[l][4] * inv) as f32;
                    }
                }
                progress.advance(1);
                (aif, layers, vis)
            },
        )
        .collect();
    let mut aif = Vec::with_capacity(w * h * 3);
    let mut layer_rgb = vec![Vec::with_capacity(w * h * 3); nl];
    let mut layer_a = vec![Vec::with_capacity(w * h); nl];
    let mut depth = Vec::with_capacity(w * h);
    for (a, l, v) in &rows {
        aif.extend_from_slice(a);
        for layer in 0..nl {
            for x in 0..w {
                let base = (layer * w + x) * 4;
                layer_rgb[layer].extend_from_slice(&l[base..base + 3]);
                layer_a[layer].push(l[base + 3]);
            }
        }
        for x in 0..w {
            // The most visible billboard (largest composite weight); the farthest if none.
            let mut best = (nl - 1, 0.0f32);
            for layer in 0..nl {
                let wgt = v[layer * w + x];
                if wgt > best.1 {
                    best = (layer, wgt);
                }
            }
            depth.push(scene.billboards[best.0].depth_mm as f32);
        }
    }
    let layers = layer_rgb
        .into_iter()
        .zip(layer_a)
        .map(|(rgb, a)| {
            Ok(LayerImages {
                rgb_linear: Image::from_vec(w, h, 3, rgb)?,
                alpha: Image::from_vec(w, h, 1, a)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(PinholeImages {
        aif_linear: Image::from_vec(w, h, 3, aif)?,
        layers,
        depth_mm: Image::from_vec(w, h, 1, depth)?,
    })
}
