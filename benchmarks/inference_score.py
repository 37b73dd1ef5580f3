"""Inference benchmark, step 2 of 3: score the kept runs against the ground truth.

Functions of the run records of ``benchmarks.inference_run`` (and the result directories and
ground truth they point to) to rows of figures, and of rows to the statistics the page shows;
nothing here runs a method. A scene's row (``score_run``) has its object- and scene-space IoU,
F1, precision and recall (``ipr_shapes.metrics.evaluate``, 5 mm voxels, objects visible in frame 0),
the seconds per object of each stage, the samples drawn, the hypotheses' volume spreads and the
best-hypothesis ceiling (``best_hypothesis_iou``). A run that failed, or whose evaluation
raises, scores 0 (``failed_row``). Time per object divides a scene's seconds by its number of
inferred objects.
"""

from __future__ import annotations

import math
import traceback
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from benchmarks.common import median
from benchmarks.inference_run import RESULT, error_text

#: Per-scene figures that are 0 when the scene failed.
SCORE_KEYS = tuple(
    f"{space}_{figure}"
    for space in ("object", "scene")
    for figure in ("iou", "f1", "precision", "recall")
)


def failed_row(scene: str, method: str, error: str) -> dict:
    """The row of a scene whose inference or evaluation failed: every score 0, no timings."""
    return {
        "scene": scene,
        "method": method,
        "error": error,
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


def best_hypothesis_iou(scene: Path, result, evaluation) -> float:
    """The ceiling of choosing among the result's written hypotheses: over the visible
    ground-truth objects of ``evaluation``, the mean of the best object IoU any hypothesis of
    the matched prediction reaches (0 when unmatched; the best mesh when an object lists no
    hypotheses), at the evaluation's voxel pitch. For the Collision Checker the written
    hypotheses are every jointly feasible candidate, so this bounds what any inference could
    pick from them; for the physics-based methods, the candidates their samples visited."""
    from ipr_shapes import voxels
    from ipr_shapes.ground_truth import frame0_ground_truth
    from ipr_shapes.result import read_mesh

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


def score_run(record: dict) -> dict:
    """One row of figures for a run record (``inference_run.run_scene``): its result evaluated
    against the scene's ground truth, its timings per object; ``failed_row`` when the run
    failed or its evaluation raises."""
    from ipr_shapes.metrics import evaluate
    from ipr_shapes.result import load_result

    scene = Path(record["scene"])
    method = record["method"]
    if record.get("error"):
        return failed_row(scene.name, method, record["error"])
    out = Path(record["directory"]) / RESULT
    try:
        result = load_result(out, load_meshes=False)
        evaluation = evaluate(scene, out)
        ceiling = best_hypothesis_iou(scene, result, evaluation)
    except Exception as error:  # noqa: BLE001 - a failing scene is a result, not a crash
        print(f"bench: inference {scene.name} {method} failed: {error_text(error)}", flush=True)
        traceback.print_exc()
        return failed_row(scene.name, method, error_text(error))
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
        "total_s_per_object": record["wall_s"] / objects,
        "samples": details.get("samples"),
        "fallback": details.get("fallback"),
        "volume_spreads": spreads,
        "best_hypothesis_iou": ceiling,
    }


def score_comparison(record: dict) -> dict:
    """The sampler against exhaustive search on one scene (``inference_run.run_comparison``):
    {"scene", "seed" (the sampler's; 0 when the record does not say), "status", "reason",
    "objects"} and, when both ran ("ok"), "same" (objects whose
    most probable hypothesis is the same), "margins" (per object, the exact posterior's
    favourite over the runner-up), "agreements" (per object, in the order of "margins":
    whether the sampler's most probable hypothesis is the exact favourite), "exact_shares"
    (the exact probability of the sampler's choice over the favourite's), "exhaustive_s" / "sampler_s" (sampling wall time),
    "models" (joint models exhaustive scored), "samples", "stability_tests" and "fallback" (the
    sampler's), "budget_samples" (its count budget, ``inference_seeds.sampler_samples``; None
    for a run with a time budget)."""
    row = {
        "scene": Path(record["scene"]).name,
        "seed": record.get("seed", 0),
        "status": record["status"],
        "reason": record.get("reason"),
        "objects": 0,
    }
    exhaustive = record.get("exhaustive")
    if exhaustive is None:
        return row
    row.update(
        objects=len(exhaustive["posteriors"]),
        exhaustive_s=exhaustive["timing_s"].get("inference_sampling", math.nan),
        models=exhaustive["samples"],
    )
    sampler = record.get("sampler")
    if record["status"] != "ok" or sampler is None:
        return row
    exact = {p["object_id"]: np.asarray(p["probabilities"]) for p in exhaustive["posteriors"]}
    same = 0
    margins, shares, agreements = [], [], []
    for posterior in sampler["posteriors"]:
        reference = exact.get(posterior["object_id"])
        probabilities = np.asarray(posterior["probabilities"])
        if reference is not None and len(reference) == len(probabilities):
            chosen = int(np.argmax(probabilities))
            agrees = chosen == int(np.argmax(reference))
            same += int(agrees)
            agreements.append(bool(agrees))
            ranked = np.sort(reference)[::-1]
            margins.append(float(ranked[0] - (ranked[1] if ranked.size > 1 else 0.0)))
            shares.append(float(reference[chosen] / ranked[0]))
    return {
        **row,
        "same": same,
        "margins": margins,
        "agreements": agreements,
        "exact_shares": shares,
        "sampler_s": sampler["timing_s"].get("inference_sampling", math.nan),
        "samples": sampler["samples"],
        "budget_samples": record.get("budget_samples"),
        "stability_tests": sampler.get("stability_tests"),
        "fallback": sampler["fallback"],
    }


