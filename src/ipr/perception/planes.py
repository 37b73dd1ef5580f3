"""Plane detection in point clouds: RANSAC with a least-squares refit on the inliers.

The paper's authors find the support (table) plane by RANSAC with a 1 cm inlier threshold and
1000 iterations; the same routine finds further large planes (container walls, the occluding
front of a drawer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Plane:
    """The plane {x : normal . x + offset = 0}; ``normal`` is a unit (3,) vector.

    ``inliers`` are indices into the point array the plane was fitted to.
    """

    normal: np.ndarray
    offset: float
    inliers: np.ndarray

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distances (N,) in metres of (N, 3) points, positive on the normal's side."""
        return points @ self.normal + self.offset

    def oriented_towards(self, point: np.ndarray) -> Plane:
        """The same plane with its normal flipped, if needed, to point towards ``point``."""
        if float(self.signed_distance(point[None])[0]) >= 0:
            return self
        return Plane(-self.normal, -self.offset, self.inliers)


def fit_plane_ransac(
    points: np.ndarray,
    *,
    threshold_m: float = 0.01,
    iterations: int = 1000,
    min_inliers: int = 500,
    rng: np.random.Generator | None = None,
) -> Plane | None:
    """Dominant plane of (N, 3) points by RANSAC, refined by least squares on its inliers.

    Hypotheses are scored in batches (vectorised over iterations on a subsample) and the best is
    re-scored on all points. Returns None when fewer than ``min_inliers`` points support any plane.
    Deterministic for a given ``rng`` (seed 0 when None).
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) < max(3, min_inliers):
        return None
    rng = np.random.default_rng(0) if rng is None else rng
    # Scoring on a subsample keeps the cost independent of the image size.
    sample = points[rng.choice(len(points), size=min(len(points), 4000), replace=False)]
    triples = points[rng.integers(0, len(points), size=(iterations, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    valid = norms > 1e-9
    if not valid.any():
        return None
    normals = normals[valid] / norms[valid, None]
    offsets = -np.einsum("ij,ij->i", normals, triples[valid, 0])
    best, best_count = None, -1
    for start in range(0, len(normals), 250):
        distances = np.abs(sample @ normals[start : start + 250].T + offsets[start : start + 250])
        counts = (distances < threshold_m).sum(axis=0)
        index = int(np.argmax(counts))
        if counts[index] > best_count:
            best, best_count = start + index, int(counts[index])
    normal, offset = normals[best], offsets[best]
    for _ in range(2):  # least-squares refits on the full inlier set
        inliers = np.flatnonzero(np.abs(points @ normal + offset) < threshold_m)
        if len(inliers) < 3:
            return None
        centroid = points[inliers].mean(axis=0)
        _, _, vt = np.linalg.svd(points[inliers] - centroid, full_matrices=False)
        normal = vt[2] * (1.0 if vt[2] @ normal >= 0 else -1.0)
        offset = -float(normal @ centroid)
    inliers = np.flatnonzero(np.abs(points @ normal + offset) < threshold_m)
    if len(inliers) < min_inliers:
        return None
    return Plane(normal, offset, inliers)
