"""Evaluation: the test table (markdown + JSON), the HTML page of test images, loss plots.

Metrics on the full test images (128 px by default), every pixel of every scene:
MAE and RMSE of the normalised disparity; ``delta < 1.25``, the fraction of pixels whose
metric depth ratio ``max(z / z*, z* / z)`` is below 1.25, with depth from disparity through
the scene's range (``1/z = d (1/z_near - 1/z_far) + 1/z_far``; disparity 0 is the finite
far depth). ``MAE K>=3`` is the MAE over the scenes whose largest blur is at least 3 px
(6 px at 256 px, the group docs/dfd.md targets). ``MAE tex`` is the MAE over the pixels
where defocus can say something about depth: those whose all-in-focus neighbourhood is
textured (:func:`textured_mask`); elsewhere (flat areas) any disparity renders alike and a
self-supervised network has nothing to learn from. ``MAE bg`` / ``MAE fg``: the MAE over
the pixels whose true disparity is below / at least ``BACKGROUND_DISPARITY`` (with far
focus the in-focus background, about 70 % of the pixels, and the foregrounds); the
all-pixel MAE is mostly the background's level. ``loss pred / truth``: for a run trained
through a rendering layer, its training loss (layer, loss terms, focus prior) on the whole
test images at the network's prediction and at the true disparity, averaged over the
scenes, and ``truth lower``: in how many scenes the loss ranks the truth below the
prediction. A layer whose loss ranks the truth lower in most scenes has a network that
did not reach what its loss asks for; one that ranks the prediction lower has a loss whose
minimum lies away from the truth (docs/dfdnet.md, "Session 31"). Reference rows: the untrained network
(the same initial weights every run starts from) and the oracle constant (the median of
each scene's *true* disparity).
"""

from __future__ import annotations

import json
from dataclasses import replace
from html import escape
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .data import Split
from .report import smooth, svg_lines, upscale, write_png
from .train import RunSpec, TrainConfig, existing, load_model, new_model, predict, scene_losses, started_from


def depth_mm(disparity: np.ndarray, near_mm: np.ndarray, far_mm: np.ndarray) -> np.ndarray:
    shape = (-1,) + (1,) * (disparity.ndim - 1)
    inv_near, inv_far = (1.0 / near_mm).reshape(shape), (1.0 / far_mm).reshape(shape)
    return 1.0 / (disparity.astype(np.float64) * (inv_near - inv_far) + inv_far)


TEXTURE_STD = 0.04
BACKGROUND_DISPARITY = 0.05
TEXTURE_WINDOW = 5


def textured_mask(aif: np.ndarray, window: int = TEXTURE_WINDOW, threshold: float = TEXTURE_STD) -> np.ndarray:
    """``(N, 3, H, W)`` display-encoded all-in-focus images -> ``(N, 1, H, W)`` booleans:
    the standard deviation of the luminance (mean of the channels) over the
    ``window x window`` box around the pixel (edge-replicated) is at least ``threshold``."""
    lum = aif.astype(np.float64).mean(1)
    r = window // 2
    pad = np.pad(lum, ((0, 0), (r, r), (r, r)), mode="edge")
    h, w = lum.shape[-2:]
    s1 = np.zeros_like(lum)
    s2 = np.zeros_like(lum)
    for dy in range(window):
        for dx in range(window):
            v = pad[:, dy : dy + h, dx : dx + w]
            s1 += v
            s2 += v * v
    n = window * window
    var = np.maximum(s2 / n - (s1 / n) ** 2, 0.0)
    return (np.sqrt(var) >= threshold)[:, None]


def metrics(pred: np.ndarray, split: Split, k_min: float = 3.0) -> Dict[str, Union[float, List[float]]]:
    """The test metrics of predicted disparities ``pred`` against ``split``'s truth: MAE,
    RMSE and delta < 1.25 (on depth), MAE where K >= ``k_min``, on textured pixels, on the
    background and the foreground, and each scene's MAE."""
    truth = split.disparity
    err = pred.astype(np.float64) - truth
    zp, zt = depth_mm(pred, split.near_mm, split.far_mm), depth_mm(truth, split.near_mm, split.far_mm)
    ratio = np.maximum(zp / zt, zt / zp)
    big = split.blur >= k_min
    tex = textured_mask(split.aif)
    bg = truth < BACKGROUND_DISPARITY
    return {
        "mae": float(np.abs(err).mean()),
        "rmse": float(np.sqrt((err ** 2).mean())),
        "delta125": float((ratio < 1.25).mean()),
        "mae_k3": float(np.abs(err[big]).mean()) if big.any() else float("nan"),
        "mae_tex": float(np.abs(err[tex]).mean()) if tex.any() else float("nan"),
        "textured_fraction": float(tex.mean()),
        "mae_bg": float(np.abs(err[bg]).mean()) if bg.any() else float("nan"),
        "mae_fg": float(np.abs(err[~bg]).mean()) if (~bg).any() else float("nan"),
        # Each test scene's MAE, in the order of ``test_scenes``: ``table`` pairs runs scene
        # by scene (seeds.py), which separates differences smaller than the seed spread.
        "mae_per_scene": [float(v) for v in np.abs(err).reshape(len(split), -1).mean(axis=1)],
    }


