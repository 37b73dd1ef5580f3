"""Inference benchmarks: accuracy and speed of ``ipr infer`` per method on every suite.

Each scene is run end to end (``ipr.pipeline.infer``: perception, hypotheses, inference) in a
child process of its own (``isolated``: BLAS limited to one thread there; the physics-based
methods add their sampling workers), then scored with ``ipr.metrics.evaluate``. Accuracy is
averaged over scenes (the paper's convention, per-object averages within a scene), with medians
beside; time per object divides a scene's seconds by its number of inferred objects. A scene
whose inference (or evaluation) raises, crashes its process or hangs past ``SCENE_TIMEOUT_S`` is
listed and scores 0.

Sections (``run``): the Collision Checker on every suite; the physics-based methods (Song &
Boularias 2018, inverse physics reasoning) on ``ycb-dynamic`` at the default budget, and
``ipr+size`` on the static suites; the tree sampler against exhaustive search of the joint
models on small scenes; object IoU against the inference budget (table and
``docs/images/iou_vs_budget.png``). Runs of the same (suite, method, budget) are shared between
tables. Progress goes to stdout as ``bench: inference SUITE METHOD i/n``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import tempfile
import time
import traceback
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchmarks.common import markdown_table, median

#: The paper's Collision Checker (Tables II and III): object space and scene space IoU/F1/P/R.
PAPER_COLLISION_CHECKER = {
    "ycb-static": {"object": (0.471, 0.653, 0.834, 0.537), "scene": (0.485, 0.654, 0.887, 0.518)},
    "ycb-dynamic": {"object": (0.478, 0.655, 0.844, 0.535), "scene": (0.499, 0.667, 0.882, 0.536)},
}
#: The paper's object/scene IoU on its dynamic YCB scenes (Table III), by our method names.
PAPER_DYNAMIC_IOU = {
    "collision-checker": (0.478, 0.499),
    "ipr+uniform": (0.618, 0.694),
    "ipr+action+uniform": (0.640, 0.702),
}
#: Methods of the physics table on ycb-dynamic, in reading order.
DYNAMIC_METHODS = (
    "collision-checker",
    "ipr+uniform",
    "ipr+size",
    "ipr+action+uniform",
    "ipr+action+size",
)
#: Methods compared on the suites without pushes.
STATIC_METHODS = ("collision-checker", "ipr+size")
STATIC_SUITES = ("ycb-static", "ycbv-real")
#: Sampler vs exhaustive: hypotheses per object, largest scene, the sampler's share of
#: exhaustive's sampling time, and the method the sampler runs (exhaustive's likelihood/prior).
COMPARISON_HYPOTHESES = 6
COMPARISON_MAX_OBJECTS = 4
COMPARISON_COMPUTE_SHARE = 0.18
COMPARISON_SAMPLER = "ipr+action+uniform"
#: IoU against the budget: inference seconds per object, method and number of scenes.
BUDGETS_S = (0.25, 0.5, 1.0, 2.0, 4.0)
BUDGET_METHOD = "ipr+action+uniform"
BUDGET_SCENES = 8
#: Targets (ycb-dynamic, 2 cores).
TARGET_GAIN_OVER_CHECKER = 0.10
TARGET_OBJECT_IOU = 0.64
TARGET_SCENE_IOU = 0.70
TARGET_WALL_S_PER_OBJECT = 3.0
TARGET_SAME_BEST = 0.90
TARGET_COMPUTE_SHARE = 0.20
#: A scene's run is killed (and scored 0) after this long: a guard against hangs, far above
#: the default budget's ~15 s per scene.
SCENE_TIMEOUT_S = 900.0
#: The same for one scene of the sampler/exhaustive comparison (up to 6^4 joint models).
COMPARISON_TIMEOUT_S = 3600.0
DOCS = Path(__file__).resolve().parents[1] / "docs"
BUDGET_IMAGE = DOCS / "images" / "iou_vs_budget.png"

#: Per-scene figures that are 0 when the scene failed.
SCORE_KEYS = tuple(
    f"{space}_{figure}"
    for space in ("object", "scene")
    for figure in ("iou", "f1", "precision", "recall")
)


# --------------------------------------------------------------------------------------------
# Running and scoring


def with_budget(config, budget_per_object_s: float):
    """``config`` (default ``Config()``) with the default inference budget per object."""
    from ipr.config import Config

    config = config or Config()
    inference = dataclasses.replace(config.inference, budget_per_object_s=budget_per_object_s)
    return dataclasses.replace(config, inference=inference)


def with_hypotheses(config, count: int):
    """``config`` (default ``Config()``) with ``count`` shape hypotheses per object."""
    from ipr.config import Config

    config = config or Config()
    checker = config.collision_checker
    hypotheses = dataclasses.replace(checker.hypotheses, count=count)
    return dataclasses.replace(
        config, collision_checker=dataclasses.replace(checker, hypotheses=hypotheses)
    )


def _error_text(error: BaseException) -> str:
    text = f"{type(error).__name__}: {error}".replace("\n", " ").replace("|", "/")
    text = text.replace("`", "'")
    return text if len(text) <= 160 else text[:157] + "..."


def failed_row(scene: Path, method: str, error: BaseException) -> dict:
    """The row of a scene whose inference or evaluation raised: every score 0, no timings."""
    return {
        "scene": scene.name,
        "method": method,
        "error": _error_text(error),
        **dict.fromkeys(SCORE_KEYS, 0.0),
        "objects": 0,
        "hypotheses_s_per_object": math.nan,
        "method_s_per_object": math.nan,
        "inference_s_per_object": math.nan,
        "total_s_per_object": math.nan,
        "samples": None,
        "fallback": None,
        "volume_spreads": [],
        "best_hypothesis_iou": 0.0,
    }


class SceneTimeout(Exception):
    """A scene's run exceeded its time limit (its process group was killed)."""


