"""Faults in batch: a full disk and workers killed at random points; no half-written file, a rerun completes
with the bytes of an undisturbed run. (benchmarks/faults.py runs 10 random kills per mode.)"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT
from helpers import run_killing_a_worker, same_outputs
from helpers import synthetic_takes as _synthetic
from mocap_autolabel.batch import BatchSettings, run_batch


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory):
    """Three synthetic takes and their outputs from one undisturbed job."""
    root = tmp_path_factory.mktemp("faults")
    _synthetic(root / "takes", 3, frames=400)
    assert run_batch([str(root / "takes")], str(root / "one"), BatchSettings(), progress="none")["ok"] == 3
    return root


def _batch_with_file_size_limit(takes, out, limit: int | None):
    """The batch command in a process whose files cannot grow past ``limit`` bytes (RLIMIT_FSIZE: a full disk)."""
    def cap():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([sys.executable, "-m", "mocap_autolabel", "batch", str(takes), "-o", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=300, preexec_fn=cap if limit else None,
                          env=dict(os.environ, PYTHONPATH=str(ROOT / "addon")))


def test_a_full_disk_reports_the_takes_and_a_rerun_completes(undisturbed, tmp_path):
    out = tmp_path / "out"
    # room for reports and summaries (a few kB), not for a labeled C3D (over 100 kB)
    full = _batch_with_file_size_limit(undisturbed / "takes", out, 40_000)
    assert full.returncode == 1 and "Traceback" not in full.stderr
    errors = {t["name"]: t["error"] for t in json.loads((out / "summary.json").read_text())["takes_detail"]}
    assert len(errors) == 3 and all("cannot write its outputs in" in e and "cut short while writing" in e
                                    for e in errors.values()), errors
    assert not list(out.glob("*.labeled.c3d")) and not [p for p in out.iterdir() if ".partial" in p.name]
    # no room even for a report: one line, nothing half-written
    tiny = _batch_with_file_size_limit(undisturbed / "takes", tmp_path / "tiny", 200)
    assert tiny.returncode == 1 and "Traceback" not in tiny.stderr, tiny.stderr
    assert tiny.stderr.strip().splitlines()[-1].startswith(f"error: {tmp_path / 'tiny'}: cannot write (File too large)")
    assert not [p for p in (tmp_path / "tiny").iterdir() if ".partial" in p.name]
    # room again: the rerun redoes the failed takes, with the bytes of the undisturbed run
    again = _batch_with_file_size_limit(undisturbed / "takes", out, None)
    assert again.returncode == 0, again.stdout + again.stderr
    assert same_outputs(undisturbed / "one", out) == ["synth0", "synth1", "synth2"]


@pytest.mark.parametrize("mode", ["jobs", pytest.param("dask", marks=pytest.mark.slow)])
def test_a_worker_killed_at_a_random_point_loses_nothing(undisturbed, tmp_path, mode):
    """Two seeded random points per mode (a pool of 2 processes; a local Dask cluster of 2 workers)."""
    if mode == "dask":
        pytest.importorskip("distributed", reason="Dask's distributed is not installed (pip install distributed)")
    settings = BatchSettings(jobs=2) if mode == "jobs" else BatchSettings(scheduler="local:2")
    rng = np.random.default_rng(7)
    for run in range(2):
        delay = float(rng.uniform(0.2, 1.2))  # from the start of the run: workers starting, labeling, writing
        for attempt in range(4):  # a run that ended before the kill is tried again, killed sooner
            out = tmp_path / f"out{run}-{attempt}"

            def batch(out=out):
                return run_batch([str(undisturbed / "takes")], str(out), settings, progress="none")

            summary, killed = run_killing_a_worker(batch, delay, rng)
            if killed:
                break
            delay /= 2
        rows = summary["takes_detail"]
        assert killed, "the run ended before a worker was killed, four times"
        assert all(r["status"] == "ok" for r in rows), (killed, rows)
        assert not [p for p in out.iterdir() if ".partial" in p.name]
        rerun = run_batch([str(undisturbed / "takes")], str(out), settings, progress="none")
        assert rerun["ok"] == 3
        assert same_outputs(undisturbed / "one", out) == ["synth0", "synth1", "synth2"]
