"""``python -m training.calibrate MODEL.onnx``: fit a model's null offset again and update its card.

Uses the same validation frames as training (the recipe's seed + 10000) and the model as
onnxruntime runs it; the ONNX file is not touched, so its checksum stays valid.
"""

from __future__ import annotations

import json
import sys

import numpy as np
from mocap_autolabel.core.atomic import atomic_output
from mocap_autolabel.core.labelers.onnx_labeler import OnnxLabeler, card_path
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.frames import FrameConfig, sample_frames

from .train import calibrate_null


def recalibrate(model_path: str) -> dict:
    labeler = OnnxLabeler(model_path)
    card = labeler.card
    card.pop("calibration", None)  # raw scores
    recipe = card["training"]["recipe"]
    layout = load_layout(card["layout"]["name"])
    val = sample_frames(layout, recipe["validation_frames"], np.random.default_rng(recipe["seed"] + 10_000),
                        FrameConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in recipe["frames"].items()}))
    offset, score = calibrate_null(labeler.scores(val.points, val.mask), val, len(layout))
    card["calibration"] = {"null_offset": offset,
                           "chosen_on": "synthetic validation frames (seed + 10000), best accuracy"}
    card["metrics"]["synthetic_validation"] = score
    card["metrics"]["null_offset"] = offset
    with atomic_output(card_path(model_path)) as tmp:
        with open(tmp, "w") as f:
            json.dump(card, f, indent=1)
    return card


if __name__ == "__main__":
    for path in sys.argv[1:]:
        c = recalibrate(path)
        print(f"{path}: null offset {c['calibration']['null_offset']}, "
              f"validation accuracy {c['metrics']['synthetic_validation']['accuracy']:.4f}")
