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
//! after the segment sweeps; `sweeps=0` for these alone),
//! `talpha=hard` and
//! `tcolour=fill|aif|aifown`, `recut=1` (judge=truelayers: the true layers degraded towards what
//! a decomposition has; see the comments at `talpha` and `recut`).
use drbokeh::dfd::layered::LayeredModel;
use drbokeh::dfd::{
    disparity_errors, estimate_disparity, masked_disparity_errors, render_layer_on, DfdOptions,
    RenderLayer,
};
use drbokeh::eval::report::SceneInputs;
use drbokeh::{Engine, Image, RenderSettings};
use std::collections::{BTreeSet, HashMap};
use std::path::PathBuf;

fn crop(img: &Image<f32>, x0: usize, y0: usize, w: usize, h: usize) -> Image<f32> {
    let c = img.channels;
    let mut data = Vec::with_capacity(w * h * c);
    for y in y0..y0 + h {
        let row = (y * img.width + x0) * c;
        data.extend_from_slice(&img.data[row..row + w * c]);
    }
    Image::from_vec(w, h, c, data).unwrap()
}

/// The values of `values` that differ from `from` and from each other by more than
/// `mindiff`, in order: the moves a search proposes.
fn distinct_moves(from: f32, values: impl Iterator<Item = f32>, mindiff: f32) -> Vec<f32> {
    let mut cands: Vec<f32> = Vec::new();
    for m in values {
        if (m - from).abs() > mindiff && cands.iter().all(|c| (c - m).abs() > mindiff) {
            cands.push(m);
        }
    }
    cands
}

/// SLIC superpixels of an RGB image in [0, 1]; returns one label per pixel, connected.
fn slic(img: &Image<f32>, step: usize, compactness: f32) -> Vec<usize> {
    let (w, h) = (img.width, img.height);
    let mut centres: Vec<[f32; 5]> = Vec::new();
    let mut y = step / 2;
    while y < h {
        let mut x = step / 2;
        while x < w {
            let i = y * w + x;
            centres.push([
                x as f32,
                y as f32,
                img.data[3 * i],
                img.data[3 * i + 1],
                img.data[3 * i + 2],
            ]);
            x += step;
        }
        y += step;
    }
    let mut label = vec![0usize; w * h];
    let s2 = (step * step) as f32;
    let m2 = compactness * compactness;
    for _ in 0..10 {
        let mut best = vec![f32::INFINITY; w * h];
        for (k, c) in centres.iter().enumerate() {
            let (cx, cy) = (c[0] as isize, c[1] as isize);
            let r = step as isize;
            for yy in (cy - r).max(0)..(cy + r + 1).min(h as isize) {
                for xx in (cx - r).max(0)..(cx + r + 1).min(w as isize) {
                    let i = yy as usize * w + xx as usize;
                    let dc: f32 = (0..3)
                        .map(|j| (img.data[3 * i + j] - c[2 + j]).powi(2))
                        .sum();
                    let ds = (xx as f32 - c[0]).powi(2) + (yy as f32 - c[1]).powi(2);
                    let d = dc / m2 + ds / s2;
                    if d < best[i] {
                        best[i] = d;
                        label[i] = k;
                    }
                }
            }
        }
        let mut acc = vec![[0f64; 6]; centres.len()];
        for i in 0..w * h {
            let a = &mut acc[label[i]];
            a[0] += (i % w) as f64;
            a[1] += (i / w) as f64;
            for j in 0..3 {
                a[2 + j] += img.data[3 * i + j] as f64;
            }
            a[5] += 1.0;
        }
        for (c, a) in centres.iter_mut().zip(&acc) {
            if a[5] > 0.0 {
                for j in 0..5 {
                    c[j] = (a[j] / a[5]) as f32;
                }
            }
        }
    }
    // Connected components of the labels; fragments under 8 px join a neighbour.
    let mut comp = vec![usize::MAX; w * h];
    let mut n = 0;
    let mut sizes = Vec::new();
    for s in 0..w * h {
        if comp[s] != usize::MAX {
            continue;
        }
        let mut stack = vec![s];
        comp[s] = n;
        let mut size = 0;
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = (i % w, i / w);
            let mut push = |j: usize| {
                if comp[j] == usize::MAX && label[j] == label[s] {
                    comp[j] = n;
                    stack.push(j);
                }
            };
            if x > 0 {
                push(i - 1);
            }
            if x + 1 < w {
                push(i + 1);
            }
            if y > 0 {
                push(i - w);
            }
            if y + 1 < h {
                push(i + w);
            }
        }
        sizes.push(size);
        n += 1;
    }
    for i in 0..w * h {
        if sizes[comp[i]] < 8 {
            let (x, y) = (i % w, i / w);
            let nb = [
                (x > 0).then(|| i - 1),
                (y > 0).then(|| i - w),
                (x + 1 < w).then(|| i + 1),
                (y + 1 < h).then(|| i + w),
            ];
            if let Some(j) = nb.into_iter().flatten().find(|&j| sizes[comp[j]] >= 8) {
                comp[i] = comp[j];
            }
        }
    }
    comp
}

