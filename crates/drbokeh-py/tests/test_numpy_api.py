"""The NumPy API's conventions: dtypes, strides, threads, the GIL, warnings, and errors."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest

import drbokeh
from conftest import random_stack

CAM = dict(focus=0.45, blur=10.0, window=13)


def test_dtype_follows_the_inputs():
    s32 = random_stack(1, 2, 11, 13, dtype=np.float32)
    assert drbokeh.render(**s32, **CAM).dtype == np.float32
    s64 = {k: v.astype(np.float64) for k, v in s32.items()}
    assert drbokeh.render(**s64, **CAM).dtype == np.float64
    # Mixed: promoted to float64, and equal to the all-float64 render.
    mixed = dict(s32, disparity=s64["disparity"])
    np.testing.assert_array_equal(drbokeh.render(**mixed, **CAM), drbokeh.render(**s64, **CAM))
    g = drbokeh.vjp(**s32, grad_output=np.ones((11, 13, 3)), **CAM)
    assert all(v.dtype == np.float64 for v in g.values())


def test_auto_engine_is_fast_in_f32_and_exact_in_f64():
    s32 = random_stack(2, 2, 15, 12, dtype=np.float32)
    s64 = {k: v.astype(np.float64) for k, v in s32.items()}
    # In float32, auto picks spans or the fast engine's taps per band and layer: within the
    # span engine's tested bound of the fast engine.
    auto32 = drbokeh.render(**s32, **CAM)
    np.testing.assert_array_equal(auto32, drbokeh.render(**s32, **CAM, engine="auto"))
    assert np.abs(auto32 - drbokeh.render(**s32, **CAM, engine="fast")).max() < 1e-5
    exact = drbokeh.render(**s64, **CAM, engine="reference")
    np.testing.assert_array_equal(drbokeh.render(**s64, **CAM), exact)
    np.testing.assert_array_equal(drbokeh.render(**s64, **CAM, engine="threaded"), exact)
    assert drbokeh.render_with_tape(**s64, **CAM)[1].engine == "threaded"
    assert drbokeh.render_with_tape(**s32, **CAM)[1].engine == "spans"
    # The fast engine agrees with the exact one (the library's tested bound).
    assert np.abs(drbokeh.render(**s32, **CAM) - exact).max() < 1e-4


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_non_contiguous_inputs_give_the_same_bytes(dtype):
    s = random_stack(3, 2, 14, 18, dtype=dtype)
    want = drbokeh.render(**s, **CAM)
    fortran = {k: np.asfortranarray(v) for k, v in s.items()}
    assert not fortran["rgb"].flags.c_contiguous
    np.testing.assert_array_equal(drbokeh.render(**fortran, **CAM), want)
    # Strided views into larger arrays, and negative strides.
    big = {k: np.repeat(np.repeat(v, 2, axis=1), 3, axis=2) for k, v in s.items()}
    strided = {k: v[:, ::2, ::3] for k, v in big.items()}
    np.testing.assert_array_equal(drbokeh.render(**strided, **CAM), want)
    flipped = {k: v[:, ::-1][:, ::-1] for k, v in s.items()}
    np.testing.assert_array_equal(drbokeh.render(**flipped, **CAM), want)
    g = np.random.default_rng(0).uniform(-1, 1, size=(14, 18, 3)).astype(dtype)
    g_want = drbokeh.vjp(**s, grad_output=g, **CAM)
    g_got = drbokeh.vjp(**strided, grad_output=np.asfortranarray(g), **CAM)
    for key in g_want:
        np.testing.assert_array_equal(g_got[key], g_want[key])
    # A broadcast (zero-stride) upstream gradient, as autograd passes for a sum.
    ones = np.broadcast_to(np.ones(1, dtype), (14, 18, 3))
    np.testing.assert_array_equal(
        drbokeh.vjp(**s, grad_output=ones, **CAM)["rgb"],
        drbokeh.vjp(**s, grad_output=np.ones((14, 18, 3), dtype), **CAM)["rgb"],
    )


def test_lists_are_accepted_as_arrays():
    s = random_stack(4, 1, 5, 6, dtype=np.float64)
    lists = {k: v.tolist() for k, v in s.items()}
    np.testing.assert_array_equal(drbokeh.render(**lists, **CAM), drbokeh.render(**s, **CAM))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_threads_do_not_change_the_output(dtype):
    s = random_stack(5, 2, 33, 29, dtype=dtype)
    g = np.random.default_rng(1).uniform(-1, 1, size=(33, 29, 3)).astype(dtype)
    base = drbokeh.render(**s, **CAM)
    grads = drbokeh.vjp(**s, grad_output=g, **CAM)
    for threads in (1, 2, 3):
        np.testing.assert_array_equal(drbokeh.render(**s, **CAM, threads=threads), base)
        got = drbokeh.vjp(**s, grad_output=g, **CAM, threads=threads)
        for key in grads:
            np.testing.assert_array_equal(got[key], grads[key])


def test_vjp_is_the_tape_backward():
    s = random_stack(6, 3, 12, 10, dtype=np.float64)
    g = np.random.default_rng(2).uniform(-1, 1, size=(12, 10, 3))
    image, tape = drbokeh.render_with_tape(**s, **CAM, preset="paper")
    np.testing.assert_array_equal(image, drbokeh.render(**s, **CAM, preset="paper"))
    assert tape.shape == (3, 12, 10) and tape.dtype == "float64"
    a = tape.backward(g)
    b = drbokeh.vjp(**s, grad_output=g, **CAM, preset="paper")
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    # The tape can be reused, and the rescaling applies the published rule to its values.
    r = tape.backward(g * 1e-3, rescale_small_gradients=True)
    exact = tape.backward(g * 1e-3)
    for key in ("rgb", "alpha", "disparity"):
        e = exact[key]
        small = (np.abs(e) >= 1e-6) & (np.abs(e) < 1e-2)
        assert small.any()
        np.testing.assert_array_equal(r[key][small], np.sign(e[small]) * 1e-2)
        np.testing.assert_array_equal(r[key][~small], e[~small])


def test_the_gil_is_released_while_rendering():
    # Big enough that the threaded engine takes well over 0.2 s on one thread.
    s = drbokeh.demo(480, 360)
    count = [0]
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            count[0] += 1

    t = threading.Thread(target=spin)
    t.start()
    try:
        # The spinner's rate while the main thread sleeps (the GIL free).
        c0, t0 = count[0], time.perf_counter()
        time.sleep(0.2)
        rate = (count[0] - c0) / (time.perf_counter() - t0)
        c0, t0 = count[0], time.perf_counter()
        drbokeh.render(s["rgb"], s["alpha"], s["disparity"], focus=s["focus"], blur=30,
                       engine="threaded", window=21, threads=1)
        elapsed = time.perf_counter() - t0
        during = count[0] - c0
    finally:
        stop.set()
        t.join()
    assert elapsed > 0.2, f"the render took {elapsed:.3f} s: too quick to tell"
    # Holding the GIL, the call would leave the spinner at most a switch interval (5 ms)
    # on either side: a few per cent of the render's time, not a tenth.
    assert during > 0.1 * rate * elapsed, (during, rate, elapsed)


def test_a_clipped_automatic_window_warns():
    s = random_stack(7, 2, 20, 20, dtype=np.float64)
    with pytest.warns(drbokeh.DrBokehWarning, match="automatic window is capped"):
        drbokeh.render(**s, focus=0.0, blur=200)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        drbokeh.render(**s, focus=0.0, blur=200, window=31)
        drbokeh.render(**s, focus=0.5, blur=10)


def test_aperture_kernel_as_array_or_file(tmp_path):
    s = random_stack(8, 2, 16, 16)
    y, x = np.mgrid[-4:5, -4:5]
    kernel = (np.abs(x) + np.abs(y) <= 4).astype(np.float64)
    np.save(tmp_path / "k.npy", kernel)
    a = drbokeh.render(**s, **CAM, aperture=kernel)
    b = drbokeh.render(**s, **CAM, aperture=f"kernel:{tmp_path / 'k.npy'}")
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, drbokeh.render(**s, **CAM))


def test_demo_and_stack_files(tmp_path):
    d = drbokeh.demo(64, 48)
    assert d["rgb"].shape == (3, 48, 64, 3) and 0 < d["focus"] < 1
    drbokeh.save_stack(tmp_path / "demo.npz", d["rgb"], d["alpha"], d["disparity"])
    back = drbokeh.load_stack(tmp_path / "demo.npz")
    np.testing.assert_array_equal(back["alpha"], d["alpha"])


def test_import_needs_no_torch():
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import drbokeh, numpy as np\n"
        "s = drbokeh.demo(32, 24)\n"
        "out = drbokeh.render(s['rgb'], s['alpha'], s['disparity'], focus=s['focus'], blur=8)\n"
        "assert out.shape == (24, 32, 3)\n"
        "try:\n"
        "    import drbokeh.torch\n"
        "except ImportError as e:\n"
        "    assert 'needs PyTorch' in str(e), e\n"
        "else:\n"
        "    raise SystemExit('drbokeh.torch imported without torch')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
    # And a plain import does not load torch.
    code = "import sys, drbokeh; assert 'torch' not in sys.modules, 'torch was imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


# ---------------------------------------------------------------------------- bad inputs

GOOD = random_stack(10, 2, 6, 7)


def _with(**changes):
    s = dict(GOOD)
    s.update(changes)
    return s


def _nan(a, index):
    a = a.copy()
    a[index] = np.nan
    return a


@pytest.mark.parametrize(
    "stack,camera,error,match",
    [
        (_with(rgb=GOOD["rgb"][0]), {}, ValueError, r"rgb has shape \(6, 7, 3\), expected \(N, H, W, 3\)"),
        (_with(rgb=GOOD["rgb"][..., :2]), {}, ValueError, r"expected \(N, H, W, 3\)"),
        (_with(alpha=GOOD["alpha"][:, :5]), {}, ValueError, r"alpha has shape \(2, 5, 7\), expected \(2, 6, 7\) to match rgb"),
        (_with(disparity=GOOD["disparity"][:1]), {}, ValueError, "disparity has shape"),
        (_with(rgb=GOOD["rgb"][:0], alpha=GOOD["alpha"][:0], disparity=GOOD["disparity"][:0]), {}, ValueError, "no layers"),
        (_with(rgb=(GOOD["rgb"] * 255).astype(np.uint8)), {}, ValueError, "rgb has dtype uint8; expected float32 or float64"),
        (_with(alpha=GOOD["alpha"].astype(np.float16)), {}, ValueError, "alpha has dtype float16"),
        (_with(rgb=_nan(GOOD["rgb"], (0, 1, 2, 0))), {}, ValueError, "layer 0 rgb"),
        (_with(alpha=_nan(GOOD["alpha"], (1, 3, 3))), {}, ValueError, "layer 1 alpha"),
        (_with(disparity=_nan(GOOD["disparity"], (0, 0, 0))), {}, ValueError, "layer 0 disparity"),
        (_with(alpha=GOOD["alpha"] + 0.5), {}, ValueError, r"outside \[0, 1\]"),
        (_with(rgb=GOOD["rgb"] - 0.5), {}, ValueError, "negative colour"),
        (GOOD, dict(focus=1.5), ValueError, r"invalid parameter focus: focus disparity must be in \[0, 1\], got 1.5"),
        (GOOD, dict(focus=float("nan")), ValueError, "invalid parameter focus:"),
        (GOOD, dict(blur=-1.0), ValueError, "invalid parameter blur"),
        (GOOD, dict(window=10), ValueError, "window size must be odd"),
        (GOOD, dict(preset="fancy"), ValueError, "unknown preset 'fancy'"),
        (GOOD, dict(engine="gpu"), ValueError, "unknown engine 'gpu'"),
        (GOOD, dict(aperture="blob"), ValueError, "aperture"),
        (GOOD, dict(aperture="kernel:/no/such/kernel.png"), OSError, "/no/such/kernel.png"),
        (GOOD, dict(aperture=np.zeros((3, 3))), ValueError, "aperture kernel"),
        (GOOD, dict(threads=0), ValueError, "invalid parameter threads: must be between 1 and 1024"),
        (GOOD, dict(gamma=0.0), ValueError, "invalid parameter gamma"),
    ],
)
def test_bad_render_inputs_raise(stack, camera, error, match):
    kwargs = dict(focus=0.5, blur=5.0)
    kwargs.update(camera)
    with pytest.raises(error, match=match):
        drbokeh.render(**stack, **kwargs)


def test_bad_gradient_inputs_raise():
    with pytest.raises(ValueError, match=r"grad_output has shape \(6, 7\), but the render is \(6, 7, 3\)"):
        drbokeh.vjp(**GOOD, grad_output=np.ones((6, 7)), focus=0.5, blur=5)
    _, tape = drbokeh.render_with_tape(**GOOD, focus=0.5, blur=5)
    with pytest.raises(ValueError, match="grad_output has shape"):
        tape.backward(np.ones((7, 6, 3), np.float32))
    with pytest.raises(ValueError, match="non-finite"):
        tape.backward(np.full((6, 7, 3), np.nan, np.float32))


def test_bad_files_raise_oserror(tmp_path):
    with pytest.raises(OSError, match="cannot open"):
        drbokeh.load_stack(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip file at all")
    with pytest.raises(OSError, match="junk.npz: not a readable NPZ archive"):
        drbokeh.load_stack(tmp_path / "junk.npz")
    np.savez(tmp_path / "partial.npz", rgb=GOOD["rgb"])
    with pytest.raises(OSError, match="missing key 'alpha'"):
        drbokeh.load_stack(tmp_path / "partial.npz")
    (tmp_path / "junk.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    with pytest.raises(OSError, match="junk.png"):
        drbokeh.read_image(tmp_path / "junk.png")
    with pytest.raises(OSError, match="cannot open"):
        drbokeh.read_disparity(tmp_path / "missing.png")
    with pytest.raises(OSError):
        drbokeh.trace(tmp_path / "missing.json")
    with pytest.raises(OSError, match="does not exist"):
        drbokeh.load_benchmark(tmp_path / "nothing")
    with pytest.raises(ValueError, match="use a .npz output name"):
        drbokeh.save_stack(tmp_path / "stack.npy", **GOOD)
    assert not (tmp_path / "stack.npy").exists()
    with pytest.raises(OSError, match="output directory .* does not exist"):
        drbokeh.save_stack(tmp_path / "no" / "such" / "stack.npz", **GOOD)
    with pytest.raises(ValueError, match="dtype must be float32 or float64"):
        drbokeh.load_stack(tmp_path / "partial.npz", dtype="int32")


def test_bad_photo_inputs_raise():
    image = np.random.default_rng(0).uniform(size=(8, 9, 3)).astype(np.float32)
    disp = np.random.default_rng(1).uniform(size=(8, 9)).astype(np.float32)
    with pytest.raises(ValueError, match=r"disparity: size 9x7 does not match image \(9x8\)"):
        drbokeh.render_image(image, disp[:7], focus=0.5)
    with pytest.raises(ValueError, match=r"image has shape \(8, 9\), expected \(H, W, 3\)"):
        drbokeh.render_image(image[..., 0], disp, focus=0.5)
    with pytest.raises(ValueError, match="focus or focus_at, not both"):
        drbokeh.render_image(image, disp, focus=0.5, focus_at=(1, 1))
    with pytest.raises(ValueError, match="invalid parameter focus_at: pixel \\(20, 1\\) is outside the 9x8 image"):
        drbokeh.render_image(image, disp, focus_at=(20, 1))
    with pytest.raises(ValueError, match="cannot be combined"):
        drbokeh.render_image(image, disp, alpha=disp, single_layer=True)
    with pytest.raises(ValueError, match=r"alpha matte: value .* outside \[0, 1\]"):
        drbokeh.render_image(image, disp, alpha=disp + 1, focus=0.5)
    with pytest.raises(ValueError, match="invalid parameter max_layers"):
        drbokeh.decompose(image, disp, max_layers=0)
    with pytest.raises(ValueError, match="pass both or neither"):
        drbokeh.decompose(image, disp, focus=0.5)
    with pytest.raises(ValueError, match="disparity map"):
        drbokeh.decompose(image, _nan(disp, (2, 2)))
