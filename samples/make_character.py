"""A stand-in for the animator's character, for the demo: Rigify's human meta-rig (bundled with
Blender), saved as a .blend that ``solve --retarget`` keys the solved hand onto.

    python samples/make_character.py out/character.blend
"""

from __future__ import annotations

import sys


def main(path: str) -> None:
    import importlib

    import bpy
    from mocap_autolabel.blender.export import save_blend

    addon_utils = importlib.import_module("addon_utils")  # Blender's own: importable once bpy is
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    bpy.context.active_object.name = "Character"
    addon_utils.disable("rigify", default_set=True)  # the file needs no add-on to be opened
    save_blend(path)
    print(f"  character {path} (Rigify's human meta-rig, armature 'Character')")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python samples/make_character.py OUT.blend")
    main(sys.argv[1])
