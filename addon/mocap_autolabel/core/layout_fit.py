"""A layout from a labeled take: each marker's bone and place on the template hand, so that a studio
gets its layout by labeling one take instead of writing TOML.

1. **Which bone.** The layout-conditioned ``set`` model scores every labeled marker against
   :func:`scan_layout`, a set of 25 typical spots over the hand (tips, phalanges, knuckles, back of
   the hand, wrist); summed over frames, one assignment gives each marker its spot.
2. **Where on it.** The hand is calibrated with the markers at their spots
   (:func:`.hand.calibrate.calibrate`: hand size, poses and each marker's offset); each marker's
   calibrated rest position is then read back as a fraction along its bone and an angle around
   it (for palm markers: along the hand's length and across its breadth). A marker that lands
   beyond its bone's end moves to the next bone.
"""

from __future__ import annotations

import fnmatch
import os
import re
import tomllib
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from .atomic import atomic_output
from .errors import MocapInputError
from .hand.calibrate import calibrate
from .hand.skeleton import BONE_INDEX, BONE_NAMES, PARENTS, HandModel
from .hands.naming import HandNaming
from .layout import Layout, Marker, parse_layout
from .take import Take

#: Most labeled frames scored for the bone guess (spread over the take).
SCAN_FRAMES = 240
#: Fewest markers of a layout (a hand needs that many to be found and labeled at all).
FEWEST = 3
#: Most markers the model was trained on.
MOST = 25


def scan_layout() -> Layout:
    """25 typical marker spots over the hand, 12 mm apart at least (what the model was trained on)."""
    spots = [Marker("thumb_dist", "thumb_dist", 0.7), Marker("thumb_prox", "thumb_prox", 0.5),
             Marker("thumb_meta", "thumb_meta", 0.5)]
    for f in ("index", "middle", "ring", "little"):
        spots += [Marker(f"{f}_dist", f"{f}_dist", 0.7), Marker(f"{f}_mid", f"{f}_mid", 0.5),
                  Marker(f"{f}_prox", f"{f}_prox", 0.35), Marker(f"{f}_meta", f"{f}_meta", 0.9)]
    for i, (along, across) in enumerate([(0.0, 0.4), (0.0, -0.4), (0.2, 0.25), (0.2, -0.25), (0.12, 0.0),
                                         (0.3, 0.0)]):
        spots.append(Marker(f"palm{i}", "palm", along, across))
    return Layout("scan", tuple(spots), description="typical marker spots, for fitting a layout")


@dataclass
class LayoutFit:
    """A fitted layout and how well it fits: ``rms`` metres of the calibration after the fit,
    ``side`` of the hand, ``spots`` the scan spot each marker was first put on."""

    layout: Layout
    rms: float
    side: str
    spots: list[str]
    #: The markers whose names say nothing of their place (:func:`name_spots`): placed by shape alone.
    unnamed: list[str] = field(default_factory=list)

    def doubt(self) -> str | None:
        """One line where the template hand fits the markers worse than :data:`DOUBTFUL_RMS` (some may
        sit on the wrong bone or the wrong side), else None."""
        if self.rms <= DOUBTFUL_RMS:
            return None
        named = (f"; these names say nothing of their place, so shape alone placed them: {', '.join(self.unnamed)} "
                 f"(names such as IndexTip or HandTop pin a marker to its finger)") if self.unnamed else ""
        return (f"the template hand fits these markers at {1000 * self.rms:.1f} mm RMS (over "
                f"{1000 * DOUBTFUL_RMS:.0f} mm): some may sit on the wrong bone or side; check the layout before "
                f"labeling with it{named}")


#: Metres: a fit worse than this is doubtful (Han et al. 2018 reject a hand labeling whose IK fit
#: is worse than 8 mm RMS).
DOUBTFUL_RMS = 0.008


def _scan_frames(observed: np.ndarray, count: int) -> np.ndarray:
    """Up to ``count`` frames spread over the take, each with at least 60 % of the markers."""
    seen = np.isfinite(observed[..., 0])
    ok = np.flatnonzero(seen.sum(axis=1) >= max(FEWEST, int(np.ceil(0.6 * observed.shape[1]))))
    return ok[np.linspace(0, len(ok) - 1, min(count, len(ok))).astype(int)] if len(ok) else ok


#: Words of marker names that say which digit a marker is on (studios name their markers so).
_DIGIT_WORDS = (("thumb", r"thumb|thb|thm|tmb|pollex"), ("index", r"index|ind|idx|indx|fore"),
                ("middle", r"middle|mid|mdl"), ("ring", r"ring|rng"),
                ("little", r"pinky|pinkie|little|lit|small|pink|pnk|pky"))
