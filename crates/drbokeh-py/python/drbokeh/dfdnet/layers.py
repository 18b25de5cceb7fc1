"""Rendering layers for training: ``disparity -> defocused image``, all differentiable.

Every layer maps ``aif`` ``(B, 3, H, W)`` (display-encoded, gamma transfer), a predicted
``disparity`` ``(B, 1, H, W)`` in [0, 1], and per-item ``focus``, ``blur`` (K) ``(B,)`` to
the display-encoded defocused image ``(B, 3, H, W)``.

- ``drbokeh-physical``, ``drbokeh-paper``: one opaque layer through
  :func:`drbokeh.torch.render` (the Rust renderer and its exact adjoint).
- ``physical3``, ``paper3``: the same through the prediction's layer stack (up to 3
  depth layers, :func:`occlusion_stack`), so a blurred nearer object shows the filled-in
  background behind it.
- ``physical5``, ``paper5``: the same stack with up to 5 depth layers, so that objects at
  different depths in front of the background get their own layers (and occlude each
  other) rather than sharing one.
- ``physical3m``, ``paper3m``: the same stack with a layer assignment the loss can move
  (:func:`movable_assignment`).
- ``gausspsf``: GaussPSF (Gur & Wolf 2019) as ``crates/drbokeh/src/baselines/gauss_psf.rs``:
  each source pixel spreads a Gaussian of ``sigma = sqrt((K d / 2)^2 + 1/4)``, gathered and
  normalised over in-image sources, ``out(x) = sum_y w I(y) / sum_y w``,
  ``w = exp(-|x-y|^2 / (2 sigma_y^2)) / sigma_y^2``, in linear light; the gather radius is
  three standard deviations of the largest Gaussian of the disparity (of the batch).
- ``aperture``: aperture compositing (Srinivasan et al. 2018), the image resampled
  (bilinear, clamped borders) at ``x + K d(x) u_j`` for 128 golden-angle spiral samples
  ``u_j`` of the unit disc and averaged in linear light: the Rust layer
  ``baselines/aperture_compositing.rs`` and its adjoint (``_native.aperture_layer``).
- ``aperturepy``: the same in PyTorch (``grid_sample``), the plain reference the Rust
  layer is tested against, and the layer every ``aperture`` run of docs/dfdnet.md up to
  session 28 was trained through (a training step at batch 4, 128 px, about 1.2x the
  Rust layer's; docs/dfdnet.md, "Session 28").

Here ``d = disparity - focus``. ``tests/test_dfdnet_layers.py`` checks the two PyTorch baselines
against the Rust ones (``drbokeh eval``'s renders are not exposed to Python, so against a
direct NumPy transcription of the Rust loops) and their gradients with ``gradcheck``.
"""

from __future__ import annotations

import math
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import torch
import torch.nn.functional as F

GAMMA = 2.2
APERTURE_SAMPLES = 128

Layer = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


def linearize(encoded: torch.Tensor, gamma: float = GAMMA) -> torch.Tensor:
    return encoded.clamp_min(0.0).pow(gamma)


def encode(linear: torch.Tensor, gamma: float = GAMMA) -> torch.Tensor:
    # The small floor keeps the derivative of x^(1/g) finite at 0 (the Rust layers give 0).
    return linear.clamp_min(1e-8).pow(1.0 / gamma)


