//! `drbokeh render` end to end: the machine contract, outputs, and every bad-input class
//! (exit code, message naming the file and the problem, no output file left behind).

mod common;

use common::{drbokeh, p, stderr, write_stack};
use ndarray::{Array3, Array4};
use ndarray_npy::{NpzWriter, ReadNpyExt, WriteNpyExt};
use std::path::PathBuf;

struct Dir(tempfile::TempDir);
impl Dir {
    fn new() -> Self {
        Dir(tempfile::tempdir().unwrap())
    }
    fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }
    /// Files other than the given inputs: must be none after a failure.
    fn assert_only(&self, inputs: &[&PathBuf]) {
        for e in std::fs::read_dir(self.0.path()).unwrap() {
            let e = e.unwrap().path();
            assert!(
                inputs.contains(&&e),
                "unexpected file left behind: {}",
                e.display()
            );
        }
    }
}

#[test]
fn machine_contract_writes_exactly_the_library_render() {
    let d = Dir::new();
    let stack_path = d.path("s.npz");
    let stack = write_stack(&stack_path, 24, 18);
    let out = d.path("out.npy");
    let o = drbokeh(&[
        "render",
        "--layers",
        p(&stack_path),
        "--preset",
        "paper",
        "--focus",
        "0.3",
        "--blur",
        "20",
        "--window",
        "15",
        "--gamma",
        "2.2",
        "--f64",
        "--output",
        p(&out),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let got = ndarray::Array3::<f64>::read_npy(std::fs::File::open(&out).unwrap()).unwrap();
    assert_eq!(got.shape(), &[18, 24, 3]);
    let mut s = drbokeh::RenderSettings::paper(0.3);
    s.camera.blur_k = 20.0;
    s.camera.window = drbokeh::Window::from_size(15).unwrap();
    let want =
        drbokeh::render(&stack, &s, drbokeh::Engine::Reference, &drbokeh::NoProgress).unwrap();
    let max = got
        .iter()
        .zip(&want.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        max <= 1e-12,
        "CLI output differs from library reference by {max}"
    );
    // f32 output: float32 (H, W, 3), close to the f64 result.
    let out32 = d.path("out32.npy");
    let o = drbokeh(&[
        "render",
        "--layers",
        p(&stack_path),
        "--focus",
        "0.3",
        "--blur",
        "20",
        "--window",
        "15",
        "--preset",
        "paper",
        "--output",
        p(&out32),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let got32 = ndarray::Array3::<f32>::read_npy(std::fs::File::open(&out32).unwrap()).unwrap();
    let max = got32
        .iter()
        .zip(&want.data)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0.0, f64::max);
    assert!(max <= 1e-4, "f32 CLI output vs f64 reference: {max}");
    // The default preset is `physical`.
    let out_default = d.path("default.npy");
    let o = drbokeh(&[
        "render",
        "--layers",
        p(&stack_path),
        "--focus",
        "0.3",
        "--blur",
        "20",
        "--window",
        "15",
        "--f64",
        "--output",
        p(&out_default),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let got = ndarray::Array3::<f64>::read_npy(std::fs::File::open(&out_default).unwrap()).unwrap();
    let mut s = drbokeh::RenderSettings::physical(0.3);
    s.camera.blur_k = 20.0;
    s.camera.window = drbokeh::Window::from_size(15).unwrap();
    let want =
        drbokeh::render(&stack, &s, drbokeh::Engine::Reference, &drbokeh::NoProgress).unwrap();
    let max = got
        .iter()
        .zip(&want.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(max <= 1e-12, "default preset is not physical: {max}");
}

#[test]
fn demo_renders_to_every_output_format_and_threads_do_not_change_bytes() {
    let d = Dir::new();
    for name in ["a.png", "b.tif", "c.exr", "d.npy", "f.jpg"] {
        let out = d.path(name);
        let o = drbokeh(&[
            "render",
            "--demo",
            "--demo-size",
            "64x48",
            "--output",
            p(&out),
            "-q",
        ]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        assert!(std::fs::metadata(&out).unwrap().len() > 100);
    }
    let img = image::open(d.path("a.png")).unwrap();
    assert_eq!((img.width(), img.height()), (64, 48));
    let out16 = d.path("e.png");
    let o = drbokeh(&[
        "render",
        "--demo",
        "--demo-size",
        "64x48",
        "--bit-depth",
        "16",
        "-o",
        p(&out16),
        "-q",
    ]);
    assert!(o.status.success());
    assert!(matches!(
        image::open(&out16).unwrap(),
        image::DynamicImage::ImageRgb16(_)
    ));
    let (t1, t3) = (d.path("t1.npy"), d.path("t3.npy"));
    for (t, n) in [(&t1, "1"), (&t3, "3")] {
        let o = drbokeh(&[
            "render",
            "--demo",
            "--demo-size",
            "50x40",
            "--threads",
            n,
            "-o",
            p(t),
            "-q",
        ]);
        assert!(o.status.success());
    }
    assert_eq!(std::fs::read(&t1).unwrap(), std::fs::read(&t3).unwrap());
}

#[test]
fn image_disparity_matte_and_focus_at() {
    let d = Dir::new();
    let (w, h) = (40u32, 30u32);
    let img =
        image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 6) as u8, (y * 8) as u8, 128]));
    let disp = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(w, h, |x, _| {
        image::Luma([if x < 20 { 60000 } else { 5000 }])
    });
    let matte = image::GrayImage::from_fn(w, h, |x, _| image::Luma([if x < 20 { 255 } else { 0 }]));
    let (ip, dp, mp) = (d.path("i.png"), d.path("d.png"), d.path("m.png"));
    img.save(&ip).unwrap();
    disp.save(&dp).unwrap();
    matte.save(&mp).unwrap();
    let out = d.path("o.png");
    let o = drbokeh(&[
        "render",
        "--image",
        p(&ip),
        "--disparity",
        p(&dp),
        "--alpha",
        p(&mp),
        "--focus-at",
        "5,5",
        "--blur",
        "8",
        "-o",
        p(&out),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rendered = image::open(&out).unwrap().to_rgb8();
    // Focused on the left half (near): it stays sharp.
    assert_eq!(rendered.get_pixel(5, 15), img.get_pixel(5, 15));
    // Depth input: 1/z normalised. Larger depth = farther.
    let depth = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(w, h, |x, _| {
        image::Luma([if x < 20 { 1000 } else { 50000 }])
    });
    let zp = d.path("z.png");
    depth.save(&zp).unwrap();
    let out2 = d.path("o2.png");
    let o = drbokeh(&[
        "render",
        "--image",
        p(&ip),
        "--depth",
        p(&zp),
        "--focus",
        "1",
        "--blur",
        "8",
        "-o",
        p(&out2),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        image::open(&out2).unwrap().to_rgb8().get_pixel(5, 15),
        img.get_pixel(5, 15)
    );
}

/// Runs a failing command and checks exit code, message fragments and no output file.
fn expect_failure(d: &Dir, inputs: &[&PathBuf], args: &[&str], fragments: &[&str]) {
    let o = drbokeh(args);
    assert!(!o.status.success(), "{args:?} should fail");
    let err = stderr(&o);
    for f in fragments {
        assert!(err.contains(f), "{args:?}: message {err:?} lacks {f:?}");
    }
    assert!(err.lines().count() <= 2, "message should be short: {err}");
    d.assert_only(inputs);
}

#[test]
fn bad_inputs_fail_cleanly() {
    let d = Dir::new();
    let out = d.path("out.png");
    let o = p(&out).to_string();
    let (w, h) = (20u32, 16u32);
    let ip = d.path("img.png");
    image::RgbImage::from_pixel(w, h, image::Rgb([100, 100, 100]))
        .save(&ip)
        .unwrap();
    let dp = d.path("disp.png");
    image::GrayImage::from_pixel(w, h, image::Luma([100]))
        .save(&dp)
        .unwrap();
    let small = d.path("small.png");
    image::GrayImage::from_pixel(w - 1, h, image::Luma([100]))
        .save(&small)
        .unwrap();
    let rgbdisp = d.path("rgbdisp.png");
    image::RgbImage::from_pixel(w, h, image::Rgb([1, 2, 3]))
        .save(&rgbdisp)
        .unwrap();
    let good = d.path("good.npz");
    write_stack(&good, 12, 10);
    let corrupt = d.path("corrupt.png");
    std::fs::write(
        &corrupt,
        b"\x89PNG\r\n\x1a\nthis is not really a png at all",
    )
    .unwrap();
    let truncated = d.path("trunc.png");
    let bytes = std::fs::read(&ip).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let trunc_npz = d.path("trunc.npz");
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(&trunc_npz, &bytes[..bytes.len() / 2]).unwrap();
    // NPZ variants.
    let write_npz =
        |name: &str, rgb: Array4<f32>, alpha: Option<Array3<f32>>, disp: Array3<f32>| {
            let path = d.path(name);
            let mut npz = NpzWriter::new(std::fs::File::create(&path).unwrap());
            npz.add_array("rgb", &rgb).unwrap();
            if let Some(a) = alpha {
                npz.add_array("alpha", &a).unwrap();
            }
            npz.add_array("disparity", &disp).unwrap();
            npz.finish().unwrap();
            path
        };
    let missing = write_npz(
        "missing.npz",
        Array4::zeros((1, 4, 4, 3)),
        None,
        Array3::zeros((1, 4, 4)),
    );
    let mismatch = write_npz(
        "mismatch.npz",
        Array4::zeros((2, 4, 4, 3)),
        Some(Array3::ones((2, 4, 5))),
        Array3::zeros((2, 4, 4)),
    );
    let mut nan_disp = Array3::<f32>::zeros((1, 4, 4));
    nan_disp[[0, 2, 1]] = f32::NAN;
    let nan = write_npz(
        "nan.npz",
        Array4::zeros((1, 4, 4, 3)),
        Some(Array3::ones((1, 4, 4))),
        nan_disp,
    );
    let two_ch = write_npz(
        "twoch.npz",
        Array4::zeros((1, 4, 4, 2))
            .into_shape_with_order((1, 4, 4, 2))
            .unwrap(),
        Some(Array3::ones((1, 4, 4))),
        Array3::zeros((1, 4, 4)),
    );
    let empty = write_npz(
        "empty.npz",
        Array4::zeros((1, 0, 4, 3)),
        Some(Array3::ones((1, 0, 4))),
        Array3::zeros((1, 0, 4)),
    );
    let absurd = write_npz(
        "absurd.npz",
        Array4::zeros((1, 70_000, 1, 3)),
        Some(Array3::ones((1, 70_000, 1))),
        Array3::zeros((1, 70_000, 1)),
    );
    let inf_npy = d.path("inf.npy");
    let mut arr = ndarray::Array2::<f32>::zeros((h as usize, w as usize));
    arr[[3, 3]] = f32::INFINITY;
    arr.write_npy(std::fs::File::create(&inf_npy).unwrap())
        .unwrap();

    let all = [
        &ip, &dp, &small, &rgbdisp, &good, &corrupt, &truncated, &trunc_npz, &missing, &mismatch,
        &nan, &two_ch, &empty, &absurd, &inf_npy,
    ];
    let r = |extra: &[&str]| {
        let mut v = vec!["render"];
        v.extend_from_slice(extra);
        v.extend_from_slice(&["--output", &o]);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let cases: Vec<(Vec<String>, Vec<String>)> = vec![
        (
            r(&["--image", p(&ip), "--disparity", p(&small)]),
            vec![p(&small).into(), "does not match".into()],
        ),
        (
            r(&[
                "--image",
                p(&ip),
                "--disparity",
                p(&dp),
                "--alpha",
                p(&small),
            ]),
            vec![p(&small).into(), "does not match".into()],
        ),
        (
            r(&["--image", p(&ip), "--disparity", p(&rgbdisp)]),
            vec![p(&rgbdisp).into(), "single-channel".into()],
        ),
        (
            r(&[
                "--image",
                p(&ip),
                "--disparity",
                p(&dp),
                "--alpha",
                p(&rgbdisp),
            ]),
            vec![p(&rgbdisp).into(), "alpha".into()],
        ),
        (
            r(&["--layers", p(&mismatch)]),
            vec![p(&mismatch).into(), "'alpha'".into(), "shape".into()],
        ),
        (
            r(&["--layers", p(&two_ch)]),
            vec![p(&two_ch).into(), "(N, H, W, 3)".into()],
        ),
        (
            r(&["--layers", p(&nan)]),
            vec![p(&nan).into(), "non-finite".into()],
        ),
        (
            r(&["--image", p(&ip), "--disparity", p(&inf_npy)]),
            vec![p(&inf_npy).into(), "non-finite".into()],
        ),
        (
            r(&["--layers", p(&empty)]),
            vec![p(&empty).into(), "empty".into()],
        ),
        (
            r(&["--layers", p(&absurd)]),
            vec![p(&absurd).into(), "absurd".into()],
        ),
        (
            r(&["--demo", "--demo-size", "100000x100000"]),
            vec!["absurd".into()],
        ),
        (
            r(&["--image", p(&corrupt), "--disparity", p(&dp)]),
            vec![p(&corrupt).into()],
        ),
        (
            r(&["--image", p(&truncated), "--disparity", p(&dp)]),
            vec![p(&truncated).into()],
        ),
        (r(&["--layers", p(&trunc_npz)]), vec![p(&trunc_npz).into()]),
        (
            r(&["--layers", p(&missing)]),
            vec![p(&missing).into(), "missing key 'alpha'".into()],
        ),
        (
            r(&["--layers", p(&good), "--window", "8"]),
            vec!["--window".into(), "odd".into()],
        ),
        (
            r(&["--layers", p(&good), "--focus", "1.5"]),
            vec!["--focus".into(), "[0, 1]".into()],
        ),
        (
            r(&["--layers", p(&good), "--focus-at", "100,3"]),
            vec!["--focus-at".into(), "outside".into()],
        ),
        (
            r(&["--layers", p(&good), "--aperture", "blob"]),
            vec!["--aperture".into(), "unknown".into()],
        ),
        (
            r(&["--layers", p(&good), "--preset", "nope"]),
            vec!["--preset".into(), "paper".into()],
        ),
        (
            r(&["--layers", &d.path("nope.npz").to_string_lossy()]),
            vec!["nope.npz".into(), "cannot open".into()],
        ),
        (
            vec![
                "render".into(),
                "--demo".into(),
                "--output".into(),
                d.path("x.bmp").to_string_lossy().into(),
            ],
            vec!["x.bmp".into(), "unsupported output extension".into()],
        ),
    ];
    for (args, frags) in &cases {
        let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        let frags: Vec<&str> = frags.iter().map(|s| s.as_str()).collect();
        expect_failure(&d, &all, &args, &frags);
    }
    // Unknown option: usage error, exit code 2.
    let o2 = drbokeh(&["render", "--demo", "--bogus", "--output", &o]);
    assert_eq!(o2.status.code(), Some(2));
    assert!(stderr(&o2).contains("--bogus"));
    d.assert_only(&all);
}
