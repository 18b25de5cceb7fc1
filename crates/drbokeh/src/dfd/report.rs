//! The files of `drbokeh dfd-eval --benchmark`: `results.json` ([`DfdBenchmarkReport`]),
//! `results.md` (tables), `index.html` (per scene the inputs, the true disparity and every
//! method's estimate side by side, the supplement's figs. 8 and 10 made from our data) and
//! `scenes/<scene>/*.png`.

use super::benchmark::{DfdBenchmarkReport, DfdMethod, ScenePictures, SummaryRow};
use crate::eval::report::{heat_colour, write_preview};
use crate::image::Image;
use crate::{io, Error, Result};
use std::fmt::Write as _;
use std::path::Path;

fn write_text(path: &Path, text: &str) -> Result<()> {
    io::write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

fn write_png_rgb8(path: &Path, w: usize, h: usize, rgb: Vec<u8>) -> Result<()> {
    let buf = image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .ok_or_else(|| Error::file(path, "bad image size"))?;
    io::write_atomic(path, |out| {
        image::DynamicImage::ImageRgb8(buf)
            .write_to(out, image::ImageFormat::Png)
            .map_err(|e| Error::file(path, format!("write failed: {e}")))
    })
}

/// Writes a disparity map with the heat colour ramp (0 black, far; 1 white, near).
pub fn write_disparity_png(path: &Path, disparity: &Image<f32>) -> Result<()> {
    let rgb = disparity
        .data
        .iter()
        .flat_map(|&d| heat_colour(d as f64))
        .collect();
    write_png_rgb8(path, disparity.width, disparity.height, rgb)
}

/// Writes a map in [0, 1] as grey.
pub fn write_grey_png(path: &Path, map: &Image<f32>) -> Result<()> {
    let rgb = map
        .data
        .iter()
        .flat_map(|&v| [(v.clamp(0.0, 1.0) * 255.0).round() as u8; 3])
        .collect();
    write_png_rgb8(path, map.width, map.height, rgb)
}

/// Writes a scene's pictures into `dir` (created if missing): `aif.jpg`, `bokeh.jpg`,
/// `truth.png`, and per method `<key>.png` (estimate) and `<key>.conf.png` (confidence).
pub fn write_scene_pictures(dir: &Path, pictures: ScenePictures) -> Result<()> {
    let (scene, runs) = pictures;
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, format!("cannot create: {e}")))?;
    write_preview(&dir.join("aif.jpg"), &scene.inputs.aif)?;
    write_preview(&dir.join("bokeh.jpg"), &scene.inputs.ground_truth)?;
    write_disparity_png(&dir.join("truth.png"), &scene.inputs.disparity)?;
    for (m, est, conf) in runs {
        write_disparity_png(&dir.join(format!("{}.png", m.key())), est)?;
        if let Some(c) = conf {
            write_grey_png(&dir.join(format!("{}.conf.png", m.key())), c)?;
        }
    }
    Ok(())
}

fn opt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        _ => "-".into(),
    }
}

/// A summary row's three AUSE values, `confidence / sensitivity / none`.
fn ause_triple(r: &SummaryRow) -> String {
    let k = &r.ranking;
    match (k.ause, k.ause_sensitivity, k.ause_uninformative) {
        (None, None, None) => "-".into(),
        (a, b, c) => format!("{} / {} / {}", opt(a, 4), opt(b, 4), opt(c, 4)),
    }
}

/// How many times larger `other`'s MAE is than `ours` (`-` if undefined).
fn ratio(ours: &SummaryRow, other: &SummaryRow) -> String {
    if ours.mae > 0.0 && other.mae.is_finite() {
        format!("{:.2}x", other.mae / ours.mae)
    } else {
        "-".into()
    }
}

