"""Convex hulls as closed, outward-oriented triangle meshes (metres), and half-space cuts.

Every hypothesis is convex (the physics needs convex shapes), and perception joins occluded
pieces by testing their joint hull: both use these helpers, so they sit below both stages.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

#: Volumes below this (m^3) are degenerate (flat or collinear point sets).
_MIN_VOLUME_M3 = 1e-9


def convex_mesh(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Convex hull of (N, 3) points as (vertices (V, 3), outward faces (F, 3), volume m^3);
    None when the points span no volume (fewer than 4, coplanar or collinear)."""
    if len(points) < 4:
        return None
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return None
    if hull.volume < _MIN_VOLUME_M3:
        return None
    return _oriented_mesh(hull)


def triangle_cross(tri: np.ndarray) -> np.ndarray:
    """(F, 3) cross products (b - a) x (c - a) of triangles (F, 3, 3) with corners a, b, c (m):
    normals of length twice the area (m^2). ``np.cross``'s arithmetic (each product rounded,
    then their difference: the same bits) without its per-call overhead, which dominates on
    a hull's few hundred triangles."""
    u = tri[:, 1] - tri[:, 0]
    v = tri[:, 2] - tri[:, 0]
    out = np.empty_like(u)
    out[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    out[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    out[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


def row_norms(vectors: np.ndarray) -> np.ndarray:
    """(N,) Euclidean norms of (N, 3) rows: ``np.linalg.norm(vectors, axis=1)``'s arithmetic
    (the same bits) without its per-call overhead."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=1))


def _oriented_mesh(hull: ConvexHull) -> tuple[np.ndarray, np.ndarray, float]:
    """Compact, outward-oriented triangle mesh of a scipy hull: compiled
    (``geometry.kernels.oriented_hull_mesh``, the same arrays), numpy's steps
    (``_oriented_mesh_numpy``) when an orientation is too close to call there."""
    from ipr_shapes.geometry.kernels import oriented_hull_mesh

    vertices, faces, certain = oriented_hull_mesh(
        hull.points, np.ascontiguousarray(hull.simplices), np.ascontiguousarray(hull.equations)
    )
    if not certain:
        return _oriented_mesh_numpy(hull)
    return vertices, faces, float(hull.volume)


def _oriented_mesh_numpy(hull: ConvexHull) -> tuple[np.ndarray, np.ndarray, float]:
    """``_oriented_mesh`` in numpy (the reference, and the fallback)."""
    simplices = hull.simplices.copy()
    tri = hull.points[simplices]
    normals = triangle_cross(tri)
    flip = np.einsum("ij,ij->i", normals, hull.equations[:, :3]) < 0
    simplices[flip] = simplices[flip][:, [0, 2, 1]]
    # Compact the vertices (the same order as np.unique's, without its sort).
    used = np.zeros(len(hull.points), dtype=bool)
    used[simplices] = True
    number = np.cumsum(used) - 1
    faces = number[simplices].astype(np.int64)
    return hull.points[used].copy(), faces, float(hull.volume)


def clip_halfspace(
    vertices: np.ndarray, faces: np.ndarray, normal: np.ndarray, offset: float
) -> np.ndarray:
    """Vertices (K, 3) of a convex mesh cut to {x : normal . x + offset >= 0}: the vertices on
    that side plus the crossings of the mesh's edges with the plane (their hull is the cut)."""
    distance = vertices @ normal + offset
    if distance.min() >= 0:
        return vertices
    # The mesh's edges (E, 2), (low, high) in lexicographic order: np.unique(axis=0) of the
    # sorted pairs, as one int64 key per pair (the same rows, without the row-wise sort).
    pairs = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    count = np.int64(len(vertices))
    keys = np.unique(pairs[:, 0].astype(np.int64) * count + pairs[:, 1])
    edges = np.stack([keys // count, keys % count], axis=1)
    da, db = distance[edges[:, 0]], distance[edges[:, 1]]
    crossing = (da < 0) != (db < 0)
    a, b = edges[crossing, 0], edges[crossing, 1]
    t = (da[crossing] / (da[crossing] - db[crossing]))[:, None]
    cut = vertices[a] + t * (vertices[b] - vertices[a])
    return np.concatenate([vertices[distance >= 0], cut])


def unique_rows(rows: np.ndarray) -> np.ndarray:
    """``np.unique(rows, axis=0)`` of (N, K) floats: the distinct rows in lexicographic order,
    the same bits, by a stable ``np.lexsort`` instead of numpy's sort of rows as structured
    scalars (compared field by field, ten times slower on a hull's few hundred planes). The
    two agree whenever numerically equal rows are also bitwise equal; rows equal but for the
    sign of a zero (which one ``np.unique`` keeps depends on its unstable sort) or any NaN
    send the call to ``np.unique`` itself."""
    rows = np.asarray(rows)
    if rows.ndim != 2 or len(rows) < 2 or rows.dtype != np.float64 or np.isnan(rows).any():
        return np.unique(rows, axis=0)
    ordered = rows[np.lexsort(rows.T[::-1])]
    same = np.all(ordered[1:] == ordered[:-1], axis=1)
    if same.any() and not np.array_equal(
        ordered[1:][same].view(np.int64), ordered[:-1][same].view(np.int64)
    ):
        return np.unique(rows, axis=0)
    return ordered[np.concatenate([[True], ~same])]
