//! Scratch study: how well confidence maps rank the pixels of `dfd`'s estimate by their
//! error on benchmark scenes (`docs/dfd.md`, section "Confidence").
//!
//! `dfd_confidence [layer=physical|aperture|gausspsf] [cache=DIR] SCENE_DIR...` runs `dfd`
//! with the defaults once per scene and layer (the estimate and its sensitivity map cached
//! in `cache`, default `/work/data/dfd/conf/cache2`), then scores the sensitivity map, the
//! occlusion band at a grid of scales, and their product, by the MAE of the most confident
//! half and the area under the sparsification curve.
use drbokeh::dfd::benchmark::{DfdLayer, DfdScene, LossCombo};
use drbokeh::dfd::confidence::{occlusion_band, sparsification, OcclusionBand};
use drbokeh::dfd::{estimate_disparity, DfdOptions, RenderLayer};
use drbokeh::RenderSettings;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn read_cache(p: &Path, n: usize) -> Option<(Vec<f64>, Vec<f64>)> {
    let b = std::fs::read(p).ok()?;
    if b.len() != 8 * n {
        return None;
    }
    let v: Vec<f64> = b
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
        .collect();
    Some((v[..n].to_vec(), v[n..].to_vec()))
}

fn main() {
    let mut layer = "physical".to_string();
    let mut cache = PathBuf::from("/work/data/dfd/conf/cache2");
    let mut grid = "1:0.1".to_string();
    let mut scenes = Vec::new();
    let mut refine: Option<(f64, f64, f64)> = None;
    let mut refined: Vec<f64> = Vec::new();
    for a in std::env::args().skip(1) {
        match a.split_once('=') {
            Some(("layer", v)) => layer = v.into(),
            Some(("cache", v)) => cache = v.into(),
            Some(("grid", v)) => grid = v.into(),
            Some(("refine", v)) => {
                let f: Vec<f64> = v.split(':').map(|x| x.parse().unwrap()).collect();
                refine = Some((f[0], f[1], f[2]));
            }
            Some((k, _)) => panic!("unknown option {k}"),
            None => scenes.push(PathBuf::from(a)),
        }
    }
    let bands: Vec<OcclusionBand> = grid
        .split(',')
        .map(|s| {
            let (r, t) = s.split_once(':').expect("grid=reach:step,...");
            OcclusionBand {
                reach: r.parse().unwrap(),
                step: t.parse().unwrap(),
            }
        })
        .collect();
    let dlayer = match layer.as_str() {
        "physical" => DfdLayer::Physical,
        "aperture" => DfdLayer::Aperture,
        "gausspsf" => DfdLayer::GaussPsf,
        o => panic!("unknown layer {o}"),
    };
    std::fs::create_dir_all(&cache).unwrap();
    let template = DfdOptions::new(RenderSettings::physical(1.0), RenderLayer::DrBokeh);
    // name -> per scene (mae_half, ause, ause_flat)
    let mut table: BTreeMap<String, Vec<(f64, f64, f64)>> = BTreeMap::new();
    let mut maes = Vec::new();
    for dir in &scenes {
        let scene = DfdScene::load(dir).unwrap();
        let i = &scene.inputs;
        let (w, h) = (i.aif.width, i.aif.height);
        let n = w * h;
        let key = format!(
            "{}_{}_{}.bin",
            dir.parent().unwrap().file_name().unwrap().to_string_lossy(),
            i.name,
            layer
        );
        let (est, sens) = match read_cache(&cache.join(&key), n) {
            Some(c) => c,
            None => {
                // As `dfd-eval` runs it (`benchmark::run_method`), keeping the sensitivity.
                let (render_layer, preset) = dlayer.layer_and_preset();
                let mut o = template.clone();
                o.settings = scene.settings(preset);
                o.settings.camera.gamma = template.settings.camera.gamma;
                o.layer = render_layer;
                let (w8, terms) = LossCombo::L1GHssim.weights(template.weights);
                (o.weights, o.terms) = (w8, terms);
                let r = estimate_disparity(&i.aif, &i.ground_truth, &o, &mut |_| {}).unwrap();
                let (est, conf) = (r.disparity, r.sensitivity);
                let bytes: Vec<u8> = est
                    .data
                    .iter()
                    .chain(conf.data.iter())
                    .flat_map(|v| v.to_le_bytes())
                    .collect();
                std::fs::write(cache.join(&key), bytes).unwrap();
                (
                    est.data.iter().map(|&v| v as f64).collect(),
                    conf.data.iter().map(|&v| v as f64).collect(),
                )
            }
        };
        let err: Vec<f64> = est
            .iter()
            .zip(&i.disparity.data)
            .map(|(e, t)| (e - *t as f64).abs())
            .collect();
        let mae = err.iter().sum::<f64>() / n as f64;
        maes.push(mae);
        let mut line = format!("{key} K {:.1} f {:.0} MAE {mae:.4} |", i.blur_k, i.focus);
        let mut add = |name: String, c: &[f64]| {
            let s = sparsification(&err, c);
            line += &format!(" {name} {:.4}/{:.4}", s.mae_confident_half, s.ause);
            table.entry(name).or_default().push((
                s.mae_confident_half,
                s.ause,
                s.ause_uninformative,
            ));
        };
        add("sens".into(), &sens);
        for b in &bands {
            let band = occlusion_band(&est, w, h, i.blur_k, i.focus, *b);
            add(format!("band{}:{}", b.reach, b.step), &band);
            let prod: Vec<f64> = band.iter().zip(&sens).map(|(a, b)| a * b).collect();
            add(format!("band{}:{}*sens", b.reach, b.step), &prod);
        }
        if let Some((rf, sig, floor)) = refine {
            let band = occlusion_band(&est, w, h, i.blur_k, i.focus, OcclusionBand::DEFAULT);
            let reach = (rf * i.blur_k * i.focus.max(1.0 - i.focus)).ceil() as isize;
            let aif: Vec<f64> = i.aif.data.iter().map(|&v| v as f64).collect();
            let stride = if reach > 12 { 2 } else { 1 };
            let out: Vec<f64> = (0..n)
                .map(|p| {
                    if band[p] >= 1.0 {
                        return est[p];
                    }
                    let (x, y) = ((p % w) as isize, (p / w) as isize);
                    let mut v: Vec<(f64, f64)> = Vec::new();
                    let mut yy = (y - reach).max(0);
                    while yy < (y + reach + 1).min(h as isize) {
                        let mut xx = (x - reach).max(0);
                        while xx < (x + reach + 1).min(w as isize) {
                            let q = yy as usize * w + xx as usize;
                            let d2: f64 = (0..3)
                                .map(|c| (aif[3 * p + c] - aif[3 * q + c]).powi(2))
                                .sum::<f64>()
                                / 3.0;
                            let wt = (-d2 / (2.0 * sig * sig)).exp() * (band[q] + floor);
                            v.push((est[q], wt));
                            xx += stride;
                        }
                        yy += stride;
                    }
                    v.sort_by(|a, b| a.0.total_cmp(&b.0));
                    let total: f64 = v.iter().map(|p| p.1).sum();
                    let mut acc = 0.0;
                    for e in &v {
                        acc += e.1;
                        if acc >= total / 2.0 {
                            return e.0;
                        }
                    }
                    est[p]
                })
                .collect();
            let mae2 = out
                .iter()
                .zip(&i.disparity.data)
                .map(|(e, t)| (e - *t as f64).abs())
                .sum::<f64>()
                / n as f64;
            line += &format!(" REFINED {mae2:.4}");
            refined.push(mae2);
        }
        println!("{line}");
    }
    let k = maes.len() as f64;
    println!(
        "MEAN over {} scenes: MAE {:.4}",
        maes.len(),
        maes.iter().sum::<f64>() / k
    );
    if !refined.is_empty() {
        println!("REFINED MEAN {:.4}", refined.iter().sum::<f64>() / k);
    }
    for (name, v) in &table {
        let m = |f: fn(&(f64, f64, f64)) -> f64| v.iter().map(f).sum::<f64>() / k;
        println!(
            "  {name:>20}: MAE most confident half {:.4}  AUSE {:.4}  (uninformative {:.4})",
            m(|x| x.0),
            m(|x| x.1),
            m(|x| x.2)
        );
    }
}
