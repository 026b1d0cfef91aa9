"""``train``: a 'set' model for a marker layout from synthetic data (needs PyTorch and the training package)."""

from __future__ import annotations

import os
import sys

from .common import EXIT_FAILED, EXIT_OK, _fail


def _train(args) -> int:
    from ..core.layout import load_layout

    try:
        layout = load_layout(args.layout)
    except Exception as exc:
        return _fail(args.layout, exc)
    # The repository root: above commands/, mocap_autolabel/ and addon/.
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    if os.path.isdir(os.path.join(root, "training")) and root not in sys.path:
        sys.path.insert(0, root)  # a source checkout: training/ sits beside addon/
    try:
        from training.recipes import recipe
        from training.train import export, train
    except ImportError as exc:
        print(f"error: training needs PyTorch and the training package of a source checkout "
              f"(pip install torch==2.13.0; run from the repository): {exc}", file=sys.stderr)
        return EXIT_FAILED
    import dataclasses

    import torch

    if args.device == "cuda" and not torch.cuda.is_available():
        print(f"error: --device cuda: PyTorch {torch.__version__} sees no CUDA GPU here (train on the CPU without "
              f"--device, or install a CUDA build of PyTorch)", file=sys.stderr)
        return EXIT_FAILED
    r = recipe("set", layout.name)
    r = dataclasses.replace(r, seed=args.seed, steps=args.steps or r.steps)
    print(f"training a set model for {layout.name} ({len(layout)} markers) on synthetic frames: {r.steps} steps",
          file=sys.stderr)
    net, metrics = train(layout, r, device=args.device)
    try:
        export(net, layout, r, metrics, args.output)
    except OSError as exc:
        print(f"error: {args.output}: cannot write ({exc.strerror or exc})", file=sys.stderr)
        return EXIT_FAILED
    v = metrics["synthetic_validation"]
    print(f"{args.output}: synthetic validation {100 * v['accuracy']:.2f} % correct, card "
          f"{os.path.splitext(args.output)[0]}.json")
    return EXIT_OK