class _GaussGather(torch.autograd.Function):
    """``num[:, c](x) = sum_o w(o, var(x+o)) src[:, c](x+o)`` over offsets ``|o_x|, |o_y| <= r``
    with ``w(o, v) = exp(-|o|^2 / (2 v)) / v``, on a ``r``-padded ``src`` and ``var``. A
    loop over offsets in both directions, so memory stays at a few planes (autograd would
    keep every offset's weights). Gradient with respect to ``var`` only."""

    @staticmethod
    def forward(ctx, src: torch.Tensor, var_p: torch.Tensor, r: int) -> torch.Tensor:  # type: ignore[override]
        b, c, hp, wp = src.shape
        h, w = hp - 2 * r, wp - 2 * r
        num = torch.zeros(b, c, h, w, dtype=src.dtype)
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                ys, xs = r + dy, r + dx
                v = var_p[:, :, ys : ys + h, xs : xs + w]
                num += torch.exp(-float(dx * dx + dy * dy) / (2.0 * v)) / v * src[:, :, ys : ys + h, xs : xs + w]
        ctx.save_for_backward(src, var_p)
        ctx.r = r
        return num

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        src, var_p = ctx.saved_tensors
        r = ctx.r
        h, w = grad.shape[-2:]
        g_var = torch.zeros_like(var_p)
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                ys, xs = r + dy, r + dx
                rr = float(dx * dx + dy * dy)
                v = var_p[:, :, ys : ys + h, xs : xs + w]
                wt = torch.exp(-rr / (2.0 * v)) / v
                dw = wt * (rr / (2.0 * v * v) - 1.0 / v)
                g_var[:, :, ys : ys + h, xs : xs + w] += dw * (grad * src[:, :, ys : ys + h, xs : xs + w]).sum(1, keepdim=True)
        return None, g_var, None


def gausspsf(aif: torch.Tensor, disparity: torch.Tensor, focus: torch.Tensor, blur: torch.Tensor) -> torch.Tensor:
    b, _, h, w = aif.shape
    lin = linearize(aif)
    k = blur.view(b, 1, 1, 1).to(aif.dtype)
    half = k * (disparity - focus.view(b, 1, 1, 1).to(aif.dtype)) * 0.5
    var = half * half + 0.25  # sigma^2 of each source pixel
    # Gather radius: three standard deviations of the largest Gaussian in the batch.
    max_sigma = math.sqrt(float(var.detach().max()))
    r = max(1, math.ceil(3.0 * max_sigma))
    # Sources outside the image carry no weight: pad with zeros and a validity plane.
    ones = torch.ones(b, 1, h, w, dtype=aif.dtype)
    src = F.pad(torch.cat([lin, ones], 1), (r, r, r, r))
    var_p = F.pad(var, (r, r, r, r), value=1.0)
    num = _GaussGather.apply(src, var_p, r)
    return encode(num[:, :3] / num[:, 3:])


def aperture_samples(n: int = APERTURE_SAMPLES) -> List[Tuple[float, float]]:
    """Area-uniform golden-angle spiral on the unit disc (as the Rust baseline)."""
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for i in range(n):
        r = math.sqrt((i + 0.5) / n)
        t = i * golden
        out.append((r * math.cos(t), r * math.sin(t)))
    return out


def aperture(aif: torch.Tensor, disparity: torch.Tensor, focus: torch.Tensor, blur: torch.Tensor) -> torch.Tensor:
    b, _, h, w = aif.shape
    lin = linearize(aif)
    uv = torch.tensor(aperture_samples(), dtype=aif.dtype)  # (S, 2)
    s = uv.shape[0]
    shift = blur.view(b, 1, 1).to(aif.dtype) * (disparity[:, 0] - focus.view(b, 1, 1).to(aif.dtype))
    ys, xs = torch.meshgrid(torch.arange(h, dtype=aif.dtype), torch.arange(w, dtype=aif.dtype), indexing="ij")
    # Sample positions (B, H, W, S), clamped to the image as the Rust bilinear lookup.
    px = (xs[None, :, :, None] + shift[..., None] * uv[:, 0]).clamp(0, w - 1)
    py = (ys[None, :, :, None] + shift[..., None] * uv[:, 1]).clamp(0, h - 1)
    gx = px / (w - 1) * 2 - 1
    gy = py / (h - 1) * 2 - 1
    grid = torch.stack([gx, gy], -1).reshape(b, h, w * s, 2)
    sampled = F.grid_sample(lin, grid, mode="bilinear", padding_mode="border", align_corners=True)
    out = sampled.view(b, 3, h, w, s).mean(-1)
    return encode(out)


