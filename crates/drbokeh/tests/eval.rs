//! Evaluation: the baselines' known defects, the report files and their schema.

use drbokeh::baselines::{self, Baseline};
use drbokeh::eval::report::{self, Method, SceneResult};
use drbokeh::trace::{self, benchmark};
use drbokeh::{Camera, Image, Layer, LayerStack, NoProgress, Window};
use std::path::Path;

const W: usize = 64;
const H: usize = 32;
/// Foreground covers columns `< EDGE`.
const EDGE: usize = 32;
const RED: [f64; 3] = [0.9, 0.1, 0.1];
const BLUE: [f64; 3] = [0.1, 0.2, 0.9];
const FG_DISP: f64 = 0.8;
const BG_DISP: f64 = 0.2;

/// Two layers: an in-focus red foreground on the left half over a blurred (CoC 12 px) blue
/// background. Both are flat, so the true defocused image is the all-in-focus image
/// itself: red left of the edge, blue right of it, with a sharp edge.
fn two_layers() -> (LayerStack<f64>, Image<f64>, Image<f64>, Camera) {
    let mut fg = Layer::<f64>::constant(W, H, RED, 1.0, FG_DISP);
    for y in 0..H {
        for x in EDGE..W {
            *fg.alpha.at_mut(x, y, 0) = 0.0;
        }
    }
    let bg = Layer::<f64>::constant(W, H, BLUE, 1.0, BG_DISP);
    let stack = LayerStack::new(vec![fg, bg]).unwrap();
    let mut aif = Image::new(W, H, 3);
    let mut disp = Image::new(W, H, 1);
    for y in 0..H {
        for x in 0..W {
            let (c, d) = if x < EDGE {
                (RED, FG_DISP)
            } else {
                (BLUE, BG_DISP)
            };
            for k in 0..3 {
                *aif.at_mut(x, y, k) = c[k];
            }
            *disp.at_mut(x, y, 0) = d;
        }
    }
    let mut cam = Camera::paper_default(FG_DISP);
    cam.blur_k = 20.0; // background CoC: 20 * 0.6 = 12 px
    cam.window = Window::from_size(33).unwrap();
    (stack, aif, disp, cam)
}

fn px(img: &Image<f64>, x: usize) -> [f64; 3] {
    [0, 1, 2].map(|c| img.at(x, H / 2, c))
}

fn max_err(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0, f64::max)
}

fn paper(stack: &LayerStack<f64>, cam: &Camera) -> Image<f64> {
    let mut s = drbokeh::RenderSettings::paper(cam.focus_disparity);
    s.camera = cam.clone();
    drbokeh::render(stack, &s, drbokeh::Engine::Reference, &NoProgress).unwrap()
}

/// Probe pixels: 2.5 px outside the foreground (background side) and inside it.
const BG_PROBE: usize = EDGE + 2;
const FG_PROBE: usize = EDGE - 3;

#[test]
fn paper_preset_keeps_the_sharp_edge() {
    let (stack, aif, disp, cam) = two_layers();
    let single = LayerStack::single(aif.clone(), disp.clone()).unwrap();
    for (what, out) in [
        ("paper on layers", paper(&stack, &cam)),
        ("paper on one layer", paper(&single, &cam)),
    ] {
        for x in [BG_PROBE, FG_PROBE] {
            let e = max_err(px(&out, x), px(&aif, x));
            assert!(e < 0.03, "{what}: error {e} at x = {x}");
        }
    }
}

#[test]
fn naive_gather_bleeds_the_sharp_foreground_into_the_background() {
    let (_, aif, disp, cam) = two_layers();
    let out = baselines::naive_gather(&aif, &disp, &cam).unwrap();
    // Background pixels next to the edge average the red foreground in: a red halo.
    let p = px(&out, BG_PROBE);
    assert!(p[0] > 0.4, "gather: red {} at the background probe", p[0]);
    // The in-focus foreground itself stays exact (it only averages itself).
    assert!(max_err(px(&out, FG_PROBE), RED) < 1e-4);
    // Far from the edge both sides are right.
    assert!(max_err(px(&out, 2), RED) < 1e-4 && max_err(px(&out, W - 2), BLUE) < 1e-4);
}

#[test]
fn naive_scatter_spreads_the_background_over_the_sharp_foreground() {
    let (_, aif, disp, cam) = two_layers();
    let out = baselines::naive_scatter(&aif, &disp, &cam).unwrap();
    let p = px(&out, FG_PROBE);
    assert!(
        p[2] > 0.35,
        "scatter: blue {} inside the in-focus foreground",
        p[2]
    );
    assert!(max_err(px(&out, W - 2), BLUE) < 1e-4);
}

#[test]
fn gauss_psf_spreads_the_background_over_the_sharp_foreground() {
    let (_, aif, disp, cam) = two_layers();
    let out = baselines::gauss_psf(&aif, &disp, &cam).unwrap();
    let p = px(&out, FG_PROBE);
    assert!(p[2] > 0.3, "gausspsf: blue {} inside the foreground", p[2]);
}

