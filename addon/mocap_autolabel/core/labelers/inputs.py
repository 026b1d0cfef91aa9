"""Input conventions of the ONNX models, named in each model's card ``input.convention``.

- ``points``  (``set``): raw observations and mask; the network is invariant to everything else.
- ``pca``     (``perm``, Ghorbani 2019): centred, rotated onto the principal axes, each axis scaled
  to [0, 1], a fixed number of slots; empty slots hold the centre (0.5, 0.5, 0.5).
- ``depth``   (``cnn``, Han 2018): an orthographic 52 x 52 depth image along the best of 10
  random axes; the network regresses the M marker positions in the image's frame.

Training code calls these same functions, so a model and its inputs cannot drift apart.
"""

from __future__ import annotations

import numpy as np

#: Han 2018's image size and the depth range of occupied pixels.
IMAGE = 52
DEPTH_RANGE = (0.1, 1.0)
#: Ten fixed "random" projection axes (seeded), so that labeling is reproducible.
_AXES = np.random.default_rng(2018).standard_normal((10, 3))
_AXES /= np.linalg.norm(_AXES, axis=1, keepdims=True)
#: Scale of the matching scores of regressed positions (metres): distance at which a label's score
#: drops by 1/2, and distance beyond which an observation is better called null.
MATCH_SIGMA = 0.01
MATCH_GATE = 0.03


