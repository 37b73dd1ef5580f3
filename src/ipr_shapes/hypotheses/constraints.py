"""Geometric constraints on hypotheses and joint models (paper Sec. IV-C, Constraints(X)).

A joint model picks one hypothesis per object. It is feasible when no two chosen shapes
intersect, none occupies space seen to be free in frame 0, and nothing is below the support or
inside a known wall. Tolerances absorb sensor noise: observed surfaces are a few millimetres off,
so two objects in contact may appear to overlap slightly.

Overlap measure: penetration depth (m), computed exactly by MuJoCo's ``mj_geomDistance``
between convex meshes, all of a scene's hypotheses compiled once into one model. A scene of 8
objects x 32 hypotheses has up to 28 x 1024 pairs, and only this query, far faster per pair
than manifold3d's exact intersection volume, fits the per-object budget (docs/DESIGN_NOTES.md,
"Overlap by penetration depth"). Depth is also the better tolerance: noise is a distance (mm),
whereas the volume of a noisy contact grows with the contact's area. ``intersection_volume``
(manifold3d) stays available for reporting and tests.

Thin candidates: a candidate thinner than the tolerance (a thin symmetry candidate, a flat
superquadric) could lie wholly inside a neighbour, or pass through its surface layer, within a
tolerated depth. The tolerance is for two *surfaces* in contact, each a few millimetres off;
once the depth reaches the thinner candidate's thickness w (``ShapeHypothesis.width_m``), that
candidate is no longer in contact with its neighbour's surface but inside it. So a pair whose
thinner candidate has w below the tolerance t is measured as depth * t / w: the depth in units
of that candidate's thickness, against the same tolerance (a depth of w is the tolerance), and
the relaxations below (forced overlaps; the Collision Checker's doubling) apply to that
measure alike. Pairs of candidates at least t thick keep their depth in metres.

A bounding-box pre-test skips most pairs: the boxes' own penetration depth bounds the shapes'
from above (a shape lies in its box, so a move that separates the boxes separates the shapes),
so pairs whose bound is within the tolerance are compatible without a query. Along one axis the
boxes [lo_a, hi_a] and [lo_b, hi_b] separate after a move of min(hi_a - lo_b, hi_b - lo_a)
(one way or the other), and the boxes' depth is the least of that over the three axes. The
intervals' overlap, min(hi_a, hi_b) - max(lo_a, lo_b), is *not* a bound: when one interval holds
the other (a thin candidate across a neighbour) it is the thin one's thickness, however deep
the thin one lies inside (until 2026-11-27 that was the pre-test, and a 2 mm candidate passed
through any neighbour; docs/experiments/2026-11-27-thin-candidates-overlap.md).

Forced overlaps: when even the least-overlapping pair of two objects' hypotheses penetrates by
more than the tolerance, the overlap is forced by the observations (segmentation bleeding,
concave objects whose hulls interpenetrate), not by the hypotheses; with
``relax_forced_overlap`` that pair of objects then tolerates the least depth plus the tolerance
(logged), so that the constraint still ranks their hypotheses instead of forbidding them all.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.checks import Checks, Interval, Options, check_fields
from ipr_shapes.hypotheses.generate import UnaryTolerances
from ipr_shapes.perception.free_space import SeenSpace
from ipr_shapes.perception.occupancy import (
    PlaneRegion,
    allowed_voxels,
    plane_regions,
    unary_report,
)
from ipr_shapes.perception.types import KnownPlane
from ipr_shapes.products import ShapeHypothesis

logger = logging.getLogger(__name__)

HypothesisKey = tuple[int, int]


@dataclass(frozen=True)
class ConstraintConfig:
    """Tolerances of the geometric constraints (metres, shares, voxel counts).

    Attributes:
        overlap_tolerance_m: two objects' shapes may interpenetrate by this penetration depth
            (sensor noise on touching surfaces, about one 5 mm voxel).
        relax_forced_overlap: tolerate overlaps the observations force (module doc).

    The unary tolerances (support, seen-free space, walls) are ``UnaryTolerances``, owned by
    ``HypothesisConfig.unary`` so that generation and checking use the same values.
    """

    CHECKS: ClassVar[Checks] = {
        "overlap_tolerance_m": Interval(0, None),
        "relax_forced_overlap": Options(True, False),
    }

    overlap_tolerance_m: float = 0.005
    relax_forced_overlap: bool = True

    def __post_init__(self) -> None:
        check_fields(self)


# --------------------------------------------------------------------------------------------
# Pairwise overlap


def key_of(h: ShapeHypothesis) -> HypothesisKey:
    """Cache key of a hypothesis: (object id, hypothesis index)."""
    return (int(h.object_id), int(h.index))


def _mesh_model(hypotheses: Sequence[ShapeHypothesis]):
    """A static MuJoCo model with one (non-colliding) mesh geom per hypothesis, and its data."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.modelname = "ipr_overlap"
    for number, h in enumerate(hypotheses):
        mesh = spec.add_mesh()
        mesh.name = f"h{number}"
        mesh.uservert = np.asarray(h.vertices, float).ravel().tolist()
        mesh.userface = np.asarray(h.faces, np.int64).ravel().tolist()
        geom = spec.worldbody.add_geom()
        geom.type = mujoco.mjtGeom.mjGEOM_MESH
        geom.meshname = mesh.name
        geom.contype = 0
        geom.conaffinity = 0
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    return model, data


