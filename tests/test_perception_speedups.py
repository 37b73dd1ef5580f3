"""The faster perception routines give exactly what the straightforward versions gave.

Each reference below is the earlier implementation (kept here only to pin the results): the
speed-ups reorder work, reuse buffers and replace sorts and sparse graphs by tables and numpy
loops, but must not change a single bit of the output.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ipr_shapes.camera import look_at
from ipr_shapes.perception import supervoxels as supervoxels_module
from ipr_shapes.perception.config import PerceptionConfig, SupervoxelsConfig
from ipr_shapes.perception.facets import _components, mean_shift_directions, pixel_areas
from ipr_shapes.perception.robot import robot_pixels
from ipr_shapes.perception.supervoxels import _VoxelIndex, compute_supervoxels, organised_normals_at
from ipr_shapes.perception.tracking import (
    _colour_codes,
    _grouped_percentile,
    _shared_count,
    segment_features,
)
from ipr_shapes.scene import Frame, Push, Pusher

K = np.array([[300.0, 0.0, 79.5], [0.0, 300.0, 59.5], [0.0, 0.0, 1.0]])


def _frame(seed: int = 0, shape: tuple[int, int] = (120, 160)) -> Frame:
    """A noisy table (z = 0) with two boxes, seen obliquely; a few dropped depth readings."""
    height, width = shape
    world_from_camera = look_at(np.array([0.35, -0.45, 0.55]), np.zeros(3))
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(u.shape)], -1)
    rays = rays.reshape(-1, 3) @ world_from_camera[:3, :3].T
    origin = world_from_camera[:3, 3]
    depth = -origin[2] / rays[:, 2]
    for centre, half in (((0.0, 0.0, 0.04), (0.05, 0.03, 0.04)), ((0.1, 0.05, 0.03), (0.03,) * 3)):
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (np.subtract(centre, half) - origin) / rays
            t2 = (np.add(centre, half) - origin) / rays
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (near <= far) & (near > 0) & (near < depth)
        depth = np.where(hit, near, depth)
    rng = np.random.default_rng(seed)
    depth = depth + rng.normal(0.0, 0.001, depth.shape)
    depth[rng.random(depth.shape) < 0.02] = 0.0
    depth = np.where(depth > 0, depth, 0.0).reshape(height, width).astype(np.float32)
    rgb = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
    return Frame(0, rgb, depth, K, world_from_camera)


def _reference_normals(depth_m, K, pixels, config):
    """The earlier ``organised_normals_at`` (bounds masks and (P, 3) selects)."""
    depth = np.asarray(depth_m, dtype=np.float32)
    height, width = depth.shape
    pixels = np.asarray(pixels, dtype=np.int64)
    flat = depth.reshape(-1)
    rows, cols = pixels // width, pixels % width
    z = flat[pixels]
    fx, fy, cx, cy = (
        np.float32(K[0, 0]),
        np.float32(K[1, 1]),
        np.float32(K[0, 2]),
        np.float32(K[1, 2]),
    )

    def backproject_at(r, c, zz):
        return np.stack([(c - cx) / fx * zz, (r - cy) / fy * zz, zz], axis=1)

    centre = backproject_at(rows.astype(np.float32), cols.astype(np.float32), z)
    r = int(config.supervoxels.normal_radius_px)
    limit = (
        np.float32(config.supervoxels.normal_max_jump_m)
        + np.float32(config.supervoxels.normal_max_jump_ratio * r) * z
    )

    def neighbour(dv, du):
        nr, nc = rows + dv, cols + du
        inside = (nr >= 0) & (nr < height) & (nc >= 0) & (nc < width)
        index = np.where(inside, nr * width + nc, 0)
        nz = np.where(inside, flat[index], 0.0).astype(np.float32)
        ok = inside & (nz > 0) & (np.abs(nz - z) <= limit)
        points = backproject_at(nr.astype(np.float32), nc.astype(np.float32), nz)
        return np.where(ok[:, None], points, centre), ok

    right, ok_right = neighbour(0, r)
    left, ok_left = neighbour(0, -r)
    down, ok_down = neighbour(r, 0)
    up, ok_up = neighbour(-r, 0)
    normal = np.cross(down - up, right - left)
    norm = np.linalg.norm(normal, axis=1)
    good = (z > 0) & (ok_right | ok_left) & (ok_down | ok_up) & (norm > 1e-12)
    normal = np.where(good[:, None], normal / np.maximum(norm, 1e-12)[:, None], 0.0)
    flip = np.einsum("pc,pc->p", normal, centre) > 0
    normal[flip] *= -1.0
    return normal.astype(np.float32)


def test_organised_normals_are_bit_identical_to_the_reference():
    config = PerceptionConfig()
    for seed in range(3):
        frame = _frame(seed)
        pixels = np.arange(frame.depth_m.size)  # every pixel: borders, holes and edges too
        fast = organised_normals_at(frame.depth_m, frame.K, pixels, config)
        reference = _reference_normals(frame.depth_m, frame.K, pixels, config)
        assert fast.dtype == np.float32
        np.testing.assert_array_equal(fast, reference)


def test_components_number_like_scipy():
    rng = np.random.default_rng(0)
    for _ in range(200):
        count = int(rng.integers(1, 60))
        pairs = rng.integers(0, count, size=(int(rng.integers(0, 2 * count)), 2))
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), (count, count))
        _, expected = connected_components(graph, directed=False)
        np.testing.assert_array_equal(_components(pairs, count), expected)


def _reference_mean_shift(normals, weights, bandwidth, iterations=30):
    """The earlier ``mean_shift_directions``."""
    modes = normals.copy()
    for _ in range(iterations):
        squared = np.maximum(2.0 - 2.0 * (modes @ normals.T), 0.0)
        kernel = np.exp(-squared / (2 * bandwidth**2))
        kernel *= weights[None, :]
        shifted = kernel @ normals
        shifted /= np.linalg.norm(shifted, axis=1, keepdims=True) + 1e-12
        converged = np.abs(shifted - modes).max() < 1e-5
        modes = shifted
        if converged:
            break
    order = np.argsort(-weights, kind="stable")
    label = np.full(len(normals), -1, dtype=np.int64)
    count = 0
    for index in order:
        if label[index] >= 0:
            continue
        near = (np.linalg.norm(modes - modes[index], axis=1) < bandwidth / 2) & (label < 0)
        label[near] = count
        label[index] = count
        count += 1
    return label


def test_mean_shift_is_bit_identical_to_the_reference():
    rng = np.random.default_rng(1)
    for _ in range(50):
        count = int(rng.integers(1, 80))
        axes = np.eye(3)[rng.integers(0, 3, count)] + rng.normal(0.0, 0.15, (count, 3))
        normals = axes / np.linalg.norm(axes, axis=1, keepdims=True)
        weights = rng.integers(1, 200, count).astype(float)
        np.testing.assert_array_equal(
            mean_shift_directions(normals, weights, 0.35),
            _reference_mean_shift(normals, weights, 0.35),
        )


def test_pixel_areas_are_bit_identical_to_the_reference():
    rng = np.random.default_rng(2)
    points = rng.normal(0.0, 0.2, (5000, 3)) + [0.0, 0.0, 0.8]
    normals = rng.normal(size=(5000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    rays = points / np.linalg.norm(points, axis=1, keepdims=True)
    tilt = np.abs(rays[:, 2]) / np.maximum(np.abs(np.einsum("ij,ij->i", rays, normals)), 0.25)
    expected = points[:, 2] ** 2 / (K[0, 0] * K[1, 1]) * tilt
    np.testing.assert_array_equal(pixel_areas(points, normals, K), expected)


@pytest.mark.parametrize("n_cells", [50, 10**9])  # the dense table and the sorted keys
def test_voxel_index_matches_unique_and_lookup(n_cells):
    rng = np.random.default_rng(3)
    keys = rng.integers(0, 50, 400)
    index = _VoxelIndex(keys, n_cells)
    expected_keys, expected_inverse = np.unique(keys, return_inverse=True)
    np.testing.assert_array_equal(index.keys, expected_keys)
    np.testing.assert_array_equal(index.of_keys, expected_inverse)
    assert index.of_keys.dtype == np.int64
    found = index.find(np.arange(50))
    expected = np.full(50, -1)
    expected[expected_keys] = np.arange(len(expected_keys))
    np.testing.assert_array_equal(found, expected)


def test_supervoxels_are_the_same_with_and_without_dense_tables(monkeypatch):
    frame = _frame(4)
    points = frame.points_world()
    keep = (points[..., 2] > 0.01) & (frame.depth_m > 0)
    # A subsample: the pixel lookup too.
    config = PerceptionConfig(supervoxels=SupervoxelsConfig(max_points=3000))
    dense = compute_supervoxels(frame, keep, config, points_world=points)
    monkeypatch.setattr(supervoxels_module, "_DENSE_CELLS_MAX", 0)
    sorted_keys = compute_supervoxels(frame, keep, config, points_world=points)
    assert dense.count > 5
    for name in ("labels", "centres", "normals", "colours", "sizes", "adjacency"):
        np.testing.assert_array_equal(getattr(dense, name), getattr(sorted_keys, name))


def test_robot_pixels_are_the_points_inside_the_capsule():
    frame = _frame(5)
    pusher = Pusher(radius_m=0.01, length_m=0.1, axis=np.array([0.0, 0.0, 1.0]))
    # Where the pusher stands before the push that follows frame 0: on the front box's face.
    push = Push(0, 1, np.array([0.0, -0.035, 0.05]), np.array([0.0, 1.0, 0.0]), 0.05, 0.1)
    config = PerceptionConfig()
    mask = robot_pixels(frame, [push], pusher, config)
    # Reference: the exact capsule distance of every valid pixel.
    points = frame.points_world().reshape(-1, 3)
    half = pusher.length_m / 2.0 - pusher.radius_m
    a = np.array(push.start_m) - [0.0, 0.0, half]
    t = np.clip((points - a) @ [0.0, 0.0, 1.0], 0.0, 2.0 * half)
    distance = np.linalg.norm(points - a - t[:, None] * [0.0, 0.0, 1.0], axis=1)
    expected = (distance <= pusher.radius_m + config.robot.pusher_margin_m) & (
        frame.depth_m.reshape(-1) > 0
    )
    assert expected.any()
    np.testing.assert_array_equal(mask.reshape(-1), expected)


def _reference_segment_features(labels, points, rgb, depth_m):
    """The per-segment ``segment_features`` (np.mean and np.percentile on each segment)."""
    flat_labels, flat_points = labels.reshape(-1), points.reshape(-1, 3)
    depth = depth_m.reshape(-1).astype(np.float64)
    features = {}
    for label in np.unique(flat_labels[flat_labels > 0]).tolist():
        pixels = np.flatnonzero(flat_labels == label)
        histogram = np.bincount(_colour_codes(rgb.reshape(-1, 3)[pixels]), minlength=216)
        with_depth = depth[pixels] > 0
        points_k = flat_points[pixels[with_depth]] if with_depth.any() else flat_points[pixels]
        area = float((depth[pixels[with_depth]] ** 2).sum()) if with_depth.any() else 0.0
        features[label] = (
            pixels,
            points_k.mean(axis=0),
            histogram / histogram.sum(),
            float(np.percentile(points_k[:, 2], 98)),
            area if area > 0 else float(pixels.size),
        )
    return features


def test_segment_features_match_the_per_segment_reference():
    """Same bits but for the footprint area, which the compiled pass sums in raster order
    rather than numpy's pairwise order."""
    frame = _frame(6)
    points = frame.points_world()
    rng = np.random.default_rng(6)
    labels = rng.integers(0, 6, frame.shape).astype(np.int32)
    labels[:20] = 7  # a segment whose pixels all lack depth
    depth = frame.depth_m.copy()
    depth[:20] = 0.0
    points[:20] = 0.0
    expected = _reference_segment_features(labels, points, frame.rgb, depth)
    found = segment_features(labels, points, frame.rgb, depth)
    assert sorted(found) == sorted(expected) == [1, 2, 3, 4, 5, 7]
    for label, (pixels, centroid, histogram, top, area) in expected.items():
        np.testing.assert_array_equal(found[label].pixels, pixels)
        np.testing.assert_array_equal(found[label].centroid, centroid)
        np.testing.assert_array_equal(found[label].histogram, histogram)
        assert found[label].top_m == top
        assert found[label].area == pytest.approx(area, rel=1e-12, abs=0)


