"""Marker layouts: built-ins with the real files' names, user TOML files, placement on the hand."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import data_path
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.hand import HandModel, blend
from mocap_autolabel.core.hand.skeleton import BONE_INDEX, DOF_INDEX
from mocap_autolabel.core.layout import builtin_layouts, load_layout
from mocap_autolabel.core.take import read_take

HAN19 = ["ThumbCMC", "ThumbMCP", "ThumbIP", "ThumbTip", "IndexMCP", "IndexPIP", "IndexTip", "MiddleMCP",
         "MiddlePIP", "MiddleTip", "RingMCP", "RingPIP", "RingTip", "PinkyMCP", "PinkyPIP", "PinkyTip",
         "BackHand1", "BackHand2", "BackHand3"]

#: Median distances (mm) between neighbouring han19 markers, from HAND.md.
HAN19_MEDIANS = {("BackHand1", "BackHand2"): 31, ("BackHand2", "BackHand3"): 37, ("BackHand1", "MiddleMCP"): 65,
                 ("ThumbCMC", "ThumbMCP"): 33, ("ThumbMCP", "ThumbIP"): 30, ("ThumbIP", "ThumbTip"): 25,
                 ("IndexMCP", "IndexPIP"): 29.5, ("IndexPIP", "IndexTip"): 29.5}


def relaxed_pose() -> np.ndarray:
    """HAND.md's relaxed pose: thumb (10, 30, 10, 10); fingers 20-30-15 (index) ... 35-45-30 (little)."""
    pose = np.zeros(26)
    deg = {"thumb_cmc_flex": 10, "thumb_cmc_abd": 30, "thumb_mcp": 10, "thumb_ip": 10}
    for f, (a, b, c) in zip(("index", "middle", "ring", "little"), ((20, 30, 15), (25, 35, 20), (30, 40, 25),
                                                                       (35, 45, 30))):
        deg |= {f"{f}_mcp_flex": a, f"{f}_pip": b, f"{f}_dip": c}
    for k, v in deg.items():
        pose[DOF_INDEX[k]] = np.radians(v)
    return pose


def test_builtins():
    assert {"han19", "glove13", "tips5", "tips3", "tips10"} <= set(builtin_layouts())
    assert load_layout("han19").names == HAN19
    assert len(load_layout("tips5")) == 5 and len(load_layout("tips3")) == 3 and len(load_layout("tips10")) == 10
    assert [m.bone for m in load_layout("tips3").markers] == ["thumb_dist", "index_dist", "little_dist"]


@pytest.mark.parametrize("side", ["left", "right"])
def test_han19_distances_in_relaxed_pose_match_hand_md(side):
    hand = HandModel(length=0.190, breadth=0.085, side=side)
    layout = load_layout("han19")
    binding, _ = layout.place(hand)
    points = blend(*hand.skinning_transforms(relaxed_pose()[None]), binding)[0] * 1000
    idx = {n: i for i, n in enumerate(layout.names)}
    for (a, b), median in HAN19_MEDIANS.items():
        d = np.linalg.norm(points[idx[a]] - points[idx[b]])
        assert abs(d / median - 1) <= 0.25, (a, b, d, median)


def test_han19_names_are_the_trc_files_names():
    folder = data_path("hands", "han2018_dense19")
    trc = next(folder.rglob("*.trc"))
    assert read_take(trc).names == HAN19


def test_glove13_names_are_the_recordings_hand_markers():
    take = read_take(data_path("hands", "qualisys_glove13", "recording_part1.tsv"))
    layout = load_layout("glove13")
    assert len(layout) == 13
    assert set(layout.names) <= set(take.names)
    others = set(take.names) - set(layout.names)
    assert all(n.startswith(("right_", "back_", "pillow_")) for n in others)


def test_markers_sit_outside_the_skin_on_the_back_of_the_digit():
    hand = HandModel(side="right")
    layout = load_layout("tips10")
    binding, normals = layout.place(hand)
    r0, p0 = hand.rest
    for m, pos, normal in zip(layout.markers, binding.rest, normals):
        b = BONE_INDEX[m.bone]
        local = r0[b].T @ (pos - p0[b])
        radial = np.hypot(local[0], local[2])
        radius = np.interp(m.along, [0, 1], hand.bone_radii[b])
        assert radial == pytest.approx(radius + m.radius + layout.glove)
        assert local[2] > 0  # dorsal
        assert np.dot(normal, r0[b][:, 2]) == pytest.approx(1.0)


def test_user_layout_file(tmp_path):
    path = tmp_path / "studio.toml"
    path.write_text('''
name = "studio4"
radius_mm = 4.0
[[markers]]
name = "RH_thumb"
bone = "thumb_dist"
along = 0.8
[[markers]]
name = "RH_index"
bone = "index_dist"
angle_deg = 45
radius_mm = 2.5
[[markers]]
name = "RH_back"
bone = "palm"
along = 0.3
across = 0.0
[[markers]]
name = "RH_ring"
bone = "ring_prox"
offset_mm = [0, 20, 14]
''')
    layout = load_layout(path)
    assert layout.name == "studio4" and layout.names == ["RH_thumb", "RH_index", "RH_back", "RH_ring"]
    assert layout.markers[0].radius == pytest.approx(0.004) and layout.markers[1].radius == pytest.approx(0.0025)
    hand = HandModel(length=0.2, breadth=0.09, side="left")
    binding, _ = layout.place(hand)
    r0, p0 = hand.rest
    b = BONE_INDEX["ring_prox"]
    assert np.allclose(binding.rest[3], r0[b] @ [0, 0.02, 0.014] + p0[b])
    assert binding.rest[2][1] == pytest.approx(0.3 * 0.2)


@pytest.mark.parametrize("text, problem", [
    ('[[markers]]\nname = "a"\nbone = "wrist"\n', "bone 'wrist'"),
    ('[[markers]]\nname = "a"\nbone = "palm"\n[[markers]]\nname = "a"\nbone = "palm"\n', "appears twice"),
    ('[[markers]]\nname = "a"\nbone = "palm"\ncolour = 3\n', "unknown key"),
    ('[[markers]]\nname = "a"\nbone = "index_dist"\nside = "up"\n', "side 'up'"),
    ('[[markers]]\nname = "a"\nbone = "index_dist"\nradius_mm = 80\n', "not a marker size"),
    ('name = "empty"\n', "no [[markers]]"),
    ('[[markers]\nname = ', "not a readable TOML"),
])
def test_bad_layout_files_name_the_file_and_the_problem(tmp_path, text, problem):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(MocapInputError) as err:
        load_layout(path)
    assert str(path) in str(err.value) and problem in str(err.value)


def test_unknown_layout_name_lists_the_builtins(tmp_path):
    with pytest.raises(MocapInputError, match="han19"):
        load_layout("han91")
    with pytest.raises(MocapInputError, match="not found"):
        load_layout(tmp_path / "missing.toml")
