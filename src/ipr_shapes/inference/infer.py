"""``infer_shapes``: a physics-based method from prepared hypotheses to marginal posteriors."""

from __future__ import annotations

import itertools
import logging
import math
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ipr_shapes.collision_checker import (
    CollisionCheckerConfig,
    medoid_base_weights,
    uniform_posteriors,
)
from ipr_shapes.errors import IprError
from ipr_shapes.factor_graph import PairwiseIoU, posterior_medoid
from ipr_shapes.inference.config import InferenceConfig
from ipr_shapes.inference.estimators import (
    effective_sample_size,
    friction_posterior,
    marginals,
    medoid_weights,
    sample_log_weights,
)
from ipr_shapes.inference.exhaustive import exhaustive_models
from ipr_shapes.inference.pool import default_workers, run_samples
from ipr_shapes.inference.problem import SampleResult, build_problem
from ipr_shapes.likelihood import ObservedFrames
from ipr_shapes.methods import DEFAULT_METHOD, get_method
from ipr_shapes.perception.types import KnownPlane
from ipr_shapes.products import ObjectPosterior, PreparedHypotheses, SamplingSummary
from ipr_shapes.progress import ProgressCallback, report
from ipr_shapes.scene import Push, Pusher

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class InferenceOutcome:
    """Posteriors of a physics-based method and how they were obtained.

    ``fallback`` names why the Collision Checker's answer was returned (None when the
    physics-based estimate was); ``samples`` the evaluated joint models (in index order);
    ``timing_s`` seconds spent sampling (``sampling``) and in the Collision Checker;
    ``summary`` how the posterior was obtained (None when there was no object).
    """

    method: str
    posteriors: list[ObjectPosterior]
    samples: list[SampleResult]
    fallback: str | None
    timing_s: dict[str, float]
    summary: SamplingSummary | None


def physics_medoid(
    base: ObjectPosterior,
    candidates: np.ndarray,
    weights: np.ndarray,
    table: PairwiseIoU | None,
    medoid_base: str = "uniform",
    checker: CollisionCheckerConfig | None = None,
    hidden: float = 0.0,
    points: np.ndarray | None = None,
    viewpoints: np.ndarray | None = None,
) -> int:
    """Index into ``base.hypotheses`` (the Collision Checker's posterior of one object) of a
    physics-based method's output shape: the medoid of its ``candidates`` (indices into
    ``base.hypotheses``) under ``weights`` ((len(candidates),), ``medoid_weights``: each
    candidate's evidence times its prior) times, with ``medoid_base = "collision-checker"``,
    the Collision Checker's medoid weights (``medoid_base_weights`` under ``checker``, from the
    object's ``hidden`` outline fraction, its observed ``points`` and their ``viewpoints``):
    prior times likelihood, the Bayes choice under IoU loss (each candidate scored against
    every weight, its own included, as the physics medoid always was; the Collision
    Checker's leave-one-out is for its own flat weights). Why: evidence that says little
    then leaves the Collision Checker's judgement of the candidates, not each candidate
    counted once (``InferenceConfig.medoid_base``). ``table``: the pairwise IoU of
    ``base.hypotheses`` already computed (None: computed here)."""
    weight = np.zeros(len(base.hypotheses))
    weight[candidates] = weights
    if medoid_base == "collision-checker":
        start, _ = medoid_base_weights(
            base.hypotheses, base.probabilities > 0, checker or CollisionCheckerConfig(),
            hidden, points, viewpoints,
        )  # fmt: skip
        weight *= start
        weight /= weight.sum()
    return posterior_medoid(base.hypotheses, weight, table)


