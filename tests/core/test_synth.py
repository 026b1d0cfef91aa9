"""The synthetic take generator: motion, corruption, fragmentation, ground truth, determinism."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT
from mocap_autolabel.core.formats.c3d import read_c3d
from mocap_autolabel.core.hand.skeleton import POSE_LIMITS, HandModel
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.corrupt import camera_visibility, gap_mask, merge_close
from mocap_autolabel.core.synth.generate import (
    EMPTY,
    GHOST,
    SynthConfig,
    clean_config,
    save_synth,
    synthesize,
)
from mocap_autolabel.core.synth.motion import generate_motion
from mocap_autolabel.core.synth.truth import load_truth
from mocap_autolabel.core.tracklets import find_tracklets, mask_runs


def _label_runs(labels, positions):
    """(slot, start, stop, label set) for every run of samples in every slot."""
    valid = ~np.isnan(positions[..., 0])
    assert np.array_equal(valid, labels != EMPTY)  # truth and data agree on where samples are
    return [(s, a, b, set(labels[a:b, s].tolist())) for s, a, b in zip(*mask_runs(valid))]


def test_clean_take_is_exactly_the_skinned_markers():
    layout = load_layout("han19")
    synth = synthesize(layout, 300, seed=4, config=clean_config())
    take, labels = synth.take, synth.labels
    assert take.n_points == len(layout)  # nothing missing: one slot per marker, never cut
    assert (labels != EMPTY).all() and not (labels == GHOST).any()
    order = labels[0]
    assert sorted(order.tolist()) == list(range(len(layout)))
    assert np.allclose(take.positions, synth.markers[:, order], atol=1e-6)


def test_corrupted_take_is_fragmented_and_truth_is_consistent():
    layout = load_layout("han19")
    synth = synthesize(layout, 3000, seed=7)
    labels, take = synth.labels, synth.take
    assert all(n.startswith("*") for n in take.names)
    runs = _label_runs(labels, take.positions)
    assert all(len(lab) == 1 for *_, lab in runs)  # a run never changes identity: new slot after every gap
    # A marker is in at most one slot per frame.
    for m in range(len(layout)):
        assert (labels == m).sum(axis=1).max() <= 1
    present = np.stack([(labels == m).any(axis=1) for m in range(len(layout))], axis=1)
    assert 0.01 < 1 - present.mean() < 0.5  # some occlusion, not a wreck
    assert (labels == GHOST).any()
    # Observed samples are near the true marker (noise of at most a few mm, merges move them half a diameter).
    f, s = np.nonzero(labels >= 0)
    err = np.linalg.norm(take.positions[f, s] - synth.markers[f, labels[f, s]], axis=1)
    assert np.percentile(err, 99) < 0.006
    assert len(find_tracklets(take)) == len(runs)


def test_same_seed_same_bytes_and_different_seed_differs(tmp_path):
    layout = load_layout("glove13")
    a = save_synth(synthesize(layout, 500, seed=11), tmp_path / "a" / "take.c3d")
    b = save_synth(synthesize(layout, 500, seed=11), tmp_path / "b" / "take.c3d")
    c = save_synth(synthesize(layout, 500, seed=12), tmp_path / "c" / "take.c3d")
    for x, y in zip(a, b):
        assert open(x, "rb").read() == open(y, "rb").read()
    assert open(a[0], "rb").read() != open(c[0], "rb").read()


def test_saved_take_and_truth_round_trip(tmp_path):
    layout = load_layout("tips10")
    synth = synthesize(layout, 400, seed=2, config=dataclasses.replace(SynthConfig(), side="left"))
    take_path, truth_path = save_synth(synth, tmp_path / "t.c3d")
    take = read_c3d(take_path)
    truth = load_truth(truth_path)
    assert take.names == synth.take.names
    assert np.array_equal(take.valid, synth.take.valid)
    assert np.nanmax(np.abs(take.positions - synth.take.positions)) < 1e-6
    assert np.array_equal(truth["labels"], synth.labels)
    assert truth["info"]["names"] == layout.names and truth["info"]["hand"]["side"] == "left"
    assert truth["poses"].shape == (400, 26) and truth["markers"].shape == (400, 10, 3)


def test_motion_is_smooth_inside_limits_and_volume():
    rate = 120.0
    poses = generate_motion(np.random.default_rng(1), 6000, rate)
    joints = poses[:, 6:]
    assert np.all(joints >= POSE_LIMITS[0, 6:] - 1e-12) and np.all(joints <= POSE_LIMITS[1, 6:] + 1e-12)
    speed = np.degrees(np.abs(np.diff(joints, axis=0))).max() * rate
    assert 50 < speed < 700  # deg/s: it moves, at human speeds (minimum jerk peaks at 1.875x the mean)
    assert np.all(poses[:, 3:6] >= [-0.8, -0.8, 0.7]) and np.all(poses[:, 3:6] <= [0.8, 0.8, 1.6])
    wrist_speed = np.linalg.norm(np.diff(poses[:, 3:6], axis=0), axis=1).max() * rate
    assert wrist_speed < 2.0


def test_gap_mask_makes_runs_of_the_asked_length():
    mask = gap_mask(np.random.default_rng(0), 200_000, 3, 0.001, 12.0)
    starts = np.diff(mask.astype(int), axis=0) == 1
    lengths = mask.sum() / starts.sum()
    assert 10 < lengths < 14  # overlapping gaps merge, so slightly above the mean of 12 is expected
    assert 0.005 < mask.mean() < 0.02


def test_merge_close_joins_markers_closer_than_a_diameter():
    x = np.array([[[0, 0, 0], [0.004, 0, 0], [0.1, 0, 0]],
                  [[0, 0, 0], [0.02, 0, 0], [np.nan] * 3]], dtype=float)
    out, merged = merge_close(x, 0.006)
    assert np.allclose(out[0, 0], [0.002, 0, 0]) and np.isnan(out[0, 1, 0]) and merged[0, 0]
    assert np.allclose(out[1, :2], x[1, :2]) and not merged[1].any()


def test_camera_visibility_blocks_and_grazing():
    cams = np.array([[3.0, 0, 0], [3.0, 0.5, 0], [-3.0, 0, 0], [-3.0, 0.5, 0]])
    markers = np.array([[[0, 0, 0], [0, 1, 0]]], dtype=float)
    normals = np.array([[[1.0, 0, 0], [0, 0, 1.0]]])  # the second marker only grazes every camera
    spheres = np.zeros((1, 1, 3))
    far = camera_visibility(markers, normals, spheres + [0, 0, 5], np.array([0.05]), cams, every=1)
    assert far.tolist() == [[True, False]]
    # A sphere between the first marker and the two +x cameras hides it (the -x ones face away).
    near = camera_visibility(markers, normals, spheres + [0.5, 0.1, 0], np.array([0.2]), cams, every=1)
    assert near.tolist() == [[False, False]]


def test_cli_synth_writes_take_and_truth(tmp_path):
    out = tmp_path / "take.c3d"
    cmd = [sys.executable, "-m", "mocap_autolabel", "synth", "--layout", "tips5", "--frames", "240", "--seed", "1",
           "-o", str(out)]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=_env())
    assert run.returncode == 0, run.stderr
    assert out.exists() and (tmp_path / "take.truth.npz").exists()
    bad = subprocess.run(cmd[:5] + ["nolayout"] + cmd[6:], capture_output=True, text=True, cwd=ROOT, env=_env())
    assert bad.returncode == 1 and bad.stderr.count("\n") == 1 and "nolayout" in bad.stderr
    wrong = subprocess.run(cmd[:-1] + [str(tmp_path / "take.txt")], capture_output=True, text=True, cwd=ROOT,
                           env=_env())
    assert wrong.returncode == 2 and ".c3d" in wrong.stderr and not (tmp_path / "take.txt").exists()


def test_bundled_demo_take_comes_from_the_generator():
    """samples/demo_take.c3d is `make sample`'s output: regenerate it and compare the data."""
    synth = synthesize(load_layout("han19"), 1200, seed=1)
    bundled = read_c3d(ROOT / "samples" / "demo_take.c3d")
    assert bundled.names == synth.take.names
    assert np.array_equal(bundled.valid, synth.take.valid)
    assert np.nanmax(np.abs(bundled.positions - synth.take.positions)) < 1e-6
    truth = load_truth(ROOT / "samples" / "demo_take.truth.npz")
    assert np.array_equal(truth["labels"], synth.labels)


