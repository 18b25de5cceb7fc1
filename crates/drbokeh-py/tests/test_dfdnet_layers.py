"""drbokeh.dfdnet's rendering layers: the PyTorch GaussPSF and aperture layers against NumPy
transcriptions of the Rust baselines and with gradcheck, the Rust aperture layer against the
PyTorch one, and the drbokeh layer's stacks (one opaque layer, quantised, five layers,
movable)."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from conftest import _rand  # noqa: E402
from drbokeh.dfdnet import layers  # noqa: E402


# ---- layers: NumPy transcriptions of crates/drbokeh/src/baselines ---------------------------


def _np_gausspsf(aif, disp, focus, k, gamma=2.2):
    """gauss_psf.rs forward: aif (H, W, 3), disp (H, W)."""
    h, w, _ = aif.shape
    lin = aif ** gamma
    sig = np.sqrt((k * (disp - focus) * 0.5) ** 2 + 0.25)
    r = max(1, math.ceil(3 * max(0.5, float(sig.max()))))
    out = np.zeros_like(aif)
    for y in range(h):
        for x in range(w):
            c, ws = np.zeros(3), 0.0
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    sx, sy = x + dx, y + dy
                    if 0 <= sx < w and 0 <= sy < h:
                        s = sig[sy, sx]
                        wt = math.exp(-(dx * dx + dy * dy) / (2 * s * s)) / (s * s)
                        c += wt * lin[sy, sx]
                        ws += wt
            out[y, x] = (c / ws) ** (1 / gamma)
    return out


def _np_aperture(aif, disp, focus, k, gamma=2.2):
    """aperture_compositing.rs forward: bilinear samples with clamped coordinates."""
    h, w, _ = aif.shape
    lin = aif ** gamma
    samples = layers.aperture_samples(128)
    out = np.zeros_like(aif)
    for y in range(h):
        for x in range(w):
            shift = k * (disp[y, x] - focus)
            acc = np.zeros(3)
            for u, v in samples:
                fx = min(max(x + shift * u, 0.0), w - 1.0)
                fy = min(max(y + shift * v, 0.0), h - 1.0)
                x0, y0 = int(math.floor(fx)), int(math.floor(fy))
                x1, y1 = min(x0 + 1, w - 1), min(y0 + 1, h - 1)
                tx, ty = fx - x0, fy - y0
                acc += (1 - ty) * ((1 - tx) * lin[y0, x0] + tx * lin[y0, x1]) + ty * ((1 - tx) * lin[y1, x0] + tx * lin[y1, x1])
            out[y, x] = (acc / len(samples)) ** (1 / gamma)
    return out


@pytest.mark.parametrize("name", ["gausspsf", "aperture", "aperturepy"])
def test_baseline_layers_match_the_rust_loops_and_have_gradients(name):
    aif = _rand(7, 10, 11, 3)
    disp = _rand(8, 10, 11)
    focus, k = 0.8, 3.0
    ref = (_np_gausspsf if name == "gausspsf" else _np_aperture)(aif, disp, focus, k)
    layer = layers.make_layer(name)
    t_aif = torch.from_numpy(aif.transpose(2, 0, 1)[None].copy())
    t_disp = torch.from_numpy(disp[None, None].copy()).requires_grad_(True)
    f, kk = torch.tensor([focus], dtype=torch.float64), torch.tensor([k], dtype=torch.float64)
    got = layer(t_aif, t_disp, f, kk)[0].detach().numpy().transpose(1, 2, 0)
    assert np.abs(got - ref).max() < 1e-7
    # Gradients with respect to the disparity, against finite differences.
    small = (t_aif[..., :6, :7].clone(), t_disp[..., :6, :7].detach().clone().requires_grad_(True))
    assert torch.autograd.gradcheck(lambda d: layer(small[0], d, f, kk), (small[1],), eps=1e-6, atol=1e-5)


def test_rust_aperture_layer_agrees_with_the_pytorch_reference_in_float32():
    """``aperture`` (the Rust layer and its adjoint) against ``aperturepy`` (PyTorch's
    grid_sample) on a float32 batch whose items differ in focus and blur, with a prediction
    that reaches past the borders: the same render and the same disparity gradient, up to
    float32 rounding; no gradient for the image; the same result on any thread count."""
    rng = np.random.default_rng(21)
    aif = torch.from_numpy(rng.uniform(0.0, 1.0, (2, 3, 24, 29)).astype(np.float32))
    aif[0, :, 5:8, 5:8] = 1.6  # a restored highlight (the "energy" source) above white
    disp = torch.from_numpy(rng.uniform(0.0, 1.0, (2, 1, 24, 29)).astype(np.float32))
    focus, blur = torch.tensor([0.0, 0.7]), torch.tensor([9.0, 4.5])
    grad_out = torch.from_numpy(rng.normal(size=(2, 3, 24, 29)).astype(np.float32))
    results = []
    for name in ("aperture", "aperturepy"):
        d = disp.clone().requires_grad_(True)
        a = aif.clone().requires_grad_(name == "aperture")
        out = layers.make_layer(name)(a, d, focus, blur)
        (out * grad_out).sum().backward()
        if name == "aperture":
            assert a.grad is None or float(a.grad.abs().max()) == 0.0
        results.append((out.detach(), d.grad.detach()))
    (out_rs, g_rs), (out_py, g_py) = results
    assert out_rs.dtype == torch.float32 and out_rs.shape == out_py.shape
    assert float((out_rs - out_py).abs().max()) < 2e-5
    # The gradient jumps where a sample crosses a texel edge or the clamped border, and the
    # two compute sample positions in other precisions (float64 in Rust, float32 here), so a
    # sample that lands on such a kink may take the other side: a few pixels may differ by a
    # sample's share; every other pixel agrees to rounding.
    off = (g_rs - g_py).abs() > 1e-4 * float(g_py.abs().max())
    assert int(off.sum()) <= max(1, off.numel() // 200), int(off.sum())
    assert float(torch.linalg.norm(g_rs - g_py) / torch.linalg.norm(g_py)) < 2e-3
    again = layers.make_layer("aperture", threads=2)(aif, disp, focus, blur)
    assert torch.equal(again, out_rs)


def test_rust_aperture_layer_rejects_bad_input_with_clear_messages():
    from drbokeh import _native

    img, disp = np.full((6, 7, 3), 0.5, np.float32), np.zeros((6, 7), np.float32)
    # The messages are the library's, as every other binding gives them.
    with pytest.raises(ValueError, match=r"disparity: size 8x6 does not match image \(7x6\)"):
        _native.aperture_layer(img, np.zeros((6, 8), np.float32), focus=0.0, blur=3.0)
    with pytest.raises(ValueError, match=r"disparity: non-finite value \(NaN\) at pixel x=0, y=0"):
        _native.aperture_layer(img, np.where(np.eye(6, 7) > 0, np.nan, 0).astype(np.float32), focus=0.0, blur=3.0)
    with pytest.raises(ValueError, match="focus"):
        _native.aperture_layer(img, disp, focus=1.5, blur=3.0)
    with pytest.raises(ValueError, match="grad_output has shape"):
        _native.aperture_layer(img, disp, focus=0.0, blur=3.0, grad_output=np.zeros((6, 7), np.float32))
    with pytest.raises(ValueError, match=r"grad_output: size 7x5 does not match image \(7x6\)"):
        _native.aperture_layer(img, disp, focus=0.0, blur=3.0, grad_output=np.zeros((5, 7, 3), np.float32))
    with pytest.raises(ValueError, match=r"grad_output: non-finite value \(inf\) at pixel x=6, y=0"):
        _native.aperture_layer(img, disp, focus=0.0, blur=3.0, grad_output=np.pad(
            np.zeros((5, 6, 3), np.float32), ((0, 1), (0, 1), (0, 0)), constant_values=np.inf))
    with pytest.raises(ValueError, match="image has dtype"):
        _native.aperture_layer(img.astype(np.int32), disp, focus=0.0, blur=3.0)


def test_drbokeh_layer_renders_one_opaque_layer():
    import drbokeh

    aif, disp = _rand(9, 16, 16, 3).astype(np.float32), _rand(10, 16, 16).astype(np.float32)
    layer = layers.make_layer("physical")
    got = layer(
        torch.from_numpy(aif.transpose(2, 0, 1)[None].copy()), torch.from_numpy(disp[None, None].copy()),
        torch.tensor([1.0]), torch.tensor([4.0]),
    )[0].numpy().transpose(1, 2, 0)
    want = drbokeh.render(aif[None], np.ones((1, 16, 16), np.float32), disp[None], focus=1.0, blur=4.0, preset="physical")
    assert np.abs(got - want).max() < 1e-6


def test_quantised_disparity_has_levels_over_its_range():
    ramp = np.linspace(0.2, 0.6, 9, dtype=np.float32)[None].repeat(3, 0)
    q = layers.quantised(ramp, 3)
    assert sorted(set(np.round(q.ravel(), 6))) == pytest.approx([0.2, 0.4, 0.6])
    assert np.abs(q - ramp).max() <= 0.1 + 1e-6
    flat = np.full((4, 4), 0.3, np.float32) + np.linspace(0, 0.01, 16, dtype=np.float32).reshape(4, 4)
    assert np.array_equal(layers.quantised(flat, 3), flat)  # range below 0.05: unchanged


def test_occlusion_layer_is_one_layer_at_a_constant_and_cuts_at_a_step():
    """``physical3``: at a constant disparity the stack is one opaque layer (the same render
    as ``physical``); at a disparity step (a near square over a textured far background)
    the near square is its own front layer, owned pixels carry the prediction's disparity
    and colour, the back layer is filled in behind the square, and the disparity gradient
    flows (finite, nonzero) on both sides of the edge."""
    rng = np.random.default_rng(5)
    aif = torch.from_numpy(rng.random((1, 3, 32, 32)).astype(np.float32) * 0.8 + 0.1)
    f, k = torch.tensor([0.0]), torch.tensor([4.0])
    const = torch.full((1, 1, 32, 32), 0.3)
    one = layers.make_layer("physical")(aif, const, f, k)
    stacked = layers.make_layer("physical3")(aif, const, f, k)
    assert torch.abs(one - stacked).max() < 1e-6
    step = torch.full((1, 1, 32, 32), 0.1)
    step[..., 10:22, 10:22] = 0.8
    rgb, alpha, disp = layers.occlusion_stack(aif, step, f, k, 3)
    assert rgb.shape == (1, 3, 32, 32, 3) and alpha.shape == disp.shape == (1, 3, 32, 32)
    assert torch.all(alpha[0, 0, 10:22, 10:22] > 0.5) and torch.all(alpha[0, 0, :5, :5] < 0.5)
    assert torch.allclose(disp[0, 0, 10:22, 10:22], step[0, 0, 10:22, 10:22])
    back = int((alpha[0].amax((1, 2)) > 0.5).nonzero().max())
    assert back > 0 and torch.all(alpha[0, back] > 0.5)  # the farthest layer covers everything
    assert torch.allclose(rgb[0, 0, 10:22, 10:22], aif[0].permute(1, 2, 0)[10:22, 10:22])
    assert torch.allclose(disp[0, back, :5, :5], step[0, 0, :5, :5])
    d = step.clone().requires_grad_(True)
    out = layers.make_layer("physical3")(aif, d, f, k)
    target = layers.make_layer("physical")(aif, torch.where(step > 0.5, step, 0.3), f, k)
    (g,) = torch.autograd.grad((out - target).abs().mean(), d)
    assert torch.isfinite(g).all()
    assert g[0, 0, 10:22, 10:22].abs().sum() > 0
    assert g[0, 0, 2:9, 2:9].sum() < 0  # the far side is pushed up, towards the target's 0.3


def test_five_layer_stack_separates_more_depths():
    """``physical5``: nested squares at four depths over a far background (each nearer one
    inside the farther one, so every depth borders the next) are cut into at least three
    front layers, where ``physical3`` keeps them all in one; every pixel is owned by one
    layer, owned pixels carry the prediction's disparity, the stack is one layer at a
    constant, and the disparity gradient flows to every depth."""
    rng = np.random.default_rng(11)
    aif = torch.from_numpy(rng.random((1, 3, 40, 40)).astype(np.float32) * 0.8 + 0.1)
    f, k = torch.tensor([0.0]), torch.tensor([3.0])
    const = torch.full((1, 1, 40, 40), 0.3)
    one = layers.make_layer("physical")(aif, const, f, k)
    assert torch.abs(one - layers.make_layer("physical5")(aif, const, f, k)).max() < 1e-6
    steps = torch.full((1, 1, 40, 40), 0.05)
    squares = [(0.3, 4), (0.5, 10), (0.7, 15), (0.95, 19)]  # (disparity, inset from the border)
    for disp, inset in squares:
        steps[..., inset : 40 - inset, inset : 40 - inset] = disp
    front_layers = []
    for n in (3, 5):
        _, alpha, disp = layers.occlusion_stack(aif, steps, f, k, n)
        assert alpha.shape == (1, n, 40, 40)
        covers = (alpha[0] > 0.5).to(torch.int32)
        owner = (covers > 0) & (torch.cumsum(covers, 0) - covers == 0)
        assert torch.all(owner.sum(0) == 1)  # each pixel owned by exactly one layer
        assert torch.allclose(disp[0][owner], steps[0, 0].expand(n, 40, 40)[owner])
        layer_of = owner.to(torch.int64).argmax(0)
        front_layers.append({int(layer_of[inset, 20]) for _, inset in squares[:3]})
        assert int(layer_of[1, 1]) not in front_layers[-1]  # the background is its own layer
    assert len(front_layers[0]) == 1 and len(front_layers[1]) == 3
    d = steps.clone().requires_grad_(True)
    out = layers.make_layer("physical5")(aif, d, f, k)
    (g,) = torch.autograd.grad((out - one).abs().mean(), d)
    assert torch.isfinite(g).all()
    for i, (_, inset) in enumerate(squares):
        ring = torch.zeros(40, 40, dtype=torch.bool)
        ring[inset : 40 - inset, inset : 40 - inset] = True
        if i + 1 < len(squares):
            nxt = squares[i + 1][1]
            ring[nxt : 40 - nxt, nxt : 40 - nxt] = False
        assert g[0, 0][ring].abs().sum() > 0


def test_movable_stack_keeps_the_render_and_adds_the_membership_gradient():
    """``physical3m``: the stack of ``physical3`` with the same alphas (but for the floor on
    the empty pixels of a layer that has a cut), the input's colour on those pixels, and an
    alpha whose derivative with respect to the disparity is the membership's,
    ``sigmoid'((d - t_n) / w) / w`` where no nearer layer covers the pixel, 0 where one does
    and on the back layer."""
    rng = np.random.default_rng(7)
    aif = torch.from_numpy(rng.random((1, 3, 32, 32)).astype(np.float32) * 0.8 + 0.1)
    f, k = torch.tensor([0.0]), torch.tensor([4.0])
    step = torch.full((1, 1, 32, 32), 0.1)
    step[..., 10:22, 10:22] = 0.8
    step[..., 10:22, 4:8] = 0.3  # a pixel column band between the levels
    fixed_rgb, fixed_alpha, fixed_disp = layers.occlusion_stack(aif, step, f, k, 3)
    d = step.clone().requires_grad_(True)
    width = 0.05
    rgb, alpha, disp = layers.occlusion_stack(aif, d, f, k, 3, movable_width=width)
    assert torch.equal(disp.detach(), fixed_disp)
    from drbokeh import _native

    dec = _native.decompose(
        aif[0].permute(1, 2, 0).contiguous().numpy(), layers.quantised(step[0, 0].numpy(), 3), max_layers=3, threads=1
    )
    cuts = list(dec["thresholds"])
    assert 1 <= len(cuts) <= 2
    covers = (fixed_alpha > 0.5).to(torch.int32)
    nearer = (torch.cumsum(covers, 1) - covers) > 0
    floor = layers.MOVABLE_ALPHA_FLOOR
    for n in range(3):
        if n < len(cuts):
            free = ~nearer[0, n]
            empty = free & (fixed_alpha[0, n] < floor)
            assert empty.any() and not empty.all()
            want = torch.where(empty, torch.full_like(fixed_alpha[0, n], floor), fixed_alpha[0, n])
            assert torch.allclose(alpha[0, n].detach(), want, atol=1e-7)
            assert torch.equal(rgb[0, n][empty], aif[0].permute(1, 2, 0)[empty])
            assert torch.equal(rgb[0, n][~empty], fixed_rgb[0, n][~empty])
            (g,) = torch.autograd.grad(alpha[0, n].sum(), d, retain_graph=True)
            s = torch.sigmoid((step[0, 0] - cuts[n]) / width)
            expect = torch.where(free, s * (1 - s) / width, torch.zeros_like(s))
            assert torch.allclose(g[0, 0], expect, atol=1e-5)
            assert g[0, 0][free].abs().max() > 0.1 and torch.all(g[0, 0][~free] == 0)
        else:
            assert torch.equal(alpha[0, n].detach(), fixed_alpha[0, n])
            (g,) = torch.autograd.grad(alpha[0, n].sum(), d, retain_graph=True, allow_unused=True)
            assert g is None or torch.all(g == 0)
    # the render differs from the fixed stack's by the floor's share only
    fixed_out = layers.make_layer("physical3")(aif, step, f, k)
    moved_out = layers.make_layer("physical3m")(aif, step, f, k)
    assert 0 < torch.abs(fixed_out - moved_out).max() < 0.01
    # levels closer than two widths (here 0.06 apart): the fixed stack, value and gradient
    near = 0.3 + (step - 0.1) * (0.12 / 0.7)
    assert not layers.separated(near[0, 0].numpy(), 3, layers.MOVABLE_WIDTH)
    assert layers.separated(step[0, 0].numpy(), 3, layers.MOVABLE_WIDTH)
    grads = []
    for name in ("physical3", "physical3m"):
        dn = near.clone().requires_grad_(True)
        out = layers.make_layer(name)(aif, dn, f, k)
        grads.append((out.detach(), torch.autograd.grad((out - fixed_out).abs().mean(), dn)[0]))
    assert torch.equal(grads[0][0], grads[1][0]) and torch.equal(grads[0][1], grads[1][1])
