"""Bone maps: which of a character's bones is which bone of our hand, for the common rig conventions.

API (the Blender layer, the CLI and the exports rely on it):

- ``CONVENTIONS``: registry ``{name: Convention subclass}`` with at least ``rigify``, ``mixamo``,
  ``ue5``, ``unity`` and ``generic``; each has ``name``, ``label`` (UI text) and
  ``bone_name(bone, side) -> str | None`` (our bone -> its bone name, None where the convention
  has no such bone), and ``match(names) -> dict[side, dict[our bone, their bone]]``.
- :class:`BoneMap`: ``convention`` and ``sides`` ``{"left" | "right": {our bone: their bone}}``;
  ``to_dict`` / ``from_dict``, ``save(path)`` / ``load(path)`` (JSON, atomic write).
- :func:`auto_map` ``(names, parents) -> BoneMap``: the convention that maps most hand bones
  (prefixes such as ``mixamorig:`` or ``DEF-`` allowed), else the generic name patterns.
- :func:`export_names` ``(convention, side) -> {our bone: name}``: names of our rig's bones in a
  convention, for engine exports (``ours`` keeps ours).

Our bones are :data:`..hand.skeleton.BONE_NAMES` (``palm``, ``thumb_meta``, ``thumb_prox``,
``thumb_dist``, ``index_meta`` ... ``little_dist``).
"""

from __future__ import annotations
