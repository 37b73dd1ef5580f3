"""Concave edges on smoothly curved surfaces (a bowl's inside, a mug's inner wall).

The convexity graph cuts every concave edge whose normals differ by more than the LCCP
tolerance (``segmentation.concavity_tolerance_deg``). A bowl of 8 cm radius bends by about
14 degrees between 2 cm supervoxels, so its inside falls apart; raising the tolerance merges
touching objects instead (docs/experiments/2026-11-26-concavity-tolerance-real-frames.md).
What tells the two apart is continuity: a curved surface keeps bending the same way at every
step, while two objects meet at a crease with flat (or convex) faces on both sides of it. A
concave edge is therefore kept strong when the surface beyond each of its two ends, along the
edge's direction, bends concavely by a comparable angle (``smooth_concave_edges``).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.types import Supervoxels

#: Cosine of the widest angle (60 degrees) between an edge's direction and a neighbouring
#: edge that continues the surface beyond one of its ends.
_CONE = 0.5


def signed_bends(supervoxels: Supervoxels) -> np.ndarray:
    """(E,) bend (deg) across each adjacency edge: the angle between the two normals,
    positive where the connection is concave ((n_i - n_j) . (c_i - c_j) <= 0), negative where
    convex."""
    pairs = supervoxels.adjacency
    n_i = supervoxels.normals[pairs[:, 0]]
    n_j = supervoxels.normals[pairs[:, 1]]
    offset = supervoxels.centres[pairs[:, 0]] - supervoxels.centres[pairs[:, 1]]
    angle = np.degrees(np.arccos(np.clip(np.einsum("ec,ec->e", n_i, n_j), -1.0, 1.0)))
    convex = np.einsum("ec,ec->e", n_i - n_j, offset) > 0
    return np.where(convex, -angle, angle)


def smooth_concave_edges(supervoxels: Supervoxels, config: PerceptionConfig) -> np.ndarray:
    """(E,) bool: concave edges that lie on a smoothly curved concave surface.

    An edge (i, j) whose concave bend alpha is at least the LCCP tolerance and below
    ``segmentation.curved_join_deg`` qualifies when on both sides the surface continues to
    bend: among the other edges (k, i) of i whose direction c_i - c_k is within 60 degrees of
    c_j - c_i (the surface beyond i, away from j), and likewise the edges (j, l) of j beyond
    j, the mean signed bend (``signed_bends``: concave positive, convex negative) is at least
    ``segmentation.curved_join_ratio`` * alpha. A crease between two objects has flat or
    convex faces on both sides (mean bend about 0, or negative) and stays cut; a bowl's
    inside bends by about the same angle at every step. Sides without such an edge (the
    surface ends) do not qualify.

    Units: supervoxel centres in metres, angles in degrees. Costs O(E * mean degree).
    """
    pairs = supervoxels.adjacency
    n_edges = len(pairs)
    result = np.zeros(n_edges, dtype=bool)
    limit = config.segmentation.curved_join_deg
    if n_edges == 0 or limit <= 0:
        return result
    bend = signed_bends(supervoxels)
    candidate = np.flatnonzero(
        (bend >= config.segmentation.concavity_tolerance_deg) & (bend < limit)
    )
    if candidate.size == 0:
        return result
    count = supervoxels.count
    centres = supervoxels.centres
    # Incidence lists: for every node, the edges touching it and the node at their other end.
    ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
    others = np.concatenate([pairs[:, 1], pairs[:, 0]])
    edge_of = np.concatenate([np.arange(n_edges), np.arange(n_edges)])
    order = np.argsort(ends, kind="stable")
    ends, others, edge_of = ends[order], others[order], edge_of[order]
    start = np.searchsorted(ends, np.arange(count + 1))
    need = config.segmentation.curved_join_ratio * bend[candidate]
    qualifies = np.ones(candidate.size, dtype=bool)
    # Side i (beyond i, away from j), then side j (beyond j, away from i).
    for near, far in ((0, 1), (1, 0)):
        node = pairs[candidate, near]
        partner = pairs[candidate, far]
        forward = centres[partner] - centres[node]  # from the beyond side through the edge
        degree = start[node + 1] - start[node]
        owner = np.repeat(np.arange(candidate.size), degree)
        slot = np.arange(owner.size) - np.repeat(np.cumsum(degree) - degree, degree)
        incident = start[node][owner] + slot
        neighbour = others[incident]
        keep = neighbour != partner[owner]
        owner, neighbour, edge = owner[keep], neighbour[keep], edge_of[incident[keep]]
        step = centres[node[owner]] - centres[neighbour]  # from the neighbour into the node
        aligned = np.einsum("ec,ec->e", step, forward[owner]) >= _CONE * np.linalg.norm(
            step, axis=1
        ) * np.linalg.norm(forward[owner], axis=1)
        owner, edge = owner[aligned], edge[aligned]
        total = np.bincount(owner, weights=bend[edge], minlength=candidate.size)
        seen = np.bincount(owner, minlength=candidate.size)
        mean = np.divide(total, seen, out=np.full(candidate.size, -np.inf), where=seen > 0)
        qualifies &= mean >= need
    result[candidate[qualifies]] = True
    return result


def join_curved_segments(
    segment_of_supervoxel: np.ndarray, supervoxels: Supervoxels, config: PerceptionConfig
) -> np.ndarray:
    """(M,) int32 segments with neighbours that meet along a smoothly curved concave surface
    joined, renumbered 1..k by decreasing size (0 stays 0).

    Two segments are joined when at least ``segmentation.curved_segment_vote`` of the
    adjacency edges between them (and at least 2) are ``smooth_concave_edges`` and their
    mean chromaticities are within ``segmentation.curved_segment_colour``. Deciding per pair of
    segments by a vote of their whole boundary, rather than per edge before the clustering,
    is robust to the single edges that depth noise makes look curved along a crease.
    """
    vote = config.segmentation.curved_segment_vote
    pairs = supervoxels.adjacency
    segments = np.asarray(segment_of_supervoxel, dtype=np.int64)
    if vote <= 0 or len(pairs) == 0 or segments.max(initial=0) < 2:
        return segment_of_supervoxel
    a, b = segments[pairs[:, 0]], segments[pairs[:, 1]]
    between = (a != b) & (a > 0) & (b > 0)
    if not between.any():
        return segment_of_supervoxel
    curved = smooth_concave_edges(supervoxels, config)[between]
    low, high = np.minimum(a[between], b[between]), np.maximum(a[between], b[between])
    n = int(segments.max()) + 1
    key, index = np.unique(low * n + high, return_inverse=True)
    total = np.bincount(index)
    agree = np.bincount(index, weights=curved)
    colour = np.zeros((n, 3))
    for channel in range(3):
        colour[:, channel] = np.bincount(
            segments, weights=supervoxels.colours[:, channel] * supervoxels.sizes, minlength=n
        )
    chroma = colour / np.maximum(colour.sum(axis=1, keepdims=True), 1e-9)
    first, second = key // n, key % n
    alike = (
        np.linalg.norm(chroma[first] - chroma[second], axis=1)
        <= config.segmentation.curved_segment_colour
    )
    join = (total >= 2) & (agree >= vote * total) & alike
    if not join.any():
        return segment_of_supervoxel
    graph = coo_matrix((np.ones(int(join.sum())), (first[join], second[join])), shape=(n, n))
    _, root = connected_components(graph, directed=False)
    labelled = segments > 0
    merged_size = np.bincount(root[segments[labelled]], weights=supervoxels.sizes[labelled])
    alive = np.flatnonzero(merged_size > 0)
    new_id = np.zeros(len(merged_size), dtype=np.int32)
    new_id[alive[np.argsort(-merged_size[alive], kind="stable")]] = np.arange(1, len(alive) + 1)
    return np.where(labelled, new_id[root[segments]], 0).astype(np.int32)