def _child(connection, function, args: tuple, kwargs: dict, timeout_s: float) -> None:
    import faulthandler
    import os
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
        outcome = ("error", _error_text(error))
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
    import os
    import signal

    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["ipr", "ipr.pipeline", "ipr.metrics", __name__])
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


def best_hypothesis_iou(scene: Path, result, evaluation) -> float:
    """The ceiling of choosing among the result's written hypotheses: over the visible
    ground-truth objects of ``evaluation``, the mean of the best object IoU any hypothesis of
    the matched prediction reaches (0 when unmatched; the best mesh when an object lists no
    hypotheses), at the evaluation's voxel pitch. For the Collision Checker the written
    hypotheses are every jointly feasible candidate, so this bounds what any inference could
    pick from them; for the physics-based methods, the candidates their samples visited."""
    from ipr import voxels
    from ipr.metrics import frame0_ground_truth
    from ipr.result import read_mesh

    poses, models, _ = frame0_ground_truth(scene)
    world_from_camera = result.world_from_camera[0]
    pitch = evaluation.voxel_size_m
    by_id = {obj.id: obj for obj in result.objects}
    values = []
    for row in evaluation.ground_truth:
        if not row.visible:
            continue
        if row.matched_id is None:
            values.append(0.0)
            continue
        truth = voxels.occupied_voxels(
            models[row.gt_index], pitch, world_from_camera @ poses[row.gt_index].camera_from_model
        )
        obj = by_id[row.matched_id]
        best = 0.0
        for path in [h.mesh_path for h in obj.hypotheses] or [obj.mesh_path]:
            keys = voxels.scanline_voxels(*voxels.closed_or_hull(read_mesh(path))[:2], pitch)
            common = voxels.intersection_count(keys, truth)
            union = keys.size + truth.size - common
            best = max(best, common / union if union else 0.0)
        values.append(best)
    return float(np.mean(values)) if values else math.nan


def score_scene(
    scene: Path,
    method: str,
    out: Path,
    *,
    config=None,
    workers: int | None = None,
    samples: int | None = None,
) -> dict:
    """Infer ``scene`` with ``method`` into ``out`` (end to end, seed 0), score it, and return
    one row of figures; an exception gives ``failed_row`` (scores 0, the error kept)."""
    from ipr.metrics import evaluate
    from ipr.pipeline import infer
    from ipr.result import load_result

    try:
        started = time.perf_counter()
        infer(scene, out, method=method, seed=0, workers=workers, samples=samples, config=config)
        wall = time.perf_counter() - started
        result = load_result(out, load_meshes=False)
        evaluation = evaluate(scene, out)
    except Exception as error:  # noqa: BLE001 - a failing scene is a result, not a crash
        print(f"bench: inference {scene.name} {method} failed: {_error_text(error)}", flush=True)
        traceback.print_exc()
        return failed_row(scene, method, error)
    timing = result.timing_s
    details = result.extra.get("inference") or {}
    spreads = [o["volumes_m3"]["ratio"] for o in result.extra.get("objects_summary", [])]
    objects = max(len(evaluation.predictions), 1)
    return {
        "scene": scene.name,
        "method": method,
        "error": None,
        "object_iou": evaluation.object_space.iou,
        "object_f1": evaluation.object_space.f1,
        "object_precision": evaluation.object_space.precision,
        "object_recall": evaluation.object_space.recall,
        "scene_iou": evaluation.scene_space.iou,
        "scene_f1": evaluation.scene_space.f1,
        "scene_precision": evaluation.scene_space.precision,
        "scene_recall": evaluation.scene_space.recall,
        "objects": len(evaluation.predictions),
        "hypotheses_s_per_object": timing.get("hypotheses", math.nan) / objects,
        "method_s_per_object": (timing.get("hypotheses", 0) + timing.get("inference", 0)) / objects,
        "inference_s_per_object": timing.get("inference", math.nan) / objects,
        "total_s_per_object": wall / objects,
        "samples": details.get("samples"),
        "fallback": details.get("fallback"),
        "volume_spreads": spreads,
        "best_hypothesis_iou": best_hypothesis_iou(scene, result, evaluation),
    }


