"""The ceiling of any choice among the hypotheses, per suite and per generator (issue 28).

The ``hypotheses`` section of docs/BENCHMARKS.md (``python -m benchmarks.run --only
hypotheses``), or on its own for a subset::

    python -m benchmarks.hypothesis_ceiling --suite ycb-dynamic --limit 4 [--scene DIR ...]
        [--perception-cache DIR] [--algorithm1-only] [--neighbour-surfaces] [--superquadric N]
        [--fitted-axis] [--unbounded-view] [--unbounded-support] [--medoid-weights W]
        [--shrink-by-scatter] [--revolution-radius wall_mean] [--carve-before-choice]
        [--medoid-self nearest]

Per scene: frame 0 is perceived, the hypotheses are prepared (``prepare_hypotheses``, the
default configuration, seed 0, as the Collision Checker's run draws them) and the Collision
Checker's marginals taken from them (``uniform_posteriors``); the output of each object is then
carved by frame 0's free space as ``ipr-shapes infer`` writes it (``ipr_shapes.carving``). Against the ground
truth (benchmark code may read it; inference never does), each visible object (>= 100 pixels in
frame 0) is matched to a prediction one-to-one by the Hungarian assignment on the Collision
Checker's output IoU (5 mm voxels), and scores:

- ``collision checker``: the IoU of the carved output (``ipr-shapes eval``'s object IoU);
- ``oracle``: the best IoU of the object's candidates the Collision Checker kept (non-zero
  probability: jointly feasible), convex as inferred: the ceiling of any choice among them;
- ``oracle, carved``: the same candidates carved by frame 0's free space as their written
  shapes are (``ipr_shapes.carving.carve_voxels``): the ceiling of any choice among the
  written shapes, which is what the Collision Checker's figure is measured on;
- per generator (``ShapeHypothesis.generator``), the best IoU of that generator's candidates,
  and how often that generator holds the object's best candidate (ties go to the first);
- the candidates' volume spread (largest / smallest kept candidate, median over objects).

Unmatched visible objects count 0 everywhere. Timing: generation and constraints of the whole
scene (``prepare_hypotheses``) per object, as process CPU time and as wall time; the machine is
shared, so CPU time is the figure to compare. The first scene is measured once untimed before
the timed runs (``warm_up``), so that the numba kernels' one-off compilation on a cold cache
(about 7 s in a fresh clone) is not counted as the first suite's per-object cost.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import pickle
import sys
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchmarks.common import markdown_table, median

#: Suites of the section (bins-real has no full models of its objects).
SUITES = ("ycb-static", "ycb-dynamic", "ycbv-real")
MIN_VISIBLE_PX = 100


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    from ipr_shapes import voxels

    common = voxels.intersection_count(a, b)
    union = a.size + b.size - common
    return common / union if union else 0.0


def _perceive(path: Path, cache: Path | None):
    """Frame 0's objects, free space and planes (pickled in ``cache`` when given)."""
    from ipr_shapes.config import Config
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.scene import load_scene

    stored = cache / f"{path.parent.name}-{path.name}.pkl" if cache else None
    if stored is not None and stored.exists():
        return pickle.loads(stored.read_bytes())
    scene = load_scene(path)
    scene = dataclasses.replace(scene, frames=scene.frames[:1], pushes=())
    perception = perceive_scene(scene, Config().perception)
    out = (scene, perception.objects, perception.free_space[0], perception.planes[0])
    if stored is not None:
        stored.parent.mkdir(parents=True, exist_ok=True)
        stored.write_bytes(pickle.dumps(out))
    return out


def checker_posteriors(scene, objects, prepared, config, rng):
    """The Collision Checker's posteriors of frame 0's ``objects`` from ``prepared`` hypotheses,
    with the medoid inputs its configured weights read (the hidden outline fractions, the
    observed points and the camera they were seen from), as ``ipr-shapes infer`` hands them over:
    benchmarks that call ``uniform_posteriors`` without them measure "candidate" weights."""
    from ipr_shapes.collision_checker import object_viewpoints, uniform_posteriors
    from ipr_shapes.perception.outline import hidden_outline_fractions

    weights = config.collision_checker.medoid_weights
    hidden = None
    if weights in ("outline", "outline-fit"):
        hidden = hidden_outline_fractions(
            scene.frames[0].depth_m, objects, config.perception.segmentation.contour_gap_m
        )
    points = viewpoints = None
    if weights in ("fit", "outline-fit"):
        points = {o.id: o.points for o in objects}
        camera = scene.frames[0].world_from_camera[:3, 3]
        viewpoints = {o.id: object_viewpoints(o, camera) for o in objects}
    return uniform_posteriors(
        prepared, config.collision_checker, rng=rng, hidden=hidden, points=points,
        viewpoints=viewpoints,
    )  # fmt: skip


