//! Issue 14, case by case: hostile inputs and outputs, as a user would try them. Each test
//! generates its case and asserts the exit code, the message (naming the file and the
//! problem) and what is left in the directory afterwards.

mod common;

use common::{p, stderr, write_stack};
use std::io::Write;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The binary under test: this build's, or `DRBOKEH_TEST_BIN` (to run the cases against
/// another build, e.g. the one before the fixes).
fn bin() -> String {
    std::env::var("DRBOKEH_TEST_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_drbokeh").into())
}

/// Address-space cap for the child processes below: far above what any of these
/// inputs needs when handled correctly, far below what their headers claim.
const ADDRESS_SPACE_CAP: u64 = 2 << 30;

/// Runs `drbokeh` with an address-space limit (so a runaway allocation fails instead of
/// swapping the machine) and one malloc arena.
fn run(args: &[&str]) -> Output {
    command(args).output().expect("run drbokeh")
}

/// As [`run`], killing the command if it runs longer than `limit` (a check that should
/// come before the work must not wait for the work).
fn run_within(args: &[&str], limit: Duration) -> Output {
    let mut child = command(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > limit {
            child.kill().unwrap();
            panic!("{args:?} still running after {limit:?}: the check came after the work");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().unwrap()
}

fn command(args: &[&str]) -> Command {
    let mut c = Command::new(bin());
    c.args(args).env("MALLOC_ARENA_MAX", "1");
    unsafe {
        c.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: ADDRESS_SPACE_CAP as libc::rlim_t,
                rlim_max: ADDRESS_SPACE_CAP as libc::rlim_t,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    c
}

/// Asserts exit code `code` and that stderr holds every one of `words`.
fn expect(o: &Output, code: i32, words: &[&str]) {
    let err = stderr(o);
    assert_eq!(
        o.status.code(),
        Some(code),
        "exit status {:?}: {err}",
        o.status
    );
    for w in words {
        assert!(err.contains(w), "stderr lacks '{w}': {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "not a one-line message: {err}"
    );
}

struct Dir(tempfile::TempDir);

impl Dir {
    fn new() -> Self {
        Dir(tempfile::tempdir().unwrap())
    }
    fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }
    /// The names in the directory, sorted.
    fn names(&self) -> Vec<String> {
        names(self.0.path())
    }
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// NPY bytes: a version-1 header for `shape` and `descr`, then `data`.
fn npy(shape: &[u64], descr: &str, data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = if shape.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut hdr = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {tuple}, }}");
    while (10 + hdr.len() + 1) % 64 != 0 {
        hdr.push(' ');
    }
    hdr.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(hdr.len() as u16).to_le_bytes());
    out.extend_from_slice(hdr.as_bytes());
    out.extend_from_slice(data);
    out
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A `w x h` disparity map (float32 NPY), a ramp.
fn write_disparity(path: &Path, w: usize, h: usize) {
    let v: Vec<f32> = (0..w * h).map(|i| (i % w) as f32 / w as f32).collect();
    std::fs::write(path, npy(&[h as u64, w as u64], "<f4", &f32_bytes(&v))).unwrap();
}

/// A `w x h` RGB PNG (8-bit), a gradient.
fn write_png(path: &Path, w: u32, h: u32) {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7) as u8, (y * 5) as u8, 90]));
    img.save(path).unwrap();
}

/// An NPZ whose arrays are streamed (deflated) without holding them: `arrays` of
/// (key, shape, value byte) in float32.
fn write_npz_zeros(path: &Path, arrays: &[(&str, Vec<u64>)]) {
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .large_file(true);
    for (key, shape) in arrays {
        zip.start_file(format!("{key}.npy"), opts).unwrap();
        zip.write_all(&npy(shape, "<f4", &[])).unwrap();
        let bytes = shape.iter().product::<u64>() * 4;
        let chunk = vec![0u8; 1 << 20];
        let mut left = bytes;
        while left > 0 {
            let n = left.min(chunk.len() as u64) as usize;
            zip.write_all(&chunk[..n]).unwrap();
            left -= n as u64;
        }
    }
    zip.finish().unwrap();
}

