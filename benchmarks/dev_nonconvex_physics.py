"""Development measurement: does convex physics plus carving lose anything against simulating
non-convex candidates decomposed into convex pieces (issue 28 item 2; docs/DESIGN_NOTES.md,
"Convex physics, then carving"; figures in docs/experiments/2026-11-26-nonconvex-physics.md)?

Usage: ``python -m benchmarks.dev_nonconvex_physics [--seed 7200] [--count 12] [--scenes DIR]
[--only NAMES] [--containers-only] [--threshold 0.05] [--out FILE]`` (one JSON line per scene),
then ``--summarise FILE...`` for the tables.

Development dynamic scenes whose pool holds the bowl, the mug and four cups
(``benchmarks.common.development_scenes(containers=True)``; seed 7200, never a benchmark
suite's). Per scene: perception, the objects' candidates (as ``benchmarks.dev_inference``), then

1. Convexity of the candidates: each candidate's mesh volume against its convex hull's.
2. Their non-convex geometry: a candidate carved by the space frame 0 saw empty
   (``ipr_shapes.carving``, what the result writes) is the only non-convex form a candidate
   has; its concavity is the share of the voxels of the carved shape's hull that carving left
   out. Of the bowl's, the mug's and the cups' candidates (``--containers-only``; else every
   object's), the Collision Checker's choice and the most concave others (``--per-object`` in
   all) with concavity >= ``--concave`` are decomposed by CoACD (the export's
   ``collision_pieces``: at most 8 pieces, seed 0, threshold ``--threshold``, the export's
   0.05 by default), timed.
3. Stability tests (the sampler's distance: the drop of the centre of mass over
   ``stability_s``, ``exp(-alpha d)`` its exploration weight) of each such candidate among its
   neighbours' Collision-Checker shapes (static), as (A) the candidate's hull (what inference
   simulates), (B) the carved shape's hull, (C) the carved shape's CoACD pieces (one rigid
   body); and of each neighbour's candidates with the concave object's shape as static
   context, A against C (an object resting in a bowl).
4. Push replay of the Collision Checker's joint model and of ``--joint`` random joint models
   with every concave object as A, B or C: each object's final pose difference (mean vertex
   distance, m) and the seconds per simulated sample.

Benchmark code may read ground truth; here it only names the matched YCB object of each
concave candidate. The synthetic scenes' own physics collides every object's convex hull
(``ipr_shapes.synth.catalogue``), so their observed motion is a hull's motion; the script
reports how much the physics would change, not which is right.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

INFINITE_DROP = 1.0  # m: a flung or exploded test counts as this far for the differences
#: Perception and candidates per scene, kept between runs (development cache, outside the scenes).
CACHE = Path("/tmp/ipr-nonconvex-cache")


def _log(*parts) -> None:
    print(time.strftime("%H:%M:%S"), *parts, file=sys.stderr, flush=True)


def _volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    tri = vertices[faces]
    return float(abs(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6)


def _hull_volume(vertices: np.ndarray) -> float:
    from scipy.spatial import ConvexHull

    return float(ConvexHull(vertices).volume)


def _pieces(vertices: np.ndarray, faces: np.ndarray, threshold: float) -> tuple[list, float]:
    """CoACD pieces (list of (vertices, faces) world) of a closed mesh and the seconds taken."""
    import trimesh

    from ipr_shapes.export.model import ExportConfig, collision_pieces

    start = time.perf_counter()
    pieces = collision_pieces(
        trimesh.Trimesh(vertices, faces, process=False),
        ExportConfig(collision="coacd", coacd_threshold=threshold),
    )
    seconds = time.perf_counter() - start
    return [(np.asarray(p.vertices), np.asarray(p.faces)) for p in pieces], seconds


def _bodies(shape, group: int, dynamic: bool = True):
    """Physics bodies of one shape: (vertices, faces) one hull, or a list of pieces welded."""
    from ipr_shapes.physics import Body

    if isinstance(shape, list):
        return [Body(v, f, dynamic=dynamic, rigid_group=group if dynamic else -1) for v, f in shape]
    return [Body(shape[0], shape[1], dynamic=dynamic)]


def _drop(target, context: list, planes, physics) -> float:
    """The stability test's drop (m) of ``target`` (a shape as ``_bodies``) among static
    ``context`` shapes."""
    from ipr_shapes.physics import build_world

    bodies = [b for shape in context for b in _bodies(shape, -1, dynamic=False)]
    first = len(bodies)
    bodies += _bodies(target, 0)
    world = build_world(bodies, planes, physics)
    world.settle(physics.stability_s)
    return float(min(world.drops()[first], INFINITE_DROP))


def _replay(shapes: list, planes, physics, pusher, pushes):
    """Final (n, 4, 4) poses of each object (first body of each) after settling and the
    pushes, and the seconds taken; None poses when the world exploded."""
    from ipr_shapes.physics import build_world

    bodies, first = [], []
    for k, shape in enumerate(shapes):
        first.append(len(bodies))
        bodies += _bodies(shape, k)
    start = time.perf_counter()
    world = build_world(bodies, planes, physics, pusher=pusher)
    world.settle()
    for push in pushes:
        world.push(push)
    seconds = time.perf_counter() - start
    if world.exploded:
        return None, seconds
    return world.poses()[first], seconds


def _pose_gap(poses_a, poses_b, vertices: np.ndarray) -> float:
    """Mean distance (m) between ``vertices`` moved by two poses."""
    if poses_a is None or poses_b is None:
        return float("inf")
    a = vertices @ poses_a[:3, :3].T + poses_a[:3, 3]
    b = vertices @ poses_b[:3, :3].T + poses_b[:3, 3]
    return float(np.linalg.norm(a - b, axis=1).mean())


def measure_scene(
    path: Path, concave: float, joint: int, per_object: int, threshold: float,
    containers_only: bool,
) -> dict:  # fmt: skip
    from scipy.optimize import linear_sum_assignment

    from benchmarks.common import CONTAINER_OBJECTS
    from ipr_shapes import voxels
    from ipr_shapes.carving import CarvingConfig, carve_voxels, surface_views, voxel_surface
    from ipr_shapes.collision_checker import uniform_posteriors
    from ipr_shapes.geometry.convex import convex_mesh
    from ipr_shapes.ground_truth import frame0_ground_truth
    from ipr_shapes.hypotheses import prepare_hypotheses
    from ipr_shapes.inference import InferenceConfig
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.scene import load_scene

    scene = load_scene(path)
    cache = CACHE / f"{path.parent.name}-{path.name}.pkl"
    if cache.exists():
        perception, prepared = pickle.loads(cache.read_bytes())
    else:
        perception = perceive_scene(scene)
        prepared = prepare_hypotheses(
            perception.objects[0], perception.free_space[0], perception.planes[0],
            rng=np.random.default_rng(0),
        )  # fmt: skip
        CACHE.mkdir(parents=True, exist_ok=True)
        cache.write_bytes(pickle.dumps((perception, prepared)))
    _log(path.name, "perceived")
    planes = perception.planes[0]
    physics = InferenceConfig().physics
    alpha = InferenceConfig().stability_alpha_per_m
    checker = uniform_posteriors(prepared)
    candidates = [list(p.hypotheses) for p in checker]
    best = [p.best for p in checker]
    views = surface_views(scene.frames[:1], perception.objects[:1], None, CarvingConfig())

    # Ground-truth names of the matched objects (benchmark only).
    poses, models, folder = frame0_ground_truth(path)
    info = json.loads((folder / "models_info.json").read_text())
    world_from_camera = scene.frames[0].world_from_camera
    truths = [
        voxels.occupied_voxels(
            model, voxels.DEFAULT_PITCH_M, world_from_camera @ p.camera_from_model
        )
        for p, model in zip(poses, models, strict=True)
    ]
    ious = np.array(
        [
            [voxels.intersection_count(p.best_hypothesis.keys(), t)
             / max(p.best_hypothesis.keys().size + t.size
                   - voxels.intersection_count(p.best_hypothesis.keys(), t), 1)
             for t in truths]
            for p in checker
        ]
    )  # fmt: skip
    names = {}
    if ious.size:
        for row, column in zip(*linear_sum_assignment(-ious), strict=True):
            if ious[row, column] > 0:
                names[row] = info.get(str(poses[column].obj_id), {}).get("name", "?")

    out = {"scene": path.name, "candidates": 0, "max_hull_gap": 0.0, "concave": [],
           "stability": [], "context": [], "replay": []}  # fmt: skip
    carved: dict[tuple[int, int], tuple] = {}
    meshes: dict[tuple[int, int], tuple] = {}
    for i, object_candidates in enumerate(candidates):
        object_id = checker[i].object_id
        for j, h in enumerate(object_candidates):
            out["candidates"] += 1
            hull = _hull_volume(h.vertices)
            out["max_hull_gap"] = max(out["max_hull_gap"], 1 - _volume(h.vertices, h.faces) / hull)
            keys = h.keys(voxels.DEFAULT_PITCH_M)
            kept = carve_voxels(keys, object_id, views)
            if kept.size < 8:
                continue
            mesh = voxel_surface(kept)
            # In voxels, so that the staircase of a voxel surface is no concavity: the voxels
            # whose centres are in the hull of the carved voxels' centres (grown by 0.1 mm,
            # so that centres on its faces count) that carving left out.
            centres = voxels.centres(kept, voxels.DEFAULT_PITCH_M)
            middle = centres.mean(axis=0)
            hull = convex_mesh(
                middle + (centres - middle) * (1 + 1e-4 / np.ptp(centres, axis=0).max())
            )
            if hull is None:
                continue
            filled = voxels.scanline_voxels(hull[0], hull[1], voxels.DEFAULT_PITCH_M)
            concavity = 1 - kept.size / max(filled.size, kept.size)
            record = {"object": i, "name": names.get(i, "unmatched"), "candidate": j,
                      "generator": h.generator, "carved_share": kept.size / max(keys.size, 1),
                      "concavity": concavity}  # fmt: skip
            meshes[(i, j)] = mesh
            out["concave"].append(record)
    # CoACD takes seconds to a minute per shape: the Collision Checker's choice of each object
    # and its ``per_object`` - 1 most concave other candidates.
    for i in range(len(candidates)):
        if containers_only and names.get(i) not in CONTAINER_OBJECTS:
            continue
        records = [r for r in out["concave"] if r["object"] == i and r["concavity"] >= concave]
        records.sort(key=lambda r: (r["candidate"] != best[i], -r["concavity"]))
        for record in records[:per_object]:
            j = record["candidate"]
            pieces, seconds = _pieces(*meshes[(i, j)], threshold)
            record.update(pieces=len(pieces), coacd_s=seconds)
            carved[(i, j)] = (meshes[(i, j)], pieces)
            _log(path.name, f"object {i} ({record['name']}) candidate {j}: concavity "
                 f"{record['concavity']:.2f}, {len(pieces)} pieces in {seconds:.1f} s")  # fmt: skip

    _log(path.name, f"carved, {len(carved)} concave")
    context_of = {
        i: [
            (candidates[k][best[k]].vertices, candidates[k][best[k]].faces)
            for k in range(len(candidates))
            if k != i
        ]
        for i in range(len(candidates))
    }
    for (i, j), (mesh, pieces) in carved.items():
        h = candidates[i][j]
        drops = {
            "A": _drop((h.vertices, h.faces), context_of[i], planes, physics),
            "B": _drop(mesh, context_of[i], planes, physics),
            "C": _drop(pieces, context_of[i], planes, physics),
        }
        out["stability"].append({"object": i, "candidate": j, **drops,
                                 "weights": {k: float(np.exp(-alpha * d))
                                             for k, d in drops.items()}})  # fmt: skip
    _log(path.name, "stability done")
    # Neighbours tested against a concave object's chosen shape: hull (A) or pieces (C).
    for (i, j), (_, pieces) in carved.items():
        if j != best[i]:
            continue
        h = candidates[i][j]
        for k in range(len(candidates)):
            near = candidates[k][best[k]].bounds
            if (
                k == i
                or np.any(near[0] > h.bounds[1] + 0.02)
                or np.any(h.bounds[0] > near[1] + 0.02)
            ):
                continue  # not a neighbour: nothing of it touches the concave object
            others = [c for c in context_of[k] if c[0] is not h.vertices]
            for m, g in enumerate(candidates[k]):
                a = _drop((g.vertices, g.faces), [*others, (h.vertices, h.faces)], planes, physics)
                c = _drop((g.vertices, g.faces), [*others, pieces], planes, physics)
                out["context"].append({"object": k, "candidate": m, "beside": i, "A": a, "C": c})

    _log(path.name, f"context done ({len(out['context'])})")
    # Push replay: the checker's joint model and random ones.
    rng = np.random.default_rng(0)
    choices = [tuple(best)] + [
        tuple(int(rng.integers(len(c))) for c in candidates) for _ in range(joint)
    ]
    for choice in choices:
        concave_here = [i for i, j in enumerate(choice) if (i, j) in carved]
        if not concave_here or not scene.pushes:
            continue
        runs = {}
        for label in ("A", "B", "C"):
            shapes = []
            for i, j in enumerate(choice):
                h = candidates[i][j]
                if (i, j) in carved and label != "A":
                    mesh, pieces = carved[(i, j)]
                    shapes.append(mesh if label == "B" else pieces)
                else:
                    shapes.append((h.vertices, h.faces))
            runs[label] = _replay(shapes, planes, physics, scene.pusher, scene.pushes)
        gaps = {}
        for i, j in enumerate(choice):
            vertices = candidates[i][j].vertices
            start = np.eye(4)
            a, b, c = (runs[label][0] for label in "ABC")
            gaps[i] = {
                "concave": i in concave_here,
                "moved_A": _pose_gap(a[i] if a is not None else None, start, vertices),
                "A_C": _pose_gap(None if a is None else a[i], None if c is None else c[i],
                                 vertices),
                "B_C": _pose_gap(None if b is None else b[i], None if c is None else c[i],
                                 vertices),
            }  # fmt: skip
        out["replay"].append({"choice": list(choice), "objects": gaps,
                              "seconds": {k: v[1] for k, v in runs.items()}})  # fmt: skip
    return out


def summarise(records: list[dict], alpha: float = 100.0) -> list[str]:
    """Table lines of the measurement records (``measure_scene``'s, one per scene)."""
    from benchmarks.common import CONTAINER_OBJECTS

    lines = []
    candidates = sum(r["candidates"] for r in records)
    gap = max(r["max_hull_gap"] for r in records)
    lines.append(f"scenes {len(records)}, candidates {candidates}, "
                 f"largest 1 - volume / hull volume {gap:.2e}")  # fmt: skip
    rows = [c for r in records for c in r["concave"]]
    for label, keep in (("containers", True), ("other objects", False)):
        values = np.array(
            [c["concavity"] for c in rows if (c["name"] in CONTAINER_OBJECTS) == keep]
        )
        if values.size:
            lines.append(f"carved concavity, {label}: {values.size} candidates, median "
                         f"{np.median(values):.2f}, >= 0.1: {np.mean(values >= 0.1):.0%}, "
                         f">= 0.3: {np.mean(values >= 0.3):.0%}")  # fmt: skip
    decomposed = [c for c in rows if "pieces" in c]
    if decomposed:
        seconds = np.array([c["coacd_s"] for c in decomposed])
        pieces = np.array([c["pieces"] for c in decomposed])
        lines.append(f"CoACD: {len(decomposed)} shapes, pieces median {np.median(pieces):g} "
                     f"(max {pieces.max()}), seconds median {np.median(seconds):.1f} "
                     f"(max {seconds.max():.1f})")  # fmt: skip
    stability = [s for r in records for s in r["stability"]]
    if stability:
        a, b, c = (np.array([s[k] for s in stability]) for k in "ABC")
        for label, x, y in (("A (hull) vs C (pieces)", a, c), ("B (carved hull) vs C", b, c)):
            dw = np.abs(np.exp(-alpha * x) - np.exp(-alpha * y))
            lines.append(f"own stability, {label}: {len(x)} tests, |drop diff| median "
                         f"{np.median(np.abs(x - y)) * 1000:.1f} mm (max "
                         f"{np.abs(x - y).max() * 1000:.1f} mm), |weight diff| mean {dw.mean():.3f}, "
                         f"> 0.1: {int((dw > 0.1).sum())}")  # fmt: skip
    context = [s for r in records for s in r["context"]]
    if context:
        a, c = (np.array([s[k] for s in context]) for k in "AC")
        dw = np.abs(np.exp(-alpha * a) - np.exp(-alpha * c))
        lines.append(f"neighbours' stability beside the container, A vs C: {len(a)} tests, "
                     f"|drop diff| > 1 mm: {int((np.abs(a - c) > 0.001).sum())}, |weight diff| "
                     f"mean {dw.mean():.4f}, > 0.1: {int((dw > 0.1).sum())}")  # fmt: skip
    replay = [x for r in records for x in r["replay"]]
    if replay:
        for label, concave in (("containers", True), ("other objects", False)):
            gaps = [o for x in replay for o in x["objects"].values() if o["concave"] == concave]
            if not gaps:
                continue
            moved = np.array([o["moved_A"] for o in gaps])
            ac = np.array([o["A_C"] for o in gaps])
            bc = np.array([o["B_C"] for o in gaps])
            lines.append(f"push replay, {label}: {len(gaps)} objects in {len(replay)} joint "
                         f"models, moved (A) median {np.median(moved) * 1000:.1f} mm; "
                         f"A vs C median {np.median(ac) * 1000:.1f} mm (max {ac.max() * 1000:.1f}); "
                         f"B vs C median {np.median(bc) * 1000:.1f} mm (max {bc.max() * 1000:.1f})")  # fmt: skip
        seconds = {k: np.array([x["seconds"][k] for x in replay]) for k in "ABC"}
        lines.append("push replay seconds per joint model: " + ", ".join(
            f"{k} {v.mean():.2f}" for k, v in seconds.items()))  # fmt: skip
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=7200)
    parser.add_argument("--count", type=int, default=12)
    parser.add_argument("--scenes", type=Path, default=Path("/tmp/ipr-dev-perception"))
    parser.add_argument("--only", type=str, default="", help="comma-separated scene names")
    parser.add_argument("--concave", type=float, default=0.1)
    parser.add_argument("--joint", type=int, default=2)
    parser.add_argument("--per-object", type=int, default=2)
    parser.add_argument("--threshold", type=float, default=0.05, help="CoACD's concavity")
    parser.add_argument(
        "--containers-only",
        action="store_true",
        help="decompose only the bowl's, the mug's and the cups' candidates",
    )
    parser.add_argument("--out", type=Path, default=Path("/tmp/ipr-nonconvex.jsonl"))
    parser.add_argument("--summarise", type=Path, nargs="*", help="print the tables of records")
    args = parser.parse_args(argv)
    if args.summarise:
        records = [json.loads(line) for p in args.summarise for line in p.read_text().splitlines()]
        print("\n".join(summarise(records)))
        return 0
    from benchmarks.common import development_scenes

    only = set(filter(None, args.only.split(",")))
    paths = development_scenes(args.scenes, args.seed, args.count, containers=True)
    with args.out.open("a") as handle:
        for path in paths:
            if only and path.name not in only:
                continue
            start = time.perf_counter()
            record = measure_scene(
                path, args.concave, args.joint, args.per_object, args.threshold,
                args.containers_only,
            )  # fmt: skip
            record["seconds"] = time.perf_counter() - start
            handle.write(json.dumps(record) + "\n")
            handle.flush()
            print(f"{path.name}: {len(record['concave'])} carved, "
                  f"{sum('pieces' in c for c in record['concave'])} concave, "
                  f"{record['seconds']:.0f} s", flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
