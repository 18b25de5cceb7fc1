//! Helpers shared by the CLI tests.
#![allow(dead_code)]

use ndarray::{Array3, Array4};
use ndarray_npy::NpzWriter;
use std::path::Path;
use std::process::{Command, Output};

/// Runs the `drbokeh` binary.
pub fn drbokeh(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drbokeh"))
        .args(args)
        .output()
        .expect("run drbokeh")
}

/// The command's stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path as &str.
pub fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A small two-layer stack written as NPZ (float32).
pub fn write_stack(path: &Path, w: usize, h: usize) -> drbokeh::LayerStack<f64> {
    let mut rgb = Array4::<f32>::zeros((2, h, w, 3));
    let mut alpha = Array3::<f32>::zeros((2, h, w));
    let mut disp = Array3::<f32>::zeros((2, h, w));
    for y in 0..h {
        for x in 0..w {
            let inside = (x as f32 - w as f32 / 2.0).abs() < w as f32 / 4.0;
            alpha[[0, y, x]] = if inside { 1.0 } else { 0.0 };
            alpha[[1, y, x]] = 1.0;
            disp[[0, y, x]] = 0.8;
            disp[[1, y, x]] = 0.1 + 0.01 * y as f32;
            for c in 0..3 {
                rgb[[0, y, x, c]] = [0.9, 0.3, 0.1][c];
                rgb[[1, y, x, c]] = ((x * 7 + y * 3 + c * 5) % 11) as f32 / 10.0;
            }
        }
    }
    let mut npz = NpzWriter::new(std::fs::File::create(path).unwrap());
    npz.add_array("rgb", &rgb).unwrap();
    npz.add_array("alpha", &alpha).unwrap();
    npz.add_array("disparity", &disp).unwrap();
    npz.finish().unwrap();
    drbokeh::io::read_stack(path).unwrap()
}
