"""A raw take as one point cloud driven by geometry nodes: no keys, for very long takes.

The take's F frames x S imported point slots become one mesh of F x S vertices, frame-major
(vertex ``f * S + c`` is column ``c`` at sample ``f``), written in bulk through the ``position``
attribute, with a boolean ``valid`` attribute (False where the file has no sample; the
position there is 0). A geometry-nodes modifier (:func:`node_group`) keeps the S points of the
scene's current frame and deletes the invalid ones, so a missing marker is not shown; its output
points carry the integer attribute ``marker`` (the column) and a radius. The object keeps the
columns' point names and slot numbers (``mocap_names``, ``mocap_slots``), so the take can be
read back exactly from the .blend alone (:func:`read_cloud`), saved and reopened, labeled and
reviewed like a take of keyed empties. Labeled markers stay keyed empties.

Measured with benchmarks/import_speed.py: see benchmarks/reports/import_speed.md.
"""

from __future__ import annotations

import bpy
import numpy as np

from ..core.take import Take
from .names import free_name

#: Object property that marks a take's raw point cloud (its value: the number of columns S).
CLOUD = "mocap_cloud"
#: The shared geometry-nodes group; ``GROUP_VERSION`` is stored on it, so that a later version of
#: the add-on builds its own group instead of reusing an older one.
GROUP_NAME = "Mocap Raw Markers"
GROUP_VERSION = 1
#: The object's name (a later take whose name is taken gets its collection's name as a prefix).
CLOUD_NAME = "Raw markers"
#: Sphere radius of the shown points, in metres (times the import's Scale): a hand marker's.
POINT_RADIUS = 0.004


def is_cloud(obj) -> bool:
    return obj is not None and CLOUD in obj and obj.type == "MESH"


def build_cloud(take: Take, slots: np.ndarray, collection: bpy.types.Collection, scale: float,
                first: int) -> bpy.types.Object:
    """The point-cloud object of ``take``'s ``slots`` (positions times ``scale``), sample 0 at
    Blender frame ``first``, linked to ``collection``."""
    slots = np.asarray(slots, dtype=np.int64)
    n_f, n_s = take.n_frames, len(slots)
    if n_s == take.n_points and (n_s == 0 or (slots == np.arange(n_s)).all()):
        pos = np.array(take.positions, dtype=np.float32)  # a copy: it is scaled and zeroed in place
    else:
        pos = take.positions[:, slots]  # fancy indexing copies
    valid = ~np.isnan(pos[..., 0])
    if scale != 1.0:
        pos *= np.float32(scale)
    pos[~valid] = 0.0
    mesh = bpy.data.meshes.new(free_name(CLOUD_NAME, bpy.data.meshes, collection.name))
    mesh.vertices.add(n_f * n_s)
    # The position attribute takes a flat float32 buffer about 70x faster than vertices' "co".
    mesh.attributes["position"].data.foreach_set("vector", pos.reshape(-1))
    del pos
    mesh.attributes.new("valid", "BOOLEAN", "POINT").data.foreach_set("value", valid.reshape(-1))
    obj = bpy.data.objects.new(free_name(CLOUD_NAME, bpy.data.objects, collection.name), mesh)
    obj[CLOUD] = n_s
    obj["mocap_slots"] = [int(s) for s in slots]
    obj["mocap_names"] = [take.names[int(s)] for s in slots]
    obj["mocap_n_points"] = int(take.n_points)
    collection.objects.link(obj)
    mod = obj.modifiers.new("Markers", "NODES")
    mod.node_group = node_group()
    _set_input(mod, "Markers", n_s)
    _set_input(mod, "First Frame", int(first))
    _set_input(mod, "Radius", float(POINT_RADIUS * scale))
    return obj


def read_cloud(obj: bpy.types.Object, scale: float) -> tuple[np.ndarray, list[str]]:
    """(positions ``(F, n_points, 3)`` float32 in metres, NaN where missing; the point names) of a
    take's point cloud: the slots it holds at their slot numbers, any other slot all missing and
    named ``*N`` (as a take of keyed empties reads back)."""
    mesh = obj.data
    n_s = int(obj[CLOUD])
    n = len(mesh.vertices)
    n_f = n // n_s if n_s else 0
    pos = np.empty(n * 3, dtype=np.float32)
    mesh.attributes["position"].data.foreach_get("vector", pos)
    valid = np.empty(n, dtype=bool)
    mesh.attributes["valid"].data.foreach_get("value", valid)
    pos = pos.reshape(n_f, n_s, 3)
    pos[~valid.reshape(n_f, n_s)] = np.nan
    if scale != 1.0:
        pos /= np.float32(scale)
    slots = [int(s) for s in obj["mocap_slots"]]
    names_by_column = list(obj["mocap_names"])
    n_points = max([int(obj.get("mocap_n_points", 0))] + [s + 1 for s in slots])
    names = [f"*{i}" for i in range(n_points)]
    for c, slot in enumerate(slots):
        names[slot] = str(names_by_column[c])
    if slots == list(range(n_points)):
        return pos, names
    positions = np.full((n_f, n_points, 3), np.nan, dtype=np.float32)
    positions[:, slots] = pos
    return positions, names


