"""Training: one U-Net per run, through one rendering layer and one loss (or supervised on
the true disparity, the upper bound). Everything but the layer and the loss is identical
across runs: the same initial weights, the same batches, crops and flips (seeded), the same
optimiser and schedule."""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional

import numpy as np
import torch

from .data import Split, random_crops
from .layers import LAYERS, make_layer
from .losses import LOSSES, defocus_loss
from .unet import UNet, parameter_count


@dataclass(frozen=True)
class RunSpec:
    """``layer`` is a rendering layer (``layers.LAYERS``) or ``supervised``; ``loss`` one of
    ``losses.LOSSES`` (ignored when supervised: L1 on the true disparity)."""

    layer: str
    loss: str = "hssim"

    @property
    def name(self) -> str:
        return "supervised" if self.layer == "supervised" else f"{self.layer}-{self.loss}"


# The table: the four layers with L1+G+HSSIM, the loss ablation through `physical`, and the
# supervised upper bound (slowest first, for the process pool).
TABLE_RUNS: List[RunSpec] = [
    RunSpec("physical", "hssim"),
    RunSpec("physical", "ssim"),
    RunSpec("physical", "l1g"),
    RunSpec("gausspsf", "hssim"),
    RunSpec("aperture", "hssim"),
    RunSpec("paper", "hssim"),
    RunSpec("supervised"),
]


def parse_run(name: str) -> RunSpec:
    if name == "supervised":
        return RunSpec("supervised")
    layer, _, loss = name.partition("-")
    if layer not in LAYERS or loss not in LOSSES:
        raise ValueError(
            f"unknown run {name!r}: expected LAYER-LOSS (layers {', '.join(LAYERS)}; "
            f"losses {', '.join(LOSSES)}) or supervised"
        )
    return RunSpec(layer, loss)


@dataclass(frozen=True)
class TrainConfig:
    steps: int = 250
    batch: int = 4
    crop: int = 64
    lr: float = 2e-3
    base: int = 12
    seed: int = 17
    eval_every: int = 25
    threads: int = 1
    w_l1: float = 0.5
    w_smooth: float = 0.5
    w_structure: float = 10.0
    edge_sensitivity: float = 10.0


def new_model(cfg: TrainConfig) -> UNet:
    torch.manual_seed(cfg.seed)
    return UNet(cfg.base)


@torch.no_grad()
def predict(model: UNet, aif: np.ndarray, batch: int = 8) -> np.ndarray:
    model.eval()
    outs = [model(torch.from_numpy(aif[i : i + batch])).numpy() for i in range(0, len(aif), batch)]
    model.train()
    return np.concatenate(outs)


def margin_px(blur: np.ndarray, crop: int) -> int:
    """Pixels left out of the image loss at every crop border: light from outside the crop
    reaches them in the traced image but not in the render (at most a quarter crop)."""
    return int(min(math.ceil(float(blur.max())) + 1, crop // 4))


def train_run(
    spec: RunSpec,
    splits: Dict[str, Split],
    cfg: TrainConfig,
    out_dir: Path,
    log: Callable[[str], None] = print,
) -> Dict[str, object]:
    """Trains one run; writes ``out_dir/<name>/model.pt`` and ``log.json`` (loss curve,
    validation MAE curve, seconds per step and per epoch). The validation MAE is logged for
    the plots only; the last weights are the result (no selection on labels)."""
    torch.set_num_threads(cfg.threads)
    train, val = splits["train"], splits["val"]
    run_dir = out_dir / spec.name
    run_dir.mkdir(parents=True, exist_ok=True)
    model = new_model(cfg)
    layer = None if spec.layer == "supervised" else make_layer(spec.layer, cfg.threads)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps, eta_min=cfg.lr * 0.05)
    rng = np.random.default_rng(cfg.seed)
    curve: List[Dict[str, float]] = []
    val_curve: List[Dict[str, float]] = []
    step_seconds: List[float] = []
    n = len(train)
    order = rng.permutation(n)
    pos = 0
    for step in range(cfg.steps):
        if pos + cfg.batch > n:
            order, pos = rng.permutation(n), 0
        idx = order[pos : pos + cfg.batch]
        pos += cfg.batch
        b = random_crops(train, idx, cfg.crop, rng)
        t0 = time.perf_counter()
        aif = torch.from_numpy(b["aif"])
        pred = model(aif)
        if layer is None:
            loss = (pred - torch.from_numpy(b["disparity"])).abs().mean()
            terms = {"disparity_l1": float(loss.detach())}
        else:
            target = torch.from_numpy(b["bokeh"])
            rendered = layer(aif, pred, torch.from_numpy(b["focus"]), torch.from_numpy(b["blur"]))
            m = margin_px(b["blur"], cfg.crop)
            inner = (slice(None), slice(None), slice(m, cfg.crop - m), slice(m, cfg.crop - m))
            r_in, t_in = rendered[inner], target[inner]
            # Pixels clipped in the traced image are left out of L1 (as drbokeh dfd does).
            unclipped = (t_in.amax(1, keepdim=True) < 0.999).to(t_in.dtype)
            loss, terms = defocus_loss(
                r_in, t_in, pred, aif, spec.loss, w_l1=cfg.w_l1, w_smooth=cfg.w_smooth,
                w_structure=cfg.w_structure, edge_sensitivity=cfg.edge_sensitivity, mask=unclipped,
            )
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        step_seconds.append(time.perf_counter() - t0)
        curve.append({"step": step, "loss": float(loss.detach()), **terms})
        if (step + 1) % cfg.eval_every == 0 or step + 1 == cfg.steps:
            mae = float(np.abs(predict(model, val.aif) - val.disparity).mean())
            val_curve.append({"step": step + 1, "val_mae": mae})
            log(f"{spec.name}: step {step + 1}/{cfg.steps} loss {float(loss.detach()):.4f} val MAE {mae:.4f} "
                f"({np.mean(step_seconds[-cfg.eval_every:]):.2f} s/step)")
    steps_per_epoch = n / cfg.batch
    result: Dict[str, object] = {
        "run": spec.name,
        "layer": spec.layer,
        "loss": spec.loss if spec.layer != "supervised" else "disparity L1",
        "config": asdict(cfg),
        "parameters": parameter_count(model),
        "train_scenes": n,
        "seconds_per_step": float(np.mean(step_seconds)),
        "seconds_per_epoch": float(np.mean(step_seconds) * steps_per_epoch),
        "epochs": cfg.steps / steps_per_epoch,
        "curve": curve,
        "val_curve": val_curve,
    }
    torch.save(model.state_dict(), run_dir / "model.pt")
    (run_dir / "log.json").write_text(json.dumps(result))
    return result


def log_line(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def train_logged(spec: RunSpec, splits: Dict[str, Split], cfg: TrainConfig, out_dir: Path) -> None:
    """:func:`train_run` with progress on stdout (a process pool's worker)."""
    t0 = time.perf_counter()
    r = train_run(spec, splits, cfg, out_dir, log_line)
    log_line(f"{spec.name}: done in {time.perf_counter() - t0:.0f} s ({r['seconds_per_epoch']:.1f} s/epoch)")


def load_model(run_dir: Path, cfg: TrainConfig) -> UNet:
    model = UNet(cfg.base)
    model.load_state_dict(torch.load(run_dir / "model.pt", weights_only=True))
    return model


def existing(out_dir: Path, spec: RunSpec) -> Optional[Dict[str, object]]:
    p = out_dir / spec.name / "log.json"
    return json.loads(p.read_text()) if p.exists() and (out_dir / spec.name / "model.pt").exists() else None
