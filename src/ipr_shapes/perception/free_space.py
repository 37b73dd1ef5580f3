"""Space the camera saw to be empty, occupied, or could not see (paper Sec. IV-B, free space).

A voxel is *free* in a frame when the camera's rays passed through it before hitting a surface,
*occupied* when it holds an observed surface, and *unknown* when it lies behind observed
surfaces, outside the image, or where the sensor gave no reading. Instead of marching every
pixel's ray, each voxel centre is projected into the image and compared with the depth there
(a projective test): the cost is one compiled pass over the voxels, independent of the image
size. The test is conservative for *free*: the depth is min-filtered over the voxel's pixel
footprint, so a voxel is free only if every ray through it that returned a reading went past
it; a footprint with no reading at all stays unknown.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numba
import numpy as np
from scipy.ndimage import minimum_filter

from ipr_shapes.camera import invert_transform, view_halfspaces

UNKNOWN, FREE, OCCUPIED = np.uint8(0), np.uint8(1), np.uint8(2)
#: Min-filter window sizes (pixels, odd) available for voxel footprints.
FOOTPRINT_WINDOWS = (1, 3, 5, 9, 15)
#: Window (pixels) within which a missing reading takes the nearest valid depth.
HOLE_FILL_WINDOW = 7


@dataclass(frozen=True, eq=False)
class VoxelGrid:
    """An axis-aligned voxel grid in the world frame.

    Attributes:
        origin: (3,) world coordinates (m) of the grid's minimum corner.
        voxel_size_m: edge length of a voxel (m).
        shape: (nx, ny, nz) number of voxels per axis.
    """

    origin: np.ndarray
    voxel_size_m: float
    shape: tuple[int, int, int]

    @staticmethod
    def around(minimum: np.ndarray, maximum: np.ndarray, voxel_size_m: float = 0.005) -> VoxelGrid:
        """The grid of voxels aligned to multiples of ``voxel_size_m`` (m) that covers the box
        with (3,) world corners ``minimum`` and ``maximum`` (m).

        Aligning to the global lattice (centres at (n + 1/2) * size, as the metrics use) keeps
        grids of different frames and stages interchangeable.
        """
        low = np.floor(np.asarray(minimum, float) / voxel_size_m)
        high = np.ceil(np.asarray(maximum, float) / voxel_size_m)
        shape = tuple(int(n) for n in np.maximum(high - low, 1))
        return VoxelGrid(low * voxel_size_m, voxel_size_m, shape)  # type: ignore[arg-type]

    def centres(self) -> np.ndarray:
        """World coordinates (nx, ny, nz, 3) of every voxel centre (m)."""
        axes = [
            self.origin[i] + (np.arange(n) + 0.5) * self.voxel_size_m
            for i, n in enumerate(self.shape)
        ]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def indices_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Voxel indices (N, 3) of world points (N, 3) and a (N,) mask of points inside the grid."""
        indices = np.floor((points - self.origin) / self.voxel_size_m).astype(np.int64)
        shape = self.shape
        inside = (
            (indices[:, 0] >= 0) & (indices[:, 0] < shape[0])
            & (indices[:, 1] >= 0) & (indices[:, 1] < shape[1])
            & (indices[:, 2] >= 0) & (indices[:, 2] < shape[2])
        )  # fmt: skip
        return indices, inside


@dataclass(frozen=True, eq=False)
class SpaceMap:
    """What one frame saw of a voxel grid: ``state`` (nx, ny, nz) uint8 of UNKNOWN/FREE/OCCUPIED,
    and ``view``, the frame's field of view as (4, 4) world half-spaces n . x + b >= 0 (unit n,
    m; ``ipr_shapes.camera.view_halfspaces``), or None when not known. Beyond ``view`` every voxel
    is UNKNOWN because the image ends there, not because something hides it: the hypotheses
    bound their hidden extent there by the object's seen part (``HypothesisConfig.outside_view_ratio``).
    """

    grid: VoxelGrid
    state: np.ndarray
    view: np.ndarray | None = None

    @property
    def free(self) -> np.ndarray:
        """(nx, ny, nz) bool, True where the camera saw empty space."""
        return self.state == FREE

    @property
    def unknown(self) -> np.ndarray:
        """(nx, ny, nz) bool, True where the camera could not see."""
        return self.state == UNKNOWN

    def state_at(self, points: np.ndarray) -> np.ndarray:
        """State (N,) of the voxels holding world points (N, 3); UNKNOWN outside the grid (the
        voxels of ``grid.indices_of``, in one compiled pass: hypotheses ask thousands of times)."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        grid = self.grid
        origin = np.asarray(grid.origin, dtype=np.float64)
        return _states_at(points, origin, float(grid.voxel_size_m), self.state)


class SeenSpace(Protocol):
    """What the hypotheses and constraints ask of a free-space map: a ``SpaceMap``, or a view
    combining several frames' maps for one object (``ipr_shapes.fusion.TrackedFreeSpace``)."""

    @property
    def grid(self) -> VoxelGrid: ...

    def state_at(self, points: np.ndarray) -> np.ndarray: ...

    # A space may also have ``view`` (``SpaceMap.view``: its frame's field of view, or None);
    # the hypotheses read it with ``getattr``, so spaces without it remain spaces.