// ---- 1. Huge NPY/NPZ headers: a one-line error, no allocation of what they claim. ----

#[test]
fn case1_huge_npy_header_is_refused_from_the_header() {
    let d = Dir::new();
    let img = d.path("img.png");
    write_png(&img, 8, 6);
    let huge = d.path("huge.npy");
    // 100000 x 100000 float32 (40 GB) claimed, 4000 bytes present.
    std::fs::write(&huge, npy(&[100_000, 100_000], "<f4", &[0u8; 4000])).unwrap();
    let out = d.path("out.png");
    let budget = [
        "huge.npy",
        "too large for the input budget",
        "--max-megapixels",
    ];
    expect(
        &run(&[
            "render",
            "--image",
            p(&img),
            "--disparity",
            p(&huge),
            "-o",
            p(&out),
        ]),
        1,
        &budget,
    );
    expect(
        &run(&[
            "render",
            "--image",
            p(&img),
            "--depth",
            p(&huge),
            "-o",
            p(&out),
        ]),
        1,
        &budget,
    );
    expect(
        &run(&[
            "render",
            "--demo",
            "--demo-size",
            "8x6",
            "--aperture",
            &format!("kernel:{}", p(&huge)),
            "-o",
            p(&out),
        ]),
        1,
        &budget,
    );
    let stack = d.path("s.npz");
    write_stack(&stack, 8, 6);
    let huge_g = d.path("g.npy");
    std::fs::write(&huge_g, npy(&[100_000, 100_000, 3], "<f4", &[0u8; 64])).unwrap();
    expect(
        &run(&[
            "vjp",
            "--layers",
            p(&stack),
            "--focus",
            "0.5",
            "--grad-output",
            p(&huge_g),
            "-o",
            p(&d.path("g.npz")),
        ]),
        1,
        &["g.npy", "too large for the input budget"],
    );
    // An NPZ stack and an NPZ map whose headers claim huge shapes (stored, not deflated).
    let npz = d.path("huge.npz");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&npz).unwrap());
    let opts = zip::write::SimpleFileOptions::default();
    for (key, shape) in [
        ("rgb", vec![3u64, 50_000, 50_000, 3]),
        ("alpha", vec![3, 50_000, 50_000]),
        ("disparity", vec![3, 50_000, 50_000]),
        ("data", vec![100_000, 100_000]),
    ] {
        zip.start_file(format!("{key}.npy"), opts).unwrap();
        zip.write_all(&npy(&shape, "<f4", &[0u8; 16])).unwrap();
    }
    zip.finish().unwrap();
    expect(
        &run(&[
            "render",
            "--layers",
            p(&npz),
            "--focus",
            "0.5",
            "-o",
            p(&out),
        ]),
        1,
        &["huge.npz", "too large for the input budget"],
    );
    expect(
        &run(&[
            "render",
            "--image",
            p(&img),
            "--disparity",
            p(&npz),
            "-o",
            p(&out),
        ]),
        1,
        &["huge.npz", "key 'data'", "too large for the input budget"],
    );
    // A header within the budget but a truncated body: refused before reading.
    let short = d.path("short.npy");
    std::fs::write(&short, npy(&[6, 8], "<f4", &[0u8; 10])).unwrap();
    expect(
        &run(&[
            "render",
            "--image",
            p(&img),
            "--disparity",
            p(&short),
            "-o",
            p(&out),
        ]),
        1,
        &["short.npy", "truncated"],
    );
    assert!(!out.exists());
    assert!(
        d.names().iter().all(|n| !n.starts_with(".drbokeh")),
        "{:?}",
        d.names()
    );
}

// ---- 2. Small files demanding unbounded memory. ----

