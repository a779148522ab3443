"""Progress reporting for long work, shared by the command line and the add-on.

Workers take ``progress(done, total)`` and ``cancel() -> bool`` callables; the command line
passes a :class:`ConsoleProgress`, the add-on a window-manager progress bar. Ctrl-C on the
command line raises KeyboardInterrupt, which every worker lets through after keeping what it
has finished.
"""

import sys
import time


class ConsoleProgress:
    """Print ``label: done/total unit (percent, rate)`` lines, at most every ``interval`` s.

    Parameters
    ----------
    label : str
    unit : str
        What is being counted ("frames").
    stream : file, optional
        Defaults to stderr, so that a command's own output on stdout stays clean.
    """

    def __init__(self, label, unit="frames", stream=None, interval=1.0):
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self.interval = interval
        self._start = time.perf_counter()
        self._last = -1e9

    def __call__(self, done, total):
        now = time.perf_counter()
        if done < total and now - self._last < self.interval:
            return
        self._last = now
        elapsed = max(now - self._start, 1e-9)
        pct = 100.0 * done / total if total else 100.0
        print(f"{self.label}: {done}/{total} {self.unit} ({pct:.0f}%, "
              f"{done / elapsed:.1f} {self.unit}/s)", file=self.stream, flush=True)


def never():
    """A cancel callback that never cancels."""
    return False
