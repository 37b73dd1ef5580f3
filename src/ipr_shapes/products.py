"""Typed products that pass between the stages (nerfstudio's stage products): the shapes the
hypotheses stage makes, the constraints it measures between them, and the posteriors inference
returns; plus the run's stage timings and sampling summary.

A neutral module: it imports no stage, so every stage after perception can name these types
without importing another stage's code.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ipr_shapes import voxels


@dataclass(frozen=True, eq=False)
class ShapeHypothesis:
    """One complete shape X_i^j of an object: a closed convex mesh, world frame, metres.

    Attributes:
        object_id: the PartialObject's id.
        index: j, the hypothesis' index among the object's hypotheses (-1: minimum shape).
        vertices: (V, 3) float64 hull vertices (m, world).
        faces: (F, 3) int64 triangles, counter-clockwise seen from outside (outward normals).
        volume_m3: enclosed volume.
        distances_m: (K,) the sampled distance d of each mirrored facet, in mirroring order.
        facet_normals: (K, 3) unit normal N of each mirrored facet.
        facet_sources: (K,) "observed", "hull" or "object" (all points as one facet) per facet.
        rounds: rounds of the repeat loop used.
        attempts: samples drawn before this one was kept.
        feasible: passed the unary checks at generation (support, walls, free space).
        free_voxels: voxels in seen-free space beyond ``forced_free_voxels`` and
            ``excused_free_voxels``.
        wall_voxels: voxels inside known walls beyond those the observed hull has.
        forced_free_voxels: seen-free voxels of the observed points' own hull (forced), beyond
            those the object's surface allowance excuses.
        excused_free_voxels: its seen-free voxels within the object's surface allowance of its
            observed points (``ipr_shapes.hypotheses.allowance``), not counted; 0 unless none of
            the object's hypotheses passed the seen-free check without the allowance.
        forced_wall_voxels: wall voxels of the observed points' own hull (forced).
        voxel_keys: sorted ``ipr_shapes.voxels`` keys of its voxels at ``voxel_pitch_m`` (None when
            not voxelised, e.g. without a free-space map).
        voxel_pitch_m: pitch of ``voxel_keys`` (m).
        generator: what made it (Algorithm 1 or one of
            ``ipr_shapes.hypotheses.structure.STRUCTURE_GENERATORS``): "algorithm1"
            (mirrored facets), "symmetry" (reflective symmetry planes), "revolution"
            (rotational symmetry about the support normal), "box", "cylinder", "sphere"
            (primitives fitted to the observed points), "superquadric" (a superquadric with
            fitted exponents) or "minimum" (the minimum shape).
        carved: ``voxel_keys`` are its hull's voxels minus those the camera saw empty
            (``ipr_shapes.carving.carve_hypotheses``: carved before the choice, so that the
            medoid weighs the shapes that will be written); ``vertices`` and ``faces`` stay the
            convex hull the physics and the constraints use.
    """

    object_id: int
    index: int
    vertices: np.ndarray
    faces: np.ndarray
    volume_m3: float
    distances_m: np.ndarray
    facet_normals: np.ndarray
    facet_sources: tuple[str, ...] = ()
    rounds: int = 0
    attempts: int = 1
    feasible: bool = True
    free_voxels: int = 0
    wall_voxels: int = 0
    forced_free_voxels: int = 0
    excused_free_voxels: int = 0
    forced_wall_voxels: int = 0
    voxel_keys: np.ndarray | None = None
    voxel_pitch_m: float = voxels.DEFAULT_PITCH_M
    generator: str = "algorithm1"
    carved: bool = False

    @functools.cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounding box [minimum, maximum] (m, world); computed once (the
        constraints ask for it per pair of objects) and read-only."""
        box = np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])
        box.setflags(write=False)
        return box

    @functools.cached_property
    def width_m(self) -> float:
        """Thickness (m): the least extent of the hull along one of its face normals (the
        distance from a face's plane to the farthest vertex behind it). Exact for boxes and
        slabs, otherwise at least the minimal width (it may be attained between two edges);
        the pairwise constraint measures a thin candidate's penetration against it
        (``ipr_shapes.hypotheses.constraints``). Computed once, compiled
        (``ipr_shapes.geometry.kernels.hull_width``)."""
        from ipr_shapes.geometry.kernels import hull_width

        return float(hull_width(np.asarray(self.vertices, float), np.asarray(self.faces, np.int64)))

    @property
    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces), the pair ``ipr_shapes.voxels`` and ``ipr_shapes.result`` accept."""
        return self.vertices, self.faces

    def face_planes(self) -> np.ndarray:
        """(F, 4) outward face planes (unit normal, offset): inside iff n . x + offset <= 0."""
        tri = self.vertices[self.faces]
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        lengths = np.linalg.norm(normals, axis=1)
        keep = lengths > 1e-15
        normals = normals[keep] / lengths[keep, None]
        return np.column_stack([normals, -np.einsum("ij,ij->i", normals, tri[keep, 0])])

    def contains(self, points: np.ndarray, tolerance_m: float = 1e-6) -> np.ndarray:
        """(N,) bool: which (N, 3) world points lie inside the hull (within ``tolerance_m``)."""
        planes = self.face_planes()
        return np.all(points @ planes[:, :3].T + planes[:, 3] <= tolerance_m, axis=1)

    def keys(self, pitch_m: float | None = None) -> np.ndarray:
        """Voxel keys at ``pitch_m`` (default: the stored pitch); cached ones when they match."""
        pitch = self.voxel_pitch_m if pitch_m is None else pitch_m
        if self.voxel_keys is not None and np.isclose(pitch, self.voxel_pitch_m):
            return self.voxel_keys
        return voxels.scanline_voxels(self.vertices, self.faces, pitch)

    def to_trimesh(self):
        """The hull as a ``trimesh.Trimesh`` (not re-processed)."""
        import trimesh

        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)


def hypotheses_to_trimesh(hypotheses: tuple[ShapeHypothesis, ...] | list[ShapeHypothesis]):
    """Trimesh meshes of a sequence of hypotheses, in order."""
    return [h.to_trimesh() for h in hypotheses]


def volume_spread(hypotheses: tuple[ShapeHypothesis, ...] | list[ShapeHypothesis]) -> dict:
    """Volumes of an object's hypotheses: min, median, max (m^3) and max / min."""
    volumes = np.array([h.volume_m3 for h in hypotheses], dtype=float)
    if volumes.size == 0:
        return {"min": 0.0, "median": 0.0, "max": 0.0, "ratio": 1.0}
    return {
        "min": float(volumes.min()),
        "median": float(np.median(volumes)),
        "max": float(volumes.max()),
        "ratio": float(volumes.max() / max(volumes.min(), 1e-12)),
    }


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
            write the hypothesis itself (``ipr_shapes.carving`` sets it); None: write every
            hypothesis as it is.
        output_keys: per hypothesis, the sorted ``ipr_shapes.voxels`` keys (default pitch) of
            its ``output_meshes`` entry, the voxels its centres-inside voxelisation reads back
            (``ipr_shapes.carving.voxel_surface``), or None; None: not known.
    """

    object_id: int
    hypotheses: tuple[ShapeHypothesis, ...]
    probabilities: np.ndarray
    best: int
    minimum: ShapeHypothesis
    inference: str
    generation_s: float = 0.0
    output_meshes: tuple[tuple[np.ndarray, np.ndarray] | None, ...] | None = None
    output_keys: tuple[np.ndarray | None, ...] | None = None

    def __post_init__(self) -> None:
        # Carved voxels stand for carved meshes: keys without meshes, or of another length,
        # would write an occupancy that is not the written shapes'.
        if self.output_keys is not None and (
            self.output_meshes is None or len(self.output_keys) != len(self.output_meshes)
        ):
            raise ValueError(
                "ObjectPosterior.output_keys needs output_meshes of the same length "
                "(set both, as ipr_shapes.carving does, or neither)"
            )

    @property
    def best_hypothesis(self) -> ShapeHypothesis:
        """The most probable hypothesis (convex, as inferred)."""
        return self.hypotheses[self.best]

    def written_mesh(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces) written for hypothesis k: its carved shape if any, else itself."""
        if self.output_meshes is not None and self.output_meshes[k] is not None:
            return self.output_meshes[k]
        return self.hypotheses[k].mesh

    def written_shape(self, k: int, pitch_m: float = voxels.DEFAULT_PITCH_M) -> Any:
        """Hypothesis k's written shape as ``ipr_shapes.result.posterior_occupancy`` takes it,
        without voxelising it again where its voxels at ``pitch_m`` are known: a carved
        shape's ``output_keys`` (at the default pitch), else the hypothesis's cached voxel
        keys when it is written as itself (the same scanline voxelisation of the same closed
        hull); otherwise ``written_mesh(k)``."""
        hypothesis = self.hypotheses[k]
        carved = self.output_meshes is not None and self.output_meshes[k] is not None
        if carved:
            known = self.output_keys[k] if self.output_keys is not None else None
            if known is not None and np.isclose(pitch_m, voxels.DEFAULT_PITCH_M):
                return known
            return self.written_mesh(k)
        if hypothesis.voxel_keys is None:
            return self.written_mesh(k)
        if not np.isclose(pitch_m, hypothesis.voxel_pitch_m):
            return self.written_mesh(k)
        return hypothesis.voxel_keys

    @property
    def output_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces) of the output shape (``best.ply``)."""
        return self.written_mesh(self.best)


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
        depths: (a, b) -> (len(candidates[a]), len(candidates[b])) overlap measures (m) for
            interacting pairs (a before b in ``ids``); pairs absent never conflict. The
            penetration depth, scaled by tolerance / thickness where the thinner candidate is
            thinner than the tolerance (``ipr_shapes.hypotheses.constraints.overlap_matrix``).
        thresholds: (a, b) -> the largest allowed measure (m) for that pair.
    """

    ids: list[int]
    generated: dict[int, tuple[ShapeHypothesis, ...]]
    minima: dict[int, ShapeHypothesis]
    candidates: dict[int, list[int]]
    seconds: dict[int, float]
    depths: dict[tuple[int, int], np.ndarray]
    thresholds: dict[tuple[int, int], float]