# Compiled per-voxel pass of ``observe_space`` and lookups of ``SpaceMap.state_at`` (nogil: frames are observed on threads; no
# fastmath: numpy's IEEE arithmetic, operation for operation, so the same states bit for bit).
_jit = numba.njit(cache=True, nogil=True)


@_jit
def _states_at(points, origin, voxel_size_m, state):
    """(N,) uint8 ``state`` of the voxels holding (N, 3) float64 ``points``: voxel index
    ``floor((p - origin) / voxel_size_m)`` per axis (numpy's arithmetic), UNKNOWN (0) outside
    the grid or for a non-finite point."""
    nx, ny, nz = state.shape
    out = np.zeros(points.shape[0], dtype=np.uint8)
    for n in range(points.shape[0]):
        i = np.floor((points[n, 0] - origin[0]) / voxel_size_m)
        j = np.floor((points[n, 1] - origin[1]) / voxel_size_m)
        k = np.floor((points[n, 2] - origin[2]) / voxel_size_m)
        if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz:  # False for NaN
            out[n] = state[np.int64(i), np.int64(j), np.int64(k)]
    return out


@_jit
def _round_half_even(x: float) -> float:
    """numpy's ``round`` of a finite float64 (ties to even); x - floor(x) is exact."""
    r = np.floor(x)
    d = x - r
    if d > 0.5 or (d == 0.5 and r % 2.0 != 0.0):
        r += 1.0
    return r


@_jit
def _project(terms, offset, k, fx, cx, fy, cy, width, height, near):
    """Pixel (u, v) and float32 depth z of grid voxel (i, j, k) (camera coordinates as the
    float32 sum ``(terms[0][i] + terms[1][j]) + (terms[2][k] + offset)``, as numpy broadcasts
    it), and whether it is in front and inside the image."""
    i, j, kk = k
    x = (terms[0][i, 0] + terms[1][j, 0]) + (terms[2][kk, 0] + offset[0])
    y = (terms[0][i, 1] + terms[1][j, 1]) + (terms[2][kk, 1] + offset[1])
    z = (terms[0][i, 2] + terms[1][j, 2]) + (terms[2][kk, 2] + offset[2])
    in_front = z > near
    safe = z if in_front else np.float32(1.0)
    u = np.int64(_round_half_even(fx * np.float64(x) / np.float64(safe) + cx))
    v = np.int64(_round_half_even(fy * np.float64(y) / np.float64(safe) + cy))
    inside = in_front and u >= 0 and u < width and v >= 0 and v < height
    return u, v, z, inside


@_jit
def _footprint_level(z, footprint_scale, nearest_z, windows):
    """Index of the smallest window (``windows`` ascending) covering a voxel's footprint
    ``ceil(footprint_scale / max(z, nearest_z))`` pixels, the last one at most (numpy's
    ``searchsorted``, left side)."""
    footprint = np.ceil(footprint_scale / np.float64(max(z, nearest_z)))
    level = 0
    while level < windows.size and windows[level] < footprint:
        level += 1
    return min(level, windows.size - 1)


@_jit
def _voxel_states(terms, offset, shape, fx, cx, fy, cy, width, height, near, footprint_scale,
                  nearest_z, windows, nearest, available, depth, margin):  # fmt: skip
    """(nx, ny, nz) uint8 states of ``observe_space`` (module doc) and (len(windows),) bool: the
    windows some voxel inside the image needed but ``available`` did not have (its state is
    then wrong: fill that window and call again). ``nearest`` holds the min-filtered depth
    (H, W) float32 of each available window, ``depth`` the readings, ``margin`` the float32
    surface margin."""
    state = np.zeros((shape[0], shape[1], shape[2]), dtype=np.uint8)
    missing = np.zeros(windows.size, dtype=np.bool_)
    for i in range(shape[0]):
        for j in range(shape[1]):
            for kk in range(shape[2]):
                u, v, z, inside = _project(
                    terms, offset, (i, j, kk), fx, cx, fy, cy, width, height, near
                )
                if not inside:
                    continue
                level = _footprint_level(z, footprint_scale, nearest_z, windows)
                if not available[level]:
                    missing[level] = True
                    continue
                observed_near = nearest[level][v, u]
                observed = depth[v, u]
                if np.isfinite(observed_near) and z < observed_near - margin:
                    state[i, j, kk] = 1  # FREE
                elif observed > 0 and abs(z - observed) <= margin:
                    state[i, j, kk] = 2  # OCCUPIED
    return state, missing


