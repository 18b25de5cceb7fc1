//! Image-quality metrics on display-encoded images (values nominally in `[0, 1]`, data
//! range 1). All metrics are computed in `f64` whatever the input type.
//!
//! - [`psnr`]: peak signal-to-noise ratio, `+inf` for identical images; use
//!   [`psnr_for_json`] / [`serialize_psnr`] when writing it to JSON.
//! - [`ssim`]: scikit-image's `structural_similarity(gaussian_weights=True, sigma=1.5,
//!   use_sample_covariance=False, data_range=1, channel_axis=-1)`, via the one SSIM
//!   implementation in [`crate::loss::ssim`](mod@crate::loss::ssim).
//! - [`ms_ssim`]: multi-scale SSIM (Wang, Simoncelli & Bovik 2003).
//! - [`error_map`]: per-pixel absolute error, averaged over channels.

use crate::loss::check_same_shape;
use crate::loss::pyramid::avg_pool2;
use crate::loss::ssim::{self as ssim_core, SsimWindow};
use crate::{Error, Image, Real, Result};

/// The MS-SSIM scale weights of Wang et al. (2003), finest scale first.
pub const MS_SSIM_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];

/// The smallest side accepted by [`ms_ssim`]: four halvings must leave at least one pixel.
pub const MS_SSIM_MIN_SIDE: usize = 1 << (MS_SSIM_WEIGHTS.len() - 1);

/// Checks two images for a metric: same shape, well formed, all values finite.
fn check_pair<T: Real>(a: &Image<T>, b: &Image<T>) -> Result<()> {
    check_same_shape("first image", a, "second image", b)?;
    a.check_finite("first image")?;
    b.check_finite("second image")
}

/// Peak signal-to-noise ratio for data range 1: `10 log10(1 / MSE)` in dB, with the MSE
/// taken over all values. Identical images give `f64::INFINITY`.
///
/// Fails if the shapes differ or a value is not finite.
pub fn psnr<T: Real>(a: &Image<T>, b: &Image<T>) -> Result<f64> {
    check_pair(a, b)?;
    let sum: f64 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(&p, &q)| {
            let d = p.f64() - q.f64();
            d * d
        })
        .sum();
    let mse = sum / a.data.len() as f64;
    if mse == 0.0 {
        return Ok(f64::INFINITY);
    }
    Ok(-10.0 * mse.log10())
}

/// A PSNR for JSON: `Some(psnr)` when finite, `None` (written as `null`) for the
/// `+inf` of identical images, or a NaN. JSON has no infinity, and a large sentinel number
/// could be mistaken for a measurement, so "no finite value" is `null`.
pub fn psnr_for_json(psnr: f64) -> Option<f64> {
    psnr.is_finite().then_some(psnr)
}

/// A serde `serialize_with` helper writing a PSNR field as [`psnr_for_json`] does
/// (`null` for identical images):
///
/// ```
/// #[derive(serde::Serialize)]
/// struct Row {
///     #[serde(serialize_with = "drbokeh::eval::metrics::serialize_psnr")]
///     psnr: f64,
/// }
/// let json = serde_json::to_string(&Row { psnr: f64::INFINITY }).unwrap();
/// assert_eq!(json, r#"{"psnr":null}"#);
/// ```
pub fn serialize_psnr<S: serde::Serializer>(
    psnr: &f64,
    serializer: S,
) -> std::result::Result<S::Ok, S::Error> {
    serde::Serialize::serialize(&psnr_for_json(*psnr), serializer)
}

/// SSIM as scikit-image computes it with `gaussian_weights=True, sigma=1.5,
/// use_sample_covariance=False, data_range=1, channel_axis=-1`: an 11-tap Gaussian
/// (`sigma = 1.5`, truncated at `int(3.5 * 1.5 + 0.5) = 5` pixels), reflect borders, the
/// 5-pixel border cropped before the mean, then the mean over channels. This is
/// [`crate::loss::ssim::ssim`] with [`SsimWindow::skimage_default`].
///
/// Fails if the shapes differ, a value is not finite, or a side is shorter than 11 pixels
/// (scikit-image refuses those too).
pub fn ssim<T: Real>(a: &Image<T>, b: &Image<T>) -> Result<f64> {
    check_pair(a, b)?;
    ssim_core::ssim(
        &a.cast::<f64>(),
        &b.cast::<f64>(),
        &SsimWindow::skimage_default(),
    )
}

