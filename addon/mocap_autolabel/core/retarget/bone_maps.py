"""Bone maps: which of a character's bones is which bone of our hand, for the common rig conventions.

API (the Blender layer, the CLI and the exports rely on it):

- ``CONVENTIONS``: registry ``{name: Convention subclass}`` with at least ``rigify``, ``mixamo``,
  ``ue5``, ``unity`` and ``generic``; each has ``name``, ``label`` (UI text) and
  ``bone_name(bone, side) -> str | None`` (our bone -> its bone name, None where the convention
  has no such bone), and ``match(names) -> dict[side, dict[our bone, their bone]]``.
- :class:`BoneMap`: ``convention`` and ``sides`` ``{"left" | "right": {our bone: their bone}}``;
  ``to_dict`` / ``from_dict``, ``save(path)`` / ``load(path)`` (JSON, atomic write).
- :func:`auto_map` ``(names, parents) -> BoneMap``: the convention that maps most hand bones
  (prefixes such as ``mixamorig:`` or ``DEF-`` allowed), else the generic name patterns.
- :func:`export_names` ``(convention, side) -> {our bone: name}``: names of our rig's bones in a
  convention, for engine exports (``ours`` keeps ours).

Our bones are :data:`..hand.skeleton.BONE_NAMES` (``palm``, ``thumb_meta``, ``thumb_prox``,
``thumb_dist``, ``index_meta`` ... ``little_dist``).

Rules every map keeps: one side's map never uses a character bone twice; a side counts only when
its hand bone (our ``palm``) is mapped, and is left out otherwise; end or tip bones (Mixamo's
``*4``, ``*_end``, ``*_tip``, ``*.end``) are never mapped; a character may have fewer bones than
ours (no finger metacarpals: ``index_prox`` is its first finger bone, ``index_meta`` is unmapped).

Matching a named convention (:meth:`Convention.match`) looks for its bone names at the end of the
character's names, after any prefix that ends at a word boundary (``mixamorig:``, ``mixamorig1:``,
``mixamorig_``, ``Character1_``, ``DEF-``, ``ORG-``, ``Armature_`` ...; not helper prefixes such as
``ik_``, ``MCH-``, ``VB ``, other than a convention's own ``ORG-``). One prefix is used per side:
the one that maps most bones with the hand among them (ties: the convention's usual prefixes in
order, e.g. Rigify's bare names, then ``DEF-``, then ``ORG-``). A generated Rigify rig has no
``hand.L`` (its hand controls are ``hand_fk.L`` / ``hand_ik.L``), so it maps to its ``DEF-``
(deforming) bones.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar

from ..atomic import read_json, write_json
from ..errors import MocapInputError
from ..hand.skeleton import BONE_NAMES, DIGITS, FINGERS

#: The hands a map may hold.
SIDES = ("left", "right")
#: ``format`` of a bone map preset file.
FORMAT = "mocap_autolabel.bone_map/1"
#: Our segments per digit, proximal to distal (bone ``f"{digit}_{segment}"``).
SEGMENTS = {d: ("meta", "prox", "dist") if d == "thumb" else ("meta", "prox", "mid", "dist") for d in DIGITS}

#: ``{side: {our bone: their bone}}``.
SideMaps = dict[str, dict[str, str]]
#: A character's hierarchy: one entry per name (a parent's index, -1 or None for a root, or a parent's
#: name), or a ``{name: parent name or None}`` mapping, or None where the hierarchy is unknown.
Parents = Sequence[int | str | None] | Mapping[str, str | None] | None


def _check_side(side: str) -> None:
    if side not in SIDES:
        raise ValueError(f"side must be one of {', '.join(SIDES)}, not {side!r}")


def _check_bone(bone: str) -> None:
    if bone not in BONE_NAMES:
        raise ValueError(f"{bone!r} is not one of our bones ({', '.join(BONE_NAMES)})")


# ------------------------------------------------------------------------------------------------
# Conventions
# ------------------------------------------------------------------------------------------------


class Convention:
    """A rig naming convention (used as a class: every method is a classmethod).

    Attributes:
        name: registry key (``CONVENTIONS[name]``), also what presets and the CLI call it.
        label: UI text.
    """

    name: ClassVar[str] = ""
    label: ClassVar[str] = ""

    @classmethod
    def bone_name(cls, bone: str, side: str) -> str | None:
        """Our ``bone`` (one of BONE_NAMES) on ``side`` -> its name in this convention; None where the
        convention has no such bone."""
        raise NotImplementedError

    @classmethod
    def export_name(cls, bone: str, side: str) -> str:
        """The name our ``bone`` gets when our rig is renamed to this convention: :meth:`bone_name`, or
        for a bone the convention lacks, a stand-in in the convention's style that :meth:`match`
        also recognises."""
        name = cls.bone_name(bone, side)
        if name is None:
            raise NotImplementedError(f"{cls.name}: no export name for {bone!r}")
        return name

    @classmethod
    def match(cls, names: Iterable[str], parents: Parents = None) -> SideMaps:
        """The character bones among ``names`` that are our bones: ``{side: {our bone: their bone}}``,
        only sides whose hand bone was found. ``parents`` (see :data:`Parents`) is used by the conventions
        that read the hierarchy (``generic``); the named conventions go by name alone."""
        raise NotImplementedError


def _boundaries(name: str) -> Iterable[int]:
    """Where a convention's name may start inside ``name``: the start, after a non-alphanumeric
    character, or at a lower-to-upper case change (``mixamorigLeftHand``, ``Character1LeftHand``)."""
    yield 0
    for i in range(1, len(name)):
        before, here = name[i - 1], name[i]
        if not before.isalnum() or (here.isupper() and (before.islower() or before.isdigit())):
            yield i


def _helper_prefix(prefix: str) -> bool:
    """Whether ``prefix`` marks a helper bone (``ik_hand_l``, ``MCH-hand.L``, ``VB hand_l``), not a
    character's own namespace."""
    return any(t.lower() in _HELPER_WORDS or t.lower() in _TIP_WORDS for t in _TOKEN.findall(prefix))


