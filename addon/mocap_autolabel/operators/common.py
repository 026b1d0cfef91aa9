"""What the operators share: the take an operator acts on (the panel's, or the selected marker's),
the messages of their polls, and selecting a marker.

What works on a whole take (Label, Re-solve, Previous / Next, the lists, Export, Solve Hand and
Fill Gaps) works on the take in the panel's Take field (an import puts the new take there; Fill
Gaps fills that take's selected markers, or all of them); the corrections (Assign, Swap, Unlabel,
Split, Lock, Unlock) work on the take of the selected markers.
"""

from __future__ import annotations

import bpy


def _is_take(coll) -> bool:
    return coll is not None and coll.name in bpy.data.collections and "mocap_source" in coll


def panel_take(context) -> bpy.types.Collection | None:
    """The take in the panel's Take field (what Label, Re-solve, Previous / Next and Export act on);
    where the field is empty, the active marker's take. A collection that is not an imported take
    is never returned."""
    from ..blender.takes import take_collection

    settings = context.scene.mocap_autolabel
    if settings.take is not None:
        return settings.take if _is_take(settings.take) else None
    return take_collection(context.active_object) if context.active_object else None


def context_take(context) -> bpy.types.Collection | None:
    """The take of the active marker (what a correction acts on), else the panel's take."""
    from ..blender.takes import take_collection

    found = take_collection(context.active_object) if context.active_object else None
    return found if _is_take(found) else panel_take(context)


def reviewed_take(context) -> bpy.types.Collection | None:
    """:func:`context_take` where it has been labeled (holds a review), else None."""
    from ..blender.takes import has_review

    coll = context_take(context)
    return coll if has_review(coll) else None


def beside_source(coll: bpy.types.Collection, ending: str) -> str:
    """A default output path for a take: its source file's path with ``ending`` instead of the extension
    (``take_labeled.c3d``), or the collection's name with it where the take has no source file."""
    import os

    src = coll.get("mocap_source") or coll.name
    return os.path.splitext(bpy.path.abspath(src) if src else coll.name)[0] + ending


def reviewed_panel_take(context) -> bpy.types.Collection | None:
    """:func:`panel_take` where it has been labeled, else None."""
    from ..blender.takes import has_review

    coll = panel_take(context)
    return coll if has_review(coll) else None


def _present(cls, found, message: str) -> bool:
    """A poll result: whether ``found`` exists, with ``message`` shown where it does not."""
    if found is None:
        cls.poll_message_set(message)
        return False
    return True


def _labeled_take_present(cls, context) -> bool:
    """A poll for operators that work on a labeled take: whether the panel's take is one, with a
    message that says what to do where it is not."""
    return _present(cls, reviewed_panel_take(context),
                    _not_a_take(context) or "Label a take first (Mocap sidebar tab > Label)")


def _not_a_take(context) -> str | None:
    """Why the panel's Take field cannot be worked on (it holds a collection that is not a take)."""
    take = context.scene.mocap_autolabel.take
    if take is not None and not _is_take(take):
        return f"'{take.name}' is not an imported take: choose a take in the Take field"
    return None


def _select_only(context, obj) -> None:
    """Make ``obj`` the only selected object and the active one (where it is in the view layer)."""
    if obj is None or obj.name not in context.view_layer.objects:
        return
    for other in context.selected_objects:
        other.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj
