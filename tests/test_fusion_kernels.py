"""The compiled nearest-neighbour search of view fusion (ipr_shapes.fusion_kernels) against
scipy's cKDTree, whose answers it must give bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from ipr_shapes.fusion import _Nearest
from ipr_shapes.fusion_kernels import build_tree, nearest_within


def _surface(rng: np.random.Generator, count: int) -> np.ndarray:
    """(count, 3) points on a noisy 8 x 5 x 3 cm box surface, as an object's view is (m)."""
    points = rng.uniform(-1.0, 1.0, (count, 3))
    axis = rng.integers(0, 3, count)
    points[np.arange(count), axis] = np.sign(points[np.arange(count), axis])
    return points * [0.04, 0.025, 0.015] + rng.normal(scale=5e-4, size=(count, 3))


@pytest.mark.parametrize("leafsize", [1, 4, 12])
def test_nearest_within_gives_cKDTree_s_answers(leafsize):
    rng = np.random.default_rng(3)
    target = _surface(rng, 1500)
    queries = _surface(rng, 4000) + rng.normal(scale=0.01, size=(4000, 3))
    reference = cKDTree(target)
    tree = build_tree(target, leafsize)
    for bound in (np.inf, 0.05, 0.01, 0.002, 0.0):
        distance = np.empty(len(queries))
        index = np.empty(len(queries), dtype=np.int64)
        nearest_within(target, *tree, queries, bound, distance, index)
        expected = reference.query(queries, distance_upper_bound=bound)
        assert np.array_equal(distance, expected[0]), bound
        assert np.array_equal(index, expected[1]), bound
        if bound in (0.01, 0.002):
            assert 0 < np.isfinite(distance).sum() < len(queries)  # some beyond the bound


def test_equal_points_and_ties_go_to_the_lower_index():
    # Repeated points (exact ties) and a flat grid (equal coordinates on two axes).
    grid = np.array([[x, y, 0.0] for x in range(6) for y in range(6)], float) * 0.01
    target = np.concatenate([grid, grid[::-1], grid[:5]])
    queries = np.concatenate([grid, grid + [0.005, 0.005, 0.0], grid + [0.0, 0.0, 0.003]])
    distance = np.empty(len(queries))
    index = np.empty(len(queries), dtype=np.int64)
    nearest_within(target, *build_tree(target, 4), queries, np.inf, distance, index)
    expected = cKDTree(target).query(queries)
    assert np.array_equal(distance, expected[0])
    # The lowest of the tied indices.
    squared = ((queries[:, None, :] - target[None]) ** 2).sum(axis=2)
    ties = squared == squared.min(axis=1, keepdims=True)
    assert np.array_equal(index, np.argmax(ties, axis=1))


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_threads_split_the_queries_without_changing_an_answer(workers):
    rng = np.random.default_rng(5)
    target = _surface(rng, 900)
    queries = _surface(rng, 2501) + rng.normal(scale=0.004, size=(2501, 3))
    distance, index = _Nearest(target, workers).query(queries, 0.01)
    expected = cKDTree(target).query(queries, distance_upper_bound=0.01)
    assert np.array_equal(distance, expected[0]) and np.array_equal(index, expected[1])
    empty = _Nearest(target, workers).query(np.empty((0, 3)), 0.01)
    assert empty[0].shape == (0,) and empty[1].shape == (0,)
