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
    again = label_take(take, layout, constraints=review.constraints, splits=review.splits, labeler=labeler)
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