#: Words that say which segment, and the scan spots' bone endings they allow.
_SEGMENT_WORDS = ((r"tip|nail|dist|dip", ("_dist",)), (r"pip", ("_mid",)), (r"mcp|prox", ("_prox",)),
                  (r"cmc|meta|knuckle", ("_meta",)), (r"middle|mid", ("_prox", "_mid")))
#: Words of markers on the back of the hand or the wrist.
_HAND_WORDS = r"hand|hnd|back|palm|wrist|wr[ab]?|fin$|rfin|lfin|dorsum"


def name_spots(name: str, scan: Layout) -> np.ndarray | None:
    """bool ``(S,)``: the :func:`scan_layout` spots a marker's name allows (``IndexTip``: the index's
    distal phalanx; ``thumb_middle``: the thumb's proximal or middle segment; ``HandTop``, ``WRA``: the
    back of the hand, the wrist or a knuckle), or None where the name says nothing."""
    text = re.sub(r"([a-z])([A-Z])|([A-Z])([A-Z][a-z])", r"\1\3 \2\4", name.rsplit(":", 1)[-1]).lower()
    words = re.findall(r"[a-z]+", text)
    digit, rest = None, list(words)
    for i, w in enumerate(words):
        for d, pattern in _DIGIT_WORDS:
            if re.fullmatch(pattern, w):
                digit, rest = d, words[:i] + words[i + 1:]
                break
        if digit:
            break
    endings = None
    for w in rest:
        for pattern, ends in _SEGMENT_WORDS:
            if re.fullmatch(pattern, w):
                endings = ends
                break
        if endings:
            break
    bones = [m.bone for m in scan.markers]
    if digit is None and endings is None:
        if any(re.fullmatch(_HAND_WORDS, w) for w in words):
            return np.array([b == "palm" or b.endswith("_meta") for b in bones])
        return None
    allowed = np.ones(len(bones), dtype=bool)
    if digit:
        allowed &= np.array([b.startswith(digit + "_") for b in bones])
    if endings:
        allowed &= np.array([b.endswith(endings) for b in bones])
    return allowed if allowed.any() else None


def guess_spots(observed: np.ndarray, labeler_for: Callable[[Layout], object],
                names: list[str] | None = None) -> list[int]:
    """The :func:`scan_layout` spot of each marker ``(F, M, 3)``: the assignment of most summed log
    probability over the scanned frames, among the spots each marker's name allows
    (:func:`name_spots`); ``labeler_for(layout)`` makes the layout's labeler."""
    scan = scan_layout()
    frames = _scan_frames(observed, SCAN_FRAMES)
    points = observed[frames].astype(np.float32)
    mask = np.isfinite(points[..., 0])
    points = np.where(mask[..., None], points, 0.0).astype(np.float32)
    scores = labeler_for(scan).scores(points, mask)  # (n, M, S + 1), log domain
    total = np.where(mask[..., None], scores[..., :len(scan)], 0.0).sum(axis=0)
    total /= np.maximum(mask.sum(axis=0), 1)[:, None]  # mean over the frames each marker is seen in
    for j, name in enumerate(names or []):
        allowed = name_spots(name, scan)
        if allowed is not None:
            total[j, ~allowed] -= 1e6
    rows, cols = linear_sum_assignment(-total)
    spots = np.empty(observed.shape[1], dtype=int)
    spots[rows] = cols
    return [int(s) for s in spots]


#: The calibration's pull towards each marker's first spot (its offset prior): a lone marker on a
#: distal phalanx slides along its arc as freely as the joint angles turn, and only this settles it.
FIT_PRIOR = 0.0005
#: Rounds of calibration, each but the last followed by :func:`steadiest_bones`.
ROUNDS = 2