class TableConvention(Convention):
    """A convention with fixed bone names (optionally after a prefix).

    Subclasses give :meth:`cores` (our bone -> its names without prefix; the first is the canonical one),
    :meth:`extras` (stand-in names for our bones the convention lacks: used for exports and recognised
    when matching), ``prefixes`` (usual prefixes, preferred in this order; the first is the one exported)
    and optionally :meth:`variants`.
    """

    prefixes: ClassVar[tuple[str, ...]] = ("",)
    #: Whether the usual prefixes' order outranks how many bones a prefix maps (Rigify: a generated
    #: rig's controls, unprefixed, before its ``DEF-`` bones, which constraints drive).
    prefix_first: ClassVar[bool] = False

    @classmethod
    def cores(cls, side: str) -> dict[str, tuple[str, ...]]:
        raise NotImplementedError

    @classmethod
    def extras(cls, side: str) -> dict[str, str]:
        return {}

    @classmethod
    def variants(cls, side: str) -> list[dict[str, tuple[str, ...]]]:
        """Name tables tried in turn (the one that maps most wins, ties: the first)."""
        table = dict(cls.cores(side))
        for bone, name in cls.extras(side).items():
            table[bone] = table.get(bone, ()) + (name,)
        return [table]

    @classmethod
    def bone_name(cls, bone: str, side: str) -> str | None:
        _check_side(side)
        _check_bone(bone)
        names = cls.cores(side).get(bone)
        return cls.prefixes[0] + names[0] if names else None

    @classmethod
    def export_name(cls, bone: str, side: str) -> str:
        name = cls.bone_name(bone, side)
        return name if name is not None else cls.prefixes[0] + cls.extras(side)[bone]

    @classmethod
    def match(cls, names: Iterable[str], parents: Parents = None) -> SideMaps:
        names = list(names)
        out: SideMaps = {}
        for side in SIDES:
            best: tuple | None = None
            for v, table in enumerate(cls.variants(side)):
                lookup = {core: (bone, rank) for bone, cores in table.items() for rank, core in enumerate(cores)}
                groups: dict[str, dict[str, tuple[int, str]]] = {}
                for name in names:
                    for i in _boundaries(name):
                        hit = lookup.get(name[i:])
                        if hit is None:
                            continue
                        bone, rank = hit
                        group = groups.setdefault(name[:i], {})
                        if bone not in group or rank < group[bone][0]:
                            group[bone] = (rank, name)
                for prefix, group in groups.items():
                    if "palm" not in group or (prefix not in cls.prefixes and _helper_prefix(prefix)):
                        continue
                    pref = cls.prefixes.index(prefix) if prefix in cls.prefixes else len(cls.prefixes)
                    key = (pref, -len(group), v, len(prefix), prefix) if cls.prefix_first else \
                        (-len(group), pref, v, len(prefix), prefix)
                    if best is None or key < best[0]:
                        best = (key, {b: n for b, (_, n) in group.items()})
            if best is not None:
                out[side] = _ordered(_unique(best[1]))
        return out


