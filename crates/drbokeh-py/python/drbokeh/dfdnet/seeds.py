"""One table over several run seeds: ``python -m drbokeh.dfdnet table DIR... -o OUT``.

Each ``DIR`` is an ``eval`` output (its ``results.json``) of the same protocol with another
``--seed``. A single seed cannot rank layers whose differences are as small as one layer's
spread over seeds (docs/dfdnet.md, sessions 12-17), so the table shows, per run, the MAE of
every seed, their mean and spread, how often the run had the lowest MAE among the runs
trained through a rendering layer, and the means of the other metrics. Below it, each
layer run is set against the one with the lowest mean scene by scene (:func:`paired`): the
seeds share their test scenes, and a scene's difficulty moves every run's MAE together, so
the per-scene difference resolves gaps smaller than the spread over seeds. The directories
must agree on everything but the seed (test scenes, data, training settings); otherwise
the table would mix protocols, and it is refused with the first difference named.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from .train import TrainConfig

# Rows of an eval table that are references, not trained through a layer.
REFERENCE_LAYERS = ("supervised", "-")
# Metrics averaged over the seeds (results.json row keys) and their column names.
MEAN_COLUMNS = (("rmse", "RMSE"), ("delta125", "delta<1.25"), ("mae_bg", "MAE bg"), ("mae_fg", "MAE fg"),
                ("loss_at_prediction", "loss pred"), ("loss_at_truth", "loss truth"), ("seconds_per_epoch", "s/epoch"))
# Columns of MEAN_COLUMNS shown with 3 / 1 decimals (the others with 4).
THREE_DIGITS = ("delta125", "loss_at_prediction", "loss_at_truth")


class SeedTableError(ValueError):
    """The directories cannot be put in one table (missing, damaged or of other protocols)."""


# Settings that may differ between the directories: the seed (the point of the table) and
# the thread count (how fast, not what is trained).
FREE_SETTINGS = ("seed", "threads")


def _read_json(path: Path, what: str) -> Dict[str, Any]:
    try:
        value = json.loads(path.read_text())
    except FileNotFoundError:
        raise SeedTableError(f"{path}: not found ({what})") from None
    except (OSError, ValueError) as e:
        raise SeedTableError(f"{path}: not readable as JSON ({type(e).__name__}: {e})") from None
    if not isinstance(value, dict):
        raise SeedTableError(f"{path}: expected a JSON object, found a {type(value).__name__} ({what})")
    return value


def _differs(a: Dict[str, Any], b: Dict[str, Any]) -> Optional[str]:
    """The first setting (outside :data:`FREE_SETTINGS`) whose value differs, with both
    values. A setting that one log lacks (written before the setting existed) counts as
    its default, which is what that run was trained with."""
    defaults = asdict(TrainConfig())
    for key in sorted(set(a) | set(b)):
        va, vb = a.get(key, defaults.get(key)), b.get(key, defaults.get(key))
        if key not in FREE_SETTINGS and va != vb:
            return f"{key} ({vb!r} against {va!r})"
    return None


def _row_ok(row: object, scenes: int) -> bool:
    """Whether a results.json row has what the table reads, with the types ``eval`` writes
    (each scene's MAE, one per test scene, is optional: older evals lack it)."""
    per_scene = row.get("mae_per_scene", []) if isinstance(row, dict) else None
    return (isinstance(row, dict) and all(isinstance(row.get(k), str) for k in ("run", "layer", "loss"))
            and isinstance(row.get("mae"), (int, float)) and isinstance(row.get("seed", 0), int)
            and isinstance(row.get("train_config", {}), dict)
            and isinstance(per_scene, list) and all(isinstance(v, (int, float)) for v in per_scene)
            and len(per_scene) in (0, scenes))


def load_results(dirs: Sequence[Path]) -> List[Dict[str, Any]]:
    """Each directory's ``results.json`` (and the training record ``config.json``, where
    ``train`` wrote one), checked to be of one protocol that differs only in the seed: the
    same test scenes, each run trained with the same settings (its log's, as ``eval``
    records them) but the seed, the same data where both directories record it; and
    distinct seeds."""
    if len(dirs) < 2:
        raise SeedTableError("table: give at least two eval directories (one per seed)")
    out = []
    for d in dirs:
        p = Path(d) / "results.json"
        r = _read_json(p, "eval results: run `python -m drbokeh.dfdnet eval` there first")
        rows, names = r.get("rows"), r.get("test_scenes", [])
        scenes = len(names) if isinstance(names, list) else -1
        if not isinstance(rows, list) or not all(_row_ok(x, scenes) for x in rows):
            raise SeedTableError(f"{p}: not an eval results file (rows need a run, layer, loss and MAE, "
                                 "and a per-scene MAE, where given, for each test scene)")
        found = {row["seed"] for row in rows if "seed" in row}
        if len(found) != 1:
            raise SeedTableError(f"{p}: " + (
                "its runs were trained with different seeds" if found else
                "no run records its seed (written before seeds were recorded: run eval there again)"))
        c = Path(d) / "config.json"
        r["training"] = _read_json(c, "training record written by train") if c.exists() else None
        r["dir"] = str(d)
        r["seed"] = found.pop()
        out.append(r)
    first = out[0]
    seeds = [r["seed"] for r in out]
    if len(set(seeds)) != len(seeds):
        raise SeedTableError(f"table: the directories repeat a seed ({seeds}); each must be another --seed")
    first_runs = {row["run"]: row for row in first["rows"] if "train_config" in row}
    for r in out[1:]:
        where = f"table: {r['dir']} differs from {first['dir']} in"
        if first.get("test_scenes") != r.get("test_scenes"):
            raise SeedTableError(f"{where} its test scenes")
        for row in r["rows"]:
            if row["run"] in first_runs and "train_config" in row:
                diff = _differs(first_runs[row["run"]]["train_config"], row["train_config"])
                if diff:
                    raise SeedTableError(f"{where} how {row['run']} was trained: {diff}")
        if first["training"] is not None and r["training"] is not None:
            for key in ("splits", "min_blur_px"):
                if first["training"].get(key) != r["training"].get(key):
                    raise SeedTableError(f"{where} its data ({key} in config.json)")
    return out


def combine(results: Sequence[Dict[str, Any]]) -> Dict[str, Any]:
    """Per run (in the first directory's order; runs missing from a seed are left out):
    MAE per seed, mean, min/max, wins among the layer runs, and the means of
    :data:`MEAN_COLUMNS`."""
    seeds = [int(r["seed"]) for r in results]
    by_seed = [{row["run"]: row for row in r["rows"]} for r in results]
    names = [row["run"] for row in results[0]["rows"] if all(row["run"] in s for s in by_seed)]
    layer_runs = [n for n in names if by_seed[0][n]["layer"] not in REFERENCE_LAYERS]
    winners = [min(layer_runs, key=lambda n: s[n]["mae"]) if layer_runs else None for s in by_seed]
    rows = []
    for n in names:
        maes = [float(s[n]["mae"]) for s in by_seed]
        row = {"run": n, "layer": by_seed[0][n]["layer"], "loss": by_seed[0][n]["loss"], "mae": maes,
               "mae_mean": float(np.mean(maes)), "mae_min": min(maes), "mae_max": max(maes),
               "wins": sum(w == n for w in winners) if n in layer_runs else None}
        for key, _ in MEAN_COLUMNS:
            vals = [s[n].get(key) for s in by_seed]
            row[key] = float(np.mean(vals)) if all(isinstance(v, (int, float)) for v in vals) else None
        # In how many (scene, seed) pairs the run's loss ranks the truth below its prediction
        # (evals since session 31 record it).
        lower = [s[n].get("truth_lower_scenes") for s in by_seed]
        row["truth_lower"] = int(sum(lower)) if all(isinstance(v, int) for v in lower) else None
        rows.append(row)
    partial = sorted({row["run"] for r in results for row in r["rows"]} - set(names))
    layered = [r for r in rows if r["wins"] is not None]
    best = min(layered, key=lambda r: r["mae_mean"])["run"] if layered else None
    return {"seeds": seeds, "dirs": [r["dir"] for r in results], "rows": rows, "left_out": partial,
            "test_scenes": len(results[0].get("test_scenes", [])),
            "best": best, "paired": paired(by_seed, layer_runs, best)}


def paired(by_seed: Sequence[Dict[str, Dict[str, Any]]], layer_runs: Sequence[str],
           best: Optional[str]) -> List[Dict[str, Any]]:
    """Each layer run against ``best`` (the lowest mean MAE), scene by scene: per test scene
    the run's MAE minus ``best``'s, averaged over the seeds; the mean over the scenes with a
    95 % interval (mean +- 1.96 standard errors, the scenes taken as independent) and the
    number of scenes where the run is lower. The seeds share their test scenes, so this
    removes the scenes' own difficulty, which dominates a seed's MAE. Runs whose evals lack
    per-scene MAEs (written before eval recorded them) are left out."""
    if best is None or not all(s[best].get("mae_per_scene") for s in by_seed):
        return []
    base = np.array([s[best]["mae_per_scene"] for s in by_seed], np.float64)
    out = []
    for n in layer_runs:
        if n == best or not all(s[n].get("mae_per_scene") for s in by_seed):
            continue
        diff = (np.array([s[n]["mae_per_scene"] for s in by_seed], np.float64) - base).mean(axis=0)
        half = 1.96 * float(diff.std(ddof=1)) / np.sqrt(len(diff)) if len(diff) > 1 else float("nan")
        mean = float(diff.mean())
        out.append({"run": n, "against": best, "mean": mean, "low": mean - half, "high": mean + half,
                    "scenes": int(len(diff)), "scenes_lower": int((diff < 0).sum())})
    return out


def _f(v: object, digits: int = 4) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def markdown(table: Dict[str, Any]) -> str:
    seeds: List[int] = table["seeds"]
    rows: List[Dict[str, Any]] = table["rows"]
    best = table["best"]
    head = ["run", "layer", "loss"] + [f"MAE seed {s}" for s in seeds] + ["MAE mean", "min-max", "lowest (of layers)"]
    head += [name + " (mean)" for _, name in MEAN_COLUMNS] + ["truth lower (all seeds)"]
    lines = ["# drbokeh.dfdnet: test table over seeds", "",
             f"Seeds {', '.join(map(str, seeds))} ({', '.join(table['dirs'])}); {table['test_scenes']} test scenes; "
             "every setting but the seed is the same in each directory. \"lowest\": at how many seeds the run had the "
             "lowest MAE among the runs trained through a rendering layer (the supervised and reference rows are not "
             "counted). The mean with the lowest value among the layer runs is in bold. \"loss pred\" / \"loss truth\": "
             "the run's training loss at its prediction and at the true disparity (means over the scenes and seeds); "
             "\"truth lower\": in how many (scene, seed) pairs that loss ranks the truth below the prediction.", "",
             "| " + " | ".join(head) + " |",
             "| --- | --- | --- | " + " | ".join("---:" for _ in head[3:]) + " |"]
    left_out: List[str] = table.get("left_out", [])
    if left_out:
        lines[4:4] = [f"Left out (not evaluated in every directory): {', '.join(left_out)}.", ""]
    for r in rows:
        mean = _f(r["mae_mean"])
        cells = [str(r["run"]), str(r["layer"]), str(r["loss"])] + [_f(v) for v in r["mae"]]
        cells += [f"**{mean}**" if r["run"] == best else mean, f"{_f(r['mae_min'])}-{_f(r['mae_max'])}",
                  "-" if r["wins"] is None else f"{r['wins']} of {len(seeds)}"]
        cells += [_f(r[key], 3 if key in THREE_DIGITS else (1 if key == "seconds_per_epoch" else 4)) for key, _ in MEAN_COLUMNS]
        cells.append("-" if r.get("truth_lower") is None
                     else f"{r['truth_lower']} of {table['test_scenes'] * len(seeds)}")
        lines.append("| " + " | ".join(cells) + " |")
    pairs: List[Dict[str, Any]] = table.get("paired", [])
    if pairs:
        lines += ["", f"Scene by scene against the lowest mean ({best}): each scene's MAE minus {best}'s, averaged "
                  f"over the seeds, then the mean over the {pairs[0]['scenes']} test scenes with a 95 % interval "
                  "(mean +- 1.96 standard errors); a negative difference is a lower error than "
                  f"{best}'s. An interval that holds 0 does not separate the two.", "",
                  "| run | minus | mean difference | 95 % interval | scenes where lower |",
                  "| --- | --- | ---: | --- | ---: |"]
        for p in pairs:
            lines.append(f"| {p['run']} | {p['against']} | {p['mean']:+.4f} | [{p['low']:+.4f}, {p['high']:+.4f}] | "
                         f"{p['scenes_lower']} of {p['scenes']} |")
    return "\n".join(lines) + "\n"


def write_table(dirs: Sequence[Path], out_dir: Path) -> Dict[str, Any]:
    """Writes ``out_dir/results.md`` and ``results.json`` (see the module docs); returns the table."""
    table = combine(load_results(dirs))
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "results.md").write_text(markdown(table))
    (out_dir / "results.json").write_text(json.dumps(table, indent=1))
    return table
