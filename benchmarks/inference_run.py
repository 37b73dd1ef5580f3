"""Inference benchmark, step 1 of 3: run the methods on the scenes and keep every run on disk.

Each (suite, scene, method, settings, code version) is run once, end to end (``ipr_shapes.pipeline.infer``:
perception, hypotheses, inference), in a child process of its own (``isolated``: BLAS limited to
one thread there; the physics-based methods add their sampling workers), and kept in the run
cache (``runs_dir()``: ``<ipr cache>/runs/inference``, beside the generated suites of
``ipr_shapes.suites``)::

    <suite>/<scene>/<method>-<key>/run.json    what was run, with what, how long it took
    <suite>/<scene>/<method>-<key>/result/     the ipr result directory (``ipr-shapes infer``'s output)

``key`` hashes the scene's path, the method, seed, sample count, workers, the inference budget,
the whole configuration and ``code_key()`` (the ipr package's source files and this module's), so
rescoring and rerendering (``benchmarks.inference_score``, ``benchmarks.inference_render``) reuse
the runs, and any change to the code makes new ones. A run that raised is kept too (its
``run.json`` has the error and no result); a run killed after its time limit, or whose process
died, is not kept and is tried again next time. Runs are written under a ``.part`` name and
renamed when complete, so an interrupted run is never reused (``python -m benchmarks.inference
--prune`` removes the leftovers of killed runs with the runs of other code versions).

The sampler against exhaustive search (``compare_scene``) is kept the same way as
``sampler-vs-exhaustive-<key>/run.json``, holding both methods' posteriors and timings.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import shutil
import time
import traceback
from datetime import UTC, datetime
from pathlib import Path

#: Every benchmark run uses this seed.
SEED = 0
#: A scene's run is killed (and scored 0) after this long: a guard against hangs, far above
#: the default budget's ~15 s per scene.
SCENE_TIMEOUT_S = 900.0
#: The same for one scene of the sampler/exhaustive comparison (up to 6^4 joint models).
COMPARISON_TIMEOUT_S = 3600.0
#: Sampler vs exhaustive: hypotheses per object, the sampler's share of exhaustive's sampling
#: time, and the method the sampler runs (exhaustive's likelihood/prior).
COMPARISON_HYPOTHESES = 6
COMPARISON_COMPUTE_SHARE = 0.18
COMPARISON_SAMPLER = "ipr+action+uniform"
#: Name of a run's record file and of its result folder inside the run directory.
RECORD = "run.json"
RESULT = "result"


# --------------------------------------------------------------------------------------------
# Settings


def with_budget(config, budget_per_object_s: float):
    """``config`` (default ``Config()``) with the default inference budget per object."""
    from ipr_shapes.config import Config

    config = config or Config()
    inference = dataclasses.replace(config.inference, budget_per_object_s=budget_per_object_s)
    return dataclasses.replace(config, inference=inference)


def with_hypotheses(config, count: int):
    """``config`` (default ``Config()``) with ``count`` shape hypotheses per object."""
    from ipr_shapes.config import Config

    config = config or Config()
    return dataclasses.replace(
        config, hypotheses=dataclasses.replace(config.hypotheses, count=count)
    )


def error_text(error: BaseException) -> str:
    """An exception as one short line that fits in a markdown table cell."""
    text = f"{type(error).__name__}: {error}".replace("\n", " ").replace("|", "/")
    text = text.replace("`", "'")
    return text if len(text) <= 160 else text[:157] + "..."


# --------------------------------------------------------------------------------------------
# The run cache


def runs_dir() -> Path:
    """Root of the run cache: ``$IPR_BENCH_RUNS``, else ``<ipr cache>/runs/inference``
    (``ipr_shapes.data.cache_dir()``: ``$IPR_CACHE`` or ``~/.cache/ipr``, outside the repository)."""
    from ipr_shapes.data import cache_dir

    override = os.environ.get("IPR_BENCH_RUNS")
    return Path(override) if override else cache_dir() / "runs" / "inference"


_CODE_KEY: str | None = None


def code_key() -> str:
    """Short hash of the code a run depends on: every ``.py`` file of the ipr package (by path
    relative to it) and this module. Computed once per process."""
    global _CODE_KEY
    if _CODE_KEY is None:
        import ipr_shapes

        package = Path(ipr_shapes.__file__).resolve().parent
        digest = hashlib.sha256()
        for source in sorted(package.rglob("*.py")):
            digest.update(source.relative_to(package).as_posix().encode())
            digest.update(source.read_bytes())
        digest.update(Path(__file__).read_bytes())
        _CODE_KEY = digest.hexdigest()[:12]
    return _CODE_KEY


def run_key(settings: dict) -> str:
    """Short hash of a run's settings (``run_settings``; the code key among them)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def run_settings(
    scene: Path,
    method: str,
    *,
    config=None,
    budget: float | None = None,
    workers: int | None = None,
    samples: int | None = None,
    seed: int = SEED,
) -> dict:
    """What decides a run's outcome, as stored in its record and hashed into its key: the
    scene's resolved path, the method, seed, samples, workers, the budget per object (None: the
    default configuration's), the whole configuration's repr and ``code_key()``."""
    from ipr_shapes.config import Config

    return {
        "scene": str(Path(scene).resolve()),
        "method": method,
        "seed": seed,
        "samples": samples,
        "workers": workers,
        "budget_per_object_s": budget,
        "config": repr(config or Config()),
        "code": code_key(),
    }


