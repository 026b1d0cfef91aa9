"""Small builders shared by the tests."""

from __future__ import annotations

import numpy as np
from mocap_autolabel.core.take import Take


def small_take(frames: int = 50, points: int = 4, seed: int = 0, gaps: bool = True) -> Take:
    """A take of points moving smoothly (metres), with a few gaps of each convention already as NaN."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames, dtype=np.float32)[:, None, None] / 100.0
    base = rng.uniform(-0.5, 0.5, (1, points, 3)).astype(np.float32)
    positions = (base + 0.1 * np.sin(2 * np.pi * t + np.arange(points)[None, :, None])).astype(np.float32)
    if gaps:
        positions[5:9, 0] = np.nan
        positions[20:21, 1] = np.nan
        positions[frames - 3:, points - 1] = np.nan
    return Take(positions=positions, names=[f"*{i}" for i in range(points)], rate=100.0, source="small.c3d")


def true_markers(synth, m: int) -> np.ndarray:
    """``(F, M, 3)`` the true labeled positions of a synthetic take (metres, NaN where unseen)."""
    out = np.full((synth.take.n_frames, m, 3), np.nan)
    f, p = np.nonzero(synth.labels >= 0)
    out[f, synth.labels[f, p]] = synth.take.positions[f, p]
    return out


def synthetic_takes(folder, count: int, frames: int = 300) -> list:
    """``count`` raw synthetic han19 takes (seeds 0, 1, ...) written as ``folder/synth<seed>.c3d``; their paths."""
    from mocap_autolabel.core.formats.c3d import write_c3d
    from mocap_autolabel.core.layout import load_layout
    from mocap_autolabel.core.synth.generate import synthesize

    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for seed in range(count):
        path = folder / f"synth{seed}.c3d"
        write_c3d(synthesize(load_layout("han19"), frames, seed=seed).take, path)
        paths.append(path)
    return paths


# --- the Blender tests' shared steps (bpy is passed in: these helpers import nothing of Blender) ---

def import_take(bpy, path, tmp_path):
    """Import a copy of ``path`` (a test may delete it) with the add-on's operator; the new take."""
    import shutil
    from pathlib import Path

    path = shutil.copy(path, tmp_path / Path(path).name)
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path)) == {"FINISHED"}
    return bpy.context.scene.mocap_autolabel.take


def import_written(bpy, take, tmp_path, name: str):
    """Write ``take`` as ``tmp_path/src/<name>.c3d`` and import it (:func:`import_take`); the new take."""
    from mocap_autolabel.core.formats.c3d import write_c3d

    path = tmp_path / "src" / f"{name}.c3d"
    path.parent.mkdir(exist_ok=True)
    write_c3d(take, path)
    return import_take(bpy, path, tmp_path)


def save_and_reopen(bpy, path):
    """Save the scene as ``path``, empty Blender, open ``path`` again; the take the scene shows."""
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return bpy.context.scene.mocap_autolabel.take


def review_state(coll):
    """The review stored on a take's collection."""
    from mocap_autolabel.blender.review import load_state

    return load_state(coll)


def select(bpy, *objs):
    """Select exactly ``objs``, the first one active (none: nothing selected, no active object)."""
    for o in bpy.context.selected_objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0] if objs else None


# --- batch runs: outputs compared, workers killed ---

def same_outputs(a, b) -> list[str]:
    """The take outputs of two batch folders (paths), compared: labeled C3Ds byte for byte, reports but for
    their timings and the id of the run that wrote them. Returns the names of the takes compared; asserts no
    temporary file is left in either."""
    import json
    from pathlib import Path

    a, b = Path(a), Path(b)
    names = sorted(p.name[: -len(".labeled.c3d")] for p in a.glob("*.labeled.c3d"))
    assert names == sorted(p.name[: -len(".labeled.c3d")] for p in b.glob("*.labeled.c3d"))
    for name in names:
        assert (a / f"{name}.labeled.c3d").read_bytes() == (b / f"{name}.labeled.c3d").read_bytes(), name
        ra, rb = (json.loads((d / f"{name}.report.json").read_text()) for d in (a, b))
        for r in (ra, rb):
            r.pop("seconds"), r.pop("run", None)
        assert ra == rb, name
    for folder in (a, b):
        assert not [p.name for p in folder.rglob("*") if ".partial" in p.name]
    return names


def worker_processes(parent: int | None = None) -> list[int]:
    """Process ids of the worker processes of this process (or of process ``parent``): children started by
    multiprocessing's spawn (``batch --jobs``), and children of its fork server (a local Dask cluster's workers)."""
    import os

    me, procs = parent or os.getpid(), []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmd = f.read()
        except (OSError, ValueError, IndexError):
            continue
        procs.append((int(entry), ppid, cmd))
    servers = {pid for pid, ppid, cmd in procs if ppid == me and b"forkserver" in cmd}
    return [pid for pid, ppid, cmd in procs
            if (ppid == me and b"spawn_main" in cmd) or ppid in servers]


def run_killing_a_worker(run, delay: float, rng) -> tuple[object, bool]:
    """``run()`` (a batch run in this process) while, ``delay`` seconds in, one of its worker processes
    (chosen by ``rng``) is killed with SIGKILL. Returns what ``run`` returned and whether one was killed."""
    import os
    import signal
    import threading
    import time

    stop = threading.Event()
    killed = []

    def killer():
        if stop.wait(delay):
            return
        while not stop.is_set():
            pids = worker_processes()
            if pids:
                os.kill(int(rng.choice(pids)), signal.SIGKILL)
                killed.append(True)
                return
            time.sleep(0.02)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    try:
        result = run()
    finally:
        stop.set()
        thread.join()
    return result, bool(killed)


def alive(pids) -> list[int]:
    """Those of ``pids`` still running (a process ended but not yet reaped, a zombie, is not)."""
    running = []
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] != "Z":
                    running.append(pid)
        except (OSError, IndexError):
            pass
    return running
