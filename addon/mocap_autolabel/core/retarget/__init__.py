"""Retargeting: the solved hands onto a character's own armature (Blender-free).

- :mod:`.target`: :class:`TargetRig`, a character armature as arrays (what Blender's bones hold).
- :mod:`.source`: :class:`SourceHand`, our solved hand per frame (from poses or from a keyed rig).
- :mod:`.bone_maps`: the rig conventions (Rigify, Mixamo, UE5, Unity, generic names), automatic
  bone maps, presets saved as JSON, and the names of our bones for engine exports.
- :mod:`.transfer`: the rotations that put a character's finger bones in the solved pose
  (reference alignment for rests that differ, the wrist modes, pinch preservation).
"""
