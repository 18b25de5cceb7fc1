"""Depth from defocus over a dataset: a small U-Net trained *without depth labels* through a
rendering layer (issue 17; supplement sec. 3.2, figs. 9-10).

The network sees the all-in-focus image and predicts disparity in [0, 1]; a rendering
layer (drbokeh ``physical`` or ``paper`` through :mod:`drbokeh.torch`, or the PyTorch
GaussPSF and aperture layers of :mod:`.layers`) turns image and prediction into a
defocused image, compared with the ray-traced one by L1 + edge-aware G + (H)SSIM
(:mod:`.losses`). Data: ``drbokeh benchmark make`` scenes (:mod:`.data`). Command line:
``python -m drbokeh.dfdnet train|eval|reproduce --out DIR`` (see ``--help``); needs PyTorch.
"""

from __future__ import annotations

from .layers import LAYERS, make_layer
from .losses import LOSSES, defocus_loss, edge_aware_smoothness, hssim, l1, ssim, ssim_sized
from .train import TABLE_RUNS, RunSpec, TrainConfig, train_run
from .unet import UNet

__all__ = [
    "LAYERS", "LOSSES", "TABLE_RUNS", "RunSpec", "TrainConfig", "UNet",
    "defocus_loss", "edge_aware_smoothness", "hssim", "l1", "make_layer", "ssim", "ssim_sized", "train_run",
]
