//! Layer decomposition and inpainting: synthetic scenes with known hidden content.

use drbokeh::layering::{
    decompose, inpaint_telea, layers_from_disparity, layers_from_matte, smooth_fill,
    two_layers_from_matte, LayeringOptions, Region, TeleaOptions,
};
use drbokeh::Image;

const FG: [f64; 3] = [0.95, 0.05, 0.05];
const FG_DISP: f64 = 0.9;

fn bg_colour(x: usize, y: usize, w: usize, h: usize) -> [f64; 3] {
    [
        0.0,
        0.25 + 0.5 * x as f64 / w as f64,
        0.7 - 0.4 * y as f64 / h as f64,
    ]
}

fn bg_disp(x: usize, y: usize, w: usize, h: usize) -> f64 {
    0.05 + 0.15 * x as f64 / w as f64 + 0.05 * y as f64 / h as f64
}

/// Fraction of pixel (x, y) covered by the foreground rectangle [x0, x1) x [y0, y1), with
/// its left edge at a half pixel (one column of mixed pixels, as a real photo has).
fn coverage(x: usize, y: usize, rect: (f64, f64, f64, f64)) -> f64 {
    let (x0, y0, x1, y1) = rect;
    let ox = ((x as f64 + 1.0).min(x1) - (x as f64).max(x0)).clamp(0.0, 1.0);
    let oy = ((y as f64 + 1.0).min(y1) - (y as f64).max(y0)).clamp(0.0, 1.0);
    ox * oy
}

/// A two-plane scene: a red foreground rectangle over a smooth background (no red at all).
/// Returns the image, its disparity, the hidden background colour and disparity, and the
/// foreground coverage.
#[allow(clippy::type_complexity)]
fn two_planes(w: usize, h: usize) -> (Image<f64>, Image<f64>, Image<f64>, Image<f64>, Vec<f64>) {
    let rect = (20.5, 12.0, 44.0, 34.0);
    let mut rgb = Image::new(w, h, 3);
    let mut disp = Image::new(w, h, 1);
    let mut true_bg = Image::new(w, h, 3);
    let mut true_bg_disp = Image::new(w, h, 1);
    let mut cov = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let a = coverage(x, y, rect);
            cov[y * w + x] = a;
            let b = bg_colour(x, y, w, h);
            for c in 0..3 {
                *rgb.at_mut(x, y, c) = a * FG[c] + (1.0 - a) * b[c];
                *true_bg.at_mut(x, y, c) = b[c];
            }
            let bd = bg_disp(x, y, w, h);
            *disp.at_mut(x, y, 0) = a * FG_DISP + (1.0 - a) * bd;
            *true_bg_disp.at_mut(x, y, 0) = bd;
        }
    }
    (rgb, disp, true_bg, true_bg_disp, cov)
}

#[test]
fn two_plane_scene_gives_two_layers_and_a_faithful_background_fill() {
    let (w, h) = (64, 48);
    let (rgb, disp, true_bg, true_bg_disp, cov) = two_planes(w, h);
    let d = layers_from_disparity(&rgb, &disp, &LayeringOptions::default()).unwrap();
    assert!(d.notes.is_empty(), "{:?}", d.notes);
    assert_eq!(d.stack.layers.len(), 2);
    assert_eq!(d.thresholds.len(), 1);
    let t = d.thresholds[0];
    assert!((0.3..0.85).contains(&t), "threshold {t}");
    let (fg, bg) = (&d.stack.layers[0], &d.stack.layers[1]);
    // The foreground layer is opaque over the rectangle's interior, transparent far from it.
    for y in 0..h {
        for x in 0..w {
            let a = fg.alpha.at(x, y, 0);
            let c = cov[y * w + x];
            if c == 1.0 && (22..42).contains(&x) && (14..32).contains(&y) {
                assert_eq!(a, 1.0, "fg alpha at ({x},{y})");
            }
            if (!(18..=46).contains(&x) || !(10..=36).contains(&y)) && c == 0.0 {
                assert_eq!(a, 0.0, "fg alpha at ({x},{y})");
            }
            assert_eq!(bg.alpha.at(x, y, 0), 1.0);
        }
    }
    // Soft alpha at the cut edge: some pixel strictly between 0 and 1.
    assert!(fg.alpha.data.iter().any(|&a| a > 0.05 && a < 0.95));
    // Foreground colour and disparity are the image's on its own pixels.
    assert_eq!(fg.rgb_encoded.at(30, 20, 0), rgb.at(30, 20, 0));
    assert!((fg.disparity.at(30, 20, 0) - FG_DISP).abs() < 1e-12);
    // Hidden background, away from the foreground's edge (smooth there): close to the truth.
    let (mut worst_c, mut worst_d) = (0.0f64, 0.0f64);
    for y in 16..30 {
        for x in 25..40 {
            for c in 0..3 {
                worst_c = worst_c.max((bg.rgb_encoded.at(x, y, c) - true_bg.at(x, y, c)).abs());
            }
            worst_d = worst_d.max((bg.disparity.at(x, y, 0) - true_bg_disp.at(x, y, 0)).abs());
        }
    }
    assert!(worst_c < 0.04, "background colour fill error {worst_c}");
    assert!(worst_d < 0.01, "background disparity fill error {worst_d}");
    // The background's disparity behind the foreground continues the background (never
    // the foreground's 0.9).
    let max_bg_disp = bg.disparity.data.iter().cloned().fold(0.0, f64::max);
    assert!(
        max_bg_disp < 0.26,
        "background disparity reaches {max_bg_disp}"
    );
    // The foreground's disparity is extended outward (receivers outside it see it as near).
    assert!((fg.disparity.at(2, 2, 0) - FG_DISP).abs() < 0.05);
}