class Rigify(TableConvention):
    """Blender's Rigify: the human meta-rig's bones, or a generated rig's ``DEF-`` (deforming) or
    ``ORG-`` copies of them; ``.L`` / ``.R``.

    Source: Blender 5.0's ``scripts/addons_core/rigify/metarigs/human.py`` (the bpy 5.0.1 module:
    ``hand.L``; ``palm.01.L`` .. ``palm.04.L`` under it, the index to little metacarpals;
    ``thumb.01.L`` .. ``thumb.03.L`` under ``palm.01.L``; ``f_index.01.L`` .. ``.03.L`` under
    ``palm.01.L``, likewise ``f_middle``, ``f_ring``, ``f_pinky``), the prefixes from
    ``rigify/utils/naming.py`` (``ORG_PREFIX = "ORG-"``, ``DEF_PREFIX = "DEF-"``), and a rig generated by
    that Rigify (``DEF-hand.L``, ``DEF-palm.01.L``, ``DEF-f_index.01.L``, ``ORG-thumb.01.L``, no ``hand.L``).
    Older meta-rigs' ``finger_index.01.L`` (blender/blender-addons ``rigify/metarigs/human.py``,
    Blender 2.7x) are recognised too.
    """

    name = "rigify"
    label = "Rigify"
    prefixes = ("", "DEF-", "ORG-")
    prefix_first = True
    _FINGER = {"index": "index", "middle": "middle", "ring": "ring", "little": "pinky"}

    @classmethod
    def cores(cls, side: str) -> dict[str, tuple[str, ...]]:
        s = ".L" if side == "left" else ".R"
        out = {"palm": (f"hand{s}", f"hand_fk{s}")}  # a generated rig's FK hand control
        for i, seg in enumerate(SEGMENTS["thumb"], 1):
            out[f"thumb_{seg}"] = (f"thumb.0{i}{s}",)
        for k, finger in enumerate(FINGERS, 1):
            out[f"{finger}_meta"] = (f"palm.0{k}{s}",)
            word = cls._FINGER[finger]
            for i, seg in enumerate(("prox", "mid", "dist"), 1):
                out[f"{finger}_{seg}"] = (f"f_{word}.0{i}{s}", f"finger_{word}.0{i}{s}")
        return out


class Mixamo(TableConvention):
    """Adobe Mixamo (Autodesk HumanIK names in the ``mixamorig:`` namespace): ``LeftHand``,
    ``LeftHandThumb1..3`` (``Thumb1`` is the thumb metacarpal), ``LeftHandIndex1..3``,
    ``LeftHandMiddle1..3``, ``LeftHandRing1..3``, ``LeftHandPinky1..3``; no finger metacarpals; the
    ``*4`` bones are the finger tips and are never mapped.

    Sources: makehumancommunity/googlecode ``makehuman/tools/blender/makewalk/target_rigs/humanik.trg``
    (the HumanIK hand names, ``LeftHandThumb1`` -> Rigify ``thumb.01.L``), DayalGupta03/Sign_Bridge1
    ``boneNames.md`` (a Mixamo rig's bones: ``LeftHandThumb4`` "tip of the thumb"), Unity mappings that
    put ``mixamorig:LeftHandThumb1`` on "Left Thumb Proximal" (the thumb's first bone).
    Exports name our finger metacarpals ``mixamorig:LeftHandIndex0`` .. ``LeftHandPinky0`` (the
    ``Index0`` style some hand-tracking skeletons use for the metacarpal); matching recognises them.
    """

    name = "mixamo"
    label = "Mixamo"
    prefixes = ("mixamorig:", "mixamorig1:", "mixamorig_", "mixamorig", "")
    _FINGER = {"index": "Index", "middle": "Middle", "ring": "Ring", "little": "Pinky"}

    @classmethod
    def cores(cls, side: str) -> dict[str, tuple[str, ...]]:
        s = side.capitalize()
        out = {"palm": (f"{s}Hand",)}
        for i, seg in enumerate(SEGMENTS["thumb"], 1):
            out[f"thumb_{seg}"] = (f"{s}HandThumb{i}",)
        for finger in FINGERS:
            for i, seg in enumerate(("prox", "mid", "dist"), 1):
                out[f"{finger}_{seg}"] = (f"{s}Hand{cls._FINGER[finger]}{i}",)
        return out

    @classmethod
    def extras(cls, side: str) -> dict[str, str]:
        return {f"{f}_meta": f"{side.capitalize()}Hand{cls._FINGER[f]}0" for f in FINGERS}


