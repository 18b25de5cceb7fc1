//! Behaviour of the `paper` forward pass: engines agree, limits and invariants of the
//! model hold, and a hand-computed golden case matches.

mod common;

use common::{random_stack, settings};
use drbokeh::aperture::KernelImage;
use drbokeh::HighlightBoost;
use drbokeh::{
    render, Aperture, Engine, Image, Layer, LayerStack, NoProgress, RenderSettings, Window,
};

fn apertures() -> Vec<Aperture> {
    // A ring-shaped kernel with a dark centre exercises the kernel path fully.
    let n = 15;
    let mut grey = Image::<f64>::new(n, n, 1);
    for y in 0..n {
        for x in 0..n {
            let r = ((x as f64 - 7.0).powi(2) + (y as f64 - 7.0).powi(2)).sqrt();
            *grey.at_mut(x, y, 0) = if (3.0..7.0).contains(&r) {
                1.0
            } else {
                0.2 * (r < 3.0) as u8 as f64
            };
        }
    }
    vec![
        Aperture::Circle,
        Aperture::Polygon {
            blades: 6,
            rotation_deg: 15.0,
        },
        Aperture::Polygon {
            blades: 5,
            rotation_deg: 0.0,
        },
        Aperture::Kernel(KernelImage::new(&grey).unwrap()),
    ]
}

#[test]
fn reference_and_threaded_agree_in_f64_for_every_aperture() {
    for (i, aperture) in apertures().into_iter().enumerate() {
        let stack = random_stack::<f64>(10 + i as u64, 23, 17, 3);
        let s = settings(0.45, 12.0, 11, aperture.clone());
        let a = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
        let b = render(&stack, &s, Engine::Threaded, &NoProgress).unwrap();
        let diff = a.max_abs_diff(&b);
        assert!(diff <= 1e-6, "aperture {aperture:?}: max diff {diff}");
        // The images must not be trivial: they differ from the unblurred input.
        assert!(a.data.iter().any(|v| *v > 0.05));
    }
}

#[test]
fn output_is_identical_for_one_and_many_threads() {
    let stack = random_stack::<f32>(7, 31, 29, 3);
    let s = settings(
        0.3,
        20.0,
        15,
        Aperture::Polygon {
            blades: 7,
            rotation_deg: 3.0,
        },
    );
    let run = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| render(&stack, &s, Engine::Threaded, &NoProgress).unwrap())
    };
    let one = run(1);
    for n in [2, 3, 8] {
        assert_eq!(one.data, run(n).data, "{n} threads differ from 1 thread");
    }
}

#[test]
fn constant_opaque_layer_renders_to_itself() {
    let colour = [0.3, 0.62, 0.91];
    for &(focus, k) in &[(0.0, 0.0), (0.5, 10.0), (1.0, 30.0), (0.2, 60.0)] {
        let stack =
            LayerStack::new(vec![Layer::<f64>::constant(19, 13, colour, 1.0, 0.7)]).unwrap();
        let out = render(
            &stack,
            &settings(focus, k, 21, Aperture::Circle),
            Engine::Threaded,
            &NoProgress,
        )
        .unwrap();
        for px in out.data.chunks_exact(3) {
            for c in 0..3 {
                assert!(
                    (px[c] - colour[c]).abs() < 1e-6,
                    "focus {focus} K {k}: {px:?}"
                );
            }
        }
    }
}

/// A two-layer scene: a square of colour `fg` (alpha 1) at disparity `fg_disp` in front of an
/// opaque background of colour `bg` at `bg_disp`. Returns the rendered red channel.
fn square_scene(fg_disp: f64, bg_disp: f64, focus: f64) -> (Image<f64>, usize, usize, usize) {
    let (w, h, half) = (61, 61, 10);
    let mut front = Layer::<f64>::constant(w, h, [1.0, 0.0, 0.0], 0.0, fg_disp);
    for y in 30 - half..=30 + half {
        for x in 30 - half..=30 + half {
            *front.alpha.at_mut(x, y, 0) = 1.0;
        }
    }
    let back = Layer::<f64>::constant(w, h, [0.0, 0.0, 1.0], 1.0, bg_disp);
    let stack = LayerStack::new(vec![front, back]).unwrap();
    let out = render(
        &stack,
        &settings(focus, 30.0, 41, Aperture::Circle),
        Engine::Threaded,
        &NoProgress,
    )
    .unwrap();
    (out, w, h, half)
}

