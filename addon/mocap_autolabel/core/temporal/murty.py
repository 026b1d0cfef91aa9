"""Murty's algorithm: the N best one-to-one labelings of one frame, best first."""

from __future__ import annotations

import heapq

import numpy as np
from scipy.optimize import linear_sum_assignment

#: Cost of a forbidden pair; any solution that uses one is infeasible.
_BIG = 1e9


def _solve(cost: np.ndarray) -> tuple[float, np.ndarray] | None:
    rows, cols = linear_sum_assignment(cost)
    total = float(cost[rows, cols].sum())
    if total >= _BIG / 2:
        return None
    out = np.empty(cost.shape[0], dtype=np.int64)
    out[rows] = cols
    return total, out


def murty(cost: np.ndarray, n_best: int) -> list[tuple[float, np.ndarray]]:
    """The ``n_best`` cheapest complete assignments of rows to distinct columns.

    Args:
        cost: ``(R, C)`` with ``R <= C``; entries ``>= 1e9`` are forbidden.
        n_best: how many assignments to return (fewer if fewer exist).

    Returns:
        ``(total cost, column of each row)`` pairs, cheapest first.
    """
    cost = np.asarray(cost, dtype=np.float64)
    first = _solve(cost)
    if first is None:
        return []
    # Heap of (cost, tie-breaker, assignment, forced rows, problem cost matrix).
    heap = [(first[0], 0, first[1], 0, cost)]
    counter = 1
    out: list[tuple[float, np.ndarray]] = []
    while heap and len(out) < n_best:
        total, _, assignment, n_forced, problem = heapq.heappop(heap)
        out.append((total, assignment))
        # Partition the rest of this problem's solution space (Murty 1968): child i keeps rows
        # before i as in this solution and forbids row i's column.
        sub = problem.copy()
        order = np.arange(cost.shape[0])
        for i in order[n_forced:]:
            child = sub.copy()
            child[i, assignment[i]] = _BIG
            solved = _solve(child)
            if solved is not None:
                heapq.heappush(heap, (solved[0], counter, solved[1], i, child))
                counter += 1
            # Force row i to its column for the next children.
            col = assignment[i]
            keep = sub[i, col]
            sub[i, :] = _BIG
            sub[:, col] = _BIG
            sub[i, col] = keep
    return out


def nbest_labelings(scores: np.ndarray, n_best: int = 5) -> list[tuple[float, np.ndarray]]:
    """N best labelings of one frame's ``(k, M + 1)`` log-domain scores (valid rows only).

    Returns ``(total score, label per observation with -1 for null)`` pairs, best first.
    """
    k, m1 = scores.shape
    m = m1 - 1
    cost = np.full((k, m + k), _BIG)
    cost[:, :m] = -scores[:, :m]
    cost[np.arange(k), m + np.arange(k)] = -scores[:, m]
    return [(-total, np.where(cols < m, cols, -1)) for total, cols in murty(cost, n_best)]
