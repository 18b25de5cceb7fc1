//! `drbokeh layers` and the decomposed `render --image --disparity`, end to end.

mod common;

use common::{drbokeh, p, stderr};
use std::path::PathBuf;

struct Scene {
    dir: tempfile::TempDir,
    image: PathBuf,
    disparity: PathBuf,
    matte: PathBuf,
}

const W: u32 = 40;
const H: u32 = 30;

/// A near left half (x < 20) over a far right half, with a matching matte.
fn scene() -> Scene {
    let dir = tempfile::tempdir().unwrap();
    let img = image::RgbImage::from_fn(W, H, |x, y| {
        if x < 20 {
            image::Rgb([230, 40, 30])
        } else {
            image::Rgb([10, (x * 5) as u8, (y * 8) as u8])
        }
    });
    let disp = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(W, H, |x, _| {
        image::Luma([if x < 20 { 60000 } else { 5000 }])
    });
    let matte = image::GrayImage::from_fn(W, H, |x, _| image::Luma([if x < 20 { 255 } else { 0 }]));
    let s = Scene {
        image: dir.path().join("i.png"),
        disparity: dir.path().join("d.png"),
        matte: dir.path().join("m.png"),
        dir,
    };
    img.save(&s.image).unwrap();
    disp.save(&s.disparity).unwrap();
    matte.save(&s.matte).unwrap();
    s
}

