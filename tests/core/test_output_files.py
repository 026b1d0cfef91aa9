"""Output files (issue 47): any name the OS accepts, a folder in the way, a folder that cannot be written, a
full device, a take of no frames; one line naming the output that failed, and no partial file left anywhere."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest
from helpers import small_take
from mocap_autolabel.cli import main
from mocap_autolabel.core.atomic import atomic_output
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.formats.c3d import read_c3d, write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import synthesize
from mocap_autolabel.core.take import Take, read_take


@pytest.fixture(scope="module")
def raw(tmp_path_factory) -> Path:
    """A short raw han19 take to label."""
    path = tmp_path_factory.mktemp("raw") / "raw.c3d"
    write_c3d(synthesize(load_layout("han19"), 150, seed=2).take, path)
    return path


@pytest.fixture
def unwritable(tmp_path):
    """A folder this process cannot create a file in: a read-only one, or /sys (sysfs) for root, whom
    permissions do not stop."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        if _can_create_in(folder):
            folder = Path("/sys")
            if not folder.is_dir() or _can_create_in(folder):
                pytest.skip("no folder this process cannot write in (root, and no /sys)")
        yield folder
    finally:
        (tmp_path / "read-only").chmod(0o755)


def _can_create_in(folder: Path) -> bool:
    try:
        (folder / ".probe").open("x").close()
    except OSError:
        return False
    (folder / ".probe").unlink()
    return True


def _partials(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if ".partial" in p.name]


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and ".partial" not in err, err
    return err


@pytest.mark.parametrize("name", ["x.C3D", "with space.c3d", "ñandú 日本 ü.c3d", "no_extension", "x.c3d.C3D",
                                  "a" * 251 + ".c3d"])
def test_write_c3d_writes_any_name_the_os_accepts(tmp_path, name):
    """ezc3d appends ".c3d" to a name that does not end so: an upper-case .C3D failed, leaving a partial file."""
    take = small_take()
    write_c3d(take, tmp_path / name)
    assert os.listdir(tmp_path) == [name]  # nothing else, no partial file
    back = read_c3d(tmp_path / name)
    np.testing.assert_array_equal(back.valid, take.valid)
    np.testing.assert_allclose(back.positions[back.valid], take.positions[take.valid], atol=1e-6)


def test_label_and_fill_write_upper_case_and_non_ascii_outputs(raw, tmp_path, capsys):
    labeled, filled = tmp_path / "labeled take.C3D", tmp_path / "gefüllt.C3D"
    assert main(["label", str(raw), "-o", str(labeled)]) == 0
    assert main(["fill", str(labeled), "-o", str(filled), "--method", "spline"]) == 0
    assert read_take(labeled).names[:19] == load_layout("han19").names
    assert read_take(filled).n_frames == 150
    assert sorted(os.listdir(tmp_path)) == sorted([labeled.name, filled.name])


@pytest.mark.parametrize("name", ["folder.c3d", "folder"])
def test_an_output_that_is_a_folder_is_one_line_naming_it(raw, tmp_path, capsys, name):
    folder = tmp_path / name
    folder.mkdir()
    with pytest.raises(IsADirectoryError) as info:
        write_c3d(small_take(), folder)
    assert info.value.filename == str(folder) and info.value.strerror == "is a folder; give a file name"
    assert os.listdir(tmp_path) == [name] and os.listdir(folder) == []  # no partial file beside it
    if name.endswith(".c3d"):
        assert main(["label", str(raw), "-o", str(folder)]) == 1
        assert _error_line(capsys) == f"error: {folder}: is a folder; give a file name"
    assert os.listdir(tmp_path) == [name] and os.listdir(folder) == []


@pytest.mark.parametrize("flag, name", [("-o", "out.c3d"), ("--report", "report.json"), ("--html", "page.html"),
                                        ("--labels", "labels.npz")])
def test_an_output_in_a_folder_that_cannot_be_written_names_the_output_and_the_cause(raw, unwritable, capsys,
                                                                                     flag, name):
    """It named a hidden temporary file as missing ("ro/.out.0fc9dd3d.partial.c3d: No such file or
    directory"), or the input take for a report."""
    if flag == "--html":
        pytest.importorskip("matplotlib", reason="the HTML page needs matplotlib")
    out = unwritable / name
    assert main(["label", str(raw), flag, str(out)]) == 1
    err = _error_line(capsys)
    assert err.startswith(f"error: {out}: cannot write in {unwritable} (") and err.endswith(
        ("(Permission denied)", "(Read-only file system)")), err
    assert not out.exists() and not _partials(unwritable)