class _ApertureRust(torch.autograd.Function):
    """The aperture layer through ``_native.aperture_layer``, item by item: the forward
    renders, the backward calls the layer's adjoint (which renders again) for the gradient
    with respect to the disparity only; the image gets none (it is the network's input)."""

    @staticmethod
    def forward(ctx, aif: torch.Tensor, disparity: torch.Tensor, focus: torch.Tensor, blur: torch.Tensor, threads: int) -> torch.Tensor:  # type: ignore[override]
        from .. import _native

        img = aif.detach().permute(0, 2, 3, 1).contiguous().numpy()
        disp = disparity.detach()[:, 0].contiguous().numpy()
        f = [float(v) for v in focus]
        k = [float(v) for v in blur]
        out = [
            _native.aperture_layer(img[i], disp[i], focus=f[i], blur=k[i], gamma=GAMMA, threads=threads)
            for i in range(img.shape[0])
        ]
        ctx.inputs = (img, disp, f, k, threads)
        return torch.from_numpy(np.stack(out)).permute(0, 3, 1, 2).to(aif.dtype)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        from .. import _native

        img, disp, f, k, threads = ctx.inputs
        g = grad.detach().permute(0, 2, 3, 1).contiguous().numpy().astype(img.dtype, copy=False)
        d = [
            _native.aperture_layer(img[i], disp[i], focus=f[i], blur=k[i], gamma=GAMMA, grad_output=g[i], threads=threads)[1]
            for i in range(img.shape[0])
        ]
        return None, torch.from_numpy(np.stack(d)).unsqueeze(1).to(grad.dtype), None, None, None


def aperture_rust(threads: int = 1) -> Layer:
    """The ``aperture`` layer: :func:`aperture` computed by the Rust layer and its adjoint."""

    def render(aif: torch.Tensor, disparity: torch.Tensor, focus: torch.Tensor, blur: torch.Tensor) -> torch.Tensor:
        return _ApertureRust.apply(aif, disparity, focus, blur, threads)

    return render


def drbokeh_layer(preset: str, threads: int = 1) -> Layer:
    from .. import torch as dbt

    def render(aif: torch.Tensor, disparity: torch.Tensor, focus: torch.Tensor, blur: torch.Tensor) -> torch.Tensor:
        rgb = aif.permute(0, 2, 3, 1).unsqueeze(1).contiguous()  # (B, 1, H, W, 3)
        disp = disparity.clamp(0.0, 1.0)
        alpha = torch.ones_like(disp)
        out = dbt.render(
            rgb, alpha, disp, focus.to(aif.dtype), blur.to(aif.dtype),
            preset=preset, gamma=GAMMA, threads=threads,
        )
        return out.permute(0, 3, 1, 2)

    return render


def quantised(disparity: np.ndarray, levels: int, min_range: float = 0.05) -> np.ndarray:
    """The disparity rounded to ``levels`` equally spaced values over its own range (a
    range below ``min_range``: returned as is). A network's prediction changes smoothly
    across an object's edge, so the decomposition (which cuts where neighbours jump)
    would find no cut in it; rounded, every change of level is a jump."""
    lo, hi = float(disparity.min()), float(disparity.max())
    if hi - lo < min_range or levels < 2:
        return np.ascontiguousarray(disparity, dtype=np.float32)
    q = np.round((disparity - lo) / (hi - lo) * (levels - 1)) / (levels - 1)
    return np.ascontiguousarray(lo + q * (hi - lo), dtype=np.float32)


