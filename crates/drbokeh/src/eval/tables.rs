//! The tables of a report: `results.csv` and `summary.md`.

use super::summary::{Report, SummaryRow};
use std::fmt::Write as _;

/// The CSV of a report: one row per scene and method. Header:
/// `scene,method,input,blur,focus,max_coc_px,bucket,psnr,ssim,ms_ssim,time_s`; an
/// infinite PSNR is written `inf`.
pub fn results_csv(report: &Report) -> String {
    let mut s =
        String::from("scene,method,input,blur,focus,max_coc_px,bucket,psnr,ssim,ms_ssim,time_s\n");
    for sc in &report.scenes {
        for r in &sc.results {
            let input = report.input_of(&r.method);
            let psnr = if r.psnr.is_finite() {
                format!("{:.6}", r.psnr)
            } else if r.psnr > 0.0 {
                "inf".to_string()
            } else {
                "nan".to_string()
            };
            let _ = writeln!(
                s,
                "{},{},{},{:.6},{:.6},{:.4},{},{},{:.6},{:.6},{:.4}",
                csv_field(&sc.scene),
                csv_field(&r.method),
                input,
                sc.blur,
                sc.focus,
                sc.max_coc_px,
                csv_field(&sc.bucket),
                psnr,
                r.ssim,
                r.ms_ssim,
                r.time_s
            );
        }
    }
    s
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

pub(super) fn fmt_ms(m: Option<f64>, s: Option<f64>, digits: usize) -> String {
    match (m, s) {
        (Some(m), Some(s)) => format!("{m:.digits$} ± {s:.digits$}"),
        _ => "–".to_string(),
    }
}

/// The mean PSNR of `method` over all scenes (`bucket` `None`) or one bucket.
fn psnr_of(report: &Report, method: &str, bucket: Option<&str>) -> Option<f64> {
    let rows = match bucket {
        None => &report.summary.overall,
        Some(b) => {
            &report
                .summary
                .by_bucket
                .iter()
                .find(|x| x.bucket == b)?
                .methods
        }
    };
    rows.iter().find(|r| r.method == method)?.psnr_mean
}

/// The photo pipeline's rows (`photo-*` methods): mean PSNR over all scenes and per blur
/// bucket, each with its difference to `scatter` when that was evaluated, as
/// `(method, [(column, cell)])`.
pub(super) fn headline_cells(report: &Report) -> Vec<(String, Vec<(String, String)>)> {
    let mut columns: Vec<(String, Option<&str>)> = vec![("all scenes".to_string(), None)];
    for b in &report.summary.by_bucket {
        columns.push((format!("{} (n={})", b.bucket, b.scenes), Some(&b.bucket)));
    }
    let mut out = Vec::new();
    for m in report
        .methods
        .iter()
        .filter(|m| m.name.starts_with("photo-"))
    {
        let cells = columns
            .iter()
            .map(|(title, bucket)| {
                let cell = match (
                    psnr_of(report, &m.name, *bucket),
                    psnr_of(report, "scatter", *bucket),
                ) {
                    (Some(p), Some(base)) => format!("{p:.2} ({:+.2})", p - base),
                    (Some(p), None) => format!("{p:.2}"),
                    _ => "–".to_string(),
                };
                (title.clone(), cell)
            })
            .collect();
        out.push((m.name.clone(), cells));
    }
    out
}

/// The headline table in Markdown (empty without `photo-*` methods).
fn headline_markdown(report: &Report) -> String {
    let rows = headline_cells(report);
    let Some((_, first)) = rows.first() else {
        return String::new();
    };
    let mut s = String::from("| method |");
    let mut rule = String::from("|---|");
    for (title, _) in first {
        let _ = write!(s, " PSNR {title} |");
        rule.push_str("---:|");
    }
    let _ = writeln!(s, "\n{rule}");
    for (name, cells) in &rows {
        let _ = write!(s, "| {name} |");
        for (_, c) in cells {
            let _ = write!(s, " {c} |");
        }
        let _ = writeln!(s);
    }
    s
}

/// The Markdown summary: overall mean ± standard deviation per method (ranked by mean
/// PSNR) and per blur-size bucket.
pub fn summary_markdown(report: &Report) -> String {
    let mut s = String::new();
    let (w, h) = report
        .scenes
        .first()
        .map(|sc| (sc.width, sc.height))
        .unwrap_or((0, 0));
    let _ = writeln!(s, "# drbokeh evaluation\n");
    let _ = writeln!(
        s,
        "Benchmark `{}`: {} scenes of {w}x{h} px. Every method renders from the same inputs with the scene's K and focus; scores against the ray-traced `bokeh.png` (display-encoded, clipped). Mean ± sample standard deviation over scenes; higher is better except time (wall clock per render, this machine).\n",
        report.benchmark, report.scene_count
    );
    let headline = headline_markdown(report);
    if !headline.is_empty() {
        let _ = writeln!(
            s,
            "## Headline: the photo pipeline
"
        );
        let _ = writeln!(
            s,
            "What a user gets from `drbokeh render --image aif.png --disparity disparity.npy` with the scene's K and focus (default highlights, decomposition into layers), mean PSNR (dB) and its gain over naive scatter. The one-layer (`-aif`) and true-layer (`-gt`) rows below are ablations.\n"
        );
        s.push_str(&headline);
        let _ = writeln!(s);
    }
    let mut ranked: Vec<&SummaryRow> = report.summary.overall.iter().collect();
    ranked.sort_by(|a, b| {
        b.psnr_mean
            .unwrap_or(f64::NEG_INFINITY)
            .total_cmp(&a.psnr_mean.unwrap_or(f64::NEG_INFINITY))
    });
    let _ = writeln!(s, "## All scenes\n");
    let _ = writeln!(
        s,
        "| rank | method | input | PSNR (dB) | SSIM | MS-SSIM | time (s) |\n|---:|---|---|---:|---:|---:|---:|"
    );
    for (i, r) in ranked.iter().enumerate() {
        let input = report.input_of(&r.method);
        let inf = if r.psnr_infinite > 0 {
            format!(" ({} identical)", r.psnr_infinite)
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}{} | {} | {} | {} |",
            i + 1,
            r.method,
            input,
            fmt_ms(r.psnr_mean, r.psnr_std, 2),
            inf,
            fmt_ms(r.ssim_mean, r.ssim_std, 4),
            fmt_ms(r.ms_ssim_mean, r.ms_ssim_std, 4),
            r.time_mean_s
                .map(|t| format!("{t:.2}"))
                .unwrap_or_else(|| "–".into())
        );
    }
    let _ = writeln!(s, "\n## By blur size (largest CoC radius in the scene)\n");
    type Metric = fn(&SummaryRow) -> (Option<f64>, Option<f64>);
    let metric_list: [(&str, Metric, usize); 3] = [
        ("PSNR (dB)", |r| (r.psnr_mean, r.psnr_std), 2),
        ("SSIM", |r| (r.ssim_mean, r.ssim_std), 4),
        ("MS-SSIM", |r| (r.ms_ssim_mean, r.ms_ssim_std), 4),
    ];
    for (title, get, digits) in metric_list {
        let _ = writeln!(s, "### {title}\n");
        let mut head = String::from("| method |");
        let mut rule = String::from("|---|");
        for b in &report.summary.by_bucket {
            let _ = write!(head, " {} (n={}) |", b.bucket, b.scenes);
            rule.push_str("---:|");
        }
        let _ = writeln!(s, "{head}\n{rule}");
        for m in &report.methods {
            let _ = write!(s, "| {} |", m.name);
            for b in &report.summary.by_bucket {
                let cell = b
                    .methods
                    .iter()
                    .find(|r| r.method == m.name)
                    .map(|r| {
                        let (mean, std) = get(r);
                        fmt_ms(mean, std, digits)
                    })
                    .unwrap_or_else(|| "–".into());
                let _ = write!(s, " {cell} |");
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s, "## Methods\n");
    for m in &report.methods {
        let _ = writeln!(s, "- `{}` ({}): {}", m.name, m.input.name(), m.description);
    }
    s
}
