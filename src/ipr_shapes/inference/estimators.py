"""From evaluated samples to each object's marginal over its candidates (``InferenceConfig.weighting``):
per-hypothesis likelihoods combined by exact elimination, or per-object / joint importance
weights; the posterior over the scene's friction, over which the marginals are mixed; and the
effective sample size diagnostic."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from ipr_shapes.factor_graph import (
    TableTooLarge,
    exact_marginals,
    interaction_components,
    log_partition,
)
from ipr_shapes.inference.problem import InferenceProblem, SampleResult


def own_log_likelihoods(
    result: SampleResult, problem: InferenceProblem, *, rest: bool = True
) -> np.ndarray | None:
    """(F, n) each object's own term of Eq. 2 (log) per friction of ``result``: -alpha *
    decimation * its norms summed over the frames (each times its ``frame_weights``), plus
    (``rest``) its chosen candidate's rest term (``rest_log_likelihoods``, the same under
    every friction); -inf under a friction whose simulation failed; None when it failed under
    every friction."""
    if result.norms is None:
        return None
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    norms = np.asarray(result.norms, float)
    if problem.config.likelihood.pushed_frames != "each":
        norms = norms * problem.frame_weights()[None, : norms.shape[1], None]
    sums = norms.sum(axis=1)
    failed = ~np.isfinite(sums).all(axis=1)
    own = -scale * np.where(np.isfinite(sums), sums, 0.0)
    if rest:
        own = own + rest_log_likelihoods(result, problem)
    own[failed] = -np.inf
    return own


def rest_log_likelihoods(result: SampleResult, problem: InferenceProblem) -> np.ndarray:
    """(n,) each object's rest term in ``result`` (log; ``InferenceConfig.rest_drop_m``): log
    P(the object is at rest where seen | the joint model) = -drop / rest_drop_m (+ a
    constant), its chosen candidate's fall in its stability test among the others' chosen
    shapes (``SampleResult.drops``), under the exponential law of the fall of the candidates
    nearest the true shapes; zeros when off or not simulated, -inf for an infinite fall
    (flung)."""
    scale = problem.config.rest_drop_m
    if scale is None or result.drops is None:
        return np.zeros(problem.count)
    drops = np.abs([float(d[j]) for d, j in zip(result.drops, result.choice, strict=True)])
    return np.where(np.isfinite(drops), -drops / scale, -np.inf)


def rest_evidence(
    results: Sequence[SampleResult], problem: InferenceProblem
) -> list[np.ndarray] | None:
    """Per object k, (m_k,) log P(k at rest where seen | X_k = j) for every candidate j (module
    doc, step 3): the log mean over the samples whose other objects' choices are compatible
    with j (``InferenceProblem.compatibility``) of exp(-drop_kj / rest_drop_m), drop_kj being
    j's fall in the stability test among that sample's other chosen shapes
    (``SampleResult.drops``): the neighbours marginalised over the joint models drawn, for
    the candidates no sample chose too. A candidate compatible with no sampled context takes
    its object's least rest evidence. None when the rest evidence is off or no sample has
    it."""
    scale = problem.config.rest_drop_m
    rows = [r for r in results if scale is not None and r.drops is not None and r.norms is not None]
    if not rows:
        return None
    out = []
    for k, candidates in enumerate(problem.candidates):
        terms = np.full((len(rows), len(candidates)), -np.inf)
        usable = np.zeros((len(rows), len(candidates)), dtype=bool)
        for row, result in enumerate(rows):
            allowed = np.ones(len(candidates), dtype=bool)
            for i, j in enumerate(result.choice):
                if i != k:
                    allowed &= problem.compatibility(k, i)[:, j]
            drops = np.abs(np.asarray(result.drops[k], float))
            usable[row] = allowed
            terms[row] = np.where(np.isfinite(drops), -drops / scale, -np.inf)
        counts = usable.sum(axis=0)
        with np.errstate(divide="ignore"):
            summed = np.logaddexp.reduce(np.where(usable, terms, -np.inf), axis=0)
            evidence = np.where(counts > 0, summed - np.log(np.maximum(counts, 1)), np.nan)
        seen = np.isfinite(evidence)
        least = float(evidence[seen].min()) if seen.any() else 0.0
        out.append(np.where(counts > 0, evidence, least))
    return out


def at_friction(
    results: Sequence[SampleResult], problem: InferenceProblem, f: int
) -> list[SampleResult]:
    """The samples as scored under friction number ``f`` alone: norms (1, T, n) and that
    friction's log likelihood (norms None and -inf where its simulation failed)."""
    out = []
    for result in results:
        own = own_log_likelihoods(result, problem)
        if own is None or not np.isfinite(own[f]).all():
            out.append(dataclasses.replace(result, norms=None, log_likelihood=-math.inf))
        else:
            norms = result.norms[f : f + 1]
            out.append(dataclasses.replace(result, norms=norms, log_likelihood=float(own[f].sum())))
    return out


