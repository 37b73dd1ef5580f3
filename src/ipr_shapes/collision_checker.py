"""The paper's Collision Checker baseline: IPR with a uniform prior and no physics.

Every object gets hypotheses (``ipr_shapes.hypotheses.prepare_hypotheses``: Algorithm 1 and the unary
constraints); the posterior over joint models is uniform over those that satisfy
Constraints(X), and each object's output is read from its marginal over its own hypotheses.

- Unary-infeasible hypotheses (below the support, in seen-free space, in walls) get probability
  0. An object with no feasible hypothesis is represented by its minimum shape alone, with
  probability 1.
- The uniform distribution factorises over the connected components of the interaction graph
  (objects some pair of whose hypotheses penetrate beyond the tolerance); each component's
  marginals are exact by variable elimination (``ipr_shapes.factor_graph``) unless its largest table
  would exceed ``max_exact_table`` entries, then sampled by Gibbs chains.
- No feasible joint assignment in a component (noisy or concave objects): the pairwise
  tolerance of that component is doubled, up to ``relax_steps`` times, then its pairwise
  constraints are dropped (each object uniform over its feasible hypotheses); logged.
- Output shape: the medoid under voxel IoU of the jointly feasible hypotheses (non-zero
  probability): the Bayes choice under IoU loss; the minimum shape when no hypothesis is
  feasible. The marginals themselves are not the weights: a candidate's marginal also counts
  the joint models it is in, i.e. how many of its neighbours' *generated* candidates it fits
  with, which says how the neighbours were sampled, not what this object is; small candidates
  fit with more and the marginals fall with volume (median correlation of marginal and log
  volume -0.57 on 75 development objects), so their medoid leaned small (docs/experiments/
  2026-11-27-thin-candidates-overlap.md). The marginals are still the written probabilities.
- Medoid weights (``CollisionCheckerConfig.medoid_weights``): "candidate" weights
  each feasible candidate equally. "family" (opt-in) gives each generator family
  (``ShapeHypothesis.generator``: Algorithm 1, symmetry, box, sphere, ...) with a jointly
  feasible candidate an equal share, split equally among its feasible candidates: a uniform
  prior over the families that explain the object, then over each family's candidates. How
  many candidates a family holds is the configuration's slot budget (Algorithm 1 makes half
  of them, the superquadric three), not evidence about the object; with each candidate
  counted once, Algorithm 1's many near-copies decide the medoid, and for an occluded object
  they are mostly its seen part mirrored short. Each candidate is then scored against the
  others only (``posterior_medoid``'s leave-one-out), so that a family's lone candidate does
  not vote for itself with its family's whole share. Opt-in: it gains on the development
  sets and loses on ycb-static and bins-real, where a wrong family's equal share is an equal
  say (docs/experiments/2026-11-28-collision-checker-choice.md).
- "outline" (opt-in) trusts the families per object as far as the object's image outline is
  hidden: the weights are ``1 - h`` each candidate once and ``h`` each family an equal share,
  ``h`` the fraction of the object's frame-0 outline behind which a nearer surface or the
  image border hides its continuation (``ipr_shapes.perception.outline``; measured by the
  pipeline's Collision Checker run and ``benchmarks.hypothesis_ceiling``; an object with no
  measure, as in the physics methods' starting answer, counts each candidate once). An object
  whose outline is all its own keeps the default's choice bit for bit. Opt-in: it gains on two
  development sets and loses on ycb-static; no per-object signal tried (hidden outline, the
  candidates' continuation behind the occluders, the families' agreement, the visible
  fraction itself) tells which family to trust there
  (docs/experiments/2026-11-28-per-object-family-trust.md).
- "fit" (opt-in) weighs each family's share by how well its candidates' surfaces pass
  through the object's observed points (``fit_weights``): every candidate contains the
  points (they are built on them), so a point's distance to a candidate's boundary (to the
  faces turned towards the camera that saw the point: a face behind it, a thin candidate's far
  side, explains nothing) is how far the candidate's surface runs from the seen surface there; the excess of that distance over
  the closest candidate's, per point, is the candidate's misfit (what all candidates share,
  the object's concavity and noise, cancels), scored as a Gaussian likelihood whose variance
  is the voxel quantisation (pitch^2 / 12) plus the shared part's mean square. A sphere whose
  surface runs through a box's faces loses its family's share; a family that fits the seen
  surface keeps it. An object whose points are not given (the physics methods' starting
  answer) counts each candidate once. Opt-in (docs/experiments/2026-11-28-family-choice.md): on
  bins-real the seen box tops lie on every family's candidate within the real sensor's scatter,
  the fit hardly moves the families' shares and their equal prior loses there
  (docs/experiments/2026-11-28-fit-outline.md).
- "outline-fit" (the default since 2026-11-28): ``1 - h`` each candidate once (as "outline")
  and ``h`` the fit weights: where the outline is the object's own, Algorithm 1's mirrored
  copies are evidence of its extent; where it is hidden, the families share it as far as
  their surfaces pass through what was seen. ``h = 0``, or no measure (the physics methods'
  starting answer), is "candidate"'s choice bit for bit, and the points are not measured. It
  gains or holds on every set measured, where "fit" and "family" lose on bins-real
  (docs/experiments/2026-11-28-fit-outline.md).
- The medoid's own vote (``CollisionCheckerConfig.medoid_self``): with unequal weights a
  candidate's own weight used to be left out of its score (``posterior_medoid``'s
  leave-one-out, so that a heavy lone candidate does not win by matching itself), which also
  makes the choice blind to the candidate's own weight: it went to light candidates lying
  between heavier clusters (a ball's revolution of weight 0.03 and IoU 0.72 over its sphere of
  0.11 and 0.98). "nearest" (opt-in, ``nearest_medoid``) credits each candidate its own
  weight times its IoU with its nearest other candidate: the truth drawn at a candidate is a
  shape like it, as close as the sample's nearest draw. It gains on six sets in the benchmark
  and loses dev 9200 (0.656 -> 0.648: an object with two candidates, which both rules score by
  their mutual IoU, a tie that floating-point rounding breaks), and it does not stop a
  generator option's new, better-fitting candidates from moving the medoid
  (docs/experiments/2026-11-28-medoid-self-vote.md).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ipr_shapes.checks import Checks, Interval, Options, check_fields
from ipr_shapes.factor_graph import (
    PairwiseIoU,
    TableTooLarge,
    elimination_table_size,
    exact_marginals,
    gibbs_marginals,
    interaction_components,
    posterior_medoid,
)
from ipr_shapes.hypotheses import (
    Carve,
    ConstraintConfig,
    HypothesisConfig,
    prepare_hypotheses,
)
from ipr_shapes.perception.free_space import SeenSpace, SpaceMap
from ipr_shapes.perception.types import KnownPlane, PartialObject
from ipr_shapes.products import ObjectPosterior, PreparedHypotheses, ShapeHypothesis
from ipr_shapes.progress import ProgressCallback

logger = logging.getLogger(__name__)

METHOD = "collision-checker"


@dataclass(frozen=True)
class CollisionCheckerConfig:
    """Settings of the Collision Checker.

    Attributes:
        max_exact_table: largest elimination table (entries) for exact marginals.
        gibbs_chains: restarts of the sampler per component.
        gibbs_sweeps: sweeps per chain (each visits every object of the component once).
        gibbs_burn_in: sweeps after a chain first becomes feasible before counting.
        relax_steps: doublings of the pairwise tolerance before dropping a component's
            pairwise constraints when nothing is jointly feasible.
        medoid_weights: the weights of the jointly feasible candidates in the output medoid:
            "candidate", each feasible candidate the same weight; "family"
            (opt-in), each generator family with a feasible candidate an equal share, split
            equally among its feasible candidates (``family_weights``), each candidate scored
            against the others only; "outline" (opt-in), per object the mixture of the two by
            the fraction of its image outline a nearer surface hides (``outline_weights``);
            "fit" (opt-in), each family's share times each candidate's likelihood of the
            observed points on its surface (``fit_weights``); "outline-fit" (default), ``1 - h``
            each candidate once and ``h`` the fit weights, ``h`` the hidden outline fraction
            (an object without it, as in the physics methods' start, "candidate"). The
            written probabilities are the marginals either way (module doc).
        medoid_self: where the weights are unequal (``medoid_base_weights``' leave-one-out
            objects), what a candidate's own weight adds to its score: "leave-one-out"
            (default), nothing (``posterior_medoid``'s leave-one-out); "nearest" (opt-in), its
            weight times its IoU with its nearest other candidate (``nearest_medoid``). Equal
            weights: every candidate's own vote counts once either way.
    """

    CHECKS: ClassVar[Checks] = {
        "max_exact_table": Interval(1, None, integer=True),
        "gibbs_chains": Interval(1, None, integer=True),
        "gibbs_sweeps": Interval(1, None, integer=True),
        "gibbs_burn_in": Interval(0, None, integer=True),
        "relax_steps": Interval(0, None, integer=True),
        "medoid_weights": Options("candidate", "family", "outline", "fit", "outline-fit"),
        "medoid_self": Options("leave-one-out", "nearest"),
    }

    max_exact_table: int = 2_000_000
    gibbs_chains: int = 4
    gibbs_sweeps: int = 300
    gibbs_burn_in: int = 30
    relax_steps: int = 3
    medoid_weights: str = "outline-fit"
    medoid_self: str = "leave-one-out"

    def __post_init__(self) -> None:
        check_fields(self)


# --------------------------------------------------------------------------------------------
# Marginals of the uniform distribution over feasible joint assignments


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
        exact = elimination_table_size(component, edges, sizes) <= config.max_exact_table
        if exact and len(component) <= 52:  # einsum's sublist format has 52 indices
            try:
                marginals = exact_marginals(component, edges, sizes, config.max_exact_table)
                how = "exact"
            except TableTooLarge:
                exact = False
        if not exact or len(component) > 52:
            marginals = gibbs_marginals(
                component, edges, sizes, rng, deadline,
                chains=config.gibbs_chains, sweeps=config.gibbs_sweeps,
                burn_in=config.gibbs_burn_in,
            )  # fmt: skip
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


# --------------------------------------------------------------------------------------------
# Medoid weights


def family_weights(generators: Sequence[str], feasible: np.ndarray) -> np.ndarray:
    """(m,) medoid weights of one object's candidates: each generator family (``generators``,
    (m,) ``ShapeHypothesis.generator``) with a candidate in ``feasible`` ((m,) bool) an equal
    share, split equally among its feasible candidates; 0 for the others (sum 1; all 0 when
    none is feasible). Why: a uniform prior over the families that can explain the object,
    then over each one's candidates; a family's candidate count is the configuration's slot
    budget, not evidence (module doc)."""
    feasible = np.asarray(feasible, dtype=bool)
    weights = np.zeros(feasible.size)
    kept = np.flatnonzero(feasible)
    if kept.size:
        _, family, members = np.unique(
            [generators[k] for k in kept], return_inverse=True, return_counts=True
        )
        weights[kept] = 1.0 / (members.size * members[family])
    return weights


def outline_weights(generators: Sequence[str], feasible: np.ndarray, hidden: float) -> np.ndarray:
    """(m,) medoid weights of one object's candidates: ``1 - hidden`` of the weight spread
    equally over the feasible candidates, ``hidden`` over them as ``family_weights`` does
    (sum 1; all 0 when none is feasible).

    ``hidden`` in [0, 1]: the fraction of the object's image outline that a nearer surface or
    the image border hides (``ipr_shapes.perception.outline.hidden_outline_fractions``). Why:
    Algorithm 1 makes half the candidates by mirroring and extending the seen part; where the
    whole outline is the object's own, the seen part spans the object and those candidates are
    evidence of its extent, so each counts once (the default). Where the outline is hidden, the
    hidden side's extent is not in the seen part, and a family's candidate count is only its
    slot budget; there each family that explains the object gets an equal share. The fraction
    is the share of the outline whose continuation the camera did not see: no threshold."""
    feasible = np.asarray(feasible, dtype=bool)
    if not 0.0 <= hidden <= 1.0:
        raise ValueError(f"hidden outline fraction {hidden} outside [0, 1]")
    equal = feasible / max(int(feasible.sum()), 1)
    return (1.0 - hidden) * equal + hidden * family_weights(generators, feasible)


def surface_distances(
    hypothesis: ShapeHypothesis, points: np.ndarray, viewpoints: np.ndarray | None = None
) -> np.ndarray:
    """(N,) distance (m) of each of ``points`` ((N, 3), world, m) from the boundary of the
    convex ``hypothesis``: inside, the smallest distance to a face's plane (exact for a convex
    solid); outside, the largest plane distance (a lower bound of the distance).

    ``viewpoints``: the camera centre each point was seen from ((3,) for all, or (N, 3),
    world, m; a row of NaN: not known, as for points fused from a later view). Given, a
    point is measured to the faces turned towards its camera only (the plane's outward normal
    has a positive component towards the camera): a seen point lies on the surface the camera
    sees, so a face behind it (the far side of a thin candidate) does not explain it. A point
    with no such face, or no viewpoint, is measured to every face."""
    v, f = hypothesis.vertices, hypothesis.faces
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    lengths = np.linalg.norm(normals, axis=1)
    keep = lengths > 1e-12
    normals = normals[keep] / lengths[keep, None]
    offsets = -np.einsum("ij,ij->i", normals, v[f[keep, 0]])
    points = np.asarray(points, float).reshape(-1, 3)
    signed = points @ normals.T + offsets
    every = np.abs(signed.max(axis=1))
    if viewpoints is None:
        return every
    towards = np.broadcast_to(np.asarray(viewpoints, float), points.shape) - points
    with np.errstate(invalid="ignore"):
        facing = towards @ normals.T > 0.0  # NaN rows: no face
    front = np.where(facing, signed, -np.inf).max(axis=1)
    return np.where(np.isfinite(front), np.abs(front), every)


def surface_cell_indices(points: np.ndarray, pitch_m: float) -> np.ndarray:
    """Indices (ascending) of the first of ``points`` ((N, 3), m) in each occupied cube of side
    ``pitch_m`` (``surface_cells``)."""
    points = np.asarray(points, float).reshape(-1, 3)
    if not len(points):
        return np.zeros(0, dtype=np.int64)
    _, first = np.unique(np.floor(points / pitch_m).astype(np.int64), axis=0, return_index=True)
    return np.sort(first)


def surface_cells(points: np.ndarray, pitch_m: float) -> np.ndarray:
    """The first of ``points`` ((N, 3), m) in each occupied cube of side ``pitch_m``: each cell
    of observed surface counts once, however many pixels the camera's range and angle gave it."""
    points = np.asarray(points, float).reshape(-1, 3)
    return points[surface_cell_indices(points, pitch_m)]


