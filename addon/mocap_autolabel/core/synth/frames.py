"""Independent labeled frames for training and testing labelers (no motion, no tracks).

Each frame is a random hand (size, side, marker placement), a random pose, a uniformly random
orientation and position, with markers dropped, ghosts added near the hand and, in some frames,
distractor markers of the body or of objects around it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..hand.skeleton import BONE_NAMES, DOF_INDEX, FINGERS, N_DOF, HandModel, sample_hand_size
from ..hand.skin import blend
from ..layout import Layout
from ..rotations import random_rotations
from .generate import EMPTY, GHOST, _slip, misplacement
from .poses import sample_joint_angles, widened_limits


@dataclass
class FrameConfig:
    """How frames are corrupted. Ranges are inclusive ``(low, high)``; lengths in metres."""

    drop: tuple[int, int] = (0, 5)  # markers removed per frame (occlusion)
    ghosts: tuple[int, int] = (0, 3)  # ghost points per frame
    ghost_near_marker: float = 0.5  # share of ghosts 5-25 mm from a marker (reflections), rest in the hand's box
    distractor_share: float = 0.5  # share of frames with body / object markers around the hand
    distractors: tuple[int, int] = (1, 8)
    noise_sd: float = 0.001
    slip: tuple[float, float] = (0.0, 0.006)  # per-hand marker placement error along the skin
    rotation: bool = True  # uniform random orientation; False keeps the hand frame
    # Per hand and finger, abduction that follows flexion (up to this many radians per radian of
    # MCP + PIP flexion, either way): real flexed fingers converge instead of curling in their
    # rest planes, and by how much differs between hands and gloves.
    convergence: float = 0.0
    proportions: float = 0.0  # per hand, every bone's length times 1 +- up to this (other gloves, other hands)
    range_margin_deg: float = 0.0  # every joint range widened by this much on both sides
    # Per hand, every marker moved at rest by a Gaussian offset of this SD per axis, doubled on the
    # distal phalanges (glove markers sit where the glove sits, not where the layout says).
    placement_sd: float = 0.0
    # Per hand, the finger markers moved sideways towards the middle of the hand by up to this
    # much at the little fingertip (less on the other fingers, half on the middle phalanges): the
    # fingertips of real hands and gloves bunch together, most visibly in a fist.
    tip_convergence: float = 0.0
    hands: int = 64  # distinct hands (size, side, placement) per call

    @property
    def max_points(self) -> int:
        return self.ghosts[1] + self.distractors[1]


@dataclass
class LabeledFrames:
    """``points`` float32 ``(n, K, 3)`` metres; ``labels`` int16 ``(n, K)`` (label index, -1 ghost or
    distractor, -2 padding); ``mask`` bool ``(n, K)``. Observations are in random order.
    ``markers`` float32 ``(n, M, 3)``: every marker's true position, dropped ones included."""

    points: np.ndarray
    labels: np.ndarray
    mask: np.ndarray
    markers: np.ndarray

    def __getitem__(self, index: slice) -> LabeledFrames:
        return LabeledFrames(self.points[index], self.labels[index], self.mask[index], self.markers[index])

    def __len__(self) -> int:
        return int(self.points.shape[0])


def hand_frames(layout: Layout, n: int, rng: np.random.Generator, cfg: FrameConfig) -> np.ndarray:
    """Clean marker positions ``(n, M, 3)`` of random hands in random poses, in each hand's frame."""
    out = np.empty((n, len(layout), 3))
    which = rng.integers(cfg.hands, size=n)
    for h in range(cfg.hands):
        rows = np.flatnonzero(which == h)
        if not len(rows):
            continue
        length, breadth = sample_hand_size(rng)
        side = "left" if rng.random() < 0.5 else "right"
        scale = None
        if cfg.proportions > 0:
            scale = tuple(1.0 + rng.uniform(-cfg.proportions, cfg.proportions, size=len(BONE_NAMES)))
        hand = HandModel(length=length, breadth=breadth, side=side, bone_scale=scale)
        binding, normals = layout.place(hand)
        binding = _slip(rng, binding, normals, cfg.slip)
        binding = binding.moved(misplacement(rng, binding, hand, cfg.placement_sd, cfg.tip_convergence))
        pose = np.zeros((len(rows), N_DOF))
        pose[:, 6:] = sample_joint_angles(rng, len(rows), margin_deg=cfg.range_margin_deg)
        lo, hi = widened_limits(cfg.range_margin_deg)
        if cfg.convergence > 0:
            c = rng.uniform(-cfg.convergence, cfg.convergence, size=len(FINGERS))
            for i, f in enumerate(FINGERS):
                flex = pose[:, DOF_INDEX[f"{f}_mcp_flex"]] + pose[:, DOF_INDEX[f"{f}_pip"]]
                a = DOF_INDEX[f"{f}_mcp_abd"]
                pose[:, a] = np.clip(pose[:, a] + c[i] * flex, lo[a - 6], hi[a - 6])
        r, t = hand.skinning_transforms(pose)
        out[rows] = blend(r, t, binding)
    return out


