//! Deterministic random numbers and stratified sample patterns.
//!
//! Every pixel draws its samples from its own generator, seeded from the render seed and
//! the pixel's index alone, so the result does not depend on threads, tiles or shards.

/// Mixes 64 bits (the SplitMix64 finaliser).
#[inline]
pub fn mix64(mut x: u64) -> u64 {
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Hashes a sequence of words to one 64-bit value.
pub fn hash_words(words: &[u64]) -> u64 {
    let mut h = 0x243F_6A88_85A3_08D3u64;
    for &w in words {
        h = mix64(h ^ w.wrapping_add(0x9E37_79B9_7F4A_7C15));
    }
    h
}

/// A small, fast, deterministic generator (SplitMix64).
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator seeded from a sequence of words (e.g. seed, purpose, pixel index).
    pub fn from_words(words: &[u64]) -> Self {
        Rng(hash_words(words))
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Uniform integer in [0, n) (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }
}

/// Maps the unit square to the unit disc preserving strata (Shirley-Chiu concentric map).
#[inline]
pub fn concentric_disc(u: f64, v: f64) -> (f64, f64) {
    let a = 2.0 * u - 1.0;
    let b = 2.0 * v - 1.0;
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, std::f64::consts::FRAC_PI_4 * (b / a))
    } else {
        (
            b,
            std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (a / b),
        )
    };
    (r * phi.cos(), r * phi.sin())
}

/// The side `n` of an `n x n` stratification with `n^2 = spp`, if `spp` is a perfect square.
pub fn strata_side(spp: usize) -> Option<usize> {
    let n = (spp as f64).sqrt().round() as usize;
    (n >= 1 && n * n == spp).then_some(n)
}

/// Fills `pixel` with jittered positions in the unit square (one per cell of an `n x n`
/// grid) and `pupil` with jittered points on the unit disc (also one per grid cell, mapped
/// concentrically), then pairs them by a random permutation (padded 2-D stratification).
pub fn stratified_pattern(
    rng: &mut Rng,
    n: usize,
    pixel: &mut Vec<(f64, f64)>,
    pupil: &mut Vec<(f64, f64)>,
) {
    pixel.clear();
    pupil.clear();
    let inv = 1.0 / n as f64;
    for j in 0..n {
        for i in 0..n {
            pixel.push((
                (i as f64 + rng.uniform()) * inv,
                (j as f64 + rng.uniform()) * inv,
            ));
            let (u, v) = (
                (i as f64 + rng.uniform()) * inv,
                (j as f64 + rng.uniform()) * inv,
            );
            pupil.push(concentric_disc(u, v));
        }
    }
    for k in (1..pupil.len()).rev() {
        let m = rng.below(k + 1);
        pupil.swap(k, m);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pattern_is_stratified_and_on_disc() {
        let mut rng = Rng::from_words(&[1, 2]);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        stratified_pattern(&mut rng, 4, &mut a, &mut b);
        assert_eq!(a.len(), 16);
        for (k, &(x, y)) in a.iter().enumerate() {
            assert_eq!((x * 4.0) as usize, k % 4);
            assert_eq!((y * 4.0) as usize, k / 4);
        }
        assert!(b.iter().all(|&(x, y)| x * x + y * y <= 1.0 + 1e-12));
        // Equal-area map: the mean squared radius of the disc is 1/2.
        let mut rng = Rng::from_words(&[3]);
        stratified_pattern(&mut rng, 64, &mut a, &mut b);
        let m2 = b.iter().map(|&(x, y)| x * x + y * y).sum::<f64>() / b.len() as f64;
        assert!((m2 - 0.5).abs() < 1e-3, "{m2}");
        assert_eq!(strata_side(1024), Some(32));
        assert_eq!(strata_side(1000), None);
    }
}
