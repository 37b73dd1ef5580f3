"""Compiled inner loops (numba) for the per-pixel passes of perception.

On the 2-core cloud machines ipr is measured on, numpy's per-pixel arithmetic is bound by memory
traffic: each operator of an expression makes a full-size temporary, and a 640x480 frame's
(H, W, 3) float64 points are 7 MB. A loop compiled by numba does the same arithmetic in one pass
with no temporaries (docs/DESIGN_NOTES.md, "Compiled kernels"). Each kernel here states the
numpy expression it replaces; ``tests/test_kernels.py`` and ``tests/test_perception_speedups.py``
pin every one against that expression. The world points and the plane fit's kernels, which the
scene loader needs too, are in ``ipr_shapes.geometry.kernels``; the kernels here share its helpers
``_rotated`` (world points in numpy's FMA order), ``_dot`` and ``_columns``.

Kernels are compiled on first use and cached on disk (``cache=True``: a new process loads them
instead of compiling them again). numba checks a cached kernel against this file only, not
against the helpers it calls from ``ipr_shapes.geometry.kernels``: after editing those, clear this
module's cache (``__pycache__/kernels.*.nbi`` and ``.nbc`` here, or the
``NUMBA_CACHE_DIR``). ``NUMBA_DISABLE_JIT=1`` runs them as plain Python, for debugging.
"""

from __future__ import annotations

import numba
import numpy as np

from ipr_shapes.geometry.kernels import _columns, _dot, _rotated

# nogil: callers may run perception in threads; no fastmath: the same IEEE arithmetic as numpy.
_jit = numba.njit(cache=True, nogil=True)


@_jit
def organised_normals(
    padded_depth: np.ndarray,
    padded_width: int,
    at: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    K: np.ndarray,
    radius_px: int,
    max_jump_m: float,
    max_jump_per_px: float,
) -> np.ndarray:
    """Unit normals (P, 3) float32, camera frame, towards the camera, of P pixels of an
    organised depth image; rows of 0 where unknown. The loop of
    ``supervoxels.organised_normals_at``, which documents the method: ``padded_depth`` is the
    flat float32 depth image (m) with a border of ``radius_px`` zeros, ``padded_width`` its
    width, ``at`` (P,) the pixels' flat indices in it and ``rows``, ``cols`` (P,) their image
    coordinates. All arithmetic in float32, operation by operation as the numpy version."""
    count = at.shape[0]
    normals = np.zeros((count, 3), dtype=np.float32)
    fx, fy = np.float32(K[0, 0]), np.float32(K[1, 1])
    cx, cy = np.float32(K[0, 2]), np.float32(K[1, 2])
    r = np.float32(radius_px)
    jump = np.float32(max_jump_m)
    jump_per_depth = np.float32(max_jump_per_px * radius_px)
    tiny = np.float32(1e-12)
    zero = np.float32(0.0)
    shifts = (radius_px, -radius_px, radius_px * padded_width, -radius_px * padded_width)
    neighbour = np.empty(4, dtype=np.float32)
    usable = np.empty(4, dtype=np.bool_)
    for p in range(count):
        z = padded_depth[at[p]]
        row_f, col_f = np.float32(rows[p]), np.float32(cols[p])
        x_factor = (col_f - cx) / fx
        y_factor = (row_f - cy) / fy
        centre_x, centre_y = x_factor * z, y_factor * z
        limit = jump + jump_per_depth * z
        for k in range(4):
            nz = padded_depth[at[p] + shifts[k]]
            ok = (nz > zero) and (abs(nz - z) <= limit)
            usable[k] = ok
            neighbour[k] = nz if ok else z
        z_right, z_left, z_down, z_up = neighbour[0], neighbour[1], neighbour[2], neighbour[3]
        x_right = (col_f + r - cx) / fx * z_right if usable[0] else centre_x
        x_left = (col_f - r - cx) / fx * z_left if usable[1] else centre_x
        y_down = (row_f + r - cy) / fy * z_down if usable[2] else centre_y
        y_up = (row_f - r - cy) / fy * z_up if usable[3] else centre_y
        a0 = x_factor * z_down - x_factor * z_up
        a1 = y_down - y_up
        a2 = z_down - z_up
        b0 = x_right - x_left
        b1 = y_factor * z_right - y_factor * z_left
        b2 = z_right - z_left
        n0, n1, n2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        squared = n0 * n0
        squared += n1 * n1
        squared += n2 * n2
        norm = np.sqrt(squared)
        good = (z > zero) and (usable[0] or usable[1]) and (usable[2] or usable[3])
        if not good or not norm > tiny:
            continue
        n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
        if n0 * centre_x + n1 * centre_y + n2 * z > zero:
            n0, n1, n2 = -n0, -n1, -n2
        normals[p, 0], normals[p, 1], normals[p, 2] = n0, n1, n2
    return normals


@_jit
def supervoxel_rounds(
    voxel_centre: np.ndarray,
    voxel_normal: np.ndarray,
    voxel_colour: np.ndarray,
    voxel_count: np.ndarray,
    candidates: np.ndarray,
    has_candidate: np.ndarray,
    seed_centre: np.ndarray,
    seed_normal: np.ndarray,
    seed_colour: np.ndarray,
    iterations: int,
    seed_size_m: float,
    normal_weight: float,
    colour_weight: float,
) -> np.ndarray:
    """The k-means rounds of ``supervoxels.compute_supervoxels``: (V,) int64 seed of each of V
    voxels after ``iterations`` rounds (0 rounds: all 0).

    Each round assigns every voxel to the nearest of its (V, 27) ``candidates`` seeds (where
    ``has_candidate``; the first of equal distances) in VCCS's distance
    ``normal_weight * (1 - n_voxel . n_seed) + |c_voxel - c_seed|^2 / seed_size_m^2
    + colour_weight * |rgb_voxel - rgb_seed|^2``, then moves each seed that kept voxels to the
    mean of their (V, 3) centres, normals (renormalised) and colours weighted by ``voxel_count``
    (V,). ``seed_centre``, ``seed_normal`` and ``seed_colour`` (S, 3) are updated in place.
    The arithmetic and summation order are those of the numpy version (same bits).
    """
    n_voxels, n_candidates = candidates.shape
    n_seeds = seed_centre.shape[0]
    assignment = np.zeros(n_voxels, dtype=np.int64)
    spatial = 1.0 / seed_size_m**2
    totals = np.empty(n_seeds)
    sums = np.empty((3, n_seeds, 3))
    for _ in range(iterations):
        for v in range(n_voxels):
            best, best_distance = 0, np.inf
            for k in range(n_candidates):
                if not has_candidate[v, k]:
                    continue
                s = candidates[v, k]
                distance = normal_weight
                for axis in range(3):
                    offset = voxel_centre[v, axis] - seed_centre[s, axis]
                    distance += offset * spatial * offset
                    distance -= normal_weight * voxel_normal[v, axis] * seed_normal[s, axis]
                    if colour_weight > 0:
                        offset = voxel_colour[v, axis] - seed_colour[s, axis]
                        distance += offset * colour_weight * offset
                if distance < best_distance:
                    best, best_distance = k, distance
            assignment[v] = candidates[v, best] if has_candidate[v, best] else candidates[v, 0]
        totals[:] = 0.0
        sums[:] = 0.0
        for v in range(n_voxels):
            s = assignment[v]
            weight = voxel_count[v]
            totals[s] += weight
            for axis in range(3):
                sums[0, s, axis] += voxel_centre[v, axis] * weight
                sums[1, s, axis] += voxel_normal[v, axis] * weight
                sums[2, s, axis] += voxel_colour[v, axis] * weight
        for s in range(n_seeds):
            if not totals[s] > 0:
                continue
            squared = sums[1, s, 0] * sums[1, s, 0]
            squared += sums[1, s, 1] * sums[1, s, 1]
            squared += sums[1, s, 2] * sums[1, s, 2]
            norm = np.sqrt(squared)
            for axis in range(3):
                seed_centre[s, axis] = sums[0, s, axis] / totals[s]
                seed_normal[s, axis] = sums[1, s, axis] / norm if norm > 1e-12 else 0.0
                seed_colour[s, axis] = sums[2, s, axis] / totals[s]
    return assignment


@_jit
def mean_shift_directions(
    normals: np.ndarray, weights: np.ndarray, bandwidth: float, iterations: int
) -> np.ndarray:
    """Mode index (N,) int64 of each unit normal (N, 3) under weighted Gaussian mean shift on
    the sphere, modes merged heaviest first; ``facets.mean_shift_directions`` documents the
    method. Equal to numpy's version up to rounding (its matrix products run in BLAS)."""
    count = normals.shape[0]
    modes = normals.copy()
    shifted = np.empty_like(modes)
    scale = 2 * bandwidth**2
    for _ in range(iterations):
        change = 0.0
        for i in range(count):
            s0 = s1 = s2 = 0.0
            for j in range(count):
                dot = modes[i, 0] * normals[j, 0] + modes[i, 1] * normals[j, 1]
                dot += modes[i, 2] * normals[j, 2]
                kernel = np.exp(-max(2.0 - 2.0 * dot, 0.0) / scale) * weights[j]
                s0 += kernel * normals[j, 0]
                s1 += kernel * normals[j, 1]
                s2 += kernel * normals[j, 2]
            norm = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2) + 1e-12
            shifted[i, 0], shifted[i, 1], shifted[i, 2] = s0 / norm, s1 / norm, s2 / norm
            for axis in range(3):
                change = max(change, abs(shifted[i, axis] - modes[i, axis]))
        modes[:] = shifted
        if change < 1e-5:
            break
    # Merge modes closer than half a bandwidth, heaviest first (a stable order): each normal
    # joins the first centre (in creation order) near its mode; a normal near none is a centre.
    order = np.argsort(-weights, kind="mergesort")
    label = np.full(count, -1, dtype=np.int64)
    centres = 0
    for index in order:
        if label[index] >= 0:
            continue
        for j in range(count):
            if label[j] >= 0:
                continue
            d0 = modes[j, 0] - modes[index, 0]
            d1 = modes[j, 1] - modes[index, 1]
            d2 = modes[j, 2] - modes[index, 2]
            if np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) < bandwidth / 2:
                label[j] = centres
        label[index] = centres
        centres += 1
    return label


@_jit
def segment_sums(
    flat_labels: np.ndarray,
    flat_points: np.ndarray,
    flat_rgb: np.ndarray,
    flat_depth: np.ndarray,
    colour_bins: int,
):
    """Per-segment sums of a label image in one pass, for ``tracking.segment_features``.

    ``flat_labels`` (P,) ints (segments k >= 1, 0 = none), ``flat_points`` (P, 3) world points
    (m), ``flat_rgb`` (P, 3) uint8 and ``flat_depth`` (P,) depth (m, 0 = no reading). Segments
    are numbered 0..G-1 in increasing label. Returns:
    ``ids`` (G,) labels; ``order`` (N,) the labelled pixels grouped by segment, in raster order
    within each (numpy's stable argsort of the labels); ``starts`` (G + 1,) each segment's
    slice of ``order``; ``with_depth`` (G,) pixels with a reading; ``used`` (G,) pixels whose
    points are used (those with a reading, or all where none has one); ``point_sums`` (G, 3)
    sums of the used points in raster order (the order of ``np.bincount`` over ``order``);
    ``used_z`` (sum of used,) the used points' z grouped by segment; ``histograms`` (G, B^3)
    int64 counts of colour bins (``B = colour_bins`` per channel, ``(c * B) // 256``);
    ``footprints`` (G,) sums of depth^2 over the pixels with a reading.
    """
    count = flat_labels.shape[0]
    largest = 0
    labelled = 0
    for p in range(count):
        if flat_labels[p] > 0:
            labelled += 1
            if flat_labels[p] > largest:
                largest = flat_labels[p]
    size_of_label = np.zeros(largest + 1, dtype=np.int64)
    for p in range(count):
        if flat_labels[p] > 0:
            size_of_label[flat_labels[p]] += 1
    segment_of_label = np.full(largest + 1, -1, dtype=np.int64)
    n_segments = 0
    for label in range(1, largest + 1):
        if size_of_label[label] > 0:
            segment_of_label[label] = n_segments
            n_segments += 1
    ids = np.empty(n_segments, dtype=np.int64)
    starts = np.zeros(n_segments + 1, dtype=np.int64)
    for label in range(1, largest + 1):
        segment = segment_of_label[label]
        if segment >= 0:
            ids[segment] = label
            starts[segment + 1] = starts[segment] + size_of_label[label]
    order = np.empty(labelled, dtype=np.int64)
    fill = starts[:-1].copy()
    with_depth = np.zeros(n_segments, dtype=np.int64)
    footprints = np.zeros(n_segments)
    histograms = np.zeros((n_segments, colour_bins**3), dtype=np.int64)
    for p in range(count):
        label = flat_labels[p]
        if label <= 0:
            continue
        segment = segment_of_label[label]
        order[fill[segment]] = p
        fill[segment] += 1
        depth = np.float64(flat_depth[p])
        if depth > 0:
            with_depth[segment] += 1
            footprints[segment] += depth * depth
        code = 0
        for channel in range(3):
            code = code * colour_bins + (np.int64(flat_rgb[p, channel]) * colour_bins) // 256
        histograms[segment, code] += 1
    used = np.zeros(n_segments, dtype=np.int64)
    point_sums = np.zeros((n_segments, 3))
    used_z = np.empty(labelled)
    used_at = 0
    for segment in range(n_segments):
        everything = with_depth[segment] == 0
        for k in range(starts[segment], starts[segment + 1]):
            p = order[k]
            if everything or flat_depth[p] > 0:
                used[segment] += 1
                for axis in range(3):
                    point_sums[segment, axis] += flat_points[p, axis]
                used_z[used_at] = flat_points[p, 2]
                used_at += 1
    return (
        ids,
        order,
        starts,
        with_depth,
        used,
        point_sums,
        used_z[:used_at],
        histograms,
        footprints,
    )