def _log_mean_exp(values: np.ndarray) -> np.ndarray:
    """log of the mean of exp(values) over the first axis (log terms averaged as
    probabilities); -inf entries count as zero probability."""
    values = np.asarray(values, dtype=float)
    return np.logaddexp.reduce(values, axis=0) - math.log(values.shape[0])


def object_log_weights(results: Sequence[SampleResult], problem: InferenceProblem) -> np.ndarray:
    """(S, n) per-object log importance weights of the samples (module doc):
    log P(O_i | X, mu) + log P(X_i) - log q_i, with object i's own term of Eq. 2 (averaged over
    the frictions, their uniform prior) and its own exploration probability; -inf for failed
    simulations."""
    weights = np.full((len(results), problem.count), -np.inf)
    for row, result in enumerate(results):
        own = own_log_likelihoods(result, problem)
        if own is None:
            continue
        own = _log_mean_exp(own)
        for k, j in enumerate(result.choice):
            weights[row, k] = (
                own[k]
                + float(problem.log_prior[k][j])
                + float(problem.surface_term(k)[j])
                - float(result.object_log_proposal[k])
            )
    return weights


def hypothesis_log_likelihoods(
    results: Sequence[SampleResult], problem: InferenceProblem
) -> list[np.ndarray]:
    """Per object, (m_k,) the log of the mean over the samples that chose each candidate of
    exp(its evidence term) (module doc, step 3): its object's own Eq. 2 term (the depth's; the
    rest evidence is ``rest_evidence``, over every sampled context), plus its
    neighbours' residual terms with ``InferenceConfig.evidence`` "neighbours"
    (``neighbour_residuals``); NaN for candidates no sample chose (the marginals give them the
    object's mean). Samples scored under several frictions take their first (``at_friction``
    picks another)."""
    choices, own = [], []
    for result in results:
        scored = own_log_likelihoods(result, problem, rest=False)
        if scored is None:
            continue
        choices.append(result.choice)
        own.append(scored[0])
    terms = np.array(own, dtype=float).reshape(len(own), problem.count)
    choices = np.array(choices, dtype=np.int64).reshape(len(own), problem.count)
    if problem.config.evidence == "neighbours":
        residuals = neighbour_residuals(choices, terms)
        terms = terms + np.stack(
            [residuals[:, list(problem.neighbours[k])].sum(axis=1) for k in range(problem.count)],
            axis=1,
        ).reshape(terms.shape)
    out = []
    for k, candidates in enumerate(problem.candidates):
        means = np.full(len(candidates), math.nan)
        for j in np.unique(choices[:, k]):
            values = terms[choices[:, k] == j, k]
            means[j] = _log_mean_exp(values)
        out.append(means)
    return out


def neighbour_residuals(choices: np.ndarray, terms: np.ndarray) -> np.ndarray:
    """(S, n) each object's Eq. 2 term (log) in each sample minus the log mean of exp(its term)
    over the samples that chose the same candidate for it: the part of its term that its own
    candidate does not explain, which the shapes it touches do (``InferenceConfig.evidence``).
    0 where a term is not finite (a failed simulation) and for a candidate drawn once.

    Args:
        choices: (S, n) each sample's candidate per object.
        terms: (S, n) each sample's own Eq. 2 term per object (log, -inf: failed).
    """
    residuals = np.zeros_like(terms)
    finite = np.isfinite(terms).all(axis=1)
    for k in range(terms.shape[1]):
        for j in np.unique(choices[finite, k]):
            rows = np.flatnonzero(finite & (choices[:, k] == j))
            values = terms[rows, k]
            residuals[rows, k] = values - _log_mean_exp(values)
    return residuals


