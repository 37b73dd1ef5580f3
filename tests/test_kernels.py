"""Each compiled kernel (``ipr.kernels``) gives what the numpy expression it replaced gave.

The references below are the earlier numpy implementations, kept here only to pin the results:
same bits where the kernel keeps numpy's order of operations, equal to rounding otherwise
(stated per test).
"""

from __future__ import annotations

import numpy as np
import pytest

from ipr import kernels
from ipr.camera import backproject, look_at


def _normalise(vectors: np.ndarray) -> np.ndarray:
    norms = np.linalg.norm(vectors, axis=1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 1e-12)


def _group_sum(groups: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    return np.stack(
        [np.bincount(groups, weights=values[:, c], minlength=count) for c in range(3)], axis=1
    )


def test_world_points_equal_backprojection_then_transform():
    rng = np.random.default_rng(3)
    K = np.array([[520.0, 0.0, 319.5], [0.0, 525.0, 241.2], [0.0, 0.0, 1.0]])
    world_from_camera = look_at(np.array([0.6, -0.4, 0.7]), np.array([0.0, 0.1, 0.0]))
    depth = rng.uniform(0.3, 2.0, (48, 64)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = 0.0
    K[0, 2], K[1, 2] = 31.5, 24.2
    expected = backproject(depth, K) @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
    points = kernels.world_points(depth, K, world_from_camera)
    assert points.shape == (48, 64, 3) and points.dtype == np.float64
    # BLAS may fuse the products: equal to a few units in the last place, not bit for bit.
    np.testing.assert_allclose(points, expected, rtol=0, atol=1e-14)
    # Zero depth is the camera centre, as backproject gives it.
    np.testing.assert_allclose(
        points[depth == 0], np.broadcast_to(world_from_camera[:3, 3], (int((depth == 0).sum()), 3))
    )


def _reference_rounds(centre, normal, colour, count, safe, has, seeds, iterations, size, wn, wc):
    """The numpy k-means rounds of ``compute_supervoxels`` before the kernel."""
    seed_centre, seed_normal, seed_colour = (a[seeds].copy() for a in (centre, normal, colour))
    n_voxels, n_seeds = len(centre), len(seeds)
    assignment = np.zeros(n_voxels, dtype=np.int64)
    spatial = 1.0 / size**2
    for _ in range(iterations):
        distance = np.full(safe.shape, wn)
        for axis in range(3):
            offset = centre[:, axis, None] - seed_centre[:, axis][safe]
            distance += offset * spatial * offset
            distance -= wn * normal[:, axis, None] * seed_normal[:, axis][safe]
            if wc > 0:
                offset = colour[:, axis, None] - seed_colour[:, axis][safe]
                distance += offset * wc * offset
        distance[~has] = np.inf
        assignment = safe[np.arange(n_voxels), np.argmin(distance, axis=1)]
        totals = np.bincount(assignment, weights=count, minlength=n_seeds)
        alive = totals > 0
        seed_centre[alive] = (
            _group_sum(assignment, centre * count[:, None], n_seeds)[alive] / totals[alive, None]
        )
        seed_normal[alive] = _normalise(_group_sum(assignment, normal * count[:, None], n_seeds))[
            alive
        ]
        seed_colour[alive] = (
            _group_sum(assignment, colour * count[:, None], n_seeds)[alive] / totals[alive, None]
        )
    return assignment


@pytest.mark.parametrize("colour_weight", [0.0, 2.0])
def test_supervoxel_rounds_are_bit_identical_to_the_numpy_rounds(colour_weight):
    rng = np.random.default_rng(11)
    n_voxels, n_seeds = 3000, 90
    centre = rng.uniform(0.0, 0.2, (n_voxels, 3))
    normal = _normalise(rng.normal(size=(n_voxels, 3)))
    colour = rng.random((n_voxels, 3))
    count = rng.integers(1, 9, n_voxels).astype(np.float64)
    seeds = rng.choice(n_voxels, n_seeds, replace=False)
    candidates = rng.integers(-1, n_seeds, (n_voxels, 27))
    candidates[:, 13] = rng.integers(0, n_seeds, n_voxels)  # its own cell's seed
    candidates[:5] = -1  # no candidate at all: the first (0) is taken
    has = candidates >= 0
    safe = np.where(has, candidates, 0)
    args = (centre, normal, colour, count, safe, has)
    expected = _reference_rounds(*args, seeds, 3, 0.02, 1.0, colour_weight)
    got = kernels.supervoxel_rounds(
        *args, centre[seeds], normal[seeds], colour[seeds], 3, 0.02, 1.0, colour_weight
    )
    np.testing.assert_array_equal(got, expected)
    assert len(np.unique(got)) > n_seeds // 2  # the rounds did not collapse the seeds
