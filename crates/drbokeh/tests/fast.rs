//! The fast engine against the reference engine: exactness contract (<= 1e-5 in linear
//! light, max abs) on multi-band, multi-tile images with partial alpha, several layers and
//! every aperture shape; identical output for any thread count.

mod common;

use common::{random_stack, settings};
use drbokeh::aperture::KernelImage;
use drbokeh::presets::ModelOptions;
use drbokeh::HighlightBoost;
use drbokeh::{render, Aperture, Engine, Image, Layer, LayerStack, NoProgress};

fn max_linear_diff<A: drbokeh::Real, B: drbokeh::Real>(
    a: &Image<A>,
    b: &Image<B>,
    gamma: f64,
) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x.f64().powf(gamma) - y.f64().powf(gamma)).abs())
        .fold(0.0, f64::max)
}

fn apertures() -> Vec<Aperture> {
    let n = 11;
    let mut grey = Image::<f64>::new(n, n, 1);
    for y in 0..n {
        for x in 0..n {
            let r = ((x as f64 - 5.0).powi(2) + (y as f64 - 5.0).powi(2)).sqrt();
            grey.data[y * n + x] = if r < 5.0 { 1.0 - 0.1 * r } else { 0.0 };
        }
    }
    vec![
        Aperture::Circle,
        Aperture::Polygon {
            blades: 6,
            rotation_deg: 10.0,
        },
        Aperture::Kernel(KernelImage::new(&grey).unwrap()),
    ]
}

/// A blob-shaped stack: layers with large empty regions (exercises tile skipping) as well
/// as the random stack's partial alpha.
fn blobs(w: usize, h: usize) -> LayerStack<f64> {
    let mut front = Layer::<f64>::constant(w, h, [0.9, 0.4, 0.1], 0.0, 0.85);
    let mut back = Layer::<f64>::constant(w, h, [0.0; 3], 1.0, 0.1);
    for y in 0..h {
        for x in 0..w {
            let r = ((x as f64 - 20.0).powi(2) + (y as f64 - 45.0).powi(2)).sqrt();
            front.alpha.data[y * w + x] = (1.0 - (r - 9.0) / 2.0).clamp(0.0, 1.0);
            for c in 0..3 {
                back.rgb_encoded.data[3 * (y * w + x) + c] = ((x / 5 + y / 7 + c) % 3) as f64 / 2.0;
            }
            back.disparity.data[y * w + x] = 0.1 + 0.3 * x as f64 / w as f64;
        }
    }
    LayerStack::new(vec![front, back]).unwrap()
}

#[test]
fn fast_matches_reference_on_random_stacks() {
    for (i, aperture) in apertures().into_iter().enumerate() {
        let stack = random_stack::<f64>(30 + i as u64, 70, 67, 3);
        let s = settings(0.5, 14.0, 21, aperture.clone());
        let reference = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
        let fast64 = render(&stack, &s, Engine::Fast, &NoProgress).unwrap();
        let fast32 = render(&stack.cast::<f32>(), &s, Engine::Fast, &NoProgress).unwrap();
        let d64 = max_linear_diff(&reference, &fast64, 2.2);
        let d32 = max_linear_diff(&reference, &fast32, 2.2);
        assert!(d64 <= 1e-5, "{aperture:?}: f64 fast vs reference {d64:e}");
        assert!(d32 <= 1e-5, "{aperture:?}: f32 fast vs reference {d32:e}");
    }
}

#[test]
fn fast_matches_reference_with_empty_regions_and_large_blur() {
    let stack = blobs(75, 90);
    for (focus, k, window) in [(0.85, 30.0, 51), (0.1, 40.0, 61), (0.5, 5.0, 9)] {
        for aperture in apertures() {
            let s = settings(focus, k, window, aperture.clone());
            let reference = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
            let fast = render(&stack.cast::<f32>(), &s, Engine::Fast, &NoProgress).unwrap();
            let d = max_linear_diff(&reference, &fast, 2.2);
            assert!(d <= 1e-5, "focus {focus} K {k} {aperture:?}: {d:e}");
        }
    }
}

#[test]
fn fast_is_identical_for_any_thread_count() {
    let stack = random_stack::<f32>(8, 90, 100, 2);
    let mut s = settings(0.3, 20.0, 31, Aperture::Circle);
    s.camera.highlight = Some(HighlightBoost::PAPER);
    let run = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| render(&stack, &s, Engine::Fast, &NoProgress).unwrap())
    };
    let one = run(1);
    for n in [2, 3, 5] {
        assert_eq!(one.data, run(n).data);
    }
}

/// `max |a^2.4-ish - b|` in linear light for the sRGB transfer.
fn max_linear_diff_srgb<A: drbokeh::Real, B: drbokeh::Real>(a: &Image<A>, b: &Image<B>) -> f64 {
    let lin = |v: f64| drbokeh::model::srgb_to_linear_with_derivative(v).0;
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (lin(x.f64()) - lin(y.f64())).abs())
        .fold(0.0, f64::max)
}

#[test]
fn fast_matches_reference_for_the_physical_preset() {
    for (i, aperture) in apertures().into_iter().enumerate() {
        let stack = random_stack::<f64>(40 + i as u64, 70, 53, 3);
        let s = settings(0.5, 14.0, 21, aperture.clone()).with_model(ModelOptions::PHYSICAL);
        let reference = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
        let fast64 = render(&stack, &s, Engine::Fast, &NoProgress).unwrap();
        let fast32 = render(&stack.cast::<f32>(), &s, Engine::Fast, &NoProgress).unwrap();
        let d64 = max_linear_diff_srgb(&reference, &fast64);
        let d32 = max_linear_diff_srgb(&reference, &fast32);
        assert!(d64 <= 1e-5, "{aperture:?}: f64 fast vs reference {d64:e}");
        assert!(d32 <= 1e-5, "{aperture:?}: f32 fast vs reference {d32:e}");
    }
    let stack = blobs(75, 90);
    for (focus, k, window) in [(0.85, 30.0, 41), (0.5, 2.0, 9)] {
        for aperture in apertures() {
            let s = settings(focus, k, window, aperture.clone()).with_model(ModelOptions::PHYSICAL);
            let reference = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
            let fast = render(&stack.cast::<f32>(), &s, Engine::Fast, &NoProgress).unwrap();
            let d = max_linear_diff_srgb(&reference, &fast);
            assert!(d <= 1e-5, "focus {focus} K {k} {aperture:?}: {d:e}");
        }
    }
}
