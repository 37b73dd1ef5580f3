"""Where the hypothesis ceiling's gap is (issue 28): an analysis, not inference.

    python -m benchmarks.ceiling_gap --scene DIR ... [--perception-cache DIR] [--json OUT]

The ceiling (``benchmarks.hypothesis_ceiling``) is the best object IoU among the candidates
the Collision Checker keeps. Per visible ground-truth object (>= 100 pixels in frame 0) this
measures the levels between 1 and that ceiling, each the mean over objects (5 mm voxels):

- ``pose cap``: the true mesh voxelised against itself moved by the error perception makes
  (the median distance of the object's observed points, ground-truth mask, from the true
  surface, in 6 directions +-x, +-y, +-z, mean): no candidate placed from the observed
  points can expect better;
- ``hull cap``: the true shape's convex hull against the true shape (no convex candidate
  beats it);
- ``gt generated``: the best candidate generated (feasible or not) from frame 0 perceived with
  the ground-truth visible masks in place of the segmentation (planes, supervoxels, facets and
  free space as perception computes them; the mask's pixels within the support clearance of
  the support are dropped, as perception drops an object's lowest centimetre);
- ``generated``: the same with the segmentation as is (objects matched to the ground truth
  one-to-one by the Hungarian assignment on the Collision Checker's carved output, as the
  ceiling bench does; unmatched objects 0);
- ``unary``: the best the unary constraints keep; ``oracle``: the best the Collision
  Checker keeps (jointly feasible): the ceiling.

So hull cap - gt generated is the candidates' share, gt generated - generated perception's,
generated - oracle the constraints'. For the oracle's candidate, 1 - IoU splits exactly over
the voxels of the union: ``concave`` (candidate voxels in the true hull outside the shape:
unavoidable for a convex candidate), ``leak`` (candidate voxels outside the true hull that
frame 0's free space calls free), ``extra`` (the rest of the candidate's excess: hidden space
it should not fill), ``missing free`` (true voxels the free space calls free: perception), and
``missing`` (true voxels the candidate lacks: too small). Rows carry the object's name, its
visible fraction (``visib_fract``) and which generator made the oracle candidate.

The ground truth is read here (benchmark analysis); inference never reads it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pickle
import sys
from pathlib import Path

import numpy as np

from benchmarks.common import markdown_table, median
from benchmarks.hypothesis_ceiling import MIN_VISIBLE_PX, _iou, _perceive, checker_posteriors


def _perceive_true_masks(path: Path, cache: Path | None):
    """Frame 0's objects from the ground-truth visible masks (module doc), free space, planes."""
    from ipr_shapes.config import Config
    from ipr_shapes.perception import partial_objects, workspace_grid
    from ipr_shapes.perception.free_space import observe_space
    from ipr_shapes.perception.robot import robot_pixels
    from ipr_shapes.perception.segmentation import segment_frame
    from ipr_shapes.scene import load_scene
    from ipr_shapes.segmentation_metrics import ground_truth_masks

    stored = cache / f"gtmask-{path.parent.name}-{path.name}.pkl" if cache else None
    if stored is not None and stored.exists():
        return pickle.loads(stored.read_bytes())
    config = Config().perception
    scene = load_scene(path)
    scene = dataclasses.replace(scene, frames=scene.frames[:1], pushes=())
    frame = scene.frames[0]
    points = frame.points_world()
    segmentation = segment_frame(
        frame, pushes=(), pusher=scene.pusher, config=config, points_world=points
    )
    labels, _, _ = ground_truth_masks(path, frame.index, frame=frame)
    labels = labels.astype(np.int32).copy()
    for plane in segmentation.planes:
        if plane.kind == "support":
            height = points.reshape(-1, 3) @ np.asarray(plane.normal, float) + plane.offset
            labels.reshape(-1)[height < config.support.clearance_m] = 0
    objects, _ = partial_objects(frame, segmentation, labels, config)
    grid = workspace_grid([objects], config)
    space = observe_space(
        frame.depth_m,
        frame.K,
        frame.world_from_camera,
        grid,
        surface_margin_m=config.free_space.surface_margin_m,
        ignore_mask=robot_pixels(frame, (), scene.pusher, config),
    )
    out = (scene, (objects,), space, segmentation.planes)
    if stored is not None:
        stored.parent.mkdir(parents=True, exist_ok=True)
        stored.write_bytes(pickle.dumps(out))
    return out