def measure_scene(path: Path, config=None, cache: Path | None = None) -> dict:
    """One scene's rows: per visible ground-truth object its scores (module doc)."""
    from scipy.optimize import linear_sum_assignment

    from ipr_shapes import voxels
    from ipr_shapes.carving import (
        carve_hypotheses,
        carve_posteriors,
        carve_voxels,
        surface_views,
    )
    from ipr_shapes.config import Config
    from ipr_shapes.ground_truth import frame0_ground_truth, visible_pixel_counts
    from ipr_shapes.hypotheses import prepare_hypotheses

    config = config or Config()
    scene, objects_per_frame, space, planes = _perceive(path, cache)
    objects = objects_per_frame[0]
    generation_rng, sampler_rng = np.random.default_rng(0).spawn(2)
    views = surface_views(scene.frames, objects_per_frame, None, config.carving)
    before_choice = config.carving.enabled and config.carving.before_choice
    cpu, wall = time.process_time(), time.perf_counter()
    prepared = prepare_hypotheses(
        objects, space, planes, config.hypotheses, config.constraints, rng=generation_rng,
        carve=functools.partial(carve_hypotheses, views=views) if before_choice else None,
    )  # fmt: skip
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    posteriors = checker_posteriors(scene, objects, prepared, config, sampler_rng)
    carved = carve_posteriors(posteriors, views) if config.carving.enabled else posteriors

    poses, models, _ = frame0_ground_truth(path)
    counts, _ = visible_pixel_counts(path, poses, models)
    world_from_camera = scene.frames[0].world_from_camera
    pitch = voxels.DEFAULT_PITCH_M
    truths = [
        voxels.occupied_voxels(model, pitch, world_from_camera @ pose.camera_from_model)
        for pose, model, count in zip(poses, models, counts, strict=True)
        if count >= MIN_VISIBLE_PX
    ]
    outputs = [voxels.scanline_voxels(*p.output_mesh, pitch) for p in carved]
    checker = np.array([[_iou(o, t) for t in truths] for o in outputs]).reshape(-1, len(truths))
    matched: dict[int, int] = {}
    if checker.size:
        for row, column in zip(*linear_sum_assignment(-checker), strict=True):
            if checker[row, column] > 0:
                matched[int(column)] = int(row)
    rows = []
    for t, truth in enumerate(truths):
        row = {
            "scene": path.name,
            "checker": 0.0,
            "oracle": 0.0,
            "oracle_carved": 0.0,
            "generators": {},
            "best": None,
        }
        if t in matched:
            k = matched[t]
            posterior = posteriors[k]
            kept = [
                h
                for h, p in zip(posterior.hypotheses, posterior.probabilities, strict=True)
                if p > 0
            ]
            # Convex as inferred (a candidate carved before the choice: its hull's voxels).
            ious = [
                _iou(voxels.scanline_voxels(*h.mesh, pitch) if h.carved else h.keys(pitch), truth)
                for h in kept
            ]
            written = [carve_voxels(h.keys(pitch), posterior.object_id, views) for h in kept]
            carved_ious = [
                _iou(w if w.size else h.keys(pitch), truth)
                for w, h in zip(written, kept, strict=True)
            ]
            best = int(np.argmax(ious))
            per_generator: dict[str, float] = {}
            for h, iou in zip(kept, ious, strict=True):
                per_generator[h.generator] = max(per_generator.get(h.generator, 0.0), iou)
            volumes = [h.volume_m3 for h in kept]
            row.update(
                checker=checker[k, t],
                oracle=ious[best],
                oracle_carved=max(carved_ious),
                generators=per_generator,
                best=kept[best].generator,
                spread=max(volumes) / max(min(volumes), 1e-12),
                kept=len(kept),
            )
        rows.append(row)
    return {
        "scene": path.name,
        "rows": rows,
        "objects": len(objects),
        "cpu_s": cpu,
        "wall_s": wall,
        "generated": Counter(h.generator for i in prepared.ids for h in prepared.generated[i]),
    }


def summarise(scenes: Sequence[dict]) -> dict:
    """Suite figures from ``measure_scene`` outputs (module doc)."""
    rows = [row for scene in scenes for row in scene["rows"]]
    n = max(len(rows), 1)
    generators = sorted({g for row in rows for g in row["generators"]})
    wins = Counter(row["best"] for row in rows if row["best"])
    objects = max(sum(s["objects"] for s in scenes), 1)
    generated = Counter()
    for scene in scenes:
        generated.update(scene["generated"])
    return {
        "scenes": len(scenes),
        "truths": len(rows),
        "checker": sum(r["checker"] for r in rows) / n,
        "oracle": sum(r["oracle"] for r in rows) / n,
        "oracle_carved": sum(r.get("oracle_carved", 0.0) for r in rows) / n,
        "generators": {
            g: {
                "oracle": sum(r["generators"].get(g, 0.0) for r in rows) / n,
                "wins": wins.get(g, 0),
                "per_object": generated[g] / objects,
            }
            for g in generators
        },
        "spread": median([r["spread"] for r in rows if "spread" in r]),
        "cpu_s_per_object": sum(s["cpu_s"] for s in scenes) / objects,
        "wall_s_per_object": sum(s["wall_s"] for s in scenes) / objects,
    }


