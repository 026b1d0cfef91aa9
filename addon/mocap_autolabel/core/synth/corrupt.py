"""What a real capture system does to clean marker trajectories: noise, occlusion, ghosts, merges.

Each function is independent, seeded through the ``rng`` it is given, and vectorised over frames.
Occlusion comes from two sources: random gaps in runs, and a camera model in which the hand's
own capsules block the view (a marker counts as seen when at least two cameras see it).
"""

from __future__ import annotations

import numpy as np

from ..hand.skeleton import HandModel
from ..hand.skin import Binding
from ..tracklets import mask_runs


def camera_ring(rng: np.random.Generator, center: np.ndarray, count: tuple[int, int] = (8, 16),
                radius: tuple[float, float] = (2.0, 3.0), height: tuple[float, float] = (0.6, 2.6)) -> np.ndarray:
    """Camera positions ``(C, 3)`` in metres on a ring around ``center`` (the volume's middle, z up).

    Heights spread from below to above the hand, as hand-capture rigs mount cameras low and high
    so that curled fingertips stay in view.
    """
    n = int(rng.integers(count[0], count[1] + 1))
    azimuth = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.uniform(0, 2 * np.pi) + rng.normal(0, 0.1, n)
    r = rng.uniform(*radius, n)
    z = rng.uniform(*height, n)
    return np.column_stack([center[0] + r * np.cos(azimuth), center[1] + r * np.sin(azimuth), z])


def occluder_spheres(hand: HandModel, per_bone: int = 2) -> tuple[Binding, np.ndarray]:
    """The hand's capsules as spheres, for visibility: their centres bound rigidly to the bones
    (pose them with :func:`blend`) and their radii ``(S,)`` in metres.

    Args:
        per_bone: spheres along each bone except the palm; the metacarpals' spheres cover the palm.
    """
    r0, p0 = hand.rest
    lengths, radii = hand.bone_lengths, hand.bone_radii
    bones = np.repeat(np.arange(1, len(lengths)), per_bone)
    along = np.tile((np.arange(per_bone) + 0.5) / per_bone, len(lengths) - 1)
    local = np.zeros((len(bones), 3))
    local[:, 1] = along * lengths[bones]
    rest = (r0[bones] @ local[:, :, None])[..., 0] + p0[bones]
    binding = Binding(rest, np.stack([bones, bones], axis=1), np.tile([1.0, 0.0], (len(bones), 1)))
    return binding, radii[bones, 0] + (radii[bones, 1] - radii[bones, 0]) * along


def camera_visibility(markers: np.ndarray, normals: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                      cameras: np.ndarray, min_views: int = 2, max_angle_deg: float = 80.0,
                      every: int = 4) -> np.ndarray:
    """Which markers the cameras see: bool ``(F, M)``.

    A camera sees a marker when the line of sight leaves the skin at less than ``max_angle_deg``
    from its normal and no occluder sphere lies on the line between them. The model is
    evaluated on every ``every``-th frame and held in between (occlusion changes slowly, and
    this keeps generation fast).

    Args:
        markers: ``(F, M, 3)`` positions, metres.
        normals: ``(F, M, 3)`` skin normals under the markers.
        centres, radii: occluder spheres ``(F, S, 3)`` and ``(S,)``.
        cameras: ``(C, 3)`` camera positions.
    """
    n_frames = markers.shape[0]
    idx = np.arange(0, n_frames, every)
    m = markers[idx].astype(np.float32)
    s = centres[idx].astype(np.float32)
    cam = cameras.astype(np.float32)
    r2 = (radii.astype(np.float32) ** 2)[None, None, :]
    cos_max = np.float32(np.cos(np.radians(max_angle_deg)))
    n = np.asarray(normals[idx], dtype=np.float32)
    views = np.zeros((len(idx), m.shape[1]), dtype=np.int16)
    active = np.arange(len(idx))  # frames in which some marker still lacks min_views cameras
    # Cameras from around the ring in interleaved order: varied views first, so most frames are
    # settled early and later cameras only work on the few frames with an occluded marker.
    for c in cam[_interleaved(len(cam))]:
        ma, sa = m[active], s[active]
        to_m = ma - c  # (f, M, 3) camera to marker
        dist_m = np.linalg.norm(to_m, axis=-1)
        u = to_m / dist_m[..., None]
        facing = -np.einsum("fmk,fmk->fm", u, n[active]) > cos_max
        to_s = sa - c  # (f, S, 3)
        t = u @ np.swapaxes(to_s, 1, 2)  # (f, M, S): depth of each sphere along each line of sight
        perp2 = np.einsum("fsk,fsk->fs", to_s, to_s)[:, None, :] - t * t
        blocked = ((t < dist_m[..., None]) & (perp2 < r2)).any(axis=-1)
        views[active] += facing & ~blocked
        active = active[(views[active] < min_views).any(axis=1)]
        if active.size == 0:
            break
    seen = views >= min_views
    return np.repeat(seen, every, axis=0)[:n_frames]


