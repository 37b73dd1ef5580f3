"""Segmentation benchmark: per-object overlap of the tracked perception labels with the
ground-truth masks, id consistency across frames, and perception time per frame.

For every scene of every suite the perception under test (``ipr_shapes.perception.perceive_scene``,
imported lazily) labels every frame; every frame is scored against the ground-truth masks of
``ipr_shapes.segmentation_metrics.ground_truth_masks`` (BOP visibility, objects with at least 100
visible pixels; the scene's own BOP ``mask_visib/`` files where it has them, as bins-real does)
with the OSD/OCID object-overlap convention (``segmentation_scores``), and the
sequence's id consistency is counted (``id_consistency_counts``). A scene whose perception raises
is scored as an empty prediction and listed. Perception runs with BLAS/OpenMP pools limited to
one thread; its time per frame is the perception's own ``timing_s["per_frame"]``.

Figures per suite: medians over scenes of each scene's mean precision, recall, F and share of
objects with F >= 0.75 (a scene's means pool its (object, frame) rows over all frames); the same
share pooled over every (object, frame) row of the suite; id consistency pooled over the suite's
(object, later frame) pairs; the median and 90th percentile of the perception time per frame.
Suites are reported real first, in the order of ``SHARE_TARGETS``.

``python -m benchmarks.segmentation --suite bins-real --suite ycbv-real`` prints the section for
the named suites without touching docs/BENCHMARKS.md (``benchmarks.run --only segmentation``
reruns it on every suite and writes the page).
"""

from __future__ import annotations

import argparse
import inspect
import math
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from benchmarks.common import markdown_table, median, one_thread

if TYPE_CHECKING:  # ipr is imported lazily (the GL backend is chosen first)
    from ipr_shapes.segmentation_metrics import LostId

#: Targets: share of visible objects with F >= 0.75 per suite (in the order the suites are
#: reported), share of ids kept (ycb-dynamic), time per frame.
SHARE_TARGETS = {"ycbv-real": 0.95, "bins-real": 0.80, "ycb-static": 0.95, "ycb-dynamic": 0.95}
ID_TARGET = 0.97
TIME_TARGET_MS = 150.0
#: Runs of each scene's perception whose per-frame median is its time (``default_perceive``).
TIMING_RUNS = 3
LOWEST_SCENES_LISTED = 3
FAILURES_LISTED = 5

#: A perception under test: scene -> (per-frame (H, W) int labels, seconds per frame).
Perceive = Callable[[object], tuple[list[np.ndarray], list[float]]]


@dataclass(frozen=True)
class SceneSegmentation:
    """Scores of one scene over all its frames.

    ``f_measure``, ``precision``, ``recall`` (N,) float64 of its visible (object, frame) rows;
    ``ceiling_f`` (N,) F of the same rows for the ground truth restricted to pixels with a depth
    reading (what a perfect depth-based segmentation can reach);
    ``frame0_visible`` visible objects in frame 0; ``ids_consistent`` of ``ids_counted``
    (object, later frame) pairs kept their id, ``lost_ids`` the other counted pairs
    (``ipr_shapes.segmentation_metrics.LostId``); ``per_frame_s`` perception seconds per frame;
    ``error`` the perception's exception (then scored as an empty prediction), else None.
    """

    scene: str
    frames: int
    frame0_visible: int
    precision: np.ndarray
    recall: np.ndarray
    f_measure: np.ndarray
    ceiling_f: np.ndarray
    ids_consistent: int
    ids_counted: int
    per_frame_s: tuple[float, ...]
    error: str | None
    lost_ids: tuple[LostId, ...] = ()

    @property
    def share_f75(self) -> float:
        """Share of the scene's visible (object, frame) rows with F >= 0.75 (nan if none)."""
        from ipr_shapes.segmentation_metrics import F_THRESHOLD

        return float(np.mean(self.f_measure >= F_THRESHOLD)) if self.f_measure.size else math.nan


