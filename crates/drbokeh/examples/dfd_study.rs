//! Scratch study: run dfd on benchmark scenes with options given as key=value.
use drbokeh::dfd::{
    disparity_errors, estimate_disparity, DfdOptions, Highlights, Init, LossTerms, LossWeights,
    Parameterisation, RenderLayer,
};
use drbokeh::eval::report::SceneInputs;
use drbokeh::presets::{ModelOptions, Transfer};
use drbokeh::{Image, Preset, RenderSettings};
use std::collections::HashMap;
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut kv: HashMap<String, String> = HashMap::new();
    let mut scenes = Vec::new();
    for a in &args[1..] {
        if let Some((k, v)) = a.split_once('=') {
            kv.insert(k.into(), v.into());
        } else {
            scenes.push(PathBuf::from(a));
        }
    }
    let get = |k: &str, d: &str| kv.get(k).cloned().unwrap_or(d.to_string());
    let tag = get("tag", "run");
    if get("prof", "0") == "1" {
        let scene = SceneInputs::load(&scenes[0]).unwrap();
        let mut s = RenderSettings::physical(scene.focus);
        s.camera.blur_k = scene.blur_k;
        s.camera.window = drbokeh::Window::auto_unclipped(scene.blur_k + 1.0);
        let stack =
            drbokeh::LayerStack::single(scene.aif.clone(), scene.disparity.clone()).unwrap();
        for _ in 0..2 {
            let t = std::time::Instant::now();
            let out =
                drbokeh::render(&stack, &s, drbokeh::Engine::Fast, &drbokeh::NoProgress).unwrap();
            let t1 = t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            let (_o, tape) = drbokeh::render_with_tape_on(
                &stack,
                &s,
                drbokeh::Engine::Fast,
                &drbokeh::NoProgress,
            )
            .unwrap();
            let t2 = t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            let (_, g) = drbokeh::loss::hssim_grad(&out, &scene.ground_truth).unwrap();
            let t3 = t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            let _ = tape.backward(&g, &drbokeh::NoProgress).unwrap();
            let t4 = t.elapsed().as_secs_f64();
            println!(
                "fast fwd {t1:.3}s, fwd+tape {t2:.3}s, hssim_grad {t3:.3}s, backward {t4:.3}s"
            );
        }
        return;
    }
    if get("probe", "0") == "1" {
        for path in &scenes {
            let scene = SceneInputs::load(path).unwrap();
            let mut s = RenderSettings::physical(scene.focus);
            s.camera.blur_k = scene.blur_k;
            s.camera.window = drbokeh::Window::auto_unclipped(scene.blur_k + 1.0);
            let target = &scene.ground_truth;
            let lossf = |r: &Image<f32>| -> (f64, f64) {
                let c = Image::from_vec(
                    r.width,
                    r.height,
                    3,
                    r.data.iter().map(|v| v.clamp(0.0, 1.0)).collect(),
                )
                .unwrap();
                (
                    drbokeh::loss::l1(&c, target).unwrap() as f64,
                    drbokeh::loss::hssim(&c, target).unwrap() as f64,
                )
            };
            let cam = scene.camera();
            let oracle = drbokeh::baselines::flatten(&scene.layers, &cam).unwrap().0;
            let gt = drbokeh::render(
                &scene.layers,
                &s,
                drbokeh::Engine::Fast,
                &drbokeh::NoProgress,
            )
            .unwrap();
            let o = DfdOptions::new(s.clone(), RenderLayer::DrBokeh);
            let est = estimate_disparity(&scene.aif, target, &o, &mut |_| {})
                .unwrap()
                .disparity;
            let ml: usize = get("layers", "5").parse().unwrap();
            let (l, hs) = lossf(&gt);
            println!("{} true layers: L1 {l:.4} HSSIM {hs:.4}", scene.name);
            for (an, aif) in [("png", &scene.aif), ("oracle", &oracle)] {
                for (dn, d) in [("truth", &scene.disparity), ("est", &est)] {
                    let single =
                        drbokeh::dfd::render_layer(RenderLayer::DrBokeh, aif, d, &s).unwrap();
                    let m = drbokeh::dfd::layered::LayeredModel::decompose(aif, d, ml).unwrap();
                    let lay = m.render(drbokeh::Engine::Fast, aif, d, &s).unwrap();
                    let (a, b) = lossf(&single);
                    let (c, e) = lossf(&lay);
                    println!(
                        "{} aif {an} at {dn}: single L1 {a:.4} HSSIM {b:.4} | layered({}) L1 {c:.4} HSSIM {e:.4}",
                        scene.name,
                        m.layer_count()
                    );
                }
            }
        }
        return;
    }
    let mut maes = Vec::new();
    for path in &scenes {
        let scene = SceneInputs::load(path).unwrap();
        let mut s = RenderSettings::paper(scene.focus);
        s.preset = get("preset", "physical").parse::<Preset>().unwrap();
        if get("srgb", "0") == "1" {
            let mut m: ModelOptions = s.model();
            m.transfer = Transfer::Srgb;
            s = s.with_model(m);
        }
        s.camera.blur_k = scene.blur_k * get("kscale", "1").parse::<f64>().unwrap();
        let layer: RenderLayer = get("layer", "drbokeh").parse().unwrap();
        let mut o = DfdOptions::new(s.clone(), layer);
        o.schedule.coarse_scales = get("coarse", "0").parse().unwrap();
        o.schedule.iterations = get("iters", "150").parse().unwrap();
        o.schedule.finest_scale = kv.get("finest").map(|v| v.parse().unwrap());
        o.schedule.fine_iterations = get("fine", "40").parse().unwrap();
        o.schedule.learning_rate = get("lr", "0.1").parse().unwrap();
        o.schedule.learning_rate_decay = get("decay", "0.7").parse().unwrap();
        o.schedule.patience = get("patience", "10").parse().unwrap();
        o.schedule.min_improvement = get("minimp", "0.001").parse().unwrap();
        o.parameterisation = get("param", "sigmoid").parse::<Parameterisation>().unwrap();
        o.highlights = get("hl", "model").parse::<Highlights>().unwrap();
        o.optimiser = get("opt", "adam").parse().unwrap();
        o.edge_sensitivity = get("edge", "10").parse().unwrap();
        let mr: f64 = get("mrad", "1.5").parse().unwrap();
        o.median = if mr > 0.0 {
            Some(drbokeh::dfd::MedianRefine {
                radius_blur_fraction: mr,
                sigma: get("msig", "0.05").parse().unwrap(),
            })
        } else {
            None
        };
        if let Some(f) = kv.get("ctx") {
            let f: f64 = f.parse().unwrap();
            o.sweep_context = (f > 0.0).then_some(f);
        }
        if get("from_truth", "0") == "1" {
            o.initial_disparity = Some(scene.disparity.clone());
        }
        o.engine = get("engine", "fast").parse().unwrap();
        let nl: usize = get("layers", "0").parse().unwrap();
        if nl > 0 {
            o.layered = Some(drbokeh::dfd::LayeredObjective {
                max_layers: nl,
                every: get("every", "10").parse().unwrap(),
            });
        }
        let init = get("init", "sweep9");
        o.init = if let Some(n) = init.strip_prefix("sweep") {
            Init::Sweep(n.parse().unwrap())
        } else {
            Init::Constant(init.parse().unwrap())
        };
        let (w, terms) = LossWeights::from_terms(&get("losses", "l1,smooth,hssim")).unwrap();
        o.weights = w;
        o.terms = terms;
        if let Some(x) = kv.get("wl1") {
            o.weights.l1 = x.parse().unwrap();
        }
        if let Some(x) = kv.get("wg") {
            o.weights.smoothness = x.parse().unwrap();
        }
        if let Some(x) = kv.get("wh") {
            o.weights.hssim = x.parse().unwrap();
        }
        let _ = LossTerms::Hssim;
        // Oracle: the unclipped all-in-focus image (composite of the true layers).
        let aif = if get("oracle_aif", "0") == "1" {
            let cam = scene.camera();
            drbokeh::baselines::flatten(&scene.layers, &cam).unwrap().0
        } else {
            scene.aif.clone()
        };
        let t0 = std::time::Instant::now();
        let r = estimate_disparity(&aif, &scene.ground_truth, &o, &mut |_| {}).unwrap();
        let secs = t0.elapsed().as_secs_f64();
        let mut v: Vec<f32> = scene.disparity.data.clone();
        v.sort_by(f32::total_cmp);
        let med = v[v.len() / 2];
        let wm_r: usize = get("wmed", "0").parse().unwrap();
        let wm_sigma: f64 = get("wsig", "0.1").parse().unwrap();
        let wm_conf = get("wconf", "0") == "1";
        let est_owned = if wm_r > 0 {
            let (w, h) = (r.disparity.width, r.disparity.height);
            let a = &aif;
            let mut out = r.disparity.clone();
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    let mut v: Vec<(f32, f64)> = Vec::new();
                    for yy in y.saturating_sub(wm_r)..(y + wm_r + 1).min(h) {
                        for xx in x.saturating_sub(wm_r)..(x + wm_r + 1).min(w) {
                            let j = yy * w + xx;
                            let d2: f64 = (0..3)
                                .map(|c| ((a.data[3 * i + c] - a.data[3 * j + c]) as f64).powi(2))
                                .sum::<f64>()
                                / 3.0;
                            let mut wt = (-d2 / (2.0 * wm_sigma * wm_sigma)).exp();
                            if wm_conf {
                                wt *= r.confidence.data[j] as f64 + 0.05;
                            }
                            v.push((r.disparity.data[j], wt));
                        }
                    }
                    v.sort_by(|p, q| p.0.total_cmp(&q.0));
                    let total: f64 = v.iter().map(|p| p.1).sum();
                    let mut acc = 0.0;
                    for p in &v {
                        acc += p.1;
                        if acc >= total / 2.0 {
                            out.data[i] = p.0;
                            break;
                        }
                    }
                }
            }
            out
        } else {
            r.disparity.clone()
        };
        let est = &est_owned;
        let cst = Image::from_vec(est.width, est.height, 1, vec![med; est.data.len()]).unwrap();
        let e = disparity_errors(est, &scene.disparity);
        let c = disparity_errors(&cst, &scene.disparity);
        // fg = not the background layer (last) in truth
        let bg = scene.layers.layers.last().unwrap().disparity.data[0];
        let fg = |i: usize| (scene.disparity.data[i] - bg).abs() > 1e-4;
        let efg = drbokeh::dfd::masked_disparity_errors(est, &scene.disparity, None, fg);
        let ebg = drbokeh::dfd::masked_disparity_errors(est, &scene.disparity, None, |i| !fg(i));
        let conf_mean = r.confidence.data.iter().map(|&v| v as f64).sum::<f64>()
            / r.confidence.data.len() as f64;
        let scales: Vec<String> = r
            .log
            .scales
            .iter()
            .map(|s| {
                format!(
                    "{}:{}it/{:.3}s",
                    s.width, s.iterations, s.seconds_per_iteration
                )
            })
            .collect();
        println!(
            "{tag} {} K {:.1} f {:.2} | MAE {:.3} (fg {:.3} bg {:.3}) const {:.3} | {:.1}s [{}] conf {:.2} clipped {} masked {:.2} loss {:.4}",
            scene.name,
            scene.blur_k,
            scene.focus,
            e.mae,
            efg.map(|x| x.mae).unwrap_or(f64::NAN),
            ebg.map(|x| x.mae).unwrap_or(f64::NAN),
            c.mae,
            secs,
            scales.join(" "),
            conf_mean,
            r.log.clipped_aif_pixels,
            r.log.masked_fraction,
            r.log.scales.last().unwrap().final_loss
        );
        let le = r.log.entries.last().unwrap();
        println!(
            "   terms: l1 {:?} smooth {:?} structure {:?}; first entry of last scale: {:?}",
            le.l1,
            le.smoothness,
            le.structure,
            r.log.entries.iter().find(|x| x.scale == le.scale).map(|x| (
                x.loss,
                x.l1,
                x.smoothness,
                x.structure
            ))
        );
        maes.push((e.mae, c.mae));
        if get("save", "1") == "1" {
            let out = format!(
                "/work/data/dfd/study/{}_{}_{}.png",
                path.parent()
                    .unwrap()
                    .file_name()
                    .unwrap()
                    .to_string_lossy(),
                scene.name,
                tag
            );
            std::fs::create_dir_all("/work/data/dfd/study").unwrap();
            let rgb = Image::from_vec(
                est.width,
                est.height,
                3,
                est.data.iter().flat_map(|&v| [v; 3]).collect(),
            )
            .unwrap();
            drbokeh::io::write_output(
                std::path::Path::new(&out),
                &rgb,
                drbokeh::io::BitDepth::Eight,
                |v| v,
            )
            .unwrap();
        }
        if let Some(p) = kv.get("curve") {
            let f = format!("{p}_{}.json", scene.name);
            std::fs::write(&f, serde_json::to_string(&r.log).unwrap()).unwrap();
        }
    }
    let n = maes.len() as f64;
    println!(
        "{tag} MEAN MAE {:.4} const {:.4} (n={})",
        maes.iter().map(|m| m.0).sum::<f64>() / n,
        maes.iter().map(|m| m.1).sum::<f64>() / n,
        maes.len()
    );
}
