//! The span adjoint's shared runs (pass B over runs of equal-radius sources: groups of 8
//! sharing their row geometry, `sources/runs.rs`; a circle's runs as row correlations,
//! `sources/conv.rs`) against its plain path, every source on its own
//! (`paths::force_source_by_source`): the same terms summed in another order, so in f64
//! every gradient agrees to rounding. The scenes have what the runs treat apart: rows of
//! one radius (constant and row-constant disparity) crossing the image's edges, tail
//! receivers (a layer's empty surround), receivers in focus inside discs and rings, span
//! and tap rows side by side (`auto`), both presets, circle and polygon apertures.
//!
//! One test function, so that the process-wide switch cannot race another test.

mod common;

use common::{mixed_stack, settings, tape_gradients};
use drbokeh::engine::paths;
use drbokeh::presets::ModelOptions;
use drbokeh::{
    render_with_stats, Aperture, Engine, Gradients, Image, Layer, LayerStack, NoProgress, Real,
    RenderSettings,
};

/// Largest allowed difference, relative to the largest gradient of the same layer and
/// kind (f64): the two orders' rounding, about `1e-16` per term times the few thousand
/// terms of a source's sums, with cancellation.
const F64_BOUND: f64 = 1e-10;

/// The same in f32: both paths round each row's sum in f32 (`6e-8` per term, a few
/// hundred terms per row) before the f64 sum over rows.
const F32_BOUND: f64 = 1e-4;

/// A kind whose gradient (nearly) vanishes is measured against this fraction of the
/// layer's largest gradient of any kind (as in `tests/spans_adjoint.rs`).
const SCALE_FLOOR: f64 = 1e-2;

/// Constant-disparity front layer (one radius everywhere) with an alpha disc that leaves
/// an empty surround, over a background whose disparity is constant along rows and ramps
/// down the image across focus (rows in focus: `e > 0` receivers).
fn rows_scene<T: Real>(w: usize, h: usize) -> LayerStack<T> {
    let mut front = Layer::<f64>::constant(w, h, [0.9, 0.4, 0.1], 0.0, 0.2);
    let mut back = Layer::<f64>::constant(w, h, [0.0; 3], 1.0, 0.1);
    let (cx, cy) = (w as f64 * 0.4, h as f64 * 0.45);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let r = ((x as f64 - cx).powi(2) + (y as f64 - cy).powi(2)).sqrt();
            front.alpha.data[i] = (0.5 - (r - w as f64 / 5.0) / 3.0).clamp(0.0, 1.0);
            for c in 0..3 {
                back.rgb_encoded.data[3 * i + c] = ((x / 5 + y / 7 + c) % 3) as f64 / 2.0;
            }
            back.disparity.data[i] = 0.1 + 0.8 * y as f64 / h as f64;
        }
    }
    LayerStack::new(vec![front, back]).unwrap().cast()
}

/// Every gradient kind as `(name, values, floor)`: the floor of its scale is
/// [`SCALE_FLOOR`] of the layer's largest gradient of any kind (0 for K and focus).
fn all_values(g: &Gradients<f64>) -> Vec<(String, Vec<f64>, f64)> {
    let mut out = Vec::new();
    for (l, lg) in g.layers.iter().enumerate() {
        let kinds = [
            ("rgb", &lg.rgb),
            ("alpha", &lg.alpha),
            ("disparity", &lg.disparity),
        ];
        let largest = kinds
            .iter()
            .flat_map(|(_, v)| v.data.iter())
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for (kind, v) in kinds {
            out.push((
                format!("layer {l} {kind}"),
                v.data.clone(),
                SCALE_FLOOR * largest,
            ));
        }
    }
    out.push(("K".into(), vec![g.blur_k], 0.0));
    out.push(("focus".into(), vec![g.focus], 0.0));
    out
}

