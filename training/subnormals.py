"""Radial-basis exponents floored in the ``set`` graphs: no subnormal floats in a frame's inference.

``exp(-x * x)`` of a pair distance far from every basis centre underflows into subnormal floats,
which x86 CPUs compute with many times the cycles of normal ones; the products over those bases
(the attention biases, each head's attention-weighted distance profile) then cost most of a
frame's inference. Floored at :data:`RBF_EXPONENT_FLOOR`, a basis value is at least ``e**-60``,
far below float32's resolution beside the values it is summed with: the scores are unchanged
(``tests/core/test_models.py`` checks them against the unfloored graph).

New exports carry the floor from the network itself (:meth:`.models.SetLabeler.pair_terms`);
:func:`floor_radial_exponents` puts it into models exported before it, and their cards' checksums
follow::

    python -m training.subnormals addon/mocap_autolabel/models/set_*.onnx
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys

import numpy as np
from mocap_autolabel.core.atomic import atomic_output

#: The lowest exponent of a radial basis value: ``e**-60`` is a normal float32, and so are its
#: products with any weight of a trained network.
RBF_EXPONENT_FLOOR = -60.0
#: What the card says of the edit.
CARD_NOTE = f"radial-basis exponents floored at {RBF_EXPONENT_FLOOR:g} (no subnormal floats; scores unchanged)"


def radial_exps(graph) -> list:
    """The graph's ``Exp`` nodes of a negated square (``exp(-s * s)``: the radial bases), not yet floored."""
    made_by = {out: node for node in graph.node for out in node.output}

    def op(name: str) -> str | None:
        node = made_by.get(name)
        return node.op_type if node is not None else None

    found = []
    for node in graph.node:
        square = made_by.get(node.input[0]) if node.op_type == "Exp" else None
        if square is not None and square.op_type == "Mul" and op(square.input[0]) == "Neg":
            found.append(node)
    return found


def floor_radial_exponents(model) -> int:
    """Floor every radial-basis exponent of the ONNX ``model`` (an ``onnx.ModelProto``, changed in
    place) at :data:`RBF_EXPONENT_FLOOR`; the number of exponents floored (0: none left to floor)."""
    from onnx import helper, numpy_helper

    graph = model.graph
    exps = radial_exps(graph)
    if not exps:
        return 0
    floor = "rbf_exponent_floor"
    graph.initializer.append(numpy_helper.from_array(np.array(RBF_EXPONENT_FLOOR, dtype=np.float32), floor))
    nodes = []
    for node in graph.node:
        if any(node is e for e in exps):
            floored = node.input[0] + "_floored"
            nodes.append(helper.make_node("Max", [node.input[0], floor], [floored], name=node.name + "_floor"))
            node.input[0] = floored
        nodes.append(node)
    del graph.node[:]
    graph.node.extend(nodes)  # each Max just before its Exp: still in topological order
    return len(exps)


def upgrade(path: str) -> int:
    """Floor the radial exponents of the model at ``path`` and bring its card's checksum along; the
    number floored (0: the file is left as it was)."""
    import onnx

    model = onnx.load(path)
    count = floor_radial_exponents(model)
    if not count:
        return 0
    onnx.checker.check_model(model)
    blob = model.SerializeToString()
    card_path = os.path.splitext(path)[0] + ".json"
    with open(card_path) as f:
        card = json.load(f)
    card["sha256"] = hashlib.sha256(blob).hexdigest()
    card["graph_edits"] = [*card.get("graph_edits", []), CARD_NOTE]
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(blob)
    with atomic_output(card_path) as tmp:
        with open(tmp, "w") as f:
            json.dump(card, f, indent=1)
    return count


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m training.subnormals", description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="+", help="ONNX models (their .json cards beside them)")
    for path in ap.parse_args(argv).models:
        print(f"{path}: {upgrade(path)} radial-basis exponent(s) floored", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
