"""Menus, panels, the viewport overlay and the drag-and-drop file handler."""

from .menus import MOCAPAL_FH_markers, MOCAPAL_MT_mocap
from .panels import classes as panel_classes

classes = (MOCAPAL_FH_markers, MOCAPAL_MT_mocap) + panel_classes
