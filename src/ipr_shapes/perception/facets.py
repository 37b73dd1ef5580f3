"""Facet decomposition of partial objects (paper Sec. III-B).

A facet is a homogeneous region of one side of an object: a box seen from above shows up to three
facets, a can a few strips of its side plus its lid. Following the paper, an object's supervoxels
(not raw points) are clustered by their normals with mean shift, so the curvature between patches
is the distance; each normal cluster is then split into spatially connected regions, because two
parallel faces (the two ends of a bottle) share a normal but are different facets.
"""

from __future__ import annotations

import numpy as np

from ipr_shapes.perception import kernels
from ipr_shapes.perception.types import Facet


def mean_shift_directions(
    normals: np.ndarray, weights: np.ndarray, bandwidth: float, iterations: int = 30
) -> np.ndarray:
    """Mode index (N,) of each unit normal (N, 3) under weighted Gaussian mean shift on the sphere.

    ``weights`` (N,) weigh the normals (supervoxel sizes). ``bandwidth`` is a chord length between
    unit vectors (0.35 is about 20 degrees). An object has tens of supervoxels, so the dense N x N
    kernel is cheaper than a general-purpose estimator's per-call set-up (scikit-learn's
    MeanShift).
    """
    # Compiled (``kernels``): objects have a few to a few hundred supervoxels, where
    # numpy's per-call costs exceed the arithmetic.
    return kernels.mean_shift_directions(
        np.ascontiguousarray(normals, dtype=np.float64),
        np.ascontiguousarray(weights, dtype=np.float64),
        float(bandwidth),
        int(iterations),
    )


def _row_norms(vectors: np.ndarray) -> np.ndarray:
    """(N, 1) Euclidean lengths of the rows of (N, 3) ``vectors``: np.linalg.norm's own
    arithmetic (sum of squares along the row, square root) without its per-call overhead."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=1, keepdims=True))


def pixel_areas(points_camera: np.ndarray, normals_camera: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Surface area (N,) in m^2 that each pixel covers, from camera-frame points and normals (N, 3).

    A pixel at planar depth z covers z^2 / (fx fy) of the fronto-parallel plane; a surface tilted
    away covers more by |r . z| / |r . n| for the unit ray r (clipped at grazing angles, where
    depth is least reliable).
    """
    z = points_camera[:, 2]
    rays = points_camera / _row_norms(points_camera)
    # In place (one pixel per object point, tens of thousands per frame), with the arithmetic
    # of z^2 / (fx fy) * (|r_z| / max(|r . n|, 0.25)).
    facing = np.einsum("ij,ij->i", rays, normals_camera)
    np.abs(facing, out=facing)
    np.maximum(facing, 0.25, out=facing)
    tilt = np.abs(rays[:, 2])
    tilt /= facing
    area = z**2
    area /= K[0, 0] * K[1, 1]
    area *= tilt
    return area


def object_facets(
    supervoxel_ids: np.ndarray,
    supervoxel_normals: np.ndarray,
    supervoxel_sizes: np.ndarray,
    adjacency: np.ndarray,
    point_supervoxel: np.ndarray,
    points_world: np.ndarray,
    point_areas: np.ndarray,
    *,
    bandwidth: float,
) -> tuple[tuple[Facet, ...], np.ndarray]:
    """Facets of one object and the facet (N,) of each of its points (-1 for none).

    Args:
        supervoxel_ids: (S,) the object's supervoxels (indices into the frame's supervoxels).
        supervoxel_normals: (M, 3) and supervoxel_sizes (M,) of all the frame's supervoxels.
        adjacency: (E, 2) supervoxel pairs that touch (the frame's graph).
        point_supervoxel: (N,) supervoxel of each of the object's points.
        points_world: (N, 3) the object's points (m); point_areas: (N,) their areas (m^2).
        bandwidth: mean-shift bandwidth on unit normals.
    """
    if len(supervoxel_ids) == 0:
        return (), np.full(len(points_world), -1, dtype=np.int64)
    count = len(supervoxel_ids)
    local = np.full(
        max(int(supervoxel_ids.max()), int(adjacency.max(initial=0))) + 1, -1, dtype=np.int64
    )
    local[supervoxel_ids] = np.arange(count)
    modes = mean_shift_directions(
        supervoxel_normals[supervoxel_ids],
        supervoxel_sizes[supervoxel_ids].astype(float),
        bandwidth,
    )
    # Connected regions of supervoxels that share a normal mode.
    pairs = local[adjacency] if len(adjacency) else np.zeros((0, 2), dtype=np.int64)
    pairs = pairs[(pairs >= 0).all(axis=1)]
    pairs = pairs[modes[pairs[:, 0]] == modes[pairs[:, 1]]]
    region = _components(pairs, count)

    lookup = np.full(int(supervoxel_ids.max()) + 1, -1, dtype=np.int64)
    lookup[supervoxel_ids] = region
    point_region = lookup[point_supervoxel]
    facets, facet_of_point = [], np.full(len(points_world), -1, dtype=np.int64)
    region_normals = supervoxel_normals[supervoxel_ids]
    region_weights = supervoxel_sizes[supervoxel_ids].astype(float)
    n_regions = int(region.max()) + 1
    # The points of every region from one sort and one gather (regions are numbered from 0;
    # points of no supervoxel of the object, region -1, come first and are skipped); their
    # counts, centres and areas from one compiled pass.
    by_region, bounds, grouped, sizes, sums, area_sums = kernels.region_groups(
        point_region, np.ascontiguousarray(points_world, dtype=np.float64), point_areas, n_regions
    )
    summed_normals = kernels.group_sums(region, region_normals * region_weights[:, None], n_regions)
    for number in range(n_regions):
        if sizes[number] == 0:
            continue
        normal = summed_normals[number]
        normal /= np.sqrt(normal @ normal) + 1e-12
        facet_of_point[by_region[bounds[number] : bounds[number + 1]]] = len(facets)
        points = grouped[bounds[number] : bounds[number + 1]]
        facets.append(Facet(sums[number] / sizes[number], normal, points, float(area_sums[number])))
    return tuple(facets), facet_of_point


def _components(pairs: np.ndarray, count: int) -> np.ndarray:
    """(count,) int64 connected component of each node of the undirected graph with edges
    (E, 2) ``pairs``, numbered as scipy's ``connected_components`` numbers them: in the order
    of each component's smallest node. Compiled union-find (``kernels``): the graphs here
    (one object's supervoxels) have a few to a few hundred nodes, where scipy's sparse-matrix
    set-up costs several times the work itself."""
    return kernels.connected_components(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), count)
