#!/usr/bin/env python3
"""Reference values for crates/drbokeh/tests/metrics_reference.rs.

Computes PSNR / SSIM with scikit-image (and MS-SSIM with numpy + scipy.ndimage) on small
deterministic images that the Rust test regenerates from the same formulas, and prints the
numbers as Rust constants. The Rust tests never run this script; it documents where the
embedded constants came from.

    pip install scikit-image numpy
    python3 tools/reference_values.py

Produced with scikit-image 0.26.0, scipy 1.17.1, numpy 2.4.6 (Python 3.11).
"""

import math

import numpy as np
import scipy.ndimage as ndi
import skimage
from skimage.metrics import _structural_similarity as skssim
from skimage.metrics import peak_signal_noise_ratio, structural_similarity


# ---- the deterministic inputs (mirrored exactly in the Rust test) ---------------------------


def pattern(w, h, c):
    """a(x, y, c) = ((7x + 13y + 5c) mod 17) / 16: a hard, high-frequency pattern in [0, 1]."""
    img = np.zeros((h, w, c), dtype=np.float64)
    for y in range(h):
        for x in range(w):
            for ch in range(c):
                img[y, x, ch] = ((x * 7 + y * 13 + ch * 5) % 17) / 16.0
    return img


def perturbed(w, h, c):
    """b = 0.8 a + 0.2 (0.5 + 0.4 sin(0.37x + 0.23y + 1.1c)): the pattern, a smooth wave mixed in."""
    a = pattern(w, h, c)
    img = np.zeros((h, w, c), dtype=np.float64)
    for y in range(h):
        for x in range(w):
            for ch in range(c):
                s = 0.5 + 0.4 * math.sin(0.37 * x + 0.23 * y + 1.1 * ch)
                img[y, x, ch] = 0.8 * a[y, x, ch] + 0.2 * s
    return img


def grey_pattern(w, h):
    """g(x, y) = ((x^2 + 3y^2 + 5xy) mod 29) / 28, one channel."""
    img = np.zeros((h, w, 1), dtype=np.float64)
    for y in range(h):
        for x in range(w):
            img[y, x, 0] = ((x * x + 3 * y * y + 5 * x * y) % 29) / 28.0
    return img


def grey_perturbed(w, h):
    """0.7 g + 0.3 ((5x + 3y) mod 7) / 6."""
    g = grey_pattern(w, h)
    img = np.zeros((h, w, 1), dtype=np.float64)
    for y in range(h):
        for x in range(w):
            img[y, x, 0] = 0.7 * g[y, x, 0] + 0.3 * ((5 * x + 3 * y) % 7) / 6.0
    return img


# ---- references ----------------------------------------------------------------------------


def sk_ssim(a, b, **kw):
    """scikit-image's gaussian-weighted SSIM, population covariance, data range 1, channels last."""
    return structural_similarity(
        a,
        b,
        gaussian_weights=True,
        use_sample_covariance=False,
        data_range=1.0,
        channel_axis=-1,
        **kw,
    )


def sk_ssim_k(a, b, k, sigma=None):
    """The loss window SSIM_k: a k-tap Gaussian (radius (k-1)/2) with sigma = k/6, crop (k-1)/2.

    scikit-image hard-codes truncate = 3.5 for its Gaussian filter, so for sigma = k/6 its
    filter radius would be int(3.5 k/6 + 0.5) > (k-1)/2. We keep skimage's SSIM code (formula,
    crop, channel loop) and only swap its filter for scipy's gaussian_filter with the explicit
    radius (k-1)/2, in reflect mode, exactly as skimage calls it otherwise.
    """
    r = (k - 1) // 2
    sigma = k / 6.0 if sigma is None else sigma
    original = skssim.gaussian

    def k_tap_gaussian(image, sigma, truncate, mode):
        return ndi.gaussian_filter(image, sigma, mode=mode, radius=r)

    skssim.gaussian = k_tap_gaussian
    try:
        return sk_ssim(a, b, sigma=sigma, win_size=k)
    finally:
        skssim.gaussian = original


def avg_pool2(img):
    h, w = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
    img = img[:h, :w]
    return 0.25 * (img[0::2, 0::2] + img[1::2, 0::2] + img[0::2, 1::2] + img[1::2, 1::2])


def ms_ssim(a, b):
    """MS-SSIM as documented in drbokeh::eval::metrics (numpy + scipy, not scikit-image)."""
    weights = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333]
    c1, c2 = 0.01**2, 0.03**2
    r = 5
    value = 1.0
    for j, wgt in enumerate(weights):
        if j > 0:
            a, b = avg_pool2(a), avg_pool2(b)
        crop = r if min(a.shape[0], a.shape[1]) >= 2 * r + 1 else 0
        ssims, css = [], []
        for ch in range(a.shape[2]):
            x, y = a[:, :, ch], b[:, :, ch]
            f = lambda im: ndi.gaussian_filter(im, 1.5, mode="reflect", radius=r)  # noqa: E731
            ux, uy = f(x), f(y)
            vx = f(x * x) - ux * ux
            vy = f(y * y) - uy * uy
            vxy = f(x * y) - ux * uy
            cs = (2 * vxy + c2) / (vx + vy + c2)
            s = (2 * ux * uy + c1) / (ux * ux + uy * uy + c1) * cs
            hh, ww = x.shape
            ssims.append(s[crop : hh - crop, crop : ww - crop].mean())
            css.append(cs[crop : hh - crop, crop : ww - crop].mean())
        term = np.mean(ssims) if j == len(weights) - 1 else np.mean(css)
        value *= max(term, 0.0) ** wgt
    return value


def main():
    print(f"// scikit-image {skimage.__version__}")
    a = pattern(40, 34, 3)
    b = perturbed(40, 34, 3)
    ga = grey_pattern(23, 19)
    gb = grey_perturbed(23, 19)
    big_a = pattern(64, 48, 3)
    big_b = perturbed(64, 48, 3)

    out = {}
    out["SSIM_RGB_40X34"] = sk_ssim(a, b, sigma=1.5)
    out["SSIM_GREY_23X19"] = sk_ssim(ga, gb, sigma=1.5)
    out["PSNR_RGB_40X34"] = peak_signal_noise_ratio(a, b, data_range=1.0)
    out["PSNR_GREY_23X19"] = peak_signal_noise_ratio(ga, gb, data_range=1.0)
    # skimage's own window for sigma = 11/6: radius int(3.5 * 11/6 + 0.5) = 6, crop 6.
    out["SSIM_SKIMAGE_SIGMA_11_6_RGB_40X34"] = sk_ssim(a, b, sigma=11.0 / 6.0)
    hssim = 0.0
    for k in (3, 5, 11, 21, 31):
        v = sk_ssim_k(a, b, k)
        out[f"SSIM_K{k}_RGB_40X34"] = v
        hssim += 1.0 - v
    out["HSSIM_RGB_40X34"] = hssim
    # Sanity: the patched path with the default radius reproduces the unpatched skimage call.
    assert abs(sk_ssim_k(a, b, 11, sigma=1.5) - out["SSIM_RGB_40X34"]) < 1e-15
    out["MS_SSIM_RGB_64X48"] = ms_ssim(big_a, big_b)
    for name, v in out.items():
        print(f"const {name}: f64 = {float(v)!r};")


if __name__ == "__main__":
    main()
