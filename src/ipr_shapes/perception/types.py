"""Data passed between the perception steps and on to hypothesis generation.

All points, centres and normals are in the world frame (metres, z up); pixel indices are flat
indices ``v * W + u`` into the frame's (H, W) image. Normals of observed surfaces point towards
the camera that saw them (out of the object).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class KnownPlane:
    """A large static plane removed from the objects: the support (table) or a wall.

    Attributes:
        kind: ``"support"`` or ``"wall"``.
        normal: (3,) unit normal pointing to the side the camera sees (into the workspace).
        offset: plane is {x : normal . x + offset = 0}, metres.
        points: (N, 3) inlier points (world, m), subsampled; their hull bounds the plane's extent
            for the physics stage.
        thickness_m: walls: depth (m) of the static slab behind the visible face (the wall's
            material: its rim and hidden face), removed with it; 0 for the support (everything
            below the support is removed anyway).
    """

    kind: str
    normal: np.ndarray
    offset: float
    points: np.ndarray
    thickness_m: float = 0.0

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (N,) of (N, 3) points to the plane, positive on the normal's side."""
        return points @ self.normal + self.offset


@dataclass(frozen=True, eq=False)
class DepthView:
    """What one camera saw: its depth image and pose, to ask whether a 3D point is visible.

    Attributes:
        depth_m: (H, W) float depth along the optical axis (m), 0 = no reading.
        K: (3, 3) intrinsics (pixels).
        world_from_camera: (4, 4) OpenCV camera frame to world frame (m).
    """

    depth_m: np.ndarray
    K: np.ndarray
    world_from_camera: np.ndarray

    def depths(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) depth of (N, 3) world points from the camera and (N,) depth observed at the
        pixel each projects to (m); NaN observed where the point is behind the camera, outside
        the image or its pixel has no reading (nothing known)."""
        z, observed, _ = self._look(points_world)
        return z, observed

    def in_image(self, points_world: np.ndarray) -> np.ndarray:
        """(N,) bool: the (N, 3) world points are in front of the camera and project into the
        image."""
        return self._look(points_world)[2]

    def _look(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``depths`` and ``in_image`` together."""
        rotation, centre = self.world_from_camera[:3, :3], self.world_from_camera[:3, 3]
        camera = (np.asarray(points_world, dtype=np.float64) - centre) @ rotation
        z = camera[:, 2]
        observed = np.full(len(camera), np.nan)
        front = z > 1e-6
        u = np.full(len(camera), -1, dtype=np.int64)
        v = np.full(len(camera), -1, dtype=np.int64)
        u[front] = np.round(self.K[0, 0] * camera[front, 0] / z[front] + self.K[0, 2])
        v[front] = np.round(self.K[1, 1] * camera[front, 1] / z[front] + self.K[1, 2])
        height, width = self.depth_m.shape
        inside = front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
        reading = self.depth_m[v[inside], u[inside]].astype(np.float64)
        observed[np.flatnonzero(inside)[reading > 0]] = reading[reading > 0]
        return z, observed, inside


@dataclass(frozen=True, eq=False)
class Supervoxels:
    """Small surface patches of one frame (paper Sec. III-A), the nodes of the segmentation graph.

    Attributes:
        labels: (H, W) int32, supervoxel of each pixel, -1 for pixels that belong to none
            (no depth, support, walls, robot).
        centres: (M, 3) mean world position of each supervoxel (m).
        normals: (M, 3) unit mean surface normal, towards the camera.
        colours: (M, 3) mean RGB in [0, 1].
        sizes: (M,) number of pixels.
        adjacency: (E, 2) int pairs (i < j) of supervoxels that touch in 3D.
    """

    labels: np.ndarray
    centres: np.ndarray
    normals: np.ndarray
    colours: np.ndarray
    sizes: np.ndarray
    adjacency: np.ndarray

    @property
    def count(self) -> int:
        """Number of supervoxels M."""
        return len(self.centres)


@dataclass(frozen=True, eq=False)
class Facet:
    """A homogeneous region of one side of an object (paper Sec. III-B).

    Attributes:
        centre: (3,) mean position (m, world).
        normal: (3,) unit mean normal, out of the object (towards the camera).
        points: (N, 3) observed points (m, world).
        area_m2: observed surface area (m^2), from the pixels' footprints.
    """

    centre: np.ndarray
    normal: np.ndarray
    points: np.ndarray
    area_m2: float


@dataclass(frozen=True, eq=False)
class PartialObject:
    """The observed part O_{i,t} of object i in frame t.

    Attributes:
        id: object id, the same for the same object in every frame (>= 1).
        frame: frame index t.
        pixels: (N,) flat pixel indices in frame t.
        points: (N, 3) world points of those pixels (m).
        colours: (N, 3) uint8 RGB of those pixels.
        facets: the object's facets; ``facet_of_point`` (N,) maps points to them (-1 = none).
        touches_border: True when the object is cut by the image border.
    """

    id: int
    frame: int
    pixels: np.ndarray
    points: np.ndarray
    colours: np.ndarray
    facets: tuple[Facet, ...] = ()
    facet_of_point: np.ndarray | None = None
    touches_border: bool = False

    @property
    def centroid(self) -> np.ndarray:
        """(3,) mean of the observed points (m, world)."""
        return self.points.mean(axis=0)


@dataclass(frozen=True, eq=False)
class FrameSegmentation:
    """Segmentation of one frame before tracking.

    Attributes:
        frame: frame index.
        labels: (H, W) int32, 0 for background/support/walls/robot, k >= 1 for segment k
            (per-frame numbering; tracking renumbers). Pixels without depth within a few pixels
            of a segment carry its label (image masks; they have no 3D point, so geometry must
            also require depth > 0).
        supervoxels: the graph nodes, with ``segment_of_supervoxel`` (M,) their segment (0 = none).
        planes: support and walls found in this frame.
    """

    frame: int
    labels: np.ndarray
    supervoxels: Supervoxels
    segment_of_supervoxel: np.ndarray
    planes: tuple[KnownPlane, ...]

    @property
    def segment_ids(self) -> list[int]:
        """Segment labels present (sorted, without 0)."""
        return sorted(int(k) for k in np.unique(self.labels) if k > 0)
