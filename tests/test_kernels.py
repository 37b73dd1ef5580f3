"""Each compiled perception kernel (``ipr_shapes.perception.kernels``) gives what the numpy expression it
replaced gave (the geometry kernels: ``test_geometry_kernels.py``).

The references below are the earlier numpy implementations, kept here only to pin the results:
same bits where the kernel keeps numpy's order of operations, equal to rounding otherwise
(stated per test).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import uniform_filter

from ipr_shapes.camera import backproject_pixels, look_at
from ipr_shapes.geometry import kernels as geometry_kernels
from ipr_shapes.perception import kernels
from ipr_shapes.perception.denoise import objects_plane_depth
from ipr_shapes.perception.facets import pixel_areas


def _normalise(vectors: np.ndarray) -> np.ndarray:
    norms = np.linalg.norm(vectors, axis=1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 1e-12)


def _group_sum(groups: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    return np.stack(
        [np.bincount(groups, weights=values[:, c], minlength=count) for c in range(3)], axis=1
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


# The numpy plane-fit depth before the kernel: float32 box filters, Cramer's rule at the rim.
def _reference_plane_depth(depth_m: np.ndarray, pixels: np.ndarray, window: int) -> np.ndarray:
    """(N,) float64 depth (m) at one object's (N,) flat pixel indices (all with a reading) of a
    (H, W) depth image, each replaced by the object's local plane fit there (module doc); a
    pixel whose neighbourhood holds fewer than 6 of the object's pixels, or only a line of
    them, keeps its reading. ``window`` is the odd neighbourhood size (< 3: no change)."""
    if window >= 3 and window % 2 == 0:
        raise ValueError(f"the denoising window must be odd, got {window}")
    height, width = depth_m.shape
    readings = depth_m.reshape(-1)[pixels].astype(np.float64)
    if window < 3 or pixels.size < 6:
        return readings
    margin = window // 2
    rows, cols = np.divmod(pixels, width)
    top, left = int(rows.min()), int(cols.min())
    # The object's bounding box padded by the margin on every side (so windows stay inside).
    shape = (int(rows.max()) - top + 1 + 2 * margin, int(cols.max()) - left + 1 + 2 * margin)
    at = (rows - top + margin) * shape[1] + (cols - left + margin)
    mask = np.zeros(shape[0] * shape[1], dtype=np.float32)
    mask[at] = 1.0
    reference = float(readings.mean())  # centred depth keeps float32 sums exact enough
    depth = np.zeros_like(mask)
    depth[at] = readings - reference
    area = window * window
    count = uniform_filter(mask.reshape(shape), window, mode="constant").reshape(-1)[at] * area
    result = readings.copy()
    # A full window is symmetric about its pixel, so the plane's value there is the mean.
    full = count > area - 0.5
    if full.any():
        mean = uniform_filter(depth.reshape(shape), window, mode="constant").reshape(-1)
        result[full] = mean[at[full]] + reference
    rim = np.flatnonzero(~full & (count > 5.5))
    if rim.size:
        fitted, ok = _rim_plane_fit(depth, mask, at[rim], shape[1], margin)
        result[rim[ok]] = fitted[ok] + reference
    return result


def _rim_plane_fit(
    depth: np.ndarray, mask: np.ndarray, at: np.ndarray, width: int, margin: int
) -> tuple[np.ndarray, np.ndarray]:
    """The local plane's depth at (N,) flat pixels ``at`` of a padded crop ((h*w,) float32
    centred depth and 0/1 mask, ``width`` wide) whose windows are partly outside the object,
    and whether it is defined ((N,) float64 and bool): least squares on the window's pixels
    of the object, in coordinates about each pixel."""
    du, dv = _window_offsets(margin)
    neighbours = at[:, None] + (dv * width + du).astype(np.int64)[None, :]
    weights = mask[neighbours].astype(np.float64)
    values = depth[neighbours].astype(np.float64)
    s, cu, cv = weights.sum(axis=1), weights @ du, weights @ dv
    cuu, cvv, cuv = weights @ (du * du), weights @ (dv * dv), weights @ (du * dv)
    sd, cdu, cdv = values.sum(axis=1), values @ du, values @ dv
    # Cramer's rule for [[s, cu, cv], [cu, cuu, cuv], [cv, cuv, cvv]] x = [sd, cdu, cdv].
    minor = cuu * cvv - cuv * cuv
    det = s * minor - cu * (cu * cvv - cuv * cv) + cv * (cu * cuv - cuu * cv)
    numerator = sd * minor - cu * (cdu * cvv - cuv * cdv) + cv * (cdu * cuv - cuu * cdv)
    ok = np.abs(det) > 1e-6 * np.maximum(s, 1.0) ** 3  # not all on one line
    return numerator / np.where(ok, det, 1.0), ok


def _window_offsets(margin: int) -> tuple[np.ndarray, np.ndarray]:
    """Column and row offsets (w*w,) float64 (read-only) of a window of half-size ``margin``,
    row-major (built once: ``np.mgrid`` costs more than the fits of a small object)."""
    dv, du = np.mgrid[-margin : margin + 1, -margin : margin + 1]
    du, dv = du.reshape(-1).astype(np.float64), dv.reshape(-1).astype(np.float64)
    du.flags.writeable = dv.flags.writeable = False
    return du, dv


@pytest.mark.parametrize("window", [3, 5, 7])
def test_objects_plane_depth_matches_the_box_filter_version(window):
    rng = np.random.default_rng(window)
    v, u = np.mgrid[:70, :90].astype(float)
    labels = np.zeros((70, 90), int)
    labels[5:40, 3:50] = 1
    labels[30:66, 45:85] = 2
    labels[50:52, 5:40] = 3  # a two-pixel-high strip: rim fits on nearly a line
    labels[60, 10:14] = 4  # fewer than 6 pixels: unchanged
    labels[rng.random(labels.shape) < 0.05] = 0
    depth = (0.8 + 0.002 * u - 0.001 * v + rng.normal(0, 0.002, u.shape)).astype(np.float32)
    depth[labels == 0] = 0.0
    flat = labels.reshape(-1)
    objects = [np.flatnonzero(flat == k) for k in (1, 2, 3, 4)]
    starts = np.cumsum([0] + [len(o) for o in objects])
    got = objects_plane_depth(depth, np.concatenate(objects), starts, window)
    expected = np.concatenate([_reference_plane_depth(depth, o, window) for o in objects])
    # float64 window sums against float32 box filters of centred depth: sub-micrometre.
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-7)
    changed = got != depth.reshape(-1)[np.concatenate(objects)]
    assert changed[: starts[1]].mean() > 0.9 and not changed[starts[3] :].any()


def test_object_pixel_geometry_matches_backprojection_and_pixel_areas():
    rng = np.random.default_rng(5)
    K = np.array([[520.0, 0.0, 40.3], [0.0, 525.0, 29.7], [0.0, 0.0, 1.0]])
    world_from_camera = look_at(np.array([0.5, -0.6, 0.8]), np.zeros(3))
    width = 80
    pixels = rng.choice(60 * width, 900, replace=False)
    depth = rng.uniform(0.4, 1.5, 900).astype(np.float32)
    supervoxel_normals = rng.normal(size=(40, 3))
    supervoxel_normals /= np.linalg.norm(supervoxel_normals, axis=1, keepdims=True)
    point_supervoxel = rng.integers(-1, 40, 900)  # -1: no supervoxel, facing the camera
    normals = np.where(
        (point_supervoxel >= 0)[:, None],
        supervoxel_normals[point_supervoxel],
        -world_from_camera[:3, 2],
    )
    world, areas = kernels.object_pixel_geometry(
        pixels, depth, width, K, world_from_camera, point_supervoxel, supervoxel_normals
    )
    camera = backproject_pixels(pixels, depth, K, width)
    expected_world = camera @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
    expected_areas = pixel_areas(camera, normals @ world_from_camera[:3, :3], K)
    np.testing.assert_allclose(world, expected_world, rtol=0, atol=1e-14)
    np.testing.assert_allclose(areas, expected_areas, rtol=1e-12)
    assert areas.min() > 0 and (areas > expected_areas.min() * 1.5).any()  # tilt matters


def _reference_dominant_faces(groups, points, pixel_normals, mean_normals, gate):
    """The numpy ``_dominant_faces`` before the kernel: centres and covariances."""
    count = len(mean_normals)
    normal = mean_normals
    inlier_groups = groups
    for _ in range(2):
        inlier = np.einsum("pc,pc->p", pixel_normals, normal[groups]) > gate
        inlier_groups = groups[inlier]
        summed = _group_sum(inlier_groups, pixel_normals[inlier], count)
        normal = np.where(
            (np.linalg.norm(summed, axis=1) > 1e-12)[:, None], _normalise(summed), normal
        )
    clear = np.bincount(inlier_groups, minlength=count) >= 6
    inlier = np.where(clear[groups], inlier, True)
    used_groups, used_points = groups[inlier], points[inlier]
    sizes = np.bincount(used_groups, minlength=count)
    centres = _group_sum(used_groups, used_points, count) / np.maximum(sizes, 1)[:, None]
    local = [used_points[:, axis] - centres[used_groups, axis] for axis in range(3)]
    covariance = np.empty((count, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            value = np.bincount(used_groups, weights=local[i] * local[j], minlength=count)
            covariance[:, i, j] = covariance[:, j, i] = value
    covariance /= np.maximum(sizes, 1)[:, None, None]
    return centres, covariance, sizes, normal


def test_dominant_face_moments_are_bit_identical_to_the_numpy_version():
    rng = np.random.default_rng(8)
    n_groups, n_points = 60, 6000
    groups = rng.integers(0, n_groups, n_points)
    groups[groups == 7] = 8  # an empty group
    groups[:4] = 9  # a tiny one (fewer than 6 kept pixels: all are used)
    groups[groups == 9] = 10
    groups[:4] = 9
    points = rng.normal(size=(n_points, 3)) * 0.02
    # Two faces per group: most normals near +z, a third near +x (the crease's other side).
    pixel_normals = np.where(rng.random((n_points, 1)) < 0.66, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    pixel_normals = _normalise(pixel_normals + rng.normal(0, 0.15, (n_points, 3)))
    mean_normals = _normalise(_group_sum(groups, pixel_normals, n_groups))
    gate = float(np.cos(np.radians(30.0)))
    got = kernels.dominant_face_moments(groups, points, pixel_normals, mean_normals, gate)
    expected = _reference_dominant_faces(groups, points, pixel_normals, mean_normals, gate)
    for found, wanted in zip(got, expected, strict=True):
        np.testing.assert_array_equal(found, wanted)
    assert got[2][7] == 0 and got[2][9] == 4  # the empty and the tiny group
    assert 0.5 < got[2][20] / (groups == 20).sum() < 0.8  # the dominant face only


def _reference_borders(labels, points, depth_m, valid, gap_m, low, high):
    """The numpy ``containers._borders`` before the kernel (dictionaries in insertion order)."""
    contacts, fronts = {}, {}
    base = int(labels.max()) + 1

    def count(counts, first, second):
        keys, numbers = np.unique(first * base + second, return_counts=True)
        for key, n in zip(keys.tolist(), numbers.tolist(), strict=True):
            pair = divmod(key, base)
            counts[pair] = counts.get(pair, 0) + n

    labels = np.where(valid, labels, 0)
    for first, second in (
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
    ):
        a, b = labels[first], labels[second]
        border = np.nonzero((a != b) & (a > 0) & (b > 0))
        a, b = a[border].astype(np.int64), b[border].astype(np.int64)
        gap = np.linalg.norm(points[first][border] - points[second][border], axis=1)
        step = depth_m[second][border] - depth_m[first][border]
        near = gap < gap_m
        count(contacts, np.minimum(a[near], b[near]), np.maximum(a[near], b[near]))
        ahead = (np.abs(step) > low) & (np.abs(step) < high)
        count(fronts, np.where(step > 0, a, b)[ahead], np.where(step > 0, b, a)[ahead])
    return contacts, fronts


def test_container_borders_match_the_numpy_version_in_order():
    from ipr_shapes.perception.config import PerceptionConfig
    from ipr_shapes.perception.containers import _borders

    rng = np.random.default_rng(12)
    labels = np.zeros((60, 80), dtype=np.int32)
    labels[5:50, 5:40] = 3
    labels[20:35, 15:30] = 1  # inside 3
    labels[10:55, 40:75] = 2  # beside 3
    labels[rng.random(labels.shape) < 0.02] = 0
    depth = rng.uniform(0.7, 0.75, labels.shape).astype(np.float32)
    depth[labels == 1] += 0.03  # behind its surround: a front step
    valid = rng.random(labels.shape) > 0.03
    world_from_camera = look_at(np.array([0.2, -0.5, 0.6]), np.zeros(3))
    K = np.array([[300.0, 0.0, 40.0], [0.0, 300.0, 30.0], [0.0, 0.0, 1.0]])
    points = geometry_kernels.world_points(depth, K, world_from_camera)
    config = PerceptionConfig()
    low, high = config.containers.front_step_m
    contacts, fronts = _borders(labels, points, depth, valid, config)
    expected = _reference_borders(
        labels, points, depth, valid, config.containers.contact_gap_m, low, high
    )
    assert list(contacts.items()) == list(expected[0].items())
    assert list(fronts.items()) == list(expected[1].items())
    assert contacts and fronts  # both kinds occur


@pytest.mark.parametrize("previous_dtype", [np.float32, np.float64])
def test_pixel_changes_match_the_numpy_comparison(previous_dtype):
    rng = np.random.default_rng(21)
    size = 5000
    valid = np.sort(rng.choice(size, 3000, replace=False))
    z = rng.uniform(0.5, 1.5, valid.size).astype(np.float32)
    previous_depth = (rng.uniform(0.5, 1.5, size) * (rng.random(size) > 0.1)).astype(previous_dtype)
    pixel = rng.integers(0, size, valid.size)
    pixel[:1000] = valid[:1000]  # many land on their own spot: small differences
    previous_depth[pixel[:1000]] = z[:1000] + rng.normal(0, 0.004, 1000)
    inside = rng.random(valid.size) > 0.05
    previous_labels = rng.integers(0, 6, size).astype(np.int32)
    tolerance, quadratic, near_m = 0.005, 0.003, 0.01
    # The numpy expressions of compare_frames before the kernel.
    before = previous_depth[pixel]
    compared = inside & (before > 0)
    limit = tolerance + quadratic * z**2
    difference = z - before
    expected_state = np.full(valid.size, 1, dtype=np.int8)
    expected_state[difference > limit] = 2
    expected_state[difference < -limit] = 3
    expected_state[~compared] = 0
    state, label, near = kernels.pixel_changes(
        size,
        valid,
        pixel,
        z,
        inside,
        previous_depth,
        previous_labels,
        np.float32(tolerance),
        np.float32(quadratic),
        difference.dtype.type(near_m),
        (1, 2, 3, 0),
    )
    np.testing.assert_array_equal(state[valid], expected_state)
    np.testing.assert_array_equal(label[valid], np.where(compared, previous_labels[pixel], 0))
    np.testing.assert_array_equal(near[valid], compared & (np.abs(difference) <= near_m))
    assert len(np.unique(expected_state)) == 4  # every state occurs


def test_grouped_order_statistic_is_the_lexsort_pick():
    rng = np.random.default_rng(4)
    groups = rng.integers(3, 40, 4000).astype(np.int32)
    groups[groups == 11] = 12  # a missing id
    values = rng.normal(size=4000).round(2)  # ties
    order = np.lexsort((values, groups))
    ids, starts, counts = np.unique(groups[order], return_index=True, return_counts=True)
    expected = values[order][starts + np.floor(0.9 * (counts - 1)).astype(np.int64)]
    found_ids, found = kernels.grouped_order_statistic(groups, values, 0.9)
    np.testing.assert_array_equal(found_ids, ids)
    np.testing.assert_array_equal(found, expected)


def test_lloyd_iterations_match_the_numpy_iterations():
    rng = np.random.default_rng(9)
    blobs = rng.normal(size=(5, 4)) * 3
    points = np.concatenate([blob + rng.normal(0, 0.6, (80, 4)) for blob in blobs])
    start = points[rng.choice(len(points), 5, replace=False)].copy()
    # The numpy iterations of kmeans_labels before the kernel.
    centres = start.copy()
    squared = np.einsum("ij,ij->i", points, points)
    labels = np.full(len(points), -1)
    for _ in range(100):
        distances = squared[:, None] - 2.0 * points @ centres.T + np.sum(centres**2, axis=1)
        new_labels = np.argmin(distances, axis=1)
        if np.array_equal(new_labels, labels):
            break
        labels = new_labels
        for c in range(5):
            if (labels == c).any():
                centres[c] = points[labels == c].mean(axis=0)
    inertia = float(np.maximum(distances[np.arange(len(points)), labels], 0.0).sum())
    found_centres = start.copy()
    found, found_inertia = kernels.lloyd_iterations(points, found_centres, 100)
    np.testing.assert_array_equal(found, labels)
    assert found_inertia == pytest.approx(inertia, rel=1e-9)
    np.testing.assert_allclose(found_centres, centres, rtol=1e-12)
    assert len(np.unique(found)) == 5


def test_pairwise_sum_is_numpy_s_sum_bit_for_bit():
    # numpy sums contiguous float64 pairwise (8 accumulators, halves above 128 values): the
    # kernel's sum must be numpy's to the bit, for every count around the block sizes.
    rng = np.random.default_rng(23)
    for count in [*range(0, 40), 127, 128, 129, 255, 256, 257, 655, 1031]:
        values = rng.standard_normal(count) * 10.0 ** rng.uniform(-6, 6, count)
        assert kernels._pairwise_sum(values, 0, count) == values.sum()
        start = count // 3
        assert kernels._pairwise_sum(values, start, count - start) == values[start:].sum()
        for width in (7, 13, 21):  # numpy's row sums (axis 1), as the seeding takes them
            rows = values[: count - count % width].reshape(-1, width)
            for row, expected in zip(rows, np.sum(rows, axis=1), strict=True):
                assert 0.0 + kernels._pairwise_sum(row, 0, width) == expected


@pytest.mark.parametrize("k", [2, 5, 9, 17])
def test_kmeans_plus_plus_kernel_is_the_numpy_seeding(k):
    # The compiled seeding must place the centres numpy's draws place: the same first index
    # and one uniform per further centre, the same squared distances, cumulative shares and
    # search. Embeddings like the spectral ones (unit rows, up to 21 columns) and plain data.
    from ipr_shapes.perception.segmentation import kmeans_plus_plus

    rng = np.random.default_rng(k)
    for m, d in ((k + 1, k), (60, k), (300, k), (655, 21)):
        points = rng.standard_normal((m, d)) ** 3
        if d == k:
            points /= np.linalg.norm(points, axis=1, keepdims=True)
        for seed in range(3):
            expected = kmeans_plus_plus(points, k, np.random.default_rng(seed))
            draws = np.random.default_rng(seed)
            first = draws.integers(m)
            found, placed = kernels.kmeans_plus_plus(points, int(first), draws.random(k - 1))
            assert placed == k
            np.testing.assert_array_equal(found, expected)


def test_kmeans_labels_with_all_points_on_one_centre_redo_the_numpy_draws():
    # Three distinct points for k = 5: the distances sum to 0 before the last centres, where
    # numpy draws an index, not a uniform; the compiled seeding stops and the restart is
    # redone in numpy from the same generator state, so the labels stay numpy's.
    from ipr_shapes.perception.segmentation import kmeans_labels, kmeans_plus_plus

    points = np.repeat(np.eye(3), [4, 3, 2], axis=0)
    found, placed = kernels.kmeans_plus_plus(points, 0, np.full(4, 0.5))
    assert placed == 3
    # A draw exactly on a cumulative share takes the next point (searchsorted side="right").
    line = np.array([[0.0], [1.0], [-1.0], [1.0], [-1.0]])
    shares = np.cumsum(np.sum((line - line[0]) ** 2, axis=1) / 4.0)
    assert shares[2] == 0.5 and int(shares.searchsorted(0.5, side="right")) == 3
    found, placed = kernels.kmeans_plus_plus(line, 0, np.array([0.5]))
    assert placed == 2 and found[1, 0] == 1.0
    rng = np.random.default_rng(7)
    expected_labels, best = None, np.inf
    for _ in range(3):
        centres = kmeans_plus_plus(points, 5, rng)
        labels, inertia = kernels.lloyd_iterations(points, centres, 100)
        if inertia < best:
            expected_labels, best = labels, inertia
    np.testing.assert_array_equal(kmeans_labels(points, 5, restarts=3, seed=7), expected_labels)


def test_supervoxel_anchor_counts_match_the_numpy_counts():
    rng = np.random.default_rng(17)
    size, count, n_labels = 6000, 50, 7
    flat_supervoxel = rng.integers(-1, count, size)
    state = rng.integers(0, 4, size).astype(np.int8)  # 0 not compared, 1 unchanged, 2, 3
    label = rng.integers(0, n_labels, size)
    label[(label == 5) & (state == 1)] = 6  # segment 5 keeps few unchanged pixels: it moved
    near = rng.random(size) < 0.5
    min_pixels, fraction = 40, 0.3
    got = kernels.supervoxel_anchor_counts(
        flat_supervoxel, state, label, near, count, n_labels, (0, 1, 2, 3), min_pixels, fraction
    )
    # The numpy expressions of supervoxel_anchors before the kernel.
    unchanged_per_label = np.bincount(label[state == 1], minlength=n_labels)
    compared_per_label = np.bincount(label[state != 0], minlength=n_labels)
    stayed = (unchanged_per_label >= min_pixels) & (
        unchanged_per_label >= fraction * compared_per_label
    )
    stayed[0] = False
    member = flat_supervoxel >= 0
    sv, pixel_state, pixel_label = flat_supervoxel[member], state[member], label[member]
    is_unchanged = pixel_state == 1
    label_stayed = stayed[pixel_label] | (pixel_label == 0)
    shifted = (pixel_state == 3) & near[member] & stayed[pixel_label]
    compatible = np.bincount(
        sv[(pixel_state == 2) | (is_unchanged & label_stayed) | shifted], minlength=count
    )
    incompatible = np.bincount(
        sv[((pixel_state == 3) & ~shifted) | (is_unchanged & ~label_stayed)], minlength=count
    )
    kept = is_unchanged & stayed[pixel_label]
    table = np.bincount(
        sv[kept] * n_labels + pixel_label[kept], minlength=count * n_labels
    ).reshape(count, n_labels)
    for found, wanted in zip(
        got, (compatible, incompatible, table, np.bincount(sv, minlength=count)), strict=True
    ):
        np.testing.assert_array_equal(found, wanted)
    assert stayed[1:5].all() and not stayed[5]


@pytest.mark.parametrize("use_normals", [True, False])
def test_wall_slab_kernels_match_the_numpy_masks(use_normals):
    rng = np.random.default_rng(13)
    points = rng.uniform(-0.3, 0.3, (3000, 3))
    points[:800, 0] = rng.normal(0.1, 0.004, 800)  # a wall's face at x = 0.1
    normals = rng.normal(size=(3000, 3))
    normals[:600] = [1.0, 0.0, 0.0]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    unknown = rng.random(3000) < 0.1
    normals[unknown] = 0.0
    heights = points[:, 2] + 0.3
    normal, offset, along = np.array([1.0, 0.0, 0.0]), -0.1, np.array([0.0, 1.0, 0.0])
    min_cos = float(np.cos(np.radians(30.0)))
    facing = (np.abs(normals @ normal) > min_cos) | unknown
    depth, position, on_plane = kernels.vertical_plane_coordinates(
        points, normals, unknown, heights, normal, offset, along, 0.01, 0.5, min_cos, use_normals
    )
    expected = (np.abs(points @ normal + offset) < 0.01) & (heights < 0.5)
    if use_normals:
        expected &= facing
    np.testing.assert_allclose(depth, points @ normal + offset, atol=1e-15)
    np.testing.assert_allclose(position, points @ along, atol=1e-15)
    np.testing.assert_array_equal(on_plane, expected)
    pool = np.flatnonzero(rng.random(3000) < 0.7)
    kept = kernels.outside_slab(
        points, normals, unknown, pool, normal, offset, 0.02, 0.05, min_cos, use_normals
    )
    slab_depth = points[pool] @ normal + offset
    done = (slab_depth < 0.02) & (slab_depth > -0.05)
    if use_normals:
        done &= facing[pool]
    np.testing.assert_array_equal(kept, pool[~done])
    assert 0 < on_plane.sum() < 800 and len(kept) < len(pool)


@pytest.mark.parametrize("use_normals", [True, False])
def test_wall_rim_cap_and_side_kernels_match_the_numpy_masks(use_normals):
    rng = np.random.default_rng(31)
    count = 4000
    depth = rng.uniform(-0.2, 0.2, count)
    position = rng.uniform(-0.3, 0.5, count)
    heights = rng.uniform(0.0, 0.3, count)
    normals_up = rng.uniform(-1.0, 1.0, count)
    # Values exactly on the bounds, the other tests passed: the comparisons' strictness must
    # be numpy's.
    depth[:20], position[:20], heights[:20], normals_up[:20] = 0.01, 0.1, 0.1, 0.99
    depth[20:40], position[20:40], heights[20:40], normals_up[20:40] = 0.0, 0.0, 0.1, 0.99
    depth[40:60], position[40:60], heights[40:60], normals_up[40:60] = -0.05, 0.1, 0.075, 0.99
    up_cos = float(np.cos(np.radians(30.0)))
    s_lo, s_hi, top = 0.0, 0.3, 0.09
    heights[40:60] = top - 0.015
    rim = kernels.wall_rim_points(
        depth, position, heights, normals_up, 0.01, -0.03, s_lo, s_hi, up_cos, 0.04
    )
    expected_rim = (
        (depth < 0.01)
        & (depth > -0.03)
        & (position >= s_lo)
        & (position <= s_hi)
        & (normals_up > up_cos)
        & (heights > 0.04)
    )
    np.testing.assert_array_equal(rim, np.flatnonzero(expected_rim))
    behind, near, in_front = kernels.wall_behind_and_near(
        depth,
        position,
        heights,
        normals_up,
        use_normals,
        0.01,
        -0.03,
        -0.15,
        top - 0.015,
        top + 0.03,
        up_cos,
        s_lo,
        s_hi,
        0.1,
        0.05,
    )
    expected_behind = (
        (depth < -0.03)
        & (depth > -0.15)
        & (heights > top - 0.015)
        & (heights < top + 0.03)
        & (position >= s_lo)
        & (position <= s_hi)
    )
    if use_normals:
        expected_behind &= normals_up > up_cos
    np.testing.assert_array_equal(behind, np.flatnonzero(expected_behind))
    slab = (depth < 0.01) & (depth > -0.03)
    expected_near = (
        ~slab & (np.abs(depth) < 0.1) & (position > s_lo - 0.05) & (position < s_hi + 0.05)
    )
    assert near == expected_near.sum() and in_front == (depth[expected_near] > 0).sum()
    assert 0 < len(rim) < count and 0 < len(behind) < count and 0 < in_front < near


def test_projection_to_the_previous_camera_is_bit_identical_to_numpy():
    rng = np.random.default_rng(23)
    height, width = 48, 64
    depth = rng.uniform(0.4, 1.6, (height, width)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = 0.0
    valid = np.flatnonzero(depth.reshape(-1) > 0)
    K = np.array([[60.0, 0.0, 31.5], [0.0, 62.0, 23.5], [0.0, 0.0, 1.0]])
    now = look_at(np.array([0.5, -0.5, 0.7]), np.zeros(3))
    before = look_at(np.array([0.56, -0.45, 0.72]), np.array([0.02, 0.0, 0.0]))
    relative = (np.linalg.inv(before) @ now).astype(np.float32)
    f32 = np.float32
    ray_x = (np.arange(width, dtype=f32) - f32(K[0, 2])) * f32(1.0 / K[0, 0])
    ray_y = (np.arange(height, dtype=f32) - f32(K[1, 2])) * f32(1.0 / K[1, 1])
    # The numpy expressions of compare_frames before the kernel.
    x_now, y_now = ray_x[None, :] * depth, ray_y[:, None] * depth
    x, y, z = (
        (relative[i, 0] * x_now + relative[i, 1] * y_now + relative[i, 2] * depth
         + relative[i, 3]).reshape(-1)[valid]
        for i in range(3)
    )  # fmt: skip
    in_front = z > 1e-6
    inverse_z = f32(1.0) / np.where(in_front, z, f32(1.0))
    u = np.rint(x * inverse_z * f32(K[0, 0]) + f32(K[0, 2]))
    v = np.rint(y * inverse_z * f32(K[1, 1]) + f32(K[1, 2]))
    inside = in_front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    pixel = np.where(inside, v.astype(np.int64) * width + u.astype(np.int64), 0)
    got = kernels.project_to_previous(
        depth, valid, ray_x, ray_y, relative, K.astype(f32), height, width
    )
    for found, wanted in zip(got, (pixel, z, inside), strict=True):
        np.testing.assert_array_equal(found, wanted)
    assert 0 < inside.mean() < 1  # some land outside the previous image


def test_facing_plane_and_row_kernels_match_the_numpy_expressions():
    # The data of ``test_geometry_kernels.test_plane_kernels_match_the_numpy_expressions``
    # (same seed, same draws), then the normals and the subset of the perception kernels.
    rng = np.random.default_rng(31)
    points = rng.uniform(-0.5, 0.5, (4000, 3))
    points[:1500, 2] = rng.normal(0.0, 0.003, 1500)  # a table at z = 0
    normals = rng.normal(size=(300, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[0] = [0.0, 0.0, 1.0]
    offsets = rng.uniform(-0.1, 0.1, 300)
    offsets[0] = 0.0
    distances = np.abs(points @ normals.T + offsets)
    point_normals = rng.normal(size=(4000, 3))
    point_normals /= np.linalg.norm(point_normals, axis=1, keepdims=True)
    unknown = rng.random(4000) < 0.1
    facing = (np.abs(point_normals @ normals.T) > 0.8) | unknown[:, None]
    np.testing.assert_array_equal(
        kernels.facing_plane_inlier_counts(
            points, point_normals, unknown, normals, offsets, 0.01, 0.8
        ),
        ((distances < 0.01) & facing).sum(axis=0),
    )
    np.testing.assert_array_equal(
        kernels.facing_plane_inliers(points, point_normals, unknown, normals[0], 0.0, 0.01, 0.8),
        np.flatnonzero((distances[:, 0] < 0.01) & facing[:, 0]),
    )
    subset = np.flatnonzero(rng.random(4000) < 0.5)
    np.testing.assert_array_equal(kernels.rows_at(points, subset), points[subset])
    np.testing.assert_array_equal(
        kernels.indices_above(points, subset, normals[0], 0.0, 0.005),
        subset[points[subset] @ normals[0] >= 0.005],
    )


def test_region_groups_sort_stably_and_skip_points_of_no_region():
    rng = np.random.default_rng(2)
    region = rng.integers(-1, 5, 500)
    region[region == 3] = -1  # a region without points
    points = rng.normal(size=(500, 3))
    areas = rng.random(500)
    by_region, bounds, grouped, sizes, sums, area_sums = kernels.region_groups(
        region, points, areas, 5
    )
    reference = np.argsort(region, kind="stable")
    np.testing.assert_array_equal(by_region, reference)
    np.testing.assert_array_equal(bounds, np.searchsorted(region[reference], np.arange(6)))
    np.testing.assert_array_equal(grouped, points[reference])
    for number in range(5):
        members = region == number
        assert sizes[number] == members.sum()
        np.testing.assert_allclose(sums[number], points[members].sum(axis=0), atol=1e-12)
        assert area_sums[number] == pytest.approx(areas[members].sum(), rel=1e-12)


def test_labelled_order_is_the_stable_sort_by_label():
    rng = np.random.default_rng(5)
    labels = rng.integers(0, 9, 3000).astype(np.int32)
    labels[labels == 4] = 0  # a missing label
    valid = rng.random(3000) < 0.8
    order, ids, starts = kernels.labelled_order(labels, valid)
    labelled = np.flatnonzero((labels > 0) & valid)
    reference = labelled[np.argsort(labels[labelled], kind="stable")]
    reference_ids, reference_starts = np.unique(labels[reference], return_index=True)
    np.testing.assert_array_equal(order, reference)
    np.testing.assert_array_equal(ids, reference_ids)
    assert ids.dtype == reference_ids.dtype
    np.testing.assert_array_equal(starts, reference_starts)
    empty = kernels.labelled_order(np.zeros(10, dtype=np.int32), np.ones(10, dtype=bool))
    assert [len(part) for part in empty] == [0, 0, 0]


def test_distinct_per_slice_is_each_slice_unique():
    rng = np.random.default_rng(6)
    values = rng.integers(-1, 40, 2000).astype(np.int32)
    starts = np.array([0, 300, 300, 1200])
    ends = np.array([300, 300, 1200, 2000])
    distinct, bounds = kernels.distinct_per_slice(values, starts, ends, 40)
    assert distinct.dtype == values.dtype
    for k, (start, end) in enumerate(zip(starts, ends, strict=True)):
        part = values[start:end]
        np.testing.assert_array_equal(
            distinct[bounds[k] : bounds[k + 1]], np.unique(part[part >= 0])
        )


def test_largest_inscribed_squared_is_the_square_of_scipys_distance_transform():
    """Exact: the kernel's integer is the square whose root scipy's largest distance is."""
    from scipy.ndimage import binary_dilation, distance_transform_edt

    rng = np.random.default_rng(3)
    for trial in range(400):
        height, width = rng.integers(1, 40, 2)
        occupied = rng.random((height, width)) < rng.uniform(0.3, 1.0)
        if trial % 2:
            occupied = binary_dilation(occupied, iterations=3)
        inside = occupied & (rng.random((height, width)) < 0.5)
        squared = kernels.largest_inscribed_squared(inside, occupied)
        if occupied.all() or not inside.any():
            assert squared == -1
        else:
            assert np.sqrt(float(squared)) == distance_transform_edt(occupied)[inside].max()


def test_seam_side_bands_are_the_numpy_masks():
    rng = np.random.default_rng(4)
    rows, cols = np.nonzero(rng.random((60, 80)) < 0.7)
    for _ in range(50):
        angle = rng.uniform(0.0, np.pi)
        cos_a, sin_a = float(np.cos(angle)), float(np.sin(angle))
        rho = float(rng.integers(-40, 90))
        box = np.sort(rng.integers(0, 80, 4).reshape(2, 2), axis=1).ravel()
        along_range = np.sort(rng.uniform(-80.0, 80.0, 2))
        side_a, side_b = kernels.seam_side_bands(
            rows, cols, box, cos_a, sin_a, rho, along_range, 2.0, 10.0
        )
        in_box = (rows >= box[0]) & (rows < box[1]) & (cols >= box[2]) & (cols < box[3])
        across = cols * cos_a + rows * sin_a - rho
        along = -cols * sin_a + rows * cos_a
        usable = in_box & (along >= along_range[0]) & (along <= along_range[1])
        for sign, side in ((1.0, side_a), (-1.0, side_b)):
            chosen = usable & (sign * across >= 2.0) & (sign * across <= 10.0)
            assert np.array_equal(side, np.flatnonzero(chosen))


def test_colour_gradient_is_bit_identical_to_scipys_filters():
    """Gaussian (sigma 1) then Sobel per channel with scipy, the strongest channel picked by
    argmax: the kernel gives the same float32 bits, borders included."""
    from scipy import ndimage

    weights = ndimage.gaussian_filter1d(np.eye(1, 9, 4)[0], 1.0, truncate=4.0, mode="constant")
    rng = np.random.default_rng(5)
    for height, width in ((5, 5), (7, 12), (40, 31)):
        rgb = rng.integers(0, 256, (height, width, 3)).astype(np.uint8)
        rgb[: height // 2] = rgb[: height // 2] // 64 * 64  # flat patches: ties between channels
        image = ndimage.gaussian_filter(rgb.astype(np.float32) / 255.0, sigma=(1.0, 1.0, 0.0))
        gx = np.stack([ndimage.sobel(image[..., c], axis=1) for c in range(3)], axis=-1)
        gy = np.stack([ndimage.sobel(image[..., c], axis=0) for c in range(3)], axis=-1)
        strongest = np.argmax(gx**2 + gy**2, axis=2)[..., None]
        best_x, best_y = kernels.colour_gradient(rgb, weights)
        assert np.array_equal(best_x, np.take_along_axis(gx, strongest, axis=2)[..., 0])
        assert np.array_equal(best_y, np.take_along_axis(gy, strongest, axis=2)[..., 0])


def _reference_chord(
    part: np.ndarray, cos_a: float, sin_a: float, rho: float, window: tuple[slice, slice]
) -> tuple[np.ndarray, np.ndarray] | None:
    """(rows, cols) of the pixels of ``part`` on the line x cos a + y sin a = rho, in order
    along it (one pixel per step along its longer image axis), stepping only through
    ``window`` (a box that holds all of ``part``)."""
    height, width = part.shape
    if abs(sin_a) > abs(cos_a):
        cols = np.arange(window[1].start, window[1].stop)
        rows = np.round((rho - cols * cos_a) / sin_a).astype(np.int64)
    else:
        rows = np.arange(window[0].start, window[0].stop)
        cols = np.round((rho - rows * sin_a) / cos_a).astype(np.int64)
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    rows, cols = rows[inside], cols[inside]
    on = part[rows, cols]
    if on.sum() < 20:
        return None
    return rows[on], cols[on]


def _reference_reaches_outline(part: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> bool:
    """Whether the stretch (pixels in order along a line) ends at the outline of ``part`` at
    both ends: within 3 px beyond each end, along the line, lies a pixel outside it (a stretch
    that stops inside cannot cut)."""
    height, width = part.shape
    length = max(len(rows) - 1, 1)
    # Per-pixel direction along the stretch (one pixel along its longer axis).
    d_row = (rows[-1] - rows[0]) / length
    d_col = (cols[-1] - cols[0]) / length
    for end, sign in ((0, -1.0), (len(rows) - 1, 1.0)):
        outside = False
        for k in (1, 2, 3):
            r = int(round(rows[end] + sign * k * d_row))
            c = int(round(cols[end] + sign * k * d_col))
            if not (0 <= r < height and 0 <= c < width) or not part[r, c]:
                outside = True
                break
        if not outside:
            return False
    return True


def _reference_densest_stretch(on_edge: np.ndarray, density: float) -> tuple[int, int]:
    """The longest [start, stop) of ``on_edge`` (bool, (n,)) whose mean is at least
    ``density``: with prefix sums s of (on_edge - density), the longest b - a with
    s[b] >= s[a]; the prefix minima are non-increasing, so each b finds its first such a by
    bisection (the first longest wins)."""
    prefix = np.concatenate([[0.0], np.cumsum(on_edge.astype(np.float64) - density)])
    lowest = np.minimum.accumulate(prefix)
    begins = np.searchsorted(-lowest, -prefix[1:], side="left")
    lengths = np.arange(1, len(on_edge) + 1) - begins
    end = int(np.argmax(lengths))
    if lengths[end] <= 0:
        return 0, 0
    return int(begins[end]), end + 1


def test_line_stretches_match_the_numpy_chord_stretch_and_outline():
    """Bit for bit: each candidate line's chord, densest stretch and outline test as the seams'
    numpy functions gave them one line at a time."""
    rng = np.random.default_rng(6)
    yy, xx = np.mgrid[0:70, 0:90]
    part = ((yy - 35) ** 2 / 30.0**2 + (xx - 45) ** 2 / 40.0**2 < 1.0) | (
        (yy > 5) & (yy < 30) & (xx > 10) & (xx < 50)
    )
    near_edge = rng.random(part.shape) < 0.8
    near_edge[:, 40:43] = True
    window = (slice(3, 68), slice(2, 88))
    angles = rng.uniform(0.0, np.pi, 200)
    angles[:4] = (0.0, np.pi / 2, np.pi / 4, 3 * np.pi / 4)
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    rho = rng.integers(-60, 110, 200).astype(np.float64)
    rho[:2] = (41.0, 30.0)
    lengths, reaches, rows, cols, bounds = kernels.line_stretches(
        part, near_edge, np.array([3, 68, 2, 88]), cos_a, sin_a, rho, 0.75, 20
    )
    found = 0
    for k in range(len(rho)):
        expected = (0, False, np.empty(0), np.empty(0))
        line = _reference_chord(part, cos_a[k], sin_a[k], int(rho[k]), window)
        if line is not None:
            start, stop = _reference_densest_stretch(near_edge[line[0], line[1]], 0.75)
            if stop - start >= 20:
                run = line[0][start:stop], line[1][start:stop]
                expected = (stop - start, _reference_reaches_outline(part, *run), *run)
        assert lengths[k] == expected[0]
        assert bool(reaches[k]) == expected[1]
        np.testing.assert_array_equal(rows[bounds[k] : bounds[k + 1]], expected[2])
        np.testing.assert_array_equal(cols[bounds[k] : bounds[k + 1]], expected[3])
        found += expected[0] > 0
    assert found > 20


def test_mean_at_is_the_numpy_mean_of_the_gathered_rows():
    rng = np.random.default_rng(7)
    values = rng.normal(size=(30, 40, 3)).astype(np.float32)
    for count in (1, 20, 333):
        rows, cols = rng.integers(0, 30, count), rng.integers(0, 40, count)
        expected = values[rows, cols].astype(np.float64).mean(axis=0)
        assert np.array_equal(kernels.mean_at(values, rows, cols), expected)


def test_hough_votes_are_the_numpy_bincount():
    rng = np.random.default_rng(8)
    directions, spread, reach = 180, 10, 120
    angles = np.linspace(0.0, np.pi, directions, endpoint=False)
    cos_a, sin_a = np.cos(angles), np.sin(angles)
    rows, cols = rng.integers(0, 80, 500), rng.integers(0, 90, 500)
    own = rng.integers(0, directions + 1, 500)  # directions itself: a direction of pi
    a = (own[None, :] + np.arange(-spread, spread + 1)[:, None]) % directions
    rho = np.round(cols * cos_a[a] + rows * sin_a[a]).astype(np.int64) + reach
    expected = np.bincount(
        (a * (2 * reach + 1) + rho).ravel(), minlength=directions * (2 * reach + 1)
    )
    votes = kernels.hough_votes(rows, cols, own, spread, cos_a, sin_a, reach)
    assert np.array_equal(votes, expected)
    # The lines with at least k votes, in index order, and their votes.
    for least in (1, 3, 20):
        lines, counts = kernels.hough_lines(rows, cols, own, spread, cos_a, sin_a, reach, least)
        assert np.array_equal(lines, np.flatnonzero(expected >= least))
        assert np.array_equal(counts, expected[lines])


def _robust_circle_numpy(points: np.ndarray, floor_m: float, rounds: int) -> tuple:
    """``kernels.robust_circle`` in numpy (Kasa by least squares, refitted on its inliers)."""
    inliers = np.ones(len(points), dtype=bool)
    for _ in range(rounds):
        kept = points[inliers]
        if len(kept) < 10:
            return 0.0, 0.0, -1.0, 0.0, 0.0
        origin = kept.mean(axis=0)
        local = kept - origin
        design = np.column_stack([local, np.ones(len(local))])
        solution, *_ = np.linalg.lstsq(design, (local**2).sum(axis=1), rcond=None)
        centre = solution[:2] / 2.0
        squared = solution[2] + centre @ centre
        if squared <= 0:
            return 0.0, 0.0, -1.0, 0.0, 0.0
        radius = np.sqrt(squared)
        centre = centre + origin
        residual = np.linalg.norm(points - centre, axis=1) - radius
        spread = 1.4826 * np.median(np.abs(residual[inliers]))
        updated = np.abs(residual) <= max(3.0 * spread, floor_m)
        if (updated == inliers).all():
            break
        inliers = updated
    rms = np.sqrt(np.mean(residual[inliers] ** 2))
    return centre[0], centre[1], radius, rms, inliers.mean()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_robust_circle_matches_the_numpy_fit(seed):
    """An arc with noise, a few outliers (a handle) and, for one seed, a filled disc: the same
    circle, RMS and inlier share as the numpy loop (to rounding: normal equations, not QR)."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.2, 0.2 + 2.5 * (seed + 1), 200)
    arc = np.column_stack([0.3 + 0.05 * np.cos(angle), 0.1 + 0.05 * np.sin(angle)])
    arc += rng.normal(0.0, 0.002, arc.shape)
    outliers = np.array([0.3, 0.1]) + rng.uniform(-0.09, 0.09, (20, 2))
    points = np.concatenate([arc, outliers])
    if seed == 2:
        points = np.array([0.3, 0.1]) + 0.04 * np.sqrt(
            rng.uniform(0, 1, (300, 1))
        ) * np.column_stack([np.cos(angle := rng.uniform(0, 2 * np.pi, 300)), np.sin(angle)])
    compiled = kernels.robust_circle(points, 0.004, 4)
    assert np.allclose(compiled, _robust_circle_numpy(points, 0.004, 4), rtol=1e-9, atol=1e-12)
    # Too few points, or all on one line: no circle.
    assert kernels.robust_circle(points[:9], 0.004, 4)[2] == -1.0
    line = np.column_stack([np.linspace(0, 0.1, 50), np.zeros(50)])
    assert kernels.robust_circle(line, 0.004, 4)[2] == -1.0


