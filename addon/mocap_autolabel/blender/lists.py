"""The panel's lists of a take's review: its review queue (what to look at, in that order) and its corrections.

Both live in the scene's settings (``scene.mocap_autolabel``, :mod:`.properties`) so that the
panel's UILists can show them and undo restores them; they are derived from the take's stored
labeling and review (:mod:`.takes`) and rebuilt after every change (and when Confident at or the
queue's filters change).
"""

from __future__ import annotations

import bpy

from ..core.labeling import NULL, unlabeled_point_names
from ..core.review import describe, review_queue, uncertain_segments
from .takes import current_take, first_frame, load_state, trajectory_names
from .timeline import mark_bad_frames

#: How many segments the list holds at most (the first of the queue).
LIST_LIMIT = 1000


def queue_filters(settings) -> dict:
    """The review queue's filters as the panel sets them (keyword arguments of ``core.review.review_queue``)."""
    return {"labeled_only": bool(settings.queue_labeled_only), "min_frames": int(settings.queue_min_frames)}


def refresh_uncertain(scene: bpy.types.Scene, take_coll: bpy.types.Collection, labeling) -> None:
    """Rebuild the scene's list of the take's review queue (``core.review.review_queue`` at the panel's
    Confident at and filters: labeled segments in doubt first, then unlabeled pieces that may be a
    marker), each under its empty's name and its raw trajectory's (``*N``); the count of uncertain
    segments the filters leave out; the Timeline's marks; and the list of the take's corrections."""
    settings = scene.mocap_autolabel
    first = first_frame(take_coll)
    filters = queue_filters(settings)
    idx = review_queue(labeling, settings.sure, **filters)
    points = unlabeled_point_names(current_take(take_coll).names, labeling.names) if len(idx) else []
    items = settings.uncertain
    items.clear()
    for i in idx[:LIST_LIMIT]:
        item = items.add()
        item.point = points[labeling.slot[i]]
        item.label = labeling.names[labeling.label[i]] if labeling.label[i] >= 0 else item.point
        item.unlabeled = bool(labeling.label[i] < 0)
        item.slot = int(labeling.slot[i])
        item.frame_start = int(labeling.start[i]) + first
        item.frame_end = int(labeling.stop[i]) - 1 + first
        item.confidence = float(labeling.confidence[i])
    settings.uncertain_total = len(idx)
    settings.uncertain_hidden = len(uncertain_segments(labeling, settings.sure)) - len(idx)
    mark_bad_frames(scene, take_coll, labeling, settings.sure, **filters)  # the Timeline follows the queue
    # Writing the index directly would jump; the property's raw storage does not call the update.
    settings["uncertain_index"] = -1
    refresh_corrections(scene, take_coll, labeling)


def refresh_corrections(scene: bpy.types.Scene, take_coll: bpy.types.Collection, labeling) -> None:
    """Rebuild the scene's list of the take's corrections: its locked decisions in the order they
    were made (the list index is the constraint's place, which Delete Correction takes), then its
    splits."""
    settings = scene.mocap_autolabel
    review = load_state(take_coll).review
    # Only a take with corrections needs its point names (reading them back from the scene costs).
    names = trajectory_names(take_coll) if review.constraints or review.splits else []
    first = first_frame(take_coll)
    items = settings.corrections
    items.clear()
    for c in review.constraints:
        item = items.add()
        item.kind = "ghost" if c.label == NULL else "label"
        item.text = describe(c, labeling.names, names, first)
        item.slot, item.frame_start, item.frame_end = c.slot, c.start + first, c.stop - 1 + first
    for slot, frame in review.splits:
        item = items.add()
        item.kind = "split"
        item.text = f"split {names[slot]} at frame {frame + first}"
        item.slot, item.frame_start, item.frame_end = slot, frame + first, frame + first
    if settings.corrections_index >= len(items):
        settings.corrections_index = len(items) - 1
