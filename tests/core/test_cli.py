"""The command line, in-process (python -m) and as a Blender -P script."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, data_path
from helpers import small_take
from mocap_autolabel.cli import main
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import synthesize


def test_info_real_file(capsys):
    path = data_path("c3d", "auto-marker-label/data/S01_Pronetokneel01_mksrem.c3d")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "76 (unlabeled (*N))" in out and "2176 from 1 at 240 Hz" in out and "20.69 %" in out


def test_info_json_and_failures(capsys, tmp_path):
    good = tmp_path / "good.c3d"
    write_c3d(small_take(), good)
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"")
    assert main(["info", "--json", str(good), str(bad)]) == 1
    captured = capsys.readouterr()
    summary = json.loads(captured.out.strip())
    assert summary["points"] == 4 and summary["frames"] == 50 and summary["vendor"].startswith("mocap_autolabel")
    assert captured.err.strip() == f"error: {bad}: file is empty (0 bytes)"


def test_usage_errors_exit_2(capsys):
    assert main([]) == 2
    assert main(["frobnicate"]) == 2
    assert main(["import", "x.c3d"]) == 2  # --blend is required
    assert main(["import", "x.c3d", "--blend", "x.txt"]) == 2
    assert "Traceback" not in capsys.readouterr().err


def _script(*args: str) -> subprocess.CompletedProcess:
    """Run cli.py as Blender runs a -P script: by path, with the arguments after '--'."""
    return subprocess.run([sys.executable, str(ROOT / "addon" / "mocap_autolabel" / "cli.py"), "--", *args],
                          capture_output=True, text=True, timeout=120, cwd=Path(ROOT).parent)


def test_script_mode_like_blender_dash_p(tmp_path):
    good = tmp_path / "good.c3d"
    write_c3d(small_take(), good)
    result = _script("info", str(good))
    assert result.returncode == 0 and "points   4" in result.stdout
    result = _script("info", str(tmp_path / "missing.c3d"))
    assert result.returncode == 1 and result.stderr.strip().endswith("missing.c3d: no such file")
    assert _script().returncode == 2


def test_label_demo_take_writes_labeled_c3d_report_and_labels(capsys, tmp_path):
    import numpy as np
    from mocap_autolabel.core.take import read_take

    demo = ROOT / "samples" / "demo_take.c3d"
    out, report, labels = tmp_path / "labeled.c3d", tmp_path / "report.json", tmp_path / "labels.npz"
    assert main(["label", str(demo), "-o", str(out), "--report", str(report), "--labels", str(labels)]) == 0
    text = capsys.readouterr().out
    assert "set + vote on han19, 1200 frames" in text and "% correct" in text
    raw, labeled = read_take(demo), read_take(out)
    assert labeled.names[:19] == load_layout("han19").names
    assert all(n.startswith("*") for n in labeled.names[19:])
    assert labeled.valid.sum() == raw.valid.sum()  # every sample kept, once
    rep = json.loads(report.read_text())
    assert rep["info"]["method"] == "set" and rep["info"]["temporal"] == "vote"
    assert rep["truth"]["instances"] == 1200 * 19 and 0.0 <= rep["summary"]["confident_share"] <= 1.0
    saved = np.load(labels)
    assert saved["labels"].shape == saved["confidence"].shape == (1200, raw.n_points)


def test_the_truth_line_scores_by_label_name_and_not_a_one_hand_labeling_of_two_hands(capsys, tmp_path):
    # A two-hand truth (L_ and R_ labels) holds nothing to score a labeling of one hand's labels by;
    # read as two hands, each label is scored against its own name's truth.
    take = tmp_path / "two.c3d"
    assert main(["synth", "--layout", "han19", "--hands", "2", "--frames", "200", "--seed", "3", "-o", str(take)]) == 0
    capsys.readouterr()
    report = tmp_path / "r.json"
    assert main(["label", str(take), "--hands", "1", "--report", str(report)]) == 0
    text = capsys.readouterr().out
    assert "not scored: it names 38 labels (L_ThumbCMC...), this labeling 19 (ThumbCMC...)" in text
    assert "% correct" not in text and "truth" not in json.loads(report.read_text())
    assert main(["label", str(take), "--report", str(report)]) == 0
    assert "% correct" in capsys.readouterr().out
    assert json.loads(report.read_text())["truth"]["accuracy"] > 0.95


def test_label_notes_heavy_occlusion_where_the_occlusion_prior_acted(capsys, tmp_path):
    from mocap_autolabel.core.synth.generate import TakeCorruption, corrupt_take

    s = synthesize(load_layout("han19"), 600, seed=7)
    heavy = TakeCorruption(gaps_per_minute=138, mean_gap_s=0.125, persistent_ghosts=3, noise_sd=0.001)
    take, _, _ = corrupt_take(s.markers, s.take.rate, seed=7, cfg=heavy)
    for name, raw in (("heavy", take), ("plain", s.take)):
        write_c3d(raw, tmp_path / f"{name}.c3d")
        assert main(["label", str(tmp_path / f"{name}.c3d")]) == 0
        text = capsys.readouterr().out
        assert ("note     heavy occlusion: the take's trajectories break" in text) == (name == "heavy")


def test_label_with_the_wrong_layout_warns_or_refuses_and_names_the_right_one(capsys, tmp_path):
    take = tmp_path / "glove.c3d"  # a glove13 take labeled with han19: a hand, but the wrong layout
    write_c3d(synthesize(load_layout("glove13"), 300, seed=4).take, take)  # half a han19 hand in most frames
    report = tmp_path / "report.json"
    assert main(["label", str(take), "--report", str(report)]) == 0
    text = capsys.readouterr().out
    assert "warning  only " in text and "% of labeled samples are confident with layout 'han19'" in text
    assert "is this a glove13 take? (--layout glove13)" in text
    doubt = json.loads(report.read_text())["info"]["layout_doubt"]
    assert doubt["layout"] == "han19" and doubt["better"] == "glove13" and doubt["share"] < doubt["better_share"]
    assert main(["label", str(take), "--layout", "glove13", "--report", str(report)]) == 0
    assert "warning" not in capsys.readouterr().out
    assert "layout_doubt" not in json.loads(report.read_text())["info"]
    demo = ROOT / "samples" / "demo_take.c3d"  # a han19 take labeled with glove13: no hand found, as in batch
    assert main(["label", str(demo), "--layout", "glove13", "--report", str(report)]) == 1
    err = capsys.readouterr().err
    assert "no hand found" in err and "'han19' fits better: use --layout han19" in err


def test_label_script_mode_writes_c3d(tmp_path):
    out = tmp_path / "labeled.c3d"
    result = _script("label", str(ROOT / "samples" / "demo_take.c3d"), "--temporal", "none", "-o", str(out))
    assert result.returncode == 0, result.stderr
    assert out.is_file() and "set + none" in result.stdout


def test_label_errors(capsys, tmp_path):
    demo = str(ROOT / "samples" / "demo_take.c3d")
    assert main(["label", demo, "--model", str(tmp_path / "missing.onnx")]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"error: {tmp_path / 'missing.onnx'}: model file not found"
    assert main(["train", "--layout", "han19", "-o", "model.pt"]) == 2
    assert main(["label", demo, "-o", str(tmp_path / "out.trc")]) == 2
    assert main(["label", demo, "--layout", "no_such_layout", "-o", str(tmp_path / "x.c3d")]) == 1
    assert "no_such_layout" in capsys.readouterr().err and not (tmp_path / "x.c3d").exists()


@pytest.mark.slow
def test_train_command_writes_a_model_and_card(tmp_path, capsys):
    pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch==2.13.0)")
    pytest.importorskip("onnx", reason="onnx is not installed")
    out = tmp_path / "tips3.onnx"
    assert main(["train", "--layout", "tips3", "-o", str(out), "--steps", "20"]) == 0
    captured = capsys.readouterr()
    assert "ETA" in captured.err and "20/20 steps" in captured.err
    card = json.loads((tmp_path / "tips3.json").read_text())
    assert card["layout"]["name"] == "tips3" and card["method"] == "set"
    # The model labels (20 steps are too few to find the hand: the CLI would refuse the take, as batch does)
    from mocap_autolabel.core.pipeline import label_take
    from mocap_autolabel.core.settings import LabelSettings
    from mocap_autolabel.core.take import read_take

    labeling = label_take(read_take(ROOT / "samples" / "demo_take.c3d"), load_layout("tips3"),
                          LabelSettings(model=str(out)))
    assert labeling.n_frames == 1200 and labeling.info["layout"] == "tips3"


def test_train_on_a_gpu_that_is_not_there_is_one_line_and_writes_nothing(tmp_path, capsys):
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch==2.13.0)")
    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA GPU: --device cuda trains there")
    out = tmp_path / "tips3.onnx"
    assert main(["train", "--layout", "tips3", "-o", str(out), "--steps", "20", "--device", "cuda"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error: --device cuda:") and "no CUDA GPU" in err[-1]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("parts", [("c3d", "ezc3d-testFiles", "Vicon.c3d"),
                                   pytest.param(("c3d", "auto-marker-label", "data", "S01_Pronetokneel01_mksrem.c3d"),
                                                marks=pytest.mark.slow)])
def test_label_a_body_take_fails_with_batchs_no_hand_rule(parts, capsys, tmp_path):
    """Body captures (no hand) used to exit 0 with body markers named as fingers; now the CLI applies
    batch's rule: one error line, exit 1, nothing written."""
    path = str(data_path(*parts))
    out, report = tmp_path / "labeled.c3d", tmp_path / "report.json"
    assert main(["label", path, "-o", str(out), "--report", str(report)]) == 1
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: no hand found: only ")
    assert "of the han19 markers labeled" in lines[0] and "unexpected" not in lines[0]
    assert not out.exists() and not report.exists() and not captured.out