def _windows_between(
    near_z: float, far_z: float, footprint_scale: float, windows: np.ndarray
) -> np.ndarray:
    """(len(windows),) bool: the footprint windows of the depths (m) from ``near_z`` to
    ``far_z`` (``footprint_scale``: a voxel's footprint in pixels at 1 m)."""
    nearest_z = np.maximum(np.array([far_z, near_z], dtype=np.float32), np.float32(0.05))
    footprints = np.ceil(footprint_scale / nearest_z.astype(np.float64))
    levels = np.minimum(np.searchsorted(windows, footprints), len(windows) - 1)
    available = np.zeros(len(windows), dtype=bool)
    available[levels[0] : levels[1] + 1] = True
    return available


def observe_space(
    depth_m: np.ndarray,
    K: np.ndarray,
    world_from_camera: np.ndarray,
    grid: VoxelGrid,
    *,
    surface_margin_m: float = 0.01,
    ignore_mask: np.ndarray | None = None,
) -> SpaceMap:
    """Free, occupied and unknown voxels of ``grid`` as seen by one depth image.

    Args:
        depth_m: (H, W) planar depth in metres, 0 where there is no reading.
        K: (3, 3) intrinsics; world_from_camera: (4, 4) OpenCV camera pose, metres.
        grid: the voxels to classify.
        surface_margin_m: a voxel within this distance (along the optical axis) of the observed
            depth is OCCUPIED; nearer than that it is FREE. It absorbs sensor noise and the
            voxel's own extent, so it should be at least the voxel size plus the depth noise.
        ignore_mask: (H, W) bool of pixels to treat as having no reading (robot, pusher).
    """
    height, width = depth_m.shape
    depth = np.where(depth_m > 0, depth_m, 0.0).astype(np.float32)
    if ignore_mask is not None:
        depth = np.where(ignore_mask, 0.0, depth)
    camera_from_world = invert_transform(world_from_camera)
    # Camera coordinates of all centres as a sum of per-axis terms (the grid is a lattice), in
    # float32: a fraction of the cost of transforming every centre.
    rotation = camera_from_world[:3, :3]
    axes = [
        grid.origin[i] + (np.arange(n) + 0.5) * grid.voxel_size_m for i, n in enumerate(grid.shape)
    ]
    terms = tuple(np.outer(axis, rotation[:, i]).astype(np.float32) for i, axis in enumerate(axes))
    offset = camera_from_world[:3, 3].astype(np.float32)
    K = np.asarray(K, dtype=np.float64)
    # The comparisons of float32 depths with Python floats are float32 ones (numpy's), here
    # and in the compiled pass.
    footprint_scale = float(K[0, 0] * grid.voxel_size_m)  # pixels at 1 m
    windows = np.array(FOOTPRINT_WINDOWS)
    projection = (
        terms, offset, np.asarray(grid.shape, np.int64), float(K[0, 0]), float(K[0, 2]),
        float(K[1, 1]), float(K[1, 2]), width, height, np.float32(1e-3),
        footprint_scale, np.float32(0.05), windows,
    )  # fmt: skip

    # Conservative "free": the nearest depth over the voxel's pixel footprint must lie beyond it.
    # The footprint shrinks with distance, so the min filter is precomputed at a few window sizes
    # (those some voxel reads) and each voxel reads the one that covers it. A missing reading
    # says nothing about where its ray ended, so it is left out of the minimum (the voxel is
    # covered by its neighbours' rays); a footprint without any reading stays unknown.
    valid_depth = np.where(depth > 0, depth, np.inf).astype(np.float32)
    # Sensors drop readings at depth discontinuities: a missing pixel is assumed to belong to the
    # nearest surface around it, so free space never leaks past an object's silhouette.
    nearby = minimum_filter(valid_depth, size=HOLE_FILL_WINDOW, mode="nearest")
    valid_depth = np.where(depth > 0, valid_depth, nearby)
    # The windows the grid's depths can need (its corners bound z; float32 rounding may step
    # past them, which the compiled pass reports, and then the window is added).
    corners = [terms[axis][[0, -1], 2] for axis in range(3)]
    corner_z = (corners[0][:, None, None] + corners[1][None, :, None]) + (corners[2] + offset[2])[
        None, None, :
    ]
    available = _windows_between(corner_z.min(), corner_z.max(), footprint_scale, windows)
    unused = np.zeros((1, 1), dtype=np.float32)
    nearest = [unused] * len(FOOTPRINT_WINDOWS)
    while True:
        for number, window in enumerate(FOOTPRINT_WINDOWS):
            if available[number] and nearest[number] is unused:
                nearest[number] = (
                    valid_depth
                    if window == 1
                    else minimum_filter(valid_depth, size=int(window), mode="nearest")
                )
        state, missing = _voxel_states(
            *projection, tuple(nearest), available, depth, np.float32(surface_margin_m)
        )
        if not missing.any():
            break
        available |= missing
    return SpaceMap(grid, state, view_halfspaces(K, world_from_camera, (height, width)))
