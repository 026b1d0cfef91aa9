"""Per-performer marker calibration: hand size and where each marker really sits.

A layout says where markers go on an average hand; on a real performer the hand is longer or
broader and every marker sits a few millimetres off. Calibration solves, jointly over a few
dozen varied frames of a labeled take (METHODS.md B):

    E = sum_frames sum_markers ||LBS(theta_f, m_j) - p_fj||^2
        + w * frames * sum_j (2 (n_j . d_j)^2 + |d_j - (n_j . d_j) n_j|^2)

over the frames' poses theta_f, the hand length and breadth, and each marker's offset d_j from
its layout position (rest hand frame; moving along the skin normal n_j costs twice as much as
moving along the skin). One Levenberg-Marquardt over all of it, its normal equations solved
exactly each step by blocks: every frame's pose touches only that frame's markers (and its
pinches), so the ~1,100 x 1,100 system is block-arrow shaped; each frame's 26 x 26 pose block is
eliminated (batched Cholesky) and only the Schur complement over the shared unknowns (offsets,
size, pads: ~60) is solved whole (issue 48: 9 s of dense algebra per calibration before).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..atomic import read_json, write_json
from ..errors import MocapInputError
from ..layout import Layout
from ..synth.poses import CANONICAL_POSES
from .ik import MIN_MARKERS, HandSolver, solve_spd
from .skeleton import BONE_INDEX, DIGITS, FINGERS, N_DOF, POSE_LIMITS, HandModel
from .skin import Binding, segment_weights, skin_point

#: Cost of moving a marker along its skin normal, and along the skin (METHODS.md B).
ALPHA_NORMAL, ALPHA_TANGENT = 2.0, 1.0
FORMAT = "mocap_autolabel.calibration/1"
#: A pinch frame whose pads stay further apart than this after a round is left out, metres.
CONTACT_DROP = 0.010


@dataclass
class Calibration:
    """A performer's hand and markers for one layout.

    Attributes:
        layout: the layout's name.
        names: ``(M,)`` its marker names, in order.
        side: ``"left"`` or ``"right"``.
        length, breadth: hand length and breadth, metres.
        offsets: ``(M, 3)`` each marker's offset from its layout position, rest hand frame, metres.
        rms_before, rms_after: marker RMS of the calibration frames before and after, metres.
        frames: the take frames (0-based) it was solved on.
        contacts: per digit, its contact pad on the distal phalanx: [along (fraction of the bone),
            angle around it (degrees, 180 = palmar)], when pinch frames were given.
        contact_gap: largest thumb-to-finger pad distance left in the pinch frames, metres.
        contacts_dropped: pinch frames left out because their gap stayed over ``CONTACT_DROP``.
    """

    layout: str
    names: list[str]
    side: str
    length: float
    breadth: float
    offsets: np.ndarray
    rms_before: float = float("nan")
    rms_after: float = float("nan")
    frames: list[int] = field(default_factory=list)
    contacts: dict[str, list[float]] = field(default_factory=dict)
    contact_gap: float = float("nan")
    contacts_dropped: int = 0

    def hand(self) -> HandModel:
        return HandModel(length=self.length, breadth=self.breadth, side=self.side)

    def binding(self, layout: Layout) -> Binding:
        """The markers of ``layout`` on this hand, offsets applied."""
        self.check(layout)
        return layout.place(self.hand())[0].moved(self.offsets)

    def solver(self, layout: Layout, **kwargs) -> HandSolver:
        return HandSolver(self.hand(), self.binding(layout), **kwargs)

    def check(self, layout: Layout, path: str = "calibration") -> None:
        if list(layout.names) != list(self.names):
            raise MocapInputError(path, f"was made for layout {self.layout!r} ({len(self.names)} markers), "
                                        f"not {layout.name!r} ({len(layout)} markers)")

    def to_dict(self) -> dict:
        """JSON-ready; lengths in millimetres, as at every file boundary."""
        return {"format": FORMAT, "layout": self.layout, "side": self.side,
                "hand_length_mm": round(self.length * 1000, 4), "hand_breadth_mm": round(self.breadth * 1000, 4),
                "markers": {n: [round(v * 1000, 4) for v in o] for n, o in zip(self.names, self.offsets)},
                "rms_before_mm": round(self.rms_before * 1000, 4), "rms_after_mm": round(self.rms_after * 1000, 4),
                "frames": [int(f) for f in self.frames], "contacts": self.contacts,
                "contact_gap_mm": round(self.contact_gap * 1000, 4) if np.isfinite(self.contact_gap) else None,
                "contacts_dropped": self.contacts_dropped}

    def save(self, path: str | os.PathLike) -> None:
        write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike) -> Calibration:
        """Read a calibration file; any problem is one :class:`MocapInputError` naming the file."""
        return cls.from_dict(read_json(path, "calibration"), os.fspath(path))

    @classmethod
    def from_dict(cls, data: dict, where: str = "calibration") -> Calibration:
        """A calibration from :meth:`to_dict`'s dict (a file's, or one kept with a solved rig);
        any problem is one :class:`MocapInputError` naming ``where``."""
        try:
            if data.get("format") != FORMAT:
                raise ValueError(f"format is {data.get('format')!r}, expected {FORMAT!r}")
            names = list(data["markers"])
            offsets = np.array([data["markers"][n] for n in names], dtype=float).reshape(len(names), 3) / 1000
            out = cls(str(data["layout"]), names, str(data["side"]), float(data["hand_length_mm"]) / 1000,
                      float(data["hand_breadth_mm"]) / 1000, offsets, float(data.get("rms_before_mm", "nan")) / 1000,
                      float(data.get("rms_after_mm", "nan")) / 1000, list(data.get("frames", [])),
                      dict(data.get("contacts", {})), float(data.get("contact_gap_mm") or "nan") / 1000,
                      int(data.get("contacts_dropped", 0)))
            out.hand()  # validates the size and side
        except (KeyError, TypeError, ValueError) as exc:
            raise MocapInputError(where, f"not a valid calibration ({exc})") from None
        return out


def detect_side(observed: np.ndarray, layout: Layout, hand: HandModel | None = None, sample: int = 24) -> str:
    """``"left"`` or ``"right"``: the side whose hand fits ``observed (F, M, 3)`` better: the lower
    median marker residual, which one mislabeled marker (a ghost holding a fingertip of a sparse
    set) cannot rule as it rules the RMS."""
    hand = hand or HandModel()
    frames = _well_seen(observed)
    frames = frames[np.linspace(0, len(frames) - 1, min(sample, len(frames))).astype(int)]
    median = {}
    for side in ("left", "right"):
        h = HandModel(hand.length, hand.breadth, side)
        solver = HandSolver(h, layout.place(h)[0])
        median[side] = np.nanmedian(solver.evaluate(solver.cold_start(observed[frames]), observed[frames]).residuals)
    return min(median, key=median.get)


def _well_seen(observed: np.ndarray) -> np.ndarray:
    """Frames with the most markers seen (all of them where there are enough such frames)."""
    seen = np.isfinite(observed).all(axis=-1).sum(axis=1)
    need = max(MIN_MARKERS, int(np.ceil(0.9 * observed.shape[1])))
    frames = np.flatnonzero(seen >= need)
    if len(frames) < 8:
        frames = np.flatnonzero(seen >= MIN_MARKERS)
    if not len(frames):
        raise ValueError(f"no frame shows at least {MIN_MARKERS} markers")
    return frames


def _diverse(angles: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` rows of ``angles (N, 20)`` chosen by farthest-point sampling."""
    chosen = [0]
    dist = np.linalg.norm(angles - angles[0], axis=1)
    for _ in range(min(count, len(angles)) - 1):
        chosen.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(angles - angles[chosen[-1]], axis=1))
    return np.array(sorted(set(chosen)))


