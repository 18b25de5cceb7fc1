"""``python -m drbokeh.dfdnet train|eval|reproduce ... --out DIR``: depth networks trained
through rendering layers, without depth labels (the Dr.Bokeh supplement's figs. 9-10):
a U-Net reads the all-in-focus image, predicts disparity, a rendering layer blurs the
image with it, and the loss compares that with the ray-traced defocused image. The true
disparity is used only to evaluate. Protocol and results: docs/dfdnet.md.

  train      train runs (default: the whole table) into DIR; ``--quick`` makes tiny data in
             DIR/data itself, trains drbokeh ``physical`` for a few steps and writes
             DIR/results.json (loss first/last, test MAE trained vs untrained)
  eval       the test table (results.md/.json), index.html with test images, plots/*.svg
  reproduce  train the whole table, then eval (the one command behind the table)
  table      one table over several seeds: the eval outputs of one protocol run with
             other --seed values, per run the MAE of each seed, mean, spread and wins
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .data import FOCUS, Split, SplitSpec, check_min_blur, default_splits, prepare, scene_index, with_min_blur, without_scenes
from .evaluate import evaluate, metrics
from .layers import LAYERS
from .losses import LOSSES
from .train import (FROM, HIGHLIGHTS, INPUTS, split_loss, TABLE_RUNS, RunSpec, TrainConfig, existing, log_line, longest_first,
                    new_model, parse_run, predict, stale_start, start_problem, train_logged, train_run)


_log = log_line
SIZE = 128
QUICK_SIZE = 64
# The table's data: fine detail on the backgrounds (session 10), so that every part of the
# background shows its blur.
BACKGROUND_DETAIL = 1.0
# --quick's own settings (tiny data, a few steps; the Python test suite's check).
QUICK = {"steps": 40, "batch": 4, "crop": 64, "background_detail": 0.0, "init_disparity": "pytorch"}
# ``--protocol NAME``: a table's settings under one name, so that reproducing it is one short
# command; options given on the command line win over them. ``session12``: the options'
# own defaults (session 12's table); ``session29``: the table of sessions 27-30
# (docs/dfdnet.md): scenes with a depth cue, four times the training scenes, only scenes
# with K >= 3 px, batches of 4, a start of 0.15, the focus prior inside the depth of
# field, and the runs with the five-layer stacks, the loss ablation and the supervised bound.
PROTOCOLS: Dict[str, Dict[str, Any]] = {
    "session12": {},
    "session29": {
        "perspective": True, "train_scenes": 960, "val_scenes": 64, "test_scenes": 128, "min_blur": 3.0,
        "batch": 4, "inputs": "aif", "init_disparity": 0.15, "focus_prior": 4.0, "focus_prior_radius": 1.0,
        "runs": "physical5-hssim,physical5-ssim,physical5-l1g,paper5-hssim,aperture-hssim,gausspsf-hssim,supervised",
    },
}
PROTOCOL_HELP = ("a table's settings by name, as defaults that the options given here override: session12 (the "
                 "options' own defaults: session 12's table), session29 (docs/dfdnet.md's current table, sessions "
                 "27-30: " + " ".join(f"--{k.replace('_', '-')}" + ("" if v is True else f" {v}")
                                       for k, v in PROTOCOLS["session29"].items()) + ")")


def _init_arg(text: str) -> object:
    if text.strip().lower() == "pytorch":
        return "pytorch"
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a disparity in (0, 1) or 'pytorch'") from None
    if not 0.0 < v < 1.0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a disparity in (0, 1) or 'pytorch'")
    return v


def _number_arg(parse: Callable[[str], Any], ok: Callable[[Any], bool], expected: str) -> Callable[[str], Any]:
    """An argparse ``type``: ``parse(text)`` where it parses and ``ok`` holds, else one line
    saying what was ``expected``."""

    def arg(text: str) -> Any:
        try:
            v = parse(text)
        except ValueError:
            v = None
        if v is None or not ok(v):
            raise argparse.ArgumentTypeError(f"{text!r}: expected {expected}")
        return v

    return arg


# A count (steps, images, scenes, pixels, threads, jobs): a whole number >= 1.
_count_arg = _number_arg(int, lambda v: v >= 1, "a whole number >= 1")
# --lr: a finite number > 0.
_rate_arg = _number_arg(float, lambda v: math.isfinite(v) and v > 0.0, "a learning rate > 0, e.g. 0.004")
# A loss weight: a finite number >= 0.
_weight_arg = _number_arg(float, lambda v: math.isfinite(v) and v >= 0.0, "a weight >= 0")
# --focus-prior-radius PX: a blur radius in pixels > 0.
_radius_arg = _number_arg(float, lambda v: math.isfinite(v) and v > 0.0, "a blur radius in pixels > 0, e.g. 1")


def _min_blur_arg(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a blur radius in pixels, >= 0") from None
    try:
        return check_min_blur(v)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _warmup_arg(text: str) -> Tuple[float, int]:
    """``--focus-prior-warmup WEIGHT:STEPS``: a weight >= 0 and a step count >= 1."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        weight, steps = float(parts[0]), int(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WEIGHT:STEPS, e.g. 4:300") from None
    if not math.isfinite(weight) or weight < 0.0 or steps < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a weight >= 0 and at least one step, e.g. 4:300")
    return weight, steps


