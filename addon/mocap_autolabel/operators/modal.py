"""Running a core job in the background while Blender stays responsive (Label Markers, Solve Hand)."""

from __future__ import annotations


def start_modal(operator, context, job) -> set[str]:
    """Start ``job`` (a :class:`..core.jobs.Job`) and make ``operator`` modal: a 0.1 s timer calls its
    ``modal`` to poll the job, and the window manager's progress bar is on. The operator keeps the
    job as ``_job`` and the timer as ``_timer``."""
    operator._job = job.start()
    wm = context.window_manager
    operator._timer = wm.event_timer_add(0.1, window=context.window)
    wm.modal_handler_add(operator)
    wm.progress_begin(0, 100)
    return {"RUNNING_MODAL"}
