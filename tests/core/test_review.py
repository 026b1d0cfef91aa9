"""Review in the core: confidence classes and corrections as constraints that a re-solve keeps."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.labelers import make_labeler
from mocap_autolabel.core.labelers.base import RememberingLabeler
from mocap_autolabel.core.labeling import NULL, Constraint
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.pipeline import label_take
from mocap_autolabel.core.review import (
    CONFIDENT,
    LOCKED,
    UNCERTAIN,
    VERY_UNCERTAIN,
    Review,
    changed_labels,
    marker_classes,
    segment_classes,
    uncertain_segments,
)
from mocap_autolabel.core.settings import Corrections, LabelSettings
from mocap_autolabel.core.synth.generate import synthesize


@pytest.fixture(scope="module")
def labeled():
    layout = load_layout("han19")
    take = synthesize(layout, 600, seed=21).take
    labeler = RememberingLabeler(make_labeler("set", layout))
    return layout, take, labeler, label_take(take, layout, labeler=labeler)


def test_classes_follow_confidence_and_locks(labeled):
    _, take, _, lab = labeled
    classes = segment_classes(lab)
    np.testing.assert_array_equal(classes[lab.confidence >= 0.95], CONFIDENT)
    assert (classes[(lab.confidence < 0.95) & (lab.confidence >= 0.5)] == UNCERTAIN).all()
    assert (classes[lab.confidence < 0.5] == VERY_UNCERTAIN).all()
    per = marker_classes(lab)
    assert per.shape == (take.n_frames, 19)
    present = np.zeros_like(per, dtype=bool)
    p = lab.per_sample()
    f, s = np.nonzero(p >= 0)
    present[f, p[f, s]] = True
    assert ((per >= 0) == present).all()
    worst = uncertain_segments(lab)
    assert (np.diff(lab.confidence[worst]) >= 0).all() and (lab.confidence[worst] < 0.95).all()


def test_corrections_are_constraints_and_resolve_keeps_them(labeled):
    layout, take, labeler, lab = labeled
    review = Review()
    per = lab.per_sample()
    frame = 200
    a, b = int(np.flatnonzero(per[frame] == 0)[0]), int(np.flatnonzero(per[frame] == 1)[0])
    review.swap(lab, 0, 1, frame)
    ghost = int(np.flatnonzero(per[frame] == 5)[0])
    review.unlabel(lab, ghost, frame)
    review.split(lab, b, frame + 50)
    assert len(review.constraints) == 3 and review.splits == [(b, frame + 50)]
    again = label_take(take, layout, corrections=Corrections(constraints=review.constraints, splits=review.splits),
                       labeler=labeler)
    after = again.per_sample()
    seg_a = (lab.slot == a) & (lab.start <= frame) & (lab.stop > frame)
    stop_a = int(lab.stop[seg_a][0])
    assert (after[frame:stop_a, a][take.valid[frame:stop_a, a]] == 1).all()
    assert (after[frame:, ghost][take.valid[frame:, ghost]][:10] == NULL).all()
    assert np.isin(changed_labels(lab, again), [0, 1, 5]).all() and {0, 1, 5} <= set(changed_labels(lab, again))
    assert again.locked.any() and (segment_classes(again)[again.locked] == LOCKED).all()
    # A newer correction replaces an older one on the same samples.
    review.assign(lab, a, frame, 3)
    assert [c.label for c in review.constraints if c.slot == a] == [3]
    back = Review.from_dict(review.to_dict())
    assert back.constraints == review.constraints and back.splits == review.splits


def test_lock_keeps_a_segment_and_errors_are_clear(labeled):
    _, _, _, lab = labeled
    review = Review()
    slot = int(lab.slot[0])
    c = review.lock(lab, slot, int(lab.start[0]))
    assert c == Constraint(slot, int(lab.start[0]), int(lab.stop[0]), int(lab.label[0]))
    empty_slot_frames = np.flatnonzero(lab.per_sample()[:, slot] < -1)
    if len(empty_slot_frames):
        with pytest.raises(ValueError, match="no sample"):
            review.unlabel(lab, slot, int(empty_slot_frames[0]))
    with pytest.raises(ValueError, match="already starts"):
        review.split(lab, slot, int(lab.start[0]))


def test_apply_constraints_changes_only_the_constrained_samples(labeled):
    from mocap_autolabel.core.review import apply_constraints, apply_split

    _, take, _, lab = labeled
    per = lab.per_sample()
    frame = 300
    slot = int(np.flatnonzero(per[frame] == 2)[0])
    seg = int(np.flatnonzero((lab.slot == slot) & (lab.start <= frame) & (lab.stop > frame))[0])
    stop = int(lab.stop[seg])
    c = Constraint(slot, frame, stop, 7)
    out = apply_constraints(lab, [c])
    expected = per.copy()
    block = expected[frame:stop]
    took = block == 7
    took[:, slot] = False
    block[took] = NULL
    block[:, slot] = np.where(block[:, slot] == -2, -2, 7)
    np.testing.assert_array_equal(out.per_sample(), expected)
    # The constrained samples are locked and sure; the samples that lost label 7 are very uncertain.
    conf = out.per_sample_confidence()
    valid = per[frame:stop, slot] != -2
    assert (conf[frame:stop, slot][valid] == 1.0).all()
    assert (conf[frame:stop][took] == 0.0).all()
    assert (segment_classes(out)[out.locked] == LOCKED).all() and out.locked.sum() >= 1
    # Elsewhere every sample keeps its label and confidence.
    same = np.ones_like(per, dtype=bool)
    same[frame:stop] = False
    np.testing.assert_array_equal(conf[same], lab.per_sample_confidence()[same])
    # A split cuts one segment in two and changes no label.
    cut = apply_split(lab, slot, frame)
    assert len(cut) == len(lab) + 1
    np.testing.assert_array_equal(cut.per_sample(), per)
    assert ((cut.slot == slot) & (cut.start == frame)).sum() == 1


def test_review_round_trips_through_flat_arrays(labeled):
    from mocap_autolabel.core.review import labeling_from_arrays, labeling_to_arrays

    _, _, _, lab = labeled
    review = Review([Constraint(1, 2, 30, 4), Constraint(3, 0, 9, NULL)], [(2, 17)])
    arrays = review.to_arrays()
    assert Review.from_arrays(arrays["constraints"], arrays["splits"]) == review
    assert Review.from_arrays([], []) == Review()
    back = labeling_from_arrays(labeling_to_arrays(lab))
    np.testing.assert_array_equal(back.per_sample(), lab.per_sample())
    np.testing.assert_array_equal(back.confidence, lab.confidence)


def test_a_newer_label_replaces_an_older_constraint_on_another_slot(labeled):
    _, _, _, lab = labeled
    review = Review()
    per = lab.per_sample()
    frame = 100
    s1, s2 = (int(np.flatnonzero(per[frame] == m)[0]) for m in (3, 4))
    first = review.assign(lab, s1, frame, 9)
    second = review.assign(lab, s2, frame, 9)
    # Two slots cannot both be label 9 in the same frames: the older constraint keeps only what
    # lies outside the newer one.
    for c in review.constraints:
        if c.slot == s1:
            assert c.stop <= second.start or c.start >= second.stop
    assert review.constraints[-1] == second and first.label == 9


def test_remembering_labeler_serves_both_hands_of_a_re_solve():
    """A two-hand take scores each hand's points on their own: a re-solve finds both remembered."""
    from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take

    layout = load_layout("han19")
    take = two_hand_take(layout, 200, seed=3, config=TwoHandConfig(close_share=0.0)).take
    inner = make_labeler("set", layout)
    calls = []

    class Counting:
        def __init__(self):
            self.layout, self.name = inner.layout, inner.name

        def scores(self, points, mask):
            calls.append(points.shape)
            return inner.scores(points, mask)

    labeler = RememberingLabeler(Counting())
    first = label_take(take, layout, LabelSettings(hand_count=2), labeler=labeler)
    assert len(calls) == 2
    again = label_take(take, layout, LabelSettings(hand_count=2, sides=first.info["hands"]["by_hand_order"]),
                       labeler=labeler)
    assert len(calls) == 2 and again.names == first.names
    np.testing.assert_array_equal(again.per_sample(), first.per_sample())


def test_labeling_again_keeps_two_hands_and_their_sides_unless_told():
    from mocap_autolabel.core.hands import relabel_plan

    layout = load_layout("han19")
    two = {"hands": {"count": 2, "sides": ["left", "right"], "by_hand_order": ["right", "left"],
                     "naming": "{Side}Hand:{name}"}}
    one = {"hands": {"count": 1}}
    options, names, changed = relabel_plan(two, layout)
    assert options == {"hand_count": 2, "sides": ["right", "left"], "naming": "{Side}Hand:{name}",
                       "hand_swaps": []}  # the hands traded places nowhere: not looked for again
    assert names[0] == "LeftHand:ThumbCMC" and names[19] == "RightHand:ThumbCMC" and not changed
    assert relabel_plan(two, layout, "2")[0] == options
    assert relabel_plan(two, layout, "1") == ({"hand_count": 1}, layout.names, True)
    assert relabel_plan(one, layout) == ({}, layout.names, False)  # found again, as the first time
    assert relabel_plan(one, layout, "2")[1][0] == "L_ThumbCMC" and relabel_plan(one, layout, "2")[2]
    assert relabel_plan(None, layout, "2") == ({"hand_count": 2}, relabel_plan(one, layout, "2")[1], False)
