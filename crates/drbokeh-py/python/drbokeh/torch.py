"""drbokeh for PyTorch: the renderer as a differentiable function and module.

:func:`render` is a ``torch.autograd.Function``: gradients flow to every tensor argument
that requires them (colour, alpha, disparity, and ``focus`` and ``blur`` as 0-d tensors),
computed by drbokeh's exact adjoint (in float64; float32 runs the fast engine's adjoint,
within 1e-5 of the exact gradient's largest value). Inputs may carry a leading batch
dimension. Tensors must be float32 or float64 on the CPU: drbokeh has no GPU backend.
:class:`BokehLayer` wraps it as an ``nn.Module`` with optionally learnable focus and blur.

Importing this module imports PyTorch; ``import drbokeh`` alone does not.
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple, Union

try:
    import torch
except ImportError as e:  # pragma: no cover - exercised by the no-torch test
    raise ImportError(
        "drbokeh.torch needs PyTorch (pip install torch); "
        "the NumPy API (import drbokeh) works without it"
    ) from e

from torch.autograd.function import once_differentiable

from . import _native

__all__ = ["render", "BokehLayer"]

Scalar = Union[float, "torch.Tensor"]

_FLOATS = (torch.float32, torch.float64)

# Keyword options of drbokeh.render that this module passes through.
_OPTIONS = ("preset", "aperture", "window", "gamma", "offset", "highlight", "engine", "threads")


def _check_device(name: str, t: "torch.Tensor") -> None:
    if t.device.type != "cpu":
        raise NotImplementedError(
            f"drbokeh.torch.render: {name} is a {t.device.type} tensor ({t.device}), but "
            "drbokeh has no GPU backend (no CUDA or other accelerator kernels): it renders "
            "on the CPU only. Move the inputs with .cpu() and the result back with .to(device)."
        )


def _tensor(name: str, x: Any) -> "torch.Tensor":
    t = x if isinstance(x, torch.Tensor) else torch.as_tensor(x)
    _check_device(name, t)
    if t.dtype not in _FLOATS:
        raise ValueError(f"{name} has dtype {t.dtype}; expected torch.float32 or torch.float64")
    return t


def _scalar(name: str, x: Scalar, batch: Optional[int]) -> "torch.Tensor":
    """focus/blur: a Python number, a 0-d tensor, or (batched inputs) a (B,) tensor."""
    if not isinstance(x, torch.Tensor):
        try:
            return torch.tensor(float(x), dtype=torch.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a number or a tensor, got {type(x).__name__}") from None
    t = _tensor(name, x)
    if t.dim() == 0 or (batch is not None and tuple(t.shape) == (batch,)):
        return t
    want = "a 0-d tensor" + (f" or shape ({batch},)" if batch is not None else "")
    raise ValueError(f"{name} has shape {tuple(t.shape)}, expected {want}")


def _numpy(t: "torch.Tensor") -> Any:
    # A view of the tensor's memory (no copy); the native side accepts any strides.
    return t.detach().numpy()


def _at(t: "torch.Tensor", i: int) -> float:
    return float(t if t.dim() == 0 else t[i])


class _Render(torch.autograd.Function):
    """Forward: one native render (and tape) per batch item. Backward: the tapes'
    adjoints."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: Any,
        rgb: "torch.Tensor",
        alpha: "torch.Tensor",
        disparity: "torch.Tensor",
        focus: "torch.Tensor",
        blur: "torch.Tensor",
        options: Dict[str, Any],
        rescale_small_gradients: bool,
    ) -> "torch.Tensor":
        batched = rgb.dim() == 5
        items = rgb.shape[0] if batched else 1
        outs: List["torch.Tensor"] = []
        tapes = []
        for i in range(items):
            pick = (lambda t: t[i]) if batched else (lambda t: t)
            out, tape = _native.render_with_tape(
                _numpy(pick(rgb)),
                _numpy(pick(alpha)),
                _numpy(pick(disparity)),
                focus=_at(focus, i),
                blur=_at(blur, i),
                **options,
            )
            outs.append(torch.from_numpy(out))
            tapes.append(tape)
        ctx.tapes = tapes
        ctx.batched = batched
        ctx.threads = options.get("threads")
        ctx.rescale = rescale_small_gradients
        ctx.dtypes = (rgb.dtype, alpha.dtype, disparity.dtype, focus.dtype, blur.dtype)
        ctx.scalar_dims = (focus.dim(), blur.dim())
        return torch.stack(outs) if batched else outs[0]

    @staticmethod
    @once_differentiable
    def backward(ctx: Any, grad_output: "torch.Tensor") -> Tuple[Optional["torch.Tensor"], ...]:
        needs = ctx.needs_input_grad
        grads = []
        for i, tape in enumerate(ctx.tapes):
            g = grad_output[i] if ctx.batched else grad_output
            grads.append(
                tape.backward(
                    _numpy(g),
                    rescale_small_gradients=ctx.rescale,
                    threads=ctx.threads,
                )
            )

        def plane(key: str, dtype: "torch.dtype") -> "torch.Tensor":
            ts = [torch.from_numpy(d[key]) for d in grads]
            t = torch.stack(ts) if ctx.batched else ts[0]
            return t.to(dtype)

        def scalar(key: str, dtype: "torch.dtype", dim: int) -> "torch.Tensor":
            values = torch.tensor([float(d[key]) for d in grads], dtype=torch.float64)
            t = values.sum() if dim == 0 else values
            return t.to(dtype)

        d_rgb, d_alpha, d_disp, d_focus, d_blur = ctx.dtypes
        return (
            plane("rgb", d_rgb) if needs[0] else None,
            plane("alpha", d_alpha) if needs[1] else None,
            plane("disparity", d_disp) if needs[2] else None,
            scalar("focus", d_focus, ctx.scalar_dims[0]) if needs[3] else None,
            scalar("blur", d_blur, ctx.scalar_dims[1]) if needs[4] else None,
            None,
            None,
        )