def _candidates(perceived, config):
    """Prepared hypotheses, posteriors and carved outputs of one perception of frame 0."""
    from ipr_shapes.carving import carve_posteriors, surface_views
    from ipr_shapes.hypotheses import prepare_hypotheses

    scene, objects_per_frame, space, planes = perceived
    objects = objects_per_frame[0]
    generation_rng, sampler_rng = np.random.default_rng(0).spawn(2)
    prepared = prepare_hypotheses(
        objects, space, planes, config.hypotheses, config.constraints, rng=generation_rng
    )
    posteriors = checker_posteriors(scene, objects, prepared, config, sampler_rng)
    views = surface_views(scene.frames, objects_per_frame, None, config.carving)
    carved = carve_posteriors(posteriors, views) if config.carving.enabled else posteriors
    return prepared, posteriors, carved


def _levels(prepared, posterior, truth, pitch):
    """Best IoU among the generated, unary-feasible and kept candidates of one object, and the
    kept best candidate."""
    generated = prepared.generated[posterior.object_id]
    feasible = set(prepared.candidates[posterior.object_id])
    ious = np.array([_iou(h.keys(pitch), truth) for h in generated])
    kept = [
        k for k, p in enumerate(posterior.probabilities) if p > 0 and k < len(generated)
    ] or list(feasible)
    unary = [k for k in range(len(generated)) if k in feasible]
    best_kept = max(kept, key=lambda k: ious[k])
    return (
        float(ious.max()),
        float(ious[unary].max()) if unary else 0.0,
        float(ious[best_kept]),
        generated[best_kept],
        generated[int(np.argmax(ious))],
    )


def _split(candidate: np.ndarray, truth: np.ndarray, hull: np.ndarray, space, pitch) -> dict:
    """1 - IoU of a candidate split over the union's voxels (module doc)."""
    from ipr_shapes import voxels
    from ipr_shapes.perception.free_space import FREE

    union = voxels.union(candidate, truth)
    n = max(len(union), 1)
    extra = np.setdiff1d(candidate, truth, assume_unique=True)
    missing = np.setdiff1d(truth, candidate, assume_unique=True)
    concave = np.intersect1d(extra, hull, assume_unique=True)
    outside = np.setdiff1d(extra, hull, assume_unique=True)
    leak = (
        int((space.state_at(voxels.centres(outside, pitch)) == FREE).sum())
        if space is not None
        else 0
    )
    missing_free = (
        int((space.state_at(voxels.centres(missing, pitch)) == FREE).sum())
        if space is not None
        else 0
    )
    return {
        "concave": len(concave) / n,
        "leak": leak / n,
        "extra": (len(outside) - leak) / n,
        "missing_free": missing_free / n,
        "missing": (len(missing) - missing_free) / n,
    }


def _surface_error(points: np.ndarray, mesh) -> float:
    """Median distance (m) of observed points from a mesh's surface (dense surface samples)."""
    from scipy.spatial import cKDTree

    samples, _ = __import__("trimesh").sample.sample_surface_even(mesh, 40000, seed=0)
    if len(points) == 0 or len(samples) == 0:
        return 0.0
    distances, _ = cKDTree(samples).query(points)
    return float(np.median(distances))