def object_viewpoints(obj: PartialObject, camera_m: np.ndarray) -> np.ndarray:
    """(N, 3) the camera centre each of ``obj``'s points was seen from: ``camera_m`` ((3,),
    world, m) for its own frame's pixels, NaN for points fused from a later view (pixel -1:
    seen from a viewpoint that moved with the object)."""
    own = np.asarray(obj.pixels).reshape(-1)[: len(obj.points)] >= 0
    return np.where(own[:, None], np.asarray(camera_m, float)[None, :], np.nan)


def fit_weights(
    generators: Sequence[str], feasible: np.ndarray, distances: np.ndarray, pitch_m: float
) -> np.ndarray:
    """(m,) medoid weights of one object's candidates: ``family_weights`` times each feasible
    candidate's likelihood of the observed surface on its boundary (sum 1; all 0 when none is
    feasible).

    ``distances``: (number feasible, N) distance (m) of each observed surface point (one per
    ``pitch_m`` cell, ``surface_cells``) from each feasible candidate's boundary
    (``surface_distances``), rows in the order of ``np.flatnonzero(feasible)``. Why: every
    candidate contains the points, so a point inside shows where the candidate's surface
    runs away from the seen surface. The smallest distance over the candidates at a point is
    what none of them can explain (concavity, noise); each candidate's excess over it, its
    root mean square ``e`` over the points, is its misfit, scored ``exp(-e^2 / (2 s^2))`` with
    ``s^2 = pitch^2 / 12 + mean(floor^2)``: the candidates are voxelised at the pitch (a
    boundary within a voxel is not resolved: the quantisation's variance) and the shared part
    is the object's own scatter about a convex surface. No points: the family weights."""
    feasible = np.asarray(feasible, dtype=bool)
    weights = family_weights(generators, feasible)
    kept = np.flatnonzero(feasible)
    distances = np.asarray(distances, float).reshape(kept.size, -1)
    if kept.size == 0 or distances.shape[1] == 0:
        return weights
    floor = distances.min(axis=0)
    excess = np.sqrt(np.mean((distances - floor) ** 2, axis=1))
    variance = pitch_m**2 / 12.0 + float(np.mean(floor**2))
    log_likelihood = -(excess**2) / (2.0 * variance)
    weights[kept] *= np.exp(log_likelihood - log_likelihood.max())
    return weights / weights.sum()