def occlusion_stack(
    source: torch.Tensor,
    disparity: torch.Tensor,
    focus: torch.Tensor,
    blur: torch.Tensor,
    max_layers: int,
    movable_width: Optional[float] = None,
) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The layer stack of the prediction, as ``drbokeh dfd --occlusion-layers`` builds it:
    per item, :func:`drbokeh.decompose` of the layer input clipped to [0, 1] (the
    highlight-corrected source differs from the photo only on clipped pixels) at the
    *detached* predicted disparity rounded to ``max_layers`` levels (:func:`quantised`;
    depth layers cut at its jumps, each filled in behind the nearer ones), padded with empty layers to ``max_layers``. Each pixel is
    owned by the front-most layer that covers it (alpha > 1/2); there the layer takes the
    input's colour and the prediction's disparity (with its gradient); elsewhere the
    decomposition's fills, held fixed (their dependence on the disparity is not
    differentiated). Returns ``rgb (B, N, H, W, 3)``, ``alpha (B, N, H, W)``,
    ``disparity (B, N, H, W)``.

    With ``movable_width`` (a disparity width ``w``) the layer assignment gets a gradient
    too (:func:`movable_assignment`) in items whose levels are :func:`separated`;
    otherwise a pixel's layer is fixed by the detached prediction."""
    from .. import _native

    b, _, h, w = source.shape
    rgb = torch.zeros(b, max_layers, h, w, 3, dtype=source.dtype)
    alpha = torch.zeros(b, max_layers, h, w, dtype=source.dtype)
    fill = torch.zeros(b, max_layers, h, w, dtype=source.dtype)
    img = source.detach().clamp(0.0, 1.0).permute(0, 2, 3, 1).contiguous().numpy()
    disp = disparity.detach().clamp(0.0, 1.0)[:, 0].contiguous().numpy()
    cuts: List[List[float]] = []
    for i in range(b):
        dec = _native.decompose(img[i], quantised(disp[i], max_layers), max_layers=max_layers, threads=1)
        cuts.append(list(dec["thresholds"]) if separated(disp[i], max_layers, movable_width) else [])
        n = dec["alpha"].shape[0]
        rgb[i, :n] = torch.from_numpy(dec["rgb"]).to(source.dtype)
        alpha[i, :n] = torch.from_numpy(dec["alpha"]).to(source.dtype)
        fill[i, :n] = torch.from_numpy(dec["disparity"]).to(source.dtype)
    covers = (alpha > 0.5).to(torch.int32)
    owner = (covers > 0) & (torch.cumsum(covers, 1) - covers == 0)  # covers, no nearer layer does
    src = source.permute(0, 2, 3, 1).unsqueeze(1).expand_as(rgb)
    rgb = torch.where(owner.unsqueeze(-1), src, rgb)
    layer_disp = torch.where(owner, disparity.clamp(0.0, 1.0).expand_as(fill), fill)
    if movable_width is not None:
        rgb, alpha = movable_assignment(src, disparity, rgb, alpha, covers, cuts, movable_width)
    return rgb, alpha, layer_disp


MOVABLE_ALPHA_FLOOR = 1e-3


def separated(disparity: np.ndarray, levels: int, width: Optional[float]) -> bool:
    """Whether the levels of :func:`quantised` are at least two membership widths apart, so
    that :func:`movable_assignment` may move pixels between the layers. Nearer levels (a
    prediction still close to flat, as at the start of training) would turn the render's
    jump at a cut (the input's colour against the layer behind's fill) into large
    derivatives over the whole image."""
    if width is None or levels < 2:
        return False
    return float(disparity.max() - disparity.min()) / (levels - 1) >= 2.0 * width