class UE5(TableConvention):
    """Unreal Engine 5's Mannequin (Manny, Quinn) and MetaHuman: ``hand_l``, ``thumb_01_l`` ..
    ``thumb_03_l`` (``thumb_01`` is the thumb metacarpal), ``index_metacarpal_l``, ``index_01_l`` ..
    ``index_03_l``, likewise ``middle``, ``ring``, ``pinky``; ``_r`` for the right hand. The UE4
    Mannequin has the same names without the metacarpals and matches too. Helper bones such as
    ``ik_hand_l``, ``lowerarm_twist_01_l``, ``wrist_inner_l`` are not hand bones.

    Sources: Roeliefantje/mediapipe2meta ``test.py`` (MetaHuman hand hierarchy: ``hand`` ->
    ``index_metacarpal`` -> ``index_01`` .. ``index_03``, ``hand`` -> ``thumb_01`` .. ``thumb_03``,
    ``_l`` / ``_r``), freemocap/freemocap_blender_addon
    ``freemocap_blender_addon/data_models/armatures/bone_name_map.py`` (Rigify ``palm.01.L`` ->
    ``index_metacarpal_l``, ``thumb.01.L`` -> ``thumb_01_l``, ``f_index.01.L`` -> ``index_01_l``),
    vespero-group/chiro-ue4 ``documentation/docs/select-bone-group.md`` (UE4 Mannequin twist and IK bones).
    """

    name = "ue5"
    label = "Unreal Engine 5 (Mannequin, MetaHuman)"
    _FINGER = {"index": "index", "middle": "middle", "ring": "ring", "little": "pinky"}

    @classmethod
    def cores(cls, side: str) -> dict[str, tuple[str, ...]]:
        s = "_l" if side == "left" else "_r"
        out = {"palm": (f"hand{s}", f"hand_fk{s}")}  # a generated rig's FK hand control
        for i, seg in enumerate(SEGMENTS["thumb"], 1):
            out[f"thumb_{seg}"] = (f"thumb_0{i}{s}",)
        for finger in FINGERS:
            word = cls._FINGER[finger]
            out[f"{finger}_meta"] = (f"{word}_metacarpal{s}",)
            for i, seg in enumerate(("prox", "mid", "dist"), 1):
                out[f"{finger}_{seg}"] = (f"{word}_0{i}{s}",)
        return out


class Unity(TableConvention):
    """Unity's Humanoid avatar (``HumanBodyBones``): ``LeftHand``, ``LeftThumbProximal`` /
    ``Intermediate`` / ``Distal`` (Unity's thumb Proximal is the thumb metacarpal),
    ``LeftIndexProximal`` / ``Intermediate`` / ``Distal``, likewise ``Middle``, ``Ring``, ``Little``;
    also the spaced form ``Left Thumb Proximal`` of ``HumanTrait.BoneName``. No finger metacarpals.

    Sources: Unity's scripting reference, ``HumanBodyBones``
    (https://docs.unity3d.com/ScriptReference/HumanBodyBones.html: "LeftThumbProximal: the left thumb
    1st phalange"), and ``HumanTrait.BoneName`` lists in public Unity projects (``"LeftHand"``,
    ``"Left Thumb Proximal"``, ``"Left Index Intermediate"``; ``mixamorig:LeftHandThumb1`` ->
    "Left Thumb Proximal").
    Also recognised: the VRM 1.0 / Godot ``SkeletonProfileHumanoid`` thumb (``LeftThumbMetacarpal``,
    ``LeftThumbProximal``, ``LeftThumbDistal``: there Proximal is the thumb's proximal phalanx), used
    where a side has a ``ThumbMetacarpal`` bone. Exports name our finger metacarpals
    ``LeftIndexMetacarpal`` .. ``LeftLittleMetacarpal`` (matching recognises them).
    """

    name = "unity"
    label = "Unity Humanoid"
    _DIGIT = {"thumb": "Thumb", "index": "Index", "middle": "Middle", "ring": "Ring", "little": "Little"}
    _WORD = {"meta": "Metacarpal", "prox": "Proximal", "mid": "Intermediate", "dist": "Distal"}

    @classmethod
    def _names(cls, side: str, digit: str, word: str) -> tuple[str, str]:
        s, d = side.capitalize(), cls._DIGIT[digit]
        return f"{s}{d}{word}", f"{s} {d} {word}"

    @classmethod
    def cores(cls, side: str) -> dict[str, tuple[str, ...]]:
        s = side.capitalize()
        out = {"palm": (f"{s}Hand", f"{s} Hand")}
        for seg, word in zip(SEGMENTS["thumb"], ("Proximal", "Intermediate", "Distal")):
            out[f"thumb_{seg}"] = cls._names(side, "thumb", word)
        for finger in FINGERS:
            for seg in ("prox", "mid", "dist"):
                out[f"{finger}_{seg}"] = cls._names(side, finger, cls._WORD[seg])
        return out

    @classmethod
    def extras(cls, side: str) -> dict[str, str]:
        return {f"{f}_meta": cls._names(side, f, "Metacarpal")[0] for f in FINGERS}

    @classmethod
    def variants(cls, side: str) -> list[dict[str, tuple[str, ...]]]:
        unity = super().variants(side)[0]
        vrm = dict(unity)
        for seg in SEGMENTS["thumb"]:
            vrm[f"thumb_{seg}"] = cls._names(side, "thumb", cls._WORD[seg])
        return [unity, vrm]


# ------------------------------------------------------------------------------------------------
# Generic name patterns
# ------------------------------------------------------------------------------------------------