def _object_fit_weights(
    hyps: Sequence[ShapeHypothesis],
    feasible: np.ndarray,
    points: np.ndarray,
    viewpoints: np.ndarray | None,
) -> np.ndarray:
    """``fit_weights`` of one object's candidates from its observed points ((N, 3), world, m)
    and their viewpoints ((3,) or (N, 3), or None: every face; ``surface_distances``)."""
    kept = np.flatnonzero(feasible)
    pitch = hyps[kept[0]].voxel_pitch_m
    points = np.asarray(points, float).reshape(-1, 3)
    cells = surface_cell_indices(points, pitch)
    if viewpoints is not None:
        viewpoints = np.broadcast_to(np.asarray(viewpoints, float), points.shape)[cells]
    distances = np.array([surface_distances(hyps[k], points[cells], viewpoints) for k in kept])
    return fit_weights([h.generator for h in hyps], feasible, distances, pitch)


def medoid_base_weights(
    hyps: Sequence[ShapeHypothesis],
    feasible: np.ndarray,
    config: CollisionCheckerConfig,
    hidden: float = 0.0,
    points: np.ndarray | None = None,
    viewpoints: np.ndarray | None = None,
) -> tuple[np.ndarray, bool]:
    """(m,) the Collision Checker's medoid weights of one object's hypotheses ``hyps`` (0 off
    ``feasible``, (m,) bool; sum 1) under ``config.medoid_weights``, and whether its medoid
    scores each candidate against the others only (``posterior_medoid``'s ``leave_one_out``).

    ``hidden``: the object's hidden outline fraction (``hidden_outline_fractions``; 0: none
    hidden or not measured); ``points``: its observed points ((N, 3), world, m; None: not
    measured) and ``viewpoints`` the camera centre each was seen from ((3,) or (N, 3); None:
    every face). They are the weights before any evidence: the physics-based methods' medoid
    takes them as its base measure (``InferenceConfig.medoid_base``)."""
    feasible = np.asarray(feasible, dtype=bool)
    generators = [h.generator for h in hyps]
    if config.medoid_weights == "family":
        return family_weights(generators, feasible), True
    if config.medoid_weights == "fit" and points is not None:
        return _object_fit_weights(hyps, feasible, points, viewpoints), True
    if config.medoid_weights == "outline" and hidden > 0.0:
        return outline_weights(generators, feasible, hidden), True
    if config.medoid_weights == "outline-fit" and hidden > 0.0:
        # Each candidate once for the seen share of the outline, the families weighed by
        # their fit for the hidden share (module doc); no points: the families' shares.
        if points is not None:
            judged = _object_fit_weights(hyps, feasible, points, viewpoints)
        else:
            judged = family_weights(generators, feasible)
        return (1.0 - hidden) * feasible / feasible.sum() + hidden * judged, True
    return feasible / max(int(feasible.sum()), 1), False


