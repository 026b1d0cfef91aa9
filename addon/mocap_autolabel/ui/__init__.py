"""Menus, panels and the drag-and-drop file handler."""

from .menus import MOCAPAL_FH_markers

classes = (MOCAPAL_FH_markers,)
