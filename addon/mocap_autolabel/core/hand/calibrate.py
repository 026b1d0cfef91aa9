"""Per-performer marker calibration: hand size and where each marker really sits.

A layout says where markers go on an average hand; on a real performer the hand is longer or
broader and every marker sits a few millimetres off. Calibration solves, jointly over a few
dozen varied frames of a labeled take (METHODS.md B):

    E = sum_frames sum_markers ||LBS(theta_f, m_j) - p_fj||^2
        + w * frames * sum_j (2 (n_j . d_j)^2 + |d_j - (n_j . d_j) n_j|^2)

over the frames' poses theta_f, the hand length and breadth, and each marker's offset d_j from
its layout position (rest hand frame; moving along the skin normal n_j costs twice as much as
moving along the skin). One Levenberg-Marquardt on the dense normal equations: with ~40 frames
that is ~1,100 unknowns, small enough to solve exactly each step.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from ..atomic import atomic_output
from ..errors import MocapInputError
from ..layout import Layout
from .ik import MIN_MARKERS, HandSolver
from .skeleton import N_DOF, POSE_LIMITS, HandModel
from .skin import Binding

#: Cost of moving a marker along its skin normal, and along the skin (METHODS.md B).
ALPHA_NORMAL, ALPHA_TANGENT = 2.0, 1.0
FORMAT = "mocap_autolabel.calibration/1"


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
                "frames": [int(f) for f in self.frames]}

    def save(self, path: str | os.PathLike) -> None:
        with atomic_output(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
            json.dump(self.to_dict(), f, indent=1)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Calibration:
        """Read a calibration file; any problem is one :class:`MocapInputError` naming the file."""
        where = os.fspath(path)
        try:
            with open(where, encoding="utf-8") as f:
                data = json.load(f)
        except FileNotFoundError:
            raise MocapInputError(where, "calibration file not found") from None
        except (OSError, ValueError) as exc:
            raise MocapInputError(where, f"not a readable calibration JSON ({exc})") from None
        try:
            if data.get("format") != FORMAT:
                raise ValueError(f"format is {data.get('format')!r}, expected {FORMAT!r}")
            names = list(data["markers"])
            offsets = np.array([data["markers"][n] for n in names], dtype=float).reshape(len(names), 3) / 1000
            out = cls(str(data["layout"]), names, str(data["side"]), float(data["hand_length_mm"]) / 1000,
                      float(data["hand_breadth_mm"]) / 1000, offsets, float(data.get("rms_before_mm", "nan")) / 1000,
                      float(data.get("rms_after_mm", "nan")) / 1000, list(data.get("frames", [])))
            out.hand()  # validates the size and side
        except (KeyError, TypeError, ValueError) as exc:
            raise MocapInputError(where, f"not a valid calibration ({exc})") from None
        return out


def detect_side(observed: np.ndarray, layout: Layout, hand: HandModel | None = None, sample: int = 24) -> str:
    """``"left"`` or ``"right"``: the side whose hand fits ``observed (F, M, 3)`` better."""
    hand = hand or HandModel()
    frames = _well_seen(observed)
    frames = frames[np.linspace(0, len(frames) - 1, min(sample, len(frames))).astype(int)]
    rms = {}
    for side in ("left", "right"):
        h = HandModel(hand.length, hand.breadth, side)
        solver = HandSolver(h, layout.place(h)[0])
        rms[side] = np.nanmedian(solver.evaluate(solver.cold_start(observed[frames]), observed[frames]).rms)
    return min(rms, key=rms.get)


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
              reference_pose: np.ndarray | None = None) -> Calibration:
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
    """
    observed = np.asarray(observed, dtype=float)
    if observed.ndim != 3 or observed.shape[1] != len(layout) or observed.shape[2] != 3:
        raise ValueError(f"observed must be (frames, {len(layout)}, 3), got {observed.shape}")
    hand = hand or HandModel()
    side = side or detect_side(observed, layout, hand)
    hand = HandModel(hand.length, hand.breadth, side)
    placed, normals = layout.place(hand)
    candidates = _well_seen(observed)
    if len(candidates) > 60 * frames:  # plenty to choose varied poses from, at a bounded cost
        candidates = candidates[np.linspace(0, len(candidates) - 1, 60 * frames).astype(int)]
    first = HandSolver(hand, placed).solve(observed[candidates])
    ok = first.solved
    chosen = _diverse(first.poses[ok, 6:], frames)
    picked, poses = candidates[ok][chosen], first.poses[ok][chosen]
    pinned = np.zeros(len(picked), dtype=bool)
    if reference is not None and len(reference):
        ref = np.asarray(reference, dtype=int)
        ref = ref[np.linspace(0, len(ref) - 1, min(5, len(ref))).astype(int)]
        joints = np.radians([0, 20, 0, 0] + [0] * 16) if reference_pose is None else np.asarray(reference_pose)
        ref_solver = HandSolver(hand, placed)
        ref_poses = ref_solver.cold_start(observed[ref])
        ref_poses[:, 6:] = joints
        ref_poses = _refine_global(ref_solver, ref_poses, observed[ref])
        picked = np.concatenate([ref, picked])
        poses = np.concatenate([ref_poses, poses])
        pinned = np.concatenate([np.ones(len(ref), dtype=bool), pinned])
    obs = observed[picked]
    seen = np.isfinite(obs).all(axis=-1)
    w = seen[..., None].astype(float)
    obs0 = np.where(seen[..., None], obs, 0.0)
    k, m = len(obs), len(layout)
    weight = prior * k
    # Prior as a residual: sqrt(weight) * (sqrt(a_n) n n^T + sqrt(a_t) (I - n n^T)) d.
    nn = normals[:, :, None] * normals[:, None, :]
    prior_mat = np.sqrt(weight) * (np.sqrt(ALPHA_NORMAL) * nn + np.sqrt(ALPHA_TANGENT) * (np.eye(3) - nn))

    def model(size: np.ndarray, offsets: np.ndarray) -> HandSolver:
        h = HandModel(float(hand.length * np.exp(size[0])), float(hand.breadth * np.exp(size[1])), side)
        return HandSolver(h, layout.place(h)[0].moved(offsets))

    def residuals(p: np.ndarray, size: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, float]:
        data = (model(size, offsets).markers(p) - obs0) * w
        pri = (prior_mat @ offsets[:, :, None])[..., 0]
        return data, float((data ** 2).sum() + (pri ** 2).sum())

    size, offsets = np.zeros(2), np.zeros((m, 3))
    n_size = 2 if solve_size else 0
    n_pose = k * N_DOF
    n_par = n_pose + 3 * m + n_size
    _, cost = residuals(poses, size, offsets)
    rms_before = float(np.sqrt(((model(size, offsets).markers(poses) - obs0) ** 2 * w).sum() / seen.sum()))
    lo, hi = POSE_LIMITS
    for round_ in range(rounds):
        if round_:
            # The poses were first fitted with the uncalibrated markers; some may sit in a wrong
            # basin that the offsets then bend towards. Refit each frame from scratch too.
            solver = model(size, offsets)
            fresh = solver.cold_start(obs)
            better = (solver.evaluate(fresh, obs).rms < solver.evaluate(poses, obs).rms) & ~pinned
            poses = np.where(better[:, None], fresh, poses)
            _, cost = residuals(poses, size, offsets)
        lam = 1e-3
        for _ in range(iterations // rounds):
            solver = model(size, offsets)
            pred, jac_pose = solver.jacobian(poses)  # (K, M, 3), (K, M, 3, 26)
            r = (pred - obs0) * w
            rows = k * m * 3
            jac = np.zeros((rows + 3 * m, n_par))
            jp = (jac_pose * w[..., None]).reshape(k, m * 3, N_DOF)
            for f in range(k):
                jac[f * m * 3:(f + 1) * m * 3, f * N_DOF:(f + 1) * N_DOF] = jp[f]
            # Offsets move a marker with its bones' blended rotation.
            rots, locs = solver.hand.forward(poses)
            skin = rots @ np.swapaxes(solver.hand.rest[0], -1, -2)
            b, bw = solver.binding.bones, solver.binding.weights
            blended = skin[:, b[:, 0]] * bw[None, :, 0, None, None] + skin[:, b[:, 1]] * bw[None, :, 1, None, None]
            blended = blended * w[..., None]  # (K, M, 3, 3)
            for j in range(m):
                jac[:rows, n_pose + 3 * j:n_pose + 3 * j + 3] = _scatter_rows(blended[:, j], k, m, j)
            jac[rows:, n_pose:n_pose + 3 * m] = _block_diag(prior_mat)
            for i in range(n_size):  # hand length and breadth by finite differences
                h = np.zeros(2)
                h[i] = 1e-4
                moved = (model(size + h, offsets).markers(poses) - obs0) * w
                jac[:rows, n_pose + 3 * m + i] = ((moved - r) / 1e-4).ravel()
            res = np.concatenate([r.ravel(), (prior_mat @ offsets[:, :, None]).ravel()])
            a = jac.T @ jac
            g = jac.T @ res
            a[np.diag_indices_from(a)] += lam * np.diag(a) + 1e-12
            # Known poses keep their joint angles: those unknowns leave the system.
            fixed = np.zeros((k, N_DOF), dtype=bool)
            fixed[pinned, 6:] = True
            fixed = np.flatnonzero(fixed.ravel())
            a[fixed, :], a[:, fixed], g[fixed] = 0.0, 0.0, 0.0
            a[fixed, fixed] = 1.0
            delta = -np.linalg.solve(a, g)
            cand_poses = HandSolver.step(poses, delta[:n_pose].reshape(k, N_DOF))
            cand_poses[:, 6:] = np.clip(cand_poses[:, 6:], lo[6:], hi[6:])
            cand_offsets = offsets + delta[n_pose:n_pose + 3 * m].reshape(m, 3)
            cand_size = size + np.concatenate([delta[n_pose + 3 * m:], np.zeros(2 - n_size)])
            _, cand_cost = residuals(cand_poses, cand_size, cand_offsets)
            if cand_cost < cost:
                poses, offsets, size, cost = cand_poses, cand_offsets, cand_size, cand_cost
                lam = max(lam / 3, 1e-9)
            else:
                lam = min(lam * 4, 1e9)
    final = model(size, offsets)
    rms_after = float(np.sqrt(((final.markers(poses) - obs0) ** 2 * w).sum() / seen.sum()))
    return Calibration(layout.name, list(layout.names), side, final.hand.length, final.hand.breadth, offsets,
                       rms_before, rms_after, [int(f) for f in picked])


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
        delta[:, :6] = -np.linalg.solve(jt @ j + 1e-9 * np.eye(6), (jt @ r[..., None]))[..., 0]
        poses = HandSolver.step(poses, delta)
        poses[:, 6:] = joints
    return poses


def _scatter_rows(block: np.ndarray, k: int, m: int, j: int) -> np.ndarray:
    """``(K, 3, 3)`` per-frame blocks of marker ``j`` placed in the ``(K * M * 3, 3)`` data rows."""
    out = np.zeros((k, m, 3, 3))
    out[:, j] = block
    return out.reshape(k * m * 3, 3)


def _block_diag(blocks: np.ndarray) -> np.ndarray:
    """``(M, 3, 3)`` to a ``(3M, 3M)`` block-diagonal matrix."""
    m = len(blocks)
    out = np.zeros((3 * m, 3 * m))
    for j in range(m):
        out[3 * j:3 * j + 3, 3 * j:3 * j + 3] = blocks[j]
    return out