def nearest_medoid(
    hypotheses: Sequence[ShapeHypothesis], weights: np.ndarray, table: PairwiseIoU | None = None
) -> int:
    """Index of the hypothesis of the highest expected voxel IoU under ``weights`` ((m,), >= 0)
    when the truth drawn *at* a candidate is a shape like it rather than the candidate itself:
    each candidate ``j`` of non-zero weight scores ``sum_{i != j} w_i IoU(i, j) + w_j n_j``,
    ``n_j`` its IoU with its nearest other candidate of non-zero weight. ``table``: as
    ``posterior_medoid``'s.

    Why: the candidates are draws standing for a continuum of shapes, so the truth near ``j``
    matches ``j`` about as well as the draw nearest to it does (the sample's own resolution
    there, as a nearest-neighbour density estimate reads it): neither exactly (IoU 1, a heavy
    lone candidate wins by its own vote) nor not at all (``posterior_medoid``'s leave-one-out,
    which makes the choice blind to the candidate's own weight and picks light candidates
    between heavier clusters). No constant: the nearest neighbour's IoU is the candidate
    set's."""
    weights = np.asarray(weights, float)
    support = np.flatnonzero(weights > 0)
    if support.size <= 1:
        return int(support[0]) if support.size else 0
    if table is None:
        table = PairwiseIoU(hypotheses)
    elif table.hypotheses is not hypotheses:
        raise ValueError("the IoU table belongs to another list of hypotheses")
    iou = table.matrix(support)
    w = weights[support]
    others = iou.copy()
    np.fill_diagonal(others, -np.inf)
    expected = iou @ w - w + w * others.max(axis=1)
    return int(support[int(np.argmax(expected))])