def render(summaries: dict[str, dict]) -> str:
    """The section's markdown."""
    lines = [
        "## Hypothesis ceiling (`benchmarks.hypothesis_ceiling`)",
        "",
        "The best any choice among the candidates could do: per visible ground-truth object, "
        "the best object IoU of the candidates the Collision Checker keeps (jointly feasible, "
        "convex as inferred; oracle: chosen against the ground truth), the same candidates "
        "carved by frame 0's free space as their written shapes are (oracle, carved), beside "
        "the Collision Checker's own carved output. Frame 0 only, default configuration, seed 0, 5 mm "
        "voxels; unmatched objects count 0. Per generator, `oracle IoU` is its best kept "
        "candidate's (0 for an object it kept none of: families that do not fit an object "
        "make no candidate or infeasible ones), `wins` the objects whose best candidate it "
        "made, `per object` the candidates it generated per object. `spread`: largest "
        "over smallest kept candidate volume, median over objects. Time: hypothesis "
        "generation and constraints per object, CPU (process) and wall seconds.",
        "",
    ]
    header = ["suite", "scenes", "objects", "collision checker", "oracle", "oracle, carved",
              "volume spread", "CPU s/object", "wall s/object"]  # fmt: skip
    table = [
        [name, s["scenes"], s["truths"], s["checker"], s["oracle"], s["oracle_carved"],
         f"{s['spread']:.1f}",
         f"{s['cpu_s_per_object']:.2f}", f"{s['wall_s_per_object']:.2f}"]
        for name, s in summaries.items()
    ]  # fmt: skip
    lines += [markdown_table(header, table), ""]
    header = ["suite", "generator", "oracle IoU", "wins", "per object"]
    table = [
        [name, g, v["oracle"], f"{v['wins']}/{s['truths']}", f"{v['per_object']:.1f}"]
        for name, s in summaries.items()
        for g, v in s["generators"].items()
    ]
    lines += [markdown_table(header, table), ""]
    return "\n".join(lines)


def warm_up(scenes: Sequence[Path], config=None, cache: Path | None = None) -> None:
    """Measure the first scene once and discard it: compiles (or loads) the kernels that
    generation uses, so that the timed runs count per-object work, not a one-off compile."""
    if scenes:
        measure_scene(Path(scenes[0]), config, cache)


