"""Worker processes that end quietly with their parent.

A killed parent (SIGKILL, an out-of-memory kill, a closed terminal) leaves its pool workers
writing results to, or reading tasks from, a pipe nobody holds: each would print a
BrokenPipeError or EOFError traceback. ``quiet_worker`` (a pool initializer's first call) makes
such a worker end silently instead: writing to the broken pipe ends it (SIGPIPE's default
action), and on Linux it is told to end when the process that started it ends. That is the
parent only for "spawn" (or "fork") workers: a forkserver's workers, and the fork server itself,
outlived a killed parent (``tests/test_batch.py``), so the batch pool spawns its workers.
"""

from __future__ import annotations

import ctypes
import signal
import sys

#: prctl option of Linux: the signal a process receives when its parent ends.
_PR_SET_PDEATHSIG = 1


def quiet_worker() -> None:
    """Make this worker process end silently when its parent is gone (module doc)."""
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        except (OSError, AttributeError):  # no prctl: the SIGPIPE default still applies
            pass