def _interleaved(n: int) -> np.ndarray:
    """The indices 0..n-1 in van der Corput order (0, n/2, n/4, 3n/4, ...): spread out first."""
    keys = [sum(((i >> k) & 1) / 2 ** (k + 1) for k in range(max(n, 1).bit_length())) for i in range(n)]
    return np.argsort(keys, kind="stable")


def gap_mask(rng: np.random.Generator, frames: int, columns: int, gaps_per_frame: np.ndarray | float,
             mean_gap: float, min_gap: int = 1) -> np.ndarray:
    """Random occlusions in runs: bool ``(frames, columns)``, True where missing.

    Args:
        gaps_per_frame: expected gap starts per frame, per column (scalar or ``(columns,)``).
        mean_gap: mean gap length in frames (lengths are geometric, at least ``min_gap``).
    """
    missing = np.zeros((frames + 1, columns), dtype=np.int32)
    lam = np.broadcast_to(np.asarray(gaps_per_frame, dtype=float), (columns,)) * frames
    counts = rng.poisson(lam)
    col = np.repeat(np.arange(columns), counts)
    start = rng.integers(0, frames, size=col.size)
    p = 1.0 / max(mean_gap - min_gap + 1, 1.0)
    length = min_gap - 1 + rng.geometric(p, size=col.size)
    stop = np.minimum(start + length, frames)
    np.add.at(missing, (start, col), 1)
    np.add.at(missing, (stop, col), -1)
    return np.cumsum(missing, axis=0)[:frames] > 0


def fill_short_gaps(missing: np.ndarray, max_length: int) -> np.ndarray:
    """Close gaps of at most ``max_length`` frames, as capture software bridges them on export.

    Args:
        missing: bool ``(F, N)``, True where missing.

    Returns:
        a new mask; gaps touching the first or last frame are kept (nothing to bridge from).
    """
    out = missing.copy()
    if max_length <= 0:
        return out
    col, start, stop = mask_runs(missing)
    short = (stop - start <= max_length) & (start > 0) & (stop < missing.shape[0])
    for c, a, b in zip(col[short], start[short], stop[short]):
        out[a:b, c] = False
    return out


