"""Batch conversion: folders of takes, headless, with progress, reports and no lost work.

``run_batch(inputs, out_dir, settings)`` labels every take (and optionally solves the hand and
writes .blend / FBX) in up to ``jobs`` processes. Per take it writes, each atomically:
``<name>.labeled.c3d`` and, last, ``<name>.report.json`` (the mark of a finished take). The report
records what made the outputs: the input (its path, size, mtime and SHA-256) and a digest of the
settings that shape them (:func:`settings_digest`). A rerun skips a take whose record matches its input
and settings now and whose outputs are all there, unless ``force``; otherwise the take is done again,
its earlier outputs removed first. An input keeps its output name in a folder across runs, and no other
input gets it (:func:`find_takes`). A bad take is reported with its reason and skipped; the others go on.
At the end ``summary.csv`` and ``summary.json``.

Only the standard library at import time: the work happens in :func:`process_take`.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import errno
import functools
import glob
import hashlib
import heapq
import io
import json
import math
import multiprocessing
import os
import re
import secrets
import sys
import time
import tomllib
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .worker_env import environ, thread_caps

if TYPE_CHECKING:  # batch imports only the standard library at module level (the CLI's --help stays fast)
    from .core.cache import RunCache
    from .core.settings import LabelSettings

TAKE_EXTENSIONS = (".c3d", ".trc", ".tsv")


@dataclass
class BatchSettings:
    """Everything a batch run can be told; a TOML file holds the same keys (``[batch]`` table).

    Attributes:
        layout: built-in layout name or a layout .toml; None: picked per take from its points' names
            (:func:`.core.process.choose_layout`), else han19.
        model: ONNX model for the labeler (default: the shipped one).
        method, temporal: labeling method and temporal mode (as the ``label`` command).
        validate: IK validation of the labels.
        confident: confidence at or above which a segment counts as confident in the reports.
        solve_hand: also fit the hand (calibrated on each take, or with ``calibration``).
        calibration: a performer calibration .json to reuse for every take.
        fit: a labeled take of the performer (C3D, TRC, TSV): ``gmm`` fits on it, ``nearest`` starts from
            its first frame (as ``label --fit``); the other methods do not use it.
        blend, fbx, bvh: also write these per take (need Blender or the bpy module).
        jobs: takes processed side by side (processes).
        scheduler: run each take as a task on a Dask cluster instead: ``tcp://HOST:8786`` (a farm's
            scheduler; inputs and the output folder must be seen by every worker under the same paths)
            or ``local:N`` (N worker processes here). Needs the ``distributed`` package.
        html: also write an HTML page per take (``<name>.report.html``, with pictures) and ``index.html``
            linking them (needs matplotlib).
        force: redo takes whose outputs are already complete.
        hands: ``auto`` (find how many hands each take holds), ``1`` or ``2``.
        hand_names: how two hands' labels carry their side (see ``label --hand-names``).
        calibration: with two hands, one calibration per side may be given as ``"left.json,right.json"``.
        fill: also fill the labeled markers' gaps in ``<name>.labeled.c3d`` (marked as computed),
            by ``fill_method`` (``auto``, ``spline``, ``rigid``, ``hand``, ``pca``, ``pose``), gaps up to
            ``max_gap`` seconds; the report's ``fill`` holds every gap.
        retarget: ``"character.blend"`` or ``"character.blend:Armature"`` (relative to the TOML): the solved
            hands retargeted onto that character's armature (``solve --retarget``); ``<name>.blend`` is the
            character's scene with them, ``<name>.fbx`` / ``.bvh`` its armature (one file, both hands);
            the report's ``retarget`` says onto what and how many bones and frames.
        bone_map: with ``retarget``, a bone-map preset's name (saved from Blender) or a .json (relative to
            the TOML); None: the automatic map.
        retarget_wrist: ``fingers`` (default), ``rotation`` or ``world`` (see ``solve --retarget-wrist``).
        pinch: keep the thumb-to-fingertip contacts when retargeting.
        bone_names: the FBX/BVH bone names and the FBX's engine axes and units: ``ours`` (default),
            ``ue5``, ``unity``, ``mixamo`` or ``rigify`` (see ``solve --bone-names``).
    """

    layout: str | None = None
    model: str | None = None
    method: str = "set"
    temporal: str = "vote"
    validate: bool = False
    confident: float = 0.95
    solve_hand: bool = False
    calibration: str | None = None
    fit: str | None = None
    blend: bool = False
    fbx: bool = False
    bvh: bool = False
    jobs: int = 1
    scheduler: str | None = None
    html: bool = False
    force: bool = False
    hands: str = "auto"
    hand_names: str | None = None
    fill: bool = False
    fill_method: str = "auto"
    max_gap: float = 1.0
    retarget: str | None = None
    bone_map: str | None = None
    retarget_wrist: str = "fingers"
    pinch: bool = False
    bone_names: str = "ours"
    extra: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_toml(cls, path: str) -> BatchSettings:
        """Settings from a TOML file: top-level keys or a ``[batch]`` table; paths are relative to it."""
        try:
            with open(path, "rb") as f:
                data = tomllib.load(f)
        except FileNotFoundError:
            raise ValueError(f"{path}: configuration file not found") from None
        except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a readable TOML configuration ({exc})") from None
        data = data.get("batch", data)
        known = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"{path}: unknown setting(s) {', '.join(sorted(unknown))}; known are "
                             f"{', '.join(sorted(known))}")
        base = os.path.dirname(os.path.abspath(path))
        for key in ("model", "calibration", "fit"):
            if data.get(key):
                data[key] = ",".join(os.path.join(base, p.strip()) for p in str(data[key]).split(","))
        if "hands" in data:
            data["hands"] = str(data["hands"])
        if str(data.get("layout", "")).endswith(".toml"):
            data["layout"] = os.path.join(base, data["layout"])
        if data.get("retarget"):  # the character's path relative to the TOML, its ":Armature" kept
            from .commands.solve import split_character

            try:
                blend, armature = split_character(str(data["retarget"]))
            except ValueError as exc:
                raise ValueError(f"{path}: {str(exc).replace('--retarget', 'retarget')}") from None
            data["retarget"] = os.path.join(base, blend) + (f":{armature}" if armature else "")
        bone_map = str(data.get("bone_map") or "")
        if bone_map.lower().endswith(".json") or "/" in bone_map or os.sep in bone_map:  # a file, not a preset
            data["bone_map"] = os.path.join(base, bone_map)
        return cls(**data)

    def outputs(self) -> list[str]:
        """Output suffixes every finished take has, besides its report."""
        out = [".labeled.c3d"]
        out += [s for s, on in ((".blend", self.blend), (".fbx", self.fbx), (".bvh", self.bvh)) if on]
        return out

    def needs_blender(self) -> bool:
        return self.blend or self.fbx or self.bvh

    def character(self) -> tuple[str, str | None] | None:
        """``(character .blend, armature or None)`` of ``retarget``, or None."""
        from .commands.solve import split_character

        return split_character(self.retarget) if self.retarget else None

    def label_settings(self, **more) -> LabelSettings:
        """The :class:`.core.settings.LabelSettings` of these batch settings (``more``: fields to add)."""
        from .core.settings import LabelSettings

        return LabelSettings(method=self.method, temporal=self.temporal, model=self.model, validate=self.validate,
                             hand_count=self.hands, naming=self.hand_names, **more)


@functools.cache
def run_cache() -> RunCache:
    """The batch worker's :class:`.core.cache.RunCache`: its results kept between its takes
    (loaded models, fitted range-of-motion labelers), made on its first take, gone with the worker."""
    from .core.cache import RunCache

    return RunCache()


def find_takes(inputs: list[str], owners: dict[str, str] | None = None,
               out_dir: str | None = None) -> list[tuple[str, str]]:
    """``(path, output name)`` for every take in files, folders (recursively) and globs, sorted;
    a folder's or glob's files that are this batch's own outputs (``<name>.labeled.c3d`` in
    ``out_dir``) are no takes: an output folder inside the inputs is not labeled again on a rerun.

    The output name keeps a folder input's sub-folders (``sub/take``), so equal file names in
    different folders do not collide; remaining collisions get ``-2``, ``-3``...

    ``owners``: the output names already given in the output folder, each to its input's absolute path
    (:func:`read_records`). An input keeps the name it was given there, and no other input gets a name
    that is given, so two inputs of one name never share outputs, whichever of them a run holds.
    """
    found: list[tuple[str, str]] = []
    for item in inputs:
        if os.path.isdir(item):
            for root, _, files in os.walk(item):
                for name in sorted(files):
                    if name.lower().endswith(TAKE_EXTENSIONS):
                        path = os.path.join(root, name)
                        found.append((path, os.path.splitext(os.path.relpath(path, item))[0]))
        elif any(ch in item for ch in "*?["):
            for path in sorted(glob.glob(item, recursive=True)):
                if os.path.isfile(path):
                    found.append((path, os.path.splitext(os.path.basename(path))[0]))
        else:
            found.append((item, os.path.splitext(os.path.basename(item))[0]))
    unique: dict[str, tuple[str, str]] = {}
    own = os.path.realpath(out_dir) if out_dir else None
    for path, name in found:  # a take named twice (folder and glob) is done once
        if own and path.lower().endswith(".labeled.c3d") and path not in inputs \
                and os.path.realpath(path).startswith(own + os.sep):
            continue
        unique.setdefault(os.path.abspath(path), (path, name))
    owners = owners or {}
    owned: dict[str, list[str]] = {}
    for name, owner in owners.items():
        owned.setdefault(owner, []).append(name)
    taken = set(owners)
    chosen: dict[str, str] = {}
    order = sorted(unique.items(), key=lambda item: item[1])
    for key, (_, base) in order:  # the name given to this input in an earlier run, its own name first
        mine = [n for n in owned.get(key, ()) if n == base or re.fullmatch(re.escape(base) + r"-\d+", n)]
        if mine:
            chosen[key] = min(mine, key=lambda n: (n != base, len(n), n))
    for key, (_, base) in order:  # then an input's own name, where no other input has it
        if key not in chosen and base not in taken:
            chosen[key] = base
            taken.add(base)
    for key, (_, base) in order:  # then -2, -3... past every name given
        if key not in chosen:
            n = 2
            while f"{base}-{n}" in taken:
                n += 1
            chosen[key] = f"{base}-{n}"
            taken.add(chosen[key])
    return sorted((path, chosen[key]) for key, (path, _) in unique.items())


REPORT = ".report.json"


def read_records(out_dir: str) -> dict[str, dict]:
    """Every take's report in ``out_dir`` (its sub-folders too), by output name; unreadable ones left out."""
    records: dict[str, dict] = {}
    for root, _, files in os.walk(out_dir):
        for file in files:
            if file.endswith(REPORT) and not file.startswith("."):
                path = os.path.join(root, file)
                try:
                    with open(path, encoding="utf-8") as f:
                        report = json.load(f)
                except (OSError, ValueError):
                    continue
                if isinstance(report, dict):
                    records[os.path.relpath(path, out_dir)[: -len(REPORT)]] = report
    return records


