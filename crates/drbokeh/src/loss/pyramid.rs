//! 2x2 average pooling (one image-pyramid step) and its adjoint.

use super::check::check_image;
use crate::{Error, Image, Real, Result};

/// Halves an image by 2x2 average pooling, per channel: output pixel `(x, y)` is the mean
/// of input pixels `(2x..2x+1, 2y..2y+1)`. The output is `floor(w/2) x floor(h/2)`: for an
/// odd width or height the last column or row is dropped.
///
/// Fails if the image is malformed or narrower or shorter than 2 pixels.
pub fn avg_pool2<T: Real>(img: &Image<T>) -> Result<Image<T>> {
    check_image("pooled image", img)?;
    if img.width < 2 || img.height < 2 {
        return Err(Error::input(
            "pooled image",
            format!(
                "{}x{} is too small to halve (needs at least 2x2)",
                img.width, img.height
            ),
        ));
    }
    let (w, h, c) = (img.width / 2, img.height / 2, img.channels);
    let quarter = T::c(0.25);
    let mut out = Image::new(w, h, c);
    for y in 0..h {
        for x in 0..w {
            for ch in 0..c {
                let s = img.at(2 * x, 2 * y, ch)
                    + img.at(2 * x + 1, 2 * y, ch)
                    + img.at(2 * x, 2 * y + 1, ch)
                    + img.at(2 * x + 1, 2 * y + 1, ch);
                *out.at_mut(x, y, ch) = s * quarter;
            }
        }
    }
    Ok(out)
}

/// The adjoint of [`avg_pool2`]: spreads a gradient on the pooled image (`grad`) back onto
/// an input of size `width x height` (a quarter to each of the four source pixels; zero on
/// a dropped odd last row or column).
///
/// Fails if `grad` is malformed or is not the pooled size of `width x height`.
pub fn avg_pool2_adjoint<T: Real>(
    grad: &Image<T>,
    width: usize,
    height: usize,
) -> Result<Image<T>> {
    check_image("pooled gradient", grad)?;
    if grad.width != width / 2 || grad.height != height / 2 {
        return Err(Error::input(
            "pooled gradient",
            format!(
                "is {}x{}, but pooling {width}x{height} gives {}x{}",
                grad.width,
                grad.height,
                width / 2,
                height / 2
            ),
        ));
    }
    let c = grad.channels;
    let quarter = T::c(0.25);
    let mut out = Image::new(width, height, c);
    for y in 0..grad.height {
        for x in 0..grad.width {
            for ch in 0..c {
                let g = grad.at(x, y, ch) * quarter;
                *out.at_mut(2 * x, 2 * y, ch) = g;
                *out.at_mut(2 * x + 1, 2 * y, ch) = g;
                *out.at_mut(2 * x, 2 * y + 1, ch) = g;
                *out.at_mut(2 * x + 1, 2 * y + 1, ch) = g;
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::testutil::Rng;

    #[test]
    fn pools_and_drops_odd_edge() {
        let img = Image::from_vec(3, 2, 1, vec![1.0f64, 3.0, 100.0, 5.0, 7.0, 100.0]).unwrap();
        let p = avg_pool2(&img).unwrap();
        assert_eq!((p.width, p.height), (1, 1));
        assert_eq!(p.data, vec![4.0]);
        assert!(avg_pool2(&Image::<f64>::new(1, 4, 1)).is_err());
    }

    #[test]
    fn adjoint_satisfies_dot_product_identity() {
        let mut rng = Rng::new(3);
        let x = rng.image(7, 6, 2, -1.0, 1.0);
        let g = rng.image(3, 3, 2, -1.0, 1.0);
        let px = avg_pool2(&x).unwrap();
        let ag = avg_pool2_adjoint(&g, 7, 6).unwrap();
        let lhs: f64 = px.data.iter().zip(&g.data).map(|(a, b)| a * b).sum();
        let rhs: f64 = x.data.iter().zip(&ag.data).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-12, "{lhs} vs {rhs}");
        assert!(avg_pool2_adjoint(&g, 8, 8).is_err());
    }
}