@dataclass(frozen=True)
class StageTimings:
    """Wall-clock seconds a run spent per stage (``result.json``'s ``timing_s``).

    Attributes:
        segmentation: perception of every frame (s).
        hypotheses: hypothesis generation and constraints (s).
        inference: the method's inference after the hypotheses (s).
        fusion: registering later views into frame 0 (s; None for the methods that do not).
        inference_collision_checker: of ``inference``, the Collision Checker's answer that
            the physics methods start from (s; None for the Collision Checker itself).
        inference_sampling: of ``inference``, tree sampling and simulation (s).
        carving: carving the written shapes by observed free space (s; None when off).
        total: the whole run (s).
    """

    segmentation: float
    hypotheses: float
    inference: float
    fusion: float | None = None
    inference_collision_checker: float | None = None
    inference_sampling: float | None = None
    carving: float | None = None
    total: float = 0.0

    _ORDER = (
        "segmentation",
        "fusion",
        "hypotheses",
        "inference",
        "inference_collision_checker",
        "inference_sampling",
        "carving",
        "total",
    )

    def to_dict(self) -> dict[str, float]:
        """Name -> seconds of the stages that ran, in pipeline order."""
        values = {name: getattr(self, name) for name in self._ORDER}
        return {name: float(value) for name, value in values.items() if value is not None}


