//! Scratch study: a search of whole image segments after `dfd`, judged by a render.
//!
//! `dfd_search judge=layered|single|aperture|gausspsf [segpx=16] [sweeps=2] SCENE...`
//! estimates each scene's disparity with the defaults of the judge's layer, cuts the
//! all-in-focus image into SLIC superpixels, and then, segment by segment, proposes to give
//! a segment the median estimate of each of its neighbours; a proposal is kept where the
//! judge's loss (0.5 L1 + 10 HSSIM of the clamped render against the traced image, on a crop
//! that holds every pixel the change can reach) falls. Prints the MAE before and after, and
//! the judge's loss on the whole image at the start, at the result and at the truth.
//! Options: `src=exr` (the judge renders the unclipped aif.exr: an oracle for the clipped
//! highlights), `from_truth=1` (start at the true disparity), `gain=G` (keep a proposal
//! only if it lowers the loss by a fraction G), `layers=N`, `compact=C`, `mindiff=D`,
//! `save=DIR` (the searched maps as PNG), `matting=PX` (judge=layered: soft alpha at the
//! decomposition's cut edges, `LayeringOptions::matting_px`), `cguard=PX` (judge=layered:
//! hidden colours filled from pixels at least PX from another layer), `pure=PX`
//! (judge=layered: see [`purify`]), `fit=N` (judge=layered: see [`fit_edge_colours`]),
//! `split=N` (judge=layered: see [`Split`]), `pixel=N` (N passes of one-pixel boundary moves
//! after the segment sweeps; `sweeps=0` for these alone), `rounds=R` (R rounds of the
//! searches; with `fit=N` or `split=N` the colours are fitted again at each round's start,
//! so that they belong to the current estimate's cuts, not only to the first estimate's),
//! `colsplit=1` (each round starts with the colour-split region moves of [`regions`];
//! `cstol` the regions' tolerance (negative: -N, the connected pieces of the layers of a
//! decomposition into at most N layers), `csq` the quantile of the values around proposed),
//! `talpha=hard` and
//! `tcolour=fill|aif|aifown`, `recut=1` (judge=truelayers: the true layers degraded towards what
//! a decomposition has; see the comments at `talpha` and `recut`).
mod edges;
mod judge;
mod oracle;
mod regions;
mod search;
mod segments;