#: Settings that say how and where a batch runs, not what its outputs hold.
RUN_ONLY = ("jobs", "scheduler", "force", "extra")


@functools.cache
def _file_digest(path: str, size: int, mtime_ns: int) -> str:
    """SHA-256 of a file's bytes; cached by its size and mtime (one read per file per process)."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def _digest(path: str) -> str | None:
    try:
        st = os.stat(path)
        return _file_digest(os.path.abspath(path), st.st_size, st.st_mtime_ns)
    except OSError:
        return None


def settings_digest(settings: BatchSettings) -> str:
    """A digest of what shapes a take's outputs besides its input: the settings (all but :data:`RUN_ONLY`;
    the output flags too, as they choose the files), the package's version and the bytes of the files they
    name (model, calibrations, a layout .toml) and of the shipped models (a retrained model labels anew)."""
    from .core.version import __version__

    shaping = {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings) if f.name not in RUN_ONLY}
    files = [p.strip() for key in ("model", "calibration", "fit") for p in (getattr(settings, key) or "").split(",")]
    if settings.layout and settings.layout.endswith(".toml"):
        files.append(settings.layout)
    if settings.retarget:  # the character and the bone map shape the retargeted outputs: a changed one redoes them
        files.append(settings.character()[0])
        if settings.bone_map and os.path.isfile(settings.bone_map):
            files.append(settings.bone_map)
    shipped = sorted(glob.glob(os.path.join(os.path.dirname(os.path.abspath(__file__)), "models", "*")))
    blob = json.dumps({"settings": shaping, "version": __version__,
                       "files": [_digest(p) for p in files if p], "shipped": [_digest(p) for p in shipped]},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:32]


def input_record(path: str) -> dict | None:
    """What identifies an input's bytes: size, mtime and SHA-256; None if it cannot be read."""
    try:
        st = os.stat(path)
        return {"size": st.st_size, "mtime_ns": st.st_mtime_ns,
                "sha256": _file_digest(os.path.abspath(path), st.st_size, st.st_mtime_ns)}
    except OSError:
        return None