def test_label_without_outputs_says_that_nothing_was_written(capsys):
    assert main(["label", str(ROOT / "samples" / "demo_take.c3d")]) == 0
    out = capsys.readouterr().out
    assert "  output   none written: give -o OUT.c3d" in out


def test_label_and_solve_progress_bar_on_stderr_only_when_shown(capsys, monkeypatch, tmp_path):
    from mocap_autolabel import cli

    monkeypatch.setattr(cli._ProgressBar, "DELAY", 0.0)  # the demo take is short: draw from the start
    demo = str(ROOT / "samples" / "demo_take.c3d")
    out = tmp_path / "labeled.c3d"
    assert main(["label", demo, "-o", str(out), "--progress"]) == 0
    captured = capsys.readouterr()
    assert "scoring 1200 frames with set" in captured.err and "] 100 %" in captured.err
    assert "%  scoring" not in captured.out  # the results alone on stdout
    assert main(["label", demo, "--progress", "--quiet"]) == 2  # one or the other
    capsys.readouterr()
    for quiet in (["--quiet"], []):  # --quiet, or not a terminal (pytest's capture) and not asked
        assert main(["label", demo] + quiet) == 0
        assert "scoring" not in capsys.readouterr().err
    assert main(["solve", str(out), "--progress"]) == 0
    assert "calibrating and solving the hand" in capsys.readouterr().err