/// The Markdown tables: per group the mean scores of every method, the default method's
/// MAE ratio against the others, and the per-scene MAE.
pub fn results_markdown(report: &DfdBenchmarkReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# dfd-eval on `{}`\n", report.benchmark);
    let o = &report.options;
    let _ = writeln!(
        s,
        "Options: preset per row, losses per row (weights L1 {}, G {}, (H)SSIM {}), highlights `{:?}`, parameterisation `{:?}`, init `{:?}`, schedule {:?}, engine {}.\n",
        o.weights.l1, o.weights.smoothness, o.weights.hssim, o.highlights, o.parameterisation, o.init, o.schedule, o.engine
    );
    for g in &report.summary {
        let _ = writeln!(s, "## {} ({} scenes)\n", g.title, g.scenes.len());
        s.push_str("| method | MAE | RMSE | δ<1.25 | MAE fg | MAE bg | MAE confident | confident | MAE most confident half | AUSE confidence / sensitivity / none | s/scene |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
        for r in &g.rows {
            let _ = writeln!(
                s,
                "| {} | {:.4} | {:.4} | {:.3} | {} | {} | {} | {} | {} | {} | {:.1} |",
                r.method,
                r.mae,
                r.rmse,
                r.within_1_25,
                opt(r.mae_foreground, 4),
                opt(r.mae_background, 4),
                opt(r.mae_confident, 4),
                opt(r.confident_fraction, 2),
                opt(r.ranking.mae_confident_half, 4),
                ause_triple(r),
                r.seconds
            );
        }
        // Ratios against the default row (drbokeh-physical with HSSIM) when present.
        if let Some(ours) = g.rows.iter().find(|r| r.key == "drbokeh-physical_hssim") {
            s.push_str("\nMAE of each row / MAE of drbokeh-physical L1+G+HSSIM: ");
            let parts: Vec<String> = g
                .rows
                .iter()
                .filter(|r| r.key != ours.key)
                .map(|r| format!("{} {}", r.method, ratio(ours, r)))
                .collect();
            s.push_str(&parts.join(", "));
            s.push('\n');
        }
        s.push_str("\nPer scene (MAE):\n\n| scene | K | focus | max CoC |");
        for r in &g.rows {
            let _ = write!(s, " {} |", r.method);
        }
        s.push_str("\n| --- | ---: | ---: | ---: |");
        for _ in &g.rows {
            s.push_str(" ---: |");
        }
        s.push('\n');
        for sc in report.scenes.iter().filter(|sc| sc.group == g.group) {
            let _ = write!(
                s,
                "| {} | {:.1} | {:.2} | {:.1} |",
                sc.scene, sc.blur, sc.focus, sc.max_coc_px
            );
            for r in &g.rows {
                let v = sc.results.iter().find(|x| x.key == r.key);
                let _ = write!(s, " {} |", opt(v.map(|v| v.errors.mae), 3));
            }
            s.push('\n');
        }
        s.push('\n');
    }
    s
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The HTML page: summary tables, then per scene the all-in-focus and defocused inputs, the
/// true disparity and every method's estimate (same colour ramp), with its MAE; the
/// confidence map of each optimised run on hover (title) and below the estimates of the
/// first method.
pub fn results_html(report: &DfdBenchmarkReport, methods: &[DfdMethod]) -> String {
    let mut s = String::from(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>drbokeh dfd-eval</title>
<style>
body { font-family: sans-serif; margin: 16px; background: #fafafa; color: #222; }
table { border-collapse: collapse; margin: 8px 0; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
td:first-child, th:first-child { text-align: left; }
.scene { border-top: 2px solid #bbb; padding: 6px 0; }
.grid { display: flex; flex-wrap: wrap; gap: 6px; margin: 4px 0; }
figure { margin: 0; }
figure img { width: 160px; height: 160px; display: block; image-rendering: pixelated; }
figcaption { font-size: 11px; max-width: 160px; }
small { color: #666; font-weight: normal; }
</style></head><body>
"#,
    );
    let _ = writeln!(
        s,
        "<h1>Depth from defocus on ray-traced pairs</h1><p>Benchmark <code>{}</code>. Disparity colour ramp: black = farthest (0), white = nearest (1). Constant = the median of the true disparity (an oracle).</p>",
        esc(&report.benchmark)
    );
    for g in &report.summary {
        let _ = writeln!(
            s,
            "<h2>{} ({} scenes)</h2><table><tr><th>method</th><th>MAE</th><th>RMSE</th><th>&delta;&lt;1.25</th><th>MAE fg</th><th>MAE bg</th><th>MAE confident</th><th>confident</th><th>MAE most confident half</th><th>AUSE confidence / sensitivity / none</th><th>s/scene</th></tr>",
            esc(&g.title),
            g.scenes.len()
        );
        for r in &g.rows {
            let _ = writeln!(
                s,
                "<tr><td>{}</td><td>{:.4}</td><td>{:.4}</td><td>{:.3}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.1}</td></tr>",
                esc(&r.method),
                r.mae,
                r.rmse,
                r.within_1_25,
                opt(r.mae_foreground, 4),
                opt(r.mae_background, 4),
                opt(r.mae_confident, 4),
                opt(r.confident_fraction, 2),
                opt(r.ranking.mae_confident_half, 4),
                ause_triple(r),
                r.seconds
            );
        }
        s.push_str("</table>\n");
    }
    for g in &report.summary {
        let _ = writeln!(s, "<h2>Scenes: {}</h2>", esc(&g.title));
        for sc in report.scenes.iter().filter(|sc| sc.group == g.group) {
            let dir = format!("scenes/{}", sc.scene);
            let _ = writeln!(
                s,
                "<section class=\"scene\"><h3>{} <small>K = {:.2}, focus = {:.3}, largest CoC {:.1} px, foreground {:.0} %, clipped aif pixels {:.1} %</small></h3><div class=\"grid\">",
                esc(&sc.scene),
                sc.blur,
                sc.focus,
                sc.max_coc_px,
                100.0 * sc.foreground_fraction,
                100.0 * sc.clipped_aif_fraction
            );
            for (file, label) in [
                ("aif.jpg", "all-in-focus"),
                ("bokeh.jpg", "defocused (ray-traced)"),
                ("truth.png", "true disparity"),
            ] {
                let _ = write!(
                    s,
                    "<figure><img src=\"{dir}/{file}\" alt=\"{label}\"><figcaption>{label}</figcaption></figure>"
                );
            }
            s.push_str("</div><div class=\"grid\">");
            for m in methods {
                let Some(r) = sc.results.iter().find(|r| r.key == m.key()) else {
                    continue;
                };
                let _ = write!(
                    s,
                    "<figure><img src=\"{dir}/{k}.png\" alt=\"{n}\" title=\"{n}\"><figcaption><b>{n}</b><br>MAE {:.3}, fg {}, bg {}</figcaption></figure>",
                    r.errors.mae,
                    opt(r.mae_foreground, 3),
                    opt(r.mae_background, 3),
                    k = m.key(),
                    n = esc(&r.method)
                );
            }
            s.push_str("</div><div class=\"grid\">");
            for m in methods {
                if matches!(m, DfdMethod::ConstantMedian) {
                    continue;
                }
                let Some(r) = sc.results.iter().find(|r| r.key == m.key()) else {
                    continue;
                };
                let _ = write!(
                    s,
                    "<figure><img src=\"{dir}/{k}.conf.png\" alt=\"confidence\"><figcaption>confidence of {n} (white = trusted, dark = within the blur of a depth step); MAE where &ge; 0.5: {}</figcaption></figure>",
                    opt(r.mae_confident, 3),
                    k = m.key(),
                    n = esc(&r.method)
                );
            }
            s.push_str("</div></section>\n");
        }
    }
    s.push_str("</body></html>\n");
    s
}

/// Writes `results.json`, `results.md` and `index.html` into `out` (which must exist).
pub fn write_report(out: &Path, report: &DfdBenchmarkReport, methods: &[DfdMethod]) -> Result<()> {
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| Error::file(out.join("results.json"), e.to_string()))?;
    write_text(&out.join("results.json"), &(json + "\n"))?;
    write_text(&out.join("results.md"), &results_markdown(report))?;
    write_text(&out.join("index.html"), &results_html(report, methods))?;
    Ok(())
}
