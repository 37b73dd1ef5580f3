"""Compiled nearest-neighbour search (numba) of view fusion's ICP (``ipr_shapes.fusion``).

Each registration asks, per start and iteration, for the nearest frame-0 point of 1,500 moved
points within a gate: scipy's ``cKDTree.query`` took ~70 % of fusion's time, about 1 us per
point, most of it its general machinery (any k, any p-norm, a priority queue). The kd-tree
here does only what the ICP asks (k = 1, Euclidean, a distance bound) with a depth-first
descent, in about half the time (docs/experiments/2026-11-27-fusion-exact-speed.md).

It gives ``cKDTree.query(points, distance_upper_bound=bound)``'s answer: the same squared
distance arithmetic in the same order (differences, squares summed over x, y, z from 0, no
fastmath), so the same distance bits (its square root), a neighbour only when the squared
distance is below the squared bound, ``n`` and inf where there is none. Two tree points at
exactly the same distance go to the lower index here (cKDTree: whichever its traversal meets
first); ``tests/test_fusion_kernels.py`` pins it against cKDTree. Compiled on first use and
cached on disk (``cache=True``); ``NUMBA_DISABLE_JIT=1`` runs it as plain Python. Its own
module, imported by ``ipr_shapes.fusion`` only when it registers a view: numba is slow to
import.
"""

from __future__ import annotations

import numba
import numpy as np

# nogil: fusion splits a query over threads; no fastmath: the same IEEE arithmetic as scipy.
_jit = numba.njit(cache=True, nogil=True)

#: Depth-first stacks (entries); a tree of n points is at most log2(n) + 1 deep.
_STACK = 128


@_jit
def _select(points: np.ndarray, order: np.ndarray, axis: int, start: int, end: int, k: int):
    """Reorder ``order[start:end]`` so that slot ``k`` holds the point whose ``axis``
    coordinate would be there sorted, none before it larger and none after it smaller
    (Hoare's quickselect, middle pivot)."""
    low, high = start, end - 1
    while low < high:
        pivot = points[order[(low + high) // 2], axis]
        i, j = low, high
        while i <= j:
            while points[order[i], axis] < pivot:
                i += 1
            while points[order[j], axis] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        if k <= j:
            high = j
        elif k >= i:
            low = i
        else:
            return


@_jit
def build_tree(points: np.ndarray, leafsize: int):
    """A kd-tree of (N, 3) float64 ``points``: each node splits at the median of its widest
    coordinate (``_select``), leaves hold at most ``leafsize`` points. Returns (order (N,)
    point index per slot, slotted (N, 3) the points in slot order (a leaf's points are
    contiguous in memory), dims (K,) split axis or -1 for a leaf, splits (K,), children
    (K, 2), ranges (K, 2) slots [start, end) of each node)."""
    n = points.shape[0]
    order = np.arange(n)
    most = 2 * n + 1
    dims = np.full(most, -1, np.int64)
    splits = np.zeros(most)
    children = np.zeros((most, 2), np.int64)
    ranges = np.zeros((most, 2), np.int64)
    ranges[0, 1] = n
    stack = np.zeros(_STACK, np.int64)
    top, count = 1, 1
    while top:
        top -= 1
        node = stack[top]
        start, end = ranges[node, 0], ranges[node, 1]
        if end - start <= leafsize:
            continue
        axis, width = 0, -1.0
        for d in range(3):
            low, high = np.inf, -np.inf
            for slot in range(start, end):
                value = points[order[slot], d]
                if value < low:
                    low = value
                if value > high:
                    high = value
            if high - low > width:
                axis, width = d, high - low
        if width <= 0.0:
            continue  # all points equal: a leaf
        middle = start + (end - start) // 2
        _select(points, order, axis, start, end, middle)
        dims[node], splits[node] = axis, points[order[middle], axis]
        # Below: coordinates <= the split; above: >= it.
        children[node, 0], children[node, 1] = count, count + 1
        ranges[count, 0], ranges[count, 1] = start, middle
        ranges[count + 1, 0], ranges[count + 1, 1] = middle, end
        stack[top], stack[top + 1] = count, count + 1
        top += 2
        count += 2
    slotted = np.empty((n, 3))
    for slot in range(n):
        slotted[slot] = points[order[slot]]
    return order, slotted, dims[:count], splits[:count], children[:count], ranges[:count]


@_jit
def nearest_within(
    points: np.ndarray,
    order: np.ndarray,
    slotted: np.ndarray,
    dims: np.ndarray,
    splits: np.ndarray,
    children: np.ndarray,
    ranges: np.ndarray,
    queries: np.ndarray,
    bound: float,
    distance: np.ndarray,
    index: np.ndarray,
) -> None:
    """Fill ``distance`` (Q,) and ``index`` (Q,) with each of (Q, 3) ``queries``' nearest tree
    point (``build_tree`` of (N, 3) ``points``) if nearer than ``bound``, else inf and N."""
    n = points.shape[0]
    limit = bound * bound
    nodes = np.zeros(_STACK, np.int64)
    floors = np.zeros(_STACK)  # squared distance to the split plane of each waiting node
    for q in range(queries.shape[0]):
        x, y, z = queries[q, 0], queries[q, 1], queries[q, 2]
        best, chosen = limit, n
        nodes[0], floors[0] = 0, 0.0
        top = 1
        while top:
            top -= 1
            if floors[top] > best:
                continue
            node = nodes[top]
            while dims[node] >= 0:
                axis = dims[node]
                offset = (x if axis == 0 else y if axis == 1 else z) - splits[node]
                near, far = (0, 1) if offset < 0 else (1, 0)
                if offset * offset <= best:  # equal: a tie with a lower index may be there
                    nodes[top], floors[top] = children[node, far], offset * offset
                    top += 1
                node = children[node, near]
            for slot in range(ranges[node, 0], ranges[node, 1]):
                a = slotted[slot, 0] - x
                b = slotted[slot, 1] - y
                c = slotted[slot, 2] - z
                squared = 0.0
                squared += a * a
                squared += b * b
                squared += c * c
                if squared < best or (squared == best and chosen < n and order[slot] < chosen):
                    best, chosen = squared, order[slot]
        if chosen < n:
            distance[q], index[q] = np.sqrt(best), chosen
        else:
            distance[q], index[q] = np.inf, n