def _seeds_arg(text: str) -> List[int]:
    """``--seeds 17,18,19``: at least two distinct integers."""
    try:
        seeds = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated integers, e.g. 17,18,19") from None
    if len(seeds) < 2 or len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"{text!r}: expected at least two distinct seeds (for one, use --seed)")
    return seeds


def _resolve(a: argparse.Namespace, quick: bool) -> None:
    """Fills the options left unset with the table's values, or --quick's."""
    table = {"steps": TrainConfig.steps, "batch": TrainConfig.batch, "crop": a.size,
             "background_detail": BACKGROUND_DETAIL, "init_disparity": TrainConfig.init_disparity}
    for key, value in (QUICK if quick else table).items():
        if getattr(a, key) is None:
            setattr(a, key, min(value, a.size) if quick and key == "crop" else value)
    if a.init_disparity == "pytorch":
        a.init_disparity = None


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", "--out", dest="out", required=True, type=Path, help="output directory")
    p.add_argument("--protocol", choices=tuple(PROTOCOLS), default="session12", help=PROTOCOL_HELP)
    p.add_argument("--data", type=Path, help="data cache directory (default OUT/data); scenes are made there if missing")
    p.add_argument("--drbokeh", help="the drbokeh command line (default $DRBOKEH_CLI, PATH, or this checkout's target/release)")
    p.add_argument("--size", type=_count_arg, default=SIZE, help=f"scene size, px (default {SIZE}; {QUICK_SIZE} with --quick)")
    p.add_argument("--spp", type=_count_arg, default=144, help="samples per pixel of the traced images (default 144)")
    p.add_argument("--focus", choices=tuple(FOCUS), default="far",
                   help="far (default): scenes focused on the background, d >= 0; near: on the nearest billboard, d <= 0 (docs/dfdnet.md)")
    p.add_argument("--background-detail", type=float, default=None, metavar="STRENGTH",
                   help=f"fine detail on the scenes' backgrounds, in [0, 1] (default {BACKGROUND_DETAIL}; 0 with --quick; "
                        "drbokeh benchmark make --background-detail; docs/dfdnet.md)")
    p.add_argument("--perspective", action="store_true",
                   help="scenes whose foregrounds' size and height in the frame follow their depth (nearer: larger, "
                        "lower), so the all-in-focus image carries a depth cue as photos do; without it the image says "
                        "nothing about how far a billboard is; training crops are then not flipped upside down "
                        "(drbokeh benchmark make --perspective; docs/dfdnet.md)")
    p.add_argument("--min-blur", type=_min_blur_arg, default=0.0, metavar="K_PX",
                   help="keep only scenes whose largest blur K is at least K_PX pixels, in every split "
                        "(default 0: all; the scenes are traced and cached as without it)")
    p.add_argument("--train-scenes", type=_count_arg, default=240, help="scenes traced for training (default 240; with far focus about half are kept)")
    p.add_argument("--val-scenes", type=_count_arg, default=32)
    p.add_argument("--test-scenes", type=_count_arg, default=64)
    p.add_argument("--threads", type=_count_arg, default=1, help="torch and renderer threads per run (default 1: on a shared machine two processes of one thread beat one of two); tracing the data uses --jobs x --threads")
    p.add_argument("--steps", type=_count_arg, default=None,
                   help=f"training steps per run (default {TrainConfig.steps}; {QUICK['steps']} with --quick)")
    p.add_argument("--batch", type=_count_arg, default=None,
                   help=f"images per step (default {TrainConfig.batch}; {QUICK['batch']} with --quick)")
    p.add_argument("--crop", type=_count_arg, default=None,
                   help=f"training crop side, a multiple of 16 (default: the whole scene, --size; {QUICK['crop']} with --quick)")
    p.add_argument("--base", type=_count_arg, default=TrainConfig.base, help=f"U-Net width (default {TrainConfig.base}: about 1.1 M parameters)")
    p.add_argument("--lr", type=_rate_arg, default=TrainConfig.lr)
    p.add_argument("--seed", type=int, default=TrainConfig.seed,
                   help=f"initial weights and batch order (default {TrainConfig.seed}); every run of one command shares it")
    p.add_argument("--highlights", choices=HIGHLIGHTS, default=TrainConfig.highlights,
                   help=f"clipped highlights in the loss (default {TrainConfig.highlights}; docs/dfdnet.md)")
    p.add_argument("--init-disparity", type=_init_arg, default=None, metavar="DISPARITY|pytorch",
                   help=f"initial disparity output, the head's bias (default {TrainConfig.init_disparity}: near the background's "
                        "disparity, 0; 'pytorch': PyTorch's initialisation, about 0.5, the default with --quick)")
    p.add_argument("--inputs", choices=INPUTS, default=TrainConfig.inputs,
                   help="what the network sees: the all-in-focus image (default, depth from one image; the defocused "
                        "image is only the loss's target) or 'aif+bokeh', the defocused image beside it (depth from the pair)")
    p.add_argument("--focus-prior", type=_weight_arg, default=TrainConfig.w_focus, metavar="WEIGHT",
                   help="weight of a prior for the least defocus: WEIGHT x mean |disparity - focus| (default 0: off; docs/dfdnet.md)")
    p.add_argument("--focus-prior-warmup", type=_warmup_arg, default=None, metavar="WEIGHT:STEPS",
                   help="start the focus prior at WEIGHT and lower it linearly to --focus-prior over the first STEPS "
                        "steps (default: no warm-up; e.g. 4:300; tried in session 23, not kept: docs/dfdnet.md)")
    p.add_argument("--focus-prior-radius", type=_radius_arg, default=None, metavar="PX",
                   help="apply the focus prior only inside the depth of field: each pixel's term is capped at PX / K, so "
                        "it stops pulling once the predicted blur radius K |disparity - focus| reaches PX pixels "
                        "(default: everywhere; e.g. 1; session 24: docs/dfdnet.md)")
    p.add_argument("--jobs", type=_count_arg, default=2, help="runs trained at once, one process each (default 2); results do not depend on it")
    p.add_argument("--runs", help="comma-separated runs (LAYER-LOSS or supervised; layers: " + ", ".join(LAYERS)
                   + "; losses: " + ", ".join(LOSSES) + "; or a fine-tune RUN-from-START, e.g. "
                   "physical5-hssim-from-aperture-hssim: START's trained network, --finetune-steps more through RUN's "
                   "layer and loss; START is trained first); default: the table: " + ",".join(r.name for r in TABLE_RUNS))
    p.add_argument("--finetune-steps", type=_count_arg, default=TrainConfig.finetune_steps, metavar="STEPS",
                   help=f"steps of a fine-tune RUN-from-START (default {TrainConfig.finetune_steps}; session 35: docs/dfdnet.md)")
    p.add_argument("--finetune-lr", type=_rate_arg, default=TrainConfig.finetune_lr, metavar="RATE",
                   help=f"a fine-tune's learning rate, cosine to 5 %% of it (default {TrainConfig.finetune_lr:g})")