def _env():
    import os

    return os.environ | {"PYTHONPATH": str(ROOT / "addon")}


@pytest.mark.parametrize("layout", ["han19", "glove13", "tips3"])
def test_every_builtin_layout_generates(layout):
    synth = synthesize(load_layout(layout), 200, seed=0)
    assert synth.markers.shape == (200, len(load_layout(layout)), 3)


def test_fill_short_gaps_bridges_only_short_inner_gaps():
    from mocap_autolabel.core.synth.corrupt import fill_short_gaps

    missing = np.zeros((30, 2), dtype=bool)
    missing[5:8, 0] = True  # 3 frames: bridged
    missing[12:20, 0] = True  # 8 frames: kept
    missing[0:2, 1] = True  # touches the start: kept
    missing[28:, 1] = True  # touches the end: kept
    out = fill_short_gaps(missing, 4)
    assert not out[5:8, 0].any() and out[12:20, 0].all()
    assert out[0:2, 1].all() and out[28:, 1].all()
    assert out.sum() == 8 + 2 + 2


def test_corrupt_take_truth_matches_positions():
    from mocap_autolabel.core.synth.generate import GHOST, TakeCorruption, corrupt_take

    layout = load_layout("han19")
    synth = synthesize(layout, 900, seed=3, config=clean_config())
    cfg = TakeCorruption(swap_share=1.0, swap_distance=1.0, fragments_per_minute=30.0)
    take, truth, facts = corrupt_take(synth.markers, 120.0, seed=4, cfg=cfg)
    again, truth2, _ = corrupt_take(synth.markers, 120.0, seed=4, cfg=cfg)
    np.testing.assert_array_equal(take.positions, again.positions)  # seeded
    np.testing.assert_array_equal(truth, truth2)
    assert facts["swaps"] == 1
    f, s = np.nonzero(truth >= 0)
    # Each truly labeled sample sits exactly on that marker (swaps included: truth follows them).
    np.testing.assert_allclose(take.positions[f, s], synth.markers[f, truth[f, s]], atol=1e-6)
    assert ((truth == GHOST) & take.valid).any() and ((truth >= 0) == (take.valid & (truth != GHOST))).all()
    # Fragments: more tracklets than gaps alone would make.
    assert len(find_tracklets(take)) > len(find_tracklets(corrupt_take(
        synth.markers, 120.0, seed=4, cfg=TakeCorruption(swap_share=0.0, fragments_per_minute=0.0))[0]))


