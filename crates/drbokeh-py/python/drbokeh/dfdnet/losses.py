"""The depth-from-defocus losses in PyTorch: L1, edge-aware smoothness G, SSIM and HSSIM
(supplement eq. 10, sec. 3.2).

They follow the definitions of the Rust ``loss`` module (``crates/drbokeh/src/loss/``)
term for term; ``tests/test_dfdnet_losses.py`` checks them against those written formulas,
computed independently with NumPy loops:

- ``l1``: the mean of ``|pred - target|`` over every value (pixels and channels).
- ``edge_aware_smoothness`` (G): over a 4-level pyramid of 2x2 average pooling (odd last
  row/column dropped), ``mean(|dx D| exp(-e |dx I|)) + mean(|dy D| exp(-e |dy I|))`` per
  level, averaged over the levels; forward differences; ``|dx I|`` is the mean over the
  guide's channels. The Rust module uses edge sensitivity ``e = 1``; ``drbokeh dfd`` uses
  ``e = 10`` (docs/dfd.md, row V2_e10), which training uses too.
- ``ssim``: per channel, a normalised Gaussian window of radius ``r`` and standard deviation
  ``sigma``; population statistics; ``C1 = 0.01^2``, ``C2 = 0.03^2``; the map's mean over the
  pixels at least ``r`` from every border (so the border rule never matters), then over
  channels. ``ssim_sized(k)`` is the loss window ``SSIM_k``: ``k`` taps, ``sigma = k / 6``.
- ``hssim``: ``sum_k (1 - SSIM_k)`` for ``k`` in ``HSSIM_WINDOWS`` = 3, 5, 11, 21, 31.

Images are ``(B, C, H, W)`` tensors; every function returns one value per batch item
``(B,)`` so that callers can weight or mask items.
"""

from __future__ import annotations

import math
from typing import List, Optional, Tuple

import torch
import torch.nn.functional as F

HSSIM_WINDOWS: Tuple[int, ...] = (3, 5, 11, 21, 31)
SMOOTHNESS_LEVELS = 4
K1 = 0.01
K2 = 0.03


def l1(pred: torch.Tensor, target: torch.Tensor, mask: Optional[torch.Tensor] = None) -> torch.Tensor:
    """Mean absolute difference per batch item. With ``mask`` ``(B, 1, H, W)`` (1 = use), the
    mean runs over the masked pixels only (all channels)."""
    diff = (pred - target).abs()
    if mask is None:
        return diff.flatten(1).mean(1)
    m = mask.expand_as(diff)
    return (diff * m).flatten(1).sum(1) / m.flatten(1).sum(1).clamp_min(1.0)


def _pool2(x: torch.Tensor) -> torch.Tensor:
    h, w = x.shape[-2] // 2 * 2, x.shape[-1] // 2 * 2
    return F.avg_pool2d(x[..., :h, :w], 2)


def edge_aware_smoothness(
    disparity: torch.Tensor, guide: torch.Tensor, edge_sensitivity: float = 1.0
) -> torch.Tensor:
    """G of a ``(B, 1, H, W)`` disparity guided by a ``(B, C, H, W)`` image (a constant: no
    gradient flows into it). Sides must be at least 16 pixels."""
    if disparity.shape[-1] < 16 or disparity.shape[-2] < 16:
        raise ValueError(f"smoothness needs at least 16x16, got {tuple(disparity.shape[-2:])}")
    d, g = disparity, guide.detach()
    total = torch.zeros(d.shape[0], dtype=d.dtype, device=d.device)
    for level in range(SMOOTHNESS_LEVELS):
        if level:
            d, g = _pool2(d), _pool2(g)
        ex = (g[..., :, 1:] - g[..., :, :-1]).abs().mean(1, keepdim=True)
        ey = (g[..., 1:, :] - g[..., :-1, :]).abs().mean(1, keepdim=True)
        dx = (d[..., :, 1:] - d[..., :, :-1]).abs()
        dy = (d[..., 1:, :] - d[..., :-1, :]).abs()
        total = total + (dx * torch.exp(-edge_sensitivity * ex)).flatten(1).mean(1)
        total = total + (dy * torch.exp(-edge_sensitivity * ey)).flatten(1).mean(1)
    return total / SMOOTHNESS_LEVELS


def gaussian_weights(radius: int, sigma: float) -> List[float]:
    """The normalised 1-D window ``exp(-t^2 / (2 sigma^2))`` for ``t = -radius..radius``."""
    w = [math.exp(-(t * t) / (2.0 * sigma * sigma)) for t in range(-radius, radius + 1)]
    s = sum(w)
    return [v / s for v in w]