/// Multi-scale SSIM (Wang, Simoncelli & Bovik 2003) over 5 scales:
/// `prod_{j<4} cs_j^{w_j} * ssim_4^{w_4}` with the weights [`MS_SSIM_WEIGHTS`], where at
/// scale `j` (scale 0 is the input, each next scale a 2x2 average pool of the previous,
/// dropping an odd last row/column) `cs_j` is the mean contrast-structure term
/// `(2 vxy + C2) / (vx + vy + C2)` and `ssim_4` the mean SSIM at the coarsest scale, both
/// with the same 11-tap `sigma = 1.5` reflect-border Gaussian window as [`ssim`] and
/// averaged over channels. Negative means are clamped to 0 before the power (as in common
/// implementations), so the result is in `[0, 1]`.
///
/// Borders and small images: at a scale whose sides are both at least 11 pixels, the
/// 5-pixel border is cropped before the mean, as in [`ssim`]; at a smaller scale the window
/// does not fit, so nothing is cropped and the mean runs over all pixels of that scale
/// (the reflect borders keep the maps defined everywhere). Images must be at least
/// [`MS_SSIM_MIN_SIDE`] (16) pixels per side so that the coarsest scale is non-empty; every
/// scale is fully cropped only from 176 pixels per side.
///
/// Fails if the shapes differ, a value is not finite, or a side is shorter than 16 pixels.
pub fn ms_ssim<T: Real>(a: &Image<T>, b: &Image<T>) -> Result<f64> {
    check_pair(a, b)?;
    if a.width < MS_SSIM_MIN_SIDE || a.height < MS_SSIM_MIN_SIDE {
        return Err(Error::input(
            "MS-SSIM",
            format!(
                "images of {}x{} are too small for 5 scales (need at least {MS_SSIM_MIN_SIDE}x{MS_SSIM_MIN_SIDE})",
                a.width, a.height
            ),
        ));
    }
    let window = SsimWindow::skimage_default();
    let mut x = a.cast::<f64>();
    let mut y = b.cast::<f64>();
    let mut value = 1.0;
    let last = MS_SSIM_WEIGHTS.len() - 1;
    for (j, &weight) in MS_SSIM_WEIGHTS.iter().enumerate() {
        if j > 0 {
            x = avg_pool2(&x)?;
            y = avg_pool2(&y)?;
        }
        let crop = if x.width.min(x.height) >= window.size() {
            window.radius()
        } else {
            0
        };
        let parts = ssim_core::ssim_parts::<f64>(&x, &y, &window, crop, false);
        let term = if j == last { parts.ssim } else { parts.cs };
        value *= term.max(0.0).powf(weight);
    }
    Ok(value)
}

/// The per-pixel error map: `mean_c |a(x, y, c) - b(x, y, c)|`, a one-channel image.
///
/// Fails if the shapes differ or an image is malformed.
pub fn error_map<T: Real>(a: &Image<T>, b: &Image<T>) -> Result<Image<T>> {
    check_same_shape("first image", a, "second image", b)?;
    let c = a.channels;
    let inv_c = T::c(1.0 / c as f64);
    let data = a
        .data
        .chunks_exact(c)
        .zip(b.data.chunks_exact(c))
        .map(|(p, q)| {
            p.iter()
                .zip(q)
                .fold(T::zero(), |acc, (&u, &v)| acc + (u - v).abs())
                * inv_c
        })
        .collect();
    Image::from_vec(a.width, a.height, 1, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize, c: usize, scale: f64) -> Image<f64> {
        let data = (0..w * h * c)
            .map(|i| scale * ((i * 37) % 101) as f64 / 100.0)
            .collect();
        Image::from_vec(w, h, c, data).unwrap()
    }

    #[test]
    fn psnr_values_and_json() {
        let a = Image::from_vec(2, 1, 1, vec![0.5f32, 0.5]).unwrap();
        let b = Image::from_vec(2, 1, 1, vec![0.6f32, 0.4]).unwrap();
        // MSE = 0.01 (to f32 rounding) -> 20 dB.
        assert!((psnr(&a, &b).unwrap() - 20.0).abs() < 1e-5);
        assert_eq!(psnr(&a, &a).unwrap(), f64::INFINITY);
        assert_eq!(psnr_for_json(f64::INFINITY), None);
        assert_eq!(psnr_for_json(f64::NAN), None);
        assert_eq!(psnr_for_json(31.5), Some(31.5));
        let mut nan = a.clone();
        nan.data[0] = f32::NAN;
        assert!(psnr(&nan, &a).is_err());
        assert!(psnr(&a, &Image::new(1, 2, 1)).is_err());
    }

    #[test]
    fn ssim_and_ms_ssim_bounds() {
        let a = ramp(24, 20, 3, 1.0);
        assert!((ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
        assert!((ms_ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
        let mut b = a.clone();
        for (i, v) in b.data.iter_mut().enumerate() {
            *v = 0.9 * *v + 0.1 * ((i % 5) as f64 / 4.0);
        }
        let mut c = a.clone();
        for (i, v) in c.data.iter_mut().enumerate() {
            *v = 0.5 * *v + 0.5 * ((i % 5) as f64 / 4.0);
        }
        let (sb, sc) = (ssim(&a, &b).unwrap(), ssim(&a, &c).unwrap());
        assert!(sb < 1.0 && sc < sb, "{sb} {sc}");
        let (mb, mc) = (ms_ssim(&a, &b).unwrap(), ms_ssim(&a, &c).unwrap());
        assert!(mb < 1.0 && mc < mb && mc >= 0.0, "{mb} {mc}");
        assert!(ssim(&ramp(10, 20, 1, 1.0), &ramp(10, 20, 1, 1.0)).is_err());
        assert!(ms_ssim(&ramp(15, 40, 1, 1.0), &ramp(15, 40, 1, 1.0)).is_err());
        assert!(ms_ssim(&ramp(16, 16, 1, 1.0), &ramp(16, 16, 1, 0.5)).is_ok());
    }

    #[test]
    fn error_map_is_channel_mean_of_absolute_error() {
        let a = Image::from_vec(2, 1, 2, vec![0.0f64, 1.0, 0.5, 0.5]).unwrap();
        let b = Image::from_vec(2, 1, 2, vec![1.0f64, 0.0, 0.25, 1.0]).unwrap();
        let e = error_map(&a, &b).unwrap();
        assert_eq!((e.width, e.height, e.channels), (2, 1, 1));
        assert_eq!(e.data, vec![1.0, 0.375]);
        assert!(error_map(&a, &Image::new(2, 1, 1)).is_err());
    }
}
