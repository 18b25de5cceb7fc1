//! The README's pictures and the sample photo cannot go stale: each committed picture is
//! compared with a fresh render by the command line that `scripts/make-pictures` states for
//! it (the script's `pic` lines are read here), and the sample photo with a fresh trace of
//! its scene. The README's photo example runs exactly as written.
//!
//! Pictures are JPEG (quality 92), so a fresh render is compared by PSNR, not by bytes
//! (bytes could differ in the last bit across CPUs): the JPEG round trip of these pictures
//! is 44.0 to 46.2 dB (measured), while a changed default falls well below the bound of 41
//! dB: the demo rendered with the paper preset instead of physical is 37.7 dB from
//! docs/demo.jpg (the test checks that this stays below the bound).

mod common;

use common::{drbokeh, p, stderr};
use std::path::{Path, PathBuf};

/// The PSNR (dB, 8-bit) a committed JPEG must keep against a fresh render.
const MIN_PSNR_DB: f64 = 41.0;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn rgb8(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

fn psnr(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let n = a.as_raw().len() as f64;
    let se: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum();
    if se == 0.0 {
        return f64::INFINITY;
    }
    10.0 * (255.0f64 * 255.0 * n / se).log10()
}

/// The `pic OUTPUT ARGS...` lines of scripts/make-pictures.
fn pictures() -> Vec<(String, Vec<String>)> {
    let script = std::fs::read_to_string(root().join("scripts/make-pictures")).unwrap();
    script
        .lines()
        .filter_map(|l| l.strip_prefix("pic "))
        .map(|l| {
            let mut words = l.split_whitespace().map(String::from);
            let out = words.next().unwrap();
            (out, words.collect())
        })
        .collect()
}

/// Runs `drbokeh ARGS... -q -o OUT` in the repository root.
fn render(args: &[String], out: &Path) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_drbokeh"))
        .current_dir(root())
        .args(args)
        .args(["-q", "-o", p(out)])
        .output()
        .unwrap();
    assert!(o.status.success(), "drbokeh {args:?}: {}", stderr(&o));
}

#[test]
fn committed_pictures_match_a_fresh_render_of_the_current_defaults() {
    let pics = pictures();
    assert!(pics.len() >= 5, "{pics:?}");
    let dir = tempfile::tempdir().unwrap();
    for (name, args) in &pics {
        let committed = root().join(name);
        let size = std::fs::metadata(&committed)
            .unwrap_or_else(|e| panic!("{name}: {e} (run scripts/make-pictures)"))
            .len();
        assert!(size < 300_000, "{name} is {size} bytes");
        let fresh = dir.path().join("fresh.png");
        render(args, &fresh);
        let db = psnr(&rgb8(&committed), &rgb8(&fresh));
        eprintln!("{name}: {db:.1} dB against a fresh render");
        assert!(
            db >= MIN_PSNR_DB,
            "{name} is stale: {db:.1} dB against `drbokeh {}` (run scripts/make-pictures)",
            args.join(" ")
        );
    }
    // The bound catches a changed default: the demo picture against the paper preset.
    let other = dir.path().join("paper.png");
    render(
        &["render", "--demo", "--preset", "paper"].map(String::from),
        &other,
    );
    let db = psnr(&rgb8(&root().join("docs/demo.jpg")), &rgb8(&other));
    eprintln!("docs/demo.jpg: {db:.1} dB against the paper preset");
    assert!(db < MIN_PSNR_DB - 2.0, "paper vs physical demo: {db:.1} dB");
}

