"""Marker layouts: which markers a glove or marker set has, and where each sits on the hand.

A layout is data, a TOML file a user can write without touching code::

    name = "my_glove"
    description = "tips and back of the hand"
    radius_mm = 3.0        # marker radius (default for every marker)
    glove_mm = 1.0         # glove or tape between skin and marker base

    [[markers]]
    name = "IndexTip"
    bone = "index_dist"    # one of mocap_autolabel.core.hand.BONE_NAMES
    along = 0.7            # fraction of the bone's length from its proximal joint
    side = "dorsal"        # dorsal | palmar | radial (thumb side) | ulnar, or angle_deg = 30

    [[markers]]
    name = "BackOfHand"
    bone = "palm"
    along = 0.25           # palm markers: fraction of HAND LENGTH from the wrist
    across = -0.1          # and fraction of HAND BREADTH to the thumb side
    side = "dorsal"

    [[markers]]
    name = "Ring"
    bone = "ring_prox"
    offset_mm = [0, 20, 12]  # or an explicit offset in the bone's frame (x to the thumb side)

Placement scales with the hand: ``along``/``across`` are fractions, the height above the skin is
the marker radius plus the glove. Only ``offset_mm`` is absolute.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from importlib import resources

import numpy as np

from .errors import MocapInputError
from .hand.skeleton import BONE_INDEX, BONE_NAMES, PALM_HALF_THICKNESS_HB, HandModel
from .hand.skin import Binding, segment_weights, skin_point

SIDES_DEG = {"dorsal": 0.0, "radial": 90.0, "palmar": 180.0, "ulnar": -90.0}


@dataclass(frozen=True)
class Marker:
    """One marker of a layout (lengths in metres, angles in degrees)."""

    name: str
    bone: str
    along: float = 0.5
    across: float = 0.0
    angle_deg: float = 0.0
    offset: tuple[float, float, float] | None = None
    radius: float = 0.003


@dataclass(frozen=True)
class Layout:
    """An ordered set of named markers on the hand.

    Attributes:
        name: short identifier (``han19``).
        markers: the markers; their order is the label order everywhere (scores, C3D output).
        glove: thickness between skin and marker base, metres.
        description: free text for people.
    """

    name: str
    markers: tuple[Marker, ...]
    glove: float = 0.001
    description: str = ""
    source: str = field(default="", compare=False)

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.markers]

    def __len__(self) -> int:
        return len(self.markers)

    def place(self, hand: HandModel) -> tuple[Binding, np.ndarray]:
        """Rest positions, skinning and outward normals of the markers on ``hand``.

        Returns:
            the :class:`Binding` of the marker centres (hand frame, metres) and ``(M, 3)`` unit
            normals of the skin under each marker.
        """
        rest, normals, bones, weights = [], [], [], []
        r0, p0 = hand.rest
        for m in self.markers:
            b = BONE_INDEX[m.bone]
            lift = m.radius + self.glove
            if m.offset is not None:
                local = np.array(m.offset) * [hand.thumb_side, 1, 1]
                pos = r0[b] @ local + p0[b]
                normal = r0[b] @ (local / (np.linalg.norm(local) or 1.0))
                along = local[1] / hand.bone_lengths[b]
            elif b == 0:
                a = np.radians(m.angle_deg)
                z = PALM_HALF_THICKNESS_HB * hand.breadth + lift
                normal = np.array([0.0, 0.0, np.cos(a)])  # palm markers: dorsal or palmar only
                pos = np.array([hand.thumb_side * m.across * hand.breadth, m.along * hand.length, 0.0]) + z * normal
                along = m.along
            else:
                pos, normal = skin_point(hand, b, m.along, np.radians(m.angle_deg), lift)
                along = m.along
            bw = segment_weights(np.array([b]), np.array([along]))
            rest.append(pos)
            normals.append(normal)
            bones.append(bw[0][0])
            weights.append(bw[1][0])
        return Binding(np.array(rest), np.array(bones), np.array(weights)), np.array(normals)


#: The layout used where none is named (CLI, batch, the Blender panel): Han's dense 19-marker glove.
DEFAULT_LAYOUT = "han19"


def builtin_layouts() -> list[str]:
    """Names of the layouts that ship with the package, by name (Blender stores a layout choice
    as its place in this list)."""
    folder = resources.files(__package__) / "layouts"
    return sorted(p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml"))


def layout_for_names(names) -> str | None:
    """The built-in layout whose every marker name is among a take's point names (case-insensitive, a
    ``subject:`` prefix ignored), the one with most markers where several are (a han19 file also names
    every tips5 marker); None where none is."""
    have = {str(n).strip().rsplit(":", 1)[-1].lower() for n in names}
    best = None
    for name in builtin_layouts():
        markers = load_layout(name).names
        if all(m.lower() in have for m in markers) and (best is None or len(markers) > best[1]):
            best = (name, len(markers))
    return best[0] if best else None


def load_layout(name_or_path: str | os.PathLike) -> Layout:
    """A built-in layout by name (``han19``) or a layout TOML file by path.

    Raises:
        MocapInputError: unknown name, unreadable file, or a layout that does not make sense.
    """
    text = os.fspath(name_or_path)
    if os.path.sep not in text and not text.endswith(".toml"):
        if text not in builtin_layouts():
            raise MocapInputError(text, f"no such layout; built-in layouts are {', '.join(builtin_layouts())}, "
                                        "or give the path of a .toml file")
        source = resources.files(__package__) / "layouts" / f"{text}.toml"
        data = tomllib.loads(source.read_text(encoding="utf-8"))
        return parse_layout(data, f"{text} (built-in)")
    try:
        with open(text, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise MocapInputError(text, "layout file not found") from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise MocapInputError(text, f"not a readable TOML layout ({exc})") from None
    return parse_layout(data, text)


def parse_layout(data: dict, source: str = "") -> Layout:
    """Build a :class:`Layout` from parsed TOML; every problem names the marker it concerns."""

    def fail(problem: str) -> MocapInputError:
        return MocapInputError(source or "layout", problem)

    name = data.get("name") or os.path.splitext(os.path.basename(source))[0]
    default_radius = float(data.get("radius_mm", 3.0)) / 1000
    glove = float(data.get("glove_mm", 1.0)) / 1000
    entries = data.get("markers")
    if not isinstance(entries, list) or not entries:
        raise fail("has no [[markers]]")
    markers, seen = [], set()
    known = {"name", "bone", "along", "across", "side", "angle_deg", "offset_mm", "radius_mm"}
    for i, e in enumerate(entries):
        label = e.get("name")
        where = f"marker {i + 1}" + (f" ({label})" if label else "")
        if not label or not isinstance(label, str):
            raise fail(f"{where} has no name")
        if label in seen:
            raise fail(f"marker name {label!r} appears twice")
        seen.add(label)
        unknown = set(e) - known
        if unknown:
            raise fail(f"{where}: unknown key(s) {', '.join(sorted(unknown))}; known are {', '.join(sorted(known))}")
        bone = e.get("bone")
        if bone not in BONE_INDEX:
            raise fail(f"{where}: bone {bone!r} is not one of {', '.join(BONE_NAMES)}")
        side = e.get("side", "dorsal")
        if "angle_deg" in e:
            angle = float(e["angle_deg"])
        elif side in SIDES_DEG:
            angle = SIDES_DEG[side]
        else:
            raise fail(f"{where}: side {side!r} is not one of {', '.join(SIDES_DEG)}")
        if bone == "palm" and angle not in (0.0, 180.0) and "offset_mm" not in e:
            raise fail(f"{where}: markers on the palm bone are dorsal or palmar (or use offset_mm)")
        offset = e.get("offset_mm")
        if offset is not None:
            if len(offset) != 3:
                raise fail(f"{where}: offset_mm needs three numbers")
            offset = tuple(float(v) / 1000 for v in offset)
        along = float(e.get("along", 0.5))
        if not -0.5 <= along <= 1.5:
            raise fail(f"{where}: along = {along} is off the bone (use 0 to 1)")
        radius = float(e.get("radius_mm", default_radius * 1000)) / 1000
        if not 0.0005 <= radius <= 0.02:
            raise fail(f"{where}: radius_mm = {radius * 1000:g} is not a marker size (0.5 to 20 mm)")
        markers.append(Marker(label, bone, along, float(e.get("across", 0.0)), angle, offset, radius))
    return Layout(str(name), tuple(markers), glove, str(data.get("description", "")), source)


#: Length of one marker's descriptor (:func:`marker_descriptors`).
DESCRIPTOR_SIZE = 3 + 3 + len(BONE_NAMES) + 1


def marker_descriptors(layout: Layout) -> np.ndarray:
    """Where each marker sits on the average template hand: what a layout-conditioned model reads.

    Returns:
        float32 ``(M, DESCRIPTOR_SIZE)``: rest position in the hand frame divided by the hand
        length (3), outward skin normal (3), one-hot bone (20), and the fraction along the bone
        (for palm markers, of the hand length) (1).
    """
    hand = HandModel()
    binding, normals = layout.place(hand)
    onehot = np.zeros((len(layout), len(BONE_NAMES)))
    onehot[np.arange(len(layout)), [BONE_INDEX[m.bone] for m in layout.markers]] = 1.0
    along = np.array([[m.along] for m in layout.markers])
    return np.concatenate([binding.rest / hand.length, normals, onehot, along], axis=1).astype(np.float32)
