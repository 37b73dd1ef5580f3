"""The compiled loops behind hypothesis generation give the same bits as the numpy they
replace: the voxel scanline (``voxel_kernels.scanline_keys``), the rays' march through the
free space (``hypotheses.kernels.first_state_samples``) and, in the constraints, the unary
check of generated hypotheses (``generated_unary_feasible``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from ipr_shapes import voxels
from ipr_shapes.hypotheses import (
    HypothesisConfig,
    UnaryTolerances,
    generate_hypotheses,
    unary_feasible,
)
from ipr_shapes.hypotheses.constraints import generated_unary_feasible
from ipr_shapes.hypotheses.generate import _ray_limits
from ipr_shapes.perception.free_space import FREE, UNKNOWN, SpaceMap, VoxelGrid
from ipr_shapes.perception.occupancy import plane_regions
from ipr_shapes.perception.types import KnownPlane

from .box_scene import SUPPORT, partial_box, render_view


def _numpy_scanline(vertices: np.ndarray, faces: np.ndarray, pitch: float) -> np.ndarray:
    """``scanline_voxels``'s set-up followed by its numpy scanline."""
    grid = vertices / pitch - 0.5
    tri_xy = grid[faces][:, :, :2]
    span = float((tri_xy.max(axis=1) - tri_xy.min(axis=1)).max()) + 2.0
    bits = int(min(24, np.floor(np.log2((2.0**31 - 2) / span))))
    fixed = np.round(grid[:, :2] * 2.0**bits).astype(np.int64)
    x, y = fixed[faces][:, :, 0], fixed[faces][:, :, 1]
    return voxels._scanline_keys_numpy(x, y, grid[faces][:, :, 2], bits)


def test_compiled_scanline_gives_the_numpy_keys():
    """Random hulls, some with every corner on the voxel lattice or half of it (columns through
    edges and vertices, crossings at voxel centres), several pitches, and a non-convex mesh."""
    rng = np.random.default_rng(7)
    checked = 0
    for trial in range(300):
        points = rng.normal(size=(int(rng.integers(4, 80)), 3)) * rng.choice([0.01, 0.04])
        points += rng.normal(size=3)
        if trial % 3 == 0:
            points = np.round(points / 0.005) * 0.005
        elif trial % 3 == 1:
            points = np.round(points / 0.0025) * 0.0025
        hull = ConvexHull(points)
        faces = hull.simplices.astype(np.int64)
        pitch = float(rng.choice([0.005, 0.003]))
        got = voxels.scanline_voxels(hull.points, faces, pitch)
        expected = _numpy_scanline(hull.points, faces, pitch)
        assert got.dtype == expected.dtype and np.array_equal(got, expected)
        checked += got.size
    assert checked > 10000
    # Non-convex: a tilted ring (columns through its hole cross the surface four times).
    import trimesh

    ring = trimesh.creation.annulus(r_min=0.015, r_max=0.03, height=0.02, sections=40)
    ring.apply_transform(trimesh.transformations.rotation_matrix(1.1, [1, 0.3, 0.2]))
    got = voxels.scanline_voxels(ring.vertices, ring.faces, 0.002)
    assert np.array_equal(got, _numpy_scanline(ring.vertices, np.asarray(ring.faces), 0.002))
    assert got.size > 1000


class _Wrapped:
    """A seen space that is not a ``SpaceMap`` (like fusion's ``TrackedFreeSpace``): rays take
    the numpy path through ``state_at``."""

    def __init__(self, space: SpaceMap) -> None:
        self._space = space

    @property
    def grid(self) -> VoxelGrid:
        return self._space.grid

    def state_at(self, points: np.ndarray) -> np.ndarray:
        return self._space.state_at(points)