def factor_marginals(
    unary_log: Sequence[np.ndarray], problem: InferenceProblem
) -> list[np.ndarray]:
    """Marginals of P(X) proportional to prod_k exp(unary_log[k][X_k]) times the pairwise
    constraints (``problem.compatible``), exact by variable elimination per connected group of
    interacting objects; a group whose tables would exceed ``max_factor_table`` (or that has
    no feasible assignment) combines its unary factors alone."""
    return _factor_marginals(unary_log, problem)[0]


def _factor_marginals(
    unary_log: Sequence[np.ndarray], problem: InferenceProblem, *, partition: bool = False
) -> tuple[list[np.ndarray], float]:
    """``factor_marginals`` and (``partition``) the log of the sum over the joint models of
    the product of exp(unary_log) and the constraints of the groups the marginals were exact
    in (a group that combines its unary factors alone is summed without them, as its
    marginals are); NaN when not asked."""
    nodes = list(range(problem.count))
    peaks = {k: float(np.max(u)) for k, u in enumerate(unary_log)}
    unary = {k: np.exp(u - peaks[k]) for k, u in enumerate(unary_log)}
    sizes = {k: len(c) for k, c in enumerate(problem.candidates)}
    estimates: dict[int, np.ndarray] = {}
    log_z = 0.0 if partition else math.nan
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
                if result and partition:
                    log_z += log_partition(
                        component, edges, sizes, problem.config.max_factor_table, unary
                    )
            except TableTooLarge:
                result = None
        for k in component:
            estimates[k] = result[k] if result else unary[k] / unary[k].sum()
            if partition:
                log_z += peaks[k] + (0.0 if result else float(np.log(unary[k].sum())))
    return [estimates[k] for k in nodes], log_z


def drawn_exact_marginals(
    results: Sequence[SampleResult], problem: InferenceProblem, unary_log: Sequence[np.ndarray]
) -> list[np.ndarray]:
    """``factor_marginals`` of ``unary_log`` (log evidence plus log prior per candidate) with
    each distinct joint model of ``results`` (scored under one friction) that the constraints
    allow scored by its own log likelihood plus log prior instead of the sum of its
    candidates' unary factors (0 for a failed simulation): P(X) proportional to P(O | X) P(X)
    for the models simulated, to prod_k exp(unary_log[k][X_k]) for the others
    (``InferenceConfig.drawn_models`` "exact", with the unary factors of "neighbours"
    evidence: the joint term's additive expansion to first order in the neighbours). Every
    joint model simulated: exhaustive search's marginals; none: the factorised ones. The sum
    over the joint models is exact per group of interacting objects (``_factor_marginals``);
    a model's correction (its own weight minus its factorised one) is added to the marginals
    of its candidates. Falls back to the factorised marginals when the corrected ones would
    not be a distribution."""
    estimates, log_z = _factor_marginals(unary_log, problem, partition=True)
    compatible = problem.compatible
    drawn: dict[tuple[int, ...], float] = {}
    for result in results:
        choice = tuple(int(j) for j in result.choice)
        if choice in drawn or not all(
            matrix[choice[a], choice[b]] for (a, b), matrix in compatible.items()
        ):
            continue
        own = result.log_likelihood + result.log_prior if result.norms is not None else -math.inf
        # The seen surfaces' fit (``surface_fit``) is a factor of the joint model as well.
        drawn[choice] = own + problem.surface_of(choice)
    if not drawn or not math.isfinite(log_z):
        return estimates
    choices = list(drawn)
    exact = np.array([drawn[c] for c in choices])
    factorised = np.array([sum(float(unary_log[k][j]) for k, j in enumerate(c)) for c in choices])
    scale = max(log_z, float(np.max(np.concatenate([exact, factorised]))))
    with np.errstate(under="ignore"):
        correction = np.exp(exact - scale) - np.exp(factorised - scale)
        base = math.exp(log_z - scale)
    out = []
    for k, estimate in enumerate(estimates):
        mass = estimate * base
        np.add.at(mass, [c[k] for c in choices], correction)
        mass = np.maximum(mass, 0.0)  # rounding: a model's own share of the sum, removed
        if not mass.sum() > 0:
            return estimates
        out.append(mass / mass.sum())
    return out


