"""Synthetic takes of two hands that interact: approach, touch, clap, interlace, cross and occlude
each other, with truth that records each sample's hand.

Each hand is a synthetic hand of its own size, corrupted as one-hand synthetic takes are
(:func:`.generate.synthesize`: camera occlusion, gaps, noise, merges, ghosts); the right hand is
then carried along the left one's path by an interaction schedule (apart, touching, clapping,
interlaced, crossing over), placed beside it (the nearest markers of the two hands 4-40 mm apart
while close, never through each other), and markers of a hand buried in the other are hidden.

Truth labels: ``0 .. M-1`` the left hand's markers, ``M .. 2M-1`` the right hand's.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, replace

import numpy as np

from ..formats.c3d import write_c3d
from ..hands import HandNaming
from ..layout import Layout
from .generate import EMPTY, GHOST, SynthConfig, SynthTake, synthesize, write_truth
from .props import hold_prop

#: What the hands do in each phase of the schedule.
PHASES = ("apart", "touch", "clap", "interlace", "cross")


@dataclass(frozen=True)
class TwoHandConfig:
    """Settings of a two-hand take (metres, seconds).

    Attributes:
        apart: distance between the hands' centres while apart, drawn per phase from this range.
        close: distance between the two hands' nearest markers while touching, clapping,
            interlaced or crossing over, drawn per phase from this range (interlaced: half of it).
            The hands are placed side by side along the phase's direction at this distance,
            never through each other.
        phase_s: length of a phase, drawn from this range; phases ease into each other over 0.3 s.
        close_share: share of the phases in which the hands are close (touch, clap, interlace, cross).
        bury: a marker nearer than this to a marker of the other hand is hidden (the other hand
            covers it) if it is one of the markers covered in that phase (each with probability
            ``bury_share``, drawn once per phase).
        synth: each hand's generator settings (default: :class:`.generate.SynthConfig`, the
            realistic corruption of one-hand synthetic takes).
        prop_markers: 3-6 to put a rigid prop of that many markers in the left hand
            (:func:`.props.hold_prop`); 0 for none. Its samples are ghosts in the truth.
    """

    apart: tuple[float, float] = (0.2, 0.4)
    close: tuple[float, float] = (0.008, 0.04)
    phase_s: tuple[float, float] = (0.8, 2.5)
    close_share: float = 0.5
    bury: float = 0.02
    bury_share: float = 0.7
    synth: SynthConfig | None = None
    prop_markers: int = 0


def synthesize_two_hands(layout: Layout, frames: int, seed: int = 0, config: TwoHandConfig | None = None,
                         rate: float = 120.0) -> tuple[SynthTake, SynthTake, np.ndarray, list]:
    """Two interacting hands of independent sizes, each corrupted as :func:`.generate.synthesize`
    corrupts one hand (camera occlusion, gaps, noise, merges, ghosts), then the right one carried
    along the left one's path by the schedule; markers buried in the other hand are hidden.

    Returns:
        ``(left, right, offset, phases)``: the two synthetic hands in the shared world frame (the
        right one's take and markers moved, buried samples removed from both takes), the right
        hand's per-frame shift ``(F, 3)`` and the schedule's phases ``(start, stop, kind)``.
    """
    cfg = config or TwoHandConfig()
    rng = np.random.default_rng([seed, 22])
    base = replace(cfg.synth or SynthConfig(), rate=rate)
    left = synthesize(layout, frames, seed=2 * seed + 1, config=replace(base, side="left"))
    right = synthesize(layout, frames, seed=2 * seed + 2, config=replace(base, side="right"))
    # The schedule: per phase, where the right hand is relative to the left one.
    direction, centres, nearest, phases = _schedule(rng, frames, rate, cfg)
    shift = _place(left.markers, right.markers, direction, centres, nearest, rate)
    right.markers = right.markers + shift[:, None, :]
    right.take = replace(right.take, positions=(right.take.positions + shift[:, None, :]).astype(np.float32))
    # Markers buried in the other hand while the hands are close: whether a marker is covered is
    # drawn once per phase (a marker pressed into the other hand stays hidden, it does not flicker).
    a, b = left.markers, right.markers
    d = np.linalg.norm(a[:, :, None] - b[:, None, :], axis=3)
    phase = np.zeros(frames, dtype=np.int64)
    for k, (start, stop, _) in enumerate(phases):
        phase[start:stop] = k
    covered = rng.random((len(phases), 2, a.shape[1])) < cfg.bury_share
    buried = [(d.min(axis=2) < cfg.bury) & covered[phase, 0], (d.min(axis=1) < cfg.bury) & covered[phase, 1]]
    for hand, hide in zip((left, right), buried):
        f, k = np.nonzero(hand.labels >= 0)
        gone = hide[f, hand.labels[f, k]]
        positions = hand.take.positions.copy()
        positions[f[gone], k[gone]] = np.nan
        hand.labels = hand.labels.copy()
        hand.labels[f[gone], k[gone]] = EMPTY
        hand.take = replace(hand.take, positions=positions)
    return left, right, shift, phases


def _schedule(rng: np.random.Generator, frames: int, rate: float,
              cfg: TwoHandConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[int, int, str]]]:
    """Per frame: the direction ``(F, 3)`` from the left hand's centre to the right one's, the
    centres' distance ``(F,)`` (NaN where the hands are close) and the nearest markers' distance
    ``(F,)`` (NaN where apart); and the phases ``(start, stop, kind)``."""
    direction = np.zeros((frames, 3))
    centres, nearest = np.full(frames, np.nan), np.full(frames, np.nan)
    phases, t = [], 0
    while t < frames:
        stop = min(frames, t + max(2, int(rng.uniform(*cfg.phase_s) * rate)))
        kind = "apart" if rng.random() >= cfg.close_share else str(rng.choice(PHASES[1:]))
        u = rng.normal(size=3)
        u[2] *= 0.3  # mostly side by side, as hands are held
        u[0] = abs(u[0]) + 0.5  # the right hand starts on the right
        u /= np.linalg.norm(u)
        w = np.linspace(0.0, 1.0, stop - t)[:, None]
        if kind == "cross":  # from one side over to the other, around the left hand
            over = np.array([0.0, 0.0, 1.0])
            angle = np.pi * w
            direction[t:stop] = np.cos(angle) * u + np.sin(angle) * over
        else:
            direction[t:stop] = u
        if kind == "apart":
            centres[t:stop] = rng.uniform(*cfg.apart)
        else:
            nearest[t:stop] = rng.uniform(*cfg.close) * (0.5 if kind == "interlace" else 1.0)
        phases.append((t, stop, kind))
        t = stop
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return direction, centres, nearest, phases


def _place(a: np.ndarray, b: np.ndarray, direction: np.ndarray, centres: np.ndarray, nearest: np.ndarray,
           rate: float) -> np.ndarray:
    """The shift ``(F, 3)`` that puts hand ``b`` (F, M, 3) along ``direction`` from hand ``a``'s
    centre: at ``centres`` between the centres, or where the nearest markers are ``nearest`` apart
    (bisection on the distance along the direction); direction and distance eased over 0.3 s
    between phases (the hand never jumps)."""
    ca, cb = a.mean(axis=1), b.mean(axis=1)
    ease = max(1, int(0.3 * rate))

    def eased(x: np.ndarray) -> np.ndarray:  # a moving mean over 0.3 s: no jump between phases
        padded = np.pad(x, [(ease // 2, ease - 1 - ease // 2)] + [(0, 0)] * (x.ndim - 1), mode="edge")
        return np.stack([np.convolve(padded[:, k], np.ones(ease) / ease, mode="valid")
                         for k in range(x.shape[1])], axis=1) if x.ndim > 1 else \
            np.convolve(padded, np.ones(ease) / ease, mode="valid")

    direction = eased(direction)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    lo, hi = np.zeros(len(a)), np.full(len(a), 0.6)
    close = np.isfinite(nearest)
    for _ in range(24):
        mid = 0.5 * (lo + hi)
        moved = b - cb[:, None] + (ca + mid[:, None] * direction)[:, None]
        gap = np.linalg.norm(a[:, :, None] - moved[:, None], axis=3).reshape(len(a), -1).min(axis=1)
        short = gap < np.where(close, nearest, 0.0)
        lo, hi = np.where(short, mid, lo), np.where(short, hi, mid)
    distance = np.where(close, hi, centres)
    distance = np.maximum(eased(distance), distance * close)
    return ca + distance[:, None] * direction - cb


@dataclass
class TwoHandTake:
    """A raw take of two hands and its truth.

    Attributes:
        take: the unlabeled take (``*N`` slots, metres).
        labels: int16 ``(F, S)``: ``0 .. M-1`` left hand, ``M .. 2M-1`` right hand, ghost -1, empty -2.
        markers: ``(F, 2M, 3)`` true marker positions, left hand first.
        sides: ``["left", "right"]``; hands: the two :class:`.generate.SynthTake` they were made from.
        phases: ``(start, stop, kind)`` of the interaction schedule.
        gap: ``(F,)`` metres: the distance between the nearest markers of the two hands.
        prop_slots: the slots of a held prop's markers (ghosts in ``labels``), if any.
    """

    take: object
    labels: np.ndarray
    markers: np.ndarray
    hands: tuple[SynthTake, SynthTake]
    phases: list
    gap: np.ndarray
    seed: int
    prop_slots: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def layout(self) -> Layout:
        return self.hands[0].layout


def two_hand_take(layout: Layout, frames: int, seed: int = 0, config: TwoHandConfig | None = None,
                  rate: float = 120.0) -> TwoHandTake:
    """A raw take of two interacting hands (see the module's docstring); deterministic in ``seed``."""
    left, right, _, phases = synthesize_two_hands(layout, frames, seed, config, rate)
    m = len(layout)
    positions = np.concatenate([left.take.positions, right.take.positions], axis=1)
    labels = np.concatenate([left.labels, np.where(right.labels >= 0, right.labels + m, right.labels)], axis=1)
    keep = np.isfinite(positions).all(axis=2).any(axis=0)  # slots emptied by burying go
    positions, labels = positions[:, keep], labels[:, keep].astype(np.int16)
    prop_slots = np.zeros(0, dtype=np.int64)
    cfg = config or TwoHandConfig()
    if cfg.prop_markers:
        noise = float(np.mean((cfg.synth or SynthConfig()).noise_sd))
        prop, _ = hold_prop(left.markers, rate, np.random.default_rng([seed, 33]), cfg.prop_markers, noise_sd=noise)
        prop_slots = positions.shape[1] + np.arange(cfg.prop_markers)
        positions = np.concatenate([positions, prop.astype(positions.dtype)], axis=1)
        labels = np.concatenate([labels, np.where(np.isfinite(prop[..., 0]), GHOST, EMPTY).astype(np.int16)], axis=1)
    take = replace(left.take, positions=positions, names=[f"*{i}" for i in range(positions.shape[1])],
                   vendor="mocap_autolabel synth (two hands)")
    a, b = left.markers, right.markers
    d = np.linalg.norm(a[:, :, None] - b[:, None, :], axis=3).reshape(frames, -1)
    return TwoHandTake(take, labels, np.concatenate([a, b], axis=1), (left, right), phases, d.min(axis=1), seed,
                       prop_slots)


def save_two_hands(two: TwoHandTake, path: str | os.PathLike, config: TwoHandConfig | None = None) -> tuple[str, str]:
    """Write the raw take as C3D (``*N``, mm) and its truth beside it (``take.truth.npz``, as
    :func:`.generate.save_synth` does: ``labels`` (F, S), ``markers`` (F, 2M, 3), ``poses``
    (F, 2, 26), ``info`` with the names of both hands' labels (``L_``/``R_``), each hand, the
    seed and the schedule); both atomic and byte-stable."""
    path = os.fspath(path)
    write_c3d(two.take, path)
    naming = HandNaming()
    info = {
        "layout": two.layout.name,
        "hands": 2,
        "names": naming.names("left", two.layout) + naming.names("right", two.layout),
        "labels": {"ghost": GHOST, "empty": EMPTY, "right_hand_from": len(two.layout)},
        "hand": [{"length_m": h.hand.length, "breadth_m": h.hand.breadth, "side": h.hand.side} for h in two.hands],
        "seed": two.seed,
        "rate": two.take.rate,
        "phases": [[int(a), int(b), k] for a, b, k in two.phases],
        "config": dataclasses.asdict(config or TwoHandConfig()),
    }
    arrays = {"labels": two.labels, "markers": two.markers.astype(np.float32),
              "poses": np.stack([h.poses for h in two.hands], axis=1).astype(np.float32),
              "info": np.array(json.dumps(info, sort_keys=True, default=str))}
    return path, write_truth(path, arrays)


__all__ = ["PHASES", "save_two_hands", "TwoHandConfig", "TwoHandTake", "synthesize_two_hands", "two_hand_take"]
