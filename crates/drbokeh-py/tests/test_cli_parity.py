"""The NumPy API computes exactly what the command line computes: renders, gradients,
decompositions, stacks, traces and benchmark scenes, compared bit for bit."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import drbokeh
from conftest import cli_camera_args, photo, random_stack, stack_npz, write_png

# (stack seed, N, H, W, camera): each with presets paper and physical, float32 and float64.
STACKS = [
    (1, 2, 17, 23, dict(focus=0.35, blur=12.0, window=11)),
    (2, 3, 20, 31, dict(focus=0.6, blur=20.0, window=None, aperture="hexagon", highlight=True)),
    (3, 1, 9, 14, dict(focus=0.2, blur=7.5, window=15, gamma=2.0, offset=0.05)),
]


def _render_args(camera):
    return {k: v for k, v in camera.items() if v is not None}


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("preset", ["paper", "physical"])
@pytest.mark.parametrize("seed,n,h,w,camera", STACKS)
def test_render_equals_cli(cli, tmp_path, seed, n, h, w, camera, preset, dtype):
    stack = random_stack(seed, n, h, w, dtype=dtype)
    path = stack_npz(tmp_path / "s.npz", stack)
    out = tmp_path / "out.npy"
    f64 = ["--f64"] if dtype == np.float64 else []
    cli("render", "--layers", path, *cli_camera_args(camera), "--preset", preset, *f64, "-o", out, "-q")
    want = np.load(out)
    got = drbokeh.render(**stack, **_render_args(camera), preset=preset)
    assert got.dtype == dtype and want.dtype == dtype
    assert got.shape == (h, w, 3)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("preset", ["paper", "physical"])
@pytest.mark.parametrize("seed,n,h,w,camera", STACKS[:2])
def test_vjp_equals_cli(cli, tmp_path, seed, n, h, w, camera, preset, dtype):
    stack = random_stack(seed, n, h, w, dtype=dtype)
    path = stack_npz(tmp_path / "s.npz", stack)
    g = np.random.default_rng(seed + 100).uniform(-1, 1, size=(h, w, 3)).astype(dtype)
    np.save(tmp_path / "g.npy", g)
    out = tmp_path / "grads.npz"
    f64 = ["--f64"] if dtype == np.float64 else []
    cli(
        "vjp", "--layers", path, "--grad-output", tmp_path / "g.npy", *cli_camera_args(camera),
        "--preset", preset, *f64, "-o", out, "-q",
    )
    want = np.load(out)
    got = drbokeh.vjp(**stack, grad_output=g, **_render_args(camera), preset=preset)
    assert set(got) == {"rgb", "alpha", "disparity", "blur", "focus"}
    for key in got:
        assert got[key].dtype == dtype, key
        assert got[key].shape == want[key].shape, key
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)


def test_vjp_rescaled_equals_cli(cli, tmp_path):
    stack = random_stack(4, 2, 12, 13, dtype=np.float64)
    path = stack_npz(tmp_path / "s.npz", stack)
    g = np.random.default_rng(5).uniform(-1e-3, 1e-3, size=(12, 13, 3))
    np.save(tmp_path / "g.npy", g)
    out = tmp_path / "grads.npz"
    cli(
        "vjp", "--layers", path, "--grad-output", tmp_path / "g.npy", "--focus", "0.4",
        "--blur", "9", "--window", "9", "--f64", "--rescale-small-gradients", "-o", out, "-q",
    )
    want = np.load(out)
    got = drbokeh.vjp(
        **stack, grad_output=g, focus=0.4, blur=9, window=9, rescale_small_gradients=True
    )
    for key in got:
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)
    exact = drbokeh.vjp(**stack, grad_output=g, focus=0.4, blur=9, window=9)
    assert not np.array_equal(exact["rgb"], got["rgb"]), "the rescaling changed nothing"


@pytest.fixture
def photo_files(tmp_path):
    image, disparity = photo(7, 40, 56)
    write_png(tmp_path / "img.png", image)
    np.save(tmp_path / "disp.npy", disparity.astype(np.float32))
    y, x = np.mgrid[0:40, 0:56]
    matte = np.clip(1.2 - np.hypot(x - 22, y - 20) / 12, 0, 1).astype(np.float32)
    np.save(tmp_path / "matte.npy", matte)
    return tmp_path


@pytest.mark.parametrize(
    "cli_args,kwargs,layers",
    [
        # Focus on the background, the disc blurred: two layers.
        (["--focus", "0.1", "--blur", "14"], dict(focus=0.1, blur=14.0), 2),
        (["--focus-at", "50,5", "--blur", "10", "--max-layers", "2"], dict(focus_at=(50, 5), blur=10.0, max_layers=2), 2),
        # Focus on the disc (tapped, or the centre pixel): one layer, and a note.
        (["--focus-at", "20,20", "--blur", "20"], dict(focus_at=(20, 20), blur=20.0), 1),
        (["--blur", "10"], dict(blur=10.0), 1),
        (["--focus", "0.3", "--single-layer"], dict(focus=0.3, single_layer=True), None),
        (["--focus", "0.25", "--blur", "12", "--alpha", "MATTE"], dict(focus=0.25, blur=12.0, alpha="MATTE"), None),
        (["--focus", "0.5", "--f64", "--window", "21"], dict(focus=0.5, window=21, dtype=np.float64), 2),
    ],
)
def test_render_image_equals_cli(cli, photo_files, cli_args, kwargs, layers):
    d = photo_files
    cli_args = [str(d / "matte.npy") if a == "MATTE" else a for a in cli_args]
    out = d / "out.npy"
    cli("render", "--image", d / "img.png", "--disparity", d / "disp.npy", *cli_args, "-o", out, "-q")
    want = np.load(out)
    dtype = kwargs.pop("dtype", np.float32)
    image, encoding = drbokeh.read_image(d / "img.png", dtype=dtype)
    assert encoding == "encoded"
    disparity = drbokeh.read_disparity(d / "disp.npy", dtype=dtype)
    if kwargs.get("alpha") == "MATTE":
        kwargs["alpha"] = drbokeh.read_matte(d / "matte.npy", dtype=dtype)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = drbokeh.render_image(image, disparity, **kwargs)
    notes = [str(w.message) for w in caught if issubclass(w.category, drbokeh.DrBokehWarning)]
    assert any("single opaque layer" in n for n in notes) == (layers == 1), notes
    assert got.dtype == want.dtype == dtype
    np.testing.assert_array_equal(got, want)


def test_render_image_linear_exr_equals_cli(cli, photo_files, tmp_path):
    # An EXR (linear light) made by the CLI itself, then rendered from as an image.
    d = photo_files
    exr = tmp_path / "linear.exr"
    cli("render", "--image", d / "img.png", "--disparity", d / "disp.npy", "--single-layer",
        "--focus", "0.2", "--blur", "0", "-o", exr, "-q")
    out = d / "out.npy"
    cli("render", "--image", exr, "--disparity", d / "disp.npy", "--focus", "0.9", "--blur", "15",
        "--gamma", "2.4", "-o", out, "-q")
    image, encoding = drbokeh.read_image(exr)
    assert encoding == "linear"
    got = drbokeh.render_image(
        image, drbokeh.read_disparity(d / "disp.npy"), linear=True, focus=0.9, blur=15, gamma=2.4
    )
    np.testing.assert_array_equal(got, np.load(out))


@pytest.mark.parametrize("matte", [False, True])
def test_decompose_equals_cli_layers(cli, photo_files, matte):
    d = photo_files
    out = d / "stack.npz"
    extra = ["--alpha", d / "matte.npy"] if matte else ["--focus", "0.2", "--blur", "10"]
    cli("layers", "--image", d / "img.png", "--disparity", d / "disp.npy", *extra, "-o", out,
        "--no-preview", "-q")
    want = np.load(out)
    image, _ = drbokeh.read_image(d / "img.png")
    kwargs = dict(alpha=drbokeh.read_matte(d / "matte.npy")) if matte else dict(focus=0.2, blur=10)
    got = drbokeh.decompose(image, drbokeh.read_disparity(d / "disp.npy"), **kwargs)
    assert got["rgb"].shape[0] == (2 if matte else len(got["thresholds"]) + 1)
    assert got["rgb"].shape[0] >= 2, got["notes"]
    for key in ("rgb", "alpha", "disparity"):
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)


def test_stack_files_round_trip_through_the_cli(cli, tmp_path):
    stack = random_stack(9, 2, 10, 12)
    path = tmp_path / "saved.npz"
    drbokeh.save_stack(path, **stack)
    loaded = drbokeh.load_stack(path)
    for key in stack:
        np.testing.assert_array_equal(loaded[key], stack[key])
    out = tmp_path / "out.npy"
    cli("render", "--layers", path, "--focus", "0.5", "--blur", "8", "-o", out, "-q")
    np.testing.assert_array_equal(drbokeh.render(**loaded, focus=0.5, blur=8), np.load(out))
    f64 = drbokeh.load_stack(path, dtype="float64")
    assert f64["rgb"].dtype == np.float64
    np.testing.assert_array_equal(f64["rgb"], stack["rgb"].astype(np.float64))


SCENE = {
    "name": "tiny",
    "camera": {
        "lens": {"model": "spherical", "curvature_radius_mm": 50.0, "rim_radius_mm": 10.0,
                 "eta": 1.5, "aperture_radius_mm": 2.5},
        "width_px": 40, "height_px": 30, "fov_deg": 10.0, "focus_distance_mm": 400.0,
    },
    "render": {"spp": 16, "aif_spp": 4, "seed": 1},
    "billboards": [
        {"name": "fence", "depth_mm": 300.0, "center": [0.4, 0.5], "size": [0.5, 0.5],
         "texture": {"type": "procedural", "kind": "fence", "seed": 5}},
        {"name": "background", "depth_mm": 3000.0, "center": [0.5, 0.5], "size": [1.6, 1.6],
         "texture": {"type": "solid", "color": [0.3, 0.5, 0.9], "alpha": 1.0}},
    ],
}


def test_trace_equals_cli(cli, tmp_path):
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(SCENE))
    cli("trace", scene, "--spp", "4", "--seed", "3", "--output", tmp_path / "out", "-q")
    got = drbokeh.trace(scene, spp=4, seed=3)
    out = tmp_path / "out"
    for key in ("rgb", "alpha", "disparity"):
        np.testing.assert_array_equal(got["layers"][key], np.load(out / "layers.npz")[key])
    np.testing.assert_array_equal(got["depth_mm"], np.load(out / "depth.npy"))
    np.testing.assert_array_equal(got["disparity"], np.load(out / "disparity.npy"))
    record = json.loads((out / "scene.json").read_text())["derived"]
    assert got["camera"]["blur"] == pytest.approx(record["blur"], rel=1e-12)
    assert got["camera"]["focus"] == pytest.approx(record["focus"], rel=1e-12)
    assert got["bokeh"].shape == got["aif"].shape == (30, 40, 3)
    # The traced defocused image is the one the CLI writes (16-bit PNG of the encoding).
    png, _ = drbokeh.read_image(out / "bokeh.png")
    assert np.abs(np.clip(got["bokeh"], 0, 1) - png).max() <= 0.5 / 65535 + 1e-6


def test_load_benchmark_equals_cli_files(cli, tmp_path):
    bench = tmp_path / "bench"
    cli("benchmark", "make", "--scenes", "2", "--size", "24", "--spp", "4", "--output", bench, "-q")
    scenes = list(drbokeh.load_benchmark(bench))
    assert [s["name"] for s in scenes] == ["scene_000", "scene_001"]
    for s in scenes:
        d = bench / s["name"]
        stack = drbokeh.load_stack(d / "layers.npz")
        for key in stack:
            np.testing.assert_array_equal(s["layers"][key], stack[key])
        np.testing.assert_array_equal(s["aif"], drbokeh.read_image(d / "aif.png")[0])
        np.testing.assert_array_equal(s["ground_truth"], drbokeh.read_image(d / "bokeh.png")[0])
        record = json.loads((d / "scene.json").read_text())["derived"]
        cam = s["camera"]
        assert cam["blur"] == record["blur"]
        assert cam["focus"] == pytest.approx(record["focus"], abs=1e-6)
        assert set(cam) == {"focus", "blur", "window", "gamma", "offset", "highlight"}
        # The camera dict is render's keyword arguments.
        out = drbokeh.render(**s["layers"], **cam, preset="paper")
        assert out.shape == (24, 24, 3)
    with pytest.raises(OSError, match="no scene directories"):
        drbokeh.load_benchmark(tmp_path)
