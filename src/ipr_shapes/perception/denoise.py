"""Depth noise removed from the observed surface of each object before its points are used.

Every hypothesis is a convex hull of (among others) the object's observed points, and a hull
takes the extreme points: with axial sensor noise of sigma (about 1-3 mm at 0.5-1 m for a
Kinect-like sensor), the few thousand points of an object always include some several sigma in
front of the true surface, so every hull bulges out by several millimetres over the whole
visible surface. At the 5 mm voxels of the evaluation that is a large share of a small object,
although the points themselves are right (docs/DESIGN_NOTES.md, "Partial objects from
plane-fitted depth").

Each pixel's depth is replaced by the value at that pixel of the plane ``depth = a + b*u +
c*v`` fitted by least squares to the pixels of the same object (tracked label) with a reading
within a ``window`` x ``window`` neighbourhood. The fit is exact on planar surfaces at any
slant and up to the object's silhouette (a plain mean would bias the rim's depth towards the
interior and shrink the object); on curved surfaces and across creases it rounds by a fraction
of the window. The fit uses only the object's own pixels, so depth never bleeds across objects.
Where the whole window lies on the object, the fit's value at the centre is the window's mean;
only the pixels near its silhouette or holes need the full least-squares fit.
"""

from __future__ import annotations

import numpy as np

from ipr_shapes.perception import kernels


def object_plane_depth(depth_m: np.ndarray, pixels: np.ndarray, window: int) -> np.ndarray:
    """(N,) float64 depth (m) at one object's (N,) flat pixel indices (all with a reading) of a
    (H, W) depth image, each replaced by the object's local plane fit there (module doc); a
    pixel whose neighbourhood holds fewer than 6 of the object's pixels, or only a line of
    them, keeps its reading. ``window`` is the odd neighbourhood size (< 3: no change)."""
    pixels = np.asarray(pixels, dtype=np.int64)
    return objects_plane_depth(depth_m, pixels, np.array([0, pixels.size]), window)


def objects_plane_depth(
    depth_m: np.ndarray, pixels: np.ndarray, starts: np.ndarray, window: int
) -> np.ndarray:
    """``object_plane_depth`` of several objects at once: ``pixels`` (N,) holds their flat
    pixels one object after the other, object k at ``pixels[starts[k]:starts[k + 1]]``
    (``starts`` (K + 1,) ascending, from 0 to N). Returns (N,) float64 depth (m)."""
    if window >= 3 and window % 2 == 0:
        raise ValueError(f"the denoising window must be odd, got {window}")
    # Compiled (``kernels``): the window sums of each pixel taken directly, in one pass.
    return kernels.objects_plane_depth(
        np.ascontiguousarray(depth_m),
        np.asarray(pixels, dtype=np.int64),
        np.asarray(starts, dtype=np.int64),
        int(window),
    )
