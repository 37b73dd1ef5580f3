"""Running samples in threads of this process that share one sampler, until a deadline."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterable

from ipr_shapes.inference.problem import InferenceProblem, SampleResult
from ipr_shapes.inference.sampler import Sampler, _Deadline


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def run_samples(
    problem: InferenceProblem,
    tasks: Iterable[tuple[int, tuple[int, ...] | None]],
    *,
    workers: int,
    deadline: float,
    on_result: Callable[[int], None] | None = None,
) -> list[SampleResult]:
    """Evaluate ``tasks`` ((index, None) = tree sample ``index``; (index, choice) = score that
    joint model) until they run out or ``deadline`` (``time.perf_counter()``) passes; results
    in task order, unfinished tasks dropped. ``on_result`` is called with the number of
    results so far, each time one arrives (from the thread that produced it, under a lock).

    ``workers`` threads share one ``Sampler`` (its stability cache and simulated models):
    MuJoCo releases the GIL while it steps, so threads run the simulations in parallel
    without a process pool's start-up or each worker repeating the first stage's tests."""
    results: list[SampleResult] = []
    tasks = iter(tasks)
    lock = threading.Lock()
    sampler = Sampler(problem)
    failure: list[BaseException] = []

    def work() -> None:
        prepared = False
        try:
            while not failure:
                with lock:
                    task = next(tasks, None)
                if task is None or time.perf_counter() >= deadline:
                    return
                index, choice = task
                try:
                    if choice is None:
                        if not prepared and workers > 1:
                            # The threads compile the stability-test worlds side by side.
                            sampler.prepare_worlds(deadline)
                            prepared = True
                        result = sampler.sample(index, deadline)
                    else:
                        result = sampler.score(index, choice, deadline)
                except _Deadline:
                    return
                with lock:
                    results.append(result)
                    if on_result is not None:
                        on_result(len(results))
        except BaseException as error:  # noqa: BLE001 - raised again in the caller
            failure.append(error)
        finally:
            sampler.release()

    try:
        if workers <= 1:
            work()
        else:
            threads = [
                threading.Thread(target=work, name=f"ipr-sampler-{number}", daemon=True)
                for number in range(workers)
            ]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
    finally:
        sampler.close()
    if failure:
        raise failure[0]
    return sorted(results, key=lambda r: r.index)