def render(
    rgb: "torch.Tensor",
    alpha: "torch.Tensor",
    disparity: "torch.Tensor",
    focus: Scalar,
    blur: Scalar,
    *,
    preset: str = "physical",
    aperture: Any = "circle",
    window: Optional[int] = None,
    gamma: float = 2.2,
    offset: float = 0.0,
    highlight: bool = False,
    engine: str = "auto",
    threads: Optional[int] = None,
    rescale_small_gradients: bool = False,
) -> "torch.Tensor":
    """Renders a layer stack, differentiably.

    Args:
        rgb: display-encoded colour ``(N, H, W, 3)``, layers front first, or
            ``(B, N, H, W, 3)`` for a batch.
        alpha: coverage in [0, 1], ``(N, H, W)`` (``(B, N, H, W)``).
        disparity: normalised disparity (larger = nearer), ``(N, H, W)``
            (``(B, N, H, W)``).
        focus: the in-focus disparity in [0, 1]: a number, a 0-d tensor, or for a batch a
            ``(B,)`` tensor (one per item).
        blur: blur strength K (blur radius in pixels per unit of relative disparity), as
            ``focus``.
        preset, aperture, window, gamma, offset, highlight, engine, threads: as
            :func:`drbokeh.render`. With ``window=None`` the window follows the largest
            blur of each item (piecewise constant in blur and disparity).
        rescale_small_gradients: the published kernel's training heuristic (gradient
            values with magnitude in [1e-6, 1e-2) raised to 1e-2); off by default, when the
            gradients are exact.

    Returns:
        The display-encoded image ``(H, W, 3)`` (``(B, H, W, 3)``), float64 if any of
        ``rgb``, ``alpha``, ``disparity`` is float64 (``engine="auto"`` is then the exact
        threaded engine), float32 otherwise. Gradients come back in each input's dtype.

    Raises:
        ValueError: bad shapes, dtypes, values (NaN, alpha outside [0, 1], focus outside
            [0, 1], ...) or options, with the library's messages (parameters named as
            the keyword arguments are).
        NotImplementedError: tensors not on the CPU (drbokeh has no GPU backend).
    """
    rgb = _tensor("rgb", rgb)
    alpha = _tensor("alpha", alpha)
    disparity = _tensor("disparity", disparity)
    if rgb.dim() not in (4, 5):
        raise ValueError(
            f"rgb has shape {tuple(rgb.shape)}, expected (N, H, W, 3) or (B, N, H, W, 3)"
        )
    batch = rgb.shape[0] if rgb.dim() == 5 else None
    for name, t in (("alpha", alpha), ("disparity", disparity)):
        if t.dim() != rgb.dim() - 1:
            want = "(B, N, H, W)" if batch is not None else "(N, H, W)"
            raise ValueError(
                f"{name} has shape {tuple(t.shape)}, expected {want} to match rgb {tuple(rgb.shape)}"
            )
        if batch is not None and t.shape[0] != batch:
            raise ValueError(f"{name} has batch size {t.shape[0]}, but rgb has {batch}")
    if batch == 0:
        raise ValueError("the batch is empty (B = 0)")
    focus_t = _scalar("focus", focus, batch)
    blur_t = _scalar("blur", blur, batch)
    if isinstance(aperture, torch.Tensor):
        _check_device("aperture", aperture)
        aperture = _numpy(aperture)
    options: Dict[str, Any] = dict(
        preset=preset,
        aperture=aperture,
        window=window,
        gamma=gamma,
        offset=offset,
        highlight=highlight,
        engine=engine,
        threads=threads,
    )
    tensors = (rgb, alpha, disparity, focus_t, blur_t)
    if torch.is_grad_enabled() and any(t.requires_grad for t in tensors):
        return _Render.apply(rgb, alpha, disparity, focus_t, blur_t, options, rescale_small_gradients)
    # Nothing to differentiate: plain renders, no tape.
    if batch is None:
        out = _native.render(
            _numpy(rgb), _numpy(alpha), _numpy(disparity),
            focus=_at(focus_t, 0), blur=_at(blur_t, 0), **options,
        )
        return torch.from_numpy(out)
    return torch.stack(
        [
            torch.from_numpy(
                _native.render(
                    _numpy(rgb[i]), _numpy(alpha[i]), _numpy(disparity[i]),
                    focus=_at(focus_t, i), blur=_at(blur_t, i), **options,
                )
            )
            for i in range(batch)
        ]
    )


