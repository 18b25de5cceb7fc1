//! CLI tests of `drbokeh eval` and `drbokeh gallery` on a tiny generated benchmark.

use std::path::Path;
use std::process::{Command, Output};

fn drbokeh(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drbokeh"))
        .args(args)
        .output()
        .expect("cannot run drbokeh")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn make_bench(dir: &Path) {
    let o = drbokeh(&[
        "benchmark",
        "make",
        "--scenes",
        "2",
        "--size",
        "64",
        "--spp",
        "16",
        "--quiet",
        "--output",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn eval_and_gallery_write_their_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let bench = tmp.path().join("bench");
    make_bench(&bench);
    let out = tmp.path().join("report");
    let o = drbokeh(&[
        "eval",
        "--benchmark",
        bench.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "--methods",
        "gather,paper-gt",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "results.json",
        "results.csv",
        "summary.md",
        "index.html",
        "psnr_vs_blur.svg",
        "ssim_vs_blur.svg",
        "ms_ssim_vs_blur.svg",
        "scenes/scene_000/gt.jpg",
        "scenes/scene_001/paper-gt.err.png",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 2 * 2, "{csv}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["methods"].as_array().unwrap().len(), 2);
    assert_eq!(json["scenes"][1]["results"][1]["method"], "paper-gt");

    // Gallery from pairs named NAME.png + NAME.disp.png (one image without a partner).
    let imgs = tmp.path().join("imgs");
    std::fs::create_dir(&imgs).unwrap();
    std::fs::copy(bench.join("scene_000/aif.png"), imgs.join("a.png")).unwrap();
    std::fs::copy(
        bench.join("scene_000/disparity.png"),
        imgs.join("a.disp.png"),
    )
    .unwrap();
    std::fs::copy(bench.join("scene_001/aif.png"), imgs.join("lonely.png")).unwrap();
    let gal = tmp.path().join("gallery");
    let o = drbokeh(&[
        "gallery",
        "--images",
        imgs.to_str().unwrap(),
        "--focal-planes",
        "3",
        "--blur",
        "8",
        "--output",
        gal.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("lonely.png"), "{}", stderr(&o));
    let html = std::fs::read_to_string(gal.join("index.html")).unwrap();
    let srcs: Vec<&str> = html
        .split("src=\"")
        .skip(1)
        .map(|s| s.split('"').next().unwrap())
        .collect();
    // Inputs (2) + 3 focal planes x 8 image+disparity methods (2 photo pipelines, 4
    // baselines, paper-aif, physical-aif).
    assert_eq!(srcs.len(), 2 + 3 * 8, "{html}");
    for s in srcs {
        assert!(gal.join(s).is_file(), "missing {s}");
    }
}

#[test]
fn bad_inputs_fail_with_clear_messages() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope");
    let out = tmp.path().join("out");
    let o = drbokeh(&[
        "eval",
        "--benchmark",
        missing.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));
    assert!(!out.exists(), "no output for a failed run");

    // A scene directory without its images.
    let bench = tmp.path().join("bench");
    std::fs::create_dir_all(bench.join("scene_000")).unwrap();
    std::fs::write(
        bench.join("scene_000/scene.json"),
        r#"{"blur": 5.0, "focus": 0.5}"#,
    )
    .unwrap();
    let o = drbokeh(&[
        "eval",
        "--benchmark",
        bench.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("aif.png") && stderr(&o).contains("missing"),
        "{}",
        stderr(&o)
    );

    let o = drbokeh(&[
        "eval",
        "--benchmark",
        bench.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "--methods",
        "gather,magic",
    ]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "a bad option value is a usage error"
    );
    assert!(
        stderr(&o).contains("unknown method 'magic'"),
        "{}",
        stderr(&o)
    );

    let o = drbokeh(&[
        "gallery",
        "--images",
        missing.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));
    let o = drbokeh(&[
        "gallery",
        "--images",
        bench.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("no image + disparity pairs"),
        "{}",
        stderr(&o)
    );
}

/// The eval's photo rows are `drbokeh render --image aif.png --disparity disparity.npy`
/// with the scene's K and focus: the same 8-bit PNG bytes, per preset, and a highlight
/// setting other than the default changes them (so the comparison can fail).
#[test]
fn photo_rows_render_what_the_cli_renders() {
    use drbokeh::eval::report::{render_method, Method, SceneInputs};
    let tmp = tempfile::tempdir().unwrap();
    let bench = tmp.path().join("bench");
    let o = drbokeh(&[
        "benchmark",
        "make",
        "--scenes",
        "1",
        "--size",
        "48",
        "--spp",
        "16",
        "--highlight-range",
        "5:50",
        "--quiet",
        "--output",
        bench.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = bench.join("scene_000");
    let scene = SceneInputs::load(&dir).unwrap();
    let (k, f) = (format!("{}", scene.blur_k), format!("{}", scene.focus));
    let aif = dir.join("aif.png").to_str().unwrap().to_string();
    let disparity = dir.join("disparity.npy").to_str().unwrap().to_string();
    for (method, preset) in [
        (Method::PhotoPhysical, "physical"),
        (Method::PhotoPaper, "paper"),
    ] {
        let cli_png = tmp.path().join(format!("cli-{preset}.png"));
        let cli = |extra: &[&str], out: &Path| {
            let mut args = vec![
                "render",
                "--image",
                &aif,
                "--disparity",
                &disparity,
                "--blur",
                &k,
                "--focus",
                &f,
                "--preset",
                preset,
                "--quiet",
                "-o",
                out.to_str().unwrap(),
            ];
            args.extend_from_slice(extra);
            let o = drbokeh(&args);
            assert!(o.status.success(), "{}", stderr(&o));
            std::fs::read(out).unwrap()
        };
        let cli_bytes = cli(&[], &cli_png);
        let lib = render_method(method, &scene).unwrap();
        let lib_png = tmp.path().join(format!("lib-{preset}.png"));
        drbokeh::io::write_output(&lib_png, &lib, drbokeh::io::BitDepth::Eight, |v| v).unwrap();
        assert!(
            std::fs::read(&lib_png).unwrap() == cli_bytes,
            "{}: eval row and CLI render differ",
            method.name()
        );
        let other = cli(&["--highlight", "off"], &tmp.path().join("off.png"));
        assert!(other != cli_bytes, "--highlight off renders the same bytes");
    }
}