def _same_input(path: str, record: dict | None) -> bool:
    """Whether ``path`` still holds the bytes ``record`` describes; the file is read only when its size is the
    same but its mtime is not (a copy, a touch), so a rerun of 100s of unchanged takes only stats them."""
    try:
        st = os.stat(path)
    except OSError:
        return False
    if not isinstance(record, dict) or record.get("size") != st.st_size:
        return False
    if record.get("mtime_ns") == st.st_mtime_ns:
        return True
    return _digest(path) == record.get("sha256")


def _finished(report: dict | None, path: str, out_dir: str, name: str, made_with: str) -> bool:
    """Whether ``report`` (the take's record in ``out_dir``) says its outputs are complete and were made from
    this input as it is now with these settings (``made_with``: :func:`settings_digest`)."""
    if not report or report.get("status") != "ok" or report.get("made_with") != made_with:
        return False
    if report.get("file") != os.path.abspath(path) or not _same_input(path, report.get("input")):
        return False
    outputs = report.get("outputs") or {}
    folder = os.path.join(out_dir, os.path.dirname(name))
    return "labeled" in outputs and all(os.path.isfile(os.path.join(folder, f)) for f in outputs.values())


#: Output files of a take named by its name alone (a two-hand take's per-side rig files are known only
#: from its report: ``take_left.fbx`` could be another take's).
STEM_OUTPUTS = (".labeled.c3d", ".blend", ".fbx", ".bvh", ".report.html")


def _clear_outputs(out_dir: str, name: str) -> None:
    """Remove a take's report and outputs before it is done again: its report first (a run killed meanwhile
    leaves no record of outputs that are gone), then every output it lists, so what a take's report lists
    is what is on disk, whatever the settings of the run before."""
    report_path = os.path.join(out_dir, name + REPORT)
    try:
        with open(report_path, encoding="utf-8") as f:
            listed = list((json.load(f).get("outputs") or {}).values())
    except (OSError, ValueError, AttributeError):
        listed = []
    folder = os.path.join(out_dir, os.path.dirname(name))
    stem = os.path.basename(name)
    files = [report_path] + [os.path.join(folder, f) for f in listed
                             if isinstance(f, str) and f == os.path.basename(f) and f.startswith(stem)]
    files += [os.path.join(out_dir, name + suffix) for suffix in STEM_OUTPUTS]
    for file in files:
        try:
            os.remove(file)
        except FileNotFoundError:
            pass


def _worker_init() -> None:
    """Undo in a spawned worker what the parent's ``import bpy`` did to the inherited ``sys.path``.

    Importing the bpy module puts Blender's script folders first on ``sys.path``; one of them holds
    Blender's pure-Python ``bpy`` package, which needs the ``_bpy`` built into the module. A spawned
    worker starts with the parent's ``sys.path``, so its own ``import bpy`` found that package
    before the module and failed with ``No module named '_bpy'``. Dropping those folders lets the
    worker import the real module, which puts them back itself.
    """
    if "bpy" in sys.modules:  # bpy already imported (a forked worker): nothing to undo
        return
    sys.path[:] = [p for p in sys.path if not os.path.isfile(os.path.join(p or ".", "bpy", "__init__.py"))]


def _end_with_parent(parent: int) -> None:
    """End this worker process as soon as its batch process (pid ``parent``) ends, killed or not.

    A pool worker otherwise lives on after a SIGKILL or SIGTERM of its batch, labeling the takes queued
    to it and writing their outputs under a rerun's feet. On Linux the kernel kills it with its parent
    (``PR_SET_PDEATHSIG``: nothing to poll, and at once, so it writes nothing after); elsewhere a daemon
    thread polls the parent's id. A whole output is never lost: a killed write leaves only a hidden
    temporary file, removed by the next run. (The kernel's signal comes when the parent's *thread* that
    started the worker ends: the pool starts its workers from the thread that submits, :func:`_run_pool`'s,
    which outlives the pool.)
    """
    import signal

    if sys.platform.startswith("linux"):
        import ctypes

        try:
            if ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0) == 0:  # PR_SET_PDEATHSIG
                if os.getppid() != parent:  # it ended before the line above
                    os._exit(1)
                return
        except (OSError, AttributeError):
            pass
    if os.name != "posix":  # Windows' getppid keeps naming a parent that is gone: nothing to watch
        return
    import threading

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.2)
        os._exit(1)

    threading.Thread(target=watch, name="mocap_autolabel parent watch", daemon=True).start()


def _pool_init(parent: int) -> None:
    """A pool worker's start: it ends with its batch, and imports the bpy module if it must."""
    _end_with_parent(parent)
    _worker_init()


def _pool_take(path: str, name: str, out_dir: str, settings: BatchSettings, made_with: str | None,
               run: str | None) -> None:
    """:func:`process_take` in a pool worker, which hands back nothing: the parent reads the report written.

    A report (up to 100 kB) sent back through the pool's result pipe takes two writes past 16 kB, or waits
    on a full pipe: a worker killed in between left a partial message, on which the pool's manager thread
    then waited for ever, and the other worker on the pipe's lock the killed one held (the hang of
    tests/core/test_batch_faults.py). A result of a few bytes is one atomic write.
    """
    process_take(path, name, out_dir, settings, made_with, run)


def farm_take(path: str, name: str, out_dir: str, settings: BatchSettings, made_with: str | None = None,
              run: str | None = None) -> dict:
    """:func:`process_take` as a task on a Dask worker (a fresh process that may have inherited bpy's paths)."""
    _worker_init()
    return process_take(path, name, out_dir, settings, made_with, run)


