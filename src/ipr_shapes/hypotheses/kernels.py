"""Compiled inner loops (numba) of hypothesis generation.

Algorithm 1 casts a few thousand rays per object through the frame's free-space map
(``generate._ray_limits``); in numpy each ray's every sample is placed, indexed and looked up
even though the ray ends at its first free voxel, a few samples in. The loop here stops there.
It does the same IEEE arithmetic as the numpy expression it replaces, operation by operation
(no fastmath), so the results are the same bits; ``tests/test_hypothesis_kernels.py`` pins it
against that expression. Compiled on first use and cached on disk, as
``ipr_shapes.perception.kernels`` (its module doc has the details; ``NUMBA_DISABLE_JIT=1``
runs the loop as plain Python).

The superquadric fit's residuals (``superquadric_residuals``) are the one exception to same
bits by design: it returns their exact Jacobian with them, where the numpy fit took forward
differences (nine residual evaluations per Jacobian); ``tests/test_superquadric.py`` pins the
residuals to the numpy expression and the Jacobian to central differences.
"""

from __future__ import annotations

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)


@_jit
def first_state_samples(
    origins: np.ndarray,
    direction: np.ndarray,
    t: np.ndarray,
    grid_origin: np.ndarray,
    voxel_m: float,
    state: np.ndarray,
    value: int,
) -> np.ndarray:
    """Per ray, the index (R,) int64 of its first sample whose voxel holds ``value``, or
    ``len(t)`` when none does. Ray r's sample s is ``origins[r] + t[s] * direction`` (world,
    m); its voxel ``floor((sample - grid_origin) / voxel_m)`` in the (nx, ny, nz) ``state``
    grid (outside the grid: no value). The numpy expression it replaces::

        samples = (origins[:, None, :] + t[None, :, None] * direction).reshape(-1, 3)
        hits = (space.state_at(samples) == value).reshape(len(origins), len(t))
        first = np.where(hits.any(axis=1), np.argmax(hits, axis=1), len(t))
    """
    nx, ny, nz = state.shape
    count, samples = origins.shape[0], t.shape[0]
    first = np.full(count, samples, dtype=np.int64)
    for r in range(count):
        for s in range(samples):
            i = np.int64(np.floor((origins[r, 0] + t[s] * direction[0] - grid_origin[0]) / voxel_m))
            if i < 0 or i >= nx:
                continue
            j = np.int64(np.floor((origins[r, 1] + t[s] * direction[1] - grid_origin[1]) / voxel_m))
            if j < 0 or j >= ny:
                continue
            k = np.int64(np.floor((origins[r, 2] + t[s] * direction[2] - grid_origin[2]) / voxel_m))
            if k < 0 or k >= nz:
                continue
            if state[i, j, k] == value:
                first[r] = s
                break
    return first


@_jit
def hull_parts(label: np.ndarray, neighbours: np.ndarray, areas: np.ndarray, normals: np.ndarray):
    """The connected parts of a hull's labelled triangles and their sums: triangles (T,) with
    ``label`` (T,) int64 join their ``neighbours`` (T, 3) (qhull's, across each edge) of the
    same label. Returns the part of each triangle (T,) int64, numbered by their smallest
    triangle (0, 1, ...), each part's area (P,) (the sum of ``areas`` (T,) m^2) and
    area-weighted normal (P, 3) (the sum of ``areas * normals[:, k]``), summed in triangle
    order like ``np.bincount`` (the same bits). The numpy it replaces
    (``generate._hull_groups``)::

        same = label[rows] == label[cols]   # rows, cols: every (triangle, neighbour) pair
        part = components(rows[same], cols[same], count)   # numbered by smallest member
        part_area = np.bincount(part, weights=areas, minlength=parts)
        part_normal[:, k] = np.bincount(part, weights=areas * normals[:, k], minlength=parts)
    """
    count = label.shape[0]
    part = np.full(count, -1, dtype=np.int64)
    stack = np.empty(count, dtype=np.int64)
    parts = 0
    for start in range(count):
        if part[start] >= 0:
            continue
        part[start] = parts
        top = 0
        stack[top] = start
        top += 1
        while top > 0:
            top -= 1
            node = stack[top]
            for e in range(neighbours.shape[1]):
                other = neighbours[node, e]
                if part[other] < 0 and label[other] == label[node]:
                    part[other] = parts
                    stack[top] = other
                    top += 1
        parts += 1
    part_area = np.zeros(parts)
    part_normal = np.zeros((parts, 3))
    for t in range(count):
        p = part[t]
        part_area[p] += areas[t]
        for k in range(3):
            part_normal[p, k] += areas[t] * normals[t, k]
    return part, part_area, part_normal


