"""The review's Blender-free rules behind the operators (issue 33): the walk through uncertain
segments, corrections across layouts, overridden corrections, messages and labeling progress."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.labeling import NULL, Constraint, Labeling
from mocap_autolabel.core.review import (
    Review,
    describe,
    plural,
    remap_review,
    uncertain_segments,
    walk_uncertain,
)


def _labeling() -> Labeling:
    """Five uncertain segments, three of them starting on frame 10 (slots 0, 1, 3), one on frame 0
    (slot 2), one on frame 40 (slot 1); plus a confident and a locked one."""
    rows = [  # slot, start, stop, label, confidence, locked
        (0, 10, 30, 0, 0.6, False), (1, 10, 20, 1, 0.9, False), (1, 40, 60, 1, 0.3, False),
        (2, 0, 50, 2, 0.7, False), (3, 10, 15, 0, 0.2, False), (3, 20, 80, 2, 0.99, False),
        (2, 60, 70, 0, 0.1, True),
    ]
    rows.sort(key=lambda r: (r[0], r[1]))
    cols = list(zip(*rows, strict=True))
    return Labeling(names=["a", "b", "c"], n_frames=100, n_points=4, slot=np.array(cols[0]),
                    start=np.array(cols[1]), stop=np.array(cols[2]), label=np.array(cols[3], dtype=np.int16),
                    confidence=np.array(cols[4], dtype=np.float32), locked=np.array(cols[5]), info={})


def _walk(lab, frame, previous, sure=0.95):
    seen, current = [], None
    while (seg := walk_uncertain(lab, sure, frame, current, previous)) is not None:
        frame = int(lab.start[seg])
        current = (frame, int(lab.slot[seg]))
        seen.append(current)
        assert len(seen) < 20
    return seen


def test_the_walk_visits_every_uncertain_segment_once_in_time_order():
    lab = _labeling()
    expected = [(0, 2), (10, 0), (10, 1), (10, 3), (40, 1)]
    assert len(uncertain_segments(lab)) == len(expected)
    assert _walk(lab, 0, previous=False) == expected  # the segment starting on the current frame included
    assert _walk(lab, 99, previous=True) == expected[::-1]
    # Moved away from the walk (current no longer at the frame): start from the frame itself.
    seg = walk_uncertain(lab, 0.95, 10, current=(0, 2), previous=False)
    assert (int(lab.start[seg]), int(lab.slot[seg])) == (10, 0)
    assert walk_uncertain(lab, 0.95, 41, None, previous=False) is None
    # A higher threshold brings the 0.99 segment in; a locked one never is.
    assert _walk(lab, 0, previous=False, sure=0.999) == expected[:4] + [(20, 3), (40, 1)]


def test_corrections_follow_a_new_layout_by_name_or_are_returned_as_dropped():
    review = Review([Constraint(0, 0, 10, 1), Constraint(1, 5, 9, NULL), Constraint(2, 0, 4, 0)], [(3, 7)])
    kept, dropped = remap_review(review, ["ThumbTip", "IndexTip"], ["index_tip", "IndexTip"])
    assert kept.constraints == [Constraint(0, 0, 10, 1), Constraint(1, 5, 9, NULL)]
    assert kept.splits == [(3, 7)] and dropped == [Constraint(2, 0, 4, 0)]
    assert review.constraints[2] == Constraint(2, 0, 4, 0)  # the original is left as it was


def test_overridden_corrections_and_removal():
    review = Review()
    lock = Constraint(0, 50, 120, 3)
    review.constraints = [lock, Constraint(4, 0, 10, 5)]
    ghost = Constraint(0, 10, 120, NULL)
    assert review.overridden_by(ghost) == [lock]
    assert review.overridden_by(Constraint(0, 60, 70, 3)) == []  # the same decision
    assert review.overridden_by(Constraint(7, 60, 70, 3)) == [lock]  # its label given elsewhere
    assert review.overridden_by(Constraint(0, 0, 50, 1)) == []  # no overlap
    assert review.remove_at(0, 60) == [lock] and len(review.constraints) == 1
    assert review.remove(0) == Constraint(4, 0, 10, 5)
    with pytest.raises(ValueError, match="no correction number 1"):
        review.remove(0)


def test_messages_and_progress():
    assert plural(1, "correction") == "1 correction" and plural(2, "correction") == "2 corrections"
    assert plural(3, "trajectory", "trajectories") == "3 trajectories"
    c = Constraint(3, 99, 1200, 0)
    assert describe(c, ["ThumbTip"], ["*0", "*1", "*2", "*3"], first=1) == "ThumbTip on *3, frames 100-1200"
    assert describe(Constraint(1, 0, 5, NULL), ["x"], ["*0", "pillow_top"]) == "unlabeled on pillow_top, frames 0-4"


def test_label_take_reports_progress_as_message_and_share(han19):
    """The core's one progress protocol: each call gives a message and the share done, which never
    goes back and ends at 1."""
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.synth.generate import synthesize

    take = synthesize(han19, frames=120, seed=3).take
    heard: list[tuple[str, float]] = []
    label_take(take, han19, progress=lambda message, share: heard.append((message, share)))
    messages, shares = [m for m, _ in heard], [s for _, s in heard]
    assert messages[0] == "finding hands" and any(m.startswith("scoring") for m in messages)
    assert shares == sorted(shares) and shares[-1] == 1.0
