"""Shared fixtures: the drbokeh command line (for bit-for-bit comparisons), random layer
stacks, and small file writers (PNG, NPY) that need nothing beyond NumPy."""

from __future__ import annotations

import os
import struct
import subprocess
import zlib
from pathlib import Path
from typing import Dict, List

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]


def _rand(seed: int, *shape: int) -> np.ndarray:
    """Uniform values in [0.05, 0.95] of the given shape, from a seeded generator (the
    dfdnet tests' random images and disparities)."""
    return np.random.default_rng(seed).uniform(0.05, 0.95, size=shape)


def _find_cli() -> Path:
    """The `drbokeh` binary: $DRBOKEH_CLI, else built from this checkout (release)."""
    env = os.environ.get("DRBOKEH_CLI")
    if env:
        path = Path(env)
        if not path.is_file():
            raise RuntimeError(f"DRBOKEH_CLI={env} is not a file")
        return path
    build = subprocess.run(
        ["cargo", "build", "--release", "--quiet", "-p", "drbokeh-cli"],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    if build.returncode != 0:
        raise RuntimeError(f"cannot build the drbokeh CLI:\n{build.stderr}")
    return REPO / "target" / "release" / "drbokeh"


@pytest.fixture(scope="session")
def cli():
    """Runs the drbokeh CLI with the given arguments; fails the test on a non-zero exit."""
    exe = _find_cli()

    def run(*args: object, ok: bool = True) -> subprocess.CompletedProcess:
        p = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True)
        if ok and p.returncode != 0:
            raise AssertionError(f"drbokeh {' '.join(map(str, args))} failed:\n{p.stderr}")
        return p

    return run


def random_stack(
    seed: int, n: int, h: int, w: int, dtype=np.float32, alpha_lo: float = 0.0
) -> Dict[str, np.ndarray]:
    """A random stack: front layers nearer, partial alpha (some exact 0 and 1 unless
    `alpha_lo` > 0), the last layer opaque (unless `alpha_lo` > 0: then every alpha lies in
    [alpha_lo, 1 - alpha_lo], for finite differences)."""
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0.02, 0.98, size=(n, h, w, 3))
    if alpha_lo > 0:
        alpha = rng.uniform(alpha_lo, 1 - alpha_lo, size=(n, h, w))
    else:
        alpha = rng.uniform(0, 1, size=(n, h, w))
        pick = rng.integers(0, 4, size=(n, h, w))
        alpha[pick == 0] = 0.0
        alpha[pick == 1] = 1.0
        alpha[-1] = 1.0
    base = np.linspace(0.85, 0.15, n) if n > 1 else np.array([0.7])
    disparity = base[:, None, None] + rng.uniform(-0.06, 0.06, size=(n, h, w))
    return {
        "rgb": rgb.astype(dtype),
        "alpha": alpha.astype(dtype),
        "disparity": disparity.astype(dtype),
    }


def write_png(path: Path, pixels: np.ndarray) -> None:
    """Writes an 8-bit RGB (H, W, 3) or grey (H, W) PNG from values in [0, 1]."""
    v = np.clip(np.round(pixels * 255), 0, 255).astype(np.uint8)
    h, w = v.shape[:2]
    colour = 2 if v.ndim == 3 else 0
    raw = b"".join(b"\x00" + v[y].tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    png = b"\x89PNG\r\n\x1a\n"
    png += chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, colour, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw))
    png += chunk(b"IEND", b"")
    Path(path).write_bytes(png)


def photo(seed: int, h: int, w: int):
    """A synthetic photo and disparity with a depth edge: a near disc on a far,
    textured background (so the decomposition cuts it into layers)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    inside = (x - 0.4 * w) ** 2 + (y - 0.5 * h) ** 2 < (0.28 * min(h, w)) ** 2
    image = rng.uniform(0.1, 0.9, size=(h, w, 3))
    image[inside] = [0.9, 0.5, 0.2]
    disparity = np.where(inside, 0.9, 0.2 + 0.1 * x / w)
    return image, disparity


def stack_npz(path: Path, stack: Dict[str, np.ndarray]) -> Path:
    np.savez(path, rgb=stack["rgb"], alpha=stack["alpha"], disparity=stack["disparity"])
    return path


def cli_camera_args(camera: Dict[str, object]) -> List[str]:
    args: List[str] = []
    for key, value in camera.items():
        if key == "highlight":
            if value:
                args.append("--highlight")
        elif value is not None:
            args += [f"--{key}", str(value)]
    return args
