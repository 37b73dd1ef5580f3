"""How much of a voxelised shape lies where the camera saw free space or inside a known wall,
and how far it reaches below the support: the measurements behind the unary constraints.

The hypotheses' unary constraints (``ipr_shapes.hypotheses.constraints``) and the joining of occluded
pieces (``ipr_shapes.perception.occlusion``) ask the same questions of the frame's space map and known
planes, so they share this one implementation.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ipr_shapes import voxels
from ipr_shapes.perception.free_space import FREE, UNKNOWN, SeenSpace, SpaceMap
from ipr_shapes.perception.types import KnownPlane

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class PlaneRegion:
    """A known plane prepared for fast inside tests.

    Attributes:
        plane: the KnownPlane.
        axes: (2, 3) orthonormal in-plane directions.
        outline: (P, 3) 2-D half-planes (a, b, c) of the wall's points' outline in ``axes``
            coordinates, inside iff a s + b t + c <= 0; None for an unbounded plane.
        thickness_m: slab depth behind the visible face (walls).
    """

    plane: KnownPlane
    axes: np.ndarray
    outline: np.ndarray | None
    thickness_m: float

    @property
    def is_support(self) -> bool:
        """True for the support plane (a half-space), False for a wall (a slab)."""
        return self.plane.kind == "support"

    def in_wall(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """(N,) bool: (N, 3) points inside the wall's slab, shrunk by ``margin_m`` all round."""
        distance = self.plane.signed_distance(points)
        inside = (distance < -margin_m) & (distance > -(self.thickness_m - margin_m))
        if self.outline is not None and inside.any():
            st = points[inside] @ self.axes.T
            lateral = np.all(st @ self.outline[:, :2].T + self.outline[:, 2] <= -margin_m, axis=1)
            inside[np.flatnonzero(inside)[~lateral]] = False
        return inside


def plane_regions(
    planes: tuple[KnownPlane, ...], wall_min_thickness_m: float = 0.005
) -> tuple[PlaneRegion, ...]:
    """Prepare known planes for inside tests (walls at least ``wall_min_thickness_m`` thick)."""
    regions = []
    for plane in planes:
        normal = np.asarray(plane.normal, float)
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
        u = np.cross(normal, helper)
        u /= np.linalg.norm(u)
        axes = np.stack([u, np.cross(normal, u)])
        outline = None
        if plane.kind != "support":
            points = np.asarray(plane.points, float).reshape(-1, 3)
            if len(points) >= 3:
                try:
                    hull = ConvexHull(points @ axes.T)
                    outline = hull.equations
                except (QhullError, ValueError):
                    logger.warning("wall outline is degenerate; treating the wall as unbounded")
            else:
                logger.warning("wall has fewer than 3 points; treating it as unbounded")
        thickness = max(float(plane.thickness_m), wall_min_thickness_m)
        regions.append(PlaneRegion(plane, axes, outline, thickness))
    return tuple(regions)


@dataclass(frozen=True)
class UnaryReport:
    """Unary constraint measurements of one convex shape.

    Attributes:
        voxel_count: voxels (centres inside) at the pitch used.
        free_voxels: of those, voxels seen FREE.
        wall_voxels: voxels inside a known wall's slab.
        below_support_m: deepest vertex below a support plane (m, >= 0).
    """

    voxel_count: int
    free_voxels: int
    wall_voxels: int
    below_support_m: float


def unary_report(
    vertices: np.ndarray,
    keys: np.ndarray | None,
    pitch_m: float,
    space: SeenSpace | None,
    regions: tuple[PlaneRegion, ...],
) -> UnaryReport:
    """Measure a convex shape (vertices (V, 3), voxel ``keys`` at ``pitch_m``) against the space
    map and known planes. Support: exact from the vertices (the hull's lowest point is one)."""
    below = 0.0
    for region in regions:
        if region.is_support:
            below = max(below, float(-region.plane.signed_distance(vertices).min()))
    free = walls = 0
    count = 0 if keys is None else int(keys.size)
    if keys is not None and keys.size:
        walls_regions = [region for region in regions if not region.is_support]
        if space is not None:
            free = _free_count(space, keys, pitch_m)
        if walls_regions:
            centres = voxels.centres(keys, pitch_m)
            wall_mask = np.zeros(len(centres), dtype=bool)
            for region in walls_regions:
                wall_mask |= region.in_wall(centres)
            walls = int(np.count_nonzero(wall_mask))
    return UnaryReport(count, free, walls, below)


def _lattice_offset(space: SeenSpace, pitch_m: float) -> np.ndarray | None:
    """(3,) int64 lattice index of a ``SpaceMap``'s origin when its grid has pitch ``pitch_m``
    and sits on the same lattice as voxel keys (``VoxelGrid.around`` aligns it), else None."""
    if isinstance(space, SpaceMap) and space.grid.voxel_size_m == pitch_m:
        origin = np.asarray(space.grid.origin, float)
        offset = np.round(origin / pitch_m)
        # np.allclose(offset * pitch_m, origin, rtol=0, atol=1e-9), without its overhead.
        if bool(np.all(np.abs(offset * pitch_m - origin) <= 1e-9)):
            return offset.astype(np.int64)
    return None


def _free_count(space: SeenSpace, keys: np.ndarray, pitch_m: float) -> int:
    """Number of voxel keys at ``pitch_m`` that ``space`` holds FREE: ``_states(...) == FREE``
    counted, in one compiled pass over the keys on a lattice-aligned ``SpaceMap``."""
    offset = _lattice_offset(space, pitch_m)
    if offset is not None:
        from ipr_shapes.perception.kernels import count_key_states

        state = space.state  # type: ignore[attr-defined]
        return int(
            count_key_states(
                np.ascontiguousarray(keys, dtype=np.int64), offset, state, FREE, voxels._BITS
            )
        )
    return int(np.count_nonzero(_states(space, keys, pitch_m) == FREE))


def _states(space: SeenSpace, keys: np.ndarray, pitch_m: float) -> np.ndarray:
    """``space.state_at`` of the centres of voxel keys at ``pitch_m``; on a ``SpaceMap`` whose grid
    has that pitch and sits on the same lattice (``VoxelGrid.around`` aligns it), the keys'
    integer indices are looked up directly (the same voxels, no float division)."""
    if isinstance(space, SpaceMap) and space.grid.voxel_size_m == pitch_m:
        offset = np.round(np.asarray(space.grid.origin, float) / pitch_m)
        if np.allclose(offset * pitch_m, space.grid.origin, rtol=0, atol=1e-9):
            indices = voxels.unpack(keys) - offset.astype(np.int64)
            shape = space.state.shape
            inside = (
                (indices[:, 0] >= 0) & (indices[:, 0] < shape[0])
                & (indices[:, 1] >= 0) & (indices[:, 1] < shape[1])
                & (indices[:, 2] >= 0) & (indices[:, 2] < shape[2])
            )  # fmt: skip
            states = np.full(len(keys), UNKNOWN, dtype=np.uint8)
            kept = indices[inside]
            flat = (kept[:, 0] * shape[1] + kept[:, 1]) * shape[2] + kept[:, 2]
            states[inside] = space.state.reshape(-1)[flat]
            return states
    return space.state_at(voxels.centres(keys, pitch_m))


def allowed_voxels(voxel_count: int, share: float, count: int) -> int:
    """Offending voxels tolerated in a shape of ``voxel_count`` voxels: max(share x n, count)."""
    return max(int(np.floor(share * voxel_count)), int(count))
