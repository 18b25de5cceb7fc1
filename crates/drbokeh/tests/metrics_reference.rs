//! Metrics and SSIM losses against independent reference values.
//!
//! The constants below were computed by `tools/reference_values.py` (scikit-image 0.26.0,
//! scipy 1.17.1, numpy 2.4.6, Python 3.11) on images generated from the same formulas as
//! [`pattern`], [`perturbed`], [`grey_pattern`] and [`grey_perturbed`] here. In short:
//!
//! ```python
//! from skimage.metrics import structural_similarity, peak_signal_noise_ratio
//! ssim = structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
//!     use_sample_covariance=False, data_range=1.0, channel_axis=-1)
//! psnr = peak_signal_noise_ratio(a, b, data_range=1.0)
//! ```
//!
//! `SSIM_K*` (the loss windows: k taps, sigma = k/6) use the same skimage call with
//! `sigma=k/6, win_size=k`, but with `skimage.metrics._structural_similarity.gaussian`
//! replaced by `scipy.ndimage.gaussian_filter(im, sigma, mode='reflect', radius=(k-1)//2)`,
//! because skimage hard-codes `truncate=3.5` (radius 6, not 5, for sigma = 11/6).
//! `SSIM_SKIMAGE_SIGMA_11_6` is the unpatched call with `sigma=11/6` (skimage's own 13-tap
//! window). `MS_SSIM` comes from a numpy/scipy implementation of the definition documented
//! in `drbokeh::eval::metrics::ms_ssim` (skimage has no MS-SSIM). The Python script is not
//! run by the tests.

use drbokeh::eval::metrics;
use drbokeh::loss::{self, SsimWindow};
use drbokeh::Image;

const SSIM_RGB_40X34: f64 = 0.9647031674042573;
const SSIM_GREY_23X19: f64 = 0.8959014565333655;
const PSNR_RGB_40X34: f64 = 21.58798066130511;
const PSNR_GREY_23X19: f64 = 17.306076184575176;
const SSIM_SKIMAGE_SIGMA_11_6_RGB_40X34: f64 = 0.9630582181059951;
const SSIM_K3_RGB_40X34: f64 = 0.9638399118457097;
const SSIM_K5_RGB_40X34: f64 = 0.9675107358875715;
const SSIM_K11_RGB_40X34: f64 = 0.9631308484225634;
const SSIM_K21_RGB_40X34: f64 = 0.9573004676389111;
const SSIM_K31_RGB_40X34: f64 = 0.9560529430518926;
const HSSIM_RGB_40X34: f64 = 0.19216509315335173;
const MS_SSIM_RGB_64X48: f64 = 0.6243720517239894;

/// Agreement required with the Python references (f64). Observed: about 1e-14 (the
/// summation order differs between numpy and this crate).
const TOL: f64 = 1e-12;

fn image(w: usize, h: usize, c: usize, f: impl Fn(usize, usize, usize) -> f64) -> Image<f64> {
    let mut img = Image::new(w, h, c);
    for y in 0..h {
        for x in 0..w {
            for ch in 0..c {
                *img.at_mut(x, y, ch) = f(x, y, ch);
            }
        }
    }
    img
}

/// `((7x + 13y + 5c) mod 17) / 16`.
fn pattern(w: usize, h: usize, c: usize) -> Image<f64> {
    image(w, h, c, |x, y, ch| {
        ((x * 7 + y * 13 + ch * 5) % 17) as f64 / 16.0
    })
}

/// `0.8 a + 0.2 (0.5 + 0.4 sin(0.37x + 0.23y + 1.1c))`.
fn perturbed(w: usize, h: usize, c: usize) -> Image<f64> {
    let a = pattern(w, h, c);
    image(w, h, c, |x, y, ch| {
        let s = 0.5 + 0.4 * (0.37 * x as f64 + 0.23 * y as f64 + 1.1 * ch as f64).sin();
        0.8 * a.at(x, y, ch) + 0.2 * s
    })
}

/// `((x^2 + 3y^2 + 5xy) mod 29) / 28`, one channel.
fn grey_pattern(w: usize, h: usize) -> Image<f64> {
    image(w, h, 1, |x, y, _| {
        ((x * x + 3 * y * y + 5 * x * y) % 29) as f64 / 28.0
    })
}

/// `0.7 g + 0.3 ((5x + 3y) mod 7) / 6`.
fn grey_perturbed(w: usize, h: usize) -> Image<f64> {
    let g = grey_pattern(w, h);
    image(w, h, 1, |x, y, _| {
        0.7 * g.at(x, y, 0) + 0.3 * ((5 * x + 3 * y) % 7) as f64 / 6.0
    })
}

