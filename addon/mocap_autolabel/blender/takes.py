"""The take collection the importer made (``scene.build_take``): finding it, reading its take back
from the scene, and the review state stored on it.

The take is read back from the collection's raw empties (or its raw point cloud,
:mod:`.pointcloud`), so a saved .blend is a complete review without the source file. The review
state lives in the collection's custom properties ``mocap_labeling`` (the Labeling's arrays),
``mocap_review`` (the constraints and splits) and ``mocap_settings`` (layout, method...): saved
with the file and restored by undo together with the keys.

Nothing here writes the scene's labeled markers: that is :mod:`.review`.
"""

from __future__ import annotations

import json
import uuid
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.labeling import Labeling
from ..core.layout import Layout, load_layout
from ..core.review import SURE, Review, labeling_from_arrays, labeling_to_arrays
from ..core.take import Take
from . import animio
from .pointcloud import CLOUD, is_cloud, read_cloud

# --- finding the take -----------------------------------------------------------------------

def take_collection(obj_or_collection) -> bpy.types.Collection | None:
    """The imported take collection an object or collection belongs to (or None)."""
    if obj_or_collection is None:
        return None
    if isinstance(obj_or_collection, bpy.types.Collection):
        colls = [obj_or_collection]
    else:
        colls = list(obj_or_collection.users_collection)
    for coll in colls:
        if "mocap_source" in coll:
            return coll
        owner = coll.get("mocap_take")
        if owner is not None and "mocap_source" in owner:
            return owner
    return None


def _raw_objects(take_coll: bpy.types.Collection) -> list[bpy.types.Object]:
    raw = take_coll.get("mocap_raw")
    return list(take_coll.objects) + (list(raw.objects) if raw is not None else [])


def raw_markers(take_coll: bpy.types.Collection) -> list[bpy.types.Object]:
    """The imported (raw) empties of the take, by slot (none for a take imported as a point cloud)."""
    return sorted((o for o in _raw_objects(take_coll)
                   if "mocap_slot" in o and "mocap_label" not in o and "mocap_null" not in o),
                  key=lambda o: o["mocap_slot"])


def raw_cloud(take_coll: bpy.types.Collection) -> bpy.types.Object | None:
    """The take's raw point cloud (:mod:`.pointcloud`), where it was imported as one, else None."""
    return next((o for o in _raw_objects(take_coll) if is_cloud(o)), None)


def first_frame(take_coll: bpy.types.Collection) -> int:
    """The Blender frame of the take's sample 0."""
    return int(take_coll.get("mocap_first", 1))


def read_take(take_coll: bpy.types.Collection) -> Take:
    """The take as the scene holds it, read back from the raw empties' keys (metres), or from the
    raw point cloud's attributes for a take imported as one.

    Slot numbers are the importer's, so labels and constraints keep meaning the same samples.
    """
    scale = float(take_coll.get("mocap_scale", 1.0))
    first = first_frame(take_coll)
    cloud = raw_cloud(take_coll)
    if cloud is not None:
        positions, names = read_cloud(cloud, scale)
        return Take(positions=positions, names=names, rate=float(take_coll.get("mocap_rate", 100.0)),
                    first_frame=first, source=take_coll.get("mocap_source", ""),
                    source_units=str(take_coll.get("mocap_units", "mm")))
    objs = raw_markers(take_coll)
    keyed = []
    last = -1
    for obj in objs:
        curves = [animio.find_fcurve(obj, "location", axis) for axis in range(3)]
        if any(c is None for c in curves):
            keyed.append((obj, None, None))
            continue
        frames, x = animio.read_keys(curves[0])
        xyz = np.stack([x, animio.read_keys(curves[1])[1], animio.read_keys(curves[2])[1]], axis=1)
        idx = np.rint(frames).astype(np.int64) - first
        keyed.append((obj, idx, xyz))
        if len(idx):
            last = max(last, int(idx.max()))
    n_points = (max(int(o["mocap_slot"]) for o in objs) + 1) if objs else 0
    positions = np.full((last + 1, n_points, 3), np.nan, dtype=np.float32)
    names = [f"*{i}" for i in range(n_points)]
    for obj, idx, xyz in keyed:
        slot = int(obj["mocap_slot"])
        names[slot] = obj.get("mocap_point", obj.name)
        if idx is not None:
            positions[idx, slot] = xyz / scale
    return Take(positions=positions, names=names, rate=float(take_coll.get("mocap_rate", 100.0)),
                first_frame=first, source=take_coll.get("mocap_source", ""),
                source_units=str(take_coll.get("mocap_units", "mm")))


