"""Every real C3D file in ../shared/data/c3d against c3d/REFERENCE.tsv and against ezc3d."""

from __future__ import annotations

import csv
import struct
import warnings

import numpy as np
import pytest
from conftest import DATA, data_path
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.formats.c3d import read_c3d

REFERENCE = DATA / "c3d" / "REFERENCE.tsv"
ROWS = list(csv.DictReader(REFERENCE.open(), delimiter="\t")) if REFERENCE.exists() else []
WITH_POINT_DATA = [r for r in ROWS if r["frames"]]

# ezc3d reads these with a frame stride that ignores the header's analog word count: from
# frame 1 on its values are shifted (zeros, then other markers' coordinates). Our values
# are continuous and our missing fraction equals REFERENCE's invalid_frac exactly, so here
# ezc3d is the one that is wrong; these files are checked for continuity instead.
EZC3D_MISALIGNED = {
    "BTKCore/Testing/Data/Input/C3DSamples/others/561xxa01_anonym.C3D",
    "pyc3dserver_examples/Samples_C3D/Sample28/dynamic.C3D",
    "pyc3dserver_examples/Samples_C3D/Sample28/standing.C3D",
    "pyc3dserver_examples/Samples_C3D/Sample28/type1.C3D",
}


def _read(row):
    return read_c3d(data_path("c3d", row["path"]))


@pytest.mark.parametrize("row", WITH_POINT_DATA, ids=lambda r: r["path"].rsplit("/", 1)[-1])
def test_file_loads_and_agrees_with_reference(row):
    take = _read(row)
    assert take.n_points == int(row["points"])
    assert take.n_frames == int(row["frames"])
    assert take.rate == pytest.approx(float(row["rate"]), abs=1e-3)
    if row["invalid_frac"] not in ("", "None"):
        assert take.missing_fraction == pytest.approx(float(row["invalid_frac"]), abs=1e-3)
    assert take.positions.dtype == np.float32
    if take.n_points == 0:
        assert any("no 3D points" in w for w in take.warnings)


@pytest.mark.parametrize("row", [r for r in WITH_POINT_DATA if r["points"] != "0"],
                         ids=lambda r: r["path"].rsplit("/", 1)[-1])
def test_positions_match_ezc3d(row):
    ezc3d = pytest.importorskip("ezc3d")
    take = _read(row)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = ezc3d.c3d(str(data_path("c3d", row["path"])))["data"]["points"][:3].transpose(2, 1, 0)
    except Exception:
        pytest.skip("ezc3d cannot read this file (MIPS processor or damaged parameters)")
    mine_mm = take.positions.astype(np.float64) / (1e-3 if take.source_units == "mm" else 1.0) * (
        1.0 if take.source_units == "mm" else 1e3)
    ref_mm = ref * (1.0 if take.source_units == "mm" else 1e3)
    if row["path"] in EZC3D_MISALIGNED:
        step = np.abs(np.diff(mine_mm, axis=0))
        assert np.nanmax(step) < 200.0, "frames are misaligned: a marker jumps > 200 mm between frames"
        return
    ref_missing = np.isnan(ref_mm[..., 0]) | ~ref_mm.any(axis=2)
    np.testing.assert_array_equal(np.isnan(mine_mm[..., 0]), ref_missing)
    both = ~ref_missing
    assert np.abs(mine_mm[both] - ref_mm[both]).max(initial=0.0) < 0.01


