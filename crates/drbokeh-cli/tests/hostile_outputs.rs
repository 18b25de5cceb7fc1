//! Issue 14, case by case: hostile outputs (an output naming an input, outputs checked
//! before the work and written all or nothing, interrupted and failed runs leaving
//! nothing behind). Each test asserts the exit code, the message and what is left in
//! the directory afterwards. Inputs are in `hostile_inputs.rs`.

mod common;
mod hostile;

use common::{p, stderr, write_stack};
use hostile::*;
use std::io::Write;
use std::path::PathBuf;
use std::process::Stdio;
use std::time::{Duration, Instant};

// ---- 4. An output path equal to an input path. ----

#[test]
fn case4_outputs_never_clobber_inputs() {
    let d = Dir::new();
    let img = d.path("img.png");
    write_png(&img, 12, 10);
    let disp = d.path("disp.npy");
    write_disparity(&disp, 12, 10);
    let aif = d.path("aif.png");
    write_png(&aif, 12, 10);
    let blurred = d.path("blurred.png");
    write_png(&blurred, 12, 10);
    std::os::unix::fs::symlink(&img, d.path("link.png")).unwrap();
    let snapshot = |paths: &[&PathBuf]| -> Vec<Vec<u8>> {
        paths.iter().map(|p| std::fs::read(p).unwrap()).collect()
    };
    let inputs = [&img, &disp, &aif, &blurred];
    let before = snapshot(&inputs);
    let img_dotted = format!("{}/./{}", d.0.path().display(), "img.png");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "render".into(),
                "--image".into(),
                p(&img).into(),
                "--disparity".into(),
                p(&disp).into(),
                "-o".into(),
                p(&img).into(),
            ],
            "--image",
        ),
        (
            vec![
                "render".into(),
                "--image".into(),
                p(&img).into(),
                "--disparity".into(),
                p(&disp).into(),
                "-o".into(),
                img_dotted.clone(),
            ],
            "--image",
        ),
        (
            vec![
                "render".into(),
                "--image".into(),
                p(&d.path("link.png")).into(),
                "--disparity".into(),
                p(&disp).into(),
                "-o".into(),
                p(&img).into(),
            ],
            "--image",
        ),
        (
            vec![
                "render".into(),
                "--image".into(),
                p(&img).into(),
                "--disparity".into(),
                p(&disp).into(),
                "-o".into(),
                p(&disp).into(),
            ],
            "--disparity",
        ),
        (
            vec![
                "dfd".into(),
                "--all-in-focus".into(),
                p(&aif).into(),
                "--defocused".into(),
                p(&blurred).into(),
                "--focus".into(),
                "0.5".into(),
                "--blur".into(),
                "5".into(),
                "-o".into(),
                p(&aif).into(),
            ],
            "--all-in-focus",
        ),
        (
            vec![
                "dfd".into(),
                "--all-in-focus".into(),
                p(&aif).into(),
                "--defocused".into(),
                p(&blurred).into(),
                "--focus".into(),
                "0.5".into(),
                "--blur".into(),
                "5".into(),
                "-o".into(),
                p(&d.path("d.png")).into(),
                "--log".into(),
                p(&d.path("d.png")).into(),
            ],
            "--output",
        ),
    ];
    for (args, option) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&args);
        let words: Vec<&str> = if args.contains(&"--log") {
            vec!["--log and --output name the same file"]
        } else {
            vec!["same file as the input", option]
        };
        expect(&o, 1, &words);
    }
    // layers -o = --disparity (an .npz map), and a preview name equal to --image.
    let disp_npz = d.path("map.npz");
    {
        let mut zip = zip::ZipWriter::new(std::fs::File::create(&disp_npz).unwrap());
        zip.start_file("data.npy", zip::write::SimpleFileOptions::default())
            .unwrap();
        let v: Vec<f32> = (0..120).map(|i| i as f32 / 120.0).collect();
        zip.write_all(&npy(&[10, 12], "<f4", &f32_bytes(&v)))
            .unwrap();
        zip.finish().unwrap();
    }
    let map_before = std::fs::read(&disp_npz).unwrap();
    expect(
        &run(&[
            "layers",
            "--image",
            p(&img),
            "--disparity",
            p(&disp_npz),
            "-o",
            p(&disp_npz),
        ]),
        1,
        &["same file as the input", "--disparity"],
    );
    let stack_named_like_image = d.path("img.npz"); // previews: img.layer0.png, ...
    std::fs::copy(&img, d.path("img.layer0.png")).unwrap();
    let preview_before = std::fs::read(d.path("img.layer0.png")).unwrap();
    expect(
        &run(&[
            "layers",
            "--image",
            p(&d.path("img.layer0.png")),
            "--disparity",
            p(&disp),
            "-o",
            p(&stack_named_like_image),
        ]),
        1,
        &["same file as the input", "--image"],
    );
    assert_eq!(
        std::fs::read(d.path("img.layer0.png")).unwrap(),
        preview_before
    );
    assert_eq!(std::fs::read(&disp_npz).unwrap(), map_before);
    assert_eq!(snapshot(&inputs), before, "an input was modified");
    assert!(!d.path("d.png").exists() && !d.path("img.npz").exists());
    assert!(
        d.names().iter().all(|n| !n.starts_with(".drbokeh")),
        "{:?}",
        d.names()
    );
}