@pytest.mark.parametrize("walls", [False, True])
def test_rays_marched_in_the_compiled_loop_stop_where_numpy_says(walls):
    """The first free voxel along each ray, rays starting inside, outside and across the grid's
    edges, with and without a wall: the same limits as the numpy path over every sample."""
    rng = np.random.default_rng(3)
    grid = VoxelGrid.around(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.15]), 0.005)
    state = rng.choice(np.array([0, 1, 2], np.uint8), size=grid.shape, p=[0.6, 0.1, 0.3])
    space = SpaceMap(grid, state)
    planes = [SUPPORT]
    if walls:
        wall_points = np.array([[0.08, y, z] for y in (-0.1, 0.1) for z in (0.0, 0.2)])
        planes.append(KnownPlane("wall", np.array([-1.0, 0.0, 0.0]), 0.08, wall_points, 0.01))
        # An unbounded wall (too few points for an outline), tilted.
        normal = np.array([0.3, 1.0, 0.1]) / np.linalg.norm([0.3, 1.0, 0.1])
        planes.append(KnownPlane("wall", normal, 0.07, wall_points[:2], 0.02))
    regions = plane_regions(tuple(planes))
    origins = rng.uniform([-0.15, -0.15, -0.02], [0.15, 0.15, 0.2], size=(400, 3))
    walled = 0
    for _ in range(5):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        compiled = _ray_limits(origins, normal, space, regions, 0.3, 0.005)
        numpy_path = _ray_limits(origins, normal, _Wrapped(space), regions, 0.3, 0.005)
        assert np.array_equal(compiled, numpy_path)
        # Free voxels stop a share of the rays, not all of them.
        planes_only = _ray_limits(origins, normal, None, regions, 0.3, 0.005)
        assert 0.05 < (compiled < planes_only).mean() < 0.95
        walled += int(
            (compiled < _ray_limits(origins, normal, space, regions[:1], 0.3, 0.005)).sum()
        )
    assert (walled > 0) == walls  # the walls stop rays that free space does not


def test_generated_hypotheses_need_not_be_measured_twice():
    """For hypotheses straight from generation, the shortcut prepare_hypotheses takes gives
    unary_feasible's answer, infeasible ones included (noise in the hidden space and a zero
    tolerance make some)."""
    view = render_view((0.0, -0.45, 0.40))
    obj, space = partial_box(view), view.space()
    state = space.state.copy()
    noise = (state == UNKNOWN) & (np.random.default_rng(0).random(state.shape) < 0.02)
    state[noise] = FREE
    space = SpaceMap(space.grid, state)
    answers = []
    for tolerance in (0.02, 0.0):
        unary = UnaryTolerances(
            free_space_tolerance=tolerance, free_space_tolerance_voxels=int(tolerance * 1000)
        )
        config = HypothesisConfig(count=12, unary=unary)
        hypotheses = generate_hypotheses(obj, space, (SUPPORT,), config, np.random.default_rng(0))
        regions = plane_regions((SUPPORT,), unary.wall_min_thickness_m)
        for h in hypotheses:
            expected = unary_feasible(h, space, (SUPPORT,), unary)
            assert generated_unary_feasible(h, regions, unary) == expected
            answers.append(expected)
    assert any(answers) and not all(answers)


def _numpy_parts(label, neighbours, areas, normals):
    """The numpy ``hull_parts`` replaces: label propagation to each part's smallest triangle,
    parts numbered in that order, sums by ``np.bincount``."""
    count = len(label)
    rows = np.repeat(np.arange(count), 3)
    cols = neighbours.ravel()
    same = label[rows] == label[cols]
    rows, cols = rows[same], cols[same]
    part = np.arange(count)
    while True:
        previous = part.copy()
        np.minimum.at(part, rows, part[cols])
        part = part[part]
        if np.array_equal(part, previous):
            break
    part = np.unique(part, return_inverse=True)[1]
    parts = int(part.max()) + 1
    area = np.bincount(part, weights=areas, minlength=parts)
    normal = np.stack(
        [np.bincount(part, weights=areas * normals[:, k], minlength=parts) for k in range(3)],
        axis=1,
    )
    return part, area, normal


