//! Test helpers shared by the loss modules: a deterministic generator and gradient checks.

use crate::Image;

/// A small deterministic generator (SplitMix64) for reproducible random test points.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }

    /// A uniform value in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// An image with values uniform in `[lo, hi)`.
    pub fn image(&mut self, w: usize, h: usize, c: usize, lo: f64, hi: f64) -> Image<f64> {
        let data = (0..w * h * c)
            .map(|_| lo + (hi - lo) * self.uniform())
            .collect();
        Image::from_vec(w, h, c, data).unwrap()
    }
}

/// Compares an analytic gradient with central finite differences of `f` at `x`:
/// on `samples` random components and along one random direction. Fails if a relative
/// error exceeds `1e-4`.
pub fn check_gradient(
    f: &dyn Fn(&Image<f64>) -> f64,
    x: &Image<f64>,
    grad: &Image<f64>,
    samples: usize,
    rng: &mut Rng,
) {
    const H: f64 = 1e-6;
    const TOL: f64 = 1e-4;
    assert_eq!(grad.data.len(), x.data.len());
    let n = x.data.len();
    let gmax = grad.data.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    assert!(gmax > 0.0, "gradient is identically zero");
    for _ in 0..samples {
        let i = ((rng.uniform() * n as f64) as usize).min(n - 1);
        let mut p = x.clone();
        p.data[i] += H;
        let mut m = x.clone();
        m.data[i] -= H;
        let fd = (f(&p) - f(&m)) / (2.0 * H);
        let an = grad.data[i];
        // Relative to the component itself; components far below the gradient's scale
        // are compared relative to 1e-3 of the largest component instead.
        let scale = an.abs().max(1e-3 * gmax);
        assert!(
            (fd - an).abs() <= TOL * scale,
            "component {i}: finite difference {fd:e}, analytic {an:e}"
        );
    }
    // Directional derivative along a random direction.
    let dir: Vec<f64> = (0..n).map(|_| rng.uniform() * 2.0 - 1.0).collect();
    let mut p = x.clone();
    let mut m = x.clone();
    for i in 0..n {
        p.data[i] += H * dir[i];
        m.data[i] -= H * dir[i];
    }
    let fd = (f(&p) - f(&m)) / (2.0 * H);
    let an: f64 = grad.data.iter().zip(&dir).map(|(g, d)| g * d).sum();
    assert!(
        (fd - an).abs() <= TOL * an.abs(),
        "directional derivative: finite difference {fd:e}, analytic {an:e}"
    );
}