#[test]
fn focus_hint_keeps_only_cuts_that_can_change_the_render() {
    let (w, h) = (64, 48);
    let (rgb, disp, _, _, _) = two_planes(w, h);
    let with = |focus: f64, blur: f64| {
        let opts = LayeringOptions {
            focus_hint: Some((focus, blur)),
            ..LayeringOptions::default()
        };
        layers_from_disparity(&rgb, &disp, &opts).unwrap()
    };
    // Focus on the background: the foreground is blurred over it, two layers.
    let d = with(0.1, 20.0);
    assert_eq!(d.stack.layers.len(), 2);
    assert!(d.notes.is_empty(), "{:?}", d.notes);
    // Focus on the foreground: it is sharper than the background behind it; no cut can
    // change the render, so one opaque layer and a note saying why.
    let d = with(0.9, 20.0);
    assert_eq!(d.stack.layers.len(), 1);
    assert_eq!(d.stack.layers[0].rgb_encoded, rgb);
    assert!(d.notes[0].contains("focus and blur"), "{:?}", d.notes);
    // A small blur (under half a pixel between the planes): the nearer side is still the
    // more blurred, so the default keeps the cut; a margin of 1 px (`min_blur_gain_px`)
    // drops it, and the note names the margin.
    let d = with(0.0, 0.5);
    assert_eq!(d.stack.layers.len(), 2);
    let margin = LayeringOptions {
        focus_hint: Some((0.0, 0.5)),
        min_blur_gain_px: 1.0,
        ..LayeringOptions::default()
    };
    let d = layers_from_disparity(&rgb, &disp, &margin).unwrap();
    assert_eq!(d.stack.layers.len(), 1);
    assert!(d.notes[0].contains("focus and blur"), "{:?}", d.notes);
    assert!(
        d.notes[0].contains("at least 1 px more than"),
        "{:?}",
        d.notes
    );
    // The three-plane scene focused on the middle plane keeps the front cut only.
    let (w, h) = (60, 40);
    let mut rgb = Image::<f32>::new(w, h, 3);
    let mut disp = Image::<f32>::new(w, h, 1);
    for y in 0..h {
        for x in 0..w {
            let d = if (8..24).contains(&x) && (8..30).contains(&y) {
                0.95
            } else if (20..48).contains(&x) && (14..36).contains(&y) {
                0.5
            } else {
                0.1
            };
            *disp.at_mut(x, y, 0) = d;
            *rgb.at_mut(x, y, 0) = d;
        }
    }
    let opts = LayeringOptions {
        focus_hint: Some((0.5, 20.0)),
        ..LayeringOptions::default()
    };
    let d = layers_from_disparity(&rgb, &disp, &opts).unwrap();
    assert_eq!(d.stack.layers.len(), 2, "{:?}", d.thresholds);
    assert!(d.thresholds[0] > 0.5, "{:?}", d.thresholds);
}

