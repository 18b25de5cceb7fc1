//! `drbokeh trace` (one user scene through a real lens) and `drbokeh benchmark make` (the
//! standard ray-traced benchmark).

use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use drbokeh::trace::{self, benchmark, SceneSpec};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Path-trace a billboard scene through a real (thick, spherical) lens: ground truth.
///
/// The lens is a thick spherical one (or an ideal thin lens). Writes into DIR: bokeh.png
/// (16-bit) and bokeh.exr (linear) — the ground-truth defocused image; aif.png/aif.exr —
/// the all-in-focus image through the chief ray; depth.npy (mm), disparity.npy and
/// disparity.png; layers.npz — the layered ground truth as a drbokeh layer stack (front
/// first); scene.json — every parameter, including the renderer's equivalent `blur` (K) and
/// `focus`. The directory appears only once complete.
///
/// Examples (the summary line names the renderer's equivalent --blur and --focus):
///   drbokeh trace examples/photo-scene.json -o photo-trace
///   drbokeh render --layers photo-trace/layers.npz --blur 18.38 --focus 0.351 \
///       -o r.png
///   drbokeh trace examples/scene.json --spp 64 -o scene-trace --force
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct TraceArgs {
    /// Scene file (JSON; see examples/scene.json and docs/ground-truth.md).
    #[arg(value_name = "SCENE.json")]
    pub scene: PathBuf,

    /// Output directory (must not exist, unless --force). --out is an alias.
    #[arg(long = "output", short = 'o', alias = "out", value_name = "DIR")]
    pub out: PathBuf,

    /// Samples per pixel (a perfect square); overrides the scene's render.spp.
    #[arg(long, value_name = "N")]
    pub spp: Option<usize>,

    /// Sampling seed; overrides the scene's render.seed.
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,

    /// Replace DIR if it exists (only after the new output is complete).
    #[arg(long)]
    pub force: bool,

    /// Number of worker threads (default: all cores). Output does not depend on it.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,

    /// No progress bar or summary on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Make the ray-traced ground-truth benchmark.
///
/// `drbokeh benchmark make --help` describes the scenes and options.
///
/// Examples:
///   drbokeh benchmark make --scenes 4 --size 128 --spp 64 -o bench
///   drbokeh benchmark make --scenes 100 --seed 1 --size 512 -o bench \
///       --shard 0/10
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct BenchmarkArgs {
    #[command(subcommand)]
    pub command: BenchmarkCommand,
}

/// Benchmark subcommands.
#[derive(Subcommand, Debug)]
pub enum BenchmarkCommand {
    // No doc comment: MakeArgs' doc comment is the help (see main.rs).
    Make(MakeArgs),
}

/// Generate the seeded benchmark scenes (resumable, shardable).
///
/// The standard benchmark: procedural five-billboard scenes traced through a
/// thick spherical lens, blur radii from 4 to 40 px (at 512 px), focus on near, middle
/// and far billboards.
///
/// Each scene goes to DIR/scene_NNN (the same files as `drbokeh trace`); DIR/manifest.json
/// lists every scene with its blur and focus. Scenes already present are skipped, so an
/// interrupted run can be resumed with the same parameters (a DIR made with others is
/// refused: every scene's blur depends on --scenes); --shard k/n makes only scenes with
/// index % n == k, so n machines can share the work (same seed, same bytes).
///
/// Examples:
///   drbokeh benchmark make --scenes 4 --size 128 --spp 64 -o bench
///   drbokeh benchmark make --scenes 100 --seed 1 --size 512 -o bench \
///       --shard 0/10
///   drbokeh benchmark make --scenes 24 --seed 202 --size 256 \
///       --highlight-range 5:50 -o bench-bright
///   drbokeh benchmark make --scenes 480 --size 128 --perspective -o bench-cue
///   drbokeh benchmark make --scenes 960 --size 128 --only-focus 0 \
///       --min-blur 3 -o bench-far
#[derive(Args, Debug)]
#[command(verbatim_doc_comment)]
pub struct MakeArgs {
    /// Number of scenes.
    #[arg(long, default_value_t = 100, value_name = "N")]
    pub scenes: usize,

    /// Master seed: scene content and sampling follow from it.
    #[arg(long, default_value_t = 0, value_name = "S")]
    pub seed: u64,

    /// Image width and height, pixels.
    #[arg(long, default_value_t = 512, value_name = "PX")]
    pub size: usize,

    /// Output directory (created if missing). --out is an alias.
    #[arg(long = "output", short = 'o', alias = "out", value_name = "DIR")]
    pub out: PathBuf,

    /// Samples per pixel of the defocused images (a perfect square).
    #[arg(long, default_value_t = trace::scene::STANDARD_SPP, value_name = "N")]
    pub spp: usize,

    /// Range of the highlights' linear intensities, LO:HI (e.g. 2:10, the default, or 5:50):
    /// the same scenes with brighter or dimmer highlights.
    #[arg(long, value_name = "LO:HI")]
    pub highlight_range: Option<String>,

    /// Fine detail on the background's surfaces, a strength in [0, 1] (default 0, none;
    /// e.g. 0.5): the same scenes with a textured sky and panels, so that every part of
    /// the background shows its blur (used for depth-from-defocus training data).
    #[arg(long, default_value_t = 0.0, value_name = "STRENGTH")]
    pub background_detail: f64,

    /// Lay the foregrounds out as a camera sees objects of about one size standing on a
    /// ground: the nearer, the larger and the lower in the frame (the same depths, focus
    /// and blur). Without it a billboard's size and place say nothing about its depth;
    /// with it the all-in-focus image carries a depth cue, as photos do (used for depth
    /// networks that see the all-in-focus image alone; docs/dfdnet.md).
    #[arg(long)]
    pub perspective: bool,

    /// Make only the scenes with index % n == k.
    #[arg(long, value_name = "k/n")]
    pub shard: Option<String>,

    /// Make only the scenes that focus at this normalised disparity (within 1e-6; 0 is the
    /// background, 1 the nearest billboard). The others stay in the manifest, untraced,
    /// as with --shard.
    #[arg(long, value_name = "DISPARITY")]
    pub only_focus: Option<f64>,

    /// Make only the scenes whose blur K (the manifest's `blur`, px per unit of disparity)
    /// is at least PX. The others stay in the manifest, untraced, as with --shard.
    #[arg(long, value_name = "PX")]
    pub min_blur: Option<f64>,

    /// Number of worker threads (default: all cores). Output does not depend on it.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,

    /// No progress bar or summary on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Traces one scene and writes its directory (replacing `out` only if `force`).
fn trace_into(
    spec: &SceneSpec,
    base_dir: &Path,
    out: &Path,
    force: bool,
    bar: &Bar,
) -> Result<trace::Scene> {
    let scene = spec.load(base_dir)?;
    let outputs = trace::trace_scene(&scene, &spec.render, bar)?;
    let mut record = spec.clone();
    trace::absolutize_paths(&mut record, base_dir);
    // Written into a temporary directory that replaces `out` (with force) once complete.
    let mut staging = drbokeh::io::Staging::new();
    trace::stage_scene_dir(&mut staging, out, force, &record, &scene, &outputs)?;
    staging.commit()?;
    Ok(scene)
}

/// `drbokeh trace`.
pub fn run_trace(a: &TraceArgs) -> Result<()> {
    crate::args::init_threads(a.threads)?;
    let mut spec = SceneSpec::read(&a.scene)?;
    if let Some(spp) = a.spp {
        spec.render.spp = spp;
    }
    if let Some(seed) = a.seed {
        spec.render.seed = seed;
    }
    spec.validate().map_err(|e| e.in_file(&a.scene))?;
    if a.out.is_dir() && !a.force {
        bail!(
            "{}: output directory already exists (use --force to replace it)",
            a.out.display()
        );
    }
    let base_dir = a.scene.parent().map(Path::to_path_buf).unwrap_or_default();
    let base_dir = if base_dir.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        base_dir
    };
    // Before any work: the output directory (never one holding an input), and the scene's
    // size against the input budget (texture sizes from their headers).
    let mut plan = drbokeh::io::OutputPlan::new();
    plan.input(&a.scene, "SCENE.json");
    for b in &spec.billboards {
        if let trace::scene::TextureSpec::Image { path, alpha, .. } = &b.texture {
            plan.input(base_dir.join(path), "a texture");
            if let Some(al) = alpha {
                plan.input(base_dir.join(al), "a texture matte");
            }
        }
    }
    let mode = if a.force {
        drbokeh::io::DirMode::Replace
    } else {
        drbokeh::io::DirMode::New
    };
    plan.dir(&a.out, "--output", mode).check()?;
    spec.check_budget(&base_dir)
        .map_err(|e| e.in_file(&a.scene))?;
    let start = Instant::now();
    let bar = Bar::new("tracing", a.quiet);
    let scene = trace_into(&spec, &base_dir, &a.out, a.force, &bar);
    bar.finish();
    let scene = scene?;
    if !a.quiet {
        eprintln!(
            "drbokeh: traced {}x{} at {} spp in {:.1} s -> {} (renderer equivalent: --blur {:.3} --focus {:.4})",
            scene.optics.width_px,
            scene.optics.height_px,
            spec.render.spp,
            start.elapsed().as_secs_f64(),
            a.out.display(),
            scene.blur_k_px(),
            scene.focus_disparity()
        );
    }
    Ok(())
}

fn parse_shard(s: &str) -> Result<(usize, usize)> {
    let bad =
        || anyhow::anyhow!("invalid parameter --shard: expected k/n with 0 <= k < n, got '{s}'");
    let (k, n) = s.split_once('/').ok_or_else(bad)?;
    let (k, n): (usize, usize) = (
        k.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || k >= n {
        return Err(bad());
    }
    Ok((k, n))
}

/// `drbokeh benchmark make`.
pub fn run_benchmark(a: &BenchmarkArgs) -> Result<()> {
    match &a.command {
        BenchmarkCommand::Make(m) => run_make(m),
    }
}

fn run_make(a: &MakeArgs) -> Result<()> {
    crate::args::init_threads(a.threads)?;
    let (k, n) = match &a.shard {
        Some(s) => parse_shard(s)?,
        None => (0, 1),
    };
    if let Some(f) = a.only_focus {
        if !(0.0..=1.0).contains(&f) {
            bail!("invalid parameter --only-focus: must be a disparity in [0, 1], got {f}");
        }
    }
    if let Some(b) = a.min_blur {
        if !(b.is_finite() && b >= 0.0) {
            bail!("invalid parameter --min-blur: must be a blur in pixels, >= 0, got {b}");
        }
    }
    if a.scenes == 0 || a.scenes > 100_000 {
        bail!(
            "invalid parameter --scenes: must be between 1 and 100000, got {}",
            a.scenes
        );
    }
    if !(8..=8192).contains(&a.size) {
        bail!(
            "invalid parameter --size: must be between 8 and 8192 pixels, got {}",
            a.size
        );
    }
    if trace::sampling::strata_side(a.spp).is_none() {
        bail!(
            "invalid parameter --spp: must be a perfect square (e.g. 256, 1024), got {}",
            a.spp
        );
    }
    let width = format!("{}", a.scenes - 1).len().max(3);
    let dir_name = |i: usize| format!("scene_{i:0width$}");
    let highlights = match &a.highlight_range {
        Some(s) => trace::procedural::HighlightRange::parse(s)?,
        None => Default::default(),
    };
    // Every spec first: a bad parameter fails before anything is written.
    let specs = (0..a.scenes)
        .map(|i| {
            let content = benchmark::Content {
                highlights,
                background_detail: a.background_detail,
                perspective: a.perspective,
            };
            benchmark::scene_spec_with_content(a.seed, i, a.scenes, a.size, a.spp, content)
        })
        .collect::<drbokeh::Result<Vec<_>>>()?;
    for s in &specs {
        s.validate()?;
    }
    if let Some(s) = specs.first() {
        // Every scene has the same size and billboard count.
        s.check_budget(Path::new("."))?;
    }
    // Sweeps the temporaries of interrupted runs (scene directories being written).
    drbokeh::io::OutputPlan::new()
        .dir(&a.out, "--output", drbokeh::io::DirMode::Merge)
        .check()?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let entries = specs
        .iter()
        .enumerate()
        .map(|(i, s)| benchmark::manifest_entry(s, i, &dir_name(i)))
        .collect::<drbokeh::Result<Vec<_>>>()?;
    let manifest = serde_json::json!({
        "benchmark": "drbokeh ray-traced ground truth",
        "seed": a.seed,
        "scenes": a.scenes,
        "size": a.size,
        "spp": a.spp,
        "highlight_range": [highlights.lo, highlights.hi],
        "background_detail": a.background_detail,
        "lens": {
            "model": "spherical",
            "curvature_radius_mm": benchmark::CURVATURE_RADIUS_MM,
            "rim_radius_mm": benchmark::RIM_RADIUS_MM,
            "eta": benchmark::ETA,
        },
        "fov_deg": benchmark::FOV_DEG,
        "display_encoding": drbokeh::trace::texture::DISPLAY_ENCODING,
        "entries": entries,
        "perspective": a.perspective,
    });
    let manifest_path = a.out.join("manifest.json");
    // A re-run resumes only the benchmark it would make: before anything is rewritten.
    check_resume(&a.out, &manifest, &specs, dir_name)?;
    let text = serde_json::to_string_pretty(&manifest)? + "\n";
    drbokeh::io::write_atomic(&manifest_path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| drbokeh::Error::file(&manifest_path, format!("write failed: {e}")))
    })?;
    // --only-focus and --min-blur, read from the manifest entry (computed without tracing).
    let wanted = |e: &serde_json::Value| {
        let focus_ok = match a.only_focus {
            Some(f) => matches!(e["focus"].as_f64(), Some(v) if (v - f).abs() <= 1e-6),
            None => true,
        };
        let blur_ok = match a.min_blur {
            Some(b) => matches!(e["blur"].as_f64(), Some(v) if v >= b),
            None => true,
        };
        focus_ok && blur_ok
    };
    let mine: Vec<usize> = (0..a.scenes)
        .filter(|&i| i % n == k && wanted(&entries[i]))
        .collect();
    let start = Instant::now();
    let (mut made, mut skipped) = (0, 0);
    for (done, &i) in mine.iter().enumerate() {
        let dir = a.out.join(dir_name(i));
        if dir.join("scene.json").is_file() {
            skipped += 1;
            continue;
        }
        let label = format!("{}/{} {}", done + 1, mine.len(), dir_name(i));
        let bar = Bar::new(&label, a.quiet);
        let t = Instant::now();
        let result = trace_into(&specs[i], Path::new("."), &dir, dir.exists(), &bar);
        bar.finish();
        result.with_context(|| format!("scene {}", dir_name(i)))?;
        made += 1;
        if !a.quiet {
            eprintln!(
                "drbokeh: {} done in {:.1} s (max blur {:.1} px, focus {})",
                dir_name(i),
                t.elapsed().as_secs_f64(),
                entries[i]["max_coc_radius_px"].as_f64().unwrap_or(0.0),
                benchmark::focus_target(i)
            );
        }
    }
    if !a.quiet {
        eprintln!(
            "drbokeh: benchmark shard {k}/{n}: {made} scenes made, {skipped} already present, {:.1} s; manifest: {}",
            start.elapsed().as_secs_f64(),
            manifest_path.display()
        );
    }
    Ok(())
}