def run_method(
    scenes: Sequence[Path],
    method: str,
    *,
    config=None,
    workers: int | None = None,
    samples: int | None = None,
    label: str = "",
) -> list[dict]:
    """Infer and evaluate every scene (``score_scene``), each in its own child process
    (``isolated``: one BLAS thread, killed after ``SCENE_TIMEOUT_S``) writing to a temporary
    folder; one row of figures per scene, failures and timeouts included as zero rows."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for number, scene in enumerate(scenes, 1):
            scene = Path(scene)
            started = time.perf_counter()
            try:
                row = isolated(
                    score_scene,
                    scene,
                    method,
                    Path(folder) / f"{number:03d}-{scene.name}",
                    config=config,
                    workers=workers,
                    samples=samples,
                    timeout_s=SCENE_TIMEOUT_S,
                )
            except Exception as error:  # noqa: BLE001 - timeouts and crashes score 0
                row = failed_row(scene, method, error)
            rows.append(row)
            status = (
                f"FAILED {row['error']}" if row["error"] else f"object IoU {row['object_iou']:.3f}"
            )
            print(
                f"bench: inference {label or '-'} {method} {number}/{len(scenes)} "
                f"{scene.name} {time.perf_counter() - started:.1f} s {status}",
                flush=True,
            )
    return rows


class Runs:
    """Rows per (suite, method, budget per object), each computed once and shared by tables.

    ``budget`` None is the default configuration (``Config().inference.budget_per_object_s``)."""

    def __init__(self, suites: dict[str, list[Path]]) -> None:
        from ipr.config import Config

        self.suites = suites
        self.default_budget = Config().inference.budget_per_object_s
        self._rows: dict[tuple[str, str, float | None, int | None], list[dict]] = {}

    def rows(
        self, suite: str, method: str, budget: float | None = None, limit: int | None = None
    ) -> list[dict]:
        """Rows of the first ``limit`` scenes (all: None) of ``suite``; the Collision Checker
        ignores the budget; the default budget reuses the default runs."""
        scenes = list(self.suites.get(suite, []))
        limit = None if limit is None or limit >= len(scenes) else limit
        if method == "collision-checker" or budget == self.default_budget:
            budget = None
        for (s, m, b, n), rows in self._rows.items():  # a longer run of the same settings
            if (s, m, b) == (suite, method, budget) and (n is None or (limit and n >= limit)):
                return rows[:limit] if limit else rows
        label = suite if budget is None else f"{suite} budget {budget:g} s/object"
        config = None if budget is None else with_budget(None, budget)
        rows = run_method(scenes[:limit] if limit else scenes, method, config=config, label=label)
        self._rows[(suite, method, budget, limit)] = rows
        return rows


# --------------------------------------------------------------------------------------------
# Tables


def _mean_median(rows: Sequence[dict], key: str) -> str:
    values = [row[key] for row in rows]
    if not values:
        return "-"
    return f"{np.mean(values):.3f} ({median(values):.3f})"


def _mean(rows: Sequence[dict], key: str) -> float:
    return float(np.mean([row[key] for row in rows])) if rows else math.nan


def _finite_median(values) -> float:
    values = [v for v in values if v is not None and math.isfinite(v)]
    return median(values)


def _seconds(value: float) -> str:
    return f"{value:.2f}" if math.isfinite(value) else "-"


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}{'' if number == 1 else 's'}"


def _met(condition: bool) -> str:
    return "yes" if condition else "**no**"


def failures(rows_by_label: dict[str, list[dict]]) -> list[str]:
    """Markdown bullets naming every failed scene (empty when none failed)."""
    return [
        f"- failed ({label}): {row['scene']}: `{row['error']}` (scored 0)"
        for label, rows in rows_by_label.items()
        for row in rows
        if row["error"]
    ]


def method_table(rows_by_method: dict[str, list[dict]], suite: str) -> str:
    """Accuracy and speed per method: object/scene IoU mean (median), seconds per object,
    samples per scene, failures, and the paper's figures where it has them."""
    table = []
    for method, rows in rows_by_method.items():
        ok = [r for r in rows if not r["error"]]
        samples = [r["samples"] for r in ok if r["samples"] is not None]
        fallbacks = sum(1 for r in ok if r["fallback"])
        paper = PAPER_DYNAMIC_IOU.get(method) if suite == "ycb-dynamic" else None
        table.append(
            [
                method,
                len(rows),
                _mean_median(rows, "object_iou"),
                _mean_median(rows, "scene_iou"),
                f"{_mean(rows, 'best_hypothesis_iou'):.3f}",
                _seconds(_finite_median(r["total_s_per_object"] for r in ok)),
                _seconds(_finite_median(r["inference_s_per_object"] for r in ok)),
                f"{median(samples):.0f}" if samples else "-",
                fallbacks if samples else "-",
                len(rows) - len(ok),
                f"{paper[0]:.3f} / {paper[1]:.3f}" if paper else "-",
            ]
        )
    return markdown_table(
        [
            "method",
            "scenes",
            "object IoU",
            "scene IoU",
            "best hypothesis IoU",
            "wall s/object",
            "inference s/object",
            "samples/scene",
            "fallbacks",
            "failed",
            "paper object / scene IoU",
        ],
        table,
    )