#[test]
fn edge_matting_estimates_partial_coverage_and_keeps_the_composite() {
    let (w, h) = (64, 48);
    let (rgb, disp, _, _, cov) = two_planes(w, h);
    let opts = LayeringOptions {
        matting_px: 2,
        ..LayeringOptions::default()
    };
    let d = layers_from_disparity(&rgb, &disp, &opts).unwrap();
    assert_eq!(d.stack.layers.len(), 2);
    let (fg, bg) = (&d.stack.layers[0], &d.stack.layers[1]);
    // The half-covered column (x = 20) gets alpha close to its true coverage.
    for y in 14..32 {
        assert!((cov[y * w + 20] - 0.5).abs() < 1e-9);
        let a = fg.alpha.at(20, y, 0);
        assert!((a - 0.5).abs() < 0.1, "alpha {a} at (20,{y})");
    }
    // Over the sharp layers, compositing front over back gives the image back.
    let mut worst = 0.0f64;
    for i in 0..w * h {
        let a = fg.alpha.data[i];
        for c in 0..3 {
            let comp =
                a * fg.rgb_encoded.data[i * 3 + c] + (1.0 - a) * bg.rgb_encoded.data[i * 3 + c];
            worst = worst.max((comp - rgb.data[i * 3 + c]).abs());
        }
    }
    assert!(worst < 0.02, "composite differs from the image by {worst}");
}

#[test]
fn inpainting_never_pulls_foreground_colour_into_the_background() {
    let (w, h) = (64, 48);
    let (rgb, disp, _, _, cov) = two_planes(w, h);
    // Decomposition: the background has no red anywhere it was filled.
    let d = layers_from_disparity(&rgb, &disp, &LayeringOptions::default()).unwrap();
    let bg = &d.stack.layers[1];
    for y in 0..h {
        for x in 0..w {
            if cov[y * w + x] == 1.0 {
                let r = bg.rgb_encoded.at(x, y, 0);
                assert!(
                    r < 1e-9,
                    "foreground red {r} leaked to background at ({x},{y})"
                );
            }
        }
    }
    // Matte path, with a matte that is exact (soft on the mixed column).
    let matte = Image::from_vec(w, h, 1, cov.clone()).unwrap();
    let s = two_layers_from_matte(&rgb, &disp, &matte).unwrap();
    let bg = &s.layers[1];
    for y in 0..h {
        for x in 0..w {
            if cov[y * w + x] > 0.0 {
                assert!(
                    bg.rgb_encoded.at(x, y, 0) < 1e-9,
                    "matte path leak at ({x},{y})"
                );
                assert!(bg.disparity.at(x, y, 0) < 0.26, "matte path disparity leak");
            }
        }
    }
    // The inpainting itself reads only Known pixels: with the foreground (and its mixed
    // edge) marked Fill and Skip, nothing red can appear.
    let region: Vec<Region> = cov
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            if c == 0.0 && (i % w) % 7 != 0 {
                Region::Known
            } else if c == 0.0 {
                Region::Fill
            } else if (i / w) % 2 == 0 {
                Region::Skip
            } else {
                Region::Fill
            }
        })
        .collect();
    let out = inpaint_telea(&rgb, &region, &TeleaOptions::default());
    for i in 0..w * h {
        if region[i] == Region::Fill {
            assert!(out.filled[i], "pixel {i} not reached");
            assert!(out.image.data[i * 3] < 1e-9, "red at {i}");
        }
        if region[i] == Region::Skip {
            assert_eq!(out.image.data[i * 3], rgb.data[i * 3]);
        }
    }
    // The smooth fill stays within the known values' range.
    let known: Vec<bool> = cov.iter().map(|&c| c == 0.0).collect();
    let filled = smooth_fill(&disp, &known);
    assert!(filled.data.iter().all(|&v| (0.05..=0.25).contains(&v)));
}