def penetration_depth(a: ShapeHypothesis, b: ShapeHypothesis) -> float:
    """Penetration depth (m, >= 0; 0 when apart or touching) of two convex hypotheses, exact
    (MuJoCo ``mj_geomDistance``). Compiles a two-mesh model per call: use ``OverlapCache``
    for many pairs."""
    return OverlapCache([a, b]).depth(a, b)


def intersection_volume(a: ShapeHypothesis, b: ShapeHypothesis) -> float:
    """Exact intersection volume (m^3) of two convex hypotheses (manifold3d; slow: for
    reporting and tests, not the constraints)."""
    import manifold3d

    first = manifold3d.Manifold.hull_points(np.asarray(a.vertices, float))
    second = manifold3d.Manifold.hull_points(np.asarray(b.vertices, float))
    return float((first ^ second).volume())


def pairwise_overlap(
    a: ShapeHypothesis, b: ShapeHypothesis, config: ConstraintConfig | None = None
) -> float:
    """The overlap measure of the constraints (m): penetration depth, scaled by t / w when
    the thinner candidate's thickness w is below the tolerance t (module doc)."""
    config = config or ConstraintConfig()
    tolerance = config.overlap_tolerance_m
    limit = thin_limits([a], [b], tolerance)
    return float(penetration_depth(a, b) * thin_scale(limit, tolerance)[0, 0])


#: Thickness (m) below which a candidate counts as flat: its measure's scale stays finite.
_FLAT_M = 1e-6


def thin_limits(
    hyps_i: Sequence[ShapeHypothesis], hyps_j: Sequence[ShapeHypothesis], tolerance_m: float
) -> np.ndarray:
    """(m_i, m_j) the depth (m) at which each pair's measure reaches the tolerance: the
    tolerance, or the thinner candidate's thickness when that is less (module doc)."""
    widths_i = np.array([h.width_m for h in hyps_i], float)
    widths_j = np.array([h.width_m for h in hyps_j], float)
    return np.minimum(tolerance_m, np.minimum.outer(widths_i, widths_j))


def thin_scale(limits: np.ndarray, tolerance_m: float) -> np.ndarray:
    """Factors (same shape as ``thin_limits``' answer) from penetration depths to the overlap
    measure: t / w where the thinner candidate's thickness w is below the tolerance t, else 1."""
    return np.where(limits < tolerance_m, tolerance_m / np.maximum(limits, _FLAT_M), 1.0)


def overlap_matrix(
    cache: OverlapCache,
    hyps_i: Sequence[ShapeHypothesis],
    hyps_j: Sequence[ShapeHypothesis],
    tolerance_m: float,
) -> np.ndarray:
    """(m_i, m_j) overlap measures (m, module doc) of two lists of hypotheses registered in
    ``cache``: penetration depths, those of pairs with a candidate thinner than the tolerance
    scaled by t / w. Pairs whose bounding boxes' depth is within their limit (the tolerance, or
    the thinner's thickness) are not queried: their measure is at most the tolerance."""
    limits = thin_limits(hyps_i, hyps_j, tolerance_m)
    depths = cache.depth_matrix(hyps_i, hyps_j, exact_above_m=limits)
    return depths * thin_scale(limits, tolerance_m)


