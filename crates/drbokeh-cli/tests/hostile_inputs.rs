//! Issue 14, case by case: hostile inputs (huge headers, zip bombs, scene limits, large
//! valid images, overflowing gradients, our own outputs as inputs, usage nits), as a user
//! would try them. Each test generates its case and asserts the exit code, the message
//! (naming the file and the problem) and what is left in the directory afterwards.
//! Outputs (clobbering, all-or-nothing, leftovers) are in `hostile_outputs.rs`.

mod common;
mod hostile;

use common::{p, stderr, write_stack};
use hostile::*;
use std::io::Write;
use std::time::{Duration, Instant};

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
        let o = run(&["trace", p(&path), "--output", p(&d.path("out")), "-q"]);
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

/// Writes a 16-bit PNG of zeros (`rgba`: 4 channels, else RGB), streamed row by row.
fn write_zero_png16(path: &std::path::Path, (w, h): (u32, u32), rgba: bool) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut enc = png::Encoder::new(file, w, h);
    enc.set_color(if rgba {
        png::ColorType::Rgba
    } else {
        png::ColorType::Rgb
    });
    enc.set_depth(png::BitDepth::Sixteen);
    enc.set_compression(png::Compression::Fast);
    let mut writer = enc.write_header().unwrap().into_stream_writer().unwrap();
    let row = vec![0u8; w as usize * if rgba { 8 } else { 6 }];
    for _ in 0..h {
        writer.write_all(&row).unwrap();
    }
    writer.finish().unwrap();
}

#[test]
fn case3_issue_png_12000x8000_rgb16_decodes() {
    // The issue's file: 12000 x 8000 RGB, 16 bits: 576 MB decoded (over the image crate's
    // default 512 MiB), 96 megapixels (under the default budget as one layer). It must be
    // decoded, and the command then fail on what is really wrong (the map's size), within
    // the 2 GiB address-space cap: the 576 MB decode plus the 1152 MB float image.
    let d = Dir::new();
    let big = d.path("big.png");
    write_zero_png16(&big, (12000, 8000), false);
    let small = d.path("small.npy");
    write_disparity(&small, 4, 4);
    let o = run(&[
        "render",
        "--image",
        p(&big),
        "--disparity",
        p(&small),
        "--single-layer",
        "-o",
        p(&d.path("o.png")),
    ]);
    expect(
        &o,
        1,
        &["small.npy", "size 4x4 does not match", "(12000x8000)"],
    );
    assert!(!stderr(&o).contains("Memory limit"), "{}", stderr(&o));
    assert_eq!(d.names(), ["big.png", "small.npy"]);
}

#[test]
fn case3_large_valid_png_decodes() {
    // 8192 x 8200 RGBA, 16 bits: 537.5 MB decoded, just over the image crate's default
    // limit of 512 MiB, well under the budget (67 megapixel-layers of 128).
    let d = Dir::new();
    let big = d.path("big.png");
    write_zero_png16(&big, (8192, 8200), true);
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
    // A negative coordinate is the value of --focus-at, not an unknown option.
    let o = with(&["--focus-at", "-1,2", "-o", p(&out)]);
    expect(&o, 2, &["invalid parameter --focus-at", "'-1,2'"]);
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
    let o = run(&[
        "dfd-eval",
        "--synthetic",
        "--methods",
        "foo",
        "--output",
        p(&d.path("r")),
    ]);
    expect(&o, 2, &["--methods", "unknown layer 'foo'"]);
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
    let o = run(&["trace", p(&scene), "--output", p(&d.path("t")), "-q"]);
    expect(&o, 1, &["tex.png", "gain", "overflow"]);
    assert!(!out.exists() && !d.path("t").exists());
}
