"""Rigid props among the trajectories (core/props.py) and in label_take."""

import numpy as np
import pytest
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.props import rigid_groups
from mocap_autolabel.core.synth.props import _rotation
from mocap_autolabel.core.tracklets import find_tracklets


def _scene(frames: int = 600, rate: float = 120.0):
    """A 4-marker rigid prop turning in space, beside 5 'finger' markers that move against each
    other except for one second in which they and the prop are still together."""
    rng = np.random.default_rng(0)
    t = np.arange(frames) / rate
    shape = rng.uniform(-0.03, 0.03, (4, 3))
    turn = _rotation(np.array([0.0, 0.6, 0.8]), 0.8 * np.sin(t))
    centre = np.stack([0.3 * np.sin(0.5 * t), 0.1 * t, 1.0 + 0.0 * t], axis=1)
    prop = centre[:, None] + np.einsum("fij,nj->fni", turn, shape)
    fingers = centre[:, None] + np.array([0.08, 0, 0]) + rng.uniform(-0.04, 0.04, (5, 3))[None]
    wave = np.sin(2 * np.pi * t[:, None] * rng.uniform(0.5, 1.5, 5)[None] + rng.uniform(0, 6, 5)[None])
    still = (t > 2.0) & (t < 3.2)
    wave[still] = wave[np.flatnonzero(still)[0]]  # everything still for 1.2 s
    fingers = fingers + 0.03 * wave[..., None] * rng.normal(size=(5, 3))[None]
    positions = np.concatenate([prop, fingers], axis=1) + rng.normal(0, 0.0003, (frames, 9, 3))
    return positions, rate


def test_rigid_groups_find_the_prop_and_not_the_moving_fingers():
    from mocap_autolabel.core.take import Take

    positions, rate = _scene()
    take = Take(positions=positions.astype(np.float32), names=[f"*{i}" for i in range(9)], rate=rate)
    groups = rigid_groups(positions, find_tracklets(take), rate)
    slots = [sorted(find_tracklets(take).slot[g].tolist()) for g in groups]
    assert slots == [[0, 1, 2, 3]]


@pytest.mark.slow
def test_a_prop_that_took_hand_labels_is_kept_out_and_named_in_the_info():
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.settings import LabelSettings
    from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take

    layout = load_layout("han19")
    two = two_hand_take(layout, 1200, seed=1, config=TwoHandConfig(prop_markers=4))
    ps, valid = two.prop_slots, two.take.valid
    before = label_take(two.take, layout, LabelSettings(props=False)).per_sample()
    assert ((before[:, ps] >= 0) & valid[:, ps]).mean() > 0.1  # the prop steals without the check
    lab = label_take(two.take, layout)
    after = lab.per_sample()
    assert lab.info["props"] and lab.info["props"][0]["trajectories"] >= 3
    assert not ((after[:, ps] >= 0) & valid[:, ps]).any()
    hand = np.ones(valid.shape[1], dtype=bool)
    hand[ps] = False
    right = lambda per: ((per == two.labels) & valid)[:, hand].sum()  # noqa: E731
    assert right(after) > right(before)
