//! The decomposition's mixed edge pixels and the ways the study makes their colours
//! purer: `pure` (inpainted from the interior), `fit` (free colours fitted to the defocused
//! image), `split` (each pixel split between two surfaces that composite to the
//! all-in-focus colour, fitted to the defocused image).
use drbokeh::{Engine, Image, RenderSettings};

/// `pure=R`: each layer's colour is made again from its own pixels farther than `R` from
/// any other layer's (the interior, whose colour is not mixed with a neighbour's at a soft
/// edge): on its edge pixels and wherever it is filled in behind nearer layers, by Telea
/// inpainting of the interior. A layer without interior keeps its colours. Alpha stays as
/// the decomposition made it.
pub fn purify(
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
pub fn owner_of(thresholds: &[f64], d: &Image<f32>) -> Vec<usize> {
    d.data
        .iter()
        .map(|&v| thresholds.iter().filter(|&&t| (v as f64) < t).count())
        .collect()
}

/// The decomposition of `aif` cut at the disparity `d` (its stack) and each pixel's owning
/// layer in it.
pub fn cut(
    aif: &Image<f32>,
    d: &Image<f32>,
    opts: &drbokeh::layering::LayeringOptions,
) -> (drbokeh::LayerStack<f32>, Vec<usize>) {
    let dec = drbokeh::layering::layers_from_disparity(aif, d, opts).unwrap();
    let owner = owner_of(&dec.thresholds, d);
    (dec.stack, owner)
}

/// Adam (beta 0.9 / 0.999, learning rate 0.02) over `n` parameters: the fits' optimiser.
struct Adam {
    m: Vec<f32>,
    v: Vec<f32>,
    c1: f32,
    c2: f32,
}

impl Adam {
    const B1: f32 = 0.9;
    const B2: f32 = 0.999;
    const LR: f32 = 0.02;

    fn new(n: usize) -> Self {
        Adam {
            m: vec![0.0; n],
            v: vec![0.0; n],
            c1: 1.0,
            c2: 1.0,
        }
    }

    /// Starts step `t` (from 1): the moments' bias corrections.
    fn begin(&mut self, t: usize) {
        self.c1 = 1.0 - Self::B1.powi(t as i32);
        self.c2 = 1.0 - Self::B2.powi(t as i32);
    }

    /// Moves parameter `q`, value `x`, along its gradient `g`.
    fn step(&mut self, q: usize, g: f32, x: &mut f32) {
        self.m[q] = Self::B1 * self.m[q] + (1.0 - Self::B1) * g;
        self.v[q] = Self::B2 * self.v[q] + (1.0 - Self::B2) * g * g;
        *x -= Self::LR * (self.m[q] / self.c1) / ((self.v[q] / self.c2).sqrt() + 1e-8);
    }
}

/// Owned pixels with a pixel of another owner within `r` (Chebyshev): the mixed edge.
pub fn edge_mask(owner: &[usize], w: usize, h: usize, r: usize) -> Vec<bool> {
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
pub fn loss_gradients(
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
pub fn fit_edge_colours(
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
    let (mut stack, owner) = cut(aif, d, &opts);
    let edge = edge_mask(&owner, w, h, 1);
    let idx: Vec<usize> = (0..w * h).filter(|&i| edge[i]).collect();
    let mut x: Vec<f32> = idx
        .iter()
        .flat_map(|&i| stack.layers[owner[i]].rgb_encoded.data[3 * i..3 * i + 3].to_vec())
        .collect();
    let mut adam = Adam::new(x.len());
    for t in 1..=iters {
        for (j, &i) in idx.iter().enumerate() {
            stack.layers[owner[i]].rgb_encoded.data[3 * i..3 * i + 3]
                .copy_from_slice(&x[3 * j..3 * j + 3]);
        }
        let grads = loss_gradients(&stack, s, target);
        adam.begin(t);
        for (j, &i) in idx.iter().enumerate() {
            for ch in 0..3 {
                let q = 3 * j + ch;
                adam.step(q, grads.layers[owner[i]].rgb.data[3 * i + ch], &mut x[q]);
                x[q] = x[q].clamp(0.0, 1.0);
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
pub struct Split {
    pub edge: Vec<bool>,
    pub nb: Vec<usize>,
    pub cov: Vec<f32>,
    pub own: Vec<f32>,
}

impl Split {
    pub fn other(&self, aif: &[f32], g: usize, c: usize) -> f32 {
        let s = self.cov[g];
        ((aif[3 * g + c] - s * self.own[3 * g + c]) / (1.0 - s)).max(0.0)
    }

    /// Writes the split into `stack` (a decomposition of the crop at `x0, y0`, `cw` x `ch`,
    /// of an image `w` wide) whose owners are `own_d`: the nearer of the two owners gets
    /// alpha and its colour, the farther becomes opaque with the other colour, the layers
    /// in front of the farther one turn transparent there. Skipped where the neighbour is
    /// outside the crop or both now have one owner.
    #[allow(clippy::too_many_arguments)]
    pub fn apply(
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

pub fn split_opts(layers: usize) -> drbokeh::layering::LayeringOptions {
    drbokeh::layering::LayeringOptions {
        max_layers: layers,
        feather_px: 0,
        ..Default::default()
    }
}

pub fn fit_split(
    aif: &Image<f32>,
    d: &Image<f32>,
    target: &Image<f32>,
    s: &RenderSettings,
    layers: usize,
    iters: usize,
) -> Split {
    let (w, h) = (aif.width, aif.height);
    let (base, owner) = cut(aif, d, &split_opts(layers));
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
    let mut adam = Adam::new(n);
    let mut split = Split {
        edge,
        nb,
        cov: vec![0.0; w * h],
        own: vec![0.0; 3 * w * h],
    };
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
        adam.begin(t);
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
            adam.step(4 * j, du, &mut x);
            u[j] = x;
            // Keep both colours in [0, 1]: own in [(I - 1 + s) / s, I / s] (with the new s);
            // where that is empty (an unclipped I above 1), both colours are I.
            let sn = sig(u[j]);
            for c in 0..3 {
                let ir = aif.data[3 * i + c];
                let mut x = own[3 * j + c];
                adam.step(4 * j + 1 + c, dp[c], &mut x);
                let (lo, hi) = (((ir - 1.0 + sn) / sn).max(0.0), (ir / sn).min(1.0));
                own[3 * j + c] = if lo <= hi { x.clamp(lo, hi) } else { ir };
            }
        }
    }
    split
}
