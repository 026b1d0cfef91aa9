"""Batch on a Dask cluster (``--scheduler``): the bytes of one job; a worker that dies mid-take loses nothing."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from conftest import ROOT
from helpers import same_outputs
from helpers import synthetic_takes as _synthetic
from mocap_autolabel.batch import BatchSettings, run_batch
from mocap_autolabel.cli import main

pytest.importorskip("distributed", reason="Dask's distributed is not installed (pip install distributed)")
import dask  # noqa: E402  (installed with distributed)


@pytest.fixture(scope="module")
def takes_and_one_job(tmp_path_factory):
    """Three short synthetic takes and their outputs from one local job."""
    root = tmp_path_factory.mktemp("farm")
    _synthetic(root / "takes", 3, frames=400)
    summary = run_batch([str(root / "takes")], str(root / "one"), BatchSettings(), progress="none")
    assert summary["ok"] == 3
    return root


def test_a_local_cluster_of_two_workers_writes_the_bytes_of_one_job(takes_and_one_job, tmp_path, capsys):
    root = takes_and_one_job
    out = tmp_path / "dask"
    assert main(["batch", str(root / "takes"), "-o", str(out), "--scheduler", "local:2", "--json-progress"]) == 0
    assert same_outputs(root / "one", out) == ["synth0", "synth1", "synth2"]
    events = [json.loads(line) for line in capsys.readouterr().err.splitlines() if line.startswith("{")]
    assert sorted(e["name"] for e in events if e["event"] == "done") == ["synth0", "synth1", "synth2"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scheduler"] == "local:2" and summary["jobs"] == 2 and summary["ok"] == 3
    # resume: a rerun on the cluster skips the finished takes; --force redoes them
    again = run_batch([str(root / "takes")], str(out), BatchSettings(scheduler="local:2"), progress="none")
    assert (again["skipped"], again["ok"]) == (3, 3)
    forced = run_batch([str(root / "takes")], str(out), BatchSettings(scheduler="local:1", force=True),
                       progress="none")
    assert (forced["skipped"], forced["ok"]) == (0, 3)


def test_bad_scheduler_settings_are_one_line(tmp_path, capsys):
    takes = tmp_path / "takes"
    _synthetic(takes, 1, frames=100)
    assert main(["batch", str(takes), "-o", str(tmp_path / "o"), "--scheduler", "local:0"]) == 2
    assert main(["batch", str(takes), "-o", str(tmp_path / "o"), "--scheduler", "nowhere"]) == 2
    assert main(["batch", str(takes), "-o", str(tmp_path / "o"), "--scheduler", "local:2", "--jobs", "2"]) == 2
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["batch", str(takes), "-o", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:9"]) == 1
    err = capsys.readouterr().err
    assert "1 to 64 workers" in err and "give a scheduler address" in err and "not both" in err
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in err and "Traceback" not in err
    assert not (tmp_path / "o" / "summary.json").exists()


KILL_ONCE = '''
import os, signal
flag = os.environ.get("MOCAP_TEST_KILL_ONCE")
if flag:
    _replace = os.replace
    def replace(src, dst, *args, **kwargs):
        # The labeled C3D is whole in its temporary file and not yet renamed: the worker dies there, once.
        if str(dst).endswith("synth1.labeled.c3d") and not os.path.exists(flag):
            open(flag, "w").close()
            os.kill(os.getpid(), signal.SIGKILL)
        return _replace(src, dst, *args, **kwargs)
    os.replace = replace
'''


def test_a_worker_killed_mid_take_loses_nothing(takes_and_one_job, tmp_path, monkeypatch):
    """The worker writing synth1 dies (SIGKILL) with the take's C3D written to its temporary name:
    the take is run again on a worker, the outputs are the bytes of an undisturbed run, and the
    killed worker's temporary file is gone."""
    root = takes_and_one_job
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(KILL_ONCE)  # loaded by the spawned worker processes only
    flag = tmp_path / "killed"
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(hook), str(ROOT / "addon")]))
    monkeypatch.setenv("MOCAP_TEST_KILL_ONCE", str(flag))
    out = tmp_path / "dask"
    summary = run_batch([str(root / "takes")], str(out), BatchSettings(scheduler="local:2"), progress="none")
    assert flag.exists(), "the worker was not killed"
    assert summary["ok"] == 3, summary["takes_detail"]
    assert same_outputs(root / "one", out) == ["synth0", "synth1", "synth2"]