def run(suites: dict[str, list[Path]], limit: int | None = None, cache: Path | None = None) -> str:
    """The section for ``benchmarks.run``: every scene of the suites of ``SUITES`` (frame-0
    perception pickled in ``cache`` when given)."""
    warm_up(next((list(suites[n]) for n in SUITES if suites.get(n)), []), cache=cache)
    summaries = {}
    for name in SUITES:
        scenes = list(suites.get(name, []))[:limit]
        if not scenes:
            continue
        measured = []
        for number, path in enumerate(scenes, 1):
            measured.append(measure_scene(Path(path), cache=cache))
            print(f"bench: hypotheses {name} {number}/{len(scenes)} {Path(path).name}", flush=True)
        summaries[name] = summarise(measured)
    return render(summaries)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--suite", action="append", default=[], choices=SUITES)
    parser.add_argument("--scene", action="append", default=[], type=Path)
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument("--perception-cache", type=Path, default=None)
    parser.add_argument(
        "--algorithm1-only", action="store_true", help="no structure-aware candidates (before)"
    )
    parser.add_argument(
        "--neighbour-surfaces",
        action="store_true",
        help="other objects' observed points stop the hidden extent's rays (opt-in)",
    )
    parser.add_argument(
        "--superquadric",
        type=int,
        default=None,
        metavar="N",
        help="N of the structure-aware candidates are superquadrics (default: the config's, 3; "
        "0: none, the candidates before them)",
    )
    parser.add_argument(
        "--fitted-axis",
        action="store_true",
        help="surfaces of revolution also about the axis the surface normals meet (opt-in)",
    )
    parser.add_argument(
        "--revolution-radius",
        choices=("largest", "wall_mean"),
        default=None,
        help="the revolved shapes' radius (default: the config's, largest: any point's largest "
        "distance from the axis; wall_mean: the side wall's mean distance, and the cylinder "
        "only where it is one radius; opt-in)",
    )
    parser.add_argument(
        "--unbounded-view",
        action="store_true",
        help="no bound on the hidden extent beyond the camera's view (before 2026-11-27)",
    )
    parser.add_argument(
        "--unbounded-support",
        action="store_true",
        help="no bound on the hidden extent beyond the support's seen outline (before 2026-11-27)",
    )
    parser.add_argument(
        "--silhouette-cut",
        choices=("always", "fallback", "off"),
        default=None,
        help="hypotheses cut to the object's own silhouette (default: the config's, fallback: "
        "only an object with no feasible hypothesis; always: every object; off: never, before "
        "2026-11-28)",
    )
    parser.add_argument(
        "--shrink-by-scatter",
        action="store_true",
        help="every candidate shrunk by its object's scatter, the median depth of the points "
        "inside their hull (opt-in)",
    )
    parser.add_argument(
        "--medoid-weights",
        choices=("candidate", "family", "outline", "fit", "outline-fit"),
        default=None,
        help="the Collision Checker's medoid weights (default: the config's; family: each "
        "generator family an equal share; outline: the two mixed by the object's hidden "
        "outline fraction; fit: each family's share times its candidates' likelihood of the "
        "observed points on the surface their camera sees; outline-fit: each candidate once "
        "for the seen share of the outline, fit for the hidden share; all opt-in)",
    )
    parser.add_argument(
        "--carve-before-choice",
        action="store_true",
        help="the candidates carved by frame 0's free space before the Collision Checker's "
        "medoid is chosen (CarvingConfig.before_choice; opt-in)",
    )
    parser.add_argument(
        "--medoid-self",
        choices=("leave-one-out", "nearest"),
        default=None,
        help="what a candidate's own weight adds to its medoid score where the weights are "
        "unequal (default: the config's, leave-one-out: nothing; nearest: its weight times its "
        "IoU with its nearest other candidate, opt-in)",
    )
    args = parser.parse_args(argv)
    from ipr_shapes.config import Config
    from ipr_shapes.suites import suite_scenes

    # Each flag overrides one hypothesis setting (None: the flag was not given).
    overrides = {
        "structure_share": 0.0 if args.algorithm1_only else None,
        "neighbour_surfaces": True if args.neighbour_surfaces else None,
        "superquadric_count": args.superquadric,
        "fitted_revolution_axis": True if args.fitted_axis else None,
        "revolution_radius": args.revolution_radius,
        "silhouette_cut": args.silhouette_cut,
        "shrink_by_scatter": True if args.shrink_by_scatter else None,
    }
    hypotheses = dataclasses.replace(
        Config().hypotheses, **{k: v for k, v in overrides.items() if v is not None}
    )
    # These two flags set a bound to None (unbounded), so they cannot ride on the None above.
    if args.unbounded_view:
        hypotheses = dataclasses.replace(hypotheses, outside_view_ratio=None)
    if args.unbounded_support:
        hypotheses = dataclasses.replace(hypotheses, outside_support_ratio=None)
    config = dataclasses.replace(Config(), hypotheses=hypotheses)
    # The Collision Checker's medoid settings (None: the flag was not given).
    checker = {"medoid_weights": args.medoid_weights, "medoid_self": args.medoid_self}
    config = dataclasses.replace(
        config,
        collision_checker=dataclasses.replace(
            config.collision_checker, **{k: v for k, v in checker.items() if v is not None}
        ),
    )
    if args.carve_before_choice:
        config = dataclasses.replace(
            config, carving=dataclasses.replace(config.carving, before_choice=True)
        )
    groups = {name: suite_scenes(name)[: args.limit] for name in args.suite}
    if args.scene:
        groups["scenes"] = args.scene[: args.limit]
    warm_up(next((list(v) for v in groups.values() if v), []), config, args.perception_cache)
    summaries = {}
    for name, scenes in groups.items():
        measured = []
        for path in scenes:
            measured.append(measure_scene(Path(path), config, args.perception_cache))
            rows = measured[-1]["rows"]
            print(
                f"{name} {Path(path).name}: checker "
                f"{np.mean([r['checker'] for r in rows]) if rows else 0:.3f} oracle "
                f"{np.mean([r['oracle'] for r in rows]) if rows else 0:.3f} carved "
                f"{np.mean([r['oracle_carved'] for r in rows]) if rows else 0:.3f} "
                f"cpu/object {measured[-1]['cpu_s'] / max(measured[-1]['objects'], 1):.2f} s",
                flush=True,
            )
        summaries[name] = summarise(measured)
    print(render(summaries))
    return 0


if __name__ == "__main__":
    sys.exit(main())
