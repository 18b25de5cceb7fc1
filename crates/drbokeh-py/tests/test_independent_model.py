"""The `paper` preset checked against an evaluation written here in NumPy, term by term from
docs/model.md (M1-M3, M7-M15, M17, M18), not from the Rust code (issue 14, case 10).

The forward pass of `drbokeh.render` must equal it to rounding, and the exact adjoint
(`drbokeh.vjp` in float64) must equal its central finite differences, also at the pixels
that the reflection padding (M9) copies, which on this 10x12 stack with window 7 are most of
the pixels."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import drbokeh

FOCUS, BLUR, GAMMA, WINDOW = 0.45, 9.0, 2.2, 7
R = (WINDOW - 1) // 2


def _reflect(i: np.ndarray, n: int) -> np.ndarray:
    """M9: mirror without repeating the edge pixel, folding as often as needed."""
    if n == 1:
        return np.zeros_like(i)
    period = 2 * (n - 1)
    i = np.mod(i, period)
    return np.where(i < n, i, period - i)


def _taps():
    """M8: the window's offsets with dist < R (strictly)."""
    for dy, dx in itertools.product(range(-R, R + 1), repeat=2):
        dist = float(np.hypot(dx, dy))
        if dist < R:
            yield dy, dx, dist


def _layer(lin, alpha, disp):
    """One layer's colour B (M13, M14) and box coverage o (M15), paper preset."""
    h, w = alpha.shape
    d = disp - FOCUS  # M1
    r = BLUR * np.abs(d) + 1.0  # M2, footprint 1 px
    e = np.exp(-3.0 * (BLUR * d) ** 2)  # M10
    ys, xs = np.mgrid[0:h, 0:w]
    colour = np.zeros((h, w, 3))
    weight = np.zeros((h, w))
    for dy, dx, dist in _taps():
        sy, sx = _reflect(ys + dy, h), _reflect(xs + dx, w)
        step = 1.0 / (1.0 + 10.0 * np.exp(-3.0 * (r[sy, sx] - dist)))  # M3
        area = r[sy, sx] ** 2  # M7
        if dy == 0 and dx == 0:
            occlusion = np.ones((h, w))  # M12, centre tap
        else:
            s = 0.5 + 0.5 * np.tanh(10.0 * ((d[sy, sx] - d) - 0.1))  # M11
            occlusion = 1.0 + e * (s - 1.0)  # M12
        c = alpha[sy, sx] * step / area * occlusion  # M13
        colour += lin[sy, sx] * c[..., None]
        weight += c
    layer_colour = colour / (weight + 1e-8)[..., None]  # M14
    half = np.minimum(np.floor(r / 2.0).astype(int), R)  # M15
    coverage = np.zeros((h, w))
    for k in np.unique(half):
        box = np.zeros((h, w))
        for dy, dx in itertools.product(range(-k, k + 1), repeat=2):
            box += alpha[_reflect(ys + dy, h), _reflect(xs + dx, w)]
        coverage = np.where(half == k, box / (2 * k + 1) ** 2, coverage)
    return layer_colour, coverage


def _render(rgb, alpha, disp):
    """M17 front to back in linear light, M18 gamma transfer (offset 0)."""
    out = np.zeros(rgb.shape[1:])
    through = np.ones(alpha.shape[1:])
    for layer in range(rgb.shape[0]):
        b, o = _layer(rgb[layer] ** GAMMA, alpha[layer], disp[layer])
        out += b * (o * through)[..., None]
        through = through * (1.0 - o)
    return np.where(out > 0, out, 0.0) ** (1.0 / GAMMA)


def _stack(seed: int, h: int, w: int):
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0.05, 0.95, (2, h, w, 3))
    alpha = np.stack([rng.uniform(0.2, 0.9, (h, w)), rng.uniform(0.3, 1.0, (h, w))])
    disp = np.stack([rng.uniform(0.6, 0.95, (h, w)), rng.uniform(0.0, 0.3, (h, w))])
    # Keep r/2 away from integers: the box coverage's half-size floor(r/2) jumps there (M15),
    # and a finite difference across the jump measures the jump, not a derivative.
    r_half = (BLUR * np.abs(disp - FOCUS) + 1.0) / 2.0
    near_jump = np.abs(r_half - np.round(r_half)) < 0.02
    disp = np.where(near_jump, disp + 0.01, disp)
    grad_out = rng.uniform(-1.0, 1.0, (h, w, 3))
    return rgb, alpha, disp, grad_out


CAM = dict(focus=FOCUS, blur=BLUR, preset="paper", window=WINDOW, gamma=GAMMA)


def _mirrored(n: int) -> set:
    """Rows (or columns) that the padding copies into the border: 1..R and n-1-R..n-2."""
    return set(range(1, R + 1)) | set(range(n - 1 - R, n - 1))


@pytest.mark.parametrize("h,w,seed", [(10, 12, 1), (12, 10, 2)])
def test_paper_forward_equals_an_independent_evaluation(h, w, seed):
    rgb, alpha, disp, _ = _stack(seed, h, w)
    ours = drbokeh.render(rgb, alpha, disp, engine="threaded", **CAM)
    np.testing.assert_allclose(ours, _render(rgb, alpha, disp), rtol=0, atol=1e-13)


@pytest.mark.parametrize("h,w,seed", [(10, 12, 1), (12, 10, 2)])
def test_exact_adjoint_matches_independent_differences_at_mirrored_pixels(h, w, seed):
    rgb, alpha, disp, grad_out = _stack(seed, h, w)
    grads = drbokeh.vjp(rgb, alpha, disp, grad_out, engine="threaded", **CAM)
    step = 1e-4

    def loss(d):
        return float((_render(rgb, alpha, d) * grad_out).sum())

    mirrored_rows, mirrored_cols = _mirrored(h), _mirrored(w)
    for layer in range(2):
        fd = np.zeros((h, w))
        for y, x in itertools.product(range(h), range(w)):
            unit = np.zeros_like(disp)
            unit[layer, y, x] = 1.0
            at = [loss(disp + t * step * unit) for t in (-2, -1, 1, 2)]
            fd[y, x] = (8.0 * (at[2] - at[1]) - (at[3] - at[0])) / (12.0 * step)
        err = np.abs(grads["disparity"][layer] - fd)
        bound = 1e-6 * np.abs(fd).max()
        mask = np.array(
            [[y in mirrored_rows or x in mirrored_cols for x in range(w)] for y in range(h)]
        )
        assert mask.mean() > 0.6  # the sizes make most pixels mirrored
        assert err[mask].max() <= bound, (layer, err[mask].max(), bound)
        assert err[~mask].max() <= bound, (layer, err[~mask].max(), bound)
