//! The library entry point `drbokeh::scene`: what the user gave -> stack, settings, notes.

mod common;

use common::random_stack;
use drbokeh::camera::{WindowCap, MAX_AUTO_WINDOW_SIZE};
use drbokeh::highlight::{HighlightRecovery, PhotoHighlights};
use drbokeh::layering::{layers_from_disparity, LayeringOptions};
use drbokeh::scene::{self, Focus, Layering, Photo, PhotoFiles, Source, View};
use drbokeh::{Aperture, Engine, Error, Image, Layer, LayerStack, Preset};

/// A two-depth photo: a near square (disparity 0.9) on a far ramp (0.1 .. 0.2).
fn photo(w: usize, h: usize) -> (Image<f32>, Image<f32>) {
    let mut rgb = Image::new(w, h, 3);
    let mut disp = Image::new(w, h, 1);
    for y in 0..h {
        for x in 0..w {
            let near = (10..30).contains(&x) && (8..26).contains(&y);
            for c in 0..3 {
                *rgb.at_mut(x, y, c) = if near {
                    [0.9, 0.1, 0.1][c]
                } else {
                    ((x / 4 + y / 4 + c) % 3) as f32 / 2.0
                };
            }
            *disp.at_mut(x, y, 0) = if near {
                0.9
            } else {
                0.1 + 0.1 * y as f32 / h as f32
            };
        }
    }
    (rgb, disp)
}

#[test]
fn a_stack_and_a_focus_value_resolve_to_the_views_settings() {
    let stack: LayerStack<f32> = random_stack(3, 20, 16, 3);
    let view = View {
        focus: Focus::Disparity(0.4),
        blur_k: 12.0,
        window: Some(15),
        gamma: 2.0,
        offset: 0.01,
        highlight: true,
        photo_highlights: PhotoHighlights::Off,
        aperture: Aperture::Polygon {
            blades: 6,
            rotation_deg: 5.0,
        },
        preset: Preset::Paper,
    };
    let s = scene::resolve(Source::Stack(stack.clone()), &view, Engine::Threaded).unwrap();
    assert_eq!(s.stack, stack);
    assert!(s.notes.is_empty());
    let cam = &s.settings.camera;
    assert_eq!(
        (cam.focus_disparity, cam.blur_k, cam.window.size()),
        (0.4, 12.0, 15)
    );
    assert_eq!(
        (cam.gamma, cam.offset, cam.highlight),
        (2.0, 0.01, Some(drbokeh::HighlightBoost::PAPER))
    );
    assert_eq!(s.settings.aperture, view.aperture);
    assert_eq!(s.settings.preset, Preset::Paper);
}

#[test]
fn focus_points_and_the_automatic_focus() {
    let mut front = Layer::<f32>::constant(12, 10, [0.5; 3], 0.0, 0.8);
    *front.alpha.at_mut(3, 4, 0) = 0.5;
    let back = Layer::<f32>::constant(12, 10, [0.5; 3], 1.0, 0.2);
    let stack = LayerStack::new(vec![front, back]).unwrap();
    let focus_at = |focus| {
        let view = View {
            focus,
            ..View::default()
        };
        scene::resolve(Source::Stack(stack.clone()), &view, Engine::Fast)
            .map(|s| s.settings.camera.focus_disparity as f32)
    };
    // The frontmost layer with alpha >= 0.5 at the pixel.
    assert_eq!(focus_at(Focus::At { x: 3, y: 4 }).unwrap(), 0.8);
    assert_eq!(focus_at(Focus::At { x: 4, y: 4 }).unwrap(), 0.2);
    // Auto: the centre pixel, except for the demo (its subject).
    assert_eq!(focus_at(Focus::Auto).unwrap(), 0.2);
    let demo = scene::resolve::<f32>(
        Source::Demo {
            width: 40,
            height: 30,
        },
        &View::default(),
        Engine::Fast,
    )
    .unwrap();
    assert_eq!(
        demo.settings.camera.focus_disparity,
        drbokeh::demo::DEMO_FOCUS
    );
    assert_eq!(demo.stack, drbokeh::demo::scene(40, 30));
    // A point outside the image names the parameter.
    match focus_at(Focus::At { x: 12, y: 0 }).unwrap_err() {
        Error::InvalidParameter { name, problem } => {
            assert_eq!(name, "focus_at");
            assert!(problem.contains("outside"), "{problem}");
        }
        e => panic!("unexpected error {e}"),
    }
}

