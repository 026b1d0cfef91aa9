"""Faults in batch: a full disk and workers killed at random points; no half-written file, a rerun completes
with the bytes of an undisturbed run. (benchmarks/faults.py runs 10 random kills per mode.)"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import ROOT
from helpers import alive, run_killing_a_worker, same_outputs, worker_processes
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


def _files(out) -> dict[str, tuple[int, int]]:
    """Every file in a batch folder (temporary ones too), with its size and mtime."""
    return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in out.iterdir()}


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_no_worker_outlives_its_batch(tmp_path, sig):
    """batch --jobs 2 killed while both workers label: they end with it, and nothing is written after
    (they went on labeling the takes queued to them for seconds, racing a rerun)."""
    takes = tmp_path / "takes"
    _synthetic(takes, 4, frames=3000)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "mocap_autolabel", "batch", str(takes), "-o", str(out),
                             "--jobs", "2", "--json-progress"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ, PYTHONPATH=str(ROOT / "addon")))
    try:
        first = None
        for line in proc.stderr:  # the first take done (either worker's): the workers are on the next ones
            event = json.loads(line)
            if event["event"] == "done":
                first = event["name"]
                break
        workers = worker_processes(proc.pid)
        assert len(workers) == 2
        proc.send_signal(sig)
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.stderr.close()
    deadline = time.monotonic() + 5
    while alive(workers) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not alive(workers), f"workers {alive(workers)} outlived their batch by 5 s"
    written = _files(out)
    time.sleep(1.5)
    assert _files(out) == written  # nothing written after
    assert first is not None and (out / f"{first}.report.json").exists() and not (out / "summary.json").exists()
    rerun = run_batch([str(takes)], str(out), BatchSettings(), progress="none")
    assert (rerun["ok"], rerun["skipped"]) == (4, 1) and not [p for p in out.iterdir() if ".partial" in p.name]


KILL_IN_RESULT = '''
import os, signal, struct
flag = os.environ.get("MOCAP_TEST_KILL_IN_RESULT")
if flag:
    from multiprocessing import connection
    wrote = []
    _replace, _send_bytes = os.replace, connection.Connection._send_bytes
    def replace(src, dst, *args, **kwargs):
        _replace(src, dst, *args, **kwargs)
        if os.environ["MOCAP_TEST_KILL_AFTER"] == "synth1":
            wrote.extend([True] * str(dst).endswith("synth1.report.json"))
        elif str(dst).endswith(".report.json"):  # "last": the worker that wrote the batch's last report
            folder = os.path.dirname(str(dst))
            wrote.extend([True] * (sum(f.endswith(".report.json") for f in os.listdir(folder)) == 3))
    def send_bytes(self, buf):
        # That worker dies handing back its result, as early as the pipe's real writes allow: after the
        # length of a message over 16 kB (written apart from its body), else after it all, lock still held.
        if wrote and b"_ResultItem" in bytes(buf[:200]) and not os.path.exists(flag):
            open(flag, "w").close()
            if len(buf) > 16384:
                self._send(struct.pack("!i", len(buf)))
            else:
                _send_bytes(self, buf)
            os.kill(os.getpid(), signal.SIGKILL)
        return _send_bytes(self, buf)
    os.replace, connection.Connection._send_bytes = replace, send_bytes
'''


@pytest.mark.parametrize("after", ["synth1", "last"])
def test_a_worker_killed_handing_back_a_result_does_not_hang_the_batch(tmp_path, after):
    """The flaky hangs of the random kills above, made certain. ``synth1``: a worker killed in the middle of
    the message that hands back a take's report (25 kB: two writes) left the pool's manager thread waiting
    for the rest of it, and the other worker waiting on the pipe's lock, for ever. ``last``: a worker killed
    right after handing back the batch's last result, its lock on the pipe still held: the pool's graceful
    shutdown waited for ever on the other worker, which waited on that lock to say it was leaving."""
    takes = tmp_path / "takes"
    _synthetic(takes, 3, frames=3000)  # synth1's report is the largest
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(KILL_IN_RESULT)
    flag = tmp_path / "killed"
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(hook), str(ROOT / "addon")]),
               MOCAP_TEST_KILL_IN_RESULT=str(flag), MOCAP_TEST_KILL_AFTER=after)
    proc = subprocess.Popen([sys.executable, "-m", "mocap_autolabel", "batch", str(takes), "-o", str(out),
                             "--jobs", "2", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and its workers
        proc.communicate()
        pytest.fail("the batch hung after its worker was killed handing back a result")
    assert flag.exists(), "the worker was not killed"
    assert proc.returncode == 0 and "3 ok, 0 failed, 0 skipped" in stdout, stdout + stderr
