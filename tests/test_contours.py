"""Segments split at an occluding contour (``ipr_shapes.perception.contours``)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.contours import split_at_occluding_contours
from ipr_shapes.perception.types import KnownPlane, Supervoxels

K = np.array([[600.0, 0.0, 80.0], [0.0, 600.0, 60.0], [0.0, 0.0, 1.0]])
HEIGHT, WIDTH = 120, 160
BLOCK = 10  # supervoxels: 10 x 10 pixel blocks (1 cm at 0.6 m), split by the objects' outlines
#: The camera frame is the world frame: up is -y (the image's rows run down).
SUPPORT = KnownPlane("support", np.array([0.0, -1.0, 0.0]), 0.2, np.zeros((0, 3)))


def _rays() -> np.ndarray:
    rows, cols = np.mgrid[:HEIGHT, :WIDTH]
    return np.stack(
        [(cols - K[0, 2]) / K[0, 0], (rows - K[1, 2]) / K[1, 1], np.ones((HEIGHT, WIDTH))], -1
    )


def _sphere_depth(centre: tuple, radius: float) -> np.ndarray:
    """(H, W) depth of a sphere (camera frame, m; inf where the ray misses it)."""
    rays = _rays()
    c = np.asarray(centre)
    a = (rays**2).sum(-1)
    b = -2.0 * rays @ c
    disc = b**2 - 4 * a * (c @ c - radius**2)
    return np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a), np.inf)


def _frame(depths: list[np.ndarray], noise_m: float = 0.001, seed: int = 0):
    """Object index (0, 1, ...; -1 = nothing) and (H, W, 3) points, nearest surface wins."""
    stack = np.stack(depths)
    nearest = np.argmin(stack, axis=0)
    depth = np.take_along_axis(stack, nearest[None], axis=0)[0]
    nearest = np.where(np.isfinite(depth), nearest, -1)
    depth = np.where(np.isfinite(depth), depth, 0.0)
    depth = depth + np.random.default_rng(seed).normal(0.0, noise_m, depth.shape) * (depth > 0)
    return nearest, _rays() * depth[..., None]


def _supervoxels(objects: np.ndarray, points: np.ndarray) -> Supervoxels:
    """Supervoxels of 10 x 10 pixel blocks cut by the objects' outlines (a supervoxel never
    spans two objects), with their points' centres and plane normals (towards the camera at
    the origin)."""
    rows, cols = np.mgrid[:HEIGHT, :WIDTH]
    block = (rows // BLOCK) * (WIDTH // BLOCK) + cols // BLOCK
    key = np.where(objects >= 0, block * 8 + objects, -1)
    _, labels = np.unique(key, return_inverse=True)
    labels = labels.reshape(HEIGHT, WIDTH) - (1 if (key < 0).any() else 0)
    labels = np.where(objects >= 0, labels, -1).astype(np.int32)
    count = int(labels.max()) + 1
    centres, normals = np.zeros((count, 3)), np.zeros((count, 3))
    for s in range(count):
        own = points[labels == s]
        centres[s] = own.mean(axis=0)
        normal = np.linalg.svd(own - centres[s], full_matrices=False)[2][-1]
        normals[s] = -normal if normal @ centres[s] > 0 else normal
    sizes = np.bincount(labels[labels >= 0])
    return Supervoxels(labels, centres, normals, np.zeros((count, 3)), sizes, np.zeros((0, 2)))


def _config(split_px: int = 150) -> PerceptionConfig:
    base = PerceptionConfig()
    return dataclasses.replace(
        base, segmentation=dataclasses.replace(base.segmentation, contour_split_px=split_px)
    )


def _split(objects, points, config=None):
    """Every supervoxel in segment 1; returns the segment of each pixel (-1 = none)."""
    supervoxels = _supervoxels(objects, points)
    segments = np.ones(supervoxels.count, dtype=np.int32)
    result = split_at_occluding_contours(
        segments,
        supervoxels,
        points,
        np.zeros(3),
        SUPPORT,
        config if config is not None else _config(),
    )
    labels = supervoxels.labels
    return np.where(labels >= 0, result[labels], -1)


def _wall(distance_m: float) -> np.ndarray:
    """A wall facing the camera at ``distance_m`` over the whole image."""
    return np.full((HEIGHT, WIDTH), distance_m)


def test_a_ball_before_a_box_face_is_split_from_it():
    """A 3 cm ball 1.2 cm in front of a box's face (one segment: the voxel graph joins
    surfaces up to 2.6 cm apart): every pixel pair across the ball's outline is a step, so
    the segment is cut there, ball and face whole."""
    objects, points = _frame([_wall(0.6), _sphere_depth((0.0, 0.0, 0.6 - 0.012 - 0.03), 0.03)])
    segments = _split(objects, points)
    ball, face = segments[objects == 1], segments[objects == 0]
    assert len(np.unique(ball)) == 1 and len(np.unique(face)) == 1
    assert ball[0] != face[0]
    # Off: one segment.
    assert len(np.unique(_split(objects, points, _config(0)))) == 1


def test_two_faces_of_one_box_are_not_split():
    """A box seen at its edge (two supervoxel groups meeting at a 53 degree crease, convex
    towards the camera): one convex object's faces meet without a step."""
    rays = _rays()
    # A box edge: the plane z = 0.6 + 0.5 x for x < 0 and z = 0.6 - 0.5 x beyond (convex,
    # the edge towards the camera), seen head-on: depth along each ray.
    left = 0.6 / (1.0 - 0.5 * rays[..., 0])
    right = 0.6 / (1.0 + 0.5 * rays[..., 0])
    depth = np.where(rays[..., 0] < 0, left, right)
    objects = np.where(rays[..., 0] < 0, 0, 1)
    points = rays * depth[..., None]
    segments = _split(objects, points)
    assert len(np.unique(segments)) == 1


