"""Training loop, ONNX export and model card, shared by the ``set``, ``perm`` and ``cnn`` models."""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from mocap_autolabel.core.atomic import atomic_output
from mocap_autolabel.core.labelers.assign import assign
from mocap_autolabel.core.layout import Layout
from mocap_autolabel.core.metrics import score_labeling
from mocap_autolabel.core.synth.frames import FrameConfig, LabeledFrames, sample_frames

from .inputs import Method, get_method


@dataclass
class Recipe:
    """Everything that determines a trained model (with the layout and the code)."""

    method: str = "set"
    steps: int = 6000
    batch: int = 256
    lr: float = 2e-3
    weight_decay: float = 1e-4
    seed: int = 0
    chunk: int = 8192  # frames generated at once (amortises building hands)
    frames: dict = field(default_factory=lambda: asdict(FrameConfig()))
    model: dict = field(default_factory=dict)
    validation_frames: int = 4096
    compile: bool = True  # torch.compile the training steps of long runs (a quarter faster on CPU)


def _progress(done: int, total: int, started: float, loss: float, stream=None) -> None:
    stream = stream or sys.stderr  # looked up per call: a default bound at import misses a redirected stderr
    elapsed = time.perf_counter() - started
    eta = elapsed / max(done, 1) * (total - done)
    width = 30
    filled = int(width * done / total)
    stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} steps  loss {loss:.3f}  "
                 f"{elapsed / 60:4.1f} min  ETA {eta / 60:4.1f} min ")
    if done == total:
        stream.write("\n")
    stream.flush()


#: Null offsets (nats) tried by :func:`calibrate_null`.
NULL_OFFSETS = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)


def calibrate_null(scores: np.ndarray, frames: LabeledFrames, n_labels: int) -> tuple[float, dict]:
    """The offset on the null column that maximises accuracy on held-out frames, and that accuracy.

    Sinkhorn with dustbins as large as the other side over-predicts null (every label may be
    missing, every observation may be a ghost); one scalar, fitted on synthetic validation
    frames, corrects it.
    """
    best = (-1.0, 0.0, {})
    for offset in NULL_OFFSETS:
        shifted = scores.copy()
        shifted[..., n_labels] -= offset
        labels, _ = assign(shifted, frames.mask)
        score = score_labeling(labels, frames.labels, frames.mask, n_labels).as_dict()
        if score["accuracy"] > best[0]:
            best = (score["accuracy"], offset, score)
    return best[1], best[2]


def validation_frames(layout: Layout, recipe: Recipe) -> LabeledFrames:
    """The held-out synthetic frames a recipe is validated and calibrated on (seed + 10000)."""
    return sample_frames(layout, recipe.validation_frames, np.random.default_rng(recipe.seed + 10_000),
                         FrameConfig(**recipe.frames))


def calibration(offset: float) -> dict:
    """The card's ``calibration`` entry."""
    return {"null_offset": offset, "chosen_on": "synthetic validation frames (seed + 10000), best accuracy"}


def write_card(model_path: str, card: dict) -> None:
    """Write the card beside ``model_path`` atomically."""
    with atomic_output(os.path.splitext(model_path)[0] + ".json") as tmp:
        with open(tmp, "w") as f:
            json.dump(card, f, indent=1)


def evaluate(method: Method, net: torch.nn.Module, layout: Layout, frames: LabeledFrames) -> tuple[float, dict]:
    """Null offset and per-frame accuracy of ``net`` on labeled frames, through the shared assignment step."""
    net.eval()
    scores = np.concatenate([method.scores(net, frames[s:s + 1024]) for s in range(0, len(frames), 1024)])
    net.train()
    return calibrate_null(scores, frames, len(layout))


def _batches(pool: LabeledFrames, size: int, rng: np.random.Generator) -> list[LabeledFrames]:
    """``pool`` cut into batches of ``size`` frames with similar point counts, in random order.

    A batch is padded to its fullest frame, and the pair tensors grow with the square of that:
    frames with distractors (up to 30 points) batched apart from those without (up to 22) make
    the average step about 15 % cheaper. Every frame is still used once, with the same weight.
    """
    order = np.argsort(pool.mask.sum(axis=1) + rng.random(len(pool)), kind="stable")
    out = [pool[order[i:i + size]] for i in range(0, len(pool) - size + 1, size)]
    return [out[i] for i in rng.permutation(len(out))]


#: Runs shorter than this train eagerly: compiling costs about 80 s on this machine.
COMPILE_FROM_STEPS = 2000