def dynamic_section(runs: Runs) -> str:
    """The physics-based methods on ycb-dynamic at the default budget, with targets."""
    rows = {method: runs.rows("ycb-dynamic", method) for method in DYNAMIC_METHODS}
    checker = _mean(rows["collision-checker"], "object_iou")
    gravity = _mean(rows["ipr+uniform"], "object_iou")
    action = _mean(rows["ipr+action+uniform"], "object_iou")
    action_scene = _mean(rows["ipr+action+uniform"], "scene_iou")
    walls = {
        method: _finite_median(r["total_s_per_object"] for r in rows[method] if not r["error"])
        for method in DYNAMIC_METHODS
        if method != "collision-checker"
    }
    slowest = max(walls, key=lambda m: walls[m] if math.isfinite(walls[m]) else math.inf)
    targets = [
        ["ipr+action+uniform >= ipr+uniform (object IoU)", f"{action:.3f} vs {gravity:.3f}"],
        [
            f"ipr+uniform >= collision-checker + {TARGET_GAIN_OVER_CHECKER:.2f} (object IoU)",
            f"{gravity:.3f} vs {checker + TARGET_GAIN_OVER_CHECKER:.3f}",
        ],
        [f"ipr+action+uniform object IoU >= {TARGET_OBJECT_IOU:.2f}", f"{action:.3f}"],
        [f"ipr+action+uniform scene IoU >= {TARGET_SCENE_IOU:.2f}", f"{action_scene:.3f}"],
        [
            f"wall time <= {TARGET_WALL_S_PER_OBJECT:g} s/object (slowest method, median)",
            f"{walls[slowest]:.2f} ({slowest})",
        ],
    ]
    met = [
        action >= gravity,
        gravity >= checker + TARGET_GAIN_OVER_CHECKER,
        action >= TARGET_OBJECT_IOU,
        action_scene >= TARGET_SCENE_IOU,
        math.isfinite(walls[slowest]) and walls[slowest] <= TARGET_WALL_S_PER_OBJECT,
    ]
    lines = [
        "## Physics-based inference on ycb-dynamic (`ipr infer --method ...`)",
        "",
        "Inverse physics reasoning (Song & Boularias 2018): tree sampling of joint shape models "
        "scored by simulating them (gravity only: `ipr+`, or gravity and the recorded pushes: "
        "`ipr+action+`) and rendering depth; `uniform` or `size` prior. Default budget "
        f"({runs.default_budget:g} s of inference per object after perception and hypotheses), "
        "all cores, seed 0, 32 hypotheses per object. IoU: mean over scenes (median in "
        "brackets), 5 mm voxels, objects visible in frame 0. `wall s/object`: the whole "
        "`ipr infer` time divided by the objects (median over scenes); `inference s/object` "
        "the inference stage alone; `samples/scene`: joint models evaluated (median); "
        "`fallbacks`: scenes answered by the Collision Checker because no sample finished or "
        "every one was impossible. `best hypothesis IoU`: the object IoU had each object's "
        "best written hypothesis (against the ground truth) been chosen, mean over scenes; for "
        "the Collision Checker these are all its jointly feasible candidates, so this is the "
        "ceiling of any choice among them (the `+action` methods draw from hypotheses of the "
        "objects fused over the frames). The paper's figures are on its 13 real dynamic YCB "
        "scenes.",
        "",
        method_table(rows, "ycb-dynamic"),
        "",
        markdown_table(
            ["target", "measured", "met"],
            [[*row, _met(ok)] for row, ok in zip(targets, met, strict=True)],
        ),
        "",
    ]
    lines += failures(rows)
    return "\n".join(lines).rstrip() + "\n"


