"""Inverse kinematics: the 26-DOF hand fitted to labeled markers, frame by frame.

Each frame minimises the summed squared distance between the observed markers and the skinned
markers of the posed hand (Levenberg-Marquardt on the analytic Jacobian of
:meth:`HandModel.forward_axes`), warm-started from the previous frame, with the joint angles
projected into their limits after every step. Missing markers (NaN) simply drop out.

Speed comes from solving many frames at once: the take is cut into chunks that are solved in
lock step, so that step ``s`` fits frame ``s`` of every chunk in one vectorised batch, each
warm-started from its own predecessor. Only the first frame of a chunk (or one after a gap)
starts cold, from a few canonical poses aligned to the markers by Kabsch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..rotations import (
    continuous_quaternions,
    kabsch,
    matrix_to_quaternion,
    matrix_to_rotvec,
    quaternion_to_rotvec,
    rotvec_to_matrix,
)
from ..synth.poses import CANONICAL_POSES
from .skeleton import DOF_INDEX, FINGERS, N_DOF, PARENTS, POSE_LIMITS, HandModel
from .skin import Binding

#: Default validation gate: a frame fitted worse than this RMS is implausible (METHODS.md B), metres.
GATE = 0.008
#: Fewest visible markers a frame needs to be solved at all.
MIN_MARKERS = 4

#: The poses a cold start tries (joint angles, radians).
_COLD_POSES = np.stack([CANONICAL_POSES[name] for name in ("relaxed", "flat", "fist")])


def _descendants() -> np.ndarray:
    """``(20, 20)`` bool: ``out[a, b]`` when bone b is a or hangs below it."""
    n = len(PARENTS)
    out = np.eye(n, dtype=bool)
    for b in range(n):
        p = PARENTS[b]
        while p >= 0:
            out[p, b] = True
            p = PARENTS[p]
    return out


_DESCENDANTS = _descendants()


def _cross_m2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the second-to-last axis (vectors laid out ``(..., 3, D)``)."""
    return np.stack([a[..., 1, :] * b[..., 2, :] - a[..., 2, :] * b[..., 1, :],
                     a[..., 2, :] * b[..., 0, :] - a[..., 0, :] * b[..., 2, :],
                     a[..., 0, :] * b[..., 1, :] - a[..., 1, :] * b[..., 0, :]], axis=-2)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcasting (faster than np.cross for small stacks)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


@dataclass
class Fit:
    """The hand solved over a take.

    Attributes:
        poses: ``(F, 26)`` pose vectors (NaN rows where the frame could not be solved).
        markers: ``(F, M, 3)`` the fitted hand's markers, metres.
        residuals: ``(F, M)`` distance from each observed marker to the fit, metres (NaN where
            the marker is missing or the frame unsolved).
        solved: ``(F,)`` bool, frames with at least :data:`MIN_MARKERS` markers.
    """

    poses: np.ndarray
    markers: np.ndarray
    residuals: np.ndarray
    solved: np.ndarray

    @property
    def rms(self) -> np.ndarray:
        """``(F,)`` root mean square marker residual per frame, metres (NaN where unsolved)."""
        sq = np.where(self.solved[:, None] & np.isfinite(self.residuals), self.residuals ** 2, 0.0)
        count = (self.solved[:, None] & np.isfinite(self.residuals)).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, np.sqrt(sq.sum(axis=1) / count), np.nan)

    def overall_rms(self) -> float:
        """RMS over every observed marker of every solved frame, metres."""
        r = self.residuals[self.solved]
        return float(np.sqrt(np.nanmean(r ** 2))) if np.isfinite(r).any() else float("nan")


