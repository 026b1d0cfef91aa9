"""The worker-thread job the Label operator polls (Blender-free)."""

from __future__ import annotations

import threading

import pytest
from mocap_autolabel.core.jobs import Cancelled, Job


def test_job_returns_its_result_and_last_message():
    job = Job(lambda say: (say("half way"), 42)[1]).start()
    assert job.wait(5)
    assert job.done and job.result == 42 and job.error is None and job.message == "half way"


def test_job_hands_its_error_to_the_caller():
    def work(say):
        raise ValueError("bad take")

    job = Job(work).start()
    job.wait(5)
    assert isinstance(job.error, ValueError) and not job.cancelled


def test_cancel_stops_the_job_at_its_next_message():
    gate = threading.Event()
    reached = []

    def work(say):
        say("first stage")
        gate.wait(5)
        say("second stage")
        reached.append("second")
        return "finished"

    job = Job(work).start()
    job.cancel()
    gate.set()
    job.wait(5)
    assert job.cancelled and reached == []
    with pytest.raises(Cancelled):
        job._say("anything")
