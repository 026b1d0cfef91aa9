"""A labeled take in the scene: labeled and unlabeled empties keyed by confidence, and the labeling run.

The take collection made by the importer (``scene.build_take``) holds the whole review:

- its raw empties (moved into a hidden "Raw" child collection at the first labeling): the
  take is read back from them, so a saved .blend is a complete review without the source file;
  or, for a take imported as a point cloud, the one raw point-cloud object (``pointcloud.py``),
  moved the same way, from whose attributes the take is read back;
- a "Labeled" child collection: one empty per layout marker, keyed where the label has a sample,
  with keyframe types by confidence class and channel groups coloured by finger;
- an "Unlabeled" child collection: one empty per point slot that has unassigned samples;
- custom properties ``mocap_labeling`` (the Labeling's arrays), ``mocap_review`` (the
  constraints and splits) and ``mocap_settings`` (layout, method...): saved with the file and
  restored by undo together with the keys.

Finding the take, reading it back and the stored state are :mod:`.takes`; the empties' colours and
lookups :mod:`.markers`; the panel's lists :mod:`.lists`. This module writes labels into the scene
(:func:`write_labeling`), runs a labeling of a scene's take (:class:`LabelRequest`) and stores its
result (:func:`finish_label`, :func:`edit`). The names of :mod:`.takes` and :mod:`.markers` stay
importable from here.

Nothing here decides labels: that is ``core.process`` (labeling, checks) and ``core.review``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.hands import labeling_sides, relabel_plan
from ..core.labeling import Labeling, unlabeled_point_names
from ..core.layout import Layout, load_layout
from ..core.review import (
    CLASS_NAMES,
    KEY_TYPES,
    SURE,
    Review,
    changed_labels,
    marker_classes,
    null_classes,
    remap_review,
    uncertain_segments,
)
from ..core.stages.decide import RAW
from ..core.take import Take
from .lists import refresh_uncertain
from .markers import (
    FINGER_COLOR_SETS,
    FINGERS,
    finger_of,
    key_type_values,
    labeled_object,  # noqa: F401 (kept importable from here)
    labeled_objects,
    null_objects,
    object_for,  # noqa: F401 (kept importable from here)
    slot_of,  # noqa: F401 (kept importable from here)
    theme_color,
)
from .names import free_name
from .pointcloud import is_cloud
from .scene import key_track, new_marker
from .takes import (
    ReviewState,
    current_take,
    first_frame,
    has_review,
    key_sure,
    load_state,
    raw_cloud,  # noqa: F401 (kept importable from here)
    raw_markers,  # noqa: F401 (kept importable from here)
    read_take,  # noqa: F401 (kept importable from here)
    sample_index,  # noqa: F401 (kept importable from here)
    scene_sure,
    state_layout,
    store_state,
    take_collection,  # noqa: F401 (kept importable from here)
    trajectory_names,  # noqa: F401 (kept importable from here)
)

# --- writing labels into the scene ----------------------------------------------------------

def _child(take_coll: bpy.types.Collection, key: str, name: str) -> bpy.types.Collection:
    coll = take_coll.get(key)
    if coll is None or coll.name not in bpy.data.collections:
        coll = bpy.data.collections.new(free_name(name, bpy.data.collections, take_coll.name))
        take_coll.children.link(coll)
        coll["mocap_take"] = take_coll
        take_coll[key] = coll
    return coll


#: The child collection of "Labeled" that holds each hand's empties in a two-hand take.
HAND_COLLECTIONS = {"left": "Left hand", "right": "Right hand"}


def _hand_collections(take_coll: bpy.types.Collection, labeled: bpy.types.Collection,
                      sides: list[str]) -> list[bpy.types.Collection]:
    """The collection each hand's labeled empties go in: "Labeled" itself for one hand; for two, a
    "Left hand" and a "Right hand" child of it (one Labeled collection per hand, which the Outliner
    shows and hides as a whole, under the one "Labeled" that the panel, export and a later take's
    names keep finding)."""
    if len(sides) < 2:
        return [labeled]
    out = []
    for side in sides:
        key = f"mocap_labeled_{side}"
        coll = take_coll.get(key)
        if coll is None or coll.name not in bpy.data.collections:
            coll = bpy.data.collections.new(free_name(HAND_COLLECTIONS[side], bpy.data.collections, take_coll.name))
            labeled.children.link(coll)
            coll["mocap_take"] = take_coll  # take_collection() finds the take from a hand's empty
            coll["mocap_side"] = side
            take_coll[key] = coll
        out.append(coll)
    return out


#: Appended to an imported empty's name when it moves into "Raw" and a label has that name.
RAW_SUFFIX = " (raw)"


def _hide_raw(take_coll: bpy.types.Collection) -> None:
    """Move the imported empties into a hidden "Raw" child as ``<name> (raw)``: the labeled and
    unlabeled empties now show every sample, each once, and take the plain names (Blender names
    are unique per file: an unlabeled ``*3``, or a labeled ``BackHand1`` where the file already
    named its points, would otherwise be ``*3.001`` or ``BackHand1.001``). The point's own name
    stays in ``mocap_point``.
    """
    made = take_coll.get("mocap_raw") is None or take_coll["mocap_raw"].name not in bpy.data.collections
    raw = _child(take_coll, "mocap_raw", "Raw")
    if made:
        hide_in_view_layers(raw)
    for obj in list(take_coll.objects):
        if "mocap_slot" in obj or is_cloud(obj):
            raw.objects.link(obj)
            take_coll.objects.unlink(obj)
        if "mocap_slot" in obj:
            obj.name = free_name(obj.get("mocap_point", obj.name) + RAW_SUFFIX, bpy.data.objects, take_coll.name,
                                 current=obj)


def hide_in_view_layers(coll: bpy.types.Collection) -> None:
    """Hide a collection with the Outliner's eye (its layer collection's ``hide_viewport``) in every
    view layer that shows it, and from renders, once, when it is made: the reviewer toggles it back
    with the eye. The collection's own ``hide_viewport`` (the monitor icon, off the Outliner's
    default filter) stays off, and later edits leave the eye as the reviewer set it."""
    coll.hide_viewport = False
    coll.hide_render = True
    for scene in bpy.data.scenes:
        for view_layer in scene.view_layers:
            for layer in _layer_collections(view_layer.layer_collection, coll):
                layer.hide_viewport = True


def _layer_collections(layer: bpy.types.LayerCollection, coll: bpy.types.Collection):
    """The layer collections of ``coll`` under ``layer`` (a collection may be linked in several places)."""
    for child in layer.children:
        if child.collection == coll:
            yield child
        yield from _layer_collections(child, coll)


def write_labeling(take_coll: bpy.types.Collection, take: Take, layout: Layout, labeling: Labeling,
                   previous: Labeling | None = None, sure: float = SURE,
                   previous_sure: float | None = None) -> dict[str, int]:
    """Show ``labeling`` in the scene; with ``previous``, rewrite only the markers that changed.

    Each labeled empty is keyed where its label has a sample; each key's type is its confidence
    class (:data:`core.review.KEY_TYPES`) at the threshold ``sure`` (the panel's Confident at).
    Slots with unassigned samples get an empty in "Unlabeled", keyed the same way. With
    ``previous``, the keys show it at ``previous_sure`` (default: the threshold stored on the take
    when they were written), so a new threshold rewrites exactly the markers it recolours.

    Returns:
        counts of rewritten labeled and unlabeled empties.
    """
    _hide_raw(take_coll)
    labeled = _child(take_coll, "mocap_labeled", "Labeled")
    unlabeled = _child(take_coll, "mocap_unlabeled", "Unlabeled")
    scale = float(take_coll.get("mocap_scale", 1.0))
    frames_all = np.arange(take.n_frames, dtype=np.float32) + first_frame(take_coll)
    types = key_type_values()
    per = labeling.per_sample()
    classes = marker_classes(labeling, sure)
    m = len(layout)
    n_labels = len(labeling.names)  # M, or 2M for two hands (the left hand's first)
    hand_colls = _hand_collections(take_coll, labeled, labeling_sides(labeling.info))
    if previous is not None and (previous.names != labeling.names or previous.per_sample().shape != per.shape):
        previous = None
    if previous_sure is None:
        previous_sure = key_sure(take_coll)
    take_coll["mocap_sure"] = float(sure)  # the threshold the keys' colours now show

    # Labeled markers: (F, M, 3) positions in layout order.
    f, s = np.nonzero(per >= 0)
    xyz = np.full((take.n_frames, n_labels, 3), np.nan, dtype=np.float32)
    xyz[f, per[f, s]] = take.positions[f, s] * scale
    todo = range(n_labels) if previous is None else changed_labels(previous, labeling, previous_sure, sure).tolist()
    from .fill import forget_fills, keep_fills, restore_fills

    kept = keep_fills(take_coll, previous, labeling, todo, take.n_frames)  # markers only recoloured
    objs = labeled_objects(labeled)
    for label in todo:
        obj = objs.get(label)
        finger = finger_of(layout, label % m)  # label % M: the layout marker, on either hand
        if obj is None:
            obj = new_marker(free_name(labeling.names[label], bpy.data.objects, take_coll.name),
                             hand_colls[min(label // m, len(hand_colls) - 1)], scale)
            obj["mocap_label"] = label
            obj.color = (*theme_color(finger), 1.0)
        valid = classes[:, label] >= 0
        curves = key_track(obj, frames_all, valid, xyz[:, label], types[classes[valid, label]],
                           group=finger.title(), action=f"{take_coll.name}|{obj.name}", hold_type="MOVING_HOLD")
        for fc in curves:
            if fc.group is not None and fc.group.color_set != FINGER_COLOR_SETS[finger]:
                fc.group.color_set = FINGER_COLOR_SETS[finger]
    restore_fills(take_coll, take, layout, labeling, kept)
    forget_fills(take_coll, [label for label in todo if label not in kept])  # their samples changed

    # Unlabeled samples, one empty per slot that has any.
    null_class = null_classes(labeling, sure)
    if previous is None:
        slots = np.flatnonzero((null_class >= 0).any(axis=0))
    else:
        slots = np.flatnonzero((null_classes(previous, previous_sure) != null_class).any(axis=0))
    nulls = null_objects(unlabeled)
    point_names = unlabeled_point_names(take.names, labeling.names)
    for slot in slots:
        valid = null_class[:, slot] >= 0
        obj = nulls.get(int(slot))
        if obj is None:
            if not valid.any():
                continue
            obj = new_marker(free_name(point_names[slot], bpy.data.objects, take_coll.name), unlabeled, scale)
            obj["mocap_null"] = int(slot)
            obj["mocap_point"] = take.names[slot]
        key_track(obj, frames_all, valid, take.positions[:, slot] * scale, types[null_class[valid, slot]],
                  action=f"{take_coll.name}|{obj.name}", hold_type="MOVING_HOLD")
    return {"labeled": len(todo), "unlabeled": len(slots)}


def recolor(scene: bpy.types.Scene, take_coll: bpy.types.Collection) -> int:
    """Rewrite the key types of the markers whose class changes at the scene's Confident at; returns
    how many empties were rewritten (none when the keys already show that threshold)."""
    sure = scene_sure(scene)
    if not has_review(take_coll) or key_sure(take_coll) == sure:
        return 0
    state = load_state(take_coll)
    counts = write_labeling(take_coll, current_take(take_coll), state_layout(state), state.labeling,
                            state.labeling, sure)
    return counts["labeled"] + counts["unlabeled"]


def summary(labeling: Labeling, sure: float, first: int = 0) -> dict:
    """The panel's figures: labels present, share of labeled samples that are confident, uncertain segments,
    and the warning when another layout fits the take clearly better (or None); ``first``: the scene frame
    of the take's first sample."""
    from ..core.hands import traded_text
    from ..core.process import LayoutDoubt

    s = labeling.summary(sure)
    doubt = labeling.info.get("layout_doubt")
    present = np.unique(labeling.label[labeling.label >= 0])
    facts = labeling.info.get("hands", {})
    hands = None
    if facts.get("count", 1) == 2:
        sure_of = f", sides {100 * facts['confidence']:.0f} % sure" if "confidence" in facts else ""
        hands = f"2 hands: left and right{sure_of}"
    return {"labels": f"{len(present)} / {len(labeling.names)}", "confident": s["confident_share"] * 100,
            "uncertain": len(uncertain_segments(labeling, sure)),
            "locked": int(labeling.locked.sum()), "layout_doubt": doubt and LayoutDoubt(**doubt),
            "hands": hands, "hands_warning": facts.get("warning"),
            "hands_traded": traded_text(facts.get("swaps", []), first),
            "props": _props_line(labeling.info.get("props", [])),
            # perm and cnn: their calibrated confidence never reaches the bar (see the CLI's note);
            # "uncalibrated": gmm or nearest on a layout without a calibration
            "never_confident": labeling.info.get("never_confident") or False,
            # set on a layout never calibrated: raw probabilities, seldom at the bar (see the CLI's note)
            "raw_confidence": labeling.info.get("confidence") == RAW}


def _props_line(props: list[dict]) -> str | None:
    """The panel's line on rigid props kept out of the hands (:mod:`..core.props`), or None."""
    if not props:
        return None
    count = sum(p["trajectories"] for p in props)
    return (f"{len(props)} rigid prop{'s' if len(props) > 1 else ''} kept out of the hands "
            f"({count} trajectories, left unlabeled)")


def legend() -> list[tuple[str, str]]:
    """(keyframe type, what it means) for the panel's legend."""
    return list(zip(KEY_TYPES, CLASS_NAMES, strict=True))


# --- viewport overlay geometry (drawn by ui/overlay.py; pure so tests can call it) -----------

def overlay_geometry(take_coll: bpy.types.Collection, layout: Layout, classes: np.ndarray, index: int,
                     sticks: bool = True) -> dict[str, np.ndarray]:
    """Points, colours and stick segments for the labeled markers at sample ``index``: the layout's
    M, or both hands' 2M (each coloured by its finger, sticks along each digit of each hand, never
    from one hand to the other).

    Args:
        classes: int8 ``(F, L)`` classes of the L labels (:func:`core.review.marker_classes`).

    Returns:
        ``points`` ``(n, 3)`` world positions, ``colors`` ``(n, 4)`` finger colours, ``uncertain``
        ``(u, 3)`` positions to ring, ``ring_colors`` ``(u, 4)``, ``lines`` ``(2 s, 3)`` stick ends.
    """
    coll = take_coll.get("mocap_labeled")
    objs = labeled_objects(coll) if coll is not None else {}
    m = len(layout)
    n_labels = classes.shape[1] if classes.ndim == 2 else m
    ok = 0 <= index < classes.shape[0]
    pos = np.full((n_labels, 3), np.nan, dtype=np.float32)
    cls = np.full(n_labels, -1, dtype=np.int8)
    for label, obj in objs.items():
        if ok and label < n_labels and classes[index, label] >= 0:
            pos[label] = obj.matrix_world.translation
            cls[label] = classes[index, label]
    shown = np.flatnonzero(cls >= 0)
    fingers = [finger_of(layout, i % m) for i in range(n_labels)]
    colors = np.array([(*theme_color(fingers[i]), 1.0) for i in shown], dtype=np.float32).reshape(-1, 4)
    ring = {1: (0.3, 0.8, 1.0, 1.0), 2: (1.0, 0.25, 0.45, 1.0)}  # the Dope Sheet's breakdown / extreme hues
    unsure = shown[(cls[shown] == 1) | (cls[shown] == 2)]
    lines = []
    if sticks:
        def along(i: int) -> tuple:
            marker = layout.markers[i % m]
            return (marker.bone.endswith(("prox", "mid", "dist")),
                    ("meta", "prox", "mid", "dist").index(marker.bone.split("_")[1]), marker.along)

        for hand in range(0, n_labels, m):  # each hand's digits on their own
            for finger in FINGERS[:-1]:
                digit = [i for i in range(hand, min(hand + m, n_labels)) if fingers[i] == finger and cls[i] >= 0]
                chain = sorted(digit, key=along)
                for a, b in zip(chain[:-1], chain[1:]):
                    lines += [pos[a], pos[b]]
    return {"points": pos[shown], "colors": colors, "uncertain": pos[unsure],
            "ring_colors": np.array([ring[int(c)] for c in cls[unsure]], dtype=np.float32).reshape(-1, 4),
            "lines": np.array(lines, dtype=np.float32).reshape(-1, 3)}


# --- labeling a take of the scene: prepared on the main thread, run anywhere, finished on the main thread

@dataclass
class LabelRequest:
    """Everything a labeling run needs, gathered from the scene so that :meth:`run` touches no Blender data."""

    take_name: str
    take: Take
    layout: Layout
    layout_ref: str
    method: str
    temporal: str
    review: Review
    previous: Labeling | None
    labeler: object
    token: str = ""  # the stored state's token when the request was made
    #: corrections of an earlier labeling with another layout that name a label this layout lacks
    dropped: list = field(default_factory=list)
    dropped_names: list = field(default_factory=list)  # the label names the dropped corrections use
    #: label_take's hand keywords (:func:`core.hands.relabel_options`): a take labeled with two
    #: hands before keeps both and their sides, so its corrections keep their hands
    hand_options: dict = field(default_factory=dict)
    hands_changed: bool = False  # labeled before with another count of hands
    #: the share of the run done (0-1), written by :meth:`run` as its stages start
    done: float = 0.0
    stage: str = ""
    #: the layout was not chosen by the user: where another built-in layout fits the take clearly
    #: better (:func:`.core.process.layout_doubt`), :meth:`run` labels with that one instead
    pick_layout: bool = False
    picked: dict | None = None  # what :meth:`run` picked: {"from", "to", "share", "better_share"}
    cache: object = None  # the session's :class:`core.cache.RunCache` (results kept between re-solves)

    def run(self, say=None, check_layout: bool = False) -> Labeling:
        """The labeling; with ``check_layout``, ``info["layout_doubt"]`` (a :class:`LayoutDoubt` as a
        dict) says when another layout fits the take clearly better (a re-solve keeps what the
        labeling it replaces said), and a take in which no hand is found (the CLI's and batch's
        rule, :func:`.core.process.process_take`) raises :class:`MocapInputError`: nothing is built.

        ``say(message)`` hears each stage as it starts; :attr:`stage` holds that line and
        :attr:`done` the share of the work done (the core's one progress protocol).
        """
        from ..core.errors import MocapInputError
        from ..core.process import Outputs, process_take
        from ..core.settings import Corrections, LabelSettings

        def staged(message: str, share: float) -> None:
            self.stage, self.done = message, share
            if say is not None:
                say(message)  # a cancelled job raises here

        options = dict(self.hand_options)
        corrections = Corrections(constraints=tuple(self.review.constraints), splits=tuple(self.review.splits),
                                  hand_swaps=options.pop("hand_swaps", None))
        settings = LabelSettings(method=self.method, temporal=self.temporal, **options)
        # As the command line does: the layout on one hand, the no-hand rule per hand.
        outputs = Outputs(check_hand=check_layout, check_layout=check_layout, pick_layout=self.pick_layout,
                          layout_hint="Layout {} in the Mocap tab", hands_hint=("Hands: One", "Hands: Two"))
        # A re-solve labels again only the frames around what the reviewer changed since.
        try:
            result = process_take(self.take, self.layout, settings, outputs, corrections=corrections,
                                  previous=None if check_layout else self.previous, labeler=self.labeler,
                                  progress=staged, cache=self.cache)
        except MocapInputError as exc:  # named for the take in the scene, not its file
            raise MocapInputError(self.take_name, exc.problem) from None
        labeling = result.labeling
        if result.picked:
            self.picked = result.picked
            self.layout, self.layout_ref, self.previous = result.layout, result.layout.name, None
        if not check_layout and self.previous is not None and self.previous.info.get("layout_doubt"):
            labeling.info["layout_doubt"] = self.previous.info["layout_doubt"]
        self.done = 1.0
        return labeling


def prepare_label(take_coll: bpy.types.Collection, layout_ref: str | None = None, method: str | None = None,
                  temporal: str | None = None, hands: str = "auto") -> LabelRequest:
    """A labeling run for the take; settings default to those it was labeled with before.

    A take labeled before keeps its corrections when it is labeled again: with another layout,
    those naming a marker the new layout also has (by name), ghost decisions and splits are kept,
    and the others are listed in the request's ``dropped`` for the caller to report. A take labeled
    with two hands keeps them and their sides (``hands="auto"``); ``hands`` ``"1"`` or ``"2"``
    forces the count, and where that changes it, the corrections naming labels are dropped (a
    hand's labels mean nothing to the other count) and reported the same way.
    """
    from ..core.labelers import labeler_method, make_labeler
    from .session import labeler, session

    state = load_state(take_coll) if has_review(take_coll) else None
    layout_ref = layout_ref or (state.layout if state else "han19")
    method = method or (state.method if state else "set")
    temporal = temporal or (state.temporal if state else "vote")
    layout = load_layout(layout_ref)
    # A two-hand take stays two hands with its sides; names are those the new labeling will have.
    hand_options, names, hands_changed = relabel_plan(state.labeling.info if state else None, layout, hands)
    keep = state is not None and (state.layout == layout_ref and not hands_changed or state.labeling.names == names)
    review = state.review if keep else Review()
    previous = state.labeling if keep else None
    dropped = []
    if state is not None and not keep:
        review, dropped = remap_review(state.review, state.labeling.names, names)
    take = current_take(take_coll)
    lab = None
    if labeler_method(method).onnx:
        lab = labeler(take_coll, method, layout, lambda: make_labeler(method, layout))
    return LabelRequest(take_coll.name, take, layout, layout_ref, method, temporal, review, previous, lab,
                        state.token if state else "", dropped, list(state.labeling.names) if state else [],
                        hand_options, hands_changed, cache=session(take_coll).cache)


def finish_label(scene: bpy.types.Scene, take_coll: bpy.types.Collection, request: LabelRequest,
                 labeling: Labeling) -> dict:
    """Show a finished labeling and store it with the request's corrections.

    Raises:
        ValueError: the take's review changed while the labeling ran (its result would undo that change).
    """
    now = str(take_coll["mocap_settings"].get("token", "")) if has_review(take_coll) else ""
    if now != request.token:
        raise ValueError(f"{take_coll.name}: the labels changed while the labeling ran; label again")

    if has_review(take_coll) and (request.previous is None or request.previous.names != labeling.names):
        _clear_labels(take_coll)  # labeled before with another layout (or another count of hands)
    counts = write_labeling(take_coll, request.take, request.layout, labeling, request.previous,
                            scene_sure(scene))
    commit(scene, take_coll, ReviewState(labeling, request.review, request.layout_ref, request.method,
                                         request.temporal))
    return counts


def commit(scene: bpy.types.Scene, take_coll: bpy.types.Collection, state: ReviewState) -> None:
    """Store the state on the take and make it the scene's reviewed take."""
    store_state(take_coll, state)
    settings = getattr(scene, "mocap_autolabel", None)
    if settings is None:  # the add-on is not registered (a CLI run): the panel adopts the take on load
        return
    if settings.take != take_coll:
        settings.take = take_coll  # its update rebuilds the list
    refresh_uncertain(scene, take_coll, state.labeling)


def edit(scene: bpy.types.Scene, take_coll: bpy.types.Collection, state: ReviewState, labeling: Labeling) -> dict:
    """Show an edited labeling (rewriting only what changed) and store it."""
    counts = write_labeling(take_coll, current_take(take_coll), state_layout(state), labeling, state.labeling,
                            scene_sure(scene))
    state.labeling = labeling
    commit(scene, take_coll, state)
    return counts


def _clear_labels(take_coll: bpy.types.Collection) -> None:
    for key in ("mocap_labeled", "mocap_unlabeled"):
        coll = take_coll.get(key)
        if coll is None:
            continue
        for obj in list(coll.all_objects):
            action = obj.animation_data.action if obj.animation_data else None
            bpy.data.objects.remove(obj)
            if action is not None and action.users == 0:
                bpy.data.actions.remove(action)
    for side in HAND_COLLECTIONS:  # a two-hand labeling's hand collections (made again where needed)
        coll = take_coll.get(f"mocap_labeled_{side}")
        if coll is not None and coll.name in bpy.data.collections:
            bpy.data.collections.remove(coll)
        take_coll.pop(f"mocap_labeled_{side}", None)