def test_readme_farm_example_runs_as_written(takes_and_one_job, tmp_path):
    """README's scheduler, worker and batch lines, with HOST, its port and the /farm folders filled in."""
    import socket
    import subprocess
    import sys
    import time

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text[text.index("### On a farm: Dask"):]
    block = block[block.index("```sh\n") + 6:block.index("```\n", block.index("```sh\n") + 6)]
    lines = [line.split("#")[0].strip() for line in block.splitlines() if line.strip()]
    assert [line.split()[:2] for line in lines] == [["dask", "scheduler"], ["dask", "worker"], ["python", "-m"]]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = str(s.getsockname()[1])
    fill = {"HOST": "127.0.0.1", "8786": port, "/farm/takes": str(takes_and_one_job / "takes"),
            "/farm/labeled": str(tmp_path / "labeled")}
    argv = []
    for line in lines:
        for key, value in fill.items():
            line = line.replace(key, value)
        argv.append(line.split())
    bindir = Path(sys.executable).parent
    env = dict(os.environ, PYTHONPATH=str(ROOT / "addon"), PATH=f"{bindir}{os.pathsep}{os.environ['PATH']}")
    started = [subprocess.Popen([str(bindir / "dask"), *argv[0][1:]], env=env, stderr=subprocess.DEVNULL)]
    try:
        time.sleep(1)
        started.append(subprocess.Popen([str(bindir / "dask"), *argv[1][1:]], env=env, stderr=subprocess.DEVNULL))
        done = subprocess.run([sys.executable, *argv[2][1:]], env=env, capture_output=True, text=True, timeout=300)
    finally:
        for proc in started[::-1]:
            proc.terminate()
            proc.wait(timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "3 ok, 0 failed, 0 skipped" in done.stdout and f"(tcp://127.0.0.1:{port})" in done.stdout
    assert same_outputs(takes_and_one_job / "one", tmp_path / "labeled") == ["synth0", "synth1", "synth2"]


@pytest.mark.slow
def test_a_worker_that_dies_costs_no_finished_take_a_second_run(tmp_path):
    """A worker killed once three takes are done: the scheduler ran again every take the dead worker had
    finished (their futures were held to the end), rewriting their outputs. Each finished take's files
    are the same files (inode and mtime) after the run as when it finished."""
    import signal
    import threading

    from helpers import worker_processes

    _synthetic(tmp_path / "takes", 6, frames=3000)
    out = tmp_path / "out"
    finished: dict[str, list] = {}
    stop = threading.Event()

    def ident(path: Path) -> tuple[int, int]:
        st = path.stat()
        return st.st_ino, st.st_mtime_ns

    def killer():
        while len(list(out.glob("*.report.json"))) < 3:
            if stop.wait(0.01):
                return
        for report in out.glob("*.report.json"):
            name = report.name[: -len(".report.json")]
            finished[name] = [ident(report), ident(out / f"{name}.labeled.c3d")]
        os.kill(worker_processes()[0], signal.SIGKILL)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    try:
        summary = run_batch([str(tmp_path / "takes")], str(out), BatchSettings(scheduler="local:2"), progress="none")
    finally:
        stop.set()
        thread.join()
    assert len(finished) >= 3, "no worker was killed"
    assert summary["ok"] == 6, summary["takes_detail"]
    rerun = {name for name, ids in finished.items()
             if [ident(out / f"{name}.report.json"), ident(out / f"{name}.labeled.c3d")] != ids}
    assert not rerun, f"finished takes run again: {sorted(rerun)}"