@_jit
def greedy_labels(
    areas: np.ndarray, normals: np.ndarray, cos_group: float, min_area_m2: float, band: float
):
    """The greedy grouping of a hull's triangles (``generate._hull_groups``): while the
    unassigned triangles' areas (T,) m^2 sum to at least ``min_area_m2``, the largest (the
    first of equals) claims every unassigned triangle whose unit normal (T, 3) is within
    ``cos_group`` of its own (label 0, 1, ...); the rest get labels of their own. Returns the
    labels (T,) int64 and whether they are certain: the products and sums here differ from
    numpy's (BLAS's, pairwise) in their last bits, so when any product lies within ``band``
    of ``cos_group``, or the area sum within ``band`` (relative) of ``min_area_m2``, it stops
    and returns False, and the caller runs numpy's loop. Otherwise every comparison has
    numpy's outcome (the two differ by ~1e-15 at most), and so do the labels."""
    count = areas.shape[0]
    label = np.full(count, -1, dtype=np.int64)
    for t in range(count):
        if not np.isfinite(areas[t]):
            return label, False
    unassigned = np.arange(count)
    size = count
    number = 0
    while size > 0:
        total = 0.0
        for i in range(size):
            total += areas[unassigned[i]]
        if abs(total - min_area_m2) <= band * max(abs(total), abs(min_area_m2)):
            return label, False
        if not total >= min_area_m2:
            break
        best = 0
        for i in range(1, size):
            if areas[unassigned[i]] > areas[unassigned[best]]:
                best = i
        seed = unassigned[best]
        kept = 0
        for i in range(size):
            t = unassigned[i]
            product = (
                normals[t, 0] * normals[seed, 0]
                + normals[t, 1] * normals[seed, 1]
                + normals[t, 2] * normals[seed, 2]
            )
            if not abs(product - cos_group) > band:
                return label, False
            if product >= cos_group:
                label[t] = number
            else:
                unassigned[kept] = t
                kept += 1
        size = kept
        number += 1
    for i in range(size):
        label[unassigned[i]] = number + i
    return label, True


@_jit
def first_wall_samples(
    origins: np.ndarray,
    direction: np.ndarray,
    t: np.ndarray,
    limit: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    thickness: np.ndarray,
    axes: np.ndarray,
    outlines: np.ndarray,
    outline_start: np.ndarray,
    band: float,
):
    """Per ray, the index (R,) int64 of its first sample before ``limit`` (R,) that is inside a
    wall's slab (``PlaneRegion.in_wall``, no margin), else ``limit``; samples as in
    ``first_state_samples``. Walls: unit ``normals`` (W, 3), ``offsets`` (W,), slab
    ``thickness`` (W,) m, in-plane ``axes`` (W, 2, 3) and outline half-planes (a, b, c) of wall
    w in rows ``outline_start[w]:outline_start[w + 1]`` of ``outlines`` (none: unbounded).
    Also returns whether the answer is certain: numpy computes the distances with BLAS, whose
    last bits differ from this loop's, so a distance or outline value within ``band`` (m) of
    its threshold stops the loop (False) and the caller takes numpy's path."""
    count, samples, walls = origins.shape[0], t.shape[0], normals.shape[0]
    first = limit.copy()
    for r in range(count):
        for s in range(min(limit[r], samples)):
            x = origins[r, 0] + t[s] * direction[0]
            y = origins[r, 1] + t[s] * direction[1]
            z = origins[r, 2] + t[s] * direction[2]
            hit = False
            for w in range(walls):
                distance = x * normals[w, 0] + y * normals[w, 1] + z * normals[w, 2] + offsets[w]
                if abs(distance) <= band or abs(distance + thickness[w]) <= band:
                    return first, False
                if not (distance < 0.0 and distance > -thickness[w]):
                    continue
                u = x * axes[w, 0, 0] + y * axes[w, 0, 1] + z * axes[w, 0, 2]
                v = x * axes[w, 1, 0] + y * axes[w, 1, 1] + z * axes[w, 1, 2]
                inside = True
                for e in range(outline_start[w], outline_start[w + 1]):
                    value = u * outlines[e, 0] + v * outlines[e, 1] + outlines[e, 2]
                    if abs(value) <= band:
                        return first, False
                    if value > 0.0:
                        inside = False
                if inside:
                    hit = True
                    break
            if hit:
                first[r] = s
                break
    return first, True