#[test]
fn case2_zip_bomb_stack_is_refused_from_its_headers() {
    // 64 layers of 500 x 500 zeros deflate to about 300 KB; with a budget of 8
    // megapixel-layers the stack (16) is refused from its headers, exactly as the issue's
    // 64 x 2000 x 2000 bomb (256) is against the default budget of 128.
    let d = Dir::new();
    let bomb = d.path("bomb.npz");
    let (n, h, w) = (64u64, 500u64, 500u64);
    write_npz_zeros(
        &bomb,
        &[
            ("rgb", vec![n, h, w, 3]),
            ("alpha", vec![n, h, w]),
            ("disparity", vec![n, h, w]),
        ],
    );
    assert!(std::fs::metadata(&bomb).unwrap().len() < 1 << 20);
    let out = d.path("out.png");
    let t = Instant::now();
    // The budget from the environment (DRBOKEH_MAX_MEGAPIXELS; --max-megapixels is tested
    // by the nits below).
    let o = command(&[
        "render",
        "--layers",
        p(&bomb),
        "--focus",
        "0.5",
        "-o",
        p(&out),
    ])
    .env("DRBOKEH_MAX_MEGAPIXELS", "8")
    .output()
    .unwrap();
    expect(
        &o,
        1,
        &[
            "bomb.npz",
            "500x500 x 64 layer(s)",
            "16.0 megapixel-layers",
            "budget 8",
        ],
    );
    assert!(
        t.elapsed() < Duration::from_secs(10),
        "refusal took {:?}",
        t.elapsed()
    );
    assert_eq!(d.names(), ["bomb.npz"]);
}

fn scene_json(billboards: usize, size: usize, same_depth: bool) -> String {
    let bb: Vec<String> = (0..billboards)
        .map(|i| {
            let depth = if same_depth {
                900.0
            } else {
                500.0 + 10.0 * i as f64
            };
            format!(
                r#"{{"depth_mm": {depth}, "center": [0.5, 0.5], "size": [40.0, 40.0],
                    "texture": {{"type": "procedural", "kind": "foliage", "seed": {i}}}}}"#
            )
        })
        .collect();
    format!(
        r#"{{"camera": {{"lens": {{"model": "thin", "focal_length_mm": 50.0, "aperture_radius_mm": 5.0}},
            "width_px": {size}, "height_px": {size}, "fov_deg": 20.0, "focus_distance_mm": 1000.0}},
            "render": {{"spp": 1, "aif_spp": 1}},
            "billboards": [{}]}}"#,
        bb.join(",")
    )
}

#[test]
fn case2_scene_limits_are_checked_before_generating_anything() {
    let d = Dir::new();
    let cases = [
        // 1000 billboards (the issue's 150 KB scene that exhausted 16 GB).
        (
            "many.json",
            scene_json(1000, 64, false),
            vec!["many.json", "1000 billboards", "at most 256"],
        ),
        // 200 billboards of 4096 x 4096 procedural textures (13 GB of texels).
        (
            "big.json",
            scene_json(200, 512, false),
            vec!["big.json", "too large for the input budget", "texels"],
        ),
        // Duplicate depths with large textures: refused before any texture exists.
        (
            "same.json",
            scene_json(20, 512, true),
            vec!["same.json", "share depth", "distinct"],
        ),
        // A 20000 x 20000 camera.
        (
            "wide.json",
            scene_json(2, 20_000, false),
            vec!["wide.json", "20000x20000", "too large"],
        ),
    ];
    for (name, text, words) in &cases {
        let path = d.path(name);
        std::fs::write(&path, text).unwrap();
        let t = Instant::now();
        let o = run(&["trace", p(&path), "--out", p(&d.path("out")), "-q"]);
        expect(&o, 1, words);
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "{name}: {:?}",
            t.elapsed()
        );
    }
    let o = run(&[
        "render",
        "--demo",
        "--demo-size",
        "20000x20000",
        "-o",
        p(&d.path("demo.png")),
    ]);
    expect(
        &o,
        1,
        &["--demo-size", "20000x20000 x 3 layer(s)", "too large"],
    );
    assert!(
        d.names().iter().all(|n| n.ends_with(".json")),
        "{:?}",
        d.names()
    );
}

