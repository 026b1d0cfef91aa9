"""The procedural hand in Blender: an Armature, a skinned mesh and the layout's markers.

Bones get exactly the core model's rest frames, and every pose is converted from the core's
skinning transforms, so that Blender's armature deformation reproduces the core's linear blend
skinning (a test holds them to 0.1 mm).
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from ..core.fill import KeptSolve, digests_fingerprint
from ..core.hand.skeleton import BONE_NAMES, PARENTS, HandModel
from ..core.hand.skin import Binding, build_mesh
from ..core.layout import Layout
from ..core.rotations import continuous_quaternions, matrix_to_quaternion
from . import animio


def _homogeneous(rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` and ``(..., 3)`` to 4x4 matrices ``(..., 4, 4)``."""
    out = np.zeros(rotations.shape[:-2] + (4, 4))
    out[..., :3, :3] = rotations
    out[..., :3, 3] = translations
    out[..., 3, 3] = 1.0
    return out


def claim_name(datablocks, name: str) -> str:
    """``name`` made free in ``datablocks`` (``bpy.data.actions``, ``.meshes``...) where an orphan
    holds it: a datablock no one uses (the data of a rig deleted by hand, which Blender keeps until
    the file is saved) goes, so that a new one gets the plain name instead of ``name.001``. One in
    use stays (the new one is then numbered, as Blender does)."""
    held = datablocks.get(name)
    if held is not None and held.users == 0:
        datablocks.remove(held)
    return name


def build_hand(hand: HandModel, name: str = "Hand", collection: bpy.types.Collection | None = None,
               layout: Layout | None = None, mesh: bool = True,
               binding: Binding | None = None) -> dict[str, bpy.types.Object]:
    """Create the hand's armature (and skinned mesh, and marker points) in ``collection``.

    ``binding`` places the layout's markers (a calibration's); default: the layout's own places.

    Returns:
        ``{"armature": obj, "mesh": obj or absent, "markers": obj or absent}``. The mesh and the
        markers are children of the armature with an Armature modifier, deformed by the same
        weights the core uses.
    """
    collection = collection or bpy.context.scene.collection
    arm = bpy.data.armatures.new(claim_name(bpy.data.armatures, name))
    arm_obj = bpy.data.objects.new(claim_name(bpy.data.objects, name), arm)
    collection.objects.link(arm_obj)
    arm.display_type = "STICK"

    # Edit bones need edit mode, which needs the object active in the view layer.
    view_layer = bpy.context.view_layer
    previous = view_layer.objects.active
    view_layer.objects.active = arm_obj
    bpy.ops.object.mode_set(mode="EDIT")
    rest = _homogeneous(*hand.rest)  # armature space is the hand frame
    for b, bone_name in enumerate(BONE_NAMES):
        eb = arm.edit_bones.new(bone_name)
        eb.head = (0.0, 0.0, 0.0)
        eb.tail = (0.0, float(hand.bone_lengths[b]), 0.0)
        eb.matrix = Matrix(rest[b].tolist())
        if PARENTS[b] >= 0:
            eb.parent = arm.edit_bones[BONE_NAMES[PARENTS[b]]]
            eb.use_connect = False
    bpy.ops.object.mode_set(mode="OBJECT")
    view_layer.objects.active = previous
    for pb in arm_obj.pose.bones:
        pb.rotation_mode = "QUATERNION"

    out = {"armature": arm_obj}
    if mesh:
        skin = build_mesh(hand)
        out["mesh"] = _skinned_object(f"{name}Skin", skin.binding, skin.faces, arm_obj, collection)
    if layout is not None:
        binding = binding if binding is not None else layout.place(hand)[0]
        obj = _skinned_object(f"{name}Markers", binding, None, arm_obj, collection)
        obj["marker_names"] = layout.names
        out["markers"] = obj
    return out


