"""``python -m training.calibrate MODEL.onnx``: fit a model's null offset again and update its card.

Uses the same validation frames as training (the recipe's seed + 10000) and the model as
onnxruntime runs it; the ONNX file is not touched, so its checksum stays valid.
"""

from __future__ import annotations

import sys

from mocap_autolabel.core.labelers.onnx_labeler import OnnxLabeler
from mocap_autolabel.core.layout import load_layout

from .train import Recipe, calibrate_null, calibration, validation_frames, write_card


def recalibrate(model_path: str) -> dict:
    labeler = OnnxLabeler(model_path)
    card = labeler.card
    card.pop("calibration", None)  # raw scores
    layout = load_layout(card["layout"]["name"])
    val = validation_frames(layout, Recipe(**card["training"]["recipe"]))
    offset, score = calibrate_null(labeler.scores(val.points, val.mask), val, len(layout))
    card["calibration"] = calibration(offset)
    card["metrics"]["synthetic_validation"] = score
    card["metrics"]["null_offset"] = offset
    write_card(model_path, card)
    return card


if __name__ == "__main__":
    for path in sys.argv[1:]:
        c = recalibrate(path)
        print(f"{path}: null offset {c['calibration']['null_offset']}, "
              f"validation accuracy {c['metrics']['synthetic_validation']['accuracy']:.4f}")
