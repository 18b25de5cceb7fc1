//! The fast adjoint (`render_with_tape_on(.., Engine::Fast, ..)`) against the exact adjoint
//! on the threaded schedule, for every input kind (colour, alpha, disparity per layer, K,
//! focus), on multi-layer stacks with partial alpha and empty regions, every aperture
//! shape, both presets, f64 and f32; identical bytes for any thread count; and a forward
//! output identical to `render(.., Engine::Fast, ..)`.
//!
//! Tolerance ([`TAIL_TOLERANCE`]) is derived from what the fast schedule drops; see its
//! doc comment.

mod common;

use common::{
    gradient_kinds, max_abs, max_diff, random_stack, random_weights, settings, tape_bits,
    tape_gradients,
};
use drbokeh::aperture::KernelImage;
use drbokeh::presets::ModelOptions;
use drbokeh::HighlightBoost;
use drbokeh::{
    render, render_with_tape, render_with_tape_on, Aperture, Engine, Image, Layer, LayerStack,
    NoProgress, Real, RenderSettings,
};

/// Largest allowed `|fast - exact|`, relative to the largest exact gradient of the same
/// layer and kind (for K and focus: relative to the exact value).
///
/// Derivation. The fast backward keeps every tap within `r + 6` px of its source (the
/// render's `r + 4.5` ([`drbokeh::model::SCATTER_TAIL_PX`]) plus 1.5 px; the sums recorded
/// by the forward and the soft-disc coverage reach as far), where the soft step is
/// `S <= 0.1 e^{-3 (dist - r)}`; summed over the dropped ring that is a kernel mass of at
/// most `0.21 (r + 6.33) e^{-18}`. Each gradient is a sum of (upstream factor) x (kernel
/// term) over taps; the kept part carries at least the centre tap's mass `S(r)`. The ratio
/// is worst for the soft-disc coverage (preset `physical`, receiver radius
/// `r_c = K |d(x)|` down to 0): `0.21 * 6.33 * 1.52e-8 / S(0) = 2.0e-8 / (1/11) = 2.2e-7`
/// (scatter term, `r >= 0.5`: `0.21 * 6.83 * 1.52e-8 / 0.31 = 7e-8`); derivative sums use
/// `S' = 3 S (1 - S) <= 3 S`: at most 6.6e-7. Gradient sums cancel
/// (`sum_y c(y,x) (Ilin(y) - B(x)) = 0`), so the largest gradient can be smaller than
/// (upstream factor x kept mass); we allow a factor 15 for that (measured: below 3), hence
/// 1e-5. Receivers whose weight sum is of the order of the tail are summed over the whole
/// window (`REFINE_WEIGHT_BELOW` in `engine/fast/adjoint/refine.rs`); `O = 1` where
/// `e(x) < 1e-9` changes O's derivatives by at most `6 K^2 |d| e(x) < 1e-7` here.
/// f64 rounding is below 1e-12. Measured on these scenes: at most 1.9e-6.
const TAIL_TOLERANCE: f64 = 1e-5;

/// A kind whose exact gradient (nearly) vanishes everywhere, e.g. an in-focus layer's
/// disparity under a kernel aperture (5e-7 in one test scene), is measured against this
/// fraction of the layer's largest gradient of any kind: its error comes from the same
/// upstream factors and kernel sums, which do not vanish with it.
const SCALE_FLOOR: f64 = 1e-2;

