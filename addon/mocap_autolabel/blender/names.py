"""Names of a take's datablocks (objects, collections, meshes) that clash with no other take's."""

from __future__ import annotations


def free_name(wanted: str, datablocks, owner: str, current=None) -> str:
    """A name for a datablock of a take that clashes with no other: ``wanted`` while it is free in
    ``datablocks`` (``bpy.data.objects``, ``bpy.data.collections``...), else ``<owner>:<wanted>``.

    Blender names are unique per file and it would append ``.001`` to the second ``IndexTip`` or
    ``Labeled``: that hides which take an object belongs to, and a script looking for
    ``IndexTip`` finds the wrong one. The first take in a scene keeps the plain names; a later
    take whose names are taken gets its collection's name as a prefix (``take2:IndexTip``, the
    subject-prefix style capture software writes). ``current`` is the datablock being renamed,
    which may already hold the name.
    """
    held = datablocks.get(wanted)
    if held is None or held == current:
        return wanted
    return f"{owner}:{wanted}"
