"""Type stubs of drbokeh's compiled module (re-exported by ``drbokeh``)."""

import os
import pathlib
from typing import Any, Dict, List, Literal, Optional, Tuple, Union, final, overload

import numpy as np
import numpy.typing as npt

__version__: str

__all__ = [
    "__version__", "DrBokehWarning", "Tape", "render", "render_with_tape", "vjp", "time_library_render",
    "aperture_layer", "render_image", "decompose", "load_stack", "save_stack", "read_image", "read_disparity",
    "read_matte", "benchmark_scenes", "load_benchmark_scene", "trace", "demo",
]

_PathLike = Union[str, "os.PathLike[str]"]
#: float32 or float64 arrays (anything else raises ValueError; lists go through np.asarray).
_FloatArray = npt.ArrayLike
#: A shape name (``"circle"``, ``"hexagon"``, ``"polygon:N[:DEG]"``, ``"triangle"`` ...
#: ``"octagon"``), ``"kernel:PATH"`` (a grey image file) or a grey ``(h, w)`` kernel array.
_ApertureArg = Union[str, npt.ArrayLike, None]
_DTypeArg = Union[str, type, np.dtype, None]
_Precision = Literal["float32", "float64"]

class DrBokehWarning(UserWarning):
    """Notes about a render: the automatic window clips the blur, the decomposition fell
    back to one layer."""

@final
class Tape:
    """What :func:`render_with_tape` recorded for the backward pass of one render."""

    @property
    def dtype(self) -> _Precision:
        """The precision of the render and of the gradients."""
    @property
    def engine(self) -> Literal["threaded", "fast", "spans"]:
        """The schedule of the backward pass: exact (every window tap), fast, or spans
        (``engine="spans"`` and float32 ``"auto"``)."""
    @property
    def shape(self) -> Tuple[int, int, int]:
        """``(N, H, W)`` of the stack the tape was recorded for."""
    def backward(
        self,
        grad_output: _FloatArray,
        *,
        rescale_small_gradients: bool = False,
        threads: Optional[int] = None,
    ) -> Dict[str, np.ndarray]:
        """Gradients of ``sum(grad_output * render)``: ``rgb (N,H,W,3)``, ``alpha (N,H,W)``,
        ``disparity (N,H,W)``, and 0-d arrays ``blur`` (d/dK) and ``focus`` (d/df), in the
        tape's dtype. ``grad_output`` is ``(H,W,3)``. The tape can be used again.
        ``rescale_small_gradients``: the published kernel's training heuristic (values of
        magnitude in [1e-6, 1e-2) raised to 1e-2); no longer the exact gradient."""

def render(
    rgb: _FloatArray,
    alpha: _FloatArray,
    disparity: _FloatArray,
    *,
    focus: float,
    blur: float,
    preset: Literal["physical", "paper"] = "physical",
    aperture: _ApertureArg = "circle",
    window: Optional[int] = None,
    gamma: float = 2.2,
    offset: float = 0.0,
    highlight: bool = False,
    engine: Literal["auto", "spans", "fast", "threaded", "reference"] = "auto",
    threads: Optional[int] = None,
) -> np.ndarray:
    """Renders a layer stack (``drbokeh render --layers``).

    Args:
        rgb: display-encoded colour ``(N, H, W, 3)``, layers front first.
        alpha: coverage in [0, 1], ``(N, H, W)``.
        disparity: normalised disparity, larger = nearer, ``(N, H, W)``.
        focus: the in-focus disparity, in [0, 1].
        blur: blur strength K: blur radius in pixels per unit of relative disparity.
        preset: ``"physical"`` (measured closer to a real lens) or ``"paper"`` (the
            published Dr.Bokeh model, exactly).
        aperture: the bokeh shape: a shape name (``"circle"``, ``"hexagon"``,
            ``"polygon:N[:DEG]"`` ...), ``"kernel:PATH"`` (a grey image file) or a grey
            ``(h, w)`` kernel array.
        window: odd gather window L = 2R + 1; ``None``: just holds the largest blur
            (at most 71 except for the fast engine; a clipped blur issues a
            :class:`DrBokehWarning`).
        gamma, offset: the display transfer ``linear = (encoded + offset) ** gamma``.
        highlight: boost bright, defocused highlights.
        engine: ``"auto"`` is spans or the fast engine's taps (whichever is cheaper per band
            and layer) in float32 and ``"threaded"`` (exact) in float64.
        threads: worker threads (default: all cores); the output never depends on it.

    Returns:
        The display-encoded image ``(H, W, 3)``: float64 if any input is float64,
        float32 otherwise.

    Raises:
        ValueError: bad shapes, dtypes, values (NaN, alpha outside [0, 1], negative colour)
            or parameters, with the library's messages (parameters named as the keyword
            arguments are).
        OSError: an aperture kernel file that cannot be read.
    """