// ---- 5 and 6. Outputs checked before the work; all or nothing. ----

#[test]
fn case5_6_output_problems_are_found_before_any_work() {
    let d = Dir::new();
    let aif = d.path("aif.png");
    write_png(&aif, 64, 64);
    let blurred = d.path("blurred.png");
    write_png(&blurred, 64, 64);
    let stack = d.path("s.npz");
    write_stack(&stack, 8, 6);
    let g = d.path("g.npy");
    std::fs::write(&g, npy(&[6, 8, 3], "<f4", &f32_bytes(&[0.1; 144]))).unwrap();
    let disp = d.path("disp.npy");
    write_disparity(&disp, 64, 64);
    let nodir = d.path("nodir");
    let dfd = |extra: &[&str]| {
        let mut args = vec![
            "dfd",
            "--all-in-focus",
            p(&aif),
            "--defocused",
            p(&blurred),
            "--focus",
            "0.5",
            "--blur",
            "5",
            "--iterations",
            "100000",
            "-o",
        ];
        args.extend_from_slice(extra);
        run_within(&args, Duration::from_secs(60))
    };
    let quick = |args: &[&str]| run_within(args, Duration::from_secs(60));
    for (o, words) in [
        // A render that would take minutes.
        (
            quick(&[
                "render",
                "--demo",
                "--demo-size",
                "2000x1500",
                "--blur",
                "200",
                "-o",
                p(&nodir.join("out.png")),
            ]),
            vec!["nodir", "does not exist"],
        ),
        (
            quick(&[
                "vjp",
                "--layers",
                p(&stack),
                "--focus",
                "0.5",
                "--grad-output",
                p(&g),
                "-o",
                p(&nodir.join("g.npz")),
            ]),
            vec!["nodir", "does not exist"],
        ),
        (
            quick(&[
                "layers",
                "--image",
                p(&aif),
                "--disparity",
                p(&disp),
                "-o",
                p(&nodir.join("s.npz")),
            ]),
            vec!["nodir", "does not exist"],
        ),
        (
            dfd(&[p(&nodir.join("d.png"))]),
            vec!["nodir", "does not exist"],
        ),
        // Case 5: the log or the preview would fail after the disparity was written.
        (
            dfd(&[p(&d.path("d.png")), "--log", p(&nodir.join("d.log.json"))]),
            vec!["d.log.json", "does not exist"],
        ),
        (
            dfd(&[p(&d.path("d.png")), "--preview", p(d.0.path())]),
            vec!["--preview names a directory"],
        ),
        (
            dfd(&[p(&d.path("d.png")), "--preview", p(&d.path("p.gif"))]),
            vec!["p.gif", "unsupported output extension"],
        ),
        (
            quick(&["render", "--demo", "-o", p(&d.path("out.bmp"))]),
            vec!["out.bmp", "unsupported output extension"],
        ),
    ] {
        expect(&o, 1, &words);
    }
    let mut left = d.names();
    left.retain(|n| {
        !["aif.png", "blurred.png", "s.npz", "g.npy", "disp.npy"].contains(&n.as_str())
    });
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn case5_dfd_writes_all_its_outputs_or_none() {
    let d = Dir::new();
    let aif = d.path("aif.png");
    write_png(&aif, 24, 20);
    let blurred = d.path("blurred.png");
    write_png(&blurred, 24, 20);
    let out = d.path("d.png");
    let o = run(&[
        "dfd",
        "--all-in-focus",
        p(&aif),
        "--defocused",
        p(&blurred),
        "--focus",
        "0.5",
        "--blur",
        "2",
        "--iterations",
        "2",
        "--coarse-scales",
        "0",
        "-q",
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        d.names(),
        [
            "aif.png",
            "blurred.png",
            "d.confidence.png",
            "d.log.json",
            "d.png",
            "d.preview.png"
        ]
    );
}

// ---- 7. Interrupted and failed runs leave nothing behind. ----

#[test]
fn case7_sigint_removes_temporaries_and_stale_ones_are_swept() {
    let d = Dir::new();
    let bench = d.path("bench");
    make_benchmark(&bench, 3, 128);
    // A scene still to make (as after an interrupted run), then what killed runs leave: a
    // scene directory of a dead process, and an old-style temporary from before the naming
    // (aged past the hour).
    std::fs::remove_dir_all(bench.join("scene_002")).unwrap();
    let dead_pid = u32::MAX - 11;
    let stale = bench.join(drbokeh::io::temps::name_for(dead_pid, 0, true));
    std::fs::create_dir_all(stale.join("inner")).unwrap();
    let legacy = bench.join(".drbokeh-scene-abc123");
    std::fs::create_dir(&legacy).unwrap();
    let old = std::time::SystemTime::now() - Duration::from_secs(7200);
    std::fs::File::open(&legacy)
        .unwrap()
        .set_modified(old)
        .unwrap();
    make_benchmark(&bench, 3, 128); // resumes: one new scene, and sweeps
    assert!(!stale.exists() && !legacy.exists(), "{:?}", names(&bench));
    assert!(bench.join("scene_002/scene.json").is_file());
    assert!(
        names(&bench).iter().all(|n| !n.starts_with('.')),
        "{:?}",
        names(&bench)
    );

    // SIGINT while eval is writing its report tree: the temporaries go, exit 130.
    let report = d.path("report");
    let mut child = command(&[
        "eval",
        "--benchmark",
        p(&bench),
        "--output",
        p(&report),
        "-q",
    ])
    .stderr(Stdio::piped())
    .spawn()
    .unwrap();
    let t = Instant::now();
    let temp_seen = loop {
        if names(d.0.path()).iter().any(|n| n.starts_with(".drbokeh-")) {
            break true;
        }
        if t.elapsed() > Duration::from_secs(60) || child.try_wait().unwrap().is_some() {
            break false;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    assert!(temp_seen, "eval finished before it could be interrupted");
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(stderr(&o).contains("interrupted"));
    assert_eq!(names(d.0.path()), ["bench"]);
}

#[test]
fn case7_failures_leave_nothing_behind() {
    let d = Dir::new();
    // trace --force onto a regular file: refused before tracing, nothing created.
    let scene = d.path("scene.json");
    std::fs::write(&scene, scene_json(2, 16, false)).unwrap();
    let file = d.path("f.txt");
    std::fs::write(&file, b"keep").unwrap();
    let o = run(&["trace", p(&scene), "--output", p(&file), "--force", "-q"]);
    expect(&o, 1, &["f.txt", "exists and is not a directory"]);
    assert_eq!(std::fs::read(&file).unwrap(), b"keep");
    // trace --force onto the directory holding the scene file: refused.
    let o = run(&[
        "trace",
        p(&scene),
        "--output",
        p(d.0.path()),
        "--force",
        "-q",
    ]);
    expect(&o, 1, &["would replace the input", "scene.json"]);
    assert_eq!(d.names(), ["f.txt", "scene.json"]);

    // eval with one corrupt scene: no partial report.
    let bench = d.path("bench");
    make_benchmark(&bench, 2, 24);
    std::fs::write(bench.join("scene_001/layers.npz"), b"not a zip").unwrap();
    let report = d.path("report");
    let o = run(&[
        "eval",
        "--benchmark",
        p(&bench),
        "--output",
        p(&report),
        "-q",
    ]);
    expect(&o, 1, &["scene_001", "layers.npz"]);
    assert!(!report.exists());
    std::fs::create_dir(&report).unwrap();
    std::fs::write(report.join("mine.txt"), b"m").unwrap();
    let o = run(&[
        "eval",
        "--benchmark",
        p(&bench),
        "--output",
        p(&report),
        "-q",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(names(&report), ["mine.txt"]);

    // gallery with a corrupt input: no empty directory.
    let photos = d.path("photos");
    std::fs::create_dir(&photos).unwrap();
    write_png(&photos.join("a.png"), 16, 12);
    std::fs::write(photos.join("a.disp.npy"), b"\x93NUMPY garbage").unwrap();
    let gallery = d.path("gallery");
    let o = run(&[
        "gallery",
        "--images",
        p(&photos),
        "--output",
        p(&gallery),
        "-q",
    ]);
    expect(&o, 1, &["a.disp.npy"]);
    assert!(!gallery.exists());
    assert_eq!(
        d.names(),
        ["bench", "f.txt", "photos", "report", "scene.json"]
    );
}

/// Spawns `render` of a 6-MP demo as a 16-bit PNG (light blur, so that encoding is a good
/// part of the run) into `dir`.
fn spawn_render(dir: &std::path::Path, out: &str) -> std::process::Child {
    command(&[
        "render",
        "--demo",
        "--demo-size",
        "3000x2000",
        "--blur",
        "2",
        "--window",
        "5",
        "--bit-depth",
        "16",
        "-o",
        p(&dir.join(out)),
        "-q",
    ])
    .stderr(Stdio::piped())
    .spawn()
    .unwrap()
}

/// Waits until `dir` holds a `.drbokeh-*` temporary (the render is encoding its output);
/// false if the child ended first or a minute passed.
fn wait_for_temporary(dir: &std::path::Path, child: &mut std::process::Child) -> bool {
    let t = Instant::now();
    loop {
        if names(dir).iter().any(|n| n.starts_with(".drbokeh-")) {
            return true;
        }
        if t.elapsed() > Duration::from_secs(60) || child.try_wait().unwrap().is_some() {
            return false;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// CPU time the process has used so far, from /proc (utime + stime, in clock ticks).
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = after.split_whitespace().collect();
    let field = |i: usize| f.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    field(11) + field(12)
}

#[test]
fn case7_render_interrupted_leaves_nothing() {
    // SIGTERM while rendering (before any output is staged): exit 143, nothing written.
    let d = Dir::new();
    let mut child = spawn_render(d.0.path(), "out.png");
    let t = Instant::now();
    while cpu_ticks(child.id()) < 20 && t.elapsed() < Duration::from_secs(60) {
        assert!(child.try_wait().unwrap().is_none(), "render ended early");
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(child.try_wait().unwrap().is_none(), "render ended early");
    unsafe {
        libc::kill(child.id() as i32, libc::SIGTERM);
    }
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(143), "{}", stderr(&o));
    assert!(stderr(&o).contains("interrupted"), "{}", stderr(&o));
    assert!(d.names().is_empty(), "{:?}", d.names());

    // SIGINT while the output is being encoded into its temporary: exit 130, the temporary
    // removed, no output.
    let mut child = spawn_render(d.0.path(), "out.png");
    assert!(
        wait_for_temporary(d.0.path(), &mut child),
        "render finished before it could be interrupted"
    );
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(d.names().is_empty(), "{:?}", d.names());
}

#[test]
fn case7_render_killed_leaves_a_temporary_the_next_render_sweeps() {
    // SIGKILL cannot be caught: the temporary stays, and the next render writing to the
    // same directory removes it (its process is gone).
    let d = Dir::new();
    let mut child = spawn_render(d.0.path(), "out.png");
    assert!(
        wait_for_temporary(d.0.path(), &mut child),
        "render finished before it could be killed"
    );
    child.kill().unwrap();
    child.wait().unwrap();
    let left = d.names();
    assert!(
        left.len() == 1 && left[0].starts_with(".drbokeh-") && left[0].ends_with(".part"),
        "{left:?}"
    );
    let o = run(&[
        "render",
        "--demo",
        "--demo-size",
        "64x48",
        "-o",
        p(&d.path("again.png")),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(d.names(), ["again.png"]);
}
