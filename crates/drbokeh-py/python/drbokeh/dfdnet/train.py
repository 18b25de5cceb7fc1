"""Training: one U-Net per run, through one rendering layer and one loss (or supervised on
the true disparity, the upper bound). Everything but the layer and the loss is identical
across runs: the same initial weights, the same batches, crops and flips (seeded), the same
optimiser and schedule."""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import torch

from .data import Split, random_crops
from .highlights import energy_source, reach_mask
from .layers import LAYERS, make_layer
from .losses import LOSSES, defocus_loss
from .unet import UNet, parameter_count


HIGHLIGHTS = ("none", "reach", "energy", "energy+reach")

# What the network sees: the all-in-focus image (the set-up: depth from one image,
# the defocused image only in the loss), or the traced defocused image beside it (depth
# from the pair: what the pair says about depth depends on the layer's model of the blur).
INPUTS = ("aif", "aif+bokeh")


# A fine-tune's name: ``LAYER-LOSS-from-START`` (``physical5-hssim-from-aperture-hssim``).
FROM = "-from-"

# A fine-tune draws its batches from ``seed + FINETUNE_SEED_OFFSET``, so that it does not see
# its start's first batches again in the same order.
FINETUNE_SEED_OFFSET = 1000


@dataclass(frozen=True)
class RunSpec:
    """``layer`` is a rendering layer (``layers.LAYERS``) or ``supervised``; ``loss`` one of
    ``losses.LOSSES`` (ignored when supervised: L1 on the true disparity); ``highlights``
    overrides ``TrainConfig.highlights`` for this run (the highlight ablation). ``start``:
    the run whose trained weights this one starts from (a fine-tune of
    ``TrainConfig.finetune_steps`` at ``finetune_lr``; session 35, docs/dfdnet.md), trained
    first in the same output directory; ``None``: a fresh network."""

    layer: str
    loss: str = "hssim"
    highlights: Optional[str] = None
    start: Optional["RunSpec"] = None

    @property
    def name(self) -> str:
        if self.layer == "supervised":
            return "supervised"
        own = f"{self.layer}-{self.loss}" + (f"-{self.highlights}" if self.highlights else "")
        return own if self.start is None else own + FROM + self.start.name

    def config(self, cfg: "TrainConfig") -> "TrainConfig":
        """``cfg`` as this run trains: its highlight mode, and a fine-tune's steps and rate."""
        if self.highlights is not None:
            cfg = replace(cfg, highlights=self.highlights)
        if self.start is not None:
            cfg = replace(cfg, steps=cfg.finetune_steps, lr=cfg.finetune_lr)
        return cfg


# The table: the four layers with L1+G+HSSIM, `physical` through the prediction's layer
# stack (`physical3`, session 5), the loss ablation through `physical` (the
# structure terms), and the supervised upper bound. (The highlight ablation of session 3,
# `physical-hssim-none`, and the L1+G baselines `gausspsf-l1g`, `aperture-l1g` are still
# available through --runs.)
TABLE_RUNS: List[RunSpec] = [
    RunSpec("physical", "hssim"),
    RunSpec("gausspsf", "hssim"),
    RunSpec("aperture", "hssim"),
    RunSpec("paper", "hssim"),
    RunSpec("physical3", "hssim"),
    RunSpec("physical", "ssim"),
    RunSpec("physical", "l1g"),
    RunSpec("supervised"),
]


# Seconds per training step relative to ``physical5`` (one thread, two trainings at once on
# 2 cores). Measured in session 29 (docs/dfdnet.md; seed 23: paper5 1.61 s, physical5 1.51,
# GaussPSF 1.30, aperture 0.84, supervised 0.24; GaussPSF's follows the largest predicted
# blur and ran 0.3-0.9x physical5's over seeds 17-23); the one-layer and three-layer stacks
# are placed between by their work, not measured lately. Only the order in which runs
# start depends on it (:func:`longest_first`), never what a run computes.
RELATIVE_STEP_COST = {
    "paper5": 1.05, "physical5": 1.0, "aperturepy": 1.0, "physical3": 0.9, "paper3": 0.9, "physical3m": 0.9,
    "paper3m": 0.9, "physical": 0.8, "paper": 0.8, "gausspsf": 0.7, "aperture": 0.6, "supervised": 0.16,
}


