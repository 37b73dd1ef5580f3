"""The paper's Collision Checker baseline: IPR with a uniform prior and no physics.

Every object gets hypotheses (Algorithm 1); the posterior over joint models is uniform over
those that satisfy Constraints(X) (``ipr.constraints``), and each object's output is read from
its marginal over its own hypotheses.

- Unary-infeasible hypotheses (below the support, in seen-free space, in walls) get probability
  0. An object with no feasible hypothesis is represented by its minimum shape
  (``ipr.hypotheses.minimum_shape``) alone, with probability 1.
- Interactions: two objects interact when some pair of their hypotheses is incompatible
  (penetration beyond the tolerance). The joint space is m^n, but the uniform distribution
  factorises over the connected components of the interaction graph, so marginals are computed
  per component.
- Exact marginals: counting feasible assignments is a sum over a product of 0/1 pairwise
  factors, computed by variable elimination (min-degree order, one ``numpy.einsum`` per
  eliminated object; numpy's own contraction-path search produced tables far larger than
  min-degree elimination, 12 s instead of milliseconds on a 7-object scene). It is exact and
  its cost is set by the largest table of the elimination (m^(treewidth + 1)), not by m^k: a
  chain of 8 objects with 32 hypotheses each costs 32^2 per step where enumeration would visit
  32^8. Components whose elimination (min-degree estimate) needs a table above
  ``max_exact_table`` entries use the sampler instead. Brute-force enumeration is never needed.
- Sampled marginals: seeded single-site Gibbs chains from random restarts. A site takes a value
  uniformly among those with the fewest conflicts with its neighbours; from a feasible state
  these are exactly the feasible values, so the chain is Gibbs sampling of the uniform
  distribution over feasible assignments, and from an infeasible state it is a min-conflicts
  search for one. Only feasible states after a burn-in are counted. Chains may fail to cross
  between feasible regions that no single change connects; restarts reduce that bias.
- No feasible joint assignment in a component (noisy or concave objects): the pairwise
  tolerance of that component is doubled, up to ``relax_steps`` times, then its pairwise
  constraints are dropped (each object uniform over its feasible hypotheses); logged.
- Output shape: the Bayes choice under IoU loss, the hypothesis with the highest
  posterior-expected voxel IoU against the others (a posterior medoid), among hypotheses with
  non-zero probability; the minimum shape when no hypothesis is feasible.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ipr import voxels
from ipr.constraints import (
    ConstraintConfig,
    OverlapCache,
    overlap_threshold,
    unary_feasible,
)
from ipr.hypotheses import (
    HypothesisConfig,
    ShapeHypothesis,
    generate_hypotheses,
    minimum_shape,
    volume_spread,
)
from ipr.perception.free_space import SeenSpace, SpaceMap
from ipr.perception.types import KnownPlane, PartialObject

logger = logging.getLogger(__name__)

METHOD = "collision-checker"


@dataclass(frozen=True)
class CollisionCheckerConfig:
    """Settings of the Collision Checker.

    Attributes:
        hypotheses: hypothesis generation (m, D_min, tolerances, per-object timeout).
        constraints: constraint tolerances.
        max_exact_table: largest elimination table (entries) for exact marginals.
        gibbs_chains: restarts of the sampler per component.
        gibbs_sweeps: sweeps per chain (each visits every object of the component once).
        gibbs_burn_in: sweeps after a chain first becomes feasible before counting.
        relax_steps: doublings of the pairwise tolerance before dropping a component's
            pairwise constraints when nothing is jointly feasible.
        generation_share: share of ``time_budget_s`` given to hypothesis generation.
    """

    hypotheses: HypothesisConfig = field(default_factory=HypothesisConfig)
    constraints: ConstraintConfig = field(default_factory=ConstraintConfig)
    max_exact_table: int = 2_000_000
    gibbs_chains: int = 4
    gibbs_sweeps: int = 300
    gibbs_burn_in: int = 30
    relax_steps: int = 3
    generation_share: float = 0.6


@dataclass(frozen=True, eq=False)
class ObjectPosterior:
    """Marginal posterior of one object's shape.

    Attributes:
        object_id: the PartialObject's id.
        hypotheses: its hypotheses (all m generated), or just its minimum shape when none
            is feasible.
        probabilities: (len(hypotheses),) marginal probabilities, summing to 1.
        best: index (into ``hypotheses``) of the output shape.
        minimum: the object's minimum shape.
        inference: "exact", "gibbs", "independent" (no interacting neighbour), or
            "relaxed-exact"/"relaxed-gibbs"/"dropped" when the constraints had to be relaxed,
            "minimum" when no hypothesis is feasible.
        generation_s: seconds spent generating its hypotheses (and minimum shape).
        output_meshes: per hypothesis, the (vertices, faces) written in its place, or None to
            write the hypothesis itself (``ipr.carving`` sets it); None: write every
            hypothesis as it is.
    """

    object_id: int
    hypotheses: tuple[ShapeHypothesis, ...]
    probabilities: np.ndarray
    best: int
    minimum: ShapeHypothesis
    inference: str
    generation_s: float = 0.0
    output_meshes: tuple[tuple[np.ndarray, np.ndarray] | None, ...] | None = None

    @property
    def best_hypothesis(self) -> ShapeHypothesis:
        """The most probable hypothesis (convex, as inferred)."""
        return self.hypotheses[self.best]

    def written_mesh(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces) written for hypothesis k: its carved shape if any, else itself."""
        if self.output_meshes is not None and self.output_meshes[k] is not None:
            return self.output_meshes[k]
        return self.hypotheses[k].mesh

    @property
    def output_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces) of the output shape (``best.ply``)."""
        return self.written_mesh(self.best)


# --------------------------------------------------------------------------------------------
# Marginals of the uniform distribution over feasible joint assignments


def _elimination_table(nodes: list[int], edges: Mapping[tuple[int, int], np.ndarray], sizes):
    """Largest table (entries) of min-degree variable elimination over ``nodes``."""
    neighbours = {i: set() for i in nodes}
    for a, b in edges:
        neighbours[a].add(b)
        neighbours[b].add(a)
    largest = 1
    remaining = set(nodes)
    while remaining:
        node = min(remaining, key=lambda i: (len(neighbours[i]), i))
        table = sizes[node] * int(np.prod([sizes[j] for j in neighbours[node]], dtype=float))
        largest = max(largest, table)
        for j in neighbours[node]:
            neighbours[j] |= neighbours[node] - {j}
            neighbours[j].discard(node)
        remaining.discard(node)
        del neighbours[node]
    return largest


def exact_marginals(
    nodes: list[int],
    edges: Mapping[tuple[int, int], np.ndarray],
    sizes: Mapping[int, int],
    max_table: float = np.inf,
    unary: Mapping[int, np.ndarray] | None = None,
) -> dict[int, np.ndarray] | None:
    """Exact marginals by variable elimination (one min-degree elimination per object).

    ``unary`` (optional) gives each object's non-negative factor over its values (default:
    ones, the uniform distribution over feasible assignments).

    Each step multiplies the factors that hold the eliminated object and sums it out in one
    ``numpy.einsum`` over their variables (cost: the table's size); tables are rescaled to a
    maximum of 1, since only normalised marginals are needed. Returns None when no assignment
    is feasible, and raises ``TableTooLarge`` when a table would exceed ``max_table`` entries.
    """
    position = {node: number for number, node in enumerate(nodes)}
    unary = unary or {}
    base = [
        ((position[i],), np.asarray(unary.get(i, np.ones(sizes[i])), dtype=np.float64))
        for i in nodes
    ]
    base += [
        ((position[a], position[b]), matrix.astype(np.float64)) for (a, b), matrix in edges.items()
    ]
    size_of = [sizes[i] for i in nodes]
    marginals = {}
    for node in nodes:
        keep = position[node]
        factors = list(base)
        remaining = set(range(len(nodes))) - {keep}
        while remaining:

            def scope(v: int, factors=factors) -> set[int]:
                return set().union(*(set(f[0]) for f in factors if v in f[0]))

            variable = min(remaining, key=lambda v: (np.prod([size_of[u] for u in scope(v)]), v))
            union = sorted(scope(variable))
            if float(np.prod([size_of[u] for u in union], dtype=float)) > max_table:
                raise TableTooLarge
            involved = [f for f in factors if variable in f[0]]
            out = [u for u in union if u != variable]
            operands: list = []
            for variables, table in involved:
                operands += [table, list(variables)]
            table = np.einsum(*operands, out)
            peak = float(table.max()) if table.size else 0.0
            if peak <= 0:
                return None
            factors = [f for f in factors if variable not in f[0]] + [(tuple(out), table / peak)]
            remaining.discard(variable)
        counts = np.ones(sizes[node])
        for variables, table in factors:  # the kept object's own unary factor is among them
            counts = counts * (table if variables else float(table))
        total = float(counts.sum())
        if total <= 0:
            return None
        marginals[node] = counts / total
    return marginals


class TableTooLarge(Exception):
    """Variable elimination would need a table above the configured size."""


def _gibbs_marginals(
    nodes: list[int],
    edges: Mapping[tuple[int, int], np.ndarray],
    sizes: Mapping[int, int],
    config: CollisionCheckerConfig,
    rng: np.random.Generator,
    deadline: float,
) -> dict[int, np.ndarray] | None:
    """Sampled marginals (module doc); None when no chain found a feasible assignment."""
    neighbours: dict[int, list[tuple[int, np.ndarray]]] = {i: [] for i in nodes}
    for (a, b), matrix in edges.items():
        neighbours[a].append((b, ~matrix))  # conflicts of a's values given b's value
        neighbours[b].append((a, ~matrix.T))
    counts = {i: np.zeros(sizes[i]) for i in nodes}
    samples = 0
    for _ in range(config.gibbs_chains):
        state = {i: int(rng.integers(sizes[i])) for i in nodes}
        feasible_since = None
        for sweep in range(config.gibbs_sweeps):
            for i in rng.permutation(nodes):
                conflicts = np.zeros(sizes[i], dtype=np.int64)
                for j, clash in neighbours[i]:
                    conflicts += clash[:, state[j]]
                best = np.flatnonzero(conflicts == conflicts.min())
                state[i] = int(best[rng.integers(best.size)])
            violated = sum(int(~m[state[a], state[b]]) for (a, b), m in edges.items())
            if violated == 0:
                if feasible_since is None:
                    feasible_since = sweep
                if sweep - feasible_since >= config.gibbs_burn_in:
                    for i in nodes:
                        counts[i][state[i]] += 1
                    samples += 1
            if time.perf_counter() > deadline and samples > 0:
                break
        if time.perf_counter() > deadline and samples > 0:
            break
    if samples == 0:
        return None
    return {i: counts[i] / counts[i].sum() for i in nodes}


def interaction_components(
    nodes: list[int], edges: Mapping[tuple[int, int], np.ndarray]
) -> list[list[int]]:
    """Connected components (sorted lists) of the interaction graph."""
    parent = {i: i for i in nodes}

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in edges:
        parent[root(a)] = root(b)
    groups: dict[int, list[int]] = {}
    for i in nodes:
        groups.setdefault(root(i), []).append(i)
    return [sorted(g) for g in groups.values()]


def _component_marginals(
    component: list[int],
    depths: Mapping[tuple[int, int], np.ndarray],
    thresholds: Mapping[tuple[int, int], float],
    sizes: Mapping[int, int],
    config: CollisionCheckerConfig,
    rng: np.random.Generator,
    deadline: float,
) -> tuple[dict[int, np.ndarray], str]:
    """Marginals of one component and how they were obtained (module doc)."""
    inside = [pair for pair in depths if pair[0] in component and pair[1] in component]
    for step in range(config.relax_steps + 1):
        edges = {pair: depths[pair] <= thresholds[pair] * 2.0**step for pair in inside}
        edges = {pair: m for pair, m in edges.items() if not m.all()}
        exact = _elimination_table(component, edges, sizes) <= config.max_exact_table
        if exact and len(component) <= 52:  # einsum's sublist format has 52 indices
            try:
                marginals = exact_marginals(component, edges, sizes, config.max_exact_table)
                how = "exact"
            except TableTooLarge:
                exact = False
        if not exact or len(component) > 52:
            marginals = _gibbs_marginals(component, edges, sizes, config, rng, deadline)
            how = "gibbs"
        if marginals is not None:
            if step:
                logger.info(
                    "objects %s: feasible only with %gx the overlap tolerance", component, 2**step
                )
                how = f"relaxed-{how}"
            return marginals, how
    logger.warning(
        "objects %s: no jointly feasible assignment even with relaxed tolerances; their "
        "pairwise constraints are dropped",
        component,
    )
    return {i: np.full(sizes[i], 1.0 / sizes[i]) for i in component}, "dropped"


def posterior_medoid(hypotheses: Sequence[ShapeHypothesis], probabilities: np.ndarray) -> int:
    """Index of the hypothesis with the highest expected voxel IoU under ``probabilities``
    (the Bayes choice under IoU loss), among those with non-zero probability."""
    support = np.flatnonzero(probabilities > 0)
    if support.size <= 1:
        return int(support[0]) if support.size else 0
    keys = [hypotheses[k].keys() for k in support]
    sizes = np.array([k.size for k in keys], dtype=float)
    iou = np.eye(support.size)
    for a in range(support.size):
        for b in range(a + 1, support.size):
            common = voxels.intersection_count(keys[a], keys[b])
            union = sizes[a] + sizes[b] - common
            iou[a, b] = iou[b, a] = common / union if union > 0 else 0.0
    expected = iou @ probabilities[support]
    return int(support[int(np.argmax(expected))])


# --------------------------------------------------------------------------------------------
# Public API


@dataclass(frozen=True, eq=False)
class PreparedHypotheses:
    """Hypotheses of every object with their unary and pairwise constraints (shared by the
    Collision Checker and the physics-based methods).

    Attributes:
        ids: object ids in the order of the objects given.
        generated: id -> all generated hypotheses (just the minimum shape when none is
            unary-feasible).
        minima: id -> minimum shape.
        candidates: id -> indices into ``generated[id]`` of the unary-feasible hypotheses.
        seconds: id -> seconds spent generating.
        depths: (a, b) -> (len(candidates[a]), len(candidates[b])) penetration depths (m) for
            interacting pairs (a before b in ``ids``); pairs absent never conflict.
        thresholds: (a, b) -> the largest allowed depth (m) for that pair.
    """

    ids: list[int]
    generated: dict[int, tuple[ShapeHypothesis, ...]]
    minima: dict[int, ShapeHypothesis]
    candidates: dict[int, list[int]]
    seconds: dict[int, float]
    depths: dict[tuple[int, int], np.ndarray]
    thresholds: dict[tuple[int, int], float]


def prepare_hypotheses(
    objects: tuple[PartialObject, ...],
    space: SpaceMap | None,
    planes: tuple[KnownPlane, ...],
    config: CollisionCheckerConfig | None = None,
    rng: np.random.Generator | None = None,
    time_budget_s: float | None = None,
    object_spaces: Mapping[int, SeenSpace] | None = None,
) -> PreparedHypotheses:
    """Generate each object's hypotheses and minimum shape, keep the unary-feasible ones and
    measure the pairwise penetration depths between interacting objects' hypotheses.

    ``object_spaces``: per object id, the seen-free space to use for that object instead of
    ``space`` (``ipr.fusion.tracked_free_spaces``: later frames' free space through the
    object's registered motion).

    ``time_budget_s``: generation gets ``generation_share`` of it, split over the objects
    (capping their timeouts). ``rng`` defaults to one seeded from ``config.hypotheses.seed``;
    each object draws from its own child stream (``rng.spawn``).
    """
    config = config or CollisionCheckerConfig()
    rng = rng if rng is not None else np.random.default_rng(config.hypotheses.seed)
    ids = [int(obj.id) for obj in objects]
    if len(set(ids)) != len(ids):
        raise ValueError(f"object ids must be distinct, got {ids}")
    hypothesis_config = config.hypotheses
    if time_budget_s is not None:
        per_object = config.generation_share * time_budget_s / max(len(objects), 1)
        hypothesis_config = dataclasses.replace(
            hypothesis_config,
            timeout_s=per_object
            if hypothesis_config.timeout_s is None
            else min(hypothesis_config.timeout_s, per_object),
        )
    object_rngs = rng.spawn(len(objects))

    generated: dict[int, tuple[ShapeHypothesis, ...]] = {}
    minima: dict[int, ShapeHypothesis] = {}
    candidates: dict[int, list[int]] = {}  # object -> indices of unary-feasible hypotheses
    seconds: dict[int, float] = {}
    for obj, object_rng in zip(objects, object_rngs, strict=True):
        begin = time.perf_counter()
        seen = (object_spaces or {}).get(obj.id, space)
        hyps = generate_hypotheses(obj, seen, planes, hypothesis_config, object_rng)
        minima[obj.id] = minimum_shape(obj, planes, hypothesis_config)
        feasible = [
            k
            for k, h in enumerate(hyps)
            if unary_feasible(h, seen, planes, config.hypotheses.unary)
        ]
        if not feasible:
            logger.warning("object %d: no feasible hypothesis; using its minimum shape", obj.id)
            hyps = (minima[obj.id],)
            feasible = [0]
        generated[obj.id], candidates[obj.id] = hyps, feasible
        seconds[obj.id] = time.perf_counter() - begin
        logger.debug(
            "object %d: %d/%d feasible, volumes %s",
            obj.id,
            len(feasible),
            len(hyps),
            volume_spread(hyps),
        )

    # Pairwise penetration depths between the feasible hypotheses of objects whose hypotheses'
    # bounding boxes overlap by more than the tolerance.
    chosen = {i: [generated[i][k] for k in candidates[i]] for i in ids}
    cache = OverlapCache([h for i in ids for h in chosen[i]])
    tolerance = config.constraints.overlap_tolerance_m
    envelopes = {
        i: np.stack([np.min([h.bounds[0] for h in chosen[i]], axis=0),
                     np.max([h.bounds[1] for h in chosen[i]], axis=0)])
        for i in ids
    }  # fmt: skip
    depths: dict[tuple[int, int], np.ndarray] = {}
    thresholds: dict[tuple[int, int], float] = {}
    for position, a in enumerate(ids):
        for b in ids[position + 1 :]:
            bound = np.min(
                np.minimum(envelopes[a][1], envelopes[b][1])
                - np.maximum(envelopes[a][0], envelopes[b][0])
            )
            if bound <= tolerance:
                continue
            matrix = cache.depth_matrix(chosen[a], chosen[b], exact_above_m=tolerance)
            threshold = overlap_threshold(matrix, config.constraints, a, b)
            if (matrix > threshold).any():
                depths[(a, b)], thresholds[(a, b)] = matrix, threshold
    logger.debug("hypotheses prepared: %d depth queries", cache.queries)
    return PreparedHypotheses(ids, generated, minima, candidates, seconds, depths, thresholds)


def uniform_posteriors(
    prepared: PreparedHypotheses,
    config: CollisionCheckerConfig | None = None,
    rng: np.random.Generator | None = None,
    deadline: float = np.inf,
) -> list[ObjectPosterior]:
    """The Collision Checker's marginals from prepared hypotheses (module doc): uniform over
    jointly feasible joint models; the Gibbs sampler stops at ``deadline``
    (``time.perf_counter()`` seconds)."""
    config = config or CollisionCheckerConfig()
    rng = rng if rng is not None else np.random.default_rng(config.hypotheses.seed)
    ids, generated, candidates = prepared.ids, prepared.generated, prepared.candidates
    sizes = {i: len(candidates[i]) for i in ids}
    marginals: dict[int, np.ndarray] = {}
    how: dict[int, str] = {}
    for component in interaction_components(ids, prepared.depths):
        if len(component) == 1:
            i = component[0]
            marginals[i] = np.full(sizes[i], 1.0 / sizes[i])
            how[i] = "independent"
            continue
        result, method = _component_marginals(
            component, prepared.depths, prepared.thresholds, sizes, config, rng, deadline
        )
        for i in component:
            marginals[i], how[i] = result[i], method

    posteriors = []
    for i in ids:
        hyps = generated[i]
        probabilities = np.zeros(len(hyps))
        probabilities[candidates[i]] = marginals[i]
        probabilities /= probabilities.sum()
        inference = "minimum" if hyps[0].index == -1 else how[i]
        posteriors.append(
            ObjectPosterior(
                i,
                hyps,
                probabilities,
                posterior_medoid(hyps, probabilities),
                prepared.minima[i],
                inference,
                prepared.seconds[i],
            )
        )
    return posteriors


def collision_checker(
    objects: tuple[PartialObject, ...],
    space: SpaceMap | None,
    planes: tuple[KnownPlane, ...],
    config: CollisionCheckerConfig | None = None,
    rng: np.random.Generator | None = None,
    time_budget_s: float | None = None,
    object_spaces: Mapping[int, SeenSpace] | None = None,
) -> list[ObjectPosterior]:
    """Marginal shape posteriors of the objects of one frame (frame 0) under a uniform prior
    restricted to jointly feasible models (module doc).

    Args:
        objects: the frame's partial objects (distinct ids).
        space: the frame's free-space map (None: no free-space constraint).
        planes: the frame's support and walls.
        config: settings (defaults: ``CollisionCheckerConfig()``).
        rng: random source (default: seeded from ``config.hypotheses.seed``).
        time_budget_s: total seconds; generation gets ``generation_share`` of it (split over
            the objects, capping their timeouts) and the sampler stops at the end of it.
        object_spaces: per object id, a seen-free space replacing ``space`` for that object
            (``prepare_hypotheses``).

    Returns:
        One ObjectPosterior per object, in the order of ``objects``.
    """
    config = config or CollisionCheckerConfig()
    rng = rng if rng is not None else np.random.default_rng(config.hypotheses.seed)
    started = time.perf_counter()
    deadline = np.inf if time_budget_s is None else started + time_budget_s
    generation_rng, sampler_rng = rng.spawn(2)
    prepared = prepare_hypotheses(
        objects, space, planes, config, generation_rng, time_budget_s, object_spaces
    )
    posteriors = uniform_posteriors(prepared, config, sampler_rng, deadline)
    logger.debug(
        "collision checker: %d objects in %.3f s", len(objects), time.perf_counter() - started
    )
    return posteriors


def write_posterior_result(
    out_dir: Path | str,
    posteriors: Sequence[ObjectPosterior],
    world_from_camera: Mapping[int, np.ndarray],
    timing_s: Mapping[str, float] | None = None,
    *,
    method: str = METHOD,
    extra: Mapping | None = None,
    extra_files: Mapping[str, bytes] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write a result directory (``ipr.result.write_result``) from per-object posteriors: per
    object its output shape as ``best.ply`` and its hypotheses with non-zero probability
    (renormalised against rounding) as weighted hypotheses.

    ``world_from_camera``: frame id -> (4, 4) OpenCV camera-to-world (frame 0 required).
    ``extra["objects_summary"]`` records each object's id, inference mode and volumes;
    ``extra`` adds further keys and ``extra_files`` further files (name -> bytes).
    """
    from ipr.result import write_result

    objects, summary = [], []
    for posterior in posteriors:
        keep = np.flatnonzero(posterior.probabilities > 0)
        weights = posterior.probabilities[keep] / posterior.probabilities[keep].sum()
        hypotheses = [
            (posterior.written_mesh(k), float(w)) for k, w in zip(keep, weights, strict=True)
        ]
        best_probability = float(posterior.probabilities[posterior.best])
        objects.append((posterior.output_mesh, hypotheses, best_probability))
        summary.append(
            {
                "object_id": posterior.object_id,
                "inference": posterior.inference,
                "hypotheses": len(posterior.hypotheses),
                "nonzero": int(keep.size),
                "best_volume_m3": posterior.best_hypothesis.volume_m3,
                "carved": posterior.output_meshes is not None
                and posterior.output_meshes[posterior.best] is not None,
                "volumes_m3": volume_spread(posterior.hypotheses),
                "generation_s": posterior.generation_s,
            }
        )
    return write_result(
        out_dir,
        method,
        dict(world_from_camera),
        objects,
        timing_s,
        {"objects_summary": summary, **dict(extra or {})},
        extra_files=extra_files,
        overwrite=overwrite,
    )


def write_collision_checker_result(
    out_dir: Path | str,
    posteriors: Sequence[ObjectPosterior],
    world_from_camera: Mapping[int, np.ndarray],
    timing_s: Mapping[str, float] | None = None,
    *,
    overwrite: bool = False,
) -> Path:
    """``write_posterior_result`` for the Collision Checker (method "collision-checker")."""
    return write_posterior_result(
        out_dir, posteriors, world_from_camera, timing_s, overwrite=overwrite
    )
