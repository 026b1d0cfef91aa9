"""``python -m training``: build the shipped models (``--all``) or one model."""

from __future__ import annotations

import argparse
import os
import sys

from mocap_autolabel.core.layout import load_layout

from .any_layout import AnyRecipe, card_summary, export_any, train_any
from .recipes import SHIPPED_LAYOUTS, recipe
from .train import export, train

CHECKPOINT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "checkpoints", "set_any.pt")
MODELS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "addon", "mocap_autolabel", "models")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m training", description=__doc__)
    ap.add_argument("--all", action="store_true", help="every shipped model (set, perm, cnn for han19 and glove13)")
    ap.add_argument("--method", action="append", choices=["set", "perm", "cnn"])
    ap.add_argument("--layout", action="append", help="built-in layout name or .toml")
    ap.add_argument("--any", action="store_true",
                    help="the layout-conditioned set model (set_any), resumable from its checkpoint")
    ap.add_argument("--checkpoint", default=CHECKPOINT, help="set_any's checkpoint (resumed when present)")
    ap.add_argument("--out", default=MODELS, help="folder for <method>_<layout>.onnx and .json")
    args = ap.parse_args(argv)
    if args.any or args.all:
        r = AnyRecipe()
        print(f"training set for any layout: {r.steps} steps (checkpoint {args.checkpoint})", file=sys.stderr)
        net, metrics = train_any(r, checkpoint=args.checkpoint)
        path = os.path.join(args.out, "set_any.onnx")
        card = export_any(net, r, metrics, path)
        print(f"wrote {path}: synthetic validation {card_summary(card)}", file=sys.stderr)
        if args.any and not (args.method or args.layout):
            return 0
    methods = args.method or (["set", "perm", "cnn"] if args.all else ["set"])
    layouts = args.layout or list(SHIPPED_LAYOUTS)
    for layout_name in layouts:
        layout = load_layout(layout_name)
        for method in methods:
            r = recipe(method, layout.name)
            print(f"training {method} for {layout.name}: {r.steps} steps", file=sys.stderr)
            net, metrics = train(layout, r)
            path = os.path.join(args.out, f"{method}_{layout.name}.onnx")
            export(net, layout, r, metrics, path)
            v = metrics["synthetic_validation"]
            print(f"wrote {path}: synthetic validation accuracy {v['accuracy']:.4f}, "
                  f"{metrics['train_seconds'] / 60:.1f} min", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
