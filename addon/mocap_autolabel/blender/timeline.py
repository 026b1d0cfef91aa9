"""The bad-frames overview: timeline markers where a take's labels need a look.

After every labeling or edit, the worst runs of frames (samples of the review queue's segments, with
the panel's filters, or labels missing inside their span, scored by ``core.review.bad_runs``) get one
timeline marker each, at the run's first
frame, so the Timeline and the Dope Sheet show at a glance where to look, and Blender's own
*Jump to Next Marker* walks them. The markers are the take's: named ``?<take>: ...``, they are
replaced whenever its labels change and never touch markers of the user or of another take.
"""

from __future__ import annotations

import re

import bpy

from ..core.review import BadRun, bad_runs
from .takes import first_frame

#: How many runs get a marker (worst first): more would bury the Timeline.
MARKER_LIMIT = 20
#: Every marker of a take starts with this, then the take's name and a colon.
MARKER_PREFIX = "?"


def marker_prefix(take_coll: bpy.types.Collection) -> str:
    return f"{MARKER_PREFIX}{take_coll.name}:"


def marker_name(take_coll: bpy.types.Collection, run: BadRun) -> str:
    """``?<take>: 3 uncertain, 1 missing`` (the most queued samples and missing labels in one frame of the
    run), at most 63 characters."""
    parts = [f"{run.uncertain} uncertain" if run.uncertain else "", f"{run.missing} missing" if run.missing else ""]
    return f"{marker_prefix(take_coll)} {', '.join(p for p in parts if p)}"[:63]


def clear_bad_frames(scene: bpy.types.Scene, take_coll: bpy.types.Collection) -> None:
    prefix = marker_prefix(take_coll)
    for marker in [m for m in scene.timeline_markers if m.name.startswith(prefix)]:
        scene.timeline_markers.remove(marker)


#: A marker :func:`marker_name` wrote: the take's name, then what the run holds.
_OURS = re.compile(rf"^{re.escape(MARKER_PREFIX)}(.+): (\d+ uncertain(, \d+ missing)?|\d+ missing)$")


def clear_orphaned_markers(scene: bpy.types.Scene) -> int:
    """Remove the markers of takes that are no longer in ``scene`` (a take deleted since it was
    labeled); returns how many. A user's own markers never match :data:`_OURS`."""
    present = {c.name for c in scene.collection.children_recursive}
    orphans = [m for m in scene.timeline_markers
               if (found := _OURS.match(m.name)) is not None and found.group(1) not in present]
    for marker in orphans:
        scene.timeline_markers.remove(marker)
    return len(orphans)


def mark_bad_frames(scene: bpy.types.Scene, take_coll: bpy.types.Collection, labeling, sure: float,
                    limit: int = MARKER_LIMIT, **filters) -> list[BadRun]:
    """Replace the take's timeline markers by one per worst run (at most ``limit``); returns the runs.
    ``filters``: the review queue's (``labeled_only``, ``min_frames``; see ``core.review.review_queue``)."""
    clear_bad_frames(scene, take_coll)
    clear_orphaned_markers(scene)
    runs = bad_runs(labeling, sure, limit, **filters)
    first = first_frame(take_coll)
    for run in runs:
        scene.timeline_markers.new(marker_name(take_coll, run), frame=run.start + first)
    return runs