def calibrate(observed: np.ndarray, layout: Layout, side: str | None = None, hand: HandModel | None = None,
              frames: int = 40, prior: float = 0.0005, iterations: int = 60, rounds: int = 3,
              solve_size: bool = True, reference: np.ndarray | None = None,
              reference_pose: np.ndarray | None = None,
              contacts: Sequence[tuple[int, str]] = (), contact_after: int = 10,
              progress: Callable[[float], None] | None = None) -> Calibration:
    """Solve the performer's hand size and marker offsets from a labeled take.

    Args:
        observed: ``(F, M, 3)`` the layout's markers over a take (a range-of-motion take, or any
            take with varied poses), metres, NaN where missing.
        layout: the layout the markers follow.
        side: the hand's side; detected from the data when None.
        hand: starting size (default: the average hand).
        frames: how many frames to solve on, picked for the most varied poses.
        prior: weight of the offset prior per frame (larger keeps markers nearer the layout).
        iterations: Levenberg-Marquardt steps in all.
        rounds: the steps are split into rounds; each later round first refits every frame's pose
            from a cold start where that fits better.
        solve_size: also solve hand length and breadth (else only the offsets).
        reference: frames (0-based) in which the performer holds a known pose, such as the flat
            hand a range-of-motion take starts with. Without one, an offset that a constant
            joint-angle bias explains equally well (a lone marker on a distal phalanx moving
            along its arc) is only settled by the prior; with one it is measured.
        reference_pose: the joint angles ``(20,)`` radians of that pose (default: flat hand).
        contacts: pinch frames, ``(frame, finger)`` with the finger one of index, middle, ring,
            little: in that frame the thumb's pad touches the finger's pad. Each pad is a contact
            point that slides on its distal phalanx's skin (along the bone and around it), solved
            with the rest; the contact term pulls the two together (METHODS.md B, E_contact). Like a
            reference pose, it measures what a joint-angle bias would otherwise absorb.
        contact_after: iterations before the contact term switches on (the paper: 10).
        progress: called with the share done (0-1) as the calibration goes (the first pose fit is
            about a third of it, the rest its iterations); it may raise to stop it.
    """
    tick = progress or (lambda _share: None)
    observed = np.asarray(observed, dtype=float)
    if observed.ndim != 3 or observed.shape[1] != len(layout) or observed.shape[2] != 3:
        raise ValueError(f"observed must be (frames, {len(layout)}, 3), got {observed.shape}")
    hand = hand or HandModel()
    side = side or detect_side(observed, layout, hand)
    hand = HandModel(hand.length, hand.breadth, side)
    placed, normals = layout.place(hand)
    picked, poses = _varied_frames(observed, hand, placed, frames, tick)
    pinned = np.zeros(len(picked), dtype=bool)
    if reference is not None and len(reference):
        picked, poses, pinned = _with_reference(observed, hand, placed, picked, poses, pinned, reference,
                                                reference_pose)
    digits = sorted({"thumb"} | {f for _, f in contacts}, key=DIGITS.index) if contacts else []
    pairs = np.zeros((0, 3), dtype=int)  # (row in picked, thumb's pad, finger's pad)
    if contacts:
        picked, poses, pinned, pairs = _with_contacts(observed, hand, placed, picked, poses, pinned, contacts, digits)
    fit = _Fit.over(observed[picked], layout, hand, normals, prior, digits, pairs, pinned, solve_size)
    poses, size, offsets, pads, dropped, rms_before = _solve(fit, poses, rounds, iterations, contact_after, tick)
    final = fit.model(size, offsets)
    rms_after = float(np.sqrt(((final.markers(poses) - fit.obs0) ** 2 * fit.w).sum() / fit.seen.sum()))
    contact = {d: [round(float(pads[2 * i]), 4), round(float(np.degrees(pads[2 * i + 1])), 2)]
               for i, d in enumerate(digits)}
    gap = float(np.linalg.norm(fit.gaps(poses, size, pads), axis=1).max()) if len(fit.pairs) else float("nan")
    return Calibration(layout.name, list(layout.names), side, final.hand.length, final.hand.breadth, offsets,
                       rms_before, rms_after, [int(f) for f in picked], contact, gap, dropped)