use drbokeh::dfd::{
    disparity_errors, estimate_disparity, masked_disparity_errors, DfdOptions, RenderLayer,
};
use drbokeh::eval::report::SceneInputs;
use drbokeh::{Image, RenderSettings};
use judge::Judge;
use search::Search;
use segments::{median, slic, Segments};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn main() {
    let mut kv: HashMap<String, String> = HashMap::new();
    let mut scenes = Vec::new();
    for a in std::env::args().skip(1) {
        if let Some((k, v)) = a.split_once('=') {
            kv.insert(k.into(), v.into());
        } else {
            scenes.push(PathBuf::from(a));
        }
    }
    let get = |k: &str, d: &str| kv.get(k).cloned().unwrap_or(d.to_string());
    let num = |k: &str, d: &str| -> f64 {
        get(k, d)
            .parse()
            .unwrap_or_else(|_| panic!("{k}= takes a number"))
    };
    let judge_kind = get("judge", "layered");
    let segpx = num("segpx", "16") as usize;
    let sweeps = num("sweeps", "2") as usize;
    let compact = num("compact", "0.15") as f32;
    let mindiff = num("mindiff", "0.03") as f32;
    let gain = num("gain", "0.0");
    let layers = num("layers", "5") as usize;
    let fit = num("fit", "0") as usize;
    let split = num("split", "0") as usize;
    let pixel_passes = num("pixel", "0") as usize;
    let rounds = (num("rounds", "1") as usize).max(1);
    let colsplit = get("colsplit", "0") == "1";
    let cstol = num("cstol", "0.05") as f32;
    let csq = num("csq", "0.5") as f32;
    // src=exr: the judge renders the unclipped all-in-focus image (an oracle for the
    // highlights: aif.exr encoded as aif.png is, exact sRGB, but not clipped).
    let src = get("src", "png");
    let est_layer = match judge_kind.as_str() {
        "aperture" => RenderLayer::Aperture,
        "gausspsf" => RenderLayer::GaussPsf,
        _ => RenderLayer::DrBokeh,
    };
    let mut totals = [0f64; 3];
    for path in &scenes {
        let scene = SceneInputs::load(path).unwrap();
        let mut s = RenderSettings::physical(scene.focus);
        s.camera.blur_k = scene.blur_k;
        s.camera.window = drbokeh::Window::auto_unclipped(scene.blur_k + 1.0);
        let target = &scene.ground_truth;
        let truth = &scene.disparity;
        let t0 = std::time::Instant::now();
        // from_truth=1: the search starts at the true disparity (is the truth a local
        // minimum of these moves?).
        let est = if get("from_truth", "0") == "1" {
            truth.clone()
        } else {
            let o = DfdOptions::new(s.clone(), est_layer);
            estimate_disparity(&scene.aif, target, &o, &mut |_| {})
                .unwrap()
                .disparity
        };
        let t_est = t0.elapsed().as_secs_f64();
        let (w, h) = (est.width, est.height);
        let aif: Image<f32> = if src == "exr" {
            // Encoded as the tracer encodes aif.png (exact sRGB), without its clipping.
            let lin: Image<f32> = drbokeh::io::read_rgb(&path.join("aif.exr")).unwrap();
            drbokeh::trace::encode_image(&lin)
        } else {
            scene.aif.clone()
        };
        let mut judge = Judge {
            kind: judge_kind.clone(),
            layer: est_layer,
            settings: s.clone(),
            aif,
            width: w,
            layers,
            matting_px: num("matting", "0") as usize,
            colour_guard_px: num("cguard", "0") as usize,
            pure_px: num("pure", "0") as usize,
            fitted: None,
            split: None,
            truth: (judge_kind == "truelayers").then(|| {
                oracle::TrueLayers::new(
                    &scene,
                    &get("talpha", "true"),
                    &get("tcolour", "true"),
                    get("recut", "0") == "1",
                )
            }),
        };
        let seg = slic(&scene.aif, segpx, compact);
        let segs = Segments::new(&seg, w, h);
        let dmax = est
            .data
            .iter()
            .map(|&v| (v as f64 - scene.focus).abs())
            .fold(0.0, f64::max);
        let reach_px = (scene.blur_k * dmax.max(0.05)).ceil() as usize + 2;
        let mut cur = est.clone();
        let (mut tried, mut kept) = (0, 0);
        let mut losses = (0.0, 0.0, 0.0);
        for round in 0..rounds {
            // The colours are fitted at the round's start, to the current estimate's cuts.
            if fit > 0 || split > 0 {
                let t_fit = std::time::Instant::now();
                judge.fitted = (fit > 0)
                    .then(|| edges::fit_edge_colours(&judge.aif, &cur, target, &s, layers, fit));
                judge.split = (split > 0)
                    .then(|| edges::fit_split(&judge.aif, &cur, target, &s, layers, split));
                println!(
                    "  round {round}: edge colours fitted in {:.1}s",
                    t_fit.elapsed().as_secs_f64()
                );
            }
            let search = Search {
                judge: &judge,
                target,
                reach_px,
                gain,
                mindiff,
            };
            if colsplit {
                let r = regions::colour_split(&search, &scene.aif, &mut cur, cstol, 40, csq);
                println!(
                    "  round {round}: colour split: {} regions, {} proposed, {} kept, MAE {:.4} ({:.0}s)",
                    r.regions,
                    r.proposed,
                    r.kept,
                    disparity_errors(&cur, truth).mae,
                    t0.elapsed().as_secs_f64()
                );
            }
            let (t, k) = search.segments(&mut cur, &segs, sweeps);
            tried += t;
            kept += k;
            if pixel_passes > 0 {
                println!(
                    "  segment search done: MAE {:.4} ({:.0}s)",
                    disparity_errors(&cur, truth).mae,
                    t0.elapsed().as_secs_f64()
                );
                search.pixels(&mut cur, pixel_passes, truth, t0);
            }
            // The round's judge on the whole image at the start, at the search's result
            // and at the true disparity: which of the three the objective ranks first.
            // (The last round's are the ones printed below.)
            losses = (
                judge.whole(&est, target),
                judge.whole(&cur, target),
                judge.whole(truth, target),
            );
            if rounds > 1 {
                println!(
                    "  round {round}: MAE {:.4}, {k} of {t} moves kept, loss start {:.4} now {:.4} truth {:.4} ({:.0}s)",
                    disparity_errors(&cur, truth).mae,
                    losses.0,
                    losses.1,
                    losses.2,
                    t0.elapsed().as_secs_f64()
                );
            }
        }
        let (l_est, l_cur, l_true) = losses;
        println!("  whole-image loss: start {l_est:.4}, search {l_cur:.4}, truth {l_true:.4}");
        let bg = scene.layers.layers.last().unwrap().disparity.data[0];
        let fg = |i: usize| (truth.data[i] - bg).abs() > 1e-4;
        let e0 = disparity_errors(&est, truth);
        let e1 = disparity_errors(&cur, truth);
        let split_mae = |d: &Image<f32>, inside: bool| {
            masked_disparity_errors(d, truth, None, |i| fg(i) == inside).map_or(f64::NAN, |x| x.mae)
        };
        let cst = Image::from_vec(w, h, 1, vec![median(truth.data.clone()); w * h]).unwrap();
        println!(
            "{judge_kind} {}/{} K {:.1} f {:.2} | MAE {:.4} -> {:.4} (fg {:.3} -> {:.3}, bg {:.3} -> {:.3}) const {:.4} | segs {} tried {tried} kept {kept} | est {t_est:.1}s total {:.1}s",
            path.parent().unwrap().file_name().unwrap().to_string_lossy(),
            scene.name,
            scene.blur_k,
            scene.focus,
            e0.mae,
            e1.mae,
            split_mae(&est, true),
            split_mae(&cur, true),
            split_mae(&est, false),
            split_mae(&cur, false),
            disparity_errors(&cst, truth).mae,
            segs.members.len(),
            t0.elapsed().as_secs_f64()
        );
        totals[0] += e0.mae;
        totals[1] += e1.mae;
        totals[2] += 1.0;
        if let Some(dir) = kv.get("save") {
            std::fs::create_dir_all(dir).unwrap();
            let out = format!(
                "{dir}/{}_{}_{judge_kind}.png",
                path.parent()
                    .unwrap()
                    .file_name()
                    .unwrap()
                    .to_string_lossy(),
                scene.name
            );
            let rgb =
                Image::from_vec(w, h, 3, cur.data.iter().flat_map(|&v| [v; 3]).collect()).unwrap();
            drbokeh::io::write_output(Path::new(&out), &rgb, drbokeh::io::BitDepth::Eight, |v| v)
                .unwrap();
        }
    }
    println!(
        "{judge_kind} MEAN MAE {:.4} -> {:.4} (n={})",
        totals[0] / totals[2],
        totals[1] / totals[2],
        totals[2]
    );
}
