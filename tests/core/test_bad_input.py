"""Bad input: one clear error naming the file, never a traceback or a half-written output."""

from __future__ import annotations

import os

import numpy as np
import pytest
from conftest import data_path
from helpers import small_take
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.take import read_take


@pytest.fixture
def good_c3d(tmp_path):
    path = tmp_path / "good.c3d"
    write_c3d(small_take(frames=200, points=6), path)
    return path


def _error(path) -> str:
    with pytest.raises(MocapInputError) as info:
        read_take(path)
    message = str(info.value)
    assert str(path) in message and "\n" not in message
    return message


def test_truncated_file(good_c3d, tmp_path):
    data = good_c3d.read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(data[: len(data) - 3000])
    assert "truncated" in _error(cut)
    cut.write_bytes(data[:100])  # within the header: it was called "not a C3D file"
    assert "truncated C3D file: 100 bytes, shorter than its 512-byte header" in _error(cut)


def test_truncated_real_file(tmp_path):
    src = data_path("c3d", "MocapRecovery/data/85_02.c3d")
    cut = tmp_path / "85_02_cut.c3d"
    cut.write_bytes(src.read_bytes()[: src.stat().st_size // 2])
    assert "truncated" in _error(cut)


def test_a_cut_off_text_file_says_which_row_is_short(tmp_path):
    """The glove recording cut mid-row: the row and its column count, not numpy's "Some errors were
    detected !" (as Blender's import showed it)."""
    src = data_path("hands", "qualisys_glove13", "recording_part1.tsv")
    cut = tmp_path / "glove_cut.tsv"
    cut.write_bytes(src.read_bytes()[:5000])
    message = _error(cut)
    assert "malformed marker table: data row 7 has 55 columns instead of 65 (is the file cut off" in message
    assert "Some errors" not in message


def test_random_bytes(tmp_path):
    path = tmp_path / "noise.c3d"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 20000, dtype=np.uint8).tobytes())
    assert "not a C3D file" in _error(path)


def test_file_shorter_than_a_header(tmp_path):
    path = tmp_path / "short.c3d"
    path.write_bytes(b"\x02\x50\x00")
    assert "truncated C3D file: 3 bytes" in _error(path)  # it begins as a C3D header does


def test_parameter_section_past_the_end(good_c3d, tmp_path):
    data = bytearray(good_c3d.read_bytes())
    data[0] = 250  # parameter block 250: far past the end of a small file
    path = tmp_path / "badptr.c3d"
    path.write_bytes(bytes(data))
    assert "outside the file" in _error(path)


def test_absurd_point_count_is_an_error_not_a_huge_allocation(good_c3d, tmp_path):
    """60,000 points in the header and in POINT:USED: no layout fits the data, nothing is allocated.
    (60,000 in the header alone is a disagreement that POINT:USED resolves: see test_c3d_corpus.)"""
    data = bytearray(good_c3d.read_bytes())
    data[2:4] = (60000).to_bytes(2, "little")  # header point count
    used = _parameter_value_offset(data, b"USED", 6)
    data[used:used + 2] = (60000).to_bytes(2, "little")
    path = tmp_path / "huge.c3d"
    path.write_bytes(bytes(data))
    assert "truncated" in _error(path)


def _parameter_value_offset(data: bytes, name: bytes, value: int) -> int:
    """Byte offset of the 16-bit value ``value`` of an Intel parameter ``name`` (locked or not) that has
    no dimensions."""
    at = 512
    while True:
        at = data.index(name, at + 1)
        start = at + len(name) + 4  # 2 bytes offset to the next record, type, number of dimensions
        named = data[at - 2] in (len(name), 256 - len(name))
        if named and data[start - 1] == 0 and data[start:start + 2] == value.to_bytes(2, "little"):
            return start


def test_missing_unknown_and_folder(tmp_path):
    assert "no such file" in _error(tmp_path / "absent.c3d")
    other = tmp_path / "take.fbx"
    other.write_text("x")
    assert "unknown file type" in _error(other)
    folder = tmp_path / "folder.c3d"
    folder.mkdir()
    assert "folder" in _error(folder)


def test_bad_text_files(tmp_path):
    trc = tmp_path / "bad.trc"
    trc.write_text("hello\nworld\n")
    assert "not a TRC file" in _error(trc)
    tsv = tmp_path / "bad.tsv"
    tsv.write_bytes(b"\xff\xfe\x00garbage")
    assert "not a text file" in _error(tsv)
    tsv.write_text("NO_OF_FRAMES\t3\n")
    assert "not a Qualisys TSV" in _error(tsv)


def test_wrong_units_warns(tmp_path):
    take = small_take()
    take.positions *= 1000.0  # metres written where millimetres were meant
    path = tmp_path / "units.c3d"
    write_c3d(take, path, units="m")
    assert any("unit" in w and "wrong" in w for w in read_take(path).warnings)


def test_failed_write_leaves_nothing(tmp_path):
    take = small_take()
    target = tmp_path / "out.c3d"
    with pytest.raises(MocapInputError):
        write_c3d(take, target, units="parsec")
    assert os.listdir(tmp_path) == []


def test_an_unknown_processor_type_is_named_not_the_parsers_internal_error(good_c3d, tmp_path):
    data = bytearray(good_c3d.read_bytes())
    data[(data[0] - 1) * 512 + 3] = 99  # the parameter section's processor type: 84, 85 or 86
    bad = tmp_path / "processor.c3d"
    bad.write_bytes(bytes(data))
    message = _error(bad)
    assert "unknown processor type 99" in message and "84 (Intel)" in message
    assert "local variable" not in message and "float_unpack" not in message


def test_solving_or_filling_a_take_that_is_not_labeled_yet_says_label_it_first(good_c3d, capsys):
    from mocap_autolabel.cli import main

    for command in (["solve", str(good_c3d), "--layout", "han19"],
                    ["fill", str(good_c3d), "--layout", "tips5", "-o", str(good_c3d.with_name("f.c3d"))]):
        assert main(command) == 1
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and str(good_c3d) in err and "label it first" in err, err
    assert not good_c3d.with_name("f.c3d").exists()