/// `pure=R`: each layer's colour is made again from its own pixels farther than `R` from
/// any other layer's (the interior, whose colour is not mixed with a neighbour's at a soft
/// edge): on its edge pixels and wherever it is filled in behind nearer layers, by Telea
/// inpainting of the interior. A layer without interior keeps its colours. Alpha stays as
/// the decomposition made it.
fn purify(
    dec: drbokeh::layering::Decomposition<f32>,
    aif: &Image<f32>,
    d: &Image<f32>,
    r: usize,
) -> drbokeh::LayerStack<f32> {
    use drbokeh::layering::Region;
    let (w, h) = (aif.width, aif.height);
    let owner = owner_of(&dec.thresholds, d);
    let edge = edge_mask(&owner, w, h, r);
    let mut layers = dec.stack.layers;
    for (k, layer) in layers.iter_mut().enumerate() {
        // Interior: owned, and no pixel of another layer within r (Chebyshev).
        let interior: Vec<bool> = (0..w * h).map(|i| owner[i] == k && !edge[i]).collect();
        if !interior.iter().any(|&b| b) {
            continue;
        }
        let region: Vec<Region> = interior
            .iter()
            .map(|&b| if b { Region::Known } else { Region::Fill })
            .collect();
        let filled = drbokeh::layering::inpaint_telea(aif, &region, &Default::default());
        for i in 0..w * h {
            if !interior[i] && filled.filled[i] && layer.alpha.data[i] > 0.0 {
                layer.rgb_encoded.data[3 * i..3 * i + 3]
                    .copy_from_slice(&filled.image.data[3 * i..3 * i + 3]);
            }
        }
    }
    drbokeh::LayerStack::new(layers).unwrap()
}

/// Each pixel's owning layer in a decomposition cut at `thresholds` (nearest first).
fn owner_of(thresholds: &[f64], d: &Image<f32>) -> Vec<usize> {
    d.data
        .iter()
        .map(|&v| thresholds.iter().filter(|&&t| (v as f64) < t).count())
        .collect()
}

/// Owned pixels with a pixel of another owner within `r` (Chebyshev): the mixed edge.
fn edge_mask(owner: &[usize], w: usize, h: usize, r: usize) -> Vec<bool> {
    let r = r as isize;
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as isize, (i / w) as isize);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx >= 0
                        && yy >= 0
                        && (xx as usize) < w
                        && (yy as usize) < h
                        && owner[yy as usize * w + xx as usize] != owner[i]
                    {
                        return true;
                    }
                }
            }
            false
        })
        .collect()
}

/// The gradients of the fits' loss (0.5 L1 + 10 HSSIM of the clamped render against
/// `target`) with respect to every layer of `stack`.
fn loss_gradients(
    stack: &drbokeh::LayerStack<f32>,
    s: &RenderSettings,
    target: &Image<f32>,
) -> drbokeh::Gradients<f32> {
    let (r, tape) =
        drbokeh::render_with_tape_on(stack, s, Engine::Fast, &drbokeh::NoProgress).unwrap();
    let c = Image::from_vec(
        r.width,
        r.height,
        3,
        r.data.iter().map(|v| v.clamp(0.0, 1.0)).collect(),
    )
    .unwrap();
    let (_, g1) = drbokeh::loss::l1_grad(&c, target).unwrap();
    let (_, g2) = drbokeh::loss::hssim_grad(&c, target).unwrap();
    let g = Image::from_vec(
        r.width,
        r.height,
        3,
        (0..r.data.len())
            .map(|q| {
                if (0.0..=1.0).contains(&r.data[q]) {
                    0.5 * g1.data[q] + 10.0 * g2.data[q]
                } else {
                    0.0
                }
            })
            .collect(),
    )
    .unwrap();
    tape.backward(&g, &drbokeh::NoProgress).unwrap()
}