@_jit
def facing_plane_inlier_counts(
    points: np.ndarray,
    point_normals: np.ndarray,
    unknown: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    threshold_m: float,
    min_cos: float,
) -> np.ndarray:
    """``ipr_shapes.geometry.kernels.plane_inlier_counts`` counting only points whose (N, 3) unit
    normal is within acos(``min_cos``) of +-the plane's, or ``unknown`` (N,) bool (no normal)."""
    xs, ys, zs = _columns(points)
    us, vs, ws = _columns(point_normals)
    counts = np.zeros(normals.shape[0], dtype=np.int64)
    for h in range(normals.shape[0]):
        n0, n1, n2, offset = normals[h, 0], normals[h, 1], normals[h, 2], offsets[h]
        count = 0
        for p in range(xs.shape[0]):  # branch-free (& and |): the compiler vectorises it
            near = abs(xs[p] * n0 + ys[p] * n1 + zs[p] * n2 + offset) < threshold_m
            facing = abs(us[p] * n0 + vs[p] * n1 + ws[p] * n2) > min_cos
            count += near & (facing | unknown[p])
        counts[h] = count
    return counts


@_jit
def facing_plane_inliers(
    points: np.ndarray,
    point_normals: np.ndarray,
    unknown: np.ndarray,
    normal: np.ndarray,
    offset: float,
    threshold_m: float,
    min_cos: float,
) -> np.ndarray:
    """(K,) int64 ascending indices of the (N, 3) points within ``threshold_m`` of the plane
    {x : normal . x + offset = 0} whose (N, 3) normal is within acos(``min_cos``) of +-the
    plane's or ``unknown`` (N,) bool: ``ipr_shapes.geometry.kernels.plane_inliers`` with the facing
    test of ``facing_plane_inlier_counts``."""
    found = np.empty(points.shape[0], dtype=np.int64)
    count = 0
    for p in range(points.shape[0]):
        near = abs(_dot(points, p, normal) + offset) < threshold_m
        if near and (unknown[p] or abs(_dot(point_normals, p, normal)) > min_cos):
            found[count] = p
            count += 1
    return found[:count].copy()


@_jit
def objects_plane_depth(
    depth_m: np.ndarray, pixels: np.ndarray, starts: np.ndarray, window: int
) -> np.ndarray:
    """(N,) float64 depth (m) of objects' flat pixels, each replaced by its object's local
    plane fit there: ``denoise.object_plane_depth`` (which documents the method) for every
    object at once. ``pixels`` (N,) holds the objects' pixels (all with a reading) one object
    after the other, object k at ``pixels[starts[k]:starts[k + 1]]``; ``window`` is odd.

    The window sums are taken directly in float64 (numpy's version used float32 box filters
    on depths centred at the object's mean): equal to well under a micrometre."""
    height, width = depth_m.shape
    result = np.empty(pixels.shape[0])
    for p in range(pixels.shape[0]):
        result[p] = depth_m.flat[pixels[p]]
    margin = window // 2
    area = window * window
    for k in range(starts.shape[0] - 1):
        first, last = starts[k], starts[k + 1]
        if window < 3 or last - first < 6:
            continue
        top, bottom, left, right = height, -1, width, -1
        reference = 0.0
        for p in range(first, last):
            row, col = pixels[p] // width, pixels[p] % width
            top, bottom = min(top, row), max(bottom, row)
            left, right = min(left, col), max(right, col)
            reference += result[p]
        reference /= last - first
        # The object's bounding box padded by the margin: every window stays inside.
        crop_width = right - left + 1 + 2 * margin
        crop_height = bottom - top + 1 + 2 * margin
        inside = np.zeros((crop_height, crop_width), dtype=np.bool_)
        centred = np.zeros((crop_height, crop_width))
        for p in range(first, last):
            row = pixels[p] // width - top + margin
            col = pixels[p] % width - left + margin
            inside[row, col] = True
            centred[row, col] = result[p] - reference
        # Summed-area tables of the mask and of the centred depth (row 0 and column 0 zero):
        # a window's count and depth sum in four reads; only windows the object does not fill
        # need the moments of the full fit.
        filled = np.zeros((crop_height + 1, crop_width + 1))
        depth_sum = np.zeros((crop_height + 1, crop_width + 1))
        for row in range(crop_height):
            for col in range(crop_width):
                filled[row + 1, col + 1] = (
                    filled[row, col + 1]
                    + filled[row + 1, col]
                    - filled[row, col]
                    + inside[row, col]
                )
                depth_sum[row + 1, col + 1] = (
                    depth_sum[row, col + 1]
                    + depth_sum[row + 1, col]
                    - depth_sum[row, col]
                    + centred[row, col]
                )
        for p in range(first, last):
            row = pixels[p] // width - top + margin
            col = pixels[p] % width - left + margin
            low_row, high_row = row - margin, row + margin + 1
            low_col, high_col = col - margin, col + margin + 1
            count = (
                filled[high_row, high_col]
                - filled[low_row, high_col]
                - filled[high_row, low_col]
                + filled[low_row, low_col]
            )
            if count > area - 0.5:
                # A full window is symmetric about its pixel: the plane's value is the mean.
                window_sum = (
                    depth_sum[high_row, high_col]
                    - depth_sum[low_row, high_col]
                    - depth_sum[high_row, low_col]
                    + depth_sum[low_row, low_col]
                )
                result[p] = window_sum / area + reference
                continue
            if count < 5.5:
                continue
            s = cu = cv = cuu = cvv = cuv = sd = cdu = cdv = 0.0
            for dv in range(-margin, margin + 1):
                for du in range(-margin, margin + 1):
                    if inside[row + dv, col + du]:
                        value = centred[row + dv, col + du]
                        s += 1.0
                        cu += du
                        cv += dv
                        cuu += du * du
                        cvv += dv * dv
                        cuv += du * dv
                        sd += value
                        cdu += value * du
                        cdv += value * dv
            # Cramer's rule for [[s, cu, cv], [cu, cuu, cuv], [cv, cuv, cvv]] x = [sd, cdu, cdv].
            minor = cuu * cvv - cuv * cuv
            det = s * minor - cu * (cu * cvv - cuv * cv) + cv * (cu * cuv - cuu * cv)
            if abs(det) > 1e-6 * max(s, 1.0) ** 3:  # not all on one line
                numerator = sd * minor - cu * (cdu * cvv - cuv * cdv) + cv * (cdu * cuv - cuu * cdv)
                result[p] = numerator / det + reference
    return result


@_jit
def object_pixel_geometry(
    pixels: np.ndarray,
    depth_m: np.ndarray,
    width: int,
    K: np.ndarray,
    world_from_camera: np.ndarray,
    point_supervoxel: np.ndarray,
    supervoxel_normals: np.ndarray,
):
    """World points (N, 3) (m) and surface areas (N,) (m^2) of N pixels, in one pass.

    ``pixels`` (N,) flat indices in an image ``width`` wide, ``depth_m`` (N,) their depths
    (m, > 0), ``point_supervoxel`` (N,) their supervoxels (-1 = none: the surface faces the
    camera) and ``supervoxel_normals`` (M, 3) those's unit normals (world). A pixel at depth z
    covers z^2 / (fx fy) of the fronto-parallel plane, more by |r_z| / max(|r . n|, 0.25) on a
    surface tilted away (r the unit ray; ``facets.pixel_areas``); the points are
    ``backproject_pixels`` moved to the world."""
    count = pixels.shape[0]
    world = np.empty((count, 3))
    areas = np.empty(count)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    for p in range(count):
        row, col = pixels[p] // width, pixels[p] % width
        z = np.float64(depth_m[p])
        x, y = (col - cx) / fx * z, (row - cy) / fy * z
        facing = 0.0  # r . n in the camera frame = (R r_camera) . n_world
        length = np.sqrt(x * x + y * y + z * z)
        supervoxel = point_supervoxel[p]
        for axis in range(3):
            world[p, axis] = _rotated(x, y, z, world_from_camera, axis)
            if supervoxel >= 0:
                normal = supervoxel_normals[supervoxel, axis]
            else:
                normal = -world_from_camera[axis, 2]
            facing += (world[p, axis] - world_from_camera[axis, 3]) * normal
        facing = max(abs(facing / length), 0.25)
        areas[p] = z * z / (fx * fy) * (abs(z / length) / facing)
    return world, areas


@_jit
def dominant_face_moments(
    groups: np.ndarray,
    points: np.ndarray,
    pixel_normals: np.ndarray,
    mean_normals: np.ndarray,
    min_cos: float,
):
    """The dominant face of each of M groups of pixels (``supervoxels._dominant_faces``
    documents the method): twice, keep each group's pixels whose normal is within
    acos(``min_cos``) of the group's normal and re-average it; then take the moments of the
    kept pixels (of all the group's pixels when fewer than 6 were kept).

    ``groups`` (N,) group of each pixel, ``points`` (N, 3) (m), ``pixel_normals`` (N, 3) unit,
    ``mean_normals`` (M, 3) each group's starting normal. Returns the faces' centres (M, 3),
    covariances (M, 3, 3) (sums of centred outer products over the pixel count), pixel counts
    (M,) int64 and re-averaged normals (M, 3). Sums run in pixel order, as numpy's bincounts.
    """
    count, n_points = mean_normals.shape[0], groups.shape[0]
    normal = mean_normals.copy()
    inlier = np.ones(n_points, dtype=np.bool_)
    inlier_count = np.zeros(count, dtype=np.int64)
    summed = np.empty((count, 3))
    for _ in range(2):
        summed[:] = 0.0
        inlier_count[:] = 0
        for p in range(n_points):
            g = groups[p]
            dot = pixel_normals[p, 0] * normal[g, 0] + pixel_normals[p, 1] * normal[g, 1]
            dot += pixel_normals[p, 2] * normal[g, 2]
            inlier[p] = dot > min_cos
            if inlier[p]:
                inlier_count[g] += 1
                for axis in range(3):
                    summed[g, axis] += pixel_normals[p, axis]
        for g in range(count):
            squared = summed[g, 0] * summed[g, 0]
            squared += summed[g, 1] * summed[g, 1]
            squared += summed[g, 2] * summed[g, 2]
            norm = np.sqrt(squared)
            if norm > 1e-12:
                for axis in range(3):
                    normal[g, axis] = summed[g, axis] / norm
    sizes = np.zeros(count, dtype=np.int64)
    centres = np.zeros((count, 3))
    for p in range(n_points):
        g = groups[p]
        if inlier[p] or inlier_count[g] < 6:  # groups without a clear face use every pixel
            sizes[g] += 1
            for axis in range(3):
                centres[g, axis] += points[p, axis]
    for g in range(count):
        for axis in range(3):
            centres[g, axis] /= max(sizes[g], 1)
    covariance = np.zeros((count, 3, 3))
    for p in range(n_points):
        g = groups[p]
        if inlier[p] or inlier_count[g] < 6:
            for i in range(3):
                local_i = points[p, i] - centres[g, i]
                for j in range(i, 3):
                    covariance[g, i, j] += local_i * (points[p, j] - centres[g, j])
    for g in range(count):
        for i in range(3):
            for j in range(i, 3):
                covariance[g, i, j] /= max(sizes[g], 1)
                covariance[g, j, i] = covariance[g, i, j]
    return centres, covariance, sizes, normal


@_jit
def fill_from_nearest(
    labels: np.ndarray, valid: np.ndarray, offsets: np.ndarray, result: np.ndarray
) -> None:
    """Give each pixel of (H, W) ``labels`` that is not ``valid`` the label of the first valid
    pixel among (P, 2) (row, column) ``offsets`` from it (sorted by length: the nearest), or
    leave it when none is valid; written into ``result`` (H, W), which starts as a copy of
    ``labels``. The loop of ``segmentation.fill_label_holes``."""
    height, width = labels.shape
    for row in range(height):
        for col in range(width):
            if valid[row, col]:
                continue
            for k in range(offsets.shape[0]):
                r, c = row + offsets[k, 0], col + offsets[k, 1]
                if 0 <= r < height and 0 <= c < width and valid[r, c]:
                    result[row, col] = labels[r, c]
                    break


@_jit
def border_pair_counts(
    labels: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    valid: np.ndarray,
    contact_gap_m: float,
    front_low_m: float,
    front_high_m: float,
    n_labels: int,
):
    """Where segments meet, counted over the 4-neighbour pixel pairs of a (H, W) label image
    (``containers._borders`` documents the rules): a pair counts when both pixels are
    ``valid`` with labels a != b, both > 0. ``points`` (H, W, 3) world (m), ``depth_m`` (H, W).

    Returns (2, L, L) int64 ``contacts`` [pass, min(a, b), max(a, b)] (world points closer than
    ``contact_gap_m``) and (2, L, L) ``fronts`` [pass, nearer, farther] (depth step strictly
    between ``front_low_m`` and ``front_high_m``); pass 0 counts horizontal pairs, pass 1
    vertical ones, and L = ``n_labels`` exceeds every label."""
    height, width = labels.shape
    contacts = np.zeros((2, n_labels, n_labels), dtype=np.int64)
    fronts = np.zeros((2, n_labels, n_labels), dtype=np.int64)
    for direction in range(2):
        d_row, d_col = (0, 1) if direction == 0 else (1, 0)
        for row in range(height - d_row):
            for col in range(width - d_col):
                a = labels[row, col] if valid[row, col] else 0
                r, c = row + d_row, col + d_col
                b = labels[r, c] if valid[r, c] else 0
                if a == b or a <= 0 or b <= 0:
                    continue
                dx = points[row, col, 0] - points[r, c, 0]
                dy = points[row, col, 1] - points[r, c, 1]
                dz = points[row, col, 2] - points[r, c, 2]
                if np.sqrt(dx * dx + dy * dy + dz * dz) < contact_gap_m:
                    contacts[direction, min(a, b), max(a, b)] += 1
                step = depth_m[r, c] - depth_m[row, col]  # > 0: a is nearer; depth's dtype
                if front_low_m < abs(step) < front_high_m:
                    if step > 0:
                        fronts[direction, a, b] += 1
                    else:
                        fronts[direction, b, a] += 1
    return contacts, fronts


