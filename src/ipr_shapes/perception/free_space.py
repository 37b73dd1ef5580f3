"""Space the camera saw to be empty, occupied, or could not see (paper Sec. IV-B, free space).

A voxel is *free* in a frame when the camera's rays passed through it before hitting a surface,
*occupied* when it holds an observed surface, and *unknown* when it lies behind observed
surfaces, outside the image, or where the sensor gave no reading. Instead of marching every
pixel's ray, each voxel centre is projected into the image and compared with the depth there
(a projective test): the cost is one vectorised pass over the voxels, independent of the image
size. The test is conservative for *free*: the depth is min-filtered over the voxel's pixel
footprint, so a voxel is free only if every ray through it that returned a reading went past
it; a footprint with no reading at all stays unknown.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.ndimage import minimum_filter

from ipr_shapes.camera import invert_transform

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
    """What one frame saw of a voxel grid: ``state`` (nx, ny, nz) uint8 of UNKNOWN/FREE/OCCUPIED."""

    grid: VoxelGrid
    state: np.ndarray

    @property
    def free(self) -> np.ndarray:
        """(nx, ny, nz) bool, True where the camera saw empty space."""
        return self.state == FREE

    @property
    def unknown(self) -> np.ndarray:
        """(nx, ny, nz) bool, True where the camera could not see."""
        return self.state == UNKNOWN

    def state_at(self, points: np.ndarray) -> np.ndarray:
        """State (N,) of the voxels holding world points (N, 3); UNKNOWN outside the grid."""
        indices, inside = self.grid.indices_of(points)
        states = np.full(len(points), UNKNOWN, dtype=np.uint8)
        kept = indices[inside]
        nx, ny, nz = self.state.shape
        # One flat gather (the grid is C-ordered): cheaper than a tuple of three index arrays.
        flat = (kept[:, 0] * ny + kept[:, 1]) * nz + kept[:, 2]
        states[inside] = self.state.reshape(-1)[flat]
        return states


class SeenSpace(Protocol):
    """What the hypotheses and constraints ask of a free-space map: a ``SpaceMap``, or a view
    combining several frames' maps for one object (``ipr_shapes.fusion.TrackedFreeSpace``)."""

    @property
    def grid(self) -> VoxelGrid: ...

    def state_at(self, points: np.ndarray) -> np.ndarray: ...


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

    # Conservative "free": the nearest depth over the voxel's pixel footprint must lie beyond it.
    # The footprint shrinks with distance, so the min filter is precomputed at a few window sizes
    # and each voxel reads the one that covers it. A missing reading says nothing about where its
    # ray ended, so it is left out of the minimum (the voxel is covered by its neighbours' rays);
    # a footprint without any reading stays unknown.
    valid_depth = np.where(depth > 0, depth, np.inf).astype(np.float32)
    # Sensors drop readings at depth discontinuities: a missing pixel is assumed to belong to the
    # nearest surface around it, so free space never leaks past an object's silhouette.
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
    return SpaceMap(grid, state.reshape(grid.shape))
