"""Per-method glue between training frames and a network: inputs, loss, export, card.

Inputs are prepared by the core's :mod:`mocap_autolabel.core.labelers.inputs` from the same
card the exported model carries, so training and labeling share one definition.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch
from mocap_autolabel.core.labelers.inputs import prepare_inputs, scores_from_outputs
from mocap_autolabel.core.synth.frames import LabeledFrames

from .models import DepthCNN, ObservationScores, PermLabeler, SetLabeler


def _tensors(feeds: dict, names: list[str]) -> tuple:
    return tuple(torch.from_numpy(np.ascontiguousarray(feeds[n])) for n in names)


class Method:
    """How one method's network is built, fed, trained and exported."""

    name = ""
    input_names: list[str] = []
    #: Inputs and outputs whose second axis is the frame's observations (any K).
    per_observation: tuple[str, ...] = ()

    def __init__(self, n_labels: int, labels: list[str], **model):
        self.m, self.model_kw = n_labels, model
        self.card = {"layout": {"labels": labels}, "input": self.card_input()}

    def build(self) -> torch.nn.Module:
        raise NotImplementedError

    def card_input(self) -> dict:
        raise NotImplementedError

    def feeds(self, frames: LabeledFrames) -> tuple[tuple, dict]:
        feeds, context = prepare_inputs(self.card, frames.points, frames.mask)
        return _tensors(feeds, self.input_names), context

    def loss(self, net: torch.nn.Module, frames: LabeledFrames) -> torch.Tensor:
        raise NotImplementedError

    def export_module(self, net: torch.nn.Module) -> torch.nn.Module:
        return net

    def scores(self, net: torch.nn.Module, frames: LabeledFrames) -> np.ndarray:
        """``(B, K, M + 1)`` scores exactly as the labeler gets them from the exported model."""
        inputs, context = self.feeds(frames)
        with torch.no_grad():
            out = self.export_module(net)(*inputs)
        return scores_from_outputs(self.card, [out.numpy()], context, frames.points, frames.mask)

    def export(self, net: torch.nn.Module, frames: LabeledFrames, path: str, output_name: str = "scores") -> None:
        inputs, _ = self.feeds(frames)
        axes = {n: {0: "frames", 1: "K"} if n in self.per_observation else {0: "frames"}
                for n in self.input_names + [output_name]}
        with warnings.catch_warnings():
            # The tracer warns about shape-dependent Python values (K, M); they are dynamic axes or constants.
            warnings.simplefilter("ignore")
            torch.onnx.export(self.export_module(net).eval(), inputs, path, dynamo=False, opset_version=17,
                              input_names=self.input_names, output_names=[output_name], dynamic_axes=axes)


def matching_loss(out: torch.Tensor, labels: np.ndarray | torch.Tensor, mask: torch.Tensor, m: int) -> torch.Tensor:
    """Negative log-likelihood of the true matching under Sinkhorn couplings with dustbins:
    ``out`` ``(B, K+1, M+1)`` log-probabilities, ``labels`` ``(B, K)`` (label, -1 ghost, -2 padding),
    ``mask`` ``(B, K)``; every observation's row, and the occlusion row of every missing label."""
    if isinstance(labels, np.ndarray):
        labels = torch.from_numpy(labels.astype(np.int64))
    labels = labels.to(out.device, torch.int64)
    k = labels.shape[1]
    target = torch.where(labels >= 0, labels, torch.full_like(labels, m))
    obs = out[:, :k].gather(2, target[..., None])[..., 0]
    obs_loss = -(obs * mask).sum() / mask.sum()
    present = torch.zeros(labels.shape[0], m + 1, device=out.device)
    present.scatter_(1, torch.where(mask > 0.5, target, torch.full_like(target, m)), 1.0)
    missing = 1.0 - present[:, :m]
    occ_loss = -(out[:, k, :m] * missing).sum() / missing.sum().clamp(min=1.0)
    return obs_loss + occ_loss