def measure_scene(path: Path, cache: Path | None = None, wide: int = 0) -> list[dict]:
    """One scene's rows, one per visible ground-truth object (module doc)."""
    from scipy.optimize import linear_sum_assignment

    from ipr_shapes import voxels
    from ipr_shapes.config import Config
    from ipr_shapes.ground_truth import frame0_ground_truth

    config = Config()
    pitch = voxels.DEFAULT_PITCH_M
    as_is = _perceive(path, cache)
    true_masks = _perceive_true_masks(path, cache)
    scene = as_is[0]
    poses, models, models_dir = frame0_ground_truth(path)
    info = json.loads((path / "scene_gt_info.json").read_text())["0"]
    names = json.loads((models_dir / "models_info.json").read_text())
    world_from_camera = scene.frames[0].world_from_camera
    placed = []
    for pose, model in zip(poses, models, strict=True):
        mesh = model.copy()
        mesh.apply_transform(world_from_camera @ pose.camera_from_model)
        placed.append(mesh)
    visible = [k for k, entry in enumerate(info) if entry["px_count_visib"] >= MIN_VISIBLE_PX]
    truths = {
        k: voxels.scanline_voxels(placed[k].vertices, placed[k].faces, pitch) for k in visible
    }

    results = {}
    for name, perceived in (("as_is", as_is), ("true_masks", true_masks)):
        prepared, posteriors, carved = _candidates(perceived, config)
        outputs = [voxels.scanline_voxels(*p.output_mesh, pitch) for p in carved]
        if name == "true_masks":  # object id = ground-truth position + 1
            matched = {
                k: i for i, p in enumerate(posteriors) for k in visible if p.object_id == k + 1
            }
        else:
            checker = np.array([[_iou(o, truths[k]) for k in visible] for o in outputs])
            checker = checker.reshape(-1, len(visible))
            matched = {}
            if checker.size:
                for row, column in zip(*linear_sum_assignment(-checker), strict=True):
                    if checker[row, column] > 0:
                        matched[visible[column]] = int(row)
        results[name] = (prepared, posteriors, outputs, matched, perceived)
    wide_best: dict[int, float] = {}
    if wide:  # the as-is objects' best among ``wide`` candidates (sampling vs families)
        from ipr_shapes.hypotheses import generate_hypotheses

        wide_config = dataclasses.replace(config.hypotheses, count=wide)
        _, objects_per_frame, space, planes = as_is
        by_id = {obj.id: obj for obj in objects_per_frame[0]}
        prepared, posteriors, _, matched, _ = results["as_is"]
        for k, i in matched.items():
            obj = by_id[posteriors[i].object_id]
            hyps = generate_hypotheses(obj, space, planes, wide_config, np.random.default_rng(1))
            wide_best[k] = max(_iou(h.keys(pitch), truths[k]) for h in hyps)

    rows = []
    for k in visible:
        truth = truths[k]
        hull_mesh = placed[k].convex_hull
        hull = voxels.scanline_voxels(hull_mesh.vertices, hull_mesh.faces, pitch)
        row = {
            "scene": f"{path.parent.name}/{path.name}",
            "object": names[str(poses[k].obj_id)].get("name", str(poses[k].obj_id)),
            "visib_fract": float(info[k]["visib_fract"]),
            "hull_cap": _iou(hull, truth),
        }
        if wide:
            row["wide_generated"] = wide_best.get(k, 0.0)
        # Perception's placement error: observed points (true mask) from the true surface.
        prepared, posteriors, outputs, matched, perceived = results["true_masks"]
        objects = {obj.id: obj for obj in perceived[1][0]}
        observed = objects.get(k + 1)
        error = _surface_error(np.asarray(observed.points), placed[k]) if observed else 0.0
        row["surface_error_m"] = error
        shifted = []
        for axis in range(3):
            for sign in (1.0, -1.0):
                moved = placed[k].vertices + sign * max(error, 1e-6) * np.eye(3)[axis]
                shifted.append(_iou(voxels.scanline_voxels(moved, placed[k].faces, pitch), truth))
        row["pose_cap"] = float(np.mean(shifted))
        for name in ("true_masks", "as_is"):
            prepared, posteriors, outputs, matched, perceived = results[name]
            prefix = "gt_" if name == "true_masks" else ""
            if k not in matched:
                row.update({f"{prefix}generated": 0.0, f"{prefix}unary": 0.0,
                            f"{prefix}oracle": 0.0, f"{prefix}checker": 0.0})  # fmt: skip
                continue
            posterior = posteriors[matched[k]]
            generated, unary, oracle, best, best_generated = _levels(
                prepared, posterior, truth, pitch
            )
            row.update({
                f"{prefix}generated": generated,
                f"{prefix}unary": unary,
                f"{prefix}oracle": oracle,
                f"{prefix}checker": _iou(outputs[matched[k]], truth),
                f"{prefix}generator": best.generator,
            })  # fmt: skip
            if name == "as_is":
                space = perceived[2]
                row["split"] = _split(best.keys(pitch), truth, hull, space, pitch)
                row["generated_split"] = _split(
                    best_generated.keys(pitch), truth, hull, space, pitch
                )
                row["generated_generator"] = best_generated.generator
                for key, chosen in (("split", best), ("generated_split", best_generated)):
                    candidate = chosen.keys(pitch)
                    common = voxels.intersection_count(candidate, truth)
                    row[key]["precision"] = common / max(len(candidate), 1)
                    row[key]["recall"] = common / max(len(truth), 1)
        rows.append(row)
    return rows


