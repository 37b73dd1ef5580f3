"""Development measurement of view fusion (docs/DESIGN_NOTES.md, "View fusion"; figures in
docs/experiments/2026-11-24-view-fusion.md and the later and pusher free-space files).

Usage: ``python -m benchmarks.dev_fusion [--seed 9100] [--count 10]``.

Generates (or reuses) development dynamic scenes with ``ipr-shapes synth`` seeds from ``--seed`` (never
the benchmark suites), and scores the Collision Checker's answer on frame 0's partial objects
with and without the later views fused into them, each with frame 0's free space alone and with
the later frames' free space through each object's registered motion (``ipr_shapes.fusion``), and
with the pusher's volumes too (``FusionConfig.pusher_free_space``), against
the ground truth of the visible objects (benchmark code may read it; inference never does).
Prints the mean object IoU per scene and over all visible objects (unmatched objects count 0,
as in ``ipr-shapes eval``'s object space), how many objects a view was fused into or have a later free
space, and the time fusion took.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np


def _matched_iou(posteriors: list, truths: list[np.ndarray]) -> float:
    """Sum over the one-to-one best matches of the best hypotheses' IoU with the truths."""
    from scipy.optimize import linear_sum_assignment

    from ipr_shapes import voxels

    if not posteriors or not truths:
        return 0.0
    iou = np.zeros((len(posteriors), len(truths)))
    for i, posterior in enumerate(posteriors):
        keys = posterior.best_hypothesis.keys()
        for j, truth in enumerate(truths):
            common = voxels.intersection_count(keys, truth)
            iou[i, j] = common / (keys.size + truth.size - common)
    rows, columns = linear_sum_assignment(-iou)
    return float(iou[rows, columns].sum())


def measure_scene(path: Path) -> dict:
    """Summed matched IoU without and with fusion, visible truths, fused objects, seconds."""
    from ipr_shapes import voxels
    from ipr_shapes.collision_checker import collision_checker
    from ipr_shapes.config import Config
    from ipr_shapes.fusion import FusionConfig, fuse_views, tracked_free_spaces
    from ipr_shapes.ground_truth import frame0_ground_truth, visible_pixel_counts
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.pipeline import checker_hidden_fractions
    from ipr_shapes.scene import load_scene

    scene = load_scene(path)
    perception = perceive_scene(scene)
    poses, models, _ = frame0_ground_truth(path)
    counts, _ = visible_pixel_counts(path, poses, models)
    world_from_camera = scene.frames[0].world_from_camera
    truths = [
        voxels.occupied_voxels(
            model, voxels.DEFAULT_PITCH_M, world_from_camera @ pose.camera_from_model
        )
        for pose, model, count in zip(poses, models, counts, strict=True)
        if count >= 100
    ]
    support = next((p for p in perception.planes[0] if p.kind == "support"), None)
    started = time.perf_counter()
    fused = fuse_views(perception.objects, perception.free_space, support)
    seconds = time.perf_counter() - started
    later_only = FusionConfig(pusher_free_space=False)
    tracked = tracked_free_spaces(fused, perception.free_space, config=later_only)
    with_pushes = tracked_free_spaces(
        fused,
        perception.free_space,
        scene.pushes,
        scene.pusher,
        FusionConfig(pusher_free_space=True),
    )
    # The default medoid weights read the hidden outline and the camera, as ``ipr-shapes infer``
    # hands them over (without them the Collision Checker measures "candidate" weights).
    hidden = checker_hidden_fractions(scene, perception, Config())
    scores = {}
    for name, objects, spaces in _variants(
        perception.objects[0], fused.objects, tracked, with_pushes
    ):
        posteriors = collision_checker(
            objects,
            perception.free_space[0],
            perception.planes[0],
            rng=np.random.default_rng(0),
            object_spaces=spaces,
            hidden=hidden,
            camera_m=world_from_camera[:3, 3],
        )
        scores[name] = _matched_iou(posteriors, truths)
    return {
        "scores": scores,
        "truths": len(truths),
        "objects": len(fused.objects),
        "fused": len(fused.fused_frames),
        "tracked": len(tracked),
        "pushed_past": sum(len(space.swept) for space in with_pushes.values()),
        "seconds": seconds,
    }


def _variants(
    frame0: tuple, fused: tuple, tracked: dict, with_pushes: dict
) -> list[tuple[str, tuple, dict]]:
    """(name, objects, per-object spaces) of the compared inputs."""
    return [
        ("frame 0", frame0, {}),
        ("fused", fused, {}),
        ("tracked free", frame0, tracked),
        ("fused+tracked", fused, tracked),
        ("+pushed past", fused, with_pushes),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=9100)
    parser.add_argument("--count", type=int, default=10)
    parser.add_argument("--scenes", type=Path, default=Path("/tmp/ipr-dev-inference"))
    args = parser.parse_args(argv)
    from benchmarks.common import development_scenes

    rows = []
    for path in development_scenes(args.scenes, args.seed, args.count):
        row = measure_scene(path)
        rows.append(row)
        per = {k: v / max(row["truths"], 1) for k, v in row["scores"].items()}
        print(f"{path.name}: " + ", ".join(f"{k} {v:.3f}" for k, v in per.items()), flush=True)
    truths = max(sum(r["truths"] for r in rows), 1)
    objects = sum(r["objects"] for r in rows)
    print(f"\n{len(rows)} scenes, {truths} visible objects, Collision Checker mean object IoU:")
    for name in rows[0]["scores"] if rows else ():
        print(f"  {name:14s} {sum(r['scores'][name] for r in rows) / truths:.3f}")
    print(
        f"views fused into {sum(r['fused'] for r in rows)} of {objects} objects, "
        f"later free space for {sum(r['tracked'] for r in rows)}; "
        f"{sum(r['pushed_past'] for r in rows)} (object, push) pairs pushed past; "
        f"fusion {sum(r['seconds'] for r in rows) / max(objects, 1):.2f} s per object"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
