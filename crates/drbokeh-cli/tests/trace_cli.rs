//! CLI tests of `drbokeh trace` and `drbokeh benchmark make`.

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

/// A tiny scene: 5 billboards, thick lens.
fn tiny_scene(lens: &str, extra_billboard: &str) -> String {
    format!(
        r#"{{
  "camera": {{ "lens": {lens}, "width_px": 24, "height_px": 20, "fov_deg": 10.0,
              "focus_distance_mm": 400.0 }},
  "render": {{ "spp": 16, "aif_spp": 4, "seed": 3 }},
  "billboards": [
    {extra_billboard}
    {{ "depth_mm": 150.0, "center": [0.3, 0.6], "size": [0.5, 0.6],
      "texture": {{ "type": "procedural", "kind": "strands", "seed": 3 }} }},
    {{ "depth_mm": 400.0, "size": [0.5, 0.5],
      "texture": {{ "type": "procedural", "kind": "fluff", "seed": 4 }} }},
    {{ "depth_mm": 900.0, "size": [0.6, 0.6],
      "texture": {{ "type": "solid", "color": [0.2, 0.5, 0.9], "alpha": 0.5 }} }},
    {{ "depth_mm": 5000.0, "size": [1.6, 1.6],
      "texture": {{ "type": "procedural", "kind": "background", "seed": 11 }} }}
  ]
}}"#
    )
}

const LENS: &str = r#"{ "model": "spherical", "curvature_radius_mm": 50.0, "rim_radius_mm": 10.0, "eta": 1.5, "aperture_radius_mm": 2.0 }"#;

const FILES: [&str; 10] = [
    "bokeh.png",
    "bokeh.exr",
    "aif.png",
    "aif.exr",
    "depth.npy",
    "disparity.npy",
    "disparity.png",
    "layers.npz",
    "scene.json",
    "bokeh.png",
];

