"""Planes in point clouds: RANSAC with a least-squares refit on the inliers.

The paper's authors find the support (table) plane by RANSAC with a 1 cm inlier threshold and
1000 iterations; the same routine finds further large planes (container walls, the occluding
front of a drawer, ``ipr_shapes.perception.planes``) and the table that sets the world frame of a
scene without camera poses (``ipr_shapes.scene.world_from_support_plane``). The compiled scoring
(``ipr_shapes.geometry.kernels``, which imports numba) is imported on the first fit, so that
``ipr_shapes.scene`` can import this module and still start fast.
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
    axis: np.ndarray | None = None,
    max_tilt_deg: float = 90.0,
    sample_size: int = 4000,
) -> Plane | None:
    """Dominant plane of (N, 3) points by RANSAC, refined by least squares on its inliers.

    Hypotheses are scored on a subsample of ``sample_size`` points (one compiled pass per
    hypothesis, ``kernels.plane_inlier_counts``) and the best is re-scored on all points. With
    ``axis`` (unit (3,)), only planes whose normal is within ``max_tilt_deg`` of +-axis are
    considered (hypotheses and refits alike). Returns None when fewer than ``min_inliers``
    points support any plane. Deterministic for a given ``rng`` (seed 0 when None).
    """
    from ipr_shapes.geometry import kernels  # numba: only where a plane is fitted

    points = np.asarray(points, dtype=np.float64)
    if len(points) < max(3, min_inliers):
        return None
    rng = np.random.default_rng(0) if rng is None else rng
    # Scoring on a subsample keeps the cost independent of the image size.
    sample = points[rng.choice(len(points), size=min(len(points), sample_size), replace=False)]
    triples = points[rng.integers(0, len(points), size=(iterations, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    valid = norms > 1e-9
    if axis is not None:
        min_cos = np.cos(np.radians(max_tilt_deg))
        valid &= np.abs(normals @ np.asarray(axis, float)) >= min_cos * np.maximum(norms, 1e-12)
    if not valid.any():
        return None
    normals = normals[valid] / norms[valid, None]
    offsets = -np.einsum("ij,ij->i", normals, triples[valid, 0])
    # Compiled scoring (``ipr_shapes.geometry.kernels``): no (sample, hypotheses) distance arrays.
    best = int(np.argmax(kernels.plane_inlier_counts(sample, normals, offsets, threshold_m)))
    normal, offset = normals[best], offsets[best]
    # The refits use at most 20000 inliers (evenly spread: they fix the plane as well as all of
    # them, at a fraction of the cost of a decomposition of a large matrix), so their inliers
    # are looked for among an even subset of at most 50000 points: on a 640x480 frame this
    # spares two of the three passes over all ~300000 points.
    refit_points = points[:: max(1, len(points) // 50000)]
    for _ in range(2):  # least-squares refits on the inliers
        inliers = kernels.plane_inliers(refit_points, normal, float(offset), threshold_m)
        if len(inliers) < 3:
            return None
        centroid, scatter = kernels.centred_scatter(
            refit_points, inliers[:: max(1, len(inliers) // 20000)]
        )
        _, vectors = np.linalg.eigh(scatter)
        refit = vectors[:, 0] * (1.0 if vectors[:, 0] @ normal >= 0 else -1.0)
        if axis is not None and abs(float(refit @ axis)) < np.cos(np.radians(max_tilt_deg)):
            break  # the refit would leave the allowed orientations: keep the hypothesis
        normal = refit
        offset = -float(normal @ centroid)
    inliers = kernels.plane_inliers(points, normal, float(offset), threshold_m)
    if len(inliers) < min_inliers:
        return None
    return Plane(normal, offset, inliers)