def friction_posterior(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> np.ndarray | None:
    """(F,) P(mu | O) over ``problem.friction_values`` (uniform prior), from the evidence each
    friction gives the same samples (module doc): with the joint weight (``joint`` or "joint"
    weighting), sum_s P(O | X_s, mu) P(X_s) / q(X_s); otherwise the product over objects of
    each object's evidence, as its marginal has it: for "hypothesis" weighting sum_j P(X_k^j)
    times candidate j's mean likelihood, over the candidates sampled; for "object" the sum of its
    per-object importance weights. None when no sample has a positive weight."""
    count = len(problem.friction_values)
    evidence = np.zeros(count)
    weighting = "joint" if joint else problem.config.weighting
    # The candidates sampled under any friction: each object's evidence sums over them.
    sampled = [np.zeros(len(c), dtype=bool) for c in problem.candidates]
    for result in results:
        if result.norms is not None:
            for k, j in enumerate(result.choice):
                sampled[k][j] = True
    for f in range(count):
        results_f = at_friction(results, problem, f)
        if not any(r.norms is not None for r in results_f):
            evidence[f] = -np.inf
        elif weighting == "joint":
            evidence[f] = np.logaddexp.reduce(
                [r.log_weight + problem.surface_of(r.choice) for r in results_f]
            )
        elif weighting == "object":
            weights = object_log_weights(results_f, problem)
            evidence[f] = float(np.logaddexp.reduce(weights, axis=0).sum())
        else:
            total = 0.0
            for k, means in enumerate(hypothesis_log_likelihoods(results_f, problem)):
                keep = sampled[k]
                prior = problem.log_prior[k][keep]
                mean = np.nan_to_num(means[keep], nan=-np.inf)  # no success under f: 0
                mean = mean + problem.surface_term(k)[keep]
                total += float(np.logaddexp.reduce(mean + prior - np.logaddexp.reduce(prior)))
            evidence[f] = total
    if not np.isfinite(evidence).any():
        return None
    posterior = np.exp(evidence - evidence.max())
    return posterior / posterior.sum()


def _exploration_ratio(results: Sequence[SampleResult], k: int, chosen: np.ndarray) -> np.ndarray:
    """(m_k,) log of object k's mean exploration probability per candidate over the samples,
    over the mean of the ``chosen`` candidates' (0 where the samples carry none: the
    stability tests' verdict on the candidates no sample chose, relative to those it did)."""
    rows = [r.exploration[k] for r in results if len(r.exploration) > k and r.exploration[k].size]
    if not rows:
        return np.zeros(chosen.size)
    explored = np.mean(rows, axis=0)
    reference = float(explored[chosen].mean())
    if reference <= 0:
        return np.zeros(chosen.size)
    with np.errstate(divide="ignore"):
        return np.log(explored / reference)


def hypothesis_unary(
    results: Sequence[SampleResult], problem: InferenceProblem
) -> list[np.ndarray]:
    """Per object, (m_k,) the log unary factor of "hypothesis" weighting from samples scored
    under one friction: each candidate's log evidence (``hypothesis_log_likelihoods``) plus its
    log prior. An object whose samples all failed keeps its prior; a candidate no sample
    chose takes the mean likelihood of its object's sampled candidates, scaled by its mean
    exploration probability against theirs (module doc, step 3). With the rest evidence
    (``InferenceConfig.rest_drop_m``) every candidate also gets its ``rest_evidence``, which
    then takes the place of the exploration ratio for the candidates no sample chose (both
    are the stability tests' verdict; the rest evidence is calibrated and measured in the
    whole joint models' contexts)."""
    rest = rest_evidence(results, problem)
    unary = []
    for k, means in enumerate(hypothesis_log_likelihoods(results, problem)):
        evidence = np.zeros(len(means))
        chosen = np.isfinite(means)
        if chosen.any():
            mean = np.logaddexp.reduce(means[chosen]) - math.log(int(chosen.sum()))
            if rest is None:
                evidence = np.where(chosen, means, mean + _exploration_ratio(results, k, chosen))
            else:
                evidence = np.where(chosen, means, mean)
        if rest is not None:
            evidence = evidence + rest[k]
        unary.append(evidence + problem.surface_term(k) + problem.log_prior[k])
    return unary


def _single_friction_marginals(
    results: Sequence[SampleResult], problem: InferenceProblem, joint: bool
) -> list[np.ndarray] | None:
    """``marginals`` of samples scored under one friction."""
    if not any(r.norms is not None for r in results):
        return None
    if not joint and problem.config.weighting == "hypothesis":
        if problem.config.drawn_models == "exact":
            # The undrawn models by the joint term's expansion to first order in the
            # neighbours (each candidate's own term plus its neighbours' residuals), whatever
            # ``evidence`` the output shape is chosen by.
            config = dataclasses.replace(problem.config, evidence="neighbours")
            first_order = hypothesis_unary(results, dataclasses.replace(problem, config=config))
            return drawn_exact_marginals(results, problem, first_order)
        return factor_marginals(hypothesis_unary(results, problem), problem)
    log_weights = sample_log_weights(results, problem, joint=joint)
    estimates = []
    for k, candidates in enumerate(problem.candidates):
        column = log_weights[:, k]
        weights = np.exp(column - column.max())
        estimate = np.zeros(len(candidates))
        np.add.at(estimate, [r.choice[k] for r in results], weights)
        estimates.append(estimate / estimate.sum())
    return estimates


def marginals(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> list[np.ndarray] | None:
    """Each object's marginal over its candidates (``InferenceConfig.weighting``; the joint
    weight when ``joint``: exact marginals for an exhaustive enumeration), summed over the
    frictions weighted by ``friction_posterior``: P(X_k | O) = sum_mu P(mu | O) P(X_k | O, mu);
    None when no sample has a positive weight."""
    if not any(math.isfinite(r.log_likelihood) for r in results):
        return None
    return _over_frictions(
        results, problem, lambda scored: _single_friction_marginals(scored, problem, joint), joint
    )


def _over_frictions(
    results: Sequence[SampleResult],
    problem: InferenceProblem,
    estimate: Callable[[Sequence[SampleResult]], list[np.ndarray] | None],
    joint: bool = False,
) -> list[np.ndarray] | None:
    """Per object, ``estimate`` (per-object (m_k,) weights from the samples scored under one
    friction, or None) summed over the frictions weighted by ``friction_posterior`` and
    normalised; with one friction, its own estimate. None when no friction gives one."""
    count = len(problem.friction_values)
    if count == 1:
        return estimate(at_friction(results, problem, 0))
    posterior = friction_posterior(results, problem, joint=joint)
    if posterior is None:
        return None
    mixed = [np.zeros(len(c)) for c in problem.candidates]
    for f in range(count):
        if posterior[f] == 0:
            continue
        values = estimate(at_friction(results, problem, f))
        if values is None:
            continue
        for k, v in enumerate(values):
            mixed[k] += posterior[f] * v
    if not all(m.sum() > 0 for m in mixed):
        return None
    return [m / m.sum() for m in mixed]


def medoid_weights(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> list[np.ndarray] | None:
    """Per object, (m_k,) the weights its output medoid is taken under: with "hypothesis"
    weighting (not ``joint``) each candidate's own unary factor (evidence times prior,
    ``hypothesis_unary``), normalised, every candidate being jointly feasible; mixed over the
    frictions by ``friction_posterior``. Not the marginals: a marginal also counts the joint
    models a candidate is in, i.e. how many of the neighbours' generated candidates it fits
    with (small candidates fit with more), as the Collision Checker's does
    (``ipr_shapes.collision_checker``, docs/experiments/2026-11-27-physics-posterior-weights.md).
    Other weightings: their marginals (sample frequencies, no constraint count). None when
    no sample has a positive weight."""
    if joint or problem.config.weighting != "hypothesis":
        return marginals(results, problem, joint=joint)
    if not any(math.isfinite(r.log_likelihood) for r in results):
        return None

    def own_evidence(scored: Sequence[SampleResult]) -> list[np.ndarray] | None:
        if not any(r.norms is not None for r in scored):
            return None
        weights = [np.exp(unary - np.max(unary)) for unary in hypothesis_unary(scored, problem)]
        return [w / w.sum() for w in weights]

    return _over_frictions(results, problem, own_evidence)


def sample_log_weights(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> np.ndarray:
    """(S, n) log importance weights per sample and object: per object
    (``object_log_weights``), or the joint weight repeated for every object when ``joint`` or
    ``InferenceConfig.weighting`` is "joint". With "hypothesis" weighting these per-object
    weights only serve as the effective-sample-size diagnostic of the summary."""
    if joint or problem.config.weighting == "joint":
        joint_weights = np.array(
            [r.log_weight + problem.surface_of(r.choice) for r in results], dtype=float
        )
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
