"""Voxel occupancy of closed triangle meshes, exact at voxel centres (the metrics' 5 mm grid).

The grid is fixed in the world frame: voxel ``(i, j, k)`` has its centre at
``((i + 1/2) p, (j + 1/2) p, (k + 1/2) p)`` for pitch ``p`` in metres, and is occupied iff its
centre is inside the closed mesh (odd number of surface crossings above it, so orientation and
winding do not matter). A mesh that is not closed is replaced by its convex hull, as the result
contract says.

Occupancy is computed by a vectorised column-parity scanline: every triangle lists the voxel
columns (x, y centres) inside its xy-projection and the height z at which it crosses each of
them; the crossings of a column, sorted by z, pair up into inside intervals whose voxel centres
are filled. Points on a projected edge or vertex are decided by simulation of simplicity (the
column is displaced by (eps, eps^2)) with exact integer edge functions (xy in fixed point), so
the two triangles sharing an edge never both count (or both miss) the column, and a column
through a vertex meets exactly the triangles the displaced column meets. Along z the inside
intervals are half-open, [lower crossing, upper crossing). Only centres lying exactly on the
surface (a set of measure zero) depend on these conventions; parity itself is exact.

Occupied voxels are a sorted, unique ``int64`` key array (``pack``): set operations on two grids
are merges of sorted arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: The contract's metric grid pitch (m).
DEFAULT_PITCH_M = 0.005
#: Bits per axis in a key; indices are stored with an offset so that negative ones pack.
_BITS = 21
_OFFSET = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1
#: Vertices closer than this (m) are the same vertex when testing whether a mesh is closed.
MERGE_TOLERANCE_M = 1e-8

EMPTY = np.zeros(0, dtype=np.int64)


# --------------------------------------------------------------------------------------------
# Keys


def pack(indices: np.ndarray) -> np.ndarray:
    """Keys (N,) int64 of integer voxel indices (N, 3); each index must be in [-2^20, 2^20).

    Keys sort like the (i, j, k) tuples, so sorted keys are in lexicographic voxel order.
    """
    indices = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    if indices.size and (indices.min() < -_OFFSET or indices.max() >= _OFFSET):
        raise ValueError(
            f"voxel index out of range [-{_OFFSET}, {_OFFSET}): the mesh is too far from the "
            "origin or too large for this pitch"
        )
    shifted = indices + _OFFSET
    return (shifted[:, 0] << (2 * _BITS)) | (shifted[:, 1] << _BITS) | shifted[:, 2]


def unpack(keys: np.ndarray) -> np.ndarray:
    """Integer voxel indices (N, 3) int64 of keys (N,)."""
    keys = np.asarray(keys, dtype=np.int64)
    return np.stack([keys >> (2 * _BITS), (keys >> _BITS) & _MASK, keys & _MASK], axis=-1) - _OFFSET


def centres(keys: np.ndarray, pitch_m: float = DEFAULT_PITCH_M) -> np.ndarray:
    """Voxel centres (N, 3) float64 in metres, world frame, of keys (N,)."""
    return (unpack(keys).astype(np.float64) + 0.5) * pitch_m


def union(*key_arrays: np.ndarray) -> np.ndarray:
    """Sorted unique keys occupied in any of the given key arrays."""
    arrays = [np.asarray(keys, dtype=np.int64) for keys in key_arrays]
    if not arrays:
        return EMPTY.copy()
    return np.unique(np.concatenate(arrays))


def intersection(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sorted keys occupied in both sorted unique key arrays."""
    return np.intersect1d(a, b, assume_unique=True)


def intersection_count(a: np.ndarray, b: np.ndarray) -> int:
    """Number of voxels occupied in both sorted unique key arrays (no copy of either)."""
    if a.size == 0 or b.size == 0:
        return 0
    if a.size > b.size:
        a, b = b, a
    position = np.searchsorted(b, a)
    position[position == b.size] = 0
    return int(np.count_nonzero(b[position] == a))


def count(keys: np.ndarray) -> int:
    """Number of occupied voxels."""
    return int(np.asarray(keys).size)


def volume_m3(keys: np.ndarray, pitch_m: float = DEFAULT_PITCH_M) -> float:
    """Occupied volume in cubic metres (count x pitch^3)."""
    return count(keys) * pitch_m**3


# --------------------------------------------------------------------------------------------
# Mesh preparation


def _as_arrays(mesh: Any) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of a trimesh or a (vertices, faces) pair."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        vertices, faces = mesh.vertices, mesh.faces
    else:
        vertices, faces = mesh
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError("mesh faces index vertices that do not exist")
    return vertices, faces