def _specs(a: argparse.Namespace) -> List[SplitSpec]:
    if not 0.0 <= a.background_detail <= 1.0:
        raise SystemExit(f"--background-detail {a.background_detail}: must be in [0, 1]")
    return default_splits(a.size, a.spp, a.train_scenes, a.val_scenes, a.test_scenes, a.focus, a.background_detail,
                          a.perspective)


def _cfg(a: argparse.Namespace) -> TrainConfig:
    if a.crop % 16 or a.crop > a.size:
        raise SystemExit(f"--crop {a.crop}: must be a multiple of 16 and at most --size {a.size}")
    return TrainConfig(steps=a.steps, batch=a.batch, crop=a.crop, base=a.base, lr=a.lr, seed=a.seed, threads=a.threads,
                       highlights=a.highlights, init_disparity=a.init_disparity, inputs=a.inputs,
                       vertical_flips=not a.perspective, finetune_steps=a.finetune_steps, finetune_lr=a.finetune_lr,
                       **_prior_fields(a))


def _prior_fields(a: argparse.Namespace) -> Dict[str, Any]:
    """The focus prior's ``TrainConfig`` fields from the command line (weight, radius, warm-up)."""
    fields: Dict[str, Any] = {"w_focus": a.focus_prior, "focus_prior_radius_px": a.focus_prior_radius}
    if a.focus_prior_warmup is not None:
        fields["w_focus_start"], fields["focus_warmup_steps"] = a.focus_prior_warmup
    return fields


