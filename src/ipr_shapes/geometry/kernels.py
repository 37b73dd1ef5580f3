"""Compiled inner loops (numba) of the geometry every stage shares: world points and planes.

The world points of a frame (``Frame.points_world``, used by the scene loader's callers and by
every stage after it) and the scoring, inlier search and moments of the RANSAC plane fit
(``ipr_shapes.geometry.planes.fit_plane_ransac``), and a convex hull's thickness
(``hull_width``, ``ShapeHypothesis.width_m``). The small helpers ``_rotated`` (the FMA order of
numpy's ``points @ R.T + t``), ``_dot`` and ``_columns`` are also called by the perception
kernels (``ipr_shapes.perception.kernels``), so that a plane distance or a world point is one
expression everywhere.

Why compiled: on the 2-core cloud machines ipr is measured on, numpy's per-pixel arithmetic is
bound by memory traffic: each operator of an expression makes a full-size temporary, and a
640x480 frame's (H, W, 3) float64 points are 7 MB. A loop compiled by numba does the same
arithmetic in one pass with no temporaries (docs/DESIGN_NOTES.md, "Compiled kernels"). Each
kernel here states the numpy expression it replaces; ``tests/test_geometry_kernels.py`` pins
every one against that expression.

Kernels are compiled on first use and cached on disk (``cache=True``, in ``__pycache__`` or
``NUMBA_CACHE_DIR``). numba checks a cached kernel against its own source file only: after
editing a helper here, clear the cache of ``ipr_shapes/perception/kernels.py`` too (its kernels have
the helpers compiled in). ``NUMBA_DISABLE_JIT=1`` runs them as plain Python, for debugging.
This module imports numba, which is slow to import: modules that must start fast
(``ipr_shapes.scene``, ``ipr_shapes.geometry.planes``) import it inside the functions that need it.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

# nogil: callers may run perception in threads; no fastmath: the same IEEE arithmetic as numpy.
_jit = numba.njit(cache=True, nogil=True)


@intrinsic
def _fused_multiply_add(typing_context, a, b, c):
    """a * b + c rounded once (LLVM's fma; Python 3.11 has no math.fma)."""
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, arguments):
        double = ir.DoubleType()
        function = builder.module.declare_intrinsic(
            "llvm.fma", [double], ir.FunctionType(double, [double, double, double])
        )
        return builder.call(function, arguments)

    return signature, codegen


@_jit
def _rotated(x: float, y: float, z: float, transform: np.ndarray, axis: int) -> float:
    """Coordinate ``axis`` of transform[:3, :3] @ (x, y, z) + transform[:3, 3], with the products
    accumulated by fused multiply-adds in x, y, z order as OpenBLAS's double-precision kernels
    accumulate them on x86-64 CPUs with FMA: the same bits as numpy's ``points @ R.T + t``
    there (a plain sum differs in the last bit, which can flip a borderline segment), equal to
    rounding elsewhere."""
    accumulated = x * transform[axis, 0]
    accumulated = _fused_multiply_add(y, transform[axis, 1], accumulated)
    accumulated = _fused_multiply_add(z, transform[axis, 2], accumulated)
    return accumulated + transform[axis, 3]


@_jit
def _dot(rows: np.ndarray, index: int, vector: np.ndarray) -> float:
    """rows[index] . vector for (N, 3) rows and a (3,) vector, summed in x, y, z order (the
    plane distances and facing tests of the kernels here and in ``ipr_shapes.perception.kernels``
    all take this one product)."""
    return rows[index, 0] * vector[0] + rows[index, 1] * vector[1] + rows[index, 2] * vector[2]


