"""Synthetic raw takes with ground truth: the procedural hand, moved, marked, and corrupted.

``synthesize(layout, frames, seed)`` is deterministic: the same arguments give the same arrays,
and :func:`save_synth` writes the same bytes.
"""

from __future__ import annotations

import dataclasses
import heapq
import io
import json
import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..atomic import atomic_output
from ..formats.c3d import write_c3d
from ..hand.skeleton import BONE_NAMES, N_DOF, HandModel, sample_hand_size
from ..hand.skin import Binding, blend, blend_directions
from ..layout import Layout
from ..take import Take
from ..tracklets import mask_runs
from .corrupt import (
    camera_ring,
    camera_visibility,
    fill_short_gaps,
    flicker_ghosts,
    gap_mask,
    merge_close,
    occluder_spheres,
    persistent_ghosts,
)
from .motion import MotionConfig, generate_motion, min_jerk
from .poses import CANONICAL_POSES, sample_joint_angles
from .truth import truth_path

GHOST = -1  #: truth label of a ghost sample
EMPTY = -2  #: truth label where a slot has no sample


@dataclass(frozen=True)
class SynthConfig:
    """Every knob of the generator, with defaults tuned against the real recordings
    (see ``benchmarks/synth_realism.py``). Lengths in metres, times in seconds.

    Set a ``*_per_*`` rate or count to 0 (or a flag to False) to switch that corruption off.
    """

    rate: float = 120.0
    side: str | None = None  # "left", "right", or None for either at random
    sex: str | None = None  # ANSUR population for the hand size; None: either at random
    hand_size: tuple[float, float] | None = None  # (length, breadth) to fix the size
    # The back of the hand within 90 degrees of up, as performers mostly hold it (180: any way).
    motion: MotionConfig = field(default_factory=lambda: MotionConfig(max_tilt_deg=90.0))
    # self-contact: the thumb's pad held on a finger (pinches, grasps), eased in and out over
    # 0.15 s; per-take rate drawn from this (off by default: the shipped models and benchmarks
    # were made without it)
    contacts_per_minute: tuple[float, float] = (0.0, 0.0)
    contact_s: tuple[float, float] = (0.5, 3.0)
    # marker misplacement, per take (see :func:`misplacement`): the glove's markers sit off the
    # layout's spots. Off by default; drawn from its own random stream, so that switching it on
    # changes nothing else about a take.
    placement_sd: float = 0.0
    tip_convergence: float = 0.0
    # noise and slip
    noise_sd: tuple[float, float] = (0.0005, 0.0015)  # per-take SD drawn from this range
    slip: tuple[float, float] = (0.002, 0.003)  # per-take, per-marker offset along the skin
    # occlusion
    cameras: bool = True
    camera_count: tuple[int, int] = (8, 16)
    min_views: int = 2
    max_view_angle_deg: float = 85.0  # a raised spherical marker is seen a little past 80 degrees
    random_gaps_per_minute: tuple[float, float] = (0.0, 1.0)  # per marker; per-take rate drawn from this
    mean_gap_s: float = 0.25
    fill_gaps_s: float = 0.15  # gaps this short are bridged, as capture software does on export (the
    # real glove recording has no gap under 0.19 s)
    # merges
    merges: bool = True
    # ghosts
    flicker_ghosts_per_frame: tuple[float, float] = (0.0, 1.5)
    ghost_spread: float = 0.05
    ghost_box: float = 0.3
    ghost_box_share: float = 0.3
    ghost_mean_frames: float = 4.0
    persistent_ghosts: tuple[int, int] = (0, 2)
    persistent_ghost_s: tuple[float, float] = (1.0, 10.0)
    persistent_ghost_distance: tuple[float, float] = (0.08, 0.25)


def clean_config() -> SynthConfig:
    """No corruption at all: every marker in every frame, exactly on the hand."""
    return SynthConfig(noise_sd=(0.0, 0.0), slip=(0.0, 0.0), cameras=False, random_gaps_per_minute=(0.0, 0.0),
                       fill_gaps_s=0.0,
                       merges=False, flicker_ghosts_per_frame=(0.0, 0.0), persistent_ghosts=(0, 0))