@dataclass(frozen=True)
class SamplingSummary:
    """How a physics-based method's posterior was obtained (``result.json``, ``inference``).

    Attributes:
        samples: joint models evaluated.
        impossible_samples: of those, simulations that exploded or flung an object.
        effective_sample_size: median over objects of Kish's effective sample size of the
            per-object importance weights (a diagnostic).
        stability_tests: simulations run for the exploration probabilities.
        workers: processes that evaluated samples.
        pushes_replayed: pushes simulated per joint model.
        frames_compared: observed frames compared with the simulation.
        fallback: why the Collision Checker's answer was returned instead (None: it was not).
        frictions: the scene frictions searched with the shapes (one value: not searched).
        friction_posterior: P(friction | O) over ``frictions`` (sums to 1; None with the
            fallback).
    """

    samples: int
    impossible_samples: int
    effective_sample_size: float
    stability_tests: int
    workers: int
    pushes_replayed: int
    frames_compared: int
    fallback: str | None
    frictions: tuple[float, ...] = ()
    friction_posterior: tuple[float, ...] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The fields as a JSON-ready dict, in declaration order."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


@dataclass(frozen=True)
class RunSummary:
    """Method-specific details of a run (``result.json``'s ``inference`` key).

    Attributes:
        fused_views: per result object id (as a string), the later frames whose
            views were registered into it; None when the method does not fuse views.
        sampling: the physics-based method's sampling summary (None for the Collision
            Checker, or when there was no object).
    """

    fused_views: Mapping[str, list[int]] | None = None
    sampling: SamplingSummary | None = None

    def to_dict(self) -> dict[str, Any]:
        """One flat JSON-ready dict (empty when there is nothing to say)."""
        out: dict[str, Any] = {}
        if self.fused_views is not None:
            out["fused_views"] = dict(self.fused_views)
        if self.sampling is not None:
            out.update(self.sampling.to_dict())
        return out
