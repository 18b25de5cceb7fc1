//! The report's self-contained HTML gallery (`index.html`).

use super::images::{method_image_names, ERROR_MAP_FULL_SCALE};
use super::methods::Method;
use super::plots::{plot_files, xml_escape};
use super::summary::Report;
use super::tables::fmt_ms;
use std::fmt::Write as _;

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map(|v| format!("{v:.digits$}"))
        .unwrap_or_else(|| "–".into())
}

/// The self-contained HTML gallery of a report (`index.html`): summary table (click a
/// column to sort), the plots, and per scene the inputs, ground truth, each method's render
/// and error map; scenes can be sorted by name, blur or any method's metric. Images are
/// referenced relatively (`scenes/<scene>/...`), so the folder can be moved or zipped.
pub fn report_html(report: &Report) -> String {
    let mut s = String::new();
    s.push_str(HTML_HEAD);
    let _ = writeln!(s, "<h1>drbokeh evaluation</h1>");
    let _ = writeln!(
        s,
        "<p>Benchmark <code>{}</code>, {} scenes. Every method gets the same inputs and the scene's K and focus; scores against the ray-traced ground truth (display-encoded, clipped). Error maps: mean absolute error over channels, black = 0, white &ge; {ERROR_MAP_FULL_SCALE}.</p>",
        xml_escape(&report.benchmark),
        report.scene_count
    );
    s.push_str("<h2>Summary (mean ± sample std over scenes; click a column to sort)</h2>\n<table class=\"sortable\" id=\"summary\"><thead><tr><th>method</th><th>input</th><th>PSNR (dB)</th><th>SSIM</th><th>MS-SSIM</th><th>time (s)</th></tr></thead><tbody>\n");
    for r in &report.summary.overall {
        let m = report.methods.iter().find(|m| m.name == r.method);
        let _ = writeln!(
            s,
            "<tr><td data-v=\"{0}\" title=\"{1}\">{0}</td><td data-v=\"{2}\">{2}</td><td data-v=\"{3}\">{4}</td><td data-v=\"{5}\">{6}</td><td data-v=\"{7}\">{8}</td><td data-v=\"{9}\">{10}</td></tr>",
            xml_escape(&r.method),
            xml_escape(m.map(|m| m.description.as_str()).unwrap_or("")),
            m.map(|m| m.input.name()).unwrap_or(""),
            fmt_opt(r.psnr_mean, 4),
            fmt_ms(r.psnr_mean, r.psnr_std, 2),
            fmt_opt(r.ssim_mean, 6),
            fmt_ms(r.ssim_mean, r.ssim_std, 4),
            fmt_opt(r.ms_ssim_mean, 6),
            fmt_ms(r.ms_ssim_mean, r.ms_ssim_std, 4),
            fmt_opt(r.time_mean_s, 4),
            fmt_opt(r.time_mean_s, 2),
        );
    }
    s.push_str("</tbody></table>\n<h2>Quality vs blur size</h2>\n<div class=\"plots\">");
    for (file, title, _) in plot_files() {
        let _ = write!(s, "<img src=\"{file}\" alt=\"{title} vs blur size\">");
    }
    s.push_str("</div>\n<h2>Scenes</h2>\n<div class=\"controls\">Sort scenes by <select id=\"sortkey\"><option value=\"name\">scene name</option><option value=\"blur\">largest blur</option>");
    for m in &report.methods {
        for (key, label) in [("psnr", "PSNR"), ("ssim", "SSIM"), ("msssim", "MS-SSIM")] {
            let _ = write!(
                s,
                "<option value=\"{key}-{0}\">{label} of {0}</option>",
                xml_escape(&m.name)
            );
        }
    }
    s.push_str("</select> <select id=\"sortdir\"><option value=\"1\">ascending</option><option value=\"-1\">descending</option></select></div>\n<div id=\"scenes\">\n");
    for sc in &report.scenes {
        let dir = format!("scenes/{}", sc.scene);
        let mut attrs = format!(
            "data-name=\"{}\" data-blur=\"{}\"",
            xml_escape(&sc.scene),
            sc.max_coc_px
        );
        for r in &sc.results {
            let psnr = if r.psnr.is_finite() {
                r.psnr.to_string()
            } else {
                "Infinity".into()
            };
            let _ = write!(
                attrs,
                " data-psnr-{m}=\"{psnr}\" data-ssim-{m}=\"{}\" data-msssim-{m}=\"{}\"",
                r.ssim,
                r.ms_ssim,
                m = xml_escape(&r.method)
            );
        }
        let _ = writeln!(s, "<section class=\"scene\" {attrs}>");
        let _ = writeln!(
            s,
            "<h3>{} <small>K = {:.2}, focus = {:.3}, largest CoC {:.1} px ({})</small></h3>",
            xml_escape(&sc.scene),
            sc.blur,
            sc.focus,
            sc.max_coc_px,
            xml_escape(&sc.bucket)
        );
        s.push_str("<div class=\"grid\">");
        for (file, label) in [
            ("aif.jpg", "all-in-focus"),
            ("disparity.png", "disparity"),
            ("gt.jpg", "ground truth"),
        ] {
            let _ = write!(
                s,
                "<figure><img src=\"{dir}/{file}\" alt=\"{label}\"><figcaption>{label}</figcaption></figure>"
            );
        }
        s.push_str("</div>\n<div class=\"grid\">");
        for r in &sc.results {
            let Ok(m) = r.method.parse::<Method>() else {
                continue;
            };
            let (img, err) = method_image_names(m);
            let psnr = if r.psnr.is_finite() {
                format!("{:.2} dB", r.psnr)
            } else {
                "∞".into()
            };
            let _ = write!(
                s,
                "<figure class=\"pair\"><div><img src=\"{dir}/{img}\" alt=\"{n}\"><img src=\"{dir}/{err}\" alt=\"{n} error\"></div><figcaption><b>{n}</b> PSNR {psnr}, SSIM {:.4}, MS-SSIM {:.4}</figcaption></figure>",
                r.ssim,
                r.ms_ssim,
                n = xml_escape(&r.method)
            );
        }
        s.push_str("</div>\n</section>\n");
    }
    s.push_str("</div>\n");
    s.push_str(HTML_SCRIPT);
    s.push_str("</body>\n</html>\n");
    s
}