@_jit
def outside_shares(centres: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Per candidate d in ``centres`` (C,) m, the share (C,) of rays r whose admissible range
    [``low[r]``, ``high[r]``] (R,) m it lies outside (``generate._admissible``). The numpy
    expression it replaces (a bool mean is its count of True, exact in float64, over R)::

        outside = (centres[:, None] < low[None, :]) | (centres[:, None] > high[None, :])
        shares = outside.mean(axis=1)
    """
    count = low.shape[0]
    shares = np.empty(centres.shape[0])
    for c in range(centres.shape[0]):
        centre = centres[c]
        outside = 0
        for r in range(count):
            if centre < low[r] or centre > high[r]:
                outside += 1
        shares[c] = outside / count
    return shares


@_jit
def _logaddexp(a: float, b: float) -> float:
    """log(exp(a) + exp(b)) without overflow (numpy's ``logaddexp`` to the last bits)."""
    top = max(a, b)
    return top + np.log1p(np.exp(-abs(a - b)))


@_jit
def superquadric_residuals(local: np.ndarray, free: np.ndarray, x: np.ndarray, weight: float):
    """The superquadric fit's residuals and their exact Jacobian in one pass
    (``superquadric.fit``): parameters ``x`` (8,) = lo (3,), hi (3,) (local extents, m), e1,
    e2; observed points ``local`` (N, 3) and seen-free voxel centres ``free`` (F, 3), local
    frame, m. Returns the residuals (N + F,) (the points' signed radial distance, m, then
    ``weight`` times how deep each free voxel lies inside, 0 outside) and d residual / d x
    (N + F, 8). The numpy residuals it replaces (``superquadric._radial``, whose finite
    differences the Jacobian replaced: one pass instead of nine)::

        r = np.concatenate([_radial(local, lo, hi, e1, e2),
                            weight * np.maximum(-_radial(free, lo, hi, e1, e2), 0.0)])

    The derivatives, with L_i = log(|q_i| / s_i + 1e-12), q = p - centre, s the semi-axes,
    A, B = 2 L_x / e2, 2 L_y / e2, M = logaddexp(A, B), xy = M e2 / e1, C = 2 L_z / e1,
    log F = logaddexp(xy, C), g = -e1 log F / 2 and r = |q| (1 - exp(g)): with a = exp(xy -
    log F) and b = exp(A - M), dg/dL = -(a b, a (1 - b), 1 - a), dg/de1 = (a xy + (1 - a) C -
    log F) / 2, dg/de2 = -a (M - b A - (1 - b) B) / 2 (0 where g is clipped to +-50); the
    semi-axis floor of 1e-6 m has derivative 0, like the kink of the free term at 0."""
    n, f = local.shape[0], free.shape[0]
    res = np.empty(n + f)
    jac = np.zeros((n + f, 8))
    e1, e2 = x[6], x[7]
    centre = np.empty(3)
    semi = np.empty(3)
    floored = np.zeros(3, dtype=np.bool_)
    for i in range(3):
        centre[i] = 0.5 * (x[i] + x[3 + i])
        semi[i] = 0.5 * (x[3 + i] - x[i])
        if semi[i] < 1e-6:
            semi[i] = 1e-6
            floored[i] = True
    q = np.empty(3)
    dl = np.empty(3)  # d L_i / d q_i
    dls = np.empty(3)  # d L_i / d s_i
    dg = np.empty(3)
    for k in range(n + f):
        inside = k >= n
        for i in range(3):
            q[i] = (free[k - n, i] if inside else local[k, i]) - centre[i]
        logs0 = 0.0
        logs = np.empty(3)
        for i in range(3):
            u = abs(q[i]) / semi[i]
            logs[i] = np.log(u + 1e-12)
            dl[i] = np.sign(q[i]) / (semi[i] * (u + 1e-12))
            dls[i] = -(u / semi[i]) / (u + 1e-12)
        logs0 = logs[0]
        a_ = 2.0 / e2 * logs0
        b_ = 2.0 / e2 * logs[1]
        m = _logaddexp(a_, b_)
        xy = m * (e2 / e1)
        c = 2.0 / e1 * logs[2]
        log_f = _logaddexp(xy, c)
        g = -0.5 * e1 * log_f
        clipped = g < -50.0 or g > 50.0
        g = min(max(g, -50.0), 50.0)
        scale = np.exp(g)
        norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
        r = norm * (1.0 - scale)
        sign = 1.0
        if inside:
            if r < 0.0:
                res[k] = weight * -r
                sign = -weight
            else:
                res[k] = 0.0
                continue
        else:
            res[k] = r
        wa = np.exp(xy - log_f)
        wb = np.exp(a_ - m)
        if clipped:
            dg[0] = dg[1] = dg[2] = 0.0
            dg1 = dg2 = 0.0
        else:
            dg[0] = -wa * wb
            dg[1] = -wa * (1.0 - wb)
            dg[2] = -(1.0 - wa)
            dg1 = 0.5 * (wa * xy + (1.0 - wa) * c - log_f)
            dg2 = -0.5 * wa * (m - wb * a_ - (1.0 - wb) * b_)
        for i in range(3):
            # d r / d q_i and d r / d s_i; q_i = p_i - (lo_i + hi_i) / 2, s_i = (hi_i - lo_i) / 2.
            dq = (q[i] / norm if norm > 0.0 else 0.0) * (1.0 - scale) - norm * scale * dg[i] * dl[i]
            ds = 0.0 if floored[i] else -norm * scale * dg[i] * dls[i]
            jac[k, i] = sign * (-0.5 * dq - 0.5 * ds)
            jac[k, 3 + i] = sign * (-0.5 * dq + 0.5 * ds)
        jac[k, 6] = sign * -norm * scale * dg1
        jac[k, 7] = sign * -norm * scale * dg2
    return res, jac