class HandSolver:
    """Fits one hand, with markers bound to it, to labeled marker positions.

    Args:
        hand: the hand model (size, side).
        binding: the markers on it (``Layout.place`` or a calibration), M points.
        iterations: Levenberg-Marquardt steps per warm-started frame.
        cold_iterations: steps for a frame without a solved predecessor.
        batch: most frames solved side by side (the number of chunks).
        retry: a warm-started frame fitted worse than this RMS (metres), and clearly worse than
            its predecessor or twice this, is also tried from a cold start.
    """

    def __init__(self, hand: HandModel, binding: Binding, iterations: int = 5, cold_iterations: int = 40,
                 batch: int = 256, retry: float = GATE / 2) -> None:
        self.hand = hand
        self.binding = binding
        self.iterations = iterations
        self.cold_iterations = cold_iterations
        self.batch = batch
        self.retry = retry
        cols, bones, self._signs = hand.dof_table
        self._cols = cols
        # Per elementary rotation d, marker j and binding slot k: the skinning weight if the
        # rotation carries that bone, else 0.
        carried = _DESCENDANTS[bones][:, binding.bones]  # (D, M, 2)
        w = carried * binding.weights[None]
        self._w0, self._w1 = w[..., 0].T, w[..., 1].T  # (M, D)
        self._wsum_t = w.sum(axis=2).T
        # Elementary rotation -> joint-angle column; the coupled cupping rotations follow their
        # finger's MCP flexion through a pose-dependent factor.
        self._map = np.zeros((len(cols), N_DOF - 6))
        cups = []
        for d, col in enumerate(cols):
            if col < N_DOF:
                self._map[d, col - 6] = 1.0
            else:
                cups.append((d, DOF_INDEX[f"{FINGERS[col - N_DOF]}_mcp_flex"], col - N_DOF))
        self._cups = tuple(cups)
        r0, p0 = hand.rest
        self._r0t = np.swapaxes(r0, -1, -2)
        self._p0 = p0
        self._rigid = (binding.bones[:, 0] == 0) & (binding.weights[:, 0] > 0.99)

    # -- model ------------------------------------------------------------------------------
    def _bone_points(self, rots: np.ndarray, locs: np.ndarray) -> np.ndarray:
        """``(F, M, 2, 3)``: every marker carried rigidly by each of its two bones."""
        s = rots @ self._r0t  # (F, 20, 3, 3) rest -> posed
        t = locs - (s @ self._p0[:, :, None])[..., 0]
        b = self.binding.bones
        return (s[:, b] @ self.binding.rest[None, :, None, :, None])[..., 0] + t[:, b]

    def markers(self, poses: np.ndarray) -> np.ndarray:
        """``(F, M, 3)`` skinned marker positions of ``poses (F, 26)``, metres."""
        rots, locs = self.hand.forward(poses)
        return self._blend(self._bone_points(rots, locs))

    def _blend(self, pts: np.ndarray) -> np.ndarray:
        w = self.binding.weights
        return pts[:, :, 0] * w[None, :, 0, None] + pts[:, :, 1] * w[None, :, 1, None]

    def jacobian(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Markers ``(F, M, 3)`` and their Jacobian ``(F, M, 3, 26)`` by the pose.

        Columns 0-2 are a small rotation of the whole hand about the wrist, applied in the
        world before the current global rotation (see :meth:`step`), not rotation-vector
        derivatives: that keeps the solve free of the rotation vector's singularity.
        """
        rots, locs, axes, pivots = self.hand.forward_axes(poses)
        pts = self._bone_points(rots, locs)
        markers = self._blend(pts)
        # Laid out (F, M, 3, D) so that one matmul maps the D elementary rotations onto columns.
        q = pts[:, :, 0, :, None] * self._w0[None, :, None] + pts[:, :, 1, :, None] * self._w1[None, :, None]
        ax = np.swapaxes(axes, 1, 2)[:, None]  # (F, 1, 3, D)
        around = np.swapaxes(_cross(axes, pivots), 1, 2)[:, None]  # (F, 1, 3, D)
        moved = _cross_m2(ax, q) - self._wsum_t[None, :, None] * around
        moved *= self._signs
        jac = np.empty(markers.shape + (N_DOF,))
        jac[..., 6:] = moved @ self._map
        coupling = self.hand.coupling(poses)
        for d, col, cup in self._cups:
            jac[..., col] += moved[..., d] * coupling[:, cup, None, None]
        rel = markers - poses[:, None, 3:6]
        eye = np.eye(3)
        jac[..., 0:3] = _cross(eye[None, None, :, :], rel[:, :, None, :]).swapaxes(-1, -2)
        jac[..., 3:6] = eye
        return markers, jac

    @staticmethod
    def step(poses: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """Apply an update ``(F, 26)`` whose first three entries are a world rotation increment."""
        out = poses + delta
        out[:, 0:3] = matrix_to_rotvec(rotvec_to_matrix(delta[:, 0:3]) @ rotvec_to_matrix(poses[:, 0:3]))
        return out

    # -- solving ----------------------------------------------------------------------------
    def refine(self, poses: np.ndarray, observed: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray]:
        """Levenberg-Marquardt from ``poses (F, 26)`` towards ``observed (F, M, 3)`` (NaN = missing).

        Returns the refined poses and their cost (sum of squared residuals, m^2) ``(F,)``.
        """
        seen = np.isfinite(observed).all(axis=-1)
        obs = np.where(seen[..., None], observed, 0.0)
        w = seen[..., None].astype(float)
        poses = poses.copy()
        lam = np.full(len(poses), 1e-3)
        markers = self.markers(poses)
        cost = ((markers - obs) ** 2 * w).sum(axis=(1, 2))
        lo, hi = POSE_LIMITS
        for _ in range(iterations):
            markers, jac = self.jacobian(poses)
            r = (markers - obs) * w
            jw = jac * w[..., None]
            jf = jw.reshape(len(poses), -1, N_DOF)
            jt = np.swapaxes(jf, 1, 2)
            a = jt @ jf
            g = (jt @ r.reshape(len(poses), -1, 1))[..., 0]
            diag = np.einsum("fii->fi", a)
            damped = a + (lam[:, None] * diag + 1e-9)[:, :, None] * np.eye(N_DOF)
            delta = -np.linalg.solve(damped, g[..., None])[..., 0]
            cand = self.step(poses, delta)
            cand[:, 6:] = np.clip(cand[:, 6:], lo[6:], hi[6:])
            cand_cost = ((self.markers(cand) - obs) ** 2 * w).sum(axis=(1, 2))
            better = cand_cost < cost
            poses[better] = cand[better]
            cost = np.where(better, cand_cost, cost)
            lam = np.clip(np.where(better, lam / 3, lam * 4), 1e-7, 1e7)
        return poses, cost

    def cold_start(self, observed: np.ndarray) -> np.ndarray:
        """Poses ``(F, 26)`` for frames with no solved predecessor: each canonical pose aligned to
        the visible markers (Kabsch, palm markers weighted most), refined, the best kept."""
        n = len(observed)
        best, best_cost = np.zeros((n, N_DOF)), np.full(n, np.inf)
        seen = np.isfinite(observed).all(axis=-1)
        wts = np.where(self._rigid, 1.0, 0.3)[None] * seen  # (F, M)
        for joints in _COLD_POSES:
            canon = np.zeros(N_DOF)
            canon[6:] = joints
            model = self.markers(canon[None])[0]  # hand frame (global identity)
            poses = np.tile(canon, (n, 1))
            rot, poses[:, 3:6] = kabsch(model, observed, wts)
            poses[:, 0:3] = matrix_to_rotvec(rot)
            poses, cost = self.refine(poses, observed, self.cold_iterations // 4)
            better = cost < best_cost
            best[better], best_cost[better] = poses[better], cost[better]
        return self.refine(best, observed, self.cold_iterations)[0]

    def solve(self, observed: np.ndarray, rate: float | None = None, smooth_hz: float = 10.0,
              initial: np.ndarray | None = None, progress: Callable[[float], None] | None = None) -> Fit:
        """Fit every frame of ``observed (F, M, 3)`` (metres, NaN = missing, M = the binding's markers).

        Args:
            rate: frames per second; with it the pose track is low-passed at ``smooth_hz``
                (:func:`smooth_poses`), without it every frame keeps its own fit.
            smooth_hz: cut-off of that filter; 0 turns it off.
            initial: optional ``(26,)`` pose to warm-start the first frame from.
            progress: called with the share of frames done (0-1) after each step; it may raise to
                stop the solve (a cancelled job does).
        """
        observed = np.asarray(observed, dtype=float)
        n = len(observed)
        solvable = np.isfinite(observed).all(axis=-1).sum(axis=1) >= MIN_MARKERS
        poses = np.full((n, N_DOF), np.nan)
        fit_rms = np.full(n, np.inf)
        length = max(8, -(-n // self.batch))
        heads = np.arange(0, n, length)
        for s in range(length):
            idx = heads + s
            idx = idx[idx < n]
            idx = idx[solvable[idx]]
            if not len(idx):
                continue
            prev = poses[idx - 1] if s > 0 else np.full((len(idx), N_DOF), np.nan)
            prev_rms = fit_rms[idx - 1] if s > 0 else np.full(len(idx), np.inf)
            if s == 0 and initial is not None:
                prev[idx == 0] = initial
            cold = ~np.isfinite(prev[:, 0])
            if (~cold).any():
                obs = observed[idx[~cold]]
                fitted, cost = self.refine(prev[~cold], obs, self.iterations)
                poses[idx[~cold]] = fitted
                # A warm start can carry a wrong local minimum along (a finger folded the wrong
                # way through a fast move): frames fitted badly, or much worse than their
                # predecessor, also try a cold start.
                rms = np.sqrt(cost / np.isfinite(obs[..., 0]).sum(axis=1))
                lost = (rms > self.retry) & (rms > 1.5 * prev_rms[~cold] + 0.001) | (rms > 2 * self.retry)
                cold[np.flatnonzero(~cold)[lost]] = True
            if cold.any():
                obs = observed[idx[cold]]
                fitted = self.cold_start(obs)
                if s > 0:  # keep the warm result where the cold one is no better
                    keep = np.isfinite(poses[idx[cold], 0])
                    old = self.evaluate(np.where(keep[:, None], poses[idx[cold]], fitted), obs).rms
                    new = self.evaluate(fitted, obs).rms
                    fitted = np.where((keep & (old <= new))[:, None], poses[idx[cold]], fitted)
                poses[idx[cold]] = fitted
            fit_rms[idx] = self.evaluate(poses[idx], observed[idx]).rms
            if progress is not None:
                progress((s + 1) / length)
        if rate:
            poses = smooth_poses(poses, rate, smooth_hz)
        return self.evaluate(poses, observed)

    def evaluate(self, poses: np.ndarray, observed: np.ndarray) -> Fit:
        """The :class:`Fit` of given ``poses (F, 26)`` (NaN rows = unsolved) to ``observed``."""
        solved = np.isfinite(poses[:, 0])
        markers = np.full(observed.shape, np.nan)
        if solved.any():
            markers[solved] = self.markers(poses[solved])
        residuals = np.linalg.norm(markers - observed, axis=-1)
        return Fit(poses, markers, residuals, solved)


def smooth_poses(poses: np.ndarray, rate: float, cutoff_hz: float = 10.0) -> np.ndarray:
    """Zero-phase low-pass (2nd-order Butterworth, forward and backward) of a pose track.

    Per-frame fits carry the markers' noise into the joint angles, worst for the short distal
    phalanges; the true motion is smooth at capture rates, so filtering runs of solved frames
    (NaN rows split them) removes most of it without lag. The global rotation is filtered as
    sign-continuous quaternions and renormalised.

    Args:
        poses: ``(F, 26)`` pose vectors, NaN rows for unsolved frames.
        rate: frames per second.
        cutoff_hz: the filter's cut-off; 0 or at least half the rate returns the poses unchanged.
    """
    out = np.array(poses, dtype=float)
    if cutoff_hz <= 0 or cutoff_hz >= rate / 2:
        return out
    from scipy.signal import butter, sosfiltfilt  # here: scipy.signal costs a labeling run 0.4 s to import

    sos = butter(2, cutoff_hz / (rate / 2), output="sos")
    solved = np.isfinite(out[:, 0])
    edges = np.flatnonzero(np.diff(np.concatenate([[0], solved.astype(np.int8), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        if stop - start < 16:
            continue
        run = out[start:stop]
        quat = continuous_quaternions(matrix_to_quaternion(rotvec_to_matrix(run[:, 0:3])), axis=0)
        lin = np.concatenate([quat, run[:, 3:]], axis=1)
        lin = sosfiltfilt(sos, lin, axis=0, padlen=min(stop - start - 1, 30))
        quat = lin[:, :4] / np.linalg.norm(lin[:, :4], axis=1, keepdims=True)
        run[:, 0:3] = quaternion_to_rotvec(quat)
        run[:, 3:] = lin[:, 4:]
        run[:, 6:] = np.clip(run[:, 6:], POSE_LIMITS[0, 6:], POSE_LIMITS[1, 6:])
    return out


