"""Issue 48: the review queue ranks what a reviewer should look at. Labeled segments in doubt first, then
unlabeled pieces long enough to matter (or continuing a doubtful label, or more likely a marker than not);
short ghosts the vote is fairly sure of stay out of the list, the walk, the Timeline's marks, the report and
the key colours; the filters; and, on real labelings against their truth, what the queue holds."""

from __future__ import annotations

import os

import numpy as np
import pytest
from mocap_autolabel.core.labeling import NULL, Labeling
from mocap_autolabel.core.metrics import segments_right
from mocap_autolabel.core.review import (
    CONFIDENT,
    QUEUE_MIN_FRAMES,
    UNCERTAIN,
    VERY_UNCERTAIN,
    frame_trouble,
    null_classes,
    queue_entries,
    review_queue,
    uncertain_segments,
    walk_uncertain,
)

DEMO = os.path.join(os.path.dirname(__file__), "..", "..", "samples", "demo_take.c3d")


def _labeling() -> tuple[Labeling, dict[str, int]]:
    """Segments named by what they are (slot, start, stop, label, confidence, locked)."""
    rows = {
        "label 0.949 long": (0, 0, 120, 0, 0.949, False),
        "label 0.949 short": (1, 0, 3, 1, 0.949, False),
        "label 0.80": (2, 0, 40, 2, 0.80, False),
        "label sure": (3, 0, 100, 3, 0.99, False),
        "label locked": (4, 0, 50, 1, 0.2, True),
        "ghost 2 frames": (5, 10, 12, NULL, 0.949, False),
        "ghost 9 frames": (5, 20, 29, NULL, 0.945, False),
        "ghost 10 frames": (5, 40, 50, NULL, 0.949, False),
        "ghost 30 frames": (6, 0, 30, NULL, 0.949, False),
        "ghost 20 frames, less sure": (6, 50, 70, NULL, 0.90, False),
        "ghost 1 frame after a doubtful label": (1, 3, 4, NULL, 0.949, False),
        "ghost 3 frames, likely a marker": (7, 60, 63, NULL, 0.3, False),
        "ghost sure": (7, 0, 5, NULL, 0.99, False),
        "ghost 4 frames after a sure label": (3, 100, 104, NULL, 0.949, False),
    }
    order = sorted(rows, key=lambda k: rows[k][:2])
    cols = list(zip(*(rows[k] for k in order), strict=True))
    lab = Labeling(names=["a", "b", "c", "d"], n_frames=130, n_points=8, slot=np.array(cols[0]),
                   start=np.array(cols[1]), stop=np.array(cols[2]), label=np.array(cols[3], dtype=np.int16),
                   confidence=np.array(cols[4], dtype=np.float32), locked=np.array(cols[5]), info={})
    return lab, {name: order.index(name) for name in rows}


def _names(lab, index, queue) -> list[str]:
    back = {i: name for name, i in index.items()}
    return [back[int(i)] for i in queue]


def test_labeled_segments_in_doubt_come_first_then_unlabeled_pieces_that_may_be_a_marker():
    lab, index = _labeling()
    assert _names(lab, index, review_queue(lab)) == [
        "label 0.80", "label 0.949 short", "label 0.949 long",  # least confident, then shortest
        "ghost 1 frame after a doubtful label",  # continues "label 0.949 short" on its trajectory
        "ghost 3 frames, likely a marker",  # then least sure it is no marker
        "ghost 20 frames, less sure",
        "ghost 30 frames", "ghost 10 frames",  # then the longest
    ]
    # Left out: locked and sure segments, and the short ghosts that continue no doubtful label.
    left = set(_names(lab, index, uncertain_segments(lab))) - set(_names(lab, index, review_queue(lab)))
    assert left == {"ghost 2 frames", "ghost 9 frames", "ghost 4 frames after a sure label"}


def test_the_filters_labeled_only_and_the_shortest_unlabeled_piece():
    lab, index = _labeling()
    assert _names(lab, index, review_queue(lab, labeled_only=True)) == [
        "label 0.80", "label 0.949 short", "label 0.949 long"]
    every = review_queue(lab, min_frames=1)
    assert sorted(every.tolist()) == sorted(uncertain_segments(lab).tolist())  # from 1 frame: the old list
    assert "ghost 10 frames" not in _names(lab, index, review_queue(lab, min_frames=25))
    assert "ghost 30 frames" in _names(lab, index, review_queue(lab, min_frames=25))
    # A higher Confident at brings the sure label and ghost in (the ghost is 5 frames: still left out).
    assert _names(lab, index, review_queue(lab, 0.999))[3] == "label sure"
    assert "ghost sure" not in _names(lab, index, review_queue(lab, 0.999))