#[test]
fn layered_blur_darkens_where_the_image_hides_the_background() {
    let (stack, aif, disp, cam) = two_layers();
    let single = LayerStack::single(aif.clone(), disp.clone()).unwrap();
    let out = baselines::layered_disc(&single, &cam, baselines::LAYERED_PLANES).unwrap();
    // The background plane has a hole under the foreground; blurred, it covers the pixels
    // next to the edge only partly: a dark fringe (every channel too low).
    let p = px(&out, BG_PROBE);
    for c in 0..3 {
        assert!(
            p[c] < 0.9 * BLUE[c],
            "layered: channel {c} = {} not darker than {}",
            p[c],
            BLUE[c]
        );
    }
    // With the hidden background (the true layers) the same renderer is right.
    let full = Baseline::LayeredDisc.render(&stack, &cam).unwrap();
    for x in [BG_PROBE, FG_PROBE] {
        assert!(max_err(px(&full, x), px(&aif, x)) < 1e-3);
    }
}

#[test]
fn baselines_are_deterministic_and_reject_bad_input() {
    let (stack, aif, disp, cam) = two_layers();
    for b in Baseline::ALL {
        let a = b.render(&stack, &cam).unwrap();
        assert_eq!(a, b.render(&stack, &cam).unwrap(), "{}", b.name());
        assert!(a.data.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
    let small = Image::<f64>::new(W - 1, H, 1);
    assert!(baselines::naive_gather(&aif, &small, &cam).is_err());
    assert!(baselines::naive_scatter(&aif, &small, &cam).is_err());
    let mut bad = cam.clone();
    bad.focus_disparity = 2.0;
    assert!(baselines::naive_gather(&aif, &disp, &bad).is_err());
    assert!(baselines::layered_disc(&stack, &cam, 0).is_err());
}

/// Makes a tiny benchmark (2 scenes of 64x64 at 16 spp) in `dir`.
fn tiny_benchmark(dir: &Path) {
    for i in 0..2 {
        let spec = benchmark::scene_spec(0, i, 2, 64, 16).unwrap();
        let scene = spec.load(Path::new(".")).unwrap();
        let out = trace::trace_scene(&scene, &spec.render, &NoProgress).unwrap();
        trace::write_scene_dir(&dir.join(format!("scene_{i:03}")), &spec, &scene, &out).unwrap();
    }
}

#[test]
fn identical_images_have_null_psnr_in_results_json() {
    let img = Image::from_vec(
        32,
        32,
        3,
        (0..32 * 32 * 3).map(|i| (i % 17) as f32 / 16.0).collect(),
    )
    .unwrap();
    let mut same = report::score(Method::PaperGt, &img, &img).unwrap();
    same.time_s = 0.5;
    assert_eq!(same.psnr, f64::INFINITY);
    let mut other = img.clone();
    other.data[0] = 0.5;
    let diff = report::score(Method::Gather, &other, &img).unwrap();
    let scene = SceneResult {
        scene: "s".into(),
        blur: 10.0,
        focus: 0.5,
        max_coc_px: 5.0,
        bucket: report::bucket_of(5.0),
        width: 32,
        height: 32,
        results: vec![same, diff],
    };
    let rep = report::Report::new(
        Path::new("bench"),
        &[Method::PaperGt, Method::Gather],
        vec![scene],
    );
    let tmp = tempfile::tempdir().unwrap();
    report::write_report(tmp.path(), &rep).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("results.json")).unwrap())
            .unwrap();
    let results = &json["scenes"][0]["results"];
    assert!(results[0]["psnr"].is_null(), "{}", results[0]);
    assert!(results[1]["psnr"].as_f64().unwrap() > 40.0);
    let overall = &json["summary"]["overall"][0];
    assert_eq!(overall["method"], "paper-gt");
    assert_eq!(overall["psnr_infinite"], 1);
    assert!(overall["psnr_mean"].is_null());
    let csv = std::fs::read_to_string(tmp.path().join("results.csv")).unwrap();
    assert!(csv.lines().nth(1).unwrap().contains(",inf,"), "{csv}");
}