fn gradients<T: Real>(stack: &LayerStack<T>, s: &RenderSettings, engine: Engine) -> Gradients<f64> {
    let (w, h) = (stack.width, stack.height);
    let g: Vec<T> = (0..w * h * 3)
        .map(|i| T::c(((i * 7919) % 13) as f64 / 6.0 - 1.0))
        .collect();
    tape_gradients(stack, s, &Image::from_vec(w, h, 3, g).unwrap(), engine)
}

/// The worst relative difference of the shared runs' gradients from the plain path's.
fn worst<T: Real>(stack: &LayerStack<T>, s: &RenderSettings, engine: Engine, name: &str) -> f64 {
    paths::force_source_by_source(false);
    let shared = gradients(stack, s, engine);
    paths::force_source_by_source(true);
    let plain = gradients(stack, s, engine);
    paths::force_source_by_source(false);
    let mut worst = 0.0f64;
    for ((kind, a, _), (_, b, floor)) in all_values(&shared).into_iter().zip(all_values(&plain)) {
        let scale = b.iter().fold(floor, |m, v| m.max(v.abs()));
        assert!(scale > 0.0, "{name}: {kind} is all zero");
        let diff = a
            .iter()
            .zip(&b)
            .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
        if std::env::var("RUNS_DEBUG").is_ok() {
            eprintln!("  {name} {kind}: {:.2e} of {scale:.3e}", diff / scale);
        }
        worst = worst.max(diff / scale);
    }
    worst
}

#[test]
fn shared_runs_match_source_by_source() {
    let apertures = [
        ("circle", Aperture::Circle),
        (
            "hexagon",
            Aperture::Polygon {
                blades: 6,
                rotation_deg: 10.0,
            },
        ),
    ];
    let mut failures = Vec::new();
    for (aperture_name, aperture) in apertures {
        // K 30 at focus 0.5: front radius 9, background 0..12 px with a row band in focus;
        // K 5 (window 41): `auto` takes tap rows where the background is near focus.
        for (k, window) in [(30.0, 51), (5.0, 41)] {
            let base = settings(0.5, k, window, aperture.clone());
            for s in [base.clone(), base.with_model(ModelOptions::PHYSICAL)] {
                for engine in [Engine::Spans, Engine::Auto] {
                    let name = format!("{aperture_name} K {k} {:?} {engine:?}", s.preset);
                    let stack64 = rows_scene::<f64>(97, 83);
                    let w64 = worst(&stack64, &s, engine, &name);
                    let w32 = worst(&rows_scene::<f32>(97, 83), &s, engine, &name);
                    eprintln!("{name}: f64 {w64:.2e}, f32 {w32:.2e}");
                    if !(w64 <= F64_BOUND && w32 <= F32_BOUND) {
                        failures.push(format!("{name}: f64 {w64:.2e}, f32 {w32:.2e}"));
                    }
                }
            }
        }
    }
    // Span and tap rows side by side (`auto`).
    for s in [
        settings(0.5, 5.0, 41, Aperture::Circle),
        settings(0.5, 5.0, 41, Aperture::Circle).with_model(ModelOptions::PHYSICAL),
    ] {
        let (_, stats) =
            render_with_stats(&mixed_stack::<f32>(40, 300), &s, Engine::Auto, &NoProgress).unwrap();
        assert!(
            stats.span_layers > 0 && stats.tap_layers > 0,
            "the scene mixes spans and taps: {stats:?}"
        );
        let name = format!("mixed {:?} Auto", s.preset);
        let w64 = worst(&mixed_stack::<f64>(40, 300), &s, Engine::Auto, &name);
        let w32 = worst(&mixed_stack::<f32>(40, 300), &s, Engine::Auto, &name);
        eprintln!("{name}: f64 {w64:.2e}, f32 {w32:.2e}");
        if !(w64 <= F64_BOUND && w32 <= F32_BOUND) {
            failures.push(format!("{name}: f64 {w64:.2e}, f32 {w32:.2e}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
