"""Retargeting onto a character's armature (core, no Blender): the transfer's rotations."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.hand.skeleton import BONE_NAMES, DOF_INDEX, JOINT_NAMES, PARENTS, HandModel
from mocap_autolabel.core.retarget.source import SourceHand
from mocap_autolabel.core.retarget.target import TargetRig
from mocap_autolabel.core.retarget.transfer import retarget
from mocap_autolabel.core.rotations import matrix_to_rotvec, quaternion_to_matrix, rot_x, rot_y, rotvec_to_matrix


def _poses(hand: HandModel, frames: int, seed: int = 0) -> np.ndarray:
    """Smooth random poses inside the joint limits, the hand turning and moving in the world."""
    from mocap_autolabel.core.hand.skeleton import POSE_LIMITS

    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, frames)[:, None]
    phase = rng.uniform(0, 2 * np.pi, (1, 26))
    lo, hi = POSE_LIMITS
    lo, hi = np.where(np.isfinite(lo), lo, -0.6), np.where(np.isfinite(hi), hi, 0.6)
    poses = lo + (hi - lo) * (0.5 + 0.45 * np.sin(2 * np.pi * 1.5 * t + phase))
    poses[:, 3:6] = 0.1 * np.sin(2 * np.pi * t + phase[:, 3:6])
    return poses


def _rig(hand: HandModel, pose: np.ndarray | None = None, names=BONE_NAMES, scale: float = 1.0,
         roll: float = 0.0, world: np.ndarray | None = None) -> TargetRig:
    """A character whose hand is our hand model at ``pose`` (None: our rest), bones rolled by ``roll``
    radians about their own axis, in armature units of ``1 / scale`` metres."""
    r, p = hand.forward(np.zeros(26) if pose is None else pose, world=False)
    rest = np.zeros((20, 4, 4))
    rest[:, :3, :3] = r[0] @ rot_y(np.full(20, roll))
    rest[:, :3, 3] = p[0] / scale
    rest[:, 3, 3] = 1.0
    return TargetRig(tuple(names), PARENTS, rest, np.asarray(hand.bone_lengths) / scale,
                     np.eye(4) if world is None else world)


def _basis(result, bone: str) -> np.ndarray:
    return quaternion_to_matrix(result.rotations[:, result.bones.index(bone)])


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.linalg.norm(matrix_to_rotvec(np.swapaxes(a, -1, -2) @ b), axis=-1))


@pytest.mark.parametrize("side", ["left", "right"])
def test_our_own_rig_gets_our_joint_rotations(side):
    hand = HandModel(side=side)
    poses = _poses(hand, 200)
    result = retarget(SourceHand.from_poses(hand, poses), _rig(hand), {b: b for b in BONE_NAMES})
    local = hand.local_rotations(poses)
    assert "palm" not in result.bones  # the wrist stays the animator's
    for b, name in enumerate(BONE_NAMES[1:], start=1):
        assert _angle(_basis(result, name), local[:, b]).max() < 1e-4, name
    assert np.degrees(np.linalg.norm(matrix_to_rotvec(local[:, 1:]), axis=-1)).max() > 20  # the fingers did move


def test_rolled_and_scaled_bones_turn_the_same_angle():
    hand = HandModel(side="left")
    poses = _poses(hand, 100, seed=3)
    plain = retarget(SourceHand.from_poses(hand, poses), _rig(hand), {b: b for b in BONE_NAMES})
    rolled = retarget(SourceHand.from_poses(hand, poses), _rig(hand, roll=np.pi / 2, scale=0.01),
                      {b: b for b in BONE_NAMES})
    for name in BONE_NAMES[1:]:
        a = np.linalg.norm(matrix_to_rotvec(_basis(plain, name)), axis=-1)
        b = np.linalg.norm(matrix_to_rotvec(_basis(rolled, name)), axis=-1)
        assert np.abs(np.degrees(a - b)).max() < 1e-4, name
        # ... about the rolled axis: the same turn seen from a bone rolled by 90 degrees about y
        r = rot_y(np.pi / 2)
        assert _angle(r.T @ _basis(plain, name) @ r, _basis(rolled, name)).max() < 1e-4


def _directions(rig: TargetRig, result) -> dict[str, np.ndarray]:
    """Each keyed bone's direction (y) in armature space, posed (the hand bone stays at rest):
    ``{bone: (F, 3)}``."""
    rest = rig.rest[:, :3, :3]
    posed = {}
    for j, name in enumerate(rig.names):
        p = rig.parents[j]
        base = rest[j] if p < 0 else posed[rig.names[p]] @ rest[p].T @ rest[j]
        posed[name] = base @ _basis(result, name) if name in result.bones else np.broadcast_to(base, (len(
            result.solved), 3, 3))
    return {n: m[..., :, 1] for n, m in posed.items() if n in result.bones}


def test_curled_rest_ends_in_our_pose():
    """A character whose rest fingers are curled (35 degrees at every finger joint) and spread ends
    in the same finger directions as one whose rest is ours."""
    hand = HandModel(side="right")
    poses = _poses(hand, 150, seed=5)
    curl = np.zeros(26)
    for f in ("index", "middle", "ring", "little"):
        curl[[DOF_INDEX[f"{f}_mcp_flex"], DOF_INDEX[f"{f}_pip"], DOF_INDEX[f"{f}_dip"]]] = np.radians(35)
        curl[DOF_INDEX[f"{f}_mcp_abd"]] = np.radians(10)
    curl[DOF_INDEX["thumb_mcp"]] = np.radians(30)
    source = SourceHand.from_poses(hand, poses)
    straight_rig, curled_rig = _rig(hand), _rig(hand, curl, roll=0.4)
    straight = _directions(straight_rig, retarget(source, straight_rig, {b: b for b in BONE_NAMES}))
    curled = _directions(curled_rig, retarget(source, curled_rig, {b: b for b in BONE_NAMES}))
    for name in BONE_NAMES[1:]:
        cos = np.sum(straight[name] * curled[name], axis=1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.01, name


def test_a_chosen_frame_as_rest():
    """The character's rest is frame 40 of the take: there its bases are the identity."""
    hand = HandModel(side="left")
    poses = _poses(hand, 80, seed=7)
    rig = _rig(hand, poses[40] * np.r_[np.zeros(6), np.ones(20)])
    result = retarget(SourceHand.from_poses(hand, poses), rig, {b: b for b in BONE_NAMES}, reference=40)
    assert np.abs(result.rotations[40, :, 1:]).max() < 1e-6
    with pytest.raises(MocapInputError, match="frame 99"):
        retarget(SourceHand.from_poses(hand, poses), rig, {b: b for b in BONE_NAMES}, reference=99)


