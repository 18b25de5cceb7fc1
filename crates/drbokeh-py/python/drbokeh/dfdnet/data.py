"""The training data: ray-traced ``drbokeh benchmark make`` scenes, cached as arrays.

Each split is one benchmark seed (train / validation / test never share a scene), and one
focus, so that the sign of ``d = disparity - focus`` is determined everywhere:

- ``far`` (the default, docs/dfdnet.md says why): ``--shard 2/3`` makes the scenes
  ``i % 3 == 2``, which focus on the background (disparity 0) or on the farthest
  foreground, each about half; only those focused on the background are kept, so
  ``d = disparity >= 0`` and the background is sharp in the traced image.
- ``near``: ``--shard 0/3``, every scene focuses on the nearest billboard (disparity 1),
  ``d <= 0`` (sessions 2-3).

A kept scene whose recorded focus is not the split's is impossible by construction and
rejected. The scenes' largest blur runs log-spaced over the scene index (2-20 px at
256 px, so 1-10 px at 128 px), so every split covers the whole range of K.

The network and the loss see ``aif`` (the all-in-focus PNG, display-encoded, clipped) and
``bokeh`` (the traced defocused PNG) and the scene's ``focus`` and ``blur`` (K); the true
``disparity`` and the metric depth range are kept for evaluation only.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np


@dataclass(frozen=True)
class SplitSpec:
    """One split: ``drbokeh benchmark make --scenes 3*count --shard S/3 --seed seed``
    (``S`` 0 for ``near`` focus, 2 for ``far``): ``count`` scenes are traced; with ``far``
    about half of them (those focused on the background) are kept."""

    name: str
    seed: int
    count: int
    size: int
    spp: int
    focus: str = "far"
    background_detail: float = 0.0
    # ``benchmark make --perspective``: foregrounds' size and height in the frame follow
    # their depth, so the all-in-focus image carries a depth cue.
    perspective: bool = False


@dataclass
class Split:
    """A split's arrays: ``aif``, ``bokeh`` ``(N, 3, H, W)`` float32 display-encoded,
    ``disparity`` ``(N, 1, H, W)``, ``focus``, ``blur``, ``near_mm``, ``far_mm`` ``(N,)``,
    ``names``."""

    aif: np.ndarray
    bokeh: np.ndarray
    disparity: np.ndarray
    focus: np.ndarray
    blur: np.ndarray
    near_mm: np.ndarray
    far_mm: np.ndarray
    names: List[str]
    # The cache was traced with only the scenes whose blur K is at least this (px): a
    # smaller --min-blur cannot be served from it (:func:`with_min_blur`).
    traced_min_blur: float = 0.0

    def __len__(self) -> int:
        return int(self.aif.shape[0])


FOCUS = {"far": (2, 0.0), "near": (0, 1.0)}  # focus -> (shard of 3, disparity in focus)


def default_splits(
    size: int = 128, spp: int = 144, train: int = 240, val: int = 32, test: int = 64, focus: str = "far",
    background_detail: float = 0.0, perspective: bool = False,
) -> List[SplitSpec]:
    if focus not in FOCUS:
        raise ValueError(f"unknown focus {focus!r} (available: {', '.join(FOCUS)})")
    return [
        SplitSpec("train", 1701, train, size, spp, focus, background_detail, perspective),
        SplitSpec("val", 1702, val, size, spp, focus, background_detail, perspective),
        SplitSpec("test", 1703, test, size, spp, focus, background_detail, perspective),
    ]


def find_cli(explicit: Optional[str] = None) -> str:
    """The ``drbokeh`` binary: ``explicit``, ``$DRBOKEH_CLI``, ``drbokeh`` on the PATH, or
    this checkout's ``target/release/drbokeh``."""
    for c in (explicit, os.environ.get("DRBOKEH_CLI"), shutil.which("drbokeh")):
        if c:
            return c
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / "target" / "release" / "drbokeh"
        if cand.is_file():
            return str(cand)
    raise FileNotFoundError(
        "cannot find the drbokeh command line (set DRBOKEH_CLI or pass --drbokeh); "
        "build it with cargo build --release -p drbokeh-cli"
    )


