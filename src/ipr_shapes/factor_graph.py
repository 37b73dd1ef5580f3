"""Factor graphs over the objects' hypotheses: marginals of a product of unary factors and
0/1 pairwise compatibility factors, and the posterior medoid that turns a marginal into one shape.

Objects are nodes; a node's values are its candidate hypotheses; an edge (a, b) carries a
(m_a, m_b) bool matrix, False where the pair of shapes may not coexist (Constraints(X)).

- Components: the distribution factorises over the connected components of the interaction
  graph, so marginals are computed per component (``interaction_components``).
- Exact marginals: variable elimination, min-degree order, one ``numpy.einsum`` per
  eliminated node; its cost is the largest table of the elimination (m^(treewidth + 1)), not
  m^k (numpy's own contraction-path search made far larger tables).
- Sampled marginals: seeded single-site Gibbs chains from random restarts; a site takes a value
  uniformly among those with the fewest conflicts with its neighbours, which from a feasible
  state is Gibbs sampling of the uniform distribution over feasible assignments and from an
  infeasible one a min-conflicts search for one.
- Output shape: the Bayes choice under voxel-IoU loss, the hypothesis with the highest
  posterior-expected IoU against the others (``posterior_medoid``).

Used by the Collision Checker (uniform factors) and by the physics methods' "hypothesis"
weighting (each candidate's likelihood as its unary factor).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.products import ShapeHypothesis


def elimination_table_size(nodes: list[int], edges: Mapping[tuple[int, int], np.ndarray], sizes):
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

    ``sizes`` gives each node's number of values m_i; ``edges`` maps (a, b) to the (m_a, m_b)
    bool compatibility matrix. ``unary`` (optional) gives each object's non-negative (m_i,)
    factor over its values (default: ones, the uniform distribution over feasible
    assignments). Returns node -> (m_i,) float64 marginal summing to 1.

    Each step multiplies the factors that hold the eliminated object and sums it out in one
    ``numpy.einsum`` over their variables (cost: the table's size); tables are rescaled to a
    maximum of 1, since only normalised marginals are needed. Returns None when no assignment
    is feasible, and raises ``TableTooLarge`` when a table would exceed ``max_table`` entries.
    """
    base = _factors(nodes, edges, sizes, unary)
    marginals = {}
    for number, node in enumerate(nodes):
        eliminated = _eliminate(base, [sizes[i] for i in nodes], max_table, keep=number)
        if eliminated is None:
            return None
        counts = np.ones(sizes[node])
        for variables, table in eliminated[0]:  # the kept object's own unary factor is among them
            counts = counts * (table if variables else float(table))
        total = float(counts.sum())
        if total <= 0:
            return None
        marginals[node] = counts / total
    return marginals


def log_partition(
    nodes: list[int],
    edges: Mapping[tuple[int, int], np.ndarray],
    sizes: Mapping[int, int],
    max_table: float = np.inf,
    unary: Mapping[int, np.ndarray] | None = None,
) -> float:
    """log of the sum over every assignment of the product of the factors (the normaliser of
    ``exact_marginals``' distribution, same arguments): every node eliminated in the same
    min-degree order, each table's rescaling kept in log. -inf when no assignment is feasible;
    raises ``TableTooLarge`` as ``exact_marginals``."""
    eliminated = _eliminate(
        _factors(nodes, edges, sizes, unary), [sizes[i] for i in nodes], max_table, keep=None
    )
    if eliminated is None:
        return -np.inf
    factors, log_scale = eliminated
    total = float(np.prod([float(table) for _, table in factors]))
    return log_scale + float(np.log(total)) if total > 0 else -np.inf


#: A factor: the node positions it holds and its non-negative table over their values.
Factor = tuple[tuple[int, ...], np.ndarray]


def _factors(
    nodes: list[int],
    edges: Mapping[tuple[int, int], np.ndarray],
    sizes: Mapping[int, int],
    unary: Mapping[int, np.ndarray] | None,
) -> list[Factor]:
    """The graph's factors over node positions: each node's unary (ones when not given), then
    each edge's compatibility matrix, as float64 tables."""
    position = {node: number for number, node in enumerate(nodes)}
    unary = unary or {}
    factors = [
        ((position[i],), np.asarray(unary.get(i, np.ones(sizes[i])), dtype=np.float64))
        for i in nodes
    ]
    factors += [
        ((position[a], position[b]), matrix.astype(np.float64)) for (a, b), matrix in edges.items()
    ]
    return factors


