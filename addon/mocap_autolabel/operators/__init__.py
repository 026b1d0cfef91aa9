"""Blender operators; each calls the core and the blender layer, nothing more."""

from .fill import classes as fill_classes
from .import_markers import MOCAPAL_OT_import_markers
from .review import classes as review_classes
from .solve_hand import MOCAPAL_OT_solve_hand
from .timeline import classes as timeline_classes

classes = (MOCAPAL_OT_import_markers, MOCAPAL_OT_solve_hand) + review_classes + timeline_classes + fill_classes