def merge_vertices(
    vertices: np.ndarray, faces: np.ndarray, tolerance_m: float = MERGE_TOLERANCE_M
) -> tuple[np.ndarray, np.ndarray]:
    """Merge coincident vertices (within ``tolerance_m``) and drop faces that become degenerate.

    Returns (V', 3) vertices (the first of each merged group) and (F', 3) faces into them.
    """
    if len(vertices) == 0:
        return vertices.reshape(0, 3), faces.reshape(0, 3)
    quantised = np.round(vertices / tolerance_m).astype(np.int64)
    order = np.lexsort(quantised.T[::-1])
    sorted_q = quantised[order]
    new_group = np.ones(len(order), dtype=bool)
    new_group[1:] = np.any(sorted_q[1:] != sorted_q[:-1], axis=1)
    group_of_sorted = np.cumsum(new_group) - 1
    remap = np.empty(len(vertices), dtype=np.int64)
    remap[order] = group_of_sorted
    merged = vertices[order[new_group]]
    faces = remap[faces]
    keep = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    return merged, faces[keep]


def is_closed(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """True when every edge of the (merged, non-degenerate) mesh is shared by an even number of
    faces, so that every generic vertical line crosses the surface an even number of times.

    Call on the output of ``merge_vertices``: coincident but distinct vertices make edges open.
    A mesh without faces is not closed.
    """
    if len(faces) == 0:
        return False
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges.sort(axis=1)
    keys = edges[:, 0] * (int(faces.max()) + 1) + edges[:, 1]
    keys.sort()
    boundaries = np.flatnonzero(np.diff(keys)) + 1
    runs = np.diff(np.concatenate([[0], boundaries, [keys.size]]))
    return bool(np.all(runs % 2 == 0))


def convex_hull(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull of (N, 3) points as (vertices, faces); empty arrays when it has no volume."""
    from scipy.spatial import ConvexHull, QhullError

    empty = (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    if len(vertices) < 4:
        return empty
    try:
        hull = ConvexHull(vertices)
    except (QhullError, ValueError):
        return empty  # flat or degenerate point set: no interior
    used, faces = np.unique(hull.simplices, return_inverse=True)
    return vertices[used], faces.reshape(-1, 3).astype(np.int64)


def closed_or_hull(mesh: Any) -> tuple[np.ndarray, np.ndarray, bool]:
    """The mesh to score: its merged self when closed, else its convex hull (contract rule).

    ``mesh`` is a trimesh or a (vertices (V, 3), faces (F, 3)) pair. Returns (vertices, faces,
    closed) where ``closed`` tells whether the mesh itself (True) or its hull (False) is returned.
    """
    vertices, faces = _as_arrays(mesh)
    merged, merged_faces = merge_vertices(vertices, faces)
    if is_closed(merged, merged_faces):
        return merged, merged_faces, True
    hull_vertices, hull_faces = convex_hull(vertices[np.unique(faces)] if faces.size else vertices)
    return hull_vertices, hull_faces, False


def transform_points(transform: np.ndarray | None, points: np.ndarray) -> np.ndarray:
    """(N, 3) points mapped by a 4x4 transform (None = identity)."""
    if transform is None:
        return points
    transform = np.asarray(transform, dtype=np.float64)
    return points @ transform[:3, :3].T + transform[:3, 3]


# --------------------------------------------------------------------------------------------
# Occupancy


#: The largest extent (m) of a mesh that is voxelised: an object in clutter is far smaller,
#: and a mesh in millimetres read as metres (1000 times too large) would need terabytes.
MAX_MESH_EXTENT_M = 10.0
#: The farthest (m) a voxelised mesh may lie from the world origin (``ipr_shapes.scene`` refuses
#: cameras and ground truth farther away): table-top scenes span a few metres.
MAX_DISTANCE_M = 100.0


def occupied_voxels(
    mesh: Any,
    pitch_m: float = DEFAULT_PITCH_M,
    world_from_mesh: np.ndarray | None = None,
) -> np.ndarray:
    """Sorted unique keys (N,) int64 of the world-grid voxels whose centre is inside the mesh.

    ``mesh`` is a trimesh or a (vertices (V, 3) metres, faces (F, 3)) pair in its own frame,
    placed in the world by ``world_from_mesh`` (4x4, None = already in the world frame). A mesh
    that is not closed is scored as its convex hull.
    """
    vertices, faces, _ = closed_or_hull(mesh)
    return scanline_voxels(transform_points(world_from_mesh, vertices), faces, pitch_m)


def occupied_voxels_many(
    meshes: Sequence[Any],
    pitch_m: float = DEFAULT_PITCH_M,
    world_from_mesh: Sequence[np.ndarray | None] | None = None,
) -> list[np.ndarray]:
    """``occupied_voxels`` of each mesh (with its own world_from_mesh, or None for all)."""
    transforms = list(world_from_mesh) if world_from_mesh is not None else [None] * len(meshes)
    if len(transforms) != len(meshes):
        raise ValueError(f"{len(meshes)} meshes but {len(transforms)} transforms")
    return [occupied_voxels(m, pitch_m, t) for m, t in zip(meshes, transforms, strict=True)]


def scanline_voxels(vertices: np.ndarray, faces: np.ndarray, pitch_m: float) -> np.ndarray:
    """Core column-parity scanline on a closed mesh already in the world frame.

    Args:
        vertices: (V, 3) float64, metres, world frame. Shared vertices must be shared by index
            (``merge_vertices``) for exact edge consistency.
        faces: (F, 3) int indices; orientation does not matter.
        pitch_m: voxel edge length in metres.

    Returns:
        Sorted unique int64 keys of the voxels whose centre is inside (odd crossing parity).
    """
    if pitch_m <= 0 or not np.isfinite(pitch_m):
        raise ValueError(f"pitch must be positive, got {pitch_m}")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return EMPTY.copy()
    if not np.all(np.isfinite(vertices)):
        raise ValueError("mesh vertices contain NaN or inf")
    from ipr_shapes.voxel_kernels import scanline_fixed, scanline_keys, scanline_setup

    # Faces within [0, V): the set-up in one compiled pass (``voxel_kernels.scanline_setup``);
    # numpy's indexing otherwise (negative indices wrap, others raise).
    compiled = bool(faces.min() >= 0 and faces.max() < len(vertices))
    if compiled:
        grid, z_corner, span, reach, extent = scanline_setup(vertices, faces, float(pitch_m))
    else:
        columns = vertices.T.copy()
        extent = float((columns.max(axis=1) - columns.min(axis=1)).max())
    if extent > MAX_MESH_EXTENT_M:
        raise ValueError(
            f"a mesh spans {extent:.4g} m, more than the {MAX_MESH_EXTENT_M:g} m an object may "
            "(are its coordinates in millimetres? meshes are in metres)"
        )
    # Grid units: voxel centre (n + 1/2) p sits at integer coordinate n.
    if not compiled:
        grid = vertices / pitch_m - 0.5
        reach = np.abs(grid).max()
    if reach >= _OFFSET:
        raise ValueError("voxel index out of range: the mesh is too far from the origin")
    # Exact predicates: xy in fixed point (2^-bits grid units) so that edge functions are exact
    # int64 arithmetic; ``bits`` is chosen so that no product can overflow.
    if not compiled:
        corners = grid[faces]  # (F, 3, 3)
        # The triangles' largest xy extent: max and min over the three corners pairwise
        # (exact, like ``max(axis=1)``, without its strided reduction).
        a, b, c = corners[:, 0, :2], corners[:, 1, :2], corners[:, 2, :2]
        span = float((np.maximum(np.maximum(a, b), c) - np.minimum(np.minimum(a, b), c)).max())
        z_corner = corners[:, :, 2]
    span = float(span) + 2.0
    bits = int(min(24, np.floor(np.log2((2.0**31 - 2) / span))))
    if compiled:
        x, y = scanline_fixed(grid, faces, 2.0**bits)
    else:
        fixed = np.round(grid[:, :2] * 2.0**bits).astype(np.int64)[faces]  # (F, 3, 2)
        x, y = fixed[:, :, 0], fixed[:, :, 1]  # (F, 3) each

    # The scanline proper, compiled (``voxel_kernels.scanline_keys``: the same keys as
    # ``_scanline_keys_numpy``, without its per-column temporaries).
    keys, fits = scanline_keys(
        np.ascontiguousarray(x),
        np.ascontiguousarray(y),
        np.ascontiguousarray(z_corner),
        bits,
        _BITS,
    )
    if not fits:
        raise ValueError("voxel index out of range: the mesh is too far from the origin")
    return keys


def _scanline_keys_numpy(
    x: np.ndarray, y: np.ndarray, z_corner: np.ndarray, bits: int
) -> np.ndarray:
    """The scanline of ``scanline_voxels`` after its set-up, in numpy: triangles' corners
    (F, 3) in fixed point (``x``, ``y`` int64, 2^-``bits`` grid units) and grid-unit heights
    ``z_corner`` (F, 3) -> sorted keys. The reference ``voxel_kernels.scanline_keys`` is
    pinned against (tests/test_hypothesis_kernels.py)."""
    i0 = -((-x.min(axis=1)) >> bits)  # ceil(min / 2^bits)
    i1 = x.max(axis=1) >> bits  # floor(max / 2^bits)
    j0 = -((-y.min(axis=1)) >> bits)
    j1 = y.max(axis=1) >> bits
    nx = np.maximum(i1 - i0 + 1, 0)
    ny = np.maximum(j1 - j0 + 1, 0)
    # Triangles with no projected area cannot contain a (displaced) column: skip them early.
    area2 = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (y[:, 1] - y[:, 0]) * (x[:, 2] - x[:, 0])
    candidates = np.where(area2 != 0, nx * ny, 0)
    live = np.flatnonzero(candidates)
    if live.size == 0:
        return EMPTY.copy()
    per = candidates[live]
    total = int(per.sum())
    owner = np.repeat(live, per)
    start = np.repeat(np.cumsum(per) - per, per)
    local = np.arange(total, dtype=np.int64) - start
    col_i = i0[owner] + local // ny[owner]
    col_j = j0[owner] + local % ny[owner]
    px, py = col_i << bits, col_j << bits

    # Edge function of each column against each triangle edge (first -> second), exact in int64:
    # the two triangles of an edge get exactly opposite values. A zero (column on the edge's
    # line) takes the sign the column displaced by (eps, eps^2) would have, which is also
    # antisymmetric in the edge's direction, so a shared edge is never counted twice or missed.
    edge_values = []
    inside = np.ones(total, dtype=bool)
    reference = None
    for first, second in ((0, 1), (1, 2), (2, 0)):
        ax, ay = x[:, first], y[:, first]
        d_x, d_y = x[:, second] - ax, y[:, second] - ay
        tie = np.where(d_y != 0, -np.sign(d_y), np.sign(d_x))
        value = d_x[owner] * (py - ay[owner]) - d_y[owner] * (px - ax[owner])
        sign = np.where(value == 0, tie[owner], np.sign(value))
        edge_values.append(value)  # = cross(second - first, column - first)
        if reference is None:
            reference = sign
            inside &= sign != 0
        else:
            inside &= sign == reference
    hit = np.flatnonzero(inside)
    if hit.size == 0:
        return EMPTY.copy()
    owner, col_i, col_j = owner[hit], col_i[hit], col_j[hit]

    # Height of the crossing: barycentric weights from the exact edge functions (edge 1->2 is
    # corner 0's weight, and so on), so z stays within the triangle's z range.
    w0, w1, w2 = (edge_values[k][hit].astype(np.float64) for k in (1, 2, 0))
    zc = z_corner[owner]
    z = (w0 * zc[:, 0] + w1 * zc[:, 1] + w2 * zc[:, 2]) / (w0 + w1 + w2)

    column = pack(np.stack([col_i, col_j, np.zeros_like(col_i)], axis=1))
    order = np.lexsort((z, column))
    column, z = column[order], z[order]
    first_of_column = np.ones(column.size, dtype=bool)
    first_of_column[1:] = column[1:] != column[:-1]
    group_start = np.flatnonzero(first_of_column)
    rank = np.arange(column.size) - np.repeat(
        group_start, np.diff(np.append(group_start, column.size))
    )
    enter = np.flatnonzero(rank % 2 == 0)
    enter = enter[enter + 1 < column.size]
    enter = enter[column[enter + 1] == column[enter]]  # an unpaired last crossing is dropped
    z0, z1 = z[enter], z[enter + 1]
    k0 = np.ceil(z0).astype(np.int64)
    k1 = np.ceil(z1).astype(np.int64)
    fill = np.maximum(k1 - k0, 0)
    if fill.sum() == 0:
        return EMPTY.copy()
    base = np.repeat(column[enter] + k0, fill)  # k = 0 packed in column; add k0
    offsets = np.arange(int(fill.sum()), dtype=np.int64) - np.repeat(np.cumsum(fill) - fill, fill)
    k_min = int(k0[fill > 0].min())
    k_max = int((k1[fill > 0] - 1).max())
    if k_min < -_OFFSET or k_max >= _OFFSET:
        raise ValueError("voxel index out of range: the mesh is too far from the origin")
    keys = base + offsets
    # Columns ascend and each column's intervals are disjoint and ascending: already sorted.
    return keys
