"""Inverse kinematics: the 26-DOF hand fitted to labeled markers, frame by frame.

Each frame minimises the summed squared distance between the observed markers and the skinned
markers of the posed hand (Levenberg-Marquardt on the analytic Jacobian of
:meth:`HandModel.forward_axes`), warm-started from the previous frame, with the joint angles
projected into their limits after every step. Missing markers (NaN) simply drop out.

Speed comes from solving many frames at once: the take is cut into chunks that are solved in
lock step, so that step ``s`` fits frame ``s`` of every chunk in one vectorised batch, each
warm-started from its own predecessor. Only the first frame of a chunk (or one after a gap)
starts cold, from a few canonical poses aligned to the markers by Kabsch.

Each step is laid out for numpy (issue 48): the kinematics run frames last
(:meth:`HandModel.chain_soa`), the normal equations are summed from the Jacobian's sparse
structure (a marker moves with the global transform and its own digit's few joints only, never
a dense ``J^T J``), and the 26 x 26 systems are solved by one batched Cholesky
(:func:`solve_spd`), not LAPACK's per-matrix ``gesv``, which a threaded BLAS made slow, load
dependent, and its results dependent on the thread count. A frame's fit does not depend on the
batch it is solved in (beyond rounding), nor on the thread count. Cold starts of many frames at
once (the template hand's checks of a sparse labeling try dozens of hypotheses) are cut into
chunks of :data:`CHUNK_FRAMES` frames solved side by side in threads (numpy releases the GIL in
its loops): the cut is fixed, so that the rounding is the same on any machine.
"""

from __future__ import annotations

import copy
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
from ..threads import side_by_side
from .skeleton import DOF_INDEX, FINGERS, N_DOF, PARENTS, POSE_LIMITS, HandModel
from .skin import Binding

#: Default validation gate: a frame fitted worse than this RMS is implausible (METHODS.md B), metres.
GATE = 0.008
#: Fewest visible markers a frame needs to be solved at all.
MIN_MARKERS = 4

#: Frames one thread cold-starts at once: a fixed cut, never one made from the thread count.
CHUNK_FRAMES = 256


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


def _cross_soa(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the FIRST axis (vectors laid out ``(3, ...)``, frames last)."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct values of sorted ``keys`` and where each one's run starts."""
    if not len(keys):
        return keys, np.zeros(0, dtype=np.int64)
    starts = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1]]))
    return keys[starts], starts


def solve_spd(a: np.ndarray, b: np.ndarray, shift: np.ndarray | None = None) -> np.ndarray:
    """Solve a stack of symmetric positive definite systems ``a (F, N, N) x = b``, ``b (F, N)`` or
    ``(F, N, R)`` (R right-hand sides); ``shift (F, N)``, if given, is added to the diagonal of
    ``a`` first (Levenberg-Marquardt damping; ``a`` itself is left as it is).

    A batched Cholesky, then the substitutions vectorised over the stack. With one right-hand side
    the system is bordered by it (``[[a, b], [b^T, huge]]``: the factor's last row is ``(L^-1
    b)^T``), which leaves only the back substitution. numpy's ``linalg.solve`` calls LAPACK's
    ``gesv`` once per small matrix, and with a threaded BLAS each call synchronises threads: 5-10
    times slower, slower still on a loaded machine; this path runs on the calling thread, the same
    whatever the thread count. A stack whose Cholesky fails (not positive definite) falls back to
    ``linalg.solve``.
    """
    one = b.ndim == 2
    rhs = b[..., None] if one else b
    f, n, r = rhs.shape
    d = np.arange(n)
    bordered = r == 1
    size = n + 1 if bordered else n
    aug = np.zeros((f, size, size))
    aug[:, :n, :n] = a
    if shift is not None:
        aug[:, d, d] += shift
    if bordered:
        aug[:, n, :n] = rhs[..., 0]
        return _bordered_solve(aug)
    try:
        low = np.linalg.cholesky(aug)
    except np.linalg.LinAlgError:
        x = np.linalg.solve(aug, rhs)
        return x[..., 0] if one else x
    lt = np.ascontiguousarray(np.moveaxis(low, 0, -1))  # (N, N, F): rows of frames
    x = np.ascontiguousarray(rhs.transpose(1, 2, 0))  # (N, R, F)
    for i in range(n):  # L y = b
        x[i] /= lt[i, i]
        x[i + 1:] -= lt[i + 1:, i, None] * x[i]
    for i in range(n - 1, -1, -1):  # L^T x = y
        x[i] /= lt[i, i]
        x[:i] -= lt[i, :i, None] * x[i]
    return np.moveaxis(x, -1, 0)  # (F, N, R)