#[test]
fn telea_continues_a_linear_ramp_and_respects_max_distance() {
    let (w, h) = (40, 30);
    let img = Image::from_vec(
        w,
        h,
        1,
        (0..w * h)
            .map(|i| 0.1 + 0.02 * (i % w) as f64 + 0.01 * (i / w) as f64)
            .collect(),
    )
    .unwrap();
    let hole = |i: usize| (10..30).contains(&(i % w)) && (8..22).contains(&(i / w));
    let region: Vec<Region> = (0..w * h)
        .map(|i| if hole(i) { Region::Fill } else { Region::Known })
        .collect();
    let mut broken = img.clone();
    for i in 0..w * h {
        if hole(i) {
            broken.data[i] = 5.0;
        }
    }
    let out = inpaint_telea(&broken, &region, &TeleaOptions::default());
    let err = out.image.max_abs_diff(&img);
    assert!(err < 0.02, "ramp fill error {err}");
    assert!(out.filled.iter().filter(|f| **f).count() == 20 * 14);
    // Limited distance: only a 3-pixel rim is filled; the rest is left as it was.
    let opts = TeleaOptions {
        max_distance: 3.0,
        ..TeleaOptions::default()
    };
    let out = inpaint_telea(&broken, &region, &opts);
    assert!(out.filled[8 * w + 10] && !out.filled[15 * w + 20]);
    assert_eq!(out.image.data[15 * w + 20], 5.0);
    assert!(out.distance[15 * w + 20].is_infinite());
}

#[test]
fn three_planes_give_three_layers_front_to_back_and_max_layers_caps_them() {
    let (w, h) = (60, 40);
    let mut rgb = Image::<f32>::new(w, h, 3);
    let mut disp = Image::<f32>::new(w, h, 1);
    for y in 0..h {
        for x in 0..w {
            let (d, c) = if (8..24).contains(&x) && (8..30).contains(&y) {
                (0.95, [0.9, 0.8, 0.1])
            } else if (20..48).contains(&x) && (14..36).contains(&y) {
                (0.5, [0.1, 0.8, 0.2])
            } else {
                (0.1 + 0.001 * x as f32, [0.2, 0.3, 0.9])
            };
            *disp.at_mut(x, y, 0) = d;
            for k in 0..3 {
                *rgb.at_mut(x, y, k) = c[k];
            }
        }
    }
    let opts = LayeringOptions {
        occlusion_band_px: Some(3.0),
        ..LayeringOptions::default()
    };
    let d = layers_from_disparity(&rgb, &disp, &opts).unwrap();
    assert_eq!(d.stack.layers.len(), 3, "{:?}", d.thresholds);
    assert!(d.thresholds[0] > d.thresholds[1]);
    let l = &d.stack.layers;
    assert_eq!(l[0].alpha.at(15, 20, 0), 1.0);
    // The middle layer reaches only `occlusion_band_px` behind the front one.
    assert_eq!(l[1].alpha.at(15, 20, 0), 0.0);
    assert_eq!(l[1].alpha.at(35, 25, 0), 1.0);
    assert_eq!(l[0].alpha.at(35, 25, 0), 0.0);
    // The middle layer extends behind the front one where they meet, its coverage
    // continued (high next to its own pixels, fading toward the background's).
    let a = l[1].alpha.at(22, 20, 0);
    assert!(a > 0.7 && a <= 1.0, "band alpha {a}");
    assert!(l[1].alpha.at(21, 20, 0) <= a);
    assert!((l[1].rgb_encoded.at(22, 20, 0) - 0.1).abs() < 1e-6);
    assert!((l[1].disparity.at(22, 20, 0) - 0.5).abs() < 1e-3);
    // The background is opaque and filled with its own colour behind both.
    assert!(l[2].alpha.data.iter().all(|&a| a == 1.0));
    assert!((l[2].rgb_encoded.at(30, 25, 2) - 0.9).abs() < 1e-6);
    assert!(l[2].disparity.at(30, 25, 0) < 0.2);
    let opts = LayeringOptions {
        max_layers: 2,
        ..LayeringOptions::default()
    };
    let d2 = layers_from_disparity(&rgb, &disp, &opts).unwrap();
    assert_eq!(d2.stack.layers.len(), 2);
}