#[test]
fn trace_writes_every_output_and_a_reusable_record() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.json");
    std::fs::write(&scene, tiny_scene(LENS, "")).unwrap();
    let out = dir.path().join("out");
    let o = drbokeh(&[
        "trace",
        scene.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in FILES {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    let stack = drbokeh::io::read_stack::<f32>(&out.join("layers.npz")).unwrap();
    assert_eq!(stack.layers.len(), 4);
    assert_eq!((stack.width, stack.height), (24, 20));
    // Front first: disparity decreases from 1 (nearest) to 0 (farthest).
    let d: Vec<f32> = stack.layers.iter().map(|l| l.disparity.data[0]).collect();
    assert_eq!(d[0], 1.0);
    assert_eq!(d[3], 0.0);
    assert!(d.windows(2).all(|w| w[0] > w[1]));
    let rec: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("scene.json")).unwrap()).unwrap();
    let derived = &rec["derived"];
    let k = derived["blur"].as_f64().unwrap();
    let focus = derived["focus"].as_f64().unwrap();
    assert!(k > 0.0);
    // Focus at 400 mm = the second billboard's disparity.
    assert!(
        (focus - d[1] as f64).abs() < 1e-6,
        "focus {focus} vs {}",
        d[1]
    );
    assert!(derived["display_encoding"]
        .as_str()
        .unwrap()
        .contains("sRGB"));
    // The record is itself a scene file: tracing it again gives the same bytes.
    let again = dir.path().join("again");
    let o = drbokeh(&[
        "trace",
        out.join("scene.json").to_str().unwrap(),
        "--output",
        again.to_str().unwrap(),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in ["bokeh.png", "bokeh.exr", "layers.npz", "depth.npy"] {
        assert_eq!(
            std::fs::read(out.join(f)).unwrap(),
            std::fs::read(again.join(f)).unwrap(),
            "{f}"
        );
    }
    // An existing output directory is refused without --force.
    let o = drbokeh(&[
        "trace",
        scene.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("already exists"));
}

fn assert_fails_cleanly(scene_text: &str, expect: &str) {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.json");
    std::fs::write(&scene, scene_text).unwrap();
    let out = dir.path().join("out");
    let o = drbokeh(&[
        "trace",
        scene.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert!(!o.status.success(), "should fail: {expect}");
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.contains(expect), "expected '{expect}' in: {err}");
    assert!(!out.exists(), "partial output left behind");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "stray files: {leftovers:?}");
}

#[test]
fn bad_input_fails_with_a_clear_message_and_no_output() {
    assert_fails_cleanly("{ \"camera\": ", "invalid scene JSON");
    let missing = r#"{ "depth_mm": 120.0, "size": [0.3, 0.3], "texture": { "type": "image", "path": "no_such_texture.png" } },"#;
    assert_fails_cleanly(&tiny_scene(LENS, missing), "no_such_texture.png");
    let wide = r#"{ "model": "spherical", "curvature_radius_mm": 10.0, "rim_radius_mm": 12.0, "eta": 1.5 }"#;
    assert_fails_cleanly(&tiny_scene(wide, ""), "rim radius");
    let near_sensor = tiny_scene(LENS, "").replace(
        "\"focus_distance_mm\": 400.0",
        "\"sensor_distance_mm\": 40.0",
    );
    assert_fails_cleanly(&near_sensor, "must exceed the focal length");
    let odd_spp = tiny_scene(LENS, "").replace("\"spp\": 16", "\"spp\": 15");
    assert_fails_cleanly(&odd_spp, "perfect square");
    let bad_detail = r#"{ "depth_mm": 120.0, "size": [0.3, 0.3], "texture": { "type": "procedural", "kind": "background", "seed": 1, "background_detail": 2.0 } },"#;
    assert_fails_cleanly(&tiny_scene(LENS, bad_detail), "background_detail");
}

fn tree_bytes(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn benchmark_is_identical_for_any_sharding_and_thread_count_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full");
    let sharded = dir.path().join("sharded");
    let common = [
        "--scenes", "3", "--seed", "7", "--size", "24", "--spp", "16", "-q",
    ];
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec!["benchmark", "make", "--output", out.to_str().unwrap()];
        args.extend_from_slice(&common);
        args.extend_from_slice(extra);
        let o = drbokeh(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    };
    run(&full, &["--threads", "1"]);
    run(&sharded, &["--shard", "1/2", "--threads", "2"]);
    assert!(sharded.join("scene_001").is_dir());
    assert!(
        !sharded.join("scene_000").exists(),
        "shard 1/2 must not make scene 0"
    );
    run(&sharded, &["--shard", "0/2"]);
    let a = tree_bytes(&full);
    assert_eq!(
        a.len(),
        1 + 3 * 9,
        "{:?}",
        a.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    assert!(
        a == tree_bytes(&sharded),
        "sharded benchmark differs from the full run"
    );
    let manifest: serde_json::Value =
        serde_json::from_str(&String::from_utf8_lossy(&a[0].1)).unwrap();
    assert_eq!(manifest["entries"].as_array().unwrap().len(), 3);
    assert_eq!(
        manifest["display_encoding"].as_str(),
        Some(drbokeh::trace::texture::DISPLAY_ENCODING)
    );
    // Re-running skips finished scenes (their files are not rewritten).
    let stamp = std::fs::metadata(full.join("scene_001/bokeh.png"))
        .unwrap()
        .modified()
        .unwrap();
    let mut args = vec!["benchmark", "make", "--output", full.to_str().unwrap()];
    args.extend_from_slice(&common[..common.len() - 1]);
    let o = drbokeh(&args);
    assert!(o.status.success());
    assert!(
        stderr(&o).contains("0 scenes made, 3 already present"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::metadata(full.join("scene_001/bokeh.png"))
            .unwrap()
            .modified()
            .unwrap(),
        stamp
    );
}

#[test]
fn benchmark_traces_only_the_scenes_that_pass_only_focus_and_min_blur() {
    let dir = tempfile::tempdir().unwrap();
    let (full, some) = (dir.path().join("full"), dir.path().join("some"));
    let make = |out: &Path, extra: &[&str]| {
        let mut args = vec!["benchmark", "make", "--output", out.to_str().unwrap()];
        args.extend_from_slice(&[
            "--scenes", "6", "--seed", "2", "--size", "24", "--spp", "16",
        ]);
        args.extend_from_slice(extra);
        drbokeh(&args)
    };
    assert!(make(&full, &["-q"]).status.success());
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(full.join("manifest.json")).unwrap()).unwrap();
    let entries = manifest["entries"].as_array().unwrap().clone();
    // The threshold halfway up the blurs of the far-focus scenes (focus 0) keeps some, not all.
    let far: Vec<&serde_json::Value> = entries
        .iter()
        .filter(|e| e["focus"].as_f64().unwrap().abs() <= 1e-6)
        .collect();
    assert!(far.len() >= 2, "seed 2 has {} far-focus scenes", far.len());
    let mut blurs: Vec<f64> = far.iter().map(|e| e["blur"].as_f64().unwrap()).collect();
    blurs.sort_by(f64::total_cmp);
    let min_blur = 0.5 * (blurs[0] + blurs[blurs.len() - 1]);
    let o = make(
        &some,
        &["--only-focus", "0", "--min-blur", &min_blur.to_string()],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let want: Vec<String> = far
        .iter()
        .filter(|e| e["blur"].as_f64().unwrap() >= min_blur)
        .map(|e| e["dir"].as_str().unwrap().to_string())
        .collect();
    assert!(!want.is_empty() && want.len() < entries.len());
    for e in &entries {
        let name = e["dir"].as_str().unwrap();
        let made = some.join(name);
        if want.iter().any(|w| w == name) {
            // The same bytes as in the full benchmark.
            for f in ["aif.png", "bokeh.png", "scene.json"] {
                assert_eq!(
                    std::fs::read(made.join(f)).unwrap(),
                    std::fs::read(full.join(name).join(f)).unwrap(),
                    "{name}/{f}"
                );
            }
        } else {
            assert!(!made.exists(), "{name} should not be traced");
        }
    }
    // The manifest still lists every scene.
    assert_eq!(
        std::fs::read(some.join("manifest.json")).unwrap(),
        std::fs::read(full.join("manifest.json")).unwrap()
    );
    for (arg, msg) in [
        (
            "--only-focus=1.5",
            "--only-focus: must be a disparity in [0, 1]",
        ),
        ("--min-blur=-1", "--min-blur: must be a blur in pixels"),
        ("--min-blur=NaN", "--min-blur: must be a blur in pixels"),
    ] {
        let o = make(&dir.path().join("bad"), &[arg]);
        assert!(!o.status.success());
        assert!(stderr(&o).contains(msg), "{}", stderr(&o));
        assert!(!dir.path().join("bad").exists(), "nothing written on {arg}");
    }
}

#[test]
fn benchmark_refuses_to_resume_a_benchmark_made_with_other_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let make = |extra: &[&str]| {
        let mut args = vec![
            "benchmark",
            "make",
            "--output",
            out.to_str().unwrap(),
            "--size",
            "24",
            "--spp",
            "16",
            "-q",
        ];
        args.extend_from_slice(extra);
        drbokeh(&args)
    };
    let o = make(&["--scenes", "3", "--seed", "7", "--shard", "0/2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let before = tree_bytes(&out);
    // Another --scenes moves every scene's blur target: the finished scenes are not this
    // run's, so it must refuse before rewriting the manifest or tracing anything.
    for (extra, flag) in [
        (
            &["--scenes", "4", "--seed", "7"][..],
            "--scenes 3 (this run: 4)",
        ),
        (&["--scenes", "3", "--seed", "8"], "--seed 7 (this run: 8)"),
        (
            &["--scenes", "3", "--seed", "7", "--perspective"],
            "--perspective false (this run: true)",
        ),
    ] {
        let o = make(extra);
        assert!(!o.status.success());
        let err = stderr(&o);
        assert!(err.contains(flag), "{err}");
        assert!(err.contains(out.to_str().unwrap()), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            tree_bytes(&out) == before,
            "a refused run changed {}",
            out.display()
        );
    }
    // Without a manifest the scenes themselves are compared.
    std::fs::remove_file(out.join("manifest.json")).unwrap();
    let o = make(&["--scenes", "3", "--seed", "8"]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("scene_000 holds a scene other than"), "{err}");
    assert!(!out.join("manifest.json").exists());
    assert!(!out.join("scene_001").exists());
    // The same parameters resume: the missing scene is made, the finished ones kept.
    let o = make(&["--scenes", "3", "--seed", "7"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("scene_001/scene.json").is_file());
    // A manifest from before --perspective (no such field) resumes as made without it.
    let path = out.join("manifest.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(manifest["perspective"], serde_json::Value::Bool(false));
    manifest.as_object_mut().unwrap().remove("perspective");
    std::fs::write(&path, manifest.to_string()).unwrap();
    let o = make(&["--scenes", "3", "--seed", "7"]);
    assert!(o.status.success(), "{}", stderr(&o));
}