def make_benchmark(spec: SplitSpec, directory: Path, cli: str, threads: int = 1, min_blur: float = 0.0) -> None:
    """Runs ``drbokeh benchmark make`` (resumable: scenes already there are kept). With
    ``far`` focus only the scenes focused on the background are traced (the others would
    be skipped by :func:`load_benchmark_dir`), and with ``min_blur`` only those whose blur K
    is at least that many pixels."""
    cmd = [
        cli, "benchmark", "make", "--scenes", str(3 * spec.count), "--shard", f"{FOCUS[spec.focus][0]}/3",
        "--seed", str(spec.seed), "--size", str(spec.size), "--spp", str(spec.spp),
        "--threads", str(threads), "--out", str(directory), "-q",
    ]
    if spec.background_detail > 0:
        cmd += ["--background-detail", str(spec.background_detail)]
    if spec.perspective:
        cmd += ["--perspective"]
    if spec.focus == "far":
        cmd += ["--only-focus", repr(FOCUS["far"][1])]
    if min_blur > 0:
        cmd += ["--min-blur", repr(float(min_blur))]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{p.stderr.strip()}")


def load_benchmark_dir(directory: Path, focus: str = "near", why_empty: str = "") -> Split:
    """The scenes of ``directory`` that focus at ``focus`` (``near``: every scene must
    focus at disparity 1; ``far``: the scenes focused at disparity 0, the background, are
    kept, the others, focused on the farthest foreground, skipped). No such scene is a
    ``ValueError`` naming the directory, with ``why_empty`` appended."""
    import drbokeh

    want = FOCUS[focus][1]
    empty = f"{directory}: no traced scene focuses at disparity {want} ({focus} focus){why_empty}"
    directory = Path(directory)
    if directory.is_dir() and not any((p / "scene.json").is_file() for p in directory.iterdir()):
        raise ValueError(empty)  # a manifest whose every scene was filtered out when traced
    aif, bokeh, disp, focus_, blur, near, far, names = [], [], [], [], [], [], [], []
    for scene in drbokeh.load_benchmark(directory):
        f = float(scene["camera"]["focus"])
        if abs(f - want) > 1e-6:
            if focus == "far":
                continue
            raise ValueError(f"{scene['path']}: focus {f}, expected {want} ({focus} focus only)")
        record = json.loads((Path(scene["path"]) / "scene.json").read_text())["derived"]
        aif.append(np.clip(scene["aif"], 0.0, 1.0).transpose(2, 0, 1))
        bokeh.append(np.clip(scene["ground_truth"], 0.0, 1.0).transpose(2, 0, 1))
        disp.append(scene["disparity"][None])
        focus_.append(want)
        blur.append(float(scene["camera"]["blur"]))
        near.append(float(record["disparity_near_depth_mm"]))
        far.append(float(record["disparity_far_depth_mm"]))
        names.append(str(scene["name"]))
    if not names:
        raise ValueError(empty)
    f32 = np.float32
    return Split(
        np.stack(aif).astype(f32), np.stack(bokeh).astype(f32), np.stack(disp).astype(f32),
        np.array(focus_, f32), np.array(blur, f32), np.array(near, np.float64),
        np.array(far, np.float64), names,
    )


def _temp_beside(path: Path) -> Path:
    """A temporary name next to ``path``, one per process (no two writers share it), with
    ``path``'s suffix: written whole, then renamed over ``path``."""
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


def _save(split: Split, path: Path) -> None:
    tmp = _temp_beside(path)
    np.savez(
        tmp, aif=split.aif, bokeh=split.bokeh, disparity=split.disparity, focus=split.focus,
        blur=split.blur, near_mm=split.near_mm, far_mm=split.far_mm, names=np.array(split.names),
        traced_min_blur=np.float64(split.traced_min_blur),
    )
    tmp.replace(path)


