"""Cleanup of a labeled take's markers in the scene: Find Spikes, Smooth, Delete Short Fragments,
Quick Label and the Fill Preview.

Each tool reads the labeled markers as the take and its labeling give them (the raw trajectories'
samples under their labels, :func:`..core.labeling.labeled_take`, read again from the scene's keys
first: a key edited by hand counts), calls the core (:mod:`..core.cleanup` finds what to change,
:mod:`..core.cleanup_labels` says how the labeling takes it), and writes the scene:

- **Find Spikes** cuts the suspect samples out of their segments as pieces of their own, very
  uncertain (the review colour of their keys; the review queue, so the panel's list, Previous / Next
  and the Timeline's marks show them); the cuts are the take's splits (a re-solve decides each
  piece on its own; the Corrections list shows them, and deleting one there takes it back).
- **Smooth** changes the take's samples themselves: the smoothed labeled samples are written into
  the raw trajectories that carry them (the raw empties' keys, or the raw point cloud), so the
  labeled markers, a relabel, a re-solve and Export Labeled C3D all see them; only measured samples
  are filtered (a gap, filled or not, stays a gap to the filter: :func:`..core.cleanup.lowpass`), and
  the fills of the smoothed markers are kept as they were (Fill Gaps again fits them to the smoothed
  samples). The take's review state gets a new token (a Fill Gaps or a fill preview made before
  refuses to write over it).
- **Delete Short Fragments** and **Quick Label** are corrections (:class:`..core.review.Review`), as
  Unlabel and Assign Label make: a re-solve keeps them.
- **Fill Preview** shows the gaps of one labeled marker with the fill ``auto`` picks
  (:class:`..core.cleanup.FillPreview`: the hand from the take's solved rig where there is one, as
  Fill Gaps takes it), lets the reviewer pick another method per gap, and writes its fills as Fill
  Gaps writes them (``GENERATED`` keys, recorded in the take's ``mocap_fill``), so Export Labeled C3D
  writes them as computed samples. The preview itself (its models solved once) is kept in the
  session's cache; the list the panel shows is in the scene (undo restores it), and the preview
  follows the list.

Undo restores every tool's change with the keys and the take's custom properties (a Blender undo
step); after an undo or redo the takes the session read are read again (:func:`forget_read_takes`).
"""

from __future__ import annotations

import json
import uuid
from collections.abc import Callable
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.errors import MocapInputError
from ..core.labeling import labeled_take
from ..core.review import apply_constraints, plural
from . import animio
from .pointcloud import CLOUD
from .takes import ReviewState, current_take, first_frame, has_review, load_state, raw_cloud, raw_markers, state_layout

#: The session cache's kind under which the fill preview is kept (:class:`..core.cache.RunCache`).
PREVIEW_KIND = "fill_preview"
#: How many runs of frames a message names at most.
SAY_RUNS = 4

Progress = Callable[[str, float], None]


def _quiet(_message: str, _share: float) -> None:
    pass


def fresh_take(take_coll: bpy.types.Collection):
    """The take as the scene holds it now: read again from the raw keys (a key edited by hand, an
    undo or another tool's write counts), and kept for the session as :func:`.takes.current_take` keeps it."""
    from .session import session

    session(take_coll).take = None
    return current_take(take_coll)


def _chosen(labeling, labels) -> np.ndarray:
    """int: the labels asked for (all where None), sorted, each once."""
    n = len(labeling.names)
    if labels is None:
        return np.arange(n, dtype=np.int64)
    out = np.unique(np.asarray(list(labels), dtype=np.int64))
    if len(out) and (out[0] < 0 or out[-1] >= n):
        raise ValueError(f"there is no label number {int(out[-1] if out[-1] >= n else out[0])} (the layout has {n})")
    return out


def _runs_text(frames: np.ndarray, first: int) -> str:
    """``"120-122, 400"``: the runs of sorted sample indices as Blender frames (at most :data:`SAY_RUNS`)."""
    if not len(frames):
        return ""
    breaks = np.flatnonzero(np.diff(frames) > 1)
    starts = np.concatenate([[frames[0]], frames[breaks + 1]])
    ends = np.concatenate([frames[breaks], [frames[-1]]])
    parts = [f"{a + first}" if a == b else f"{a + first}-{b + first}" for a, b in zip(starts, ends)]
    more = len(parts) - SAY_RUNS
    return ", ".join(parts[:SAY_RUNS]) + (f" and {more} more" if more > 0 else "")