#[test]
fn in_focus_object_occludes_blurred_background() {
    // Foreground in focus (disp 0.8), background far and blurred (r = 22 px).
    let (out, _, _, half) = square_scene(0.8, 0.07, 0.8);
    // Inside the square, beyond a 2-pixel soft-edge band, no background (blue) colour.
    for y in 30 - half + 2..=30 + half - 2 {
        for x in 30 - half + 2..=30 + half - 2 {
            assert!(
                out.at(x, y, 2) < 1e-3,
                "blue {} at ({x},{y})",
                out.at(x, y, 2)
            );
            assert!(
                out.at(x, y, 0) > 0.999,
                "red {} at ({x},{y})",
                out.at(x, y, 0)
            );
        }
    }
    // Outside, the background stays background right next to the sharp edge.
    assert!(out.at(30 + half + 3, 30, 2) > 0.9);
    assert!(out.at(30 + half + 3, 30, 0) < 0.35);
}

#[test]
fn blurred_foreground_spreads_over_in_focus_background() {
    // Foreground near and blurred (r = 19 px), background in focus.
    let (out, _, _, half) = square_scene(0.8, 0.2, 0.2);
    // Partial occlusion: the foreground's colour spreads outside the square's footprint...
    let outside = out.at(30 + half + 5, 30, 0);
    assert!(
        outside > 0.15,
        "foreground red outside its footprint: {outside}"
    );
    // ...and the in-focus background shows through the foreground's blurred rim.
    let rim = out.at(30 + half - 2, 30, 2);
    assert!(rim > 0.15, "background blue inside the rim: {rim}");
    // The centre of the square is still the foreground.
    assert!(out.at(30, 30, 0) > 0.95);
    // Far from everything, the background is untouched.
    assert!((out.at(2, 2, 2) - 1.0).abs() < 1e-6);
}

#[test]
fn transparent_front_layer_changes_nothing() {
    let base = random_stack::<f64>(3, 21, 18, 2);
    let mut with_ghost = base.clone();
    let mut ghost = Layer::<f64>::constant(21, 18, [0.9, 0.1, 0.4], 0.0, 0.95);
    *ghost.rgb_encoded.at_mut(3, 3, 0) = 0.2;
    with_ghost.layers.insert(0, ghost);
    let s = settings(0.4, 15.0, 13, Aperture::Circle);
    let a = render(&base, &s, Engine::Threaded, &NoProgress).unwrap();
    let b = render(&with_ghost, &s, Engine::Threaded, &NoProgress).unwrap();
    assert!(a.max_abs_diff(&b) < 1e-12);
}

#[test]
fn layer_order_matters_where_layers_overlap() {
    let stack = random_stack::<f64>(4, 21, 18, 3);
    let mut swapped = stack.clone();
    swapped.layers.swap(0, 1);
    let s = settings(0.5, 15.0, 13, Aperture::Circle);
    let a = render(&stack, &s, Engine::Threaded, &NoProgress).unwrap();
    let b = render(&swapped, &s, Engine::Threaded, &NoProgress).unwrap();
    assert!(a.max_abs_diff(&b) > 1e-2);
}

#[test]
fn f32_and_f64_agree() {
    for aperture in apertures() {
        let s64 = random_stack::<f64>(5, 25, 19, 3);
        let s32: LayerStack<f32> = s64.cast();
        let s = settings(0.55, 25.0, 17, aperture);
        let a = render(&s64, &s, Engine::Threaded, &NoProgress).unwrap();
        let b = render(&s32, &s, Engine::Threaded, &NoProgress)
            .unwrap()
            .cast::<f64>();
        let diff = a.max_abs_diff(&b);
        assert!(diff <= 1e-4, "f32 vs f64: {diff}");
    }
}