def default_perceive(timing_runs: int = TIMING_RUNS) -> Perceive:
    """The perception under test, ``ipr_shapes.perception.perceive_scene``, as a ``Perceive``.

    The scene is perceived ``timing_runs`` times: the labels are the first run's (the
    perception is deterministic) and each frame's time is its median over the runs, so that a
    burst of load on a shared machine does not decide a frame's figure.
    """
    from ipr_shapes.perception import perceive_scene

    keywords = {}
    if "with_free_space" in inspect.signature(perceive_scene).parameters:
        keywords["with_free_space"] = False  # not part of the per-frame time; saves bench time

    def perceive(scene: object) -> tuple[list[np.ndarray], list[float]]:
        perception = perceive_scene(scene, **keywords)
        runs = [perception.timing_s["per_frame"]]
        for _ in range(timing_runs - 1):
            runs.append(perceive_scene(scene, **keywords).timing_s["per_frame"])
        per_frame = np.median(np.array(runs, dtype=np.float64), axis=0)
        return list(perception.labels), [float(s) for s in per_frame]

    return perceive


class _Renderers:
    """One ``ipr_shapes.rendering.Renderer`` per image size, closed together."""

    def __init__(self) -> None:
        self._by_size: dict[tuple[int, int], object] = {}

    def get(self, width: int, height: int) -> object:
        from ipr_shapes.rendering import Renderer

        if (width, height) not in self._by_size:
            self._by_size[(width, height)] = Renderer(width, height)
        return self._by_size[(width, height)]

    def close(self) -> None:
        for renderer in self._by_size.values():
            renderer.close()
        self._by_size.clear()


def evaluate_scene(
    scene_path: Path, perceive: Perceive, renderers: _Renderers
) -> SceneSegmentation:
    """Run ``perceive`` on one scene and score every frame (module doc)."""
    from ipr_shapes.scene import load_scene
    from ipr_shapes.segmentation_metrics import (
        ground_truth_masks,
        id_consistency_counts,
        segmentation_scores,
    )

    scene = load_scene(scene_path)
    error = None
    try:
        with one_thread():
            labels, per_frame_s = perceive(scene)
        if len(labels) != len(scene.frames):
            raise ValueError(f"{len(labels)} label images for {len(scene.frames)} frames")
    except Exception as exception:  # a failing scene is scored, not fatal
        error = "".join(traceback.format_exception_only(exception)).strip()
        labels = [np.zeros(frame.shape, dtype=np.int32) for frame in scene.frames]
        per_frame_s = []

    truths, obj_ids, rows, ceiling = [], [], [], []
    frame0_visible = 0
    for frame, predicted in zip(scene.frames, labels, strict=True):
        height, width = frame.shape
        truth, ids, _ = ground_truth_masks(
            scene_path, frame.index, renderer=renderers.get(width, height), frame=frame
        )
        scores = segmentation_scores(np.asarray(predicted), truth)
        if frame.index == 0:
            frame0_visible = scores.n_visible
        rows.extend(scores.objects)
        measured = segmentation_scores(np.where(frame.depth_m > 0, truth, 0), truth)
        ceiling.extend(row.f_measure for row in measured.objects)
        truths.append(truth)
        obj_ids.append(ids)
    ids = id_consistency_counts([np.asarray(p) for p in labels], truths, obj_ids)
    return SceneSegmentation(
        scene=scene_path.name,
        frames=len(scene.frames),
        frame0_visible=frame0_visible,
        precision=np.array([row.precision for row in rows], dtype=np.float64),
        recall=np.array([row.recall for row in rows], dtype=np.float64),
        f_measure=np.array([row.f_measure for row in rows], dtype=np.float64),
        ceiling_f=np.array(ceiling, dtype=np.float64),
        ids_consistent=ids.consistent,
        ids_counted=ids.counted,
        per_frame_s=tuple(per_frame_s),
        error=error,
        lost_ids=ids.lost,
    )


def evaluate_suite(scenes: list[Path], perceive: Perceive) -> list[SceneSegmentation]:
    """``evaluate_scene`` on every scene of a suite, sharing the GL renderers."""
    renderers = _Renderers()
    try:
        return [evaluate_scene(Path(scene), perceive, renderers) for scene in scenes]
    finally:
        renderers.close()