def constant_guess(split: Split) -> np.ndarray:
    med = np.median(split.disparity.reshape(len(split), -1), axis=1)
    return np.broadcast_to(med[:, None, None, None], split.disparity.shape).astype(np.float32)


def _fmt(v: float, digits: int = 4) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


# The ``TrainConfig`` fields that make up a run's training loss (``image_loss``).
LOSS_FIELDS = ("w_l1", "w_smooth", "w_structure", "edge_sensitivity", "highlights", "w_focus", "focus_prior_radius_px")


def trained_loss(log_config: Dict[str, Any], cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with the loss settings a run's log records (its weights, highlight mode and
    focus prior at the end of training), so that the loss is the one it was trained with
    whatever the eval's command line says."""
    return replace(cfg, **{k: log_config[k] for k in LOSS_FIELDS if k in log_config})


def evaluate(
    out_dir: Path,
    splits: Dict[str, Split],
    runs: Sequence[RunSpec],
    cfg: TrainConfig,
    html_scenes: int = 8,
    note: str = "",
    left_out: str = "",
) -> Dict[str, Any]:
    """Writes ``results.md``, ``results.json``, ``index.html`` (+ ``html/*.png``) and
    ``plots/*.svg`` into ``out_dir``; returns the results. ``left_out`` says which scenes of
    the split the test set lacks (empty: none), in the table's header and the JSON."""
    test = splits["test"]
    rows: List[Dict[str, Any]] = []
    preds: Dict[str, np.ndarray] = {}
    starts: Dict[Tuple[int, int, Optional[float], str], TrainConfig] = {}
    logs: Dict[str, Dict[str, Any]] = {}  # the trained runs' logs, for the plots too
    for spec in runs:
        run_dir = out_dir / spec.name
        log = existing(out_dir, spec)
        if log is None:  # not trained here
            continue
        logs[spec.name] = log
        start = started_from(log["config"], cfg)
        starts[(start.seed, start.base, start.init_disparity, start.inputs)] = start
        p = predict(load_model(run_dir, spec.config(start)), start.input_of(test.aif, test.bokeh))
        preds[spec.name] = p
        ranked: Dict[str, Any] = {}
        if spec.layer != "supervised":
            trained = trained_loss(log["config"], start)
            at_pred = scene_losses(spec, trained, test, p)
            at_truth = scene_losses(spec, trained, test, test.disparity)
            ranked = {"loss_at_prediction": float(at_pred.mean()), "loss_at_truth": float(at_truth.mean()),
                      "truth_lower_scenes": int((at_truth < at_pred).sum())}
        rows.append({
            "run": spec.name, "layer": spec.layer, "loss": log["loss"], **metrics(p, test), **ranked,
            "seconds_per_step": log["seconds_per_step"], "seconds_per_epoch": log["seconds_per_epoch"],
            "epochs": log["epochs"], "steps": log["config"]["steps"],
            # How the run was trained (its log), so that tables over seeds can check that
            # only the seed differs (``seeds.py``).
            "seed": start.seed, "train_config": log["config"],
        })
    # The untrained row is the start the runs trained from (their seed, width and initial
    # disparity, from their logs) when they share one, so that runs trained with --seed 18
    # are not compared with seed 17's start; the command line's otherwise.
    untrained_cfg = next(iter(starts.values())) if len(starts) == 1 else cfg
    untrained = predict(new_model(untrained_cfg), untrained_cfg.input_of(test.aif, test.bokeh))
    preds["untrained"] = untrained
    rows.append({"run": "untrained network", "layer": "-", "loss": "-", **metrics(untrained, test)})
    rows.append({"run": "constant (true median, oracle)", "layer": "-", "loss": "-", **metrics(constant_guess(test), test)})

    lines = [
        "# drbokeh.dfdnet: test table",
        "",
        note,
        "",
        f"Test: {len(test)} scenes ({test.aif.shape[-1]} px, focus at disparity "
        f"{', '.join(f'{f:g}' for f in sorted(set(test.focus.tolist())))}), "
        f"{int((test.blur >= 3).sum())} with largest blur >= 3 px; "
        f"{100 * textured_mask(test.aif).mean():.0f} % of the pixels textured (MAE tex), "
        f"{100 * (test.disparity < BACKGROUND_DISPARITY).mean():.0f} % background (MAE bg)."
        + (f" {left_out}." if left_out else ""),
        "",
        "| run | layer | loss | MAE | RMSE | delta<1.25 | MAE K>=3 | MAE tex | MAE bg | MAE fg | loss pred / truth | truth lower | s/step | s/epoch |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        ranked_cells = (f"{_fmt(r['loss_at_prediction'], 3)} / {_fmt(r['loss_at_truth'], 3)} | "
                        f"{r['truth_lower_scenes']} of {len(test)}") if "loss_at_truth" in r else "- | -"
        lines.append(
            f"| {r['run']} | {r['layer']} | {r['loss']} | {_fmt(r['mae'])} | {_fmt(r['rmse'])} | "
            f"{_fmt(r['delta125'], 3)} | {_fmt(r['mae_k3'])} | {_fmt(r['mae_tex'])} | {_fmt(r['mae_bg'])} | {_fmt(r['mae_fg'])} | {ranked_cells} | "
            f"{_fmt(r.get('seconds_per_step', float('nan')), 2)} | {_fmt(r.get('seconds_per_epoch', float('nan')), 1)} |"
        )
    (out_dir / "results.md").write_text("\n".join(lines) + "\n")
    results = {"rows": rows, "config": cfg.__dict__, "test_scenes": test.names, "note": note, "left_out": left_out}
    (out_dir / "results.json").write_text(json.dumps(results, indent=1))
    _plots(out_dir, logs)
    _html(out_dir, test, preds, rows, html_scenes)
    return results


