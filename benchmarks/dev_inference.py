"""Development measurements of IPR inference (docs/DESIGN_NOTES.md, "Physics and inference";
figures in docs/experiments/2026-11-21-likelihood-and-weighting.md and the files beside it).

Usage: ``python -m benchmarks.dev_inference [--seed 9100] [--count 10] [--samples 40]
[--frictions 0.25 0.35 0.5 0.7 1.0] [--cache DIR] [--select 0 1 ...] [--config FILE]``
(``--config``: a TOML whose ``[inference]`` section replaces the default ``InferenceConfig``'s
settings; ``--frictions`` then overrides its frictions).

``--cache DIR`` keeps each scene's measurement (pickled, keyed by scene, samples and
frictions), so that processes with disjoint ``--select`` (scene positions) measure in parallel
and a last run without ``--select`` reports over all of them from the cache.

Generates (or reuses) development dynamic scenes with ``ipr-shapes synth`` seeds from 9100 (never the
benchmark suites), samples ``--samples`` joint models per scene with the full method in one
process, and scores, against each object's matched ground truth (benchmark code may read it;
inference never does):

- the Collision Checker's output (posterior medoid);
- the IPR estimate per weighting (``InferenceConfig.weighting``) and alpha, with every frame
  (the full method) and with frame 0 only (the gravity-only variants), from the same samples
  (alpha and the weighting only weigh them); at alpha 0.2 also with the seen-surface factor
  (``InferenceConfig.surface_fit``; each scene's frame-0 points are kept in the cache);
- the best of each object's candidates (oracle) and of the candidates the sampler visited;
- with ``--frictions`` (off by default, as ``InferenceConfig.frictions``; include
  ``physics.friction``, 1.0) the friction search: the same samples scored under
  ``physics.friction`` alone (no search, when it is one of ``--frictions``) against the
  marginal over the searched frictions; the same with the samples the search affords in the
  CPU time the single friction takes for all of them and for 12 (about the default budget;
  tree sampling and the likelihood under each timed again, one thread); two cheap
  alternatives on the same samples (each candidate's likelihood averaged over the frictions;
  one friction drawn per sample); and per scene the friction posterior beside the generator's
  per-object frictions (``synth.json``), with their rank correlation.

Figures are mean object IoU over the visible ground-truth objects (unmatched objects count 0),
the convention of ``ipr-shapes eval``'s object space, of the convex candidates as inferred: what the
result writes is then carved by the space the camera saw empty (``ipr_shapes.carving``), which this
script leaves out so that it measures the choice among candidates alone.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ALPHAS = (0.05, 0.2, 0.5, 2.0, 10.0)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    from ipr_shapes import voxels

    common = voxels.intersection_count(a, b)
    union = a.size + b.size - common
    return common / union if union else 0.0


def measure_scene(
    path: Path, samples: int, frictions: tuple[float, ...] | None = None, base=None
) -> dict:
    """Samples of one scene and the IoU of every candidate of every matched object, under
    ``base`` (an ``InferenceConfig``; None: the default) with ``frictions`` when given."""
    import dataclasses

    from scipy.optimize import linear_sum_assignment

    from ipr_shapes import voxels
    from ipr_shapes.collision_checker import object_viewpoints, uniform_posteriors
    from ipr_shapes.ground_truth import frame0_ground_truth, visible_pixel_counts
    from ipr_shapes.hypotheses import prepare_hypotheses
    from ipr_shapes.inference import InferenceConfig, build_problem, run_samples
    from ipr_shapes.likelihood import observed_frames
    from ipr_shapes.methods import METHODS
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.perception.config import SegmentationConfig
    from ipr_shapes.perception.outline import hidden_outline_fractions
    from ipr_shapes.scene import load_scene

    scene = load_scene(path)
    perception = perceive_scene(scene)
    config = base or InferenceConfig()
    if frictions is not None:
        config = dataclasses.replace(config, frictions=frictions)
    prepared = prepare_hypotheses(
        perception.objects[0], perception.free_space[0], perception.planes[0],
        rng=np.random.default_rng(0),
    )  # fmt: skip
    uniform = uniform_posteriors(prepared)
    # The Collision Checker's default medoid weights read the frame-0 outline and points.
    hidden = hidden_outline_fractions(
        scene.frames[0].depth_m,
        perception.objects[0],
        SegmentationConfig().contour_gap_m,
    )
    camera = np.asarray(scene.frames[0].world_from_camera, float)[:3, 3]
    viewpoints = {o.id: object_viewpoints(o, camera) for o in perception.objects[0]}
    observed = observed_frames(scene.frames, perception.labels, config.likelihood.decimation)
    problem, _ = build_problem(
        prepared, uniform, perception.planes[0], observed,
        variant=METHODS["ipr+action+uniform"], pusher=scene.pusher, pushes=scene.pushes,
        config=config, seed=0,
    )  # fmt: skip
    results = run_samples(problem, ((i, None) for i in range(samples)), workers=1, deadline=np.inf)
    timing = _likelihood_seconds(problem, results)
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
    checker = np.array([[_iou(p.best_hypothesis.keys(), t) for t in truths] for p in uniform])
    matched = {}
    if checker.size:
        for row, column in zip(*linear_sum_assignment(-checker), strict=True):
            if checker[row, column] > 0:
                matched[int(row)] = int(column)
    candidate_iou = {
        k: np.array([_iou(h.keys(), truths[t]) for h in problem.candidates[k]])
        for k, t in matched.items()
    }
    return {
        "problem": problem,
        "results": results,
        "truths": len(truths),
        "checker": {k: checker[k, t] for k, t in matched.items()},
        "candidate_iou": candidate_iou,
        "timing": timing,
        "true_frictions": _true_frictions(path),
        "points": {o.id: o.points for o in perception.objects[0]},
        "hidden": hidden,
        "viewpoints": viewpoints,
    }


def _cached_measurement(
    path: Path, samples: int, frictions: tuple[float, ...] | None, cache: Path | None, base=None
) -> dict:
    """``measure_scene``, read from / written to ``cache`` when given."""
    import hashlib
    import pickle

    if cache is None:
        return measure_scene(path, samples, frictions, base)
    key = (
        f"{path.parent.name}-{path.name}-{samples}-{'default' if frictions is None else frictions}"
    )
    if base is not None:
        key += "-" + hashlib.sha256(repr(base).encode()).hexdigest()[:8]
    file = cache / f"{key}.pkl"
    if file.exists():
        return pickle.loads(file.read_bytes())
    scene = measure_scene(path, samples, frictions, base)
    cache.mkdir(parents=True, exist_ok=True)
    partial = file.with_suffix(".part")
    partial.write_bytes(pickle.dumps(scene))
    partial.rename(file)
    return scene


def _likelihood_seconds(problem, results, count: int = 6) -> tuple[float, float]:
    """CPU seconds of the likelihood of the first ``count`` sampled joint models under the
    problem's frictions and under ``physics.friction`` alone (fresh samplers, one thread)."""
    import dataclasses
    import time

    from ipr_shapes.inference import Sampler

    seconds = []
    for frictions in (problem.frictions, ()):
        sampler = Sampler(dataclasses.replace(problem, frictions=frictions))
        started = time.process_time()
        for result in results[:count]:
            sampler.depth_norms(result.choice)
        seconds.append(time.process_time() - started)
        sampler.close()
    return seconds[0], seconds[1]


