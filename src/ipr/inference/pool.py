"""Running samples in this process or in a pool of worker processes, until a deadline."""

from __future__ import annotations

import logging
import multiprocessing
import os
import queue
import time
from collections.abc import Callable, Iterable

from ipr.inference.problem import InferenceProblem, SampleResult
from ipr.inference.sampler import Sampler, _Deadline
from ipr.workers import quiet_worker

logger = logging.getLogger(__name__)

_WORKER: Sampler | None = None


#: Seconds to wait past the deadline for samples in flight to stop themselves.
_GRACE_S = 10.0


def _init_worker(problem: InferenceProblem) -> None:
    global _WORKER
    quiet_worker()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _WORKER = Sampler(problem)


def _worker_task(task: tuple[int, tuple[int, ...] | None, float]) -> SampleResult | None:
    index, choice, monotonic_deadline = task
    # time.monotonic is one clock for every process of the machine; perf_counter may not be.
    deadline = time.perf_counter() + (monotonic_deadline - time.monotonic())
    try:
        if choice is None:
            return _WORKER.sample(index, deadline)
        return _WORKER.score(index, choice, deadline)
    except _Deadline:
        return None


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
    in task order, unfinished tasks dropped. ``on_result`` is called in this process with the
    number of results so far, each time one arrives."""
    results: list[SampleResult] = []
    tasks = iter(tasks)

    def received(result: SampleResult) -> None:
        results.append(result)
        if on_result is not None:
            on_result(len(results))

    if workers <= 1:
        sampler = Sampler(problem)
        try:
            for index, choice in tasks:
                if time.perf_counter() >= deadline:
                    break
                try:
                    if choice is None:
                        received(sampler.sample(index, deadline))
                    else:
                        received(sampler.score(index, choice, deadline))
                except _Deadline:
                    break
        finally:
            sampler.close()
        return sorted(results, key=lambda r: r.index)

    if time.perf_counter() >= deadline:
        return results
    # A fork server starts workers from a clean process (no GL context inherited).
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["ipr.inference.pool"])
    finished: queue.Queue = queue.Queue()
    monotonic_deadline = time.monotonic() + min(deadline - time.perf_counter(), 1e9)
    pool = context.Pool(workers, initializer=_init_worker, initargs=(problem,))
    in_flight = 0
    clean = False
    try:
        exhausted = False
        while True:
            while not exhausted and in_flight < 2 * workers:
                task = next(tasks, None)
                if task is None or time.perf_counter() >= deadline:
                    exhausted = True
                    break
                pool.apply_async(
                    _worker_task,
                    ((task[0], task[1], monotonic_deadline),),
                    callback=finished.put,
                    error_callback=finished.put,
                )
                in_flight += 1
            if in_flight == 0:
                break
            # Past the deadline, wait for the tasks in flight: each stops itself at the
            # deadline (between stability tests and pushes), so this takes a fraction of a
            # second; terminating workers instead can hang CPython's pool (a killed worker may
            # hold the task queue's lock).
            wait = deadline - time.perf_counter()
            if wait <= 0:
                exhausted = True
                wait = _GRACE_S
            try:
                outcome = finished.get(timeout=min(max(wait, 0.0), 3600.0) + 0.05)
            except queue.Empty:
                if exhausted:
                    break  # stragglers past the grace period: terminated below
                continue
            in_flight -= 1
            if isinstance(outcome, BaseException):
                raise outcome
            if outcome is not None:
                received(outcome)
        clean = in_flight == 0
    finally:
        if clean:
            pool.close()
        else:
            logger.warning("sampling workers did not stop in time; terminating them")
            pool.terminate()
        pool.join()
    return sorted(results, key=lambda r: r.index)
