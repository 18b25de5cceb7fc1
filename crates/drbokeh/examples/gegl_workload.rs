//! The GEGL-equivalent workload of issue 18 ([`drbokeh::bench::gegl_scene`]) as files, for
//! comparing `drbokeh render` with GEGL's `gegl:lens-blur` on the same input, whole process:
//! writes `image.png` (8-bit RGB), `disparity.png` (16-bit grey, `r / 33`: render with
//! `--single-layer --no-normalize --focus 0 --blur 33`) and `mask.png` (the same values:
//! GEGL's `aux` radius map for `radius=33`).
//!
//! With `--render ENGINE [--preset NAME] [--repeat N]` it renders the workload in process
//! instead (for profiling).
//!
//! Run: `cargo run --release -p drbokeh --example gegl_workload -- DIR [SIZE]`

use drbokeh::bench::{gegl_scene, gegl_workload, GEGL_BLUR_K};
use drbokeh::{render_with_stats, Engine, Image, NoProgress, Preset};
use std::path::PathBuf;

fn main() -> drbokeh::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let positional: Vec<&String> = args
        .iter()
        .enumerate()
        .filter(|(i, a)| !a.starts_with("--") && (*i == 0 || !args[i - 1].starts_with("--")))
        .map(|(_, a)| a)
        .collect();
    let size: usize = positional
        .get(1)
        .map_or(1024, |s| s.parse().expect("SIZE is a number"));
    if let Some(engine) = flag("--render") {
        let engine: Engine = engine.parse()?;
        let preset: Preset = flag("--preset")
            .unwrap_or_else(|| "physical".into())
            .parse()?;
        let repeat: usize = flag("--repeat").map_or(1, |n| n.parse().expect("a number"));
        let (stack, settings) = gegl_workload(size, size, preset);
        for _ in 0..repeat {
            let t = std::time::Instant::now();
            let (_, stats) = render_with_stats(&stack, &settings, engine, &NoProgress)?;
            println!("{engine:?} {:.3} s {stats:?}", t.elapsed().as_secs_f64());
        }
        return Ok(());
    }
    let dir = PathBuf::from(positional.first().expect("usage: gegl_workload DIR [SIZE]"));
    let (rgb, radius) = gegl_scene(size, size);
    drbokeh::io::write_output(
        &dir.join("image.png"),
        &rgb,
        drbokeh::io::BitDepth::Eight,
        |v| v,
    )?;
    let map = Image::from_vec(
        size,
        size,
        1,
        radius.data.iter().map(|r| r / GEGL_BLUR_K as f32).collect(),
    )?;
    drbokeh::io::write_grey(&dir.join("disparity.png"), &map)?;
    drbokeh::io::write_grey(&dir.join("mask.png"), &map)?;
    println!(
        "wrote {}/{{image,disparity,mask}}.png ({size}x{size})",
        dir.display()
    );
    Ok(())
}
