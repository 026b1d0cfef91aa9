"""Batch runs with Blender outputs: .blend and rig files, README's batch examples, one- and two-hand folders."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import ROOT
from helpers import synthetic_takes as _synthetic
from mocap_autolabel.batch import BatchSettings, run_batch
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import synthesize
from mocap_autolabel.core.take import read_take


@pytest.mark.slow
def test_blend_and_hand_outputs(tmp_path, bpy_module):
    takes = tmp_path / "takes"
    _synthetic(takes, 1, frames=400)
    start = time.perf_counter()
    summary = run_batch([str(takes)], str(tmp_path / "out"), BatchSettings(blend=True, fbx=True), progress="none")
    assert summary["ok"] == 1, summary["takes_detail"]
    report = json.loads((tmp_path / "out" / "synth0.report.json").read_text())
    assert report["outputs"] == {"labeled": "synth0.labeled.c3d", "blend": "synth0.blend", "fbx": "synth0.fbx"}
    assert report["hand"]["marker_rms_mm"] < 8 and time.perf_counter() - start < 300
    assert (tmp_path / "out" / "synth0.blend").stat().st_size > 0


def _readme_batch_examples() -> tuple[str, list[str]]:
    """README's batch settings file (the TOML block of "Batch runs") and its batch command lines."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## Batch runs"):]
    toml = section[section.index("```toml\n") + len("```toml\n"):]
    toml = toml[:toml.index("```")]
    synopsis = text[text.index("### Command line"):text.index("### As a library")]
    commands = [line.split("#")[0].strip() for line in synopsis.splitlines()
                if line.startswith("python -m mocap_autolabel batch ")]
    return toml, commands


