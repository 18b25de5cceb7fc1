//! Property test over hostile files: random bytes, and valid PNG/EXR/NPY/NPZ/JSON files
//! with bytes of their headers overwritten or their ends cut. Every run of the CLI on
//! them must end in success or a clean error (exit 0, 1 or 2, a message, no panic), never
//! an abort or a crash, and within a small input budget (`DRBOKEH_MAX_MEGAPIXELS=2`) under an
//! address-space limit of 1 GiB: a reader that allocated what a corrupt header claims
//! would be killed by the limit (abort, exit 134) and fail the test.

mod common;

use common::{p, write_stack};
use proptest::prelude::*;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The binary under test: this build's, or `DRBOKEH_TEST_BIN` (to run the cases against
/// another build, e.g. the one before the fixes).
fn bin() -> String {
    std::env::var("DRBOKEH_TEST_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_drbokeh").into())
}

const ADDRESS_SPACE_CAP: u64 = 1 << 30;
const TIME_LIMIT: Duration = Duration::from_secs(120);

/// Valid seed files of every format, made once per test process.
struct Seeds {
    _dir: tempfile::TempDir,
    png: PathBuf,
    exr: PathBuf,
    npy: PathBuf,
    npz: PathBuf,
    json: PathBuf,
}

fn seeds() -> &'static Seeds {
    static SEEDS: std::sync::OnceLock<Seeds> = std::sync::OnceLock::new();
    SEEDS.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("seed.png");
        image::RgbImage::from_fn(8, 6, |x, y| image::Rgb([(x * 30) as u8, (y * 40) as u8, 77]))
            .save(&png)
            .unwrap();
        let exr = dir.path().join("seed.exr");
        image::DynamicImage::ImageRgb32F(image::Rgb32FImage::from_fn(8, 6, |x, y| {
            image::Rgb([x as f32 / 8.0, y as f32 / 6.0, 0.5])
        }))
        .save(&exr)
        .unwrap();
        let npy = dir.path().join("seed.npy");
        let v: Vec<f32> = (0..48).map(|i| i as f32 / 48.0).collect();
        {
            use ndarray_npy::WriteNpyExt;
            ndarray::Array2::from_shape_vec((6, 8), v)
                .unwrap()
                .write_npy(std::fs::File::create(&npy).unwrap())
                .unwrap();
        }
        let npz = dir.path().join("seed.npz");
        write_stack(&npz, 8, 6);
        let json = dir.path().join("seed.json");
        std::fs::write(
            &json,
            r#"{"camera": {"lens": {"model": "thin", "focal_length_mm": 50.0, "aperture_radius_mm": 5.0},
 "width_px": 16, "height_px": 12, "fov_deg": 20.0, "focus_distance_mm": 1000.0},
 "render": {"spp": 1, "aif_spp": 1, "seed": 3},
 "billboards": [
  {"depth_mm": 600.0, "center": [0.4, 0.5], "size": [0.5, 0.5], "texture": {"type": "solid", "color": [0.9, 0.2, 0.1], "alpha": 0.7}},
  {"depth_mm": 3000.0, "size": [1.6, 1.6], "texture": {"type": "procedural", "kind": "background", "seed": 7}}]}"#,
        )
        .unwrap();
        Seeds {
            _dir: dir,
            png,
            exr,
            npy,
            npz,
            json,
        }
    })
}

#[derive(Clone, Copy, Debug)]
enum Format {
    Png,
    Exr,
    Npy,
    Npz,
    Json,
}

impl Format {
    fn seed(self) -> &'static Path {
        let s = seeds();
        match self {
            Format::Png => &s.png,
            Format::Exr => &s.exr,
            Format::Npy => &s.npy,
            Format::Npz => &s.npz,
            Format::Json => &s.json,
        }
    }

    fn ext(self) -> &'static str {
        match self {
            Format::Png => "png",
            Format::Exr => "exr",
            Format::Npy => "npy",
            Format::Npz => "npz",
            Format::Json => "json",
        }
    }
}

/// The harness itself: every unmodified seed file is read and the command succeeds under
/// the same limits (so the properties below exercise the readers, not a broken setup).
#[test]
fn seeds_succeed_under_the_same_limits() {
    for format in [
        Format::Png,
        Format::Exr,
        Format::Npy,
        Format::Npz,
        Format::Json,
    ] {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            run_on(format, format.seed(), dir.path()).0,
            Some(0),
            "{format:?}"
        );
    }
}