@dataclass
class SynthTake:
    """A synthetic take and everything true about it.

    Attributes:
        take: the unlabeled take (``*N`` slots, metres, NaN where missing).
        labels: int16 ``(F, S)`` truth per slot and frame: the layout index, :data:`GHOST` or :data:`EMPTY`.
        layout: the layout the markers follow.
        hand: the hand that moved.
        poses: ``(F, 26)`` pose vectors.
        markers: ``(F, M, 3)`` true marker centres (with slip, without noise or occlusion), metres.
        seed: the seed it was made from.
        config: the settings it was made with.
    """

    take: Take
    labels: np.ndarray
    layout: Layout
    hand: HandModel
    poses: np.ndarray
    markers: np.ndarray
    seed: int
    config: SynthConfig


def synthesize(layout: Layout, frames: int, seed: int = 0, config: SynthConfig | None = None) -> SynthTake:
    """Generate one synthetic unlabeled take of a hand wearing ``layout``.

    Args:
        layout: the marker layout.
        frames: number of frames.
        seed: random seed; the only source of randomness.
        config: the generator's settings (defaults: realistic corruption).
    """
    if frames < 1:
        raise ValueError(f"frames must be positive, got {frames}")
    cfg = config or SynthConfig()
    rng = np.random.default_rng(seed)
    length, breadth = cfg.hand_size or sample_hand_size(rng, cfg.sex)
    side = cfg.side or ("left" if rng.random() < 0.5 else "right")
    hand = HandModel(length=length, breadth=breadth, side=side)

    poses = generate_motion(rng, frames, cfg.rate, cfg.motion)
    if cfg.contacts_per_minute[1] > 0:  # its own random stream: takes without contacts stay as they were
        add_contacts(np.random.default_rng([seed, 1]), hand, poses, cfg.rate, cfg.contacts_per_minute, cfg.contact_s)
    binding, normals = layout.place(hand)
    binding = _slip(rng, binding, normals, cfg.slip)
    binding = binding.moved(misplacement(np.random.default_rng([seed, 2]), binding, hand, cfg.placement_sd,
                                         cfg.tip_convergence))  # zeros when off
    skin_r, skin_t = (a.astype(np.float32) for a in hand.skinning_transforms(poses))  # float32: speed
    markers = blend(skin_r, skin_t, binding).astype(np.float64)  # (F, M, 3)
    n_markers = markers.shape[1]

    # Occlusion: camera model and random gaps in runs.
    missing = np.zeros((frames, n_markers), dtype=bool)
    centre = markers.mean(axis=1)
    if cfg.cameras:
        world_normals = blend_directions(skin_r, binding, normals)
        sphere_binding, radii = occluder_spheres(hand)
        spheres = blend(skin_r, skin_t, sphere_binding)
        volume_centre = 0.5 * (np.array(cfg.motion.volume_min) + np.array(cfg.motion.volume_max))
        cams = camera_ring(rng, volume_centre, cfg.camera_count)
        missing |= ~camera_visibility(markers, world_normals, spheres, radii, cams, cfg.min_views,
                                      cfg.max_view_angle_deg)
    gap_rate = rng.uniform(*cfg.random_gaps_per_minute) / 60.0 / cfg.rate
    if gap_rate > 0:
        missing |= gap_mask(rng, frames, n_markers, gap_rate, cfg.mean_gap_s * cfg.rate)
    missing = fill_short_gaps(missing, int(round(cfg.fill_gaps_s * cfg.rate)))

    sd = rng.uniform(*cfg.noise_sd)
    observed = markers + rng.normal(0.0, sd, size=markers.shape) if sd > 0 else markers.copy()
    observed[missing] = np.nan
    if cfg.merges:
        diameter = 2 * min(m.radius for m in layout.markers)
        observed, _ = merge_close(observed, diameter)

    # Ghosts.
    hand_rot = skin_r[:, 0].astype(np.float64)  # the palm's rest frame is the hand frame
    tracks = [observed]
    track_labels = list(range(n_markers))
    n_persistent = int(rng.integers(cfg.persistent_ghosts[0], cfg.persistent_ghosts[1] + 1))
    if n_persistent:
        dur = (int(cfg.persistent_ghost_s[0] * cfg.rate), int(cfg.persistent_ghost_s[1] * cfg.rate))
        pg = persistent_ghosts(rng, centre, hand_rot, n_persistent, dur, cfg.persistent_ghost_distance)
        pg[gap_mask(rng, frames, n_persistent, 2.0 / cfg.rate, cfg.mean_gap_s * cfg.rate)] = np.nan
        if sd > 0:
            pg += rng.normal(0.0, sd, size=pg.shape)
        tracks.append(pg)
        track_labels += [GHOST] * n_persistent
    flicker_rate = rng.uniform(*cfg.flicker_ghosts_per_frame)
    flicker = []
    if flicker_rate > 0:
        flicker = flicker_ghosts(rng, centre, hand_rot, flicker_rate, cfg.ghost_spread, cfg.ghost_box,
                                 cfg.ghost_box_share, cfg.ghost_mean_frames, max(sd, 1e-4))

    positions, labels = _pack(rng, np.concatenate(tracks, axis=1), np.array(track_labels), flicker)
    take = Take(positions=positions, names=[f"*{i}" for i in range(positions.shape[1])], rate=cfg.rate,
                first_frame=1, source_units="m", vendor="mocap_autolabel synth")
    return SynthTake(take, labels, layout, hand, poses, markers, seed, cfg)


