"""Progress of a run, reported to an optional observer (a plain callable; no global state).

``run_pipeline(..., progress=observer)`` calls ``observer(ProgressEvent(...))`` as the run
advances; the Python API reports nothing unless given one, and the ``ipr`` command draws the
events as progress bars on stderr when it is a terminal. Events arrive in the calling process
(the sampling workers' results are counted as the parent receives them), in stage order:

- ``compiling``: the numba kernels are about to be compiled (a cold cache, once after install
  or after their source changed: about 30 s); ``done`` 0, ``total`` None.
- ``perception``: frames segmented (``done`` of ``total``), reported as each frame is done;
  tracking and facets follow the last frame.
- ``free_space``: frames whose free-space voxel map is made (``done`` of ``total``; none when
  no object was found).
- ``fusion``: later views registered into frame 0 (0 of 1, then 1 of 1).
- ``hypotheses``: objects whose hypotheses are generated (``done`` of ``total``).
- ``sampling``: joint models simulated (``done``; ``total`` when the count is fixed, else None)
  and ``seconds_left`` until the deadline (None without one).
- ``carving``: written shapes carved (0 of 1, then 1 of 1).

An observer must be cheap and must not raise; it is called from the thread running the stage.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class ProgressEvent:
    """How far one stage of a run has got.

    Attributes:
        stage: the stage's name (module doc).
        done: units done (frames, objects, samples).
        total: units in all (None: not known in advance).
        seconds_left: wall-clock seconds until the stage must stop (None: no deadline).
    """

    stage: str
    done: int
    total: int | None = None
    seconds_left: float | None = None


#: What ``run_pipeline`` and the stages accept as ``progress``.
ProgressCallback = Callable[[ProgressEvent], None]


def report(progress: ProgressCallback | None, stage: str, done: int, total: int | None = None,
           seconds_left: float | None = None) -> None:  # fmt: skip
    """Call ``progress`` with one event, when there is an observer."""
    if progress is not None:
        progress(ProgressEvent(stage, int(done), total, seconds_left))
