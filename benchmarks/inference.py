"""Inference benchmarks: accuracy and speed of ``ipr-shapes infer`` per method on every suite.

The ``inference`` section of docs/BENCHMARKS.md (``python -m benchmarks.run --only inference``),
in three steps, each its own module:

1. ``benchmarks.inference_run``: each scene run end to end per method in a child process of its
   own and kept on disk, keyed by its settings and the code (a rerun reuses it; a code change
   makes a new one);
2. ``benchmarks.inference_score``: each kept run scored against the ground truth;
3. ``benchmarks.inference_render``: the scored rows as the page's tables and plot.

This module ties them: ``Runs`` gives the scored rows of a (suite, method, budget), each computed
once and shared by the tables, and ``run`` writes the section. Progress goes to stdout as
``bench: inference SUITE METHOD i/n``. A scene whose inference (or evaluation) raises, crashes
its process or hangs past ``inference_run.SCENE_TIMEOUT_S`` is listed and scores 0.

For a quick look at a few runs without the page (the same cache)::

    python -m benchmarks.inference --scene DIR [--scene DIR ...] [--method M ...]
        [--budget S] [--compare [--seeds N ...]]
    python -m benchmarks.inference --suite ycb-dynamic --limit 2 --method collision-checker
    python -m benchmarks.inference --prune    # delete the runs of other code versions
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from benchmarks import inference_render as render
from benchmarks.inference_run import run_scene
from benchmarks.inference_score import score_comparison, score_run
from benchmarks.inference_seeds import COMPARISON_SEEDS, seeded_records
from ipr_shapes.methods import get_method


def _status(row: dict) -> str:
    return f"FAILED {row['error']}" if row["error"] else f"object IoU {row['object_iou']:.3f}"


def run_method(
    scenes: Sequence[Path],
    method: str,
    *,
    suite: str = "",
    budget: float | None = None,
    label: str = "",
) -> list[dict]:
    """Run (or reuse the kept run of) ``method`` on every scene at ``budget`` seconds of
    inference per object (None: the default configuration) and score it; one row of figures
    per scene, failures and timeouts included as zero rows."""
    rows = []
    for number, scene in enumerate(scenes, 1):
        scene = Path(scene)
        started = time.perf_counter()
        record = run_scene(suite, scene, method, budget=budget)
        row = score_run(record)
        rows.append(row)
        print(
            f"bench: inference {label or '-'} {method} {number}/{len(scenes)} "
            f"{scene.name} {time.perf_counter() - started:.1f} s {_status(row)}"
            + (" (kept run)" if record.get("cached") else ""),
            flush=True,
        )
    return rows


class Runs:
    """Rows per (suite, method, budget per object), each computed once and shared by tables.

    ``budget`` None is the default configuration (``Config().inference.budget_per_object_s``)."""

    def __init__(self, suites: dict[str, list[Path]]) -> None:
        from ipr_shapes.config import Config

        self.suites = suites
        self.default_budget = Config().inference.budget_per_object_s
        self._rows: dict[tuple[str, str, float | None, int | None], list[dict]] = {}

    def rows(
        self, suite: str, method: str, budget: float | None = None, limit: int | None = None
    ) -> list[dict]:
        """Rows of the first ``limit`` scenes (all: None) of ``suite``; the methods without
        physics sampling (the Collision Checker, Zheng et al. 2013) ignore the budget; the
        default budget reuses the default runs."""
        scenes = list(self.suites.get(suite, []))
        limit = None if limit is None or limit >= len(scenes) else limit
        if not get_method(method).physics or budget == self.default_budget:
            budget = None
        for (s, m, b, n), rows in self._rows.items():  # a longer run of the same settings
            if (s, m, b) == (suite, method, budget) and (n is None or (limit and n >= limit)):
                return rows[:limit] if limit else rows
        label = suite if budget is None else f"{suite} budget {budget:g} s/object"
        rows = run_method(
            scenes[:limit] if limit else scenes, method, suite=suite, budget=budget, label=label
        )
        self._rows[(suite, method, budget, limit)] = rows
        return rows


def compare_scenes(
    scenes: Sequence[Path], *, suite: str = "ycb-dynamic", seeds: Sequence[int] = COMPARISON_SEEDS
) -> list[dict]:
    """The sampler against exhaustive search on every scene at each of the sampler's
    ``seeds`` (``inference_seeds``: run or reused, then scored; one row per scene and seed,
    one for a scene exhaustive search refused), with progress lines."""
    rows = []
    for number, scene in enumerate(scenes, 1):
        scene = Path(scene)
        started = time.perf_counter()
        records = seeded_records(suite, scene, seeds)
        scene_rows = [score_comparison(record) for record in records]
        rows += scene_rows
        ok = [row for row in scene_rows if row["status"] == "ok"]
        detail = (
            "same per seed "
            + " ".join(f"{row['same']}/{row['objects']}" for row in ok)
            + ", sampler s "
            + " ".join(f"{row['sampler_s']:.1f}" for row in ok)
            + f" vs {ok[0]['exhaustive_s']:.1f} s"
            if ok
            else "; ".join(f"{row['status']}: {row['reason']}" for row in scene_rows)
        )
        kept = sum(bool(record.get("cached")) for record in records)
        print(
            f"bench: inference sampler-vs-exhaustive {number}/{len(scenes)} "
            f"{scene.name} {time.perf_counter() - started:.1f} s; {detail}"
            + (f" ({kept} of {len(records)} kept runs)" if kept else ""),
            flush=True,
        )
    return rows


def run(suites: dict[str, list[Path]]) -> str:
    """Markdown sections: the Collision Checker on every suite, the physics-based methods, the
    sampler against exhaustive search, and IoU against the budget."""
    started = time.perf_counter()
    runs = Runs(suites)
    parts = [render.checker_section(runs)]
    if suites.get("ycb-dynamic"):
        parts.append(render.dynamic_section(runs))
    parts.append(render.static_section(runs))
    if suites.get("ycb-dynamic"):
        parts.append(render.comparison_section(compare_scenes(suites["ycb-dynamic"])))
        parts.append(render.budget_section(runs))
    parts.append(f"_Inference benchmark time: {time.perf_counter() - started:.0f} s._\n")
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> int:
    """Run (or reuse) a few runs and print their table; the page is not touched."""
    parser = argparse.ArgumentParser(
        description="Run or reuse inference benchmark runs on a few scenes and print the "
        "method table (and the sampler against exhaustive search with --compare)."
    )
    parser.add_argument("--suite", default="ycb-dynamic", help="suite name (cache folder)")
    parser.add_argument("--scene", type=Path, action="append", help="scene folder (repeatable)")
    parser.add_argument("--limit", type=int, help="the suite's first N scenes (no --scene)")
    parser.add_argument("--method", action="append", help="method (repeatable)")
    parser.add_argument("--budget", type=float, help="inference seconds per object")
    parser.add_argument("--compare", action="store_true", help="sampler against exhaustive")
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=list(COMPARISON_SEEDS),
        help="the sampler's seeds in --compare (exhaustive search runs once)",
    )
    parser.add_argument(
        "--prune",
        action="store_true",
        help="only delete the kept runs of other code versions than this checkout's",
    )
    args = parser.parse_args(argv)

    if args.prune:
        import shutil

        from benchmarks.inference_run import runs_dir, stale_runs

        stale = stale_runs()
        for directory in stale:
            shutil.rmtree(directory)
        print(f"bench: removed {len(stale)} runs of other code versions from {runs_dir()}")
        return 0

    if args.scene:
        scenes = list(args.scene)
    else:
        from ipr_shapes.suites import suite_scenes

        scenes = suite_scenes(args.suite)[: args.limit]
    runs = Runs({args.suite: scenes})
    methods = args.method or ["collision-checker"]
    rows = {m: runs.rows(args.suite, m, args.budget) for m in methods}
    print(render.method_table(rows, args.suite))
    if args.compare:
        rows = compare_scenes(scenes, suite=args.suite, seeds=args.seeds)
        print(render.comparison_section(rows, args.suite))
    return 0


if __name__ == "__main__":
    sys.exit(main())