def movable_assignment(
    src: torch.Tensor,
    disparity: torch.Tensor,
    rgb: torch.Tensor,
    alpha: torch.Tensor,
    covers: torch.Tensor,
    cuts: List[List[float]],
    width: float,
) -> Tuple[torch.Tensor, torch.Tensor]:
    """Let the loss move pixels between the layers of :func:`occlusion_stack`.

    Layer ``n`` holds the pixels nearer than its cut ``t_n`` (the decomposition's
    thresholds, nearest first; the back layer has none). Where no nearer layer covers a
    pixel, its membership of layer ``n`` is ``m = sigmoid((disparity - t_n) / width)``, and
    the layer's alpha becomes ``alpha + m - detach(m)``: the same value, with the
    membership's derivative (a straight-through estimate), so a pixel that the prediction
    has put on the wrong side of a cut is pushed across it when joining the other layer
    lowers the loss. The derivative of the render with respect to an alpha of 0 is
    meaningless where the layer is empty around the pixel (its colour there is 0 / 0,
    ``docs/model.md`` M14), so those pixels get alpha ``MOVABLE_ALPHA_FLOOR`` (the one
    change to the render: at most that much of a layer shows where it did not) and the
    input's colour, which is what the pixel would bring to the layer."""
    b, n_layers = alpha.shape[:2]
    thr = torch.zeros(b, n_layers, 1, 1, dtype=alpha.dtype)
    has_cut = torch.zeros(b, n_layers, 1, 1, dtype=torch.bool)
    for i, item_cuts in enumerate(cuts):
        for n, t in enumerate(item_cuts[:n_layers]):
            thr[i, n] = float(t)
            has_cut[i, n] = True
    # no nearer layer covers the pixel, and the layer has a cut behind it
    free = (torch.cumsum(covers, 1) - covers == 0) & has_cut
    member = torch.sigmoid((disparity.clamp(0.0, 1.0) - thr) / width)
    empty = free & (alpha < MOVABLE_ALPHA_FLOOR)
    rgb = torch.where(empty.unsqueeze(-1), src, rgb)
    alpha = torch.where(empty, torch.full_like(alpha, MOVABLE_ALPHA_FLOOR), alpha)
    alpha = alpha + torch.where(free, member - member.detach(), torch.zeros_like(member))
    return rgb, alpha


def drbokeh_occlusion_layer(
    preset: str, max_layers: int, threads: int = 1, movable_width: Optional[float] = None
) -> Layer:
    """The drbokeh layer through the prediction's layer stack (:func:`occlusion_stack`)
    instead of one opaque layer: behind a blurred nearer object the render shows the
    filled-in farther layer, as the lens does. ``movable_width``: see
    :func:`movable_assignment`."""
    from .. import torch as dbt

    def render(source: torch.Tensor, disparity: torch.Tensor, focus: torch.Tensor, blur: torch.Tensor) -> torch.Tensor:
        rgb, alpha, disp = occlusion_stack(source, disparity, focus, blur, max_layers, movable_width)
        out = dbt.render(
            rgb, alpha, disp, focus.to(source.dtype), blur.to(source.dtype),
            preset=preset, gamma=GAMMA, threads=threads,
        )
        return out.permute(0, 3, 1, 2)

    return render


LAYERS = (
    "physical", "paper", "gausspsf", "aperture", "aperturepy", "physical3", "paper3", "physical5", "paper5", "physical3m", "paper3m",
)

# The membership width of the movable stacks (``physical3m``, ``paper3m``), in disparity.
# 0.1 against 0.05 at run seed 17 (the tuning seed), validation MAE at the last step 0.168
# against 0.174 (docs/dfdnet.md, "Session 17").
MOVABLE_WIDTH = 0.1


def make_layer(name: str, threads: int = 1) -> Layer:
    table: Dict[str, Callable[[], Layer]] = {
        "physical": lambda: drbokeh_layer("physical", threads),
        "paper": lambda: drbokeh_layer("paper", threads),
        "gausspsf": lambda: gausspsf,
        "aperture": lambda: aperture_rust(threads),
        "aperturepy": lambda: aperture,
        # the drbokeh layers through the prediction's layer stack (at most 3 depth layers)
        "physical3": lambda: drbokeh_occlusion_layer("physical", 3, threads),
        "paper3": lambda: drbokeh_occlusion_layer("paper", 3, threads),
        # up to 5 depth layers (docs/dfdnet.md, session 19)
        "physical5": lambda: drbokeh_occlusion_layer("physical", 5, threads),
        "paper5": lambda: drbokeh_occlusion_layer("paper", 5, threads),
        # the same, with a layer assignment the loss can move (movable_assignment)
        "physical3m": lambda: drbokeh_occlusion_layer("physical", 3, threads, MOVABLE_WIDTH),
        "paper3m": lambda: drbokeh_occlusion_layer("paper", 3, threads, MOVABLE_WIDTH),
    }
    if name not in table:
        raise ValueError(f"unknown layer {name!r} (available: {', '.join(LAYERS)})")
    return table[name]()