@_jit
def group_sums(groups: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """(count, C) sums of the rows of (N, C) ``values`` per group id (N,) in [0, count), in row
    order: ``np.bincount(groups, weights=values[:, c], minlength=count)`` for every column c
    in one pass (same bits)."""
    sums = np.zeros((count, values.shape[1]))
    for p in range(groups.shape[0]):
        for c in range(values.shape[1]):
            sums[groups[p], c] += values[p, c]
    return sums


@_jit
def voxel_keys(points: np.ndarray, pixels: np.ndarray, voxel_m: float):
    """Voxel keys (N,) int64 of the (P, 3) world points (m) at flat ``pixels`` (N,), and the
    grid's dims (3,): each point's cell floor(x / ``voxel_m``) shifted so that the smallest is
    1 on every axis (neighbour offsets never wrap), key (x * dims[1] + y) * dims[2] + z, with
    dims one more than the largest shifted cell on every axis."""
    count = pixels.shape[0]
    cells = np.empty((count, 3), dtype=np.int64)
    low = np.full(3, np.iinfo(np.int64).max, dtype=np.int64)
    high = np.full(3, np.iinfo(np.int64).min, dtype=np.int64)
    for p in range(count):
        for axis in range(3):
            cell = np.int64(np.floor(points[pixels[p], axis] / voxel_m))
            cells[p, axis] = cell
            low[axis] = min(low[axis], cell)
            high[axis] = max(high[axis], cell)
    dims = high - low + 3  # shifted cells run from 1 to high - low + 1
    keys = np.empty(count, dtype=np.int64)
    for p in range(count):
        x = cells[p, 0] - low[0] + 1
        y = cells[p, 1] - low[1] + 1
        z = cells[p, 2] - low[2] + 1
        keys[p] = (x * dims[1] + y) * dims[2] + z
    return keys, dims


@_jit
def pixel_changes(
    size: int,
    valid: np.ndarray,
    pixel: np.ndarray,
    z: np.ndarray,
    inside: np.ndarray,
    previous_depth: np.ndarray,
    previous_labels: np.ndarray,
    tolerance_m,
    tolerance_quadratic,
    near_m,
    states: tuple,
):
    """Per-pixel comparison of frame t with frame t-1 (``temporal.compare_frames`` documents
    it): pixel ``valid[k]`` (flat, of ``size`` pixels) with depth ``z[k]`` lands on flat pixel
    ``pixel[k]`` of frame t-1 where ``inside[k]``. Returns (size,) int8 states (``states`` =
    (unchanged, revealed, arrived, not compared); pixels without depth 0), (size,) int32 labels
    of frame t-1 there (0 where not compared) and (size,) bool "within ``near_m``". The
    tolerances are scalars of z's dtype, so the arithmetic is numpy's (same bits)."""
    unchanged, revealed, arrived, not_compared = states
    state = np.zeros(size, dtype=np.int8)
    previous_label = np.zeros(size, dtype=np.int32)
    near = np.zeros(size, dtype=np.bool_)
    for k in range(valid.shape[0]):
        before = previous_depth[pixel[k]]
        depth = z[k]
        if not (inside[k] and before > 0):
            state[valid[k]] = not_compared
            continue
        tolerance = tolerance_m + tolerance_quadratic * depth**2
        difference = depth - before
        if difference < -tolerance:
            state[valid[k]] = arrived
        elif difference > tolerance:
            state[valid[k]] = revealed
        else:
            state[valid[k]] = unchanged
        previous_label[valid[k]] = previous_labels[pixel[k]]
        near[valid[k]] = abs(difference) <= near_m
    return state, previous_label, near


@_jit
def grouped_order_statistic(groups: np.ndarray, values: np.ndarray, fraction: float):
    """The distinct ids (G,) of (N,) ``groups`` (ascending) and, for each, the value at
    position floor(``fraction`` * (n - 1)) of its n (N,) ``values`` sorted ascending (the
    lower of numpy's percentile neighbours)."""
    if groups.shape[0] == 0:
        return np.zeros(0, dtype=groups.dtype), np.zeros(0)
    lowest, highest = groups.min(), groups.max()
    sizes = np.zeros(highest - lowest + 2, dtype=np.int64)
    for group in groups:
        sizes[group - lowest + 1] += 1
    starts = np.cumsum(sizes)
    fill = starts[:-1].copy()
    grouped = np.empty(values.shape[0])
    for p in range(groups.shape[0]):
        slot = groups[p] - lowest
        grouped[fill[slot]] = values[p]
        fill[slot] += 1
    n_groups = 0
    for slot in range(highest - lowest + 1):
        n_groups += starts[slot + 1] > starts[slot]
    ids = np.empty(n_groups, dtype=groups.dtype)
    statistic = np.empty(n_groups)
    found = 0
    for slot in range(highest - lowest + 1):
        first, last = starts[slot], starts[slot + 1]
        if last == first:
            continue
        # A selection, not a sort: the value at that position of the sorted group.
        position = int(np.floor(fraction * (last - first - 1)))
        ids[found] = slot + lowest
        statistic[found] = np.partition(grouped[first:last], position)[position]
        found += 1
    return ids, statistic


@_jit
def connected_components(pairs: np.ndarray, count: int) -> np.ndarray:
    """(count,) int64 connected component of each node of the undirected graph with (E, 2)
    edges ``pairs``, numbered in the order of each component's smallest node (as scipy's
    ``connected_components`` numbers them): union-find whose roots are the smallest nodes."""
    parent = np.arange(count)
    for e in range(pairs.shape[0]):
        a, b = pairs[e, 0], pairs[e, 1]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a < b:
            parent[b] = a
        elif b < a:
            parent[a] = b
    component = np.empty(count, dtype=np.int64)
    n_components = 0
    for node in range(count):  # a root precedes its component's other nodes
        root = node
        while parent[root] != root:
            root = parent[root]
        if root == node:
            component[node] = n_components
            n_components += 1
        else:
            component[node] = component[root]
    return component


@_jit
def _block_sum(values: np.ndarray, start: int, count: int) -> float:
    """numpy's pairwise summation of at most 128 contiguous float64 ``values[start:start +
    count]``: below 8 values in order (from -0.0), else eight accumulators combined as a tree
    and the rest added in order (``_pairwise_sum``)."""
    if count < 8:
        result = -0.0
        for i in range(start, start + count):
            result += values[i]
        return result
    r0, r1, r2, r3 = values[start], values[start + 1], values[start + 2], values[start + 3]
    r4, r5, r6, r7 = values[start + 4], values[start + 5], values[start + 6], values[start + 7]
    i = 8
    while i < count - (count % 8):
        r0 += values[start + i]
        r1 += values[start + i + 1]
        r2 += values[start + i + 2]
        r3 += values[start + i + 3]
        r4 += values[start + i + 4]
        r5 += values[start + i + 5]
        r6 += values[start + i + 6]
        r7 += values[start + i + 7]
        i += 8
    result = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < count:
        result += values[start + i]
        i += 1
    return result


@_jit
def _pairwise_sum(values: np.ndarray, start: int, count: int) -> float:
    """numpy's pairwise summation (``np.add.reduce`` of contiguous float64) of
    ``values[start:start + count]``: up to 128 values ``_block_sum``, beyond that the sum of
    the two halves' sums (the first half a multiple of 8 long); the same additions in the
    same order, so the same bits. numpy recurses; here an explicit stack does (a cached numba
    kernel calling a recursive one crashed)."""
    if count <= 128:
        return _block_sum(values, start, count)
    starts = np.empty(64, dtype=np.int64)
    counts = np.empty(64, dtype=np.int64)
    stages = np.empty(64, dtype=np.int64)  # 0: new, 1: left half pending, 2: right pending
    lefts = np.empty(64)
    starts[0], counts[0], stages[0] = start, count, 0
    top = 1
    value = 0.0
    returned = False  # ``value`` holds the sum of the node just finished
    while top > 0:
        node = top - 1
        size = counts[node]
        half = size // 2
        half -= half % 8
        if size <= 128:
            value = _block_sum(values, starts[node], size)
            returned = True
            top -= 1
        elif not returned:  # a new node: its left half first
            stages[node] = 1
            starts[top], counts[top], stages[top] = starts[node], half, 0
            top += 1
        elif stages[node] == 1:  # the left half's sum: keep it, then the right half
            lefts[node] = value
            stages[node] = 2
            starts[top], counts[top], stages[top] = starts[node] + half, size - half, 0
            top += 1
            returned = False
        else:  # both halves done
            value = lefts[node] + value
            top -= 1
    return value


@_jit
def kmeans_plus_plus(points: np.ndarray, first: int, uniforms: np.ndarray):
    """k-means++ centres ((k, d), k = len(uniforms) + 1) of (m, d) points, from the first
    centre ``points[first]`` and one uniform draw in [0, 1) per further centre: each next
    centre is the point where the cumulative share of the squared distances to the nearest
    centre so far first exceeds the draw. ``segmentation.kmeans_labels``' numpy seeding, the
    same arithmetic in the same order (``np.sum(axis=1)`` and ``sum()`` by ``_pairwise_sum``,
    ``np.cumsum`` in order, ``searchsorted(side="right")``), in one pass. Returns the centres
    and how many were placed: fewer than k when the squared distances sum to 0 (every point
    on a centre), where numpy draws an index instead of a uniform (the caller redoes it)."""
    m, d = points.shape
    k = uniforms.shape[0] + 1
    centres = np.empty((k, d))
    for j in range(d):
        centres[0, j] = points[first, j]
    row = np.empty(d)
    closest = np.empty(m)
    for i in range(m):
        for j in range(d):
            difference = points[i, j] - centres[0, j]
            row[j] = difference * difference
        closest[i] = 0.0 + _pairwise_sum(row, 0, d)
    cdf = np.empty(m)
    for c in range(1, k):
        total = 0.0 + _pairwise_sum(closest, 0, m)
        if not total > 0:
            return centres, c
        running = 0.0
        for i in range(m):
            share = closest[i] / total
            running = share if i == 0 else running + share
            cdf[i] = running
        last = cdf[m - 1]
        for i in range(m):
            cdf[i] /= last
        draw = uniforms[c - 1]
        low, high = 0, m
        while low < high:  # the first entry above the draw (side="right")
            middle = (low + high) // 2
            if cdf[middle] <= draw:
                low = middle + 1
            else:
                high = middle
        for j in range(d):
            centres[c, j] = points[low, j]
        for i in range(m):
            for j in range(d):
                difference = points[i, j] - centres[c, j]
                row[j] = difference * difference
            distance = 0.0 + _pairwise_sum(row, 0, d)
            if distance < closest[i]:
                closest[i] = distance
    return centres, k


@_jit
def lloyd_iterations(points: np.ndarray, centres: np.ndarray, max_iterations: int):
    """Lloyd's k-means from the (k, d) ``centres`` (updated in place) on (m, d) ``points``:
    assign each point to its nearest centre (the first of equals), move each centre that kept
    points to their mean, until the assignment stops changing or ``max_iterations``. Returns
    the (m,) int64 labels and the inertia (sum of squared distances to the assigned centres,
    as |x|^2 - 2 x.c + |c|^2 clipped at 0, from the last assignment)."""
    m, d = points.shape
    k = centres.shape[0]
    labels = np.full(m, -1, dtype=np.int64)
    nearest = np.zeros(m)
    squared = np.zeros(m)
    for i in range(m):
        for j in range(d):
            squared[i] += points[i, j] * points[i, j]
    centre_squared = np.zeros(k)
    sums = np.zeros((k, d))
    counts = np.zeros(k)
    for _ in range(max_iterations):
        for c in range(k):
            centre_squared[c] = 0.0
            for j in range(d):
                centre_squared[c] += centres[c, j] * centres[c, j]
        changed = False
        for i in range(m):
            best, best_distance = 0, np.inf
            for c in range(k):
                dot = 0.0
                for j in range(d):
                    dot += points[i, j] * centres[c, j]
                distance = squared[i] - 2.0 * dot + centre_squared[c]
                if distance < best_distance:
                    best, best_distance = c, distance
            nearest[i] = best_distance
            if labels[i] != best:
                labels[i] = best
                changed = True
        if not changed:
            break
        sums[:] = 0.0
        counts[:] = 0.0
        for i in range(m):
            counts[labels[i]] += 1.0
            for j in range(d):
                sums[labels[i], j] += points[i, j]
        for c in range(k):
            if counts[c] > 0:  # an emptied cluster keeps its centre
                for j in range(d):
                    centres[c, j] = sums[c, j] / counts[c]
    inertia = 0.0
    for i in range(m):
        inertia += max(nearest[i], 0.0)
    return labels, inertia


@_jit
def rows_at(values: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """``values[indices]`` for (N, 3) ``values`` (float64 points, uint8 colours; the result
    keeps their dtype) and (K,) indices: numpy's fancy indexing of rows costs several times
    this loop on hundreds of thousands of rows."""
    out = np.empty((indices.shape[0], 3), dtype=values.dtype)
    for k in range(indices.shape[0]):
        for axis in range(3):
            out[k, axis] = values[indices[k], axis]
    return out


@_jit
def labels_of_keys(table: np.ndarray, keys: np.ndarray, label_of_cell: np.ndarray) -> np.ndarray:
    """(K,) int64 label of each of the (K,) int64 cell ``keys`` through a dense cell ->
    voxel ``table`` (-1 = no voxel) and the voxels' (V,) int64 labels, -1 where the cell has no
    voxel (``supervoxels.compute_supervoxels``: every kept pixel takes its voxel's label).
    The numpy expression it replaces::

        position = table[keys].astype(np.int64)
        np.where(position >= 0, label_of_cell[position], -1)
    """
    out = np.empty(keys.shape[0], dtype=np.int64)
    for k in range(keys.shape[0]):
        voxel = table[keys[k]]
        out[k] = label_of_cell[voxel] if voxel >= 0 else -1
    return out


@_jit
def dense_normalised_laplacian(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, scale: np.ndarray
) -> np.ndarray:
    """(m, m) float64 L_sym = I - D^-1/2 W D^-1/2 of the (m, m) float64 CSR matrix W
    (``indptr``, ``indices``, ``data``; duplicate entries summed in storage order, as scipy's
    ``toarray`` sums them) with ``scale`` (m,) = D^-1/2 (``segmentation.spectral_clusters``,
    dense solver). The numpy expression it replaces::

        np.eye(m) - (W.toarray() * scale[:, None]) * scale[None, :]
    """
    m = scale.shape[0]
    dense = np.zeros((m, m))
    for row in range(m):
        for entry in range(indptr[row], indptr[row + 1]):
            dense[row, indices[entry]] += data[entry]
    for row in range(m):
        for col in range(m):
            value = (dense[row, col] * scale[row]) * scale[col]
            dense[row, col] = (1.0 if row == col else 0.0) - value
    return dense


@_jit
def indices_above(
    points: np.ndarray, indices: np.ndarray, normal: np.ndarray, offset: float, clearance: float
) -> np.ndarray:
    """The (K,) ``indices`` whose (N, 3) points lie at least ``clearance`` (m) above the plane
    {x : normal . x + offset = 0} (positive side), in order: ``indices[points[indices] @ normal
    + offset >= clearance]`` in one pass."""
    found = np.empty(indices.shape[0], dtype=indices.dtype)
    count = 0
    for k in range(indices.shape[0]):
        i = indices[k]
        if _dot(points, i, normal) + offset >= clearance:
            found[count] = i
            count += 1
    return found[:count].copy()


@_jit
def supervoxel_anchor_counts(
    flat_supervoxel: np.ndarray,
    state: np.ndarray,
    label: np.ndarray,
    near: np.ndarray,
    count: int,
    n_labels: int,
    states: tuple,
    min_pixels: int,
    static_fraction: float,
):
    """The pixel counts of ``temporal.supervoxel_anchors`` (which documents the rules) in two
    passes over the (P,) pixels: ``flat_supervoxel`` (-1 = none), ``state`` (int8 states,
    ``states`` = (not compared, unchanged, revealed, arrived)), ``label`` (previous segment,
    0 = none, < ``n_labels``) and ``near`` (bool). Returns, per supervoxel (``count``): the
    compatible and incompatible pixel counts (int64), the (count, n_labels) table of unchanged
    pixels of segments that stayed, and the pixel count."""
    not_compared, unchanged, revealed, arrived = states
    unchanged_per_label = np.zeros(n_labels, dtype=np.int64)
    compared_per_label = np.zeros(n_labels, dtype=np.int64)
    for p in range(state.shape[0]):
        if state[p] == unchanged:
            unchanged_per_label[label[p]] += 1
        if state[p] != not_compared:
            compared_per_label[label[p]] += 1
    stayed = np.zeros(n_labels, dtype=np.bool_)
    for segment in range(1, n_labels):
        stayed[segment] = (unchanged_per_label[segment] >= min_pixels) and (
            unchanged_per_label[segment] >= static_fraction * compared_per_label[segment]
        )
    compatible = np.zeros(count, dtype=np.int64)
    incompatible = np.zeros(count, dtype=np.int64)
    table = np.zeros((count, n_labels), dtype=np.int64)
    pixels = np.zeros(count, dtype=np.int64)
    for p in range(state.shape[0]):
        supervoxel = flat_supervoxel[p]
        if supervoxel < 0:
            continue
        pixels[supervoxel] += 1
        segment = label[p]
        segment_stayed = stayed[segment]
        shifted = state[p] == arrived and near[p] and segment_stayed
        if state[p] == unchanged:
            if segment_stayed or segment == 0:
                compatible[supervoxel] += 1
            else:
                incompatible[supervoxel] += 1
            if segment_stayed:
                table[supervoxel, segment] += 1
        elif state[p] == revealed or shifted:
            compatible[supervoxel] += 1
        elif state[p] == arrived:
            incompatible[supervoxel] += 1
    return compatible, incompatible, table, pixels


@_jit
def vertical_plane_coordinates(
    points: np.ndarray,
    point_normals: np.ndarray,
    unknown: np.ndarray,
    heights: np.ndarray,
    normal: np.ndarray,
    offset: float,
    along: np.ndarray,
    threshold_m: float,
    max_height_m: float,
    min_cos: float,
    use_normals: bool,
):
    """For (N, 3) points (m) and a vertical plane (unit ``normal``, ``offset``) with the
    horizontal direction ``along`` it: each point's signed depth (N,) in front of the plane,
    its position (N,) along it, and whether it lies on the plane's face (N,) bool: within
    ``threshold_m`` of it, below ``max_height_m`` (``heights`` (N,) above the support) and,
    with ``use_normals``, facing the plane's way (within acos(``min_cos``) of +-normal) or
    of ``unknown`` normal (``planes._wall_cues``)."""
    count = points.shape[0]
    depth = np.empty(count)
    position = np.empty(count)
    on_plane = np.empty(count, dtype=np.bool_)
    for p in range(count):
        depth[p] = _dot(points, p, normal) + offset
        position[p] = _dot(points, p, along)
        inside = abs(depth[p]) < threshold_m and heights[p] < max_height_m
        if inside and use_normals and not unknown[p]:
            inside = abs(_dot(point_normals, p, normal)) > min_cos
        on_plane[p] = inside
    return depth, position, on_plane


@_jit
def mark_wall_slab(
    depth: np.ndarray,
    position: np.ndarray,
    heights: np.ndarray,
    front_m: float,
    back_m: float,
    start: float,
    end: float,
    column_top: np.ndarray,
    top_margin_m: float,
    mask: np.ndarray,
) -> None:
    """Set ``mask`` (N,) bool True, in place, at the points in a wall's static slab
    (``planes.static_geometry_mask``): signed ``depth`` (N,) in (``back_m``, ``front_m``),
    ``position`` (N,) along the wall in (``start``, ``end``) and height (``heights`` (N,) above
    the support) below ``column_top`` (C,) of their 2 cm column (from ``start``) plus
    ``top_margin_m``. The depths and positions stay numpy's products (OpenBLAS's fused
    multiply-adds, whose order a loop does not reproduce bit for bit). The numpy expression it
    replaces::

        candidate = np.flatnonzero(
            (depth < front_m) & (depth > back_m) & (position > start) & (position < end)
        )
        local_top = column_top[((position[candidate] - start) / 0.02).astype(np.int64)]
        mask[candidate[heights[candidate] < local_top + top_margin_m]] = True

    (a column index past the table, where numpy would raise, reads the last column)."""
    last = column_top.shape[0] - 1
    for p in range(depth.shape[0]):
        if depth[p] < front_m and depth[p] > back_m and position[p] > start and position[p] < end:
            column = min(int((position[p] - start) / 0.02), last)
            if heights[p] < column_top[column] + top_margin_m:
                mask[p] = True


@_jit
def outside_slab(
    points: np.ndarray,
    point_normals: np.ndarray,
    unknown: np.ndarray,
    pool: np.ndarray,
    normal: np.ndarray,
    offset: float,
    front_m: float,
    back_m: float,
    min_cos: float,
    use_normals: bool,
) -> np.ndarray:
    """The (K,) ``pool`` indices of (N, 3) points that stay in the wall search after a wall
    (unit ``normal``, ``offset``) was found: those not in its slab (depth in
    (-``back_m``, ``front_m``)) or, with ``use_normals``, in it but not facing its way
    (``_facing``: within acos(``min_cos``) of +-normal, or ``unknown``)."""
    kept = np.empty(pool.shape[0], dtype=pool.dtype)
    count = 0
    for k in range(pool.shape[0]):
        p = pool[k]
        depth = _dot(points, p, normal) + offset
        done = depth < front_m and depth > -back_m
        if done and use_normals and not unknown[p]:
            done = abs(_dot(point_normals, p, normal)) > min_cos
        if not done:
            kept[count] = p
            count += 1
    return kept[:count].copy()


@_jit
def project_to_previous(
    depth_m: np.ndarray,
    valid: np.ndarray,
    ray_x: np.ndarray,
    ray_y: np.ndarray,
    relative: np.ndarray,
    previous_K: np.ndarray,
    previous_height: int,
    previous_width: int,
):
    """Where each ``valid`` pixel (K,) (flat) of a (H, W) float32 depth image lands in the
    previous camera: its flat pixel there (K,) int64 (0 where not ``inside``), its depth there
    z (K,) float32 and whether it is inside that image and in front of the camera (K,) bool.
    ``ray_x`` (W,) and ``ray_y`` (H,) float32 are the pixel grid's (c - cx) / fx, ``relative``
    (4, 4) float32 the previous camera from this one and ``previous_K`` (3, 3) float32. All in
    float32, operation by operation as ``temporal.compare_frames``'s numpy version."""
    height, width = depth_m.shape
    count = valid.shape[0]
    pixel = np.zeros(count, dtype=np.int64)
    z_out = np.empty(count, dtype=np.float32)
    inside = np.zeros(count, dtype=np.bool_)
    one = np.float32(1.0)
    for k in range(count):
        row, col = valid[k] // width, valid[k] % width
        z_now = depth_m[row, col]
        x_now = ray_x[col] * z_now
        y_now = ray_y[row] * z_now
        x = (
            relative[0, 0] * x_now
            + relative[0, 1] * y_now
            + relative[0, 2] * z_now
            + relative[0, 3]
        )
        y = (
            relative[1, 0] * x_now
            + relative[1, 1] * y_now
            + relative[1, 2] * z_now
            + relative[1, 3]
        )
        z = (
            relative[2, 0] * x_now
            + relative[2, 1] * y_now
            + relative[2, 2] * z_now
            + relative[2, 3]
        )
        z_out[k] = z
        if not z > np.float32(1e-6):
            continue
        inverse_z = one / z
        u = np.rint(x * inverse_z * previous_K[0, 0] + previous_K[0, 2])
        v = np.rint(y * inverse_z * previous_K[1, 1] + previous_K[1, 2])
        if u >= 0 and u < previous_width and v >= 0 and v < previous_height:
            inside[k] = True
            pixel[k] = np.int64(v) * previous_width + np.int64(u)
    return pixel, z_out, inside


@_jit
def labelled_order(flat_labels: np.ndarray, valid: np.ndarray):
    """The pixels with a label > 0 and a reading, grouped by label: ``order`` (N,) int64 flat
    indices, ``ids`` (K,) the distinct labels ascending and ``starts`` (K,) int64 where each
    label's pixels begin in ``order``. A counting sort, stable: the same as
    ``labelled = np.flatnonzero((flat_labels > 0) & valid)``, ``order =
    labelled[np.argsort(flat_labels[labelled], kind="stable")]`` and ``ids, starts =
    np.unique(flat_labels[order], return_index=True)`` without the sort."""
    highest = 0
    for p in range(flat_labels.shape[0]):
        if flat_labels[p] > highest and valid[p]:
            highest = flat_labels[p]
    counts = np.zeros(highest + 1, dtype=np.int64)
    for p in range(flat_labels.shape[0]):
        label = flat_labels[p]
        if label > 0 and valid[p]:
            counts[label] += 1
    n_ids = 0
    for label in range(1, highest + 1):
        n_ids += counts[label] > 0
    ids = np.empty(n_ids, dtype=flat_labels.dtype)
    starts = np.empty(n_ids, dtype=np.int64)
    fill = np.zeros(highest + 1, dtype=np.int64)
    total = 0
    found = 0
    for label in range(1, highest + 1):
        if counts[label] > 0:
            ids[found] = label
            starts[found] = total
            found += 1
        fill[label] = total
        total += counts[label]
    order = np.empty(total, dtype=np.int64)
    for p in range(flat_labels.shape[0]):
        label = flat_labels[p]
        if label > 0 and valid[p]:
            order[fill[label]] = p
            fill[label] += 1
    return order, ids, starts


@_jit
def distinct_per_slice(values: np.ndarray, starts: np.ndarray, ends: np.ndarray, count: int):
    """The distinct values >= 0 (ascending) of each slice ``values[starts[k]:ends[k]]`` of
    (N,) int ``values`` in [-1, ``count``): ``np.unique(part[part >= 0])`` of every slice, as
    one (D,) array of their dtype and (K + 1,) int64 bounds (slice k's at ``bounds[k]:bounds[k + 1]``).
    A mark per value instead of a sort of every slice."""
    seen = np.zeros(count, dtype=np.bool_)
    distinct = np.empty(values.shape[0], dtype=values.dtype)
    bounds = np.zeros(starts.shape[0] + 1, dtype=np.int64)
    total = 0
    for k in range(starts.shape[0]):
        first = total
        for p in range(starts[k], ends[k]):
            value = values[p]
            if value >= 0 and not seen[value]:
                seen[value] = True
                distinct[total] = value
                total += 1
        distinct[first:total].sort()
        for d in range(first, total):
            seen[distinct[d]] = False
        bounds[k + 1] = total
    return distinct[:total].copy(), bounds


@_jit
def region_groups(point_region: np.ndarray, points: np.ndarray, areas: np.ndarray, count: int):
    """The (N,) points grouped by region id in [-1, ``count``): ``by_region`` (N,) int64 as
    ``np.argsort(point_region, kind="stable")`` (a counting sort: region -1 first), ``bounds``
    (count + 1,) int64 where region r's points begin in it (``np.searchsorted`` of the sorted
    regions), ``grouped`` (N, 3) ``points[by_region]``, and ``region_sums``'s counts, point
    sums and area sums of the points of each region id >= 0, added in point order."""
    n = point_region.shape[0]
    starts = np.zeros(count + 2, dtype=np.int64)  # slot 0: region -1
    for p in range(n):
        starts[point_region[p] + 2] += 1
    for slot in range(1, count + 2):
        starts[slot] += starts[slot - 1]
    fill = starts[: count + 1].copy()
    by_region = np.empty(n, dtype=np.int64)
    grouped = np.empty((n, 3))
    sizes = np.zeros(count, dtype=np.int64)
    sums = np.zeros((count, 3))
    area_sums = np.zeros(count)
    for p in range(n):
        region = point_region[p]
        slot = fill[region + 1]
        fill[region + 1] += 1
        by_region[slot] = p
        for axis in range(3):
            grouped[slot, axis] = points[p, axis]
        if region < 0:
            continue
        sizes[region] += 1
        area_sums[region] += areas[p]
        for axis in range(3):
            sums[region, axis] += points[p, axis]
    return by_region, starts[1:].copy(), grouped, sizes, sums, area_sums


@_jit
def count_key_states(
    keys: np.ndarray, offset: np.ndarray, state: np.ndarray, value: int, bits: int
) -> int:
    """Number of voxel keys (N,) int64 (``ipr_shapes.voxels.pack``, ``bits`` per axis) whose
    voxel, at integer index minus ``offset`` (3,) int64 in the (nx, ny, nz) uint8 ``state``
    grid, holds ``value`` (voxels outside the grid hold none): ``np.count_nonzero(
    occupancy._states(space, keys, pitch) == value)`` for a lattice-aligned grid, with no
    (N, 3) index temporaries."""
    nx, ny, nz = state.shape
    half = np.int64(1) << (bits - 1)
    mask = (np.int64(1) << bits) - 1
    count = 0
    for n in range(keys.shape[0]):
        key = keys[n]
        i = (key >> (2 * bits)) - half - offset[0]
        j = ((key >> bits) & mask) - half - offset[1]
        k = (key & mask) - half - offset[2]
        if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz and state[i, j, k] == value:
            count += 1
    return count


@_jit
def thin_edges(magnitude: np.ndarray, direction: np.ndarray, at: np.ndarray) -> np.ndarray:
    """(H, W) bool: of the pixels ``at`` (int64 flat indices into the (H, W) float32
    ``magnitude``), those whose magnitude is at least that of both neighbours across the edge
    (Canny's non-maximum suppression), the gradient ``direction`` ((H, W) float32, rad)
    quantised to 45 degrees as ``np.round(direction / (np.pi / 4)) % 4`` in float32
    (half to even), neighbours outside the image 0. The seams' ``_thin`` without its
    temporaries (every frame, strong and faint pixels)."""
    return thin_edges_in_sectors(magnitude, direction, at, np.full(at.shape[0], -1, np.int8))


@_jit
def thin_edges_in_sectors(
    magnitude: np.ndarray, direction: np.ndarray, at: np.ndarray, sectors: np.ndarray
) -> np.ndarray:
    """``thin_edges`` with each pixel's sector given ((N,) int8, 0-3: ``gradient_sectors``),
    or -1 where it is read from ``direction`` as ``thin_edges`` does."""
    height, width = magnitude.shape
    edges = np.zeros((height, width), dtype=np.bool_)
    quarter = np.float32(np.pi / 4)
    for k in range(at.shape[0]):
        index = at[k]
        r = index // width
        c = index - r * width
        sector = np.int64(sectors[k])
        if sector < 0:
            q = np.float64(np.float32(direction[r, c]) / quarter)
            rounded = np.floor(q + 0.5)
            if q + 0.5 == rounded and rounded % 2.0 != 0.0:
                rounded -= 1.0  # half to even, as np.round
            sector = int(rounded % 4.0)
        if sector == 0:
            dy, dx = 0, 1
        elif sector == 1:
            dy, dx = 1, 1
        elif sector == 2:
            dy, dx = 1, 0
        else:
            dy, dx = 1, -1
        value = magnitude[r, c]
        ahead = np.float32(0.0)
        if 0 <= r + dy < height and 0 <= c + dx < width:
            ahead = magnitude[r + dy, c + dx]
        behind = np.float32(0.0)
        if 0 <= r - dy < height and 0 <= c - dx < width:
            behind = magnitude[r - dy, c - dx]
        if value >= ahead and value >= behind:
            edges[r, c] = True
    return edges


@_jit
def gradient_sectors(gx: np.ndarray, gy: np.ndarray, at: np.ndarray, tangents: np.ndarray):
    """(N,) int8: the 45 degree sector of ``thin_edges`` (0: the gradient along x, 1: along
    x = y, 2: along y, 3: along x = -y) of the gradient (gx, gy) ((H, W) float32, not both 0)
    at each of the pixels ``at`` ((N,) int64 flat indices), read from the components without
    an arctangent: sector 0 when |gy| < |gx| tan(22.5 deg - d), 2 when |gy| > |gx| tan(67.5
    deg + d), 1 or 3 (by the components' signs) between tan(22.5 deg + d) and tan(67.5 deg -
    d); -1 within d of a boundary (``tangents``: those four tangents, float64), where the
    float32 arctangent's rounding decides and the caller measures it."""
    width = gx.shape[1]
    out = np.empty(at.shape[0], dtype=np.int8)
    for k in range(at.shape[0]):
        index = at[k]
        r = index // width
        c = index - r * width
        x = np.float64(gx[r, c])
        y = np.float64(gy[r, c])
        a = abs(x)
        b = abs(y)
        if b < a * tangents[0]:
            out[k] = 0
        elif b > a * tangents[3]:
            out[k] = 2
        elif b > a * tangents[1] and b < a * tangents[2]:
            out[k] = 1 if (x > 0.0) == (y > 0.0) else 3
        else:
            out[k] = -1
    return out


@_jit
def linked_to(pixels: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of the (H, W) bool ``pixels`` 8-connected through ``pixels`` to
    a pixel of ``seeds`` ((H, W) bool) that is in ``pixels``: the union of the components of
    ``scipy.ndimage.label(pixels, np.ones((3, 3)))`` that hold a seed, by one flood fill from
    the seeds instead of labelling the whole frame (Canny's hysteresis in the seams)."""
    height, width = pixels.shape
    reached = np.zeros((height, width), dtype=np.bool_)
    stack = np.empty(height * width, dtype=np.int64)
    top = 0
    for r in range(height):
        for c in range(width):
            if seeds[r, c] and pixels[r, c] and not reached[r, c]:
                reached[r, c] = True
                stack[top] = r * width + c
                top += 1
    while top > 0:
        top -= 1
        r = stack[top] // width
        c = stack[top] - r * width
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr, cc = r + dr, c + dc
                if 0 <= rr < height and 0 <= cc < width and pixels[rr, cc] and not reached[rr, cc]:
                    reached[rr, cc] = True
                    stack[top] = rr * width + cc
                    top += 1
    return reached


@_jit
def dilate_diamond(mask: np.ndarray, radius: int) -> np.ndarray:
    """(H, W) bool: the pixels within city-block distance ``radius`` of a pixel of ``mask``:
    ``scipy.ndimage.binary_dilation(mask, iterations=radius)`` (its default cross, border 0),
    by the two-pass city-block distance transform (the seams' ring around the segments, every
    frame)."""
    height, width = mask.shape
    far = height + width + radius + 1
    distance = np.empty((height, width), dtype=np.int64)
    for r in range(height):
        for c in range(width):
            if mask[r, c]:
                distance[r, c] = 0
            else:
                best = far
                if r > 0 and distance[r - 1, c] + 1 < best:
                    best = distance[r - 1, c] + 1
                if c > 0 and distance[r, c - 1] + 1 < best:
                    best = distance[r, c - 1] + 1
                distance[r, c] = best
    out = np.zeros((height, width), dtype=np.bool_)
    for r in range(height - 1, -1, -1):
        for c in range(width - 1, -1, -1):
            best = distance[r, c]
            if r + 1 < height and distance[r + 1, c] + 1 < best:
                best = distance[r + 1, c] + 1
            if c + 1 < width and distance[r, c + 1] + 1 < best:
                best = distance[r, c + 1] + 1
            distance[r, c] = best
            out[r, c] = best <= radius
    return out


@_jit
def erode_diamond(mask: np.ndarray, radius: int) -> np.ndarray:
    """(h, w) bool: the pixels of ``mask`` whose every pixel within city-block distance
    ``radius`` lies inside the grid and in ``mask``: ``scipy.ndimage.binary_erosion(mask,
    iterations=radius)`` (its default cross, border 0), whose iterated crosses are that
    diamond. One pass with a row's run of ``mask`` pixels (the seams' ``_best_cut``, once per
    search)."""
    height, width = mask.shape
    # Each pixel's run of mask pixels to its left and right (inclusive), so that a row span
    # [c - k, c + k] is inside when both runs reach k.
    left = np.zeros((height, width), dtype=np.int64)
    right = np.zeros((height, width), dtype=np.int64)
    for r in range(height):
        run = 0
        for c in range(width):
            run = run + 1 if mask[r, c] else 0
            left[r, c] = run
        run = 0
        for c in range(width - 1, -1, -1):
            run = run + 1 if mask[r, c] else 0
            right[r, c] = run
    out = np.zeros((height, width), dtype=np.bool_)
    for r in range(radius, height - radius):
        for c in range(radius, width - radius):
            if not mask[r, c]:
                continue
            inside = True
            for dr in range(-radius, radius + 1):
                k = radius - abs(dr)
                if left[r + dr, c] <= k or right[r + dr, c] <= k:
                    inside = False
                    break
            out[r, c] = inside
    return out


@_jit
def label_four_connected(mask: np.ndarray):
    """(h, w) int32 labels of the 4-connected components of the (h, w) bool ``mask`` (0
    outside) and their count: ``scipy.ndimage.label(mask)`` (its default cross structure), the
    components numbered 1.. in the order of their first pixel in row-major order, as scipy
    numbers them. One flood fill per component instead of scipy's two passes and its
    set-up per call: the seams' ``_split`` labels the pieces of every candidate cut."""
    height, width = mask.shape
    labels = np.zeros((height, width), dtype=np.int32)
    stack = np.empty(height * width, dtype=np.int64)
    count = 0
    for r0 in range(height):
        for c0 in range(width):
            if not mask[r0, c0] or labels[r0, c0] != 0:
                continue
            count += 1
            labels[r0, c0] = count
            top = 0
            stack[0] = r0 * width + c0
            top = 1
            while top > 0:
                top -= 1
                r, c = divmod(stack[top], width)
                if r > 0 and mask[r - 1, c] and labels[r - 1, c] == 0:
                    labels[r - 1, c] = count
                    stack[top] = (r - 1) * width + c
                    top += 1
                if r + 1 < height and mask[r + 1, c] and labels[r + 1, c] == 0:
                    labels[r + 1, c] = count
                    stack[top] = (r + 1) * width + c
                    top += 1
                if c > 0 and mask[r, c - 1] and labels[r, c - 1] == 0:
                    labels[r, c - 1] = count
                    stack[top] = r * width + c - 1
                    top += 1
                if c + 1 < width and mask[r, c + 1] and labels[r, c + 1] == 0:
                    labels[r, c + 1] = count
                    stack[top] = r * width + c + 1
                    top += 1
    return labels, count


@_jit
def largest_inscribed_squared(inside: np.ndarray, occupied: np.ndarray) -> int:
    """The largest squared Euclidean distance (px^2, exact integer) from a pixel of ``inside``
    to the nearest pixel of the (h, w) bool grid that is not ``occupied``: the square of
    ``scipy.ndimage.distance_transform_edt(occupied)[inside].max()`` (which is the root of
    the same integer), -1 when every pixel is occupied or none is inside. Felzenszwalb and
    Huttenlocher's two passes (column distances, then the lower envelope of parabolas along
    each row) in integers, the envelope's breakpoints compared as fractions: the seams'
    ``_split`` asks this once per candidate cut (the width of a piece)."""
    height, width = inside.shape
    big = height + width + 1
    column = np.empty((height, width), dtype=np.int64)
    any_free = False
    for c in range(width):
        last = -1
        for r in range(height):
            if not occupied[r, c]:
                last = r
                any_free = True
            column[r, c] = r - last if last >= 0 else big
        last = -1
        for r in range(height - 1, -1, -1):
            if not occupied[r, c]:
                last = r
            if last >= 0 and last - r < column[r, c]:
                column[r, c] = last - r
    if not any_free:
        return -1
    best = -1
    vertex = np.empty(width, dtype=np.int64)
    cut_num = np.empty(width + 1, dtype=np.int64)  # breakpoint k: cut_num[k] / cut_den[k]
    cut_den = np.empty(width + 1, dtype=np.int64)
    for r in range(height):
        wanted = False
        for c in range(width):
            if inside[r, c]:
                wanted = True
                break
        if not wanted:
            continue
        k = -1
        for q in range(width):
            if column[r, q] >= big:
                continue
            f_q = column[r, q] * column[r, q] + q * q
            while k >= 0:
                p = vertex[k]
                num = f_q - (column[r, p] * column[r, p] + p * p)
                den = 2 * (q - p)
                # The new parabola takes over where it is below vertex k's: drop k when that
                # is at or before vertex k's own start.
                if k > 0 and num * cut_den[k] <= cut_num[k] * den:
                    k -= 1
                else:
                    break
            if k < 0:
                k = 0
                vertex[0] = q
            else:
                p = vertex[k]
                k += 1
                vertex[k] = q
                cut_num[k] = f_q - (column[r, p] * column[r, p] + p * p)
                cut_den[k] = 2 * (q - p)
        k_top = k
        k = 0
        for c in range(width):
            while k < k_top and cut_num[k + 1] < c * cut_den[k + 1]:
                k += 1
            if inside[r, c]:
                p = vertex[k]
                squared = (c - p) * (c - p) + column[r, p] * column[r, p]
                if squared > best:
                    best = squared
    return best


@_jit
def seam_side_bands(
    rows: np.ndarray,
    cols: np.ndarray,
    box: np.ndarray,
    cos_a: float,
    sin_a: float,
    rho: float,
    along_range: np.ndarray,
    near: float,
    far: float,
):
    """Positions in (rows, cols) ((N,) int64 pixels, any order kept) of the pixels in the
    bands beside a seam on the line x cos a + y sin a = rho: inside ``box`` (top, bottom,
    left, right; half-open), ``along_range`` (lowest, highest) of -x sin a + y cos a, and
    across = x cos a + y sin a - rho in [near, far] (side one) or in [-far, -near] (side
    two). The masks of the numpy expressions ``across = xx * cos_a + yy * sin_a - rho`` and
    ``along = -xx * sin_a + yy * cos_a`` with the same operations in the same order."""
    n = rows.shape[0]
    side_a = np.empty(n, dtype=np.int64)
    side_b = np.empty(n, dtype=np.int64)
    count_a = 0
    count_b = 0
    for i in range(n):
        y = rows[i]
        x = cols[i]
        if y < box[0] or y >= box[1] or x < box[2] or x >= box[3]:
            continue
        along = float(-x) * sin_a + float(y) * cos_a
        if along < along_range[0] or along > along_range[1]:
            continue
        across = float(x) * cos_a + float(y) * sin_a - rho
        if across >= near and across <= far:
            side_a[count_a] = i
            count_a += 1
        elif -across >= near and -across <= far:
            side_b[count_b] = i
            count_b += 1
    return side_a[:count_a].copy(), side_b[:count_b].copy()


@_jit
def _reflected(index: int, length: int) -> int:
    """``index`` folded into [0, length) as scipy.ndimage's mode "reflect" (d c b a | a b c d),
    for overshoots up to ``length``."""
    if index < 0:
        return -index - 1
    if index >= length:
        return 2 * length - index - 1
    return index


@_jit
def _padded(plane: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """(H + 2 rows, W + 2 cols) copy of the (H, W) float32 ``plane`` with reflected borders."""
    height, width = plane.shape
    out = np.empty((height + 2 * rows, width + 2 * cols), dtype=np.float32)
    for y in range(height + 2 * rows):
        source_y = _reflected(y - rows, height)
        for x in range(width):
            out[y, x + cols] = plane[source_y, x]
        for x in range(cols):
            out[y, x] = plane[source_y, _reflected(x - cols, width)]
            out[y, width + cols + x] = plane[source_y, _reflected(width + x, width)]
    return out


@_jit
def colour_gradient(rgb: np.ndarray, weights: np.ndarray):
    """Sobel x and y components (H, W) float32 of the colour channel whose squared gradient is
    largest at each pixel (the first of equals), of the (H, W, 3) uint8 image in [0, 1] smoothed
    by the symmetric (2r + 1,) float64 ``weights`` (a Gaussian's) along columns and rows. The
    same numbers as ``scipy.ndimage.gaussian_filter(rgb.astype(np.float32) / 255.0, sigma=(s, s,
    0))`` followed by ``ndimage.sobel`` per channel and ``np.argmax`` of ``gx**2 + gy**2``: each
    1D pass in scipy's order of operations (``NI_Correlate1D``: the centre tap, then each pair
    of mirrored taps from the outside in, summed in float64 and stored as float32), borders
    reflected. Needs H, W > r. One compiled pass per filter instead of numpy's temporaries
    (the seams' edges, every frame); the borders are reflected by index (a padded copy of one
    row at most), and the last Sobel passes and the channels' comparison share one pass."""
    height, width = rgb.shape[0], rgb.shape[1]
    radius = weights.shape[0] // 2
    best_x = np.zeros((height, width), dtype=np.float32)
    best_y = np.zeros((height, width), dtype=np.float32)
    best = np.zeros((height, width), dtype=np.float32)
    image = np.empty((height, width), dtype=np.float32)
    plane = np.empty((height, width), dtype=np.float32)
    smooth = np.empty((height + 2, width + 2), dtype=np.float32)
    first_x = np.empty((height + 2, width), dtype=np.float32)
    first_y = np.empty((height, width + 2), dtype=np.float32)
    row = np.empty(width + 2 * radius, dtype=np.float32)
    gx = np.empty(width, dtype=np.float32)
    gy = np.empty(width, dtype=np.float32)
    sums = np.empty(width, dtype=np.float64)
    # Each 8-bit value in [0, 1] as float32 (the same bits as float32(v) / float32(255)).
    scale = np.float32(255.0)
    level = np.empty(256, dtype=np.float32)
    for value in range(256):
        level[value] = np.float32(value) / scale
    for channel in range(3):
        for y in range(height):
            for x in range(width):
                image[y, x] = level[rgb[y, x, channel]]
        # Gaussian along the columns (axis 0), rows reflected at the borders.
        # (Each pixel's sum in a row of accumulators: the taps in scipy's order per pixel.)
        for y in range(height):
            for x in range(width):
                sums[x] = np.float64(image[y, x]) * weights[radius]
            for j in range(radius, 0, -1):
                weight = weights[radius - j]
                above = _reflected(y - j, height)
                below = _reflected(y + j, height)
                for x in range(width):
                    sums[x] += (np.float64(image[above, x]) + np.float64(image[below, x])) * weight
            for x in range(width):
                plane[y, x] = np.float32(sums[x])
        # Then along the rows (axis 1), each row padded by reflection.
        for y in range(height):
            for x in range(width):
                row[x + radius] = plane[y, x]
            for x in range(radius):
                row[x] = plane[y, _reflected(x - radius, width)]
                row[width + radius + x] = plane[y, _reflected(width + x, width)]
            for x in range(width):
                sums[x] = np.float64(row[x + radius]) * weights[radius]
            for j in range(radius, 0, -1):
                weight = weights[radius - j]
                for x in range(width):
                    sums[x] += (
                        np.float64(row[x + radius - j]) + np.float64(row[x + radius + j])
                    ) * weight
            # Padded by one for the Sobel passes.
            for x in range(width):
                smooth[y + 1, x + 1] = np.float32(sums[x])
            smooth[y + 1, 0] = smooth[y + 1, 1]
            smooth[y + 1, width + 1] = smooth[y + 1, width]
        for x in range(width + 2):
            smooth[0, x] = smooth[1, x]
            smooth[height + 1, x] = smooth[height, x]
        # The Sobel passes' first halves: x: [-1, 0, 1] along the rows; y: along the columns
        # (each padded by one for its second half).
        for y in range(height):
            for x in range(width):
                total = np.float64(smooth[y + 1, x + 1]) * 0.0
                total += (np.float64(smooth[y + 1, x]) - np.float64(smooth[y + 1, x + 2])) * -1.0
                first_x[y + 1, x] = np.float32(total)
            for x in range(width):
                total = np.float64(smooth[y + 1, x + 1]) * 0.0
                total += (np.float64(smooth[y, x + 1]) - np.float64(smooth[y + 2, x + 1])) * -1.0
                first_y[y, x + 1] = np.float32(total)
            first_y[y, 0] = first_y[y, 1]
            first_y[y, width + 1] = first_y[y, width]
        for x in range(width):
            first_x[0, x] = first_x[1, x]
            first_x[height + 1, x] = first_x[height, x]
        # Their second halves: x: [1, 2, 1] along the columns; y: along the rows. And the
        # channel with the largest square.
        for y in range(height):
            for x in range(width):
                total = np.float64(first_x[y + 1, x]) * 2.0
                total += (np.float64(first_x[y, x]) + np.float64(first_x[y + 2, x])) * 1.0
                gx[x] = np.float32(total)
            for x in range(width):
                total = np.float64(first_y[y, x + 1]) * 2.0
                total += (np.float64(first_y[y, x]) + np.float64(first_y[y, x + 2])) * 1.0
                gy[x] = np.float32(total)
            for x in range(width):
                square = gx[x] * gx[x] + gy[x] * gy[x]
                if channel == 0 or square > best[y, x]:
                    best[y, x] = square
                    best_x[y, x] = gx[x]
                    best_y[y, x] = gy[x]
    return best_x, best_y


@_jit
def colour_gradient_at(
    rgb: np.ndarray, weights: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    """(N,) float64 gradient magnitudes of ``colour_gradient`` at the N pixels (rows, cols)
    (int64) of the (H, W, 3) uint8 image only: the same filters (the symmetric (2r + 1,)
    ``weights`` along columns and rows, Sobel, the channel with the largest squared gradient,
    borders reflected), summed in float64 per pixel (not float32 per pass: equal to
    ``np.hypot`` of ``colour_gradient``'s components within float32 rounding). For a noise
    scale from a sample of the frame (``seams._edge_noise``) without the frame's gradient."""
    height, width = rgb.shape[0], rgb.shape[1]
    radius = weights.shape[0] // 2
    out = np.zeros(rows.shape[0])
    smooth = np.empty((3, 3))
    sums = np.empty(2 * radius + 3)
    for i in range(rows.shape[0]):
        best = -1.0
        for channel in range(3):
            # The smoothed image at the pixel's 3 x 3 neighbourhood (each neighbour's position
            # reflected, then its taps: the Sobel pass reads the smoothed image's border),
            # along the columns, then along the rows.
            inside = (radius < rows[i] < height - radius - 1) and (
                radius < cols[i] < width - radius - 1
            )
            if inside:
                # Away from the border: the columns' sums shared by the three neighbours.
                for dy in range(3):
                    for xx in range(2 * radius + 3):
                        column = 0.0
                        for j in range(-radius, radius + 1):
                            column += (
                                weights[j + radius]
                                * rgb[rows[i] + dy - 1 + j, cols[i] + xx - radius - 1, channel]
                            )
                        sums[xx] = column
                    for dx in range(3):
                        total = 0.0
                        for k in range(-radius, radius + 1):
                            total += weights[k + radius] * sums[dx + k + radius]
                        smooth[dy, dx] = total / 255.0
            for dy in range(3 if not inside else 0):
                y0 = _reflected(rows[i] + dy - 1, height)
                for dx in range(3):
                    x0 = _reflected(cols[i] + dx - 1, width)
                    total = 0.0
                    for k in range(-radius, radius + 1):
                        x = _reflected(x0 + k, width)
                        column = 0.0
                        for j in range(-radius, radius + 1):
                            column += (
                                weights[j + radius] * rgb[_reflected(y0 + j, height), x, channel]
                            )
                        total += weights[k + radius] * column
                    smooth[dy, dx] = total / 255.0
            gx = (smooth[0, 2] - smooth[0, 0]) + 2.0 * (smooth[1, 2] - smooth[1, 0])
            gx += smooth[2, 2] - smooth[2, 0]
            gy = (smooth[2, 0] - smooth[0, 0]) + 2.0 * (smooth[2, 1] - smooth[0, 1])
            gy += smooth[2, 2] - smooth[0, 2]
            square = gx * gx + gy * gy
            if square > best:
                best = square
        out[i] = np.sqrt(best)
    return out


@_jit
def line_stretches(
    part: np.ndarray,
    near_edge: np.ndarray,
    window: np.ndarray,
    cos_a: np.ndarray,
    sin_a: np.ndarray,
    rho: np.ndarray,
    coverage: float,
    shortest: int,
):
    """For K candidate lines x cos a + y sin a = rho ((K,) float64 each) through the (h, w)
    bool ``part``, the densest stretch of each line's chord (the seams' candidate cuts; the
    numpy version one line at a time is pinned in ``tests/test_kernels.py``):

    - the chord: the pixels of ``part`` on the line, one per step along its longer image axis
      through ``window`` (top, bottom, left, right; a box holding all of ``part``), the other
      coordinate ``np.round((rho - t cos a) / sin a)`` (or with sin and cos swapped); fewer
      than ``shortest`` pixels: no chord;
    - its longest run [start, stop) whose share of ``near_edge`` pixels is at least
      ``coverage`` (the first longest);
    - whether that run reaches the outline of ``part`` at both ends (a pixel outside it or
      outside the grid within 3 px beyond each end, stepping along the run).

    Returns ``lengths`` (K,) int64 (stop - start; 0 with no chord or no run), ``reaches``
    (K,) bool, and the runs' pixels: ``rows``, ``cols`` (total,) int64, line k's at
    ``bounds[k]:bounds[k + 1]`` ((K + 1,) int64), runs shorter than ``shortest`` left out."""
    height, width = part.shape
    count = rho.shape[0]
    steps = max(window[1] - window[0], window[3] - window[2])
    chord_rows = np.empty(steps, dtype=np.int64)
    chord_cols = np.empty(steps, dtype=np.int64)
    prefix = np.empty(steps + 1, dtype=np.float64)
    lowest = np.empty(steps + 1, dtype=np.float64)
    lengths = np.zeros(count, dtype=np.int64)
    reaches = np.zeros(count, dtype=np.bool_)
    bounds = np.zeros(count + 1, dtype=np.int64)
    out_rows = np.empty(count * steps, dtype=np.int64)
    out_cols = np.empty(count * steps, dtype=np.int64)
    total = 0
    for k in range(count):
        n = 0
        # One pixel per column of a steep line, per row of a flat one.
        steep = abs(sin_a[k]) > abs(cos_a[k])
        first, last = (window[2], window[3]) if steep else (window[0], window[1])
        for t in range(first, last):
            if steep:
                row, col = np.int64(np.rint((rho[k] - t * cos_a[k]) / sin_a[k])), np.int64(t)
            else:
                row, col = np.int64(t), np.int64(np.rint((rho[k] - t * sin_a[k]) / cos_a[k]))
            if 0 <= row < height and 0 <= col < width and part[row, col]:
                chord_rows[n] = row
                chord_cols[n] = col
                n += 1
        bounds[k + 1] = total
        if n < shortest:
            continue
        # Densest run: prefix sums of (on edge - coverage), each end's first start at or
        # below it among the non-increasing prefix minima (bisection).
        prefix[0] = 0.0
        lowest[0] = 0.0
        for i in range(n):
            on = 1.0 if near_edge[chord_rows[i], chord_cols[i]] else 0.0
            prefix[i + 1] = prefix[i] + (on - coverage)
            lowest[i + 1] = min(lowest[i], prefix[i + 1])
        best_length = 0
        best_start = 0
        for b in range(1, n + 1):
            low, high = 0, n + 1
            while low < high:  # first j with -lowest[j] >= -prefix[b]
                middle = (low + high) // 2
                if -lowest[middle] >= -prefix[b]:
                    high = middle
                else:
                    low = middle + 1
            if b - low > best_length:
                best_length = b - low
                best_start = low
        if best_length < shortest:
            continue
        lengths[k] = best_length
        start = best_start
        stop = best_start + best_length
        for i in range(start, stop):
            out_rows[total] = chord_rows[i]
            out_cols[total] = chord_cols[i]
            total += 1
        bounds[k + 1] = total
        # The outline beyond both ends.
        steps_along = max(stop - start - 1, 1)
        d_row = (chord_rows[stop - 1] - chord_rows[start]) / steps_along
        d_col = (chord_cols[stop - 1] - chord_cols[start]) / steps_along
        both = True
        for end in range(2):
            at = start if end == 0 else stop - 1
            sign = -1.0 if end == 0 else 1.0
            outside = False
            for step in range(1, 4):
                r = np.int64(np.rint(chord_rows[at] + sign * step * d_row))
                c = np.int64(np.rint(chord_cols[at] + sign * step * d_col))
                if not (0 <= r < height and 0 <= c < width) or not part[r, c]:
                    outside = True
                    break
            if not outside:
                both = False
                break
        reaches[k] = both
    return lengths, reaches, out_rows[:total].copy(), out_cols[:total].copy(), bounds


@_jit
def line_sides(
    rows: np.ndarray,
    cols: np.ndarray,
    foot_m2: np.ndarray,
    size_m: np.ndarray,
    cos_a: float,
    sin_a: float,
    rho: float,
) -> np.ndarray:
    """Room on the two sides of the line x cos a + y sin a = rho among the (N,) pixels
    (rows, cols) of a part (int64), each with its footprint ``foot_m2`` (m^2) and its size
    ``size_m`` (m per px, depth / focal). Returns (2, 3) float64: per side (x cos a + y sin a
    above rho, below it) the summed footprint (m^2), the side's extent across the line (its
    farthest pixel's distance + 0.5 px) and along it (px, + 1), the latter two times the
    side's largest ``size_m``: upper bounds of the area and of the width (twice the inscribed
    radius) of any piece of the part within that half-plane (the seams' cheap test before a
    trial cut, ``seams._room_for_pieces``). Sides with no pixel give zeros."""
    area = np.zeros(2)
    across = np.zeros(2)
    low = np.full(2, np.inf)
    high = np.full(2, -np.inf)
    scale = np.zeros(2)
    for i in range(rows.shape[0]):
        distance = cols[i] * cos_a + rows[i] * sin_a - rho
        along = -cols[i] * sin_a + rows[i] * cos_a
        side = 0 if distance > 0 else 1
        area[side] += foot_m2[i]
        distance = abs(distance)
        if distance > across[side]:
            across[side] = distance
        if along < low[side]:
            low[side] = along
        if along > high[side]:
            high[side] = along
        if size_m[i] > scale[side]:
            scale[side] = size_m[i]
    out = np.zeros((2, 3))
    for side in range(2):
        if high[side] < low[side]:
            continue
        out[side, 0] = area[side]
        out[side, 1] = (across[side] + 0.5) * scale[side]
        out[side, 2] = (high[side] - low[side] + 1.0) * scale[side]
    return out


@_jit
def middle_values(values: np.ndarray, mask: np.ndarray):
    """The middle order statistics (k = (n - 1) // 2 and n // 2, 0-based; equal for odd n) of
    the (N,) float32 ``values`` >= 0 (no NaN) at the (N,) bool ``mask`` (n of them, n > 0):
    those of ``np.sort(values[mask])``, the values a median averages. A radix selection on the
    float32 bits (their order as unsigned integers is the values' order for values >= 0: 11,
    11 and 10 bits, a small histogram each), then the smallest value above the first: a few
    passes without a gathered copy or its partition (the seams' noise scale over a frame, the
    depth a pixel without one takes)."""
    bits = values.view(np.uint32)
    counts = np.zeros(2048, dtype=np.int64)
    k = 0
    for i in range(bits.shape[0]):
        if mask[i]:
            k += 1
    count = k
    k = (count - 1) // 2
    prefix = np.uint32(0)
    below = 0
    for shift, width, known in ((21, 2047, 0), (10, 2047, 11), (0, 1023, 22)):
        counts[:] = 0
        for i in range(bits.shape[0]):
            if mask[i] and (known == 0 or (bits[i] >> np.uint32(32 - known)) == prefix):
                counts[(bits[i] >> np.uint32(shift)) & np.uint32(width)] += 1
        digit = 0
        while below + counts[digit] <= k:
            below += counts[digit]
            digit += 1
        prefix = (prefix << np.uint32(32 - known - shift)) | np.uint32(digit)
        last = counts[digit]
    # ``prefix`` holds all 32 bits: the k-th value; ``below`` values lie below it and ``last``
    # equal it.
    low_bits = prefix
    high_bits = prefix
    if count % 2 == 0 and below + last <= k + 1:
        high_bits = np.uint32(0xFFFFFFFF)
        for i in range(bits.shape[0]):
            if mask[i] and bits[i] > low_bits and bits[i] < high_bits:
                high_bits = bits[i]
    out = np.empty(2, dtype=np.uint32)
    out[0] = low_bits
    out[1] = high_bits
    chosen = out.view(np.float32)
    return chosen[0], chosen[1]


@_jit
def room_pixels(part: np.ndarray, depth: np.ndarray, top: int, left: int, focal_px: float):
    """A part's pixels for the seams' room test (``seams._Room``): the (N,) int64 rows and
    columns (plus ``top``, ``left``) of the (h, w) bool ``part``'s pixels, row-major (as
    ``np.nonzero``), and each one's size (N,) float64 (m per px: its float32 ``depth``,
    or the median of the others' where it has none, 0 with none at all, over ``focal_px``)
    and footprint (its square). The median as numpy's of the float64 depths (the middle
    values by ``middle_values``, averaged as numpy's mean of two); one compiled pass for
    numpy's search, gathers and temporaries."""
    height, width = part.shape
    count = 0
    missing = 0
    for r in range(height):
        for c in range(width):
            if part[r, c]:
                count += 1
                if not depth[r, c] > 0:
                    missing += 1
    rows = np.empty(count, dtype=np.int64)
    cols = np.empty(count, dtype=np.int64)
    measured = np.empty(count, dtype=np.float32)
    k = 0
    for r in range(height):
        for c in range(width):
            if part[r, c]:
                rows[k] = r + top
                cols[k] = c + left
                measured[k] = depth[r, c]
                k += 1
    fill = 0.0
    if missing > 0 and missing < count:
        known = measured > 0
        low, high = middle_values(measured, known)
        if (count - missing) % 2 == 1:
            fill = np.float64(low)
        else:
            fill = (np.float64(low) + np.float64(high)) / 2.0
    size = np.empty(count)
    foot = np.empty(count)
    for i in range(count):
        value = np.float64(measured[i])
        if not value > 0:
            value = fill
        size[i] = value / focal_px
        foot[i] = size[i] * size[i]
    return rows, cols, size, foot


@_jit
def line_sides_fit(
    rows: np.ndarray,
    cols: np.ndarray,
    foot_m2: np.ndarray,
    size_m: np.ndarray,
    cos_a: float,
    sin_a: float,
    rho: float,
    min_area: float,
    min_width: float,
) -> bool:
    """Whether ``line_sides`` of these arguments gives each side a summed footprint of at least
    ``min_area`` and both extents at least ``min_width`` (the seams' room test,
    ``seams._Room.fits``), from the same per-pixel arithmetic in the same order, but stopping
    once every test holds: the footprints are >= 0, so each side's running sum (float addition
    of non-negative terms is monotone), its farthest distance, its range along the line and its
    largest size only grow pixel by pixel, and a test the first pixels pass all of them pass.
    A part cut near its middle passes after a fraction of its pixels (the compiled screen of
    the seams' candidates runs this for each candidate line)."""
    area = np.zeros(2)
    across = np.zeros(2)
    low = np.full(2, np.inf)
    high = np.full(2, -np.inf)
    scale = np.zeros(2)
    n = rows.shape[0]
    for i in range(n):
        distance = cols[i] * cos_a + rows[i] * sin_a - rho
        along = -cols[i] * sin_a + rows[i] * cos_a
        side = 0 if distance > 0 else 1
        area[side] += foot_m2[i]
        distance = abs(distance)
        if distance > across[side]:
            across[side] = distance
        if along < low[side]:
            low[side] = along
        if along > high[side]:
            high[side] = along
        if size_m[i] > scale[side]:
            scale[side] = size_m[i]
        if (i & 127) == 127 or i == n - 1:
            fits = True
            for s in range(2):
                # (A side with no pixel yet: zeros, as ``line_sides`` gives it.)
                width_across = 0.0
                width_along = 0.0
                if high[s] >= low[s]:
                    width_across = (across[s] + 0.5) * scale[s]
                    width_along = (high[s] - low[s] + 1.0) * scale[s]
                if not (area[s] >= min_area and min(width_across, width_along) >= min_width):
                    fits = False
                    break
            if fits:
                return True
    return False


@_jit
def mean_at(values: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(3,) float64 mean of the (H, W, 3) ``values`` at the pixels (rows, cols) ((N,) int64,
    N > 0): ``values[rows, cols].astype(np.float64).mean(axis=0)`` without the gathered copy
    (numpy sums the rows in order along axis 0, as here)."""
    total = np.zeros(3)
    for i in range(rows.shape[0]):
        for axis in range(3):
            total[axis] += np.float64(values[rows[i], cols[i], axis])
    return total / rows.shape[0]


@_jit
def hough_votes(
    rows: np.ndarray,
    cols: np.ndarray,
    own: np.ndarray,
    spread: int,
    cos_a: np.ndarray,
    sin_a: np.ndarray,
    reach: int,
) -> np.ndarray:
    """Votes (D * (2 reach + 1),) int64 of the lines x cos a + y sin a = rho (direction a of D,
    rho + reach at a * (2 reach + 1) + rho + reach) through the (N,) pixels (rows, cols), each
    voting for its own direction index ``own`` +- ``spread`` (modulo D), rho rounded half to
    even: the seams' ``np.bincount`` of ``np.round(cols * cos_a[a] + rows * sin_a[a])`` over
    every (pixel, direction) pair, without the (2 spread + 1, N) temporaries."""
    directions = cos_a.shape[0]
    width = 2 * reach + 1
    votes = np.zeros(directions * width, dtype=np.int64)
    for i in range(rows.shape[0]):
        for step in range(-spread, spread + 1):
            a = (own[i] + step) % directions
            rho = np.int64(np.rint(cols[i] * cos_a[a] + rows[i] * sin_a[a])) + reach
            votes[a * width + rho] += 1
    return votes


@_jit
def hough_lines(
    rows: np.ndarray,
    cols: np.ndarray,
    own: np.ndarray,
    spread: int,
    cos_a: np.ndarray,
    sin_a: np.ndarray,
    reach: int,
    least: int,
):
    """The lines with at least ``least`` of ``hough_votes``' votes: their indices (int64,
    ascending, as ``np.flatnonzero(votes >= least)``) and their votes, read in one compiled
    pass over the vote array instead of numpy's comparison, search and gather over it (a
    part's search; the array has 180 directions by twice the crop's diagonal)."""
    votes = hough_votes(rows, cols, own, spread, cos_a, sin_a, reach)
    count = 0
    for index in range(votes.shape[0]):
        if votes[index] >= least:
            count += 1
    lines = np.empty(count, dtype=np.int64)
    counts = np.empty(count, dtype=np.int64)
    count = 0
    for index in range(votes.shape[0]):
        if votes[index] >= least:
            lines[count] = index
            counts[count] = votes[index]
            count += 1
    return lines, counts


@_jit
def fragment_borders(
    labels: np.ndarray,
    points: np.ndarray,
    depth_m: np.ndarray,
    rgb: np.ndarray,
    supervoxel_labels: np.ndarray,
    supervoxel_normals: np.ndarray,
    gap_m: float,
    min_cos: float,
    touch_min_cos: float,
    pixel_area: float,
    n_labels: int,
):
    """One pass over a (H, W) label image for ``fragments.join_fragments`` and
    ``thin.join_thin_pieces``.

    ``points`` (H, W, 3) world (m); ``depth_m`` (H, W), 0 = no reading; ``rgb`` (H, W, 3);
    ``supervoxel_labels`` (H, W), -1 = none, indexing (M, 3) ``supervoxel_normals``;
    ``pixel_area`` = 1 / (fx fy). Returns (L,) float64 areas (sum of depth^2 x
    ``pixel_area`` over a label's pixels with depth, m^2), (L, 3) float64 colour sums over all
    its pixels, and (L, L) int64 ``outline``, ``continuous`` and ``touching`` counts at
    [min(a, b), max(a, b)] of 4-neighbour pixel pairs with labels a != b, both with depth:
    every such pair, and those with both labels > 0 whose points are closer than ``gap_m``
    and whose supervoxels' normals (a pixel of none counts as (0, 0, 0)) have a cosine of at
    least ``min_cos`` (``continuous``) or ``touch_min_cos`` (``touching``). Replaces the
    numpy ``np.bincount`` of areas and colours and the masked pair counts of
    ``fragments._pair_counts``."""
    height, width = labels.shape
    area = np.zeros(n_labels)
    colour = np.zeros((n_labels, 3))
    outline = np.zeros((n_labels, n_labels), dtype=np.int64)
    continuous = np.zeros((n_labels, n_labels), dtype=np.int64)
    touching = np.zeros((n_labels, n_labels), dtype=np.int64)
    for row in range(height):
        for col in range(width):
            a = labels[row, col]
            for channel in range(3):
                colour[a, channel] += rgb[row, col, channel]
            if depth_m[row, col] <= 0:
                continue
            area[a] += float(depth_m[row, col]) ** 2 * pixel_area
            for direction in range(2):
                r = row + (1 if direction == 1 else 0)
                c = col + (1 if direction == 0 else 0)
                if r >= height or c >= width or depth_m[r, c] <= 0:
                    continue
                b = labels[r, c]
                if a == b:
                    continue
                low, high = min(a, b), max(a, b)
                outline[low, high] += 1
                if low <= 0:
                    continue
                dx = points[row, col, 0] - points[r, c, 0]
                dy = points[row, col, 1] - points[r, c, 1]
                dz = points[row, col, 2] - points[r, c, 2]
                if np.sqrt(dx * dx + dy * dy + dz * dz) >= gap_m:
                    continue
                s, t = supervoxel_labels[row, col], supervoxel_labels[r, c]
                cosine = 0.0
                if s >= 0 and t >= 0:
                    cosine = (
                        supervoxel_normals[s, 0] * supervoxel_normals[t, 0]
                        + supervoxel_normals[s, 1] * supervoxel_normals[t, 1]
                        + supervoxel_normals[s, 2] * supervoxel_normals[t, 2]
                    )
                if cosine >= min_cos:
                    continuous[low, high] += 1
                if cosine >= touch_min_cos:
                    touching[low, high] += 1
    return area, colour, outline, continuous, touching


@_jit
def wall_rim_points(
    depth: np.ndarray,
    position: np.ndarray,
    heights: np.ndarray,
    normals_up: np.ndarray,
    front_m: float,
    back_m: float,
    s_lo: float,
    s_hi: float,
    min_cos_up: float,
    min_height_m: float,
) -> np.ndarray:
    """Indices (ascending) of the points of a wall's rim (``planes._wall_cues``): ``depth`` (N,)
    in front of the plane below ``front_m`` and above ``back_m``, ``position`` (N,) along it
    within [``s_lo``, ``s_hi``], facing up (``normals_up`` (N,) above ``min_cos_up``) and
    ``heights`` (N,) above ``min_height_m``. Replaces the numpy mask ``(depth < front_m) &
    (depth > back_m) & (s >= s_lo) & (s <= s_hi) & (normals_up > min_cos_up) & (h >
    min_height_m)`` and its ``np.flatnonzero``."""
    count = depth.shape[0]
    found = np.empty(count, dtype=np.int64)
    n = 0
    for p in range(count):
        if (
            depth[p] < front_m
            and depth[p] > back_m
            and position[p] >= s_lo
            and position[p] <= s_hi
            and normals_up[p] > min_cos_up
            and heights[p] > min_height_m
        ):
            found[n] = p
            n += 1
    return found[:n]


@_jit
def wall_behind_and_near(
    depth: np.ndarray,
    position: np.ndarray,
    heights: np.ndarray,
    normals_up: np.ndarray,
    use_normals: bool,
    slab_front_m: float,
    slab_back_m: float,
    cap_back_m: float,
    low_m: float,
    high_m: float,
    min_cos_up: float,
    s_lo: float,
    s_hi: float,
    side_range_m: float,
    margin_m: float,
):
    """The cap and side figures of a wall (``planes._wall_cues``) in one pass over (N,)
    ``depth``, ``position``, ``heights`` and ``normals_up``: the indices (ascending) of the
    points behind the face (``depth`` below ``slab_back_m`` and above ``cap_back_m``, heights
    strictly between ``low_m`` and ``high_m``, ``position`` within [``s_lo``, ``s_hi``] and,
    with ``use_normals``, facing up: ``normals_up`` above ``min_cos_up``), and the number of
    points near the wall outside its slab (not (``slab_back_m`` < depth < ``slab_front_m``),
    |depth| below ``side_range_m``, ``position`` strictly within ``margin_m`` of the run) and
    how many of those are in front (depth > 0). Replaces the numpy masks ``behind``, ``slab``
    and ``near``."""
    count = depth.shape[0]
    found = np.empty(count, dtype=np.int64)
    n = 0
    near = 0
    in_front = 0
    for p in range(count):
        d = depth[p]
        s = position[p]
        if (
            d < slab_back_m
            and d > cap_back_m
            and heights[p] > low_m
            and heights[p] < high_m
            and s >= s_lo
            and s <= s_hi
            and (not use_normals or normals_up[p] > min_cos_up)
        ):
            found[n] = p
            n += 1
        in_slab = d < slab_front_m and d > slab_back_m
        if not in_slab and abs(d) < side_range_m and s > s_lo - margin_m and s < s_hi + margin_m:
            near += 1
            if d > 0:
                in_front += 1
    return found[:n], near, in_front


@_jit
def robust_circle(points: np.ndarray, floor_m: float, rounds: int) -> tuple:
    """Robust Kasa circle through (N, 2) float64 ``points`` (``containers._rim_circle``).

    Each round fits |p|^2 = 2 c . p + k by least squares to the inliers (in coordinates centred
    on their mean; the 3 x 3 normal equations by Gaussian elimination with partial pivoting),
    then takes as inliers the points within max(3 x 1.4826 x the inliers' median absolute
    residual, ``floor_m``) of the circle; it stops when they stay the same or after ``rounds``.
    Replaces the same loop in numpy (about 25 array calls a round).

    Returns (cx, cy, radius, rms, share): centre and radius, the inliers' RMS residual and
    their share of the points; radius -1 when fewer than 10 inliers remain, the points lie on
    a line, or the fitted squared radius is not positive.
    """
    n = points.shape[0]
    inliers = np.ones(n, dtype=np.bool_)
    residual = np.empty(n)
    cx = 0.0
    cy = 0.0
    radius = -1.0
    for _ in range(rounds):
        count = 0
        mx = 0.0
        my = 0.0
        for i in range(n):
            if inliers[i]:
                mx += points[i, 0]
                my += points[i, 1]
                count += 1
        if count < 10:
            return 0.0, 0.0, -1.0, 0.0, 0.0
        mx /= count
        my /= count
        a = np.zeros((3, 4))
        for i in range(n):
            if inliers[i]:
                x = points[i, 0] - mx
                y = points[i, 1] - my
                row = (x, y, 1.0)
                target = x * x + y * y
                for r in range(3):
                    for c in range(3):
                        a[r, c] += row[r] * row[c]
                    a[r, 3] += row[r] * target
        for col in range(3):
            pivot = col
            for r in range(col + 1, 3):
                if abs(a[r, col]) > abs(a[pivot, col]):
                    pivot = r
            if a[pivot, col] == 0.0:
                return 0.0, 0.0, -1.0, 0.0, 0.0
            if pivot != col:
                for c in range(4):
                    a[col, c], a[pivot, c] = a[pivot, c], a[col, c]
            for r in range(col + 1, 3):
                factor = a[r, col] / a[col, col]
                for c in range(col, 4):
                    a[r, c] -= factor * a[col, c]
        solution = np.zeros(3)
        for r in range(2, -1, -1):
            total = a[r, 3]
            for c in range(r + 1, 3):
                total -= a[r, c] * solution[c]
            solution[r] = total / a[r, r]
        ux = solution[0] / 2.0
        uy = solution[1] / 2.0
        squared = solution[2] + ux * ux + uy * uy
        if squared <= 0.0:
            return 0.0, 0.0, -1.0, 0.0, 0.0
        radius = np.sqrt(squared)
        cx = ux + mx
        cy = uy + my
        kept = np.empty(count)
        k = 0
        for i in range(n):
            dx = points[i, 0] - cx
            dy = points[i, 1] - cy
            residual[i] = np.sqrt(dx * dx + dy * dy) - radius
            if inliers[i]:
                kept[k] = abs(residual[i])
                k += 1
        limit = max(3.0 * 1.4826 * np.median(kept), floor_m)
        changed = False
        for i in range(n):
            inside = abs(residual[i]) <= limit
            if inside != inliers[i]:
                changed = True
                inliers[i] = inside
        if not changed:
            break
    total = 0.0
    count = 0
    for i in range(n):
        if inliers[i]:
            total += residual[i] * residual[i]
            count += 1
    if count == 0:
        return cx, cy, radius, np.inf, 0.0
    return cx, cy, radius, np.sqrt(total / count), count / n


@_jit
def _root(parent: np.ndarray, node: int) -> int:
    """Union-find root of ``node`` with path halving."""
    while parent[node] != node:
        parent[node] = parent[parent[node]]
        node = parent[node]
    return node


@_jit
def segment_surface_parts(
    supervoxel_labels: np.ndarray,
    segment_of_supervoxel: np.ndarray,
    points: np.ndarray,
    gap_m: float,
):
    """The parts of each segment along which its surface runs on, and the steps between them,
    for ``contours.split_at_occluding_contours``; one pass over the image.

    ``supervoxel_labels`` (H, W), -1 = none; ``segment_of_supervoxel`` (M,), 0 = none;
    ``points`` (H, W, 3) world (m). Two supervoxels of one segment (> 0) are in one part when
    some 4-neighbour pixel pair between them has points closer than ``gap_m``. Returns (M,)
    int64 part of each supervoxel (numbered as ``connected_components`` numbers them) and
    (S, 2) int64 supervoxel pairs of the other pixel pairs between two supervoxels of one
    segment (one row per pixel pair: the steps)."""
    height, width = supervoxel_labels.shape
    count = segment_of_supervoxel.shape[0]
    parent = np.arange(count)
    steps = np.empty((2 * height * width, 2), dtype=np.int64)
    n_steps = 0
    limit = gap_m * gap_m
    for row in range(height):
        for col in range(width):
            a = supervoxel_labels[row, col]
            if a < 0 or segment_of_supervoxel[a] <= 0:
                continue
            for direction in range(2):
                r = row + (1 if direction == 1 else 0)
                c = col + (1 if direction == 0 else 0)
                if r >= height or c >= width:
                    continue
                b = supervoxel_labels[r, c]
                if b < 0 or b == a or segment_of_supervoxel[b] != segment_of_supervoxel[a]:
                    continue
                squared = 0.0
                for k in range(3):
                    delta = points[row, col, k] - points[r, c, k]
                    squared += delta * delta
                if squared < limit:
                    ra, rb = _root(parent, a), _root(parent, b)
                    if ra < rb:
                        parent[rb] = ra
                    elif rb < ra:
                        parent[ra] = rb
                else:
                    steps[n_steps, 0] = a
                    steps[n_steps, 1] = b
                    n_steps += 1
    part = np.empty(count, dtype=np.int64)
    n_parts = 0
    for node in range(count):  # a root is its component's smallest node
        root = _root(parent, node)
        if root == node:
            part[node] = n_parts
            n_parts += 1
        else:
            part[node] = part[root]
    return part, steps[:n_steps].copy()


@_jit
def stretch_lengths(
    stretch_rows: np.ndarray,
    stretch_cols: np.ndarray,
    bounds: np.ndarray,
    which: np.ndarray,
    depth: np.ndarray,
    points: np.ndarray,
) -> np.ndarray:
    """(K,) float64 3D length (m) of each stretch ``which`` ((K,) int64 into ``bounds``; the
    stretch k is ``stretch_rows/cols[bounds[k]:bounds[k + 1]]``) between its outermost pixels
    with depth (``depth`` (h, w) > 0; ``points`` (h, w, 3), m), -1 for fewer than two: the
    seams' length test, in float64 (numpy's is a float32 norm; ``seams._best_cut`` screens
    with it and a margin, then tests the survivors as before)."""
    out = np.full(which.shape[0], -1.0)
    for index in range(which.shape[0]):
        k = which[index]
        first = -1
        last = -1
        for i in range(bounds[k], bounds[k + 1]):
            if depth[stretch_rows[i], stretch_cols[i]] > 0:
                if first < 0:
                    first = i
                last = i
        if first < 0 or last == first:
            continue
        total = 0.0
        for axis in range(3):
            step = np.float64(
                points[stretch_rows[first], stretch_cols[first], axis]
                - points[stretch_rows[last], stretch_cols[last], axis]
            )
            total += step * step
        out[index] = np.sqrt(total)
    return out


@_jit
def seam_screen(
    which: np.ndarray,
    line_cos: np.ndarray,
    line_sin: np.ndarray,
    line_rho: np.ndarray,
    stretch_rows: np.ndarray,
    stretch_cols: np.ndarray,
    bounds: np.ndarray,
    room_rows: np.ndarray,
    room_cols: np.ndarray,
    room_foot: np.ndarray,
    room_size: np.ndarray,
    min_area: float,
    min_width: float,
    part_rows: np.ndarray,
    part_cols: np.ndarray,
    height: int,
    width: int,
    near: float,
    far: float,
    normals: np.ndarray,
    max_angle_deg: float,
    start: int,
) -> int:
    """The first of the candidate seams ``which[start:]`` (line k: x cos + y sin = rho, its stretch
    ``stretch_rows/cols[bounds[k]:bounds[k + 1]]``), whether it passes the seams' room test
    (``line_sides`` over the part's pixels ``room_*`` against ``min_area`` and ``min_width``:
    the same answers as ``seams._Room.fits``, by ``line_sides_fit``) and whether the mean normals (``normals`` (h, w,
    3)) of its side bands among ``part_rows/cols`` (the part's pixels with a normal, row-major:
    only the rows of the seam's box are read; the bands
    ``near``-``far`` px off the line within the stretch's extent, each of at least 20 pixels,
    as ``seams._coplanar_sides`` chooses them) lie within ``max_angle_deg``: one pass for all
    candidates instead of one numpy call each; its position in ``which``, or -1 if none. The
    angle is compared with a float64 norm (numpy's is BLAS's): the caller adds a margin and tests
    the one found as before."""
    box = np.empty(4, dtype=np.int64)
    along_range = np.empty(2)
    for index in range(start, which.shape[0]):
        k = which[index]
        cos_a = line_cos[k]
        sin_a = line_sin[k]
        rho = line_rho[k]
        if not line_sides_fit(
            room_rows, room_cols, room_foot, room_size, cos_a, sin_a, rho, min_area, min_width
        ):
            continue
        start, stop = bounds[k], bounds[k + 1]
        low_r = stretch_rows[start]
        high_r = low_r
        low_c = stretch_cols[start]
        high_c = low_c
        along_low = np.inf
        along_high = -np.inf
        for i in range(start, stop):
            r = stretch_rows[i]
            c = stretch_cols[i]
            low_r = min(low_r, r)
            high_r = max(high_r, r)
            low_c = min(low_c, c)
            high_c = max(high_c, c)
            along = float(-c) * sin_a + float(r) * cos_a
            along_low = min(along_low, along)
            along_high = max(along_high, along)
        far_px = int(far)
        box[0] = max(low_r - far_px, 0)
        box[1] = min(high_r + far_px + 1, height)
        box[2] = max(low_c - far_px, 0)
        box[3] = min(high_c + far_px + 1, width)
        along_range[0] = along_low
        along_range[1] = along_high
        # The part's pixels are row-major: only those in the box's rows can be in a band.
        first = np.searchsorted(part_rows, box[0])
        last = np.searchsorted(part_rows, box[1])
        band_a, band_b = seam_side_bands(
            part_rows[first:last],
            part_cols[first:last],
            box,
            cos_a,
            sin_a,
            rho,
            along_range,
            near,
            far,
        )
        if band_a.shape[0] < 20 or band_b.shape[0] < 20:
            continue
        band_a += first
        band_b += first
        normal_a = mean_at(normals, part_rows[band_a], part_cols[band_a])
        normal_b = mean_at(normals, part_rows[band_b], part_cols[band_b])
        normal_a /= max(np.sqrt(np.sum(normal_a * normal_a)), 1e-12)
        normal_b /= max(np.sqrt(np.sum(normal_b * normal_b)), 1e-12)
        cos_angle = min(max(np.sum(normal_a * normal_b), -1.0), 1.0)
        if np.degrees(np.arccos(cos_angle)) <= max_angle_deg:
            return index
    return -1


@_jit
def piece_spans(points: np.ndarray, pieces: np.ndarray, measured: np.ndarray, count: int):
    """(count + 1, 3) float64 range (largest less smallest) of the (H, W, 3) ``points`` of
    each piece id of the (H, W) int ``pieces`` at the (H, W) bool ``measured``, per
    coordinate; zeros for a piece with no such pixel: for id p,
    ``cloud = points[(pieces == p) & measured].astype(np.float64);
    cloud.max(axis=0) - cloud.min(axis=0)`` (minimum and maximum are exact in any order). One
    pass for all pieces; numpy's reductions along a short last axis of a gathered copy take
    ten times as long."""
    low = np.full((count + 1, 3), np.inf)
    high = np.full((count + 1, 3), -np.inf)
    for row in range(pieces.shape[0]):
        for col in range(pieces.shape[1]):
            piece = pieces[row, col]
            if piece > 0 and piece <= count and measured[row, col]:
                for axis in range(3):
                    value = np.float64(points[row, col, axis])
                    if value < low[piece, axis]:
                        low[piece, axis] = value
                    if value > high[piece, axis]:
                        high[piece, axis] = value
    spans = np.zeros((count + 1, 3))
    for piece in range(count + 1):
        if high[piece, 0] >= low[piece, 0]:
            for axis in range(3):
                spans[piece, axis] = high[piece, axis] - low[piece, axis]
    return spans