def _bordered_solve(aug: np.ndarray) -> np.ndarray:
    """``x (F, N)`` of the systems in ``aug (F, N + 1, N + 1)``: each matrix in the leading block,
    its right-hand side in the last row (the rest of ``aug`` is overwritten)."""
    n = aug.shape[1] - 1
    aug[:, :n, n] = 0.0
    aug[:, n, n] = 1e300
    try:
        low = np.linalg.cholesky(aug)
    except np.linalg.LinAlgError:
        return np.linalg.solve(aug[:, :n, :n], aug[:, n, :n, None])[..., 0]
    lt = np.ascontiguousarray(np.moveaxis(low, 0, -1))  # (N + 1, N + 1, F): rows of frames
    x = lt[n, :n].copy()  # (N, F): L^-1 b
    for i in range(n - 1, -1, -1):  # L^T x = L^-1 b
        x[i] /= lt[i, i]
        x[:i] -= lt[i, :i] * x[i]
    return x.T


def _solve_soa(a: np.ndarray, g: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """:func:`solve_spd` of systems laid out frames last: ``a (N, N, F)``, ``g (N, F)``, ``shift
    (N, F)`` on the diagonal; ``x (F, N)``."""
    n, f = g.shape
    aug = np.empty((f, n + 1, n + 1))
    aug[:, :n, :n] = a.transpose(2, 0, 1)
    d = np.arange(n)
    aug[:, d, d] += shift.T
    aug[:, n, :n] = g.T
    return _bordered_solve(aug)


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


#: HandSolver's sparse-Jacobian attributes: its index arrays (they depend on the markers' bones), and
#: the weights (they depend on the binding's weights too).
_STRUCTURE = ("_pattern", "_rank", "_valid", "_dof", "_sign", "_cup", "_merge", "_slots", "_slot_cols",
              "_slot_starts", "_pairs", "_pair_starts", "_pair_cols")
_WEIGHTS = ("_weight", "_weight_sum")


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
        # The sparse Jacobian's index arrays and weights are made when a Jacobian is first asked for
        # (a solver that only places markers, as calibration's contact pads, never needs them), and
        # kept in a box that copies share (moved(); rebound() to a size with the same pattern).
        self._box = {}
        self._weight = None
        self._local = self._locals(hand, binding)
        self._blend_w = (binding.weights[:, 0, None], binding.weights[:, 1, None])  # (M, 1) each
        self._rigid = (binding.bones[:, 0] == 0) & (binding.weights[:, 0] > 0.99)

    def _structure(self, hand: HandModel, binding: Binding) -> None:
        """Which rotations move which marker, and the index arrays of the sparse normal equations:
        what depends on the markers' bones alone (not on the hand's size or the markers' places)."""
        cols, bones, signs = hand.dof_table
        m = len(binding.rest)
        self._pattern = (binding.bones.tobytes(), (binding.weights > 0).tobytes())
        # Per marker j, elementary rotation d and binding slot: carried if the rotation moves that bone.
        carried = _DESCENDANTS[bones][:, binding.bones] & (binding.weights > 0)[None]  # (D, M, 2)
        # Each marker moves with a few of the D rotations only (its digit's, at most 5): the
        # Jacobian is built over those, ``(M, K)`` of them per marker (padded with weight 0).
        moves = carried.any(axis=2).T  # (M, D)
        k = max(1, int(moves.sum(axis=1).max()))
        rank = np.argsort(~moves, axis=1, kind="stable")[:, :k]  # each marker's rotations first
        valid = np.take_along_axis(moves, rank, axis=1)  # (M, K)
        self._rank, self._valid = rank, valid
        self._dof = np.where(valid, rank, 0)  # (M, K) rotation index
        self._sign = (signs[self._dof] * valid)[..., None]  # (M, K, 1)
        # Rotation -> joint-angle column (0-19); a coupled cupping rotation moves with its finger's
        # MCP flexion through a pose-dependent factor (its row of coupling(), 4 = none).
        col = cols[self._dof]
        cup = valid & (col >= N_DOF)
        self._cup = np.where(cup, col - N_DOF, len(FINGERS))  # (M, K)
        target = np.array([[DOF_INDEX[f"{FINGERS[c - N_DOF]}_mcp_flex"] if c >= N_DOF else c for c in row]
                           for row in col]) - 6
        # A marker moved both by a cupping rotation and by its finger's flexion gets one column:
        # the cup's motion is added to the flexion's slot, and the cup's slot is dropped.
        keep = valid.copy()
        merge = []  # (marker, cup slot, flexion slot)
        for j in range(m):
            for c in np.flatnonzero(cup[j]):
                same = np.flatnonzero(valid[j] & ~cup[j] & (target[j] == target[j, c]))
                if len(same):
                    merge.append((j, c, same[0]))
                    keep[j, c] = False
        self._merge = tuple(np.array(x, dtype=np.int64) for x in zip(*merge)) if merge else None
        # Kept slots grouped by column (sums over markers by np.add.reduceat), and per marker the
        # pairs of its kept slots grouped by their (unordered) pair of columns: the sparse J^T J.
        sj, sk = np.nonzero(keep)
        st = target[sj, sk]
        order = np.argsort(st, kind="stable")
        self._slots = (sj[order], sk[order])
        self._slot_cols, self._slot_starts = _groups(st[order])
        pairs = [(j, k1, k2, min(target[j, k1], target[j, k2]), max(target[j, k1], target[j, k2]))
                 for j in range(m) for k1 in np.flatnonzero(keep[j]) for k2 in np.flatnonzero(keep[j]) if k1 <= k2]
        pj, pk1, pk2, c1, c2 = (np.array(x, dtype=np.int64).reshape(-1) for x in zip(*pairs)) if pairs else \
            (np.zeros(0, dtype=np.int64),) * 5
        order = np.lexsort((c2, c1))
        self._pairs = (pj[order], pk1[order], pk2[order])
        keys, self._pair_starts = _groups(c1[order] * (N_DOF - 6) + c2[order])
        self._pair_cols = (keys // (N_DOF - 6), keys % (N_DOF - 6))

    def _weights(self, hand: HandModel, binding: Binding) -> None:
        """The skinning weights of each marker's K rotations."""
        _, bones, _ = hand.dof_table
        carried = _DESCENDANTS[bones][:, binding.bones]  # (D, M, 2)
        w = (carried * binding.weights[None]).transpose(1, 0, 2)  # (M, D, 2)
        weight = np.take_along_axis(w, self._rank[..., None], axis=1) * self._valid[..., None]  # (M, K, 2)
        self._weight = (weight[..., 0, None], weight[..., 1, None])  # (M, K, 1) each
        self._weight_sum = weight.sum(axis=2)[..., None]

    def _sparse(self) -> None:
        """Make the sparse Jacobian's index arrays and weights, or take them from the box."""
        if self._weight is not None:
            return
        box = self._box
        if "_pattern" in box:
            self.__dict__.update({k: box[k] for k in _STRUCTURE})
        else:
            self._structure(self.hand, self.binding)
            box.update({k: getattr(self, k) for k in _STRUCTURE})
        if "_weight" in box:
            self.__dict__.update({k: box[k] for k in _WEIGHTS})
        else:
            self._weights(self.hand, self.binding)
            box.update({k: getattr(self, k) for k in _WEIGHTS})

    def rebound(self, hand: HandModel, binding: Binding) -> HandSolver:
        """A solver of the same settings for another hand (size) and markers: the index arrays are
        shared when the markers sit on the same bones (calibration tries many sizes)."""
        out = copy.copy(self)
        out.hand, out.binding = hand, binding
        same = hand.side == self.hand.side and self._box.get("_pattern") == (
            binding.bones.tobytes(), (binding.weights > 0).tobytes())
        out._box = {k: self._box[k] for k in _STRUCTURE} if same else {}
        out._weight = None
        out._local = self._locals(hand, binding)
        out._blend_w = (binding.weights[:, 0, None], binding.weights[:, 1, None])
        out._rigid = (binding.bones[:, 0] == 0) & (binding.weights[:, 0] > 0.99)
        return out

    def moved(self, offsets: np.ndarray) -> HandSolver:
        """This solver with its markers displaced by ``offsets (M, 3)`` at rest (hand frame,
        metres): the same hand and skinning, so everything but the markers' rest places is shared."""
        out = copy.copy(self)
        out.binding = self.binding.moved(offsets)
        out._local = self._locals(self.hand, out.binding)
        return out

    @staticmethod
    def _locals(hand: HandModel, binding: Binding) -> np.ndarray:
        """Each marker in each of its two bones' frames ``(3, M, 2, 1)``: posed, it is
        ``rots[b] @ local + locs[b]``."""
        r0, p0 = hand.rest
        bb = binding.bones
        local = (np.swapaxes(r0[bb], -1, -2) @ (binding.rest[:, None, :] - p0[bb])[..., None])[..., 0]  # (M, 2, 3)
        return np.ascontiguousarray(local.transpose(2, 0, 1)[..., None])

    # -- model ------------------------------------------------------------------------------
    # Internally arrays are laid out frames last, ``(3, M, F)``: see HandModel.chain_soa.
    def _points(self, rots: np.ndarray, locs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every marker carried rigidly by each of its two bones ``(3, M, 2, F)``, and the skinned
        markers ``(3, M, F)``."""
        b = self.binding.bones
        rb = rots[:, :, b]  # (3, 3, M, 2, F)
        loc = self._local
        pts = rb[:, 0] * loc[0] + rb[:, 1] * loc[1] + rb[:, 2] * loc[2] + locs[:, b]
        w0, w1 = self._blend_w
        return pts, pts[:, :, 0] * w0 + pts[:, :, 1] * w1

    def _markers_soa(self, poses: np.ndarray) -> np.ndarray:
        rots, locs, _, _ = self.hand.chain_soa(poses)
        return self._points(rots, locs)[1]

    def markers(self, poses: np.ndarray) -> np.ndarray:
        """``(F, M, 3)`` skinned marker positions of ``poses (F, 26)``, metres."""
        return np.ascontiguousarray(self._markers_soa(poses).transpose(2, 1, 0))

    def _moved(self, poses: np.ndarray, seen: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Markers ``(3, M, F)`` and how each marker moves per unit turn of each of its K rotations
        ``(3, M, K, F)`` (cupping merged into its flexion's slot; zero where not ``seen (M, F)``)."""
        self._sparse()
        rots, locs, axes, pivots = self.hand.chain_soa(poses, axes=True)
        pts, markers = self._points(rots, locs)
        # Turning rotation d moves marker j by axis_d x (q_jd - wsum_jd pivot_d), q_jd the blend of
        # its bone points that d carries: over each marker's own K rotations only.
        w0, w1 = self._weight
        q = pts[:, :, None, 0] * w0 + pts[:, :, None, 1] * w1  # (3, M, K, F)
        lever = q - self._weight_sum * pivots[:, self._dof]
        factor = np.concatenate([self.hand.coupling(poses).T, np.ones((1, len(poses)))])[self._cup] * self._sign
        if seen is not None:
            factor = factor * seen[:, None]
        moved = _cross_soa(axes[:, self._dof], lever) * factor
        if self._merge is not None:
            j, cup, flex = self._merge
            moved[:, j, flex] += moved[:, j, cup]
        return markers, moved

    def jacobian(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Markers ``(F, M, 3)`` and their Jacobian ``(F, M, 3, 26)`` by the pose.

        Columns 0-2 are a small rotation of the whole hand about the wrist, applied in the
        world before the current global rotation (see :meth:`step`), not rotation-vector
        derivatives: that keeps the solve free of the rotation vector's singularity.
        """
        poses = np.atleast_2d(np.asarray(poses, dtype=float))
        markers, moved = self._moved(poses, None)
        n, m = len(poses), markers.shape[1]
        jac = np.zeros((3, m, N_DOF, n))
        sj, sk = self._slots
        jac[:, sj, 6 + np.repeat(self._slot_cols, np.diff(np.append(self._slot_starts, len(sj))))] = moved[:, sj, sk]
        # A world rotation w moves a marker by w x rel: columns e_i x rel.
        rx, ry, rz = markers - poses.T[3:6, None]
        jac[1, :, 0], jac[2, :, 0] = -rz, ry
        jac[0, :, 1], jac[2, :, 1] = rz, -rx
        jac[0, :, 2], jac[1, :, 2] = -ry, rx
        for i in range(3):
            jac[i, :, 3 + i] = 1.0
        return (np.ascontiguousarray(markers.transpose(2, 1, 0)), np.ascontiguousarray(jac.transpose(3, 1, 0, 2)))

    def _normal(self, poses: np.ndarray, obs: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, ...]:
        """Cost ``(F,)``, ``J^T J (26, 26, F)`` and ``J^T r (26, F)`` of ``poses`` against ``obs
        (3, M, F)`` (0 where not ``seen (M, F)``), summed from the Jacobian's sparse structure: a
        marker's row has the 6 global columns and those of its own K rotations only."""
        markers, moved = self._moved(poses, seen)
        n = len(poses)
        r = (markers - obs) * seen  # (3, M, F)
        rel = (markers - poses.T[3:6, None]) * seen
        a = np.zeros((N_DOF, N_DOF, n))
        g = np.empty((N_DOF, n))
        # Global block: rotation columns e_i x rel, translation columns the identity.
        rr = (rel[:, None] * rel[None]).sum(axis=2)  # (3, 3, F)
        a[0:3, 0:3] = (rr[0, 0] + rr[1, 1] + rr[2, 2]) * np.eye(3)[..., None] - rr
        sx, sy, sz = rel.sum(axis=1)
        zero = np.zeros(n)
        skew = np.array([[zero, -sz, sy], [sz, zero, -sx], [-sy, sx, zero]])
        a[0:3, 3:6] = skew
        a[3:6, 0:3] = skew.transpose(1, 0, 2)
        a[3:6, 3:6] = seen.sum(axis=0) * np.eye(3)[..., None]
        g[0:3] = _cross_soa(rel, r).sum(axis=1)
        g[3:6] = r.sum(axis=1)
        # Joint columns against the global ones, and the gradient, summed per column.
        sj, sk = self._slots
        mv = moved[:, sj, sk]  # (3, E, F)
        per = np.concatenate([_cross_soa(rel[:, sj], mv), mv, (mv * r[:, sj]).sum(axis=0)[None]])  # (7, E, F)
        per = np.add.reduceat(per, self._slot_starts, axis=1)  # (7, C, F)
        cols = 6 + self._slot_cols
        a[cols, 0:6] = per[:6].transpose(1, 0, 2)
        a[0:6, cols] = per[:6]
        g[6:] = 0.0
        g[cols] = per[6]
        # Joint block: per marker, its slots' motions dotted pairwise, summed per pair of columns.
        pj, pk1, pk2 = self._pairs
        dots = np.add.reduceat((moved[:, pj, pk1] * moved[:, pj, pk2]).sum(axis=0), self._pair_starts, axis=0)
        c1, c2 = self._pair_cols
        a[6 + c1, 6 + c2] = dots
        a[6 + c2, 6 + c1] = dots
        return (r ** 2).sum(axis=(0, 1)), a, g

    @staticmethod
    def step(poses: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """Apply an update ``(F, 26)`` whose first three entries are a world rotation increment."""
        out = poses + delta
        out[:, 0:3] = matrix_to_rotvec(rotvec_to_matrix(delta[:, 0:3]) @ rotvec_to_matrix(poses[:, 0:3]))
        return out

    # -- solving ----------------------------------------------------------------------------
    def refine(self, poses: np.ndarray, observed: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray]:
        """Levenberg-Marquardt from ``poses (F, 26)`` towards ``observed (F, M, 3)`` (NaN = missing).

        Returns the refined poses and their cost (sum of squared residuals, m^2) ``(F,)``. Every
        frame is its own problem (its own damping); a candidate's cost and normal equations come
        from one forward kinematics, kept for the next step where the candidate is taken.
        """
        seen = np.isfinite(observed).all(axis=-1)
        obs = np.where(seen[..., None], observed, 0.0).transpose(2, 1, 0).copy()  # (3, M, F)
        seen = seen.T.copy()  # (M, F)
        poses = np.array(poses, dtype=float)
        n = len(poses)
        lam = np.full(n, 1e-3)
        if iterations <= 0:
            return poses, self._cost(poses, obs, seen)
        cost, a, g = self._normal(poses, obs, seen)
        lo, hi = POSE_LIMITS
        diagonal = np.arange(N_DOF)
        for it in range(iterations):
            delta = -_solve_soa(a, g, lam * a[diagonal, diagonal] + 1e-9)
            cand = self.step(poses, delta)
            cand[:, 6:] = np.clip(cand[:, 6:], lo[6:], hi[6:])
            if it == iterations - 1:
                cand_cost = self._cost(cand, obs, seen)
                better = cand_cost < cost
            else:
                cand_cost, cand_a, cand_g = self._normal(cand, obs, seen)
                better = cand_cost < cost
                a[..., better] = cand_a[..., better]
                g[:, better] = cand_g[:, better]
            poses[better] = cand[better]
            cost = np.where(better, cand_cost, cost)
            lam = np.clip(np.where(better, lam / 3, lam * 4), 1e-7, 1e7)
        return poses, cost

    def _cost(self, poses: np.ndarray, obs: np.ndarray, seen: np.ndarray) -> np.ndarray:
        """Sum of squared residuals ``(F,)`` against ``obs (3, M, F)``, 0 where not ``seen (M, F)``."""
        return (((self._markers_soa(poses) - obs) * seen) ** 2).sum(axis=(0, 1))

    def cold_start(self, observed: np.ndarray) -> np.ndarray:
        """Poses ``(F, 26)`` for frames with no solved predecessor: each canonical pose aligned to
        the visible markers (Kabsch, palm markers weighted most), refined, the best kept (the first
        of equals). The canonical starts are refined side by side, in one batch."""
        return self._cold_start(observed)[0]

    def _cold_start(self, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`cold_start`'s poses and their cost (sum of squared residuals) ``(F,)``: chunks of
        :data:`CHUNK_FRAMES` frames, side by side in threads."""
        chunks = [observed[a:a + CHUNK_FRAMES] for a in range(0, len(observed), CHUNK_FRAMES)] or [observed]
        self._sparse()  # the index arrays once, before any threads share them
        solved = side_by_side(self._cold_start_chunk, chunks)
        if len(solved) == 1:
            return solved[0]
        return np.concatenate([p for p, _ in solved]), np.concatenate([c for _, c in solved])

    def _cold_start_chunk(self, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_cold_start` of at most :data:`CHUNK_FRAMES` frames."""
        n = len(observed)
        seen = np.isfinite(observed).all(axis=-1)
        wts = np.where(self._rigid, 1.0, 0.3)[None] * seen  # (F, M)
        starts = []
        for joints in _COLD_POSES:
            canon = np.zeros(N_DOF)
            canon[6:] = joints
            model = self.markers(canon[None])[0]  # hand frame (global identity)
            poses = np.tile(canon, (n, 1))
            rot, poses[:, 3:6] = kabsch(model, observed, wts)
            poses[:, 0:3] = matrix_to_rotvec(rot)
            starts.append(poses)
        k = len(starts)
        poses, cost = self.refine(np.concatenate(starts), np.concatenate([observed] * k), self.cold_iterations // 4)
        cost = np.where(np.isnan(cost), np.inf, cost).reshape(k, n)
        pick = np.argmin(cost, axis=0)  # the first of equal costs, as a running "strictly better" keeps
        best = poses.reshape(k, n, N_DOF)[pick, np.arange(n)]
        best[~np.isfinite(cost[pick, np.arange(n)])] = 0.0  # no start fitted at all: from zeros, as before
        return self.refine(best, observed, self.cold_iterations)

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
            step_rms = np.full(len(idx), np.inf)
            if (~cold).any():
                obs = observed[idx[~cold]]
                fitted, cost = self.refine(prev[~cold], obs, self.iterations)
                poses[idx[~cold]] = fitted
                # A warm start can carry a wrong local minimum along (a finger folded the wrong
                # way through a fast move): frames fitted badly, or much worse than their
                # predecessor, also try a cold start.
                rms = np.sqrt(cost / np.isfinite(obs[..., 0]).sum(axis=1))
                lost = (rms > self.retry) & (rms > 1.5 * prev_rms[~cold] + 0.001) | (rms > 2 * self.retry)
                step_rms[~cold] = rms
                cold[np.flatnonzero(~cold)[lost]] = True
            if cold.any():
                obs = observed[idx[cold]]
                fitted, cost = self._cold_start(obs)
                new = np.sqrt(cost / np.isfinite(obs[..., 0]).sum(axis=1))
                keep = step_rms[cold] <= new  # keep the warm result where the cold one is no better
                poses[idx[cold]] = np.where(keep[:, None], poses[idx[cold]], fitted)
                step_rms[cold] = np.where(keep, step_rms[cold], new)
            fit_rms[idx] = step_rms
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
    sign-continuous quaternions and renormalised. The filter is scipy.signal's ``butter(2, ...,
    output="sos")`` run by ``sosfiltfilt(..., padlen=min(run - 1, 30))``, written out here in numpy
    (scipy.signal takes 0.2-0.4 s to import, a tenth of a whole solve).

    Args:
        poses: ``(F, 26)`` pose vectors, NaN rows for unsolved frames.
        rate: frames per second.
        cutoff_hz: the filter's cut-off; 0 or at least half the rate returns the poses unchanged.
    """
    out = np.array(poses, dtype=float)
    if cutoff_hz <= 0 or cutoff_hz >= rate / 2:
        return out
    sos = butter2(cutoff_hz / (rate / 2))
    solved = np.isfinite(out[:, 0])
    edges = np.flatnonzero(np.diff(np.concatenate([[0], solved.astype(np.int8), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        if stop - start < 16:
            continue
        run = out[start:stop]
        quat = continuous_quaternions(matrix_to_quaternion(rotvec_to_matrix(run[:, 0:3])), axis=0)
        lin = np.concatenate([quat, run[:, 3:]], axis=1)
        lin = filtfilt2(sos, lin, padlen=min(stop - start - 1, 30))
        quat = lin[:, :4] / np.linalg.norm(lin[:, :4], axis=1, keepdims=True)
        run[:, 0:3] = quaternion_to_rotvec(quat)
        run[:, 3:] = lin[:, 4:]
        run[:, 6:] = np.clip(run[:, 6:], POSE_LIMITS[0, 6:], POSE_LIMITS[1, 6:])
    return out


def butter2(wn: float) -> np.ndarray:
    """The 2nd-order Butterworth low-pass at ``wn`` (a fraction of the Nyquist rate) as one
    second-order section ``[b0, b1, b2, 1, a1, a2]``: what ``scipy.signal.butter(2, wn,
    output="sos")`` designs (analog prototype, pre-warped cut-off, bilinear transform)."""
    warped = 4.0 * np.tan(np.pi * wn / 2.0)
    poles = warped * -np.exp(1j * np.pi * np.array([-1.0, 1.0]) / 4.0)  # the prototype's, scaled
    z_poles = (4.0 + poles) / (4.0 - poles)
    gain = warped ** 2 / np.real(np.prod(4.0 - poles))
    a = np.real(np.poly(z_poles))
    return np.array([gain, 2.0 * gain, gain, 1.0, a[1], a[2]])


def filtfilt2(sos: np.ndarray, x: np.ndarray, padlen: int) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, x, axis=0, padlen=padlen)`` for one second-order section:
    odd extension by ``padlen`` samples at each end, the filter forwards then backwards, each pass
    started in the steady state of its first sample (``sosfilt_zi``)."""
    b0, b1, b2, _, a1, a2 = sos
    if len(x) <= padlen:
        raise ValueError(f"the signal must be longer than padlen ({padlen}), got {len(x)} samples")
    ext = np.concatenate([2 * x[0] - x[padlen:0:-1], x, 2 * x[-1] - x[-2:-(padlen + 2):-1]]) if padlen else x
    # Steady state of a unit step (lfilter_zi): (I - A^T) zi = b[1:] - a[1:] b0.
    c0, c1 = b1 - a1 * b0, b2 - a2 * b0
    zi0 = (c0 + c1) / (1.0 + a1 + a2)
    zi = np.array([zi0, c1 - a2 * zi0])
    y = _sosfilt2(sos, ext, zi[:, None] * ext[0])
    y = _sosfilt2(sos, y[::-1], zi[:, None] * y[-1])[::-1]
    return y[padlen:len(y) - padlen] if padlen else y


def _sosfilt2(sos: np.ndarray, x: np.ndarray, state: np.ndarray) -> np.ndarray:
    """One second-order section, direct form II transposed, along axis 0 of ``x (N, C)`` from
    ``state (2, C)``: the recursion scipy's sosfilt runs, each channel in step."""
    b0, b1, b2, _, a1, a2 = (float(v) for v in sos)
    z0, z1 = state[0].copy(), state[1].copy()
    y = np.empty_like(x)
    bx1, bx2 = b1 * x, b2 * x  # the input's terms, all samples at once
    y0 = b0 * x
    for n in range(len(x)):
        yn = y0[n] + z0
        y[n] = yn
        z0 = bx1[n] - a1 * yn + z1
        z1 = bx2[n] - a2 * yn
    return y
