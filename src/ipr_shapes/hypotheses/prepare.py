"""The hypotheses stage's product: every object's hypotheses with their constraints measured.

Algorithm 1 (``ipr_shapes.hypotheses.generate``) runs per object; the unary constraints
(``ipr_shapes.hypotheses.constraints``) keep the feasible hypotheses (an object with none is
represented by its minimum shape); the pairwise overlap measures (penetration depths, a
candidate thinner than the tolerance's relative to its thickness) are measured between the
feasible hypotheses of objects whose envelopes overlap. Every inference method (the Collision
Checker and the physics-based ones) starts from this ``PreparedHypotheses``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from threadpoolctl import ThreadpoolController

from ipr_shapes.hypotheses.constraints import (
    ConstraintConfig,
    OverlapCache,
    box_depth_bounds,
    generated_unary_feasible,
    interacting_pairs,
    overlap_matrix,
    overlap_threshold,
    thin_limits,
)
from ipr_shapes.hypotheses.generate import HypothesisConfig, generate_hypotheses, minimum_shape
from ipr_shapes.hypotheses.neighbours import neighbour_spaces
from ipr_shapes.perception.free_space import SeenSpace, SpaceMap
from ipr_shapes.perception.occupancy import plane_regions
from ipr_shapes.perception.types import KnownPlane, PartialObject
from ipr_shapes.products import PreparedHypotheses, ShapeHypothesis, volume_spread
from ipr_shapes.progress import ProgressCallback, report

logger = logging.getLogger(__name__)

#: ``carve(hypotheses, object id)``: the hypotheses with their voxels carved
#: (``ipr_shapes.carving.carve_hypotheses`` bound to a run's views; a callable, so that this
#: stage does not import the later carving stage).
Carve = Callable[[Sequence[ShapeHypothesis], int], tuple[ShapeHypothesis, ...]]

#: The BLAS libraries loaded with numpy and scipy, found once. The stage's linear algebra is
#: small (SVDs of 100 x 8 Jacobians in the superquadric fits, 3 x 3 frames, hulls' products):
#: OpenBLAS threads spread it over every core and spin for nothing, and the last bits of a fit
#: would depend on the machine's core count; so the stage runs on one BLAS thread.
_BLAS = ThreadpoolController()


def prepare_hypotheses(
    objects: tuple[PartialObject, ...],
    space: SpaceMap | None,
    planes: tuple[KnownPlane, ...],
    config: HypothesisConfig | None = None,
    constraints: ConstraintConfig | None = None,
    rng: np.random.Generator | None = None,
    time_budget_s: float | None = None,
    object_spaces: Mapping[int, SeenSpace] | None = None,
    progress: ProgressCallback | None = None,
    carve: Carve | None = None,
) -> PreparedHypotheses:
    """Generate each object's hypotheses and minimum shape, keep the unary-feasible ones and
    measure the pairwise penetration depths between interacting objects' hypotheses.

    ``object_spaces``: per object id, the seen-free space to use for that object instead of
    ``space`` (``ipr_shapes.fusion.tracked_free_spaces``: later frames' free space through the
    object's registered motion). With ``config.neighbour_surfaces`` the rays that bound each object's
    hidden extent also stop at the other objects' observed points (``neighbour_spaces``).

    ``time_budget_s``: generation gets ``config.budget_share`` of it, split over the objects
    (capping their timeouts). ``rng`` defaults to one seeded from ``config.seed``; each object
    draws from its own child stream (``rng.spawn``). ``progress`` hears of each object done
    (``ipr_shapes.progress``, stage ``hypotheses``). ``carve``: each object's hypotheses and
    minimum shape are passed through it after the unary checks, ``carve(hypotheses, object
    id)`` (``ipr_shapes.carving.carve_hypotheses`` with the run's views: their voxels lose what
    the camera saw empty, their convex meshes stay), so that the choice among them weighs the
    shapes that are written (``CarvingConfig.before_choice``); None: not carved.

    Returns the objects' hypotheses with their unary and pairwise constraints, in the order of
    ``objects``.
    """
    with _BLAS.limit(limits=1, user_api="blas"):
        return _prepare(
            objects, space, planes, config, constraints, rng, time_budget_s, object_spaces,
            progress, carve,
        )  # fmt: skip


def _prepare(
    objects: tuple[PartialObject, ...],
    space: SpaceMap | None,
    planes: tuple[KnownPlane, ...],
    config: HypothesisConfig | None,
    constraints: ConstraintConfig | None,
    rng: np.random.Generator | None,
    time_budget_s: float | None,
    object_spaces: Mapping[int, SeenSpace] | None,
    progress: ProgressCallback | None,
    carve: Carve | None = None,
) -> PreparedHypotheses:
    """``prepare_hypotheses`` on one BLAS thread (its doc)."""
    config = config or HypothesisConfig()
    constraints = constraints or ConstraintConfig()
    rng = rng if rng is not None else np.random.default_rng(config.seed)
    ids = [int(obj.id) for obj in objects]
    if len(set(ids)) != len(ids):
        raise ValueError(f"object ids must be distinct, got {ids}")
    hypothesis_config = config
    if time_budget_s is not None:
        per_object = config.budget_share * time_budget_s / max(len(objects), 1)
        hypothesis_config = dataclasses.replace(
            hypothesis_config,
            timeout_s=per_object
            if hypothesis_config.timeout_s is None
            else min(hypothesis_config.timeout_s, per_object),
        )
    object_rngs = rng.spawn(len(objects))
    regions = plane_regions(planes, config.unary.wall_min_thickness_m)
    bounds = neighbour_spaces(objects, space, object_spaces) if config.neighbour_surfaces else {}

    generated: dict[int, tuple[ShapeHypothesis, ...]] = {}
    minima: dict[int, ShapeHypothesis] = {}
    candidates: dict[int, list[int]] = {}  # object -> indices of unary-feasible hypotheses
    seconds: dict[int, float] = {}
    report(progress, "hypotheses", 0, len(objects))
    for done, (obj, object_rng) in enumerate(zip(objects, object_rngs, strict=True), start=1):
        begin = time.perf_counter()
        seen = (object_spaces or {}).get(obj.id, space)
        hyps = generate_hypotheses(
            obj, seen, planes, hypothesis_config, object_rng, bounds=bounds.get(obj.id)
        )
        minima[obj.id] = minimum_shape(obj, planes, hypothesis_config)
        # generate_hypotheses checked each against ``seen`` and ``planes`` already (h.feasible):
        # ``unary_feasible``'s answer without measuring every hypothesis again.
        feasible = [
            k for k, h in enumerate(hyps) if generated_unary_feasible(h, regions, config.unary)
        ]
        if not feasible:
            logger.warning("object %d: no feasible hypothesis; using its minimum shape", obj.id)
            hyps = (minima[obj.id],)
            feasible = [0]
        if carve is not None:
            # After the unary checks (they read the convex voxels generation measured).
            minima[obj.id] = carve((minima[obj.id],), obj.id)[0]
            hyps = (minima[obj.id],) if hyps[0].index == -1 else carve(hyps, obj.id)
        generated[obj.id], candidates[obj.id] = hyps, feasible
        seconds[obj.id] = time.perf_counter() - begin
        report(progress, "hypotheses", done, len(objects))
        logger.debug(
            "object %d: %d/%d feasible, volumes %s",
            obj.id,
            len(feasible),
            len(hyps),
            volume_spread(hyps),
        )

    # Pairwise overlap measures (penetration depths; a thin candidate's relative to its
    # thickness: ``constraints`` module doc) between the feasible hypotheses of objects whose
    # hypotheses' bounding boxes may overlap by more than that allows.
    chosen = {i: [generated[i][k] for k in candidates[i]] for i in ids}
    tolerance = constraints.overlap_tolerance_m
    pairs = interacting_pairs(chosen, tolerance)
    # Only the hypotheses some pair's depth query needs go into the MuJoCo model (the rest keep
    # their box bounds): compiling costs per mesh, and a geom's depths do not depend on the
    # other meshes in the model.
    queried: dict[int, np.ndarray] = {i: np.zeros(len(chosen[i]), dtype=bool) for i in ids}
    for a, b in pairs:
        needed = box_depth_bounds(chosen[a], chosen[b]) > thin_limits(
            chosen[a], chosen[b], tolerance
        )
        queried[a] |= needed.any(axis=1)
        queried[b] |= needed.any(axis=0)
    cache = OverlapCache([h for i in ids for h, q in zip(chosen[i], queried[i], strict=True) if q])
    depths: dict[tuple[int, int], np.ndarray] = {}
    thresholds: dict[tuple[int, int], float] = {}
    for a, b in pairs:
        matrix = overlap_matrix(cache, chosen[a], chosen[b], tolerance)
        threshold = overlap_threshold(matrix, constraints, a, b)
        if (matrix > threshold).any():
            depths[(a, b)], thresholds[(a, b)] = matrix, threshold
    logger.debug("hypotheses prepared: %d depth queries", cache.queries)
    return PreparedHypotheses(ids, generated, minima, candidates, seconds, depths, thresholds)