/// `fit=N`: the colours of the mixed edge pixels (owned pixels within 1 px of another
/// layer) of the decomposition at `d`, fitted to the defocused image by `iters` Adam steps
/// (learning rate 0.02, encoded colour in [0, 1]) on 0.5 L1 + 10 HSSIM of the clamped
/// render. Returns the edge mask and the fitted colours (full image, RGB).
fn fit_edge_colours(
    aif: &Image<f32>,
    d: &Image<f32>,
    target: &Image<f32>,
    s: &RenderSettings,
    layers: usize,
    iters: usize,
) -> (Vec<bool>, Vec<f32>) {
    let (w, h) = (aif.width, aif.height);
    let opts = drbokeh::layering::LayeringOptions {
        max_layers: layers,
        ..Default::default()
    };
    let dec = drbokeh::layering::layers_from_disparity(aif, d, &opts).unwrap();
    let owner = owner_of(&dec.thresholds, d);
    let edge = edge_mask(&owner, w, h, 1);
    let mut stack = dec.stack;
    let idx: Vec<usize> = (0..w * h).filter(|&i| edge[i]).collect();
    let mut x: Vec<f32> = idx
        .iter()
        .flat_map(|&i| stack.layers[owner[i]].rgb_encoded.data[3 * i..3 * i + 3].to_vec())
        .collect();
    let (mut m, mut v) = (vec![0f32; x.len()], vec![0f32; x.len()]);
    let (b1, b2, lr) = (0.9f32, 0.999f32, 0.02f32);
    for t in 1..=iters {
        for (j, &i) in idx.iter().enumerate() {
            stack.layers[owner[i]].rgb_encoded.data[3 * i..3 * i + 3]
                .copy_from_slice(&x[3 * j..3 * j + 3]);
        }
        let grads = loss_gradients(&stack, s, target);
        let (c1, c2) = (1.0 - b1.powi(t as i32), 1.0 - b2.powi(t as i32));
        for (j, &i) in idx.iter().enumerate() {
            for ch in 0..3 {
                let q = 3 * j + ch;
                let gr = grads.layers[owner[i]].rgb.data[3 * i + ch];
                m[q] = b1 * m[q] + (1.0 - b1) * gr;
                v[q] = b2 * v[q] + (1.0 - b2) * gr * gr;
                x[q] = (x[q] - lr * (m[q] / c1) / ((v[q] / c2).sqrt() + 1e-8)).clamp(0.0, 1.0);
            }
        }
    }
    let mut full = vec![0f32; w * h * 3];
    for (j, &i) in idx.iter().enumerate() {
        full[3 * i..3 * i + 3].copy_from_slice(&x[3 * j..3 * j + 3]);
    }
    (edge, full)
}

/// `split=N`: each mixed edge pixel `i` of the decomposition at the start (owned pixels
/// within 1 px of another layer; no feather) is split between its own surface (coverage
/// `cov`, colour `own`) and the surface of a neighbouring pixel `nb` of another layer
/// (colour `other`), constrained to composite to the all-in-focus colour:
/// `cov own + (1 - cov) other = I`. `cov` (a sigmoid, in [0.02, 0.98]) and `own` are
/// fitted to the defocused image by N Adam steps; `other` follows from the constraint.
struct Split {
    edge: Vec<bool>,
    nb: Vec<usize>,
    cov: Vec<f32>,
    own: Vec<f32>,
}

impl Split {
    fn other(&self, aif: &[f32], g: usize, c: usize) -> f32 {
        let s = self.cov[g];
        ((aif[3 * g + c] - s * self.own[3 * g + c]) / (1.0 - s)).max(0.0)
    }

    /// Writes the split into `stack` (a decomposition of the crop at `x0, y0`, `cw` x `ch`,
    /// of an image `w` wide) whose owners are `own_d`: the nearer of the two owners gets
    /// alpha and its colour, the farther becomes opaque with the other colour, the layers
    /// in front of the farther one turn transparent there. Skipped where the neighbour is
    /// outside the crop or both now have one owner.
    #[allow(clippy::too_many_arguments)]
    fn apply(
        &self,
        stack: &mut drbokeh::LayerStack<f32>,
        own_d: &[usize],
        aif_full: &[f32],
        x0: usize,
        y0: usize,
        cw: usize,
        ch: usize,
        w: usize,
    ) {
        for y in 0..ch {
            for x in 0..cw {
                let (j, g) = (y * cw + x, (y0 + y) * w + x0 + x);
                if !self.edge[g] {
                    continue;
                }
                let nb = self.nb[g];
                let (nx, ny) = (nb % w, nb / w);
                if nx < x0 || ny < y0 || nx >= x0 + cw || ny >= y0 + ch {
                    continue;
                }
                let (o1, o2) = (own_d[j], own_d[(ny - y0) * cw + nx - x0]);
                if o1 == o2 {
                    continue;
                }
                let s = self.cov[g];
                let own: [f32; 3] = std::array::from_fn(|c| self.own[3 * g + c]);
                let oth: [f32; 3] = std::array::from_fn(|c| self.other(aif_full, g, c));
                let (front, back, a, cf, cb) = if o1 < o2 {
                    (o1, o2, s, own, oth)
                } else {
                    (o2, o1, 1.0 - s, oth, own)
                };
                for (k, l) in stack.layers.iter_mut().enumerate() {
                    if k == front {
                        l.alpha.data[j] = a;
                        l.rgb_encoded.data[3 * j..3 * j + 3].copy_from_slice(&cf);
                    } else if k == back {
                        l.alpha.data[j] = 1.0;
                        l.rgb_encoded.data[3 * j..3 * j + 3].copy_from_slice(&cb);
                    } else if k < back {
                        l.alpha.data[j] = 0.0;
                    }
                }
            }
        }
    }
}

fn split_opts(layers: usize) -> drbokeh::layering::LayeringOptions {
    drbokeh::layering::LayeringOptions {
        max_layers: layers,
        feather_px: 0,
        ..Default::default()
    }
}