@pytest.mark.parametrize("stem,variants", [
    ("io_anim_c3d/test/testfiles/sample01/Eb015{}.c3d", ["pi", "pr", "si", "sr", "vi", "vr"]),
    ("kineticstoolkit/data/c3d_test_suite/Sample02/{}.c3d",
     ["pc_int", "pc_real", "dec_int", "dec_real", "sgi_int", "sgi_real"]),
])
def test_processor_and_format_variants_agree(stem, variants):
    """The same capture stored as Intel, DEC and MIPS, INT and REAL gives the same positions.

    All variants agree within 0.1 mm, except that Sample02's pc_int and sgi_int store some
    samples one integer step (POINT:SCALE = 0.281 mm) away from the REAL files while dec_int
    matches them exactly: a rounding difference inside the c3d.org files themselves, so INT
    versus REAL is allowed one quantisation step there.
    """
    takes = {v: read_c3d(data_path("c3d", stem.format(v))) for v in variants}
    ref = takes[variants[1]]  # a REAL file
    for variant, take in takes.items():
        np.testing.assert_array_equal(np.isnan(take.positions), np.isnan(ref.positions), err_msg=variant)
        assert take.names == ref.names
        bound = 1e-4  # 0.1 mm
        if variant.endswith(("int", "i")) and variant not in ("dec_int", "pi", "si", "vi"):
            bound = 0.28118187e-3 * 1.001
        assert np.nanmax(np.abs(take.positions - ref.positions)) <= bound, variant
    same_encoding = [v for v in variants if v.endswith("real") or v in ("pr", "sr", "vr")]
    for variant in same_encoding:
        np.testing.assert_array_equal(takes[variant].positions, ref.positions, err_msg=variant)


def test_damaged_parameter_sections_are_repaired_and_reported():
    for name in ("badParameterOffset.c3d", "mocap36.c3d"):
        take = read_c3d(data_path("c3d", "BTKCore/Testing/Data/Input/C3DSamples/others", name))
        assert any("repaired parameter section" in w for w in take.warnings)
        assert not any(n.startswith("*") for n in take.names)