def test_a_face_seen_edge_on_is_not_split_from_its_neighbour():
    """A box's top face towards the camera and, below its edge, a side face seen almost
    edge-on (receding 15 mm per pixel row): the pixel pairs across the edge are steps of more
    than 1 cm, but the side face's supervoxels do not face the camera, so the steps prove
    nothing (one box). With any supervoxel counted the segment would be cut."""
    rays = _rays()
    rows = np.arange(HEIGHT)[:, None].repeat(WIDTH, 1)
    edge = 60
    depth = np.where(rows < edge, 0.6, 0.6 + 0.015 * (rows - edge + 1))
    objects = np.where(rows < edge, 0, np.where(rows < edge + BLOCK, 1, -1))
    points = rays * depth[..., None]
    assert len(np.unique(_split(objects, points)[objects >= 0])) == 1
    base = _config()
    any_normal = dataclasses.replace(
        base, segmentation=dataclasses.replace(base.segmentation, contour_facing_cos=-1.0)
    )
    assert len(np.unique(_split(objects, points, any_normal)[objects >= 0])) == 2


def _cylinder_depth(radius: float, centre_z: float, far: bool) -> np.ndarray:
    """(H, W) depth of an upright cylinder (axis along the image's rows) of ``radius`` around
    (0, *, ``centre_z``): its near or ``far`` side (inf where the ray misses it)."""
    rays = _rays()
    a = rays[..., 0] ** 2 + 1.0
    b = -2.0 * centre_z
    disc = b**2 - 4 * a * (centre_z**2 - radius**2)
    root = np.sqrt(np.maximum(disc, 0.0))
    t = ((-b + root) if far else (-b - root)) / (2 * a)
    return np.where(disc >= 0, t, np.inf)


def test_a_cups_inside_seen_over_its_front_wall_is_not_split():
    """A cup (4 cm radius, 3 mm wall): the image's lower half sees its front wall, the upper
    half, over the rim, the inside's far wall 8 cm behind. The wall occludes the inside as one
    object occludes another, but the inside lies within the circle fitted to the wall's
    footprint on the support (the containers' rule), so the segment stays whole; without the
    circle (neither part within the other's convex hull) it would be cut."""
    rows = np.arange(HEIGHT)[:, None].repeat(WIDTH, 1)
    front = _cylinder_depth(0.04, 0.6, far=False)
    inside = _cylinder_depth(0.037, 0.6, far=True)
    depth = np.where(rows >= HEIGHT // 2, front, inside)
    objects = np.where(np.isfinite(depth), np.where(rows >= HEIGHT // 2, 0, 1), -1)
    points = _rays() * np.where(np.isfinite(depth), depth, 0.0)[..., None]
    segments = _split(objects, points)
    assert len(np.unique(segments[objects >= 0])) == 1
    base = _config()
    no_circle = dataclasses.replace(
        base, containers=dataclasses.replace(base.containers, circle_rms_m=0.0)
    )
    assert len(np.unique(_split(objects, points, no_circle)[objects >= 0])) == 2


def test_an_object_seen_on_both_sides_of_an_occluder_stays_whole():
    """A face behind a bar (the bar another segment, not in this one): the face's two visible
    parts share no outline in the image, nothing shows a step between them."""
    wall = _wall(0.6)
    bar = np.where(np.abs(np.arange(WIDTH) - WIDTH / 2) < 8, 0.5, np.inf)[None].repeat(HEIGHT, 0)
    objects, points = _frame([wall, bar])
    face_only = np.where(objects == 0, 0, -1)  # the bar's pixels are not in the segment
    segments = _split(face_only, points)
    assert len(np.unique(segments[face_only == 0])) == 1


def test_a_short_step_outline_or_a_small_part_is_not_split():
    """The ball's outline shared with the face along fewer pixel pairs than
    ``contour_min_pairs`` (here required above the whole outline), or a part smaller than
    ``contour_split_px``: one segment."""
    objects, points = _frame([_wall(0.6), _sphere_depth((0.0, 0.0, 0.6 - 0.012 - 0.03), 0.03)])
    base = _config()
    strict = dataclasses.replace(
        base, segmentation=dataclasses.replace(base.segmentation, contour_min_pairs=100000)
    )
    assert len(np.unique(_split(objects, points, strict))) == 1
    ball_px = int((objects == 1).sum())
    assert len(np.unique(_split(objects, points, _config(ball_px + 1)))) == 1
    assert len(np.unique(_split(objects, points, _config(ball_px - 1)))) == 2


def test_three_large_parts_are_left_alone():
    """Two balls before one face: which parts belong together is not asked."""
    objects, points = _frame(
        [
            _wall(0.6),
            _sphere_depth((-0.05, 0.0, 0.6 - 0.012 - 0.025), 0.025),
            _sphere_depth((0.05, 0.0, 0.6 - 0.012 - 0.025), 0.025),
        ]
    )
    assert len(np.unique(_split(objects, points))) == 1