#[test]
fn the_automatic_window_holds_the_largest_blur_and_says_when_it_is_capped() {
    let mut stack: LayerStack<f32> = random_stack(7, 24, 20, 2);
    for l in &mut stack.layers {
        l.disparity.data.iter_mut().for_each(|d| *d = 0.9);
    }
    let view = |k: f64| View {
        focus: Focus::Disparity(0.1),
        blur_k: k,
        ..View::default()
    };
    // K 10, |d| 0.8 (a hair less in f32): radius 8 + 1 (pixel footprint) + 3 (margin) =
    // R 12, no note.
    let s = scene::resolve(Source::Stack(stack.clone()), &view(10.0), Engine::Threaded).unwrap();
    assert_eq!(s.settings.camera.window.radius_px(), 12);
    assert_eq!(
        s.settings.camera.window,
        drbokeh::model::automatic_window(10.0, stack.max_defocus(0.1), WindowCap::Clipped)
    );
    assert!(s.notes.is_empty(), "{:?}", s.notes);
    // K 100: radius 81 + 3 exceeds the cap of L = 71 except on the fast engine.
    let s = scene::resolve(Source::Stack(stack.clone()), &view(100.0), Engine::Threaded).unwrap();
    assert_eq!(s.settings.camera.window.size(), MAX_AUTO_WINDOW_SIZE);
    assert_eq!(s.notes.len(), 1);
    assert!(s.notes[0].contains("capped"), "{}", s.notes[0]);
    let s = scene::resolve(Source::Stack(stack), &view(100.0), Engine::Fast).unwrap();
    assert_eq!(s.settings.camera.window.radius_px(), 84);
    assert!(s.notes.is_empty(), "{:?}", s.notes);
}

#[test]
fn a_photo_is_decomposed_for_the_focus_and_blur_it_resolves_to() {
    let (rgb, disp) = photo(40, 32);
    let view = View {
        focus: Focus::At { x: 2, y: 30 },
        blur_k: 10.0,
        preset: Preset::Paper,
        ..View::default()
    };
    let source = |layering, matte: Option<Image<f32>>| {
        Source::Photo(Photo {
            rgb_encoded: rgb.clone(),
            disparity: disp.clone(),
            matte,
            layering,
        })
    };
    let s = scene::resolve(source(Layering::default(), None), &view, Engine::Fast).unwrap();
    // The same decomposition, made by hand with the focus at the far pixel and K = 10.
    let focus = disp.at(2, 30, 0) as f64;
    let opts = LayeringOptions {
        focus_hint: Some((focus, 10.0)),
        ..LayeringOptions::default()
    };
    let by_hand = layers_from_disparity(&rgb, &disp, &opts).unwrap();
    assert_eq!(s.stack, by_hand.stack);
    assert_eq!(s.stack.layers.len(), 2);
    assert_eq!(s.settings.camera.focus_disparity, focus);
    // One layer on request; the matte's two layers with a matte.
    let single = scene::resolve(source(Layering::SingleLayer, None), &view, Engine::Fast).unwrap();
    assert_eq!(
        single.stack,
        LayerStack::single(rgb.clone(), disp.clone()).unwrap()
    );
    let mut matte = Image::<f32>::new(40, 32, 1);
    matte.data.iter_mut().step_by(7).for_each(|a| *a = 1.0);
    let two = scene::resolve(
        source(Layering::default(), Some(matte.clone())),
        &view,
        Engine::Fast,
    )
    .unwrap();
    assert_eq!(
        two.stack,
        drbokeh::layering::two_layers_from_matte(&rgb, &disp, &matte).unwrap()
    );
}

#[test]
fn errors_name_parameters_and_files() {
    let stack: LayerStack<f32> = random_stack(1, 10, 8, 2);
    let param_of =
        |view: View| match scene::resolve(Source::Stack(stack.clone()), &view, Engine::Fast) {
            Err(Error::InvalidParameter { name, .. }) => name,
            other => panic!("expected a parameter error, got {other:?}"),
        };
    let base = View {
        focus: Focus::Disparity(0.5),
        ..View::default()
    };
    assert_eq!(
        param_of(View {
            focus: Focus::Disparity(1.5),
            ..base.clone()
        }),
        "focus"
    );
    assert_eq!(
        param_of(View {
            window: Some(8),
            ..base.clone()
        }),
        "window"
    );
    assert_eq!(
        param_of(View {
            blur_k: -1.0,
            ..base.clone()
        }),
        "blur"
    );
    assert_eq!(
        param_of(View {
            gamma: 0.0,
            ..base.clone()
        }),
        "gamma"
    );
    match scene::parse_aperture("blob").unwrap_err() {
        Error::InvalidParameter { name, .. } => assert_eq!(name, "aperture"),
        e => panic!("unexpected error {e}"),
    }
    match "nope".parse::<Preset>().unwrap_err() {
        Error::InvalidParameter { name, .. } => assert_eq!(name, "preset"),
        e => panic!("unexpected error {e}"),
    }
    match scene::resolve::<f32>(
        Source::Demo {
            width: 100_000,
            height: 100_000,
        },
        &base,
        Engine::Fast,
    )
    .unwrap_err()
    {
        Error::InvalidInput { what, problem } => {
            assert_eq!(what, "demo_size");
            assert!(problem.contains("absurd"), "{problem}");
        }
        e => panic!("unexpected error {e}"),
    }
    // Files: a size mismatch names the second file; a missing stack names its path.
    let dir = tempfile::tempdir().unwrap();
    let (rgb, disp) = photo(40, 32);
    let image = dir.path().join("i.png");
    drbokeh::io::write_output(&image, &rgb, drbokeh::io::BitDepth::Eight, |v| v).unwrap();
    let small = dir.path().join("small.npy");
    {
        let (w, h) = (39, 32);
        let values: Vec<f32> = disp.data[..w * h].to_vec();
        let arr = ndarray::Array2::from_shape_vec((h, w), values).unwrap();
        ndarray_npy::write_npy(&small, &arr).unwrap();
    }
    let files = PhotoFiles::new(&image, &small, drbokeh::io::DepthKind::Disparity);
    let e = scene::resolve::<f32>(Source::PhotoFiles(files), &base, Engine::Fast).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("small.npy") && msg.contains("does not match"),
        "{msg}"
    );
    let missing = dir.path().join("none.npz");
    let e = scene::resolve::<f32>(Source::StackFile(missing), &base, Engine::Fast).unwrap_err();
    assert!(e.to_string().contains("none.npz"), "{e}");
}

