"""Blender operators; each calls the core and the blender layer, nothing more."""

from .import_markers import MOCAPAL_OT_import_markers

classes = (MOCAPAL_OT_import_markers,)