def suite_figures(results: list[SceneSegmentation]) -> dict[str, float]:
    """The suite's figures (module doc); ratios in [0, 1], times in ms, nan when undefined."""
    from ipr_shapes.segmentation_metrics import F_THRESHOLD

    scored = [r for r in results if r.f_measure.size]
    pooled_f = np.concatenate([r.f_measure for r in results]) if results else np.zeros(0)
    pooled_ceiling = np.concatenate([r.ceiling_f for r in results]) if results else np.zeros(0)
    consistent = sum(r.ids_consistent for r in results)
    counted = sum(r.ids_counted for r in results)
    times_ms = 1000.0 * np.array([s for r in results for s in r.per_frame_s], dtype=np.float64)
    return {
        "scenes": len(results),
        "frames": sum(r.frames for r in results),
        "visible_frame0": sum(r.frame0_visible for r in results),
        "visible_rows": int(pooled_f.size),
        "precision": median([float(r.precision.mean()) for r in scored]),
        "recall": median([float(r.recall.mean()) for r in scored]),
        "f_measure": median([float(r.f_measure.mean()) for r in scored]),
        "share_median": median([r.share_f75 for r in scored]),
        "share_pooled": float(np.mean(pooled_f >= F_THRESHOLD)) if pooled_f.size else math.nan,
        "share_ceiling": (
            float(np.mean(pooled_ceiling >= F_THRESHOLD)) if pooled_ceiling.size else math.nan
        ),
        "ids_consistent": consistent,
        "ids_counted": counted,
        "ids_kept": consistent / counted if counted else math.nan,
        "time_median_ms": float(np.median(times_ms)) if times_ms.size else math.nan,
        "time_p90_ms": float(np.percentile(times_ms, 90)) if times_ms.size else math.nan,
        "failures": sum(r.error is not None for r in results),
    }


def ordered(suites: dict[str, list[Path]]) -> dict[str, list[Path]]:
    """The suites in the order of ``SHARE_TARGETS`` (the real suites first), others after."""
    rank = {name: number for number, name in enumerate(SHARE_TARGETS)}
    names = sorted(suites, key=lambda name: (rank.get(name, len(rank)), name))
    return {name: suites[name] for name in names}


def _percent(value: float) -> str:
    return "-" if math.isnan(value) else f"{100 * value:.1f} %"


def _ms(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.0f}"


def _met(value: float, target: float, *, at_most: bool = False) -> str:
    if math.isnan(value):
        return "-"
    return "yes" if (value <= target if at_most else value >= target) else "**no**"