def render_with_tape(
    rgb: _FloatArray,
    alpha: _FloatArray,
    disparity: _FloatArray,
    *,
    focus: float,
    blur: float,
    preset: Literal["physical", "paper"] = "physical",
    aperture: _ApertureArg = "circle",
    window: Optional[int] = None,
    gamma: float = 2.2,
    offset: float = 0.0,
    highlight: bool = False,
    engine: Literal["auto", "spans", "fast", "threaded", "reference"] = "auto",
    threads: Optional[int] = None,
) -> Tuple[np.ndarray, Tape]:
    """:func:`render`, also recording a :class:`Tape` for the backward pass. The image is
    :func:`render`'s, bit for bit. ``engine="auto"``: the span engine's adjoint in float32
    (within 1e-3 of the exact gradient's largest value, measured within 1e-4), the exact
    one in float64; ``"fast"``: the fast engine's (within 1e-5)."""

def vjp(
    rgb: _FloatArray,
    alpha: _FloatArray,
    disparity: _FloatArray,
    grad_output: _FloatArray,
    *,
    focus: float,
    blur: float,
    preset: Literal["physical", "paper"] = "physical",
    aperture: _ApertureArg = "circle",
    window: Optional[int] = None,
    gamma: float = 2.2,
    offset: float = 0.0,
    highlight: bool = False,
    engine: Literal["auto", "spans", "fast", "threaded", "reference"] = "auto",
    threads: Optional[int] = None,
    rescale_small_gradients: bool = False,
) -> Dict[str, np.ndarray]:
    """The gradient of ``sum(grad_output * render(...))`` with respect to every input, as
    ``drbokeh vjp`` writes it: ``rgb (N,H,W,3)``, ``alpha (N,H,W)``, ``disparity
    (N,H,W)``, and 0-d arrays ``blur`` (d/dK) and ``focus`` (d/df). ``grad_output`` is
    ``(H, W, 3)``; float64 if any array (``grad_output`` included) is float64."""

def render_image(
    image: _FloatArray,
    disparity: _FloatArray,
    *,
    focus: Optional[float] = None,
    focus_at: Optional[Tuple[int, int]] = None,
    blur: float = 30.0,
    alpha: Optional[_FloatArray] = None,
    single_layer: bool = False,
    max_layers: Optional[int] = None,
    linear: bool = False,
    preset: Literal["physical", "paper"] = "physical",
    aperture: _ApertureArg = "circle",
    window: Optional[int] = None,
    gamma: float = 2.2,
    offset: float = 0.0,
    highlight: bool = False,
    engine: Literal["auto", "spans", "fast", "threaded", "reference"] = "auto",
    threads: Optional[int] = None,
) -> np.ndarray:
    """Renders a photo as ``drbokeh render --image`` does.

    ``image`` ``(H, W, 3)`` is display-encoded (``linear=True``: linear light, encoded
    with the render's transfer first, as the command line does for EXR); ``disparity``
    ``(H, W)`` is normalised (larger = nearer; see :func:`read_disparity`). With ``alpha``
    (a matte ``(H, W)``) the stack is the paper's two layers; with ``single_layer`` one
    opaque layer; otherwise up to ``max_layers`` (default 5) depth layers cut for this
    focus and blur. ``focus``: a disparity; ``focus_at=(x, y)``: the disparity seen at that
    pixel; neither: the centre pixel's. A display-encoded photo's clipped highlights are
    recovered as the command line's default does (``--highlight auto``, docs/highlights.md);
    ``highlight=True`` uses the paper's boost alone (``--highlight``). Notes are issued as
    :class:`DrBokehWarning`."""