/// Fast vs exact in f64 (within [`TAIL_TOLERANCE`]) and in f32: the fast f32 gradient must
/// lie within the tail tolerance plus twice the f32 rounding error that the exact adjoint
/// itself shows in f32 (both measured against the exact f64 adjoint).
fn check(name: &str, stack: &LayerStack<f64>, s: &RenderSettings, seed: u64) {
    let g = random_weights(seed, stack.width, stack.height);
    let exact = gradient_kinds(&tape_gradients(stack, s, &g, Engine::Threaded));
    let fast = gradient_kinds(&tape_gradients(stack, s, &g, Engine::Fast));
    let (stack32, g32) = (stack.cast::<f32>(), g.cast::<f32>());
    let exact32 = gradient_kinds(&tape_gradients(&stack32, s, &g32, Engine::Threaded));
    let fast32 = gradient_kinds(&tape_gradients(&stack32, s, &g32, Engine::Fast));
    let mut failures = Vec::new();
    for i in 0..exact.len() {
        let (kind, reference) = (&exact[i].0, &exact[i].1);
        // The layer's largest gradient of any kind (for K and focus: their own value).
        let layer_max = if i + 2 < exact.len() {
            let l0 = i / 3 * 3;
            (l0..l0 + 3)
                .map(|j| max_abs(&exact[j].1))
                .fold(0.0, f64::max)
        } else {
            0.0
        };
        let scale = max_abs(reference).max(SCALE_FLOOR * layer_max);
        assert!(scale > 0.0, "{name}: {kind} is all zero");
        let d64 = max_diff(reference, &fast[i].1);
        if d64 > TAIL_TOLERANCE * scale {
            failures.push(format!(
                "{name} f64 {kind}: max diff {d64:e} > {TAIL_TOLERANCE:e} x {scale:e}"
            ));
        }
        let rounding32 = max_diff(reference, &exact32[i].1);
        let d32 = max_diff(reference, &fast32[i].1);
        if d32 > TAIL_TOLERANCE * scale + 2.0 * rounding32 {
            failures.push(format!(
                "{name} f32 {kind}: max diff {d32:e} > {TAIL_TOLERANCE:e} x {scale:e} + 2 x {rounding32:e}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

fn kernel_aperture() -> Aperture {
    let n = 9;
    let mut grey = Image::<f64>::new(n, n, 1);
    for y in 0..n {
        for x in 0..n {
            let r = ((x as f64 - 4.0).powi(2) + (y as f64 - 4.0).powi(2)).sqrt();
            grey.data[y * n + x] = (1.0 - r / 5.0).max(0.0) * (1.0 + 0.5 * ((x + y) % 3) as f64);
        }
    }
    Aperture::Kernel(KernelImage::new(&grey).unwrap())
}

fn apertures() -> Vec<(&'static str, Aperture)> {
    vec![
        ("circle", Aperture::Circle),
        (
            "pentagon",
            Aperture::Polygon {
                blades: 5,
                rotation_deg: 10.0,
            },
        ),
        ("kernel", kernel_aperture()),
    ]
}

/// Three layers with partial alpha (exact zeros and ones), the middle one near focus (its
/// receivers evaluate the occlusion term), 40x33: several tiles, taps cut by the reach.
#[test]
fn fast_adjoint_matches_exact_paper() {
    for (i, (name, aperture)) in apertures().into_iter().enumerate() {
        let stack = random_stack::<f64>(3 + i as u64, 40, 33, 3);
        let mut s = settings(0.45, 10.0, 25, aperture);
        match i {
            1 => s.camera.highlight = Some(HighlightBoost::PAPER),
            2 => {
                s.camera.gamma = 1.8;
                s.camera.offset = 0.05;
            }
            _ => {}
        }
        check(&format!("paper {name}"), &stack, &s, 5 + i as u64);
    }
}

#[test]
fn fast_adjoint_matches_exact_physical() {
    for (i, (name, aperture)) in apertures().into_iter().enumerate() {
        let stack = random_stack::<f64>(13 + i as u64, 40, 33, 3);
        let mut s = settings(0.45, 10.0, 25, aperture).with_model(ModelOptions::PHYSICAL);
        s.camera.highlight = (i == 1).then_some(HighlightBoost::PAPER);
        check(&format!("physical {name}"), &stack, &s, 15 + i as u64);
    }
}

/// A sharp foreground disc (the rest of its layer empty: alpha exactly 0, whose alpha
/// gradient is still needed) over a blurred textured background, 48x40.
fn blobs(w: usize, h: usize) -> LayerStack<f64> {
    let mut front = Layer::<f64>::constant(w, h, [0.9, 0.4, 0.1], 0.0, 0.85);
    let mut back = Layer::<f64>::constant(w, h, [0.0; 3], 1.0, 0.1);
    for y in 0..h {
        for x in 0..w {
            let r = ((x as f64 - 18.0).powi(2) + (y as f64 - 22.0).powi(2)).sqrt();
            front.alpha.data[y * w + x] = (1.0 - (r - 7.0) / 2.0).clamp(0.0, 1.0);
            front.disparity.data[y * w + x] = 0.85 + 0.002 * x as f64;
            for c in 0..3 {
                back.rgb_encoded.data[3 * (y * w + x) + c] =
                    0.1 + 0.8 * ((x / 5 + y / 7 + c) % 3) as f64 / 2.0;
            }
            back.disparity.data[y * w + x] = 0.1 + 0.3 * x as f64 / w as f64;
        }
    }
    LayerStack::new(vec![front, back]).unwrap()
}

#[test]
fn fast_adjoint_matches_exact_with_empty_regions() {
    let stack = blobs(48, 40);
    for (name, aperture) in apertures() {
        // Focus on the foreground (sharp, occluding) and on the background.
        for (focus, k) in [(0.86, 12.0), (0.2, 9.0)] {
            let s = settings(focus, k, 31, aperture.clone());
            check(&format!("paper {name} f={focus}"), &stack, &s, 21);
            let s = s.with_model(ModelOptions::PHYSICAL);
            check(&format!("physical {name} f={focus}"), &stack, &s, 22);
        }
    }
}

#[test]
fn fast_adjoint_is_identical_for_any_thread_count() {
    let stack = random_stack::<f32>(9, 37, 29, 3);
    let g = random_weights(7, 37, 29).cast::<f32>();
    let paper = settings(
        0.4,
        11.0,
        25,
        Aperture::Polygon {
            blades: 5,
            rotation_deg: 0.0,
        },
    );
    for s in [paper.clone(), paper.with_model(ModelOptions::PHYSICAL)] {
        let run = |n: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| tape_bits(&stack, &s, Engine::Fast, &g))
        };
        let one = run(1);
        for n in [2, 3] {
            assert!(one == run(n), "{n} threads differ from 1");
        }
    }
}

#[test]
fn fast_tape_forward_is_the_fast_render() {
    fn same<T: Real>(stack: &LayerStack<T>, s: &RenderSettings) {
        let (out, _) = render_with_tape_on(stack, s, Engine::Fast, &NoProgress).unwrap();
        let plain = render(stack, s, Engine::Fast, &NoProgress).unwrap();
        let bits = |i: &Image<T>| i.data.iter().map(|v| v.f64().to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&out), bits(&plain));
    }
    let stack = random_stack::<f64>(4, 45, 38, 3);
    for (_, aperture) in apertures() {
        let s = settings(0.45, 10.0, 25, aperture);
        for s in [s.clone(), s.with_model(ModelOptions::PHYSICAL)] {
            same(&stack, &s);
            same(&stack.cast::<f32>(), &s);
        }
    }
    // The default entry point keeps the exact threaded schedule.
    let s = settings(0.45, 10.0, 25, Aperture::Circle);
    let (out, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
    assert_eq!(tape.engine(), Engine::Threaded);
    assert_eq!(
        out.data,
        render(&stack, &s, Engine::Threaded, &NoProgress)
            .unwrap()
            .data
    );
}

#[test]
fn fast_backward_rejects_a_bad_gradient() {
    let stack = random_stack::<f64>(1, 6, 5, 2);
    let s = settings(0.5, 5.0, 5, Aperture::Circle);
    let (_, tape) = render_with_tape_on(&stack, &s, Engine::Fast, &NoProgress).unwrap();
    assert!(tape.backward(&Image::new(5, 6, 3), &NoProgress).is_err());
    let mut bad = Image::<f64>::new(6, 5, 3);
    bad.data[0] = f64::NAN;
    assert!(tape.backward(&bad, &NoProgress).is_err());
}