def _tree_seconds(problem, count: int) -> float:
    """CPU seconds of drawing the first ``count`` joint models by tree sampling (stability
    tests, no likelihood: the part of a sample's cost the friction search does not touch)."""
    import time

    from ipr_shapes.inference import Sampler

    sampler = Sampler(problem)
    started = time.process_time()
    for index in range(count):
        sampler.tree_sample(np.random.default_rng([problem.seed, index]))
    seconds = time.process_time() - started
    sampler.close()
    return seconds


def _true_frictions(path: Path) -> list[float]:
    """The generator's per-object sliding frictions (``synth.json``; [] when absent)."""
    import json

    try:
        objects = json.loads((path / "synth.json").read_text())["objects"]
    except (OSError, KeyError, ValueError):
        return []
    return [float(o["friction"]) for o in objects]


def estimate_iou(
    scene: dict,
    alpha: float,
    frames: int | None,
    weighting: str = "hypothesis",
    prior: str = "uniform",
    friction: float | str | None = None,
    count: int | None = None,
    surface: bool = False,
    base: bool = False,
) -> dict[int, float]:
    """IoU of the IPR output per matched object with ``alpha``, the first ``frames``,
    ``weighting`` (``InferenceConfig.weighting``), ``prior`` ("uniform" or "size"), the
    samples scored under ``friction`` alone (None: marginalised over the searched frictions;
    "sampled S": each sample under one friction drawn uniformly with seed S, as if friction
    were sampled with the shapes at the cost of one; "averaged": each candidate's likelihood
    averaged over the frictions, without a posterior over them), the first ``count``
    samples (None: all), with ``surface``, each candidate's seen-surface factor
    (``InferenceConfig.surface_fit``) from the scene's frame-0 points, and with ``base`` the
    Collision Checker's default medoid weights as the medoid's base measure
    (``InferenceConfig.medoid_base = "collision-checker"``, ``physics_medoid``)."""
    import dataclasses

    from ipr_shapes.factor_graph import posterior_medoid
    from ipr_shapes.inference import (
        at_friction,
        medoid_weights,
        size_log_prior,
        surface_log_likelihoods,
    )

    problem = scene["problem"]
    if surface:
        points = scene["points"]
        terms = tuple(
            surface_log_likelihoods(c, points[i]) if i in points else np.zeros(len(c))
            for c, i in zip(problem.candidates, problem.ids, strict=True)
        )
        problem = dataclasses.replace(problem, surface_log_likelihood=terms)
    if prior == "size":
        log_prior = tuple(
            size_log_prior(c, problem.config.size_prior_exponent) for c in problem.candidates
        )
        problem = dataclasses.replace(problem, log_prior=log_prior)
    config = dataclasses.replace(
        problem.config,
        weighting=weighting,
        likelihood=dataclasses.replace(problem.config.likelihood, alpha_per_m=alpha),
    )
    problem = dataclasses.replace(problem, config=config)
    results = scene["results"][:count]
    if isinstance(friction, str) and friction.startswith("sampled"):
        seed = int(friction.split()[1])
        count_f = len(problem.friction_values)
        draws = np.random.default_rng(seed).integers(count_f, size=len(results))
        results = [
            at_friction([r], problem, int(f))[0] for r, f in zip(results, draws, strict=True)
        ]
        problem = dataclasses.replace(problem, frictions=())
    elif friction == "averaged":
        results = [
            r for f in range(len(problem.friction_values)) for r in at_friction(results, problem, f)
        ]
        problem = dataclasses.replace(problem, frictions=())
    elif friction is not None:
        index = problem.friction_values.index(friction)
        results = at_friction(results, problem, index)
        problem = dataclasses.replace(problem, frictions=())
    results = [
        dataclasses.replace(r, norms=None if r.norms is None else r.norms[:, :frames])
        for r in results
    ]
    # The weights the library's medoid is taken under (its marginals for "object").
    estimate = medoid_weights(results, problem)
    output = {}
    for k, ious in scene["candidate_iou"].items():
        weights = estimate[k] if estimate else None
        if base and estimate:
            start, _ = _checker_weights(scene, k)
            weights = weights * start
            weights = weights / weights.sum()
        best = posterior_medoid(problem.candidates[k], weights) if estimate else 0
        output[k] = float(ious[best])
    return output