def failed_report(path: str, name: str, out_dir: str, reason: str, run: str | None = None) -> dict:
    """Write and return the report of a take that never finished (its worker died on every try)."""
    from .core.atomic import atomic_output

    _clear_outputs(out_dir, name)  # what a killed try wrote before its report: the report lists no output
    report = {"file": os.path.abspath(path), "name": name, "status": "failed", "error": f"{path}: {reason}",
              "seconds": {"total": 0.0}} | ({"run": run} if run else {})
    with atomic_output(os.path.join(out_dir, name + REPORT)) as tmp, open(tmp, "w", encoding="utf-8") as f:
        json.dump(report, f, indent=1)
    return report


def _done_in_run(out_dir: str, name: str, run: str) -> dict | None:
    """The report a task of this run (``run``) already wrote for the take, whole outputs and all, or None."""
    try:
        with open(os.path.join(out_dir, name + REPORT), encoding="utf-8") as f:
            report = json.load(f)
    except (OSError, ValueError):
        return None
    if not isinstance(report, dict) or report.get("run") != run:
        return None
    folder = os.path.join(out_dir, os.path.dirname(name))
    if not all(os.path.isfile(os.path.join(folder, f)) for f in (report.get("outputs") or {}).values()):
        return None
    return report


def process_take(path: str, name: str, out_dir: str, settings: BatchSettings, made_with: str | None = None,
                 run: str | None = None) -> dict:
    """Label one take (and solve its hand) and write its outputs; never raises for a bad take.

    ``made_with``: :func:`settings_digest` of ``settings`` (computed if not given), kept in the report with
    the input's :func:`input_record`, so a rerun knows whether the outputs are still those it would make.
    ``run``: the batch run's id, also kept: a task run again for a take this run already finished (a Dask
    scheduler reruns the tasks a dead worker held) returns that take's report and writes nothing.

    Returns the report dict that was written (``status`` "ok" or "failed" with ``error``).
    """
    from .core.atomic import atomic_output
    from .core.errors import MocapInputError

    if run and (done := _done_in_run(out_dir, name, run)) is not None:
        return done
    start = time.perf_counter()
    # The input's record is taken before it is read: a file changed meanwhile then differs from it on a rerun.
    report: dict = {"file": os.path.abspath(path), "name": name, "status": "failed", "input": input_record(path),
                    "made_with": made_with or settings_digest(settings)} | ({"run": run} if run else {})
    timings: dict = {}
    try:
        _clear_outputs(out_dir, name)
        report.update(_work(path, name, out_dir, settings, timings))
        report["status"] = "ok"
    except MocapInputError as exc:
        report["error"] = str(exc)
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EACCES, errno.EROFS):
            report["error"] = f"{path}: unexpected {type(exc).__name__}: {exc}"
        else:  # the disk is full, or the file too large for it, or the folder not writable
            report["error"] = f"{path}: cannot write its outputs in {out_dir}: {exc.strerror}"
    except Exception as exc:  # one bad take must not stop the batch
        report["error"] = f"{path}: unexpected {type(exc).__name__}: {exc}"
    if report["status"] != "ok":  # a take that failed midway lists no output: none is left behind
        with contextlib.suppress(OSError):
            _clear_outputs(out_dir, name)
    timings["total"] = round(time.perf_counter() - start, 4)
    report["seconds"] = timings
    target = os.path.join(out_dir, name + REPORT)
    with atomic_output(target) as tmp, open(tmp, "w", encoding="utf-8") as f:
        json.dump(report, f, indent=1)
    return report


def _work(path: str, name: str, out_dir: str, settings: BatchSettings, timings: dict) -> dict:

    from .core.formats.c3d import write_c3d
    from .core.labeling import unlabeled_point_names
    from .core.layout import load_layout
    from .core.process import Outputs, choose_layout, performer_inputs, process_take
    from .core.take import read_take

    t = time.perf_counter()
    take = read_take(path)
    layout = load_layout(choose_layout(take, settings.layout))
    timings["read"] = round(time.perf_counter() - t, 4)
    calibrations = {}
    if settings.calibration:
        from .core.hand.calibrate import Calibration

        for file in settings.calibration.split(","):
            cal = Calibration.load(file)
            cal.check(layout, file)
            calibrations[cal.side] = cal
    one_cal = next(iter(calibrations.values())) if len(calibrations) == 1 else None
    outputs = Outputs(solve=settings.solve_hand or settings.needs_blender(),
                      fill=settings.fill_method if settings.fill else None, max_gap=settings.max_gap,
                      calibrations={**calibrations, "": one_cal} if one_cal is not None else calibrations or None,
                      confident=settings.confident)
    performer = run_cache().remember("performer", (settings.fit, layout.name, settings.method),
                                     lambda: performer_inputs(settings.fit, layout, settings.method))
    result = process_take(take, layout, settings.label_settings(validate_hand=one_cal), outputs,
                          cache=run_cache(), **performer)
    labeling, labeled, checks, solved = result.labeling, result.labeled, result.checks, result.solves
    timings.update(result.seconds)
    facts = labeling.info["hands"]
    two = facts["count"] == 2
    out = {"layout": layout.name, "frames": take.n_frames, "points": take.n_points, "rate": take.rate,
           "hand_frames": round(max(check.share for _, check in checks), 4), "hands": facts["count"],
           "summary": labeling.summary(settings.confident, take.first_frame,
                                       unlabeled_point_names(take.names, labeling.names)),
           "outputs": {}}
    if two or "sides" in facts:
        m = len(layout)
        out["per_hand"] = []
        for h, (side, check) in enumerate(checks):
            part = labeling.label_range(h * m, (h + 1) * m) if two else labeling
            summary = part.summary(settings.confident)
            out["per_hand"].append({"side": side or facts["sides"][0], "hand_frames": round(check.share, 4),
                                    "labels_present": int(len(set(part.label[part.label >= 0].tolist()))),
                                    "confident_share": round(summary["confident_share"], 4),
                                    "uncertain_segments": len(summary["uncertain_segments"])})
        out["sides_confidence"] = facts.get("confidence")
    if result.warnings:
        out["warning"] = "; ".join(result.warnings)
    written = result.output_take
    if result.filled is not None:
        out["fill"] = result.filled.report()
    t = time.perf_counter()
    target = os.path.join(out_dir, name + ".labeled.c3d")
    write_c3d(written, target)
    out["outputs"]["labeled"] = os.path.basename(target)
    timings["write"] = round(time.perf_counter() - t, 4)
    rms: list[list] = []  # per hand solved, the marker RMS per frame (mm), and its side ("" for one hand)
    sides: list[str] = []
    if settings.solve_hand or settings.needs_blender():
        reports = []
        for side, one in solved:
            rep = one.report()
            rms.append(rep.pop("per_frame_rms_mm"))
            sides.append(side)
            reports.append(rep | ({"side": side} if side else {}))
        if two:
            out["hands_solved"] = reports
            out["hand"] = {"marker_rms_mm": round(max(r["marker_rms_mm"] for r in reports), 4)}  # the worse hand
        else:
            out["hand"] = reports[0]
        if settings.needs_blender():
            t = time.perf_counter()
            from .core.solve import as_rig

            rigs = as_rig(solved)
            out["outputs"].update(_blender_outputs(labeled, rigs, os.path.join(out_dir, name), settings, out))
            timings["blender"] = round(time.perf_counter() - t, 4)
    if settings.html:
        t = time.perf_counter()
        out["outputs"]["html"] = os.path.basename(name) + ".report.html"
        _take_page(out | {"name": name, "file": os.path.abspath(path)}, labeling, take.first_frame, rms, sides,
                   out_dir, settings, written if settings.fill else None)
        timings["html"] = round(time.perf_counter() - t, 4)
    return out


