"""The fingers' order over a whole take, checked by the template hand (core.hand.finger_order)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import true_markers
from mocap_autolabel.core.hand.finger_order import (
    candidate_orders,
    checked_order,
    checked_sides,
    checked_spans,
    finger_groups,
    label_map,
    labeler_loss,
)
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.pipeline import label_take
from mocap_autolabel.core.synth.generate import synthesize


def test_which_layouts_are_checked():
    tips5 = finger_groups(load_layout("tips5_hand3"))
    assert tips5 is not None and [len(g) for g in tips5] == [1] * 5
    assert [len(g) for g in finger_groups(load_layout("tips10_hand3"))] == [2] * 5
    assert finger_groups(load_layout("tips5")) is None  # no hand frame: five tips alone fit several orders
    assert finger_groups(load_layout("tips3_hand3")) is None  # not every finger
    assert finger_groups(load_layout("han19")) is None  # the thumb's markers are not the fingers'
    orders = candidate_orders()
    assert orders[0] == (0, 1, 2, 3, 4) and len(orders) == len(set(orders)) == 23
    assert all(sorted(o) == [0, 1, 2, 3, 4] for o in orders)


@pytest.mark.parametrize("order", [(1, 0, 2, 3, 4), (2, 1, 0, 3, 4), (1, 2, 0, 3, 4)])
def test_a_wrong_finger_order_is_put_back_and_a_right_one_kept(order):
    layout = load_layout("tips5_hand3")
    groups, m = finger_groups(layout), len(layout)
    synth = synthesize(layout, 300, seed=5)
    right = true_markers(synth, m)
    kept, facts = checked_order(right, layout, groups)
    assert kept == (0, 1, 2, 3, 4) and facts["side"] in ("left", "right")
    wrong = np.full_like(right, np.nan)
    wrong[:, label_map(groups, order, m)] = right  # each finger's labels on another finger
    back, facts = checked_order(wrong, layout, groups)
    restored = np.full_like(wrong, np.nan)
    restored[:, label_map(groups, back, m)] = wrong
    assert np.array_equal(restored, right, equal_nan=True)
    assert facts["chosen_mm"] <= 0.9 * facts["residual_mm"]


def _scores_for(observed: np.ndarray, sure: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-sample labels ``(F, M)`` (slot j holds label j where seen), slots ``(F, M)`` and log-probability
    scores ``(F, M, M + 1)`` of a labeler sure of those labels, or one that cannot tell the labels apart."""
    frames, m, _ = observed.shape
    seen = np.isfinite(observed[..., 0])
    per = np.where(seen, np.arange(m), -1)
    slots = per.astype(np.int32)  # observation j of a frame is take slot j
    scores = np.full((frames, m, m + 1), np.log(1.0 / (m + 1)), dtype=np.float32)
    if sure:
        scores[:] = -20.0
        scores[:, np.arange(m), np.arange(m)] = 0.0
    return per, slots, scores


def test_the_labelers_word_keeps_an_order_it_is_sure_of_and_gives_way_where_it_cannot_tell():
    layout = load_layout("tips5_hand3")
    groups, m = finger_groups(layout), len(layout)
    right = true_markers(synthesize(layout, 300, seed=5), m)
    swap = (1, 0, 2, 3, 4)
    wrong = np.full_like(right, np.nan)
    wrong[:, label_map(groups, swap, m)] = right
    per, slots, scores = _scores_for(wrong, sure=False)
    unsure = labeler_loss(scores, slots, per, m, 0, groups)
    assert unsure.shape == (len(candidate_orders()),) and np.allclose(unsure, 0.0)
    back, _ = checked_order(wrong, layout, groups, lost=unsure)
    assert back == checked_order(wrong, layout, groups)[0] != (0, 1, 2, 3, 4)  # the fit alone decides
    per, slots, scores = _scores_for(wrong, sure=True)
    sure = labeler_loss(scores, slots, per, m, 0, groups)
    assert sure[0] == 0.0 and (sure[1:] > 0).all()
    moved = np.isfinite(wrong[:, groups[0][0], 0]).sum() + np.isfinite(wrong[:, groups[1][0], 0]).sum()
    assert sure[candidate_orders().index(swap)] == pytest.approx(20.0 * moved)  # thumb and index both moved
    kept, facts = checked_order(wrong, layout, groups, lost=sure)
    assert kept == (0, 1, 2, 3, 4) and facts["chosen_mm"] == facts["residual_mm"]
    # A second hand's block of labels: each finger's score is the better hand's (sides named after scoring).
    two = np.concatenate([np.full_like(scores, -30.0)[..., :m], scores], axis=2)
    assert np.allclose(labeler_loss(two, slots, per, m, 0, groups), sure)