def _eliminate(
    factors: list[Factor], size_of: list[int], max_table: float, keep: int | None
) -> tuple[list[Factor], float] | None:
    """Sum every position but ``keep`` out of ``factors`` in min-degree order (the smallest
    table first, ties to the lower position), one ``numpy.einsum`` per step, each new table
    rescaled to a maximum of 1: the factors left (over ``keep`` alone, or scalars) and the log
    of the rescalings' product. None when a table is all zero (no feasible assignment);
    raises ``TableTooLarge`` when a table would exceed ``max_table`` entries."""
    factors = list(factors)
    log_scale = 0.0
    remaining = set(range(len(size_of))) - ({keep} if keep is not None else set())
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
        log_scale += float(np.log(peak))
        factors = [f for f in factors if variable not in f[0]] + [(tuple(out), table / peak)]
        remaining.discard(variable)
    return factors, log_scale


class TableTooLarge(Exception):
    """Variable elimination would need a table above the configured size."""


def gibbs_marginals(
    nodes: list[int],
    edges: Mapping[tuple[int, int], np.ndarray],
    sizes: Mapping[int, int],
    rng: np.random.Generator,
    deadline: float,
    *,
    chains: int,
    sweeps: int,
    burn_in: int,
) -> dict[int, np.ndarray] | None:
    """Sampled marginals of the uniform distribution over feasible assignments (module doc):
    ``chains`` restarts of ``sweeps`` sweeps, counting feasible states ``burn_in`` sweeps after
    a chain first becomes feasible, until ``deadline`` (``time.perf_counter()`` seconds) once
    something was counted. ``edges`` and ``sizes`` as in ``exact_marginals``. Returns node ->
    (m_i,) marginal summing to 1; None when no chain found a feasible assignment."""
    neighbours: dict[int, list[tuple[int, np.ndarray]]] = {i: [] for i in nodes}
    for (a, b), matrix in edges.items():
        neighbours[a].append((b, ~matrix))  # conflicts of a's values given b's value
        neighbours[b].append((a, ~matrix.T))
    counts = {i: np.zeros(sizes[i]) for i in nodes}
    samples = 0
    for _ in range(chains):
        state = {i: int(rng.integers(sizes[i])) for i in nodes}
        feasible_since = None
        for sweep in range(sweeps):
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
                if sweep - feasible_since >= burn_in:
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


class PairwiseIoU:
    """Voxel IoU of pairs of one object's hypotheses (``hypotheses``, by index), each pair
    counted once and kept: the Collision Checker's medoid and a physics method's medoid of the
    same object ask for many of the same pairs (the candidates are among the Collision
    Checker's feasible hypotheses). Why: the voxel intersections are most of a medoid's cost
    (0.16 CPU-s for the 12 medoids of a 6-object ycb-dynamic scene,
    docs/experiments/2026-11-27-whole-run-speed-3.md)."""

    def __init__(self, hypotheses: Sequence[ShapeHypothesis]) -> None:
        self.hypotheses = hypotheses
        self._iou: dict[tuple[int, int], float] = {}

    def matrix(self, support: np.ndarray) -> np.ndarray:
        """(S, S) IoU of the hypotheses ``support`` (S,) (indices, increasing), ones on the
        diagonal."""
        iou = np.eye(support.size)
        keys: dict[int, np.ndarray] = {}
        for a in range(support.size):
            for b in range(a + 1, support.size):
                pair = (int(support[a]), int(support[b]))
                value = self._iou.get(pair)
                if value is None:
                    for k in pair:
                        if k not in keys:
                            keys[k] = self.hypotheses[k].keys()
                    first, second = keys[pair[0]], keys[pair[1]]
                    common = voxels.intersection_count(first, second)
                    union = float(first.size) + float(second.size) - common
                    value = self._iou[pair] = common / union if union > 0 else 0.0
                iou[a, b] = iou[b, a] = value
        return iou


def posterior_medoid(
    hypotheses: Sequence[ShapeHypothesis],
    probabilities: np.ndarray,
    table: PairwiseIoU | None = None,
    *,
    leave_one_out: bool = False,
) -> int:
    """Index of the hypothesis with the highest expected voxel IoU under ``probabilities``
    (the Bayes choice under IoU loss), among those with non-zero probability. ``table``: the
    pairs' IoU already computed for ``hypotheses`` (a ``PairwiseIoU`` of the same list; None:
    computed here), filled with the pairs computed. ``leave_one_out``: each hypothesis is
    scored against the others only (its own weight left out and the rest renormalised): the
    candidates are draws standing for a continuum of shapes, and matching itself (IoU 1) is a
    vote of its own weight, which with unequal weights favours a heavy lone candidate (with
    equal weights it is the same choice)."""
    support = np.flatnonzero(probabilities > 0)
    if support.size <= 1:
        return int(support[0]) if support.size else 0
    if table is None:
        table = PairwiseIoU(hypotheses)
    elif table.hypotheses is not hypotheses:
        raise ValueError("the IoU table belongs to another list of hypotheses")
    weights = probabilities[support]
    expected = table.matrix(support) @ weights
    if leave_one_out:
        expected = (expected - weights) / np.maximum(weights.sum() - weights, 1e-300)
    return int(support[int(np.argmax(expected))])