def _take_page(report: dict, labeling, first_frame: int, rms: list, sides: list[str], out_dir: str,
               settings: BatchSettings, filled=None) -> None:
    """Write ``<name>.report.html``: the take's page, linking back to the batch's index.html. ``filled``:
    the written take, when its gaps were filled (its fills are shown)."""
    from .core.atomic import atomic_output
    from .core.overview import label_classes, label_fills
    from .html_report import take_page

    fills = None if filled is None else label_fills(labeling.names, filled)
    name = report["name"]
    index = os.path.relpath("index.html", os.path.dirname(name) or ".").replace(os.sep, "/")
    page = take_page(report | {"outputs": {k: v for k, v in report["outputs"].items() if k != "html"}},
                     label_classes(labeling, settings.confident, fills), labeling.names, first_frame,
                     rms_mm=rms or None, rms_labels=[f"{s} hand" if s else "hand" for s in sides], index=index)
    with atomic_output(os.path.join(out_dir, name + ".report.html")) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(page)


def _blender_outputs(take, solved, stem: str, settings: BatchSettings, facts: dict | None = None) -> dict:
    """The take's .blend, FBX and BVH (retargeted onto ``settings.retarget``'s character where given; its
    facts then go in ``facts["retarget"]``): ``{kind: file name}``."""
    from .blender.export import write_retargeted_scene, write_solved_scene
    from .core.quiet import silenced_stdout

    paths = {kind: stem + "." + kind if on else None
             for kind, on in (("blend", settings.blend), ("fbx", settings.fbx), ("bvh", settings.bvh))}
    with silenced_stdout():  # Blender's "Saved copy as .partial.blend" and the exporters' lines
        if settings.retarget:
            from .commands.solve import plain

            character, armature = settings.character()
            written, done = write_retargeted_scene(take, solved, character, armature=armature,
                                                   bone_map=settings.bone_map, wrist=settings.retarget_wrist,
                                                   pinch=settings.pinch, bone_names=settings.bone_names, **paths)
            if facts is not None:
                facts["retarget"] = plain(done)
        else:
            written = write_solved_scene(take, solved, bone_names=settings.bone_names, **paths)
    return {kind: os.path.basename(path) for kind, path in written.items()}


