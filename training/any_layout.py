"""The layout-conditioned ``set`` model (``set_any``): one model for every marker layout.

Trained on random layouts (:func:`mocap_autolabel.core.synth.layouts.random_layout`), one per run of
``Recipe.chunk`` frames, so that each batch has one label set. Training checkpoints itself every
``CHECKPOINT_STEPS`` steps and resumes from the checkpoint when run again with the same recipe: a
run of hours on 2 cores can be stopped and picked up. ``python -m training --any`` (``make models``).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from mocap_autolabel.core.atomic import atomic_output
from mocap_autolabel.core.labelers.assign import assign
from mocap_autolabel.core.labelers.inputs import prepare_inputs
from mocap_autolabel.core.layout import DESCRIPTOR_SIZE, Layout, builtin_layouts, load_layout, marker_descriptors
from mocap_autolabel.core.metrics import score_labeling
from mocap_autolabel.core.synth.frames import FrameConfig, LabeledFrames, sample_frames
from mocap_autolabel.core.synth.layouts import HELD_OUT, random_layout

from .inputs import matching_loss
from .models import AnyLayoutLabeler, ObservationScores
from .train import NULL_OFFSETS, _batches, _progress, card_tail, write_card

#: Steps between checkpoints.
CHECKPOINT_STEPS = 100
#: Share of training layouts that are parts of the built-in ones (:func:`training_layout`).
BUILTIN_SHARE = 0.3


@dataclass
class AnyRecipe:
    """Everything that determines the ``set_any`` model (with the code)."""

    steps: int = 30000
    batch: int = 192
    lr: float = 3e-3
    weight_decay: float = 1e-4
    seed: int = 0
    chunk: int = 1152  # frames of one random layout (6 batches)
    frames: dict = field(default_factory=lambda: asdict(FrameConfig(
        hands=12, distractor_share=0.3, convergence=0.1, proportions=0.1, range_margin_deg=15.0, placement_sd=0.003,
        tip_convergence=0.018)))
    model: dict = field(default_factory=lambda: {"dim": 64, "hidden": 128, "layers": 4, "queries": 2,
                                                 "label_layers": 2})
    validation_layouts: int = 48
    validation_frames: int = 128  # per validation layout
    compile: bool = False  # label sets of every size recompile the graph again and again


def frame_config(recipe: AnyRecipe, layout: Layout) -> FrameConfig:
    """The recipe's corruption scaled to ``layout``: at most a quarter of its markers dropped, and ghosts
    and distractors in proportion to its size (eight distractors around five fingertips drown them)."""
    cfg = dict(recipe.frames)
    m = len(layout)
    cfg["drop"] = (0, min(cfg["drop"][1], max(1, m // 4)))
    cfg["ghosts"] = (0, min(cfg["ghosts"][1], max(1, m // 5)))
    cfg["distractors"] = (1, min(cfg["distractors"][1], max(2, m // 3)))
    return FrameConfig(**cfg)


def training_layout(rng: np.random.Generator) -> Layout:
    """A random layout (:func:`random_layout`), or now and then a random part of a built-in one
    without its markers in the held-out band, so that the sets studios use are seen often."""
    if rng.random() >= BUILTIN_SHARE:
        return random_layout(rng)
    lo, hi = HELD_OUT["proximal_phalanx_along"]
    while True:
        markers = [m for m in load_layout(str(rng.choice(builtin_layouts()))).markers
                   if not (m.bone.endswith("_prox") and lo <= m.along < hi)]
        if len(markers) >= 3:
            break
    keep = rng.permutation(len(markers))[:int(rng.integers(3, len(markers) + 1))]
    return Layout("builtin part", tuple(markers[i] for i in keep))


def descriptors(layout: Layout) -> torch.Tensor:
    return torch.from_numpy(marker_descriptors(layout))


def feeds(frames: LabeledFrames, layout: Layout) -> tuple[torch.Tensor, ...]:
    """The network's inputs, prepared by the core exactly as the labeler prepares them."""
    f, _ = prepare_inputs({"input": {"convention": "points"}}, frames.points, frames.mask)
    return (torch.from_numpy(f["points"]), torch.from_numpy(f["mask"]), torch.from_numpy(f["axes"]),
            descriptors(layout))


