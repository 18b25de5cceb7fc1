"""Clipped highlights of the all-in-focus image, for the training loss.

The all-in-focus PNG clips highlights that the traced defocused image shows as balls
carrying 2-10x more light (docs/dfd.md). Rendering the clipped photo as one opaque layer
then fits the traced image *better* at wrong disparities (spread a highlight as far as
possible) than at the true one, and a network trained on that loss learns "a clipped
highlight is far" (docs/dfdnet.md). Two remedies, both computed from the image pair alone
(no depth), the same for every rendering layer:

- :func:`reach_mask`: the pixels that no clipped all-in-focus pixel can reach, i.e. the
  clipped mask dilated by the largest blur radius ``K`` (a disc), inverted; the loss is
  taken over these pixels only.
- :func:`energy_source`: the energy start of ``drbokeh dfd``
  (``crates/drbokeh/src/dfd/highlights.rs``): blur moves light but keeps it, so summed over
  a clipped region widened by ``K`` the linear defocused image holds the light the clipped
  all-in-focus image lacks; that missing light, shared equally among the region's clipped
  pixels (per channel), is added to them. The result (display-encoded, above 1 where
  boosted) is the layer's source image; the network still sees the clipped photo.
"""

from __future__ import annotations

import math

import numpy as np

CLIP_LEVEL = 0.999
GAMMA = 2.2


def _disc(radius: float) -> np.ndarray:
    r = int(math.floor(radius))
    t = np.arange(-r, r + 1)
    return (t[:, None] ** 2 + t[None, :] ** 2) <= radius * radius


def dilate(mask: np.ndarray, radius: float) -> np.ndarray:
    """``mask`` ``(H, W)`` bool dilated by a disc of ``radius`` px (pixel centres within)."""
    h, w = mask.shape
    disc = _disc(radius)
    r = disc.shape[0] // 2
    out = np.zeros_like(mask)
    ys, xs = np.nonzero(disc)
    padded = np.zeros((h + 2 * r, w + 2 * r), bool)
    padded[r : r + h, r : r + w] = mask
    for dy, dx in zip(ys, xs):
        out |= padded[dy : dy + h, dx : dx + w]
    return out


def clipped(image: np.ndarray) -> np.ndarray:
    """``(3, H, W)`` display-encoded -> ``(H, W)``: any channel at white."""
    return image.max(0) >= CLIP_LEVEL


def reach_mask(aif: np.ndarray, blur: np.ndarray) -> np.ndarray:
    """``(N, 3, H, W)``, ``(N,)`` -> ``(N, 1, H, W)`` float32: 1 where no clipped
    all-in-focus pixel of the scene lies within ``K + 1`` px (the largest blur radius,
    plus a pixel for the footprint's soft edge)."""
    out = np.empty((aif.shape[0], 1) + aif.shape[-2:], np.float32)
    for i in range(aif.shape[0]):
        out[i, 0] = ~dilate(clipped(aif[i]), float(blur[i]) + 1.0)
    return out


def _label(region: np.ndarray) -> np.ndarray:
    """4-connected component labels of ``region`` (-1 outside)."""
    h, w = region.shape
    label = np.full((h, w), -1, np.int64)
    n = 0
    for y0, x0 in zip(*np.nonzero(region)):
        if label[y0, x0] >= 0:
            continue
        stack = [(y0, x0)]
        label[y0, x0] = n
        while stack:
            y, x = stack.pop()
            for yy, xx in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)):
                if 0 <= yy < h and 0 <= xx < w and region[yy, xx] and label[yy, xx] < 0:
                    label[yy, xx] = n
                    stack.append((yy, xx))
        n += 1
    return label


def energy_source(aif: np.ndarray, bokeh: np.ndarray, blur: np.ndarray, max_gain: float = 100.0) -> np.ndarray:
    """``(N, 3, H, W)`` display-encoded all-in-focus and defocused images, ``(N,)`` K ->
    the all-in-focus images with their clipped channels' light raised by the missing
    energy (display-encoded, gamma 2.2; gains clamped to ``[1, max_gain]``)."""
    out = aif.astype(np.float32).copy()
    for i in range(aif.shape[0]):
        lin_a = aif[i].astype(np.float64) ** GAMMA
        lin_t = bokeh[i].astype(np.float64) ** GAMMA
        clip_c = aif[i] >= CLIP_LEVEL  # (3, H, W) per channel
        if not clip_c.any():
            continue
        label = _label(dilate(clip_c.any(0), float(blur[i]) + 1.0))
        n = int(label.max()) + 1
        inside = label >= 0
        for c in range(3):
            missing = np.bincount(label[inside], (lin_t[c] - lin_a[c])[inside], n)
            csum = np.bincount(label[clip_c[c]], lin_a[c][clip_c[c]], n)
            gain = 1.0 + np.maximum(missing, 0.0) / np.maximum(csum, 1e-12)
            gain = np.clip(gain, 1.0, max_gain)
            sel = clip_c[c]
            out[i, c][sel] = (lin_a[c][sel] * gain[label[sel]]) ** (1.0 / GAMMA)
    return out