/// The manifest fields that decide which scenes a benchmark holds.
const MANIFEST_PARAMETERS: [(&str, &str); 7] = [
    ("seed", "--seed"),
    ("scenes", "--scenes"),
    ("size", "--size"),
    ("spp", "--spp"),
    ("highlight_range", "--highlight-range"),
    ("background_detail", "--background-detail"),
    ("perspective", "--perspective"),
];

/// Refuses to resume into `out` when what is there was made with other parameters: each
/// scene's blur target depends on `--scenes` and every scene on the others, so skipping a
/// finished scene is right only when it is the scene this run would trace. Checks the
/// existing `manifest.json` field by field, then every finished scene's `scene.json`
/// against its spec.
fn check_resume(
    out: &Path,
    manifest: &serde_json::Value,
    specs: &[SceneSpec],
    dir_name: impl Fn(usize) -> String,
) -> Result<()> {
    let refuse = |what: String| {
        anyhow::anyhow!(
            "{}: {what}; give another --output, or this benchmark's parameters to resume it",
            out.display()
        )
    };
    let manifest_path = out.join("manifest.json");
    if manifest_path.is_file() {
        let old: serde_json::Value = std::fs::read_to_string(&manifest_path)
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok())
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: unreadable benchmark manifest; give another --output",
                    manifest_path.display()
                )
            })?;
        for (key, flag) in MANIFEST_PARAMETERS {
            // Benchmarks made before --perspective existed have no such field: off.
            let absent = match key {
                "perspective" => serde_json::Value::Bool(false),
                _ => serde_json::Value::Null,
            };
            let was = old.get(key).unwrap_or(&absent);
            let now = &manifest[key];
            if was != now {
                return Err(refuse(format!(
                    "holds a benchmark made with {flag} {was} (this run: {now})"
                )));
            }
        }
    }
    for (i, spec) in specs.iter().enumerate() {
        let path = out.join(dir_name(i)).join("scene.json");
        if !path.is_file() {
            continue;
        }
        let mut existing = SceneSpec::read(&path)?;
        existing.derived = None;
        let mut expected = spec.clone();
        trace::absolutize_paths(&mut expected, Path::new("."));
        if existing != expected {
            return Err(refuse(format!(
                "{} holds a scene other than the one this run makes there",
                dir_name(i)
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::parse_shard;

    #[test]
    fn shard_parsing() {
        assert_eq!(parse_shard("1/4").unwrap(), (1, 4));
        assert!(parse_shard("4/4").is_err());
        assert!(parse_shard("1-4").is_err());
        assert!(parse_shard("0/0").is_err());
    }
}