@_jit
def world_points(depth_m: np.ndarray, K: np.ndarray, world_from_camera: np.ndarray) -> np.ndarray:
    """(H, W, 3) float64 world points (m) of every pixel of a (H, W) depth image (m) with
    intrinsics K (3, 3) and a 4x4 world-from-camera transform; meaningless where depth is 0.

    ``backproject(depth_m, K) @ R.T + t`` in one pass (``_rotated``: the same bits)."""
    height, width = depth_m.shape
    out = np.empty((height, width, 3))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    for row in range(height):
        for col in range(width):
            z = np.float64(depth_m[row, col])
            x = (col - cx) / fx * z
            y = (row - cy) / fy * z
            for axis in range(3):
                out[row, col, axis] = _rotated(x, y, z, world_from_camera, axis)
    return out


@_jit
def plane_inlier_counts(
    points: np.ndarray, normals: np.ndarray, offsets: np.ndarray, threshold_m: float
) -> np.ndarray:
    """(H,) int64 count of the (N, 3) points within ``threshold_m`` of each of H planes
    {x : normals[h] . x + offsets[h] = 0} (unit (H, 3) normals): RANSAC's scores,
    ``(np.abs(points @ normals.T + offsets) < threshold_m).sum(axis=0)`` without the (N, H)
    arrays."""
    xs, ys, zs = _columns(points)
    counts = np.zeros(normals.shape[0], dtype=np.int64)
    for h in range(normals.shape[0]):
        n0, n1, n2, offset = normals[h, 0], normals[h, 1], normals[h, 2], offsets[h]
        count = 0
        for p in range(xs.shape[0]):  # branch-free: the compiler vectorises it
            count += abs(xs[p] * n0 + ys[p] * n1 + zs[p] * n2 + offset) < threshold_m
        counts[h] = count
    return counts


@_jit
def _columns(points: np.ndarray):
    """The three columns of (N, 3) ``points`` as contiguous (N,) float64 arrays."""
    count = points.shape[0]
    xs, ys, zs = np.empty(count), np.empty(count), np.empty(count)
    for p in range(count):
        xs[p], ys[p], zs[p] = points[p, 0], points[p, 1], points[p, 2]
    return xs, ys, zs


@_jit
def plane_inliers(
    points: np.ndarray, normal: np.ndarray, offset: float, threshold_m: float
) -> np.ndarray:
    """(K,) int64 indices of the (N, 3) points within ``threshold_m`` of the plane
    {x : normal . x + offset = 0}, ascending: ``np.flatnonzero(np.abs(points @ normal +
    offset) < threshold_m)`` in one pass."""
    found = np.empty(points.shape[0], dtype=np.int64)
    count = 0
    for p in range(points.shape[0]):
        if abs(_dot(points, p, normal) + offset) < threshold_m:
            found[count] = p
            count += 1
    return found[:count].copy()


@_jit
def centred_scatter(points: np.ndarray, indices: np.ndarray):
    """Centroid (3,) and scatter matrix (3, 3) (sum of outer products of the centred points)
    of the (N, 3) points at ``indices`` (K,): a plane fit's moments, without gathering them."""
    centroid = np.zeros(3)
    for k in range(indices.shape[0]):
        for axis in range(3):
            centroid[axis] += points[indices[k], axis]
    centroid /= max(indices.shape[0], 1)
    scatter = np.zeros((3, 3))
    for k in range(indices.shape[0]):
        d0 = points[indices[k], 0] - centroid[0]
        d1 = points[indices[k], 1] - centroid[1]
        d2 = points[indices[k], 2] - centroid[2]
        scatter[0, 0] += d0 * d0
        scatter[0, 1] += d0 * d1
        scatter[0, 2] += d0 * d2
        scatter[1, 1] += d1 * d1
        scatter[1, 2] += d1 * d2
        scatter[2, 2] += d2 * d2
    scatter[1, 0], scatter[2, 0], scatter[2, 1] = scatter[0, 1], scatter[0, 2], scatter[1, 2]
    return centroid, scatter


