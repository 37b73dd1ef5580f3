"""Development measurements of IPR inference (docs/DESIGN_NOTES.md, "Physics and inference";
figures in docs/experiments/2026-11-21-likelihood-and-weighting.md and the files beside it).

Usage: ``python -m benchmarks.dev_inference [--seed 9100] [--count 10] [--samples 40]
[--config FILE]`` (``--config``: a TOML whose ``[inference]`` section replaces the default
``InferenceConfig``'s settings).

Generates (or reuses) development dynamic scenes with ``ipr-shapes synth`` seeds from 9100 (never the
benchmark suites), samples ``--samples`` joint models per scene with the full method in one
process, and scores, against each object's matched ground truth (benchmark code may read it;
inference never does):

- the Collision Checker's output (posterior medoid);
- the IPR estimate per weighting (``InferenceConfig.weighting``) and alpha, with every frame
  (the full method) and with frame 0 only (the gravity-only variants), from the same samples
  (alpha and the weighting only weigh them);
- the best of each object's candidates (oracle) and of the candidates the sampler visited.

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


def measure_scene(path: Path, samples: int, config=None) -> dict:
    """Samples of one scene and the IoU of every candidate of every matched object, under
    ``config`` (an ``InferenceConfig``; None: the default)."""
    from scipy.optimize import linear_sum_assignment

    from ipr_shapes import voxels
    from ipr_shapes.collision_checker import uniform_posteriors
    from ipr_shapes.ground_truth import frame0_ground_truth, visible_pixel_counts
    from ipr_shapes.hypotheses import prepare_hypotheses
    from ipr_shapes.inference import InferenceConfig, build_problem, run_samples
    from ipr_shapes.likelihood import observed_frames
    from ipr_shapes.methods import METHODS
    from ipr_shapes.perception import perceive_scene
    from ipr_shapes.scene import load_scene

    scene = load_scene(path)
    perception = perceive_scene(scene)
    config = config or InferenceConfig()
    prepared = prepare_hypotheses(
        perception.objects[0], perception.free_space[0], perception.planes[0],
        rng=np.random.default_rng(0),
    )  # fmt: skip
    uniform = uniform_posteriors(prepared)
    observed = observed_frames(scene.frames, perception.labels, config.likelihood.decimation)
    problem, _ = build_problem(
        prepared, uniform, perception.planes[0], observed,
        variant=METHODS["ipr+action+uniform"], pusher=scene.pusher, pushes=scene.pushes,
        config=config, seed=0,
    )  # fmt: skip
    results = run_samples(problem, ((i, None) for i in range(samples)), workers=1, deadline=np.inf)
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
    }


def estimate_iou(
    scene: dict,
    alpha: float,
    frames: int | None,
    weighting: str = "hypothesis",
    prior: str = "uniform",
) -> dict[int, float]:
    """IoU of the IPR output per matched object with ``alpha``, the first ``frames``,
    ``weighting`` (``InferenceConfig.weighting``) and ``prior`` ("uniform" or "size")."""
    import dataclasses

    from ipr_shapes.factor_graph import posterior_medoid
    from ipr_shapes.inference import marginals, size_log_prior

    problem = scene["problem"]
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
    results = [
        dataclasses.replace(r, norms=None if r.norms is None else r.norms[:frames])
        for r in scene["results"]
    ]
    estimate = marginals(results, problem)
    output = {}
    for k, ious in scene["candidate_iou"].items():
        best = posterior_medoid(problem.candidates[k], estimate[k]) if estimate else 0
        output[k] = float(ious[best])
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
    parser.add_argument("--config", type=Path, help="a TOML configuration (ipr-shapes config show)")
    args = parser.parse_args(argv)
    from benchmarks.common import development_scenes

    config = None
    if args.config is not None:
        from ipr_shapes.config import read_config
        from ipr_shapes.errors import IprError

        try:
            config = read_config(args.config).inference
        except IprError as error:
            parser.exit(2, f"error: {error}\n")
    scenes = []
    for path in development_scenes(args.scenes, args.seed, args.count):
        scenes.append(measure_scene(path, args.samples, config))
        print(f"{path.name}: {len(scenes[-1]['candidate_iou'])} matched objects", flush=True)
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
    truths = sum(s["truths"] for s in scenes)
    print(f"\n{len(scenes)} scenes, {truths} visible objects, {args.samples} samples per scene")
    for label, value in rows:
        print(f"{label:36s} {value:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
