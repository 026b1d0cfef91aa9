"""Blender operators; each calls the core and the blender layer, nothing more."""

from .cleanup import classes as cleanup_classes
from .corrections import classes as correction_classes
from .export import classes as export_classes
from .fill import classes as fill_classes
from .import_markers import MOCAPAL_OT_import_markers
from .label import classes as label_classes
from .make_layout import classes as make_layout_classes
from .navigation import classes as navigation_classes
from .retarget import classes as retarget_classes
from .solve_hand import MOCAPAL_OT_solve_hand
from .timeline import classes as timeline_classes

classes = ((MOCAPAL_OT_import_markers, MOCAPAL_OT_solve_hand) + label_classes + correction_classes + navigation_classes
           + export_classes + timeline_classes + fill_classes + make_layout_classes + retarget_classes
           + cleanup_classes)