def run(suites: dict[str, list[Path]], perceive: Perceive | None = None) -> str:
    """Markdown section with the segmentation figures of every suite.

    ``perceive`` defaults to ``ipr_shapes.perception.perceive_scene`` (imported here, lazily); when that
    cannot be imported the section says so instead of failing the whole benchmark run.
    """
    header = [
        "## Segmentation and tracking (`ipr_shapes.perception`)",
        "",
        "Every frame of every scene is segmented and tracked by `perceive_scene`, and scored "
        "against ground-truth masks rendered from the models and poses (BOP visibility: front-most "
        "and within 15 mm of the observed depth or no reading; generated walls occlude), or the "
        "scene's own BOP `mask_visib/` masks where it has them (bins-real). OSD/OCID "
        "object overlap: each visible object (>= 100 px) takes the predicted segment with the "
        "best F-measure (not one-to-one: merged objects lose precision, split ones recall). "
        "Precision, recall, F: medians over scenes of the scene's mean over its (object, frame) "
        "rows; `F>=0.75`: share of visible objects with F >= 0.75, median over scenes and pooled "
        "over all (object, frame) rows; `ids kept`: share of (object, later frame) pairs whose "
        "object, found in frame 0 (F >= 0.5), has its best segment (F >= 0.5) under the same "
        "id (`ipr_shapes.segmentation_metrics`). Time: perception per frame (planes to facets, tracking "
        "shared out, free space excluded), one BLAS thread, 640x480, each frame's median over "
        f"{TIMING_RUNS} runs. `ceiling`: the pooled "
        "F>=0.75 share of the ground truth itself restricted to pixels with a depth reading "
        "(masks include pixels without depth, which a depth-based segmentation cannot label).",
        "",
        "Targets: F>=0.75 pooled of visible objects "
        + ", ".join(f"{name} >= {target:.0%}" for name, target in SHARE_TARGETS.items())
        + f"; tracking keeps >= {ID_TARGET:.0%} of ids (ycb-dynamic); perception <= "
        f"{TIME_TARGET_MS:.0f} ms per 640x480 frame on one core.",
        "",
    ]
    if perceive is None:
        try:
            perceive = default_perceive()
        except ImportError as error:
            return "\n".join(
                [*header, f"_Not run: the perception cannot be imported ({error})._", ""]
            )

    started = time.perf_counter()
    figures, lowest, failures = {}, {}, {}
    for name, scenes in ordered(suites).items():
        results = evaluate_suite(list(scenes), perceive)
        figures[name] = suite_figures(results)
        ranked = sorted((r for r in results if r.f_measure.size), key=lambda r: r.share_f75)
        lowest[name] = [f"{r.scene} {_percent(r.share_f75)}" for r in ranked[:LOWEST_SCENES_LISTED]]
        failures[name] = [f"{r.scene}: {r.error}" for r in results if r.error is not None]

    rows = []
    for name, f in figures.items():
        rows.append(
            [
                name,
                f"{f['scenes']}",
                f"{f['frames']}",
                f"{f['visible_frame0']}",
                f"{f['visible_rows']}",
                f["precision"],
                f["recall"],
                f["f_measure"],
                _percent(f["share_median"]),
                _percent(f["share_pooled"]),
                _percent(f["share_ceiling"]),
                f"{_percent(f['ids_kept'])} ({f['ids_consistent']}/{f['ids_counted']})",
                _ms(f["time_median_ms"]),
                _ms(f["time_p90_ms"]),
                f"{f['failures']}",
            ]
        )
    lines = [
        *header,
        markdown_table(
            [
                "suite",
                "scenes",
                "frames",
                "visible objects, frame 0",
                "visible (object, frame)",
                "precision",
                "recall",
                "F",
                "F>=0.75 median",
                "F>=0.75 pooled",
                "ceiling",
                "ids kept",
                "ms/frame median",
                "ms/frame p90",
                "failed scenes",
            ],
            rows,
        ),
        "",
    ]
    checks = []
    for name, f in figures.items():
        target = SHARE_TARGETS.get(name)
        if target is not None:
            checks.append(
                [
                    name,
                    f"F>=0.75 pooled >= {target:.0%}",
                    _percent(f["share_pooled"]),
                    _met(f["share_pooled"], target),
                ]
            )
    if "ycb-dynamic" in figures:
        kept = figures["ycb-dynamic"]["ids_kept"]
        checks.append(
            ["ycb-dynamic", f"ids kept >= {ID_TARGET:.0%}", _percent(kept), _met(kept, ID_TARGET)]
        )
    all_times = [
        f["time_median_ms"] for f in figures.values() if not math.isnan(f["time_median_ms"])
    ]
    worst_time = max(all_times) if all_times else math.nan
    checks.append(
        [
            "all",
            f"median ms/frame (slowest suite) <= {TIME_TARGET_MS:.0f}",
            _ms(worst_time),
            _met(worst_time, TIME_TARGET_MS, at_most=True),
        ]
    )
    lines += [markdown_table(["suite", "target", "measured", "met"], checks), ""]
    for name in figures:
        if lowest[name]:
            lines.append(f"- {name}, lowest F>=0.75 shares: {', '.join(lowest[name])}.")
        for failure in failures[name][:FAILURES_LISTED]:
            lines.append(f"- {name}, perception failed on {failure}")
        if len(failures[name]) > FAILURES_LISTED:
            lines.append(
                f"- {name}: {len(failures[name]) - FAILURES_LISTED} more failed scenes not listed"
            )
    lines += ["", f"_Segmentation benchmark time: {time.perf_counter() - started:.0f} s._", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print the segmentation section for the named suites (docs/BENCHMARKS.md is untouched)."""
    parser = argparse.ArgumentParser(
        description="Run the segmentation benchmark on a few suites and print its section."
    )
    parser.add_argument(
        "--suite", action="append", help="suite name (repeatable; default: the real suites)"
    )
    parser.add_argument(
        "--timing-runs",
        type=int,
        default=TIMING_RUNS,
        help=f"perception runs per scene whose per-frame median is the time (default {TIMING_RUNS})",
    )
    parser.add_argument(
        "--config",
        type=Path,
        help="TOML settings over the defaults (its [perception] sections; one timing run)",
    )
    args = parser.parse_args(argv)
    from ipr_shapes.suites import REAL, SUITES, suite_scenes

    names = args.suite or list(REAL)
    unknown = [name for name in names if name not in SUITES]
    if unknown:
        parser.error(f"unknown suite {unknown[0]!r}; choose from {', '.join(SUITES)}")
    suites = {name: suite_scenes(name) for name in names}
    if args.config is not None:
        from benchmarks.dev_perception import configured_perceive

        perceive = configured_perceive(args.config)
    else:
        perceive = default_perceive(args.timing_runs)
    print(run(suites, perceive))
    return 0


if __name__ == "__main__":
    sys.exit(main())