#[test]
fn bad_inputs_give_errors_or_single_layers_never_panics() {
    let (w, h) = (64, 48);
    let (rgb, disp, _, _, cov) = two_planes(w, h);
    let opts = LayeringOptions::default();
    // Matte of the wrong size.
    let small = Image::<f64>::new(w - 1, h, 1);
    let e = layers_from_matte(&rgb, &disp, &small, &opts)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("alpha matte") && e.contains("63x48") && e.contains("64x48"),
        "{e}"
    );
    // Disparity of the wrong size, wrong channels, non-finite values, bad matte range.
    let e = layers_from_disparity(&rgb, &Image::new(w, h + 1, 1), &opts).unwrap_err();
    assert!(e.to_string().contains("disparity map"), "{e}");
    let e = layers_from_disparity(&rgb, &Image::new(w, h, 3), &opts).unwrap_err();
    assert!(e.to_string().contains("channels"), "{e}");
    let mut nan = disp.clone();
    nan.data[5] = f64::NAN;
    let e = layers_from_disparity(&rgb, &nan, &opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("non-finite") && e.contains("disparity"), "{e}");
    let mut inf_rgb = rgb.clone();
    inf_rgb.data[7] = f64::INFINITY;
    assert!(decompose(&inf_rgb, &disp, None, &opts).is_err());
    let mut bad_matte = Image::from_vec(w, h, 1, cov.clone()).unwrap();
    bad_matte.data[0] = 1.5;
    let e = layers_from_matte(&rgb, &disp, &bad_matte, &opts).unwrap_err();
    assert!(e.to_string().contains("outside [0, 1]"), "{e}");
    let e = layers_from_disparity(
        &rgb,
        &disp,
        &LayeringOptions {
            max_layers: 0,
            ..opts.clone()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("max_layers"), "{e}");
    // Empty matte: one opaque layer, with a note.
    let empty = Image::<f64>::new(w, h, 1);
    let d = layers_from_matte(&rgb, &disp, &empty, &opts).unwrap();
    assert_eq!(d.stack.layers.len(), 1);
    assert!(d.notes[0].contains("single opaque layer"), "{:?}", d.notes);
    // Full matte: two layers, the background is the image, with a note.
    let full = Image::from_vec(w, h, 1, vec![1.0; w * h]).unwrap();
    let d = layers_from_matte(&rgb, &disp, &full, &opts).unwrap();
    assert_eq!(d.stack.layers.len(), 2);
    assert!(!d.notes.is_empty());
    // Constant disparity and a smooth ramp: no discontinuity, one layer and a note.
    let flat = Image::from_vec(w, h, 1, vec![0.4; w * h]).unwrap();
    let d = layers_from_disparity(&rgb, &flat, &opts).unwrap();
    assert_eq!(d.stack.layers.len(), 1);
    assert!(d.notes[0].contains("constant"), "{:?}", d.notes);
    let ramp = Image::from_vec(
        w,
        h,
        1,
        (0..w * h).map(|i| (i % w) as f64 / w as f64).collect(),
    )
    .unwrap();
    let d = layers_from_disparity(&rgb, &ramp, &opts).unwrap();
    assert_eq!(d.stack.layers.len(), 1);
    assert!(
        d.notes[0].contains("no disparity discontinuity"),
        "{:?}",
        d.notes
    );
    assert_eq!(d.stack.layers[0].rgb_encoded, rgb);
    // Degenerate sizes.
    for (ww, hh) in [(1, 1), (1, 7), (9, 1), (2, 2)] {
        let img = Image::<f32>::new(ww, hh, 3);
        let dd =
            Image::from_vec(ww, hh, 1, (0..ww * hh).map(|i| (i % 2) as f32).collect()).unwrap();
        let d = layers_from_disparity(&img, &dd, &opts).unwrap();
        assert!(!d.stack.layers.is_empty());
        let m = Image::from_vec(ww, hh, 1, vec![1.0f32; ww * hh]).unwrap();
        layers_from_matte(&img, &dd, &m, &opts).unwrap();
    }
}