LEVELS = (
    "pose_cap",
    "hull_cap",
    "wide_generated",
    "gt_generated",
    "generated",
    "unary",
    "oracle",
    "checker",
)
SPLITS = ("concave", "leak", "extra", "missing_free", "missing")


def render(rows: list[dict]) -> str:
    """Markdown tables: the levels (means and medians), the oracle's 1 - IoU split, and both
    by visible fraction and by object."""
    lines = []
    header = ["objects", *LEVELS, "gt oracle", "gt checker"]
    mean = [float(np.mean([r.get(level, 0.0) for r in rows])) for level in LEVELS]
    med = [median([r.get(level, 0.0) for r in rows]) for level in LEVELS]
    gt = [float(np.mean([r.get("gt_oracle", 0.0) for r in rows])),
          float(np.mean([r.get("gt_checker", 0.0) for r in rows]))]  # fmt: skip
    gt_med = [median([r.get("gt_oracle", 0.0) for r in rows]),
              median([r.get("gt_checker", 0.0) for r in rows])]  # fmt: skip
    lines += [markdown_table(header, [[f"{len(rows)} (mean)", *mean, *gt],
                                      [f"{len(rows)} (median)", *med, *gt_med]]), ""]  # fmt: skip
    split_rows = [r for r in rows if "split" in r]
    header = ["group", "objects", "IoU", "1 - IoU", *SPLITS, "precision", "recall"]

    def group(label: str, members: list[dict], key: str = "split", level: str = "oracle") -> list:
        if not members:
            return [label, 0, *([float("nan")] * (len(header) - 2))]
        return [
            label,
            len(members),
            float(np.mean([r[level] for r in members])),
            float(np.mean([1 - r[level] for r in members])),
            *[float(np.mean([r[key][s] for r in members])) for s in SPLITS],
            float(np.mean([r[key]["precision"] for r in members])),
            float(np.mean([r[key]["recall"] for r in members])),
        ]

    for key, level in (("split", "oracle"), ("generated_split", "generated")):
        table = [group(f"{level}: all matched", split_rows, key, level)]
        for low, high in ((0.0, 0.3), (0.3, 0.6), (0.6, 0.8), (0.8, 1.01)):
            members = [r for r in split_rows if low <= r["visib_fract"] < high]
            table.append(group(f"visible {low:.1f}-{min(high, 1.0):.1f}", members, key, level))
        lines += [markdown_table(header, table), ""]
    by_object: dict[str, list[dict]] = {}
    for r in split_rows:
        by_object.setdefault(r["object"], []).append(r)
    table = [group(name, members) for name, members in sorted(by_object.items())]
    lines += [markdown_table(header, table), ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", action="append", default=[], type=Path, required=True)
    parser.add_argument("--perception-cache", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    parser.add_argument("--wide", type=int, default=0, help="also the best of this many")
    args = parser.parse_args(argv)
    rows = []
    for path in args.scene:
        scene_rows = measure_scene(path, args.perception_cache, args.wide)
        rows += scene_rows
        print(
            f"{path.name}: "
            + " ".join(
                f"{lv} {np.mean([r.get(lv, 0.0) for r in scene_rows]):.3f}" for lv in LEVELS
            ),
            flush=True,
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    print(render(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