# --------------------------------------------------------------------------------------------
# Statistics over rows


def mean(rows: Sequence[dict], key: str) -> float:
    """Mean of ``key`` over the rows (nan when there are none)."""
    return float(np.mean([row[key] for row in rows])) if rows else math.nan


def finite_median(values: Iterable[float | None]) -> float:
    """Median of the finite values (nan when none is)."""
    values = [v for v in values if v is not None and math.isfinite(v)]
    return median(values)


def ok_rows(rows: Sequence[dict]) -> list[dict]:
    """The rows of scenes that did not fail."""
    return [r for r in rows if not r["error"]]


def comparison_totals(rows: Sequence[dict]) -> dict:
    """Over the "ok" comparison rows: objects, objects with the same most probable
    hypothesis, their share, the summed sampling seconds of both methods and their ratio."""
    objects = sum(r["objects"] for r in rows)
    same = sum(r["same"] for r in rows)
    exhaustive_s = sum(r["exhaustive_s"] for r in rows)
    sampler_s = sum(r["sampler_s"] for r in rows)
    return {
        "objects": objects,
        "same": same,
        "share": same / objects if objects else math.nan,
        "exhaustive_s": exhaustive_s,
        "sampler_s": sampler_s,
        "ratio": sampler_s / exhaustive_s if exhaustive_s > 0 else math.nan,
    }


#: Sampler vs exhaustive: an object's exact posterior has a clear favourite when its most
#: probable hypothesis leads the runner-up by more than this (probability); below it the
#: favourite differs from its neighbours by noise and agreement is not measurable (issue 29).
CLEAR_MARGIN = 0.1


def clear_agreement(rows: Sequence[dict], min_margin: float = CLEAR_MARGIN) -> dict:
    """Over the objects of the "ok" comparison rows whose exact margin exceeds
    ``min_margin``: {"objects", "same" (the sampler's most probable hypothesis is the exact
    favourite), "share" (nan when there is none), "scenes" (rows with at least one)}."""
    objects = same = scenes = 0
    for row in rows:
        pairs = [
            agrees
            for margin, agrees in zip(
                row.get("margins") or [], row.get("agreements") or [], strict=True
            )
            if margin > min_margin
        ]
        objects += len(pairs)
        same += sum(pairs)
        scenes += bool(pairs)
    return {
        "objects": objects,
        "same": same,
        "share": same / objects if objects else math.nan,
        "scenes": scenes,
    }


def seeded_agreement(rows: Sequence[dict], min_margin: float = CLEAR_MARGIN) -> dict:
    """``clear_agreement`` of the "ok" comparison rows of several sampler seeds (one row per
    scene and seed, "seed" in each): {"pooled": over every seed and object (objects counted
    once per seed; "scenes" and "distinct": the scenes and objects with a clear exact
    favourite, each once), "seeds": {seed: the seed's own}, "ratio": summed sampler seconds
    over summed exhaustive seconds over the rows (exhaustive's counted once per seed: the
    share of its compute each sampler run took)}. The pooled share is the judged figure: one seed's is one draw of the
    sampler's randomness on a few objects."""
    ok = [r for r in rows if r["status"] == "ok"]
    seeds = sorted({r.get("seed", 0) for r in ok})
    pooled = clear_agreement(ok, min_margin)
    once = clear_agreement(list({r["scene"]: r for r in ok}.values()), min_margin)
    pooled.update(scenes=once["scenes"], distinct=once["objects"])
    exhaustive_s = sum(r["exhaustive_s"] for r in ok)
    return {
        "pooled": pooled,
        "seeds": {
            s: clear_agreement([r for r in ok if r.get("seed", 0) == s], min_margin) for s in seeds
        },
        "ratio": sum(r["sampler_s"] for r in ok) / exhaustive_s if exhaustive_s > 0 else math.nan,
    }


def pooled_margins(rows: Sequence[dict]) -> tuple[list[float], list[float]]:
    """Every object's exact margin and exact share of the sampler's choice, over the rows."""
    margins = [m for r in rows for m in r.get("margins") or []]
    shares = [s for r in rows for s in r.get("exact_shares") or []]
    return margins, shares