#[test]
fn photo_highlights_apply_to_photos_only() {
    // A grey photo, far half (disparity 0) defocused, near half (1) in focus, with a
    // clipped 2x2 highlight in the far half.
    let (w, h) = (24, 16);
    let mut rgb = Image::<f32>::new(w, h, 3);
    rgb.data.iter_mut().for_each(|v| *v = 0.3);
    let mut disparity = Image::<f32>::new(w, h, 1);
    for y in 0..h {
        for x in w / 2..w {
            disparity.data[y * w + x] = 1.0;
        }
    }
    for (x, y) in [(3, 5), (4, 5), (3, 6), (4, 6)] {
        for c in 0..3 {
            rgb.data[3 * (y * w + x) + c] = 1.0;
        }
    }
    let photo = |layering| {
        Source::Photo(Photo {
            rgb_encoded: rgb.clone(),
            disparity: disparity.clone(),
            matte: None,
            layering,
        })
    };
    let view = |photo_highlights| View {
        focus: Focus::Disparity(1.0),
        blur_k: 20.0,
        photo_highlights,
        ..View::default()
    };
    // Default: the rim estimate with the boost's photo constants for a photo, no boost for a
    // stack.
    assert_eq!(
        View::default().photo_highlights,
        PhotoHighlights::Estimate(drbokeh::highlight::HighlightEstimate::DEFAULT)
    );
    let s = scene::resolve(
        photo(Layering::SingleLayer),
        &view(PhotoHighlights::default()),
        Engine::Fast,
    )
    .unwrap();
    assert_eq!(
        s.settings.camera.highlight,
        Some(drbokeh::HighlightBoost::PHOTO)
    );
    {
        // The defocused clipped 2x2 blob (all edge pixels, a rim at the background: the
        // photo's only rim says "far over white", so pooling lifts the cap to `poolmax`,
        // on edge pixels `poolmax^edgep`) is recovered; the rest is kept.
        let got = &s.stack.layers[0].rgb_encoded;
        let tone = view(PhotoHighlights::Off).tone();
        let lin = tone.linearize(got.data[3 * (5 * w + 3)] as f64);
        let d = drbokeh::highlight::HighlightEstimate::DEFAULT;
        let want = d.pool_max.powf(d.edge_power.unwrap());
        assert!((lin - want).abs() < 1e-4, "{lin} vs {want}");
        assert!(lin > 2.0, "{lin}");
        assert_eq!(got.data[0], 0.3);
    }
    let stack = LayerStack::single(rgb.clone(), disparity.clone()).unwrap();
    let s = scene::resolve(
        Source::Stack(stack),
        &view(PhotoHighlights::default()),
        Engine::Fast,
    )
    .unwrap();
    assert_eq!(s.settings.camera.highlight, None);
    // Off: nothing.
    let s = scene::resolve(
        photo(Layering::SingleLayer),
        &view(PhotoHighlights::Off),
        Engine::Fast,
    )
    .unwrap();
    assert_eq!(s.settings.camera.highlight, None);
    assert_eq!(s.stack.layers[0].rgb_encoded, rgb);
    // Recovery: the defocused clipped blob gets the gain in linear light, the rest is kept.
    let r = HighlightRecovery {
        gain: 3.0,
        threshold: 0.9,
    };
    let s = scene::resolve(
        photo(Layering::SingleLayer),
        &view(PhotoHighlights::Recover(r)),
        Engine::Fast,
    )
    .unwrap();
    assert_eq!(s.settings.camera.highlight, None);
    let got = &s.stack.layers[0].rgb_encoded;
    let tone = view(PhotoHighlights::Off).tone();
    let lin = tone.linearize(got.data[3 * (5 * w + 3)] as f64);
    assert!((lin - 3.0).abs() < 1e-4, "{lin}");
    assert_eq!(got.data[0], 0.3);
}