def test_two_hands_sides_the_wrong_way_round_are_put_back():
    layout = load_layout("tips5_hand3")
    groups, m = finger_groups(layout), len(layout)
    hand = true_markers(synthesize(layout, 300, seed=5), m)
    _, facts = checked_order(hand, layout, groups)
    mirrored = hand * np.array([-1.0, 1.0, 1.0])  # the same hand seen in a mirror: the other side
    other = "left" if facts["side"] == "right" else "right"
    sides, found = checked_sides([hand, mirrored], layout, groups, [other, facts["side"]])
    assert sides == [facts["side"], other]
    assert [order for order, _ in found] == [(0, 1, 2, 3, 4)] * 2 and [f["side"] for _, f in found] == sides
    kept, _ = checked_sides([hand, mirrored], layout, groups, [facts["side"], other])
    assert kept == [facts["side"], other]


def test_a_stretch_of_the_take_in_a_wrong_order_is_found_and_the_rest_left():
    layout = load_layout("tips5_hand3")
    groups, m = finger_groups(layout), len(layout)
    right = true_markers(synthesize(layout, 300, seed=3), m)
    _, facts = checked_order(right, layout, groups)
    swap = (0, 1, 3, 2, 4)  # middle and ring the other way round in frames 120-179 only
    wrong = right.copy()
    wrong[120:180][:, label_map(groups, swap, m)] = right[120:180]
    spans = checked_spans(wrong, layout, groups, facts["side"], np.array([0, 120, 180, 300]))
    assert [(a, b, order) for a, b, order, _ in spans] == [(120, 180, swap)]
    assert checked_spans(right, layout, groups, facts["side"], np.array([0, 120, 180, 300])) == []
    # The labeler's word: one that cannot tell the fingers apart leaves it to the fit, one sure of the
    # stretch's labels keeps them.
    per, slots, scores = _scores_for(wrong, sure=False)
    unsure = checked_spans(wrong, layout, groups, facts["side"], np.array([0, 120, 180, 300]),
                           lambda a, b: labeler_loss(scores[a:b], slots[a:b], per[a:b], m, 0, groups))
    assert [(a, b, order) for a, b, order, _ in unsure] == [(120, 180, swap)]
    per, slots, scores = _scores_for(wrong, sure=True)
    assert checked_spans(wrong, layout, groups, facts["side"], np.array([0, 120, 180, 300]),
                         lambda a, b: labeler_loss(scores[a:b], slots[a:b], per[a:b], m, 0, groups)) == []
    # too short a stretch is not judged on its own
    short = right.copy()
    short[120:130][:, label_map(groups, swap, m)] = right[120:130]
    assert checked_spans(short, layout, groups, facts["side"], np.array([0, 120, 130, 300])) == []


def test_the_pipeline_keeps_a_right_labeling_and_puts_back_a_take_with_two_fingers_swapped():
    from mocap_autolabel.core.review import SURE

    layout = load_layout("tips5_hand3")
    right = synthesize(layout, 300, seed=2)
    labeling = label_take(right.take, layout)
    [checked] = labeling.info["finger_order"]
    assert checked["moved"] == {} and checked["segments"] == 0
    # seed 4: set + vote label the middle and ring fingertips the other way round for the whole take
    swapped = synthesize(layout, 300, seed=4)
    labeling = label_take(swapped.take, layout)
    [checked] = labeling.info["finger_order"]
    assert checked["moved"] == {"middle": "ring", "ring": "middle"} and checked["segments"] > 0
    per, ok = labeling.per_sample(), swapped.take.valid & (swapped.labels >= 0)
    assert (per[ok] == swapped.labels[ok]).mean() > 0.95
    moved = np.isin(labeling.label, [layout.names.index("MiddleTip"), layout.names.index("RingTip")])
    assert (labeling.confidence[moved] < SURE).all()  # the reviewer checks what the fit moved
    assert "finger order changed by the template hand's fit (middle -> ring, ring -> middle)" \
        in labeling.info["hands"]["warning"]
    assert "finger_order" not in label_take(synthesize(load_layout("tips3"), 100, seed=1).take,
                                            load_layout("tips3")).info