def run_directory(suite: str, scene: Path, name: str, settings: dict) -> Path:
    """Where the run of ``settings`` is kept: ``runs_dir()/suite/scene/name-key``."""
    return runs_dir() / (suite or "-") / Path(scene).name / f"{name}-{run_key(settings)}"


def read_record(directory: Path) -> dict | None:
    """The record of a complete run in ``directory`` (None when there is none)."""
    path = Path(directory) / RECORD
    if not path.is_file():
        return None
    record = json.loads(path.read_text(encoding="utf-8"))
    record["directory"] = str(directory)
    return record


def _write_record(directory: Path, record: dict) -> None:
    staging = directory / (RECORD + ".tmp")
    staging.write_text(json.dumps(record, indent=1, default=str) + "\n", encoding="utf-8")
    staging.replace(directory / RECORD)


def _fresh(directory: Path) -> Path:
    """An empty staging folder beside ``directory``, of this process alone (another process
    may be running the same run)."""
    partial = directory.with_name(f"{directory.name}.part-{os.getpid()}")
    if partial.exists():  # a leftover of this process id's earlier, killed run
        shutil.rmtree(partial)
    partial.mkdir(parents=True)
    return partial


def _publish(partial: Path, directory: Path) -> None:
    """Move a complete run into place, unless another process finished the same run first."""
    try:
        partial.rename(directory)
    except OSError:
        if not (directory / RECORD).is_file():
            raise
        shutil.rmtree(partial)


def stale_runs(root: Path | None = None) -> list[Path]:
    """The kept runs (and leftovers of killed ones) under ``root`` (default ``runs_dir()``)
    made by other code than this checkout's (``code_key()``). Other checkouts on the machine
    share the cache, so nothing removes them unasked (``python -m benchmarks.inference
    --prune``)."""
    root = Path(root or runs_dir())
    if not root.is_dir():
        return []
    stale = []
    for directory in sorted(root.glob("*/*/*")):
        if ".part-" in directory.name:
            stale.append(directory)
            continue
        record = read_record(directory)
        if record is None or record.get("code") != code_key():
            stale.append(directory)
    return stale


# --------------------------------------------------------------------------------------------
# Child processes


class SceneTimeout(Exception):
    """A scene's run exceeded its time limit (its process group was killed)."""


def _child(connection, function, args: tuple, kwargs: dict, timeout_s: float) -> None:
    import faulthandler
    import sys

    from threadpoolctl import threadpool_limits

    os.setpgrp()  # its own process group: a timeout kills it with its pool workers
    # Just before the parent gives up, print every thread's stack to stderr (diagnosis).
    faulthandler.dump_traceback_later(max(timeout_s - 5.0, 1.0), exit=False, file=sys.stderr)
    try:
        with threadpool_limits(limits=1):
            outcome = ("ok", function(*args, **kwargs))
    except BaseException as error:  # noqa: BLE001 - reported to the parent
        traceback.print_exc()
        outcome = ("error", error_text(error))
    faulthandler.cancel_dump_traceback_later()
    connection.send(outcome)
    connection.close()