const HTML_HEAD: &str = r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>drbokeh evaluation</title>
<style>
body { font-family: sans-serif; margin: 16px; background: #fafafa; color: #222; }
table { border-collapse: collapse; margin: 8px 0; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
th { background: #eee; cursor: pointer; }
td:first-child, th:first-child { text-align: left; }
.plots img { max-width: 32%; min-width: 320px; border: 1px solid #ddd; margin: 2px; }
.scene { border-top: 2px solid #bbb; padding: 6px 0; }
.grid { display: flex; flex-wrap: wrap; gap: 8px; margin: 4px 0; }
figure { margin: 0; }
figure img { width: 200px; height: auto; display: block; }
figure.pair div { display: flex; gap: 2px; }
figcaption { font-size: 11px; max-width: 402px; }
small { color: #666; font-weight: normal; }
.controls { margin: 8px 0; }
</style>
</head>
<body>
"#;

const HTML_SCRIPT: &str = r#"<script>
(function () {
  function sortScenes() {
    var key = document.getElementById('sortkey').value;
    var dir = parseFloat(document.getElementById('sortdir').value);
    var box = document.getElementById('scenes');
    var items = Array.prototype.slice.call(box.querySelectorAll('section.scene'));
    items.sort(function (a, b) {
      if (key === 'name') {
        return dir * a.getAttribute('data-name').localeCompare(b.getAttribute('data-name'));
      }
      var va = parseFloat(a.getAttribute('data-' + key));
      var vb = parseFloat(b.getAttribute('data-' + key));
      if (isNaN(va)) va = -Infinity;
      if (isNaN(vb)) vb = -Infinity;
      return dir * (va === vb ? 0 : (va < vb ? -1 : 1));
    });
    items.forEach(function (el) { box.appendChild(el); });
  }
  document.getElementById('sortkey').addEventListener('change', sortScenes);
  document.getElementById('sortdir').addEventListener('change', sortScenes);
  Array.prototype.forEach.call(document.querySelectorAll('table.sortable'), function (table) {
    Array.prototype.forEach.call(table.querySelectorAll('th'), function (th, col) {
      var dir = -1;
      th.addEventListener('click', function () {
        dir = -dir;
        var body = table.tBodies[0];
        var rows = Array.prototype.slice.call(body.rows);
        rows.sort(function (a, b) {
          var x = a.cells[col].getAttribute('data-v'), y = b.cells[col].getAttribute('data-v');
          var fx = parseFloat(x), fy = parseFloat(y);
          if (!isNaN(fx) && !isNaN(fy)) return dir * (fx - fy);
          return dir * String(x).localeCompare(String(y));
        });
        rows.forEach(function (r) { body.appendChild(r); });
      });
    });
  });
})();
</script>
"#;
