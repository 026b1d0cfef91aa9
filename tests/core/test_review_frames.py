"""Issue 33 (core side): unlabeled point names, uncertain segments counted one way, bad-frame runs."""

from __future__ import annotations

import numpy as np
from mocap_autolabel.core.labeling import NULL, labeled_take, segments_from_runs, unlabeled_point_names
from mocap_autolabel.core.review import bad_runs, frame_trouble, uncertain_segments
from mocap_autolabel.core.take import Take


def test_unlabeled_points_keep_file_names_else_their_slot():
    names = ["*7", "right_elbow", "", "IndexTip", "pillow", "pillow"]
    assert unlabeled_point_names(names, ["IndexTip", "ThumbTip"]) == \
        ["*0", "right_elbow", "*2", "*3", "pillow", "*5"]


def _labeling():
    # 10 frames, 3 slots: slot 0 is label 0 throughout; slot 1 label 1 in frames 0-3, missing 4-5, label 1
    # again 6-9; slot 2 an unlabeled trajectory in frames 2-4.
    per = np.full((10, 3), -2, dtype=np.int64)
    per[:, 0] = 0
    per[0:4, 1] = 1
    per[6:10, 1] = 1
    per[2:5, 2] = NULL
    lab = segments_from_runs(["A", "B"], per, per != -2, {})
    lab.confidence[:] = 0.99
    lab.confidence[(lab.slot == 2)] = 0.4  # an uncertain unlabeled segment
    return lab


def test_uncertain_unlabeled_segments_count_in_the_summary_and_the_review_alike():
    lab = _labeling()
    summary = lab.summary(0.95, first_frame=101, points=["*0", "*1", "right_elbow"])
    assert len(summary["uncertain_segments"]) == len(uncertain_segments(lab, 0.95)) == 1
    seg = summary["uncertain_segments"][0]
    assert (seg["point"], seg["label"], seg["frame_start"], seg["frame_end"]) == ("right_elbow", None, 103, 105)


def test_bad_runs_mark_uncertain_samples_and_gaps_inside_a_labels_span():
    lab = _labeling()
    uncertain, missing = frame_trouble(lab, 0.95)
    assert uncertain.tolist() == [0, 0, 1, 1, 1, 0, 0, 0, 0, 0]
    assert missing.tolist() == [0, 0, 0, 0, 1, 1, 0, 0, 0, 0]
    runs = bad_runs(lab, 0.95)
    assert [(r.start, r.stop, r.uncertain, r.missing, r.score) for r in runs] == [(2, 6, 1, 1, 5)]


def test_labeled_take_names_unlabeled_points_as_the_scene_does():
    lab = _labeling()
    pos = np.zeros((10, 3, 3), dtype=np.float32)
    pos[lab.per_sample() == -2] = np.nan
    take = Take(positions=pos, names=["*0", "*1", "right_elbow"], rate=100.0)
    out = labeled_take(take, lab)
    assert out.names == ["A", "B", "right_elbow"]
