"""Menus, panels, the viewport overlay and the drag-and-drop file handler."""

from .menus import MOCAPAL_FH_markers
from .panels import classes as panel_classes

classes = (MOCAPAL_FH_markers,) + panel_classes