fn fit_split(
    aif: &Image<f32>,
    d: &Image<f32>,
    target: &Image<f32>,
    s: &RenderSettings,
    layers: usize,
    iters: usize,
) -> Split {
    let (w, h) = (aif.width, aif.height);
    let dec = drbokeh::layering::layers_from_disparity(aif, d, &split_opts(layers)).unwrap();
    let owner = owner_of(&dec.thresholds, d);
    let edge = edge_mask(&owner, w, h, 1);
    // The neighbour of another owner: 4-neighbours first, then diagonals.
    let offs: [(isize, isize); 8] = [
        (1, 0),
        (-1, 0),
        (0, 1),
        (0, -1),
        (1, 1),
        (-1, -1),
        (1, -1),
        (-1, 1),
    ];
    let nb: Vec<usize> = (0..w * h)
        .map(|i| {
            if !edge[i] {
                return i;
            }
            let (x, y) = ((i % w) as isize, (i / w) as isize);
            offs.iter()
                .map(|&(dx, dy)| (x + dx, y + dy))
                .filter(|&(xx, yy)| xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h)
                .map(|(xx, yy)| yy as usize * w + xx as usize)
                .find(|&q| owner[q] != owner[i])
                .unwrap_or(i)
        })
        .collect();
    let edge: Vec<bool> = (0..w * h).map(|i| edge[i] && nb[i] != i).collect();
    let idx: Vec<usize> = (0..w * h).filter(|&i| edge[i]).collect();
    let sig = |u: f32| 0.02 + 0.96 / (1.0 + (-u).exp());
    // Parameters per pixel: u (coverage) and the own colour (3).
    let mut u = vec![2.0f32; idx.len()];
    let mut own: Vec<f32> = idx
        .iter()
        .flat_map(|&i| aif.data[3 * i..3 * i + 3].to_vec())
        .collect();
    let n = 4 * idx.len();
    let (mut m, mut v) = (vec![0f32; n], vec![0f32; n]);
    let (b1, b2, lr) = (0.9f32, 0.999f32, 0.02f32);
    let mut split = Split {
        edge,
        nb,
        cov: vec![0.0; w * h],
        own: vec![0.0; 3 * w * h],
    };
    let base = dec.stack;
    for t in 1..=iters + 1 {
        for (j, &i) in idx.iter().enumerate() {
            split.cov[i] = sig(u[j]);
            split.own[3 * i..3 * i + 3].copy_from_slice(&own[3 * j..3 * j + 3]);
        }
        if t == iters + 1 {
            break;
        }
        let mut stack = base.clone();
        split.apply(&mut stack, &owner, &aif.data, 0, 0, w, h, w);
        let grads = loss_gradients(&stack, s, target);
        let (c1, c2) = (1.0 - b1.powi(t as i32), 1.0 - b2.powi(t as i32));
        let mut step = |q: usize, gr: f32, x: &mut f32| {
            m[q] = b1 * m[q] + (1.0 - b1) * gr;
            v[q] = b2 * v[q] + (1.0 - b2) * gr * gr;
            *x -= lr * (m[q] / c1) / ((v[q] / c2).sqrt() + 1e-8);
        };
        for (j, &i) in idx.iter().enumerate() {
            let (o1, o2) = (owner[i], owner[split.nb[i]]);
            let sv = split.cov[i];
            // The front layer's alpha is cov (own surface in front) or 1 - cov.
            let (front, da_ds) = if o1 < o2 { (o1, 1.0) } else { (o2, -1.0) };
            // The own colour sits in layer o1, the other colour in layer o2.
            let (g_own, g_oth) = (&grads.layers[o1], &grads.layers[o2]);
            let mut ds = da_ds * grads.layers[front].alpha.data[i];
            let mut dp = [0f32; 3];
            for c in 0..3 {
                let ir = aif.data[3 * i + c];
                let p = own[3 * j + c];
                let go = g_oth.rgb.data[3 * i + c];
                ds += go * (ir - p) / ((1.0 - sv) * (1.0 - sv));
                dp[c] = g_own.rgb.data[3 * i + c] - go * sv / (1.0 - sv);
            }
            let du = ds * (sv - 0.02) * (0.98 - sv) / 0.96;
            let mut x = u[j];
            step(4 * j, du, &mut x);
            u[j] = x;
            // Keep both colours in [0, 1]: own in [(I - 1 + s) / s, I / s] (with the new s);
            // where that is empty (an unclipped I above 1), both colours are I.
            let sn = sig(u[j]);
            for c in 0..3 {
                let ir = aif.data[3 * i + c];
                let mut x = own[3 * j + c];
                step(4 * j + 1 + c, dp[c], &mut x);
                let (lo, hi) = (((ir - 1.0 + sn) / sn).max(0.0), (ir / sn).min(1.0));
                own[3 * j + c] = if lo <= hi { x.clamp(lo, hi) } else { ir };
            }
        }
    }
    split
}