/// Timings on a 12-megapixel synthetic scene: `cargo test --release --test layering --
/// --ignored --nocapture`.
#[test]
#[ignore]
fn timing_12_megapixels() {
    use std::time::Instant;
    let (w, h) = (4000, 3000);
    let mut rgb = Image::<f32>::new(w, h, 3);
    let mut disp = Image::<f32>::new(w, h, 1);
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as f32 - 1800.0, y as f32 - 1500.0);
            let person = (dx / 700.0).powi(2) + (dy / 1100.0).powi(2) < 1.0;
            let mid = (2600..3600).contains(&x) && y > 1800;
            let (d, c) = if person {
                (0.9, [0.8, 0.5, 0.4])
            } else if mid {
                (0.5, [0.3, 0.6, 0.3])
            } else {
                (
                    0.1 + 0.1 * y as f32 / h as f32,
                    [0.2 + 0.1 * ((x / 37) % 3) as f32, 0.3, 0.7],
                )
            };
            *disp.at_mut(x, y, 0) = d;
            for c2 in 0..3 {
                *rgb.at_mut(x, y, c2) = c[c2];
            }
        }
    }
    let hole: Vec<Region> = disp
        .data
        .iter()
        .map(|&d| if d > 0.8 { Region::Fill } else { Region::Known })
        .collect();
    let n_hole = hole.iter().filter(|r| **r == Region::Fill).count();
    let t = Instant::now();
    let out = inpaint_telea(&rgb, &hole, &TeleaOptions::default());
    let t_telea = t.elapsed().as_secs_f64();
    assert!(out.filled.iter().filter(|f| **f).count() == n_hole);
    let known: Vec<bool> = hole.iter().map(|r| *r == Region::Known).collect();
    let t = Instant::now();
    let _ = smooth_fill(&disp, &known);
    let t_smooth = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let d = layers_from_disparity(&rgb, &disp, &LayeringOptions::default()).unwrap();
    let t_dec = t.elapsed().as_secs_f64();
    let matte = Image::from_vec(
        w,
        h,
        1,
        disp.data
            .iter()
            .map(|&d| if d > 0.8 { 1.0 } else { 0.0 })
            .collect(),
    )
    .unwrap();
    let t = Instant::now();
    let _ = two_layers_from_matte(&rgb, &disp, &matte).unwrap();
    let t_matte = t.elapsed().as_secs_f64();
    println!(
        "12 MP ({w}x{h}), hole {:.1} MP: telea colour fill {t_telea:.2} s, smooth disparity fill {t_smooth:.2} s, decomposition into {} layers {t_dec:.2} s, matte two-layer {t_matte:.2} s",
        n_hole as f64 / 1e6,
        d.stack.layers.len()
    );
}