def test_a_reviewers_lock_is_never_moved_by_the_check():
    from mocap_autolabel.core.labeling import Constraint
    from mocap_autolabel.core.settings import Corrections

    layout = load_layout("tips5_hand3")
    swapped = synthesize(layout, 300, seed=4)
    # the reviewer locks a ring-tip sample as MiddleTip, the order the vote chose for this take
    middle = layout.names.index("MiddleTip")
    f, p = np.nonzero(swapped.labels == layout.names.index("RingTip"))
    lock = Constraint(slot=int(p[0]), start=int(f[0]), stop=int(f[0]) + 1, label=middle)
    labeling = label_take(swapped.take, layout, corrections=Corrections(constraints=(lock,)))
    [checked] = labeling.info["finger_order"]
    assert checked["moved"] == {} and checked["kept_for_locks"] == {"middle": "ring", "ring": "middle"}
    assert labeling.per_sample()[lock.start, lock.slot] == middle


def test_two_real_sparse_hands_whose_shape_gave_the_wrong_sides_get_them_put_back():
    # han2018 User1 capture2 sequence 16, both files as one take reduced to tips + a hand cluster
    # and corrupted as benchmarks/two_hands.py does: both hands' labels look like right hands' (a
    # permuted finger order turns the shape), and the shape's call had the sides the wrong way round.
    import os

    from conftest import data_path
    from mocap_autolabel.core.layout import Layout
    from mocap_autolabel.core.review import SURE
    from mocap_autolabel.core.synth.generate import corrupt_take
    from mocap_autolabel.core.take import read_take

    han19 = load_layout("han19")
    names = ["ThumbTip", "IndexTip", "MiddleTip", "RingTip", "PinkyTip", "BackHand1", "BackHand2", "BackHand3"]
    by_name = {mk.name: mk for mk in han19.markers}
    layout = Layout("tips5+back", tuple(by_name[n] for n in names), han19.glove, "han19 subset")
    folder = data_path("hands", "han2018_dense19", "User1", "capture2")
    files = [read_take(os.path.join(str(folder), f"sequence.16_training_dense_{side}.trc"))
             for side in ("left", "right")]
    n = min(t.n_frames for t in files)
    markers = np.concatenate([t.positions[:n, [t.names.index(x) for x in names]] for t in files], axis=1)
    take, truth, _ = corrupt_take(markers.astype(np.float64), 120.0, seed=34)
    labeling = label_take(take, layout)
    facts = labeling.info["hands"]
    assert facts["sides_by"] == "the template hand's fit" and "check the sides" in facts["warning"]
    per, m = labeling.per_sample(), len(layout)
    ok = take.valid & (truth >= 0) & (per >= 0)
    assert ((truth[ok] < m) == (per[ok] < m)).mean() > 0.9  # each hand's labels on its own side
    assert (labeling.confidence[labeling.label >= 0] < SURE).all()


def test_a_stretch_order_never_gives_one_label_to_two_trajectories_of_a_frame():
    """A stretch's order moves only the trajectories inside it: where the middle tip's piece inside
    would take the ring label of a trajectory running past the stretch's ends, nothing moves (a
    han2018 tips + hand cluster take came out with RingTip twice in frames 19-34, and writing it
    failed: "labeling gives one label to two samples of the same frame")."""
    from mocap_autolabel.core.labeling import Labeling
    from mocap_autolabel.core.stages.refine import _reorder

    layout = load_layout("tips5_hand3")
    groups, m = finger_groups(layout), len(layout)
    middle, ring = layout.names.index("MiddleTip"), layout.names.index("RingTip")
    swap = (0, 1, 3, 2, 4)  # middle <-> ring

    def labeling() -> Labeling:  # slot 0: the ring tip over frames 0-39; slot 1: the middle tip over 10-29
        return Labeling(layout.names, 40, 2, np.array([0, 1]), np.array([0, 10]), np.array([40, 30]),
                        np.array([ring, middle], dtype=np.int16), np.ones(2, dtype=np.float32),
                        np.zeros(2, dtype=bool), {})

    lab, facts = labeling(), {}
    done = _reorder(lab, groups, swap, np.array([False, True]), 0, m, facts, "frames 10-29: ")
    assert done["moved"] == {} and done["kept_for_overlap"] == {"middle": "ring", "ring": "middle"}
    assert lab.label.tolist() == [ring, middle] and not facts
    per = lab.per_sample()
    assert all(len(set(row[row >= 0].tolist())) == len(row[row >= 0]) for row in per)
    # Both trajectories in the stretch: the order moves them together.
    lab = labeling()
    done = _reorder(lab, groups, swap, np.array([True, True]), 0, m, {}, "")
    assert lab.label.tolist() == [middle, ring] and done["segments"] == 2