def isolated(function, *args, timeout_s: float, **kwargs):
    """``function(*args, **kwargs)`` in a child process (fork server, BLAS limited to one
    thread), returning its result. A child that raises gives RuntimeError, one that dies
    RuntimeError with its exit code, and one still running after ``timeout_s`` (e.g. a
    deadlocked worker pool) is killed with its process group: SceneTimeout. The arguments
    and result must pickle."""
    import multiprocessing
    import signal

    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["ipr_shapes", "ipr_shapes.pipeline", __name__])
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(
        target=_child, args=(sender, function, args, kwargs, timeout_s), daemon=False
    )
    process.start()
    sender.close()
    outcome = None
    try:
        ready = receiver.poll(timeout_s)
        outcome = receiver.recv() if ready else None
    except EOFError:  # the child died without answering
        outcome = ("error", None)
    finally:
        if process.is_alive() and outcome is None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(process.pid, signal.SIGKILL)
        process.join(30)
        if process.is_alive():
            process.kill()
            process.join()
        receiver.close()
    if outcome is None:
        raise SceneTimeout(f"no answer after {timeout_s:.0f} s; killed")
    status, value = outcome
    if status == "error":
        if value is None:
            raise RuntimeError(f"the process died (exit code {process.exitcode})")
        raise RuntimeError(value)
    return value


# --------------------------------------------------------------------------------------------
# One method on one scene


def infer_scene(partial: Path, settings: dict, config=None) -> None:
    """Infer ``settings["scene"]`` with its method into ``partial/result`` (``ipr-shapes infer``'s
    output) and write ``partial/run.json``: the settings, the wall time of the ``infer`` call,
    and the error when it raised (then there is no result)."""
    from ipr_shapes.pipeline import infer

    record = {**settings, "error": None, "wall_s": None, "created": None}
    try:
        started = time.perf_counter()
        infer(
            settings["scene"],
            partial / RESULT,
            method=settings["method"],
            seed=settings["seed"],
            workers=settings["workers"],
            samples=settings["samples"],
            config=config,
        )
        record["wall_s"] = time.perf_counter() - started
    except Exception as error:  # noqa: BLE001 - a failing scene is a result, not a crash
        name = Path(settings["scene"]).name
        print(
            f"bench: inference {name} {settings['method']} failed: {error_text(error)}", flush=True
        )
        traceback.print_exc()
        record["error"] = error_text(error)
    record["created"] = datetime.now(UTC).isoformat(timespec="seconds")
    _write_record(partial, record)


def run_scene(
    suite: str,
    scene: Path,
    method: str,
    *,
    budget: float | None = None,
    workers: int | None = None,
    samples: int | None = None,
) -> dict:
    """The record (``read_record``) of ``method`` on ``scene`` at ``budget`` seconds of
    inference per object (None: the default configuration), from the cache or run now in a
    child process (``isolated``, killed after ``SCENE_TIMEOUT_S``). The record's ``cached`` says
    which. A run that timed out or whose process died gives a record with the error that is
    not kept (``directory`` None)."""
    config = None if budget is None else with_budget(None, budget)
    settings = run_settings(
        scene, method, config=config, budget=budget, workers=workers, samples=samples
    )
    directory = run_directory(suite, scene, method, settings)
    record = read_record(directory)
    if record is not None:
        return {**record, "cached": True}
    partial = _fresh(directory)
    try:
        isolated(infer_scene, partial, settings, config, timeout_s=SCENE_TIMEOUT_S)
    except Exception as error:  # noqa: BLE001 - timeouts and crashes score 0, not kept
        shutil.rmtree(partial, ignore_errors=True)
        return {**settings, "error": error_text(error), "wall_s": None, "directory": None,
                "cached": False}  # fmt: skip
    _publish(partial, directory)
    return {**read_record(directory), "cached": False}


# --------------------------------------------------------------------------------------------
# Sampler against exhaustive search on one scene


def _posteriors(result) -> dict:
    """A pipeline result's per-object probabilities, timings and summary (JSON-ready)."""
    return {
        "posteriors": [
            {"object_id": int(p.object_id), "probabilities": [float(x) for x in p.probabilities]}
            for p in result.posteriors
        ],
        "timing_s": {k: float(v) for k, v in result.timing_s.items()},
        "samples": result.summary.sampling.samples if result.summary.sampling else None,
        "fallback": result.summary.sampling.fallback if result.summary.sampling else None,
    }


