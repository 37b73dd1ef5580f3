"""A 10 x 6 x 4 cm box standing on the table z = 0, seen by rendered depth cameras: partial
objects, free-space maps and the true shape for hypothesis and constraint tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from ipr_shapes.camera import backproject, look_at
from ipr_shapes.perception.free_space import FREE, OCCUPIED, SpaceMap, VoxelGrid, observe_space
from ipr_shapes.perception.types import Facet, KnownPlane, PartialObject
from ipr_shapes.rendering import render_depth_and_ids

BOX_HALF = np.array([0.05, 0.03, 0.02])  # m, centred at (0, 0, 0.02): bottom on z = 0
WIDTH, HEIGHT = 320, 240
K = np.array([[300.0, 0.0, WIDTH / 2 - 0.5], [0.0, 300.0, HEIGHT / 2 - 0.5], [0.0, 0.0, 1.0]])
GRID = VoxelGrid.around(np.array([-0.3, -0.3, -0.05]), np.array([0.3, 0.3, 0.3]), 0.005)
SUPPORT = KnownPlane(
    "support",
    np.array([0.0, 0.0, 1.0]),
    0.0,
    np.array([[x, y, 0.0] for x in (-0.4, 0.4) for y in (-0.4, 0.4)]),
)


def box_mesh(half: np.ndarray = BOX_HALF, centre: np.ndarray | None = None):
    """(vertices (8, 3), outward faces (12, 3)) of an axis-aligned box (m)."""
    centre = np.array([0.0, 0.0, half[2]]) if centre is None else np.asarray(centre, float)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    vertices = centre + corners * half
    hull = ConvexHull(vertices)
    faces = hull.simplices.copy()
    tri = vertices[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", normals, hull.equations[:, :3]) < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return vertices, faces


TABLE = box_mesh(np.array([0.4, 0.4, 0.005]), np.array([0.0, 0.0, -0.005]))
#: A backdrop behind the table, so that every ray of a low camera returns a depth.
BACKDROP = box_mesh(np.array([0.6, 0.01, 0.4]), np.array([0.0, 0.42, 0.3]))


@dataclass(frozen=True, eq=False)
class View:
    """One rendered view: depth (H, W) m, object index image, camera pose."""

    depth: np.ndarray
    index: np.ndarray
    world_from_camera: np.ndarray

    def space(self) -> SpaceMap:
        return observe_space(self.depth, K, self.world_from_camera, GRID)


def render_view(eye, target=(0.0, 0.0, 0.02), box=None) -> View:
    """Render the box (index 0) on the table (index 1) before a backdrop from ``eye``."""
    box = box_mesh() if box is None else box
    pose = look_at(np.asarray(eye, float), np.asarray(target, float))
    meshes = [box, TABLE, BACKDROP]
    depth, index = render_depth_and_ids(meshes, [None] * 3, K, WIDTH, HEIGHT, pose)
    return View(depth, index, pose)


def partial_box(
    view: View,
    object_id: int = 1,
    touches_border: bool = False,
    motion: np.ndarray | None = None,
    frame: int = 0,
) -> PartialObject:
    """The box's observed points with one facet per visible face (by nearest face plane).

    ``motion``: (4, 4) world transform the box was moved by before ``view`` was rendered
    (None: the box at its place); faces are found in the box's own frame, normals turned."""
    motion = np.eye(4) if motion is None else np.asarray(motion, float)
    mask = (view.index == 0) & (view.depth > 0)
    camera = backproject(view.depth, K)[mask]
    points = camera @ view.world_from_camera[:3, :3].T + view.world_from_camera[:3, 3]
    centre = np.array([0.0, 0.0, BOX_HALF[2]])
    local = ((points - motion[:3, 3]) @ motion[:3, :3] - centre) / BOX_HALF
    axis = np.argmax(np.abs(local), axis=1)
    sign = np.sign(local[np.arange(len(local)), axis])
    face = axis * 2 + (sign > 0)
    facets, facet_of_point = [], np.full(len(points), -1)
    for number in np.unique(face):
        members = face == number
        if members.sum() < 10:
            continue
        normal = np.zeros(3)
        normal[number // 2] = 1.0 if number % 2 else -1.0
        facet_points = points[members]
        in_plane = np.delete(local[members] * BOX_HALF, number // 2, axis=1)
        facet_of_point[members] = len(facets)
        facets.append(
            Facet(
                facet_points.mean(axis=0),
                motion[:3, :3] @ normal,
                facet_points,
                float(ConvexHull(in_plane).volume),
            )
        )
    pixels = np.flatnonzero(mask.ravel())
    colours = np.zeros((len(points), 3), dtype=np.uint8)
    return PartialObject(
        object_id, frame, pixels, points, colours, tuple(facets), facet_of_point, touches_border
    )


def merged_space(*spaces: SpaceMap) -> SpaceMap:
    """What several views saw together: FREE where any saw free, OCCUPIED where any saw a
    surface (and none saw free), else UNKNOWN."""
    free = np.any([s.state == FREE for s in spaces], axis=0)
    occupied = np.any([s.state == OCCUPIED for s in spaces], axis=0) & ~free
    state = np.where(free, FREE, np.where(occupied, OCCUPIED, np.uint8(0))).astype(np.uint8)
    return SpaceMap(spaces[0].grid, state)