def _set_input(mod, name: str, value) -> None:
    """Set the modifier's input socket ``name`` (inputs are keyed by identifier since Blender 4.0)."""
    for item in mod.node_group.interface.items_tree:
        if getattr(item, "in_out", None) == "INPUT" and item.name == name:
            mod[item.identifier] = value
            return
    raise KeyError(name)


def node_group() -> bpy.types.NodeTree:
    """The geometry-nodes group that shows a point cloud's current frame (made once per file).

    Inputs: the F x S vertices, ``Markers`` (S), ``First Frame`` (the Blender frame of sample 0)
    and ``Radius``. Output: S points at the positions of sample ``round(frame) - First Frame``
    (Sample Index at ``index + sample * S``), those not valid deleted; out of the take's range no
    point at all.
    """
    for group in bpy.data.node_groups:
        if group.get("mocap_cloud_version") == GROUP_VERSION and group.bl_idname == "GeometryNodeTree":
            return group
    ng = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    ng["mocap_cloud_version"] = GROUP_VERSION
    iface = ng.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    iface.new_socket("Markers", in_out="INPUT", socket_type="NodeSocketInt")
    iface.new_socket("First Frame", in_out="INPUT", socket_type="NodeSocketInt")
    iface.new_socket("Radius", in_out="INPUT", socket_type="NodeSocketFloat")
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = ng.nodes, ng.links
    gin = nodes.new("NodeGroupInput")
    gout = nodes.new("NodeGroupOutput")
    gout.location = (1200, 0)

    def node(kind: str, x: float, y: float, **attrs):
        n = nodes.new(kind)
        n.location = (x, y)
        for key, value in attrs.items():
            setattr(n, key, value)
        return n

    time = node("GeometryNodeInputSceneTime", 0, -300)
    to_int = node("FunctionNodeFloatToInt", 150, -300, rounding_mode="ROUND")
    links.new(time.outputs["Frame"], to_int.inputs[0])
    index = node("GeometryNodeInputIndex", 150, -450)
    # sample * S + index, in integers where Blender has Integer Math (4.3+); float math elsewhere
    # is exact up to 2**24 samples (F x S), e.g. 216,000 frames x 77 markers.
    if hasattr(bpy.types, "FunctionNodeIntegerMath"):
        def math(op: str, x: float, y: float):
            return node("FunctionNodeIntegerMath", x, y, operation=op)
    else:
        def math(op: str, x: float, y: float):
            return node("ShaderNodeMath", x, y, operation=op)
    sample = math("SUBTRACT", 300, -300)
    links.new(to_int.outputs[0], sample.inputs[0])
    links.new(gin.outputs["First Frame"], sample.inputs[1])
    offset = math("MULTIPLY", 450, -300)
    links.new(sample.outputs[0], offset.inputs[0])
    links.new(gin.outputs["Markers"], offset.inputs[1])
    at = math("ADD", 600, -300)
    links.new(offset.outputs[0], at.inputs[0])
    links.new(index.outputs[0], at.inputs[1])

    position = node("GeometryNodeInputPosition", 600, 100)
    take_pos = node("GeometryNodeSampleIndex", 750, 100, data_type="FLOAT_VECTOR", domain="POINT")
    links.new(gin.outputs["Geometry"], take_pos.inputs["Geometry"])
    links.new(position.outputs[0], take_pos.inputs["Value"])
    links.new(at.outputs[0], take_pos.inputs["Index"])
    valid = node("GeometryNodeInputNamedAttribute", 600, -100, data_type="BOOLEAN")
    valid.inputs["Name"].default_value = "valid"
    take_valid = node("GeometryNodeSampleIndex", 750, -100, data_type="BOOLEAN", domain="POINT")
    links.new(gin.outputs["Geometry"], take_valid.inputs["Geometry"])
    links.new(valid.outputs["Attribute"], take_valid.inputs["Value"])
    links.new(at.outputs[0], take_valid.inputs["Index"])

    points = node("GeometryNodePoints", 900, 200)
    links.new(gin.outputs["Markers"], points.inputs["Count"])
    links.new(take_pos.outputs[0], points.inputs["Position"])
    links.new(gin.outputs["Radius"], points.inputs["Radius"])
    column = node("GeometryNodeStoreNamedAttribute", 1000, 200, data_type="INT", domain="POINT")
    column.inputs["Name"].default_value = "marker"
    links.new(points.outputs[0], column.inputs["Geometry"])
    links.new(index.outputs[0], column.inputs["Value"])
    hide = node("FunctionNodeBooleanMath", 900, -100, operation="NOT")
    links.new(take_valid.outputs[0], hide.inputs[0])
    delete = node("GeometryNodeDeleteGeometry", 1100, 100, domain="POINT")
    links.new(column.outputs[0], delete.inputs["Geometry"])
    links.new(hide.outputs[0], delete.inputs["Selection"])
    links.new(delete.outputs[0], gout.inputs["Geometry"])
    return ng