fn assert_close(name: &str, got: f64, want: f64) {
    assert!(
        (got - want).abs() <= TOL,
        "{name}: got {got:.17}, reference {want:.17} (diff {:e})",
        got - want
    );
}

#[test]
fn ssim_matches_scikit_image() {
    let (a, b) = (pattern(40, 34, 3), perturbed(40, 34, 3));
    assert_close("SSIM rgb", metrics::ssim(&a, &b).unwrap(), SSIM_RGB_40X34);
    let (ga, gb) = (grey_pattern(23, 19), grey_perturbed(23, 19));
    assert_close(
        "SSIM grey",
        metrics::ssim(&ga, &gb).unwrap(),
        SSIM_GREY_23X19,
    );
    // f32 inputs are computed in f64 after conversion: only the input rounding differs.
    let s32 = metrics::ssim(&a.cast::<f32>(), &b.cast::<f32>()).unwrap();
    assert!((s32 - SSIM_RGB_40X34).abs() < 1e-6, "{s32}");
}

#[test]
fn psnr_matches_scikit_image() {
    let (a, b) = (pattern(40, 34, 3), perturbed(40, 34, 3));
    assert_close("PSNR rgb", metrics::psnr(&a, &b).unwrap(), PSNR_RGB_40X34);
    let (ga, gb) = (grey_pattern(23, 19), grey_perturbed(23, 19));
    assert_close(
        "PSNR grey",
        metrics::psnr(&ga, &gb).unwrap(),
        PSNR_GREY_23X19,
    );
    assert_eq!(metrics::psnr(&a, &a).unwrap(), f64::INFINITY);
}

#[test]
fn loss_ssim_at_11_with_sigma_1_5_is_the_metric() {
    let (a, b) = (pattern(40, 34, 3), perturbed(40, 34, 3));
    let window = SsimWindow::new(5, 1.5).unwrap();
    let (v, _) = loss::ssim_grad(&a, &b, &window).unwrap();
    assert_eq!(v, metrics::ssim(&a, &b).unwrap());
    assert_eq!(loss::ssim(&a, &b, &window).unwrap(), v);
}

#[test]
fn skimage_window_for_sigma_11_over_6() {
    // skimage's own window for sigma = 11/6 is 13 taps (radius int(3.5 * 11/6 + 0.5) = 6).
    let (a, b) = (pattern(40, 34, 3), perturbed(40, 34, 3));
    let window = SsimWindow::skimage(11.0 / 6.0).unwrap();
    assert_eq!(window.size(), 13);
    assert_close(
        "SSIM skimage sigma 11/6",
        loss::ssim(&a, &b, &window).unwrap(),
        SSIM_SKIMAGE_SIGMA_11_6_RGB_40X34,
    );
}

#[test]
fn loss_windows_and_hssim_match_references() {
    let (a, b) = (pattern(40, 34, 3), perturbed(40, 34, 3));
    let refs = [
        (3, SSIM_K3_RGB_40X34),
        (5, SSIM_K5_RGB_40X34),
        (11, SSIM_K11_RGB_40X34),
        (21, SSIM_K21_RGB_40X34),
        (31, SSIM_K31_RGB_40X34),
    ];
    for (k, want) in refs {
        let got = loss::ssim(&a, &b, &SsimWindow::sized(k).unwrap()).unwrap();
        assert_close(&format!("SSIM_{k}"), got, want);
    }
    assert_close("HSSIM", loss::hssim(&a, &b).unwrap(), HSSIM_RGB_40X34);
    let (h, _) = loss::hssim_grad(&a, &b).unwrap();
    assert_close("HSSIM (grad path)", h, HSSIM_RGB_40X34);
    // The k = 11 loss window (sigma 11/6) differs from both skimage windows.
    assert!((SSIM_K11_RGB_40X34 - SSIM_RGB_40X34).abs() > 1e-4);
    assert!((SSIM_K11_RGB_40X34 - SSIM_SKIMAGE_SIGMA_11_6_RGB_40X34).abs() > 1e-5);
}

#[test]
fn ms_ssim_matches_numpy_reference() {
    let (a, b) = (pattern(64, 48, 3), perturbed(64, 48, 3));
    assert_close(
        "MS-SSIM",
        metrics::ms_ssim(&a, &b).unwrap(),
        MS_SSIM_RGB_64X48,
    );
}