#: Sideways shift of each finger's markers (index to little) per unit of ``tip_convergence``,
#: towards the thumb: the fingertips close in on a point between the index and the middle finger.
_CONVERGENCE = {"index": -0.5, "middle": 0.3, "ring": 0.65, "little": 1.0}


def misplacement(rng: np.random.Generator, binding: Binding, hand: HandModel, sd: float,
                 convergence: float) -> np.ndarray:
    """Rest-frame offsets ``(M, 3)`` metres of one hand's markers: each moved by a Gaussian offset of
    ``sd`` per axis (doubled on the distal phalanges), and the finger markers moved sideways towards
    the middle of the hand by up to ``convergence`` at the little fingertip (less on the other
    fingers, half on the middle phalanges). Glove markers sit where the glove sits, not where the
    layout says, and the fingertips of real hands and gloves bunch together, most visibly in a fist."""
    out = np.zeros_like(binding.rest)
    if sd <= 0 and convergence <= 0:
        return out
    bone = np.array(BONE_NAMES)[binding.bones[:, 0]]
    distal = np.char.endswith(bone, "_dist")
    out += sd * rng.standard_normal(out.shape) * np.where(distal, 2.0, 1.0)[:, None]
    level = rng.uniform(-0.25, 1.0) * convergence
    for f, w in _CONVERGENCE.items():
        share = np.where(bone == f"{f}_dist", 1.0, np.where(bone == f"{f}_mid", 0.5, 0.0))
        out[:, 0] += hand.thumb_side * w * level * share
    return out


def _slip(rng: np.random.Generator, binding: Binding, normals: np.ndarray, slip: tuple[float, float]) -> Binding:
    """Move each marker 2-3 mm along the skin in a random direction, once per take (placement error)."""
    if slip[1] <= 0:
        return binding
    d = rng.standard_normal(normals.shape)
    d -= np.sum(d * normals, axis=1, keepdims=True) * normals  # tangent to the skin
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    amount = rng.uniform(*slip, size=(len(normals), 1))
    return binding.moved(d * amount)


