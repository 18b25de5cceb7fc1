//! L1 loss: the mean absolute difference between a prediction and a target.

use super::check::check_same_shape;
use crate::{Image, Real, Result};

/// Mean absolute difference `(1/n) sum_i |pred_i - target_i|`, where the mean runs over
/// **all** `n = width * height * channels` values (not a per-pixel sum, not per channel).
///
/// Fails if the images differ in shape or are malformed.
pub fn l1<T: Real>(pred: &Image<T>, target: &Image<T>) -> Result<T> {
    check_same_shape("L1 prediction", pred, "L1 target", target)?;
    let sum: f64 = pred
        .data
        .iter()
        .zip(&target.data)
        .map(|(&p, &t)| (p - t).abs().f64())
        .sum();
    Ok(T::c(sum / pred.data.len() as f64))
}

/// [`l1`] and its gradient with respect to `pred`: `sign(pred_i - target_i) / n`, with the
/// subgradient 0 where `pred_i == target_i`.
pub fn l1_grad<T: Real>(pred: &Image<T>, target: &Image<T>) -> Result<(T, Image<T>)> {
    let value = l1(pred, target)?;
    let inv_n = T::c(1.0 / pred.data.len() as f64);
    let data = pred
        .data
        .iter()
        .zip(&target.data)
        .map(|(&p, &t)| {
            let d = p - t;
            if d > T::zero() {
                inv_n
            } else if d < T::zero() {
                -inv_n
            } else {
                T::zero()
            }
        })
        .collect();
    let grad = Image {
        width: pred.width,
        height: pred.height,
        channels: pred.channels,
        data,
    };
    Ok((value, grad))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::testutil::{check_gradient, Rng};

    #[test]
    fn value_is_mean_over_all_values() {
        let a = Image::from_vec(2, 1, 2, vec![0.0f64, 1.0, 2.0, 3.0]).unwrap();
        let b = Image::from_vec(2, 1, 2, vec![1.0f64, 1.0, 0.0, 3.5]).unwrap();
        // |−1| + 0 + 2 + 0.5 = 3.5 over 4 values.
        assert_eq!(l1(&a, &b).unwrap(), 0.875);
        let (v, g) = l1_grad(&a, &b).unwrap();
        assert_eq!(v, 0.875);
        assert_eq!(g.data, vec![-0.25, 0.0, 0.25, -0.25]);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let mut rng = Rng::new(11);
        let target = rng.image(9, 7, 3, 0.0, 1.0);
        // Keep every |pred - target| >= 0.01, far from the kink at equality.
        let mut pred = target.clone();
        for v in &mut pred.data {
            let step = 0.01 + 0.3 * rng.uniform();
            *v += if rng.uniform() < 0.5 { step } else { -step };
        }
        let (_, grad) = l1_grad(&pred, &target).unwrap();
        let f = |p: &Image<f64>| l1(p, &target).unwrap();
        check_gradient(&f, &pred, &grad, 40, &mut rng);
    }

    #[test]
    fn rejects_mismatched_shapes() {
        let a = Image::<f32>::new(4, 4, 3);
        let b = Image::<f32>::new(4, 4, 1);
        assert!(l1(&a, &b).is_err());
        assert!(l1_grad(&a, &b).is_err());
        let mut bad = Image::<f32>::new(4, 4, 3);
        bad.data.pop();
        assert!(l1(&bad, &a).is_err());
    }
}