@overload
def aperture_layer(
    image: _FloatArray,
    disparity: _FloatArray,
    *,
    focus: float,
    blur: float,
    gamma: float = 2.2,
    grad_output: None = None,
    threads: Optional[int] = None,
) -> np.ndarray: ...
@overload
def aperture_layer(
    image: _FloatArray,
    disparity: _FloatArray,
    *,
    focus: float,
    blur: float,
    gamma: float = 2.2,
    grad_output: _FloatArray,
    threads: Optional[int] = None,
) -> Tuple[np.ndarray, np.ndarray]:
    """Aperture compositing (Srinivasan et al. 2018) as a rendering layer: ``image``
    ``(H, W, 3)`` (display-encoded) resampled bilinearly, borders clamped, at
    ``x + blur (disparity(x) - focus) u_j`` for 128 golden-angle samples ``u_j`` of the
    unit disc, averaged in linear light (``encoded ** gamma``) and encoded again. Returns
    the render ``(H, W, 3)``; with ``grad_output`` ``(H, W, 3)``, ``(render, d_disparity)``
    where ``d_disparity`` ``(H, W)`` is the gradient of ``sum(grad_output * render)`` with
    respect to ``disparity``. float64 if any array is, float32 otherwise."""

def decompose(
    image: _FloatArray,
    disparity: _FloatArray,
    *,
    alpha: Optional[_FloatArray] = None,
    max_layers: int = 5,
    jump: float = 0.05,
    band: Optional[float] = None,
    focus: Optional[float] = None,
    blur: Optional[float] = None,
    threads: Optional[int] = None,
) -> Dict[str, Any]:
    """Decomposes a photo into a layer stack as ``drbokeh layers`` does. Returns ``rgb
    (N,H,W,3)``, ``alpha (N,H,W)``, ``disparity (N,H,W)``, ``thresholds`` (the cut
    disparities, nearest first: ``List[float]``) and ``notes`` (``List[str]``)."""

def load_stack(path: _PathLike, *, dtype: _DTypeArg = None) -> Dict[str, np.ndarray]:
    """Reads and validates a layer stack NPZ: ``rgb``, ``alpha``, ``disparity`` of
    ``dtype`` (float32 by default). Raises OSError naming the file and the problem."""

def save_stack(path: _PathLike, rgb: _FloatArray, alpha: _FloatArray, disparity: _FloatArray) -> None:
    """Validates and writes a layer stack NPZ (float32 arrays), atomically."""

def read_image(path: _PathLike, *, dtype: _DTypeArg = None) -> Tuple[np.ndarray, Literal["encoded", "linear"]]:
    """Reads a colour image as ``(H, W, 3)`` values as stored, and says which:
    ``"encoded"`` (PNG, JPEG, TIFF: display-encoded, scaled to [0, 1]) or ``"linear"``
    (EXR: linear light)."""

def read_disparity(
    path: _PathLike, *, depth: bool = False, normalize: bool = True, dtype: _DTypeArg = None
) -> np.ndarray:
    """Reads a disparity map ``(H, W)`` (16-bit PNG, EXR, NPY, NPZ key ``data``),
    min-max normalised unless ``normalize=False``; ``depth=True``: metric depth converted
    to disparity 1/z first."""

def read_matte(path: _PathLike, *, dtype: _DTypeArg = None) -> np.ndarray:
    """Reads an alpha matte ``(H, W)`` in [0, 1]: a grey image or an image's alpha channel."""

def benchmark_scenes(benchmark: _PathLike) -> List[pathlib.Path]:
    """The scene directories of a benchmark, sorted (see ``drbokeh.load_benchmark``)."""

def load_benchmark_scene(dir: _PathLike) -> Dict[str, Any]:
    """One benchmark scene as a dict (see ``drbokeh.load_benchmark``)."""

def trace(
    scene: _PathLike,
    *,
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    threads: Optional[int] = None,
) -> Dict[str, Any]:
    """Path-traces a billboard scene (JSON, as ``drbokeh trace``) in memory: ``bokeh``,
    ``aif`` (sRGB-encoded, unclipped), ``bokeh_linear``, ``aif_linear`` ``(H, W, 3)``,
    ``depth_mm``, ``disparity`` ``(H, W)``, ``layers`` (a stack dict) and ``camera``
    (``focus``, ``blur``). float32."""

def demo(width: int = 640, height: int = 426, *, dtype: _DTypeArg = None) -> Dict[str, Any]:
    """The built-in demo scene: ``rgb``, ``alpha``, ``disparity`` (three layers) and
    ``focus`` (the disparity of its subject)."""

def time_library_render(
    rgb: _FloatArray,
    alpha: _FloatArray,
    disparity: _FloatArray,
    *,
    focus: float,
    blur: float,
    preset: str = "physical",
    window: Optional[int] = None,
    engine: str = "auto",
    threads: Optional[int] = None,
    repeats: int = 1,
) -> List[float]:
    """For the overhead benchmark: seconds of each of ``repeats`` calls of the Rust
    library's ``drbokeh::render`` alone on this stack (converted once)."""
