"""The labeler protocol, the shared assignment step, metrics, Murty, gmm and nearest (no models needed)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from mocap_autolabel.core.labelers import NULL, assign, make_labeler, pack_frames
from mocap_autolabel.core.labelers.assign import assign_frame
from mocap_autolabel.core.labelers.gmm import GmmLabeler
from mocap_autolabel.core.labelers.inputs import depth_image, pca_slots
from mocap_autolabel.core.labelers.nearest import NearestLabeler, digit_chains
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.metrics import clustered_se, data_set_stats, score_labeling
from mocap_autolabel.core.rotations import random_rotations
from mocap_autolabel.core.synth.frames import FrameConfig, sample_frames
from mocap_autolabel.core.synth.generate import clean_config, synthesize
from mocap_autolabel.core.temporal.murty import murty, nbest_labelings


def test_pack_frames_left_packs_and_keeps_slots():
    pos = np.full((2, 4, 3), np.nan, dtype=np.float32)
    pos[0, 1] = 1.0
    pos[0, 3] = 3.0
    pos[1, 0] = 0.5
    b = pack_frames(pos)
    assert b.points.shape == (2, 2, 3)
    assert b.mask.tolist() == [[True, True], [True, False]]
    assert b.slots.tolist() == [[1, 3], [0, -1]]
    assert b.points[0, 1, 0] == 3.0 and b.points[1, 1, 0] == 0.0


def test_pack_frames_max_points_keeps_points_near_the_median():
    pos = np.zeros((1, 5, 3), dtype=np.float32)
    pos[0, :, 0] = [0.0, 0.01, 0.02, 5.0, 0.03]
    b = pack_frames(pos, max_points=3)
    assert sorted(b.slots[0].tolist()) == [0, 1, 2] or sorted(b.slots[0].tolist()) == [1, 2, 4]
    assert 3 not in b.slots[0]


def _brute_force(scores: np.ndarray) -> float:
    """Best total score over every one-to-one labeling with null allowed."""
    k, m1 = scores.shape
    best = -np.inf
    options = list(range(m1 - 1)) + [NULL]
    for labels in itertools.product(options, repeat=k):
        real = [x for x in labels if x != NULL]
        if len(real) != len(set(real)):
            continue
        best = max(best, sum(scores[i, x] for i, x in enumerate(labels)))
    return best


def test_assign_frame_is_optimal():
    rng = np.random.default_rng(3)
    for _ in range(40):
        k, m = int(rng.integers(1, 5)), int(rng.integers(1, 4))
        scores = rng.normal(size=(k, m + 1))
        labels = assign_frame(scores)
        got = sum(scores[i, x] if x != NULL else scores[i, m] for i, x in enumerate(labels))
        assert got == pytest.approx(_brute_force(scores))


def test_assign_resolves_conflicts_and_reports_confidence():
    # Both observations prefer label 0; the second prefers it less, so it takes label 1.
    scores = np.log(np.array([[[0.9, 0.05, 0.05], [0.6, 0.35, 0.05], [0.1, 0.1, 0.8]]]))
    mask = np.array([[True, True, False]])
    labels, conf = assign(scores, mask)
    assert labels.tolist() == [[0, 1, NULL]]
    assert conf[0, 0] == pytest.approx(0.9) and conf[0, 1] == pytest.approx(0.35) and conf[0, 2] == 0.0


def test_metrics_count_each_kind_of_error():
    # 1 frame, 3 labels, observations: 0 -> label 0 (right), 1 -> true label 1 given label 2 (erroneous
    # for 2? no: label 2 is truly missing -> false marker), 2 -> ghost given label 1 (erroneous).
    truth = np.array([[0, 1, -1]])
    pred = np.array([[0, 2, 1]])
    mask = np.ones((1, 3), dtype=bool)
    s = score_labeling(pred, truth, mask, 3)
    assert (s.instances, s.correct, s.erroneous, s.false_marker, s.false_occlusion) == (3, 1, 1, 1, 0)
    s = score_labeling(np.array([[0, -1, -1]]), truth, mask, 3)
    assert (s.correct, s.false_occlusion, s.ghost_recall, s.ghost_precision) == (2, 1, 1.0, 0.5)
    assert s.frames_all_correct == 0


def test_data_set_stats_counts_inner_gaps_only():
    present = np.array([[1, 0], [0, 0], [1, 1], [1, 1]], dtype=bool)
    st = data_set_stats(present)
    assert st["gaps"] == 1 and st["mean_gap_frames"] == 1.0 and st["tracklets"] == 3


def test_murty_matches_enumeration():
    rng = np.random.default_rng(0)
    for _ in range(60):
        r = int(rng.integers(1, 5))
        c = r + int(rng.integers(0, 3))
        cost = rng.random((r, c))
        every = sorted(sum(cost[i, p[i]] for i in range(r)) for p in itertools.permutations(range(c), r))
        assert np.allclose([t for t, _ in murty(cost, 8)], every[:8])


def test_nbest_labelings_first_is_the_assignment():
    rng = np.random.default_rng(1)
    scores = rng.normal(size=(4, 4))
    best = nbest_labelings(scores, 5)
    assert len(best) == 5 and all(a[0] >= b[0] for a, b in zip(best, best[1:]))
    assert best[0][1].tolist() == assign_frame(scores).tolist()


def test_pca_slots_are_rotation_invariant():
    cfg = FrameConfig(ghosts=(0, 0), distractor_share=0)
    fr = sample_frames(load_layout("han19"), 64, np.random.default_rng(2), cfg)
    rot = random_rotations(np.random.default_rng(3), 64)
    turned = (rot[:, None] @ fr.points[..., None].astype(np.float64))[..., 0] + 0.3
    a, ia = pca_slots(fr.points.astype(np.float64), fr.mask, 22)
    b, ib = pca_slots(turned, fr.mask, 22)
    assert (ia == ib).all()
    assert np.allclose(a, b, atol=1e-4)
    assert ((a >= 0) & (a <= 1)).all()


def test_depth_image_marks_each_observation():
    fr = sample_frames(load_layout("han19"), 16, np.random.default_rng(4))
    image, centre, rot, scale = depth_image(fr.points.astype(np.float64), fr.mask)
    assert image.shape == (16, 1, 52, 52)
    occupied = image[image > 0]
    assert occupied.min() >= 0.1 - 1e-6 and occupied.max() <= 1.0 + 1e-6
    assert ((image > 0).sum(axis=(1, 2, 3)) <= fr.mask.sum(axis=1)).all()
    assert np.allclose(rot @ np.swapaxes(rot, 1, 2), np.eye(3), atol=1e-9)


def test_digit_chains_run_proximal_to_distal():
    layout = load_layout("han19")
    parent, child = digit_chains(layout)
    names = layout.names
    assert names[parent[names.index("IndexTip")]] == "IndexPIP"
    assert names[child[names.index("IndexMCP")]] == "IndexPIP"
    assert parent[names.index("BackHand1")] == -1


@pytest.fixture(scope="module")
def clean_take():
    return synthesize(load_layout("glove13"), 900, seed=5, config=clean_config())


def test_gmm_labels_its_subject(clean_take):
    layout = clean_take.layout
    # Fitted on every other frame (the range of motion), scored on the frames between.
    labeler = GmmLabeler(layout).fit(clean_take.markers[::2])
    assert sorted(layout.names[i] for i in labeler.rigid) == ["hand_left", "hand_right", "hand_top"]
    held = clean_take.markers[1::2]
    b = pack_frames(held)
    labels, _ = labeler.label(b)
    s = score_labeling(labels, np.where(b.mask, b.slots, -2), b.mask, len(layout))
    assert s.accuracy > 0.9
    with pytest.raises(RuntimeError):
        GmmLabeler(layout).scores(b.points, b.mask)


def test_nearest_tracks_from_the_first_frame_and_restarts_at_fallbacks(clean_take):
    layout = clean_take.layout
    markers = clean_take.markers[:300]
    b = pack_frames(markers)
    truth = np.where(b.mask, b.slots, -2)
    labels, _ = make_labeler("nearest", layout, start=markers[0]).label(b)
    assert score_labeling(labels, truth, b.mask, len(layout)).accuracy == 1.0
    # A wrong start (two labels swapped) stays wrong until a fallback frame restarts the tracker.
    wrong = markers[0].copy()
    wrong[[3, 4]] = wrong[[4, 3]]
    labels, _ = NearestLabeler(layout, start=wrong, fallback={100: markers[100]}).label(b)
    per_frame = (labels == truth).all(axis=1)
    assert not per_frame[:100].any() and per_frame[100:].all()
    with pytest.raises(ValueError, match="first frame"):
        NearestLabeler(layout).scores(b.points, b.mask)


def test_make_labeler_rejects_unknown_methods():
    with pytest.raises(ValueError, match="choose one of set, perm"):
        make_labeler("magic", load_layout("han19"))


def test_clustered_se_counts_takes_not_frames():
    # Two takes alike: no spread, no error. One wholly bad take among three clean ones: the pooled
    # share is 75 %, the takes' residuals -75, 25, 25 and 25 frames of 400.
    assert clustered_se([90, 90], [100, 100]) == 0.0
    se = clustered_se([0, 100, 100, 100], [100, 100, 100, 100])
    assert se == pytest.approx(100 * np.sqrt(4 / 3 * (75 ** 2 + 3 * 25 ** 2)) / 400)
    assert se > 100 * np.sqrt(0.75 * 0.25 / 400)  # wider than frames counted as independent
    assert np.isnan(clustered_se([5], [10]))