def _plots(out_dir: Path, logs: Dict[str, Dict[str, Any]]) -> None:
    """The loss curves and validation MAE of the runs whose ``log.json`` is in ``logs``
    (by run name, in the table's order)."""
    plots = out_dir / "plots"
    plots.mkdir(exist_ok=True)
    val: Dict[str, List] = {}
    rel: Dict[str, List] = {}
    for name, log in logs.items():
        losses = [c["loss"] for c in log["curve"]]
        sm = smooth(losses, 25)
        steps = [c["step"] + 1 for c in log["curve"]]
        (plots / f"loss_{name}.svg").write_text(
            svg_lines({name: list(zip(steps, sm))}, f"training loss, {name} (running mean of 25)", "step", "loss", log_y=True)
        )
        rel[name] = [(s, v / sm[0]) for s, v in zip(steps, sm)]
        val[name] = [(c["step"], c["val_mae"]) for c in log["val_curve"]]
    if rel:
        (plots / "loss_relative.svg").write_text(
            svg_lines(rel, "training loss / its start (running mean of 25)", "step", "relative loss", log_y=True)
        )
        (plots / "val_mae.svg").write_text(svg_lines(val, "validation disparity MAE (monitoring only)", "step", "MAE"))


def _html(out_dir: Path, test: Split, preds: Dict[str, np.ndarray], rows: List[Dict[str, Any]], count: int) -> None:
    pics = out_dir / "html"
    pics.mkdir(exist_ok=True)
    order = np.argsort(test.blur)
    chosen = order[np.linspace(0, len(order) - 1, min(count, len(order))).round().astype(int)]
    chosen = list(dict.fromkeys(int(i) for i in chosen))
    mae = {str(r["run"]): r["mae"] for r in rows}
    cols = ["aif", "bokeh", "truth"] + list(preds)
    head = "".join(f"<th>{escape(c)}<br><small>{'' if c not in mae else 'MAE ' + _fmt(float(mae[c]))}</small></th>" for c in cols)
    body = []
    for i in chosen:
        name = test.names[i]
        cells = []
        for c in cols:
            if c == "aif":
                img, err = test.aif[i].transpose(1, 2, 0), None
            elif c == "bokeh":
                img, err = test.bokeh[i].transpose(1, 2, 0), None
            elif c == "truth":
                img, err = test.disparity[i, 0], None
            else:
                key = "untrained" if c == "untrained" else c
                img = preds[key][i, 0]
                err = float(np.abs(img - test.disparity[i, 0]).mean())
            fname = f"{name}_{c}.png"
            write_png(pics / fname, upscale(img, 2))
            cap = "" if err is None else f"<br><small>{err:.3f}</small>"
            cells.append(f'<td><img src="html/{fname}" width="{2 * img.shape[1]}">{cap}</td>')
        body.append(f"<tr><td>{escape(name)}<br><small>K {test.blur[i]:.1f} px</small></td>{''.join(cells)}</tr>")
    table = (out_dir / "results.md").read_text()
    seen = {"aif": "the all-in-focus image (aif) only", "aif+bokeh": "the all-in-focus and the defocused image (aif and bokeh)"}
    inputs = sorted({str(r["train_config"].get("inputs", "aif")) for r in rows if isinstance(r.get("train_config"), dict)})
    sees = "; ".join(seen.get(i, i) for i in inputs) or seen["aif"]
    page = (
        "<!doctype html><meta charset='utf-8'><title>drbokeh.dfdnet test images</title>"
        "<style>body{font-family:sans-serif} td,th{padding:2px;text-align:center;vertical-align:top}</style>"
        "<h1>Depth networks trained through rendering layers: test images</h1>"
        f"<p>The networks see {escape(sees)}; bokeh is the ray-traced target of the self-supervised loss. "
        "Disparity: white = near (1), black = far (0). Numbers under predictions: the scene's MAE.</p>"
        f"<table><tr><th>scene</th>{head}</tr>{''.join(body)}</table>"
        f"<h2>Table</h2><pre>{escape(table)}</pre>"
        "<h2>Curves</h2><img src='plots/loss_relative.svg'><img src='plots/val_mae.svg'>"
    )
    (out_dir / "index.html").write_text(page)
