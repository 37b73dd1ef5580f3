"""From evaluated samples to each object's marginal over its candidates (``InferenceConfig.weighting``):
per-hypothesis likelihoods combined by exact elimination, or per-object / joint importance
weights; and the effective sample size diagnostic."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ipr_shapes.factor_graph import TableTooLarge, exact_marginals, interaction_components
from ipr_shapes.inference.problem import InferenceProblem, SampleResult


def object_log_weights(results: Sequence[SampleResult], problem: InferenceProblem) -> np.ndarray:
    """(S, n) per-object log importance weights of the samples (module doc):
    log P(O_i | X, mu) + log P(X_i) - log q_i, with object i's own term of Eq. 2 and its own
    exploration probability; -inf for failed simulations."""
    config = problem.config.likelihood
    scale = config.alpha_per_m * problem.observed.decimation
    weights = np.full((len(results), problem.count), -np.inf)
    for row, result in enumerate(results):
        if result.norms is None:
            continue
        for k, j in enumerate(result.choice):
            weights[row, k] = (
                -scale * float(result.norms[:, k].sum())
                + float(problem.log_prior[k][j])
                - float(result.object_log_proposal[k])
            )
    return weights


def hypothesis_log_likelihoods(
    results: Sequence[SampleResult], problem: InferenceProblem
) -> list[np.ndarray]:
    """Per object, (m_k,) the log of the mean over the samples that chose each candidate of
    exp(its own Eq. 2 term) (module doc, step 3); NaN for candidates no sample chose."""
    config = problem.config.likelihood
    scale = config.alpha_per_m * problem.observed.decimation
    terms: list[list[list[float]]] = [[[] for _ in c] for c in problem.candidates]
    for result in results:
        if result.norms is None:
            continue
        own = -scale * result.norms.sum(axis=0)
        for k, j in enumerate(result.choice):
            terms[k][j].append(float(own[k]))
    return [
        np.array([np.logaddexp.reduce(t) - math.log(len(t)) if t else math.nan for t in per_object])
        for per_object in terms
    ]


def factor_marginals(
    unary_log: Sequence[np.ndarray], problem: InferenceProblem
) -> list[np.ndarray]:
    """Marginals of P(X) proportional to prod_k exp(unary_log[k][X_k]) times the pairwise
    constraints (``problem.compatible``), exact by variable elimination per connected group of
    interacting objects; a group whose tables would exceed ``max_factor_table`` (or that has
    no feasible assignment) combines its unary factors alone."""
    nodes = list(range(problem.count))
    unary = {k: np.exp(u - np.max(u)) for k, u in enumerate(unary_log)}
    sizes = {k: len(c) for k, c in enumerate(problem.candidates)}
    estimates: dict[int, np.ndarray] = {}
    for component in interaction_components(nodes, problem.compatible):
        edges = {
            pair: matrix
            for pair, matrix in problem.compatible.items()
            if pair[0] in component and pair[1] in component
        }
        result = None
        if len(component) > 1 and len(component) <= 52:
            try:
                result = exact_marginals(
                    component, edges, sizes, problem.config.max_factor_table, unary
                )
            except TableTooLarge:
                result = None
        for k in component:
            estimates[k] = result[k] if result else unary[k] / unary[k].sum()
    return [estimates[k] for k in nodes]


def marginals(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> list[np.ndarray] | None:
    """Each object's marginal over its candidates (``InferenceConfig.weighting``; the joint
    weight when ``joint``: exact marginals for an exhaustive enumeration); None when no
    sample has a positive weight."""
    if not any(math.isfinite(r.log_likelihood) for r in results):
        return None
    if not joint and problem.config.weighting == "hypothesis":
        unary = []
        for k, means in enumerate(hypothesis_log_likelihoods(results, problem)):
            # Candidates no sample chose get no probability, as with importance weights (every
            # sample's own choice is jointly feasible, so the constraints stay satisfiable); an
            # object whose samples all failed keeps its prior.
            chosen = np.isfinite(means)
            evidence = np.where(chosen, means, -np.inf) if chosen.any() else np.zeros(len(means))
            unary.append(evidence + problem.log_prior[k])
        return factor_marginals(unary, problem)
    log_weights = sample_log_weights(results, problem, joint=joint)
    estimates = []
    for k, candidates in enumerate(problem.candidates):
        column = log_weights[:, k]
        weights = np.exp(column - column.max())
        estimate = np.zeros(len(candidates))
        np.add.at(estimate, [r.choice[k] for r in results], weights)
        estimates.append(estimate / estimate.sum())
    return estimates


def sample_log_weights(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> np.ndarray:
    """(S, n) log importance weights per sample and object: per object
    (``object_log_weights``), or the joint weight repeated for every object when ``joint`` or
    ``InferenceConfig.weighting`` is "joint". With "hypothesis" weighting these per-object
    weights only serve as the effective-sample-size diagnostic of the summary."""
    if joint or problem.config.weighting == "joint":
        joint_weights = np.array([r.log_weight for r in results], dtype=float)
        return np.repeat(joint_weights[:, None], problem.count, axis=1)
    return object_log_weights(results, problem)


def effective_sample_size(log_weights: np.ndarray) -> float:
    """Kish's effective sample size of (S,) log importance weights (0 when none is finite)."""
    log_weights = np.asarray(log_weights, float)
    log_weights = log_weights[np.isfinite(log_weights)]
    if log_weights.size == 0:
        return 0.0
    weights = np.exp(log_weights - log_weights.max())
    return float(weights.sum() ** 2 / np.sum(weights**2))