def _skinned_object(name: str, binding: Binding, faces: np.ndarray | None, arm_obj: bpy.types.Object,
                    collection: bpy.types.Collection) -> bpy.types.Object:
    me = bpy.data.meshes.new(claim_name(bpy.data.meshes, name))
    me.vertices.add(len(binding.rest))
    me.vertices.foreach_set("co", binding.rest.astype(np.float32).ravel())
    if faces is not None and len(faces):
        me.loops.add(faces.size)
        me.loops.foreach_set("vertex_index", faces.astype(np.int32).ravel())
        me.polygons.add(len(faces))
        me.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
        me.polygons.foreach_set("loop_total", np.full(len(faces), 3, dtype=np.int32))
    me.update()
    me.validate()
    obj = bpy.data.objects.new(claim_name(bpy.data.objects, name), me)
    collection.objects.link(obj)
    obj.parent = arm_obj
    for b, bone_name in enumerate(BONE_NAMES):
        group = obj.vertex_groups.new(name=bone_name)
        for k in range(binding.bones.shape[1]):
            sel = (binding.bones[:, k] == b) & (binding.weights[:, k] > 0)
            # vertex_groups.add takes one weight per call: group the vertices by weight value.
            for w in np.unique(binding.weights[sel, k]):
                idx = np.flatnonzero(sel & (binding.weights[:, k] == w))
                group.add(idx.tolist(), float(w), "ADD")
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = arm_obj
    mod.use_deform_preserve_volume = False  # plain linear blend skinning, as in the core
    return obj


def pose_bases(hand: HandModel, poses: np.ndarray, arm_obj: bpy.types.Object) -> np.ndarray:
    """Pose-bone basis matrices ``(F, 20, 4, 4)`` that put the armature in ``poses (F, 26)``.

    Computed against Blender's own rest matrices (``bone.matrix_local``), so any rounding in the
    edit-bone roll cannot leak into the pose: Blender's pose matrix of bone b becomes
    ``S_b @ rest_b`` with ``S_b`` the core's skinning transform.
    """
    skin = _homogeneous(*hand.skinning_transforms(poses))
    rest = np.array([np.array(arm_obj.data.bones[name].matrix_local) for name in BONE_NAMES])
    posed = skin @ rest  # armature-space pose matrices
    bases = np.empty_like(posed)
    inv_rest = np.linalg.inv(rest)
    for b, p in enumerate(PARENTS):
        if p < 0:
            bases[:, b] = inv_rest[b] @ posed[:, b]
        else:
            bases[:, b] = (inv_rest[b] @ rest[p]) @ _rigid_inverse(posed[:, p]) @ posed[:, b]
    return bases