def train(layout: Layout, recipe: Recipe, progress: Callable | None = _progress, *,
          device: str = "cpu") -> tuple[torch.nn.Module, dict]:
    """Train one model of ``recipe.method`` for ``layout`` on synthetic frames; returns it (on the CPU) and
    its metrics. ``device``: where the steps run (``"cuda"`` on a GPU machine; ``set`` only, not compiled)."""
    torch.manual_seed(recipe.seed)
    rng = np.random.default_rng(recipe.seed)
    method = get_method(recipe.method, layout.names, **recipe.model)
    net = method.build().to(device)
    opt = torch.optim.AdamW(net.parameters(), lr=recipe.lr, weight_decay=recipe.weight_decay)
    warm = max(1, recipe.steps // 20)

    def schedule(step: int) -> float:  # linear warm-up, cosine decay
        return min(1.0, (step + 1) / warm) * 0.5 * (1 + math.cos(math.pi * min(step, recipe.steps) / recipe.steps))

    sched = torch.optim.lr_scheduler.LambdaLR(opt, schedule)
    cfg = FrameConfig(**recipe.frames)
    val = validation_frames(layout, recipe)
    started = time.perf_counter()
    compiled = recipe.compile and recipe.steps >= COMPILE_FROM_STEPS and device == "cpu"
    step_net = torch.compile(net, dynamic=True) if compiled else net
    batches: list[LabeledFrames] = []
    ema = None
    for step in range(recipe.steps):
        if not batches:
            batches = _batches(sample_frames(layout, recipe.chunk, rng, cfg), recipe.batch, rng)
        batch = batches.pop()
        k = max(1, int(batch.mask.sum(axis=1).max()))
        batch = LabeledFrames(batch.points[:, :k], batch.labels[:, :k], batch.mask[:, :k], batch.markers)
        try:
            loss = method.loss(step_net, batch)
        except Exception as e:  # torch.compile needs a C++ toolchain: without one, train eagerly
            if step_net is net:
                raise
            reason = (str(e).splitlines() or [""])[0][:200]
            warnings.warn(f"torch.compile failed ({type(e).__name__}: {reason}); training eagerly", stacklevel=2)
            step_net = net
            loss = method.loss(net, batch)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        sched.step()
        ema = loss.item() if ema is None else 0.98 * ema + 0.02 * loss.item()
        if progress and (step % 10 == 0 or step == recipe.steps - 1):
            progress(step + 1, recipe.steps, started, ema)
    seconds = time.perf_counter() - started
    net = net.cpu()
    offset, val_score = evaluate(method, net, layout, val)
    metrics = {"synthetic_validation": val_score, "null_offset": offset, "train_seconds": round(seconds, 1)}
    net.eval()
    return net, metrics


def export(net: torch.nn.Module, layout: Layout, recipe: Recipe, metrics: dict, path: str) -> dict:
    """Write ``path`` (ONNX) and ``path`` with ``.json`` (the card) atomically; returns the card."""
    method = get_method(recipe.method, layout.names, **recipe.model)
    example = sample_frames(layout, 4, np.random.default_rng(0), FrameConfig(**recipe.frames))
    with atomic_output(path) as tmp:
        method.export(net, example, tmp)
    digest = hashlib.sha256(open(path, "rb").read()).hexdigest()
    card = {
        "format": "mocap_autolabel model card 1",
        "method": recipe.method,
        "layout": {"name": layout.name, "labels": layout.names},
        "input": method.card["input"],
        **card_tail(recipe, metrics, digest, "synthetic frames only (mocap_autolabel.core.synth.frames)"),
    }
    write_card(path, card)
    return card


def card_tail(recipe, metrics: dict, digest: str, data: str, **training) -> dict:
    """The entries every model card ends with: output, training (recipe, data, frames seen, versions,
    machine, and ``training``'s extra entries), calibration, metrics and the model's checksum."""
    return {
        "output": {"name": "scores", "shape": ["frames", "K", "M + 1"],
                   "meaning": "log-domain scores of each observation against the M labels and null (last column)"},
        "training": {"recipe": asdict(recipe), **training, "data": data, "frames_seen": recipe.steps * recipe.batch,
                     "torch": torch.__version__, "machine": f"{platform.machine()} {os.cpu_count()} cores"},
        "calibration": calibration(metrics.get("null_offset", 0.0)),
        "metrics": metrics,
        "sha256": digest,
    }
