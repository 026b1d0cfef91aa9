"""Tracklets: runs of valid samples of one point slot, the unit that labeling decides on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .take import Take


@dataclass(frozen=True)
class Tracklets:
    """All tracklets of a take, as parallel arrays ordered by (slot, start).

    A tracklet's id is its index in these arrays: for the same file and the same options the
    ids are the same, so constraints and reviews can refer to them.

    Attributes:
        slot: int ``(n,)``, the point slot (column of ``Take.positions``) of each tracklet.
        start: int ``(n,)``, first frame index (0-based, into ``Take.positions``).
        stop: int ``(n,)``, one past the last frame index.
    """

    slot: np.ndarray
    start: np.ndarray
    stop: np.ndarray

    def __len__(self) -> int:
        return int(self.slot.shape[0])

    @property
    def length(self) -> np.ndarray:
        """int ``(n,)``: frames in each tracklet."""
        return self.stop - self.start

    def id_map(self, n_frames: int, n_points: int) -> np.ndarray:
        """int32 ``(frames, points)``: the tracklet id of every sample, -1 where there is none."""
        begin = np.zeros((n_points, n_frames), dtype=bool)
        begin[self.slot, self.start] = True
        cover = np.zeros((n_points, n_frames + 1), dtype=np.int32)
        np.add.at(cover, (self.slot, self.start), 1)
        np.add.at(cover, (self.slot, self.stop), -1)
        inside = np.cumsum(cover, axis=1)[:, :n_frames] > 0
        # Ids are ordered by (slot, start), which is row-major order of ``begin``.
        ids = (np.cumsum(begin.ravel()) - 1).reshape(n_points, n_frames).astype(np.int32)
        ids[~inside] = -1
        return ids.T


def mask_runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True in every column of a bool ``(frames, columns)`` mask.

    Returns:
        column, start and stop (one past the end) int arrays, ordered by (column, start).
    """
    padded = np.zeros((mask.shape[0] + 2, mask.shape[1]), dtype=np.int8)
    padded[1:-1] = mask
    edges = np.diff(padded, axis=0).T  # (columns, frames + 1)
    column, start = np.nonzero(edges == 1)
    _, stop = np.nonzero(edges == -1)
    return column, start, stop


def find_tracklets(take: Take, max_speed: float | None = None) -> Tracklets:
    """Split every point slot of ``take`` into runs between gaps.

    Args:
        take: the take.
        max_speed: metres per second; if given, a step between consecutive frames faster than
            this also starts a new tracklet (a capture system that joined two markers).
    """
    valid = take.valid.T  # (points, frames): row-major order is (slot, frame)
    jump = np.zeros_like(valid)
    if max_speed is not None and take.n_frames > 1:
        step = np.linalg.norm(np.diff(take.positions, axis=0), axis=2).T
        jump[:, 1:] = step > max_speed / take.rate  # NaN compares False; gaps split anyway
    before = np.zeros_like(valid)
    before[:, 1:] = valid[:, :-1]
    after = np.zeros_like(valid)
    after[:, :-1] = valid[:, 1:] & ~jump[:, 1:]
    slot, start = np.nonzero(valid & (~before | jump))
    _, last = np.nonzero(valid & ~after)
    return Tracklets(slot=slot.astype(np.int32), start=start.astype(np.int64), stop=last.astype(np.int64) + 1)


#: Seconds a trajectory must last to count in :func:`break_rate` (a flickering ghost lasts less).
TRACKED_S = 0.1


def break_rate(tracklets: Tracklets, n_frames: int, rate: float) -> float:
    """How often the take's trajectories break: ends of trajectories of at least
    :data:`TRACKED_S` seconds before the take's last frame, per second of such trajectories
    (hand takes with a few short occlusions a marker-minute: about 0.25; a quarter of the samples
    missing in gaps of about 15 frames at 120 Hz: about 1.6).

    Args:
        tracklets: the take's runs between gaps (:func:`find_tracklets`).
        n_frames: the take's frames.
        rate: frames per second.
    """
    length = tracklets.length
    tracked = length >= max(1, int(round(TRACKED_S * rate)))
    seconds = length[tracked].sum() / rate
    if seconds <= 0:
        return 0.0
    return float(((tracklets.stop < n_frames) & tracked).sum() / seconds)


def find_crossings(take: Take, near: float = 0.03, gain: float = 0.003, max_points: int = 64) -> dict[int, list[int]]:
    """Frames where two trajectories that pass close may have traded markers without a gap.

    A capture system's tracker can swap the identities of two markers that come within a few
    millimetres of each other. At such a frame each trajectory continues where the other one
    was heading: predicted at constant velocity from the two frames before, the crossed
    continuation fits better than the straight one. A pair is a candidate when its points were
    within ``near`` of each other the frame before and crossing them lowers the summed
    prediction error by more than ``gain``. Both trajectories are cut there and their parts
    decided apart; a cut where nothing was swapped only splits one decision in two.

    Args:
        take: the take (metres).
        near: metres between the two points at the frame before.
        gain: metres of summed prediction error that crossing must save. Of 3, 5, 8 and 12 mm,
            3 mm labeled synthetic validation takes best, for han19 and glove13 alike.
        max_points: frames with more slots than this valid in three frames running are skipped
            (a flood of ghosts: the pairs grow with the square).

    Returns:
        ``{slot: [frames where a new part begins]}``.
    """
    cuts: dict[int, list[int]] = {}
    if take.n_frames < 3 or take.n_points < 2:
        return cuts
    ok = take.valid[2:] & take.valid[1:-1] & take.valid[:-2]  # (F - 2, S): row i is frame i + 2
    count = ok.sum(axis=1)
    frames = np.flatnonzero((count >= 2) & (count <= max_points)) + 2
    if not len(frames):
        return cuts
    k = int(count[frames - 2].max())
    step = max(1, 4_000_000 // (k * k))
    upper = np.triu(np.ones((k, k), dtype=bool), 1)
    for lo in range(0, len(frames), step):
        f = frames[lo:lo + step]
        # Pack the slots valid in all three frames to the left, the same order in each.
        slots = np.argsort(~ok[f - 2], axis=1, kind="stable")[:, :k]
        live = np.take_along_axis(ok[f - 2], slots, axis=1)
        now, before, earlier = (np.take_along_axis(take.positions[f - d], slots[..., None], axis=1).astype(np.float64)
                                for d in (0, 1, 2))
        sq = (before * before).sum(axis=2)
        gap2 = sq[:, :, None] + sq[:, None, :] - 2.0 * before @ before.transpose(0, 2, 1)
        row, i, j = np.nonzero(live[:, :, None] & live[:, None, :] & upper & (gap2 < near * near))
        if not len(row):
            continue
        # Constant-velocity predictions of both points of each close pair, and where they are now.
        pred_i, pred_j = (2.0 * before[row, s] - earlier[row, s] for s in (i, j))
        now_i, now_j = now[row, i], now[row, j]
        straight = np.linalg.norm(pred_i - now_i, axis=1) + np.linalg.norm(pred_j - now_j, axis=1)
        crossed = np.linalg.norm(pred_i - now_j, axis=1) + np.linalg.norm(pred_j - now_i, axis=1)
        cross = straight - crossed > gain
        for fr, a, b in zip(f[row[cross]], slots[row[cross], i[cross]], slots[row[cross], j[cross]]):
            cuts.setdefault(int(a), []).append(int(fr))
            cuts.setdefault(int(b), []).append(int(fr))
    return cuts