def test_no_metacarpals_and_extra_bones():
    """A Mixamo-like hand: no finger metacarpals (the first finger bone hangs from the hand) and an
    unmapped end bone; the first finger bone gets our metacarpal's and proximal turns together."""
    hand = HandModel(side="left")
    poses = _poses(hand, 60, seed=9)
    r, p = hand.forward(np.zeros(26), world=False)
    keep = [b for b in range(20) if not (BONE_NAMES[b].endswith("_meta") and BONE_NAMES[b] != "thumb_meta")]
    names = [BONE_NAMES[b] for b in keep] + ["index_end"]
    old_to_new = {b: i for i, b in enumerate(keep)}
    parents = []
    for b in keep:
        q = PARENTS[b]
        while q >= 0 and q not in old_to_new:
            q = PARENTS[q]
        parents.append(old_to_new.get(q, -1))
    parents.append(names.index("index_dist"))
    rest = np.zeros((len(names), 4, 4))
    rest[:len(keep), :3, :3], rest[:len(keep), :3, 3] = r[0, keep], p[0, keep]
    d = BONE_NAMES.index("index_dist")
    rest[-1, :3, :3], rest[-1, :3, 3] = r[0, d], p[0, d] + r[0, d, :, 1] * hand.bone_lengths[d]
    rest[:, 3, 3] = 1.0
    rig = TargetRig(tuple(names), tuple(parents), rest, np.r_[np.asarray(hand.bone_lengths)[keep], 0.01])
    result = retarget(SourceHand.from_poses(hand, poses), rig, {n: n for n in names if n in BONE_NAMES})
    assert "index_end" not in result.bones
    g = SourceHand.from_poses(hand, poses).palm_relative()
    rest_g = hand.rest[0]
    b = BONE_NAMES.index("index_prox")
    expected = rest_g[b].T @ g[:, b]  # relative to the palm: the metacarpal's turn included
    assert _angle(_basis(result, "index_prox"), expected).max() < 1e-4


