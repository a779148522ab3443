"""Running a take's passes: one after the other, or in forked worker processes; progress,
cancel and passes that start when another ends.

A job is one pass (or part of one, or a batch of measures); ``run(job, report, should_stop)``
tracks it, calling ``report(n)`` as frames are done and raising :class:`Cancelled` with what it
has done when ``should_stop()`` says so.
"""

class Cancelled(Exception):
    """Raised inside the tracking loop when the caller's cancel() says so."""


def _run_in_turn(run, jobs, progress, cancel, then=None):
    """Run the passes one after the other; a cancel keeps the frames tracked so far.

    ``progress(n)`` gets the frames tracked so far; ``then(job, frames)``, called as each pass
    ends, returns the passes to run after it (:func:`track`'s passes that go on).
    """
    results = {}
    done = 0

    def report(n):
        nonlocal done
        done += n
        if progress is not None:
            progress(done)

    queue = list(jobs)
    while queue:
        job = queue.pop(0)
        try:
            results[job] = run(job, report, cancel)
        except Cancelled as exc:
            results[job] = exc.args[0]
            return results, True
        if then is not None:
            queue += then(job, results[job])
    return results, False


class _Later:
    """``fn(*args)`` made when its result is asked for (a future without a thread)."""

    __slots__ = ("fn", "args")

    def __init__(self, fn, *args):
        self.fn, self.args = fn, args

    def result(self):
        return self.fn(*self.args)


def default_cores():
    """Cores this process may run on."""
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:      # not on Linux
        return os.cpu_count() or 1


def default_workers():
    """Worker processes for the passes when none are asked for: one per core, at most 4."""
    return min(default_cores(), 4)


def _can_fork():
    """Worker processes share the take by forking: on Linux (macOS forbids forking a process
    with system frameworks loaded, Windows cannot fork), and not inside the Blender application
    (its window, GPU and job threads must not be forked; Blender as a Python module may)."""
    import multiprocessing
    import sys

    bpy = sys.modules.get("bpy")
    in_blender = bpy is not None and bool(getattr(getattr(bpy, "app", None), "binary_path", ""))
    return (sys.platform.startswith("linux") and not in_blender
            and "fork" in multiprocessing.get_all_start_methods())


_FORKED = None      # (run, counter, stop event): what a forked worker runs


def _ignore_interrupt():
    """Ctrl-C reaches the whole process group: the parent turns it into a polite stop."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _forked_pass(job):
    run, counter, stop = _FORKED

    def report(n):
        with counter.get_lock():
            counter.value += n

    try:
        return run(job, report, stop.is_set), False
    except Cancelled as exc:
        return exc.args[0], True


def _run_in_processes(run, jobs, workers, progress, cancel, then=None):
    """Run independent passes in forked worker processes (they inherit the plates, the
    background models and the tracker), polling progress and cancel every quarter second.
    ``progress`` and ``then`` as in :func:`_run_in_turn`: a pass ``then`` returns starts as
    soon as a worker is free."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    global _FORKED
    ctx = multiprocessing.get_context("fork")
    counter = ctx.Value("i", 0)
    stop = ctx.Event()
    _FORKED = (run, counter, stop)
    results, cancelled = {}, False
    try:
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_ignore_interrupt) as pool:
            futures = {pool.submit(_forked_pass, job): job for job in jobs}
            pending = set(futures)
            try:
                while pending:
                    finished, pending = wait(pending, timeout=0.25,
                                             return_when=FIRST_COMPLETED)
                    for fut in finished:
                        out, was_cancelled = fut.result()
                        job = futures[fut]
                        results[job] = out
                        cancelled |= was_cancelled
                        if then is not None and not (cancelled or stop.is_set()):
                            for new in then(job, out):
                                started = pool.submit(_forked_pass, new)
                                futures[started] = new
                                pending.add(started)
                    if progress is not None:
                        progress(counter.value)
                    if cancel is not None and not stop.is_set() and cancel():
                        stop.set()
            except BaseException:
                # an error in one pass, or a second Ctrl-C: the other workers stop at their
                # next frame instead of finishing their passes before the pool closes
                stop.set()
                raise
    finally:
        _FORKED = None
    return results, cancelled or stop.is_set()