@pytest.mark.slow
def test_every_readme_batch_example_runs_as_written(tmp_path):
    """README's studio.toml (solve_hand + fbx + jobs = 2) and its batch synopsis with every output flag,
    in spawned workers from a parent that imported bpy (they failed with No module named '_bpy')."""
    pytest.importorskip("bpy", reason="the bpy module (pip install bpy==5.0.1) is not installed")
    import dataclasses

    import numpy as np
    from mocap_autolabel.core.hand.calibrate import Calibration
    from mocap_autolabel.core.synth.generate import SynthConfig

    toml, commands = _readme_batch_examples()
    assert "solve_hand = true" in toml and "jobs = 2" in toml and len(commands) == 1
    settings = BatchSettings.from_toml(_write(tmp_path / "studio.toml", toml))
    layout = load_layout(settings.layout)
    (tmp_path / "takes").mkdir()
    config = dataclasses.replace(SynthConfig(), side="right")
    for seed in range(2):
        synth = synthesize(layout, 300, seed=seed, config=config)
        write_c3d(synth.take, tmp_path / "takes" / f"take{seed}.c3d")
    # the performer's calibration the settings file names: the synthetic hand itself, markers on their spots
    hand = synth.hand
    os.makedirs(os.path.dirname(settings.calibration), exist_ok=True)
    Calibration(layout.name, list(layout.names), hand.side, hand.length, hand.breadth,
                np.zeros((len(layout), 3))).save(settings.calibration)
    env = dict(os.environ, PYTHONPATH=str(ROOT / "addon"))
    cli = [sys.executable, "-m", "mocap_autolabel"]

    # "batch INPUTS... -o OUT_DIR --config studio.toml", as the settings file is meant to be used
    done = subprocess.run(cli + ["batch", "takes", "-o", "studio", "--config", "studio.toml", "--quiet"],
                          cwd=tmp_path, capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "2 ok, 0 failed, 0 skipped" in done.stdout and "with 2 job(s)" in done.stdout
    for seed in range(2):
        report = json.loads((tmp_path / "studio" / f"take{seed}.report.json").read_text())
        assert report["outputs"]["fbx"] == f"take{seed}.fbx" and report["layout"] == "glove13"
        assert report["hand"]["marker_rms_mm"] < 10
    summary = json.loads((tmp_path / "studio" / "summary.json").read_text())
    assert summary["settings"]["calibration"] == str(tmp_path / "performers" / "p01.json")

    # the synopsis, every optional flag given (INPUTS, OUT_DIR and the files filled in), on the han19 takes
    words = commands[0].split()[3:]
    flags = [w.strip("[]") for w in words if w.startswith("[--")]
    assert {"--jobs", "--solve-hand", "--blend", "--fbx", "--bvh", "--validate", "--fill", "--max-gap"} <= set(flags)
    _synthetic(tmp_path / "han19", 2)
    values = {"--config": "han19.toml", "--layout": "han19", "--model": str(ROOT / "addon" / "mocap_autolabel" /
                                                                            "models" / "set_han19.onnx"),
              "--jobs": "2", "--calibration": None, "--method": "set", "--fill-method": "spline", "--max-gap": "0.5",
              "--fit": "han19/synth0.c3d"}  # set does not read it: any take that is there
    _write(tmp_path / "han19.toml", "[batch]\nconfident = 0.9\n")
    argv = ["batch", "han19", "-o", "synopsis"]
    for flag in flags:
        if flag in ("--quiet", "--json-progress", "--calibration"):  # one of the pair; a calibration is per layout
            continue
        argv += [flag] + ([values[flag]] if values.get(flag) else [])
    done = subprocess.run(cli + argv + ["--quiet"], cwd=tmp_path, capture_output=True, text=True, env=env,
                          timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "2 ok, 0 failed, 0 skipped" in done.stdout
    assert "partial.blend" not in done.stdout + done.stderr  # Blender's own save lines stay out
    for suffix in (".labeled.c3d", ".report.json", ".blend", ".fbx", ".bvh"):
        assert (tmp_path / "synopsis" / f"synth0{suffix}").stat().st_size > 0
    assert json.loads((tmp_path / "synopsis" / "synth0.report.json").read_text())["fill"]["method"] == "spline"


def _write(path: Path, text: str) -> str:
    path.write_text(text, encoding="utf-8")
    return str(path)


@pytest.fixture(scope="module")
def mixed_folder(tmp_path_factory, bpy_module):
    """A folder of two one-hand takes (the second is the one tests/core/test_batch.py forces two hands
    on) and a two-hand take, run once with FBX rigs: ``(takes, out, summary)``."""
    from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take

    root = tmp_path_factory.mktemp("mixed")
    takes = root / "takes"
    _synthetic(takes, 1, frames=300)
    han19 = load_layout("han19")
    write_c3d(two_hand_take(han19, 300, seed=3, config=TwoHandConfig(close_share=0.0)).take, takes / "two.c3d")
    write_c3d(synthesize(han19, 300, seed=9).take, takes / "forced.c3d")
    out = root / "out"
    return takes, out, run_batch([str(takes)], str(out), BatchSettings(fbx=True), progress="none")


@pytest.mark.slow
def test_a_folder_of_one_and_two_hand_takes(mixed_folder):
    from mocap_autolabel.core.hands import split_hands

    _, out, summary = mixed_folder
    han19 = load_layout("han19")
    assert summary["ok"] == 3, summary["takes_detail"]
    two = json.loads((out / "two.report.json").read_text())
    assert two["hands"] == 2 and [h["side"] for h in two["per_hand"]] == ["left", "right"]
    assert all(h["labels_present"] == 19 and h["confident_share"] > 0.5 for h in two["per_hand"])
    assert [h["side"] for h in two["hands_solved"]] == ["left", "right"]
    assert two["outputs"] == {"labeled": "two.labeled.c3d", "fbx_left": "two_left.fbx", "fbx_right": "two_right.fbx"}
    assert {s for s, _ in split_hands(read_take(out / "two.labeled.c3d"), han19)} == {"left", "right"}
    one = json.loads((out / "synth0.report.json").read_text())
    assert one["hands"] == 1 and "per_hand" not in one and one["outputs"]["fbx"] == "synth0.fbx"
    rows = {r["name"]: r for r in summary["takes_detail"]}
    assert rows["two"]["sides"] == "left right" and rows["synth0"]["hands"] == 1


@pytest.mark.slow
def test_a_rerun_finds_the_folder_complete_until_a_hands_rig_file_is_missing(mixed_folder):
    """A rerun finds every take complete, the two-hand one with its per-hand rig files included
    (the rerun that redoes it writes the missing file again)."""
    takes, out, summary = mixed_folder
    assert summary["ok"] == 3, summary["takes_detail"]
    settings = BatchSettings(fbx=True)
    again = run_batch([str(takes)], str(out), settings, progress="none")
    assert again["skipped"] == 3
    (out / "two_right.fbx").unlink()
    assert run_batch([str(takes)], str(out), settings, progress="none")["skipped"] == 2
    assert (out / "two_right.fbx").stat().st_size > 0
