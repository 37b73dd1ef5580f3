"""Development measurement of segmentation and tracking (docs/DESIGN_NOTES.md, "Perception";
the figures in docs/experiments/).

Usage: ``python -m benchmarks.dev_perception [--sets 8000:12 8100:24 ...] [--containers]
[--tracker-only] [--lost] [--config FILE]``.

Generates (or reuses) the development dynamic scenes of the design notes with ``ipr-shapes synth``
(base seeds 8000 (12 scenes), 8100 (24), 8012 (38), 8150 (50), and the held-out check 8050
(24); never the benchmark suites' seeds) under ``--scenes``, runs the perception on every scene
and scores it with the segmentation benchmark's own code (``benchmarks.segmentation``'s
``evaluate_suite`` and ``suite_figures``). Prints, per set, over the development sets pooled
and for the held-out check: ids kept ((object, later frame) pairs kept / pairs), the pooled
share of (object, frame) rows with F >= 0.75, and the median perception ms per frame.

``--containers`` scores the sets whose generator pool also holds open containers (bowl, mug,
cups; ``benchmarks.common.CONTAINER_OBJECTS``): by default static seed 7100 (16 scenes) and
dynamic seed 7200 (12), the sets of docs/experiments/2026-11-25-open-container-insides.md; a
set is then ``seed:count[:kind]``.

``--tracker-only`` caches each scene's untracked segmentation labels (``--cache``) on first use
and then reruns only the tracker on them (segmentation does not depend on the tracker: its
temporal step compares with the previous frame's untracked segmentation), for quick decisions
on tracker changes; its ms per frame is then the tracker's share alone. Decisions on anything
else, and the timing, need the full run.

``--lost`` also lists every lost (object, later frame) pair (``LostId``) and counts them by
kind: no segment with F >= 0.5 in the later frame (segmentation), a new id, or another frame-0
object's id, each split by whether the frame-0 id went to another visible object, is shown but
on no object's best segment, or is not shown at all, and marks the piece flips (the later
label was another frame-0 piece of the same object: ``LostId.piece_flip``); the diagnosis each
session used to rebuild in a throwaway script.
"""

from __future__ import annotations

import argparse
import ast
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # imported lazily at run time (the GL backend is chosen first)
    from benchmarks.segmentation import SceneSegmentation
    from ipr_shapes.segmentation_metrics import LostId

#: (base seed, scene count) of the development sets; the held-out check is scored apart.
DEVELOPMENT_SETS = ((8000, 12), (8100, 24), (8012, 38), (8150, 50))
HELD_OUT_SETS = ((8050, 24),)
#: (base seed, scene count, kind) of the container development sets (``--containers``).
CONTAINER_SETS = ((7100, 16, "static"), (7200, 12, "dynamic"))


def tracker_only_perceive(cache: Path, overrides: dict[str, float] | None = None):
    """A ``benchmarks.segmentation.Perceive`` that segments each scene once (labels cached as
    ``cache/<scene folder>-<scene>.npz``) and reruns only the tracking (``track_scene``) with
    the default ``TrackingConfig`` changed by ``overrides``; its seconds per frame are the
    tracker's time shared out over the frames."""
    from dataclasses import replace

    from ipr_shapes.perception import PerceptionConfig, perceive_scene, track_scene

    cache.mkdir(parents=True, exist_ok=True)
    defaults = PerceptionConfig()
    config = replace(defaults, tracking=replace(defaults.tracking, **(overrides or {})))

    def perceive(scene) -> tuple[list[np.ndarray], list[float]]:
        path = cache / f"{Path(scene.path).parent.name}-{Path(scene.path).name}.npz"
        if path.exists():
            with np.load(path) as stored:
                untracked = [stored[f"frame{i}"] for i in range(len(scene.frames))]
        else:
            perception = perceive_scene(scene, with_free_space=False)
            untracked = [s.labels for s in perception.segmentations]
            np.savez_compressed(path, **{f"frame{i}": u for i, u in enumerate(untracked)})
        points = [frame.points_world() for frame in scene.frames]
        started = time.perf_counter()
        labels = track_scene(untracked, scene, points, config)
        share = (time.perf_counter() - started) / max(len(scene.frames), 1)
        return labels, [share] * len(scene.frames)

    return perceive


def configured_perceive(path: Path):
    """A ``benchmarks.segmentation.Perceive`` running the perception with the settings of a
    TOML file (``ipr_shapes.config.read_config``; one timing run)."""
    from ipr_shapes.config import read_config
    from ipr_shapes.perception import perceive_scene

    config = read_config(path).perception

    def perceive(scene: object) -> tuple[list[np.ndarray], list[float]]:
        perception = perceive_scene(scene, config, with_free_space=False)
        return list(perception.labels), [float(s) for s in perception.timing_s["per_frame"]]

    return perceive


