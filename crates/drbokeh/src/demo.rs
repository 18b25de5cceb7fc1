//! The built-in demo scene: three procedural layers, deterministic, no files needed.
//!
//! - front (disparity 0.9): dark leaves and thin stems with soft, matting-like edges;
//! - subject (disparity 0.55, the default focus): a striped, shaded ball on a stand;
//! - background (disparity 0.05 to 0.15): a dusk gradient with small bright lights that
//!   turn into bokeh balls. The lights are high dynamic range, as real lights are: their
//!   linear intensity is [`LIGHT_GAIN`] (6 to 30) times white, stored as display-encoded
//!   values above 1 (`gain^(1/2.2)`), so that spread over a blur disc they stay bright.

use crate::image::Image;
use crate::stack::{Layer, LayerStack};
use crate::Real;

/// The focus disparity that puts the demo's subject in focus.
pub const DEMO_FOCUS: f64 = 0.55;
/// The number of layers of the demo stack.
pub const LAYERS: u64 = 3;
/// The demo's default size.
pub const DEMO_SIZE: (usize, usize) = (640, 426);

/// The range of the demo lights' linear intensities, in units of white (1.0): a light
/// of radius 2.5 px spread over a blur disc of radius 13.5 px (the default view) keeps
/// about 1/30 of its intensity per pixel, so lights at 1.0 (clipped at white) would
/// render as dim grey discs.
pub const LIGHT_GAIN: (f64, f64) = (6.0, 30.0);