/// Runs the command that reads a file of `format` at `path`, under the address-space cap.
fn check_file(format: Format, path: &Path, dir: &Path) -> Result<(), TestCaseError> {
    let out = dir.join("out.png");
    let (code, err) = run_on(format, path, dir);
    prop_assert!(
        matches!(code, Some(0..=2)),
        "{format:?}: status {code:?} (signal or abort): {err}"
    );
    prop_assert!(!err.contains("panicked"), "{format:?}: {err}");
    if code != Some(0) {
        prop_assert!(
            err.starts_with("drbokeh: error: ") || err.starts_with("error: "),
            "{err}"
        );
        prop_assert!(!out.exists(), "{format:?}: output left after a failure");
    }
    let _ = std::fs::remove_file(&out);
    let _ = std::fs::remove_dir_all(dir.join("traced"));
    Ok(())
}

/// Runs the command reading `path` as `format`; its exit code (None: killed) and stderr.
fn run_on(format: Format, path: &Path, dir: &Path) -> (Option<i32>, String) {
    let s = seeds();
    let out = dir.join("out.png");
    let mut args: Vec<String> = match format {
        Format::Png | Format::Exr => vec![
            "render".into(),
            "--image".into(),
            p(path).into(),
            "--disparity".into(),
            p(&s.npy).into(),
            "--single-layer".into(),
        ],
        Format::Npy => vec![
            "render".into(),
            "--image".into(),
            p(&s.png).into(),
            "--disparity".into(),
            p(path).into(),
            "--single-layer".into(),
        ],
        Format::Npz => vec!["render".into(), "--layers".into(), p(path).into()],
        Format::Json => vec![
            "trace".into(),
            p(path).into(),
            "--spp".into(),
            "1".into(),
            "--output".into(),
            p(&dir.join("traced")).into(),
        ],
    };
    if !matches!(format, Format::Json) {
        args.extend(["--focus", "0.5", "--blur", "2", "-o", p(&out)].map(String::from));
    }
    args.extend(["--threads", "1", "-q"].map(String::from));
    let mut cmd = Command::new(bin());
    cmd.args(&args)
        .env("MALLOC_ARENA_MAX", "1")
        .env("DRBOKEH_MAX_MEGAPIXELS", "2")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    unsafe {
        cmd.pre_exec(|| {
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
    let mut child = cmd.spawn().unwrap();
    let t = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > TIME_LIMIT {
            let _ = child.kill();
            return (None, format!("{format:?}: ran over {TIME_LIMIT:?}"));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let o = child.wait_with_output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn formats() -> impl Strategy<Value = Format> {
    prop_oneof![
        Just(Format::Png),
        Just(Format::Exr),
        Just(Format::Npy),
        Just(Format::Npz),
        Just(Format::Json),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Random bytes under every extension.
    #[test]
    fn random_bytes_fail_cleanly(format in formats(), bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(format!("x.{}", format.ext()));
        std::fs::write(&path, &bytes).unwrap();
        check_file(format, &path, dir.path())?;
    }

    /// Valid files with header bytes overwritten (within the first 160 bytes, where the
    /// sizes, shapes and dtypes live; anywhere for JSON) and possibly cut short.
    #[test]
    fn mutated_headers_fail_cleanly(
        format in formats(),
        edits in prop::collection::vec((0usize..160, any::<u8>()), 1..6),
        cut in prop::option::of(0.0f64..1.0),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let mut bytes = std::fs::read(format.seed()).unwrap();
        let span = match format {
            Format::Json => bytes.len(),
            _ => bytes.len().min(160),
        };
        for (i, b) in &edits {
            let i = (i * span / 160).min(bytes.len() - 1);
            bytes[i] = *b;
        }
        if let Some(c) = cut {
            bytes.truncate((bytes.len() as f64 * c) as usize);
        }
        let path = dir.path().join(format!("x.{}", format.ext()));
        std::fs::write(&path, &bytes).unwrap();
        check_file(format, &path, dir.path())?;
    }

    /// NPY headers with arbitrary shapes and dtypes, the data absent or short.
    #[test]
    fn npy_headers_with_any_shape_fail_cleanly(
        dims in prop::collection::vec(prop_oneof![0u64..10, 1u64..100_000, Just(u64::MAX / 3)], 0..5),
        descr in prop_oneof![Just("<f4"), Just(">f8"), Just("|u1"), Just("<u2"), Just("<i8"), Just("<f2")],
        fortran in any::<bool>(),
        data_len in 0usize..400,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let shape = match dims.len() {
            0 => "()".to_string(),
            1 => format!("({},)", dims[0]),
            _ => format!("({})", dims.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
        };
        let fo = if fortran { "True" } else { "False" };
        let mut hdr = format!("{{'descr': '{descr}', 'fortran_order': {fo}, 'shape': {shape}, }}");
        while (10 + hdr.len() + 1) % 64 != 0 {
            hdr.push(' ');
        }
        hdr.push('\n');
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(hdr.len() as u16).to_le_bytes());
        bytes.extend_from_slice(hdr.as_bytes());
        bytes.extend(vec![0x3fu8; data_len]);
        let path = dir.path().join("x.npy");
        std::fs::write(&path, &bytes).unwrap();
        check_file(Format::Npy, &path, dir.path())?;
    }
}
