//! The adjoint against central finite differences of the forward pass, in f64.

mod common;

use common::{random_weights, settings, Rng};
use drbokeh::aperture::KernelImage;
use drbokeh::presets::{Coverage, CoverageRadius, Footprint, ModelOptions, ScatterStep, Transfer};
use drbokeh::HighlightBoost;
use drbokeh::{
    render, render_with_tape, Aperture, Engine, Image, Layer, LayerStack, NoProgress,
    RenderSettings,
};

/// A stack whose alpha stays in [0.1, 1] (finite differences of alpha are meaningless where
/// a layer is empty: the 1e-8 regulariser dominates, see the spec) and whose disparities
/// sit in distinct depth bands, some in focus and some blurred.
fn fd_stack(seed: u64, w: usize, h: usize, n: usize) -> LayerStack<f64> {
    let mut rng = Rng(seed);
    let layers = (0..n)
        .map(|l| {
            let mut layer = Layer::<f64>::constant(w, h, [0.0; 3], 1.0, 0.0);
            let base = 0.85 - 0.7 * l as f64 / (n - 1) as f64;
            for i in 0..w * h {
                for c in 0..3 {
                    layer.rgb_encoded.data[3 * i + c] = rng.range(0.05, 0.95);
                }
                layer.alpha.data[i] = if l == n - 1 { 1.0 } else { rng.range(0.1, 1.0) };
                layer.disparity.data[i] = base + rng.range(-0.06, 0.06);
            }
            layer
        })
        .collect();
    LayerStack::new(layers).unwrap()
}

fn loss(stack: &LayerStack<f64>, s: &RenderSettings, weights: &Image<f64>) -> f64 {
    let out = render(stack, s, Engine::Threaded, &NoProgress).unwrap();
    out.data.iter().zip(&weights.data).map(|(a, b)| a * b).sum()
}

const STEP: f64 = 1e-6;

/// The central difference's rounding noise: the loss is a sum of a few hundred encoded
/// values times weights in [-1, 1] (|loss| up to about 10), so each evaluation carries a
/// rounding error of about 1e-14, and the difference quotient `/(2 STEP)` about 1e-8.
const FD_NOISE: f64 = 1e-8;

fn check(name: &str, analytic: f64, fd: f64, failures: &mut Vec<String>) {
    // Relative error 1e-4, plus the finite difference's own rounding noise.
    let err = (analytic - fd).abs();
    if err > 1e-4 * fd.abs() + FD_NOISE {
        failures.push(format!("{name}: analytic {analytic:e} vs fd {fd:e}"));
    }
}

/// Whether a perturbation of STEP (in disparity, K or focus: r moves by at most
/// max(K, 1) * STEP) could cross a coverage-box jump (r(x)/2 at an integer; paper box
/// coverage only, the soft disc has none) or the kink of |d| at d = 0. A margin of 1e-4 is
/// ten times the largest move.
fn near_kink(disp: f64, s: &RenderSettings) -> bool {
    let d = disp - s.camera.focus_disparity;
    let r = s.camera.blur_k * d.abs() + s.model().footprint.px();
    let box_jump =
        s.model().coverage == Coverage::PaperBox && ((r / 2.0) - (r / 2.0).round()).abs() < 1e-4;
    d.abs() < 1e-4 || box_jump
}