def test_grouped_percentile_is_numpys_percentile_of_each_run():
    rng = np.random.default_rng(7)
    for trial in range(100):
        counts = rng.integers(0, 40, int(rng.integers(1, 8)))
        counts[0] = rng.integers(1, 3000)
        values = rng.normal(0.0, 0.3, int(counts.sum()))
        if trial % 3 == 0:
            values = np.round(values, 2)  # ties
        found = _grouped_percentile(values, counts, 98.0)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        for index, (start, count) in enumerate(zip(starts, counts, strict=True)):
            if count == 0:
                assert np.isnan(found[index])
            else:
                assert found[index] == np.percentile(values[start : start + count], 98.0)


def test_shared_count_is_the_size_of_the_intersection():
    rng = np.random.default_rng(8)
    for _ in range(100):
        first = np.unique(rng.integers(0, 500, int(rng.integers(0, 300))))
        second = np.unique(rng.integers(0, 500, int(rng.integers(0, 300))))
        expected = np.intersect1d(first, second, assume_unique=True).size
        assert _shared_count(first, second) == _shared_count(second, first) == expected


def _reference_fill(labels, valid, max_distance_px):
    """Each pixel without depth takes the label of its nearest valid pixel within the distance
    (ties: first offset in row-major order), pixel by pixel."""
    from ipr_shapes.perception.segmentation import _offsets_by_distance

    result = labels.copy()
    height, width = labels.shape
    offsets = _offsets_by_distance(max_distance_px)
    for row, col in zip(*np.nonzero(~valid), strict=True):
        for d_row, d_col in offsets:
            r, c = row + d_row, col + d_col
            if 0 <= r < height and 0 <= c < width and valid[r, c]:
                result[row, col] = labels[r, c]
                break
    return result