def compare_scene(scene_path: Path, *, hypotheses: int = COMPARISON_HYPOTHESES) -> dict:
    """Exhaustive search, then the sampler with ``COMPARISON_COMPUTE_SHARE`` of its sampling
    time, both on one worker with ``hypotheses`` per object and seed 0 (same hypotheses).

    Returns {"scene", "status": "ok"|"skipped"|"failed", "reason", "exhaustive", "sampler"},
    the last two each {"posteriors": [{"object_id", "probabilities"}], "timing_s", "samples",
    "fallback"} when run; "skipped" when exhaustive refuses the scene (too many objects or
    joint models), has no object or fell back.
    """
    from ipr_shapes.errors import IprError
    from ipr_shapes.pipeline import run_pipeline
    from ipr_shapes.scene import load_scene

    row = {"scene": Path(scene_path).name, "status": "failed", "reason": None}
    base = with_hypotheses(None, hypotheses)
    try:
        scene = load_scene(scene_path)
        # No deadline for exhaustive: a sample limit disables the default budget, and every
        # joint model is one task (the limit only has to exceed their number).
        exhaustive = run_pipeline(
            scene,
            base,
            method="exhaustive",
            seed=SEED,
            workers=1,
            samples=max(base.inference.max_exhaustive_models, 1),
        )
    except IprError as error:
        return {**row, "status": "skipped", "reason": error_text(error)}
    except Exception as error:  # noqa: BLE001
        traceback.print_exc()
        return {**row, "reason": error_text(error)}
    row["exhaustive"] = _posteriors(exhaustive)
    objects = len(exhaustive.posteriors)
    exhaustive_s = exhaustive.timing_s.get("inference_sampling", math.nan)
    if objects == 0 or not exhaustive_s > 0:
        return {**row, "status": "skipped", "reason": "no object to infer"}
    fallback = exhaustive.summary.sampling.fallback if exhaustive.summary.sampling else None
    if fallback:
        return {**row, "status": "skipped", "reason": f"exhaustive: {fallback}"}
    budget = COMPARISON_COMPUTE_SHARE * exhaustive_s / objects
    try:
        sampler = run_pipeline(
            scene, with_budget(base, budget), method=COMPARISON_SAMPLER, seed=SEED, workers=1
        )
    except Exception as error:  # noqa: BLE001
        traceback.print_exc()
        return {**row, "reason": f"sampler: {error_text(error)}"}
    return {**row, "status": "ok", "sampler": _posteriors(sampler)}


def _compare_into(partial: Path, settings: dict, hypotheses: int) -> None:
    record = {
        **settings,
        "scene_path": settings["scene"],
        **compare_scene(Path(settings["scene"]), hypotheses=hypotheses),
    }
    record["created"] = datetime.now(UTC).isoformat(timespec="seconds")
    _write_record(partial, record)


def run_comparison(suite: str, scene: Path, *, hypotheses: int = COMPARISON_HYPOTHESES) -> dict:
    """The record of ``compare_scene`` on ``scene``, from the cache or run now in a child
    process (killed after ``COMPARISON_TIMEOUT_S``; a timeout or a dead process gives a
    "failed" record that is not kept)."""
    config = with_hypotheses(None, hypotheses)
    settings = {
        **run_settings(scene, "sampler-vs-exhaustive", config=config, workers=1),
        "sampler": COMPARISON_SAMPLER,
        "compute_share": COMPARISON_COMPUTE_SHARE,
    }
    directory = run_directory(suite, scene, "sampler-vs-exhaustive", settings)
    record = read_record(directory)
    if record is not None:
        return {**record, "cached": True}
    partial = _fresh(directory)
    try:
        isolated(_compare_into, partial, settings, hypotheses, timeout_s=COMPARISON_TIMEOUT_S)
    except Exception as error:  # noqa: BLE001 - timeouts and crashes are listed, not kept
        shutil.rmtree(partial, ignore_errors=True)
        return {**settings, "scene": Path(scene).name, "status": "failed",
                "reason": error_text(error), "directory": None, "cached": False}  # fmt: skip
    _publish(partial, directory)
    return {**read_record(directory), "cached": False}