fn run_fd(stack: &LayerStack<f64>, s: &RenderSettings, seed: u64) {
    let (w, h) = (stack.width, stack.height);
    let weights = random_weights(seed, w, h);
    let (_, tape) = render_with_tape(stack, s, &NoProgress).unwrap();
    let grads = tape.backward(&weights, &NoProgress).unwrap();
    let mut failures = Vec::new();
    let mut checked = 0;
    for l in 0..stack.layers.len() {
        for i in 0..w * h {
            for c in 0..3 {
                let mut p = stack.clone();
                p.layers[l].rgb_encoded.data[3 * i + c] += STEP;
                let up = loss(&p, s, &weights);
                p.layers[l].rgb_encoded.data[3 * i + c] -= 2.0 * STEP;
                let fd = (up - loss(&p, s, &weights)) / (2.0 * STEP);
                check(
                    &format!("layer {l} rgb[{i}][{c}]"),
                    grads.layers[l].rgb.data[3 * i + c],
                    fd,
                    &mut failures,
                );
                checked += 1;
            }
            if stack.layers[l].alpha.data[i] < 1.0 {
                let mut p = stack.clone();
                p.layers[l].alpha.data[i] += STEP;
                let up = loss(&p, s, &weights);
                p.layers[l].alpha.data[i] -= 2.0 * STEP;
                let fd = (up - loss(&p, s, &weights)) / (2.0 * STEP);
                check(
                    &format!("layer {l} alpha[{i}]"),
                    grads.layers[l].alpha.data[i],
                    fd,
                    &mut failures,
                );
                checked += 1;
            }
            if !near_kink(stack.layers[l].disparity.data[i], s) {
                let mut p = stack.clone();
                p.layers[l].disparity.data[i] += STEP;
                let up = loss(&p, s, &weights);
                p.layers[l].disparity.data[i] -= 2.0 * STEP;
                let fd = (up - loss(&p, s, &weights)) / (2.0 * STEP);
                check(
                    &format!("layer {l} disparity[{i}]"),
                    grads.layers[l].disparity.data[i],
                    fd,
                    &mut failures,
                );
                checked += 1;
            }
        }
    }
    // Scalars: only meaningful when no pixel sits on a coverage jump within the step.
    let all_clear = |s: &RenderSettings| {
        stack
            .layers
            .iter()
            .flat_map(|l| l.disparity.data.iter())
            .all(|&d| !near_kink(d, s))
    };
    if all_clear(s) {
        let mut p = s.clone();
        p.camera.blur_k += STEP;
        let up = loss(stack, &p, &weights);
        p.camera.blur_k -= 2.0 * STEP;
        let fd = (up - loss(stack, &p, &weights)) / (2.0 * STEP);
        check("blur K", grads.blur_k, fd, &mut failures);
        let mut p = s.clone();
        p.camera.focus_disparity += STEP;
        let up = loss(stack, &p, &weights);
        p.camera.focus_disparity -= 2.0 * STEP;
        let fd = (up - loss(stack, &p, &weights)) / (2.0 * STEP);
        check("focus", grads.focus, fd, &mut failures);
        checked += 2;
    } else {
        panic!("test scene has a pixel on a coverage jump; pick another seed");
    }
    assert!(checked > 100);
    assert!(
        failures.is_empty(),
        "{} of {checked} gradients wrong:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn fd_circle_three_layers() {
    let stack = fd_stack(21, 9, 8, 3);
    run_fd(&stack, &settings(0.5, 9.0, 9, Aperture::Circle), 1);
}

#[test]
fn fd_polygon_with_highlight() {
    let mut stack = fd_stack(22, 8, 9, 2);
    // Some bright pixels so the highlight boost is active and differentiated.
    for i in (0..72).step_by(5) {
        stack.layers[1].rgb_encoded.data[3 * i] = 0.93;
    }
    let mut s = settings(
        0.42,
        11.0,
        9,
        Aperture::Polygon {
            blades: 6,
            rotation_deg: 20.0,
        },
    );
    s.camera.highlight = Some(HighlightBoost::PAPER);
    run_fd(&stack, &s, 2);
}

#[test]
fn fd_kernel_aperture() {
    let n = 9;
    let mut grey = Image::<f64>::new(n, n, 1);
    for y in 0..n {
        for x in 0..n {
            let r = ((x as f64 - 4.0).powi(2) + (y as f64 - 4.0).powi(2)).sqrt();
            grey.data[y * n + x] = (1.0 - r / 5.0).max(0.0) * (1.0 + 0.5 * ((x + y) % 3) as f64);
        }
    }
    let stack = fd_stack(23, 8, 8, 2);
    run_fd(
        &stack,
        &settings(
            0.6,
            10.0,
            9,
            Aperture::Kernel(KernelImage::new(&grey).unwrap()),
        ),
        3,
    );
}

#[test]
fn fd_with_gamma_and_offset() {
    let stack = fd_stack(24, 7, 7, 3);
    let mut s = settings(0.3, 7.0, 7, Aperture::Circle);
    s.camera.gamma = 1.8;
    s.camera.offset = 0.05;
    run_fd(&stack, &s, 4);
}

/// With exact zeros in alpha (empty regions), colour and disparity gradients stay exact.
#[test]
fn fd_with_empty_regions_for_colour_and_disparity() {
    let mut stack = fd_stack(25, 8, 8, 2);
    for i in 0..32 {
        stack.layers[0].alpha.data[i] = 0.0;
    }
    let s = settings(0.55, 8.0, 7, Aperture::Circle);
    let weights = random_weights(5, 8, 8);
    let (_, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
    let grads = tape.backward(&weights, &NoProgress).unwrap();
    let mut failures = Vec::new();
    for l in 0..2 {
        for i in 0..64 {
            if near_kink(stack.layers[l].disparity.data[i], &s) {
                continue;
            }
            let mut p = stack.clone();
            p.layers[l].disparity.data[i] += STEP;
            let up = loss(&p, &s, &weights);
            p.layers[l].disparity.data[i] -= 2.0 * STEP;
            let fd = (up - loss(&p, &s, &weights)) / (2.0 * STEP);
            check(
                &format!("layer {l} disparity[{i}]"),
                grads.layers[l].disparity.data[i],
                fd,
                &mut failures,
            );
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The coverage box's half-size floor(r/2) jumps; its derivative is zero (as in the paper):
/// at a pixel sitting exactly on a jump the analytic gradient equals the one-sided
/// difference on the side that keeps the box, while the central difference sees the jump.
#[test]
fn coverage_floor_has_zero_derivative() {
    let (w, h) = (9, 9);
    // Disparity a hair above 0.7 so r sits just above the jump at r = 4 (0.7 - 0.4 rounds
    // below 0.3 in binary).
    let mut front = Layer::<f64>::constant(w, h, [0.8, 0.3, 0.2], 0.0, 0.7 + 1e-10);
    let back = Layer::<f64>::constant(w, h, [0.1, 0.2, 0.7], 1.0, 0.2);
    for y in 0..h {
        for x in 3..w {
            front.alpha.data[y * w + x] = 0.2 + 0.08 * x as f64;
        }
    }
    // K = 10, f = 0.4: r = 10 * 0.3 + 1 = 4 (+1e-9), so floor(r/2) = 2, on the jump.
    let stack = LayerStack::new(vec![front, back]).unwrap();
    let s = settings(0.4, 10.0, 9, Aperture::Circle);
    let weights = random_weights(6, w, h);
    let (_, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
    let grads = tape.backward(&weights, &NoProgress).unwrap();
    let i = 4 * w + 4;
    let base = loss(&stack, &s, &weights);
    let mut up = stack.clone();
    up.layers[0].disparity.data[i] += STEP;
    let mut down = stack.clone();
    down.layers[0].disparity.data[i] -= STEP;
    let (l_up, l_down) = (loss(&up, &s, &weights), loss(&down, &s, &weights));
    let one_sided = (l_up - base) / STEP; // r grows: the box keeps half-size 2
    let central = (l_up - l_down) / (2.0 * STEP);
    let g = grads.layers[0].disparity.data[i];
    assert!(
        (g - one_sided).abs() < 1e-3 * one_sided.abs().max(1e-3),
        "analytic {g} vs one-sided {one_sided}"
    );
    assert!(
        (central - one_sided).abs() > 100.0 * (g - one_sided).abs().max(1e-6),
        "the box jump should show in the central difference ({central} vs {one_sided})"
    );
}

#[test]
fn adjoint_is_deterministic_for_any_thread_count() {
    let stack = common::random_stack::<f32>(9, 29, 23, 3);
    let s = settings(
        0.4,
        15.0,
        13,
        Aperture::Polygon {
            blades: 5,
            rotation_deg: 0.0,
        },
    );
    let weights = random_weights(7, 29, 23).cast::<f32>();
    let run = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| {
                let (out, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
                let g = tape.backward(&weights, &NoProgress).unwrap();
                let mut bytes: Vec<u32> = out.data.iter().map(|v| v.to_bits()).collect();
                for l in &g.layers {
                    bytes.extend(
                        l.rgb
                            .data
                            .iter()
                            .chain(&l.alpha.data)
                            .chain(&l.disparity.data)
                            .map(|v| v.to_bits()),
                    );
                }
                (bytes, g.blur_k.to_bits(), g.focus.to_bits())
            })
    };
    let one = run(1);
    for n in [2, 4, 7] {
        assert!(one == run(n), "{n} threads differ from 1");
    }
    // The tape's forward is the threaded render, bit for bit.
    let (out, _) = render_with_tape(&stack, &s, &NoProgress).unwrap();
    assert_eq!(
        out.data,
        render(&stack, &s, Engine::Threaded, &NoProgress)
            .unwrap()
            .data
    );
}

#[test]
fn backward_rejects_a_mismatched_gradient() {
    let stack = fd_stack(1, 6, 5, 2);
    let (_, tape) = render_with_tape(
        &stack,
        &settings(0.5, 5.0, 5, Aperture::Circle),
        &NoProgress,
    )
    .unwrap();
    assert!(tape.backward(&Image::new(5, 6, 3), &NoProgress).is_err());
    let mut bad = Image::<f64>::new(6, 5, 3);
    bad.data[0] = f64::NAN;
    assert!(tape.backward(&bad, &NoProgress).is_err());
}

// ---- The `physical` preset and its options, one at a time (same tolerances). ----

fn physical(s: RenderSettings) -> RenderSettings {
    s.with_model(ModelOptions::PHYSICAL)
}

#[test]
fn fd_physical_circle_three_layers() {
    // Seeds 31 and 41 each had one colour gradient of ~1e-5 whose central difference at
    // STEP = 1e-6 is noise-limited (the sRGB encode is steep for dark outputs): off by
    // 1.1e-9 absolute, 1.3e-4 relative; with a 1e-5 step both agree within tolerance.
    let stack = fd_stack(51, 9, 8, 3);
    run_fd(
        &stack,
        &physical(settings(0.5, 9.0, 9, Aperture::Circle)),
        11,
    );
}

#[test]
fn fd_physical_polygon_with_highlight() {
    let mut stack = fd_stack(32, 8, 9, 2);
    for i in (0..72).step_by(5) {
        stack.layers[1].rgb_encoded.data[3 * i] = 0.93;
        stack.layers[0].rgb_encoded.data[3 * i + 1] = 0.02; // the sRGB linear segment
    }
    let mut s = physical(settings(
        0.42,
        11.0,
        9,
        Aperture::Polygon {
            blades: 6,
            rotation_deg: 20.0,
        },
    ));
    // The photo constants (threshold 0.9: the 0.93 values are above it).
    s.camera.highlight = Some(HighlightBoost::PHOTO);
    run_fd(&stack, &s, 12);
}

#[test]
fn fd_physical_kernel_aperture() {
    let n = 9;
    let mut grey = Image::<f64>::new(n, n, 1);
    for y in 0..n {
        for x in 0..n {
            let r = ((x as f64 - 4.0).powi(2) + (y as f64 - 4.0).powi(2)).sqrt();
            grey.data[y * n + x] = (1.0 - r / 5.0).max(0.0) * (1.0 + 0.5 * ((x + y) % 3) as f64);
        }
    }
    let stack = fd_stack(33, 8, 8, 2);
    run_fd(
        &stack,
        &physical(settings(
            0.6,
            10.0,
            9,
            Aperture::Kernel(KernelImage::new(&grey).unwrap()),
        )),
        13,
    );
}

/// Each option alone: the disc coverage with the gamma transfer (and an offset), and the
/// paper's box with the sRGB transfer.
#[test]
fn fd_single_options() {
    let stack = fd_stack(34, 7, 7, 3);
    let mut s = settings(0.3, 7.0, 7, Aperture::Circle).with_model(ModelOptions {
        coverage: Coverage::SoftDisc,
        coverage_radius: CoverageRadius::Scatter,
        transfer: Transfer::Gamma,
        footprint: Footprint::Pixel,
        step: ScatterStep::Paper,
    });
    s.camera.gamma = 1.8;
    s.camera.offset = 0.05;
    run_fd(&stack, &s, 14);
    let s = settings(0.35, 6.0, 7, Aperture::Circle).with_model(ModelOptions {
        coverage: Coverage::PaperBox,
        coverage_radius: CoverageRadius::Scatter,
        transfer: Transfer::Srgb,
        footprint: Footprint::HalfPixel,
        step: ScatterStep::Paper,
    });
    run_fd(&fd_stack(35, 7, 6, 2), &s, 15);
    // The sharp step alone, with the paper's box, footprint and gamma.
    let s = settings(0.4, 7.0, 7, Aperture::Circle).with_model(ModelOptions {
        step: ScatterStep::Sharp,
        ..ModelOptions::PAPER
    });
    run_fd(&fd_stack(37, 7, 6, 2), &s, 17);
    // The disc with the scatter radius r(x), with the polygon.
    let s = settings(
        0.45,
        8.0,
        7,
        Aperture::Polygon {
            blades: 5,
            rotation_deg: 0.0,
        },
    )
    .with_model(ModelOptions {
        coverage_radius: CoverageRadius::Scatter,
        ..ModelOptions::PHYSICAL
    });
    run_fd(&fd_stack(36, 7, 6, 2), &s, 16);
}

/// The soft disc is continuous in r(x): where the paper's box jumps (r(x)/2 an integer),
/// the physical coverage's central difference matches the analytic gradient.
#[test]
fn physical_coverage_is_differentiable_through_the_receiver_radius() {
    let (w, h) = (9, 9);
    let mut front = Layer::<f64>::constant(w, h, [0.8, 0.3, 0.2], 0.0, 0.7 + 1e-10);
    let back = Layer::<f64>::constant(w, h, [0.1, 0.2, 0.7], 1.0, 0.2);
    for y in 0..h {
        for x in 3..w {
            front.alpha.data[y * w + x] = 0.2 + 0.08 * x as f64;
        }
    }
    let stack = LayerStack::new(vec![front, back]).unwrap();
    let s = physical(settings(0.4, 10.0, 9, Aperture::Circle));
    let weights = random_weights(16, w, h);
    let (_, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
    let grads = tape.backward(&weights, &NoProgress).unwrap();
    let i = 4 * w + 4;
    let mut up = stack.clone();
    up.layers[0].disparity.data[i] += STEP;
    let mut down = stack.clone();
    down.layers[0].disparity.data[i] -= STEP;
    let central = (loss(&up, &s, &weights) - loss(&down, &s, &weights)) / (2.0 * STEP);
    let g = grads.layers[0].disparity.data[i];
    assert!(
        central.abs() > 1e-4,
        "expected a sizeable gradient, got {central}"
    );
    assert!(
        (g - central).abs() <= 1e-4 * central.abs(),
        "analytic {g} vs central {central}"
    );
}

#[test]
fn physical_adjoint_is_deterministic_and_matches_threaded() {
    let stack = common::random_stack::<f32>(19, 23, 19, 3);
    let s = physical(settings(0.4, 15.0, 13, Aperture::Circle));
    let weights = random_weights(17, 23, 19).cast::<f32>();
    let run = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| {
                let (out, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
                let g = tape.backward(&weights, &NoProgress).unwrap();
                let mut bytes: Vec<u32> = out.data.iter().map(|v| v.to_bits()).collect();
                for l in &g.layers {
                    bytes.extend(l.alpha.data.iter().map(|v| v.to_bits()));
                    bytes.extend(l.disparity.data.iter().map(|v| v.to_bits()));
                }
                (bytes, g.blur_k.to_bits(), g.focus.to_bits())
            })
    };
    assert!(run(1) == run(3));
    let (out, _) = render_with_tape(&stack, &s, &NoProgress).unwrap();
    assert_eq!(
        out.data,
        render(&stack, &s, Engine::Threaded, &NoProgress)
            .unwrap()
            .data
    );
}

// ---- Issue 14, case 10: the pixels reflection padding mirrors, to a relative 1e-6. ----

/// A stack whose disparities are uniform in [0, 1] per pixel (so some receivers are in
/// focus and the occlusion term is active, others blurred), alpha in [0.1, 1) with exact
/// zeros and ones on alternate seeds; the last layer opaque.
fn mirrored_stack(seed: u64, w: usize, h: usize, n: usize) -> LayerStack<f64> {
    let mut rng = Rng(seed);
    let zeros = seed % 2 == 0;
    let layers = (0..n)
        .map(|l| {
            let mut layer = Layer::<f64>::constant(w, h, [0.0; 3], 1.0, 0.0);
            for i in 0..w * h {
                for c in 0..3 {
                    layer.rgb_encoded.data[3 * i + c] = rng.range(0.05, 0.95);
                }
                let a = rng.range(0.0, 1.0);
                layer.alpha.data[i] = match (l == n - 1, zeros) {
                    (true, _) => 1.0,
                    (false, true) if a < 0.2 => 0.0,
                    (false, true) if a > 0.8 => 1.0,
                    _ => 0.1 + 0.9 * a,
                };
                layer.disparity.data[i] = rng.range(0.0, 1.0);
            }
            layer
        })
        .collect();
    LayerStack::new(layers).unwrap()
}

/// Every colour, alpha and disparity gradient against a fourth-order central difference
/// (step 1e-4: truncation error about (1e-4 / 0.05)^4 relative at the sharpest in-focus
/// curvature, rounding about 1e-11 absolute), to a relative 1e-6. The images are small
/// for their window (R = 3 at 10 x 12; R = 4 at 7 x 6, where the padding folds more than
/// once), so most pixels are copied by the reflection padding: a missing or doubled term
/// at mirrored pixels shows as a relative error of 1e-5 or more.
#[test]
fn fd_mirrored_pixels_to_relative_1e6() {
    const H: f64 = 1e-4;
    let cases = [
        (10, 12, 7, 1u64),
        (10, 12, 7, 2),
        (12, 10, 7, 3),
        (7, 6, 9, 4),
    ];
    let mut checked = 0;
    let mut failures = Vec::new();
    for (w, h, window, seed) in cases {
        let stack = mirrored_stack(seed, w, h, 2);
        for preset in [ModelOptions::PAPER, ModelOptions::PHYSICAL] {
            let s = settings(0.45, 9.0, window, Aperture::Circle).with_model(preset);
            let weights = random_weights(seed + 40, w, h);
            let (_, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
            let grads = tape.backward(&weights, &NoProgress).unwrap();
            let fd = |bump: &dyn Fn(&mut LayerStack<f64>, f64)| {
                let at = |t: f64| {
                    let mut p = stack.clone();
                    bump(&mut p, t);
                    loss(&p, &s, &weights)
                };
                (8.0 * (at(H) - at(-H)) - (at(2.0 * H) - at(-2.0 * H))) / (12.0 * H)
            };
            for l in 0..2 {
                for i in 0..w * h {
                    let a = stack.layers[l].alpha.data[i];
                    let d = stack.layers[l].disparity.data[i] - 0.45;
                    let r = 9.0 * d.abs() + s.model().footprint.px();
                    let box_jump = s.model().coverage == Coverage::PaperBox
                        && ((r / 2.0) - (r / 2.0).round()).abs() < 5e-3;
                    let mut entries: Vec<(String, f64, f64)> = Vec::new();
                    for c in 0..3 {
                        let g = fd(&|p, t| p.layers[l].rgb_encoded.data[3 * i + c] += t);
                        entries.push((format!("rgb[{c}]"), grads.layers[l].rgb.data[3 * i + c], g));
                    }
                    if a > 2.0 * H && a < 1.0 - 2.0 * H {
                        let g = fd(&|p, t| p.layers[l].alpha.data[i] += t);
                        entries.push(("alpha".into(), grads.layers[l].alpha.data[i], g));
                    }
                    if d.abs() > 1e-3 && !box_jump {
                        let g = fd(&|p, t| p.layers[l].disparity.data[i] += t);
                        entries.push(("disparity".into(), grads.layers[l].disparity.data[i], g));
                    }
                    for (name, analytic, numeric) in entries {
                        checked += 1;
                        if (analytic - numeric).abs() > 1e-6 * numeric.abs() + 1e-9 {
                            failures.push(format!(
                                "{w}x{h} L{window} seed {seed} {:?} layer {l} x={} y={} {name}: analytic {analytic:e} vs fd {numeric:e}",
                                preset.coverage,
                                i % w,
                                i / w
                            ));
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 3000, "{checked}");
    assert!(
        failures.is_empty(),
        "{} of {checked} gradients off:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
