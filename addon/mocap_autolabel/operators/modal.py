"""Running a core job in the background while Blender stays responsive (Label Markers, Solve Hand,
Fill Gaps): the work runs on a worker thread (:class:`..core.jobs.Job`, no Blender data touched),
a 0.1 s timer polls it, the status bar shows the stage and the share done, Esc cancels and leaves
the scene as it was (the scene is written only on the main thread, once the work is complete)."""

from __future__ import annotations

import bpy


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


def end_modal(operator, context) -> None:
    """Stop polling: the timer, the progress bar and the status text go."""
    wm = context.window_manager
    wm.event_timer_remove(operator._timer)
    wm.progress_end()
    context.workspace.status_text_set(None)


def in_background(context) -> bool:
    """Whether an operator invoked in ``context`` can run its work in the background: a window to
    poll from (not a script's ``execute``, not ``blender -b``, where modal handlers never run)."""
    return context.window is not None and not bpy.app.background


class JobModal:
    """The ``modal`` of an operator whose work runs as a :class:`..core.jobs.Job` (:func:`start_modal`).

    The operator provides ``_progress(job) -> (text, share)`` for the status bar, ``_job_failed(exc)``
    and ``_job_done(context, result)`` (main thread, the scene written there); a cancel reports
    "<label> cancelled; the scene is unchanged"."""

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if not job.done:
            text, share = self._progress(job)
            context.workspace.status_text_set(f"{text}, {100 * share:.0f} % ({job.elapsed:.1f} s) - Esc to cancel")
            context.window_manager.progress_update(min(99, int(100 * share)))
            return {"PASS_THROUGH"}
        end_modal(self, context)
        if job.cancelled:
            self.report({"WARNING"}, f"{self.bl_label} cancelled; the scene is unchanged")
            return {"CANCELLED"}
        if job.error is not None:
            return self._job_failed(job.error)
        return self._job_done(context, job.result)
