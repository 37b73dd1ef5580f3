"""The surface allowance (issue 28): when every candidate of an object fails the seen-free check,
the seen-free space within how far its measured surface departs from a convex solid is excused,
so a real sensor's bent depth does not leave it only its minimum shape; space beyond the
allowance still counts, and objects with a feasible candidate are checked as before."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial import cKDTree

from ipr_shapes import voxels
from ipr_shapes.camera import backproject
from ipr_shapes.hypotheses import HypothesisConfig, generate_hypotheses, unary_feasible
from ipr_shapes.hypotheses.allowance import excused_keys, surface_allowance
from ipr_shapes.hypotheses.constraints import generated_unary_feasible
from ipr_shapes.hypotheses.generate import UnaryTolerances
from ipr_shapes.perception.free_space import FREE, observe_space
from ipr_shapes.perception.occupancy import plane_regions

from .box_scene import GRID, SUPPORT, K, View, partial_box, render_view

EYE = (0.25, -0.35, 0.25)
BEND_M = 0.03  # the sides' depth reads this much (m) too far (lab frames: 7-35 mm)
LOW_M = (0.01, 0.04)  # true heights (m) of the box's pixels read too far (its sides)


def _bent_view() -> View:
    """The box seen from ``EYE`` by a sensor that bends its surface back: the box's pixels
    whose true point is ``LOW_M`` above the table (its sides below the top edge) read
    ``BEND_M`` deeper, as a real sensor's smoothed depth does towards the junction with the
    table; the rest exact. The box's pixels whose bent point is within 1 cm of the table are the
    table's (perception's support band)."""
    view = render_view(EYE)
    camera = backproject(view.depth, K)
    world = camera @ view.world_from_camera[:3, :3].T + view.world_from_camera[:3, 3]
    low = (
        (view.index == 0)
        & (view.depth > 0)
        & (world[..., 2] > LOW_M[0])
        & (world[..., 2] < LOW_M[1])
    )
    depth = np.where(low, view.depth + BEND_M, view.depth).astype(view.depth.dtype)
    # As perception does, the points within 1 cm of the table go with the table.
    bent = backproject(depth, K) @ view.world_from_camera[:3, :3].T + view.world_from_camera[:3, 3]
    index = np.where((view.index == 0) & (bent[..., 2] < 0.01), 1, view.index)
    return View(depth, index, view.world_from_camera)


@pytest.fixture(scope="module")
def bent():
    view = _bent_view()
    obj = partial_box(view)
    space = observe_space(view.depth, K, view.world_from_camera, GRID)
    return view, obj, space


def test_allowance_is_the_measured_surfaces_departure_from_convex(bent):
    _, bent_obj, _ = bent
    exact = partial_box(render_view(EYE))
    # Exact depth of a convex box: every point on its own hull.
    assert surface_allowance(exact.points, 0.95) < 5e-4
    # The bent strip lies behind the hull of the rest: the allowance reaches into the bend.
    allowed = surface_allowance(bent_obj.points, 0.95)
    assert 0.003 < allowed <= BEND_M + 1e-3
    assert surface_allowance(bent_obj.points[:3], 0.95) == 0.0


def test_excused_voxels_are_seen_free_and_near_the_objects_points(bent):
    _, obj, space = bent
    allowed = surface_allowance(obj.points, 0.95)
    keys = excused_keys(obj.points, space, GRID.voxel_size_m, allowed)
    assert keys.size > 0
    assert np.all(keys[1:] > keys[:-1])  # sorted, unique
    centres = voxels.centres(keys, GRID.voxel_size_m)
    assert np.all(space.state_at(centres) == FREE)
    distance, _ = cKDTree(obj.points).query(centres)
    assert distance.max() <= allowed + 1e-9
    # Every seen-free voxel that close to a point is excused (brute force over the grid).
    free = GRID.centres()[space.state == FREE]
    near, _ = cKDTree(obj.points).query(free, distance_upper_bound=allowed)
    expected = np.unique(voxels.pack(np.floor(free[near <= allowed] / GRID.voxel_size_m)))
    assert np.array_equal(keys, expected)
    assert excused_keys(obj.points, None, GRID.voxel_size_m, allowed).size == 0
    assert excused_keys(obj.points, space, GRID.voxel_size_m, 0.0).size == 0


def _hypotheses(obj, space, quantile):
    config = HypothesisConfig(
        count=12,
        unary=dataclasses.replace(UnaryTolerances(), surface_allowance_quantile=quantile),
    )
    return config, generate_hypotheses(obj, space, (SUPPORT,), config, np.random.default_rng(3))


def test_bent_junction_keeps_candidates_feasible_and_checks_agree(bent):
    _, obj, space = bent
    _, without = _hypotheses(obj, space, None)
    config, with_allowance = _hypotheses(obj, space, 0.95)
    # Without the allowance every candidate fails (the lab frames' fallback); with it some pass.
    assert not any(h.feasible for h in without)
    assert any(h.feasible for h in with_allowance)
    assert any(h.excused_free_voxels > 0 for h in with_allowance)
    assert all(h.excused_free_voxels == 0 for h in without)
    # The constraint stage gives generation's answer (it subtracts the excused voxels too).
    for hyps, quantile in ((with_allowance, 0.95), (without, None)):
        tolerances = UnaryTolerances(surface_allowance_quantile=quantile)
        regions = plane_regions((SUPPORT,), tolerances.wall_min_thickness_m)
        for h in hyps:
            assert unary_feasible(h, space, (SUPPORT,), tolerances) == generated_unary_feasible(
                h, regions, tolerances
            )


def test_space_beyond_the_allowance_still_counts(bent):
    """A shape reaching 3 cm beyond the box's side, where the camera saw the table, is still
    infeasible: the allowance excuses millimetres around the measured surface, not more."""
    _, obj, space = bent
    config, hyps = _hypotheses(obj, space, 0.95)
    h = next(h for h in hyps if h.feasible)
    widened_vertices = h.vertices.copy()
    toward_camera = np.asarray(EYE, float)[:2] / np.linalg.norm(EYE[:2])
    front = (widened_vertices[:, :2] @ toward_camera) > (h.vertices[:, :2] @ toward_camera).mean()
    widened_vertices[front, :2] += 0.03 * toward_camera
    widened = dataclasses.replace(
        h, vertices=widened_vertices, voxel_keys=None, excused_free_voxels=h.excused_free_voxels
    )
    assert not unary_feasible(widened, space, (SUPPORT,), config.unary)


def test_objects_with_a_feasible_candidate_are_checked_as_before():
    """The allowance is a second check for objects none of whose candidates pass: where the
    sensor is exact some pass, and the hypotheses are those made without it."""
    view = render_view(EYE)
    obj = partial_box(view)
    space = observe_space(view.depth, K, view.world_from_camera, GRID)
    _, without = _hypotheses(obj, space, None)
    _, with_allowance = _hypotheses(obj, space, 0.95)
    assert any(h.feasible for h in without)
    for a, b in zip(with_allowance, without, strict=True):
        assert np.array_equal(a.vertices, b.vertices)
        assert (a.feasible, a.free_voxels, a.excused_free_voxels) == (b.feasible, b.free_voxels, 0)


@pytest.mark.parametrize("bad", [-0.1, 1.5, "0.95"])
def test_allowance_quantile_is_validated(bad):
    with pytest.raises(ValueError):
        UnaryTolerances(surface_allowance_quantile=bad)
