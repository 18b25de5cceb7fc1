//! `drbokeh dfd`: writes the disparity, its JSON loss log and a preview; rejects bad input.

mod common;

use common::{drbokeh, p, stderr};

fn write_pair(dir: &std::path::Path, w: u32, h: u32) -> (std::path::PathBuf, std::path::PathBuf) {
    let aif = image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([
            ((x * 37 + y * 11) % 255) as u8,
            ((x * 5 + y * 29) % 255) as u8,
            90,
        ])
    });
    let (a, b) = (dir.join("aif.png"), dir.join("blur.png"));
    aif.save(&a).unwrap();
    // A crude "defocused" version: a 3x3 box blur.
    let blurred = image::imageops::blur(&aif, 1.5);
    blurred.save(&b).unwrap();
    (a, b)
}

/// `drbokeh dfd` on a pair at focus 1, K 4, full resolution, quiet, with `extra` options.
fn quick_dfd(
    a: &std::path::Path,
    b: &std::path::Path,
    out: &std::path::Path,
    extra: &[&str],
) -> std::process::Output {
    let mut args = vec![
        "dfd",
        "--all-in-focus",
        p(a),
        "--defocused",
        p(b),
        "--focus",
        "1",
        "--blur",
        "4",
        "--finest-scale",
        "0",
        "--output",
        p(out),
        "-q",
    ];
    args.extend_from_slice(extra);
    drbokeh(&args)
}

#[test]
fn dfd_writes_disparity_log_and_preview() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = write_pair(d.path(), 32, 32);
    let out = d.path().join("disp.png");
    let o = quick_dfd(
        &a,
        &b,
        &out,
        &[
            "--fine-iterations",
            "3",
            "--patience",
            "0",
            "--method",
            "gausspsf",
            "--losses",
            "l1,smooth=2",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    // Blur 4 px at full resolution, focus 1: nothing to note, and -q prints nothing.
    assert!(stderr(&o).is_empty(), "{}", stderr(&o));
    let disp = image::open(&out).unwrap();
    assert!(matches!(disp, image::DynamicImage::ImageLuma16(_)));
    let log: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.path().join("disp.log.json")).unwrap()).unwrap();
    assert_eq!(log["layer"], "gausspsf");
    // A term's own weight (TERM=WEIGHT); the others off.
    assert_eq!(log["weights"]["smoothness"], 2.0);
    assert_eq!(log["weights"]["l1"], 0.5);
    assert_eq!(log["weights"]["hssim"], 0.0);
    // 3 iterations at the one (full-resolution) scale.
    assert_eq!(log["scales"].as_array().unwrap().len(), 1);
    assert_eq!(log["entries"].as_array().unwrap().len(), 3);
    assert!(log["entries"][0]["l1"].as_f64().unwrap() > 0.0);
    assert!(log["entries"][0]["structure"].is_null());
    assert!(d.path().join("disp.confidence.png").exists());
    assert!(d.path().join("disp.preview.png").exists());
    // The sensitivity map only when asked for (a float map here).
    let files = std::fs::read_dir(d.path()).unwrap().count();
    let sens = d.path().join("sens.npy");
    let o = quick_dfd(
        &a,
        &b,
        &d.path().join("disp2.png"),
        &["--fine-iterations", "2", "--sensitivity", p(&sens)],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    // disp2.png, its confidence, log and preview, and the sensitivity.
    assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), files + 5);
    let bytes = std::fs::read(&sens).unwrap();
    assert!(bytes.starts_with(b"\x93NUMPY"));
}

#[test]
fn dfd_notes_a_small_blur_and_a_focus_inside_the_range() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = write_pair(d.path(), 32, 32);
    let out = d.path().join("disp.png");
    // Focus 0.5 with K 4: the largest blur is 2 px, and the sign of d is open.
    let o = drbokeh(&[
        "dfd",
        "--all-in-focus",
        p(&a),
        "--defocused",
        p(&b),
        "--focus",
        "0.5",
        "--blur",
        "4",
        "--fine-iterations",
        "2",
        "--output",
        p(&out),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    // Printed even with -q, one line each.
    let notes: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("drbokeh: note: "))
        .collect();
    assert_eq!(notes.len(), 2, "{err}");
    assert!(notes[0].contains("largest blur is 2.0 px"), "{err}");
    assert!(notes[1].contains("focus 0.5 is inside"), "{err}");
    let log: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.path().join("disp.log.json")).unwrap()).unwrap();
    assert_eq!(log["schema_version"], 2);
    assert_eq!(log["notes"][0]["kind"], "small_blur");
    assert_eq!(log["notes"][0]["blur_px"], 2.0);
    assert_eq!(log["notes"][1]["kind"], "focus_inside");
}

