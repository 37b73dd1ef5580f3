"""Other objects' observed surfaces bound an object's hidden extent (issue 28, ceiling gap).

A hidden part of object A cannot hold a surface the camera saw on object B. The free-space
map cannot say so: it calls every observed surface OCCUPIED, whichever object it belongs to,
so Algorithm 1's rays and the structure-aware reaches run through a neighbour's visible side
and the unary check accepts a candidate that swallows it; only the pairwise constraint, after
generation, rejects such a candidate, and when every candidate of A does, the jointly
feasible set loses A's good candidates too (docs/experiments/2026-11-26-ceiling-gap.md).

``neighbour_spaces`` gives each object a view of the space in which the voxels holding the
other objects' observed points (and none of its own) read FREE: seen free *of this object*.
``generate_hypotheses`` casts the hidden extent's rays through it (its ``bounds``), so they
stop there. The unary check keeps the frame's own space: a convex candidate of a concave
object (a pitcher, a bowl) must hold whatever lies in its concavity, and only the pairwise
constraint can tolerate such forced overlap (``relax_forced_overlap``); counted as seen-free
space in the unary check, a neighbour in the concavity made every candidate infeasible (a
suite scene's large object fell back to its minimum shape, 0.81 -> 0.49).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.perception.free_space import FREE, SeenSpace, SpaceMap, VoxelGrid
from ipr_shapes.perception.types import PartialObject


def _point_keys(points: np.ndarray, pitch_m: float) -> np.ndarray:
    """Sorted unique voxel keys (global lattice of ``pitch_m``) of (N, 3) world points (m)."""
    points = np.asarray(points, float).reshape(-1, 3)
    points = points[np.all(np.isfinite(points), axis=1)]
    return np.unique(voxels.pack(np.floor(points / pitch_m).astype(np.int64)))


@dataclass(frozen=True, eq=False)
class NeighbourSpace:
    """A seen space in which the voxels of ``blocked`` (sorted keys at the grid's pitch) read
    FREE; for a base that is not a ``SpaceMap`` (a tracked view over several frames)."""

    base: SeenSpace
    blocked: np.ndarray

    @property
    def grid(self) -> VoxelGrid:
        """The base's grid."""
        return self.base.grid

    @property
    def view(self) -> np.ndarray | None:
        """The base's field of view (``SpaceMap.view``), None when it has none."""
        return getattr(self.base, "view", None)

    def state_at(self, points: np.ndarray) -> np.ndarray:
        """State (N,) of the voxels holding world points (N, 3)."""
        states = np.array(self.base.state_at(points), dtype=np.uint8, copy=True)
        if self.blocked.size and len(points):
            pitch = self.base.grid.voxel_size_m
            keys = voxels.pack(np.floor(np.asarray(points, float) / pitch).astype(np.int64))
            states[np.isin(keys, self.blocked)] = FREE
        return states


def neighbour_spaces(
    objects: tuple[PartialObject, ...],
    space: SeenSpace | None,
    object_spaces: Mapping[int, SeenSpace] | None = None,
) -> dict[int, SeenSpace]:
    """Per object id, its seen space (``object_spaces`` or ``space``) with the voxels of the
    other objects' observed points that hold none of its own reading FREE (module doc); an
    object without a space is left out."""
    out: dict[int, SeenSpace] = {}
    keys: dict[tuple[int, float], np.ndarray] = {}

    def point_keys(obj: PartialObject, pitch: float) -> np.ndarray:
        if (obj.id, pitch) not in keys:
            keys[(obj.id, pitch)] = _point_keys(obj.points, pitch)
        return keys[(obj.id, pitch)]

    for obj in objects:
        seen = (object_spaces or {}).get(obj.id, space)
        if seen is None:
            continue
        pitch = float(seen.grid.voxel_size_m)
        others = [point_keys(o, pitch) for o in objects if o.id != obj.id]
        blocked = np.setdiff1d(
            np.unique(np.concatenate(others)) if others else np.zeros(0, np.int64),
            point_keys(obj, pitch),
            assume_unique=True,
        )
        if isinstance(seen, SpaceMap) and np.allclose(
            np.round(seen.grid.origin / pitch) * pitch, seen.grid.origin, rtol=0, atol=1e-9
        ):
            state = seen.state.copy()
            indices = voxels.unpack(blocked) - np.round(seen.grid.origin / pitch).astype(np.int64)
            inside = np.all((indices >= 0) & (indices < np.array(seen.grid.shape)), axis=1)
            state[tuple(indices[inside].T)] = FREE
            out[obj.id] = SpaceMap(seen.grid, state, getattr(seen, "view", None))
        else:
            out[obj.id] = NeighbourSpace(seen, blocked)
    return out
