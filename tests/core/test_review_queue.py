"""Issue 48: the review queue ranks what a reviewer should look at. Labeled segments in doubt first, then
unlabeled pieces long enough to matter (or continuing a doubtful label, or close to where a marker the
labeling lacks should be, or more likely a marker than not); short ghosts the vote is fairly sure of stay out
of the list, the walk, the Timeline's marks, the report and the key colours; the filters; the distance to a
missing marker, kept through edits and storage (old states without it rank as before); and, on real
labelings against their truth, what the queue holds."""

from __future__ import annotations

import os

import numpy as np
import pytest
from mocap_autolabel.core.labeling import NULL, Constraint, Labeling, segments_from_runs
from mocap_autolabel.core.layout import Layout, Marker
from mocap_autolabel.core.metrics import segments_right
from mocap_autolabel.core.review import (
    CONFIDENT,
    QUEUE_MIN_FRAMES,
    QUEUE_NEAR_MM,
    THUMB_SLACK_MM,
    UNCERTAIN,
    VERY_UNCERTAIN,
    apply_constraints,
    apply_split,
    frame_trouble,
    labeling_from_arrays,
    labeling_to_arrays,
    marker_slack,
    missing_marker_distance,
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


def _hidden_marker_take(names=("a", "b")):
    """30 frames at 100 Hz, two markers of one hand moving together along x (1 mm per frame) plus a jump
    of +50 mm in y from frame 10 on; marker "a" (slot 0) is hidden in frames 10-19, marker "b" (slot 1) is
    seen throughout (labeled "b" where ``names`` has it). Slot 2: a point for 2 frames (14-15) where "a"
    should be (moved with "b"); slot 3: a point for 2 frames far from it; slot 4: a point at "a"'s place in
    frames 3-4, where "a" is seen (carried)."""
    frames, slots = 30, 5
    pos = np.full((frames, slots, 3), np.nan)
    t = np.arange(frames) * 0.001
    jump = np.where(np.arange(frames) >= 10, 0.05, 0.0)
    a = np.stack([t, jump, np.zeros(frames)], axis=1)
    b = a + [0.02, 0.0, 0.0]
    pos[:, 1] = b
    pos[:10, 0], pos[20:, 0] = a[:10], a[20:]
    pos[14:16, 2] = a[14:16] + [0.002, 0.0, 0.0]  # 2 mm off where "a" should be
    pos[14:16, 3] = a[14:16] + [0.0, 0.0, 0.08]  # 8 cm away
    pos[3:5, 4] = a[3:5] + [0.0, 0.001, 0.0]  # next to "a", which is seen there
    valid = ~np.isnan(pos[..., 0])
    labels = np.full((frames, slots), NULL)
    labels[:, 0] = 0
    if len(names) > 1:
        labels[:, 1] = 1
    lab = segments_from_runs(list(names), labels, valid, {})
    lab.confidence[:] = 0.949
    return lab, pos


def _seg(lab, slot):
    return int(np.flatnonzero(lab.slot == slot)[0])


def test_a_point_where_a_hidden_marker_should_be_is_close_to_it_and_a_ghost_is_not():
    lab, pos = _hidden_marker_take()
    mm = missing_marker_distance(lab, pos, hand_size=2, rate=100.0)
    # "a" is missing in frames 10-19: followed from frame 9 and 20 as "b" moved (the jump in y included).
    assert 0 <= mm[_seg(lab, 2)] <= 3
    assert mm[_seg(lab, 3)] >= 75  # a ghost far from it
    assert mm[_seg(lab, 4)] == -1  # "a" is carried by slot 0 there: no marker is missing
    assert (mm[lab.label >= 0] == -1).all()
    # Without "b" to follow, the jump is not seen: where "a" should be is blended from its last and next
    # positions (at frame 14, under half the 50 mm jump).
    alone, _ = _hidden_marker_take(names=("a",))
    assert missing_marker_distance(alone, pos, hand_size=1, rate=100.0)[_seg(alone, 2)] >= 20
    # A marker not seen within the window: nothing to measure against.
    assert missing_marker_distance(lab, pos, hand_size=2, rate=100.0, window_s=0.02)[_seg(lab, 2)] == -1
    np.testing.assert_array_equal(mm, missing_marker_distance(lab, pos, hand_size=2, rate=100.0))  # same again


def test_a_short_unlabeled_piece_near_a_missing_marker_is_queued_a_ghost_is_not():
    lab, pos = _hidden_marker_take()
    assert not set(review_queue(lab).tolist()) & {_seg(lab, s) for s in (2, 3, 4)}  # not known: as before
    lab.missing_mm = missing_marker_distance(lab, pos, hand_size=2, rate=100.0)
    queue = review_queue(lab).tolist()
    assert _seg(lab, 2) in queue  # a 2-frame piece where the hidden "a" should be
    assert _seg(lab, 3) not in queue and _seg(lab, 4) not in queue  # far from it; where "a" is carried
    assert queue.index(_seg(lab, 2)) > max(queue.index(i) for i in np.flatnonzero(lab.label >= 0))
    assert _seg(lab, 2) not in review_queue(lab, near_mm=-1)  # the rule off
    assert _seg(lab, 2) not in review_queue(lab, labeled_only=True)
    assert null_classes(lab)[14, 2] == UNCERTAIN and null_classes(lab)[14, 3] == CONFIDENT
    # The report's entries carry the distance and rank the same; an old report without it, as before.
    summary = lab.summary(0.95)["uncertain_segments"]
    assert [(e["slot"], e["start"]) for e in queue_entries(summary)] == \
        [(int(lab.slot[i]), int(lab.start[i])) for i in review_queue(lab)]
    old = [{k: v for k, v in e.items() if k != "missing_mm"} for e in summary]
    assert [(e["slot"], e["start"]) for e in queue_entries(old)] == \
        [(int(lab.slot[i]), int(lab.start[i])) for i in review_queue(lab, near_mm=-1)]


def test_the_distance_survives_storage_edits_and_old_states_load_without_it():
    lab, pos = _hidden_marker_take()
    lab.missing_mm = missing_marker_distance(lab, pos, hand_size=2, rate=100.0)
    back = labeling_from_arrays(labeling_to_arrays(lab))
    np.testing.assert_array_equal(back.missing_mm, lab.missing_mm)
    assert review_queue(back).tolist() == review_queue(lab).tolist()
    # As a .blend stores it: every array as a list of int64 (confidence as float64).
    stored = {k: (np.asarray(v, dtype=np.float64 if k == "confidence" else np.int64).tolist()
                  if isinstance(v, np.ndarray) else v) for k, v in labeling_to_arrays(lab).items()}
    np.testing.assert_array_equal(labeling_from_arrays(stored).missing_mm, lab.missing_mm)
    # An old state (stored before the distance was recorded) loads, not knowing it: the queue as before.
    old = {k: v for k, v in stored.items() if k != "missing_mm"}
    loaded = labeling_from_arrays(old)
    assert loaded.missing_mm is None and "missing_mm" not in labeling_to_arrays(loaded)
    assert review_queue(loaded).tolist() == review_queue(lab, near_mm=-1).tolist()
    assert labeling_from_arrays({**stored, "missing_mm": [1, 2]}).missing_mm is None  # another length: unknown
    # Edits keep it where the samples were not edited: a split, a correction elsewhere, a hand's labels.
    split = apply_split(lab, 2, 15)
    assert split.missing_mm[(split.slot == 2)].tolist() == [lab.missing_mm[_seg(lab, 2)]] * 2
    edited = apply_constraints(lab, [Constraint(3, 14, 16, 0)])
    assert edited.missing_mm[_seg(edited, 2)] == lab.missing_mm[_seg(lab, 2)]
    assert (edited.missing_mm[edited.slot == 3] == -1).all()  # now labeled, locked
    part = lab.label_range(1, 2)
    assert part.missing_mm is not None and len(part.missing_mm) == len(part)


@pytest.fixture(scope="module")
def demo():
    from mocap_autolabel.core.layout import load_layout
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.synth.truth import load_truth, truth_path
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


def test_two_hand_takes_queue_every_wrong_segment_in_doubt_and_mostly_what_matters(han19):
    """Two interacting synthetic hands (as benchmarks/two_hands.py): every wrong segment in doubt is queued,
    the short unlabeled pieces among them (markers seen again for a frame or two in their gaps) for lying
    where their marker should be, and nearly every entry is labeled, an unlabeled piece of at least 10 frames
    or an error."""
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.synth.two_hands import two_hand_take

    two = two_hand_take(han19, 600, seed=1)
    lab = label_take(two.take, han19)
    assert lab.missing_mm is not None and lab.missing_mm.shape == lab.label.shape
    queue = review_queue(lab)
    wrong = ~segments_right(lab, two.labels, two.take.valid)
    in_doubt = np.flatnonzero(wrong & (lab.confidence < 0.95) & ~lab.locked)
    assert np.isin(in_doubt, queue).all()
    short = in_doubt[(lab.label[in_doubt] < 0) & (lab.length[in_doubt] < QUEUE_MIN_FRAMES)]
    assert len(short) and (lab.missing_mm[short] <= QUEUE_NEAR_MM).all()
    assert not np.isin(short, review_queue(lab, near_mm=-1)).any()  # the rule is what brings them in
    # Here 3 of the 4 short pieces it brings in are those errors: on a take this small they alone take the
    # share of labeled or long entries to 89 % (the bar holds over the benchmark's sets: benchmarks/review.py).
    assert len(queue) < len(uncertain_segments(lab)) and _share_worth_a_look(lab, queue) >= 0.85
    worth = (lab.label[queue] >= 0) | (lab.length[queue] >= QUEUE_MIN_FRAMES) | wrong[queue]
    assert worth.mean() >= 0.95


def test_a_thumb_marker_is_given_more_room_than_the_others():
    lab, pos = _hidden_marker_take()
    pos = pos.copy()
    pos[14:16, 2] += [0.028, 0.0, 0.0]  # the piece 30 mm off where the hidden "a" should be
    plain = missing_marker_distance(lab, pos, hand_size=2, rate=100.0)[_seg(lab, 2)]
    assert QUEUE_NEAR_MM < plain <= QUEUE_NEAR_MM + THUMB_SLACK_MM
    thumb = Layout("t", (Marker("a", "thumb_dist"), Marker("b", "index_dist")))
    slack = marker_slack(thumb)
    np.testing.assert_array_equal(slack, [THUMB_SLACK_MM, 0.0])
    given = missing_marker_distance(lab, pos, hand_size=2, rate=100.0, slack_mm=slack)[_seg(lab, 2)]
    assert given == plain - THUMB_SLACK_MM
    lab.missing_mm = missing_marker_distance(lab, pos, hand_size=2, rate=100.0)
    assert _seg(lab, 2) not in review_queue(lab)  # as far from a finger marker: not queued
    lab.missing_mm = missing_marker_distance(lab, pos, hand_size=2, rate=100.0, slack_mm=slack)
    assert _seg(lab, 2) in review_queue(lab)  # from a thumb marker: queued