def _varied_frames(observed: np.ndarray, hand: HandModel, placed: Binding, frames: int,
                   tick: Callable[[float], None]) -> tuple[np.ndarray, np.ndarray]:
    """At most ``frames`` well-seen frames of the most varied poses (0-based) and their poses, fitted
    with the layout's markers on ``hand`` (the first third of the progress)."""
    candidates = _well_seen(observed)
    if len(candidates) > 60 * frames:  # plenty to choose varied poses from, at a bounded cost
        candidates = candidates[np.linspace(0, len(candidates) - 1, 60 * frames).astype(int)]
    first = HandSolver(hand, placed).solve(observed[candidates], progress=lambda done: tick(0.3 * done))
    ok = first.solved
    chosen = _diverse(first.poses[ok, 6:], frames)
    return candidates[ok][chosen], first.poses[ok][chosen]


def _with_reference(observed: np.ndarray, hand: HandModel, placed: Binding, picked: np.ndarray, poses: np.ndarray,
                    pinned: np.ndarray, reference: np.ndarray,
                    reference_pose: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``picked``, ``poses`` and ``pinned`` with up to five frames of the known ``reference`` pose put
    first, pinned to its joint angles (their global rotation and position fitted)."""
    ref = np.asarray(reference, dtype=int)
    ref = ref[np.linspace(0, len(ref) - 1, min(5, len(ref))).astype(int)]
    joints = CANONICAL_POSES["flat"] if reference_pose is None else np.asarray(reference_pose)
    ref_solver = HandSolver(hand, placed)
    ref_poses = ref_solver.cold_start(observed[ref])
    ref_poses[:, 6:] = joints
    ref_poses = _refine_global(ref_solver, ref_poses, observed[ref])
    picked = np.concatenate([ref, picked])
    poses = np.concatenate([ref_poses, poses])
    pinned = np.concatenate([np.ones(len(ref), dtype=bool), pinned])
    return picked, poses, pinned


def _with_contacts(observed: np.ndarray, hand: HandModel, placed: Binding, picked: np.ndarray, poses: np.ndarray,
                   pinned: np.ndarray, contacts: Sequence[tuple[int, str]],
                   digits: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``picked``, ``poses`` and ``pinned`` with the pinch frames of ``contacts`` added (cold-started
    poses), and the pairs ``(row in picked, thumb's pad, finger's pad)`` of each pinch."""
    bad = [f for _, f in contacts if f not in FINGERS]
    if bad:
        raise ValueError(f"contacts name fingers {bad}; fingers are {', '.join(FINGERS)}")
    frames_c = np.array([f for f, _ in contacts], dtype=int)
    new = np.setdiff1d(frames_c, picked)
    if len(new):
        picked = np.concatenate([picked, new])
        poses = np.concatenate([poses, HandSolver(hand, placed).cold_start(observed[new])])
        pinned = np.concatenate([pinned, np.zeros(len(new), dtype=bool)])
    row = {int(f): i for i, f in enumerate(picked)}
    pairs = np.array([(row[int(f)], 0, digits.index(d)) for f, d in contacts], dtype=int)
    return picked, poses, pinned, pairs


@dataclass
class _Fit:
    """The calibration's least-squares problem over the ``K`` picked frames: their markers, the
    offsets' prior, and the pinch contacts (``pairs``, which :func:`_solve` drops as it goes).

    Unknowns, in this order: ``K`` poses, ``M`` offsets, the hand's log length and breadth (where
    solved), each contact digit's pad (along, angle).
    """

    layout: Layout
    hand: HandModel
    obs: np.ndarray  # (K, M, 3) the picked frames' markers, NaN where missing
    obs0: np.ndarray  # the same, 0 where missing
    seen: np.ndarray  # bool (K, M)
    w: np.ndarray  # (K, M, 1): 1 where seen
    prior_mat: np.ndarray  # (M, 3, 3): the offsets' prior as a residual
    digits: list[str]
    pairs: np.ndarray
    pinned: np.ndarray  # bool (K,): frames of a known pose keep their joint angles
    n_size: int
    placed: dict = field(default_factory=dict, repr=False)  # size -> the solver of the layout placed on that hand

    @classmethod
    def over(cls, obs: np.ndarray, layout: Layout, hand: HandModel, normals: np.ndarray, prior: float,
             digits: list[str], pairs: np.ndarray, pinned: np.ndarray, solve_size: bool) -> _Fit:
        seen = np.isfinite(obs).all(axis=-1)
        w = seen[..., None].astype(float)
        obs0 = np.where(seen[..., None], obs, 0.0)
        weight = prior * len(obs)
        # Prior as a residual: sqrt(weight) * (sqrt(a_n) n n^T + sqrt(a_t) (I - n n^T)) d.
        nn = normals[:, :, None] * normals[:, None, :]
        prior_mat = np.sqrt(weight) * (np.sqrt(ALPHA_NORMAL) * nn + np.sqrt(ALPHA_TANGENT) * (np.eye(3) - nn))
        return cls(layout, hand, obs, obs0, seen, w, prior_mat, digits, pairs, pinned, 2 if solve_size else 0)

    @property
    def k(self) -> int:
        return len(self.obs)

    @property
    def m(self) -> int:
        return len(self.layout)

    @property
    def n_pose(self) -> int:
        return self.k * N_DOF

    @property
    def n_pad(self) -> int:
        return 2 * len(self.digits)

    @property
    def n_par(self) -> int:
        return self.n_pose + 3 * self.m + self.n_size + self.n_pad

    def sized(self, size: np.ndarray) -> HandModel:
        return self._placed(size).hand

    def _placed(self, size: np.ndarray) -> HandSolver:
        """The solver of the layout placed on the hand of ``size``, built once per size (a step
        asks for the same size several times: its residuals, Jacobian and candidate)."""
        key = np.asarray(size, dtype=float).tobytes()
        if key not in self.placed:
            some = next(iter(self.placed.values()), None)
            if len(self.placed) > 16:
                self.placed.clear()
            hand = self.hand
            h = HandModel(float(hand.length * np.exp(size[0])), float(hand.breadth * np.exp(size[1])), hand.side)
            placed = self.layout.place(h)[0]
            self.placed[key] = HandSolver(h, placed) if some is None else some.rebound(h, placed)
        return self.placed[key]

    def model(self, size: np.ndarray, offsets: np.ndarray) -> HandSolver:
        return self._placed(size).moved(offsets)

    def gaps(self, p: np.ndarray, size: np.ndarray, pads: np.ndarray) -> np.ndarray:
        """``(C, 3)`` thumb pad minus finger pad in each pinch frame, metres."""
        pairs = self.pairs
        h = self.sized(size)
        at = HandSolver(h, _pads(h, self.digits, pads)).markers(p[pairs[:, 0]])
        return at[np.arange(len(pairs)), pairs[:, 1]] - at[np.arange(len(pairs)), pairs[:, 2]]

    def residuals(self, p: np.ndarray, size: np.ndarray, offsets: np.ndarray, pads: np.ndarray,
                  touching: bool) -> tuple[np.ndarray, float]:
        data = (self.model(size, offsets).markers(p) - self.obs0) * self.w
        pri = (self.prior_mat @ offsets[:, :, None])[..., 0]
        cost = float((data ** 2).sum() + (pri ** 2).sum())
        if touching and len(self.pairs):
            cost += float((self.gaps(p, size, pads) ** 2).sum())
        return data, cost

    def refit_cold(self, poses: np.ndarray, size: np.ndarray, offsets: np.ndarray, touching: bool) -> np.ndarray:
        """``poses`` with each frame refitted from a cold start where that fits better (not a pinned
        frame, nor a pinch frame once the contacts count)."""
        obs, pairs = self.obs, self.pairs
        solver = self.model(size, offsets)
        fresh = solver.cold_start(obs)
        better = (solver.evaluate(fresh, obs).rms < solver.evaluate(poses, obs).rms) & ~self.pinned
        better[pairs[:, 0]] &= not touching  # a pinch frame's pose answers to its contact too
        return np.where(better[:, None], fresh, poses)

    def system(self, poses: np.ndarray, size: np.ndarray, offsets: np.ndarray, pads: np.ndarray,
               touching: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The normal equations ``J^T J`` and gradient ``J^T r`` of every residual (markers, prior,
        contacts) over every unknown, by blocks: each frame's pose touches only its own markers (and
        its pinches), so ``J^T J`` is block-arrow shaped. Returns ``a_pp (K, 26, 26)``, ``a_pg
        (K, 26, G)``, ``a_gg (G, G)``, ``g_p (K, 26)``, ``g_g (G,)``, G the shared unknowns (offsets,
        size, pads)."""
        k, m, pairs, w, obs0 = self.k, self.m, self.pairs, self.w, self.obs0
        n_size, n_pad = self.n_size, self.n_pad
        n_g = 3 * m + n_size + n_pad
        solver = self.model(size, offsets)
        pred, jac_pose = solver.jacobian(poses)  # (K, M, 3), (K, M, 3, 26)
        r = ((pred - obs0) * w).reshape(k, 3 * m)
        jp = (jac_pose * w[..., None]).reshape(k, 3 * m, N_DOF)
        jg = np.zeros((k, m, 3, n_g))
        # Offsets move a marker with its bones' blended rotation.
        rots, _ = solver.hand.forward(poses)
        skin = rots @ np.swapaxes(solver.hand.rest[0], -1, -2)
        b, bw = solver.binding.bones, solver.binding.weights
        blended = skin[:, b[:, 0]] * bw[None, :, 0, None, None] + skin[:, b[:, 1]] * bw[None, :, 1, None, None]
        j = np.arange(m)
        jg[:, :, :, :3 * m].reshape(k, m, 3, m, 3)[:, j, :, j, :] = np.swapaxes(blended * w[..., None], 0, 1)
        con = self.gaps(poses, size, pads) if touching else np.zeros((len(pairs), 3))
        jc = np.zeros((len(pairs), 3, n_g))  # the contacts' rows over the shared unknowns
        for i in range(n_size):  # hand length and breadth by finite differences
            h = np.zeros(2)
            h[i] = 1e-4
            moved = ((self.model(size + h, offsets).markers(poses) - obs0) * w).reshape(k, 3 * m)
            jg[..., 3 * m + i] = ((moved - r) / 1e-4).reshape(k, m, 3)
            if touching:
                jc[..., 3 * m + i] = (self.gaps(poses, size + h, pads) - con) / 1e-4
        jg = jg.reshape(k, 3 * m, n_g)
        jpt, jgt = np.swapaxes(jp, 1, 2), np.swapaxes(jg, 1, 2)
        # Frame by frame, then summed: small products that a threaded BLAS runs on one thread (a
        # long matrix-vector product is split over threads, and its sums then depend on their count).
        a_pp = jpt @ jp
        a_pg = jpt @ jg
        a_gg = (jgt @ jg).sum(axis=0)
        g_p = (jpt @ r[..., None])[..., 0]
        g_g = (jgt @ r[..., None])[..., 0].sum(axis=0)
        prior = np.zeros((3 * m, 3 * m))
        prior.reshape(m, 3, m, 3)[j, :, j, :] = self.prior_mat
        a_gg[:3 * m, :3 * m] += prior.T @ prior
        g_g[:3 * m] += prior.T @ (self.prior_mat @ offsets[:, :, None]).ravel()
        if touching and len(pairs):
            h_ = self.sized(size)
            _, jac_pad = HandSolver(h_, _pads(h_, self.digits, pads)).jacobian(poses[pairs[:, 0]])  # (C, D, 3, 26)
            c = np.arange(len(pairs))
            jgap = jac_pad[c, pairs[:, 1]] - jac_pad[c, pairs[:, 2]]  # (C, 3, 26)
            for i in range(n_pad):  # pads slide on the skin: finite differences
                h = np.zeros(n_pad)
                h[i] = 1e-4
                jc[..., n_g - n_pad + i] = (self.gaps(poses, size, pads + h) - con) / 1e-4
            jgt = np.swapaxes(jgap, 1, 2)  # (C, 26, 3)
            np.add.at(a_pp, pairs[:, 0], jgt @ jgap)
            np.add.at(a_pg, pairs[:, 0], jgt @ jc)
            np.add.at(g_p, pairs[:, 0], (jgt @ con[..., None])[..., 0])
            jct = np.swapaxes(jc, 1, 2)
            a_gg += (jct @ jc).sum(axis=0)
            g_g += (jct @ con[..., None])[..., 0].sum(axis=0)
        return a_pp, a_pg, a_gg, g_p, g_g

    def step(self, poses: np.ndarray, size: np.ndarray, offsets: np.ndarray, pads: np.ndarray, touching: bool,
             lam: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One damped Gauss-Newton step (damping ``lam``): candidate poses, size, offsets and pads.

        The damped normal equations are solved exactly, by blocks (:func:`_block_solve`), instead
        of as one dense ~1,100-unknown system."""
        k, m, n_size, n_pad = self.k, self.m, self.n_size, self.n_pad
        lo, hi = POSE_LIMITS
        a_pp, a_pg, a_gg, g_p, g_g = self.system(poses, size, offsets, pads, touching)
        d = np.arange(N_DOF)
        a_pp[:, d, d] += lam * a_pp[:, d, d] + 1e-12
        e = np.arange(len(a_gg))
        a_gg[e, e] += lam * a_gg[e, e] + 1e-12
        # Known poses keep their joint angles: those unknowns leave the system.
        fixed = np.zeros((k, N_DOF), dtype=bool)
        fixed[self.pinned, 6:] = True
        a_pp[fixed[:, :, None] | fixed[:, None, :]] = 0.0
        a_pp[fixed[:, :, None] & np.eye(N_DOF, dtype=bool)] = 1.0
        a_pg[fixed] = 0.0
        g_p[fixed] = 0.0
        delta_p, delta_g = _block_solve(a_pp, a_pg, a_gg, g_p, g_g)
        cand_poses = HandSolver.step(poses, delta_p)
        cand_poses[:, 6:] = np.clip(cand_poses[:, 6:], lo[6:], hi[6:])
        cand_offsets = offsets + delta_g[:3 * m].reshape(m, 3)
        cand_size = size + np.concatenate([delta_g[3 * m:3 * m + n_size], np.zeros(2 - n_size)])
        cand_pads = pads + delta_g[len(delta_g) - n_pad:]
        cand_pads[0::2] = np.clip(cand_pads[0::2], 0.25, 1.0)  # stay on the distal phalanx
        return cand_poses, cand_size, cand_offsets, cand_pads


def _solve(fit: _Fit, poses: np.ndarray, rounds: int, iterations: int, contact_after: int,
           tick: Callable[[float], None]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, float]:
    """Levenberg-Marquardt over ``fit``'s unknowns from ``poses``, in ``rounds``: the poses, size,
    offsets and pads found, how many pinch frames were dropped, and the marker RMS before."""
    size, offsets = np.zeros(2), np.zeros((fit.m, 3))
    pads = np.tile([0.6, np.pi], len(fit.digits))  # (along, angle) per digit: the palmar pad
    touching = False
    dropped = 0
    _, cost = fit.residuals(poses, size, offsets, pads, touching)
    rms_before = float(np.sqrt(((fit.model(size, offsets).markers(poses) - fit.obs0) ** 2 * fit.w).sum()
                               / fit.seen.sum()))
    for round_ in range(rounds):
        if round_ and touching and len(fit.pairs):
            # A pinch frame whose pose fell into another basin cannot close its gap and would bend
            # the calibration towards it: drop its contact (the markers still count).
            keep = np.linalg.norm(fit.gaps(poses, size, pads), axis=1) <= CONTACT_DROP
            dropped += int((~keep).sum())
            fit.pairs = fit.pairs[keep]
        if round_:
            # The poses were first fitted with the uncalibrated markers; some may sit in a wrong
            # basin that the offsets then bend towards. Refit each frame from scratch too.
            poses = fit.refit_cold(poses, size, offsets, touching)
            _, cost = fit.residuals(poses, size, offsets, pads, touching)
        lam = 1e-3
        for it in range(iterations // rounds):
            tick(0.3 + 0.7 * (round_ * (iterations // rounds) + it) / max(1, rounds * (iterations // rounds)))
            if not touching and len(fit.pairs) and round_ * (iterations // rounds) + it >= contact_after:
                touching = True
                _, cost = fit.residuals(poses, size, offsets, pads, touching)
            cand_poses, cand_size, cand_offsets, cand_pads = fit.step(poses, size, offsets, pads, touching, lam)
            _, cand_cost = fit.residuals(cand_poses, cand_size, cand_offsets, cand_pads, touching)
            if cand_cost < cost:
                poses, offsets, size, pads, cost = cand_poses, cand_offsets, cand_size, cand_pads, cand_cost
                lam = max(lam / 3, 1e-9)
            else:
                lam = min(lam * 4, 1e9)
    return poses, size, offsets, pads, dropped, rms_before


def _block_solve(a_pp: np.ndarray, a_pg: np.ndarray, a_gg: np.ndarray, g_p: np.ndarray,
                 g_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve the block-arrow system ``[[diag(a_pp), a_pg], [a_pg^T, a_gg]] [dp; dg] = -[g_p; g_g]``
    (K frames' 26 x 26 pose blocks, G shared unknowns): a block Cholesky. Each pose block is
    factored (``L``) and eliminated through ``Y = L^-1 [a_pg | g_p]``, which leaves the Schur
    complement ``a_gg - sum Y^T Y`` over the shared unknowns; the poses follow by one back
    substitution each. Returns ``dp (K, 26)`` and ``dg (G,)``."""
    k, n, n_g = a_pg.shape
    try:
        low = np.linalg.cholesky(a_pp)
    except np.linalg.LinAlgError:  # not positive definite (never seen): solve the blocks as they are
        x = solve_spd(a_pp, np.concatenate([a_pg, g_p[..., None]], axis=2))
        apg_t = np.swapaxes(a_pg, 1, 2)
        delta_g = solve_spd(((a_gg - (apg_t @ x[..., :-1]).sum(axis=0)))[None],
                            (-g_g + (apg_t @ x[..., -1:]).sum(axis=0)[:, 0])[None])[0]
        return -x[..., -1] - (x[..., :-1] * delta_g).sum(axis=2), delta_g
    lt = np.ascontiguousarray(np.moveaxis(low, 0, -1))  # (26, 26, K)
    y = np.ascontiguousarray(np.concatenate([a_pg, g_p[..., None]], axis=2).transpose(1, 2, 0))  # (26, G + 1, K)
    for i in range(n):  # L y = [a_pg | g_p]
        y[i] /= lt[i, i]
        y[i + 1:] -= lt[i + 1:, i, None] * y[i]
    yf = np.ascontiguousarray(y.transpose(2, 0, 1))  # (K, 26, G + 1)
    yt = np.swapaxes(yf[..., :-1], 1, 2)
    schur = a_gg - (yt @ yf[..., :-1]).sum(axis=0)
    rhs = -g_g + (yt @ yf[..., -1:]).sum(axis=0)[:, 0]
    delta_g = solve_spd(schur[None], rhs[None])[0]
    x = -(y[:, -1] + (y[:, :-1] * delta_g[:, None]).sum(axis=1))  # (26, K): L^T dp = -(y + Y dg)
    for i in range(n - 1, -1, -1):
        x[i] /= lt[i, i]
        x[:i] -= lt[i, :i] * x[i]
    return x.T, delta_g


def _pads(hand: HandModel, digits: list[str], pads: np.ndarray) -> Binding:
    """Contact points on the skin of each digit's distal phalanx; ``pads`` holds (along, angle) pairs."""
    bones = np.array([BONE_INDEX[f"{d}_dist"] for d in digits], dtype=np.int64)
    rest = np.array([skin_point(hand, b, pads[2 * i], pads[2 * i + 1])[0] for i, b in enumerate(bones)])
    return Binding(rest, *segment_weights(bones, pads[0::2]))


def _refine_global(solver: HandSolver, poses: np.ndarray, observed: np.ndarray, iterations: int = 20) -> np.ndarray:
    """Fit only the global rotation and position of ``poses``, joint angles held."""
    joints = poses[:, 6:].copy()
    for _ in range(iterations):
        pred, jac = solver.jacobian(poses)
        seen = np.isfinite(observed).all(axis=-1)
        r = np.where(seen[..., None], pred - observed, 0.0).reshape(len(poses), -1)
        j = (jac[..., :6] * seen[..., None, None]).reshape(len(poses), -1, 6)
        jt = np.swapaxes(j, 1, 2)
        delta = np.zeros_like(poses)
        delta[:, :6] = -solve_spd(jt @ j + 1e-9 * np.eye(6), (jt @ r[..., None])[..., 0])
        poses = HandSolver.step(poses, delta)
        poses[:, 6:] = joints
    return poses
