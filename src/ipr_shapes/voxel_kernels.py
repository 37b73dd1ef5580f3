"""Compiled inner loops (numba) of the voxel occupancy of meshes (``ipr_shapes.voxels``): the
scanline and its set-up (grid coordinates, extents and fixed-point corners in one pass each).

The column-parity scanline voxelises every hypothesis (the unary constraints count its voxels
in seen-free space) and every mesh the metrics score. In numpy each candidate column of each
triangle is a row of a dozen temporaries; the loop here tests a column and moves on. It does the
same integer and floating-point operations in the same order (no fastmath), so it gives the
same keys; ``tests/test_hypothesis_kernels.py`` pins it against the numpy version
(``voxels._scanline_keys_numpy``). Compiled on first use and cached on disk (``cache=True``,
in ``__pycache__`` or ``NUMBA_CACHE_DIR``); ``NUMBA_DISABLE_JIT=1`` runs it as plain Python.
Its own module, below ``ipr_shapes.voxels`` and ``ipr_shapes.geometry`` (which may not import
each other), and imported only when a mesh is voxelised: numba is slow to import.
"""

from __future__ import annotations

import numba
import numpy as np

# No fastmath: the same IEEE arithmetic as numpy.
_jit = numba.njit(cache=True, nogil=True)


@_jit
def _sign(value):
    return (value > 0) - (value < 0)


@_jit
def scanline_keys(x: np.ndarray, y: np.ndarray, z_corner: np.ndarray, bits: int, key_bits: int):
    """The column-parity scanline of ``ipr_shapes.voxels.scanline_voxels`` (its comments
    document the method) after its set-up: triangles' corners (F, 3) in fixed point (``x``,
    ``y`` int64, 2^-``bits`` grid units) and grid-unit heights ``z_corner`` (F, 3) float64.
    Returns the sorted keys (N,) int64 (``voxels.pack``: ``key_bits`` per axis, indices
    shifted by offset = 2^(key_bits - 1)) and whether every k index fits in [-offset,
    offset) (else the keys are not valid). The same integer edge functions, the same float operations in the same order
    for the crossing heights, and the same pairing of each column's crossings sorted by
    height, so the same keys as the numpy version, without its per-column temporaries."""
    faces = x.shape[0]
    offset = np.int64(1) << (key_bits - 1)
    # Pass 1: the crossings (column i, j, height z) in the numpy version's order.
    capacity = 64
    col_i = np.empty(capacity, dtype=np.int64)
    col_j = np.empty(capacity, dtype=np.int64)
    heights = np.empty(capacity, dtype=np.float64)
    count = 0
    unit = np.int64(1) << bits
    for f in range(faces):
        x0, x1, x2 = x[f, 0], x[f, 1], x[f, 2]
        y0, y1, y2 = y[f, 0], y[f, 1], y[f, 2]
        area2 = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
        if area2 == 0:
            continue
        i0 = -((-min(x0, x1, x2)) >> bits)
        i1 = max(x0, x1, x2) >> bits
        j0 = -((-min(y0, y1, y2)) >> bits)
        j1 = max(y0, y1, y2) >> bits
        if i1 < i0 or j1 < j0:
            continue
        # Edges (0, 1), (1, 2), (2, 0): start, direction and tie sign.
        ax = (x0, x1, x2)
        ay = (y0, y1, y2)
        dx = (x1 - x0, x2 - x1, x0 - x2)
        dy = (y1 - y0, y2 - y1, y0 - y2)
        tie0 = -_sign(dy[0]) if dy[0] != 0 else _sign(dx[0])
        tie1 = -_sign(dy[1]) if dy[1] != 0 else _sign(dx[1])
        tie2 = -_sign(dy[2]) if dy[2] != 0 else _sign(dx[2])
        for ci in range(i0, i1 + 1):
            px = ci * unit
            for cj in range(j0, j1 + 1):
                py = cj * unit
                v0 = dx[0] * (py - ay[0]) - dy[0] * (px - ax[0])
                s0 = tie0 if v0 == 0 else _sign(v0)
                if s0 == 0:
                    continue
                v1 = dx[1] * (py - ay[1]) - dy[1] * (px - ax[1])
                s1 = tie1 if v1 == 0 else _sign(v1)
                if s1 != s0:
                    continue
                v2 = dx[2] * (py - ay[2]) - dy[2] * (px - ax[2])
                s2 = tie2 if v2 == 0 else _sign(v2)
                if s2 != s0:
                    continue
                # Barycentric weights: edge 1->2 is corner 0's, 2->0 corner 1's, 0->1 corner 2's.
                w0, w1, w2 = np.float64(v1), np.float64(v2), np.float64(v0)
                z = (w0 * z_corner[f, 0] + w1 * z_corner[f, 1] + w2 * z_corner[f, 2]) / (
                    w0 + w1 + w2
                )
                if count == capacity:
                    capacity *= 2
                    col_i = np.concatenate((col_i, np.empty(capacity - count, dtype=np.int64)))
                    col_j = np.concatenate((col_j, np.empty(capacity - count, dtype=np.int64)))
                    heights = np.concatenate(
                        (heights, np.empty(capacity - count, dtype=np.float64))
                    )
                col_i[count] = ci
                col_j[count] = cj
                heights[count] = z
                count += 1
    keys = np.empty(0, dtype=np.int64)
    if count == 0:
        return keys, True
    col_i, col_j, heights = col_i[:count], col_j[:count], heights[:count]
    # Pass 2: sort by (column, height); ties in height give the same pairs in any order.
    order = np.argsort(heights, kind="mergesort")
    column = ((col_i + offset) << (2 * key_bits)) | ((col_j + offset) << key_bits)
    order = order[np.argsort(column[order], kind="mergesort")]
    column = column[order]
    heights = heights[order]
    # Pass 3: pair each column's crossings (first with second, third with fourth, ...).
    total = 0
    k_min = np.int64(np.iinfo(np.int64).max)
    k_max = np.int64(np.iinfo(np.int64).min)
    starts = np.empty(count, dtype=np.int64)
    fills = np.empty(count, dtype=np.int64)
    pairs = 0
    rank = 0
    for n in range(count):
        if n > 0 and column[n] != column[n - 1]:
            rank = 0
        if rank % 2 == 0 and n + 1 < count and column[n + 1] == column[n]:
            k0 = np.int64(np.ceil(heights[n]))
            k1 = np.int64(np.ceil(heights[n + 1]))
            fill = max(k1 - k0, 0)
            if fill > 0:
                starts[pairs] = column[n] + offset + k0
                fills[pairs] = fill
                pairs += 1
                total += fill
                k_min = min(k_min, k0)
                k_max = max(k_max, k1 - 1)
        rank += 1
    if total == 0:
        return keys, True
    keys = np.empty(total, dtype=np.int64)
    at = 0
    for p in range(pairs):
        for k in range(fills[p]):
            keys[at] = starts[p] + k
            at += 1
    return keys, k_min >= -offset and k_max < offset