def _centre(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    n = np.maximum(mask.sum(axis=1, keepdims=True), 1)[..., None]
    return (points * mask[..., None]).sum(axis=1, keepdims=True) / n


def _sign_by_skew(coords: np.ndarray, mask: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Flip each axis so that the cloud's third moment along it is positive (PCA signs are arbitrary)."""
    skew = ((coords ** 3) * mask[..., None]).sum(axis=1)  # (B, D)
    sign = np.where(skew < 0, -1.0, 1.0)
    return axes * sign[:, None, :]


def principal_frame(points: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre ``(B, 1, 3)`` and rotation ``(B, 3, 3)`` whose columns are the principal axes, largest first."""
    centre = _centre(points, mask)
    d = (points - centre) * mask[..., None]
    cov = np.swapaxes(d, 1, 2) @ d
    _, vec = np.linalg.eigh(cov)  # ascending eigenvalues
    vec = vec[:, :, ::-1]
    vec = _sign_by_skew(d @ vec, mask, vec)
    # Keep a proper rotation: the third axis follows from the first two.
    vec[:, :, 2] = np.cross(vec[:, :, 0], vec[:, :, 1])
    return centre, vec


def pca_slots(points: np.ndarray, mask: np.ndarray, slots: int) -> tuple[np.ndarray, np.ndarray]:
    """Ghorbani's canonical input: ``x`` float32 ``(B, slots, 3)`` and which observation fills each slot.

    The first principal axis becomes z and the second x; each axis is scaled to [0, 1] over the
    frame's observations; slots are filled in order of z, empty slots last. Frames with more
    observations than slots keep those nearest the centre.

    Returns:
        x, and ``index`` int ``(B, slots)``: the observation (column of ``points``) in each slot, -1 if empty.
    """
    b, k, _ = points.shape
    centre, axes = principal_frame(points, mask)
    c = (points - centre) @ axes  # columns: first, second, third principal axis
    c = c[:, :, [1, 2, 0]]  # x = second, y = third, z = first
    radius = np.where(mask, np.linalg.norm(points - centre, axis=2), np.inf)
    order = np.argsort(radius, axis=1, kind="stable")[:, :slots]
    # Slots in order of the first principal coordinate: part of the canonical form (a random order
    # would leave the MLP to learn permutation equivariance too, which 3,000 steps cannot teach).
    first = np.take_along_axis(np.where(mask, c[..., 2], np.inf), order, axis=1)
    order = np.take_along_axis(order, np.argsort(first, axis=1, kind="stable"), axis=1)
    index = np.where(np.take_along_axis(mask, order, axis=1), order, -1)
    if k < slots:
        index = np.concatenate([index, np.full((b, slots - k), -1)], axis=1)
    used = index >= 0
    sel = np.take_along_axis(c, np.maximum(index, 0)[..., None], axis=1)
    lo = np.where(used[..., None], sel, np.inf).min(axis=1, keepdims=True)
    hi = np.where(used[..., None], sel, -np.inf).max(axis=1, keepdims=True)
    x = (sel - lo) / np.maximum(hi - lo, 1e-6)
    x = np.where(used[..., None], x, 0.5)
    return x.astype(np.float32), index


def depth_image(points: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Han's sparse depth image of every frame.

    Returns:
        image float32 ``(B, 1, 52, 52)``; centre ``(B, 1, 3)``; rotation ``(B, 3, 3)`` (columns: image
        u, image v, depth axis); scale ``(B,)`` metres per canonical unit. Canonical coordinates
        are ``(p - centre) @ rotation / scale``; the image spans [-0.5, 0.5] in u and v with a 10 % margin.
    """
    b = points.shape[0]
    centre = _centre(points, mask)
    d = (points - centre) * mask[..., None]
    # Projecting along the axis of least spread among 10 gives the largest 2D spread.
    along = d @ _AXES.T  # (B, K, 10)
    n = np.maximum(mask.sum(axis=1), 1)[:, None]
    var = (along ** 2).sum(axis=1) / n
    axis = _AXES[np.argmin(var, axis=1)]  # (B, 3)
    # In-plane: principal axes of the projected cloud.
    helper = np.where(np.abs(axis[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    plane = np.stack([e1, e2], axis=2)  # (B, 3, 2)
    uv = d @ plane
    cov = np.swapaxes(uv, 1, 2) @ uv
    _, vec = np.linalg.eigh(cov)
    vec = vec[:, :, ::-1]
    vec = _sign_by_skew(uv @ vec, mask, vec)
    u_axis = (plane @ vec)  # (B, 3, 2)
    depth_axis = np.cross(u_axis[:, :, 0], u_axis[:, :, 1])
    rot = np.concatenate([u_axis, depth_axis[:, :, None]], axis=2)
    c = d @ rot
    extent = np.where(mask[..., None], np.abs(c[..., :2]), 0).max(axis=(1, 2))
    scale = np.maximum(extent / 0.4, 1e-3)  # +-0.4 of the image: 10 % margin each side
    c = c / scale[:, None, None]
    pix = np.clip(((c[..., :2] + 0.5) * IMAGE).astype(np.int64), 0, IMAGE - 1)
    z = c[..., 2]
    zlo = np.where(mask, z, np.inf).min(axis=1, keepdims=True)
    zhi = np.where(mask, z, -np.inf).max(axis=1, keepdims=True)
    depth = DEPTH_RANGE[0] + (DEPTH_RANGE[1] - DEPTH_RANGE[0]) * (z - zlo) / np.maximum(zhi - zlo, 1e-6)
    image = np.zeros((b, IMAGE * IMAGE), dtype=np.float32)
    flat = pix[..., 1] * IMAGE + pix[..., 0]
    rows = np.repeat(np.arange(b), points.shape[1])
    keep = mask.ravel()
    np.maximum.at(image, (rows[keep], flat.ravel()[keep]), depth.ravel()[keep].astype(np.float32))
    return image.reshape(b, 1, IMAGE, IMAGE), centre, rot, scale


def match_scores(predicted: np.ndarray, points: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """Scores ``(B, K, M + 1)`` from regressed marker positions ``(B, M, 3)`` and observations ``(B, K, 3)``.

    Both in the same coordinates; ``scale`` (metres per unit, ``(B,)``) converts distances to metres.
    Score = -(d / sigma)^2 / 2; the null column sits at the gate distance.
    """
    d = np.linalg.norm(points[:, :, None, :] - predicted[:, None, :, :], axis=3)
    if scale is not None:
        d = d * scale[:, None, None]
    s = -0.5 * (d / MATCH_SIGMA) ** 2
    null = np.full(s.shape[:2] + (1,), -0.5 * (MATCH_GATE / MATCH_SIGMA) ** 2)
    return np.concatenate([s, null], axis=2).astype(np.float32)


def prepare_inputs(card: dict, points: np.ndarray, mask: np.ndarray) -> tuple[dict, dict]:
    """ONNX feeds for a model with this card, plus what :func:`scores_from_outputs` needs back."""
    convention = card["input"].get("convention", "points")
    if convention == "points":
        _, axes = principal_frame(points.astype(np.float64), mask)
        return {"points": points.astype(np.float32), "mask": mask.astype(np.float32),
                "axes": axes.astype(np.float32)}, {}
    if convention == "pca":
        x, index = pca_slots(points, mask, int(card["input"]["slots"]))
        return {"x": x}, {"index": index}
    if convention == "depth":
        image, centre, rot, scale = depth_image(points, mask)
        return {"image": image}, {"centre": centre, "rot": rot, "scale": scale}
    raise ValueError(f"unknown input convention {convention!r}")


def scores_from_outputs(card: dict, outputs: list, context: dict, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Turn a model's raw outputs into the protocol's ``(B, K, M + 1)`` scores.

    The card's ``calibration.null_offset`` (nats, chosen on held-out synthetic frames after
    training) is subtracted from the null column.
    """
    convention = card["input"].get("convention", "points")
    m = len(card["layout"]["labels"])
    if convention == "points":
        scores = outputs[0]
    elif convention == "pca":
        scores = slot_scores(outputs[0], context["index"], points.shape[1], m)
    elif convention == "depth":
        pred = outputs[0].reshape(len(points), m, 3)
        canon = ((points - context["centre"]) @ context["rot"]) / context["scale"][:, None, None]
        scores = match_scores(pred, canon, context["scale"])
    else:
        raise ValueError(f"unknown input convention {convention!r}")
    offset = float(card.get("calibration", {}).get("null_offset", 0.0))
    if offset:
        scores = scores.copy()
        scores[..., m] -= offset
    return scores


def slot_scores(log_d: np.ndarray, index: np.ndarray, k: int, m: int) -> np.ndarray:
    """Map slot-by-column log-probabilities ``(B, S, S)`` (M label columns, then null columns) to ``(B, K, M + 1)``."""
    b, s, _ = log_d.shape
    null = np.logaddexp.reduce(log_d[:, :, m:], axis=2) if s > m else np.full((b, s), -30.0)
    per_slot = np.concatenate([log_d[:, :, :m], null[..., None]], axis=2)
    out = np.full((b, k, m + 1), -30.0, dtype=np.float32)
    out[:, :, m] = 0.0  # observations that did not fit in a slot are called null
    rows, cols = np.nonzero(index >= 0)
    out[rows, index[rows, cols]] = per_slot[rows, cols]
    return out