/// A small deterministic hash to [0, 1) (no RNG crate needed for fixed content).
fn hash01(i: u64) -> f64 {
    let mut x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

/// A leaf: centre, semi-axes (pixels) and orientation (radians).
type Leaf = ((f64, f64), (f64, f64), f64);

/// Soft coverage of a shape from its signed distance in pixels (negative inside).
fn soft_edge(signed_distance_px: f64, width_px: f64) -> f64 {
    (0.5 - signed_distance_px / width_px).clamp(0.0, 1.0)
}

/// Distance from p to the segment a-b.
fn segment_distance(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (vx, vy) = (b.0 - a.0, b.1 - a.1);
    let t = (((p.0 - a.0) * vx + (p.1 - a.1) * vy) / (vx * vx + vy * vy)).clamp(0.0, 1.0);
    ((p.0 - a.0 - t * vx).powi(2) + (p.1 - a.1 - t * vy).powi(2)).sqrt()
}

/// Builds the demo stack at `width x height` (content scales with the size).
pub fn scene<T: Real>(width: usize, height: usize) -> LayerStack<T> {
    let s = width.min(height) as f64 / 426.0;
    let (wf, hf) = (width as f64, height as f64);
    let mut layers = Vec::new();

    // Front layer: leaves (ellipses) on stems entering from the lower-left corner.
    let mut front = Layer::<T>::constant(width, height, [0.0; 3], 0.0, 0.9);
    let leaves: Vec<Leaf> = (0..9)
        .map(|i| {
            let t = i as f64 / 8.0;
            let c = (
                wf * (0.02 + 0.42 * t),
                hf * (0.98 - 0.45 * t + 0.08 * hash01(i)),
            );
            let axes = (s * (34.0 - 10.0 * t), s * (13.0 - 3.0 * t));
            (c, axes, 0.6 + 1.2 * hash01(i + 50))
        })
        .collect();
    let stems: Vec<((f64, f64), (f64, f64))> = (0..7)
        .map(|i| {
            let t = i as f64 / 6.0;
            (
                (0.0, hf * (0.7 + 0.3 * t)),
                (wf * (0.15 + 0.3 * hash01(i + 9)), hf * (0.35 + 0.5 * t)),
            )
        })
        .collect();
    for y in 0..height {
        for x in 0..width {
            let p = (x as f64 + 0.5, y as f64 + 0.5);
            let mut a: f64 = 0.0;
            let mut green = 0.0;
            for &(c, axes, angle) in &leaves {
                let (dx, dy) = (p.0 - c.0, p.1 - c.1);
                let (u, v) = (
                    dx * angle.cos() + dy * angle.sin(),
                    -dx * angle.sin() + dy * angle.cos(),
                );
                let rho = ((u / axes.0).powi(2) + (v / axes.1).powi(2)).sqrt();
                let cov = soft_edge((rho - 1.0) * axes.1, 2.0 * s);
                if cov > a {
                    a = cov;
                    green = 0.35 + 0.25 * (1.0 - rho).max(0.0) + 0.1 * (u / axes.0 * 6.0).sin();
                }
            }
            for &(p0, p1) in &stems {
                let cov = 0.85 * soft_edge(segment_distance(p, p0, p1) - 0.6 * s, 1.5);
                if cov > a {
                    a = cov;
                    green = 0.3;
                }
            }
            *front.alpha.at_mut(x, y, 0) = T::c(a);
            let rgb = [0.12 * green, green, 0.18 * green];
            for (c, v) in rgb.iter().enumerate() {
                *front.rgb_encoded.at_mut(x, y, c) = T::c(v.clamp(0.0, 1.0));
            }
        }
    }
    layers.push(front);

    // Subject: a striped ball on a thin stand, in focus at DEMO_FOCUS.
    let mut subject = Layer::<T>::constant(width, height, [0.0; 3], 0.0, DEMO_FOCUS);
    let (cx, cy, rad) = (wf * 0.6, hf * 0.45, 95.0 * s);
    for y in 0..height {
        for x in 0..width {
            let p = (x as f64 + 0.5, y as f64 + 0.5);
            let (dx, dy) = (p.0 - cx, p.1 - cy);
            let dist = (dx * dx + dy * dy).sqrt();
            let ball = soft_edge(dist - rad, 1.5);
            let stand = soft_edge(
                segment_distance(p, (cx, cy + rad * 0.9), (cx, hf * 1.1)) - 6.0 * s,
                1.5,
            );
            let a = ball.max(stand);
            let shade = if ball >= stand {
                let nz = (1.0 - (dist / rad).min(1.0).powi(2)).sqrt();
                let light = 0.25 + 0.75 * (nz * 0.8 - dx / rad * 0.3 - dy / rad * 0.3).max(0.0);
                let stripe = ((dx + dy * 0.4) / (11.0 * s)).sin() > 0.0;
                let base = if stripe {
                    [0.95, 0.55, 0.15]
                } else {
                    [0.95, 0.92, 0.85]
                };
                base.map(|b| b * light)
            } else {
                [0.3, 0.3, 0.32]
            };
            *subject.alpha.at_mut(x, y, 0) = T::c(a);
            for (c, v) in shade.iter().enumerate() {
                *subject.rgb_encoded.at_mut(x, y, c) = T::c(v.clamp(0.0, 1.0));
            }
        }
    }
    layers.push(subject);

    // Background: dusk gradient, a far ground plane, and small bright lights.
    let mut bg = Layer::<T>::constant(width, height, [0.0; 3], 1.0, 0.05);
    let lights: Vec<(f64, f64, [f64; 3])> = (0..70)
        .map(|i| {
            let warm = hash01(i + 300);
            let linear_gain = LIGHT_GAIN.0 + (LIGHT_GAIN.1 - LIGHT_GAIN.0) * hash01(i + 400);
            // Display-encoded (gamma 2.2, the default view's transfer): above 1.
            let encoded_gain = linear_gain.powf(1.0 / 2.2);
            let col = [1.0, 0.75 + 0.25 * warm, 0.45 + 0.5 * (1.0 - warm)];
            (
                wf * hash01(i + 100),
                hf * (0.1 + 0.6 * hash01(i + 200)),
                col.map(|c| c * encoded_gain),
            )
        })
        .collect();
    for y in 0..height {
        for x in 0..width {
            let v = y as f64 / hf;
            let mut rgb = [0.05 + 0.25 * v * v, 0.06 + 0.15 * v * v, 0.20 - 0.05 * v];
            for &(lx, ly, col) in &lights {
                let d = ((x as f64 + 0.5 - lx).powi(2) + (y as f64 + 0.5 - ly).powi(2)).sqrt();
                let k = soft_edge(d - 2.5 * s, 1.0);
                for c in 0..3 {
                    rgb[c] = rgb[c] * (1.0 - k) + col[c] * k;
                }
            }
            *bg.disparity.at_mut(x, y, 0) = T::c(0.05 + 0.1 * v * v);
            for (c, val) in rgb.iter().enumerate() {
                // Not clipped at 1: the lights are HDR.
                *bg.rgb_encoded.at_mut(x, y, c) = T::c(val.max(0.0));
            }
        }
    }
    layers.push(bg);
    LayerStack::new(layers).expect("demo scene is valid by construction")
}

/// The demo's disparity as seen from the camera (frontmost layer with alpha >= 0.5).
pub fn visible_disparity<T: Real>(stack: &LayerStack<T>) -> Image<T> {
    let mut out = Image::new(stack.width, stack.height, 1);
    for y in 0..stack.height {
        for x in 0..stack.width {
            *out.at_mut(x, y, 0) = T::c(stack.disparity_at(x, y).unwrap_or(0.0));
        }
    }
    out
}