def longest_first(runs: List[RunSpec]) -> List[RunSpec]:
    """``runs`` ordered by :data:`RELATIVE_STEP_COST`, the costliest first (ties keep their
    order): with two processes pulling from one queue, a short run last fills the other
    core's tail, where a long run last trains alone (session 29: GaussPSF last, one core
    idle for about 18 minutes)."""
    return sorted(runs, key=lambda r: -RELATIVE_STEP_COST.get(r.layer, 1.0))


def parse_run(name: str) -> RunSpec:
    """The run named ``name``: ``LAYER-LOSS``, ``LAYER-LOSS-HIGHLIGHTS``, ``supervised``, or a
    fine-tune ``RUN-from-START`` (both layer runs; a start is itself trained from scratch, and
    never the supervised network, whose weights have seen the true depth)."""
    if FROM in name:
        own, start = name.split(FROM, 1)
        if own == "supervised" or start == "supervised":
            raise ValueError(f"run {name!r}: a fine-tune is trained through a layer, and starts from a run trained "
                             "through one (the supervised network has seen the true depth)")
        if FROM in start:
            raise ValueError(f"run {name!r}: a fine-tune starts from a run trained from scratch, not from another fine-tune")
        return replace(parse_run(own), start=parse_run(start))
    if name == "supervised":
        return RunSpec("supervised")
    parts = name.split("-")
    layer, loss = parts[0], parts[1] if len(parts) > 1 else ""
    hl = parts[2] if len(parts) == 3 else None
    if len(parts) not in (2, 3) or layer not in LAYERS or loss not in LOSSES or (hl is not None and hl not in HIGHLIGHTS):
        raise ValueError(
            f"unknown run {name!r}: expected LAYER-LOSS or LAYER-LOSS-HIGHLIGHTS (layers {', '.join(LAYERS)}; "
            f"losses {', '.join(LOSSES)}; highlights {', '.join(HIGHLIGHTS)}) or supervised"
        )
    return RunSpec(layer, loss, hl)