_TOKEN = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+")
_SIDE_WORDS = {"l": "left", "left": "left", "r": "right", "right": "right"}
_DIGIT_WORDS = {
    "thumb": "thumb", "pollex": "thumb",
    "index": "index", "pointer": "index", "fore": "index",
    "middle": "middle", "mid": "middle",
    "ring": "ring",
    "pinky": "little", "pinkie": "little", "little": "little", "small": "little",
}
_SEGMENT_WORDS = {
    "meta": "meta", "metacarpal": "meta", "metacarpals": "meta", "carpal": "meta", "palm": "meta", "cmc": "meta",
    "prox": "prox", "proximal": "prox", "mcp": "prox",
    "inter": "inter", "intermediate": "inter", "mid": "inter", "middle": "inter", "medial": "inter",
    "pip": "inter",
    "dist": "dist", "distal": "dist", "dip": "dist", "ip": "dist",
}
#: Hand words, best first.
_HAND_WORDS = {"hand": 0, "wrist": 1, "palm": 2}
#: End/tip bones: never mapped.
_TIP_WORDS = {"end", "tip", "tips", "top", "nub", "site", "effector", "nail", "tail"}
#: Helper bones (controls, mechanism, twist, IK, attachment points): never hand bones.
_HELPER_WORDS = {
    "ik", "fk", "pole", "target", "tgt", "ctrl", "ctl", "control", "con", "mch", "org", "tweak", "master",
    "drv", "driver", "twist", "roll", "helper", "socket", "attach", "attachment", "weapon", "prop", "grip",
    "ref", "offset", "space", "parent", "root", "null", "grp", "group", "pivot", "aim", "corrective", "vb",
    "dummy", "bend", "lock", "follow", "gun", "widget", "wgt", "jiggle", "dyn", "physics", "phys",
    "collider", "spring", "sim", "mirror", "scale", "rot", "pos", "loc",
}
#: Other body parts: a bone named with one of these is neither hand nor finger (``LeftForeArm``, ``Toe_Index``).
_BODY_WORDS = {
    "arm", "forearm", "upperarm", "lowerarm", "elbow", "shoulder", "clavicle", "scapula", "leg", "upleg",
    "thigh", "calf", "shin", "knee", "foot", "toe", "toes", "ball", "heel", "ankle", "spine", "neck", "head",
    "eye", "jaw", "hip", "hips", "pelvis", "chest", "face", "lip", "brow", "lid", "ear", "nose", "tongue",
    "teeth", "cheek", "breast",
}


@dataclass(frozen=True)
class _Info:
    """What a bone's name says: its side (None: none or both), its kind (``"hand"``, ``"finger"`` or
    None), digit, segment word (``meta``, ``prox``, ``inter``, ``dist`` or None), last number, hand-word
    rank (lower is better) and its words that mean nothing here (prefixes such as ``DEF``, ``J``, ``Bip``)."""

    side: str | None
    kind: str | None = None
    digit: str | None = None
    segment: str | None = None
    number: int | None = None
    rank: int = 0
    extra: tuple[str, ...] = ()


def _digit_word(token: str) -> str | None:
    if token in _DIGIT_WORDS:
        return _DIGIT_WORDS[token]
    if token.endswith("finger") and token[: -len("finger")] in _DIGIT_WORDS:  # forefinger, indexfinger
        return _DIGIT_WORDS[token[: -len("finger")]]
    return None


def _classify(name: str) -> _Info:
    tokens = [t.lower() for t in _TOKEN.findall(name)]
    sides = {_SIDE_WORDS[t] for t in tokens if t in _SIDE_WORDS}
    side = sides.pop() if len(sides) == 1 else None
    if any(t in _TIP_WORDS or t in _HELPER_WORDS or t in _BODY_WORDS for t in tokens):
        return _Info(side)
    numbers = [int(t) for t in tokens if t.isdigit()]
    number = numbers[-1] if numbers else None
    words = [t for t in tokens if not t.isdigit() and t not in _SIDE_WORDS]
    for i, t in enumerate(words):
        digit = _digit_word(t)
        if digit is not None:
            rest = words[:i] + words[i + 1:]
            segments = {_SEGMENT_WORDS[w] for w in rest if w in _SEGMENT_WORDS}
            segment = segments.pop() if len(segments) == 1 else None
            extra = tuple(w for w in rest if w not in _SEGMENT_WORDS and w != "finger")
            return _Info(side, "finger", digit, segment, number, extra=extra)
    if "palm" in words and number is not None and 1 <= number <= len(FINGERS):  # Rigify's palm.01 .. palm.04
        return _Info(side, "finger", FINGERS[number - 1], "meta", 0, extra=tuple(w for w in words if w != "palm"))
    hand = [_HAND_WORDS[w] for w in words if w in _HAND_WORDS]
    if hand:
        return _Info(side, "hand", rank=min(hand), extra=tuple(w for w in words if w not in _HAND_WORDS))
    return _Info(side)


def _parent_map(names: list[str], parents: Parents) -> dict[str, str | None]:
    if parents is None:
        return dict.fromkeys(names)
    if isinstance(parents, Mapping):
        return {n: parents.get(n) for n in names}
    parents = list(parents)
    if len(parents) != len(names):
        raise ValueError(f"{len(names)} bone names but {len(parents)} parents")
    out: dict[str, str | None] = {}
    for n, p in zip(names, parents):
        if p is None or isinstance(p, str):
            out[n] = p
        elif int(p) < 0:
            out[n] = None
        elif int(p) < len(names):
            out[n] = names[int(p)]
        else:
            raise ValueError(f"bone {n!r}: parent index {p} out of range")
    return out