// ---- 3. Valid images above the decoder's default 512 MiB limit. ----

#[test]
fn case3_large_valid_png_decodes() {
    // 8192 x 8200 RGBA, 16 bits: 537.5 MB decoded, just over the image crate's default
    // limit of 512 MiB, well under the budget (67 megapixel-layers of 128).
    let d = Dir::new();
    let big = d.path("big.png");
    {
        let (w, h) = (8192u32, 8200u32);
        let file = std::io::BufWriter::new(std::fs::File::create(&big).unwrap());
        let mut enc = png::Encoder::new(file, w, h);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Sixteen);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header().unwrap().into_stream_writer().unwrap();
        let row = vec![0u8; w as usize * 8];
        for _ in 0..h {
            writer.write_all(&row).unwrap();
        }
        writer.finish().unwrap();
    }
    let small = d.path("small.npy");
    write_disparity(&small, 4, 4);
    // Decoding succeeds; the map's size is then what is wrong.
    let o = command(&[
        "render",
        "--image",
        p(&big),
        "--disparity",
        p(&small),
        "--single-layer",
        "-o",
        p(&d.path("o.png")),
    ])
    .env("DRBOKEH_MAX_MEGAPIXELS", "100")
    .output()
    .unwrap();
    // The address-space cap is 2 GiB: the 537.5 MB decode plus the 806 MB float copy fit.
    expect(
        &o,
        1,
        &["small.npy", "size 4x4 does not match", "(8192x8200)"],
    );
    // As a matte: the alpha channel of the same file is read.
    let o = run(&[
        "layers",
        "--image",
        p(&big),
        "--disparity",
        p(&small),
        "--alpha",
        p(&big),
        "-o",
        p(&d.path("s.npz")),
        "--max-megapixels",
        "140",
    ]);
    expect(&o, 1, &["small.npy", "does not match"]);
}

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
fn case5_dfd_writes_all_three_outputs_or_none() {
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
        "--scales",
        "1",
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
            "d.log.json",
            "d.png",
            "d.preview.png"
        ]
    );
}

// ---- 7. Interrupted and failed runs leave nothing behind. ----