def _filter(x: torch.Tensor, w1: torch.Tensor) -> torch.Tensor:
    """Separable 'valid' filtering of every channel of ``x`` with the 1-D window ``w1``."""
    c = x.shape[1]
    k = w1.numel()
    x = F.conv2d(x, w1.view(1, 1, 1, k).expand(c, 1, 1, k), groups=c)
    return F.conv2d(x, w1.view(1, 1, k, 1).expand(c, 1, k, 1), groups=c)


def ssim(
    x: torch.Tensor, y: torch.Tensor, radius: int, sigma: float, mask: Optional[torch.Tensor] = None
) -> torch.Tensor:
    """Gaussian-window SSIM per batch item (data range 1), cropped by ``radius``. With
    ``mask`` ``(B, 1, H, W)`` (1 = use) the map's mean runs over the masked window centres
    only (an item with none left gives 1, i.e. no loss)."""
    if x.shape[-1] <= 2 * radius or x.shape[-2] <= 2 * radius:
        raise ValueError(f"SSIM window radius {radius} too large for {tuple(x.shape[-2:])}")
    w1 = torch.tensor(gaussian_weights(radius, sigma), dtype=x.dtype, device=x.device)
    c1, c2 = K1 * K1, K2 * K2
    ux, uy = _filter(x, w1), _filter(y, w1)
    vx = _filter(x * x, w1) - ux * ux
    vy = _filter(y * y, w1) - uy * uy
    vxy = _filter(x * y, w1) - ux * uy
    s = (2 * ux * uy + c1) * (2 * vxy + c2) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
    if mask is None:
        return s.flatten(1).mean(1)
    h, w = s.shape[-2:]
    m = mask[..., radius : radius + h, radius : radius + w].expand_as(s)
    n = m.flatten(1).sum(1)
    return torch.where(n > 0, (s * m).flatten(1).sum(1) / n.clamp_min(1.0), torch.ones_like(n))


def ssim_sized(x: torch.Tensor, y: torch.Tensor, k: int, mask: Optional[torch.Tensor] = None) -> torch.Tensor:
    """``SSIM_k``: a ``k``-tap window (radius ``(k-1)/2``) with ``sigma = k/6``."""
    if k < 3 or k % 2 == 0:
        raise ValueError(f"SSIM window size must be odd and at least 3, got {k}")
    return ssim(x, y, (k - 1) // 2, k / 6.0, mask)


def hssim(x: torch.Tensor, y: torch.Tensor, mask: Optional[torch.Tensor] = None) -> torch.Tensor:
    """``sum_k (1 - SSIM_k)`` over ``HSSIM_WINDOWS``, per batch item."""
    return sum((1.0 - ssim_sized(x, y, k, mask) for k in HSSIM_WINDOWS), torch.zeros(x.shape[0], dtype=x.dtype))


LOSSES = ("l1g", "ssim", "hssim")


def defocus_loss(
    rendered: torch.Tensor,
    target: torch.Tensor,
    disparity: torch.Tensor,
    guide: torch.Tensor,
    loss: str,
    *,
    w_l1: float = 0.5,
    w_smooth: float = 0.5,
    w_structure: float = 10.0,
    edge_sensitivity: float = 10.0,
    mask: Optional[torch.Tensor] = None,
    structure_mask: Optional[torch.Tensor] = None,
) -> Tuple[torch.Tensor, dict]:
    """The training loss, averaged over the batch: ``w_l1 L1 + w_smooth G`` plus
    ``w_structure (1 - SSIM_11)`` (``loss="ssim"``) or ``w_structure HSSIM`` (``"hssim"``).
    Default weights: the published training configuration (L1 0.5, G 0.5, HSSIM 10).
    ``mask`` restricts L1, ``structure_mask`` the (H)SSIM maps (both ``(B, 1, H, W)``, 1 =
    use). Returns the loss and its terms (floats) for logging."""
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r} (available: {', '.join(LOSSES)})")
    t_l1 = l1(rendered, target, mask).mean()
    t_g = edge_aware_smoothness(disparity, guide, edge_sensitivity).mean()
    total = w_l1 * t_l1 + w_smooth * t_g
    terms = {"l1": float(t_l1.detach()), "g": float(t_g.detach())}
    if loss == "ssim":
        t_s = (1.0 - ssim_sized(rendered, target, 11, structure_mask)).mean()
        total = total + w_structure * t_s
        terms["ssim"] = float(t_s.detach())
    elif loss == "hssim":
        t_s = hssim(rendered, target, structure_mask).mean()
        total = total + w_structure * t_s
        terms["hssim"] = float(t_s.detach())
    return total, terms
