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