def test_empty_file_gives_one_clear_error():
    path = data_path("c3d", "BTKCore/Testing/Data/Input/C3DSamples/others/Empty.c3d")
    with pytest.raises(MocapInputError, match="empty") as info:
        read_c3d(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


VICON = "ezc3d-testFiles/Vicon.c3d"  # Intel REAL, 580 frames of 51 points, data at block 29, 100 Hz


@pytest.mark.parametrize("offset,fmt,value,disagreement", [
    (8, "<H", 900, "frame count disagrees: 900 in the header's first/last frame, 580 in POINT:FRAMES"),
    (8, "<H", 300, "frame count disagrees: 300 in the header's first/last frame, 580 in POINT:FRAMES"),
    (2, "<H", 60000, "point count disagrees: 60000 in the header, 51 in POINT:USED"),
    (16, "<H", 40, "data start disagrees: 40 in the header, 29 in POINT:DATA_START"),
    (12, "<f", 0.01, "sample format disagrees: INT in the header's scale sign, REAL in POINT:SCALE"),
    (20, "<f", 50.0, "frame rate disagrees: 100 Hz in POINT:RATE, 50 Hz in the header"),
], ids=["frames-over", "frames-under", "points", "data-start", "scale-sign", "rate"])
def test_a_header_that_disagrees_with_the_parameters_is_read_as_the_data_holds(tmp_path, offset, fmt, value,
                                                                               disagreement):
    """The header word is wrong, the parameter agrees with the data section's size: the file is read
    as the original, with one warning naming both values (the issue's real case: a header frame range
    past the data, which was refused as "truncated" while ezc3d reads it)."""
    src = data_path("c3d", VICON)
    data = bytearray(src.read_bytes())
    struct.pack_into(fmt, data, offset, value)
    patched = tmp_path / "patched.c3d"
    patched.write_bytes(bytes(data))
    original, take = read_c3d(src), read_c3d(patched)
    np.testing.assert_array_equal(take.positions, original.positions)
    assert take.names == original.names and take.rate == original.rate
    assert [w for w in take.warnings if w not in original.warnings] == [
        next(w for w in take.warnings if w.startswith(disagreement))]
    if disagreement.startswith("frame count"):  # the reference reads as many frames
        ezc3d = pytest.importorskip("ezc3d")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert ezc3d.c3d(str(patched))["data"]["points"].shape[2] == take.n_frames


def test_a_header_and_parameters_that_all_overrun_the_data_are_refused(tmp_path):
    src = data_path("c3d", VICON)
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(src.read_bytes()[:-3000])
    with pytest.raises(MocapInputError, match="truncated: the header declares 580 frames but the data "
                                              "section holds only 579"):
        read_c3d(cut)


def test_an_integer_files_scale_that_disagrees_is_read_with_point_scale_as_ezc3d_does(tmp_path):
    src = data_path("c3d", "io_anim_c3d/test/testfiles/sample01/Eb015pi.c3d")  # Intel INT, POINT:SCALE 0.0833
    data = bytearray(src.read_bytes())
    struct.pack_into("<f", data, 12, 0.5)  # the header's scale
    patched = tmp_path / "scale.c3d"
    patched.write_bytes(bytes(data))
    take = read_c3d(patched)
    np.testing.assert_array_equal(take.positions, read_c3d(src).positions)
    assert take.warnings == ["POINT:SCALE (0.0833333) and the header's scale (0.5) disagree; read with POINT:SCALE"]
    ezc3d = pytest.importorskip("ezc3d")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = ezc3d.c3d(str(patched))["data"]["points"][:3].transpose(2, 1, 0) / 1000.0  # mm
    valid = ~np.isnan(take.positions)
    assert np.abs(take.positions[valid] - ref[valid]).max() < 1e-6


# Intel REAL, 41 points x 140 frames, ANALOG:USED 0, data at block 5 (OptiTrack Motive, no analog data).
NO_ANALOG = "kineticstoolkit/data/kinematics/sample_probing_acromion_R.c3d"


def _optotrak_header(src, dst):
    """``src`` with the header of issue 47's Optotrak export (not in the corpus): a first/last frame range of
    1,149 frames and analog words per frame that the data section does not hold (its parameters say 0)."""
    data = bytearray(src.read_bytes())
    first = struct.unpack_from("<H", data, 6)[0]
    struct.pack_into("<H", data, 8, first + 1148)  # last frame: 1,149 frames
    struct.pack_into("<H", data, 4, 16)  # analog words per frame
    struct.pack_into("<H", data, 18, 1)  # analog samples per frame
    dst.write_bytes(bytes(data))
    return dst


def test_header_analog_words_and_frames_the_data_does_not_hold_are_read_as_ezc3d_does(tmp_path):
    """Issue 47: the header states 1,149 frames and analog words per frame, POINT:FRAMES and ANALOG:USED (0)
    agree with the data section; it was refused as truncated, ezc3d reads POINT:FRAMES frames of points only."""
    ezc3d = pytest.importorskip("ezc3d")
    src = data_path("c3d", NO_ANALOG)
    patched = _optotrak_header(src, tmp_path / "optotrak.c3d")
    original, take = read_c3d(src), read_c3d(patched)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = ezc3d.c3d(str(patched))["data"]["points"][:3].transpose(2, 1, 0)  # file units
    ref = ref * (1e-3 if take.source_units == "mm" else 1.0)
    assert take.n_frames == ref.shape[0] == 140 and take.n_points == ref.shape[1] == 41
    np.testing.assert_array_equal(take.positions, original.positions)
    valid = ~np.isnan(take.positions)
    assert np.abs(take.positions[valid] - ref[valid]).max() < 1e-6
    assert [w for w in take.warnings if w not in original.warnings] == [
        "analog words per frame disagrees: 16 in the header, 0 in ANALOG:USED x ANALOG:RATE/POINT:RATE; read 0 "
        "analog words per frame, which the data section's size supports",
        "frame count disagrees: 1149 in the header's first/last frame, 140 in POINT:FRAMES; read 140 frames, "
        "which the data section's size supports"]


def test_the_same_header_over_a_cut_data_section_is_still_refused_in_one_line(tmp_path):
    patched = _optotrak_header(data_path("c3d", NO_ANALOG), tmp_path / "optotrak.c3d")
    patched.write_bytes(patched.read_bytes()[:-3000])
    with pytest.raises(MocapInputError, match="file is truncated: the header declares 1149 frames") as info:
        read_c3d(patched)
    assert "\n" not in str(info.value)