class _Tree:
    """The hierarchy, safe against cycles in bad input."""

    def __init__(self, names: list[str], parent: dict[str, str | None]):
        self.parent = {n: (p if p in parent and p != n else None) for n, p in parent.items()}
        self.order = {n: i for i, n in enumerate(names)}
        self.limit = len(names)

    def ancestors(self, name: str) -> Iterable[str]:
        p = self.parent.get(name)
        for _ in range(self.limit):
            if p is None:
                return
            yield p
            p = self.parent.get(p)

    def depth(self, name: str) -> int:
        return sum(1 for _ in self.ancestors(name))

    def below(self, name: str, top: str) -> bool:
        return any(a == top for a in self.ancestors(name))


class Generic(Convention):
    """Name patterns, for rigs that follow none of the named conventions (and for those with unusual
    prefixes or separators).

    - Side: a ``L`` / ``R`` / ``Left`` / ``Right`` word anywhere in the name (``hand.L``, ``hand_l``,
      ``L_hand``, ``l-hand``, ``LeftHand``, ``Left_Hand``, ``Hand_Left``; words are split at
      non-letters, case changes and digits); a finger or hand bone without one takes its nearest
      ancestor's.
    - Hand: ``hand``, else ``wrist``, else ``palm``; of several, the one with the most finger bones
      below it, then the deepest.
    - Fingers: thumb/pollex, index/pointer/fore(finger), middle/mid, ring, pinky/pinkie/little/small;
      Rigify-style ``palm.01`` .. ``palm.04`` are the index .. little metacarpals.
    - Each finger's chain comes from the hierarchy (the longest parent-child run of that finger's
      bones below the hand; numbers only order bones that are not chained). Segment words place the
      bones where every bone of a chain has one: meta/metacarpal/carpal/cmc, prox/proximal/mcp,
      inter/intermediate/mid/middle/pip, dist/distal/dip/ip (a thumb named proximal/intermediate/distal,
      Unity's way, is metacarpal/proximal/distal). Otherwise by position: a thumb's three bones are
      meta, prox, dist; a finger's four are meta, prox, mid, dist, its three prox, mid, dist. A thumb
      of four numbered from 0 starts with an extra bone (dropped); numbered from 1 it ends with a tip
      (dropped), and then so do the fingers' fourth bones (``Index1..4`` as in Mixamo).
    - Never: tips/ends (end, tip, nub, top ...), helpers (ik, fk, twist, roll, ctrl, mch, org, tweak,
      master, pole, target, socket, weapon ...), other body parts (arm, forearm, toe ...).

    :meth:`bone_name` gives the names exports use: ``hand.L``, ``thumb_metacarpal.L``,
    ``index_proximal.L``, ``index_intermediate.L``, ``little_distal.R`` ...
    """

    name = "generic"
    label = "Generic (name patterns)"
    _WORD = {"meta": "metacarpal", "prox": "proximal", "mid": "intermediate", "dist": "distal"}

    @classmethod
    def bone_name(cls, bone: str, side: str) -> str | None:
        _check_side(side)
        _check_bone(bone)
        s = ".L" if side == "left" else ".R"
        if bone == "palm":
            return f"hand{s}"
        digit, seg = bone.split("_")
        return f"{digit}_{cls._WORD[seg]}{s}"

    @classmethod
    def match(cls, names: Iterable[str], parents: Parents = None) -> SideMaps:
        names = list(names)
        tree = _Tree(names, _parent_map(names, parents))
        info = {n: _classify(n) for n in names}

        def side_of(n: str) -> str | None:
            if info[n].side is not None:
                return info[n].side
            return next((info[a].side for a in tree.ancestors(n) if a in info and info[a].side), None)

        out: SideMaps = {}
        for side in SIDES:
            hands = [n for n in names if info[n].kind == "hand" and side_of(n) == side]
            if not hands:
                continue
            fingers = [n for n in names if info[n].kind == "finger" and side_of(n) == side]

            def hand_key(h: str, fingers: list[str] = fingers) -> tuple:
                below = sum(tree.below(f, h) for f in fingers)
                return (below, tree.depth(h), -info[h].rank, -len(info[h].extra), -tree.order[h])

            hand = max(hands, key=hand_key)
            under = [f for f in fingers if tree.below(f, hand)]
            fingers = under or fingers
            chains = {d: _chain([f for f in fingers if info[f].digit == d], tree, hand, info) for d in DIGITS}
            thumb = chains["thumb"]
            tips = len(thumb) > 3 and info[thumb[0]].number != 0
            bones = {"palm": hand}
            for digit in DIGITS:
                bones.update(_place(digit, chains[digit], info, tips))
            out[side] = _ordered(_unique(bones))
        return out