def _load(path: Path) -> Split:
    """A cached split; a file that is not one (truncated, corrupt, another array file) is a
    ``ValueError`` naming it."""
    try:
        with np.load(path) as z:
            split = Split(
                z["aif"], z["bokeh"], z["disparity"], z["focus"], z["blur"], z["near_mm"], z["far_mm"],
                [str(n) for n in z["names"]],
                # caches from before the option hold every scene
                float(z["traced_min_blur"]) if "traced_min_blur" in z.files else 0.0,
            )
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        raise ValueError(f"{path}: not a cached split ({type(e).__name__}: {e}); delete it to trace it again") from None
    n = len(split.names)
    shapes = [a.shape[0] for a in (split.aif, split.bokeh, split.disparity, split.focus, split.blur)]
    if any(m != n for m in shapes):
        raise ValueError(f"{path}: not a cached split (arrays of {shapes} scenes for {n} names); delete it to trace it again")
    return split


def prepare(
    data_dir: Path, specs: Sequence[SplitSpec], cli: Optional[str] = None, threads: int = 1, log=print,
    min_blur: float = 0.0, only: Optional[Sequence[str]] = None,
) -> Dict[str, Split]:
    """Makes (if missing) and loads every split, cached as ``data_dir/<name>.npz``; the
    ray-traced scenes stay in ``data_dir/<name>/``. With ``only``, just the splits of those
    names are made and loaded (``eval`` needs the test split alone: a larger test split in a
    new directory then traces nothing else). A split made here traces only the scenes
    with blur K >= ``min_blur`` px (the cache records it; :func:`with_min_blur` refuses a
    smaller threshold on it). ``data_dir/splits.json`` records the
    specs, all of them whatever ``only`` says; a cache made with other specs is an error
    (delete it or use another directory)."""
    if only is not None:
        unknown = sorted(set(only) - {s.name for s in specs})
        if unknown:
            raise ValueError(f"no split named {', '.join(unknown)} (splits: {', '.join(s.name for s in specs)})")
    data_dir.mkdir(parents=True, exist_ok=True)
    record = data_dir / "splits.json"
    want = [s.__dict__ for s in specs]
    text = json.dumps(want, indent=1)
    old = None
    if record.exists():
        try:
            old = record.read_text()
            # Caches from before the focus option are near focus; from before the detail or
            # the perspective option, without.
            made = [{"focus": "near", "background_detail": 0.0, "perspective": False, **r} for r in json.loads(old)]
        except (ValueError, TypeError) as e:
            raise ValueError(f"{record}: not a record of splits ({e}); delete it or use another --data directory") from None
        if made != want:
            raise ValueError(f"{record} was made with other splits; use another --data directory")
    # Written only when it changes, and whole (a temporary file renamed over it): processes
    # that share the cache (training and eval side by side) never read a half-written record.
    if old != text:
        tmp = _temp_beside(record)
        tmp.write_text(text)
        tmp.replace(record)
    out: Dict[str, Split] = {}
    for spec in specs:
        if only is not None and spec.name not in only:
            continue
        cache = data_dir / f"{spec.name}.npz"
        if not cache.exists():
            import time

            t0 = time.perf_counter()
            make_benchmark(spec, data_dir / spec.name, find_cli(cli), threads, min_blur)
            why = f"; only scenes with a blur K >= {min_blur} px were traced: lower the minimum blur" if min_blur > 0 else ""
            split = load_benchmark_dir(data_dir / spec.name, spec.focus, why)
            split.traced_min_blur = float(min_blur)
            _save(split, cache)
            log(f"data: {spec.name}: {len(split)} scenes at {spec.size} px in {time.perf_counter() - t0:.0f} s")
        out[spec.name] = _load(cache)
    return out


def subset(split: Split, keep: np.ndarray) -> Split:
    """The scenes where ``keep`` (a boolean ``(N,)`` array) is true."""
    idx = np.flatnonzero(keep)
    return Split(
        split.aif[idx], split.bokeh[idx], split.disparity[idx], split.focus[idx], split.blur[idx],
        split.near_mm[idx], split.far_mm[idx], [split.names[i] for i in idx], split.traced_min_blur,
    )