def loss(net: torch.nn.Module, frames: LabeledFrames, layout: Layout) -> torch.Tensor:
    """Negative log-likelihood of the true matching under the Sinkhorn couplings (with dustbins)."""
    inputs = feeds(frames, layout)
    return matching_loss(net(*inputs), frames.labels, inputs[1], len(layout))


def build(recipe: AnyRecipe) -> AnyLayoutLabeler:
    return AnyLayoutLabeler(DESCRIPTOR_SIZE, **recipe.model)


def validation_set(recipe: AnyRecipe) -> list[tuple[Layout, LabeledFrames]]:
    """Held-out random layouts and frames (seed + 10000)."""
    rng = np.random.default_rng(recipe.seed + 10_000)
    out = []
    for i in range(recipe.validation_layouts):
        layout = random_layout(rng, f"validation{i}")
        out.append((layout, sample_frames(layout, recipe.validation_frames, rng, frame_config(recipe, layout))))
    return out


def evaluate(net: torch.nn.Module, val: list[tuple[Layout, LabeledFrames]]) -> tuple[float, dict]:
    """The null offset that maximises accuracy over all validation layouts, and the scores at it."""
    net.eval()
    export = ObservationScores(net)
    with torch.no_grad():
        scores = [export(*feeds(frames, layout)).numpy() for layout, frames in val]
    net.train()
    best = (-1.0, 0.0, {})
    for offset in NULL_OFFSETS:
        total = {"instances": 0, "correct": 0, "frames": 0, "frames_all_correct": 0}
        for (layout, frames), s in zip(val, scores):
            shifted = s.copy()
            shifted[..., len(layout)] -= offset
            labels, _ = assign(shifted, frames.mask)
            r = score_labeling(labels, frames.labels, frames.mask, len(layout)).as_dict()
            for key in total:
                total[key] += r[key]
        accuracy = total["correct"] / total["instances"]
        if accuracy > best[0]:
            best = (accuracy, offset, {**total, "accuracy": accuracy,
                                       "frame_accuracy": total["frames_all_correct"] / total["frames"]})
    return best[1], best[2]


def _state(rng: np.random.Generator) -> dict:
    return {"numpy": rng.bit_generator.state, "torch": torch.get_rng_state()}


