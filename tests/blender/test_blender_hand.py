"""Blender's armature deformation must reproduce the core's LBS: it guards every later IK result."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.hand import HandModel, blend, build_mesh
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.rotations import rotvec_to_matrix
from mocap_autolabel.core.synth.motion import generate_motion
from mocap_autolabel.core.synth.poses import CANONICAL_POSES, sample_joint_angles

TOLERANCE_M = 1e-4  # 0.1 mm


def _armature():
    from mocap_autolabel.blender import armature

    return armature


def _evaluated_points(bpy, obj) -> np.ndarray:
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    world = np.array(ev.matrix_world)
    return co.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3]


def _random_poses(rng, n):
    poses = np.zeros((n, 26))
    poses[:, 0:3] = rng.normal(0, 1.5, (n, 3))
    poses[:, 3:6] = rng.uniform(-1, 1, (n, 3))
    poses[:, 6:] = sample_joint_angles(rng, n)
    poses[0, 6:] = CANONICAL_POSES["letter_r"]  # crossed fingers: bones close together
    return poses


@pytest.mark.parametrize("side", ["right", "left"])
def test_set_pose_matches_numpy_lbs(empty_scene, bpy_module, side):
    hand = HandModel(length=0.185, breadth=0.082, side=side)
    layout = load_layout("han19")
    objs = _armature().build_hand(hand, layout=layout)
    mesh, markers = build_mesh(hand), layout.place(hand)[0]
    rng = np.random.default_rng(3)
    for pose in _random_poses(rng, 6):
        _armature().set_pose(objs["armature"], hand, pose)
        r, t = hand.skinning_transforms(pose[None])
        for obj, binding in ((objs["mesh"], mesh.binding), (objs["markers"], markers)):
            expected = blend(r, t, binding)[0]
            got = _evaluated_points(bpy_module, obj)
            assert got.shape == expected.shape
            assert np.abs(got - expected).max() < TOLERANCE_M


def test_keyed_motion_matches_numpy_lbs(empty_scene, bpy_module):
    """The bulk keyframes (slotted actions on 4.4+, action.fcurves on 4.2) reproduce the motion."""
    hand = HandModel(side="right")
    layout = load_layout("glove13")
    objs = _armature().build_hand(hand, layout=layout, mesh=False)
    poses = generate_motion(np.random.default_rng(5), 240)
    _armature().key_poses(objs["armature"], hand, poses, first_frame=10)
    expected = blend(*hand.skinning_transforms(poses), layout.place(hand)[0])
    for frame in (10, 11, 57, 130, 249):
        empty_scene.frame_set(frame)
        got = _evaluated_points(bpy_module, objs["markers"])
        assert np.abs(got - expected[frame - 10]).max() < TOLERANCE_M


def test_build_hand_rest_pose_and_names(empty_scene, bpy_module):
    hand = HandModel(side="left")
    objs = _armature().build_hand(hand, layout=load_layout("tips5"))
    arm = objs["armature"].data
    assert [b.name for b in arm.bones] == list(hand_bone_names())
    r0, p0 = hand.rest
    for b, bone in enumerate(arm.bones):
        m = np.array(bone.matrix_local)
        assert np.allclose(m[:3, :3], r0[b], atol=1e-5)
        assert np.allclose(m[:3, 3], p0[b], atol=1e-6)
    assert list(objs["markers"]["marker_names"]) == load_layout("tips5").names
    # At rest the skin is where the core put it.
    got = _evaluated_points(bpy_module, objs["mesh"])
    assert np.abs(got - build_mesh(hand).binding.rest).max() < 1e-6
    assert np.allclose(rotvec_to_matrix(np.zeros(3)), np.eye(3))


def hand_bone_names():
    from mocap_autolabel.core.hand import BONE_NAMES

    return BONE_NAMES
