//! Shared test helpers: a deterministic RNG and random layer stacks.
#![allow(dead_code)]

use drbokeh::{
    render_with_tape_on, Aperture, Engine, Gradients, Image, Layer, LayerGradients, LayerStack,
    NoProgress, Real, RenderSettings, Window,
};

/// SplitMix64: tiny, deterministic, good enough for test data.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.f64()
    }
}

/// A random stack: `n` layers, front first, with partial alpha (some exact zeros and ones),
/// smooth-ish disparity per layer (front layers nearer), random colours; last layer opaque.
pub fn random_stack<T: Real>(seed: u64, w: usize, h: usize, n: usize) -> LayerStack<T> {
    let mut rng = Rng(seed);
    let layers = (0..n)
        .map(|l| {
            let base = 0.9 - 0.8 * l as f64 / (n.max(2) - 1) as f64;
            let (gx, gy) = (rng.range(-0.02, 0.02), rng.range(-0.02, 0.02));
            let mut rgb = Image::new(w, h, 3);
            let mut alpha = Image::new(w, h, 1);
            let mut disp = Image::new(w, h, 1);
            for y in 0..h {
                for x in 0..w {
                    for c in 0..3 {
                        *rgb.at_mut(x, y, c) = T::c(rng.f64());
                    }
                    let a = if l == n - 1 {
                        1.0
                    } else {
                        match rng.next_u64() % 4 {
                            0 => 0.0,
                            1 => 1.0,
                            _ => rng.f64(),
                        }
                    };
                    *alpha.at_mut(x, y, 0) = T::c(a);
                    let d = base + gx * x as f64 + gy * y as f64 + rng.range(-0.03, 0.03);
                    *disp.at_mut(x, y, 0) = T::c(d.clamp(0.0, 1.0));
                }
            }
            Layer {
                rgb_encoded: rgb,
                alpha,
                disparity: disp,
            }
        })
        .collect();
    LayerStack::new(layers).unwrap()
}

/// `paper` settings with focus, blur K, window size L and aperture.
pub fn settings(focus: f64, k: f64, window: usize, aperture: Aperture) -> RenderSettings {
    let mut s = RenderSettings::paper(focus);
    s.camera.blur_k = k;
    s.camera.window = Window::from_size(window).unwrap();
    s.aperture = aperture;
    s
}

/// Everything a tape yields, as bits: the forward output, then every layer's colour, alpha
/// and disparity gradient, then the blur and focus gradients (for exact comparisons of
/// schedules and thread counts).
pub fn tape_bits(
    stack: &LayerStack<f32>,
    s: &RenderSettings,
    engine: Engine,
    grad_output: &Image<f32>,
) -> (Vec<u32>, u64, u64) {
    let (out, tape) = render_with_tape_on(stack, s, engine, &NoProgress).unwrap();
    let r = tape.backward(grad_output, &NoProgress).unwrap();
    let mut bits: Vec<u32> = out.data.iter().map(|v| v.to_bits()).collect();
    for l in &r.layers {
        bits.extend(
            l.rgb
                .data
                .iter()
                .chain(&l.alpha.data)
                .chain(&l.disparity.data)
                .map(|v| v.to_bits()),
        );
    }
    (bits, r.blur_k.to_bits(), r.focus.to_bits())
}

/// Renders `stack` on `engine` with a tape and back-propagates `g`: every gradient, in f64.
pub fn tape_gradients<T: Real>(
    stack: &LayerStack<T>,
    s: &RenderSettings,
    g: &Image<T>,
    engine: Engine,
) -> Gradients<f64> {
    let (_, tape) = render_with_tape_on(stack, s, engine, &NoProgress).unwrap();
    assert_eq!(tape.engine(), engine);
    let r = tape.backward(g, &NoProgress).unwrap();
    Gradients {
        layers: r
            .layers
            .iter()
            .map(|l| LayerGradients {
                rgb: l.rgb.cast(),
                alpha: l.alpha.cast(),
                disparity: l.disparity.cast(),
            })
            .collect(),
        blur_k: r.blur_k,
        focus: r.focus,
    }
}

/// Two layers: a front layer of patchy alpha (exact zeros and ones) at disparity 0.95, and
/// a background out of focus (0.95) in its first 128 rows and near focus below, its
/// disparities spread by 0.7 across the columns: at K 5 that spread needs more
/// interpolation points than the span engine takes, so `auto` renders those band-layers
/// with taps and the others with spans.
pub fn mixed_stack<T: Real>(w: usize, h: usize) -> LayerStack<T> {
    let mut front = Layer::<f64>::constant(w, h, [0.9, 0.4, 0.1], 0.0, 0.95);
    let mut back = Layer::<f64>::constant(w, h, [0.0; 3], 1.0, 0.5);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            front.alpha.data[i] = (((x / 6 + y / 9) % 4) as f64 / 3.0).min(1.0);
            for c in 0..3 {
                back.rgb_encoded.data[3 * i + c] = ((x / 5 + y / 7 + c) % 3) as f64 / 2.0;
            }
            back.disparity.data[i] = if y < 128 {
                0.95
            } else {
                0.15 + 0.7 * x as f64 / w as f64
            };
        }
    }
    LayerStack::new(vec![front, back]).unwrap().cast()
}

/// Output weights for a vector-Jacobian product: a `w x h` RGB image, uniform in [-1, 1),
/// from `seed`.
pub fn random_weights(seed: u64, w: usize, h: usize) -> Image<f64> {
    let mut rng = Rng(seed);
    let data = (0..w * h * 3).map(|_| rng.range(-1.0, 1.0)).collect();
    Image::from_vec(w, h, 3, data).unwrap()
}

/// Every gradient of `g` as `(name, values)`: per layer rgb, alpha and disparity, then K
/// and focus.
pub fn gradient_kinds(g: &Gradients<f64>) -> Vec<(String, Vec<f64>)> {
    let mut out = Vec::new();
    for (l, lg) in g.layers.iter().enumerate() {
        out.push((format!("layer {l} rgb"), lg.rgb.data.clone()));
        out.push((format!("layer {l} alpha"), lg.alpha.data.clone()));
        out.push((format!("layer {l} disparity"), lg.disparity.data.clone()));
    }
    out.push(("K".into(), vec![g.blur_k]));
    out.push(("focus".into(), vec![g.focus]));
    out
}

/// The largest magnitude in `v` (0 for none).
pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// The largest difference between `a` and `b`, element by element.
pub fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}