fn median(mut v: Vec<f32>) -> f32 {
    v.sort_by(f32::total_cmp);
    v[v.len() / 2]
}

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
    let judge = get("judge", "layered");
    let segpx: usize = get("segpx", "16").parse().unwrap();
    let sweeps: usize = get("sweeps", "2").parse().unwrap();
    let compact: f32 = get("compact", "0.15").parse().unwrap();
    let mindiff: f32 = get("mindiff", "0.03").parse().unwrap();
    let gain: f64 = get("gain", "0.0").parse().unwrap();
    let layers: usize = get("layers", "5").parse().unwrap();
    let matting: usize = get("matting", "0").parse().unwrap();
    let cguard: usize = get("cguard", "0").parse().unwrap();
    let pure: usize = get("pure", "0").parse().unwrap();
    let fit: usize = get("fit", "0").parse().unwrap();
    let split: usize = get("split", "0").parse().unwrap();
    // src=exr: the judge renders the unclipped all-in-focus image (an oracle for the
    // highlights: aif.exr encoded as aif.png is, exact sRGB, but not clipped).
    let src = get("src", "png");
    let est_layer = match judge.as_str() {
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
        let t0 = std::time::Instant::now();
        let o = DfdOptions::new(s.clone(), est_layer);
        // from_truth=1: the search starts at the true disparity (is the truth a local
        // minimum of these moves?).
        let est = if get("from_truth", "0") == "1" {
            scene.disparity.clone()
        } else {
            estimate_disparity(&scene.aif, target, &o, &mut |_| {})
                .unwrap()
                .disparity
        };
        let t_est = t0.elapsed().as_secs_f64();
        let (w, h) = (est.width, est.height);
        // judge=truelayers (an oracle): the scene's true layer stack (true alpha and hidden
        // colours), each pixel's proposed disparity written into the layer that owns it (the
        // billboard whose disparity is the pixel's true disparity); at the true disparity it
        // renders the true layers exactly.
        let owner: Vec<usize> = (0..scene.disparity.data.len())
            .map(|i| {
                let t = scene.disparity.data[i];
                (0..scene.layers.layers.len())
                    .min_by(|&a, &b| {
                        let da = (scene.layers.layers[a].disparity.data[i] - t).abs();
                        let db = (scene.layers.layers[b].disparity.data[i] - t).abs();
                        da.total_cmp(&db)
                    })
                    .unwrap()
            })
            .collect();
        // Degraded oracles, to tell which part of the true layers the truth's minimum needs:
        // `talpha=hard` thresholds each layer's alpha at 1/2 (the last stays opaque), as a
        // decomposition by pixel labels has it; `tcolour=fill` keeps each layer's true
        // colour on the pixels it owns and fills the rest (hidden behind nearer layers) by
        // Telea inpainting of them, as the decomposition guesses hidden colours;
        // `tcolour=aif` also puts the all-in-focus colour (the mix at soft edges) on the
        // owned pixels before the fill, as the decomposition does; `tcolour=aifown` the
        // all-in-focus colour on the owned pixels and the true colours behind them.
        let talpha = get("talpha", "true");
        let tcolour = get("tcolour", "true");
        let nl = scene.layers.layers.len();
        let colours: Vec<Image<f32>> = (0..nl)
            .map(|k| {
                let l = &scene.layers.layers[k];
                if tcolour == "true" {
                    return l.rgb_encoded.clone();
                }
                if tcolour == "aifown" {
                    // The all-in-focus colour on the owned pixels, the true colour elsewhere.
                    let mut c = l.rgb_encoded.clone();
                    for (i, &o) in owner.iter().enumerate() {
                        if o == k {
                            c.data[3 * i..3 * i + 3]
                                .copy_from_slice(&scene.aif.data[3 * i..3 * i + 3]);
                        }
                    }
                    return c;
                }
                let src = if tcolour == "aif" {
                    &scene.aif
                } else {
                    &l.rgb_encoded
                };
                let region: Vec<drbokeh::layering::Region> = owner
                    .iter()
                    .map(|&o| {
                        if o == k {
                            drbokeh::layering::Region::Known
                        } else {
                            drbokeh::layering::Region::Fill
                        }
                    })
                    .collect();
                if !region.contains(&drbokeh::layering::Region::Known) {
                    return l.rgb_encoded.clone();
                }
                drbokeh::layering::inpaint_telea(src, &region, &Default::default()).image
            })
            .collect();
        // `recut=1`: ownership follows the proposal, as in a decomposition cut at the
        // proposed disparity: a pixel whose proposed disparity is nearest another layer's
        // plane moves into that layer (opaque, the all-in-focus colour), and where it moves
        // farther the layers in front of it there turn transparent.
        let recut = get("recut", "0") == "1";
        let stack_at = |d: &Image<f32>, x0: usize, y0: usize| -> drbokeh::LayerStack<f32> {
            let mut layers: Vec<drbokeh::Layer<f32>> = scene
                .layers
                .layers
                .iter()
                .enumerate()
                .map(|(k, l)| {
                    let mut alpha = crop(&l.alpha, x0, y0, d.width, d.height);
                    if talpha == "hard" && k + 1 < nl {
                        for a in &mut alpha.data {
                            *a = if *a >= 0.5 { 1.0 } else { 0.0 };
                        }
                    }
                    drbokeh::Layer {
                        rgb_encoded: crop(&colours[k], x0, y0, d.width, d.height),
                        alpha,
                        disparity: crop(&l.disparity, x0, y0, d.width, d.height),
                    }
                })
                .collect();
            for y in 0..d.height {
                for x in 0..d.width {
                    let (j, g) = (y * d.width + x, (y0 + y) * w + x0 + x);
                    let t = owner[g];
                    let v = d.data[j];
                    let k = if recut {
                        (0..nl)
                            .min_by(|&a, &b| {
                                let da = (scene.layers.layers[a].disparity.data[g] - v).abs();
                                let db = (scene.layers.layers[b].disparity.data[g] - v).abs();
                                da.total_cmp(&db)
                            })
                            .unwrap()
                    } else {
                        t
                    };
                    layers[k].disparity.data[j] = v;
                    if k != t {
                        layers[k].alpha.data[j] = 1.0;
                        for c in 0..3 {
                            layers[k].rgb_encoded.data[3 * j + c] = scene.aif.data[3 * g + c];
                        }
                        for l in layers.iter_mut().take(k).skip(t) {
                            l.alpha.data[j] = 0.0;
                        }
                    }
                }
            }
            drbokeh::LayerStack::new(layers).unwrap()
        };
        let judge_aif: Image<f32> = if src == "exr" {
            // Encoded as the tracer encodes aif.png (exact sRGB), without its clipping.
            let lin: Image<f32> = drbokeh::io::read_rgb(&path.join("aif.exr")).unwrap();
            drbokeh::trace::encode_image(&lin)
        } else {
            scene.aif.clone()
        };
        let t_fit = std::time::Instant::now();
        let fitted = (fit > 0).then(|| fit_edge_colours(&judge_aif, &est, target, &s, layers, fit));
        let splitfit = (split > 0).then(|| fit_split(&judge_aif, &est, target, &s, layers, split));
        if fit > 0 || split > 0 {
            println!(
                "  edge colours fitted in {:.1}s",
                t_fit.elapsed().as_secs_f64()
            );
        }
        // The decomposition `judge=layered` makes (as `LayeredModel::decompose`).
        let plain = drbokeh::layering::LayeringOptions {
            max_layers: layers,
            ..Default::default()
        };
        let lossf = |aif: &Image<f32>,
                     d: &Image<f32>,
                     tg: &Image<f32>,
                     x0: usize,
                     y0: usize|
         -> f64 {
            let r = match judge.as_str() {
                "truelayers" => {
                    drbokeh::render(&stack_at(d, x0, y0), &s, Engine::Fast, &drbokeh::NoProgress)
                        .unwrap()
                }
                "layered" if split > 0 => {
                    let dec = drbokeh::layering::layers_from_disparity(aif, d, &split_opts(layers))
                        .unwrap();
                    let own = owner_of(&dec.thresholds, d);
                    let mut st = dec.stack;
                    splitfit.as_ref().unwrap().apply(
                        &mut st,
                        &own,
                        &judge_aif.data,
                        x0,
                        y0,
                        d.width,
                        d.height,
                        w,
                    );
                    drbokeh::render(&st, &s, Engine::Fast, &drbokeh::NoProgress).unwrap()
                }
                "layered" if fit > 0 => {
                    // The decomposition at the proposal, with the fitted colours on the
                    // pixels of the start's mixed edge, in whichever layer owns them now.
                    let dec = drbokeh::layering::layers_from_disparity(aif, d, &plain).unwrap();
                    let own = owner_of(&dec.thresholds, d);
                    let mut st = dec.stack;
                    let (edge, rgb) = fitted.as_ref().unwrap();
                    for y in 0..d.height {
                        for x in 0..d.width {
                            let (j, g) = (y * d.width + x, (y0 + y) * w + x0 + x);
                            if edge[g] {
                                st.layers[own[j]].rgb_encoded.data[3 * j..3 * j + 3]
                                    .copy_from_slice(&rgb[3 * g..3 * g + 3]);
                            }
                        }
                    }
                    drbokeh::render(&st, &s, Engine::Fast, &drbokeh::NoProgress).unwrap()
                }
                "layered" if pure > 0 => {
                    let dec = drbokeh::layering::layers_from_disparity(aif, d, &plain).unwrap();
                    let st = purify(dec, aif, d, pure);
                    drbokeh::render(&st, &s, Engine::Fast, &drbokeh::NoProgress).unwrap()
                }
                "layered" if matting > 0 || cguard > 0 => {
                    // The decomposition with soft alpha at its cut edges (the photo
                    // pipeline's edge matting) or fills that skip edge pixels, rendered
                    // as it is.
                    let opts = drbokeh::layering::LayeringOptions {
                        max_layers: layers,
                        matting_px: matting,
                        colour_guard_px: cguard,
                        ..Default::default()
                    };
                    let st = drbokeh::layering::layers_from_disparity(aif, d, &opts)
                        .unwrap()
                        .stack;
                    drbokeh::render(&st, &s, Engine::Fast, &drbokeh::NoProgress).unwrap()
                }
                "layered" => LayeredModel::decompose(aif, d, layers)
                    .unwrap()
                    .render(Engine::Fast, aif, d, &s)
                    .unwrap(),
                "single" => {
                    render_layer_on(RenderLayer::DrBokeh, Engine::Fast, aif, d, &s).unwrap()
                }
                _ => render_layer_on(est_layer, Engine::Fast, aif, d, &s).unwrap(),
            };
            let c = Image::from_vec(
                r.width,
                r.height,
                3,
                r.data.iter().map(|v| v.clamp(0.0, 1.0)).collect(),
            )
            .unwrap();
            0.5 * drbokeh::loss::l1(&c, tg).unwrap() as f64
                + 10.0 * drbokeh::loss::hssim(&c, tg).unwrap() as f64
        };
        let seg = slic(&scene.aif, segpx, compact);
        let nseg = seg.iter().max().unwrap() + 1;
        let mut members = vec![Vec::new(); nseg];
        let mut nbrs = vec![BTreeSet::new(); nseg];
        for i in 0..w * h {
            members[seg[i]].push(i);
            let (x, y) = (i % w, i / w);
            if x + 1 < w && seg[i + 1] != seg[i] {
                nbrs[seg[i]].insert(seg[i + 1]);
                nbrs[seg[i + 1]].insert(seg[i]);
            }
            if y + 1 < h && seg[i + w] != seg[i] {
                nbrs[seg[i]].insert(seg[i + w]);
                nbrs[seg[i + w]].insert(seg[i]);
            }
        }
        let mut cur = est.clone();
        let dmax = cur
            .data
            .iter()
            .map(|&v| (v as f64 - scene.focus).abs())
            .fold(0.0, f64::max);
        let reach = (scene.blur_k * dmax.max(0.05)).ceil() as usize + 2;
        // The crop a change of the pixels a..=b (along one axis of length n) can reach, at
        // least 40 px (HSSIM's largest window is 31).
        let grow = |a: usize, b: usize, n: usize| {
            let lo = a.saturating_sub(2 * reach);
            let hi = (b + 2 * reach + 1).min(n);
            let lo = if hi - lo < 40 {
                hi.saturating_sub(40)
            } else {
                lo
            };
            let hi = if hi - lo < 40 { (lo + 40).min(n) } else { hi };
            (lo, hi)
        };
        // The best of `cands` for the pixels `pixels` (all set to one value), judged on the
        // crop every pixel the change can reach lies in; `None` where none lowers the loss
        // by the fraction `gain`. The one move of both searches.
        let best_move = |cur: &Image<f32>, pixels: &[usize], cands: &[f32]| -> Option<f32> {
            if cands.is_empty() {
                return None;
            }
            let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
            for &i in pixels {
                x0 = x0.min(i % w);
                x1 = x1.max(i % w);
                y0 = y0.min(i / w);
                y1 = y1.max(i / w);
            }
            let (cx0, cx1) = grow(x0, x1, w);
            let (cy0, cy1) = grow(y0, y1, h);
            let (cw, ch) = (cx1 - cx0, cy1 - cy0);
            let a = crop(&judge_aif, cx0, cy0, cw, ch);
            let tg = crop(target, cx0, cy0, cw, ch);
            let base_d = crop(cur, cx0, cy0, cw, ch);
            let base = lossf(&a, &base_d, &tg, cx0, cy0);
            let mut best = (base * (1.0 - gain), None);
            for &c in cands {
                let mut d = base_d.clone();
                for &i in pixels {
                    let (x, y) = (i % w - cx0, i / w - cy0);
                    d.data[y * cw + x] = c;
                }
                let l = lossf(&a, &d, &tg, cx0, cy0);
                if l < best.0 {
                    best = (l, Some(c));
                }
            }
            best.1
        };
        let mut kept = 0;
        let mut tried = 0;
        for _ in 0..sweeps {
            for k in 0..nseg {
                if members[k].is_empty() {
                    continue;
                }
                let med = median(members[k].iter().map(|&i| cur.data[i]).collect());
                let cands = distinct_moves(
                    med,
                    nbrs[k]
                        .iter()
                        .map(|&n| median(members[n].iter().map(|&i| cur.data[i]).collect())),
                    mindiff,
                );
                tried += cands.len();
                if let Some(c) = best_move(&cur, &members[k], &cands) {
                    kept += 1;
                    for &i in &members[k] {
                        cur.data[i] = c;
                    }
                }
            }
        }
        // pixel=N: after the segment sweeps, up to N passes of one-pixel moves along the
        // boundaries (a pixel whose 4-neighbour differs by more than `mindiff` is proposed
        // that neighbour's value, kept where the judge's loss on the crop falls), so that
        // a boundary can move a pixel at a time where moving whole segments cannot.
        let pixel_passes: usize = get("pixel", "0").parse().unwrap();
        if pixel_passes > 0 {
            println!(
                "  segment search done: MAE {:.4} ({:.0}s)",
                disparity_errors(&cur, &scene.disparity).mae,
                t0.elapsed().as_secs_f64()
            );
        }
        for pass in 0..pixel_passes {
            let mut moved = 0;
            let mut proposed = 0;
            for i in 0..w * h {
                let (x, y) = (i % w, i / w);
                let nb = [
                    (x > 0).then(|| i - 1),
                    (x + 1 < w).then(|| i + 1),
                    (y > 0).then(|| i - w),
                    (y + 1 < h).then(|| i + w),
                ];
                let cands = distinct_moves(
                    cur.data[i],
                    nb.into_iter().flatten().map(|n| cur.data[n]),
                    mindiff,
                );
                if cands.is_empty() {
                    continue;
                }
                proposed += 1;
                if proposed % 2000 == 0 {
                    eprintln!(
                        "  pixel pass {pass}: {proposed} proposed, {moved} moved, MAE {:.4} ({:.0}s)",
                        disparity_errors(&cur, &scene.disparity).mae,
                        t0.elapsed().as_secs_f64()
                    );
                }
                if let Some(c) = best_move(&cur, &[i], &cands) {
                    moved += 1;
                    cur.data[i] = c;
                }
            }
            let e = disparity_errors(&cur, &scene.disparity);
            println!(
                "  pixel pass {pass}: {proposed} boundary pixels, {moved} moved, MAE {:.4} ({:.0}s)",
                e.mae,
                t0.elapsed().as_secs_f64()
            );
            if moved == 0 {
                break;
            }
        }
        // The judge's loss on the whole image at the start, at the search's result and at
        // the true disparity: which of the three the objective itself ranks first.
        let (l_est, l_cur, l_true) = (
            lossf(&judge_aif, &est, target, 0, 0),
            lossf(&judge_aif, &cur, target, 0, 0),
            lossf(&judge_aif, &scene.disparity, target, 0, 0),
        );
        println!("  whole-image loss: start {l_est:.4}, search {l_cur:.4}, truth {l_true:.4}");
        let bg = scene.layers.layers.last().unwrap().disparity.data[0];
        let fg = |i: usize| (scene.disparity.data[i] - bg).abs() > 1e-4;
        let e0 = disparity_errors(&est, &scene.disparity);
        let e1 = disparity_errors(&cur, &scene.disparity);
        let f0 = masked_disparity_errors(&est, &scene.disparity, None, fg).map(|x| x.mae);
        let f1 = masked_disparity_errors(&cur, &scene.disparity, None, fg).map(|x| x.mae);
        let b0 = masked_disparity_errors(&est, &scene.disparity, None, |i| !fg(i)).map(|x| x.mae);
        let b1 = masked_disparity_errors(&cur, &scene.disparity, None, |i| !fg(i)).map(|x| x.mae);
        let med = median(scene.disparity.data.clone());
        let cst = Image::from_vec(w, h, 1, vec![med; w * h]).unwrap();
        let ec = disparity_errors(&cst, &scene.disparity);
        println!(
            "{judge} {}/{} K {:.1} f {:.2} | MAE {:.4} -> {:.4} (fg {:.3} -> {:.3}, bg {:.3} -> {:.3}) const {:.4} | segs {nseg} tried {tried} kept {kept} | est {t_est:.1}s total {:.1}s",
            path.parent().unwrap().file_name().unwrap().to_string_lossy(),
            scene.name,
            scene.blur_k,
            scene.focus,
            e0.mae,
            e1.mae,
            f0.unwrap_or(f64::NAN),
            f1.unwrap_or(f64::NAN),
            b0.unwrap_or(f64::NAN),
            b1.unwrap_or(f64::NAN),
            ec.mae,
            t0.elapsed().as_secs_f64()
        );
        totals[0] += e0.mae;
        totals[1] += e1.mae;
        totals[2] += 1.0;
        if let Some(dir) = kv.get("save") {
            std::fs::create_dir_all(dir).unwrap();
            let out = format!(
                "{dir}/{}_{}_{judge}.png",
                path.parent()
                    .unwrap()
                    .file_name()
                    .unwrap()
                    .to_string_lossy(),
                scene.name
            );
            let rgb =
                Image::from_vec(w, h, 3, cur.data.iter().flat_map(|&v| [v; 3]).collect()).unwrap();
            drbokeh::io::write_output(
                std::path::Path::new(&out),
                &rgb,
                drbokeh::io::BitDepth::Eight,
                |v| v,
            )
            .unwrap();
        }
    }
    println!(
        "{judge} MEAN MAE {:.4} -> {:.4} (n={})",
        totals[0] / totals[2],
        totals[1] / totals[2],
        totals[2]
    );
}
