"""The cleanup tools' edits of a labeling (core/cleanup_labels.py): suspects cut out and marked, short
fragments unlabeled, quick labeling; locked decisions never touched."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.cleanup_labels import (
    SUSPECT_CONFIDENCE,
    carriers,
    label_segment,
    mark_suspects,
    short_segments,
    to_slots,
    unlabel_segments,
)
from mocap_autolabel.core.labeling import EMPTY, NULL, segments_from_runs
from mocap_autolabel.core.review import DOUBTFUL, Review, apply_constraints, review_queue

NAMES = ["A", "B", "C"]


def _labeling(per: np.ndarray, confidence: float = 0.99):
    """A labeling of per-sample labels ``(F, P)`` (EMPTY: no sample), every segment at ``confidence``."""
    lab = segments_from_runs(NAMES, per, per != EMPTY, {})
    lab.confidence[:] = confidence
    return lab


def _take():
    """20 frames, 3 slots: A on slot 0 throughout; B on slot 1 for frames 0-3, then on slot 2 for 3-6
    (one run of 6 frames carried by two trajectories), slot 2 unlabeled from 8; slot 1 empty after 3."""
    per = np.full((20, 3), EMPTY, dtype=np.int64)
    per[:, 0] = 0
    per[0:3, 1] = 1
    per[3:6, 2] = 1
    per[8:20, 2] = NULL
    return _labeling(per)


def test_carriers_and_to_slots():
    lab = _take()
    car = carriers(lab)
    assert car.shape == (20, 3)
    assert (car[:, 0] == 0).all() and car[:3, 1].tolist() == [1, 1, 1] and car[3:6, 1].tolist() == [2, 2, 2]
    assert (car[6:, 1] == -1).all() and (car[:, 2] == -1).all()
    mask = np.zeros((20, 2), dtype=bool)
    mask[[2, 4, 10], 1] = True  # B at frames 2 and 4, and at 10 where nothing carries it
    frames, slots = to_slots(lab, mask, [0, 1])
    assert frames.tolist() == [2, 4] and slots.tolist() == [1, 2]


def test_mark_suspects_cuts_them_out_very_uncertain_for_the_queue():
    lab = _take()
    review = Review()
    suspect = np.zeros((20, 3), dtype=bool)
    suspect[5:7, 0] = True  # inside A's segment
    suspect[10, 2] = True  # an unlabeled sample: left alone
    out, marked = mark_suspects(lab, review, suspect)
    assert (marked.samples, marked.locked, marked.cuts) == (2, 0, 2)
    np.testing.assert_array_equal(out.per_sample(), lab.per_sample())  # no label changes
    a = np.flatnonzero(out.slot == 0)
    assert [(int(out.start[i]), int(out.stop[i])) for i in a] == [(0, 5), (5, 7), (7, 20)]
    assert out.confidence[a].tolist() == pytest.approx([0.99, SUSPECT_CONFIDENCE, 0.99])
    assert SUSPECT_CONFIDENCE < DOUBTFUL  # very uncertain: the review's strongest colour
    assert review.splits == [(0, 5), (0, 7)]
    assert a[1] in review_queue(out)
    # Marking again adds nothing.
    again, marked = mark_suspects(out, review, suspect)
    assert marked.cuts == 0 and review.splits == [(0, 5), (0, 7)] and len(again) == len(out)


def test_mark_suspects_at_a_segment_start_and_in_locked_segments():
    lab = _take()
    lab.locked[(lab.slot == 2) & (lab.label == 1)] = True  # B on slot 2 was decided by the reviewer
    review = Review()
    suspect = np.zeros((20, 3), dtype=bool)
    suspect[0, 0] = True  # the take's first sample: no cut before it
    suspect[3:5, 2] = True  # locked
    out, marked = mark_suspects(lab, review, suspect)
    assert (marked.samples, marked.locked, marked.cuts) == (1, 2, 1)
    assert review.splits == [(0, 1)]
    seg = np.flatnonzero((out.slot == 0) & (out.start == 0))[0]
    assert out.stop[seg] == 1 and out.confidence[seg] == SUSPECT_CONFIDENCE and not out.locked[seg]
    locked = np.flatnonzero(out.slot == 2)
    assert out.locked[locked[0]] and out.confidence[locked[0]] == pytest.approx(0.99)
    with pytest.raises(ValueError, match="frames, points"):
        mark_suspects(lab, review, suspect[:, :2])


def test_short_segments_count_a_labels_run_across_trajectories():
    lab = _take()
    segs, locked = short_segments(lab, 6, None)  # B's run is 6 frames: not shorter
    assert not len(segs) and not len(locked)
    segs, locked = short_segments(lab, 7, None)
    assert sorted((int(lab.slot[i]), int(lab.start[i])) for i in segs) == [(1, 0), (2, 3)]
    assert not len(short_segments(lab, 7, [0])[0])  # A alone asked: nothing
    lab.locked[segs[0]] = True
    segs2, locked = short_segments(lab, 7, None)
    assert len(segs2) == 1 and locked.tolist() == [segs[0]]
    review = Review()
    made = unlabel_segments(lab, review, segs2)
    assert [(c.slot, c.start, c.stop, c.label) for c in made] == [(2, 3, 6, NULL)] and review.constraints == made
    out = apply_constraints(lab, made)
    assert (out.per_sample()[3:6, 2] == NULL).all() and (out.per_sample()[0:3, 1] == 1).all()


def test_label_segment_takes_the_whole_segment():
    lab = _take()
    review = Review()
    c = label_segment(lab, review, 2, 15, 2)  # slot 2's unlabeled piece, from anywhere in it
    assert (c.slot, c.start, c.stop, c.label) == (2, 8, 20, 2) and review.constraints == [c]
    out = apply_constraints(lab, [c])
    assert (out.per_sample()[8:20, 2] == 2).all() and out.locked[(out.slot == 2) & (out.start == 8)].all()
    with pytest.raises(ValueError, match="no label number 3"):
        label_segment(lab, review, 2, 15, 3)
    with pytest.raises(ValueError, match="point slot 1 has no sample at frame 10"):
        label_segment(lab, review, 1, 10, 0)
