"""Filled gaps in the scene: the fills of a labeled take's markers as keys of their own type.

*Fill Gaps* keys each filled sample on its labeled empty with the keyframe type ``GENERATED``
(none of the confidence colours: KEYFRAME, BREAKDOWN, EXTREME, JITTER), so the Dope Sheet shows
fills apart from measured samples, and the marker is shown in the gap. The take collection keeps
what was filled in ``mocap_fill`` (method, max gap, every gap); the keys are the fill itself: a
saved .blend keeps both, and *Export Labeled C3D* writes the ``GENERATED`` keys as computed samples.

A relabel or correction that changes a marker's samples rewrites it from its measured samples:
its fills go (the record drops them) and *Fill Gaps* fills them again; a marker rewritten only for
its confidence colours keeps them. A re-solve of the hand refills every filled gap with the new
solve.

The fill is the core's (:func:`core.process.process_take`); the hand comes from the take's solved rig,
where there is one: the solve it keeps (:func:`.armature.keep_solve`: calibration, poses, and a digest
of each frame's markers it was solved from) is used as it is while the labels give the same markers,
and where they changed only the frames around the change are solved again, with the kept
calibration (:func:`core.fill.update_solve`); the rig is keyed again and keeps the new solve. Fill
Gaps gathers its inputs on the main thread (:func:`prepare_fill`), works on a worker thread
(:meth:`FillRequest.run`, no Blender data) and writes the scene on the main thread
(:func:`finish_fill`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.errors import MocapInputError
from ..core.labeling import labeled_take
from ..core.process import Outputs, process_take
from ..core.review import marker_classes
from ..core.settings import LabelSettings
from . import animio
from .armature import kept_solve
from .markers import finger_of, key_type_values, labeled_object
from .scene import key_track
from .takes import current_take, first_frame, key_sure, load_state, state_layout

#: The keyframe type of a filled sample.
FILL_KEY = "GENERATED"


def fill_record(take_coll: bpy.types.Collection) -> dict:
    """``{"method", "max_gap", "gaps": [{"label", "start", "stop", "method", "error_mm"}]}`` (empty: none)."""
    raw = take_coll.get("mocap_fill")
    return json.loads(raw) if raw else {}


def _store(take_coll: bpy.types.Collection, record: dict) -> None:
    if record.get("gaps"):
        take_coll["mocap_fill"] = json.dumps(record)
    else:
        take_coll.pop("mocap_fill", None)


def forget_fills(take_coll: bpy.types.Collection, labels) -> None:
    """Drop the record of the fills of ``labels`` (their keys were rewritten from measured samples)."""
    record = fill_record(take_coll)
    if record:
        gone = {int(v) for v in labels}
        record["gaps"] = [g for g in record["gaps"] if g["label"] not in gone]
        _store(take_coll, record)


def _fill_keys(take_coll: bpy.types.Collection, obj) -> tuple[np.ndarray, np.ndarray]:
    """An empty's :data:`FILL_KEY` location keys: sample indices ``(k,)`` and ``(k, 3)`` metres (the
    import's Scale taken off)."""
    curves = [animio.find_fcurve(obj, "location", axis) for axis in range(3)] if obj is not None else [None]
    if any(c is None for c in curves):
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    mine = animio.read_key_types(curves[0]) == animio.key_type_value(FILL_KEY)
    frames = animio.read_keys(curves[0])[0][mine]
    xyz = np.stack([animio.read_keys(c)[1][mine] for c in curves], axis=1) / float(take_coll.get("mocap_scale", 1.0))
    return np.rint(frames).astype(np.int64) - first_frame(take_coll), xyz