def _runs(a: argparse.Namespace) -> List[RunSpec]:
    if not a.runs:
        return list(TABLE_RUNS)
    try:
        return [parse_run(r.strip()) for r in a.runs.split(",") if r.strip()]
    except ValueError as e:
        raise SystemExit(f"--runs: {e}")


def _splits(a: argparse.Namespace, only: Optional[Sequence[str]] = None) -> Dict[str, Split]:
    """Every split (or those named in ``only``), traced into --data if missing, with the
    scenes below --min-blur left out. Tracing uses the cores the trainings will (``--jobs`` x
    ``--threads``); its bytes do not depend on the thread count."""
    trace_threads = a.threads * max(1, a.jobs)
    try:
        splits = prepare(a.data or a.out / "data", _specs(a), a.drbokeh, trace_threads, _log, min_blur=a.min_blur,
                         only=only)
    except ValueError as e:
        raise SystemExit(f"--data: {e}")
    try:
        kept = with_min_blur(splits, a.min_blur)
    except ValueError as e:
        raise SystemExit(f"--min-blur: {e}")
    if a.min_blur > 0:
        for name in kept:
            _log(f"data: {name}: {len(kept[name])} of {len(splits[name])} scenes with K >= {a.min_blur} px")
    return kept


def _train(a: argparse.Namespace, runs: List[RunSpec], cfg: TrainConfig) -> None:
    """Trains the runs not yet trained in --out (all of them with --retrain): the runs from
    scratch first, then the fine-tunes, whose starts must be trained by then. A fine-tune
    whose start is trained again now, or was since it was fine-tuned, is trained again too.
    Every fine-tune's start is checked before any tracing (one line if it cannot be one)."""
    fresh = [spec for spec in runs if spec.start is None and (a.retrain or existing(a.out, spec) is None)]
    finetunes = []
    for spec in runs:
        if spec.start is None:
            if spec not in fresh:
                _log(f"{spec.name}: already trained in {a.out / spec.name} (--retrain to redo)")
            continue
        stale = "its start is trained again now" if spec.start in fresh else stale_start(a.out, spec)
        if a.retrain or existing(a.out, spec) is None:
            finetunes.append(spec)
        elif stale is not None:
            _log(f"{spec.name}: trained again: {stale}")
            finetunes.append(spec)
        else:
            _log(f"{spec.name}: already trained in {a.out / spec.name} (--retrain to redo)")
    for spec in finetunes:
        assert spec.start is not None
        if spec.start not in fresh:
            if existing(a.out, spec.start) is None:
                raise SystemExit(f"--runs: {spec.name} starts from {spec.start.name}, which is neither trained in "
                                 f"{a.out} nor among the runs: add {spec.start.name} to --runs")
            problem = start_problem(a.out, spec.start, cfg)
            if problem is not None:
                raise SystemExit(f"--runs: {spec.name}: {problem}")
    a.out.mkdir(parents=True, exist_ok=True)
    splits = _splits(a)
    (a.out / "config.json").write_text(json.dumps(
        {"train": asdict(cfg), "splits": [s.__dict__ for s in _specs(a)], "min_blur_px": a.min_blur}, indent=1))
    for group in (fresh, finetunes):
        _train_group(a, group, splits, cfg)
    # Fine-tunes in --out that were not asked for and whose start was just trained again.
    for spec in _trained_finetunes(a.out):
        if spec not in runs:
            stale = stale_start(a.out, spec)
            if stale is not None:
                _log(f"note: {stale}")


