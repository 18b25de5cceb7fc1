"""A small U-Net: the all-in-focus image ``(B, 3, H, W)`` in, disparity ``(B, 1, H, W)`` in
[0, 1] out (a sigmoid). Four 2x poolings, so H and W must be multiples of 16."""

from __future__ import annotations

from typing import List

import torch
from torch import nn


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=1, padding_mode="replicate"),
        nn.GroupNorm(min(8, cout // 4), cout),
        nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, padding_mode="replicate"),
        nn.GroupNorm(min(8, cout // 4), cout),
        nn.ReLU(inplace=True),
    )


class UNet(nn.Module):
    """Encoder widths ``base * (1, 2, 4, 8, 16)``; ``base=12`` has about 1.1 M parameters, ``base=16`` 1.9 M.
    ``in_channels``: 3 for the all-in-focus image, 6 with the defocused image beside it."""

    def __init__(self, base: int = 16, in_channels: int = 3) -> None:
        super().__init__()
        widths = [base * m for m in (1, 2, 4, 8, 16)]
        self.down = nn.ModuleList()
        cin = in_channels
        for c in widths:
            self.down.append(_block(cin, c))
            cin = c
        self.up = nn.ModuleList()
        self.merge = nn.ModuleList()
        for c in reversed(widths[:-1]):
            self.up.append(nn.ConvTranspose2d(cin, c, 2, stride=2))
            self.merge.append(_block(2 * c, c))
            cin = c
        self.head = nn.Conv2d(cin, 1, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.shape[-1] % 16 or x.shape[-2] % 16:
            raise ValueError(f"UNet input sides must be multiples of 16, got {tuple(x.shape[-2:])}")
        skips: List[torch.Tensor] = []
        h = x - 0.5
        for i, block in enumerate(self.down):
            if i:
                h = nn.functional.max_pool2d(h, 2)
            h = block(h)
            skips.append(h)
        skips.pop()
        for up, merge in zip(self.up, self.merge):
            h = up(h)
            h = merge(torch.cat([h, skips.pop()], 1))
        return torch.sigmoid(self.head(h))


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