def _checker_weights(scene: dict, k: int) -> tuple[np.ndarray, bool]:
    """The Collision Checker's default medoid weights of object ``k``'s candidates (the
    problem's order) and whether its medoid leaves each candidate out (``medoid_base_weights``)."""
    from ipr_shapes.collision_checker import CollisionCheckerConfig, medoid_base_weights

    problem = scene["problem"]
    i = problem.ids[k]
    candidates = problem.candidates[k]
    return medoid_base_weights(
        candidates, np.ones(len(candidates), dtype=bool), CollisionCheckerConfig(),
        scene["hidden"].get(i, 0.0), scene["points"].get(i), scene["viewpoints"].get(i),
    )  # fmt: skip


def checker_iou(scene: dict) -> dict[int, float]:
    """IoU per matched object of the Collision Checker's default medoid (its medoid weights
    over the same candidates, ``_checker_weights``), the physics medoid's flat-evidence answer
    with ``base``."""
    from ipr_shapes.factor_graph import posterior_medoid

    output = {}
    for k, ious in scene["candidate_iou"].items():
        weights, leave_one_out = _checker_weights(scene, k)
        candidates = scene["problem"].candidates[k]
        output[k] = float(ious[posterior_medoid(candidates, weights, leave_one_out=leave_one_out)])
    return output