#[test]
fn highlight_boost_brightens_only_bright_defocused_pixels() {
    let mut layer = Layer::<f64>::constant(15, 15, [0.2, 0.2, 0.2], 1.0, 0.1);
    *layer.rgb_encoded.at_mut(7, 7, 0) = 1.0;
    let stack = LayerStack::new(vec![layer]).unwrap();
    let mut s = settings(0.6, 5.0, 9, Aperture::Circle);
    let plain = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
    s.camera.highlight = Some(HighlightBoost::PAPER);
    let boosted = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
    assert!(boosted.at(7, 7, 0) > plain.at(7, 7, 0) + 1e-3);
    // Dark channels are not boosted.
    assert!((boosted.at(7, 7, 1) - plain.at(7, 7, 1)).abs() < 1e-12);
    // In focus, nothing is boosted.
    s.camera.focus_disparity = 0.1;
    let a = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
    s.camera.highlight = None;
    let b = render(&stack, &s, Engine::Reference, &NoProgress).unwrap();
    assert!(a.max_abs_diff(&b) < 1e-12);
}

/// The photo constants (threshold 0.9, amount 0.25): a value between the paper's threshold
/// (200/255) and 0.9 is not boosted; a recovered highlight (encoded above 1) is boosted
/// more than with the paper's.
#[test]
fn photo_boost_starts_higher_and_lifts_recovered_light_more() {
    let mut layer = Layer::<f64>::constant(15, 15, [0.2, 0.2, 0.2], 1.0, 0.1);
    *layer.rgb_encoded.at_mut(7, 7, 0) = 1.6;
    *layer.rgb_encoded.at_mut(7, 7, 1) = 0.85;
    let stack = LayerStack::new(vec![layer]).unwrap();
    let mut s = settings(0.6, 5.0, 9, Aperture::Circle);
    let at = |s: &drbokeh::RenderSettings, c| {
        render(&stack, s, Engine::Reference, &NoProgress)
            .unwrap()
            .at(7, 7, c)
    };
    let plain = [at(&s, 0), at(&s, 1)];
    s.camera.highlight = Some(HighlightBoost::PAPER);
    let paper = [at(&s, 0), at(&s, 1)];
    s.camera.highlight = Some(HighlightBoost::PHOTO);
    let photo = [at(&s, 0), at(&s, 1)];
    assert!(paper[1] > plain[1] + 1e-3, "0.85 is above 200/255");
    assert!((photo[1] - plain[1]).abs() < 1e-12, "0.85 is below 0.9");
    assert!(photo[0] > paper[0] + 1e-3, "{photo:?} {paper:?}");
    // Out-of-range constants are refused, naming the parameter.
    s.camera.highlight = Some(HighlightBoost {
        amount: f64::NAN,
        ..HighlightBoost::PHOTO
    });
    let err = render(&stack, &s, Engine::Reference, &NoProgress).unwrap_err();
    assert!(err.to_string().contains("boost amount"), "{err}");
    s.camera.highlight = Some(HighlightBoost {
        threshold_encoded: 1.0,
        ..HighlightBoost::PHOTO
    });
    assert!(render(&stack, &s, Engine::Reference, &NoProgress).is_err());
}