def _trained_finetunes(out: Path) -> List[RunSpec]:
    """The fine-tunes trained in ``out`` (directories named ``RUN-from-START`` with a model)."""
    found = []
    for d in sorted(out.iterdir()) if out.is_dir() else []:
        if FROM in d.name:
            try:
                spec = parse_run(d.name)
            except ValueError:
                continue
            if existing(out, spec) is not None:
                found.append(spec)
    return found


def _train_group(a: argparse.Namespace, todo: List[RunSpec], splits: Dict[str, Split], cfg: TrainConfig) -> None:
    """Trains ``todo``, ``--jobs`` at once (one process each), the longest first."""
    if a.jobs <= 1 or len(todo) <= 1:
        for spec in todo:
            train_logged(spec, splits, cfg, a.out)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    todo = longest_first(todo)
    _log("training order (the longest first): " + ", ".join(spec.name for spec in todo))
    with ProcessPoolExecutor(a.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        for f in [pool.submit(train_logged, spec, splits, cfg, a.out) for spec in todo]:
            f.result()


# ``--exclude-scenes-of``: the scene indices to leave out of the test split, and the directory.
Exclusion = Optional[Tuple[List[int], Path]]


def _exclusion(a: argparse.Namespace) -> Exclusion:
    """The scene indices of ``--exclude-scenes-of DIR``'s test set (its results.json), after
    checking that DIR's test split, where its config.json records one, has this run's
    layouts (seed, size, focus, background, perspective): else the same index is another
    scene. ``None`` without the option."""
    d = a.exclude_scenes_of
    if d is None:
        return None
    what = f"--exclude-scenes-of {d}"
    try:
        names = json.loads((d / "results.json").read_text()).get("test_scenes")
    except FileNotFoundError:
        raise SystemExit(f"{what}: no results.json there (give an eval output directory)") from None
    except (OSError, ValueError, AttributeError) as e:
        raise SystemExit(f"{what}: results.json is not an eval results file ({type(e).__name__}: {e})") from None
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise SystemExit(f"{what}: results.json lists no test scenes")
    try:
        indices = [scene_index(n) for n in names]
    except ValueError as e:
        raise SystemExit(f"{what}: results.json: {e}") from None
    mine = next(s for s in _specs(a) if s.name == "test")
    try:
        theirs = [s for s in json.loads((d / "config.json").read_text()).get("splits", []) if s.get("name") == "test"]
    except FileNotFoundError:
        theirs = []
    except (OSError, ValueError, AttributeError) as e:
        raise SystemExit(f"{what}: config.json is not readable ({type(e).__name__}: {e})") from None
    for key in ("seed", "size", "focus", "background_detail", "perspective"):
        if theirs and theirs[0].get(key) != getattr(mine, key):
            raise SystemExit(f"{what}: its test split has another {key} ({theirs[0].get(key)!r} against "
                             f"{getattr(mine, key)!r}), so its scene indices are other layouts")
    return indices, d


def _eval(a: argparse.Namespace, runs: List[RunSpec], cfg: TrainConfig, exclusion: Exclusion) -> None:
    """The eval, on the test split without ``exclusion``'s scenes (:func:`_exclusion`). It
    reads (and, if missing, traces) the test split alone. Runs not trained in --out are left
    out and named; none trained is an error, before any tracing."""
    missing = [spec.name for spec in runs if existing(a.out, spec) is None]
    if len(missing) == len(runs):
        raise SystemExit(f"eval: no run of {', '.join(missing)} is trained in {a.out} (train writes "
                         f"{a.out}/RUN/model.pt: give eval the --out that train had)")
    if missing:
        _log(f"eval: not trained in {a.out}, left out: {', '.join(missing)}")
    for spec in runs:
        stale = stale_start(a.out, spec)
        if stale is not None:
            raise SystemExit(f"eval: {stale}")
    splits = _splits(a, only=("test",))
    left_out = ""
    if exclusion is not None:
        indices, d = exclusion
        test = splits["test"]
        try:
            splits["test"] = without_scenes(test, indices)
        except ValueError as e:
            raise SystemExit(f"--exclude-scenes-of {d}: {e}") from None
        left_out = (f"{len(test) - len(splits['test'])} of the split's {len(test)} scenes left out: "
                    f"the layouts of {d}'s test set (--exclude-scenes-of)")
        _log(f"eval: {left_out}")
    res = evaluate(a.out, splits, runs, cfg, note=a.note or "", left_out=left_out)
    _log(f"wrote {a.out / 'results.md'}, {a.out / 'index.html'}")
    print((a.out / "results.md").read_text())
    del res


def _write_table(dirs: List[Path], out: Path) -> None:
    from .seeds import SeedTableError, write_table

    try:
        write_table(dirs, out)
    except SeedTableError as e:
        raise SystemExit(f"error: {e}") from None
    _log(f"wrote {out / 'results.md'}")
    print((out / "results.md").read_text())


def _reproduce_seeds(a: argparse.Namespace, exclusion: Exclusion) -> None:
    """``reproduce --seeds``: the table at each seed into OUT/seed<S> (one data cache), then
    the table over the seeds in OUT."""
    dirs = []
    for seed in a.seeds:
        b = _namespace_with(a, seed=seed, out=a.out / f"seed{seed}", data=a.data or a.out / "data")
        runs, cfg = _runs(b), _cfg(b)
        _log(f"seed {seed}: {b.out}")
        _train(b, runs, cfg)
        _eval(b, runs, cfg, exclusion)
        dirs.append(b.out)
    _write_table(dirs, a.out)


def _namespace_with(a: argparse.Namespace, **changes: object) -> argparse.Namespace:
    """A copy of ``a`` with ``changes``."""
    return argparse.Namespace(**{**vars(a), **changes})


def _quick(a: argparse.Namespace) -> None:
    """Tiny data (64 px, far focus as the table), a few steps of drbokeh ``physical``."""
    specs = [SplitSpec("train", 1711, 64, a.size, a.spp, a.focus, a.background_detail, a.perspective),
             SplitSpec("val", 1712, 8, a.size, a.spp, a.focus, a.background_detail, a.perspective),
             SplitSpec("test", 1713, 24, a.size, a.spp, a.focus, a.background_detail, a.perspective)]
    cfg = TrainConfig(steps=a.steps, batch=a.batch, crop=a.crop, base=8,
                      lr=a.lr, eval_every=10, threads=a.threads, highlights=a.highlights,
                      init_disparity=a.init_disparity, inputs=a.inputs, vertical_flips=not a.perspective,
                      **_prior_fields(a))
    a.out.mkdir(parents=True, exist_ok=True)
    splits = prepare(a.data or a.out / "data", specs, a.drbokeh, a.threads, _log)
    spec = RunSpec("physical", "hssim")
    r = train_run(spec, splits, cfg, a.out, _log)
    losses = [c["loss"] for c in r["curve"]]
    n = max(1, len(losses) // 5)
    from .train import load_model

    test = splits["test"]
    trained_model, untrained_model = load_model(a.out / spec.name, cfg), new_model(cfg)
    test_input = cfg.input_of(test.aif, test.bokeh)
    trained = metrics(predict(trained_model, test_input), test)
    untrained = metrics(predict(untrained_model, test_input), test)
    out = {
        "run": spec.name, "steps": cfg.steps,
        "loss_first": float(np.mean(losses[:n])), "loss_last": float(np.mean(losses[-n:])),
        # The training loss on the whole validation images (fixed, unlike the batches).
        "val_loss_untrained": split_loss(untrained_model, splits["val"], spec, cfg),
        "val_loss_trained": split_loss(trained_model, splits["val"], spec, cfg),
        "test_mae_trained": trained["mae"], "test_mae_untrained": untrained["mae"],
        "seconds_per_step": r["seconds_per_step"],
    }
    (a.out / "results.json").write_text(json.dumps(out, indent=1))
    _log(json.dumps(out))


RETRAIN_HELP = ("train runs again even if DIR has them (a fine-tune RUN-from-START is trained again anyway when "
                "START is, now or since)")
NOTE_HELP = "a line put above the table (e.g. what is reduced)"
EXCLUDE_HELP = ("score only the test scenes whose layouts are not in DIR's test set (DIR: an eval output of the same "
                "test seed, e.g. a smaller --test-scenes that choices were made on); scenes match by index")

EXAMPLES = {
    "main": """examples:
  python -m drbokeh.dfdnet train --quick --out q        # a few minutes: tiny data, 40 steps
  python -m drbokeh.dfdnet reproduce --data D --out R   # session 12's table (about 45 min on 2 cores)
  python -m drbokeh.dfdnet reproduce --protocol session29 --data D --out R --seed 24   # the current table (1.5-2 h)
  python -m drbokeh.dfdnet train --data D --out R --runs physical-hssim,gausspsf-hssim --seed 18
  python -m drbokeh.dfdnet table R17 R18 R19 -o T       # one table over three seeds' eval outputs""",
    "train": """examples:
  python -m drbokeh.dfdnet train --quick --out q
  python -m drbokeh.dfdnet train --data D --out R --runs physical-hssim,gausspsf-hssim
  python -m drbokeh.dfdnet train --data D --out R --runs physical-hssim --focus-prior 1 --steps 500

Runs already in DIR are kept (--retrain trains them again). Each run writes DIR/RUN/model.pt
and DIR/RUN/log.json; the data is traced into --data (default DIR/data) once and reused.""",
    "eval": """examples:
  python -m drbokeh.dfdnet eval --data D --out R
  python -m drbokeh.dfdnet eval --data D --out R --note "seed 18"
  python -m drbokeh.dfdnet eval --data D2 --test-scenes 512 --out E --exclude-scenes-of R   # new layouts only

Evaluates the runs trained in DIR on the test split: DIR/results.md and results.json,
DIR/index.html with the test images, DIR/plots/*.svg (loss curves, validation MAE).
It reads only the test split of --data, and traces only that split if it is missing.
A fine-tune RUN-from-START whose START was trained again since is refused (its log records
the start's weights): train it again first (train --runs RUN-from-START).""",
    "table": """examples:
  python -m drbokeh.dfdnet table R17 R18 R19 -o T     # R17..R19: eval outputs of seeds 17-19
  python -m drbokeh.dfdnet table P17 P18 -o T2         # two seeds are enough to run it

Each DIR is what `eval --out DIR --seed N` wrote for one seed N of the same protocol.

Reads each DIR/results.json (and config.json), checks that they differ only in the seed
(test scenes, each run's training settings, data), and writes OUT/results.md and
results.json: per run the test MAE at every seed, the mean, the spread (min-max), at how
many seeds it was the lowest of the runs trained through a rendering layer, and the means
of RMSE, delta < 1.25, MAE bg/fg and s/epoch.""",
    "reproduce": """examples:
  python -m drbokeh.dfdnet reproduce --data D --out R
  python -m drbokeh.dfdnet reproduce --data D --out R --seed 19
  python -m drbokeh.dfdnet reproduce --data D --out R --seeds 17,18,19   # R/seed17..19, R/results.md
  python -m drbokeh.dfdnet reproduce --protocol session29 --data D --out R --seed 24   # docs/dfdnet.md's table

Traces the data if --data lacks it, trains every run of the table (--jobs at once), then
evaluates: the one command behind docs/dfdnet.md's table.""",
}


def parse_args(argv: Optional[List[str]] = None) -> argparse.Namespace:
    """The command line, with the options left unset filled in (the table's values, or
    ``--quick``'s)."""
    raw = argparse.RawDescriptionHelpFormatter
    ap = argparse.ArgumentParser(prog="python -m drbokeh.dfdnet", description=__doc__,
                                 epilog=EXAMPLES["main"], formatter_class=raw)
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="train runs", description="Train depth networks through rendering layers.",
                       epilog=EXAMPLES["train"], formatter_class=raw)
    _common(t)
    t.add_argument("--quick", action="store_true", help="tiny self-made data, few steps, DIR/results.json")
    t.add_argument("--retrain", action="store_true", help=RETRAIN_HELP)
    e = sub.add_parser("eval", help="test table, HTML page, plots", description="The test table of the runs in DIR.",
                       epilog=EXAMPLES["eval"], formatter_class=raw)
    _common(e)
    e.add_argument("--note", help=NOTE_HELP)
    e.add_argument("--exclude-scenes-of", type=Path, metavar="DIR", help=EXCLUDE_HELP)
    r = sub.add_parser("reproduce", help="train the whole table, then eval",
                       description="Train the whole table, then evaluate it.", epilog=EXAMPLES["reproduce"],
                       formatter_class=raw)
    _common(r)
    r.add_argument("--retrain", action="store_true", help=RETRAIN_HELP)
    r.add_argument("--note", help=NOTE_HELP)
    r.add_argument("--exclude-scenes-of", type=Path, metavar="DIR", help=EXCLUDE_HELP)
    r.add_argument("--seeds", type=_seeds_arg, metavar="S,S,...",
                   help="the whole table at each seed (instead of --seed) into OUT/seed<S>, sharing the data, "
                        "then one table over them in OUT (as the table command)")
    tb = sub.add_parser("table", help="one table over several seeds' eval outputs",
                        description="One test table over the eval outputs of several seeds.",
                        epilog=EXAMPLES["table"], formatter_class=raw)
    tb.add_argument("dirs", nargs="+", type=Path, metavar="DIR", help="eval output directories, one per --seed")
    tb.add_argument("-o", "--output", "--out", dest="out", required=True, type=Path, help="output directory")
    a = ap.parse_args(argv)
    if a.cmd == "table":
        return a
    quick = a.cmd == "train" and a.quick
    if a.protocol != "session12":
        if quick:
            ap.error("--protocol and --quick: --quick has its own settings")
        # Again with the protocol's settings as defaults, so that what is given here wins.
        for sp in (t, e, r):
            sp.set_defaults(**PROTOCOLS[a.protocol])
        a = ap.parse_args(argv)
    if quick and a.size == SIZE:
        a.size = QUICK_SIZE
    _resolve(a, quick)
    return a


def _check_directories(a: argparse.Namespace) -> None:
    """--out (and --data) must be directories or not exist yet: a file there is refused in
    one line before anything is traced, trained or written."""
    for option, path in (("--out", a.out), ("--data", getattr(a, "data", None))):
        if path is not None and path.exists() and not path.is_dir():
            raise SystemExit(f"{option} {path}: exists and is not a directory")


def main(argv: Optional[List[str]] = None) -> int:
    a = parse_args(argv)
    _check_directories(a)
    try:
        return _run(a)
    except OSError as e:
        # at the command line's edge: a directory that cannot be made or a file that cannot
        # be written (permissions, a full disk) in one line, not a traceback
        where = f"{e.filename}: " if e.filename else ""
        raise SystemExit(f"error: {where}{e.strerror or e}") from None


def _run(a: argparse.Namespace) -> int:
    if a.cmd == "table":
        _write_table(a.dirs, a.out)
        return 0
    if a.cmd == "train" and a.quick:
        _quick(a)
        return 0
    start = time.monotonic()
    if a.protocol != "session12":
        _log(f"protocol {a.protocol} (options given on the command line override it)")
    # read (and a bad one refused) before tracing and training
    exclusion = _exclusion(a) if a.cmd in ("eval", "reproduce") else None
    if a.cmd == "reproduce" and a.seeds:
        _reproduce_seeds(a, exclusion)
    else:
        runs, cfg = _runs(a), _cfg(a)
        if a.cmd in ("train", "reproduce"):
            _train(a, runs, cfg)
        if a.cmd in ("eval", "reproduce"):
            _eval(a, runs, cfg, exclusion)
    if a.cmd == "reproduce":
        _log(f"reproduce: {(time.monotonic() - start) / 60:.1f} min wall in all (data, training, eval)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