def test_every_output_is_checked_before_the_work_so_a_bad_one_leaves_no_other_written(raw, unwritable, tmp_path,
                                                                                      capsys):
    """``label -o x.c3d --report dir.json`` (a folder) wrote x.c3d, then failed on the report."""
    labeled, folder = tmp_path / "x.c3d", tmp_path / "dir.json"
    folder.mkdir()
    assert main(["label", str(raw), "-o", str(labeled), "--report", str(folder)]) == 1
    assert _error_line(capsys) == f"error: {folder}: is a folder; give a file name"
    assert main(["label", str(raw), "-o", str(labeled), "--report", str(unwritable / "r.json")]) == 1
    assert _error_line(capsys).startswith(f"error: {unwritable / 'r.json'}: cannot write in {unwritable} (")
    assert main(["label", str(raw), "--report", str(tmp_path / "r.json"), "-o", str(unwritable / "x.c3d")]) == 1
    _error_line(capsys)
    assert main(["label", str(raw), "-o", str(labeled)]) == 0
    capsys.readouterr()
    filled = tmp_path / "filled.c3d"
    assert main(["fill", str(labeled), "-o", str(filled), "--method", "spline", "--report", str(folder)]) == 1
    assert _error_line(capsys) == f"error: {folder}: is a folder; give a file name"
    assert sorted(os.listdir(tmp_path)) == ["dir.json", "read-only", "x.c3d"] and not os.listdir(folder)


def test_an_output_is_never_an_input_nor_two_outputs_one_file(raw, tmp_path, capsys):
    """``label take.c3d -o take.c3d`` replaced the raw capture with the labeled one."""
    take = tmp_path / "take.c3d"
    take.write_bytes(raw.read_bytes())
    assert main(["label", str(take), "-o", str(take)]) == 1
    assert _error_line(capsys) == f"error: {take}: is an input of this command; give another file name for the output"
    assert take.read_bytes() == raw.read_bytes()
    both = tmp_path / "both.c3d"
    assert main(["label", str(take), "-o", str(both), "--report", str(both)]) == 1
    assert _error_line(capsys) == f"error: {both}: is given for two outputs; give each its own file name"
    assert sorted(os.listdir(tmp_path)) == ["take.c3d"]


def test_a_report_on_a_full_device_names_the_report(raw, tmp_path, capsys):
    """/dev/full: every write fails with ENOSPC, as on a full disk. A device is written in place (renaming a
    file onto it would replace the device itself)."""
    full = Path("/dev/full")
    if not full.is_char_device():
        pytest.skip("no /dev/full")
    with atomic_output(full) as tmp:  # written in place: nothing would be renamed onto the device
        assert tmp == str(full)
    assert main(["label", str(raw), "--report", str(full)]) == 1
    assert _error_line(capsys) == f"error: {full}: No space left on device"
    assert main(["label", str(raw), "-o", str(tmp_path / "labeled.c3d")]) == 0
    assert main(["fill", str(tmp_path / "labeled.c3d"), "-o", str(tmp_path / "filled.c3d"), "--method", "spline",
                 "--report", str(full)]) == 1
    assert _error_line(capsys) == f"error: {full}: No space left on device"
    assert stat.S_ISCHR(full.stat().st_mode) and not _partials(tmp_path)
    with pytest.raises(OSError, match="is not a regular file"):  # a C3D is no stream: nothing written in /dev
        write_c3d(small_take(), full)


def test_write_c3d_refuses_a_take_it_could_not_read_back(tmp_path):
    """A take of 0 frames raised ZeroDivisionError inside ezc3d; a subnormal rate wrote a file of rate 0."""
    with pytest.raises(MocapInputError, match=r"out.c3d: cannot write a C3D of a take with no frames"):
        write_c3d(Take(np.zeros((0, 3, 3), np.float32), ["a", "b", "c"], 100.0), tmp_path / "out.c3d")
    take = small_take()
    for rate in (1e-320, 1e-6, 0.5):
        with pytest.raises(MocapInputError, match="cannot write a C3D at .* frames per second"):
            write_c3d(Take(take.positions, take.names, rate), tmp_path / "out.c3d")
    assert os.listdir(tmp_path) == []


def test_a_c3d_of_an_implausible_rate_is_refused_at_read_time(tmp_path):
    import ezc3d

    c = ezc3d.c3d()  # ezc3d itself writes what write_c3d refuses
    c["parameters"]["POINT"]["RATE"]["value"] = [1e-6]
    c["parameters"]["POINT"]["LABELS"]["value"] = ["a"]
    c["data"]["points"] = np.ones((4, 1, 5))
    path = tmp_path / "slow.c3d"
    c.write(str(path))
    with pytest.raises(MocapInputError, match=r"slow.c3d: no usable frame rate .*expected 1 to 1,000,000"):
        read_take(path)


def test_outputs_sent_to_a_device_are_written_in_place(raw, capsys):
    """``--labels /dev/null`` raised struct.error from zipfile (a zip is sought back and forth); two
    outputs may share a device."""
    null = Path("/dev/null")
    if not null.is_char_device():
        pytest.skip("no /dev/null")
    assert main(["label", str(raw), "--report", str(null), "--labels", str(null), "--quiet"]) == 0
    assert "Traceback" not in capsys.readouterr().err