/// The 5x5 two-layer case of tools/golden_paper.py, an independent plain-Python
/// evaluation of docs/model.md's formulas for preset `paper` (K = 4, f = 0.5, L = 5,
/// gamma 2.2, circle).
/// Values printed by `python3 tools/golden_paper.py`.
#[rustfmt::skip]
const GOLDEN: [[f64; 3]; 25] = [
    [0.6260151753878558, 0.289995164750557, 0.21185268306721694],
    [0.6388135842267804, 0.3105960950421991, 0.21122399839888753],
    [0.6751528715715321, 0.34365058396186504, 0.20925274795173773],
    [0.6726388467053894, 0.35080563740207305, 0.22581324031708144],
    [0.6989057696486393, 0.35524441340775326, 0.2309535986395422],
    [0.661236260114424, 0.2890749066199541, 0.2375126849641098],
    [0.6719931885832019, 0.3122725155621235, 0.23739109904739028],
    [0.702808978398999, 0.3492596621538397, 0.23701219469746218],
    [0.6887940036735275, 0.3589071509388184, 0.2648201999262437],
    [0.7080601920422657, 0.3637333845687451, 0.2767559015641721],
    [0.7157865691097393, 0.2867214132484865, 0.2806506136563345],
    [0.7236716544651249, 0.31457079163150475, 0.280565851458734],
    [0.7465217091984658, 0.3588893351694524, 0.2803018398530101],
    [0.7140630869969952, 0.37117656037418717, 0.3300508181913676],
    [0.7255436538878393, 0.3783690121153569, 0.3498495151807786],
    [0.661236259984366, 0.2895276684259462, 0.3783143867925243],
    [0.6719931884087177, 0.31262655240604276, 0.3782372970610337],
    [0.7028089782336548, 0.34909809568341593, 0.3779972414181401],
    [0.6887940035177995, 0.3584261527525839, 0.4276399871102553],
    [0.7080601919550357, 0.36363304735033875, 0.4491853296907462],
    [0.6260151752992176, 0.2907221428718817, 0.426582072426987],
    [0.6388135840352043, 0.3110624244334777, 0.4272784199411696],
    [0.6751528713922621, 0.34357760679899346, 0.4294370738037473],
    [0.6726388465651808, 0.35013348829009633, 0.47956701420475056],
    [0.6989057697222494, 0.3550520940777723, 0.5025799814681539],
];

#[test]
fn golden_5x5_two_layers() {
    let (w, h) = (5, 5);
    let mut front = Layer::<f64>::constant(w, h, [0.0; 3], 0.0, 0.0);
    let mut back = Layer::<f64>::constant(w, h, [0.0; 3], 1.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let (xf, yf) = (x as f64, y as f64);
            *front.alpha.at_mut(x, y, 0) = (1.0 - 0.35 * (xf - 1.5).hypot(yf - 2.0)).max(0.0);
            for (c, v) in [0.9, 0.2 + 0.1 * xf, 0.1].into_iter().enumerate() {
                *front.rgb_encoded.at_mut(x, y, c) = v;
            }
            *front.disparity.at_mut(x, y, 0) = 0.8 + 0.02 * yf;
            for (c, v) in [0.1 + 0.15 * xf, 0.3, 0.2 + 0.1 * yf]
                .into_iter()
                .enumerate()
            {
                *back.rgb_encoded.at_mut(x, y, c) = v;
            }
            *back.disparity.at_mut(x, y, 0) = 0.2 + 0.03 * xf;
        }
    }
    let stack = LayerStack::new(vec![front, back]).unwrap();
    let s = settings(0.5, 4.0, 5, Aperture::Circle);
    for engine in [Engine::Reference, Engine::Threaded] {
        let out = render(&stack, &s, engine, &NoProgress).unwrap();
        for (i, g) in GOLDEN.iter().enumerate() {
            for c in 0..3 {
                let v = out.data[3 * i + c];
                assert!(
                    (v - g[c]).abs() < 1e-12,
                    "{engine:?} pixel {i} ch {c}: {v} vs {}",
                    g[c]
                );
            }
        }
    }
}

#[test]
fn invalid_parameters_are_errors_not_panics() {
    let stack = random_stack::<f32>(1, 8, 8, 2);
    let mut s = RenderSettings::paper(1.5);
    assert!(render(&stack, &s, Engine::Threaded, &NoProgress).is_err());
    s.camera.focus_disparity = 0.5;
    s.camera.blur_k = f64::NAN;
    assert!(render(&stack, &s, Engine::Threaded, &NoProgress).is_err());
    assert!(Window::from_size(4).is_err());
    assert!(Window::from_size(1).is_err());
    assert!(Aperture::parse_shape("polygon:2").is_err());
    assert!(Aperture::parse_shape("blob").is_err());
    let mut bad = stack.clone();
    bad.layers[1].alpha.data[3] = f32::NAN;
    assert!(bad.validate().is_err());
    bad.layers[1].alpha.data[3] = 1.5;
    assert!(bad.validate().is_err());
}