def test_wall_slab_marks_are_the_numpy_masks():
    rng = np.random.default_rng(17)
    count = 5000
    depth = rng.uniform(-0.06, 0.03, count)
    position = rng.uniform(-0.4, 0.4, count)
    heights = rng.uniform(-0.05, 0.4, count)
    depth[:50] = 0.01  # on the bounds: excluded, as numpy's strict tests exclude them
    position[50:100] = -0.3
    start, columns = -0.3, 31
    end = start + columns * 0.02
    column_top = rng.uniform(0.05, 0.3, columns)
    column_top[::7] = -np.inf  # columns without wall points
    mask = rng.random(count) < 0.2  # marks already set stay set
    initial = mask.copy()
    expected = mask.copy()
    candidate = np.flatnonzero(
        (depth < 0.01) & (depth > -0.04) & (position > start) & (position < end)
    )
    local_top = column_top[((position[candidate] - start) / 0.02).astype(np.int64)]
    expected[candidate[heights[candidate] < local_top + 0.01]] = True
    kernels.mark_wall_slab(
        depth, position, heights, 0.01, -0.04, start, end, column_top, 0.01, mask
    )
    np.testing.assert_array_equal(mask, expected)
    assert (mask & ~initial).sum() > 100  # the kernel marked points of its own