/// The (a)/(b)/(c) comparison on ray-traced benchmark scenes (`drbokeh benchmark make`):
/// `paper` preset on (a) one opaque layer, (b) this decomposition made for the scene's
/// focus and blur (as `drbokeh render --image` does), (c) the ground-truth layers; PSNR and
/// SSIM against the ray-traced image. Run with
/// `DRBOKEH_BENCH=DIR cargo test --release -p drbokeh --test layering benchmark_abc --
/// --ignored --nocapture`. Experiments: `DRBOKEH_LAYER_OPTS=max_layers=3,hint=0,...`
/// overrides options (keys below; `hint=0`: no focus hint, as `drbokeh layers` without
/// `--focus`), and `DRBOKEH_DUMP=DIR` writes each scene's stack and the three renders.
#[test]
#[ignore]
fn benchmark_abc() {
    use drbokeh::{
        eval::{metrics, report},
        io, LayerStack,
    };
    let Ok(dir) = std::env::var("DRBOKEH_BENCH") else {
        println!("DRBOKEH_BENCH not set");
        return;
    };
    let scenes = report::list_scenes(std::path::Path::new(&dir)).unwrap();
    // Optional overrides for experiments: DRBOKEH_LAYER_OPTS="matting_px=0,max_layers=5".
    let mut opts = LayeringOptions::default();
    let mut use_hint = true;
    for kv in std::env::var("DRBOKEH_LAYER_OPTS")
        .unwrap_or_default()
        .split(',')
        .filter(|s| !s.is_empty())
    {
        let (key, v) = kv.split_once('=').expect("KEY=VALUE");
        match key {
            "matting_px" => opts.matting_px = v.parse().unwrap(),
            "unpremultiply" => opts.matting_unpremultiply = v == "1",
            "max_layers" => opts.max_layers = v.parse().unwrap(),
            "jump" => opts.jump_fraction = v.parse().unwrap(),
            "feather" => opts.feather_px = v.parse().unwrap(),
            "guard" => opts.colour_guard_px = v.parse().unwrap(),
            "disp_guard" => opts.disparity_guard_px = v.parse().unwrap(),
            "band_alpha" => opts.band_alpha_fill = v == "1",
            "band" => opts.occlusion_band_px = Some(v.parse().unwrap()),
            "hint" => use_hint = v == "1",
            "gain" => opts.min_blur_gain_px = v.parse().unwrap(),
            _ => panic!("unknown option {key}"),
        }
    }
    let preset = match std::env::var("DRBOKEH_PRESET").as_deref() {
        Ok("physical") => drbokeh::Preset::Physical,
        _ => drbokeh::Preset::Paper,
    };
    println!("options: {opts:?}, preset {preset:?}");
    println!("| scene | K | focus | layers (b) | (a) single | (b) decomposed | (c) true layers, clipped | (c) true layers | (h) oracle hard |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut sums = [0.0; 10];
    for s in &scenes {
        let scene = report::SceneInputs::load(s).unwrap();
        let (k, focus) = (scene.blur_k, scene.focus);
        let single = LayerStack::single(scene.aif.clone(), scene.disparity.clone()).unwrap();
        let mut opts = opts.clone();
        if use_hint {
            opts.focus_hint = Some((focus, k));
        }
        let dec = layers_from_disparity(&scene.aif, &scene.disparity, &opts).unwrap();
        // The photo has lost the highlights above white that the true layers keep: the
        // like-for-like comparison clips them.
        let mut clipped = scene.layers.clone();
        for l in &mut clipped.layers {
            l.rgb_encoded
                .data
                .iter_mut()
                .for_each(|v| *v = v.clamp(0.0, 1.0));
        }
        let dump = std::env::var("DRBOKEH_DUMP").ok().map(|d| {
            let d = std::path::Path::new(&d).join(s.file_name().unwrap());
            std::fs::create_dir_all(&d).unwrap();
            io::write_stack(&d.join("ours.npz"), &dec.stack).unwrap();
            for (name, img) in [("aif", &scene.aif), ("truth", &scene.ground_truth)] {
                io::write_output(
                    &d.join(format!("{name}.npy")),
                    img,
                    io::BitDepth::Eight,
                    |v| v,
                )
                .unwrap();
            }
            d
        });
        let cam = scene.camera();
        let mut row = vec![];
        let oracle = hard_oracle(&clipped, &scene.aif);
        for (name, stack) in [
            ("a", &single),
            ("b", &dec.stack),
            ("c", &clipped),
            ("c_raw", &scene.layers),
            ("h", &oracle),
        ] {
            let mut out = report::render_preset(preset, stack, &cam).unwrap();
            out.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
            if let Some(d) = &dump {
                io::write_output(
                    &d.join(format!("{name}.npy")),
                    &out,
                    io::BitDepth::Eight,
                    |v| v,
                )
                .unwrap();
            }
            row.push((
                metrics::psnr(&out, &scene.ground_truth).unwrap(),
                metrics::ssim(&out, &scene.ground_truth).unwrap(),
            ));
        }
        for (i, (p, q)) in row.iter().enumerate() {
            sums[2 * i] += p;
            sums[2 * i + 1] += q;
        }
        let cells: Vec<String> = row
            .iter()
            .map(|(p, q)| format!("{p:.2} / {q:.4}"))
            .collect();
        println!(
            "| {} | {k:.1} | {focus:.2} | {} | {} |",
            scene.name,
            dec.stack.layers.len(),
            cells.join(" | ")
        );
    }
    let n = scenes.len() as f64;
    let means: Vec<String> = (0..5)
        .map(|i| format!("{:.2} / {:.4}", sums[2 * i] / n, sums[2 * i + 1] / n))
        .collect();
    println!("| mean | | | | {} |", means.join(" | "));
    let gap = sums[4] - sums[0];
    if gap.abs() > 1e-12 {
        println!(
            "share of the (a)-(c clipped) PSNR gap closed by (b): {:.0} %",
            100.0 * (sums[2] - sums[0]) / gap
        );
    }
}

/// Experiment: the true layers with hard visible labels (the most visible layer of each
/// pixel gets alpha 1 and the photo's colour; hidden content stays true).
fn hard_oracle(gt: &drbokeh::LayerStack<f32>, aif: &Image<f32>) -> drbokeh::LayerStack<f32> {
    let n = gt.width * gt.height;
    let nl = gt.layers.len();
    let mut label = vec![nl - 1; n];
    for (i, lab) in label.iter_mut().enumerate() {
        let mut t = 1.0f32;
        let mut best = 0.0f32;
        for (l, layer) in gt.layers.iter().enumerate() {
            let a = layer.alpha.data[i];
            if t * a > best {
                best = t * a;
                *lab = l;
            }
            t *= 1.0 - a;
        }
    }
    let mut out = gt.clone();
    for (l, layer) in out.layers.iter_mut().enumerate() {
        for i in 0..n {
            if label[i] == l {
                layer.alpha.data[i] = 1.0;
                layer.rgb_encoded.data[3 * i..3 * i + 3]
                    .copy_from_slice(&aif.data[3 * i..3 * i + 3]);
            } else if label[i] < l {
                // hidden: true content
            } else {
                layer.alpha.data[i] = 0.0;
            }
        }
    }
    out
}

/// Behind thin structures (a comb: 1-px strands 4 px apart hanging from a bar) every
/// visible background pixel is next to a strand: the fill under the strands must come from those gap pixels, not
/// from beyond the strands' whole extent, or the background's fine pattern is lost.
#[test]
fn background_behind_thin_strands_is_filled_from_the_gaps() {
    let (w, h) = (64, 40);
    let bg = |x: usize, y: usize| {
        [
            0.5 + 0.4 * (x as f64 * 0.7).sin(),
            0.3 + 0.3 * (y as f64 / h as f64),
            0.5 + 0.4 * (x as f64 * 0.45).cos(),
        ]
    };
    let strand = |x: usize| (16..48).contains(&x) && x % 4 == 0;
    let bar = |x: usize, y: usize| (16..48).contains(&x) && y < 4;
    let mut rgb = Image::new(w, h, 3);
    let mut disp = Image::new(w, h, 1);
    for y in 0..h {
        for x in 0..w {
            let fg = strand(x) || bar(x, y);
            let c = if fg { [0.9, 0.9, 0.9] } else { bg(x, y) };
            for (k, v) in c.iter().enumerate() {
                *rgb.at_mut(x, y, k) = *v;
            }
            *disp.at_mut(x, y, 0) = if fg { 0.9 } else { 0.1 };
        }
    }
    let worst = |opts: &LayeringOptions| {
        let d = layers_from_disparity(&rgb, &disp, opts).unwrap();
        assert_eq!(d.stack.layers.len(), 2, "{:?}", d.notes);
        let back = &d.stack.layers[1];
        let mut worst = 0.0f64;
        for y in 4..h {
            for x in (0..w).filter(|&x| strand(x)) {
                let truth = bg(x, y);
                for (k, t) in truth.iter().enumerate() {
                    worst = worst.max((back.rgb_encoded.at(x, y, k) - t).abs());
                }
            }
        }
        worst
    };
    let default = worst(&LayeringOptions::default());
    // The pattern changes by up to 0.4 * 0.7 = 0.28 per pixel: filling each strand pixel
    // from its two neighbours keeps the error well under that.
    assert!(default < 0.15, "fill behind strands off by {default}");
    // Excluding the pixels next to a nearer layer (a 2-px guard) leaves no source within
    // 16 px: the fill smears, which is why the default guard is 0.
    let guarded = worst(&LayeringOptions {
        colour_guard_px: 2,
        ..Default::default()
    });
    assert!(guarded > 2.0 * default, "guard 2: {guarded} vs {default}");
}

#[test]
fn a_clipped_pixel_beyond_a_cut_edge_is_not_feathered_into_the_nearer_layer() {
    // The two-plane scene; on two rows, the background pixel just left of the rectangle's
    // first own pixel: one made clipped (a light of the background), one left as it is.
    let (w, h) = (64, 48);
    let (mut rgb, disp, ..) = two_planes(w, h);
    let first_own = |stack: &drbokeh::LayerStack<f64>, y: usize| {
        (0..w)
            .find(|&x| stack.layers[0].alpha.at(x, y, 0) == 1.0)
            .expect("the rectangle crosses the row")
    };
    let (y_clip, y_plain) = (20, 26);
    let before = layers_from_disparity(&rgb, &disp, &LayeringOptions::default()).unwrap();
    let x_clip = first_own(&before.stack, y_clip) - 1;
    let x_plain = first_own(&before.stack, y_plain) - 1;
    assert!(before.stack.layers[0].alpha.at(x_clip, y_clip, 0) > 0.05);
    for c in 0..3 {
        *rgb.at_mut(x_clip, y_clip, c) = 1.0;
    }
    let d = layers_from_disparity(&rgb, &disp, &LayeringOptions::default()).unwrap();
    assert_eq!(d.stack.layers.len(), 2);
    assert_eq!(first_own(&d.stack, y_clip), x_clip + 1, "same labels");
    let fg = &d.stack.layers[0];
    // The plain edge pixel is feathered; the clipped one is not (feathered, its light
    // would spread with the foreground's blur).
    let plain = fg.alpha.at(x_plain, y_plain, 0);
    assert!(
        plain > 0.05 && plain < 1.0,
        "plain edge pixel alpha {plain}"
    );
    assert_eq!(
        fg.alpha.at(x_clip, y_clip, 0),
        0.0,
        "clipped edge pixel alpha"
    );
}