def static_section(runs: Runs) -> str:
    """``ipr+size`` against the Collision Checker on the suites without pushes."""
    lines = [
        "## Physics-based inference without pushes (ycb-static, ycbv-real)",
        "",
        "`ipr+size` (gravity, size prior) against the Collision Checker, same settings and "
        "columns as above.",
        "",
    ]
    failed: dict[str, list[dict]] = {}
    for suite in STATIC_SUITES:
        if not runs.suites.get(suite):
            continue
        rows = {method: runs.rows(suite, method) for method in STATIC_METHODS}
        failed.update({f"{suite} {m}": r for m, r in rows.items()})
        lines += [
            f"**{suite}** ({_count(len(runs.suites[suite]), 'scene')})",
            "",
            method_table(rows, suite),
        ]
        lines.append("")
    lines += failures(failed)
    return "\n".join(lines).rstrip() + "\n"


# --------------------------------------------------------------------------------------------
# Sampler against exhaustive search


def compare_scene(scene_path: Path, *, hypotheses: int = COMPARISON_HYPOTHESES) -> dict:
    """Exhaustive search, then the sampler with ``COMPARISON_COMPUTE_SHARE`` of its sampling
    time, both on one worker with ``hypotheses`` per object and seed 0 (same hypotheses).

    Returns {"scene", "status": "ok"|"skipped"|"failed", "reason", "objects", "same",
    "exhaustive_s", "sampler_s", "models", "samples", "fallback"}; "skipped" when exhaustive
    refuses the scene (too many objects or joint models).
    """
    from ipr.errors import IprError
    from ipr.pipeline import run_pipeline
    from ipr.scene import load_scene

    row = {"scene": scene_path.name, "status": "failed", "reason": None, "objects": 0}
    base = with_hypotheses(None, hypotheses)
    try:
        scene = load_scene(scene_path)
        # No deadline for exhaustive: a sample limit disables the default budget, and every
        # joint model is one task (the limit only has to exceed their number).
        exhaustive = run_pipeline(
            scene,
            base,
            method="exhaustive",
            seed=0,
            workers=1,
            samples=max(base.inference.max_exhaustive_models, 1),
        )
    except IprError as error:
        return {**row, "status": "skipped", "reason": _error_text(error)}
    except Exception as error:  # noqa: BLE001
        traceback.print_exc()
        return {**row, "reason": _error_text(error)}
    objects = len(exhaustive.posteriors)
    exhaustive_s = exhaustive.timing_s.get("inference_sampling", math.nan)
    row.update(
        objects=objects,
        exhaustive_s=exhaustive_s,
        models=exhaustive.summary.get("samples"),
    )
    if objects == 0 or not exhaustive_s > 0:
        return {**row, "status": "skipped", "reason": "no object to infer"}
    if exhaustive.summary.get("fallback"):
        return {
            **row,
            "status": "skipped",
            "reason": f"exhaustive: {exhaustive.summary['fallback']}",
        }
    budget = COMPARISON_COMPUTE_SHARE * exhaustive_s / objects
    try:
        sampler = run_pipeline(
            scene, with_budget(base, budget), method=COMPARISON_SAMPLER, seed=0, workers=1
        )
    except Exception as error:  # noqa: BLE001
        traceback.print_exc()
        return {**row, "reason": f"sampler: {_error_text(error)}"}
    exact = {p.object_id: p for p in exhaustive.posteriors}
    same = 0
    margins, shares = [], []
    for posterior in sampler.posteriors:
        reference = exact.get(posterior.object_id)
        if reference is not None and len(reference.probabilities) == len(posterior.probabilities):
            chosen = int(np.argmax(posterior.probabilities))
            same += int(chosen == int(np.argmax(reference.probabilities)))
            ranked = np.sort(reference.probabilities)[::-1]
            margins.append(float(ranked[0] - (ranked[1] if ranked.size > 1 else 0.0)))
            shares.append(float(reference.probabilities[chosen] / ranked[0]))
    return {
        **row,
        "status": "ok",
        "same": same,
        "margins": margins,
        "exact_shares": shares,
        "sampler_s": sampler.timing_s.get("inference_sampling", math.nan),
        "samples": sampler.summary.get("samples"),
        "fallback": sampler.summary.get("fallback"),
    }