def test_rows_at_keeps_the_dtype_and_is_the_fancy_index():
    rng = np.random.default_rng(23)
    indices = rng.integers(0, 2000, 700)
    colours = rng.integers(0, 256, (2000, 3), dtype=np.uint8)
    points = rng.normal(size=(2000, 3))
    for values in (colours, points):
        got = kernels.rows_at(values, indices)
        assert got.dtype == values.dtype
        np.testing.assert_array_equal(got, values[indices])


def test_labels_of_keys_is_the_table_lookup_and_where():
    rng = np.random.default_rng(29)
    table = np.full(5000, -1, dtype=np.int32)
    cells = rng.choice(5000, 800, replace=False)
    table[cells] = np.arange(800, dtype=np.int32)
    label_of_cell = rng.integers(0, 60, 800).astype(np.int64)
    keys = rng.integers(0, 5000, 20000).astype(np.int64)
    position = table[keys].astype(np.int64)
    expected = np.where(position >= 0, label_of_cell[position], -1)
    got = kernels.labels_of_keys(table, keys, label_of_cell)
    assert got.dtype == expected.dtype == np.int64
    np.testing.assert_array_equal(got, expected)
    assert (got == -1).any() and (got >= 0).any()


def test_dense_normalised_laplacian_is_the_numpy_expression():
    from scipy.sparse import coo_matrix

    rng = np.random.default_rng(37)
    m = 120
    rows = rng.integers(0, m, 900)
    cols = rng.integers(0, m, 900)
    values = np.where(rng.random(900) < 0.7, 1.0, 0.05) * rng.uniform(0.1, 1.0, 900)
    weights = coo_matrix((values, (rows, cols)), shape=(m, m))
    weights = (weights + weights.T).tocsr()
    weights.data[::5] = 0.0  # stored zeros stay zeros
    degree = np.asarray(weights.sum(axis=1)).ravel()
    scale = 1.0 / np.sqrt(np.maximum(degree, 1e-12))
    expected = np.eye(m) - (weights.toarray() * scale[:, None]) * scale[None, :]
    got = kernels.dense_normalised_laplacian(weights.indptr, weights.indices, weights.data, scale)
    assert np.array_equal(got, expected)
    assert np.array_equal(np.signbit(got), np.signbit(expected))  # -0.0 where numpy has it
    # Duplicate entries (a non-canonical CSR) are summed as scipy's toarray sums them.
    duplicated = weights.copy()
    duplicated.indices = duplicated.indices.copy()
    duplicated.has_canonical_format = False
    first = duplicated.indptr[3]
    if duplicated.indptr[4] - first >= 2:
        duplicated.indices[first + 1] = duplicated.indices[first]
    expected = np.eye(m) - (duplicated.toarray() * scale[:, None]) * scale[None, :]
    got = kernels.dense_normalised_laplacian(
        duplicated.indptr, duplicated.indices, duplicated.data, scale
    )
    assert np.array_equal(got, expected)


def test_piece_spans_are_each_pieces_point_range():
    """The seams' bound on a piece's face size (``seams._FrameFaces.reach``): per piece id, the
    range of its points with depth, as numpy's min and max of the gathered points."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        height, width = rng.integers(5, 40, size=2)
        points = rng.normal(size=(height, width, 3)).astype(np.float32)
        pieces = rng.integers(0, 5, size=(height, width))
        measured = rng.random((height, width)) < 0.7
        count = int(pieces.max())
        spans = kernels.piece_spans(points, pieces, measured, count)
        assert spans.shape == (count + 1, 3)
        assert np.all(spans[0] == 0.0)
        for piece in range(1, count + 1):
            cloud = points[(pieces == piece) & measured].astype(np.float64)
            expected = cloud.max(axis=0) - cloud.min(axis=0) if len(cloud) else np.zeros(3)
            assert np.array_equal(spans[piece], expected)
