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