def _box_bounds(lo_a: np.ndarray, hi_a: np.ndarray, lo_b: np.ndarray, hi_b: np.ndarray):
    """(m_a, m_b) penetration depths (m) of bounding boxes given by corners (m_a/m_b, 3) each:
    upper bounds on their shapes' depths (module doc; 0 for boxes apart on some axis)."""
    move = np.minimum(hi_a[:, None, :] - lo_b[None, :, :], hi_b[None, :, :] - lo_a[:, None, :])
    return np.maximum(move.min(axis=2), 0.0)


def box_depth(lo_a: np.ndarray, hi_a: np.ndarray, lo_b: np.ndarray, hi_b: np.ndarray) -> float:
    """Penetration depth (m) of two axis-aligned boxes given by their (3,) corners: the least
    move along one axis that separates them (0 when apart), an upper bound on the depth of any
    two shapes inside them (module doc)."""
    move = np.minimum(np.asarray(hi_a) - np.asarray(lo_b), np.asarray(hi_b) - np.asarray(lo_a))
    return max(float(move.min()), 0.0)


def box_depth_bounds(
    hyps_i: Sequence[ShapeHypothesis], hyps_j: Sequence[ShapeHypothesis]
) -> np.ndarray:
    """(m_i, m_j) upper bounds (m) on the penetration depths of two lists of hypotheses from
    their bounding boxes (module doc): ``OverlapCache.depth_matrix`` queries the pairs whose
    bound exceeds its ``exact_above_m``."""
    bounds_i = np.array([h.bounds for h in hyps_i]).reshape(-1, 2, 3)
    bounds_j = np.array([h.bounds for h in hyps_j]).reshape(-1, 2, 3)
    return _box_bounds(bounds_i[:, 0], bounds_i[:, 1], bounds_j[:, 0], bounds_j[:, 1])


class OverlapCache:
    """Penetration depths between hypotheses, computed once per pair.

    All hypotheses given at construction are compiled into one MuJoCo model (once: compiling
    costs far more than a query); a pair's depth is then one ``mj_geomDistance`` query, cached
    under the pair of keys (object id, hypothesis index). Keys must be unique.
    """

    def __init__(self, hypotheses: Iterable[ShapeHypothesis]) -> None:
        self._hypotheses = list(hypotheses)
        self._geom: dict[HypothesisKey, int] = {}
        for number, h in enumerate(self._hypotheses):
            key = key_of(h)
            if key in self._geom:
                raise ValueError(f"duplicate hypothesis key {key}")
            self._geom[key] = number
        self._model, self._data = (
            _mesh_model(self._hypotheses) if self._hypotheses else (None, None)
        )
        self._depth: dict[tuple[HypothesisKey, HypothesisKey], float] = {}
        self._matrices: dict[tuple, np.ndarray] = {}
        self.queries = 0

    def __contains__(self, h: ShapeHypothesis) -> bool:
        return key_of(h) in self._geom and self._hypotheses[self._geom[key_of(h)]] is h

    def depth(self, a: ShapeHypothesis, b: ShapeHypothesis) -> float:
        """Exact penetration depth (m, >= 0) of two registered hypotheses."""
        ka, kb = key_of(a), key_of(b)
        pair = (ka, kb) if ka <= kb else (kb, ka)
        cached = self._depth.get(pair)
        if cached is None:
            import mujoco

            distance = mujoco.mj_geomDistance(
                self._model, self._data, self._geom[ka], self._geom[kb], 0.0, None
            )
            self.queries += 1
            cached = max(-float(distance), 0.0)
            self._depth[pair] = cached
        return cached

    def depth_matrix(
        self,
        hyps_i: Sequence[ShapeHypothesis],
        hyps_j: Sequence[ShapeHypothesis],
        exact_above_m: float | np.ndarray = 0.0,
    ) -> np.ndarray:
        """(m_i, m_j) penetration depths (m). Pairs whose bounding-box bound is at most
        ``exact_above_m`` (a number, or one per pair: (m_i, m_j)) are not queried: they hold
        that bound (>= the true depth) instead."""
        above = np.asarray(exact_above_m, float)
        signature = (
            tuple(map(key_of, hyps_i)),
            tuple(map(key_of, hyps_j)),
            above.shape,
            above.tobytes(),
        )
        cached = self._matrices.get(signature)
        if cached is not None:
            return cached
        depths = box_depth_bounds(hyps_i, hyps_j)
        # ``depth`` per pair, inlined: at thousands of pairs its call overhead outweighs the
        # query itself.
        import mujoco

        keys_i, keys_j = signature[0], signature[1]
        cache, geom, model, data = self._depth, self._geom, self._model, self._data
        distance_of = mujoco.mj_geomDistance
        rows, cols = np.nonzero(depths > above)
        found = []
        queries = 0
        # Python ints and lists: numpy scalars' indexing and item assignment cost more than
        # the query (the same pairs, in the same order, as a loop over ``np.nonzero``).
        for a, b in zip(rows.tolist(), cols.tolist(), strict=True):
            ka, kb = keys_i[a], keys_j[b]
            pair = (ka, kb) if ka <= kb else (kb, ka)
            depth = cache.get(pair)
            if depth is None:
                negative = -float(distance_of(model, data, geom[ka], geom[kb], 0.0, None))
                queries += 1
                # max(negative, 0.0), without the builtin's call: the first argument unless
                # the second is larger (signed zeros and NaN as max gives them).
                depth = 0.0 if negative < 0.0 else negative
                cache[pair] = depth
            found.append(depth)
        self.queries += queries
        if found:
            depths[rows, cols] = found
        self._matrices[signature] = depths
        return depths