def steadiest_bones(observed: np.ndarray, layout: Layout, cal, bones: list[int],
                    rest: np.ndarray) -> tuple[list[int], np.ndarray]:
    """Each marker's bone again: the bone in whose rest frame its positions over the calibration's
    frames stay most still (a marker rides on one bone), and its mean rest position there; the
    palm wins a tie with a finger's metacarpal. ``rest`` ``(M, 3)`` and ``bones`` are the current."""
    from .hand.ik import HandSolver

    hand = cal.hand()
    picked = np.asarray(cal.frames, dtype=int)
    fit = HandSolver(hand, layout.place(hand)[0].moved(cal.offsets)).solve(observed[picked])
    ok = fit.solved & np.isfinite(fit.poses).all(axis=1)
    if ok.sum() < 5:
        return bones, rest
    r, t = hand.skinning_transforms(fit.poses[ok])  # (F, 20, 3, 3), (F, 20, 3): rest -> posed
    p = observed[picked][ok]  # (F, M, 3)
    local = np.einsum("fbji,fmbj->fmbi", r, p[:, :, None, :] - t[:, None])  # (F, M, 20, 3) in rest space
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a marker unseen in every frame: NaN, left as it is
        spread = np.nanmean(np.sum((local - np.nanmean(local, axis=0)) ** 2, axis=-1), axis=0)  # (M, 20)
    spread[:, 0] *= 0.8  # the palm before a metacarpal that moves with it
    new_bones, new_rest = list(bones), rest.copy()
    for j in range(len(bones)):
        if not np.isfinite(spread[j]).any():
            continue
        b = int(np.nanargmin(spread[j]))
        if spread[j, b] < 0.7 * spread[j, bones[j]]:  # clearly steadier
            new_bones[j] = b
            new_rest[j] = np.nanmean(local[:, j, b], axis=0)
    return new_bones, new_rest


def _place_on(hand: HandModel, bone: int, p: np.ndarray) -> tuple[float, float, float]:
    """``(along, across, angle_deg)`` of rest position ``p`` (hand frame) on ``bone`` of ``hand``."""
    if bone == 0:
        return float(p[1] / hand.length), float(hand.thumb_side * p[0] / hand.breadth), 0.0 if p[2] >= 0 else 180.0
    r0, p0 = hand.rest
    local = r0[bone].T @ (p - p0[bone])
    angle = np.degrees(np.arctan2(hand.thumb_side * local[0], local[2]))
    return float(local[1] / hand.bone_lengths[bone]), 0.0, float(angle)


def _child(bone: int) -> int | None:
    children = [b for b, parent in enumerate(PARENTS) if parent == bone]
    return children[0] if len(children) == 1 else None


def placed_marker(hand: HandModel, name: str, bone: int, p: np.ndarray, radius: float) -> Marker:
    """The marker at rest position ``p`` read back on ``bone``, or on the next bone along its digit
    where it lies beyond this one's end (a finger marker on the palm stays on its metacarpal)."""
    for _ in range(3):
        along, across, angle = _place_on(hand, bone, p)
        if bone and along > 1.0 and _child(bone) is not None:
            bone = _child(bone)
        elif bone and along < 0.0 and PARENTS[bone] > 0:
            bone = PARENTS[bone]
        else:
            break
    along = float(np.clip(along, -0.5, 1.5))
    return Marker(name, BONE_NAMES[bone], round(along, 4), round(across, 4), round(angle, 2), None, radius)


def fit_layout(observed: np.ndarray, names: list[str], *, name: str = "fitted", labeler_for: Callable | None = None,
               frames: int = 40, source: str = "take", progress: Callable[[float], None] | None = None) -> LayoutFit:
    """A layout for a labeled take: each marker's bone and place on the template hand.

    Args:
        observed: ``(F, M, 3)`` the labeled markers, metres, NaN where missing (one hand).
        names: ``(M,)`` their names, the layout's marker names.
        name: the layout's name.
        labeler_for: makes the labeler of a layout (default: the shipped ``set`` model).
        frames: frames the calibration is solved on.
        source: what the markers came from, for errors.
        progress: called with the share done (0-1).

    Raises:
        MocapInputError: too few or too many markers, or too few frames in which most are seen.
    """
    tick = progress or (lambda _share: None)
    observed = np.asarray(observed, dtype=float)
    m = observed.shape[1]
    if not FEWEST <= m <= MOST:
        raise MocapInputError(source, f"a layout is fitted from {FEWEST} to {MOST} labeled markers of one hand, "
                                      f"not {m}")
    if len(_scan_frames(observed, SCAN_FRAMES)) < 10:
        raise MocapInputError(source, "fewer than 10 frames show most of the labeled markers: label a take (or a "
                                      "calibration pose) in which the hand is well seen")
    if labeler_for is None:
        from .labelers import make_labeler

        def labeler_for(layout: Layout):
            return make_labeler("set", layout)

    spots = guess_spots(observed, labeler_for, names)
    tick(0.2)
    scan = scan_layout()
    layout = Layout(name, tuple(Marker(n, scan.markers[s].bone, scan.markers[s].along, scan.markers[s].across)
                                for n, s in zip(names, spots)), description="fitted from a labeled take")
    for round_ in range(ROUNDS):
        share = (0.2 + 0.75 * round_ / ROUNDS, 0.75 / ROUNDS)
        last = round_ == ROUNDS - 1
        try:  # the hand's size only once the markers sit on their bones: a marker on the wrong one drags it
            cal = calibrate(observed, layout, frames=frames, prior=FIT_PRIOR, solve_size=last,
                            progress=lambda s, a=share: tick(a[0] + a[1] * s))
        except ValueError:  # an implausible size: the average hand's
            cal = calibrate(observed, layout, frames=frames, prior=FIT_PRIOR, solve_size=False)
        hand = cal.hand()
        rest = layout.place(hand)[0].rest + cal.offsets
        bones = [BONE_INDEX[mk.bone] for mk in layout.markers]
        if not last:  # the calibration's poses say which bone each marker rides on
            bones, rest = steadiest_bones(observed, layout, cal, bones, rest)
        layout = Layout(name, tuple(placed_marker(hand, n, b, p, mk.radius)
                                    for n, b, mk, p in zip(names, bones, layout.markers, rest)),
                        description="fitted from a labeled take")
    tick(1.0)
    markers = layout.markers
    layout = Layout(name, markers, layout.glove, f"fitted from {source} ({cal.side} hand, "
                                                f"{1000 * cal.rms_after:.1f} mm RMS)")
    return LayoutFit(layout, float(cal.rms_after), cal.side, [scan.names[s] for s in spots],
                     [n for n in names if name_spots(n, scan) is None])


