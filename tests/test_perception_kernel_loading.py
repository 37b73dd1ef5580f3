"""The perception's time per frame leaves out the process's loading of its compiled kernels.

A process loads every numba kernel once, on its first call (0.15-0.2 s on the first frame with
a warm cache, tens of seconds of compiling with an empty one); ``perceive_scene`` reports that
apart (``timing_s["kernels"]``) instead of as the first frame's cost."""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
from numba.core import event as numba_event

import ipr_shapes.perception as perception
from ipr_shapes.scene import load_scene, write_scene
from tests.conftest import make_frames


def test_a_compile_holds_the_lock_the_listener_times() -> None:
    """numba announces loading and compiling as the ``numba:compiler_lock`` event."""

    @numba.njit(cache=False)
    def fresh(x):  # defined here: compiled on this call
        return x + 1.0

    loading = perception._KernelLoading()
    with numba_event.install_listener("numba:compiler_lock", loading):
        assert fresh(1.0) == 2.0
        compiled = loading.seconds
        fresh(2.0)  # compiled already: no lock
    assert compiled > 0 and loading.seconds == compiled


def test_per_frame_time_leaves_out_kernel_loading(tmp_path: Path, monkeypatch) -> None:
    clock = {"now": 0.0}
    monkeypatch.setattr(
        perception, "time", type("Clock", (), {"perf_counter": lambda: clock["now"]})
    )

    def load_kernels(seconds: float) -> None:
        # A kernel compiling the kernels it calls: the re-entrant lock counts once.
        numba_event.start_event("numba:compiler_lock")
        numba_event.start_event("numba:compiler_lock")
        clock["now"] += seconds
        numba_event.end_event("numba:compiler_lock")
        numba_event.end_event("numba:compiler_lock")

    def with_cost(function, work: float, loading: float):
        def timed(*args, **kwargs):
            load_kernels(loading)
            clock["now"] += work
            return function(*args, **kwargs)

        return timed

    monkeypatch.setattr(perception, "segment_frame", with_cost(perception.segment_frame, 0.25, 5.0))
    monkeypatch.setattr(perception, "track_scene", with_cost(perception.track_scene, 0.125, 2.0))
    monkeypatch.setattr(
        perception, "partial_objects", with_cost(perception.partial_objects, 0.0625, 1.0)
    )
    write_scene(tmp_path / "scene", make_frames(2))
    scene = load_scene(tmp_path / "scene")
    result = perception.perceive_scene(scene, with_free_space=False)
    timing = result.timing_s
    assert timing["kernels"] == 5.0 + 5.0 + 2.0 + 1.0 + 1.0
    assert timing["segmentation"] == 0.5 and timing["tracking"] == 0.125
    assert timing["facets"] == 0.125
    np.testing.assert_allclose(timing["per_frame"], [0.25 + 0.0625 + 0.0625] * 2)