def interacting_pairs(
    hypotheses: Mapping[int, Sequence[ShapeHypothesis]], tolerance_m: float
) -> list[tuple[int, int]]:
    """The pairs (a, b) of object ids (a before b in the mapping's order) some pair of whose
    hypotheses may exceed the tolerance: the penetration depth of the objects' envelopes (the
    box around all their hypotheses' boxes) bounds every pair's (module doc), and a pair
    matters once its depth may exceed the tolerance or the thinnest candidate's thickness."""
    ids = [i for i in hypotheses if len(hypotheses[i])]
    envelopes = {
        i: (np.min([h.bounds[0] for h in hypotheses[i]], axis=0),
            np.max([h.bounds[1] for h in hypotheses[i]], axis=0))
        for i in ids
    }  # fmt: skip
    thinnest = {i: min(h.width_m for h in hypotheses[i]) for i in ids}
    pairs = []
    for position, a in enumerate(ids):
        for b in ids[position + 1 :]:
            bound = box_depth(*envelopes[a], *envelopes[b])
            if bound > min(tolerance_m, thinnest[a], thinnest[b]):
                pairs.append((a, b))
    return pairs


def compatibility_matrix(
    hyps_i: Sequence[ShapeHypothesis],
    hyps_j: Sequence[ShapeHypothesis],
    config: ConstraintConfig | None = None,
    cache: OverlapCache | None = None,
) -> np.ndarray:
    """(m_i, m_j) bool: True where hypothesis a of object i and b of object j may coexist
    (overlap measure within the tolerance, relaxed for forced overlaps: module doc).

    ``cache`` must hold every hypothesis of both lists (one is built for them otherwise).
    """
    config = config or ConstraintConfig()
    if len(hyps_i) == 0 or len(hyps_j) == 0:
        return np.ones((len(hyps_i), len(hyps_j)), dtype=bool)
    if cache is None or not all(h in cache for h in (*hyps_i, *hyps_j)):
        cache = OverlapCache([*hyps_i, *hyps_j])
    measures = overlap_matrix(cache, hyps_i, hyps_j, config.overlap_tolerance_m)
    return measures <= overlap_threshold(measures, config, hyps_i[0].object_id, hyps_j[0].object_id)


