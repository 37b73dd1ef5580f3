"""Each compiled geometry kernel (``ipr_shapes.geometry.kernels``) gives what the numpy expression it
replaced gave: same bits where the kernel keeps numpy's order of operations, equal to rounding
otherwise (stated per test). The perception kernels: ``test_kernels.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from ipr_shapes.camera import backproject, look_at
from ipr_shapes.geometry import kernels


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


def test_plane_kernels_match_the_numpy_expressions():
    rng = np.random.default_rng(31)
    points = rng.uniform(-0.5, 0.5, (4000, 3))
    points[:1500, 2] = rng.normal(0.0, 0.003, 1500)  # a table at z = 0
    normals = rng.normal(size=(300, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[0] = [0.0, 0.0, 1.0]
    offsets = rng.uniform(-0.1, 0.1, 300)
    offsets[0] = 0.0
    distances = np.abs(points @ normals.T + offsets)
    counts = kernels.plane_inlier_counts(points, normals, offsets, 0.01)
    np.testing.assert_array_equal(counts, (distances < 0.01).sum(axis=0))
    assert int(np.argmax(counts)) == 0
    inliers = kernels.plane_inliers(points, normals[0], 0.0, 0.01)
    np.testing.assert_array_equal(inliers, np.flatnonzero(distances[:, 0] < 0.01))
    centroid, scatter = kernels.centred_scatter(points, inliers)
    centred = points[inliers] - points[inliers].mean(axis=0)
    np.testing.assert_allclose(centroid, points[inliers].mean(axis=0), atol=1e-15)
    np.testing.assert_allclose(scatter, centred.T @ centred, rtol=1e-10, atol=1e-15)


def test_inside_lines_is_the_hull_mask_of_numpy():
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(8)
    for _ in range(5):
        pixels = rng.uniform([5, 3], [150, 110], size=(40, 2))  # (column, row)
        hull = ConvexHull(np.round(pixels))
        yy, xx = np.mgrid[0:120, 0:160]
        expected = np.ones((120, 160), dtype=bool)
        for a, b, c in hull.equations:
            expected &= a * xx + b * yy + c <= 0.5
        found = kernels.inside_lines(np.ascontiguousarray(hull.equations), 120, 160)
        assert found.shape == (120, 160) and 0 < found.sum() < found.size
        np.testing.assert_array_equal(found, expected)


def test_positions_in_sorted_is_searchsorted_where_found():
    rng = np.random.default_rng(9)
    values = np.flatnonzero(rng.random(5000) < 0.6)
    targets = np.flatnonzero(rng.random(5200) < 0.3)  # some beyond the last value
    position = np.minimum(np.searchsorted(values, targets), len(values) - 1)
    expected = position[values[position] == targets]
    np.testing.assert_array_equal(kernels.positions_in_sorted(values, targets), expected)
    assert len(kernels.positions_in_sorted(values[:0], targets)) == 0


def test_large_pieces_are_the_closed_mask_pieces_of_scipy():
    from scipy import ndimage

    rng = np.random.default_rng(10)
    eight = np.ones((3, 3), dtype=bool)
    for density in (0.05, 0.3, 0.6):
        mask = ndimage.binary_opening(rng.random((60, 80)) < density * 2, structure=eight)
        mask |= rng.random((60, 80)) < density / 4  # specks and one-pixel gaps
        mask[0, :5] = mask[-1, -5:] = True  # pieces on the border
        for share in (0.0, 0.3, 1.0):
            closed = mask | ndimage.binary_closing(mask, structure=eight)
            labels, count = ndimage.label(closed, structure=eight)
            sizes = np.bincount(labels[mask], minlength=count + 1)
            sizes[0] = 0
            expected = mask & np.isin(labels, np.flatnonzero(sizes >= share * sizes.max()))
            np.testing.assert_array_equal(kernels.large_pieces(mask, share), expected)


def test_hull_width_is_numpy_s_least_extent_across_the_faces():
    """The compiled thickness (early stop per face) against the numpy expression over every
    face and vertex, on random hulls from flat to round, turned at random."""
    from scipy.spatial import ConvexHull

    from ipr_shapes.products import ShapeHypothesis

    rng = np.random.default_rng(5)
    widths = []
    for _ in range(60):
        points = rng.normal(size=(rng.integers(8, 200), 3)) * rng.uniform(0.001, 0.05, 3)
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        points = points @ rotation.T + rng.uniform(-0.2, 0.2, 3)
        hull = ConvexHull(points)
        faces = hull.simplices.copy()
        tri = points[faces]
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        flip = np.einsum("ij,ij->i", normals, hull.equations[:, :3]) < 0
        faces[flip] = faces[flip][:, [0, 2, 1]]
        h = ShapeHypothesis(1, 0, points, faces, hull.volume, np.zeros(0), np.zeros((0, 3)))
        planes = h.face_planes()
        expected = -(points @ planes[:, :3].T + planes[:, 3]).min(axis=0).max()
        assert kernels.hull_width(points, faces.astype(np.int64)) == pytest.approx(
            expected, abs=1e-12
        )
        assert h.width_m == pytest.approx(expected, abs=1e-12)
        widths.append(expected)
    assert min(widths) < 0.004 < max(widths)  # thin and thick hulls both met