class Progress:
    """Batch progress on stderr: a bar with ETAs, or JSON lines, or nothing.

    A take's time is a fixed part (process start, calibration, writing the .blend and FBX cost about the
    same for any take) and a part per byte of its file (the frames to label and solve). Two fits on the
    takes done (:meth:`model`), blended geometrically: ``a + b * size`` by least squares, which counts
    the more the more the sizes done differ (:data:`SPREAD`); and ``c * size ** p`` by least squares in
    logarithms, ``p`` between 0 (all of it fixed) and 1 (all of it per byte) drawn towards 1/2
    (:data:`PRIOR`), the geometric middle of the two, off by at most the square root of the sizes' ratio
    either way: one take done says its time scaled by the square root of the sizes' ratio. A worker's
    first take also pays for the worker's start (imports, model load): the fit leaves the first
    ``jobs`` takes out once as many others are done, and what they took beyond it is the warm-up
    (:meth:`warmup`) that such a take in flight is expected to take on top.

    The batch ETA is when the last worker would be free (:meth:`eta`): each take in flight takes what
    is left of its expected time (never less than nothing), the takes not started go in order to the
    first worker free, over ``jobs`` workers. Takes start in the order :meth:`begin` gives, as a worker
    frees (a pool's and a cluster's order); a ``start`` event says when one did. A take's time is its
    span from its start to its ``done`` event where known (what it cost the batch), else the seconds
    the event gives. Failed takes count as done, not in the fit; skipped ones cost nothing.
    """

    #: How strongly the fit's exponent is drawn towards 1/2: as much as takes whose log sizes vary by this
    #: much (squared, summed) pull it towards their own (sizes from 1 to 2.7 times each other).
    PRIOR = 1.0
    #: How much the sizes done must differ for the fit of a fixed cost and a cost per byte to count half:
    #: their count times their squared coefficient of variation.
    SPREAD = 0.5

    def __init__(self, sizes: dict[str, int], mode: str = "bar", jobs: int = 1, stream=None,
                 clock=time.perf_counter) -> None:
        self.sizes, self.mode, self.jobs, self.stream, self.clock = sizes, mode, jobs, stream or sys.stderr, clock
        self.total = len(sizes)
        self.done = 0
        self.first: set[str] = set()  # the takes each worker starts with (:meth:`begin`)
        self.cold: list[tuple[int, float]] = []  # (bytes, seconds) of those done
        self._sums = NO_SUMS  # of the others (:func:`_add`)
        self.queue: list[str] = []  # takes to run, not started
        self.running: dict[str, float] = {}  # take -> when it started (known or inferred)
        self.inferred: set[str] = set()  # takes whose start was inferred, not told
        self.freed: list[float] = []  # when workers came free, not yet taken by a take
        self.began: float | None = None

    def begin(self, names: list[str]) -> None:
        """The takes to run, in the order they start (the first ``jobs`` at once, then one as each worker frees)."""
        self.began = self.clock()
        self.queue = [n for n in names if n not in self.running]
        self.first = set(self.queue[:self.jobs])

    def _warm(self) -> bool:
        """Whether the fit leaves the workers' first takes out: once as many others are done (2 at least)."""
        return self._sums[0] >= max(2, len(self.cold))

    def _fit_sums(self) -> tuple:
        """The sums the fit uses (:func:`_add`): of the takes after the workers' first once :meth:`_warm`,
        else of every take done."""
        if self._warm():
            return self._sums
        sums = self._sums
        for size, seconds in self.cold:
            sums = _add(sums, size, seconds)
        return sums

    def model(self):
        """:meth:`seconds` as a function of the size (on a worker already started), fitted on the takes done;
        None before one is. ``a + b * size`` by least squares (a fixed cost and one per byte), and
        ``c * size ** p`` fitted in logarithms with ``p`` drawn towards 1/2 (:data:`PRIOR`), blended
        geometrically: the more the sizes done differ (:data:`SPREAD`), the more the first one counts."""
        n, sx, sy, sxx, sxy, ss, st, sss, sst = self._fit_sums()
        if not n:
            return None
        mx, my = sx / n, sy / n
        p = min(max((sxy - n * mx * my + self.PRIOR * 0.5) / (sxx - n * mx * mx + self.PRIOR), 0.0), 1.0)
        c = math.exp(my - p * mx)
        ms, mt = ss / n, st / n
        var = max(sss - n * ms * ms, 0.0)  # n times the sizes' variance
        weight = (var / (ms * ms)) / (var / (ms * ms) + self.SPREAD)
        if n < 2 or weight < 1e-6:
            return lambda size: c * _bytes(size) ** p
        b = (sst - n * ms * mt) / var
        a = mt - b * ms
        if b < 0:  # bigger takes were quicker: their sizes say nothing
            a, b = mt, 0.0
        elif a < 0:  # no fixed cost seen: time in proportion to bytes
            a, b = 0.0, st / ss
        return lambda size: (a + b * _bytes(size)) ** weight * (c * _bytes(size) ** p) ** (1.0 - weight)

    def seconds(self, size: int) -> float:
        """The seconds a take of ``size`` bytes is expected to take on a worker already started (:meth:`model`;
        NaN before a take is done)."""
        return self._predictor()(size)

    def _predictor(self):
        """:meth:`seconds` as a function of the size, the fit done once."""
        return self.model() or (lambda size: float("nan"))

    def warmup(self) -> float:
        """What a worker's first take took beyond :meth:`seconds` (its start), on average; 0 until the fit
        leaves those takes out (:meth:`_warm`)."""
        if not self._warm() or not self.cold:
            return 0.0
        predict = self._predictor()
        return sum(max(t - predict(s), 0.0) for s, t in self.cold) / len(self.cold)

    def _timed(self, name: str, size: int, seconds: float) -> None:
        if name in self.first:
            self.cold.append((size, seconds))
        else:
            self._sums = _add(self._sums, size, seconds)

    def expected(self, name: str) -> float:
        """The seconds take ``name`` is expected to take, a worker's start included where it is the worker's
        first (NaN before a take is done)."""
        return self._expecting()(name)

    def _expecting(self):
        """:meth:`expected` as a function of the take, the fit done once."""
        predict, warmup = self._predictor(), self.warmup()
        return lambda name: predict(self.sizes.get(name, 0)) + (warmup if name in self.first else 0.0)

    def eta(self, now: float | None = None) -> float:
        """Seconds until the last take is done (NaN before the takes are known or one is done; 0 when
        none is left)."""
        if self.began is None:
            return float("nan")
        if not self.queue and not self.running:
            return 0.0
        if self.model() is None:
            return float("nan")
        now = self.clock() if now is None else now
        expected = self._expecting()
        free = [max(expected(n) - (now - start), 0.0) for n, start in self.running.items()]
        free += [0.0] * max(self.jobs - len(free), 0)
        heapq.heapify(free)
        for name in self.queue:  # list scheduling: each next take to the first worker free
            heapq.heapreplace(free, free[0] + expected(name))
        return max(free)

    def _fill(self) -> None:
        """Start the takes a free worker would have started (in :meth:`begin`'s order)."""
        while self.queue and self.began is not None and len(self.running) < self.jobs:
            name = self.queue.pop(0)
            self.running[name] = self.freed.pop(0) if self.freed else self.began
            self.inferred.add(name)

    def _started(self, name: str, now: float) -> None:
        if name in self.queue:
            self.queue.remove(name)
            if len(self.running) >= self.jobs and self.inferred:  # the take thought started was not yet
                back = max(self.inferred, key=lambda n: self.running[n])
                self.inferred.discard(back)
                self.running.pop(back)
                self.queue.insert(0, back)
        self.running[name] = now
        self.inferred.discard(name)

    def event(self, kind: str, **fields) -> None:
        name = fields.get("name", "")
        size = self.sizes.get(name, 0)
        now = self.clock()
        self._fill()
        if kind == "start":
            self._started(name, now)
        elif kind in ("done", "failed", "skipped"):
            self.done += 1
            if name in self.queue:  # finished before it was thought started: a worker ran it instead
                self._started(name, now - fields.get("seconds", 0.0))
            start = self.running.pop(name, None)
            self.inferred.discard(name)
            if kind != "skipped":
                self.freed.append(now)
            if kind == "done":
                self._timed(name, size, now - start if start is not None else fields.get("seconds", 0.0))
            self._fill()
        batch_eta = self.eta(now)
        take_eta = self.expected(name) if kind == "start" else float("nan")
        if self.mode == "json":
            line = {"event": kind, "done": self.done, "total": self.total, **fields}
            if batch_eta == batch_eta:
                line["eta_s"] = round(batch_eta, 1)
            if take_eta == take_eta:
                line["take_eta_s"] = round(take_eta, 1)
            print(json.dumps(line), file=self.stream, flush=True)
        elif self.mode == "bar":
            width = 24
            filled = int(width * self.done / max(self.total, 1))
            what = {"start": "working on", "done": "done", "failed": "FAILED", "skipped": "skipped",
                    "end": "finished"}.get(kind, kind)
            extra = f": {fields['error']}" if kind == "failed" else ""
            if take_eta == take_eta:
                extra = f" (about {_clock(take_eta)})"
            elif kind in ("done", "failed"):
                extra = f" in {_clock(fields.get('seconds', 0.0))}" + extra
            print(f"[{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} ETA {_clock(batch_eta)}  "
                  f"{what} {name}{extra}", file=self.stream, flush=True)