def overlap_threshold(
    depths: np.ndarray, config: ConstraintConfig, object_i: int = -1, object_j: int = -1
) -> float:
    """Overlap measure (m) tolerated between two objects given their matrix of measures
    (``overlap_matrix``; penetration depths for candidates at least the tolerance thick)."""
    tolerance = config.overlap_tolerance_m
    least = float(depths.min()) if depths.size else 0.0
    if config.relax_forced_overlap and least > tolerance:
        logger.info(
            "objects %d and %d overlap by at least %.1f mm whatever their hypotheses; tolerating "
            "that overlap",
            object_i,
            object_j,
            least * 1e3,
        )
        return least + tolerance
    return tolerance


# --------------------------------------------------------------------------------------------
# Unary and joint feasibility


def unary_feasible(
    h: ShapeHypothesis,
    space: SeenSpace | None,
    planes: tuple[KnownPlane, ...],
    tolerances: UnaryTolerances | None = None,
) -> bool:
    """True when ``h`` is not below the support (beyond ``support_tolerance_m``) and has at most
    the tolerated voxels in seen-free space and in walls, beyond those its observed points'
    own hull has (``h.forced_*_voxels``) and those its object's surface allowance excuses
    (``h.excused_free_voxels``, measured at generation against the same space). Voxels at the
    space grid's pitch (5 mm default)."""
    config = tolerances or UnaryTolerances()
    regions = plane_regions(planes, config.wall_min_thickness_m)
    needs_voxels = space is not None or any(not r.is_support for r in regions)
    pitch = space.grid.voxel_size_m if space is not None else voxels.DEFAULT_PITCH_M
    keys = h.keys(pitch) if needs_voxels else None
    report = unary_report(h.vertices, keys, pitch, space, regions)
    if report.below_support_m > config.support_tolerance_m:
        return False
    allowed = allowed_voxels(
        report.voxel_count, config.free_space_tolerance, config.free_space_tolerance_voxels
    )
    free = report.free_voxels - h.excused_free_voxels - h.forced_free_voxels
    walls = report.wall_voxels - h.forced_wall_voxels
    return free <= allowed and walls <= allowed


def generated_unary_feasible(
    h: ShapeHypothesis, regions: tuple[PlaneRegion, ...], tolerances: UnaryTolerances
) -> bool:
    """``unary_feasible`` of a hypothesis straight from ``generate_hypotheses`` with the same
    space, planes (``regions``: ``plane_regions(planes, tolerances.wall_min_thickness_m)``) and
    tolerances: generation measured its seen-free and wall voxels against them already
    (``h.feasible``), so only the support depth is left to check (from the vertices). The same
    answer without voxelising and looking up every hypothesis twice."""
    below = 0.0
    for region in regions:
        if region.is_support:
            below = max(below, float(-region.plane.signed_distance(h.vertices).min()))
    return bool(h.feasible) and below <= tolerances.support_tolerance_m


def joint_feasible(
    choice: Mapping[int, int],
    hypotheses: Mapping[int, Sequence[ShapeHypothesis]],
    space: SeenSpace | None,
    planes: tuple[KnownPlane, ...],
    config: ConstraintConfig | None = None,
    cache: OverlapCache | None = None,
    tolerances: UnaryTolerances | None = None,
) -> bool:
    """Constraints(X) of a joint model: ``choice`` maps object id -> index into
    ``hypotheses[object id]``; every chosen shape is unary-feasible and no two intersect
    (pairwise tolerance as in ``compatibility_matrix``, from the objects' full hypothesis lists;
    unary ``tolerances`` default to ``UnaryTolerances()``).
    """
    config = config or ConstraintConfig()
    chosen = {i: hypotheses[i][j] for i, j in choice.items()}
    if not all(unary_feasible(h, space, planes, tolerances) for h in chosen.values()):
        return False
    if cache is None:
        cache = OverlapCache([h for i in choice for h in hypotheses[i]])
    ids = sorted(choice)
    for position, i in enumerate(ids):
        for j in ids[position + 1 :]:
            matrix = compatibility_matrix(hypotheses[i], hypotheses[j], config, cache)
            if not matrix[choice[i], choice[j]]:
                return False
    return True