@pytest.mark.parametrize("seed", range(4))
def test_fill_label_holes_matches_the_pixel_by_pixel_fill(seed):
    """Large holes far from every segment (skipped by the fast path), thin dropout bands between
    segments and the background, and a labelled pixel without depth."""
    from ipr_shapes.perception.segmentation import fill_label_holes

    rng = np.random.default_rng(seed)
    labels = np.zeros((60, 80), dtype=np.int32)
    labels[10:30, 10:35] = 1
    labels[25:50, 40:70] = 2
    valid = rng.random(labels.shape) > 0.3
    valid[:, 72:] = False  # a wide hole beside segment 2
    valid[:, 35:40] = False  # a dropout band along segment 1's edge, filled up to 3 px deep
    valid[52:, :] = False
    labels[~valid] = 0
    labels[5, 5] = 3  # a label on a pixel without depth, far from the others
    valid[5, 5] = False
    for distance in (1.5, 3.0):
        expected = _reference_fill(labels, valid, distance)
        assert (fill_label_holes(labels, valid, distance) == expected).all()
    assert (fill_label_holes(labels, valid, 3.0) > 0).sum() > (labels > 0).sum()


def test_frames_perceived_on_threads_are_those_perceived_one_by_one(scene_dir, monkeypatch):
    """The frames' partial objects and free-space maps made on two threads are the very
    ones made in order in one thread, in frame order, and the threads made them."""
    import pickle
    import threading

    import ipr_shapes.perception as perception
    from ipr_shapes.scene import load_scene

    scene = load_scene(scene_dir)
    alone = perception.perceive_scene(scene)
    names = []
    observe = perception.observe_space
    decompose = perception.partial_objects
    monkeypatch.setattr(perception, "observe_space",
                        lambda *a, **k: names.append(threading.current_thread().name)
                        or observe(*a, **k))  # fmt: skip
    monkeypatch.setattr(perception, "partial_objects",
                        lambda *a, **k: names.append(threading.current_thread().name)
                        or decompose(*a, **k))  # fmt: skip
    together = perception.perceive_scene(scene, workers=2)
    assert len(names) == 2 * len(scene.frames) >= 4
    assert all(name.startswith("ipr-perception") for name in names)
    for field in ("labels", "facet_labels", "objects", "planes"):
        assert pickle.dumps(getattr(together, field)) == pickle.dumps(getattr(alone, field))
    assert all(
        np.array_equal(a.state, b.state)
        for a, b in zip(together.free_space, alone.free_space, strict=True)
    )
    assert [m.state.any() for m in together.free_space] == [True] * len(scene.frames)