def _bytes(size: int) -> float:
    """A file's size for the ETA's fit: at least a kilobyte (an empty or unreadable file still costs a take)."""
    return max(float(size), 1024.0)


#: No take done yet: count, then the sums of x, y, x², xy (x, y the logs of bytes and seconds), then of
#: s, t, s², st (bytes and seconds).
NO_SUMS = (0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def _add(sums: tuple, size: int, seconds: float) -> tuple:
    """``sums`` (:data:`NO_SUMS`) with one take more."""
    n, sx, sy, sxx, sxy, ss, st, sss, sst = sums
    b = _bytes(size)
    x, y = math.log(b), math.log(max(seconds, 1e-3))
    return (n + 1, sx + x, sy + y, sxx + x * x, sxy + x * y, ss + b, st + seconds, sss + b * b, sst + b * seconds)


def _clock(seconds: float) -> str:
    if seconds != seconds:
        return "--:--"
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}" if seconds >= 3600 else \
        f"{seconds // 60:02d}:{seconds % 60:02d}"


def _clean_partials(out_dir: str) -> None:
    """Remove temporary files a killed run left behind (outputs are renamed into place only when whole)."""
    for root, _, files in os.walk(out_dir):
        for name in files:
            if name.startswith(".") and ".partial" in name:
                try:
                    os.remove(os.path.join(root, name))
                except OSError:
                    pass


def run_batch(inputs: list[str], out_dir: str, settings: BatchSettings, progress: str = "bar") -> dict:
    """Process every take; returns the summary (also written as summary.json and summary.csv)."""
    os.makedirs(out_dir, exist_ok=True)
    _clean_partials(out_dir)
    records = read_records(out_dir)
    takes = find_takes(inputs, {name: r["file"] for name, r in records.items() if isinstance(r.get("file"), str)},
                       out_dir)
    made_with = settings_digest(settings)
    run = secrets.token_hex(8)  # this run's mark in the reports it writes
    sizes = {name: (os.path.getsize(path) if os.path.isfile(path) else 0) for path, name in takes}
    bar = Progress(sizes, progress, max(1, settings.jobs))
    rows: list[dict] = []
    todo = []
    for path, name in takes:
        report = records.get(name)
        if not settings.force and _finished(report, path, out_dir, name, made_with):
            bar.event("skipped", name=name)
            rows.append(_row(report, skipped=True))
        else:
            todo.append((path, name))
    start = time.perf_counter()
    workers = settings.jobs
    bar.begin([name for _, name in todo])
    if settings.scheduler:
        from .farm import farm_client, run_on_farm, worker_threads

        with farm_client(settings.scheduler) as client:
            workers = bar.jobs = worker_threads(client)
            bar.begin([name for _, name in todo])  # the cluster's workers are here now
            task = functools.partial(farm_take, made_with=made_with, run=run)
            for report in run_on_farm(client, todo, out_dir, settings, task,
                                      functools.partial(failed_report, run=run)):
                rows.append(_finish(bar, report))
    elif settings.jobs <= 1 or len(todo) <= 1:
        for path, name in todo:
            bar.event("start", name=name)
            rows.append(_finish(bar, process_take(path, name, out_dir, settings, made_with, run)))
    else:
        rows += _run_pool(todo, out_dir, settings, bar, made_with, run)
    _clean_partials(out_dir)  # what a worker killed mid-take left (its take was redone or is reported)
    wall = time.perf_counter() - start
    rows.sort(key=lambda r: r["name"])
    failed = [r for r in rows if r["status"] == "failed"]
    frames = sum(r["frames"] or 0 for r in rows if not r["skipped"] and r["status"] == "ok")
    # Takes of earlier runs whose outputs are in this folder but whose inputs this run was not given: listed
    # apart, so that the summary and the index name everything the folder holds.
    ours = {name for _, name in takes}
    earlier = [_row({**report, "name": name}, skipped=True) | {"status": EARLIER}
               for name, report in sorted(records.items()) if name not in ours]
    summary = {"takes": len(rows), "ok": sum(r["status"] == "ok" for r in rows), "failed": len(failed),
               "skipped": sum(r["skipped"] for r in rows), "earlier": len(earlier), "seconds": round(wall, 3),
               "frames_processed": frames, "frames_per_second": round(frames / wall, 1) if wall > 0 else None,
               "jobs": settings.jobs if not settings.scheduler else workers, "scheduler": settings.scheduler,
               "settings": dataclasses.asdict(settings) | {"extra": None}, "takes_detail": rows,
               "earlier_detail": earlier}
    _write_summary(out_dir, summary)
    if settings.html:
        from .core.atomic import atomic_output
        from .html_report import index_page

        with atomic_output(os.path.join(out_dir, "index.html")) as tmp, open(tmp, "w", encoding="utf-8") as f:
            f.write(index_page(rows + earlier, f"Batch: {os.path.abspath(out_dir)}"))
    else:  # an earlier run's index would link pages this run removed
        with contextlib.suppress(FileNotFoundError):
            os.remove(os.path.join(out_dir, "index.html"))
    bar.event("end", name=f"{summary['ok']} ok, {summary['failed']} failed, {summary['skipped']} skipped")
    return summary


#: Times a take is started in a pool whose worker process died before the take is reported as failed.
POOL_TRIES = 3


def _run_pool(todo: list[tuple[str, str]], out_dir: str, settings: BatchSettings, bar: Progress,
              made_with: str | None = None, run: str | None = None) -> list[dict]:
    """The takes in ``settings.jobs`` spawned processes; a pool whose process died (killed, out of memory) is
    started again for the takes not finished, each up to :data:`POOL_TRIES` times, then reported as failed."""
    rows: list[dict] = []
    tries = dict.fromkeys((name for _, name in todo), 0)
    with environ(thread_caps(settings.jobs)):  # spawned workers read these before numpy and onnxruntime start
        context = multiprocessing.get_context("spawn")
        while todo:
            broken = []
            others = set(multiprocessing.active_children())
            with ProcessPoolExecutor(settings.jobs, mp_context=context, initializer=_pool_init,
                                     initargs=(os.getpid(),)) as pool:
                pending = {}
                for path, name in todo:  # no "start" events: the pool decides when a take starts
                    tries[name] += 1
                    pending[pool.submit(_pool_take, path, name, out_dir, settings, made_with, run)] = (path, name)
                while pending:
                    finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in finished:
                        path, name = pending.pop(fut)
                        try:
                            fut.result()
                            rows.append(_finish(bar, _read_report(out_dir, name)))
                        except BrokenProcessPool:
                            broken.append((path, name))
                _end_workers(pool, set(multiprocessing.active_children()) - others)
            todo = []
            for path, name in broken:
                if tries[name] < POOL_TRIES:
                    todo.append((path, name))
                else:
                    rows.append(_finish(bar, failed_report(path, name, out_dir, f"its worker process died on "
                                                           f"each of {POOL_TRIES} tries (killed, or out of memory)",
                                                           run)))
    return rows


def _end_workers(pool: ProcessPoolExecutor, workers: set) -> None:
    """End a pool whose every take is reported: its workers hold nothing more of the batch's.

    A worker killed (out of memory, by a user) right after handing back the last result still held the
    result pipe's lock, and the pool's graceful shutdown then waits for ever on another worker that waits
    on that lock to say it is leaving (the pool only ends its workers by force when a death comes before
    its last result). Ending them by force here, as the pool itself does with a broken pool, cannot lose
    work: every output is written and every report read.
    """
    pool.shutdown(wait=False, cancel_futures=True)
    for worker in workers:
        worker.terminate()
    for worker in workers:
        worker.join()


def _read_report(out_dir: str, name: str) -> dict:
    with open(os.path.join(out_dir, name + REPORT), encoding="utf-8") as f:
        return json.load(f)


def _finish(bar: Progress, report: dict) -> dict:
    row = _row(report, skipped=False)
    if row["status"] == "ok":
        bar.event("done", name=row["name"], seconds=row["seconds"])
    else:
        bar.event("failed", name=row["name"], seconds=row["seconds"], error=row["error"])
    return row


#: The status of a take listed from an earlier run's report: its outputs are in the folder, its input was
#: not among this run's.
EARLIER = "earlier run"


def _row(report: dict, skipped: bool) -> dict:
    summary = report.get("summary") or {}
    hand = report.get("hand") or {}
    return {"name": report.get("name"), "file": report.get("file"), "status": report.get("status"),
            "skipped": skipped, "error": report.get("error", ""), "warning": report.get("warning", ""),
            "frames": report.get("frames"), "hands": report.get("hands"),
            "sides": " ".join(h["side"] for h in report.get("per_hand", [])),
            "confident_share": round(summary["confident_share"], 4) if "confident_share" in summary else None,
            "uncertain_segments": len(summary.get("uncertain_segments", [])) if summary else None,
            "marker_rms_mm": hand.get("marker_rms_mm"),
            "retarget": _retarget_cell(report.get("retarget")),
            "seconds": (report.get("seconds") or {}).get("total", 0.0),
            "page": report.get("name", "") + ".report.html" if "html" in report.get("outputs", {}) else None,
            # the take's files in the output folder, its report too: exactly what is on disk for it
            "outputs": sorted(os.path.join(os.path.dirname(report.get("name") or ""), f)
                              for f in [*(report.get("outputs") or {}).values(),
                                        os.path.basename(report.get("name") or "") + REPORT])}


def _retarget_cell(facts: dict | None) -> str | None:
    """A take's retargeting in the summary: ``Armature (left 16, right 16 bones)``, or None."""
    if not isinstance(facts, dict):
        return None
    hands = ", ".join(f"{side} {len(f.get('bones', ()))}" for side, f in (facts.get("hands") or {}).items())
    return f"{facts.get('armature')} ({hands} bones)" if hands else str(facts.get("armature"))


def _write_summary(out_dir: str, summary: dict) -> None:
    from .core.atomic import atomic_output

    with atomic_output(os.path.join(out_dir, "summary.json")) as tmp, open(tmp, "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=1)
    buf = io.StringIO()
    cols = ["name", "status", "skipped", "frames", "hands", "sides", "confident_share", "uncertain_segments",
            "marker_rms_mm", "retarget", "seconds", "error", "warning", "file"]
    writer = csv.DictWriter(buf, cols, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(summary["takes_detail"] + summary.get("earlier_detail", []))
    with atomic_output(os.path.join(out_dir, "summary.csv")) as tmp, open(tmp, "w", encoding="utf-8",
                                                                         newline="") as f:
        f.write(buf.getvalue())


def format_table(summary: dict) -> str:
    """The summary as a plain-text table for the terminal."""
    rows = summary["takes_detail"]
    head = ("take", "status", "frames", "hands", "confident", "uncertain", "hand RMS mm", "s")
    body = [(r["name"], ("skipped" if r["skipped"] else r["status"]) + (" *" if r["error"] else " !" if r.get("warning")
                                                                         else ""),
             str(r["frames"] or ""), "" if not r.get("hands") else
             (f"{r['hands']} ({r['sides']})" if r.get("sides") else str(r["hands"])),
             "" if r["confident_share"] is None else f"{100 * r['confident_share']:.1f} %",
             "" if r["uncertain_segments"] is None else str(r["uncertain_segments"]),
             "" if r["marker_rms_mm"] is None else f"{r['marker_rms_mm']:.2f}", f"{r['seconds']:.1f}")
            for r in rows]
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(b, widths)) for b in body]
    for r in rows:
        if r["error"]:
            lines.append(f"* {r['name']}: {r['error']}")
        elif r.get("warning"):
            lines.append(f"! {r['name']}: {r['warning']}")
    lines.append(f"{summary['ok']} ok, {summary['failed']} failed, {summary['skipped']} skipped; "
                 f"{summary['frames_processed']:,} frames in {summary['seconds']:.1f} s " +
                 (f"on {summary['jobs']} Dask worker thread(s) ({summary['scheduler']})" if summary.get("scheduler")
                  else f"with {summary['jobs']} job(s)"))
    earlier = [r["name"] for r in summary.get("earlier_detail", [])]
    if earlier:
        shown = ", ".join(earlier[:5]) + (f" and {len(earlier) - 5} more" if len(earlier) > 5 else "")
        lines.append(f"also in the folder from earlier runs (their inputs are not among this run's): {shown}")
    return "\n".join(lines)