def filled_keys(take_coll: bpy.types.Collection, n_labels: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fills as the keys hold them: sample indices and labels ``(k,)`` each, and ``(k, 3)``
    metres, from the :data:`FILL_KEY` location keys of the labeled empties."""
    found = [(label, *_fill_keys(take_coll, labeled_object(take_coll, label))) for label in range(n_labels)]
    idx = np.concatenate([[0]] + [i for _, i, _ in found])[1:].astype(np.int64)
    labels = np.concatenate([[0]] + [np.full(len(i), label) for label, i, _ in found])[1:].astype(np.int64)
    return idx, labels, np.concatenate([np.zeros((0, 3))] + [x for _, _, x in found])


def keep_fills(take_coll: bpy.types.Collection, previous, labeling, labels, n_frames: int) -> dict:
    """Before a labeling's markers ``labels`` are rewritten: the fills of those whose samples stay
    the same (only their confidence colours change), ``{label: (bool (F,), (F, 3) metres)}``."""
    record = fill_record(take_coll)
    filled = {g["label"] for g in record.get("gaps", [])} & {int(v) for v in labels}
    if previous is None or not filled:
        return {}
    before, now = previous.per_sample(), labeling.per_sample()
    out = {}
    for label in sorted(filled):
        if np.array_equal(before == label, now == label):
            idx, xyz = _fill_keys(take_coll, labeled_object(take_coll, label))
            mask, positions = np.zeros(n_frames, dtype=bool), np.full((n_frames, 3), np.nan)
            ok = (idx >= 0) & (idx < n_frames)
            mask[idx[ok]], positions[idx[ok]] = True, xyz[ok]
            out[label] = (mask, positions)
    return out


def restore_fills(take_coll: bpy.types.Collection, take, layout, labeling, kept: dict) -> None:
    """Key again the fills :func:`keep_fills` kept (after their markers were rewritten)."""
    for label, (mask, positions) in kept.items():
        _key_label(take_coll, take, layout, labeling, label, mask, positions)


def _key_label(take_coll: bpy.types.Collection, take, layout, labeling, label: int,
               fill: np.ndarray | None = None, positions: np.ndarray | None = None) -> None:
    """Rewrite a labeled empty's keys: its measured samples typed by confidence, and the samples
    where bool ``fill (F,)`` holds at ``positions (F, 3)`` metres typed :data:`FILL_KEY`."""
    obj = labeled_object(take_coll, label)
    if obj is None:
        return
    scale = float(take_coll.get("mocap_scale", 1.0))
    classes = marker_classes(labeling, key_sure(take_coll))[:, label]
    measured = classes >= 0
    per = labeling.per_sample()
    xyz = np.full((take.n_frames, 3), np.nan, dtype=np.float32)
    f, s = np.nonzero(per == label)
    xyz[f] = take.positions[f, s] * scale
    types = np.where(measured, key_type_values()[np.maximum(classes, 0)], animio.key_type_value(FILL_KEY))
    valid = measured.copy()
    if fill is not None:
        fill = fill & ~measured
        xyz[fill] = positions[fill] * scale
        valid |= fill
    frames_all = np.arange(take.n_frames, dtype=np.float32) + first_frame(take_coll)
    key_track(obj, frames_all, valid, xyz, types[valid], group=finger_of(layout, label % len(layout)).title(),
              hold_type="MOVING_HOLD")


def solved_rigs(take_coll: bpy.types.Collection) -> dict[str, bpy.types.Object]:
    """``{side: armature}``: the rigs solved from the take (side ``""`` for one hand) that keep a
    calibration."""
    out = {}
    for coll in bpy.data.collections:
        source = coll.get("mocap_solved_from")
        if source != take_coll.name and not str(source or "").startswith(take_coll.name + ":"):
            continue
        side = "" if source == take_coll.name else str(source).split(":")[-1]
        for obj in coll.all_objects:
            if obj.type == "ARMATURE" and "mocap_calibration" in obj:
                out[side] = obj
    return out


@dataclass
class FillRequest:
    """Everything a fill needs, gathered on the main thread (:func:`prepare_fill`) so that :meth:`run`
    touches no Blender data (it runs on a worker thread while Blender stays responsive).

    ``kept`` is the solve each rig of the take keeps (:func:`.armature.kept_solve`), by side; the
    fill uses it as it is where the labels did not change since, and solves again only the
    frames that changed; ``solves`` (``[(side, HandSolve)]``) where given are used instead.
    """

    take_name: str
    take: object  # the labeled take (metres, the scene's frames)
    layout: object
    naming: str | None
    method: str
    max_gap: float
    labels: list[int]  # the labels whose fills are keyed
    kept: dict = field(default_factory=dict)
    solves: list | None = None
    token: str = ""  # the review state's token it was gathered from
    rigs: dict = field(default_factory=dict)  # per side, the kept solve's rig (:func:`_rig_key`)
    share: float = 0.0  # of the work done, set as the fill goes
    stage: str = "starting"

    def run(self, say=None) -> FillResult:
        """The hands brought up to date with the labels (:func:`~..core.fill.update_solve`) and the
        fill (:func:`~..core.process.process_take`). ``say(message)`` hears each stage and may raise to
        stop (a cancelled Job's does)."""
        from ..core.fill import fill_method, update_solve
        from ..core.hands import HandNaming, split_hands

        def progress(message: str, share: float) -> None:
            self.stage, self.share = message, share
            if say is not None:
                say(message)

        solves, updated = self.solves, {}
        if solves is None and self.kept and fill_method(self.method).uses_hand:
            hands = split_hands(self.take, self.layout, HandNaming(self.naming) if self.naming else None)
            mine = [(side, one) for side, one in hands if side in self.kept]
            solves = [] if mine else None  # None: no hand of the take is solved (``hand`` says so)
            for i, (side, one) in enumerate(mine):
                def per_hand(message: str, share: float, i: int = i, side: str = side) -> None:
                    progress(f"{side} hand: {message}" if side else message, 0.9 * (i + share) / len(mine))

                solved, digests, facts = update_solve(self.kept[side], one, self.layout, per_hand)
                solves.append((side, solved))
                updated[side] = (solved, digests, facts)
        progress("filling gaps", 0.9 if updated else 0.0)
        outputs = Outputs(label=False, fill=self.method, max_gap=self.max_gap, calibrations={}, calibrate=False)
        try:
            filled = process_take(self.take, self.layout, LabelSettings(naming=self.naming), outputs,
                                  solves=solves).filled
        except MocapInputError as exc:  # named for the take in the scene
            raise MocapInputError(self.take_name, exc.problem) from None
        progress("filled", 1.0)
        return FillResult(filled, updated)


@dataclass
class FillResult:
    """What :meth:`FillRequest.run` made: the fill (:class:`~..core.fill.TakeFill`) and, per side
    whose kept solve it used, ``(HandSolve, digests, facts)`` (:func:`~..core.fill.update_solve`)."""

    filled: object
    updated: dict


def prepare_fill(take_coll: bpy.types.Collection, method: str = "auto", max_gap: float = 1.0,
                 labels: list[int] | None = None, solves: list | None = None) -> FillRequest:
    """The :class:`FillRequest` of Fill Gaps on the take's labeled markers ``labels`` (default all):
    the take with its current labels and the solve each of its rigs keeps."""
    state = load_state(take_coll)
    labeling = state.labeling
    take = labeled_take(current_take(take_coll), labeling)
    chosen = sorted(set(range(len(labeling.names)) if labels is None else labels))
    kept, rigs = {}, {}
    if solves is None:
        for side, arm in solved_rigs(take_coll).items():
            one = kept_solve(arm)
            if one is not None:
                kept[side], rigs[side] = one, _rig_key(arm)
    return FillRequest(take_coll.name, take, state_layout(state), labeling.info.get("hands", {}).get("naming"),
                       method, float(max_gap), chosen, kept, solves, state.token, rigs)


def _rig_key(arm: bpy.types.Object) -> tuple:
    """What tells a rig's kept solve from another: its name, calibration and poses' fingerprint."""
    from .armature import SOLVE_RECORD

    record = arm.get(SOLVE_RECORD) or {}
    return arm.name, str(arm["mocap_calibration"]), str(record.get("fingerprint", "")), int(record.get("frames", 0))


def finish_fill(take_coll: bpy.types.Collection, request: FillRequest, result: FillResult) -> dict:
    """Key the fills of a :class:`FillRequest`'s labels, record them, and keep on each rig the solve
    the fill brought up to date; the fill's report for those labels, with ``hand_solve``: per side,
    what was solved again (``{"solved_frames": 0, ...}`` where the kept solve was used as it was)."""
    from .armature import update_solved_hand

    state = load_state(take_coll)
    if state.token != request.token:  # relabeled while the fill ran in the background
        raise MocapInputError(take_coll.name, "its labels changed while its gaps were being filled: Fill Gaps again")
    rigs = solved_rigs(take_coll)
    for side, (solved, digests, facts) in result.updated.items():
        arm = rigs.get(side)
        kept = request.kept[side]
        if (arm is not None and _rig_key(arm) == request.rigs[side]  # not solved again meanwhile
                and (facts["solved_frames"] or kept.digests is None)):
            update_solved_hand(arm, solved, digests, kept.smooth_hz)
    layout, labeling = state_layout(state), state.labeling
    take = current_take(take_coll)
    filled = result.filled
    chosen = request.labels
    for label in chosen:
        _key_label(take_coll, take, layout, labeling, label, filled.take.filled[:, label],
                   filled.take.positions[:, label])
    record = fill_record(take_coll)
    keep = [g for g in record.get("gaps", []) if g["label"] not in chosen]
    mine = [g for g in filled.gaps if g.marker in chosen]
    record = {"method": request.method, "max_gap": request.max_gap,
              "gaps": keep + [{"label": g.marker, "start": g.start, "stop": g.stop, "method": g.method,
                               "error_mm": round(1000 * g.error, 3)} for g in mine if g.filled]}
    _store(take_coll, record)
    report = filled.report()
    report["gap_list"] = [g.as_dict(take.rate, take.first_frame) for g in mine]
    report["filled"] = sum(1 for g in mine if g.filled)
    report["open"] = len(mine) - report["filled"]
    report["gaps"] = len(mine)
    report["methods"] = {}
    for g in mine:
        if g.filled:
            report["methods"][g.method] = report["methods"].get(g.method, 0) + 1
    report["hand_solve"] = {side: facts for side, (_, _, facts) in result.updated.items()}
    return report


def fill_scene(take_coll: bpy.types.Collection, method: str = "auto", max_gap: float = 1.0,
               labels: list[int] | None = None, solves: list | None = None) -> dict:
    """Fill the gaps of the take's labeled markers (``labels``, default all) and key the fills, at
    once (:func:`prepare_fill`, :meth:`FillRequest.run`, :func:`finish_fill`).

    The hand (``hand``, ``auto``) is the solve the take's rig keeps, solved again where the labels
    changed since (only around the frames that changed, with its calibration), or ``solves``
    (``[(side, HandSolve)]``) where given. Returns the fill's report (:meth:`core.fill.TakeFill.report`)
    for those labels.

    Raises:
        MocapInputError: ``hand`` was asked and the take has no solved hand.
    """
    request = prepare_fill(take_coll, method, max_gap, labels, solves)
    return finish_fill(take_coll, request, request.run())


def clear_fill(take_coll: bpy.types.Collection, labels: list[int] | None = None) -> int:
    """Remove the fills of ``labels`` (default all): their keys again hold only measured samples.
    Returns how many filled samples went."""
    state = load_state(take_coll)
    n = len(state.labeling.names)
    idx, lab, _ = filled_keys(take_coll, n)
    chosen = sorted(set(range(n) if labels is None else labels))
    layout, take = state_layout(state), current_take(take_coll)
    for label in sorted(set(lab.tolist()) & set(chosen)):
        _key_label(take_coll, take, layout, state.labeling, label)
    forget_fills(take_coll, chosen)
    return int(np.isin(lab, chosen).sum()) if len(idx) else 0


def refill(take_coll: bpy.types.Collection, solves: list | None = None) -> dict | None:
    """Fill again every label the record holds, with its method and max gap (after a re-solve,
    with the new ``solves``); None when the take has no fills."""
    record = fill_record(take_coll)
    if not record.get("gaps"):
        return None
    labels = sorted({g["label"] for g in record["gaps"]})
    return fill_scene(take_coll, record["method"], float(record["max_gap"]), labels, solves)
