"""FBX and BVH of an animated armature through Blender's own exporters, headless.

Both write to a temporary file that is renamed into place only when the exporter succeeded.
"""

from __future__ import annotations

import os

import bpy

from ..core.atomic import atomic_output
from ..core.errors import MocapInputError
from ..core.process import as_solves


def _only_selected(arm_obj: bpy.types.Object) -> None:
    view_layer = bpy.context.view_layer
    for obj in view_layer.objects:
        obj.select_set(False)
    arm_obj.select_set(True)
    view_layer.objects.active = arm_obj


def _run(path: str, export) -> None:
    with atomic_output(path) as tmp:
        result = export(tmp)
        if "FINISHED" not in result or not os.path.isfile(tmp):
            raise MocapInputError(path, f"Blender's exporter did not finish ({', '.join(result)})")


def export_fbx(arm_obj: bpy.types.Object, path: str, frame_start: int, frame_end: int) -> None:
    """The armature and its animation (every frame baked, no simplification) as FBX."""
    _only_selected(arm_obj)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = frame_start, frame_end
    _run(path, lambda tmp: bpy.ops.export_scene.fbx(
        filepath=tmp, use_selection=True, object_types={"ARMATURE"}, add_leaf_bones=False,
        bake_anim=True, bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
        bake_anim_simplify_factor=0.0, bake_anim_force_startend_keying=True))


def export_bvh(arm_obj: bpy.types.Object, path: str, frame_start: int, frame_end: int) -> None:
    """The armature's animation as BVH (Euler rotations in each bone's native order)."""
    _only_selected(arm_obj)
    _run(path, lambda tmp: bpy.ops.export_anim.bvh(filepath=tmp, frame_start=frame_start, frame_end=frame_end,
                                                   rotate_mode="NATIVE", global_scale=1.0))


def save_blend(path: str) -> None:
    """Save the open scene to ``path``, complete or not at all."""
    with atomic_output(path) as tmp:
        bpy.ops.wm.save_as_mainfile(filepath=tmp, check_existing=False, copy=True)


def export_labeled_c3d(take_coll: bpy.types.Collection, path: str) -> None:
    """Write a reviewed take of the scene as a labeled C3D (``core.labeling.labeled_take``): the
    layout's markers by name, then one point per trajectory left unlabeled, named as its empty in
    the scene (the file's own name, or ``*<slot>``).

    The file is in the take's own terms, not the scene's: positions in the file's units (the
    import's Scale taken off), frames numbered as the file numbered them (the import's Frame
    Offset taken off), so a round trip gives the original first frame. Filled samples (the
    ``GENERATED`` keys of *Fill Gaps*) are written as computed: residual 0, no camera bits.
    """
    import numpy as np

    from ..core.formats.c3d import write_c3d
    from ..core.labeling import labeled_take
    from ..core.take import UNIT_SCALE
    from .fill import filled_keys
    from .scene import file_frames
    from .takes import current_take, load_state

    take = file_frames(take_coll, current_take(take_coll))
    units = take.source_units if take.source_units in UNIT_SCALE else "mm"
    labeling = load_state(take_coll).labeling
    out = labeled_take(take, labeling)
    idx, labels, xyz = filled_keys(take_coll, len(labeling.names))
    if len(idx):  # the fills (Fill Gaps), written as computed samples
        out.filled = np.zeros(out.valid.shape, dtype=bool)
        out.positions[idx, labels] = xyz
        out.filled[idx, labels] = True
    write_c3d(out, path, units=units)


def write_solved_scene(take, solved, blend: str | None = None, fbx: str | None = None,
                       bvh: str | None = None) -> dict[str, str]:
    """A fresh scene with the labeled markers beside the solved, keyed rig; then the asked-for files.

    ``solved`` is one HandSolve, or ``[(side, HandSolve), ...]`` for a take of two hands: one rig
    per hand in the one .blend (armatures ``Hand_L`` / ``Hand_R``, collections ``left hand`` /
    ``right hand``), and one FBX / BVH per hand with the side before the extension
    (``take_left.fbx``).

    Returns ``{"blend" | "fbx" | "bvh" (+ "_left" / "_right"): path}`` of what was written.
    """
    from ..core.hands import sided_path
    from .armature import build_solved_hand, solved_hand_collection
    from .scene import ImportOptions, build_take

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    coll = build_take(take, scene, ImportOptions())
    hands = as_solves(solved)
    rigs = []
    for side, one in hands:
        name = f"Hand_{side[0].upper()}" if side else "Hand"
        folder = solved_hand_collection(scene, f"{coll.name}:{side}" if side else coll.name,
                                        f"{side} hand" if side else "Hand")
        rigs.append((side, one, build_solved_hand(one, folder, name=name)))
    out = {}
    if blend:
        save_blend(blend)
        out["blend"] = blend
    for side, one, arm in rigs:
        first, last = one.first_frame, one.first_frame + take.n_frames - 1
        key = f"_{side}" if side else ""
        for kind, path, export in (("fbx", fbx, export_fbx), ("bvh", bvh, export_bvh)):
            if path:
                export(arm, sided_path(path, side), first, last)
                out[kind + key] = sided_path(path, side)
    return out



def write_review_scene(take, layout_ref: str, labeling, blend: str, method: str = "set", temporal: str = "vote",
                       solved=None) -> str:
    """A fresh scene for review: the raw take, its labeled and unlabeled markers keyed by confidence,
    the review state (so the add-on's panel picks it up), and the solved hand if given; saved to ``blend``.

    ``solved`` is one HandSolve, or ``[(side, HandSolve), ...]`` for a take of two hands (rigs
    ``Hand_L`` / ``Hand_R``, which the panel's Solve Hand replaces when it solves the take again)."""
    from ..core.layout import load_layout
    from ..core.review import Review
    from .armature import build_solved_hand, solved_hand_collection
    from .review import commit, write_labeling
    from .scene import ImportOptions, build_take
    from .takes import ReviewState

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    coll = build_take(take, scene, ImportOptions())
    write_labeling(coll, take, load_layout(layout_ref), labeling)
    commit(scene, coll, ReviewState(labeling, Review(), layout_ref, method, temporal))
    hands = as_solves(solved)
    for side, one in hands:
        if side:  # sources as Solve Hand names them, so that solving the take again replaces these rigs
            build_solved_hand(one, solved_hand_collection(scene, f"{coll.name}:{side}", f"{coll.name} {side} hand"),
                              name=f"Hand_{side[0].upper()}")
        else:
            build_solved_hand(one, solved_hand_collection(scene, coll.name, "Hand"))
    save_blend(blend)
    return blend