def _chain(bones: list[str], tree: _Tree, hand: str, info: dict[str, _Info]) -> list[str]:
    """One finger's bones, proximal to distal: the longest chain of them in the hierarchy (ties: the
    chain sharing most prefix words with the hand bone, ``DEF-f_index.01.L`` with ``DEF-hand.L``)."""
    if not bones:
        return []
    members = set(bones)
    up: dict[str, str | None] = {}
    for b in bones:
        up[b] = next((a for a in tree.ancestors(b) if a in members or a == hand), None)
        if up[b] == hand:
            up[b] = None
    depth: dict[str, int] = {}

    def deep(b: str) -> int:
        if b not in depth:
            depth[b] = 0  # a cycle cannot recurse forever
            depth[b] = 1 + (deep(up[b]) if up[b] is not None else 0)
        return depth[b]

    own = set(info[hand].extra)
    end = max(bones, key=lambda b: (deep(b), len(own.intersection(info[b].extra)), -tree.order[b]))
    chain = [end]
    while up[chain[-1]] is not None and len(chain) <= len(bones):
        chain.append(up[chain[-1]])
    chain.reverse()
    if len(chain) == 1 and len(bones) > 1:  # not chained (no hierarchy): by number, then name order
        numbered = sorted(bones, key=lambda b: (info[b].number is None, info[b].number or 0, tree.order[b]))
        chain, seen = [], set()
        for b in numbered:
            if info[b].number is None or info[b].number not in seen:
                chain.append(b)
                seen.add(info[b].number)
    return chain


_THUMB_SLOT = {"meta": 0, "prox": 1, "dist": 2}
_FINGER_SLOT = {"meta": 0, "prox": 1, "inter": 2, "dist": 3}


def _place(digit: str, chain: list[str], info: dict[str, _Info], tips: bool) -> dict[str, str]:
    """Our bones of ``digit`` -> the bones of ``chain`` (see :class:`Generic`)."""
    if not chain:
        return {}
    segs = SEGMENTS[digit]
    words = [info[b].segment for b in chain]
    if all(words):
        if digit == "thumb":
            slot = dict(_THUMB_SLOT)
            if "inter" in words and "meta" not in words:  # Unity: the thumb's proximal is its metacarpal
                slot = {"prox": 0, "inter": 1, "dist": 2}
        else:
            slot = _FINGER_SLOT
        at = [slot.get(w, -1) for w in words]
        if min(at) >= 0 and all(a < b for a, b in zip(at, at[1:])):
            return {f"{digit}_{segs[i]}": b for i, b in zip(at, chain)}
    numbers = [info[b].number for b in chain]
    meta_first = words[0] == "meta"
    if digit == "thumb":
        if len(chain) > 3:
            chain = chain[1:4] if numbers[0] == 0 else chain[:3]
        start = 0 if len(chain) == 3 or meta_first else 1
    else:
        if len(chain) > 4:
            chain = chain[:4]
        if len(chain) == 4 and tips and not meta_first and numbers[0] != 0:
            chain = chain[:3]
        start = 0 if len(chain) == 4 or meta_first else 1
    return {f"{digit}_{segs[start + i]}": b for i, b in enumerate(chain[: len(segs) - start])}


def _unique(bones: dict[str, str]) -> dict[str, str]:
    """Drop any later use of a character bone already used (a side never uses one twice)."""
    seen: set[str] = set()
    out = {}
    for bone in BONE_NAMES:
        name = bones.get(bone)
        if name is not None and name not in seen:
            out[bone] = name
            seen.add(name)
    return out


def _ordered(bones: Mapping[str, str]) -> dict[str, str]:
    return {b: bones[b] for b in BONE_NAMES if b in bones}


#: The conventions, most specific first (auto_map's order for ties).
CONVENTIONS: dict[str, type[Convention]] = {c.name: c for c in (Rigify, Mixamo, UE5, Unity, Generic)}


# ------------------------------------------------------------------------------------------------
# Bone maps
# ------------------------------------------------------------------------------------------------