#[test]
fn dfd_rejects_bad_input() {
    let d = tempfile::tempdir().unwrap();
    let (a, _) = write_pair(d.path(), 32, 32);
    let small = d.path().join("small.png");
    image::RgbImage::new(31, 32).save(&small).unwrap();
    let out = d.path().join("disp.png");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "dfd",
            "--all-in-focus",
            p(&a),
            "--focus",
            "1",
            "--blur",
            "4",
            "-q",
        ];
        args.extend_from_slice(extra);
        drbokeh(&args)
    };
    let o = run(&["--defocused", p(&small), "--output", p(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("small.png") && stderr(&o).contains("does not match"),
        "{}",
        stderr(&o)
    );
    let o = run(&["--defocused", p(&a), "--losses", "l2", "--output", p(&out)]);
    assert!(
        stderr(&o).contains("unknown loss term 'l2'"),
        "{}",
        stderr(&o)
    );
    let o = run(&[
        "--defocused",
        p(&a),
        "--losses",
        "l1,smooth=-1",
        "--output",
        p(&out),
    ]);
    assert_ne!(o.status.code(), Some(0));
    assert!(
        stderr(&o).contains("the weight of 'smooth'") && stderr(&o).contains("-1"),
        "{}",
        stderr(&o)
    );
    let o = run(&[
        "--defocused",
        p(&a),
        "--method",
        "nope",
        "--output",
        p(&out),
    ]);
    assert!(stderr(&o).contains("unknown layer"), "{}", stderr(&o));
    let o = run(&[
        "--defocused",
        p(&a),
        "--output",
        p(&d.path().join("disp.txt")),
    ]);
    assert!(
        stderr(&o).contains("unsupported output extension"),
        "{}",
        stderr(&o)
    );
    // A start outside [0, 1]: the file, the value and the pixel are named.
    let mut start = ndarray::Array2::<f32>::from_elem((32, 32), 0.5);
    start[[2, 3]] = -0.25;
    let init = d.path().join("init.npy");
    ndarray_npy::write_npy(&init, &start).unwrap();
    let o = run(&[
        "--defocused",
        p(&a),
        "--initial-disparity",
        p(&init),
        "--output",
        p(&out),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o)
            .contains("init.npy: initial disparity -0.25 at pixel x=3, y=2 is outside [0, 1]"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

#[test]
fn dfd_occlusion_layers_are_logged_and_checked() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = write_pair(d.path(), 32, 32);
    let out = d.path().join("disp.png");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "dfd",
            "--all-in-focus",
            p(&a),
            "--defocused",
            p(&b),
            "--focus",
            "0",
            "--blur",
            "4",
            "--fine-iterations",
            "3",
            "--patience",
            "0",
            "--finest-scale",
            "0",
            "--losses",
            "l1,smooth",
            "--output",
            p(&out),
            "-q",
        ];
        args.extend_from_slice(extra);
        drbokeh(&args)
    };
    let o = run(&["--occlusion-layers", "3", "--redecompose-every", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let log: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.path().join("disp.log.json")).unwrap()).unwrap();
    assert_eq!(log["layered"]["max_layers"], 3);
    assert_eq!(log["layered"]["every"], 2);
    assert_eq!(log["entries"].as_array().unwrap().len(), 3);
    std::fs::remove_file(&out).unwrap();
    let o = run(&["--redecompose-every", "2"]);
    assert_eq!(o.status.code(), Some(2)); // a usage error
    assert!(
        stderr(&o).contains("--redecompose-every") && stderr(&o).contains("--occlusion-layers"),
        "{}",
        stderr(&o)
    );
    let o = run(&["--occlusion-layers", "17"]);
    assert_eq!(o.status.code(), Some(2)); // a usage error
    assert!(stderr(&o).contains("--occlusion-layers"), "{}", stderr(&o));
    assert!(!out.exists());
}

#[test]
fn dfd_colour_vote_is_off_by_default_logged_when_on_and_checked() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = write_pair(d.path(), 32, 32);
    let out = d.path().join("disp.png");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "dfd",
            "--all-in-focus",
            p(&a),
            "--defocused",
            p(&b),
            "--focus",
            "0",
            "--blur",
            "4",
            "--fine-iterations",
            "2",
            "--finest-scale",
            "0",
            "--output",
            p(&out),
            "-q",
        ];
        args.extend_from_slice(extra);
        drbokeh(&args)
    };
    let log_of = || -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(d.path().join("disp.log.json")).unwrap()).unwrap()
    };
    let o = run(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(log_of().get("colour_vote").is_none());
    std::fs::remove_file(&out).unwrap();
    let o = run(&["--colour-bins", "16"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(log_of()["colour_vote"], 16);
    std::fs::remove_file(&out).unwrap();
    let o = run(&["--colour-bins", "0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(log_of().get("colour_vote").is_none());
    std::fs::remove_file(&out).unwrap();
    let o = run(&["--colour-bins", "300"]);
    assert_eq!(o.status.code(), Some(2)); // a usage error
    assert!(stderr(&o).contains("--colour-bins"), "{}", stderr(&o));
    assert!(!out.exists());
}

/// `dfd-eval --benchmark` on a tiny traced benchmark: `results.json` scores each optimised
/// run's confidence and sensitivity maps by their sparsification (the constant has none),
/// and `results.md` shows the columns.
#[test]
fn dfd_eval_scores_the_confidence_maps() {
    let d = tempfile::tempdir().unwrap();
    let bench = d.path().join("bench");
    let o = drbokeh(&[
        "benchmark",
        "make",
        "--scenes",
        "2",
        "--size",
        "48",
        "--spp",
        "4",
        "--output",
        p(&bench),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = d.path().join("report");
    let o = drbokeh(&[
        "dfd-eval",
        "--benchmark",
        p(&bench),
        "--methods",
        "physical",
        "--losses",
        "hssim",
        "--groups",
        "all",
        "--output",
        p(&out),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["schema_version"], 2);
    let scenes = json["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 2);
    for sc in scenes {
        let runs = sc["results"].as_array().unwrap();
        let (ours, constant) = (&runs[0], &runs[1]);
        let mae = ours["errors"]["mae"].as_f64().unwrap();
        let half = ours["mae_confident_half"].as_f64().unwrap();
        // The most confident half cannot hold more than twice the whole map's error.
        assert!((0.0..=2.0 * mae + 1e-12).contains(&half), "{half} vs {mae}");
        for k in ["ause", "ause_sensitivity", "ause_uninformative"] {
            let v = ours[k].as_f64().unwrap();
            // The oracle's curve is the lowest any ranking can reach.
            assert!((0.0..=1.0).contains(&v), "{k} {v}");
            assert!(constant[k].is_null());
        }
    }
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("AUSE confidence / sensitivity / none"));
}