def test_bone_scale_changes_proportions_only_where_asked():
    from mocap_autolabel.core.hand.skeleton import BONE_NAMES

    plain = HandModel(side="left")
    scale = np.ones(len(BONE_NAMES))
    scale[BONE_NAMES.index("index_mid")] = 1.1
    varied = HandModel(side="left", bone_scale=tuple(scale))
    ratio = varied.bone_lengths / plain.bone_lengths
    assert ratio[BONE_NAMES.index("index_mid")] == pytest.approx(1.1)
    assert np.delete(ratio, BONE_NAMES.index("index_mid")) == pytest.approx(1.0)


def test_misplacement_moves_finger_markers_towards_the_middle_of_the_hand():
    from mocap_autolabel.core.hand.skeleton import BONE_NAMES
    from mocap_autolabel.core.synth.generate import misplacement

    layout = load_layout("han19")
    for side in ("left", "right"):
        hand = HandModel(side=side)
        binding = layout.place(hand)[0]
        assert not misplacement(np.random.default_rng(0), binding, hand, 0.0, 0.0).any()
        bone = np.array(BONE_NAMES)[binding.bones[:, 0]]
        little, index = layout.names.index("PinkyTip"), layout.names.index("IndexTip")
        shifts = []
        for seed in range(200):
            off = misplacement(np.random.default_rng(seed), binding, hand, 0.0, 0.02)
            moved = np.flatnonzero(np.abs(off).sum(axis=1) > 0)
            fingers = ("index", "middle", "ring", "little")
            assert set(bone[moved]) <= {f"{f}_{s}" for f in fingers for s in ("mid", "dist")}
            assert not off[:, 1:].any()  # sideways only
            x = off[:, 0] * hand.thumb_side  # towards the thumb
            assert np.sign(x[little]) == -np.sign(x[index]) or x[little] == 0
            shifts.append(x[little])
        assert -0.005 - 1e-9 <= min(shifts) and max(shifts) <= 0.02 + 1e-9 and np.mean(shifts) > 0.005
        spread = np.std([misplacement(np.random.default_rng(s), binding, hand, 0.003, 0.0) for s in range(300)],
                        axis=0)
        distal = np.char.endswith(bone, "_dist")
        assert spread[distal].mean() == pytest.approx(0.006, rel=0.1)
        assert spread[~distal].mean() == pytest.approx(0.003, rel=0.1)


