"""drbokeh.dfdnet's losses against their written formulas (the Rust loss module's definitions,
computed here with plain NumPy loops), the highlight modes' mask and energy, and the focus
prior's term."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from conftest import _rand  # noqa: E402
from drbokeh.dfdnet import layers, losses  # noqa: E402


# ---- losses -------------------------------------------------------------------------------


def _np_ssim(x, y, radius, sigma):
    """SSIM of (C, H, W) images by the written formula, one window position at a time."""
    t = np.arange(-radius, radius + 1)
    g = np.exp(-(t ** 2) / (2 * sigma ** 2))
    w2 = np.outer(g, g) / g.sum() ** 2
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    c, h, wd = x.shape
    vals = []
    for ch in range(c):
        for yy in range(radius, h - radius):
            for xx in range(radius, wd - radius):
                px = x[ch, yy - radius : yy + radius + 1, xx - radius : xx + radius + 1]
                py = y[ch, yy - radius : yy + radius + 1, xx - radius : xx + radius + 1]
                ux, uy = (w2 * px).sum(), (w2 * py).sum()
                vx = (w2 * px * px).sum() - ux * ux
                vy = (w2 * py * py).sum() - uy * uy
                vxy = (w2 * px * py).sum() - ux * uy
                vals.append((2 * ux * uy + c1) * (2 * vxy + c2) / ((ux * ux + uy * uy + c1) * (vx + vy + c2)))
    return float(np.mean(vals))


def _np_pool(a):
    h, w = a.shape[-2] // 2, a.shape[-1] // 2
    a = a[..., : 2 * h, : 2 * w]
    return 0.25 * (a[..., 0::2, 0::2] + a[..., 1::2, 0::2] + a[..., 0::2, 1::2] + a[..., 1::2, 1::2])


def _np_smoothness(d, guide, e):
    """G by the written formula: d (H, W), guide (C, H, W)."""
    total = 0.0
    for level in range(4):
        if level:
            d, guide = _np_pool(d), _np_pool(guide)
        h, w = d.shape
        sx, sy = [], []
        for yy in range(h):
            for xx in range(w - 1):
                sx.append(abs(d[yy, xx + 1] - d[yy, xx]) * math.exp(-e * np.abs(guide[:, yy, xx + 1] - guide[:, yy, xx]).mean()))
        for yy in range(h - 1):
            for xx in range(w):
                sy.append(abs(d[yy + 1, xx] - d[yy, xx]) * math.exp(-e * np.abs(guide[:, yy + 1, xx] - guide[:, yy, xx]).mean()))
        total += np.mean(sx) + np.mean(sy)
    return total / 4


def test_l1_and_smoothness_match_their_formulas():
    x, y = _rand(1, 2, 3, 20, 18), _rand(2, 2, 3, 20, 18)
    got = losses.l1(torch.from_numpy(x), torch.from_numpy(y)).numpy()
    assert np.allclose(got, np.abs(x - y).reshape(2, -1).mean(1), rtol=1e-12)
    d, g = _rand(3, 1, 1, 19, 17), _rand(4, 1, 3, 19, 17)  # odd sides: pooling drops a row
    for e in (1.0, 10.0):
        got = float(losses.edge_aware_smoothness(torch.from_numpy(d), torch.from_numpy(g), e)[0])
        assert got == pytest.approx(_np_smoothness(d[0, 0], g[0], e), rel=1e-10)


def test_ssim_and_hssim_match_their_formulas():
    x = _rand(5, 1, 3, 34, 33)
    y = np.clip(x + 0.1 * _rand(6, 1, 3, 34, 33) - 0.05, 0, 1)
    tx, ty = torch.from_numpy(x), torch.from_numpy(y)
    want = {}
    for k in losses.HSSIM_WINDOWS:
        want[k] = _np_ssim(x[0], y[0], (k - 1) // 2, k / 6.0)
        assert float(losses.ssim_sized(tx, ty, k)[0]) == pytest.approx(want[k], rel=1e-10)
    assert float(losses.hssim(tx, ty)[0]) == pytest.approx(sum(1 - v for v in want.values()), rel=1e-10)
    # Identical images: SSIM 1, HSSIM 0; a window too large is refused.
    assert float(losses.hssim(tx, tx)[0]) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="too large"):
        losses.ssim_sized(tx[..., :20, :20], ty[..., :20, :20], 21)


def test_masked_ssim_is_the_mean_over_kept_window_centres():
    x = _rand(11, 2, 3, 33, 33)
    y = np.clip(x + 0.2 * _rand(12, 2, 3, 33, 33) - 0.1, 0, 1)
    tx, ty = torch.from_numpy(x), torch.from_numpy(y)
    ones = torch.ones(2, 1, 33, 33, dtype=torch.float64)
    assert torch.allclose(losses.hssim(tx, ty, ones), losses.hssim(tx, ty), rtol=1e-12)
    x, y, tx, ty, ones = x[..., :24, :24], y[..., :24, :24], tx[..., :24, :24], ty[..., :24, :24], ones[..., :24, :24]
    # Keep only window centres in the left half: the mean over those entries of the map.
    mask = ones.clone()
    mask[..., 12:] = 0
    r = 2
    full = losses.ssim(tx, ty, r, 5 / 6.0, None)
    got = losses.ssim(tx, ty, r, 5 / 6.0, mask)
    for b in range(2):
        vals = []
        for ch in range(3):
            for yy in range(r, 24 - r):
                for xx in range(r, 12):
                    vals.append(_np_ssim(x[b, ch : ch + 1, yy - r : yy + r + 1, xx - r : xx + r + 1],
                                         y[b, ch : ch + 1, yy - r : yy + r + 1, xx - r : xx + r + 1], r, 5 / 6.0))
        assert float(got[b]) == pytest.approx(np.mean(vals), rel=1e-10)
        assert float(got[b]) != pytest.approx(float(full[b]), rel=1e-6)
    # Nothing kept: no loss (SSIM 1).
    assert torch.all(losses.ssim(tx, ty, r, 5 / 6.0, torch.zeros_like(ones)) == 1.0)


def test_highlight_reach_and_energy():
    from drbokeh.dfdnet import highlights

    # Reach: one clipped pixel; K = 4 -> every pixel within 5 px of it is left out.
    aif = np.full((1, 3, 21, 21), 0.3, np.float32)
    aif[0, :, 10, 10] = 1.0
    keep = highlights.reach_mask(aif, np.array([4.0], np.float32))[0, 0]
    yy, xx = np.mgrid[:21, :21]
    dist2 = (yy - 10) ** 2 + (xx - 10) ** 2
    assert np.array_equal(keep == 0, dist2 <= 25)
    # Energy: a highlight of 6x white (linear) spread into a disc of radius 5 over a
    # background of 0.2; the clipped pixel gets its light back.
    bg = 0.2
    aif = np.full((1, 3, 40, 40), bg ** (1 / 2.2), np.float32)
    aif[0, :, 20, 20] = 1.0
    yy, xx = np.mgrid[:40, :40]
    disc = (yy - 20) ** 2 + (xx - 20) ** 2 <= 25
    lin = np.full((3, 40, 40), bg)
    lin[:, disc] += (6.0 - bg) / disc.sum()
    bokeh = (lin ** (1 / 2.2)).astype(np.float32)[None]
    src = highlights.energy_source(aif, bokeh, np.array([6.0], np.float32))
    assert src[0, :, 20, 20] ** 2.2 == pytest.approx([6.0] * 3, rel=1e-3)
    unclipped = np.ones((40, 40), bool)
    unclipped[20, 20] = False
    assert np.array_equal(src[0][:, unclipped], aif[0][:, unclipped])




def test_focus_prior_adds_its_weighted_term_to_the_image_loss():
    from drbokeh.dfdnet.train import TrainConfig, image_loss

    rng = np.random.default_rng(5)
    b = {"aif": rng.uniform(0.1, 0.9, (2, 3, 48, 48)).astype(np.float32),
         "bokeh": rng.uniform(0.1, 0.9, (2, 3, 48, 48)).astype(np.float32),
         "focus": np.array([0.0, 0.25], np.float32), "blur": np.array([2.0, 3.0], np.float32)}
    pred = torch.from_numpy(rng.uniform(0.0, 1.0, (2, 1, 48, 48)).astype(np.float32))
    layer = layers.make_layer("gausspsf")
    base, terms = image_loss(layer, "hssim", TrainConfig(), b, pred)
    assert "focus" not in terms
    with_prior, terms = image_loss(layer, "hssim", TrainConfig(w_focus=1.5), b, pred)
    expected = np.abs(pred.numpy() - b["focus"].reshape(-1, 1, 1, 1)).mean()
    assert terms["focus"] == pytest.approx(expected, rel=1e-5)
    assert float(with_prior) == pytest.approx(float(base) + 1.5 * expected, rel=1e-5)


def test_focus_prior_radius_caps_each_pixel_term_at_the_blur_radius():
    """``--focus-prior-radius PX``: a pixel's prior term is min(|d - f|, PX / K), so its
    gradient vanishes once the blur radius K |d - f| reaches PX, and is the plain prior's
    below; malformed values are refused."""
    from drbokeh.dfdnet.__main__ import _cfg, parse_args
    from drbokeh.dfdnet.train import TrainConfig, image_loss

    b = {"aif": np.full((2, 3, 48, 48), 0.5, np.float32), "bokeh": np.full((2, 3, 48, 48), 0.5, np.float32),
         "focus": np.array([0.0, 0.25], np.float32), "blur": np.array([2.0, 4.0], np.float32)}
    # Item 0 (K 2, cap 0.5 for 1 px): |d - f| = 0.2 (below, kept) and 0.8 (capped at 0.5).
    # Item 1 (K 4, cap 0.25): |d - f| = 0.1 (kept) and 0.45 (capped at 0.25).
    pred = np.zeros((2, 1, 48, 48), np.float32)
    pred[0, 0, :, :24], pred[0, 0, :, 24:] = 0.2, 0.8
    pred[1, 0, :, :24], pred[1, 0, :, 24:] = 0.35, 0.7
    p = torch.from_numpy(pred).requires_grad_(True)
    layer = layers.make_layer("gausspsf")
    cfg = _cfg(parse_args(["train", "--out", "o", "--focus-prior", "2", "--focus-prior-radius", "1"]))
    assert (cfg.w_focus, cfg.focus_prior_radius_px) == (2.0, 1.0)
    _, terms = image_loss(layer, "l1g", cfg, b, p)
    assert terms["focus"] == pytest.approx((0.2 + 0.5 + 0.1 + 0.25) / 4, rel=1e-5)
    _, plain = image_loss(layer, "l1g", TrainConfig(w_focus=2.0), b, p)
    assert plain["focus"] == pytest.approx((0.2 + 0.8 + 0.1 + 0.45) / 4, rel=1e-5)
    # The prior's gradient alone: the loss without the prior, subtracted.
    with_prior, _ = image_loss(layer, "l1g", cfg, b, p)
    (g_with,) = torch.autograd.grad(with_prior, p)
    without, _ = image_loss(layer, "l1g", TrainConfig(), b, p)
    (g_without,) = torch.autograd.grad(without, p)
    g = (g_with - g_without).numpy() * pred.size / 2.0
    assert g[0, 0, :, :24] == pytest.approx(np.ones((48, 24)), abs=1e-3)
    assert g[1, 0, :, :24] == pytest.approx(np.ones((48, 24)), abs=1e-3)
    assert np.abs(g[:, 0, :, 24:]).max() < 1e-3
    for bad in ("0", "-1", "x", "nan", "inf"):
        with pytest.raises(SystemExit):
            parse_args(["train", "--out", "o", "--focus-prior-radius", bad])
    with pytest.raises(ValueError, match="radius"):
        TrainConfig(focus_prior_radius_px=0.0)