#[test]
fn sample_photo_is_our_trace_of_its_scene() {
    let ex = root().join("examples");
    let photo = ex.join("photo.png");
    let disp = ex.join("photo.disp.png");
    let total = std::fs::metadata(&photo).unwrap().len() + std::fs::metadata(&disp).unwrap().len();
    assert!(total < 300_000, "sample photo + disparity: {total} bytes");
    let dir = tempfile::tempdir().unwrap();
    let trace = dir.path().join("trace");
    let o = drbokeh(&[
        "trace",
        p(&ex.join("photo-scene.json")),
        "-o",
        p(&trace),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // The disparity map is the trace's, byte for byte.
    assert_eq!(
        std::fs::read(&disp).unwrap(),
        std::fs::read(trace.join("disparity.png")).unwrap(),
        "examples/photo.disp.png is not the trace of examples/photo-scene.json"
    );
    // The photo is the trace's 16-bit all-in-focus image in 8 bits (scripts/make-pictures).
    let aif = rgb8(&trace.join("aif.png"));
    let committed = rgb8(&photo);
    let max_diff = aif
        .as_raw()
        .iter()
        .zip(committed.as_raw())
        .map(|(&a, &b)| (a as i32 - b as i32).abs())
        .max()
        .unwrap();
    assert!(
        max_diff <= 1,
        "examples/photo.png differs from the trace by {max_diff}/255"
    );
}

#[test]
fn readme_photo_example_runs_as_written() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let line =
        "drbokeh render --image examples/photo.png --disparity examples/photo.disp.png -o out.png";
    assert!(readme.contains(line), "README.md lacks `{line}`");
    let dir = tempfile::tempdir().unwrap();
    let args: Vec<&str> = line.split_whitespace().skip(1).collect();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_drbokeh"))
        .current_dir(dir.path())
        .args(args.iter().map(|a| {
            if a.starts_with("examples/") {
                root().join(a).into_os_string()
            } else {
                a.into()
            }
        }))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let out = rgb8(&dir.path().join("out.png"));
    let input = rgb8(&root().join("examples/photo.png"));
    assert_eq!(out.dimensions(), input.dimensions());
    // Focus falls on the centre pixel (the foliage): the centre stays sharp, the far city
    // (the top rows) is blurred.
    let (w, h) = input.dimensions();
    let region = |img: &image::RgbImage, x0: u32, y0: u32, x1: u32, y1: u32| {
        image::imageops::crop_imm(img, x0, y0, x1 - x0, y1 - y0).to_image()
    };
    let centre = psnr(
        &region(&out, w / 2 - 12, h / 2 - 12, w / 2 + 12, h / 2 + 12),
        &region(&input, w / 2 - 12, h / 2 - 12, w / 2 + 12, h / 2 + 12),
    );
    // The city's lit windows on the right (far behind the focus) are blurred away.
    let city = psnr(
        &region(&out, 340, 90, 420, 280),
        &region(&input, 340, 90, 420, 280),
    );
    eprintln!("centre {centre:.1} dB, city {city:.1} dB");
    assert!(
        centre > 30.0 && city < centre - 8.0,
        "centre {centre:.1} dB, city {city:.1} dB"
    );
    // The message names the layers and focus it used.
    assert!(stderr(&o).contains("rendered 480x320"), "{}", stderr(&o));
}

#[test]
fn demo_bokeh_balls_are_bright() {
    // The sky (the top fifth of the demo) is dark blue, about 26/255; its lights turn into
    // bokeh balls. Clipped at white (linear 1.0) they were dim grey discs: the 95th
    // percentile of the sky's brightness was 50/255 (54 with --highlight). As HDR lights
    // (6 to 30x white) it is about 163/255.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.png");
    render(&["render", "--demo"].map(String::from), &out);
    let img = rgb8(&out);
    let (w, h) = img.dimensions();
    let mut sky: Vec<f64> = (0..h / 5)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| img.get_pixel(x, y).0.iter().map(|&c| c as f64).sum::<f64>() / 3.0)
        .collect();
    sky.sort_by(f64::total_cmp);
    let median = sky[sky.len() / 2];
    let p95 = sky[sky.len() * 95 / 100];
    assert!(median < 40.0, "the sky is {median}/255");
    assert!(
        p95 >= 120.0,
        "the bokeh balls are dim: 95th percentile {p95}/255"
    );
}
