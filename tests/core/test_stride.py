"""Scoring every stride-th frame of a trajectory (core.temporal.stride)."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.labelers.base import FrameBatch
from mocap_autolabel.core.temporal.stride import stride_for, strided_scores
from mocap_autolabel.core.temporal.voting import Segments, split_segments
from mocap_autolabel.core.tracklets import mask_runs


def _batch(valid: np.ndarray) -> FrameBatch:
    """Each frame's valid slots packed in slot order; a point's x is its frame, y its slot."""
    frames, slots = valid.shape
    k = max(int(valid.sum(axis=1).max()), 1)
    points = np.zeros((frames, k, 3), dtype=np.float32)
    mask = np.zeros((frames, k), dtype=bool)
    slot_of = np.full((frames, k), -1, dtype=np.int64)
    for f in range(frames):
        s = np.flatnonzero(valid[f])
        points[f, :len(s), 0], points[f, :len(s), 1] = f, s
        mask[f, :len(s)], slot_of[f, :len(s)] = True, s
    return FrameBatch(points, mask, slot_of)


def _segments(valid: np.ndarray, cuts: dict[int, list[int]] | None = None) -> Segments:
    slot, start, stop = mask_runs(valid)
    return split_segments(Segments(slot.astype(np.int64), start.astype(np.int64), stop.astype(np.int64)), cuts or {})


class Recorder:
    """A labeler whose scores say which frame and slot they were computed on."""

    def __init__(self):
        self.rows = []

    def __call__(self, points, mask):
        self.rows.append(points.shape[0])
        out = np.zeros(points.shape[:2] + (2,), dtype=np.float32)
        out[..., 0], out[..., 1] = points[..., 0], points[..., 1]  # frame, slot
        return out


def _donors(valid, cuts=None, stride=3, every=None):
    batch, segments, rec = _batch(valid), _segments(valid, cuts), Recorder()
    out = strided_scores(rec, batch, segments, stride, every=every)
    f, k = np.nonzero(batch.mask)
    return batch, segments, rec, f, batch.slots[f, k], out[f, k, 0].astype(int), out[f, k, 1].astype(int)


def test_stride_one_scores_every_frame_once():
    valid = np.random.default_rng(0).random((50, 6)) < 0.7
    batch, rec = _batch(valid), Recorder()
    out = strided_scores(rec, batch, _segments(valid), 1)
    assert rec.rows == [50]
    np.testing.assert_array_equal(out, rec(batch.points, batch.mask))


def test_each_sample_takes_scores_of_its_own_trajectory_piece_within_the_stride():
    rng = np.random.default_rng(1)
    valid = rng.random((300, 12)) < 0.8
    cuts = {3: [40, 41, 170], 7: [101]}
    batch, segments, rec, f, slot, src_frame, src_slot = _donors(valid, cuts, stride=3)
    # Scores come from the same slot, a scored frame at most 2 frames away, in the same segment.
    np.testing.assert_array_equal(src_slot, slot)
    assert np.abs(src_frame - f).max() <= 2
    key = segments.slot * 1000 + segments.start
    piece = np.searchsorted(key, slot * 1000 + f, side="right")
    donor_piece = np.searchsorted(key, slot * 1000 + src_frame, side="right")
    np.testing.assert_array_equal(piece, donor_piece)
    # Fewer rows scored than frames: every third frame plus those of pieces that miss them.
    assert 100 <= rec.rows[0] < 300


def test_a_piece_between_scored_frames_is_scored_on_its_own_frame():
    valid = np.zeros((12, 3), dtype=bool)
    valid[:, 0] = True
    valid[4, 1] = True  # one frame, between the frames 3 and 6 that stride 3 scores
    valid[7:9, 2] = True
    _, _, rec, f, slot, src_frame, _ = _donors(valid, stride=3)
    np.testing.assert_array_equal(src_frame[slot == 1], [4])
    assert set(src_frame[slot == 2].tolist()) == {7}  # a piece of 7-8 has no frame of 0, 3, 6, 9: its first
    assert rec.rows == [6]  # frames 0, 3, 6, 9 and the pieces' own 4 and 7


def test_rows_asked_for_are_scored_whatever_the_stride():
    valid = np.ones((20, 2), dtype=bool)
    every = np.zeros(20, dtype=bool)
    every[10:15] = True
    _, _, _, f, _, src_frame, _ = _donors(valid, stride=4, every=every)
    inside = (f >= 10) & (f < 15)
    np.testing.assert_array_equal(src_frame[inside], f[inside])


@pytest.mark.parametrize("rate, stride", [(120.0, 4), (100.0, 3), (60.0, 2), (30.0, 1), (480.0, 16)])
def test_stride_follows_the_frame_rate(rate, stride):
    assert stride_for(rate) == stride


def test_label_take_scores_every_4th_frame_at_120_hz_and_labels_as_with_every_frame(han19):
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.settings import LabelSettings
    from mocap_autolabel.core.synth.generate import synthesize

    s = synthesize(han19, 1200, seed=3)
    assert s.take.rate == 120.0
    strided, every = label_take(s.take, han19), label_take(s.take, han19, LabelSettings(stride=1))
    assert (strided.info["stride"], every.info["stride"]) == (4, 1)
    valid = s.take.valid
    for lab in (strided, every):
        per = lab.per_sample()
        assert ((per == np.where(s.labels >= 0, s.labels, -1)) | ~valid).mean() > 0.995
    per_frame = label_take(s.take, han19, LabelSettings(temporal="none"))
    assert per_frame.info["stride"] == 1  # per-frame labels need every frame
