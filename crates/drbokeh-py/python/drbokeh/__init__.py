"""drbokeh: differentiable, occlusion-aware bokeh rendering (Dr.Bokeh).

NumPy arrays in, arrays out. A layer stack is ``rgb (N, H, W, 3)`` display-encoded
colour, ``alpha (N, H, W)`` coverage and ``disparity (N, H, W)`` (larger = nearer,
normalised to [0, 1]), layers front first: the convention of the ``.npz`` stacks that the
``drbokeh`` command line reads. Arrays may be float32 or float64, contiguous or not; the
result is float64 when any input is float64 (and ``engine="auto"`` then runs the exact
threaded engine, as ``drbokeh render --f64``), float32 otherwise.

- :func:`render`, :func:`vjp`, :func:`render_with_tape`: render a stack, and its exact
  gradients with respect to every input.
- :func:`render_image`, :func:`decompose`: the photo path (image + disparity [+ matte]).
- :func:`load_stack`, :func:`save_stack`, :func:`read_image`, :func:`read_disparity`,
  :func:`read_matte`, :func:`load_benchmark`, :func:`trace`, :func:`demo`: the data path.
- ``drbokeh.torch``: the renderer as a PyTorch autograd function and ``nn.Module``
  (imports PyTorch when first used; ``import drbokeh`` alone does not need it).

Errors raise ``ValueError`` (bad arrays and parameters) or ``OSError`` (files), with the
messages the command line prints, parameters named as the keyword arguments are
(``invalid parameter focus: ...`` where the command line says ``--focus``). The GIL is released while rendering; ``threads=N`` runs the work
on a pool of N threads (the output never depends on it).
"""

from __future__ import annotations

import os
from typing import Any, Dict, Iterator, Union

from ._native import (
    DrBokehWarning,
    Tape,
    __version__,
    decompose,
    demo,
    load_stack,
    read_disparity,
    read_image,
    read_matte,
    render,
    render_image,
    render_with_tape,
    save_stack,
    trace,
    vjp,
)
from . import _native

__all__ = [
    "DrBokehWarning",
    "Tape",
    "__version__",
    "decompose",
    "demo",
    "load_benchmark",
    "load_stack",
    "read_disparity",
    "read_image",
    "read_matte",
    "render",
    "render_image",
    "render_with_tape",
    "save_stack",
    "trace",
    "vjp",
]


def load_benchmark(directory: Union[str, "os.PathLike[str]"]) -> Iterator[Dict[str, Any]]:
    """Iterates over the scenes of a ray-traced benchmark (``drbokeh benchmark make``).

    The scene directories are listed (sorted by name) when this is called, so a missing or
    empty benchmark raises at once; each scene is loaded when the iteration reaches it.
    Each scene is a dict: ``name``, ``path``, ``aif`` (H, W, 3) the all-in-focus image,
    ``disparity`` (H, W), ``layers`` (the layered ground truth: a dict of ``rgb``,
    ``alpha``, ``disparity`` for :func:`render`), ``ground_truth`` (H, W, 3) the traced
    defocused image (display-encoded, clipped), ``camera`` (``focus``, ``blur``,
    ``window``, ``gamma``, ``offset``, ``highlight``: keyword arguments of :func:`render`)
    and ``max_coc_px``. Arrays are float32::

        for scene in drbokeh.load_benchmark("bench"):
            out = drbokeh.render(**scene["layers"], **scene["camera"], preset="paper")
    """
    dirs = _native.benchmark_scenes(directory)

    def scenes() -> Iterator[Dict[str, Any]]:
        for d in dirs:
            yield _native.load_benchmark_scene(d)

    return scenes()


def __getattr__(name: str) -> Any:
    # `drbokeh.torch` without an explicit `import drbokeh.torch`: imported (with PyTorch)
    # only when first used.
    if name == "torch":
        import importlib

        return importlib.import_module(".torch", __name__)
    raise AttributeError(f"module 'drbokeh' has no attribute {name!r}")