def merge_close(positions: np.ndarray, distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Two markers closer than ``distance`` (metres) become one observation at their midpoint.

    The lower-index marker carries the merged observation; the other goes missing for that frame.

    Args:
        positions: ``(F, M, 3)`` with NaN where missing.

    Returns:
        the merged positions (a copy) and bool ``(F, M)``: True where a marker absorbed another.
    """
    out = positions.copy()
    merged = np.zeros(positions.shape[:2], dtype=bool)
    coords = np.ascontiguousarray(positions.transpose(1, 2, 0))  # (M, 3, F): contiguous rows are fast
    found = []
    for a in range(positions.shape[1] - 1):
        d = coords[a + 1:] - coords[a]
        near_b, near_f = np.nonzero(d[:, 0] ** 2 + d[:, 1] ** 2 + d[:, 2] ** 2 < distance**2)  # NaN: False
        found.append((near_f, np.full(near_f.size, a), near_b + a + 1))
    f, i, j = (np.concatenate(x) for x in zip(*found)) if found else (np.zeros(0, int),) * 3
    # Pairs that share a marker in the same frame (three markers bunched) are resolved one by one.
    n = positions.shape[1]
    keys, counts = np.unique(np.concatenate([f * n + i, f * n + j]), return_counts=True)
    shared = (counts[np.searchsorted(keys, f * n + i)] > 1) | (counts[np.searchsorted(keys, f * n + j)] > 1)
    a, b, c = f[~shared], i[~shared], j[~shared]
    out[a, b] = 0.5 * (positions[a, b] + positions[a, c])
    out[a, c] = np.nan
    merged[a, b] = True
    for frame, p, q in zip(f[shared], i[shared], j[shared]):
        if np.isnan(out[frame, p, 0]) or np.isnan(out[frame, q, 0]):
            continue  # already merged into a third marker this frame
        out[frame, p] = 0.5 * (out[frame, p] + out[frame, q])
        out[frame, q] = np.nan
        merged[frame, p] = True
    return out, merged


def flicker_ghosts(rng: np.random.Generator, centre: np.ndarray, rotation: np.ndarray, per_frame: float,
                   spread: float, box: float, box_share: float, mean_length: float,
                   jitter: float) -> list[tuple[int, np.ndarray]]:
    """Short-lived ghost points: most near the hand, moving with it; some anywhere in a box.

    Args:
        centre: ``(F, 3)`` hand centre per frame, metres.
        rotation: ``(F, 3, 3)`` hand orientation per frame.
        per_frame: mean number of ghosts present in a frame.
        spread: SD (metres) of near-hand ghosts around the centre, in the hand frame.
        box: edge (metres) of the box around the hand for the uniform ghosts.
        box_share: fraction of ghosts that are uniform in the box.
        mean_length: mean ghost lifetime in frames (geometric).
        jitter: per-frame position noise of a ghost, metres.

    Returns:
        ghost runs as ``(first frame, positions (n, 3))``.
    """
    frames = centre.shape[0]
    n = rng.poisson(per_frame * frames / mean_length)
    starts = rng.integers(0, frames, size=n)
    lengths = rng.geometric(1.0 / mean_length, size=n)
    in_box = rng.random(n) < box_share
    offsets = rng.normal(0, spread, size=(n, 3))
    box_pos = rng.uniform(-box / 2, box / 2, size=(n, 3))
    runs = []
    for k in range(n):
        a = starts[k]
        b = min(a + lengths[k], frames)
        if in_box[k]:
            pos = np.broadcast_to(centre[a] + box_pos[k], (b - a, 3))
        else:
            pos = centre[a:b] + rotation[a:b] @ offsets[k]
        runs.append((int(a), pos + rng.normal(0, jitter, size=(b - a, 3))))
    return runs


def persistent_ghosts(rng: np.random.Generator, centre: np.ndarray, rotation: np.ndarray, count: int,
                      duration: tuple[int, int], distance: tuple[float, float]) -> np.ndarray:
    """Long-lived ghost tracks (a reflective object nearby, a ring or watch on the hand).

    Half of them rest in the world near where the hand passes and drift slowly; the other half
    ride rigidly with the hand at ``distance`` from its centre.

    Returns:
        ``(F, count, 3)`` positions, NaN outside each ghost's lifetime.
    """
    frames = centre.shape[0]
    out = np.full((frames, count, 3), np.nan)
    for g in range(count):
        n = int(min(frames, rng.integers(duration[0], duration[1] + 1)))
        a = int(rng.integers(0, frames - n + 1))
        direction = rng.standard_normal(3)
        offset = direction / np.linalg.norm(direction) * rng.uniform(*distance)
        if rng.random() < 0.5:
            drift = np.cumsum(rng.normal(0, 2e-4, size=(n, 3)), axis=0)
            out[a:a + n, g] = centre[a] + offset + drift
        else:
            out[a:a + n, g] = centre[a:a + n] + rotation[a:a + n] @ offset
    return out