def _observe_space_reference(depth_m, K, world_from_camera, grid, surface_margin_m, ignore_mask):
    """``observe_space`` as numpy computed it before the compiled pass (the reference)."""
    from scipy.ndimage import minimum_filter

    from ipr_shapes.camera import invert_transform
    from ipr_shapes.perception.free_space import (
        FOOTPRINT_WINDOWS,
        FREE,
        HOLE_FILL_WINDOW,
        OCCUPIED,
        UNKNOWN,
    )  # fmt: skip

    height, width = depth_m.shape
    depth = np.where(depth_m > 0, depth_m, 0.0).astype(np.float32)
    depth = np.where(ignore_mask, 0.0, depth)
    camera_from_world = invert_transform(world_from_camera)
    rotation = camera_from_world[:3, :3]
    axes = [
        grid.origin[i] + (np.arange(n) + 0.5) * grid.voxel_size_m for i, n in enumerate(grid.shape)
    ]
    terms = [np.outer(axis, rotation[:, i]).astype(np.float32) for i, axis in enumerate(axes)]
    camera = (
        terms[0][:, None, None, :]
        + terms[1][None, :, None, :]
        + (terms[2] + camera_from_world[:3, 3].astype(np.float32))[None, None, :, :]
    ).reshape(-1, 3)
    z = camera[:, 2]
    in_front = z > 1e-3
    safe_z = np.where(in_front, z, 1.0)
    u = np.round(K[0, 0] * camera[:, 0] / safe_z + K[0, 2]).astype(np.int64)
    v = np.round(K[1, 1] * camera[:, 1] / safe_z + K[1, 2]).astype(np.int64)
    in_image = in_front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    valid_depth = np.where(depth > 0, depth, np.inf).astype(np.float32)
    nearby = minimum_filter(valid_depth, size=HOLE_FILL_WINDOW, mode="nearest")
    valid_depth = np.where(depth > 0, valid_depth, nearby)
    index = np.flatnonzero(in_image)
    zi = z[index]
    footprint_px = np.ceil(K[0, 0] * grid.voxel_size_m / np.maximum(zi, 0.05))
    windows = np.array(FOOTPRINT_WINDOWS)
    level = np.minimum(np.searchsorted(windows, footprint_px), len(windows) - 1)
    ui, vi = u[index], v[index]
    observed_near = np.empty(len(index), dtype=np.float32)
    for number, window in enumerate(windows):
        chosen = level == number
        if chosen.any():
            nearest = (
                valid_depth
                if window == 1
                else minimum_filter(valid_depth, size=int(window), mode="nearest")
            )
            observed_near[chosen] = nearest[vi[chosen], ui[chosen]]
    observed = depth[vi, ui]
    state = np.full(len(z), UNKNOWN, dtype=np.uint8)
    free = np.isfinite(observed_near) & (zi < observed_near - surface_margin_m)
    occupied = ~free & (observed > 0) & (np.abs(zi - observed) <= surface_margin_m)
    state[index[free]] = FREE
    state[index[occupied]] = OCCUPIED
    return state.reshape(grid.shape)