def _rigid_inverse(m: np.ndarray) -> np.ndarray:
    """The inverse of rigid 4x4 transforms ``(..., 4, 4)`` (rotation and translation: a pose matrix is
    one skinning transform times one rest matrix), ``[R^T, -R^T t]``: on a 3,000-frame take about
    25 times faster than a general inverse."""
    out = np.zeros_like(m)
    rt = np.swapaxes(m[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -(rt @ m[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def set_pose(arm_obj: bpy.types.Object, hand: HandModel, pose: np.ndarray) -> None:
    """Put the armature in one pose (26,) without keyframes."""
    bases = pose_bases(hand, np.asarray(pose)[None], arm_obj)[0]
    for b, name in enumerate(BONE_NAMES):
        arm_obj.pose.bones[name].matrix_basis = Matrix(bases[b].tolist())


def key_poses(arm_obj: bpy.types.Object, hand: HandModel, poses: np.ndarray, first_frame: int = 1) -> None:
    """Keyframe ``poses (F, 26)`` on frames ``first_frame ...`` in bulk: every bone's quaternion,
    and the root bone's location. Keys are LINEAR: consecutive captured frames, nothing to ease.
    Frames whose pose is NaN (unsolved) get no key."""
    poses = np.asarray(poses, dtype=float)
    solved = np.isfinite(poses).all(axis=1)
    frames = np.arange(first_frame, first_frame + len(poses), dtype=np.float64)[solved]
    poses = poses[solved]
    if not len(poses):
        return
    bases = pose_bases(hand, poses, arm_obj)
    quats = continuous_quaternions(matrix_to_quaternion(bases[..., :3, :3]), axis=0)
    if arm_obj.animation_data is None or arm_obj.animation_data.action is None:
        claim_name(bpy.data.actions, f"{arm_obj.name}Action")
    animio.ensure_action(arm_obj, f"{arm_obj.name}Action")
    for b, name in enumerate(BONE_NAMES):
        path = f'pose.bones["{name}"]'
        for i in range(4):
            fc = animio.find_fcurve(arm_obj, f"{path}.rotation_quaternion", i) or animio.new_fcurve(
                arm_obj, f"{path}.rotation_quaternion", i, group=name)
            animio.write_keys(fc, frames, quats[:, b, i])
        if PARENTS[b] < 0:
            for i in range(3):
                fc = animio.find_fcurve(arm_obj, f"{path}.location", i) or animio.new_fcurve(
                    arm_obj, f"{path}.location", i, group=name)
                animio.write_keys(fc, frames, bases[:, b, i, 3])


def solved_hand_collection(scene: bpy.types.Scene, source: str, name: str,
                           replaces: tuple | list = ()) -> bpy.types.Collection:
    """A new collection ``name`` in ``scene`` for the hand solved from ``source`` (a take's collection
    name, or a file; ``<take>:left`` / ``<take>:right`` for the hands of a two-hand take). An earlier
    solve of the same source (or of one in ``replaces``) goes first, with its objects, their data
    and actions: solving again replaces the hand instead of adding a second one."""
    gone = {source, *replaces}
    for old in [c for c in bpy.data.collections if c.get("mocap_solved_from") in gone]:
        objs = list(old.all_objects)
        owned = {o.data for o in objs if o.data is not None}
        owned |= {o.animation_data.action for o in objs if o.animation_data and o.animation_data.action}
        bpy.data.batch_remove(objs + [old])
        bpy.data.batch_remove([d for d in owned if d.users == 0])  # shared data stays
    collection = bpy.data.collections.new(claim_name(bpy.data.collections, name))
    collection["mocap_solved_from"] = source
    scene.collection.children.link(collection)
    return collection


#: The custom property of a solved rig that keeps its solve (see :func:`keep_solve`).
SOLVE_RECORD = "mocap_solve"


def build_solved_hand(solved, collection: bpy.types.Collection | None = None, name: str = "Hand",
                      scale: float = 1.0, digests: np.ndarray | None = None,
                      smooth_hz: float = 10.0) -> bpy.types.Object:
    """The calibrated rig of a :class:`~mocap_autolabel.core.solve.HandSolve`, keyed on every solved
    frame (``solved.first_frame`` on), its markers placed by the calibration; the solve is kept on the
    armature (:func:`keep_solve`, with ``digests`` and ``smooth_hz``).

    ``scale`` is the take's import Scale (Blender units per metre): the armature object gets it, so the
    rig, its skin and its markers sit on the take's empties while bones and keys stay in metres (the
    core's units, and what FBX/BVH export and a re-solve expect)."""
    cal = solved.calibration
    hand = cal.hand()
    objs = build_hand(hand, name=name, collection=collection, layout=solved.layout, binding=cal.binding(solved.layout))
    arm = objs["armature"]
    arm.scale = (scale, scale, scale)
    key_poses(arm, hand, solved.fit.poses, first_frame=solved.first_frame)
    keep_solve(arm, solved, digests, smooth_hz)
    return arm


def keep_solve(arm: bpy.types.Object, solved, digests: np.ndarray | None = None, smooth_hz: float = 10.0) -> None:
    """Keep a solve on its rig, saved with the .blend: the calibration (``mocap_calibration``, JSON)
    and :data:`SOLVE_RECORD`: its poses ``(F, 26)`` as solved (float64, NaN rows unsolved), the
    low-pass cut-off, and where given the :func:`~mocap_autolabel.core.fill.frame_digests` of the
    markers it was solved from with their fingerprint: Fill Gaps reuses the solve while they match
    and solves again only the frames that changed (:func:`~mocap_autolabel.core.fill.update_solve`)."""
    import json

    poses = np.ascontiguousarray(solved.fit.poses, dtype=np.float64)
    arm["mocap_calibration"] = json.dumps(solved.calibration.to_dict())
    arm["mocap_marker_rms_mm"] = solved.fit.overall_rms() * 1000
    record = {"layout": solved.layout.name, "first_frame": int(solved.first_frame), "rate": float(solved.rate),
              "frames": len(poses), "smooth_hz": float(smooth_hz), "poses": poses.reshape(-1)}
    if digests is not None:
        record["digests"] = np.ascontiguousarray(digests, dtype=np.int32)
        record["fingerprint"] = digests_fingerprint(digests)
    arm[SOLVE_RECORD] = record


def kept_solve(arm: bpy.types.Object) -> KeptSolve | None:
    """The solve a rig keeps (:func:`keep_solve`): its calibration, and its poses and digests where
    kept (a rig of an older version keeps only its calibration); None without a calibration."""
    import json

    from ..core.hand.calibrate import Calibration

    if "mocap_calibration" not in arm:
        return None
    cal = Calibration.from_dict(json.loads(arm["mocap_calibration"]), f"{arm.name}'s calibration")
    record = arm.get(SOLVE_RECORD)
    if record is None or "poses" not in record:
        return KeptSolve(cal)
    poses = np.asarray(record["poses"], dtype=np.float64).reshape(int(record["frames"]), -1).copy()
    digests = np.asarray(record["digests"], dtype=np.int32).copy() if "digests" in record else None
    return KeptSolve(cal, poses, digests, float(record.get("smooth_hz", 10.0)))


def update_solved_hand(arm: bpy.types.Object, solved, digests: np.ndarray | None = None,
                       smooth_hz: float = 10.0) -> None:
    """A rig keyed again with a solve of the same calibration (some frames solved again), and the
    solve kept (:func:`keep_solve`)."""
    key_poses(arm, solved.calibration.hand(), solved.fit.poses, first_frame=solved.first_frame)
    keep_solve(arm, solved, digests, smooth_hz)


def drive_armature(target: bpy.types.Object, hand: HandModel, poses: np.ndarray, bone_map: dict[str, str],
                   first_frame: int = 1) -> None:
    """Key a user's own hand armature with ``poses (F, 26)`` through ``bone_map`` (our bone -> theirs).

    Each mapped bone turns, in the world, exactly as our bone turns from its rest (so other rest
    orientations and bone rolls do not matter); unmapped bones ride along with their parent; the
    mapped root bone's head follows our wrist from its own rest place. Keys are written in bulk,
    frames with a NaN pose get none.
    """
    unknown = [b for b in bone_map if b not in BONE_NAMES]
    missing = [t for t in bone_map.values() if t not in target.data.bones]
    if unknown or missing:
        raise ValueError(f"bone map: unknown hand bones {unknown}, bones missing in {target.name!r}: {missing}")
    poses = np.asarray(poses, dtype=float)
    solved = np.isfinite(poses).all(axis=1)
    poses = poses[solved]
    frames = np.arange(first_frame, first_frame + len(solved), dtype=np.float64)[solved]
    if not len(poses):
        return
    skin_r, skin_t = hand.skinning_transforms(poses)  # (F, 20, 3, 3) rest -> posed, hand frame = world
    world = np.array(target.matrix_world)
    a = world[:3, :3] / np.linalg.norm(world[:3, :3], axis=0)  # the target object's rotation
    ours = {t: BONE_NAMES.index(b) for b, t in bone_map.items()}
    bones = list(target.data.bones)  # parents come before children
    rest = {b.name: np.array(b.matrix_local) for b in bones}
    posed: dict[str, np.ndarray] = {}
    bases: dict[str, np.ndarray] = {}
    n = len(poses)
    for bone in bones:
        r = rest[bone.name]
        parent = bone.parent.name if bone.parent else None
        m = np.empty((n, 4, 4))
        if parent is None:
            m[:] = r
        else:
            m[:] = posed[parent] @ (np.linalg.inv(rest[parent]) @ r)
        if bone.name in ours:
            change = a.T @ skin_r[:, ours[bone.name]] @ a  # our bone's turn, in the target's space
            m[:, :3, :3] = change @ r[:3, :3]
            if parent is None:
                wrist = (a.T @ poses[:, 3:6, None])[..., 0] / np.linalg.norm(world[:3, :3], axis=0)
                m[:, :3, 3] = r[:3, 3] + wrist
        posed[bone.name] = m
        if parent is None:
            bases[bone.name] = np.linalg.inv(r) @ m
        else:
            bases[bone.name] = np.linalg.inv(r) @ rest[parent] @ np.linalg.inv(posed[parent]) @ m
            bases[bone.name][:, :3, 3] = 0.0  # heads follow the hierarchy
    animio.ensure_action(target, f"{target.name}Action")
    for bone in bones:
        pb = target.pose.bones[bone.name]
        pb.rotation_mode = "QUATERNION"
        quats = continuous_quaternions(matrix_to_quaternion(bases[bone.name][:, :3, :3]), axis=0)
        path = f'pose.bones["{bone.name}"]'
        channels = [("rotation_quaternion", i, quats[:, i]) for i in range(4)]
        if bone.parent is None:
            channels += [("location", i, bases[bone.name][:, i, 3]) for i in range(3)]
        for prop, i, values in channels:
            fc = animio.find_fcurve(target, f"{path}.{prop}", i) or animio.new_fcurve(
                target, f"{path}.{prop}", i, group=bone.name)
            animio.write_keys(fc, frames, values)