def _pack(rng: np.random.Generator, tracks: np.ndarray, track_labels: np.ndarray,
          flicker: list[tuple[int, np.ndarray]], breaks: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cut every track at its gaps and lay the runs into ``*N`` slots, as a capture system would.

    ``track_labels`` is ``(T,)`` (one label per track) or ``(F, T)`` (per frame: a track whose
    identity changes, a swap). ``breaks`` bool ``(F, T)`` also ends a run before each True frame
    (a trajectory broken without a gap). Every run starts a new trajectory. To keep files small a
    slot is reused once its previous run has ended (with at least one empty frame between), so a
    slot can hold several runs; the runs are laid in order of their start, ties in random order,
    so slot order says nothing about labels.

    Returns:
        positions float32 ``(F, S, 3)`` and truth labels int16 ``(F, S)``.
    """
    frames = tracks.shape[0]
    present = ~np.isnan(tracks[..., 0])
    if breaks is not None:  # a one-frame hole in a doubled time axis splits the run there
        doubled = np.zeros((2 * frames, tracks.shape[1]), dtype=bool)
        doubled[0::2] = present
        doubled[1::2] = present
        doubled[1:-1:2] &= ~breaks[1:]
        run_track, run_start, run_stop = mask_runs(doubled)
        run_start, run_stop = (run_start + 1) // 2, (run_stop + 1) // 2
    else:
        run_track, run_start, run_stop = mask_runs(present)
    truth = np.broadcast_to(track_labels, (frames, tracks.shape[1]))
    n_tracks = len(run_track)
    starts = np.concatenate([run_start, [a for a, _ in flicker]]).astype(np.int64)
    stops = np.concatenate([run_stop, [a + len(p) for a, p in flicker]]).astype(np.int64)
    order = np.lexsort((rng.random(len(starts)), starts))
    slot_of = np.empty(len(starts), dtype=np.int64)
    free: list[tuple[int, int]] = []  # (frame from which the slot is free, slot)
    n_slots = 0
    for i in order:
        if free and free[0][0] < starts[i]:
            _, slot = heapq.heappop(free)
        else:
            slot, n_slots = n_slots, n_slots + 1
        slot_of[i] = slot
        heapq.heappush(free, (int(stops[i]), slot))
    positions = np.full((frames, n_slots, 3), np.nan, dtype=np.float32)
    labels = np.full((frames, n_slots), EMPTY, dtype=np.int16)
    for i in range(len(starts)):
        a, b, slot = starts[i], stops[i], slot_of[i]
        if i < n_tracks:
            positions[a:b, slot] = tracks[a:b, run_track[i]]
            labels[a:b, slot] = truth[a:b, run_track[i]]
        else:
            positions[a:b, slot] = flicker[i - n_tracks][1]
            labels[a:b, slot] = GHOST
    return positions, labels


def save_synth(synth: SynthTake, path: str | os.PathLike) -> tuple[str, str]:
    """Write the take as C3D (``*N`` names, mm) and its truth beside it; both atomic and byte-stable.

    The truth file is an ``.npz`` (``numpy.load``) with ``labels`` (F, S) int16, ``markers``
    (F, M, 3) float32 metres, ``poses`` (F, 26) float32 and ``info``, a JSON string with the
    layout's marker names, the hand, the seed and the generator settings.

    Returns:
        the paths written (take, truth).
    """
    path = os.fspath(path)
    write_c3d(synth.take, path)
    info = {
        "layout": synth.layout.name,
        "names": synth.layout.names,
        "labels": {"ghost": GHOST, "empty": EMPTY},
        "hand": {"length_m": synth.hand.length, "breadth_m": synth.hand.breadth, "side": synth.hand.side},
        "seed": synth.seed,
        "rate": synth.take.rate,
        "config": dataclasses.asdict(synth.config),
    }
    arrays = {
        "labels": synth.labels,
        "markers": synth.markers.astype(np.float32),
        "poses": synth.poses.astype(np.float32),
        "info": np.array(json.dumps(info, sort_keys=True)),
    }
    return path, write_truth(path, arrays)


def write_truth(take_path: str, arrays: dict[str, np.ndarray]) -> str:
    """Write the truth sidecar of ``take_path`` (atomic and byte-stable); returns its path."""
    out = truth_path(take_path)
    with atomic_output(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for key, arr in arrays.items():
            # A fixed timestamp: numpy.savez stamps the current time, which breaks byte-identity.
            entry = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            entry.compress_type = zipfile.ZIP_DEFLATED
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
            z.writestr(entry, buf.getvalue())
    return out


@dataclass(frozen=True)
class TakeCorruption:
    """How :func:`corrupt_take` turns clean labeled marker tracks into a raw take (rates per
    marker unless said otherwise; times in seconds, lengths in metres)."""

    gaps_per_minute: float = 10.0  # run-length occlusions
    mean_gap_s: float = 0.25
    fragments_per_minute: float = 3.0  # trajectory broken without a gap (a new *N slot)
    swap_share: float = 0.3  # share of takes in which the two markers that pass closest trade trajectories
    swap_distance: float = 0.02  # ...if they come this close
    flicker_ghosts_per_frame: float = 1.0  # per take
    ghost_mean_frames: float = 4.0
    persistent_ghosts: int = 1  # per take, 1-3 s long
    noise_sd: float = 0.0


def corrupt_take(markers: np.ndarray, rate: float, seed: int, cfg: TakeCorruption | None = None,
                 extra: np.ndarray | None = None) -> tuple[Take, np.ndarray, dict]:
    """A raw take from clean labeled tracks, with gaps, fragments, swaps and ghost tracklets.

    Args:
        markers: ``(F, M, 3)`` true marker positions in metres (NaN where truly missing).
        rate: frames per second.
        seed: random seed.
        cfg: the corruption.
        extra: optional ``(F, E, 3)`` tracks of other markers (body, objects): kept as distractors.

    Returns:
        the take (``*N`` slots), the truth int16 ``(F, S)`` (label, :data:`GHOST` or :data:`EMPTY`)
        and facts about what was done (swaps).
    """
    cfg = cfg or TakeCorruption()
    rng = np.random.default_rng(seed)
    frames, m, _ = markers.shape
    tracks = np.array(markers, dtype=np.float64)
    truth = np.broadcast_to(np.arange(m), (frames, m)).copy()
    facts = {"swaps": 0}
    if rng.random() < cfg.swap_share and frames > 2:
        d = np.linalg.norm(tracks[:, :, None] - tracks[:, None, :], axis=3)
        d[:, np.arange(m), np.arange(m)] = np.inf
        d = np.where(np.isnan(d), np.inf, d)
        f, a, b = np.unravel_index(np.argmin(d[1:-1]), d[1:-1].shape)
        f += 1
        if d[f, a, b] < cfg.swap_distance:
            tracks[f:, [a, b]] = tracks[f:, [b, a]]
            truth[f:, [a, b]] = truth[f:, [b, a]]
            facts["swaps"] = 1
    missing = gap_mask(rng, frames, m, cfg.gaps_per_minute / 60.0 / rate, cfg.mean_gap_s * rate)
    tracks[missing] = np.nan
    if cfg.noise_sd > 0:
        tracks += rng.normal(0.0, cfg.noise_sd, size=tracks.shape)
    centre = np.nanmean(markers, axis=1)
    centre = np.where(np.isnan(centre), np.nanmean(centre, axis=0), centre)
    eye = np.broadcast_to(np.eye(3), (frames, 3, 3))
    parts, labels = [tracks], [truth]
    if cfg.persistent_ghosts:
        dur = (int(1.0 * rate), int(3.0 * rate))
        parts.append(persistent_ghosts(rng, centre, eye, cfg.persistent_ghosts, dur, (0.08, 0.25)))
        labels.append(np.full((frames, cfg.persistent_ghosts), GHOST))
    if extra is not None:
        parts.append(np.asarray(extra, dtype=np.float64))
        labels.append(np.full((frames, extra.shape[1]), GHOST))
    flicker = []
    if cfg.flicker_ghosts_per_frame > 0:
        flicker = flicker_ghosts(rng, centre, eye, cfg.flicker_ghosts_per_frame, 0.05, 0.3, 0.3,
                                 cfg.ghost_mean_frames, 1e-4)
    all_tracks = np.concatenate(parts, axis=1)
    breaks = gap_mask(rng, frames, all_tracks.shape[1], cfg.fragments_per_minute / 60.0 / rate, 1.0)
    positions, truth_slots = _pack(rng, all_tracks, np.concatenate(labels, axis=1), flicker, breaks)
    take = Take(positions=positions, names=[f"*{i}" for i in range(positions.shape[1])], rate=rate,
                source_units="mm", vendor="mocap_autolabel corrupt_take")
    return take, truth_slots, facts


#: Joint angles (20,) of the flat hand that range-of-motion takes start with, radians.
FLAT_HAND = CANONICAL_POSES["flat"]


def marker_motion(layout: Layout, hand: HandModel, frames: int, seed: int, noise: float = 0.0,
                  offsets: np.ndarray | None = None, flat_frames: int = 0, rate: float = 120.0,
                  pinches: Sequence[tuple[int, str]] = ()) -> tuple[np.ndarray, np.ndarray]:
    """A labeled marker track of ``hand`` moving at random: what IK and calibration are checked on.

    Args:
        offsets: ``(M, 3)`` marker displacements from the layout positions (rest hand frame, metres).
        flat_frames: the motion starts with this many frames of :data:`FLAT_HAND`.
        noise: standard deviation per axis, metres.
        pinches: ``(frame, finger)``: that frame's pose is bent until the thumb's palmar pad
            touches the finger's (:func:`pinch`).

    Returns:
        poses ``(F, 26)`` and markers ``(F, M, 3)`` in layout order, metres.
    """
    rng = np.random.default_rng(seed)
    poses = generate_motion(rng, frames, rate)
    poses[:flat_frames, 6:] = FLAT_HAND
    for frame, finger in pinches:
        poses[frame] = pinch(hand, poses[frame], finger)
    binding = layout.place(hand)[0]
    if offsets is not None:
        binding = binding.moved(offsets)
    markers = blend(*hand.skinning_transforms(poses), binding)
    return poses, markers + rng.normal(0.0, noise, markers.shape) if noise > 0 else markers


def add_contacts(rng: np.random.Generator, hand: HandModel, poses: np.ndarray, rate: float,
                 per_minute: tuple[float, float], duration_s: tuple[float, float]) -> list[tuple[int, int, str]]:
    """Bend ``poses (F, 26)`` in place so that the thumb's pad rests on a finger for a while: on
    the distal or middle phalanx of the index, middle, ring or little finger, palmar or on its
    thumb side, eased in and out over 0.15 s. A thumb tip held on a finger reads frame after
    frame as that finger's marker; real takes are full of such pinches and grasps.

    Returns ``(start, stop, finger)`` of each contact.
    """
    frames = len(poses)
    count = rng.poisson(rng.uniform(*per_minute) * frames / rate / 60.0)
    ease = max(1.0, 0.15 * rate)
    out = []
    for _ in range(count):
        length = max(2, int(rng.uniform(*duration_s) * rate))
        start = int(rng.integers(0, max(1, frames - length)))
        idx = np.arange(start, min(frames, start + length))
        finger = str(rng.choice(["index", "middle", "ring", "little"]))
        bone = str(rng.choice(["dist", "mid"]))
        along, angle = rng.uniform(0.3, 0.9), rng.uniform(np.pi / 2, np.pi)
        key = np.unique(np.append(idx[::4], idx[-1]))  # solved every 4th frame, interpolated between
        bent = touch(hand, poses[key], finger, bone, along, angle, steps=15)[0]
        full = np.stack([np.interp(idx, key, bent[:, d]) for d in range(6, poses.shape[1])], axis=1)
        w = min_jerk(np.clip(np.minimum(idx - start + 1, idx[-1] - idx + 1) / ease, 0.0, 1.0))[:, None]
        poses[idx, 6:] = (1.0 - w) * poses[idx, 6:] + w * full
        out.append((int(idx[0]), int(idx[-1]) + 1, finger))
    return out


def pinch(hand: HandModel, pose: np.ndarray, finger: str, steps: int = 40) -> np.ndarray:
    """``pose (26,)`` bent (thumb and ``finger`` joints only) until the palmar pads of the thumb and
    finger tips touch: pads at 60 % of each distal phalanx, on the skin."""
    return touch(hand, np.asarray(pose, dtype=float)[None], finger, steps=steps)[0][0]


def touch(hand: HandModel, poses: np.ndarray, finger: str, bone: str = "dist", along: float = 0.6,
          angle: float = np.pi, steps: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """``poses (N, 26)`` bent (thumb and ``finger`` joints only) until the thumb's palmar pad (60 %
    of its distal phalanx) touches ``finger``'s ``bone`` (``"dist"`` or ``"mid"``) at ``along``
    of its length and ``angle`` around it (pi palmar, pi/2 its thumb side; see ``skin_point``).

    Returns:
        The bent poses ``(N, 26)`` and the gap left between the two pads ``(N,)`` metres: a pose
        whose joint limits keep the two apart gets as close as they allow (about 1 in 6 random
        starts for the little finger's tip, 1 in 50 for the index's).
    """
    from ..hand.ik import HandSolver
    from ..hand.skeleton import BONE_INDEX, JOINT_NAMES
    from ..hand.skin import segment_weights, skin_point

    bones = np.array([BONE_INDEX["thumb_dist"], BONE_INDEX[f"{finger}_{bone}"]])
    rest = np.array([skin_point(hand, bones[0], 0.6, np.pi)[0], skin_point(hand, bones[1], along, angle)[0]])
    solver = HandSolver(hand, Binding(rest, *segment_weights(bones, np.array([0.6, along]))))
    free = np.array([6 + i for i, n in enumerate(JOINT_NAMES) if n.startswith(("thumb", finger))])
    out = np.array(poses, dtype=float)
    for _ in range(steps):
        pads = solver.markers(out)
        target = np.repeat(pads.mean(axis=1, keepdims=True), 2, axis=1)
        moved = solver.refine(out, target, 3)[0]
        out[:, free] = moved[:, free]  # only the two digits bend; the hand stays where it was
    pads = solver.markers(out)
    return out, np.linalg.norm(pads[:, 0] - pads[:, 1], axis=1)


def pose_samples(layout: Layout, n: int, seed: int = 0, side: str = "right") -> np.ndarray:
    """The layout's markers ``(n, M, 3)`` (metres, layout order, hand frame, no noise) on the model's
    average hand in ``n`` independent poses drawn as the training frames draw them
    (:func:`.poses.sample_joint_angles`): the whole range of every joint, not one motion through it."""
    hand = HandModel(side=side)
    poses = np.zeros((n, N_DOF))
    poses[:, 6:] = sample_joint_angles(np.random.default_rng(seed), n)
    return blend(*hand.skinning_transforms(poses), layout.place(hand)[0])