#[test]
fn eval_on_a_tiny_benchmark_writes_every_file_with_the_documented_schema() {
    let tmp = tempfile::tempdir().unwrap();
    let bench = tmp.path().join("bench");
    std::fs::create_dir(&bench).unwrap();
    tiny_benchmark(&bench);
    let out = tmp.path().join("report");
    let rep =
        report::evaluate_benchmark(&bench, &Method::ALL, Some(&out), None, &NoProgress).unwrap();
    report::write_report(&out, &rep).unwrap();

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["schema_version"], report::SCHEMA_VERSION);
    assert_eq!(json["scene_count"], 2);
    let methods: Vec<&str> = json["methods"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert_eq!(methods, Method::ALL.map(|m| m.name()).to_vec());
    let scenes = json["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 2);
    for (i, s) in scenes.iter().enumerate() {
        assert_eq!(s["scene"], format!("scene_{i:03}"));
        for key in ["blur", "focus", "max_coc_px"] {
            assert!(s[key].as_f64().unwrap() >= 0.0, "{key}");
        }
        assert!(s["bucket"].is_string());
        assert_eq!(
            (s["width"].as_u64(), s["height"].as_u64()),
            (Some(64), Some(64))
        );
        let results = s["results"].as_array().unwrap();
        assert_eq!(results.len(), Method::ALL.len());
        for r in results {
            let psnr = r["psnr"].as_f64().unwrap();
            assert!((5.0..80.0).contains(&psnr), "{r}");
            for key in ["ssim", "ms_ssim"] {
                let v = r[key].as_f64().unwrap();
                assert!((-1.0..=1.0).contains(&v), "{r}");
            }
            assert!(r["time_s"].as_f64().unwrap() >= 0.0);
            for f in [
                format!("{}.jpg", r["method"].as_str().unwrap()),
                format!("{}.err.png", r["method"].as_str().unwrap()),
            ] {
                assert!(out
                    .join("scenes")
                    .join(s["scene"].as_str().unwrap())
                    .join(f)
                    .is_file());
            }
        }
    }
    let overall = json["summary"]["overall"].as_array().unwrap();
    assert_eq!(overall.len(), Method::ALL.len());
    for r in overall {
        assert_eq!(r["n"], 2);
        assert!(r["psnr_mean"].as_f64().is_some() && r["psnr_std"].as_f64().is_some());
    }
    assert!(!json["summary"]["by_bucket"].as_array().unwrap().is_empty());

    // CSV: header, one row per scene and method, numeric fields parse.
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        [
            "scene",
            "method",
            "input",
            "blur",
            "focus",
            "max_coc_px",
            "bucket",
            "psnr",
            "ssim",
            "ms_ssim",
            "time_s"
        ]
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2 * Method::ALL.len());
    for r in &rows {
        assert_eq!(r.len(), header.len());
        for i in [3, 4, 5, 7, 8, 9, 10] {
            r[i].parse::<f64>().unwrap();
        }
        assert!(["aif+disparity", "layers"].contains(&r[2]));
    }

    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    for m in Method::ALL {
        assert!(md.contains(&format!("| {} |", m.name())), "{md}");
    }
    assert!(md.contains("By blur size"));
    for (file, _, _) in report::plot_files() {
        let svg = std::fs::read_to_string(out.join(file)).unwrap();
        assert!(svg.starts_with("<svg") && (svg.contains("polyline") || svg.contains("circle")));
    }
    // Every image the page references exists, relative to the report folder.
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    let srcs: Vec<&str> = html
        .split("src=\"")
        .skip(1)
        .map(|s| s.split('"').next().unwrap())
        .collect();
    assert!(
        srcs.len() >= 3 + 2 * 3 + 2 * 2 * Method::ALL.len(),
        "{}",
        srcs.len()
    );
    for s in srcs {
        assert!(!s.starts_with('/') && !s.contains("://"), "{s}");
        assert!(out.join(s).is_file(), "missing {s}");
    }
    assert!(html.contains("<script>") && html.contains("sortkey"));
}

#[test]
fn missing_benchmark_or_scene_files_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let e = report::list_scenes(&tmp.path().join("nope")).unwrap_err();
    assert!(e.to_string().contains("does not exist"), "{e}");
    let e = report::list_scenes(tmp.path()).unwrap_err();
    assert!(e.to_string().contains("no scene"), "{e}");
    let scene = tmp.path().join("scene_000");
    std::fs::create_dir(&scene).unwrap();
    std::fs::write(scene.join("scene.json"), "{\"blur\": 3, \"focus\": 0.5}").unwrap();
    let e =
        report::evaluate_benchmark(tmp.path(), &Method::ALL, None, None, &NoProgress).unwrap_err();
    assert!(
        e.to_string().contains("aif.png") && e.to_string().contains("missing"),
        "{e}"
    );
    assert!("paper".parse::<Method>().is_err());
    assert_eq!(
        Method::parse_list("gather, paper-gt,gather").unwrap(),
        vec![Method::Gather, Method::PaperGt]
    );
}

#[test]
fn buckets_and_statistics() {
    assert_eq!(report::bucket_of(3.9), "<8 px");
    assert_eq!(report::bucket_of(8.0), "8-16 px");
    assert_eq!(report::bucket_of(40.0), ">=32 px");
    let (m, s) = report::mean_std(&[1.0, 2.0, 3.0, f64::INFINITY]).unwrap();
    assert!((m - 2.0).abs() < 1e-12 && (s - 1.0).abs() < 1e-12);
    assert!(report::mean_std(&[f64::INFINITY]).is_none());
}
