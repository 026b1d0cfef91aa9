"""TRC (Han et al.) and Qualisys TSV readers on the real hand recordings."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import data_path
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.take import read_take

HAN19 = ["ThumbCMC", "ThumbMCP", "ThumbIP", "ThumbTip", "IndexMCP", "IndexPIP", "IndexTip", "MiddleMCP",
         "MiddlePIP", "MiddleTip", "RingMCP", "RingPIP", "RingTip", "PinkyMCP", "PinkyPIP", "PinkyTip",
         "BackHand1", "BackHand2", "BackHand3"]


def test_trc_han2018():
    folder = data_path("hands", "han2018_dense19")
    files = sorted(folder.rglob("*.trc"))
    assert len(files) > 100
    for path in files[:20]:
        take = read_take(path)
        assert take.names == HAN19 and take.rate == 120.0 and take.source_units == "mm"
        assert take.missing_fraction == 0.0
        # Hand markers sit within 30 cm of each other: metres, not millimetres.
        spread = np.nanmax(take.positions, axis=1) - np.nanmin(take.positions, axis=1)
        assert 0.03 < spread.max() < 0.3
    first = files[0].read_text().splitlines()[5].split("\t")
    take = read_take(files[0])
    np.testing.assert_allclose(take.positions[0, 0], np.array(first[2:5], float) / 1000.0, rtol=1e-6)


def test_qualisys_tsv_glove13():
    take = read_take(data_path("hands", "qualisys_glove13", "recording_part1.tsv"))
    assert take.n_frames == 3000 and take.n_points == 21 and take.rate == 100.0
    assert take.names[:3] == ["hand_top", "hand_left", "hand_right"] and "pillow_right" in take.names
    thumb = take.names.index("thumb_tip")
    assert 0.02 < 1 - take.valid[:, thumb].mean() < 0.15  # real occlusions of the thumb tip
    np.testing.assert_allclose(take.positions[0, 0], [0.110406, 0.135075, 0.460584], rtol=1e-6)


def _patched(tmp_path, src, old: str, new: str):
    text = src.read_text()
    assert old in text
    path = tmp_path / src.name
    path.write_text(text.replace(old, new, 1))
    return path


TRC = ("hands", "han2018_dense19", "User1", "capture1", "sequence.20_training_dense_left.trc")  # 27 frames, 19


def test_trc_counts_that_disagree_with_the_rows_are_read_as_the_rows_hold(tmp_path):
    src = data_path(*TRC)
    original = read_take(src)
    take = read_take(_patched(tmp_path, src, "\t27\t19\tmm", "\t27\t60000\tmm"))  # NumMarkers
    np.testing.assert_array_equal(take.positions, original.positions)
    assert take.warnings == ["marker count disagrees: 60000 in NumMarkers, 19 in the marker names; the data "
                             "rows hold 19; read 19 (unnamed markers as *N)"]
    take = read_take(_patched(tmp_path, src, "\tPinkyTip\t", "\t\t"))  # a name left out
    np.testing.assert_array_equal(take.positions, original.positions)
    assert take.names == [n if n != "PinkyTip" else "*15" for n in original.names] and not take.warnings
    take = read_take(_patched(tmp_path, src, "\tBackHand3\t", "\t\t"))  # the last name left out
    assert take.names == original.names[:-1] + ["*18"]
    assert take.warnings == ["marker count disagrees: 19 in NumMarkers, 18 in the marker names; the data rows "
                             "hold 19; read 19 (unnamed markers as *N)"]
    take = read_take(_patched(tmp_path, src, "\t27\t19\tmm", "\t2147483648\t19\tmm"))  # NumFrames
    assert take.n_frames == original.n_frames
    assert take.warnings == ["frame count disagrees: NumFrames says 2147483648, the file holds 26 data rows; "
                             "read 26"]


def test_tsv_counts_that_disagree_with_the_rows_are_read_as_the_rows_hold(tmp_path):
    src = data_path("hands", "qualisys_glove13", "recording_part1.tsv")
    take = read_take(_patched(tmp_path, src, "NO_OF_MARKERS\t21", "NO_OF_MARKERS\t20"))
    assert take.n_points == 21 and take.warnings[0].startswith(
        "marker count disagrees: 20 in NO_OF_MARKERS, 21 in the marker names; the data rows hold 21; read 21")
    take = read_take(_patched(tmp_path, src, "NO_OF_FRAMES\t3000", "NO_OF_FRAMES\t5000"))
    assert take.n_frames == 3000
    assert take.warnings == ["frame count disagrees: NO_OF_FRAMES says 5000, the file holds 3000 data rows; read 3000"]


@pytest.mark.parametrize("rate", ["nan", "-120", "inf", "0"])
def test_a_rate_that_is_no_rate_is_one_clear_error(tmp_path, rate):
    path = _patched(tmp_path, data_path(*TRC), "120\t120\t27", f"{rate}\t{rate}\t27")
    with pytest.raises(MocapInputError, match="no usable frame rate"):
        read_take(path)


@pytest.mark.parametrize("rate", ["1e-320", "1e-6", "0.5"])
def test_an_implausible_rate_is_refused_at_read_time(tmp_path, rate, capsys):
    """Found by the fuzzer: a subnormal DataRate (1e-320) was read, and label then wrote a C3D of rate 0 (the
    file's float32) that the tool itself refuses; 1e-6 Hz was read too."""
    from mocap_autolabel.cli import main

    path = _patched(tmp_path, data_path(*TRC), "120\t120\t27", f"{rate}\t{rate}\t27")
    message = f"{path}: no usable frame rate (DataRate '{rate}', CameraRate '{rate}'; expected 1 to 1,000,000 " \
              f"frames per second)"
    with pytest.raises(MocapInputError) as info:
        read_take(path)
    assert str(info.value) == message
    out = tmp_path / "labeled.c3d"
    assert main(["label", str(path), "-o", str(out)]) == 1
    assert capsys.readouterr().err.strip() == f"error: {message}" and not out.exists()


def test_trc_damage_that_no_count_explains(tmp_path):
    """Found by the fuzzer: a frame number Blender cannot key, and a huge NumMarkers with the names
    line gone (it made 2^31 names)."""
    src = data_path(*TRC)
    take = read_take(_patched(tmp_path, src, "\n0\t0\t", "\n99999999999999999999\t0\t"))
    assert take.first_frame == 1
    assert take.warnings == ["first frame number '99999999999999999999' is not a frame number; frames numbered "
                             "from 1"]
    lines = src.read_text().splitlines()
    lines[2] = lines[2].replace("\t27\t19\t", "\t27\t2147483648\t")
    del lines[3]
    path = tmp_path / "no_names.trc"
    path.write_text("\n".join(lines))
    with pytest.raises(MocapInputError, match="the first data row holds 19 markers but the header states more "
                                              r"\(2147483648 in NumMarkers, 57 in the marker names\)"):
        read_take(path)