@dataclass(frozen=True)
class TrainConfig:
    # The table's protocol since session 12 (docs/dfdnet.md, session 11): whole 128 px
    # images in batches of 2, 1500 steps, the disparity output starting at the far
    # background's value. Every layer gains from each of these, and none changes the order.
    steps: int = 1500
    batch: int = 2
    crop: int = 128
    lr: float = 4e-3
    base: int = 12
    seed: int = 17
    eval_every: int = 25
    threads: int = 1
    w_l1: float = 0.5
    w_smooth: float = 0.5
    w_structure: float = 10.0
    edge_sensitivity: float = 10.0
    # Clipped highlights (highlights.py): "none" (the clipped photo as is, L1 leaves out
    # pixels clipped in the traced image), "reach" (every image term leaves out the pixels a
    # clipped all-in-focus pixel can reach), "energy" (the layer renders the photo with the
    # highlights' missing light restored, the render clipped at white as the camera's),
    # "energy+reach" (both).
    highlights: str = "energy"
    # Initial value of the disparity output (the head's bias; None: PyTorch's default
    # initialisation, about 0.5).
    init_disparity: Optional[float] = 0.05
    # Weight of the focus prior: mean |disparity - focus| of the prediction (0: off).
    w_focus: float = 0.0
    # The prior's warm-up: its weight falls linearly from ``w_focus_start`` at the first
    # step to ``w_focus`` at step ``focus_warmup_steps`` (0: no warm-up). At a flat start
    # the drbokeh layers' loss gives the background little push down or asks to raise
    # it, where GaussPSF's lowers it; a stronger prior early holds the background down
    # while the objects rise. Tried in session 23 and not kept: a weight that holds
    # `physical5`'s background traps GaussPSF at the focus (docs/dfdnet.md).
    w_focus_start: float = 0.0
    focus_warmup_steps: int = 0
    # The prior only inside the depth of field (None: everywhere): a pixel's term is
    # min(|disparity - focus|, R / K), so it pulls a pixel towards the focus only while the
    # predicted blur radius K |disparity - focus| is below R px, where a lens shows (almost)
    # no blur and the rendering gives no gradient, and leaves blurred objects alone
    # (session 24, docs/dfdnet.md).
    focus_prior_radius_px: Optional[float] = None
    # What the network sees (INPUTS).
    inputs: str = "aif"
    # Whether training crops are also flipped upside down. Off for scenes laid out on a
    # ground (``--perspective``), whose height in the frame is a depth cue that a flip
    # would invert (session 26, docs/dfdnet.md).
    vertical_flips: bool = True
    # A fine-tune (``RunSpec.start``): its steps, and its learning rate (cosine to 5 % of it, as
    # a run from scratch). Session 35 (docs/dfdnet.md): 500 at 0.001 from the aperture network.
    finetune_steps: int = 500
    finetune_lr: float = 1e-3

    def __post_init__(self) -> None:
        if self.inputs not in INPUTS:
            raise ValueError(f"unknown network input {self.inputs!r} (available: {', '.join(INPUTS)})")
        if self.focus_warmup_steps < 0 or not math.isfinite(self.w_focus_start) or self.w_focus_start < 0.0:
            raise ValueError(
                f"focus prior warm-up {self.w_focus_start}:{self.focus_warmup_steps}: "
                "expected a weight >= 0 and a step count >= 0"
            )
        r = self.focus_prior_radius_px
        if r is not None and (not math.isfinite(r) or r <= 0.0):
            raise ValueError(f"focus prior radius {r}: expected a blur radius in pixels > 0")

    def focus_weight(self, step: int) -> float:
        """The focus prior's weight at training step ``step`` (0-based): ``w_focus`` after
        the warm-up, and during it the straight line from ``w_focus_start``."""
        if step >= self.focus_warmup_steps:
            return self.w_focus
        t = step / self.focus_warmup_steps
        return self.w_focus_start + (self.w_focus - self.w_focus_start) * t

    @property
    def in_channels(self) -> int:
        return 3 if self.inputs == "aif" else 6

    def input_of(self, aif: np.ndarray, bokeh: np.ndarray) -> np.ndarray:
        """The network's input ``(N, C, H, W)``: ``aif``, or with ``aif+bokeh`` ``aif`` and
        ``bokeh`` stacked along the channels (``inputs`` is checked on construction)."""
        return aif if self.inputs == "aif" else np.concatenate([aif, bokeh], 1)


def new_model(cfg: TrainConfig) -> UNet:
    torch.manual_seed(cfg.seed)
    model = UNet(cfg.base, cfg.in_channels)
    if cfg.init_disparity is not None:
        p = min(max(cfg.init_disparity, 1e-3), 1 - 1e-3)
        bias = model.head.bias
        assert bias is not None  # the head is a Conv2d with a bias (unet.py)
        with torch.no_grad():
            bias.fill_(math.log(p / (1 - p)))
    return model


def highlight_arrays(split: Split, mode: str) -> Dict[str, np.ndarray]:
    """The per-scene arrays a highlight mode needs: ``reach`` ``(N, 1, H, W)`` (1 = in the
    loss) and/or ``source`` ``(N, 3, H, W)`` (the layer's input image)."""
    if mode not in HIGHLIGHTS:
        raise ValueError(f"unknown highlight mode {mode!r} (available: {', '.join(HIGHLIGHTS)})")
    out: Dict[str, np.ndarray] = {}
    if "reach" in mode:
        out["reach"] = reach_mask(split.aif, split.blur)
    if "energy" in mode:
        out["source"] = energy_source(split.aif, split.bokeh, split.blur)
    return out


@torch.no_grad()
def predict(model: UNet, x: np.ndarray, batch: int = 8) -> np.ndarray:
    """The disparity the network predicts for its inputs ``x`` (``TrainConfig.input_of``)."""
    model.eval()
    outs = [model(torch.from_numpy(x[i : i + batch])).numpy() for i in range(0, len(x), batch)]
    model.train()
    return np.concatenate(outs)