def test_misplaced_takes_move_the_markers_and_nothing_else_about_the_hand():
    layout = load_layout("han19")
    plain = synthesize(layout, 120, seed=3)
    again = synthesize(layout, 120, seed=3, config=SynthConfig(placement_sd=0.0, tip_convergence=0.0))
    moved = synthesize(layout, 120, seed=3, config=SynthConfig(placement_sd=0.003, tip_convergence=0.018))
    assert np.array_equal(plain.markers, again.markers)  # off: the take as it always was
    assert np.array_equal(plain.poses, moved.poses) and plain.hand == moved.hand
    shift = np.linalg.norm(moved.markers - plain.markers, axis=2)  # (F, M)
    assert np.all(shift > 0) and 0.002 < shift.mean() < 0.02  # every marker off its spot, by millimetres
    # A misplacement is fixed on the hand: the offset between the two takes' markers of one bone
    # is the same rigid motion in every frame, so its size does not change.
    assert np.ptp(shift[:, layout.names.index("BackHand1")]) < 1e-9


@pytest.mark.parametrize("side", ["left", "right"])
def test_touch_puts_the_thumb_pad_on_the_finger_and_bends_only_those_two_digits(side):
    from mocap_autolabel.core.hand.ik import HandSolver
    from mocap_autolabel.core.hand.skeleton import BONE_INDEX, JOINT_NAMES, N_DOF
    from mocap_autolabel.core.hand.skin import Binding, segment_weights, skin_point
    from mocap_autolabel.core.synth.generate import touch
    from mocap_autolabel.core.synth.poses import sample_joint_angles

    hand = HandModel(side=side)
    poses = np.zeros((6, N_DOF))
    poses[:, 6:] = sample_joint_angles(np.random.default_rng(3), 6)
    touched = 0
    # The thumb's pad on a fingertip's pad, on its thumb side, on the middle phalanx's thumb side.
    sites = (("dist", 0.6, np.pi), ("dist", 0.5, np.pi / 2), ("mid", 0.5, np.pi / 2))
    for finger, (bone, along, angle) in zip(("index", "middle", "ring", "little"), sites * 2):
        out, gap = touch(hand, poses, finger, bone, along, angle)
        bones = np.array([BONE_INDEX["thumb_dist"], BONE_INDEX[f"{finger}_{bone}"]])
        rest = np.array([skin_point(hand, bones[0], 0.6, np.pi)[0], skin_point(hand, bones[1], along, angle)[0]])
        solver = HandSolver(hand, Binding(rest, *segment_weights(bones, np.array([0.6, along]))))
        pads, before = solver.markers(out), solver.markers(poses)
        np.testing.assert_allclose(gap, np.linalg.norm(pads[:, 0] - pads[:, 1], axis=1), atol=1e-12)
        assert (gap < np.linalg.norm(before[:, 0] - before[:, 1], axis=1) - 0.005).all()  # all closed in
        touched += int((gap < 0.001).sum())
        kept = [6 + i for i, n in enumerate(JOINT_NAMES) if not n.startswith(("thumb", finger))]
        np.testing.assert_array_equal(out[:, kept], poses[:, kept])  # the other digits and the wrist stay
        np.testing.assert_array_equal(out[:, :6], poses[:, :6])
        lo, hi = POSE_LIMITS
        assert (out[:, 6:] >= lo[6:] - 1e-9).all() and (out[:, 6:] <= hi[6:] + 1e-9).all()
    # 17 of these 24 starts touch; the rest are held apart by joint limits (most at the little
    # finger), and the gap says so.
    assert touched >= 16


def test_contacts_bend_only_their_frames_and_leave_takes_without_them_as_they_were():
    from mocap_autolabel.core.synth.generate import add_contacts

    layout = load_layout("han19")
    plain = synthesize(layout, 1200, seed=4)
    assert np.array_equal(plain.poses, synthesize(layout, 1200, seed=4, config=SynthConfig()).poses)
    touching = synthesize(layout, 1200, seed=4, config=SynthConfig(contacts_per_minute=(30.0, 30.0)))
    changed = np.abs(touching.poses - plain.poses).max(axis=1) > 0
    assert changed.any() and not changed.all()
    np.testing.assert_array_equal(touching.poses[:, :6], plain.poses[:, :6])  # the wrist moves as before

    poses = generate_motion(np.random.default_rng(5), 1200, 120.0)
    before = poses.copy()
    contacts = add_contacts(np.random.default_rng(6), HandModel(), poses, 120.0, (30.0, 30.0), (0.5, 1.0))
    assert contacts
    inside = np.zeros(len(poses), dtype=bool)
    for start, stop, finger in contacts:
        assert finger in ("index", "middle", "ring", "little") and 60 <= stop - start <= 120
        inside[start:stop] = True
    np.testing.assert_array_equal(poses[~inside], before[~inside])
    lo, hi = POSE_LIMITS
    assert (poses[:, 6:] >= lo[6:] - 1e-9).all() and (poses[:, 6:] <= hi[6:] + 1e-9).all()
