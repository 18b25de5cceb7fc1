//! The SVG plots of a report: one metric against the scene's blur size.

use super::scoring::MethodResult;
use super::summary::{buckets, Report};
use std::fmt::Write as _;

/// Colours of the plot series.
const PALETTE: [&str; 8] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#d62728", "#8c564b", "#e377c2", "#17becf",
];

pub(super) fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

/// "Nice" tick values covering `[lo, hi]`.
fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= target as f64)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-9 * step {
        out.push(t);
        t += step;
    }
    out
}

/// An SVG plot of one metric against the scene's largest CoC radius: each scene a point,
/// each method a line through its per-bucket means.
pub fn metric_plot_svg(report: &Report, title: &str, get: MetricAccessor) -> String {
    let (w, h) = (760.0, 440.0);
    let (left, right, top, bottom) = (64.0, 190.0, 36.0, 48.0);
    let mut pts: Vec<(usize, f64, f64)> = Vec::new();
    for sc in &report.scenes {
        for r in &sc.results {
            if let Some(mi) = report.methods.iter().position(|m| m.name == r.method) {
                let v = get(r);
                if v.is_finite() {
                    pts.push((mi, sc.max_coc_px, v));
                }
            }
        }
    }
    let (mut x0, mut x1, mut y0, mut y1) = (0.0f64, 1.0f64, f64::INFINITY, f64::NEG_INFINITY);
    for &(_, x, y) in &pts {
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !y0.is_finite() {
        (y0, y1) = (0.0, 1.0);
    }
    let pad = ((y1 - y0) * 0.08).max(1e-3);
    y0 -= pad;
    y1 += pad;
    x1 *= 1.05;
    x0 = x0.min(0.0);
    let px = |x: f64| left + (x - x0) / (x1 - x0) * (w - left - right);
    let py = |y: f64| top + (1.0 - (y - y0) / (y1 - y0)) * (h - top - bottom);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="20" text-anchor="middle" font-size="15">{} vs blur size</text>"#,
        (left + w - right) / 2.0,
        xml_escape(title)
    );
    for t in ticks(x0, x1, 8) {
        let x = px(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{top}" x2="{x:.1}" y2="{:.1}" stroke="#e5e5e5"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{t}</text>"##,
            h - bottom,
            h - bottom + 16.0
        );
    }
    for t in ticks(y0, y1, 6) {
        let y = py(t);
        let label = if (y1 - y0) < 0.5 {
            format!("{t:.3}")
        } else {
            format!("{t}")
        };
        let _ = writeln!(
            s,
            r##"<line x1="{left}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#e5e5e5"/><text x="{:.1}" y="{:.1}" text-anchor="end">{label}</text>"##,
            w - right,
            left - 6.0,
            y + 4.0
        );
    }
    let _ = writeln!(
        s,
        r##"<rect x="{left}" y="{top}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
        w - left - right,
        h - top - bottom
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">largest CoC radius in the scene (px)</text>"#,
        (left + w - right) / 2.0,
        h - 10.0
    );
    let _ = writeln!(
        s,
        r#"<text transform="translate(16 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
        (top + h - bottom) / 2.0,
        xml_escape(title)
    );
    let bks = buckets();
    for (mi, m) in report.methods.iter().enumerate() {
        let colour = PALETTE[mi % PALETTE.len()];
        for &(_, x, y) in pts.iter().filter(|p| p.0 == mi) {
            let _ = writeln!(
                s,
                r#"<circle cx="{:.1}" cy="{:.1}" r="3" fill="{colour}" fill-opacity="0.45"/>"#,
                px(x),
                py(y)
            );
        }
        // Line through the per-bucket means (x: mean blur of the bucket's scenes).
        let mut line = Vec::new();
        for b in &bks {
            let sel: Vec<(f64, f64)> = pts
                .iter()
                .filter(|p| {
                    p.0 == mi && p.1 >= b.min_px && b.max_px.map(|hi| p.1 < hi).unwrap_or(true)
                })
                .map(|p| (p.1, p.2))
                .collect();
            if !sel.is_empty() {
                let n = sel.len() as f64;
                line.push((
                    sel.iter().map(|p| p.0).sum::<f64>() / n,
                    sel.iter().map(|p| p.1).sum::<f64>() / n,
                ));
            }
        }
        if line.len() > 1 {
            let d: Vec<String> = line
                .iter()
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2"/>"#,
                d.join(" ")
            );
        }
        for &(x, y) in &line {
            let _ = writeln!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="7" height="7" fill="{colour}"/>"#,
                px(x) - 3.5,
                py(y) - 3.5
            );
        }
        let ly = top + 10.0 + 20.0 * mi as f64;
        let lx = w - right + 14.0;
        let _ = writeln!(
            s,
            r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="3"/><text x="{}" y="{}">{}</text>"#,
            lx + 22.0,
            lx + 28.0,
            ly + 4.0,
            xml_escape(&m.name)
        );
    }
    for (i, line) in ["dots: scenes", "squares, lines: means", "per blur bucket"]
        .iter()
        .enumerate()
    {
        let _ = writeln!(
            s,
            r##"<text x="{:.1}" y="{:.1}" font-size="10" fill="#555">{line}</text>"##,
            w - right + 14.0,
            h - bottom - 28.0 + 13.0 * i as f64
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Reads one metric from a result.
pub type MetricAccessor = fn(&MethodResult) -> f64;

/// The SVG plots written by [`crate::eval::report::write_report`]: (file name, metric title, accessor).
pub fn plot_files() -> [(&'static str, &'static str, MetricAccessor); 3] {
    [
        ("psnr_vs_blur.svg", "PSNR (dB)", |r| r.psnr),
        ("ssim_vs_blur.svg", "SSIM", |r| r.ssim),
        ("ms_ssim_vs_blur.svg", "MS-SSIM", |r| r.ms_ssim),
    ]
}
