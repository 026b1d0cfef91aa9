"""mocap_autolabel: automatic labeling of optical hand motion capture.

As a Blender extension this module registers the operators and UI; as a Python package
(``python -m mocap_autolabel``) it is the command line. ``bpy`` is imported only inside
register/unregister, so the core and the CLI work without Blender.
"""

__version__ = "0.1.0"


def _classes():
    from . import operators, ui

    return operators.classes + ui.classes


def register() -> None:
    import bpy

    from .ui.menus import menu_import

    for cls in _classes():
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)


def unregister() -> None:
    import bpy

    from .ui.menus import menu_import

    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