def test_foreseeable_failures_say_what_is_wrong_in_one_line(capsys, tmp_path):
    demo = str(ROOT / "samples" / "demo_take.c3d")
    assert main(["label", demo, "--report", str(tmp_path)]) == 1
    assert capsys.readouterr().err.strip() == f"error: {tmp_path}: is a folder; give a file name"
    vicon = str(data_path("c3d", "ezc3d-testFiles", "Vicon.c3d"))
    assert main(["label", vicon, "--validate"]) == 1
    err = capsys.readouterr().err.strip()
    # A body capture: too few labels for a hand, or labels scattered wider than any hand.
    assert err.startswith(f"error: {vicon}: IK validation: ") and "no hand found (is this a han19 take?)" in err
    assert "unexpected" not in err and len(err.splitlines()) == 1


#: gmm fitted on han19's synthetic range of motion labels 81.2 % of the demo take's instances right
#: (set + vote: 99.98 %).
GMM_ROM_ACCURACY = 0.78


def test_label_gmm_without_fit_fits_the_layouts_synthetic_range_of_motion(capsys, tmp_path):
    """`label --method gmm` was a usage error without --fit; now it fits on synthetic hands."""
    report = tmp_path / "report.json"
    assert main(["label", str(ROOT / "samples" / "demo_take.c3d"), "--method", "gmm", "--report", str(report),
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "gmm + vote on han19" in out and "note     gmm fitted on the han19 synthetic range of motion" in out
    assert json.loads(report.read_text())["truth"]["accuracy"] > GMM_ROM_ACCURACY


@pytest.mark.parametrize("method", ["perm", "cnn"])
def test_label_says_why_perm_and_cnn_leave_every_segment_for_review(method, capsys):
    assert main(["label", str(ROOT / "samples" / "demo_take.c3d"), "--method", method]) == 0
    out = capsys.readouterr().out  # a hand take: labeled (their low per-frame probabilities found no hand before)
    assert f"note     {method} + vote never rates a segment confident on han19" in out


def test_the_command_lines_choices_are_the_registries():
    """The command line spells the methods out (its --help imports no numpy); they must be the
    registries' names, in the registries' order (the first is the default)."""
    from mocap_autolabel.commands.common import FILL_METHODS, LABEL_METHODS, TEMPORAL_MODES
    from mocap_autolabel.core.fill import FILL_METHODS as FILLS
    from mocap_autolabel.core.labelers import LABELERS
    from mocap_autolabel.core.process import TEMPORAL_MODES as MODES

    assert LABEL_METHODS == tuple(LABELERS) and TEMPORAL_MODES == tuple(MODES) and FILL_METHODS == tuple(FILLS)
    args = main.__globals__["build_parser"]().parse_args(["label", "take.c3d"])
    assert (args.method, args.temporal, args.fill_method) == (LABEL_METHODS[0], TEMPORAL_MODES[0], FILL_METHODS[0])