@dataclass
class BoneMap:
    """Which character bone is which of our bones, per hand.

    Attributes:
        convention: the convention it came from (a :data:`CONVENTIONS` key), or any other name for a
            hand-made map (e.g. ``"custom"``); informational.
        sides: ``{"left" | "right": {our bone: the character's bone}}``; a side is there only with its
            ``palm`` (the character's hand bone) mapped; no character bone twice in a side.

    Raises:
        ValueError: on construction, for an unknown side or bone, a side without ``palm``, a bone used
            twice in a side, or names that are not non-empty strings.
    """

    convention: str
    sides: SideMaps = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.convention, str) or not self.convention:
            raise ValueError(f"convention must be a non-empty string, not {self.convention!r}")
        if not isinstance(self.sides, Mapping):
            raise ValueError(f"sides must be a mapping of side -> bones, not {type(self.sides).__name__}")
        sides: SideMaps = {}
        for side, bones in self.sides.items():
            if side not in SIDES:
                raise ValueError(f"unknown side {side!r} (sides are {', '.join(SIDES)})")
            if not isinstance(bones, Mapping):
                raise ValueError(f"{side} side: expected a mapping of our bone -> character bone")
            unknown = [b for b in bones if b not in BONE_NAMES]
            if unknown:
                raise ValueError(f"{side} side: unknown bone(s) {', '.join(map(repr, unknown))} "
                                 f"(ours are {', '.join(BONE_NAMES)})")
            bad = [b for b, n in bones.items() if not isinstance(n, str) or not n]
            if bad:
                raise ValueError(f"{side} side: bone(s) {', '.join(bad)} need a non-empty character bone name")
            if "palm" not in bones:
                raise ValueError(f"{side} side: 'palm' (the character's hand bone) is not mapped")
            used: dict[str, str] = {}
            for b in BONE_NAMES:
                if b in bones:
                    if bones[b] in used:
                        raise ValueError(f"{side} side: {bones[b]!r} is mapped twice ({used[bones[b]]} and {b})")
                    used[bones[b]] = b
            sides[side] = _ordered(bones)
        self.sides = {s: sides[s] for s in SIDES if s in sides}

    @property
    def count(self) -> int:
        """How many bones are mapped, both sides together."""
        return sum(len(b) for b in self.sides.values())

    def to_dict(self) -> dict:
        """JSON-ready: ``{"format", "convention", "sides": {side: {our bone: theirs}}}``."""
        return {"format": FORMAT, "convention": self.convention, "sides": {s: dict(b) for s, b in self.sides.items()}}

    @classmethod
    def from_dict(cls, data: Mapping, where: str = "bone map") -> BoneMap:
        """A map from :meth:`to_dict`'s dict; any problem is one :class:`MocapInputError` naming ``where``."""
        try:
            if not isinstance(data, Mapping):
                raise ValueError(f"expected a JSON object, got {type(data).__name__}")
            if data.get("format") != FORMAT:
                raise ValueError(f"format is {data.get('format')!r}, expected {FORMAT!r}")
            return cls(data["convention"], data["sides"])
        except (KeyError, TypeError, ValueError) as exc:
            detail = f"missing {exc}" if isinstance(exc, KeyError) else str(exc)
            raise MocapInputError(where, f"not a valid bone map ({detail})") from None

    def save(self, path: str | os.PathLike) -> None:
        """Write the map as a JSON preset, atomically (complete or not at all)."""
        write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike) -> BoneMap:
        """Read a preset written by :meth:`save`; any problem is one :class:`MocapInputError` naming the file."""
        return cls.from_dict(read_json(path, "bone map"), os.fspath(path))


#: How many times more bones the generic name patterns must map than the best named convention to
#: be preferred (a generated Rigify rig's controls before the patterns' reading of its deform bones).
GENERIC_MARGIN = 1.5


def auto_map(names: Iterable[str], parents: Parents = None) -> BoneMap:
    """The bone map of a character with bones ``names`` (and hierarchy ``parents``, see :data:`Parents`):
    the convention in :data:`CONVENTIONS` that maps the most bones (both sides together; ties: the more
    specific convention, in :data:`CONVENTIONS` order, before ``generic``).

    Returns a map with no sides (convention ``generic``) where no hand bone was found.
    """
    names = list(names)
    best = BoneMap(Generic.name)
    for name, convention in CONVENTIONS.items():
        if convention is Generic:
            continue
        found = BoneMap(name, convention.match(names, parents))
        if found.count > best.count:
            best = found
    generic = BoneMap(Generic.name, Generic.match(names, parents))
    # Name patterns also read a known convention's bones (helpers and copies included): they win only
    # where the conventions' tables read clearly fewer.
    return generic if generic.count > GENERIC_MARGIN * best.count else best


def export_names(convention: str, side: str) -> dict[str, str]:
    """Our bone -> the name it gets in ``convention`` (a :data:`CONVENTIONS` key, or ``"ours"``), for
    renaming our rig of hand ``side`` at export; distinct for every bone.

    Bones the convention lacks get stand-ins in its style, which its matching recognises: Mixamo
    ``mixamorig:LeftHandIndex0`` .. ``LeftHandPinky0``, Unity ``LeftIndexMetacarpal`` ..
    ``LeftLittleMetacarpal`` for our finger metacarpals. ``ours`` keeps our names (no side).
    """
    _check_side(side)
    if convention == "ours":
        return {b: b for b in BONE_NAMES}
    if convention not in CONVENTIONS:
        raise ValueError(f"unknown bone naming {convention!r} (known: ours, {', '.join(CONVENTIONS)})")
    cls = CONVENTIONS[convention]
    return {b: cls.export_name(b, side) for b in BONE_NAMES}