def _markers_text(names: list[str], mask: np.ndarray, labels: np.ndarray, first: int) -> str:
    """``"IndexTip 120-122; RingTip 400"``: where bool ``mask (F, k)`` holds, per label of ``labels``."""
    hit = [(names[int(label)], np.flatnonzero(mask[:, k])) for k, label in enumerate(labels) if mask[:, k].any()]
    text = "; ".join(f"{name} {_runs_text(f, first)}" for name, f in hit[:SAY_RUNS])
    return text + (f"; {plural(len(hit) - SAY_RUNS, 'more marker')}" if len(hit) > SAY_RUNS else "")


# --- Find Spikes ----------------------------------------------------------------------------------

def mark_spikes(scene: bpy.types.Scene, take_coll: bpy.types.Collection, state: ReviewState, *,
                labels=None, max_accel: float, max_speed: float, progress: Progress | None = None) -> dict:
    """Find the spikes and jumps of the labeled markers ``labels`` (default all;
    :func:`..core.cleanup.find_spikes`) and mark them for review (:func:`..core.cleanup_labels.mark_suspects`).

    Returns:
        ``{"samples", "markers", "marked", "locked", "suspect" (bool (F, k) over "labels"), "labels",
        "message"}``: the suspect samples, the names of the markers that have any, how many were
        marked and how many lie in locked segments (left as they are), and the report's line.
    """
    from ..core.cleanup import find_spikes
    from ..core.cleanup_labels import mark_suspects, to_slots
    from .review import edit

    say = progress or _quiet
    say("reading the labeled markers", 0.0)
    take = fresh_take(take_coll)
    lab = state.labeling
    chosen = _chosen(lab, labels)
    markers = labeled_take(take, lab).positions[:, chosen]
    say("finding spikes and jumps", 0.1)
    try:
        suspect = find_spikes(markers, take.rate, max_accel=max_accel, max_speed=max_speed)
    except ValueError as exc:
        raise MocapInputError(take_coll.name, str(exc)) from None
    say("marking them for review", 0.8)
    frames, slots = to_slots(lab, suspect, chosen)
    mask = np.zeros((lab.n_frames, lab.n_points), dtype=bool)
    mask[frames, slots] = True
    marked_lab, marked = mark_suspects(lab, state.review, mask)
    if marked.samples:
        edit(scene, take_coll, state, marked_lab)
    say("marked", 1.0)
    names = [lab.names[int(label)] for k, label in enumerate(chosen) if suspect[:, k].any()]
    n = int(suspect.sum())
    which = "the labeled markers" if labels is None else plural(len(chosen), "selected marker")
    if not n:
        message = f"No suspect samples on {which} (max acceleration {max_accel:g} m/s², max speed {max_speed:g} m/s)"
    else:
        message = (f"{plural(n, 'suspect sample')} on {plural(len(names), 'marker')} "
                   f"({_markers_text(lab.names, suspect, chosen, first_frame(take_coll))}): marked very "
                   f"uncertain for review (Previous / Next)")
        if marked.locked:
            message += f"; {marked.locked} in locked segments left as they are"
    return {"samples": n, "markers": names, "marked": marked.samples, "locked": marked.locked, "suspect": suspect,
            "labels": chosen, "message": message}


# --- Smooth ----------------------------------------------------------------------------------------