def hand_points(take: Take, *, side: str | None = None, naming: HandNaming | None = None,
                points: list[str] | None = None) -> tuple[np.ndarray, list[str]]:
    """One hand's labeled markers of ``take``: ``(F, M, 3)`` metres and their names.

    Args:
        side: keep the points named for this hand by ``naming`` (default ``L_``/``R_`` prefixes), their
            names without the side token; None: every labeled point, names as they are.
        points: keep only names matching one of these wildcards (``*``, ``?``), after the side is taken off.

    Raises:
        MocapInputError: no labeled point is left.
    """
    keep, names = [], []
    pattern = None
    if side is not None:
        naming = naming or HandNaming()
        template = re.escape(naming.template).replace(re.escape("{name}"), "(?P<name>.+)")
        for token, value in (("{S}", side[0].upper()), ("{side}", side), ("{Side}", side.capitalize())):
            template = template.replace(re.escape(token), re.escape(value))
        pattern = re.compile(template + "$")
    for i, full in enumerate(take.names):
        if take.unlabeled[i]:
            continue
        name = full.rsplit(":", 1)[-1] if pattern is None else full
        if pattern is not None:
            found = pattern.match(full)
            if not found:
                continue
            name = found.group("name")
        if points and not any(fnmatch.fnmatchcase(name, p) for p in points):
            continue
        keep.append(i)
        names.append(name)
    if not keep:
        what = f"no labeled point of the {side} hand" if side else "no labeled point"
        raise MocapInputError(take.source, f"{what}{' matches ' + ', '.join(points) if points else ''}: "
                                           "label the take first (or check --side, --hand-names, --points)")
    return take.positions[:, keep].astype(np.float64), names


def layout_toml(layout: Layout) -> str:
    """``layout`` as a layout TOML (see :mod:`.layout`), each marker on its bone by fractions and angle."""
    lines = [f"name = {_quoted(layout.name)}", f"description = {_quoted(layout.description)}",
             f"glove_mm = {1000 * layout.glove:g}", ""]
    for mk in layout.markers:
        lines += ["[[markers]]", f"name = {_quoted(mk.name)}", f'bone = "{mk.bone}"', f"along = {mk.along:g}"]
        if mk.bone == "palm":
            lines.append(f"across = {mk.across:g}")
        if mk.angle_deg:
            lines.append(f"angle_deg = {mk.angle_deg:g}")
        lines += [f"radius_mm = {1000 * mk.radius:g}", ""]
    return "\n".join(lines)


def write_fitted_layout(take: Take, path: str, *, side: str | None = None, naming: HandNaming | None = None,
                        points: list[str] | None = None, name: str | None = None, frames: int = 40,
                        progress: Callable[[float], None] | None = None) -> LayoutFit:
    """Fit a layout to one hand's labeled markers of ``take`` (:func:`hand_points`, :func:`fit_layout`)
    and write it to ``path`` as TOML, atomically; what is written is read back as a layout first."""
    observed, names = hand_points(take, side=side, naming=naming, points=points)
    name = name or os.path.splitext(os.path.basename(path))[0]
    fit = fit_layout(observed, names, name=name, source=take.source, frames=frames, progress=progress)
    text = layout_toml(fit.layout)
    parse_layout(tomllib.loads(text), path)
    with atomic_output(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
    return fit


def _quoted(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'
