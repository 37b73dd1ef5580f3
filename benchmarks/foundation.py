"""Foundation benchmarks: scene generation speed, suite statistics, metrics sanity (oracle).

- Generation time per scene: fresh scenes generated one after another in one process (so the
  figure is a single-core time), medians per kind; suites themselves are generated in parallel.
- Suite statistics: objects, visible objects, frames and pushes per scene.
- Oracle: each scene's ground truth written as a result and scored with ``ipr-shapes eval``; a correct
  metrics implementation gives IoU 1 up to voxelisation ties, so anything below 0.99 is a bug.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

from benchmarks.common import markdown_table, median

TIMING_SCENES_PER_KIND = 6


def generation_timing(seed: int = 99) -> dict[str, list[float]]:
    """Seconds per scene for fresh static and dynamic scenes (all three arrangements)."""
    from ipr_shapes.suites import ARRANGEMENTS
    from ipr_shapes.synth import generate_scene

    timings: dict[str, list[float]] = {"static": [], "dynamic": []}
    with tempfile.TemporaryDirectory() as folder:
        for kind in timings:
            for index in range(TIMING_SCENES_PER_KIND):
                started = time.perf_counter()
                generate_scene(
                    Path(folder),
                    kind=kind,
                    seed=seed + index,
                    arrangement=ARRANGEMENTS[index % 3],
                    name=f"{kind}-{index}",
                )
                timings[kind].append(time.perf_counter() - started)
    return timings


def suite_statistics(scenes: list[Path]) -> dict[str, float]:
    """Median objects, visible objects, frames and pushes per scene of a suite."""
    from ipr_shapes.scene import load_visible_pixel_counts

    objects, visible, frames, pushes = [], [], [], []
    for scene in scenes:
        counts = load_visible_pixel_counts(scene)
        gt = json.loads((scene / "scene_gt.json").read_text())
        frames.append(len(gt))
        if counts is not None:
            objects.append(len(counts[0]))
            visible.append(sum(count >= 100 for count in counts[0]))
        actions = scene / "actions.json"
        pushes.append(len(json.loads(actions.read_text())["pushes"]) if actions.exists() else 0)
    return {
        "scenes": len(scenes),
        "objects": median(objects),
        "visible": median(visible),
        "frames": median(frames),
        "pushes": median(pushes),
    }


def oracle_scores(scenes: list[Path]) -> dict[str, float]:
    """Minimum and median IoU of the ground truth scored as a result, both spaces."""
    from ipr_shapes.ground_truth import write_ground_truth_result
    from ipr_shapes.metrics import evaluate

    scene_iou, object_iou, seconds = [], [], []
    with tempfile.TemporaryDirectory() as folder:
        for scene in scenes:
            result = write_ground_truth_result(scene, Path(folder) / scene.name)
            started = time.perf_counter()
            evaluation = evaluate(scene, result)
            seconds.append(time.perf_counter() - started)
            scene_iou.append(evaluation.scene_space.iou)
            object_iou.append(evaluation.object_space.iou)
    return {
        "scene_min": min(scene_iou),
        "scene_median": median(scene_iou),
        "object_min": min(object_iou),
        "object_median": median(object_iou),
        "eval_s": median(seconds),
    }


def run(suites: dict[str, list[Path]]) -> str:
    """Markdown section with the foundation figures."""
    timings = generation_timing()
    lines = [
        "## Scene generation (`ipr-shapes synth`)",
        "",
        f"Fresh scenes generated one after another in one process, {TIMING_SCENES_PER_KIND} "
        "per kind (table, container and drawer arrangements in turn), 640x480, "
        "seconds per scene. Target: at most 10 s.",
        "",
        markdown_table(
            ["kind", "median s", "max s"],
            [[kind, median(values), max(values)] for kind, values in timings.items()],
        ),
        "",
        "## Benchmark suites",
        "",
        "Generated on first use from fixed seeds and cached outside the repository "
        "(`ipr-shapes suite NAME`); medians per scene.",
        "",
    ]
    rows = []
    for name, scenes in suites.items():
        if name == "ycbv-real":
            continue
        stats = suite_statistics(scenes)
        rows.append(
            [name]
            + [f"{stats[key]:g}" for key in ("scenes", "objects", "visible", "frames", "pushes")]
        )
    lines += [
        markdown_table(
            ["suite", "scenes", "objects", "visible (>=100 px)", "frames", "pushes"], rows
        ),
        "",
    ]
    lines += [
        "## Metrics sanity: ground truth scored as a result",
        "",
        "`ipr-shapes ground-truth` then `ipr-shapes eval` on every scene; IoU must be at least 0.99 in both "
        "spaces (5 mm voxels). `eval s` is the median time of one evaluation.",
        "",
    ]
    rows = []
    for name, scenes in suites.items():
        scores = oracle_scores(scenes)
        rows.append(
            [
                name,
                len(scenes),
                scores["scene_min"],
                scores["scene_median"],
                scores["object_min"],
                scores["object_median"],
                scores["eval_s"],
            ]
        )
    lines += [
        markdown_table(
            [
                "suite",
                "scenes",
                "scene IoU min",
                "scene IoU median",
                "object IoU min",
                "object IoU median",
                "eval s",
            ],
            rows,
        ),
        "",
    ]
    return "\n".join(lines)