def test_pinch_kept_on_longer_fingers():
    """A character with 20 % longer fingers keeps the thumb-to-fingertip distance where ours touch."""
    hand = HandModel(side="right")
    frames = 120
    poses = np.zeros((frames, 26))
    t = np.sin(np.linspace(0, np.pi, frames)) ** 2  # reach for a pinch and let go
    # A pinch of this hand model: its thumb and index tips 12 mm apart at the top of the reach.
    for name, angle in (("thumb_cmc_flex", 22.0), ("thumb_cmc_abd", 21.3), ("thumb_mcp", 9.7), ("thumb_ip", 3.9),
                        ("index_mcp_flex", 22.3), ("index_pip", 58.4), ("index_dip", 35.9)):
        poses[:, DOF_INDEX[name]] = np.radians(angle) * t
    source = SourceHand.from_poses(hand, poses)
    tips = source.tips()
    ours = np.linalg.norm(tips[:, BONE_NAMES.index("thumb_dist")] - tips[:, BONE_NAMES.index("index_dist")], axis=1)
    radii = hand.bone_radii[:, 1]
    reach = radii[BONE_NAMES.index("thumb_dist")] + radii[BONE_NAMES.index("index_dist")] + 0.005
    contact = ours < reach
    assert 5 < contact.sum() < frames - 20, "the test's motion must pinch for a while"
    # 20 % longer fingers, the thumb as ours (a stylised character's hand).
    long_hand = HandModel(side="right", bone_scale=tuple(1.2 if b.split("_")[0] in ("index", "middle", "ring", "little")
                                                         else 1.0 for b in BONE_NAMES))
    rig = _rig(long_hand, scale=0.01)
    rig = TargetRig(rig.names, rig.parents, rig.rest, rig.lengths, np.diag([0.01, 0.01, 0.01, 1.0]))
    plain = retarget(source, rig, {b: b for b in BONE_NAMES})
    kept = retarget(source, rig, {b: b for b in BONE_NAMES}, pinch=True)

    def tip_distance(result):
        r, h = _posed(rig, result)
        th, ix = rig.index("thumb_dist"), rig.index("index_dist")
        tip = lambda j: h[:, j] + r[:, j, :, 1] * rig.lengths[j]  # noqa: E731
        return np.linalg.norm(tip(th) - tip(ix), axis=1) * 0.01  # metres

    before = np.abs(tip_distance(plain) - ours)[contact]
    after = np.abs(tip_distance(kept) - ours)[contact]
    assert before.max() > 0.005  # the longer fingers miss the pinch without the correction
    assert after.max() < 0.001
    assert kept.facts["pinch"]["frames"] == contact.sum()
    far = ~contact & (np.abs(np.arange(frames)[:, None] - np.flatnonzero(contact)[None]).min(axis=1) > 8)
    assert np.allclose(kept.rotations[far], plain.rotations[far])  # untouched away from the contact


def _posed(rig: TargetRig, result) -> tuple[np.ndarray, np.ndarray]:
    """Armature-space rotations ``(F, B, 3, 3)`` and heads ``(F, B, 3)`` of the posed character."""
    frames = len(result.solved)
    rest = rig.rest[:, :3, :3]
    r = np.empty((frames, len(rig.names), 3, 3))
    h = np.empty((frames, len(rig.names), 3))
    for j in range(len(rig.names)):
        p = rig.parents[j]
        basis = _basis(result, rig.names[j]) if rig.names[j] in result.bones else np.eye(3)
        if p < 0:
            r[:, j], h[:, j] = rest[j] @ basis, rig.rest[j, :3, 3]
        else:
            r[:, j] = r[:, p] @ rest[p].T @ rest[j] @ basis
            h[:, j] = h[:, p] + (r[:, p] @ (rest[p].T @ (rig.rest[j, :3, 3] - rig.rest[p, :3, 3]))[:, None])[..., 0]
    return r, h


def test_wrist_rotation_follows_our_palm():
    hand = HandModel(side="left")
    poses = _poses(hand, 50, seed=11)
    world = np.eye(4)
    world[:3, :3] = rot_x(np.pi / 2)  # a character standing in a Y-up file
    rig = _rig(hand, world=world)
    result = retarget(SourceHand.from_poses(hand, poses), rig, {b: b for b in BONE_NAMES}, wrist="world")
    assert result.bones[0] == "palm" and result.location_bone == "palm"
    palm = world[:3, :3] @ rig.rest[0, :3, :3] @ _basis(result, "palm")
    assert _angle(palm, rotvec_to_matrix(poses[:, :3])).max() < 1e-4
    head = (world[:3, :3] @ (rig.rest[0, :3, 3] + rig.rest[0, :3, :3] @ result.locations[..., None])[..., 0].T).T
    assert np.abs(head - poses[:, 3:6]).max() < 1e-9


def test_bad_maps_say_what_is_wrong():
    hand = HandModel(side="left")
    source = SourceHand.from_poses(hand, _poses(hand, 5))
    rig = _rig(hand)
    with pytest.raises(MocapInputError, match="not mapped"):
        retarget(source, rig, {"index_prox": "index_prox"})
    with pytest.raises(MocapInputError, match="not in the armature"):
        retarget(source, rig, {"palm": "palm", "index_prox": "nope"})
    with pytest.raises(MocapInputError, match="two fingers"):
        retarget(source, rig, {"palm": "palm", "index_prox": "index_prox"})
    assert len(JOINT_NAMES) == 20