def compare_scenes(scenes: Sequence[Path], *, hypotheses: int = COMPARISON_HYPOTHESES) -> list:
    """``compare_scene`` on every scene, each in its own child process (``isolated``, killed
    after ``COMPARISON_TIMEOUT_S``), with progress lines."""
    rows = []
    for number, scene in enumerate(scenes, 1):
        scene = Path(scene)
        started = time.perf_counter()
        try:
            row = isolated(
                compare_scene, scene, hypotheses=hypotheses, timeout_s=COMPARISON_TIMEOUT_S
            )
        except Exception as error:  # noqa: BLE001 - timeouts and crashes are listed
            row = {
                "scene": scene.name,
                "status": "failed",
                "reason": _error_text(error),
                "objects": 0,
            }
        rows.append(row)
        detail = (
            f"{row['same']}/{row['objects']} same, {row['sampler_s']:.1f} s vs "
            f"{row['exhaustive_s']:.1f} s"
            if row["status"] == "ok"
            else f"{row['status']}: {row['reason']}"
        )
        print(
            f"bench: inference sampler-vs-exhaustive {number}/{len(scenes)} "
            f"{scene.name} {time.perf_counter() - started:.1f} s; {detail}",
            flush=True,
        )
    return rows


def _fraction(value: float) -> str:
    return f"{value:.2f}" if math.isfinite(value) else "-"


def _margin_summary(rows: Sequence[dict]) -> str:
    """One sentence on how flat the exact posteriors are and how good the sampler's choices
    are under them (pooled over objects)."""
    margins = [m for r in rows for m in r.get("margins") or []]
    shares = [s for r in rows for s in r.get("exact_shares") or []]
    if not margins:
        return ""
    return (
        f"Exact posteriors: median margin of the most probable hypothesis over the runner-up "
        f"{median(margins):.3f} ({sum(m < 0.05 for m in margins)} of {len(margins)} objects "
        f"under 0.05); the sampler's choices have a median {median(shares):.0%} (lowest "
        f"{min(shares):.0%}) of the exact favourite's probability.\n"
    )