#[test]
fn layers_writes_a_stack_and_previews() {
    let s = scene();
    let out = s.dir.path().join("stack.npz");
    let o = drbokeh(&[
        "layers",
        "--image",
        p(&s.image),
        "--disparity",
        p(&s.disparity),
        "--output",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 layer(s)"), "{}", stderr(&o));
    let stack = drbokeh::io::read_stack::<f32>(&out).unwrap();
    assert_eq!(stack.layers.len(), 2);
    let (fg, bg) = (&stack.layers[0], &stack.layers[1]);
    assert_eq!(fg.alpha.at(5, 15, 0), 1.0);
    assert_eq!(fg.alpha.at(35, 15, 0), 0.0);
    assert!(bg.alpha.data.iter().all(|&a| a == 1.0));
    // The background behind the red foreground is filled from the background: no red.
    assert!(
        bg.rgb_encoded.at(10, 15, 0) < 0.1,
        "{}",
        bg.rgb_encoded.at(10, 15, 0)
    );
    assert!(bg.disparity.at(10, 15, 0) < 0.1);
    for k in 0..2 {
        for name in [
            format!("stack.layer{k}.png"),
            format!("stack.layer{k}.disparity.png"),
        ] {
            let img = image::open(s.dir.path().join(&name)).unwrap();
            assert_eq!((img.width(), img.height()), (W, H), "{name}");
        }
    }
    // With the matte: the paper's two layers, foreground alpha = matte.
    let out2 = s.dir.path().join("matte.npz");
    let o = drbokeh(&[
        "layers",
        "--image",
        p(&s.image),
        "--disparity",
        p(&s.disparity),
        "--alpha",
        p(&s.matte),
        "--no-preview",
        "-o",
        p(&out2),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).is_empty());
    let stack = drbokeh::io::read_stack::<f32>(&out2).unwrap();
    assert_eq!(stack.layers.len(), 2);
    assert_eq!(stack.layers[0].alpha.at(19, 3, 0), 1.0);
    assert_eq!(stack.layers[0].alpha.at(20, 3, 0), 0.0);
    assert!(!s.dir.path().join("matte.layer0.png").exists());
}

#[test]
fn render_decomposes_by_default_and_matches_the_layers_command() {
    let s = scene();
    let stack = s.dir.path().join("s.npz");
    let o = drbokeh(&[
        "layers",
        "--image",
        p(&s.image),
        "--disparity",
        p(&s.disparity),
        "--no-preview",
        "-o",
        p(&stack),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Plain --highlight: the paper's boost alone, for the photo and the stack alike.
    let camera = [
        "--focus",
        "0.0",
        "--blur",
        "10",
        "--window",
        "23",
        "--highlight",
        "-q",
    ];
    let render = |scene: &[&str], name: &str| -> Vec<f32> {
        let out = s.dir.path().join(name);
        let mut args = vec!["render"];
        args.extend_from_slice(scene);
        args.extend_from_slice(&camera);
        args.extend_from_slice(&["-o", p(&out)]);
        let o = drbokeh(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let f = std::fs::File::open(&out).unwrap();
        use ndarray_npy::ReadNpyExt;
        ndarray::Array3::<f32>::read_npy(f)
            .unwrap()
            .into_raw_vec_and_offset()
            .0
    };
    let (i, d) = (p(&s.image), p(&s.disparity));
    let decomposed = render(&["--image", i, "--disparity", d], "a.npy");
    let from_stack = render(&["--layers", p(&stack)], "b.npy");
    let single = render(&["--image", i, "--disparity", d, "--single-layer"], "c.npy");
    let two = render(
        &["--image", i, "--disparity", d, "--max-layers", "2"],
        "e.npy",
    );
    assert_eq!(decomposed, from_stack);
    assert_eq!(decomposed, two);
    // Focused on the far right half: far from the edge it is the image in both.
    let at = |v: &[f32], x: usize, y: usize, c: usize| v[(y * W as usize + x) * 3 + c];
    let img = image::open(&s.image).unwrap().to_rgb8();
    for v in [&decomposed, &single] {
        let want = img.get_pixel(36, 15)[1] as f32 / 255.0;
        assert!((at(v, 36, 15, 1) - want).abs() < 1e-3);
    }
    // Near the edge, the blurred red foreground is rendered with the background behind
    // it: the two models differ there.
    let diff = (0..W as usize)
        .map(|x| (at(&decomposed, x, 15, 0) - at(&single, x, 15, 0)).abs())
        .fold(0.0f32, f32::max);
    assert!(diff > 0.02, "decomposition changed nothing ({diff})");
}

#[test]
fn bad_inputs_fail_cleanly_and_degenerate_ones_give_one_layer() {
    let s = scene();
    let dir = s.dir.path();
    let out = dir.join("out.npz");
    let small = dir.join("small.png");
    image::GrayImage::from_pixel(W - 1, H, image::Luma([255]))
        .save(&small)
        .unwrap();
    let fail = |args: &[&str], fragments: &[&str]| {
        let o = drbokeh(args);
        assert!(!o.status.success(), "{args:?} should fail");
        let e = stderr(&o);
        for f in fragments {
            assert!(e.contains(f), "{args:?}: {e:?} lacks {f:?}");
        }
        assert!(!out.exists());
    };
    let (i, d) = (p(&s.image), p(&s.disparity));
    fail(
        &[
            "layers",
            "--image",
            i,
            "--disparity",
            d,
            "--alpha",
            p(&small),
            "-o",
            p(&out),
        ],
        &["small.png", "39x30", "does not match"],
    );
    fail(
        &[
            "layers",
            "--image",
            i,
            "--disparity",
            d,
            "--max-layers",
            "0",
            "-o",
            p(&out),
        ],
        &["--max-layers", "between 1 and 16"],
    );
    fail(
        &[
            "layers",
            "--image",
            i,
            "--disparity",
            d,
            "--jump",
            "2",
            "-o",
            p(&out),
        ],
        &["--jump"],
    );
    fail(
        &[
            "layers",
            "--image",
            i,
            "--disparity",
            d,
            "-o",
            p(&dir.join("x.png")),
        ],
        &["x.png", ".npz"],
    );
    fail(&["layers", "--image", i, "-o", p(&out)], &["--disparity"]);
    let nan = dir.join("nan.npy");
    {
        use ndarray_npy::WriteNpyExt;
        let mut a = ndarray::Array2::<f32>::zeros((H as usize, W as usize));
        a[[3, 4]] = f32::NAN;
        a.write_npy(std::fs::File::create(&nan).unwrap()).unwrap();
    }
    fail(
        &[
            "layers",
            "--image",
            i,
            "--disparity",
            p(&nan),
            "-o",
            p(&out),
        ],
        &["nan.npy", "non-finite"],
    );
    fail(
        &[
            "render",
            "--image",
            i,
            "--disparity",
            d,
            "--alpha",
            p(&small),
            "-o",
            p(&dir.join("r.png")),
        ],
        &["small.png", "does not match"],
    );
    assert!(!dir.join("r.png").exists());
    // Empty matte: one layer and a note.
    let empty = dir.join("empty.png");
    image::GrayImage::new(W, H).save(&empty).unwrap();
    let o = drbokeh(&[
        "layers",
        "--image",
        i,
        "--disparity",
        d,
        "--alpha",
        p(&empty),
        "--no-preview",
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("note") && stderr(&o).contains("single opaque layer"));
    assert_eq!(
        drbokeh::io::read_stack::<f32>(&out).unwrap().layers.len(),
        1
    );
    // Disparity without a discontinuity: one layer and a note; render works too.
    let ramp = dir.join("ramp.png");
    image::ImageBuffer::<image::Luma<u16>, _>::from_fn(W, H, |x, _| {
        image::Luma([(x * 1000) as u16])
    })
    .save(&ramp)
    .unwrap();
    let o = drbokeh(&[
        "layers",
        "--image",
        i,
        "--disparity",
        p(&ramp),
        "--no-preview",
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("no disparity discontinuity"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        drbokeh::io::read_stack::<f32>(&out).unwrap().layers.len(),
        1
    );
    let r = dir.join("r.png");
    let o = drbokeh(&[
        "render",
        "--image",
        i,
        "--disparity",
        p(&ramp),
        "-o",
        p(&r),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).is_empty(), "{}", stderr(&o));
    // Without -q, the fallback to one layer is explained in one note line.
    let o = drbokeh(&["render", "--image", i, "--disparity", p(&ramp), "-o", p(&r)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    let notes: Vec<&str> = err.lines().filter(|l| l.contains("note:")).collect();
    assert_eq!(notes.len(), 1, "{err}");
    assert!(
        notes[0].contains("no disparity discontinuity") && notes[0].contains("single opaque layer"),
        "{}",
        notes[0]
    );
}

#[test]
fn render_leaves_out_cuts_that_cannot_change_the_render() {
    let s = scene();
    let (i, d) = (p(&s.image), p(&s.disparity));
    let render = |extra: &[&str], name: &str| {
        let out = s.dir.path().join(name);
        let mut args = vec!["render", "--image", i, "--disparity", d, "--blur", "10"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["-o", p(&out)]);
        let o = drbokeh(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        (stderr(&o), std::fs::read(&out).unwrap())
    };
    // Focused on the near half: it is sharp over a blurred background, layers cannot
    // change the render; a note says so and the output is the single layer's.
    let (err, near) = render(&["--focus", "1"], "near.png");
    assert!(
        err.contains("note:") && err.contains("focus and blur"),
        "{err}"
    );
    let (_, single) = render(&["--focus", "1", "--single-layer"], "single.png");
    assert_eq!(near, single);
    // Focused on the far half: two layers, no note.
    let (err, _) = render(&["--focus", "0"], "far.png");
    assert!(!err.contains("note:"), "{err}");
    assert!(err.contains("2 layer(s)"), "{err}");
    // `layers --focus --blur` makes the same choice.
    let out = s.dir.path().join("s.npz");
    let o = drbokeh(&[
        "layers",
        "--image",
        i,
        "--disparity",
        d,
        "--focus",
        "1",
        "--blur",
        "10",
        "--no-preview",
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("focus and blur"), "{}", stderr(&o));
    assert_eq!(
        drbokeh::io::read_stack::<f32>(&out).unwrap().layers.len(),
        1
    );
    let o = drbokeh(&[
        "layers",
        "--image",
        i,
        "--disparity",
        d,
        "--focus",
        "1",
        "--no-preview",
        "-o",
        p(&out),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--blur"), "{}", stderr(&o));
}

#[test]
fn vjp_on_an_image_uses_the_render_decomposition() {
    use ndarray::Array3;
    use ndarray_npy::NpzReader;
    let s = scene();
    let (i, d) = (p(&s.image), p(&s.disparity));
    let grad = s.dir.path().join("g.npy");
    ndarray_npy::write_npy(
        &grad,
        &ndarray::Array3::<f32>::ones((H as usize, W as usize, 3)),
    )
    .unwrap();
    // The number of layers in the gradient file is the number the render used.
    let layers_for = |focus: &str| {
        let out = s.dir.path().join(format!("grads-{focus}.npz"));
        let o = drbokeh(&[
            "vjp",
            "--image",
            i,
            "--disparity",
            d,
            "--blur",
            "10",
            "--focus",
            focus,
            "--grad-output",
            p(&grad),
            "-o",
            p(&out),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let mut npz = NpzReader::new(std::fs::File::open(&out).unwrap()).unwrap();
        let alpha: Array3<f32> = npz.by_name("alpha").unwrap();
        (alpha.shape()[0], stderr(&o))
    };
    // Focused on the near half, the cut cannot change the render: one layer, with a note.
    let (n, err) = layers_for("1");
    assert_eq!(n, 1, "{err}");
    assert!(
        err.contains("note:") && err.contains("focus and blur"),
        "{err}"
    );
    // Focused on the far half: the two layers `render` uses.
    let (n, err) = layers_for("0");
    assert_eq!(n, 2, "{err}");
}