def infer_shapes(
    prepared: PreparedHypotheses,
    planes: tuple[KnownPlane, ...],
    observed: ObservedFrames,
    *,
    method: str = DEFAULT_METHOD,
    pusher: Pusher | None = None,
    pushes: Sequence[Push] = (),
    config: InferenceConfig | None = None,
    collision_checker_config: CollisionCheckerConfig | None = None,
    seed: int = 0,
    deadline: float | None = None,
    workers: int | None = None,
    progress: ProgressCallback | None = None,
    points: Mapping[int, np.ndarray] | None = None,
    hidden: Mapping[int, float] | None = None,
    viewpoints: Mapping[int, np.ndarray] | None = None,
) -> InferenceOutcome:
    """Marginal shape posteriors by IPR (module doc).

    Args:
        prepared: hypotheses and constraints of the frame-0 objects.
        planes: frame-0 support and walls.
        observed: the observed frames (frame 0 first) with tracked labels.
        method: a physics-based method of ``ipr_shapes.methods.METHODS``.
        pusher, pushes: the robot's pusher and pushes (world frame).
        config: settings (default ``InferenceConfig()``).
        collision_checker_config: settings of the Collision Checker (fallback answer).
        seed: seed of the samples.
        deadline: ``time.perf_counter()`` time to stop at (None: ``budget_per_object_s`` per
            object from the end of the Collision Checker, unless ``config.max_samples`` is set).
        workers: overrides ``config.workers``.
        progress: observer of the samples drawn and the time left (``ipr_shapes.progress``, stage
            ``sampling``).
        points: per object id its observed points ((N, 3), world, m), which
            ``config.surface_fit`` scores each candidate's surface against (None: no surface
            factor), and from which ``config.medoid_base = "collision-checker"`` computes the
            Collision Checker's fit weights (None: the families' equal shares).
        hidden: per object id the hidden fraction of its frame-0 image outline
            (``hidden_outline_fractions``), for ``config.medoid_base = "collision-checker"``
            (None or absent: 0).
        viewpoints: per object id the camera centre each of its ``points`` was seen from
            ((3,) or (N, 3), world, m; NaN: not known; ``object_viewpoints``), for the same.
    """
    variant = get_method(method)
    if not variant.physics:
        raise IprError(
            f"{method} is not a physics-based method (fix: use ipr_shapes.collision_checker)"
        )
    config = config or InferenceConfig()
    started = time.perf_counter()
    # The medoids' pairwise IoU, per object: the final medoid's candidates are among the
    # Collision Checker's, whose medoid computed their pairs.
    tables: dict[int, PairwiseIoU] = {}
    uniform = uniform_posteriors(
        prepared,
        collision_checker_config,
        np.random.default_rng([seed, 2**31]),
        math.inf if deadline is None else deadline,
        tables,
    )
    checked = time.perf_counter()
    n = len(prepared.ids)
    timing = {"collision_checker": checked - started}
    if n == 0:
        return InferenceOutcome(method, [], [], None, {**timing, "sampling": 0.0}, None)
    if deadline is None:
        # The sampling budget is sampling's own: the Collision Checker's answer (the starting
        # point) does not take from it.
        deadline = math.inf if config.max_samples else checked + config.budget_per_object_s * n
    frames = observed
    if not variant.actions:
        first_push = min((p.after_frame for p in pushes), default=None)
        if first_push is not None:
            # The frames observed before the first push (frame 0 at least); a push after
            # every observed frame leaves them all.
            before = sum(1 for frame in observed.frames if frame < first_push)
            frames = observed.only(max(1, before))
    problem, indices = build_problem(
        prepared, uniform, planes, frames,
        variant=variant, pusher=pusher, pushes=pushes, config=config, seed=seed, points=points,
    )  # fmt: skip
    workers = workers or config.workers or default_workers()
    if variant.exhaustive:
        models = exhaustive_models(problem)
        tasks: Iterable = ((index, choice) for index, choice in enumerate(models))
        workers = min(workers, max(1, len(models)))
        total = len(models)
    else:
        limit = config.max_samples if config.max_samples else None
        tasks = ((index, None) for index in (range(limit) if limit else itertools.count()))
        total = limit

    def sampled_so_far(done: int) -> None:
        left = None if math.isinf(deadline) else max(deadline - time.perf_counter(), 0.0)
        report(progress, "sampling", done, total, left)

    sampled_so_far(0)
    samples = run_samples(
        problem, tasks, workers=workers, deadline=deadline,
        on_result=sampled_so_far if progress is not None else None,
    )  # fmt: skip
    sampled = time.perf_counter()
    timing["sampling"] = sampled - checked
    estimate = marginals(samples, problem, joint=variant.exhaustive)
    fallback = None
    if not samples:
        fallback = "the time budget ran out before the first sample; Collision Checker answer"
    elif estimate is None:
        fallback = "every sampled model exploded or was impossible; Collision Checker answer"
    if fallback:
        logger.warning("%s: %s", method, fallback)
        posteriors = uniform
    else:
        # The medoid is weighted by each candidate's own evidence, not its marginal, which
        # also counts the neighbours' candidates it fits with (``medoid_weights``).
        weights = medoid_weights(samples, problem, joint=variant.exhaustive) or estimate
        posteriors = []
        for k, base in enumerate(uniform):
            probabilities = np.zeros(len(base.hypotheses))
            probabilities[indices[k]] = estimate[k]
            i = base.object_id
            best = physics_medoid(
                base, indices[k], weights[k], tables.get(i), config.medoid_base,
                collision_checker_config or CollisionCheckerConfig(),
                (hidden or {}).get(i, 0.0), (points or {}).get(i), (viewpoints or {}).get(i),
            )  # fmt: skip
            posteriors.append(
                ObjectPosterior(
                    base.object_id,
                    base.hypotheses,
                    probabilities,
                    best,
                    base.minimum,
                    method,
                    base.generation_s,
                )
            )
    finite = [r for r in samples if math.isfinite(r.log_likelihood)]
    frictions = problem.friction_values
    posterior_mu = None
    if not fallback:
        posterior_mu = friction_posterior(samples, problem, joint=variant.exhaustive)
    summary = SamplingSummary(
        samples=len(samples),
        impossible_samples=len(samples) - len(finite),
        effective_sample_size=float(
            np.median(
                [
                    effective_sample_size(column)
                    for column in sample_log_weights(samples, problem, joint=variant.exhaustive).T
                ]
            )
        )
        if samples and problem.count
        else 0.0,
        stability_tests=int(sum(r.stability_tests for r in samples)),
        workers=workers,
        pushes_replayed=len(problem.pushes),
        frames_compared=len(problem.observed.frames),
        fallback=fallback,
        frictions=tuple(float(f) for f in frictions),
        friction_posterior=None if posterior_mu is None else tuple(float(p) for p in posterior_mu),
    )
    logger.info(
        "%s: %d samples (%d impossible, ESS %.1f) in %.2f s with %d workers",
        method, len(samples), summary.impossible_samples, summary.effective_sample_size,
        timing["sampling"], workers,
    )  # fmt: skip
    if posterior_mu is not None and len(frictions) > 1:
        logger.info(
            "%s: friction posterior %s over %s",
            method, np.round(posterior_mu, 3).tolist(), list(frictions),
        )  # fmt: skip
    return InferenceOutcome(method, posteriors, samples, fallback, timing, summary)
