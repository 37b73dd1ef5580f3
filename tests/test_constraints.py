"""Geometric constraints: exact overlaps, compatibility matrices, unary and joint feasibility."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ipr_shapes.hypotheses import UnaryTolerances
from ipr_shapes.hypotheses.constraints import (
    ConstraintConfig,
    OverlapCache,
    box_depth_bounds,
    compatibility_matrix,
    interacting_pairs,
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


def cuboid(object_id: int, index: int, lower, upper) -> ShapeHypothesis:
    """An axis-aligned box hypothesis from its lower to its upper corner (m)."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    vertices, faces = box_mesh((upper - lower) / 2, (upper + lower) / 2)
    volume = float(np.prod(upper - lower))
    return ShapeHypothesis(object_id, index, vertices, faces, volume, np.zeros(0), np.zeros((0, 3)))


def test_thickness_is_the_least_extent_across_the_faces():
    slab = cuboid(1, 0, [0, 0, 0], [0.1, 0.002, 0.04])
    assert slab.width_m == pytest.approx(0.002, abs=1e-12)
    assert cube(1, 1, [0, 0, 0], size=0.03).width_m == pytest.approx(0.03, abs=1e-12)
    # Turned 30 degrees about z: still 2 mm across its broad faces (not its box's 5.2 cm).
    turn = np.deg2rad(30.0)
    rotation = np.array(
        [[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]]
    )
    turned = dataclasses.replace(slab, vertices=slab.vertices @ rotation.T)
    assert turned.width_m == pytest.approx(0.002, abs=1e-12)
    assert np.ptp(turned.vertices[:, 1]) > 0.05


def test_a_thin_candidate_across_a_neighbour_is_not_passed_by_the_box_pretest():
    """A 2 mm slab across a long box: its bounding box's intervals overlap by 2 mm along y, but
    separating them takes a 3.9 cm move (up z); the pre-test must not answer 2 mm."""
    config = ConstraintConfig(overlap_tolerance_m=0.005)
    box = cuboid(1, 0, [-0.049, -0.03, 0.0], [0.049, 0.2, 0.039])
    slab = cuboid(2, 0, [-0.05, 0.098, 0.0], [0.05, 0.1, 0.04])
    assert box_depth_bounds([box], [slab])[0, 0] == pytest.approx(0.039, abs=1e-9)
    assert penetration_depth(box, slab) == pytest.approx(0.039, abs=1e-6)
    cache = OverlapCache([box, slab])
    assert cache.depth_matrix([box], [slab], exact_above_m=0.005)[0, 0] == pytest.approx(
        0.039, abs=1e-6
    )
    strict = ConstraintConfig(overlap_tolerance_m=0.005, relax_forced_overlap=False)
    assert compatibility_matrix([box], [slab], strict, cache).tolist() == [[False]]
    # The objects' envelopes (one candidate each here) interact: the pair is measured.
    assert interacting_pairs({1: [box], 2: [slab]}, 0.005) == [(1, 2)]
    apart = cuboid(2, 1, [-0.05, 0.3, 0.0], [0.05, 0.302, 0.04])
    assert interacting_pairs({1: [box], 2: [apart]}, 0.005) == []
    # A box that stops 1 cm short of the slab is compatible; with both, only it is.
    short = cuboid(1, 1, [-0.049, -0.03, 0.0], [0.049, 0.088, 0.039])
    assert compatibility_matrix([box, short], [slab], config).tolist() == [[False], [True]]


def test_a_candidate_thinner_than_the_tolerance_may_not_sink_into_a_neighbour():
    """The tolerance is for touching surfaces: a 2 mm slab 3 mm deep into a box's face (within
    the 5 mm tolerance) lies wholly inside it and is refused; 1 mm deep (half of it, a noisy
    contact) passes, and so does a 1 cm plate 3 mm deep (its depth within the tolerance)."""
    config = ConstraintConfig(overlap_tolerance_m=0.005, relax_forced_overlap=False)
    box = cuboid(1, 0, [0.0, 0.0, 0.0], [0.1, 0.1, 0.1])
    sunk = cuboid(2, 0, [0.02, 0.02, 0.097], [0.08, 0.08, 0.099])  # 3 mm deep, 2 mm thick
    touching = cuboid(2, 1, [0.02, 0.02, 0.099], [0.08, 0.08, 0.101])  # 1 mm deep
    plate = cuboid(2, 2, [0.02, 0.02, 0.097], [0.08, 0.08, 0.107])  # 3 mm deep, 1 cm thick
    assert intersection_volume(box, sunk) == pytest.approx(sunk.volume_m3, rel=1e-9)
    assert penetration_depth(box, sunk) == pytest.approx(0.003, abs=1e-6)
    matrix = compatibility_matrix([box], [sunk, touching, plate], config)
    assert matrix.tolist() == [[False, True, True]]
    # The measure: the depth in units of the thinner candidate's thickness (t / w = 2.5).
    assert pairwise_overlap(box, sunk, config) == pytest.approx(0.0075, abs=1e-6)
    assert pairwise_overlap(box, touching, config) == pytest.approx(0.0025, abs=1e-6)
    assert pairwise_overlap(box, plate, config) == pytest.approx(0.003, abs=1e-6)


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
