"""Which trajectory holds a marker, checked by the template hand (core.hand.holders)."""

from __future__ import annotations

import glob
import os

import numpy as np
from conftest import data_path
from helpers import true_markers
from mocap_autolabel.core.hand.finger_order import checked_order, finger_groups
from mocap_autolabel.core.hand.holders import better_holders
from mocap_autolabel.core.layout import Layout, load_layout
from mocap_autolabel.core.pipeline import label_take
from mocap_autolabel.core.process import Outputs, process_take
from mocap_autolabel.core.settings import LabelSettings
from mocap_autolabel.core.synth.generate import corrupt_take, synthesize
from mocap_autolabel.core.take import read_take


def test_a_ghost_that_holds_a_fingertip_gives_it_back_to_the_fingertip():
    layout = load_layout("tips5_hand3")
    m, pinky = len(layout), layout.names.index("PinkyTip")
    synth = synthesize(layout, 200, seed=3)
    right = true_markers(synth, m)
    _, facts = checked_order(right, layout, finger_groups(layout))
    # A ring riding with the hand, 9 cm off the hand cluster's centre: taken for the pinky tip.
    cluster = synth.markers[:, [i for i, mk in enumerate(layout.markers) if mk.bone == "palm"]].mean(axis=1)
    ghost = cluster + np.array([0.0, 0.09, 0.0])
    positions = np.stack([right[:, pinky], ghost], axis=1)  # slot 0: the true pinky tip, slot 1: the ghost
    wrong = right.copy()
    wrong[:, pinky] = ghost
    [holder] = better_holders(positions, wrong, [(0, 0, 200)], layout, facts["side"])
    assert (holder.slot, holder.label) == (0, pinky) and holder.fitted <= 0.7 * holder.before
    assert better_holders(positions, right, [(1, 0, 200)], layout, facts["side"]) == []  # the ghost takes nothing


def _reduced(layout: Layout, names: list[str]) -> Layout:
    by_name = {mk.name: mk for mk in layout.markers}
    return Layout("tips5+back", tuple(by_name[n] for n in names), layout.glove, "han19 subset")


def test_a_real_take_whose_pinky_tip_a_ghost_held_is_labeled_right():
    # han2018 User1's twelfth sequence reduced to tips + a hand cluster and corrupted as
    # benchmarks/layouts.py does: set + vote gave a ghost that rides with the hand the pinky tip.
    han19 = load_layout("han19")
    names = ["ThumbTip", "IndexTip", "MiddleTip", "RingTip", "PinkyTip", "BackHand1", "BackHand2", "BackHand3"]
    paths = sorted(glob.glob(os.path.join(str(data_path("hands", "han2018_dense19")), "User1", "capture*", "*.trc")))
    take = read_take(paths[11])
    markers = take.positions[:, [take.names.index(n) for n in names]].astype(np.float64)
    raw, truth, _ = corrupt_take(markers, 120.0, seed=1)
    layout = _reduced(han19, names)
    labeling = label_take(raw, layout, LabelSettings(hand_count=1))
    # the front ends' entry too: the no-hand rule reads the moved segments' evidence
    result = process_take(raw, layout, LabelSettings(hand_count=1), Outputs(check_layout=False))
    assert np.array_equal(result.labeling.per_sample(), labeling.per_sample())
    per, ok = labeling.per_sample(), raw.valid & (truth >= 0)
    assert (per[ok] == truth[ok]).mean() == 1.0
    [moved] = labeling.info["holders"]
    assert moved["label"] == "PinkyTip" and moved["fitted_mm"] <= 0.7 * moved["residual_mm"]
    assert "given to another trajectory by the template hand's fit (a ghost riding with the hand held it?): " \
           f"PinkyTip in frames {raw.first_frame}-{raw.first_frame + 49}" in labeling.info["hands"]["warning"]
    pinky = labeling.label == layout.names.index("PinkyTip")
    assert (labeling.confidence[pinky] < 0.95).all()  # what the check moved is shown to the reviewer
