"""drbokeh.torch: gradients (gradcheck in float64), batches, modules, errors, and a small
optimisation through the renderer."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the PyTorch layer needs torch")

import drbokeh  # noqa: E402
import drbokeh.torch as dt  # noqa: E402
from conftest import random_stack  # noqa: E402

CAM = dict(window=11)


def fd_inputs(seed: int, n: int = 2, h: int = 5, w: int = 6, dtype=torch.float64):
    """Inputs for finite differences: alpha strictly inside (0, 1), colour inside (0, 1),
    disparities in separate bands away from the focus (no kink of |d - f| nearby)."""
    s = random_stack(seed, n, h, w, dtype=np.float64, alpha_lo=0.1)
    t = {k: torch.tensor(v, dtype=dtype) for k, v in s.items()}
    focus = torch.tensor(0.55, dtype=dtype)
    blur = torch.tensor(6.0, dtype=dtype)
    return t["rgb"], t["alpha"], t["disparity"], focus, blur


@pytest.mark.parametrize("preset", ["paper", "physical"])
@pytest.mark.parametrize("wrt", ["rgb", "alpha", "disparity", "focus", "blur", "all"])
def test_gradcheck_float64(preset, wrt):
    names = ["rgb", "alpha", "disparity", "focus", "blur"]
    inputs = list(fd_inputs(1))
    for i, name in enumerate(names):
        inputs[i].requires_grad_(wrt in (name, "all"))

    def f(*args):
        return dt.render(*args, preset=preset, **CAM)

    assert torch.autograd.gradcheck(f, tuple(inputs))


@pytest.mark.parametrize("preset", ["paper", "physical"])
def test_gradcheck_batched_with_per_item_focus(preset):
    items = [fd_inputs(seed, n=2, h=4, w=5) for seed in (2, 3)]
    rgb, alpha, disp = (torch.stack([it[k] for it in items]).requires_grad_() for k in range(3))
    focus = torch.tensor([0.5, 0.6], dtype=torch.float64, requires_grad=True)
    blur = torch.tensor(5.0, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda *a: dt.render(*a, preset=preset, **CAM), (rgb, alpha, disp, focus, blur)
    )


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_forward_and_gradients_equal_the_numpy_api(dtype):
    s = random_stack(4, 3, 9, 11, dtype=np.float64)
    rgb, alpha, disp = (torch.tensor(s[k], dtype=dtype, requires_grad=True) for k in s)
    focus = torch.tensor(0.4, dtype=dtype, requires_grad=True)
    blur = torch.tensor(9.0, dtype=dtype, requires_grad=True)
    out = dt.render(rgb, alpha, disp, focus, blur, **CAM)
    assert out.dtype == dtype and out.shape == (9, 11, 3)
    np_in = {k: v.astype(np.float32 if dtype == torch.float32 else np.float64) for k, v in s.items()}
    # The forward output is the tape's, which is auto's render in both precisions (in
    # float32 auto records the span render for the span adjoint).
    want_out = drbokeh.render(**np_in, focus=0.4, blur=9.0, engine="auto", **CAM)
    np.testing.assert_array_equal(out.detach().numpy(), want_out)
    g = torch.linspace(-1, 1, out.numel(), dtype=dtype).reshape(out.shape)
    out.backward(g)
    want = drbokeh.vjp(**np_in, grad_output=g.numpy(), focus=0.4, blur=9.0, **CAM)
    for t, key in ((rgb, "rgb"), (alpha, "alpha"), (disp, "disparity"), (focus, "focus"), (blur, "blur")):
        assert t.grad.dtype == dtype
        np.testing.assert_array_equal(t.grad.numpy(), want[key], err_msg=key)


def test_batch_equals_loop():
    stacks = [random_stack(seed, 2, 8, 10, dtype=np.float64) for seed in (5, 6, 7)]
    batch = {k: torch.tensor(np.stack([s[k] for s in stacks]), requires_grad=True) for k in stacks[0]}
    focus = torch.tensor([0.3, 0.5, 0.7], dtype=torch.float64, requires_grad=True)
    blur = torch.tensor(8.0, dtype=torch.float64, requires_grad=True)
    out = dt.render(batch["rgb"], batch["alpha"], batch["disparity"], focus, blur, **CAM)
    assert out.shape == (3, 8, 10, 3)
    weights = torch.rand(out.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    (out * weights).sum().backward()
    blur_grad = 0.0
    for i, s in enumerate(stacks):
        item = {k: torch.tensor(v, requires_grad=True) for k, v in s.items()}
        f = focus.detach()[i].clone().requires_grad_()
        b = torch.tensor(8.0, dtype=torch.float64, requires_grad=True)
        o = dt.render(item["rgb"], item["alpha"], item["disparity"], f, b, **CAM)
        assert torch.equal(o, out[i].detach())
        (o * weights[i]).sum().backward()
        for k in item:
            assert torch.equal(item[k].grad, batch[k].grad[i]), k
        assert torch.equal(f.grad, focus.grad[i])
        blur_grad += float(b.grad)
    assert float(blur.grad) == pytest.approx(blur_grad, rel=1e-12)


def test_python_floats_and_partial_requires_grad():
    rgb, alpha, disp, _, _ = fd_inputs(8)
    disp.requires_grad_()
    out = dt.render(rgb, alpha, disp, 0.55, 6.0, **CAM)
    out.sum().backward()
    assert disp.grad is not None and rgb.grad is None
    # Without anything to differentiate: the same image, no graph.
    plain = dt.render(rgb, alpha, disp.detach(), 0.55, 6.0, **CAM)
    assert not plain.requires_grad
    assert torch.equal(plain, out.detach())
    with torch.no_grad():
        assert not dt.render(rgb, alpha, disp, 0.55, 6.0, **CAM).requires_grad


def test_mixed_dtypes_give_gradients_in_each_inputs_dtype():
    rgb, alpha, disp, focus, blur = fd_inputs(9)
    rgb = rgb.float().requires_grad_()
    disp = disp.requires_grad_()
    focus = focus.float().requires_grad_()
    out = dt.render(rgb, alpha, disp, focus, blur, **CAM)
    assert out.dtype == torch.float64
    out.sum().backward()
    assert rgb.grad.dtype == torch.float32 and disp.grad.dtype == torch.float64
    assert focus.grad.dtype == torch.float32


def test_rescaling_is_off_by_default_and_explicit():
    rgb, alpha, disp, focus, blur = fd_inputs(10)
    grads = []
    for flag in (False, True):
        d = disp.clone().requires_grad_()
        out = dt.render(rgb, alpha, d, focus, blur, rescale_small_gradients=flag, **CAM)
        (out * 1e-3).sum().backward()
        grads.append(d.grad)
    g = torch.full((5, 6, 3), 1e-3, dtype=torch.float64).numpy()
    exact = drbokeh.vjp(rgb.numpy(), alpha.numpy(), disp.numpy(), g, focus=0.55, blur=6.0, **CAM)
    rescaled = drbokeh.vjp(rgb.numpy(), alpha.numpy(), disp.numpy(), g, focus=0.55, blur=6.0,
                           rescale_small_gradients=True, **CAM)
    np.testing.assert_array_equal(grads[0].numpy(), exact["disparity"])
    np.testing.assert_array_equal(grads[1].numpy(), rescaled["disparity"])
    assert not torch.equal(grads[0], grads[1])


def test_bokeh_layer_learns_focus_and_blur():
    layer = dt.BokehLayer(focus=0.5, blur=7.0, learn_focus=True, window=11)
    assert [n for n, _ in layer.named_parameters()] == ["focus"]
    assert set(layer.state_dict()) == {"focus", "blur"}
    rgb, alpha, disp, _, _ = fd_inputs(11)
    out = layer(rgb, alpha, disp)
    assert out.shape == (5, 6, 3)
    out.sum().backward()
    assert layer.focus.grad is not None and layer.focus.grad.abs() > 0
    both = dt.BokehLayer(learn_focus=True, learn_blur=True, preset="paper")
    assert {n for n, _ in both.named_parameters()} == {"focus", "blur"}
    assert "preset='paper'" in repr(both)
    with pytest.raises(ValueError, match="unknown option"):
        dt.BokehLayer(windw=3)


def test_bad_tensors_raise():
    rgb, alpha, disp, focus, blur = fd_inputs(12)
    with pytest.raises(ValueError, match="rgb has shape"):
        dt.render(rgb[0], alpha, disp, focus, blur)
    with pytest.raises(ValueError, match="alpha has shape"):
        dt.render(rgb, alpha[0], disp, focus, blur)
    with pytest.raises(ValueError, match="batch size"):
        dt.render(rgb[None].expand(2, -1, -1, -1, -1), alpha[None], disp[None].expand(2, -1, -1, -1), focus, blur)
    with pytest.raises(ValueError, match="dtype torch.float16"):
        dt.render(rgb.half(), alpha, disp, focus, blur)
    with pytest.raises(ValueError, match="dtype torch.int64"):
        dt.render(rgb, alpha, (disp * 10).long(), focus, blur)
    bad = disp.clone()
    bad[0, 1, 1] = float("nan")
    with pytest.raises(ValueError, match="layer 0 disparity"):
        dt.render(rgb, alpha, bad, focus, blur)
    with pytest.raises(ValueError, match="focus has shape"):
        dt.render(rgb, alpha, disp, torch.tensor([0.5, 0.5]), blur)
    with pytest.raises(ValueError, match="invalid parameter focus:"):
        dt.render(rgb, alpha, disp, 1.5, blur)
    with pytest.raises(ValueError, match=r"layer 0 alpha: value .* outside \[0, 1\]"):
        dt.render(rgb, alpha * 2, disp.requires_grad_(), focus, blur)


def test_tensors_off_the_cpu_name_the_missing_gpu_backend():
    rgb, alpha, disp, focus, blur = fd_inputs(13)
    with pytest.raises(NotImplementedError, match="no GPU backend"):
        dt.render(rgb.to("meta"), alpha, disp, focus, blur)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cuda_tensors_name_the_missing_gpu_backend():
    rgb, alpha, disp, focus, blur = fd_inputs(14)
    with pytest.raises(NotImplementedError, match="cuda tensor .*no GPU backend"):
        dt.render(rgb.cuda(), alpha.cuda(), disp.cuda(), focus, blur)
    with pytest.raises(NotImplementedError, match="focus is a cuda tensor"):
        dt.render(rgb, alpha, disp, focus.cuda(), blur)


def test_drbokeh_torch_is_reachable_as_an_attribute():
    import importlib

    assert importlib.import_module("drbokeh").torch is dt


def test_adam_recovers_a_disparity():
    """Recover a single opaque layer's disparity map from its defocused render, by Adam
    through the renderer (known colour, focus and blur)."""
    h, w = 24, 24
    rng = np.random.default_rng(0)
    rgb = torch.tensor(rng.uniform(0.05, 0.95, size=(1, h, w, 3)), dtype=torch.float32)
    alpha = torch.ones(1, h, w)
    y, x = np.mgrid[0:h, 0:w]
    true = torch.tensor(0.65 + 0.25 * x / (w - 1), dtype=torch.float32)[None]
    # Blur radii of 1.4 to 2.1 px: large enough to tell depth, small enough that each
    # pixel's disparity is seen through its own neighbourhood.
    focus, blur = 0.2, 3.0
    target = dt.render(rgb, alpha, true, focus, blur, window=11)
    disp = torch.full((1, h, w), 0.5, requires_grad=True)
    opt = torch.optim.Adam([disp], lr=0.02)
    start = (disp - true).abs().mean().item()
    losses = []
    for _ in range(150):
        opt.zero_grad()
        loss = (dt.render(rgb, alpha, disp, focus, blur, window=11) - target).abs().mean()
        loss.backward()
        opt.step()
        with torch.no_grad():
            disp.clamp_(0.0, 1.0)
        losses.append(loss.item())
    end = (disp - true).abs().mean().item()
    # Interior pixels (a border of 3 px sees the reflected padding) are recovered.
    inner = (disp - true)[:, 3:-3, 3:-3].abs().mean().item()
    assert losses[-1] < 0.1 * losses[0], losses[::15]
    assert end < 0.05 * start, (start, end)
    assert inner < 0.01, inner