def test_hull_parts_are_the_numpy_components_and_sums():
    """Hulls of random clouds, triangles labelled by a few random normal directions (parts
    split where a label's triangles do not touch): the same parts, areas and normals."""
    from ipr_shapes.geometry.convex import row_norms, triangle_cross
    from ipr_shapes.hypotheses.kernels import hull_parts

    rng = np.random.default_rng(5)
    split = 0
    for _ in range(50):
        hull = ConvexHull(rng.normal(size=(int(rng.integers(10, 200)), 3)))
        normals = hull.equations[:, :3]
        areas = 0.5 * row_norms(triangle_cross(hull.points[hull.simplices]))
        directions = rng.normal(size=(int(rng.integers(1, 6)), 3))
        label = np.argmax(normals @ directions.T, axis=1).astype(np.int64)
        got = hull_parts(label, hull.neighbors.astype(np.int64), areas, normals)
        expected = _numpy_parts(label, hull.neighbors, areas, normals)
        for a, b in zip(got, expected, strict=True):
            assert a.shape == b.shape and np.array_equal(a, b)
        split += got[1].size > len(np.unique(label))
    assert split > 0


def test_greedy_labels_are_numpy_s_or_give_way_to_them():
    """The compiled greedy grouping gives numpy's labels whenever it is certain, and is certain
    on generic hulls; a product at the threshold itself makes it give way."""
    from ipr_shapes.geometry.convex import row_norms, triangle_cross
    from ipr_shapes.hypotheses.generate import _CERTAIN_BAND, _greedy_labels_numpy
    from ipr_shapes.hypotheses.kernels import greedy_labels

    rng = np.random.default_rng(11)
    certain = 0
    for _ in range(100):
        hull = ConvexHull(rng.normal(size=(int(rng.integers(10, 300)), 3)))
        normals = np.ascontiguousarray(hull.equations[:, :3])
        areas = 0.5 * row_norms(triangle_cross(hull.points[hull.simplices]))
        cos_group, min_area = np.cos(np.radians(rng.uniform(5, 40))), areas.sum() * 0.05
        label, sure = greedy_labels(areas, normals, cos_group, min_area, _CERTAIN_BAND)
        if sure:
            expected = _greedy_labels_numpy(areas, hull.equations[:, :3], cos_group, min_area)
            assert np.array_equal(label, expected)
            certain += 1
    assert certain >= 95
    # Two triangles' normals exactly cos_group apart: too close to call.
    normals = np.array([[0.0, 0.0, 1.0], [0.0, np.sin(0.3), np.cos(0.3)]])
    _, sure = greedy_labels(np.ones(2), normals, normals[1, 2], 0.5, _CERTAIN_BAND)
    assert not sure