def margin_px(blur: np.ndarray, crop: int) -> int:
    """Pixels left out of the image loss at every crop border: light from outside the crop
    reaches them in the traced image but not in the render (at most a quarter crop)."""
    return int(min(math.ceil(float(blur.max())) + 1, crop // 4))


def image_loss(
    layer: Callable[..., torch.Tensor], loss_name: str, cfg: TrainConfig, b: Dict[str, np.ndarray], pred: torch.Tensor,
    w_focus: Optional[float] = None,
) -> Tuple[torch.Tensor, Dict[str, float]]:
    """The self-supervised loss of one batch ``b`` (from :func:`random_crops`, with the
    highlight mode's arrays): render ``pred`` through ``layer``, compare with the traced
    image inside the crop's margin. Pixels clipped in the traced image are always left out
    of L1 (as ``drbokeh dfd`` does); see ``TrainConfig.highlights`` for the rest.
    ``w_focus``: the focus prior's weight (default ``cfg.w_focus``; training passes
    ``cfg.focus_weight(step)``)."""
    aif = torch.from_numpy(b["aif"])
    source = torch.from_numpy(b["source"]) if "source" in b else aif
    target = torch.from_numpy(b["bokeh"])
    rendered = layer(source, pred, torch.from_numpy(b["focus"]), torch.from_numpy(b["blur"]))
    if "source" in b:
        rendered = rendered.clamp(max=1.0)  # the camera clips as the traced PNG is clipped
    crop = aif.shape[-1]
    m = margin_px(b["blur"], crop)
    inner = (slice(None), slice(None), slice(m, crop - m), slice(m, crop - m))
    r_in, t_in = rendered[inner], target[inner]
    unclipped = (t_in.amax(1, keepdim=True) < 0.999).to(t_in.dtype)
    structure_mask = None
    if "reach" in b:
        structure_mask = torch.from_numpy(b["reach"])[inner]
        unclipped = unclipped * structure_mask
    total, terms = defocus_loss(
        r_in, t_in, pred, aif, loss_name, w_l1=cfg.w_l1, w_smooth=cfg.w_smooth,
        w_structure=cfg.w_structure, edge_sensitivity=cfg.edge_sensitivity, mask=unclipped,
        structure_mask=structure_mask,
    )
    w_focus = cfg.w_focus if w_focus is None else w_focus
    if w_focus > 0.0:
        focus = torch.from_numpy(b["focus"]).to(pred.dtype).view(-1, 1, 1, 1)
        off_focus = (pred - focus).abs()
        if cfg.focus_prior_radius_px is not None:
            # |d - f| capped at R / K: no pull once the blur radius K |d - f| reaches R px.
            k = torch.from_numpy(b["blur"]).to(pred.dtype).view(-1, 1, 1, 1)
            off_focus = torch.minimum(off_focus, cfg.focus_prior_radius_px / k)
        t_f = off_focus.mean()
        total = total + w_focus * t_f
        terms["focus"] = float(t_f.detach())
        terms["focus_weight"] = w_focus
    return total, terms


def time_left(seconds_per_step: float, steps_left: int) -> str:
    """``", about 12 min left"`` at ``seconds_per_step`` (the recent steps' mean) for the
    ``steps_left``; empty when none are left. Whole minutes from one, seconds below."""
    if steps_left <= 0:
        return ""
    left = seconds_per_step * steps_left
    return f", about {left / 60:.0f} min left" if left >= 60 else f", about {left:.0f} s left"


def train_run(
    spec: RunSpec,
    splits: Dict[str, Split],
    cfg: TrainConfig,
    out_dir: Path,
    log: Callable[[str], None] = print,
) -> Dict[str, Any]:
    """Trains one run; writes ``out_dir/<name>/model.pt`` and ``log.json`` (loss curve,
    validation MAE curve, seconds per step and per epoch). The validation MAE is logged for
    the plots only; the last weights are the result (no selection on labels)."""
    cfg = spec.config(cfg)
    torch.set_num_threads(cfg.threads)
    train, val = splits["train"], splits["val"]
    run_dir = out_dir / spec.name
    run_dir.mkdir(parents=True, exist_ok=True)
    model = new_model(cfg) if spec.start is None else start_model(out_dir, spec.start, cfg)
    start_digest = None if spec.start is None else weights_digest(out_dir / spec.start.name)
    layer = None if spec.layer == "supervised" else make_layer(spec.layer, cfg.threads)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps, eta_min=cfg.lr * 0.05)
    rng = np.random.default_rng(cfg.seed + (0 if spec.start is None else FINETUNE_SEED_OFFSET))
    extra = highlight_arrays(train, cfg.highlights) if layer is not None else {}
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
        b = random_crops(train, idx, cfg.crop, rng, extra, cfg.vertical_flips)
        t0 = time.perf_counter()
        pred = model(torch.from_numpy(cfg.input_of(b["aif"], b["bokeh"])))
        if layer is None:
            loss = (pred - torch.from_numpy(b["disparity"])).abs().mean()
            terms = {"disparity_l1": float(loss.detach())}
        else:
            loss, terms = image_loss(layer, spec.loss, cfg, b, pred, cfg.focus_weight(step))
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        step_seconds.append(time.perf_counter() - t0)
        curve.append({"step": step, "loss": float(loss.detach()), **terms})
        if (step + 1) % cfg.eval_every == 0 or step + 1 == cfg.steps:
            mae = float(np.abs(predict(model, cfg.input_of(val.aif, val.bokeh)) - val.disparity).mean())
            val_curve.append({"step": step + 1, "val_mae": mae})
            recent = float(np.mean(step_seconds[-cfg.eval_every:]))
            log(f"{spec.name}: step {step + 1}/{cfg.steps} loss {float(loss.detach()):.4f} val MAE {mae:.4f} "
                f"({recent:.2f} s/step{time_left(recent, cfg.steps - step - 1)})")
    steps_per_epoch = n / cfg.batch
    result: Dict[str, Any] = {
        "run": spec.name,
        "layer": spec.layer,
        "loss": spec.loss if spec.layer != "supervised" else "disparity L1",
        "start": None if spec.start is None else spec.start.name,
        # The start's weights (:func:`weights_digest`), so that a later --retrain of the start
        # shows this run to be stale (:func:`stale_start`).
        "start_digest": start_digest,
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


@torch.no_grad()
def scene_losses(spec: RunSpec, cfg: TrainConfig, split: Split, disparity: np.ndarray) -> np.ndarray:
    """The run's training loss (:func:`image_loss`: its layer, loss terms and focus prior)
    of each scene of ``split`` with the disparity ``disparity`` ``(N, 1, H, W)``, on the
    whole images: e.g. at a network's prediction and at the true disparity, to see which of
    the two the loss ranks lower."""
    cfg = spec.config(cfg)
    layer = make_layer(spec.layer, cfg.threads)
    extra = highlight_arrays(split, cfg.highlights)
    out = np.zeros(len(split))
    for i in range(len(split)):
        b = {"aif": split.aif[i : i + 1], "bokeh": split.bokeh[i : i + 1], "focus": split.focus[i : i + 1],
             "blur": split.blur[i : i + 1], **{k: v[i : i + 1] for k, v in extra.items()}}
        d = torch.from_numpy(np.ascontiguousarray(disparity[i : i + 1], dtype=np.float32))
        out[i] = float(image_loss(layer, spec.loss, cfg, b, d)[0])
    return out


@torch.no_grad()
def split_loss(model: UNet, split: Split, spec: RunSpec, cfg: TrainConfig) -> float:
    """The run's image loss on a split's whole images, scene by scene, averaged."""
    if len(split) == 0:
        return 0.0
    # One scene at a time, as before scene_losses existed (the same float rounding).
    c = spec.config(cfg)
    pred = np.concatenate([predict(model, c.input_of(split.aif[i : i + 1], split.bokeh[i : i + 1]))
                           for i in range(len(split))])
    return float(scene_losses(spec, cfg, split, pred).mean())


def log_line(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def train_logged(spec: RunSpec, splits: Dict[str, Split], cfg: TrainConfig, out_dir: Path) -> None:
    """:func:`train_run` with progress on stdout (a process pool's worker)."""
    t0 = time.perf_counter()
    r = train_run(spec, splits, cfg, out_dir, log_line)
    log_line(f"{spec.name}: done in {time.perf_counter() - t0:.0f} s ({r['seconds_per_epoch']:.1f} s/epoch)")


def load_model(run_dir: Path, cfg: TrainConfig) -> UNet:
    model = UNet(cfg.base, cfg.in_channels)
    model.load_state_dict(torch.load(run_dir / "model.pt", weights_only=True))
    return model


def started_from(log_config: Dict[str, Any], cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with the seed, U-Net width, initial disparity and network input a run's log
    records (what its network was before training); ``cfg``'s values where an older log
    lacks one (logs from before the input option: the all-in-focus image)."""
    init = log_config.get("init_disparity", cfg.init_disparity)
    return replace(cfg, seed=int(log_config.get("seed", cfg.seed)),
                   base=int(log_config.get("base", cfg.base)),
                   init_disparity=None if init is None else float(init),
                   inputs=str(log_config.get("inputs", "aif")))


def start_problem(out_dir: Path, start: RunSpec, cfg: TrainConfig) -> Optional[str]:
    """Why run ``start`` in ``out_dir`` cannot start a fine-tune with ``cfg`` (not trained
    there, or its network has another width or input), in one line; ``None`` if it can."""
    log = existing(out_dir, start)
    if log is None:
        return (f"{start.name} is not trained in {out_dir}: a fine-tune starts from its weights "
                f"(train it first, e.g. --runs {start.name},...)")
    was = started_from(log["config"], cfg)
    theirs, mine = {"base": was.base, "inputs": was.inputs}, {"base": cfg.base, "inputs": cfg.inputs}
    if theirs != mine:
        return f"{out_dir / start.name} was trained with {theirs}, this fine-tune with {mine}"
    return None


def start_model(out_dir: Path, start: RunSpec, cfg: TrainConfig) -> UNet:
    """The trained network of run ``start`` in ``out_dir``, for a fine-tune with ``cfg``;
    an error (``ValueError``, :func:`start_problem`'s line) if it cannot be one."""
    problem = start_problem(out_dir, start, cfg)
    if problem is not None:
        raise ValueError(problem)
    return load_model(out_dir / start.name, cfg)


def weights_digest(run_dir: Path) -> str:
    """A SHA-256 of a trained network's weights (``run_dir/model.pt``): each tensor's name,
    shape, type and values in the state dict's order, so that it names the weights and not
    the file's packing."""
    h = hashlib.sha256()
    for name, t in torch.load(run_dir / "model.pt", weights_only=True).items():
        a = t.detach().cpu().contiguous().numpy()
        h.update(f"{name}:{a.dtype}:{a.shape};".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def stale_start(out_dir: Path, spec: RunSpec) -> Optional[str]:
    """For a fine-tune trained in ``out_dir``: why its network no longer follows from its
    start there (the start was trained again since), in one line; ``None`` if
    it does, if ``spec`` is not a trained fine-tune, if its start is not in ``out_dir``, or
    if its log predates the start's digest (``start_digest``)."""
    if spec.start is None:
        return None
    log = existing(out_dir, spec)
    if log is None or log.get("start_digest") is None:
        return None
    if existing(out_dir, spec.start) is None:  # e.g. an eval directory that links the fine-tune alone
        return None
    if weights_digest(out_dir / spec.start.name) != log["start_digest"]:
        return (f"{spec.name} in {out_dir} was fine-tuned from an earlier {spec.start.name} (trained again since): "
                f"train it again (--runs {spec.name} --retrain)")
    return None


def existing(out_dir: Path, spec: RunSpec) -> Optional[Dict[str, Any]]:
    p = out_dir / spec.name / "log.json"
    return json.loads(p.read_text()) if p.exists() and (out_dir / spec.name / "model.pt").exists() else None