def current_take(take_coll: bpy.types.Collection) -> Take:
    """The take of the scene, read once per session (re-read when its raw empties change)."""
    from .session import session

    cache = session(take_coll)
    cloud = raw_cloud(take_coll)
    objs = raw_markers(take_coll) if cloud is None else [cloud]
    key = (len(objs), first_frame(take_coll), float(take_coll.get("mocap_scale", 1.0)),
           sum(len(animio.fcurves_of(o)) for o in objs) if cloud is None
           else (cloud.name, len(cloud.data.vertices), int(cloud[CLOUD])))
    if cache.take is None or cache.take_key != key:
        if not objs:
            from ..core.errors import MocapInputError

            raise MocapInputError(take_coll.name, "the take has no imported marker empties to label")
        cache.take, cache.take_key = read_take(take_coll), key
    return cache.take


def sample_index(take_coll: bpy.types.Collection, frame: int) -> int:
    """The take's sample index (0-based) of a Blender frame."""
    return int(frame) - first_frame(take_coll)


def trajectory_names(take_coll: bpy.types.Collection) -> list[str]:
    """The name of every point slot as the reviewer knows it: the file's point name, ``*N`` where
    the file named none (what messages and the Corrections list say instead of a slot number)."""
    return list(current_take(take_coll).names)


# --- the stored review state ------------------------------------------------------------------

@dataclass
class ReviewState:
    """What the take collection stores: the labeling, the corrections and how labels were made."""

    labeling: Labeling
    review: Review
    layout: str
    method: str
    temporal: str
    token: str = ""


def has_review(take_coll: bpy.types.Collection) -> bool:
    return take_coll is not None and "mocap_labeling" in take_coll


def store_state(take_coll: bpy.types.Collection, state: ReviewState) -> None:
    """Write the state into the collection's custom properties (a new token marks the change)."""
    arrays = labeling_to_arrays(state.labeling)
    take_coll["mocap_labeling"] = {
        "names": "\n".join(arrays.pop("names")), "n_frames": arrays.pop("n_frames"),
        "n_points": arrays.pop("n_points"),
        **{k: np.asarray(v, dtype=np.float64 if k == "confidence" else np.int64).tolist() for k, v in arrays.items()},
    }
    rev = state.review.to_arrays()
    take_coll["mocap_review"] = {k: v.tolist() for k, v in rev.items()}
    state.token = uuid.uuid4().hex
    info = {k: v for k, v in state.labeling.info.items() if isinstance(v, (str, int, float, bool, dict, list))}
    take_coll["mocap_settings"] = {"layout": state.layout, "method": state.method, "temporal": state.temporal,
                                   "token": state.token, "info": json.dumps(info, default=str)}


def load_state(take_coll: bpy.types.Collection) -> ReviewState:
    """The stored state (raises KeyError when the take was never labeled)."""
    data = take_coll["mocap_labeling"]
    settings = take_coll["mocap_settings"]
    arrays = {k: np.asarray(data[k]) for k in ("slot", "start", "stop", "label", "confidence", "locked")}
    if "missing_mm" in data:  # each unlabeled piece's distance to a missing marker; older states lack it
        arrays["missing_mm"] = np.asarray(data["missing_mm"])
    labeling = labeling_from_arrays({**arrays, "names": str(data["names"]).split("\n"),
                                     "n_frames": data["n_frames"], "n_points": data["n_points"]},
                                    info=json.loads(settings.get("info", "{}")))
    rev = take_coll.get("mocap_review") or {}
    review = Review.from_arrays(np.asarray(rev.get("constraints", [])), np.asarray(rev.get("splits", [])))
    return ReviewState(labeling, review, str(settings["layout"]), str(settings["method"]),
                       str(settings["temporal"]), str(settings.get("token", "")))


def state_layout(state: ReviewState) -> Layout:
    return load_layout(state.layout)


def key_sure(take_coll: bpy.types.Collection) -> float:
    """The confidence threshold the take's key colours show (the default before any was stored)."""
    return float(take_coll.get("mocap_sure", SURE))


def scene_sure(scene: bpy.types.Scene | None) -> float:
    """The panel's Confident at (the default where the add-on is not registered: a CLI run)."""
    settings = getattr(scene, "mocap_autolabel", None) if scene is not None else None
    return float(settings.sure) if settings is not None else SURE
