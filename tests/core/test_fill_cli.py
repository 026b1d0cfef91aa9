"""The fill command, label --fill and batch --fill (spline, rigid and pca: no calibration, seconds)."""

from __future__ import annotations

import json

import numpy as np
from mocap_autolabel.batch import BatchSettings, run_batch
from mocap_autolabel.cli import main
from mocap_autolabel.core.formats.c3d import read_c3d, write_c3d
from mocap_autolabel.core.hand import HandModel
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import marker_motion, synthesize
from mocap_autolabel.core.take import Take

HAN19 = load_layout("han19")


def _labeled(path, frames: int = 360) -> np.ndarray:
    """A labeled han19 take with a few gaps written to ``path``; returns the truth ``(F, 19, 3)``."""
    _, truth = marker_motion(HAN19, HandModel(side="right"), frames, seed=5)
    x = truth.astype(np.float32)
    x[100:130, 3] = np.nan  # 0.25 s
    x[200:205, 7] = np.nan
    x[:12, 9] = np.nan  # at the start: left open
    x[150:330, 12] = np.nan  # 1.5 s: left open at the default max gap
    write_c3d(Take(x, list(HAN19.names), 120.0, residuals=np.where(np.isnan(x[..., 0]), np.nan, 0.001)), path)
    return truth


def test_fill_command_writes_the_filled_take_and_reports_every_gap(tmp_path, capsys):
    take, out, report = tmp_path / "labeled.c3d", tmp_path / "filled.c3d", tmp_path / "fill.json"
    truth = _labeled(take)
    assert main(["fill", str(take), "-o", str(out), "--method", "rigid", "--report", str(report)]) == 0
    text = capsys.readouterr().out
    assert "2 of 4 gaps filled (2 rigid; 35 samples), 2 left open" in text
    assert "open     1 gap at the start of the take" in text and "open     1 gap longer than max_gap" in text
    back = read_c3d(out)
    assert back.filled.sum() == 35 and back.filled[100:130, 3].all()
    assert np.abs(back.positions[back.filled] - truth[back.filled]).max() < 0.005
    rep = json.loads(report.read_text())
    assert rep["filled"] == 2 and rep["open"] == 2 and len(rep["gap_list"]) == 4
    gap = next(g for g in rep["gap_list"] if g["marker"] == "ThumbTip")
    assert gap["first_frame"] == 101 and gap["frames"] == 30 and gap["method"] == "rigid"
    assert gap["expected_error_mm"] > 0
    assert main(["fill", str(take), "-o", str(out), "--method", "pca", "--max-gap", "2"]) == 0
    assert "3 of 4 gaps filled (3 pca" in capsys.readouterr().out


def test_fill_command_refuses_bad_input_in_one_line(tmp_path, capsys):
    take = tmp_path / "labeled.c3d"
    _labeled(take)
    out = tmp_path / "filled.c3d"
    assert main(["fill", str(take), "-o", str(tmp_path / "filled.trc")]) == 2
    assert main(["fill", str(take), "-o", str(out), "--max-gap", "0"]) == 2
    assert main(["fill", str(take), "-o", str(out), "--layout", "glove13", "--method", "spline"]) == 1
    err = capsys.readouterr().err
    assert f"{take}: is not labeled with layout 'glove13'" in err and "Traceback" not in err
    assert not out.exists()


def test_label_and_batch_fill(tmp_path, capsys):
    raw = tmp_path / "takes" / "raw.c3d"
    raw.parent.mkdir()
    write_c3d(synthesize(HAN19, 300, seed=1).take, raw)  # two gaps inside the take
    out = tmp_path / "labeled.c3d"
    assert main(["label", str(raw), "-o", str(out), "--fill", "--fill-method", "spline", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "filled   2 of 3 gaps filled (2 spline; 41 samples), 1 left open" in text
    filled = read_c3d(out)
    assert filled.filled is not None and filled.filled[:, :19].any() and not filled.filled[:, 19:].any()
    assert main(["label", str(raw), "--fill"]) == 2  # nowhere to write the fills
    summary = run_batch([str(raw.parent)], str(tmp_path / "batch"), BatchSettings(fill=True, fill_method="spline"),
                        progress="none")
    assert summary["ok"] == 1
    rep = json.loads((tmp_path / "batch" / "raw.report.json").read_text())
    assert rep["fill"]["filled"] >= 1 and rep["fill"]["method"] == "spline"
    back = read_c3d(tmp_path / "batch" / "raw.labeled.c3d")
    np.testing.assert_array_equal(back.filled, filled.filled)


def test_the_command_line_offers_every_fill_method():
    from mocap_autolabel.cli import FILL_METHODS
    from mocap_autolabel.core.fill import METHODS

    assert FILL_METHODS == METHODS


def test_fill_finds_the_layout_the_file_is_labeled_with(tmp_path, capsys):
    glove = load_layout("glove13")
    _, x = marker_motion(glove, HandModel(side="right"), 240, seed=3)
    x = x.astype(np.float32)
    x[100:110, 4] = np.nan
    take = tmp_path / "glove.c3d"
    write_c3d(Take(x, list(glove.names), 100.0), take)
    assert main(["fill", str(take), "-o", str(tmp_path / "out.c3d"), "--method", "spline"]) == 0
    assert "spline fill on glove13" in capsys.readouterr().out
    raw = tmp_path / "raw.c3d"
    write_c3d(Take(x, [f"*{i}" for i in range(len(glove))], 100.0), raw)
    assert main(["fill", str(raw), "-o", str(tmp_path / "out2.c3d")]) == 1
    err = capsys.readouterr().err
    assert "is not labeled with a built-in layout" in err and "--layout" in err and "Traceback" not in err


def test_label_fill_says_why_gaps_stay_open_and_info_counts_fills(tmp_path, capsys):
    take = tmp_path / "take.c3d"
    write_c3d(synthesize(HAN19, 600, seed=1).take, take)
    out, report = tmp_path / "lab.c3d", tmp_path / "lab.json"
    assert main(["label", str(take), "-o", str(out), "--fill", "--fill-method", "spline", "--quiet",
                 "--report", str(report)]) == 0
    text = capsys.readouterr().out
    fill = json.loads(report.read_text())["fill"]
    assert fill["filled"] > 0 and fill["open"] > 0  # the test can tell
    said = sum(int(line.split()[1]) for line in text.splitlines() if line.startswith("  open     "))
    assert said == fill["open"]  # each open gap with its reason
    filled = read_c3d(out).filled.sum()
    assert filled == fill["filled_samples"]
    assert main(["info", str(out)]) == 0
    assert f"filled   {filled} samples marked as computed" in capsys.readouterr().out
    assert main(["label", str(take), "-o", str(out), "--max-gap", "0.5"]) == 2  # not without --fill
    assert "are for --fill" in capsys.readouterr().err
