//! Scratch study: how well confidence maps rank the pixels of `dfd`'s estimate by their
//! error on benchmark scenes (`docs/dfd.md`, section "Confidence").
//!
//! `dfd_confidence [layer=physical|aperture|gausspsf] [cache=DIR] SCENE_DIR...` runs `dfd`
//! with the defaults once per scene and layer (the estimate and its sensitivity map cached
//! in `cache`, default `/work/data/dfd/conf/cache2`), then scores the sensitivity map, the
//! occlusion band at a grid of scales, and their product, by the MAE of the most confident
//! half and the area under the sparsification curve. `refine=R:S:F` refills the band's
//! pixels by a confidence x colour weighted median; `prop=L:S:P[:sens|band|both]` fills the
//! estimate by weighted least squares (data weight the chosen map to the power P, colour-
//! aware smoothness L with colour sigma S) (`docs/dfd.md`, "Confidence" and "Small blurs").
use drbokeh::dfd::benchmark::{method_options, DfdLayer, DfdScene, LossCombo};
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
    let mut prop: Option<(f64, f64, f64, String)> = None;
    let mut propagated: Vec<f64> = Vec::new();
    for a in std::env::args().skip(1) {
        match a.split_once('=') {
            Some(("layer", v)) => layer = v.into(),
            Some(("cache", v)) => cache = v.into(),
            Some(("grid", v)) => grid = v.into(),
            Some(("refine", v)) => {
                let f: Vec<f64> = v.split(':').map(|x| x.parse().unwrap()).collect();
                refine = Some((f[0], f[1], f[2]));
            }
            Some(("prop", v)) => {
                let f: Vec<&str> = v.split(':').collect();
                prop = Some((
                    f[0].parse().unwrap(),
                    f[1].parse().unwrap(),
                    f[2].parse().unwrap(),
                    f.get(3).unwrap_or(&"sens").to_string(),
                ));
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
                let o = method_options(&scene, dlayer, LossCombo::L1GHssim, &template);
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
        let mae_of = |map: &[f64]| -> f64 {
            map.iter()
                .zip(&i.disparity.data)
                .map(|(e, t)| (e - *t as f64).abs())
                .sum::<f64>()
                / n as f64
        };
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
            let mae2 = mae_of(&out);
            line += &format!(" REFINED {mae2:.4}");
            refined.push(mae2);
        }
        if let Some((lambda, sig, pow, ref wt)) = prop {
            let aif: Vec<f64> = i.aif.data.iter().map(|&v| v as f64).collect();
            let band = occlusion_band(&est, w, h, i.blur_k, i.focus, OcclusionBand::DEFAULT);
            let c: Vec<f64> = (0..n)
                .map(|p| match wt.as_str() {
                    "sens" => sens[p].powf(pow),
                    "band" => band[p].powf(pow),
                    _ => (sens[p] * band[p]).powf(pow),
                })
                .collect();
            let out = propagate(&est, &c, &aif, w, h, lambda, sig);
            let mae2 = mae_of(&out);
            line += &format!(" PROP {mae2:.4}");
            propagated.push(mae2);
        }
        println!("{line}");
    }
    if !propagated.is_empty() {
        println!(
            "PROPAGATED MEAN {:.4}",
            propagated.iter().sum::<f64>() / propagated.len() as f64
        );
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

/// Weighted least squares fill: minimises sum_p c_p (d_p - e_p)^2 + lambda sum_{p~q} w_pq
/// (d_p - d_q)^2 over 4-neighbours, w_pq = exp(-|I_p - I_q|^2 / (2 sig^2)) (mean over
/// channels), by conjugate gradients with a diagonal preconditioner.
fn propagate(
    e: &[f64],
    c: &[f64],
    aif: &[f64],
    w: usize,
    h: usize,
    lambda: f64,
    sig: f64,
) -> Vec<f64> {
    let n = w * h;
    let wt = |p: usize, q: usize| {
        let d2: f64 = (0..3)
            .map(|k| (aif[3 * p + k] - aif[3 * q + k]).powi(2))
            .sum::<f64>()
            / 3.0;
        lambda * (-d2 / (2.0 * sig * sig)).exp()
    };
    // right (x+1) and down (y+1) edge weights
    let mut wr = vec![0.0; n];
    let mut wd = vec![0.0; n];
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            if x + 1 < w {
                wr[p] = wt(p, p + 1);
            }
            if y + 1 < h {
                wd[p] = wt(p, p + w);
            }
        }
    }
    let diag: Vec<f64> = (0..n)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            let mut s = c[p] + wr[p] + wd[p];
            if x > 0 {
                s += wr[p - 1];
            }
            if y > 0 {
                s += wd[p - w];
            }
            s.max(1e-12)
        })
        .collect();
    let apply = |v: &[f64], out: &mut [f64]| {
        for p in 0..n {
            let (x, y) = (p % w, p / w);
            let mut s = diag[p] * v[p];
            if x + 1 < w {
                s -= wr[p] * v[p + 1];
            }
            if y + 1 < h {
                s -= wd[p] * v[p + w];
            }
            if x > 0 {
                s -= wr[p - 1] * v[p - 1];
            }
            if y > 0 {
                s -= wd[p - w] * v[p - w];
            }
            out[p] = s;
        }
    };
    let b: Vec<f64> = (0..n).map(|p| c[p] * e[p]).collect();
    let mut x = e.to_vec();
    let mut ax = vec![0.0; n];
    apply(&x, &mut ax);
    let mut r: Vec<f64> = (0..n).map(|p| b[p] - ax[p]).collect();
    let mut z: Vec<f64> = (0..n).map(|p| r[p] / diag[p]).collect();
    let mut d = z.clone();
    let mut rz: f64 = (0..n).map(|p| r[p] * z[p]).sum();
    let b2: f64 = b.iter().map(|v| v * v).sum::<f64>().max(1e-30);
    let mut ad = vec![0.0; n];
    for _ in 0..2000 {
        apply(&d, &mut ad);
        let alpha = rz / (0..n).map(|p| d[p] * ad[p]).sum::<f64>();
        for p in 0..n {
            x[p] += alpha * d[p];
            r[p] -= alpha * ad[p];
        }
        if r.iter().map(|v| v * v).sum::<f64>() < 1e-12 * b2 {
            break;
        }
        for p in 0..n {
            z[p] = r[p] / diag[p];
        }
        let rz2: f64 = (0..n).map(|p| r[p] * z[p]).sum();
        let beta = rz2 / rz;
        rz = rz2;
        for p in 0..n {
            d[p] = z[p] + beta * d[p];
        }
    }
    x.iter().map(|v| v.clamp(0.0, 1.0)).collect()
}