@_jit
def inside_lines(equations: np.ndarray, height: int, width: int) -> np.ndarray:
    """(height, width) bool: the pixels (column x, row y) with ``a * x + b * y + c <= 0.5``
    for every row (a, b, c, ...) of ``equations`` (a convex hull's edges in image coordinates):
    numpy's ``inside &= a * xx + b * yy + c <= 0.5`` over ``np.mgrid`` for each edge, with the
    same arithmetic, in one pass that stops at a pixel's first failed edge."""
    inside = np.zeros((height, width), dtype=np.bool_)
    for y in range(height):
        for x in range(width):
            keep = True
            for e in range(equations.shape[0]):
                if not (equations[e, 0] * x + equations[e, 1] * y + equations[e, 2] <= 0.5):
                    keep = False
                    break
            inside[y, x] = keep
    return inside


@_jit
def positions_in_sorted(values: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(K,) int64 positions in ``values`` (N,) of the ``targets`` (M,) found there, both
    ascending and without repeats: ``position = np.searchsorted(values, targets)``, kept where
    ``values[position] == targets``, by one merge of the two lists instead of a binary search
    per target."""
    found = np.empty(min(values.shape[0], targets.shape[0]), dtype=np.int64)
    count = 0
    j = 0
    for t in range(targets.shape[0]):
        target = targets[t]
        while j < values.shape[0] and values[j] < target:
            j += 1
        if j == values.shape[0]:
            break
        if values[j] == target:
            found[count] = j
            count += 1
    return found[:count].copy()


@_jit
def large_pieces(mask: np.ndarray, share: float) -> np.ndarray:
    """(h, w) bool: the pixels of ``mask`` in the large 8-connected pieces of ``mask |
    binary_closing(mask)`` (3 x 3 structure, scipy's border value 0), those holding at least
    ``share`` of the largest piece's ``mask`` pixels: ``support._largest_piece``'s
    ``ndimage.binary_closing``, ``ndimage.label``, ``np.bincount`` and ``np.isin`` in a few
    passes (a piece's number does not matter, only which pixels are kept)."""
    height, width = mask.shape
    dilated = np.zeros((height, width), dtype=np.bool_)
    for y in range(height):
        for x in range(width):
            if mask[y, x]:
                for dy in range(max(y - 1, 0), min(y + 2, height)):
                    for dx in range(max(x - 1, 0), min(x + 2, width)):
                        dilated[dy, dx] = True
    closed = mask.copy()
    for y in range(1, height - 1):  # the erosion's border value 0: border pixels erode
        for x in range(1, width - 1):
            if closed[y, x]:
                continue
            full = True
            for dy in range(y - 1, y + 2):
                for dx in range(x - 1, x + 2):
                    if not dilated[dy, dx]:
                        full = False
            closed[y, x] = full
    piece = np.full((height, width), -1, dtype=np.int64)
    sizes = np.zeros(height * width + 1, dtype=np.int64)
    stack = np.empty(height * width, dtype=np.int64)
    count = 0
    for y in range(height):
        for x in range(width):
            if not closed[y, x] or piece[y, x] >= 0:
                continue
            piece[y, x] = count
            top = 0
            stack[top] = y * width + x
            top += 1
            while top > 0:
                top -= 1
                cy, cx = stack[top] // width, stack[top] % width
                sizes[count] += mask[cy, cx]
                for dy in range(max(cy - 1, 0), min(cy + 2, height)):
                    for dx in range(max(cx - 1, 0), min(cx + 2, width)):
                        if closed[dy, dx] and piece[dy, dx] < 0:
                            piece[dy, dx] = count
                            stack[top] = dy * width + dx
                            top += 1
            count += 1
    largest = 0
    for number in range(count):
        largest = max(largest, sizes[number])
    kept = np.zeros((height, width), dtype=np.bool_)
    for y in range(height):
        for x in range(width):
            if mask[y, x] and sizes[piece[y, x]] >= share * largest:
                kept[y, x] = True
    return kept


@_jit
def oriented_hull_mesh(points: np.ndarray, simplices: np.ndarray, equations: np.ndarray):
    """A qhull hull's triangles as a compact, outward mesh (``convex._oriented_mesh``):
    vertices (V, 3) (the used ``points`` (N, 3), in their order), faces (F, 3) int64 into
    them, each simplex (F, 3) reversed when its corners' cross product (b - a) x (c - a)
    points against its facet's outward normal ``equations[:, :3]`` (F, 4); and whether every
    such sign is certain. The numpy it replaces::

        flip = np.einsum("ij,ij->i", triangle_cross(points[simplices]), equations[:, :3]) < 0
        simplices[flip] = simplices[flip][:, [0, 2, 1]]
        used = np.zeros(len(points), dtype=bool); used[simplices] = True
        faces = (np.cumsum(used) - 1)[simplices].astype(np.int64); vertices = points[used]

    The products here are summed in this loop's order, einsum's possibly in another: a dot
    product within 1e-12 of the sum of its terms' magnitudes of zero could take the other
    sign there, so it returns False and the caller runs numpy's version."""
    count = simplices.shape[0]
    faces = np.empty((count, 3), dtype=np.int64)
    used = np.zeros(points.shape[0], dtype=np.bool_)
    for f in range(count):
        i, j, k = simplices[f, 0], simplices[f, 1], simplices[f, 2]
        u0 = points[j, 0] - points[i, 0]
        u1 = points[j, 1] - points[i, 1]
        u2 = points[j, 2] - points[i, 2]
        v0 = points[k, 0] - points[i, 0]
        v1 = points[k, 1] - points[i, 1]
        v2 = points[k, 2] - points[i, 2]
        p0 = (u1 * v2 - u2 * v1) * equations[f, 0]
        p1 = (u2 * v0 - u0 * v2) * equations[f, 1]
        p2 = (u0 * v1 - u1 * v0) * equations[f, 2]
        dot = p0 + p1 + p2
        if not abs(dot) > 1e-12 * (abs(p0) + abs(p1) + abs(p2)):
            return np.empty((0, 3)), faces, False
        faces[f, 0] = i
        if dot < 0.0:
            faces[f, 1], faces[f, 2] = k, j
        else:
            faces[f, 1], faces[f, 2] = j, k
        used[i] = used[j] = used[k] = True
    number = np.empty(points.shape[0], dtype=np.int64)
    kept = 0
    for n in range(points.shape[0]):
        number[n] = kept
        kept += used[n]
    vertices = np.empty((kept, 3))
    for n in range(points.shape[0]):
        if used[n]:
            vertices[number[n], 0] = points[n, 0]
            vertices[number[n], 1] = points[n, 1]
            vertices[number[n], 2] = points[n, 2]
    for f in range(count):
        for c in range(3):
            faces[f, c] = number[faces[f, c]]
    return vertices, faces, True


@_jit
def hull_width(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Thickness (m) of a closed convex hull, (V, 3) ``vertices`` and (F, 3) outward
    ``faces``: the least over its faces of the distance from the face's plane to the farthest
    vertex behind it (``ShapeHypothesis.width_m``; 0 without a face of non-zero area). A face
    stops being scanned once its distance reaches the least so far. The numpy expression it
    replaces (the same to rounding: the cross products' order differs)::

        planes = h.face_planes()
        width = -(h.vertices @ planes[:, :3].T + planes[:, 3]).min(axis=0).max()
    """
    best = np.inf
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        u0 = vertices[b, 0] - vertices[a, 0]
        u1 = vertices[b, 1] - vertices[a, 1]
        u2 = vertices[b, 2] - vertices[a, 2]
        v0 = vertices[c, 0] - vertices[a, 0]
        v1 = vertices[c, 1] - vertices[a, 1]
        v2 = vertices[c, 2] - vertices[a, 2]
        n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
        length = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if length <= 1e-15:
            continue
        n0, n1, n2 = n0 / length, n1 / length, n2 / length
        far = 0.0
        for k in range(vertices.shape[0]):
            behind = (
                n0 * (vertices[a, 0] - vertices[k, 0])
                + n1 * (vertices[a, 1] - vertices[k, 1])
                + n2 * (vertices[a, 2] - vertices[k, 2])
            )
            if behind > far:
                far = behind
                if far >= best:
                    break
        if far < best:
            best = far
    return best if best < np.inf else 0.0