def sample_frames(layout: Layout, n: int, rng: np.random.Generator, cfg: FrameConfig | None = None) -> LabeledFrames:
    """``n`` independent labeled frames of ``layout`` (see the module docstring)."""
    cfg = cfg or FrameConfig()
    local = hand_frames(layout, n, rng, cfg)
    local += rng.normal(0.0, cfg.noise_sd, size=local.shape)
    return corrupt_markers(local, rng, cfg, place=True)


def corrupt_markers(markers: np.ndarray, rng: np.random.Generator, cfg: FrameConfig,
                    place: bool = False) -> LabeledFrames:
    """Drop markers, add ghosts and distractors, shuffle: the labeling problem of each frame.

    Args:
        markers: ``(n, M, 3)`` true marker positions in metres (a hand frame, or a capture's own
            coordinates for real data).
        rng: the random source.
        cfg: what to add and remove.
        place: also turn each frame by a random rotation (when ``cfg.rotation``) and move it to a
            random place in a 2 m capture volume. Distractor "body" markers extend along -y, the
            forearm direction of the hand frame, so give hand-frame markers when using them.
    """
    n, m, _ = markers.shape
    local = np.asarray(markers, dtype=np.float64)

    # Occlusion: drop a random number of markers.
    n_drop = np.minimum(rng.integers(cfg.drop[0], cfg.drop[1] + 1, size=n), m - 1)  # keep one marker at least
    rank = np.argsort(rng.random((n, m)), axis=1).argsort(axis=1)
    marker_ok = rank >= n_drop[:, None]

    # Ghosts: reflections beside a marker, or anywhere in the hand's box.
    g = cfg.ghosts[1]
    ghost_ok = np.arange(g) < rng.integers(cfg.ghosts[0], g + 1, size=(n, 1))
    near = local[np.arange(n)[:, None], rng.integers(m, size=(n, g))]
    direction = rng.standard_normal((n, g, 3))
    direction /= np.linalg.norm(direction, axis=2, keepdims=True)
    near = near + direction * rng.uniform(0.005, 0.025, size=(n, g, 1))
    lo, hi = local.min(axis=1, keepdims=True) - 0.02, local.max(axis=1, keepdims=True) + 0.02
    boxed = lo + (hi - lo) * rng.random((n, g, 3))
    ghosts = np.where(rng.random((n, g, 1)) < cfg.ghost_near_marker, near, boxed)

    # Distractors: body markers up the forearm and beyond, or rigid objects around the hand.
    d = cfg.distractors[1]
    has = rng.random((n, 1)) < cfg.distractor_share
    dist_ok = has & (np.arange(d) < rng.integers(cfg.distractors[0], d + 1, size=(n, 1)))
    along = rng.uniform(0.12, 0.7, size=(n, d, 1)) * np.array([0.0, -1.0, 0.0])
    body = along + rng.normal(0.0, 0.08, size=(n, d, 3))
    centre = rng.standard_normal((n, 1, 3))
    centre = centre / np.linalg.norm(centre, axis=2, keepdims=True) * rng.uniform(0.06, 0.3, size=(n, 1, 1))
    objects = local.mean(axis=1, keepdims=True) + centre + rng.normal(0.0, 0.05, size=(n, d, 3))
    distractors = np.where(rng.random((n, 1, 1)) < 0.5, body, objects)

    pts = np.concatenate([local, ghosts, distractors], axis=1)
    if place:
        rot = random_rotations(rng, n) if cfg.rotation else np.broadcast_to(np.eye(3), (n, 3, 3))
        origin = rng.uniform(-1.0, 1.0, size=(n, 1, 3)) + np.array([0.0, 0.0, 1.2])
        pts = (rot[:, None] @ pts[..., None])[..., 0] + origin
    ok = np.concatenate([marker_ok, ghost_ok, dist_ok], axis=1)
    lab = np.concatenate([np.broadcast_to(np.arange(m), (n, m)), np.full((n, g + d), GHOST)], axis=1)

    # Shuffle, then pack valid observations to the left.
    keys = rng.random(ok.shape) + (~ok) * 2.0
    order = np.argsort(keys, axis=1)[:, : m + cfg.max_points]
    mask = np.take_along_axis(ok, order, axis=1)
    k = max(1, int(mask.sum(axis=1).max()))
    order, mask = order[:, :k], mask[:, :k]
    points = np.take_along_axis(pts, order[..., None], axis=1)
    labels = np.take_along_axis(lab, order, axis=1)
    points[~mask] = 0.0
    labels[~mask] = EMPTY
    return LabeledFrames(points.astype(np.float32), labels.astype(np.int16), mask, pts[:, :m].astype(np.float32))