def mean_over_truths(scenes: list[dict], values: list[dict[int, float]]) -> float:
    """Mean over every visible ground-truth object (unmatched ones count 0)."""
    return sum(sum(v.values()) for v in values) / max(sum(s["truths"] for s in scenes), 1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=9100)
    parser.add_argument("--count", type=int, default=10)
    parser.add_argument("--samples", type=int, default=40)
    parser.add_argument("--scenes", type=Path, default=Path("/tmp/ipr-dev-inference"))
    parser.add_argument("--frictions", type=float, nargs="*", default=None)
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument("--select", type=int, nargs="*", default=None)
    parser.add_argument("--config", type=Path, help="a TOML configuration (ipr-shapes config show)")
    args = parser.parse_args(argv)
    base = None
    if args.config is not None:
        from ipr_shapes.config import read_config
        from ipr_shapes.errors import IprError

        try:
            base = read_config(args.config).inference
        except IprError as error:
            parser.exit(2, f"error: {error}\n")
    from benchmarks.common import development_scenes
    from ipr_shapes.inference import InferenceConfig, friction_posterior

    frictions = tuple(args.frictions) if args.frictions is not None else None
    scenes = []
    paths = development_scenes(args.scenes, args.seed, args.count)
    if args.select is not None:
        paths = [paths[i] for i in args.select]
    for path in paths:
        scenes.append(_cached_measurement(path, args.samples, frictions, args.cache, base))
        scene = scenes[-1]
        problem = scene["problem"]
        posterior = friction_posterior(scene["results"], problem)
        searched, single = scene["timing"]
        print(
            f"{path.name}: {len(scene['candidate_iou'])} matched objects; friction posterior "
            f"{np.round(posterior, 3).tolist() if posterior is not None else None} over "
            f"{list(problem.friction_values)}; true {np.round(scene['true_frictions'], 2).tolist()}"
            f"; likelihood CPU s {searched:.2f} searched / {single:.2f} single",
            flush=True,
        )
    rows = [
        ("Collision Checker", mean_over_truths(scenes, [s["checker"] for s in scenes])),
        ("oracle (best candidate)", mean_over_truths(
            scenes, [{k: float(v.max()) for k, v in s["candidate_iou"].items()} for s in scenes]
        )),
        ("oracle (best sampled)", mean_over_truths(scenes, [
            {k: float(v[sorted({r.choice[k] for r in s["results"]})].max())
             for k, v in s["candidate_iou"].items()}
            for s in scenes
        ])),
    ]  # fmt: skip
    rows.append(("IPR hypothesis, every frame, alpha 2, size prior", mean_over_truths(
        scenes, [estimate_iou(s, 2.0, None, "hypothesis", "size") for s in scenes]
    )))  # fmt: skip
    rows.append(("IPR object, every frame, alpha 2, size prior", mean_over_truths(
        scenes, [estimate_iou(s, 2.0, None, "object", "size") for s in scenes]
    )))  # fmt: skip
    for weighting in ("hypothesis", "object"):
        for frames, label in ((None, "every frame"), (1, "frame 0 only")):
            for alpha in ALPHAS:
                values = [estimate_iou(s, alpha, frames, weighting) for s in scenes]
                rows.append(
                    (f"IPR {weighting}, {label}, alpha {alpha:g}", mean_over_truths(scenes, values))
                )
    if all("points" in s for s in scenes):  # caches written before the points have none
        for frames, label in ((None, "every frame"), (1, "frame 0 only")):
            values = [estimate_iou(s, 0.2, frames, surface=True) for s in scenes]
            rows.append(
                (
                    f"IPR hypothesis, {label}, alpha 0.2, seen-surface fit",
                    mean_over_truths(scenes, values),
                )
            )
    if all("hidden" in s for s in scenes):  # caches written before the outline have none
        rows.append(
            (
                "Collision Checker, default medoid weights",
                mean_over_truths(scenes, [checker_iou(s) for s in scenes]),
            )
        )
        for frames, label in ((None, "every frame"), (1, "frame 0 only")):
            values = [estimate_iou(s, 0.2, frames, base=True) for s in scenes]
            rows.append(
                (
                    f"IPR hypothesis, {label}, alpha 0.2, Collision Checker base",
                    mean_over_truths(scenes, values),
                )
            )
    default = InferenceConfig().physics.friction
    if all(default in s["problem"].friction_values for s in scenes) and any(
        len(s["problem"].friction_values) > 1 for s in scenes
    ):
        # Equal time: per scene, the samples the search affords in the single friction's CPU
        # time (tree sampling and likelihood timed again, one thread).
        affordable = []
        for s in scenes:
            searched, single = (t / min(len(s["results"]), 6) for t in s["timing"])
            tree = _tree_seconds(s["problem"], len(s["results"])) / len(s["results"])
            affordable.append((tree + single) / (tree + searched))
            print(
                f"CPU s per sample: tree sampling {tree:.2f}, likelihood {single:.2f} single / "
                f"{searched:.2f} searched"
            )
        budget = 12  # about what the default budget affords (docs/DESIGN_NOTES.md)
        small = [max(1, int(budget * ratio)) for ratio in affordable]
        affordable = [max(1, int(args.samples * ratio)) for ratio in affordable]
        for alpha in (0.2, 2.0):
            rows.append((f"IPR hypothesis, alpha {alpha:g}, friction {default:g} alone, {budget} samples",
                         mean_over_truths(scenes, [estimate_iou(s, alpha, None, friction=default, count=budget)
                                                   for s in scenes])))  # fmt: skip
            rows.append((f"IPR hypothesis, alpha {alpha:g}, searched, equal time to {budget} samples",
                         mean_over_truths(scenes, [estimate_iou(s, alpha, None, count=c)
                                                   for s, c in zip(scenes, small, strict=True)])))  # fmt: skip
            rows.append((f"IPR hypothesis, alpha {alpha:g}, friction {default:g} alone",
                         mean_over_truths(scenes, [estimate_iou(s, alpha, None, friction=default)
                                                   for s in scenes])))  # fmt: skip
            rows.append((f"IPR hypothesis, alpha {alpha:g}, friction searched",
                         mean_over_truths(scenes, [estimate_iou(s, alpha, None) for s in scenes])))  # fmt: skip
            rows.append((f"IPR hypothesis, alpha {alpha:g}, searched, equal time",
                         mean_over_truths(scenes, [estimate_iou(s, alpha, None, count=c)
                                                   for s, c in zip(scenes, affordable, strict=True)])))  # fmt: skip
            rows.append((f"IPR hypothesis, alpha {alpha:g}, likelihood averaged over frictions",
                         mean_over_truths(scenes, [estimate_iou(s, alpha, None, friction="averaged")
                                                   for s in scenes])))  # fmt: skip
            sampled = [
                mean_over_truths(scenes, [estimate_iou(s, alpha, None, friction=f"sampled {seed}")
                                          for s in scenes])
                for seed in range(5)
            ]  # fmt: skip
            rows.append((f"IPR hypothesis, alpha {alpha:g}, one friction drawn per sample "
                         f"(5 draws: {min(sampled):.3f}-{max(sampled):.3f})", float(np.mean(sampled))))  # fmt: skip
        print(f"samples affordable in equal time: {affordable} (to {budget}: {small})")
        means = []
        for s in scenes:
            posterior = friction_posterior(s["results"], s["problem"])
            if posterior is not None and s["true_frictions"]:
                means.append((float(posterior @ s["problem"].friction_values),
                              float(np.mean(s["true_frictions"]))))  # fmt: skip
        if len(means) > 2:
            from scipy.stats import spearmanr

            rho = spearmanr(*zip(*means, strict=True)).statistic
            print(f"posterior mean friction vs the scene's mean true friction: Spearman {rho:.2f}")
    truths = sum(s["truths"] for s in scenes)
    print(f"\n{len(scenes)} scenes, {truths} visible objects, {args.samples} samples per scene")
    for label, value in rows:
        print(f"{label:36s} {value:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
