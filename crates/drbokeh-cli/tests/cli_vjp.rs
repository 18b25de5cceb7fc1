//! `drbokeh vjp`: the machine contract (keys, shapes, values equal to the library's exact
//! gradient) and its input checks.

mod common;

use common::{drbokeh, p, stderr, write_stack};
use ndarray::{Array0, Array3, Array4};
use ndarray_npy::{NpzReader, WriteNpyExt};

#[test]
fn vjp_writes_the_library_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let stack_path = dir.path().join("s.npz");
    let stack = write_stack(&stack_path, 14, 11);
    let g = Array3::<f64>::from_shape_fn((11, 14, 3), |(y, x, c)| {
        ((x * 3 + y * 5 + c) % 7) as f64 / 7.0 - 0.4
    });
    let g_path = dir.path().join("g.npy");
    g.write_npy(std::fs::File::create(&g_path).unwrap())
        .unwrap();
    let out = dir.path().join("grads.npz");
    let o = drbokeh(&[
        "vjp",
        "--layers",
        p(&stack_path),
        "--grad-output",
        p(&g_path),
        "--focus",
        "0.35",
        "--blur",
        "12",
        "--window",
        "11",
        "--preset",
        "paper",
        "--f64",
        "--output",
        p(&out),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut npz = NpzReader::new(std::fs::File::open(&out).unwrap()).unwrap();
    let rgb: Array4<f64> = npz.by_name("rgb").unwrap();
    let alpha: Array3<f64> = npz.by_name("alpha").unwrap();
    let disp: Array3<f64> = npz.by_name("disparity").unwrap();
    let blur: Array0<f64> = npz.by_name("blur").unwrap();
    let focus: Array0<f64> = npz.by_name("focus").unwrap();
    assert_eq!(rgb.shape(), &[2, 11, 14, 3]);
    assert_eq!(alpha.shape(), &[2, 11, 14]);
    assert_eq!(disp.shape(), &[2, 11, 14]);

    let mut s = drbokeh::RenderSettings::paper(0.35);
    s.camera.blur_k = 12.0;
    s.camera.window = drbokeh::Window::from_size(11).unwrap();
    let (_, tape) = drbokeh::render_with_tape(&stack, &s, &drbokeh::NoProgress).unwrap();
    let gi = drbokeh::Image::from_vec(14, 11, 3, g.iter().copied().collect()).unwrap();
    let want = tape.backward(&gi, &drbokeh::NoProgress).unwrap();
    for l in 0..2 {
        assert_eq!(
            rgb.index_axis(ndarray::Axis(0), l)
                .iter()
                .copied()
                .collect::<Vec<_>>(),
            want.layers[l].rgb.data
        );
        assert_eq!(
            alpha
                .index_axis(ndarray::Axis(0), l)
                .iter()
                .copied()
                .collect::<Vec<_>>(),
            want.layers[l].alpha.data
        );
        assert_eq!(
            disp.index_axis(ndarray::Axis(0), l)
                .iter()
                .copied()
                .collect::<Vec<_>>(),
            want.layers[l].disparity.data
        );
    }
    assert_eq!(blur.into_scalar(), want.blur_k);
    assert_eq!(focus.into_scalar(), want.focus);
    assert!(want.blur_k != 0.0 && want.focus != 0.0);

    // Central finite difference of sum(G * render) through the CLI's own render, for focus.
    let render_sum = |f: &str| {
        let r = dir.path().join("r.npy");
        let o = drbokeh(&[
            "render",
            "--layers",
            p(&stack_path),
            "--focus",
            f,
            "--blur",
            "12",
            "--window",
            "11",
            "--preset",
            "paper",
            "--f64",
            "--output",
            p(&r),
            "-q",
        ]);
        assert!(o.status.success());
        use ndarray_npy::ReadNpyExt;
        let a = Array3::<f64>::read_npy(std::fs::File::open(&r).unwrap()).unwrap();
        (&a * &g).sum()
    };
    let fd = (render_sum("0.350001") - render_sum("0.349999")) / 2e-6;
    assert!(
        (fd - want.focus).abs() < 1e-4 * fd.abs().max(1e-3),
        "focus: fd {fd} vs {}",
        want.focus
    );
}

#[test]
fn vjp_rejects_bad_gradients() {
    let dir = tempfile::tempdir().unwrap();
    let stack_path = dir.path().join("s.npz");
    write_stack(&stack_path, 8, 6);
    let g_path = dir.path().join("g.npy");
    Array3::<f32>::zeros((6, 9, 3))
        .write_npy(std::fs::File::create(&g_path).unwrap())
        .unwrap();
    let out = dir.path().join("grads.npz");
    let o = drbokeh(&[
        "vjp",
        "--layers",
        p(&stack_path),
        "--grad-output",
        p(&g_path),
        "--focus",
        "0.5",
        "-o",
        p(&out),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("g.npy") && stderr(&o).contains("9x6"),
        "{}",
        stderr(&o)
    );
    Array3::<f32>::zeros((6, 8, 2))
        .write_npy(std::fs::File::create(&g_path).unwrap())
        .unwrap();
    let o = drbokeh(&[
        "vjp",
        "--layers",
        p(&stack_path),
        "--grad-output",
        p(&g_path),
        "--focus",
        "0.5",
        "-o",
        p(&out),
    ]);
    assert!(stderr(&o).contains("expected (H, W, 3)"), "{}", stderr(&o));
    assert!(!out.exists());
}

/// Without --f64, `--engine auto` runs the adjoint on the fast engine: the CLI's gradient is
/// the library's `render_with_tape_on(.., Engine::Fast, ..)` in f32, and `--engine
/// threaded` the exact one.
#[test]
fn vjp_auto_in_f32_uses_the_fast_adjoint() {
    let dir = tempfile::tempdir().unwrap();
    let stack_path = dir.path().join("s.npz");
    let stack = write_stack(&stack_path, 13, 10).cast::<f32>();
    let g = Array3::<f32>::from_shape_fn((10, 13, 3), |(y, x, c)| {
        ((x * 5 + y * 3 + c) % 9) as f32 / 9.0 - 0.45
    });
    let g_path = dir.path().join("g.npy");
    g.write_npy(std::fs::File::create(&g_path).unwrap())
        .unwrap();
    let mut s = drbokeh::RenderSettings::paper(0.35);
    s.camera.blur_k = 12.0;
    s.camera.window = drbokeh::Window::from_size(11).unwrap();
    let gi = drbokeh::Image::from_vec(13, 10, 3, g.iter().copied().collect()).unwrap();
    for (engine, want_engine) in [
        ("auto", drbokeh::Engine::Fast),
        ("threaded", drbokeh::Engine::Threaded),
    ] {
        let out = dir.path().join(format!("grads-{engine}.npz"));
        let o = drbokeh(&[
            "vjp",
            "--layers",
            p(&stack_path),
            "--grad-output",
            p(&g_path),
            "--focus",
            "0.35",
            "--blur",
            "12",
            "--window",
            "11",
            "--engine",
            engine,
            "--preset",
            "paper",
            "--output",
            p(&out),
            "-q",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let mut npz = NpzReader::new(std::fs::File::open(&out).unwrap()).unwrap();
        let alpha: Array3<f32> = npz.by_name("alpha").unwrap();
        let disp: Array3<f32> = npz.by_name("disparity").unwrap();
        let (_, tape) =
            drbokeh::render_with_tape_on(&stack, &s, want_engine, &drbokeh::NoProgress).unwrap();
        let want = tape.backward(&gi, &drbokeh::NoProgress).unwrap();
        for l in 0..2 {
            let layer = |a: &Array3<f32>| {
                a.index_axis(ndarray::Axis(0), l)
                    .iter()
                    .copied()
                    .collect::<Vec<_>>()
            };
            assert_eq!(layer(&alpha), want.layers[l].alpha.data, "{engine}");
            assert_eq!(layer(&disp), want.layers[l].disparity.data, "{engine}");
        }
    }
}
