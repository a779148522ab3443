"""Long work from a modal timer: progress bar, status line, Esc to cancel.

A :class:`Job` runs a core worker ``work(progress, cancel)`` on a thread of its own (the worker
touches no bpy), while the operator's modal handler wakes on a timer, moves the progress bar and
the panel's status line, and on Esc asks the worker to stop; the worker then returns what it
has done, which is applied like a finished run. The result is applied on the main thread.

:class:`JobOperator` is the modal operator around a job; subclasses give ``prepare(context)``,
which reads the scene and returns the worker, and ``finish(context, value, cancelled)``.
"""

import threading
import time
import traceback

import bpy

from ..core.errors import ZoopraxisError
from .guard import SceneGuard

TIMER_STEP = 0.1


class Job:
    """A worker on a thread, observed by polling.

    Parameters
    ----------
    work : callable(progress, cancel) -> object
        ``progress(done, total)`` may be called from the worker thread; ``cancel()`` returns
        True once :meth:`cancel` was called.
    """

    def __init__(self, work):
        self.work = work
        self.done = 0
        self.total = 0
        self.value = None
        self.error = None
        self.finished = threading.Event()
        self._cancel = threading.Event()
        self._thread = None
        self.started = None

    def progress(self, done, total):
        self.done, self.total = int(done), int(total)

    def cancel(self):
        self._cancel.set()

    @property
    def cancelled(self):
        return self._cancel.is_set()

    @property
    def fraction(self):
        return min(1.0, self.done / self.total) if self.total else 0.0

    def _run(self):
        try:
            self.value = self.work(self.progress, self._cancel.is_set)
        except BaseException as ex:  # handed to the main thread, which reports it
            self.error = ex
            self.traceback = traceback.format_exc()
        finally:
            self.finished.set()

    def start(self):
        self.started = time.perf_counter()
        self._thread = threading.Thread(target=self._run, name="zoopraxis-job", daemon=True)
        self._thread.start()
        return self

    def run_here(self):
        """Run on the calling thread (headless, or from scripts)."""
        self.started = time.perf_counter()
        self._run()
        return self

    def wait(self, timeout=None):
        return self.finished.wait(timeout)

    def status(self, label):
        if self.cancelled and not self.finished.is_set():
            return f"{label}: stopping after this frame..."
        if self.total:
            return f"{label}: {self.done}/{self.total} ({100 * self.fraction:.0f}%), Esc to stop"
        return f"{label}: starting, Esc to stop"


def one_line(ex):
    """The user's line for an error: a ZoopraxisError's own message; for anything else (a bug)
    its type and message, and where to find the rest."""
    message = " ".join(str(ex).split())
    if isinstance(ex, ZoopraxisError):
        return message
    return f"internal error, see the console: {type(ex).__name__}: {message[:200]}"


def report_error(operator, ex, tb=None):
    """One short ERROR line for the user, the traceback for the console."""
    operator.report({'ERROR'}, one_line(ex))
    print(tb or "".join(traceback.format_exception(ex)), flush=True)


class JobOperator:
    """Mixin for a modal operator that runs a :class:`Job` (see module docstring)."""

    label = "Working"

    def prepare(self, context):
        """Read the scene; return ``work(progress, cancel)``. May raise ZoopraxisError."""
        raise NotImplementedError

    def finish(self, context, value, cancelled):
        """Apply the worker's value on the main thread; return a one-line summary."""
        raise NotImplementedError

    def cleanup(self):
        """Release what ``prepare`` opened (plates)."""

    # -- Blender entry points ------------------------------------------------------------

    def execute(self, context):
        """Run to the end on this thread (scripts, tests, background mode)."""
        settings = context.scene.zoopraxis
        try:
            work = self.prepare(context)
            job = Job(work).run_here()
            return self._complete(context, job)
        except Exception as ex:
            report_error(self, ex)
            return {'CANCELLED'}
        finally:
            settings.running = False
            self.cleanup()

    def invoke(self, context, event):
        settings = context.scene.zoopraxis
        if settings.running:
            self.report({'ERROR'}, "another Zoopraxis job is running (Esc stops it)")
            return {'CANCELLED'}
        if context.window is None or bpy.app.background:
            return self.execute(context)
        try:
            work = self.prepare(context)
        except Exception as ex:
            report_error(self, ex)
            self.cleanup()
            return {'CANCELLED'}
        self._job = Job(work).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_STEP, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 1000)
        settings.running = True
        settings.progress = 0.0
        settings.status = self._job.status(self.label)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        job = self._job
        if event.type == 'ESC' and event.value == 'PRESS':
            job.cancel()
        elif event.type != 'TIMER':
            return {'PASS_THROUGH'}
        settings = context.scene.zoopraxis
        settings.progress = job.fraction
        settings.status = job.status(self.label)
        context.window_manager.progress_update(int(1000 * job.fraction))
        for area in context.screen.areas if context.screen else ():
            area.tag_redraw()
        if not job.finished.is_set():
            return {'RUNNING_MODAL'}
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        settings.running = False
        try:
            return self._complete(context, job)
        finally:
            self.cleanup()

    def _complete(self, context, job):
        settings = context.scene.zoopraxis
        if job.error is not None:
            if not isinstance(job.error, Exception):  # KeyboardInterrupt, SystemExit
                raise job.error
            report_error(self, job.error, job.traceback)
            settings.status = f"{self.label}: failed: {one_line(job.error)}"
            return {'CANCELLED'}
        if job.value is None:
            settings.status = f"{self.label}: stopped before any frame was done"
            self.report({'WARNING'}, settings.status)
            return {'CANCELLED'}
        from .bake import ensure_object_mode

        try:
            with SceneGuard(context.scene):
                summary = self.finish(context, job.value, job.cancelled)
        except Exception as ex:
            report_error(self, ex)
            settings.status = f"{self.label}: failed: {one_line(ex)}"
            return {'CANCELLED'}
        finally:
            ensure_object_mode(context)
        elapsed = time.perf_counter() - job.started
        settings.status = f"{summary} ({elapsed:.1f} s)"
        settings.progress = 1.0
        self.report({'WARNING'} if job.cancelled else {'INFO'}, settings.status)
        return {'FINISHED'}
