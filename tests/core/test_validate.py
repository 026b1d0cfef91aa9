"""IK validation of a labeling: fit scores, downgrades, and the pipeline with validate=True."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.hand.ik import GATE
from mocap_autolabel.core.labeling import NULL, Constraint, Labeling
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.pipeline import label_take
from mocap_autolabel.core.settings import Corrections, LabelSettings
from mocap_autolabel.core.synth.generate import GHOST, synthesize
from mocap_autolabel.core.validate import DOWNGRADED, downgrade, fit_scores


def test_fit_scores_prefer_the_nearest_fitted_marker_and_null_far_away():
    predicted = np.array([[[0.0, 0, 0], [0.02, 0, 0]], [[np.nan] * 3, [0.0, 0, 0]]])  # (F=2, M=2, 3)
    points = np.array([[[0.001, 0, 0], [0.5, 0, 0], [0, 0, 0]], [[0.0, 0, 0], [0.0, 0, 0], [0, 0, 0]]])
    mask = np.array([[True, True, False], [True, True, True]])
    s = fit_scores(points, mask, predicted)
    assert s.shape == (2, 3, 3)
    assert s[0, 0, 0] > s[0, 0, 2] > s[0, 0, 1]  # near marker 0: label 0, then null, then marker 1
    assert s[0, 1, 2] > s[0, 1, :2].max()  # far from every marker: null
    np.testing.assert_allclose(s[0, 0, 2], -2.0)  # null sits where a label is GATE away
    assert (s[0, 2] == 0).all()  # padding says nothing
    assert (s[1, :, 0] == 0).all()  # a marker the fit cannot place says nothing
    loose = fit_scores(points, mask, predicted, spread=0.01)
    assert loose[0, 0, 1] > s[0, 0, 1]  # a loose fit speaks more softly


def test_downgrade_caps_only_unlocked_segments_over_the_gate():
    lab = Labeling(names=["a"], n_frames=10, n_points=3, slot=np.array([0, 1, 2]), start=np.zeros(3, int),
                   stop=np.full(3, 10), label=np.array([0, 0, NULL], dtype=np.int16),
                   confidence=np.array([0.99, 0.99, 0.99], dtype=np.float32), locked=np.array([False, True, False]),
                   info={})
    assert downgrade(lab, np.array([2 * GATE, 2 * GATE, np.nan])) == 1
    np.testing.assert_allclose(lab.confidence, [DOWNGRADED, 0.99, 0.99])


@pytest.fixture(scope="module")
def take_and_truth():
    synth = synthesize(load_layout("han19"), 600, seed=5)
    return synth.take, synth.labels


def test_validation_keeps_accuracy_and_constraints(take_and_truth):
    layout = load_layout("han19")
    take, truth = take_and_truth
    t = np.where(truth == GHOST, NULL, truth)
    slot = int(np.flatnonzero(take.valid[100])[0])
    constraint = Constraint(slot, 100, 140, NULL)
    plain = label_take(take, layout, corrections=Corrections(constraints=[constraint]))
    checked = label_take(take, layout, LabelSettings(validate=True), corrections=Corrections(constraints=[constraint]))
    v = take.valid
    acc_plain = (plain.per_sample()[v] == t[v]).mean()
    acc_checked = (checked.per_sample()[v] == t[v]).mean()
    assert acc_checked >= acc_plain - 0.002
    assert (checked.per_sample()[100:140, slot][v[100:140, slot]] == NULL).all()
    info = checked.info["validation"]
    assert info["side"] in ("left", "right") and 150 < info["hand_length_mm"] < 230
    assert info["marker_rms_mm"] < 8
    assert "validate" in checked.info["seconds"]


def test_validation_needs_vote(take_and_truth):
    with pytest.raises(ValueError, match="vote"):
        label_take(take_and_truth[0], load_layout("han19"), LabelSettings(temporal="none", validate=True))
