"""Geometric constraints: exact overlaps, compatibility matrices, unary and joint feasibility."""

from __future__ import annotations

import numpy as np
import pytest

from ipr_shapes.hypotheses import UnaryTolerances
from ipr_shapes.hypotheses.constraints import (
    ConstraintConfig,
    OverlapCache,
    compatibility_matrix,
    intersection_volume,
    joint_feasible,
    pairwise_overlap,
    penetration_depth,
    unary_feasible,
)
from ipr_shapes.perception.free_space import FREE, SpaceMap, VoxelGrid
from ipr_shapes.perception.types import KnownPlane
from ipr_shapes.products import ShapeHypothesis

from .box_scene import SUPPORT, box_mesh


def cube(object_id: int, index: int, lower, size: float = 0.1) -> ShapeHypothesis:
    """An axis-aligned cube hypothesis with its lower corner at ``lower`` (m)."""
    half = np.full(3, size / 2)
    vertices, faces = box_mesh(half, np.asarray(lower, float) + half)
    return ShapeHypothesis(
        object_id, index, vertices, faces, size**3, np.zeros(0), np.zeros((0, 3))
    )


def test_overlap_of_two_cubes_offset_by_half_is_exact():
    a, b = cube(1, 0, [0, 0, 0]), cube(2, 0, [0.05, 0, 0])
    assert intersection_volume(a, b) == pytest.approx(0.5 * 0.1**3, rel=1e-9)
    assert penetration_depth(a, b) == pytest.approx(0.05, abs=1e-6)
    assert pairwise_overlap(a, b) == pytest.approx(0.05, abs=1e-6)
    # Rotated overlap along a diagonal: cubes sharing a corner region 2 x 3 x 4 cm.
    c = cube(3, 0, [0.08, 0.07, 0.06])
    assert intersection_volume(a, c) == pytest.approx(0.02 * 0.03 * 0.04, rel=1e-9)
    assert penetration_depth(a, c) == pytest.approx(0.02, abs=1e-6)
    apart = cube(4, 0, [0.2, 0, 0])
    assert penetration_depth(a, apart) == 0.0
    assert intersection_volume(a, apart) == 0.0


def test_compatibility_matrix_with_tolerance_and_box_pretest():
    config = ConstraintConfig(overlap_tolerance_m=0.005)
    first = [cube(1, 0, [0, 0, 0]), cube(1, 1, [0, 0.5, 0])]
    second = [cube(2, 0, [0.05, 0, 0]), cube(2, 1, [0.097, 0, 0]), cube(2, 2, [0.3, 0, 0])]
    cache = OverlapCache([*first, *second])
    matrix = compatibility_matrix(first, second, config, cache)
    assert matrix.tolist() == [[False, True, True], [True, True, True]]
    # Only the pair whose boxes overlap beyond the tolerance needed an exact query.
    assert cache.queries == 1
    compatibility_matrix(first, second, config, cache)
    assert cache.queries == 1  # cached
    assert compatibility_matrix(second, first, config).T.tolist() == matrix.tolist()


def test_forced_overlap_is_relaxed_but_still_ranks():
    first = [cube(1, 0, [0, 0, 0])]
    second = [cube(2, 0, [0.07, 0, 0]), cube(2, 1, [0.05, 0, 0])]  # 3 and 5 cm deep
    relaxed = compatibility_matrix(first, second, ConstraintConfig(overlap_tolerance_m=0.005))
    assert relaxed.tolist() == [[True, False]]
    strict = compatibility_matrix(
        first, second, ConstraintConfig(overlap_tolerance_m=0.005, relax_forced_overlap=False)
    )
    assert strict.tolist() == [[False, False]]


def test_unary_feasibility_support_free_space_and_walls():
    grid = VoxelGrid.around(np.array([-0.2, -0.2, -0.1]), np.array([0.3, 0.3, 0.3]))
    state = np.zeros(grid.shape, dtype=np.uint8)
    centres = grid.centres()
    state[centres[..., 0] > 0.15] = FREE  # seen empty beyond x = 0.15
    space = SpaceMap(grid, state)
    config = UnaryTolerances()
    assert unary_feasible(cube(1, 0, [0, 0, 0]), space, (SUPPORT,), config)
    assert not unary_feasible(cube(1, 1, [0, 0, -0.02]), space, (SUPPORT,), config)  # below
    assert unary_feasible(cube(1, 2, [0, 0, -0.004]), space, (SUPPORT,), config)  # noise
    assert not unary_feasible(cube(1, 3, [0.1, 0, 0]), space, (SUPPORT,), config)  # free
    # One 5 mm layer of 20 x 20 voxels out of 8000 pokes into free space: 5 % of the shape.
    poking = cube(1, 4, [0.055, 0, 0])
    assert not unary_feasible(poking, space, (SUPPORT,), config)
    assert unary_feasible(poking, space, (SUPPORT,), UnaryTolerances(free_space_tolerance=0.06))
    assert unary_feasible(
        poking, space, (SUPPORT,), UnaryTolerances(free_space_tolerance_voxels=400)
    )
    wall = KnownPlane(
        "wall",
        np.array([-1.0, 0.0, 0.0]),
        0.2,  # face at x = 0.2, the camera side is x < 0.2
        np.array([[0.2, y, z] for y in (-0.2, 0.2) for z in (0.0, 0.2)]),
        thickness_m=0.02,
    )
    assert unary_feasible(cube(1, 5, [0.0, 0, 0]), None, (SUPPORT, wall), config)
    assert not unary_feasible(cube(1, 6, [0.15, 0, 0]), None, (SUPPORT, wall), config)
    assert unary_feasible(cube(1, 7, [0.15, 0.25, 0]), None, (SUPPORT, wall), config)  # beside


def test_joint_feasibility_of_choices():
    hypotheses = {
        1: [cube(1, 0, [0, 0, 0]), cube(1, 1, [0, 0, 0], size=0.2)],
        2: [cube(2, 0, [0.12, 0, 0]), cube(2, 1, [0.12, 0, -0.05])],
    }
    assert joint_feasible({1: 0, 2: 0}, hypotheses, None, (SUPPORT,))
    assert not joint_feasible({1: 1, 2: 0}, hypotheses, None, (SUPPORT,))  # they intersect
    assert not joint_feasible({1: 0, 2: 1}, hypotheses, None, (SUPPORT,))  # below support


def test_free_voxels_that_the_observed_points_force_are_forgiven():
    import dataclasses

    grid = VoxelGrid.around(np.array([-0.2, -0.2, -0.1]), np.array([0.3, 0.3, 0.3]))
    state = np.zeros(grid.shape, dtype=np.uint8)
    state[grid.centres()[..., 0] > 0.15] = FREE  # seen empty beyond x = 0.15
    space = SpaceMap(grid, state)
    poking = cube(1, 4, [0.055, 0, 0])  # 400 of its 8000 voxels are in free space
    assert not unary_feasible(poking, space, (SUPPORT,), UnaryTolerances())
    # The observed points' own hull already has those voxels there: the observation forces
    # them (noise, a thin gap), so they are not held against the hypothesis.
    forced = dataclasses.replace(poking, forced_free_voxels=400)
    assert unary_feasible(forced, space, (SUPPORT,), UnaryTolerances())
    assert not unary_feasible(
        dataclasses.replace(poking, forced_free_voxels=100), space, (SUPPORT,), UnaryTolerances()
    )