def train_any(recipe: AnyRecipe, checkpoint: str | None = None,
              progress: Callable | None = _progress) -> tuple[torch.nn.Module, dict]:
    """Train (or resume training) the ``set_any`` model; returns it and its validation metrics."""
    torch.manual_seed(recipe.seed)
    rng = np.random.default_rng(recipe.seed)
    net = build(recipe)
    opt = torch.optim.AdamW(net.parameters(), lr=recipe.lr, weight_decay=recipe.weight_decay)
    warm = max(1, recipe.steps // 20)

    def schedule(step: int) -> float:  # linear warm-up, cosine decay
        return min(1.0, (step + 1) / warm) * 0.5 * (1 + math.cos(math.pi * min(step, recipe.steps) / recipe.steps))

    sched = torch.optim.lr_scheduler.LambdaLR(opt, schedule)
    start, seconds = 0, 0.0
    if checkpoint:
        os.makedirs(os.path.dirname(os.path.abspath(checkpoint)), exist_ok=True)
    if checkpoint and os.path.exists(checkpoint):
        saved = torch.load(checkpoint, weights_only=False)
        if saved["recipe"] != asdict(recipe):
            raise SystemExit(f"{checkpoint}: made with another recipe; delete it to start again")
        net.load_state_dict(saved["net"])
        opt.load_state_dict(saved["opt"])
        sched.load_state_dict(saved["sched"])
        rng.bit_generator.state = saved["rng"]["numpy"]
        torch.set_rng_state(saved["rng"]["torch"])
        start, seconds = saved["step"], saved["seconds"]
        print(f"resuming {checkpoint} at step {start}", file=sys.stderr)
    step_net = torch.compile(net, dynamic=True) if recipe.compile else net
    started = time.perf_counter() - seconds
    batches: list[LabeledFrames] = []
    layout = None
    saved_at = start
    ema = None
    for step in range(start, recipe.steps):
        if not batches:
            layout = training_layout(rng)
            pool = sample_frames(layout, recipe.chunk, rng, frame_config(recipe, layout))
            batches = _batches(pool, recipe.batch, rng)
        batch = batches.pop()
        k = max(1, int(batch.mask.sum(axis=1).max()))
        batch = LabeledFrames(batch.points[:, :k], batch.labels[:, :k], batch.mask[:, :k], batch.markers)
        try:
            value = loss(step_net, batch, layout)
        except Exception as e:  # torch.compile needs a C++ toolchain: without one, train eagerly
            if step_net is net:
                raise
            warnings.warn(f"torch.compile failed ({type(e).__name__}); training eagerly", stacklevel=2)
            step_net = net
            value = loss(net, batch, layout)
        opt.zero_grad()
        value.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        sched.step()
        ema = value.item() if ema is None else 0.98 * ema + 0.02 * value.item()
        done = step + 1
        if progress and (step % 10 == 0 or done == recipe.steps):
            progress(done, recipe.steps, started, ema)
        # A checkpoint at a chunk's end, so that a resumed run draws the same next layout.
        if checkpoint and not batches and (done - saved_at >= CHECKPOINT_STEPS or done == recipe.steps):
            saved_at = done
            with atomic_output(checkpoint) as tmp:
                torch.save({"recipe": asdict(recipe), "net": net.state_dict(), "opt": opt.state_dict(),
                            "sched": sched.state_dict(), "rng": _state(rng), "step": done,
                            "seconds": time.perf_counter() - started, "loss": ema}, tmp)
    seconds = time.perf_counter() - started
    offset, val_score = evaluate(net, validation_set(recipe))
    net.eval()
    return net, {"synthetic_validation": val_score, "null_offset": offset, "train_seconds": round(seconds, 1)}


def export_any(net: torch.nn.Module, recipe: AnyRecipe, metrics: dict, path: str) -> dict:
    """Write ``path`` (ONNX) and its card atomically; returns the card."""
    layout = random_layout(np.random.default_rng(0), "example")
    example = feeds(sample_frames(layout, 4, np.random.default_rng(0), frame_config(recipe, layout)), layout)
    names = ["points", "mask", "axes", "layout"]
    axes = {"points": {0: "frames", 1: "K"}, "mask": {0: "frames", 1: "K"}, "axes": {0: "frames"},
            "layout": {0: "M"}, "scores": {0: "frames", 1: "K", 2: "M + 1"}}
    with atomic_output(path) as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(ObservationScores(net).eval(), example, tmp, dynamo=False, opset_version=17,
                          input_names=names, output_names=["scores"], dynamic_axes=axes)
    digest = hashlib.sha256(open(path, "rb").read()).hexdigest()
    card = {
        "format": "mocap_autolabel model card 1",
        "method": "set",
        "layout": {"name": "any", "labels": []},
        "input": {"convention": "points", "layout_conditioned": True,
                  "points": {"shape": ["frames", "K", 3], "dtype": "float32", "units": "m",
                             "meaning": "observations of each frame, any order, padded with anything"},
                  "mask": {"shape": ["frames", "K"], "dtype": "float32", "meaning": "1 real observation, 0 padding"},
                  "axes": {"shape": ["frames", 3, 3], "dtype": "float32",
                           "meaning": "principal axes of each frame's observations, from "
                                      "core.labelers.inputs.principal_frame (signs do not matter)"},
                  "layout": {"shape": ["M", DESCRIPTOR_SIZE], "dtype": "float32",
                             "meaning": "each label's marker on the template hand, from "
                                        "core.layout.marker_descriptors"}},
        **card_tail(recipe, metrics, digest, "synthetic frames of random layouts only "
                                             "(mocap_autolabel.core.synth.layouts)", held_out=HELD_OUT),
    }
    write_card(path, card)
    return card


def card_summary(card: dict) -> str:
    v = card["metrics"]["synthetic_validation"]
    return json.dumps({"accuracy": round(v["accuracy"], 4), "frame_accuracy": round(v["frame_accuracy"], 4)})
