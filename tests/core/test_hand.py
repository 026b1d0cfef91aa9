"""The procedural hand: anatomy, kinematics, mirroring, skin and linear blend skinning."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.hand import BONE_NAMES, HandModel, blend, build_mesh, sample_hand_size
from mocap_autolabel.core.hand.skeleton import ANSUR, DOF_INDEX, POSE_LIMITS
from mocap_autolabel.core.hand.skin import Binding, segment_weights
from mocap_autolabel.core.rotations import (
    continuous_quaternions,
    matrix_to_quaternion,
    matrix_to_rotvec,
    rotvec_to_matrix,
)
from mocap_autolabel.core.synth.poses import CANONICAL_POSES, couple_dip, sample_joint_angles

B = {n: i for i, n in enumerate(BONE_NAMES)}


def _tip(hand, pose, digit, world=False):
    r, p = hand.forward(pose, world=world)
    b = B[f"{digit}_dist"]
    return p[:, b] + r[:, b] @ np.array([0, hand.bone_lengths[b], 0])


def _pose(**deg):
    pose = np.zeros(26)
    for k, v in deg.items():
        pose[DOF_INDEX[k]] = np.radians(v)
    return pose


def test_middle_finger_reaches_hand_length():
    hand = HandModel(length=0.2, breadth=0.09, side="left")
    tip = _tip(hand, np.zeros(26), "middle")[0]
    # 6 degrees of rest splay shorten the reach by 1 - cos(6 deg) of the finger.
    assert tip[1] == pytest.approx(0.2, abs=0.002)
    assert abs(tip[2]) < 1e-12


def test_bones_scale_with_hand_size():
    small, big = HandModel(0.17, 0.08), HandModel(0.21, 0.08)
    assert np.allclose(big.bone_lengths / small.bone_lengths, 0.21 / 0.17)


def test_flexion_curls_towards_the_palm_and_abduction_spreads():
    for side in ("left", "right"):
        hand = HandModel(side=side)
        thumb_side = 1 if side == "left" else -1
        for digit in ("index", "middle", "ring", "little"):
            flexed = _tip(hand, _pose(**{f"{digit}_mcp_flex": 60, f"{digit}_pip": 60}), digit)[0]
            assert flexed[2] < -0.03  # palmar
        spread = _tip(hand, _pose(index_mcp_abd=15), "index")[0] - _tip(hand, np.zeros(26), "index")[0]
        assert spread[0] * thumb_side > 0.01
        little = _tip(hand, _pose(little_mcp_abd=30), "little")[0] - _tip(hand, np.zeros(26), "little")[0]
        assert little[0] * thumb_side < -0.01
        across = _tip(hand, _pose(thumb_cmc_flex=40), "thumb")[0] - _tip(hand, np.zeros(26), "thumb")[0]
        assert across[0] * thumb_side < -0.01  # thumb moves across the palm
        opposed = _tip(hand, _pose(thumb_cmc_abd=60), "thumb")[0] - _tip(hand, np.zeros(26), "thumb")[0]
        assert opposed[2] < -0.02


def test_right_hand_is_the_mirror_of_the_left():
    rng = np.random.default_rng(0)
    poses = np.zeros((20, 26))
    poses[:, 6:] = sample_joint_angles(rng, 20)
    left, right = HandModel(side="left"), HandModel(side="right")
    rl, pl = left.forward(poses, world=False)
    rr, pr = right.forward(poses, world=False)
    m = np.diag([-1.0, 1, 1])
    assert np.allclose(pr, pl @ m)
    assert np.allclose(rr, m @ rl @ m)
    assert np.allclose(np.linalg.det(rr), 1.0)


def test_global_pose_moves_the_hand_rigidly():
    hand = HandModel()
    pose = _pose(index_pip=40)
    moved = pose.copy()
    moved[0:3] = [0.3, -1.0, 2.0]
    moved[3:6] = [0.5, 0.1, 1.2]
    _, local = hand.forward(pose)
    _, world = hand.forward(moved)
    expected = local[0] @ rotvec_to_matrix(moved[0:3]).T + moved[3:6]
    assert np.allclose(world[0], expected)


def test_local_rotations_compose_to_the_forward_kinematics():
    from mocap_autolabel.core.hand.skeleton import PARENTS

    rng = np.random.default_rng(1)
    for side in ("left", "right"):
        hand = HandModel(side=side)
        poses = np.zeros((5, 26))
        poses[:, 6:] = sample_joint_angles(rng, 5)
        rots, _ = hand.forward(poses, world=False)
        basis = hand.local_rotations(poses)
        r0, _ = hand.rest
        for b, p in enumerate(PARENTS):
            if p < 0:
                continue
            rebuilt = rots[:, p] @ (r0[p].T @ r0[b]) @ basis[:, b]
            assert np.allclose(rebuilt, rots[:, b], atol=1e-12)


def test_limits_and_dip_coupling():
    for name, angles in CANONICAL_POSES.items():
        assert np.all(angles >= POSE_LIMITS[0, 6:] - 1e-9) and np.all(angles <= POSE_LIMITS[1, 6:] + 1e-9), name
    samples = sample_joint_angles(np.random.default_rng(2), 5000)
    assert np.all(samples >= POSE_LIMITS[0, 6:]) and np.all(samples <= POSE_LIMITS[1, 6:])
    # Every joint is exercised over most of its range.
    span = (samples.max(0) - samples.min(0)) / (POSE_LIMITS[1, 6:] - POSE_LIMITS[0, 6:])
    assert span.min() > 0.8
    coupled = couple_dip(np.radians(np.full(20, 30.0)))
    assert np.degrees(coupled[DOF_INDEX["index_dip"] - 6]) == pytest.approx(20.0)
    hand = HandModel()
    assert np.array_equal(hand.clip(np.full(26, 10.0))[6:], POSE_LIMITS[1, 6:])


def test_skinning_weights_blend_at_joints_only():
    bones, weights = segment_weights(np.array([B["index_mid"]] * 4), np.array([0.0, 0.5, 1.0, 0.1]))
    assert np.allclose(weights.sum(1), 1.0)
    assert list(bones[0]) == [B["index_mid"], B["index_prox"]] and weights[0, 1] == pytest.approx(0.5)
    assert weights[1, 1] == 0.0
    assert list(bones[2]) == [B["index_mid"], B["index_dist"]] and weights[2, 1] == pytest.approx(0.5)
    assert 0 < weights[3, 1] < 0.5
    # Tips and the palm have nothing to blend with.
    _, w = segment_weights(np.array([B["index_dist"], B["index_meta"]]), np.array([1.0, 0.0]))
    assert np.allclose(w[:, 1], 0.0)


def test_lbs_rest_is_identity_and_rigid_points_follow_their_bone():
    hand = HandModel()
    mesh = build_mesh(hand)
    r, t = hand.skinning_transforms(np.zeros((1, 26)))
    assert np.abs(blend(r, t, mesh.binding)[0] - mesh.binding.rest).max() < 1e-12
    rng = np.random.default_rng(4)
    poses = np.zeros((3, 26))
    poses[:, :3] = rng.normal(size=(3, 3))
    poses[:, 6:] = sample_joint_angles(rng, 3)
    rots, locs = hand.forward(poses)
    b = B["ring_mid"]
    local = np.array([0.001, 0.01, 0.008])
    r0, p0 = hand.rest
    point = Binding((r0[b] @ local + p0[b])[None], np.array([[b, b]]), np.array([[1.0, 0.0]]))
    moved = blend(*hand.skinning_transforms(poses), point)[:, 0]
    assert np.allclose(moved, (rots[:, b] @ local) + locs[:, b])


@pytest.mark.parametrize("side", ["left", "right"])
def test_mesh_is_closed_and_outward(side):
    mesh = build_mesh(HandModel(side=side))
    v, f = mesh.binding.rest, mesh.faces
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == len(edges)  # no directed edge twice
    assert all((b, a) in directed for a, b in directed)  # every edge has its twin: closed
    volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
    assert 150e-6 < volume < 600e-6  # m^3, positive: normals point outwards


def test_hand_sizes_follow_ansur():
    rng = np.random.default_rng(5)
    male = np.array([sample_hand_size(rng, "male") for _ in range(2000)]) * 1000
    lo, hi = ANSUR["male"]["length_5_95"]
    assert male[:, 0].min() >= lo and male[:, 0].max() <= hi
    assert male[:, 0].mean() == pytest.approx(193.3, abs=2.0)
    assert male[:, 1].mean() == pytest.approx(88.3, abs=1.5)
    assert np.corrcoef(male.T)[0, 1] > 0.4
    with pytest.raises(ValueError):
        HandModel(side="middle")


def test_rotation_helpers_round_trip():
    rng = np.random.default_rng(6)
    v = rng.normal(size=(500, 3))
    v *= (np.pi * 0.999 * rng.random(500) / np.linalg.norm(v, axis=1))[:, None]
    r = rotvec_to_matrix(v)
    assert np.allclose(matrix_to_rotvec(r), v, atol=1e-9)
    q = matrix_to_quaternion(r)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    # A slow turn through more than 180 degrees: w changes sign, so some quaternions flip.
    turn = matrix_to_quaternion(rotvec_to_matrix(np.linspace(0, 5.0, 200)[:, None] * [0.0, 0.6, 0.8]))
    flipped = turn * np.where(rng.random(200) < 0.5, -1, 1)[:, None]
    smooth = continuous_quaternions(flipped)
    assert np.all(np.sum(smooth[1:] * smooth[:-1], axis=1) > 0.99)
    assert np.allclose(np.abs(smooth), np.abs(turn))


def test_widened_pose_ranges_go_past_the_limits_and_no_further():
    from mocap_autolabel.core.hand.skeleton import JOINT_LIMITS_DEG
    from mocap_autolabel.core.synth.poses import widened_limits

    rng = np.random.default_rng(5)
    plain = np.degrees(sample_joint_angles(rng, 4000))
    wide = np.degrees(sample_joint_angles(rng, 4000, margin_deg=15.0))
    lo, hi = JOINT_LIMITS_DEG[:, 0], JOINT_LIMITS_DEG[:, 1]
    assert (plain >= lo - 1e-9).all() and (plain <= hi + 1e-9).all()
    assert (wide >= lo - 15 - 1e-9).all() and (wide <= hi + 15 + 1e-9).all()
    beyond = (wide < lo - 1) | (wide > hi + 1)
    assert beyond.any(axis=0).all()  # every joint is sampled past its textbook range sometimes
    wlo, whi = widened_limits(15.0)
    np.testing.assert_allclose(np.degrees(whi - wlo), hi - lo + 30)
