"""Depth noise removed from the observed surface of each object before its points are used.

Every hypothesis is a convex hull of (among others) the object's observed points, and a hull
takes the extreme points: with axial sensor noise of sigma (about 1-3 mm at 0.5-1 m for a
Kinect-like sensor), the few thousand points of an object always include some several sigma in
front of the true surface, so every hull bulges out by several millimetres over the whole
visible surface. At the 5 mm voxels of the evaluation that is a large share of a small object
(development scenes: the minimum shapes' voxels were 82 % inside the true object, although
fewer than 0.2 % of the points were more than 5 mm outside it).

Each pixel's depth is replaced by the value at that pixel of the plane ``depth = a + b*u +
c*v`` fitted by least squares to the pixels of the same object (tracked label) with a reading
within a ``window`` x ``window`` neighbourhood. The fit is exact on planar surfaces at any
slant and up to the object's silhouette (a plain mean would bias the rim's depth towards the
interior and shrink the object); on curved surfaces and across creases it rounds by a fraction
of the window. The fit uses only the object's own pixels, so depth never bleeds across objects.
Where the whole window lies on the object, the fit's value at the centre is the window's mean
(a box filter over the object's bounding box); only the pixels near its silhouette or holes are
fitted one by one.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.ndimage import uniform_filter


def object_plane_depth(depth_m: np.ndarray, pixels: np.ndarray, window: int) -> np.ndarray:
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


@functools.lru_cache(maxsize=8)
def _window_offsets(margin: int) -> tuple[np.ndarray, np.ndarray]:
    """Column and row offsets (w*w,) float64 (read-only) of a window of half-size ``margin``,
    row-major (built once: ``np.mgrid`` costs more than the fits of a small object)."""
    dv, du = np.mgrid[-margin : margin + 1, -margin : margin + 1]
    du, dv = du.reshape(-1).astype(np.float64), dv.reshape(-1).astype(np.float64)
    du.flags.writeable = dv.flags.writeable = False
    return du, dv