def comparison_section(rows: Sequence[dict], suite: str = "ycb-dynamic") -> str:
    """Agreement of the sampler's most probable hypotheses with exhaustive search's."""
    ok = [r for r in rows if r["status"] == "ok"]
    skipped = [r for r in rows if r["status"] == "skipped"]
    failed = [r for r in rows if r["status"] == "failed"]
    objects = sum(r["objects"] for r in ok)
    same = sum(r["same"] for r in ok)
    exhaustive_s = sum(r["exhaustive_s"] for r in ok)
    sampler_s = sum(r["sampler_s"] for r in ok)
    share = same / objects if objects else math.nan
    ratio = sampler_s / exhaustive_s if exhaustive_s > 0 else math.nan
    table = [
        [
            r["scene"],
            r["objects"],
            r["models"] if r["models"] is not None else "-",
            r["samples"] if r["samples"] is not None else "-",
            f"{r['same']}/{r['objects']}",
            _fraction(median(r.get("margins") or [math.nan])),
            _fraction(min(r.get("exact_shares") or [math.nan])),
            f"{r['exhaustive_s']:.1f}",
            f"{r['sampler_s']:.1f}",
            f"{r['sampler_s'] / r['exhaustive_s']:.0%}" if r["exhaustive_s"] > 0 else "-",
            "yes" if r["fallback"] else "no",
        ]
        for r in ok
    ]
    lines = [
        "## Tree sampler against exhaustive search",
        "",
        f"On the {suite} scenes the exhaustive search accepts (at most "
        f"{COMPARISON_MAX_OBJECTS} objects; {COMPARISON_HYPOTHESES} hypotheses per object), "
        "`exhaustive` scores every jointly feasible joint model (gravity and pushes, uniform "
        f"prior), then `{COMPARISON_SAMPLER}` runs with "
        f"{COMPARISON_COMPUTE_SHARE:.0%} of exhaustive's sampling time as its budget. Both "
        "seed 0, one worker, the same hypotheses. `same`: objects whose most probable "
        "hypothesis is the same in both; seconds: the sampling stage (wall). Target: at least "
        f"{TARGET_SAME_BEST:.0%} the same at most {TARGET_COMPUTE_SHARE:.0%} of the "
        "compute (the paper: 13%); the sampler stops at its deadline, so its measured share "
        "can exceed its budget by the few milliseconds a sample needs to notice it. "
        "`exact margin`: the median over the scene's objects of how much more exact posterior "
        "probability the most probable hypothesis has than the runner-up (how clear-cut the "
        "answer to agree on is); `worst exact share`: the lowest, over the objects, exact "
        "probability of the sampler's choice as a share of the most probable hypothesis's.",
        "",
    ]
    if table:
        lines += [
            markdown_table(
                [
                    "scene",
                    "objects",
                    "joint models",
                    "samples",
                    "same",
                    "exact margin",
                    "worst exact share",
                    "exhaustive s",
                    "sampler s",
                    "compute",
                    "fallback",
                ],
                table,
            ),
            "",
        ]
    lines += [
        markdown_table(
            ["target", "measured", "met"],
            [
                [
                    f"same most probable hypothesis >= {TARGET_SAME_BEST:.0%}",
                    f"{share:.1%} ({same}/{objects} objects, {_count(len(ok), 'scene')})"
                    if objects
                    else "- (no scene)",
                    _met(objects > 0 and share >= TARGET_SAME_BEST),
                ],
                [
                    f"compute (sampler s / exhaustive s, summed) <= {TARGET_COMPUTE_SHARE:.0%}",
                    f"{ratio:.2%}" if math.isfinite(ratio) else "-",
                    _met(math.isfinite(ratio) and ratio <= TARGET_COMPUTE_SHARE),
                ],
            ],
        ),
        "",
        _margin_summary(ok),
        f"Skipped {len(skipped)} of {len(rows)} scenes (more than {COMPARISON_MAX_OBJECTS} "
        "objects or too many joint models); failed: "
        + (", ".join(f"{r['scene']} (`{r['reason']}`)" for r in failed) or "none")
        + ".",
        "",
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# IoU against the budget


def budget_section(runs: Runs, suite: str = "ycb-dynamic", image: Path | None = None) -> str:
    """Mean object IoU of ``BUDGET_METHOD`` per inference budget on the first
    ``BUDGET_SCENES`` scenes, with the Collision Checker at budget 0; table and PNG plot."""
    from benchmarks.plot import Series, line_plot

    image = Path(image or BUDGET_IMAGE)
    checker = runs.rows(suite, "collision-checker", limit=BUDGET_SCENES)
    per_budget = {b: runs.rows(suite, BUDGET_METHOD, b, limit=BUDGET_SCENES) for b in BUDGETS_S}
    table = [
        [
            "0 (collision-checker)",
            _mean_median(checker, "object_iou"),
            _mean_median(checker, "scene_iou"),
            _seconds(_finite_median(r["total_s_per_object"] for r in checker if not r["error"])),
            "-",
            sum(1 for r in checker if r["error"]),
        ]
    ]
    for budget, rows in per_budget.items():
        ok = [r for r in rows if not r["error"]]
        samples = [r["samples"] for r in ok if r["samples"] is not None]
        table.append(
            [
                f"{budget:g}",
                _mean_median(rows, "object_iou"),
                _mean_median(rows, "scene_iou"),
                _seconds(_finite_median(r["total_s_per_object"] for r in ok)),
                f"{median(samples):.0f}" if samples else "-",
                len(rows) - len(ok),
            ]
        )
    paper_iou = PAPER_DYNAMIC_IOU["ipr+action+uniform"][0]
    points = [(0.0, _mean(checker, "object_iou"))]
    points += [(b, _mean(rows, "object_iou")) for b, rows in per_budget.items()]
    line_plot(
        image,
        [
            Series(BUDGET_METHOD, points),
            Series(
                f"paper IPR+action ({paper_iou:.3f})",
                [(0.0, paper_iou), (max(BUDGETS_S), paper_iou)],
                dashed=True,
            ),
        ],
        title=f"Object IoU vs inference budget ({suite}, {_count(len(checker), 'scene')})",
        x_label="inference budget per object (s, evenly spaced doublings); 0 = Collision Checker",
        y_label="mean object IoU",
        categorical_x=True,
        x_ticks=(0.0, *BUDGETS_S),
    )
    try:
        shown = image.relative_to(DOCS)
    except ValueError:
        shown = image
    failed = {f"budget {b:g}": rows for b, rows in per_budget.items()}
    lines = [
        "## Object IoU against the inference budget",
        "",
        f"`{BUDGET_METHOD}` on the first {len(checker)} {suite} scenes with "
        "`budget_per_object_s` (inference seconds per object; perception and hypotheses come "
        "on top) set in the configuration, all cores, seed 0; budget 0 is the Collision "
        "Checker (the sampler's starting point). IoU: mean (median); `wall s/object` and "
        "`samples/scene`: medians.",
        "",
        markdown_table(
            [
                "budget s/object",
                "object IoU",
                "scene IoU",
                "wall s/object",
                "samples/scene",
                "failed",
            ],
            table,
        ),
        "",
        f"![IoU vs budget]({shown.as_posix()})",
        "",
    ]
    lines += failures({"collision-checker": checker, **failed})
    return "\n".join(lines).rstrip() + "\n"


# --------------------------------------------------------------------------------------------
# The page


def checker_section(runs: Runs) -> str:
    """Markdown section: the Collision Checker on every suite, next to the paper."""
    lines = [
        "## Collision Checker (`ipr infer --method collision-checker`)",
        "",
        "The paper's ablation: a uniform prior over jointly feasible shapes (no physics). "
        "End to end per scene, seed 0, one BLAS thread; accuracy is the mean over scenes "
        "(median in brackets), 5 mm voxels, objects visible in frame 0. The paper's figures are "
        "on its own real YCB scenes (12 static, 13 dynamic), not on these suites.",
        "",
    ]
    accuracy, speed = [], []
    failed = {}
    for name, scenes in runs.suites.items():
        rows = runs.rows(name, "collision-checker")
        failed[name] = rows
        ok = [r for r in rows if not r["error"]]
        for space in ("object", "scene"):
            paper = PAPER_COLLISION_CHECKER.get(name, {}).get(space)
            accuracy.append(
                [
                    name,
                    space,
                    _mean_median(rows, f"{space}_iou"),
                    _mean_median(rows, f"{space}_f1"),
                    _mean_median(rows, f"{space}_precision"),
                    _mean_median(rows, f"{space}_recall"),
                    f"{paper[0]:.3f}" if paper else "-",
                ]
            )
        speed.append(
            [
                name,
                len(scenes),
                _finite_median(r["hypotheses_s_per_object"] for r in ok),
                _finite_median(r["method_s_per_object"] for r in ok),
                _finite_median(r["total_s_per_object"] for r in ok),
                median([ratio for r in ok for ratio in r["volume_spreads"]]),
            ]
        )
    lines += [
        markdown_table(
            ["suite", "space", "IoU", "F1", "precision", "recall", "paper IoU"], accuracy
        ),
        "",
    ]
    lines += [
        "Seconds per object, medians over scenes. Targets: hypothesis generation at most 0.5 s, "
        "Collision Checker end to end at most 1 s per object on one core (the paper: 7.75 s and "
        "0.32 s). `end to end` counts hypotheses and inference; `with perception` is the whole "
        "`ipr infer` wall time (all frames perceived) divided by the objects. `volume spread` is "
        "the median over all objects of max/min hypothesis volume (32 hypotheses per object).",
        "",
        markdown_table(
            [
                "suite",
                "scenes",
                "hypotheses s/object",
                "end to end s/object",
                "with perception s/object",
                "volume spread",
            ],
            speed,
        ),
        "",
    ]
    lines += failures(failed)
    return "\n".join(lines).rstrip() + "\n"


def run(suites: dict[str, list[Path]]) -> str:
    """Markdown sections: the Collision Checker on every suite, the physics-based methods, the
    sampler against exhaustive search, and IoU against the budget."""
    started = time.perf_counter()
    runs = Runs(suites)
    parts = [checker_section(runs)]
    if suites.get("ycb-dynamic"):
        parts.append(dynamic_section(runs))
    parts.append(static_section(runs))
    if suites.get("ycb-dynamic"):
        parts.append(comparison_section(compare_scenes(suites["ycb-dynamic"])))
        parts.append(budget_section(runs))
    parts.append(f"_Inference benchmark time: {time.perf_counter() - started:.0f} s._\n")
    return "\n".join(parts)
