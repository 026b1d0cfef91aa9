"""Batch takes as tasks on a Dask cluster (``batch --scheduler``): a farm's scheduler or a local one.

Each take is one task running :func:`mocap_autolabel.batch.process_take` on a worker, which writes the
take's outputs atomically into the output folder (a folder every worker and this process see under
the same path). Dask reschedules the task of a worker that dies (``distributed.scheduler.allowed-failures``
times) and retries a task that raised (``retries``); a take that fails on every try is reported like a
bad file. Needs the optional ``distributed`` package (``pip install "mocap_autolabel[farm]"``); nothing
else in the package imports it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import re
from collections.abc import Callable, Iterator

from .worker_env import environ, thread_caps

#: Tries per take for a task that raised (a worker that died is rescheduled by Dask on its own).
TRIES = 3

MISSING = ('batch --scheduler needs Dask\'s distributed package, which is not installed: '
           'pip install "mocap_autolabel[farm]" (or pip install distributed)')


class FarmError(Exception):
    """The cluster cannot be used (package missing, scheduler unreachable, bad address); one line."""


def parse_scheduler(text: str) -> tuple[str, int | str]:
    """``("local", N)`` for ``local:N``, else ``("address", text)`` for a scheduler such as ``tcp://host:8786``."""
    match = re.fullmatch(r"local:(\d+)", text.strip())
    if match:
        n = int(match.group(1))
        if not 1 <= n <= 64:
            raise FarmError(f"--scheduler {text}: a local cluster has 1 to 64 workers")
        return "local", n
    if not re.fullmatch(r"([a-z]+://)?[^\s:/]+:\d+", text.strip()):
        raise FarmError(f"--scheduler {text}: give a scheduler address (tcp://HOST:8786) or local:N")
    return "address", text.strip()


@contextlib.contextmanager
def farm_client(scheduler: str, threads_per_worker: int | None = None) -> Iterator:
    """A ``distributed.Client`` on ``scheduler`` (``local:N`` starts N worker processes here and stops them after).

    A local cluster's workers run one task each, with ``threads_per_worker`` threads for numpy and
    onnxruntime (default: this machine's cores shared among them).
    """
    kind, where = parse_scheduler(scheduler)
    if importlib.util.find_spec("distributed") is None:
        raise FarmError(MISSING)
    if kind == "local":
        env = thread_caps(int(where), threads_per_worker)
        with environ(env):  # the workers' thread caps, read as numpy and onnxruntime load
            _start_forkserver()  # it imports while this process imports Dask
    from distributed import Client, LocalCluster

    if kind == "local":
        import dask

        # Dask's nanny makes glibc hand freed memory back to the system at 64 KiB (its
        # MALLOC_TRIM_THRESHOLD_): labeling allocates and frees large numpy temporaries, and paid
        # for that in page faults (the same takes 15 % slower than in batch --jobs). glibc's own
        # default instead (None unsets it); the thread caps as set above. Nor does a worker sample its own stack every
        # 10 ms for Dask's profiler (a dashboard this cluster does not serve). The event-loop tick (20 ms),
        # system monitor (0.5 s) and memory monitor (0.1 s) wake each worker's loop for the GIL while it
        # labels, and work stealing moves nothing when each worker holds one take: slowed, and off
        # (8 takes: Dask's time against batch --jobs 2 from +11.8 % to +9.1 %, medians of 5 pairs of runs).
        for attempt in range(TRIES):  # a worker process that dies while the cluster starts fails the start
            try:
                with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                                      "distributed.worker.profile.enabled": False,
                                      "distributed.worker.multiprocessing-method": "forkserver",
                                      "distributed.scheduler.worker-saturation": 1.0,
                                      "distributed.admin.tick.interval": "1s",
                                      "distributed.admin.system-monitor.interval": "2s",
                                      "distributed.worker.memory.monitor-interval": "1s",
                                      "distributed.scheduler.work-stealing": False}):
                    cluster = LocalCluster(n_workers=int(where), threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=logging.ERROR, env=env)
                break
            except (RuntimeError, OSError, TimeoutError) as exc:
                if attempt == TRIES - 1:
                    raise FarmError(f"could not start a local Dask cluster of {where} workers: {exc}") from None
        with cluster, Client(cluster) as client:
            yield client
        return
    try:
        client = Client(where)  # waits Dask's distributed.comm.timeouts.connect (30 s by default)
    except (OSError, TimeoutError) as exc:
        raise FarmError(f"cannot reach the Dask scheduler at {where}: {exc}") from None
    with client:
        yield client


#: What the local cluster's fork server imports once, before it forks each worker: a worker then
#: starts without importing Dask and the labeling (about 0.6 s of CPU each, on this 2-core machine
#: most of what a local cluster cost beyond ``batch --jobs``).
PRELOAD = ["distributed", "numpy", "scipy.optimize", "scipy.sparse", "onnxruntime", "mocap_autolabel.batch",
           "mocap_autolabel.core.process"]


def _start_forkserver() -> None:
    """Start multiprocessing's fork server with :data:`PRELOAD`: the local cluster's workers are
    forked from it (``distributed.worker.multiprocessing-method``), a single-threaded process,
    unlike this one."""
    import multiprocessing
    from multiprocessing import forkserver

    # One started for an earlier cluster of this process has that moment's environment (another
    # cluster's thread caps): stopped (CPython 3.8+), and a new one started. Left running at the
    # end of a run, it ends with this process.
    stop = getattr(forkserver._forkserver, "_stop", None)
    if stop is not None:
        stop()
    multiprocessing.get_context("forkserver").set_forkserver_preload(PRELOAD)
    forkserver.ensure_running()


def worker_threads(client) -> int:
    """Tasks the cluster runs at once (its workers' threads), at least 1."""
    return max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))


def run_on_farm(client, todo: list[tuple[str, str]], out_dir: str, settings, task: Callable,
                failed: Callable[[str, str, str, str], dict]) -> Iterator[dict]:
    """Submit ``task(path, name, out_dir, settings)`` per take; yield each take's report as it finishes.

    Paths are made absolute, so workers must see inputs and ``out_dir`` under the same paths. A take
    whose task failed on every try (its worker died each time, or it raised) yields
    ``failed(path, name, out_dir, reason)``. A take's future is released once its report is here, so a
    worker that dies later costs no finished take a second run (a task that finished as its worker died,
    before the report came, is run again: :func:`mocap_autolabel.batch.process_take` then finds the
    take's report of this run and writes nothing).
    """
    from distributed import as_completed

    out_dir = os.path.abspath(out_dir)
    futures = {}
    for path, name in todo:
        fut = client.submit(task, os.path.abspath(path), name, out_dir, settings, retries=TRIES - 1, pure=False,
                            key=f"mocap_autolabel-{name}-{os.urandom(6).hex()}")
        futures[fut] = (path, name)
    # Each future is let go as soon as its report is here: a task whose result the client still holds is
    # run again by the scheduler when the worker that holds it dies (rewriting the take's outputs, and
    # delaying the rest). as_completed keeps none it has yielded.
    for fut in as_completed(list(futures)):
        path, name = futures.pop(fut)
        try:
            report = fut.result()
        except Exception as exc:  # KilledWorker (it died on every try) or what the task raised each time
            report = failed(path, name, out_dir, f"failed on every try on the cluster ({type(exc).__name__}: {exc})")
        fut.release()
        del fut
        yield report