class BokehLayer(torch.nn.Module):
    """Lens blur as a module: ``forward(rgb, alpha, disparity)`` renders the stack (shapes
    as :func:`render`, batched or not) at this layer's focus and blur.

    Args:
        focus: initial focus disparity in [0, 1].
        blur: initial blur strength K.
        learn_focus: make ``focus`` an ``nn.Parameter`` (trained with the module);
            otherwise it is a buffer (saved in the state dict, not trained).
        learn_blur: likewise for ``blur``.
        rescale_small_gradients: see :func:`render` (off: exact gradients).
        **options: ``preset``, ``aperture``, ``window``, ``gamma``, ``offset``,
            ``highlight``, ``engine``, ``threads``, as :func:`render`.

    A learned focus must stay in [0, 1] and blur in [0, 10000] (the renderer raises
    otherwise); clamp them after an optimiser step if the loss can push them out.
    """

    focus: "torch.Tensor"
    blur: "torch.Tensor"

    def __init__(
        self,
        focus: float = 0.5,
        blur: float = 30.0,
        *,
        learn_focus: bool = False,
        learn_blur: bool = False,
        rescale_small_gradients: bool = False,
        **options: Any,
    ) -> None:
        super().__init__()
        unknown = sorted(set(options) - set(_OPTIONS))
        if unknown:
            raise ValueError(
                f"unknown option(s) {', '.join(unknown)} (available: {', '.join(_OPTIONS)})"
            )
        for name, value, learn in (("focus", focus, learn_focus), ("blur", blur, learn_blur)):
            t = torch.tensor(float(value), dtype=torch.get_default_dtype())
            if learn:
                self.register_parameter(name, torch.nn.Parameter(t))
            else:
                self.register_buffer(name, t)
        self.rescale_small_gradients = rescale_small_gradients
        self.options: Dict[str, Any] = dict(options)

    def forward(
        self, rgb: "torch.Tensor", alpha: "torch.Tensor", disparity: "torch.Tensor"
    ) -> "torch.Tensor":
        return render(
            rgb,
            alpha,
            disparity,
            self.focus,
            self.blur,
            rescale_small_gradients=self.rescale_small_gradients,
            **self.options,
        )

    def extra_repr(self) -> str:
        parts = [f"focus={float(self.focus.detach()):.4g}", f"blur={float(self.blur.detach()):.4g}"]
        parts += [f"{k}={v!r}" for k, v in self.options.items() if not hasattr(v, "shape")]
        if self.rescale_small_gradients:
            parts.append("rescale_small_gradients=True")
        return ", ".join(parts)
