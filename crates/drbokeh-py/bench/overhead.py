"""The Python layer's overhead: drbokeh.render on a 1 MP two-layer float32 stack against
the Rust library's drbokeh::render on the same stack, in the same process, interleaved.

    python crates/drbokeh-py/bench/overhead.py [--size 1000] [--rounds 9] [--threads N]

`drbokeh.render` is the whole Python call: checking and copying the three arrays into the
library's layer stack (one copy each), resolving the settings, rendering with the GIL
released, and handing the image to NumPy. The library's time is measured by
`drbokeh._native.time_library_render`, which converts the stack once and then times only
`drbokeh::render(&stack, &settings, engine, &NoProgress)` (what a Rust caller pays). Each
round runs one of each, alternating which goes first; the report gives the medians and
the ratio of medians; then the Python call's own work is timed alone (the arguments
converted and the settings resolved, no render).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

import drbokeh
from drbokeh import _native


def stack(size: int, seed: int = 0):
    """Two layers: a soft-edged disc with texture in front (disparity 0.8) of a textured
    background (disparity 0.2 .. 0.3)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    r = np.hypot(x - 0.45, y - 0.5)
    alpha0 = np.clip((0.3 - r) * 40, 0, 1)
    rgb = rng.uniform(0.05, 0.95, size=(2, size, size, 3)).astype(np.float32)
    alpha = np.stack([alpha0, np.ones_like(alpha0)]).astype(np.float32)
    disparity = np.stack([np.full_like(x, 0.8), 0.2 + 0.1 * x]).astype(np.float32)
    return rgb, alpha, disparity


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1000, help="image side (default 1000: 1 MP)")
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--focus", type=float, default=0.5)
    ap.add_argument("--blur", type=float, default=20.0)
    ap.add_argument("--engine", default="auto")
    a = ap.parse_args()
    rgb, alpha, disparity = stack(a.size)
    kw = dict(focus=a.focus, blur=a.blur, engine=a.engine, threads=a.threads)
    # Warm up both paths (page faults, thread pool start).
    drbokeh.render(rgb, alpha, disparity, **kw)
    _native.time_library_render(rgb, alpha, disparity, **kw)
    py, rs = [], []
    load0 = os.getloadavg()
    for i in range(a.rounds):
        order = ("py", "rs") if i % 2 == 0 else ("rs", "py")
        for which in order:
            if which == "py":
                t0 = time.perf_counter()
                drbokeh.render(rgb, alpha, disparity, **kw)
                py.append(time.perf_counter() - t0)
            else:
                rs.extend(_native.time_library_render(rgb, alpha, disparity, **kw, repeats=1))
    mp, mr = statistics.median(py), statistics.median(rs)
    # Paired differences (the two calls of a round run back to back) are less sensitive
    # to the machine's load drifting between rounds.
    diff = statistics.median(p - r for p, r in zip(py, rs))
    load = os.getloadavg()
    print(f"stack: 2 layers, {a.size}x{a.size} ({a.size * a.size / 1e6:.2f} MP), float32, "
          f"focus {a.focus}, blur {a.blur}, engine {a.engine}, threads {a.threads or 'all'} "
          f"({os.cpu_count()} cores), {a.rounds} rounds")
    print(f"load average (1 min) before {load0[0]:.2f}, after {load[0]:.2f}")
    print(f"drbokeh.render (Python):     median {mp * 1e3:8.1f} ms  min {min(py) * 1e3:8.1f} ms")
    print(f"drbokeh::render (Rust API):  median {mr * 1e3:8.1f} ms  min {min(rs) * 1e3:8.1f} ms")
    print(f"overhead: median ratio {mp / mr:.4f} ({(mp / mr - 1) * 100:+.2f} %), "
          f"min ratio {min(py) / min(rs):.4f} ({(min(py) / min(rs) - 1) * 100:+.2f} %)")
    print(f"median paired difference {diff * 1e3:+.1f} ms ({diff / mr * 100:+.2f} % of the Rust median)")
    # The Python call's own work, without the render: the same argument checks, copies,
    # validation and settings as drbokeh.render (time_library_render with no repeats).
    conv = []
    for _ in range(a.rounds):
        t0 = time.perf_counter()
        _native.time_library_render(rgb, alpha, disparity, **kw, repeats=0)
        conv.append(time.perf_counter() - t0)
    mc = statistics.median(conv)
    print(f"arguments alone (checks, one copy per array, validation, settings): median "
          f"{mc * 1e3:.1f} ms, min {min(conv) * 1e3:.1f} ms ({mc / mr * 100:.2f} % of the Rust median)")


if __name__ == "__main__":
    main()