def write_raw(take_coll: bpy.types.Collection, frames: np.ndarray, slots: np.ndarray, xyz: np.ndarray) -> None:
    """Write samples of the take into its raw trajectories: sample indices ``frames`` and point slots
    ``slots`` ``(n,)`` each (each a sample the take has), positions ``xyz (n, 3)`` in metres (the
    import's Scale applied here). The raw empties' location keys keep their frames, interpolation and
    types (their values change), or the raw point cloud's positions change."""
    scale = float(take_coll.get("mocap_scale", 1.0))
    values = np.asarray(xyz, dtype=np.float64) * scale
    frames, slots = np.asarray(frames, dtype=np.int64), np.asarray(slots, dtype=np.int64)
    cloud = raw_cloud(take_coll)
    if cloud is not None:
        mesh = cloud.data
        n_s, n = int(cloud[CLOUD]), len(mesh.vertices)
        column = {int(s): c for c, s in enumerate(cloud["mocap_slots"])}
        cols = np.array([column[int(s)] for s in slots], dtype=np.int64)
        pos = np.empty(n * 3, dtype=np.float32)
        mesh.attributes["position"].data.foreach_get("vector", pos)
        pos.reshape(n // n_s, n_s, 3)[frames, cols] = values
        mesh.attributes["position"].data.foreach_set("vector", pos)
        mesh.update()
        return
    first = first_frame(take_coll)
    objs = {int(o["mocap_slot"]): o for o in raw_markers(take_coll)}
    for slot in np.unique(slots):
        mine = slots == slot
        for axis in range(3):
            fc = animio.find_fcurve(objs[int(slot)], "location", axis)
            points = fc.keyframe_points
            co = np.empty(2 * len(points), dtype=np.float32)
            points.foreach_get("co", co)
            at = np.rint(co[0::2]).astype(np.int64) - first  # sorted: one key per sample
            key = np.searchsorted(at, frames[mine])
            if (key >= len(at)).any() or (at[np.minimum(key, len(at) - 1)] != frames[mine]).any():
                raise MocapInputError(take_coll.name, f"the raw trajectory {objs[int(slot)].name} has no key at some "
                                                      "of the samples to write")
            co[2 * key + 1] = values[mine, axis]
            points.foreach_set("co", co)
            fc.update()


def _rewrite_labels(take_coll: bpy.types.Collection, take, state: ReviewState, labels: np.ndarray) -> None:
    """Key the labeled markers ``labels`` again from ``take`` (their samples changed, not their
    labels), their fills kept as they were."""
    from .fill import keep_fills, restore_fills

    n = take.n_frames
    kept = keep_fills(take_coll, state.labeling, state.labeling, [int(v) for v in labels], n)
    none = (np.zeros(n, dtype=bool), np.full((n, 3), np.nan))
    restore_fills(take_coll, take, state_layout(state), state.labeling,
                  {int(label): kept.get(int(label), none) for label in labels})


def smooth_markers(scene: bpy.types.Scene, take_coll: bpy.types.Collection, state: ReviewState, *, labels=None,
                   cutoff_hz: float, order: int, progress: Progress | None = None) -> dict:
    """Low-pass the labeled markers ``labels`` (default all): a zero-lag Butterworth filter of
    ``order`` at ``cutoff_hz`` over each run of their measured samples (:func:`..core.cleanup.lowpass`),
    written into the take (see the module).

    Returns:
        ``{"samples", "markers", "max_change_mm", "rms_change_mm", "fills_kept", "message"}``.

    Raises:
        MocapInputError: a cut-off not below the Nyquist frequency (half the take's rate), or a bad order.
    """
    from ..core.cleanup import lowpass
    from ..core.cleanup_labels import carriers
    from .fill import fill_record
    from .review import commit

    say = progress or _quiet
    say("reading the labeled markers", 0.0)
    take = fresh_take(take_coll)
    rate = float(take.rate)
    if not 0 < cutoff_hz < rate / 2:
        raise MocapInputError(take_coll.name, f"a Cut-off of {cutoff_hz:g} Hz is not below the Nyquist frequency "
                                              f"({rate / 2:g} Hz, half of {rate:g} fps): choose a lower one")
    lab = state.labeling
    chosen = _chosen(lab, labels)
    markers = labeled_take(take, lab).positions[:, chosen].astype(np.float64)
    say("filtering", 0.2)
    try:
        smoothed = lowpass(markers, rate, cutoff_hz=cutoff_hz, order=order)
    except ValueError as exc:
        raise MocapInputError(take_coll.name, str(exc)) from None
    valid = np.isfinite(markers).all(axis=2)
    f, k = np.nonzero(valid)
    say("writing the take", 0.5)
    write_raw(take_coll, f, carriers(lab)[:, chosen][f, k], smoothed[f, k])
    take = fresh_take(take_coll)
    say("keying the labeled markers", 0.7)
    _rewrite_labels(take_coll, take, state, chosen)
    commit(scene, take_coll, state)  # a new token: the take's samples changed
    say("smoothed", 1.0)
    change = np.linalg.norm(smoothed[f, k] - markers[f, k], axis=1) * 1000.0
    filled = {g["label"] for g in fill_record(take_coll).get("gaps", [])} & {int(v) for v in chosen}
    names = [lab.names[int(label)] for j, label in enumerate(chosen) if valid[:, j].any()]
    which = "labeled markers" if labels is None else "selected markers"
    message = (f"Smoothed {len(names)} {which} ({plural(int(valid.sum()), 'sample')}) at {cutoff_hz:g} Hz, "
               f"order {order}: samples moved {float(np.sqrt(np.mean(change ** 2))) if len(change) else 0.0:.2f} mm "
               f"RMS, at most {float(change.max()) if len(change) else 0.0:.2f} mm")
    if filled:
        message += f"; the fills of {plural(len(filled), 'marker')} kept as they were (Fill Gaps again to fit them)"
    return {"samples": int(valid.sum()), "markers": names, "max_change_mm": float(change.max()) if len(change) else 0.0,
            "rms_change_mm": float(np.sqrt(np.mean(change ** 2))) if len(change) else 0.0,
            "fills_kept": len(filled), "message": message}


# --- Delete Short Fragments -------------------------------------------------------------------------

def delete_short_fragments(scene: bpy.types.Scene, take_coll: bpy.types.Collection, state: ReviewState, *,
                           labels=None, min_frames: int) -> dict:
    """Take the samples in runs shorter than ``min_frames`` off the labeled markers ``labels``
    (default all): their segments are unlabeled by correction (:func:`..core.cleanup_labels.short_segments`),
    their keys leave the labeled markers for the take's unlabeled ones.

    Returns:
        ``{"samples", "segments", "markers", "locked", "message"}``: what was deleted, and how many
        short segments are locked (left as they are).
    """
    from ..core.cleanup_labels import short_segments, unlabel_segments
    from .review import edit

    lab = state.labeling
    chosen = _chosen(lab, labels)
    if int(min_frames) != min_frames or min_frames < 1:
        raise MocapInputError(take_coll.name, f"Shorter Than must be 1 frame or more, got {min_frames}")
    segs, locked = short_segments(lab, int(min_frames), chosen)
    made = unlabel_segments(lab, state.review, segs)
    first = first_frame(take_coll)
    mask = np.zeros((lab.n_frames, len(chosen)), dtype=bool)
    col = {int(label): k for k, label in enumerate(chosen)}
    for i in segs:
        mask[lab.start[i]:lab.stop[i], col[int(lab.label[i])]] = True
    if made:
        edit(scene, take_coll, state, apply_constraints(lab, made))
    n = int(mask.sum())
    names = [lab.names[int(label)] for k, label in enumerate(chosen) if mask[:, k].any()]
    which = "the labeled markers" if labels is None else plural(len(chosen), "selected marker")
    if n:
        message = (f"Deleted {plural(n, 'sample')} in runs shorter than {min_frames} frames from "
                   f"{plural(len(names), 'marker')} ({_markers_text(lab.names, mask, chosen, first)}): "
                   f"unlabeled by {plural(len(made), 'correction')}")
    else:
        message = f"No run shorter than {min_frames} frames on {which}"
    if len(locked):
        message += f"; {plural(len(locked), 'locked segment')} left as they are"
    return {"samples": n, "segments": len(segs), "markers": names, "locked": len(locked), "message": message}


# --- Quick Label ------------------------------------------------------------------------------------

def quick_constraint(scene: bpy.types.Scene, take_coll: bpy.types.Collection, state: ReviewState, *, slot: int,
                     frame: int, label: str = "") -> tuple:
    """The correction of Quick Label: the whole segment of trajectory ``slot`` under Blender frame
    ``frame`` gets ``label`` (a label's name), or the panel's Next Label where ``label`` is empty
    (:func:`..core.cleanup_labels.label_segment`; added to ``state.review``, not yet applied).

    Returns:
        ``(Constraint, text)``: the correction and what it does, in the reviewer's words.
    """
    from ..core.cleanup_labels import label_segment, segment_at
    from .takes import sample_index, trajectory_names

    lab = state.labeling
    names = lab.names
    if label:
        if label not in names:
            raise ValueError(f"there is no label {label!r} in the layout ({', '.join(names[:4])}...)")
        number = names.index(label)
    else:
        number = int(scene.mocap_autolabel.cleanup.quick_next)
        if number >= len(names):
            raise ValueError(f"Next Label {number} is past the layout's last label ({len(names) - 1}: "
                             f"{names[-1]}); set it in the Cleanup panel")
    index = sample_index(take_coll, frame)
    seg = segment_at(lab, slot, index)
    first = first_frame(take_coll)
    was = int(lab.label[seg])
    who = trajectory_names(take_coll)[slot] + (f" ({names[was]})" if was >= 0 else "")
    c = label_segment(lab, state.review, slot, index, number)
    return c, f"{who}, frames {c.start + first}-{c.stop - 1 + first}, labeled {names[number]}: "


def advance_quick_label(scene: bpy.types.Scene, take_coll: bpy.types.Collection, *, label: int) -> str:
    """Move the panel's Next Label to the label after ``label`` (back to the first after the last);
    returns the text that says which it is."""
    names = load_state(take_coll).labeling.names
    nxt = (int(label) + 1) % len(names)
    scene.mocap_autolabel.cleanup.quick_next = nxt
    return f"; next: {names[nxt]}" + (" (the layout's first again)" if nxt == 0 else "")


# --- Fill Preview -----------------------------------------------------------------------------------

@dataclass
class PreviewRequest:
    """What a fill preview of one labeled marker needs, gathered on the main thread
    (:func:`prepare_preview`) so that :meth:`run` touches no Blender data.

    Attributes:
        label: the marker's label; ``column``: its column among its hand's markers (``hand``,
            :func:`..core.hands.split_hands`: the layout's markers of its side, metres);
        names: the hand's markers' names as the scene shows them.
        kept: the solve the hand's rig keeps (:func:`.armature.kept_solve`), or None (no hand).
    """

    take_name: str
    label: int
    name: str
    column: int
    hand: object
    layout: object
    names: list
    max_gap: float
    kept: object = None
    token: str = ""
    stage: str = "starting"
    share: float = 0.0

    def run(self, say=None):
        """The :class:`..core.cleanup.FillPreview` of the marker's hand (the kept solve brought up to
        date with the labels first, as Fill Gaps does: :func:`..core.fill.update_solve`)."""
        from ..core.cleanup import FillPreview
        from ..core.fill import layout_partners, update_solve

        def progress(message: str, share: float) -> None:
            self.stage, self.share = message, share
            if say is not None:
                say(message)

        solver = poses = None
        if self.kept is not None:
            solved, _, _ = update_solve(self.kept, self.hand, self.layout,
                                        lambda message, share: progress(f"hand: {message}", 0.8 * share))
            solver, poses = solved.solver(), solved.fit.poses
        progress("trying the fill methods", 0.8)
        try:
            out = FillPreview(self.hand.positions, self.hand.rate, max_gap=self.max_gap, solver=solver, poses=poses,
                              partners=layout_partners(self.layout), names=list(self.names))
        except ValueError as exc:
            raise MocapInputError(self.take_name, str(exc)) from None
        progress("previewed", 1.0)
        return out


def prepare_preview(take_coll: bpy.types.Collection, *, label: int, max_gap: float) -> PreviewRequest:
    """The :class:`PreviewRequest` of the labeled marker ``label`` of the take."""
    from ..core.hands import HandNaming, hands_in_names, split_hands
    from .armature import kept_solve
    from .fill import solved_rigs

    state = load_state(take_coll)
    lab = state.labeling
    if not 0 <= label < len(lab.names):
        raise ValueError(f"there is no label number {label} (the layout has {len(lab.names)})")
    if not max_gap > 0:
        raise MocapInputError(take_coll.name, f"Max Gap must be above 0 seconds, got {max_gap:g}")
    layout = state_layout(state)
    naming = lab.info.get("hands", {}).get("naming")
    naming = HandNaming(naming) if naming else None
    take = labeled_take(fresh_take(take_coll), lab)
    found = hands_in_names(take.names, layout, naming)
    side = next((s for s, cols in found.items() if label in cols), None)
    if side is None:
        raise MocapInputError(take_coll.name, f"{lab.names[label]} belongs to no labeled hand of layout {layout.name}")
    cols = found[side]
    hand = dict(split_hands(take, layout, naming))[side]
    arm = solved_rigs(take_coll).get(side)
    kept = kept_solve(arm) if arm is not None else None
    return PreviewRequest(take_coll.name, int(label), lab.names[label], cols.index(label), hand, layout,
                          [take.names[c] for c in cols], float(max_gap), kept, state.token)


def _tried_text(tried: dict) -> str:
    return "; ".join(f"{k} {1000 * v:.1f} mm" if isinstance(v, float) else f"{k}: {v}" for k, v in tried.items())


def _show_gap(item, gap, names: list, first: int) -> None:
    """One row of the panel's list from a :class:`..core.cleanup.GapPreview`."""
    item.frame_start, item.frame_end = gap.start + first, gap.stop - 1 + first
    item.asked, item.method = gap.asked, gap.method or ""
    item.donors = ", ".join(names[int(d)] for d in gap.donors)
    item.error_mm = 1000.0 * float(gap.error.mean()) if gap.filled else 0.0
    item.reason, item.tried = gap.reason, _tried_text(gap.tried)


def finish_preview(scene: bpy.types.Scene, take_coll: bpy.types.Collection, request: PreviewRequest, preview) -> dict:
    """Keep a finished preview in the session and show its marker's gaps in the panel's list.

    Returns:
        ``{"gaps", "filled", "methods", "message"}``.
    """
    from .session import session

    if load_state(take_coll).token != request.token:
        raise MocapInputError(take_coll.name, "its labels changed while the fill was previewed: Preview Fill again")
    cs = scene.mocap_autolabel.cleanup
    entries = session(take_coll).cache.entries(PREVIEW_KIND)
    entries.clear()  # one preview at a time
    pid = uuid.uuid4().hex
    entries[pid] = (request, preview)
    cs.preview_take, cs.preview_label, cs.preview_name = take_coll, request.label, request.name
    cs.preview_token, cs.preview_id, cs.preview_max_gap = request.token, pid, request.max_gap
    cs.preview.clear()
    first = first_frame(take_coll)
    mine = [(i, g) for i, g in enumerate(preview.gaps) if g.marker == request.column]
    for i, gap in mine:
        item = cs.preview.add()
        item.gap = i
        _show_gap(item, gap, request.names, first)
    cs.preview_index = 0 if mine else -1
    methods: dict[str, int] = {}
    for _, g in mine:
        if g.filled:
            methods[g.method] = methods.get(g.method, 0) + 1
    filled = sum(methods.values())
    said = ", ".join(f"{n} {k}" for k, n in sorted(methods.items()))
    message = (f"{request.name}: {plural(len(mine), 'gap')}, {filled} filled by auto" + (f" ({said})" if said else "")
               + (f", {len(mine) - filled} left open" if len(mine) > filled else ""))
    return {"gaps": len(mine), "filled": filled, "methods": methods, "message": message}


def preview_fill(scene: bpy.types.Scene, take_coll: bpy.types.Collection, *, label: int, max_gap: float,
                 progress: Progress | None = None) -> dict:
    """Preview the fill of every gap of the labeled marker ``label``, at once (:func:`prepare_preview`,
    :meth:`PreviewRequest.run`, :func:`finish_preview`)."""
    request = prepare_preview(take_coll, label=label, max_gap=max_gap)
    say = progress or _quiet
    return finish_preview(scene, take_coll, request, request.run(lambda message: say(message, request.share)))


def _previewed(scene: bpy.types.Scene):
    """``(take, state, request, preview)`` of the preview the panel's list shows, its methods as the list
    says (undo may have taken a pick back); made again where the session lost it (a file loaded)."""
    from .session import session

    cs = scene.mocap_autolabel.cleanup
    coll = cs.preview_take
    if coll is None or not cs.preview_id or not len(cs.preview) or not has_review(coll):
        raise ValueError("no fill preview: select a labeled marker and Preview Fill")
    state = load_state(coll)
    if state.token != cs.preview_token:
        raise MocapInputError(coll.name, "its labels or samples changed since the fill preview: Preview Fill again")
    entries = session(coll).cache.entries(PREVIEW_KIND)
    entry = entries.get(cs.preview_id)
    if entry is None:
        request = prepare_preview(coll, label=cs.preview_label, max_gap=cs.preview_max_gap)
        entries.clear()
        entry = entries[cs.preview_id] = (request, request.run())
    request, preview = entry
    for item in cs.preview:
        if preview.gaps[item.gap].asked != item.asked:
            preview.choose(item.gap, item.asked)
    return coll, state, request, preview


def choose_fill_method(scene: bpy.types.Scene, *, row: int, method: str) -> dict:
    """Fill the gap in row ``row`` of the panel's list (-1: its active row) by ``method`` instead
    (``auto`` or one method of :data:`..core.fill.METHODS`).

    Returns:
        ``{"filled", "method", "error_mm", "message"}``.
    """
    cs = scene.mocap_autolabel.cleanup
    coll, _, request, preview = _previewed(scene)
    row = cs.preview_index if row < 0 else row
    if not 0 <= row < len(cs.preview):
        raise ValueError("no gap chosen: click one in the Fill Preview list")
    item = cs.preview[row]
    try:
        gap = preview.choose(item.gap, method)
    except ValueError as exc:
        raise MocapInputError(coll.name, str(exc)) from None
    _show_gap(item, gap, request.names, first_frame(coll))
    frames = f"{request.name} frames {item.frame_start}-{item.frame_end}"
    if gap.filled:
        message = f"{frames}: {gap.method}, {item.error_mm:.1f} mm expected" + (f", from {item.donors}" if item.donors
                                                                               else "")
    else:
        message = f"{frames}: {method} leaves it open ({gap.reason})"
    return {"filled": gap.filled, "method": gap.method, "error_mm": item.error_mm, "message": message}


def apply_fill_preview(scene: bpy.types.Scene) -> dict:
    """Write the fills of the panel's preview into its marker as Fill Gaps writes fills (``GENERATED``
    keys, recorded in the take's ``mocap_fill``); a gap the preview leaves open keeps the fill it had.

    Returns:
        ``{"filled", "gaps", "samples", "methods", "message"}``.
    """
    from .fill import fill_record, keep_fills, restore_fills

    coll, state, request, preview = _previewed(scene)
    lab, label = state.labeling, request.label
    take = fresh_take(coll)
    n = take.n_frames
    mine = [g for g in preview.gaps if g.marker == request.column]
    mask, positions = np.zeros(n, dtype=bool), np.full((n, 3), np.nan)
    for g in mine:
        if g.filled:
            mask[g.start:g.stop] = True
            positions[g.start:g.stop] = g.positions
    old = keep_fills(coll, lab, lab, [label], n).get(label)
    if old is not None:
        keep = old[0] & ~mask
        mask |= keep
        positions[keep] = old[1][keep]
    restore_fills(coll, take, state_layout(state), lab, {label: (mask, positions)})
    record = fill_record(coll)
    done = [g for g in mine if g.filled]
    gaps = [g for g in record.get("gaps", [])
            if not (g["label"] == label and any(g["start"] < d.stop and d.start < g["stop"] for d in done))]
    gaps += [{"label": label, "start": g.start, "stop": g.stop, "method": g.method,
              "error_mm": round(1000 * float(g.error.mean()), 3)} for g in done]
    if gaps:
        coll["mocap_fill"] = json.dumps({"method": record.get("method", "auto"),
                                         "max_gap": record.get("max_gap", request.max_gap), "gaps": gaps})
    methods: dict[str, int] = {}
    for g in done:
        methods[g.method] = methods.get(g.method, 0) + 1
    said = ", ".join(f"{v} {k}" for k, v in sorted(methods.items()))
    message = (f"Filled {len(done)} of {plural(len(mine), 'gap')} of {request.name} "
               f"({plural(sum(g.stop - g.start for g in done), 'sample')}" + (f": {said})" if said else ")"))
    return {"filled": len(done), "gaps": len(mine), "samples": int(sum(g.stop - g.start for g in done)),
            "methods": methods, "message": message}
