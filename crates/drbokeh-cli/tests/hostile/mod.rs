//! Helpers of the hostile-input and hostile-output tests: the binary under test (or
//! `DRBOKEH_TEST_BIN`), runs under an address-space cap and a time limit, message checks,
//! and writers of small (and hostile) NPY/NPZ/PNG files.
#![allow(dead_code)]

use crate::common::{p, stderr};
use std::io::Write;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The binary under test: this build's, or `DRBOKEH_TEST_BIN` (to run the cases against
/// another build, e.g. the one before the fixes).
pub fn bin() -> String {
    std::env::var("DRBOKEH_TEST_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_drbokeh").into())
}

/// Address-space cap for the child processes below: far above what any of these
/// inputs needs when handled correctly, far below what their headers claim.
pub const ADDRESS_SPACE_CAP: u64 = 2 << 30;

/// Runs `drbokeh` with an address-space limit (so a runaway allocation fails instead of
/// swapping the machine) and one malloc arena.
pub fn run(args: &[&str]) -> Output {
    command(args).output().expect("run drbokeh")
}

/// As [`run`], killing the command if it runs longer than `limit` (a check that should
/// come before the work must not wait for the work).
pub fn run_within(args: &[&str], limit: Duration) -> Output {
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

pub fn command(args: &[&str]) -> Command {
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
pub fn expect(o: &Output, code: i32, words: &[&str]) {
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

pub struct Dir(pub tempfile::TempDir);

impl Dir {
    pub fn new() -> Self {
        Dir(tempfile::tempdir().unwrap())
    }
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }
    /// The names in the directory, sorted.
    pub fn names(&self) -> Vec<String> {
        names(self.0.path())
    }
}

pub fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// NPY bytes: a version-1 header for `shape` and `descr`, then `data`.
pub fn npy(shape: &[u64], descr: &str, data: &[u8]) -> Vec<u8> {
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

pub fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A `w x h` disparity map (float32 NPY), a ramp.
pub fn write_disparity(path: &Path, w: usize, h: usize) {
    let v: Vec<f32> = (0..w * h).map(|i| (i % w) as f32 / w as f32).collect();
    std::fs::write(path, npy(&[h as u64, w as u64], "<f4", &f32_bytes(&v))).unwrap();
}

/// A `w x h` RGB PNG (8-bit), a gradient.
pub fn write_png(path: &Path, w: u32, h: u32) {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7) as u8, (y * 5) as u8, 90]));
    img.save(path).unwrap();
}

/// An NPZ whose arrays are streamed (deflated) without holding them: `arrays` of
/// (key, shape, value byte) in float32.
pub fn write_npz_zeros(path: &Path, arrays: &[(&str, Vec<u64>)]) {
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

pub fn scene_json(billboards: usize, size: usize, same_depth: bool) -> String {
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

/// Makes a small ray-traced benchmark of `scenes` scenes.
pub fn make_benchmark(dir: &Path, scenes: usize, size: usize) {
    let o = run(&[
        "benchmark",
        "make",
        "--scenes",
        &scenes.to_string(),
        "--size",
        &size.to_string(),
        "--spp",
        "1",
        "--output",
        p(dir),
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}