def _line(name: str, figures: dict) -> str:
    return (
        f"{name:14s} ids kept {figures['ids_consistent']:4d} / {figures['ids_counted']:4d} "
        f"({figures['ids_kept']:.3f})  F>=0.75 {figures['share_pooled']:.3f} "
        f"({figures['visible_rows']} rows)  {figures['time_median_ms']:.0f} ms/frame"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--sets",
        nargs="*",
        default=None,
        help="seed:count development sets (default: the design notes' four and the check)",
    )
    parser.add_argument("--no-held-out", action="store_true", help="skip the held-out check")
    parser.add_argument(
        "--containers", action="store_true", help="the sets with open containers in the pool"
    )
    parser.add_argument("--tracker-only", action="store_true")
    parser.add_argument("--lost", action="store_true", help="list and count the lost ids")
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="NAME=VALUE",
        help="with --tracker-only: TrackingConfig fields to change (Python literals)",
    )
    parser.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="TOML settings over the defaults (its [perception] sections; 'ipr-shapes config show')",
    )
    parser.add_argument("--scenes", type=Path, default=Path("/tmp/ipr-dev-perception"))
    parser.add_argument("--cache", type=Path, default=Path("/tmp/ipr-dev-perception/untracked"))
    args = parser.parse_args(argv)
    for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(variable, "1")
    from benchmarks.common import development_scenes
    from benchmarks.segmentation import default_perceive, evaluate_suite, suite_figures

    if args.sets is None:
        development = list(CONTAINER_SETS if args.containers else DEVELOPMENT_SETS)
    else:
        development = [_parse_set(s, parser) for s in args.sets]
    development = [(*s, "dynamic") if len(s) == 2 else s for s in development]
    held_out = [] if args.no_held_out or args.containers else list(HELD_OUT_SETS)
    held_out = [(*s, "dynamic") for s in held_out]
    overrides = {k: ast.literal_eval(v) for k, v in (s.split("=", 1) for s in args.set)}
    if overrides and not args.tracker_only:
        parser.error("--set needs --tracker-only")
    if args.config is not None and args.tracker_only:
        parser.error("--config needs the full run (without --tracker-only)")
    if args.config is not None:
        perceive = configured_perceive(args.config)
    elif args.tracker_only:
        perceive = tracker_only_perceive(args.cache, overrides)
    else:
        perceive = default_perceive(timing_runs=1)

    pooled = []
    for group, sets in (("development", development), ("held-out", held_out)):
        results_group = []
        for seed, count, kind in sets:
            scenes = development_scenes(
                args.scenes, seed, count, kind=kind, containers=args.containers
            )
            results = evaluate_suite(scenes, perceive)
            results_group.extend(results)
            print(_line(f"{seed} ({count})", suite_figures(results)), flush=True)
            for result in results:
                if result.error is not None:
                    print(f"  {result.scene}: {result.error}")
                if args.lost:
                    for lost in result.lost_ids:
                        print(f"  {seed}/{result.scene}: {_lost_line(lost)}")
        if results_group:
            print(_line(group, suite_figures(results_group)), flush=True)
            if args.lost:
                print(_lost_counts(results_group), flush=True)
        if group == "development":
            pooled = results_group
    return 0 if pooled or held_out else 1


def _lost_where(lost: LostId) -> str:
    """Where a lost pair's frame-0 id went in the later frame."""
    if lost.frame0_label_holder is not None:
        return "to another object"
    return "shown, on no object" if lost.frame0_label_shown else "not shown"


def _lost_line(lost: LostId) -> str:
    """One ``LostId`` as a line."""
    later = "-" if lost.label is None else str(lost.label)
    holder = "" if lost.frame0_label_holder is None else f" {lost.frame0_label_holder}"
    flip = "; piece flip" if lost.piece_flip else ""
    return (
        f"frame {lost.frame} object {lost.obj_id}/{lost.occurrence}: id {lost.frame0_label} -> "
        f"{later} ({lost.kind}; frame-0 id {_lost_where(lost)}{holder}{flip})"
    )


def _lost_counts(results: list[SceneSegmentation]) -> str:
    """Lost pairs of ``results`` counted by kind and where the frame-0 id went."""
    from collections import Counter

    counts = Counter((lost.kind, _lost_where(lost)) for r in results for lost in r.lost_ids)
    flips = sum(lost.piece_flip for r in results for lost in r.lost_ids)
    return (
        "  lost: "
        + "; ".join(
            f"{kind}, frame-0 id {where}: {n}" for (kind, where), n in sorted(counts.items())
        )
        + f" (piece flips among them: {flips})"
    )


def _parse_set(text: str, parser: argparse.ArgumentParser) -> tuple:
    """``seed:count[:kind]`` -> (seed, count[, kind])."""
    parts = text.split(":")
    try:
        if len(parts) in (2, 3) and (len(parts) == 2 or parts[2] in ("static", "dynamic")):
            return (int(parts[0]), int(parts[1]), *parts[2:])
    except ValueError:
        pass
    parser.error(f"a set is seed:count[:static|dynamic], got {text!r}")
    raise AssertionError  # parser.error exits


if __name__ == "__main__":
    sys.exit(main())
