"""mocap_autolabel: automatic labeling of optical hand motion capture.

As a Blender extension this module registers the operators and UI; as a Python package
(``python -m mocap_autolabel``) it is the command line. ``bpy`` is imported only inside
register/unregister, so the core and the CLI work without Blender.
"""

from .core.version import __version__ as __version__  # one place: core/version.py

#: Shortcuts of the review, all Shift+Alt+key in the Frames keymap (every editor: the viewport, the
#: Dope Sheet, the Graph Editor, the Timeline): (operator, key, properties). Blender's default
#: keymap binds none of these in those editors' Object-mode and animation keymaps (a test checks).
SHORTCUTS = (("mocap_autolabel.next_uncertain", "RIGHT_ARROW", {"previous": False}),
             ("mocap_autolabel.next_uncertain", "LEFT_ARROW", {"previous": True}),
             ("mocap_autolabel.assign_label", "A", {}),
             ("mocap_autolabel.swap_labels", "S", {}),
             ("mocap_autolabel.unlabel", "U", {}),
             ("mocap_autolabel.lock", "L", {}))
_keymap_items: list = []


def _classes():
    from . import operators, ui
    from .blender import properties

    return properties.classes + operators.classes + ui.classes


def _add_shortcuts() -> None:
    import bpy

    keyconfig = bpy.context.window_manager.keyconfigs.addon
    if keyconfig is None:  # background mode has no add-on keyconfig
        return
    keymap = keyconfig.keymaps.new(name="Frames")
    for idname, key, props in SHORTCUTS:
        item = keymap.keymap_items.new(idname, key, "PRESS", shift=True, alt=True)
        for name, value in props.items():
            setattr(item.properties, name, value)
        _keymap_items.append((keymap, item))


def register() -> None:
    import bpy

    from .blender import properties
    from .ui import overlay
    from .ui.menus import MENU_PARENTS, menu_import, menu_mocap

    for cls in _classes():
        bpy.utils.register_class(cls)
    properties.register()
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    for parent in MENU_PARENTS:
        getattr(bpy.types, parent).append(menu_mocap)
    overlay.register()
    _add_shortcuts()


def unregister() -> None:
    import bpy

    from .blender import properties
    from .ui import overlay
    from .ui.menus import MENU_PARENTS, menu_import, menu_mocap

    for keymap, item in _keymap_items:
        keymap.keymap_items.remove(item)
    _keymap_items.clear()
    overlay.unregister()
    for parent in MENU_PARENTS:
        getattr(bpy.types, parent).remove(menu_mocap)
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    properties.unregister()
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