class SetMethod(Method):
    name = "set"
    input_names = ["points", "mask", "axes"]
    per_observation = ("points", "mask", "scores")

    def build(self) -> torch.nn.Module:
        return SetLabeler(self.m, **self.model_kw)

    def card_input(self) -> dict:
        return {"convention": "points",
                "points": {"shape": ["frames", "K", 3], "dtype": "float32", "units": "m",
                           "meaning": "observations of each frame, any order, padded with anything"},
                "mask": {"shape": ["frames", "K"], "dtype": "float32", "meaning": "1 real observation, 0 padding"},
                "axes": {"shape": ["frames", 3, 3], "dtype": "float32",
                         "meaning": "principal axes of each frame's observations (columns, largest variance "
                                    "first), from core.labelers.inputs.principal_frame; only |coordinates| "
                                    "on them are used, so their signs do not matter"}}

    def export_module(self, net: torch.nn.Module) -> torch.nn.Module:
        return ObservationScores(net)

    def loss(self, net: torch.nn.Module, frames: LabeledFrames) -> torch.Tensor:
        """Negative log-likelihood of the true matching under the Sinkhorn couplings (with dustbins)."""
        inputs, _ = self.feeds(frames)
        device = next(net.parameters()).device
        inputs = tuple(t.to(device) for t in inputs)
        mask = inputs[1]
        out = net(*inputs)  # (B, K+1, M+1)
        return matching_loss(out, frames.labels, mask, self.m)


class PermMethod(Method):
    name = "perm"
    input_names = ["x"]

    @property
    def slots(self) -> int:
        return self.m + 3

    def build(self) -> torch.nn.Module:
        return PermLabeler(self.m, self.slots, **self.model_kw)

    def card_input(self) -> dict:
        return {"convention": "pca", "slots": self.m + 3,
                "x": {"shape": ["frames", self.m + 3, 3], "dtype": "float32",
                      "meaning": "observations centred, on principal axes (z first, x second), each axis scaled "
                                 "to [0, 1]; empty slots (0.5, 0.5, 0.5)"}}

    def loss(self, net: torch.nn.Module, frames: LabeledFrames) -> torch.Tensor:
        """Cross-entropy of the doubly stochastic matrix against the true permutation."""
        (x,), context = self.feeds(frames)
        index = context["index"]
        b, s = index.shape
        lab = np.take_along_axis(frames.labels.astype(np.int64), np.maximum(index, 0), axis=1)
        lab = np.where(index >= 0, lab, -2)
        target = np.empty_like(lab)
        for f in range(b):  # a column per slot: empty slots stand for missing labels, as in the paper
            free = [j for j in range(self.m) if j not in set(lab[f][lab[f] >= 0].tolist())]
            free += list(range(self.m, s))
            empty, ghost = np.flatnonzero(lab[f] == -2), np.flatnonzero(lab[f] == -1)
            target[f] = lab[f]
            target[f, np.concatenate([empty, ghost])] = free[:len(empty) + len(ghost)]
        log_d = net(x)
        return -log_d.gather(2, torch.from_numpy(target)[..., None]).mean()


class CnnMethod(Method):
    name = "cnn"
    input_names = ["image"]

    def build(self) -> torch.nn.Module:
        return DepthCNN(self.m, **self.model_kw)

    def card_input(self) -> dict:
        return {"convention": "depth",
                "image": {"shape": ["frames", 1, 52, 52], "dtype": "float32",
                          "meaning": "orthographic depth image along the best of 10 fixed random axes; "
                                     "depth in [0.1, 1] where a marker falls, 0 elsewhere"}}

    def loss(self, net: torch.nn.Module, frames: LabeledFrames) -> torch.Tensor:
        """Squared error of the regressed positions of all M markers (occluded ones too), canonical units."""
        (image,), ctx = self.feeds(frames)
        target = ((frames.markers - ctx["centre"]) @ ctx["rot"]) / ctx["scale"][:, None, None]
        pred = net(image).reshape(-1, self.m, 3)
        return ((pred - torch.from_numpy(target.astype(np.float32))) ** 2).sum(-1).mean()


METHODS = {"set": SetMethod, "perm": PermMethod, "cnn": CnnMethod}


def get_method(name: str, labels: list[str], **model) -> Method:
    return METHODS[name](len(labels), labels, **model)