# --------------------------------------------------------------------------------------------
# Public API


def uniform_posteriors(
    prepared: PreparedHypotheses,
    config: CollisionCheckerConfig | None = None,
    rng: np.random.Generator | None = None,
    deadline: float = np.inf,
    tables: dict[int, PairwiseIoU] | None = None,
    hidden: Mapping[int, float] | None = None,
    points: Mapping[int, np.ndarray] | None = None,
    viewpoints: Mapping[int, np.ndarray] | None = None,
) -> list[ObjectPosterior]:
    """The Collision Checker's marginals from prepared hypotheses (module doc): uniform over
    jointly feasible joint models; the Gibbs sampler stops at ``deadline``
    (``time.perf_counter()`` seconds). ``tables``, when given, receives per object id the
    pairwise IoU of its hypotheses its medoid computed (``PairwiseIoU``), for a later medoid
    of the same object. ``hidden``: per object id the hidden fraction of its image outline
    (``hidden_outline_fractions``), read by ``medoid_weights = "outline"`` (an object absent:
    0, each candidate counted once). ``points``: per object id its observed points ((N, 3),
    world, m), read by ``medoid_weights = "fit"`` (an object absent, as in the physics
    methods' starting answer: each candidate counted once) and "outline-fit" (absent: the
    families' equal shares for the hidden share). ``viewpoints``: per object id the camera
    centre each of its points was seen from ((3,) or (N, 3) rows of ``points``, world, m; NaN:
    not known), so that a point is measured to the candidate faces its camera sees
    (``surface_distances``); absent: every face."""
    config = config or CollisionCheckerConfig()
    rng = rng if rng is not None else np.random.default_rng(0)
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
        # The medoid of the jointly feasible candidates, not under the marginals (module
        # doc): a marginal also counts how many of the neighbours' candidates a candidate fits
        # with. Each family an equal share, or each candidate counted once.
        weights, leave_one_out = medoid_base_weights(
            hyps, probabilities > 0, config, (hidden or {}).get(i, 0.0), (points or {}).get(i),
            (viewpoints or {}).get(i),
        )  # fmt: skip
        table = PairwiseIoU(hyps)
        if tables is not None:
            tables[i] = table
        if leave_one_out and config.medoid_self == "nearest":
            best = nearest_medoid(hyps, weights, table)
        else:
            best = posterior_medoid(hyps, weights, table, leave_one_out=leave_one_out)
        posteriors.append(
            ObjectPosterior(
                i,
                hyps,
                probabilities,
                best,
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
    *,
    hypotheses: HypothesisConfig | None = None,
    constraints: ConstraintConfig | None = None,
    progress: ProgressCallback | None = None,
    hidden: Mapping[int, float] | None = None,
    camera_m: np.ndarray | None = None,
    carve: Carve | None = None,
) -> list[ObjectPosterior]:
    """Marginal shape posteriors of the objects of one frame (frame 0) under a uniform prior
    restricted to jointly feasible models (module doc).

    Args:
        objects: the frame's partial objects (distinct ids).
        space: the frame's free-space map (None: no free-space constraint).
        planes: the frame's support and walls.
        config: settings of the marginals (defaults: ``CollisionCheckerConfig()``).
        rng: random source (default: seeded from ``hypotheses.seed``).
        time_budget_s: total seconds; generation gets ``hypotheses.budget_share`` of it (split
            over the objects, capping their timeouts) and the sampler stops at the end of it.
        object_spaces: per object id, a seen-free space replacing ``space`` for that object
            (``prepare_hypotheses``).
        hypotheses, constraints: settings of generation and of the constraints (defaults).
        progress: observer of the hypotheses' progress (``ipr_shapes.progress``).
        hidden: per object id the hidden fraction of its image outline in frame 0
            (``hidden_outline_fractions``), for ``config.medoid_weights = "outline"`` and
            "outline-fit".
        camera_m: (3,) frame 0's camera centre (world, m), from which the objects' own points
            (pixel index >= 0; fused points from later views have -1) were seen, for the fit
            weights (``surface_distances``); None: every face.
        carve: the candidates are carved by it before the medoid is chosen
            (``prepare_hypotheses``; ``CarvingConfig.before_choice``); None: not carved.

    Returns:
        One ObjectPosterior per object, in the order of ``objects``.
    """
    config = config or CollisionCheckerConfig()
    hypotheses = hypotheses or HypothesisConfig()
    rng = rng if rng is not None else np.random.default_rng(hypotheses.seed)
    started = time.perf_counter()
    deadline = np.inf if time_budget_s is None else started + time_budget_s
    generation_rng, sampler_rng = rng.spawn(2)
    prepared = prepare_hypotheses(
        objects, space, planes, hypotheses, constraints, generation_rng, time_budget_s,
        object_spaces, progress, carve,
    )  # fmt: skip
    points = viewpoints = None
    if config.medoid_weights in ("fit", "outline-fit"):
        points = {o.id: o.points for o in objects}
        if camera_m is not None:
            viewpoints = {o.id: object_viewpoints(o, camera_m) for o in objects}
    posteriors = uniform_posteriors(
        prepared, config, sampler_rng, deadline, hidden=hidden, points=points,
        viewpoints=viewpoints,
    )  # fmt: skip
    logger.debug(
        "collision checker: %d objects in %.3f s", len(objects), time.perf_counter() - started
    )
    return posteriors