def test_walk_trouble_and_colours_follow_the_queue():
    lab, index = _labeling()
    queue = review_queue(lab)
    seen, frame, current = [], 0, None
    while (seg := walk_uncertain(lab, 0.95, frame, current)) is not None:
        frame, current = int(lab.start[seg]), (int(lab.start[seg]), int(lab.slot[seg]))
        seen.append(seg)
    assert sorted(seen) == sorted(queue.tolist())
    assert [lab.start[s] for s in seen] == sorted(lab.start[s] for s in seen)
    labeled = walk_uncertain(lab, 0.95, 0, None, labeled_only=True)
    assert lab.label[labeled] >= 0
    # The Timeline's count of samples to review: the queue's samples alone.
    uncertain, _ = frame_trouble(lab, 0.95)
    assert uncertain[11] == 3  # two doubtful labels and "ghost 30 frames"; not "ghost 2 frames" (10-11)
    assert frame_trouble(lab, 0.95, min_frames=1)[0][11] == 4
    # Keys of unlabeled empties: a ghost left out is not shown as uncertain; one in the queue is.
    classes = null_classes(lab)
    assert classes[10, 5] == CONFIDENT and classes[45, 5] == UNCERTAIN and classes[61, 7] == VERY_UNCERTAIN
    assert classes[3, 1] == UNCERTAIN and classes[0, 0] == -1  # a labeled sample is not a null's


def test_a_reports_uncertain_segments_rank_as_the_labeling_does():
    lab, index = _labeling()
    summary = lab.summary(0.95, first_frame=1)
    entries = queue_entries(summary["uncertain_segments"])
    assert [(e["slot"], e["start"]) for e in entries] == [(int(lab.slot[i]), int(lab.start[i]))
                                                          for i in review_queue(lab)]
    assert len(queue_entries(summary["uncertain_segments"], labeled_only=True)) == 3
    assert queue_entries([]) == []


@pytest.fixture(scope="module")
def demo():
    from mocap_autolabel.core.layout import load_layout
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.synth.generate import load_truth, truth_path
    from mocap_autolabel.core.take import read_take

    take = read_take(DEMO)
    return take, load_truth(truth_path(DEMO))["labels"], label_take(take, load_layout("han19"))


def _share_worth_a_look(lab, queue) -> float:
    return float(((lab.label[queue] >= 0) | (lab.length[queue] >= QUEUE_MIN_FRAMES)).mean())


def test_the_demo_takes_queue_is_short_and_holds_its_error(demo):
    """The demo take: 77 uncertain segments, 67 of them unlabeled ghosts mostly 1-5 frames long. The queue
    is its labeled segments in doubt and a few long unlabeled pieces, the one wrong segment among the first."""
    take, truth, lab = demo
    queue = review_queue(lab)
    wrong = np.flatnonzero(~segments_right(lab, truth, take.valid))
    assert len(wrong) >= 1 and np.isin(wrong, queue).all()
    assert np.flatnonzero(np.isin(queue, wrong)).max() < 10  # among the labeled segments, at the top
    assert len(queue) <= len(uncertain_segments(lab)) // 3 and _share_worth_a_look(lab, queue) >= 0.9
    # The report's entries are the same queue, in the same order.
    from mocap_autolabel.core.labeling import unlabeled_point_names

    summary = lab.summary(0.95, take.first_frame, unlabeled_point_names(take.names, lab.names))
    assert [(e["slot"], e["start"]) for e in queue_entries(summary["uncertain_segments"])] == \
        [(int(lab.slot[i]), int(lab.start[i])) for i in queue]


def test_two_hand_takes_queue_every_doubtful_label_and_mostly_what_matters(han19):
    """Two interacting synthetic hands (as benchmarks/two_hands.py): every wrong labeled segment in doubt is
    queued, and at least 90 % of the entries are labeled or unlabeled pieces of at least 10 frames."""
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.synth.two_hands import two_hand_take

    two = two_hand_take(han19, 600, seed=1)
    lab = label_take(two.take, han19)
    queue = review_queue(lab)
    wrong = ~segments_right(lab, two.labels, two.take.valid)
    doubtful_labels = np.flatnonzero(wrong & (lab.label >= 0) & (lab.confidence < 0.95))
    assert np.isin(doubtful_labels, queue).all()
    assert len(queue) < len(uncertain_segments(lab)) and _share_worth_a_look(lab, queue) >= 0.9