def scene_index(name: str) -> int:
    """The index in a scene's directory name (``scene_0020`` -> 20). A split's scene layout
    (billboards, textures, disparity) follows its seed and this index; the name's zero
    padding and the scene's blur K follow the number of scenes traced, so the same index
    in a larger split of the same seed is the same layout with another K."""
    stem, _, digits = name.rpartition("_")
    if not stem or not digits.isdigit():
        raise ValueError(f"{name!r}: not a scene name (scene_<index>)")
    return int(digits)


def without_scenes(split: Split, indices: Sequence[int]) -> Split:
    """The split without the scenes whose index (:func:`scene_index`) is in ``indices``
    (e.g. a larger test split without the layouts of a smaller one that choices were made
    on). Leaving no scene is a ``ValueError``."""
    drop = set(indices)
    kept = subset(split, np.array([scene_index(n) not in drop for n in split.names], dtype=bool))
    if len(kept) == 0:
        raise ValueError(f"leaving out {len(drop)} scene indices leaves none of the split's {len(split)} scenes")
    return kept


def check_min_blur(min_blur_px: float) -> float:
    """``min_blur_px`` if it is a blur radius in pixels (finite, >= 0); else a ``ValueError``."""
    if not (np.isfinite(min_blur_px) and min_blur_px >= 0.0):
        raise ValueError(f"minimum blur {min_blur_px}: must be a radius in pixels, >= 0")
    return min_blur_px


def with_min_blur(splits: Dict[str, Split], min_blur_px: float) -> Dict[str, Split]:
    """Every split with only its scenes whose largest blur K is at least ``min_blur_px``
    pixels (all of them for 0). A split left with no scene is an error, and so is a
    negative or non-finite threshold (:func:`check_min_blur`), and so is a threshold below
    the one a split's cache was traced with (it lacks the scenes in between)."""
    check_min_blur(min_blur_px)
    for name, split in splits.items():
        if min_blur_px < split.traced_min_blur:
            raise ValueError(
                f"minimum blur {min_blur_px} px: the cached {name} split holds only scenes with K >= "
                f"{split.traced_min_blur} px; use that threshold or more, or another --data directory"
            )
    if min_blur_px == 0.0:
        return dict(splits)
    out: Dict[str, Split] = {}
    for name, split in splits.items():
        kept = subset(split, split.blur >= min_blur_px)
        if len(kept) == 0:
            largest = float(split.blur.max()) if len(split) else 0.0
            raise ValueError(f"minimum blur {min_blur_px} px: no {name} scene has a blur that large (largest {largest:.2f} px)")
        out[name] = kept
    return out


def random_crops(
    split: Split, indices: np.ndarray, crop: int, rng: np.random.Generator,
    extra: Optional[Dict[str, np.ndarray]] = None, vertical_flips: bool = True,
) -> Dict[str, np.ndarray]:
    """A batch of random ``crop x crop`` windows with random horizontal and vertical flips
    (the same for image, target and disparity, and for the ``(N, C, H, W)`` arrays in
    ``extra``, returned under their keys). The random draws do not depend on ``extra``.
    ``vertical_flips=False`` leaves the images upright (scenes with a ground, where height
    in the frame says how far a thing is); the draws are the same either way."""
    h, w = split.aif.shape[-2:]
    arrays = {"aif": split.aif, "bokeh": split.bokeh, "disparity": split.disparity, **(extra or {})}
    out: Dict[str, List[np.ndarray]] = {k: [] for k in arrays}
    for i in indices:
        y = int(rng.integers(0, h - crop + 1))
        x = int(rng.integers(0, w - crop + 1))
        fy, fx = bool(rng.integers(0, 2)), bool(rng.integers(0, 2))
        fy = fy and vertical_flips
        for key in out:
            a = arrays[key][i, :, y : y + crop, x : x + crop]
            if fy:
                a = a[:, ::-1]
            if fx:
                a = a[:, :, ::-1]
            out[key].append(np.ascontiguousarray(a))
    batch = {k: np.stack(v) for k, v in out.items()}
    batch["focus"] = split.focus[indices]
    batch["blur"] = split.blur[indices]
    return batch