/// Makes a small ray-traced benchmark of `scenes` scenes.
fn make_benchmark(dir: &Path, scenes: usize, size: usize) {
    let o = run(&[
        "benchmark",
        "make",
        "--scenes",
        &scenes.to_string(),
        "--size",
        &size.to_string(),
        "--spp",
        "1",
        "--out",
        p(dir),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn case7_sigint_removes_temporaries_and_stale_ones_are_swept() {
    let d = Dir::new();
    let bench = d.path("bench");
    make_benchmark(&bench, 2, 128);
    // Plant what killed runs leave: a scene directory of a dead process, and an old-style
    // temporary from before the naming (aged past the hour).
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
    assert!(
        names(&bench).iter().all(|n| !n.starts_with('.')),
        "{:?}",
        names(&bench)
    );

    // SIGINT while eval is writing its report tree: the temporaries go, exit 130.
    let report = d.path("report");
    let mut child = command(&["eval", "--benchmark", p(&bench), "--out", p(&report), "-q"])
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
    let o = run(&["trace", p(&scene), "--out", p(&file), "--force", "-q"]);
    expect(&o, 1, &["f.txt", "exists and is not a directory"]);
    assert_eq!(std::fs::read(&file).unwrap(), b"keep");
    // trace --force onto the directory holding the scene file: refused.
    let o = run(&["trace", p(&scene), "--out", p(d.0.path()), "--force", "-q"]);
    expect(&o, 1, &["would replace the input", "scene.json"]);
    assert_eq!(d.names(), ["f.txt", "scene.json"]);

    // eval with one corrupt scene: no partial report.
    let bench = d.path("bench");
    make_benchmark(&bench, 2, 24);
    std::fs::write(bench.join("scene_001/layers.npz"), b"not a zip").unwrap();
    let report = d.path("report");
    let o = run(&["eval", "--benchmark", p(&bench), "--out", p(&report), "-q"]);
    expect(&o, 1, &["scene_001", "layers.npz"]);
    assert!(!report.exists());
    std::fs::create_dir(&report).unwrap();
    std::fs::write(report.join("mine.txt"), b"m").unwrap();
    let o = run(&["eval", "--benchmark", p(&bench), "--out", p(&report), "-q"]);
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
        "--out",
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

// ---- 8. vjp with a finite but huge upstream gradient. ----

#[test]
fn case8_vjp_overflow_is_an_error_not_nan_output() {
    let d = Dir::new();
    let stack = d.path("s.npz");
    write_stack(&stack, 8, 6);
    let g = d.path("g.npy");
    std::fs::write(&g, npy(&[6, 8, 3], "<f4", &f32_bytes(&[1e38; 144]))).unwrap();
    let out = d.path("grads.npz");
    for f64 in [false, true] {
        let mut args = vec![
            "vjp",
            "--layers",
            p(&stack),
            "--focus",
            "0.5",
            "--blur",
            "10",
            "--grad-output",
            p(&g),
            "-o",
            p(&out),
            "-q",
        ];
        if f64 {
            args.push("--f64");
        }
        let o = run(&args);
        if f64 {
            // 1e38 times gradients of order 1 stays finite in double precision.
            assert!(o.status.success(), "{}", stderr(&o));
            std::fs::remove_file(&out).unwrap();
        } else {
            expect(
                &o,
                1,
                &[
                    "grads.npz",
                    "overflowed",
                    "scale the upstream gradient down",
                ],
            );
        }
    }
    assert_eq!(d.names(), ["g.npy", "s.npz"]);
}

// ---- 9. Our own outputs are valid inputs. ----

#[test]
fn case9_benchmark_focus_is_a_valid_focus() {
    let d = Dir::new();
    let bench = d.path("bench");
    make_benchmark(&bench, 3, 16);
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(bench.join("manifest.json")).unwrap()).unwrap();
    for e in manifest["entries"].as_array().unwrap() {
        let focus = e["focus"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&focus), "manifest focus {focus}");
        let dir = bench.join(e["dir"].as_str().unwrap());
        let scene: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("scene.json")).unwrap()).unwrap();
        let f = scene["derived"]["focus"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&f), "scene.json focus {f}");
        let o = run(&[
            "render",
            "--layers",
            p(&dir.join("layers.npz")),
            "--focus",
            &f.to_string(),
            "--blur",
            "2",
            "-o",
            p(&d.path("r.png")),
            "-q",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    // The value the issue found in scene.json, as typed.
    let o = run(&[
        "render",
        "--demo",
        "--demo-size",
        "16x12",
        "--focus",
        "1.0000000000000002",
        "-o",
        p(&d.path("r.png")),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

// ---- Usability nits. ----

#[test]
fn nits_usage_errors_exit_2_with_the_option_named() {
    let d = Dir::new();
    let out = d.path("o.png");
    let demo = ["render", "--demo", "--demo-size", "16x12", "-q"];
    let with = |extra: &[&str]| {
        let mut a = demo.to_vec();
        a.extend_from_slice(extra);
        run(&a)
    };
    // Negative numbers are values.
    let o = with(&["--focus", "-1", "-o", p(&out)]);
    expect(&o, 2, &["--focus", "must be in [0, 1], got -1"]);
    let o = with(&["--offset", "-0.5", "-o", p(&out)]);
    expect(&o, 2, &["--offset", "must be in [0, 1]"]);
    // Bit depths: every bad value is a usage error; 16 bits with JPEG is refused.
    for bad in ["12", "32"] {
        let o = with(&["--bit-depth", bad, "-o", p(&out)]);
        assert_eq!(
            o.status.code(),
            Some(2),
            "--bit-depth {bad}: {}",
            stderr(&o)
        );
    }
    let o = with(&["--bit-depth", "16", "-o", p(&d.path("o.jpg"))]);
    expect(&o, 2, &["--bit-depth", "o.jpg", "JPEG"]);
    let o = run(&["render", "--demo", "--threads", "0", "-o", p(&out)]);
    expect(&o, 2, &["--threads"]);
    // The budget flag: a bad value is a usage error; a small budget refuses the demo.
    let o = with(&["--max-megapixels", "0", "-o", p(&out)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = run(&[
        "render",
        "--demo",
        "--demo-size",
        "200x100",
        "--max-megapixels",
        "0.05",
        "-o",
        p(&out),
    ]);
    expect(
        &o,
        1,
        &["--demo-size", "200x100 x 3 layer(s)", "budget 0.05"],
    );
    // dfd-eval names its own option.
    let o = run(&["dfd-eval", "--layers", "foo", "--out", p(&d.path("r"))]);
    expect(&o, 2, &["--layers", "unknown layer 'foo'"]);
    // bench --only with no match: refused at once.
    let t = Instant::now();
    let o = run(&["bench", "--only", "no-such-workload"]);
    expect(&o, 2, &["--only", "matches no workload"]);
    assert!(t.elapsed() < Duration::from_secs(10));
    assert!(d.names().is_empty(), "{:?}", d.names());
}

#[test]
fn nits_messages_name_the_file_and_the_real_culprit() {
    let d = Dir::new();
    let img = d.path("img.png");
    write_png(&img, 8, 6);
    let disp = d.path("disp.npy");
    write_disparity(&disp, 8, 6);
    let matte = d.path("matte.npy");
    std::fs::write(&matte, npy(&[6, 8], "<f4", &f32_bytes(&[1.5; 48]))).unwrap();
    let out = d.path("o.png");
    expect(
        &run(&[
            "render",
            "--image",
            p(&img),
            "--disparity",
            p(&disp),
            "--alpha",
            p(&matte),
            "-o",
            p(&out),
        ]),
        1,
        &["matte.npy", "alpha matte values must be in [0, 1]", "1.5"],
    );
    // The focus read at the centre pixel of an unnormalised map: not --focus's fault.
    let far = d.path("far.npy");
    std::fs::write(&far, npy(&[6, 8], "<f4", &f32_bytes(&[3.0; 48]))).unwrap();
    let o = run(&[
        "render",
        "--image",
        p(&img),
        "--disparity",
        p(&far),
        "--no-normalize",
        "--single-layer",
        "-o",
        p(&out),
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("centre pixel") && !err.contains("invalid parameter --focus"),
        "{err}"
    );
    // An empty kernel: names the option.
    let o = run(&[
        "render",
        "--demo",
        "--demo-size",
        "16x12",
        "--aperture",
        "kernel:",
        "-o",
        p(&out),
    ]);
    expect(&o, 2, &["--aperture", "kernel:IMAGE"]);
    // A texture gain that overflows float32: names the texture.
    let tex = d.path("tex.png");
    write_png(&tex, 4, 4);
    let scene = d.path("gain.json");
    std::fs::write(
        &scene,
        scene_json(1, 16, false).replace(
            r#""texture": {"type": "procedural", "kind": "foliage", "seed": 0}"#,
            r#""texture": {"type": "image", "path": "tex.png", "gain": 1e300}"#,
        ),
    )
    .unwrap();
    let o = run(&["trace", p(&scene), "--out", p(&d.path("t")), "-q"]);
    expect(&o, 1, &["tex.png", "gain", "overflow"]);
    assert!(!out.exists() && !d.path("t").exists());
}