@pytest.mark.parametrize("predicted", [True, False])
def test_free_space_is_bit_identical_to_the_numpy_reference(scene_dir, monkeypatch, predicted):
    """The compiled per-voxel pass gives numpy's states voxel for voxel (float32 sums and
    comparisons, float64 projection, rounding ties to even), for a grid reaching behind and
    beside the camera, with holes and a masked region; also when no min-filter window is
    predicted and each one is added as the pass asks for it."""
    import ipr_shapes.perception.free_space as free_space
    from ipr_shapes.perception.free_space import VoxelGrid, observe_space
    from ipr_shapes.scene import load_scene

    if not predicted:
        monkeypatch.setattr(
            free_space, "_windows_between", lambda *a: np.zeros(len(a[3]), dtype=bool)
        )
    frames = load_scene(scene_dir).frames
    rng = np.random.default_rng(5)
    for frame in frames:
        depth = frame.depth_m.copy()
        depth[rng.random(depth.shape) < 0.05] = 0.0  # holes
        ignore = np.zeros(depth.shape, dtype=bool)
        ignore[10:40, 20:60] = True
        centre = frame.world_from_camera[:3, 3]
        # From well behind the camera to past the table: voxels behind, beside and in view.
        grid = VoxelGrid.around(centre - 0.6, centre + 0.6, 0.01)
        for margin in (0.01, 0.004):
            got = observe_space(
                depth, frame.K, frame.world_from_camera, grid,
                surface_margin_m=margin, ignore_mask=ignore,
            ).state  # fmt: skip
            expected = _observe_space_reference(
                depth, frame.K, frame.world_from_camera, grid, margin, ignore
            )
            assert np.array_equal(got, expected)
            assert (expected == 1).sum() > 1000 and (expected == 2).sum() > 20
            assert (expected == 0).sum() > 100
