//! The span engine against the fast engine (its exact reference): display-encoded output
//! within 1e-3 (max) and 1e-4 (mean) on scenes with partial alpha, several layers, both
//! presets, circle and polygon apertures, in-focus and blurred receivers side by side; each
//! approximation at its worst case; identical output for any thread count.

mod common;

use common::{random_stack, settings};
use drbokeh::presets::ModelOptions;
use drbokeh::{
    render, render_with_stats, Aperture, Engine, Image, Layer, LayerStack, NoProgress,
    RenderSettings,
};

/// `(max, mean)` absolute difference of two display-encoded images.
fn display_diff(a: &Image<f32>, b: &Image<f32>) -> (f64, f64) {
    let (mut max, mut sum) = (0.0f64, 0.0f64);
    for (x, y) in a.data.iter().zip(&b.data) {
        let d = (*x as f64 - *y as f64).abs();
        max = max.max(d);
        sum += d;
    }
    (max, sum / a.data.len() as f64)
}

fn apertures() -> Vec<Aperture> {
    vec![
        Aperture::Circle,
        Aperture::Polygon {
            blades: 6,
            rotation_deg: 10.0,
        },
        Aperture::Polygon {
            blades: 3,
            rotation_deg: 0.0,
        },
    ]
}

fn presets(s: RenderSettings) -> [RenderSettings; 2] {
    [s.clone(), s.with_model(ModelOptions::PHYSICAL)]
}

/// Two layers: an in-focus, partially transparent disc in front of a background whose
/// disparity ramps across focus (in-focus and blurred receivers side by side).
fn blobs(w: usize, h: usize) -> LayerStack<f32> {
    let mut front = Layer::<f32>::constant(w, h, [0.9, 0.4, 0.1], 0.0, 0.85);
    let mut back = Layer::<f32>::constant(w, h, [0.0; 3], 1.0, 0.1);
    for y in 0..h {
        for x in 0..w {
            let r = ((x as f32 - 20.0).powi(2) + (y as f32 - 45.0).powi(2)).sqrt();
            front.alpha.data[y * w + x] = (1.0 - (r - 9.0) / 2.0).clamp(0.0, 1.0);
            for c in 0..3 {
                back.rgb_encoded.data[3 * (y * w + x) + c] = ((x / 5 + y / 7 + c) % 3) as f32 / 2.0;
            }
            back.disparity.data[y * w + x] = 0.1 + 0.8 * x as f32 / w as f32;
        }
    }
    LayerStack::new(vec![front, back]).unwrap()
}

fn check(stack: &LayerStack<f32>, s: &RenderSettings, what: &str) -> (f64, f64) {
    let fast = render(stack, s, Engine::Fast, &NoProgress).unwrap();
    let (spans, stats) = render_with_stats(stack, s, Engine::Spans, &NoProgress).unwrap();
    let (max, mean) = display_diff(&fast, &spans);
    eprintln!("{what}: max {max:.2e} mean {mean:.2e} {stats:?}");
    assert_eq!(stats.tap_layers, 0, "{what}: every band-layer as spans");
    assert!(
        max <= 1e-3 && mean <= 1e-4,
        "{what}: max {max:e} mean {mean:e}"
    );
    (max, mean)
}

#[test]
fn spans_match_fast_on_random_stacks() {
    for (i, aperture) in apertures().into_iter().enumerate() {
        let stack = random_stack::<f32>(50 + i as u64, 90, 77, 3);
        for s in presets(settings(0.5, 20.0, 41, aperture.clone())) {
            check(&stack, &s, &format!("random {aperture:?} {:?}", s.preset));
        }
    }
}

#[test]
fn spans_match_fast_with_focus_and_blur_side_by_side() {
    let stack = blobs(96, 90);
    for (focus, k, window) in [(0.85, 30.0, 61), (0.5, 30.0, 61), (0.3, 100.0, 121)] {
        for aperture in apertures() {
            for s in presets(settings(focus, k, window, aperture.clone())) {
                check(
                    &stack,
                    &s,
                    &format!("blobs f {focus} K {k} {aperture:?} {:?}", s.preset),
                );
            }
        }
    }
}