def test_outside_shares_are_numpy_s_mean():
    """The compiled share of rays each candidate d violates is numpy's bool mean, bit for bit,
    ties at a ray's ends (a centre equal to low or high is inside) and NaN ends included."""
    from ipr_shapes.hypotheses.kernels import outside_shares

    rng = np.random.default_rng(5)
    for trial in range(200):
        rays = int(rng.integers(1, 120))
        low = rng.normal(size=rays) * 0.05
        high = low + np.abs(rng.normal(size=rays)) * 0.1
        centres = np.arange(0.0, 0.3, 0.005) + 0.0025
        if trial % 4 == 0:
            low[: rays // 2] = centres[rng.integers(0, len(centres), rays // 2)]
            high[rays // 2 :] = centres[rng.integers(0, len(centres), rays - rays // 2)]
        if trial % 7 == 0:
            low[0] = np.nan
        got = outside_shares(centres, low, high)
        outside = (centres[:, None] < low[None, :]) | (centres[:, None] > high[None, :])
        expected = outside.mean(axis=1)
        assert got.dtype == expected.dtype and got.tobytes() == expected.tobytes()


def test_weighted_choice_is_generator_choice():
    """``_weighted_choice`` draws what ``Generator.choice(n, size, p=p)`` draws and leaves the
    generator in the same state; an invalid ``p`` gets numpy's own error."""
    from ipr_shapes.hypotheses.generate import _weighted_choice

    first, second = np.random.default_rng(3), np.random.default_rng(3)
    for _ in range(500):
        n = int(first.integers(1, 50))
        second.integers(1, 50)
        weights = first.random(n) ** 3
        second.random(n)
        p = weights / weights.sum()
        count = int(first.integers(1, 40))
        second.integers(1, 40)
        expected = first.choice(n, size=count, p=p)
        got = _weighted_choice(second, p, count)
        assert got.dtype == expected.dtype and np.array_equal(got, expected)
        assert first.random() == second.random()
    with pytest.raises(ValueError):
        _weighted_choice(np.random.default_rng(0), np.array([0.5, np.nan]), 3)


def test_unique_rows_are_numpy_s_unique():
    """``unique_rows`` gives ``np.unique(axis=0)``'s rows, bit for bit: rounded planes with
    repeats, signed zeros (rows equal but for a zero's sign give way to numpy) and NaN."""
    from ipr_shapes.geometry.convex import unique_rows

    rng = np.random.default_rng(9)
    for trial in range(500):
        rows = rng.normal(size=(int(rng.integers(2, 300)), int(rng.integers(1, 5))))
        rows = np.round(rows * rng.choice([1e-9, 1e-3, 1.0]), int(rng.integers(0, 10)))
        rows = np.concatenate([rows, rows[rng.integers(0, len(rows), len(rows) // 2)]])
        if trial % 5 == 0:
            rows[rng.random(rows.shape) < 0.2] = -0.0
        if trial % 11 == 0:
            rows[0, 0] = np.nan
        got, expected = unique_rows(rows), np.unique(rows, axis=0)
        assert got.shape == expected.shape and got.tobytes() == expected.tobytes()
    signed = np.array([[0.0, 1.0], [-0.0, 1.0], [0.0, 1.0], [2.0, 0.0]])
    assert unique_rows(signed).tobytes() == np.unique(signed, axis=0).tobytes()


def test_depths_do_not_depend_on_the_other_meshes_in_the_model():
    """``prepare_hypotheses`` compiles only the hypotheses some depth query needs: a pair's
    depth from a model of two meshes is the one from a model of all of them."""
    from ipr_shapes.hypotheses.constraints import OverlapCache

    view = render_view((0.0, -0.45, 0.40))
    config = HypothesisConfig(count=6)
    first = generate_hypotheses(partial_box(view), None, (SUPPORT,), config)
    # A second object: the same shapes moved 3-4 cm (partly overlapping the first's).
    second = [
        dataclasses.replace(h, object_id=7, vertices=h.vertices + [0.03, 0.01, 0.0]) for h in first
    ]
    whole = OverlapCache([*first, *second]).depth_matrix(first, second)
    assert whole.max() > 0.005
    for a, h in enumerate(first):
        for b, g in enumerate(second):
            assert OverlapCache([g, h]).depth(h, g) == whole[a, b]


def test_oriented_hull_mesh_is_numpy_s():
    """The compiled outward mesh of a qhull hull is numpy's, array for array: random hulls,
    lattice points (coplanar facets split in triangles, slivers), and it is certain on them."""
    from ipr_shapes.geometry.convex import _oriented_mesh, _oriented_mesh_numpy
    from ipr_shapes.geometry.kernels import oriented_hull_mesh

    rng = np.random.default_rng(13)
    certain = 0
    for trial in range(300):
        points = rng.normal(size=(int(rng.integers(4, 400)), 3)) * rng.choice([0.01, 0.1])
        if trial % 2:
            points = np.round(points / 0.005) * 0.005
        hull = ConvexHull(points + rng.normal(size=3))
        got, expected = _oriented_mesh(hull), _oriented_mesh_numpy(hull)
        assert got[0].tobytes() == expected[0].tobytes() and got[0].shape == expected[0].shape
        assert got[1].dtype == expected[1].dtype and np.array_equal(got[1], expected[1])
        assert got[2] == expected[2]
        certain += oriented_hull_mesh(hull.points, hull.simplices, hull.equations)[2]
    assert certain >= 295


def test_slice_ranks_are_numpy_s_unique_inverse():
    """``structure._ranks`` numbers non-negative ints as ``np.unique(return_inverse=True)``."""
    from ipr_shapes.hypotheses.structure import _ranks

    rng = np.random.default_rng(17)
    for trial in range(500):
        values = rng.integers(0, int(rng.integers(1, 80)), size=int(rng.integers(0, 300)))
        if trial % 50 == 0 and values.size:
            values[0] = 10**9  # an outlier: numpy's sort
        got, expected = _ranks(values), np.unique(values, return_inverse=True)[1]
        assert got.dtype == expected.dtype and np.array_equal(got, expected)