@_jit
def scanline_setup(vertices: np.ndarray, faces: np.ndarray, pitch_m: float):
    """The set-up of ``ipr_shapes.voxels.scanline_voxels`` before its fixed-point scale, in one
    pass: grid coordinates ``vertices / pitch_m - 0.5`` (V, 3), the corners' z (F, 3), the
    triangles' largest xy extent in grid units, the largest |grid coordinate| and the mesh's
    largest extent (m). Finite vertices and faces within [0, V) only (the caller checks).
    The same divisions and subtractions as numpy's, and max and min are exact in any order."""
    count = vertices.shape[0]
    grid = np.empty((count, 3))
    reach = 0.0
    extent = 0.0
    for axis in range(3):
        low = vertices[0, axis]
        high = vertices[0, axis]
        for v in range(count):
            value = vertices[v, axis]
            low = min(low, value)
            high = max(high, value)
            g = value / pitch_m - 0.5
            grid[v, axis] = g
            reach = max(reach, abs(g))
        extent = max(extent, high - low)
    z_corner = np.empty((faces.shape[0], 3))
    span = 0.0
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        z_corner[f, 0] = grid[a, 2]
        z_corner[f, 1] = grid[b, 2]
        z_corner[f, 2] = grid[c, 2]
        for axis in range(2):
            high = max(max(grid[a, axis], grid[b, axis]), grid[c, axis])
            low = min(min(grid[a, axis], grid[b, axis]), grid[c, axis])
            span = max(span, high - low)
    return grid, z_corner, span, reach, extent


@_jit
def scanline_fixed(grid: np.ndarray, faces: np.ndarray, scale: float):
    """The corners' fixed-point xy (F, 3) int64 each: ``np.round(grid[:, :2] * scale)`` (round
    half to even, numpy's ``rint`` for zero decimals) cast to int64, gathered by ``faces``."""
    x = np.empty((faces.shape[0], 3), dtype=np.int64)
    y = np.empty((faces.shape[0], 3), dtype=np.int64)
    for f in range(faces.shape[0]):
        for c in range(3):
            v = faces[f, c]
            x[f, c] = np.int64(np.rint(grid[v, 0] * scale))
            y[f, c] = np.int64(np.rint(grid[v, 1] * scale))
    return x, y
