//! Depth from defocus: the baseline layers' gradients against finite differences, and
//! recovery of a known disparity through our renderer.

mod common;

use common::Rng;
use drbokeh::dfd::experiment::synthetic_pair;
use drbokeh::dfd::{
    disparity_errors, estimate_disparity, render_layer, render_layer_vjp, DfdOptions, RenderLayer,
};
use drbokeh::{Image, RenderSettings};

fn pair(seed: u64, w: usize, h: usize) -> (Image<f64>, Image<f64>, Image<f64>) {
    let mut rng = Rng(seed);
    let aif = Image::from_vec(
        w,
        h,
        3,
        (0..w * h * 3).map(|_| rng.range(0.05, 0.95)).collect(),
    )
    .unwrap();
    let disp = Image::from_vec(w, h, 1, (0..w * h).map(|_| rng.range(0.1, 0.7)).collect()).unwrap();
    let g = Image::from_vec(
        w,
        h,
        3,
        (0..w * h * 3).map(|_| rng.range(-1.0, 1.0)).collect(),
    )
    .unwrap();
    (aif, disp, g)
}

fn fd_check(layer: RenderLayer, seed: u64) {
    let (w, h) = (9, 8);
    let (aif, disp, g) = pair(seed, w, h);
    let mut s = RenderSettings::paper(0.8);
    s.camera.blur_k = 5.0;
    let loss = |d: &Image<f64>| -> f64 {
        let out = render_layer(layer, &aif, d, &s).unwrap();
        out.data.iter().zip(&g.data).map(|(a, b)| a * b).sum()
    };
    let (_, grad) = render_layer_vjp(layer, &aif, &disp, &s, |_| Ok(g.clone())).unwrap();
    let step = 1e-6;
    let mut failures = Vec::new();
    for i in 0..w * h {
        let mut p = disp.clone();
        p.data[i] += step;
        let up = loss(&p);
        p.data[i] -= 2.0 * step;
        let fd = (up - loss(&p)) / (2.0 * step);
        if (grad.data[i] - fd).abs() > 1e-4 * fd.abs().max(1e-5) {
            failures.push(format!(
                "pixel {i}: analytic {:e} vs fd {fd:e}",
                grad.data[i]
            ));
        }
    }
    assert!(
        grad.data.iter().any(|v| v.abs() > 1e-3),
        "gradient should not vanish"
    );
    assert!(failures.is_empty(), "{layer:?}:\n{}", failures.join("\n"));
}

#[test]
fn gausspsf_gradient_matches_finite_differences() {
    fd_check(RenderLayer::GaussPsf, 3);
}

#[test]
fn aperture_gradient_matches_finite_differences() {
    fd_check(RenderLayer::Aperture, 4);
}

#[test]
fn drbokeh_layer_gradient_matches_finite_differences() {
    fd_check(RenderLayer::DrBokeh, 5);
}

/// A 64x64 piecewise-planar scene rendered by our renderer (K = 10, focus 1): optimising
/// through the same renderer recovers its disparity. The scene's disparity spans 0.2 to
/// 0.92 and the initial guess is 0.5 everywhere (MAE about 0.2). We require MAE < 0.02: below 3% of the range, i.e. the
/// regions' depths are recovered and only pixels within a blur radius of a depth edge,
/// where defocus cannot tell which side a pixel belongs to, may be off.
#[test]
fn dfd_recovers_a_known_disparity() {
    let mut s = RenderSettings::paper(1.0);
    s.camera.blur_k = 10.0;
    let pair = synthetic_pair::<f32>(1, 64, &s).unwrap();
    let mut o = DfdOptions::new(s, RenderLayer::DrBokeh);
    o.schedule.iterations = 150;
    o.schedule.fine_iterations = 150;
    o.schedule.scales = 2;
    let r = estimate_disparity(&pair.all_in_focus, &pair.defocused, &o, &mut |_| {}).unwrap();
    let (est, log) = (r.disparity, r.log.entries);
    let start = disparity_errors(
        &Image::from_vec(64, 64, 1, vec![0.5f32; 64 * 64]).unwrap(),
        &pair.disparity,
    );
    let end = disparity_errors(&est, &pair.disparity);
    assert!(start.mae > 0.1, "initial MAE {}", start.mae);
    assert!(
        end.mae < 0.02,
        "recovered MAE {} (from {})",
        end.mae,
        start.mae
    );
    // The loss went down at the finest scale.
    let fine: Vec<f64> = log
        .iter()
        .filter(|e| e.scale == 0)
        .map(|e| e.loss)
        .collect();
    assert!(fine.last().unwrap() < &fine[0]);
}

#[test]
fn dfd_rejects_mismatched_pairs() {
    let s = RenderSettings::paper(1.0);
    let o = DfdOptions::new(s, RenderLayer::GaussPsf);
    let a = Image::<f32>::new(32, 32, 3);
    let b = Image::<f32>::new(32, 31, 3);
    assert!(estimate_disparity(&a, &b, &o, &mut |_| {}).is_err());
}
